//! The compute kernels, their pipelines and dispatches, and the object that ties them to a device
//! state: [`GpuMonolayer`], which takes a whole Heun step on fixed patches, with the friction
//! solve where the phase has one.
//!
//! Each kernel's WGSL sits in `shaders/`, one file per stage, named like its CPU module; every
//! file is compiled with `shaders/model.wgsl` (the shared parameters and patches) in front.

#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::buffers::GpuPatch;
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::buffers::SolveScalars;
use crate::gpu::buffers::{DeviceState, Hierarchy, Layout, Slot, LATTICE_GROUP};
use crate::gpu::context::{GpuContext, GpuError};
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::readback::read_now;
use crate::model::Monolayer;
use std::future::Future;

const MODEL_WGSL: &str = include_str!("../../shaders/model.wgsl");
const GATHER_WGSL: &str = include_str!("../../shaders/gather.wgsl");
const FREE_ENERGY_WGSL: &str = include_str!("../../shaders/free_energy.wgsl");
const SHAPE_WGSL: &str = include_str!("../../shaders/shape.wgsl");
const FORCES_WGSL: &str = include_str!("../../shaders/forces.wgsl");
const MOTION_WGSL: &str = include_str!("../../shaders/motion.wgsl");
const MONOLAYER_WGSL: &str = include_str!("../../shaders/monolayer.wgsl");
const FRICTION_WGSL: &str = include_str!("../../shaders/friction.wgsl");
const MULTIGRID_WGSL: &str = include_str!("../../shaders/multigrid.wgsl");
const CELL_WGSL: &str = include_str!("../../shaders/cell.wgsl");

/// The per-site kernels' workgroup width (`@workgroup_size(64)`); the lattice kernels'
/// workgroups are 8 × 8 sites.
const SITES_PER_GROUP: usize = 64;
const LATTICE_TILE: usize = 8;

/// One dispatch, in the order of one evaluation of the right-hand side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Σφ and Σφ² on the lattice (`shaders/gather.wgsl`).
    LatticeSums,
    /// Q_i and Q̂_i, with A_i in the same pass over each patch (`shaders/shape.wgsl`).
    AreaAndShape,
    /// μ_i (`shaders/free_energy.wgsl`); needs Σφ² and A_i.
    ChemicalPotential,
    /// f_i (`shaders/forces.wgsl`); needs μ_i and Q̂_i.
    ForceDensity,
    /// n = Σ w_j and F = Σ w_j f_j on the lattice (`shaders/gather.wgsl`); needs f_i.
    FrictionSums,
    /// v_i and ∂_t φ_i without a friction solve (`shaders/motion.wgsl`); needs μ_i and f_i.
    VelocityAndRate,
    /// Heun's predictor (`shaders/monolayer.wgsl`); needs the rate.
    Predict,
    /// Heun's corrector and the range check (`shaders/monolayer.wgsl`); needs the predictor's
    /// φ_n and R(φ_n), and the rate at φ*.
    Correct,
    /// The friction operator for the current n (its diagonal and the mobility, as
    /// `FrictionSolver::prepare`), r = F − C u from the warm start, and the partial sums of ‖r‖²
    /// and ‖F‖².
    CgStart,
    /// The previous update's r stored, then the stop test and β, p′ = z + β p, q = C p′ and partial
    /// sums of p′·q.
    CgProduct,
    /// α, u += α p′, p = p′, and partial sums of the new r's ‖r‖² (r − α q, stored by the next
    /// `CgProduct`): with the Jacobi preconditioner.
    CgUpdate,
    /// `CgUpdate`, and the next multigrid application's restriction to level 1 from the new r
    /// (`shaders/multigrid.wgsl`).
    CgUpdateRestrict,
    /// The pull ξ_c S from the solution (`FrictionSolver::pull_from_solution`), and partial
    /// sums of the true residual.
    FrictionPull,
    /// The true residual against the CPU's tolerance (one workgroup).
    FrictionCheck,
    /// z = r / diag C and partial sums of r·z: the Jacobi preconditioner.
    Jacobi,
    /// Multigrid level 1 from C (`shaders/multigrid.wgsl`, as `Multigrid::setup`), and the first
    /// application's level-0 sweep from zero and its restriction to level 1.
    MgSetUpFine,
    /// The coarser levels and the coarsest level's inverse, then the first application's cycle
    /// on levels 1 to the coarsest (one workgroup).
    MgSetUpCoarse,
    /// The cycle on levels 1 to the coarsest (one workgroup).
    MgCoarseCycle,
    /// The prolongation to level 0 and its last sweep: z, and partial sums of r·z.
    MgSmooth,
    /// Each cell's patch follows it: the next patch, re-centred (relaxation) or fitted to its
    /// support (active), φ laid out in it (`shaders/cell.wgsl`, as `Monolayer::update_patches`
    /// and `Cell::relayout`).
    MovePatch,
}

/// What preconditions the friction CG on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preconditioner {
    /// One cycle of the CPU's aggregation multigrid (`shaders/multigrid.wgsl`): three dispatches
    /// per application (the restriction riding with the kernel before), few iterations.
    Multigrid,
    /// z = r / diag C: one dispatch per application, many iterations.
    Jacobi,
}

impl Preconditioner {
    /// CG iterations recorded per solve unless set otherwise (`SOLVE_ITERATIONS`,
    /// `JACOBI_ITERATIONS`).
    pub fn default_iterations(self) -> usize {
        match self {
            Preconditioner::Multigrid => SOLVE_ITERATIONS,
            Preconditioner::Jacobi => JACOBI_ITERATIONS,
        }
    }

    /// The kernels of its set-up for a new operator and its first application, z = M r with
    /// its partial sums of r·z, after `CgStart`.
    pub fn first_application(self) -> &'static [Kernel] {
        match self {
            Preconditioner::Multigrid => &[Kernel::MgSetUpFine, Kernel::MgSetUpCoarse, Kernel::MgSmooth],
            Preconditioner::Jacobi => &[Kernel::Jacobi],
        }
    }

    /// One CG iteration with it: r stored, the stop test, β, p and q = C p; α, u and p; z = M r.
    pub fn iteration(self) -> &'static [Kernel] {
        match self {
            Preconditioner::Multigrid => {
                &[Kernel::CgProduct, Kernel::CgUpdateRestrict, Kernel::MgCoarseCycle, Kernel::MgSmooth]
            }
            Preconditioner::Jacobi => &[Kernel::CgProduct, Kernel::CgUpdate, Kernel::Jacobi],
        }
    }
}

/// How a kernel's invocations cover the state.
#[derive(Clone, Copy, Debug)]
enum Grid {
    /// One invocation per lattice site, in 8 × 8 tiles.
    Lattice,
    /// One workgroup per cell.
    Cells,
    /// One invocation per padded site of each cell: x the site, y the cell (so at most 65,535
    /// cells, WebGPU's workgroups per dimension; `Layout::fits` checks it).
    Sites,
    /// One invocation per lattice site in row-major order, 256 per workgroup (the friction
    /// solve: one partial sum per workgroup).
    LatticeRows,
    /// One workgroup: the true residual's check, the coarse levels of the multigrid.
    Single,
    /// One invocation per site of multigrid level 1, 256 per workgroup.
    LevelOne,
}

impl Kernel {
    /// Every kernel, in the order of one evaluation.
    pub const ALL: [Kernel; 20] = [
        Kernel::LatticeSums,
        Kernel::AreaAndShape,
        Kernel::ChemicalPotential,
        Kernel::ForceDensity,
        Kernel::FrictionSums,
        Kernel::VelocityAndRate,
        Kernel::Predict,
        Kernel::Correct,
        Kernel::CgStart,
        Kernel::CgProduct,
        Kernel::CgUpdate,
        Kernel::CgUpdateRestrict,
        Kernel::FrictionPull,
        Kernel::FrictionCheck,
        Kernel::Jacobi,
        Kernel::MgSetUpFine,
        Kernel::MgSetUpCoarse,
        Kernel::MgCoarseCycle,
        Kernel::MgSmooth,
        Kernel::MovePatch,
    ];

    /// One evaluation of the rate R(φ) where there is no friction solve: Σφ², A_i with Q̂_i, μ_i,
    /// f_i, then v_i and ∂_t φ_i. (In relaxation ζ = 0 and Q̂_i is not needed; it is summed
    /// anyway with A_i, as the CPU computes Q_i in both phases.)
    pub const RATE: [Kernel; 5] = [
        Kernel::LatticeSums,
        Kernel::AreaAndShape,
        Kernel::ChemicalPotential,
        Kernel::ForceDensity,
        Kernel::VelocityAndRate,
    ];

    /// The stages up to the friction solve's right-hand side (n and F): [`Self::RATE`]'s up to
    /// the forces, then the friction sums.
    pub const FRICTION_SUMS: [Kernel; 5] = {
        let mut out = Kernel::RATE;
        out[4] = Kernel::FrictionSums;
        out
    };

    /// The friction solve of Eq. 2 with `iterations` CG iterations recorded (those after both
    /// components converged return at once): the operator with the residual of the warm start,
    /// the preconditioner's set-up and its first application, the iterations, then the pull and
    /// the check of the true residual.
    pub fn friction_solve(pc: Preconditioner, iterations: usize) -> Vec<Kernel> {
        let mut out = vec![Kernel::CgStart];
        out.extend_from_slice(pc.first_application());
        for _ in 0..iterations {
            out.extend_from_slice(pc.iteration());
        }
        out.extend_from_slice(&[Kernel::FrictionPull, Kernel::FrictionCheck]);
        out
    }

    /// One evaluation of the rate R(φ): [`Self::RATE`], with the friction sums and the solve
    /// before the velocities when the phase has cell–cell friction.
    pub fn rate(solve: Option<(Preconditioner, usize)>) -> Vec<Kernel> {
        let Some((pc, iterations)) = solve else {
            return Kernel::RATE.to_vec();
        };
        let mut out = Kernel::FRICTION_SUMS.to_vec();
        out.extend(Kernel::friction_solve(pc, iterations));
        out.push(Kernel::VelocityAndRate);
        out
    }

    /// One Heun step: R(φ), the predictor, R(φ*), the corrector.
    pub fn step(solve: Option<(Preconditioner, usize)>) -> Vec<Kernel> {
        let rate = Kernel::rate(solve);
        let mut out = rate.clone();
        out.push(Kernel::Predict);
        out.extend(rate);
        out.push(Kernel::Correct);
        out
    }

    /// One step as the CPU's `Monolayer::step` takes it within a phase: [`Self::step`], then the
    /// patches following the cells ([`Kernel::MovePatch`], `Monolayer::update_patches`).
    pub fn whole_step(solve: Option<(Preconditioner, usize)>) -> Vec<Kernel> {
        let mut out = Kernel::step(solve);
        out.push(Kernel::MovePatch);
        out
    }

    /// The file of `shaders/` the kernel is in: its stage, named like the CPU module.
    pub fn shader_file(self) -> &'static str {
        let files = [
            (GATHER_WGSL, "gather.wgsl"),
            (FREE_ENERGY_WGSL, "free_energy.wgsl"),
            (SHAPE_WGSL, "shape.wgsl"),
            (FORCES_WGSL, "forces.wgsl"),
            (MOTION_WGSL, "motion.wgsl"),
            (MONOLAYER_WGSL, "monolayer.wgsl"),
            (FRICTION_WGSL, "friction.wgsl"),
            (MULTIGRID_WGSL, "multigrid.wgsl"),
            (CELL_WGSL, "cell.wgsl"),
        ];
        let text = self.source().0;
        files.iter().find(|(t, _)| std::ptr::eq(*t, text)).map_or("?", |(_, name)| name)
    }

    /// The stage's WGSL file and the kernel's entry point in it.
    fn source(self) -> (&'static str, &'static str) {
        match self {
            Kernel::MgSetUpFine => (MULTIGRID_WGSL, "mg_set_up_fine"),
            Kernel::MgSetUpCoarse => (MULTIGRID_WGSL, "mg_set_up_coarse"),
            Kernel::CgUpdateRestrict => (MULTIGRID_WGSL, "cg_update_restrict"),
            Kernel::MgCoarseCycle => (MULTIGRID_WGSL, "mg_coarse_cycle"),
            Kernel::MgSmooth => (MULTIGRID_WGSL, "mg_smooth"),
            Kernel::Jacobi => (FRICTION_WGSL, "jacobi"),
            Kernel::MovePatch => (CELL_WGSL, "move_patch"),
            Kernel::LatticeSums => (GATHER_WGSL, "lattice_sums"),
            Kernel::ChemicalPotential => (FREE_ENERGY_WGSL, "chemical_potential"),
            Kernel::AreaAndShape => (SHAPE_WGSL, "area_and_shape"),
            Kernel::ForceDensity => (FORCES_WGSL, "force_density"),
            Kernel::FrictionSums => (GATHER_WGSL, "friction_sums"),
            Kernel::VelocityAndRate => (MOTION_WGSL, "velocity_and_rate"),
            Kernel::Predict => (MONOLAYER_WGSL, "predict"),
            Kernel::Correct => (MONOLAYER_WGSL, "correct"),
            Kernel::CgStart => (FRICTION_WGSL, "cg_start"),
            Kernel::CgProduct => (FRICTION_WGSL, "cg_product"),
            Kernel::CgUpdate => (FRICTION_WGSL, "cg_update"),
            Kernel::FrictionPull => (FRICTION_WGSL, "friction_pull"),
            Kernel::FrictionCheck => (FRICTION_WGSL, "friction_check"),
        }
    }

    /// The WGSL the kernel is compiled from: `shaders/model.wgsl`, then its stage's file (the
    /// multigrid's after the friction solve's, whose bindings and helpers it uses, and after
    /// the CPU cycle's constants).
    pub fn wgsl(self) -> String {
        let (stage, _) = self.source();
        if stage == MULTIGRID_WGSL {
            use crate::model::multigrid::{COARSEST_SIDE, COARSE_CORRECTIONS, OMEGA, OVER_CORRECTION};
            let cycle = format!(
                "const COARSEST_SIDE: u32 = {COARSEST_SIDE}u;\nconst OMEGA: f32 = {:?};\n\
                 const OVER_CORRECTION: f32 = {:?};\nconst COARSE_CORRECTIONS: u32 = {COARSE_CORRECTIONS}u;\n\
                 const MAX_ROW_LANES: u32 = {MAX_ROW_LANES}u;\n",
                OMEGA as f32, OVER_CORRECTION as f32
            );
            format!("{MODEL_WGSL}\n{FRICTION_WGSL}\n{cycle}{stage}")
        } else {
            format!("{MODEL_WGSL}\n{stage}")
        }
    }

    /// The buffers the entry point uses, which is what its bind group must hold: the pipeline's
    /// layout is derived from the shader, so a slot missing here, or one too many, fails at
    /// bind-group creation.
    fn slots(self) -> &'static [Slot] {
        use Slot::*;
        match self {
            Kernel::LatticeSums => &[Params, Patches, Phi, SumPhi, SumPhi2],
            Kernel::ChemicalPotential => &[Params, Patches, Phi, SumPhi2, Area, Mu],
            Kernel::AreaAndShape => &[Params, Patches, Phi, Area, Shape, QHat],
            Kernel::ForceDensity => &[Params, Patches, Phi, Mu, QHat, Fx, Fy],
            Kernel::FrictionSums => &[Params, Patches, Phi, Fx, Fy, Weight, Force],
            Kernel::VelocityAndRate => &[Params, Patches, Phi, Mu, Fx, Fy, Drag, Velocity, Rate],
            Kernel::Predict => &[Params, Patches, Phi, Rate, Phi0, K1],
            Kernel::Correct => &[Params, Patches, Phi, Rate, Phi0, K1, Fault],
            Kernel::CgStart => &[Params, Weight, Force, Drag, Diagonal, MeanVelocity, CgVectors, Partials, Solve],
            Kernel::CgProduct => &[Params, Weight, Diagonal, CgVectors, Partials, Solve],
            Kernel::CgUpdate => &[Params, Force, MeanVelocity, CgVectors, Partials, Solve],
            Kernel::CgUpdateRestrict => {
                &[Params, Weight, Force, Diagonal, MeanVelocity, CgVectors, Partials, Solve, MgWork]
            }
            Kernel::FrictionPull => &[Params, Weight, Force, Drag, Diagonal, MeanVelocity, Partials, Solve],
            Kernel::FrictionCheck => &[Params, Partials, Solve],
            Kernel::Jacobi => &[Params, Diagonal, CgVectors, Partials, Solve],
            Kernel::MgSetUpFine => &[Params, Weight, Drag, Diagonal, CgVectors, Solve, Hierarchy, MgWork],
            Kernel::MgSetUpCoarse => &[Params, Weight, Drag, Diagonal, Partials, Solve, Hierarchy, MgWork],
            Kernel::MgCoarseCycle => &[Params, Weight, Diagonal, Partials, Solve, Hierarchy, MgWork],
            Kernel::MgSmooth => &[Params, Weight, Diagonal, CgVectors, Partials, Solve, MgWork],
            Kernel::MovePatch => &[Params, Patches, Phi, Phi0, PatchFault],
        }
    }

    fn grid(self) -> Grid {
        match self {
            Kernel::LatticeSums | Kernel::FrictionSums => Grid::Lattice,
            Kernel::AreaAndShape | Kernel::MovePatch => Grid::Cells,
            Kernel::ChemicalPotential
            | Kernel::ForceDensity
            | Kernel::VelocityAndRate
            | Kernel::Predict
            | Kernel::Correct => Grid::Sites,
            Kernel::CgStart
            | Kernel::CgProduct
            | Kernel::CgUpdate
            | Kernel::CgUpdateRestrict
            | Kernel::FrictionPull
            | Kernel::Jacobi
            | Kernel::MgSmooth => Grid::LatticeRows,
            Kernel::MgSetUpFine => Grid::LevelOne,
            Kernel::FrictionCheck | Kernel::MgSetUpCoarse | Kernel::MgCoarseCycle => Grid::Single,
        }
    }

    /// The bytes a dispatch must move at the least: every value it reads or writes, once (a
    /// stencil's neighbours and the patch table come from cache). For projections: a GPU's
    /// time for a dispatch is at least this over its memory bandwidth.
    pub fn compulsory_bytes(self, state: &DeviceState) -> u64 {
        let layout = &state.layout;
        let padded: u64 = layout.patches.iter().map(|p| p.padded_len() as u64).sum();
        let interior: u64 = layout.patches.iter().map(|p| p.w as u64 * p.h as u64).sum();
        let (n, l2) = (layout.n_cells() as u64, (layout.box_size * layout.box_size) as u64);
        let hierarchy = Hierarchy::new(layout.box_size);
        let level1 = hierarchy.sides.first().map_or(0, |m| (m * m) as u64);
        let (coarse_floats, coarse_work) = (hierarchy.hierarchy_floats() as u64, hierarchy.work_sites() as u64);
        let values = match self {
            // φ at every covered site; Σφ and Σφ² written.
            Kernel::LatticeSums => interior + 2 * l2,
            // φ and Σφ² at each interior site; μ written, halo included.
            Kernel::ChemicalPotential => padded + interior + padded,
            // φ; A_i, Q_i and Q̂_i written.
            Kernel::AreaAndShape => padded + 5 * n,
            // φ and μ; f_x and f_y written.
            Kernel::ForceDensity => 2 * padded + 2 * padded,
            // φ, f_x and f_y at every covered site; n and F written.
            Kernel::FrictionSums => 3 * interior + 3 * l2,
            // φ, μ, f_x, f_y and the mobility at each site; v and the rate written.
            Kernel::VelocityAndRate => 4 * padded + interior + 3 * padded,
            // φ and the rate read; φ_n, R(φ_n) and φ written.
            Kernel::Predict => 2 * padded + 3 * padded + n,
            // φ_n, R(φ_n) and the rate read; φ written.
            Kernel::Correct => 3 * padded + padded + n,
            // n, the drag, F and u read; the drag, the diagonal and r written.
            Kernel::CgStart => l2 + 4 * l2 + 2 * l2 + 2 * l2 + 4 * l2 + l2 + 2 * l2,
            // z, p, r, q, n and the diagonal read; r, p′ and q written.
            Kernel::CgProduct => 10 * l2 + 6 * l2,
            // u, p′, r, q and F read; u and p written.
            Kernel::CgUpdate => 10 * l2 + 4 * l2,
            // CgUpdate's, n and the diagonal read, level 1's b written.
            Kernel::CgUpdateRestrict => 14 * l2 + 2 * l2 + 2 * level1,
            // n, u, F and the diagonal read; the pull written.
            Kernel::FrictionPull => l2 + 2 * l2 + 2 * l2 + 2 * l2 + l2,
            // The partial sums, one workgroup.
            Kernel::FrictionCheck => 4 * l2.div_ceil(LATTICE_GROUP as u64),
            // r, q and the diagonal read; z written.
            Kernel::Jacobi => 4 * l2 + l2 + 2 * l2,
            // n, ξ_s, the diagonal and r read; level 1 and its b written.
            Kernel::MgSetUpFine => 5 * l2 + coarse_floats.min(6 * level1) + 2 * level1,
            // The levels read and written once each, then a cycle's reads.
            Kernel::MgSetUpCoarse => 3 * coarse_floats + 2 * coarse_work,
            // Every coarse level's coefficients and vectors, once (the W-cycle reads them again
            // from cache).
            Kernel::MgCoarseCycle => coarse_floats + 2 * coarse_work,
            // n, the diagonal, r, q and level 1's x read; z written.
            Kernel::MgSmooth => 6 * l2 + 2 * level1 + 2 * l2,
            // φ read, the next patch and its code written, φ laid out into φ_n and back.
            Kernel::MovePatch => interior + 10 * n + 4 * padded,
        };
        4 * values
    }

    /// The longest run of loop iterations one invocation takes in a dispatch, one after
    /// another (dependent or merely in sequence), barrier phases included: the part of the
    /// dispatch no number of invocations shortens. Read off each kernel's WGSL (loops over a
    /// site's stencil count once); [`serial_chain`] adds them up along a step.
    pub fn serial_steps(self, state: &DeviceState) -> u64 {
        let layout = &state.layout;
        let ceil = |a: usize, b: usize| a.div_ceil(b) as u64;
        // A halving tree over a workgroup of 256 or 64 invocations; a total of the lattice's
        // partial sums (`total_of` in friction.wgsl): its share of the entries, then the tree.
        let (tree256, tree64) = (8, 6);
        let groups = (layout.box_size * layout.box_size).div_ceil(LATTICE_GROUP);
        let total = ceil(groups, TOTAL_LANES) + TOTAL_LANES.ilog2() as u64;
        // The stop test: the total of ‖r‖² and ‖F‖² (or of r·z with the flags).
        let done = total;
        let per_cell = ceil(layout.max_padded, SITES_PER_GROUP) + tree64;
        let hierarchy = Hierarchy::new(layout.box_size);
        match self {
            // Per chunk of 64 cells, one invocation compacts the chunk's flags, then every site
            // adds the listed cells (at most the chunk).
            Kernel::LatticeSums | Kernel::FrictionSums => {
                2 * ceil(layout.n_cells(), GATHER_CHUNK) * GATHER_CHUNK as u64
            }
            // Two passes (the padded sites, then the interior ones) and the tree.
            Kernel::AreaAndShape => 2 * ceil(layout.max_padded, SITES_PER_GROUP) + tree64,
            // The sums and their tree, then two passes over the next patch's padded sites.
            Kernel::MovePatch => per_cell + 2 * ceil(layout.max_padded, SITES_PER_GROUP),
            Kernel::ChemicalPotential
            | Kernel::ForceDensity
            | Kernel::VelocityAndRate
            | Kernel::Predict
            | Kernel::Correct => 1,
            // Level 1's site, then its aggregate's restriction.
            Kernel::MgSetUpFine => 2,
            Kernel::CgStart => 2 * tree256 + 1,
            Kernel::CgProduct | Kernel::CgUpdate | Kernel::FrictionPull => done + tree256 + 1,
            Kernel::CgUpdateRestrict => done + tree256 + 2,
            Kernel::Jacobi | Kernel::MgSmooth => done + tree256 + 1,
            Kernel::FrictionCheck => total,
            Kernel::MgSetUpCoarse => {
                let levels: u64 = hierarchy.sides.iter().skip(1).map(|m| ceil(m * m, LATTICE_GROUP)).sum();
                let n = hierarchy.sides.last().map_or(0, |m| m * m);
                // The inverse: zeroing, the rows, then two phases per pivot.
                let inverse = if n == 0 {
                    0
                } else {
                    ceil(n * n, LATTICE_GROUP) + ceil(n, LATTICE_GROUP) + 2 * n as u64 * ceil(n * n, LATTICE_GROUP)
                };
                levels + inverse + done + coarse_cycle_steps(&hierarchy.sides)
            }
            Kernel::MgCoarseCycle => done + coarse_cycle_steps(&hierarchy.sides),
        }
    }

    /// Workgroups to dispatch over the state's layout.
    fn workgroups(self, state: &DeviceState) -> [u32; 3] {
        let layout = &state.layout;
        let n = layout.n_cells() as u32;
        match self.grid() {
            Grid::Lattice => {
                let tiles = layout.box_size.div_ceil(LATTICE_TILE) as u32;
                [tiles, tiles, 1]
            }
            Grid::Cells => [n, 1, 1],
            Grid::Sites => [layout.max_padded.div_ceil(SITES_PER_GROUP) as u32, n, 1],
            Grid::LatticeRows => [(layout.box_size * layout.box_size).div_ceil(LATTICE_GROUP) as u32, 1, 1],
            Grid::Single => [1, 1, 1],
            Grid::LevelOne => {
                let m = Hierarchy::new(layout.box_size).sides.first().copied().unwrap_or(1);
                [(m * m).div_ceil(LATTICE_GROUP) as u32, 1, 1]
            }
        }
    }
}

/// Invocations that add a part's partial sums before their tree (`TOTAL_LANES` in
/// `shaders/friction.wgsl`).
const TOTAL_LANES: usize = 16;

/// Cells listed per pass over a lattice tile (`CHUNK` in `shaders/gather.wgsl`).
const GATHER_CHUNK: usize = 64;

/// The most invocations that apply one row of the coarsest level's inverse (written into
/// `shaders/multigrid.wgsl` by [`Kernel::wgsl`]).
const MAX_ROW_LANES: usize = 16;

/// Invocations per row when the coarsest level's inverse is applied (`row_lanes` in
/// `shaders/multigrid.wgsl`): the most, a power of two up to [`MAX_ROW_LANES`], that gives every
/// one of the n rows its own within a workgroup.
fn row_lanes(n: usize) -> usize {
    let mut lanes = 1;
    while lanes < MAX_ROW_LANES && 2 * lanes * n <= LATTICE_GROUP {
        lanes *= 2;
    }
    lanes
}

/// The serial steps of `mg_coarse_cycle`'s walk (`shaders/multigrid.wgsl`) over levels of these
/// sides (level 1 first): each loop over a level's sites is its share per invocation, each
/// visit of the coarsest level its share of a row's n products and the tree over the row's
/// lanes ([`row_lanes`]).
fn coarse_cycle_steps(sides: &[usize]) -> u64 {
    use crate::model::multigrid::COARSE_CORRECTIONS;
    let share = |k: usize| sides[k - 1].pow(2).div_ceil(LATTICE_GROUP) as u64;
    let last = sides.len();
    if last == 0 {
        return 0;
    }
    // The same walk as the shader's: down smoothing from zero and restricting, the coarsest
    // solved, up prolonging, down again while a level has corrections left, smoothing last.
    let (mut steps, mut k, mut down) = (0u64, 1usize, true);
    let mut corrections = vec![0usize; last + 1];
    loop {
        if down {
            if k == last {
                let n = sides[k - 1].pow(2);
                let lanes = row_lanes(n);
                steps += n.div_ceil(lanes) as u64 + u64::from(lanes.ilog2());
                if k == 1 {
                    return steps;
                }
                down = false;
                k -= 1;
                continue;
            }
            corrections[k] = 0;
            steps += share(k) + share(k) + share(k + 1);
            k += 1;
            continue;
        }
        steps += share(k);
        corrections[k] += 1;
        if corrections[k] < COARSE_CORRECTIONS {
            steps += share(k) + share(k + 1);
            k += 1;
            down = true;
            continue;
        }
        steps += 2 * share(k);
        if k == 1 {
            return steps;
        }
        k -= 1;
    }
}

/// The serial steps of a list of dispatches ([`Kernel::serial_steps`]), which run one after
/// another: the longest chain a step's dispatches make whatever the GPU's width.
pub fn serial_chain(kernels: &[Kernel], state: &DeviceState) -> u64 {
    kernels.iter().map(|k| k.serial_steps(state)).sum()
}

/// The kernels' pipelines, compiled once per device.
pub struct Pipelines {
    pipelines: Vec<wgpu::ComputePipeline>,
}

impl Pipelines {
    /// Every kernel at once, without waiting for the device to take them (a browser then
    /// compiles them before the first submission runs).
    pub fn new(ctx: &GpuContext) -> Self {
        let pipelines = Kernel::ALL.iter().map(|&k| pipeline(ctx, k)).collect();
        Pipelines { pipelines }
    }

    /// The pipelines [`compile`] made, one per kernel in the order of [`Kernel::ALL`].
    ///
    /// # Panics
    /// If there are not as many as kernels.
    pub fn from_compiled(pipelines: Vec<wgpu::ComputePipeline>) -> Self {
        assert_eq!(pipelines.len(), Kernel::ALL.len(), "one pipeline per kernel, in the order of Kernel::ALL");
        Pipelines { pipelines }
    }

    fn get(&self, k: Kernel) -> &wgpu::ComputePipeline {
        &self.pipelines[k as usize]
    }
}

/// One kernel's pipeline, resolved once the device has taken it: a browser compiles in its GPU
/// process, so awaiting each kernel in turn lets a page show the compilation's progress (about
/// 5 s for all of them on SwiftShader). An error names the kernel.
pub fn compile(
    ctx: &GpuContext,
    kernel: Kernel,
) -> impl Future<Output = Result<wgpu::ComputePipeline, GpuError>> + 'static {
    compile_wgsl(ctx, &kernel.wgsl(), kernel.source().1)
}

/// [`compile`] of WGSL source and its entry point.
fn compile_wgsl(
    ctx: &GpuContext,
    source: &str,
    entry: &'static str,
) -> impl Future<Output = Result<wgpu::ComputePipeline, GpuError>> + 'static {
    let scope = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let made = pipeline_from(ctx, source, entry);
    checked(entry, made, scope.pop())
}

/// The pipeline once its error scope resolved without an error.
async fn checked(
    name: &'static str,
    pipeline: wgpu::ComputePipeline,
    errors: impl Future<Output = Option<wgpu::Error>>,
) -> Result<wgpu::ComputePipeline, GpuError> {
    match errors.await {
        None => Ok(pipeline),
        Some(e) => Err(GpuError::Kernel { kernel: name, reason: e.to_string() }),
    }
}

fn pipeline(ctx: &GpuContext, kernel: Kernel) -> wgpu::ComputePipeline {
    let (source, entry) = (kernel.wgsl(), kernel.source().1);
    pipeline_from(ctx, &source, entry)
}

fn pipeline_from(ctx: &GpuContext, source: &str, entry: &str) -> wgpu::ComputePipeline {
    let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(entry),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    ctx.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        // Derived from the shader: exactly the bindings the entry point uses.
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A monolayer's state on the device with the pipelines and bind groups that step it.
pub struct GpuMonolayer {
    pipelines: Pipelines,
    state: DeviceState,
    bind_groups: Vec<wgpu::BindGroup>,
    /// CG iterations recorded per friction solve (the host cannot stop early: nothing is read
    /// back inside a step); a solve that has not converged by then is reported by
    /// [`Self::read_solve`].
    pub solve_iterations: usize,
    pub preconditioner: Preconditioner,
}

/// CG iterations recorded per friction solve with the multigrid preconditioner unless set
/// otherwise: a cold start at the paper's size and χ = 0.001 takes about a dozen (tests/gpu.rs),
/// a warm-started solve inside a run 3–5; the iterations after convergence return at once.
pub const SOLVE_ITERATIONS: usize = 30;

/// The same for the Jacobi preconditioner: a cold start at the paper's size takes about 210.
pub const JACOBI_ITERATIONS: usize = 400;

impl GpuMonolayer {
    /// Compiles the kernels and uploads the monolayer's current state; refuses a monolayer
    /// beyond the device's limits, naming the limit.
    pub fn new(ctx: &GpuContext, m: &Monolayer) -> Result<Self, GpuError> {
        Self::with_pipelines(ctx, Pipelines::new(ctx), m)
    }

    /// [`Self::new`] with pipelines compiled beforehand ([`compile`]).
    pub fn with_pipelines(ctx: &GpuContext, pipelines: Pipelines, m: &Monolayer) -> Result<Self, GpuError> {
        let state = DeviceState::upload(ctx, m)?;
        let bind_groups = bind_groups(ctx, &pipelines, &state);
        Ok(GpuMonolayer {
            pipelines,
            state,
            bind_groups,
            solve_iterations: SOLVE_ITERATIONS,
            preconditioner: Preconditioner::Multigrid,
        })
    }

    /// Replaces the device state by the monolayer's current one (patches may have moved, so
    /// buffers and bind groups are made anew).
    pub fn upload(&mut self, ctx: &GpuContext, m: &Monolayer) -> Result<(), GpuError> {
        self.upload_in(ctx, m, Layout::of(m))
    }

    /// [`Self::upload`] in a given layout (tests: a capacity the patches soon outgrow).
    pub fn upload_in(&mut self, ctx: &GpuContext, m: &Monolayer, layout: Layout) -> Result<(), GpuError> {
        self.state = DeviceState::upload_in(ctx, m, layout)?;
        self.bind_groups = bind_groups(ctx, &self.pipelines, &self.state);
        Ok(())
    }

    pub fn state(&self) -> &DeviceState {
        &self.state
    }

    pub fn state_mut(&mut self) -> &mut DeviceState {
        &mut self.state
    }

    /// Records the kernels, in the given order, into one compute pass. Within a pass every
    /// dispatch sees the writes of the ones before it (WebGPU's usage scopes are per dispatch).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, kernels: &[Kernel]) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("stages"), timestamp_writes: None });
        for &k in kernels {
            self.dispatch(&mut pass, k);
        }
    }

    fn dispatch(&self, pass: &mut wgpu::ComputePass, k: Kernel) {
        let [x, y, z] = k.workgroups(&self.state);
        pass.set_pipeline(self.pipelines.get(k));
        pass.set_bind_group(0, &self.bind_groups[k as usize], &[]);
        pass.dispatch_workgroups(x, y, z);
    }

    /// Runs the kernels, each in its own compute pass with a timestamp at its start and its end,
    /// and returns each one's time on the device in ms; `None` where the device writes no
    /// timestamps ([`GpuContext::has_timestamps`]). Blocking, native only: `bench --gpu`. An
    /// error if the device failed.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn time_kernels(&self, ctx: &GpuContext, kernels: &[Kernel]) -> Result<Option<Vec<f64>>, GpuError> {
        if !ctx.has_timestamps() {
            return Ok(None);
        }
        let period_ns = f64::from(ctx.queue.get_timestamp_period());
        let mut out = Vec::with_capacity(kernels.len());
        for chunk in kernels.chunks(wgpu::QUERY_SET_MAX_QUERIES as usize / 2) {
            let count = 2 * chunk.len() as u32;
            let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage times"),
                ty: wgpu::QueryType::Timestamp,
                count,
            });
            let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("stage times"),
                size: wgpu::QUERY_SIZE as u64 * count as u64,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let mut encoder =
                ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("stage times") });
            for (i, &k) in chunk.iter().enumerate() {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("stage"),
                    timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                        query_set: &set,
                        beginning_of_pass_write_index: Some(2 * i as u32),
                        end_of_pass_write_index: Some(2 * i as u32 + 1),
                    }),
                });
                self.dispatch(&mut pass, k);
            }
            encoder.resolve_query_set(&set, 0..count, &resolved, 0);
            ctx.queue.submit([encoder.finish()]);
            let words = read_now(ctx, &resolved)?;
            let tick = |i: usize| u64::from(words[2 * i]) | (u64::from(words[2 * i + 1]) << 32);
            out.extend((0..chunk.len()).map(|i| tick(2 * i + 1).saturating_sub(tick(2 * i)) as f64 * period_ns / 1e6));
        }
        Ok(Some(out))
    }

    /// Encodes and submits the kernels; returns without waiting for them.
    pub fn run(&self, ctx: &GpuContext, kernels: &[Kernel]) -> wgpu::SubmissionIndex {
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("stages") });
        self.encode(&mut encoder, kernels);
        ctx.queue.submit([encoder.finish()])
    }

    /// The stages up to the friction solve's right-hand side, in evaluation order: Σφ², A_i,
    /// μ_i, Q_i, f_i, n and F.
    pub fn evaluate(&self, ctx: &GpuContext) -> wgpu::SubmissionIndex {
        self.run(ctx, &Kernel::FRICTION_SUMS)
    }

    /// The friction solve's preconditioner and recorded iterations where the phase has one.
    pub fn solve(&self) -> Option<(Preconditioner, usize)> {
        self.state.solves_friction.then_some((self.preconditioner, self.solve_iterations))
    }

    /// Sets the preconditioner, with its default recorded iterations.
    pub fn set_preconditioner(&mut self, pc: Preconditioner) {
        self.preconditioner = pc;
        self.solve_iterations = pc.default_iterations();
    }

    /// The kernels of one whole step in the uploaded phase ([`Kernel::whole_step`]: the Heun
    /// step and the patches following the cells).
    pub fn step_kernels(&self) -> Vec<Kernel> {
        Kernel::whole_step(self.solve())
    }

    /// One Heun step on the patches as they are, with the friction solve where the phase has
    /// one, all in one submission with nothing read back (the CPU's
    /// `Monolayer::step_on_fixed_patches`). Whether φ left its range is in [`Slot::Fault`], per
    /// cell; whether the last solve converged, in [`Self::read_solve`].
    pub fn step_on_fixed_patches(&self, ctx: &GpuContext) -> wgpu::SubmissionIndex {
        self.run(ctx, &Kernel::step(self.solve()))
    }

    /// One step as the CPU's `Monolayer::step` takes it within a phase: the Heun step, then the
    /// patches following the cells ([`Kernel::whole_step`]), in one submission. A cell whose
    /// patch could not follow is in [`Slot::PatchFault`].
    pub fn step(&self, ctx: &GpuContext) -> wgpu::SubmissionIndex {
        self.run(ctx, &self.step_kernels())
    }

    /// The patches as they are on the device now (they move with every [`Self::step`]).
    /// Blocking, native only, as the three below: tests and diagnostics; a run reads its state
    /// through `readback::read_words`, a future. Each is an error if the device failed.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_patches(&self, ctx: &GpuContext) -> Result<Vec<GpuPatch>, GpuError> {
        Ok(bytemuck::cast_slice(&read_now(ctx, self.state.buffer(Slot::Patches))?).to_vec())
    }

    /// The friction solve's scalars after every submitted kernel has finished: its iterations,
    /// its residual and whether it converged.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_solve(&self, ctx: &GpuContext) -> Result<SolveScalars, GpuError> {
        // The buffer was made with the size of `SolveScalars` (`DeviceState::upload`), so the
        // words read are one of them whatever the device wrote into it.
        Ok(*bytemuck::from_bytes(bytemuck::cast_slice(&read_now(ctx, self.state.buffer(Slot::Solve))?)))
    }

    /// A buffer's contents as u32 (`Slot::Fault`), after every submitted kernel has finished.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_u32(&self, ctx: &GpuContext, slot: Slot) -> Result<Vec<u32>, GpuError> {
        read_now(ctx, self.state.buffer(slot))
    }

    /// A buffer's contents as f32, after every submitted kernel has finished: a readback stalls
    /// the queue (milliseconds in a browser).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read(&self, ctx: &GpuContext, slot: Slot) -> Result<Vec<f32>, GpuError> {
        Ok(read_now(ctx, self.state.buffer(slot))?.into_iter().map(f32::from_bits).collect())
    }
}

fn bind_groups(ctx: &GpuContext, pipelines: &Pipelines, state: &DeviceState) -> Vec<wgpu::BindGroup> {
    Kernel::ALL
        .iter()
        .map(|&k| {
            let entries: Vec<wgpu::BindGroupEntry> = k
                .slots()
                .iter()
                .map(|&s| wgpu::BindGroupEntry { binding: s.binding(), resource: state.buffer(s).as_entire_binding() })
                .collect();
            ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(k.source().1),
                layout: &pipelines.get(k).get_bind_group_layout(0),
                entries: &entries,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A kernel the device refuses is named in the error, not left to the device's panic
    /// handler or a blank page (the page compiles each kernel with [`compile`]).
    #[cfg(not(target_arch = "wasm32"))]
    #[test]
    fn a_kernel_that_does_not_compile_is_named() {
        let ctx = match GpuContext::new() {
            Ok(ctx) => ctx,
            Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => panic!("CI=true: no adapter: {e}"),
            Err(_) => return,
        };
        let broken = "@compute @workgroup_size(1) fn broken() { let x: f32 = 1u; }";
        let error = pollster::block_on(compile_wgsl(&ctx, broken, "broken")).expect_err("refused");
        assert!(matches!(&error, GpuError::Kernel { kernel: "broken", .. }), "{error}");
        assert!(pollster::block_on(compile(&ctx, Kernel::LatticeSums)).is_ok());
    }

    /// Pipelines and bind groups are stored in the order of `Kernel::ALL` and found by
    /// `kernel as usize`; buffers likewise by `slot as usize`.
    #[test]
    fn lists_follow_the_declaration_order() {
        for (i, k) in Kernel::ALL.iter().enumerate() {
            assert_eq!(*k as usize, i, "{k:?}");
        }
        for (i, s) in Slot::ALL.iter().enumerate() {
            assert_eq!(s.binding() as usize, i, "{s:?}");
        }
    }

    /// The workgroup size written in each entry point's WGSL is the one the host dispatches for
    /// (`workgroups`): a mismatch would leave sites unvisited or visit them twice, silently.
    #[test]
    fn each_kernels_workgroup_is_the_one_the_host_counts_with() {
        for k in Kernel::ALL {
            let (source, entry) = (k.wgsl(), k.source().1);
            let at = source.find(&format!("fn {entry}(")).unwrap_or_else(|| panic!("{entry} in its WGSL"));
            let attr = source[..at].rfind("@workgroup_size(").unwrap_or_else(|| panic!("{entry}: no @workgroup_size"));
            let inner = &source[attr + "@workgroup_size(".len()..];
            let size: Vec<usize> = inner[..inner.find(')').unwrap()]
                .split(',')
                .map(|v| v.trim().parse().expect("a literal size"))
                .collect();
            let expected = match k.grid() {
                Grid::Lattice => vec![LATTICE_TILE, LATTICE_TILE],
                Grid::Cells | Grid::Sites => vec![SITES_PER_GROUP],
                Grid::LatticeRows | Grid::LevelOne | Grid::Single => vec![LATTICE_GROUP],
            };
            assert_eq!(size, expected, "{entry} ({:?})", k.grid());
        }
        // The margin friction_check divides by is the one the host multiplies the tolerance by.
        let at = FRICTION_WGSL.find("const RECURSIVE_RESIDUAL_MARGIN: f32 = ").expect("the margin in friction.wgsl");
        let value: String = FRICTION_WGSL[at + 39..].chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
        assert_eq!(value.parse::<f64>().unwrap(), crate::gpu::buffers::RECURSIVE_RESIDUAL_MARGIN, "WGSL margin");
        // The lanes of a total are the ones the serial steps count with.
        let at = FRICTION_WGSL.find("const TOTAL_LANES: u32 = ").expect("TOTAL_LANES in friction.wgsl");
        let value: String = FRICTION_WGSL[at + 25..].chars().take_while(char::is_ascii_digit).collect();
        assert_eq!(value.parse::<usize>().unwrap(), TOTAL_LANES, "WGSL TOTAL_LANES");
        // The gather's chunk is the one the serial steps count with.
        let at = GATHER_WGSL.find("const CHUNK: u32 = ").expect("CHUNK in gather.wgsl");
        let value: String = GATHER_WGSL[at + 19..].chars().take_while(char::is_ascii_digit).collect();
        assert_eq!(value.parse::<usize>().unwrap(), GATHER_CHUNK, "WGSL CHUNK");
        // The reductions' group in friction.wgsl and multigrid.wgsl is the host's.
        for text in [FRICTION_WGSL, MULTIGRID_WGSL] {
            if let Some(at) = text.find("const GROUP: u32 = ") {
                let value: String = text[at + 19..].chars().take_while(char::is_ascii_digit).collect();
                assert_eq!(value.parse::<usize>().unwrap(), LATTICE_GROUP, "WGSL GROUP");
            }
        }
    }

    /// The walk visits the coarsest level 2^(levels − 1) times (two corrections below level 1),
    /// as the W-cycle does: sides 70, 35, 18, 9, 5 (the paper's 140²) give 16 visits of a
    /// 25-row inverse applied 8 lanes to a row (4 products, then 3 tree steps), and each finer
    /// level's loops in proportion.
    #[test]
    fn the_coarse_cycles_serial_steps_follow_the_w_cycle() {
        assert_eq!((row_lanes(25), row_lanes(36), row_lanes(16), row_lanes(1)), (8, 4, 16, 16));
        assert_eq!(coarse_cycle_steps(&[]), 0);
        assert_eq!(coarse_cycle_steps(&[5]), 4 + 3);
        // One level above the coarsest: down (3 loops), coarsest, up (prolong), down again
        // (restrict: 2 loops), coarsest, up (prolong, then the final sweep's 2 loops).
        assert_eq!(coarse_cycle_steps(&[9, 5]), (1 + 1 + 1) + 7 + 1 + (1 + 1) + 7 + 1 + 2);
        let full = coarse_cycle_steps(&[70, 35, 18, 9, 5]);
        assert!(full > 16 * 7, "{full}");
    }

    /// Every binding a kernel lists is declared in the WGSL it is compiled from with that number.
    #[test]
    fn every_listed_slot_is_declared_by_its_shader() {
        for k in Kernel::ALL {
            let (source, entry) = (k.wgsl(), k.source().1);
            for s in k.slots() {
                let declared = format!("@binding({})", s.binding());
                assert!(source.contains(&declared), "{entry}: {s:?} not declared as {declared}");
            }
        }
    }
}
