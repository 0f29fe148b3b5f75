// Skinning with SkinNet's weights: linear blend (LBS) and dual quaternion (DQS, Kavan et al.
// 2007) of the skinning matrices, positions and normals, one thread per vertex.

fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(a.w * b.xyz + b.w * a.xyz + cross(a.xyz, b.xyz), a.w * b.w - dot(a.xyz, b.xyz));
}

fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    return v + 2.0 * cross(q.xyz, cross(q.xyz, v) + q.w * v);
}

// Unit quaternion of a rotation matrix given by its columns (Shepperd's branch on the largest
// diagonal term, as glam's `Quat::from_mat3`).
fn quat_from_axes(x: vec3<f32>, y: vec3<f32>, z: vec3<f32>) -> vec4<f32> {
    var q: vec4<f32>;
    if z.z <= 0.0 {
        let dif10 = y.y - x.x;
        let omm22 = 1.0 - z.z;
        if dif10 <= 0.0 {
            let f = omm22 - dif10;
            q = vec4<f32>(f, x.y + y.x, x.z + z.x, y.z - z.y) * (0.5 / sqrt(f));
        } else {
            let f = omm22 + dif10;
            q = vec4<f32>(x.y + y.x, f, y.z + z.y, z.x - x.z) * (0.5 / sqrt(f));
        }
    } else {
        let sum10 = y.y + x.x;
        let opm22 = 1.0 + z.z;
        if sum10 <= 0.0 {
            let f = opm22 - sum10;
            q = vec4<f32>(x.z + z.x, y.z + z.y, f, x.y - y.x) * (0.5 / sqrt(f));
        } else {
            let f = opm22 + sum10;
            q = vec4<f32>(y.z - z.y, z.x - x.z, x.y - y.x, f) * (0.5 / sqrt(f));
        }
    }
    return normalize(q);
}

fn unit_or_zero(v: vec3<f32>) -> vec3<f32> {
    let len = length(v);
    return select(vec3<f32>(0.0), v / len, len > 1e-20);
}

// Per frame: the unit dual quaternion of every joint's skinning matrix (assumed rigid).
@compute @workgroup_size(64)
fn frame_joint_dqs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let j = group_index(wid, nwg) * THREADS + lid;
    if j >= params.joint_count {
        return;
    }
    let m = joint_mats[j];
    let r = quat_from_axes(m[0].xyz, m[1].xyz, m[2].xyz);
    joint_dqs[2u * j] = r;
    joint_dqs[2u * j + 1u] = 0.5 * quat_mul(vec4<f32>(m[3].xyz, 0.0), r);
}

// Vertex `v` skinned by the blended matrix `m`: position, and the normal through the cofactor
// matrix (det · M⁻ᵀ), correct for the non-rigid blend. Shared by every LBS kernel.
fn lbs_vertex(m: mat4x4<f32>, v: u32) -> Vertex {
    let p = m * vec4<f32>(rest[v].position.xyz, 1.0);
    let c0 = m[0].xyz;
    let c1 = m[1].xyz;
    let c2 = m[2].xyz;
    let cof = mat3x3<f32>(cross(c1, c2), cross(c2, c0), cross(c0, c1));
    return Vertex(vec4<f32>(p.xyz, 1.0), vec4<f32>(unit_or_zero(cof * rest[v].normal.xyz), 0.0));
}

// The blend of vertex `v`'s SkinNet weights over the skinning matrices.
fn blended_matrix(v: u32) -> mat4x4<f32> {
    let j_count = params.joint_count;
    var m = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    for (var j = 0u; j < j_count; j++) {
        m += joint_mats[j] * skin_weights[v * j_count + j];
    }
    return m;
}

@compute @workgroup_size(64)
fn skin_lbs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let v = group_index(wid, nwg) * THREADS + lid;
    if v >= params.vertex_count {
        return;
    }
    skinned[v] = lbs_vertex(blended_matrix(v), v);
}

@compute @workgroup_size(64)
fn skin_dqs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let v = group_index(wid, nwg) * THREADS + lid;
    if v >= params.vertex_count {
        return;
    }
    let j_count = params.joint_count;
    let base = v * j_count;
    // Antipodality is resolved against the most influential joint's rotation.
    var pivot = 0u;
    var best = skin_weights[base];
    for (var j = 1u; j < j_count; j++) {
        let w = skin_weights[base + j];
        if w > best {
            best = w;
            pivot = j;
        }
    }
    let qp = joint_dqs[2u * pivot];
    var br = vec4<f32>(0.0);
    var bd = vec4<f32>(0.0);
    for (var j = 0u; j < j_count; j++) {
        let r = joint_dqs[2u * j];
        let w = select(skin_weights[base + j], -skin_weights[base + j], dot(r, qp) < 0.0);
        br += w * r;
        bd += w * joint_dqs[2u * j + 1u];
    }
    let len = length(br);
    if !(len > 1e-8) {
        // Rotations that cancel (or weights that vanish): LBS of the same weights, as the CPU
        // path and the fast path do, rather than a division by zero.
        skinned[v] = lbs_vertex(blended_matrix(v), v);
        return;
    }
    br /= len;
    bd /= len;
    let t = 2.0 * (br.w * bd.xyz - bd.w * br.xyz + cross(br.xyz, bd.xyz));
    let p = quat_rotate(br, rest[v].position.xyz) + t;
    let n = unit_or_zero(quat_rotate(br, rest[v].normal.xyz));
    skinned[v] = Vertex(vec4<f32>(p, 1.0), vec4<f32>(n, 0.0));
}
