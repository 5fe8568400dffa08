//! The state the kernels read and write, on the device: the cells' φ on their patches, the
//! patch geometry, the parameters as a uniform, and the fields the stages derive (Σφ, Σφ², A_i,
//! μ_i, Q_i, Q̂_i, f_i, n and F, the friction solve's operator, vectors and scalars, the drag,
//! v_i and ∂_t φ_i, and Heun's φ_n, R(φ_n) and range faults).
//! Uploaded from a CPU [`Monolayer`], in f32.
//!
//! The per-cell fields (φ, μ, f_x, f_y) are every cell's padded patch storage one after the
//! other, in cell order, exactly as each [`crate::model::Cell`] stores it; `GpuPatch::offset`
//! says where each cell's starts.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::gpu::context::{GpuContext, GpuError};
use crate::model::multigrid::level_sides;
use crate::model::{
    load, Advection, FreeEnergy, FrictionWeights, Laplacian, Monolayer, Params, PassiveForce, Patch, Phase, Real,
};

/// The buffers of the GPU state, each with the binding number every kernel gives it
/// (`@binding(n)` in `shaders/*.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// `GpuParams`, a uniform.
    Params = 0,
    /// `GpuPatch` per cell.
    Patches = 1,
    /// φ_i, per cell on its padded patch.
    Phi = 2,
    /// Σ_i φ_i on the lattice.
    SumPhi = 3,
    /// Σ_i φ_i² on the lattice.
    SumPhi2 = 4,
    /// A_i, one per cell.
    Area = 5,
    /// μ_i, per cell on its padded patch.
    Mu = 6,
    /// Q_i = (Q_xx, Q_xy), one pair per cell.
    Shape = 7,
    /// Q̂_i, one pair per cell.
    QHat = 8,
    /// f_x and f_y of f_i = f^p_i + f^a_i, per cell on its padded patch.
    Fx = 9,
    Fy = 10,
    /// n = Σ_j w_j on the lattice, the friction weights.
    Weight = 11,
    /// F = Σ_j w_j f_j on the lattice, (x, y) per site.
    Force = 12,
    /// The CPU's `motion::Drag` on the lattice, with ξ_s(x): (pull ξ_c S, mobility, ξ_s) per
    /// site. The friction solve writes the pull and the mobility 1/[ξ_s + ξ_c N]; without one
    /// the pull is 0 and the mobility 1/ξ_relax (relaxation) or 1/ξ_s(x) (ξ_cell = 0).
    Drag = 13,
    /// v_i, (x, y) per padded site of each cell (one buffer for both, as F: a kernel may bind
    /// at most 8 storage buffers, WebGPU's default, and the motion kernel needs them all).
    Velocity = 14,
    /// ∂_t φ_i = R(φ_i) of the latest evaluation, per cell on its padded patch.
    Rate = 15,
    /// Heun's φ_n (the start of the step) and R(φ_n), per cell on its padded patch.
    Phi0 = 16,
    K1 = 17,
    /// Per cell, the padded index of the first site (in storage order, which is the CPU's row
    /// by row) where the corrector's φ left [φ_min, φ_max], or `NO_FAULT`.
    Fault = 18,
    /// The friction operator's diagonal n (ξ_s + ξ_c N), 0 outside the solve (n = 0).
    Diagonal = 19,
    /// u = V/n, (x, y) per lattice site: the friction solve's solution and next warm start.
    MeanVelocity = 20,
    /// The friction CG's work vectors, (x, y) per site, one after the other in one buffer (an
    /// arena: with its own binding each, the fused kernels would bind more than 8 storage
    /// buffers, WebGPU's default): the residual r, the direction p, the next direction
    /// p′ = z + β p (while p is still read), the product q = C p′ and z = M r
    /// (`CG_VECTORS`; `shaders/friction.wgsl`).
    CgVectors = 21,
    /// Per workgroup of the lattice, partial sums of the CG's inner products (`PARTIAL_SUMS`
    /// vec4 each).
    Partials = 22,
    /// The CG's scalars, [`SolveScalars`].
    Solve = 23,
    /// The multigrid hierarchy below C: per level k ≥ 1 six values per site (diagonal, four
    /// forward bonds, mass), then the coarsest level's inverse (`shaders/multigrid.wgsl`).
    Hierarchy = 24,
    /// Per level k ≥ 1 of the hierarchy, x, b and t of a cycle, (x, y) per site.
    MgWork = 25,
    /// Per cell, the first [`PatchFault`] code other than `Moved` since the faults were last
    /// cleared (sticky), or `Moved`.
    PatchFault = 26,
}

/// How many of the friction CG's vectors [`Slot::CgVectors`] holds, each the lattice's L² (x, y)
/// pairs, in this order: r, p, p′, q, z (`RESIDUAL` … `PRECONDITIONED` in
/// `shaders/friction.wgsl`).
pub const CG_VECTORS: usize = 5;

/// Why a cell's patch did not move (`Slot::PatchFault`; `shaders/cell.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PatchFault {
    Moved = 0,
    /// No site has φ above the presence threshold (the CPU's `CellLost`, "vanished").
    Vanished = 1,
    /// The patch would span the box (the CPU's `CellLost`).
    SpansTheBox = 2,
    /// The patch would outgrow the cell's storage: upload again with more room.
    BeyondCapacity = 3,
}

impl PatchFault {
    pub fn from_code(code: u32) -> Option<Self> {
        [PatchFault::Moved, PatchFault::Vanished, PatchFault::SpansTheBox, PatchFault::BeyondCapacity]
            .into_iter()
            .find(|f| *f as u32 == code)
    }
}

/// The parts of `Slot::Partials`, a vec4 per workgroup each: ‖r‖² with ‖F‖², p·Cp, r·z and
/// the true residual (`shaders/friction.wgsl`).
pub const PARTIAL_SUMS: usize = 4;

/// `Slot::Fault` of a cell whose φ stayed in range.
pub const NO_FAULT: u32 = u32::MAX;

impl Slot {
    pub const ALL: [Slot; 27] = [
        Slot::Params,
        Slot::Patches,
        Slot::Phi,
        Slot::SumPhi,
        Slot::SumPhi2,
        Slot::Area,
        Slot::Mu,
        Slot::Shape,
        Slot::QHat,
        Slot::Fx,
        Slot::Fy,
        Slot::Weight,
        Slot::Force,
        Slot::Drag,
        Slot::Velocity,
        Slot::Rate,
        Slot::Phi0,
        Slot::K1,
        Slot::Fault,
        Slot::Diagonal,
        Slot::MeanVelocity,
        Slot::CgVectors,
        Slot::Partials,
        Slot::Solve,
        Slot::Hierarchy,
        Slot::MgWork,
        Slot::PatchFault,
    ];

    pub fn binding(self) -> u32 {
        self as u32
    }
}

/// The fraction of the CPU's relative tolerance that the GPU's friction CG asks of its own
/// residual. CG updates r recursively (r −= α q); in f32 that r drifts from the true F − C u by
/// rounding accumulated over the iterations, 7 % of the tolerance after 197 iterations at full
/// size from a cold start (tests/gpu.rs), where the true residual then missed 10⁻⁴. Asking half
/// the tolerance of the recursive residual keeps the true one within the CPU's tolerance at the
/// cost of a few more iterations (CG's convergence is geometric).
pub const RECURSIVE_RESIDUAL_MARGIN: f64 = 0.5;

/// The parameters of the stages, as `Params` in `shaders/model.wgsl` (same fields, same
/// order): the coefficients of [`FreeEnergy`], the knobs of shape, forces and motion, and the
/// time step with φ's allowed range, in f32.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuParams {
    pub box_size: u32,
    pub n_cells: u32,
    pub laplacian: u32,
    pub passive: u32,
    pub bulk: f32,
    pub gradient: f32,
    pub area: f32,
    pub target_area: f32,
    pub repulsion: f32,
    pub q_magnitude: f32,
    pub q_epsilon: f32,
    pub zeta: f32,
    pub friction_weights: u32,
    pub presence_threshold: f32,
    pub advection: u32,
    pub j0: f32,
    pub dt: f32,
    pub phi_min: f32,
    pub phi_max: f32,
    pub xi_cell: f32,
    pub friction_tolerance: f32,
    pub relax_patch_size: u32,
    pub patch_margin: u32,
    /// 0 during relaxation, 1 when active.
    pub active: u32,
}

impl GpuParams {
    /// The same coefficients as the CPU derives (`FreeEnergy::new`), rounded once to f32; ζ and
    /// ξ_cell as the phase has them (`Phase::zeta_and_xi_cell`, the CPU's rule).
    pub fn new(p: &Params, phase: Phase) -> Self {
        let fe = FreeEnergy::new(p);
        let (zeta, xi_cell) = phase.zeta_and_xi_cell(p);
        GpuParams {
            box_size: p.box_size as u32,
            n_cells: p.n_cells as u32,
            laplacian: match p.laplacian {
                Laplacian::FivePoint => 0,
                Laplacian::NinePoint => 1,
            },
            passive: match p.passive_force {
                PassiveForce::GradMu => 0,
                PassiveForce::PhiGradMu => 1,
            },
            bulk: fe.bulk as f32,
            gradient: fe.gradient as f32,
            area: fe.area as f32,
            target_area: fe.target_area as f32,
            repulsion: fe.repulsion as f32,
            q_magnitude: p.q_magnitude as f32,
            q_epsilon: p.q_epsilon as f32,
            zeta: zeta as f32,
            friction_weights: match p.friction_weights {
                FrictionWeights::Phi => 0,
                FrictionWeights::Presence => 1,
                FrictionWeights::Subdomain => 2,
            },
            presence_threshold: p.presence_threshold as f32,
            advection: match p.advection {
                Advection::Central => 0,
                Advection::Upwind => 1,
            },
            j0: p.j0 as f32,
            dt: p.dt as f32,
            phi_min: p.phi_min as f32,
            phi_max: p.phi_max as f32,
            xi_cell: xi_cell as f32,
            friction_tolerance: (p.friction_tolerance * RECURSIVE_RESIDUAL_MARGIN) as f32,
            relax_patch_size: p.relax_patch_size as u32,
            patch_margin: p.patch_margin as u32,
            active: (phase == Phase::Active) as u32,
        }
    }
}

/// One cell's patch and where its padded storage starts, as `Patch` in `shaders/model.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuPatch {
    pub x0: u32,
    pub y0: u32,
    pub w: u32,
    pub h: u32,
    pub offset: u32,
    /// Values the cell's storage holds: its padded patch may grow to this.
    pub capacity: u32,
    pub pad: [u32; 2],
}

impl GpuPatch {
    /// The CPU's patch.
    pub fn patch(&self) -> Patch {
        Patch { x0: self.x0 as usize, y0: self.y0 as usize, w: self.w as usize, h: self.h as usize }
    }

    pub fn padded_len(&self) -> usize {
        (self.w as usize + 2) * (self.h as usize + 2)
    }
}

/// Where each cell's padded storage sits in the per-cell arrays.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The patches as uploaded (on the device they move: `GpuMonolayer::read_patches`).
    pub patches: Vec<GpuPatch>,
    /// Sum of the capacities: the length of φ, μ, f_x, f_y.
    pub total: usize,
    /// The largest capacity: the per-site kernels' width.
    pub max_padded: usize,
    pub box_size: usize,
}

/// Every cell's capacity, in units of the largest padded patch at upload: room for a patch
/// that grows (an active cell's support changes with its shape) without new buffers. A patch
/// that would outgrow it is reported (`PatchFault::BeyondCapacity`).
pub const CAPACITY_FACTOR: usize = 2;

impl Layout {
    /// The layout with the default capacity ([`Layout::default_capacity`]).
    pub fn of(m: &Monolayer) -> Self {
        Self::with_capacity(m, Self::default_capacity(m))
    }

    /// `CAPACITY_FACTOR` times the largest padded patch, and at least a relaxation patch.
    pub fn default_capacity(m: &Monolayer) -> usize {
        let p = m.params();
        let square = (p.relax_patch_size + 2) * (p.relax_patch_size + 2);
        (CAPACITY_FACTOR * Self::largest_padded(m)).max(square)
    }

    /// The largest padded patch of the monolayer: the least capacity that takes its cells.
    pub fn largest_padded(m: &Monolayer) -> usize {
        m.cells().iter().map(|c| c.patch().padded_len()).max().unwrap_or(0)
    }

    /// Every cell with storage for `capacity` values (at least its padded patch).
    pub fn with_capacity(m: &Monolayer, capacity: usize) -> Self {
        let capacity = capacity.max(Self::largest_padded(m));
        let p = m.params();
        let mut patches = Vec::with_capacity(m.cells().len());
        let mut total = 0;
        for c in m.cells() {
            let p = c.patch();
            let offset = total as u32;
            patches.push(GpuPatch {
                x0: p.x0 as u32,
                y0: p.y0 as u32,
                w: p.w as u32,
                h: p.h as u32,
                offset,
                capacity: capacity as u32,
                pad: [0; 2],
            });
            total += capacity;
        }
        Layout { patches, total, max_padded: capacity, box_size: p.box_size }
    }

    pub fn n_cells(&self) -> usize {
        self.patches.len()
    }

    /// Whether the device can take this layout: the per-site kernels run one row of workgroups
    /// per cell (kernels.rs, `Grid::Sites`), and the largest buffers are the per-site velocity
    /// (2 values per padded site) and the lattice force (2 per site), in f32.
    pub fn fits(&self, limits: &wgpu::Limits) -> Result<(), GpuError> {
        let too_large = |what: String, value: u64, limit: u64, limit_name| {
            (value > limit).then_some(GpuError::TooLarge { what, value, limit, limit_name })
        };
        let per_dimension = u64::from(limits.max_compute_workgroups_per_dimension);
        let binding = limits.max_storage_buffer_binding_size;
        let l2 = (self.box_size * self.box_size) as u64;
        let largest = (8 * self.total as u64).max(8 * CG_VECTORS as u64 * l2);
        let errors = [
            too_large(
                "the number of cells (one row of workgroups each)".into(),
                self.n_cells() as u64,
                per_dimension,
                "max_compute_workgroups_per_dimension",
            ),
            too_large(
                format!(
                    "the largest buffer in bytes (2 f32 per padded patch site, or the CG's vectors: {} f32 per \
                     lattice site)",
                    2 * CG_VECTORS
                ),
                largest,
                binding,
                "max_storage_buffer_binding_size",
            ),
            too_large("the largest buffer in bytes".into(), largest, limits.max_buffer_size, "max_buffer_size"),
        ];
        errors.into_iter().flatten().next().map_or(Ok(()), Err)
    }

    /// A per-cell field of the CPU (one padded vector per cell) as one f32 array in this layout
    /// (zeros beyond each padded patch, up to its capacity).
    pub fn flatten<'a, T: Real>(&self, fields: impl Iterator<Item = &'a [T]>) -> Vec<f32> {
        let mut out = vec![0.0; self.total];
        let mut cells = 0;
        for (f, p) in fields.zip(&self.patches) {
            assert_eq!(f.len(), p.padded_len(), "fields must follow the layout's patches");
            out[p.offset as usize..][..f.len()].iter_mut().zip(f).for_each(|(o, &v)| *o = load(v) as f32);
            cells += 1;
        }
        assert_eq!(cells, self.patches.len(), "one field per cell");
        out
    }

    /// Cell i's padded storage within a per-cell array of this layout.
    pub fn cell<'a, T>(&self, i: usize, data: &'a [T]) -> &'a [T] {
        patch_storage(self.patches[i], data)
    }
}

/// A cell's padded storage within a per-cell array, given its patch (as uploaded, or as read
/// back after the patches moved).
pub fn patch_storage<T>(p: GpuPatch, data: &[T]) -> &[T] {
    &data[p.offset as usize..][..p.padded_len()]
}

impl Layout {}

/// The device buffers of one state, indexed by [`Slot`].
pub struct DeviceState {
    pub layout: Layout,
    pub params: GpuParams,
    /// Whether the CPU solves Eq. 2 in this phase (active, ξ_cell > 0): then the mobility
    /// uploaded is not the one it uses, and the GPU cannot step.
    pub solves_friction: bool,
    buffers: Vec<wgpu::Buffer>,
}

/// Storage buffers are written by the kernels, copied out by a readback, and overwritten by
/// uploads.
const STORAGE: wgpu::BufferUsages =
    wgpu::BufferUsages::STORAGE.union(wgpu::BufferUsages::COPY_SRC).union(wgpu::BufferUsages::COPY_DST);

impl DeviceState {
    /// φ of every cell, the patches and the parameters of the monolayer's current phase; every
    /// derived field zero until a kernel writes it.
    /// Refuses, naming the limit, a monolayer too large for the device.
    pub fn upload(ctx: &GpuContext, m: &Monolayer) -> Result<Self, GpuError> {
        Self::upload_in(ctx, m, Layout::of(m))
    }

    /// [`DeviceState::upload`] in a given layout (tests: a tight capacity).
    pub fn upload_in(ctx: &GpuContext, m: &Monolayer, layout: Layout) -> Result<Self, GpuError> {
        layout.fits(&ctx.device.limits())?;
        let params = GpuParams::new(m.params(), m.phase());
        let phi = layout.flatten(m.cells().iter().map(|c| c.phi().data));
        let (l2, n, total) = (layout.box_size * layout.box_size, layout.n_cells(), layout.total);
        let drag = drag(m.params(), m.phase(), &m.lattice().xi_s);
        let warm_start: Vec<[f32; 2]> = m.warm_start().iter().map(|u| [u.re as f32, u.im as f32]).collect();
        let groups = (l2).div_ceil(LATTICE_GROUP);
        let hierarchy = Hierarchy::new(layout.box_size);
        let buffers = Slot::ALL
            .iter()
            .map(|&slot| {
                let init = |contents: &[u8], usage| {
                    let label = Some(slot_label(slot));
                    ctx.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label, contents, usage })
                };
                let zeros = |floats: usize| init(&vec![0u8; 4 * floats], STORAGE);
                match slot {
                    Slot::Params => {
                        init(bytemuck::bytes_of(&params), wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST)
                    }
                    Slot::Patches => init(bytemuck::cast_slice(&layout.patches), STORAGE),
                    Slot::Phi => init(bytemuck::cast_slice(&phi), STORAGE),
                    Slot::SumPhi | Slot::SumPhi2 | Slot::Weight => zeros(l2),
                    Slot::Force => zeros(2 * l2),
                    Slot::Area => zeros(n),
                    Slot::Shape | Slot::QHat => zeros(2 * n),
                    Slot::Mu | Slot::Fx | Slot::Fy => zeros(total),
                    Slot::Drag => init(bytemuck::cast_slice(&drag), STORAGE),
                    Slot::Velocity => zeros(2 * total),
                    Slot::Rate | Slot::Phi0 | Slot::K1 => zeros(total),
                    Slot::Fault => init(bytemuck::cast_slice(&vec![NO_FAULT; n]), STORAGE),
                    Slot::Diagonal => zeros(l2),
                    Slot::MeanVelocity => init(bytemuck::cast_slice(&warm_start), STORAGE),
                    Slot::CgVectors => zeros(CG_VECTORS * 2 * l2),
                    Slot::Partials => zeros(PARTIAL_SUMS * 4 * groups),
                    Slot::Hierarchy => zeros(hierarchy.hierarchy_floats().max(1)),
                    Slot::MgWork => zeros(2 * hierarchy.work_sites().max(1)),
                    Slot::PatchFault => zeros(n),
                    Slot::Solve => zeros(std::mem::size_of::<SolveScalars>() / 4),
                }
            })
            .collect();
        let solves_friction = m.phase().zeta_and_xi_cell(m.params()).1 > 0.0;
        Ok(DeviceState { layout, params, solves_friction, buffers })
    }

    pub fn buffer(&self, slot: Slot) -> &wgpu::Buffer {
        &self.buffers[slot as usize]
    }

    /// Enters a phase: the parameters of `GpuParams::new` and the drag as uploaded for it (the
    /// CPU's switch from relaxation to activity at `relax_steps`). Written through the queue, so
    /// it takes effect before the next submission.
    pub fn set_phase(&mut self, ctx: &GpuContext, p: &Params, phase: Phase, xi_s: &[f64]) {
        self.params = GpuParams::new(p, phase);
        self.solves_friction = phase.zeta_and_xi_cell(p).1 > 0.0;
        ctx.queue.write_buffer(self.buffer(Slot::Params), 0, bytemuck::bytes_of(&self.params));
        ctx.queue.write_buffer(self.buffer(Slot::Drag), 0, bytemuck::cast_slice(&drag(p, phase, xi_s)));
    }

    /// Clears the sticky faults: φ's range and the patch's per cell, and the count of
    /// unconverged solves.
    pub fn reset_faults(&self, ctx: &GpuContext) {
        let n = self.layout.n_cells();
        ctx.queue.write_buffer(self.buffer(Slot::Fault), 0, bytemuck::cast_slice(&vec![NO_FAULT; n]));
        ctx.queue.write_buffer(
            self.buffer(Slot::PatchFault),
            0,
            bytemuck::cast_slice(&vec![PatchFault::Moved as u32; n]),
        );
        ctx.queue.write_buffer(self.buffer(Slot::Solve), 0, bytemuck::bytes_of(&SolveScalars::default()));
    }
}

/// `Slot::Drag` as uploaded: a pull of zero; the mobility of `Monolayer::evaluate` without a
/// friction solve, computed in f64 as the CPU does and rounded once (1/ξ_relax during
/// relaxation, 1/ξ_s(x) when active; with ξ_cell > 0 the friction solve replaces it in every
/// evaluation); and ξ_s(x).
pub fn drag(p: &Params, phase: Phase, xi_s: &[f64]) -> Vec<[f32; 4]> {
    let mobility = |xs: f64| match phase {
        Phase::Relaxation => 1.0 / p.xi_relax,
        Phase::Active => 1.0 / xs,
    };
    xi_s.iter().map(|&xs| [0.0, 0.0, mobility(xs) as f32, xs as f32]).collect()
}

/// The multigrid levels below the lattice, as `shaders/multigrid.wgsl` derives them: the CPU's
/// (`model::multigrid::level_sides`) without the finest.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Hierarchy {
    /// Sides of levels 1, 2, …, the coarsest last (empty when L ≤ 6).
    pub sides: Vec<usize>,
}

impl Hierarchy {
    pub fn new(l: usize) -> Self {
        Hierarchy { sides: level_sides(l)[1..].to_vec() }
    }

    /// f32 values of `Slot::Hierarchy`: six per site of every level, then the coarsest level's
    /// dense inverse.
    pub fn hierarchy_floats(&self) -> usize {
        let levels: usize = self.sides.iter().map(|m| 6 * m * m).sum();
        let n = self.sides.last().map_or(0, |m| m * m);
        levels + n * n
    }

    /// Sites of `Slot::MgWork`: x, b and t of every level.
    pub fn work_sites(&self) -> usize {
        self.sides.iter().map(|m| 3 * m * m).sum()
    }
}

/// Sites per workgroup of the friction solve's lattice kernels (`GROUP` in
/// `shaders/friction.wgsl`): one partial sum per workgroup.
pub const LATTICE_GROUP: usize = 256;

/// The friction CG's scalars, as `Solve` in `shaders/friction.wgsl` (x and y components).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SolveScalars {
    pub rz: [f32; 2],
    pub alpha: [f32; 2],
    pub beta: [f32; 2],
    /// ‖r_c‖² of the last residual.
    pub rr: [f32; 2],
    /// (tolerance · ‖F‖)² / 2.
    pub target2: f32,
    /// ‖F‖².
    pub ff: f32,
    pub iterations: [u32; 2],
    /// 1 once the component met its target.
    pub done: [u32; 2],
    /// Solves that ended short of their target since the host last reset the scalars.
    pub unconverged: u32,
    /// The most iterations any solve took since the host last reset the scalars.
    pub most_iterations: u32,
    /// Solves that met their recursive target but missed the tolerance on the true residual
    /// since the host last reset the scalars (`friction_check`).
    pub inaccurate: u32,
    /// 1 once the last solve was found done (a hint the kernels read, `solve_finished`).
    pub finished: u32,
}

impl SolveScalars {
    /// Whether both components met their target.
    pub fn converged(&self) -> bool {
        self.done == [1, 1]
    }

    /// ‖F − C u‖/‖F‖ by the CG's own (recursively updated) residual, as the CPU reports it.
    pub fn residual(&self) -> f64 {
        if self.ff == 0.0 {
            0.0
        } else {
            ((self.rr[0] as f64 + self.rr[1] as f64) / self.ff as f64).sqrt()
        }
    }
}

fn slot_label(slot: Slot) -> &'static str {
    match slot {
        Slot::Params => "params",
        Slot::Patches => "patches",
        Slot::Phi => "phi",
        Slot::SumPhi => "sum_phi",
        Slot::SumPhi2 => "sum_phi2",
        Slot::Area => "area",
        Slot::Mu => "mu",
        Slot::Shape => "shape",
        Slot::QHat => "q_hat",
        Slot::Fx => "fx",
        Slot::Fy => "fy",
        Slot::Weight => "weight",
        Slot::Force => "force",
        Slot::Drag => "drag",
        Slot::Velocity => "velocity",
        Slot::Rate => "rate",
        Slot::Phi0 => "phi0",
        Slot::K1 => "k1",
        Slot::Fault => "fault",
        Slot::Diagonal => "diagonal",
        Slot::MeanVelocity => "mean_velocity",
        Slot::CgVectors => "cg_vectors",
        Slot::Partials => "partials",
        Slot::Solve => "solve",
        Slot::Hierarchy => "hierarchy",
        Slot::MgWork => "mg_work",
        Slot::PatchFault => "patch_fault",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The WGSL structs `Params` (24 four-byte fields), `Patch` (8) and `Solve` (18) have these
    /// sizes; a field added on one side only changes them.
    #[test]
    fn structs_have_the_wgsl_sizes() {
        assert_eq!(std::mem::size_of::<GpuParams>(), 96);
        assert_eq!(PatchFault::from_code(3), Some(PatchFault::BeyondCapacity));
        assert_eq!(std::mem::size_of::<GpuPatch>(), 32);
        assert_eq!(std::mem::size_of::<SolveScalars>(), 72);
    }

    /// The levels of the paper's and the page's lattices, as the CPU's multigrid builds them.
    #[test]
    fn hierarchy_sides_follow_the_cpu() {
        assert_eq!(Hierarchy::new(140).sides, [70, 35, 18, 9, 5]);
        assert_eq!(Hierarchy::new(80).sides, [40, 20, 10, 5]);
        assert_eq!(Hierarchy::new(60).sides, [30, 15, 8, 4]);
        assert!(Hierarchy::new(6).sides.is_empty());
        assert_eq!(Hierarchy::new(140).hierarchy_floats(), 6 * (4900 + 1225 + 324 + 81 + 25) + 625);
    }

    /// Each cell's storage follows the previous one, with room to grow, and `cell` finds its
    /// padded patch again.
    #[test]
    fn layout_packs_the_patches_in_cell_order() {
        let p = Params { box_size: 40, n_cells: 4, ..Params::default() };
        let m = Monolayer::new(p, 1).unwrap();
        let layout = Layout::of(&m);
        let flat = layout.flatten(m.cells().iter().map(|c| c.phi().data));
        let mut offset = 0;
        for (i, c) in m.cells().iter().enumerate() {
            assert_eq!(layout.patches[i].offset as usize, offset);
            assert!(layout.patches[i].capacity as usize >= CAPACITY_FACTOR * c.patch().padded_len());
            let back: Vec<f64> = layout.cell(i, &flat).iter().map(|&v| v as f64).collect();
            let rounded: Vec<f64> = c.phi().padded().iter().map(|&v| v as f32 as f64).collect();
            assert_eq!(back, rounded, "cell {i}");
            offset += layout.patches[i].capacity as usize;
        }
        assert_eq!((layout.total, flat.len()), (offset, offset));
    }

    /// A layout beyond a device's limits is refused, naming the limit; the full size fits
    /// WebGPU's defaults (the limits every adapter offers).
    #[test]
    fn a_layout_beyond_the_device_limits_is_refused_by_name() {
        let m = Monolayer::new(Params::default(), 1).unwrap();
        let layout = Layout::of(&m);
        layout.fits(&wgpu::Limits::default()).unwrap();
        let few_rows = wgpu::Limits { max_compute_workgroups_per_dimension: 99, ..wgpu::Limits::default() };
        let e = layout.fits(&few_rows).unwrap_err().to_string();
        assert!(
            e.contains("number of cells") && e.contains("is 100") && e.contains("max_compute_workgroups_per_dimension"),
            "{e}"
        );
        let small = 8 * layout.total.max(140 * 140) as u64 - 1;
        let narrow = wgpu::Limits { max_storage_buffer_binding_size: small, ..wgpu::Limits::default() };
        let e = layout.fits(&narrow).unwrap_err().to_string();
        assert!(e.contains("max_storage_buffer_binding_size"), "{e}");
        let short = wgpu::Limits { max_buffer_size: small, ..wgpu::Limits::default() };
        assert!(layout.fits(&short).unwrap_err().to_string().contains("max_buffer_size"));
    }
}
