//! `WebSim`: the object the page drives. It owns a [`Monolayer`] and forwards to it; the only
//! state of its own is what the page adds (the painted substrate map, each cell's colour key,
//! the measurements of the last frame, the readouts and the saved states of "What if?").

use wasm_bindgen::prelude::*;

use super::binding::{js_err, DefectMark, Readout, SpiralMark};

use super::history::{History, Verdict, Watch};
use super::measure::{tissue_stats, TissueStats};
use super::readouts::{run_record_json, ReadoutLog};
use super::render::WebView;
use super::view::{FieldKind, ViewBuilder};
use crate::analysis::VoidRegions;
use crate::formats::{encode_frame, frame_file_name, snapshot};
use crate::model::{Monolayer, Params};

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
    /// The readouts since the tissue was made (the Download button's CSV), with its holes.
    log: ReadoutLog,
    /// The live tissue's saved states, for "What if?" (a replay keeps none).
    history: History,
    /// A replay's watch for the hole it was rewound before, and the fingerprint its state had
    /// when it was saved (None: the live tissue).
    replay: Option<(Watch, u64)>,
}

/// A saved state of the live tissue ([`WebSim::saved_states`]).
#[wasm_bindgen(getter_with_clone)]
pub struct SavedState {
    pub step: f64,
    /// The core's fingerprint of the state when it was saved (16 hex digits).
    pub fingerprint: String,
    /// Bytes it takes.
    pub bytes: f64,
}

/// Where the live tissue rewinds to for its last hole ([`WebSim::rewind_point`]).
#[wasm_bindgen]
#[derive(Clone, Copy)]
pub struct RewindPoint {
    /// The step of the saved state a replay starts from.
    pub from: f64,
    /// The last hole's first row of readouts, and where it opened (its centroid there).
    pub hole_step: f64,
    pub hole_x: f64,
    pub hole_y: f64,
}

/// What a replay watches for and has seen so far ([`WebSim::replay_watch`]).
#[wasm_bindgen(getter_with_clone)]
pub struct ReplayWatch {
    /// The saved state's step, and its fingerprint when it was saved.
    pub from: f64,
    pub saved_fingerprint: String,
    /// The original hole: its first row and where it opened.
    pub hole_step: f64,
    pub hole_x: f64,
    pub hole_y: f64,
    /// The last step watched, and the distance within which a hole is the same tear (R).
    pub until: f64,
    pub radius: f64,
    pub verdict: ReplayVerdict,
    /// The step a hole opened within R, if one did.
    pub tear_step: Option<f64>,
}

/// Whether a replay tore where the original did ([`Verdict`]).
#[wasm_bindgen]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplayVerdict {
    Watching,
    Tore,
    Held,
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
        let m = Monolayer::new(p, seed as u64).map_err(js_err)?;
        let keys = (1..=m.params().n_cells as u32).collect();
        Ok(Self::wrap(m, keys, ReadoutLog::default(), None))
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
        let m = Monolayer::from_state(p, seed as u64, state).map_err(js_err)?;
        let keys = (1..=m.params().n_cells as u32).collect();
        Ok(Self::wrap(m, keys, ReadoutLog::default(), None))
    }

    /// The tissue, for the GPU engine's upload.
    #[cfg(feature = "gpu")]
    pub(super) fn monolayer(&self) -> &Monolayer {
        &self.m
    }

    /// The page's object for `m`, its cells coloured by `keys`, its readouts going on in `log`;
    /// `replay`: a replay's watch (see the field).
    fn wrap(m: Monolayer, keys: Vec<u32>, mut log: ReadoutLog, replay: Option<(Watch, u64)>) -> WebSim {
        log.record_if_due(&m);
        let mut sim = WebSim {
            log,
            keys,
            // The painted multipliers are the core's substrate map (1 where nothing is painted).
            substrate: m.state().substrate,
            view: ViewBuilder::default(),
            stats: TissueStats::default(),
            stats_step: u64::MAX,
            regions: VoidRegions::default(),
            history: History::default(),
            replay,
            m,
        };
        sim.remember();
        sim
    }

    /// Saves the state if it is due ([`History`]); a replay saves none.
    fn remember(&mut self) {
        if self.replay.is_none() {
            let last_hole = self.log.nucleations.last().copied();
            self.history.record_if_due(&self.m, &self.keys, self.log.tracker.as_ref(), last_hole);
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
        self.remember();
        Ok(())
    }

    /// Runs `n` steps, stopping at each row of readouts (and each state to save). On an error
    /// (instability, failed solve) the state before the failing step is kept and the error's
    /// message is thrown to the page.
    pub fn step(&mut self, n: u32) -> Result<(), JsError> {
        let mut left = n as u64;
        while left > 0 {
            let k = left.min(ReadoutLog::steps_to_next_row(self.m.step_count(), self.m.params().relax_steps));
            self.log.advance(&mut self.m, k).map_err(js_err)?;
            self.remember();
            left -= k;
        }
        Ok(())
    }

    /// What the page reads out of the tissue now.
    pub fn readout(&mut self) -> Readout {
        let stats = self.measure();
        Readout::of(&self.m, stats)
    }

    /// The saved states, oldest first ("What if?"; the browser tests compare fingerprints).
    pub fn saved_states(&self) -> Vec<SavedState> {
        let states = self.history.iter().map(|s| SavedState {
            step: s.step as f64,
            fingerprint: format!("{:016x}", s.fingerprint),
            bytes: s.size() as f64,
        });
        states.collect()
    }

    /// Where "What if?" would rewind to: the latest saved state at least `history::LEAD` steps
    /// before the last hole's first row, if one is kept (none in a replay).
    pub fn rewind_point(&self) -> Option<RewindPoint> {
        let hole = self.log.nucleations.last()?;
        let saved = self.history.rewind_point(hole.step).filter(|_| self.replay.is_none())?;
        Some(RewindPoint { from: saved.step as f64, hole_step: hole.step as f64, hole_x: hole.x, hole_y: hole.y })
    }

    /// A replay of this tissue from its [`WebSim::rewind_point`]: a new tissue, bit for bit the
    /// saved state (its readouts start there; its hole tracker goes on from the saved one),
    /// watched for a hole within R of where the last one opened. This tissue is left as it is.
    pub fn rewind(&self) -> Result<WebSim, JsError> {
        let point = self.rewind_point().ok_or_else(|| JsError::new("rewind: no hole with a saved state before it"))?;
        let hole = *self.log.nucleations.last().expect("a rewind point has a hole");
        let saved = self.history.rewind_point(hole.step).expect("the rewind point's state");
        let m = saved.monolayer().map_err(js_err)?;
        let (radius, l) = (m.params().radius, m.params().box_size);
        let log = ReadoutLog::resumed(saved.tracker.clone(), saved.step);
        let watch = Watch::new(point.from as u64, hole, radius, l);
        Ok(WebSim::wrap(m, saved.keys.clone(), log, Some((watch, saved.fingerprint))))
    }

    /// A replay's watch and what it has seen so far (None: the live tissue).
    pub fn replay_watch(&self) -> Option<ReplayWatch> {
        let (w, fingerprint) = self.replay?;
        let (verdict, tear_step) = match w.verdict(self.m.step_count(), &self.log.nucleations) {
            Verdict::Watching => (ReplayVerdict::Watching, None),
            Verdict::Tore(n) => (ReplayVerdict::Tore, Some(n.step as f64)),
            Verdict::Held => (ReplayVerdict::Held, None),
        };
        Some(ReplayWatch {
            from: w.from as f64,
            saved_fingerprint: format!("{fingerprint:016x}"),
            hole_step: w.hole.step as f64,
            hole_x: w.hole.x,
            hole_y: w.hole.y,
            until: w.until as f64,
            radius: w.radius,
            verdict,
            tear_step,
        })
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

    pub fn box_size(&self) -> usize {
        self.m.params().box_size
    }

    pub fn n_cells(&self) -> usize {
        self.m.cells().len()
    }

    /// Steps since the random disks, relaxation included (f64: exact far beyond any visit to the page).
    pub fn step_count(&self) -> f64 {
        self.m.step_count() as f64
    }

    /// Whether activity is on (relaxation is over).
    pub fn active(&self) -> bool {
        self.m.phase() == crate::Phase::Active
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

    /// ±½ defects of the smoothed nematic field as last drawn (director and signed fields).
    pub fn defects(&self) -> Vec<DefectMark> {
        DefectMark::all(&self.view.defects)
    }

    /// Spiral cores as last drawn (speed and strain rate).
    pub fn spiral_cores(&self) -> Vec<SpiralMark> {
        SpiralMark::all(&self.view.spiral_cores)
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
