//! Per-frame preprocessing (paper §3.1–3.2): image gradients, per-point normals, the 25-bin normal code
//! and the floor height.
//!
//! Everything here is computed once per frame and shared by every hypothesis.

use std::f32::consts::{FRAC_PI_4, FRAC_PI_8, PI};
use std::num::NonZeroUsize;

use glam::{DMat3, DVec3, Vec2, Vec3};
use rayon::prelude::*;

use super::scene::floor_to_i64;
use crate::error::{Error, Result};
use crate::frame::{Frame, PointCloud};
use crate::geometry::Camera;

/// Neighbours of the plane fit that gives a point's normal (paper §3.1.2, after Song & Xiao).
pub const NORMAL_NEIGHBOURS: usize = 15;
/// Neighbours of each plane fit with [`NormalSearch::KdTreeWide`].
pub const WIDE_NORMAL_NEIGHBOURS: usize = 40;

/// Quantile of the point heights taken as the floor (the paper's layout section, §6: floors at the 0.001
/// quantile of the points along gravity).
pub const FLOOR_QUANTILE: f64 = 0.001;

/// Horizontal cell (metres, on the upright x and y) of the floor-plane test of [`Preprocessed::unseen_floor`].
pub const FLOOR_PLANE_CELL_M: f32 = 0.2;
/// Height band above [`Preprocessed::floor`] (metres) whose upward-facing points ([`normal_bin`] 0) make
/// the floor plane of [`Preprocessed::unseen_floor`]'s test: wide enough for the depth noise of a floor a
/// few metres away around its 0.001 quantile.
pub const FLOOR_PLANE_BAND_M: f32 = 0.1;
/// Fewest [`FLOOR_PLANE_CELL_M`] cells (0.4 m² at 0.2 m) of upward-facing points in the band for the lowest
/// points to be taken for a floor seen by the camera ([`Preprocessed::unseen_floor`]).
pub const FLOOR_PLANE_MIN_CELLS: usize = 10;
/// Camera height above the floor (metres) assumed where the floor is not seen
/// ([`Preprocessed::unseen_floor`]): SUN RGB-D's, from the bottoms of its floor-standing objects relative
/// to the camera (`../shared/data/sunrgbd-size-stats.json`, `bottom_z_rel_camera_m`: medians 1.20–1.37 m
/// over the ten categories, 1.35 m for the chairs, 10 481 of its 17 273 boxes), rounded down.
pub const UNSEEN_FLOOR_CAMERA_HEIGHT_M: f32 = 1.3;
/// Least height of the camera above a floor it sees (metres): lowest points less than this below the
/// camera are a top or the bottom of something the picture cuts, not the floor, however large a plane
/// they make ([`Preprocessed::unseen_floor`]). SUN RGB-D's cameras stand higher: its floor-standing
/// objects' bottoms lie at least 1.04–1.20 m below the camera in nine of ten boxes
/// (`../shared/data/sunrgbd-size-stats.json`, `bottom_z_rel_camera_m`, 0.9 quantiles of the nine
/// categories that stand on the floor — the bookshelf, often on a table, left out), and a floor lies below
/// what stands on it; rounded down. Not chosen on synthetic frames (synth's cameras stand 1.0–1.7 m high).
pub const MIN_CAMERA_HEIGHT_M: f32 = 1.0;

/// Why the lowest points of a frame are not a floor the camera sees ([`Preprocessed::lowest_points_not_floor`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NotFloor {
    /// Less than [`MIN_CAMERA_HEIGHT_M`] below the camera: a top or a cut object, however large a plane.
    TooHigh,
    /// Fewer than [`FLOOR_PLANE_MIN_CELLS`] cells of upward-facing points ([`Preprocessed::floor_plane_cells`]).
    NoPlane,
}

impl std::fmt::Display for NotFloor {
    /// What the lowest points are, as `detect`'s and `info`'s lines say it ("the lowest points …").
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotFloor::TooHigh => write!(f, "less than {MIN_CAMERA_HEIGHT_M} m below the camera"),
            NotFloor::NoPlane => f.write_str("holding no horizontal plane"),
        }
    }
}

/// Number of bins of the normal orientation code.
pub const NORMAL_BINS: usize = 25;

/// `cos 22.5°`: normals within 22.5° of straight up fall into bin 0 of the normal code.
const UP_CONE_COS: f32 = 0.923_879_5;
/// `sin 22.5°`: the elevation ring boundary between "tilted" and "near-horizontal" normals.
const RING_SIN: f32 = 0.382_683_43;

/// Image gradients of an RGB image with the filters `[−1, 0, 1]` and `[−1, 0, 1]ᵀ`, no smoothing.
///
/// Intensities are scaled to [0, 1], so `|dx|, |dy| ≤ 1` and magnitudes are at most √2. At the image
/// border the missing neighbour is replaced by the border pixel itself (replicate padding), so the border
/// gradient is a one-sided difference `I(1) − I(0)` (HOG's implementations use the same). For every pixel
/// the colour channel with the largest magnitude `dx² + dy²`, as computed in f32, gives (dx, dy) (ties of
/// the computed magnitudes: the first channel, R; channels whose exact magnitudes tie — (1, 3) and (3, 1)
/// — may round apart, and the larger rounding wins: 5 % of a synthetic frame's pixels had such ties).
/// Image x runs along columns (right), y along rows (down).
///
/// [`ImageGradients::compute`] runs [`table_gradient`], the CPU twin of the `image_gradients` kernel
/// (`shaders/image_gradients.wgsl`), which gives the same floats as this definition ([`pixel_gradient`])
/// through a table of differences and their squares, so that no float product is left for a GPU compiler
/// to fuse into another rounding.
#[derive(Clone, Debug)]
pub struct ImageGradients {
    pub width: u32,
    pub height: u32,
    /// Row-major (dx, dy) per pixel.
    pub gradients: Vec<Vec2>,
}

impl ImageGradients {
    pub fn compute(rgb: &image::RgbImage) -> ImageGradients {
        let (w, h) = rgb.dimensions();
        let (raw, table) = (rgb.as_raw().as_slice(), gradient_table());
        let gradients = (0..h)
            .into_par_iter()
            .flat_map_iter(|row| (0..w).map(move |col| table_gradient(raw, w, h, table, col, row)))
            .collect();
        ImageGradients { width: w, height: h, gradients }
    }

    pub fn at(&self, col: u32, row: u32) -> Vec2 {
        self.gradients[(row * self.width + col) as usize]
    }
}

/// The gradient (dx, dy) of one pixel, as [`ImageGradients::compute`] defines it (replicate padding, the
/// colour channel of the largest magnitude); for callers that need a few pixels, not the whole image (the
/// room layout's subsampled points).
pub fn pixel_gradient(rgb: &image::RgbImage, col: u32, row: u32) -> Vec2 {
    let (w, h) = rgb.dimensions();
    let raw = rgb.as_raw();
    let at = |col: u32, row: u32, ch: usize| raw[((row * w + col) * 3) as usize + ch] as f32 * (1.0 / 255.0);
    let (left, right) = (col.saturating_sub(1), (col + 1).min(w - 1));
    let (up, down) = (row.saturating_sub(1), (row + 1).min(h - 1));
    let mut best = Vec2::ZERO;
    let mut best_sq = -1.0f32;
    for ch in 0..3 {
        let g = Vec2::new(at(right, row, ch) - at(left, row, ch), at(col, down, ch) - at(col, up, ch));
        let sq = g.length_squared();
        if sq > best_sq {
            best_sq = sq;
            best = g;
        }
    }
    best
}

/// Intensity levels of a colour channel (8 bits): [`gradient_table`] has `GRADIENT_LEVELS²` entries.
pub const GRADIENT_LEVELS: u32 = 256;

/// One intensity level as [`pixel_gradient`] scales it to [0, 1].
fn gradient_level(byte: u32) -> f32 {
    byte as f32 * (1.0 / 255.0)
}

/// The table of the `image_gradients` kernel and its twin: entry `high · GRADIENT_LEVELS + low` is
/// `(level(high) − level(low), that difference squared)`, each rounded to f32 as [`pixel_gradient`] rounds
/// it. A kernel that looks these up does no float multiplication, so nothing can be fused into a
/// multiply-add with another rounding: the GPU's gradients are the CPU's bit for bit. Built once (512 KiB).
pub fn gradient_table() -> &'static [[f32; 2]] {
    static TABLE: std::sync::OnceLock<Vec<[f32; 2]>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        (0..GRADIENT_LEVELS * GRADIENT_LEVELS)
            .map(|entry| {
                let d = gradient_level(entry / GRADIENT_LEVELS) - gradient_level(entry % GRADIENT_LEVELS);
                [d, d * d]
            })
            .collect()
    })
}

/// CPU twin of `shaders/image_gradients.wgsl`: the gradient of pixel (`col`, `row`) of the `width × height`
/// RGB image `raw` (row-major, three bytes a pixel) looked up in `table` ([`gradient_table`]); equal bit for
/// bit to [`pixel_gradient`]. Per channel, the squared magnitude is the sum of the two looked-up squares (the
/// same two roundings and one addition as `Vec2::length_squared`), and the channel of the largest wins,
/// the first on ties.
pub fn table_gradient(raw: &[u8], width: u32, height: u32, table: &[[f32; 2]], col: u32, row: u32) -> Vec2 {
    let channel = |col: u32, row: u32, ch: u32| raw[((row * width + col) * 3 + ch) as usize] as u32;
    let left = if col == 0 { 0 } else { col - 1 };
    let right = (col + 1).min(width - 1);
    let up = if row == 0 { 0 } else { row - 1 };
    let down = (row + 1).min(height - 1);
    let mut best = Vec2::ZERO;
    let mut best_sq = -1.0f32;
    for ch in 0..3 {
        let x = table[(channel(right, row, ch) * GRADIENT_LEVELS + channel(left, row, ch)) as usize];
        let y = table[(channel(col, down, ch) * GRADIENT_LEVELS + channel(col, up, ch)) as usize];
        let sq = x[1] + y[1];
        if sq > best_sq {
            best_sq = sq;
            best = Vec2::new(x[0], y[0]);
        }
    }
    best
}

/// Gradient magnitude `√(dx² + dy²)`.
pub fn gradient_magnitude(g: Vec2) -> f32 {
    (g.x * g.x + g.y * g.y).sqrt()
}

/// Unsigned gradient orientation in [0, π): `atan2(dy, dx)` folded by π. A zero gradient gives 0.
pub fn gradient_orientation(g: Vec2) -> f32 {
    let mut angle = g.y.atan2(g.x);
    if angle < 0.0 {
        angle += PI;
    }
    if angle >= PI {
        angle -= PI;
    }
    angle
}

/// How each point's plane-fit neighbours are found (paper §3.1.2: its [`NORMAL_NEIGHBOURS`] nearest 3D
/// neighbours, after Song & Xiao, without saying how they are searched).
///
/// In a model file (`features.normals`) it is the search the model was trained with, written only when it
/// is not the default: files written before the field read as the k-d tree's, and a model of the default
/// search serialises as it did before the field existed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NormalSearch {
    /// The nearest of all the frame's points, by a k-d tree ([`estimate_normals`]). The default, and what
    /// every shipped model was trained with.
    #[default]
    KdTree,
    /// The [`WIDE_NORMAL_NEIGHBOURS`] (40) nearest of all the frame's points, by the same k-d tree
    /// ([`estimate_normals_of`]; since 2026-12-08, our departure from the paper's 15, not yet shipped). On
    /// depth quantised in steps (structured light: Kinect v1, Xtion, and `synth`'s models of them) 15
    /// neighbours often lie on one step and fit the optical axis (46 % of the points of 40 training frames,
    /// seed 1000, 320×240; their floor points in the up bin 35 %); 40 reach across steps (15 % and 80 %).
    /// Models trained with it on the 1 000 training frames and scored on the 325 selection frames (first
    /// stage, no voting): desk +5.8 [2.2, 8.3], table's cuboid model +3.8 [−0.6, 9.5], bed −0.8 [−4.0, 2.8],
    /// dresser −11.6 [−18.1, −2.2] against the same training with 15 — no uniform win (docs/measurements.md,
    /// "The normals' neighbourhood").
    #[serde(rename = "kdtree-40")]
    KdTreeWide,
    /// The nearest among the points of the [`NORMAL_WINDOW`]×[`NORMAL_WINDOW`] image window around the
    /// point's pixel ([`window_neighbour_mask`], [`window_normals`]): a search of fixed size and shape per
    /// pixel, the one a GPU does well (issue #10's "image-space neighbourhood"). Near points of one
    /// surface are near in the image too, so the two searches mostly agree; they part where the 15 nearest
    /// reach beyond the window (far, sparse points at 320×240) or across a depth edge.
    Window,
}

impl NormalSearch {
    /// Every search, in the order the command line's help lists their [`NormalSearch::name`]s.
    pub const ALL: [NormalSearch; 3] = [NormalSearch::KdTree, NormalSearch::Window, NormalSearch::KdTreeWide];

    /// Whether this is the default search (a model file leaves the field out then).
    pub fn is_default(&self) -> bool {
        *self == NormalSearch::default()
    }

    /// The name the command line and model files use (`kdtree`, `window`, `kdtree-40`).
    pub fn name(self) -> &'static str {
        match self {
            NormalSearch::KdTree => "kdtree",
            NormalSearch::Window => "window",
            NormalSearch::KdTreeWide => "kdtree-40",
        }
    }
}

impl std::str::FromStr for NormalSearch {
    type Err = Error;

    fn from_str(name: &str) -> Result<Self> {
        NormalSearch::ALL.into_iter().find(|search| search.name() == name).ok_or_else(|| {
            let names: Vec<&str> = NormalSearch::ALL.iter().map(|search| search.name()).collect();
            Error::Input(format!("unknown normal search '{name}' (expected one of: {})", names.join(", ")))
        })
    }
}

/// Side of the image window of [`NormalSearch::Window`], in pixels (odd; the point's pixel at its centre).
pub const NORMAL_WINDOW: u32 = 7;
/// [`NORMAL_WINDOW`]`²` window pixels: a selection fits in a `[u32; 2]` bit mask.
pub const NORMAL_WINDOW_PIXELS: u32 = NORMAL_WINDOW * NORMAL_WINDOW;
const _: () = assert!(NORMAL_WINDOW % 2 == 1 && NORMAL_WINDOW_PIXELS <= 64);
/// Fixed-point units per metre of the window search's offsets (a quarter millimetre): distances are
/// compared as integers, so the CPU and a GPU pick the same neighbours bit for bit (float sums of squares
/// could be fused into different roundings on a GPU).
pub const NORMAL_WINDOW_UNITS: f32 = 4000.0;
/// Largest offset per axis, in units (4.1 m): `3 · 16 383²` fits in a `u32`.
pub const NORMAL_WINDOW_CLAMP: f32 = 16383.0;

/// The frame's points laid out by pixel for the window search: `[x, y, z, 1]` at a pixel with a point,
/// `[0, 0, 0, 0]` elsewhere (the layout of the `depth_points` kernel's output), row-major.
pub fn point_grid(image_size: [u32; 2], points: &[Vec3], pixels: &[[u32; 2]]) -> Vec<[f32; 4]> {
    let [width, height] = image_size;
    let mut grid = vec![[0.0f32; 4]; width as usize * height as usize];
    for (p, &[col, row]) in points.iter().zip(pixels) {
        grid[(row * width + col) as usize] = [p.x, p.y, p.z, 1.0];
    }
    grid
}

/// One axis of a window offset in fixed point: `⌊(a − b) · units⌋` clamped to ±[`NORMAL_WINDOW_CLAMP`].
/// A subtraction, then a product, then a floor — each correctly rounded in WGSL as in Rust, and nothing
/// a compiler may fuse — so the GPU twin gets the same integer.
fn window_offset(a: f32, b: f32) -> i32 {
    // `floor_to_i64`: `f32::floor` is a libm call on baseline x86-64 (9 % of the search's time); the same
    // integer for every f32, and clamping before or after the conversion agrees for every value.
    let limit = NORMAL_WINDOW_CLAMP as i64;
    floor_to_i64((a - b) * NORMAL_WINDOW_UNITS).clamp(-limit, limit) as i32
}

/// The neighbours of pixel (`col`, `row`)'s point for [`NormalSearch::Window`]: of the points at the
/// [`NORMAL_WINDOW_PIXELS`] pixels of the window centred on it (inside the image), the
/// [`NORMAL_NEIGHBOURS`] nearest in 3D (the point itself, at distance 0, among them), as a bit mask of
/// window slots (`slot = (dy + r)·NORMAL_WINDOW + (dx + r)`, bit `slot % 32` of word `slot / 32`).
/// Distances are squared fixed-point offsets ([`NORMAL_WINDOW_UNITS`]); of equal distances the earlier
/// slot is kept. `[0, 0]` for a pixel without a point.
///
/// CPU twin of `shaders/normal_window.wgsl` (`window_mask`; same names, same order of operations).
pub fn window_neighbour_mask(grid: &[[f32; 4]], width: u32, height: u32, col: u32, row: u32) -> [u32; 2] {
    let centre = grid[(row * width + col) as usize];
    if centre[3] == 0.0 {
        return [0, 0];
    }
    let radius = (NORMAL_WINDOW / 2) as i32;
    // The nearest so far, sorted by (distance, slot).
    let mut keys = [0u32; NORMAL_NEIGHBOURS];
    let mut slots = [0u32; NORMAL_NEIGHBOURS];
    let mut count = 0usize;
    for dy in -radius..=radius {
        for dx in -radius..=radius {
            let (c, r) = (col as i32 + dx, row as i32 + dy);
            if c < 0 || r < 0 || c >= width as i32 || r >= height as i32 {
                continue;
            }
            let p = grid[(r as u32 * width + c as u32) as usize];
            if p[3] == 0.0 {
                continue;
            }
            let ox = window_offset(p[0], centre[0]);
            let oy = window_offset(p[1], centre[1]);
            let oz = window_offset(p[2], centre[2]);
            let key = (ox * ox) as u32 + (oy * oy) as u32 + (oz * oz) as u32;
            let slot = ((dy + radius) * NORMAL_WINDOW as i32 + (dx + radius)) as u32;
            if count == NORMAL_NEIGHBOURS && key >= keys[NORMAL_NEIGHBOURS - 1] {
                continue;
            }
            // Insertion: later slots of an equal distance go after the earlier ones.
            let mut i = count.min(NORMAL_NEIGHBOURS - 1);
            while i > 0 && keys[i - 1] > key {
                keys[i] = keys[i - 1];
                slots[i] = slots[i - 1];
                i -= 1;
            }
            keys[i] = key;
            slots[i] = slot;
            count = (count + 1).min(NORMAL_NEIGHBOURS);
        }
    }
    let mut mask = [0u32; 2];
    for &slot in &slots[..count] {
        mask[(slot / 32) as usize] |= 1 << (slot % 32);
    }
    mask
}

/// The points of a window mask (see [`window_neighbour_mask`]) around pixel (`col`, `row`), in slot order.
pub fn window_mask_points(
    grid: &[[f32; 4]],
    width: u32,
    col: u32,
    row: u32,
    mask: [u32; 2],
) -> impl Iterator<Item = Vec3> + Clone + '_ {
    let radius = (NORMAL_WINDOW / 2) as i32;
    (0..NORMAL_WINDOW_PIXELS).filter(move |slot| mask[(slot / 32) as usize] >> (slot % 32) & 1 == 1).map(move |slot| {
        let (dx, dy) = ((slot % NORMAL_WINDOW) as i32 - radius, (slot / NORMAL_WINDOW) as i32 - radius);
        let p = grid[((row as i32 + dy) as u32 * width + (col as i32 + dx) as u32) as usize];
        Vec3::new(p[0], p[1], p[2])
    })
}

/// Normals of [`NormalSearch::Window`] for the points at `pixels`, from each point's window mask
/// (`masks[i]` of `pixels[i]`, computed by [`window_neighbour_mask`] or its GPU twin): the same plane fit
/// as [`estimate_normals`] ([`plane_normal`], double precision) over the mask's points in slot order, turned
/// toward the camera; fewer than 3 points, or coincident ones, give the unit vector toward the camera.
pub fn normals_from_window_masks(grid: &[[f32; 4]], width: u32, pixels: &[[u32; 2]], masks: &[[u32; 2]]) -> Vec<Vec3> {
    pixels
        .par_iter()
        .zip(masks)
        .map(|(&[col, row], &mask)| {
            let c = grid[(row * width + col) as usize];
            let p = Vec3::new(c[0], c[1], c[2]);
            let normal =
                plane_normal(window_mask_points(grid, width, col, row, mask)).unwrap_or_else(|| toward_camera(p));
            if normal.dot(-p) < 0.0 {
                -normal
            } else {
                normal
            }
        })
        .collect()
}

/// Normals of [`NormalSearch::Window`] on the CPU: [`window_neighbour_mask`] per point, then
/// [`normals_from_window_masks`].
pub fn window_normals(image_size: [u32; 2], points: &[Vec3], pixels: &[[u32; 2]]) -> Vec<Vec3> {
    let [width, height] = image_size;
    let grid = point_grid(image_size, points, pixels);
    let masks: Vec<[u32; 2]> =
        pixels.par_iter().map(|&[col, row]| window_neighbour_mask(&grid, width, height, col, row)).collect();
    normals_from_window_masks(&grid, width, pixels, &masks)
}

/// How far two sets of normals of the same points agree ([`normal_agreement`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormalAgreement {
    pub points: usize,
    /// Share of (point, yaw) pairs whose 25-bin code ([`normal_bin`] of the normal rotated by −yaw, as a
    /// hypothesis of that yaw bins it) is the same for both normals: what the features see.
    pub same_code: f64,
    /// Median angle between the two normals of a point, degrees (normals are oriented toward the camera,
    /// so this is the angle, not the angle between lines).
    pub median_angle_deg: f64,
    /// Share of points whose two normals are within 10°.
    pub within_10_deg: f64,
}

/// Agreement of normals `a` and `b` (one each per point) over the hypothesis `yaws` (radians).
pub fn normal_agreement(a: &[Vec3], b: &[Vec3], yaws: &[f32]) -> NormalAgreement {
    assert_eq!(a.len(), b.len(), "one normal of each per point");
    let rotations: Vec<glam::Mat3> = yaws.iter().map(|&yaw| glam::Mat3::from_rotation_z(-yaw)).collect();
    let same: usize = a
        .par_iter()
        .zip(b)
        .map(|(&na, &nb)| rotations.iter().filter(|r| normal_bin(**r * na) == normal_bin(**r * nb)).count())
        .sum();
    let mut angles: Vec<f64> =
        a.iter().zip(b).map(|(na, nb)| (na.dot(*nb).clamp(-1.0, 1.0) as f64).acos().to_degrees()).collect();
    angles.sort_by(f64::total_cmp);
    let n = a.len();
    let median_angle_deg = match n {
        0 => 0.0,
        _ if n % 2 == 1 => angles[n / 2],
        _ => 0.5 * (angles[n / 2 - 1] + angles[n / 2]),
    };
    let share = |count: usize, of: usize| if of == 0 { 1.0 } else { count as f64 / of as f64 };
    NormalAgreement {
        points: n,
        same_code: share(same, n * yaws.len()),
        median_angle_deg,
        within_10_deg: share(angles.iter().filter(|&&d| d <= 10.0).count(), n),
    }
}

/// The frame data every hypothesis reads: upright points with their normals and image gradients, the
/// camera and the floor height.
#[derive(Clone, Debug)]
pub struct Preprocessed {
    pub camera: Camera,
    /// Image size (width, height) in pixels.
    pub image_size: [u32; 2],
    /// Upright points (metres); the camera is at the origin.
    pub points: Vec<Vec3>,
    /// Unit normal per point, oriented toward the camera (`n · (0 − p) ≥ 0`).
    pub normals: Vec<Vec3>,
    /// Image gradient (dx, dy) at each point's pixel (see [`ImageGradients`]).
    pub gradients: Vec<Vec2>,
    /// Floor height (upright z, metres): the [`FLOOR_QUANTILE`] quantile of the point heights.
    pub floor: f32,
}

impl Preprocessed {
    /// Preprocesses a frame: point cloud, gradients at the points' pixels, normals and floor.
    /// Fails on a frame without any valid depth.
    pub fn from_frame(frame: &Frame) -> Result<Preprocessed> {
        Self::from_frame_with(frame, NormalSearch::default())
    }

    /// [`Preprocessed::from_frame`] with the normals' neighbours found by `search`.
    pub fn from_frame_with(frame: &Frame, search: NormalSearch) -> Result<Preprocessed> {
        Self::from_frame_using(frame, |rgb, cloud| {
            let normals = match search {
                NormalSearch::KdTree => estimate_normals(&cloud.points),
                NormalSearch::KdTreeWide => estimate_normals_of(&cloud.points, WIDE_NORMAL_NEIGHBOURS),
                NormalSearch::Window => window_normals([rgb.width(), rgb.height()], &cloud.points, &cloud.pixels),
            };
            Ok((ImageGradients::compute(rgb), normals))
        })
    }

    /// [`Preprocessed::from_frame`] with the image gradients and the normals (one per point) given by
    /// `gradients_and_normals(RGB image, point cloud)` (the GPU's kernels: `backend::Backend::preprocess`).
    pub fn from_frame_using(
        frame: &Frame,
        gradients_and_normals: impl FnOnce(&image::RgbImage, &PointCloud) -> Result<(ImageGradients, Vec<Vec3>)>,
    ) -> Result<Preprocessed> {
        let cloud = frame.point_cloud();
        if cloud.len() < NORMAL_NEIGHBOURS {
            return Err(Error::Input(format!(
                "frame '{}' has {} points with depth; the feature engine needs at least {NORMAL_NEIGHBOURS}",
                frame.name,
                cloud.len()
            )));
        }
        let camera = Camera::new(frame.intrinsics(), frame.rtilt());
        let (image, normals) = gradients_and_normals(&frame.rgb, &cloud)?;
        let image_size = [frame.width(), frame.height()];
        if [image.width, image.height] != image_size || image.gradients.len() != (image.width * image.height) as usize {
            return Err(Error::Input(format!(
                "frame '{}': {} gradients of a {}×{} image for a {}×{} frame",
                frame.name,
                image.gradients.len(),
                image.width,
                image.height,
                image_size[0],
                image_size[1]
            )));
        }
        if normals.len() != cloud.len() {
            return Err(Error::Input(format!(
                "frame '{}': {} normals for {} points",
                frame.name,
                normals.len(),
                cloud.len()
            )));
        }
        Ok(Self::from_cloud_and_normals(camera, image_size, &cloud, &image, normals))
    }

    /// Preprocesses a point cloud with precomputed image gradients.
    pub fn from_cloud(
        camera: Camera,
        image_size: [u32; 2],
        cloud: &PointCloud,
        image: &ImageGradients,
    ) -> Preprocessed {
        Self::from_cloud_and_normals(camera, image_size, cloud, image, estimate_normals(&cloud.points))
    }

    /// Preprocesses a point cloud whose normals (one per point) are already known.
    pub fn from_cloud_and_normals(
        camera: Camera,
        image_size: [u32; 2],
        cloud: &PointCloud,
        image: &ImageGradients,
        normals: Vec<Vec3>,
    ) -> Preprocessed {
        assert_eq!(normals.len(), cloud.len(), "one normal per point");
        let gradients = cloud.pixels.iter().map(|&[col, row]| image.at(col, row)).collect();
        let floor = floor_height(&cloud.points);
        Preprocessed { camera, image_size, points: cloud.points.clone(), normals, gradients, floor }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// How many [`FLOOR_PLANE_CELL_M`] ground cells hold a point within [`FLOOR_PLANE_BAND_M`] above
    /// [`Preprocessed::floor`] whose normal faces up ([`normal_bin`] 0 of the upright normal): the area of
    /// the lowest points' horizontal plane, in cells.
    pub fn floor_plane_cells(&self) -> usize {
        let inv_cell = 1.0 / FLOOR_PLANE_CELL_M;
        let cells: std::collections::HashSet<(i64, i64)> = self
            .points
            .iter()
            .zip(&self.normals)
            .filter(|(p, n)| p.z <= self.floor + FLOOR_PLANE_BAND_M && normal_bin(**n) == 0)
            .map(|(p, _)| (floor_to_i64(p.x * inv_cell), floor_to_i64(p.y * inv_cell)))
            .collect();
        cells.len()
    }

    /// A second floor for the sliding window where the camera does not see the floor, or `None` where it
    /// does (our addition; the paper takes the 0.001 quantile of the heights, [`FLOOR_QUANTILE`], in every
    /// frame). Close to a bed, a bathtub or a counter the picture can hold no floor at all: the lowest
    /// points are then the bottom of what the image cuts, or a top, and every box of the window, standing
    /// on them, floats — on the project's synthetic frames one in ten (the training set's 1 000 frames,
    /// seed 1000: 60 with the quantile more than 10 cm above the annotated floor, 40 more than 20 cm, none
    /// more than 10 cm below it). The test: the lowest points are a floor when their upward-facing points
    /// ([`FLOOR_PLANE_BAND_M`] above [`Preprocessed::floor`]) cover at least [`FLOOR_PLANE_MIN_CELLS`]
    /// cells of [`FLOOR_PLANE_CELL_M`] (a floor seen is a plane; the bottom edge of a cut object is not,
    /// and a top has its sides below it) and lie at least [`MIN_CAMERA_HEIGHT_M`] below the camera (a
    /// bed's, bathtub's or counter's top filling the picture's bottom makes a plane too, since 2026-12-07,
    /// afternoon). Otherwise the floor is somewhere below the lowest points, and
    /// the second floor is where a camera usually stands above it, [`UNSEEN_FLOOR_CAMERA_HEIGHT_M`] below
    /// the camera — `None` when the lowest points are already that low (nothing to add). Detection runs
    /// the window of the floor's models on both floors (`crate::detect::DetectOptions::unseen_floor`), and
    /// the diagnosis's window recall counts both (`crate::diagnose::frame_window_best_ious`); training uses
    /// [`Preprocessed::floor`] alone. The thresholds were
    /// chosen on the training set's floors and the selection set's AP (README, "The floor where it is not
    /// seen").
    pub fn unseen_floor(&self) -> Option<f32> {
        let assumed = -UNSEEN_FLOOR_CAMERA_HEIGHT_M;
        (self.floor > assumed && self.lowest_points_not_floor().is_some()).then_some(assumed)
    }

    /// Why the lowest points are not a floor the camera sees, or `None` when they are: the test of
    /// [`Preprocessed::unseen_floor`] without its last clause (whether a second floor would add anything).
    pub fn lowest_points_not_floor(&self) -> Option<NotFloor> {
        if self.floor > -MIN_CAMERA_HEIGHT_M {
            Some(NotFloor::TooHigh)
        } else {
            (self.floor_plane_cells() < FLOOR_PLANE_MIN_CELLS).then_some(NotFloor::NoPlane)
        }
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// The [`FLOOR_QUANTILE`] quantile of the heights (element `⌊q·(n−1)⌋` of the sorted heights); 0 for no
/// points.
pub fn floor_height(points: &[Vec3]) -> f32 {
    if points.is_empty() {
        return 0.0;
    }
    let mut heights: Vec<f32> = points.iter().map(|p| p.z).collect();
    let index = (FLOOR_QUANTILE * (heights.len() - 1) as f64).floor() as usize;
    let (_, value, _) = heights.select_nth_unstable_by(index, f32::total_cmp);
    *value
}

/// Unit normals from a least-squares plane fit (smallest eigenvector of the neighbourhood covariance) to
/// each point's [`NORMAL_NEIGHBOURS`] nearest 3D neighbours (the point itself included), found with a k-d
/// tree; each normal is turned to face the camera at the origin. With fewer points than neighbours all
/// points are used. A neighbourhood with no defined plane (all neighbours coincide) gets the unit vector
/// toward the camera.
pub fn estimate_normals(points: &[Vec3]) -> Vec<Vec3> {
    estimate_normals_of(points, NORMAL_NEIGHBOURS)
}

/// [`estimate_normals`] with each point's `neighbours` nearest (the point included) instead of
/// [`NORMAL_NEIGHBOURS`]; with fewer points than that, all of them.
pub fn estimate_normals_of(points: &[Vec3], neighbours: usize) -> Vec<Vec3> {
    if points.is_empty() {
        return Vec::new();
    }
    let entries: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    let tree: kiddo::ImmutableKdTree<f32, 3> = match kiddo::ImmutableKdTree::new_from_slice(&entries) {
        Ok(tree) => tree,
        // Construction only fails on empty input, excluded above; fall back to camera-facing normals.
        Err(_) => return points.iter().map(|&p| toward_camera(p)).collect(),
    };
    let k = NonZeroUsize::new(neighbours.min(points.len())).unwrap_or(NonZeroUsize::MIN);
    points
        .par_iter()
        .map(|&p| {
            let neighbours = tree.query(&p.to_array()).nearest_n::<kiddo::SquaredEuclidean<f32>>(k).execute();
            let normal =
                plane_normal(neighbours.iter().map(|n| points[n.item as usize])).unwrap_or_else(|| toward_camera(p));
            if normal.dot(-p) < 0.0 {
                -normal
            } else {
                normal
            }
        })
        .collect()
}

fn toward_camera(p: Vec3) -> Vec3 {
    (-p).try_normalize().unwrap_or(Vec3::Z)
}

/// Normal of the least-squares plane through `points`: the eigenvector of the smallest eigenvalue of their
/// covariance (double precision). `None` when the points coincide.
///
/// Two passes over `points` (the mean, then the covariance), so no buffer per call: it runs once per point
/// of a frame.
pub fn plane_normal(points: impl Iterator<Item = Vec3> + Clone) -> Option<Vec3> {
    let (count, sum) = points.clone().fold((0usize, DVec3::ZERO), |(n, s), p| (n + 1, s + p.as_dvec3()));
    if count < 3 {
        return None;
    }
    let mean = sum / count as f64;
    let mut cov = DMat3::ZERO;
    for p in points {
        let d = p.as_dvec3() - mean;
        cov += DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    smallest_eigenvector(cov).map(|v| v.as_vec3())
}

/// Eigenvector of the smallest eigenvalue of a symmetric positive semi-definite 3×3 matrix.
///
/// Eigenvalues by the trigonometric closed form; the eigenvector is the longest cross product of two rows
/// of `M − λI` (they span the plane orthogonal to it). When `M − λI` has rank < 2 (a repeated smallest
/// eigenvalue: a line or a blob of points) any vector orthogonal to its non-zero row is an answer; one is
/// returned. `None` for the zero matrix.
pub fn smallest_eigenvector(m: DMat3) -> Option<DVec3> {
    let scale = m.to_cols_array().iter().fold(0.0f64, |s, x| s.max(x.abs()));
    if scale == 0.0 || !scale.is_finite() {
        return None;
    }
    let a = m * (1.0 / scale);
    let (a00, a11, a22) = (a.x_axis.x, a.y_axis.y, a.z_axis.z);
    let (a01, a02, a12) = (a.y_axis.x, a.z_axis.x, a.z_axis.y);
    let p1 = a01 * a01 + a02 * a02 + a12 * a12;
    let q = (a00 + a11 + a22) / 3.0;
    let lambda = if p1 < 1e-30 {
        a00.min(a11).min(a22)
    } else {
        let p2 = (a00 - q).powi(2) + (a11 - q).powi(2) + (a22 - q).powi(2) + 2.0 * p1;
        let p = (p2 / 6.0).sqrt();
        let b = (a - DMat3::from_diagonal(DVec3::splat(q))) * (1.0 / p);
        let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
        let phi = r.acos() / 3.0;
        // Eigenvalues q + 2p·cos(φ + 2πk/3); k = 1 gives the smallest.
        q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos()
    };
    let shifted = a - DMat3::from_diagonal(DVec3::splat(lambda));
    // Symmetric: rows are columns.
    let rows = [shifted.x_axis, shifted.y_axis, shifted.z_axis];
    let candidates = [rows[0].cross(rows[1]), rows[0].cross(rows[2]), rows[1].cross(rows[2])];
    let best = candidates.iter().copied().max_by(|u, v| u.length_squared().total_cmp(&v.length_squared()))?;
    if best.length_squared() > 1e-24 {
        return Some(best.normalize());
    }
    // Rank ≤ 1: any vector orthogonal to the largest row.
    let row = rows.iter().copied().max_by(|u, v| u.length_squared().total_cmp(&v.length_squared()))?;
    if row.length_squared() < 1e-24 {
        return Some(DVec3::Z);
    }
    Some(row.normalize().any_orthonormal_vector())
}

/// The 25-bin normal orientation code of a normal given in a cuboid's own frame.
///
/// `local = (n·a, n·b, n_z)` with `a` the cuboid's width axis, `b` its depth axis (the front is −b), so the
/// code turns with the hypothesis: for a hypothesis of yaw θ, `local` is the upright normal rotated by −θ
/// about z. Bins:
/// * bin 0: near-vertical upward normals, `n_z ≥ cos 22.5°` (floors, seats, table tops);
/// * bins 1 + 8·ring + sector, 24 bins: three elevation rings — ring 0 `n_z < −sin 22.5°` (facing down,
///   straight down included), ring 1 `|n_z| ≤ sin 22.5°` (near-horizontal normals: vertical surfaces),
///   ring 2 `sin 22.5° < n_z < cos 22.5°` (tilted up) — times eight 45° azimuth sectors of the horizontal
///   part measured from the cuboid's front: azimuth `α = atan2(n·a, −n·b)` (0 = out of the front, +π/2 =
///   along +a, π = out of the back), sector `⌊(α + π/8)/(π/4)⌋ mod 8`, so sector 0 is centred on the front.
///
/// The GPU never evaluates this: per yaw the CPU writes each point's bin (an integer) next to the point,
/// so both paths count exactly the same bins.
pub fn normal_bin(local: Vec3) -> u32 {
    if local.z >= UP_CONE_COS {
        return 0;
    }
    let ring = if local.z < -RING_SIN {
        0
    } else if local.z <= RING_SIN {
        1
    } else {
        2
    };
    let azimuth = local.x.atan2(-local.y);
    let sector = (((azimuth + FRAC_PI_8) / FRAC_PI_4).floor() as i32).rem_euclid(8) as u32;
    1 + 8 * ring + sector
}
