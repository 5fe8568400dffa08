// What every compute stage of the GPU stepper shares (src/gpu/): the parameters and
// the cells' patches. src/gpu/kernels.rs prepends this file to each stage's file, as the
// renderer does with common.wgsl.
//
// Layouts are written by src/gpu/buffers.rs (`GpuParams`, `GpuPatch`: the same fields in the
// same order). Every stage binds its buffers at the same binding numbers (`Slot` in
// src/gpu/buffers.rs), so a buffer has one number in every file.

// The coefficients of src/model/free_energy.rs (`FreeEnergy`), the knobs of shape.rs,
// forces.rs and motion.rs, and Heun's Δt and range check (monolayer.rs), in f32.
struct Params {
    // L, the side of the periodic lattice.
    box_size: u32,
    n_cells: u32,
    // 0: five-point Laplacian, 1: nine-point (`Laplacian`).
    laplacian: u32,
    // 0: f^p = -∇μ, 1: f^p = -φ∇μ (`PassiveForce`).
    passive: u32,
    // 8γ/λ, 2γλ, 4μ/πR², πR², cκ/λ.
    bulk: f32,
    gradient: f32,
    area: f32,
    target_area: f32,
    repulsion: f32,
    // m and ε of Q̂ = m Q / √(|Q|² + ε²).
    q_magnitude: f32,
    q_epsilon: f32,
    // ζ of this phase (0 during relaxation).
    zeta: f32,
    // 0: w = φ clamped, 1: presence, 2: the whole patch (`FrictionWeights`).
    friction_weights: u32,
    // φ above which a cell is present (`presence_threshold`).
    presence_threshold: f32,
    // 0: central differences in −v·∇φ, 1: upwind (`Advection`).
    advection: u32,
    // J₀ of Eq. 1.
    j0: f32,
    // Δt, and the range [φ_min, φ_max] Heun's corrector checks φ against.
    dt: f32,
    phi_min: f32,
    phi_max: f32,
    // ξ_cell of this phase (0 during relaxation), and the relative tolerance the friction CG
    // asks of its recursive residual: the CPU's times `RECURSIVE_RESIDUAL_MARGIN`
    // (src/gpu/buffers.rs; shaders/friction.wgsl).
    xi_cell: f32,
    friction_tolerance: f32,
    // The patches (src/model/monolayer.rs `update_patches`; shaders/cell.wgsl): the square's
    // side during relaxation, the margin beyond the support when active, and which phase this
    // is (0: relaxation, 1: active).
    relax_patch_size: u32,
    patch_margin: u32,
    active_phase: u32,
};

// One cell's patch (src/model/lattice.rs `Patch`) and where its padded storage starts in the
// per-cell arrays (φ, μ, f): (w + 2) × (h + 2) values, row-major, a one-site ring of zeros,
// within a capacity the patch may grow into (shaders/cell.wgsl).
struct Patch {
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
    offset: u32,
    capacity: u32,
    _pad1: u32,
    _pad2: u32,
};

// Row stride of a patch's padded storage (`Patch::stride`).
fn stride(p: Patch) -> u32 {
    return p.w + 2u;
}

// Invocation k of a per-site kernel (`Grid::Sites`: x the padded index, y the cell) in its
// cell's patch p: the padded site as (column, row), its index in the per-cell arrays, whether k
// falls in the padded storage at all (a row's last workgroup has spare invocations, which do
// nothing) and whether the site is interior (column and row in 1..=w, 1..=h: not the halo).
struct Site {
    at: vec2<u32>,
    i: u32,
    inside: bool,
    interior: bool,
};

fn site_of(p: Patch, k: u32) -> Site {
    let s = stride(p);
    let at = vec2<u32>(k % s, k / s);
    let inside = k < s * (p.h + 2u);
    let interior = inside && at.x >= 1u && at.x <= p.w && at.y >= 1u && at.y <= p.h;
    return Site(at, p.offset + k, inside, interior);
}

// Lattice index gy·L + gx of interior padded site (column, row) (`Patch::global_xy`).
fn lattice_index(p: Patch, site: vec2<u32>, l: u32) -> u32 {
    let gx = (p.x0 + site.x - 1u) % l;
    let gy = (p.y0 + site.y - 1u) % l;
    return gy * l + gx;
}

// Whether x is a finite number, read from its bits: a WGSL compiler may assume that no float
// is NaN or infinite (Metal's fast math does) and fold away a comparison that counts on NaN
// being unordered, but not a test of the exponent's bits. Every fault check goes through it.
fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn is_finite2(v: vec2<f32>) -> vec2<bool> {
    return (bitcast<vec2<u32>>(v) & vec2<u32>(0x7f800000u)) != vec2<u32>(0x7f800000u);
}
