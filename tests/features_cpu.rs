//! The CPU feature engine against analytic cases and independent computations.

use std::f32::consts::PI;
use std::path::Path;

use cog_gpu::features::cpu::{self, view_cosine};
use cog_gpu::features::feature_layout::{view_features, FeatureLayout, Groups, COG, DENSITY, NORMALS, PER_VOXEL, VIEW};
use cog_gpu::features::preprocess::{
    estimate_normals, floor_height, gradient_orientation, normal_bin, plane_normal, ImageGradients, Preprocessed,
};
use cog_gpu::features::{sliding_window, FeatureScene, Hypothesis, SizeQuantiles, WindowOptions};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::{Camera, Cuboid};
use glam::{Mat3, Vec2, Vec3};

const FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";
const STATS: &str = "../shared/data/sunrgbd-size-stats.json";

/// A level camera (Rtilt = I) looking along +y, 500 px focal length, 640×480.
fn level_camera() -> Camera {
    Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY)
}

#[test]
fn gradients_take_the_strongest_channel_and_replicate_borders() {
    let mut img = image::RgbImage::new(4, 3);
    // Red ramps along x by 10 per column, blue jumps by 200 between rows 1 and 2.
    for (x, y, p) in img.enumerate_pixels_mut() {
        p.0 = [(10 * x) as u8, 0, if y == 2 { 200 } else { 0 }];
    }
    let g = ImageGradients::compute(&img);
    // Interior pixel (1, 0): red dx = (20 − 0)/255, blue dy = 0 (rows 0,1 replicate) → red wins.
    let g10 = g.at(1, 0);
    assert!((g10.x - 20.0 / 255.0).abs() < 1e-6 && g10.y == 0.0, "{g10:?}");
    // Pixel (1, 1): blue dy = (200 − 0)/255 beats red.
    let g11 = g.at(1, 1);
    assert!(g11.x == 0.0 && (g11.y - 200.0 / 255.0).abs() < 1e-6, "{g11:?}");
    // Border column 0: one-sided red difference (10 − 0)/255.
    assert!((g.at(0, 0).x - 10.0 / 255.0).abs() < 1e-6);
    // Orientation is unsigned in [0, π).
    assert!((gradient_orientation(Vec2::new(-1.0, 0.0)) - 0.0).abs() < 1e-6);
    assert!((gradient_orientation(Vec2::new(0.0, -1.0)) - PI / 2.0).abs() < 1e-6);
    assert!((gradient_orientation(Vec2::new(1.0, 1.0)) - PI / 4.0).abs() < 1e-6);
}

#[test]
fn normals_of_a_plane_face_the_camera() {
    // A tilted plane z = 0.5·x − 1 sampled on a grid 2 m in front of the camera.
    let mut points = Vec::new();
    for a in 0..20 {
        for b in 0..20 {
            let (x, y) = (-0.5 + 0.05 * a as f32, 2.0 + 0.05 * b as f32);
            points.push(Vec3::new(x, y, 0.5 * x - 1.0));
        }
    }
    let normals = estimate_normals(&points);
    let expected = Vec3::new(-0.5, 0.0, 1.0).normalize(); // faces up, toward the camera above the plane
    for (p, n) in points.iter().zip(&normals) {
        assert!(n.dot(expected) > 0.9999, "normal {n:?} at {p:?}");
        assert!(n.dot(-*p) >= 0.0);
    }
    // A degenerate neighbourhood (all points equal) has no plane.
    assert!(plane_normal([Vec3::ONE; 5].into_iter()).is_none());
}

#[test]
fn normal_code_bins_in_the_cuboid_frame() {
    assert_eq!(normal_bin(Vec3::Z), 0);
    // Out of the front (−b): ring 1 (horizontal), sector 0.
    assert_eq!(normal_bin(Vec3::new(0.0, -1.0, 0.0)), 9);
    // Along +a: sector 2; out of the back: sector 4; along −a: sector 6.
    assert_eq!(normal_bin(Vec3::new(1.0, 0.0, 0.0)), 11);
    assert_eq!(normal_bin(Vec3::new(0.0, 1.0, 0.0)), 13);
    assert_eq!(normal_bin(Vec3::new(-1.0, 0.0, 0.0)), 15);
    // Straight down: ring 0; tilted up 45° out of the front: ring 2, sector 0.
    assert_eq!(normal_bin(-Vec3::Z), 1);
    assert_eq!(normal_bin(Vec3::new(0.0, -1.0, 1.0).normalize()), 17);
    // Sector boundaries at ±22.5°: 20° off the front stays in sector 0, 25° moves to sector 1.
    let at = |deg: f32| Vec3::new(deg.to_radians().sin(), -deg.to_radians().cos(), 0.0);
    assert_eq!(normal_bin(at(20.0)), 9);
    assert_eq!(normal_bin(at(25.0)), 10);
    assert_eq!(normal_bin(at(-25.0)), 16);
}

#[test]
fn floor_is_the_low_quantile() {
    let mut points: Vec<Vec3> = (0..10_000).map(|i| Vec3::new(0.0, 1.0, i as f32 * 0.001)).collect();
    points.push(Vec3::new(0.0, 1.0, -5.0)); // one outlier below the floor does not move it much
    let floor = floor_height(&points);
    // ⌊0.001·10000⌋ = 10th smallest: the outlier, then 0.000 … 0.009.
    assert!((floor - 0.009).abs() < 1e-6, "{floor}");
}

#[test]
fn sizes_come_from_the_statistics_file() {
    let q = SizeQuantiles::from_stats_file(Path::new(STATS), "bed").unwrap();
    let sizes = q.sizes();
    assert_eq!(sizes.len(), 45);
    assert_eq!(sizes[0], Vec3::new(1.034, 1.454, 0.809));
    assert_eq!(sizes[44], Vec3::new(2.191, 2.244, 1.42));
    let err = SizeQuantiles::from_stats_file(Path::new(STATS), "spaceship").unwrap_err();
    assert!(err.to_string().contains("spaceship"));
    // The file names the nightstand as SUN RGB-D does, `night_stand` (median width 0.61 m): found under
    // cog-gpu's name (it was not).
    let nightstand = SizeQuantiles::from_stats_file(Path::new(STATS), "nightstand").unwrap();
    assert_eq!(nightstand.widths[2], 0.61);
    // From cuboids: quantiles by linear interpolation.
    let cuboids: Vec<Cuboid> =
        (0..11).map(|i| Cuboid::new(Vec3::ZERO, Vec3::new(1.0 + 0.1 * i as f32, 1.0, 1.0), 0.0)).collect();
    let from = SizeQuantiles::from_cuboids(&cuboids).unwrap();
    assert!((from.widths[2] - 1.5).abs() < 1e-6 && (from.widths[0] - 1.1).abs() < 1e-6);
}

/// Points of a wall patch on the plane y = `depth`, x ∈ [x0, x1], z ∈ [z0, z1], on a `n × n` grid, with
/// normals toward the camera and a constant image gradient.
fn wall(depth: f32, x: (f32, f32), z: (f32, f32), n: usize, gradient: Vec2) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec2>) {
    let mut points = Vec::new();
    for a in 0..n {
        for b in 0..n {
            let u = (a as f32 + 0.5) / n as f32;
            let v = (b as f32 + 0.5) / n as f32;
            points.push(Vec3::new(x.0 + u * (x.1 - x.0), depth, z.0 + v * (z.1 - z.0)));
        }
    }
    let normals = vec![Vec3::new(0.0, -1.0, 0.0); points.len()];
    let gradients = vec![gradient; points.len()];
    (points, normals, gradients)
}

fn scene_of(points: Vec<Vec3>, normals: Vec<Vec3>, gradients: Vec<Vec2>, floor: f32, yaws: &[f32]) -> FeatureScene {
    let pre = Preprocessed { camera: level_camera(), image_size: [640, 480], points, normals, gradients, floor };
    FeatureScene::new(pre, yaws, 0.1)
}

/// Area of the silhouette of a box from the camera: half the sum of the absolute projected areas of its six
/// faces (each silhouette point is covered once by the front faces and once by the back faces). Computed
/// here independently of `geometry::projected_hull_area`.
fn silhouette_area(camera: &Camera, corners: &[Vec3; 8]) -> f32 {
    let p: Vec<Vec2> = corners.iter().map(|&c| camera.project(c).unwrap()).collect();
    let faces = [[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];
    let area = |f: &[usize; 4]| {
        let mut twice = 0.0;
        for e in 0..4 {
            let (a, b) = (p[f[e]], p[f[(e + 1) % 4]]);
            twice += a.x * b.y - a.y * b.x;
        }
        (0.5 * twice).abs()
    };
    0.5 * faces.iter().map(area).sum::<f32>()
}

#[test]
fn density_of_a_voxel_filled_at_a_known_rate() {
    // One 0.4 m voxel (1×1×1 grid, not expanded) 2 m in front of the camera; 400 points on its front face.
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::ALL).unwrap();
    let (points, normals, gradients) = wall(2.0, (-0.2, 0.2), (-0.2, 0.2), 20, Vec2::ZERO);
    let scene = scene_of(points, normals, gradients, -0.2, &[0.0]);
    let cuboid = Cuboid::new(Vec3::new(0.0, 2.1, 0.0), Vec3::splat(0.4), 0.0); // front face at y = 1.9
    let hyp = Hypothesis::from_cuboid(&scene, 0, &cuboid);
    let mut f = vec![0.0; layout.dim()];
    let inside = cpu::hypothesis_features(&scene, &layout, &hyp, &mut f);
    assert_eq!(inside, 400);
    let area = silhouette_area(&scene.pre.camera, &cuboid.corners());
    // Front face 0.4 m at 1.9 m → 105.26 px on a side; the back face is smaller and hidden.
    assert!((area - (0.4 * 500.0 / 1.9f32).powi(2)).abs() < 1.0, "{area}");
    assert!((f[DENSITY] - 400.0 / area).abs() < 1e-4 * f[DENSITY], "{} vs {}", f[DENSITY], 400.0 / area);
    // Every normal points out of the cuboid's front: normal bin 9 holds the whole density.
    assert!((f[NORMALS + 9] - f[DENSITY]).abs() < 1e-7);
    assert_eq!(f[NORMALS..COG].iter().filter(|&&v| v != 0.0).count(), 1);
    // No gradients: COG all zero.
    assert!(f[COG..PER_VOXEL].iter().all(|&v| v == 0.0));
}

/// Image gradient of a 3D edge direction `edge` on a surface point `p` seen by a level camera: perpendicular
/// in the image to the projected edge direction (the analytic image of a stripe texture).
fn gradient_of_edge(camera: &Camera, p: Vec3, edge: Vec3, magnitude: f32) -> Vec2 {
    let a = camera.project(p).unwrap();
    let b = camera.project(p + edge * 1e-3).unwrap();
    let e = (b - a).normalize();
    Vec2::new(-e.y, e.x) * magnitude
}

#[test]
fn fronto_parallel_wall_lands_in_the_expected_cog_bin() {
    // Gradient at 40° = 2π/9 on the face (from the width axis toward up): COG bin 2. In the image, up is
    // −y, so the image gradient is (cos 40°, −sin 40°).
    let phi = 2.0 * PI / 9.0;
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::ALL).unwrap();
    let (points, normals, gradients) = wall(2.0, (-0.2, 0.2), (-0.2, 0.2), 10, Vec2::new(phi.cos(), -phi.sin()) * 0.5);
    let scene = scene_of(points, normals, gradients, -0.2, &[0.0]);
    let cuboid = Cuboid::new(Vec3::new(0.0, 2.1, 0.0), Vec3::splat(0.4), 0.0);
    let mut f = vec![0.0; layout.dim()];
    cpu::hypothesis_features(&scene, &layout, &Hypothesis::from_cuboid(&scene, 0, &cuboid), &mut f);
    let cog = &f[COG..PER_VOXEL];
    // 100 points × 0.5 = 50 in bin 2; normalised 50/√(2500 + 0.01).
    let expected = 50.0 / (2500.0f32 + 0.01).sqrt();
    assert!((cog[2] - expected).abs() < 1e-4, "{cog:?}");
    assert!(cog.iter().enumerate().all(|(b, &v)| b == 2 || v.abs() < 1e-4), "{cog:?}");
    // Halfway between bins 4 and 5 (90° = 4.5·20°): a horizontal edge, vertical image gradient.
    let (points, normals, gradients) = wall(2.0, (-0.2, 0.2), (-0.2, 0.2), 10, Vec2::new(0.0, 1.0));
    let scene = scene_of(points, normals, gradients, -0.2, &[0.0]);
    cpu::hypothesis_features(&scene, &layout, &Hypothesis::from_cuboid(&scene, 0, &cuboid), &mut f);
    let cog = &f[COG..PER_VOXEL];
    assert!((cog[4] - cog[5]).abs() < 1e-4 && cog[4] > 0.7, "{cog:?}");
}

/// HOG-style histogram with bins fixed in the image: unsigned gradient angle, 9 bins of π/9, linear split.
fn hog_histogram(gradients: &[Vec2]) -> [f32; 9] {
    let mut h = [0.0f32; 9];
    for g in gradients {
        let p = gradient_orientation(*g) * 9.0 / PI;
        let b0 = (p.floor() as usize).min(8);
        let frac = p - b0 as f32;
        h[b0] += (1.0 - frac) * g.length();
        h[(b0 + 1) % 9] += frac * g.length();
    }
    h
}

fn cosine(a: &[f32], b: &[f32]) -> f32 {
    let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na: f32 = a.iter().map(|x| x * x).sum::<f32>().sqrt();
    let nb: f32 = b.iter().map(|x| x * x).sum::<f32>().sqrt();
    dot / (na * nb)
}

#[test]
fn turning_cuboid_and_scene_together_keeps_cog_while_hog_changes() {
    // A small textured box face (0.15 m) with stripes whose in-face gradient is at 40°, the whole object
    // turned about its vertical axis by different yaws in front of a fixed camera. The image gradients are
    // recomputed analytically for each pose.
    let phi = 2.0 * PI / 9.0;
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::ALL).unwrap();
    let centre = Vec3::new(0.2, 2.5, -0.3);
    let size = Vec3::splat(0.15);
    let mut cogs = Vec::new();
    let mut hogs = Vec::new();
    for yaw in [0.0f32, 0.5, -0.7, 1.0] {
        let cuboid = Cuboid::new(centre, size, yaw);
        let a = cuboid.width_axis().extend(0.0);
        let edge = (phi + PI / 2.0).cos() * a + (phi + PI / 2.0).sin() * Vec3::Z;
        let mut points = Vec::new();
        let mut gradients = Vec::new();
        for i in 0..12 {
            for k in 0..12 {
                let local =
                    Vec3::new(-0.075 + 0.15 * (i as f32 + 0.5) / 12.0, -0.074, -0.075 + 0.15 * (k as f32 + 0.5) / 12.0);
                let p = cuboid.from_local(local);
                points.push(p);
                gradients.push(gradient_of_edge(&level_camera(), p, edge, 0.5));
            }
        }
        let normals = vec![cuboid.front().extend(0.0); points.len()];
        hogs.push(hog_histogram(&gradients));
        let scene = scene_of(points, normals, gradients, centre.z - 0.075, &[yaw]);
        let mut f = vec![0.0; layout.dim()];
        let inside = cpu::hypothesis_features(&scene, &layout, &Hypothesis::from_cuboid(&scene, 0, &cuboid), &mut f);
        assert_eq!(inside, 144);
        cogs.push(f[COG..PER_VOXEL].to_vec());
    }
    for n in 1..cogs.len() {
        let c = cosine(&cogs[0], &cogs[n]);
        // Not exactly 1: the projection is linearised at the voxel centre, and the face's points see
        // slightly different perspective (0.15 m face at 2.5 m).
        assert!(c > 0.995, "COG changed with the pose: cosine {c} ({:?} vs {:?})", cogs[0], cogs[n]);
        assert!(cogs[n][2] > 0.99, "{:?}", cogs[n]);
    }
    let worst_hog = (1..hogs.len()).map(|n| cosine(&hogs[0], &hogs[n])).fold(1.0f32, f32::min);
    assert!(worst_hog < 0.8, "HOG-style binning should change with the pose, worst cosine {worst_hog}");
}

#[test]
fn view_features_tell_facing_from_facing_away() {
    let towards = Cuboid::new(Vec3::new(0.0, 3.0, 0.0), Vec3::ONE, 0.0); // front −b = −y: faces the camera
    let away = Cuboid::new(Vec3::new(0.0, 3.0, 0.0), Vec3::ONE, PI);
    let side = Cuboid::new(Vec3::new(0.0, 3.0, 0.0), Vec3::ONE, PI / 2.0);
    assert!((view_cosine(&towards) - 1.0).abs() < 1e-6);
    assert!((view_cosine(&away) + 1.0).abs() < 1e-6);
    assert!(view_cosine(&side).abs() < 1e-6);
    let (ft, fa) = (view_features(view_cosine(&towards)), view_features(view_cosine(&away)));
    assert!((ft[10] - 1.0).abs() < 1e-6 && (fa[0] - 1.0).abs() < 1e-6);
    assert!((ft[0] - (-2.0f32 * 2.0 / 0.5).exp()).abs() < 1e-7); // (1 − (−1))²/(2·0.25) = 8
    assert_eq!((ft[VIEW - 1], fa[VIEW - 1]), (1.0, 1.0));
}

#[test]
fn real_frame_counts_match_a_brute_force_pass() {
    let frame = Frame::read(FRAME, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    assert!(pre.floor < -0.8 && pre.floor > -2.0, "floor {}", pre.floor);
    let sizes = set_sizes();
    let yaws = cog_gpu::features::default_yaws();
    let scene = FeatureScene::new(pre, &yaws, 0.1);
    let set = sliding_window(&scene, &WindowOptions { sizes, min_points: 50 });
    // This close-up frame (2 m × 1 m of desk and wall) is dense everywhere: every chair box holds points.
    assert_eq!(set.generated, 45 * scene.yaws.iter().map(occupied_cells).sum::<usize>());
    assert!(!set.hypotheses.is_empty() && set.hypotheses.len() <= set.generated);
    // The skipping count agrees with a brute-force count above the floor slab to within the cell layer.
    let hyp = set.hypotheses[set.hypotheses.len() / 2];
    let cuboid = hyp.cuboid(&scene);
    let brute = scene.pre.points.iter().filter(|p| cuboid.contains(**p) && p.z > scene.pre.floor + 0.1).count() as f32;
    assert!((hyp.points_inside as f32 - brute).abs() < 0.25 * brute, "{} vs brute force {brute}", hyp.points_inside);
    // A higher threshold drops hypotheses.
    let strict = sliding_window(&scene, &WindowOptions { sizes: set_sizes(), min_points: hyp.points_inside });
    assert!(strict.hypotheses.len() < set.hypotheses.len() && strict.generated == set.generated);
    assert!(strict.hypotheses.iter().all(|h| h.points_inside >= hyp.points_inside));
    let layout = FeatureLayout::default();
    // A few kept hypotheses spread over the set: counts from the features vs a brute-force pass with
    // Cuboid::to_local over every point.
    let step = (set.hypotheses.len() / 5).max(1);
    for hyp in set.hypotheses.iter().step_by(step).take(5) {
        assert!((hyp.bottom - scene.pre.floor).abs() < 1e-6);
        let mut f = vec![0.0; layout.dim()];
        let inside = cpu::hypothesis_features(&scene, &layout, hyp, &mut f);
        let expanded = cpu::expanded_cuboid(&scene, &layout, hyp);
        let brute = scene.pre.points.iter().filter(|&&p| expanded.contains(p)).count() as i64;
        // Points exactly on a face may be decided differently by the two formulas; allow 0.1 %.
        assert!((inside as i64 - brute).abs() <= 1 + brute / 1000, "inside {inside} vs brute force {brute}");
        assert!(f.iter().all(|v| v.is_finite()));
    }
}

fn set_sizes() -> Vec<Vec3> {
    SizeQuantiles::from_stats_file(Path::new(STATS), "chair").unwrap().sizes()
}

fn occupied_cells(grid: &cog_gpu::features::YawGrid) -> usize {
    (0..grid.cells[1])
        .flat_map(|row| (0..grid.cells[0]).map(move |col| (row, col)))
        .filter(|&(row, col)| !grid.row_span(row, (col, col)).is_empty())
        .count()
}

#[test]
fn polynomial_angle_matches_atan2_mod_pi() {
    for n in 0..3600 {
        let theta = n as f32 * (std::f32::consts::TAU / 3600.0);
        for r in [1e-3f32, 1.0, 250.0] {
            let (y, x) = (r * theta.sin(), r * theta.cos());
            let expected = y.atan2(x).rem_euclid(PI);
            let got = cpu::unsigned_angle(y, x);
            assert!((0.0..PI).contains(&got), "{got} out of [0, π) at θ = {theta}");
            let diff = (got - expected).abs();
            assert!(diff.min(PI - diff) < 2e-5, "θ = {theta}: {got} vs {expected}");
        }
    }
    assert_eq!(cpu::unsigned_angle(0.0, 0.0), 0.0);
}

#[test]
fn weights_files_round_trip_and_reject_other_layouts() {
    use cog_gpu::features::WeightsFile;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.json");
    let layout = FeatureLayout::default();
    let weights: Vec<f32> = (0..layout.dim()).map(|n| n as f32 * 1e-4).collect();
    let file = WeightsFile::new(layout, "bed", weights, 0.5).unwrap();
    file.write(&path).unwrap();
    assert_eq!(WeightsFile::read(&path).unwrap(), file);
    // A file written for another feature order (id mismatch) is rejected, naming the file.
    let text = std::fs::read_to_string(&path).unwrap().replace("cog-v1 grid=5x5x5", "cog-v0 grid=5x5x5");
    std::fs::write(&path, text).unwrap();
    let err = WeightsFile::read(&path).unwrap_err().to_string();
    assert!(err.contains("w.json") && err.contains("layout_id"), "{err}");
    // Wrong length; non-zero weights in a switched-off group.
    assert!(WeightsFile::new(layout, "bed", vec![0.0; 10], 0.0).is_err());
    let geom = FeatureLayout::new([5, 5, 5], true, Groups::GEOM).unwrap();
    let mut w = vec![0.0; geom.dim()];
    w[COG] = 1.0;
    assert!(WeightsFile::new(geom, "bed", w, 0.0).unwrap_err().to_string().contains("cog bin 0"));
}

/// A floor seen by a structured-light camera (320×240, fx 285, 7.5 cm baseline, disparity in eighths of a
/// pixel, camera 1.3 m up looking level): the quantised depths put the floor's points on fronto-parallel
/// strips, and the 15 nearest of a point mostly lie on its strip, whose plane is the optical axis's; the 40
/// nearest of `NormalSearch::KdTreeWide` reach the neighbouring strips and find the floor: the shares of
/// the floor's points in the up cone (the normal code's bin 0). And each search's name round trip, as model
/// files and the command line write it.
#[test]
fn forty_neighbours_find_a_floor_on_quantised_depth() {
    use cog_gpu::features::preprocess::{estimate_normals_of, NormalSearch, NORMAL_NEIGHBOURS, WIDE_NORMAL_NEIGHBOURS};
    let (fx, baseline, height) = (285.0f32, 0.075f32, 1.3f32);
    let mut points = Vec::new();
    for row in 125..240 {
        for col in 0..320 {
            // The ray through the pixel (x right, y forward, z up), to the floor z = −1.3.
            let ray = Vec3::new((col as f32 + 0.5 - 160.0) / fx, 1.0, -(row as f32 + 0.5 - 120.0) / fx);
            let depth = height / -ray.z;
            if depth > 4.0 {
                continue;
            }
            let disparity = (fx * baseline / depth * 8.0).round() / 8.0;
            points.push(ray * (fx * baseline / disparity));
        }
    }
    let up_share = |neighbours: usize| {
        let normals = estimate_normals_of(&points, neighbours);
        normals.iter().filter(|n| normal_bin(**n) == 0).count() as f64 / normals.len() as f64
    };
    let (narrow, wide) = (up_share(NORMAL_NEIGHBOURS), up_share(WIDE_NORMAL_NEIGHBOURS));
    eprintln!("up cone: {narrow:.3} with 15 neighbours, {wide:.3} with 40");
    assert!(narrow < 0.5 && wide > 0.8, "up cone: {narrow:.3} with 15 neighbours, {wide:.3} with 40");
    assert_eq!(estimate_normals_of(&points, NORMAL_NEIGHBOURS), estimate_normals(&points));
    // `Preprocessed` with the search fits each point's 40 nearest.
    let frame = Frame::read(FRAME, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame_with(&frame, NormalSearch::KdTreeWide).unwrap();
    assert_eq!(pre.normals, estimate_normals_of(&frame.point_cloud().points, WIDE_NORMAL_NEIGHBOURS));
    for search in NormalSearch::ALL {
        assert_eq!(search.name().parse::<NormalSearch>().unwrap(), search);
        let json = serde_json::to_string(&search).unwrap();
        assert_eq!(json, format!("\"{}\"", search.name()));
        assert_eq!(serde_json::from_str::<NormalSearch>(&json).unwrap(), search);
    }
}
