//! Orientation evidence: how well each of the [`ORIENTATIONS`] explains the frame's wall normals — shared
//! by the heuristic baseline (its orientation) and the learned model (three features per hypothesis).
//!
//! # Why the model has them (our addition to the paper's Manhattan-voxel features)
//! The voxel features see normals only through 30° classes ([`super::voxels::normal_class`]), so rooms
//! turned by 2–6° from each other have nearly the same features, and the first shipped model chose an
//! orientation 4–24° off the room on frames where the heuristic's normal alignment was right (validation
//! seed 13: 81.7 against 98.4 free-space IoU on one frame, 81.9 against 97.3 on another). The alignment
//! below is a property of the orientation alone, so it is the same for every hypothesis of one orientation:
//! a per-orientation term added to the voxel score ([`super::voxels::ScoringTables::total`]).
//!
//! # Definitions
//! - A **wall normal** is a unit normal with `|n_z| <` [`MAX_WALL_NORMAL_Z`]; `h` its horizontal part,
//!   normalised.
//! - The **alignment** of orientation `k` with power `p` is `Σ max(|h·a_k|, |h·b_k|)^p` over the wall normals
//!   (`a_k`, `b_k` the room axes). [`BROAD_POWER`] = 8 (the heuristic's; about 8 % less at 10° off an axis)
//!   and [`SHARP_POWER`] = 64 (about 4 % less at 2°, 15 % at 4°).
//! - The **features** of orientation `k` ([`ORIENTATION_FEATURES`] = 3): the broad alignment divided by its
//!   largest value over the orientations, the sharp alignment divided by its largest value, and 1 for the
//!   orientation of the largest broad alignment (the heuristic's choice; the first on ties) else 0. All 0
//!   when the frame has no wall normal.

use super::{room_axes, LayoutScene, ORIENTATIONS};

/// Normals with `|n_z|` below this are wall evidence.
pub const MAX_WALL_NORMAL_Z: f32 = 0.5;
/// Power of the heuristic's (broad) alignment.
pub const BROAD_POWER: i32 = 8;
/// Power of the sharp alignment.
pub const SHARP_POWER: i32 = 64;
/// Orientation features per hypothesis (the last entries of the layout feature vector).
pub const ORIENTATION_FEATURES: usize = 3;

/// The alignment of every orientation with power `power` (see the module doc), in orientation order.
pub fn alignment(scene: &LayoutScene, power: i32) -> Vec<f64> {
    let horizontal: Vec<_> = scene
        .normals
        .iter()
        .filter(|n| n.z.abs() < MAX_WALL_NORMAL_Z)
        .map(|n| n.truncate().normalize_or_zero())
        .collect();
    (0..ORIENTATIONS)
        .map(|k| {
            let (a, b) = room_axes(k);
            horizontal.iter().map(|h| (h.dot(a).abs().max(h.dot(b).abs()) as f64).powi(power)).sum()
        })
        .collect()
}

/// Index of the largest alignment (the first on ties, so deterministic).
pub fn dominant(alignment: &[f64]) -> usize {
    alignment.iter().enumerate().fold((0, f64::MIN), |best, (k, &s)| if s > best.1 { (k, s) } else { best }).0
}

/// The orientation features of every orientation (see the module doc), in orientation order.
pub fn orientation_features(scene: &LayoutScene) -> Vec<[f32; ORIENTATION_FEATURES]> {
    let broad = alignment(scene, BROAD_POWER);
    let sharp = alignment(scene, SHARP_POWER);
    let best = dominant(&broad);
    // Every wall normal adds a positive amount to every orientation's alignment, so the largest broad
    // alignment is 0 exactly when there is no wall normal, and then the sharp one is 0 too.
    let (broad_max, sharp_max) = (broad[best], sharp.iter().copied().fold(0.0, f64::max));
    if broad_max <= 0.0 || sharp_max <= 0.0 {
        return vec![[0.0; ORIENTATION_FEATURES]; ORIENTATIONS];
    }
    (0..ORIENTATIONS)
        .map(|k| [(broad[k] / broad_max) as f32, (sharp[k] / sharp_max) as f32, if k == best { 1.0 } else { 0.0 }])
        .collect()
}

/// Edge-orientation features per hypothesis when the model has them ([`super::voxels::Descriptor::edges`]).
pub const EDGE_FEATURES: usize = 2;
/// Image edges within this angle of the projected vertical are left out of the edge alignment (cos 20°):
/// vertical lines lie in every wall plane and say nothing about the yaw.
pub const VERTICAL_EDGE_COS: f32 = 0.939_692_6;

/// The **edge alignment** of every orientation with power `power` (see [`edge_orientation_features`]), in
/// orientation order: `Σ |g|·max(|ê·â(p)|, |ê·b̂(p)|)^power` over the points with a gradient `g` whose edge
/// direction `ê` (unit, perpendicular to `g` in the image) is not within 20° of the projected vertical, with
/// `â(p)`, `b̂(p)` the unit image directions of the room axes at the point — the directions towards the
/// orientation's two horizontal vanishing points.
pub fn edge_alignment(scene: &LayoutScene, power: i32) -> Vec<f64> {
    use crate::features::cpu::image_direction;
    let camera = &scene.camera;
    let up = camera.to_camera(glam::Vec3::Z);
    // (point in camera coordinates, unit edge direction, magnitude) of the usable gradients.
    let edges: Vec<(glam::Vec3, glam::Vec2, f32)> = scene
        .points
        .iter()
        .zip(&scene.gradients)
        .filter_map(|(&p, &g)| {
            let at = camera.to_camera(p);
            let magnitude = g.length();
            if at.z <= crate::geometry::MIN_PROJECT_DEPTH || magnitude == 0.0 {
                return None;
            }
            let edge = glam::Vec2::new(-g.y, g.x) / magnitude;
            let vertical = image_direction(camera.intrinsics, at, up).normalize_or_zero();
            (edge.dot(vertical).abs() < VERTICAL_EDGE_COS).then_some((at, edge, magnitude))
        })
        .collect();
    (0..ORIENTATIONS)
        .map(|k| {
            let (a, b) = room_axes(k);
            let (a, b) = (camera.to_camera(a.extend(0.0)), camera.to_camera(b.extend(0.0)));
            edges
                .iter()
                .map(|&(at, edge, magnitude)| {
                    let along = |d| edge.dot(image_direction(camera.intrinsics, at, d).normalize_or_zero()).abs();
                    magnitude as f64 * (along(a).max(along(b)) as f64).powi(power)
                })
                .sum()
        })
        .collect()
}

/// The edge-orientation features of every orientation, in orientation order (our addition, with COG's
/// projected room axes: the paper's layout model "utilizes our COG descriptor"): the edge alignment
/// ([`edge_alignment`]) with the powers [`BROAD_POWER`] and [`SHARP_POWER`], each divided by its largest
/// value over the orientations (all 0 when the frame has no usable gradient). The normal-based orientation
/// features see the walls' depth; these see the lines drawn on them and along them (skirting, shelves,
/// window frames, the wall–floor and wall–ceiling boundaries), which point at the room's vanishing points
/// — the classic cue of single-image layout estimation, here with the 3D axes projected at each point.
pub fn edge_orientation_features(scene: &LayoutScene) -> Vec<[f32; EDGE_FEATURES]> {
    let broad = edge_alignment(scene, BROAD_POWER);
    let sharp = edge_alignment(scene, SHARP_POWER);
    let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
    let (broad_max, sharp_max) = (max(&broad), max(&sharp));
    if broad_max <= 0.0 || sharp_max <= 0.0 {
        return vec![[0.0; EDGE_FEATURES]; ORIENTATIONS];
    }
    (0..ORIENTATIONS).map(|k| [(broad[k] / broad_max) as f32, (sharp[k] / sharp_max) as f32]).collect()
}
