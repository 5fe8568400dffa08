//! The paper's regime criterion (Fig. 3c–d): an exponential survival fitted to hole lifetimes,
//! holes still open at the end counted as censored, and the three regimes it separates. Pure, so
//! the sweep, the figures and the page can all classify a run the same way.

/// The paper's three regimes (Fig. 3d).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Regime {
    NoHoles,
    OnlyShortLived,
    ShortAndLongLived,
}

impl Regime {
    pub fn name(self) -> &'static str {
        match self {
            Regime::NoHoles => "no_holes",
            Regime::OnlyShortLived => "only_short_lived",
            Regime::ShortAndLongLived => "short_and_long_lived",
        }
    }
}

/// Fits an exponential survival S(τ) = exp(−τ/τ_h) to hole lifetimes, holes still open at the end
/// counting as censored: the maximum-likelihood τ_h = (Σ durations) / (number closed), infinite
/// when none closed.
pub fn fitted_lifetime(lifetimes: &[(f64, bool)]) -> Option<f64> {
    if lifetimes.is_empty() {
        return None;
    }
    let total: f64 = lifetimes.iter().map(|l| l.0).sum();
    let closed = lifetimes.iter().filter(|l| l.1).count();
    Some(if closed == 0 { f64::INFINITY } else { total / closed as f64 })
}

/// The paper's criterion: no holes; else long-lived when the fitted lifetime exceeds half the
/// run's active time.
pub fn classify(lifetimes: &[(f64, bool)], active_time: f64) -> Regime {
    match fitted_lifetime(lifetimes) {
        None => Regime::NoHoles,
        Some(t) if t > 0.5 * active_time => Regime::ShortAndLongLived,
        Some(_) => Regime::OnlyShortLived,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regimes_follow_the_papers_criterion() {
        assert_eq!(classify(&[], 100.0), Regime::NoHoles);
        // Three holes closing after 5, 10, 15 of a run of 100: short-lived (τ = 10).
        assert_eq!(classify(&[(5.0, true), (10.0, true), (15.0, true)], 100.0), Regime::OnlyShortLived);
        // One closed after 10 and one open for 90: τ = 100 > 50.
        assert_eq!(classify(&[(10.0, true), (90.0, false)], 100.0), Regime::ShortAndLongLived);
        assert_eq!(fitted_lifetime(&[(30.0, false)]), Some(f64::INFINITY));
    }
}
