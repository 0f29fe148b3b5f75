//! Where a file-based capture's poses come from: the character's own glTF clips, another glTF's
//! clips (joints matched by name, or retargeted through a joint map), or BVH files (each one
//! clip named by its file stem, always retargeted: a BVH skeleton never shares a rig's names
//! and rest pose).
//!
//! BVH clips are sampled at the frame nearest below the asked time (motion capture runs at
//! 30–120 frames per second; the captures sample a clip at 4–16 phases). BVH lengths are read
//! in CMU's units (converted to metres); the retargeting scales the root's travel to the
//! character's size whatever they are.

use std::path::{Path, PathBuf};

use glam::Vec3;

use skinfield_formats::bvh::{BvhMotion, BvhOptions, CMU_UNIT_TO_METRES, load_bvh_with};
use skinfield_formats::gltf_io::{Clip, GltfDocument, GltfSkin, load_gltf};
use skinfield_formats::{Pose, Retarget, Skeleton};

use super::SynthError;
use super::joint_map::JointMap;

/// The motion of a capture: which clips exist and how each becomes a pose of the character.
pub(crate) enum Motion {
    /// The character file's own clips.
    Own,
    /// Another glTF's clips, joints matched by name.
    GltfByName(GltfDocument),
    /// Another glTF's clips, retargeted from its largest skin (boxed: the retargeting holds
    /// both skeletons).
    GltfRetargeted(GltfDocument, Box<Retarget>),
    /// BVH files, each retargeted from its own skeleton; the stems of every BVH file there
    /// was to choose from.
    Bvh(Vec<BvhClip>, Vec<String>),
}

/// One BVH file as a clip.
pub(crate) struct BvhClip {
    /// The file stem.
    pub name: String,
    /// The parsed file.
    pub motion: BvhMotion,
    /// From its skeleton to the character's.
    pub retarget: Retarget,
}

/// A clip of a [`Motion`], ready to sample.
pub(crate) struct ClipRef<'a> {
    /// Its length in seconds.
    pub duration_s: f32,
    kind: ClipKind<'a>,
}

enum ClipKind<'a> {
    Own(&'a Clip, &'a GltfSkin),
    ByName(&'a Clip, &'a GltfSkin),
    Retargeted(&'a Clip, &'a GltfSkin, &'a Retarget),
    Bvh(&'a BvhClip),
}

/// Whether `path` names BVH motion: a `.bvh` file or a folder (of `.bvh` files).
fn is_bvh(path: &Path) -> bool {
    path.is_dir()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("bvh"))
}

impl Motion {
    /// Opens the motion of a capture of a character whose poses are expressed on `skeleton`:
    /// its own clips (`motion` = `None`), or the file or folder `motion`, retargeted through
    /// `joint_map` where given (BVH always needs one). Of a folder of BVH files only the
    /// clips named in `wanted` are read (another skeleton's files may sit beside them). With
    /// `in_place` the retargeted hips drop their travel across the floor (+Y up).
    pub fn open(
        motion: Option<&Path>,
        joint_map: Option<&JointMap>,
        skeleton: &Skeleton,
        wanted: &[String],
        in_place: bool,
    ) -> Result<Self, SynthError> {
        if in_place && joint_map.is_none() {
            return Err(SynthError::Config {
                field: "in_place",
                reason: "only retargeted motion (a joint map) can be played in place".into(),
            });
        }
        let up = if in_place { Vec3::Y } else { Vec3::ZERO };
        let map_error = |map: &JointMap, reason: String| SynthError::JointMap {
            path: map.origin.clone(),
            reason,
        };
        let Some(path) = motion else {
            return match joint_map {
                None => Ok(Self::Own),
                Some(map) => Err(map_error(
                    map,
                    "a joint map retargets another file's clips; name the motion file too".into(),
                )),
            };
        };
        if !is_bvh(path) {
            let doc = load_gltf(path)?;
            return match joint_map {
                None => Ok(Self::GltfByName(doc)),
                Some(map) => {
                    let skin = doc.largest_skin().ok_or_else(|| SynthError::Config {
                        field: "motion",
                        reason: format!("{} has no skin to retarget from", path.display()),
                    })?;
                    let retarget = Retarget::new(&skin.skeleton, skeleton, &map.pairs)
                        .map_err(|e| map_error(map, e.to_string()))?
                        .in_place(up);
                    Ok(Self::GltfRetargeted(doc, Box::new(retarget)))
                }
            };
        }
        let map = joint_map.ok_or_else(|| SynthError::Config {
            field: "joint_map",
            reason: format!(
                "{} is BVH motion, whose joints are never the character's: give a joint map",
                path.display()
            ),
        })?;
        let files: Vec<PathBuf> = if path.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map_err(|e| SynthError::Config {
                    field: "motion",
                    reason: format!("{}: {e}", path.display()),
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && is_bvh(p))
                .collect();
            files.sort();
            files
        } else {
            vec![path.to_path_buf()]
        };
        let stem = |file: &Path| {
            file.file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned())
        };
        let available: Vec<String> = files.iter().map(|f| stem(f)).collect();
        let options = BvhOptions {
            unit_scale: CMU_UNIT_TO_METRES,
        };
        let clips = files
            .iter()
            .filter(|file| !path.is_dir() || wanted.contains(&stem(file)))
            .map(|file| {
                let motion = load_bvh_with(file, &options).map_err(|e| SynthError::Config {
                    field: "motion",
                    reason: e.to_string(),
                })?;
                let retarget = Retarget::new(&motion.skeleton, skeleton, &map.pairs)
                    .map_err(|e| map_error(map, format!("{}: {e}", file.display())))?
                    .in_place(up);
                Ok(BvhClip {
                    name: stem(file),
                    motion,
                    retarget,
                })
            })
            .collect::<Result<Vec<_>, SynthError>>()?;
        Ok(Self::Bvh(clips, available))
    }

    /// The clip named `name`: from `own` (the character's file and skin) for [`Motion::Own`],
    /// by name from the motion file with the character's skin `own.1` as the pose's skeleton.
    pub fn clip<'a>(
        &'a self,
        name: &str,
        own: Option<(&'a GltfDocument, &'a GltfSkin)>,
    ) -> Option<ClipRef<'a>> {
        let gltf = |doc: &'a GltfDocument| doc.clip(name);
        let (duration_s, kind) = match self {
            Self::Own => {
                let (doc, skin) = own?;
                let clip = gltf(doc)?;
                (clip.duration_s, ClipKind::Own(clip, skin))
            }
            Self::GltfByName(doc) => {
                let clip = gltf(doc)?;
                (clip.duration_s, ClipKind::ByName(clip, own?.1))
            }
            Self::GltfRetargeted(doc, retarget) => {
                let clip = gltf(doc)?;
                let skin = doc.largest_skin()?;
                (clip.duration_s, ClipKind::Retargeted(clip, skin, retarget))
            }
            Self::Bvh(clips, _) => {
                let clip = clips.iter().find(|c| c.name == name)?;
                (clip.motion.duration_s(), ClipKind::Bvh(clip))
            }
        };
        Some(ClipRef { duration_s, kind })
    }

    /// The clip names there are, for messages.
    pub fn names(&self, own: Option<&GltfDocument>) -> Vec<String> {
        let gltf = |doc: &GltfDocument| doc.clips.iter().map(|c| c.name.clone()).collect();
        match self {
            Self::Own => own.map_or_else(Vec::new, gltf),
            Self::GltfByName(doc) | Self::GltfRetargeted(doc, _) => gltf(doc),
            Self::Bvh(_, available) => available.clone(),
        }
    }

    /// Where the clips come from, for messages.
    pub fn describe(&self, own: Option<&GltfDocument>) -> String {
        match self {
            Self::Own => own.map_or_else(String::new, |d| d.source.display().to_string()),
            Self::GltfByName(doc) | Self::GltfRetargeted(doc, _) => {
                doc.source.display().to_string()
            }
            Self::Bvh(..) => "the BVH motion".into(),
        }
    }
}

impl ClipRef<'_> {
    /// The character's pose at `t` seconds.
    pub fn pose(&self, t: f32) -> Result<Pose, SynthError> {
        let retargeted = |retarget: &Retarget, pose: &Pose| {
            retarget.apply(pose).map_err(|e| SynthError::Config {
                field: "motion",
                reason: format!("retargeting the pose at {t} s: {e}"),
            })
        };
        match self.kind {
            ClipKind::Own(clip, skin) => Ok(clip.sample(skin, t)),
            ClipKind::ByName(clip, skin) => {
                Ok(clip.sample_by_name(&skin.skeleton, &skin.default_pose(), t))
            }
            ClipKind::Retargeted(clip, skin, retarget) => {
                retargeted(retarget, &clip.sample(skin, t))
            }
            ClipKind::Bvh(clip) => {
                let frames = clip.motion.frame_count();
                let k = if clip.motion.frame_time > 0.0 {
                    ((t / clip.motion.frame_time).max(0.0) as usize).min(frames.saturating_sub(1))
                } else {
                    0
                };
                let pose = clip.motion.poses.get(k).ok_or_else(|| SynthError::Config {
                    field: "motion",
                    reason: format!("BVH clip `{}` has no frames", clip.name),
                })?;
                retargeted(&clip.retarget, pose)
            }
        }
    }
}
