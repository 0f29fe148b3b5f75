//! The manifest's JSON entries turned into the formats' own types (cameras, template,
//! skeleton, degrees of freedom, motion, skin) and back, each failure naming the file and the
//! field.

use std::path::Path;

use glam::{Mat3, Quat, Vec2, Vec3};

use super::*;
use crate::camera::{Camera, Distortion};
use crate::math::Transform;
use crate::mesh::{PartLabel, Template};
use crate::pose::Pose;
use crate::skeleton::{Axis, JointDofs, Skeleton};
use crate::skin::StaticSkin;

impl CameraEntry {
    /// The camera this entry describes (not yet validated).
    #[must_use]
    pub fn to_camera(&self) -> Camera {
        let [k1, k2, p1, p2, k3] = self.distortion;
        let r = self.rotation;
        Camera {
            name: self.name.clone(),
            width: self.width,
            height: self.height,
            fx: self.fx,
            fy: self.fy,
            cx: self.cx,
            cy: self.cy,
            distortion: Distortion { k1, k2, p1, p2, k3 },
            // Rows in the file; glam matrices are built from columns.
            rotation: Mat3::from_cols_array_2d(&r).transpose(),
            translation: Vec3::from_array(self.translation),
        }
    }

    /// The entry of a camera (exact: the floats are copied, not recomputed).
    #[must_use]
    pub fn from_camera(c: &Camera) -> Self {
        let d = c.distortion;
        Self {
            name: c.name.clone(),
            width: c.width,
            height: c.height,
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
            distortion: [d.k1, d.k2, d.p1, d.p2, d.k3],
            rotation: c.rotation.transpose().to_cols_array_2d(),
            translation: c.translation.to_array(),
        }
    }
}

impl TemplateFile {
    /// The template mesh, validated.
    pub fn to_template(&self, file: &Path) -> Result<Template, CaptureError> {
        let n = self.positions.len();
        let t = Template {
            positions: self
                .positions
                .iter()
                .map(|p| Vec3::from_array(*p))
                .collect(),
            normals: self.normals.iter().map(|p| Vec3::from_array(*p)).collect(),
            triangles: self.triangles.clone(),
            uvs: self
                .uvs
                .as_ref()
                .map(|u| u.iter().map(|p| Vec2::from_array(*p)).collect()),
            colors: self
                .colors
                .as_ref()
                .map(|u| u.iter().map(|p| Vec3::from_array(*p)).collect()),
            part_labels: match &self.part_labels {
                None => None,
                Some(labels) => Some(
                    labels
                        .iter()
                        .enumerate()
                        .map(|(i, &l)| match l {
                            0 => Ok(PartLabel::Skin),
                            1 => Ok(PartLabel::Clothing),
                            _ => Err(CaptureError::invalid(
                                file,
                                format!("part_labels[{i}]"),
                                format!("{l} is not 0 (skin) or 1 (clothing)"),
                            )),
                        })
                        .collect::<Result<_, _>>()?,
                ),
            },
        };
        t.validate()
            .map_err(|e| CaptureError::invalid(file, "mesh", e))?;
        let bad_color =
            |c: &Vec3| !(c.is_finite() && c.min_element() >= 0.0 && c.max_element() <= 1.0);
        if let Some(i) = t.colors.as_ref().and_then(|c| c.iter().position(bad_color)) {
            return Err(CaptureError::invalid(
                file,
                format!("colors[{i}]"),
                "not in [0, 1]",
            ));
        }
        if let Some(i) = t
            .normals
            .iter()
            .position(|v| (v.length() - 1.0).abs() > 1e-3)
        {
            return Err(CaptureError::invalid(
                file,
                format!("normals[{i}]"),
                "not a unit vector",
            ));
        }
        debug_assert_eq!(t.vertex_count(), n);
        Ok(t)
    }
}

impl SkeletonEntry {
    /// The skeleton, validated.
    pub fn to_skeleton(&self, file: &Path) -> Result<Skeleton, CaptureError> {
        if self.joints.len() > crate::skeleton::MAX_JOINTS {
            return Err(CaptureError::invalid(
                file,
                "skeleton.joints",
                "too many joints",
            ));
        }
        let mut names = Vec::new();
        let mut parents = Vec::new();
        let mut locals = Vec::new();
        let mut dofs = Vec::new();
        for (j, e) in self.joints.iter().enumerate() {
            names.push(e.name.clone());
            parents.push(e.parent);
            locals.push(transform_from_array(&e.bind_local));
            dofs.push(e.dofs.to_dofs().ok_or_else(|| {
                CaptureError::invalid(
                    file,
                    format!("skeleton.joints[{j}].dofs"),
                    "axes must be 1 to 3 of X/Y/Z with one [min, max] each",
                )
            })?);
        }
        let base = glam::Mat4::from_cols_array(&self.base);
        Skeleton::new(names, parents, locals, None, Some(dofs), base)
            .map_err(|e| CaptureError::invalid(file, "skeleton", e))
    }
}

impl DofsEntry {
    /// The degrees of freedom, or `None` for an invalid axis string or limit count.
    #[must_use]
    pub fn to_dofs(&self) -> Option<JointDofs> {
        Some(match self {
            DofsEntry::Free => JointDofs::Free,
            DofsEntry::Fixed => JointDofs::Fixed,
            DofsEntry::Euler { axes, limits } => {
                let axes: Vec<Axis> = axes
                    .chars()
                    .map(|c| match c {
                        'X' => Some(Axis::X),
                        'Y' => Some(Axis::Y),
                        'Z' => Some(Axis::Z),
                        _ => None,
                    })
                    .collect::<Option<_>>()?;
                let ok = (1..=3).contains(&axes.len())
                    && limits.len() == axes.len()
                    && limits
                        .iter()
                        .all(|[a, b]| a.is_finite() && b.is_finite() && a <= b);
                if !ok {
                    return None;
                }
                JointDofs::Euler {
                    axes,
                    limits: limits.clone(),
                }
            }
        })
    }
}

/// A transform from `[tx, ty, tz, qx, qy, qz, qw, sx, sy, sz]`.
#[must_use]
pub fn transform_from_array(a: &[f32; 10]) -> Transform {
    Transform {
        translation: Vec3::new(a[0], a[1], a[2]),
        rotation: Quat::from_xyzw(a[3], a[4], a[5], a[6]),
        scale: Vec3::new(a[7], a[8], a[9]),
    }
}

/// `[tx, ty, tz, qx, qy, qz, qw, sx, sy, sz]` of a transform.
#[must_use]
pub fn transform_to_array(t: &Transform) -> [f32; 10] {
    let (p, q, s) = (t.translation, t.rotation, t.scale);
    [p.x, p.y, p.z, q.x, q.y, q.z, q.w, s.x, s.y, s.z]
}

impl MotionFile {
    /// One pose per frame, each checked against the skeleton (joint count, finite, unit
    /// quaternions within 1e-3); the frame rate must be finite and positive.
    pub fn to_poses(&self, file: &Path, skeleton: &Skeleton) -> Result<Vec<Pose>, CaptureError> {
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return Err(CaptureError::invalid(
                file,
                "fps",
                format!("{} is not a positive frame rate", self.fps),
            ));
        }
        if self.frames.len() > MAX_FRAMES {
            return Err(CaptureError::invalid(file, "frames", "too many frames"));
        }
        let mut poses = Vec::with_capacity(self.frames.len());
        for (f, frame) in self.frames.iter().enumerate() {
            if frame.len() != skeleton.len() {
                return Err(CaptureError::invalid(
                    file,
                    format!("frames[{f}]"),
                    format!(
                        "{} joints, the skeleton has {}",
                        frame.len(),
                        skeleton.len()
                    ),
                ));
            }
            let locals: Vec<Transform> = frame.iter().map(transform_from_array).collect();
            for (j, t) in locals.iter().enumerate() {
                if !t.is_finite() || (t.rotation.length() - 1.0).abs() > 1e-3 {
                    return Err(CaptureError::invalid(
                        file,
                        format!("frames[{f}][{j}]"),
                        "non-finite or non-unit rotation",
                    ));
                }
            }
            poses.push(Pose { locals });
        }
        Ok(poses)
    }
}

impl SkinFile {
    /// The static skin, validated against the vertex and joint counts.
    pub fn to_skin(
        &self,
        file: &Path,
        vertices: usize,
        joints: usize,
    ) -> Result<StaticSkin, CaptureError> {
        if self.offsets.len() != vertices + 1 {
            return Err(CaptureError::invalid(
                file,
                "offsets",
                format!("{} entries, expected {}", self.offsets.len(), vertices + 1),
            ));
        }
        if self.joint_count != joints {
            return Err(CaptureError::invalid(
                file,
                "joint_count",
                format!("{} joints, the skeleton has {joints}", self.joint_count),
            ));
        }
        StaticSkin::new(
            self.offsets.clone(),
            self.joints.clone(),
            self.weights.clone(),
            joints,
        )
        .map_err(|e| CaptureError::invalid(file, "weights", e))
    }
}
