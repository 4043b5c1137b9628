//! Manhattan voxels (paper §5, Fig. "layout"), the cubical-voxel variant, and the scoring of hypotheses.
//!
//! # Cells
//! Per orientation the points are binned once into 5 cm ground cells of the room frame (cell `i` spans
//! `u ∈ [50·i, 50·i + 50)` mm, centre `50·i + 25`) × 6 height layers × 4 normal classes ([`YawCells`]). A
//! hypothesis assigns each *cell* (by its centre) to a region, so a region boundary is exact to ±2.5 cm and
//! every hypothesis of an orientation reuses the same bins: scoring is a sum over cells, not over points.
//!
//! # Height layers
//! 6 equal layers between the frame's floor and ceiling (paper); points below the floor or above the
//! ceiling count in the lowest or highest layer.
//!
//! # Regions, Manhattan (12 per layer)
//! With the inward distances of a cell centre to the four walls `d = [v1 − v, u − u0, v − v0, u1 − u]`
//! (front, left, back, right; negative outside), the region's wall is `w = argmin d` (first on ties) and
//! `dmin = d[w]`: interior `R_w` (`dmin > 150 mm`), wall band `R_{4+w}` (`|dmin| ≤ 150 mm`: the paper's
//! 0.15 m threshold, taken on both sides of the wall since the points of a wall scatter to both sides), or
//! exterior `R_{8+w}` (`dmin < −150 mm`). Taking the nearest wall inside and the farthest-out wall outside
//! is exactly "split at the corners by the diagonals": the borders are the 45° lines through the corners.
//!
//! # Regions, cubical (the comparison, 16 per layer)
//! The inside of the cuboid split into a 4 × 4 grid along `a` (`i`, from the left wall) and `b` (`j`, from
//! the back wall), region `4·j + i`; points outside the cuboid are ignored (the paper's criticism of it).
//!
//! # Descriptor per cell (our choice; paper: density, normals, COG)
//! Four normal classes, counted per region and layer and divided by the number of points of the frame:
//! for Manhattan regions relative to the region's wall — **facing** (|n·wall normal| ≥ cos 30°), **across**
//! (|n·other horizontal axis| ≥ cos 30°: the orthogonal walls), **horizontal** (|n_z| ≥ cos 30°: floor,
//! ceiling, table tops) and **other**; for cubical regions relative to the room axes (along a, along b,
//! horizontal, other). The point density is the sum of the four classes, so a linear model has it without
//! a separate entry.
//! Feature index: `(region·6 + layer)·4 + class`; Manhattan 12·6·4 = 288 voxel dimensions, cubical 16·6·4 =
//! 384.
//!
//! # COG (optional, [`Descriptor::cog`]; paper: the layout model "utilizes our COG descriptor")
//! The paper's COG (§3.2: 9 unsigned orientation bins laid on a plane of the voxel, projected into the image
//! where the gradient is, the magnitude split between the two nearest bins) adapted to the room: per point
//! (its pixel's gradient, `crate::features::preprocess::pixel_gradient`), the bins lie on a **wall plane**
//! through the point — plane 0 spanned by the room axis `a` and the vertical (the front and back walls),
//! plane 1 by `b` and the vertical (the left and right walls) — projected at the point itself (not at a
//! voxel centre: a room's cells are metres wide), with the detector's arithmetic
//! (`crate::features::cpu::cog_basis` and `cog_position`). A Manhattan region takes the histogram on its
//! wall's plane (front/back regions 0, 2, 4, 6, 8, 10: plane 0; left/right: plane 1), so "horizontal" and
//! "vertical" mean the same on every wall of every room; a cubical region on the cuboid's front face (plane
//! 0), as the detector's voxels. A plane seen edge-on at a point gets nothing from it. **Normalisation**
//! (our choice): the sums are divided by the frame's total gradient magnitude `Σ|g|` over its points
//! (contrast-invariant across frames), not by each cell's own norm as the paper's `φ/√(‖φ‖² + ε)` — a
//! per-cell norm is not linear in the points, and the scoring below needs each ground cell's contribution
//! to be independent of the rest of the hypothesis. Feature index `voxel_dim + (region·6 + layer)·9 + bin`
//! ([`Descriptor::cog_index`]): 648 dimensions for Manhattan voxels, 864 for cubical.
//!
//! After them come the [`BOX_FEATURES`] = 16 *box features*, computed per hypothesis on the CPU rather
//! than summed by the kernel: the 3 orientation features of [`super::orientation`] (the same for every
//! hypothesis of one orientation), then 4 **wall leaks**, per wall (front, left, back, right)
//! `sqrt(n_w / N)` with `n_w` the points whose cell centre lies more than the band (150 mm) beyond the wall's
//! line (the whole half-plane, corners included) and `N` the frame's points. The exterior regions hold the
//! same points linearly; the square root makes a few points behind a wall cost much more than their share
//! (our choice: the first model put walls on the fronts of counters and wardrobes, leaving the strip of
//! real wall visible above them outside the room); then 9 **reach** features of the front wall, with `r`
//! the distance in metres by which it lies beyond the outer edge `f` (metres from the camera) of the
//! farthest occupied cell in front (0 at or inside it), and `[m, n]` the orientation's
//! [`front_plane_evidence`] at `f` (the fraction of the rays through that plane that returned no depth, and
//! the fraction seen within 0.5 m of it): `[r > 0]`, `r`, `r²`, `[r > 0]·f`, `[r > 0]·m`, `r·m`, `r²·m`,
//! `[r > 0]·√n`, `r·√n`. The hypotheses include front walls 0.5, 1 and 2 m beyond the points for rooms
//! larger than the sensor's range ([`super`]'s module doc), and their voxel features are alike (nothing is
//! out there), so the model needs these to learn whether and how far to reach: the indicator and the square
//! let it prefer any of the four distances, and the products with the evidence let that preference depend
//! on whether the plane of the farthest points was seen (small `m`, or points on it: `n`) or not (`m` near
//! 1, `n` near 0); the square root of `n` because a seen wall near the range gives `n` of only 0.05–0.27.
//! 304 and 400 dimensions in all without COG, 952 and 1 264 with. With [`Descriptor::edges`] the 2
//! edge-orientation features of the orientation ([`super::orientation::edge_orientation_features`]) close
//! the vector, weighted on the CPU like the box features.
//!
//! # Scoring (the GPU kernel's twin)
//! `score(h) = w·φ(h)` is a sum over cells of a per-(cell, region) contribution, tabulated once per frame
//! and weight vector ([`ScoringTables`]) in fixed point: `round(x·2^e)` as i32, with `2^e` the largest
//! power of two such that, for every orientation, `Σ_cells max_region |x|·2^e ≤ 2^30`. A hypothesis's score
//! is then an i32 sum that cannot overflow and does not depend on summation order. The box features add
//! the integer `round(w_box·b(h)·2^e)` (i64, on the CPU: [`ScoringTables::total`]); the real score is
//! `(sum + that) / 2^e`. [`score_box`] is written like `shaders/room_layout.wgsl`.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

pub use super::orientation::{EDGE_FEATURES, ORIENTATION_FEATURES};
use super::{room_axes, to_mm, LayoutScene, RoomBox};
use crate::features::cpu::{cog_basis, cog_position};
pub use crate::features::feature_layout::COG_BINS;
use crate::features::preprocess::gradient_magnitude;

/// Wall-leak features per hypothesis (see the module doc).
pub const WALL_LEAK_FEATURES: usize = 4;
/// Reach features per hypothesis: the front wall's beyond, reach, reach², beyond × farthest, and beyond,
/// reach and reach² times the missing fraction, beyond and reach times √near (see the module doc).
pub const REACH_FEATURES: usize = 9;
/// Features of a hypothesis computed on the CPU: orientation, then wall leaks, then reach.
pub const BOX_FEATURES: usize = ORIENTATION_FEATURES + WALL_LEAK_FEATURES + REACH_FEATURES;

/// Ground-cell side, millimetres.
pub const CELL_MM: i32 = 50;
/// Half-width of the wall bands, millimetres (paper: 0.15 m).
pub const BAND_MM: i32 = 150;
/// Equal height layers between floor and ceiling (paper: 6).
pub const LAYERS: usize = 6;
/// Normal classes per layer and region.
pub const NORMAL_CLASSES: usize = 4;
/// Bins of one cell: layers × normal classes.
pub const CELL_BINS: usize = LAYERS * NORMAL_CLASSES;
/// Normal classes in the room frame: the normal is (anti)parallel to `a`, to `b`, vertical, or none.
pub const ALONG_A: u32 = 0;
pub const ALONG_B: u32 = 1;
pub const HORIZONTAL: u32 = 2;
pub const OTHER: u32 = 3;
/// `cos 30°`: a normal within 30° of an axis belongs to that axis's class.
pub const AXIS_COS: f32 = 0.866_025_4;
/// Manhattan regions per layer; cubical regions per layer and splits per horizontal axis.
pub const MANHATTAN_REGIONS: u32 = 12;
pub const CUBICAL_SPLITS: i32 = 4;
pub const CUBICAL_REGIONS: u32 = (CUBICAL_SPLITS * CUBICAL_SPLITS) as u32;
/// A cell in no region (cubical voxels: outside the cuboid).
pub const NO_REGION: u32 = u32::MAX;
/// Fixed-point budget: per-orientation sums of the largest |contribution| stay below 2^30.
const SCORE_BUDGET: f64 = (1u64 << 30) as f64;
/// The largest fixed-point scale, and the scale of a model whose voxel weights are all zero: the box and
/// edge features' term (`ScoringTables::total`, rounded to 1/scale in an `i64`) keeps 2⁻³² of resolution
/// without overflowing, where the voxel budget alone would give a scale of 1 (zero voxel weights: the box
/// term rounded to whole units, until 2026-12-08) or an overflowing one (tiny voxel weights). Trained models
/// have scales far below it (their voxel sums reach the budget at about 2²⁰).
const MAX_SCALE: f64 = (1u64 << 32) as f64;

/// How a hypothesis's space is divided into feature cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Discretisation {
    /// The paper's Manhattan voxels: 12 regions × 6 layers.
    Manhattan,
    /// Regular voxels inside the cuboid: 4 × 4 × 6.
    Cubical,
}

impl Discretisation {
    pub fn regions(self) -> u32 {
        match self {
            Discretisation::Manhattan => MANHATTAN_REGIONS,
            Discretisation::Cubical => CUBICAL_REGIONS,
        }
    }

    /// Length of the voxel part of the feature vector (the box features follow it).
    pub fn voxel_dim(self) -> usize {
        self.regions() as usize * CELL_BINS
    }

    /// Length of the feature vector: the voxel features, then the box features.
    pub fn dim(self) -> usize {
        self.voxel_dim() + BOX_FEATURES
    }

    pub fn name(self) -> &'static str {
        match self {
            Discretisation::Manhattan => "manhattan",
            Discretisation::Cubical => "cubical",
        }
    }

    /// The region of a cell centre `(u, v)` (millimetres) for `room_box`, or [`NO_REGION`].
    pub fn region(self, u: i32, v: i32, room_box: &RoomBox) -> u32 {
        match self {
            Discretisation::Manhattan => manhattan_region(u, v, room_box),
            Discretisation::Cubical => cubical_region(u, v, room_box),
        }
    }

    /// The feature class of a point of room-frame class `class` in region `region`.
    pub fn feature_class(self, region: u32, class: u32) -> u32 {
        match self {
            // Walls 0 and 2 (front, back) have normals ±b, walls 1 and 3 ±a: "facing" is class 0.
            Discretisation::Manhattan => match (class, region.is_multiple_of(2)) {
                (ALONG_B, true) | (ALONG_A, false) => 0,
                (ALONG_A, true) | (ALONG_B, false) => 1,
                (other, _) => other,
            },
            Discretisation::Cubical => class,
        }
    }
}

/// The wall planes a COG histogram is taken on (see the module doc): plane 0 is spanned by the room axis `a`
/// and the vertical (the front and back walls), plane 1 by `b` and the vertical (the left and right walls).
pub const COG_PLANES: usize = 2;

/// What a layout model's feature vector holds: the voxel discretisation, whether the COG histograms follow
/// the voxel features, and whether the edge-orientation features
/// ([`super::orientation::edge_orientation_features`]) follow the box features (see the module doc). Models
/// without them (format version 3 files written before them lack the fields) are read with both false.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Descriptor {
    pub discretisation: Discretisation,
    #[serde(default)]
    pub cog: bool,
    #[serde(default)]
    pub edges: bool,
}

impl Descriptor {
    pub fn new(discretisation: Discretisation, cog: bool, edges: bool) -> Descriptor {
        Descriptor { discretisation, cog, edges }
    }

    pub fn regions(self) -> u32 {
        self.discretisation.regions()
    }

    /// Length of the voxel (point-count) part of the feature vector.
    pub fn voxel_dim(self) -> usize {
        self.discretisation.voxel_dim()
    }

    /// Length of the COG part (0 without COG): regions × layers × [`COG_BINS`].
    pub fn cog_dim(self) -> usize {
        if self.cog {
            self.regions() as usize * LAYERS * COG_BINS
        } else {
            0
        }
    }

    /// Index of the first box feature.
    pub fn box_start(self) -> usize {
        self.voxel_dim() + self.cog_dim()
    }

    /// Length of the feature vector: voxel features, COG features, the box features, then the edge-orientation
    /// features.
    pub fn dim(self) -> usize {
        self.box_start() + BOX_FEATURES + if self.edges { EDGE_FEATURES } else { 0 }
    }

    /// `manhattan` or `cubical`, then `+cog` and `+edges` for what the model adds.
    pub fn name(self) -> String {
        let (cog, edges) = (if self.cog { "+cog" } else { "" }, if self.edges { "+edges" } else { "" });
        format!("{}{cog}{edges}", self.discretisation.name())
    }

    /// The COG plane of region `region` (see the module doc): a Manhattan region's wall's plane, for cubical
    /// voxels the cuboid's front face (plane 0, as the detector's voxels).
    pub fn cog_plane(self, region: u32) -> usize {
        match self.discretisation {
            Discretisation::Manhattan => (region % 2) as usize,
            Discretisation::Cubical => 0,
        }
    }

    /// Index of (region, layer, COG bin) in the feature vector.
    pub fn cog_index(self, region: u32, layer: usize, bin: usize) -> usize {
        self.voxel_dim() + (region as usize * LAYERS + layer) * COG_BINS + bin
    }
}

/// One point's COG contribution in one orientation (see the module doc): its height layer, and per COG
/// plane the lower of its two orientation bins and the gradient magnitude's shares of the two (0 where the
/// plane is seen edge-on).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CogPoint {
    pub layer: u8,
    pub bin0: [u8; COG_PLANES],
    pub shares: [[f32; 2]; COG_PLANES],
}

/// One orientation's COG planes in camera coordinates: the horizontal axis of each plane (`a`, then `b`) and
/// the vertical — the same for every point of the orientation, so made once per orientation.
#[derive(Clone, Copy, Debug)]
pub struct CogAxes {
    pub along: [Vec3; COG_PLANES],
    pub up: Vec3,
}

impl CogAxes {
    pub fn new(camera: &crate::geometry::Camera, a: Vec2, b: Vec2) -> CogAxes {
        CogAxes { along: [a, b].map(|axis| camera.to_camera(axis.extend(0.0))), up: camera.to_camera(Vec3::Z) }
    }
}

impl CogPoint {
    /// The COG contribution of the point `p` (upright) with image gradient `g`, on the planes `axes`.
    pub fn new(scene: &LayoutScene, axes: &CogAxes, p: Vec3, g: Vec2) -> CogPoint {
        let camera = &scene.camera;
        let at = camera.to_camera(p);
        let magnitude = gradient_magnitude(g);
        let mut out = CogPoint { layer: layer(p.z, scene.floor, scene.ceiling) as u8, ..CogPoint::default() };
        for (plane, &along) in axes.along.iter().enumerate() {
            if let Some(frame) = cog_basis(camera.intrinsics, at, along, axes.up) {
                let (bin0, frac) = cog_position(&frame, g.x, g.y);
                out.bin0[plane] = bin0 as u8;
                out.shares[plane] = [(1.0 - frac) * magnitude, frac * magnitude];
            }
        }
        out
    }

    /// Hands `add(layer, bin, share · norm)` this point's two bins on `plane` — the one accumulation that
    /// [`features`] and [`ScoringTables::new`] share.
    fn accumulate(&self, plane: usize, norm: f64, mut add: impl FnMut(usize, usize, f64)) {
        let bin0 = self.bin0[plane] as usize;
        let [s0, s1] = self.shares[plane];
        add(self.layer as usize, bin0, s0 as f64 * norm);
        add(self.layer as usize, (bin0 + 1) % COG_BINS, s1 as f64 * norm);
    }
}

/// Manhattan region of a cell centre (see the module doc). Twin of `manhattan_region` in the shader.
pub fn manhattan_region(u: i32, v: i32, b: &RoomBox) -> u32 {
    let d = [b.v1 - v, u - b.u0, v - b.v0, b.u1 - u];
    let mut wall = 0u32;
    let mut dmin = d[0];
    for (w, &dw) in d.iter().enumerate().skip(1) {
        if dw < dmin {
            dmin = dw;
            wall = w as u32;
        }
    }
    if dmin > BAND_MM {
        wall
    } else if dmin >= -BAND_MM {
        4 + wall
    } else {
        8 + wall
    }
}

/// Cubical region of a cell centre (see the module doc). Twin of `cubical_region` in the shader.
pub fn cubical_region(u: i32, v: i32, b: &RoomBox) -> u32 {
    if u < b.u0 || u > b.u1 || v < b.v0 || v > b.v1 {
        return NO_REGION;
    }
    let i = (CUBICAL_SPLITS * (u - b.u0) / (b.u1 - b.u0)).min(CUBICAL_SPLITS - 1);
    let j = (CUBICAL_SPLITS * (v - b.v0) / (b.v1 - b.v0)).min(CUBICAL_SPLITS - 1);
    (j * CUBICAL_SPLITS + i) as u32
}

/// Room-frame class of a unit normal (see the module doc).
pub fn normal_class(n: Vec3, a: Vec2, b: Vec2) -> u32 {
    let h = n.truncate();
    if n.z.abs() >= AXIS_COS {
        HORIZONTAL
    } else if h.dot(a).abs() >= AXIS_COS {
        ALONG_A
    } else if h.dot(b).abs() >= AXIS_COS {
        ALONG_B
    } else {
        OTHER
    }
}

/// Height layer of `z` between `floor` and `ceiling` (clamped to the end layers).
pub fn layer(z: f32, floor: f32, ceiling: f32) -> usize {
    let t = (z - floor) / (ceiling - floor) * LAYERS as f32;
    (t.floor().max(0.0) as usize).min(LAYERS - 1)
}

/// Index of the cell containing coordinate `mm`.
fn cell_index(mm: i32) -> i32 {
    mm.div_euclid(CELL_MM)
}

/// Centre (mm) of cell `i`.
pub fn cell_centre(i: i32) -> i32 {
    i * CELL_MM + CELL_MM / 2
}

/// First cell whose centre is ≥ `mm`.
fn first_cell_at_or_after(mm: i32) -> i32 {
    -(-(mm - CELL_MM / 2)).div_euclid(CELL_MM)
}

/// One orientation's points binned into ground cells (see the module doc).
#[derive(Clone, Debug)]
pub struct YawCells {
    pub yaw_index: u32,
    /// Occupied cells' centres `(u, v)` in millimetres, sorted by (v, u).
    pub centres: Vec<[i32; 2]>,
    /// Per occupied cell, point counts by `layer·4 + class`.
    pub bins: Vec<[u16; CELL_BINS]>,
    /// Points of the frame (all of them land in some cell).
    pub total_points: u32,
    /// The orientation's features ([`super::orientation::orientation_features`]): filled by
    /// [`super::hypotheses`], which sees every orientation; 0 from [`YawCells::new`] alone.
    pub orientation: [f32; ORIENTATION_FEATURES],
    /// The orientation's edge-orientation features ([`super::orientation::edge_orientation_features`]): filled
    /// by [`super::hypotheses`] when asked for; 0 otherwise.
    pub edge_orientation: [f32; EDGE_FEATURES],
    /// [`front_plane_evidence`] at [`YawCells::farthest_front`]: `[missing, near]`, whether the sensor saw
    /// the plane of the farthest points in front.
    pub front_evidence: [f32; 2],
    /// With COG ([`YawCells::new`]'s `cog`): the points' [`CogPoint`]s grouped by cell, cell `c`'s at
    /// `cog_points[cog_offsets[c] .. cog_offsets[c + 1]]`; both empty without.
    pub cog_offsets: Vec<u32>,
    pub cog_points: Vec<CogPoint>,
    /// `1 / Σ|g|` over the frame's points (0 when the image has no gradient): COG features are fractions of
    /// the frame's gradient magnitude.
    pub cog_norm: f64,
    /// Dense summed-area table of point counts over cells `origin .. origin + size`, `(size + 1)²` entries.
    origin: [i32; 2],
    size: [usize; 2],
    table: Vec<u32>,
}

impl YawCells {
    /// Bins the points for orientation `yaw_index`; `cog` adds their [`CogPoint`]s (a model with COG
    /// features needs them; they cost time and memory, so the others go without).
    pub fn new(scene: &LayoutScene, yaw_index: usize, cog: bool) -> YawCells {
        let (a, b) = room_axes(yaw_index);
        let mut keyed: Vec<([i32; 2], usize, usize)> = scene
            .points
            .iter()
            .zip(&scene.normals)
            .enumerate()
            .map(|(i, (p, n))| {
                let cell = [cell_index(to_mm(p.truncate().dot(b))), cell_index(to_mm(p.truncate().dot(a)))];
                let bin = layer(p.z, scene.floor, scene.ceiling) * NORMAL_CLASSES + normal_class(*n, a, b) as usize;
                (cell, bin, i)
            })
            .collect();
        keyed.sort_unstable();
        let mut centres: Vec<[i32; 2]> = Vec::new();
        let mut bins: Vec<[u16; CELL_BINS]> = Vec::new();
        let (mut cog_offsets, mut cog_points) = (Vec::new(), Vec::new());
        let cog_axes = CogAxes::new(&scene.camera, a, b);
        for &([j, i], bin, point) in &keyed {
            let centre = [cell_centre(i), cell_centre(j)];
            if centres.last() != Some(&centre) {
                centres.push(centre);
                bins.push([0; CELL_BINS]);
                if cog {
                    cog_offsets.push(cog_points.len() as u32);
                }
            }
            let last = bins.len() - 1;
            bins[last][bin] = bins[last][bin].saturating_add(1);
            if cog {
                cog_points.push(CogPoint::new(scene, &cog_axes, scene.points[point], scene.gradients[point]));
            }
        }
        if cog {
            cog_offsets.push(cog_points.len() as u32);
        }
        let magnitude: f64 =
            if cog { scene.gradients.iter().map(|&g| gradient_magnitude(g) as f64).sum() } else { 0.0 };
        let cog_norm = if magnitude > 0.0 { 1.0 / magnitude } else { 0.0 };
        let (lo_i, hi_i) = keyed.iter().fold((i32::MAX, i32::MIN), |(lo, hi), k| (lo.min(k.0[1]), hi.max(k.0[1])));
        let (lo_j, hi_j) = (keyed.first().map_or(0, |k| k.0[0]), keyed.last().map_or(0, |k| k.0[0]));
        let origin = if keyed.is_empty() { [0, 0] } else { [lo_i, lo_j] };
        let size = if keyed.is_empty() { [0, 0] } else { [(hi_i - lo_i + 1) as usize, (hi_j - lo_j + 1) as usize] };
        let stride = size[0] + 1;
        let mut table = vec![0u32; stride * (size[1] + 1)];
        for &([j, i], _, _) in &keyed {
            table[(j - origin[1] + 1) as usize * stride + (i - origin[0] + 1) as usize] += 1;
        }
        for row in 1..=size[1] {
            for col in 1..=size[0] {
                table[row * stride + col] += table[(row - 1) * stride + col] + table[row * stride + col - 1]
                    - table[(row - 1) * stride + col - 1];
            }
        }
        let mut cells = YawCells {
            yaw_index: yaw_index as u32,
            front_evidence: [0.0; 2],
            centres,
            bins,
            total_points: keyed.len() as u32,
            orientation: [0.0; ORIENTATION_FEATURES],
            edge_orientation: [0.0; EDGE_FEATURES],
            cog_offsets,
            cog_points,
            cog_norm,
            origin,
            size,
            table,
        };
        cells.front_evidence = front_plane_evidence(scene, b, cells.farthest_front() as f32 / 1000.0);
        cells
    }

    /// The [`CogPoint`]s of occupied cell `cell` (none without COG).
    pub fn cog_of_cell(&self, cell: usize) -> &[CogPoint] {
        match (self.cog_offsets.get(cell), self.cog_offsets.get(cell + 1)) {
            (Some(&lo), Some(&hi)) => &self.cog_points[lo as usize..hi as usize],
            _ => &[],
        }
    }

    /// Points whose cell centre lies inside the box's footprint (walls inclusive).
    pub fn points_inside(&self, b: &RoomBox) -> u64 {
        self.points_in([b.u0, b.u1], [b.v0, b.v1])
    }

    /// Per wall (front, left, back, right), the points whose cell centre lies more than [`BAND_MM`] beyond
    /// the wall's line, on its outer side.
    pub fn points_beyond_walls(&self, b: &RoomBox) -> [u64; 4] {
        const FAR: i32 = i32::MAX / 4;
        [
            self.points_in([-FAR, FAR], [b.v1 + BAND_MM + 1, FAR]),
            self.points_in([-FAR, b.u0 - BAND_MM - 1], [-FAR, FAR]),
            self.points_in([-FAR, FAR], [-FAR, b.v0 - BAND_MM - 1]),
            self.points_in([b.u1 + BAND_MM + 1, FAR], [-FAR, FAR]),
        ]
    }

    /// How far (millimetres, ≥ 0) the front wall lies beyond [`YawCells::farthest_front`] — the reach of
    /// the box features (see the module doc); 0 when it is at or inside it.
    pub fn front_reach(&self, b: &RoomBox) -> i32 {
        (b.v1 - self.farthest_front()).max(0)
    }

    /// The outer edge `v` (millimetres) of the farthest occupied cell in front of the camera: its distance
    /// along the front wall's normal (0 when the frame has no points in front).
    pub fn farthest_front(&self) -> i32 {
        if self.size == [0, 0] {
            return 0;
        }
        ((self.origin[1] + self.size[1] as i32) * CELL_MM).max(0)
    }

    /// Points whose cell centre `(u, v)` lies in `[u_lo, u_hi] × [v_lo, v_hi]` (millimetres, inclusive).
    fn points_in(&self, [u_lo, u_hi]: [i32; 2], [v_lo, v_hi]: [i32; 2]) -> u64 {
        let clamp = |lo: i32, hi: i32, axis: usize| -> Option<(usize, usize)> {
            let first = (first_cell_at_or_after(lo) - self.origin[axis]).max(0);
            let last = (cell_index(hi - CELL_MM / 2) - self.origin[axis]).min(self.size[axis] as i32 - 1);
            (first <= last).then(|| (first as usize, last as usize + 1))
        };
        let (Some((i0, i1)), Some((j0, j1))) = (clamp(u_lo, u_hi, 0), clamp(v_lo, v_hi, 1)) else { return 0 };
        let stride = self.size[0] + 1;
        let at = |row: usize, col: usize| self.table[row * stride + col] as i64;
        (at(j1, i1) - at(j0, i1) - at(j1, i0) + at(j0, i0)) as u64
    }
}

/// Distance (metres, along the front wall's normal) within which a point counts as seen **at** the front
/// plane ([`front_plane_evidence`]).
pub const FRONT_NEAR_M: f32 = 0.5;

/// What the sensor saw along the rays that cross the plane `v = front_m` (metres along the room axis `b`, in
/// front of the camera) between the floor and the ceiling — the frame's rays are the points' directions
/// and [`LayoutScene::missing_rays`]: `[missing, near]`, the fraction of those rays that returned no depth
/// and the fraction whose point lies within [`FRONT_NEAR_M`] of the plane; `[0, 0]` when none crosses it
/// (`front_m` ≤ 0: no points in front).
///
/// Our evidence for a front wall beyond the sensor's range (the paper's walls stop at the farthest point;
/// our hypotheses reach past it, see [`super`]'s module doc). On the validation frames (seed 13) the 14 of
/// 100 rooms whose front wall lies more than 0.3 m beyond the farthest point have `missing` 0.49–0.96 and
/// `near` ≤ 0.002 (but one: 0.01 and 0.009): the rays through the plane return nothing, and what they do
/// return is short of it (furniture, side walls). A wall seen at the farthest points has `missing` 0–0.4
/// (nearer walls; `near` 0.02–1) or, for the 11 near the sensor's range, whose returns fade out, up to
/// 0.86, and then `near` 0.05–0.27 (its own points) for all but four (0.003–0.007), which lie within
/// 0.15 m of the farthest point (ambiguous to any evidence). A ray's
/// direction is what counts (a point on a chair in front of the plane still says that the sensor saw along
/// that ray); the side walls are ignored (the plane is unbounded across).
pub fn front_plane_evidence(scene: &LayoutScene, b: Vec2, front_m: f32) -> [f32; 2] {
    if front_m <= 0.0 {
        return [0.0; 2];
    }
    let crosses = |d: &Vec3| {
        let along = d.truncate().dot(b);
        if along <= 0.0 {
            return false;
        }
        let z = front_m * d.z / along;
        z > scene.floor && z < scene.ceiling
    };
    let (mut seen, mut near) = (0usize, 0usize);
    for p in scene.points.iter().filter(|p| crosses(p)) {
        seen += 1;
        near += usize::from((p.truncate().dot(b) - front_m).abs() <= FRONT_NEAR_M);
    }
    let missing = scene.missing_rays.iter().filter(|d| crosses(d)).count();
    let crossing = seen + missing;
    if crossing == 0 {
        [0.0; 2]
    } else {
        [missing as f32 / crossing as f32, near as f32 / crossing as f32]
    }
}

/// The feature vector `φ(h)` of one hypothesis (see the module doc), length `desc.dim()`.
pub fn features(desc: Descriptor, cells: &YawCells, room_box: &RoomBox) -> Vec<f32> {
    let disc = desc.discretisation;
    let mut out = vec![0f64; desc.dim()];
    let norm = 1.0 / cells.total_points.max(1) as f64;
    for (cell, (centre, bins)) in cells.centres.iter().zip(&cells.bins).enumerate() {
        let region = disc.region(centre[0], centre[1], room_box);
        if region == NO_REGION {
            continue;
        }
        for (bin, &count) in bins.iter().enumerate() {
            if count > 0 {
                let (layer, class) = (bin / NORMAL_CLASSES, bin % NORMAL_CLASSES);
                let index = feature_index(region, layer, disc.feature_class(region, class as u32));
                out[index] += count as f64 * norm;
            }
        }
        if desc.cog {
            for point in cells.cog_of_cell(cell) {
                point.accumulate(desc.cog_plane(region), cells.cog_norm, |layer, bin, x| {
                    out[desc.cog_index(region, layer, bin)] += x
                });
            }
        }
    }
    let first_box = desc.box_start();
    for (j, x) in box_features(cells, room_box).into_iter().enumerate() {
        out[first_box + j] = x;
    }
    if desc.edges {
        for (j, &x) in cells.edge_orientation.iter().enumerate() {
            out[first_box + BOX_FEATURES + j] = x as f64;
        }
    }
    out.into_iter().map(|x| x as f32).collect()
}

/// The box features of one hypothesis (see the module doc): orientation, then wall leaks, then reach.
pub fn box_features(cells: &YawCells, room_box: &RoomBox) -> [f64; BOX_FEATURES] {
    let mut out = [0.0; BOX_FEATURES];
    for (j, &o) in cells.orientation.iter().enumerate() {
        out[j] = o as f64;
    }
    let total = cells.total_points.max(1) as f64;
    for (j, n) in cells.points_beyond_walls(room_box).into_iter().enumerate() {
        out[ORIENTATION_FEATURES + j] = (n as f64 / total).sqrt();
    }
    let reach_mm = cells.front_reach(room_box);
    let (beyond, reach) = (if reach_mm > 0 { 1.0 } else { 0.0 }, reach_mm as f64 / 1000.0);
    let first = ORIENTATION_FEATURES + WALL_LEAK_FEATURES;
    let [missing, near] = cells.front_evidence.map(|x| x as f64);
    let near = near.sqrt();
    out[first..first + REACH_FEATURES].copy_from_slice(&[
        beyond,
        reach,
        reach * reach,
        beyond * cells.farthest_front() as f64 / 1000.0,
        beyond * missing,
        reach * missing,
        reach * reach * missing,
        beyond * near,
        reach * near,
    ]);
    out
}

/// Index of (region, layer, feature class) in the feature vector.
pub fn feature_index(region: u32, layer: usize, class: u32) -> usize {
    (region as usize * LAYERS + layer) * NORMAL_CLASSES + class as usize
}

/// Per orientation, per occupied cell, per region: the fixed-point contribution to `w·φ` (see the module
/// doc). `contributions[k][cell·regions + region]`.
#[derive(Clone, Debug)]
pub struct ScoringTables {
    pub discretisation: Discretisation,
    /// Real score = integer score / `scale`.
    pub scale: f64,
    pub contributions: Vec<Vec<i32>>,
    /// The weights of the box features.
    pub box_weights: [f64; BOX_FEATURES],
    /// The weights of the edge-orientation features (0 for a model without them).
    pub edge_weights: [f64; EDGE_FEATURES],
}

impl ScoringTables {
    pub fn new(desc: Descriptor, cells: &[YawCells], w: &[f64]) -> ScoringTables {
        let disc = desc.discretisation;
        let regions = disc.regions() as usize;
        let real: Vec<Vec<f64>> = cells
            .par_iter()
            .map(|yaw| {
                let norm = 1.0 / yaw.total_points.max(1) as f64;
                let mut out = vec![0.0; yaw.bins.len() * regions];
                for (c, bins) in yaw.bins.iter().enumerate() {
                    for r in 0..regions {
                        let mut x = 0.0;
                        for (bin, &count) in bins.iter().enumerate() {
                            if count > 0 {
                                let class = disc.feature_class(r as u32, (bin % NORMAL_CLASSES) as u32);
                                x += count as f64 * w[feature_index(r as u32, bin / NORMAL_CLASSES, class)];
                            }
                        }
                        x *= norm;
                        if desc.cog {
                            for point in yaw.cog_of_cell(c) {
                                point.accumulate(desc.cog_plane(r as u32), yaw.cog_norm, |layer, bin, v| {
                                    x += v * w[desc.cog_index(r as u32, layer, bin)]
                                });
                            }
                        }
                        out[c * regions + r] = x;
                    }
                }
                out
            })
            .collect();
        let bound = real
            .iter()
            .map(|yaw| yaw.chunks(regions).map(|c| c.iter().fold(0f64, |m, x| m.max(x.abs()))).sum::<f64>())
            .fold(0f64, f64::max);
        let scale = if bound > 0.0 {
            2f64.powi((SCORE_BUDGET / bound).log2().floor() as i32).min(MAX_SCALE)
        } else {
            MAX_SCALE
        };
        let contributions = real.iter().map(|yaw| yaw.iter().map(|x| (x * scale).round() as i32).collect()).collect();
        let mut box_weights = [0.0; BOX_FEATURES];
        box_weights.copy_from_slice(&w[desc.box_start()..desc.box_start() + BOX_FEATURES]);
        let mut edge_weights = [0.0; EDGE_FEATURES];
        if desc.edges {
            edge_weights.copy_from_slice(&w[desc.box_start() + BOX_FEATURES..desc.dim()]);
        }
        ScoringTables { discretisation: disc, scale, contributions, box_weights, edge_weights }
    }

    /// The whole fixed-point score of `room_box` given its voxel score (the kernel's or [`score_box`]'s) and
    /// its orientation's cells: the voxel score plus `round((w_box·b(h) + w_edges·e(k))·scale)`. The real score is this divided
    /// by `scale`.
    pub fn total(&self, cells: &YawCells, room_box: &RoomBox, voxel_score: i32) -> i64 {
        let boxes: f64 = box_features(cells, room_box).iter().zip(&self.box_weights).map(|(&b, &w)| b * w).sum();
        let edges: f64 = cells.edge_orientation.iter().zip(&self.edge_weights).map(|(&e, &w)| e as f64 * w).sum();
        let x = boxes + edges;
        voxel_score as i64 + (x * self.scale).round() as i64
    }

    /// [`ScoringTables::total`] of every hypothesis, given their voxel scores (in the same order).
    pub fn totals(&self, cells: &[YawCells], boxes: &[RoomBox], voxel_scores: &[i32]) -> Vec<i64> {
        boxes.iter().zip(voxel_scores).map(|(b, &s)| self.total(&cells[b.yaw_index as usize], b, s)).collect()
    }
}

/// Integer score of one hypothesis: the sum over its orientation's cells of the contribution of the cell's
/// region (0 for no region). Twin of the shader's per-invocation loop.
pub fn score_box(disc: Discretisation, centres: &[[i32; 2]], contributions: &[i32], room_box: &RoomBox) -> i32 {
    let regions = disc.regions() as usize;
    let mut total = 0i32;
    for (cell, centre) in centres.iter().enumerate() {
        let region = disc.region(centre[0], centre[1], room_box);
        if region != NO_REGION {
            total = total.wrapping_add(contributions[cell * regions + region as usize]);
        }
    }
    total
}

/// Integer scores of many hypotheses on the CPU (rayon), in their order.
pub fn scores_cpu(cells: &[YawCells], tables: &ScoringTables, boxes: &[RoomBox]) -> Vec<i32> {
    boxes
        .par_iter()
        .map(|b| {
            let k = b.yaw_index as usize;
            score_box(tables.discretisation, &cells[k].centres, &tables.contributions[k], b)
        })
        .collect()
}
