//! The regime map like the paper's Fig. 3d, as PNG and SVG.

use std::path::{Path, PathBuf};

use super::tables::RegimePoint;
use crate::analysis::Regime;
use crate::run::error::RunError;

/// The regime map like the paper's Fig. 3d, χ (log scale) against ζ: red circles no holes, blue
/// squares only short-lived, green triangles short- and long-lived; a cross where a run blew up.
/// Drawn only when the grid varies both `chi` and `zeta`.
pub(super) fn plot_regime_map(base: &Path, points: &[RegimePoint]) -> Result<Vec<PathBuf>, RunError> {
    use crate::run::plots::{both_of, plot_err, regime_marker, Draw, FONT};
    use plotters::coord::Shift;
    use plotters::prelude::*;

    let get = |p: &RegimePoint, k: &str| p.values.iter().find(|v| v.0 == k).and_then(|v| v.1.parse::<f64>().ok());
    let xy: Vec<(f64, f64, Regime, bool)> =
        points.iter().filter_map(|p| Some((get(p, "chi")?, get(p, "zeta")?, p.regime, p.blew_up > 0))).collect();
    if xy.len() < 2 || xy.iter().any(|p| p.0 <= 0.0) {
        return Ok(Vec::new());
    }
    struct Map(Vec<(f64, f64, Regime, bool)>);
    impl Draw for Map {
        fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
            root.fill(&WHITE).map_err(plot_err)?;
            let f = |g: fn(f64, f64) -> f64, i: fn(&(f64, f64, Regime, bool)) -> f64, init| {
                self.0.iter().map(i).fold(init, g)
            };
            let (x0, x1) = (f(f64::min, |p| p.0, f64::MAX) / 2.0, f(f64::max, |p| p.0, 0.0) * 2.0);
            let (y0, y1) = (f(f64::min, |p| p.1, f64::MAX), f(f64::max, |p| p.1, f64::MIN));
            let pad = ((y1 - y0) * 0.15).max(0.05);
            let mut chart = ChartBuilder::on(root)
                .caption("Regime map", (FONT, 22))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(50)
                .build_cartesian_2d((x0..x1).log_scale(), (y0 - pad)..(y1 + pad))
                .map_err(plot_err)?;
            chart.configure_mesh().x_desc("χ = ξ_s / ξ_cell").y_desc("ζ").draw().map_err(plot_err)?;
            for &(x, y, regime, blew_up) in &self.0 {
                regime_marker(&mut chart, (x, y), regime, blew_up)?;
            }
            Ok(())
        }
    }
    both_of(base, (640, 480), &Map(xy))
}
