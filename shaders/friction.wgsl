// src/model/friction.rs on the GPU: the force balance of Eq. 2 solved on the lattice for the
// local mean velocity u = V/n,
//
//   C u = F,  C = diag(n (ξ_s + ξ_c N)) − ξ_c diag(n) A₈ diag(n),   N = Σ_{N8} n,
//
// then every cell's velocity v_i = [f_i + ξ_c S] / [ξ_s + ξ_c N], S = Σ_{N8} n u (motion.wgsl
// reads the mobility and the pull from `drag`). Sites with n = 0 are outside the solve: C's row
// there is zero and u stays 0.
//
// Conjugate gradients preconditioned by one multigrid cycle (multigrid.wgsl, as the CPU) or by
// Jacobi, z = r / diag(C) (`jacobi`), both velocity components at once (C is real: the x and y components are two independent systems, carried here as the
// two lanes of a vec2, each with its own step lengths α and β and its own stop). The scalars
// live on the device (`Solve`); nothing is read back. The host records a fixed number of
// iterations; a component that has met its target, ‖r_c‖ ≤ tolerance·‖F‖/√2 (as the CPU's),
// takes no further steps (α = 0), and once both have, the per-site kernels return at once.
//
// Sums (r·z, ‖r‖², p·Cp, ‖F‖²) are made in a fixed order: each workgroup of 256 sites adds its
// sites in a halving tree into one partial sum (`partials`), and the kernel that needs the total
// adds the partial sums in the same way, in every workgroup alike (`total_of`): the
// same bits everywhere, and no one-workgroup kernel between the grid-wide ones. No float atomics:
// the same state on the same adapter gives the same bits. The scalars are derived from the
// partial sums where they are used, never written where a kernel that reads them runs: a part
// of `partials` is written by one kernel and read only by the kernels after it, and `solve`
// keeps only what the host reads and the previous r·z (written by `cg_update`, read by the next
// `cg_product`).
//
// The vectors r, p, p′, q and z share one buffer (`vectors`, sections of L² sites; `Slot::CgVectors`).
// r is stored one update behind: `cg_update` forms r − α q where it needs it and leaves it to the
// kernels after it (`residual_now`, with the α it wrote into `solve`), and the next `cg_product`,
// which reads no neighbour's r, stores it. So the multigrid's restriction, which needs the new r
// at its aggregate's neighbours, runs in the update's own dispatch (`cg_update_restrict` in
// multigrid.wgsl) without racing the update's writes.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(11) var<storage, read> weight: array<f32>;
@group(0) @binding(12) var<storage, read> force: array<vec2<f32>>;
@group(0) @binding(13) var<storage, read_write> drag: array<vec4<f32>>;
@group(0) @binding(19) var<storage, read_write> diagonal: array<f32>;
@group(0) @binding(20) var<storage, read_write> mean_velocity: array<vec2<f32>>;
@group(0) @binding(21) var<storage, read_write> vectors: array<vec2<f32>>;
@group(0) @binding(22) var<storage, read_write> partials: array<vec4<f32>>;
@group(0) @binding(23) var<storage, read_write> solve: Solve;

// The sections of `vectors` (`CG_VECTORS` in src/gpu/buffers.rs): r (stored one update behind),
// p, p′ = z + β p, q = C p′ and z = M r.
const RESIDUAL: u32 = 0u;
const DIRECTION: u32 = 1u;
const DIRECTION_NEXT: u32 = 2u;
const PRODUCT: u32 = 3u;
const PRECONDITIONED: u32 = 4u;

// Where site x of a section is in `vectors`.
fn at(section: u32, x: u32) -> u32 {
    return section * params.box_size * params.box_size + x;
}

// r at site y after the latest update, r − α q with the update's α (0 for a component done, and
// at the start of a solve, where r is stored as it is).
fn residual_after(y: u32, alpha: vec2<f32>) -> vec2<f32> {
    let r = vectors[at(RESIDUAL, y)];
    let step = select(alpha * vectors[at(PRODUCT, y)], vec2<f32>(0.0, 0.0), alpha == vec2<f32>(0.0, 0.0));
    return r - step;
}

// r at site y now, in a kernel after the update that wrote `solve.alpha`.
fn residual_now(y: u32) -> vec2<f32> {
    return residual_after(y, solve.alpha);
}

// The CG scalars of both components (x, y), as `SolveScalars` in src/gpu/buffers.rs.
struct Solve {
    // r·z of the current residual.
    rz: vec2<f32>,
    alpha: vec2<f32>,
    beta: vec2<f32>,
    // ‖r‖² of the current residual.
    rr: vec2<f32>,
    // (tolerance·‖F‖)²/2: each component's target for ‖r‖².
    target2: f32,
    // ‖F‖², both components.
    ff: f32,
    // Iterations taken, and whether the component has met its target (1) or not (0).
    iterations: vec2<u32>,
    done: vec2<u32>,
    // Solves that ended without meeting their target since the host last reset it: sticky, so
    // that a failure in any step of a submission is seen at the next check.
    unconverged: u32,
    // The most iterations any solve took since the host last reset it (sticky, as above): what
    // the host sizes the recorded iterations by.
    most_iterations: u32,
    // Solves that met their target on the recursive residual but missed the CPU's tolerance on
    // the true one, F − C u (sticky, as above; `friction_check`).
    inaccurate: u32,
    // 1 once a workgroup found both components done in this solve (`solve_finished`): a hint
    // that spares the later kernels' sums, never a different answer.
    finished: atomic<u32>,
};

// The part of the CPU's tolerance the recursive residual is held to (`RECURSIVE_RESIDUAL_MARGIN`
// in src/gpu/buffers.rs, which `params.friction_tolerance` is multiplied by): the true residual
// is checked against the tolerance itself.
const RECURSIVE_RESIDUAL_MARGIN: f32 = 0.5;

const GROUP: u32 = 256u;

// `partials` holds four parts of one vec4 per workgroup g of the lattice (G workgroups), at
// part·G + g, each written by one kernel and read only by later ones: RR (‖r‖² of x and y and
// ‖F‖², from `cg_start` and `cg_update`), PQ (p·Cp of x and y, 0 for a component done, and the
// r·z `cg_product` used, from `cg_product`), RZ (r·z of x and y and the stop flags, from the
// preconditioner) and TRUE (‖F − C u‖² of x and y, from `friction_pull`).
const RR: u32 = 0u;
const PQ: u32 = 1u;
const RZ: u32 = 2u;
const TRUE: u32 = 3u;

fn groups() -> u32 {
    let l = params.box_size;
    return (l * l + GROUP - 1u) / GROUP;
}

var<workgroup> tree: array<vec4<f32>, 256>;

// Adds tree[0..width) into tree[0] by halving (a fixed order); every invocation of the
// workgroup calls it.
fn reduce_tree(t: u32, width: u32) {
    for (var half = width / 2u; half > 0u; half = half / 2u) {
        workgroupBarrier();
        if t < half {
            tree[t] = tree[t] + tree[t + half];
        }
    }
    workgroupBarrier();
}

// Adds every invocation's value over the workgroup (`reduce_tree`) and stores the sum as
// workgroup g's entry of `part` in `partials`; every invocation calls it.
fn store_partial(t: u32, part: u32, g: u32, value: vec4<f32>) {
    tree[t] = value;
    reduce_tree(t, GROUP);
    if t == 0u {
        partials[part * groups() + g] = tree[0];
    }
}

// Adds a part's partial sums, one per workgroup of the lattice, in a fixed order: invocation
// t < TOTAL_LANES adds entries t, t + TOTAL_LANES, …, then a halving tree over the lanes (few
// barrier phases: every kernel that needs a scalar takes one such total). Every invocation
// calls it and gets the total.
const TOTAL_LANES: u32 = 16u;

fn total_of(t: u32, part: u32) -> vec4<f32> {
    let first = part * groups();
    var s = vec4<f32>(0.0, 0.0, 0.0, 0.0);
    if t < TOTAL_LANES {
        for (var g = t; g < groups(); g += TOTAL_LANES) {
            s += partials[first + g];
        }
    }
    workgroupBarrier();
    tree[t] = s;
    reduce_tree(t, TOTAL_LANES);
    // Uniform by construction, and known so to WGSL (a kernel may return on it, then meet a
    // barrier); the barrier after it keeps the next sum from overwriting it too soon.
    let total = workgroupUniformLoad(&tree[0]);
    workgroupBarrier();
    return total;
}

// Each component's target for ‖r‖², (tolerance·‖F‖)²/2, from ‖F‖².
fn target2_of(ff: f32) -> f32 {
    let tol = params.friction_tolerance;
    return tol * tol * ff * 0.5;
}

// Whether each component has met its target, from the latest ‖r‖² and ‖F‖² (`RR`), the same in
// every workgroup. A residual that is not a finite number never meets it (by its bits:
// `is_finite2`), so such a solve counts as unconverged and the step is put back. Once a
// component is done its α is 0 and its r no longer changes, so the answer stays.
fn done_of(rr_ff: vec4<f32>) -> vec2<bool> {
    let target2 = target2_of(rr_ff.z);
    return is_finite2(rr_ff.xy) & vec2<bool>(is_finite(target2)) & (rr_ff.xy <= vec2<f32>(target2, target2));
}

var<workgroup> finished_here: u32;

// The hint that both components are done in this solve, uniformly across the workgroup.
fn finished_hint(t: u32) -> bool {
    if t == 0u {
        finished_here = atomicLoad(&solve.finished);
    }
    return workgroupUniformLoad(&finished_here) != 0u;
}

// Records that both components are done: a workgroup of a later kernel then skips its sums.
// Set only on a finding every workgroup would make, so a workgroup that reads it a moment too
// early sums and finds the same.
fn mark_finished(t: u32) {
    if t == 0u {
        atomicStore(&solve.finished, 1u);
    }
}

// Whether both components have met their target: the kernels after that return at once. From
// the hint where it is set, else from the sums of ‖r‖² (`RR`); a kernel that writes `RR` must not
// ask (`cg_update` asks `PQ`).
fn solve_finished(t: u32) -> bool {
    if finished_hint(t) {
        return true;
    }
    let done = all(done_of(total_of(t, RR)));
    if done {
        mark_finished(t);
    }
    return done;
}

// The 8 neighbours of lattice site x on the periodic L × L lattice.
fn neighbour(x: u32, dx: i32, dy: i32) -> u32 {
    let l = i32(params.box_size);
    let gx = (i32(x % params.box_size) + dx + l) % l;
    let gy = (i32(x / params.box_size) + dy + l) % l;
    return u32(gy * l + gx);
}

// Σ_{N8} n(x') u(x') (`lattice::neighbour_sum8` of n u): the pull's S, and C u's coupling.
fn velocity_sum8(x: u32) -> vec2<f32> {
    var s = vec2<f32>(0.0, 0.0);
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            if dx != 0 || dy != 0 {
                let y = neighbour(x, dx, dy);
                s += weight[y] * mean_velocity[y];
            }
        }
    }
    return s;
}

// (C u)(x) = d u(x) − ξ_c n(x) Σ_{N8} n u (`multigrid::weights_row`), given the diagonal d > 0
// and the neighbour sum.
fn c_times_u(x: u32, d: f32, sum8: vec2<f32>) -> vec2<f32> {
    return d * mean_velocity[x] - params.xi_cell * weight[x] * sum8;
}

// The operator for the current n at site x (`FrictionSolver::prepare`): N, diag(C) =
// n (ξ_s + ξ_c N) (0 where n = 0) and the mobility 1/[ξ_s + ξ_c N] into `drag`.z (ξ_s(x) is
// `drag`.w); returns the diagonal.
fn set_up_site(x: u32) -> f32 {
    var nb = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            if dx != 0 || dy != 0 {
                nb += weight[neighbour(x, dx, dy)];
            }
        }
    }
    let xi_s = drag[x].w;
    let total = xi_s + params.xi_cell * nb;
    drag[x].z = 1.0 / total;
    let n = weight[x];
    let d = select(0.0, n * total, n > 0.0);
    diagonal[x] = d;
    return d;
}

// The solve's start: the operator for the current n (`set_up_site`), then r = F − C u from the
// warm start u (C's row at x needs only its own diagonal), and partial sums of ‖r‖² and ‖F‖²
// (`Component::load` and the start of `Component::pcg`). The previous r·z is cleared, so the
// first direction is z alone (β = 0: the old p is not read).
@compute @workgroup_size(256)
fn cg_start(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
            @builtin(workgroup_id) wg: vec3<u32>) {
    let x = gid.x;
    let l = params.box_size;
    if x == 0u {
        solve.rz = vec2<f32>(0.0, 0.0);
        solve.alpha = vec2<f32>(0.0, 0.0);
        solve.beta = vec2<f32>(0.0, 0.0);
        solve.iterations = vec2<u32>(0u, 0u);
        atomicStore(&solve.finished, 0u);
    }
    var rr = vec2<f32>(0.0, 0.0);
    var ff = 0.0;
    if x < l * l {
        let d = set_up_site(x);
        ff = force_squared(x);
        if d > 0.0 {
            let r = force[x] - c_times_u(x, d, velocity_sum8(x));
            vectors[at(RESIDUAL, x)] = r;
            rr = r * r;
        } else {
            vectors[at(RESIDUAL, x)] = vec2<f32>(0.0, 0.0);
        }
    }
    store_partial(t, RR, wg.x, vec4<f32>(rr, ff, 0.0));
}

// ‖F(x)‖², over every site: F vanishes where n does (every weight is 0 there), so this is the
// sum over the solve's sites, and `cg_update` can add it again without the diagonal.
fn force_squared(x: u32) -> f32 {
    let f = force[x];
    return dot(f, f);
}

// z = M r by Jacobi, r / diag(C) in the solve and 0 outside, into `preconditioned`; partial
// sums of r·z.
@compute @workgroup_size(256)
fn jacobi(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
          @builtin(workgroup_id) wg: vec3<u32>) {
    if finished_hint(t) {
        return;
    }
    let done = done_of(total_of(t, RR));
    if all(done) {
        mark_finished(t);
        return;
    }
    let x = gid.x;
    let l = params.box_size;
    var rz = vec2<f32>(0.0, 0.0);
    if x < l * l {
        let d = diagonal[x];
        let r = residual_now(x);
        let z = select(vec2<f32>(0.0, 0.0), r / d, d > 0.0);
        vectors[at(PRECONDITIONED, x)] = z;
        rz = r * z;
    }
    store_partial(t, RZ, wg.x, vec4<f32>(rz, stop_flags(t, done)));
}

// The stop flags as the preconditioner writes them beside r·z: 1 done, 0 not, given by the
// first invocation only (the tree adds what every invocation gives).
fn stop_flags(t: u32, done: vec2<bool>) -> vec2<f32> {
    return select(vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 1.0), done & vec2<bool>(t == 0u));
}

// An iteration's start for each component still iterating: β = (r·z)_new / (r·z)_old (0 at the
// first iteration, whose p is 0), the direction p′ = z + β p, q = C p′ and partial sums of p′·q
// (0 for a component done, which keeps its p). r·z and the stop flags are the preconditioner's
// (`RZ`: every workgroup wrote the same flags, so a flag's sum is positive when it is set). p′
// goes to p′'s section, since the neighbours' p is read here; `cg_update` makes it p. The
// r·z used goes beside the sums, for `cg_update`'s α. First the previous update's r is stored
// (no neighbour's r is read here, and q is replaced only after).
@compute @workgroup_size(256)
fn cg_product(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
              @builtin(workgroup_id) wg: vec3<u32>) {
    if finished_hint(t) {
        return;
    }
    let rz_flags = total_of(t, RZ);
    let done = rz_flags.zw > vec2<f32>(0.0, 0.0);
    if all(done) {
        mark_finished(t);
        return;
    }
    let rz = rz_flags.xy;
    let old = solve.rz;
    let beta = select(vec2<f32>(0.0, 0.0), rz / old, old != vec2<f32>(0.0, 0.0));
    let x = gid.x;
    let l = params.box_size;
    var pq = vec2<f32>(0.0, 0.0);
    if x < l * l {
        vectors[at(RESIDUAL, x)] = residual_now(x);
        let d = diagonal[x];
        let p = next_direction(x, beta, done);
        var q = vec2<f32>(0.0, 0.0);
        if d > 0.0 {
            var s = vec2<f32>(0.0, 0.0);
            for (var dy = -1; dy <= 1; dy++) {
                for (var dx = -1; dx <= 1; dx++) {
                    if dx != 0 || dy != 0 {
                        let y = neighbour(x, dx, dy);
                        s += weight[y] * next_direction(y, beta, done);
                    }
                }
            }
            q = d * p - params.xi_cell * weight[x] * s;
        }
        vectors[at(DIRECTION_NEXT, x)] = p;
        vectors[at(PRODUCT, x)] = q;
        pq = select(p * q, vec2<f32>(0.0, 0.0), done);
    }
    // r·z once per workgroup (the tree adds what every invocation gives).
    store_partial(t, PQ, wg.x, vec4<f32>(pq, select(vec2<f32>(0.0, 0.0), rz, t == 0u)));
}

// p′ = z + β p at site y for the components still iterating (z alone where β = 0: the first
// iteration, whose old p is not this solve's), p for those done.
fn next_direction(y: u32, beta: vec2<f32>, done: vec2<bool>) -> vec2<f32> {
    let p = vectors[at(DIRECTION, y)];
    let bp = select(beta * p, vec2<f32>(0.0, 0.0), beta == vec2<f32>(0.0, 0.0));
    return select(vectors[at(PRECONDITIONED, y)] + bp, p, done);
}

// α = r·z / p′·Cp′ for each component still iterating (p′·Cp′ > 0 there; `cg_product` wrote 0
// for a component done, whose α is then 0), u += α p′, p = p′, and partial sums of the new r's
// ‖r‖² and ‖F‖² (r − α q, not stored: see `residual_now`). r·z is the one `cg_product` used
// (beside its first sum: every workgroup wrote the same). The first invocation keeps it for the
// next β, writes α for the kernels after and counts the iteration. Returns α: 0 where nothing
// was updated, the same in every invocation.
fn update_step(x: u32, t: u32, g: u32) -> vec2<f32> {
    if finished_hint(t) {
        return vec2<f32>(0.0, 0.0);
    }
    let pq = total_of(t, PQ).xy;
    let running = pq != vec2<f32>(0.0, 0.0);
    if !any(running) {
        if x == 0u {
            solve.alpha = vec2<f32>(0.0, 0.0);
        }
        return vec2<f32>(0.0, 0.0);
    }
    let rz = partials[PQ * groups()].zw;
    let alpha = select(vec2<f32>(0.0, 0.0), rz / pq, running);
    let l = params.box_size;
    if x == 0u {
        let old = solve.rz;
        let beta = select(vec2<f32>(0.0, 0.0), rz / old, old != vec2<f32>(0.0, 0.0));
        solve.beta = select(vec2<f32>(0.0, 0.0), beta, running);
        solve.alpha = alpha;
        solve.rz = select(old, rz, running);
        solve.iterations += select(vec2<u32>(0u, 0u), vec2<u32>(1u, 1u), running);
    }
    var rr = vec2<f32>(0.0, 0.0);
    var ff = 0.0;
    if x < l * l {
        let p = vectors[at(DIRECTION_NEXT, x)];
        vectors[at(DIRECTION, x)] = p;
        mean_velocity[x] += alpha * p;
        let r = residual_after(x, alpha);
        rr = r * r;
        ff = force_squared(x);
    }
    store_partial(t, RR, g, vec4<f32>(rr, ff, 0.0));
    return alpha;
}

// An iteration's update (`update_step`), with the Jacobi preconditioner after it.
@compute @workgroup_size(256)
fn cg_update(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
             @builtin(workgroup_id) wg: vec3<u32>) {
    _ = update_step(gid.x, t, wg.x);
}

// The pull ξ_c S, S = Σ_{N8} n u, into `drag`.xy (`FrictionSolver::pull_from_solution`); where
// F vanished everywhere the solution is u = 0, as on the CPU. Also the partial sums of the true
// residual's ‖F − C u‖², which `friction_check` holds to the tolerance: the CG's own residual
// is updated recursively and drifts from the true one in f32.
@compute @workgroup_size(256)
fn friction_pull(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
                 @builtin(workgroup_id) wg: vec3<u32>) {
    let sums = total_of(t, RR);
    let done = done_of(sums);
    let last = sums.xy;
    let ff = sums.z;
    let x = gid.x;
    let l = params.box_size;
    var rr = vec2<f32>(0.0, 0.0);
    if x < l * l {
        if x == 0u {
            solve.done = select(vec2<u32>(0u, 0u), vec2<u32>(1u, 1u), done);
            solve.rr = last;
            solve.ff = ff;
            solve.target2 = target2_of(ff);
            if !all(done) {
                solve.unconverged += 1u;
            }
            solve.most_iterations = max(solve.most_iterations, max(solve.iterations.x, solve.iterations.y));
        }
        if ff == 0.0 {
            mean_velocity[x] = vec2<f32>(0.0, 0.0);
            drag[x] = vec4<f32>(0.0, 0.0, drag[x].zw);
        } else {
            let sum8 = velocity_sum8(x);
            drag[x] = vec4<f32>(params.xi_cell * sum8, drag[x].zw);
            let d = diagonal[x];
            if d > 0.0 {
                let r = force[x] - c_times_u(x, d, sum8);
                rr = r * r;
            }
        }
    }
    store_partial(t, TRUE, wg.x, vec4<f32>(rr, 0.0, 0.0));
}

// The true residual of each component against the CPU's tolerance, ‖F − C u‖_c² ≤
// (tolerance · ‖F‖)²/2; a solve that misses it (or whose residual is not a finite number, by
// its bits) is counted in `inaccurate`, so that the host does not take a step the CPU would
// have refused.
@compute @workgroup_size(256)
fn friction_check(@builtin(local_invocation_index) t: u32) {
    let rr = total_of(t, TRUE).xy;
    if t == 0u && solve.ff != 0.0 {
        let target2 = solve.target2 / (RECURSIVE_RESIDUAL_MARGIN * RECURSIVE_RESIDUAL_MARGIN);
        let met = is_finite2(rr) & vec2<bool>(is_finite(target2)) & (rr <= vec2<f32>(target2, target2));
        if !all(met) {
            solve.inaccurate += 1u;
        }
    }
}
