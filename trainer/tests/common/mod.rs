//! What the command-line integration tests share.

use std::process::Command;

/// Runs the `trainer` binary with `args`: exit code (-1 when killed), stdout, stderr.
pub fn trainer(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `trainer synth` of a small built-in capture into `out` (`train_frames` training frames, one
/// test frame), plus `extra`.
// Each test crate compiles this module on its own; not every one synthesises.
#[allow(dead_code)]
pub fn tiny_synth(out: &str, train_frames: &str, extra: &[&str]) -> (i32, String, String) {
    let mut args = vec![
        "synth",
        "--out",
        out,
        "--grid",
        "40",
        "--vertices",
        "2500",
        "--train-frames",
        train_frames,
        "--test-frames",
        "1",
    ];
    args.extend_from_slice(extra);
    trainer(&args)
}

/// `trainer train` of `capture` into `out` with the configuration file `config`, writing the
/// model even when the guard would refuse it (these captures are too small to learn), plus
/// `extra`.
// Each test crate compiles this module on its own; not every one trains.
#[allow(dead_code)]
pub fn train(capture: &str, out: &str, config: &str, extra: &[&str]) -> (i32, String, String) {
    let mut args = vec![
        "train",
        "--capture",
        capture,
        "--out",
        out,
        "--config",
        config,
        "--allow-worse",
        "--quiet",
    ];
    args.extend_from_slice(extra);
    trainer(&args)
}

/// A tiny built-in capture of 4 cameras at 48² with `train_frames` training frames, synthesised
/// into `DIR/cap`; returns its folder.
// Each test crate compiles this module on its own; not every one synthesises.
#[allow(dead_code)]
pub fn four_camera_capture(dir: &std::path::Path, train_frames: &str) -> std::path::PathBuf {
    let cap = dir.join("cap");
    let (code, _, err) = tiny_synth(
        cap.to_str().unwrap(),
        train_frames,
        &["--cameras", "4", "--resolution", "48"],
    );
    assert_eq!(code, 0, "{err}");
    cap
}
