//! Helpers shared by the C ABI's integration tests: the thread's last error message, a failure
//! assertion that checks the message names what went wrong, and transforms in the C layout.
#![allow(dead_code)]

use std::ffi::CStr;

use skinfield::{SkfStatus, SkfTransform, skf_last_error};
use skinfield_runtime::{Pose, Transform};

/// This thread's last error message.
pub fn last_error() -> String {
    // SAFETY: skf_last_error never returns null and the string lives until the next failure.
    unsafe { CStr::from_ptr(skf_last_error()) }
        .to_string_lossy()
        .into_owned()
}

/// Asserts a failure with `status` whose message contains every one of `words`.
#[track_caller]
pub fn fails(got: SkfStatus, status: SkfStatus, words: &[&str]) {
    let message = last_error();
    assert_eq!(got, status, "{message}");
    for w in words {
        assert!(message.contains(w), "`{message}` does not mention `{w}`");
    }
}

/// Asserts success, showing the error message otherwise.
#[track_caller]
pub fn ok(got: SkfStatus) {
    assert_eq!(got, SkfStatus::Ok, "{}", last_error());
}

/// A transform in the C layout.
pub fn c_transform(t: &Transform) -> SkfTransform {
    SkfTransform {
        translation: t.translation.to_array(),
        rotation: t.rotation.to_array(),
        scale: t.scale.to_array(),
    }
}

/// A pose's local transforms in the C layout, in the model's joint order.
pub fn c_pose(pose: &Pose) -> Vec<SkfTransform> {
    pose.locals.iter().map(c_transform).collect()
}
