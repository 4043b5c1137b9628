//! Small objects searched on support surfaces (paper §4, `features::hypotheses::surface_window`): a
//! constructed pillow on a table top is found by the surface window and by no box of the floor window;
//! every hypothesis stands on the surface inside its footprint; the table's own points do not keep a
//! box; the surfaces detection searches are those of confident detections of the surface categories;
//! a training example of a surface model answers on its surfaces only, its target on the pillow.

use cog_gpu::category::SurfaceCategories;
use cog_gpu::detect::detected_surfaces;
use cog_gpu::eval::Detection;
use cog_gpu::features::hypotheses::{SURFACE_CLEARANCE_M, SURFACE_MARGIN_M};
use cog_gpu::features::preprocess::Preprocessed;
use cog_gpu::features::LatticePhase;
use cog_gpu::features::{
    sliding_window, surface_window, FeatureLayout, FeatureScene, Groups, SizeQuantiles, Support, SupportSurface,
    WindowOptions, YawAnchor,
};
use cog_gpu::geometry::{iou_3d, polygon_contains, Camera, Cuboid};
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};
use glam::{Mat3, Vec2, Vec3};

const FLOOR: f32 = -1.2;
/// The table top, 0.7 m above the floor.
const TOP: f32 = FLOOR + 0.7;

/// A table (1.2 × 0.8 m, turned by 22.5° — one of the camera anchor's 16 yaws — top 0.7 m above the floor) 3 m in front of the camera, the floor
/// around it, and a pillow (0.4 × 0.3 × 0.15 m) lying on the table's right half: points on a 2 cm grid.
fn scene_with_pillow() -> (FeatureScene, Cuboid, Cuboid) {
    let table = Cuboid::new(Vec3::new(0.0, 3.0, FLOOR + 0.35), Vec3::new(1.2, 0.8, 0.7), 22.5f32.to_radians());
    let pillow_local = Vec3::new(0.3, 0.0, 0.0);
    let pillow_centre = table.from_local(pillow_local).truncate().extend(TOP + 0.075);
    let pillow = Cuboid::new(pillow_centre, Vec3::new(0.4, 0.3, 0.15), table.yaw);
    let mut points = Vec::new();
    let mut normals = Vec::new();
    for a in 0..60 {
        for b in 0..40 {
            let local = Vec3::new(-0.59 + 0.02 * a as f32, -0.39 + 0.02 * b as f32, 0.35);
            let p = table.from_local(local);
            if pillow.contains(p + Vec3::Z * 0.01) {
                continue; // under the pillow: hidden
            }
            points.push(p);
            normals.push(Vec3::Z);
        }
    }
    // The pillow's top and its four sides.
    for a in 0..20 {
        for b in 0..15 {
            points.push(pillow.from_local(Vec3::new(-0.19 + 0.02 * a as f32, -0.14 + 0.02 * b as f32, 0.075)));
            normals.push(Vec3::Z);
        }
    }
    for a in 0..20 {
        for c in 0..7 {
            let (s, u) = (-0.19 + 0.02 * a as f32, -0.06 + 0.02 * c as f32);
            for side in [-0.15f32, 0.15] {
                points.push(pillow.from_local(Vec3::new(s, side, u)));
                normals.push(Vec3::Y * side.signum());
            }
        }
    }
    // The floor: a 4 × 3 m patch around the table, outside its footprint.
    for a in 0..100 {
        for b in 0..75 {
            let p = Vec3::new(-2.0 + 0.04 * a as f32, 1.5 + 0.04 * b as f32, FLOOR);
            if !table.contains(p + Vec3::Z * 0.01) {
                points.push(p);
                normals.push(Vec3::Z);
            }
        }
    }
    let gradients = vec![Vec2::ZERO; points.len()];
    let camera = Camera::new([500.0, 500.0, 320.5, 240.5], Mat3::IDENTITY);
    let pre = Preprocessed { camera, image_size: [640, 480], points, normals, gradients, floor: FLOOR };
    let yaws: Vec<f32> = (0..4).map(|k| table.yaw + k as f32 * std::f32::consts::FRAC_PI_2).collect();
    (FeatureScene::new(pre, &yaws, 0.1), table, pillow)
}

fn pillow_sizes(pillow: &Cuboid) -> Vec<Vec3> {
    SizeQuantiles::from_cuboids(&[*pillow]).unwrap().sizes()[..1].to_vec()
}

/// Training settings of a pillow model (3x3x3, 0.1 m, the pillow's size) standing on `support`.
fn pillow_training(pillow: &Cuboid, support: Support) -> cog_gpu::learn::detector::TrainingSettings {
    use cog_gpu::features::fast::FastOptions;
    use cog_gpu::learn::detector::{FeatureEngine, PositiveTarget, TrainingSettings};
    TrainingSettings {
        layout: FeatureLayout::new([3, 3, 3], true, Groups::ALL).unwrap(),
        sizes: pillow_sizes(pillow),
        step: 0.1,
        min_points: 20,
        engine: FeatureEngine::Fast(FastOptions::default()),
        target: PositiveTarget::BestWindow,
        yaw_anchor: YawAnchor::Camera,
        lattice: LatticePhase::Camera,
        support,
        surfaces: false,
    }
}

#[test]
fn a_pillow_on_a_table_is_found_on_the_surface_and_by_no_floor_box() {
    let (scene, table, pillow) = scene_with_pillow();
    let options = WindowOptions { sizes: pillow_sizes(&pillow), min_points: 20 };
    let surface = SupportSurface { object: table, z: TOP };
    let set = surface_window(&scene, &options, &[surface]);
    assert!(!set.hypotheses.is_empty());
    let best = set.hypotheses.iter().map(|h| iou_3d(&h.cuboid(&scene), &pillow)).fold(0.0f32, f32::max);
    assert!(best >= 0.5, "best IoU with the pillow {best}");
    // The floor window with the same sizes (every box kept, however empty) puts every box on the floor:
    // none reaches the pillow.
    let floor = sliding_window(&scene, &WindowOptions { min_points: 0, ..options.clone() });
    assert!(!floor.hypotheses.is_empty());
    assert!(floor.hypotheses.iter().all(|h| iou_3d(&h.cuboid(&scene), &pillow) == 0.0));
    // No surface, no hypothesis.
    let none = surface_window(&scene, &options, &[]);
    assert_eq!((none.generated, none.hypotheses.len()), (0, 0));
}

#[test]
fn every_surface_hypothesis_stands_on_the_surface_inside_the_grown_footprint() {
    let (scene, table, pillow) = scene_with_pillow();
    let options = WindowOptions { sizes: pillow_sizes(&pillow), min_points: 20 };
    let surface = SupportSurface { object: table, z: TOP };
    let set = surface_window(&scene, &options, &[surface]);
    // The footprint grown by the margin, from the table's corners pushed out along its own axes.
    let (c, s) = (table.yaw.cos(), table.yaw.sin());
    let (hw, hd) = (0.6 + SURFACE_MARGIN_M, 0.4 + SURFACE_MARGIN_M);
    let grown: Vec<Vec2> = [(-hw, -hd), (hw, -hd), (hw, hd), (-hw, hd)]
        .iter()
        .map(|&(u, v)| Vec2::new(u * c - v * s, u * s + v * c) + table.centre.truncate())
        .collect();
    let mut generated = 0;
    for (k, grid) in scene.yaws.iter().enumerate() {
        for row in 0..grid.cells[1] {
            for col in 0..grid.cells[0] {
                let centre = Vec2::new(
                    grid.origin[0] + (col as f32 + 0.5) * grid.step,
                    grid.origin[1] + (row as f32 + 0.5) * grid.step,
                );
                let upright = grid.to_upright(centre.extend(0.0)).truncate();
                if !grid.row_span(row, (col, col)).is_empty() && polygon_contains(&grown, upright) {
                    generated += options.sizes.len();
                }
            }
        }
        assert!(set.hypotheses.iter().filter(|h| h.yaw_index as usize == k).count() <= generated);
    }
    assert_eq!(set.generated, generated, "one hypothesis per size at every occupied cell of the footprint");
    for h in &set.hypotheses {
        assert_eq!(h.bottom, TOP);
        let cuboid = h.cuboid(&scene);
        assert!(polygon_contains(&grown, cuboid.centre.truncate()), "{cuboid:?} off the surface");
        // The skipping count is of points above the surface's own: each kept box holds pillow points, up
        // to the count's ground cells (a cell whose centre is inside the box counts whole: the box grown
        // by one cell on each side holds every point counted).
        let grown_box = Cuboid::new(cuboid.centre, cuboid.size + Vec3::new(0.2, 0.2, 0.0), cuboid.yaw);
        let brute = scene.pre.points.iter().filter(|p| grown_box.contains(**p) && p.z > TOP + 0.01).count();
        assert!(brute > 0 && h.points_inside >= options.min_points, "{h:?}: {brute} points above the top");
    }
    // Boxes over the bare left half of the table (centres within 0.1 m of a point 0.45 m from the pillow,
    // so at least 0.05 m away from it) hold only the table's points: none is kept, though such boxes
    // were generated (the table's points are at most SURFACE_CLEARANCE_M above the surface).
    const { assert!(SURFACE_CLEARANCE_M > 0.0) };
    let left = table.from_local(Vec3::new(-0.35, 0.0, 0.0)).truncate();
    assert!(set.hypotheses.iter().all(|h| h.cuboid(&scene).centre.truncate().distance(left) > 0.1));
    let everything = surface_window(&scene, &WindowOptions { min_points: 0, ..options.clone() }, &[surface]);
    assert!(everything.hypotheses.iter().any(|h| h.cuboid(&scene).centre.truncate().distance(left) <= 0.1));
}

#[test]
fn surfaces_come_from_confident_detections_of_surface_categories() {
    let layout = FeatureLayout::new([3, 3, 3], false, Groups::GEOM).unwrap();
    let sizes = SizeQuantiles {
        widths: vec![0.5, 0.6, 0.7, 0.8, 0.9],
        depths: vec![0.5, 0.6, 0.7],
        heights: vec![0.7, 0.8, 0.9],
    };
    let model = |category: &str| {
        Model::new(
            category,
            layout,
            sizes.clone(),
            WindowSettings {
                step: 0.2,
                min_points: 50,
                yaw_anchor: YawAnchor::Walls,
                support: Support::Floor,
                lattice: LatticePhase::Camera,
                supporters: SurfaceCategories::ALL,
            },
            FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
            vec![0.0; layout.dim()],
            serde_json::json!({}),
        )
        .unwrap()
    };
    let models = vec![model("table"), model("chair"), model("bed")];
    let table = Cuboid::new(Vec3::new(0.0, 3.0, -0.85), Vec3::new(1.0, 0.6, 0.7), 0.0);
    let with_surface = |category: &str, score: f32, z: Option<f32>| {
        let mut d = Detection::new(category, &table, score);
        d.surface_z = z;
        d
    };
    let detections = vec![
        with_surface("table", 0.8, Some(-0.5)),  // kept
        with_surface("table", 0.05, Some(-0.5)), // below the minimum score
        with_surface("chair", 0.9, Some(-0.7)),  // not a surface category
        with_surface("bed", 0.9, None),          // no surface measured
        with_surface("sofa", 0.9, Some(-0.8)),   // no model: not searched
    ];
    let surfaces = detected_surfaces(&detections, &models, 0.1, SurfaceCategories::ALL);
    assert_eq!(surfaces.len(), 1);
    assert_eq!(surfaces[0].z, -0.5);
    assert_eq!(surfaces[0].object, detections[0].cuboid());
    assert!(detected_surfaces(&detections, &models, 0.9, SurfaceCategories::ALL).is_empty());
    // A model's supporters choose among them: the table's surface only for a set that holds tables.
    let beds_and_counters = SurfaceCategories::NONE.with("bed").and_then(|s| s.with("counter")).unwrap();
    assert!(detected_surfaces(&detections, &models, 0.1, beds_and_counters).is_empty());
    let tables = SurfaceCategories::NONE.with("table").unwrap();
    assert_eq!(detected_surfaces(&detections, &models, 0.1, tables), surfaces);
}

/// The supporters' set: membership, names in `SURFACE_CATEGORIES` order, the list a model file holds
/// (absent = all), and a name that carries no surface refused with a message naming it.
#[test]
fn supporter_sets_hold_surface_categories_only() {
    use cog_gpu::category::SURFACE_CATEGORIES;
    let set = SurfaceCategories::NONE.with("counter").and_then(|s| s.with("bed")).unwrap();
    assert_eq!(set.names(), vec!["bed", "counter"]);
    assert!(set.contains("counter") && set.contains("bed") && !set.contains("table") && !set.contains("chair"));
    assert!(SurfaceCategories::NONE.with("chair").is_none());
    assert_eq!(SurfaceCategories::ALL.names(), SURFACE_CATEGORIES.to_vec());
    assert!(SurfaceCategories::ALL.is_all() && !set.is_all() && SurfaceCategories::default().is_all());
    assert_eq!(serde_json::to_string(&set).unwrap(), r#"["bed","counter"]"#);
    assert_eq!(serde_json::from_str::<SurfaceCategories>(r#"["counter","bed"]"#).unwrap(), set);
    let error = serde_json::from_str::<SurfaceCategories>(r#"["counter","chair"]"#).unwrap_err().to_string();
    assert!(error.contains("'chair' is not a category with a support surface"), "{error}");
}

#[test]
fn a_surface_models_training_example_answers_on_its_surfaces() {
    use cog_gpu::learn::detector::{stands_on_a_surface, TrainingExample, SURFACE_HEIGHT_TOLERANCE_M};
    let (scene, table, pillow) = scene_with_pillow();
    let surface = SupportSurface { object: table, z: TOP };
    assert!(stands_on_a_surface(&pillow, &[surface]));
    // On the floor, or hovering above the top by more than the tolerance: on no surface.
    let lowered = Cuboid::new(pillow.centre - Vec3::Z * 0.7, pillow.size, pillow.yaw);
    let raised = Cuboid::new(pillow.centre + Vec3::Z * (SURFACE_HEIGHT_TOLERANCE_M + 0.01), pillow.size, pillow.yaw);
    assert!(!stands_on_a_surface(&lowered, &[surface]) && !stands_on_a_surface(&raised, &[surface]));
    let settings = pillow_training(&pillow, Support::Surfaces);
    let example = TrainingExample::new("pillow".into(), &scene.pre, Some(pillow), &[]).on_surfaces(vec![surface]);
    let window = example.window(&settings);
    assert!(!window.hypotheses.hypotheses.is_empty());
    assert!(window.hypotheses.hypotheses.iter().all(|h| h.bottom == TOP));
    let target = window.target.expect("a surface box near the pillow");
    assert_eq!(window.losses[target], 0.0);
    let best = window.hypotheses.hypotheses[target].cuboid(&window.scene);
    assert!(iou_3d(&best, &pillow) >= 0.5, "target IoU {}", iou_3d(&best, &pillow));
    // Without surfaces the example has no box to answer with (only "no object").
    let bare = TrainingExample::new("pillow".into(), &scene.pre, Some(pillow), &[]);
    assert!(bare.window(&settings).hypotheses.hypotheses.is_empty());
}

/// The free window (`Support::Free`, paper §4's comparison "with a free window"): bottoms at every
/// step from the floor to `FREE_MAX_BOTTOM_M`, so it finds the pillow on the table without being told of
/// the table; it enumerates every occupied cell at every bottom, and keeps a box only for points above
/// its bottom's clearance.
#[test]
fn the_free_window_finds_the_pillow_at_its_height_without_a_surface() {
    use cog_gpu::features::free_window;
    use cog_gpu::features::hypotheses::{free_bottoms, FREE_MAX_BOTTOM_M};
    // Bottoms by hand: 1.5 m at 0.1 m is 16 layers, at 0.2 m 8 (0 … 1.4), at 0.5 m 4.
    assert_eq!(FREE_MAX_BOTTOM_M, 1.5);
    for (step, count) in [(0.1f32, 16usize), (0.2, 8), (0.5, 4)] {
        let bottoms = free_bottoms(FLOOR, step);
        assert_eq!(bottoms.len(), count, "step {step}");
        for (k, b) in bottoms.iter().enumerate() {
            assert!((b - (FLOOR + k as f32 * step)).abs() < 1e-5);
        }
    }
    let (scene, table, pillow) = scene_with_pillow();
    let options = WindowOptions { sizes: pillow_sizes(&pillow), min_points: 20 };
    let set = free_window(&scene, &options);
    let best = set.hypotheses.iter().map(|h| iou_3d(&h.cuboid(&scene), &pillow)).fold(0.0f32, f32::max);
    assert!(best >= 0.5, "best IoU with the pillow {best}");
    // Generated: every occupied cell of every yaw, at each of the 16 bottoms, every size.
    let occupied: usize = scene
        .yaws
        .iter()
        .map(|grid| {
            (0..grid.cells[1])
                .flat_map(|row| (0..grid.cells[0]).map(move |col| (row, col)))
                .filter(|&(row, col)| !grid.row_span(row, (col, col)).is_empty())
                .count()
        })
        .sum();
    assert_eq!(set.generated, occupied * 16 * options.sizes.len());
    for h in &set.hypotheses {
        let k = ((h.bottom - FLOOR) / 0.1).round();
        assert!((0.0..=15.0).contains(&k) && (h.bottom - (FLOOR + k * 0.1)).abs() < 1e-5, "{h:?}");
        // Every kept box holds points above its bottom's clearance (counted by ground cells: the box
        // grown by a cell on each side holds all of them).
        let cuboid = h.cuboid(&scene);
        let grown_box = Cuboid::new(cuboid.centre, cuboid.size + Vec3::new(0.2, 0.2, 0.0), cuboid.yaw);
        let above = |p: &&Vec3| p.z > h.bottom + SURFACE_CLEARANCE_M - 0.03;
        let brute = scene.pre.points.iter().filter(|p| grown_box.contains(**p)).filter(above).count();
        assert!(brute as u32 >= options.min_points, "{h:?}: {brute} points above its bottom");
    }
    // The floor and the bare table top keep no box: nothing stands on them but the pillow. A box whose
    // bottom is on the table top and that does not reach the pillow (centre 0.45 m from it) holds only
    // the top's own points.
    let left = table.from_local(Vec3::new(-0.35, 0.0, 0.0)).truncate();
    let on_top = |h: &&cog_gpu::features::Hypothesis| (h.bottom - TOP).abs() < 0.01;
    assert!(set.hypotheses.iter().filter(on_top).all(|h| h.cuboid(&scene).centre.truncate().distance(left) > 0.1));
}

/// A free-window model's training example needs no surface: its window reaches the pillow on the table
/// by itself, and its target is the pillow.
#[test]
fn a_free_models_training_example_answers_at_the_pillows_height() {
    use cog_gpu::learn::detector::TrainingExample;
    let (scene, _table, pillow) = scene_with_pillow();
    let settings = pillow_training(&pillow, Support::Free);
    let example = TrainingExample::new("pillow".into(), &scene.pre, Some(pillow), &[]);
    let window = example.window(&settings);
    let target = window.target.expect("a free-window box near the pillow");
    let best = window.hypotheses.hypotheses[target].cuboid(&window.scene);
    assert!(iou_3d(&best, &pillow) >= 0.5, "target IoU {}", iou_3d(&best, &pillow));
    assert!((best.bottom() - TOP).abs() < 0.06, "target bottom {} against the top {TOP}", best.bottom());
}

/// The floor-and-surfaces window (`Support::FloorAndSurfaces`, for sinks: pedestals on the floor, basins
/// on counters) is exactly the floor window's hypotheses and the surface window's, each yaw's together in
/// yaw order, with the two counts of generated boxes summed; it finds the pillow on the table as the
/// surface window does, and keeps every floor box. A surface at the floor's own height repeats floor
/// boxes: they are scored once (the floor window's).
#[test]
fn the_floor_and_surface_window_is_the_union_of_the_two_without_repeats() {
    use cog_gpu::features::hypotheses::floor_and_surface_window;
    use cog_gpu::features::Hypothesis;
    let (scene, table, pillow) = scene_with_pillow();
    // min_points 0 keeps every floor box, so the floor window is not empty with the pillow's sizes.
    let options = WindowOptions { sizes: pillow_sizes(&pillow), min_points: 0 };
    let surface = SupportSurface { object: table, z: TOP };
    let floor = sliding_window(&scene, &options);
    let on_top = surface_window(&scene, &options, &[surface]);
    let both = floor_and_surface_window(&scene, &options, &[surface]);
    assert!(!floor.hypotheses.is_empty() && !on_top.hypotheses.is_empty());
    assert_eq!(both.generated, floor.generated + on_top.generated);
    // Per yaw: the floor's boxes, then the surface's, each in its own order.
    let of_yaw = |set: &[Hypothesis], k: usize| -> Vec<Hypothesis> {
        set.iter().filter(|h| h.yaw_index as usize == k).copied().collect()
    };
    for k in 0..scene.yaws.len() {
        let mut expected = of_yaw(&floor.hypotheses, k);
        expected.extend(of_yaw(&on_top.hypotheses, k));
        assert_eq!(of_yaw(&both.hypotheses, k), expected, "yaw {k}");
    }
    assert!(both.hypotheses.windows(2).all(|w| w[0].yaw_index <= w[1].yaw_index), "not in yaw order");
    let best = both.hypotheses.iter().map(|h| iou_3d(&h.cuboid(&scene), &pillow)).fold(0.0f32, f32::max);
    assert!(best >= 0.5, "best IoU with the pillow {best}");
    // A "surface" on the floor itself (a detection's surface at the floor's height) gives boxes the floor
    // window has too: the union holds each once.
    let low = SupportSurface { object: table, z: FLOOR };
    let repeats = surface_window(&scene, &options, &[low]);
    let union = floor_and_surface_window(&scene, &options, &[low]);
    let same = |a: &Hypothesis, b: &Hypothesis| {
        (a.yaw_index, a.size_index, a.centre, a.bottom) == (b.yaw_index, b.size_index, b.centre, b.bottom)
    };
    let repeated = repeats.hypotheses.iter().filter(|r| floor.hypotheses.iter().any(|f| same(f, r))).count();
    assert!(repeated > 0, "the floor-height surface repeats no floor box: the case is not tested");
    assert_eq!(union.hypotheses.len(), floor.hypotheses.len() + repeats.hypotheses.len() - repeated);
    for (i, a) in union.hypotheses.iter().enumerate() {
        assert!(!union.hypotheses[i + 1..].iter().any(|b| same(a, b)), "{a:?} twice");
    }
    // That surface is the floor: the floor window alone searches it.
    assert_eq!(union.hypotheses, floor.hypotheses);
}

/// A floor-and-surfaces model's training example answers on its surfaces (the pillow on the table is its
/// target) and on the floor; without surfaces it still has the floor's boxes (a surface model's has none).
#[test]
fn a_floor_and_surfaces_training_example_answers_on_the_surface_and_keeps_the_floor() {
    use cog_gpu::learn::detector::TrainingExample;
    let (scene, table, pillow) = scene_with_pillow();
    assert!(Support::FloorAndSurfaces.uses_surfaces() && Support::Surfaces.uses_surfaces());
    assert!(!Support::Floor.uses_surfaces() && !Support::Free.uses_surfaces());
    assert_eq!(Support::FloorAndSurfaces.name(), "floor+surfaces");
    // Every box kept (min_points 0): nothing stands on the constructed floor, whose boxes would else be
    // skipped as empty.
    let settings = cog_gpu::learn::detector::TrainingSettings {
        min_points: 0,
        ..pillow_training(&pillow, Support::FloorAndSurfaces)
    };
    let surface = SupportSurface { object: table, z: TOP };
    let example = TrainingExample::new("pillow".into(), &scene.pre, Some(pillow), &[]).on_surfaces(vec![surface]);
    let window = example.window(&settings);
    let target = window.target.expect("a surface box near the pillow");
    let best = window.hypotheses.hypotheses[target].cuboid(&window.scene);
    assert!(iou_3d(&best, &pillow) >= 0.5, "target IoU {}", iou_3d(&best, &pillow));
    let bottoms = |w: &cog_gpu::learn::detector::ExampleWindow, z: f32| {
        w.hypotheses.hypotheses.iter().filter(|h| (h.bottom - z).abs() < 1e-6).count()
    };
    assert!(bottoms(&window, TOP) > 0 && bottoms(&window, FLOOR) > 0, "boxes on the top and on the floor");
    let bare = TrainingExample::new("pillow".into(), &scene.pre, Some(pillow), &[]).window(&settings);
    assert!(bottoms(&bare, FLOOR) > 0 && bottoms(&bare, TOP) == 0);
}

/// The resting window (`Support::Resting`): the free window's boxes less those at a raised bottom below
/// the camera with no upward-facing top seen around them. On the pillow scene (camera at z = 0, the floor
/// 1.2 m below) with two pictures hung on walls — one below the camera's height (0.75–1.05 m above the
/// floor), one above it (1.25–1.55 m), vertical points only: it keeps every floor box, every box on the
/// table top and every box at or above the camera's height, still finds the pillow, drops every box that
/// only the low picture holds up, and is a subsequence of the free window.
#[test]
fn the_resting_window_keeps_the_free_boxes_that_stand_on_a_seen_top() {
    use cog_gpu::features::free_window;
    use cog_gpu::features::hypotheses::{resting_window, RESTING_MIN_UP_POINTS, RESTING_REACH_CELLS};
    use cog_gpu::features::Hypothesis;
    let (scene, table, pillow) = scene_with_pillow();
    let mut pre = scene.pre.clone();
    let low = Vec2::new(1.3, 4.2);
    for (x0, z0) in [(low.x - 0.24, FLOOR + 0.76), (-1.54, FLOOR + 1.26)] {
        for a in 0..25 {
            for c in 0..15 {
                pre.points.push(Vec3::new(x0 + 0.02 * a as f32, 4.2, z0 + 0.02 * c as f32));
                pre.normals.push(-Vec3::Y);
                pre.gradients.push(Vec2::ZERO);
            }
        }
    }
    let scene = FeatureScene::new(pre, &scene.yaw_angles(), 0.1);
    let mut sizes = pillow_sizes(&pillow);
    sizes.push(Vec3::new(0.5, 0.1, 0.3)); // a picture's box
    let options = WindowOptions { sizes, min_points: 20 };
    let free = free_window(&scene, &options);
    let rest = resting_window(&scene, &options);
    let key =
        |h: &Hypothesis| (h.yaw_index, h.size_index, h.centre.x.to_bits(), h.centre.y.to_bits(), h.bottom.to_bits());
    // A subsequence of the free window.
    let mut free_keys = free.hypotheses.iter().map(key);
    for h in &rest.hypotheses {
        assert!(free_keys.any(|k| k == key(h)), "{h:?} is not a free-window box (or out of its order)");
    }
    assert!(rest.generated < free.generated && rest.hypotheses.len() < free.hypotheses.len());
    let kept: std::collections::HashSet<_> = rest.hypotheses.iter().map(key).collect();
    // Every floor box, every box whose bottom is the table top and whose centre lies over the table, and
    // every box at or above the camera's height (there are some: the high picture holds them up).
    let mut above_camera = 0;
    for h in &free.hypotheses {
        let centre = h.cuboid(&scene).centre.truncate();
        let on_table = (h.bottom - TOP).abs() < 0.01 && polygon_contains(&table.footprint(), centre);
        above_camera += usize::from(h.bottom >= 0.0);
        if h.bottom == FLOOR || on_table || h.bottom >= 0.0 {
            assert!(kept.contains(&key(h)), "{h:?} dropped");
        }
    }
    assert!(above_camera > 0, "the high picture must hold up free boxes");
    let best = rest.hypotheses.iter().map(|h| iou_3d(&h.cuboid(&scene), &pillow)).fold(0.0f32, f32::max);
    assert!(best >= 0.5, "best IoU with the pillow {best}");
    // The low picture holds up free boxes, and none of the resting window's.
    let at_low_picture = |h: &&Hypothesis| {
        h.bottom > FLOOR + 0.05 && h.bottom < 0.0 && h.cuboid(&scene).centre.truncate().distance(low) < 0.4
    };
    assert!(free.hypotheses.iter().filter(at_low_picture).count() > 0, "the free window must reach the low picture");
    assert_eq!(rest.hypotheses.iter().filter(at_low_picture).count(), 0);
    // Every raised box kept below the camera has its upward-facing points (brute force over a region that
    // holds the window's: 2.5 cells around the centre's cell on each ground axis, its diagonal; a step and
    // a count cell around the bottom).
    let reach = (RESTING_REACH_CELLS as f32 + 1.0) * 0.1 * std::f32::consts::SQRT_2;
    for h in rest.hypotheses.iter().filter(|h| h.bottom != FLOOR && h.bottom < 0.0) {
        let centre = h.cuboid(&scene).centre.truncate();
        let tops = scene
            .pre
            .points
            .iter()
            .zip(&scene.pre.normals)
            .filter(|(p, n)| n.z > 0.92 && (p.z - h.bottom).abs() <= 0.15 && p.truncate().distance(centre) <= reach)
            .count();
        assert!(tops as u32 >= RESTING_MIN_UP_POINTS, "{h:?}: {tops} upward-facing points around it");
    }
}

/// `windows` searches several models of one scene with each yaw's count tables built once for all of
/// them: every request's set equals its window searched alone (same hypotheses in the same order, same
/// generated count), whatever the mix of supports and sizes in the call.
#[test]
fn windows_of_several_models_equal_each_window_alone() {
    use cog_gpu::features::hypotheses::{window, windows, WindowRequest};
    let (scene, table, pillow) = scene_with_pillow();
    let surface = SupportSurface { object: table, z: TOP };
    let on_floor = SupportSurface { object: table, z: FLOOR };
    let small = WindowOptions { sizes: pillow_sizes(&pillow), min_points: 20 };
    let large = WindowOptions { sizes: vec![Vec3::new(1.2, 0.8, 0.7), Vec3::new(0.5, 0.5, 1.0)], min_points: 50 };
    // min_points 0 keeps the floor's pillow-sized boxes (the floor slab holds the only points there).
    let every = WindowOptions { sizes: pillow_sizes(&pillow), min_points: 0 };
    let surfaces = [surface, on_floor];
    let requests = [
        WindowRequest { support: Support::Floor, options: &large, surfaces: &[] },
        WindowRequest { support: Support::Surfaces, options: &small, surfaces: &surfaces },
        WindowRequest { support: Support::Free, options: &small, surfaces: &[] },
        WindowRequest { support: Support::Resting, options: &small, surfaces: &[] },
        WindowRequest { support: Support::FloorAndSurfaces, options: &small, surfaces: &surfaces },
        WindowRequest { support: Support::Floor, options: &every, surfaces: &[] },
        WindowRequest { support: Support::Surfaces, options: &small, surfaces: &[] },
    ];
    let together = windows(&scene, &requests);
    assert_eq!(together.len(), requests.len());
    for (n, (request, set)) in requests.iter().zip(&together).enumerate() {
        let alone = window(request.support, &scene, request.options, request.surfaces);
        assert_eq!(set.hypotheses, alone.hypotheses, "request {n} ({:?})", request.support);
        assert_eq!(set.generated, alone.generated, "request {n} ({:?})", request.support);
    }
    // Not a vacuous comparison: every support but the surface-less one keeps boxes here.
    for (n, set) in together.iter().enumerate().take(6) {
        assert!(!set.hypotheses.is_empty(), "request {n} kept nothing");
    }
    assert!(together[6].hypotheses.is_empty() && together[6].generated == 0);
}
