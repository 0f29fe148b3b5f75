//! `SkfView::parse` on arbitrary bytes, then again with the length field and checksum repaired
//! (otherwise nearly every mutation stops at the checksum); every accessor of a view that parses
//! is exercised.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinfield_formats::skf::{HEADER_LEN, Net, SkfView, file_checksum};

fn exercise(v: &SkfView<'_>) {
    for t in v.tensors() {
        let mut out = vec![0.0; t.len()];
        t.to_f32(&mut out)
            .expect("buffer of the tensor's own length");
        let _ = (t.get(t.len()), t.as_f16(), t.name.as_str());
    }
    let s = v.skeleton();
    for j in 0..s.len() {
        let _ = (s.name(j), s.parent(j), s.bind_local(j), s.inverse_bind(j));
    }
    let _ = s.to_skeleton();
    if let Some(c) = v.candidates() {
        for a in 0..c.len() {
            let _ = (c.position(a), c.joints(a).count());
        }
    }
    if let Some(r) = v.pose_range() {
        for i in 0..r.len() {
            let (low, high) = (r.low(i), r.high(i));
            assert!(
                low.is_finite() && high.is_finite() && low <= high,
                "a parsed PRNG section has finite, ordered bounds"
            );
        }
    }
    for net in [Net::Skin, Net::Albedo, Net::Shadow] {
        for i in 0..=v.config().hidden_widths().len() + 1 {
            let _ = v.layer(net, i);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(v) = SkfView::parse(data) {
        exercise(&v);
    }
    if data.len() >= HEADER_LEN {
        let mut b = data.to_vec();
        let len = b.len() as u64;
        b[16..24].copy_from_slice(&len.to_le_bytes());
        let sum = file_checksum(&b);
        b[24..32].copy_from_slice(&sum.to_le_bytes());
        if let Ok(v) = SkfView::parse(&b) {
            exercise(&v);
        }
    }
});
