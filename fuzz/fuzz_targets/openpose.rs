//! `parse_openpose` on arbitrary bytes: a file that parses yields exactly the requested keypoint
//! count, every detection finite with a confidence in `(0, 1]`.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use skinfield_formats::capture::keypoints::parse_openpose;

fuzz_target!(|data: &[u8]| {
    let (count, bytes) = match data.split_first() {
        Some((&n, rest)) => (usize::from(n % 32), rest),
        None => return,
    };
    if let Ok(k) = parse_openpose(Path::new("fuzz.json"), bytes, count) {
        assert_eq!(k.len(), count);
        for d in k.into_iter().flatten() {
            assert!(d.x.is_finite() && d.y.is_finite());
            assert!(d.confidence > 0.0 && d.confidence <= 1.0);
        }
    }
});
