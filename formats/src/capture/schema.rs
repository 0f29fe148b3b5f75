//! The JSON shapes of a capture's files (serde); conversions to the core types live in the
//! parent module, which validates them.

use serde::{Deserialize, Serialize};

/// How the colour images are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum ImageFormat {
    /// 8-bit sRGB PNG.
    #[default]
    Png,
    /// Linear float RGB OpenEXR.
    Exr,
}

impl ImageFormat {
    /// File extension without the dot.
    #[must_use]
    pub fn extension(self) -> &'static str {
        match self {
            ImageFormat::Png => "png",
            ImageFormat::Exr => "exr",
        }
    }
}

/// `manifest.json`: what the capture holds and where.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CaptureManifest {
    /// Always `skinfield-capture`.
    pub format: String,
    /// Layout version (1).
    pub version: u32,
    /// `y` or `z`: the axis about which root heading is removed.
    pub up_axis: String,
    /// The calibrated cameras; their names are the image folder names.
    pub cameras: Vec<CameraEntry>,
    /// Path of the [`TemplateFile`].
    pub template: String,
    /// Path of the [`MotionFile`]; absent when the motion is still to be fitted to the
    /// capture's 2D keypoints (`trainer track` writes it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<String>,
    /// Path of a [`SkinFile`] of initial weights the trainer may use.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_weights: Option<String>,
    /// Number of frames of the motion.
    pub frame_count: usize,
    /// Named frame ranges of the motion (informational: which motion each frame comes from).
    #[serde(default)]
    pub clips: Vec<ClipEntry>,
    /// Frames the trainer may use.
    pub train_frames: Vec<usize>,
    /// Frames held out for evaluation (disjoint from `train_frames`).
    pub test_frames: Vec<usize>,
    /// Folder of the colour images (`{images}/{camera}/{frame:05}.{png|exr}`).
    pub images: String,
    /// Folder of the masks (`{masks}/{camera}/{frame:05}.png`).
    pub masks: String,
    /// Encoding of the colour images.
    #[serde(default)]
    pub image_format: ImageFormat,
    /// Folder of 2D keypoint detections ([`super::keypoints`]), if the capture has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub keypoints: Option<String>,
    /// Per-view part-label images ([`LabelsEntry`]), if the capture has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<LabelsEntry>,
    /// The frame a template is reconstructed from (`trainer template`): typically the actor's
    /// calibration pose at the start of the recording. It may be outside the training and test
    /// frames; its images and masks must exist.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub canonical_frame: Option<usize>,
    /// Ground truth for evaluation only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub evaluation: Option<EvaluationEntry>,
    /// How the capture was made (informational).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<SourceEntry>,
}

/// One calibrated pinhole camera (OpenCV convention: `x_cam = R·x_world + t`, +Y down).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraEntry {
    /// Unique name of `[A-Za-z0-9_-]`, also the image folder name.
    pub name: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Focal length x (pixels).
    pub fx: f32,
    /// Focal length y (pixels).
    pub fy: f32,
    /// Principal point x (pixels).
    pub cx: f32,
    /// Principal point y (pixels).
    pub cy: f32,
    /// Brown–Conrady `[k1, k2, p1, p2, k3]`.
    #[serde(default)]
    pub distortion: [f32; 5],
    /// World-to-camera rotation, as three rows.
    pub rotation: [[f32; 3]; 3],
    /// World-to-camera translation.
    pub translation: [f32; 3],
}

/// Per-view part-label images: `{folder}/{camera}/{frame:05}.png`, 8-bit RGB, one colour per
/// part (2D human parsing, or the synthetic ground truth). A pixel whose colour is not in the
/// palette (the background, an anti-aliased edge) has no label.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LabelsEntry {
    /// Folder of the label images.
    pub folder: String,
    /// Colour of each part label, indexed by the template's part label (0 = skin, 1 =
    /// clothing); 1 to 254 distinct colours.
    pub palette: Vec<[u8; 3]>,
    /// Frames that have label images (each must exist for every camera).
    pub frames: Vec<usize>,
}

/// A named range of frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipEntry {
    /// Motion name (e.g. `walk`).
    pub name: String,
    /// First frame.
    pub first: usize,
    /// Number of frames.
    pub count: usize,
    /// `train` or `test`.
    pub split: String,
}

/// Evaluation-only ground truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EvaluationEntry {
    /// Folder of `{frame:05}.bin` ground-truth posed meshes, one per test frame.
    pub gt_meshes: String,
    /// Path of a [`SkinFile`]: the ground-truth deformer's static weights.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub true_weights: Option<String>,
    /// What the ground-truth deformer does (informational).
    #[serde(default)]
    pub deformer: String,
}

/// Provenance of a capture.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceEntry {
    /// Program that made it (e.g. `trainer synth`).
    pub generator: String,
    /// Character source (`procedural` or a file name).
    pub character: String,
    /// RNG seed.
    pub seed: u64,
    /// Direction the light travels (world space, unit), for reference.
    pub light_direction: [f32; 3],
}

/// `template.json`: the canonical mesh and the skeleton.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemplateFile {
    /// Canonical positions (metres).
    pub positions: Vec<[f32; 3]>,
    /// Unit normals.
    pub normals: Vec<[f32; 3]>,
    /// Counter-clockwise triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Texture coordinates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Linear RGB colours in [0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colors: Option<Vec<[f32; 3]>>,
    /// 0 = skin, 1 = clothing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub part_labels: Option<Vec<u8>>,
    /// The skeleton the mesh is bound to.
    pub skeleton: SkeletonEntry,
}

/// A skeleton in JSON.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkeletonEntry {
    /// Joints in topological order.
    pub joints: Vec<JointEntry>,
    /// Column-major 4×4 transform above the roots.
    pub base: [f32; 16],
}

/// One joint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointEntry {
    /// Unique name.
    pub name: String,
    /// Parent index (smaller than this joint's) or `null` for a root.
    pub parent: Option<usize>,
    /// Bind-pose local transform `[tx, ty, tz, qx, qy, qz, qw, sx, sy, sz]`.
    pub bind_local: [f32; 10],
    /// Degrees of freedom.
    pub dofs: DofsEntry,
}

/// Degrees of freedom of a joint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum DofsEntry {
    /// Any rotation.
    Free,
    /// No rotation.
    Fixed,
    /// Euler angles about `axes` (e.g. `"ZXY"`, applied in that order), each within `[min, max]`.
    Euler {
        /// One to three of `X`, `Y`, `Z`.
        axes: String,
        /// Limits per axis in radians.
        limits: Vec<[f32; 2]>,
    },
}

/// `motion.json`: one pose per frame, each a list of per-joint local transforms
/// `[tx, ty, tz, qx, qy, qz, qw, sx, sy, sz]` in joint order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionFile {
    /// Frames per second (informational).
    pub fps: f32,
    /// Per frame, per joint local transform.
    pub frames: Vec<Vec<[f32; 10]>>,
}

/// Static skinning weights in CSR form (see [`crate::StaticSkin::new`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SkinFile {
    /// Joint count the indices refer to.
    pub joint_count: usize,
    /// `vertices + 1` offsets into `joints` / `weights`.
    pub offsets: Vec<u32>,
    /// Joint indices.
    pub joints: Vec<u32>,
    /// Weights.
    pub weights: Vec<f32>,
}
