//! Where the time of a step goes: wall time per stage, and the friction solver's work.
//!
//! The physics never reads a clock; the pipeline wraps each stage in [`Counters::time`]. In
//! WebAssembly there is no `std` clock, so the stage times stay zero there (the page measures
//! steps per second itself).

/// The stages of one evaluation of the right-hand side, plus the per-step work around it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// Σφ², friction weights and force densities gathered onto the lattice.
    Gather,
    /// Cell areas and chemical potentials μ_i.
    ChemicalPotential,
    /// Shape tensors and force densities.
    Forces,
    /// The lattice friction solve for V.
    FrictionSolve,
    /// Per-cell velocities and dφ/dt.
    Velocity,
    /// Heun updates and stability checks.
    Update,
    /// Patch resizing and moving.
    Patches,
}

impl Stage {
    pub const ALL: [Stage; 7] = [
        Stage::Gather,
        Stage::ChemicalPotential,
        Stage::Forces,
        Stage::FrictionSolve,
        Stage::Velocity,
        Stage::Update,
        Stage::Patches,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Gather => "gather onto lattice",
            Stage::ChemicalPotential => "chemical potential",
            Stage::Forces => "shape tensor + forces",
            Stage::FrictionSolve => "friction solve",
            Stage::Velocity => "velocities + dφ/dt",
            Stage::Update => "Heun update + checks",
            Stage::Patches => "patch resizing",
        }
    }
}

/// Accumulated since the last [`Counters::reset`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Counters {
    /// Seconds per stage, indexed like [`Stage::ALL`].
    pub seconds: [f64; 7],
    pub steps: u64,
    /// Friction solves (two per active step: predictor and corrector).
    pub solves: u64,
    /// Krylov iterations summed over the solves.
    pub iterations: u64,
    /// Largest relative residual any solve stopped at.
    pub max_residual: f64,
}

impl Counters {
    pub fn reset(&mut self) {
        *self = Counters::default();
    }

    /// Runs `f`, adding its wall time to `stage` (natively; a plain call in wasm).
    #[inline]
    pub fn time<R>(&mut self, stage: Stage, f: impl FnOnce() -> R) -> R {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let t = std::time::Instant::now();
            let r = f();
            self.seconds[stage as usize] += t.elapsed().as_secs_f64();
            r
        }
        #[cfg(target_arch = "wasm32")]
        {
            let _ = stage;
            f()
        }
    }

    pub fn total_seconds(&self) -> f64 {
        self.seconds.iter().sum()
    }

    /// A table of milliseconds per step by stage.
    pub fn report(&self) -> String {
        let steps = self.steps.max(1) as f64;
        let total = self.total_seconds();
        let mut s = String::new();
        for st in Stage::ALL {
            let t = self.seconds[st as usize];
            s += &format!(
                "  {:<24} {:>8.3} ms/step  {:>5.1} %\n",
                st.name(),
                1e3 * t / steps,
                100.0 * t / total.max(1e-300)
            );
        }
        s += &format!("  {:<24} {:>8.3} ms/step\n", "total", 1e3 * total / steps);
        if self.solves > 0 {
            s += &format!(
                "  friction solve: {:.2} iterations/step ({:.2} per solve), max residual {:.1e}\n",
                self.iterations as f64 / steps,
                self.iterations as f64 / self.solves as f64,
                self.max_residual
            );
        }
        s
    }
}
