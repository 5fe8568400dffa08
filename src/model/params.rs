//! Every knob of the model in one struct, with the paper's values as defaults.
//!
//! Field names follow the paper's symbols (see the table in docs/model.md). The conventions the
//! paper leaves open (docs/reading.md §7) are named fields here, not constants buried
//! in the kernels, so that the calibration can compare them run against run.

use serde::{Deserialize, Serialize};

/// How the passive force density is formed from the chemical potential μ_i (paper Eq. 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PassiveForce {
    /// f^p_i = −∇μ_i, as printed in the paper, and the default: with subdomain friction
    /// weights it comes closer to the paper's regime map than −φ_i ∇μ_i (docs/calibration.md).
    GradMu,
    /// f^p_i = −φ_i ∇μ_i, the usual phase-field form (the default until the paper-length
    /// runs compared the two; docs/calibration.md).
    PhiGradMu,
}

/// Which cells count in the cell–cell friction sum of Eq. 2, and with what weight.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrictionWeights {
    /// Each cell j at x' weighs φ_j(x'), clamped to [0, 1] (docs/reading.md §4).
    Phi,
    /// Each cell with φ_j(x') > `presence_threshold` weighs 1: "j ∈ x'" read as every cell
    /// present at x', with the paper's own threshold; a stronger friction at cell edges (the
    /// default until the subdomain reading was screened; docs/calibration.md).
    Presence,
    /// Every cell whose subdomain (patch) covers x' weighs 1, whatever φ_j(x') is: in the
    /// paper's code each phase field lives on its own subdomain (its SI Sec. A), so "all phase
    /// fields at the lattice site x'" may be every field defined there. The patch rule
    /// (`relax_patch_size`, then `patch_margin` beyond φ > `presence_threshold`) then becomes
    /// part of the model. The strongest of the three readings (n ≈ 4.5 per site at full size),
    /// and the default: the one that comes closest to the paper's regime map and speeds
    /// (docs/calibration.md).
    Subdomain,
}

/// The discrete Laplacian used in the chemical potential.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Laplacian {
    /// (E + W + N + S − 4c).
    FivePoint,
    /// (4(E + W + N + S) + (NE + NW + SE + SW) − 20c) / 6: isotropic to leading order.
    NinePoint,
}

/// How −v·∇φ is discretised in the equation of motion (Eq. 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Advection {
    /// Central differences, second order.
    Central,
    /// First-order upwind differences: diffusive, but monotone.
    Upwind,
}

/// All parameters of a simulation. Defaults are the paper's (Supplementary Sec. A) at full size,
/// in the low-friction regime where holes form.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    // --- lattice and cells -------------------------------------------------------------------
    /// L: side of the periodic square lattice, in sites (Δx = 1).
    pub box_size: usize,
    /// N: number of cells.
    pub n_cells: usize,
    /// R: target cell radius; the area constraint targets πR².
    pub radius: f64,

    // --- free energy (Supplementary Eqs. S1–S3) ----------------------------------------------
    /// λ: interface width.
    pub lambda: f64,
    /// γ: surface tension (Cahn–Hilliard strength γ/λ).
    pub gamma: f64,
    /// κ: overlap repulsion (strength κ/λ).
    pub kappa: f64,
    /// μ: stiffness of the soft area constraint (the paper's μ, not the chemical potential).
    pub mu: f64,
    /// Prefactor c of the repulsion term (c κ/λ) φ_i Σ_{j≠i} φ_j² in δF/δφ_i: 4 follows the
    /// double sum as printed (each pair counted twice), 2 is Mueller et al.'s convention.
    pub repulsion_factor: f64,
    /// J₀: relaxation rate of the phase fields towards the free-energy minimum.
    pub j0: f64,

    // --- activity and friction (Eqs. 2, 4, 5) ------------------------------------------------
    /// ζ: activity; ζ > 0 is extensile.
    pub zeta: f64,
    /// |Q̂|: magnitude of the normalised shape tensor. ½ is the unit-order nematic tensor
    /// n n − I/2; 2 is "normalised by 0.5|Q|" read literally.
    pub q_magnitude: f64,
    /// ε in Q̂ = |Q̂| Q / √(|Q|² + ε²): a round cell has no direction, and this makes Q̂ fade
    /// smoothly to zero instead of jumping between arbitrary directions.
    pub q_epsilon: f64,
    /// ξ_s: substrate friction (uniform value; a per-site map multiplies it).
    pub xi_substrate: f64,
    /// ξ_cell: cell–cell friction. χ = ξ_s / ξ_cell.
    pub xi_cell: f64,
    /// Passive force form (Eq. 3).
    pub passive_force: PassiveForce,
    /// Weights in the cell–cell friction sum (Eq. 2).
    pub friction_weights: FrictionWeights,
    /// φ above which a cell counts as present (friction weights `presence`; patch sizing).
    pub presence_threshold: f64,

    // --- numerics ----------------------------------------------------------------------------
    /// Δt: time step.
    pub dt: f64,
    /// Discrete Laplacian in μ_i.
    pub laplacian: Laplacian,
    /// Advection scheme in Eq. 1.
    pub advection: Advection,
    /// Relative residual ‖b − B V‖/‖b‖ at which the friction solve stops. 1e-4 keeps the
    /// solve's error in φ 4–25× below the time step's at Δt = 0.1, and the measured statistics
    /// (holes, speeds, correlation lengths, aspect ratios) within 0.1 % of 1e-5's over
    /// 20,000 steps (docs/performance.md, "Tolerance").
    pub friction_tolerance: f64,
    /// Iterations after which the friction solve gives up with an error.
    pub friction_max_iterations: usize,
    /// Side of the square patch each cell lives on during relaxation.
    pub relax_patch_size: usize,
    /// After relaxation, a patch side sits this many sites beyond the last site with
    /// φ > `presence_threshold` (it grows and shrinks to keep it so).
    pub patch_margin: usize,
    /// φ_i outside [−bound_low, 1 + bound_high] stops the run as unstable: bounds as values.
    pub phi_min: f64,
    /// Upper bound of φ_i before the run is stopped as unstable.
    pub phi_max: f64,

    // --- protocol ----------------------------------------------------------------------------
    /// Steps of passive relaxation (ζ = 0, ξ_cell = 0) from small random disks.
    pub relax_steps: u64,
    /// Friction used during relaxation: v = f / ξ_relax.
    pub xi_relax: f64,
    /// Steps with activity and cell–cell friction after relaxation.
    pub active_steps: u64,
    /// Radius of the initial disks, as a fraction of R.
    pub initial_radius_fraction: f64,
    /// Smallest distance between the edges of two initial disks, in sites (see
    /// `model::init::random_disks` for why they start apart).
    pub initial_gap: f64,

    // --- units (reporting only; the dynamics never read them) ---------------------------------
    /// Seconds per simulation time unit, for speeds in µm/h (Δx ≈ 1 µm); it changes no
    /// dynamics. The paper settles it itself: its persistence threshold τ_t > 0.5 t_total is
    /// 5,000 time units, which it calls "∼ 5 h", so one time unit ≈ 3.6 s (the default); its
    /// "Δt ∼ 5 s" is the same estimate rounded (docs/calibration.md, "Units").
    pub time_unit_seconds: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            box_size: 140,
            n_cells: 100,
            radius: 8.0,
            lambda: 2.0,
            gamma: 0.06,
            kappa: 0.5,
            mu: 20.0,
            repulsion_factor: 4.0,
            j0: 1.0,
            zeta: 0.5,
            q_magnitude: 0.5,
            q_epsilon: 1e-2,
            xi_substrate: 0.001,
            xi_cell: 1.0,
            passive_force: PassiveForce::GradMu,
            friction_weights: FrictionWeights::Subdomain,
            presence_threshold: 0.01,
            dt: 0.1,
            laplacian: Laplacian::FivePoint,
            advection: Advection::Central,
            friction_tolerance: 1e-4,
            friction_max_iterations: 500,
            relax_patch_size: 30,
            patch_margin: 4,
            phi_min: -0.5,
            phi_max: 1.5,
            relax_steps: 10_000,
            xi_relax: 1.0,
            active_steps: 100_000,
            initial_radius_fraction: 0.5,
            initial_gap: 2.0,
            time_unit_seconds: 3.6,
        }
    }
}

/// The most steps of either phase of the protocol.
pub const MAX_STEPS: u64 = 1_000_000_000;

/// The largest lattice a run may have (`box_size`), 4096²: hundreds of times the paper's.
pub const MAX_BOX_SIZE: usize = 4096;

/// A parameter outside its allowed range, named as in the config file.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("parameter `{name}` = {value}: {allowed}")]
pub struct ParamError {
    pub name: &'static str,
    pub value: String,
    pub allowed: String,
}

/// A number as a message shows it: as written where that is short (`0.06`, `1000`), in
/// scientific notation far from 1 (`1e308`, not its 309 digits; `1e-300`, not 300 zeros).
pub fn number_text(x: f64) -> String {
    let a = x.abs();
    if x.is_finite() && a != 0.0 && !(1e-4..1e15).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// A parameter's value as its error shows it ([`number_text`] for reals).
trait Shown {
    fn shown(&self) -> String;
}

impl Shown for f64 {
    fn shown(&self) -> String {
        number_text(*self)
    }
}

impl Shown for usize {
    fn shown(&self) -> String {
        self.to_string()
    }
}

impl Shown for u64 {
    fn shown(&self) -> String {
        self.to_string()
    }
}

fn check(ok: bool, name: &'static str, value: impl Shown, allowed: impl Into<String>) -> Result<(), ParamError> {
    if ok {
        Ok(())
    } else {
        Err(ParamError { name, value: value.shown(), allowed: allowed.into() })
    }
}

fn positive(name: &'static str, v: f64) -> Result<(), ParamError> {
    check(v.is_finite() && v > 0.0, name, v, "must be a finite number > 0")
}

fn non_negative(name: &'static str, v: f64) -> Result<(), ParamError> {
    check(v.is_finite() && v >= 0.0, name, v, "must be a finite number ≥ 0")
}

/// The range of a friction coefficient: the paper's χ = ξ_s/ξ_cell spans 0.001 to 1 at
/// ξ_cell = 1, well inside it; far outside, the friction solve's matrix is so ill-conditioned
/// that the solve fails, which would end the run as `failed:` instead of refusing the value.
pub const FRICTION_RANGE: (f64, f64) = (1e-6, 1e3);

/// A friction coefficient in [`FRICTION_RANGE`], or 0 where `zero_ok` (ξ_cell = 0: the dry
/// limit, and the relaxation's friction).
fn friction(name: &'static str, v: f64, zero_ok: bool) -> Result<(), ParamError> {
    let (lo, hi) = FRICTION_RANGE;
    let ok = (lo..=hi).contains(&v) || (zero_ok && v == 0.0);
    let allowed =
        if zero_ok { format!("must be 0 or in [{lo:e}, {hi:e}]") } else { format!("must be in [{lo:e}, {hi:e}]") };
    check(ok, name, v, allowed)
}

impl Params {
    /// Of `factors` (name, value), the one furthest above its default: where a bound on their
    /// product is broken, the value most likely given is named, not the one left at its default.
    fn furthest_above_default(&self, factors: &[(&'static str, f64)]) -> (&'static str, f64) {
        let defaults = Params::default();
        let default_of = |name: &str| match name {
            "j0" => defaults.j0,
            "gamma" => defaults.gamma,
            "lambda" => defaults.lambda,
            _ => defaults.dt,
        };
        let ratio = |&(name, v): &(&'static str, f64)| if v.is_finite() { v / default_of(name) } else { f64::INFINITY };
        *factors.iter().max_by(|a, b| ratio(a).total_cmp(&ratio(b))).expect("factors given")
    }

    /// The friction ratio χ = ξ_s / ξ_cell (infinite in the dry limit ξ_cell = 0).
    pub fn chi(&self) -> f64 {
        self.xi_substrate / self.xi_cell
    }

    /// µm/h per lattice site per time unit (Δx ≈ 1 µm).
    pub fn microns_per_hour(&self) -> f64 {
        3600.0 / self.time_unit_seconds
    }

    /// Set ξ_s from χ, keeping ξ_cell.
    pub fn set_chi(&mut self, chi: f64) {
        self.xi_substrate = chi * self.xi_cell;
    }

    /// The area every cell is pulled towards, πR².
    pub fn target_area(&self) -> f64 {
        core::f64::consts::PI * self.radius * self.radius
    }

    /// Steps of the whole protocol, relaxation and active phase.
    pub fn total_steps(&self) -> u64 {
        self.relax_steps + self.active_steps
    }

    /// Checks every parameter against its allowed range and against the others, in groups in
    /// this order (the first error found is the one reported).
    pub fn validate(&self) -> Result<(), ParamError> {
        self.check_tissue()?;
        self.check_forces()?;
        self.check_friction_and_time_step()?;
        self.check_patches_and_guards()?;
        self.check_protocol()
    }

    /// The lattice and the cells on it: the box, their number, size and cover.
    fn check_tissue(&self) -> Result<(), ParamError> {
        check(
            (16..=MAX_BOX_SIZE).contains(&self.box_size),
            "box_size",
            self.box_size,
            format!("must be in [16, {MAX_BOX_SIZE}]"),
        )?;
        check(self.n_cells >= 1 && self.n_cells <= 100_000, "n_cells", self.n_cells, "must be in [1, 100000]")?;
        check(self.radius.is_finite() && self.radius >= 2.0, "radius", self.radius, "must be ≥ 2 sites")?;
        check(
            self.radius * 4.0 < self.box_size as f64,
            "radius",
            self.radius,
            format!("a cell's diameter 2R must be below half the box (box_size = {})", self.box_size),
        )?;
        let covered = self.n_cells as f64 * self.target_area() / (self.box_size * self.box_size) as f64;
        check(
            covered <= 1.5,
            "n_cells",
            self.n_cells,
            format!(
                "N·πR² = {:.0} is {:.0} % of the box L² = {}: at most 150 % (the paper has 103 %)",
                self.n_cells as f64 * self.target_area(),
                covered * 100.0,
                self.box_size * self.box_size
            ),
        )?;
        Ok(())
    }

    /// The free energy and the activity: λ, γ, κ, μ, the repulsion, J₀, ζ and Q.
    fn check_forces(&self) -> Result<(), ParamError> {
        positive("lambda", self.lambda)?;
        non_negative("gamma", self.gamma)?;
        non_negative("kappa", self.kappa)?;
        non_negative("mu", self.mu)?;
        check(
            self.repulsion_factor.is_finite() && self.repulsion_factor > 0.0,
            "repulsion_factor",
            self.repulsion_factor,
            "must be > 0 (4 as printed, 2 as in Mueller et al.)",
        )?;
        positive("j0", self.j0)?;
        check(
            self.zeta.is_finite() && self.zeta.abs() <= 10.0,
            "zeta",
            self.zeta,
            "must be in [−10, 10] (ζ > 0 is extensile)",
        )?;
        check(
            self.q_magnitude.is_finite() && self.q_magnitude > 0.0 && self.q_magnitude <= 4.0,
            "q_magnitude",
            self.q_magnitude,
            "must be in (0, 4] (½, 1 or 2 are the readings of the paper)",
        )?;
        positive("q_epsilon", self.q_epsilon)?;
        Ok(())
    }

    /// The frictions, the time step and the explicit scheme's stability, the friction solve.
    fn check_friction_and_time_step(&self) -> Result<(), ParamError> {
        friction("xi_substrate", self.xi_substrate, false)?;
        friction("xi_cell", self.xi_cell, true)?;
        check(
            self.presence_threshold > 0.0 && self.presence_threshold < 0.5,
            "presence_threshold",
            self.presence_threshold,
            "must be in (0, 0.5)",
        )?;
        check(self.dt.is_finite() && self.dt > 0.0 && self.dt <= 0.5, "dt", self.dt, "must be in (0, 0.5]")?;
        // Explicit diffusion of φ: J₀·2γλ·Δt·(max Laplacian eigenvalue 8) must stay below 2
        // (Heun's stability limit on the negative real axis is about 2).
        let diffusion = self.j0 * 2.0 * self.gamma * self.lambda * 8.0 * self.dt;
        let (name, value) = self.furthest_above_default(&[
            ("j0", self.j0),
            ("gamma", self.gamma),
            ("lambda", self.lambda),
            ("dt", self.dt),
        ]);
        check(
            diffusion < 2.0,
            name,
            value,
            format!(
                "J₀·2γλ·8·Δt = {} must be < 2 for the explicit scheme to be stable: lower {name} (or another of j0, \
                 gamma, lambda, dt)",
                number_text(diffusion)
            ),
        )?;
        check(
            self.friction_tolerance > 0.0 && self.friction_tolerance <= 1e-2,
            "friction_tolerance",
            self.friction_tolerance,
            "must be in (0, 1e-2]",
        )?;
        check(
            self.friction_max_iterations >= 1 && self.friction_max_iterations <= 100_000,
            "friction_max_iterations",
            self.friction_max_iterations,
            "must be in [1, 100000]",
        )?;
        Ok(())
    }

    /// The patches, the φ guards and the relaxation's friction.
    fn check_patches_and_guards(&self) -> Result<(), ParamError> {
        // patch_margin first: relax_patch_size's range is computed from it.
        check(
            self.patch_margin >= 2 && self.patch_margin <= 32,
            "patch_margin",
            self.patch_margin,
            "must be in [2, 32]",
        )?;
        let min_patch = (2.0 * self.radius).ceil() as usize + 2 * self.patch_margin;
        check(
            self.relax_patch_size >= min_patch && self.relax_patch_size < self.box_size,
            "relax_patch_size",
            self.relax_patch_size,
            format!("must be in [{min_patch}, {}): at least 2R + 2·patch_margin and below the box", self.box_size),
        )?;
        check(self.phi_min < 0.0 && self.phi_min.is_finite(), "phi_min", self.phi_min, "must be a finite number < 0")?;
        check(self.phi_max > 1.0 && self.phi_max.is_finite(), "phi_max", self.phi_max, "must be a finite number > 1")?;
        friction("xi_relax", self.xi_relax, false)?;
        Ok(())
    }

    /// The protocol: its steps, the initial placement and the time unit.
    fn check_protocol(&self) -> Result<(), ParamError> {
        // A billion steps is months of computing; the bound keeps their sum far from overflow.
        for (name, steps) in [("relax_steps", self.relax_steps), ("active_steps", self.active_steps)] {
            check(steps <= MAX_STEPS, name, steps, "must be in [0, 1000000000]")?;
        }
        check(
            self.initial_radius_fraction > 0.0 && self.initial_radius_fraction <= 1.0,
            "initial_radius_fraction",
            self.initial_radius_fraction,
            "must be in (0, 1]",
        )?;
        check(
            self.initial_gap.is_finite() && self.initial_gap >= 0.0,
            "initial_gap",
            self.initial_gap,
            "must be a finite number ≥ 0",
        )?;
        // Random sequential placement of exclusion disks jams near 55 % of the plane: ask for at
        // most half.
        let exclusion = self.initial_radius_fraction * self.radius + 0.5 * self.initial_gap;
        let fill = self.n_cells as f64 * core::f64::consts::PI * exclusion * exclusion
            / (self.box_size * self.box_size) as f64;
        check(
            fill <= 0.5,
            "n_cells",
            self.n_cells,
            format!(
                "{:.0} % of the box would be needed to place the initial disks apart (at most 50 %): lower \
                 n_cells, initial_radius_fraction or initial_gap",
                fill * 100.0
            ),
        )?;
        positive("time_unit_seconds", self.time_unit_seconds)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_papers_and_valid() {
        let p = Params::default();
        p.validate().unwrap();
        assert_eq!((p.box_size, p.n_cells, p.radius), (140, 100, 8.0));
        assert_eq!((p.lambda, p.gamma, p.kappa, p.mu, p.j0, p.dt), (2.0, 0.06, 0.5, 20.0, 1.0, 0.1));
        assert_eq!(p.relax_steps, 10_000);
        assert_eq!(p.active_steps, 100_000);
        // ζ = 0.5, χ = 0.001: the paper's persistent-hole point, so that `run` opens holes.
        assert_eq!(p.zeta, 0.5);
        assert!((p.chi() - 0.001).abs() < 1e-15);
        // The conventions the calibration chose (docs/calibration.md).
        assert_eq!((p.passive_force, p.friction_weights), (PassiveForce::GradMu, FrictionWeights::Subdomain));
        assert_eq!(p.q_magnitude, 0.5);
        // One site per time unit is 1,000 µm/h at 3.6 s per time unit, 720 µm/h at 5 s.
        assert_eq!(p.microns_per_hour(), 1000.0);
        assert_eq!(Params { time_unit_seconds: 5.0, ..p }.microns_per_hour(), 720.0);
    }

    #[test]
    fn errors_name_the_parameter_and_range() {
        let p = Params { dt: 0.0, ..Params::default() };
        let e = p.validate().unwrap_err();
        assert_eq!(e.name, "dt");
        assert!(e.to_string().contains("(0, 0.5]"), "{e}");

        let p = Params { n_cells: 300, ..Params::default() };
        let e = p.validate().unwrap_err();
        assert_eq!(e.name, "n_cells");
        assert!(e.to_string().contains("150 %"), "{e}");

        let p = Params { time_unit_seconds: 0.0, ..Params::default() };
        assert_eq!(p.validate().unwrap_err().name, "time_unit_seconds");

        let p = Params { relax_patch_size: 10, ..Params::default() };
        assert_eq!(p.validate().unwrap_err().name, "relax_patch_size");

        let p = Params { patch_margin: 1000, ..Params::default() };
        let e = p.validate().unwrap_err();
        assert!(e.name == "patch_margin" && e.to_string().contains("[2, 32]"), "{e}");

        let p = Params { active_steps: u64::MAX, ..Params::default() };
        assert_eq!(p.validate().unwrap_err().name, "active_steps");

        let p = Params { initial_gap: 6.0, ..Params::default() };
        let e = p.validate().unwrap_err();
        assert!(e.name == "n_cells" && e.to_string().contains("apart"), "{e}");

        // The stability bound names the factor given furthest above its default, printed short.
        let p = Params { gamma: 20.0, ..Params::default() };
        let e = p.validate().unwrap_err();
        assert_eq!(e.name, "gamma", "{e}");
        let p = Params { gamma: 1e308, ..Params::default() };
        let e = p.validate().unwrap_err().to_string();
        assert!(e.starts_with("parameter `gamma` = 1e308: J₀·2γλ·8·Δt = inf must be < 2"), "{e}");
        let p = Params { gamma: 0.2, dt: 0.5, ..Params::default() };
        assert_eq!(p.validate().unwrap_err().name, "dt", "Δt is 5 times its default, γ 3.3 times");
        assert_eq!(number_text(0.06), "0.06");
        assert_eq!(number_text(-1e-300), "-1e-300");
        assert_eq!(number_text(1e15), "1e15");
        assert_eq!(number_text(123456.5), "123456.5");
    }
}
