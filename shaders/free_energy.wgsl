// src/model/free_energy.rs on the GPU: with the area A_i = Σ φ_i² of each cell (summed in
// shape.wgsl's pass over the patch, `area_and_shape`),
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
@group(0) @binding(5) var<storage, read> area: array<f32>;
@group(0) @binding(6) var<storage, read_write> mu: array<f32>;

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
