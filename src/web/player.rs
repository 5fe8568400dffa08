//! `WebPlayback`: the binding of [`Playback`], a run's frames opened in the page (worker.js
//! reads the dropped or picked files and hands their bytes here, one at a time).

use wasm_bindgen::prelude::*;

use super::binding::{DefectMark, Readout, SpiralMark};
use super::playback::Playback;
use super::render::WebView;
use super::view::FieldKind;

/// A native run's frames opened in the page ([`Playback`]), fed by worker.js.
#[wasm_bindgen]
pub struct WebPlayback(Playback);

#[wasm_bindgen]
impl WebPlayback {
    /// A playback of the run whose `run.json` (its name and text) is given, or of frames alone
    /// (empty name). Throws, naming the file, if the record is not a run of this program.
    #[wasm_bindgen(constructor)]
    pub fn new(run_json_name: &str, run_json: &str) -> Result<WebPlayback, JsError> {
        let record = (!run_json_name.is_empty()).then_some((run_json_name, run_json));
        Playback::new(record).map(WebPlayback).map_err(|e| JsError::new(&e))
    }

    /// Checks a frame file against the run: its step, or throws what is wrong with it.
    pub fn check(&self, name: &str, bytes: &[u8]) -> Result<f64, JsError> {
        self.0.check(name, bytes).map(|s| s as f64).map_err(|e| JsError::new(&e))
    }

    /// Shows a frame file.
    pub fn show(&mut self, name: &str, bytes: &[u8]) -> Result<(), JsError> {
        self.0.show(name, bytes).map_err(|e| JsError::new(&e))
    }

    /// Whether the run's record was given (else the native defaults are assumed).
    pub fn has_record(&self) -> bool {
        self.0.info.is_some()
    }

    /// The code version that wrote the run ("" without run.json).
    pub fn run_version(&self) -> String {
        self.0.info.as_ref().map(|i| i.version.clone()).unwrap_or_default()
    }

    /// The run's seed (0 without run.json).
    pub fn seed(&self) -> f64 {
        self.0.info.as_ref().map_or(0.0, |i| i.seed as f64)
    }

    /// What the page reads out of the frame shown (nothing before the first).
    pub fn readout(&self) -> Option<Readout> {
        self.0.monolayer().map(|m| Readout::of(m, self.0.stats))
    }

    /// What the renderer draws of the frame shown for `field` (throws before the first frame).
    pub fn view(&mut self, field: FieldKind, dpr: f32) -> Result<WebView, JsError> {
        self.0.view(field, dpr).map(|v| WebView(v.clone())).ok_or_else(|| JsError::new("no frame shown yet"))
    }

    /// ±½ defects as last drawn.
    pub fn defects(&self) -> Vec<DefectMark> {
        DefectMark::all(&self.0.builder().defects)
    }

    /// Spiral cores as last drawn.
    pub fn spiral_cores(&self) -> Vec<SpiralMark> {
        SpiralMark::all(&self.0.builder().spiral_cores)
    }
}
