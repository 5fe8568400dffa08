// src/model/multigrid.rs on the GPU: the aggregation multigrid that preconditions the friction
// CG (friction.wgsl). The same hierarchy: level 0 is C itself (its diagonal and n), each level
// k + 1 aggregates 2 × 2 sites of level k (periodic; an odd side leaves a one-site-wide last
// aggregate), its operator the Galerkin product Pᵀ A P with P piecewise constant, until the side
// is at most 6, where the level is solved exactly. The same cycle: one damped Jacobi sweep
// (ω = 2/3) from zero, coarse corrections over-corrected by 1.5 (one on level 0, two below: a
// W-cycle), one sweep after.
//
// Where it differs from the CPU, and why:
// - f32 throughout (WGSL has no f64). The CPU builds the hierarchy in f64 because the Galerkin
//   diagonal, Σ diag_f + 2 Σ internal bonds, cancels down to the small mass ξ_s n. Here every
//   level's diagonal is built without cancellation from the row-sum identity C·1 = ξ_s n, which
//   Galerkin coarsening keeps: diag = mass − Σ (bonds to the other aggregates), every term of
//   one sign (bonds are ≤ 0). The mass of an aggregate is the sum of its sites' masses.
// - The coarsest level is solved by its explicit inverse, computed in parallel (Gauss–Jordan)
//   and applied by many invocations, where the CPU uses a Cholesky factor in f64: a triangular
//   solve is a chain of n² dependent steps on one invocation, reached 16 times per W-cycle.
// - Level 0 is worked by grid-wide kernels (the restriction, `mg_smooth`, which also finishes
//   the prolongation), every coarser level by one workgroup (`mg_coarse_cycle`: 70² sites and
//   fewer at the paper's size). The restriction rides with the kernel before it: in a CG
//   iteration the update (`cg_update_restrict`), in the first application the set-up of level 1
//   (`mg_set_up_fine`); the coarser levels and the coarsest level's inverse are built by the
//   first cycle's kernel (`mg_set_up_coarse`). So an application is three dispatches, the
//   set-up none of its own.
//
// Storage: `hierarchy` holds, for every level k ≥ 1, six values per site (the diagonal, the
// bonds east, north-west, north and north-east, i.e. `FORWARD`, and the mass), then the coarsest
// level's inverse (row-major, n × n, n its number of sites). `mg_work` holds for every
// level k ≥ 1 its x, b and t (vec2: both velocity components), one after the other.

// Compiled after friction.wgsl (src/gpu/kernels.rs), whose bindings (params, n, drag, the
// diagonal, r, z, the partial sums, the scalars), `GROUP`, `tree` and helpers it uses.
@group(0) @binding(24) var<storage, read_write> hierarchy: array<f32>;
@group(0) @binding(25) var<storage, read_write> mg_work: array<vec2<f32>>;
// COARSEST_SIDE, OMEGA, OVER_CORRECTION and COARSE_CORRECTIONS are `model::multigrid`'s own,
// written in front of this file by src/gpu/kernels.rs (`Kernel::wgsl`), so the two cycles
// cannot drift apart; MAX_ROW_LANES too, so that `Kernel::serial_steps` counts what runs.
// Values per site of a level in `hierarchy`: the diagonal, four forward bonds, the mass.
const PER_SITE: u32 = 6u;
const DIAG: u32 = 0u;
const MASS: u32 = 5u;

// Level k's side and where its values sit: `coef` in `hierarchy` (six per site; for k = 0 none:
// level 0 is C's own form), `x`, `b`, `t` in `mg_work` (for k = 0 unused: level 0's vectors
// are the CG's). Computed once per kernel or per level visited, not per site.
struct Level {
    k: u32,
    m: u32,
    coef: u32,
    x: u32,
    b: u32,
    t: u32,
};

fn level(k: u32) -> Level {
    var m = params.box_size;
    var coef = 0u;
    var work = 0u;
    for (var j = 1u; j <= k; j++) {
        if j > 1u {
            coef += PER_SITE * m * m;
            work += 3u * m * m;
        }
        m = (m + 1u) / 2u;
    }
    return Level(k, m, coef, work, work + m * m, work + 2u * m * m);
}

// The index of the coarsest level (`Multigrid::new`: coarsen while the side exceeds 6).
fn coarsest() -> u32 {
    var m = params.box_size;
    var k = 0u;
    while m > COARSEST_SIDE {
        m = (m + 1u) / 2u;
        k++;
    }
    return k;
}

// Where the coarsest level's inverse starts in `hierarchy`: after the last level.
fn factor_offset(last: Level) -> u32 {
    return last.coef + PER_SITE * last.m * last.m;
}

// Site s + (dx, dy) on a periodic m × m level.
fn step_to(s: u32, dx: i32, dy: i32, m: u32) -> u32 {
    let mi = i32(m);
    let x = (i32(s % m) + dx + mi) % mi;
    let y = (i32(s / m) + dy + mi) % mi;
    return u32(y * mi + x);
}

// The aggregate (site of level k + 1) that site s of an m-wide level k belongs to.
fn aggregate(s: u32, m: u32) -> u32 {
    let mc = (m + 1u) / 2u;
    return ((s / m) / 2u) * mc + (s % m) / 2u;
}

// Which stored bond (1..4: east, north-west, north, north-east) is the one from a site in
// direction (dx, dy), and whether it is stored at the neighbour (the direction is the opposite
// of a forward one): `ALL_AS_FORWARD`.
fn forward_index(dx: i32, dy: i32) -> vec2<u32> {
    if dy == 0 && dx == 1 { return vec2<u32>(1u, 0u); }
    if dy == 1 && dx == -1 { return vec2<u32>(2u, 0u); }
    if dy == 1 && dx == 0 { return vec2<u32>(3u, 0u); }
    if dy == 1 && dx == 1 { return vec2<u32>(4u, 0u); }
    if dy == 0 && dx == -1 { return vec2<u32>(1u, 1u); }
    if dy == -1 && dx == 1 { return vec2<u32>(2u, 1u); }
    if dy == -1 && dx == 0 { return vec2<u32>(3u, 1u); }
    return vec2<u32>(4u, 1u);
}

// `FORWARD`[q − 1] as (dx, dy).
fn forward_direction(q: u32) -> vec2<i32> {
    switch q {
        case 1u: { return vec2<i32>(1, 0); }
        case 2u: { return vec2<i32>(-1, 1); }
        case 3u: { return vec2<i32>(0, 1); }
        default: { return vec2<i32>(1, 1); }
    }
}

// n on the sites in the solve, 0 elsewhere (`Weights::n`).
fn n_in_solve(x: u32) -> f32 {
    return select(0.0, weight[x], diagonal[x] > 0.0);
}

// The bond of a level between site s and s + (dx, dy): −ξ_c n n′ on level 0, stored below it.
fn bond(lv: Level, s: u32, dx: i32, dy: i32) -> f32 {
    let t = step_to(s, dx, dy, lv.m);
    if lv.k == 0u {
        return -params.xi_cell * n_in_solve(s) * n_in_solve(t);
    }
    let f = forward_index(dx, dy);
    let at = select(s, t, f.y == 1u);
    return hierarchy[lv.coef + PER_SITE * at + f.x];
}

fn level_diagonal(lv: Level, s: u32) -> f32 {
    if lv.k == 0u {
        return diagonal[s];
    }
    return hierarchy[lv.coef + PER_SITE * s + DIAG];
}

// The mass of site s: n ξ_s on level 0 (C·1 = ξ_s n), the sum over its aggregate below.
fn level_mass(lv: Level, s: u32) -> f32 {
    if lv.k == 0u {
        return n_in_solve(s) * drag[s].w;
    }
    return hierarchy[lv.coef + PER_SITE * s + MASS];
}

// Coarse site c of level k + 1 from level k (`Level::coarsen`), gathered: its diagonal as its
// mass less the bonds leaving it, each forward bond as the sum of the fine bonds that join it to
// that neighbour.
fn coarsen_site(fine: Level, coarse: Level, c: u32) {
    let m = fine.m;
    let mc = coarse.m;
    let ic = c % mc;
    let jc = c / mc;
    var coef = array<f32, 6>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    var mass = 0.0;
    var leaving = 0.0;
    for (var j = 2u * jc; j < min(2u * jc + 2u, m); j++) {
        for (var i = 2u * ic; i < min(2u * ic + 2u, m); i++) {
            let f = j * m + i;
            mass += level_mass(fine, f);
            for (var dy = -1; dy <= 1; dy++) {
                for (var dx = -1; dx <= 1; dx++) {
                    if dx == 0 && dy == 0 {
                        continue;
                    }
                    let other = aggregate(step_to(f, dx, dy, m), m);
                    if other == c {
                        continue;
                    }
                    let b = bond(fine, f, dx, dy);
                    leaving += b;
                    for (var q = 1u; q <= 4u; q++) {
                        let d = forward_direction(q);
                        if other == step_to(c, d.x, d.y, mc) {
                            coef[q] += b;
                        }
                    }
                }
            }
        }
    }
    // Outside the solve (no site of the aggregate in it) everything is 0: mass and bonds.
    coef[DIAG] = mass - leaving;
    coef[MASS] = mass;
    let o = coarse.coef + PER_SITE * c;
    for (var q = 0u; q < PER_SITE; q++) {
        hierarchy[o + q] = coef[q];
    }
}

// Level 1 from C (`Multigrid::setup`, the first `coarsen`) and the first application's
// restriction to it (r as `cg_start` stored it: α is 0): one invocation per site of level 1.
@compute @workgroup_size(256)
fn mg_set_up_fine(@builtin(global_invocation_id) gid: vec3<u32>) {
    let coarse = level(1u);
    if coarsest() >= 1u && gid.x < coarse.m * coarse.m {
        coarsen_site(level(0u), coarse, gid.x);
        restrict_to_level_one(gid.x, solve.alpha);
    }
}

fn barrier() {
    storageBarrier();
    workgroupBarrier();
}

// The first application's coarse levels: levels 2 to the coarsest built, each from the one
// above, and the coarsest level's inverse (`coarsen_rest`), then the cycle on them
// (`coarse_cycle`). One workgroup.
@compute @workgroup_size(256)
fn mg_set_up_coarse(@builtin(local_invocation_index) t: u32) {
    coarsen_rest(t);
    barrier();
    coarse_cycle(t);
}

// Levels 2 to the coarsest, each from the one above, then the coarsest level's inverse
// (`Coarsest::factor` on the CPU is a Cholesky factor; see `coarsest_inverse`).
fn coarsen_rest(t: u32) {
    let last = coarsest();
    for (var k = 1u; k < last; k++) {
        let fine = level(k);
        let coarse = level(k + 1u);
        for (var c = t; c < coarse.m * coarse.m; c += GROUP) {
            coarsen_site(fine, coarse, c);
        }
        barrier();
    }
    if last == 0u {
        return;
    }
    coarsest_inverse(level(last), t);
}

// The coarsest level's operator A⁻¹, dense (n × n, row-major after the last level), by
// Gauss–Jordan elimination without pivoting (A is symmetric positive definite) worked by the
// whole workgroup: per pivot two barrier phases of at most ⌈n²/256⌉ entries per invocation, so
// the longest chain of dependent steps is about 2n, where a Cholesky factor and its two
// triangular solves on one invocation were n³/6 and n² per application. A site outside the
// solve gets an identity row, as on the CPU.
fn coarsest_inverse(lv: Level, t: u32) {
    let m = lv.m;
    let n = m * m;
    let a = factor_offset(lv);
    // A, row by row: each invocation gathers its rows (a bond stored at the neighbour too), so
    // no two invocations add into one entry.
    for (var e = t; e < n * n; e += GROUP) {
        hierarchy[a + e] = 0.0;
    }
    barrier();
    for (var x = t; x < n; x += GROUP) {
        let d = level_diagonal(lv, x);
        hierarchy[a + x * n + x] += select(1.0, d, d > 0.0);
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                if dx != 0 || dy != 0 {
                    let y = step_to(x, dx, dy, m);
                    hierarchy[a + x * n + y] += bond(lv, x, dx, dy);
                }
            }
        }
    }
    barrier();
    // In place: for pivot k, a_ij −= a_ik a_kj / p off row and column k; then row k / p,
    // column k −a_ik / p, the pivot 1/p. p is read before the barrier that lets it change.
    for (var k = 0u; k < n; k++) {
        let p = hierarchy[a + k * n + k];
        for (var e = t; e < n * n; e += GROUP) {
            let i = e / n;
            let j = e % n;
            if i != k && j != k {
                hierarchy[a + e] -= hierarchy[a + i * n + k] * hierarchy[a + k * n + j] / p;
            }
        }
        barrier();
        for (var e = t; e < n * n; e += GROUP) {
            let i = e / n;
            let j = e % n;
            if i == k && j == k {
                hierarchy[a + e] = 1.0 / p;
            } else if i == k {
                hierarchy[a + e] /= p;
            } else if j == k {
                hierarchy[a + e] = -hierarchy[a + e] / p;
            }
        }
        barrier();
    }
}

// (A v)(s) on a level k ≥ 1, v in `mg_work` from `v0`.
fn apply_level(lv: Level, s: u32, v0: u32) -> vec2<f32> {
    var out = level_diagonal(lv, s) * mg_work[v0 + s];
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            if dx != 0 || dy != 0 {
                out += bond(lv, s, dx, dy) * mg_work[v0 + step_to(s, dx, dy, lv.m)];
            }
        }
    }
    return out;
}

// x = ω D⁻¹ b on a level, 0 outside the solve.
fn smooth_from_zero(lv: Level, t: u32) {
    for (var s = t; s < lv.m * lv.m; s += GROUP) {
        let d = level_diagonal(lv, s);
        mg_work[lv.x + s] = select(vec2<f32>(0.0, 0.0), OMEGA / d * mg_work[lv.b + s], d > 0.0);
    }
    barrier();
}

// b of the level below = Pᵀ (b − A x): the residual (into t), then its sum over each aggregate.
fn restrict_residual(lv: Level, coarse: Level, t: u32) {
    let m = lv.m;
    for (var s = t; s < m * m; s += GROUP) {
        mg_work[lv.t + s] = mg_work[lv.b + s] - apply_level(lv, s, lv.x);
    }
    barrier();
    let mc = coarse.m;
    for (var c = t; c < mc * mc; c += GROUP) {
        let ic = c % mc;
        let jc = c / mc;
        var sum = vec2<f32>(0.0, 0.0);
        for (var j = 2u * jc; j < min(2u * jc + 2u, m); j++) {
            for (var i = 2u * ic; i < min(2u * ic + 2u, m); i++) {
                sum += mg_work[lv.t + j * m + i];
            }
        }
        mg_work[coarse.b + c] = sum;
    }
    barrier();
}

// x += P x_coarse, over-corrected, on the sites in the solve.
fn prolong(lv: Level, coarse: Level, t: u32) {
    for (var s = t; s < lv.m * lv.m; s += GROUP) {
        let w = select(0.0, OVER_CORRECTION, level_diagonal(lv, s) > 0.0);
        mg_work[lv.x + s] += w * mg_work[coarse.x + aggregate(s, lv.m)];
    }
    barrier();
}

// x += ω D⁻¹ (b − A x) on a level.
fn smooth_level(lv: Level, t: u32) {
    for (var s = t; s < lv.m * lv.m; s += GROUP) {
        mg_work[lv.t + s] = mg_work[lv.b + s] - apply_level(lv, s, lv.x);
    }
    barrier();
    for (var s = t; s < lv.m * lv.m; s += GROUP) {
        let d = level_diagonal(lv, s);
        mg_work[lv.x + s] += select(vec2<f32>(0.0, 0.0), OMEGA / d * mg_work[lv.t + s], d > 0.0);
    }
    barrier();
}

// x = A⁻¹ b on the coarsest level, both components: row r of the stored inverse times b, split
// over `row_lanes(n)` invocations per row, each adding every lanes-th product in order, then a
// halving tree over the row's lanes (a fixed order): about n/lanes + log₂ lanes dependent steps
// per visit where one invocation per row took n.
fn coarsest_solve(lv: Level, t: u32) {
    let n = lv.m * lv.m;
    let a = factor_offset(lv);
    let lanes = row_lanes(n);
    let r = t / lanes;
    let j = t % lanes;
    var s = vec2<f32>(0.0, 0.0);
    if r < n {
        for (var q = j; q < n; q += lanes) {
            s += hierarchy[a + r * n + q] * mg_work[lv.b + q];
        }
    }
    tree[t] = vec4<f32>(s, 0.0, 0.0);
    for (var half = lanes / 2u; half > 0u; half = half / 2u) {
        workgroupBarrier();
        if j < half {
            tree[t] = tree[t] + tree[t + half];
        }
    }
    workgroupBarrier();
    if j == 0u && r < n {
        mg_work[lv.x + r] = tree[t].xy;
    }
    barrier();
}

// Invocations per row of the coarsest level's inverse: the most, a power of two up to
// `MAX_ROW_LANES`, that lets every row have its own (`row_lanes` in src/gpu/kernels.rs).
fn row_lanes(n: u32) -> u32 {
    var lanes = 1u;
    while lanes < MAX_ROW_LANES && 2u * lanes * n <= GROUP {
        lanes = 2u * lanes;
    }
    return lanes;
}

// Level 0's part of the cycle before the coarse levels (`Multigrid::cycle` at k = 0), at site c of
// level 1: x₀ = ω D⁻¹ r (not stored: `mg_smooth` forms it again where it needs it) and b₁ =
// Pᵀ (r − C x₀), with r after the update of step α (`residual_after`). n x₀ is formed once per
// site of the aggregate's 4 × 4 window (its 2 × 2 sites and their ring); the sums run in the
// order of the stencil loops, as `apply_level`.
fn restrict_to_level_one(c: u32, alpha: vec2<f32>) {
    let m = params.box_size;
    let one = level(1u);
    let m1 = one.m;
    let ic = c % m1;
    let jc = c / m1;
    let corner = (2u * jc) * m + 2u * ic;
    var nx0: array<vec2<f32>, 16>;
    for (var w = 0u; w < 16u; w++) {
        let y = step_to(corner, i32(w % 4u) - 1, i32(w / 4u) - 1, m);
        nx0[w] = n_in_solve(y) * smoothed_from_zero(y, alpha);
    }
    var sum = vec2<f32>(0.0, 0.0);
    for (var j = 2u * jc; j < min(2u * jc + 2u, m); j++) {
        for (var i = 2u * ic; i < min(2u * ic + 2u, m); i++) {
            let f = j * m + i;
            let w = (j - 2u * jc + 1u) * 4u + (i - 2u * ic + 1u);
            let r = residual_after(f, alpha);
            let d = diagonal[f];
            var cx = d * select(vec2<f32>(0.0, 0.0), OMEGA / d * r, d > 0.0);
            let nf = n_in_solve(f);
            if nf > 0.0 {
                var s = vec2<f32>(0.0, 0.0);
                for (var dy = -1; dy <= 1; dy++) {
                    for (var dx = -1; dx <= 1; dx++) {
                        if dx != 0 || dy != 0 {
                            s += nx0[u32(i32(w) + dy * 4 + dx)];
                        }
                    }
                }
                cx -= params.xi_cell * nf * s;
            }
            sum += r - cx;
        }
    }
    mg_work[one.b + c] = sum;
}

// x₀ = ω D⁻¹ r at site y of level 0, 0 outside the solve.
fn smoothed_from_zero(y: u32, alpha: vec2<f32>) -> vec2<f32> {
    let d = diagonal[y];
    return select(vec2<f32>(0.0, 0.0), OMEGA / d * residual_after(y, alpha), d > 0.0);
}

// A CG iteration's update (`update_step` in friction.wgsl) and, in the same dispatch, the next
// application's restriction to level 1 from the updated r. The update stores no r, so the r the
// restriction reads around its aggregate is the same in every workgroup. The aggregates are
// dealt round the workgroups (invocation t of workgroup g takes site t·G + g of level 1, G
// workgroups), so that every workgroup takes its share of the restriction's work.
@compute @workgroup_size(256)
fn cg_update_restrict(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
                      @builtin(workgroup_id) wg: vec3<u32>) {
    let alpha = update_step(gid.x, t, wg.x);
    let one = level(1u);
    let c = t * groups() + wg.x;
    if any(alpha != vec2<f32>(0.0, 0.0)) && coarsest() >= 1u && c < one.m * one.m {
        restrict_to_level_one(c, alpha);
    }
}

// The coarse levels' part of the cycle: x₁ ≈ A₁⁻¹ b₁ by the W-cycle from level 1 down, in one
// workgroup. WGSL has no recursion, so `Multigrid::cycle`'s calls are unrolled into a walk:
// down (smooth from zero, restrict) to the coarsest, solve it, then up (prolong), down again
// while a level has coarse corrections left, and smooth on the way up.
@compute @workgroup_size(256)
fn mg_coarse_cycle(@builtin(local_invocation_index) t: u32) {
    coarse_cycle(t);
}

fn coarse_cycle(t: u32) {
    let last = coarsest();
    if last == 0u {
        return;
    }
    if solve_finished(t) {
        return;
    }
    var levels: array<Level, 16>;
    for (var j = 1u; j <= last; j++) {
        levels[j] = level(j);
    }
    var corrections = array<u32, 16>();
    var k = 1u;
    var down = true;
    loop {
        if down {
            if k == last {
                coarsest_solve(levels[k], t);
                if k == 1u {
                    break;
                }
                down = false;
                k = k - 1u;
                continue;
            }
            smooth_from_zero(levels[k], t);
            corrections[k] = 0u;
            restrict_residual(levels[k], levels[k + 1u], t);
            k = k + 1u;
            continue;
        }
        prolong(levels[k], levels[k + 1u], t);
        corrections[k] += 1u;
        if corrections[k] < COARSE_CORRECTIONS {
            restrict_residual(levels[k], levels[k + 1u], t);
            k = k + 1u;
            down = true;
            continue;
        }
        smooth_level(levels[k], t);
        if k == 1u {
            break;
        }
        k = k - 1u;
    }
}

// Level 0's part after the coarse levels, r as the latest update left it (`residual_after`):
// the prolongation x₀′ = x₀ + P x₁ (over-corrected) and the last sweep
// z = x₀′ + ω D⁻¹ (r − C x₀′), x₀′ formed wherever it is needed; z into its section of
// `vectors`, and the partial sums of r·z with the stop flags (`RZ` of `partials`).
@compute @workgroup_size(256)
fn mg_smooth(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) t: u32,
             @builtin(workgroup_id) wg: vec3<u32>) {
    if finished_hint(t) {
        return;
    }
    let done = done_of(total_of(t, RR));
    if all(done) {
        mark_finished(t);
        return;
    }
    let m = params.box_size;
    let x = gid.x;
    // Level 1's x, or none where level 0 is the coarsest.
    let coarse = select(-1, i32(level(1u).x), coarsest() >= 1u);
    let alpha = solve.alpha;
    var rz = vec2<f32>(0.0, 0.0);
    if x < m * m {
        var z = vec2<f32>(0.0, 0.0);
        let d = diagonal[x];
        let r = residual_after(x, alpha);
        if d > 0.0 {
            let own = prolonged(x, m, coarse, alpha);
            var s = vec2<f32>(0.0, 0.0);
            for (var dy = -1; dy <= 1; dy++) {
                for (var dx = -1; dx <= 1; dx++) {
                    if dx != 0 || dy != 0 {
                        let y = step_to(x, dx, dy, m);
                        s += n_in_solve(y) * prolonged(y, m, coarse, alpha);
                    }
                }
            }
            let cx = d * own - params.xi_cell * weight[x] * s;
            z = own + OMEGA / d * (r - cx);
        }
        vectors[at(PRECONDITIONED, x)] = z;
        rz = r * z;
    }
    store_partial(t, RZ, wg.x, vec4<f32>(rz, stop_flags(t, done)));
}

// x₀′ at site y of level 0: ω D⁻¹ r + 1.5 x₁ of its aggregate (x₁ from `coarse` in `mg_work`,
// none if −1), 0 outside the solve.
fn prolonged(y: u32, m: u32, coarse: i32, alpha: vec2<f32>) -> vec2<f32> {
    let d = diagonal[y];
    var x1 = vec2<f32>(0.0, 0.0);
    if coarse >= 0 {
        x1 = mg_work[u32(coarse) + aggregate(y, m)];
    }
    return select(vec2<f32>(0.0, 0.0), OMEGA / d * residual_after(y, alpha) + OVER_CORRECTION * x1, d > 0.0);
}
