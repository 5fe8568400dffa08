// src/model/forces.rs on the GPU: the force density on each cell (Eqs. 3 and 4),
//
//   f_i = f^p_i + f^a_i,  f^p_i = −∇μ_i (or −φ_i ∇μ_i),  f^a_i = −ζ Q̂_i · ∇φ_i,
//
// at every interior site of every patch (central differences; μ reads zero on the halo). Zero
// on the halo, as on the CPU.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(6) var<storage, read> mu: array<f32>;
@group(0) @binding(8) var<storage, read> q_hat: array<vec2<f32>>;
@group(0) @binding(9) var<storage, read_write> fx: array<f32>;
@group(0) @binding(10) var<storage, read_write> fy: array<f32>;

// f_i at padded site k = global_invocation_id.x of cell i = global_invocation_id.y
// (`forces::force_density`).
@compute @workgroup_size(64)
fn force_density(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = patches[gid.y];
    let site = site_of(p, gid.x);
    if !site.inside {
        return;
    }
    let i = site.i;
    if !site.interior {
        fx[i] = 0.0;
        fy[i] = 0.0;
        return;
    }
    let s = stride(p);
    let q = q_hat[gid.y];
    let mx = 0.5 * (mu[i + 1u] - mu[i - 1u]);
    let my = 0.5 * (mu[i + s] - mu[i - s]);
    let px = 0.5 * (phi[i + 1u] - phi[i - 1u]);
    let py = 0.5 * (phi[i + s] - phi[i - s]);
    var weight = 1.0;
    if params.passive == 1u {
        weight = phi[i];
    }
    fx[i] = -weight * mx - params.zeta * (q.x * px + q.y * py);
    fy[i] = -weight * my - params.zeta * (q.y * px - q.x * py);
}
