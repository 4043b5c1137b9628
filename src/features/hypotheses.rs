//! Sliding-window cuboid hypotheses (paper §3.5).
//!
//! * **Sizes**: every combination of the category's width quantiles {0.1, 0.3, 0.5, 0.7, 0.9}, depth
//!   quantiles {0.25, 0.5, 0.75} and height quantiles {0.3, 0.5, 0.8}: 45 sizes, `size_index =
//!   (w·3 + d)·3 + h`. From a training set's annotated cuboids ([`SizeQuantiles::from_cuboids`]) or, when
//!   no training set is given, from the SUN RGB-D statistics in `sunrgbd-size-stats.json`
//!   ([`SizeQuantiles::from_stats_file`], the same quantiles computed over the official test split's boxes).
//! * **Yaws**: 16, `θ₀ + 2πk/16`, k = 0..15 (the full circle: the front matters). The paper gives 16
//!   orientations but not where they start. `θ₀` is chosen per frame by the window's [`YawAnchor`]:
//!   `camera` puts it at 0 (the upright frame's x axis, i.e. fixed to the camera's heading); `walls` (the
//!   default of models trained since it was added) puts it at the frame's dominant wall direction
//!   ([`wall_direction`], from the normals) modulo 22.5°, so that the four directions of a Manhattan room are among the 16
//!   and furniture standing square to the walls has a hypothesis at its own yaw instead of up to 11.25° off
//!   (which costs a 1 m × 0.3 m box against a wall a third of its IoU).
//! * **Centres**: for each yaw, the ground-plane lattice of that yaw's bucket grid (cells of side `step`,
//!   default 0.1 m, axis-aligned with the hypothesis): one centre at the middle of every cell that holds at
//!   least one point — the visible part of the scene. Bottoms on the floor.
//! * **Skipping**: a hypothesis is kept when at least `min_points` points (default
//!   [`DEFAULT_MIN_POINTS`]) lie inside the (non-expanded) cuboid and more than `step` above the floor,
//!   counted on the bucket grid: the points of the cells (side `step` on the ground, `step` vertically from
//!   the floor) whose centres lie inside the cuboid, leaving out the lowest layer (the floor slab: every box
//!   standing on a visible floor holds floor points), via a summed-volume table, so the test costs O(1) per
//!   hypothesis. The count is within one cell layer of the exact one; it only decides what is scored.

use std::f32::consts::TAU;
use std::path::Path;

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

use super::preprocess::Preprocessed;
use super::scene::{ceil_to_i64, extent, floor_to_i64, rotate, FeatureScene, PointRecord, YawGrid};
use crate::error::{Error, Result};
use crate::geometry::{polygon_contains, Cuboid};

/// Width, depth and height quantile levels (paper §3.5).
pub const WIDTH_QUANTILES: [f64; 5] = [0.1, 0.3, 0.5, 0.7, 0.9];
pub const DEPTH_QUANTILES: [f64; 3] = [0.25, 0.5, 0.75];
pub const HEIGHT_QUANTILES: [f64; 3] = [0.3, 0.5, 0.8];
/// Number of hypothesis orientations.
pub const YAW_COUNT: usize = 16;
/// Default ground-plane step of the centres (metres).
pub const DEFAULT_STEP: f32 = 0.1;
/// Default minimum number of points inside a kept hypothesis: a 0.3 m × 0.3 m patch of surface at 3 m
/// from a Kinect gives about 600 points, so 50 only drops boxes around (nearly) empty space.
pub const DEFAULT_MIN_POINTS: u32 = 50;

/// Size quantiles of one category (metres).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SizeQuantiles {
    pub widths: Vec<f32>,
    pub depths: Vec<f32>,
    pub heights: Vec<f32>,
}

impl SizeQuantiles {
    /// Reads a category's quantiles from a size statistics file (`sunrgbd-size-stats.json` format:
    /// `{category: {width_m: {q: [...], v: [...]}, depth_m: ..., height_m: ...}}`). The `q` levels must be
    /// the paper's. Category keys are compared as annotation names are ([`crate::category::normalise_name`]):
    /// the SUN RGB-D file's `night_stand` is the `nightstand` (it was not found).
    pub fn from_stats_file(path: &Path, category: &str) -> Result<SizeQuantiles> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let root: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("malformed JSON: {e}")))?;
        let wanted = crate::category::normalise_name(category).0;
        let entry = root
            .get(category)
            .or_else(|| {
                let entries = root.as_object()?;
                entries.iter().find(|(key, _)| crate::category::normalise_name(key).0 == wanted).map(|(_, v)| v)
            })
            .ok_or_else(|| Error::invalid(path, format!("no size statistics for category '{category}'")))?;
        let field = |name: &str, levels: &[f64]| -> Result<Vec<f32>> {
            let what = format!("{category}.{name}");
            let get = |key: &str| -> Result<Vec<f64>> {
                entry
                    .get(name)
                    .and_then(|f| f.get(key))
                    .and_then(|v| v.as_array())
                    .ok_or_else(|| Error::invalid(path, format!("{what}.{key} missing or not an array")))?
                    .iter()
                    .map(|x| x.as_f64().ok_or_else(|| Error::invalid(path, format!("{what}.{key} holds a non-number"))))
                    .collect()
            };
            let (q, v) = (get("q")?, get("v")?);
            if q.len() != levels.len() || q.iter().zip(levels).any(|(a, b)| (a - b).abs() > 1e-9) {
                return Err(Error::invalid(path, format!("{what}.q is {q:?}, expected {levels:?}")));
            }
            let (smallest, largest) =
                (crate::limits::MIN_OBJECT_SIZE_M as f64, crate::limits::MAX_OBJECT_SIZE_M as f64);
            if v.len() != q.len() || v.iter().any(|x| !(x.is_finite() && (smallest..=largest).contains(x))) {
                return Err(Error::invalid(
                    path,
                    format!("{what}.v must hold {} sizes in [{smallest}, {largest}] m, found {v:?}", q.len()),
                ));
            }
            Ok(v.iter().map(|&x| x as f32).collect())
        };
        Ok(SizeQuantiles {
            widths: field("width_m", &WIDTH_QUANTILES)?,
            depths: field("depth_m", &DEPTH_QUANTILES)?,
            heights: field("height_m", &HEIGHT_QUANTILES)?,
        })
    }

    /// Quantiles of annotated cuboids (linear interpolation between order statistics).
    pub fn from_cuboids(cuboids: &[Cuboid]) -> Result<SizeQuantiles> {
        if cuboids.is_empty() {
            return Err(Error::Input("no training cuboids to take size quantiles from".into()));
        }
        let pick = |axis: usize, levels: &[f64]| {
            let mut v: Vec<f32> = cuboids.iter().map(|c| c.size[axis]).collect();
            v.sort_by(f32::total_cmp);
            levels.iter().map(|&q| quantile_sorted(&v, q)).collect()
        };
        Ok(SizeQuantiles {
            widths: pick(0, &WIDTH_QUANTILES),
            depths: pick(1, &DEPTH_QUANTILES),
            heights: pick(2, &HEIGHT_QUANTILES),
        })
    }

    /// All (width, depth, height) combinations, `index = (w·nd + d)·nh + h`.
    pub fn sizes(&self) -> Vec<Vec3> {
        let mut out = Vec::new();
        for &w in &self.widths {
            for &d in &self.depths {
                for &h in &self.heights {
                    out.push(Vec3::new(w, d, h));
                }
            }
        }
        out
    }
}

fn quantile_sorted(v: &[f32], q: f64) -> f32 {
    let pos = q * (v.len() - 1) as f64;
    let (i, frac) = (pos.floor() as usize, pos - pos.floor());
    let next = v[(i + 1).min(v.len() - 1)];
    (v[i] as f64 * (1.0 - frac) + next as f64 * frac) as f32
}

/// The 16 hypothesis yaws `2πk/16` (the [`YawAnchor::Camera`] set).
pub fn default_yaws() -> Vec<f32> {
    anchored_yaws(0.0)
}

/// The 16 hypothesis yaws `θ₀ + 2πk/16` with `θ₀ = anchor` reduced into [0, 2π/16).
pub fn anchored_yaws(anchor: f32) -> Vec<f32> {
    let spacing = TAU / YAW_COUNT as f32;
    let start = anchor.rem_euclid(spacing);
    // rem_euclid can return `spacing` itself for an anchor just below a multiple of it.
    let start = if start >= spacing { 0.0 } else { start };
    (0..YAW_COUNT).map(|k| start + spacing * k as f32).collect()
}

/// Where the 16 yaws of a sliding window start (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum YawAnchor {
    /// `2πk/16`: fixed to the camera's heading. What model files without a `yaw_anchor` were trained with.
    #[default]
    Camera,
    /// `θ₀ + 2πk/16` with `θ₀` the frame's [`wall_direction`] (the camera set when no walls are seen).
    Walls,
}

impl YawAnchor {
    /// The anchor's name in model files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            YawAnchor::Camera => "camera",
            YawAnchor::Walls => "walls",
        }
    }
}

/// The sliding window's 16 yaws under `anchor`, given the frame's wall direction (`None`: no dominant
/// direction, so the walls anchor falls back to the camera's yaws).
pub fn yaws_under(anchor: YawAnchor, wall_direction: Option<f32>) -> Vec<f32> {
    match anchor {
        YawAnchor::Camera => default_yaws(),
        YawAnchor::Walls => anchored_yaws(wall_direction.unwrap_or(0.0)),
    }
}

/// The sliding window's 16 yaws for `pre` under `anchor` (for several anchors of one frame use
/// [`FrameYaws`], which estimates the wall direction once).
pub fn window_yaws(pre: &Preprocessed, anchor: YawAnchor) -> Vec<f32> {
    FrameYaws::new(pre).yaws(anchor)
}

/// One frame's window yaws under any anchor: the wall direction ([`frame_wall_direction`], a histogram
/// over every normal) is estimated on first use and kept, so that a frame searched by many models,
/// checked by the memory budget first, pays for it once.
pub struct FrameYaws<'a> {
    pre: &'a Preprocessed,
    wall_direction: std::sync::OnceLock<Option<f32>>,
}

impl<'a> FrameYaws<'a> {
    pub fn new(pre: &'a Preprocessed) -> Self {
        Self { pre, wall_direction: std::sync::OnceLock::new() }
    }

    /// The frame's wall direction (estimated on the first call).
    pub fn wall_direction(&self) -> Option<f32> {
        *self.wall_direction.get_or_init(|| frame_wall_direction(self.pre))
    }

    /// The window's 16 yaws under `anchor` ([`yaws_under`]); the camera anchor never estimates walls.
    pub fn yaws(&self, anchor: YawAnchor) -> Vec<f32> {
        match anchor {
            YawAnchor::Camera => default_yaws(),
            YawAnchor::Walls => yaws_under(anchor, self.wall_direction()),
        }
    }
}

/// Index of the yaw of `yaws` nearest to `yaw` (angles compared around the circle; the first of equals).
pub fn nearest_yaw_index(yaws: &[f32], yaw: f32) -> usize {
    let gap = |a: f32| {
        let d = (a - yaw).rem_euclid(TAU);
        d.min(TAU - d)
    };
    let mut best = 0;
    for (k, &a) in yaws.iter().enumerate() {
        if gap(a) < gap(yaws[best]) {
            best = k;
        }
    }
    best
}

/// A normal counts as a wall's when its vertical component is below this (surfaces within ~11.5° of
/// vertical).
pub const WALL_NORMAL_MAX_Z: f32 = 0.2;
/// Normals within this angle (degrees) of the camera's optical axis do not vote: a depth sensor quantises
/// depth, so neighbouring pixels often share one depth and their fitted plane is the constant-depth plane,
/// whose normal is the optical axis whatever the surface (on the real office frame 40 % of the
/// near-vertical normals lie within 0.2° of it). A wall squarely facing the camera loses its votes; the
/// walls at right angles to it still vote for the same direction modulo 90°.
pub const WALL_NORMAL_AXIS_EXCLUSION_DEG: f32 = 10.0;
/// Fewest voting normals for [`wall_direction`] to give an answer.
pub const WALL_DIRECTION_MIN_NORMALS: usize = 500;
/// The smoothed histogram's peak must be at least this many times its mean bin: a frame that sees little
/// wall (a camera looking down at a bed) has a flat histogram whose highest bin is often furniture or
/// noise, and its window keeps the camera's yaws.
pub const WALL_DIRECTION_MIN_PEAK_RATIO: f64 = 4.5;
/// Bins of the wall-direction histogram over [0°, 90°) (1° each).
const WALL_DIRECTION_BINS: usize = 90;
/// Half-width (bins) of the triangular smoothing of that histogram, and of the refinement window.
const WALL_DIRECTION_HALF_WIDTH: usize = 3;

/// The wall direction of a frame: [`wall_direction`] of its normals with its camera's optical axis.
pub fn frame_wall_direction(pre: &Preprocessed) -> Option<f32> {
    // Camera coordinates (x, z, −y) → upright: the optical axis (camera z) is the rotation's second column.
    wall_direction(&pre.normals, pre.camera.rtilt * Vec3::Y)
}

/// The dominant horizontal direction of the frame's vertical surfaces, modulo 90°, in [0, π/2): the
/// direction of a Manhattan room's walls (and of the furniture standing square to them).
///
/// The normals with `|n_z| < WALL_NORMAL_MAX_Z` and more than [`WALL_NORMAL_AXIS_EXCLUSION_DEG`] from the
/// optical axis `optical_axis` (upright) vote with their azimuth folded into [0°, 90°) in a 1° histogram
/// (integer counts); the histogram is smoothed circularly with a triangle of half-width 3 bins and its
/// highest bin (the first of equals) is refined by the 4-fold circular mean of the votes within 3° of it
/// (`atan2(Σ sin 4α, Σ cos 4α) / 4`, summed in f64 in point order, so the result is the same on every
/// run). `None` when fewer than [`WALL_DIRECTION_MIN_NORMALS`] normals vote or the peak is weaker than
/// [`WALL_DIRECTION_MIN_PEAK_RATIO`] times the mean: the window then keeps the camera's yaws.
pub fn wall_direction(normals: &[Vec3], optical_axis: Vec3) -> Option<f32> {
    use std::f64::consts::FRAC_PI_2;
    let axis = optical_axis.normalize_or_zero();
    let max_axis_cosine = WALL_NORMAL_AXIS_EXCLUSION_DEG.to_radians().cos();
    let folded: Vec<f64> = normals
        .iter()
        .filter(|n| n.z.abs() < WALL_NORMAL_MAX_Z && n.truncate().length_squared() > 1e-6)
        .filter(|n| n.dot(axis).abs() < max_axis_cosine)
        .map(|n| (n.y as f64).atan2(n.x as f64).rem_euclid(FRAC_PI_2))
        .collect();
    if folded.len() < WALL_DIRECTION_MIN_NORMALS {
        return None;
    }
    let bin_of = |a: f64| ((a / FRAC_PI_2 * WALL_DIRECTION_BINS as f64) as usize).min(WALL_DIRECTION_BINS - 1);
    let mut histogram = [0u64; WALL_DIRECTION_BINS];
    for &a in &folded {
        histogram[bin_of(a)] += 1;
    }
    let half = WALL_DIRECTION_HALF_WIDTH as isize;
    let smoothed: Vec<u64> = (0..WALL_DIRECTION_BINS as isize)
        .map(|b| {
            (-half..=half)
                .map(|o| {
                    let weight = (half + 1 - o.abs()) as u64;
                    weight * histogram[(b + o).rem_euclid(WALL_DIRECTION_BINS as isize) as usize]
                })
                .sum()
        })
        .collect();
    let peak_bin = (0..WALL_DIRECTION_BINS).fold(0, |best, b| if smoothed[b] > smoothed[best] { b } else { best });
    let mean = smoothed.iter().sum::<u64>() as f64 / WALL_DIRECTION_BINS as f64;
    if (smoothed[peak_bin] as f64) < WALL_DIRECTION_MIN_PEAK_RATIO * mean {
        return None;
    }
    let peak = (peak_bin as f64 + 0.5) * FRAC_PI_2 / WALL_DIRECTION_BINS as f64;
    let reach = (WALL_DIRECTION_HALF_WIDTH as f64 + 0.5) * FRAC_PI_2 / WALL_DIRECTION_BINS as f64;
    let (mut sin_sum, mut cos_sum) = (0.0f64, 0.0f64);
    for &a in &folded {
        // Offset from the peak, wrapped into [−45°, 45°).
        let offset = (a - peak + 0.5 * FRAC_PI_2).rem_euclid(FRAC_PI_2) - 0.5 * FRAC_PI_2;
        if offset.abs() <= reach {
            let (s, c) = (4.0 * offset).sin_cos();
            sin_sum += s;
            cos_sum += c;
        }
    }
    let direction = (peak + sin_sum.atan2(cos_sum) / 4.0).rem_euclid(FRAC_PI_2);
    Some(direction as f32)
}

/// One cuboid hypothesis, in the frame of its yaw's [`YawGrid`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hypothesis {
    /// Index into [`FeatureScene::yaws`].
    pub yaw_index: u16,
    /// Index into the size list it was made from.
    pub size_index: u16,
    /// Centre on the ground plane in the yaw's rotated frame (s, t).
    pub centre: Vec2,
    /// Bottom height (upright z).
    pub bottom: f32,
    /// (width, depth, height).
    pub size: Vec3,
    /// Points inside, as counted for the skipping test.
    pub points_inside: u32,
}

impl Hypothesis {
    /// The hypothesis as an upright cuboid.
    pub fn cuboid(&self, scene: &FeatureScene) -> Cuboid {
        let grid = &scene.yaws[self.yaw_index as usize];
        let centre = grid.to_upright(self.centre.extend(self.bottom + 0.5 * self.size.z));
        Cuboid::new(centre, self.size, grid.yaw)
    }
}

/// Options of the sliding window.
#[derive(Clone, Debug)]
pub struct WindowOptions {
    pub sizes: Vec<Vec3>,
    /// Minimum points inside (see the module doc).
    pub min_points: u32,
}

/// Hypotheses of one sliding window with the counts the reports need.
#[derive(Clone, Debug, Default)]
pub struct HypothesisSet {
    pub hypotheses: Vec<Hypothesis>,
    /// Hypotheses enumerated before the skipping test.
    pub generated: usize,
}

/// Per-yaw summed-volume table of point counts over (s cell, t cell, z cell from the floor).
struct CountTable {
    dims: [usize; 3],
    /// `(dims+1)`-sized inclusive prefix sums.
    sums: Vec<u32>,
}

impl CountTable {
    /// The table of `grid`'s points with z cells of side `z_cell` from `floor` up.
    fn build(grid: &YawGrid, floor: f32, z_cell: f32) -> CountTable {
        Self::build_of(grid, floor, z_cell, |_| true)
    }

    /// [`CountTable::build`] counting only the points for which `counted` holds (the table's z extent is
    /// still that of all points).
    fn build_of(grid: &YawGrid, floor: f32, z_cell: f32, counted: impl Fn(&PointRecord) -> bool) -> CountTable {
        let inv_z_cell = 1.0 / z_cell;
        let max_z = grid.records.iter().fold(floor, |m, r| m.max(r.z_metres()));
        let nz = (((max_z - floor) * inv_z_cell).floor() as usize + 1).max(1);
        let dims = [grid.cells[0] as usize, grid.cells[1] as usize, nz];
        let (sx, sy) = (dims[0] + 1, dims[1] + 1);
        let mut sums = vec![0u32; sx * sy * (nz + 1)];
        let at = |x: usize, y: usize, z: usize| (z * sy + y) * sx + x;
        for row in 0..grid.cells[1] {
            for col in 0..grid.cells[0] {
                for r in grid.records[grid.row_span(row, (col, col))].iter().filter(|r| counted(r)) {
                    let z = floor_to_i64((r.z_metres() - floor) * inv_z_cell).clamp(0, nz as i64 - 1) as usize;
                    sums[at(col as usize + 1, row as usize + 1, z + 1)] += 1;
                }
            }
        }
        for z in 1..=nz {
            for y in 1..=dims[1] {
                for x in 1..=dims[0] {
                    let v = sums[at(x, y, z)] + sums[at(x - 1, y, z)] + sums[at(x, y - 1, z)] + sums[at(x, y, z - 1)]
                        - sums[at(x - 1, y - 1, z)]
                        - sums[at(x - 1, y, z - 1)]
                        - sums[at(x, y - 1, z - 1)]
                        + sums[at(x - 1, y - 1, z - 1)];
                    sums[at(x, y, z)] = v;
                }
            }
        }
        CountTable { dims, sums }
    }

    /// Points in cells `lo..=hi` (inclusive, clamped); 0 when empty.
    fn count(&self, lo: [i64; 3], hi: [i64; 3]) -> u32 {
        match (self.ground_rect([lo[0], lo[1]], [hi[0], hi[1]]), self.z_layers(lo[2], hi[2])) {
            (Some(rect), Some((a, b))) => (self.below(&rect, b) - self.below(&rect, a)) as u32,
            _ => 0,
        }
    }

    /// Ground cells `lo..=hi` along s and t, clamped to the table, as prefix indices; `None` when no cell
    /// is left.
    fn ground_rect(&self, lo: [i64; 2], hi: [i64; 2]) -> Option<GroundRect> {
        let mut rect = GroundRect { a: [0; 2], b: [0; 2] };
        for k in 0..2 {
            let (l, h) = (lo[k].max(0), hi[k].min(self.dims[k] as i64 - 1));
            if h < l {
                return None;
            }
            (rect.a[k], rect.b[k]) = (l as usize, h as usize + 1);
        }
        Some(rect)
    }

    /// Z cells `lo..=hi`, clamped, as the prefix layers `(a, b)` that bound them; `None` when empty.
    fn z_layers(&self, lo: i64, hi: i64) -> Option<(usize, usize)> {
        let (l, h) = (lo.max(0), hi.min(self.dims[2] as i64 - 1));
        (h >= l).then_some((l as usize, h as usize + 1))
    }

    /// Points in the ground cells of `rect` and the z cells below prefix layer `z` (`0..z`): four reads.
    /// A box's count is the difference of two of these, the eight-corner formula regrouped (exact in
    /// integers).
    fn below(&self, rect: &GroundRect, z: usize) -> i64 {
        let (sx, sy) = (self.dims[0] + 1, self.dims[1] + 1);
        let s = |x: usize, y: usize| self.sums[(z * sy + y) * sx + x] as i64;
        s(rect.b[0], rect.b[1]) - s(rect.a[0], rect.b[1]) - s(rect.b[0], rect.a[1]) + s(rect.a[0], rect.a[1])
    }
}

/// A clamped ground rectangle of a [`CountTable`]: prefix indices `a[k]..b[k]` along s (k = 0) and t.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct GroundRect {
    a: [usize; 2],
    b: [usize; 2],
}

/// The range of cell indices whose centres `origin + (c + ½)·cell` lie in `[lo, hi]` (empty when the
/// first exceeds the last).
fn centred_cells(lo: f32, hi: f32, origin: f32, cell: f32) -> (i64, i64) {
    (ceil_to_i64((lo - origin) / cell - 0.5), floor_to_i64((hi - origin) / cell - 0.5))
}

/// Pushes onto `kept` the hypotheses of every size of `options` at `(yaw_index, centre, bottom)` (`centre`
/// a lattice cell's centre in the yaw's rotated frame) that hold at least `options.min_points` points,
/// counted by `table` over the ground cells whose centres lie inside the box and the z cells
/// `z_cells(size)`; returns the number of sizes tried.
fn push_sizes(
    table: &CountTable,
    grid: &YawGrid,
    (yaw_index, centre, bottom): (usize, Vec2, f32),
    options: &WindowOptions,
    z_cells: impl Fn(Vec3) -> (i64, i64),
    kept: &mut Vec<Hypothesis>,
) -> usize {
    // Consecutive sizes share their width and depth (`SizeQuantiles::sizes` varies the height fastest,
    // and most boxes of a centre start at the same z cell), so the ground rectangle and its count below
    // the lowest z layer are kept while they repeat: four table reads per size instead of eight, and the
    // same integers as [`CountTable::count`] (the window was a fifth of a frame's CPU time on the GPU path).
    let mut ground: Option<([u32; 2], Option<GroundRect>)> = None;
    let mut low: Option<(usize, i64)> = None;
    for (size_index, &size) in options.sizes.iter().enumerate() {
        let footprint = [size.x.to_bits(), size.y.to_bits()];
        let rect = match ground {
            Some((seen, rect)) if seen == footprint => rect,
            _ => {
                let (s0, s1) =
                    centred_cells(centre.x - 0.5 * size.x, centre.x + 0.5 * size.x, grid.origin[0], grid.step);
                let (t0, t1) =
                    centred_cells(centre.y - 0.5 * size.y, centre.y + 0.5 * size.y, grid.origin[1], grid.step);
                let rect = table.ground_rect([s0, t0], [s1, t1]);
                (ground, low) = (Some((footprint, rect)), None);
                rect
            }
        };
        let (z0, z1) = z_cells(size);
        let inside = match (rect, table.z_layers(z0, z1)) {
            (Some(rect), Some((a, b))) => {
                let below_a = match low {
                    Some((layer, n)) if layer == a => n,
                    _ => {
                        let n = table.below(&rect, a);
                        low = Some((a, n));
                        n
                    }
                };
                (table.below(&rect, b) - below_a) as u32
            }
            _ => 0,
        };
        if inside >= options.min_points {
            kept.push(Hypothesis {
                yaw_index: yaw_index as u16,
                size_index: size_index as u16,
                centre,
                bottom,
                size,
                points_inside: inside,
            });
        }
    }
    options.sizes.len()
}

/// One yaw's point-count tables, built once and shared by every window searched on the yaw ([`windows`]):
/// with z cells of the window step (the floor's sliding window), of [`SURFACE_COUNT_CELL_M`] (the surface,
/// free and resting windows) and of [`SURFACE_COUNT_CELL_M`] over the upward-facing points only (the
/// resting window's tops) — each only when a request needs it. A frame's models that share a scene used
/// to build their own tables, one per model and yaw: a fifth of the window's CPU time with the 19 shipped
/// models. They are built before the requests run (not on first use), so no thread waits for another's.
struct YawCounts<'g> {
    grid: &'g YawGrid,
    floor: f32,
    step: Option<CountTable>,
    surface: Option<CountTable>,
    tops: Option<CountTable>,
}

impl<'g> YawCounts<'g> {
    /// The tables of `grid` that `requests` read.
    fn new(grid: &'g YawGrid, floor: f32, requests: &[WindowRequest], raised: &[Vec<SupportSurface>]) -> Self {
        let reads_step = requests.iter().any(|r| matches!(r.support, Support::Floor | Support::FloorAndSurfaces));
        let reads_surface = requests.iter().zip(raised).any(|(r, raised)| match r.support {
            Support::Floor => false,
            Support::Surfaces => !r.surfaces.is_empty(),
            Support::FloorAndSurfaces => !raised.is_empty(),
            Support::Free | Support::Resting => true,
        });
        let reads_tops = requests.iter().any(|r| r.support == Support::Resting);
        YawCounts {
            grid,
            floor,
            step: reads_step.then(|| CountTable::build(grid, floor, grid.step)),
            surface: reads_surface.then(|| CountTable::build(grid, floor, SURFACE_COUNT_CELL_M)),
            tops: reads_tops.then(|| CountTable::build_of(grid, floor, SURFACE_COUNT_CELL_M, |r| r.normal_bin == 0)),
        }
    }

    /// Z cells of the window step.
    fn step(&self) -> &CountTable {
        self.step.as_ref().expect("built for the floor windows")
    }

    /// Z cells of [`SURFACE_COUNT_CELL_M`].
    fn surface(&self) -> &CountTable {
        self.surface.as_ref().expect("built for the surface, free and resting windows")
    }

    /// Z cells of [`SURFACE_COUNT_CELL_M`], upward-facing points only.
    fn tops(&self) -> &CountTable {
        self.tops.as_ref().expect("built for the resting windows")
    }
}

/// One model's window in a call of [`windows`]: where its boxes stand, its sizes and skipping threshold,
/// and the surfaces it searches (read only when [`Support::uses_surfaces`]).
#[derive(Clone, Copy)]
pub struct WindowRequest<'a> {
    pub support: Support,
    pub options: &'a WindowOptions,
    pub surfaces: &'a [SupportSurface],
}

/// The windows of several models on one scene ([`window`] of each request, the same hypotheses in the
/// same order), yaws in parallel and each yaw's requests in parallel, **each yaw's count tables built once
/// for all the requests** (`YawCounts`) and dropped when the yaw is done: at most one yaw's tables per
/// thread, as before. `detect` searches all the models of a scene with one call.
pub fn windows(scene: &FeatureScene, requests: &[WindowRequest]) -> Vec<HypothesisSet> {
    use rayon::prelude::*;
    let floor = scene.pre.floor;
    // A surface at the floor's own height is the floor, which the floor part of a floor+surfaces window
    // searches already (see `floor_and_surface_window`).
    let raised: Vec<Vec<SupportSurface>> = requests
        .iter()
        .map(|r| match r.support {
            Support::FloorAndSurfaces => r.surfaces.iter().filter(|s| s.z != floor).copied().collect(),
            _ => Vec::new(),
        })
        .collect();
    let per_yaw: Vec<Vec<(usize, Vec<Hypothesis>)>> = scene
        .yaws
        .par_iter()
        .enumerate()
        .map(|(yaw_index, grid)| {
            let counts = YawCounts::new(grid, floor, requests, &raised);
            requests
                .par_iter()
                .zip(&raised)
                .map(|(request, raised)| {
                    let mut kept = Vec::new();
                    let options = request.options;
                    let generated = match request.support {
                        Support::Floor => floor_yaw(&counts, yaw_index, options, &mut kept),
                        Support::Surfaces => surface_yaw(&counts, yaw_index, options, request.surfaces, &mut kept),
                        Support::Free => layered_yaw(&counts, yaw_index, options, false, &mut kept),
                        Support::Resting => layered_yaw(&counts, yaw_index, options, true, &mut kept),
                        // Within a yaw the floor's hypotheses first, then those on the surfaces.
                        Support::FloorAndSurfaces => {
                            floor_yaw(&counts, yaw_index, options, &mut kept)
                                + surface_yaw(&counts, yaw_index, options, raised, &mut kept)
                        }
                    };
                    (generated, kept)
                })
                .collect()
        })
        .collect();
    // Each request's yaws (moved, not copied), then each request's set gathered in yaw order, the requests
    // in parallel.
    let mut by_request: Vec<Vec<(usize, Vec<Hypothesis>)>> = requests.iter().map(|_| Vec::new()).collect();
    for yaw in per_yaw {
        for (parts, part) in by_request.iter_mut().zip(yaw) {
            parts.push(part);
        }
    }
    by_request
        .into_par_iter()
        .map(|parts| {
            let mut set = HypothesisSet {
                hypotheses: Vec::with_capacity(parts.iter().map(|(_, kept)| kept.len()).sum()),
                generated: 0,
            };
            for (generated, kept) in parts {
                set.generated += generated;
                set.hypotheses.extend(kept);
            }
            set
        })
        .collect()
}

/// The one window of `request` on `scene`.
fn single_window(scene: &FeatureScene, request: WindowRequest) -> HypothesisSet {
    windows(scene, &[request]).pop().unwrap_or_default()
}

/// The centre of lattice cell `(col, row)` of `grid`, in the yaw's rotated frame.
fn cell_centre(grid: &YawGrid, col: u32, row: u32) -> Vec2 {
    Vec2::new(grid.origin[0] + (col as f32 + 0.5) * grid.step, grid.origin[1] + (row as f32 + 0.5) * grid.step)
}

/// The centre (in the yaw's rotated frame) of every lattice cell of `grid` that holds a point.
fn occupied_centres(grid: &YawGrid) -> impl Iterator<Item = Vec2> + '_ {
    occupied_cells(grid).map(move |(col, row)| cell_centre(grid, col, row))
}

/// The (column, row) of every lattice cell of `grid` that holds a point, row by row.
fn occupied_cells(grid: &YawGrid) -> impl Iterator<Item = (u32, u32)> + '_ {
    (0..grid.cells[1]).flat_map(move |row| {
        (0..grid.cells[0]).filter(move |&col| !grid.row_span(row, (col, col)).is_empty()).map(move |col| (col, row))
    })
}

/// The count-table z cells (of [`SURFACE_COUNT_CELL_M`] from `floor`) of a box of height `size.z`
/// standing at `bottom`, without the [`SURFACE_CLEARANCE_M`] above the bottom (what it stands on).
fn cells_above(bottom: f32, floor: f32) -> impl Fn(Vec3) -> (i64, i64) {
    move |size| centred_cells(bottom + SURFACE_CLEARANCE_M, bottom + size.z, floor, SURFACE_COUNT_CELL_M)
}

/// Enumerates the sliding window over every yaw of `scene` (see the module doc).
pub fn sliding_window(scene: &FeatureScene, options: &WindowOptions) -> HypothesisSet {
    single_window(scene, WindowRequest { support: Support::Floor, options, surfaces: &[] })
}

/// One yaw of [`sliding_window`]: pushes its kept hypotheses onto `kept`, returns how many it generated.
fn floor_yaw(counts: &YawCounts, yaw_index: usize, options: &WindowOptions, kept: &mut Vec<Hypothesis>) -> usize {
    let (grid, floor, table) = (counts.grid, counts.floor, counts.step());
    // The floor slab (the lowest cell layer) is left out: every box on the floor holds floor points,
    // which say nothing about an object.
    let z_cells = |size: Vec3| (1, centred_cells(floor, floor + size.z, floor, grid.step).1);
    occupied_centres(grid)
        .map(|centre| push_sizes(table, grid, (yaw_index, centre, floor), options, z_cells, kept))
        .sum()
}

/// Where a window's boxes stand (a model file's `window.support`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Support {
    /// On the floor: the sliding window of §3.5 ([`sliding_window`]), for objects that stand on it.
    #[default]
    Floor,
    /// On the support surfaces of other objects (paper §4: small objects "searched only on predicted
    /// surfaces"; [`surface_window`]).
    Surfaces,
    /// Anywhere: the "free" sliding window the paper compares the surface search with, its bottom at
    /// every height from the floor up to [`FREE_MAX_BOTTOM_M`] ([`free_window`]) — for what stands on
    /// things no detector finds (a TV on the wall or on a cabinet, a box on a shelf).
    Free,
    /// On the floor and on the support surfaces ([`floor_and_surface_window`]): the union of the
    /// floor's sliding window and the surface window, for a category that stands on either — a sink is
    /// a pedestal on the floor or a basin on a counter (half of the generator's sinks each), which the
    /// surface window alone can never reach in the first case nor the floor window in the second.
    /// Searched after the floor models, like [`Support::Surfaces`].
    #[serde(rename = "floor+surfaces")]
    FloorAndSurfaces,
    /// The free window's boxes that rest on something seen ([`resting_window`]): every box on the
    /// floor, and a box at a raised bottom only where upward-facing points lie at that height around its
    /// centre — a pillow or a lamp on furniture stands on a top the camera sees beside it. For what stands
    /// on furniture no detector finds; not for what hangs on a wall (a wall-mounted TV stands on nothing).
    Resting,
}

impl Support {
    /// The support's name in model files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Support::Floor => "floor",
            Support::Surfaces => "surfaces",
            Support::Free => "free",
            Support::FloorAndSurfaces => "floor+surfaces",
            Support::Resting => "resting",
        }
    }

    /// Whether the window searches the support surfaces of other objects (so that its model runs
    /// after the models whose detections carry them, and trains with the annotated ones).
    pub fn uses_surfaces(self) -> bool {
        matches!(self, Support::Surfaces | Support::FloorAndSurfaces)
    }
}

/// How far (metres) beyond the footprint of the object that carries a surface a small object's centre
/// may lie and still be searched on it: detected footprints are off by up to a step or so, and a pillow
/// or a lamp often stands at the very edge of what carries it.
pub const SURFACE_MARGIN_M: f32 = 0.1;
/// Points less than this (metres) above a surface are the surface itself: the skipping test of
/// [`surface_window`] leaves them out, as the sliding window leaves out the floor slab.
pub const SURFACE_CLEARANCE_M: f32 = 0.05;
/// Vertical cell of the surface window's point counts (metres): small objects are 0.1–0.6 m tall, so the
/// step-sized cells of the floor window would be too coarse to tell the object from the surface.
pub const SURFACE_COUNT_CELL_M: f32 = 0.05;

/// A horizontal surface that small objects are searched on: the cuboid of the object that carries it (a
/// detection at test time, an annotated object in training) and the surface's height (upright z).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupportSurface {
    pub object: Cuboid,
    pub z: f32,
}

impl SupportSurface {
    /// The footprint a small object's centre must lie in: the object's, grown by [`SURFACE_MARGIN_M`]
    /// on every side.
    pub fn search_footprint(&self) -> [Vec2; 4] {
        let grown = Vec3::new(2.0 * SURFACE_MARGIN_M, 2.0 * SURFACE_MARGIN_M, 0.0);
        Cuboid::new(self.object.centre, self.object.size + grown, self.object.yaw).footprint()
    }

    /// Whether a box whose centre lies at upright `(x, y)` = `centre` and whose bottom is at `bottom`
    /// stands on this surface: the centre inside [`Self::search_footprint`] and the bottom within
    /// `height_tolerance` of the surface.
    pub fn holds(&self, centre: Vec2, bottom: f32, height_tolerance: f32) -> bool {
        (bottom - self.z).abs() <= height_tolerance && polygon_contains(&self.search_footprint(), centre)
    }
}

/// The window of a category searched on support surfaces (paper §4's small objects): for every yaw of
/// `scene` and every surface, one centre at the middle of each lattice cell (the sliding window's cells,
/// side `step`) that holds a point and lies inside the surface's [`SupportSurface::search_footprint`],
/// every size of `options`, the bottom at the surface. A hypothesis is kept when at least
/// `options.min_points` points lie inside its box and [`SURFACE_CLEARANCE_M`] or more above the surface
/// (counted on ground cells × [`SURFACE_COUNT_CELL_M`] layers, like the sliding window's test). Two
/// surfaces at the same height that share a cell give its hypotheses once (the first surface's).
/// `generated` counts the hypotheses before the skipping test.
pub fn surface_window(scene: &FeatureScene, options: &WindowOptions, surfaces: &[SupportSurface]) -> HypothesisSet {
    single_window(scene, WindowRequest { support: Support::Surfaces, options, surfaces })
}

/// One yaw of [`surface_window`] (no table is built when there is no surface).
fn surface_yaw(
    counts: &YawCounts,
    yaw_index: usize,
    options: &WindowOptions,
    surfaces: &[SupportSurface],
    kept: &mut Vec<Hypothesis>,
) -> usize {
    if surfaces.is_empty() {
        return 0;
    }
    let (grid, floor, table) = (counts.grid, counts.floor, counts.surface());
    let step = grid.step;
    let mut seen = std::collections::HashSet::new();
    let mut generated = 0;
    for surface in surfaces {
        let footprint = surface.search_footprint();
        // The footprint in the yaw's rotated frame bounds the cells to look at.
        let (lo, hi) = extent(&footprint.map(|p| rotate(&p.extend(0.0), grid.sin, grid.cos)));
        let (c0, c1) = centred_cells(lo[0], hi[0], grid.origin[0], step);
        let (r0, r1) = centred_cells(lo[1], hi[1], grid.origin[1], step);
        let (c0, c1) = (c0.max(0), c1.min(grid.cells[0] as i64 - 1));
        let (r0, r1) = (r0.max(0), r1.min(grid.cells[1] as i64 - 1));
        for row in r0..=r1 {
            for col in c0..=c1 {
                let (row, col) = (row as u32, col as u32);
                if grid.row_span(row, (col, col)).is_empty() {
                    continue;
                }
                let centre = cell_centre(grid, col, row);
                let upright = grid.to_upright(centre.extend(0.0)).truncate();
                if !polygon_contains(&footprint, upright) || !seen.insert((col, row, surface.z.to_bits())) {
                    continue;
                }
                let at = (yaw_index, centre, surface.z);
                generated += push_sizes(table, grid, at, options, cells_above(surface.z, floor), kept);
            }
        }
    }
    generated
}

/// Highest bottom (metres above the floor) of the free window's boxes. Chosen to cover what the
/// generator (and a real room) puts above the floor: furniture tops (≤ 1.2 m) and wall-mounted TVs
/// (bottoms 0.9–1.4 m); a box on a bookshelf's top shelf (up to 2 m) is left out — each 0.1 m more costs
/// a whole layer of boxes.
pub const FREE_MAX_BOTTOM_M: f32 = 1.5;

/// The bottoms of the free window: `floor + k·step` for k = 0, 1, … up to [`FREE_MAX_BOTTOM_M`] (the
/// vertical step is the window's ground step, so a box is never more than half a step off vertically).
pub fn free_bottoms(floor: f32, step: f32) -> Vec<f32> {
    // The small slack keeps 1.5 at step 0.1 or 0.5 despite rounding.
    let layers = (FREE_MAX_BOTTOM_M / step + 1e-3).floor() as usize;
    (0..=layers).map(|k| floor + k as f32 * step).collect()
}

/// The free window (see [`Support::Free`]): for every yaw of `scene`, every bottom of [`free_bottoms`]
/// and the centre of every lattice cell that holds a point, every size of `options`. A hypothesis is kept
/// when at least `options.min_points` points lie inside its box and [`SURFACE_CLEARANCE_M`] or more
/// above its bottom — as in [`surface_window`]: whatever a box stands on (floor, shelf, cabinet top) is
/// not the object — counted on ground cells × [`SURFACE_COUNT_CELL_M`] layers. `generated` counts the
/// hypotheses before the skipping test.
pub fn free_window(scene: &FeatureScene, options: &WindowOptions) -> HypothesisSet {
    single_window(scene, WindowRequest { support: Support::Free, options, surfaces: &[] })
}

/// Upward-facing points ([`normal_bin`] 0) a raised bottom of [`resting_window`] needs around a
/// centre: a pillow or lamp on a bed, sofa, nightstand or dresser has hundreds around it; 5 ignores the
/// odd stray normal on a wall.
///
/// [`normal_bin`]: crate::features::preprocess::normal_bin
pub const RESTING_MIN_UP_POINTS: u32 = 5;
/// Ground cells on each side of a centre's own cell that [`resting_window`] looks at for a top: 2, so a
/// 5 × 5 block (0.5 m × 0.5 m at the 0.1 m step) — what a small object stands on reaches beyond it
/// (3 cells kept the same calibration boxes within reach).
pub const RESTING_REACH_CELLS: i64 = 2;

/// The resting window (see [`Support::Resting`]): the boxes of [`free_window`], in its order, less those at
/// a raised bottom `b` (every bottom of [`free_bottoms`] but the floor) below the camera's height
/// (upright z 0) whose centre's ground cell and the [`RESTING_REACH_CELLS`] cells around it hold fewer than
/// [`RESTING_MIN_UP_POINTS`] upward-facing points within one step of `b` (the [`SURFACE_COUNT_CELL_M`]
/// layers whose centres lie in `b ± step`). Choices (made on the calibration set's window recall, README
/// "The free window"): one step rather than half, so a top keeps the two bottoms nearest it — the
/// window's best box for a thin pillow is often the layer just above or below its top (half a step lost
/// a tenth of the pillows at IoU 0.5); bottoms at or above the camera's height are always kept, because a
/// top there is seen edge-on or not at all (a lamp on a tall cabinet). The skipping test is the free
/// window's. `generated` counts the hypotheses at the bottoms and centres kept, before the skipping test.
pub fn resting_window(scene: &FeatureScene, options: &WindowOptions) -> HypothesisSet {
    single_window(scene, WindowRequest { support: Support::Resting, options, surfaces: &[] })
}

/// One yaw of the free window's boxes ([`free_window`]), with `on_seen_tops` only those of the resting
/// window ([`resting_window`]): one loop for both, so the resting window stays a subsequence of the free one.
fn layered_yaw(
    counts: &YawCounts,
    yaw_index: usize,
    options: &WindowOptions,
    on_seen_tops: bool,
    kept: &mut Vec<Hypothesis>,
) -> usize {
    let (grid, floor, table) = (counts.grid, counts.floor, counts.surface());
    let tops = on_seen_tops.then(|| counts.tops());
    let reach = RESTING_REACH_CELLS;
    let mut generated = 0;
    for (layer, bottom) in free_bottoms(floor, grid.step).into_iter().enumerate() {
        let z_cells = cells_above(bottom, floor);
        let needs_top = tops.filter(|_| layer > 0 && bottom < 0.0);
        let (z0, z1) = centred_cells(bottom - grid.step, bottom + grid.step, floor, SURFACE_COUNT_CELL_M);
        for (col, row) in occupied_cells(grid) {
            let (c, r) = (col as i64, row as i64);
            if needs_top.is_some_and(|t| {
                t.count([c - reach, r - reach, z0], [c + reach, r + reach, z1]) < RESTING_MIN_UP_POINTS
            }) {
                continue;
            }
            let centre = cell_centre(grid, col, row);
            generated += push_sizes(table, grid, (yaw_index, centre, bottom), options, &z_cells, kept);
        }
    }
    generated
}

/// The window of [`Support::FloorAndSurfaces`]: the hypotheses of [`sliding_window`] and then those of
/// [`surface_window`] on `surfaces`, each yaw's together and in yaw order (as every window's); `generated`
/// is the sum of the two. A surface at the floor's own height is the floor, searched by the floor window:
/// it is left out, so no box (same lattice cell, size and bottom) is scored twice.
pub fn floor_and_surface_window(
    scene: &FeatureScene,
    options: &WindowOptions,
    surfaces: &[SupportSurface],
) -> HypothesisSet {
    single_window(scene, WindowRequest { support: Support::FloorAndSurfaces, options, surfaces })
}

/// The window of `support` on `scene` with `options`: [`sliding_window`], [`surface_window`] on
/// `surfaces` (read only when [`Support::uses_surfaces`]), [`free_window`],
/// [`floor_and_surface_window`] or [`resting_window`].
pub fn window(
    support: Support,
    scene: &FeatureScene,
    options: &WindowOptions,
    surfaces: &[SupportSurface],
) -> HypothesisSet {
    single_window(scene, WindowRequest { support, options, surfaces })
}

impl Hypothesis {
    /// The hypothesis of an arbitrary upright cuboid (e.g. an annotation) whose yaw is that of
    /// `scene.yaws[yaw_index]` (the cuboid's own yaw is not read). `points_inside` is left 0.
    pub fn from_cuboid(scene: &FeatureScene, yaw_index: usize, cuboid: &Cuboid) -> Hypothesis {
        let grid = &scene.yaws[yaw_index];
        let c = cuboid.centre;
        Hypothesis {
            yaw_index: yaw_index as u16,
            size_index: 0,
            centre: Vec2::from(rotate(&c, grid.sin, grid.cos)),
            bottom: cuboid.bottom(),
            size: cuboid.size,
            points_inside: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{DepthSource, Frame};

    fn sample_scene() -> FeatureScene {
        let frame = Frame::read("assets/sample/synth-bedroom-s52", DepthSource::Raw).unwrap();
        let pre = Preprocessed::from_frame(&frame).unwrap();
        FeatureScene::new(pre, &[0.0, 0.7], 0.1)
    }

    /// Points of `grid` in ground cells `lo..=hi` and z cells (of `z_cell` from `floor`) `lo..=hi`, counted
    /// one by one: the table's independent reference.
    fn brute_count(grid: &YawGrid, floor: f32, z_cell: f32, nz: i64, lo: [i64; 3], hi: [i64; 3]) -> u32 {
        let mut n = 0;
        for row in 0..grid.cells[1] {
            for col in 0..grid.cells[0] {
                for r in &grid.records[grid.row_span(row, (col, col))] {
                    let z = floor_to_i64((r.z_metres() - floor) * (1.0 / z_cell)).clamp(0, nz - 1);
                    let cell = [col as i64, row as i64, z];
                    n += u32::from((0..3).all(|k| lo[k] <= cell[k] && cell[k] <= hi[k]));
                }
            }
        }
        n
    }

    #[test]
    fn table_counts_equal_points_counted_one_by_one() {
        let scene = sample_scene();
        let floor = scene.pre.floor;
        for grid in &scene.yaws {
            let table = CountTable::build(grid, floor, 0.1);
            let nz = table.dims[2] as i64;
            let [cs, ct] = [grid.cells[0] as i64, grid.cells[1] as i64];
            // Boxes of every shape, some reaching past the table or empty (hi < lo).
            let mut seed = 7u64;
            let mut next = |n: i64| {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((seed >> 33) % (n as u64 + 6)) as i64 - 3
            };
            for _ in 0..200 {
                let lo = [next(cs), next(ct), next(nz)];
                let hi = [lo[0] + next(cs / 2), lo[1] + next(ct / 2), lo[2] + next(nz)];
                assert_eq!(table.count(lo, hi), brute_count(grid, floor, 0.1, nz, lo, hi), "{lo:?}..={hi:?}");
            }
        }
    }

    /// The window's shared-footprint counting keeps exactly the boxes a count per size keeps, whatever the
    /// order of the sizes (product order, where footprints repeat, or shuffled, where they do not). The
    /// count per size is `CountTable::count`, checked against points counted one by one above.
    #[test]
    fn window_counts_equal_a_count_per_size_in_any_size_order() {
        let scene = sample_scene();
        let floor = scene.pre.floor;
        let widths = [0.4f32, 0.9, 1.6];
        let mut sizes: Vec<Vec3> = widths
            .iter()
            .flat_map(|&w| [0.5f32, 1.1].into_iter().flat_map(move |d| [0.3f32, 0.8, 1.9].map(|h| Vec3::new(w, d, h))))
            .collect();
        for shuffled in [false, true] {
            if shuffled {
                sizes.reverse();
                sizes.swap(1, 7);
            }
            let options = WindowOptions { sizes: sizes.clone(), min_points: 20 };
            let set = sliding_window(&scene, &options);
            let mut expected = Vec::new();
            for (yaw_index, grid) in scene.yaws.iter().enumerate() {
                let table = CountTable::build(grid, floor, grid.step);
                for centre in occupied_centres(grid) {
                    for (size_index, size) in sizes.iter().enumerate() {
                        let (s0, s1) =
                            centred_cells(centre.x - 0.5 * size.x, centre.x + 0.5 * size.x, grid.origin[0], grid.step);
                        let (t0, t1) =
                            centred_cells(centre.y - 0.5 * size.y, centre.y + 0.5 * size.y, grid.origin[1], grid.step);
                        let z1 = centred_cells(floor, floor + size.z, floor, grid.step).1;
                        let inside = table.count([s0, t0, 1], [s1, t1, z1]);
                        if inside >= options.min_points {
                            expected.push((yaw_index, size_index, centre, inside));
                        }
                    }
                }
            }
            let got: Vec<_> = set
                .hypotheses
                .iter()
                .map(|h| (h.yaw_index as usize, h.size_index as usize, h.centre, h.points_inside))
                .collect();
            assert!(expected.len() > 100, "{} boxes kept: too few to test", expected.len());
            assert_eq!(got, expected, "shuffled: {shuffled}");
        }
    }
}
