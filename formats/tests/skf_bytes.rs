//! `.skf` robustness: round trips of a small and a full-size model, every truncated prefix,
//! seeded bit flips (caught by the checksum, and, with the checksum recomputed, never a panic),
//! one constructed failure per `SkfError` variant, and absurd counts and offsets in headers.

use glam::{Mat4, Quat, Vec3};
use half::f16;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use skinfield_formats::skf::{
    self, ALIGN, Candidates, Dtype, HEADER_LEN, MAX_FILE_LEN, MAX_HIDDEN_LAYERS, MAX_TENSORS,
    ModelConfig, Net, PoseRange, SECTION_ENTRY_LEN, SkfConfigError, SkfError, SkfModel, SkfView,
    TENSOR_ENTRY_LEN, Tag, file_checksum, read_skf_file, tag,
};
use skinfield_formats::{Skeleton, Transform};

/// A skeleton of `n` joints (a binary tree) with rotated, translated and scaled bind transforms
/// and a non-identity base.
fn skeleton(n: usize, rng: &mut ChaCha8Rng) -> Skeleton {
    let bind = (0..n)
        .map(|_| Transform {
            translation: Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ),
            rotation: Quat::from_euler(
                glam::EulerRot::ZXY,
                rng.random(),
                rng.random(),
                rng.random(),
            ),
            scale: Vec3::splat(rng.random_range(0.5..2.0)),
        })
        .collect();
    Skeleton::new(
        (0..n).map(|j| format!("joint_{j}")).collect(),
        (0..n).map(|j| j.checked_sub(1).map(|p| p / 2)).collect(),
        bind,
        None,
        None,
        Mat4::from_rotation_translation(Quat::from_rotation_x(-0.5), Vec3::new(0.1, 0.2, 0.3)),
    )
    .unwrap()
}

/// A model for `config` with seeded values in [-3, 3], plus a few values at f16's edges.
fn model(config: ModelConfig, seed: u64) -> SkfModel {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let skeleton = skeleton(config.joint_count as usize, &mut rng);
    let mut m = SkfModel {
        config,
        skeleton,
        tensors: Vec::new(),
        candidates: None,
        pose_range: None,
    };
    let shapes: Vec<(usize, usize)> = config.layer_shapes(Net::Skin).collect();
    for (i, (out, inp)) in shapes.into_iter().enumerate() {
        let mut w: Vec<f32> = (0..out * inp)
            .map(|_| rng.random_range(-3.0..3.0))
            .collect();
        // Exactly representable, rounded, largest finite, subnormal, flushed to zero, signed zero.
        let edges = [0.5, 0.1, 65504.0, -6.0e-8, 1.0e-9, -0.0];
        w[..edges.len()].copy_from_slice(&edges);
        let b = (0..out).map(|_| rng.random_range(-3.0..3.0)).collect();
        m.push_layer(Net::Skin, i, w, out, inp, b);
    }
    m
}

/// J = 3, two hidden layers of 8, skip into the second, L = 2.
fn small_config() -> ModelConfig {
    let mut c = ModelConfig::paper_architecture(3, [-0.5, -1.0, -0.25], [0.5, 1.0, 0.25]);
    c.pe_frequencies = 2;
    c.hidden_count = 2;
    c.hidden = [0; MAX_HIDDEN_LAYERS];
    c.hidden[..2].copy_from_slice(&[8, 8]);
    c.skip_layer = 1;
    c
}

fn small() -> (SkfModel, Vec<u8>) {
    let m = model(small_config(), 7);
    let bytes = m.to_bytes().unwrap();
    (m, bytes)
}

fn full() -> (SkfModel, Vec<u8>) {
    let m = model(
        ModelConfig::paper_architecture(24, [-1.0, -0.2, -0.5], [1.0, 1.8, 0.5]),
        11,
    );
    let bytes = m.to_bytes().unwrap();
    (m, bytes)
}

fn assert_round_trip(m: &SkfModel, bytes: &[u8]) {
    let v = SkfView::parse(bytes).unwrap();
    assert_eq!(*v.config(), m.config);
    assert_eq!(v.tensor_count(), m.tensors.len());
    for (name, dims, values) in &m.tensors {
        let t = v.tensor(name).unwrap_or_else(|| panic!("{name}"));
        assert_eq!(t.dtype, Dtype::F16);
        assert_eq!(t.rank as usize, dims.len(), "{name}");
        assert_eq!(
            t.dims,
            [dims[0] as u32, dims.get(1).map_or(0, |&d| d as u32)],
            "{name}"
        );
        let mut got = vec![0.0; t.len()];
        t.to_f32(&mut got).unwrap();
        assert_eq!(got.len(), values.len(), "{name}");
        for (i, (g, x)) in got.iter().zip(values).enumerate() {
            // Bitwise: -0.0 stays -0.0, and 65504 (f16's largest) stays finite.
            assert_eq!(
                g.to_bits(),
                f16::from_f32(*x).to_f32().to_bits(),
                "{name}[{i}]: {g} from {x}"
            );
        }
        let in_place = t.as_f16().unwrap();
        assert!(
            in_place
                .iter()
                .zip(&got)
                .all(|(h, g)| h.to_f32().to_bits() == g.to_bits())
        );
        assert_eq!(
            t.bytes.as_ptr() as usize % ALIGN,
            (bytes.as_ptr() as usize) % ALIGN,
            "{name} offset aligned"
        );
    }
    for (i, (out, inp)) in m.config.layer_shapes(Net::Skin).enumerate() {
        let (w, b) = v.layer(Net::Skin, i).unwrap();
        assert_eq!(
            (w.dims, b.dims),
            ([out as u32, inp as u32], [out as u32, 0])
        );
    }
    assert!(
        v.layer(Net::Skin, m.config.hidden_count as usize + 1)
            .is_none()
    );
    assert!(v.layer(Net::Albedo, 0).is_none());
    // The skeleton's fields come back bit for bit (stored as f32).
    let s = v.skeleton().to_skeleton().unwrap();
    assert_eq!(s.names(), m.skeleton.names());
    assert_eq!(s.parents(), m.skeleton.parents());
    assert_eq!(s.bind_local(), m.skeleton.bind_local());
    assert_eq!(s.inverse_bind(), m.skeleton.inverse_bind());
    assert_eq!(s.base(), m.skeleton.base());
}

#[test]
fn small_and_full_size_models_round_trip() {
    let (m, bytes) = small();
    assert_round_trip(&m, &bytes);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("small.skf");
    m.write(&path).unwrap();
    assert_eq!(read_skf_file(&path).unwrap(), bytes);
    let (m, bytes) = full();
    assert_eq!(
        m.config.macs_per_vertex(Net::Skin),
        m.tensors
            .iter()
            .step_by(2)
            .map(|t| t.2.len())
            .sum::<usize>()
    );
    assert_round_trip(&m, &bytes);
}

#[test]
fn every_truncated_prefix_is_an_error() {
    let (_, bytes) = small();
    for cut in 0..bytes.len() {
        let e = SkfView::parse(&bytes[..cut]).unwrap_err();
        assert!(
            matches!(e, SkfError::Truncated { len, .. } if len == cut as u64),
            "cut {cut}: {e}"
        );
    }
    // With a CAND section (version 1.1), and with CAND and PRNG (1.2): every prefix too.
    for (name, m) in [
        ("CAND", with_candidates()),
        ("CAND + PRNG", with_pose_range()),
    ] {
        let bytes = m.to_bytes().unwrap();
        SkfView::parse(&bytes).unwrap().candidates().unwrap();
        for cut in 0..bytes.len() {
            assert!(
                matches!(
                    SkfView::parse(&bytes[..cut]),
                    Err(SkfError::Truncated { .. })
                ),
                "{name} file, cut {cut}"
            );
        }
    }
    // The full-size file: every prefix through the tables, then every 61st.
    let (_, bytes) = full();
    let data = section(&bytes, tag::DATA).1;
    for cut in (0..data).chain((data..bytes.len()).step_by(61)) {
        assert!(
            matches!(
                SkfView::parse(&bytes[..cut]),
                Err(SkfError::Truncated { .. })
            ),
            "cut {cut}"
        );
    }
}

/// The small model with three anchors and their candidate lists.
fn with_candidates() -> SkfModel {
    let (mut m, _) = small();
    m.candidates = Some(Candidates {
        positions: vec![[0.0, 0.5, 0.0], [0.1, 1.0, 0.0], [-0.2, 1.5, 0.1]],
        lists: vec![vec![0, 1], vec![1], vec![0, 1, 2]],
        k: 3,
    });
    m
}

/// The model with candidates and the training range of its 9 pose features (3 joints).
fn with_pose_range() -> SkfModel {
    let mut m = with_candidates();
    let poses = [
        [0.1f32, -0.2, 0.3, 0.0, 0.5, -0.5, 1.0, 0.0, 0.0],
        [-0.1, 0.2, 0.3, 0.0, 0.25, 0.5, -1.0, 0.0, 0.0],
    ];
    m.pose_range = PoseRange::of(9, poses.iter().map(|p| &p[..]));
    m
}

#[test]
fn pose_range_round_trips_and_sets_the_minor_version() {
    let m = with_pose_range();
    let r = m.pose_range.clone().unwrap();
    assert_eq!(r.low, [-0.1, -0.2, 0.3, 0.0, 0.25, -0.5, -1.0, 0.0, 0.0]);
    assert_eq!(r.high, [0.1, 0.2, 0.3, 0.0, 0.5, 0.5, 1.0, 0.0, 0.0]);
    let bytes = m.to_bytes().unwrap();
    let v = SkfView::parse(&bytes).unwrap();
    assert_eq!(v.minor_version(), 2);
    let p = v.pose_range().unwrap();
    assert_eq!(p.len(), 9);
    for i in 0..9 {
        assert_eq!((p.low(i), p.high(i)), (r.low[i], r.high[i]), "feature {i}");
    }
    // Without the range the same model is 1.1, without candidates 1.0.
    let c = with_candidates().to_bytes().unwrap();
    assert_eq!(SkfView::parse(&c).unwrap().minor_version(), 1);
    assert!(SkfView::parse(&c).unwrap().pose_range().is_none());
    assert_eq!(SkfView::parse(&small().1).unwrap().minor_version(), 0);
    // A range that does not fit the skeleton is refused on writing, naming both counts.
    let mut wrong = with_pose_range();
    wrong.pose_range = Some(PoseRange {
        low: vec![0.0; 6],
        high: vec![0.0; 6],
    });
    let e = wrong.to_bytes().unwrap_err().to_string();
    assert!(
        e.contains("PRNG: 6 pose features, the skeleton has 9"),
        "{e}"
    );
    wrong.pose_range = Some(PoseRange {
        low: vec![0.0; 9],
        high: vec![0.0; 8],
    });
    assert!(matches!(
        wrong.to_bytes(),
        Err(skf::SkfFileError::Invalid(_))
    ));
    assert_eq!(PoseRange::of(3, std::iter::empty()), None);
    // In the file, a lower bound above its upper one is refused with its feature.
    let (_, at, _) = section(&bytes, tag::PRNG);
    let bad = patched(&bytes, |b| put(b, at + 16 + 4 * 4, &0.75f32.to_le_bytes()));
    assert_eq!(parse_err(&bad), SkfError::BadPoseRange(4));
    let twice = patched(&bytes, |b| {
        let prng_entry = HEADER_LEN + 5 * SECTION_ENTRY_LEN;
        let cand_entry = HEADER_LEN + 4 * SECTION_ENTRY_LEN;
        put(b, cand_entry, &tag::PRNG);
        assert_eq!(&b[prng_entry..prng_entry + 4], &tag::PRNG);
    });
    assert_eq!(
        parse_err(&twice),
        SkfError::DuplicateSection(Tag(tag::PRNG))
    );
}

fn reseal(b: &mut [u8]) {
    let sum = file_checksum(b);
    b[24..32].copy_from_slice(&sum.to_le_bytes());
}

/// Touches every accessor of a view that parsed, so a bad value that slipped through would
/// panic here.
fn exercise(v: &SkfView<'_>) {
    for t in v.tensors() {
        let mut out = vec![0.0; t.len()];
        t.to_f32(&mut out).unwrap();
        let _ = (
            t.get(t.len()),
            t.get(usize::MAX),
            t.as_f16(),
            t.name.as_str(),
        );
    }
    let s = v.skeleton();
    for j in 0..s.len() {
        let _ = (s.name(j), s.parent(j), s.bind_local(j), s.inverse_bind(j));
    }
    let _ = s.to_skeleton();
    for i in 0..=v.config().hidden_count as usize + 1 {
        let _ = v.layer(Net::Skin, i);
    }
    if let Some(r) = v.pose_range() {
        for i in 0..r.len() {
            let _ = (r.low(i), r.high(i));
        }
    }
}

#[test]
fn seeded_bit_flips_are_caught_and_never_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    for (label, (_, bytes), flips) in [("small", small(), 4000), ("full", full(), 150)] {
        let (mut resealed_ok, mut resealed_err) = (0, 0);
        for _ in 0..flips {
            let mut b = bytes.clone();
            let at = rng.random_range(0..b.len());
            b[at] ^= 1 << rng.random_range(0..8);
            let e = SkfView::parse(&b).unwrap_err();
            // Magic, major version and file length are checked before the checksum.
            if !(at < 10 || (16..24).contains(&at)) {
                assert!(
                    matches!(e, SkfError::Checksum { .. }),
                    "{label} flip at {at}: {e}"
                );
            }
            reseal(&mut b);
            match SkfView::parse(&b) {
                Ok(v) => {
                    resealed_ok += 1;
                    exercise(&v);
                }
                Err(_) => resealed_err += 1,
            }
        }
        // Most flips land in tensor data and still parse once resealed; the rest are refused.
        assert!(
            resealed_ok > 0 && resealed_err > 0,
            "{label}: {resealed_ok} ok, {resealed_err} refused"
        );
    }
    // Bursts of random bytes and extreme field values at 4-byte-aligned positions of the
    // header, tables and skeleton.
    let (_, bytes) = small();
    let tables_end = section(&bytes, tag::DATA).1;
    let extremes: [u64; 7] = [0, 1, 63, 64, u64::from(u32::MAX), u64::MAX, 1 << 31];
    for _ in 0..6000 {
        let mut b = bytes.clone();
        if rng.random_bool(0.5) {
            let at = rng.random_range(0..b.len() - 8);
            let n = rng.random_range(1..8);
            rng.fill(&mut b[at..at + n]);
        } else {
            let at = rng.random_range(0..tables_end / 4 - 2) * 4;
            let v = extremes[rng.random_range(0..extremes.len())].to_le_bytes();
            let width = if rng.random_bool(0.5) { 4 } else { 8 };
            b[at..at + width].copy_from_slice(&v[..width]);
        }
        if rng.random_bool(0.9) {
            reseal(&mut b);
        }
        if let Ok(v) = SkfView::parse(&b) {
            exercise(&v);
        }
    }
}

/// `(entry position, offset, len)` of the section tagged `t`.
fn section(b: &[u8], t: [u8; 4]) -> (usize, usize, usize) {
    let count = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
    (0..count)
        .map(|s| HEADER_LEN + s * SECTION_ENTRY_LEN)
        .find(|&e| b[e..e + 4] == t)
        .map(|e| (e, u64_at(b, e + 8) as usize, u64_at(b, e + 16) as usize))
        .unwrap()
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

/// Position of the TINF entry of tensor `name`.
fn tensor_entry(b: &[u8], name: &str) -> usize {
    let tinf = section(b, tag::TINF).1;
    let count = u32::from_le_bytes(b[tinf..tinf + 4].try_into().unwrap()) as usize;
    (0..count)
        .map(|i| tinf + 8 + i * TENSOR_ENTRY_LEN)
        .find(|&e| b[e..e + 24].split(|&c| c == 0).next() == Some(name.as_bytes()))
        .unwrap()
}

/// A copy of `bytes` with `patch` applied and the checksum recomputed.
fn patched(bytes: &[u8], patch: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
    let mut b = bytes.to_vec();
    patch(&mut b);
    reseal(&mut b);
    b
}

fn put(b: &mut [u8], at: usize, v: &[u8]) {
    b[at..at + v.len()].copy_from_slice(v);
}

fn parse_err(b: &[u8]) -> SkfError {
    SkfView::parse(b).unwrap_err()
}

#[test]
fn header_and_section_failures_each_have_their_variant() {
    let (_, b) = small();
    let len = b.len() as u64;
    let (conf_e, conf, _) = section(&b, tag::CONF);
    let (skel_e, skel, skel_len) = section(&b, tag::SKEL);
    let (tinf_e, tinf, _) = section(&b, tag::TINF);
    let (data_e, data, data_len) = section(&b, tag::DATA);
    assert_eq!(data + data_len, b.len());

    assert_eq!(
        parse_err(&b[..10]),
        SkfError::Truncated {
            needed: HEADER_LEN as u64,
            len: 10
        }
    );
    assert_eq!(parse_err(&patched(&b, |b| b[0] = b'X')), SkfError::BadMagic);
    assert_eq!(
        parse_err(&patched(&b, |b| put(b, 8, &2u16.to_le_bytes()))),
        SkfError::UnsupportedVersion { major: 2, minor: 0 }
    );
    // A later minor version with the same layout is read.
    assert_eq!(
        SkfView::parse(&patched(&b, |b| put(b, 10, &3u16.to_le_bytes())))
            .unwrap()
            .minor_version(),
        3
    );
    let mut longer = b.clone();
    longer.extend_from_slice(&[0; 64]);
    reseal(&mut longer);
    assert_eq!(
        parse_err(&longer),
        SkfError::LengthMismatch {
            declared: len,
            actual: len + 64
        }
    );
    for declared in [MAX_FILE_LEN + 1, u64::MAX] {
        assert_eq!(
            parse_err(&patched(&b, |b| put(b, 16, &declared.to_le_bytes()))),
            SkfError::TooLarge(declared)
        );
    }
    let mut flipped = b.clone();
    flipped[data + 3] ^= 0x10;
    assert!(
        matches!(parse_err(&flipped), SkfError::Checksum { stored, computed } if stored != computed)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| b[40] = 1)),
        SkfError::ReservedNonZero(40)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| b[skel_e + 5] = 1)),
        SkfError::ReservedNonZero(skel_e as u64)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| b[tinf_e + 31] = 1)),
        SkfError::ReservedNonZero(tinf_e as u64)
    );
    for count in [0, 17, u32::MAX] {
        assert_eq!(
            parse_err(&patched(&b, |b| put(b, 12, &count.to_le_bytes()))),
            SkfError::SectionCount(count)
        );
    }
    // Four sections declared, eight present in the count: the table would run into CONF.
    assert!(matches!(
        parse_err(&patched(&b, |b| put(b, 12, &8u32.to_le_bytes()))),
        SkfError::SectionPlacement { .. }
    ));
    let e = parse_err(&patched(&b, |b| {
        put(b, skel_e + 8, &((skel + 2) as u64).to_le_bytes())
    }));
    assert!(
        matches!(e, SkfError::SectionPlacement { tag, offset } if tag.0 == tag::SKEL && offset == skel as u64 + 2),
        "{e}"
    );
    let e = parse_err(&patched(&b, |b| {
        put(b, skel_e + 8, &(conf as u64).to_le_bytes())
    }));
    assert!(
        matches!(e, SkfError::SectionPlacement { tag, offset } if tag.0 == tag::SKEL && offset == conf as u64),
        "{e}"
    );
    for (offset, len) in [
        (data as u64, u64::MAX),
        (u64::MAX - 63, 64),
        (!63u64, 0),
        (data as u64, data_len as u64 + 1),
    ] {
        let e = parse_err(&patched(&b, |b| {
            put(b, data_e + 8, &offset.to_le_bytes());
            put(b, data_e + 16, &len.to_le_bytes());
        }));
        assert!(
            matches!(e, SkfError::SectionOutOfBounds { tag } if tag.0 == tag::DATA),
            "{offset} {len}: {e}"
        );
    }
    // DATA declared 64 bytes short: its tail is covered by nothing.
    let e = parse_err(&patched(&b, |b| {
        put(b, data_e + 16, &(data_len as u64 - 64).to_le_bytes())
    }));
    assert_eq!(
        e,
        SkfError::Uncovered {
            offset: len - 64,
            len: 64
        }
    );
    // A non-zero byte in the padding after SKEL.
    assert_ne!(
        (skel + skel_len) % ALIGN,
        0,
        "the test needs padding after SKEL"
    );
    let e = parse_err(&patched(&b, |b| b[skel + skel_len + 1] = 7));
    assert_eq!(
        e,
        SkfError::Uncovered {
            offset: (skel + skel_len) as u64,
            len: (tinf - skel - skel_len) as u64
        }
    );
    // An unknown tag is skipped, so DATA goes missing; a second TINF is a duplicate.
    let e = parse_err(&patched(&b, |b| put(b, data_e, b"XTRA")));
    assert!(
        matches!(e, SkfError::MissingSection(t) if t.0 == tag::DATA),
        "{e}"
    );
    let e = parse_err(&patched(&b, |b| put(b, data_e, b"TINF")));
    assert!(
        matches!(e, SkfError::DuplicateSection(t) if t.0 == tag::TINF),
        "{e}"
    );
    // CONF one byte short (its last byte is zero, so the gap left is valid padding).
    let e = parse_err(&patched(&b, |b| put(b, conf_e + 16, &127u64.to_le_bytes())));
    assert!(
        matches!(e, SkfError::SectionLength { tag, len: 127, expected: 128 } if tag.0 == tag::CONF),
        "{e}"
    );
    let e = parse_err(&patched(&b, |b| put(b, conf + 8, &7u32.to_le_bytes())));
    assert_eq!(
        e,
        SkfError::Config(SkfConfigError::BadField("pose_encoding"))
    );
}

/// Offset of SKEL's joint record `j`.
fn record(b: &[u8], j: usize) -> usize {
    section(b, tag::SKEL).1 + skf::SKEL_HEADER_LEN + j * skf::JOINT_RECORD_LEN
}

#[test]
fn skeleton_failures_each_have_their_variant() {
    let (_, b) = small();
    let (_, skel, skel_len) = section(&b, tag::SKEL);
    let conf = section(&b, tag::CONF).1;
    let rec: Vec<usize> = (0..4).map(|j| record(&b, j)).collect();
    let names = rec[3];
    for count in [4, 2, u32::MAX] {
        let e = parse_err(&patched(&b, |b| put(b, skel, &count.to_le_bytes())));
        assert_eq!(
            e,
            SkfError::JointCount {
                skel: count,
                conf: 3
            }
        );
    }
    let e = parse_err(&patched(&b, |b| put(b, conf + 16, &u32::MAX.to_le_bytes())));
    assert_eq!(e, SkfError::Config(SkfConfigError::BadField("joint_count")));
    let names_len = u32::from_le_bytes(b[skel + 4..skel + 8].try_into().unwrap());
    let e = parse_err(&patched(&b, |b| {
        put(b, skel + 4, &(names_len + 1).to_le_bytes())
    }));
    assert!(
        matches!(e, SkfError::SectionLength { tag, len, expected } if tag.0 == tag::SKEL && len == skel_len as u64 && expected == len + 1),
        "{e}"
    );
    for absurd in [u32::MAX, skf::MAX_NAMES_LEN as u32 + 1] {
        let e = parse_err(&patched(&b, |b| put(b, skel + 4, &absurd.to_le_bytes())));
        assert!(
            matches!(e, SkfError::SectionLength { tag, .. } if tag.0 == tag::SKEL),
            "{e}"
        );
    }
    assert_eq!(
        parse_err(&patched(&b, |b| b[skel + 9] = 1)),
        SkfError::ReservedNonZero(8)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| put(b, skel + 16, &f32::NAN.to_le_bytes()))),
        SkfError::NonFiniteJoint(0)
    );
    for (j, parent) in [(0, 0), (1, 1), (1, 2), (2, 7), (2, u32::MAX - 1)] {
        let e = parse_err(&patched(&b, |b| put(b, rec[j], &parent.to_le_bytes())));
        assert_eq!(
            e,
            SkfError::BadParent(j as u32),
            "joint {j} parent {parent}"
        );
    }
    // Name offset and length: past the names block, overflowing, empty, not UTF-8.
    for (field, value) in [(4, 1000), (4, u32::MAX), (8, 1000), (8, u32::MAX), (8, 0)] {
        let e = parse_err(&patched(&b, |b| {
            put(b, rec[2] + field, &u32::to_le_bytes(value))
        }));
        assert_eq!(e, SkfError::BadJointName(2), "field {field} = {value}");
    }
    assert_eq!(
        parse_err(&patched(&b, |b| b[names + 8] = 0xff)),
        SkfError::BadJointName(1)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| b[rec[1] + 12] = 1)),
        SkfError::ReservedNonZero(1)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| b[rec[2] + 127] = 1)),
        SkfError::ReservedNonZero(2)
    );
    for (float, value) in [(0, f32::INFINITY), (5, f32::NAN), (25, f32::NEG_INFINITY)] {
        let e = parse_err(&patched(&b, |b| {
            put(b, rec[1] + 16 + 4 * float, &value.to_le_bytes())
        }));
        assert_eq!(e, SkfError::NonFiniteJoint(1), "float {float}");
    }
}

#[test]
fn tensor_table_failures_each_have_their_variant() {
    let (m, b) = small();
    let (tinf_e, tinf, _) = section(&b, tag::TINF);
    let (data_e, data, data_len) = section(&b, tag::DATA);
    let count = m.tensors.len() as u32;
    let w0 = tensor_entry(&b, "skin.l0.weight");
    let b0 = tensor_entry(&b, "skin.l0.bias");
    let name = |s: &str| skf::TensorName::new(s).unwrap();
    let l0 = name("skin.l0.weight");

    assert_eq!(
        parse_err(&patched(&b, |b| b[tinf + 4] = 1)),
        SkfError::ReservedNonZero(4)
    );
    for absurd in [MAX_TENSORS as u32 + 1, u32::MAX] {
        assert_eq!(
            parse_err(&patched(&b, |b| put(b, tinf, &absurd.to_le_bytes()))),
            SkfError::TensorCount(absurd)
        );
    }
    let e = parse_err(&patched(&b, |b| put(b, tinf, &(count - 1).to_le_bytes())));
    assert!(
        matches!(e, SkfError::SectionLength { tag, .. } if tag.0 == tag::TINF),
        "{e}"
    );
    let e = parse_err(&patched(&b, |b| b.copy_within(w0..w0 + 24, b0)));
    assert_eq!(e, SkfError::BadTensorName(1));
    assert_eq!(
        parse_err(&patched(&b, |b| put(b, w0, &[0; 24]))),
        SkfError::BadTensorName(0)
    );
    assert_eq!(
        parse_err(&patched(&b, |b| put(b, w0, &[0xff, 0xfe]))),
        SkfError::BadTensorName(0)
    );
    for code in [0, 3, u32::MAX] {
        let e = parse_err(&patched(&b, |b| put(b, w0 + 24, &code.to_le_bytes())));
        assert_eq!(e, SkfError::BadDtype { name: l0, code });
    }
    // Rank 0 and 3, a zero dimension, a second dim on a rank-1 tensor, a third dim.
    for (at, value) in [(28, 0), (28, 3), (32, 0), (36, 0), (40, 1), (44, 1)] {
        let e = parse_err(&patched(&b, |b| put(b, w0 + at, &u32::to_le_bytes(value))));
        assert_eq!(e, SkfError::BadShape(l0), "byte {at} = {value}");
    }
    assert_eq!(
        parse_err(&patched(&b, |b| put(b, b0 + 36, &1u32.to_le_bytes()))),
        SkfError::BadShape(name("skin.l0.bias"))
    );
    // The dtype size times the dims must be nbytes: F32 for F16 bytes, huge dims, huge nbytes.
    assert_eq!(
        parse_err(&patched(&b, |b| put(b, w0 + 24, &2u32.to_le_bytes()))),
        SkfError::ByteSize(l0)
    );
    let huge_dims = |b: &mut Vec<u8>| {
        put(b, w0 + 32, &u32::MAX.to_le_bytes());
        put(b, w0 + 36, &u32::MAX.to_le_bytes());
    };
    assert_eq!(parse_err(&patched(&b, huge_dims)), SkfError::ByteSize(l0));
    for nbytes in [u64::MAX, u64::MAX - 1, 0] {
        assert_eq!(
            parse_err(&patched(&b, |b| put(b, w0 + 56, &u64::to_le_bytes(nbytes)))),
            SkfError::ByteSize(l0)
        );
    }
    // Offsets: misaligned, overflowing, past DATA, overlapping the previous tensor.
    let w0_offset = u64_at(&b, w0 + 48);
    for offset in [w0_offset + 2, u64::MAX - 1, !63u64, data_len as u64] {
        let e = parse_err(&patched(&b, |b| put(b, w0 + 48, &offset.to_le_bytes())));
        assert_eq!(e, SkfError::TensorPlacement(l0), "offset {offset}");
    }
    let e = parse_err(&patched(&b, |b| put(b, b0 + 48, &w0_offset.to_le_bytes())));
    assert_eq!(e, SkfError::TensorPlacement(name("skin.l0.bias")));
    // A non-zero byte in the padding after skin.l0.bias (16 bytes, then 48 of padding).
    let pad = data + (u64_at(&b, b0 + 48) + u64_at(&b, b0 + 56)) as usize;
    let w1 = tensor_entry(&b, "skin.l1.weight");
    assert_ne!(
        pad - data,
        u64_at(&b, w1 + 48) as usize,
        "the test needs padding after skin.l0.bias"
    );
    assert_eq!(
        parse_err(&patched(&b, |b| b[pad + 5] = 1)),
        SkfError::TensorPlacement(name("skin.l1.weight"))
    );
    // DATA longer than its tensors.
    let mut longer = b.clone();
    longer.extend_from_slice(&[0; 64]);
    put(&mut longer, 16, &(b.len() as u64 + 64).to_le_bytes());
    put(
        &mut longer,
        data_e + 16,
        &(data_len as u64 + 64).to_le_bytes(),
    );
    reseal(&mut longer);
    assert_eq!(
        parse_err(&longer),
        SkfError::Uncovered {
            offset: data_len as u64,
            len: 64
        }
    );
    // A network tensor renamed away, or shaped [in, out].
    assert_eq!(
        parse_err(&patched(&b, |b| b[w0 + 13] = 0)),
        SkfError::MissingTensor(l0)
    );
    let e = parse_err(&patched(&b, |b| {
        put(b, w0 + 32, &24u32.to_le_bytes());
        put(b, w0 + 36, &8u32.to_le_bytes());
    }));
    assert_eq!(
        e,
        SkfError::TensorShape {
            name: l0,
            got: [24, 8],
            expected: [8, 24]
        }
    );
    assert_eq!(count, 6);
    let _ = tinf_e;

    let v = SkfView::parse(&b).unwrap();
    let t = v.tensor("skin.l0.weight").unwrap();
    assert_eq!(
        t.to_f32(&mut [0.0; 3]),
        Err(SkfError::OutputLength {
            len: 3,
            expected: 8 * 24
        })
    );
}

#[test]
fn absurd_counts_and_offsets_are_refused_at_once() {
    // Each patch names a count or an offset that, trusted, would mean gigabytes; the reader
    // refuses it from the header alone (it allocates nothing at all: it only borrows).
    let (_, b) = full();
    let (tinf_e, tinf, _) = section(&b, tag::TINF);
    let skel = section(&b, tag::SKEL).1;
    let w = tensor_entry(&b, "skin.l4.weight");
    type Patch = (usize, Vec<u8>);
    let cases: [(&str, Patch); 10] = [
        ("section count", (12, u32::MAX.to_le_bytes().to_vec())),
        ("file length", (16, u64::MAX.to_le_bytes().to_vec())),
        (
            "section offset",
            (tinf_e + 8, (u64::MAX - 7).to_le_bytes().to_vec()),
        ),
        (
            "section length",
            (tinf_e + 16, u64::MAX.to_le_bytes().to_vec()),
        ),
        ("tensor count", (tinf, u32::MAX.to_le_bytes().to_vec())),
        ("joint count", (skel, u32::MAX.to_le_bytes().to_vec())),
        ("names_len", (skel + 4, u32::MAX.to_le_bytes().to_vec())),
        (
            "tensor dims",
            (
                w + 32,
                [u32::MAX.to_le_bytes(), (u32::MAX - 1).to_le_bytes()].concat(),
            ),
        ),
        (
            "tensor offset",
            (w + 48, (u64::MAX - 63).to_le_bytes().to_vec()),
        ),
        (
            "tensor nbytes",
            (w + 56, (u64::MAX - 1).to_le_bytes().to_vec()),
        ),
    ];
    for (what, (at, bytes)) in cases {
        let e = parse_err(&patched(&b, |b| put(b, at, &bytes)));
        let expected = match what {
            "section count" => matches!(e, SkfError::SectionCount(u32::MAX)),
            "file length" => matches!(e, SkfError::TooLarge(u64::MAX)),
            "section offset" | "section length" => matches!(e, SkfError::SectionOutOfBounds { .. }),
            "tensor count" => matches!(e, SkfError::TensorCount(u32::MAX)),
            "joint count" => matches!(e, SkfError::JointCount { skel: u32::MAX, .. }),
            "names_len" => matches!(e, SkfError::SectionLength { .. }),
            "tensor dims" | "tensor nbytes" => matches!(e, SkfError::ByteSize(_)),
            _ => matches!(e, SkfError::TensorPlacement(_)),
        };
        assert!(expected, "{what}: {e}");
    }
}

/// Not a check: writes seed inputs for `cargo fuzz run skf` into `$SKINFIELD_FUZZ_SEEDS/skf`
/// (`SKINFIELD_FUZZ_SEEDS=/tmp/seeds cargo test --workspace --test skf_bytes -- --ignored`).
#[test]
#[ignore = "writes fuzz seeds when SKINFIELD_FUZZ_SEEDS is set"]
fn write_fuzz_seeds() {
    let Some(dir) = std::env::var_os("SKINFIELD_FUZZ_SEEDS") else {
        return;
    };
    let dir = std::path::PathBuf::from(dir).join("skf");
    std::fs::create_dir_all(&dir).unwrap();
    let (_, small) = small();
    std::fs::write(dir.join("small.skf"), &small).unwrap();
    // 24 joints and all three nets, with narrow layers so the file stays a few kilobytes.
    let mut c = small_config();
    c.joint_count = 24;
    c.hidden[..2].copy_from_slice(&[4, 4]);
    c.nets = Net::Skin.bit() | Net::Albedo.bit() | Net::Shadow.bit();
    let mut m = model(c, 5);
    for net in [Net::Albedo, Net::Shadow] {
        let shapes: Vec<(usize, usize)> = c.layer_shapes(net).collect();
        for (i, (out, inp)) in shapes.into_iter().enumerate() {
            m.push_layer(net, i, vec![0.25; out * inp], out, inp, vec![-0.5; out]);
        }
    }
    let bytes = m.to_bytes().unwrap();
    SkfView::parse(&bytes).unwrap();
    std::fs::write(dir.join("three_nets.skf"), &bytes).unwrap();
    std::fs::write(
        dir.join("candidates.skf"),
        with_candidates().to_bytes().unwrap(),
    )
    .unwrap();
    std::fs::write(
        dir.join("pose_range.skf"),
        with_pose_range().to_bytes().unwrap(),
    )
    .unwrap();
}
