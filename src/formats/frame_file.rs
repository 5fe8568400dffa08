//! Frame files (`frame_*.npz`): the one encoder and the one decoder of the format, from and to
//! bytes, shared by `monolayer run` and `analyze` (`run::files`, which adds the files) and by the
//! page (which has no files, only what the user drops or picks, and downloads its state). Both go
//! through `ndarray-npy` and its `zip` with pure-Rust deflate, so the same code builds for wasm32;
//! `tests/frame_file.rs` checks the page's path against `monolayer run`'s frames.
//!
//! A frame is the analysis's input and both faces write it, so the format lives in `formats`,
//! below both `run` and `web`; [`frame_file_name`] names its files.
//!
//! Arrays of a frame (N cells, L box; lattice arrays are indexed [y, x]): `step` (), `time` (),
//! `centres` (N, 2), `areas` (N,), `q_hat` (N, 2), `shape_tensor` (N, 2), `patches` (N, 4: x0,
//! y0, w, h), `phi` (each cell's φ on its patch, row by row, concatenated), `phi_offsets`
//! (N + 1), `phi_sum` (L, L), `velocity` (L, L, 2).

use std::io::{Cursor, Read};

use ndarray::{arr0, Array0, Array1, Array2, Array3, ArrayD};
use ndarray_npy::{NpzReader, NpzWriter, ReadNpzError, WriteNpzError};
use num_complex::Complex64 as C64;

use super::error::{FormatError, FormatResult};
use crate::model::{Monolayer, Patch};

/// The name of the frame file of `step` in a run's `frames/` directory: `frame_0011000.npz`.
pub fn frame_file_name(step: u64) -> String {
    format!("frame_{step:07}.npz")
}

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
pub fn encode_frame(m: &mut Monolayer) -> FormatResult<Vec<u8>> {
    m.evaluate_now()?;
    frame_bytes(m).map_err(FormatError::Write)
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

/// Refuses NaN, infinities and absurd magnitudes (beyond 10¹⁰⁰, whose squares overflow): no file
/// this program writes holds one, so a file that does is damaged, and the tables measured from it
/// would fill with NaN.
pub fn check_finite<'a>(name: &str, values: impl Iterator<Item = &'a f64>) -> FormatResult<()> {
    match values.enumerate().find(|(_, v)| !(v.is_finite() && v.abs() <= 1e100)) {
        Some((index, &value)) => Err(FormatError::NotFinite { array: name.into(), value, index }),
        None => Ok(()),
    }
}

/// Reads a frame file's bytes, checking every array's shape; any box size and number of cells.
/// `expect` is (L, N) of the run's `run.json` when known. Errors start with `name` (the file's
/// name) and say which array is wrong, as `monolayer analyze` does.
pub fn decode_frame(name: &str, bytes: &[u8], expect: Option<(usize, usize)>) -> FormatResult<FrameData> {
    let (l, n) = expect.unzip();
    decode(bytes, l, n).map_err(|e| FormatError::Frame { name: name.into(), source: Box::new(e) })
}

/// [`decode_frame`] for a run on an L×L lattice whose number of cells is checked afterwards
/// against the run's record (`run::files::check_frame`).
pub fn decode_frame_of_box(name: &str, bytes: &[u8], l: usize) -> FormatResult<FrameData> {
    decode(bytes, Some(l), None).map_err(|e| FormatError::Frame { name: name.into(), source: Box::new(e) })
}

/// The shape and item size an `.npy` header declares: `(shape, bytes per item)`.
fn npy_header(bytes: &[u8]) -> Option<(Vec<u64>, u64)> {
    let rest = bytes.strip_prefix(b"\x93NUMPY")?;
    let (len, start) = match rest.first()? {
        1 => (u16::from_le_bytes([*rest.get(2)?, *rest.get(3)?]) as usize, 4),
        _ => (u32::from_le_bytes(rest.get(2..6)?.try_into().ok()?) as usize, 6),
    };
    let text = std::str::from_utf8(rest.get(start..start + len)?).ok()?;
    let after = |key: &str| text.find(key).map(|i| &text[i + key.len()..]);
    let shape = after("'shape':")?;
    let shape = &shape[shape.find('(')? + 1..shape.find(')')?];
    let shape =
        shape.split(',').map(str::trim).filter(|s| !s.is_empty()).map(|s| s.parse().ok()).collect::<Option<_>>()?;
    let descr = after("'descr':")?;
    let descr = descr.trim_start().trim_start_matches(['\'', '"']);
    let digits: String = descr.chars().skip_while(|c| !c.is_ascii_digit()).take_while(char::is_ascii_digit).collect();
    Some((shape, digits.parse().ok().filter(|&b| b > 0)?))
}

/// The most values one array of a frame or checkpoint of an L×L run holds: the lattice fields
/// (2 L²), or every cell's φ together (each cell's patch is at most L² and the cells cover the
/// box a few times at most: 64 L², against ≈ 5 L² at the paper's density).
pub fn max_array_values(l: usize) -> u64 {
    64 * (l as u64).pow(2) + 4096
}

/// Checks every array's header in an `.npz` before anything is allocated from it: a damaged or
/// hostile header may declare any shape (ndarray-npy would allocate it whole, and the process
/// abort). No array holds more than `max_values`, nor more bytes than its zip entry, whose size
/// deflate bounds by its compressed size.
pub fn check_npz_headers(archive: impl Read + std::io::Seek, max_values: u64) -> FormatResult<()> {
    let npz = FormatError::Npz;
    let mut zip = zip::ZipArchive::new(archive).map_err(|e| npz(format!("not a readable .npz: {e}")))?;
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).map_err(|e| npz(format!("not a readable .npz: {e}")))?;
        let name = entry.name().trim_end_matches(".npy").to_string();
        // Deflate expands at most 1032-fold.
        let (size, packed) = (entry.size(), entry.compressed_size());
        if size > packed.saturating_mul(1100).saturating_add(4096) {
            return Err(npz(format!("array `{name}`: {size} bytes from {packed} compressed: a damaged file")));
        }
        let mut head = Vec::new();
        (&mut entry).take(1 << 16).read_to_end(&mut head).map_err(|e| npz(format!("array `{name}`: {e}")))?;
        let (shape, item) =
            npy_header(&head).ok_or_else(|| npz(format!("array `{name}`: not a readable .npy header")))?;
        let values = shape.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
        let bytes = values.and_then(|v| v.checked_mul(item));
        match (values, bytes) {
            (Some(v), Some(b)) if v <= max_values && b <= size => {}
            _ => {
                return Err(npz(format!(
                    "array `{name}`: its header declares shape {shape:?}, more than the file holds or a run on this \
                     lattice has ({max_values} values at most): a damaged file"
                )))
            }
        }
    }
    Ok(())
}

fn decode(bytes: &[u8], expect_l: Option<usize>, expect_n: Option<usize>) -> FormatResult<FrameData> {
    let npz = FormatError::Npz;
    // Without the run's box, an array is bounded by its bytes alone (≤ 1100× the file's size).
    check_npz_headers(Cursor::new(bytes), expect_l.map_or(u64::MAX, max_array_values))?;
    let mut z = NpzReader::new(Cursor::new(bytes)).map_err(|e| npz(format!("not a readable .npz: {e}")))?;
    let e = |name: &'static str| move |x: ReadNpzError| npz(format!("array `{name}`: {x}"));
    let step: Array0<i64> = z.by_name("step").map_err(e("step"))?;
    let time: Array0<f64> = z.by_name("time").map_err(e("time"))?;
    let patches: Array2<i64> = z.by_name("patches").map_err(e("patches"))?;
    let phi: Array1<f64> = z.by_name("phi").map_err(e("phi"))?;
    let offsets: Array1<i64> = z.by_name("phi_offsets").map_err(e("phi_offsets"))?;
    let q_hat: Array2<f64> = z.by_name("q_hat").map_err(e("q_hat"))?;
    let velocity: Array3<f64> = z.by_name("velocity").map_err(e("velocity"))?;
    let (l, l2, two) = velocity.dim();
    if l != l2 || two != 2 || l < 4 {
        return Err(npz(format!("array `velocity` is {:?}, not L×L×2 for a box of L ≥ 4 sites", velocity.dim())));
    }
    let n = patches.nrows();
    if let Some(el) = expect_l.filter(|&el| el != l) {
        return Err(npz(format!("a {l}×{l} lattice, the run's run.json has box_size = {el}: not a frame of this run")));
    }
    if let Some(en) = expect_n.filter(|&en| en != n) {
        return Err(npz(format!("holds {n} cells, the run's run.json has n_cells = {en}: not a frame of this run")));
    }
    if patches.ncols() != 4 || offsets.len() != n + 1 || q_hat.dim() != (n, 2) {
        return Err(npz(format!(
            "`patches` {:?}, `phi_offsets` ({}), `q_hat` {:?} disagree on the number of cells",
            patches.dim(),
            offsets.len(),
            q_hat.dim()
        )));
    }
    let phi = phi.as_slice().ok_or_else(|| npz("array `phi` is not contiguous".into()))?;
    let step = step.into_scalar();
    if step < 0 {
        return Err(npz(format!("array `step` = {step}: a step is ≥ 0")));
    }
    let time = time.into_scalar();
    check_finite("time", [time].iter())?;
    check_finite("phi", phi.iter())?;
    check_finite("q_hat", q_hat.iter())?;
    check_finite("velocity", velocity.iter())?;
    // The analysis recomputes these from φ and never uses them, but NaN in any array means the
    // file is damaged, and whatever else it holds cannot be trusted either.
    let names = z.names().map_err(|x| npz(format!("not a readable .npz: {x}")))?;
    for name in ["phi_sum", "centres", "areas", "shape_tensor"] {
        if names.iter().any(|n| n.trim_end_matches(".npy") == name) {
            let a: ArrayD<f64> = z.by_name(name).map_err(e(name))?;
            check_finite(name, a.iter())?;
        }
    }
    let mut cells = Vec::with_capacity(n);
    for i in 0..n {
        let [x0, y0, w, h] = [0, 1, 2, 3].map(|k| patches[[i, k]]);
        let fits = |v: i64, lo: i64| v >= lo && (v as usize) < l + lo as usize;
        if !(fits(x0, 0) && fits(y0, 0) && fits(w, 1) && fits(h, 1)) {
            return Err(npz(format!("cell {i}: patch ({x0}, {y0}, {w}, {h}) does not fit the {l}×{l} lattice")));
        }
        let p = Patch { x0: x0 as usize, y0: y0 as usize, w: w as usize, h: h as usize };
        let (a, b) = (offsets[i], offsets[i + 1]);
        if a < 0 || b < a || b as usize > phi.len() || b - a != (p.w * p.h) as i64 {
            return Err(npz(format!("cell {i}: `phi_offsets` [{a}, {b}) do not hold its {}×{} patch", p.w, p.h)));
        }
        let mut padded = vec![0.0; p.padded_len()];
        for row in 0..p.h {
            let src = a as usize + row * p.w;
            padded[p.idx(0, row)..][..p.w].copy_from_slice(&phi[src..src + p.w]);
        }
        cells.push((p, padded));
    }
    let v = velocity.as_slice().ok_or_else(|| npz("array `velocity` is not contiguous".into()))?;
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
    use crate::model::Params;

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
        let cut = decode_frame("cut.npz", &bytes[..bytes.len() / 2], None).unwrap_err().to_string();
        assert!(cut.starts_with("cut.npz: not a readable .npz"), "{cut}");
        let junk = decode_frame("junk.npz", b"hello", None).unwrap_err().to_string();
        assert!(junk.starts_with("junk.npz: "), "{junk}");
        let other = decode_frame("o.npz", &bytes, Some((48, 4))).unwrap_err().to_string();
        assert!(other.contains("box_size = 48"), "{other}");
        let other = decode_frame("o.npz", &bytes, Some((40, 5))).unwrap_err().to_string();
        assert!(other.contains("n_cells = 5"), "{other}");
    }

    /// An .npz whose .npy header declares 2⁴⁰ values: refused before anything is allocated, by
    /// the decoder the page and `analyze` share (ndarray-npy would try to allocate 8 TiB).
    fn npz_declaring(shape: &str) -> Vec<u8> {
        use std::io::Write;
        let dict = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({shape}), }}");
        let mut npy = b"\x93NUMPY\x01\x00".to_vec();
        let len = (dict.len() + 1).div_ceil(64) * 64;
        npy.extend((len as u16).to_le_bytes());
        npy.extend(format!("{dict:<w$}\n", w = len - 1).bytes());
        npy.extend([0u8; 16]);
        let mut z = zip::ZipWriter::new(Cursor::new(Vec::new()));
        z.start_file("step.npy", zip::write::SimpleFileOptions::default()).unwrap();
        z.write_all(&npy).unwrap();
        z.finish().unwrap().into_inner()
    }

    #[test]
    fn a_header_declaring_more_than_the_file_holds_is_refused_before_allocating() {
        let e = decode_frame("big.npz", &npz_declaring("1099511627776,"), None).unwrap_err().to_string();
        assert!(e.starts_with("big.npz: array `step`: its header declares shape [1099511627776]"), "{e}");
        let e = decode_frame_of_box("big.npz", &npz_declaring("1000, 1000"), 40).unwrap_err().to_string();
        assert!(e.contains("106496 values at most"), "{e}");
        // The same archive with an honest header gets past the bound, to ndarray-npy (which
        // refuses an f64 `step`).
        let e = decode_frame("ok.npz", &npz_declaring("2,"), None).unwrap_err().to_string();
        assert!(e.starts_with("ok.npz: array `step`: error reading npy"), "{e}");
    }
}
