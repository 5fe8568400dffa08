// Line segments over the lattice (elongation axes, velocity arrows, director), one instance
// each, drawn as quads of a fixed width in device pixels with soft edges.

struct Seg {
    @location(0) a: vec2<f32>,       // ends in lattice coordinates
    @location(1) b: vec2<f32>,
    @location(2) colour: vec4<f32>,  // sRGB, alpha
    @location(3) width: f32,         // device pixels
};

struct SOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) colour: vec4<f32>,
    @location(1) across: f32,        // −1 … 1 across the quad
};

@vertex
fn vs_seg(@builtin(vertex_index) vi: u32, s: Seg) -> SOut {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(0.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
        vec2<f32>(0.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(0.0, 1.0),
    );
    let c = corners[vi];
    let l = u.lattice.x;
    let sites_per_px = l / max(u.lattice.z, 1.0);
    // At least 1.5 pixels wide, so lines stay smooth when the canvas is drawn at low resolution;
    // one extra pixel for the soft edge.
    let half = 0.5 * (max(s.width, 1.5) + 1.0) * sites_per_px;
    let d = s.b - s.a;
    let len = max(length(d), 1e-6);
    let dir = d / len;
    let normal = vec2<f32>(-dir.y, dir.x);
    // Extend both ends by the half width: round-looking caps that join arrow heads cleanly.
    let p = s.a - dir * half + dir * (len + 2.0 * half) * c.x + normal * half * c.y;
    var o: SOut;
    o.pos = vec4<f32>(p.x / l * 2.0 - 1.0, 1.0 - p.y / l * 2.0, 0.0, 1.0);
    o.colour = s.colour;
    o.across = c.y;
    return o;
}

@fragment
fn fs_seg(in: SOut) -> @location(0) vec4<f32> {
    let edge = 1.0 - smoothstep(0.6, 1.0, abs(in.across));
    let c = out_colour(in.colour.rgb, in.colour.a * edge);
    return c;
}
