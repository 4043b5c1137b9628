//! Room layout (`cog_gpu::room_layout`): free-space IoU against hand-computed boxes, the Manhattan and
//! cubical region assignment of hand-placed points, the summed-area IoU against the direct count, the
//! hypotheses' 80 % rule, the orientation features against their closed form, the wall leaks against a
//! direct count, front walls and reach features beyond the points of a room larger than the sensor's range,
//! the floor and ceiling snapped to constructed planes, the COG of a wall seen square on against its
//! hand-computed bins, the edge-orientation alignment against a chord-built reference, the model file,
//! and the PLY writer read back.

use cog_gpu::frame::RoomLayout;
use cog_gpu::geometry::Camera;
use cog_gpu::ply::{write_ply, LineSet};
use cog_gpu::room_layout::baseline::dominant_orientation;
use cog_gpu::room_layout::free_space::{
    free_space_counts, free_space_iou, YawFreeSpace, EVALUATION_PHASE, TRAINING_PHASE,
};
use cog_gpu::room_layout::learn::yaw_difference_mod_90;
use cog_gpu::room_layout::orientation::{edge_alignment, edge_orientation_features, orientation_features};
use cog_gpu::room_layout::voxels::{
    box_features, cubical_region, features, front_plane_evidence, manhattan_region, CogAxes, CogPoint, Descriptor,
    Discretisation, ScoringTables, YawCells, BOX_FEATURES, COG_BINS, EDGE_FEATURES, LAYERS, ORIENTATION_FEATURES,
    REACH_FEATURES, WALL_LEAK_FEATURES,
};
use cog_gpu::room_layout::{
    missing_rays, orientation_yaw, room_axes, snap_floor_and_ceiling, to_mm, LayoutScene, RoomBox, MIN_ROOM_HEIGHT,
    ORIENTATIONS, SNAP_MIN_POINTS,
};
use glam::{Mat3, Vec2, Vec3};

/// A camera at the upright origin looking along +y with no tilt, with a very wide field of view (focal
/// length 1 px on a 2000 × 2000 image: everything within 89.9° of the axis is in view), so that the view
/// frustum is (almost) the half-space y > 0.
fn wide_camera() -> (Camera, [u32; 2]) {
    (Camera::new([1.0, 1.0, 1000.5, 1000.5], Mat3::IDENTITY), [2000, 2000])
}

fn rect(x0: f32, x1: f32, y0: f32, y1: f32, floor: f32, ceiling: f32) -> RoomLayout {
    RoomLayout {
        corners: vec![Vec2::new(x0, y0), Vec2::new(x1, y0), Vec2::new(x1, y1), Vec2::new(x0, y1)],
        floor,
        ceiling,
    }
}

#[test]
fn identical_rooms_have_free_space_iou_one() {
    let (camera, size) = wide_camera();
    let room = rect(-2.0, 2.0, 1.0, 5.0, -1.5, 1.0);
    let counts = free_space_counts(&room, &room, &camera, size, (Vec2::X, Vec2::Y), EVALUATION_PHASE);
    // 40 × 40 columns × 25 layers, all in view.
    assert_eq!(counts.a, 40 * 40 * 25);
    assert_eq!(free_space_iou(&room, &room, &camera, size), 1.0);
}

#[test]
fn disjoint_rooms_have_free_space_iou_zero() {
    let (camera, size) = wide_camera();
    let a = rect(-2.0, 0.0, 1.0, 5.0, -1.5, 1.0);
    let b = rect(0.0, 2.0, 1.0, 5.0, -1.5, 1.0);
    assert_eq!(free_space_iou(&a, &b, &camera, size), 0.0);
    // Same footprint, stacked heights: disjoint too.
    let c = rect(-2.0, 0.0, 1.0, 5.0, 1.0, 2.0);
    assert_eq!(free_space_iou(&a, &c, &camera, size), 0.0);
}

#[test]
fn partial_overlap_matches_the_hand_computation() {
    let (camera, size) = wide_camera();
    // A: 4 m × 4 m × 2.5 m; B: shifted by 1 m in x and 0.5 m up. Intersection 3 × 4 × 2 = 24 m³, union
    // 40 + 40 − 24 = 56 m³: IoU 24/56 = 3/7 (voxel boundaries fall on the box faces, so the voxel count
    // is exact).
    let a = rect(-2.0, 2.0, 1.0, 5.0, -1.5, 1.0);
    let b = rect(-1.0, 3.0, 1.0, 5.0, -1.0, 1.5);
    let iou = free_space_iou(&a, &b, &camera, size);
    assert!((iou - 3.0 / 7.0).abs() < 1e-12, "{iou}");
}

/// The evaluation's voxel centres lie 2.5 cm from the 5 cm lattice of the hypotheses' walls: a room whose
/// walls are on it scores as the same room moved by 0.1 mm (within that move's volume), where centres at
/// odd multiples of 5 cm (training's grid phase) let the half-open inside test decide a whole slab of
/// voxels.
#[test]
fn the_evaluation_does_not_jump_when_walls_move_a_tenth_of_a_millimetre() {
    let (camera, size) = wide_camera();
    let truth = rect(-2.0, 2.0, 1.0, 5.0, -1.5, 1.0);
    // Walls on the 5 cm lattice (a layout of `synth --seed 21` frame 29 as the shipped model predicted it),
    // two of them at odd multiples of 5 cm: on training's voxel centres.
    let (x0, x1, y0, y1) = (-2.2, 2.35, 0.0, 5.85);
    let on_lattice = rect(x0, x1, y0, y1, -1.5, 1.0);
    let moved = rect(x0 - 1e-4, x1 + 1e-4, y0 - 1e-4, y1 + 1e-4, -1.5, 1.0);
    let iou = |a: &RoomLayout, phase: f32| free_space_counts(a, &truth, &camera, size, (Vec2::X, Vec2::Y), phase).iou();
    let (before, after) = (iou(&on_lattice, EVALUATION_PHASE), iou(&moved, EVALUATION_PHASE));
    assert!((before - after).abs() < 1e-3, "{before} against {after}");
    assert_eq!(free_space_iou(&on_lattice, &truth, &camera, size), before);
    let (before, after) = (iou(&on_lattice, TRAINING_PHASE), iou(&moved, TRAINING_PHASE));
    assert!((before - after).abs() > 1e-2, "training's grid jumps here: {before} against {after}");
}

#[test]
fn only_the_space_in_view_counts() {
    let (camera, size) = wide_camera();
    // Behind the camera (y < 0) nothing is in view: two rooms differing only there are the same free space.
    let a = rect(-2.0, 2.0, -3.0, 4.0, -1.5, 1.0);
    let b = rect(-2.0, 2.0, 0.0, 4.0, -1.5, 1.0);
    assert_eq!(free_space_iou(&a, &b, &camera, size), 1.0);
    // A normal camera (fx = 500 on 640 × 480) sees a 65° wide cone: a room entirely beside it is not seen.
    let narrow = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
    let beside = rect(5.0, 9.0, 0.0, 1.0, -1.5, 1.0);
    let counts = free_space_counts(&beside, &beside, &narrow, [640, 480], (Vec2::X, Vec2::Y), EVALUATION_PHASE);
    assert_eq!(counts.a, 0);
    assert_eq!(counts.iou(), 0.0);
}

/// A frame-like scene: the camera of `wide_camera`, points on the walls of a 4 × 6 m room.
fn room_scene() -> LayoutScene {
    let mut points = Vec::new();
    let mut normals = Vec::new();
    for i in 0..80 {
        for k in 0..25 {
            let (t, z) = (i as f32 / 80.0, -1.4 + k as f32 * 0.1);
            // Front wall y = 5, side walls x = ±2 (from y = 0.5 to 5), floor.
            points.push(Vec3::new(-2.0 + 4.0 * t, 5.0, z));
            normals.push(Vec3::NEG_Y);
            points.push(Vec3::new(-2.0, 0.5 + 4.5 * t, z));
            normals.push(Vec3::X);
            points.push(Vec3::new(2.0, 0.5 + 4.5 * t, z));
            normals.push(Vec3::NEG_X);
            points.push(Vec3::new(-2.0 + 4.0 * t, 0.5 + 4.5 * (k as f32 / 25.0), -1.5));
            normals.push(Vec3::Z);
        }
    }
    let gradients = vec![Vec2::ZERO; points.len()];
    scene_of(points, normals, gradients, 1.0, Vec::new())
}

/// A scene seen by `wide_camera`, floor at −1.5 m, every pixel sampled.
fn scene_of(
    points: Vec<Vec3>,
    normals: Vec<Vec3>,
    gradients: Vec<Vec2>,
    ceiling: f32,
    missing_rays: Vec<Vec3>,
) -> LayoutScene {
    let (camera, image_size) = wide_camera();
    LayoutScene { camera, image_size, points, normals, gradients, floor: -1.5, ceiling, stride: 1, missing_rays }
}

/// Index of the orientation with yaw `degrees` (panics when there is none: a test set-up error).
fn orientation_at(degrees: f32) -> usize {
    (0..ORIENTATIONS).find(|&k| (orientation_yaw(k).to_degrees() - degrees).abs() < 1e-3).expect("no such yaw")
}

/// Index of the orientation with yaw 0 (the room frame is the upright frame).
const YAW_ZERO: usize = 22;

#[test]
fn orientations_are_evenly_spaced_modulo_ninety_degrees_and_include_zero() {
    assert_eq!(orientation_at(0.0), YAW_ZERO);
    let mut degrees: Vec<f32> = (0..ORIENTATIONS).map(|k| orientation_yaw(k).to_degrees()).collect();
    assert!(degrees.iter().all(|d| (-45.0..45.0).contains(d)), "{degrees:?}");
    // Around the circle modulo 90° (the wrap from the last back to the first included), every gap is the
    // same: 90° / ORIENTATIONS.
    degrees.push(degrees[0] + 90.0);
    for pair in degrees.windows(2) {
        assert!((pair[1] - pair[0] - 90.0 / ORIENTATIONS as f32).abs() < 1e-3, "{pair:?}");
    }
}

#[test]
fn manhattan_regions_of_hand_placed_points() {
    // Room u ∈ [−2000, 2000], v ∈ [0, 5000] mm. Regions: 0..3 interior of front/left/back/right,
    // 4..7 their wall bands (±150 mm), 8..11 outside.
    let b = RoomBox { yaw_index: YAW_ZERO as u32, u0: -2000, u1: 2000, v0: 0, v1: 5000 };
    let cases = [
        ((0, 4000), 0),     // nearest the front wall, 1000 mm from it
        ((-1500, 2500), 1), // nearest the left wall
        ((0, 800), 2),      // nearest the back wall
        ((1500, 2500), 3),  // nearest the right wall
        ((0, 4900), 4),     // 100 mm inside the front wall
        ((0, 5100), 4),     // 100 mm outside it: still the band
        ((-2150, 2500), 5), // exactly 150 mm outside the left wall: band (inclusive)
        ((0, -150), 6),     // back band
        ((1900, 2500), 7),  // right band
        ((0, 5151), 8),     // 151 mm beyond the front wall: exterior
        ((-3000, 2500), 9), // beyond the left wall
        ((0, -1000), 10),   // behind the back wall
        ((2500, 2500), 11), // beyond the right wall
        // Corners: the 45° diagonals split them. 120 mm from the front, 100 mm from the right: right band.
        ((1900, 4880), 7),
        // 100 mm from the front, 120 mm from the right: front band.
        ((1880, 4900), 4),
        // 200 mm from the front, 160 mm from the right: nearest the right wall but beyond its band: right
        // interior.
        ((1840, 4800), 3),
        // Outside the front-right corner, further out in u than in v: right exterior.
        ((3000, 5500), 11),
        // Further out in v than in u: front exterior.
        ((2500, 6000), 8),
        // Interior near the corner: 400 mm from the front, 600 from the right: front interior.
        ((1400, 4600), 0),
    ];
    for ((u, v), expected) in cases {
        assert_eq!(manhattan_region(u, v, &b), expected, "point ({u}, {v})");
    }
}

#[test]
fn cubical_regions_of_hand_placed_points() {
    let b = RoomBox { yaw_index: YAW_ZERO as u32, u0: -2000, u1: 2000, v0: 0, v1: 4000 };
    // 4 × 4 cells of 1 m: i along u from the left, j along v from the back; region 4j + i.
    assert_eq!(cubical_region(-1999, 1, &b), 0);
    assert_eq!(cubical_region(-500, 500, &b), 1);
    assert_eq!(cubical_region(1500, 3500, &b), 15);
    assert_eq!(cubical_region(2000, 4000, &b), 15); // the far walls belong to the last cell
    assert_eq!(cubical_region(0, 2000, &b), 10);
    assert_eq!(cubical_region(2001, 100, &b), u32::MAX);
    assert_eq!(cubical_region(0, -1, &b), u32::MAX);
}

#[test]
fn features_of_a_constructed_room_put_wall_points_in_their_bands() {
    let scene = room_scene();
    let cells = YawCells::new(&scene, YAW_ZERO, false);
    assert_eq!(cells.total_points as usize, scene.points.len());
    let truth = RoomBox { yaw_index: YAW_ZERO as u32, u0: -2000, u1: 2000, v0: 0, v1: 5000 };
    let phi = features(MANHATTAN, &cells, &truth);
    assert_eq!(phi.len(), 288 + BOX_FEATURES);
    let voxel_part = &phi[..288];
    // The voxel part sums to 1 (every point is in exactly one region, layer and class).
    assert!((voxel_part.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    let n = scene.points.len() as f32;
    // Front wall band (region 4), "facing" class 0, summed over the layers: the 2000 front-wall points.
    let front_facing: f32 = (0..LAYERS).map(|l| phi[(4 * LAYERS + l) * 4]).sum();
    assert!((front_facing * n - 2000.0).abs() < 0.5, "{}", front_facing * n);
    // The left and right walls' points are "facing" in their own bands 5 and 7, except the ones in the
    // front corners within 150 mm (cells of the front band by the diagonal split): nothing is exterior.
    let exterior: f32 = voxel_part[8 * LAYERS * 4..].iter().sum();
    assert_eq!(exterior, 0.0);
    // No wall leaks, and no reach (the walls are at the points).
    assert_eq!(phi[288 + ORIENTATION_FEATURES..], [0.0; WALL_LEAK_FEATURES + REACH_FEATURES]);
    // A room 1 m too narrow on the left puts the left wall's points outside, in region 9.
    let narrow = RoomBox { u0: -1000, ..truth };
    let phi = features(MANHATTAN, &cells, &narrow);
    let left_exterior: f32 =
        (0..LAYERS).flat_map(|l| (0..4).map(move |c| (9 * LAYERS + l) * 4 + c)).map(|i| phi[i]).sum();
    assert!(left_exterior * n > 1500.0, "{}", left_exterior * n);
    // ... and its leak feature (wall 1, left) sees them: sqrt(> 1500 / 8000) > 0.43.
    assert!(phi[288 + ORIENTATION_FEATURES + 1] > 0.43, "{}", phi[288 + ORIENTATION_FEATURES + 1]);
}

/// The Manhattan descriptor without COG (the first tests' features).
const MANHATTAN: Descriptor = Descriptor { discretisation: Discretisation::Manhattan, cog: false, edges: false };

/// Both discretisations, each without and with COG.
fn all_descriptors() -> Vec<Descriptor> {
    [Discretisation::Manhattan, Discretisation::Cubical]
        .map(|d| [false, true].map(|cog| Descriptor::new(d, cog, cog)))
        .concat()
}

/// A model whose voxel (and COG) weights are all zero, or tiny, scores its box and edge features to the
/// fixed point's resolution: before 2026-12-08 zero voxel weights made the scale 1 (the box term rounded to
/// whole units) and weights of 1e-30 an overflowing one.
#[test]
fn a_model_of_box_features_alone_is_scored_to_full_resolution() {
    let scene = turned(&room_scene(), 14.0);
    let (cells, _) = cog_gpu::room_layout::hypotheses(&scene, false, true);
    let desc = Descriptor::new(Discretisation::Manhattan, false, true);
    let b = RoomBox { yaw_index: orientation_at(14.0) as u32, u0: -2000, u1: 2000, v0: 0, v1: 5000 };
    let start = desc.voxel_dim() + desc.cog_dim();
    for voxel_weight in [0.0, 1e-30] {
        let w: Vec<f64> = (0..desc.dim())
            .map(|i| if i < start { voxel_weight } else { ((i * 37 % 101) as f64 - 50.0) / 7.3 })
            .collect();
        let tables = ScoringTables::new(desc, &cells, &w);
        let s = cog_gpu::room_layout::voxels::scores_cpu(&cells, &tables, &[b])[0];
        let phi = features(desc, &cells[b.yaw_index as usize], &b);
        let dot: f64 = phi.iter().zip(&w).map(|(&x, &w)| x as f64 * w).sum();
        let total = tables.total(&cells[b.yaw_index as usize], &b, s) as f64 / tables.scale;
        assert!((total - dot).abs() < 1e-6 * (1.0 + dot.abs()), "voxel weights {voxel_weight}: {total} vs {dot}");
        assert!(dot.fract().abs() > 1e-3, "a dot product that is no whole number tests the resolution: {dot}");
    }
}

#[test]
fn scoring_tables_give_the_dot_product_with_the_features() {
    // The scene turned by 14°, so that the orientation features differ between orientations (the cells of
    // `hypotheses` carry them) and the orientation term of the score is tested too; gradients with no
    // structure, so that every COG bin is used.
    let mut scene = turned(&room_scene(), 14.0);
    scene.gradients =
        (0..scene.points.len()).map(|i| Vec2::new((i as f32 * 0.37).sin(), (i as f32 * 0.11).cos()) * 0.5).collect();
    let (cells, _) = cog_gpu::room_layout::hypotheses(&scene, true, true);
    assert!(cells.iter().any(|c| c.orientation != cells[0].orientation));
    assert!(cells.iter().any(|c| c.edge_orientation != cells[0].edge_orientation));
    for desc in all_descriptors() {
        let w: Vec<f64> = (0..desc.dim()).map(|i| ((i * 37 % 101) as f64 - 50.0) / 7.0).collect();
        let tables = ScoringTables::new(desc, &cells, &w);
        let boxes = [
            RoomBox { yaw_index: orientation_at(14.0) as u32, u0: -2000, u1: 2000, v0: 0, v1: 5000 },
            RoomBox { yaw_index: orientation_at(-30.0) as u32, u0: -2600, u1: 1500, v0: -300, v1: 4000 },
        ];
        let scores = cog_gpu::room_layout::voxels::scores_cpu(&cells, &tables, &boxes);
        for (b, s) in boxes.iter().zip(scores) {
            let phi = features(desc, &cells[b.yaw_index as usize], b);
            let extra = if desc.edges { EDGE_FEATURES } else { 0 };
            assert_eq!(phi.len(), desc.voxel_dim() + desc.cog_dim() + BOX_FEATURES + extra);
            let start = desc.voxel_dim() + desc.cog_dim();
            assert_eq!(phi[start..start + ORIENTATION_FEATURES], cells[b.yaw_index as usize].orientation);
            if desc.edges {
                assert_eq!(phi[start + BOX_FEATURES..], cells[b.yaw_index as usize].edge_orientation);
            }
            if desc.cog {
                // The COG part holds the gradients inside the room (not all zero).
                assert!(phi[desc.voxel_dim()..start].iter().any(|&x| x > 0.0), "{desc:?}");
            }
            let dot: f64 = phi.iter().zip(&w).map(|(&x, &w)| x as f64 * w).sum();
            // Fixed point: each cell's contribution and the box features' term are rounded to 1/scale.
            let cells_of_yaw = cells[b.yaw_index as usize].centres.len() as f64;
            let total = tables.total(&cells[b.yaw_index as usize], b, s) as f64 / tables.scale;
            assert!((total - dot).abs() < 1e-5 + (cells_of_yaw + 1.0) / tables.scale, "{desc:?} {b:?}");
        }
    }
}

#[test]
fn cog_of_a_wall_ahead_falls_in_the_hand_computed_bins() {
    // The front wall y = 5 m seen square on (camera at the origin looking along +y, focal length 1 px): the
    // wall's horizontal axis a = x projects to the image direction (0.2, 0) and the vertical to (0, −0.2)
    // at every point of the wall. A horizontal image gradient (a vertical edge) is a gradient along a:
    // angle 0, all of it in bin 0. A vertical image gradient (a horizontal edge) is a gradient along the
    // vertical: 90°, half-way between bins 4 (80°) and 5 (100°). The wall's plane is spanned by a (plane
    // 0); plane 1 (spanned by b = y, the viewing direction) is seen edge-on there and gets nothing.
    let mut scene = room_scene();
    let (a, b) = room_axes(YAW_ZERO);
    let ahead = Vec3::new(0.0, 5.0, 0.0);
    let axes = CogAxes::new(&scene.camera, a, b);
    let vertical_edge = CogPoint::new(&scene, &axes, ahead, Vec2::new(0.8, 0.0));
    assert_eq!(vertical_edge.bin0[0], 0);
    assert!((vertical_edge.shares[0][0] - 0.8).abs() < 1e-5 && vertical_edge.shares[0][1].abs() < 1e-5);
    assert_eq!(vertical_edge.shares[1], [0.0; 2]);
    let horizontal_edge = CogPoint::new(&scene, &axes, ahead, Vec2::new(0.0, 0.6));
    assert_eq!(horizontal_edge.bin0[0], 4);
    for share in horizontal_edge.shares[0] {
        assert!((share - 0.3).abs() < 1e-4, "{:?}", horizontal_edge.shares);
    }
    assert_eq!(horizontal_edge.layer as usize, 3); // z = 0 is 1.5 m above the floor of a 2.5 m room: layer 3
                                                   // The whole room with horizontal edges on the front wall only (its 2 000 points; every other point has no
                                                   // gradient): the room's COG features are the front band's (region 4) bins 4 and 5, half of the frame's
                                                   // gradient magnitude each, whatever the layer; every other COG feature is 0.
    scene.gradients =
        scene.normals.iter().map(|&n| if n == Vec3::NEG_Y { Vec2::new(0.0, 0.6) } else { Vec2::ZERO }).collect();
    let cells = YawCells::new(&scene, YAW_ZERO, true);
    let desc = Descriptor::new(Discretisation::Manhattan, true, false);
    let truth = RoomBox { yaw_index: YAW_ZERO as u32, u0: -2000, u1: 2000, v0: 0, v1: 5000 };
    let phi = features(desc, &cells, &truth);
    assert_eq!(phi.len(), 288 + 12 * LAYERS * COG_BINS + BOX_FEATURES);
    let front_band = |bin: usize| -> f32 { (0..LAYERS).map(|l| phi[desc.cog_index(4, l, bin)]).sum() };
    assert!(
        (front_band(4) - 0.5).abs() < 1e-4 && (front_band(5) - 0.5).abs() < 1e-4,
        "{} {}",
        front_band(4),
        front_band(5)
    );
    let cog_total: f32 = phi[288..288 + desc.cog_dim()].iter().sum();
    assert!((cog_total - 1.0).abs() < 1e-5, "{cog_total}");
    // The cubical descriptor puts them in its cells along the front wall (j = 3: regions 12–15), on its
    // front-face plane (plane 0 as well); its cuboid must hold the wall's cells (centres at v = 5025 mm).
    let cubical = Descriptor::new(Discretisation::Cubical, true, false);
    let phi = features(cubical, &cells, &RoomBox { v1: 5050, ..truth });
    let back_rows: f32 = (0..12)
        .flat_map(|r| (0..LAYERS).flat_map(move |l| (0..COG_BINS).map(move |k| (r, l, k))))
        .map(|(r, l, k)| phi[cubical.cog_index(r, l, k)])
        .sum();
    assert_eq!(back_rows, 0.0);
    let front_row: f32 = (12..16)
        .flat_map(|r| (0..LAYERS).map(move |l| (r, l)))
        .map(|(r, l)| phi[cubical.cog_index(r, l, 4)] + phi[cubical.cog_index(r, l, 5)])
        .sum();
    assert!((front_row - 1.0).abs() < 1e-4, "{front_row}");
}

#[test]
fn edges_along_the_room_axes_align_with_their_own_orientation() {
    // Lines along the room's axes, drawn on the left wall (x = −2 m) at six heights, from 1 to 5 m ahead:
    // each point's gradient is perpendicular to its line's image, which the test takes from the projection
    // of two points 1 m apart on the 3D line (an independent construction of the projected axis: a 3D line
    // projects to a straight line, and the long chord keeps the f32 rounding of pixel positions small). At yaw 0
    // every edge runs along the axis b: its alignment is 1 and the sum is the total gradient magnitude, for
    // any power; turned orientations align less, and the features peak at yaw 0 (1 and 1). The vertical
    // edges of the same wall (gradients along the image's rows) are left out: they add nothing anywhere.
    let (camera, _) = wide_camera();
    let (mut points, mut normals, mut gradients) = (Vec::new(), Vec::new(), Vec::new());
    for h in 0..6 {
        for i in 0..40 {
            let p = Vec3::new(-2.0, 1.0 + 0.1 * i as f32, -1.4 + 0.45 * h as f32);
            let (q0, q1) = (camera.project(p).unwrap(), camera.project(p + Vec3::Y).unwrap());
            let along = (q1 - q0).normalize();
            points.push(p);
            normals.push(Vec3::X);
            gradients.push(Vec2::new(-along.y, along.x) * 0.5);
            // A vertical edge at the same point: its image runs along the projected vertical.
            let (v0, v1) = (camera.project(p).unwrap(), camera.project(p + Vec3::Z).unwrap());
            let up = (v1 - v0).normalize();
            points.push(p);
            normals.push(Vec3::X);
            gradients.push(Vec2::new(-up.y, up.x) * 0.7);
        }
    }
    let scene = scene_of(points, normals, gradients, 1.5, Vec::new());
    let along_b_total = 240.0 * 0.5;
    for power in [8, 64] {
        let alignment = edge_alignment(&scene, power);
        assert!(
            (alignment[YAW_ZERO] - along_b_total).abs() < 1e-3 * along_b_total,
            "{} {:?}",
            alignment[YAW_ZERO],
            &alignment[YAW_ZERO - 3..YAW_ZERO + 4]
        );
        for (k, &x) in alignment.iter().enumerate() {
            if k != YAW_ZERO {
                assert!(x < alignment[YAW_ZERO], "power {power}: orientation {k} {x}");
            }
        }
        // Every orientation against a reference built from chords: the image direction of a room axis at a
        // point is the chord from the point's image to the image of the point 1 m along the axis.
        for (k, &x) in alignment.iter().enumerate() {
            let (a, b) = room_axes(k);
            let reference: f64 = scene
                .points
                .iter()
                .zip(&scene.gradients)
                .filter(|(_, g)| g.x.abs() < 0.6) // the b-edges (the vertical edges have g = (0.7, 0))
                .map(|(&p, &g)| {
                    let q = camera.project(p).unwrap();
                    let chord = |d: Vec2| (camera.project(p + d.extend(0.0)).unwrap() - q).normalize();
                    let edge = Vec2::new(-g.y, g.x).normalize();
                    let along = edge.dot(chord(a)).abs().max(edge.dot(chord(b)).abs()) as f64;
                    g.length() as f64 * along.powi(power)
                })
                .sum();
            assert!((x - reference).abs() < 2e-3 * along_b_total, "power {power}, orientation {k}: {x} vs {reference}");
        }
        // 10° off, the lines recede to another vanishing point: a clearly lower alignment.
        assert!(alignment[orientation_at(10.0)] < 0.95 * alignment[YAW_ZERO], "power {power}");
    }
    let features = edge_orientation_features(&scene);
    assert_eq!(features[YAW_ZERO], [1.0, 1.0]);
    // No gradient at all: every feature 0.
    let flat = LayoutScene { gradients: vec![Vec2::ZERO; scene.points.len()], ..scene };
    assert!(edge_orientation_features(&flat).iter().all(|f| *f == [0.0; EDGE_FEATURES]));
}

/// `scene` turned about the vertical axis by `degrees` (points and normals).
fn turned(scene: &LayoutScene, degrees: f32) -> LayoutScene {
    let r = Mat3::from_rotation_z(degrees.to_radians());
    LayoutScene {
        points: scene.points.iter().map(|&p| r * p).collect(),
        normals: scene.normals.iter().map(|&n| r * n).collect(),
        ..scene.clone()
    }
}

#[test]
fn wall_leaks_count_the_points_beyond_each_wall() {
    let scene = turned(&room_scene(), -20.0);
    let k = orientation_at(-20.0);
    let cells = YawCells::new(&scene, k, false);
    let (a, b) = room_axes(k);
    // The cell centre of each point, directly (5 cm cells centred at 50·i + 25 mm).
    let centre = |mm: i32| mm.div_euclid(50) * 50 + 25;
    let centres: Vec<(i32, i32)> =
        scene.points.iter().map(|p| (centre(to_mm(p.truncate().dot(a))), centre(to_mm(p.truncate().dot(b))))).collect();
    for room_box in [
        RoomBox { yaw_index: k as u32, u0: -2000, u1: 2000, v0: 0, v1: 5000 },
        RoomBox { yaw_index: k as u32, u0: -1500, u1: 1200, v0: -300, v1: 3000 },
        RoomBox { yaw_index: k as u32, u0: -2400, u1: 100, v0: 1000, v1: 4700 },
    ] {
        let count = |f: &dyn Fn(i32, i32) -> bool| centres.iter().filter(|&&(u, v)| f(u, v)).count() as u64;
        let direct = [
            count(&|_, v| v > room_box.v1 + 150),
            count(&|u, _| u < room_box.u0 - 150),
            count(&|_, v| v < room_box.v0 - 150),
            count(&|u, _| u > room_box.u1 + 150),
        ];
        assert_eq!(cells.points_beyond_walls(&room_box), direct, "{room_box:?}");
        let features = box_features(&cells, &room_box);
        for (wall, &n) in direct.iter().enumerate() {
            let expected = (n as f64 / scene.points.len() as f64).sqrt();
            assert_eq!(features[ORIENTATION_FEATURES + wall], expected);
        }
    }
    // The hand case: with the front wall at 3 m the front wall's 2 000 points (at 5 m) are beyond it, and
    // with the room's own walls nothing is.
    let walls_at_3 = RoomBox { yaw_index: k as u32, u0: -2100, u1: 2100, v0: 0, v1: 3000 };
    assert!(cells.points_beyond_walls(&walls_at_3)[0] >= 2000);
    let own = RoomBox { yaw_index: k as u32, u0: -2100, u1: 2100, v0: 0, v1: 5100 };
    assert_eq!(cells.points_beyond_walls(&own), [0, 0, 0, 0]);
}

#[test]
fn floor_and_ceiling_snap_to_their_planes() {
    // A floor at −1.2 m (100 points facing up) with a noise tail to −1.25 m (the 0.001 quantile's side),
    // walls, and a ceiling at 1.4 m (100 points facing down): 2.6 m high, seen.
    let mut points = Vec::new();
    let mut normals = Vec::new();
    for i in 0..100 {
        let x = i as f32 * 0.01;
        points.push(Vec3::new(x, 2.0, -1.2 + if i % 10 == 0 { -0.05 } else { 0.0 }));
        normals.push(Vec3::Z);
        points.push(Vec3::new(x, 2.0, 1.4 + if i % 10 == 0 { 0.03 } else { 0.0 }));
        normals.push(Vec3::NEG_Z);
        points.push(Vec3::new(x, 3.0, -1.0 + 0.02 * i as f32));
        normals.push(Vec3::NEG_Y);
    }
    // Quantiles at the noise tails: both snap to the planes' medians.
    assert_eq!(snap_floor_and_ceiling(&points, &normals, -1.25, 1.43), (-1.2, 1.4));
    // No ceiling seen (without the ceiling's points the highest reach 0.98 m, 2.18 m above the floor):
    // floor + MIN_ROOM_HEIGHT.
    let (unseen_points, unseen_normals): (Vec<Vec3>, Vec<Vec3>) =
        points.iter().zip(&normals).filter(|(_, n)| n.z > -0.5).map(|(p, n)| (*p, *n)).unzip();
    let (floor, ceiling) = snap_floor_and_ceiling(&unseen_points, &unseen_normals, -1.25, 0.98);
    assert_eq!(floor, -1.2);
    assert!((ceiling - (-1.2 + MIN_ROOM_HEIGHT)).abs() < 1e-6, "{ceiling}");
    // Fewer than SNAP_MIN_POINTS facing points near a quantile: the quantile stays.
    let few = SNAP_MIN_POINTS - 1;
    let sparse_points: Vec<Vec3> = points.iter().step_by(3).take(few).copied().collect();
    let sparse_normals: Vec<Vec3> = normals.iter().step_by(3).take(few).copied().collect();
    assert_eq!(snap_floor_and_ceiling(&sparse_points, &sparse_normals, -1.25, 1.43).0, -1.25);
    // Points facing the wrong way (a table top's underside near the floor) do not snap the floor.
    let down: Vec<Vec3> = normals.iter().map(|n| -*n).collect();
    assert_eq!(snap_floor_and_ceiling(&points, &down, -1.25, 1.43), (-1.25, 1.43));
}

#[test]
fn orientation_features_follow_the_walls_normals() {
    // Every wall normal of the room scene is ±x or ±y: at yaw φ (|φ| ≤ 45°) each contributes cos^p φ, so
    // relative to the peak at the walls' orientation the broad feature is cos⁸ φ and the sharp one cos⁶⁴ φ.
    for walls_deg in [0.0f32, 20.0, -36.0] {
        let scene = turned(&room_scene(), walls_deg);
        let evidence = orientation_features(&scene);
        let peak = orientation_at(walls_deg);
        assert_eq!(evidence[peak], [1.0, 1.0, 1.0], "walls at {walls_deg}°");
        assert_eq!(dominant_orientation(&scene), peak);
        for (k, o) in evidence.iter().enumerate() {
            let off = yaw_difference_mod_90(orientation_yaw(k), walls_deg.to_radians()).cos() as f64;
            assert!((o[0] as f64 - off.powi(8)).abs() < 1e-4, "{walls_deg}° k={k}: {o:?}");
            assert!((o[1] as f64 - off.powi(64)).abs() < 1e-4, "{walls_deg}° k={k}: {o:?}");
            assert_eq!(o[2], if k == peak { 1.0 } else { 0.0 });
        }
    }
    // Hand values 10° off the walls: cos⁸ 10° = 0.8847, cos⁶⁴ 10° = 0.3754.
    let o = orientation_features(&room_scene())[orientation_at(10.0)];
    assert!((o[0] - 0.8847).abs() < 1e-3 && (o[1] - 0.3754).abs() < 1e-3, "{o:?}");
    // Without wall normals (only the floor) there is no evidence.
    let mut floor_only = room_scene();
    floor_only.normals.iter_mut().for_each(|n| *n = Vec3::Z);
    assert!(orientation_features(&floor_only).iter().all(|o| *o == [0.0; ORIENTATION_FEATURES]));
}

#[test]
fn summed_area_iou_equals_the_direct_count() {
    let (camera, size) = wide_camera();
    let truth = RoomLayout {
        corners: vec![Vec2::new(-2.0, 0.5), Vec2::new(2.5, 0.2), Vec2::new(2.9, 5.0), Vec2::new(-1.8, 5.3)],
        floor: -1.4,
        ceiling: 1.2,
    };
    for k in [0usize, orientation_at(-36.0), YAW_ZERO, orientation_at(20.0), ORIENTATIONS - 1] {
        let boxes = [
            RoomBox { yaw_index: k as u32, u0: -2000, u1: 2000, v0: 100, v1: 5000 },
            RoomBox { yaw_index: k as u32, u0: -1200, u1: 2600, v0: -800, v1: 3900 },
        ];
        let table = YawFreeSpace::new(k, &camera, size, -1.5, 1.0, &truth, [-3.0, 3.0, -1.0, 5.5]);
        for b in &boxes {
            let direct = free_space_counts(&b.to_room(-1.5, 1.0), &truth, &camera, size, room_axes(k), TRAINING_PHASE);
            assert_eq!(table.counts(b), direct, "orientation {k}, {b:?}");
        }
    }
}

#[test]
fn hypotheses_hold_eighty_percent_and_include_the_room() {
    let scene = room_scene();
    let (cells, boxes) = cog_gpu::room_layout::hypotheses(&scene, false, false);
    assert!(!boxes.is_empty());
    for b in &boxes {
        let inside = cells[b.yaw_index as usize].points_inside(b);
        assert!(inside as f64 >= 0.8 * scene.points.len() as f64, "{b:?} holds {inside}");
        assert!(b.u1 - b.u0 >= 1000 && b.v1 - b.v0 >= 1000);
        // The camera (the origin) is in the room.
        assert!(b.u0 <= 0 && b.u1 >= 0 && b.v0 <= 0 && b.v1 >= 0, "{b:?}");
    }
    // The walls are at u = ±2000 (cells centred at ±1975 / ±2025), v = 5000; the back at the camera (0).
    let truth = RoomLayout { corners: rect(-2.0, 2.0, 0.0, 5.0, -1.5, 1.0).corners, floor: -1.5, ceiling: 1.0 };
    let best = boxes
        .iter()
        .map(|b| free_space_iou(&b.to_room(-1.5, 1.0), &truth, &scene.camera, scene.image_size))
        .fold(0.0, f64::max);
    assert!(best > 0.97, "best hypothesis IoU {best}");
}

#[test]
fn the_front_wall_reaches_beyond_the_farthest_points() {
    // The 4 × 5 m room of `room_scene` seen only to y < 3 m, as by a sensor of 3 m range: the farthest cell
    // ends at v = 3000 mm and the front wall (5 m) returns no depth.
    let full = room_scene();
    let (points, normals): (Vec<Vec3>, Vec<Vec3>) =
        full.points.iter().zip(&full.normals).filter(|(p, _)| p.y < 3.0).map(|(p, n)| (*p, *n)).unzip();
    let scene = LayoutScene { points, normals, ..full };
    let (cells, boxes) = cog_gpu::room_layout::hypotheses(&scene, false, false);
    let at_yaw_zero: Vec<&RoomBox> = boxes.iter().filter(|b| b.yaw_index as usize == YAW_ZERO).collect();
    assert_eq!(cells[YAW_ZERO].farthest_front(), 3000);
    // Front walls at the farthest edge and 0.5, 1 and 2 m beyond it, all among the hypotheses.
    for v1 in [3000, 3500, 4000, 5000] {
        assert!(at_yaw_zero.iter().any(|b| b.v1 == v1), "no front wall at {v1} mm");
    }
    // The other walls stop at their points (the left points at x = −2.0 fill the cell [−2000, −1950) mm,
    // the right ones at 2.0 the cell [2000, 2050)) and at the camera (the back: the points start at 0.5 m).
    for b in &at_yaw_zero {
        assert!(b.u0 >= -2000 && b.u1 <= 2050 && b.v0 == 0, "{b:?}");
    }
    // The room itself (front wall 2 m beyond the points) is a hypothesis, and the best one.
    let truth = rect(-2.0, 2.0, 0.0, 5.0, -1.5, 1.0);
    let iou = |b: &RoomBox| free_space_iou(&b.to_room(-1.5, 1.0), &truth, &scene.camera, scene.image_size);
    let best = boxes.iter().max_by(|a, b| iou(a).total_cmp(&iou(b))).unwrap();
    assert_eq!((best.yaw_index as usize, best.v1), (YAW_ZERO, 5000), "{best:?}");
    assert!(iou(best) > 0.97, "best hypothesis IoU {}", iou(best));
    // Reach features [r > 0, r, r², (r > 0)·f] with f = 3 m, the farthest cell's edge.
    let reach_of =
        |b: &RoomBox| box_features(&cells[YAW_ZERO], b)[ORIENTATION_FEATURES + WALL_LEAK_FEATURES..].to_vec();
    let room = RoomBox { yaw_index: YAW_ZERO as u32, u0: -2000, u1: 2050, v0: 0, v1: 5000 };
    assert_eq!(reach_of(&room).len(), REACH_FEATURES);
    // The scene has no missing rays, so the three `missing` products are 0; `near` is, of the points whose
    // ray crosses the plane y = 3 m between floor and ceiling, those within 0.5 m short of it (the side
    // walls from y = 2.5 m on), counted here directly, and it enters as its square root.
    let [missing, near] = cells[YAW_ZERO].front_evidence;
    assert_eq!(missing, 0.0);
    let crosses = |p: &Vec3| p.y > 0.0 && 3.0 * p.z / p.y > -1.5 && 3.0 * p.z / p.y < 1.0;
    let crossing: Vec<&Vec3> = scene.points.iter().filter(|p| crosses(p)).collect();
    let near_by_hand = crossing.iter().filter(|p| p.y >= 2.5).count() as f32 / crossing.len() as f32;
    assert!(near_by_hand > 0.0 && near_by_hand < 1.0);
    assert_eq!(near, near_by_hand);
    let s = (near as f64).sqrt();
    assert_eq!(reach_of(&room), [1.0, 2.0, 4.0, 3.0, 0.0, 0.0, 0.0, s, 2.0 * s]);
    assert_eq!(reach_of(&RoomBox { v1: 3500, ..room }), [1.0, 0.5, 0.25, 3.0, 0.0, 0.0, 0.0, s, 0.5 * s]);
    assert_eq!(reach_of(&RoomBox { v1: 3000, ..room }), [0.0; REACH_FEATURES]);
    // With the evidence of an unseen wall (set by hand), the `missing` products follow.
    let mut unseen = cells[YAW_ZERO].clone();
    unseen.front_evidence = [0.75, 0.0];
    let reach =
        box_features(&unseen, &RoomBox { v1: 4000, ..room })[ORIENTATION_FEATURES + WALL_LEAK_FEATURES..].to_vec();
    assert_eq!(reach, [1.0, 1.0, 1.0, 3.0, 0.75, 0.75, 0.75, 0.0, 0.0]);
}

#[test]
fn front_plane_evidence_counts_the_rays_through_the_plane_by_hand() {
    // Camera at the origin looking along +y; floor −1.5 m, ceiling 1.0 m; the plane y = 4 m.
    let mut points = Vec::new();
    // 10 points of a wall on the plane (crossing, near), 5 of a chair at 2 m (crossing, not near),
    // 3 floor points at 2 m (their rays pass below the floor at the plane: not crossing).
    points.extend((0..10).map(|i| Vec3::new(-1.0 + 0.2 * i as f32, 4.0, 0.0)));
    points.extend((0..5).map(|i| Vec3::new(0.1 * i as f32, 2.0, 0.0)));
    points.extend((0..3).map(|i| Vec3::new(0.1 * i as f32, 2.0, -1.5)));
    let normals = vec![Vec3::Z; points.len()];
    // Missing rays: 6 level ones ahead (crossing), 2 behind the camera, 1 so steep that it meets the plane
    // above the ceiling (z = 4 > 1).
    let mut missing_rays = vec![Vec3::new(0.0, 1.0, 0.1); 6];
    missing_rays.extend([Vec3::new(0.0, -1.0, 0.0), Vec3::new(0.3, -1.0, 0.0), Vec3::new(0.0, 1.0, 1.0)]);
    let gradients = vec![Vec2::ZERO; points.len()];
    let scene = scene_of(points, normals, gradients, 1.0, missing_rays);
    let crossing = 10.0 + 5.0 + 6.0;
    assert_eq!(front_plane_evidence(&scene, Vec2::Y, 4.0), [6.0 / crossing, 10.0 / crossing]);
    // At 4.6 m the wall's points are 0.6 m short of the plane: not near.
    assert_eq!(front_plane_evidence(&scene, Vec2::Y, 4.6), [6.0 / crossing, 0.0]);
    // Looking backwards only the two rays behind the camera cross; both missing.
    assert_eq!(front_plane_evidence(&scene, -Vec2::Y, 4.0), [1.0, 0.0]);
    // No plane in front (no points there): no evidence.
    assert_eq!(front_plane_evidence(&scene, Vec2::Y, 0.0), [0.0, 0.0]);
}

#[test]
fn orientation_difference_is_taken_modulo_ninety_degrees() {
    let d = |a: f32, b: f32| yaw_difference_mod_90(a.to_radians(), b.to_radians()).to_degrees();
    assert!((d(10.0, 0.0) - 10.0).abs() < 1e-4);
    assert!((d(100.0, 0.0) - 10.0).abs() < 1e-4);
    assert!((d(-40.0, 40.0) - 10.0).abs() < 1e-4);
    assert!((d(44.0, -44.0) - (-2.0)).abs() < 1e-4);
}

#[test]
fn ply_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.ply");
    let points = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(-0.5, 4.25, -1.5)];
    let colours = [[10u8, 20, 30], [200, 100, 0]];
    let room = LineSet::from_prism(&rect(0.0, 4.0, 0.0, 3.0, -1.5, 1.0).corners, -1.5, 1.0, [255, 215, 0]);
    write_ply(&path, "test", &points, &colours, &[room]).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let (header, body) = text.split_once("end_header\n").unwrap();
    assert!(header.starts_with("ply\nformat ascii 1.0\n"));
    assert!(header.contains("element vertex 10\n") && header.contains("element edge 12\n"), "{header}");
    let rows: Vec<Vec<f64>> =
        body.lines().map(|l| l.split_whitespace().map(|x| x.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 10 + 12);
    assert_eq!(rows[1], vec![-0.5, 4.25, -1.5, 200.0, 100.0, 0.0]);
    // The room's vertex 2 (after the 2 points) is the floor corner (4, 3, −1.5).
    assert_eq!(rows[2 + 2][..3], [4.0, 3.0, -1.5]);
    // Every edge joins two room vertices (indices 2..10), 4 m, 3 m or 2.5 m apart.
    for e in &rows[10..] {
        let (i, j) = (e[0] as usize, e[1] as usize);
        assert!((2..10).contains(&i) && (2..10).contains(&j), "{e:?}");
        let (p, q) = (&rows[i], &rows[j]);
        let length = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        assert!([4.0, 3.0, 2.5].iter().any(|l| (length - l).abs() < 1e-6), "edge {e:?} length {length}");
    }
}

/// `missing_rays` lists, in row-major order, exactly the pixels of the stride grid without depth, each as
/// the upright point that the same pixel would have at 1 m depth (filled in and back-projected by
/// `Frame::point_cloud`, the reference), bit for bit.
#[test]
fn missing_rays_are_the_holes_back_projected_at_one_metre() {
    use cog_gpu::frame::Frame;
    let (w, h) = (9u32, 7u32);
    let mut frame = Frame {
        name: "holes".into(),
        rgb: image::RgbImage::from_pixel(w, h, image::Rgb([90, 120, 150])),
        depth_mm: vec![2000; (w * h) as usize],
        k: [[7.5, 0.0, 4.7], [0.0, 8.0, 3.2], [0.0, 0.0, 1.0]],
        // A camera pitched and rolled a little, so that Rtilt is no permutation.
        extrinsics: [[0.99, 0.1, 0.0], [-0.1, 0.99, 0.05], [0.0, -0.05, 0.998]],
        scene: None,
        objects: Vec::new(),
        layout: None,
    };
    let stride = 2;
    // Holes on the grid (even columns and rows) and off it (which must not be listed).
    let holes_on_grid = [(0u32, 0u32), (4, 2), (8, 6), (2, 4)];
    let holes_off_grid = [(1u32, 0u32), (3, 3), (8, 5)];
    for &(c, r) in holes_on_grid.iter().chain(&holes_off_grid) {
        frame.depth_mm[(r * w + c) as usize] = 0;
    }
    let rays = missing_rays(&frame, stride);
    let mut expected_pixels: Vec<(u32, u32)> = holes_on_grid.to_vec();
    expected_pixels.sort_by_key(|&(c, r)| (r, c));
    assert_eq!(rays.len(), expected_pixels.len());
    // Reference: only the holes, filled at exactly 1 m, through the point cloud.
    let mut filled = frame.clone();
    filled.depth_mm = vec![0; (w * h) as usize];
    for &(c, r) in &expected_pixels {
        filled.depth_mm[(r * w + c) as usize] = 1000;
    }
    let cloud = filled.point_cloud();
    let cloud_pixels: Vec<(u32, u32)> = cloud.pixels.iter().map(|p| (p[0], p[1])).collect();
    assert_eq!(cloud_pixels, expected_pixels);
    for (ray, point) in rays.iter().zip(&cloud.points) {
        assert_eq!(ray.to_array().map(f32::to_bits), point.to_array().map(f32::to_bits), "{ray} vs {point}");
    }
    // By hand, independent of the back-projection code: with identity extrinsics Rtilt is the identity,
    // and pixel (col 4, row 2) looks along ((4 + 1 − 4.7)/7.5, 1, −(2 + 1 − 3.2)/8) = (0.04, 1, 0.025).
    frame.extrinsics = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let upright = missing_rays(&frame, stride)[1];
    assert!((upright - Vec3::new(0.04, 1.0, 0.025)).abs().max_element() < 1e-7, "{upright}");
}
