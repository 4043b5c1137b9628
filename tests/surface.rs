//! Support-surface slices (paper §4.1, `features::surface`): a constructed table top lands in the slice
//! that holds its height and nowhere else; slice scores equal the dot products of the slice features;
//! the centre-slice initialisation copies the right weights.

use cog_gpu::features::fast::FastOptions;
use cog_gpu::features::feature_layout::{FeatureLayout, Groups, DENSITY, NORMALS, PER_VOXEL};
use cog_gpu::features::preprocess::{normal_bin, Preprocessed};
use cog_gpu::features::surface::{
    best_slice, centre_slice_weights, surface_height, SurfaceEngine, SurfaceWeights, SLICES, SLICE_DIM, SLICE_VOXELS,
};
use cog_gpu::features::{FeatureScene, Hypothesis};
use cog_gpu::geometry::{Camera, Cuboid};
use glam::{Mat3, Vec2, Vec3};

/// A table top: a horizontal square of points at `top` (upright z; the floor is at 0), 0.8 m wide, 3 m in
/// front of a level camera 1.2 m above the floor, normals up, no image gradient; plus a floor patch.
fn table_scene(top: f32) -> FeatureScene {
    let mut points = Vec::new();
    let mut normals = Vec::new();
    for a in 0..40 {
        for b in 0..40 {
            let (x, y) = (-0.4 + 0.02 * (a as f32 + 0.5), 2.6 + 0.02 * (b as f32 + 0.5));
            points.push(Vec3::new(x, y, top - 1.2));
            normals.push(Vec3::Z);
            // The floor around the table, outside its footprint.
            points.push(Vec3::new(x + 1.5, y, -1.2));
            normals.push(Vec3::Z);
        }
    }
    let gradients = vec![Vec2::ZERO; points.len()];
    let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
    let pre = Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: -1.2 };
    FeatureScene::new(pre, &[0.0], 0.1)
}

/// The table's box: 0.8 × 0.8 m, from the floor to 0.7 m.
fn table_box(scene: &FeatureScene) -> Hypothesis {
    let cuboid = Cuboid::new(Vec3::new(0.0, 3.0, -1.2 + 0.35), Vec3::new(0.8, 0.8, 0.7), 0.0);
    Hypothesis::from_cuboid(scene, 0, &cuboid)
}

#[test]
fn a_table_top_lies_in_the_slice_of_its_height_only() {
    // Slices of 0.1 m: a top at 0.55 m is in slice 5 (0.5–0.6 m), at 0.23 m in slice 2.
    for (top, expected) in [(0.55f32, 5usize), (0.23, 2)] {
        let scene = table_scene(top);
        let hyp = table_box(&scene);
        let engine = SurfaceEngine::new(&scene, Groups::ALL, FastOptions::default());
        let slices = engine.slices(std::slice::from_ref(&hyp));
        assert_eq!(slices.len(), SLICES * SLICE_DIM);
        let up = NORMALS + normal_bin(Vec3::Z) as usize;
        for h in 0..SLICES {
            let slice = &slices[h * SLICE_DIM..(h + 1) * SLICE_DIM];
            let occupied = (0..SLICE_VOXELS).filter(|v| slice[v * PER_VOXEL + DENSITY] > 0.0).count();
            if h == expected {
                // The top covers the whole 5×5 footprint, every point with an upward normal.
                assert_eq!(occupied, SLICE_VOXELS, "top {top}: slice {h}");
                for v in 0..SLICE_VOXELS {
                    let voxel = &slice[v * PER_VOXEL..(v + 1) * PER_VOXEL];
                    assert!(voxel[up] > 0.0 && (voxel[up] - voxel[DENSITY]).abs() <= 1e-6 * voxel[DENSITY]);
                }
            } else {
                assert!(slice.iter().all(|&x| x == 0.0), "top {top}: slice {h} is not empty");
            }
        }
        // Weights that reward upward normals find the slice, and its centre is within 5 cm of the top.
        let mut w = vec![0.0f32; SLICE_DIM];
        for v in 0..SLICE_VOXELS {
            w[v * PER_VOXEL + up] = 1.0;
        }
        let weights = SurfaceWeights::new(w, [0.0; SLICES]).unwrap();
        let scores = engine.slice_scores(std::slice::from_ref(&hyp), &weights)[0];
        let (h, _) = best_slice(&scores);
        assert_eq!(h, expected);
        let height = surface_height(&hyp, h) - scene.pre.floor;
        assert!((height - top).abs() <= 0.05 + 1e-6, "surface at {height}, top at {top}");
    }
}

#[test]
fn slice_scores_are_the_dot_products_of_the_slices_plus_the_height_bias() {
    let scene = table_scene(0.45);
    let base = table_box(&scene);
    // A few boxes around the table, of other heights and positions.
    let hyps: Vec<Hypothesis> = (0..6)
        .map(|n| Hypothesis {
            centre: base.centre + Vec2::new(0.05 * n as f32, -0.03 * n as f32),
            size: base.size + Vec3::new(0.0, 0.1 * (n % 2) as f32, 0.07 * n as f32),
            ..base
        })
        .collect();
    let engine = SurfaceEngine::new(&scene, Groups::ALL, FastOptions::default());
    let slices = engine.slices(&hyps);
    // Deterministic pseudo-random weights.
    let w: Vec<f32> = (0..SLICE_DIM).map(|k| ((k * 7919 % 1000) as f32 / 500.0) - 1.0).collect();
    let indicator = [0.3, -0.2, 0.1, 0.0, 0.5, -0.4, 0.25];
    let weights = SurfaceWeights::new(w.clone(), indicator).unwrap();
    let scores = engine.slice_scores(&hyps, &weights);
    for (n, row) in scores.iter().enumerate() {
        for h in 0..SLICES {
            let start = (n * SLICES + h) * SLICE_DIM;
            let reference: f64 = slices[start..start + SLICE_DIM]
                .iter()
                .zip(&w)
                .map(|(&x, &w)| f64::from(x) * f64::from(w))
                .sum::<f64>()
                + f64::from(indicator[h]);
            let scale = 1.0 + reference.abs();
            assert!(
                (f64::from(row[h]) - reference).abs() <= 1e-5 * scale,
                "box {n} slice {h}: {} vs {reference}",
                row[h]
            );
        }
    }
}

#[test]
fn best_slice_breaks_ties_toward_the_lowest_height() {
    assert_eq!(best_slice(&[0.0, 2.0, 1.0, 2.0, -1.0, 0.0, 2.0]), (1, 2.0));
    assert_eq!(best_slice(&[5.0; SLICES]), (0, 5.0));
    assert_eq!(best_slice(&[-3.0, -2.0, -1.0, -4.0, -5.0, -6.0, -0.5]), (6, -0.5));
}

#[test]
fn centre_slice_weights_copy_the_middle_layer_of_the_base_grid() {
    // Each weight holds its own index, so the copy can be read back by hand.
    for expanded in [false, true] {
        let layout = FeatureLayout::new([5, 5, 5], expanded, Groups::ALL).unwrap();
        let w: Vec<f32> = (0..layout.dim()).map(|k| k as f32).collect();
        let slice = centre_slice_weights(&layout, &w).unwrap();
        assert_eq!(slice.len(), SLICE_DIM);
        let n = if expanded { 7 } else { 5 };
        let shift = usize::from(expanded);
        for j in 0..5 {
            for i in 0..5 {
                // Voxel (i, j, 2) of the base grid: (i + 1, j + 1, 3) of the expanded 7×7×7.
                let voxel = ((2 + shift) * n + j + shift) * n + i + shift;
                for e in 0..PER_VOXEL {
                    assert_eq!(slice[(j * 5 + i) * PER_VOXEL + e], (voxel * PER_VOXEL + e) as f32);
                }
            }
        }
    }
    // Wrong grid or length: a clear error.
    let narrow = FeatureLayout::new([3, 1, 3], true, Groups::ALL).unwrap();
    let err = centre_slice_weights(&narrow, &vec![0.0; narrow.dim()]).unwrap_err();
    assert!(err.to_string().contains("5×5"), "{err}");
    let layout = FeatureLayout::default();
    let err = centre_slice_weights(&layout, &[0.0; 10]).unwrap_err();
    assert!(err.to_string().contains("10 cuboid weights"), "{err}");
    assert!(SurfaceWeights::new(vec![0.0; 3], [0.0; SLICES]).is_err());
    assert!(SurfaceWeights::new(vec![f32::NAN; SLICE_DIM], [0.0; SLICES]).is_err());
}
