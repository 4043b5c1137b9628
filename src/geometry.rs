//! Oriented cuboids in the upright (gravity-aligned) frame and the geometry the detector needs.
//!
//! # Conventions (used everywhere in cog-gpu)
//! * The upright frame is SUN RGB-D's: x right, y forward (away from the camera), z up, metres.
//! * A [`Cuboid`] has a `centre`, a `size` = (width, depth, height) and a `yaw` in radians.
//! * `yaw` is the angle of the cuboid's **width axis** `a = (cos yaw, sin yaw, 0)` from +x, counter-clockwise
//!   seen from above. The **depth axis** is `b = (-sin yaw, cos yaw, 0)` (a turned by +90°), the height
//!   axis is +z.
//! * The cuboid's **front** is `-b = (sin yaw, -cos yaw, 0)`: with yaw = 0 an object in front of the camera
//!   faces the camera. This is the SUN RGB-D orientation vector: annotators draw the front edge first, and
//!   the reader takes the polygon's first edge p1→p2 as the width axis and its side of the box as the front
//!   (see [`Cuboid::from_polygon`]).
//! * Footprint corners are listed counter-clockwise starting at the front-left corner:
//!   `p1 = c - a·w/2 - b·d/2`, `p2 = c + a·w/2 - b·d/2`, `p3 = c + a·w/2 + b·d/2`, `p4 = c - a·w/2 + b·d/2`;
//!   [`Cuboid::corners`] gives the four bottom corners in that order, then the four top corners.
//! * The cuboid's local frame has coordinates (s, t, u) along (a, b, z) measured from the centre, so a point
//!   is inside when |s| ≤ w/2, |t| ≤ d/2, |u| ≤ h/2.

use glam::{DVec2, Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// An oriented 3D box that can turn about the up axis only (objects stand on a base).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cuboid {
    /// Centre in the upright frame (metres).
    pub centre: Vec3,
    /// (width, depth, height) along the width axis, the depth axis and z (metres, all > 0).
    pub size: Vec3,
    /// Angle of the width axis from +x, counter-clockwise seen from above (radians).
    pub yaw: f32,
}

impl Cuboid {
    pub fn new(centre: Vec3, size: Vec3, yaw: f32) -> Self {
        Self { centre, size, yaw }
    }

    /// Unit width axis `a = (cos yaw, sin yaw)` on the ground plane.
    pub fn width_axis(&self) -> Vec2 {
        Vec2::new(self.yaw.cos(), self.yaw.sin())
    }

    /// Unit depth axis `b = (-sin yaw, cos yaw)` on the ground plane.
    pub fn depth_axis(&self) -> Vec2 {
        Vec2::new(-self.yaw.sin(), self.yaw.cos())
    }

    /// Unit direction the object faces, `-b` (see the module doc).
    pub fn front(&self) -> Vec2 {
        -self.depth_axis()
    }

    pub fn bottom(&self) -> f32 {
        self.centre.z - 0.5 * self.size.z
    }

    pub fn top(&self) -> f32 {
        self.centre.z + 0.5 * self.size.z
    }

    pub fn volume(&self) -> f32 {
        self.size.x * self.size.y * self.size.z
    }

    /// The four footprint corners p1..p4 (counter-clockwise, front-left first).
    pub fn footprint(&self) -> [Vec2; 4] {
        let c = self.centre.truncate();
        let half_w = self.width_axis() * (0.5 * self.size.x);
        let half_d = self.depth_axis() * (0.5 * self.size.y);
        [c - half_w - half_d, c + half_w - half_d, c + half_w + half_d, c - half_w + half_d]
    }

    /// The 8 corners: bottom p1..p4 then top p1..p4.
    pub fn corners(&self) -> [Vec3; 8] {
        let f = self.footprint();
        let (z0, z1) = (self.bottom(), self.top());
        [
            f[0].extend(z0),
            f[1].extend(z0),
            f[2].extend(z0),
            f[3].extend(z0),
            f[0].extend(z1),
            f[1].extend(z1),
            f[2].extend(z1),
            f[3].extend(z1),
        ]
    }

    /// Coordinates (s, t, u) of an upright point in the cuboid's local frame (see the module doc).
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        self.direction_to_local(p - self.centre)
    }

    /// A direction (a normal, an offset) in the cuboid's local axes: [`Cuboid::to_local`] without the
    /// centre, the same rotation.
    pub fn direction_to_local(&self, d: Vec3) -> Vec3 {
        let (sin, cos) = self.yaw.sin_cos();
        Vec3::new(d.x * cos + d.y * sin, -d.x * sin + d.y * cos, d.z)
    }

    /// Upright point of local coordinates (s, t, u).
    pub fn from_local(&self, local: Vec3) -> Vec3 {
        let (sin, cos) = self.yaw.sin_cos();
        self.centre + Vec3::new(local.x * cos - local.y * sin, local.x * sin + local.y * cos, local.z)
    }

    /// Whether `p` lies inside or on the boundary of the cuboid.
    pub fn contains(&self, p: Vec3) -> bool {
        let l = self.to_local(p);
        let h = 0.5 * self.size;
        l.x.abs() <= h.x && l.y.abs() <= h.y && l.z.abs() <= h.z
    }

    /// Builds a cuboid from a SUN RGB-D footprint polygon (upright x, y of p1..p4) and a vertical range.
    ///
    /// Width = |p2 − p1| along the first edge, depth = |p3 − p2|; the centre is the mean of the four
    /// corners. The front is the side of the first edge (the SUN RGB-D orientation vector points from the
    /// centre to the midpoint of p1p2). For a counter-clockwise polygon that is yaw = atan2 of p1→p2; a
    /// clockwise polygon has its first edge on the other side of the width axis, so its yaw is turned by
    /// π to keep the front on the p1p2 side. Returns `None` for a degenerate polygon (an edge shorter
    /// than 1 mm or a non-finite coordinate).
    pub fn from_polygon(corners: [Vec2; 4], z_min: f32, z_max: f32) -> Option<Cuboid> {
        if corners.iter().any(|c| !c.is_finite()) || !z_min.is_finite() || !z_max.is_finite() {
            return None;
        }
        let edge_w = corners[1] - corners[0];
        let edge_d = corners[2] - corners[1];
        let (width, depth) = (edge_w.length(), edge_d.length());
        if width < 1e-3 || depth < 1e-3 || z_max - z_min < 1e-4 {
            return None;
        }
        let centre = (corners[0] + corners[1] + corners[2] + corners[3]) * 0.25;
        let counter_clockwise = edge_w.perp_dot(edge_d) > 0.0;
        let mut yaw = edge_w.y.atan2(edge_w.x);
        if !counter_clockwise {
            yaw = wrap_angle(yaw + std::f32::consts::PI);
        }
        Some(Cuboid { centre: centre.extend(0.5 * (z_min + z_max)), size: Vec3::new(width, depth, z_max - z_min), yaw })
    }
}

/// Wraps an angle into (−π, π].
pub fn wrap_angle(angle: f32) -> f32 {
    use std::f32::consts::{PI, TAU};
    let mut a = angle % TAU;
    if a <= -PI {
        a += TAU;
    } else if a > PI {
        a -= TAU;
    }
    a
}

/// A pinhole camera in the upright frame: intrinsics in SUN RGB-D's 1-based pixel convention and Rtilt.
///
/// Projection inverts the frame module's back-projection exactly: the upright point `p` has camera
/// coordinates `c = Rtiltᵀ·p = (x, z, −y)` (x right, y down, z forward), then `u = fx·x/z + cx`,
/// `v = fy·y/z + cy` (1-based). [`Camera::project`] returns **0-based** image coordinates
/// `(u − 1, v − 1)`, so the centre of the pixel in column `col`, row `row` is at exactly `(col, row)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// (fx, fy, cx, cy), 1-based convention.
    pub intrinsics: [f32; 4],
    /// Rotation from (x, z, −y) camera coordinates to the upright frame.
    pub rtilt: glam::Mat3,
}

/// Points closer to the camera plane than this (metres along the optical axis) do not project.
pub const MIN_PROJECT_DEPTH: f32 = 1e-3;

impl Camera {
    pub fn new(intrinsics: [f32; 4], rtilt: glam::Mat3) -> Self {
        Self { intrinsics, rtilt }
    }

    /// Camera coordinates (x right, y down, z forward) of an upright point.
    pub fn to_camera(&self, p: Vec3) -> Vec3 {
        let c = self.rtilt.transpose() * p; // (x, z, -y)
        Vec3::new(c.x, -c.z, c.y)
    }

    /// 0-based image coordinates of an upright point, or `None` when it lies less than
    /// [`MIN_PROJECT_DEPTH`] in front of the camera.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        self.project_camera(self.to_camera(p))
    }

    /// 0-based image coordinates of a point in camera coordinates (x right, y down, z forward), or `None`
    /// when it lies less than [`MIN_PROJECT_DEPTH`] in front of the camera.
    pub fn project_camera(&self, c: Vec3) -> Option<Vec2> {
        if c.z < MIN_PROJECT_DEPTH {
            return None;
        }
        let [fx, fy, cx, cy] = self.intrinsics;
        Some(Vec2::new(fx * c.x / c.z + cx - 1.0, fy * c.y / c.z + cy - 1.0))
    }
}

// ---------------------------------------------------------------------------------------------------------
// Voxels and projection (consumed by the feature engine)

/// The 8 corners of one voxel of `cuboid` split into `grid = [nx, ny, nz]` equal cells along its width,
/// depth and height axes.
///
/// Voxel index `voxel = [i, j, k]`: `i` counts along the width axis `a` from the left (−a, s = −w/2) side,
/// `j` along the depth axis `b` from the **front** (−b, t = −d/2) side, `k` along z from the bottom. The
/// voxel spans local `s ∈ [−w/2 + i·w/nx, −w/2 + (i+1)·w/nx]` and likewise for t and u.
///
/// The corners come in the same order as [`Cuboid::corners`] (bottom front-left, front-right, back-right,
/// back-left, then the top four), so a `[1, 1, 1]` grid gives exactly the cuboid's corners.
/// Every `grid` entry must be ≥ 1 and `voxel[n] < grid[n]` (checked in debug builds; an index past the grid
/// gives a cell outside the cuboid, it does not panic).
pub fn voxel_corners(cuboid: &Cuboid, grid: [u32; 3], voxel: [u32; 3]) -> [Vec3; 8] {
    debug_assert!(grid.iter().all(|&g| g >= 1), "voxel grid {grid:?} has an empty axis");
    debug_assert!(voxel.iter().zip(&grid).all(|(v, g)| v < g), "voxel {voxel:?} outside grid {grid:?}");
    let size = cuboid.size;
    let cell = Vec3::new(size.x / grid[0] as f32, size.y / grid[1] as f32, size.z / grid[2] as f32);
    let lo = -0.5 * size + cell * Vec3::new(voxel[0] as f32, voxel[1] as f32, voxel[2] as f32);
    let hi = lo + cell;
    let (sin, cos) = cuboid.yaw.sin_cos();
    let a = Vec3::new(cos, sin, 0.0);
    let b = Vec3::new(-sin, cos, 0.0);
    let c = cuboid.centre;
    // Ground-plane corners in the footprint order: (s, t) = (lo, lo), (hi, lo), (hi, hi), (lo, hi).
    let base = [c + a * lo.x + b * lo.y, c + a * hi.x + b * lo.y, c + a * hi.x + b * hi.y, c + a * lo.x + b * hi.y];
    let (z0, z1) = (Vec3::Z * lo.z, Vec3::Z * hi.z);
    [base[0] + z0, base[1] + z0, base[2] + z0, base[3] + z0, base[0] + z1, base[1] + z1, base[2] + z1, base[3] + z1]
}

/// Projects many upright points; `None` for each point [`Camera::project`] rejects (behind or within
/// [`MIN_PROJECT_DEPTH`] of the camera plane).
pub fn project_points(camera: &Camera, points: &[Vec3]) -> Vec<Option<Vec2>> {
    points.iter().map(|&p| camera.project(p)).collect()
}

/// Area in pixels² of the convex hull of the projected `corners` (e.g. a cuboid's or a voxel's 8 corners).
///
/// Returns `None` when any corner is behind the camera or closer than [`MIN_PROJECT_DEPTH`] to its plane:
/// the image of such a box is unbounded or wraps around, so there is no meaningful area. The feature
/// engine treats such a voxel as empty. Fewer than 3 points, or collinear images, give `Some(0.0)`.
/// The area does not depend on the 0- or 1-based pixel convention.
pub fn projected_hull_area(camera: &Camera, corners: &[Vec3]) -> Option<f32> {
    // The usual call has 8 corners: keep it off the heap.
    const STACK: usize = 8;
    if corners.len() <= STACK {
        let mut image = [Vec2::ZERO; STACK];
        for (slot, &p) in image.iter_mut().zip(corners) {
            *slot = camera.project(p)?;
        }
        Some(convex_hull_area(&mut image[..corners.len()]))
    } else {
        let mut image = corners.iter().map(|&p| camera.project(p)).collect::<Option<Vec<_>>>()?;
        Some(convex_hull_area(&mut image))
    }
}

/// Cross product (o→a) × (o→b): positive when o, a, b turn counter-clockwise (in a y-up frame).
fn turn(o: Vec2, a: Vec2, b: Vec2) -> f32 {
    (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
}

/// Writes the convex hull of `points` into `hull` (Andrew's monotone chain) and returns its vertex count.
///
/// `points` is sorted in place (by x, then y). `hull` must hold at least `2·points.len()` entries. The
/// hull is counter-clockwise in a y-up frame (clockwise on screen, where y points down), without repeated
/// or collinear vertices. Fewer than 3 distinct points give the distinct points themselves (count < 3).
fn convex_hull_into(points: &mut [Vec2], hull: &mut [Vec2]) -> usize {
    let n = points.len();
    points.sort_unstable_by(|p, q| p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)));
    if n < 3 {
        let mut k = 0;
        for &p in points.iter() {
            if k == 0 || hull[k - 1] != p {
                hull[k] = p;
                k += 1;
            }
        }
        return k;
    }
    let mut k = 0;
    for &p in points.iter() {
        while k >= 2 && turn(hull[k - 2], hull[k - 1], p) <= 0.0 {
            k -= 1;
        }
        hull[k] = p;
        k += 1;
    }
    let lower = k + 1;
    for &p in points.iter().rev().skip(1) {
        while k >= lower && turn(hull[k - 2], hull[k - 1], p) <= 0.0 {
            k -= 1;
        }
        hull[k] = p;
        k += 1;
    }
    // The last point pushed is the first one again.
    k - 1
}

/// Convex hull of a point set (counter-clockwise in a y-up frame, no collinear vertices).
pub fn convex_hull(points: &[Vec2]) -> Vec<Vec2> {
    let mut sorted = points.to_vec();
    let mut hull = vec![Vec2::ZERO; 2 * points.len()];
    let k = convex_hull_into(&mut sorted, &mut hull);
    hull.truncate(k);
    hull
}

/// Area of the convex hull of `points` (sorted in place); 0 for fewer than 3 points or a collinear set.
pub fn convex_hull_area(points: &mut [Vec2]) -> f32 {
    const STACK: usize = 8;
    if points.len() <= STACK {
        let mut hull = [Vec2::ZERO; 2 * STACK];
        let k = convex_hull_into(points, &mut hull);
        polygon_area(&hull[..k]).abs()
    } else {
        let mut hull = vec![Vec2::ZERO; 2 * points.len()];
        let k = convex_hull_into(points, &mut hull);
        polygon_area(&hull[..k]).abs()
    }
}

/// Signed area of a simple polygon by the shoelace formula: positive when the vertices run
/// counter-clockwise (in a y-up frame such as the upright ground plane), negative when clockwise; 0 for
/// fewer than 3 vertices. Accumulates in f64.
pub fn polygon_area(polygon: &[Vec2]) -> f32 {
    let n = polygon.len();
    if n < 3 {
        return 0.0;
    }
    let origin = polygon[0].as_dvec2();
    let mut twice = 0.0f64;
    for i in 1..n - 1 {
        let p = polygon[i].as_dvec2() - origin;
        let q = polygon[i + 1].as_dvec2() - origin;
        twice += p.perp_dot(q);
    }
    (0.5 * twice) as f32
}

// ---------------------------------------------------------------------------------------------------------
// Convex polygons on the ground plane, overlap and IoU

/// Largest vertex count the stack-only clipping path handles (two rectangles need at most 8).
const CLIP_STACK: usize = 16;

/// Clips the convex polygon `subject` by the convex polygon `clip` (Sutherland–Hodgman), in f64.
///
/// `clip_sign` is +1 when `clip` runs counter-clockwise and −1 when clockwise, so either orientation
/// works. Points on a clip edge count as inside, so touching polygons give a degenerate (zero-area) result
/// and identical polygons give the polygon itself (possibly with repeated vertices, which do not change
/// the area). `out` and `scratch` must each hold `2·(subject.len() + clip.len())` points; the result is
/// `out[..returned]`.
fn clip_convex(subject: &[DVec2], clip: &[DVec2], clip_sign: f64, out: &mut [DVec2], scratch: &mut [DVec2]) -> usize {
    let capacity = out.len().min(scratch.len());
    let mut n = subject.len().min(capacity);
    out[..n].copy_from_slice(&subject[..n]);
    for (i, &edge_start) in clip.iter().enumerate() {
        if n == 0 {
            break;
        }
        let edge = clip[(i + 1) % clip.len()] - edge_start;
        if edge == DVec2::ZERO {
            continue;
        }
        // Signed distance-like side of each point: ≥ 0 inside (left of a counter-clockwise edge).
        let side = |p: DVec2| clip_sign * edge.perp_dot(p - edge_start);
        scratch[..n].copy_from_slice(&out[..n]);
        let mut k = 0;
        let mut prev = scratch[n - 1];
        let mut prev_side = side(prev);
        for &cur in &scratch[..n] {
            let cur_side = side(cur);
            let (prev_in, cur_in) = (prev_side >= 0.0, cur_side >= 0.0);
            if prev_in != cur_in && k < capacity {
                // Strictly opposite signs (one ≥ 0, the other < 0): the denominator is never 0.
                let t = prev_side / (prev_side - cur_side);
                out[k] = prev + (cur - prev) * t;
                k += 1;
            }
            if cur_in && k < capacity {
                out[k] = cur;
                k += 1;
            }
            prev = cur;
            prev_side = cur_side;
        }
        n = k;
    }
    n
}

/// Signed shoelace area in f64 (positive counter-clockwise).
fn polygon_area_f64(polygon: &[DVec2]) -> f64 {
    let n = polygon.len();
    if n < 3 {
        return 0.0;
    }
    let origin = polygon[0];
    let mut twice = 0.0;
    for i in 1..n - 1 {
        twice += (polygon[i] - origin).perp_dot(polygon[i + 1] - origin);
    }
    0.5 * twice
}

/// Intersection of two convex polygons on the ground plane (either orientation each; the result runs in
/// `a`'s orientation). The result may contain repeated vertices where edges touch; touching polygons give
/// a degenerate polygon of zero area and disjoint ones an empty list. Computed in f64. Polygons with
/// fewer than 3 vertices give an empty list.
pub fn convex_intersection(a: &[Vec2], b: &[Vec2]) -> Vec<Vec2> {
    if a.len() < 3 || b.len() < 3 {
        return Vec::new();
    }
    let a64: Vec<DVec2> = a.iter().map(|p| p.as_dvec2()).collect();
    let b64: Vec<DVec2> = b.iter().map(|p| p.as_dvec2()).collect();
    let capacity = 2 * (a.len() + b.len());
    let (mut out, mut scratch) = (vec![DVec2::ZERO; capacity], vec![DVec2::ZERO; capacity]);
    let sign = polygon_area_f64(&b64).signum();
    let n = clip_convex(&a64, &b64, sign, &mut out, &mut scratch);
    out[..n].iter().map(|p| p.as_vec2()).collect()
}

/// Area of the intersection of two convex polygons (either orientation), ≥ 0.
pub fn convex_intersection_area(a: &[Vec2], b: &[Vec2]) -> f32 {
    polygon_area(&convex_intersection(a, b)).abs()
}

/// Top-down overlap area of two rectangles given counter-clockwise (f64 corners), without allocating.
fn rectangle_overlap_area(a: &[DVec2; 4], b: &[DVec2; 4]) -> f64 {
    let mut out = [DVec2::ZERO; CLIP_STACK];
    let mut scratch = [DVec2::ZERO; CLIP_STACK];
    let n = clip_convex(a, b, 1.0, &mut out, &mut scratch);
    polygon_area_f64(&out[..n]).abs()
}

/// Footprint corners in f64 (counter-clockwise, the [`Cuboid::footprint`] order).
fn footprint_f64(c: &Cuboid) -> [DVec2; 4] {
    let centre = c.centre.truncate().as_dvec2();
    let (sin, cos) = (c.yaw as f64).sin_cos();
    let half_w = DVec2::new(cos, sin) * (0.5 * c.size.x as f64);
    let half_d = DVec2::new(-sin, cos) * (0.5 * c.size.y as f64);
    [centre - half_w - half_d, centre + half_w - half_d, centre + half_w + half_d, centre - half_w + half_d]
}

/// Whether the footprints' bounding circles are apart, so the footprints cannot overlap.
fn footprints_apart(a: &Cuboid, b: &Cuboid) -> bool {
    let ra = 0.5 * a.size.truncate().length();
    let rb = 0.5 * b.size.truncate().length();
    let d = (a.centre.truncate() - b.centre.truncate()).length_squared();
    d > (ra + rb) * (ra + rb)
}

/// Top-down (ground-plane) overlap area of the two footprints in m², ignoring heights. Used for the
/// contextual 2D overlap features of small objects on supporting surfaces.
pub fn footprint_overlap_area(a: &Cuboid, b: &Cuboid) -> f32 {
    if footprints_apart(a, b) {
        return 0.0;
    }
    rectangle_overlap_area(&footprint_f64(a), &footprint_f64(b)) as f32
}

/// Length of the overlap of the two cuboids' vertical ranges (0 when apart or touching).
pub fn vertical_overlap(a: &Cuboid, b: &Cuboid) -> f32 {
    (a.top().min(b.top()) - a.bottom().max(b.bottom())).max(0.0)
}

/// Volume of the 3D intersection of two cuboids (m³): footprint overlap area × vertical overlap, exact
/// for boxes that turn about z only. Computed in f64.
pub fn intersection_volume(a: &Cuboid, b: &Cuboid) -> f32 {
    intersection_volume_f64(a, b) as f32
}

fn intersection_volume_f64(a: &Cuboid, b: &Cuboid) -> f64 {
    let dz = (a.top().min(b.top()) as f64 - a.bottom().max(b.bottom()) as f64).max(0.0);
    if dz <= 0.0 || footprints_apart(a, b) {
        return 0.0;
    }
    rectangle_overlap_area(&footprint_f64(a), &footprint_f64(b)) * dz
}

/// 3D intersection over union as the SUN RGB-D benchmark computes it: the area of the intersection of
/// the two footprint rectangles × the overlap of the vertical ranges, divided by
/// `vol a + vol b − intersection`. In [0, 1]; symmetric; unchanged by turning either box by π. Degenerate
/// input (a non-positive union, non-finite values) gives 0.
pub fn iou_3d(a: &Cuboid, b: &Cuboid) -> f32 {
    let inter = intersection_volume_f64(a, b);
    if inter <= 0.0 {
        return 0.0;
    }
    let union = a.volume() as f64 + b.volume() as f64 - inter;
    let iou = inter / union;
    if iou.is_finite() && union > 0.0 {
        iou.clamp(0.0, 1.0) as f32
    } else {
        0.0
    }
}

// ---------------------------------------------------------------------------------------------------------
// The structured-prediction loss (paper eq. 5)

/// The paper's loss (eq. 5) for a present truth and a present estimate (ȳ = 1):
/// `Δ = 1 − IoU(B, B̄)·(1 + cos(θ̄ − θ))/2`, with θ the cuboids' yaws. In [0, 1]; 0 only for the same box
/// with the same front, and a box turned by π (same IoU, opposite front) costs 1.
pub fn detection_loss(truth: &Cuboid, estimate: &Cuboid) -> f32 {
    let iou = iou_3d(truth, estimate);
    let agreement = 0.5 * (1.0 + (estimate.yaw - truth.yaw).cos());
    (1.0 - iou * agreement).clamp(0.0, 1.0)
}

/// The loss of eq. 5 with the presence cases of the paper: `None` means absent (y = 0 for the truth: the
/// scene has no instance; ȳ = 0 for the estimate: the hypothesis says "no object").
///
/// * truth present, estimate present: [`detection_loss`];
/// * both absent: 0;
/// * one present and the other absent: 1.
pub fn structured_loss(truth: Option<&Cuboid>, estimate: Option<&Cuboid>) -> f32 {
    match (truth, estimate) {
        (Some(t), Some(e)) => detection_loss(t, e),
        (None, None) => 0.0,
        _ => 1.0,
    }
}

// ---------------------------------------------------------------------------------------------------------
// Cuboid-to-wall relations (contextual features D(B, M) and A(B, M))

/// Distance from a point to the segment `p`–`q` (to `p` when the segment has zero length).
pub fn point_segment_distance(point: Vec2, p: Vec2, q: Vec2) -> f32 {
    let edge = q - p;
    let len2 = edge.length_squared();
    let t = if len2 > 0.0 { ((point - p).dot(edge) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (point - (p + edge * t)).length()
}

/// Whether a ground-plane point lies inside a simple polygon (even-odd rule, so the polygon may be
/// non-convex and run either way round, as real room annotations do). An empty polygon contains nothing.
pub fn polygon_contains(polygon: &[Vec2], p: Vec2) -> bool {
    let mut inside = false;
    let mut j = polygon.len().wrapping_sub(1);
    for i in 0..polygon.len() {
        let (a, b) = (polygon[i], polygon[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Signed area of a polygon (shoelace formula, positive counter-clockwise), in f64.
pub fn polygon_signed_area(polygon: &[Vec2]) -> f64 {
    let n = polygon.len();
    (0..n)
        .map(|i| {
            let (a, b) = (polygon[i].as_dvec2(), polygon[(i + 1) % n].as_dvec2());
            a.perp_dot(b)
        })
        .sum::<f64>()
        * 0.5
}

/// Whether two edges of a polygon that share no corner cross or touch (f64 orientation tests).
fn segments_meet(a: Vec2, b: Vec2, c: Vec2, d: Vec2) -> bool {
    let (a, b, c, d) = (a.as_dvec2(), b.as_dvec2(), c.as_dvec2(), d.as_dvec2());
    let orient = |p: glam::DVec2, q: glam::DVec2, r: glam::DVec2| (q - p).perp_dot(r - p);
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    let within = |p: glam::DVec2, q: glam::DVec2, r: glam::DVec2| {
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return true;
    }
    (d1 == 0.0 && within(c, d, a))
        || (d2 == 0.0 && within(c, d, b))
        || (d3 == 0.0 && within(a, b, c))
        || (d4 == 0.0 && within(a, b, d))
}

/// What is wrong with a polygon as a footprint or a room outline, or `None` when it is a usable simple
/// polygon: fewer than 3 corners, a non-finite corner, a zero (or, relative to its edges, negligible) area —
/// collinear corners —, or two non-adjacent edges that cross or touch (a bow-tie).
pub fn polygon_problem(polygon: &[Vec2]) -> Option<&'static str> {
    let n = polygon.len();
    if n < 3 {
        return Some("has fewer than 3 corners");
    }
    if polygon.iter().any(|c| !c.is_finite()) {
        return Some("has a non-finite corner");
    }
    let perimeter: f64 = (0..n).map(|i| polygon[i].as_dvec2().distance(polygon[(i + 1) % n].as_dvec2())).sum();
    // A square of the same perimeter has area (perimeter/4)²; a real outline has a sizeable fraction of it.
    if polygon_signed_area(polygon).abs() <= 1e-3 * (perimeter / 4.0).powi(2) || perimeter < 1e-6 {
        return Some("has (nearly) zero area: its corners are collinear or coincide");
    }
    for i in 0..n {
        for j in i + 1..n {
            // Adjacent edges share a corner (edge n−1 and edge 0 too).
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue;
            }
            if segments_meet(polygon[i], polygon[(i + 1) % n], polygon[j], polygon[(j + 1) % n]) {
                return Some("intersects itself");
            }
        }
    }
    None
}

/// Cells per side of the grid whose centres [`in_view_share`] projects (1 000 points a box).
pub const IN_VIEW_SAMPLES: u32 = 10;

/// The share of `cuboid`'s volume that the camera sees inside its `width × height` image: of the centres
/// of an [`IN_VIEW_SAMPLES`]³ grid of equal cells of the box, the fraction in front of the camera
/// ([`Camera::project`]) whose projection lies on the image (0-based pixel centres, so the image spans
/// [−0.5, width − 0.5) × [−0.5, height − 0.5)). Occlusion is not considered. An annotation rule that keeps
/// every object with enough visible pixels (synth's `visible`, the shipped test set's) keeps boxes the
/// camera barely sees — a bed beside the camera whose foot is in the picture — and their box cannot be
/// recovered from the points.
pub fn in_view_share(cuboid: &Cuboid, camera: &Camera, width: u32, height: u32) -> f32 {
    let n = IN_VIEW_SAMPLES;
    let mut inside = 0u32;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let unit = |c: u32| (c as f32 + 0.5) / n as f32 - 0.5;
                let local = Vec3::new(unit(i), unit(j), unit(k)) * cuboid.size;
                if let Some(uv) = camera.project(cuboid.from_local(local)) {
                    inside += on_image(uv, [width, height]) as u32;
                }
            }
        }
    }
    inside as f32 / (n * n * n) as f32
}

/// Whether 0-based image coordinates `uv` lie on an image of `size` (width, height) pixels: pixel centres
/// are integers, so the image spans [−0.5, width − 0.5) × [−0.5, height − 0.5).
pub fn on_image(uv: Vec2, size: [u32; 2]) -> bool {
    let (w, h) = (size[0] as f32 - 0.5, size[1] as f32 - 0.5);
    uv.x >= -0.5 && uv.x < w && uv.y >= -0.5 && uv.y < h
}
