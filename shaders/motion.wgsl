// src/model/motion.rs on the GPU: the velocity and the rate of Eq. 1 on each patch,
//
//   v_i = (f_i + pull) × mobility,   ∂_t φ_i = −v_i · ∇φ_i − J₀ μ_i,
//
// with the CPU's `Drag` (`Slot::Drag`: the pull ξ_c S in .xy and the mobility in .z): from the
// friction solve (friction.wgsl) when active with ξ_cell > 0, else a pull of zero and the
// mobility 1/ξ_relax (relaxation) or 1/ξ_s(x) (activity with ξ_cell = 0). ∇φ is
// central (`Neighbourhood::gradient`) or upwind, against v, as `Advection` says. v and the rate
// are zero on the halo, as on the CPU (which writes the interior only of buffers that start
// zero): Heun adds Δt × rate on the whole padded storage, so the halo of φ stays zero.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(6) var<storage, read> mu: array<f32>;
@group(0) @binding(9) var<storage, read> fx: array<f32>;
@group(0) @binding(10) var<storage, read> fy: array<f32>;
@group(0) @binding(13) var<storage, read> drag: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read_write> velocity: array<vec2<f32>>;
@group(0) @binding(15) var<storage, read_write> rate: array<f32>;

// v_i and ∂_t φ_i at padded site k = global_invocation_id.x of cell i = global_invocation_id.y
// (`motion::velocity_and_rate`). The CPU skips writing v in the predictor; here it is always
// written (two streams more, one kernel fewer), so a test can read it after any evaluation.
@compute @workgroup_size(64)
fn velocity_and_rate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = patches[gid.y];
    let site = site_of(p, gid.x);
    if !site.inside {
        return;
    }
    let i = site.i;
    if !site.interior {
        velocity[i] = vec2<f32>(0.0, 0.0);
        rate[i] = 0.0;
        return;
    }
    let s = stride(p);
    let d = drag[lattice_index(p, site.at, params.box_size)];
    let v = vec2<f32>((fx[i] + d.x) * d.z, (fy[i] + d.y) * d.z);
    velocity[i] = v;
    let c = phi[i];
    var g: vec2<f32>;
    if params.advection == 1u {
        // Upwind: the difference on the side v comes from.
        g.x = select(phi[i + 1u] - c, c - phi[i - 1u], v.x > 0.0);
        g.y = select(phi[i + s] - c, c - phi[i - s], v.y > 0.0);
    } else {
        g = vec2<f32>(0.5 * (phi[i + 1u] - phi[i - 1u]), 0.5 * (phi[i + s] - phi[i - s]));
    }
    rate[i] = -(v.x * g.x + v.y * g.y) - params.j0 * mu[i];
}
