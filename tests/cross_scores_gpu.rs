//! The context cascade's cross scores on the GPU (`detect::cross_scores` through `Backend::box_scores`):
//! where the kernels run — here lavapipe, forced by `COG_GPU_FAST_KERNEL=always`, which this file sets for
//! its one test — the exact kernel scores the boxes, and every cross score is within 1e-5 of Σ|wᵢφᵢ| (the
//! box's features from the CPU's exact path, dotted term by term with the model's weights) of the CPU
//! backend's.

mod common;

use std::path::Path;

use cog_gpu::backend::Backend;
use cog_gpu::category::is_cross_score_category;
use cog_gpu::detect::{box_hypothesis, cross_scores};
use cog_gpu::eval::Detection;
use cog_gpu::features::hypotheses::DEFAULT_STEP;
use cog_gpu::features::{cpu, FeatureScene, Preprocessed};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::Cuboid;
use cog_gpu::gpu::features::scores_gpu;
use cog_gpu::model::read_models_dir;

const SAMPLE: &str = "assets/sample/synth-bedroom-s52";

/// The shipped cross-category models (the ten large and the counter) score the sample bedroom's annotated
/// boxes, each also moved and turned, as detections of their categories, plus a pillow (no cross category):
/// the GPU backend gives the CPU backend's maps, scores within 1e-5 of Σ|wᵢφᵢ|, and its box scores are the
/// exact kernel's bit for bit (the route taken), the CPU backend's the CPU exact path's.
#[test]
fn cross_scores_on_the_gpu_match_the_cpu() {
    std::env::set_var("COG_GPU_FAST_KERNEL", "always");
    let Some(ctx) = common::gpu_context() else { return };
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let models: Vec<_> = read_models_dir(Path::new("assets/models"), None)
        .unwrap()
        .into_iter()
        .filter(|m| is_cross_score_category(&m.category))
        .collect();
    assert_eq!(models.len(), 11, "the ten large categories and the counter");
    let layout = &models[0].layout;
    assert!(models.iter().all(|m| &m.layout == layout), "the shipped eleven share one layout");
    let mut detections = Vec::new();
    for object in &frame.objects {
        let c = object.cuboid;
        let category = if is_cross_score_category(&object.category) { object.category.as_str() } else { "pillow" };
        detections.push(Detection::new(category, &c, 0.5));
        let moved = Cuboid::new(c.centre + glam::Vec3::new(0.07, -0.05, 0.0), c.size * 0.9, c.yaw + 0.2);
        detections.push(Detection::new(category, &moved, 0.4));
    }
    assert!(detections.iter().filter(|d| is_cross_score_category(&d.category)).count() >= 6);
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let mut on_cpu = detections.clone();
    cross_scores(&pre, &models, &mut on_cpu, Backend::Cpu);
    let mut on_gpu = detections.clone();
    cross_scores(&pre, &models, &mut on_gpu, Backend::Gpu(&ctx));
    let mut compared = 0;
    for (c, g) in on_cpu.iter().zip(&on_gpu) {
        if !is_cross_score_category(&c.category) {
            assert!(c.cross_scores.is_none() && g.cross_scores.is_none());
            continue;
        }
        let (cs, gs) = (c.cross_scores.as_ref().unwrap(), g.cross_scores.as_ref().unwrap());
        assert_eq!(cs.keys().collect::<Vec<_>>(), gs.keys().collect::<Vec<_>>());
        // The box's features, computed on their own (one yaw grid), for the scale of each model's sum.
        let cuboid = c.cuboid();
        let scene = FeatureScene::new(pre.clone(), &[cuboid.yaw], DEFAULT_STEP);
        let hypothesis = box_hypothesis(&scene, 0, &cuboid);
        let (row, _) = cpu::features(&scene, layout, std::slice::from_ref(&hypothesis));
        for model in &models {
            let scale: f64 = row.iter().zip(&model.weights).map(|(f, w)| (*f as f64 * *w as f64).abs()).sum();
            let (cpu_score, gpu_score) = (cs[&model.category], gs[&model.category]);
            assert!(
                ((gpu_score - cpu_score) as f64).abs() <= 1e-5 * scale.max(1.0),
                "{} box, {} model: GPU {gpu_score} vs CPU {cpu_score} (Σ|wφ| {scale})",
                c.category,
                model.category
            );
            compared += 1;
        }
    }
    assert!(compared >= 66, "{compared} scores compared");
    // The routes: the GPU backend's box scores are the exact kernel's, the CPU backend's the CPU's.
    let cuboids: Vec<Cuboid> = detections.iter().map(Detection::cuboid).collect();
    let yaws: Vec<f32> = cuboids.iter().map(|c| c.yaw).collect();
    let scene = FeatureScene::new(pre.clone(), &yaws, DEFAULT_STEP);
    let hypotheses: Vec<_> = cuboids.iter().enumerate().map(|(i, c)| box_hypothesis(&scene, i, c)).collect();
    let weights: Vec<Vec<f32>> = models.iter().take(3).map(|m| m.weights.clone()).collect();
    let kernel = scores_gpu(&ctx, &scene, layout, &hypotheses, &weights).unwrap().0;
    let routed = Backend::Gpu(&ctx).box_scores(&scene, layout, &hypotheses, &weights);
    assert!(kernel.iter().zip(&routed).all(|(a, b)| a.to_bits() == b.to_bits()) && kernel.len() == routed.len());
    // The CPU backend's box scores: each box's features (the CPU's exact path) dotted with each model's
    // weights in f64 here, within 1e-5 of Σ|wᵢφᵢ|.
    let routed = Backend::Cpu.box_scores(&scene, layout, &hypotheses, &weights);
    let (rows, _) = cpu::features(&scene, layout, &hypotheses);
    let dim = layout.dim();
    assert_eq!(routed.len(), hypotheses.len() * weights.len());
    for (h, row) in rows.chunks(dim).enumerate() {
        for (m, w) in weights.iter().enumerate() {
            let dot: f64 = row.iter().zip(w).map(|(f, w)| *f as f64 * *w as f64).sum();
            let scale: f64 = row.iter().zip(w).map(|(f, w)| (*f as f64 * *w as f64).abs()).sum();
            let got = routed[h * weights.len() + m] as f64;
            assert!((got - dot).abs() <= 1e-5 * scale.max(1.0), "box {h}, model {m}: {got} vs {dot}");
        }
    }
}
