//! Plots of a run's analysis, each as PNG and SVG (plotters): hole areas against time, C_v(r)
//! and C_Q(r), and a snapshot like the paper's Fig. 1a–b: a chosen field as colours, cell
//! outlines at φ_i = ½, elongation axes, ±½ defects (+½ with a line towards its tail), spiral
//! cores and void sites.
//!
//! Both backends draw into memory and the files are written with [`crate::run::files::write_atomic`].
//! Text is laid out and rasterised by ab_glyph from DejaVu Sans embedded in the binary (crate
//! `dejavu`): no fontconfig and no system fonts are needed, so plots work on a headless machine.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Once;

use image::ImageEncoder;
use plotters::coord::combinators::LogCoord;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

use super::files::Frame;
use crate::analysis::{Analysis, Hole};
use crate::model::Cell;
use crate::run::error::RunError;
use crate::run::files::write_atomic;

pub(crate) const FONT: &str = "sans-serif";

/// Registers the embedded font under the family name the plots use (once per process).
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let ok = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok();
        assert!(ok, "the embedded DejaVu Sans font does not parse");
    });
}

pub(crate) fn plot_err(e: impl std::fmt::Display) -> RunError {
    RunError::Plot(e.to_string())
}

/// A generic drawing function usable with both backends.
pub(crate) trait Draw {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError>;
}

/// Draws `d` into `base.png` and `base.svg`, each written atomically.
pub(crate) fn both_of(base: &Path, size: (u32, u32), d: &impl Draw) -> Result<Vec<PathBuf>, RunError> {
    register_font();
    let png = base.with_extension("png");
    let svg = base.with_extension("svg");
    let (w, h) = size;
    let mut pixels = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        d.draw(&root)?;
        root.present().map_err(plot_err)?;
    }
    write_atomic(&png, |out| {
        image::codecs::png::PngEncoder::new(out)
            .write_image(&pixels, w, h, image::ColorType::Rgb8)
            .map_err(|e| RunError::file(&png, e))
    })?;
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        d.draw(&root)?;
        root.present().map_err(plot_err)?;
    }
    write_atomic(&svg, |out| out.write_all(text.as_bytes()).map_err(|e| RunError::io(&svg, e)))?;
    Ok(vec![png, svg])
}

/// The series legend, in the same style on every plot.
fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
) -> Result<(), RunError> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font((FONT, 14))
        .draw()
        .map_err(plot_err)
}

/// Colours of the plots' series (matplotlib's first eight), shared by `analyze`, the sweep and
/// the figures.
pub(crate) const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
];

struct HoleAreas<'a>(&'a [Hole]);

impl Draw for HoleAreas<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
        root.fill(&WHITE).map_err(plot_err)?;
        let holes = self.0;
        let t = |f: fn(f64, f64) -> f64, init: f64| holes.iter().flat_map(|h| &h.history).map(|p| p.0).fold(init, f);
        let (t0, t1) = if holes.is_empty() { (0.0, 1.0) } else { (t(f64::min, f64::MAX), t(f64::max, f64::MIN)) };
        let t1 = if t1 > t0 { t1 } else { t0 + 1.0 };
        let amax = holes.iter().map(|h| h.max_area()).max().unwrap_or(1).max(1) as f64 * 1.1;
        let caption = if holes.is_empty() { "Hole area: no holes".to_string() } else { "Hole area".to_string() };
        let mut chart = ChartBuilder::on(root)
            .caption(caption, (FONT, 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, 0.0..amax)
            .map_err(plot_err)?;
        chart.configure_mesh().x_desc("time").y_desc("area (sites)").draw().map_err(plot_err)?;
        for (k, h) in holes.iter().enumerate() {
            let c = PALETTE[k % PALETTE.len()];
            let pts: Vec<(f64, f64)> = h.history.iter().map(|p| (p.0, p.1 as f64)).collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                .map_err(plot_err)?
                .label(format!("hole {} ({})", h.id, h.fate()))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
            chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 3, c.filled()))).map_err(plot_err)?;
        }
        if !holes.is_empty() {
            draw_legend(&mut chart)?;
        }
        Ok(())
    }
}

/// Area of every hole against time: `base.png`, `base.svg`.
pub fn hole_areas(base: &Path, holes: &[Hole]) -> Result<Vec<PathBuf>, RunError> {
    both_of(base, (900, 600), &HoleAreas(holes))
}

struct Correlations<'a> {
    cv: &'a [f64],
    cq: &'a [f64],
    lengths: (Option<f64>, Option<f64>),
    frames: usize,
}

impl Draw for Correlations<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
        root.fill(&WHITE).map_err(plot_err)?;
        let rmax = self.cv.len().saturating_sub(1).max(1) as f64;
        let lo = self.cv.iter().chain(self.cq).copied().filter(|v| v.is_finite()).fold(0.0, f64::min);
        let mut chart = ChartBuilder::on(root)
            .caption(format!("Correlations (mean of {} frames)", self.frames), (FONT, 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..rmax, (lo - 0.05)..1.05)
            .map_err(plot_err)?;
        chart.configure_mesh().x_desc("r (sites)").y_desc("C(r)").draw().map_err(plot_err)?;
        let e = (-1.0f64).exp();
        chart
            .draw_series(LineSeries::new(vec![(0.0, e), (rmax, e)], BLACK.mix(0.4)))
            .map_err(plot_err)?
            .label("1/e")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.4)));
        let fmt = |l: Option<f64>| l.map(|v| format!("{v:.1}")).unwrap_or_else(|| "> L/2".into());
        let series = [(self.cv, "C_v", PALETTE[0], self.lengths.0), (self.cq, "C_Q", PALETTE[3], self.lengths.1)];
        for (c, name, colour, len) in series {
            let pts = c.iter().enumerate().filter(|(_, v)| v.is_finite()).map(|(r, &v)| (r as f64, v));
            chart
                .draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                .map_err(plot_err)?
                .label(format!("{name}(r), length {}", fmt(len)))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        }
        draw_legend(&mut chart)?;
        Ok(())
    }
}

/// C_v(r), C_Q(r) and the 1/e line: `base.png`, `base.svg`.
pub fn correlations(
    base: &Path,
    cv: &[f64],
    cq: &[f64],
    lengths: (Option<f64>, Option<f64>),
    frames: usize,
) -> Result<Vec<PathBuf>, RunError> {
    both_of(base, (900, 600), &Correlations { cv, cq, lengths, frames })
}

/// The field drawn under a snapshot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Background {
    /// ε̇ = ∇·v/2 of the smoothed velocity, over its largest magnitude (Fig. 1b, velocity).
    StrainRate,
    /// ∇·f^a of the smoothed active force, over its largest magnitude (Fig. 1b, force).
    ActiveForceDivergence,
    /// |v| of the smoothed velocity, over its largest value.
    Speed,
}

/// A diverging colour for t ∈ [−1, 1]: blue, white, red.
fn diverging(t: f64) -> RGBColor {
    let t = t.clamp(-1.0, 1.0);
    let (end, s) = if t < 0.0 { ((59.0, 76.0, 192.0), -t) } else { ((180.0, 4.0, 38.0), t) };
    let mix = |a: f64| (255.0 + (a - 255.0) * s).round() as u8;
    RGBColor(mix(end.0), mix(end.1), mix(end.2))
}

/// Segments of the φ = ½ contour of one cell (marching squares on its padded patch, the zero
/// halo closing the outline), in lattice coordinates.
fn outline(patch: crate::model::Patch, phi: &[f64], l: usize) -> Vec<[(f64, f64); 2]> {
    let s = patch.stride();
    let rows = patch.h + 2;
    let mut segs = Vec::new();
    let level = 0.5;
    for j in 0..rows - 1 {
        for i in 0..s - 1 {
            // Corners counter-clockwise from (i, j).
            let v = [phi[j * s + i], phi[j * s + i + 1], phi[(j + 1) * s + i + 1], phi[(j + 1) * s + i]];
            let corner = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)];
            let mut cuts = Vec::with_capacity(4);
            for e in 0..4 {
                let (a, b) = (v[e], v[(e + 1) % 4]);
                if (a >= level) != (b >= level) {
                    let t = (level - a) / (b - a);
                    let (p, q) = (corner[e], corner[(e + 1) % 4]);
                    cuts.push((p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1)));
                }
            }
            // Padded (i, j) is patch site (i − 1, j − 1); place the square on the lattice.
            let ox = ((patch.x0 + i + l - 1) % l) as f64;
            let oy = ((patch.y0 + j + l - 1) % l) as f64;
            let at = |c: (f64, f64)| (ox + c.0, oy + c.1);
            // Two cuts: one segment; four (a saddle): pair them in order.
            for pair in cuts.chunks_exact(2) {
                segs.push([at(pair[0]), at(pair[1])]);
            }
        }
    }
    segs
}

struct Snapshot<'a> {
    frame: &'a Frame,
    a: &'a Analysis,
    background: Background,
}

impl Draw for Snapshot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
        let (a, frame) = (self.a, self.frame);
        let l = a.l;
        let lf = l as f64;
        root.fill(&WHITE).map_err(plot_err)?;
        let (field, name): (Vec<f64>, &str) = match self.background {
            Background::StrainRate => (a.strain_rate.clone(), "strain rate ε̇/max|ε̇|"),
            Background::ActiveForceDivergence => (a.active_force_divergence.clone(), "∇·f^a / max|∇·f^a|"),
            Background::Speed => {
                (a.smooth.vx.iter().zip(&a.smooth.vy).map(|(x, y)| x.hypot(*y)).collect(), "speed |v|/max|v|")
            }
        };
        let scale = field.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(f64::MIN_POSITIVE);
        let caption = format!("step {}, t = {}: {name}", frame.data.step, frame.data.time);
        let mut chart = ChartBuilder::on(root)
            .caption(caption, (FONT, 20))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..lf, 0.0..lf)
            .map_err(plot_err)?;
        chart.configure_mesh().disable_mesh().draw().map_err(plot_err)?;
        // Colours per site; void sites (Σφ < 0.01) black.
        let void = &a.voids.labels;
        chart
            .draw_series((0..l * l).map(|k| {
                let (x, y) = ((k % l) as f64, (k / l) as f64);
                let colour = if void[k] != u32::MAX { BLACK } else { diverging(field[k] / scale) };
                Rectangle::new([(x, y), (x + 1.0, y + 1.0)], colour.filled())
            }))
            .map_err(plot_err)?;
        // Outlines at φ = ½ and elongation axes through the centres.
        for ((patch, phi), q) in frame.data.cells.iter().zip(&frame.data.q_hat) {
            chart
                .draw_series(outline(*patch, phi, l).into_iter().map(|s| PathElement::new(s.to_vec(), BLACK)))
                .map_err(plot_err)?;
            let [cx, cy] = Cell::new(*patch, phi.clone()).centre(l);
            let th = 0.5 * q[1].atan2(q[0]);
            let r = 0.5 * a.radius;
            let (dx, dy) = (r * th.cos(), r * th.sin());
            // Offsets of ±0.5 put the axis on the site centres the colours are drawn at.
            let p = |s: f64| (cx + 0.5 + s * dx, cy + 0.5 + s * dy);
            chart
                .draw_series(std::iter::once(PathElement::new(vec![p(-1.0), p(1.0)], BLACK.stroke_width(2))))
                .map_err(plot_err)?;
        }
        let green = RGBColor(0, 170, 0);
        for d in &a.defects {
            let c = (d.x + 0.5, d.y + 0.5);
            if d.twice_charge > 0 {
                let tail = (c.0 + a.radius * d.orientation.cos(), c.1 + a.radius * d.orientation.sin());
                chart.draw_series(std::iter::once(Circle::new(c, 5, green.filled()))).map_err(plot_err)?;
                chart
                    .draw_series(std::iter::once(PathElement::new(vec![c, tail], green.stroke_width(3))))
                    .map_err(plot_err)?;
            } else {
                chart.draw_series(std::iter::once(TriangleMarker::new(c, 6, BLUE.filled()))).map_err(plot_err)?;
            }
        }
        let cyan = RGBColor(0, 200, 220);
        for s in a.spiral_cores() {
            let c = (s.x + 0.5, s.y + 0.5);
            chart.draw_series(std::iter::once(Cross::new(c, 7, cyan.stroke_width(3)))).map_err(plot_err)?;
            chart.draw_series(std::iter::once(Circle::new(c, 7, cyan.stroke_width(2)))).map_err(plot_err)?;
        }
        Ok(())
    }
}

/// The frame's cells, defects, spiral cores and holes over a field: `base.png`, `base.svg`.
/// `a` must hold the measurements of `frame`.
pub fn snapshot(base: &Path, frame: &Frame, a: &Analysis, background: Background) -> Result<Vec<PathBuf>, RunError> {
    both_of(base, (900, 930), &Snapshot { frame, a, background })
}

/// One grid point of a regime map (the paper's Fig. 3d), drawn as the paper draws it: no holes a
/// red circle, only short-lived holes a blue square, short- and long-lived a green triangle; a
/// cross over a point where a run failed. Shared by the sweep's map and the figures'.
pub(crate) fn regime_marker<DB: DrawingBackend>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<LogCoord<f64>, RangedCoordf64>>,
    (x, y): (f64, f64),
    regime: crate::analysis::Regime,
    failed: bool,
) -> Result<(), RunError> {
    use crate::analysis::Regime;
    let (red, blue, green) = (PALETTE[3], PALETTE[0], PALETTE[2]);
    match regime {
        Regime::NoHoles => chart.draw_series(std::iter::once(Circle::new((x, y), 7, red.filled()))),
        Regime::OnlyShortLived => chart
            .draw_series(std::iter::once(EmptyElement::at((x, y)) + Rectangle::new([(-7, -7), (7, 7)], blue.filled()))),
        Regime::ShortAndLongLived => chart.draw_series(std::iter::once(
            EmptyElement::at((x, y)) + Polygon::new(vec![(0, -8), (-8, 7), (8, 7)], green.filled()),
        )),
    }
    .map_err(plot_err)?;
    if failed {
        let cross = EmptyElement::at((x, y)) + Cross::new((0, 0), 10, BLACK.stroke_width(2));
        chart.draw_series(std::iter::once(cross)).map_err(plot_err)?;
    }
    Ok(())
}

/// The fields about a nucleation site in one frame, as the paper's Fig. 1b draws them: the
/// velocity over the strain rate (spiral cores as cyan stars), the active force over its
/// divergence, and the director over the strain rate with the ±½ defects (+½ green with a line
/// to its tail, −½ blue). Smoothed fields (the 2R window), each colour over its largest
/// magnitude in the view; void sites black; the coming nucleation site a black ring.
struct NucleationFields<'a> {
    a: &'a Analysis,
    centre: (f64, f64),
    caption: String,
}

impl NucleationFields<'_> {
    /// View coordinates of lattice point (x, y): the periodic image nearest the centre.
    fn unwrap(&self, x: f64, y: f64) -> (f64, f64) {
        let lf = self.a.l as f64;
        let near = |v: f64, c: f64| c + (v - c + lf / 2.0).rem_euclid(lf) - lf / 2.0;
        (near(x, self.centre.0), near(y, self.centre.1))
    }
}

impl Draw for NucleationFields<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
        let a = self.a;
        let l = a.l;
        let half = 4.0 * a.radius;
        let (cx, cy) = self.centre;
        root.fill(&WHITE).map_err(plot_err)?;
        let (title, body) = root.split_vertically(40);
        title.draw(&Text::new(self.caption.clone(), (10, 10), (FONT, 20).into_font())).map_err(plot_err)?;
        let panels = body.split_evenly((1, 3));
        let s = &a.smooth;
        let in_view: Vec<usize> = (0..l * l)
            .filter(|&k| {
                let (x, y) = self.unwrap((k % l) as f64, (k / l) as f64);
                (x - cx).abs() <= half && (y - cy).abs() <= half
            })
            .collect();
        let scale_of = |f: &[f64]| in_view.iter().fold(0.0f64, |m, &k| m.max(f[k].abs())).max(f64::MIN_POSITIVE);
        let kinds = [("velocity, ε̇ / max", 0), ("active force, ∇·f^a / max", 1), ("director, ε̇ / max", 2)];
        for (panel, (name, kind)) in panels.iter().zip(kinds) {
            let colour_field: &[f64] = if kind == 1 { &a.active_force_divergence } else { &a.strain_rate };
            let scale = scale_of(colour_field);
            let mut chart = ChartBuilder::on(panel)
                .caption(name, (FONT, 18))
                .margin(8)
                .x_label_area_size(25)
                .y_label_area_size(35)
                .build_cartesian_2d(cx - half..cx + half + 1.0, cy - half..cy + half + 1.0)
                .map_err(plot_err)?;
            chart.configure_mesh().disable_mesh().draw().map_err(plot_err)?;
            chart
                .draw_series(in_view.iter().map(|&k| {
                    let (x, y) = self.unwrap((k % l) as f64, (k / l) as f64);
                    let c = if a.voids.labels[k] != u32::MAX { BLACK } else { diverging(colour_field[k] / scale) };
                    Rectangle::new([(x, y), (x + 1.0, y + 1.0)], c.filled())
                }))
                .map_err(plot_err)?;
            // Arrows (velocity, force) or director lines every third site.
            let sparse = in_view.iter().copied().filter(|&k| (k % l).is_multiple_of(3) && (k / l).is_multiple_of(3));
            let (ax, ay): (&[f64], &[f64]) = if kind == 1 { (&s.fx, &s.fy) } else { (&s.vx, &s.vy) };
            let amax = in_view.iter().fold(0.0f64, |m, &k| m.max(ax[k].hypot(ay[k]))).max(f64::MIN_POSITIVE);
            for k in sparse {
                let (x, y) = self.unwrap((k % l) as f64, (k / l) as f64);
                let c = (x + 0.5, y + 0.5);
                let seg = if kind == 2 {
                    let th = 0.5 * s.qxy[k].atan2(s.qxx[k]);
                    let (dx, dy) = (1.3 * th.cos(), 1.3 * th.sin());
                    vec![(c.0 - dx, c.1 - dy), (c.0 + dx, c.1 + dy)]
                } else {
                    let f = 2.8 / amax;
                    vec![c, (c.0 + f * ax[k], c.1 + f * ay[k])]
                };
                chart.draw_series(std::iter::once(PathElement::new(seg, BLACK.stroke_width(1)))).map_err(plot_err)?;
            }
            let cyan = RGBColor(0, 200, 220);
            for p in a.spiral_cores() {
                let c = self.unwrap(p.x + 0.5, p.y + 0.5);
                chart.draw_series(std::iter::once(Cross::new(c, 7, cyan.stroke_width(3)))).map_err(plot_err)?;
            }
            if kind == 2 {
                let green = RGBColor(0, 170, 0);
                for d in &a.defects {
                    let c = self.unwrap(d.x + 0.5, d.y + 0.5);
                    if d.twice_charge > 0 {
                        let tail =
                            (c.0 + 0.6 * a.radius * d.orientation.cos(), c.1 + 0.6 * a.radius * d.orientation.sin());
                        chart.draw_series(std::iter::once(Circle::new(c, 5, green.filled()))).map_err(plot_err)?;
                        chart
                            .draw_series(std::iter::once(PathElement::new(vec![c, tail], green.stroke_width(3))))
                            .map_err(plot_err)?;
                    } else {
                        chart
                            .draw_series(std::iter::once(TriangleMarker::new(c, 6, BLUE.filled())))
                            .map_err(plot_err)?;
                    }
                }
            }
            chart
                .draw_series(std::iter::once(Circle::new((cx + 0.5, cy + 0.5), 10, BLACK.stroke_width(2))))
                .map_err(plot_err)?;
        }
        Ok(())
    }
}

/// The paper's Fig. 1b about (x, y) in the frame `a` measured: `base.png`, `base.svg`.
pub fn nucleation_fields(
    base: &Path,
    a: &Analysis,
    site: (f64, f64),
    caption: String,
) -> Result<Vec<PathBuf>, RunError> {
    both_of(base, (1500, 560), &NucleationFields { a, centre: site, caption })
}
