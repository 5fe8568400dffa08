//! A [`View`] as an image of one pixel per lattice site, for the page's Canvas 2D renderer: the
//! one it falls back to where the browser offers neither WebGPU nor WebGL2 (a blocklisted GPU
//! driver, a locked-down school computer). The page scales the image up to the canvas and draws
//! the view's segments over it as lines.
//!
//! The colours are those of the wgpu renderer's shaders (`shaders/common.wgsl`,
//! `shaders/field.wgsl`), evaluated once per site instead of per pixel: the cells in their own
//! colours with a dark outline where the dominant cell changes, holes near black, junctions
//! grey, the fields through viridis or the diverging map, the painted substrate striped. sRGB
//! bytes, as a 2D canvas takes them.

use super::view::{FieldKind, View};

type Rgb = [f32; 3];

/// Where no cell has φ > ½: a hole (Σφ < 0.01) near black, a junction a neutral grey
/// (`HOLE_COLOUR`, `JUNCTION_COLOUR` of field.wgsl).
const HOLE: Rgb = [0.02, 0.02, 0.03];
const JUNCTION: Rgb = [0.36, 0.37, 0.40];
const OUTLINE: Rgb = [0.02, 0.02, 0.03];

/// RGBA bytes, `l × l` of them row by row (row 0 at the top, as the lattice is drawn), for
/// `view`; `substrate` tints the painted substrate as the wgpu renderer does.
pub fn site_colours(view: &View, substrate: bool) -> Vec<u8> {
    let l = view.l;
    let mut out = Vec::with_capacity(4 * l * l);
    let (lo, hi) = view.range;
    let span = (hi - lo).max(1e-9);
    for y in 0..l {
        for x in 0..l {
            let i = y * l + x;
            let t = view.tissue[i];
            let (key, phi) = (t[0], t[1]);
            let inside = key > 0.0 && phi > 0.5;
            let mut c = if view.kind.shows_field() {
                colormap(view.kind, (view.field[i][0] - lo) / span)
            } else if inside {
                scale(cell_colour(key), 0.85 + 0.15 * phi.clamp(0.0, 1.0))
            } else {
                mix(HOLE, JUNCTION, smoothstep(0.01, 0.35, t[1] + t[3]))
            };
            if outline(view, x, y) {
                c = mix(c, OUTLINE, if view.kind.shows_field() { 0.45 } else { 0.9 });
            }
            let s = view.field[i][1];
            if substrate && s != 1.0 {
                let stripe = if ((x + y) as f32 * 0.25).fract() >= 0.5 { 1.0 } else { 0.0 };
                let tint = if s < 1.0 { [0.2, 0.55, 1.0] } else { [1.0, 0.55, 0.1] };
                c = mix(c, tint, 0.18 + 0.22 * stripe);
            }
            out.extend(c.map(byte));
            out.push(255);
        }
    }
    out
}

/// The colour bar of `kind`: `n` RGBA pixels from its minimum (left) to its maximum.
pub fn bar_colours(kind: FieldKind, n: usize) -> Vec<u8> {
    (0..n)
        .flat_map(|k| {
            let c = colormap(kind, k as f32 / (n.max(2) - 1) as f32).map(byte);
            [c[0], c[1], c[2], 255]
        })
        .collect()
}

/// A site on a cell's edge: inside a cell, with a neighbour (periodic) that is not inside the
/// same one. The outline at φ = ½ of the wgpu renderer, at the resolution of the lattice.
fn outline(view: &View, x: usize, y: usize) -> bool {
    let l = view.l;
    let owner = |x: usize, y: usize| {
        let t = view.tissue[y * l + x];
        if t[0] > 0.0 && t[1] > 0.5 {
            t[0]
        } else {
            0.0
        }
    };
    let me = owner(x, y);
    me > 0.0
        && [((x + 1) % l, y), ((x + l - 1) % l, y), (x, (y + 1) % l), (x, (y + l - 1) % l)]
            .iter()
            .any(|&(a, b)| owner(a, b) != me)
}

fn colormap(kind: FieldKind, t: f32) -> Rgb {
    if kind.is_signed() {
        diverging(t)
    } else {
        viridis(t)
    }
}

/// `cell_colour` of field.wgsl: hues spaced by the golden angle, muted.
fn cell_colour(key: f32) -> Rgb {
    let h = (key * 0.618_034).fract() * 6.0;
    let rgb = [h, h + 4.0, h + 2.0].map(|c| (((c / 6.0).fract() * 6.0 - 3.0).abs() - 1.0).clamp(0.0, 1.0));
    let v = 0.62 + 0.18 * (key * 0.377).fract();
    scale(mix([1.0; 3], rgb, 0.55), v)
}

/// `viridis` of common.wgsl (a degree-6 polynomial fit of matplotlib's table), in sRGB.
fn viridis(t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    const C: [Rgb; 7] = [
        [0.277_727_33, 0.005_407_344_5, 0.334_099_8],
        [0.105_093_04, 1.404_613_5, 1.384_590_2],
        [-0.330_861_83, 0.214_847_56, 0.095_095_16],
        [-4.634_230_6, -5.799_101, -19.332_441],
        [6.228_27, 14.179_933, 56.690_55],
        [4.776_385, -13.745_145, -65.353_03],
        [-5.435_456, 4.645_852_6, 26.312_435],
    ];
    let mut c = C[6];
    for k in (0..6).rev() {
        c = [0, 1, 2].map(|j| C[k][j] + t * c[j]);
    }
    c
}

/// `diverging` of common.wgsl: blue through a light neutral to red, mixed in linear light.
fn diverging(t: f32) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    let blue = [0.23, 0.30, 0.75].map(srgb_to_linear);
    let mid = [0.87, 0.87, 0.87].map(srgb_to_linear);
    let red = [0.71, 0.02, 0.15].map(srgb_to_linear);
    let lin = if t < 0.5 { mix(blue, mid, 2.0 * t) } else { mix(mid, red, 2.0 * t - 1.0) };
    lin.map(linear_to_srgb)
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    [0, 1, 2].map(|j| a[j] + (b[j] - a[j]) * t)
}

fn scale(a: Rgb, k: f32) -> Rgb {
    a.map(|c| c * k)
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn byte(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6 × 6 lattice: cell 1 on the left two columns, cell 2 on the next two, a hole on the
    /// last two; the field rises from 0 at the left to 1 at the right.
    fn view(kind: FieldKind) -> View {
        let l = 6;
        let mut tissue = vec![[0.0; 4]; l * l];
        let mut field = vec![[0.0, 1.0, 0.0, 0.0]; l * l];
        for y in 0..l {
            for x in 0..l {
                tissue[y * l + x] = match x {
                    0 | 1 => [1.0, 0.95, 0.0, 0.0],
                    2 | 3 => [2.0, 0.95, 0.0, 0.0],
                    _ => [0.0, 0.0, 0.0, 0.0],
                };
                field[y * l + x][0] = x as f32 / 5.0;
            }
        }
        View { l, kind, tissue, field, segments: vec![], range: (0.0, 1.0) }
    }

    fn pixel(rgba: &[u8], l: usize, x: usize, y: usize) -> [u8; 3] {
        let i = 4 * (y * l + x);
        [rgba[i], rgba[i + 1], rgba[i + 2]]
    }

    #[test]
    fn cells_take_their_colours_holes_are_black_and_edges_are_outlined() {
        // Cell 1 wraps across the periodic edge onto column 5: columns 5, 0, 1 are cell 1.
        let mut v = view(FieldKind::Tissue);
        for y in 0..6 {
            v.tissue[y * 6 + 5] = [1.0, 0.95, 0.0, 0.0];
        }
        v.tissue[3 * 6 + 4] = [0.0; 4];
        let px = site_colours(&v, true);
        assert_eq!(px.len(), 4 * 36);
        assert!(px.chunks(4).all(|p| p[3] == 255), "opaque");
        // Column 0 lies inside cell 1: the cell's own colour, scaled by φ as the shader does.
        let inner = pixel(&px, 6, 0, 3);
        assert_eq!(inner, scale(cell_colour(1.0), 0.85 + 0.15 * 0.95).map(byte));
        assert_eq!(inner, pixel(&px, 6, 0, 0), "a cell is one colour");
        // Column 1 borders cell 2: outlined, darker.
        let edge = pixel(&px, 6, 1, 3);
        assert!(edge.iter().zip(&inner).all(|(e, i)| e < i), "outline {edge:?} not darker than {inner:?}");
        assert_ne!(pixel(&px, 6, 3, 0), pixel(&px, 6, 0, 0), "neighbouring cells differ");
        // A site no cell covers (Σφ = 0): near black.
        assert_eq!(pixel(&px, 6, 4, 3), HOLE.map(byte));
    }

    #[test]
    fn fields_go_through_their_colormaps_and_the_substrate_is_striped() {
        let v = view(FieldKind::PhiSum);
        let px = site_colours(&v, true);
        // The hole's columns are not outlined: the field's colour as it is.
        assert_eq!(pixel(&px, 6, 5, 2), viridis(1.0).map(byte));
        assert_eq!(pixel(&px, 6, 4, 2), viridis(0.8).map(byte));
        // viridis runs from dark purple to yellow.
        assert!(viridis(0.0)[2] > viridis(0.0)[1] && viridis(1.0)[0] > 0.9 && viridis(1.0)[2] < 0.2);
        let s = site_colours(&view(FieldKind::StrainRate), true);
        assert_eq!(pixel(&s, 6, 5, 2), diverging(1.0).map(byte));
        let mid = diverging(0.5).map(byte);
        assert!(mid.iter().all(|&c| (c as i32 - 222).abs() <= 1), "the diverging map's middle is light grey: {mid:?}");
        let bar = bar_colours(FieldKind::Speed, 11);
        assert_eq!(bar.len(), 44);
        assert_eq!(&bar[..3], &viridis(0.0).map(byte));
        assert_eq!(&bar[40..43], &viridis(1.0).map(byte));
        // A soft site: tinted blue, or left alone without `substrate`.
        let mut soft = v.clone();
        soft.field[2 * 6 + 5][1] = 0.1;
        let tinted = pixel(&site_colours(&soft, true), 6, 5, 2);
        assert_ne!(tinted, pixel(&px, 6, 5, 2));
        assert_eq!(pixel(&site_colours(&soft, false), 6, 5, 2), pixel(&px, 6, 5, 2));
    }
}
