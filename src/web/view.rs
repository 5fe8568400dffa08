//! The data the shaders draw, built on the CPU from the core's fields after each batch of steps:
//! per site the two cells with the largest φ (for colours and φ = ½ outlines), per site the
//! chosen field, and line segments (elongation axes, velocity arrows, director).
//!
//! Everything here reads the core through its public accessors, and the derived fields (strain
//! rate, active-force divergence, nematic field and its ±½ defects) come from
//! [`crate::analysis`], the same code as the offline analysis: nothing is computed a second way.

use bytemuck::{Pod, Zeroable};

use crate::analysis::defects::{Defect, DefectFinder};
use crate::analysis::fields::{divergence, strain_rate, CoarseFields};
use crate::Monolayer;

/// Which field the page shows under the cells' outlines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldKind {
    /// Cells in their own colours, outlines and elongation axes.
    Tissue,
    /// Σ_i φ_i.
    PhiSum,
    /// |Σ_i φ_i v_i| with velocity arrows.
    Speed,
    /// |Σ_i φ_i Q̂_i| with the director as headless segments, and the ±½ defects.
    Director,
    /// Isotropic strain rate ε̇ = ∇·v/2 of the smoothed velocity (paper Fig. 2), with defects.
    StrainRate,
    /// ∇·f^a of the smoothed active force, with defects.
    ForceDivergence,
}

impl FieldKind {
    pub fn from_name(name: &str) -> Option<FieldKind> {
        Some(match name {
            "tissue" => FieldKind::Tissue,
            "phi" => FieldKind::PhiSum,
            "speed" => FieldKind::Speed,
            "director" => FieldKind::Director,
            "strain" => FieldKind::StrainRate,
            "activediv" => FieldKind::ForceDivergence,
            _ => return None,
        })
    }
}

/// One line segment in lattice coordinates, drawn as a quad `width` device pixels wide.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct Segment {
    pub a: [f32; 2],
    pub b: [f32; 2],
    /// sRGB colour and alpha (the shader converts to the surface's space).
    pub colour: [f32; 4],
    pub width: f32,
    pub _pad: [f32; 3],
}

/// The frame's data: textures as f32 RGBA texels (L×L, row-major, y down), segments, and the
/// colour range of the field.
#[derive(Default)]
pub struct ViewData {
    pub l: usize,
    /// (key₁, φ₁, key₂, φ₂): colour keys (0 = no cell) and φ of the two largest φ_i.
    pub tissue: Vec<[f32; 4]>,
    /// (field value, substrate multiplier, 0, 0).
    pub field: Vec<[f32; 4]>,
    pub segments: Vec<Segment>,
    /// Colour range of the field (min, max) as drawn and labelled on the colour bar.
    pub range: (f32, f32),
    /// Running maximum that sets the range of speed and of the signed fields, smoothed so that
    /// the colours do not flicker.
    scale: f64,
    /// Raw and smoothed coarse-grained fields, scratch, defects (reused between frames).
    coarse: Option<(CoarseFields, CoarseFields)>,
    row: Vec<f64>,
    tmp: Vec<f64>,
    signed: Vec<f64>,
    finder: DefectFinder,
    pub defects: Vec<Defect>,
    last_kind: Option<FieldKind>,
}

const WHITE: [f32; 4] = [1.0, 1.0, 1.0, 0.9];
const ARROW: [f32; 4] = [1.0, 1.0, 1.0, 0.85];
/// +½ defects in orange, −½ in cyan (both readable on the colormaps).
const PLUS_HALF: [f32; 4] = [1.0, 0.6, 0.1, 1.0];
const MINUS_HALF: [f32; 4] = [0.2, 0.9, 1.0, 1.0];

impl ViewData {
    /// Rebuilds everything for `kind`. `keys[i]` is cell i's colour key (stable when a cell is
    /// removed, so the other cells keep their colours).
    pub fn build(&mut self, m: &mut Monolayer, keys: &[u32], kind: FieldKind, dpr: f32) {
        let l = m.params().box_size;
        self.l = l;
        if self.last_kind != Some(kind) {
            self.scale = 0.0; // a new field: its own range
            self.last_kind = Some(kind);
        }
        self.build_tissue(m, keys, l);
        self.segments.clear();
        let substrate = &m.lattice().substrate;
        self.field.clear();
        self.field.extend(substrate.iter().map(|&s| [0.0, s as f32, 0.0, 0.0]));
        match kind {
            FieldKind::Tissue => {
                self.range = (0.0, 1.0);
                self.elongation_axes(m, dpr);
            }
            FieldKind::PhiSum => {
                let phi_sum = m.phi_sum();
                for (f, &s) in self.field.iter_mut().zip(phi_sum) {
                    f[0] = s as f32;
                }
                self.range = (0.0, 1.2);
            }
            FieldKind::Speed => self.speed(m, l, dpr),
            FieldKind::Director => {
                self.director(m, l, dpr);
                self.defect_marks(dpr);
            }
            FieldKind::StrainRate | FieldKind::ForceDivergence => {
                self.coarse_fields(m, l);
                let (_, smooth) = self.coarse.as_ref().expect("built by coarse_fields");
                self.signed.resize(l * l, 0.0);
                if kind == FieldKind::StrainRate {
                    strain_rate(&smooth.vx, &smooth.vy, &mut self.signed, l);
                } else {
                    divergence(&smooth.fx, &smooth.fy, &mut self.signed, l, 1.0);
                }
                let top = self.signed.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                let s = self.follow_scale(top) as f32;
                for (f, &v) in self.field.iter_mut().zip(&self.signed) {
                    f[0] = v as f32;
                }
                self.range = (-s, s);
                self.defect_marks(dpr);
            }
        }
    }

    /// The range follows the largest value, rising at once and falling slowly.
    fn follow_scale(&mut self, top: f64) -> f64 {
        self.scale = if top > self.scale { top } else { 0.97 * self.scale + 0.03 * top };
        self.scale.max(1e-6)
    }

    /// Eq. S4's fields (velocity, active force, nematic) gathered from the cells, smoothed over
    /// the paper's 2R window, and the ±½ defects of the smoothed nematic field.
    fn coarse_fields(&mut self, m: &mut Monolayer, l: usize) {
        if self.coarse.as_ref().is_none_or(|(raw, _)| raw.l != l) {
            self.coarse = Some((CoarseFields::new(l), CoarseFields::new(l)));
        }
        let zeta = m.params().zeta;
        let half = (m.params().radius.round() as usize).min((l - 1) / 2);
        let (raw, smooth) = self.coarse.as_mut().expect("built above");
        raw.clear();
        for cell in m.cells() {
            raw.add_cell(cell.patch(), cell.phi().data, cell.q_hat(), zeta, None);
        }
        raw.set_velocity(m.velocity_field());
        smooth.smooth_from(raw, half, &mut self.row, &mut self.tmp);
        self.finder.find(&smooth.qxx, &smooth.qxy, l, &mut self.defects);
    }

    /// +½: a dot with a tail along its orientation (head to tail); −½: three spokes.
    fn defect_marks(&mut self, dpr: f32) {
        let defects = std::mem::take(&mut self.defects);
        for d in &defects {
            let p = [d.x + 0.5, d.y + 0.5];
            if d.twice_charge > 0 {
                let (c, s) = (d.orientation.cos(), d.orientation.sin());
                self.push([p[0] - 0.6 * c, p[1] - 0.6 * s], [p[0] + 0.6 * c, p[1] + 0.6 * s], PLUS_HALF, 7.0 * dpr);
                self.push(p, [p[0] + 4.0 * c, p[1] + 4.0 * s], PLUS_HALF, 2.5 * dpr);
            } else {
                for k in 0..3 {
                    let a = k as f64 * 2.0 * std::f64::consts::PI / 3.0 + std::f64::consts::FRAC_PI_2;
                    self.push(p, [p[0] + 2.5 * a.cos(), p[1] + 2.5 * a.sin()], MINUS_HALF, 2.5 * dpr);
                }
            }
        }
        self.defects = defects;
    }

    /// For every site, the two cells with the largest φ_i there.
    fn build_tissue(&mut self, m: &Monolayer, keys: &[u32], l: usize) {
        self.tissue.clear();
        self.tissue.resize(l * l, [0.0; 4]);
        for (cell, &key) in m.cells().iter().zip(keys) {
            let phi = cell.phi();
            let k = key as f32;
            for run in cell.patch().runs(l) {
                for i in 0..run.len {
                    let v = phi.data[run.padded + i] as f32;
                    let t = &mut self.tissue[run.global + i];
                    if v > t[1] {
                        *t = [k, v, t[0], t[1]];
                    } else if v > t[3] {
                        t[2] = k;
                        t[3] = v;
                    }
                }
            }
        }
    }

    fn elongation_axes(&mut self, m: &Monolayer, dpr: f32) {
        let l = m.params().box_size;
        let (q_mag, r) = (m.params().q_magnitude, m.params().radius);
        for cell in m.cells() {
            let [qxx, qxy] = cell.q_hat();
            let s = (qxx * qxx + qxy * qxy).sqrt() / q_mag;
            if s < 0.05 {
                continue; // a round cell has no axis
            }
            let theta = 0.5 * qxy.atan2(qxx);
            let half = 0.7 * r * s.min(1.0);
            let c = cell.centre(l);
            let d = [half * theta.cos(), half * theta.sin()];
            self.push([c[0] - d[0], c[1] - d[1]], [c[0] + d[0], c[1] + d[1]], WHITE, 2.0 * dpr);
        }
    }

    fn speed(&mut self, m: &mut Monolayer, l: usize, dpr: f32) {
        let v = m.velocity_field().to_vec();
        let mut vmax = 0.0f64;
        for (f, c) in self.field.iter_mut().zip(&v) {
            let s = c.norm();
            vmax = vmax.max(s);
            f[0] = s as f32;
        }
        let top = self.follow_scale(vmax).max(1e-3);
        self.range = (0.0, top as f32);
        let spacing = 7;
        let scale = 0.9 * spacing as f64 / top;
        for y in (spacing / 2..l).step_by(spacing) {
            for x in (spacing / 2..l).step_by(spacing) {
                let c = v[y * l + x];
                if c.norm() < 0.05 * top {
                    continue;
                }
                let p = [x as f64 + 0.5, y as f64 + 0.5];
                let d = [c.re * scale, c.im * scale];
                let tip = [p[0] + d[0], p[1] + d[1]];
                self.push(p, tip, ARROW, 1.5 * dpr);
                // Head: two short strokes back from the tip at ±25°.
                let back = [-d[0] * 0.3, -d[1] * 0.3];
                for (cs, sn) in [(0.906, 0.423), (0.906, -0.423)] {
                    let h = [tip[0] + back[0] * cs - back[1] * sn, tip[1] + back[0] * sn + back[1] * cs];
                    self.push(tip, h, ARROW, 1.5 * dpr);
                }
            }
        }
    }

    /// |Q| and the director of the smoothed nematic field Σ_i φ_i Q̂_i.
    fn director(&mut self, m: &mut Monolayer, l: usize, dpr: f32) {
        self.coarse_fields(m, l);
        let q_mag = m.params().q_magnitude;
        let (_, smooth) = self.coarse.as_ref().expect("built by coarse_fields");
        let q: Vec<[f64; 2]> = smooth.qxx.iter().zip(&smooth.qxy).map(|(&a, &b)| [a, b]).collect();
        for (f, t) in self.field.iter_mut().zip(&q) {
            f[0] = (t[0] * t[0] + t[1] * t[1]).sqrt() as f32;
        }
        self.range = (0.0, q_mag as f32);
        let spacing = 6;
        for y in (spacing / 2..l).step_by(spacing) {
            for x in (spacing / 2..l).step_by(spacing) {
                let [qxx, qxy] = q[y * l + x];
                let s = (qxx * qxx + qxy * qxy).sqrt() / q_mag;
                if s < 0.05 {
                    continue;
                }
                let theta = 0.5 * qxy.atan2(qxx);
                let half = 0.45 * spacing as f64 * s.min(1.0);
                let p = [x as f64 + 0.5, y as f64 + 0.5];
                let d = [half * theta.cos(), half * theta.sin()];
                self.push([p[0] - d[0], p[1] - d[1]], [p[0] + d[0], p[1] + d[1]], WHITE, 1.5 * dpr);
            }
        }
    }

    /// Adds a segment (not wrapped: one that crosses the box edge is clipped there).
    fn push(&mut self, a: [f64; 2], b: [f64; 2], colour: [f32; 4], width: f32) {
        self.segments.push(Segment {
            a: [a[0] as f32, a[1] as f32],
            b: [b[0] as f32, b[1] as f32],
            colour,
            width,
            _pad: [0.0; 3],
        });
    }
}
