//! The fast-path scoring kernel (`shaders/fast_scores.wgsl`): fused scores `w·φ(h)` of many hypotheses from
//! the fast path's summed-area tables — steps 3–4 of [`crate::features::fast`] on the GPU.
//!
//! # Design
//! Step 1 (the per-yaw lattices) stays on the CPU, built by the [`FastEngine`]; step 2 (the per-(yaw, bottom,
//! height) [`LayerTable`]s) and steps 3–4 run on the GPU. Hypotheses are grouped by table (the engine's
//! grouping, over every job of the call: a table that several models use is built once); each group's
//! hypotheses are cut into chunks of at most [`MAX_CHUNK`], with up to [`MAX_WEIGHTS`] weight vectors per
//! pass: one *dispatch record* ([`FastParams`]) per (group, chunk, pass). **Batches, not dispatches, meet
//! the queue**: groups are collected into a batch of at most [`MAX_BATCH_BYTES`] (and at most the
//! storage-binding limit: a batch's tables are bound as one range). Per batch, one `BatchLayout` places
//! everything in shared buffers — the yaws' lattice points, the tables, the records and boundaries, the
//! weight passes, the dispatch records and the scores — taken from a pool that the [`GpuContext`] keeps
//! from batch to batch and frame to frame (no buffer is created per batch once the pool has grown); the
//! table range is cleared on the GPU, the tables are built by [`crate::gpu::fast_tables`]'s three kernels,
//! **one dispatch per phase for all the batch's tables**, and the hypotheses are scored by one dispatch of
//! this kernel per record, **all through one bind group** (the record is a uniform at a dynamic offset); the
//! batch is submitted once and its scores read back once. How the work
//! is batched does not change a single bit of the scores (tested).
//!
//! Per hypothesis the CPU packs a [`FastRecord`] (low corner and voxel size of the expanded box, and its
//! centre) and the `nx + 1 + ny + 1` voxel-boundary cell indices (two 16-bit indices per word since
//! 2026-11-28, [`pack_boundaries`]: 32 bytes instead of 64 with the default grid, written and uploaded per
//! hypothesis), computed by the engine's own membership rule (`FastEngine::voxel_boundaries`, the function
//! its scoring uses; no view cosine, no allocation per hypothesis), so cell membership is identical by
//! construction. The shader runs **one invocation per hypothesis** (since 2026-11-28; before, a workgroup of
//! 64 invocations per hypothesis, one voxel each, reduced in workgroup memory): it visits the voxels in the
//! layout's order, row by row, each voxel's right table corners becoming the next one's left corners (18
//! texel reads per voxel instead of 36), differences four corners with wrapping `u32` arithmetic (exact, as
//! on the CPU), finalises the 35 features as `FastEngine::scores` does (density and normal bins over the
//! linearised projected area, COG normalised `φ/√(‖φ‖² + ε)`, switched-off groups and empty voxels
//! contributing nothing) and adds each voxel's dot product with each of the pass's weight vectors to that
//! vector's score in voxel order: results are bit-identical run to run. **The tables, the boundaries and the
//! weights are read as textures** ([`TexelRows`]: each is copied from its buffer into an `rgba32` texture
//! 8192 texels wide after the tables are built), the records and scores stay buffers. Why, measured on
//! lavapipe (CI's device): its storage-buffer loads run lane by lane with a branch per lane and component
//! (~13 ns per `vec4`), texture reads are vectorised gathers (1.4–4.9 ns; `examples/lavapipe_loads.rs`); a
//! workgroup costs a coroutine per subgroup and every barrier switches them (the workgroup per hypothesis
//! spent about 0.8 s of scoring outside its voxel loop on the bed window's first 40 000 hypotheses); and
//! lavapipe runs every `if` body and every iteration of a loop of constant length with the lanes masked,
//! so the loop over the weights has the pass's own length, not `MAX_WEIGHTS`. The bed window on the
//! standard frame went from 25.4–26.1 s to 6.4–6.7 s there (tables and scores; the CPU fast path
//! 0.76–0.85 s; README, "The fast path"). On hardware
//! GPUs a thread per hypothesis is the usual shape (no barriers, the weights read at one address by a
//! whole warp); its speed there is not measured yet.
//!
//! **The view features are computed in the shader too** (since 2026-11-28; before, the CPU computed their
//! dot products while packing, 52 ns per hypothesis of the GPU path's CPU time): the record carries the
//! box's centre on the ground, and after the voxels the invocation computes its view cosine (the centre
//! turned upright with the yaw's own `cos`/`sin`, the front from `Cuboid::front` of the yaw, both passed in
//! [`FastParams::view`]), the 11 radial basis functions and the bias, and adds their dot product with the
//! pass's view weights (stored after its voxel weights) to the voxel part — in the order of
//! `FastEngine::scores` (voxels first, then view). The operations are the CPU's in its order, but the GPU's
//! `exp`, `sqrt` and division are not correctly rounded (and a driver may fuse a multiply-add), so the
//! view part agrees with the CPU's to float precision rather than bit for bit — within the paths' 1e-5
//! relative agreement, tested with weights on the view features alone.
//!
//! A table larger than the storage-binding limit (128 MiB on lavapipe; ~40 MB for a 10 m × 10 m room at
//! the default lattice) is an [`Error::Gpu`]; callers fall back to the CPU path.
//!
//! With the debug log on (`RUST_LOG=cog_gpu::gpu=debug`), each call logs where its time went (grouping,
//! packing, the batches' preparation, the wait for the GPU, the view features) and, where the device has
//! timestamp queries, the GPU time of each of the four passes.
//!
//! # CPU twin
//! [`fast_scores_main`] is the shader's entry point in Rust (same names, same loop order, same reduction
//! tree), run over every workgroup by [`fast_scores_reference`], which packs its inputs with the
//! same code as [`fast_scores_gpu`] (the same `BatchLayout`, its buffers filled on the CPU with the
//! CPU-built tables). It differs from `FastEngine::scores` only in the order of the float
//! additions (the engine sums the voxels in order ℓ), so the three agree to ~1e-6 relative.

use std::collections::BTreeMap;

use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;

use super::fast_tables::{
    table_invocations, table_params, table_params_at, table_points, table_words, TableParams, TablePoint, SCAN_COLUMNS,
    SCAN_ROWS,
};
use super::{buffer_range, Arena, Binding, GpuContext, KernelSpec, TexelRows};
use crate::error::{Error, Result};
use crate::features::cpu::{dot, ExpandedBox, VIEW_MIN_DISTANCE};
use crate::features::fast::{group_by_table, CellRegion, FastEngine, LayerTable, TableKey, TableSpan, CHANNELS};
use crate::features::feature_layout::{
    view_features, FeatureLayout, COG, COG_BINS, COG_EPSILON, NORMALS, PER_VOXEL, VIEW,
};
use crate::features::out_of_view::add_out_of_view_scores;
use crate::features::preprocess::NORMAL_BINS;
use crate::features::surface::{slice_weight_vectors, with_height_biases, SurfaceEngine, SurfaceWeights, SLICES};
use crate::features::Hypothesis;
use crate::geometry::{Cuboid, MIN_PROJECT_DEPTH};
use glam::Vec3;

/// The kernel's spec (registered in [`super::Kernels`]).
pub const KERNEL: KernelSpec = KernelSpec {
    label: "fast_scores",
    source: include_str!("../../shaders/fast_scores.wgsl"),
    entry_point: "main",
    bindings: &[
        Binding::UniformDynamic,
        Binding::TextureU32,
        Binding::StorageRead,
        Binding::TextureU32,
        Binding::TextureF32,
        Binding::StorageReadWrite,
    ],
};

/// Weight vectors scored per dispatch (the shader's `MAX_WEIGHTS`); more are done in several passes.
pub const MAX_WEIGHTS: usize = 8;
/// Invocations per workgroup (the shader's `WORKGROUP`): one invocation per hypothesis, so one workgroup
/// scores up to 64 hypotheses of a dispatch.
pub const WORKGROUP: usize = 64;
/// Largest number of hypotheses per dispatch.
pub const MAX_CHUNK: usize = 1 << 16;

/// Twin of WGSL `struct FastParams` in `shaders/fast_scores.wgsl`: one dispatch record (one table, one chunk
/// of hypotheses, one pass of weight vectors), the uniform of one dispatch (bound at a dynamic offset).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FastParams {
    /// nx, ny, nz, dim.
    pub grid: [u32; 4],
    /// Hypothesis count, weight count, group bits (1 density, 2 normals, 4 cog, 8 view), boundary words per
    /// hypothesis ([`boundary_words`]).
    pub job: [u32; 4],
    /// Entries per table row (cells along s + 1), rows per layer (cells along t + 1), unused, unused.
    pub table: [u32; 4],
    /// fx, fy, 1 / cog_scale, unused.
    pub scale: [f32; 4],
    /// `camera_from_rotated` of the yaw, columns 0–2 (xyz, w unused).
    pub m0: [f32; 4],
    pub m1: [f32; 4],
    pub m2: [f32; 4],
    /// Where the dispatch's inputs lie in the batch's buffers: first `vec4` of its table, first record, first
    /// boundary, first `vec4` of its weights (filled in by the batch's layout).
    pub base: [u32; 4],
    /// First score in the scores buffer, unused, unused, unused.
    pub at: [u32; 4],
    /// The view features' geometry: the yaw's `cos θ`, `sin θ` (its [`crate::features::YawGrid`]'s, which
    /// turn a rotated-frame centre upright) and the boxes' front direction (x, y) upright
    /// ([`crate::geometry::Cuboid::front`] of the yaw).
    pub view: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<FastParams>() == 160);

/// Twin of WGSL `struct FastRecord`: one hypothesis's expanded box in the yaw's rotated frame, and its
/// centre on the ground for the view features.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FastRecord {
    /// Low corner (s, t, z), then the centre's s.
    pub lo: [f32; 4],
    /// Voxel size along (s, t, z), then the centre's t.
    pub cell: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<FastRecord>() == 32);
// The shader hard-codes the channel layout of a table entry as 9 vec4: count and normal bins 0–2, normal
// bins 3–22, normal bins 23–24 and COG bins 0–1, COG bins 2–5, COG bins 6–8 and the pad.
const _: () =
    assert!(CHANNELS == 36 && PER_VOXEL == 35 && NORMALS == 1 && NORMAL_BINS == 25 && COG == 26 && COG_BINS == 9);

/// Group bits of the shader: 1 density, 2 normals, 4 COG, 8 view.
fn group_bits(layout: &FeatureLayout) -> u32 {
    let g = layout.groups;
    u32::from(g.density) | (u32::from(g.normals) << 1) | (u32::from(g.cog) << 2) | (u32::from(g.view) << 3)
}

/// Words of packed voxel boundaries per hypothesis for the grid `g`: its `g[0] + 1 + g[1] + 1` boundaries,
/// two per word.
pub fn boundary_words(g: &[u32; 3]) -> usize {
    (g[0] as usize + g[1] as usize + 2).div_ceil(2)
}

/// Packs `boundaries` (each at most [`MAX_LATTICE_CELLS`]) two per word into `words`, the lower half first —
/// what the shader's `boundary` unpacks. A hypothesis's boundaries are 64 bytes as `u32`s with the default
/// grid; packed, 32: the packing on the CPU writes them and the upload copies them, per hypothesis.
pub fn pack_boundaries(boundaries: &[u32], words: &mut [u32]) {
    for (word, pair) in words.iter_mut().zip(boundaries.chunks(2)) {
        *word = pair[0] | (pair.get(1).copied().unwrap_or(0) << 16);
    }
}

/// Boundary `k` of packed `words` ([`pack_boundaries`]): the shader's `boundary`.
pub fn packed_boundary(words: &[u32], k: usize) -> u32 {
    (words[k >> 1] >> ((k & 1) * 16)) & 0xffff
}

/// Most lattice cells along an axis the packed boundaries can address (a boundary is a cell index in
/// `0..=cells`): 3.2 km at the default 5 cm lattice, far beyond any table that fits a storage binding.
pub const MAX_LATTICE_CELLS: usize = u16::MAX as usize;

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

/// One dispatch record's inputs (what the shader reads for its hypotheses), before the batch's layout places
/// them in the shared buffers.
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
    /// The lattice cells the table covers: those the group's hypotheses' voxels reach (`bounds` are
    /// relative to its first cell).
    pub(crate) region: CellRegion,
    pub records: &'a [FastRecord],
    /// Per hypothesis its `nx + 1 + ny + 1` voxel boundaries less the first cell of `region` (along s for
    /// the first `nx + 1`, along t for the rest), two 16-bit boundaries per word (the lower half first),
    /// `params.job[3]` words ([`pack_boundaries`]).
    pub bounds: &'a [u32],
    /// The pass's weight vectors, each voxel padded to [`CHANNELS`] with a zero: `params.job[1] × voxels ×
    /// CHANNELS`, then with the view group each vector's [`VIEW`] view weights (`params.job[1] × VIEW`).
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
    /// The cells the group's voxels reach (as the CPU path's tables, [`CellRegion`]).
    region: CellRegion,
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
        let layout = engine.layout();
        let g = layout.grid();
        let words = boundary_words(&g);
        let mut region: Option<CellRegion> = None;
        let mut chunks = Vec::new();
        for (job, job_members) in members {
            for part in job_members.chunks(max_chunk.max(1)) {
                // Hypotheses in parallel (groups differ in size by orders of magnitude, so a group per
                // thread left most threads idle while the largest groups packed).
                let mut records = vec![FastRecord::default(); part.len()];
                let mut bounds = vec![0u32; part.len() * words];
                let part_region = records
                    .par_iter_mut()
                    .zip(bounds.par_chunks_mut(words))
                    .zip(part)
                    .map(|((record, bounds), &n)| {
                        let hyp = &jobs[*job].hypotheses[n];
                        let expanded = ExpandedBox::new(layout, hyp);
                        let boundaries = engine.voxel_boundaries(&expanded, key.yaw_index);
                        pack_boundaries(boundaries.all(), bounds);
                        let ExpandedBox { lo, cell, .. } = expanded;
                        *record = FastRecord {
                            lo: [lo[0], lo[1], lo[2], hyp.centre.x],
                            cell: [cell[0], cell[1], cell[2], hyp.centre.y],
                        };
                        CellRegion::of(&boundaries)
                    })
                    .reduce_with(CellRegion::union);
                region = match (region, part_region) {
                    (Some(a), Some(b)) => Some(a.union(b)),
                    (a, b) => a.or(b),
                };
                chunks.push(PackedChunk { job: *job, members: part.to_vec(), records, bounds });
            }
        }
        // The group's table covers the cells its voxels reach (as the CPU path's); its boundaries become
        // relative to that region's first cells: each packed word less the same two cells packed alike
        // (each half of a word is at least its cell, so no borrow crosses from one half to the other).
        let region = region.unwrap_or(CellRegion::whole(engine.lattice(key.yaw_index as usize)));
        let [lo_s, lo_t] = region.lo().map(|c| c as u32);
        let firsts: Vec<u32> = (0..g[0] + 1).map(|_| lo_s).chain((0..g[1] + 1).map(|_| lo_t)).collect();
        let mut offsets = vec![0u32; words];
        pack_boundaries(&firsts, &mut offsets);
        chunks.par_iter_mut().flat_map(|chunk| chunk.bounds.par_chunks_mut(words)).for_each(|bounds| {
            for (word, offset) in bounds.iter_mut().zip(&offsets) {
                *word -= offset;
            }
        });
        let span = engine.table_span(key);
        let table = build_table.then(|| engine.build_table(key, region));
        PackedGroup { yaw_index: key.yaw_index as usize, span, region, table, chunks }
    }

    /// At most the bytes the group of `key` with `members` adds to a batch's arenas
    /// (`scores_per_hypothesis[job]` outputs per hypothesis): its table (taken over the whole lattice, an
    /// upper bound of its region's: the region is known only once the group is packed), and per member its
    /// record, boundaries and scores. Known before the group is packed, so batches are planned first
    /// ([`plan_batches`]).
    fn bytes(engine: &FastEngine, key: TableKey, members: &JobMembers, scores_per_hypothesis: &[usize]) -> u64 {
        let g = engine.layout().grid();
        let words = boundary_words(&g);
        let lattice = engine.lattice(key.yaw_index as usize);
        let table_words = table_words(&table_params(lattice, engine.table_span(key), 0));
        let per_member = |job: usize| std::mem::size_of::<FastRecord>() + 4 * (words + scores_per_hypothesis[job]);
        let members: usize = members.iter().map(|(job, m)| m.len() * per_member(*job)).sum();
        (4 * table_words + members) as u64
    }
}

/// Cuts `groups` (in order) into batches of at most `max_batch_bytes` each (a group larger than that alone),
/// as ranges of group indices.
fn plan_batches(
    engine: &FastEngine,
    groups: &[(TableKey, JobMembers)],
    scores_per_hypothesis: &[usize],
    max_batch_bytes: u64,
) -> Vec<std::ops::Range<usize>> {
    let mut batches = Vec::new();
    let (mut first, mut bytes) = (0, 0u64);
    for (n, (key, members)) in groups.iter().enumerate() {
        let group_bytes = PackedGroup::bytes(engine, *key, members, scores_per_hypothesis);
        if n > first && bytes + group_bytes > max_batch_bytes {
            batches.push(first..n);
            (first, bytes) = (n, 0);
        }
        bytes += group_bytes;
    }
    if first < groups.len() {
        batches.push(first..groups.len());
    }
    batches
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

/// The shader's weight layout of one job: per pass of at most [`MAX_WEIGHTS`] vectors, their voxel parts,
/// each voxel padded to [`CHANNELS`] with a zero weight, then (with the view group) their view parts.
fn padded_passes(layout: &FeatureLayout, weights: &[Vec<f32>]) -> Vec<Vec<f32>> {
    let voxels = layout.voxel_count();
    weights
        .chunks(MAX_WEIGHTS)
        .map(|chunk| {
            let mut padded = Vec::with_capacity(chunk.len() * pass_stride(layout));
            for w in chunk {
                for voxel in w[..voxels * PER_VOXEL].chunks(PER_VOXEL) {
                    padded.extend_from_slice(voxel);
                    padded.resize(padded.len() + CHANNELS - PER_VOXEL, 0.0);
                }
            }
            if layout.groups.view {
                let offset = layout.view_offset();
                for w in chunk {
                    padded.extend_from_slice(&w[offset..offset + VIEW]);
                }
            }
            padded
        })
        .collect()
}

/// Numbers per weight vector in a pass of [`padded_passes`].
fn pass_stride(layout: &FeatureLayout) -> usize {
    layout.voxel_count() * CHANNELS + if layout.groups.view { VIEW } else { 0 }
}

/// Packs every dispatch of every job and hands them to `execute` one batch at a time (GPU: one submission
/// per batch; CPU twin: each dispatch in turn), which returns each dispatch's `records.len() × weight count`
/// scores (voxel and view parts); returns, per job, `scores[h·W + w]`. Jobs whose
/// hypotheses share a table (same yaw, bottom and height) share its group: the table is built once. The
/// dispatches, and so the scores, do not depend on how they are batched or which other jobs come along.
/// Batches are planned from the groups' sizes first ([`plan_batches`]); a batch's groups are packed
/// (records and boundaries computed, tables built on the CPU when `build_tables`) in parallel,
/// and **the next batch is packed while the last one executes** (`rayon::join`: the packing of a call's
/// next batch used to wait for its last batch's GPU work and read-back), so at most two batches are held.
/// Nothing blocks a rayon thread on work that needs another one (a thread waiting in the join helps with
/// the other half; a batch's execution waits only on the GPU and on a pool set, whose holder does no rayon
/// work while it holds it).
fn run(
    engine: &FastEngine,
    jobs: &[FastJob],
    chunking: FastChunking,
    build_tables: bool,
    times: &mut RunTimes,
    mut execute: impl FnMut(&[FastDispatch]) -> Result<Vec<Vec<f32>>> + Send,
) -> Result<Vec<Vec<f32>>> {
    let layout = engine.layout();
    layout.validate()?;
    let scene = engine.scene();
    for job in jobs {
        validate_job(engine, job)?;
    }
    if let Some(cells) = (0..scene.yaws.len()).flat_map(|y| engine.lattice(y).cells()).find(|&c| c > MAX_LATTICE_CELLS)
    {
        return Err(Error::Gpu(format!(
            "fast_scores: a lattice of {cells} cells along an axis; the packed voxel boundaries address at most \
             {MAX_LATTICE_CELLS}"
        )));
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
    let dim = layout.dim();
    let g = layout.grid();
    let words = boundary_words(&g) as u32;
    let [fx, fy, _, _] = scene.pre.camera.intrinsics;
    let inv_cog_scale = 1.0 / engine.cog_scale();
    let params_of = |group: &PackedGroup, chunk: &PackedChunk, count: usize| {
        let stride = group.region.table_stride();
        let grid = &scene.yaws[group.yaw_index];
        let m = grid.camera_from_rotated;
        let front = Cuboid::new(Vec3::ZERO, Vec3::ONE, grid.yaw).front();
        FastParams {
            grid: [g[0], g[1], g[2], dim as u32],
            job: [chunk.records.len() as u32, count as u32, group_bits(layout), words],
            table: [stride[0] as u32, stride[1] as u32, 0, 0],
            scale: [fx, fy, inv_cog_scale, 0.0],
            m0: m.x_axis.extend(0.0).to_array(),
            m1: m.y_axis.extend(0.0).to_array(),
            m2: m.z_axis.extend(0.0).to_array(),
            // Filled in by the batch's layout.
            base: [0; 4],
            at: [0; 4],
            view: [grid.cos, grid.sin, front.x, front.y],
        }
    };
    let mut flush = |batch: &[PackedGroup], scores: &mut [Vec<f32>], times: &mut RunTimes| -> Result<()> {
        let mut dispatches = Vec::new();
        let mut owners = Vec::new();
        let mut chunk_index = 0;
        for (group_index, group) in batch.iter().enumerate() {
            for chunk in &group.chunks {
                for (pass, pass_weights) in passes[chunk.job].iter().enumerate() {
                    let count = pass_weights.len() / pass_stride(layout).max(1);
                    dispatches.push(FastDispatch {
                        group: group_index,
                        chunk: chunk_index,
                        pass: first_pass[chunk.job] + pass,
                        params: params_of(group, chunk, count),
                        table: group.table.as_ref().map(LayerTable::sums),
                        yaw_index: group.yaw_index,
                        span: group.span,
                        region: group.region,
                        records: &chunk.records,
                        bounds: &chunk.bounds,
                        weights: pass_weights,
                    });
                    owners.push((chunk, pass));
                }
                chunk_index += 1;
            }
        }
        let executed = std::time::Instant::now();
        let outs = execute(&dispatches)?;
        times.execute += executed.elapsed().as_secs_f64();
        let placing = std::time::Instant::now();
        if outs.len() != dispatches.len() {
            return Err(Error::Gpu(format!("{} dispatches returned {} results", dispatches.len(), outs.len())));
        }
        for ((d, out), (chunk, pass)) in dispatches.iter().zip(&outs).zip(owners) {
            let count = d.params.job[1] as usize;
            let w_total = w_totals[chunk.job];
            let job_scores = &mut scores[chunk.job];
            for (slot, &n) in chunk.members.iter().enumerate() {
                let row = &mut job_scores[n * w_total + pass * MAX_WEIGHTS..][..count];
                row.copy_from_slice(&out[slot * count..(slot + 1) * count]);
            }
        }
        times.place += placing.elapsed().as_secs_f64();
        Ok(())
    };
    // Table groups over all jobs, in key order (deterministic), each with its jobs' members in job order.
    let grouping = std::time::Instant::now();
    let mut by_key: BTreeMap<TableKey, JobMembers> = BTreeMap::new();
    let job_groups: Vec<Vec<(TableKey, Vec<usize>)>> = jobs
        .par_iter()
        .map(|job| if job.weights.is_empty() { Vec::new() } else { group_by_table(job.hypotheses) })
        .collect();
    for (j, groups) in job_groups.into_iter().enumerate() {
        for (key, members) in groups {
            by_key.entry(key).or_default().push((j, members));
        }
    }
    times.group += grouping.elapsed().as_secs_f64();
    let groups: Vec<(TableKey, JobMembers)> = by_key.into_iter().collect();
    let plan = plan_batches(engine, &groups, &w_totals, chunking.max_batch_bytes);
    let pack = |range: &std::ops::Range<usize>| -> (Vec<PackedGroup>, f64) {
        let packing = std::time::Instant::now();
        let packed = groups[range.clone()]
            .par_iter()
            .map(|(key, members)| PackedGroup::new(engine, jobs, *key, members, chunking.max_chunk, build_tables))
            .collect();
        (packed, packing.elapsed().as_secs_f64())
    };
    let mut current = plan.first().map(pack);
    for range in plan.iter().skip(1).map(Some).chain([None]) {
        let Some((batch, pack_seconds)) = current.take() else { break };
        times.pack += pack_seconds;
        let (next, executed) = rayon::join(|| range.map(pack), || flush(&batch, &mut scores, times));
        executed?;
        current = next;
    }
    Ok(scores)
}

/// Seconds of the parts of [`run`] (for the debug log): grouping the hypotheses by table, packing the
/// groups (records and boundaries), executing the batches, placing their
/// scores.
#[derive(Default)]
struct RunTimes {
    group: f64,
    pack: f64,
    execute: f64,
    place: f64,
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

/// The latent support surfaces' slice scores on the GPU (paper §4: "on the GPU the seven slices of one
/// hypothesis come from the same tables"): the fast kernel on the surface grid's tables with the
/// [`slice_weight_vectors`], one weight vector per slice, plus the height biases — what
/// [`SurfaceEngine::slice_scores`] gives on the CPU (its twin there: [`FastEngine::scores`] with the same
/// vectors equals [`FastEngine::layer_scores`] bit for bit), to the kernel's ~1e-6 relative.
pub fn slice_scores_gpu(
    ctx: &GpuContext,
    engine: &SurfaceEngine,
    hypotheses: &[Hypothesis],
    weights: &SurfaceWeights,
) -> Result<Vec<[f32; SLICES]>> {
    let layers =
        fast_scores_gpu(ctx, engine.engine(), hypotheses, &slice_weight_vectors(weights, engine.engine().layout()))?;
    Ok(with_height_biases(&layers, weights))
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

/// Several jobs' fast-path scores on the GPU (see `run`: tables shared between jobs are built once), cut as
/// `chunking` says. Per batch (`run_batch`): its inputs placed by one `BatchLayout` in pooled buffers,
/// its tables built by [`crate::gpu::fast_tables`]'s kernels (one dispatch per phase) and all its hypotheses
/// scored by one dispatch, in four compute passes of one submission, and one read-back.
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
        // A batch's tables are bound as one range (the table kernels see them all).
        max_batch_bytes: chunking.max_batch_bytes.min(max_binding),
    };
    ctx.checked("fast_scores kernels", || {
        let mut submissions = 0usize;
        let mut dispatch_count = 0usize;
        let mut tables = (0usize, 0u64);
        // Where the call's wall time goes (debug log): packing and view features on the CPU are the rest.
        let started = std::time::Instant::now();
        let mut batch_times = BatchTimes::default();
        let mut run_times = RunTimes::default();
        let scores = run(engine, jobs, chunking, false, &mut run_times, |dispatches| {
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
            }
            submissions += 1;
            dispatch_count += dispatches.len();
            run_batch(ctx, engine, dispatches, &mut batch_times)
        })?;
        let scores = with_out_of_view_scores(engine, jobs, scores);
        let total = started.elapsed().as_secs_f64();
        log::debug!(
            "fast_scores time: {total:.4} s in all: grouping {:.4}, packing {:.4} (while earlier \
             batches execute), placing scores {:.4}; batches {:.4}: preparing {:.4} (layout {:.4}, waiting for the \
             pool {:.4}, buffers {:.4}, uploads {:.4}, bind groups {:.4}, encoding {:.4}), submitting and waiting \
             for the GPU and the read-back {:.4} (GPU passes: scatter {:.4}, rows {:.4}, columns {:.4}, scoring \
             {:.4})",
            run_times.group,
            run_times.pack,
            run_times.place,
            run_times.execute,
            batch_times.prepare,
            batch_times.layout,
            batch_times.pool_wait,
            batch_times.buffers,
            batch_times.uploads,
            batch_times.bind_groups,
            batch_times.encoding,
            batch_times.wait,
            batch_times.gpu[0],
            batch_times.gpu[1],
            batch_times.gpu[2],
            batch_times.gpu[3],
        );
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
    table_words(&table_params_at(engine.lattice(d.yaw_index), d.span, 0, 0, 0, d.region))
}

/// Where everything of one batch lies in its buffers, computed once and used alike by the GPU path and its
/// CPU twin: each yaw's lattice points (packed, indexed by point), each group's table, each chunk's records
/// and boundaries, each weight pass, and per dispatch its scores and its record ([`FastParams`] with the
/// bases filled in).
struct BatchLayout<'p> {
    /// Per yaw of the scene: its first point and its points, when the batch uses it.
    yaw_points: Vec<Option<(usize, &'p [TablePoint])>>,
    point_count: usize,
    /// Per group index.
    groups: Vec<GroupPlacement>,
    /// Per chunk index: byte offsets of its records and boundaries.
    chunks: Vec<(u64, u64)>,
    /// Per global weight pass: byte offset of its weights, when the batch uses it.
    passes: Vec<Option<u64>>,
    /// Per dispatch: its record (at `i · record_stride` of the records buffer), and the byte offset of its
    /// scores.
    params: Vec<FastParams>,
    outs: Vec<u64>,
    tables: Arena,
    records: Arena,
    bounds: Arena,
    weights: Arena,
    scores: Arena,
}

impl<'p> BatchLayout<'p> {
    /// The layout of `dispatches` with storage offsets aligned to `align` bytes; the yaws' lattice points
    /// are the engine's own (uploaded as they are).
    fn new(engine: &'p FastEngine, dispatches: &[FastDispatch], align: u32) -> Result<BatchLayout<'p>> {
        let too_large = |what: &str| Error::Gpu(format!("fast_scores: a batch's {what} pass 2³² elements"));
        let index = |bytes: u64, unit: u64, what: &str| u32::try_from(bytes / unit).map_err(|_| too_large(what));
        let mut used = vec![false; engine.scene().yaws.len()];
        for d in dispatches {
            used[d.yaw_index] = true;
        }
        let mut point_count = 0usize;
        let yaw_points: Vec<Option<(usize, &[TablePoint])>> = used
            .iter()
            .enumerate()
            .map(|(yaw, &used)| {
                let points = used.then(|| table_points(engine.lattice(yaw)))?;
                let first = point_count;
                point_count += points.len();
                Some((first, points))
            })
            .collect();
        let [mut tables, mut records, mut bounds, mut weights, mut scores] = [(); 5].map(|_| Arena::new(align));
        let mut groups: Vec<GroupPlacement> = Vec::new();
        let mut chunks: Vec<(u64, u64)> = Vec::new();
        let mut passes: Vec<Option<u64>> = Vec::new();
        let mut params = Vec::with_capacity(dispatches.len());
        let mut outs = Vec::with_capacity(dispatches.len());
        for d in dispatches {
            if d.group == groups.len() {
                let lattice = engine.lattice(d.yaw_index);
                let table_bytes = 4 * table_words(&table_params_at(lattice, d.span, 0, 0, 0, d.region)) as u64;
                let table = tables.place(table_bytes);
                let first_word = index(table, 4, "tables")?;
                let first_point = yaw_points[d.yaw_index].expect("placed above").0 as u32;
                let steps = [0, SCAN_ROWS, SCAN_COLUMNS]
                    .map(|mode| table_params_at(lattice, d.span, mode, first_word, first_point, d.region));
                groups.push(GroupPlacement { table, params: steps });
            }
            if d.chunk == chunks.len() {
                let record = records.place(std::mem::size_of_val(d.records) as u64);
                chunks.push((record, bounds.place(std::mem::size_of_val(d.bounds) as u64)));
            }
            if passes.len() <= d.pass {
                passes.resize(d.pass + 1, None);
            }
            let weight = *passes[d.pass].get_or_insert_with(|| weights.place(std::mem::size_of_val(d.weights) as u64));
            let (group, (record, bound)) = (&groups[d.group], chunks[d.chunk]);
            let out = scores.place(4 * (d.records.len() * d.params.job[1] as usize) as u64);
            params.push(FastParams {
                base: [
                    index(group.table, 16, "tables")?,
                    index(record, std::mem::size_of::<FastRecord>() as u64, "records")?,
                    index(bound, 4, "boundaries")?,
                    index(weight, 16, "weights")?,
                ],
                at: [index(out, 4, "scores")?, 0, 0, 0],
                ..d.params
            });
            outs.push(out);
        }
        Ok(BatchLayout {
            yaw_points,
            point_count,
            groups,
            chunks,
            passes,
            params,
            outs,
            tables,
            records,
            bounds,
            weights,
            scores,
        })
    }

    /// Each dispatch's scores, cut from the batch's score buffer `all`.
    fn split_scores(&self, dispatches: &[FastDispatch], all: &[f32]) -> Vec<Vec<f32>> {
        dispatches
            .iter()
            .zip(&self.outs)
            .map(|(d, &out)| {
                let start = (out / 4) as usize;
                all[start..start + d.records.len() * d.params.job[1] as usize].to_vec()
            })
            .collect()
    }
}

/// One batch on the GPU: uploads its lattice points, records, boundaries, weights and dispatch records into
/// pooled buffers, builds its tables (three dispatches) and scores its hypotheses (one dispatch per record,
/// all through one bind group), submits once and reads the scores back once.
fn run_batch(
    ctx: &GpuContext,
    engine: &FastEngine,
    dispatches: &[FastDispatch],
    times: &mut BatchTimes,
) -> Result<Vec<Vec<f32>>> {
    let started = std::time::Instant::now();
    let mut mark = started;
    let storage_align = ctx.limits.min_storage_buffer_offset_alignment;
    let layout = BatchLayout::new(engine, dispatches, storage_align)?;
    times.layout += split(&mut mark);
    // The pooled buffers are this batch's until its scores are read back. Calls on other threads (other
    // engines of the frame) pack their batches meanwhile; nothing below runs rayon work, so a thread that
    // holds the lock never steals a task that waits for it.
    let mut pool = ctx.pool();
    times.pool_wait += split(&mut mark);
    let max_size = ctx.limits.max_buffer_size;
    let mut pooled = |label: &'static str, usage: wgpu::BufferUsages, bytes: u64| {
        pool.buffer(&ctx.device, label, usage, bytes, max_size)
    };
    let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
    let point_bytes = (layout.point_count * std::mem::size_of::<TablePoint>()) as u64;
    // The dispatch records, each at a multiple of the uniform-offset alignment.
    let record_size = std::mem::size_of::<FastParams>() as u64;
    let record_stride = record_size.next_multiple_of(u64::from(ctx.limits.min_uniform_buffer_offset_alignment));
    let params_bytes = record_stride * layout.params.len() as u64;
    // The tables, boundaries and weights are read by the scoring kernel as textures (`TexelRows`: lavapipe
    // reads storage buffers lane by lane), copies of their buffers; the buffers hold whole rows for the copies.
    let max_rows = ctx.limits.max_texture_dimension_2d;
    let table_rows = TexelRows::for_bytes(layout.tables.len, max_rows, "fast_scores: the batch's tables")?;
    let weight_rows = TexelRows::for_bytes(layout.weights.len, max_rows, "fast_scores: the batch's weights")?;
    let bound_rows = TexelRows::for_bytes(layout.bounds.len, max_rows, "fast_scores: the batch's boundaries")?;
    let lattice_buffer = pooled("fast lattice points", storage, point_bytes);
    // Pooled, so not zero: the table range is cleared on the GPU before the scatter adds into it.
    let table_buffer = pooled("fast tables", storage, table_rows.bytes());
    let record_buffer = pooled("fast records", storage, layout.records.len);
    let bound_buffer = pooled("fast bounds", storage, bound_rows.bytes());
    let weight_buffer = pooled("fast weights", storage, weight_rows.bytes());
    let params_buffer = pooled("fast params", wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST, params_bytes);
    let out_buffer = pooled("fast scores", storage, layout.scores.len);
    let staging =
        pooled("fast scores staging", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST, layout.scores.len);
    // The table kernels' params: the three phases one after the other, each at an aligned offset.
    let table_params_size = std::mem::size_of::<TableParams>();
    let mut phase_params = Arena::new(storage_align);
    let phase_at: [u64; 3] = [(); 3].map(|_| phase_params.place((layout.groups.len() * table_params_size) as u64));
    let table_params_buffer = pooled("fast table params", storage, phase_params.len);
    let table_texture = pool.texture(&ctx.device, "fast tables", wgpu::TextureFormat::Rgba32Uint, table_rows, max_rows);
    let weight_texture =
        pool.texture(&ctx.device, "fast weights", wgpu::TextureFormat::Rgba32Float, weight_rows, max_rows);
    let bound_texture = pool.texture(&ctx.device, "fast bounds", wgpu::TextureFormat::Rgba32Uint, bound_rows, max_rows);
    // Everything the batch uploads, laid out as in its destination buffers, region after region, in one
    // pooled upload buffer: one copy per destination buffer.
    let mut regions = Arena::new(wgpu::COPY_BUFFER_ALIGNMENT as u32);
    let region_sizes =
        [point_bytes, phase_params.len, layout.records.len, layout.bounds.len, layout.weights.len, params_bytes]
            .map(|bytes| bytes.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT));
    let [point_region, phase_region, record_region, bound_region, weight_region, params_region] =
        region_sizes.map(|bytes| regions.place(bytes));
    let upload = ctx.mapped_upload(&mut pool, "fast uploads", regions.len)?;
    times.buffers += split(&mut mark);
    {
        let mut image = upload
            .get_mapped_range_mut(..regions.len.max(4))
            .map_err(|e| Error::Gpu(format!("writing the mapped upload buffer: {e}")))?;
        let mut put = |region: u64, at: u64, bytes: &[u8]| {
            let start = (region + at) as usize;
            image.slice(start..start + bytes.len()).copy_from_slice(bytes);
        };
        for (first, points) in layout.yaw_points.iter().flatten() {
            put(point_region, (first * std::mem::size_of::<TablePoint>()) as u64, bytemuck::cast_slice(points));
        }
        for (step, &at) in phase_at.iter().enumerate() {
            let step_params: Vec<TableParams> = layout.groups.iter().map(|g| g.params[step]).collect();
            put(phase_region, at, bytemuck::cast_slice(&step_params));
        }
        // Each chunk's records and boundaries and each pass's weights once (dispatches share them).
        let mut chunk_written = vec![false; layout.chunks.len()];
        let mut pass_written = vec![false; layout.passes.len()];
        for d in dispatches {
            if !std::mem::replace(&mut chunk_written[d.chunk], true) {
                let (record, bound) = layout.chunks[d.chunk];
                put(record_region, record, bytemuck::cast_slice(d.records));
                put(bound_region, bound, bytemuck::cast_slice(d.bounds));
            }
            if !std::mem::replace(&mut pass_written[d.pass], true) {
                let at = layout.passes[d.pass].expect("placed with its dispatch");
                put(weight_region, at, bytemuck::cast_slice(d.weights));
            }
        }
        for (n, record) in layout.params.iter().enumerate() {
            put(params_region, n as u64 * record_stride, bytemuck::bytes_of(record));
        }
    }
    pool.unmap_upload("fast uploads", &upload);
    times.uploads += split(&mut mark);
    // The tables: three phases (scatter, rows, columns), each one dispatch over all the batch's tables
    // (workgroup z: the table), in pieces of at most TABLES_PER_DISPATCH tables.
    let mut phases: [Vec<(wgpu::BindGroup, u32, u32)>; 3] = Default::default();
    for (step, &at) in phase_at.iter().enumerate() {
        let kernel = if step == 0 { &ctx.kernels.fast_table_scatter } else { &ctx.kernels.fast_table_scan };
        for (piece, members) in layout.groups.chunks(TABLES_PER_DISPATCH).enumerate() {
            let offset = at + (piece * TABLES_PER_DISPATCH * table_params_size) as u64;
            let invocations = members.iter().map(|g| table_invocations(&g.params[0])[step]).max().unwrap_or(0);
            let bind_group = ctx.bind_group_ranges(
                kernel,
                &[
                    (&table_params_buffer, offset, (members.len() * table_params_size) as u64),
                    (&lattice_buffer, 0, point_bytes.max(4)),
                    (&table_buffer, 0, layout.tables.len.max(4)),
                ],
            );
            phases[step].push((bind_group, invocations, members.len() as u32));
        }
    }
    let kernel = &ctx.kernels.fast_scores;
    let [table_view, bound_view, weight_view] =
        [&table_texture, &bound_texture, &weight_texture].map(|t| t.create_view(&Default::default()));
    let scoring = ctx.bind_group_resources(
        kernel,
        &[
            buffer_range(&params_buffer, 0, record_size),
            wgpu::BindingResource::TextureView(&table_view),
            buffer_range(&record_buffer, 0, layout.records.len.max(4)),
            wgpu::BindingResource::TextureView(&bound_view),
            wgpu::BindingResource::TextureView(&weight_view),
            buffer_range(&out_buffer, 0, layout.scores.len.max(4)),
        ],
    );
    times.bind_groups += split(&mut mark);
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(kernel.label) });
    let destinations = [
        (&lattice_buffer, point_region),
        (&table_params_buffer, phase_region),
        (&record_buffer, record_region),
        (&bound_buffer, bound_region),
        (&weight_buffer, weight_region),
        (&params_buffer, params_region),
    ];
    for ((buffer, region), bytes) in destinations.into_iter().zip(region_sizes) {
        if bytes > 0 {
            encoder.copy_buffer_to_buffer(&upload, region, buffer, 0, Some(bytes));
        }
    }
    let timer = ctx.pass_timer(4);
    encoder.clear_buffer(&table_buffer, 0, Some(layout.tables.len.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT)));
    // Each dispatch is its own usage scope (WebGPU): a phase sees the previous phase's writes.
    let table_kernels = [&ctx.kernels.fast_table_scatter, &ctx.kernels.fast_table_scan, &ctx.kernels.fast_table_scan];
    for (index, (kernel, jobs)) in table_kernels.into_iter().zip(&phases).enumerate() {
        let jobs: Vec<(&wgpu::BindGroup, u32, u32)> = jobs.iter().map(|(b, n, z)| (b, *n, *z)).collect();
        ctx.encode_layered_dispatches(&mut encoder, kernel, &jobs, timer.as_ref().map(|t| (t, index as u32)))?;
    }
    table_rows.encode_copy(&mut encoder, &table_buffer, &table_texture);
    weight_rows.encode_copy(&mut encoder, &weight_buffer, &weight_texture);
    bound_rows.encode_copy(&mut encoder, &bound_buffer, &bound_texture);
    // One invocation per hypothesis (the 1-D convention).
    let jobs: Vec<(u32, u32)> = dispatches
        .iter()
        .enumerate()
        .map(|(n, d)| {
            let offset = u32::try_from(n as u64 * record_stride);
            let invocations = u32::try_from(d.records.len());
            match (offset, invocations) {
                (Ok(offset), Ok(invocations)) => Ok((offset, invocations)),
                _ => Err(Error::Gpu("fast_scores: a dispatch record offset or size beyond 2³²".into())),
            }
        })
        .collect::<Result<_>>()?;
    ctx.encode_dispatches_at(&mut encoder, kernel, &scoring, &jobs, timer.as_ref().map(|t| (t, 3)))?;
    if let Some(timer) = &timer {
        timer.resolve(&mut encoder);
    }
    times.encoding += split(&mut mark);
    let prepared = std::time::Instant::now();
    let all: Vec<f32> = ctx.read_buffer_through(encoder, &out_buffer, (layout.scores.len / 4) as usize, &staging)?;
    times.prepare += (prepared - started).as_secs_f64();
    times.wait += prepared.elapsed().as_secs_f64();
    if let Some(timer) = &timer {
        for (total, seconds) in times.gpu.iter_mut().zip(timer.seconds(ctx)?) {
            *total += seconds;
        }
    }
    Ok(layout.split_scores(dispatches, &all))
}

/// Seconds of [`run_batch`] calls: before the submission, and from it to the scores on the CPU.
#[derive(Default)]
struct BatchTimes {
    prepare: f64,
    /// The batch's layout.
    layout: f64,
    /// Waiting for the buffer pool while another call's batch holds it.
    pool_wait: f64,
    buffers: f64,
    uploads: f64,
    bind_groups: f64,
    encoding: f64,
    wait: f64,
    /// GPU seconds of the four passes (when the device has timestamp queries and the debug log is on).
    gpu: [f64; 4],
}

/// Seconds since `*mark`, moving the mark to now.
fn split(mark: &mut std::time::Instant) -> f64 {
    let now = std::time::Instant::now();
    let seconds = (now - *mark).as_secs_f64();
    *mark = now;
    seconds
}

/// Where one table group's table lies in a batch's buffers, and its build params.
struct GroupPlacement {
    /// Byte offset in the tables buffer.
    table: u64,
    /// Scatter, rows, columns.
    params: [TableParams; 3],
}

/// Tables per dispatch of a table phase (the dispatch's workgroup z); a multiple of 16 so that every piece's
/// params (48 bytes each) start at a multiple of 256 bytes, the largest storage-offset alignment there is.
const TABLES_PER_DISPATCH: usize = 16384;
const _: () = assert!((TABLES_PER_DISPATCH * std::mem::size_of::<TableParams>()).is_multiple_of(256));

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
    run(engine, jobs, chunking, true, &mut RunTimes::default(), |dispatches| {
        // The GPU's layout and buffers, filled on the CPU (the tables from the CPU's LayerTables).
        let layout = BatchLayout::new(engine, dispatches, TWIN_ALIGN)?;
        let mut table = vec![0u32; (layout.tables.len / 4) as usize];
        let mut records = vec![FastRecord::default(); (layout.records.len / 32) as usize];
        // Whole texels (4 words), as the texture the shader reads them from.
        let mut bounds = vec![0u32; (layout.bounds.len / 4).next_multiple_of(4) as usize];
        let mut weights = vec![0.0f32; (layout.weights.len / 4) as usize];
        for d in dispatches {
            let group = &layout.groups[d.group];
            let words = d.table.ok_or_else(|| Error::Gpu("the CPU twin needs the CPU-built table".into()))?;
            let at = (group.table / 4) as usize;
            table[at..at + words.len()].copy_from_slice(words);
            let (record, bound) = layout.chunks[d.chunk];
            let at = (record / 32) as usize;
            records[at..at + d.records.len()].copy_from_slice(d.records);
            let at = (bound / 4) as usize;
            bounds[at..at + d.bounds.len()].copy_from_slice(d.bounds);
            let at = (layout.passes[d.pass].expect("placed") / 4) as usize;
            weights[at..at + d.weights.len()].copy_from_slice(d.weights);
        }
        // Every invocation of every dispatch: (dispatch, hypothesis).
        let invocations: Vec<(usize, usize)> =
            dispatches.iter().enumerate().flat_map(|(n, d)| (0..d.records.len()).map(move |h| (n, h))).collect();
        let writes: Vec<Vec<(usize, f32)>> = invocations
            .into_par_iter()
            .map(|(n, h)| fast_scores_main(&layout.params[n], &table, &records, &bounds, &weights, h))
            .collect();
        let mut out = vec![0.0f32; (layout.scores.len / 4) as usize];
        for (at, value) in writes.into_iter().flatten() {
            out[at] = value;
        }
        Ok(layout.split_scores(dispatches, &out))
    })
    .map(|scores| with_out_of_view_scores(engine, jobs, scores))
}

/// The jobs' kernel scores with the out-of-view group's part added (on the CPU, by the rule every path
/// shares: `features::out_of_view`; the kernel's weights hold only the voxel and view parts).
fn with_out_of_view_scores(engine: &FastEngine, jobs: &[FastJob], mut scores: Vec<Vec<f32>>) -> Vec<Vec<f32>> {
    for (job, job_scores) in jobs.iter().zip(&mut scores) {
        add_out_of_view_scores(engine.scene(), engine.layout(), job.hypotheses, job.weights, job_scores);
    }
    scores
}

/// The CPU twin's storage-offset alignment (any power of two from 32 gives the same scores; 256 is the
/// largest a device may ask for).
const TWIN_ALIGN: u32 = 256;

/// The shader's `main` for the invocation of hypothesis `h` of the dispatch of record `params`: the writes it
/// makes, as (index in `out`, value). Written to read like `shaders/fast_scores.wgsl`; its `vec4`s are
/// `[_; 4]` here; `table`, `bounds` and `weights` are the buffers the shader sees as textures, read through
/// `texel` as it reads them (element `n` of a [`TexelRows`] texture is element `n` of its buffer).
pub fn fast_scores_main(
    params: &FastParams,
    table: &[u32],
    records: &[FastRecord],
    bounds: &[u32],
    weights: &[f32],
    h: usize,
) -> Vec<(usize, f32)> {
    // Past the last hypothesis of its dispatch (the grid's padding): no work, no write.
    if h >= params.job[0] as usize {
        return Vec::new();
    }
    let [nx, ny, nz, _] = params.grid.map(|v| v as usize);
    let weight_count = params.job[1] as usize;
    let groups = params.job[2];
    let use_density = groups & 1 != 0;
    let use_normals = groups & 2 != 0;
    let use_cog = groups & 4 != 0;
    let use_view = groups & 8 != 0;
    let mut score = [0.0f32; MAX_WEIGHTS];

    let record = &records[params.base[1] as usize + h];
    let lo = record.lo;
    let cell = record.cell;
    let face_areas = [cell[1] * cell[2], cell[0] * cell[2], cell[0] * cell[1]];
    let [fx, fy, inv_cog_scale, _] = params.scale;
    let b = params.base[2] as usize + h * params.job[3] as usize;
    let row = params.table[0] as usize;
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
    // Boundary k of the hypothesis: its word read from its texel (four words per texel), unpacked by
    // `packed_boundary` (that word is word 0 of the slice; k & 1 picks its half).
    let boundary = |k: usize| -> usize {
        let word = b + (k >> 1);
        let words = texel_at(bounds, texel(word / 4));
        packed_boundary(&words[word % 4..], k & 1) as usize
    };
    // The entry whose first vec4 is element e: the 36 channels of a corner, as 9 vec4.
    let corner = |e: usize| -> [[u32; 4]; 9] { std::array::from_fn(|c| texel_at(table, texel(e + c))) };
    let sums = |high: [u32; 4], left: [u32; 4], low: [u32; 4], both: [u32; 4]| -> [u32; 4] {
        [0, 1, 2, 3].map(|n| high[n].wrapping_sub(left[n]).wrapping_sub(low[n]).wrapping_add(both[n]))
    };
    // The voxels in the layout's order ℓ = (k·ny + j)·nx + i.
    for k in 0..nz {
        let layer = k * params.table[1] as usize;
        for j in 0..ny {
            let y0 = boundary(nx + 1 + j);
            let y1 = boundary(nx + 1 + j + 1);
            // Step 3: each voxel's right corners are the next one's left corners.
            let x_first = boundary(0);
            let mut left = corner(params.base[0] as usize + ((layer + y1) * row + x_first) * 9);
            let mut both = corner(params.base[0] as usize + ((layer + y0) * row + x_first) * 9);
            for i in 0..nx {
                let v = (k * ny + j) * nx + i;
                let x1 = boundary(i + 1);
                let high = corner(params.base[0] as usize + ((layer + y1) * row + x1) * 9);
                let low = corner(params.base[0] as usize + ((layer + y0) * row + x1) * 9);
                let channel = |c: usize| sums(high[c], left[c], low[c], both[c]);
                let s0 = channel(0);
                if s0[0] == 0 {
                    left = high;
                    both = low;
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
                // COG bins are channels 26..34: s6.zw, s7, s8.xyz.
                let s6 = channel(6);
                let s7 = channel(7);
                let s8 = channel(8);
                let mut cog = 0.0f32;
                if use_cog {
                    let g = [s6[2], s6[3], s7[0], s7[1], s7[2], s7[3], s8[0], s8[1], s8[2]]
                        .map(|x| x as f32 * inv_cog_scale);
                    let mut norm_sq = 0.0f32;
                    for x in g {
                        norm_sq += x * x;
                    }
                    cog = inv_cog_scale * (1.0 / (norm_sq + COG_EPSILON).sqrt());
                }
                let f = [
                    mul(to_f32(s0), [density, normal, normal, normal]),
                    mul(to_f32(channel(1)), [normal; 4]),
                    mul(to_f32(channel(2)), [normal; 4]),
                    mul(to_f32(channel(3)), [normal; 4]),
                    mul(to_f32(channel(4)), [normal; 4]),
                    mul(to_f32(channel(5)), [normal; 4]),
                    mul(to_f32(s6), [normal, normal, cog, cog]),
                    mul(to_f32(s7), [cog; 4]),
                    mul(to_f32(s8), [cog, cog, cog, 0.0]),
                ];
                for (w, slot) in score.iter_mut().enumerate().take(weight_count) {
                    let wb = params.base[3] as usize + (w * voxels + v) * 9;
                    let mut acc = 0.0f32;
                    for (c, fc) in f.iter().enumerate() {
                        acc = dot_acc(acc, texel_at(weights, texel(wb + c)), *fc);
                    }
                    *slot += acc;
                }
                left = high;
                both = low;
            }
        }
    }
    // The view part (the shader's `view_cosine`; its `view_part` writes out `view_features`).
    let view_cosine = |s: f32, t: f32| -> f32 {
        let x = s * params.view[0] - t * params.view[1];
        let y = s * params.view[1] + t * params.view[0];
        let to_camera = [-x, -y];
        let length = (to_camera[0] * to_camera[0] + to_camera[1] * to_camera[1]).sqrt();
        if length < VIEW_MIN_DISTANCE {
            return 0.0;
        }
        let inv_length = 1.0 / length;
        params.view[2] * (to_camera[0] * inv_length) + params.view[3] * (to_camera[1] * inv_length)
    };
    // The VIEW weights after the pass's voxel weights, dotted in order with the view features.
    let view_part = |w: usize, cosine: f32| -> f32 {
        let wb = 4 * (params.base[3] as usize + weight_count * voxels * 9 + w * 3);
        dot(&weights[wb..wb + VIEW], &view_features(cosine))
    };
    let cosine = view_cosine(record.lo[3], record.cell[3]);
    (0..weight_count)
        .map(|w| {
            let mut total = score[w];
            if use_view {
                total += view_part(w, cosine);
            }
            (params.at[0] as usize + h * weight_count + w, total)
        })
        .collect()
}

/// The shader's `texel`: where `vec4` element `n` of a buffer lies in its [`TexelRows`] texture.
fn texel(n: usize) -> [usize; 2] {
    let width = TexelRows::WIDTH as usize;
    [n % width, n / width]
}

/// The texel `[x, y]` of the [`TexelRows`] texture copied from `data` (rows of `WIDTH` `vec4`s).
fn texel_at<T: Copy>(data: &[T], [x, y]: [usize; 2]) -> [T; 4] {
    let n = 4 * (y * TexelRows::WIDTH as usize + x);
    [data[n], data[n + 1], data[n + 2], data[n + 3]]
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_boundaries_unpack_to_themselves() {
        for g in [[5u32, 5, 5], [7, 7, 7], [5, 3, 5], [4, 2, 1]] {
            let count = (g[0] + g[1] + 2) as usize;
            // Every value a boundary can take at the edges of the 16 bits, and some between.
            let edges = [0, 1, 255, 256, 65_534, MAX_LATTICE_CELLS as u32];
            let boundaries: Vec<u32> =
                (0..count).map(|k| (edges[k % 6] + (k / 6) as u32).min(MAX_LATTICE_CELLS as u32)).collect();
            let mut words = vec![u32::MAX; boundary_words(&g)];
            pack_boundaries(&boundaries, &mut words);
            assert_eq!(words.len(), count.div_ceil(2));
            let unpacked: Vec<u32> = (0..count).map(|k| packed_boundary(&words, k)).collect();
            assert_eq!(unpacked, boundaries, "grid {g:?}");
            if count % 2 == 1 {
                assert_eq!(words[count / 2] >> 16, 0, "grid {g:?}: the last word's upper half is clear");
            }
        }
    }
}
