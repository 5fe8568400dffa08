// src/model/shape.rs on the GPU: the shape tensor of Eq. 5 and its normalisation,
//
//   Q_xx = −½ Σ (∂_xφ² − ∂_yφ²),  Q_xy = −Σ ∂_xφ ∂_yφ  (central differences),
//   Q̂_i = m Q_i / √(|Q_i|² + ε²),
//
// one workgroup per cell, with the cell's area (free_energy.wgsl's μ needs it).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(5) var<storage, read_write> area: array<f32>;
@group(0) @binding(7) var<storage, read_write> shape: array<vec2<f32>>;
@group(0) @binding(8) var<storage, read_write> q_hat: array<vec2<f32>>;

const WORKGROUP: u32 = 64u;
var<workgroup> sums: array<vec4<f32>, WORKGROUP>;

// Q_i with Q̂_i, and the free energy's area A_i = Σ φ_i² over the padded patch
// (`free_energy::area`): both are sums over each cell's patch, so they share one pass and one
// dispatch. Invocation t sums the sites t, t + 64, ... in order (the padded ones for A_i, the
// interior ones for Q_i), then a fixed halving tree adds the 64 partial sums: a fixed order, so
// the same bits on every run (`shape::shape_tensor`).
@compute @workgroup_size(64)
fn area_and_shape(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let p = patches[wg.x];
    let s = stride(p);
    var a = 0.0;
    for (var k = t; k < s * (p.h + 2u); k += WORKGROUP) {
        let v = phi[p.offset + k];
        a += v * v;
    }
    var q = vec2<f32>(0.0, 0.0);
    for (var k = t; k < p.w * p.h; k += WORKGROUP) {
        let i = p.offset + (k / p.w + 1u) * s + k % p.w + 1u;
        let gx = 0.5 * (phi[i + 1u] - phi[i - 1u]);
        let gy = 0.5 * (phi[i + s] - phi[i - s]);
        q.x -= 0.5 * (gx * gx - gy * gy);
        q.y -= gx * gy;
    }
    sums[t] = vec4<f32>(a, q, 0.0);
    workgroupBarrier();
    for (var width = WORKGROUP / 2u; width > 0u; width /= 2u) {
        if t < width {
            sums[t] += sums[t + width];
        }
        workgroupBarrier();
    }
    if t == 0u {
        let total = sums[0];
        area[wg.x] = total.x;
        shape[wg.x] = total.yz;
        q_hat[wg.x] = normalise(total.yz);
    }
}

// Q̂ = m Q / √(|Q|² + ε²) (`shape::normalise`).
fn normalise(q: vec2<f32>) -> vec2<f32> {
    let eps = params.q_epsilon;
    let norm = sqrt(q.x * q.x + q.y * q.y + eps * eps);
    return vec2<f32>(params.q_magnitude * q.x / norm, params.q_magnitude * q.y / norm);
}
