// Heun's predictor and corrector of src/model/monolayer.rs (`Then::Predict`, `Then::Correct`) on
// the GPU, over every padded site of every cell (the halo too, where φ, φ_n and the rates are
// zero, so it stays zero):
//
//   predictor: φ_n ← φ,  R(φ_n) ← R,  φ* = φ_n + Δt R(φ_n);
//   corrector: φ' = φ_n + ½Δt [R(φ_n) + R(φ*)], then the check that φ' lies in [φ_min, φ_max].
//
// The CPU swaps buffers where this copies them; a copy keeps every kernel's bindings fixed.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read_write> phi: array<f32>;
@group(0) @binding(15) var<storage, read> rate: array<f32>;
@group(0) @binding(16) var<storage, read_write> phi0: array<f32>;
@group(0) @binding(17) var<storage, read_write> k1: array<f32>;
// Per cell, the smallest padded index with φ' out of range, or NO_FAULT. An atomic minimum on
// integers: its result does not depend on the order the invocations arrive in, so the flag is
// as deterministic as the rest (no float atomics anywhere). It is sticky: over the steps of a
// submission it keeps the smallest index of any step, until the host resets it
// (`GpuMonolayer::reset_faults`), so that a fault in any step is seen at the next check.
@group(0) @binding(18) var<storage, read_write> fault: array<atomic<u32>>;

const NO_FAULT: u32 = 0xffffffffu;

@compute @workgroup_size(64)
fn predict(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = patches[gid.y];
    let site = site_of(p, gid.x);
    if !site.inside {
        return;
    }
    let i = site.i;
    let p0 = phi[i];
    let k = rate[i];
    phi0[i] = p0;
    k1[i] = k;
    phi[i] = p0 + params.dt * k;
}

@compute @workgroup_size(64)
fn correct(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = patches[gid.y];
    let site = site_of(p, gid.x);
    if !site.inside {
        return;
    }
    let i = site.i;
    let half = 0.5 * params.dt;
    let v = phi0[i] + half * (k1[i] + rate[i]);
    phi[i] = v;
    // `first_out_of_range` looks at the interior only, row by row; the padded index orders the
    // sites the same way. A NaN or an infinity counts, as on the CPU, by its bits (`is_finite`).
    if site.interior && !(is_finite(v) && v >= params.phi_min && v <= params.phi_max) {
        atomicMin(&fault[gid.y], gid.x);
    }
}
