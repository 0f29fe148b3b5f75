//! `trainer synth`: synthetic multi-view captures with known ground truth.
//!
//! The built-in character (no external files) is a procedural clothed human of about 1.75 m
//! with 24 joints ([`character`]), an implicit-surface body meshed by marching tetrahedra and
//! simplified to about 10k vertices, wearing a loose skirt and sleeves, with procedural colours
//! ([`body`], [`texture`]). It moves through a motion library whose test clips lie outside the
//! training ranges ([`motion`]); the ground truth is posed by a documented deformer that static
//! skinning cannot reproduce ([`deform`]: DQS with the true weights of [`weights`], flexion
//! bulges, skirt pushed out by the legs); twelve cameras on two rings ([`rig`]) see it rendered
//! by the software rasteriser with Lambert + specular shading and shadows ([`output`]).

use skinfield_formats::capture::{CaptureError, ImageFormat};
use skinfield_formats::{Skeleton, SkeletonError, SkinError, Template};

pub mod body;
pub mod character;
mod clips;
pub mod deform;
pub mod gltf_character;
pub mod gltf_source;
pub mod joint_map;
pub mod labels;
pub mod mask_error;
pub mod motion;
pub mod output;
pub mod rig;
pub mod texture;
pub mod weights;

pub use gltf_source::{GltfSource, synthesize_gltf};
pub use joint_map::JointMap;
pub use motion::TestMotions;
pub use output::{SynthSummary, synthesize};

/// Why a synthetic capture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The skeleton or a pose is invalid (a bug in the character definition).
    #[error("skeleton: {0}")]
    Skeleton(#[from] SkeletonError),
    /// The true weights are invalid.
    #[error("true weights: {0}")]
    Skin(#[from] SkinError),
    /// The glTF character or motion could not be read.
    #[error(transparent)]
    Gltf(#[from] skinfield_formats::gltf_io::GltfError),
    /// Writing the capture failed.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The joint map (`--joint-map`) cannot be read, is not a JSON object of joint names, or
    /// does not fit the character's and the motion's skeletons.
    #[error("joint map {}: {reason}", path.display())]
    JointMap {
        /// The file (or what the map was built from).
        path: std::path::PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The configuration is unusable.
    #[error("synth configuration: field `{field}`: {reason}")]
    Config {
        /// The field.
        field: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// What to generate. [`SynthConfig::default`] is the capture the README trains on;
/// [`SynthConfig::tiny`] is for tests.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthConfig {
    /// Frames per training clip (5 clips).
    pub train_frames_per_clip: usize,
    /// Frames per test clip (3 clips).
    pub test_frames_per_clip: usize,
    /// Number of cameras.
    pub cameras: usize,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Marching grid: cells along the character's height.
    pub grid: usize,
    /// Vertex count the template is simplified to (about).
    pub target_vertices: usize,
    /// Shadow map size in texels per side.
    pub shadow_map: usize,
    /// Colour images as 8-bit sRGB PNG or linear float EXR (masks are always PNG).
    pub image_format: ImageFormat,
    /// Which poses the test frames hold (the novel test clips, or held-out phases of the
    /// training clips).
    pub test_motions: TestMotions,
    /// Share of the part-label images' boundary pixels given a neighbouring part's label
    /// ([`labels::with_boundary_noise`]); 0 writes exact labels.
    pub label_noise: f32,
    /// Pixels by which every mask's outline is moved outwards (inwards when negative), as a
    /// segmentation that over- or under-segments by a constant margin
    /// ([`mask_error::offset_coverage`]); 0 writes exact masks. The images and the ground truth
    /// stay exact.
    pub mask_offset_px: f32,
    /// Seed of every random choice (colour noise, motion amplitudes, camera jitter).
    pub seed: u64,
}

/// The largest outline offset [`SynthConfig::mask_offset_px`] accepts, in pixels.
pub const MAX_MASK_OFFSET_PX: f32 = 16.0;

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            train_frames_per_clip: 16,
            test_frames_per_clip: 8,
            cameras: 12,
            width: 256,
            height: 256,
            grid: 180,
            target_vertices: 10_000,
            shadow_map: 512,
            image_format: ImageFormat::Png,
            test_motions: TestMotions::Novel,
            label_noise: 0.0,
            mask_offset_px: 0.0,
            seed: 0,
        }
    }
}

impl SynthConfig {
    /// A capture small enough for unit tests (a fraction of a second to make).
    #[must_use]
    pub fn tiny() -> Self {
        Self {
            train_frames_per_clip: 1,
            test_frames_per_clip: 1,
            cameras: 2,
            width: 40,
            height: 40,
            grid: 40,
            target_vertices: 2500,
            shadow_map: 96,
            image_format: ImageFormat::Png,
            test_motions: TestMotions::Novel,
            label_noise: 0.0,
            mask_offset_px: 0.0,
            seed: 0,
        }
    }

    /// Checks that every count is usable.
    pub fn validate(&self) -> Result<(), SynthError> {
        let bad = |field, reason: &str| {
            Err(SynthError::Config {
                field,
                reason: reason.into(),
            })
        };
        if self.train_frames_per_clip == 0 {
            return bad("train_frames_per_clip", "must be at least 1");
        }
        if self.test_motions == TestMotions::HeldOutPhases
            && self.test_frames_per_clip > self.train_frames_per_clip
        {
            return bad(
                "test_frames_per_clip",
                "held-out phases need at most train_frames_per_clip test frames per clip",
            );
        }
        if self.cameras == 0 || self.cameras > 256 {
            return bad("cameras", "must be 1 to 256");
        }
        if !(8..=4096).contains(&self.width) || !(8..=4096).contains(&self.height) {
            return bad("width/height", "must be 8 to 4096 pixels");
        }
        if !(16..=600).contains(&self.grid) {
            return bad("grid", "must be 16 to 600 cells");
        }
        if !(1000..=200_000).contains(&self.target_vertices) {
            return bad("target_vertices", "must be 1000 to 200000");
        }
        if !(0.0..=1.0).contains(&self.label_noise) {
            return bad("label_noise", "must be in [0, 1]");
        }
        if !(-MAX_MASK_OFFSET_PX..=MAX_MASK_OFFSET_PX).contains(&self.mask_offset_px) {
            return bad("mask_offset_px", "must be within ±16 pixels");
        }
        if !(16..=4096).contains(&self.shadow_map) {
            return bad("shadow_map", "must be 16 to 4096 texels");
        }
        Ok(())
    }
}

/// The built-in character: template, skeleton, parts and its ground-truth deformer.
#[derive(Clone, Debug)]
pub struct Character {
    /// The template (bind pose) with colours and skin / clothing labels.
    pub template: Template,
    /// The skeleton with joint-angle DOFs.
    pub skeleton: Skeleton,
    /// Fine part per vertex.
    pub parts: Vec<body::Part>,
    /// The ground-truth deformer (holds the true weights).
    pub deformer: deform::GroundTruthDeformer,
}

/// Builds the built-in character for a configuration.
pub fn build_character(config: &SynthConfig) -> Result<Character, SynthError> {
    let skeleton = character::build_skeleton()?;
    let mesh = body::build_mesh(config.grid, config.target_vertices, config.seed);
    let skirt: Vec<bool> = mesh.parts.iter().map(|p| *p == body::Part::Skirt).collect();
    let skin = weights::true_weights(&skeleton, &mesh.template.positions, &skirt)?;
    let t = &mesh.template;
    let deformer = deform::GroundTruthDeformer::new(
        skeleton.clone(),
        skin,
        t.positions.clone(),
        t.normals.clone(),
        t.triangles.clone(),
        mesh.parts.clone(),
    );
    Ok(Character {
        template: mesh.template,
        skeleton,
        parts: mesh.parts,
        deformer,
    })
}

#[cfg(test)]
mod tests;
