//! glTF export: a skinned character (skeleton, template, weights, optionally one clip) and a
//! posed mesh sequence. Both are written as one self-contained file: `.glb` (binary chunk) or
//! `.gltf` (buffer as a base64 data URI), chosen by the extension, atomically.

use std::path::Path;

use base64::Engine as _;
use glam::{Mat4, Vec3};
use serde_json::{Value, json};

use super::GltfError;
use crate::math::Transform;
use crate::mesh::{Template, area_weighted_normals};
use crate::pose::Pose;
use crate::skeleton::Skeleton;
use crate::skf::write_atomic;
use crate::skin::StaticSkin;

/// Frame rate [`write_gltf_mesh_sequence`] assumes.
pub const DEFAULT_SEQUENCE_FPS: f32 = 30.0;

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const UNSIGNED_SHORT: u32 = 5123;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// The binary buffer with its views and accessors, built up as data is added.
#[derive(Default)]
struct Buffer {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Buffer {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut v = json!({ "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len() });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// A float accessor of `kind` ("SCALAR", "VEC3", …) with `comps` floats per element.
    fn floats(
        &mut self,
        data: &[f32],
        comps: usize,
        kind: &str,
        target: Option<u32>,
        bounds: bool,
    ) -> usize {
        let view = self.view(bytemuck::cast_slice(data), target);
        let mut a = json!({ "bufferView": view, "componentType": FLOAT, "count": data.len() / comps, "type": kind });
        if bounds {
            let mut min = vec![f32::INFINITY; comps];
            let mut max = vec![f32::NEG_INFINITY; comps];
            for e in data.chunks_exact(comps) {
                for c in 0..comps {
                    min[c] = min[c].min(e[c]);
                    max[c] = max[c].max(e[c]);
                }
            }
            a["min"] = json!(min);
            a["max"] = json!(max);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn vec3s(&mut self, data: &[Vec3], bounds: bool) -> usize {
        let flat: Vec<f32> = data.iter().flat_map(|v| v.to_array()).collect();
        self.floats(&flat, 3, "VEC3", Some(ARRAY_BUFFER), bounds)
    }

    fn indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let flat: Vec<u32> = triangles.iter().flatten().copied().collect();
        let view = self.view(bytemuck::cast_slice(&flat), Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({ "bufferView": view, "componentType": UNSIGNED_INT, "count": flat.len(), "type": "SCALAR" }));
        self.accessors.len() - 1
    }

    fn joints(&mut self, data: &[[u16; 4]]) -> usize {
        let view = self.view(bytemuck::cast_slice(data), Some(ARRAY_BUFFER));
        self.accessors.push(json!({ "bufferView": view, "componentType": UNSIGNED_SHORT, "count": data.len(), "type": "VEC4" }));
        self.accessors.len() - 1
    }
}

fn export_err(path: &Path, reason: impl Into<String>) -> GltfError {
    GltfError::Export {
        file: path.display().to_string(),
        reason: reason.into(),
    }
}

/// Serialises `root` with `buf` as `.glb` or `.gltf` (by `path`'s extension), checks that the
/// gltf crate accepts the result, and writes it atomically.
fn finish(path: &Path, mut root: Value, buf: Buffer) -> Result<(), GltfError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let glb = match ext.as_deref() {
        Some("glb") => true,
        Some("gltf") => false,
        _ => return Err(export_err(path, "extension must be .glb or .gltf")),
    };
    let mut buffer = json!({ "byteLength": buf.bin.len() });
    if !glb {
        let b64 = base64::engine::general_purpose::STANDARD.encode(&buf.bin);
        buffer["uri"] = json!(format!("data:application/octet-stream;base64,{b64}"));
    }
    root["asset"] = json!({ "version": "2.0", "generator": concat!("skinfield-formats ", env!("CARGO_PKG_VERSION")) });
    root["buffers"] = json!([buffer]);
    root["bufferViews"] = Value::Array(buf.views);
    root["accessors"] = Value::Array(buf.accessors);
    let json = serde_json::to_vec(&root).map_err(|e| export_err(path, e.to_string()))?;
    let bytes = if glb {
        glb_container(json, buf.bin).map_err(|r| export_err(path, r))?
    } else {
        json
    };
    // Our own output must pass the gltf crate's schema validation; if not, this is our bug.
    gltf::Gltf::from_slice(&bytes)
        .map_err(|e| export_err(path, format!("output fails glTF validation: {e}")))?;
    write_atomic(path, &bytes).map_err(|source| GltfError::Io {
        file: path.display().to_string(),
        source,
    })
}

fn glb_container(mut json: Vec<u8>, mut bin: Vec<u8>) -> Result<Vec<u8>, String> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total32 =
        u32::try_from(total).map_err(|_| format!("GLB of {total} bytes exceeds 4 GiB"))?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

fn trs(t: &Transform) -> Value {
    json!({
        "translation": t.translation.to_array(),
        "rotation": t.rotation.normalize().to_array(),
        "scale": t.scale.to_array(),
    })
}

/// Writes a skinned character: one node per joint (named, TRS = `bind_local`), a
/// `skeleton_base` matrix node above the roots when `base` is not the identity, one mesh with
/// `ceil(max_influences / 4)` `JOINTS_n`/`WEIGHTS_n` sets (u16 joints, f32 weights), the
/// inverse bind matrices, and optionally one LINEAR clip `(name, times, poses)` with a
/// translation, rotation and scale channel per joint.
pub fn write_gltf_character(
    path: &Path,
    skeleton: &Skeleton,
    template: &Template,
    skin: &StaticSkin,
    clip: Option<(&str, &[f32], &[Pose])>,
) -> Result<(), GltfError> {
    template.validate().map_err(|source| GltfError::Mesh {
        file: path.display().to_string(),
        source,
    })?;
    let (nv, nj) = (template.vertex_count(), skeleton.len());
    if skin.vertex_count() != nv || skin.joint_count() != nj {
        return Err(export_err(
            path,
            format!(
                "skin is {}×{} but the template has {nv} vertices and the skeleton {nj} joints",
                skin.vertex_count(),
                skin.joint_count()
            ),
        ));
    }
    if let Some((_, times, poses)) = clip {
        if times.is_empty() || times.len() != poses.len() {
            return Err(export_err(
                path,
                format!("clip has {} times and {} poses", times.len(), poses.len()),
            ));
        }
        if times.iter().any(|t| !t.is_finite()) || times.windows(2).any(|w| w[1] <= w[0]) {
            return Err(export_err(path, "clip times must be finite and increasing"));
        }
        for p in poses {
            skeleton
                .check_pose(p)
                .map_err(|e| export_err(path, format!("clip pose: {e}")))?;
        }
    }
    let mut buf = Buffer::default();
    let mut nodes: Vec<Value> = skeleton
        .names()
        .iter()
        .zip(skeleton.bind_local())
        .enumerate()
        .map(|(j, (name, t))| {
            let mut n = trs(t);
            n["name"] = json!(name);
            let children: Vec<usize> = skeleton.children(j).collect();
            if !children.is_empty() {
                n["children"] = json!(children);
            }
            n
        })
        .collect();
    let roots: Vec<usize> = (0..nj)
        .filter(|&j| skeleton.parents()[j].is_none())
        .collect();
    let mut scene = Vec::new();
    if skeleton.base().abs_diff_eq(Mat4::IDENTITY, 0.0) {
        scene.extend(&roots);
    } else {
        nodes.push(json!({ "name": "skeleton_base", "matrix": skeleton.base().to_cols_array(), "children": roots }));
        scene.push(nodes.len() - 1);
    }
    nodes.push(json!({ "name": "mesh", "mesh": 0, "skin": 0 }));
    scene.push(nodes.len() - 1);

    let ibm: Vec<f32> = skeleton
        .inverse_bind()
        .iter()
        .flat_map(Mat4::to_cols_array)
        .collect();
    let ibm_acc = buf.floats(&ibm, 16, "MAT4", None, false);
    let mut attributes = json!({
        "POSITION": buf.vec3s(&template.positions, true),
        "NORMAL": buf.vec3s(&template.normals, false),
    });
    if let Some(uvs) = &template.uvs {
        let flat: Vec<f32> = uvs.iter().flat_map(|v| v.to_array()).collect();
        attributes["TEXCOORD_0"] = json!(buf.floats(&flat, 2, "VEC2", Some(ARRAY_BUFFER), false));
    }
    if let Some(colors) = &template.colors {
        attributes["COLOR_0"] = json!(buf.vec3s(colors, false));
    }
    let sets = skin.max_influences().div_ceil(4).max(1);
    for set in 0..sets {
        let mut js = vec![[0u16; 4]; nv];
        let mut ws = vec![0f32; nv * 4];
        for v in 0..nv {
            let (j, w) = skin.influences(v);
            for k in 0..4 {
                if let (Some(&jj), Some(&ww)) = (j.get(set * 4 + k), w.get(set * 4 + k)) {
                    // Joint counts are capped at MAX_JOINTS (1024), so u16 always fits.
                    js[v][k] = jj as u16;
                    ws[v * 4 + k] = ww;
                }
            }
        }
        attributes[format!("JOINTS_{set}")] = json!(buf.joints(&js));
        attributes[format!("WEIGHTS_{set}")] =
            json!(buf.floats(&ws, 4, "VEC4", Some(ARRAY_BUFFER), false));
    }
    let indices = buf.indices(&template.triangles);
    let mut root = json!({
        "scene": 0,
        "scenes": [{ "nodes": scene }],
        "nodes": nodes,
        "meshes": [{ "name": "character", "primitives": [{ "attributes": attributes, "indices": indices }] }],
        "skins": [{ "joints": (0..nj).collect::<Vec<_>>(), "inverseBindMatrices": ibm_acc }],
    });
    if let Some((name, times, poses)) = clip {
        let input = buf.floats(times, 1, "SCALAR", None, true);
        let (mut samplers, mut channels) = (Vec::new(), Vec::new());
        for j in 0..nj {
            let tr: Vec<f32> = poses
                .iter()
                .flat_map(|p| p.locals[j].translation.to_array())
                .collect();
            let sc: Vec<f32> = poses
                .iter()
                .flat_map(|p| p.locals[j].scale.to_array())
                .collect();
            let mut prev = glam::Quat::IDENTITY;
            let rot: Vec<f32> = poses
                .iter()
                .flat_map(|p| {
                    // Keep consecutive keys in one hemisphere so every tool interpolates alike.
                    let q = p.locals[j].rotation.normalize();
                    let q = if q.dot(prev) < 0.0 { -q } else { q };
                    prev = q;
                    q.to_array()
                })
                .collect();
            for (path_name, data, comps, kind) in [
                ("translation", tr, 3, "VEC3"),
                ("rotation", rot, 4, "VEC4"),
                ("scale", sc, 3, "VEC3"),
            ] {
                let output = buf.floats(&data, comps, kind, None, false);
                samplers
                    .push(json!({ "input": input, "output": output, "interpolation": "LINEAR" }));
                channels.push(json!({ "sampler": samplers.len() - 1, "target": { "node": j, "path": path_name } }));
            }
        }
        root["animations"] = json!([{ "name": name, "samplers": samplers, "channels": channels }]);
    }
    finish(path, root, buf)
}

/// [`write_gltf_mesh_sequence_at`] at [`DEFAULT_SEQUENCE_FPS`].
pub fn write_gltf_mesh_sequence(
    path: &Path,
    topology: &Template,
    frames: &[Vec<Vec3>],
) -> Result<(), GltfError> {
    write_gltf_mesh_sequence_at(path, topology, frames, DEFAULT_SEQUENCE_FPS)
}

/// Writes posed meshes as one node per frame (`frame_{k}`, each with its own mesh sharing the
/// template's triangles and UVs, normals recomputed per frame) and a STEP animation
/// `sequence` that scales node `k` to 1 during `[k/fps, (k+1)/fps)` and to 0 otherwise; by
/// default only frame 0 is visible.
///
/// One node per frame rather than morph targets: every viewer plays it, positions are stored
/// exactly (no base + displacement round-off), and a reader can take frame `k` alone.
pub fn write_gltf_mesh_sequence_at(
    path: &Path,
    topology: &Template,
    frames: &[Vec<Vec3>],
    fps: f32,
) -> Result<(), GltfError> {
    topology.validate().map_err(|source| GltfError::Mesh {
        file: path.display().to_string(),
        source,
    })?;
    if frames.is_empty() {
        return Err(export_err(path, "no frames"));
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(export_err(path, format!("fps {fps} must be positive")));
    }
    let n = topology.vertex_count();
    for (k, f) in frames.iter().enumerate() {
        if f.len() != n || f.iter().any(|p| !p.is_finite()) {
            return Err(export_err(
                path,
                format!(
                    "frame {k} has {} positions (or a non-finite one), the template {n}",
                    f.len()
                ),
            ));
        }
    }
    let mut buf = Buffer::default();
    let indices = buf.indices(&topology.triangles);
    let uvs = topology.uvs.as_ref().map(|uvs| {
        let flat: Vec<f32> = uvs.iter().flat_map(|v| v.to_array()).collect();
        buf.floats(&flat, 2, "VEC2", Some(ARRAY_BUFFER), false)
    });
    let (mut nodes, mut meshes) = (Vec::new(), Vec::new());
    for (k, f) in frames.iter().enumerate() {
        let mut attributes = json!({
            "POSITION": buf.vec3s(f, true),
            "NORMAL": buf.vec3s(&area_weighted_normals(f, &topology.triangles), false),
        });
        if let Some(uv) = uvs {
            attributes["TEXCOORD_0"] = json!(uv);
        }
        meshes.push(json!({ "name": format!("frame_{k}"), "primitives": [{ "attributes": attributes, "indices": indices }] }));
        let s = if k == 0 { 1.0 } else { 0.0 };
        nodes.push(json!({ "name": format!("frame_{k}"), "mesh": k, "scale": [s, s, s] }));
    }
    let mut root = json!({
        "scene": 0,
        "scenes": [{ "nodes": (0..frames.len()).collect::<Vec<_>>() }],
        "nodes": nodes,
        "meshes": meshes,
    });
    if frames.len() > 1 {
        let (mut samplers, mut channels) = (Vec::new(), Vec::new());
        let last = frames.len() - 1;
        for k in 0..frames.len() {
            let t = |i: usize| i as f32 / fps;
            // Keys only where node k changes: on at t_k, off at t_{k+1}.
            let (times, scales): (Vec<f32>, Vec<f32>) = match k {
                0 => (vec![0.0, t(1)], vec![1.0, 0.0]),
                k if k == last => (vec![0.0, t(k)], vec![0.0, 1.0]),
                k => (vec![0.0, t(k), t(k + 1)], vec![0.0, 1.0, 0.0]),
            };
            let input = buf.floats(&times, 1, "SCALAR", None, true);
            let values: Vec<f32> = scales.iter().flat_map(|&s| [s, s, s]).collect();
            let output = buf.floats(&values, 3, "VEC3", None, false);
            samplers.push(json!({ "input": input, "output": output, "interpolation": "STEP" }));
            channels.push(json!({ "sampler": k, "target": { "node": k, "path": "scale" } }));
        }
        root["animations"] =
            json!([{ "name": "sequence", "samplers": samplers, "channels": channels }]);
    }
    finish(path, root, buf)
}
