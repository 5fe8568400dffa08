//! The relaxed tissues the browser demo starts from (www/assets/): each file the page lists is,
//! byte for byte, what `monolayer relaxed-state` writes now, and decodes to the state the core
//! reaches by relaxing with the page's parameters. A change of the physics or of the page's size
//! that would make the page start from a stale tissue fails here, with the command that remakes
//! the file.

mod common;

use std::path::{Path, PathBuf};

use common::{monolayer, stderr};
use monolayer::formats::snapshot::{self, relaxation_key};
use monolayer::{Monolayer, Params};

const STATE_JS: &str = include_str!("../www/js/state.js");

/// The number after `key:` in the first line of state.js that starts with `line_start`.
fn number_after(line_start: &str, key: &str) -> f64 {
    let line = STATE_JS.lines().find(|l| l.trim_start().starts_with(line_start)).expect(line_start);
    number_after_in(line, key)
}

/// The number after the first `key:` in `s`.
fn number_after_in(s: &str, key: &str) -> f64 {
    let at = s.find(&format!("{key}:")).unwrap_or_else(|| panic!("no {key}: in {s}"));
    let num: String =
        s[at + key.len() + 1..].trim_start().chars().take_while(|c| c.is_ascii_digit() || *c == '.').collect();
    num.parse().unwrap_or_else(|_| panic!("{key} in {s}"))
}

/// The page's size called `name` in state.js's SIZES (`  name: { box: …, cells: …, relaxSteps: … },`).
fn page_size(name: &str) -> Params {
    let line = format!("{name}:");
    Params {
        box_size: number_after(&line, "box") as usize,
        n_cells: number_after(&line, "cells") as usize,
        relax_steps: number_after(&line, "relaxSteps") as u64,
        ..Params::default()
    }
}

/// The page's listed relaxed states: (its size's parameters, seed, γ, file under www/), one
/// entry a line in SHIPPED_STATES (those that start with `{ size:`).
fn page() -> Vec<(Params, u64, f64, PathBuf)> {
    let start = STATE_JS.find("export const SHIPPED_STATES").expect("SHIPPED_STATES");
    let block = &STATE_JS[start..start + STATE_JS[start..].find("];").expect("SHIPPED_STATES ends")];
    let entries = block
        .lines()
        .filter(|l| l.trim_start().starts_with("{ size:"))
        .map(|e| {
            let size = e.split('\'').nth(1).expect("size name");
            let seed = number_after_in(e, "seed") as u64;
            let gamma = number_after_in(e, "gamma");
            let file = e.split("asset('").nth(1).unwrap().split('\'').next().unwrap();
            let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("www").join("assets").join(file);
            (page_size(size), seed, gamma, path)
        })
        .collect::<Vec<_>>();
    assert!(
        entries.len() >= 2,
        "state.js lists {} relaxed states, expected the reduced and the paper's",
        entries.len()
    );
    entries
}

#[test]
fn shipped_relaxed_states_are_what_the_core_relaxes_now() {
    for (size, seed, gamma, file) in page() {
        let p = Params { gamma, ..size };
        let remake = format!(
            "cargo run --release -- relaxed-state --set box_size={} --set n_cells={} --relax-steps {} --set gamma={gamma} \
             --seed {seed} --out www/{}",
            p.box_size,
            p.n_cells,
            p.relax_steps,
            file.strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("www")).unwrap().display()
        );
        let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}; remake it: {remake}", file.display()));
        let mut m = Monolayer::new(p.clone(), seed).unwrap();
        m.advance(p.relax_steps).unwrap();
        let shipped = snapshot::decode(&bytes, relaxation_key(&p, seed), p.box_size)
            .unwrap_or_else(|e| panic!("{}: {e}; remake it: {remake}", file.display()));
        assert!(shipped == m.state(), "{} is not the state the core relaxes now; remake it: {remake}", file.display());
        assert_eq!(bytes, snapshot::encode(&m.state(), relaxation_key(&p, seed)));
    }
}

#[test]
fn the_command_writes_a_state_that_continues_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("relaxed.bin");
    let small = ["--set", "box_size=50", "--set", "n_cells=8", "--relax-steps", "120", "--seed", "4"];
    let o = monolayer(&[&["relaxed-state", "--out", out.to_str().unwrap()][..], &small[..]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("step 120, 8 cells"), "{}", stderr(&o));
    let p = Params { box_size: 50, n_cells: 8, relax_steps: 120, ..Params::default() };
    let state = snapshot::decode(&std::fs::read(&out).unwrap(), relaxation_key(&p, 4), 50).unwrap();
    let mut from_file = Monolayer::from_state(p.clone(), 4, state).unwrap();
    let mut straight = Monolayer::new(p.clone(), 4).unwrap();
    straight.advance(120 + 30).unwrap();
    from_file.advance(30).unwrap();
    assert_eq!(from_file.fingerprint(), straight.fingerprint());
    assert_eq!(from_file.step_count(), 150);

    // --advance: the state that many active steps on, which continues only under the
    // parameters that made it (another ζ is refused by name).
    let later = dir.path().join("later.bin");
    let o = monolayer(
        &[&["relaxed-state", "--advance", "20", "--zeta", "0.7", "--out", later.to_str().unwrap()][..], &small[..]]
            .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("step 140, 8 cells"), "{}", stderr(&o));
    let p7 = Params { zeta: 0.7, ..p.clone() };
    let bytes = std::fs::read(&later).unwrap();
    let mut from_later =
        Monolayer::from_state(p7.clone(), 4, snapshot::decode_shipped(&bytes, &p7, 4).unwrap()).unwrap();
    let mut straight = Monolayer::new(p7, 4).unwrap();
    straight.advance(150).unwrap();
    from_later.advance(10).unwrap();
    assert_eq!(from_later.fingerprint(), straight.fingerprint());
    let err = snapshot::decode_shipped(&bytes, &p, 4).unwrap_err().to_string();
    assert!(err.contains("other parameters"), "{err}");

    // A bad parameter is named, and nothing is written.
    let bad = dir.path().join("bad.bin");
    let o = monolayer(&["relaxed-state", "--set", "n_cells=0", "--out", bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("n_cells"), "{}", stderr(&o));
    assert!(!bad.exists());
}

/// The page's shipped states further on than the relaxation (`{ preset: …, seed, step,
/// firstHole, file }` lines of SHIPPED_STATES).
struct LaterState {
    preset: String,
    seed: u64,
    step: u64,
    first_hole: u64,
    file: PathBuf,
}

fn later_states() -> Vec<LaterState> {
    let start = STATE_JS.find("export const SHIPPED_STATES").expect("SHIPPED_STATES");
    let block = &STATE_JS[start..start + STATE_JS[start..].find("];").expect("SHIPPED_STATES ends")];
    block
        .lines()
        .filter(|l| l.trim_start().starts_with("{ preset:"))
        .map(|e| {
            let file = e.split("asset('").nth(1).unwrap().split('\'').next().unwrap();
            LaterState {
                preset: e.split('\'').nth(1).expect("preset name").to_string(),
                seed: number_after_in(e, "seed") as u64,
                step: number_after_in(e, "step") as u64,
                first_hole: number_after_in(e, "firstHole") as u64,
                file: Path::new(env!("CARGO_MANIFEST_DIR")).join("www").join("assets").join(file),
            }
        })
        .collect()
}

/// The parameters of the page's preset `name` (its PRESETS line in state.js).
fn preset_params(name: &str) -> Params {
    let presets = &STATE_JS[STATE_JS.find("export const PRESETS").expect("PRESETS")..];
    let line = presets
        .lines()
        .map(str::trim_start)
        .find(|l| l.starts_with(&format!("{name}:")) || l.starts_with(&format!("'{name}':")))
        .unwrap_or_else(|| panic!("preset {name} in state.js"));
    let size = line.split("size: '").nth(1).unwrap().split('\'').next().unwrap();
    let mut p =
        Params { zeta: number_after_in(line, "zeta"), gamma: number_after_in(line, "gamma"), ..page_size(size) };
    p.set_chi(number_after_in(line, "chi"));
    p
}

/// A shipped state further on is, byte for byte, its preset's shipped relaxed state stepped on
/// to its step, under the key of every parameter of the trajectory; and the page's label is
/// true: stepping on one step at a time, the page's own hole count first sees a hole at
/// `firstHole`, and the hole is still open at the first readout row after it (the browser test
/// reads the step there). A change of the physics that moves either fails here, with the
/// command that remakes the file or the step to write.
#[test]
fn shipped_states_further_on_open_their_first_hole_where_the_page_says() {
    let later = later_states();
    let default = STATE_JS.split("export const DEFAULT_PRESET = '").nth(1).unwrap().split('\'').next().unwrap();
    assert!(
        later.iter().any(|s| s.preset == default && s.seed == 1),
        "the page's default preset ({default}) opens on a shipped state a short time before a hole"
    );
    for s in later {
        let p = preset_params(&s.preset);
        let remake = format!(
            "cargo run --release -- relaxed-state --set box_size={} --set n_cells={} --relax-steps {} --set gamma={} \
             --zeta {} --chi {} --seed {} --advance {} --out www/{}",
            p.box_size,
            p.n_cells,
            p.relax_steps,
            p.gamma,
            p.zeta,
            p.xi_substrate / p.xi_cell,
            s.seed,
            s.step - p.relax_steps,
            s.file.strip_prefix(Path::new(env!("CARGO_MANIFEST_DIR")).join("www")).unwrap().display()
        );
        let (_, _, _, relaxed_file) = page()
            .into_iter()
            .find(|(q, seed, g, _)| *seed == s.seed && *g == p.gamma && q.box_size == p.box_size)
            .unwrap_or_else(|| panic!("no shipped relaxed state for preset {} seed {}", s.preset, s.seed));
        let relaxed = snapshot::decode_shipped(&std::fs::read(&relaxed_file).unwrap(), &p, s.seed).unwrap();
        let mut m = Monolayer::from_state(p.clone(), s.seed, relaxed).unwrap();
        m.advance(s.step - p.relax_steps).unwrap();
        let bytes = std::fs::read(&s.file).unwrap_or_else(|e| panic!("{}: {e}; remake it: {remake}", s.file.display()));
        assert!(
            bytes == snapshot::encode(&m.state(), snapshot::trajectory_key(&p, s.seed)),
            "{} is not the state the core reaches now; remake it: {remake}",
            s.file.display()
        );
        let shipped = snapshot::decode_shipped(&bytes, &p, s.seed).unwrap();
        let mut m = Monolayer::from_state(p.clone(), s.seed, shipped).unwrap();
        let mut regions = monolayer::analysis::VoidRegions::default();
        let mut holes =
            |m: &mut Monolayer| monolayer::web::tissue_stats(m.phi_sum(), p.box_size, p.radius, &mut regions).holes;
        assert_eq!(holes(&mut m), 0, "preset {}: a hole is open already at the shipped step {}", s.preset, s.step);
        while holes(&mut m) == 0 && m.step_count() <= s.first_hole.max(s.step) + 5_000 {
            m.step().unwrap();
        }
        assert_eq!(
            m.step_count(),
            s.first_hole,
            "preset {} seed {} opens its first hole at step {}: set its firstHole in www/js/state.js",
            s.preset,
            s.seed,
            m.step_count()
        );
        let every = monolayer::web::ROW_EVERY;
        let row = p.relax_steps + (s.first_hole - p.relax_steps).div_ceil(every) * every;
        m.advance(row - m.step_count()).unwrap();
        assert!(holes(&mut m) > 0, "the first hole closed before the readout row at step {row}");
    }
}
