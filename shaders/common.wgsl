// Shared by every shader of the demo (the renderer prepends this file to each of them).
//
// Colours are written as sRGB values and converted to linear light here when the surface
// encodes to sRGB itself (WebGL2's default surface): without this the colormap would be
// encoded twice and look washed out. On a non-sRGB surface (WebGPU's bgra8unorm canvas) the
// sRGB values go out as they are.

// Written by src/web/render.rs (`Uniforms`, the same layout).
struct Uniforms {
    // x: lattice side L; y: device pixels per CSS pixel; z: side of the drawn lattice in device
    // pixels.
    lattice: vec4<f32>,
    // x, y: colour range of the field.
    range: vec4<f32>,
    // Booleans, 0 or 1. x: a field is shown under the outlines (else the cells' colours);
    // y: the field is signed (diverging colormap); z: the surface wants linear values;
    // w: tint the painted substrate.
    flags: vec4<u32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

// The colour to write for an sRGB colour, on this surface.
fn out_colour(srgb: vec3<f32>, alpha: f32) -> vec4<f32> {
    let c = clamp(srgb, vec3<f32>(0.0), vec3<f32>(1.0));
    return vec4<f32>(select(c, srgb_to_linear(c), u.flags.z != 0u), alpha);
}

// Viridis (perceptually uniform, readable in greyscale and by colour-blind viewers): a
// degree-6 polynomial fit of the matplotlib table (by Matt Zucker, CC0), in sRGB, t ∈ [0, 1].
fn viridis(t_in: f32) -> vec3<f32> {
    let t = clamp(t_in, 0.0, 1.0);
    let c0 = vec3<f32>(0.2777273272234177, 0.005407344544966578, 0.3340998053353061);
    let c1 = vec3<f32>(0.1050930431085774, 1.404613529898575, 1.384590162594685);
    let c2 = vec3<f32>(-0.3308618287255563, 0.214847559468213, 0.09509516302823659);
    let c3 = vec3<f32>(-4.634230498983486, -5.799100973351585, -19.33244095627987);
    let c4 = vec3<f32>(6.228269936347081, 14.17993336680509, 56.69055260068105);
    let c5 = vec3<f32>(4.776384997670288, -13.74514537774601, -65.35303263337234);
    let c6 = vec3<f32>(-5.435455855934631, 4.645852612178535, 26.3124352495832);
    return c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6)))));
}

// For signed fields (strain rate, force divergence), t ∈ [0, 1] with ½ at zero: blue through a
// light neutral to red, interpolated in linear light (so the middle does not darken) between
// endpoints of equal lightness, then returned in sRGB like `viridis`.
fn diverging(t_in: f32) -> vec3<f32> {
    let t = clamp(t_in, 0.0, 1.0);
    let blue = srgb_to_linear(vec3<f32>(0.23, 0.30, 0.75));
    let mid = srgb_to_linear(vec3<f32>(0.87, 0.87, 0.87));
    let red = srgb_to_linear(vec3<f32>(0.71, 0.02, 0.15));
    let lin = select(mix(mid, red, 2.0 * t - 1.0), mix(blue, mid, 2.0 * t), t < 0.5);
    return linear_to_srgb(lin);
}

fn linear_to_srgb(c: vec3<f32>) -> vec3<f32> {
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(hi, lo, c <= vec3<f32>(0.0031308));
}

// The colormap of the field shown.
fn colormap(t: f32) -> vec3<f32> {
    if u.flags.y != 0u {
        return diverging(t);
    }
    return viridis(t);
}
