//! Room layout (paper §5): the room as a Manhattan cuboid — four walls at right angles, floor and ceiling —
//! predicted from one RGB-D frame by scoring many cuboid hypotheses with "Manhattan voxel" features and a
//! structural-SVM weight vector.
//!
//! Flow: [`LayoutScene::from_frame`] (a subsampled upright point cloud with normals, floor and ceiling) →
//! [`hypotheses`] (cuboids per orientation) → [`voxels::YawCells`] (the points binned once per orientation,
//! with the orientation's [`orientation`] features)
//! → [`voxels::scores_cpu`] or the GPU twin `crate::gpu::room_layout` (chosen by the caller, see
//! [`predict`]) → the best hypothesis. Evaluation:
//! [`free_space`]; learning: [`learn`]; the model file: [`model`]; the plane-fitting baseline: [`baseline`].
//!
//! # Choices where the paper is terse (one place, used everywhere)
//! - **Points**: the frame's point cloud subsampled on the pixel grid (every `s`-th column and row, the
//!   smallest `s` giving at most [`MAX_LAYOUT_POINTS`]); walls are large, so a few thousand points place them
//!   as well as 300 000 and the normals (15 nearest neighbours, as the detector) cost milliseconds.
//! - **Floor and ceiling**: the 0.001 and 0.999 quantiles of all point heights (paper), shared by every
//!   hypothesis of the frame — except that a camera pitched down often sees no ceiling at all, and the
//!   0.999 quantile is then the top of the visible walls, far below the ceiling. When the points reach less
//!   than [`MIN_ROOM_HEIGHT`] above the floor, the ceiling is put at floor + [`MIN_ROOM_HEIGHT`] (rooms are
//!   at least that high; our deviation from the paper, which loses the free space above the visible walls).
//!   Then each snaps to its plane ([`snap_floor_and_ceiling`]): the median height of the horizontal points
//!   (normal within 30° of vertical, facing into the room) within [`SNAP_BAND_M`] of the quantile, when
//!   there are at least [`SNAP_MIN_POINTS`] of them (our addition: the 0.001 quantile is the lower tail of
//!   the floor's depth noise, 1.4 cm below the annotated floor at the median of the training frames (seed
//!   11), and free-space IoU on 0.1 m voxels loses a whole layer of the visible floor when a voxel centre
//!   falls in between — 0.75 points of the annotated footprint's own IoU on those frames, 98.39 → 99.14).
//! - **Orientations**: a rectangle turned by 90° is the same rectangle, so the paper's 18 orientations in
//!   [0°, 180°) are only 9 distinct rooms. We keep 45 *distinct* ones: yaws `−44° + 2°·k`, k = 0..44, i.e.
//!   [−44°, 44°] in 2° steps, evenly spaced modulo 90° and including 0° (walls square to the camera's
//!   heading). A room is then at most 1° from an orientation: on the validation frames (seed 13) the
//!   first version's 18 orientations in 5° steps left the best hypothesis at mean free-space IoU 95.7 for
//!   rooms within 1° of an orientation and 89.6 for rooms 2–2.5° from one; 2° steps (measured with yaws
//!   `−45° + 2°·k`, before the grid was shifted by 1° to include 0°) raised the mean of the best hypothesis
//!   from 93.4 to 94.5 and the learned model's (C = 10 000) from 90.8 to 91.1. The yaw is measured from the upright +x axis; the room's own axes are
//!   `a = (cos φ, sin φ)` and `b = (−sin φ, cos φ)`, so `b` is the axis closest to the camera's forward
//!   direction (+y upright) and the walls are named from the camera: wall 0 **front** (`v = v1`, outward
//!   normal +b), 1 **left** (`u = u0`, −a), 2 **back** (`v = v0`, −b, usually behind the camera), 3
//!   **right** (`u = u1`, +a). Features are indexed by these names, so they mean the same for every yaw.
//! - **Wall positions** (paper: "capture at least 80 % of all 3D points, bounded by the farthest and
//!   closest points"): in the room frame `(u, v)` in integer millimetres, each wall's candidates are (i) the
//!   farthest point on its side, (ii) the [`PEAKS_PER_WALL`] strongest local maxima of the 5 cm histogram of
//!   points whose normal faces that wall (planes show as peaks), searched between the farthest point and the
//!   0.2 quantile (a wall closer than that would leave more than 20 % of the points outside), and (iii) the
//!   camera's own coordinate when the camera lies beyond the farthest point (the camera is in the room; the
//!   wall behind it is never seen), and (iv) for the front wall — the one the camera faces — the positions
//!   [`REACH_STEPS_MM`] = 0.5, 1 and 2 m beyond the farthest point (our addition: the paper bounds the walls
//!   by the farthest point, but a depth sensor stops at 4.5–7.5 m and a large room's far wall returns no
//!   depth, while free-space IoU counts the whole room inside the view; on the validation frames (seed 13)
//!   the best hypothesis's mean free-space IoU goes 94.9 → 96.9 with them, and the hypotheses per frame
//!   from a mean of 434 to 871. Reaching with the left and right walls too gave 97.8 with 6 523 hypotheses,
//!   but a model trained with them chose side walls beyond the points where they are out of view — free for
//!   the loss — and scored 92.49 against 92.85 without any reach. The box features' *reach* (see
//!   [`voxels`]) tells the model how far beyond the points the front wall lies and whether the sensor saw
//!   the plane of the farthest points ([`voxels::front_plane_evidence`], from the rays of the pixels
//!   without depth, [`LayoutScene::missing_rays`]): the reach alone, without that evidence, did not help
//!   (92.69), with it the validation mean rose to 93.85). All combinations with sides ≥ [`MIN_SIDE_MM`] that contain the camera
//!   (our addition: the camera is in the room; without it the learned model sometimes put the unseen back
//!   wall in front of the camera) and whose cuboid holds ≥ 80 % of the points (cell centres, see
//!   [`voxels`]) are kept.
//! - **Positions are integers** (millimetres in the room frame of each yaw), so that region assignment is
//!   exact and identical on the CPU and the GPU.

pub mod baseline;
pub mod free_space;
pub mod learn;
pub mod model;
pub mod orientation;
pub mod output;
pub mod voxels;

use glam::{Vec2, Vec3};

use crate::error::{Error, Result};
use crate::features::preprocess::{estimate_normals, pixel_gradient, NORMAL_NEIGHBOURS};
use crate::frame::{quantile_of_unsorted, Frame, RoomLayout};
use crate::geometry::Camera;

/// Most points the layout uses (see the module doc: pixel-grid subsampling).
pub const MAX_LAYOUT_POINTS: usize = 16_000;
/// Floor at this quantile of the point heights (paper §5).
pub const FLOOR_QUANTILE: f32 = 0.001;
/// Ceiling at this quantile of the point heights (paper §5).
pub const CEILING_QUANTILE: f32 = 0.999;
/// Least floor-to-ceiling height of a room (metres); see the module doc.
pub const MIN_ROOM_HEIGHT: f32 = 2.4;
/// Floor and ceiling snap to the horizontal points within this distance (metres) of their quantiles.
pub const SNAP_BAND_M: f32 = 0.1;
/// Fewest such points (of the subsampled cloud) for a snap; fewer keep the quantile.
pub const SNAP_MIN_POINTS: usize = 20;
/// Number of distinct orientations (see the module doc).
pub const ORIENTATIONS: usize = 45;
/// First orientation (degrees) and step between orientations.
pub const FIRST_YAW_DEG: f32 = -44.0;
pub const YAW_STEP_DEG: f32 = 2.0;
/// A hypothesis must hold at least this fraction of the points (paper §5).
pub const MIN_INSIDE_FRACTION: f64 = 0.8;
/// Histogram peaks kept as wall candidates per wall (besides the farthest point and the camera).
pub const PEAKS_PER_WALL: usize = 8;
/// Smallest room side, millimetres.
pub const MIN_SIDE_MM: i32 = 1000;
/// Front-wall candidates beyond the farthest point (millimetres past it; see the module doc).
pub const REACH_STEPS_MM: [i32; 3] = [500, 1000, 2000];

/// Yaw (radians) of orientation `k`.
pub fn orientation_yaw(k: usize) -> f32 {
    (FIRST_YAW_DEG + YAW_STEP_DEG * k as f32).to_radians()
}

/// The room frame's axes `(a, b)` of orientation `k` (see the module doc).
pub fn room_axes(k: usize) -> (Vec2, Vec2) {
    let (s, c) = orientation_yaw(k).sin_cos();
    (Vec2::new(c, s), Vec2::new(-s, c))
}

/// Integer millimetres of a coordinate in metres (rounded to nearest).
pub fn to_mm(metres: f32) -> i32 {
    (metres * 1000.0).round() as i32
}

/// One room hypothesis: orientation `yaw_index` and the four wall positions in that orientation's room
/// frame (`u` along `a`, `v` along `b`, millimetres); `u0 < u1`, `v0 < v1`. Floor and ceiling are the
/// frame's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct RoomBox {
    pub yaw_index: u32,
    pub u0: i32,
    pub u1: i32,
    pub v0: i32,
    pub v1: i32,
}

impl RoomBox {
    pub fn yaw(&self) -> f32 {
        orientation_yaw(self.yaw_index as usize)
    }

    /// Floor corners (upright x, y), counter-clockwise seen from above, starting at (u0, v0).
    pub fn corners(&self) -> [Vec2; 4] {
        let (a, b) = room_axes(self.yaw_index as usize);
        let at = |u: i32, v: i32| a * (u as f32 / 1000.0) + b * (v as f32 / 1000.0);
        [at(self.u0, self.v0), at(self.u1, self.v0), at(self.u1, self.v1), at(self.u0, self.v1)]
    }

    /// The room annotation this hypothesis stands for, between `floor` and `ceiling`.
    pub fn to_room(&self, floor: f32, ceiling: f32) -> RoomLayout {
        RoomLayout { corners: self.corners().to_vec(), floor, ceiling }
    }
}

/// What the layout reads of a frame (see the module doc for the choices).
#[derive(Clone, Debug)]
pub struct LayoutScene {
    pub camera: Camera,
    /// (width, height) in pixels.
    pub image_size: [u32; 2],
    /// Subsampled upright points and their unit normals.
    pub points: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// Image gradient (dx, dy) at each point's pixel ([`crate::features::preprocess::pixel_gradient`]): the
    /// COG features' input.
    pub gradients: Vec<Vec2>,
    /// Height quantiles of all the frame's points.
    pub floor: f32,
    pub ceiling: f32,
    /// Pixel stride of the subsampling.
    pub stride: u32,
    /// Upright directions (from the camera, the origin) of the subsampled pixels that returned **no depth**
    /// (the same pixel grid as `points`): the evidence that the sensor saw nothing within its range along
    /// them ([`voxels::front_plane_evidence`]). Not unit length (any positive multiple of the ray).
    pub missing_rays: Vec<Vec3>,
}

impl LayoutScene {
    /// Reads the layout's view of a frame. Fails (naming the frame) without enough depth, or when the
    /// points have no height extent.
    pub fn from_frame(frame: &Frame) -> Result<LayoutScene> {
        let cloud = frame.point_cloud();
        let mut heights: Vec<f32> = cloud.points.iter().map(|p| p.z).collect();
        let (floor, ceiling) = match (
            quantile_of_unsorted(&mut heights, FLOOR_QUANTILE),
            quantile_of_unsorted(&mut heights, CEILING_QUANTILE),
        ) {
            (Some(f), Some(c)) => (f, c),
            _ => return Err(Error::Input(format!("frame '{}' has no points with depth", frame.name))),
        };
        let stride = subsampling_stride(cloud.len());
        let keep: Vec<usize> = (0..cloud.len())
            .filter(|&i| {
                let [col, row] = cloud.pixels[i];
                col % stride == 0 && row % stride == 0
            })
            .collect();
        let points: Vec<Vec3> = keep.iter().map(|&i| cloud.points[i]).collect();
        let gradients: Vec<Vec2> = keep
            .iter()
            .map(|&i| {
                let [col, row] = cloud.pixels[i];
                pixel_gradient(&frame.rgb, col, row)
            })
            .collect();
        if points.len() < NORMAL_NEIGHBOURS {
            return Err(Error::NoRoom(format!(
                "frame '{}': {} points (subsampled); the room layout needs at least {NORMAL_NEIGHBOURS}",
                frame.name,
                points.len(),
            )));
        }
        let normals = estimate_normals(&points);
        let (floor, ceiling) = snap_floor_and_ceiling(&points, &normals, floor, ceiling);
        let camera = Camera::new(frame.intrinsics(), frame.rtilt());
        let missing_rays = missing_rays(frame, stride);
        Ok(LayoutScene {
            camera,
            image_size: [frame.width(), frame.height()],
            points,
            normals,
            gradients,
            floor,
            ceiling,
            stride,
            missing_rays,
        })
    }
}

/// Upright directions of the pixels on the subsampling grid (every `stride`-th column and row, as the points)
/// whose depth is missing: [`Frame::upright_point`] at depth 1, the back-projection of
/// [`Frame::point_cloud`].
pub fn missing_rays(frame: &Frame, stride: u32) -> Vec<Vec3> {
    let (w, h) = (frame.width(), frame.height());
    let rtilt = frame.rtilt_f64();
    let mut out = Vec::new();
    for row in (0..h).step_by(stride as usize) {
        for col in (0..w).step_by(stride as usize) {
            if frame.depth_mm[(row * w + col) as usize] == 0 {
                out.push(frame.upright_point(&rtilt, col, row, 1.0).as_vec3());
            }
        }
    }
    out
}

/// Floor and ceiling from their height quantiles `(floor_q, ceiling_q)` and the subsampled points with
/// their normals (see the module doc): each snaps to the median height of the horizontal points facing
/// into the room within [`SNAP_BAND_M`] of its quantile (at least [`SNAP_MIN_POINTS`] of them), and the
/// ceiling, when it is not seen (its quantile less than [`MIN_ROOM_HEIGHT`] above the floor), is put at
/// floor + [`MIN_ROOM_HEIGHT`].
pub fn snap_floor_and_ceiling(points: &[Vec3], normals: &[Vec3], floor_q: f32, ceiling_q: f32) -> (f32, f32) {
    let horizontal = voxels::AXIS_COS;
    let median_height = |keep: &dyn Fn(Vec3, Vec3) -> bool| -> Option<f32> {
        let mut heights: Vec<f32> =
            points.iter().zip(normals).filter(|(&p, &n)| keep(p, n)).map(|(p, _)| p.z).collect();
        if heights.len() < SNAP_MIN_POINTS {
            return None;
        }
        quantile_of_unsorted(&mut heights, 0.5)
    };
    let floor =
        median_height(&|p, n| n.z >= horizontal && p.z >= floor_q && p.z <= floor_q + SNAP_BAND_M).unwrap_or(floor_q);
    if ceiling_q < floor + MIN_ROOM_HEIGHT {
        return (floor, floor + MIN_ROOM_HEIGHT);
    }
    let ceiling = median_height(&|p, n| n.z <= -horizontal && p.z <= ceiling_q && p.z >= ceiling_q - SNAP_BAND_M)
        .unwrap_or(ceiling_q);
    (floor, ceiling.max(floor + MIN_ROOM_HEIGHT))
}

/// Smallest pixel stride `s` with `n / s² ≤ MAX_LAYOUT_POINTS`.
pub fn subsampling_stride(n: usize) -> u32 {
    let mut s = 1u32;
    while n / (s as usize * s as usize) > MAX_LAYOUT_POINTS {
        s += 1;
    }
    s
}

/// A predicted room: the chosen hypothesis, its room polygon and its score.
#[derive(Clone, Debug)]
pub struct PredictedLayout {
    pub room_box: RoomBox,
    pub room: RoomLayout,
    pub score: f64,
    /// Number of hypotheses scored.
    pub hypotheses: usize,
}

/// Wall candidates of one side in one orientation, ascending, deduplicated; `reach` adds those beyond the
/// farthest point ([`REACH_STEPS_MM`]).
fn wall_candidates(
    coords: &[i32],
    facing: &[bool],
    low_side: bool,
    reach: bool,
    camera_mm: i32,
    cell_mm: i32,
) -> Vec<i32> {
    let mut sorted = coords.to_vec();
    sorted.sort_unstable();
    let n = sorted.len();
    // The farthest point, moved outward to its cell's edge so that its cell centre is inside the wall.
    let farthest = if low_side {
        sorted[0].div_euclid(cell_mm) * cell_mm
    } else {
        (sorted[n - 1].div_euclid(cell_mm) + 1) * cell_mm
    };
    let limit_index = ((1.0 - MIN_INSIDE_FRACTION) * (n - 1) as f64).round() as usize;
    let limit = if low_side { sorted[limit_index] } else { sorted[n - 1 - limit_index] };
    let (lo, hi) = if low_side { (farthest, limit) } else { (limit, farthest) };
    // Histogram over cells (cell centres at `cell_index·cell_mm + cell_mm/2` from `lo` rounded down).
    let origin = lo.div_euclid(cell_mm) * cell_mm;
    let bins = ((hi - origin).div_euclid(cell_mm) + 1).max(1) as usize;
    let mut histogram = vec![0u32; bins];
    for (&c, &f) in coords.iter().zip(facing) {
        if f && c >= lo && c <= hi {
            histogram[((c - origin).div_euclid(cell_mm)) as usize] += 1;
        }
    }
    let min_count = (n / 500).max(3) as u32;
    let mut peaks: Vec<(u32, usize)> = (0..bins)
        .filter(|&i| {
            let h = histogram[i];
            h >= min_count && (i == 0 || histogram[i - 1] <= h) && (i + 1 == bins || histogram[i + 1] < h)
        })
        .map(|i| (histogram[i], i))
        .collect();
    // Strongest first; ties by position so the order never depends on anything else.
    peaks.sort_unstable_by(|x, y| y.0.cmp(&x.0).then(x.1.cmp(&y.1)));
    let mut out: Vec<i32> =
        peaks.iter().take(PEAKS_PER_WALL).map(|&(_, i)| origin + i as i32 * cell_mm + cell_mm / 2).collect();
    out.push(farthest);
    if reach {
        out.extend(REACH_STEPS_MM.iter().map(|&step| if low_side { farthest - step } else { farthest + step }));
    }
    let camera_beyond = if low_side { camera_mm < farthest } else { camera_mm > farthest };
    if camera_beyond {
        out.push(camera_mm);
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// The hypotheses of one orientation (see the module doc), given the binned points of that orientation.
pub fn orientation_hypotheses(scene: &LayoutScene, cells: &voxels::YawCells) -> Vec<RoomBox> {
    let k = cells.yaw_index as usize;
    let (a, b) = room_axes(k);
    let us: Vec<i32> = scene.points.iter().map(|p| to_mm(p.truncate().dot(a))).collect();
    let vs: Vec<i32> = scene.points.iter().map(|p| to_mm(p.truncate().dot(b))).collect();
    let faces_a: Vec<bool> = scene.normals.iter().map(|n| voxels::normal_class(*n, a, b) == voxels::ALONG_A).collect();
    let faces_b: Vec<bool> = scene.normals.iter().map(|n| voxels::normal_class(*n, a, b) == voxels::ALONG_B).collect();
    let cell = voxels::CELL_MM;
    // Only the front wall (v1), the one the camera faces, reaches beyond the points (see the module doc).
    let u0s = wall_candidates(&us, &faces_a, true, false, 0, cell);
    let u1s = wall_candidates(&us, &faces_a, false, false, 0, cell);
    let v0s = wall_candidates(&vs, &faces_b, true, false, 0, cell);
    let v1s = wall_candidates(&vs, &faces_b, false, true, 0, cell);
    let needed = (MIN_INSIDE_FRACTION * cells.total_points as f64).ceil() as u64;
    let mut out = Vec::new();
    // The camera (the origin) is inside every hypothesis.
    for &u0 in u0s.iter().filter(|&&u0| u0 <= 0) {
        for &u1 in u1s.iter().filter(|&&u1| u1 >= 0 && u1 - u0 >= MIN_SIDE_MM) {
            for &v0 in v0s.iter().filter(|&&v0| v0 <= 0) {
                for &v1 in v1s.iter().filter(|&&v1| v1 >= 0 && v1 - v0 >= MIN_SIDE_MM) {
                    let room_box = RoomBox { yaw_index: k as u32, u0, u1, v0, v1 };
                    if cells.points_inside(&room_box) >= needed {
                        out.push(room_box);
                    }
                }
            }
        }
    }
    out
}

/// Every orientation's binned points (with its orientation features, and with the points' COG contributions
/// when `cog`) and hypotheses, orientation by orientation.
/// `edges` adds the edge-orientation features ([`orientation::edge_orientation_features`]).
pub fn hypotheses(scene: &LayoutScene, cog: bool, edges: bool) -> (Vec<voxels::YawCells>, Vec<RoomBox>) {
    use rayon::prelude::*;
    let per_yaw: Vec<(voxels::YawCells, Vec<RoomBox>)> = (0..ORIENTATIONS)
        .into_par_iter()
        .map(|k| {
            let cells = voxels::YawCells::new(scene, k, cog);
            let boxes = orientation_hypotheses(scene, &cells);
            (cells, boxes)
        })
        .collect();
    let evidence = orientation::orientation_features(scene);
    let edge_evidence = if edges {
        orientation::edge_orientation_features(scene)
    } else {
        vec![[0.0; orientation::EDGE_FEATURES]; ORIENTATIONS]
    };
    let mut all_cells = Vec::with_capacity(ORIENTATIONS);
    let mut all_boxes = Vec::new();
    for (((mut cells, boxes), features), edge_features) in per_yaw.into_iter().zip(evidence).zip(edge_evidence) {
        cells.orientation = features;
        cells.edge_orientation = edge_features;
        all_cells.push(cells);
        all_boxes.extend(boxes);
    }
    (all_cells, all_boxes)
}

/// The integer scores of every hypothesis (one per box, in order), given the frame's binned points and the
/// model's tables: [`voxels::scores_cpu`], or its GPU twin through `crate::backend::Backend::layout_scores`.
/// `predict` takes the scorer as an argument so that this module, which the GPU kernel's module imports for
/// its data, imports neither `gpu` nor `backend` (imports flow one way: `room_layout` → `gpu` → `backend`).
pub type ScoreHypotheses<'a> = dyn Fn(&[voxels::YawCells], &voxels::ScoringTables, &[RoomBox]) -> Result<Vec<i32>> + 'a;

/// Scores every hypothesis of a frame with a model's weights — the voxel part through `score_hypotheses`,
/// plus the box features' term ([`voxels::ScoringTables::total`]) — and returns the best (the first of the
/// highest integer score, so the answer is the same on every backend).
pub fn predict(
    scene: &LayoutScene,
    model: &model::LayoutModel,
    score_hypotheses: &ScoreHypotheses,
) -> Result<PredictedLayout> {
    let descriptor = model.descriptor;
    let (cells, boxes) = hypotheses(scene, descriptor.cog, descriptor.edges);
    if boxes.is_empty() {
        return Err(Error::NoRoom(format!(
            "no room hypothesis: no box with sides of at least {} m around the camera holds {:.0} % of the \
             points (a view from close to a wall, whose points span less than that)",
            MIN_SIDE_MM as f64 / 1000.0,
            100.0 * MIN_INSIDE_FRACTION
        )));
    }
    let tables = voxels::ScoringTables::new(descriptor, &cells, &model.weights_f64());
    let scores = score_hypotheses(&cells, &tables, &boxes)?;
    if scores.len() != boxes.len() {
        return Err(Error::Input(format!("{} layout scores for {} hypotheses", scores.len(), boxes.len())));
    }
    let totals = tables.totals(&cells, &boxes, &scores);
    let best = (0..boxes.len()).fold(0, |best, i| if totals[i] > totals[best] { i } else { best });
    let room_box = boxes[best];
    Ok(PredictedLayout {
        room_box,
        room: room_box.to_room(scene.floor, scene.ceiling),
        score: totals[best] as f64 / tables.scale,
        hypotheses: boxes.len(),
    })
}

/// The heuristic baseline's room ([`baseline`]), with score 0.
pub fn predict_heuristic(scene: &LayoutScene) -> PredictedLayout {
    let room_box = baseline::heuristic_layout(scene);
    PredictedLayout { room_box, room: room_box.to_room(scene.floor, scene.ceiling), score: 0.0, hypotheses: 1 }
}
