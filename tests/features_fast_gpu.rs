//! The fast-path scoring kernel (`shaders/fast_scores.wgsl`) against its CPU twin
//! (`gpu::fast::fast_scores_reference`) and against `FastEngine::scores`, on lavapipe or any adapter.
//!
//! Without an adapter these tests fail with a clear message, unless `COG_GPU_SKIP_GPU_TESTS=1` (then they
//! pass after saying they were skipped). Run with `NODEVICE_SELECT=1`.
//!
//! Tolerance: the three differ only in the order of float additions (and in the driver's rounding of
//! `u32 → f32`, division and `sqrt`), so scores agree to 1e-5 relative to the magnitude of the dot product,
//! `Σ|w_i·φ_i|` (the score itself can cancel to near 0 with random signed weights).

mod common;

use std::path::Path;

use cog_gpu::features::cpu::view_cosine;
use cog_gpu::features::fast::{FastEngine, FastOptions};
use cog_gpu::features::feature_layout::{view_features, FeatureLayout, Groups};
use cog_gpu::features::{sliding_window, WindowOptions};
use cog_gpu::features::{Hypothesis, PreparedWindow, SizeQuantiles};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::gpu::fast::{
    fast_scores_gpu, fast_scores_gpu_chunked, fast_scores_gpu_jobs, fast_scores_reference, fast_scores_reference_jobs,
    FastChunking, FastJob,
};
use cog_gpu::gpu::{GpuContext, TRIM_FRAMES};

const FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";
const STATS: &str = "../shared/data/sunrgbd-size-stats.json";

fn context() -> Option<GpuContext> {
    common::gpu_context()
}

fn sizes(category: &str) -> Vec<glam::Vec3> {
    SizeQuantiles::from_stats_file(Path::new(STATS), category).unwrap().sizes()
}

/// The real frame's `category` window.
fn real_window(category: &str) -> PreparedWindow {
    let frame = Frame::read(FRAME, DepthSource::Raw).unwrap();
    PreparedWindow::new(&frame, sizes(category), 0.1, 50).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Asserts `got ≈ expected` within 1e-5 of the magnitude `Σ|w_i·φ_i|` (see the module doc); `magnitude`
/// holds those sums, laid out like the scores.
fn assert_scores_match(got: &[f32], expected: &[f32], magnitude: &[f32], what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}");
    let mut worst = 0.0f64;
    for (n, ((&g, &e), &m)) in got.iter().zip(expected).zip(magnitude).enumerate() {
        let scale = (m as f64).max(e.abs() as f64).max(1e-6);
        let relative = (g as f64 - e as f64).abs() / scale;
        worst = worst.max(relative);
        assert!(relative <= 1e-5, "{what}: score {n}: {g} vs {e} (magnitude {m}, relative {relative:.2e})");
    }
    eprintln!("{what}: {} scores, worst relative difference {worst:.2e}", got.len());
}

/// GPU vs CPU twin vs `FastEngine::scores` for `layout` on `hyps`; returns the GPU scores.
fn compare_paths(
    ctx: &GpuContext,
    window: &PreparedWindow,
    layout: &FeatureLayout,
    hyps: &[Hypothesis],
    weights: &[Vec<f32>],
    what: &str,
) -> Vec<f32> {
    let engine = FastEngine::new(&window.scene, layout, FastOptions::default());
    let engine_scores = engine.scores(hyps, weights);
    let reference = fast_scores_reference(&engine, hyps, weights, FastChunking::default()).unwrap();
    let gpu = fast_scores_gpu(ctx, &engine, hyps, weights).unwrap();
    // Σ|w_i·φ_i|: every feature is ≥ 0, so the engine's scores with |w| are exactly that sum.
    let abs_weights: Vec<Vec<f32>> = weights.iter().map(|w| w.iter().map(|x| x.abs()).collect()).collect();
    let magnitude = engine.scores(hyps, &abs_weights);
    assert!(magnitude.iter().all(|&m| m > 0.0), "{what}: a hypothesis with no features");
    assert_scores_match(&gpu, &reference, &magnitude, &format!("{what}: GPU vs CPU twin"));
    assert_scores_match(&reference, &engine_scores, &magnitude, &format!("{what}: CPU twin vs FastEngine::scores"));
    assert_scores_match(&gpu, &engine_scores, &magnitude, &format!("{what}: GPU vs FastEngine::scores"));
    gpu
}

#[test]
fn gpu_fast_scores_match_the_cpu_on_a_real_frame_and_are_reproducible() {
    let Some(ctx) = context() else { return };
    let window = real_window("bed");
    let layout = FeatureLayout::default();
    let hyps = common::spread_sample(&window, 2000);
    assert!(hyps.len() >= 1500, "{} hypotheses", hyps.len());
    let weights = common::random_weights(&layout, 3, 1);
    let gpu = compare_paths(&ctx, &window, &layout, &hyps, &weights, "real frame, default layout");
    // Bit-identical across runs (exact integer sums, fixed reduction order).
    let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
    let again = fast_scores_gpu(&ctx, &engine, &hyps, &weights).unwrap();
    assert_eq!(bits(&again), bits(&gpu), "GPU fast scores differ between runs");
}

#[test]
fn gpu_fast_scores_match_the_cpu_on_a_synthetic_frame() {
    let Some(ctx) = context() else { return };
    let window = common::synthetic_window("chair");
    let hyps = common::spread_sample(&window, 3000);
    assert!(hyps.len() >= 1000, "{} hypotheses", hyps.len());
    let layout = FeatureLayout::default();
    compare_paths(&ctx, &window, &layout, &hyps, &common::random_weights(&layout, 2, 2), "synthetic frame");
}

#[test]
fn gpu_fast_scores_honour_switched_off_groups_and_other_grids() {
    let Some(ctx) = context() else { return };
    let window = common::synthetic_window("table");
    let hyps = common::spread_sample(&window, 600);
    let off = |density, normals, cog, view| Groups { density, normals, cog, view, out_of_view: false };
    for layout in [
        FeatureLayout::new([5, 5, 5], true, off(true, false, true, false)).unwrap(),
        FeatureLayout::new([5, 5, 5], true, off(false, true, false, true)).unwrap(),
        FeatureLayout::new([5, 5, 5], true, off(false, false, true, true)).unwrap(),
        FeatureLayout::new([3, 1, 3], true, Groups::GEOM).unwrap(),
        FeatureLayout::new([5, 5, 7], false, Groups::ALL).unwrap(),
    ] {
        compare_paths(&ctx, &window, &layout, &hyps, &common::random_weights(&layout, 3, 3), &layout.id());
    }
}

/// The view part, computed in the shader since 2026-11-28: weights on the view features alone (voxel weights
/// 0), ten vectors (two weight passes: the second pass's view weights lie at their own offset), the
/// hypotheses of every yaw and one moved onto the camera's vertical (view cosine 0 by the CPU's rule).
#[test]
fn gpu_fast_view_part_matches_the_cpu_in_every_pass() {
    let Some(ctx) = context() else { return };
    let window = common::synthetic_window("sofa");
    let layout = FeatureLayout::default();
    let mut hyps = common::spread_sample(&window, 500);
    assert!(hyps.len() >= 300, "{} hypotheses", hyps.len());
    let mut at_camera = hyps[0];
    at_camera.centre = glam::Vec2::ZERO;
    hyps.push(at_camera);
    let offset = layout.view_offset();
    let weights: Vec<Vec<f32>> = common::random_weights(&layout, 10, 7)
        .into_iter()
        .map(|w| w.iter().enumerate().map(|(i, &x)| if i >= offset { x } else { 0.0 }).collect())
        .collect();
    let gpu = compare_paths(&ctx, &window, &layout, &hyps, &weights, "view weights only, ten vectors");
    // Independent expectation: the score is the view weights dotted with the 12 view features of the
    // cuboid's view cosine (0 for the box on the camera's vertical).
    for (n, hyp) in hyps.iter().enumerate() {
        let cosine = if n + 1 == hyps.len() { 0.0 } else { view_cosine(&hyp.cuboid(&window.scene)) };
        let view = view_features(cosine);
        for (w, weight) in weights.iter().enumerate() {
            let expected: f32 = weight[offset..].iter().zip(&view).map(|(a, b)| a * b).sum();
            let got = gpu[n * weights.len() + w];
            assert!(
                (got - expected).abs() <= 1e-5 * (1.0 + expected.abs()),
                "hypothesis {n}, vector {w}: {got} vs {expected}"
            );
        }
    }
}

#[test]
fn chunked_dispatches_batches_and_weight_passes_equal_the_single_dispatch() {
    let Some(ctx) = context() else { return };
    let window = common::synthetic_window("bed");
    let layout = FeatureLayout::default();
    let hyps = common::spread_sample(&window, 400);
    // Ten weight vectors: two passes of the kernel (at most 8 per pass).
    let weights = common::random_weights(&layout, 10, 4);
    let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
    let whole = fast_scores_gpu(&ctx, &engine, &hyps, &weights).unwrap();
    let chunks_of_7 = FastChunking { max_chunk: 7, ..FastChunking::default() };
    let chunked = fast_scores_gpu_chunked(&ctx, &engine, &hyps, &weights, chunks_of_7).unwrap();
    assert_eq!(bits(&chunked), bits(&whole), "chunks of 7 hypotheses");
    // A submission per table group (any group is larger than one byte), and chunks of 7 within them.
    let one_group_per_batch = FastChunking { max_chunk: 7, max_batch_bytes: 1 };
    let batched = fast_scores_gpu_chunked(&ctx, &engine, &hyps, &weights, one_group_per_batch).unwrap();
    assert_eq!(bits(&batched), bits(&whole), "one submission per table group");
    // The CPU twin runs the same dispatches: chunking and batching do not change its bits either.
    let reference = fast_scores_reference(&engine, &hyps, &weights, chunks_of_7).unwrap();
    let reference_whole = fast_scores_reference(&engine, &hyps, &weights, FastChunking::default()).unwrap();
    assert_eq!(bits(&reference), bits(&reference_whole));
    let reference_batched = fast_scores_reference(&engine, &hyps, &weights, one_group_per_batch).unwrap();
    assert_eq!(bits(&reference_batched), bits(&reference_whole));
    let abs_weights: Vec<Vec<f32>> = weights.iter().map(|w| w.iter().map(|x| x.abs()).collect()).collect();
    let magnitude = engine.scores(&hyps, &abs_weights);
    assert_scores_match(&whole, &reference, &magnitude, "ten weight vectors: GPU vs CPU twin");
    assert_scores_match(&whole, &engine.scores(&hyps, &weights), &magnitude, "ten weight vectors: GPU vs engine");
}

#[test]
fn several_jobs_in_one_call_equal_one_call_each() {
    let Some(ctx) = context() else { return };
    // Three models' windows on one scene (one engine): bed, chair and bed again (the repeated job shares
    // every table with the first), with one, one and nine weight vectors.
    let window = common::synthetic_window("bed");
    let layout = FeatureLayout::default();
    let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
    let chair_window = sliding_window(&window.scene, &WindowOptions { sizes: sizes("chair"), min_points: 50 });
    let bed = common::spread_sample(&window, 300);
    let stride = (chair_window.hypotheses.len() / 300).max(1);
    let chair: Vec<Hypothesis> = chair_window.hypotheses.iter().step_by(stride).take(300).copied().collect();
    assert!(chair.len() >= 100, "{} chair hypotheses", chair.len());
    let weights = [
        common::random_weights(&layout, 1, 5),
        common::random_weights(&layout, 1, 6),
        common::random_weights(&layout, 9, 7),
    ];
    let jobs = [
        FastJob { hypotheses: &bed, weights: &weights[0] },
        FastJob { hypotheses: &chair, weights: &weights[1] },
        FastJob { hypotheses: &bed, weights: &weights[2] },
    ];
    let together = fast_scores_gpu_jobs(&ctx, &engine, &jobs, FastChunking::default()).unwrap();
    let twin_together = fast_scores_reference_jobs(&engine, &jobs, FastChunking::default()).unwrap();
    assert_eq!(together.len(), 3);
    for (n, job) in jobs.iter().enumerate() {
        let alone = fast_scores_gpu(&ctx, &engine, job.hypotheses, job.weights).unwrap();
        assert_eq!(bits(&together[n]), bits(&alone), "job {n}: GPU, together vs alone");
        let twin_alone = fast_scores_reference(&engine, job.hypotheses, job.weights, FastChunking::default()).unwrap();
        assert_eq!(bits(&twin_together[n]), bits(&twin_alone), "job {n}: CPU twin, together vs alone");
        let abs_weights: Vec<Vec<f32>> = job.weights.iter().map(|w| w.iter().map(|x| x.abs()).collect()).collect();
        let magnitude = engine.scores(job.hypotheses, &abs_weights);
        assert_scores_match(&together[n], &engine.scores(job.hypotheses, job.weights), &magnitude, &format!("job {n}"));
    }
}

#[test]
fn concurrent_calls_on_one_context_equal_the_calls_one_after_the_other() {
    // `detect` runs its engines' calls on several threads at once, sharing the context's buffer pool (each
    // batch holds it from its uploads to its read-back) and its error scopes (thread-local). Four calls on
    // two engines (other grids, other weights), run concurrently and then in turn, small batches forcing
    // several per call: the same bits either way, and the pool reused between them.
    let Some(ctx) = context() else { return };
    let window = common::synthetic_window("bed");
    let layouts = [FeatureLayout::default(), FeatureLayout::new([3, 1, 3], true, Groups::ALL).unwrap()];
    let engines: Vec<FastEngine> =
        layouts.iter().map(|l| FastEngine::new(&window.scene, l, FastOptions::default())).collect();
    let hyps = common::spread_sample(&window, 200);
    let weights: Vec<Vec<Vec<f32>>> =
        (0..4).map(|n| common::random_weights(&layouts[n % 2], 1 + n, 40 + n as u64)).collect();
    let chunking = FastChunking { max_chunk: 64, max_batch_bytes: 16 << 20 };
    let call = |n: usize| {
        let job = FastJob { hypotheses: &hyps, weights: &weights[n] };
        fast_scores_gpu_jobs(&ctx, &engines[n % 2], &[job], chunking).unwrap().pop().unwrap()
    };
    let concurrent: Vec<Vec<f32>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4).map(|n| s.spawn(move || call(n))).collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (n, got) in concurrent.iter().enumerate() {
        assert_eq!(bits(got), bits(&call(n)), "call {n}: concurrent vs one after the other");
        let twin = fast_scores_reference(&engines[n % 2], &hyps, &weights[n], chunking).unwrap();
        let abs_weights: Vec<Vec<f32>> = weights[n].iter().map(|w| w.iter().map(|x| x.abs()).collect()).collect();
        let magnitude = engines[n % 2].scores(&hyps, &abs_weights);
        assert_scores_match(got, &twin, &magnitude, &format!("call {n}: concurrent GPU vs CPU twin"));
    }
}

#[test]
fn trimmed_pools_shrink_to_the_recent_frames_and_score_the_same() {
    // A long run's pools follow its recent frames: after one large call, TRIM_FRAMES + 1 frames of a small
    // one (each ended by `end_frame`, as `detect` does) leave the pools exactly as a fresh context's after
    // the small call alone, and the small call's scores are the same bits before, during and after.
    let Some(ctx) = context() else { return };
    let window = common::synthetic_window("bed");
    let layout = FeatureLayout::default();
    let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
    let large = common::spread_sample(&window, 3000);
    // The small call: 40 hypotheses of one table (same yaw, bottom and height).
    let first = window.set.hypotheses[0];
    let small: Vec<Hypothesis> = window
        .set
        .hypotheses
        .iter()
        .filter(|h| h.yaw_index == first.yaw_index && h.bottom == first.bottom && h.size.z == first.size.z)
        .take(40)
        .copied()
        .collect();
    assert!(small.len() >= 10, "{} hypotheses share the first one's table", small.len());
    let weights = common::random_weights(&layout, 1, 11);
    let score = |ctx: &GpuContext, hyps: &[Hypothesis]| fast_scores_gpu(ctx, &engine, hyps, &weights).unwrap();

    let Some(fresh) = context() else { return };
    let small_alone = score(&fresh, &small);
    let small_pools = fresh.pooled_bytes();
    assert!(small_pools > 0);

    score(&ctx, &large);
    ctx.end_frame();
    let large_pools = ctx.pooled_bytes();
    assert!(large_pools > 2 * small_pools, "the large call's pools {large_pools} B, the small one's {small_pools} B");
    for frame in 1..=TRIM_FRAMES + 1 {
        assert_eq!(bits(&score(&ctx, &small)), bits(&small_alone), "small call, frame {frame} after the large one");
        ctx.end_frame();
        let pooled = ctx.pooled_bytes();
        if frame < TRIM_FRAMES {
            assert_eq!(pooled, large_pools, "frame {frame}: the large frame is recent, nothing let go");
        }
    }
    assert_eq!(ctx.pooled_bytes(), small_pools, "trimmed to what the small call alone makes");
    // Made again at the small call's sizes (the upload buffer mapped at creation): still the same bits.
    assert_eq!(bits(&score(&ctx, &small)), bits(&small_alone), "small call after the trim");
}
