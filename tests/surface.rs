//! Support-surface slices (paper §4.1, `features::surface`): a constructed table top lands in the slice
//! that holds its height and nowhere else; slice scores equal the dot products of the slice features;
//! the centre-slice initialisation copies the right weights; the surface measured from the points alone.

use cog_gpu::eval::Detection;
use cog_gpu::features::fast::FastOptions;
use cog_gpu::features::feature_layout::{FeatureLayout, Groups, DENSITY, NORMALS, PER_VOXEL};
use cog_gpu::features::preprocess::{normal_bin, Preprocessed};
use cog_gpu::features::surface::{
    best_slice, centre_slice_weights, refined_surface_height, surface_height, SurfaceEngine, SurfaceWeights, SLICES,
    SLICE_DIM, SLICE_VOXELS,
};
use cog_gpu::features::LatticePhase;
use cog_gpu::features::Support;
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

/// `detect` on the constructed table with a model of `category` that has latent surfaces: cuboid weights
/// 0 and surface weights that reward upward normals, so a hypothesis scores its best slice's upward-normal
/// density plus that slice's bias (`indicator`). Returns the detections, each with its independently
/// computed best slice and that slice's hypothesis, after checking every score against that independent
/// maximum and every `latent_slice` against the best slice.
fn detect_constructed_table(
    category: &str,
    top: f32,
    indicator: [f32; SLICES],
) -> (FeatureScene, Vec<(Detection, usize, Hypothesis)>) {
    use cog_gpu::backend::Backend;
    use cog_gpu::detect::{detect_preprocessed, DetectOptions};
    use cog_gpu::features::LatticePhase;
    use cog_gpu::features::{SizeQuantiles, YawAnchor};
    use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};
    let scene = table_scene(top);
    let layout = FeatureLayout::new([5, 5, 5], false, Groups::ALL).unwrap();
    let sizes = SizeQuantiles { widths: vec![0.8; 5], depths: vec![0.8; 3], heights: vec![0.7; 3] };
    let window = WindowSettings {
        step: 0.1,
        min_points: 50,
        yaw_anchor: YawAnchor::Camera,
        support: Support::Floor,
        lattice: LatticePhase::Camera,
        supporters: cog_gpu::category::SurfaceCategories::ALL,
    };
    let features = FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() };
    let up = NORMALS + normal_bin(Vec3::Z) as usize;
    let mut slice = vec![0.0f32; SLICE_DIM];
    for v in 0..SLICE_VOXELS {
        slice[v * PER_VOXEL + up] = 1.0;
    }
    let surface = SurfaceWeights::new(slice, indicator).unwrap();
    let model = Model::new(category, layout, sizes, window, features, vec![0.0; layout.dim()], serde_json::json!({}))
        .unwrap()
        .with_surface(surface.clone())
        .unwrap();
    // Without box voting: each detection's box is the hypothesis scored, rebuilt below from the box.
    let options = DetectOptions { min_score: Some(-1.0), box_voting: None, ..DetectOptions::default() };
    let found = detect_preprocessed("table", scene.pre.clone(), &[model], Backend::Cpu, &options).unwrap();
    assert!(!found.detections.is_empty());
    // The scene detection scored on: the camera's 16 yaws, the model's step.
    let yaws = cog_gpu::features::hypotheses::default_yaws();
    let detect_scene = FeatureScene::new(scene.pre.clone(), &yaws, 0.1);
    let engine = SurfaceEngine::new(&detect_scene, Groups::ALL, FastOptions::default());
    let checked = found
        .detections
        .into_iter()
        .map(|d| {
            let yaw = cog_gpu::features::hypotheses::nearest_yaw_index(&yaws, d.yaw);
            let hyp = Hypothesis::from_cuboid(&detect_scene, yaw, &d.cuboid());
            let (h, best) = best_slice(&engine.slice_scores(std::slice::from_ref(&hyp), &surface)[0]);
            assert!((d.score - best).abs() <= 1e-4 * (1.0 + best.abs()), "score {} vs {best}", d.score);
            assert_eq!(d.latent_slice, Some(h as u8), "the chosen slice is the best one");
            (d, h, hyp)
        })
        .collect();
    (scene, checked)
}

/// A latent-surface model of a category without support surfaces (the bookshelf) reports the surface
/// measured in its chosen slice: the median height of the slice's upward points (all of the table's top lie
/// at one height), else the slice's centre; the best detection's surface is the table top.
#[test]
fn detection_reports_the_surface_of_its_latent_slice() {
    let top = 0.55f32;
    let (scene, found) = detect_constructed_table("bookshelf", top, [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06]);
    for (d, h, hyp) in &found {
        let z = d.surface_z.expect("a latent model's detections carry their surface");
        assert_eq!(z, refined_surface_height(&scene.pre, &d.cuboid(), *h), "surface_z vs slice {h}");
        let slice_bottom = hyp.bottom + *h as f32 * hyp.size.z / SLICES as f32;
        let top_in_slice =
            (slice_bottom..=slice_bottom + hyp.size.z / SLICES as f32).contains(&(top + scene.pre.floor));
        if top_in_slice && d.cuboid().contains(Vec3::new(0.0, 3.0, top + scene.pre.floor)) {
            assert!((z - (top + scene.pre.floor)).abs() < 1e-5, "{z}");
        } else if !top_in_slice {
            assert!((z - surface_height(hyp, *h)).abs() < 1e-5, "no upward point: the slice centre");
        }
    }
    let height = found[0].0.surface_z.unwrap() - scene.pre.floor;
    assert!((height - top).abs() < 1e-5, "the best box's surface at {height} m, the top at {top} m");
}

/// A latent-surface model of a support-surface category (the table) reports the surface measured from the
/// points in the box wherever its latent slice is — here a bias of 10 puts it in slice 2, 0.2–0.3 m up the
/// 0.7 m boxes, below the top at 0.55 m — and the slice's surface only where the points show none.
#[test]
fn a_surface_category_reports_the_measured_surface_whatever_its_latent_slice() {
    use cog_gpu::features::surface::measured_surface_height;
    let top = 0.55f32;
    let (scene, found) = detect_constructed_table("table", top, [0.0, 0.0, 10.0, 0.0, 0.0, 0.0, 0.0]);
    let mut on_top = 0;
    for (d, h, _) in &found {
        assert_eq!(*h, 2, "the indicator's slice");
        let z = d.surface_z.expect("a latent model's detections carry their surface");
        match measured_surface_height(&scene.pre, &d.cuboid()) {
            // The scene's only upward face above the floor is the top: measured, it is the top's height,
            // not slice 2's.
            Some(_) => {
                assert!((z - (top + scene.pre.floor)).abs() < 1e-5, "measured {z}, the top at {top} m");
                on_top += 1;
            }
            // Without the top in its footprint, a box standing on the floor holds no upward point in slice
            // 2 (0.2–0.3 m up, the top at 0.55 m, the floor below its bottom): the slice's centre.
            None => {
                let cuboid = d.cuboid();
                let centre = cuboid.bottom() + 2.5 * cuboid.size.z / 7.0;
                assert!((z - centre).abs() < 1e-5, "no measured surface: {z}, slice 2's centre {centre}");
            }
        }
    }
    assert!(on_top > 0, "some detection measures the table top");
    let height = found[0].0.surface_z.unwrap() - scene.pre.floor;
    assert!((height - top).abs() < 1e-5, "the best box's surface at {height} m, the top at {top} m");
}

/// CCCP's default initialisation: the slice with the most upward-facing points of each ground truth, on the
/// constructed table (its top at 0.55 m fills slice 5 of the 0.7 m box; at 0.23 m slice 2), never slice 0
/// (the floor it stands on), and its only latent, 0, for a "no object" example.
#[test]
fn the_initial_slice_is_the_one_with_the_most_upward_points() {
    use cog_gpu::features::hypotheses::YawAnchor;
    use cog_gpu::learn::detector::{DetectorOracle, FeatureEngine, PositiveTarget, TrainingExample, TrainingSettings};
    for (top, expected) in [(0.55f32, 5usize), (0.23, 2)] {
        let scene = table_scene(top);
        let truth = Cuboid::new(Vec3::new(0.0, 3.0, -1.2 + 0.35), Vec3::new(0.8, 0.8, 0.7), 0.0);
        let settings = TrainingSettings {
            layout: FeatureLayout::new([5, 5, 5], false, Groups::ALL).unwrap(),
            sizes: vec![Vec3::new(0.8, 0.8, 0.7)],
            step: 0.2,
            min_points: 10,
            engine: FeatureEngine::Fast(FastOptions::default()),
            target: PositiveTarget::Exact,
            yaw_anchor: YawAnchor::Camera,
            lattice: LatticePhase::Camera,
            support: Support::Floor,
            surfaces: true,
        };
        let positive = TrainingExample::new("table".into(), &scene.pre, Some(truth), &[]);
        let negative = TrainingExample::new("none".into(), &scene.pre, None, &[]);
        let oracle = DetectorOracle::new(settings, vec![positive, negative]).unwrap();
        assert_eq!(oracle.upward_slices(), vec![expected, 0], "top at {top} m");
    }
}

/// The measured surface: the median height of the upward points inside the footprint and the slice only;
/// sideways normals, points outside the footprint or the slice do not count; no point gives the centre.
#[test]
fn the_refined_surface_is_the_median_of_the_slice_upward_points() {
    // A 1 m cube on the floor (z from 0 to 1): slice 3 spans 3/7..4/7 m.
    let cube = Cuboid::new(Vec3::new(0.0, 3.0, 0.5), Vec3::ONE, 0.0);
    let (low, high) = (3.0 / 7.0, 4.0 / 7.0);
    let mut points = Vec::new();
    let mut normals = Vec::new();
    let mut add = |p: Vec3, n: Vec3| {
        points.push(p);
        normals.push(n);
    };
    for (k, z) in [0.45f32, 0.46, 0.50, 0.52, 0.55].into_iter().enumerate() {
        add(Vec3::new(0.1 * k as f32 - 0.2, 3.0, z), Vec3::Z);
    }
    add(Vec3::new(0.0, 3.0, 0.44), Vec3::X); // sideways: not a surface
    add(Vec3::new(2.0, 3.0, 0.44), Vec3::Z); // outside the footprint
    add(Vec3::new(0.0, 3.0, 0.9), Vec3::Z); // another slice
    let gradients = vec![Vec2::ZERO; points.len()];
    let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
    let pre = Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 };
    assert!((low..high).contains(&0.45) && (low..high).contains(&0.55));
    assert_eq!(refined_surface_height(&pre, &cube, 3), 0.50, "the median of 0.45, 0.46, 0.50, 0.52, 0.55");
    assert_eq!(refined_surface_height(&pre, &cube, 6), 0.9);
    assert!((refined_surface_height(&pre, &cube, 1) - 1.5 / 7.0).abs() < 1e-6, "an empty slice: its centre");
}

/// The surface under a cover: a bed 0.55 m high whose duvet (400 upward points at 0.55 m) leaves a strip of
/// the mattress (20 points, 5 % of the duvet's, at 0.50 m) in view, pillows on it (30 points at 0.62 m):
/// the measured surface is the mattress, where the pillows rest. Without the strip, with a strip of fewer
/// than `MEASURED_MIN_POINTS` points or (under 1 600 duvet points) of less than `MEASURED_COVER_SHARE` of
/// the duvet's, with the strip 10 cm down (a shelf, beyond `MEASURED_COVER_DEPTH_M`), 2 cm down (the
/// cover's own thickness, not a face under it) or joined to the duvet without a valley (a slope of
/// points), it is the duvet.
#[test]
fn the_measured_surface_under_a_cover_is_the_face_below_it() {
    use cog_gpu::features::surface::{
        measured_surface_height, MEASURED_COVER_DEPTH_M, MEASURED_COVER_SHARE, MEASURED_MIN_POINTS,
    };
    let bed = Cuboid::new(Vec3::new(-0.4, 2.5, 0.275), Vec3::new(2.0, 1.6, 0.55), 20f32.to_radians());
    // `side` × `side` duvet points.
    let measure_on = |side: usize, strip: &[f32]| {
        let mut points = Vec::new();
        let mut add = |x: f32, y: f32, z: f32| points.push(bed.from_local(Vec3::new(x, y, z - 0.275)));
        for i in 0..side {
            for j in 0..side {
                add(-0.9 + 1.2 * i as f32 / side as f32, -0.7 + 1.4 * j as f32 / side as f32, 0.55);
            }
        }
        for (k, &z) in strip.iter().enumerate() {
            add(0.95, -0.7 + 0.01 * k as f32, z);
        }
        for k in 0..30 {
            add(0.8, -0.6 + 0.02 * k as f32, 0.62);
        }
        let normals = vec![Vec3::Z; points.len()];
        let gradients = vec![Vec2::ZERO; points.len()];
        let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
        let pre = Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 };
        measured_surface_height(&pre, &bed).expect("the duvet is a surface")
    };
    let measure = |strip: &[f32]| measure_on(20, strip);
    let near = |z: f32, want: f32| (z - want).abs() < 1e-4;
    assert!(near(measure(&[0.50; 20]), 0.50), "{}", measure(&[0.50; 20]));
    assert!(near(measure(&[]), 0.55));
    assert!(near(measure(&[0.50; MEASURED_MIN_POINTS - 1]), 0.55));
    // 1 600 duvet points need 16 under them: 20 are enough, 12 (more than MEASURED_MIN_POINTS) are not.
    let need = (MEASURED_COVER_SHARE * 1600.0) as usize;
    assert!(need > 12 && need <= 20 && MEASURED_MIN_POINTS <= 12);
    assert!(near(measure_on(40, &[0.50; 20]), 0.50));
    assert!(near(measure_on(40, &[0.50; 12]), 0.55));
    const { assert!(MEASURED_COVER_DEPTH_M < 0.10) };
    assert!(near(measure(&[0.45; 20]), 0.55));
    assert!(near(measure(&[0.53; 20]), 0.55));
    let slope: Vec<f32> = (0..60).map(|k| 0.50 + 0.05 * k as f32 / 60.0).collect();
    assert!(near(measure(&slope), 0.55));
}

/// The surface measured from the points alone (models without latent surfaces): the fullest 2 cm height bin
/// of the upward points in the footprint, with its neighbours, gives the median; a smaller, higher face
/// (things standing on the top), the floor around and under the box, sideways normals and points outside
/// the footprint do not move it; a top a little above a low box is still found; too few points give none.
#[test]
fn the_measured_surface_is_the_fullest_horizontal_face_in_the_footprint() {
    use cog_gpu::features::surface::{measured_surface_height, MEASURED_MIN_POINTS};
    // A table 0.75 m high, 1 × 0.6 m, turned by 30°, on a floor at z = 0.
    let table = Cuboid::new(Vec3::new(0.5, 3.0, 0.375), Vec3::new(1.0, 0.6, 0.75), 30f32.to_radians());
    let mut points = Vec::new();
    let mut normals = Vec::new();
    let mut add = |local: Vec3, n: Vec3| {
        points.push(table.from_local(local - Vec3::new(0.0, 0.0, 0.375)));
        normals.push(n);
    };
    // The top: 8 × 5 points at 0.75 m ± 1 cm of noise (median 0.75 exactly).
    for i in 0..8 {
        for j in 0..5 {
            let noise = [-0.01, 0.0, 0.01, 0.0, 0.0][(i + j) % 5];
            add(Vec3::new(-0.45 + 0.12 * i as f32, -0.25 + 0.12 * j as f32, 0.75 + noise), Vec3::Z);
        }
    }
    // A box on it (12 upward points at 0.85 m), the floor inside the footprint (30 at 0 m), the legs'
    // sideways points, and a sofa seat beside the table (outside the footprint, 60 points at 0.45 m).
    for k in 0..12 {
        add(Vec3::new(0.01 * k as f32, 0.0, 0.85), Vec3::Z);
    }
    for k in 0..30 {
        add(Vec3::new(-0.3 + 0.02 * k as f32, 0.1, 0.0), Vec3::Z);
    }
    for k in 0..30 {
        add(Vec3::new(0.45, 0.25, 0.02 * k as f32), Vec3::X);
    }
    for k in 0..60 {
        add(Vec3::new(0.7 + 0.01 * k as f32, 0.0, 0.45), Vec3::Z);
    }
    let gradients = vec![Vec2::ZERO; points.len()];
    let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
    let pre = Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 };
    assert_eq!(measured_surface_height(&pre, &table), Some(0.75));
    // A window box 0.1 m too low (top at 0.65 m; one slice, 0.093 m, above it reaches 0.743 m) reaches only
    // the 8 top points at 0.74 m: fewer than MEASURED_MIN_POINTS, so no surface rather than a wrong one.
    let low_box = Cuboid::new(Vec3::new(0.5, 3.0, 0.325), Vec3::new(1.0, 0.6, 0.65), table.yaw);
    assert_eq!(measured_surface_height(&pre, &low_box), None);
    // A box 5 cm lower than the top (top at 0.7 m: reach 0.8 m) finds the top.
    let lower_box = Cuboid::new(Vec3::new(0.5, 3.0, 0.35), Vec3::new(1.0, 0.6, 0.7), table.yaw);
    assert_eq!(measured_surface_height(&pre, &lower_box), Some(0.75));
    // Fewer than MEASURED_MIN_POINTS upward points near the peak: no surface.
    let few: Vec<usize> =
        (0..pre.points.len()).filter(|&i| pre.normals[i] == Vec3::Z).take(MEASURED_MIN_POINTS - 1).collect();
    let sparse = Preprocessed {
        points: few.iter().map(|&i| pre.points[i]).collect(),
        normals: few.iter().map(|&i| pre.normals[i]).collect(),
        gradients: vec![Vec2::ZERO; few.len()],
        ..pre.clone()
    };
    assert_eq!(measured_surface_height(&sparse, &table), None);
}

/// A nightstand whose top is mostly hidden by what stands on it shows more upward points on its lower
/// shelf: the fullest face is the shelf, the surface of a top-surface category is the top (the highest face
/// with a fifth of the fullest's points), and a top with fewer than that, or fewer than
/// `MEASURED_MIN_POINTS`, leaves the shelf. A bed keeps the fullest face whatever lies above it.
#[test]
fn a_top_surface_category_reports_its_top_over_a_fuller_shelf() {
    use cog_gpu::features::surface::{
        category_surface_height, measured_surface_height, top_surface_height, MEASURED_MIN_POINTS, TOP_FACE_SHARE,
        TOP_SURFACE_CATEGORIES,
    };
    assert!(TOP_SURFACE_CATEGORIES.contains(&"nightstand") && !TOP_SURFACE_CATEGORIES.contains(&"bed"));
    // A nightstand 0.6 m high, 0.5 × 0.4 m, on a floor at z = 0; a shelf at 0.2 m.
    let stand = Cuboid::new(Vec3::new(0.2, 2.5, 0.3), Vec3::new(0.5, 0.4, 0.6), 0.0);
    let scene = |top_points: usize, shelf_points: usize| {
        let mut points = Vec::new();
        for k in 0..shelf_points {
            points.push(stand.from_local(Vec3::new(-0.2 + 0.4 * (k % 20) as f32 / 20.0, -0.1, 0.2 - 0.3)));
        }
        for k in 0..top_points {
            points.push(stand.from_local(Vec3::new(-0.2 + 0.4 * (k % 20) as f32 / 20.0, 0.1, 0.6 - 0.3)));
        }
        let normals = vec![Vec3::Z; points.len()];
        let gradients = vec![Vec2::ZERO; points.len()];
        let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
        Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 }
    };
    // 100 shelf points, 25 on the top (a quarter: at least a fifth, and at least MEASURED_MIN_POINTS).
    let pre = scene(25, 100);
    const { assert!(25.0 >= TOP_FACE_SHARE * 100.0 && 25 >= MEASURED_MIN_POINTS) };
    assert_eq!(measured_surface_height(&pre, &stand), Some(0.2), "the fullest face is the shelf");
    assert_eq!(top_surface_height(&pre, &stand), Some(0.6), "the highest face with enough points is the top");
    assert_eq!(category_surface_height(&pre, &stand, "nightstand"), Some(0.6));
    assert_eq!(category_surface_height(&pre, &stand, "bed"), Some(0.2), "a bed keeps the fullest face");
    // 15 top points against 100: under a fifth, so the shelf; 25 against 100 but the top with 9 points
    // (under MEASURED_MIN_POINTS) against 40: the shelf too.
    assert_eq!(top_surface_height(&scene(15, 100), &stand), Some(0.2));
    assert_eq!(top_surface_height(&scene(MEASURED_MIN_POINTS - 1, 40), &stand), Some(0.2));
    // Only a top: the top, as the fullest face.
    assert_eq!(top_surface_height(&scene(30, 0), &stand), Some(0.6));
    // No face with MEASURED_MIN_POINTS: none.
    assert_eq!(top_surface_height(&scene(MEASURED_MIN_POINTS - 1, 0), &stand), None);
}

/// A bed's mattress 7.5 cm under its duvet (the generator's duvets are up to 7 cm thick, beyond the 6 cm
/// that `measured_surface_height` looks down): a bed's surface looks down to `BED_COVER_DEPTH_M` and finds
/// it; the same points as a sofa's (or through `measured_surface_height`) give the duvet; a face 10 cm down
/// is out of a bed's reach too.
#[test]
fn a_beds_mattress_is_found_deeper_under_its_duvet() {
    use cog_gpu::features::surface::{
        category_surface_height, measured_surface_height, BED_COVER_DEPTH_M, MEASURED_COVER_DEPTH_M,
    };
    const { assert!(MEASURED_COVER_DEPTH_M < 0.075 && 0.075 < BED_COVER_DEPTH_M && BED_COVER_DEPTH_M < 0.10) };
    let bed = Cuboid::new(Vec3::new(-0.4, 2.5, 0.275), Vec3::new(2.0, 1.6, 0.55), 20f32.to_radians());
    // 400 duvet points at 0.55 m and a strip of 20 mattress points at `mattress` beside it.
    let scene = |mattress: f32| {
        let mut points = Vec::new();
        let mut add = |x: f32, y: f32, z: f32| points.push(bed.from_local(Vec3::new(x, y, z - 0.275)));
        for i in 0..20 {
            for j in 0..20 {
                add(-0.9 + 1.2 * i as f32 / 20.0, -0.7 + 1.4 * j as f32 / 20.0, 0.55);
            }
        }
        for k in 0..20 {
            add(0.95, -0.7 + 0.01 * k as f32, mattress);
        }
        let normals = vec![Vec3::Z; points.len()];
        let gradients = vec![Vec2::ZERO; points.len()];
        let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
        Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 }
    };
    let near = |z: Option<f32>, want: f32| z.is_some_and(|z| (z - want).abs() < 1e-4);
    let deep = scene(0.475);
    assert!(near(category_surface_height(&deep, &bed, "bed"), 0.475));
    assert!(near(category_surface_height(&deep, &bed, "sofa"), 0.55));
    assert!(near(measured_surface_height(&deep, &bed), 0.55));
    // A face 10 cm down: beyond a bed's reach as well.
    assert!(near(category_surface_height(&scene(0.45), &bed, "bed"), 0.55));
    // 5 cm down: both find it.
    assert!(near(category_surface_height(&scene(0.50), &bed, "bed"), 0.50));
    assert!(near(measured_surface_height(&scene(0.50), &bed), 0.50));
}

/// A dresser taller than the camera: its front face is seen up to its top at 1.0 m, its top not at all, and
/// a TV stands 0.4 m behind the front, its screen up to 1.5 m. A top-surface category then reports the
/// front face's upper edge if it is a dresser or nightstand (the TV's face is not in the front's slab); so
/// does a window box 0.2 m lower than the dresser; a bed, table, desk or sofa (no fallback) reports none; a face of upward points still wins over the edge; a face too
/// sparse to tell gives none.
#[test]
fn an_unseen_top_is_the_upper_edge_of_the_front_face() {
    use cog_gpu::features::surface::{
        category_surface, category_surface_height, front_edge_height, top_surface_height, SurfaceSource,
        FRONT_EDGE_CATEGORIES, FRONT_MIN_MEDIAN, MEASURED_MIN_POINTS,
    };
    let dresser = Cuboid::new(Vec3::new(0.3, 3.0, 0.5), Vec3::new(0.9, 0.5, 1.0), 25f32.to_radians());
    let toward = |local: Vec3| dresser.from_local(local) - dresser.from_local(Vec3::ZERO);
    // The front (local y = −0.25, normals −y): 9 columns × 100 rows at z = 0.005, 0.015, …, 0.995; the TV's
    // screen (local y = +0.15, normals −y) from 1.0 to 1.5 m; the side (local x = +0.45, normals +x).
    let scene = |columns: usize, top_points: usize| {
        let mut points = Vec::new();
        let mut normals = Vec::new();
        let mut add = |x: f32, y: f32, z: f32, n: Vec3| {
            points.push(dresser.from_local(Vec3::new(x, y, z - 0.5)));
            normals.push(n);
        };
        for i in 0..columns {
            for k in 0..100 {
                add(-0.4 + 0.1 * i as f32, -0.25, 0.005 + 0.01 * k as f32, toward(-Vec3::Y));
            }
        }
        for i in 0..5 {
            for k in 0..50 {
                add(-0.2 + 0.1 * i as f32, 0.15, 1.005 + 0.01 * k as f32, toward(-Vec3::Y));
            }
        }
        for k in 0..30 {
            add(0.45, 0.0, 0.03 * k as f32, toward(Vec3::X));
        }
        for k in 0..top_points {
            add(-0.4 + 0.8 * k as f32 / top_points as f32, -0.1, 0.97, Vec3::Z);
        }
        let gradients = vec![Vec2::ZERO; points.len()];
        let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
        Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 }
    };
    let near = |z: Option<f32>, want: f32| z.is_some_and(|z| (z - want).abs() < 1e-4);
    let unseen = scene(9, 0);
    assert_eq!(top_surface_height(&unseen, &dresser), None, "no upward face");
    assert!(near(front_edge_height(&unseen, &dresser), 1.0), "{:?}", front_edge_height(&unseen, &dresser));
    for category in FRONT_EDGE_CATEGORIES {
        assert!(near(category_surface_height(&unseen, &dresser, category), 1.0), "{category}");
    }
    for category in ["bed", "table", "desk", "sofa"] {
        assert_eq!(category_surface_height(&unseen, &dresser, category), None, "{category} has no fallback");
    }
    // A window box 0.2 m lower than the dresser (top at 0.8 m) follows the front up to the same edge.
    let low_box = Cuboid::new(Vec3::new(0.3, 3.0, 0.4), Vec3::new(0.9, 0.5, 0.8), dresser.yaw);
    assert!(near(category_surface_height(&unseen, &low_box, "dresser"), 1.0));
    // A face of enough upward points (at 0.97 m, 3 cm under the edge, to tell them apart) wins over the edge.
    let seen = scene(9, 2 * MEASURED_MIN_POINTS);
    assert!(near(category_surface_height(&seen, &dresser, "dresser"), 0.97));
    // One column: two points per 2 cm bin, under FRONT_MIN_MEDIAN — no edge, no surface.
    const { assert!(2.0 < FRONT_MIN_MEDIAN) };
    assert_eq!(category_surface_height(&scene(1, 0), &dresser, "dresser"), None);
    // The rule that answered, as the detections record it.
    let source = |pre: &Preprocessed| category_surface(pre, &dresser, "dresser").map(|(_, s)| s);
    assert_eq!(source(&unseen), Some(SurfaceSource::FrontEdge));
    assert_eq!(source(&seen), Some(SurfaceSource::Face));
    assert_eq!(source(&scene(1, 0)), None);
}

/// The front face's upper edge is where the face ends: a face that runs on up through the whole reach
/// ([`FRONT_REACH_M`] above the box's top — a wall behind a false dresser) has none (it reported the reach's
/// top, 0.6 m above the box, before 2026-12-08); and a box less than [`FRONT_WALK_FROM_M`] tall walks its
/// face from the bottom, so its edge is where its points stop, not under its bottom (it reported the box's
/// bottom − 2 cm before).
#[test]
fn the_front_edge_is_where_the_face_ends_within_the_reach() {
    use cog_gpu::features::surface::{front_edge_height, FRONT_REACH_M, FRONT_WALK_FROM_M, MEASURED_BIN_M};
    // A face of 9 columns in the box's front plane (local y = −0.25, normals −y), 1 cm rows from z = 0.005 to
    // `face_top`, the box standing on z = 0.
    let scene = |cuboid: &Cuboid, face_top: f32| {
        let toward = |local: Vec3| cuboid.from_local(local) - cuboid.from_local(Vec3::ZERO);
        let mut points = Vec::new();
        for i in 0..9 {
            let mut z = 0.005;
            while z < face_top {
                points.push(cuboid.from_local(Vec3::new(-0.4 + 0.1 * i as f32, -0.25, z - cuboid.size.z / 2.0)));
                z += 0.01;
            }
        }
        let normals = vec![toward(-Vec3::Y); points.len()];
        let gradients = vec![Vec2::ZERO; points.len()];
        let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
        Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: 0.0 }
    };
    let dresser = Cuboid::new(Vec3::new(0.3, 3.0, 0.5), Vec3::new(0.9, 0.5, 1.0), 25f32.to_radians());
    // The face ends 0.2 m above the box's top, within the reach: that is its edge (a window box's case).
    let edge = front_edge_height(&scene(&dresser, 1.2), &dresser).expect("an edge within the reach");
    assert!((edge - 1.2).abs() < 1e-4, "{edge}");
    // The face runs 0.2 m past the reach: no edge.
    const { assert!(FRONT_REACH_M < 0.8) };
    assert_eq!(front_edge_height(&scene(&dresser, 1.0 + FRONT_REACH_M + 0.2), &dresser), None);
    // A box 0.25 m tall (under FRONT_WALK_FROM_M) whose face ends at 0.15 m: the edge is 0.16 m, the top of
    // the 2 cm bin holding the face's last row (z = 0.145).
    const { assert!(FRONT_WALK_FROM_M > 0.25 && MEASURED_BIN_M == 0.02) };
    let low = Cuboid::new(Vec3::new(0.3, 3.0, 0.125), Vec3::new(0.9, 0.5, 0.25), 25f32.to_radians());
    let edge = front_edge_height(&scene(&low, 0.15), &low).expect("an edge on the low box");
    assert!((edge - 0.16).abs() < 1e-4, "{edge}");
}
