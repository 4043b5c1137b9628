//! The latent support surfaces' slice scores on the GPU (`gpu::fast::slice_scores_gpu`: the fast kernel on
//! the surface grid's tables with one weight vector per slice, `features::surface::slice_weight_vectors`)
//! against the CPU's `SurfaceEngine::slice_scores`, on lavapipe or any adapter; and, on the CPU alone, the
//! identity that makes the kernel's result the slice scores: the fused scores with the per-slice vectors
//! are the per-layer scores, bit for bit.
//!
//! Without an adapter the GPU test fails with a clear message, unless `COG_GPU_SKIP_GPU_TESTS=1` (then it
//! passes after saying it was skipped). Run with `NODEVICE_SELECT=1`.

mod common;

use cog_gpu::features::fast::FastOptions;
use cog_gpu::features::feature_layout::Groups;
use cog_gpu::features::surface::{
    best_slice, slice_weight_vectors, with_height_biases, SurfaceEngine, SurfaceWeights, SLICES, SLICE_DIM,
};
use cog_gpu::gpu::fast::slice_scores_gpu;

/// Deterministic signed weights for the slice and the height biases.
fn weights(seed: usize) -> SurfaceWeights {
    let slice = (0..SLICE_DIM).map(|k| (((k + seed) * 7919 % 1000) as f32 / 500.0) - 1.0).collect();
    SurfaceWeights::new(slice, [0.3, -0.2, 0.1, 0.0, 0.5, -0.4, 0.25]).unwrap()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn fused_scores_with_one_vector_per_slice_are_the_layer_scores_bit_for_bit() {
    let window = common::synthetic_window("table");
    let hyps = common::spread_sample(&window, 1500);
    assert!(hyps.len() >= 500, "{} hypotheses", hyps.len());
    let engine = SurfaceEngine::new(&window.scene, Groups::ALL, FastOptions::default());
    let w = weights(0);
    let vectors = slice_weight_vectors(&w, engine.engine().layout());
    assert_eq!(vectors.len(), SLICES);
    for (h, v) in vectors.iter().enumerate() {
        assert_eq!(v.len(), engine.engine().layout().dim(), "a vector spans the whole surface grid");
        // The slice's weights in layer h, nothing anywhere else.
        assert!(v[h * SLICE_DIM..(h + 1) * SLICE_DIM] == w.slice[..]);
        assert!(v.iter().enumerate().all(|(n, &x)| (h * SLICE_DIM..(h + 1) * SLICE_DIM).contains(&n) || x == 0.0));
    }
    let fused = engine.engine().scores(&hyps, &vectors);
    let layers = engine.engine().layer_scores(&hyps, &w.slice);
    assert_eq!(bits(&fused), bits(&layers), "fused scores with the slice vectors differ from the layer scores");
    // Independently: the slice scores with their height biases are the dot products of the slices'
    // features (`SurfaceEngine::slices`, the fast path's feature rows) with `w_slice`, plus `u_h` (in f64).
    let some = &hyps[..100];
    let features = engine.slices(some);
    for (n, row) in with_height_biases(&fused[..100 * SLICES], &w).iter().enumerate() {
        for (h, &score) in row.iter().enumerate() {
            let start = (n * SLICES + h) * SLICE_DIM;
            let reference: f64 = features[start..start + SLICE_DIM]
                .iter()
                .zip(&w.slice)
                .map(|(&x, &w)| f64::from(x) * f64::from(w))
                .sum::<f64>()
                + f64::from(w.indicator[h]);
            assert!((f64::from(score) - reference).abs() <= 1e-5 * (1.0 + reference.abs()), "box {n} slice {h}");
        }
    }
    // Not a vacuous comparison: the slices score differently.
    assert!(fused.chunks(SLICES).any(|row| row.iter().any(|&s| s != row[0])));
}

#[test]
fn gpu_slice_scores_match_the_cpu() {
    let Some(ctx) = common::gpu_context() else { return };
    let window = common::synthetic_window("table");
    let hyps = common::spread_sample(&window, 1500);
    let engine = SurfaceEngine::new(&window.scene, Groups::ALL, FastOptions::default());
    for seed in [1, 2] {
        let w = weights(seed);
        // Σ|w_i·φ_i| per hypothesis and slice: every feature is ≥ 0, so the slice scores with |w| and no
        // height bias are that sum.
        let absolute = SurfaceWeights::new(w.slice.iter().map(|x| x.abs()).collect(), [0.0; SLICES]).unwrap();
        let magnitude = engine.slice_scores(&hyps, &absolute);
        let cpu = engine.slice_scores(&hyps, &w);
        let gpu = slice_scores_gpu(&ctx, &engine, &hyps, &w).unwrap();
        assert_eq!(gpu.len(), hyps.len());
        let mut worst = 0.0f64;
        let mut same_best = 0;
        for (n, ((g, c), m)) in gpu.iter().zip(&cpu).zip(&magnitude).enumerate() {
            for h in 0..SLICES {
                let scale = f64::from(m[h]).max(f64::from(c[h].abs())).max(1e-6);
                let relative = f64::from(g[h] - c[h]).abs() / scale;
                worst = worst.max(relative);
                assert!(relative <= 1e-5, "hypothesis {n} slice {h}: GPU {} vs CPU {}", g[h], c[h]);
            }
            same_best += usize::from(best_slice(g).0 == best_slice(c).0);
        }
        // The best slice agrees but for near ties.
        assert!(same_best * 100 >= hyps.len() * 99, "best slice agrees for {same_best} of {}", hyps.len());
        eprintln!("seed {seed}: {} hypotheses, worst relative difference {worst:.2e}", hyps.len());
    }
}

/// `detect` with the shipped table (latent surfaces) on the sample bedroom: the GPU path with the kernels
/// forced on (lavapipe included) chooses the same slices and gives the same scores as the CPU path.
#[test]
fn detect_with_latent_surfaces_agrees_between_the_paths() {
    let Some(_ctx) = common::gpu_context() else { return };
    let dir = tempfile::tempdir().unwrap();
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    std::fs::copy("assets/models/table.json", models.join("table.json")).unwrap();
    let detect = |cpu: bool| -> Vec<serde_json::Value> {
        let out = dir.path().join(if cpu { "cpu" } else { "gpu" });
        let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_cog-gpu"));
        if cpu {
            command.arg("--cpu");
        }
        let output = command
            .args(["detect", "assets/sample/synth-bedroom-s52", "--models", models.to_str().unwrap()])
            .args(["--no-overlay", "--min-score", "-1", "--out", out.to_str().unwrap()])
            .env("NODEVICE_SELECT", "1")
            .env("COG_GPU_FAST_KERNEL", "always")
            .output()
            .unwrap();
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let file = std::fs::read(out.join("synth-bedroom-s52.json")).unwrap();
        let json: serde_json::Value = serde_json::from_slice(&file).unwrap();
        json["detections"].as_array().unwrap().clone()
    };
    let (cpu, gpu) = (detect(true), detect(false));
    assert!(cpu.len() >= 3, "{} table detections", cpu.len());
    assert_eq!(cpu.len(), gpu.len());
    for (c, g) in cpu.iter().zip(&gpu) {
        assert!(c["latent_slice"].is_u64(), "a latent model's detection names its slice: {c}");
        assert_eq!(c["latent_slice"], g["latent_slice"], "{c} vs {g}");
        // Box voting weighs the boxes by their probabilities, so the centres agree to their rounding.
        for axis in 0..3 {
            let (a, b) = (c["centre"][axis].as_f64().unwrap(), g["centre"][axis].as_f64().unwrap());
            assert!((a - b).abs() <= 1e-5, "centres {} vs {}", c["centre"], g["centre"]);
        }
        let (a, b) = (c["raw_score"].as_f64().unwrap(), g["raw_score"].as_f64().unwrap());
        assert!((a - b).abs() <= 1e-5 * a.abs().max(1.0), "raw scores {a} vs {b}");
    }
}
