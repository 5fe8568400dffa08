//! Frame files (`frame_*.npz`, the native format of `monolayer run`) in the page: the current
//! state written as one, and a run's frames read back, from bytes (the page has no files, only
//! what the user drops or picks). Both go through `ndarray-npy`, the crate the native writer and
//! reader use, and its `zip` with pure-Rust deflate: the same code builds natively, where
//! `tests/frame_file.rs` checks it against `monolayer run`'s own frames byte for byte and array
//! for array.
//!
//! Arrays of a frame (N cells, L box; lattice arrays are indexed [y, x]): `step` (), `time` (),
//! `centres` (N, 2), `areas` (N,), `q_hat` (N, 2), `shape_tensor` (N, 2), `patches` (N, 4: x0,
//! y0, w, h), `phi` (each cell's φ on its patch, row by row, concatenated), `phi_offsets`
//! (N + 1), `phi_sum` (L, L), `velocity` (L, L, 2).

use std::io::Cursor;

use ndarray::{arr0, Array0, Array1, Array2, Array3};
use ndarray_npy::{NpzReader, NpzWriter, ReadNpzError, WriteNpzError};
use num_complex::Complex64 as C64;

use crate::model::lattice::Patch;
use crate::Monolayer;

/// One frame as read from a file: what the view and the analysis need of it.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameData {
    pub step: u64,
    /// Simulation time of the frame (step × Δt, relaxation included).
    pub time: f64,
    /// Box size L, from the shape of `velocity`.
    pub l: usize,
    /// Each cell's patch and φ on the padded patch storage (halo of zeros).
    pub cells: Vec<(Patch, Vec<f64>)>,
    pub q_hat: Vec<[f64; 2]>,
    /// Σ_i φ_i v_i, (v_x, v_y) as (re, im), index y·L + x.
    pub velocity: Vec<C64>,
}

impl FrameData {
    /// The cells as [`crate::analysis::Analysis::measure_cells`] takes them.
    pub fn cell_views(&self) -> impl Iterator<Item = (Patch, &[f64], [f64; 2])> {
        self.cells.iter().zip(&self.q_hat).map(|((p, phi), q)| (*p, phi.as_slice(), *q))
    }
}

/// The current state of `m` as a frame file, the bytes `monolayer run` writes for it (after
/// [`Monolayer::evaluate_now`], which leaves the trajectory as it is, so that the velocities
/// belong to this φ).
pub fn encode_frame(m: &mut Monolayer) -> Result<Vec<u8>, String> {
    m.evaluate_now().map_err(|e| e.to_string())?;
    frame_bytes(m).map_err(|e| format!("writing the frame: {e}"))
}

/// The frame file of `m` as it stands (its velocities as last evaluated): the one encoder of the
/// format, shared by `monolayer run` (`run::files::write_frame`) and the page's download.
/// Arrays (N cells, L box; lattice arrays are indexed [y, x]): `step` (), `time` (), `centres`
/// (N, 2), `areas` (N,), `q_hat` (N, 2: Q̂_xx, Q̂_xy), `shape_tensor` (N, 2), `patches` (N, 4: x0,
/// y0, w, h), `phi` (Σ w·h: each cell's φ on its patch, row by row, concatenated), `phi_offsets`
/// (N + 1), `phi_sum` (L, L), `velocity` (L, L, 2).
pub fn frame_bytes(m: &mut Monolayer) -> Result<Vec<u8>, WriteNpzError> {
    let l = m.params().box_size;
    let n = m.cells().len();
    let phi_sum = Array2::from_shape_vec((l, l), m.phi_sum().to_vec()).expect("L×L");
    let v = m.velocity_field();
    let velocity = Array3::from_shape_fn((l, l, 2), |(y, x, c)| if c == 0 { v[y * l + x].re } else { v[y * l + x].im });
    let cells = m.cells();
    let centres = Array2::from_shape_fn((n, 2), |(i, k)| cells[i].centre(l)[k]);
    let areas = Array1::from_iter(cells.iter().map(|c| c.area()));
    let q_hat = Array2::from_shape_fn((n, 2), |(i, k)| cells[i].q_hat()[k]);
    let shape = Array2::from_shape_fn((n, 2), |(i, k)| cells[i].shape_tensor()[k]);
    let mut patches = Array2::<i64>::zeros((n, 4));
    let mut offsets = vec![0i64];
    let mut phi = Vec::new();
    for (i, c) in cells.iter().enumerate() {
        let p = c.patch();
        for (k, v) in [p.x0, p.y0, p.w, p.h].into_iter().enumerate() {
            patches[[i, k]] = v as i64;
        }
        phi.extend(c.phi().interior());
        offsets.push(phi.len() as i64);
    }
    let step = m.step_count();
    let time = step as f64 * m.params().dt;
    let mut z = NpzWriter::new_compressed(Cursor::new(Vec::new()));
    z.add_array("step", &arr0(step as i64))?;
    z.add_array("time", &arr0(time))?;
    z.add_array("centres", &centres)?;
    z.add_array("areas", &areas)?;
    z.add_array("q_hat", &q_hat)?;
    z.add_array("shape_tensor", &shape)?;
    z.add_array("patches", &patches)?;
    z.add_array("phi", &Array1::from(phi))?;
    z.add_array("phi_offsets", &Array1::from(offsets))?;
    z.add_array("phi_sum", &phi_sum)?;
    z.add_array("velocity", &velocity)?;
    Ok(z.finish()?.into_inner())
}

/// Refuses NaN and infinities: no file this program writes holds one.
fn finite<'a>(name: &str, values: impl Iterator<Item = &'a f64>) -> Result<(), String> {
    match values.enumerate().find(|(_, v)| !v.is_finite()) {
        Some((k, v)) => Err(format!("array `{name}` holds {v} at index {k}: a damaged file")),
        None => Ok(()),
    }
}

/// Reads a frame file's bytes, checking every array's shape; any box size and number of cells.
/// `expect` is (L, N) of the run's `run.json` when known. Errors start with `name` (the file's
/// name) and say which array is wrong, as `monolayer analyze` does.
pub fn decode_frame(name: &str, bytes: &[u8], expect: Option<(usize, usize)>) -> Result<FrameData, String> {
    decode(bytes, expect).map_err(|e| format!("{name}: {e}"))
}

fn decode(bytes: &[u8], expect: Option<(usize, usize)>) -> Result<FrameData, String> {
    let mut z = NpzReader::new(Cursor::new(bytes)).map_err(|e| format!("not a readable .npz: {e}"))?;
    let e = |name: &'static str| move |x: ReadNpzError| format!("array `{name}`: {x}");
    let step: Array0<i64> = z.by_name("step").map_err(e("step"))?;
    let time: Array0<f64> = z.by_name("time").map_err(e("time"))?;
    let patches: Array2<i64> = z.by_name("patches").map_err(e("patches"))?;
    let phi: Array1<f64> = z.by_name("phi").map_err(e("phi"))?;
    let offsets: Array1<i64> = z.by_name("phi_offsets").map_err(e("phi_offsets"))?;
    let q_hat: Array2<f64> = z.by_name("q_hat").map_err(e("q_hat"))?;
    let velocity: Array3<f64> = z.by_name("velocity").map_err(e("velocity"))?;
    let (l, l2, two) = velocity.dim();
    if l != l2 || two != 2 || l < 4 {
        return Err(format!("array `velocity` is {:?}, not L×L×2 for a box of L ≥ 4 sites", velocity.dim()));
    }
    let n = patches.nrows();
    if let Some((el, en)) = expect {
        if l != el {
            return Err(format!("a {l}×{l} lattice, the run's run.json has box_size = {el}: not a frame of this run"));
        }
        if n != en {
            return Err(format!("holds {n} cells, the run's run.json has n_cells = {en}: not a frame of this run"));
        }
    }
    if patches.ncols() != 4 || offsets.len() != n + 1 || q_hat.dim() != (n, 2) {
        return Err(format!(
            "`patches` {:?}, `phi_offsets` ({}), `q_hat` {:?} disagree on the number of cells",
            patches.dim(),
            offsets.len(),
            q_hat.dim()
        ));
    }
    let phi = phi.as_slice().ok_or("array `phi` is not contiguous")?;
    let step = step.into_scalar();
    if step < 0 {
        return Err(format!("array `step` = {step}: a step is ≥ 0"));
    }
    let time = time.into_scalar();
    finite("time", [time].iter())?;
    finite("phi", phi.iter())?;
    finite("q_hat", q_hat.iter())?;
    finite("velocity", velocity.iter())?;
    let mut cells = Vec::with_capacity(n);
    for i in 0..n {
        let [x0, y0, w, h] = [0, 1, 2, 3].map(|k| patches[[i, k]]);
        let fits = |v: i64, lo: i64| v >= lo && (v as usize) < l + lo as usize;
        if !(fits(x0, 0) && fits(y0, 0) && fits(w, 1) && fits(h, 1)) {
            return Err(format!("cell {i}: patch ({x0}, {y0}, {w}, {h}) does not fit the {l}×{l} lattice"));
        }
        let p = Patch { x0: x0 as usize, y0: y0 as usize, w: w as usize, h: h as usize };
        let (a, b) = (offsets[i], offsets[i + 1]);
        if a < 0 || b < a || b as usize > phi.len() || b - a != (p.w * p.h) as i64 {
            return Err(format!("cell {i}: `phi_offsets` [{a}, {b}) do not hold its {}×{} patch", p.w, p.h));
        }
        let mut padded = vec![0.0; p.padded_len()];
        for row in 0..p.h {
            let src = a as usize + row * p.w;
            padded[p.idx(0, row)..][..p.w].copy_from_slice(&phi[src..src + p.w]);
        }
        cells.push((p, padded));
    }
    let v = velocity.as_slice().ok_or("array `velocity` is not contiguous")?;
    Ok(FrameData {
        step: step as u64,
        time,
        l,
        cells,
        q_hat: q_hat.rows().into_iter().map(|r| [r[0], r[1]]).collect(),
        velocity: v.chunks_exact(2).map(|c| C64::new(c[0], c[1])).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Params;

    fn small() -> Monolayer {
        let p = Params { box_size: 40, n_cells: 4, relax_steps: 10, ..Params::default() };
        let mut m = Monolayer::new(p, 2).unwrap();
        m.advance(15).unwrap();
        m
    }

    #[test]
    fn a_written_frame_reads_back_with_the_states_cells_and_velocity() {
        let mut m = small();
        let bytes = encode_frame(&mut m).unwrap();
        let f = decode_frame("f.npz", &bytes, Some((40, 4))).unwrap();
        assert_eq!((f.step, f.l, f.cells.len()), (15, 40, 4));
        assert_eq!(f.time, 15.0 * m.params().dt);
        for ((p, phi), c) in f.cells.iter().zip(m.cells()) {
            assert_eq!(*p, c.patch());
            let interior = c.phi().interior();
            let read: Vec<f64> =
                (0..p.h).flat_map(|y| (0..p.w).map(move |x| (x, y))).map(|(x, y)| phi[p.idx(x, y)]).collect();
            assert_eq!(read, interior);
        }
        assert_eq!(f.velocity, m.velocity_field());
    }

    #[test]
    fn damaged_and_foreign_files_are_refused_with_the_file_and_the_reason() {
        let mut m = small();
        let bytes = encode_frame(&mut m).unwrap();
        let cut = decode_frame("cut.npz", &bytes[..bytes.len() / 2], None).unwrap_err();
        assert!(cut.starts_with("cut.npz: not a readable .npz"), "{cut}");
        let junk = decode_frame("junk.npz", b"hello", None).unwrap_err();
        assert!(junk.starts_with("junk.npz: "), "{junk}");
        let other = decode_frame("o.npz", &bytes, Some((48, 4))).unwrap_err();
        assert!(other.contains("box_size = 48"), "{other}");
        let other = decode_frame("o.npz", &bytes, Some((40, 5))).unwrap_err();
        assert!(other.contains("n_cells = 5"), "{other}");
    }
}
