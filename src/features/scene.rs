//! Per-yaw work shared by every hypothesis of that yaw: the points rotated into the yaw's frame, their
//! normal codes, and a bucket grid over the ground plane so a hypothesis finds its points without a pass
//! over the whole cloud.
//!
//! For yaw θ the rotated frame has coordinates `(s, t, z)` along `a = (cos θ, sin θ, 0)`,
//! `b = (−sin θ, cos θ, 0)` and z — the frame of [`crate::geometry::Cuboid::to_local`] for a cuboid of yaw θ
//! centred at the origin — so a hypothesis of that yaw is an axis-aligned box in it. Points are bucketed
//! into square ground cells of side `step` and stored cell by cell, rows (t) outer and columns (s) inner
//! ([`YawGrid::records`], [`YawGrid::cell_start`]): the points of the cells `s0..=s1` of one row are one
//! contiguous range. Within a cell the points keep the point cloud's order, so the layout is deterministic.
//!
//! The CPU computes all of this once per yaw (rotations, normal codes as integers, magnitudes) and both the
//! CPU and the GPU feature paths read the same records — which is what makes their integer counts equal.

use bytemuck::{Pod, Zeroable};
use glam::{DMat3, DVec3, Mat3, Vec3};
use rayon::prelude::*;

use super::preprocess::{gradient_magnitude, normal_bin, Preprocessed};

/// Fixed-point units per metre of [`PointRecord`] coordinates and hypothesis boxes (2¹⁶: 15 µm steps,
/// ±32 km range).
pub const FIXED_PER_METRE: f32 = 65536.0;

/// Metres → fixed point (rounded to nearest).
pub fn to_fixed(metres: f32) -> i32 {
    (metres * FIXED_PER_METRE).round() as i32
}

/// One point as the kernels read it (32 bytes; mirrors `PointRecord` in `shaders/features.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PointRecord {
    /// Rotated-frame coordinates (s, t) and height z in fixed point ([`FIXED_PER_METRE`] units): voxel
    /// membership is decided with integer arithmetic, so no compiler's float rewriting can make the CPU
    /// and the GPU put a point on different sides of a voxel face.
    pub s: i32,
    pub t: i32,
    pub z: i32,
    /// Normal code in this yaw's frame ([`normal_bin`]).
    pub normal_bin: u32,
    /// Image gradient (dx, dy) at the point's pixel and its magnitude.
    pub gx: f32,
    pub gy: f32,
    pub magnitude: f32,
    pub _pad: u32,
}

/// The points of one yaw, bucketed (see the module doc).
#[derive(Clone, Debug)]
pub struct YawGrid {
    pub yaw: f32,
    /// `sin θ`, `cos θ` (f32, from the f64 values) used for every rotation of this yaw.
    pub sin: f32,
    pub cos: f32,
    /// Ground-plane coordinates (s, t) of the corner of cell (0, 0).
    pub origin: [f32; 2],
    /// Cell side (metres) and its inverse.
    pub step: f32,
    pub inv_step: f32,
    /// Cells along s and t.
    pub cells: [u32; 2],
    /// `cell_start[r·cells[0] + c]` is the first record of cell (c, r); one extra entry at the end.
    pub cell_start: Vec<u32>,
    pub records: Vec<PointRecord>,
    /// Camera coordinates (x right, y down, z forward) of a rotated-frame point `q` are
    /// `camera_from_rotated · q` (the camera is at the origin).
    pub camera_from_rotated: Mat3,
}

impl PointRecord {
    /// Height in metres.
    pub fn z_metres(&self) -> f32 {
        self.z as f32 / FIXED_PER_METRE
    }
}

impl YawGrid {
    /// Rotates, codes and buckets the points for yaw `yaw` with ground cells of side `step`.
    pub fn build(pre: &Preprocessed, yaw: f32, step: f32) -> YawGrid {
        let (sin64, cos64) = (yaw as f64).sin_cos();
        let (sin, cos) = (sin64 as f32, cos64 as f32);
        let inv_step = 1.0 / step;
        let rotated: Vec<[f32; 2]> = pre.points.par_iter().map(|p| rotate(p, sin, cos)).collect();
        let (origin, cells) = grid_cells(extent(&rotated), step);
        // `cells` fit in u32 for any scene that passed `features::budget` (whose limit is far below 2³²
        // cells); index arithmetic is in usize so that no product can wrap.
        let cells = cells.map(|c| c.min(u32::MAX as f64) as u32);
        let cell_of = |r: &[f32; 2]| -> usize {
            let c = [0, 1].map(|a| (((r[a] - origin[a]) * inv_step).floor().max(0.0) as u32).min(cells[a] - 1));
            c[1] as usize * cells[0] as usize + c[0] as usize
        };
        // Counting sort by cell keeps the cloud order inside each cell.
        let cell_count = cells[0] as usize * cells[1] as usize;
        let mut cell_start = vec![0u32; cell_count + 1];
        let point_cells: Vec<usize> = rotated.iter().map(cell_of).collect();
        for &c in &point_cells {
            cell_start[c + 1] += 1;
        }
        for c in 0..cell_count {
            cell_start[c + 1] += cell_start[c];
        }
        let mut next = cell_start.clone();
        let mut records = vec![PointRecord::default(); rotated.len()];
        for (index, &c) in point_cells.iter().enumerate() {
            let n = pre.normals[index];
            let local = Vec3::new(n.x * cos + n.y * sin, -n.x * sin + n.y * cos, n.z);
            let g = pre.gradients[index];
            records[next[c] as usize] = PointRecord {
                s: to_fixed(rotated[index][0]),
                t: to_fixed(rotated[index][1]),
                z: to_fixed(pre.points[index].z),
                normal_bin: normal_bin(local),
                gx: g.x,
                gy: g.y,
                magnitude: gradient_magnitude(g),
                _pad: 0,
            };
            next[c] += 1;
        }
        YawGrid {
            yaw,
            sin,
            cos,
            origin,
            step,
            inv_step,
            cells,
            cell_start,
            records,
            camera_from_rotated: camera_from_rotated(pre, sin64, cos64),
        }
    }

    /// Inclusive range of cell indices along axis `axis` (0 = s, 1 = t) that holds every point with
    /// coordinate in `[lo, hi]`, widened by 0.1 mm so rounding in the bucketing can never drop a point;
    /// `None` when the range misses the grid.
    pub fn cell_range(&self, axis: usize, lo: f32, hi: f32) -> Option<(u32, u32)> {
        const MARGIN: f32 = 1e-4;
        let first = ((lo - MARGIN - self.origin[axis]) * self.inv_step).floor();
        let last = ((hi + MARGIN - self.origin[axis]) * self.inv_step).floor();
        let n = self.cells[axis] as f32;
        if last < 0.0 || first >= n {
            return None;
        }
        Some((first.max(0.0) as u32, last.min(n - 1.0) as u32))
    }

    /// Record range of the cells `s_cells.0..=s_cells.1` in row `row`.
    pub fn row_span(&self, row: u32, s_cells: (u32, u32)) -> std::ops::Range<usize> {
        let base = row as usize * self.cells[0] as usize;
        self.cell_start[base + s_cells.0 as usize] as usize..self.cell_start[base + s_cells.1 as usize + 1] as usize
    }

    /// Upright coordinates of a rotated-frame point.
    pub fn to_upright(&self, q: Vec3) -> Vec3 {
        Vec3::new(q.x * self.cos - q.y * self.sin, q.x * self.sin + q.y * self.cos, q.z)
    }
}

/// Rotated-frame ground coordinates (s, t) of an upright point for a yaw with `sin θ`, `cos θ`.
pub fn rotate(p: &Vec3, sin: f32, cos: f32) -> [f32; 2] {
    [p.x * cos + p.y * sin, -p.x * sin + p.y * cos]
}

/// Component-wise minimum and maximum of ground coordinates (both 0 when there are none).
pub fn extent(coordinates: &[[f32; 2]]) -> ([f32; 2], [f32; 2]) {
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for r in coordinates {
        for a in 0..2 {
            lo[a] = lo[a].min(r[a]);
            hi[a] = hi[a].max(r[a]);
        }
    }
    if coordinates.is_empty() {
        (lo, hi) = ([0.0; 2], [0.0; 2]);
    }
    (lo, hi)
}

/// The origin and the number of cells along s and t of a bucket grid of side `step` over the extent
/// `(lo, hi)`. The counts are floats so that an absurd extent cannot overflow before it is checked.
pub fn grid_cells((lo, hi): ([f32; 2], [f32; 2]), step: f32) -> ([f32; 2], [f64; 2]) {
    let inv_step = 1.0 / step;
    let origin = lo.map(|v| (v * inv_step).floor() * step);
    let cells = [0, 1].map(|a| (((hi[a] - origin[a]) * inv_step).floor() as f64 + 1.0).max(1.0));
    (origin, cells)
}

/// `C·R(θ)` where `R(θ)` takes rotated-frame coordinates to upright ones and `C` upright ones to the camera's
/// (x right, y down, z forward): `C·p = (c.x, −c.z, c.y)` with `c = Rtiltᵀ·p` (as
/// [`crate::geometry::Camera::to_camera`]). Double precision, rounded once.
fn camera_from_rotated(pre: &Preprocessed, sin: f64, cos: f64) -> Mat3 {
    let rotation = DMat3::from_cols(DVec3::new(cos, sin, 0.0), DVec3::new(-sin, cos, 0.0), DVec3::Z);
    let swap = DMat3::from_cols(DVec3::X, DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, -1.0, 0.0));
    (swap * pre.camera.rtilt.as_dmat3().transpose() * rotation).as_mat3()
}

/// A preprocessed frame with the yaw grids of a set of yaws: everything the feature paths read.
#[derive(Clone, Debug)]
pub struct FeatureScene {
    pub pre: Preprocessed,
    pub yaws: Vec<YawGrid>,
}

impl FeatureScene {
    /// Builds the yaw grids for `yaws` with ground cells of side `step` (metres).
    pub fn new(pre: Preprocessed, yaws: &[f32], step: f32) -> FeatureScene {
        let grids = yaws.iter().map(|&yaw| YawGrid::build(&pre, yaw, step)).collect();
        FeatureScene { pre, yaws: grids }
    }

    /// The angles of the yaw grids, in order.
    pub fn yaw_angles(&self) -> Vec<f32> {
        self.yaws.iter().map(|g| g.yaw).collect()
    }
}
