//! `parse_bvh` on arbitrary bytes (lossy UTF-8); a clip that parses must be self-consistent and
//! give finite forward kinematics inputs for every frame.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinfield_formats::bvh::{BvhOptions, parse_bvh};

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(m) = parse_bvh(&text, &BvhOptions::default()) {
        assert_eq!(m.values.len(), m.frame_count() * m.channel_count());
        assert_eq!(m.channels.len(), m.skeleton.len());
        assert!(
            m.end_sites
                .iter()
                .all(|e| e.parent < m.skeleton.len() && e.offset.is_finite())
        );
        let mut world = vec![Default::default(); m.skeleton.len()];
        for pose in &m.poses {
            m.skeleton
                .world_matrices(pose, &mut world)
                .expect("every pose fits the skeleton");
        }
    }
});
