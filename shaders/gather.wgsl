// The lattice sums of src/model/monolayer.rs (`gather`): Σ_j φ_j and Σ_j φ_j² at every site of
// the L×L lattice. Σφ² feeds the repulsion term of μ_i (free_energy.wgsl); Σφ is the coverage
// the analysis reads.
//
// Every site sums its cells in index order, as the CPU does: no atomics, and the same bits on
// every run.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(3) var<storage, read_write> sum_phi: array<f32>;
@group(0) @binding(4) var<storage, read_write> sum_phi2: array<f32>;

const TILE: u32 = 8u;
const CHUNK: u32 = 64u;

// Whether a run of `len` sites from `start` and one of TILE sites from `tile` overlap on the
// periodic axis of length l (both shorter than l).
fn runs_overlap(start: u32, len: u32, tile: u32, l: u32) -> bool {
    return (tile + l - start) % l < len || (start + l - tile) % l < TILE;
}

// The cells of the current chunk of CHUNK cells whose patch lies over this workgroup's tile:
// a flag per cell, then the flagged ones as a list in cell order.
var<workgroup> over_tile: array<u32, CHUNK>;
var<workgroup> listed: array<u32, CHUNK>;
var<workgroup> n_listed: u32;

// One workgroup per 8 × 8 tile of the lattice. The cells are taken in chunks of 64: each
// invocation tests one cell of the chunk against the tile, the first lists the cells flagged in
// cell order, and then every invocation adds the listed cells at its site. A site thus visits
// the few patches near it instead of all N, and still sums in cell order.
@compute @workgroup_size(8, 8)
fn lattice_sums(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let l = params.box_size;
    let tile = wg.xy * TILE;
    let inside = gid.x < l && gid.y < l;
    var s = 0.0;
    var s2 = 0.0;
    for (var first = 0u; first < params.n_cells; first += CHUNK) {
        let mine = first + t;
        var flag = 0u;
        if mine < params.n_cells {
            let p = patches[mine];
            flag = u32(runs_overlap(p.x0, p.w, tile.x, l) && runs_overlap(p.y0, p.h, tile.y, l));
        }
        over_tile[t] = flag;
        workgroupBarrier();
        if t == 0u {
            var n = 0u;
            for (var k = 0u; k < CHUNK; k++) {
                if over_tile[k] != 0u {
                    listed[n] = first + k;
                    n++;
                }
            }
            n_listed = n;
        }
        workgroupBarrier();
        let n = workgroupUniformLoad(&n_listed);
        for (var k = 0u; k < n; k++) {
            let p = patches[listed[k]];
            // Patch column and row of this site; both wrap around the periodic edges
            // (`Patch::row_of`, and the same for columns).
            let a = (gid.x + l - p.x0) % l;
            let b = (gid.y + l - p.y0) % l;
            if inside && a < p.w && b < p.h {
                let v = phi[p.offset + (b + 1u) * stride(p) + a + 1u];
                s += v;
                s2 += v * v;
            }
        }
        workgroupBarrier();
    }
    if inside {
        sum_phi[gid.y * l + gid.x] = s;
        sum_phi2[gid.y * l + gid.x] = s2;
    }
}
