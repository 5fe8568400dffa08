//! `monolayer branch`: a new run from a run's exact state at one of its frames, stepped on with
//! parameters changed (and φ perturbed, for replicas). The model is deterministic and resumes bit
//! for bit, so a branch that changes nothing continues its parent's trajectory exactly: what a
//! branch with a change does differently is the change's doing.
//!
//! The parent's state at the step comes from its kept checkpoint there (`run --keep-checkpoints`),
//! or is replayed from the latest state before it that the run holds (the random disks of its
//! seed at worst); either way it is checked against the parent's frame at that step, bit for bit,
//! before anything is changed.

use std::fs;
use std::path::{Path, PathBuf};

use crate::formats::{decode_frame_of_box, encode_frame, BranchOrigin, Engine, ParamChange, RunRecord, RunStatus};
use crate::model::{Monolayer, Params, Perturbation, State, MAX_STEPS, STORE_NAME};
use crate::run::config::{number, params_from_table, parse_assignment};
use crate::run::error::RunError;
use crate::run::files::{
    check_checkpoint_params, checkpoint_path, frame_path, kept_checkpoint_path, read_checkpoint, read_frame, RunLock,
    KEPT_CHECKPOINTS,
};
use crate::run::runner::{check_memory, RunDir};

/// What a branch is made of.
#[derive(Clone, Debug)]
pub struct BranchOptions {
    /// The parent run's directory.
    pub parent: PathBuf,
    /// The parent's step to start from: one at which it wrote a frame.
    pub at: u64,
    /// `KEY=VALUE` changes of parameters (`chi` sets ξ_s = χ·ξ_cell).
    pub sets: Vec<String>,
    /// Steps to run from `at` (default: to the parent's end).
    pub steps: Option<u64>,
    /// Steps between frames (default: the parent's).
    pub frame_interval: Option<u64>,
    pub perturbation: Option<Perturbation>,
    /// The branch's directory: new, or empty.
    pub out: PathBuf,
}

/// Parameters a branch cannot change: the lattice and the cells are the parent's, the state is
/// past the relaxation, the length is `--steps`, and the rest acts only before the relaxation
/// ends.
const FIXED: [(&str, &str); 8] = [
    ("box_size", "the lattice is the parent's"),
    ("n_cells", "the cells are the parent's"),
    ("relax_steps", "the branch starts past the relaxation"),
    ("active_steps", "give the branch's length with --steps"),
    ("initial_radius_fraction", "it shapes only the initial disks"),
    ("initial_gap", "it places only the initial disks"),
    ("xi_relax", "it acts only during the relaxation"),
    ("relax_patch_size", "it acts only during the relaxation"),
];

/// The parent's parameters with `sets` applied, and each change as the record keeps it. Every
/// key is checked as `--set` checks it; a key given twice, an unknown one and one of `FIXED`
/// are refused by name.
pub fn branch_params(parent: &Params, sets: &[String]) -> Result<(Params, Vec<ParamChange>), RunError> {
    let mut table = toml::Table::try_from(parent).expect("parameters serialise");
    let mut given: Vec<(String, toml::Value)> = Vec::new();
    for s in sets {
        let (k, v) = parse_assignment("--set", s)?;
        if given.iter().any(|(g, _)| *g == k) {
            return Err(RunError::Options(format!("--set {s}: `{k}` is given twice; give it once")));
        }
        if let Some((_, why)) = FIXED.iter().find(|(f, _)| *f == k) {
            return Err(RunError::Options(format!("--set {s}: a branch cannot change `{k}` ({why})")));
        }
        given.push((k, v));
    }
    let chi = given.iter().position(|(k, _)| k == "chi").map(|i| given.remove(i));
    if chi.is_some() && given.iter().any(|(k, _)| k == "xi_substrate") {
        return Err(RunError::Options("--set chi and --set xi_substrate both set ξ_s: give one of them".into()));
    }
    for (k, v) in &given {
        table.insert(k.clone(), v.clone());
    }
    let mut params = params_from_table(&table, "--set")?;
    if let Some((_, v)) = &chi {
        let c = number("chi", v).map_err(|e| e.context("--set"))?;
        if c.is_nan() || c <= 0.0 {
            return Err(RunError::invalid("--set chi =", c, "a finite number > 0 (χ = ξ_s/ξ_cell)"));
        }
        params.set_chi(c);
    }
    let json = |p: &Params| serde_json::to_value(p).expect("parameters serialise");
    let (before, after) = (json(parent), json(&params));
    let mut keys: Vec<String> = given.into_iter().map(|(k, _)| k).collect();
    if chi.is_some() {
        keys.push("xi_substrate".into());
    }
    let changes = keys
        .into_iter()
        .map(|key| ParamChange { parent: before[&key].clone(), branch: after[&key].clone(), key })
        .collect();
    Ok((params, changes))
}

/// The parent's record, checked: a run of this program, on the CPU engine, in this build's
/// precision, ended, with a frame at `at`.
fn parent_record(dir: &Path, at: u64) -> Result<RunRecord, RunError> {
    let record = RunRecord::load(dir)?;
    let path = RunRecord::path(dir);
    if Engine::parse(&record.engine)? != Engine::Cpu {
        return Err(RunError::file(
            &path,
            format!(
                "the run was stepped by the {} engine: a branch continues a trajectory bit for bit, which only the \
                 CPU engine's runs allow",
                record.engine
            ),
        ));
    }
    if record.storage != STORE_NAME {
        return Err(RunError::file(
            &path,
            format!(
                "the run stores its fields in {}, this build in {STORE_NAME}: branch it with a build of its precision",
                record.storage
            ),
        ));
    }
    let last = match (&record.status, record.last_frame_step) {
        (RunStatus::Finished | RunStatus::Failed(_), Some(last)) => last,
        (status, _) => {
            return Err(RunError::file(
                &path,
                format!(
                    "the run has not finished (status \"{status}\"): finish it first (`monolayer run --resume {}`), \
                     then branch it",
                    dir.display()
                ),
            ))
        }
    };
    let (first, fi) = (record.first_frame_step(), record.frame_interval);
    if at < first || at > last || !(at - first).is_multiple_of(fi) {
        return Err(RunError::invalid(
            "--at",
            at,
            format!("a step at which the run wrote a frame: {first} to {last}, every {fi}"),
        ));
    }
    Ok(record)
}

/// The latest state the parent holds at or before `at`: a kept checkpoint, its last checkpoint,
/// or its random disks; with where it came from.
fn latest_state(dir: &Path, record: &RunRecord, at: u64) -> Result<(State, String), RunError> {
    let l = record.params.box_size;
    let kept = kept_checkpoint_path(dir, at);
    if kept.exists() {
        return Ok((checked_checkpoint(&kept, record)?, format!("kept checkpoint {}", kept.display())));
    }
    let mut candidates: Vec<(u64, PathBuf)> = Vec::new();
    if let Ok(entries) = fs::read_dir(dir.join(KEPT_CHECKPOINTS)) {
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let step =
                name.strip_prefix("checkpoint_").and_then(|s| s.strip_suffix(".npz")).and_then(|s| s.parse().ok());
            if let Some(step) = step.filter(|&s: &u64| s < at) {
                candidates.push((step, e.path()));
            }
        }
    }
    let last = checkpoint_path(dir);
    if last.exists() {
        let state = read_checkpoint(&last, l)?;
        if state.step == at {
            check_checkpoint_params(&last, record)?;
            return Ok((state, format!("the run's checkpoint {}", last.display())));
        }
        if state.step < at {
            candidates.push((state.step, last));
        }
    }
    candidates.sort();
    match candidates.pop() {
        Some((step, path)) => {
            Ok((checked_checkpoint(&path, record)?, format!("replayed from step {step} ({})", path.display())))
        }
        None => {
            let m = Monolayer::new(record.params.clone(), record.seed)?;
            Ok((m.state(), format!("replayed from step 0 (the random disks of seed {})", record.seed)))
        }
    }
}

fn checked_checkpoint(path: &Path, record: &RunRecord) -> Result<State, RunError> {
    let state = read_checkpoint(path, record.params.box_size)?;
    check_checkpoint_params(path, record)?;
    Ok(state)
}

/// The parent's monolayer at `at`, replayed from `state` where it is earlier
/// (`progress(done, of)` as it goes), and checked bit for bit against the parent's frame there.
fn parent_at(
    dir: &Path,
    record: &RunRecord,
    state: State,
    at: u64,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Monolayer, RunError> {
    let mut m = Monolayer::from_state(record.params.clone(), record.seed, state)?;
    let todo = at - m.step_count();
    while m.step_count() < at {
        let step = m.step_count();
        m.step().map_err(|e| RunError::from(e).context(format!("replaying {} at step {step}", dir.display())))?;
        progress(todo - (at - m.step_count()), todo);
    }
    let frame = frame_path(dir, at);
    let l = record.params.box_size;
    let theirs = read_frame(&frame, l)?.data;
    let mut probe = m.clone();
    let ours = decode_frame_of_box("the replayed state", &encode_frame(&mut probe)?, l)?;
    if ours != theirs {
        return Err(RunError::file(
            &frame,
            format!(
                "the state at step {at} does not give this frame bit for bit: the run was made by another build's \
                 arithmetic (its run.json: version {}), or its files were changed; branch it with the build that \
                 made it",
                record.version
            ),
        ));
    }
    Ok(m)
}

/// Refuses an output that holds anything: a branch starts in a new or empty directory.
fn fresh_output(out: &Path) -> Result<(), RunError> {
    match fs::read_dir(out) {
        Ok(mut entries) => {
            if entries.next().is_some() {
                return Err(RunError::OtherRun {
                    dir: out.to_path_buf(),
                    why: "is not empty: a branch starts in a new or empty directory (continue a branch that stopped \
                          with `monolayer run --resume DIR`)"
                        .into(),
                });
            }
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotADirectory => {
            Err(RunError::file(out, "not a directory: give a new directory for the branch"))
        }
        Err(e) => Err(RunError::io(out, e)),
    }
}

/// Makes the branch: checks everything, takes the parent's state at `at` (replaying it if
/// needed, `progress(done, of)`), applies the changes and the perturbation, and writes the
/// branch's first frame, checkpoint and record. Returns the run, ready to
/// [`RunDir::execute`].
pub fn create_branch(o: &BranchOptions, progress: &mut dyn FnMut(u64, u64)) -> Result<RunDir, RunError> {
    let parent = parent_record(&o.parent, o.at)?;
    let (mut params, changes) = branch_params(&parent.params, &o.sets)?;
    let p = &parent.params;
    let steps = match o.steps {
        Some(0) => return Err(RunError::invalid("--steps", 0, format!("in [1, {MAX_STEPS}]"))),
        Some(n) if n > MAX_STEPS => return Err(RunError::invalid("--steps", n, format!("in [1, {MAX_STEPS}]"))),
        Some(n) => n,
        None => match p.total_steps().saturating_sub(o.at) {
            0 => {
                return Err(RunError::Options(format!(
                    "--at {}: the run ends there; give the branch's length with --steps",
                    o.at
                )))
            }
            n => n,
        },
    };
    let fi = o.frame_interval.unwrap_or(parent.frame_interval);
    if fi == 0 || fi > steps || !(o.at - p.relax_steps).is_multiple_of(fi) {
        return Err(RunError::invalid(
            "--frame-interval",
            fi,
            format!(
                "in [1, --steps = {steps}] and a divisor of --at − relax_steps = {} (the frames stay on the run's \
                 grid)",
                o.at - p.relax_steps
            ),
        ));
    }
    params.active_steps = o.at - p.relax_steps + steps;
    params.validate()?;
    if let Some(perturbation) = &o.perturbation {
        perturbation.validate()?;
    }
    check_memory(&params)?;
    fresh_output(&o.out)?;
    let parent_dir = fs::canonicalize(&o.parent).map_err(|e| RunError::io(&o.parent, e))?;
    if fs::canonicalize(&o.out).is_ok_and(|out| out == parent_dir) {
        return Err(RunError::Options("--out is the parent run itself: give a new directory".into()));
    }
    let (state, source) = latest_state(&o.parent, &parent, o.at)?;
    let mut state = parent_at(&o.parent, &parent, state, o.at, progress)?.state();
    if let Some(perturbation) = &o.perturbation {
        perturbation.apply(&mut state)?;
    }
    let monolayer = Monolayer::from_state(params.clone(), parent.seed, state)?;
    let mut record = RunRecord::new(params, parent.seed, fi);
    record.branch = Some(BranchOrigin {
        parent: parent_dir.display().to_string(),
        parent_version: parent.version.clone(),
        step: o.at,
        changes,
        perturbation: o.perturbation,
        source,
    });
    fs::create_dir_all(o.out.join("frames")).map_err(|e| RunError::io(&o.out, e))?;
    let lock = RunLock::acquire(&o.out)?;
    RunDir::create_from(lock, &o.out, monolayer, record)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sets(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn each_change_is_recorded_with_both_values() {
        let parent = Params { zeta: 0.3, ..Params::default() };
        let (p, changes) = branch_params(&parent, &sets(&["zeta=0", "gamma=0.08"])).unwrap();
        assert_eq!((p.zeta, p.gamma), (0.0, 0.08));
        assert_eq!(changes.len(), 2);
        assert_eq!(changes[0].key, "zeta");
        assert_eq!(changes[0].parent, serde_json::json!(0.3));
        assert_eq!(changes[0].branch, serde_json::json!(0.0));
        let (p, changes) = branch_params(&parent, &sets(&["chi=0.01"])).unwrap();
        assert_eq!(p.xi_substrate, 0.01 * p.xi_cell);
        assert_eq!(changes[0].key, "xi_substrate");
        let (same, none) = branch_params(&parent, &[]).unwrap();
        assert_eq!((same, none), (parent, vec![]));
    }

    #[test]
    fn bad_changes_are_refused_by_name() {
        let parent = Params::default();
        for (args, expect) in [
            (&["zeta=0", "zeta=0.1"][..], "`zeta` is given twice"),
            (&["box_size=80"][..], "cannot change `box_size`"),
            (&["active_steps=5"][..], "--steps"),
            (&["zeta_typo=1"][..], "unknown parameter `zeta_typo`"),
            (&["zeta=abc"][..], "parameter `zeta`"),
            (&["chi=0.1", "xi_substrate=0.1"][..], "both set ξ_s"),
            (&["chi=-1"][..], "chi"),
        ] {
            let e = branch_params(&parent, &sets(args)).unwrap_err().to_string();
            assert!(e.contains(expect), "{args:?}: {e}");
        }
    }
}
