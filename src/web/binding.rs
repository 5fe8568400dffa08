//! What every binding shares (wasm32): the start hook that routes a Rust panic to the console,
//! and the error a binding throws to the page.

/// An error of the core as the exception a binding throws to the page.
pub fn js_err(e: impl std::fmt::Display) -> wasm_bindgen::JsError {
    wasm_bindgen::JsError::new(&e.to_string())
}

/// Runs once when the module is instantiated: a Rust panic then reaches the console with its
/// message, and the page (which wraps every call) shows it instead of freezing silently.
#[wasm_bindgen::prelude::wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

/// How many threads run the core's parallel loops: 1 in the single-thread build; in the
/// threaded one (feature `threads`), the workers of the pool that `initThreadPool(n)` started
/// (the worker that calls the core waits while they work).
#[wasm_bindgen::prelude::wasm_bindgen(js_name = coreThreads)]
pub fn core_threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

/// What the page reads out of a tissue, live or a run's frame (worker.js `stats`), by name.
#[wasm_bindgen::prelude::wasm_bindgen]
#[derive(Clone, Copy, Debug)]
pub struct Readout {
    /// Steps since the random disks, relaxation included (f64: exact far beyond any visit).
    pub step: f64,
    /// Whether activity is on (the relaxation is over).
    pub active: bool,
    /// Time since activity started, in time units (steps × Δt; 0 while relaxing).
    pub active_time: f64,
    /// Void regions (Σφ < 0.01) larger than πR²/4.
    pub holes: u32,
    /// All void sites, in holes or smaller gaps (µm² at Δx ≈ 1 µm).
    pub void_area: u32,
    /// Fraction of the box covered by cells (Σφ ≥ ½).
    pub packing: f64,
    pub zeta: f64,
    pub chi: f64,
    pub gamma: f64,
    pub cells: u32,
    pub box_size: u32,
    pub relax_steps: f64,
    /// Seconds per simulation time unit (reporting only: the page's clock and chart).
    pub time_unit_seconds: f64,
}

impl Readout {
    /// The readout of `m`, whose Σφ measured as `stats`.
    pub fn of(m: &crate::Monolayer, stats: super::TissueStats) -> Readout {
        let p = m.params();
        Readout {
            step: m.step_count() as f64,
            active: m.phase() == crate::Phase::Active,
            active_time: m.step_count().saturating_sub(p.relax_steps) as f64 * p.dt,
            holes: stats.holes,
            void_area: stats.void_area,
            packing: stats.packing,
            zeta: p.zeta,
            chi: p.chi(),
            gamma: p.gamma,
            cells: m.cells().len() as u32,
            box_size: p.box_size as u32,
            relax_steps: p.relax_steps as f64,
            time_unit_seconds: p.time_unit_seconds,
        }
    }
}

/// A ±½ defect of the smoothed nematic field as the page marks it (`analysis::Defect`).
#[wasm_bindgen::prelude::wasm_bindgen]
#[derive(Clone, Copy, Debug)]
pub struct DefectMark {
    /// Where it is, in lattice sites.
    pub x: f64,
    pub y: f64,
    /// Twice its charge: +1 or −1.
    pub twice_charge: i32,
    /// A +½ defect's orientation, radians (NaN for a −½, which has none).
    pub orientation: f64,
}

impl DefectMark {
    /// The marks of `defects`, in their order.
    pub fn all(defects: &[crate::analysis::Defect]) -> Vec<DefectMark> {
        let mark = |d: &crate::analysis::Defect| DefectMark {
            x: d.x,
            y: d.y,
            twice_charge: d.twice_charge as i32,
            orientation: d.orientation,
        };
        defects.iter().map(mark).collect()
    }
}

/// A spiral core of the flow as the page marks it (a +1 point of the velocity, `analysis::PlusOne`).
#[wasm_bindgen::prelude::wasm_bindgen]
#[derive(Clone, Copy, Debug)]
pub struct SpiralMark {
    /// Where it is, in lattice sites.
    pub x: f64,
    pub y: f64,
    /// The velocity's divergence there (> 0: the flow swirls outwards).
    pub divergence: f64,
}

impl SpiralMark {
    /// The marks of `cores`, in their order.
    pub fn all(cores: &[crate::analysis::PlusOne]) -> Vec<SpiralMark> {
        cores.iter().map(|p| SpiralMark { x: p.x, y: p.y, divergence: p.divergence }).collect()
    }
}
