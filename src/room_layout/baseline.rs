//! The plane-fitting heuristic baseline the learned layout is compared with (in the spirit of the SUN
//! RGB-D baseline, which fits planes to the point cloud without learning).
//!
//! Our heuristic (choices): the orientation is the one of the [`super::ORIENTATIONS`] whose axes best
//! explain the wall normals — the largest `Σ max(|n·a|, |n·b|)⁸` over points with a near-horizontal normal
//! (`|n_z| < 0.5`); the walls are at the 0.01 and 0.99 quantiles of the points' room-frame coordinates (the
//! extreme points, robust to a few outliers), each moved outward to contain the camera (the camera is in
//! the room); floor and ceiling are the frame's.

use super::voxels::CELL_MM;
use super::{orientation, room_axes, to_mm, LayoutScene, RoomBox};

/// Quantile of the room-frame coordinates that places the near walls (and `1 −` it the far ones).
pub const WALL_QUANTILE: f64 = 0.01;

/// Orientation whose axes best align with the near-horizontal normals ([`orientation::alignment`] with
/// [`orientation::BROAD_POWER`], the first maximum).
pub fn dominant_orientation(scene: &LayoutScene) -> usize {
    orientation::dominant(&orientation::alignment(scene, orientation::BROAD_POWER))
}

/// The heuristic room of a frame.
pub fn heuristic_layout(scene: &LayoutScene) -> RoomBox {
    let k = dominant_orientation(scene);
    let (a, b) = room_axes(k);
    let quantiles = |mut values: Vec<i32>| {
        values.sort_unstable();
        let at = |q: f64| values[(q * (values.len() - 1) as f64).round() as usize];
        (at(WALL_QUANTILE).min(0), at(1.0 - WALL_QUANTILE).max(0))
    };
    let (u0, u1) = quantiles(scene.points.iter().map(|p| to_mm(p.truncate().dot(a))).collect());
    let (v0, v1) = quantiles(scene.points.iter().map(|p| to_mm(p.truncate().dot(b))).collect());
    // A degenerate cloud (all points on a line) still gives a room with positive sides.
    RoomBox { yaw_index: k as u32, u0, u1: u1.max(u0 + CELL_MM), v0, v1: v1.max(v0 + CELL_MM) }
}
