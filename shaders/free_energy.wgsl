// src/model/free_energy.rs on the GPU: the area A_i = Σ φ_i² of each cell, then
//
//   μ_i = (γ/λ)·8 φ_i(1−φ_i)(1−2φ_i) − 2γλ ∇²φ_i − (4μ/πR²)(1 − A_i/πR²) φ_i
//         + (c κ/λ) φ_i Σ_{j≠i} φ_j²
//
// at every site of every patch (Supplementary Eqs. S1–S3; docs/reading.md §2), term by term in
// the CPU's order. μ is zero on the halo, as on the CPU.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(4) var<storage, read> sum_phi2: array<f32>;
@group(0) @binding(5) var<storage, read_write> area: array<f32>;
@group(0) @binding(6) var<storage, read_write> mu: array<f32>;

const WORKGROUP: u32 = 64u;
var<workgroup> sums: array<f32, WORKGROUP>;

// A_i = Σ φ_i² over the padded patch (`free_energy::area`). One workgroup per cell: invocation
// t sums sites t, t + 64, ... in order, then a fixed halving tree adds the 64 partial sums. The
// order is fixed, so the bits are too.
@compute @workgroup_size(64)
fn cell_area(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let p = patches[wg.x];
    let n = stride(p) * (p.h + 2u);
    var s = 0.0;
    for (var k = t; k < n; k += WORKGROUP) {
        let v = phi[p.offset + k];
        s += v * v;
    }
    sums[t] = s;
    workgroupBarrier();
    for (var width = WORKGROUP / 2u; width > 0u; width /= 2u) {
        if t < width {
            sums[t] += sums[t + width];
        }
        workgroupBarrier();
    }
    if t == 0u {
        area[wg.x] = sums[0];
    }
}

// The discrete Laplacian at padded index i (`free_energy::laplacian`).
fn laplacian(i: u32, s: u32) -> f32 {
    let c = phi[i];
    let nn = phi[i - 1u] + phi[i + 1u] + phi[i - s] + phi[i + s];
    if params.laplacian == 0u {
        return nn - 4.0 * c;
    }
    let diag = phi[i - s - 1u] + phi[i - s + 1u] + phi[i + s - 1u] + phi[i + s + 1u];
    return (4.0 * nn + diag - 20.0 * c) / 6.0;
}

// μ_i at padded site k = global_invocation_id.x of cell i = global_invocation_id.y
// (`FreeEnergy::chemical_potential`).
@compute @workgroup_size(64)
fn chemical_potential(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = patches[gid.y];
    let site = site_of(p, gid.x);
    if !site.inside {
        return;
    }
    let i = site.i;
    if !site.interior {
        mu[i] = 0.0;
        return;
    }
    let c = phi[i];
    let lap = laplacian(i, stride(p));
    let g = sum_phi2[lattice_index(p, site.at, params.box_size)];
    let area_term = params.area * (1.0 - area[gid.y] / params.target_area);
    mu[i] = params.bulk * c * (1.0 - c) * (1.0 - 2.0 * c) - params.gradient * lap - area_term * c
        + params.repulsion * c * (g - c * c);
}
