//! Where the lattice of hypothesis centres starts (`features::scene::LatticePhase`): on a constructed room
//! corner — a back wall 3.137 m in front of the camera, a side wall 1.513 m to its left, the floor — the
//! walls' planes are found where they were built, the `walls` lattice puts a row of centres on them, the
//! `camera` lattice keeps multiples of the step, and a door set into the back wall is hit by the `walls`
//! window and missed by the `camera` one.

use cog_gpu::features::preprocess::Preprocessed;
use cog_gpu::features::scene::{grid_cells, rotate, wall_planes, LatticePhase, YawGrid};
use cog_gpu::features::{sliding_window, FeatureScene, WindowOptions};
use cog_gpu::geometry::{iou_3d, Camera, Cuboid};
use glam::{Mat3, Vec2, Vec3};

const FLOOR: f32 = -1.2;
const BACK_WALL_Y: f32 = 3.137;
const SIDE_WALL_X: f32 = -1.513;
const STEP: f32 = 0.2;

/// The door: 0.9 × 0.07 × 2.0 m, its centre 2 cm into the back wall (a recessed leaf and the frame
/// proud of the wall, as synth's doors), 0.5 m right of the camera.
fn door() -> Cuboid {
    Cuboid::new(Vec3::new(0.5, BACK_WALL_Y + 0.02, FLOOR + 1.0), Vec3::new(0.9, 0.07, 2.0), 0.0)
}

/// Points on a 2 cm grid: the back wall (normal −y, toward the camera) with the door's leaf 3 cm behind
/// its plane, the side wall (normal +x) and the floor (normal +z).
fn room() -> Preprocessed {
    let door = door();
    let mut points = Vec::new();
    let mut normals = Vec::new();
    for a in 0..200 {
        for c in 0..125 {
            let (x, z) = (SIDE_WALL_X + 0.02 * a as f32, FLOOR + 0.02 * c as f32);
            let in_door = (x - door.centre.x).abs() < 0.4 && z < FLOOR + 1.95;
            points.push(Vec3::new(x, if in_door { BACK_WALL_Y + 0.03 } else { BACK_WALL_Y }, z));
            normals.push(-Vec3::Y);
        }
    }
    for b in 0..150 {
        for c in 0..125 {
            points.push(Vec3::new(SIDE_WALL_X, 0.2 + 0.02 * b as f32, FLOOR + 0.02 * c as f32));
            normals.push(Vec3::X);
        }
    }
    for a in 0..100 {
        for b in 0..75 {
            points.push(Vec3::new(SIDE_WALL_X + 0.04 * a as f32, 0.2 + 0.04 * b as f32, FLOOR));
            normals.push(Vec3::Z);
        }
    }
    let gradients = vec![Vec2::ZERO; points.len()];
    let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
    Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: FLOOR }
}

fn rotated(pre: &Preprocessed, yaw: f32) -> Vec<[f32; 2]> {
    let (sin, cos) = yaw.sin_cos();
    pre.points.iter().map(|p| rotate(p, sin, cos)).collect()
}

/// Distance of `x` from the nearest centre `origin + (k + ½)·step`.
fn off_lattice(x: f32, origin: f32, step: f32) -> f32 {
    let k = ((x - origin) / step - 0.5).round();
    (x - (origin + (k + 0.5) * step)).abs()
}

#[test]
fn the_walls_planes_are_found_where_they_were_built() {
    let pre = room();
    // Yaw 0: s = x, t = y; the back wall faces −t (behind a box facing the camera), the side wall ±s.
    let [s, t] = wall_planes(&pre, &rotated(&pre, 0.0), 0.0, 1.0);
    assert!((t.expect("back wall") - BACK_WALL_Y).abs() < 0.005, "t plane {t:?}");
    assert!((s.expect("side wall") - SIDE_WALL_X).abs() < 0.005, "s plane {s:?}");
    // Yaw π/2: s = y, t = −x; the side wall (normal +x) faces −t, the back wall ±s.
    let yaw = std::f32::consts::FRAC_PI_2;
    let (sin, cos) = yaw.sin_cos();
    let [s, t] = wall_planes(&pre, &rotated(&pre, yaw), sin, cos);
    assert!((t.expect("side wall behind") + SIDE_WALL_X).abs() < 0.005, "t plane {t:?}");
    assert!((s.expect("back wall beside") - BACK_WALL_Y).abs() < 0.005, "s plane {s:?}");
    // Yaw π: t = −y, the back wall faces +t (it would be in front of such a box): no plane along t.
    let yaw = std::f32::consts::PI;
    let (sin, cos) = yaw.sin_cos();
    let [_, t] = wall_planes(&pre, &rotated(&pre, yaw), sin, cos);
    assert_eq!(t, None);
}

#[test]
fn the_walls_lattice_puts_centres_on_the_walls_and_the_camera_lattice_does_not_move() {
    let pre = room();
    let walls = YawGrid::build_with(&pre, 0.0, STEP, LatticePhase::Walls);
    assert!(off_lattice(BACK_WALL_Y, walls.origin[1], STEP) < 0.005, "t origin {}", walls.origin[1]);
    assert!(off_lattice(SIDE_WALL_X, walls.origin[0], STEP) < 0.005, "s origin {}", walls.origin[0]);
    // The walls grid still holds every point (its origin at or below the lowest coordinate).
    assert_eq!(walls.records.len(), pre.points.len());
    let camera = YawGrid::build_with(&pre, 0.0, STEP, LatticePhase::Camera);
    let expected = grid_cells(cog_gpu::features::scene::extent(&rotated(&pre, 0.0)), STEP).0;
    assert_eq!(camera.origin, expected);
    assert_eq!(camera.origin, YawGrid::build(&pre, 0.0, STEP).origin);
    for axis in 0..2 {
        let multiple = camera.origin[axis] / STEP;
        assert!((multiple - multiple.round()).abs() < 1e-4, "camera origin {:?}", camera.origin);
    }
    // 3.137 is 0.037 from the camera lattice's nearest centre (3.1), and the side wall 0.013 (−1.5).
    assert!((off_lattice(BACK_WALL_Y, camera.origin[1], STEP) - 0.037).abs() < 1e-4);
}

#[test]
fn a_door_in_the_wall_is_hit_by_the_walls_window_only() {
    let door = door();
    let best_iou = |lattice: LatticePhase| -> f32 {
        let scene = FeatureScene::with_lattice(room(), &[0.0], STEP, lattice);
        let options = WindowOptions { sizes: vec![door.size], min_points: 20 };
        let set = sliding_window(&scene, &options);
        set.hypotheses.iter().map(|h| iou_3d(&h.cuboid(&scene), &door)).fold(0.0, f32::max)
    };
    // Walls: a centre row on the wall plane, 2 cm from the door's centre: depth overlap 5 of 9 cm, the
    // width and height exact (centres at 0.5 m along s: the side wall's phase, −1.513 + 0.2·k + ... is
    // 0.487; 1.3 cm off): IoU ≈ 0.05/0.09 · 0.887/0.913 ≈ 0.54.
    let walls = best_iou(LatticePhase::Walls);
    assert!(walls > 0.5, "walls lattice: best IoU {walls}");
    // Camera: the nearest centres are 3.1 and 3.3 m, 5.7 and 14.3 cm from the door's centre: at best
    // 1.3 of 7 cm of depth overlap, IoU ≈ 0.013/0.127 ≈ 0.10 — below the 0.25 of a detection.
    let camera = best_iou(LatticePhase::Camera);
    assert!(camera < 0.15, "camera lattice: best IoU {camera}");
}
