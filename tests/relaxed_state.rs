//! The relaxed tissues the browser demo starts from (www/assets/): each file the page lists is,
//! byte for byte, what `monolayer relaxed-state` writes now, and decodes to the state the core
//! reaches by relaxing with the page's parameters. A change of the physics or of the page's size
//! that would make the page start from a stale tissue fails here, with the command that remakes
//! the file.

mod common;

use std::path::{Path, PathBuf};

use common::{monolayer, stderr};
use monolayer::model::snapshot::{self, relaxation_key};
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
/// entry a line in RELAXED_STATES.
fn page() -> Vec<(Params, u64, f64, PathBuf)> {
    let start = STATE_JS.find("export const RELAXED_STATES").expect("RELAXED_STATES");
    let block = &STATE_JS[start..start + STATE_JS[start..].find("];").expect("RELAXED_STATES ends")];
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
    let mut straight = Monolayer::new(p, 4).unwrap();
    straight.advance(120 + 30).unwrap();
    from_file.advance(30).unwrap();
    assert_eq!(from_file.fingerprint(), straight.fingerprint());
    assert_eq!(from_file.step_count(), 150);

    // A bad parameter is named, and nothing is written.
    let bad = dir.path().join("bad.bin");
    let o = monolayer(&["relaxed-state", "--set", "n_cells=0", "--out", bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("n_cells"), "{}", stderr(&o));
    assert!(!bad.exists());
}

/// The browser test waits for the page's default preset (seed 1, from its shipped relaxed state)
/// to open its first hole at `FIRST_HOLE_STEP` (tests/browser/demo.test.mjs). The core steps the
/// same bits natively, so the step is found here one step at a time, with the page's own hole
/// count; a change of the physics or of its arithmetic that moves it fails here first, with the
/// new step.
#[test]
fn the_default_preset_opens_its_first_hole_where_the_browser_test_expects() {
    const DEMO_TEST: &str = include_str!("browser/demo.test.mjs");
    let expected: u64 = DEMO_TEST
        .split("const FIRST_HOLE_STEP = Number(process.env.FIRST_HOLE_STEP ?? ")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .expect("FIRST_HOLE_STEP in demo.test.mjs")
        .parse()
        .expect("FIRST_HOLE_STEP is a number");
    let preset = STATE_JS.split("export const DEFAULT_PRESET = '").nth(1).unwrap().split('\'').next().unwrap();
    let line = STATE_JS
        .lines()
        .map(str::trim_start)
        .find(|l| l.starts_with(&format!("{preset}:")) || l.starts_with(&format!("'{preset}':")))
        .unwrap_or_else(|| panic!("preset {preset} in state.js"));
    let size = line.split("size: '").nth(1).unwrap().split('\'').next().unwrap();
    let (zeta, chi, gamma) =
        (number_after_in(line, "zeta"), number_after_in(line, "chi"), number_after_in(line, "gamma"));
    let (relaxed, seed, _, file) = page()
        .into_iter()
        .find(|(p, seed, g, _)| *seed == 1 && *g == gamma && *p == page_size(size))
        .unwrap_or_else(|| panic!("no shipped relaxed state for preset {preset}"));
    let mut p = Params { zeta, gamma, ..relaxed };
    p.set_chi(chi);
    let state = snapshot::decode_relaxed(&std::fs::read(&file).unwrap(), &p, seed).unwrap();
    let mut m = Monolayer::from_state(p.clone(), seed, state).unwrap();
    let mut regions = monolayer::analysis::holes::VoidRegions::default();
    let holes = |m: &mut Monolayer, regions: &mut _| {
        monolayer::web::measure::tissue_stats(m.phi_sum(), p.box_size, p.radius, regions).holes
    };
    while holes(&mut m, &mut regions) == 0 && m.step_count() <= expected + 2_000 {
        m.step().unwrap();
    }
    assert_eq!(
        m.step_count(),
        expected,
        "preset {preset} opens its first hole at step {} (relaxation included): set FIRST_HOLE_STEP in \
         tests/browser/demo.test.mjs to it",
        m.step_count()
    );
    // The browser test reads the step from the page's readouts, a row every ROW_EVERY active
    // steps: the hole must still be open at the first row after it opens.
    let every = monolayer::web::readouts::ROW_EVERY;
    let row = p.relax_steps + (expected - p.relax_steps).div_ceil(every) * every;
    m.advance(row - m.step_count()).unwrap();
    assert!(holes(&mut m, &mut regions) > 0, "the first hole closed before the readout row at step {row}");
}
