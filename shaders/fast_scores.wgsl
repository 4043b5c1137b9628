// Fused scores of the fast path (src/features/fast.rs, steps 3–4) from one summed-area LayerTable.
// CPU twin: `fast_scores_main` in src/gpu/fast.rs (same names, same loops, same order of the additions).
//
// One dispatch per dispatch record (one table group × chunk × weight pass), all through one bind group: the
// record is a uniform bound at a dynamic offset of the batch's records buffer, and says where its table,
// hypotheses, boundaries, weights and scores lie in the batch's shared buffers. (A single dispatch for the
// whole batch, each workgroup searching its record in a storage array, was tried: its scoring pass was no
// faster on an H200 — 0.12 s per frame against 0.11–0.14 s with one dispatch per record — nor on
// lavapipe.) One invocation per hypothesis (64 hypotheses per workgroup; no workgroup memory, no barrier). It
// visits the voxels in the layout's order ℓ = (k·ny + j)·nx + i, row by row: each voxel's channel sums are
// four table corners (u32 wrapping differences: exact whatever the order), and along a row the right
// corners of one voxel are the left corners of the next, read once. It finalises the 35 features (density
// and normal bins over the linearised projected area, normalised COG; an empty voxel contributes nothing)
// and adds each voxel's dot product with each weight vector of the pass to that vector's score, in voxel
// order, so the result is the same bits on every run. Then the view part (group bit 8): the view cosine of
// the box's centre, its VIEW_RBFS radial basis functions and the bias, dotted with the pass's view
// weights — after the voxels, as `FastEngine::scores` adds it.
//
// Shaped for lavapipe (CI's device; `gpu::TexelRows` has the measurements) as much as for GPUs: the
// tables, boundaries and weights are textures (lavapipe runs storage-buffer loads lane by lane, texture
// reads as gathers); no barriers (each workgroup is a set of coroutines there, each barrier a switch);
// the loop over weights has the pass's length (lavapipe executes masked-off iterations and `if` bodies
// too); everything is vec4 and the corner channels are named struct fields, not dynamically indexed
// arrays (which lavapipe keeps in memory; only the pass's scores are one, touched once per voxel and
// weight vector).
//
// Loops are short (the voxels of a row, the rows, the layers, ≤ MAX_WEIGHTS weights): far from gallivm's
// 65535-iteration cap (see shaders/features.wgsl).

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
// The batch's LayerTables, one vec4 per 4 channels (CHANNELS = 36 = 9 vec4 per entry), element n at
// `texel(n)`: a copy of the tables' storage buffer (lavapipe reads storage buffers lane by lane, textures
// with vectorised gathers; `gpu::TexelRows`).
@group(0) @binding(1) var table: texture_2d<u32>;
@group(0) @binding(2) var<storage, read> records: array<FastRecord>;
// Per hypothesis: nx + 1 cell boundaries along s, then ny + 1 along t (voxel i covers cells xs[i]..xs[i+1]),
// two 16-bit boundaries per word, the lower half first (`boundary`); four words per texel, word n in
// component n % 4 of element n / 4 (a texture, as the tables).
@group(0) @binding(3) var bounds: texture_2d<u32>;
// The passes' weight vectors, each voxel padded to 36 (pad weight 0):
// weight(base.w + (w·voxels + ℓ)·9 + c) holds the weights of channels 4c..4c+3 of voxel ℓ; with the view
// group, weight(base.w + weight_count·voxels·9 + w·3 + c) those of view features 4c..4c+3 after them.
// Element n at `texel(n)`, as the tables.
@group(0) @binding(4) var weights: texture_2d<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;


// Texels per row of the `table` and `weights` textures (`gpu::TexelRows::WIDTH`).
const TEXELS_PER_ROW: u32 = 8192u;

// The texel that holds vec4 element n of a buffer copied into a texture TEXELS_PER_ROW wide.
fn texel(n: u32) -> vec2<u32> {
    return vec2<u32>(n % TEXELS_PER_ROW, n / TEXELS_PER_ROW);
}

fn table_entry(n: u32) -> vec4<u32> {
    return textureLoad(table, texel(n), 0);
}

fn weight(n: u32) -> vec4<f32> {
    return textureLoad(weights, texel(n), 0);
}

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
        acc += weight(wb + j / 4u)[j % 4u] * feature;
    }
    return acc;
}

// Boundary k of the hypothesis whose boundaries start at word b.
fn boundary(b: u32, k: u32) -> u32 {
    let word = b + (k >> 1u);
    return (textureLoad(bounds, texel(word / 4u), 0)[word % 4u] >> ((k & 1u) * 16u)) & 0xffffu;
}

// acc + a·b, adding the four products one after the other (the CPU twin's order).
fn dot_acc(acc: f32, a: vec4<f32>, b: vec4<f32>) -> f32 {
    return (((acc + a.x * b.x) + a.y * b.y) + a.z * b.z) + a.w * b.w;
}

// One table entry: the 36 channels of a corner, as 9 vec4.
struct Corner {
    c0: vec4<u32>,
    c1: vec4<u32>,
    c2: vec4<u32>,
    c3: vec4<u32>,
    c4: vec4<u32>,
    c5: vec4<u32>,
    c6: vec4<u32>,
    c7: vec4<u32>,
    c8: vec4<u32>,
}

// The entry whose first vec4 is element e.
fn corner(e: u32) -> Corner {
    return Corner(table_entry(e), table_entry(e + 1u), table_entry(e + 2u), table_entry(e + 3u), table_entry(e + 4u),
                  table_entry(e + 5u), table_entry(e + 6u), table_entry(e + 7u), table_entry(e + 8u));
}

// A voxel's channel sums from its four corners (u32 wrapping: exact in any order).
fn sums(high: vec4<u32>, left: vec4<u32>, low: vec4<u32>, both: vec4<u32>) -> vec4<u32> {
    return high - left - low + both;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let h = gid.x + gid.y * nwg.x * WORKGROUP;
    if (h >= params.job.x) {
        return;
    }
    let nx = params.grid.x;
    let ny = params.grid.y;
    let nz = params.grid.z;
    let weight_count = params.job.y;
    let groups = params.job.z;
    let use_density = (groups & 1u) != 0u;
    let use_normals = (groups & 2u) != 0u;
    let use_cog = (groups & 4u) != 0u;
    let use_view = (groups & 8u) != 0u;
    var score: array<f32, MAX_WEIGHTS>;

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
    // The voxels in the layout's order ℓ = (k·ny + j)·nx + i.
    for (var k = 0u; k < nz; k++) {
        let layer = k * params.table.y;
        for (var j = 0u; j < ny; j++) {
            let y0 = boundary(b, nx + 1u + j);
            let y1 = boundary(b, nx + 1u + j + 1u);
            // Step 3: a voxel's sums from four corners of layer k (9 vec4 per entry); along a row of voxels
            // each voxel's right corners are the next one's left corners, read once.
            let x_first = boundary(b, 0u);
            var left = corner(params.base.x + ((layer + y1) * row + x_first) * 9u);
            var both = corner(params.base.x + ((layer + y0) * row + x_first) * 9u);
            for (var i = 0u; i < nx; i++) {
                let v = (k * ny + j) * nx + i;
                let x1 = boundary(b, i + 1u);
                let high = corner(params.base.x + ((layer + y1) * row + x1) * 9u);
                let low = corner(params.base.x + ((layer + y0) * row + x1) * 9u);
                let s0 = sums(high.c0, left.c0, low.c0, both.c0);
                if (s0.x == 0u) {
                    left = high;
                    both = low;
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
                let s6 = sums(high.c6, left.c6, low.c6, both.c6);
                let s7 = sums(high.c7, left.c7, low.c7, both.c7);
                let s8 = sums(high.c8, left.c8, low.c8, both.c8);
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
                let f1 = vec4<f32>(sums(high.c1, left.c1, low.c1, both.c1)) * normal;
                let f2 = vec4<f32>(sums(high.c2, left.c2, low.c2, both.c2)) * normal;
                let f3 = vec4<f32>(sums(high.c3, left.c3, low.c3, both.c3)) * normal;
                let f4 = vec4<f32>(sums(high.c4, left.c4, low.c4, both.c4)) * normal;
                let f5 = vec4<f32>(sums(high.c5, left.c5, low.c5, both.c5)) * normal;
                let f6 = vec4<f32>(s6) * vec4<f32>(normal, normal, cog, cog);
                let f7 = vec4<f32>(s7) * cog;
                let f8 = vec4<f32>(s8) * vec4<f32>(cog, cog, cog, 0.0);
                // A loop of the pass's length (not MAX_WEIGHTS with the rest masked: lavapipe runs masked
                // work too). Each voxel's product is added to the score on its own, in voxel order.
                for (var w = 0u; w < weight_count; w++) {
                    let wb = params.base.w + (w * voxels + v) * 9u;
                    var acc = 0.0;
                    acc = dot_acc(acc, weight(wb), f0);
                    acc = dot_acc(acc, weight(wb + 1u), f1);
                    acc = dot_acc(acc, weight(wb + 2u), f2);
                    acc = dot_acc(acc, weight(wb + 3u), f3);
                    acc = dot_acc(acc, weight(wb + 4u), f4);
                    acc = dot_acc(acc, weight(wb + 5u), f5);
                    acc = dot_acc(acc, weight(wb + 6u), f6);
                    acc = dot_acc(acc, weight(wb + 7u), f7);
                    acc = dot_acc(acc, weight(wb + 8u), f8);
                    score[w] += acc;
                }
                left = high;
                both = low;
            }
        }
    }
    let cosine = view_cosine(record.lo.w, record.cell.w);
    for (var w = 0u; w < weight_count; w++) {
        var total = score[w];
        if (use_view) {
            total += view_part(w, weight_count, voxels, cosine);
        }
        out[params.at.x + h * weight_count + w] = total;
    }
}
