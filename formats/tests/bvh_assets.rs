//! BVH import: an analytic clip whose world positions are worked out by hand, an independent
//! f64 forward-kinematics reference, malformed input (one test per error), every truncated
//! prefix, and every CMU clip in the shared data checked against its `SOURCE.md`.

use glam::{Mat4, Vec3};
use skinfield_formats::bvh::{
    BvhChannel, BvhError, BvhMotion, BvhOptions, CMU_UNIT_TO_METRES, MAX_CHANNELS_PER_JOINT,
    load_bvh, load_bvh_with, parse_bvh,
};
use skinfield_formats::shared_data::shared_data_dir;
use skinfield_formats::{Axis, JointDofs, SkeletonError};

/// Hips (ZXY, with position) → Spine (XYZ) → Head (YXZ) → End Site, and a zero-length Leg (ZYX)
/// on the root with its own End Site. Orders differ per joint on purpose.
const ANALYTIC: &str = "HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    JOINT Head
    {
      OFFSET 0 5 0
      CHANNELS 3 Yrotation Xrotation Zrotation
      End Site
      {
        OFFSET 0 2 0
      }
    }
  }
  JOINT Leg
  {
    OFFSET 0 0 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 3 0 0
    }
  }
}
MOTION
Frames: 4
Frame Time: 0.04
0 0 0 0 0 0 0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 90 0 0 0 0 0 0 0 0
-4 5 0.5 90 90 0 0 90 90 0 0 0 0 90 90
0.5 -1.25 2 30 -45 60 -20 35 110 15 -70 25 40 -65 80
";

/// World positions of the joints then the End Sites, frame `f`.
fn world_points(m: &BvhMotion, f: usize) -> Vec<Vec3> {
    let mut w = vec![Mat4::IDENTITY; m.skeleton.len()];
    m.skeleton.world_matrices(&m.poses[f], &mut w).unwrap();
    let joints = w.iter().map(|w| w.transform_point3(Vec3::ZERO));
    let ends = m
        .end_sites
        .iter()
        .map(|e| w[e.parent].transform_point3(e.offset));
    joints.chain(ends).collect()
}

fn assert_points(got: &[Vec3], want: &[[f32; 3]], tol: f32, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (*g - Vec3::from_array(*w)).length() < tol,
            "{what} point {i}: got {g}, want {w:?}"
        );
    }
}

#[test]
fn analytic_clip_has_hand_computed_world_positions() {
    let m = parse_bvh(ANALYTIC, &BvhOptions::default()).unwrap();
    assert_eq!(m.skeleton.names(), ["Hips", "Spine", "Head", "Leg"]);
    assert_eq!(m.skeleton.parents(), [None, Some(0), Some(1), Some(0)]);
    assert_eq!(m.frame_count(), 4);
    assert_eq!(m.channel_count(), 15);
    assert!((m.frame_time - 0.04).abs() < 1e-9 && (m.duration_s() - 0.16).abs() < 1e-6);
    assert_eq!(m.end_sites.len(), 2);
    assert_eq!((m.end_sites[0].parent, m.end_sites[1].parent), (2, 3));
    let axes = |j: usize| match &m.skeleton.dofs()[j] {
        JointDofs::Euler { axes, .. } => axes.clone(),
        other => panic!("joint {j}: {other:?}"),
    };
    use Axis::{X, Y, Z};
    assert_eq!(
        [axes(0), axes(1), axes(2), axes(3)],
        [vec![Z, X, Y], vec![X, Y, Z], vec![Y, X, Z], vec![Z, Y, X]]
    );
    assert_eq!(
        m.channels[0][..3],
        [
            BvhChannel::Xposition,
            BvhChannel::Yposition,
            BvhChannel::Zposition
        ]
    );
    for t in m.skeleton.bind_local() {
        assert_eq!(t.rotation, glam::Quat::IDENTITY);
    }
    assert_eq!(m.frame_values(1).unwrap()[..4], [1.0, 2.0, 3.0, 90.0]);

    // Points: Hips, Spine, Head, Leg, Head's End Site, Leg's End Site.
    // Frame 0: the bind pose, offsets summed.
    assert_points(
        &world_points(&m, 0),
        &[
            [0., 0., 0.],
            [0., 10., 0.],
            [0., 15., 0.],
            [0., 0., 0.],
            [0., 17., 0.],
            [3., 0., 0.],
        ],
        1e-5,
        "frame 0",
    );
    // Frame 1: root at (1,2,3) turned Rz(90°) (+Y → −X): Spine = (1,2,3) + (−10,0,0).
    // Spine Rx(90°) sends +Y to +Z, then Rz(90°) keeps Z: Head = Spine + (0,0,5), tip (0,0,7).
    // Leg: zero length, at the root; its tip (3,0,0) turns to (0,3,0).
    assert_points(
        &world_points(&m, 1),
        &[
            [1., 2., 3.],
            [-9., 2., 3.],
            [-9., 2., 8.],
            [1., 2., 3.],
            [-9., 2., 10.],
            [1., 5., 3.],
        ],
        1e-4,
        "frame 1",
    );
    // Frame 2: root R = Rz(90)·Rx(90) (channel order Z, X, Y). Spine offset (0,10,0):
    // Rx → (0,0,10), Rz keeps it. (The reverse order would give (−10,0,0).)
    // Spine R = Rx(0)·Ry(90)·Rz(90): (0,5,0) → Rz → (−5,0,0) → Ry → (0,0,5); root R: Rx → (0,−5,0),
    // Rz → (5,0,0). Head tip (0,2,0) → (2,0,0) the same way.
    // Leg R = Rz(0)·Ry(90)·Rx(90): (3,0,0) → Rx keeps → Ry → (0,0,−3); root: Rx → (0,3,0), Rz → (−3,0,0).
    assert_points(
        &world_points(&m, 2),
        &[
            [-4., 5., 0.5],
            [-4., 5., 10.5],
            [1., 5., 10.5],
            [-4., 5., 0.5],
            [3., 5., 10.5],
            [-7., 5., 0.5],
        ],
        1e-4,
        "frame 2",
    );

    // Unit scale multiplies every length and nothing else.
    let half = parse_bvh(ANALYTIC, &BvhOptions { unit_scale: 0.5 }).unwrap();
    for f in 0..4 {
        let (a, b) = (world_points(&m, f), world_points(&half, f));
        for (a, b) in a.iter().zip(&b) {
            assert!((*a * 0.5 - *b).length() < 1e-4, "frame {f}: {a} vs {b}");
        }
    }
}

/// An independent forward kinematics in f64 with explicit rotation matrices.
fn reference_points(values: &[f64]) -> Vec<[f64; 3]> {
    type M = [[f64; 3]; 3];
    fn rot(axis: char, deg: f64) -> M {
        let (s, c) = deg.to_radians().sin_cos();
        match axis {
            'X' => [[1., 0., 0.], [0., c, -s], [0., s, c]],
            'Y' => [[c, 0., s], [0., 1., 0.], [-s, 0., c]],
            _ => [[c, -s, 0.], [s, c, 0.], [0., 0., 1.]],
        }
    }
    fn mul(a: &M, b: &M) -> M {
        let mut r = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                r[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        r
    }
    fn apply(a: &M, v: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|i| a[i][0] * v[0] + a[i][1] * v[1] + a[i][2] * v[2])
    }
    fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
        [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }
    let euler = |order: &str, v: &[f64]| {
        let mut r = rot('X', 0.0);
        for (axis, deg) in order.chars().zip(v) {
            r = mul(&r, &rot(axis, *deg));
        }
        r
    };
    let hips_p = [values[0], values[1], values[2]];
    let hips_r = euler("ZXY", &values[3..6]);
    let spine_r = mul(&hips_r, &euler("XYZ", &values[6..9]));
    let head_r = mul(&spine_r, &euler("YXZ", &values[9..12]));
    let leg_r = mul(&hips_r, &euler("ZYX", &values[12..15]));
    let spine_p = add(hips_p, apply(&hips_r, [0., 10., 0.]));
    let head_p = add(spine_p, apply(&spine_r, [0., 5., 0.]));
    let tip = add(head_p, apply(&head_r, [0., 2., 0.]));
    let leg_tip = add(hips_p, apply(&leg_r, [3., 0., 0.]));
    vec![hips_p, spine_p, head_p, hips_p, tip, leg_tip]
}

#[test]
fn every_frame_matches_an_independent_f64_reference() {
    let m = parse_bvh(ANALYTIC, &BvhOptions::default()).unwrap();
    for f in 0..m.frame_count() {
        let values: Vec<f64> = m
            .frame_values(f)
            .unwrap()
            .iter()
            .map(|&v| f64::from(v))
            .collect();
        let want: Vec<[f32; 3]> = reference_points(&values)
            .iter()
            .map(|p| p.map(|x| x as f32))
            .collect();
        assert_points(&world_points(&m, f), &want, 1e-4, &format!("frame {f}"));
    }
}

fn err(text: &str) -> BvhError {
    parse_bvh(text, &BvhOptions::default()).expect_err("expected an error")
}

/// 1-based line of the first occurrence of `needle` in `text`.
fn line_of(text: &str, needle: &str) -> usize {
    1 + text[..text.find(needle).unwrap()].matches('\n').count()
}

/// The line an error names.
fn line(e: &BvhError) -> usize {
    use BvhError as E;
    match e {
        E::UnexpectedEof { line, .. }
        | E::Unexpected { line, .. }
        | E::BadNumber { line, .. }
        | E::NonFinite { line, .. }
        | E::ChannelCount { line, .. }
        | E::UnknownChannel { line, .. }
        | E::DuplicateChannel { line, .. }
        | E::DuplicateField { line, .. }
        | E::MissingOffset { line, .. }
        | E::TooMany { line, .. }
        | E::TooManyFrames { line, .. }
        | E::FramesExceedData { line, .. }
        | E::BadFrameTime { line, .. }
        | E::FrameChannelCount { line, .. }
        | E::BadChannelValue { line, .. }
        | E::NonFiniteTranslation { line, .. }
        | E::MissingFrames { line, .. }
        | E::TrailingData { line, .. } => *line,
        other => panic!("no line in {other:?}"),
    }
}

/// The hierarchy part of [`ANALYTIC`] (up to `MOTION`).
fn hierarchy_part() -> &'static str {
    &ANALYTIC[..ANALYTIC.find("MOTION").unwrap()]
}

/// The frame lines of [`ANALYTIC`], as tokens.
fn frame_tokens() -> Vec<Vec<String>> {
    let lines: Vec<&str> = ANALYTIC.lines().collect();
    let first = lines
        .iter()
        .position(|l| l.starts_with("Frame Time"))
        .unwrap()
        + 1;
    lines[first..]
        .iter()
        .map(|l| l.split_whitespace().map(str::to_owned).collect())
        .collect()
}

/// A clip from a hierarchy, a header and frame lines.
fn clip(hierarchy: &str, frames: &str, time: &str, lines: &[Vec<String>], newline: &str) -> String {
    let body: Vec<String> = lines.iter().map(|l| l.join(" ")).collect();
    format!(
        "{hierarchy}MOTION{newline}Frames: {frames}{newline}Frame Time: {time}{newline}{}{newline}",
        body.join(newline)
    )
}

#[test]
fn malformed_hierarchies_give_typed_errors_with_lines() {
    let spine_offset = "    OFFSET 0 10 0";
    let l = line_of(ANALYTIC, spine_offset);
    let one = |with: &str| ANALYTIC.replacen(spine_offset, with, 1);
    let e = err(&one("    OFFSET 0 1x 0"));
    assert!(
        matches!(&e, BvhError::BadNumber { field: "OFFSET", text, .. } if text == "1x")
            && line(&e) == l,
        "{e}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains(&format!("line {l}")) && msg.contains("OFFSET") && msg.contains("1x"),
        "{msg}"
    );
    let e = err(&one("    OFFSET 0 nan 0"));
    assert!(
        matches!(
            e,
            BvhError::NonFinite {
                field: "OFFSET",
                ..
            }
        ) && line(&e) == l,
        "{e}"
    );
    assert!(matches!(
        err(&one("    OFFSET 0 1e39 0")),
        BvhError::NonFinite { .. }
    ));
    // Two numbers only: the CHANNELS keyword on the next line is read as the third.
    let e = err(&one("    OFFSET 0 10"));
    assert!(
        matches!(&e, BvhError::BadNumber { text, .. } if text == "CHANNELS") && line(&e) == l + 1,
        "{e}"
    );
    // No OFFSET: reported at the joint's closing brace.
    let e = err(&one(""));
    assert!(
        matches!(&e, BvhError::MissingOffset { joint, .. } if joint == "Spine"),
        "{e}"
    );
    assert_eq!(line(&e), line_of(ANALYTIC, "  }\n  JOINT Leg"));
    let e = err(&one("OFFSET 0 10 0 OFFSET 0 1 0"));
    assert!(
        matches!(
            e,
            BvhError::DuplicateField {
                field: "OFFSET",
                ..
            }
        ) && line(&e) == l,
        "{e}"
    );
    let e = err(&ANALYTIC.replacen("      OFFSET 0 2 0", "OFFSET 0 2 0 OFFSET 1 1 1", 1));
    assert!(
        matches!(&e, BvhError::DuplicateField { joint, .. } if joint == "End Site"),
        "{e}"
    );
    let e = err(&ANALYTIC.replacen("      OFFSET 0 2 0", "", 1));
    assert!(
        matches!(&e, BvhError::MissingOffset { joint, .. } if joint == "End Site"),
        "{e}"
    );

    let spine_channels = "    CHANNELS 3 Xrotation Yrotation Zrotation";
    let l = line_of(ANALYTIC, spine_channels);
    let chans = |with: &str| ANALYTIC.replacen(spine_channels, with, 1);
    let e = err(&chans("CHANNELS 4294967296 Xrotation"));
    assert!(
        matches!(&e, BvhError::ChannelCount { count: 4294967296, joint, .. } if joint == "Spine")
            && line(&e) == l
    );
    assert!(matches!(
        err(&chans("CHANNELS 7 Xrotation")),
        BvhError::ChannelCount { count: 7, .. }
    ));
    assert_eq!(MAX_CHANNELS_PER_JOINT, 6);
    assert!(matches!(
        err(&chans("CHANNELS -1")),
        BvhError::BadNumber {
            field: "CHANNELS",
            ..
        }
    ));
    let e = err(&chans("CHANNELS 3 Xrotation Wrotation Zrotation"));
    assert!(
        matches!(&e, BvhError::UnknownChannel { found, .. } if found == "Wrotation")
            && line(&e) == l
    );
    let e = err(&chans("CHANNELS 3 Xrotation Zrotation xROTATION"));
    assert!(
        matches!(
            e,
            BvhError::DuplicateChannel {
                channel: BvhChannel::Xrotation,
                ..
            }
        ),
        "{e}"
    );
    let e = err(&chans(
        "CHANNELS 3 Xrotation Yrotation Zrotation CHANNELS 0",
    ));
    assert!(
        matches!(
            e,
            BvhError::DuplicateField {
                field: "CHANNELS",
                ..
            }
        ),
        "{e}"
    );
    let e = err(&ANALYTIC.replace("JOINT Head", "JOINT Hips"));
    assert!(
        matches!(e, BvhError::Skeleton(SkeletonError::DuplicateName(ref n)) if n == "Hips"),
        "{e}"
    );
    let e = err(&ANALYTIC.replace("JOINT Head", "JIONT Head"));
    assert!(
        matches!(e, BvhError::Unexpected { .. }) && line(&e) == line_of(ANALYTIC, "JOINT Head"),
        "{e}"
    );
    let e = err(&ANALYTIC.replace("JOINT Head", "JOINT {"));
    assert!(
        matches!(
            e,
            BvhError::Unexpected {
                expected: "joint name",
                ..
            }
        ),
        "{e}"
    );
    let e = err(&ANALYTIC.replacen("      OFFSET 0 2 0", "JOINT Tip { OFFSET 0 0 0 }", 1));
    assert!(
        matches!(
            e,
            BvhError::Unexpected {
                expected: "OFFSET or }",
                ..
            }
        ),
        "{e}"
    );
    let e = err("HIERARCHY\nMOTION\n");
    assert!(
        matches!(
            e,
            BvhError::Unexpected {
                expected: "ROOT",
                ..
            }
        ) && line(&e) == 2,
        "{e}"
    );
    assert!(matches!(
        err(""),
        BvhError::UnexpectedEof {
            line: 1,
            expected: "HIERARCHY"
        }
    ));
    assert!(matches!(
        parse_bvh(ANALYTIC, &BvhOptions { unit_scale: 0.0 }),
        Err(BvhError::BadUnitScale(_))
    ));
    assert!(matches!(
        parse_bvh(
            ANALYTIC,
            &BvhOptions {
                unit_scale: f32::NAN
            }
        ),
        Err(BvhError::BadUnitScale(_))
    ));
}

#[test]
fn malformed_motion_gives_typed_errors_with_lines() {
    let frames = frame_tokens();
    let motion = |count: &str, time: &str, lines: &[Vec<String>]| {
        clip(hierarchy_part(), count, time, lines, "\n")
    };
    let text = motion("4", "0.04", &frames);
    assert_eq!(
        parse_bvh(&text, &BvhOptions::default()).unwrap(),
        parse_bvh(ANALYTIC, &BvhOptions::default()).unwrap()
    );
    let count_line = line_of(&text, "Frames:");
    let time_line = count_line + 1;
    let frame_line = |f: usize| time_line + 1 + f;
    let at = |e: &BvhError, l: usize| assert_eq!(line(e), l, "{e}");

    let e = err(&motion("99999999999999999999", "0.04", &frames));
    assert!(
        matches!(
            e,
            BvhError::BadNumber {
                field: "Frames",
                ..
            }
        ),
        "{e}"
    );
    at(&e, count_line);
    let e = err(&motion("18446744073709551615", "0.04", &frames));
    assert!(matches!(e, BvhError::TooManyFrames { .. }), "{e}");
    at(&e, count_line);
    assert!(matches!(
        err(&motion("1048577", "0.04", &frames)),
        BvhError::TooManyFrames { .. }
    ));
    // Within the caps but not within the bytes present: refused before allocating.
    let e = err(&motion("1000", "0.04", &frames));
    assert!(
        matches!(
            e,
            BvhError::FramesExceedData {
                frames: 1000,
                channels: 15,
                ..
            }
        ),
        "{e}"
    );
    at(&e, time_line);
    let e = err(&motion("5", "0.04", &frames));
    assert!(
        matches!(
            e,
            BvhError::MissingFrames {
                expected: 5,
                found: 4,
                ..
            }
        ),
        "{e}"
    );
    let e = err(&motion("3", "0.04", &frames));
    assert!(matches!(e, BvhError::TrailingData { frames: 3, .. }), "{e}");
    at(&e, frame_line(3));
    for bad in ["0", "-1", "NaN", "inf"] {
        let e = err(&motion("4", bad, &frames));
        assert!(matches!(e, BvhError::BadFrameTime { .. }), "{e}");
        at(&e, time_line);
    }
    assert!(matches!(
        err(&motion("4", "fast", &frames)),
        BvhError::BadNumber {
            field: "Frame Time",
            ..
        }
    ));
    assert!(matches!(
        err(&motion("four", "0.04", &frames)),
        BvhError::BadNumber {
            field: "Frames",
            ..
        }
    ));
    assert!(matches!(
        err(&motion("4", "0.04", &frames).replace("Frame Time", "Frame Rate")),
        BvhError::Unexpected { .. }
    ));

    let mut short = frames.clone();
    short[2].pop();
    let e = err(&motion("4", "0.04", &short));
    assert!(
        matches!(
            e,
            BvhError::FrameChannelCount {
                frame: 2,
                expected: 15,
                found: 14,
                ..
            }
        ),
        "{e}"
    );
    at(&e, frame_line(2));
    let mut long = frames.clone();
    long[1].push("0".into());
    let e = err(&motion("4", "0.04", &long));
    assert!(
        matches!(
            e,
            BvhError::FrameChannelCount {
                frame: 1,
                found: 16,
                ..
            }
        ),
        "{e}"
    );
    at(&e, frame_line(1));
    // Value 7 is the Spine's second channel.
    for bad in ["NaN", "inf", "-infinity", "1e39", "1,5", "0x10"] {
        let mut f = frames.clone();
        f[1][7] = bad.into();
        let e = err(&motion("4", "0.04", &f));
        assert!(
            matches!(&e, BvhError::BadChannelValue { frame: 1, joint, channel: BvhChannel::Yrotation, .. } if joint == "Spine"),
            "{bad}: {e}"
        );
        at(&e, frame_line(1));
    }
    // A finite value whose scaled translation overflows.
    let mut big = frames.clone();
    big[0][0] = "3e38".into();
    let e = parse_bvh(&motion("4", "0.04", &big), &BvhOptions { unit_scale: 10.0 }).unwrap_err();
    assert!(
        matches!(e, BvhError::NonFiniteTranslation { frame: 0, .. }),
        "{e}"
    );
    at(&e, frame_line(0));
}

#[test]
fn absurd_joint_and_end_site_counts_are_capped() {
    let mut text = String::from("HIERARCHY\n");
    for i in 0..1100 {
        text.push_str(&format!(
            "{} j{i} {{ OFFSET 0 1 0 CHANNELS 1 Xrotation\n",
            if i == 0 { "ROOT" } else { "JOINT" }
        ));
    }
    let e = err(&text);
    assert!(
        matches!(
            e,
            BvhError::TooMany {
                what: "joints",
                max: 1024,
                ..
            }
        ),
        "{e}"
    );
    assert_eq!(line(&e), 1026);
    let mut text = String::from("HIERARCHY\nROOT r { OFFSET 0 0 0\n");
    text.push_str(&"End Site { OFFSET 0 1 0 }\n".repeat(1100));
    assert!(matches!(
        err(&text),
        BvhError::TooMany {
            what: "End Sites",
            max: 1024,
            ..
        }
    ));
}

#[test]
fn layout_variants_parse_the_same() {
    let reference = parse_bvh(ANALYTIC, &BvhOptions::default()).unwrap();
    let frames = frame_tokens();
    // The whole hierarchy on one line, lower-case keywords, `Frames :` split, CRLF, no final
    // newline.
    let flat = hierarchy_part()
        .replace('\n', " ")
        .replace("HIERARCHY", "hierarchy")
        .replace("OFFSET", "offset");
    let text = clip(&flat, "4", "0.04", &frames, "\r\n")
        .replace("Frames:", "Frames :")
        .replace("MOTION", "motion");
    assert_eq!(
        parse_bvh(text.trim_end(), &BvhOptions::default()).unwrap(),
        reference
    );

    // A second root, with one channel of its own.
    let two_roots = format!(
        "{}ROOT Other {{ OFFSET 1 0 0 CHANNELS 1 Yrotation }}\n",
        hierarchy_part()
    );
    let mut f = frames.clone();
    for l in &mut f {
        l.push("90".into());
    }
    let m = parse_bvh(
        &clip(&two_roots, "4", "0.04", &f, "\n"),
        &BvhOptions::default(),
    )
    .unwrap();
    assert_eq!((m.skeleton.len(), m.skeleton.parents()[4]), (5, None));
    for (p, r) in m.poses.iter().zip(&reference.poses) {
        assert_eq!(p.locals[..4], r.locals[..4]);
        assert_eq!(p.locals[4].translation, Vec3::X);
        assert!(
            p.locals[4]
                .rotation
                .angle_between(glam::Quat::from_rotation_y(90f32.to_radians()))
                < 1e-6
        );
    }

    // A joint without CHANNELS is Fixed and keeps its bind pose.
    let fixed = hierarchy_part().replacen("    CHANNELS 3 Xrotation Yrotation Zrotation\n", "", 1);
    let mut f = frames.clone();
    for l in &mut f {
        l.drain(6..9);
    }
    let m = parse_bvh(&clip(&fixed, "4", "0.04", &f, "\n"), &BvhOptions::default()).unwrap();
    assert_eq!(m.skeleton.dofs()[1], JointDofs::Fixed);
    assert!(m.channels[1].is_empty());
    assert!(
        m.poses
            .iter()
            .all(|p| p.locals[1] == m.skeleton.bind_local()[1])
    );
    assert_eq!(m.poses[3].locals[2], reference.poses[3].locals[2]);

    // No channels at all: every frame is the bind pose.
    let none = hierarchy_part()
        .lines()
        .filter(|l| !l.contains("CHANNELS"))
        .collect::<Vec<_>>()
        .join("\n");
    let m = parse_bvh(
        &format!("{none}\nMOTION\nFrames: 3\nFrame Time: 1\n\n\n\n"),
        &BvhOptions::default(),
    )
    .unwrap();
    assert_eq!((m.frame_count(), m.channel_count()), (3, 0));
    assert!(m.poses.iter().all(|p| *p == m.skeleton.bind_pose()));
    assert!(matches!(
        err(&format!("{none}\nMOTION\nFrames: 3\nFrame Time: 1\n\n")),
        BvhError::FramesExceedData { .. }
    ));
}

#[test]
fn every_truncated_prefix_errors_or_parses_a_consistent_clip() {
    let full = parse_bvh(ANALYTIC, &BvhOptions::default()).unwrap();
    let mut ok = 0;
    for cut in 0..ANALYTIC.len() {
        match parse_bvh(&ANALYTIC[..cut], &BvhOptions::default()) {
            Err(_) => {}
            Ok(m) => {
                // Only a cut inside the last number can still parse: same skeleton, same frames
                // but possibly the last value.
                ok += 1;
                assert_eq!(m.skeleton, full.skeleton, "cut {cut}");
                assert_eq!(m.frame_count(), 4, "cut {cut}");
                assert_eq!(m.poses[..3], full.poses[..3], "cut {cut}");
                assert_eq!(m.values[..59], full.values[..59], "cut {cut}");
            }
        }
    }
    // The text ends in "80\n": cutting the newline or the "0" still parses.
    assert_eq!(ok, 2);
}

#[test]
fn load_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.bvh");
    let e = load_bvh(&missing).unwrap_err();
    assert!(
        matches!(e, BvhError::Io { .. }) && e.to_string().contains("missing.bvh"),
        "{e}"
    );
    let bad = dir.path().join("bad.bvh");
    std::fs::write(&bad, ANALYTIC.replace("Frame Time: 0.04", "Frame Time: -1")).unwrap();
    let e = load_bvh(&bad).unwrap_err();
    assert!(
        matches!(&e, BvhError::File { source, .. } if matches!(**source, BvhError::BadFrameTime { .. }))
    );
    assert!(
        e.to_string().contains("bad.bvh") && e.to_string().contains("line 32"),
        "{e}"
    );
    let good = dir.path().join("good.bvh");
    std::fs::write(&good, ANALYTIC).unwrap();
    assert_eq!(
        load_bvh_with(&good, &BvhOptions { unit_scale: 2.0 }).unwrap(),
        parse_bvh(ANALYTIC, &BvhOptions { unit_scale: 2.0 }).unwrap()
    );
}

/// `SOURCE.md`'s verified table: file, root, joints (End Sites excluded), channels, frames,
/// frame time; End Sites counted with `grep -c "End Site"`.
const CMU: [(&str, &str, usize, usize, usize, f32, usize); 5] = [
    ("131_01.bvh", "Hips", 31, 96, 994, 0.008_333_3, 7),
    ("131_03.bvh", "Hips", 31, 96, 1102, 0.008_333_3, 7),
    ("02_01.bvh", "Hips", 31, 96, 343, 0.008_333, 7),
    ("pirouette.bvh", "hip", 43, 132, 592, 0.008_333_33, 14),
    ("jumping_jacks.bvh", "Hips", 31, 96, 125, 0.033_33, 7),
];

fn euler_orders(m: &BvhMotion) -> Vec<String> {
    m.skeleton
        .dofs()
        .iter()
        .map(|d| match d {
            JointDofs::Euler { axes, .. } => axes.iter().map(|a| format!("{a:?}")).collect(),
            other => format!("{other:?}"),
        })
        .collect()
}

#[test]
fn cmu_clips_match_their_source_md() {
    let Some(data) = shared_data_dir() else {
        return;
    };
    for (file, root, joints, channels, frames, frame_time, end_sites) in CMU {
        let path = data.join("mocap-cmu").join(file);
        let m = load_bvh_with(
            &path,
            &BvhOptions {
                unit_scale: CMU_UNIT_TO_METRES,
            },
        )
        .unwrap();
        assert_eq!(m.skeleton.names()[0], root, "{file}");
        assert_eq!(m.skeleton.len(), joints, "{file}");
        assert_eq!(m.channel_count(), channels, "{file}");
        assert_eq!(m.frame_count(), frames, "{file}");
        assert_eq!(m.frame_time, frame_time, "{file}");
        assert_eq!(m.end_sites.len(), end_sites, "{file}");
        assert_eq!(m.values.len(), frames * channels, "{file}");

        // The last frame as the test reads it from the text itself.
        let text = std::fs::read_to_string(&path).unwrap();
        let last: Vec<f32> = text
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap()
            .split_whitespace()
            .map(|t| t.parse().unwrap())
            .collect();
        assert_eq!(m.frame_values(frames - 1).unwrap(), &last[..], "{file}");

        let orders = euler_orders(&m);
        let count = |o: &str| orders.iter().filter(|x| *x == o).count();
        if file == "pirouette.bvh" {
            // Root ZYX, every other joint ZXY.
            assert_eq!((orders[0].as_str(), count("ZXY")), ("ZYX", 42), "{file}");
        } else if file.starts_with("131") || file == "jumping_jacks.bvh" {
            // 12 joints ZXY and 18 ZYX besides the root (ZYX).
            assert_eq!((count("ZXY"), count("ZYX")), (12, 19), "{file}");
        }
        if root == "Hips" {
            // CMU's zero-length joints.
            let lhip = m.skeleton.find("LHipJoint").unwrap();
            assert_eq!(
                m.skeleton.bind_local()[lhip].translation,
                Vec3::ZERO,
                "{file}"
            );
        }
    }
}

/// Lowest and highest point (joints and End Sites) of frame `f`, metres.
fn vertical_extent(m: &BvhMotion, w: &mut [Mat4], f: usize) -> (f32, f32) {
    m.skeleton.world_matrices(&m.poses[f], w).unwrap();
    let joints = w.iter().map(|w| w.transform_point3(Vec3::ZERO).y);
    let ends = m
        .end_sites
        .iter()
        .map(|e| w[e.parent].transform_point3(e.offset).y);
    joints
        .chain(ends)
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), y| {
            (lo.min(y), hi.max(y))
        })
}

#[test]
fn cmu_clips_in_metres_stay_on_the_ground_and_keep_their_bones() {
    let Some(data) = shared_data_dir() else {
        return;
    };
    // (file, unit scale, largest spread of the lowest point over the clip, body height range).
    // Measured: 131_01 (a dance on the spot) floor spread 0.10 m, pirouette 0.17 m; composing
    // the Euler angles in reverse order makes the feet leave the floor (0.66 m and 0.71 m).
    // pirouette is in centimetres (its standing height is ≈ 175 units), the CMU conversions in
    // CMU units.
    let cases = [
        ("131_01.bvh", CMU_UNIT_TO_METRES, 0.15, 0.7..1.6),
        (
            "pirouette.bvh",
            skinfield_formats::bvh::CENTIMETRES_TO_METRES,
            0.25,
            1.1..1.9,
        ),
    ];
    for (file, unit_scale, max_spread, heights) in cases {
        let m = load_bvh_with(
            data.join("mocap-cmu").join(file),
            &BvhOptions { unit_scale },
        )
        .unwrap();
        let mut w = vec![Mat4::IDENTITY; m.skeleton.len()];
        let (mut lowest, mut highest) = (f32::INFINITY, f32::NEG_INFINITY);
        for f in 0..m.frame_count() {
            let (floor, top) = vertical_extent(&m, &mut w, f);
            lowest = lowest.min(floor);
            highest = highest.max(floor);
            assert!(
                heights.contains(&(top - floor)),
                "{file} frame {f}: body height {}",
                top - floor
            );
            // Bone lengths are the OFFSET lengths in every frame.
            for (j, parent) in m.skeleton.parents().iter().enumerate() {
                if let Some(parent) = *parent {
                    let len = w[j].w_axis.truncate().distance(w[parent].w_axis.truncate());
                    let want = m.skeleton.bind_local()[j].translation.length();
                    assert!(
                        (len - want).abs() < 1e-4,
                        "{file} frame {f} joint {j}: {len} vs {want}"
                    );
                }
            }
        }
        assert!(
            highest - lowest < max_spread,
            "{file}: the lowest point moves by {} m",
            highest - lowest
        );
    }
}

/// Not a check: writes seed inputs for `cargo fuzz run bvh` into `$SKINFIELD_FUZZ_SEEDS/bvh`:
/// the analytic clip and the hierarchy plus two frames of each CMU clip
/// (`SKINFIELD_FUZZ_SEEDS=/tmp/seeds cargo test --workspace --test bvh_assets -- --ignored`).
#[test]
#[ignore = "writes fuzz seeds when SKINFIELD_FUZZ_SEEDS is set"]
fn write_fuzz_seeds() {
    let Some(dir) = std::env::var_os("SKINFIELD_FUZZ_SEEDS") else {
        return;
    };
    let dir = std::path::PathBuf::from(dir).join("bvh");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("analytic.bvh"), ANALYTIC).unwrap();
    let Some(data) = shared_data_dir() else {
        return;
    };
    for (file, ..) in CMU {
        let text = std::fs::read_to_string(data.join("mocap-cmu").join(file)).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let time = lines
            .iter()
            .position(|l| l.trim_start().starts_with("Frame Time"))
            .unwrap();
        let motion = lines.iter().position(|l| l.trim() == "MOTION").unwrap();
        let head = lines[..motion].join("\n");
        let seed = format!(
            "{head}\nMOTION\nFrames: 2\n{}\n{}\n{}\n",
            lines[time],
            lines[time + 1],
            lines[time + 2]
        );
        assert_eq!(
            parse_bvh(&seed, &BvhOptions::default())
                .unwrap()
                .frame_count(),
            2
        );
        std::fs::write(dir.join(file), seed).unwrap();
    }
}
