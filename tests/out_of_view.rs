//! The out-of-view group of the feature layout (`features::out_of_view`): its indicators against an
//! independent projection of every voxel centre, and every path — exact and fast on the CPU, the GPU's
//! exact and fast kernels with the indicators' part added on the CPU — giving the same indicators and
//! scores. GPU parts run on lavapipe (or any adapter; see `tests/common` for skipping).

mod common;

use cog_gpu::features::cpu;
use cog_gpu::features::fast::{FastEngine, FastOptions};
use cog_gpu::features::feature_layout::{FeatureLayout, Groups};
use cog_gpu::features::out_of_view::out_of_view_voxels;
use cog_gpu::features::{Hypothesis, PreparedWindow};
use cog_gpu::geometry::{voxel_corners, Cuboid};
use cog_gpu::gpu::fast::fast_scores_gpu;
use cog_gpu::gpu::features::{features_gpu, scores_gpu};
use glam::Vec3;

fn with_out_of_view(base_grid: [u32; 3], expanded: bool) -> FeatureLayout {
    FeatureLayout::new(base_grid, expanded, Groups { out_of_view: true, ..Groups::ALL }).unwrap()
}

/// Independent expectation for voxel (i, j, k): its centre as the mean of its eight corners
/// (`geometry::voxel_corners` of the upright cuboid scaled by the layout's expansion), projected by the
/// camera's own matrices; `None` when the centre lies within `margin` pixels (or 10⁻⁶ m of depth) of the
/// rule's border, where the two computations' roundings may disagree.
fn expected_out_of_view(window: &PreparedWindow, layout: &FeatureLayout, hyp: &Hypothesis) -> Vec<Option<bool>> {
    let scene = &window.scene;
    let cuboid = hyp.cuboid(scene);
    let e = layout.expansion();
    let expanded = Cuboid::new(cuboid.centre, cuboid.size * Vec3::new(e[0], e[1], e[2]), cuboid.yaw);
    let camera = &scene.pre.camera;
    let [width, height] = scene.pre.image_size.map(|n| n as f32);
    let [fx, fy, cx, cy] = camera.intrinsics;
    let margin = 1e-3;
    let g = layout.grid();
    let mut out = vec![None; layout.voxel_count()];
    for k in 0..g[2] {
        for j in 0..g[1] {
            for i in 0..g[0] {
                let corners = voxel_corners(&expanded, g, [i, j, k]);
                let centre = corners.iter().copied().sum::<Vec3>() / 8.0;
                let c = camera.to_camera(centre);
                let depth = c.z - 1e-3;
                let verdict = if depth.abs() < 1e-6 {
                    None
                } else if depth < 0.0 {
                    Some(true)
                } else {
                    let (u, v) = (fx * c.x / c.z + cx - 1.0, fy * c.y / c.z + cy - 1.0);
                    // Distance to the image's border, negative outside [−0.5, w − 0.5) × [−0.5, h − 0.5).
                    let inside = (u + 0.5).min(width - 0.5 - u).min(v + 0.5).min(height - 0.5 - v);
                    if inside.abs() < margin {
                        None
                    } else {
                        Some(inside < 0.0)
                    }
                };
                out[layout.voxel_index(i, j, k)] = verdict;
            }
        }
    }
    out
}

#[test]
fn indicators_mark_exactly_the_voxel_centres_off_the_picture() {
    let window = common::synthetic_window("bed");
    let hyps = common::spread_sample(&window, 3000);
    assert!(hyps.len() >= 1000, "{} hypotheses", hyps.len());
    for layout in [with_out_of_view([5, 5, 5], true), with_out_of_view([3, 1, 3], false)] {
        let (features, _) = cpu::features(&window.scene, &layout, &hyps);
        let offset = layout.out_of_view_offset();
        let (mut partly_out, mut all_in, mut checked) = (0, 0, 0usize);
        for (n, hyp) in hyps.iter().enumerate() {
            let row = &features[n * layout.dim()..(n + 1) * layout.dim()];
            let indicators = &row[offset..];
            assert_eq!(indicators.len(), layout.voxel_count());
            assert!(indicators.iter().all(|&x| x == 0.0 || x == 1.0), "hypothesis {n}: indicators are 0 or 1");
            for (voxel, expected) in expected_out_of_view(&window, &layout, hyp).into_iter().enumerate() {
                if let Some(out) = expected {
                    checked += 1;
                    assert_eq!(indicators[voxel] == 1.0, out, "{}: hypothesis {n}, voxel {voxel}", layout.id());
                }
            }
            if indicators.contains(&1.0) {
                partly_out += 1;
            } else {
                all_in += 1;
            }
        }
        // Both kinds are many: the comparison says something about each.
        assert!(partly_out >= 100 && all_in >= 100, "{}: {partly_out} partly out, {all_in} all in", layout.id());
        assert!(checked >= hyps.len() * layout.voxel_count() * 99 / 100, "{checked} voxels checked");
        // The group off: the same vector without the indicators.
        let narrow = layout.without_out_of_view();
        let (without, _) = cpu::features(&window.scene, &narrow, &hyps);
        for n in 0..hyps.len() {
            assert_eq!(
                features[n * layout.dim()..n * layout.dim() + narrow.dim()],
                without[n * narrow.dim()..(n + 1) * narrow.dim()]
            );
        }
    }
}

fn assert_close(got: &[f32], expected: &[f32], magnitude: &[f32], what: &str) {
    assert_eq!(got.len(), expected.len(), "{what}");
    for (n, ((&g, &e), &m)) in got.iter().zip(expected).zip(magnitude).enumerate() {
        let relative = (g as f64 - e as f64).abs() / (m as f64).max(e.abs() as f64).max(1e-6);
        assert!(relative <= 1e-5, "{what}: score {n}: {g} vs {e} (relative {relative:.2e})");
    }
}

#[test]
fn every_path_gives_the_same_indicators_and_scores() {
    let window = common::synthetic_window("bed");
    let scene = &window.scene;
    let layout = with_out_of_view([5, 5, 5], true);
    let hyps = common::spread_sample(&window, 600);
    let dim = layout.dim();
    let offset = layout.out_of_view_offset();
    let (exact, _) = cpu::features(scene, &layout, &hyps);
    let engine = FastEngine::new(scene, &layout, FastOptions::default());
    let fast = engine.features(&hyps);
    // The indicators: bit for bit the same on the exact and the fast path, and the listed voxels.
    for (n, hyp) in hyps.iter().enumerate() {
        let voxels = out_of_view_voxels(scene, &layout, hyp);
        let mut expected = vec![0.0f32; layout.voxel_count()];
        voxels.iter().for_each(|&v| expected[v] = 1.0);
        assert_eq!(exact[n * dim + offset..(n + 1) * dim], expected[..], "exact path, hypothesis {n}");
        assert_eq!(fast[n * dim + offset..(n + 1) * dim], expected[..], "fast path, hypothesis {n}");
    }
    // Weights on the indicators alone: every path's score is the sum of the out-of-view voxels' weights.
    let weights: Vec<Vec<f32>> = common::random_weights(&layout, 3, 5)
        .into_iter()
        .map(|w| w.iter().enumerate().map(|(i, &x)| if i >= offset { x } else { 0.0 }).collect())
        .collect();
    let by_hand: Vec<f32> = hyps
        .iter()
        .flat_map(|hyp| {
            let voxels = out_of_view_voxels(scene, &layout, hyp);
            weights.iter().map(move |w| voxels.iter().map(|&v| w[offset + v]).sum::<f32>()).collect::<Vec<_>>()
        })
        .collect();
    assert!(by_hand.iter().filter(|&&s| s != 0.0).count() >= 50, "too few hypotheses partly out of view");
    assert_eq!(engine.scores(&hyps, &weights), by_hand, "fast path, indicator weights only");
    let ones = vec![1.0f32; by_hand.len()];
    assert_close(&cpu::scores(scene, &layout, &hyps, &weights).0, &by_hand, &ones, "exact path, indicators only");
    // Whole random weights: the exact path's fused scores are its features' dot products, and the fast
    // path's scores those of its own features.
    let weights = common::random_weights(&layout, 2, 6);
    let abs: Vec<Vec<f32>> = weights.iter().map(|w| w.iter().map(|x| x.abs()).collect()).collect();
    let dots = |rows: &[f32], w: &[Vec<f32>]| -> Vec<f32> {
        rows.chunks(dim).flat_map(|row| w.iter().map(|w| cpu::dot(w, row)).collect::<Vec<_>>()).collect()
    };
    let (exact_scores, _) = cpu::scores(scene, &layout, &hyps, &weights);
    assert_close(&exact_scores, &dots(&exact, &weights), &dots(&exact, &abs), "exact path vs its features");
    let fast_scores = engine.scores(&hyps, &weights);
    let fast_magnitude = dots(&fast, &abs);
    assert_close(&fast_scores, &dots(&fast, &weights), &fast_magnitude, "fast path vs its features");
    // The GPU kernels (the indicators' part added on the CPU).
    let Some(ctx) = common::gpu_context() else { return };
    let (gpu_features, _) = features_gpu(&ctx, scene, &layout, &hyps).unwrap();
    assert_eq!(gpu_features.len(), exact.len());
    for n in 0..hyps.len() {
        assert_eq!(gpu_features[n * dim + offset..(n + 1) * dim], exact[n * dim + offset..(n + 1) * dim]);
    }
    let (gpu_exact_scores, _) = scores_gpu(&ctx, scene, &layout, &hyps, &weights).unwrap();
    assert_close(&gpu_exact_scores, &exact_scores, &dots(&exact, &abs), "GPU exact kernel vs the CPU");
    let gpu_fast_scores = fast_scores_gpu(&ctx, &engine, &hyps, &weights).unwrap();
    assert_close(&gpu_fast_scores, &fast_scores, &fast_magnitude, "GPU fast kernel vs the CPU");
}
