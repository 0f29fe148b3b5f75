//! The mesh handle: a canonical mesh bound to a model, with its rest normals and tangents.

use skinfield_runtime::{BoundMesh, Vec3, Vec4};

use crate::model::SkfModel;
use crate::ptr;
use crate::status::{Failure, SkfStatus, guard};

/// A canonical mesh bound to a model (opaque): positions in the model's canonical space, and
/// the rest normals and tangents the skinning of normals and tangents needs.
pub struct SkfMesh {
    pub(crate) bound: BoundMesh,
    pub(crate) normals: Option<Vec<Vec3>>,
    pub(crate) tangents: Option<Vec<Vec4>>,
}

/// `count` vectors of `N` floats each, checked finite.
fn vectors<const N: usize>(data: &[f32], field: &str) -> Result<Vec<[f32; N]>, Failure> {
    if let Some(i) = data.iter().position(|x| !x.is_finite()) {
        return Err(Failure::invalid(format!(
            "`{field}`[{}] is not finite",
            i / N
        )));
    }
    Ok(data
        .chunks_exact(N)
        .map(|c| core::array::from_fn(|k| c[k]))
        .collect())
}

/// Binds a mesh of `vertex_count` vertices to `model`: `positions` holds `3 × vertex_count`
/// floats (x, y, z per vertex), `normals` (nullable) `3 × vertex_count`, `tangents` (nullable)
/// `4 × vertex_count` (x, y, z, handedness). All are copied. Any resolution binds: the
/// network is a field over canonical space. Release with [`skf_mesh_free`].
///
/// # Safety
/// `model` must be a live model; the arrays must hold the stated number of floats;
/// `out_mesh` must be writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_mesh_bind(
    model: *const SkfModel,
    positions: *const f32,
    normals: *const f32,
    tangents: *const f32,
    vertex_count: usize,
    out_mesh: *mut *mut SkfMesh,
) -> SkfStatus {
    guard("skf_mesh_bind", || {
        // SAFETY: the caller's contract above.
        let model = unsafe { ptr::object(model, "model") }?;
        if out_mesh.is_null() {
            return Err(crate::status::null("out_mesh"));
        }
        if vertex_count == 0 {
            return Err(Failure::invalid(
                "`vertex_count` is 0: a mesh needs vertices",
            ));
        }
        let floats = |n: usize| {
            vertex_count.checked_mul(n).ok_or_else(|| {
                Failure::invalid(format!("`vertex_count` = {vertex_count} is absurd"))
            })
        };
        // SAFETY: the caller's contract above.
        let p = unsafe { ptr::slice(positions, floats(3)?, "positions") }?;
        let p: Vec<Vec3> = vectors::<3>(p, "positions")?
            .into_iter()
            .map(Vec3::from_array)
            .collect();
        let normals = if normals.is_null() {
            None
        } else {
            // SAFETY: the caller's contract above.
            let n = unsafe { ptr::slice(normals, floats(3)?, "normals") }?;
            Some(
                vectors::<3>(n, "normals")?
                    .into_iter()
                    .map(Vec3::from_array)
                    .collect(),
            )
        };
        let tangents = if tangents.is_null() {
            None
        } else {
            // SAFETY: the caller's contract above.
            let t = unsafe { ptr::slice(tangents, floats(4)?, "tangents") }?;
            Some(
                vectors::<4>(t, "tangents")?
                    .into_iter()
                    .map(Vec4::from_array)
                    .collect(),
            )
        };
        let bound = BoundMesh::bind(&model.net, &p).map_err(Failure::invalid)?;
        let mesh = Box::into_raw(Box::new(SkfMesh {
            bound,
            normals,
            tangents,
        }));
        // SAFETY: checked non-null above; the caller guarantees it is writable.
        unsafe { ptr::write(out_mesh, mesh, "out_mesh") }
    })
}

/// Releases a mesh (null is ignored).
///
/// # Safety
/// `mesh` must come from [`skf_mesh_bind`] and not have been freed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_mesh_free(mesh: *mut SkfMesh) {
    if !mesh.is_null() {
        // SAFETY: the caller's contract: a live box from skf_mesh_bind.
        drop(unsafe { Box::from_raw(mesh) });
    }
}

/// The number of vertices of a bound mesh (`*out_count`).
///
/// # Safety
/// `mesh` must be a live mesh; `out_count` writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn skf_mesh_vertex_count(
    mesh: *const SkfMesh,
    out_count: *mut usize,
) -> SkfStatus {
    guard("skf_mesh_vertex_count", || {
        // SAFETY: the caller's contract above.
        let mesh = unsafe { ptr::object(mesh, "mesh") }?;
        // SAFETY: the caller's contract above.
        unsafe { ptr::write(out_count, mesh.bound.vertex_count(), "out_count") }
    })
}
