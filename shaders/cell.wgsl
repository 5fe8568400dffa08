// The patches following the cells on the GPU (src/model/monolayer.rs `update_patches`, and
// src/model/cell.rs `local_centre`, `support`, `relayout`): after each step, every cell's patch
// is re-centred on the cell during relaxation (a square of `relax_patch_size`) and fitted to its
// support, φ > `presence_threshold`, plus `patch_margin` when active; φ moves with it, zero
// where the new patch reaches beyond the old.
//
// Each cell's storage has a fixed capacity (`Patch::capacity`, set at upload), so a patch can
// move and grow without the buffers being made again. One dispatch, one workgroup per cell (a
// cell's patch and storage are its own, so its workgroup's barriers order everything):
// `next_patch` finds the next patch and a code for `patch_fault`, `relayout` copies φ into the
// next layout in `phi0` (Heun's φ_n, free between steps), then φ is copied back and the next
// patch made current. A cell whose patch cannot be made keeps its old one, and its code says why
// (the CPU's `CellLost`, or a capacity the host must enlarge by uploading again).

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> patches: array<Patch>;
@group(0) @binding(2) var<storage, read_write> phi: array<f32>;
@group(0) @binding(16) var<storage, read_write> phi0: array<f32>;
@group(0) @binding(26) var<storage, read_write> patch_fault: array<u32>;

// `patch_fault` codes (`PatchFault` in src/gpu/buffers.rs).
const MOVED: u32 = 0u;
const VANISHED: u32 = 1u;
const SPANS_THE_BOX: u32 = 2u;
const BEYOND_CAPACITY: u32 = 3u;

const WORKGROUP: u32 = 64u;
// Per invocation: the bounding box (a_min, a_max, b_min, b_max) of its sites with φ above the
// threshold, and the sums Σφ⁺, Σφ⁺a, Σφ⁺b of the centre.
var<workgroup> boxes: array<vec4<u32>, WORKGROUP>;
var<workgroup> centres: array<vec3<f32>, WORKGROUP>;

const EMPTY: vec4<u32> = vec4<u32>(0xffffffffu, 0u, 0xffffffffu, 0u);

// p.x0 + d on the periodic lattice (`lattice::wrap`).
fn wrap(x: u32, d: i32) -> u32 {
    let l = i32(params.box_size);
    return u32(((i32(x) + d) % l + l) % l);
}

var<workgroup> next_here: Patch;

// Cell i's patch follows it (`Monolayer::update_patches`, `Cell::relayout`): one workgroup per
// cell, the next patch found, φ laid out in it (in `phi0`), then copied back and the patch
// table updated.
@compute @workgroup_size(64)
fn move_patch(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) t: u32) {
    let i = wg.x;
    let old = patches[i];
    next_patch(i, old, t);
    let next = workgroupUniformLoad(&next_here);
    let n = stride(next) * (next.h + 2u);
    for (var k = t; k < n; k += WORKGROUP) {
        phi0[next.offset + k] = relayout(old, next, k);
    }
    storageBarrier();
    for (var k = t; k < n; k += WORKGROUP) {
        phi[next.offset + k] = phi0[next.offset + k];
    }
    if t == 0u {
        patches[i] = next;
    }
}

// The next patch of cell i, whose patch is p, into `next_here`, and its code into `patch_fault`
// (every invocation of the workgroup calls it). The centre's sums run in a fixed order
// (strided, then a halving tree); the bounding box is a min and a max, whatever the order.
fn next_patch(i: u32, p: Patch, t: u32) {
    let s = stride(p);
    var bb = EMPTY;
    var c = vec3<f32>(0.0, 0.0, 0.0);
    for (var k = t; k < p.w * p.h; k += WORKGROUP) {
        let a = k % p.w;
        let b = k / p.w;
        let v = phi[p.offset + (b + 1u) * s + a + 1u];
        if v > params.presence_threshold {
            bb = vec4<u32>(min(bb.x, a), max(bb.y, a), min(bb.z, b), max(bb.w, b));
        }
        let w = max(v, 0.0);
        c += vec3<f32>(w, w * f32(a), w * f32(b));
    }
    boxes[t] = bb;
    centres[t] = c;
    workgroupBarrier();
    for (var width = WORKGROUP / 2u; width > 0u; width /= 2u) {
        if t < width {
            let o = boxes[t + width];
            let m = boxes[t];
            boxes[t] = vec4<u32>(min(m.x, o.x), max(m.y, o.y), min(m.z, o.z), max(m.w, o.w));
            centres[t] += centres[t + width];
        }
        workgroupBarrier();
    }
    if t == 0u {
        next_here = next_of(i, p);
    }
}

// Cell i's next patch from its old one p and the workgroup's sums (`boxes`, `centres`), with its
// code into `patch_fault`.
fn next_of(i: u32, p: Patch) -> Patch {
    var next = p;
    var code = MOVED;
    if params.active_phase == 0u {
        // Relaxation (`Cell::local_centre`): a square on the centre of φ⁺, rounded half away
        // from zero as f64::round (the centre is not negative).
        let sums = centres[0];
        var centre = vec2<f32>(f32(p.w) / 2.0, f32(p.h) / 2.0);
        if sums.x > 0.0 {
            centre = sums.yz / sums.x;
        }
        let half = i32(params.relax_patch_size / 2u);
        next.x0 = wrap(p.x0, i32(floor(centre.x + 0.5)) - half);
        next.y0 = wrap(p.y0, i32(floor(centre.y + 0.5)) - half);
        next.w = params.relax_patch_size;
        next.h = params.relax_patch_size;
    } else {
        // Activity (`Cell::support`): the bounding box of φ > threshold, plus the margin.
        let box = boxes[0];
        let margin = params.patch_margin;
        if box.x > box.y {
            code = VANISHED;
        } else {
            next.w = box.y - box.x + 1u + 2u * margin;
            next.h = box.w - box.z + 1u + 2u * margin;
            next.x0 = wrap(p.x0, i32(box.x) - i32(margin));
            next.y0 = wrap(p.y0, i32(box.z) - i32(margin));
            if next.w >= params.box_size || next.h >= params.box_size {
                code = SPANS_THE_BOX;
            }
        }
    }
    if code == MOVED && (next.w + 2u) * (next.h + 2u) > p.capacity {
        code = BEYOND_CAPACITY;
    }
    if code != MOVED {
        next = p;
    }
    // Sticky, as the other faults: the first one stays until the host reads and clears it, so
    // that a fault in the middle of a submission is not hidden by a later step.
    if patch_fault[i] == MOVED {
        patch_fault[i] = code;
    }
    return next;
}

// φ at padded site k of the next patch (`Cell::relayout`): from the same lattice site of the old
// patch, or 0 where the old patch does not reach (and on the halo).
fn relayout(old: Patch, next: Patch, k: u32) -> f32 {
    let site = site_of(next, k);
    if !site.interior {
        return 0.0;
    }
    let l = params.box_size;
    let gx = (next.x0 + site.at.x - 1u) % l;
    let gy = (next.y0 + site.at.y - 1u) % l;
    let oa = (gx + l - old.x0) % l;
    let ob = (gy + l - old.y0) % l;
    if oa < old.w && ob < old.h {
        return phi[old.offset + (ob + 1u) * stride(old) + oa + 1u];
    }
    return 0.0;
}
