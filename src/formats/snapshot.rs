//! A [`State`] as bytes that both targets read, bit for bit: how the browser demo starts from a
//! confluent tissue relaxed natively by the same core (`monolayer relaxed-state`, www/assets/)
//! instead of spending its first seconds on the relaxation.
//!
//! A snapshot is keyed by everything its state depends on (the seed and every parameter the
//! relaxation reads, [`relaxation_key`]), so a page whose parameters differ from the ones it was
//! made with refuses it and relaxes live instead; and by a checksum, so a damaged file is refused
//! rather than simulated. The native checkpoint (`run::files`, .npz) stays the format for Python;
//! this one is for the page, where a zip reader would cost more than the state.
//!
//! Layout, little-endian: `MAGIC`, `VERSION` (u32), key (u64), step (u64), L (u32), N (u32);
//! per cell x0, y0, w, h (u32) and its padded φ ((w + 2)(h + 2) f64); a flags byte (bit 0: the
//! solver's warm start follows as L² pairs of f64, else it is zero; bit 1: the substrate map
//! follows as L² f64, else it is 1 everywhere; bit 2: the corrector shift follows as L² pairs
//! of f64, else it is zero); then FNV-1a 64 of every byte before it.

use num_complex::Complex64 as C64;

use crate::model::{fnv1a, FrictionWeights, Params, Patch, SimError, State, STORE_NAME};

const MAGIC: &[u8; 8] = b"MLSTATE\0";
const VERSION: u32 = 1;
const HAS_WARM_START: u8 = 1;
const HAS_SUBSTRATE: u8 = 2;
const HAS_CORRECTOR_SHIFT: u8 = 4;

/// The key of a relaxed state: the seed and every parameter the relaxation reads. Those it does
/// not read (activity, the friction of the active phase and its solve, the active steps, the
/// time unit) are set to fixed values first, so that one relaxed state serves every preset that
/// differs only in them, and a change of their defaults leaves the key alone. Any other
/// parameter changes the key, and so does the storage precision of the cells' fields (an f64
/// build's keys are those of the builds before f32 storage existed).
pub fn relaxation_key(params: &Params, seed: u64) -> u64 {
    let p = relaxation_params(params);
    // Debug prints every field, floats exactly (shortest round-trip form), on both targets.
    let storage = if STORE_NAME == "f64" { String::new() } else { format!("storage {STORE_NAME}; ") };
    fnv1a(format!("seed {seed}; {storage}{p:?}").as_bytes())
}

/// `params` with every parameter the relaxation does not read set to a fixed value.
fn relaxation_params(params: &Params) -> Params {
    Params {
        zeta: 0.0,
        q_magnitude: 0.0,
        q_epsilon: 0.0,
        xi_substrate: 0.0,
        xi_cell: 0.0,
        friction_weights: FrictionWeights::Phi,
        friction_tolerance: 0.0,
        friction_max_iterations: 0,
        active_steps: 0,
        time_unit_seconds: 0.0,
        ..params.clone()
    }
}

/// The key of a state past the relaxation: the seed and every parameter the trajectory reads
/// (all but the run's length and the time unit, which only name the steps), so that a state
/// from the active phase continues only under exactly the parameters that made it. The page
/// ships one such state, a short time before a hole opens.
pub fn trajectory_key(params: &Params, seed: u64) -> u64 {
    let p = Params { active_steps: 0, time_unit_seconds: 0.0, ..params.clone() };
    let storage = if STORE_NAME == "f64" { String::new() } else { format!("storage {STORE_NAME}; ") };
    fnv1a(format!("trajectory; seed {seed}; {storage}{p:?}").as_bytes())
}

/// The key a state at `step` of the run of `params` and `seed` is saved under: the relaxation
/// key at the end of the relaxation ([`relaxation_key`]), the trajectory key past it
/// ([`trajectory_key`]); `None` before the end of the relaxation, which no file holds.
pub fn key_at(params: &Params, seed: u64, step: u64) -> Option<u64> {
    match step.cmp(&params.relax_steps) {
        std::cmp::Ordering::Less => None,
        std::cmp::Ordering::Equal => Some(relaxation_key(params, seed)),
        std::cmp::Ordering::Greater => Some(trajectory_key(params, seed)),
    }
}

/// A shipped state of `params` and `seed` from `bytes`, at whatever step it was saved: the end
/// of the relaxation (as [`decode_relaxed`]) or any later step (keyed by every parameter of the
/// trajectory). Refused if it was made with other parameters, another seed or precision, or
/// saved before the end of the relaxation.
pub fn decode_shipped(bytes: &[u8], params: &Params, seed: u64) -> Result<State, SimError> {
    decode_with(bytes, params.box_size, |step| {
        key_at(params, seed, step).ok_or_else(|| {
            SimError::Invalid(format!(
                "relaxed state: saved at step {step}, before the end of the {} relaxation steps",
                params.relax_steps
            ))
        })
    })
}

/// The relaxed state of `params` and `seed` from `bytes` (see [`decode`]): refused if it was
/// made with other relaxation parameters, another seed or precision, or saved at any step but
/// the end of the relaxation.
pub fn decode_relaxed(bytes: &[u8], params: &Params, seed: u64) -> Result<State, SimError> {
    let state = decode(bytes, relaxation_key(params, seed), params.box_size)?;
    if state.step != params.relax_steps {
        return Err(SimError::Invalid(format!(
            "relaxed state: saved at step {}, not at the end of the {} relaxation steps",
            state.step, params.relax_steps
        )));
    }
    Ok(state)
}

/// The bytes of `state`, under `key` (see [`relaxation_key`]).
pub fn encode(state: &State, key: u64) -> Vec<u8> {
    let l = (state.substrate.len() as f64).sqrt() as usize;
    let mut out = Vec::with_capacity(64 + state.cells.iter().map(|(_, phi)| 16 + 8 * phi.len()).sum::<usize>());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&key.to_le_bytes());
    out.extend_from_slice(&state.step.to_le_bytes());
    out.extend_from_slice(&(l as u32).to_le_bytes());
    out.extend_from_slice(&(state.cells.len() as u32).to_le_bytes());
    for (p, phi) in &state.cells {
        for v in [p.x0, p.y0, p.w, p.h] {
            out.extend_from_slice(&(v as u32).to_le_bytes());
        }
        phi.iter().for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
    }
    let nonzero = |field: &[C64]| field.iter().any(|u| u.re != 0.0 || u.im != 0.0);
    let (warm, shift) = (nonzero(&state.warm_start), nonzero(&state.corrector_shift));
    let substrate = state.substrate.iter().any(|&s| s != 1.0);
    let flag = |present, bit| if present { bit } else { 0 };
    out.push(flag(warm, HAS_WARM_START) | flag(substrate, HAS_SUBSTRATE) | flag(shift, HAS_CORRECTOR_SHIFT));
    let mut complex = |field: &[C64]| {
        field.iter().for_each(|u| {
            out.extend_from_slice(&u.re.to_le_bytes());
            out.extend_from_slice(&u.im.to_le_bytes());
        })
    };
    if warm {
        complex(&state.warm_start);
    }
    if shift {
        complex(&state.corrector_shift);
    }
    if substrate {
        state.substrate.iter().for_each(|v| out.extend_from_slice(&v.to_le_bytes()));
    }
    out.extend_from_slice(&fnv1a(&out).to_le_bytes());
    out
}

/// Reads bytes written by [`encode`]; refuses a damaged file, another format, another key (a
/// state relaxed with other parameters or another seed) or another lattice side `l`.
pub fn decode(bytes: &[u8], key: u64, l: usize) -> Result<State, SimError> {
    decode_with(bytes, l, |_| Ok(key))
}

/// [`decode`] with the key the file must hold given by its step (`key_for`), which may refuse
/// the step itself.
fn decode_with(bytes: &[u8], l: usize, key_for: impl FnOnce(u64) -> Result<u64, SimError>) -> Result<State, SimError> {
    let bad = |why: String| SimError::Invalid(format!("relaxed state: {why}"));
    if bytes.len() < MAGIC.len() + 8 {
        return Err(bad(format!("{} bytes, shorter than its header", bytes.len())));
    }
    let (body, sum) = bytes.split_at(bytes.len() - 8);
    if !body.starts_with(MAGIC) {
        return Err(bad("not a relaxed-state file (wrong magic bytes)".into()));
    }
    if fnv1a(body) != u64::from_le_bytes(sum.try_into().expect("8 bytes")) {
        return Err(bad("checksum mismatch: the file is damaged or truncated".into()));
    }
    let mut r = Reader { bytes: body, at: MAGIC.len() };
    let version = r.u32()?;
    if version != VERSION {
        return Err(bad(format!("format version {version}, this core reads {VERSION}")));
    }
    let file_key = r.u64()?;
    let step = r.u64()?;
    // Both phases at their longest: a larger step count is no state of a run (and would wrap).
    if step > 2 * crate::model::MAX_STEPS {
        return Err(bad(format!("step {step}: more than a run's 2·10⁹ steps")));
    }
    let key = key_for(step)?;
    if file_key != key {
        return Err(bad(format!(
            "made with other parameters or another seed (key {file_key:016x}, these parameters give {key:016x})"
        )));
    }
    let (file_l, n) = (r.u32()? as usize, r.u32()? as usize);
    if file_l != l {
        return Err(bad(format!("lattice {file_l}×{file_l}, the parameters say {l}×{l}")));
    }
    let mut cells = Vec::with_capacity(n.min(body.len() / 16));
    for i in 0..n {
        let [x0, y0, w, h] = [r.u32()?, r.u32()?, r.u32()?, r.u32()?].map(|v| v as usize);
        if [x0, y0, w, h].iter().any(|&v| v >= l) || w == 0 || h == 0 {
            return Err(bad(format!("cell {i}: patch ({x0}, {y0}, {w}, {h}) does not fit the {l}×{l} lattice")));
        }
        let patch = Patch { x0, y0, w, h };
        let phi = r.f64s(patch.padded_len())?;
        cells.push((patch, phi));
    }
    let flags = r.u8()?;
    if flags & !(HAS_WARM_START | HAS_SUBSTRATE | HAS_CORRECTOR_SHIFT) != 0 {
        return Err(bad(format!("flags {flags:#04x} name a field this core does not know")));
    }
    let mut complex = |bit| -> Result<Vec<C64>, SimError> {
        Ok(if flags & bit != 0 {
            r.f64s(2 * l * l)?.chunks_exact(2).map(|c| C64::new(c[0], c[1])).collect()
        } else {
            vec![C64::new(0.0, 0.0); l * l]
        })
    };
    let warm_start = complex(HAS_WARM_START)?;
    let corrector_shift = complex(HAS_CORRECTOR_SHIFT)?;
    let substrate = if flags & HAS_SUBSTRATE != 0 { r.f64s(l * l)? } else { vec![1.0; l * l] };
    if r.at != body.len() {
        return Err(bad(format!("{} bytes left over after the state", body.len() - r.at)));
    }
    let nan = |what: &str| bad(format!("{what} holds NaN or an infinity: a damaged file"));
    if cells.iter().any(|(_, phi)| phi.iter().any(|v| !v.is_finite())) {
        return Err(nan("φ"));
    }
    let finite = |field: &[C64]| field.iter().all(|c| c.re.is_finite() && c.im.is_finite());
    if !finite(&warm_start) {
        return Err(nan("the warm start"));
    }
    if !finite(&corrector_shift) {
        return Err(nan("the corrector shift"));
    }
    if substrate.iter().any(|&v| !(v.is_finite() && v > 0.0)) {
        return Err(bad("the substrate map holds a value that is not a finite friction > 0".into()));
    }
    Ok(State { step, cells, warm_start, corrector_shift, substrate })
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], SimError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or_else(|| SimError::Invalid("relaxed state: ends in the middle of its data".into()))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self) -> Result<u8, SimError> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32, SimError> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self) -> Result<u64, SimError> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().expect("8 bytes")))
    }
    fn f64s(&mut self, n: usize) -> Result<Vec<f64>, SimError> {
        let bytes = self.take(n.saturating_mul(8))?;
        Ok(bytes.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Monolayer;

    fn small() -> Params {
        Params { box_size: 40, n_cells: 6, relax_steps: 30, relax_patch_size: 26, ..Params::default() }
    }

    fn relaxed(p: &Params, seed: u64) -> Monolayer {
        let mut m = Monolayer::new(p.clone(), seed).unwrap();
        m.advance(p.relax_steps).unwrap();
        m
    }

    #[test]
    fn round_trip_continues_bit_for_bit() {
        let p = small();
        let mut a = relaxed(&p, 3);
        let key = relaxation_key(&p, 3);
        let bytes = encode(&a.state(), key);
        let s = decode(&bytes, key, p.box_size).unwrap();
        assert_eq!(s, a.state());
        let mut b = Monolayer::from_state(p.clone(), 3, s).unwrap();
        a.advance(20).unwrap();
        b.advance(20).unwrap();
        assert_eq!(a.fingerprint(), b.fingerprint());
    }

    #[test]
    fn warm_start_corrector_shift_and_substrate_are_kept_when_not_trivial() {
        let p = small();
        let mut m = relaxed(&p, 1);
        let mut map = vec![1.0; 40 * 40];
        map[17] = 0.25;
        m.set_substrate(&map).unwrap();
        m.advance(3).unwrap(); // active: the solver's warm start and shift are no longer zero
        let s = m.state();
        assert!(s.warm_start.iter().any(|u| u.re != 0.0));
        assert!(s.corrector_shift.iter().any(|u| u.re != 0.0));
        let bytes = encode(&s, 9);
        assert_eq!(decode(&bytes, 9, 40).unwrap(), s);
        // Each field on its own, the others trivial.
        let zero = vec![C64::new(0.0, 0.0); 40 * 40];
        for only in [
            State { warm_start: zero.clone(), ..s.clone() },
            State { corrector_shift: zero.clone(), ..s.clone() },
            State { substrate: vec![1.0; 40 * 40], ..s.clone() },
        ] {
            assert_eq!(decode(&encode(&only, 9), 9, 40).unwrap(), only);
        }
    }

    #[test]
    fn the_key_reads_the_relaxation_parameters_only() {
        let p = small();
        let k = relaxation_key(&p, 1);
        let active_only = Params {
            zeta: 0.3,
            xi_substrate: 0.5,
            q_magnitude: 2.0,
            active_steps: 7,
            friction_weights: FrictionWeights::Subdomain,
            ..p.clone()
        };
        assert_eq!(relaxation_key(&active_only, 1), k);
        assert_ne!(relaxation_key(&p, 2), k, "the seed");
        assert_ne!(relaxation_key(&Params { gamma: 0.07, ..p.clone() }, 1), k, "γ");
        assert_ne!(relaxation_key(&Params { relax_steps: 31, ..p.clone() }, 1), k, "relaxation steps");
        assert_ne!(relaxation_key(&Params { box_size: 41, ..p.clone() }, 1), k, "the box");
        // The storage precision: an f64 build keeps the keys of the builds before f32 storage
        // existed (the shipped states' keys), an f32 build's keys differ from them.
        let before_f32 = relaxation_key_without_storage(&p, 1);
        assert_eq!(k == before_f32, STORE_NAME == "f64", "the precision in the key");
    }

    /// The key as builds computed it before the storage precision entered it.
    fn relaxation_key_without_storage(params: &Params, seed: u64) -> u64 {
        fnv1a(format!("seed {seed}; {:?}", relaxation_params(params)).as_bytes())
    }

    #[test]
    fn a_state_past_the_relaxation_continues_only_under_every_parameter_that_made_it() {
        let p = Params { zeta: 0.5, ..small() };
        let mut a = relaxed(&p, 2);
        a.advance(5).unwrap();
        let bytes = encode(&a.state(), key_at(&p, 2, a.step_count()).unwrap());
        let s = decode_shipped(&bytes, &p, 2).unwrap();
        assert_eq!(s.step, p.relax_steps + 5);
        let mut b = Monolayer::from_state(p.clone(), 2, s).unwrap();
        a.advance(10).unwrap();
        b.advance(10).unwrap();
        assert_eq!(a.fingerprint(), b.fingerprint());
        // The length of the run and the time unit only name steps; every other parameter,
        // activity and friction included, and the seed are the trajectory's.
        let renamed = Params { active_steps: 9, time_unit_seconds: 1.0, ..p.clone() };
        assert!(decode_shipped(&bytes, &renamed, 2).is_ok());
        let err = |q: &Params, seed| decode_shipped(&bytes, q, seed).unwrap_err().to_string();
        assert!(err(&Params { zeta: 0.6, ..p.clone() }, 2).contains("other parameters"), "ζ");
        assert!(err(&Params { xi_substrate: 0.5, ..p.clone() }, 2).contains("other parameters"), "χ");
        assert!(err(&p, 3).contains("other parameters"), "the seed");
        assert!(err(&Params { relax_steps: 40, ..p.clone() }, 2).contains("before the end"), "saved mid-relaxation");
        // The end of the relaxation keeps its own key, which serves every activity.
        let r = relaxed(&p, 2);
        let at_end = encode(&r.state(), key_at(&p, 2, p.relax_steps).unwrap());
        assert_eq!(decode_shipped(&at_end, &Params { zeta: 2.0, ..p.clone() }, 2).unwrap(), r.state());
        assert!(decode_shipped(b"", &p, 2).unwrap_err().to_string().contains("header"));
    }

    #[test]
    fn damaged_foreign_or_mismatched_files_are_refused() {
        let p = small();
        let key = relaxation_key(&p, 1);
        let bytes = encode(&relaxed(&p, 1).state(), key);
        let err = |b: &[u8], key, l| decode(b, key, l).unwrap_err().to_string();
        assert!(err(&bytes, key ^ 1, 40).contains("other parameters"));
        assert!(err(&bytes, key, 41).contains("lattice"));
        assert!(err(&bytes[..bytes.len() - 3], key, 40).contains("checksum"));
        assert!(err(&bytes[..5], key, 40).contains("header"));
        assert!(err(b"", key, 40).contains("header"));
        assert!(err(b"PK\x03\x04 a zip file, not a state", key, 40).contains("magic"));
        for at in [20, bytes.len() / 2, bytes.len() - 9] {
            let mut b = bytes.clone();
            b[at] ^= 0x10;
            assert!(err(&b, key, 40).contains("checksum"), "a bit flipped at byte {at}");
        }
    }
}
