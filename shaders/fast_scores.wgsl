// Fused scores of the fast path (src/features/fast.rs, steps 3–4) from one summed-area LayerTable.
// CPU twin: `fast_scores_main` in src/gpu/fast.rs (same names, same loop and reduction order).
//
// One dispatch per dispatch record (one table group × chunk × weight pass), all through one bind group: the
// record is a uniform bound at a dynamic offset of the batch's records buffer, and says where its table,
// hypotheses, boundaries, weights and scores lie in the batch's shared buffers. (A single dispatch for the
// whole batch, each workgroup searching its record in a storage array, was tried: its scoring pass was no
// faster on an H200 — 0.12 s per frame against 0.11–0.14 s with one dispatch per record — nor on
// lavapipe.) One workgroup of 64 invocations per hypothesis. Invocation `lid` takes the voxels ℓ = lid, lid + 64, …
// (ℓ = (k·ny + j)·nx + i, the layout's order; at most 9 voxels for the largest grid), reads the voxel's
// 36 channels as four table corners (u32 wrapping differences: exact whatever the order), finalises the
// 35 features (density and normal bins over the linearised projected area, normalised COG; an empty
// voxel contributes nothing) and dots them with up to MAX_WEIGHTS weight vectors. Everything is vec4 and
// the loops over channels and weights are written out or of constant length: lavapipe keeps dynamically
// indexed private arrays in memory and gathers them lane by lane (a first version with a `values` array
// and scalar loads was 1.4× slower). On lavapipe the kernel is bound by its 45 non-uniform vec4 loads per
// voxel (36 table, 9 weights), which gallivm performs lane by lane. The 64 partial scores
// per weight vector are reduced in workgroup memory in a fixed tree order, so the result is the same
// bits on every run. Then invocation 0 adds the view part (group bit 8): the view cosine of the box's centre,
// its VIEW_RBFS radial basis functions and the bias, dotted with the pass's view weights — after the voxels,
// as `FastEngine::scores` adds it.
//
// Loops are short (≤ 9 voxels × ≤ 36 channels per invocation): far from gallivm's 65535-iteration cap
// (see shaders/features.wgsl).

const MAX_WEIGHTS: u32 = 8u;
const WORKGROUP: u32 = 64u;
const MIN_PROJECT_DEPTH: f32 = 1e-3;
const COG_EPSILON: f32 = 0.01;
// The view features (src/features/feature_layout.rs): VIEW_RBFS radial basis functions of the view cosine
// at −1, −0.8, …, 1 with width VIEW_SIGMA, then a constant 1.
const VIEW: u32 = 12u;
const VIEW_RBFS: u32 = 11u;
const VIEW_SIGMA: f32 = 0.5;
// A centre horizontally within this of the camera has view cosine 0 (`view_cosine`).
const VIEW_MIN_DISTANCE: f32 = 1e-6;

// One hypothesis: its expanded box's low corner and voxel size in the yaw's rotated frame, and its centre on
// the ground (s, t) for the view features.
struct FastRecord {
    lo: vec4<f32>,   // s, t, z, centre s
    cell: vec4<f32>, // voxel size along s, t, z, centre t
}

struct FastParams {
    grid: vec4<u32>,  // nx, ny, nz, dim (unused)
    job: vec4<u32>,   // hypothesis count, weight count, group bits (1 density, 2 normals, 4 cog, 8 view), boundary words per hypothesis
    table: vec4<u32>, // entries per table row (cells along s + 1), rows per layer (cells along t + 1), unused, unused
    scale: vec4<f32>, // fx, fy, 1 / cog_scale, unused
    m0: vec4<f32>,    // camera_from_rotated, column 0 (xyz)
    m1: vec4<f32>,    // column 1
    m2: vec4<f32>,    // column 2
    base: vec4<u32>,  // first vec4 of the table in `table`, first record, first boundary, first vec4 of the weights
    at: vec4<u32>,    // first score in `out`, unused, unused, unused
    view: vec4<f32>,  // the yaw's rotation to upright (cos, sin) and the boxes' front direction (x, y), upright
}

// This dispatch's record (a dynamic offset into the batch's records).
@group(0) @binding(0) var<uniform> params: FastParams;
// The batch's LayerTables, one vec4 per 4 channels (CHANNELS = 36 = 9 vec4 per entry).
@group(0) @binding(1) var<storage, read> table: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> records: array<FastRecord>;
// Per hypothesis: nx + 1 cell boundaries along s, then ny + 1 along t (voxel i covers cells xs[i]..xs[i+1]),
// two 16-bit boundaries per word, the lower half first (`boundary`).
@group(0) @binding(3) var<storage, read> bounds: array<u32>;
// The passes' weight vectors, each voxel padded to 36 (pad weight 0):
// weights[base.w + (w·voxels + ℓ)·9 + c] holds the weights of channels 4c..4c+3 of voxel ℓ; with the view
// group, weights[base.w + weight_count·voxels·9 + w·3 + c] those of view features 4c..4c+3 after them.
@group(0) @binding(4) var<storage, read> weights: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;

var<workgroup> partial: array<f32, 512>; // WORKGROUP × MAX_WEIGHTS

fn camera_point(q: vec3<f32>) -> vec3<f32> {
    return params.m0.xyz * q.x + params.m1.xyz * q.y + params.m2.xyz * q.z;
}

// Written out (not dot()) so the order of the additions is the CPU's.
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// The view cosine of a box centred at (s, t) on the ground (`view_cosine`: the centre turned upright, the
// unit direction from it to the camera, dotted with the front), with the CPU's operations in its order.
fn view_cosine(s: f32, t: f32) -> f32 {
    let x = s * params.view.x - t * params.view.y;
    let y = s * params.view.y + t * params.view.x;
    let to_camera = vec2<f32>(-x, -y);
    let length = sqrt(to_camera.x * to_camera.x + to_camera.y * to_camera.y);
    if (length < VIEW_MIN_DISTANCE) {
        return 0.0;
    }
    let inv_length = 1.0 / length;
    return params.view.z * (to_camera.x * inv_length) + params.view.w * (to_camera.y * inv_length);
}

// The view part of weight vector w's score: Σ_j weights_j · view_j over the VIEW features in order.
fn view_part(w: u32, weight_count: u32, voxels: u32, cosine: f32) -> f32 {
    let wb = params.base.w + weight_count * voxels * 9u + w * 3u;
    var acc = 0.0;
    for (var j = 0u; j < VIEW; j++) {
        var feature = 1.0;
        if (j < VIEW_RBFS) {
            let d = cosine - (-1.0 + 0.2 * f32(j));
            feature = exp(-(d * d) / (2.0 * VIEW_SIGMA * VIEW_SIGMA));
        }
        acc += weights[wb + j / 4u][j % 4u] * feature;
    }
    return acc;
}

// Boundary k of the hypothesis whose boundaries start at word b.
fn boundary(b: u32, k: u32) -> u32 {
    return (bounds[b + (k >> 1u)] >> ((k & 1u) * 16u)) & 0xffffu;
}

// acc + a·b, adding the four products one after the other (the CPU twin's order).
fn dot_acc(acc: f32, a: vec4<f32>, b: vec4<f32>) -> f32 {
    return (((acc + a.x * b.x) + a.y * b.y) + a.z * b.z) + a.w * b.w;
}

// Channels 4c..4c+3 of the voxel whose corners are the entries (in vec4 units) high, left, low, both.
fn sums(high: u32, left: u32, low: u32, both: u32, c: u32) -> vec4<u32> {
    return table[high + c] - table[left + c] - table[low + c] + table[both + c];
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) lid: u32) {
    let h = wg.x + wg.y * nwg.x;
    let nx = params.grid.x;
    let ny = params.grid.y;
    let nz = params.grid.z;
    let weight_count = params.job.y;
    let groups = params.job.z;
    let use_density = (groups & 1u) != 0u;
    let use_normals = (groups & 2u) != 0u;
    let use_cog = (groups & 4u) != 0u;
    let use_view = (groups & 8u) != 0u;
    // Uniform control flow up to the barriers: out-of-range work is masked, not returned from.
    let working = h < params.job.x;
    var my_partial: array<f32, 8>;

    if (working) {
        let record = records[params.base.y + h];
        let lo = record.lo.xyz;
        let cell = record.cell.xyz;
        let face_areas = vec3<f32>(cell.y * cell.z, cell.x * cell.z, cell.x * cell.y);
        let fx = params.scale.x;
        let fy = params.scale.y;
        let inv_cog_scale = params.scale.z;
        let b = params.base.z + h * params.job.w;
        let row = params.table.x;
        let voxels = nx * ny * nz;
        for (var v = lid; v < voxels; v += WORKGROUP) {
            let i = v % nx;
            let j = (v / nx) % ny;
            let k = v / (nx * ny);
            // Step 3: the voxel's sums, four corners of layer k (9 vec4 per entry).
            let x0 = boundary(b, i);
            let x1 = boundary(b, i + 1u);
            let y0 = boundary(b, nx + 1u + j);
            let y1 = boundary(b, nx + 1u + j + 1u);
            let layer = k * params.table.y;
            let high = params.base.x + ((layer + y1) * row + x1) * 9u;
            let left = params.base.x + ((layer + y1) * row + x0) * 9u;
            let low = params.base.x + ((layer + y0) * row + x1) * 9u;
            let both = params.base.x + ((layer + y0) * row + x0) * 9u;
            let s0 = sums(high, left, low, both, 0u);
            if (s0.x == 0u) {
                continue;
            }
            // Step 4: each channel's multiplier: 1/area for density and normal bins, 1/cog_scale times the
            // COG normalisation for COG bins, 0 for switched-off groups.
            var density = 0.0;
            var normal = 0.0;
            let centre = vec3<f32>(lo.x + (f32(i) + 0.5) * cell.x, lo.y + (f32(j) + 0.5) * cell.y,
                                   lo.z + (f32(k) + 0.5) * cell.z);
            let p = camera_point(centre);
            if (p.z >= MIN_PROJECT_DEPTH) {
                let area = fx * fy
                    * (face_areas.x * abs(dot3(params.m0.xyz, p)) + face_areas.y * abs(dot3(params.m1.xyz, p))
                       + face_areas.z * abs(dot3(params.m2.xyz, p)))
                    / (p.z * p.z * p.z);
                let inv_area = 1.0 / max(area, 1.0);
                density = select(0.0, inv_area, use_density);
                normal = select(0.0, inv_area, use_normals);
            }
            // COG bins are channels 26..34: s6.zw, s7, s8.xyz.
            let s6 = sums(high, left, low, both, 6u);
            let s7 = sums(high, left, low, both, 7u);
            let s8 = sums(high, left, low, both, 8u);
            var cog = 0.0;
            if (use_cog) {
                let g6 = vec4<f32>(s6) * inv_cog_scale;
                let g7 = vec4<f32>(s7) * inv_cog_scale;
                let g8 = vec4<f32>(s8) * inv_cog_scale;
                var norm_sq = 0.0;
                norm_sq += g6.z * g6.z;
                norm_sq += g6.w * g6.w;
                norm_sq += g7.x * g7.x;
                norm_sq += g7.y * g7.y;
                norm_sq += g7.z * g7.z;
                norm_sq += g7.w * g7.w;
                norm_sq += g8.x * g8.x;
                norm_sq += g8.y * g8.y;
                norm_sq += g8.z * g8.z;
                // (sum · 2⁻ⁿ) · scale = sum · (2⁻ⁿ · scale) exactly: 1/cog_scale is a power of two.
                cog = inv_cog_scale * (1.0 / sqrt(norm_sq + COG_EPSILON));
            }
            let f0 = vec4<f32>(s0) * vec4<f32>(density, normal, normal, normal);
            let f1 = vec4<f32>(sums(high, left, low, both, 1u)) * normal;
            let f2 = vec4<f32>(sums(high, left, low, both, 2u)) * normal;
            let f3 = vec4<f32>(sums(high, left, low, both, 3u)) * normal;
            let f4 = vec4<f32>(sums(high, left, low, both, 4u)) * normal;
            let f5 = vec4<f32>(sums(high, left, low, both, 5u)) * normal;
            let f6 = vec4<f32>(s6) * vec4<f32>(normal, normal, cog, cog);
            let f7 = vec4<f32>(s7) * cog;
            let f8 = vec4<f32>(s8) * vec4<f32>(cog, cog, cog, 0.0);
            // Constant trip count (unrolled by the driver): my_partial stays in registers.
            for (var w = 0u; w < MAX_WEIGHTS; w++) {
                if (w < weight_count) {
                    let wb = params.base.w + (w * voxels + v) * 9u;
                    var acc = 0.0;
                    acc = dot_acc(acc, weights[wb], f0);
                    acc = dot_acc(acc, weights[wb + 1u], f1);
                    acc = dot_acc(acc, weights[wb + 2u], f2);
                    acc = dot_acc(acc, weights[wb + 3u], f3);
                    acc = dot_acc(acc, weights[wb + 4u], f4);
                    acc = dot_acc(acc, weights[wb + 5u], f5);
                    acc = dot_acc(acc, weights[wb + 6u], f6);
                    acc = dot_acc(acc, weights[wb + 7u], f7);
                    acc = dot_acc(acc, weights[wb + 8u], f8);
                    my_partial[w] += acc;
                }
            }
        }
    }

    for (var w = 0u; w < MAX_WEIGHTS; w++) {
        partial[lid * MAX_WEIGHTS + w] = my_partial[w];
    }
    workgroupBarrier();
    // Fixed tree: partial[l] += partial[l + stride] for stride 32, 16, …, 1.
    for (var stride = WORKGROUP / 2u; stride > 0u; stride = stride / 2u) {
        if (lid < stride) {
            for (var w = 0u; w < MAX_WEIGHTS; w++) {
                partial[lid * MAX_WEIGHTS + w] += partial[(lid + stride) * MAX_WEIGHTS + w];
            }
        }
        workgroupBarrier();
    }
    if (lid == 0u && working) {
        let record = records[params.base.y + h];
        let cosine = view_cosine(record.lo.w, record.cell.w);
        let voxels = nx * ny * nz;
        for (var w = 0u; w < weight_count; w++) {
            var score = partial[w];
            if (use_view) {
                score += view_part(w, weight_count, voxels, cosine);
            }
            out[params.at.x + h * weight_count + w] = score;
        }
    }
}
