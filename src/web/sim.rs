//! `WebSim`: the object the page drives. It owns a [`Monolayer`] and forwards to it; the only
//! state of its own is what the page adds (the painted substrate map, each cell's colour key,
//! the measurements of the last frame).

use wasm_bindgen::prelude::*;

use super::binding::js_err;

use super::measure::{tissue_stats, TissueStats};
use super::readouts::{run_record_json, ReadoutLog};
use super::render::WebView;
use super::view::{FieldKind, ViewBuilder};
use crate::analysis::VoidRegions;
use crate::formats::{encode_frame, frame_file_name, snapshot};
use crate::{Monolayer, Params};

/// The page's parameters: its size and the three sliders; every other one is the native default.
fn page_params(box_size: usize, n_cells: usize, relax_steps: u32, zeta: f64, chi: f64, gamma: f64) -> Params {
    let mut p = Params { box_size, n_cells, relax_steps: relax_steps as u64, zeta, gamma, ..Params::default() };
    p.set_chi(chi);
    p
}

/// The state a GPU engine downloaded (`gpu_engine::WebGpuEngine::download`), for
/// [`WebSim::adopt`].
#[cfg(feature = "gpu")]
#[wasm_bindgen]
pub struct GpuState(pub(super) Monolayer);

#[cfg(feature = "gpu")]
#[wasm_bindgen]
impl GpuState {
    pub fn step_count(&self) -> f64 {
        self.0.step_count() as f64
    }
}

/// The simulation object the page drives (step, parameters, brushes): a [`Monolayer`], its view
/// and its readouts.
#[wasm_bindgen]
pub struct WebSim {
    m: Monolayer,
    /// Colour key of each cell (cell index + 1 at the start; unchanged when a cell is removed).
    keys: Vec<u32>,
    /// Per-site multiplier of ξ_s painted by the brushes (1 = untouched).
    substrate: Vec<f64>,
    view: ViewBuilder,
    stats: TissueStats,
    /// Step at which `stats` was measured (u64::MAX: never).
    stats_step: u64,
    regions: VoidRegions,
    /// The readouts since the tissue was made (the Download button's CSV).
    log: ReadoutLog,
}

/// A copy of a tissue's core, stepped without the page's readouts (a row of measurements every
/// 10 active steps, 8–10 % of the page's step): the same steps, bit for bit, as the native core
/// times, so that the tests compare like with like (docs/performance.md, "wasm against
/// native"). Stepping it leaves the page's tissue as it was.
#[wasm_bindgen]
pub struct CoreCopy(Monolayer);

#[wasm_bindgen]
impl CoreCopy {
    /// Runs `n` steps.
    pub fn step(&mut self, n: u32) -> Result<(), JsError> {
        self.0.advance(n as u64).map_err(js_err)
    }

    pub fn step_count(&self) -> f64 {
        self.0.step_count() as f64
    }
}

#[wasm_bindgen]
impl WebSim {
    /// A copy of the tissue's core, to time without the readouts ([`CoreCopy`]).
    pub fn core_copy(&self) -> CoreCopy {
        CoreCopy(self.m.clone())
    }

    /// A new tissue from random disks: the protocol's relaxation (ζ = 0, no cell friction)
    /// for `relax_steps`, then activity ζ at friction ratio χ = ξ_s/ξ_cell and surface tension γ.
    /// Every other parameter keeps the native default.
    #[wasm_bindgen(constructor)]
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        box_size: usize,
        n_cells: usize,
        relax_steps: u32,
        zeta: f64,
        chi: f64,
        gamma: f64,
        seed: u32,
    ) -> Result<WebSim, JsError> {
        let p = page_params(box_size, n_cells, relax_steps, zeta, chi, gamma);
        Ok(Self::wrap(Monolayer::new(p, seed as u64).map_err(js_err)?))
    }

    /// The same tissue as [`WebSim::new`] with the same arguments, further on: its state is
    /// read from `snapshot` (written natively by `monolayer relaxed-state`), bit for bit what
    /// stepping here would give. A state at the end of the relaxation serves every ζ and χ; a
    /// later one (`--advance`) only exactly the parameters that made it. Throws if the snapshot
    /// was made with other parameters or another seed, or is damaged; the page then relaxes live.
    #[allow(clippy::too_many_arguments)]
    pub fn from_snapshot(
        snapshot: &[u8],
        box_size: usize,
        n_cells: usize,
        relax_steps: u32,
        zeta: f64,
        chi: f64,
        gamma: f64,
        seed: u32,
    ) -> Result<WebSim, JsError> {
        let p = page_params(box_size, n_cells, relax_steps, zeta, chi, gamma);
        p.validate().map_err(js_err)?;
        let state = snapshot::decode_shipped(snapshot, &p, seed as u64).map_err(js_err)?;
        Ok(Self::wrap(Monolayer::from_state(p, seed as u64, state).map_err(js_err)?))
    }

    /// The tissue, for the GPU engine's upload.
    #[cfg(feature = "gpu")]
    pub(super) fn monolayer(&self) -> &Monolayer {
        &self.m
    }

    fn wrap(m: Monolayer) -> WebSim {
        let (n, l) = (m.params().n_cells, m.params().box_size);
        let mut log = ReadoutLog::default();
        log.record_if_due(&m);
        WebSim {
            log,
            keys: (1..=n as u32).collect(),
            substrate: vec![1.0; l * l],
            view: ViewBuilder::default(),
            stats: TissueStats::default(),
            stats_step: u64::MAX,
            regions: VoidRegions::default(),
            m,
        }
    }

    /// Takes the state a GPU engine downloaded (`WebGpuEngine::download`) as this tissue's:
    /// what is drawn and read out from now on is measured on it, as on the CPU engine's. Its
    /// cells must be this tissue's (the engine was uploaded from it and steps it). The download
    /// carries φ only, so the velocities and Q̂ that the speed, director, strain-rate and
    /// force views and the readouts measure are evaluated here, on the CPU, from that φ (the
    /// trajectory is the same with or without the evaluation).
    #[cfg(feature = "gpu")]
    pub fn adopt(&mut self, state: GpuState) -> Result<(), JsError> {
        let mut m = state.0;
        if m.cells().len() != self.m.cells().len() || m.params().box_size != self.m.params().box_size {
            return Err(JsError::new("adopt: the GPU's state is not this tissue's (upload it again after an edit)"));
        }
        m.evaluate_now().map_err(js_err)?;
        self.m = m;
        self.stats_step = u64::MAX;
        self.log.record_if_due(&self.m);
        Ok(())
    }

    /// Runs `n` steps. On an error (instability, failed solve) the state before the failing
    /// step is kept and the error's message is thrown to the page.
    pub fn step(&mut self, n: u32) -> Result<(), JsError> {
        self.log.advance(&mut self.m, n as u64).map_err(js_err)
    }

    /// The readouts since the tissue was made as CSV, its last row the current state
    /// (`readouts::ReadoutLog::csv`).
    pub fn readouts_csv(&mut self) -> String {
        self.log.csv(&self.m)
    }

    /// Steps from `step` (the GPU engine's, which may be ahead of this tissue) to the next state
    /// due a readout row: the GPU engine ends its submissions there and hands that state over,
    /// so that its readouts have the CPU engine's rows.
    pub fn steps_to_next_row(&self, step: f64) -> f64 {
        ReadoutLog::steps_to_next_row(step as u64, self.m.params().relax_steps) as f64
    }

    /// Rows recorded so far.
    pub fn readout_rows(&self) -> usize {
        self.log.rows.len()
    }

    /// The current state as a frame file in the native format (`monolayer run`'s `.npz`).
    pub fn frame_npz(&mut self) -> Result<Vec<u8>, JsError> {
        encode_frame(&mut self.m).map_err(js_err)
    }

    /// Its name in a run directory (`frame_<step>.npz`).
    pub fn frame_name(&self) -> String {
        frame_file_name(self.m.step_count())
    }

    /// A `run.json` that makes a run directory of the frame, for `monolayer analyze`.
    pub fn run_json(&self) -> String {
        run_record_json(&self.m)
    }

    fn update(&mut self, f: impl FnOnce(&mut Params)) -> Result<(), JsError> {
        let mut p = self.m.params().clone();
        f(&mut p);
        self.m.set_params(p).map_err(js_err)
    }

    /// Activity ζ (takes effect after relaxation).
    pub fn set_zeta(&mut self, zeta: f64) -> Result<(), JsError> {
        self.update(|p| p.zeta = zeta)
    }

    /// Friction ratio χ = ξ_s/ξ_cell (sets ξ_s, keeps ξ_cell).
    pub fn set_chi(&mut self, chi: f64) -> Result<(), JsError> {
        self.update(|p| p.set_chi(chi))
    }

    /// Surface tension γ.
    pub fn set_gamma(&mut self, gamma: f64) -> Result<(), JsError> {
        self.update(|p| p.gamma = gamma)
    }

    pub fn zeta(&self) -> f64 {
        self.m.params().zeta
    }

    pub fn chi(&self) -> f64 {
        self.m.params().chi()
    }

    pub fn gamma(&self) -> f64 {
        self.m.params().gamma
    }

    pub fn box_size(&self) -> usize {
        self.m.params().box_size
    }

    pub fn n_cells(&self) -> usize {
        self.m.cells().len()
    }

    pub fn relax_steps(&self) -> f64 {
        self.m.params().relax_steps as f64
    }

    /// Steps since the random disks, relaxation included (f64: exact far beyond any visit to the page).
    pub fn step_count(&self) -> f64 {
        self.m.step_count() as f64
    }

    /// Whether activity is on (relaxation is over).
    pub fn active(&self) -> bool {
        self.m.phase() == crate::Phase::Active
    }

    /// Time since activity started, in simulation units (steps × Δt; 0 while relaxing).
    pub fn active_time(&self) -> f64 {
        self.m.step_count().saturating_sub(self.m.params().relax_steps) as f64 * self.m.params().dt
    }

    /// Seconds per simulation time unit (reporting only: the page's clock and chart).
    pub fn time_unit_seconds(&self) -> f64 {
        self.m.params().time_unit_seconds
    }

    /// The core's bit-exact hash of the state, as 16 hex digits (as `monolayer fingerprint`).
    pub fn fingerprint(&self) -> String {
        format!("{:016x}", self.m.fingerprint())
    }

    fn measure(&mut self) -> TissueStats {
        if self.stats_step != self.m.step_count() {
            let (l, radius) = (self.m.params().box_size, self.m.params().radius);
            let phi_sum = self.m.phi_sum();
            self.stats = tissue_stats(phi_sum, l, radius, &mut self.regions);
            self.stats_step = self.m.step_count();
        }
        self.stats
    }

    /// Σφ on the lattice, row by row (L² values): what tests compare between the engines.
    pub fn phi_sum(&mut self) -> Vec<f64> {
        self.m.phi_sum().to_vec()
    }

    /// Holes: connected void regions (Σφ < 0.01) larger than πR²/4.
    pub fn holes(&mut self) -> u32 {
        self.measure().holes
    }

    /// All void sites (µm² at Δx ≈ 1 µm), in holes or smaller gaps.
    pub fn hole_area(&mut self) -> u32 {
        self.measure().void_area
    }

    /// ±½ defects of the smoothed nematic field as last drawn (director and signed fields),
    /// flattened as [x, y, twice the charge, orientation] per defect.
    pub fn defects(&self) -> Vec<f64> {
        self.view.defects.iter().flat_map(|d| [d.x, d.y, d.twice_charge as f64, d.orientation]).collect()
    }

    /// Spiral cores as last drawn (speed and strain rate), flattened as [x, y, ∇·v] per core.
    pub fn spiral_cores(&self) -> Vec<f64> {
        self.view.spiral_cores.iter().flat_map(|p| [p.x, p.y, p.divergence]).collect()
    }

    /// Fraction of the box covered by cells (Σφ ≥ ½).
    pub fn packing_fraction(&mut self) -> f64 {
        self.measure().packing
    }

    /// Multiplies ξ_s by `multiplier` on a disc of `radius` sites around lattice point (x, y)
    /// (periodic): < 1 is a soft (low-friction) substrate, > 1 a stiff one, 1 erases.
    pub fn paint_substrate(&mut self, x: f64, y: f64, radius: f64, multiplier: f64) -> Result<(), JsError> {
        if !(multiplier.is_finite() && multiplier > 0.0 && radius.is_finite() && radius > 0.0) {
            return Err(JsError::new("brush: multiplier and radius must be finite and > 0"));
        }
        let l = self.m.params().box_size as i64;
        let r = radius.ceil() as i64;
        let (cx, cy) = (x.floor() as i64, y.floor() as i64);
        for dy in -r..=r {
            for dx in -r..=r {
                if ((dx * dx + dy * dy) as f64) <= radius * radius {
                    let (gx, gy) = ((cx + dx).rem_euclid(l), (cy + dy).rem_euclid(l));
                    self.substrate[(gy * l + gx) as usize] = multiplier;
                }
            }
        }
        self.m.set_substrate(&self.substrate).map_err(js_err)
    }

    /// Resets the substrate to uniform friction.
    pub fn clear_substrate(&mut self) -> Result<(), JsError> {
        self.substrate.fill(1.0);
        self.m.set_substrate(&self.substrate).map_err(js_err)
    }

    /// ξ_s multiplier at a site (1 where nothing was painted).
    pub fn substrate_at(&self, x: f64, y: f64) -> f64 {
        let l = self.m.params().box_size as i64;
        let (gx, gy) = ((x.floor() as i64).rem_euclid(l), (y.floor() as i64).rem_euclid(l));
        self.substrate[(gy * l + gx) as usize]
    }

    /// Index of the cell with the largest φ at a lattice point, or −1 where φ < ½ for all.
    pub fn cell_at(&self, x: f64, y: f64) -> i32 {
        let l = self.m.params().box_size;
        let (gx, gy) =
            ((x.floor() as i64).rem_euclid(l as i64) as usize, (y.floor() as i64).rem_euclid(l as i64) as usize);
        let mut best = (-1, 0.5);
        for (i, c) in self.m.cells().iter().enumerate() {
            let p = c.patch();
            let (a, b) = ((gx + l - p.x0) % l, (gy + l - p.y0) % l);
            if a < p.w && b < p.h {
                let v = c.phi().at(a, b);
                if v > best.1 {
                    best = (i as i32, v);
                }
            }
        }
        best.0
    }

    /// Laser ablation: removes the cell under lattice point (x, y) and continues from the same
    /// state without it (the core's checkpoint path, with n_cells − 1). Returns whether a cell
    /// was there.
    pub fn remove_cell_at(&mut self, x: f64, y: f64) -> Result<bool, JsError> {
        let i = self.cell_at(x, y);
        if i < 0 || self.m.cells().len() <= 1 {
            return Ok(false);
        }
        let i = i as usize;
        let mut state = self.m.state();
        state.cells.remove(i);
        let params = Params { n_cells: self.m.params().n_cells - 1, ..self.m.params().clone() };
        self.m = Monolayer::from_state(params, self.m.seed(), state).map_err(js_err)?;
        self.keys.remove(i);
        self.stats_step = u64::MAX;
        Ok(true)
    }

    /// Evaluates the velocities, Q̂ and forces at the current φ, as a GPU hand-off does
    /// ([`WebSim::adopt`]); the CPU engine's own fields are those of its last step's
    /// evaluation. The trajectory is the same either way (the browser tests compare the
    /// engines at one φ with it).
    pub fn evaluate(&mut self) -> Result<(), JsError> {
        self.m.evaluate_now().map_err(js_err)
    }

    /// The values of `field` at every site, row-major, as the renderer colours them (the
    /// browser tests compare the engines with it).
    pub fn field_values(&mut self, field: FieldKind) -> Vec<f32> {
        self.view.build(&mut self.m, &self.keys, field, 1.0).field.iter().map(|f| f[0]).collect()
    }

    /// What the renderer draws for `field` now; `dpr` (device pixels per CSS pixel) sets the
    /// line widths.
    pub fn view(&mut self, field: FieldKind, dpr: f32) -> WebView {
        WebView(self.view.build(&mut self.m, &self.keys, field, dpr).clone())
    }
}
