//! The fast-path scoring kernel (`shaders/fast_scores.wgsl`): fused scores `w·φ(h)` of many hypotheses from
//! the fast path's summed-area tables — steps 3–4 of [`crate::features::fast`] on the GPU.
//!
//! # Design
//! Steps 1–2 (the per-yaw lattices and the per-(yaw, bottom, height) [`LayerTable`]s) stay on the CPU, built
//! by the [`FastEngine`]'s own code. Hypotheses are grouped by table (the engine's grouping); each table
//! is uploaded once and its hypotheses are dispatched in chunks of at most [`MAX_CHUNK`] (fewer when the
//! device's storage-binding limit asks for it), with up to [`MAX_WEIGHTS`] weight vectors per pass.
//!
//! Per hypothesis the CPU packs a [`FastRecord`] (low corner and voxel size of the expanded box) and the
//! `nx + 1 + ny + 1` voxel-boundary cell indices, computed by the engine's own membership rule
//! (`FastEngine::voxel_boundaries`, the function its scoring uses), so cell membership is identical by
//! construction. The shader runs one workgroup of 64 invocations per hypothesis; invocation `lid` takes
//! the voxels `ℓ = lid + 64·r` in the layout's order, differences four table corners with wrapping `u32`
//! arithmetic (exact, as on the CPU), finalises the 35 features as `FastEngine::scores` does (density
//! and normal bins over the linearised projected area, COG normalised `φ/√(‖φ‖² + ε)`, switched-off
//! groups and empty voxels contributing nothing) and dots them with the weights. The 64 partial scores are
//! reduced in workgroup memory in a fixed tree order: results are bit-identical run to run.
//!
//! **Choice: the view features are added on the CPU** ([`FastEngine`]'s own `view`, 12 numbers per
//! hypothesis), after the voxel part comes back, in the same order as `FastEngine::scores` (voxels first,
//! then view). This keeps `exp` out of the shader and the view part identical to the CPU path.
//!
//! A table larger than the storage-binding limit (128 MiB on lavapipe; ~40 MB for a 10 m × 10 m room at
//! the default lattice) is an [`Error::Gpu`]; callers fall back to the CPU path.
//!
//! # CPU twin
//! [`fast_scores_main`] is the shader's entry point in Rust (same names, same loop order, same
//! reduction tree), run over every workgroup by [`fast_scores_reference`], which packs its inputs with the
//! same code as [`fast_scores_gpu`]. It differs from `FastEngine::scores` only in the order of the float
//! additions (the engine sums the voxels in order ℓ), so the three agree to ~1e-6 relative.

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

use super::{BufferBinding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::cpu::{dot, HypothesisRecord};
use crate::features::fast::{group_by_table, FastEngine, LayerTable, CHANNELS};
use crate::features::feature_layout::{FeatureLayout, COG, COG_BINS, COG_EPSILON, NORMALS, PER_VOXEL, VIEW};
use crate::features::preprocess::NORMAL_BINS;
use crate::features::Hypothesis;
use crate::geometry::MIN_PROJECT_DEPTH;

/// The kernel's spec (registered in [`super::Kernels`]).
pub const KERNEL: KernelSpec = KernelSpec {
    label: "fast_scores",
    source: include_str!("../../shaders/fast_scores.wgsl"),
    entry_point: "main",
    bindings: &[
        BufferBinding::Uniform,
        BufferBinding::StorageRead,
        BufferBinding::StorageRead,
        BufferBinding::StorageRead,
        BufferBinding::StorageRead,
        BufferBinding::StorageReadWrite,
    ],
};

/// Weight vectors scored per dispatch (the shader's `MAX_WEIGHTS`); more are done in several passes.
pub const MAX_WEIGHTS: usize = 8;
/// Invocations per workgroup (the shader's `WORKGROUP`): one workgroup per hypothesis.
pub const WORKGROUP: usize = 64;
/// Largest number of hypotheses per dispatch.
pub const MAX_CHUNK: usize = 1 << 16;

/// Twin of WGSL `struct FastParams` in `shaders/fast_scores.wgsl`: one dispatch (one table, one chunk of
/// hypotheses, one pass of weight vectors).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FastParams {
    /// nx, ny, nz, dim.
    pub grid: [u32; 4],
    /// Hypothesis count, weight count, group bits (1 density, 2 normals, 4 cog), boundaries per hypothesis.
    pub job: [u32; 4],
    /// Entries per table row (cells along s + 1), rows per layer (cells along t + 1), unused, unused.
    pub table: [u32; 4],
    /// fx, fy, 1 / cog_scale, unused.
    pub scale: [f32; 4],
    /// `camera_from_rotated` of the yaw, columns 0–2 (xyz, w unused).
    pub m0: [f32; 4],
    pub m1: [f32; 4],
    pub m2: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<FastParams>() == 112);

/// Twin of WGSL `struct FastRecord`: one hypothesis's expanded box in the yaw's rotated frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FastRecord {
    /// Low corner (s, t, z), unused.
    pub lo: [f32; 4],
    /// Voxel size along (s, t, z), unused.
    pub cell: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<FastRecord>() == 32);
// The shader hard-codes the channel layout of a table entry as 9 vec4: count and normal bins 0–2, normal
// bins 3–22, normal bins 23–24 and COG bins 0–1, COG bins 2–5, COG bins 6–8 and the pad.
const _: () =
    assert!(CHANNELS == 36 && PER_VOXEL == 35 && NORMALS == 1 && NORMAL_BINS == 25 && COG == 26 && COG_BINS == 9);

/// Group bits of the shader (the view group is the CPU's, see the module doc).
fn group_bits(layout: &FeatureLayout) -> u32 {
    let g = layout.groups;
    u32::from(g.density) | (u32::from(g.normals) << 1) | (u32::from(g.cog) << 2)
}

/// One dispatch's inputs, exactly what the shader binds.
pub struct FastDispatch<'a> {
    /// Index of the table group (dispatches of one group share the table).
    pub group: usize,
    /// Index of the weight pass (dispatches of one pass share the weights).
    pub pass: usize,
    pub params: FastParams,
    /// The whole [`LayerTable`], `u32` words.
    pub table: &'a [u32],
    pub records: &'a [FastRecord],
    /// `params.job[3]` boundaries per hypothesis.
    pub bounds: &'a [u32],
    /// The pass's weight vectors without the view part, each voxel padded to [`CHANNELS`] with a zero:
    /// `params.job[1] × voxels × CHANNELS`.
    pub weights: &'a [f32],
}

/// Packs every dispatch and runs it with `execute` (GPU or CPU twin), which returns the
/// `records.len() × weight count` voxel scores; adds the view part on the CPU and returns
/// `scores[h·W + w]`.
fn run(
    engine: &FastEngine,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    max_chunk: usize,
    mut execute: impl FnMut(&FastDispatch) -> Result<Vec<f32>>,
) -> Result<Vec<f32>> {
    let layout = engine.layout();
    layout.validate()?;
    let scene = engine.scene();
    let dim = layout.dim();
    for (n, v) in weights.iter().enumerate() {
        if v.len() != dim {
            return Err(Error::Input(format!("weight vector {n} has {} entries; the layout has {dim}", v.len())));
        }
    }
    for (n, h) in hypotheses.iter().enumerate() {
        if h.yaw_index as usize >= scene.yaws.len() {
            return Err(Error::Input(format!(
                "hypothesis {n} has yaw index {} but the scene has {} yaws",
                h.yaw_index,
                scene.yaws.len()
            )));
        }
    }
    let w_total = weights.len();
    let mut scores = vec![0.0f32; hypotheses.len() * w_total];
    if hypotheses.is_empty() || w_total == 0 {
        return Ok(scores);
    }
    // The shader's weight layout: voxel part only, each voxel padded to CHANNELS with a zero weight.
    let voxels = layout.voxel_count();
    let passes: Vec<Vec<f32>> = weights
        .chunks(MAX_WEIGHTS)
        .map(|chunk| {
            let mut padded = Vec::with_capacity(chunk.len() * voxels * CHANNELS);
            for w in chunk {
                for voxel in w[..voxels * PER_VOXEL].chunks(PER_VOXEL) {
                    padded.extend_from_slice(voxel);
                    padded.resize(padded.len() + CHANNELS - PER_VOXEL, 0.0);
                }
            }
            padded
        })
        .collect();
    let g = layout.grid();
    let bounds_per_hyp = (g[0] + g[1] + 2) as usize;
    let [fx, fy, _, _] = scene.pre.camera.intrinsics;
    let inv_cog_scale = 1.0 / engine.cog_scale();
    for (group, (key, members)) in group_by_table(hypotheses).into_iter().enumerate() {
        let table: LayerTable = engine.table(key);
        let stride = table.stride();
        let m = scene.yaws[key.yaw_index as usize].camera_from_rotated;
        for part in members.chunks(max_chunk.max(1)) {
            let mut records = Vec::with_capacity(part.len());
            let mut bounds = Vec::with_capacity(part.len() * bounds_per_hyp);
            for &n in part {
                let record = HypothesisRecord::new(scene, layout, &hypotheses[n]);
                let [xs, ys] = engine.voxel_boundaries(&record, key.yaw_index);
                bounds.extend(xs.iter().chain(&ys).map(|&c| c as u32));
                records.push(FastRecord {
                    lo: [record.lo[0], record.lo[1], record.lo[2], 0.0],
                    cell: [record.cell[0], record.cell[1], record.cell[2], 0.0],
                });
            }
            for (pass, pass_weights) in passes.iter().enumerate() {
                let count = pass_weights.len() / (voxels * CHANNELS).max(1);
                let params = FastParams {
                    grid: [g[0], g[1], g[2], dim as u32],
                    job: [part.len() as u32, count as u32, group_bits(layout), bounds_per_hyp as u32],
                    table: [stride[0] as u32, stride[1] as u32, 0, 0],
                    scale: [fx, fy, inv_cog_scale, 0.0],
                    m0: m.x_axis.extend(0.0).to_array(),
                    m1: m.y_axis.extend(0.0).to_array(),
                    m2: m.z_axis.extend(0.0).to_array(),
                };
                let dispatch = FastDispatch {
                    group,
                    pass,
                    params,
                    table: table.sums(),
                    records: &records,
                    bounds: &bounds,
                    weights: pass_weights,
                };
                let out = execute(&dispatch)?;
                for (slot, &n) in part.iter().enumerate() {
                    for w in 0..count {
                        scores[n * w_total + pass * MAX_WEIGHTS + w] = out[slot * count + w];
                    }
                }
            }
        }
    }
    if layout.groups.view {
        let offset = layout.view_offset();
        scores.par_chunks_mut(w_total).zip(hypotheses.par_iter()).for_each(|(row, hyp)| {
            let view = engine.view(hyp);
            for (score, w) in row.iter_mut().zip(weights) {
                *score += dot(&w[offset..offset + VIEW], &view);
            }
        });
    }
    Ok(scores)
}

/// Fused fast-path scores on the GPU, `scores[h·W + w] = weights[w] · φ(h)`, the layout of
/// [`FastEngine::scores`] (and its values to ~1e-6 relative; see the module doc).
pub fn fast_scores_gpu(
    ctx: &GpuContext,
    engine: &FastEngine,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
) -> Result<Vec<f32>> {
    fast_scores_gpu_chunked(ctx, engine, hypotheses, weights, MAX_CHUNK)
}

/// [`fast_scores_gpu`] with at most `max_chunk` hypotheses per dispatch (tests force small chunks; the
/// device limits may make it smaller still).
pub fn fast_scores_gpu_chunked(
    ctx: &GpuContext,
    engine: &FastEngine,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    max_chunk: usize,
) -> Result<Vec<f32>> {
    let kernel = &ctx.kernels.fast_scores;
    let max_binding = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    let g = engine.layout().grid();
    // The largest per-hypothesis storage binding: its boundaries, its record or its scores.
    let per_hyp =
        ((g[0] + g[1] + 2) as u64 * 4).max(std::mem::size_of::<FastRecord>() as u64).max(MAX_WEIGHTS as u64 * 4);
    let chunk = max_chunk.min(MAX_CHUNK).min((max_binding / per_hyp).max(1) as usize);
    ctx.checked("fast_scores kernel", || {
        // Uploads shared by the dispatches of one table group / one weight pass.
        let mut table_buffer: Option<(usize, wgpu::Buffer)> = None;
        let mut weight_buffers: Vec<Option<wgpu::Buffer>> = Vec::new();
        run(engine, hypotheses, weights, chunk, |d| {
            let table_bytes = std::mem::size_of_val(d.table) as u64;
            if table_bytes > max_binding {
                return Err(Error::Gpu(format!(
                    "fast_scores: a layer table of {table_bytes} bytes exceeds the storage-binding limit of \
                     {max_binding} bytes"
                )));
            }
            if table_buffer.as_ref().is_none_or(|(group, _)| *group != d.group) {
                table_buffer = Some((d.group, ctx.storage_buffer("fast table", d.table)));
            }
            if weight_buffers.len() <= d.pass {
                weight_buffers.resize_with(d.pass + 1, || None);
            }
            let weights_buf =
                weight_buffers[d.pass].get_or_insert_with(|| ctx.storage_buffer("fast weights", d.weights));
            let table_buf = &table_buffer.as_ref().expect("uploaded above").1;
            let count = d.records.len() * d.params.job[1] as usize;
            let uniform = ctx.uniform_buffer("fast params", &d.params);
            let records = ctx.storage_buffer("fast records", d.records);
            let bounds = ctx.storage_buffer("fast bounds", d.bounds);
            let out = ctx.output_buffer("fast scores", (count * 4) as u64);
            let bind_group = ctx.bind_group(kernel, &[&uniform, table_buf, &records, &bounds, weights_buf, &out]);
            // One workgroup per hypothesis: the 1-D convention with 64 invocations per hypothesis.
            let invocations = (d.records.len() * kernel.invocations_per_workgroup() as usize) as u32;
            ctx.dispatch_and_read(kernel, &bind_group, invocations, &out, count)
        })
    })
}

/// The CPU twin of the whole GPU path: the same dispatches as [`fast_scores_gpu_chunked`], each run by
/// [`fast_scores_main`] over its workgroups.
pub fn fast_scores_reference(
    engine: &FastEngine,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    max_chunk: usize,
) -> Result<Vec<f32>> {
    run(engine, hypotheses, weights, max_chunk, |d| {
        let count = d.params.job[1] as usize;
        let mut out = vec![0.0f32; d.records.len() * count];
        out.par_chunks_mut(count.max(1))
            .enumerate()
            .for_each(|(h, row)| fast_scores_main(&d.params, d.table, d.records, d.bounds, d.weights, h, row));
        Ok(out)
    })
}

/// The shader's `main` for workgroup `h` (all 64 invocations, then the reduction), writing
/// `out[h·weight_count..]` as `row`. Written to read like `shaders/fast_scores.wgsl`; its `vec4`s are
/// `[_; 4]` here, `table` and `weights` are indexed in `vec4` units through [`vec4_at`].
pub fn fast_scores_main(
    params: &FastParams,
    table: &[u32],
    records: &[FastRecord],
    bounds: &[u32],
    weights: &[f32],
    h: usize,
    row: &mut [f32],
) {
    let [nx, ny, nz, _] = params.grid.map(|v| v as usize);
    let weight_count = params.job[1] as usize;
    let groups = params.job[2];
    let use_density = groups & 1 != 0;
    let use_normals = groups & 2 != 0;
    let use_cog = groups & 4 != 0;
    let mut partial = [0.0f32; WORKGROUP * MAX_WEIGHTS];

    let record = &records[h];
    let lo = record.lo;
    let cell = record.cell;
    let face_areas = [cell[1] * cell[2], cell[0] * cell[2], cell[0] * cell[1]];
    let [fx, fy, inv_cog_scale, _] = params.scale;
    let b = h * params.job[3] as usize;
    let table_row = params.table[0] as usize;
    let voxels = nx * ny * nz;
    let camera_point = |q: [f32; 3]| -> [f32; 3] {
        [0, 1, 2].map(|a| params.m0[a] * q[0] + params.m1[a] * q[1] + params.m2[a] * q[2])
    };
    let dot3 = |a: &[f32; 4], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    // acc + a·b, adding the four products one after the other.
    let dot_acc =
        |acc: f32, a: [f32; 4], b: [f32; 4]| (((acc + a[0] * b[0]) + a[1] * b[1]) + a[2] * b[2]) + a[3] * b[3];
    let to_f32 = |s: [u32; 4]| s.map(|x| x as f32);
    let mul = |a: [f32; 4], m: [f32; 4]| [a[0] * m[0], a[1] * m[1], a[2] * m[2], a[3] * m[3]];
    for lid in 0..WORKGROUP {
        let mut my_partial = [0.0f32; MAX_WEIGHTS];
        for v in (lid..voxels).step_by(WORKGROUP) {
            let i = v % nx;
            let j = (v / nx) % ny;
            let k = v / (nx * ny);
            // Step 3: the voxel's sums, four corners of layer k (9 vec4 per entry).
            let x0 = bounds[b + i] as usize;
            let x1 = bounds[b + i + 1] as usize;
            let y0 = bounds[b + nx + 1 + j] as usize;
            let y1 = bounds[b + nx + 1 + j + 1] as usize;
            let layer = k * params.table[1] as usize;
            let high = ((layer + y1) * table_row + x1) * 9;
            let left = ((layer + y1) * table_row + x0) * 9;
            let low = ((layer + y0) * table_row + x1) * 9;
            let both = ((layer + y0) * table_row + x0) * 9;
            let sums = |c: usize| -> [u32; 4] {
                let [hi, le, lo, bo] = [high, left, low, both].map(|e| vec4_at(table, e + c));
                [0, 1, 2, 3].map(|n| hi[n].wrapping_sub(le[n]).wrapping_sub(lo[n]).wrapping_add(bo[n]))
            };
            let s0 = sums(0);
            if s0[0] == 0 {
                continue;
            }
            // Step 4: each channel's multiplier.
            let mut density = 0.0f32;
            let mut normal = 0.0f32;
            let centre = [
                lo[0] + (i as f32 + 0.5) * cell[0],
                lo[1] + (j as f32 + 0.5) * cell[1],
                lo[2] + (k as f32 + 0.5) * cell[2],
            ];
            let p = camera_point(centre);
            if p[2] >= MIN_PROJECT_DEPTH {
                let area = fx
                    * fy
                    * (face_areas[0] * dot3(&params.m0, p).abs()
                        + face_areas[1] * dot3(&params.m1, p).abs()
                        + face_areas[2] * dot3(&params.m2, p).abs())
                    / (p[2] * p[2] * p[2]);
                let inv_area = 1.0 / area.max(1.0);
                density = if use_density { inv_area } else { 0.0 };
                normal = if use_normals { inv_area } else { 0.0 };
            }
            // COG bins are channels 26..34: s6[2..], s7, s8[..3].
            let (s6, s7, s8) = (sums(6), sums(7), sums(8));
            let mut cog = 0.0f32;
            if use_cog {
                let [g6, g7, g8] = [s6, s7, s8].map(|s| to_f32(s).map(|x| x * inv_cog_scale));
                let mut norm_sq = 0.0f32;
                for x in [g6[2], g6[3], g7[0], g7[1], g7[2], g7[3], g8[0], g8[1], g8[2]] {
                    norm_sq += x * x;
                }
                cog = inv_cog_scale * (1.0 / (norm_sq + COG_EPSILON).sqrt());
            }
            let f = [
                mul(to_f32(s0), [density, normal, normal, normal]),
                mul(to_f32(sums(1)), [normal; 4]),
                mul(to_f32(sums(2)), [normal; 4]),
                mul(to_f32(sums(3)), [normal; 4]),
                mul(to_f32(sums(4)), [normal; 4]),
                mul(to_f32(sums(5)), [normal; 4]),
                mul(to_f32(s6), [normal, normal, cog, cog]),
                mul(to_f32(s7), [cog; 4]),
                mul(to_f32(s8), [cog, cog, cog, 0.0]),
            ];
            for (w, slot) in my_partial.iter_mut().enumerate() {
                if w < weight_count {
                    let wb = (w * voxels + v) * 9;
                    let mut acc = 0.0f32;
                    for (c, fc) in f.iter().enumerate() {
                        acc = dot_acc(acc, vec4_at(weights, wb + c), *fc);
                    }
                    *slot += acc;
                }
            }
        }
        partial[lid * MAX_WEIGHTS..(lid + 1) * MAX_WEIGHTS].copy_from_slice(&my_partial);
    }
    // Fixed tree: partial[l] += partial[l + stride] for stride 32, 16, …, 1.
    let mut stride = WORKGROUP / 2;
    while stride > 0 {
        for lid in 0..stride {
            for w in 0..MAX_WEIGHTS {
                partial[lid * MAX_WEIGHTS + w] += partial[(lid + stride) * MAX_WEIGHTS + w];
            }
        }
        stride /= 2;
    }
    row[..weight_count].copy_from_slice(&partial[..weight_count]);
}

/// Element `n` of `data` viewed as an array of `vec4`s.
fn vec4_at<T: Copy>(data: &[T], n: usize) -> [T; 4] {
    [data[4 * n], data[4 * n + 1], data[4 * n + 2], data[4 * n + 3]]
}

/// Whether [`crate::backend::Backend::fast_scores`] runs the kernel on `ctx` (see there).
pub fn use_kernel_on(ctx: &GpuContext) -> bool {
    static SAID: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    if ctx.info.device_type != wgpu::DeviceType::Cpu
        || std::env::var("COG_GPU_FAST_KERNEL").is_ok_and(|v| v == "always")
    {
        return true;
    }
    if !SAID.swap(true, std::sync::atomic::Ordering::Relaxed) {
        log::info!(
            "{} is a software adapter: the fast path scores on the CPU, which is faster there \
             (COG_GPU_FAST_KERNEL=always runs the kernel anyway)",
            ctx.info.name
        );
    }
    false
}
