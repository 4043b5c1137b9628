//! The exact CPU path: features (and fused scores) of hypotheses, written stage by stage like
//! `shaders/features.wgsl`, with rayon over hypotheses.
//!
//! # Stages (per hypothesis; the shader runs one invocation per voxel column (i, j))
//! 1. [`HypothesisRecord::new`] (host side in both paths): the expanded box in the yaw's rotated frame —
//!    its low corner `lo`, voxel size `cell`, both also in fixed point — and the view cosine.
//! 2. [`cog_frame`] per voxel: the projected COG basis at the voxel centre.
//! 3. [`accumulate_column`]: for the bucket rows and cells that cover the column, every point whose voxel
//!    index `⌊(p − lo)·n / extent⌋` (per axis, integers in fixed point) is (i, j, ·) adds 1 to its voxel's count, 1 to its normal
//!    code's bin and its gradient magnitude, split between two COG bins, as fixed-point integers.
//! 4. [`finalise_voxel`]: density, normal bins and the normalised COG of each voxel of the column.
//! 5. View features (host) and, for scoring, the dot products with the weight vectors.
//!
//! # COG bins (paper §3.2.2–3.2.3), as implemented
//! The voxel's front face is the plane through the voxel centre spanned by the width axis `a` and the up
//! axis `z`. Perspective projection is linearised at the voxel centre `P` (camera coordinates): a 3D
//! direction `D` maps to the image direction `J·D = (fx·(D.x·P.z − P.x·D.z)/P.z², fy·(D.y·P.z − P.y·D.z)/P.z²)`
//! — the limit ε → 0 of projecting `P` and `P + ε·D` — so the projected bin `k` is
//! `cos(kπ/9)·J·a + sin(kπ/9)·J·z`: bins are evenly spaced by π/9 on the face, bin 0 (the paper's bin 1)
//! along the width axis. A pixel's gradient is assigned through its edge: the image edge direction
//! `e = (−dy, dx)` is written as `α·J·a + β·J·z`, which gives the edge's direction `ψ = atan2(β, α)` on the
//! face; the gradient's direction on the face is the in-face normal of that edge, `φ = ψ + π/2 (mod π)`
//! (for a fronto-parallel face this is the image gradient's angle measured with the face's up axis, i.e.
//! image y **up**: bin 0 holds horizontal gradients as in HOG, and COG bin `k` is the HOG bin `(9 − k) mod 9`
//! of `atan2(dy, dx) mod π` with image y down — the same bins, mirrored). Working through the edge makes the descriptor exact for planar texture in any
//! pose: a 3D edge on the face lands in the same bin whatever the viewpoint, which comparing the gradient
//! itself with projected bin directions would not do (perpendicularity is not preserved by projection).
//! The magnitude is split linearly in φ between the bins `⌊9φ/π⌋` and the next one (mod 9), the two
//! projected bins nearest the gradient (projection preserves the cyclic order of directions).
//!
//! # Fixed point and degenerate cases
//! * COG contributions are rounded to multiples of 2⁻²⁰ and summed as 64-bit integers (two u32 words in the
//!   shader), so the sum does not depend on the order and CPU and GPU agree to the last unit whenever
//!   their per-point contributions round alike.
//! * Empty voxel: all 35 entries 0.
//! * Density and normal bins divide by `max(A, 1)` pixels²; a voxel with a corner behind (or within 1 mm of)
//!   the camera plane has no defined silhouette ([`crate::geometry::projected_hull_area`] is `None`):
//!   density and normal bins 0.
//! * COG: a voxel whose centre is within 1 mm of the camera plane or behind it, or whose front face is seen
//!   edge-on (`|J·a × J·z| < 10⁻³·|J·a|·|J·z|`, i.e. the projected basis is degenerate to within 0.06°),
//!   has COG 0. Pixels with zero gradient add nothing.
//! * View features when the cuboid centre is (horizontally) within 1 µm of the camera: `x = 0`.

use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::feature_layout::{view_features, FeatureLayout, COG, COG_BINS, COG_EPSILON, DENSITY, NORMALS, PER_VOXEL};
use super::hypotheses::Hypothesis;
use super::preprocess::NORMAL_BINS;
use super::scene::{to_fixed, FeatureScene, YawGrid};
use crate::geometry::{projected_hull_area, voxel_corners, Cuboid, MIN_PROJECT_DEPTH};

/// Fixed-point scale of the COG accumulators (2²⁰ units per unit of gradient magnitude).
pub const COG_FIXED_SCALE: f32 = 1048576.0;
/// Edge-on threshold on `|J·a × J·z| / (|J·a|·|J·z|)`.
pub const EDGE_ON_SIN: f32 = 1e-3;
/// The largest nz the accumulators hold.
const MAX_Z: usize = super::feature_layout::MAX_GRID_Z as usize;

/// Per-hypothesis geometry as the kernels read it (48 bytes, mirrors `Hypothesis` in the shader).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct HypothesisRecord {
    /// Low corner of the expanded box in the rotated frame (s, t, z).
    pub lo: [f32; 3],
    /// Cosine for the view features (see [`view_cosine`]).
    pub view_x: f32,
    /// Voxel size along (s, t, z).
    pub cell: [f32; 3],
    pub _pad0: f32,
    /// `lo` and the extent of the expanded box in fixed point ([`to_fixed`]): a point `p` (fixed point) is
    /// in voxel `⌊(p − lo)·n / extent⌋` (integer division) along each axis when `0 ≤ p − lo < extent`.
    pub lo_fixed: [i32; 3],
    pub _pad1: i32,
    pub extent_fixed: [i32; 3],
    pub _pad2: i32,
}

/// The expanded box of a hypothesis in its yaw's rotated frame as its voxels see it: the part of
/// [`HypothesisRecord`] that the fast path needs (it has no use for the view cosine, which takes the whole
/// cuboid to compute, so its hot loops make only this).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExpandedBox {
    /// Low corner (s, t, z).
    pub lo: [f32; 3],
    /// Voxel size along (s, t, z).
    pub cell: [f32; 3],
    /// Extent along (s, t, z).
    pub extent: Vec3,
}

impl ExpandedBox {
    pub fn new(layout: &FeatureLayout, hyp: &Hypothesis) -> ExpandedBox {
        let grid = layout.grid();
        let expansion = layout.expansion();
        let extent = Vec3::new(hyp.size.x * expansion[0], hyp.size.y * expansion[1], hyp.size.z * expansion[2]);
        let centre_z = hyp.bottom + 0.5 * hyp.size.z;
        let lo = [hyp.centre.x - 0.5 * extent.x, hyp.centre.y - 0.5 * extent.y, centre_z - 0.5 * extent.z];
        let cell = [0, 1, 2].map(|a| extent[a] / grid[a] as f32);
        ExpandedBox { lo, cell, extent }
    }

    /// Rotated-frame centre of voxel (i, j, k) of the expanded grid.
    pub fn voxel_centre(&self, [i, j, k]: [u32; 3]) -> Vec3 {
        Vec3::new(
            self.lo[0] + (i as f32 + 0.5) * self.cell[0],
            self.lo[1] + (j as f32 + 0.5) * self.cell[1],
            self.lo[2] + (k as f32 + 0.5) * self.cell[2],
        )
    }
}

impl HypothesisRecord {
    pub fn new(scene: &FeatureScene, layout: &FeatureLayout, hyp: &Hypothesis) -> HypothesisRecord {
        let ExpandedBox { lo, cell, extent } = ExpandedBox::new(layout, hyp);
        HypothesisRecord {
            lo,
            view_x: view_cosine(&hyp.cuboid(scene)),
            cell,
            _pad0: 0.0,
            lo_fixed: lo.map(to_fixed),
            _pad1: 0,
            extent_fixed: [0, 1, 2].map(|a| to_fixed(extent[a]).max(1)),
            _pad2: 0,
        }
    }
}

/// A centre horizontally closer than this (metres) to the camera has view cosine 0 ([`view_cosine`]).
pub const VIEW_MIN_DISTANCE: f32 = 1e-6;

/// Cosine of the horizontal angle between the cuboid's front and the direction from its centre to the
/// camera (at the origin): 1 when it faces the camera, −1 when it faces away; 0 when the centre is
/// (horizontally) within [`VIEW_MIN_DISTANCE`] (1 µm) of the camera.
pub fn view_cosine(cuboid: &Cuboid) -> f32 {
    let to_camera = -cuboid.centre.truncate();
    if to_camera.length() < VIEW_MIN_DISTANCE {
        return 0.0;
    }
    cuboid.front().dot(to_camera.normalize())
}

/// The upright expanded box of a hypothesis (what the voxel grid covers).
pub fn expanded_cuboid(scene: &FeatureScene, layout: &FeatureLayout, hyp: &Hypothesis) -> Cuboid {
    let mut cuboid = hyp.cuboid(scene);
    let e = layout.expansion();
    cuboid.size = Vec3::new(cuboid.size.x * e[0], cuboid.size.y * e[1], cuboid.size.z * e[2]);
    cuboid
}

/// The projected COG basis of one voxel: image directions of the width axis and the up axis at the voxel
/// centre. `None` in the degenerate cases of the module doc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CogFrame {
    pub da: Vec2,
    pub dz: Vec2,
}

/// Stage 2: the COG basis of the voxel whose centre has rotated-frame coordinates `centre`.
pub fn cog_frame(grid: &YawGrid, intrinsics: [f32; 4], centre: Vec3) -> Option<CogFrame> {
    let m = grid.camera_from_rotated;
    cog_basis(intrinsics, m * centre, m.x_axis, m.z_axis)
}

/// The COG basis at camera-frame point `p` (x right, y down, z forward) of the 3D orientation bins spanned
/// by the camera-frame directions `along` (bin 0) and `up`: their image directions there. `None` when `p`
/// is less than [`MIN_PROJECT_DEPTH`] in front of the camera or the plane is seen edge-on. Shared by the
/// detector's voxels ([`cog_frame`]) and the room layout's wall planes (`room_layout::voxels`).
pub fn cog_basis(intrinsics: [f32; 4], p: Vec3, along: Vec3, up: Vec3) -> Option<CogFrame> {
    if p.z < MIN_PROJECT_DEPTH {
        return None;
    }
    let da = image_direction(intrinsics, p, along);
    let dz = image_direction(intrinsics, p, up);
    let cross = da.x * dz.y - da.y * dz.x;
    let scale = da.length() * dz.length();
    // Written so that a NaN (degenerate input) also counts as edge-on.
    let well_conditioned = cross.abs() >= EDGE_ON_SIN * scale;
    if !well_conditioned || scale == 0.0 {
        return None;
    }
    Some(CogFrame { da, dz })
}

/// The image direction (pixels per metre, x right, y down) of the camera-frame direction `d` at the
/// camera-frame point `p` (`p.z` > 0): the derivative of the projection along `d`.
pub fn image_direction(intrinsics: [f32; 4], p: Vec3, d: Vec3) -> Vec2 {
    let (fx, fy) = (intrinsics[0], intrinsics[1]);
    let inv_z2 = 1.0 / (p.z * p.z);
    Vec2::new(fx * (d.x * p.z - p.x * d.z) * inv_z2, fy * (d.y * p.z - p.y * d.z) * inv_z2)
}

/// Angle of the line through (x, y) in [0, π): `atan2(y, x) mod π`, with a polynomial arctangent
/// (|error| < 2·10⁻⁵ rad, far below the π/9 bin width) built from + − × ÷ only. The shader evaluates the
/// same polynomial: Vulkan lets a driver's `atan2` be off by up to 4096 ulp, which would make the two paths
/// disagree by more than the 1e-5 the tests allow.
pub fn unsigned_angle(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = if ax < ay { (ax, ay) } else { (ay, ax) };
    if hi == 0.0 {
        return 0.0;
    }
    let t = lo / hi;
    let t2 = t * t;
    let poly = ((((-0.011_721_2 * t2 + 0.052_653_32) * t2 - 0.116_432_87) * t2 + 0.193_543_46) * t2 - 0.332_623_47)
        * t2
        + 0.999_977_26;
    let mut angle = poly * t;
    if ay > ax {
        angle = FRAC_PI_2 - angle;
    }
    if x < 0.0 {
        angle = PI - angle;
    }
    // Fold by π: (x, y) and (−x, −y) are the same line.
    if y < 0.0 {
        angle = PI - angle;
    }
    if angle >= PI {
        angle -= PI;
    }
    angle
}

/// Where a gradient falls among the COG bins: the lower bin `⌊9φ/π⌋` and the fraction of the way to the
/// next one (see the module doc).
pub fn cog_position(frame: &CogFrame, gx: f32, gy: f32) -> (usize, f32) {
    use std::f32::consts::PI;
    let (ex, ey) = (-gy, gx);
    let alpha = frame.dz.y * ex - frame.dz.x * ey;
    let beta = frame.da.x * ey - frame.da.y * ex;
    let phi = unsigned_angle(alpha, -beta);
    let position = phi * (COG_BINS as f32 / PI);
    let bin0 = (position.floor() as usize).min(COG_BINS - 1);
    (bin0, position - bin0 as f32)
}

/// The two COG bins of a gradient and their fixed-point shares (see the module doc).
pub fn cog_split(frame: &CogFrame, gx: f32, gy: f32, magnitude: f32) -> (usize, u32, usize, u32) {
    let (bin0, frac) = cog_position(frame, gx, gy);
    let bin1 = (bin0 + 1) % COG_BINS;
    let scaled = magnitude * COG_FIXED_SCALE;
    let share1 = (frac * scaled + 0.5) as u32;
    let share0 = ((1.0 - frac) * scaled + 0.5) as u32;
    (bin0, share0, bin1, share1)
}

/// Integer sums of one voxel column (index k = voxel layer).
#[derive(Clone, Debug)]
pub struct ColumnAccumulator {
    pub count: [u32; MAX_Z],
    pub normals: [[u32; NORMAL_BINS]; MAX_Z],
    pub cog: [[u64; COG_BINS]; MAX_Z],
}

impl Default for ColumnAccumulator {
    fn default() -> Self {
        ColumnAccumulator { count: [0; MAX_Z], normals: [[0; NORMAL_BINS]; MAX_Z], cog: [[0; COG_BINS]; MAX_Z] }
    }
}

/// Voxel index of coordinate `p` along one axis, if inside `[0, n)`.
#[inline]
fn axis_index(p: i32, lo: i32, extent: i32, n: u32) -> Option<u32> {
    let d = p.wrapping_sub(lo);
    if d >= 0 && d < extent {
        // d·n < extent·n fits in i32 while extent·n < 2³¹: extent in 2⁻¹⁶ m, n at most 64 (a grid of
        // `MAX_COLUMNS` along one axis), so boxes under 512 m along that axis — the GPU twin computes the
        // same i32 product.
        Some((d * n as i32 / extent) as u32)
    } else {
        None
    }
}

/// Stage 3: accumulates the points of voxel column (i, j). Returns the number of points accepted.
pub fn accumulate_column(
    grid: &YawGrid,
    layout: &FeatureLayout,
    hyp: &HypothesisRecord,
    column: [u32; 2],
    frames: &[Option<CogFrame>],
    acc: &mut ColumnAccumulator,
) -> u32 {
    let g = layout.grid();
    let [i, j] = column;
    let s_lo = hyp.lo[0] + i as f32 * hyp.cell[0];
    let t_lo = hyp.lo[1] + j as f32 * hyp.cell[1];
    let (Some(s_cells), Some(t_cells)) =
        (grid.cell_range(0, s_lo, s_lo + hyp.cell[0]), grid.cell_range(1, t_lo, t_lo + hyp.cell[1]))
    else {
        return 0;
    };
    let use_cog = layout.groups.cog;
    let mut accepted = 0;
    for row in t_cells.0..=t_cells.1 {
        for r in &grid.records[grid.row_span(row, s_cells)] {
            let (lo, extent) = (hyp.lo_fixed, hyp.extent_fixed);
            let Some(k) = axis_index(r.z, lo[2], extent[2], g[2]) else { continue };
            if axis_index(r.s, lo[0], extent[0], g[0]) != Some(i) || axis_index(r.t, lo[1], extent[1], g[1]) != Some(j)
            {
                continue;
            }
            let k = k as usize;
            accepted += 1;
            acc.count[k] += 1;
            acc.normals[k][r.normal_bin as usize] += 1;
            if use_cog && r.magnitude > 0.0 {
                if let Some(frame) = &frames[k] {
                    let (b0, q0, b1, q1) = cog_split(frame, r.gx, r.gy, r.magnitude);
                    acc.cog[k][b0] += q0 as u64;
                    acc.cog[k][b1] += q1 as u64;
                }
            }
        }
    }
    accepted
}

/// Value of a fixed-point COG sum, converted exactly as the shader does (high word ·2¹², low word ·2⁻²⁰).
pub fn fixed_to_f32(sum: u64) -> f32 {
    (sum >> 32) as f32 * 4096.0 + (sum & 0xffff_ffff) as f32 * (1.0 / COG_FIXED_SCALE)
}

/// Stage 4: the 35 features of voxel layer `k` of a column; `area` is the voxel's projected hull area.
pub fn finalise_voxel(layout: &FeatureLayout, acc: &ColumnAccumulator, k: usize, area: Option<f32>, out: &mut [f32]) {
    let groups = layout.groups;
    if let Some(area) = area {
        let inv_area = 1.0 / area.max(1.0);
        if groups.density {
            out[DENSITY] = acc.count[k] as f32 * inv_area;
        }
        if groups.normals {
            for (slot, &n) in out[NORMALS..NORMALS + NORMAL_BINS].iter_mut().zip(&acc.normals[k]) {
                *slot = n as f32 * inv_area;
            }
        }
    }
    if groups.cog {
        let mut values = [0.0f32; COG_BINS];
        let mut norm_sq = 0.0f32;
        for (value, &sum) in values.iter_mut().zip(&acc.cog[k]) {
            *value = fixed_to_f32(sum);
            norm_sq += *value * *value;
        }
        let scale = 1.0 / (norm_sq + COG_EPSILON).sqrt();
        for (slot, value) in out[COG..COG + COG_BINS].iter_mut().zip(values) {
            *slot = value * scale;
        }
    }
}

/// Rotated-frame centre of voxel (i, j, k).
pub fn voxel_centre(hyp: &HypothesisRecord, voxel: [u32; 3]) -> Vec3 {
    Vec3::new(
        hyp.lo[0] + (voxel[0] as f32 + 0.5) * hyp.cell[0],
        hyp.lo[1] + (voxel[1] as f32 + 0.5) * hyp.cell[1],
        hyp.lo[2] + (voxel[2] as f32 + 0.5) * hyp.cell[2],
    )
}

/// Features of one hypothesis into `out` (length `layout.dim()`, overwritten). Returns the number of
/// points inside the expanded box (point·voxel updates).
pub fn hypothesis_features(scene: &FeatureScene, layout: &FeatureLayout, hyp: &Hypothesis, out: &mut [f32]) -> u32 {
    let grid = &scene.yaws[hyp.yaw_index as usize];
    let record = HypothesisRecord::new(scene, layout, hyp);
    let expanded = expanded_cuboid(scene, layout, hyp);
    let g = layout.grid();
    out.fill(0.0);
    let mut inside = 0;
    let mut frames = [None; MAX_Z];
    for j in 0..g[1] {
        for i in 0..g[0] {
            if layout.groups.cog {
                for k in 0..g[2] {
                    frames[k as usize] = cog_frame(grid, scene.pre.camera.intrinsics, voxel_centre(&record, [i, j, k]));
                }
            }
            let mut acc = ColumnAccumulator::default();
            inside += accumulate_column(grid, layout, &record, [i, j], &frames, &mut acc);
            for k in 0..g[2] {
                if acc.count[k as usize] == 0 {
                    continue; // empty voxel: all zeros
                }
                let area = projected_hull_area(&scene.pre.camera, &voxel_corners(&expanded, g, [i, j, k]));
                let offset = layout.voxel_index(i, j, k) * PER_VOXEL;
                finalise_voxel(layout, &acc, k as usize, area, &mut out[offset..offset + PER_VOXEL]);
            }
        }
    }
    if layout.groups.view {
        let offset = layout.view_offset();
        out[offset..offset + super::feature_layout::VIEW].copy_from_slice(&view_features(record.view_x));
    }
    super::out_of_view::write_out_of_view(scene, layout, hyp, out);
    inside
}

/// Features of many hypotheses (rayon), row-major `hypotheses.len() × layout.dim()`, and the points inside
/// each.
pub fn features(scene: &FeatureScene, layout: &FeatureLayout, hypotheses: &[Hypothesis]) -> (Vec<f32>, Vec<u32>) {
    let dim = layout.dim();
    let mut out = vec![0.0f32; hypotheses.len() * dim];
    let inside = out
        .par_chunks_mut(dim.max(1))
        .zip(hypotheses.par_iter())
        .map(|(row, hyp)| hypothesis_features(scene, layout, hyp, row))
        .collect();
    (out, inside)
}

/// Fused scoring on the CPU: `scores[h·W + w] = weights[w] · φ(h)` for every hypothesis and weight vector
/// (each of length `layout.dim()`), without keeping the features. Returns the scores and the total number
/// of points inside the expanded boxes.
pub fn scores(
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
) -> (Vec<f32>, u64) {
    let dim = layout.dim();
    let per: Vec<(Vec<f32>, u32)> = hypotheses
        .par_iter()
        .map_init(
            || vec![0.0f32; dim],
            |buffer, hyp| {
                let inside = hypothesis_features(scene, layout, hyp, buffer);
                (weights.iter().map(|w| dot(w, buffer)).collect(), inside)
            },
        )
        .collect();
    let total = per.iter().map(|(_, n)| *n as u64).sum();
    (per.into_iter().flat_map(|(s, _)| s).collect(), total)
}

/// Dot product in index order.
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
