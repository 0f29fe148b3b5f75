//! `load_gltf_slice` on arbitrary bytes (glTF JSON or GLB, no external buffers): it must return,
//! never panic, whatever the gltf crate does inside.
//!
//! libfuzzer-sys installs a panic hook that aborts on every panic, even one that `gltf_io`
//! catches on purpose around the gltf crate. This target replaces the hook so such panics
//! unwind to `gltf_io`'s `catch_unwind` (they are counted, and the 1st, 2nd, 4th, 8th, … shown); a
//! panic that escapes `load_gltf_slice` still reaches libfuzzer-sys, which aborts: a crash.
#![no_main]

use std::sync::Once;
use std::sync::atomic::{AtomicUsize, Ordering};

use libfuzzer_sys::fuzz_target;

static CAUGHT: AtomicUsize = AtomicUsize::new(0);

fn count_panics() {
    std::panic::set_hook(Box::new(|info| {
        let n = CAUGHT.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            eprintln!(
                "gltf target: panic #{n} inside the import (caught unless a crash follows): {info}"
            );
        }
    }));
}

fuzz_target!(|data: &[u8]| {
    static HOOK: Once = Once::new();
    HOOK.call_once(count_panics);
    let _ = skinfield_formats::gltf_io::load_gltf_slice(data, None);
});
