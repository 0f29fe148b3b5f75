//! Reading one glTF primitive: positions, normals, UVs, colours, triangles (strips and fans
//! converted) and the skinning influences of every `JOINTS_n`/`WEIGHTS_n` set.

use glam::{Vec2, Vec3};
use gltf::accessor::{DataType, Dimensions};

use super::GltfError;
use super::import::Source;
use crate::mesh::{MAX_VERTICES, Template, area_weighted_normals};

/// Most `JOINTS_n`/`WEIGHTS_n` sets read per primitive (32 influences).
pub(crate) const MAX_INFLUENCE_SETS: u32 = 8;
pub(crate) fn triangles_in(mode: gltf::mesh::Mode, indices: usize) -> usize {
    use gltf::mesh::Mode;
    match mode {
        Mode::Triangles => indices / 3,
        Mode::TriangleStrip | Mode::TriangleFan => indices.saturating_sub(2),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => 0,
    }
}

/// Geometry of one primitive as stored.
pub(crate) struct PrimitiveData {
    /// Positions as stored.
    pub positions: Vec<Vec3>,
    /// Normals as stored, or area-weighted from the triangles when absent.
    pub normals: Vec<Vec3>,
    /// `TEXCOORD_0`, if present.
    pub uvs: Option<Vec<Vec2>>,
    /// `COLOR_0` as RGB, if present.
    pub colors: Option<Vec<Vec3>>,
    /// Triangles, indices local to the primitive.
    pub triangles: Vec<[u32; 3]>,
}

pub(crate) fn read_primitive(
    src: &Source<'_>,
    prim: &gltf::Primitive<'_>,
    field: &str,
) -> Result<PrimitiveData, GltfError> {
    use gltf::mesh::Mode;
    check_attributes(src, prim, field)?;
    let reader = prim.reader(src.data());
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| {
            src.field(
                format!("{field}.attributes.POSITION"),
                "missing or unreadable",
            )
        })?
        .map(Vec3::from)
        .collect();
    let n = positions.len();
    if positions.iter().any(|p| !p.is_finite()) {
        return Err(src.field(
            format!("{field}.attributes.POSITION"),
            "holds a non-finite value",
        ));
    }
    let indices: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(src.field(
            format!("{field}.indices"),
            format!("index {bad} but the primitive has {n} vertices"),
        ));
    }
    let triangles: Vec<[u32; 3]> = match prim.mode() {
        Mode::Triangles => indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
        // Strips alternate winding so every triangle stays counter-clockwise.
        Mode::TriangleStrip => indices
            .windows(3)
            .enumerate()
            .map(|(k, w)| {
                if k % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[1], w[0], w[2]]
                }
            })
            .collect(),
        Mode::TriangleFan => indices
            .windows(2)
            .skip(1)
            .map(|w| [indices[0], w[0], w[1]])
            .collect(),
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip => Vec::new(),
    };
    let normals = match reader.read_normals() {
        Some(it) => {
            let v: Vec<Vec3> = it.map(Vec3::from).collect();
            if v.len() != n || v.iter().any(|x| !x.is_finite()) {
                return Err(src.field(
                    format!("{field}.attributes.NORMAL"),
                    "count differs from POSITION or not finite",
                ));
            }
            v
        }
        None => area_weighted_normals(&positions, &triangles),
    };
    let uvs = match reader.read_tex_coords(0) {
        Some(it) => {
            let v: Vec<Vec2> = it.into_f32().map(Vec2::from).collect();
            if v.len() != n {
                return Err(src.field(
                    format!("{field}.attributes.TEXCOORD_0"),
                    "count differs from POSITION",
                ));
            }
            Some(v)
        }
        None => None,
    };
    let colors = match reader.read_colors(0) {
        Some(it) => {
            let v: Vec<Vec3> = it.into_rgb_f32().map(Vec3::from).collect();
            if v.len() != n {
                return Err(src.field(
                    format!("{field}.attributes.COLOR_0"),
                    "count differs from POSITION",
                ));
            }
            Some(v)
        }
        None => None,
    };
    Ok(PrimitiveData {
        positions,
        normals,
        uvs,
        colors,
        triangles,
    })
}

/// Element types the glTF spec allows for the attributes we read.
fn check_attributes(
    src: &Source<'_>,
    prim: &gltf::Primitive<'_>,
    field: &str,
) -> Result<(), GltfError> {
    use DataType::{F32, U8, U16, U32};
    use gltf::Semantic as S;
    for (semantic, acc) in prim.attributes() {
        let f = format!("{field}.attributes.{}", semantic.to_string());
        match semantic {
            S::Positions | S::Normals => src.expect(&acc, &[Dimensions::Vec3], &[F32], &f)?,
            S::TexCoords(_) => src.expect(&acc, &[Dimensions::Vec2], &[F32, U8, U16], &f)?,
            S::Colors(_) => src.expect(
                &acc,
                &[Dimensions::Vec3, Dimensions::Vec4],
                &[F32, U8, U16],
                &f,
            )?,
            S::Joints(_) => src.expect(&acc, &[Dimensions::Vec4], &[U8, U16], &f)?,
            S::Weights(_) => src.expect(&acc, &[Dimensions::Vec4], &[F32, U8, U16], &f)?,
            S::Tangents => src.expect(&acc, &[Dimensions::Vec4], &[F32], &f)?,
        }
    }
    if let Some(acc) = prim.indices() {
        src.expect(
            &acc,
            &[Dimensions::Scalar],
            &[U8, U16, U32],
            &format!("{field}.indices"),
        )?;
    }
    Ok(())
}

/// Per-vertex `(skin joint, weight)` pairs over every `JOINTS_n`/`WEIGHTS_n` set, zero
/// weights dropped and repeated joints merged.
pub(crate) fn read_influences(
    src: &Source<'_>,
    prim: &gltf::Primitive<'_>,
    field: &str,
    vertices: usize,
    skin_joints: usize,
) -> Result<Vec<Vec<(usize, f32)>>, GltfError> {
    let reader = prim.reader(src.data());
    let mut out = vec![Vec::<(usize, f32)>::with_capacity(4); vertices];
    let mut set = 0u32;
    while let Some(joints) = reader.read_joints(set) {
        if set >= MAX_INFLUENCE_SETS {
            return Err(GltfError::TooLarge {
                file: src.file.to_owned(),
                field: format!("{field}: JOINTS_n sets"),
                count: u64::from(set) + 1,
                cap: u64::from(MAX_INFLUENCE_SETS),
            });
        }
        let wfield = format!("{field}.attributes.WEIGHTS_{set}");
        let weights = reader
            .read_weights(set)
            .ok_or_else(|| src.field(wfield.clone(), "missing beside JOINTS"))?;
        let joints: Vec<[u16; 4]> = joints.into_u16().collect();
        let weights: Vec<[f32; 4]> = weights.into_f32().collect();
        if joints.len() != vertices || weights.len() != vertices {
            return Err(src.field(
                wfield,
                format!(
                    "JOINTS/WEIGHTS counts {}/{} differ from {vertices} vertices",
                    joints.len(),
                    weights.len()
                ),
            ));
        }
        for (v, (js, ws)) in joints.iter().zip(&weights).enumerate() {
            for (&j, &w) in js.iter().zip(ws) {
                if !(w.is_finite() && w >= 0.0) {
                    return Err(src.field(wfield, format!("vertex {v} has weight {w}")));
                }
                if w == 0.0 {
                    continue;
                }
                let j = usize::from(j);
                if j >= skin_joints {
                    return Err(src.field(
                        format!("{field}.attributes.JOINTS_{set}"),
                        format!("vertex {v} refers to joint {j}, the skin has {skin_joints}"),
                    ));
                }
                match out[v].iter_mut().find(|(k, _)| *k == j) {
                    Some((_, acc)) => *acc += w,
                    None => out[v].push((j, w)),
                }
            }
        }
        set += 1;
    }
    if set == 0 {
        return Err(src.field(
            format!("{field}.attributes.JOINTS_0"),
            "skinned primitive without joints",
        ));
    }
    Ok(out)
}

/// Appends a primitive's geometry to `t` (attribute options stay aligned: a primitive
/// without UVs or colours gets zeros or white where others have them).
pub(crate) fn append(t: &mut Template, p: PrimitiveData) -> Result<(), String> {
    let base = t.positions.len();
    let n = p.positions.len();
    if base.checked_add(n).is_none_or(|total| total > MAX_VERTICES) {
        return Err(format!("more than {MAX_VERTICES} vertices"));
    }
    let b = base as u32;
    t.triangles
        .extend(p.triangles.iter().map(|tri| tri.map(|i| i + b)));
    match (&mut t.uvs, p.uvs) {
        (Some(a), Some(b)) => a.extend(b),
        (Some(a), None) => a.extend(std::iter::repeat_n(Vec2::ZERO, n)),
        (None, Some(b)) => {
            let mut a = vec![Vec2::ZERO; base];
            a.extend(b);
            t.uvs = Some(a);
        }
        (None, None) => {}
    }
    match (&mut t.colors, p.colors) {
        (Some(a), Some(b)) => a.extend(b),
        (Some(a), None) => a.extend(std::iter::repeat_n(Vec3::ONE, n)),
        (None, Some(b)) => {
            let mut a = vec![Vec3::ONE; base];
            a.extend(b);
            t.colors = Some(a);
        }
        (None, None) => {}
    }
    t.positions.extend(p.positions);
    t.normals.extend(p.normals);
    Ok(())
}
