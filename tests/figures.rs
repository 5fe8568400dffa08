//! `monolayer figures`: the plan (one run per point and seed, shared between figures, the paper's
//! counts), its refusals, the Slurm scripts, and the `smoke` scale end to end.

mod common;

use common::{csv_files, monolayer, stderr};
use std::path::Path;

use monolayer::run::figures::{Figure, Plan, Scale};

#[test]
fn the_paper_plan_has_the_papers_counts_and_shares_runs() {
    let plan = Plan::new(Scale::Paper, &Figure::ALL, &[], &[]).unwrap();
    let count = |f: Figure, pick: &dyn Fn(&monolayer::run::figures::Point) -> bool| {
        plan.runs_of(f).filter(|(_, p)| pick(p)).count()
    };
    let at = |chi: f64, zeta: f64| {
        move |p: &monolayer::run::figures::Point| {
            matches!(p.friction, monolayer::run::figures::Friction::Chi(c) if c == chi) && p.zeta == zeta
        }
    };
    // 10 simulations per point for Figs. 1c–d, 3a–b, 3d, S2, S3; 100 for Figs. 2 and 3c; 3 for S1.
    assert_eq!(count(Figure::Fig3d, &at(0.1, 0.3)), 10);
    assert_eq!(count(Figure::Fig1c, &at(0.05, 0.3)), 10);
    assert_eq!(count(Figure::Fig2, &at(0.005, 0.4)), 100);
    assert_eq!(count(Figure::Fig3c, &at(0.001, 0.5)), 100);
    assert_eq!(plan.runs_of(Figure::FigS1).count(), 12);
    assert!(plan.runs_of(Figure::FigS1).all(|(j, _)| j.params.box_size == 120));
    assert!(plan
        .runs_of(Figure::FigS3)
        .all(|(j, _)| j.params.active_steps == 100_000 && j.params.relax_steps == 10_000));
    // Every run once: the χ = 0.001, ζ = 0.3, seed 1 run serves 1c, 1d, 2, 3ab, 3c, 3d, S2, S3, mechanism.
    let mut names: Vec<&str> = plan.jobs.iter().map(|j| j.name.as_str()).collect();
    names.sort();
    names.dedup();
    assert_eq!(names.len(), plan.jobs.len());
    let k = plan.jobs.iter().position(|j| j.name == "chi0.001_zeta0.3_gamma0.06_L140_seed1").unwrap();
    assert_eq!(plan.points[k].1.len(), 9, "{:?}", plan.points[k].1);
    // 9 points × 100 (Figs. 2, 3c) + 6 × 10 (the rest of 3d) + 3 γ × 10 (S3) + 4 × 3 (S1).
    assert_eq!(plan.jobs.len(), 900 + 60 + 30 + 12);
    // The dry limit of Fig. S1.
    let dry = plan.jobs.iter().find(|j| j.name.starts_with("dry")).unwrap();
    assert_eq!((dry.params.xi_cell, dry.params.xi_substrate), (0.0, 1.0));
}

/// The evidence scale: the paper's protocol with 4 seeds per point for Figs. 2 and
/// 3c, 3 elsewhere, χ = 0.01 at ζ = 0.4 and 0.5, S1 with the same 100 cells on 120²; named by
/// `--help`.
#[test]
fn the_evidence_plan_is_the_papers_protocol_with_enough_seeds() {
    use monolayer::run::figures::{Friction, Point, S1_INITIAL_GAP};
    let plan = Plan::new(Scale::Evidence, &Figure::ALL, &[], &[]).unwrap();
    assert_eq!(plan.frame_interval, 1000);
    assert!(plan.jobs.iter().all(|j| j.params.relax_steps == 10_000 && j.params.active_steps == 100_000));
    let at =
        |chi: f64, zeta: f64| move |p: &Point| matches!(p.friction, Friction::Chi(c) if c == chi) && p.zeta == zeta;
    let count = |f: Figure, pick: &dyn Fn(&Point) -> bool| plan.runs_of(f).filter(|(_, p)| pick(p)).count();
    for zeta in [0.3, 0.4, 0.5] {
        for chi in [0.01, 0.005, 0.001] {
            assert_eq!(count(Figure::Fig2, &at(chi, zeta)), 4, "Fig. 2 at χ = {chi}, ζ = {zeta}");
        }
        for chi in [0.005, 0.001] {
            assert_eq!(count(Figure::Fig3c, &at(chi, zeta)), 4);
        }
        assert_eq!(count(Figure::Fig3ab, &at(0.01, zeta)), 3, "χ = 0.01 at ζ = {zeta}");
        assert_eq!(count(Figure::Fig3d, &at(0.05, zeta)), 3);
    }
    for chi in [0.1, 0.05, 0.01, 0.005, 0.001] {
        assert_eq!(count(Figure::Fig1c, &at(chi, 0.3)), 3);
        assert_eq!(count(Figure::Mechanism, &at(chi, 0.3)), 3);
    }
    assert_eq!(plan.runs_of(Figure::FigS3).count(), 12);
    // S1: the paper's 120² box holds the same 100 cells, their disks placed with a 1-site gap.
    assert_eq!(plan.runs_of(Figure::FigS1).count(), 12);
    assert!(plan
        .runs_of(Figure::FigS1)
        .all(|(j, _)| { (j.params.box_size, j.params.n_cells, j.params.initial_gap) == (120, 100, S1_INITIAL_GAP) }));
    // 36 (Figs. 2, 3c) + 9 (χ = 0.1 of 3a–b) + 9 (χ = 0.05 of 3d) + 9 (S3's other γ) + 12 (S1).
    assert_eq!(plan.jobs.len(), 75);
    let o = monolayer(&["figures", "--help"]);
    let help = String::from_utf8_lossy(&o.stdout);
    assert!(
        help.contains("evidence") && help.contains("100,000 active steps") && help.contains("every 1,000"),
        "{help}"
    );
}

/// `--point` keeps part of each figure's grid: the plan's runs at those points only, the same
/// runs (names, seeds, steps) the whole plan has there; a selection that matches nothing is
/// refused with the points there are, and a key that is not a point's, by name.
#[test]
fn a_point_selection_keeps_only_those_points_of_the_plan() {
    let whole = Plan::new(Scale::Evidence, &[Figure::Fig2], &[], &[]).unwrap();
    let picked = ["chi=0.01,zeta=0.5".to_string(), "chi=0.001".to_string()];
    let part = Plan::new(Scale::Evidence, &[Figure::Fig2], &[], &picked).unwrap();
    // (0.01, 0.5) and χ = 0.001 at its three ζ: 4 points × 4 seeds.
    assert_eq!(part.jobs.len(), 16);
    assert_eq!(part.points_of(Figure::Fig2).len(), 4);
    for j in &part.jobs {
        let same = whole.jobs.iter().find(|w| w.name == j.name).expect("a run of the whole plan");
        assert_eq!((same.seed, same.params.total_steps()), (j.seed, j.params.total_steps()));
        assert!(j.name.starts_with("chi0.001_") || j.name.starts_with("chi0.01_zeta0.5_"), "{}", j.name);
    }
    let e = Plan::new(Scale::Evidence, &[Figure::Fig2], &[], &["chi=0.1".into()]).unwrap_err().to_string();
    assert!(e.contains("--point chi=0.1") && e.contains("chi=0.005,zeta=0.4,gamma=0.06"), "{e}");
    let e = Plan::new(Scale::Evidence, &[Figure::Fig2], &[], &["xi=1".into()]).unwrap_err().to_string();
    assert!(e.contains("`xi`") && e.contains("chi, zeta, gamma"), "{e}");
    let e = Plan::new(Scale::Evidence, &[Figure::Fig2], &[], &["zeta=high".into()]).unwrap_err().to_string();
    assert!(e.contains("--point zeta=high") && e.contains("`zeta`") && e.contains("finite number"), "{e}");
    let e = Plan::new(Scale::Evidence, &[Figure::Fig2], &[], &["chi=0.01,chi=0.005".into()]).unwrap_err().to_string();
    assert!(e.contains("sets `chi` twice"), "{e}");
    // The dry limit by name (Fig. S1), and the Slurm tasks get the selection.
    let dry = Plan::new(Scale::Evidence, &[Figure::FigS1], &[], &["chi=dry".into()]).unwrap();
    assert!(!dry.jobs.is_empty() && dry.jobs.iter().all(|j| j.name.starts_with("dry")));
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f");
    let args =
        ["figures", "--out", out.to_str().unwrap(), "--only", "2", "--point", "zeta=0.5", "--slurm", "--dry-run"];
    let o = monolayer(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("--point zeta=0.5 --stage runs") && text.contains("--point zeta=0.5 --stage figures"),
        "{text}"
    );
}

#[test]
fn figures_and_scales_are_checked_before_anything_runs() {
    assert_eq!(Figure::parse_list("3a,3b, s1").unwrap(), vec![Figure::Fig3ab, Figure::FigS1]);
    let e = Figure::parse_list("1c,4").unwrap_err().to_string();
    assert!(e.contains("--only 4") && e.contains("S3"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f");
    let out = out.to_str().unwrap();
    let o = monolayer(&["figures", "--out", out, "--scale", "huge"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("smoke, standard, evidence, paper"), "{}", stderr(&o));
    let o = monolayer(&["figures", "--out", out, "--set", "zeta=40"]);
    assert!(!o.status.success() && stderr(&o).contains("`zeta`"), "{}", stderr(&o));
    let o = monolayer(&["figures", "--out", out, "--stage", "draw"]);
    assert!(stderr(&o).contains("all, runs, figures"), "{}", stderr(&o));
    // The paper's scale is days of core time: refused here without --yes, after the estimate.
    let o = monolayer(&["figures", "--out", out, "--scale", "paper", "--only", "S1"]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("12 runs") && e.contains("core-hours") && e.contains("--yes") && e.contains("ms/step"), "{e}");
    // Figures without their runs: refused, naming the runs and what to do.
    let o = monolayer(&["figures", "--out", out, "--stage", "figures", "--only", "3d"]);
    assert!(stderr(&o).contains("are not finished") && stderr(&o).contains("--stage runs"), "{}", stderr(&o));
    assert!(!Path::new(out).join("figures.md").exists());
}

#[test]
fn slurm_dry_run_prints_an_array_with_a_throttle_and_an_afterok_aggregation() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("f");
    let o = monolayer(&["figures", "--out", out.to_str().unwrap(), "--slurm", "--dry-run", "--throttle", "3"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    let plan = Plan::new(Scale::Smoke, &Figure::ALL, &[], &[]).unwrap();
    let n = plan.jobs.len();
    assert!(text.contains(&format!("#SBATCH --array=0-{}%3", n - 1)), "{text}");
    assert!(text.contains("--output=") && text.contains("run-%A_%a.out"), "{text}");
    assert!(text.contains(&format!("--stage runs --shard \"${{SLURM_ARRAY_TASK_ID}}/{n}\"")), "{text}");
    assert!(text.contains("--stage figures") && text.contains("--dependency=afterok:"), "{text}");
    assert!(!out.exists(), "a dry run writes nothing");
}

#[test]
#[ignore = "28 small runs, 1–2 minutes: scripts/test.sh runs it (cargo test --release -- --include-ignored)"]
fn the_smoke_scale_draws_every_figure_and_resumes_without_running_again() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("smoke");
    let o = monolayer(&["figures", "--out", out.to_str().unwrap(), "--scale", "smoke", "--quiet", "--jobs", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    for f in Figure::ALL {
        for ext in ["png", "svg", "csv"] {
            let p = out.join(format!("{}.{ext}", f.stem()));
            assert!(p.metadata().is_ok_and(|m| m.len() > 100), "{} missing or empty", p.display());
        }
    }
    let md = std::fs::read_to_string(out.join("figures.md")).unwrap();
    for f in Figure::ALL {
        assert!(md.contains(&format!("({}.png)", f.stem())), "figures.md lacks {}", f.stem());
    }
    assert!(md.contains("**The paper:**") && md.contains("scale `smoke`"), "{md}");
    let csvs = csv_files(&out);
    assert!(csvs["fig3d.csv"].lines().count() == 16, "{}", csvs["fig3d.csv"]);
    assert!(csvs["figS1.csv"].contains("dry,"), "the dry limit is in Fig. S1");
    // The definitions reach the figures: chance lines, both fits, the mechanism.
    for f in ["fig1c.csv", "fig1d.csv", "figS2.csv", "figmechanism.csv"] {
        assert!(csvs[f].lines().next().unwrap().contains("_chance_mean"), "{f} lacks its chance line");
    }
    assert!(csvs["fig2_fits.csv"].starts_with("chi,zeta,chi_0.1_over_zeta,bins_with_holes,hole_sites,binomial_amplitude,binomial_coefficient,binomial_coefficient_se,least_squares_"));
    assert!(csvs["figmechanism_alignment.csv"].contains("bordering_a_hole"), "{}", csvs["figmechanism_alignment.csv"]);
    assert!(md.contains("chance") && md.contains("binomial"), "{md}");
    // Again: every run is done, nothing runs, the same tables.
    let o = monolayer(&["figures", "--out", out.to_str().unwrap(), "--scale", "smoke", "--quiet"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("0 to run"), "{}", stderr(&o));
    assert_eq!(csv_files(&out), csvs);
    // Part of Fig. 2's grid from the same runs: only those points drawn, and the report says so.
    let part = dir.path().join("part");
    std::fs::create_dir_all(&part).unwrap();
    std::os::unix::fs::symlink(out.join("runs"), part.join("runs")).unwrap();
    let args = ["figures", "--out", part.to_str().unwrap(), "--scale", "smoke", "--only", "2", "--point", "zeta=0.5"];
    let o = monolayer(&[&args[..], &["--stage", "figures"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let fits = std::fs::read_to_string(part.join("fig2_fits.csv")).unwrap();
    let zetas: Vec<&str> = fits.lines().skip(1).map(|l| l.split(',').nth(1).unwrap()).collect();
    assert!(!zetas.is_empty() && zetas.iter().all(|z| *z == "0.5"), "{fits}");
    let md = std::fs::read_to_string(part.join("figures.md")).unwrap();
    assert!(md.contains("--point zeta=0.5") && md.contains("**Drawn at the selected points only**"), "{md}");
}
