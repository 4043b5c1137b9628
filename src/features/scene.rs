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
//! # Where the lattice starts ([`LatticePhase`])
//! Hypothesis centres sit at `origin + (c + ½)·step` along s and t. With [`LatticePhase::Camera`] (what every
//! model file without a `"lattice"` was trained with) the origin is a multiple of the step from the camera,
//! so a wall falls anywhere between two centres. Things stand against walls — doors in them, bookshelves,
//! dressers, beds and nightstands flush with them — and a centre up to half a step off a thin object's
//! plane misses it: a 9 cm door is hit at IoU ≥ 0.25 only when a centre lies within about 4 cm of its
//! plane, which a 0.2 m step gives for under half of the doors. With [`LatticePhase::Walls`] each yaw puts a
//! row of centres on a wall seen in its frame ([`wall_phase`]): along t (the depth axis; a box's front faces
//! −t) on the wall that would stand *behind* a box of this yaw — the strongest plane of points whose normal
//! faces −t —, along s on the strongest plane of points facing ±s (a side wall). A flush box of depth `d`
//! then has its centre `d/2` from a centre row, exact for `d` a multiple of twice the step, and a slab in
//! the wall (a door) is on a row. Yaws that see no such plane keep the camera phase along that axis. The
//! window's cells, the surface window's and free window's centres and the fast path's lattice all follow
//! `origin`, so they move together.
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

/// `x.floor() as i64`, without the call: on baseline x86-64 (no SSE4.1) `f32::floor` is a libm call, and
/// the sliding window, the lattices and the tables take the floor of millions of cell positions per frame
/// (7 % of a detection's profile samples were in `floorf` and `ceilf`). Equal to `x.floor() as i64` for every
/// f32, NaN (0) and infinities (saturated) included: truncation toward zero is the floor except for a
/// negative non-integer, and `t as f32` is exact wherever `x` has a fractional part (`|x| < 2²⁴`).
#[inline]
pub fn floor_to_i64(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// `x.ceil() as i64` for every f32, without the call (see [`floor_to_i64`]).
#[inline]
pub fn ceil_to_i64(x: f32) -> i64 {
    let t = x as i64;
    if (t as f32) < x {
        t.saturating_add(1)
    } else {
        t
    }
}

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

/// Where the per-yaw lattice of hypothesis centres starts (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LatticePhase {
    /// Multiples of the step from the camera. What model files without a `"lattice"` were trained with.
    #[default]
    Camera,
    /// A row of centres on the walls seen in each yaw's frame ([`wall_phase`]).
    Walls,
}

/// `cos 30°`: a normal within 30° of an axis faces along it (as the room layout's normal classes).
pub const WALL_NORMAL_COS: f32 = 0.866_025_4;
/// Histogram bin of [`wall_phase`] (metres); a plane is the best window of three bins.
pub const WALL_BIN_M: f32 = 0.01;
/// Fewest points in a plane's three bins, as a fraction of the frame's points, for [`wall_phase`] to
/// follow it (0.5 %: a wall strip seen in a 320×240 frame holds thousands; the side of a piece of furniture
/// a few hundred).
pub const WALL_MIN_FRACTION: f32 = 0.005;

/// The plane of [`LatticePhase::Walls`] along each rotated axis of one yaw, `[s, t]` (metres, `None` where
/// none is seen): along t the points whose rotated normal has `n_t ≤ −cos 30°` (surfaces facing the front
/// of a box of this yaw: the wall behind it), along s those with `|n_s| ≥ cos 30°`. Per axis the points'
/// coordinates are counted in [`WALL_BIN_M`] bins; the plane is the three adjacent bins with the most
/// points (the first such window on ties) if they hold at least [`WALL_MIN_FRACTION`] of the points, at
/// the mean coordinate of their points (summed in f64 in point order: the same every run).
pub fn wall_planes(pre: &Preprocessed, rotated: &[[f32; 2]], sin: f32, cos: f32) -> [Option<f32>; 2] {
    let min_count = ((WALL_MIN_FRACTION * pre.points.len() as f32).ceil() as usize).max(1);
    // The normals in the yaw's rotated frame (as the points: `rotate`).
    let local_normals: Vec<[f32; 2]> = pre.normals.iter().map(|n| rotate(n, sin, cos)).collect();
    let faces = |axis: usize, n: &[f32; 2]| match axis {
        0 => n[0].abs() >= WALL_NORMAL_COS,
        _ => n[1] <= -WALL_NORMAL_COS,
    };
    [0, 1].map(|axis| {
        let coords: Vec<f64> =
            rotated.iter().zip(&local_normals).filter(|(_, n)| faces(axis, n)).map(|(r, _)| r[axis] as f64).collect();
        if coords.len() < min_count {
            return None;
        }
        let bins: Vec<i64> = coords.iter().map(|&c| (c / WALL_BIN_M as f64).floor() as i64).collect();
        let first = *bins.iter().min()?;
        let mut counts = vec![0usize; (*bins.iter().max()? - first + 1) as usize];
        for &b in &bins {
            counts[(b - first) as usize] += 1;
        }
        // The window of bins `i-1..=i+1` with the most points (bins outside count 0).
        let window =
            |i: usize| counts[i] + if i > 0 { counts[i - 1] } else { 0 } + counts.get(i + 1).copied().unwrap_or(0);
        let best = (0..counts.len()).fold(0, |best, i| if window(i) > window(best) { i } else { best });
        if window(best) < min_count {
            return None;
        }
        let window_bins = first + best as i64 - 1..=first + best as i64 + 1;
        let inside: Vec<f64> =
            coords.iter().zip(&bins).filter(|(_, b)| window_bins.contains(b)).map(|(&c, _)| c).collect();
        Some((inside.iter().sum::<f64>() / inside.len() as f64) as f32)
    })
}

/// The lattice phase `[s, t]` of one yaw (metres in `[0, step)`; see [`grid_cells`]): 0 under
/// [`LatticePhase::Camera`]; under [`LatticePhase::Walls`] the phase that puts a centre row on each of
/// the yaw's [`wall_planes`] (centres at `phase + (k + ½)·step`), 0 along an axis without one.
pub fn wall_phase(
    pre: &Preprocessed,
    rotated: &[[f32; 2]],
    sin: f32,
    cos: f32,
    step: f32,
    lattice: LatticePhase,
) -> [f32; 2] {
    match lattice {
        LatticePhase::Camera => [0.0; 2],
        LatticePhase::Walls => wall_planes(pre, rotated, sin, cos).map(|plane| match plane {
            Some(w) => (w - 0.5 * step).rem_euclid(step),
            None => 0.0,
        }),
    }
}

impl YawGrid {
    /// Rotates, codes and buckets the points for yaw `yaw` with ground cells of side `step`, the lattice
    /// at the camera's phase.
    pub fn build(pre: &Preprocessed, yaw: f32, step: f32) -> YawGrid {
        Self::build_with(pre, yaw, step, LatticePhase::Camera)
    }

    /// [`YawGrid::build`] with the lattice at `lattice`'s phase (see the module doc).
    pub fn build_with(pre: &Preprocessed, yaw: f32, step: f32, lattice: LatticePhase) -> YawGrid {
        let (sin64, cos64) = (yaw as f64).sin_cos();
        let (sin, cos) = (sin64 as f32, cos64 as f32);
        let inv_step = 1.0 / step;
        let rotated: Vec<[f32; 2]> = pre.points.par_iter().map(|p| rotate(p, sin, cos)).collect();
        let phase = wall_phase(pre, &rotated, sin, cos, step, lattice);
        let (origin, cells) = grid_cells_at(extent(&rotated), step, phase);
        // `cells` fit in u32 for any scene that passed `features::budget` (whose limit is far below 2³²
        // cells); index arithmetic is in usize so that no product can wrap.
        let cells = cells.map(|c| c.min(u32::MAX as f64) as u32);
        let cell_of = |r: &[f32; 2]| -> usize {
            let c = [0, 1].map(|a| floor_to_i64((r[a] - origin[a]) * inv_step).clamp(0, cells[a] as i64 - 1) as u32);
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
pub fn grid_cells(extent: ([f32; 2], [f32; 2]), step: f32) -> ([f32; 2], [f64; 2]) {
    grid_cells_at(extent, step, [0.0; 2])
}

/// [`grid_cells`] with the origin at `phase` (metres, per axis, in `[0, step)`) plus a multiple of the
/// step: the largest such origin at or below the extent's low corner. A phase of 0 is [`grid_cells`]
/// exactly; another adds at most one cell per axis.
pub fn grid_cells_at((lo, hi): ([f32; 2], [f32; 2]), step: f32, phase: [f32; 2]) -> ([f32; 2], [f64; 2]) {
    let inv_step = 1.0 / step;
    let origin = [0, 1].map(|a| ((lo[a] - phase[a]) * inv_step).floor() * step + phase[a]);
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
    /// Builds the yaw grids for `yaws` with ground cells of side `step` (metres), the lattice at the
    /// camera's phase.
    pub fn new(pre: Preprocessed, yaws: &[f32], step: f32) -> FeatureScene {
        Self::with_lattice(pre, yaws, step, LatticePhase::Camera)
    }

    /// [`FeatureScene::new`] with the lattice at `lattice`'s phase.
    pub fn with_lattice(pre: Preprocessed, yaws: &[f32], step: f32, lattice: LatticePhase) -> FeatureScene {
        // The yaws' grids are independent: built in parallel, gathered in yaw order.
        let grids = yaws.par_iter().map(|&yaw| YawGrid::build_with(&pre, yaw, step, lattice)).collect();
        FeatureScene { pre, yaws: grids }
    }

    /// The angles of the yaw grids, in order.
    pub fn yaw_angles(&self) -> Vec<f32> {
        self.yaws.iter().map(|g| g.yaw).collect()
    }
}
