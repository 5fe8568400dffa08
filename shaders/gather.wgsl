// The lattice sums of src/model/monolayer.rs (`gather` and `gather_pair`) at every site of the
// L×L lattice:
// - `lattice_sums`: Σ_j φ_j and Σ_j φ_j². Σφ² feeds the repulsion term of μ_i
//   (free_energy.wgsl); Σφ is the coverage the analysis reads.
// - `friction_sums`: n = Σ_j w_j and F = Σ_j w_j f_j, the weights and the force of the friction
//   balance (Eq. 2), with w_j of `motion::friction_weight`.
//
// Every site sums its cells in index order, as the CPU does: no atomics, and the same bits on
// every run.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> patches: array<Patch>;
@group(0) @binding(2) var<storage, read> phi: array<f32>;
@group(0) @binding(3) var<storage, read_write> sum_phi: array<f32>;
@group(0) @binding(4) var<storage, read_write> sum_phi2: array<f32>;
@group(0) @binding(9) var<storage, read> fx: array<f32>;
@group(0) @binding(10) var<storage, read> fy: array<f32>;
@group(0) @binding(11) var<storage, read_write> weight: array<f32>;
@group(0) @binding(12) var<storage, read_write> force: array<vec2<f32>>;

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

// Lists, in cell order, the cells first .. first + CHUNK whose patch lies over the tile whose
// corner is `tile`, and returns how many. Every invocation of the workgroup calls it: each
// tests one cell, then the first compacts the flags.
fn list_chunk(first: u32, t: u32, tile: vec2<u32>) -> u32 {
    let l = params.box_size;
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
    return workgroupUniformLoad(&n_listed);
}

// The padded index of lattice site `site` in patch p, or none (an index past φ's end) if the
// patch does not cover it. Column and row wrap around the periodic edges (`Patch::row_of`,
// and the same for columns).
fn index_in(p: Patch, site: vec2<u32>) -> u32 {
    let l = params.box_size;
    let a = (site.x + l - p.x0) % l;
    let b = (site.y + l - p.y0) % l;
    if a < p.w && b < p.h {
        return p.offset + (b + 1u) * stride(p) + a + 1u;
    }
    return arrayLength(&phi);
}

// One workgroup per 8 × 8 tile of the lattice. The cells are taken in chunks of 64
// (`list_chunk`), and each site adds the listed cells: it visits the few patches near it
// instead of all N, and still sums in cell order.
@compute @workgroup_size(8, 8)
fn lattice_sums(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let l = params.box_size;
    let inside = gid.x < l && gid.y < l;
    var s = 0.0;
    var s2 = 0.0;
    for (var first = 0u; first < params.n_cells; first += CHUNK) {
        let n = list_chunk(first, t, wg.xy * TILE);
        for (var k = 0u; k < n; k++) {
            let i = index_in(patches[listed[k]], gid.xy);
            if inside && i < arrayLength(&phi) {
                let v = phi[i];
                s += v;
                s2 += v * v;
            }
        }
        // The list is rewritten by the next chunk only after every site has read it.
        workgroupBarrier();
    }
    if inside {
        sum_phi[gid.y * l + gid.x] = s;
        sum_phi2[gid.y * l + gid.x] = s2;
    }
}

// w_j(x) of cell j at a site of its patch where φ_j = v (`motion::friction_weight`).
fn friction_weight(v: f32) -> f32 {
    switch params.friction_weights {
        // φ, clamped: φ undershoots 0 and overshoots 1 near interfaces.
        case 0u: {
            return clamp(v, 0.0, 1.0);
        }
        // Presence: 1 where φ exceeds the threshold.
        case 1u: {
            return select(0.0, 1.0, v > params.presence_threshold);
        }
        // Subdomain: 1 on the whole patch.
        default: {
            return 1.0;
        }
    }
}

// n and F at every site, tiled and in cell order as `lattice_sums`.
@compute @workgroup_size(8, 8)
fn friction_sums(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) t: u32,
) {
    let l = params.box_size;
    let inside = gid.x < l && gid.y < l;
    var n_sum = 0.0;
    var f_sum = vec2<f32>(0.0, 0.0);
    for (var first = 0u; first < params.n_cells; first += CHUNK) {
        let n = list_chunk(first, t, wg.xy * TILE);
        for (var k = 0u; k < n; k++) {
            let i = index_in(patches[listed[k]], gid.xy);
            if inside && i < arrayLength(&phi) {
                let w = friction_weight(phi[i]);
                n_sum += w;
                f_sum += vec2<f32>(w * fx[i], w * fy[i]);
            }
        }
        workgroupBarrier();
    }
    if inside {
        weight[gid.y * l + gid.x] = n_sum;
        force[gid.y * l + gid.x] = f_sum;
    }
}
