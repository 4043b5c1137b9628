//! The scoring backend: the one place that chooses, per scoring step, between the CPU implementations of
//! [`crate::features`] and their GPU kernels in [`crate::gpu`]. It sits above both, so that `features`
//! (definitions, CPU reference and fast path) never imports `gpu`, and `gpu` (kernels and their CPU
//! twins) imports `features` only for the definitions it shares: data and imports flow one way,
//! `features` → `gpu` → `backend` → `detect` and the commands. The same holds for the room layout:
//! `room_layout` (definitions, CPU scorer) → `gpu::room_layout` (its kernel) → [`Backend::layout_scores`],
//! which the commands hand to [`crate::room_layout::predict`].

use crate::error::Result;
use crate::features::fast::FastEngine;
use crate::features::preprocess::NormalSearch;
use crate::features::surface::{SurfaceEngine, SurfaceWeights, SLICES};
use crate::features::Preprocessed;
use crate::features::{cpu, FeatureLayout, FeatureScene, Hypothesis};
use crate::frame::Frame;
pub use crate::gpu::fast::FastJob;
use crate::gpu::fast::{fast_scores_gpu, fast_scores_gpu_jobs, slice_scores_gpu, use_kernel_on, FastChunking};
use crate::gpu::preprocess::gradients_and_normals_gpu;
use crate::gpu::GpuContext;
use crate::room_layout::voxels::{self, ScoringTables, YawCells};
use crate::room_layout::RoomBox;

/// Which implementation scores.
#[derive(Clone, Copy)]
pub enum Backend<'a> {
    Cpu,
    Gpu(&'a GpuContext),
}

impl<'a> Backend<'a> {
    /// Preprocesses `frame` with the normals' neighbours found by `search`. On a GPU that runs kernels
    /// ([`use_kernel_on`]: a hardware adapter, or `COG_GPU_FAST_KERNEL=always`) the image gradients run as
    /// the `image_gradients` kernel and the window search as the `normal_window` kernel, both in one submission
    /// ([`crate::gpu::preprocess`]); each gives its CPU twin's result bit for bit, so both paths get the same
    /// gradients and normals. The k-d tree search and
    /// the plane fits stay on the CPU.
    pub fn preprocess(&self, frame: &Frame, search: NormalSearch) -> Result<Preprocessed> {
        match self {
            Backend::Gpu(ctx) if use_kernel_on(ctx) => {
                Preprocessed::from_frame_using(frame, |rgb, cloud| gradients_and_normals_gpu(ctx, rgb, cloud, search))
            }
            _ => Preprocessed::from_frame_with(frame, search),
        }
    }

    /// The GPU when a context was acquired, else the CPU.
    pub fn of(gpu: Option<&'a GpuContext>) -> Backend<'a> {
        match gpu {
            Some(ctx) => Backend::Gpu(ctx),
            None => Backend::Cpu,
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu(_) => "gpu",
        }
    }

    /// Ends a frame: on the GPU, trims the context's pooled buffers ([`GpuContext::end_frame`]); nothing on
    /// the CPU.
    pub fn end_frame(&self) {
        if let Backend::Gpu(ctx) = self {
            ctx.end_frame();
        }
    }

    /// Exact-path fused scores (`hypotheses.len() × weights.len()`) and the point·voxel updates.
    pub fn scores(
        &self,
        scene: &FeatureScene,
        layout: &FeatureLayout,
        hypotheses: &[Hypothesis],
        weights: &[Vec<f32>],
    ) -> Result<(Vec<f32>, u64)> {
        match self {
            Backend::Cpu => Ok(cpu::scores(scene, layout, hypotheses, weights)),
            Backend::Gpu(ctx) => crate::gpu::features::scores_gpu(ctx, scene, layout, hypotheses, weights),
        }
    }

    /// Exact-path scores (`hypotheses.len() × weights.len()`) of a few boxes that no table serves — the
    /// context cascade's cross scores ([`crate::detect::cross_scores`]): where the kernels run
    /// ([`use_kernel_on`]: a hardware adapter, or `COG_GPU_FAST_KERNEL=always`) by the exact kernel
    /// ([`crate::gpu::features::scores_gpu`]), else by the CPU's exact path ([`cpu::scores`]; on a software
    /// adapter the kernel is about 4× slower than the CPU: README, "Detection"). A GPU failure is logged and
    /// the CPU scores them, as in [`Backend::fast_scores`]. The two give the same scores within 1e-5 of
    /// Σ|wᵢφᵢ| (float sums in another order).
    pub fn box_scores(
        &self,
        scene: &FeatureScene,
        layout: &FeatureLayout,
        hypotheses: &[Hypothesis],
        weights: &[Vec<f32>],
    ) -> Vec<f32> {
        self.kernel_or_cpu(
            "box scores",
            |ctx| crate::gpu::features::scores_gpu(ctx, scene, layout, hypotheses, weights).map(|(scores, _)| scores),
            || cpu::scores(scene, layout, hypotheses, weights).0,
        )
    }

    /// Fast-path scores: the GPU kernel with [`Backend::Gpu`], [`FastEngine::scores`] with
    /// [`Backend::Cpu`]. A GPU failure (e.g. a table over the binding limit) is logged and the CPU path is
    /// taken, so the caller always gets scores.
    ///
    /// On a software adapter (`DeviceType::Cpu`: lavapipe, llvmpipe, WARP) the kernels are 8–13× slower than
    /// the CPU path on the same cores (lavapipe, 2026-11-28: the bed window, a frame's 19 models), so there
    /// the CPU path is
    /// used unless the environment sets `COG_GPU_FAST_KERNEL=always` ([`use_kernel_on`]; said once, at
    /// info level).
    pub fn fast_scores(&self, engine: &FastEngine, hypotheses: &[Hypothesis], weights: &[Vec<f32>]) -> Vec<f32> {
        self.kernel_or_cpu(
            "fast_scores",
            |ctx| fast_scores_gpu(ctx, engine, hypotheses, weights),
            || engine.scores(hypotheses, weights),
        )
    }

    /// The latent support surfaces' slice scores (`w_sliceᵀφ_surface(I, B, h) + u_h`, [`SLICES`] per
    /// hypothesis): where the fast path's kernel runs ([`use_kernel_on`]) by that kernel on the surface
    /// grid's tables ([`slice_scores_gpu`]), else [`SurfaceEngine::slice_scores`] on the CPU; a GPU failure
    /// is logged and the CPU scores them, as in [`Backend::fast_scores`].
    pub fn slice_scores(
        &self,
        engine: &SurfaceEngine,
        hypotheses: &[Hypothesis],
        weights: &SurfaceWeights,
    ) -> Vec<[f32; SLICES]> {
        self.kernel_or_cpu(
            "slice scores",
            |ctx| slice_scores_gpu(ctx, engine, hypotheses, weights),
            || engine.slice_scores(hypotheses, weights),
        )
    }

    /// [`Backend::fast_scores`] of several jobs on one engine (one per model whose fast-path settings the
    /// engine serves): on the GPU all of them in as few submissions as the batch budget allows, with the
    /// lattice points uploaded once and tables that several jobs use built once; on the CPU one after the
    /// other. Returns each job's scores.
    pub fn fast_scores_jobs(&self, engine: &FastEngine, jobs: &[FastJob]) -> Vec<Vec<f32>> {
        self.kernel_or_cpu(
            "fast_scores",
            |ctx| fast_scores_gpu_jobs(ctx, engine, jobs, FastChunking::default()),
            || jobs.iter().map(|job| engine.scores(job.hypotheses, job.weights)).collect(),
        )
    }

    /// Integer scores of room-layout hypotheses: [`voxels::scores_cpu`] or its kernel
    /// ([`crate::gpu::room_layout::scores_gpu`]); the two agree exactly (fixed point, tested on lavapipe).
    pub fn layout_scores(&self, cells: &[YawCells], tables: &ScoringTables, boxes: &[RoomBox]) -> Result<Vec<i32>> {
        match self {
            Backend::Cpu => Ok(voxels::scores_cpu(cells, tables, boxes)),
            Backend::Gpu(ctx) => crate::gpu::room_layout::scores_gpu(ctx, cells, tables, boxes),
        }
    }

    /// The one fallback rule of the scoring steps that have a kernel: where the kernels run
    /// ([`use_kernel_on`]: a hardware adapter, or `COG_GPU_FAST_KERNEL=always`) `on_gpu`, and if it fails
    /// (e.g. a table over the binding limit) a warning naming `what` and `on_cpu`; elsewhere (the CPU, or a
    /// software adapter without the override) `on_cpu`. So the caller always gets scores.
    fn kernel_or_cpu<T>(
        &self,
        what: &str,
        on_gpu: impl FnOnce(&GpuContext) -> Result<T>,
        on_cpu: impl FnOnce() -> T,
    ) -> T {
        match self {
            Backend::Gpu(ctx) if use_kernel_on(ctx) => on_gpu(ctx).unwrap_or_else(|e| {
                log::warn!("{what} on the GPU failed ({e}): scoring on the CPU");
                on_cpu()
            }),
            _ => on_cpu(),
        }
    }
}
