// Features of cuboid hypotheses (density, normal histogram, COG, view) and fused scoring.
// CPU twin: src/features/cpu.rs (same stages and names; read its module doc for the definitions).
//
// One workgroup per hypothesis, one invocation per voxel column (i, j) (local index = j·nx + i). Every
// voxel has exactly one writer, so the accumulators live in the invocation's private memory: no atomics,
// and the fixed-point integer sums make the result independent of the summation order and bit-identical
// across runs. Points are found through the yaw's bucket grid: for each bucket row covering the column,
// one contiguous record range.
//
// mode 0: write the feature vectors (out[h·dim + …]); mode 1: dot them with `weight_count` weight vectors
// (out[h·weight_count + w]) without writing them. inside[h] = points inside the expanded box.

const MAX_Z: u32 = 9u;
const NORMAL_BINS: u32 = 25u;
const COG_BINS: u32 = 9u;
const PER_VOXEL: u32 = 35u;
const COG_OFFSET: u32 = 26u;
const VIEW: u32 = 12u;
const MAX_COLUMNS: u32 = 64u;
const MAX_WEIGHTS: u32 = 8u;
const PI: f32 = 3.14159265358979;
const COG_FIXED_SCALE: f32 = 1048576.0;
const EDGE_ON_SIN: f32 = 1e-3;
const MIN_PROJECT_DEPTH: f32 = 1e-3;
const COG_EPSILON: f32 = 0.01;
const BUCKET_MARGIN: f32 = 1e-4;
const VIEW_SIGMA: f32 = 0.5;

struct PointRecord {
    s: i32,   // fixed point, 2^16 per metre
    t: i32,
    z: i32,
    normal_bin: u32,
    gx: f32,
    gy: f32,
    magnitude: f32,
    pad: u32,
}

struct Hypothesis {
    lo_view: vec4<f32>,   // lo (s, t, z), view cosine
    cell: vec4<f32>,      // voxel size (s, t, z), unused
    lo_fixed: vec4<i32>,  // lo in fixed point (s, t, z), unused
    extent_fixed: vec4<i32>, // extent of the expanded box in fixed point, unused
}

struct Params {
    grid: vec4<u32>,        // nx, ny, nz, dim
    job: vec4<u32>,         // hypothesis count, weight count, mode, group bits (1 density, 2 normals, 4 cog, 8 view)
    buckets: vec4<u32>,     // bucket cells along s, along t, unused, unused
    bucket_geom: vec4<f32>, // origin s, origin t, inverse step, unused
    intrinsics: vec4<f32>,  // fx, fy, unused, unused
    m0: vec4<f32>,          // camera_from_rotated, column 0 (xyz)
    m1: vec4<f32>,          // column 1
    m2: vec4<f32>,          // column 2
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> points: array<PointRecord>;
@group(0) @binding(2) var<storage, read> cell_start: array<u32>;
@group(0) @binding(3) var<storage, read> hyps: array<Hypothesis>;
@group(0) @binding(4) var<storage, read> weights: array<f32>;
@group(0) @binding(5) var<storage, read_write> out: array<f32>;
@group(0) @binding(6) var<storage, read_write> inside: array<u32>;

var<workgroup> partial: array<f32, 512>; // MAX_COLUMNS × MAX_WEIGHTS

// Per-invocation accumulators of the column (stage 3), zero at the start of every invocation.
var<private> count: array<u32, 9>;
var<private> normals: array<u32, 225>;
var<private> cog_lo: array<u32, 81>;
var<private> cog_hi: array<u32, 81>;
var<private> frames: array<vec4<f32>, 9>;
var<private> frame_valid: array<bool, 9>;
var<private> my_inside: u32;

// Job constants of the current hypothesis and column, set before the point loop.
var<private> cur_lo_fixed: vec3<i32>;
var<private> cur_extent_fixed: vec3<i32>;
var<private> cur_column: vec2<i32>;
var<private> cur_use_cog: bool;

// Stage 3 for one point record.
fn accumulate_point(n: u32) {
    let r = points[n];
    let k = axis_index(r.z, cur_lo_fixed.z, cur_extent_fixed.z, params.grid.z);
    if (k < 0) {
        return;
    }
    if (axis_index(r.s, cur_lo_fixed.x, cur_extent_fixed.x, params.grid.x) != cur_column.x
        || axis_index(r.t, cur_lo_fixed.y, cur_extent_fixed.y, params.grid.y) != cur_column.y) {
        return;
    }
    let ku = u32(k);
    my_inside += 1u;
    count[ku] += 1u;
    normals[ku * NORMAL_BINS + r.normal_bin] += 1u;
    if (cur_use_cog && r.magnitude > 0.0 && frame_valid[ku]) {
        let fr = frames[ku];
        let ex = -r.gy;
        let ey = r.gx;
        let alpha = fr.w * ex - fr.z * ey;
        let beta = fr.x * ey - fr.y * ex;
        let phi = unsigned_angle(alpha, -beta);
        let position = phi * (f32(COG_BINS) / PI);
        let bin0 = min(u32(floor(position)), COG_BINS - 1u);
        let frac = position - f32(bin0);
        let bin1 = (bin0 + 1u) % COG_BINS;
        let scaled = r.magnitude * COG_FIXED_SCALE;
        let share1 = u32(frac * scaled + 0.5);
        let share0 = u32((1.0 - frac) * scaled + 0.5);
        let i0 = ku * COG_BINS + bin0;
        let old0 = cog_lo[i0];
        cog_lo[i0] = old0 + share0;
        if (cog_lo[i0] < old0) {
            cog_hi[i0] += 1u;
        }
        let i1 = ku * COG_BINS + bin1;
        let old1 = cog_lo[i1];
        cog_lo[i1] = old1 + share1;
        if (cog_lo[i1] < old1) {
            cog_hi[i1] += 1u;
        }
    }
}

// Points per iteration of the point loop. Lavapipe (gallivm) caps the total iterations of all loops of
// one shader invocation at 65535 and silently leaves the loop after that; handling 16 points per
// iteration keeps a column of up to ~10⁶ points under the cap.
const POINTS_PER_ITERATION: u32 = 16u;
var<workgroup> column_inside: array<u32, 64>;

fn camera_point(q: vec3<f32>) -> vec3<f32> {
    return params.m0.xyz * q.x + params.m1.xyz * q.y + params.m2.xyz * q.z;
}

// Stage 2: projected COG basis (da.xy, dz.xy) of the voxel centred at q; valid = false when degenerate.
struct CogFrame {
    basis: vec4<f32>,
    valid: bool,
}

fn image_direction(p: vec3<f32>, d: vec3<f32>, inv_z2: f32) -> vec2<f32> {
    return vec2<f32>(params.intrinsics.x * (d.x * p.z - p.x * d.z) * inv_z2,
                     params.intrinsics.y * (d.y * p.z - p.y * d.z) * inv_z2);
}

fn cog_frame(centre: vec3<f32>) -> CogFrame {
    var frame: CogFrame;
    frame.valid = false;
    let p = camera_point(centre);
    if (p.z < MIN_PROJECT_DEPTH) {
        return frame;
    }
    let inv_z2 = 1.0 / (p.z * p.z);
    let da = image_direction(p, params.m0.xyz, inv_z2);
    let dz = image_direction(p, params.m2.xyz, inv_z2);
    let cross_az = da.x * dz.y - da.y * dz.x;
    let scale = length(da) * length(dz);
    if (!(abs(cross_az) >= EDGE_ON_SIN * scale) || scale == 0.0) {
        return frame;
    }
    frame.basis = vec4<f32>(da, dz);
    frame.valid = true;
    return frame;
}

// Voxel index along one axis, or -1 when outside the box (integer arithmetic: exact on every device).
fn axis_index(p: i32, lo: i32, extent: i32, n: u32) -> i32 {
    let d = p - lo;
    if (d >= 0 && d < extent) {
        return d * i32(n) / extent;
    }
    return -1;
}

// Inclusive bucket range along one axis covering [lo, hi]; x > y when it misses the grid.
fn cell_range(origin: f32, n: u32, lo: f32, hi: f32) -> vec2<i32> {
    let inv_step = params.bucket_geom.z;
    let first = floor((lo - BUCKET_MARGIN - origin) * inv_step);
    let last = floor((hi + BUCKET_MARGIN - origin) * inv_step);
    let nf = f32(n);
    if (last < 0.0 || first >= nf) {
        return vec2<i32>(1, 0);
    }
    return vec2<i32>(i32(max(first, 0.0)), i32(min(last, nf - 1.0)));
}

// atan2(y, x) mod π in [0, π) with the CPU twin's polynomial (the driver's atan2 may be off by 4096 ulp).
fn unsigned_angle(y: f32, x: f32) -> f32 {
    let ax = abs(x);
    let ay = abs(y);
    let lo = min(ax, ay);
    let hi = max(ax, ay);
    if (hi == 0.0) {
        return 0.0;
    }
    let t = lo / hi;
    let t2 = t * t;
    let poly = ((((-0.0117212 * t2 + 0.05265332) * t2 - 0.11643287) * t2 + 0.19354346) * t2 - 0.33262347) * t2
        + 0.99997726;
    var angle = poly * t;
    if (ay > ax) {
        angle = PI / 2.0 - angle;
    }
    if (x < 0.0) {
        angle = PI - angle;
    }
    if (y < 0.0) {
        angle = PI - angle;
    }
    if (angle >= PI) {
        angle -= PI;
    }
    return angle;
}

fn fixed_to_f32(hi: u32, lo: u32) -> f32 {
    return f32(hi) * 4096.0 + f32(lo) * (1.0 / COG_FIXED_SCALE);
}

// Silhouette area (pixels²) of the box [a, b] in the rotated frame: half the summed |area| of its six
// projected faces (front and back faces each tile the silhouette once). Negative when a corner is within
// MIN_PROJECT_DEPTH of the camera plane or behind it.
fn silhouette_area(a: vec3<f32>, b: vec3<f32>) -> f32 {
    var image: array<vec2<f32>, 8>;
    for (var c = 0u; c < 8u; c++) {
        let q = vec3<f32>(select(a.x, b.x, (c & 1u) != 0u), select(a.y, b.y, (c & 2u) != 0u), select(a.z, b.z, (c & 4u) != 0u));
        let p = camera_point(q);
        if (p.z < MIN_PROJECT_DEPTH) {
            return -1.0;
        }
        image[c] = vec2<f32>(params.intrinsics.x * p.x / p.z, params.intrinsics.y * p.y / p.z);
    }
    // Faces as corner cycles: s = lo, s = hi, t = lo, t = hi, z = lo, z = hi.
    let faces = array<vec4<u32>, 6>(
        vec4<u32>(0u, 2u, 6u, 4u), vec4<u32>(1u, 3u, 7u, 5u), vec4<u32>(0u, 1u, 5u, 4u),
        vec4<u32>(2u, 3u, 7u, 6u), vec4<u32>(0u, 1u, 3u, 2u), vec4<u32>(4u, 5u, 7u, 6u));
    var total = 0.0;
    for (var f = 0u; f < 6u; f++) {
        let v = faces[f];
        var twice = 0.0;
        for (var e = 0u; e < 4u; e++) {
            let p = image[v[e]];
            let q = image[v[(e + 1u) % 4u]];
            twice += p.x * q.y - p.y * q.x;
        }
        total += abs(0.5 * twice);
    }
    return 0.5 * total;
}

@compute @workgroup_size(64)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
        @builtin(local_invocation_index) column: u32) {
    let h = wg.x + wg.y * nwg.x;
    let nx = params.grid.x;
    let ny = params.grid.y;
    let nz = params.grid.z;
    let dim = params.grid.w;
    let weight_count = params.job.y;
    let mode = params.job.z;
    let groups = params.job.w;
    let use_density = (groups & 1u) != 0u;
    let use_normals = (groups & 2u) != 0u;
    let use_cog = (groups & 4u) != 0u;
    let use_view = (groups & 8u) != 0u;
    // Uniform control flow up to the barrier: out-of-range work is masked, not returned from.
    let working = h < params.job.x && column < nx * ny;
    var my_partial: array<f32, 8>;

    if (working) {
        let hyp = hyps[h];
        let lo = hyp.lo_view.xyz;
        let cell = hyp.cell.xyz;
        let i = column % nx;
        let j = column / nx;

        // Stage 2: COG bases of the column's voxels.
        if (use_cog) {
            for (var k = 0u; k < nz; k++) {
                let centre = lo + (vec3<f32>(f32(i), f32(j), f32(k)) + 0.5) * cell;
                let frame = cog_frame(centre);
                frames[k] = frame.basis;
                frame_valid[k] = frame.valid;
            }
        }

        // Stage 3: accumulate.
        cur_lo_fixed = hyp.lo_fixed.xyz;
        cur_extent_fixed = hyp.extent_fixed.xyz;
        cur_column = vec2<i32>(i32(i), i32(j));
        cur_use_cog = use_cog;
        let s_lo = lo.x + f32(i) * cell.x;
        let t_lo = lo.y + f32(j) * cell.y;
        let s_cells = cell_range(params.bucket_geom.x, params.buckets.x, s_lo, s_lo + cell.x);
        let t_cells = cell_range(params.bucket_geom.y, params.buckets.y, t_lo, t_lo + cell.y);
        if (s_cells.x <= s_cells.y && t_cells.x <= t_cells.y) {
            for (var row = u32(t_cells.x); row <= u32(t_cells.y); row++) {
                let base = row * params.buckets.x;
                let first = cell_start[base + u32(s_cells.x)];
                let end = cell_start[base + u32(s_cells.y) + 1u];
                for (var n = first; n < end; n += POINTS_PER_ITERATION) {
                    accumulate_point(n);
                    if (n + 1u < end) { accumulate_point(n + 1u); }
                    if (n + 2u < end) { accumulate_point(n + 2u); }
                    if (n + 3u < end) { accumulate_point(n + 3u); }
                    if (n + 4u < end) { accumulate_point(n + 4u); }
                    if (n + 5u < end) { accumulate_point(n + 5u); }
                    if (n + 6u < end) { accumulate_point(n + 6u); }
                    if (n + 7u < end) { accumulate_point(n + 7u); }
                    if (n + 8u < end) { accumulate_point(n + 8u); }
                    if (n + 9u < end) { accumulate_point(n + 9u); }
                    if (n + 10u < end) { accumulate_point(n + 10u); }
                    if (n + 11u < end) { accumulate_point(n + 11u); }
                    if (n + 12u < end) { accumulate_point(n + 12u); }
                    if (n + 13u < end) { accumulate_point(n + 13u); }
                    if (n + 14u < end) { accumulate_point(n + 14u); }
                    if (n + 15u < end) { accumulate_point(n + 15u); }
                }
            }
        }

        // Stage 4: finalise each voxel of the column; write it or dot it.
        for (var k = 0u; k < nz; k++) {
            var feature: array<f32, 35>;
            if (count[k] > 0u) {
                let a = lo + vec3<f32>(f32(i), f32(j), f32(k)) * cell;
                let area = silhouette_area(a, a + cell);
                if (area >= 0.0) {
                    let inv_area = 1.0 / max(area, 1.0);
                    if (use_density) {
                        feature[0] = f32(count[k]) * inv_area;
                    }
                    if (use_normals) {
                        for (var b = 0u; b < NORMAL_BINS; b++) {
                            feature[1u + b] = f32(normals[k * NORMAL_BINS + b]) * inv_area;
                        }
                    }
                }
                if (use_cog) {
                    var norm_sq = 0.0;
                    for (var b = 0u; b < COG_BINS; b++) {
                        let v = fixed_to_f32(cog_hi[k * COG_BINS + b], cog_lo[k * COG_BINS + b]);
                        feature[COG_OFFSET + b] = v;
                        norm_sq += v * v;
                    }
                    let scale = 1.0 / sqrt(norm_sq + COG_EPSILON);
                    for (var b = 0u; b < COG_BINS; b++) {
                        feature[COG_OFFSET + b] = feature[COG_OFFSET + b] * scale;
                    }
                }
            }
            let offset = ((k * ny + j) * nx + i) * PER_VOXEL;
            if (mode == 0u) {
                let base = h * dim + offset;
                for (var f = 0u; f < PER_VOXEL; f++) {
                    out[base + f] = feature[f];
                }
            } else if (count[k] > 0u) {
                for (var w = 0u; w < weight_count; w++) {
                    let wbase = w * dim + offset;
                    var acc = 0.0;
                    for (var f = 0u; f < PER_VOXEL; f++) {
                        acc += weights[wbase + f] * feature[f];
                    }
                    my_partial[w] += acc;
                }
            }
        }
    }

    column_inside[column] = my_inside;
    for (var w = 0u; w < MAX_WEIGHTS; w++) {
        partial[column * MAX_WEIGHTS + w] = my_partial[w];
    }
    workgroupBarrier();

    if (column == 0u && h < params.job.x) {
        // Stage 5: view features, totals, in column order (deterministic).
        var view: array<f32, 12>;
        if (use_view) {
            let x = hyps[h].lo_view.w;
            for (var v = 0u; v < 11u; v++) {
                let d = x - (-1.0 + 0.2 * f32(v));
                view[v] = exp(-(d * d) / (2.0 * VIEW_SIGMA * VIEW_SIGMA));
            }
            view[11] = 1.0;
        }
        var total_inside = 0u;
        for (var c = 0u; c < nx * ny; c++) {
            total_inside += column_inside[c];
        }
        inside[h] = total_inside;
        let view_offset = nx * ny * nz * PER_VOXEL;
        if (mode == 0u) {
            for (var v = 0u; v < VIEW; v++) {
                out[h * dim + view_offset + v] = view[v];
            }
        } else {
            for (var w = 0u; w < weight_count; w++) {
                var score = 0.0;
                for (var c = 0u; c < nx * ny; c++) {
                    score += partial[c * MAX_WEIGHTS + w];
                }
                for (var v = 0u; v < VIEW; v++) {
                    score += weights[w * dim + view_offset + v] * view[v];
                }
                out[h * weight_count + w] = score;
            }
        }
    }
}
