// image_gradients: per pixel, the image gradient (dx, dy) of the colour channel of the largest magnitude,
// with the filters [-1, 0, 1] and [-1, 0, 1]ᵀ and replicate padding (paper §3.2's HOG-style gradients; the
// definition is `pixel_gradient` in src/features/preprocess.rs).
//
// CPU twin: `table_gradient` in src/features/preprocess.rs (same names, same order of operations); the Rust
// side of the kernel: src/gpu/image_gradients.rs.
//
// Input `rgb`: the image's bytes as stored (row-major, R, G, B per pixel), four to a u32 word, the first byte
// in the low bits; the last word padded with zeros. `table[high * GRADIENT_LEVELS + low]` = (level(high) −
// level(low), its square), rounded to f32 on the CPU (`gradient_table`): the kernel only looks up, adds and
// compares, so no product is left for the compiler to fuse into a multiply-add of another rounding, and the
// gradients are the CPU's bit for bit. Output `gradients[pixel]`: (dx, dy).

struct ImageGradientsParams {
    width: u32,
    height: u32,
    // Number of pixels (width · height).
    pixel_count: u32,
    pad: u32,
}

const WORKGROUP_SIZE: u32 = 64u;
// Intensity levels of a channel: the table has GRADIENT_LEVELS² entries.
const GRADIENT_LEVELS: u32 = 256u;

@group(0) @binding(0) var<uniform> params: ImageGradientsParams;
@group(0) @binding(1) var<storage, read> rgb: array<u32>;
@group(0) @binding(2) var<storage, read> table: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> gradients: array<vec2<f32>>;

// Byte `ch` (0 = R) of pixel (col, row).
fn channel(col: u32, row: u32, ch: u32) -> u32 {
    let byte = (row * params.width + col) * 3u + ch;
    return (rgb[byte / 4u] >> ((byte % 4u) * 8u)) & 0xffu;
}

fn pixel_gradient(pixel: u32) -> vec2<f32> {
    let col = pixel % params.width;
    let row = pixel / params.width;
    let left = select(col - 1u, 0u, col == 0u);
    let right = min(col + 1u, params.width - 1u);
    let up = select(row - 1u, 0u, row == 0u);
    let down = min(row + 1u, params.height - 1u);
    var best = vec2<f32>(0.0, 0.0);
    var best_sq = -1.0;
    for (var ch = 0u; ch < 3u; ch++) {
        let x = table[channel(right, row, ch) * GRADIENT_LEVELS + channel(left, row, ch)];
        let y = table[channel(col, down, ch) * GRADIENT_LEVELS + channel(col, up, ch)];
        let sq = x.y + y.y;
        if sq > best_sq {
            best_sq = sq;
            best = vec2<f32>(x.x, y.x);
        }
    }
    return best;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn image_gradients(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) num_workgroups: vec3<u32>) {
    // 1-D job dispatched over x and y (see src/gpu/mod.rs, "1-D dispatch convention").
    let pixel = gid.x + gid.y * num_workgroups.x * WORKGROUP_SIZE;
    if pixel >= params.pixel_count {
        return;
    }
    gradients[pixel] = pixel_gradient(pixel);
}
