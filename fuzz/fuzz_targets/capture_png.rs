//! The capture's PNG readers on arbitrary bytes: `mask_from_png` and `labels_from_png` at a size
//! set by the first two bytes (1–64 pixels a side). A file that decodes has exactly that many
//! pixels, coverage in `[0, 1]` with `inside` its 50 % level, and labels that are palette indices
//! or `NO_LABEL`; every other input is an error, never a panic or an allocation beyond the cap.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use skinfield_formats::capture::{LabelsEntry, NO_LABEL, labels_from_png, mask_from_png};

fuzz_target!(|data: &[u8]| {
    let [w, h, rest @ ..] = data else {
        return;
    };
    let (width, height) = (u32::from(w % 64) + 1, u32::from(h % 64) + 1);
    let pixels = (width * height) as usize;
    if let Ok(mask) = mask_from_png(Path::new("fuzz.png"), rest.to_vec(), width, height) {
        assert_eq!(mask.coverage.len(), pixels);
        assert_eq!(mask.inside.len(), pixels);
        for (c, inside) in mask.coverage.iter().zip(&mask.inside) {
            assert!((0.0..=1.0).contains(c));
            assert_eq!(*inside, *c > 0.5);
        }
    }
    let entry = LabelsEntry {
        folder: "labels".into(),
        palette: vec![[255, 160, 120], [40, 90, 220]],
        frames: vec![0],
    };
    if let Ok(labels) = labels_from_png(Path::new("fuzz.png"), rest.to_vec(), width, height, &entry)
    {
        assert_eq!(labels.labels.len(), pixels);
        assert!(labels.labels.iter().all(|&l| l < 2 || l == NO_LABEL));
    }
});
