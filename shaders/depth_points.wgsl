// depth_points: stored depth PNG values → upright points, one vec4 per pixel.
//
// CPU twin: src/gpu/depth_points.rs (same names, same f32 operation order).
//
// Input `stored_depth`: the raw 16-bit values of the depth PNG (not yet decoded), two per u32 word:
// the job's pixel 2k in the low half of word k, pixel 2k+1 in the high half (word 0 starts at the job's
// first pixel, `params.first_pixel`, whatever its parity). An odd last pixel leaves the high half 0.
// Output `points[i]` for the job's pixel i: (x, y, z, 1) in the upright frame when the pixel has depth,
// (0, 0, 0, 0) when it does not.

// Twin of the Rust `DepthPointsParams` (80 bytes). Rtilt is passed as three vec4 columns (w unused)
// because a uniform mat3x3 has 16-byte column strides that a packed Rust [[f32; 3]; 3] would not match.
struct DepthPointsParams {
    rtilt_col0: vec4<f32>,
    rtilt_col1: vec4<f32>,
    rtilt_col2: vec4<f32>,
    // (fx, fy, cx, cy), 1-based pixel convention.
    intrinsics: vec4<f32>,
    width: u32,
    height: u32,
    // Row-major index of the job's first pixel in the whole image.
    first_pixel: u32,
    // Number of pixels in the job.
    pixel_count: u32,
}

const WORKGROUP_SIZE: u32 = 64u;
// Depth beyond this is clamped to it (the SUN RGB-D toolbox's convention).
const MAX_DEPTH_M: f32 = 8.0;

@group(0) @binding(0) var<uniform> params: DepthPointsParams;
@group(0) @binding(1) var<storage, read> stored_depth: array<u32>;
@group(0) @binding(2) var<storage, read_write> points: array<vec4<f32>>;

// Undoes the toolbox's 3-bit left rotation of the 16-bit millimetre value.
fn decode_depth_mm(stored: u32) -> u32 {
    return ((stored >> 3u) | (stored << 13u)) & 0xffffu;
}

// The stored 16-bit value of the job's pixel `local`.
fn stored_value(local: u32) -> u32 {
    let word = stored_depth[local >> 1u];
    return (word >> ((local & 1u) * 16u)) & 0xffffu;
}

fn depth_point(local: u32) -> vec4<f32> {
    let pixel = params.first_pixel + local;
    let col = pixel % params.width;
    let row = pixel / params.width;
    let mm = decode_depth_mm(stored_value(local));
    if mm == 0u {
        return vec4<f32>(0.0, 0.0, 0.0, 0.0);
    }
    let z = min(f32(mm) / 1000.0, MAX_DEPTH_M);
    // 1-based pixel coordinates.
    let u = f32(col + 1u);
    let v = f32(row + 1u);
    let fx = params.intrinsics.x;
    let fy = params.intrinsics.y;
    let cx = params.intrinsics.z;
    let cy = params.intrinsics.w;
    let x = (u - cx) * z / fx;
    let y = (v - cy) * z / fy;
    // p = Rtilt·(x, z, −y), written out column by column so the CPU twin can repeat the order.
    let p = params.rtilt_col0.xyz * x + params.rtilt_col1.xyz * z + params.rtilt_col2.xyz * (-y);
    return vec4<f32>(p, 1.0);
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn depth_points(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) num_workgroups: vec3<u32>) {
    // 1-D job dispatched over x and y (see src/gpu/mod.rs, "1-D dispatch convention").
    let local = gid.x + gid.y * num_workgroups.x * WORKGROUP_SIZE;
    if local >= params.pixel_count {
        return;
    }
    points[local] = depth_point(local);
}
