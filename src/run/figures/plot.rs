//! The figures' plots, drawn by the figures stage ([`super::draw`]): one or two panels of series
//! (points with error bars, lines), and the regime map; PNG and SVG through [`crate::run::plots`]
//! (embedded font, atomic).

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::analysis::Regime;
use crate::run::error::RunError;
use crate::run::plots::{self, both_of, plot_err, regime_marker, Draw, FONT};

/// The first six of the shared palette: the figures cycle through six colours.
const PALETTE: &[RGBColor] = plots::PALETTE.split_at(6).0;

/// How a series marks its points (the paper tells χ apart by filled, faint and empty symbols).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marker {
    None,
    Filled,
    Faint,
    Empty,
}

#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text; empty: not in the legend.
    pub label: String,
    pub colour: usize,
    /// (x, y, standard error; 0 for none).
    pub points: Vec<(f64, f64, f64)>,
    pub line: bool,
    pub marker: Marker,
}

impl Series {
    pub fn new(label: impl Into<String>, colour: usize) -> Self {
        Series { label: label.into(), colour, points: Vec::new(), line: false, marker: Marker::Filled }
    }

    pub fn push(&mut self, x: f64, y: f64, err: f64) {
        self.points.push((x, y, err));
    }
}

#[derive(Clone, Debug)]
pub struct Panel {
    pub title: String,
    pub x: String,
    pub y: String,
    pub log_y: bool,
    /// The y axis starts at 0 (counts, distances, survival).
    pub y_from_zero: bool,
    /// A dotted horizontal line (1/e on the correlations).
    pub hline: Option<f64>,
    /// The line's legend.
    pub hline_label: String,
    /// A fixed x range (the precursors' 10 frames), else the data's.
    pub x_range: Option<(f64, f64)>,
    pub series: Vec<Series>,
}

impl Panel {
    pub fn new(title: &str, x: &str, y: &str) -> Self {
        Panel {
            title: title.into(),
            x: x.into(),
            y: y.into(),
            log_y: false,
            y_from_zero: false,
            hline: None,
            hline_label: "1/e".into(),
            x_range: None,
            series: Vec::new(),
        }
    }

    fn shown(&self) -> impl Iterator<Item = &(f64, f64, f64)> {
        self.series
            .iter()
            .flat_map(|s| &s.points)
            .filter(|p| p.0.is_finite() && p.1.is_finite() && (!self.log_y || p.1 > 0.0))
    }

    /// The axes' ranges, with room at the top for the legend (drawn in the upper right, where it
    /// would otherwise hide the points there).
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let entries = self.series.iter().filter(|s| !s.label.is_empty()).count() + self.hline.is_some() as usize;
        // The legend's share of a 500-pixel-high panel's plotting area, about 400 pixels.
        let share = if entries > 0 { ((entries * 17 + 14) as f64 / 400.0).min(0.6) } else { 0.0 };
        let room = share / (1.0 - share);
        let fold = |f: fn(&(f64, f64, f64)) -> f64, g: fn(f64, f64) -> f64, init| self.shown().map(f).fold(init, g);
        let (mut x0, mut x1) = (fold(|p| p.0, f64::min, f64::MAX), fold(|p| p.0, f64::max, f64::MIN));
        let (mut y0, mut y1) = (fold(|p| p.1 - p.2, f64::min, f64::MAX), fold(|p| p.1 + p.2, f64::max, f64::MIN));
        if let Some(r) = self.x_range {
            (x0, x1) = r;
        } else if x0 > x1 {
            (x0, x1) = (0.0, 1.0);
        }
        if x1 - x0 < 1e-12 {
            (x0, x1) = (x0 - 0.5 * x0.abs().max(1.0), x1 + 0.5 * x1.abs().max(1.0));
        }
        if let Some(h) = self.hline {
            y0 = y0.min(h);
            y1 = y1.max(h);
        }
        if self.log_y {
            let lo = self.shown().map(|p| p.1).fold(f64::MAX, f64::min);
            let hi = self.shown().map(|p| p.1).fold(f64::MIN, f64::max);
            if lo > hi {
                return ((x0, x1), (1e-6, 1.0));
            }
            let (lo, hi) = (lo / 2.0, (hi * 2.0).max(lo * 10.0));
            return ((x0, x1 + 0.02 * (x1 - x0)), (lo, hi * (hi / lo).powf(room)));
        }
        if y0 > y1 {
            (y0, y1) = (0.0, 1.0);
        }
        if self.y_from_zero {
            y0 = y0.min(0.0);
        }
        let pad = ((y1 - y0) * 0.08).max(1e-9);
        let xpad = (x1 - x0) * 0.04;
        let bottom = if self.y_from_zero && y0 >= 0.0 { 0.0 } else { y0 - pad };
        ((x0 - xpad, x1 + xpad), (bottom, y1 + pad + (y1 + pad - bottom) * room))
    }
}

fn colour(s: &Series) -> RGBColor {
    PALETTE[s.colour % PALETTE.len()]
}

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel) -> Result<(), RunError> {
    let ((x0, x1), (y0, y1)) = p.ranges();
    let (caption, label) = (20, 14);
    let mut builder = ChartBuilder::on(area);
    builder.margin(12).x_label_area_size(40).y_label_area_size(64);
    if !p.title.is_empty() {
        builder.caption(&p.title, (FONT, caption));
    }
    macro_rules! body {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(p.x.as_str())
                .y_desc(p.y.as_str())
                .label_style((FONT, label))
                .x_labels(10)
                .y_labels(10)
                .y_label_formatter(&|v: &f64| {
                    if p.log_y {
                        format!("{v:.0e}")
                    } else {
                        format!("{}", (v * 1e6).round() / 1e6)
                    }
                })
                .light_line_style(WHITE.mix(0.0))
                .draw()
                .map_err(plot_err)?;
            if let Some(h) = p.hline {
                chart
                    .draw_series(LineSeries::new(vec![(x0, h), (x1, h)], BLACK.mix(0.4)))
                    .map_err(plot_err)?
                    .label(p.hline_label.as_str())
                    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.4)));
            }
            let mut labelled = false;
            for s in &p.series {
                let c = colour(s);
                let pts: Vec<(f64, f64, f64)> = s
                    .points
                    .iter()
                    .copied()
                    .filter(|q| q.0.is_finite() && q.1.is_finite() && (!p.log_y || q.1 > 0.0))
                    .collect();
                if s.line {
                    // A faint series (a chance line) is drawn faint and thin, so it reads apart
                    // from the measured curve of the same colour.
                    let style = if s.marker == Marker::Faint { c.mix(0.45).stroke_width(1) } else { c.stroke_width(2) };
                    let a =
                        chart.draw_series(LineSeries::new(pts.iter().map(|q| (q.0, q.1)), style)).map_err(plot_err)?;
                    if !s.label.is_empty() && s.marker == Marker::None {
                        labelled = true;
                        a.label(&s.label)
                            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                    }
                }
                for q in pts.iter().filter(|q| q.2 > 0.0) {
                    let lo = if p.log_y { (q.1 - q.2).max(q.1 * 0.1) } else { q.1 - q.2 };
                    chart
                        .draw_series(std::iter::once(PathElement::new(vec![(q.0, lo), (q.0, q.1 + q.2)], c)))
                        .map_err(plot_err)?;
                }
                let style = match s.marker {
                    Marker::None => continue,
                    Marker::Filled => c.filled(),
                    Marker::Faint => c.mix(0.35).filled(),
                    Marker::Empty => c.stroke_width(2),
                };
                let a = chart.draw_series(pts.iter().map(|q| Circle::new((q.0, q.1), 4, style))).map_err(plot_err)?;
                if !s.label.is_empty() {
                    labelled = true;
                    a.label(&s.label).legend(move |(x, y)| Circle::new((x + 10, y), 4, style));
                }
            }
            if p.series.iter().all(|s| s.points.is_empty()) {
                let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
                chart
                    .draw_series(std::iter::once(Text::new("no data at this scale", (cx, cy), (FONT, 16))))
                    .map_err(plot_err)?;
            }
            if labelled {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperRight)
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .label_font((FONT, 12))
                    .draw()
                    .map_err(plot_err)?;
            }
        }};
    }
    if p.log_y {
        body!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale()).map_err(plot_err)?);
    } else {
        body!(builder.build_cartesian_2d(x0..x1, y0..y1).map_err(plot_err)?);
    }
    Ok(())
}

struct Panels<'a> {
    panels: &'a [Panel],
}

impl Draw for Panels<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
        root.fill(&WHITE).map_err(plot_err)?;
        let areas = root.split_evenly((1, self.panels.len().max(1)));
        for (area, p) in areas.iter().zip(self.panels) {
            draw_panel(area, p)?;
        }
        Ok(())
    }
}

/// One or more panels side by side: `base.png`, `base.svg`.
pub fn panels(base: &Path, panels: &[Panel]) -> Result<Vec<PathBuf>, RunError> {
    let w = 640 * panels.len().max(1) as u32;
    both_of(base, (w, 500), &Panels { panels })
}

struct RegimeMap<'a>(&'a [(f64, f64, Regime, bool)]);

impl Draw for RegimeMap<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
        root.fill(&WHITE).map_err(plot_err)?;
        let xs = self.0.iter().map(|p| p.0);
        let (x0, x1) = if self.0.is_empty() {
            (0.001, 0.1)
        } else {
            (xs.clone().fold(f64::MAX, f64::min), xs.fold(0.0, f64::max))
        };
        let ys = self.0.iter().map(|p| p.1);
        let (y0, y1) = if self.0.is_empty() {
            (0.3, 0.5)
        } else {
            (ys.clone().fold(f64::MAX, f64::min), ys.fold(f64::MIN, f64::max))
        };
        let pad = ((y1 - y0) * 0.15).max(0.05);
        let mut chart = ChartBuilder::on(root)
            .caption("Fig. 3d: regimes", (FONT, 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d((x0 / 2.0..x1 * 2.0).log_scale(), (y0 - pad)..(y1 + pad))
            .map_err(plot_err)?;
        chart.configure_mesh().x_desc("χ = ξ_s / ξ_cell").y_desc("ζ").draw().map_err(plot_err)?;
        for &(x, y, regime, failed) in self.0 {
            regime_marker(&mut chart, (x, y), regime, failed)?;
        }
        Ok(())
    }
}

/// The regime map (χ log scale against ζ): red circles no holes, blue squares only short-lived,
/// green triangles short- and long-lived, a cross where a run failed.
pub fn regime_map(base: &Path, cells: &[(f64, f64, Regime, bool)]) -> Result<Vec<PathBuf>, RunError> {
    both_of(base, (640, 500), &RegimeMap(cells))
}
