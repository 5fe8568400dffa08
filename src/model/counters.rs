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
    /// The lattice friction solve for V, with the setup of its operator.
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
        let (r, seconds) = wall_time(f);
        self.seconds[stage as usize] += seconds;
        r
    }

    /// Runs `f`, a parallel loop that runs the `stages` cell by cell, each timed through
    /// `Laps`, and shares its wall time between them in proportion to the time each took
    /// on its threads.
    pub fn time_laps<R, const N: usize>(&mut self, stages: [Stage; N], f: impl FnOnce(&Laps<N>) -> R) -> R {
        let laps = Laps::default();
        let (r, wall) = wall_time(|| f(&laps));
        for (stage, part) in stages.iter().zip(shares_of(wall, laps.nanos())) {
            self.seconds[*stage as usize] += part;
        }
        r
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

/// `wall` shared in proportion to the laps' times (equally if none took any time).
fn shares_of<const N: usize>(wall: f64, laps: [u64; N]) -> [f64; N] {
    let total: u64 = laps.iter().sum();
    laps.map(|lap| wall * if total > 0 { lap as f64 / total as f64 } else { 1.0 / N as f64 })
}

/// `f`'s result and its wall time in seconds (zero in wasm, which has no `std` clock).
#[inline]
fn wall_time<R>(f: impl FnOnce() -> R) -> (R, f64) {
    #[cfg(not(target_arch = "wasm32"))]
    {
        let t = std::time::Instant::now();
        let r = f();
        (r, t.elapsed().as_secs_f64())
    }
    #[cfg(target_arch = "wasm32")]
    {
        (f(), 0.0)
    }
}

/// Time per stage inside one parallel loop that runs several stages cell by cell: each lap is
/// timed on its own thread and summed over the cells (see [`Counters::time_laps`]).
#[derive(Debug)]
pub struct Laps<const N: usize> {
    #[cfg(not(target_arch = "wasm32"))]
    nanos: [std::sync::atomic::AtomicU64; N],
}

impl<const N: usize> Default for Laps<N> {
    fn default() -> Self {
        Laps {
            #[cfg(not(target_arch = "wasm32"))]
            nanos: std::array::from_fn(|_| std::sync::atomic::AtomicU64::new(0)),
        }
    }
}

impl<const N: usize> Laps<N> {
    /// Runs `f`, adding its time to stage `k` of the loop (a plain call in wasm).
    #[inline]
    pub fn lap<R>(&self, k: usize, f: impl FnOnce() -> R) -> R {
        #[cfg(not(target_arch = "wasm32"))]
        {
            let t = std::time::Instant::now();
            let r = f();
            self.nanos[k].fetch_add(t.elapsed().as_nanos() as u64, std::sync::atomic::Ordering::Relaxed);
            r
        }
        #[cfg(target_arch = "wasm32")]
        {
            let _ = k;
            f()
        }
    }

    fn nanos(&self) -> [u64; N] {
        #[cfg(not(target_arch = "wasm32"))]
        {
            std::array::from_fn(|k| self.nanos[k].load(std::sync::atomic::Ordering::Relaxed))
        }
        #[cfg(target_arch = "wasm32")]
        {
            [0; N]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A loop's wall time goes to its stages in proportion to their laps.
    #[test]
    fn wall_time_is_shared_in_proportion_to_the_laps() {
        assert_eq!(shares_of(2.0, [1, 3]), [0.5, 1.5]);
        assert_eq!(shares_of(2.0, [0, 0, 0, 0]), [0.5; 4]);
        assert_eq!(shares_of(1.0, [0, 7]), [0.0, 1.0]);
    }

    /// Every lap is timed, and all of the loop's wall time goes to its stages. (Which stage
    /// gets more is the pure sharing above: sleeps are only lower bounds on a loaded machine.)
    #[test]
    fn laps_share_all_the_wall_time() {
        let mut c = Counters::default();
        let sleep = |ms| std::thread::sleep(std::time::Duration::from_millis(ms));
        c.time_laps([Stage::Velocity, Stage::Update], |laps| {
            laps.lap(0, || sleep(1));
            laps.lap(1, || sleep(20));
        });
        let (v, u) = (c.seconds[Stage::Velocity as usize], c.seconds[Stage::Update as usize]);
        assert!(v > 0.0 && u > 0.0, "velocity {v} s, update {u} s");
        assert!(v + u >= 0.021, "the loop slept 21 ms: {} s", v + u);
        assert!((v + u - c.total_seconds()).abs() <= 1e-15);
    }
}
