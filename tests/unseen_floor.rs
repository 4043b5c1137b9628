//! The floor where the camera does not see it (`Preprocessed::unseen_floor`, `detect::merge_floors`,
//! `DetectOptions::unseen_floor`): the floor-plane test against hand-counted cells, the second floor's
//! rule, the merge of two floors' detections against a hand-worked case, and detection on a frame whose
//! floor was cut out of its depth — on the CPU, and on the GPU with its kernels forced
//! (`COG_GPU_FAST_KERNEL=always`, which this file sets for its GPU test) giving the CPU's boxes.

mod common;
use common::run_cog_gpu as run;

use glam::{DMat3, Vec2, Vec3};

use cog_gpu::backend::Backend;
use cog_gpu::detect::{compare_paths, detect_frame, merge_floors, DetectOptions};
use cog_gpu::eval::Detection;
use cog_gpu::features::preprocess::{
    NotFloor, FLOOR_PLANE_BAND_M, FLOOR_PLANE_CELL_M, FLOOR_PLANE_MIN_CELLS, MIN_CAMERA_HEIGHT_M,
    UNSEEN_FLOOR_CAMERA_HEIGHT_M,
};
use cog_gpu::features::{FeatureLayout, Groups, Preprocessed, SizeQuantiles};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::{iou_3d, Camera, Cuboid};
use cog_gpu::model::{FeaturePath, FeatureSettings, Model};

const SAMPLE: &str = "assets/sample/synth-bedroom-s52";
const UP: Vec3 = Vec3::Z;
const SIDEWAYS: Vec3 = Vec3::X;

/// A preprocessed frame of the given points and normals (camera and gradients do not enter the test), its
/// floor set as given.
fn scene(points: Vec<(Vec3, Vec3)>, floor: f32) -> Preprocessed {
    let n = points.len();
    let camera = Camera::new([500.0, 500.0, 320.0, 240.0], glam::Mat3::IDENTITY);
    Preprocessed {
        camera,
        image_size: [640, 480],
        points: points.iter().map(|p| p.0).collect(),
        normals: points.iter().map(|p| p.1).collect(),
        gradients: vec![Vec2::ZERO; n],
        floor,
    }
}

/// Upward-facing points on a grid of `cells` × `cells` cells of the test's size, one at each cell's
/// centre, at height `z`, starting at the origin's cell.
fn plane(cells: usize, z: f32) -> Vec<(Vec3, Vec3)> {
    let c = FLOOR_PLANE_CELL_M;
    (0..cells * cells)
        .map(|k| (Vec3::new(((k % cells) as f32 + 0.5) * c, ((k / cells) as f32 + 0.5) * c, z), UP))
        .collect()
}

#[test]
fn the_floor_plane_counts_the_cells_of_upward_points_in_its_band() {
    let c = FLOOR_PLANE_CELL_M;
    let floor = -1.2;
    let points = vec![
        // Two in the first cell (one cell), one in the next along x, one at negative x (cell −1).
        (Vec3::new(0.25 * c, 0.5 * c, floor), UP),
        (Vec3::new(0.75 * c, 0.25 * c, floor + 0.5 * FLOOR_PLANE_BAND_M), UP),
        (Vec3::new(1.5 * c, 0.5 * c, floor + FLOOR_PLANE_BAND_M), UP),
        (Vec3::new(-0.5 * c, 0.5 * c, floor), UP),
        // Not counted: above the band, facing sideways, tilted beyond the up cone (bin 0 ends at 22.5°).
        (Vec3::new(3.5 * c, 0.5 * c, floor + FLOOR_PLANE_BAND_M + 0.01), UP),
        (Vec3::new(4.5 * c, 0.5 * c, floor), SIDEWAYS),
        (Vec3::new(5.5 * c, 0.5 * c, floor), Vec3::new(0.5, 0.0, 0.8).normalize()),
        // Counted: within 22.5° of up.
        (Vec3::new(6.5 * c, 0.5 * c, floor), Vec3::new(0.3, 0.0, 0.95).normalize()),
    ];
    assert_eq!(scene(points, floor).floor_plane_cells(), 4);
}

/// The rule's three parts: a plane of enough cells, at least [`MIN_CAMERA_HEIGHT_M`] below the camera, is a
/// floor seen; fewer cells, or a plane closer to the camera (a top), is not — then the second floor is the
/// assumed one, unless the lowest points are that low already.
#[test]
fn a_second_floor_only_where_the_lowest_points_are_no_plane_and_above_the_assumed_camera_height() {
    let assumed = -UNSEEN_FLOOR_CAMERA_HEIGHT_M;
    let min = FLOOR_PLANE_MIN_CELLS;
    // A side of a cut object (sideways normals) is the lowest, a top above it: no floor seen.
    let mut cut: Vec<(Vec3, Vec3)> = (0..200).map(|k| (Vec3::new(0.01 * k as f32, 1.0, -0.8), SIDEWAYS)).collect();
    cut.extend(plane(8, -0.5));
    assert_eq!(scene(cut.clone(), -0.8).unseen_floor(), Some(assumed));
    assert_eq!(scene(cut.clone(), -0.8).lowest_points_not_floor(), Some(NotFloor::TooHigh));
    // The same, lower than the assumed floor: no plane, but nothing to add.
    assert_eq!(scene(cut.clone(), assumed - 0.2).lowest_points_not_floor(), Some(NotFloor::NoPlane));
    assert_eq!(scene(cut, assumed - 0.2).unseen_floor(), None);
    // A plane of one cell fewer than the least a seen floor covers, then of exactly that many.
    let side = (min as f64).sqrt().ceil() as usize;
    let seen = -1.1;
    let few: Vec<(Vec3, Vec3)> = plane(side, seen).into_iter().take(min - 1).collect();
    assert_eq!(scene(few.clone(), seen).unseen_floor(), Some(assumed));
    assert_eq!(scene(few, seen).lowest_points_not_floor(), Some(NotFloor::NoPlane));
    let enough: Vec<(Vec3, Vec3)> = plane(side, seen).into_iter().take(min).collect();
    assert_eq!(scene(enough.clone(), seen).unseen_floor(), None);
    assert_eq!(scene(enough, seen).lowest_points_not_floor(), None);
    // A wide plane (100 cells) exactly the least camera height below the camera is a floor; 5 cm higher it
    // is a top (a bed filling the picture's bottom), whatever its size.
    let lowest = -MIN_CAMERA_HEIGHT_M;
    assert_eq!(scene(plane(10, lowest), lowest).unseen_floor(), None);
    let top = lowest + 0.05;
    assert!(scene(plane(10, top), top).floor_plane_cells() >= min);
    assert_eq!(scene(plane(10, top), top).unseen_floor(), Some(assumed));
    assert_eq!(scene(plane(10, top), top).lowest_points_not_floor(), Some(NotFloor::TooHigh));
}

fn chair(centre: [f32; 3], score: f32) -> Detection {
    Detection::new("chair", &Cuboid::new(Vec3::from(centre), Vec3::new(0.5, 0.5, 0.8), 0.0), score)
}

#[test]
fn merging_two_floors_suppresses_across_them_only() {
    // Seen floor: a at x = 0, b at x = 2, and d beside a (a box that its floor's NMS demoted and kept).
    // Lower floor: c on a's place 0.2 m lower (IoU 0.6 with a), e on b's place scoring more than b, f of
    // another category on a's place.
    let a = chair([0.0, 2.0, -0.8], 2.0);
    let b = chair([2.0, 2.0, -0.8], 1.0);
    let d = chair([0.1, 2.0, -0.8], 0.1);
    let c = chair([0.0, 2.0, -1.0], 1.5);
    let e = chair([2.0, 2.0, -1.0], 3.0);
    let f = Detection::new("table", &a.cuboid(), 0.5);
    assert!(iou_3d(&a.cuboid(), &c.cuboid()) > 0.15 && iou_3d(&a.cuboid(), &d.cuboid()) > 0.15);
    let options = DetectOptions::default();
    let merged = merge_floors(vec![a.clone(), b, d.clone()], vec![c, e.clone(), f.clone()], &options);
    // c loses to a, b to e; d stays (its own floor's NMS kept it); f is of another category.
    assert_eq!(merged, vec![e.clone(), a.clone(), f.clone(), d.clone()]);
    // At most max_per_category per category, the best first.
    let two = DetectOptions { max_per_category: 2, ..options };
    let merged = merge_floors(vec![a.clone(), d], vec![e.clone(), f.clone()], &two);
    assert_eq!(merged, vec![e, a, f]);
}

/// A one-voxel model whose score is the box's point density (as in `tests/detect.rs`).
fn density_model() -> Model {
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::GEOM).unwrap();
    let mut weights = vec![0.0; layout.dim()];
    weights[0] = 1.0;
    let mut model = Model::new(
        "nightstand",
        layout,
        SizeQuantiles {
            widths: vec![0.45, 0.5, 0.55, 0.6, 0.65],
            depths: vec![0.4, 0.45, 0.5],
            heights: vec![0.5, 0.6, 0.7],
        },
        common::floor_window(0.3, 100),
        FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
        weights,
        serde_json::Value::Null,
    )
    .unwrap();
    model.threshold = 0.0;
    model
}

/// The sample bedroom with every pixel whose point lies within `cut` metres of its floor made missing:
/// a picture without a floor.
fn without_floor(frame: &Frame, floor: f32, cut: f32) -> Frame {
    let mut cropped = frame.clone();
    let rtilt: DMat3 = frame.rtilt_f64();
    let width = frame.width();
    for (i, depth) in cropped.depth_mm.iter_mut().enumerate() {
        if *depth == 0 {
            continue;
        }
        let (col, row) = (i as u32 % width, i as u32 / width);
        let z = frame.upright_point(&rtilt, col, row, *depth as f64 / 1000.0).z as f32;
        if z < floor + cut {
            *depth = 0;
        }
    }
    cropped
}

#[test]
fn detection_searches_the_second_floor_only_where_the_floor_is_not_seen() {
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let model = density_model();
    let models = std::slice::from_ref(&model);
    // Room for every box of both floors (the denser boxes of the lowest points' floor would fill 20).
    let on = DetectOptions { box_voting: None, max_per_category: 500, ..DetectOptions::default() };
    let off = DetectOptions { unseen_floor: false, ..on };
    // The sample's floor is seen: both settings detect the same.
    let pre = Preprocessed::from_frame(&frame).unwrap();
    assert_eq!(pre.unseen_floor(), None, "{} floor cells", pre.floor_plane_cells());
    let seen_on = detect_frame(&frame, models, Backend::Cpu, &on).unwrap();
    assert_eq!(seen_on, detect_frame(&frame, models, Backend::Cpu, &off).unwrap());
    // Without its lowest 0.2 m the lowest points (the furniture's sides, cut) float above the assumed floor
    // and are no plane. (Cut at 0.4–0.5 m, the bed's top is the lowest: a plane, taken for a floor.)
    let cropped = without_floor(&frame, pre.floor, 0.2);
    let lowest = Preprocessed::from_frame(&cropped).unwrap();
    let assumed = -UNSEEN_FLOOR_CAMERA_HEIGHT_M;
    assert!(lowest.floor > assumed + 0.1, "lowest points at {}", lowest.floor);
    assert_eq!(lowest.unseen_floor(), Some(assumed), "{} floor cells", lowest.floor_plane_cells());
    let one = detect_frame(&cropped, models, Backend::Cpu, &off).unwrap().detections;
    let two = detect_frame(&cropped, models, Backend::Cpu, &on).unwrap().detections;
    let stands_on = |d: &Detection, z: f32| (d.cuboid().bottom() - z).abs() < 1e-4;
    assert!(!one.is_empty() && one.iter().all(|d| stands_on(d, lowest.floor)));
    // Every box of the two stands on one of the floors, some on the second; across the floors none
    // overlaps another beyond the NMS IoU; those on the lowest points are the one floor's, in order.
    assert!(two.iter().all(|d| stands_on(d, lowest.floor) || stands_on(d, assumed)));
    assert!(two.iter().any(|d| stands_on(d, assumed)), "no box on the second floor");
    for (i, x) in two.iter().enumerate() {
        for y in &two[i + 1..] {
            if stands_on(x, assumed) != stands_on(y, assumed) {
                assert!(iou_3d(&x.cuboid(), &y.cuboid()) <= on.nms_iou + 1e-6);
            }
        }
    }
    let upper: Vec<&Detection> = two.iter().filter(|d| stands_on(d, lowest.floor)).collect();
    let mut rest = one.iter();
    for d in upper {
        assert!(rest.any(|o| o == d), "a box of the lowest points' floor the one floor did not detect");
    }
}

/// The second floor's pass on the GPU backend, the fast kernels forced on lavapipe: the same boxes as the
/// CPU's, scores within the paths' tolerance, some of them on the second floor.
#[test]
fn the_gpu_path_searches_the_second_floor_as_the_cpu_does() {
    std::env::set_var("COG_GPU_FAST_KERNEL", "always");
    let Some(ctx) = common::gpu_context() else { return };
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let cropped = without_floor(&frame, pre.floor, 0.2);
    let model = density_model();
    let options = DetectOptions { box_voting: None, max_per_category: 500, ..DetectOptions::default() };
    let cpu = detect_frame(&cropped, std::slice::from_ref(&model), Backend::Cpu, &options).unwrap().detections;
    let gpu = detect_frame(&cropped, std::slice::from_ref(&model), Backend::Gpu(&ctx), &options).unwrap().detections;
    let assumed = -UNSEEN_FLOOR_CAMERA_HEIGHT_M;
    assert!(cpu.iter().any(|d| (d.cuboid().bottom() - assumed).abs() < 1e-4), "no box on the second floor");
    let agreement = compare_paths(&[cpu], &[gpu]);
    assert!(agreement.same, "{agreement:?}");
}

/// `detect --unseen-floor on|off` (default on), `bench --detect --unseen-floor` and `info`: on the sample
/// bedroom without its floor, the default puts boxes on the second floor and `off` none, the two runs carry
/// different fingerprints, `info` names the second floor (and none on the sample as it is), and a value
/// other than on/off is refused naming the flag.
#[test]
fn the_cli_searches_the_second_floor_unless_told_off() {
    let dir = tempfile::tempdir().unwrap();
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let cropped = without_floor(&frame, pre.floor, 0.2);
    let frame_dir = dir.path().join("frames").join(&frame.name);
    cropped.write(&frame_dir).unwrap();
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    density_model().write(&models.join("nightstand.json")).unwrap();
    let detect = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec!["--cpu", "detect", frame_dir.to_str().unwrap(), "--models", models.to_str().unwrap()];
        args.extend(["--out", out.to_str().unwrap(), "--no-overlay", "--box-voting", "off"]);
        args.extend(["--max-per-category", "500"]);
        args.extend(extra);
        let output = run(&args);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let text = std::fs::read_to_string(out.join(format!("{}.json", frame.name))).unwrap();
        serde_json::from_str::<serde_json::Value>(&text).unwrap()
    };
    let on = detect("on", &[]);
    let off = detect("off", &["--unseen-floor", "off"]);
    let assumed = -UNSEEN_FLOOR_CAMERA_HEIGHT_M;
    let on_second = |file: &serde_json::Value| {
        file["detections"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| {
                let (z, h) = (d["centre"][2].as_f64().unwrap(), d["size"][2].as_f64().unwrap());
                (z - 0.5 * h - assumed as f64).abs() < 1e-4
            })
            .count()
    };
    assert!(on_second(&on) > 0 && on_second(&off) == 0, "{} and {}", on_second(&on), on_second(&off));
    assert_ne!(on["run"], off["run"]);
    // `info` says the same: no floor seen on the cut frame, the second floor named; seen on the sample.
    let info = |dir: &str| {
        let output = run(&["info", dir, "--json"]);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        serde_json::from_slice::<serde_json::Value>(&output.stdout).unwrap()
    };
    let cut = info(frame_dir.to_str().unwrap());
    assert!(cut["floor_plane_cells"].as_u64().unwrap() < FLOOR_PLANE_MIN_CELLS as u64);
    assert!((cut["unseen_floor"].as_f64().unwrap() - assumed as f64).abs() < 1e-6);
    let whole = info(SAMPLE);
    assert!(whole["floor_plane_cells"].as_u64().unwrap() >= FLOOR_PLANE_MIN_CELLS as u64);
    assert!(whole["unseen_floor"].is_null());
    // Its floor is the one the window stands on, to the bit (an order statistic, not an interpolation).
    assert_eq!(whole["floor"].as_f64().unwrap() as f32, pre.floor);
    let bad = run(&["--cpu", "detect", frame_dir.to_str().unwrap(), "--unseen-floor", "maybe"]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--unseen-floor"));
    let bench = run(&[
        "--cpu",
        "bench",
        "--detect",
        frame_dir.to_str().unwrap(),
        "--models",
        models.to_str().unwrap(),
        "--unseen-floor",
        "off",
        "--warmup",
        "0",
        "--json",
    ]);
    assert!(bench.status.success(), "{}", String::from_utf8_lossy(&bench.stderr));
    let report: serde_json::Value = serde_json::from_slice(&bench.stdout).unwrap();
    assert_eq!(report["unseen_floor"], serde_json::Value::Bool(false));
}

/// The diagnosis's window recall counts the second floor's boxes as detection searches them: on the
/// sample bedroom without its floor, each nightstand moved to stand on the assumed floor is reached at
/// least as well with the second floor as without, one of them better; on the frame as it is (its floor
/// seen) the two agree.
#[test]
fn the_window_recall_counts_the_second_floor() {
    use cog_gpu::diagnose::frame_window_best_ious;
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let model = density_model();
    let models = std::slice::from_ref(&model);
    let assumed = -UNSEEN_FLOOR_CAMERA_HEIGHT_M;
    let lowered: Vec<cog_gpu::frame::Object> = frame
        .objects
        .iter()
        .filter(|o| o.category == "nightstand")
        .map(|o| {
            let mut o = o.clone();
            o.cuboid.centre.z = assumed + 0.5 * o.cuboid.size.z;
            o
        })
        .collect();
    assert!(!lowered.is_empty());
    let cropped = Preprocessed::from_frame(&without_floor(&frame, pre.floor, 0.2)).unwrap();
    let with = &frame_window_best_ious(&cropped, models, &lowered, true)["nightstand"];
    let without = &frame_window_best_ious(&cropped, models, &lowered, false)["nightstand"];
    assert!(with.iter().zip(without).all(|(a, b)| a >= b), "{with:?} {without:?}");
    assert!(with.iter().zip(without).any(|(a, b)| a > b), "{with:?} {without:?}");
    assert_eq!(
        frame_window_best_ious(&pre, models, &frame.objects, true),
        frame_window_best_ious(&pre, models, &frame.objects, false)
    );
}
