//! Geometry tests against analytic answers and an independent Monte-Carlo IoU.

use std::f32::consts::{FRAC_PI_2, PI};

use cog_gpu::geometry::{
    convex_hull, convex_hull_area, convex_intersection, convex_intersection_area, detection_loss,
    footprint_overlap_area, intersection_volume, iou_3d, point_segment_distance, polygon_area, project_points,
    projected_hull_area, structured_loss, vertical_overlap, voxel_corners, wrap_angle, Camera, Cuboid,
};
use glam::{Mat3, Vec2, Vec3};

/// A small deterministic generator (64-bit LCG, high bits) so the property tests need no crate.
struct Lcg(u64);

impl Lcg {
    fn next_u32(&mut self) -> u32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 33) as u32
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        self.next_u32() as f64 / (1u64 << 31) as f64
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit() as f32
    }
    fn cuboid(&mut self) -> Cuboid {
        Cuboid::new(
            Vec3::new(self.range(-1.0, 1.0), self.range(1.0, 3.0), self.range(0.0, 1.0)),
            Vec3::new(self.range(0.2, 2.0), self.range(0.2, 2.0), self.range(0.2, 1.5)),
            self.range(-PI, PI),
        )
    }
}

fn assert_close(got: f32, want: f32, tol: f32, what: &str) {
    assert!((got - want).abs() <= tol, "{what}: got {got}, want {want} (±{tol})");
}

fn unit_box(yaw: f32) -> Cuboid {
    Cuboid::new(Vec3::new(0.3, 2.0, 0.5), Vec3::new(1.2, 0.8, 1.0), yaw)
}

// ----------------------------------------------------------------------------------------------------
// Polygons

#[test]
fn shoelace_area_is_signed_by_orientation() {
    let ccw = [Vec2::new(0.0, 0.0), Vec2::new(2.0, 0.0), Vec2::new(2.0, 3.0), Vec2::new(0.0, 3.0)];
    assert_close(polygon_area(&ccw), 6.0, 1e-6, "ccw rectangle");
    let mut cw = ccw;
    cw.reverse();
    assert_close(polygon_area(&cw), -6.0, 1e-6, "cw rectangle");
    let triangle = [Vec2::new(1.0, 1.0), Vec2::new(4.0, 1.0), Vec2::new(1.0, 5.0)];
    assert_close(polygon_area(&triangle), 6.0, 1e-6, "3-4-5 triangle");
    assert_eq!(polygon_area(&ccw[..2]), 0.0);
}

fn square(centre: Vec2, side: f32, angle: f32) -> Vec<Vec2> {
    let (s, c) = angle.sin_cos();
    let a = Vec2::new(c, s) * (0.5 * side);
    let b = Vec2::new(-s, c) * (0.5 * side);
    vec![centre - a - b, centre + a - b, centre + a + b, centre - a + b]
}

#[test]
fn convex_intersection_of_known_shapes() {
    let unit = square(Vec2::ZERO, 1.0, 0.0);
    // Identical polygons: the polygon itself.
    assert_close(convex_intersection_area(&unit, &unit), 1.0, 1e-6, "identical");
    // Offset by (0.5, 0.5): a quarter.
    let shifted = square(Vec2::new(0.5, 0.5), 1.0, 0.0);
    assert_close(convex_intersection_area(&unit, &shifted), 0.25, 1e-6, "quarter overlap");
    // Touching along an edge, and at a corner: nothing.
    let beside = square(Vec2::new(1.0, 0.0), 1.0, 0.0);
    assert_close(convex_intersection_area(&unit, &beside), 0.0, 1e-7, "touching edge");
    let diagonal = square(Vec2::new(1.0, 1.0), 1.0, 0.0);
    assert_close(convex_intersection_area(&unit, &diagonal), 0.0, 1e-7, "touching corner");
    // Disjoint: an empty polygon.
    assert!(convex_intersection(&unit, &square(Vec2::new(3.0, 0.0), 1.0, 0.0)).is_empty());
    // A unit square and itself turned by 45°: a regular octagon of area 2(√2 − 1).
    let turned = square(Vec2::ZERO, 1.0, PI / 4.0);
    assert_close(convex_intersection_area(&unit, &turned), 2.0 * (2f32.sqrt() - 1.0), 1e-6, "octagon");
    // Clockwise inputs give the same area.
    let mut cw = turned.clone();
    cw.reverse();
    assert_close(convex_intersection_area(&unit, &cw), 2.0 * (2f32.sqrt() - 1.0), 1e-6, "octagon, cw clip");
    assert_close(convex_intersection_area(&cw, &unit), 2.0 * (2f32.sqrt() - 1.0), 1e-6, "octagon, cw subject");
    // Containment: the smaller polygon.
    let small = square(Vec2::new(0.1, -0.1), 0.3, 0.7);
    assert_close(convex_intersection_area(&unit, &small), 0.09, 1e-6, "contained");
    assert_close(convex_intersection_area(&small, &unit), 0.09, 1e-6, "containing");
}

#[test]
fn convex_hull_drops_interior_and_collinear_points() {
    let points = [
        Vec2::new(0.0, 0.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(2.0, 0.0),
        Vec2::new(2.0, 2.0),
        Vec2::new(0.0, 2.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(0.5, 1.5),
        Vec2::new(2.0, 2.0),
    ];
    let hull = convex_hull(&points);
    assert_eq!(hull.len(), 4, "hull {hull:?}");
    assert_close(polygon_area(&hull), 4.0, 1e-6, "hull is counter-clockwise with area 4");
    let mut pts = points;
    assert_close(convex_hull_area(&mut pts), 4.0, 1e-6, "hull area");
    let mut line = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(2.0, 2.0)];
    assert_eq!(convex_hull_area(&mut line), 0.0);
    // More points than the stack path holds.
    let mut many: Vec<Vec2> = (0..40).map(|i| Vec2::from_angle(i as f32 * 0.05 * PI)).collect();
    let want = 0.5 * 40.0 * (0.05 * PI).sin(); // regular 40-gon inscribed in the unit circle
    assert_close(convex_hull_area(&mut many), want, 1e-5, "40-gon");
}

// ----------------------------------------------------------------------------------------------------
// IoU

#[test]
fn identical_boxes_have_iou_one() {
    for yaw in [0.0, 0.4, -2.0, PI] {
        let b = unit_box(yaw);
        assert_close(iou_3d(&b, &b), 1.0, 1e-6, "identical");
    }
}

#[test]
fn disjoint_boxes_have_iou_zero() {
    let a = unit_box(0.3);
    let mut far = a;
    far.centre.x += 5.0;
    assert_eq!(iou_3d(&a, &far), 0.0);
    let mut above = a;
    above.centre.z += 1.5;
    assert_eq!(iou_3d(&a, &above), 0.0);
}

#[test]
fn box_against_itself_turned_by_ninety_degrees() {
    let square_footprint = Cuboid::new(Vec3::new(0.0, 2.0, 0.4), Vec3::new(0.9, 0.9, 0.8), 0.2);
    let mut turned = square_footprint;
    turned.yaw += FRAC_PI_2;
    assert_close(iou_3d(&square_footprint, &turned), 1.0, 1e-5, "square footprint");

    let (w, d) = (1.5f32, 0.6f32);
    let rect = Cuboid::new(Vec3::new(0.0, 2.0, 0.4), Vec3::new(w, d, 0.8), 0.7);
    let mut turned = rect;
    turned.yaw += FRAC_PI_2;
    let m = w.min(d);
    assert_close(iou_3d(&rect, &turned), m * m / (2.0 * w * d - m * m), 1e-5, "w×d rectangle");
}

#[test]
fn half_overlaps_give_one_third() {
    let a = unit_box(0.8);
    // Shift by half the width along the width axis: intersection V/2, union 3V/2.
    let mut shifted = a;
    shifted.centre += (a.width_axis() * (0.5 * a.size.x)).extend(0.0);
    assert_close(iou_3d(&a, &shifted), 1.0 / 3.0, 1e-5, "half width");
    // Same along the depth axis.
    let mut shifted = a;
    shifted.centre += (a.depth_axis() * (0.5 * a.size.y)).extend(0.0);
    assert_close(iou_3d(&a, &shifted), 1.0 / 3.0, 1e-5, "half depth");
    // Vertical half overlap.
    let mut raised = a;
    raised.centre.z += 0.5 * a.size.z;
    assert_close(iou_3d(&a, &raised), 1.0 / 3.0, 1e-5, "half height");
    assert_close(vertical_overlap(&a, &raised), 0.5 * a.size.z, 1e-6, "vertical overlap");
    assert_close(intersection_volume(&a, &raised), 0.5 * a.volume(), 1e-5, "intersection volume");
}

#[test]
fn touching_faces_give_zero() {
    let a = Cuboid::new(Vec3::new(0.0, 2.0, 0.5), Vec3::new(1.0, 0.5, 1.0), 0.0);
    let mut side = a;
    side.centre.x += 1.0;
    assert_eq!(iou_3d(&a, &side), 0.0, "side by side");
    let mut on_top = a;
    on_top.centre.z += 1.0;
    assert_eq!(iou_3d(&a, &on_top), 0.0, "stacked");
    // Turned boxes touch up to rounding.
    let b = unit_box(0.9);
    let mut beside = b;
    beside.centre += (b.width_axis() * b.size.x).extend(0.0);
    assert!(iou_3d(&b, &beside) < 1e-5, "turned, side by side: {}", iou_3d(&b, &beside));
}

#[test]
fn iou_is_symmetric_and_blind_to_the_front() {
    let mut rng = Lcg(7);
    for _ in 0..200 {
        let (a, b) = (rng.cuboid(), rng.cuboid());
        let ab = iou_3d(&a, &b);
        assert_close(iou_3d(&b, &a), ab, 1e-5, "symmetry");
        let mut flipped = b;
        flipped.yaw += PI;
        assert_close(iou_3d(&a, &flipped), ab, 1e-5, "yaw + π");
    }
}

#[test]
fn footprint_overlap_ignores_heights() {
    let a = Cuboid::new(Vec3::new(0.0, 2.0, 0.5), Vec3::new(1.0, 1.0, 1.0), 0.0);
    let high = Cuboid::new(Vec3::new(0.0, 2.0, 5.0), Vec3::new(1.0, 1.0, 0.1), PI / 4.0);
    assert_close(footprint_overlap_area(&a, &high), 2.0 * (2f32.sqrt() - 1.0), 1e-5, "octagon");
    assert_eq!(iou_3d(&a, &high), 0.0);
    let mut apart = high;
    apart.centre.x = 3.0;
    assert_eq!(footprint_overlap_area(&a, &apart), 0.0);
}

/// Independent estimate: sample the bounding box of both cuboids uniformly and count points in both.
fn monte_carlo_iou(a: &Cuboid, b: &Cuboid, rng: &mut Lcg, samples: usize) -> f32 {
    let corners: Vec<Vec3> = a.corners().into_iter().chain(b.corners()).collect();
    let lo = corners.iter().fold(Vec3::splat(f32::INFINITY), |m, c| m.min(*c));
    let hi = corners.iter().fold(Vec3::splat(f32::NEG_INFINITY), |m, c| m.max(*c));
    let (mut both, mut either) = (0usize, 0usize);
    for _ in 0..samples {
        let p = Vec3::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y), rng.range(lo.z, hi.z));
        let (in_a, in_b) = (a.contains(p), b.contains(p));
        both += (in_a && in_b) as usize;
        either += (in_a || in_b) as usize;
    }
    both as f32 / either as f32
}

#[test]
fn random_pairs_have_valid_iou_matching_monte_carlo() {
    let mut rng = Lcg(12345);
    let mut checked = 0;
    for i in 0..1000 {
        let a = rng.cuboid();
        let b = rng.cuboid();
        let ab = iou_3d(&a, &b);
        assert!((0.0..=1.0).contains(&ab), "pair {i}: IoU {ab}");
        assert_close(iou_3d(&b, &a), ab, 1e-5, "symmetry");
        assert_close(iou_3d(&a, &a), 1.0, 1e-5, "self");
        // A few overlapping pairs against the independent estimate.
        if ab > 0.05 && checked < 6 {
            let estimate = monte_carlo_iou(&a, &b, &mut rng, 200_000);
            assert_close(ab, estimate, 0.02, &format!("pair {i} {a:?} {b:?} vs Monte Carlo"));
            checked += 1;
        }
    }
    assert_eq!(checked, 6, "too few overlapping random pairs");
    // Nearby pairs overlap more often: check those too.
    for _ in 0..4 {
        let a = rng.cuboid();
        let mut b = a;
        b.centre += Vec3::new(rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), rng.range(-0.2, 0.2));
        b.yaw += rng.range(-1.0, 1.0);
        b.size *= rng.range(0.7, 1.3);
        let estimate = monte_carlo_iou(&a, &b, &mut rng, 200_000);
        assert_close(iou_3d(&a, &b), estimate, 0.02, "nearby pair vs Monte Carlo");
    }
}

// ----------------------------------------------------------------------------------------------------
// Loss

#[test]
fn loss_at_full_overlap_depends_on_orientation() {
    let square_box = Cuboid::new(Vec3::new(0.0, 2.0, 0.5), Vec3::new(0.8, 0.8, 1.0), 0.3);
    let mut turned = square_box;
    assert_close(detection_loss(&square_box, &turned), 0.0, 1e-6, "same box");
    turned.yaw += FRAC_PI_2;
    assert_close(detection_loss(&square_box, &turned), 0.5, 1e-5, "quarter turn");
    turned.yaw += FRAC_PI_2;
    assert_close(detection_loss(&square_box, &turned), 1.0, 1e-5, "reversed front");
    // Partial overlap, same orientation: 1 − IoU.
    let a = unit_box(0.0);
    let mut b = a;
    b.centre.z += 0.5 * a.size.z;
    assert_close(detection_loss(&a, &b), 2.0 / 3.0, 1e-5, "1 − 1/3");
}

#[test]
fn loss_presence_cases() {
    let a = unit_box(0.1);
    assert_eq!(structured_loss(None, None), 0.0);
    assert_eq!(structured_loss(Some(&a), None), 1.0);
    assert_eq!(structured_loss(None, Some(&a)), 1.0);
    assert_close(structured_loss(Some(&a), Some(&a)), 0.0, 1e-6, "both present");
}

// ----------------------------------------------------------------------------------------------------
// Projection and voxels

/// An upright camera (Rtilt = I): upright (x, y, z) is camera (x, −z, y), so the optical axis is +y.
fn level_camera(f: f32) -> Camera {
    Camera::new([f, f, 320.0, 240.0], Mat3::IDENTITY)
}

#[test]
fn hull_area_of_a_square_facing_the_camera() {
    let (f, s, z) = (500.0f32, 0.4f32, 2.5f32);
    let camera = level_camera(f);
    // A square of side s in the plane y = z, centred off the axis (translation does not change the area).
    let square = [
        Vec3::new(0.3, z, 0.1),
        Vec3::new(0.3 + s, z, 0.1),
        Vec3::new(0.3 + s, z, 0.1 + s),
        Vec3::new(0.3, z, 0.1 + s),
    ];
    let want = (f * s / z).powi(2);
    assert_close(projected_hull_area(&camera, &square).unwrap(), want, want * 1e-5, "square");
    // A cube centred on the optical axis: the hull is the image of its nearer face.
    let d = 0.6f32;
    let cube = Cuboid::new(Vec3::new(0.0, z, 0.0), Vec3::new(s, d, s), 0.0);
    let near = z - 0.5 * d;
    let want = (f * s / near).powi(2);
    assert_close(projected_hull_area(&camera, &cube.corners()).unwrap(), want, want * 1e-5, "cube");
    // Turning the cube by π changes nothing.
    let turned = Cuboid { yaw: PI, ..cube };
    assert_close(projected_hull_area(&camera, &turned.corners()).unwrap(), want, want * 1e-4, "cube yaw π");
}

#[test]
fn hull_area_is_none_behind_the_camera() {
    let camera = level_camera(500.0);
    let straddling = Cuboid::new(Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 1.0), 0.0);
    assert_eq!(projected_hull_area(&camera, &straddling.corners()), None);
    let behind = Cuboid::new(Vec3::new(0.0, -3.0, 0.0), Vec3::new(1.0, 1.0, 1.0), 0.0);
    assert_eq!(projected_hull_area(&camera, &behind.corners()), None);
    assert_eq!(projected_hull_area(&camera, &[]), Some(0.0));
    let projected = project_points(&camera, &[Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.0, -2.0, 0.0)]);
    // The principal point (cx, cy) = (320, 240) in 1-based pixels is (319, 239) 0-based.
    assert_eq!(projected, vec![Some(Vec2::new(319.0, 239.0)), None]);
}

/// Whether `p` lies inside the counter-clockwise convex polygon (a small tolerance in pixels² on the edge).
fn inside_convex(p: Vec2, hull: &[Vec2]) -> bool {
    (0..hull.len()).all(|i| {
        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
        (b - a).perp_dot(p - a) >= -1e-3
    })
}

#[test]
fn interior_points_project_inside_the_hull() {
    let tilt = Mat3::from_rotation_x(-0.15) * Mat3::from_rotation_y(0.05);
    let camera = Camera::new([520.0, 515.0, 310.0, 250.0], tilt);
    let mut rng = Lcg(99);
    for _ in 0..20 {
        let mut c = rng.cuboid();
        c.centre.y += 1.0;
        let image: Vec<Vec2> = c.corners().iter().map(|&p| camera.project(p).unwrap()).collect();
        let hull = convex_hull(&image);
        let area = projected_hull_area(&camera, &c.corners()).unwrap();
        assert_close(area, polygon_area(&hull).abs(), area * 1e-5, "hull area");
        for _ in 0..50 {
            let local = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), rng.range(-0.5, 0.5)) * c.size;
            let p = camera.project(c.from_local(local)).unwrap();
            assert!(inside_convex(p, &hull), "{p} outside the hull of {c:?}");
        }
    }
}

#[test]
fn single_voxel_is_the_cuboid() {
    let c = Cuboid::new(Vec3::new(0.5, 2.0, 0.4), Vec3::new(1.1, 0.7, 0.8), 0.6);
    let v = voxel_corners(&c, [1, 1, 1], [0, 0, 0]);
    for (got, want) in v.iter().zip(c.corners()) {
        assert!(got.distance(want) < 1e-6, "{got} vs {want}");
    }
}

#[test]
fn voxel_indices_run_from_left_front_bottom() {
    // yaw = 0: width along +x (left = −x), depth along +y (front = −y, towards the camera), height +z.
    let c = Cuboid::new(Vec3::new(0.0, 3.0, 1.0), Vec3::new(2.0, 3.0, 4.0), 0.0);
    let grid = [2, 3, 4];
    let first = voxel_corners(&c, grid, [0, 0, 0]);
    assert!(first[0].distance(Vec3::new(-1.0, 1.5, -1.0)) < 1e-6, "{}", first[0]);
    assert!(first[6].distance(Vec3::new(0.0, 2.5, 0.0)) < 1e-6, "{}", first[6]);
    let last = voxel_corners(&c, grid, [1, 2, 3]);
    assert!(last[0].distance(Vec3::new(0.0, 3.5, 2.0)) < 1e-6, "{}", last[0]);
    assert!(last[6].distance(c.corners()[6]) < 1e-6, "{}", last[6]);
    // The voxels tile the cuboid: each is a box of 1/24 the volume, centred inside it.
    let mut rng = Lcg(3);
    let turned = Cuboid { yaw: 1.1, ..rng.cuboid() };
    let grid = [3, 2, 5];
    let mut centres = Vec::new();
    for i in 0..3 {
        for j in 0..2 {
            for k in 0..5 {
                let v = voxel_corners(&turned, grid, [i, j, k]);
                let centre = v.iter().copied().sum::<Vec3>() / 8.0;
                let cell = (v[1] - v[0]).length() * (v[3] - v[0]).length() * (v[4] - v[0]).length();
                assert_close(cell, turned.volume() / 30.0, 1e-5, "voxel volume");
                let local = turned.to_local(centre) / turned.size + 0.5; // in (0, 1)
                let want = Vec3::new((i as f32 + 0.5) / 3.0, (j as f32 + 0.5) / 2.0, (k as f32 + 0.5) / 5.0);
                assert!(local.distance(want) < 1e-4, "voxel {i},{j},{k}: {local} vs {want}");
                centres.push(centre);
            }
        }
    }
    assert_eq!(centres.len(), 30);
}

// ----------------------------------------------------------------------------------------------------
// Walls

#[test]
fn segment_distance() {
    let (p, q) = (Vec2::new(0.0, 0.0), Vec2::new(2.0, 0.0));
    assert_close(point_segment_distance(Vec2::new(1.0, 1.5), p, q), 1.5, 1e-6, "above");
    assert_close(point_segment_distance(Vec2::new(5.0, 4.0), p, q), 5.0, 1e-6, "past the end");
    assert_close(point_segment_distance(Vec2::new(3.0, 4.0), p, p), 5.0, 1e-6, "zero-length");
}

// ----------------------------------------------------------------------------------------------------
// Cuboid basics

#[test]
fn from_polygon_round_trips_both_orientations() {
    let mut rng = Lcg(2024);
    for _ in 0..200 {
        let c = rng.cuboid();
        let f = c.footprint();
        for (name, poly) in [("ccw", f), ("cw", [f[1], f[0], f[3], f[2]])] {
            let back = Cuboid::from_polygon(poly, c.bottom(), c.top()).unwrap();
            assert!(back.centre.distance(c.centre) < 1e-5, "{name}: centre {} vs {}", back.centre, c.centre);
            assert!(back.size.distance(c.size) < 1e-5, "{name}: size {} vs {}", back.size, c.size);
            assert_close(wrap_angle(back.yaw - c.yaw), 0.0, 1e-5, name);
        }
    }
    let degenerate = [Vec2::ZERO, Vec2::ZERO, Vec2::ONE, Vec2::Y];
    assert_eq!(Cuboid::from_polygon(degenerate, 0.0, 1.0), None);
}

#[test]
fn contains_corners_and_rejects_outside_points() {
    // Exactly representable corners.
    let c = Cuboid::new(Vec3::new(1.0, 2.0, 0.5), Vec3::new(2.0, 1.0, 1.0), 0.0);
    for corner in c.corners() {
        assert!(c.contains(corner), "{corner}");
    }
    assert!(!c.contains(Vec3::new(2.01, 2.0, 0.5)));
    assert!(!c.contains(Vec3::new(1.0, 2.0, 1.01)));
    // Turned: corners pulled 0.1 % towards the centre are in, pushed 0.1 % out are out.
    let t = Cuboid { yaw: 0.7, ..c };
    for corner in t.corners() {
        assert!(t.contains(t.centre + (corner - t.centre) * 0.999));
        assert!(!t.contains(t.centre + (corner - t.centre) * 1.001));
    }
}
