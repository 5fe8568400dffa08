//! Reading a run's frames (`frames/frame_NNNNNNN.npz`, README "Output") for the offline analysis,
//! with errors that name the file and the array that is wrong.

use std::fs::{self, File};
use std::io::BufReader;
use std::path::{Path, PathBuf};

use ndarray::{Array0, Array1, Array2, Array3};
use ndarray_npy::NpzReader;
use num_complex::Complex64 as C64;

use crate::io::RunRecord;
use crate::lattice::Patch;

/// One frame: what the analysis needs of it.
#[derive(Clone, Debug)]
pub struct Frame {
    pub path: PathBuf,
    pub step: u64,
    pub time: f64,
    /// Each cell's patch and φ on the padded patch storage (halo of zeros).
    pub cells: Vec<(Patch, Vec<f64>)>,
    pub q_hat: Vec<[f64; 2]>,
    /// Σ_i φ_i v_i, (v_x, v_y) as (re, im), index y·L + x.
    pub velocity: Vec<C64>,
}

impl Frame {
    /// The cells as [`super::Analysis::measure_cells`] takes them.
    pub fn cell_views(&self) -> impl Iterator<Item = (Patch, &[f64], [f64; 2])> {
        self.cells.iter().zip(&self.q_hat).map(|((p, phi), q)| (*p, phi.as_slice(), *q))
    }
}

/// A run directory checked for analysis: its record and its complete frames, in step order.
#[derive(Clone, Debug)]
pub struct RunFrames {
    pub dir: PathBuf,
    pub record: RunRecord,
    /// (step, path) of every frame file, sorted by step.
    pub frames: Vec<(u64, PathBuf)>,
}

impl RunFrames {
    /// Opens `dir` as a run: its `run.json` must be this program's, of this format version,
    /// and it must have at least one frame. Frames are written by an atomic rename, so every
    /// `frame_*.npz` present is complete (a frame being written is a hidden temporary file,
    /// skipped): a run in progress is read up to its last complete frame.
    pub fn open(dir: &Path) -> Result<Self, String> {
        let record = RunRecord::load(dir)?;
        let frames_dir = dir.join("frames");
        let entries = fs::read_dir(&frames_dir).map_err(|e| {
            format!("{}: {e} (a run's frames are in DIR/frames; has this run written any yet?)", frames_dir.display())
        })?;
        let mut frames = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| format!("{}: {e}", frames_dir.display()))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(step) = name.strip_prefix("frame_").and_then(|s| s.strip_suffix(".npz")) {
                let step: u64 = step
                    .parse()
                    .map_err(|_| format!("{}: not a frame name (frame_<step>.npz)", entry.path().display()))?;
                frames.push((step, entry.path()));
            }
        }
        if frames.is_empty() {
            return Err(format!(
                "{}: no frames yet (status \"{}\"); frames are written every {} active steps",
                frames_dir.display(),
                record.status,
                record.frame_interval
            ));
        }
        frames.sort();
        Ok(RunFrames { dir: dir.to_path_buf(), record, frames })
    }
}

fn err(path: &Path, what: impl std::fmt::Display) -> String {
    format!("{}: {what}", path.display())
}

/// Reads one frame of a run on an L×L lattice, checking every array's shape.
pub fn read_frame(path: &Path, l: usize) -> Result<Frame, String> {
    let file = File::open(path).map_err(|e| err(path, e))?;
    let mut z = NpzReader::new(BufReader::new(file)).map_err(|e| err(path, format!("not a readable .npz: {e}")))?;
    let e = |name: &'static str| move |x: ndarray_npy::ReadNpzError| err(path, format!("array `{name}`: {x}"));
    let step: Array0<i64> = z.by_name("step").map_err(e("step"))?;
    let time: Array0<f64> = z.by_name("time").map_err(e("time"))?;
    let patches: Array2<i64> = z.by_name("patches").map_err(e("patches"))?;
    let phi: Array1<f64> = z.by_name("phi").map_err(e("phi"))?;
    let offsets: Array1<i64> = z.by_name("phi_offsets").map_err(e("phi_offsets"))?;
    let q_hat: Array2<f64> = z.by_name("q_hat").map_err(e("q_hat"))?;
    let velocity: Array3<f64> = z.by_name("velocity").map_err(e("velocity"))?;
    if velocity.dim() != (l, l, 2) {
        return Err(err(path, format!("array `velocity` is {:?}, the run's lattice is {l}×{l}×2", velocity.dim())));
    }
    let n = patches.nrows();
    if patches.ncols() != 4 || offsets.len() != n + 1 || q_hat.dim() != (n, 2) {
        return Err(err(
            path,
            format!(
                "`patches` {:?}, `phi_offsets` ({}), `q_hat` {:?} disagree on the number of cells",
                patches.dim(),
                offsets.len(),
                q_hat.dim()
            ),
        ));
    }
    let phi = phi.as_slice().ok_or_else(|| err(path, "array `phi` is not contiguous"))?;
    let mut cells = Vec::with_capacity(n);
    for i in 0..n {
        let [x0, y0, w, h] = [0, 1, 2, 3].map(|k| patches[[i, k]]);
        if x0 < 0
            || y0 < 0
            || x0 as usize >= l
            || y0 as usize >= l
            || w < 1
            || h < 1
            || w as usize > l
            || h as usize > l
        {
            return Err(err(path, format!("cell {i}: patch ({x0}, {y0}, {w}, {h}) does not fit the {l}×{l} lattice")));
        }
        let p = Patch { x0: x0 as usize, y0: y0 as usize, w: w as usize, h: h as usize };
        let (a, b) = (offsets[i], offsets[i + 1]);
        if a < 0 || b as usize > phi.len() || b - a != (p.w * p.h) as i64 {
            return Err(err(path, format!("cell {i}: `phi_offsets` [{a}, {b}) do not hold its {}×{} patch", p.w, p.h)));
        }
        let mut padded = vec![0.0; p.padded_len()];
        for bb in 0..p.h {
            let src = a as usize + bb * p.w;
            padded[p.idx(0, bb)..][..p.w].copy_from_slice(&phi[src..src + p.w]);
        }
        cells.push((p, padded));
    }
    let v = velocity.as_slice().ok_or_else(|| err(path, "array `velocity` is not contiguous"))?;
    Ok(Frame {
        path: path.to_path_buf(),
        step: step.into_scalar() as u64,
        time: time.into_scalar(),
        cells,
        q_hat: q_hat.rows().into_iter().map(|r| [r[0], r[1]]).collect(),
        velocity: v.chunks_exact(2).map(|c| C64::new(c[0], c[1])).collect(),
    })
}
