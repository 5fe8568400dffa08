// The lattice: cells in their own colours with outlines at φ = ½, or a field under the outlines,
// and the painted substrate as a striped tint. One triangle covers the viewport; each fragment
// reads the four sites around it (the textures are f32, which is not filterable, so the
// bilinear interpolation is done here).

@group(0) @binding(1) var tissue_tex: texture_2d<f32>; // (key₁, φ₁, key₂, φ₂) per site
@group(0) @binding(2) var field_tex: texture_2d<f32>;  // (value, substrate multiplier, -, -)

struct VOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_full(@builtin(vertex_index) i: u32) -> VOut {
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    var o: VOut;
    o.pos = vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0);
    o.uv = vec2<f32>(p.x, 1.0 - p.y); // lattice row 0 at the top
    return o;
}

fn wrap_site(s: vec2<i32>) -> vec2<i32> {
    let l = i32(u.lattice.x);
    return ((s % l) + l) % l;
}

fn tissue(s: vec2<i32>) -> vec4<f32> {
    return textureLoad(tissue_tex, wrap_site(s), 0);
}

fn field(s: vec2<i32>) -> vec4<f32> {
    return textureLoad(field_tex, wrap_site(s), 0);
}

// φ of the cell with colour key `key` at a site, from that site's two largest φ.
fn phi_of(key: f32, t: vec4<f32>) -> f32 {
    return select(select(0.0, t.w, t.z == key), t.y, t.x == key);
}

fn bilinear(a: f32, b: f32, c: f32, d: f32, f: vec2<f32>) -> f32 {
    return mix(mix(a, b, f.x), mix(c, d, f.x), f.y);
}

// A muted colour per cell: hues spaced by the golden angle so neighbours differ.
fn cell_colour(key: f32) -> vec3<f32> {
    let h = fract(key * 0.6180339887) * 6.0;
    let rgb = clamp(abs(fract(vec3<f32>(h, h + 4.0, h + 2.0) / 6.0) * 6.0 - 3.0) - 1.0, vec3<f32>(0.0), vec3<f32>(1.0));
    let v = 0.62 + 0.18 * fract(key * 0.377);
    return v * mix(vec3<f32>(1.0), rgb, 0.55);
}

// Where no cell has φ > ½: a hole (Σφ < 0.01, the paper's void) is near black, a junction
// between cells (Σφ higher) a neutral grey, so holes stand out from the seams of the tissue.
const HOLE_COLOUR: vec3<f32> = vec3<f32>(0.02, 0.02, 0.03);
const JUNCTION_COLOUR: vec3<f32> = vec3<f32>(0.36, 0.37, 0.40);

@fragment
fn fs_field(in: VOut) -> @location(0) vec4<f32> {
    let p = in.uv * u.lattice.x;       // lattice coordinates; site (i, j) is centred at (i + ½, j + ½)
    let q = p - 0.5;
    let i0 = vec2<i32>(floor(q));
    let f = q - floor(q);
    let t00 = tissue(i0);
    let t10 = tissue(i0 + vec2<i32>(1, 0));
    let t01 = tissue(i0 + vec2<i32>(0, 1));
    let t11 = tissue(i0 + vec2<i32>(1, 1));

    // The cell drawn here: of the cells dominant at the four sites, the one with the largest
    // interpolated φ.
    var key = 0.0;
    var phi = 0.0;
    for (var k = 0; k < 4; k++) {
        var cand = t00.x;
        if k == 1 { cand = t10.x; }
        if k == 2 { cand = t01.x; }
        if k == 3 { cand = t11.x; }
        let v = bilinear(phi_of(cand, t00), phi_of(cand, t10), phi_of(cand, t01), phi_of(cand, t11), f);
        if cand > 0.0 && v > phi {
            key = cand;
            phi = v;
        }
    }

    // The field's four sites are read only when a field is shown (software GPUs pay per load).
    var value = 0.0;
    if u.flags.x != 0u {
        value = bilinear(field(i0).x, field(i0 + vec2<i32>(1, 0)).x, field(i0 + vec2<i32>(0, 1)).x,
                         field(i0 + vec2<i32>(1, 1)).x, f);
    }

    // Outline at φ = ½, about 1.5 device pixels wide whatever the zoom (φ's screen gradient).
    let w = max(fwidth(phi), 1e-5);
    let dist_px = abs(phi - 0.5) / w;
    let line = clamp(1.0 + 0.75 * u.lattice.y - dist_px, 0.0, 1.0);
    let inside = smoothstep(-1.0, 1.0, (phi - 0.5) / w);

    var colour: vec3<f32>;
    if u.flags.x == 0u {
        // Σφ from the two largest φ of each site (the rest is negligible away from junctions).
        let sum = bilinear(t00.y + t00.w, t10.y + t10.w, t01.y + t01.w, t11.y + t11.w, f);
        let background = mix(HOLE_COLOUR, JUNCTION_COLOUR, smoothstep(0.01, 0.35, sum));
        let fill = cell_colour(key) * (0.85 + 0.15 * clamp(phi, 0.0, 1.0));
        colour = mix(background, fill, inside);
        colour = mix(colour, vec3<f32>(0.02, 0.02, 0.03), line * 0.9);
    } else {
        let t = (value - u.range.x) / max(u.range.y - u.range.x, 1e-9);
        colour = colormap(t);
        colour = mix(colour, vec3<f32>(0.0), line * 0.45);
    }

    // Painted substrate: soft (low friction) in blue, stiff in orange, as diagonal stripes so
    // the tint reads without colour vision too.
    var substrate = 1.0;
    if u.flags.w != 0u {
        substrate = field(vec2<i32>(floor(p))).y;
    }
    if substrate != 1.0 {
        let stripe = step(0.5, fract((p.x + p.y) * 0.25));
        let tint = select(vec3<f32>(1.0, 0.55, 0.1), vec3<f32>(0.2, 0.55, 1.0), substrate < 1.0);
        colour = mix(colour, tint, 0.18 + 0.22 * stripe);
    }
    return out_colour(colour, 1.0);
}

// The colour bar under the lattice: the same colormap, left (min) to right (max).
@fragment
fn fs_bar(in: VOut) -> @location(0) vec4<f32> {
    return out_colour(colormap(in.uv.x), 1.0);
}
