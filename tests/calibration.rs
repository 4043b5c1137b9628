//! Score calibration: the logistic fit against known parameters, monotonicity, the benchmark's labelling
//! of detections, storage in model files, and how detection and the overlay use calibrated scores.

use cog_gpu::calibration::{fit_logistic, label_detections, Calibration, MIN_SLOPE};
use cog_gpu::detect::{calibrate, overlay_selection, OVERLAY_SAME_CATEGORY_IOU};
use cog_gpu::eval::Detection;
use cog_gpu::features::LatticePhase;
use cog_gpu::features::Support;
use cog_gpu::features::YawAnchor;
use cog_gpu::features::{FeatureLayout, SizeQuantiles};
use cog_gpu::frame::Object;
use cog_gpu::geometry::Cuboid;
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};
use glam::Vec3;

/// Deterministic uniform numbers in [0, 1) (a 64-bit LCG), so the test data is fixed.
fn uniforms(count: usize) -> Vec<f64> {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    (0..count)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

#[test]
fn logistic_fit_recovers_known_parameters() {
    // Labels drawn from p = σ(2·s − 1) on scores spread over [−2, 3].
    let (a, b) = (2.0f64, -1.0f64);
    let u = uniforms(40_000);
    let samples: Vec<(f32, bool)> = u
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let s = -2.0 + 5.0 * (k as f64 / u.len() as f64);
            let p = 1.0 / (1.0 + (-(a * s + b)).exp());
            (s as f32, r < p)
        })
        .collect();
    let (fa, fb) = fit_logistic(&samples).unwrap();
    assert!((fa - a).abs() < 0.1, "a = {fa}");
    assert!((fb - b).abs() < 0.1, "b = {fb}");
}

#[test]
fn logistic_fit_matches_the_closed_form_of_two_score_levels() {
    // Two score levels with 1/4 and 3/4 true positives: the maximum-likelihood logistic curve passes
    // through both frequencies, σ(a·0 + b) = 1/4 and σ(a·1 + b) = 3/4, so b = −ln 3 and a = 2 ln 3 (the
    // weak prior moves them by < 1e-3 with 4 000 samples).
    let mut samples = Vec::new();
    for k in 0..2000 {
        samples.push((0.0f32, k % 4 == 0));
        samples.push((1.0f32, k % 4 != 0));
    }
    let (a, b) = fit_logistic(&samples).unwrap();
    let ln3 = 3f64.ln();
    assert!((b + ln3).abs() < 2e-3, "b = {b}, expected {}", -ln3);
    assert!((a - 2.0 * ln3).abs() < 4e-3, "a = {a}, expected {}", 2.0 * ln3);
}

#[test]
fn calibration_is_monotone_even_on_inverted_data() {
    // Higher scores are *less* often true positives: the unconstrained fit has a < 0; the calibration keeps
    // the smallest positive slope so that it never reorders a category's detections.
    let samples: Vec<(f32, bool)> = (0..1000).map(|k| (k as f32 / 100.0, k % 10 == 0 && k < 500)).collect();
    let (a, b) = fit_logistic(&samples).unwrap();
    assert_eq!(a, MIN_SLOPE);
    let calibration =
        Calibration { a, b, detections: 1000, true_positives: 50, iou: 0.25, data: String::new(), frames: 1 };
    let mut previous = -1.0;
    for k in -50..50 {
        let p = calibration.probability(k as f32 * 0.3);
        assert!(p >= previous, "not monotone at {k}");
        previous = p;
    }
    // With a fixed slope the fitted b makes the mean probability equal the true-positive rate (0.05).
    let mean: f64 = samples.iter().map(|s| calibration.probability(s.0) as f64).sum::<f64>() / samples.len() as f64;
    assert!((mean - 0.05).abs() < 2e-3, "mean probability {mean}");
}

/// Fewer than `MIN_RELIABLE_TRUE_POSITIVES` (20) true positives: flagged, with the counts; 20: not.
#[test]
fn a_calibration_on_few_true_positives_is_flagged() {
    use cog_gpu::calibration::{Calibration, MIN_RELIABLE_TRUE_POSITIVES};
    assert_eq!(MIN_RELIABLE_TRUE_POSITIVES, 20);
    let mut c = Calibration {
        a: 9.4,
        b: 0.87,
        detections: 4400,
        true_positives: 1,
        iou: 0.25,
        data: String::new(),
        frames: 220,
    };
    let why = c.shortage().expect("one true positive");
    assert!(why.contains("1 true positive") && why.contains("4400 detections"), "{why}");
    c.true_positives = 19;
    assert!(c.shortage().is_some());
    c.true_positives = 20;
    assert_eq!(c.shortage(), None);
}

#[test]
fn calibration_needs_both_outcomes() {
    let all_true: Vec<(f32, bool)> = (0..10).map(|k| (k as f32, true)).collect();
    let err = fit_logistic(&all_true).unwrap_err().to_string();
    assert!(err.contains("true and false positives"), "{err}");
    assert!(fit_logistic(&[]).is_err());
}

fn object(category: &str, centre: [f32; 3], size: [f32; 3]) -> Object {
    Object { category: category.into(), label: None, cuboid: Cuboid::new(Vec3::from(centre), Vec3::from(size), 0.0) }
}

fn detection(category: &str, centre: [f32; 3], size: [f32; 3], score: f32) -> Detection {
    Detection::new(category, &Cuboid::new(Vec3::from(centre), Vec3::from(size), 0.0), score)
}

#[test]
fn labels_follow_the_benchmark_matching() {
    // Frame 0: one bed at the origin; frame 1: no bed, one chair.
    let truth = vec![
        vec![object("bed", [0.0, 2.0, 0.5], [2.0, 1.5, 1.0])],
        vec![object("chair", [1.0, 2.0, 0.4], [0.5, 0.5, 0.8])],
    ];
    let detections = vec![
        vec![
            detection("bed", [0.0, 2.0, 0.5], [2.0, 1.5, 1.0], 0.5), // exact: TP
            detection("bed", [0.1, 2.0, 0.5], [2.0, 1.5, 1.0], 0.9), // IoU 0.9: TP, taken first (higher)
            detection("bed", [5.0, 2.0, 0.5], [2.0, 1.5, 1.0], 0.7), // far away: FP
            detection("chair", [0.0, 2.0, 0.5], [2.0, 1.5, 1.0], 2.0), // another category: ignored
        ],
        vec![detection("bed", [1.0, 2.0, 0.4], [0.5, 0.5, 0.8], 0.8)], // frame without a bed: FP
    ];
    let labels = label_detections(&detections, &truth, "bed", 0.25);
    // Score order 0.9, 0.8, 0.7, 0.5: the 0.9 box takes the bed, so the exact box (0.5) is a duplicate.
    assert_eq!(labels, vec![(0.9, true), (0.8, false), (0.7, false), (0.5, false)]);
}

fn tiny_model(category: &str) -> Model {
    let layout = FeatureLayout::new([3, 3, 3], false, cog_gpu::features::Groups::ALL).unwrap();
    let boxes: Vec<Cuboid> =
        (0..5).map(|k| Cuboid::new(Vec3::ZERO, Vec3::new(1.0 + 0.1 * k as f32, 1.0, 1.0), 0.0)).collect();
    Model::new(
        category,
        layout,
        SizeQuantiles::from_cuboids(&boxes).unwrap(),
        WindowSettings {
            step: 0.2,
            min_points: 50,
            yaw_anchor: YawAnchor::Walls,
            support: Support::Floor,
            lattice: LatticePhase::Camera,
            supporters: cog_gpu::category::SurfaceCategories::ALL,
        },
        FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
        vec![0.0; layout.dim()],
        serde_json::json!({}),
    )
    .unwrap()
}

#[test]
fn models_store_and_check_their_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bed.json");
    let mut model = tiny_model("bed");
    model.calibration = Some(Calibration {
        a: 1.5,
        b: -0.5,
        detections: 10,
        true_positives: 3,
        iou: 0.25,
        data: "d".into(),
        frames: 2,
    });
    model.write(&path).unwrap();
    let back = Model::read(&path).unwrap();
    assert_eq!(back.calibration, model.calibration);
    // A decreasing calibration is rejected with the file's name.
    let text = std::fs::read_to_string(&path).unwrap().replace("\"a\":1.5", "\"a\":-1.5");
    std::fs::write(&path, text).unwrap();
    let err = Model::read(&path).unwrap_err().to_string();
    assert!(err.contains("bed.json") && err.contains("monotone"), "{err}");
    // A model without calibration reads as before.
    let plain = tiny_model("chair");
    plain.write(&dir.path().join("chair.json")).unwrap();
    assert_eq!(Model::read(&dir.path().join("chair.json")).unwrap().calibration, None);
}

#[test]
fn detection_reports_calibrated_scores_and_keeps_the_raw_ones() {
    let mut bed = tiny_model("bed");
    bed.calibration = Some(Calibration {
        a: 2.0,
        b: 0.0,
        detections: 1,
        true_positives: 1,
        iou: 0.25,
        data: String::new(),
        frames: 1,
    });
    let chair = tiny_model("chair"); // uncalibrated: raw scores stay
    let mut detections = vec![
        detection("chair", [0.0, 3.0, 0.4], [0.5, 0.5, 0.8], 0.6),
        detection("bed", [2.0, 3.0, 0.5], [2.0, 1.5, 1.0], 0.0),
        detection("bed", [4.0, 3.0, 0.5], [2.0, 1.5, 1.0], 1.0),
    ];
    calibrate(&mut detections, &[bed, chair]);
    let expected_high = 1.0 / (1.0 + (-2.0f32).exp()); // σ(2·1)
    assert_eq!(detections[0].category, "bed");
    assert!((detections[0].score - expected_high).abs() < 1e-6);
    assert_eq!(detections[0].raw_score, Some(1.0));
    assert_eq!(detections[1].category, "chair");
    assert_eq!((detections[1].score, detections[1].raw_score), (0.6, None));
    assert!((detections[2].score - 0.5).abs() < 1e-6 && detections[2].raw_score == Some(0.0));
}

/// The overlay draws one box per object: a better box of another category at IoU ≥ 0.4, or of its own at
/// IoU ≥ the NMS's, hides a box; boxes beside each other (the hand-computed IoUs below) are all drawn.
#[test]
fn overlay_draws_one_category_per_object() {
    let detections = vec![
        detection("bed", [0.0, 2.0, 0.5], [2.0, 1.5, 1.0], 0.9),
        detection("sofa", [0.05, 2.0, 0.5], [2.0, 1.5, 1.0], 0.8), // same furniture, other category: skipped
        // Same category, 0.3 m over: IoU 2.55 / 3.45 = 0.74 ≥ the NMS's 0.15 (a demoted duplicate): skipped.
        detection("bed", [0.3, 2.0, 0.5], [2.0, 1.5, 1.0], 0.75),
        // Same category, 1.8 m over: IoU 0.3 / 5.7 = 0.053 < 0.15 (two beds side by side): kept.
        detection("bed", [1.8, 2.0, 0.5], [2.0, 1.5, 1.0], 0.7),
        detection("nightstand", [1.4, 0.9, 0.3], [0.5, 0.4, 0.6], 0.6), // beside the bed (IoU < 0.4): kept
        detection("chair", [4.0, 2.0, 0.4], [0.5, 0.5, 0.8], 0.5),
    ];
    let chosen = overlay_selection(&detections, 3, 0.0, OVERLAY_SAME_CATEGORY_IOU);
    let names: Vec<(&str, f32)> = chosen.iter().map(|d| (d.category.as_str(), d.score)).collect();
    assert_eq!(names, vec![("bed", 0.9), ("bed", 0.7), ("nightstand", 0.6)]);
    // The hand-computed IoUs, and where they lie against the overlay's same-category limit (the NMS's).
    let iou = |a: usize, b: usize| cog_gpu::geometry::iou_3d(&detections[a].cuboid(), &detections[b].cuboid());
    assert!((iou(0, 2) - 2.55 / 3.45).abs() < 1e-5 && (iou(0, 3) - 0.3 / 5.7).abs() < 1e-5);
    let limit = OVERLAY_SAME_CATEGORY_IOU;
    assert!(limit == cog_gpu::nms::DEFAULT_NMS_IOU && iou(0, 3) < limit && limit <= iou(0, 2));
    // `detect --nms-iou 0.8` draws what its NMS would keep: the duplicate at 0.74 too.
    let loose = overlay_selection(&detections, 3, 0.0, 0.8);
    let names: Vec<(&str, f32)> = loose.iter().map(|d| (d.category.as_str(), d.score)).collect();
    assert_eq!(names, vec![("bed", 0.9), ("bed", 0.75), ("bed", 0.7)]);
}

/// The overlay's probability floor drops calibrated detections below it (wherever they rank) and never an
/// uncalibrated one, whose score is raw; 0 keeps the plain best-`count` rule.
#[test]
fn overlay_floor_applies_to_calibrated_probabilities_only() {
    let calibrated = |category: &str, x: f32, probability: f32| {
        let mut d = detection(category, [x, 2.0, 0.5], [1.0, 1.0, 1.0], probability);
        d.raw_score = Some(probability - 0.5); // any raw score: what marks `score` as a probability
        d
    };
    let uncalibrated = detection("chair", [3.0, 2.0, 0.4], [0.5, 0.5, 0.8], 0.3); // raw 0.3, below the floor
    let detections = vec![
        calibrated("bed", 0.0, 0.9),
        calibrated("table", 6.0, 0.49), // just below 0.5: not drawn
        uncalibrated,
        calibrated("sofa", 9.0, 0.5), // at the floor: drawn
        calibrated("desk", 12.0, 0.1),
    ];
    let names = |chosen: Vec<Detection>| -> Vec<String> { chosen.iter().map(|d| d.category.clone()).collect() };
    assert_eq!(names(overlay_selection(&detections, 8, 0.5, OVERLAY_SAME_CATEGORY_IOU)), ["bed", "sofa", "chair"]);
    assert_eq!(names(overlay_selection(&detections, 2, 0.5, OVERLAY_SAME_CATEGORY_IOU)), ["bed", "sofa"]);
    assert_eq!(
        names(overlay_selection(&detections, 8, 0.0, OVERLAY_SAME_CATEGORY_IOU)),
        ["bed", "sofa", "table", "chair", "desk"]
    );
}

/// The raw score at a probability: the closed form (logit(p) − b) / a, and exactly the boundary of the
/// computed probabilities (the score there reaches p, the next lower f32 does not).
#[test]
fn the_raw_score_at_a_probability_is_the_exact_boundary() {
    let calibration = |a: f64, b: f64| Calibration {
        a,
        b,
        detections: 0,
        true_positives: 0,
        iou: 0.25,
        data: String::new(),
        frames: 0,
    };
    // σ(2·0.5 − 1) = 0.5; σ(2·(ln 3 + 1)/2 − 1) = σ(ln 3) = 0.75.
    let c = calibration(2.0, -1.0);
    assert!((c.raw_score_at(0.5) - 0.5).abs() <= 1e-6);
    assert!((c.raw_score_at(0.75) - ((3.0f32).ln() + 1.0) / 2.0).abs() <= 1e-6);
    // With the cut near 0, where the f32 values are dense and the rounded probability flat over ~10⁹ of
    // them ((1, 0) at 0.5; the shipped chair's slope with b = logit(0.001) at 0.001; a = 10⁻³ near 1), and
    // at the coefficients' bounds.
    let logit = |p: f64| (p / (1.0 - p)).ln();
    let cases = [
        (2.0, -1.0),
        (12.24, -9.39),
        (0.01, 3.0),
        (8.7, -6.4),
        (1.0, 0.0),
        (1.0, 1e-3),
        (15.43, logit(0.001)),
        (1e-3, 0.0),
        (1e-3, 1e6),
        (1e-3, -1e6),
        (1e6, 1e6),
        (1e6, -1e6),
    ];
    for (a, b) in cases {
        let c = calibration(a, b);
        for p in [1e-6f32, 0.001, 0.05, 0.3, 0.5, 0.9, 0.999, 0.9999999] {
            let raw = c.raw_score_at(p);
            if raw == f32::NEG_INFINITY {
                // Every score reaches p (b = 10⁶ puts even −f32::MAX at probability 1).
                assert!(c.probability(-f32::MAX) >= p, "a {a} b {b} p {p}");
                continue;
            }
            if raw == f32::INFINITY {
                assert!(c.probability(f32::MAX) < p, "a {a} b {b} p {p}");
                continue;
            }
            assert!(c.probability(raw) >= p, "a {a} b {b} p {p}: σ at {raw} is {}", c.probability(raw));
            assert!(c.probability(raw.next_down()) < p, "a {a} b {b} p {p}: {raw} is not the smallest");
        }
    }
}

/// `calibrate` checks that every model file can be written before it writes the first: with a directory
/// in the place of the second model's file, the run fails naming it and the first model is not written
/// either (it was: the models before the failure calibrated, the rest not). Eight synthetic frames; per
/// annotated bed and chair one detection on the box (raw 2) and one beside it (raw −1), so both fit.
#[test]
fn calibrate_writes_no_model_when_one_cannot_be_written() {
    use cog_gpu::eval::FrameDetections;
    use cog_gpu::synth::{self, SynthOptions};
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets, models) = (tmp.path().join("data"), tmp.path().join("dets"), tmp.path().join("models"));
    std::fs::create_dir_all(&dets).unwrap();
    std::fs::create_dir_all(&models).unwrap();
    let categories = ["bed", "chair"];
    for index in 0..8 {
        let options = SynthOptions { rooms: vec![synth::room::RoomType::Bedroom], ..SynthOptions::small(160, 120) };
        let synthetic = synth::generate_frame(5, index, &options).unwrap();
        let frame = &synthetic.frame;
        synthetic.write(&data.join(&frame.name), None).unwrap();
        let mut detections = Vec::new();
        for object in frame.objects.iter().filter(|o| categories.contains(&o.category.as_str())) {
            let mut hit = Detection::new(&object.category, &object.cuboid, 2.0);
            hit.raw_score = Some(2.0);
            let beside = Cuboid { centre: object.cuboid.centre + Vec3::new(5.0, 0.0, 0.0), ..object.cuboid };
            let mut miss = Detection::new(&object.category, &beside, -1.0);
            miss.raw_score = Some(-1.0);
            detections.extend([hit, miss]);
        }
        FrameDetections { frame: frame.name.clone(), detections }
            .write(&dets.join(format!("{}.json", frame.name)))
            .unwrap();
    }
    for category in categories {
        std::fs::copy(format!("assets/models/{category}.json"), models.join(format!("{category}.json"))).unwrap();
    }
    let out = tmp.path().join("out");
    std::fs::create_dir_all(out.join("chair.json")).unwrap();
    let run = |out: &std::path::Path| {
        std::process::Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
            .args(["calibrate", "--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap()])
            .args(["--models", models.to_str().unwrap(), "--out", out.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let failed = run(&out);
    let err = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(1), "{err}");
    assert!(err.contains("chair.json") && err.contains("nothing written"), "{err}");
    assert!(!out.join("bed.json").exists(), "the bed model was written before the chair failed");
    // The same run into a writable directory calibrates both.
    let written = tmp.path().join("written");
    let ok = run(&written);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    for category in categories {
        let model = Model::read(&written.join(format!("{category}.json"))).unwrap();
        assert!(model.calibration.is_some(), "{category}");
    }
}
