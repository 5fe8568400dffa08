//! Native output: frames NumPy reads directly (`.npz`), bit-exact checkpoints, and the run record
//! (`run.json`). Every file is written to a temporary name in the same directory and renamed, so
//! a reader (or a crash) never sees half a file.

use std::fs::{self, File};
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use ndarray::{arr0, Array1, Array2, Array3};
use ndarray_npy::{NpzReader, NpzWriter};
use num_complex::Complex64 as C64;
use serde::{Deserialize, Serialize};

use crate::lattice::Patch;
use crate::monolayer::{Monolayer, State};
use crate::params::Params;

/// Identifies the files of this program and the version of their layout.
pub const FORMAT: &str = "monolayer-run";
pub const FORMAT_VERSION: u32 = 1;

pub type IoResult<T> = Result<T, String>;

fn err(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: {e}", path.display())
}

/// Writes `path` through a temporary file in the same directory and a rename.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> IoResult<()>) -> IoResult<()> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.file_name().ok_or_else(|| err(path, "not a file name"))?.to_string_lossy();
    let tmp = dir.join(format!(".{name}.tmp"));
    let file = File::create(&tmp).map_err(|e| err(&tmp, e))?;
    let mut w = BufWriter::new(file);
    let result = write(&mut w).and_then(|_| {
        let file = w.into_inner().map_err(|e| err(&tmp, e))?;
        file.sync_all().map_err(|e| err(&tmp, e))
    });
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(e);
    }
    fs::rename(&tmp, path).map_err(|e| err(path, e))
}

/// What `run.json` records: enough to reproduce the run and to continue it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    pub format: String,
    pub format_version: u32,
    /// Version of this program that wrote the run.
    pub version: String,
    pub seed: u64,
    /// Steps between frames in the active phase.
    pub frame_interval: u64,
    /// "running", "finished", or "failed: …" with the reason.
    pub status: String,
    /// Last step with a frame (None before the first).
    pub last_frame_step: Option<u64>,
    pub params: Params,
}

impl RunRecord {
    pub fn new(params: Params, seed: u64, frame_interval: u64) -> Self {
        RunRecord {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            version: env!("CARGO_PKG_VERSION").into(),
            seed,
            frame_interval,
            status: "running".into(),
            last_frame_step: None,
            params,
        }
    }

    pub fn path(dir: &Path) -> PathBuf {
        dir.join("run.json")
    }

    pub fn save(&self, dir: &Path) -> IoResult<()> {
        let path = Self::path(dir);
        write_atomic(&path, |w| {
            serde_json::to_writer_pretty(&mut *w, self).map_err(|e| err(&path, e))?;
            w.write_all(b"\n").map_err(|e| err(&path, e))
        })
    }

    /// Reads and checks `DIR/run.json`, naming what is wrong.
    pub fn load(dir: &Path) -> IoResult<Self> {
        let path = Self::path(dir);
        if !dir.is_dir() {
            return Err(format!("{}: no such directory", dir.display()));
        }
        let file = File::open(&path).map_err(|e| err(&path, format!("{e} (is this a run directory?)")))?;
        let value: serde_json::Value =
            serde_json::from_reader(BufReader::new(file)).map_err(|e| err(&path, format!("not valid JSON: {e}")))?;
        if value.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
            return Err(err(&path, format!("not a record of this program (no \"format\": \"{FORMAT}\")")));
        }
        let v = value.get("format_version").and_then(|v| v.as_u64());
        if v != Some(FORMAT_VERSION as u64) {
            return Err(err(&path, format!("format_version {v:?}, this program reads {FORMAT_VERSION}")));
        }
        let record: RunRecord = serde_json::from_value(value).map_err(|e| err(&path, e))?;
        record.params.validate().map_err(|e| err(&path, e))?;
        Ok(record)
    }
}

/// Name of the frame file of a step: `frames/frame_0011000.npz`.
pub fn frame_path(dir: &Path, step: u64) -> PathBuf {
    dir.join("frames").join(format!("frame_{step:07}.npz"))
}

fn npz_err(path: &Path) -> impl Fn(ndarray_npy::WriteNpzError) -> String + '_ {
    move |e| err(path, e)
}

/// Per-cell arrays of a frame or checkpoint: patches (x0, y0, w, h) and the concatenated fields.
fn patch_table(patches: impl Iterator<Item = Patch>, n: usize) -> Array2<i64> {
    let mut t = Array2::<i64>::zeros((n, 4));
    for (i, p) in patches.enumerate() {
        t[[i, 0]] = p.x0 as i64;
        t[[i, 1]] = p.y0 as i64;
        t[[i, 2]] = p.w as i64;
        t[[i, 3]] = p.h as i64;
    }
    t
}

fn complex_field(v: &[C64], l: usize) -> Array3<f64> {
    Array3::from_shape_fn((l, l, 2), |(y, x, c)| if c == 0 { v[y * l + x].re } else { v[y * l + x].im })
}

/// Writes one frame of the current state (after [`Monolayer::evaluate_now`] so that velocities
/// belong to this φ). Arrays (N cells, L box; lattice arrays are indexed [y, x]):
/// `step` (), `time` (), `centres` (N, 2), `areas` (N,), `q_hat` (N, 2: Q̂_xx, Q̂_xy),
/// `shape_tensor` (N, 2), `patches` (N, 4: x0, y0, w, h), `phi` (Σ w·h: each cell's φ on its
/// patch, row by row, concatenated), `phi_offsets` (N + 1), `phi_sum` (L, L), `velocity` (L, L, 2).
pub fn write_frame(m: &mut Monolayer, path: &Path) -> IoResult<()> {
    let l = m.params().box_size;
    let n = m.cells().len();
    let phi_sum = Array2::from_shape_vec((l, l), m.phi_sum().to_vec()).expect("L×L");
    let velocity = complex_field(m.velocity_field(), l);
    let cells = m.cells();
    let centres = Array2::from_shape_fn((n, 2), |(i, k)| cells[i].centre(l)[k]);
    let areas = Array1::from_iter(cells.iter().map(|c| c.area()));
    let q_hat = Array2::from_shape_fn((n, 2), |(i, k)| cells[i].q_hat()[k]);
    let shape = Array2::from_shape_fn((n, 2), |(i, k)| cells[i].shape_tensor()[k]);
    let patches = patch_table(cells.iter().map(|c| c.patch()), n);
    let mut offsets = vec![0i64];
    let mut phi = Vec::new();
    for c in cells {
        phi.extend(c.phi().interior());
        offsets.push(phi.len() as i64);
    }
    let step = m.step_count();
    let time = step as f64 * m.params().dt;
    write_atomic(path, |w| {
        let mut z = NpzWriter::new_compressed(w);
        let e = npz_err(path);
        z.add_array("step", &arr0(step as i64)).map_err(&e)?;
        z.add_array("time", &arr0(time)).map_err(&e)?;
        z.add_array("centres", &centres).map_err(&e)?;
        z.add_array("areas", &areas).map_err(&e)?;
        z.add_array("q_hat", &q_hat).map_err(&e)?;
        z.add_array("shape_tensor", &shape).map_err(&e)?;
        z.add_array("patches", &patches).map_err(&e)?;
        z.add_array("phi", &Array1::from(phi)).map_err(&e)?;
        z.add_array("phi_offsets", &Array1::from(offsets)).map_err(&e)?;
        z.add_array("phi_sum", &phi_sum).map_err(&e)?;
        z.add_array("velocity", &velocity).map_err(&e)?;
        z.finish().map_err(&e)?;
        Ok(())
    })
}

/// Writes the exact state (f64 bits, padded patches, the solver's warm start).
pub fn write_checkpoint(m: &Monolayer, path: &Path) -> IoResult<()> {
    let s = m.state();
    let l = m.params().box_size;
    let n = s.cells.len();
    let patches = patch_table(s.cells.iter().map(|(p, _)| *p), n);
    let mut offsets = vec![0i64];
    let mut phi = Vec::new();
    for (_, f) in &s.cells {
        phi.extend_from_slice(f);
        offsets.push(phi.len() as i64);
    }
    let warm = complex_field(&s.warm_start, l);
    let substrate = Array2::from_shape_vec((l, l), s.substrate.clone()).expect("L×L");
    write_atomic(path, |w| {
        let mut z = NpzWriter::new_compressed(w);
        let e = npz_err(path);
        z.add_array("step", &arr0(s.step as i64)).map_err(&e)?;
        z.add_array("patches", &patches).map_err(&e)?;
        z.add_array("phi_padded", &Array1::from(phi)).map_err(&e)?;
        z.add_array("phi_offsets", &Array1::from(offsets)).map_err(&e)?;
        z.add_array("warm_start", &warm).map_err(&e)?;
        z.add_array("substrate", &substrate).map_err(&e)?;
        z.finish().map_err(&e)?;
        Ok(())
    })
}

/// Reads a checkpoint written by [`write_checkpoint`].
pub fn read_checkpoint(path: &Path, l: usize) -> IoResult<State> {
    let file = File::open(path).map_err(|e| err(path, e))?;
    let mut z = NpzReader::new(BufReader::new(file)).map_err(|e| err(path, e))?;
    let e = |name: &str| {
        let name = name.to_string();
        move |x: ndarray_npy::ReadNpzError| err(path, format!("array `{name}`: {x}"))
    };
    let step: ndarray::Array0<i64> = z.by_name("step").map_err(e("step"))?;
    let patches: Array2<i64> = z.by_name("patches").map_err(e("patches"))?;
    let phi: Array1<f64> = z.by_name("phi_padded").map_err(e("phi_padded"))?;
    let offsets: Array1<i64> = z.by_name("phi_offsets").map_err(e("phi_offsets"))?;
    let warm: Array3<f64> = z.by_name("warm_start").map_err(e("warm_start"))?;
    let substrate: Array2<f64> = z.by_name("substrate").map_err(e("substrate"))?;
    if warm.dim() != (l, l, 2) || substrate.dim() != (l, l) {
        return Err(err(path, format!("lattice arrays are not {l}×{l}")));
    }
    let n = patches.nrows();
    if offsets.len() != n + 1 || patches.ncols() != 4 {
        return Err(err(path, "patch table and offsets disagree"));
    }
    let mut cells = Vec::with_capacity(n);
    for i in 0..n {
        let (a, b) = (offsets[i] as usize, offsets[i + 1] as usize);
        if a > b || b > phi.len() {
            return Err(err(path, format!("cell {i}: offsets out of range")));
        }
        let p = Patch {
            x0: patches[[i, 0]] as usize,
            y0: patches[[i, 1]] as usize,
            w: patches[[i, 2]] as usize,
            h: patches[[i, 3]] as usize,
        };
        cells.push((p, phi.slice(ndarray::s![a..b]).to_vec()));
    }
    let complex = |a: &Array3<f64>| (0..l * l).map(|k| C64::new(a[[k / l, k % l, 0]], a[[k / l, k % l, 1]])).collect();
    Ok(State {
        step: step.into_scalar() as u64,
        cells,
        warm_start: complex(&warm),
        substrate: substrate.iter().copied().collect(),
    })
}

/// Parameters from an optional TOML file and `key=value` overrides (values in TOML syntax).
pub fn load_params(config: Option<&Path>, overrides: &[String]) -> IoResult<Params> {
    let mut table = match config {
        Some(path) => {
            let text = fs::read_to_string(path).map_err(|e| err(path, e))?;
            text.parse::<toml::Table>().map_err(|e| err(path, e))?
        }
        None => toml::Table::new(),
    };
    for o in overrides {
        let (k, v) = o.split_once('=').ok_or_else(|| format!("--set {o}: expected key=value, e.g. --set zeta=0.4"))?;
        let snippet = format!("{} = {}", k.trim(), v.trim());
        let parsed = snippet
            .parse::<toml::Table>()
            .or_else(|_| format!("{} = \"{}\"", k.trim(), v.trim()).parse::<toml::Table>())
            .map_err(|e| format!("--set {o}: {e}"))?;
        table.extend(parsed);
    }
    let params: Params = table.try_into().map_err(|e: toml::de::Error| {
        let origin = config.map(|p| p.display().to_string()).unwrap_or_else(|| "--set".into());
        format!("{origin}: {}", e.message())
    })?;
    Ok(params)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overrides_and_unknown_keys() {
        let p = load_params(None, &["zeta=0.3".into(), "passive_force=grad_mu".into()]).unwrap();
        assert_eq!(p.zeta, 0.3);
        assert_eq!(p.passive_force, crate::params::PassiveForce::GradMu);
        let e = load_params(None, &["zeta_typo=0.3".into()]).unwrap_err();
        assert!(e.contains("zeta_typo"), "{e}");
        let e = load_params(None, &["zeta".into()]).unwrap_err();
        assert!(e.contains("key=value"), "{e}");
    }

    #[test]
    fn atomic_write_leaves_nothing_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.bin");
        let r = write_atomic(&path, |_| Err("boom".into()));
        assert!(r.is_err());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
        write_atomic(&path, |w| w.write_all(b"ok").map_err(|e| e.to_string())).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"ok");
    }
}
