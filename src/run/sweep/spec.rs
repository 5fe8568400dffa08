//! A sweep as given (its file, or `--grid`, `--point`, `--set`, `--seeds`) and the runs it
//! expands to, each validated and named, and its shards.
//!
//! A sweep file:
//! ```toml
//! seeds = [1, 2, 3]          # every grid point runs once per seed
//! frame_interval = 1000      # optional (default 1000)
//! [base]                     # any parameter (names of `monolayer params`); defaults fill the rest
//! active_steps = 100000
//! [grid]                     # lists: their Cartesian product is run; `chi` sets ξ_s = χ ξ_cell
//! chi = [0.1, 0.01, 0.001]
//! zeta = [0.3, 0.4, 0.5]
//! ```
//!
//! Points that are not a grid (the paper's regime-map set, say) are listed instead as
//! `[[points]]` tables, or `--point chi=0.1,zeta=0.5` on the command line; every point takes the
//! grid's product if there is one too. All points set the same parameters.

use std::path::Path;

use serde::Deserialize;

use crate::model::Params;
use crate::run::config::{number, params_from_table, parse_assignments, parse_list};
use crate::run::error::RunError;

/// A sweep as written in its file (or assembled from the command line).
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    #[serde(default)]
    pub base: toml::Table,
    #[serde(default)]
    pub grid: toml::Table,
    /// Single points, each a table of parameter values, run instead of the empty point the grid
    /// starts from.
    #[serde(default)]
    pub points: Vec<toml::Table>,
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    #[serde(default = "default_frame_interval")]
    pub frame_interval: u64,
    /// Every run keeps every checkpoint (`run --keep-checkpoints`), the states
    /// `monolayer branch` starts from.
    #[serde(default)]
    pub keep_checkpoints: bool,
}

/// The most runs one sweep takes (the paper's whole plan is 1,002).
pub const MAX_RUNS: usize = 100_000;

fn default_seeds() -> Vec<u64> {
    vec![1]
}

fn default_frame_interval() -> u64 {
    1000
}

/// One run of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// Directory name under `OUT/runs/`, e.g. `chi0.01_zeta0.3_seed1`.
    pub name: String,
    /// The grid values of this run, in grid order, as text.
    pub values: Vec<(String, String)>,
    pub params: Params,
    pub seed: u64,
}

fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

impl SweepSpec {
    pub fn from_file(path: &Path) -> Result<Self, RunError> {
        let text = crate::run::files::read_text_input(path, "a sweep file")?;
        crate::run::config::from_toml(&text, &path.display().to_string())
    }

    /// `KEY=V1,V2,…` from the command line into the grid (values in TOML syntax; bare words
    /// are strings).
    pub fn add_grid(&mut self, arg: &str) -> Result<(), RunError> {
        let (k, values) = parse_list("--grid", arg)?;
        if self.grid.contains_key(&k) {
            return Err(RunError::Options(format!(
                "--grid {arg}: `{k}` is already a grid axis (give its values in one --grid {k}=V1,V2,…)"
            )));
        }
        self.grid.insert(k, toml::Value::Array(values));
        Ok(())
    }

    /// `K1=V1,K2=V2,…` from the command line as one point (values in TOML syntax, one each).
    pub fn add_point(&mut self, arg: &str) -> Result<(), RunError> {
        self.points.push(parse_assignments("--point", arg)?);
        Ok(())
    }

    /// The listed points as (key, value) lists in key order, or the one empty point; checked:
    /// every point sets the same keys, and none that the grid varies (a point listed twice is
    /// refused by [`Self::jobs`], as two runs of one name).
    fn starting_points(&self) -> Result<Vec<Vec<(String, toml::Value)>>, RunError> {
        let Some(first) = self.points.first() else { return Ok(vec![Vec::new()]) };
        let keys: Vec<&String> = first.keys().collect();
        if keys.is_empty() {
            return Err(RunError::Sweep("a point sets no parameter".into()));
        }
        if let Some(k) = keys.iter().find(|k| self.grid.contains_key(k.as_str())) {
            return Err(RunError::Sweep(format!("`{k}` is set both by the points and by the grid")));
        }
        let mut out = Vec::new();
        for p in &self.points {
            if p.keys().collect::<Vec<_>>() != keys {
                let names = |t: &toml::Table| t.keys().cloned().collect::<Vec<_>>().join(", ");
                return Err(RunError::Sweep(format!(
                    "every point must set the same parameters: {} against {}",
                    names(first),
                    names(p)
                )));
            }
            out.push(p.iter().map(|(k, v)| (k.clone(), v.clone())).collect());
        }
        Ok(out)
    }

    /// Every run of the sweep, each one's parameters validated: a bad sweep fails here, before
    /// anything runs, naming the run and the parameter.
    pub fn jobs(&self) -> Result<Vec<Job>, RunError> {
        self.check_seeds()?;
        let axes = self.grid_axes()?;
        self.check_keys_set_once()?;
        let runs = axes
            .iter()
            .try_fold(self.points.len().max(1).saturating_mul(self.seeds.len()), |n, (_, v)| n.checked_mul(v.len()))
            .filter(|&n| n <= MAX_RUNS);
        if runs.is_none() {
            return Err(RunError::Sweep(format!(
                "more than {MAX_RUNS} runs (the paper's whole plan is 1,002): split it into several sweeps"
            )));
        }
        let mut jobs = Vec::new();
        let mut names = std::collections::HashMap::new();
        for point in self.points_of(&axes)? {
            let label: Vec<(String, String)> = point.iter().map(|(k, v)| (k.clone(), value_text(v))).collect();
            let params = self.point_params(&point, &label)?;
            for &seed in &self.seeds {
                let mut name: String = label.iter().map(|(k, v)| format!("{k}{v}_")).collect();
                name = name.replace(['/', ' ', '"'], "");
                name.push_str(&format!("seed{seed}"));
                if let Some(&other) = names.get(&name) {
                    let other: &Job = &jobs[other];
                    return Err(RunError::Sweep(format!(
                        "runs {:?} and {:?} would share the directory {name}",
                        other.values, label
                    )));
                }
                names.insert(name.clone(), jobs.len());
                jobs.push(Job { name, values: label.clone(), params: params.clone(), seed });
            }
        }
        Ok(jobs)
    }

    /// The seeds and the frame interval: some seeds, none twice (two jobs of one name would share
    /// a directory, and the tables would count them twice).
    fn check_seeds(&self) -> Result<(), RunError> {
        if self.seeds.is_empty() {
            return Err(RunError::Sweep("`seeds` is empty".into()));
        }
        if self.frame_interval == 0 {
            return Err(RunError::Sweep("`frame_interval` must be ≥ 1".into()));
        }
        if self.seeds.len() > MAX_RUNS {
            return Err(RunError::Sweep(format!("{} seeds, more than a sweep's {MAX_RUNS} runs", self.seeds.len())));
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(seed) = self.seeds.iter().find(|s| !seen.insert(**s)) {
            return Err(RunError::Sweep(format!("`seeds` lists {seed} twice")));
        }
        Ok(())
    }

    /// The grid's axes, each a non-empty list of distinct values (equal as numbers is equal:
    /// `zeta = [1, 1.0]` would be two runs of one point).
    fn grid_axes(&self) -> Result<Vec<(String, Vec<toml::Value>)>, RunError> {
        let mut axes = Vec::new();
        for (k, v) in &self.grid {
            let values = match v {
                toml::Value::Array(a) if !a.is_empty() => a.clone(),
                toml::Value::Array(_) => return Err(RunError::Sweep(format!("grid `{k}` is an empty list"))),
                other => vec![other.clone()],
            };
            if values.len() > MAX_RUNS {
                return Err(RunError::Sweep(format!(
                    "grid `{k}` lists {} values, more than a sweep's {MAX_RUNS} runs",
                    values.len()
                )));
            }
            let mut seen = std::collections::HashMap::new();
            for v in &values {
                let id = match number(k, v) {
                    Ok(x) => format!("{}", x + 0.0),
                    Err(_) => value_text(v),
                };
                if let Some(first) = seen.insert(id, v) {
                    let (a, b) = (value_text(first), value_text(v));
                    return Err(RunError::Sweep(format!(
                        "grid `{k}` lists {a} twice ({a} and {b} are one value: two identical runs)"
                    )));
                }
            }
            axes.push((k.clone(), values));
        }
        Ok(axes)
    }

    /// Each parameter set in one place only: `chi` and `xi_substrate` are one (χ sets
    /// ξ_s = χ·ξ_cell), and a grid or point value would replace the base's unsaid.
    fn check_keys_set_once(&self) -> Result<(), RunError> {
        let sets = |key: &str| {
            self.base.contains_key(key)
                || self.grid.contains_key(key)
                || self.points.iter().any(|p| p.contains_key(key))
        };
        if sets("chi") && sets("xi_substrate") {
            return Err(RunError::Sweep(
                "sets both `chi` and `xi_substrate` (χ sets ξ_s = χ·ξ_cell, so one would override \
                        the other): give one of them"
                    .into(),
            ));
        }
        if let Some(k) =
            self.base.keys().find(|k| self.grid.contains_key(*k) || self.points.iter().any(|p| p.contains_key(*k)))
        {
            let by = if self.grid.contains_key(k) { "the grid" } else { "the points" };
            return Err(RunError::Sweep(format!(
                "`{k}` is set both by [base] (or --set) and by {by}, whose value would replace the base's: give \
                 it in one of them"
            )));
        }
        Ok(())
    }

    /// Every point: the listed points (or the one empty point), each times the grid's product.
    fn points_of(&self, axes: &[(String, Vec<toml::Value>)]) -> Result<Vec<Vec<(String, toml::Value)>>, RunError> {
        let mut points = self.starting_points()?;
        for (k, values) in axes {
            points = points
                .into_iter()
                .flat_map(|p| {
                    values.iter().map(move |v| {
                        let mut q = p.clone();
                        q.push((k.clone(), v.clone()));
                        q
                    })
                })
                .collect();
        }
        Ok(points)
    }

    /// The parameters of one point (`label`: its values as text, to name it in errors): the base
    /// with the point's values over it, `chi` setting ξ_s, validated.
    fn point_params(&self, point: &[(String, toml::Value)], label: &[(String, String)]) -> Result<Params, RunError> {
        let mut table = self.base.clone();
        let mut chi = table.remove("chi");
        for (k, v) in point {
            if k == "chi" {
                chi = Some(v.clone());
            } else {
                table.insert(k.clone(), v.clone());
            }
        }
        let described: Vec<String> = label.iter().map(|(k, v)| format!("{k} = {v}")).collect();
        let origin = if described.is_empty() {
            "sweep, run the base run".to_string()
        } else {
            format!("sweep, run {}", described.join(", "))
        };
        let mut params = params_from_table(&table, &origin)?;
        if let Some(c) = chi {
            params.set_chi(number("chi", &c).map_err(|e| e.context(origin.as_str()))?);
        }
        params.validate().map_err(|e| RunError::from(e).context(origin))?;
        Ok(params)
    }
}

/// A shard of a sweep: run `index` of every `count` jobs (a Slurm job array sets
/// `--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// The shard of a Slurm job array, when run as one.
    /// The task's index counts from the array's first (`SLURM_ARRAY_TASK_MIN`), so that
    /// `--array=1-N` runs every shard as `--array=0-N-1` does.
    pub fn of_slurm_array() -> Result<Option<Shard>, RunError> {
        let var = |name: &str| std::env::var(name).ok();
        let (Some(id), Some(count)) = (var("SLURM_ARRAY_TASK_ID"), var("SLURM_ARRAY_TASK_COUNT")) else {
            return Ok(None);
        };
        let number = |name: &str, v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| RunError::Parse(format!("{name} = {v:?}: not a task number (from Slurm's environment)")))
        };
        let (id, count) = (number("SLURM_ARRAY_TASK_ID", &id)?, number("SLURM_ARRAY_TASK_COUNT", &count)?);
        let min = var("SLURM_ARRAY_TASK_MIN").map(|m| number("SLURM_ARRAY_TASK_MIN", &m)).transpose()?.unwrap_or(0);
        let max = var("SLURM_ARRAY_TASK_MAX").map(|m| number("SLURM_ARRAY_TASK_MAX", &m)).transpose()?;
        let contiguous = max.is_none_or(|max| max.checked_sub(min).map(|d| d + 1) == Some(count));
        match id.checked_sub(min) {
            Some(index) if index < count && count > 0 && contiguous => Ok(Some(Shard { index, count })),
            _ => Err(RunError::Options(format!(
                "this Slurm array task (SLURM_ARRAY_TASK_ID = {id}, MIN = {min}, MAX = {}, COUNT = {count}) is not one of \
                 a contiguous array such as --array=0-{}: give each task its share with --shard K/N",
                max.map(|m| m.to_string()).unwrap_or_else(|| "unset".into()),
                count.saturating_sub(1)
            ))),
        }
    }
}

impl std::str::FromStr for Shard {
    type Err = RunError;
    fn from_str(s: &str) -> Result<Self, RunError> {
        let bad = || RunError::Parse(format!("--shard {s}: expected K/N with 0 ≤ K < N"));
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (k.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_expands_validates_and_names() {
        let mut spec: SweepSpec =
            toml::from_str("seeds = [1, 2]\n[base]\nactive_steps = 10\n[grid]\nchi = [0.1, 0.01]\n").unwrap();
        spec.add_grid("zeta=0.3,0.5").unwrap();
        let jobs = spec.jobs().unwrap();
        assert_eq!(jobs.len(), 8);
        assert_eq!(jobs[0].name, "chi0.1_zeta0.3_seed1");
        assert!((jobs[0].params.xi_substrate - 0.1).abs() < 1e-15);
        assert_eq!(jobs[0].params.active_steps, 10);
        let bad: SweepSpec = toml::from_str("[grid]\nzeta = [0.3, 40.0]\n").unwrap();
        let e = bad.jobs().unwrap_err().to_string();
        assert!(e.contains("zeta = 40") && e.contains("`zeta`"), "{e}");
        let typo: SweepSpec = toml::from_str("[grid]\nzetta = [0.3]\n").unwrap();
        assert!(typo.jobs().unwrap_err().to_string().contains("zetta"));
        assert!(toml::from_str::<SweepSpec>("sedes = [1]\n").is_err());
        assert_eq!("2/4".parse::<Shard>().unwrap(), Shard { index: 2, count: 4 });
    }

    #[test]
    fn points_are_listed_runs_named_like_grid_runs() {
        let mut spec: SweepSpec = toml::from_str("seeds = [1, 2]\n[[points]]\nchi = 0.1\nzeta = 0.5\n").unwrap();
        spec.add_point("chi=0.001,zeta=0.3").unwrap();
        let jobs = spec.jobs().unwrap();
        let names: Vec<&str> = jobs.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(
            names,
            ["chi0.1_zeta0.5_seed1", "chi0.1_zeta0.5_seed2", "chi0.001_zeta0.3_seed1", "chi0.001_zeta0.3_seed2"]
        );
        assert!((jobs[2].params.xi_substrate - 0.001).abs() < 1e-15 && jobs[2].params.zeta == 0.3);
        // With a grid, every point takes its product.
        spec.add_grid("gamma=0.05,0.06").unwrap();
        assert_eq!(spec.jobs().unwrap()[0].name, "chi0.1_zeta0.5_gamma0.05_seed1");
        assert_eq!(spec.jobs().unwrap().len(), 8);
        // Refused, each naming why.
        let err = |spec: &SweepSpec| spec.jobs().unwrap_err().to_string();
        let mut overlap = spec.clone();
        overlap.add_grid("zeta=0.3").unwrap();
        assert!(err(&overlap).contains("`zeta` is set both"), "{}", err(&overlap));
        let mut uneven = spec.clone();
        uneven.add_point("chi=0.01").unwrap();
        assert!(err(&uneven).contains("the same parameters"), "{}", err(&uneven));
        let mut twice = spec.clone();
        twice.add_point("chi=0.1,zeta=0.5").unwrap();
        assert!(err(&twice).contains("would share the directory chi0.1_zeta0.5_gamma0.05_seed1"), "{}", err(&twice));
        let empty = || toml::from_str::<SweepSpec>("").unwrap();
        assert!(empty().add_point("chi=0.1,chi=0.2").unwrap_err().to_string().contains("twice"));
        let mut bad = empty();
        bad.add_point("chi=0.1,zeta=40").unwrap();
        assert!(err(&bad).contains("zeta"), "{}", err(&bad));
        assert!("4/4".parse::<Shard>().is_err());
    }
}
