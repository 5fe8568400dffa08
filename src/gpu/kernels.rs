//! The compute kernels, their pipelines and dispatches, and the object that ties them to a device
//! state: [`GpuMonolayer`], which can take a whole Heun step where there is no friction solve.
//!
//! Each kernel's WGSL sits in `shaders/`, one file per stage, named like its CPU module; every
//! file is compiled with `shaders/model.wgsl` (the shared parameters and patches) in front.

use crate::gpu::buffers::{DeviceState, Slot};
use crate::gpu::context::{GpuContext, GpuError};
use crate::model::monolayer::Monolayer;

const MODEL_WGSL: &str = include_str!("../../shaders/model.wgsl");
const GATHER_WGSL: &str = include_str!("../../shaders/gather.wgsl");
const FREE_ENERGY_WGSL: &str = include_str!("../../shaders/free_energy.wgsl");
const SHAPE_WGSL: &str = include_str!("../../shaders/shape.wgsl");
const FORCES_WGSL: &str = include_str!("../../shaders/forces.wgsl");
const MOTION_WGSL: &str = include_str!("../../shaders/motion.wgsl");
const MONOLAYER_WGSL: &str = include_str!("../../shaders/monolayer.wgsl");

/// The per-site kernels' workgroup width (`@workgroup_size(64)`); the lattice kernels'
/// workgroups are 8 × 8 sites.
const SITES_PER_GROUP: usize = 64;
const LATTICE_TILE: usize = 8;

/// One dispatch, in the order of one evaluation of the right-hand side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    /// Σφ and Σφ² on the lattice (`shaders/gather.wgsl`).
    LatticeSums,
    /// A_i (`shaders/free_energy.wgsl`).
    CellArea,
    /// μ_i (`shaders/free_energy.wgsl`); needs Σφ² and A_i.
    ChemicalPotential,
    /// Q_i and Q̂_i (`shaders/shape.wgsl`).
    ShapeTensor,
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
}

/// How a kernel's invocations cover the state.
enum Grid {
    /// One invocation per lattice site, in 8 × 8 tiles.
    Lattice,
    /// One workgroup per cell.
    Cells,
    /// One invocation per padded site of each cell: x the site, y the cell (so at most 65,535
    /// cells, WebGPU's workgroups per dimension; `Layout::fits` checks it).
    Sites,
}

impl Kernel {
    /// Every kernel, in the order of one evaluation.
    pub const ALL: [Kernel; 9] = [
        Kernel::LatticeSums,
        Kernel::CellArea,
        Kernel::ChemicalPotential,
        Kernel::ShapeTensor,
        Kernel::ForceDensity,
        Kernel::FrictionSums,
        Kernel::VelocityAndRate,
        Kernel::Predict,
        Kernel::Correct,
    ];

    /// One evaluation of the rate R(φ) where there is no friction solve: Σφ², A_i, μ_i, Q̂_i, f_i,
    /// then v_i and ∂_t φ_i. (In relaxation ζ = 0 and Q̂_i is not needed; its dispatch stays so
    /// that one list serves both phases, as the CPU computes Q_i in both.)
    pub const RATE: [Kernel; 6] = [
        Kernel::LatticeSums,
        Kernel::CellArea,
        Kernel::ChemicalPotential,
        Kernel::ShapeTensor,
        Kernel::ForceDensity,
        Kernel::VelocityAndRate,
    ];

    /// The stages up to the friction solve's right-hand side (n and F): [`Self::RATE`]'s up to
    /// the forces, then the friction sums.
    pub const FRICTION_SUMS: [Kernel; 6] = {
        let mut out = Kernel::RATE;
        out[5] = Kernel::FrictionSums;
        out
    };

    /// One Heun step without a friction solve: R(φ), the predictor, R(φ*), the corrector.
    pub const STEP: [Kernel; 14] = {
        let mut out = [Kernel::Predict; 14];
        let mut k = 0;
        while k < 6 {
            out[k] = Kernel::RATE[k];
            out[7 + k] = Kernel::RATE[k];
            k += 1;
        }
        out[13] = Kernel::Correct;
        out
    };

    /// The stage's WGSL file and the kernel's entry point in it.
    fn source(self) -> (&'static str, &'static str) {
        match self {
            Kernel::LatticeSums => (GATHER_WGSL, "lattice_sums"),
            Kernel::CellArea => (FREE_ENERGY_WGSL, "cell_area"),
            Kernel::ChemicalPotential => (FREE_ENERGY_WGSL, "chemical_potential"),
            Kernel::ShapeTensor => (SHAPE_WGSL, "shape_tensor"),
            Kernel::ForceDensity => (FORCES_WGSL, "force_density"),
            Kernel::FrictionSums => (GATHER_WGSL, "friction_sums"),
            Kernel::VelocityAndRate => (MOTION_WGSL, "velocity_and_rate"),
            Kernel::Predict => (MONOLAYER_WGSL, "predict"),
            Kernel::Correct => (MONOLAYER_WGSL, "correct"),
        }
    }

    /// The buffers the entry point uses, which is what its bind group must hold: the pipeline's
    /// layout is derived from the shader, so a slot missing here, or one too many, fails at
    /// bind-group creation.
    fn slots(self) -> &'static [Slot] {
        use Slot::*;
        match self {
            Kernel::LatticeSums => &[Params, Patches, Phi, SumPhi, SumPhi2],
            Kernel::CellArea => &[Patches, Phi, Area],
            Kernel::ChemicalPotential => &[Params, Patches, Phi, SumPhi2, Area, Mu],
            Kernel::ShapeTensor => &[Params, Patches, Phi, Shape, QHat],
            Kernel::ForceDensity => &[Params, Patches, Phi, Mu, QHat, Fx, Fy],
            Kernel::FrictionSums => &[Params, Patches, Phi, Fx, Fy, Weight, Force],
            Kernel::VelocityAndRate => &[Params, Patches, Phi, Mu, Fx, Fy, Mobility, Velocity, Rate],
            Kernel::Predict => &[Params, Patches, Phi, Rate, Phi0, K1, Fault],
            Kernel::Correct => &[Params, Patches, Phi, Rate, Phi0, K1, Fault],
        }
    }

    fn grid(self) -> Grid {
        match self {
            Kernel::LatticeSums | Kernel::FrictionSums => Grid::Lattice,
            Kernel::CellArea | Kernel::ShapeTensor => Grid::Cells,
            Kernel::ChemicalPotential
            | Kernel::ForceDensity
            | Kernel::VelocityAndRate
            | Kernel::Predict
            | Kernel::Correct => Grid::Sites,
        }
    }

    /// The bytes a dispatch must move at the least: every value it reads or writes, once (a
    /// stencil's neighbours and the patch table come from cache). For projections: a GPU's
    /// time for a dispatch is at least this over its memory bandwidth.
    pub fn compulsory_bytes(self, state: &DeviceState) -> u64 {
        let layout = &state.layout;
        let padded = layout.total as u64;
        let interior: u64 = layout.patches.iter().map(|p| p.w as u64 * p.h as u64).sum();
        let (n, l2) = (layout.n_cells() as u64, (layout.box_size * layout.box_size) as u64);
        let values = match self {
            // φ at every covered site; Σφ and Σφ² written.
            Kernel::LatticeSums => interior + 2 * l2,
            // φ; A_i written.
            Kernel::CellArea => padded + n,
            // φ and Σφ² at each interior site; μ written, halo included.
            Kernel::ChemicalPotential => padded + interior + padded,
            // φ; Q_i and Q̂_i written.
            Kernel::ShapeTensor => padded + 4 * n,
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
        };
        4 * values
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
        }
    }
}

/// The kernels' pipelines, compiled once per device.
pub struct Pipelines {
    pipelines: Vec<wgpu::ComputePipeline>,
}

impl Pipelines {
    pub fn new(ctx: &GpuContext) -> Self {
        let pipelines = Kernel::ALL.iter().map(|&k| pipeline(ctx, k)).collect();
        Pipelines { pipelines }
    }

    fn get(&self, k: Kernel) -> &wgpu::ComputePipeline {
        &self.pipelines[k as usize]
    }
}

fn pipeline(ctx: &GpuContext, kernel: Kernel) -> wgpu::ComputePipeline {
    let (stage, entry) = kernel.source();
    let source = format!("{MODEL_WGSL}\n{stage}");
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
}

impl GpuMonolayer {
    /// Compiles the kernels and uploads the monolayer's current state; refuses a monolayer
    /// beyond the device's limits, naming the limit.
    pub fn new(ctx: &GpuContext, m: &Monolayer) -> Result<Self, GpuError> {
        let pipelines = Pipelines::new(ctx);
        let state = DeviceState::upload(ctx, m)?;
        let bind_groups = bind_groups(ctx, &pipelines, &state);
        Ok(GpuMonolayer { pipelines, state, bind_groups })
    }

    /// Replaces the device state by the monolayer's current one (patches may have moved, so
    /// buffers and bind groups are made anew).
    pub fn upload(&mut self, ctx: &GpuContext, m: &Monolayer) -> Result<(), GpuError> {
        self.state = DeviceState::upload(ctx, m)?;
        self.bind_groups = bind_groups(ctx, &self.pipelines, &self.state);
        Ok(())
    }

    pub fn state(&self) -> &DeviceState {
        &self.state
    }

    /// Records the kernels, in the given order, into one compute pass. Within a pass every
    /// dispatch sees the writes of the ones before it (WebGPU's usage scopes are per dispatch).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, kernels: &[Kernel]) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("stages"), timestamp_writes: None });
        for &k in kernels {
            let [x, y, z] = k.workgroups(&self.state);
            pass.set_pipeline(self.pipelines.get(k));
            pass.set_bind_group(0, &self.bind_groups[k as usize], &[]);
            pass.dispatch_workgroups(x, y, z);
        }
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

    /// One Heun step on the patches as they are (they do not follow the cells on the GPU yet),
    /// all in one submission with nothing read back: [`Kernel::STEP`]. Only where the CPU has no
    /// friction solve (relaxation, or ξ_cell = 0), which the state was uploaded in: the GPU has
    /// no friction solve yet. Whether φ left its range is in [`Slot::Fault`], per cell.
    pub fn step(&self, ctx: &GpuContext) -> wgpu::SubmissionIndex {
        assert!(
            !self.state.solves_friction,
            "the GPU step needs a phase without a friction solve (relaxation, or xi_cell = 0)"
        );
        self.run(ctx, &Kernel::STEP)
    }

    /// A buffer's contents as u32 (`Slot::Fault`), after every submitted kernel has finished. For
    /// tests and diagnostics only.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read_u32(&self, ctx: &GpuContext, slot: Slot) -> Vec<u32> {
        read_f32(ctx, self.state.buffer(slot)).iter().map(|v| v.to_bits()).collect()
    }

    /// A buffer's contents as f32, after every submitted kernel has finished. For tests and
    /// diagnostics only: a readback stalls the queue (milliseconds in a browser). Native only
    /// for now (it blocks on the device).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn read(&self, ctx: &GpuContext, slot: Slot) -> Vec<f32> {
        read_f32(ctx, self.state.buffer(slot))
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

/// Copies `buffer` to a mappable one, waits for the queue and reads it as f32.
#[cfg(not(target_arch = "wasm32"))]
fn read_f32(ctx: &GpuContext, buffer: &wgpu::Buffer) -> Vec<f32> {
    let size = buffer.size();
    let staging = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        // The receiver waits below; it cannot be gone.
        let _ = tx.send(r);
    });
    ctx.wait();
    rx.recv().expect("the map callback runs during the poll").expect("the readback buffer maps");
    let data = staging.get_mapped_range(..).expect("the buffer is mapped");
    let out = bytemuck::cast_slice(&data).to_vec();
    drop(data);
    staging.unmap();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// Every binding a kernel lists is declared in its stage's WGSL file with that number.
    #[test]
    fn every_listed_slot_is_declared_by_its_shader() {
        for k in Kernel::ALL {
            let (source, entry) = k.source();
            for s in k.slots() {
                let declared = format!("@binding({})", s.binding());
                assert!(source.contains(&declared), "{entry}: {s:?} not declared as {declared}");
            }
        }
    }
}
