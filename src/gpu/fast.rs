//! The fast-path scoring kernel (`shaders/fast_scores.wgsl`): fused scores `w·φ(h)` of many hypotheses from
//! the fast path's summed-area tables — steps 3–4 of [`crate::features::fast`] on the GPU.
//!
//! # Design
//! Steps 1–2 (the per-yaw lattices and the per-(yaw, bottom, height) [`LayerTable`]s) stay on the CPU, built
//! by the [`FastEngine`]'s own code, in parallel (a few table groups per thread at a time). Hypotheses are
//! grouped by table (the engine's grouping); each group's hypotheses are dispatched in chunks of at most
//! [`MAX_CHUNK`] (fewer when the device's storage-binding limit asks for it), with up to [`MAX_WEIGHTS`]
//! weight vectors per pass. **Batches, not dispatches, meet the queue**: table groups are collected into a
//! batch of at most [`MAX_BATCH_BYTES`] (all of one model's groups on a 640×480 frame); per batch one
//! buffer per kind of input (tables, records, boundaries, parameters at aligned offsets) and one for the
//! scores are filled through the queue, every dispatch is recorded in one compute pass with its own bind
//! group of buffer ranges, and the batch is submitted once and read back once. No buffer is created per
//! dispatch and the CPU waits once per batch, not once per dispatch. How the work is batched does not
//! change a single bit of the scores (tested).
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

use std::collections::BTreeMap;

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

use super::fast_tables::{
    table_invocations, table_params, table_points, table_words, TableParams, TablePoint, SCAN_COLUMNS, SCAN_ROWS,
};
use super::{BufferBinding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::cpu::{dot, HypothesisRecord};
use crate::features::fast::{group_by_table, FastEngine, LayerTable, TableKey, TableSpan, CHANNELS};
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

/// How the work is cut into dispatches and submissions (tests force small values; the device limits may
/// make them smaller still).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FastChunking {
    /// Largest number of hypotheses per dispatch.
    pub max_chunk: usize,
    /// Largest size of one submission's arenas (tables, records, boundaries, scores) in bytes; table
    /// groups are added to a batch until the next would pass it (a single larger group is a batch of its
    /// own).
    pub max_batch_bytes: u64,
}

/// Default arena budget of one submission: all table groups of one model on a 640×480 frame (≈ 80 tables
/// of 1–2 MB) fit in one.
pub const MAX_BATCH_BYTES: u64 = 512 << 20;

impl Default for FastChunking {
    fn default() -> Self {
        FastChunking { max_chunk: MAX_CHUNK, max_batch_bytes: MAX_BATCH_BYTES }
    }
}

/// One dispatch's inputs, exactly what the shader binds.
pub struct FastDispatch<'a> {
    /// Index of the table group within its batch (dispatches of one group share the table).
    pub group: usize,
    /// Index of the chunk within its batch (dispatches of one chunk share records and boundaries).
    pub chunk: usize,
    /// Index of the weight pass (dispatches of one pass share the weights).
    pub pass: usize,
    pub params: FastParams,
    /// The whole [`LayerTable`], `u32` words, when it was built on the CPU (the CPU twin); `None` when the
    /// GPU builds it from the lattice of yaw `yaw_index` ([`crate::gpu::fast_tables`]).
    pub table: Option<&'a [u32]>,
    pub yaw_index: usize,
    /// The table's layers along z.
    pub(crate) span: TableSpan,
    pub records: &'a [FastRecord],
    /// `params.job[3]` boundaries per hypothesis.
    pub bounds: &'a [u32],
    /// The pass's weight vectors without the view part, each voxel padded to [`CHANNELS`] with a zero:
    /// `params.job[1] × voxels × CHANNELS`.
    pub weights: &'a [f32],
}

/// One model's share of a call: its hypotheses and weight vectors (scores `hypotheses.len() ×
/// weights.len()`, hypothesis-major).
#[derive(Clone, Copy)]
pub struct FastJob<'a> {
    pub hypotheses: &'a [Hypothesis],
    pub weights: &'a [Vec<f32>],
}

/// The hypotheses of one table group, per job: (job, indices into its hypotheses).
type JobMembers = Vec<(usize, Vec<usize>)>;

/// One table group packed on the CPU: its table and, per chunk of hypotheses (of any job that uses the
/// table), their records and voxel boundaries.
struct PackedGroup {
    yaw_index: usize,
    span: TableSpan,
    /// Words of the table.
    table_words: usize,
    /// The table, when built on the CPU.
    table: Option<LayerTable>,
    chunks: Vec<PackedChunk>,
}

struct PackedChunk {
    /// The job the hypotheses belong to.
    job: usize,
    /// Indices into the job's hypotheses.
    members: Vec<usize>,
    records: Vec<FastRecord>,
    bounds: Vec<u32>,
}

impl PackedGroup {
    /// Packs each job's `members` in chunks of at most `max_chunk`, and builds the table of `key` when
    /// `build_table`.
    fn new(
        engine: &FastEngine,
        jobs: &[FastJob],
        key: TableKey,
        members: &JobMembers,
        max_chunk: usize,
        build_table: bool,
    ) -> Self {
        let scene = engine.scene();
        let layout = engine.layout();
        let g = layout.grid();
        let bounds_per_hyp = (g[0] + g[1] + 2) as usize;
        let mut chunks = Vec::new();
        for (job, job_members) in members {
            for part in job_members.chunks(max_chunk.max(1)) {
                let mut records = Vec::with_capacity(part.len());
                let mut bounds = Vec::with_capacity(part.len() * bounds_per_hyp);
                for &n in part {
                    let record = HypothesisRecord::new(scene, layout, &jobs[*job].hypotheses[n]);
                    let [xs, ys] = engine.voxel_boundaries(&record, key.yaw_index);
                    bounds.extend(xs.iter().chain(&ys).map(|&c| c as u32));
                    records.push(FastRecord {
                        lo: [record.lo[0], record.lo[1], record.lo[2], 0.0],
                        cell: [record.cell[0], record.cell[1], record.cell[2], 0.0],
                    });
                }
                chunks.push(PackedChunk { job: *job, members: part.to_vec(), records, bounds });
            }
        }
        let span = engine.table_span(key);
        let [row, rows] = engine.lattice(key.yaw_index as usize).table_stride();
        PackedGroup {
            yaw_index: key.yaw_index as usize,
            span,
            table_words: span.layers * rows * row * CHANNELS,
            table: build_table.then(|| engine.table(key)),
            chunks,
        }
    }

    /// Bytes this group adds to a batch's arenas (`scores_per_hypothesis[job]` outputs per hypothesis).
    fn bytes(&self, scores_per_hypothesis: &[usize]) -> u64 {
        let chunks: usize = self
            .chunks
            .iter()
            .map(|c| {
                std::mem::size_of_val(c.records.as_slice())
                    + 4 * (c.bounds.len() + c.members.len() * scores_per_hypothesis[c.job])
            })
            .sum();
        (4 * self.table_words + chunks) as u64
    }
}

/// Checks a job's weights and hypotheses against the engine.
fn validate_job(engine: &FastEngine, job: &FastJob) -> Result<()> {
    let dim = engine.layout().dim();
    for (n, v) in job.weights.iter().enumerate() {
        if v.len() != dim {
            return Err(Error::Input(format!("weight vector {n} has {} entries; the layout has {dim}", v.len())));
        }
    }
    let yaws = engine.scene().yaws.len();
    if let Some((n, h)) = job.hypotheses.iter().enumerate().find(|(_, h)| h.yaw_index as usize >= yaws) {
        return Err(Error::Input(format!(
            "hypothesis {n} has yaw index {} but the scene has {yaws} yaws",
            h.yaw_index
        )));
    }
    Ok(())
}

/// The shader's weight layout of one job: per pass of at most [`MAX_WEIGHTS`] vectors, the voxel part only,
/// each voxel padded to [`CHANNELS`] with a zero weight.
fn padded_passes(layout: &FeatureLayout, weights: &[Vec<f32>]) -> Vec<Vec<f32>> {
    let voxels = layout.voxel_count();
    weights
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
        .collect()
}

/// Packs every dispatch of every job and hands them to `execute` one batch at a time (GPU: one submission
/// per batch; CPU twin: each dispatch in turn), which returns each dispatch's `records.len() × weight count`
/// voxel scores; adds the view part on the CPU and returns, per job, `scores[h·W + w]`. Jobs whose
/// hypotheses share a table (same yaw, bottom and height) share its group: the table is built once. The
/// dispatches, and so the scores, do not depend on how they are batched or which other jobs come along.
/// Table groups are packed (records computed, tables built on the CPU when `build_tables`) in parallel, a
/// few per thread at a time, so that at most about one batch of tables is held.
fn run(
    engine: &FastEngine,
    jobs: &[FastJob],
    chunking: FastChunking,
    build_tables: bool,
    mut execute: impl FnMut(&[FastDispatch]) -> Result<Vec<Vec<f32>>>,
) -> Result<Vec<Vec<f32>>> {
    let layout = engine.layout();
    layout.validate()?;
    let scene = engine.scene();
    for job in jobs {
        validate_job(engine, job)?;
    }
    let w_totals: Vec<usize> = jobs.iter().map(|j| j.weights.len()).collect();
    let mut scores: Vec<Vec<f32>> = jobs.iter().map(|j| vec![0.0f32; j.hypotheses.len() * j.weights.len()]).collect();
    // Weight passes of all jobs, numbered globally (dispatches of one pass share its upload).
    let passes: Vec<Vec<Vec<f32>>> = jobs.iter().map(|j| padded_passes(layout, j.weights)).collect();
    let first_pass: Vec<usize> = passes
        .iter()
        .scan(0, |next, p| {
            let first = *next;
            *next += p.len();
            Some(first)
        })
        .collect();
    let voxels = layout.voxel_count();
    let dim = layout.dim();
    let g = layout.grid();
    let bounds_per_hyp = g[0] + g[1] + 2;
    let [fx, fy, _, _] = scene.pre.camera.intrinsics;
    let inv_cog_scale = 1.0 / engine.cog_scale();
    let params_of = |group: &PackedGroup, chunk: &PackedChunk, count: usize| {
        let stride = engine.lattice(group.yaw_index).table_stride();
        let m = scene.yaws[group.yaw_index].camera_from_rotated;
        FastParams {
            grid: [g[0], g[1], g[2], dim as u32],
            job: [chunk.records.len() as u32, count as u32, group_bits(layout), bounds_per_hyp],
            table: [stride[0] as u32, stride[1] as u32, 0, 0],
            scale: [fx, fy, inv_cog_scale, 0.0],
            m0: m.x_axis.extend(0.0).to_array(),
            m1: m.y_axis.extend(0.0).to_array(),
            m2: m.z_axis.extend(0.0).to_array(),
        }
    };
    let mut flush = |batch: &[PackedGroup], scores: &mut [Vec<f32>]| -> Result<()> {
        let mut dispatches = Vec::new();
        let mut owners = Vec::new();
        let mut chunk_index = 0;
        for (group_index, group) in batch.iter().enumerate() {
            for chunk in &group.chunks {
                for (pass, pass_weights) in passes[chunk.job].iter().enumerate() {
                    let count = pass_weights.len() / (voxels * CHANNELS).max(1);
                    dispatches.push(FastDispatch {
                        group: group_index,
                        chunk: chunk_index,
                        pass: first_pass[chunk.job] + pass,
                        params: params_of(group, chunk, count),
                        table: group.table.as_ref().map(LayerTable::sums),
                        yaw_index: group.yaw_index,
                        span: group.span,
                        records: &chunk.records,
                        bounds: &chunk.bounds,
                        weights: pass_weights,
                    });
                    owners.push((chunk, pass));
                }
                chunk_index += 1;
            }
        }
        let outs = execute(&dispatches)?;
        if outs.len() != dispatches.len() {
            return Err(Error::Gpu(format!("{} dispatches returned {} results", dispatches.len(), outs.len())));
        }
        for ((d, out), (chunk, pass)) in dispatches.iter().zip(&outs).zip(owners) {
            let count = d.params.job[1] as usize;
            let w_total = w_totals[chunk.job];
            let job_scores = &mut scores[chunk.job];
            for (slot, &n) in chunk.members.iter().enumerate() {
                for w in 0..count {
                    job_scores[n * w_total + pass * MAX_WEIGHTS + w] = out[slot * count + w];
                }
            }
        }
        Ok(())
    };
    // Table groups over all jobs, in key order (deterministic), each with its jobs' members in job order.
    let mut by_key: BTreeMap<TableKey, JobMembers> = BTreeMap::new();
    for (j, job) in jobs.iter().enumerate() {
        if job.weights.is_empty() {
            continue;
        }
        for (key, members) in group_by_table(job.hypotheses) {
            by_key.entry(key).or_default().push((j, members));
        }
    }
    let groups: Vec<(TableKey, JobMembers)> = by_key.into_iter().collect();
    let mut batch: Vec<PackedGroup> = Vec::new();
    let mut batch_bytes = 0u64;
    for window in groups.chunks(2 * rayon::current_num_threads().max(1)) {
        let packed: Vec<PackedGroup> = window
            .par_iter()
            .map(|(key, members)| PackedGroup::new(engine, jobs, *key, members, chunking.max_chunk, build_tables))
            .collect();
        for group in packed {
            let bytes = group.bytes(&w_totals);
            if !batch.is_empty() && batch_bytes + bytes > chunking.max_batch_bytes {
                flush(&batch, &mut scores)?;
                batch.clear();
                batch_bytes = 0;
            }
            batch_bytes += bytes;
            batch.push(group);
        }
    }
    if !batch.is_empty() {
        flush(&batch, &mut scores)?;
    }
    if layout.groups.view {
        let offset = layout.view_offset();
        for (job, job_scores) in jobs.iter().zip(scores.iter_mut()) {
            let w_total = job.weights.len();
            if w_total == 0 {
                continue;
            }
            job_scores.par_chunks_mut(w_total).zip(job.hypotheses.par_iter()).for_each(|(row, hyp)| {
                let view = engine.view(hyp);
                for (score, w) in row.iter_mut().zip(job.weights) {
                    *score += dot(&w[offset..offset + VIEW], &view);
                }
            });
        }
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
    fast_scores_gpu_chunked(ctx, engine, hypotheses, weights, FastChunking::default())
}

/// [`fast_scores_gpu`] cut as `chunking` says.
pub fn fast_scores_gpu_chunked(
    ctx: &GpuContext,
    engine: &FastEngine,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    chunking: FastChunking,
) -> Result<Vec<f32>> {
    let mut scores = fast_scores_gpu_jobs(ctx, engine, &[FastJob { hypotheses, weights }], chunking)?;
    Ok(scores.pop().unwrap_or_default())
}

/// Byte offsets of the pieces packed into one buffer, each aligned for binding.
struct Arena {
    align: u64,
    len: u64,
}

impl Arena {
    fn new(align: u32) -> Arena {
        Arena { align: u64::from(align.max(4)), len: 0 }
    }

    /// Reserves `bytes` and returns their offset.
    fn place(&mut self, bytes: u64) -> u64 {
        let at = self.len.next_multiple_of(self.align);
        self.len = at + bytes;
        at
    }
}

/// Several jobs' fast-path scores on the GPU (see [`run`]: tables shared between jobs are built once), cut as
/// `chunking` says. Per batch: the lattice points of its yaws uploaded once, its
/// tables built by [`crate::gpu::fast_tables`]'s kernels into one buffer, one buffer per other kind of input
/// (records, boundaries, parameters) and one for the scores, filled through the queue; the table
/// dispatches (three phases) and every scoring dispatch recorded in four compute passes, one submission and
/// one read-back; the weights are uploaded once per call.
pub fn fast_scores_gpu_jobs(
    ctx: &GpuContext,
    engine: &FastEngine,
    jobs: &[FastJob],
    chunking: FastChunking,
) -> Result<Vec<Vec<f32>>> {
    let max_binding = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    let g = engine.layout().grid();
    // The largest per-hypothesis storage binding: its boundaries, its record or its scores.
    let per_hyp =
        ((g[0] + g[1] + 2) as u64 * 4).max(std::mem::size_of::<FastRecord>() as u64).max(MAX_WEIGHTS as u64 * 4);
    let chunking = FastChunking {
        max_chunk: chunking.max_chunk.min(MAX_CHUNK).min((max_binding / per_hyp).max(1) as usize),
        max_batch_bytes: chunking.max_batch_bytes.min(ctx.limits.max_buffer_size),
    };
    ctx.checked("fast_scores kernels", || {
        let mut weight_buffers: Vec<Option<wgpu::Buffer>> = Vec::new();
        let mut submissions = 0usize;
        let mut dispatch_count = 0usize;
        let mut tables = (0usize, 0u64);
        let scores = run(engine, jobs, chunking, false, |dispatches| {
            for (n, d) in dispatches.iter().enumerate() {
                let bytes = 4 * fast_tables_words(engine, d) as u64;
                // Dispatches of one table group are consecutive and share its table.
                if n == 0 || dispatches[n - 1].group != d.group {
                    tables.0 += 1;
                    tables.1 += bytes;
                }
                if bytes > max_binding {
                    return Err(Error::Gpu(format!(
                        "fast_scores: a layer table of {bytes} bytes exceeds the storage-binding limit of \
                         {max_binding} bytes"
                    )));
                }
                if weight_buffers.len() <= d.pass {
                    weight_buffers.resize_with(d.pass + 1, || None);
                }
                weight_buffers[d.pass].get_or_insert_with(|| ctx.storage_buffer("fast weights", d.weights));
            }
            submissions += 1;
            dispatch_count += dispatches.len();
            run_batch(ctx, engine, dispatches, &weight_buffers)
        })?;
        log::debug!(
            "fast_scores: {} jobs, {} hypotheses, {} tables ({:.1} MB) built on the GPU, {dispatch_count} scoring \
             dispatches, {submissions} submissions",
            jobs.len(),
            jobs.iter().map(|j| j.hypotheses.len()).sum::<usize>(),
            tables.0,
            tables.1 as f64 * 1e-6
        );
        Ok(scores)
    })
}

/// Words of the table dispatch `d` reads.
fn fast_tables_words(engine: &FastEngine, d: &FastDispatch) -> usize {
    table_words(&table_params(engine.lattice(d.yaw_index), d.span, 0))
}

/// One batch on the GPU: uploads the lattice points of its yaws, builds its tables, records every scoring
/// dispatch, submits once and reads the scores back once.
fn run_batch(
    ctx: &GpuContext,
    engine: &FastEngine,
    dispatches: &[FastDispatch],
    weight_buffers: &[Option<wgpu::Buffer>],
) -> Result<Vec<Vec<f32>>> {
    let storage_align = ctx.limits.min_storage_buffer_offset_alignment;
    let [mut lattices, mut tables, mut records, mut bounds, mut outs] = [(); 5].map(|_| Arena::new(storage_align));
    let mut params = Arena::new(ctx.limits.min_uniform_buffer_offset_alignment);
    let fast_params_size = std::mem::size_of::<FastParams>() as u64;
    let table_params_size = std::mem::size_of::<TableParams>() as u64;
    // Placement: each yaw's points, each group's table (with its three table params) and each chunk's
    // records and boundaries once; per dispatch its scores and params.
    let mut yaw_at: Vec<Option<(u64, Vec<TablePoint>)>> = vec![None; engine.scene().yaws.len()];
    let mut group_at: Vec<Option<GroupPlacement>> = Vec::new();
    let mut chunk_at: Vec<Option<(u64, u64)>> = Vec::new();
    let mut placed = Vec::with_capacity(dispatches.len());
    for d in dispatches {
        if yaw_at[d.yaw_index].is_none() {
            let points = table_points(engine.lattice(d.yaw_index));
            yaw_at[d.yaw_index] = Some((lattices.place(std::mem::size_of_val(points.as_slice()) as u64), points));
        }
        if group_at.len() <= d.group {
            group_at.resize_with(d.group + 1, || None);
        }
        if group_at[d.group].is_none() {
            let lattice = engine.lattice(d.yaw_index);
            let steps = [0, SCAN_ROWS, SCAN_COLUMNS].map(|mode| table_params(lattice, d.span, mode));
            group_at[d.group] = Some(GroupPlacement {
                yaw_index: d.yaw_index,
                table: tables.place(4 * table_words(&steps[0]) as u64),
                table_bytes: 4 * table_words(&steps[0]) as u64,
                params: steps.map(|p| (params.place(table_params_size), p)),
            });
        }
        if chunk_at.len() <= d.chunk {
            chunk_at.resize(d.chunk + 1, None);
        }
        let (record, bound) = *chunk_at[d.chunk].get_or_insert_with(|| {
            let record = records.place(std::mem::size_of_val(d.records) as u64);
            (record, bounds.place(std::mem::size_of_val(d.bounds) as u64))
        });
        let count = d.records.len() * d.params.job[1] as usize;
        placed.push((record, bound, outs.place(4 * count as u64), params.place(fast_params_size)));
    }
    let storage = |label: &str, arena: &Arena| ctx.output_buffer(label, arena.len);
    let lattice_buffer = storage("fast lattice points", &lattices);
    // New buffers are zeroed (wgpu's guarantee): the tables' scatter adds into zeros.
    let table_buffer = storage("fast tables", &tables);
    let record_buffer = storage("fast records", &records);
    let bound_buffer = storage("fast bounds", &bounds);
    let out_buffer = storage("fast scores", &outs);
    let params_buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("fast params"),
        size: params.len.max(4).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    for (at, points) in yaw_at.iter().flatten() {
        ctx.queue.write_buffer(&lattice_buffer, *at, bytemuck::cast_slice(points));
    }
    // The tables: three phases (scatter, rows, columns), one dispatch per table in each.
    let mut phases: [Vec<(wgpu::BindGroup, u32)>; 3] = Default::default();
    for group in group_at.iter().flatten() {
        let (points_at, points) = yaw_at[group.yaw_index].as_ref().expect("placed with its group");
        let points_bytes = (std::mem::size_of_val(points.as_slice()) as u64).max(4);
        let invocations = table_invocations(&group.params[0].1);
        for (step, &(param_at, step_params)) in group.params.iter().enumerate() {
            ctx.queue.write_buffer(&params_buffer, param_at, bytemuck::bytes_of(&step_params));
            let kernel = if step == 0 { &ctx.kernels.fast_table_scatter } else { &ctx.kernels.fast_table_scan };
            let bind_group = ctx.bind_group_ranges(
                kernel,
                &[
                    (&params_buffer, param_at, table_params_size),
                    (&lattice_buffer, *points_at, points_bytes),
                    (&table_buffer, group.table, group.table_bytes),
                ],
            );
            phases[step].push((bind_group, invocations[step]));
        }
    }
    let kernel = &ctx.kernels.fast_scores;
    let mut written_chunks = vec![false; chunk_at.len()];
    let mut scoring = Vec::with_capacity(dispatches.len());
    for (d, &(record, bound, out, param)) in dispatches.iter().zip(&placed) {
        if !std::mem::replace(&mut written_chunks[d.chunk], true) {
            ctx.queue.write_buffer(&record_buffer, record, bytemuck::cast_slice(d.records));
            ctx.queue.write_buffer(&bound_buffer, bound, bytemuck::cast_slice(d.bounds));
        }
        ctx.queue.write_buffer(&params_buffer, param, bytemuck::bytes_of(&d.params));
        let weights = weight_buffers[d.pass].as_ref().ok_or_else(|| Error::Gpu("fast weights not uploaded".into()))?;
        let group = group_at[d.group].as_ref().expect("placed above");
        let count = d.records.len() * d.params.job[1] as usize;
        let bind_group = ctx.bind_group_ranges(
            kernel,
            &[
                (&params_buffer, param, fast_params_size),
                (&table_buffer, group.table, group.table_bytes),
                (&record_buffer, record, std::mem::size_of_val(d.records) as u64),
                (&bound_buffer, bound, std::mem::size_of_val(d.bounds) as u64),
                (weights, 0, weights.size()),
                (&out_buffer, out, 4 * count as u64),
            ],
        );
        // One workgroup per hypothesis: the 1-D convention with 64 invocations per hypothesis.
        scoring.push((bind_group, (d.records.len() * kernel.invocations_per_workgroup() as usize) as u32));
    }
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(kernel.label) });
    // Each dispatch is its own usage scope (WebGPU): a phase sees the previous phase's writes.
    ctx.encode_dispatches(&mut encoder, &ctx.kernels.fast_table_scatter, &phases[0])?;
    ctx.encode_dispatches(&mut encoder, &ctx.kernels.fast_table_scan, &phases[1])?;
    ctx.encode_dispatches(&mut encoder, &ctx.kernels.fast_table_scan, &phases[2])?;
    ctx.encode_dispatches(&mut encoder, kernel, &scoring)?;
    let all: Vec<f32> = ctx.read_buffer_after(encoder, &out_buffer, (outs.len / 4) as usize)?;
    Ok(dispatches
        .iter()
        .zip(&placed)
        .map(|(d, &(_, _, out, _))| {
            let start = (out / 4) as usize;
            all[start..start + d.records.len() * d.params.job[1] as usize].to_vec()
        })
        .collect())
}

/// Where one table group's table and its three build params lie in a batch's buffers.
struct GroupPlacement {
    yaw_index: usize,
    table: u64,
    table_bytes: u64,
    /// Scatter, rows, columns: (offset in the params buffer, params).
    params: [(u64, TableParams); 3],
}

/// The CPU twin of the whole GPU path: the same dispatches as [`fast_scores_gpu_chunked`], each run by
/// [`fast_scores_main`] over its workgroups.
pub fn fast_scores_reference(
    engine: &FastEngine,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    chunking: FastChunking,
) -> Result<Vec<f32>> {
    let mut scores = fast_scores_reference_jobs(engine, &[FastJob { hypotheses, weights }], chunking)?;
    Ok(scores.pop().unwrap_or_default())
}

/// The CPU twin of [`fast_scores_gpu_jobs`].
pub fn fast_scores_reference_jobs(
    engine: &FastEngine,
    jobs: &[FastJob],
    chunking: FastChunking,
) -> Result<Vec<Vec<f32>>> {
    run(engine, jobs, chunking, true, |dispatches| {
        dispatches
            .iter()
            .map(|d| {
                let table = d.table.ok_or_else(|| Error::Gpu("the CPU twin needs the CPU-built table".into()))?;
                let count = d.params.job[1] as usize;
                let mut out = vec![0.0f32; d.records.len() * count];
                out.par_chunks_mut(count.max(1))
                    .enumerate()
                    .for_each(|(h, row)| fast_scores_main(&d.params, table, d.records, d.bounds, d.weights, h, row));
                Ok(out)
            })
            .collect()
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
