// The lattice sums of src/model/monolayer.rs (`gather`): Σ_j φ_j and Σ_j φ_j² at every site of
// the L×L lattice. Σφ² feeds the repulsion term of μ_i (free_energy.wgsl); Σφ is the coverage
// the analysis reads.
//
// One invocation per lattice site visits the cells in index order, as the CPU does, so every
// site sums in cell order: no atomics, and the same bits on every run.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(3) var<storage, read_write> sum_phi: array<f32>;
@group(0) @binding(4) var<storage, read_write> sum_phi2: array<f32>;

@compute @workgroup_size(8, 8)
fn lattice_sums(@builtin(global_invocation_id) gid: vec3<u32>) {
    let l = params.box_size;
    if gid.x >= l || gid.y >= l {
        return;
    }
    var s = 0.0;
    var s2 = 0.0;
    for (var i = 0u; i < params.n_cells; i++) {
        let p = patches[i];
        // Patch column and row of this site; both wrap around the periodic edges
        // (`Patch::row_of`, and the same for columns).
        let a = (gid.x + l - p.x0) % l;
        let b = (gid.y + l - p.y0) % l;
        if a < p.w && b < p.h {
            let v = phi[p.offset + (b + 1u) * stride(p) + a + 1u];
            s += v;
            s2 += v * v;
        }
    }
    sum_phi[gid.y * l + gid.x] = s;
    sum_phi2[gid.y * l + gid.x] = s2;
}
