// normal_window: per pixel, the plane-fit neighbours of its point among the 7×7 pixels around it
// (NormalSearch::Window, paper §3.1.2's 15 nearest neighbours searched in an image window).
//
// CPU twin: `window_neighbour_mask` in src/features/preprocess.rs (same names, same order of operations);
// the Rust side of the kernel: src/gpu/normal_window.rs.
//
// Input `grid[pixel]`: the frame's point at that pixel as (x, y, z, 1), or (0, 0, 0, 0) for a pixel without
// one (the layout of depth_points' output), row-major. Output `masks[pixel]`: the window slots of the
// NORMAL_NEIGHBOURS nearest points as a 49-bit mask (slot = (dy + r)·NORMAL_WINDOW + (dx + r); bit slot % 32
// of component slot / 32); (0, 0) for a pixel without a point. Distances are integers (quarter millimetres),
// so the choice is the CPU's bit for bit; the plane fit itself stays on the CPU (double precision).

struct NormalWindowParams {
    width: u32,
    height: u32,
    // Row-major index of the job's first pixel.
    first_pixel: u32,
    // Number of pixels in the job.
    pixel_count: u32,
}

const WORKGROUP_SIZE: u32 = 64u;
const NORMAL_WINDOW: i32 = 7;
const NORMAL_NEIGHBOURS: u32 = 15u;
// Fixed-point units per metre, and the largest offset per axis in units (3 · 16383² fits in a u32).
const NORMAL_WINDOW_UNITS: f32 = 4000.0;
const NORMAL_WINDOW_CLAMP: f32 = 16383.0;

@group(0) @binding(0) var<uniform> params: NormalWindowParams;
@group(0) @binding(1) var<storage, read> grid: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> masks: array<vec2<u32>>;

// One axis of a window offset in fixed point: a subtraction, a product and a floor, nothing to fuse.
fn window_offset(a: f32, b: f32) -> i32 {
    return i32(clamp(floor((a - b) * NORMAL_WINDOW_UNITS), -NORMAL_WINDOW_CLAMP, NORMAL_WINDOW_CLAMP));
}

fn window_mask(pixel: u32) -> vec2<u32> {
    let width = params.width;
    let col = i32(pixel % width);
    let row = i32(pixel / width);
    let centre = grid[pixel];
    if centre.w == 0.0 {
        return vec2<u32>(0u, 0u);
    }
    let radius = NORMAL_WINDOW / 2;
    // The nearest so far, sorted by (distance, slot).
    var keys: array<u32, NORMAL_NEIGHBOURS>;
    var slots: array<u32, NORMAL_NEIGHBOURS>;
    var count = 0u;
    for (var dy = -radius; dy <= radius; dy++) {
        for (var dx = -radius; dx <= radius; dx++) {
            let c = col + dx;
            let r = row + dy;
            if c < 0 || r < 0 || c >= i32(width) || r >= i32(params.height) {
                continue;
            }
            let p = grid[u32(r) * width + u32(c)];
            if p.w == 0.0 {
                continue;
            }
            let ox = window_offset(p.x, centre.x);
            let oy = window_offset(p.y, centre.y);
            let oz = window_offset(p.z, centre.z);
            let key = u32(ox * ox) + u32(oy * oy) + u32(oz * oz);
            let slot = u32((dy + radius) * NORMAL_WINDOW + (dx + radius));
            if count == NORMAL_NEIGHBOURS && key >= keys[NORMAL_NEIGHBOURS - 1u] {
                continue;
            }
            // Insertion: later slots of an equal distance go after the earlier ones.
            var i = min(count, NORMAL_NEIGHBOURS - 1u);
            while i > 0u && keys[i - 1u] > key {
                keys[i] = keys[i - 1u];
                slots[i] = slots[i - 1u];
                i -= 1u;
            }
            keys[i] = key;
            slots[i] = slot;
            count = min(count + 1u, NORMAL_NEIGHBOURS);
        }
    }
    var mask = vec2<u32>(0u, 0u);
    for (var k = 0u; k < count; k++) {
        let slot = slots[k];
        mask[slot / 32u] |= 1u << (slot % 32u);
    }
    return mask;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn normal_window(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) num_workgroups: vec3<u32>) {
    // 1-D job dispatched over x and y (see src/gpu/mod.rs, "1-D dispatch convention").
    let local = gid.x + gid.y * num_workgroups.x * WORKGROUP_SIZE;
    if local >= params.pixel_count {
        return;
    }
    masks[local] = window_mask(params.first_pixel + local);
}
