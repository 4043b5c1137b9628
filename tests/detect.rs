//! Detection: scores against an independent computation, NMS and caps, the overlay, and the CLI.

mod common;
use cog_gpu::features::Support;
use common::run_cog_gpu as run;
use std::path::{Path, PathBuf};
use std::process::Command;

use cog_gpu::backend::Backend;
use cog_gpu::detect::{detect_frame, overlay, DetectOptions, REVOTE_DEMOTION};
use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::features::LatticePhase;
use cog_gpu::features::YawAnchor;
use cog_gpu::features::{FeatureLayout, Groups, Preprocessed, SizeQuantiles};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::{iou_3d, projected_hull_area, Camera};
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};

const SAMPLE: &str = "assets/sample/synth-bedroom-s52";

fn bed_sizes() -> SizeQuantiles {
    SizeQuantiles { widths: vec![1.4, 1.5, 1.6, 1.7, 1.8], depths: vec![1.9, 2.0, 2.1], heights: vec![0.45, 0.5, 0.55] }
}

/// A one-voxel model whose score is the box's point density: weight 1 on the density, 0 elsewhere.
fn density_model(path: FeaturePath, step: f32) -> Model {
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::GEOM).unwrap();
    let mut weights = vec![0.0; layout.dim()];
    weights[0] = 1.0;
    let mut model = Model::new(
        "bed",
        layout,
        bed_sizes(),
        WindowSettings {
            step,
            min_points: 500,
            yaw_anchor: YawAnchor::Walls,
            support: Support::Floor,
            lattice: LatticePhase::Camera,
            supporters: cog_gpu::category::SurfaceCategories::ALL,
        },
        FeatureSettings { path, subdivisions: 2, normals: Default::default() },
        weights,
        serde_json::Value::Null,
    )
    .unwrap();
    model.threshold = 0.0;
    model
}

#[test]
fn exact_scores_are_point_densities_and_detections_obey_nms() {
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let model = density_model(FeaturePath::Exact, 0.3);
    // Without box voting: each detection is a scored hypothesis (voting moves boxes off the ones scored).
    let options = DetectOptions { max_per_category: 5, box_voting: None, ..DetectOptions::default() };
    let result = detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &options).unwrap();
    let detections = &result.detections;
    assert!(!detections.is_empty() && detections.len() <= 5, "{} detections", detections.len());
    assert_eq!(result.frame, frame.name);
    // Independent score of each detection: points inside its cuboid over the area of its projected hull.
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let camera = Camera::new(frame.intrinsics(), frame.rtilt());
    for d in detections {
        assert_eq!(d.category, "bed");
        let cuboid = d.cuboid();
        let inside = pre.points.iter().filter(|p| cuboid.contains(**p)).count() as f32;
        let area = projected_hull_area(&camera, &cuboid.corners()).unwrap();
        let expected = inside / area.max(1.0);
        // Points exactly on a face may go either way between fixed-point and float membership.
        assert!((d.score - expected).abs() <= 0.005 * expected + 2.0 / area, "score {} vs {expected}", d.score);
        assert!(d.score >= model.threshold);
    }
    for pair in detections.windows(2) {
        assert!(pair[0].score >= pair[1].score, "sorted by score");
    }
    for (i, a) in detections.iter().enumerate() {
        for b in &detections[i + 1..] {
            assert!(iou_3d(&a.cuboid(), &b.cuboid()) <= options.nms_iou + 1e-6);
        }
    }
    // The overlay: the frame's size, drawn where the best box's corners project.
    let picture = overlay(&frame, &result);
    assert_eq!(picture.dimensions(), frame.rgb.dimensions());
    let changed = picture.pixels().zip(frame.rgb.pixels()).filter(|(a, b)| a != b).count();
    assert!(changed > 100, "{changed} pixels changed");
    let corner =
        detections[0].cuboid().corners().iter().filter_map(|&c| camera.project(c)).find(|p| {
            p.x >= 1.0 && p.y >= 1.0 && p.x < frame.width() as f32 - 1.0 && p.y < frame.height() as f32 - 1.0
        });
    if let Some(p) = corner {
        let (x, y) = (p.x.round() as u32, p.y.round() as u32);
        assert_ne!(picture.get_pixel(x, y), frame.rgb.get_pixel(x, y), "corner ({x}, {y}) not drawn");
    }
}

#[test]
fn a_threshold_above_every_score_leaves_no_detection() {
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let model = density_model(FeaturePath::Fast, 0.3);
    let options = DetectOptions { min_score: Some(1e9), ..DetectOptions::default() };
    assert!(detect_frame(&frame, &[model], Backend::Cpu, &options).unwrap().detections.is_empty());
    let bad = DetectOptions { nms_iou: 1.5, ..DetectOptions::default() };
    assert!(detect_frame(&frame, &[], Backend::Cpu, &bad).is_err());
}

/// `min_probability` keeps exactly the detections whose calibrated score is at least it: the same as
/// detecting down to any raw score and dropping the rest afterwards (NMS and the per-category cap look only
/// down the ranking, so boxes below the cut change nothing above it), a detection whose score equals the
/// cut included.
#[test]
fn a_minimum_probability_keeps_exactly_the_detections_at_or_above_it() {
    use cog_gpu::calibration::Calibration;
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let mut model = density_model(FeaturePath::Fast, 0.3);
    model.calibration = Some(Calibration {
        a: 2.0,
        b: -1.0,
        detections: 0,
        true_positives: 0,
        iou: 0.25,
        data: String::new(),
        frames: 0,
    });
    let everything = DetectOptions { min_score: Some(f32::MIN), ..DetectOptions::default() };
    let all = detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &everything).unwrap().detections;
    assert!(all.len() >= 4, "{} detections", all.len());
    let mut cuts: Vec<f32> = vec![all[all.len() / 2].score, all[1].score, 0.5 * (all[2].score + all[3].score)];
    cuts.retain(|&p| p > 0.0 && p < 1.0);
    assert!(!cuts.is_empty(), "scores {:?}", all.iter().map(|d| d.score).collect::<Vec<_>>());
    for p in cuts {
        let options = DetectOptions { min_probability: Some(p), ..DetectOptions::default() };
        let kept = detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &options).unwrap().detections;
        let expected: Vec<_> = all.iter().filter(|d| d.score >= p).cloned().collect();
        assert!(!expected.is_empty());
        assert_eq!(kept, expected, "cut {p}");
    }
    // Without a calibration the probability means nothing: an error naming the model.
    model.calibration = None;
    let options = DetectOptions { min_probability: Some(0.5), ..DetectOptions::default() };
    let error = detect_frame(&frame, &[model], Backend::Cpu, &options).unwrap_err().to_string();
    assert!(error.contains("'bed' model has no calibration"), "{error}");
    // A probability outside (0, 1), or both cuts at once, is refused.
    for bad in [
        DetectOptions { min_probability: Some(1.0), ..DetectOptions::default() },
        DetectOptions { min_probability: Some(0.0), ..DetectOptions::default() },
        DetectOptions { min_probability: Some(f32::NAN), ..DetectOptions::default() },
        DetectOptions { min_probability: Some(0.5), min_score: Some(0.0), ..DetectOptions::default() },
    ] {
        assert!(bad.validate().is_err(), "{bad:?}");
    }
}

/// The default cut: a calibrated model keeps exactly the detections whose calibrated probability is at
/// least `DEFAULT_MIN_PROBABILITY` (its raw `threshold` ignored), a model without a calibration those whose
/// raw score is at least its `threshold` — both against detecting down to any score and cutting afterwards.
#[test]
fn the_default_cut_is_a_probability_for_a_calibrated_model_and_the_raw_threshold_otherwise() {
    use cog_gpu::calibration::Calibration;
    use cog_gpu::detect::DEFAULT_MIN_PROBABILITY;
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let mut model = density_model(FeaturePath::Fast, 0.3);
    let everything = DetectOptions { min_score: Some(f32::MIN), ..DetectOptions::default() };
    let raw = detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &everything).unwrap().detections;
    assert!(raw.len() >= 4, "{} detections", raw.len());
    assert!(raw[0].score > raw[1].score && raw[1].score > raw[2].score, "{raw:?}");
    // Uncalibrated: reported scores are raw; the cut is the model's threshold, between the best two.
    model.threshold = 0.5 * (raw[0].score + raw[1].score);
    let kept =
        detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &DetectOptions::default()).unwrap().detections;
    assert_eq!(kept, raw[..1].to_vec());
    // Calibrated so that probability 10⁻³ falls between the second and the third raw score: a = 1,
    // b = logit(10⁻³) − (z₂ + z₃)/2. The raw threshold (which would keep one) no longer applies.
    let midpoint = 0.5 * (f64::from(raw[1].score) + f64::from(raw[2].score));
    let p = f64::from(DEFAULT_MIN_PROBABILITY);
    model.calibration = Some(Calibration {
        a: 1.0,
        b: (p / (1.0 - p)).ln() - midpoint,
        detections: 0,
        true_positives: 0,
        iou: 0.25,
        data: String::new(),
        frames: 0,
    });
    let all = detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &everything).unwrap().detections;
    let expected: Vec<_> = all.iter().filter(|d| d.score >= DEFAULT_MIN_PROBABILITY).cloned().collect();
    assert_eq!(expected.len(), 2, "probabilities {:?}", all.iter().map(|d| d.score).collect::<Vec<_>>());
    let kept =
        detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &DetectOptions::default()).unwrap().detections;
    assert_eq!(kept, expected);
    // `detect --help` states the same default.
    let help = String::from_utf8(run(&["detect", "--help"]).stdout).unwrap();
    assert!(help.contains(&format!("Default: {DEFAULT_MIN_PROBABILITY} for every calibrated model")), "{help}");
}

fn binary() -> &'static str {
    env!("CARGO_BIN_EXE_cog-gpu")
}

fn models_dir(dir: &Path) -> PathBuf {
    let models = dir.join("models");
    std::fs::create_dir_all(&models).unwrap();
    density_model(FeaturePath::Fast, 0.2).write(&models.join("bed.json")).unwrap();
    models
}

#[test]
fn the_cli_writes_detections_and_overlays() {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let out = dir.path().join("out");
    let output = run(&[
        "--cpu",
        "detect",
        SAMPLE,
        "--models",
        models.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--max-per-category",
        "3",
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let name = "synth-bedroom-s52";
    let read = FrameDetections::read(&out.join(format!("{name}.json"))).unwrap();
    assert_eq!(read.frame, name);
    assert!(!read.detections.is_empty() && read.detections.len() <= 3);
    let png = image::open(out.join(format!("{name}.png"))).unwrap();
    assert_eq!((png.width(), png.height()), (320, 240));
    // --json prints the same detections.
    let output = run(&[
        "--cpu",
        "detect",
        SAMPLE,
        "--models",
        models.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--max-per-category",
        "3",
        "--no-overlay",
        "--json",
    ]);
    assert!(output.status.success());
    let printed: Vec<FrameDetections> = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(printed, vec![read]);
}

/// `detect` warns, naming the model, when an uncalibrated model's detections are voted (their demoted boxes
/// fall [`cog_gpu::detect::REVOTE_DEMOTION`] raw units, mostly under the cut), and not with `--box-voting off`
/// nor for a calibrated model.
#[test]
fn detect_warns_of_voting_with_an_uncalibrated_model() {
    use cog_gpu::calibration::Calibration;
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let warned = |extra: &[&str]| {
        let out = dir.path().join("out");
        let mut args = vec!["--cpu", "detect", SAMPLE, "--models", models.to_str().unwrap()];
        args.extend(["--out", out.to_str().unwrap(), "--no-overlay", "--max-per-category", "1"]);
        args.extend(extra);
        let output = run(&args);
        let stderr = String::from_utf8_lossy(&output.stderr).to_string();
        assert!(output.status.success(), "{stderr}");
        stderr.contains("not calibrated: bed;")
    };
    assert!(warned(&[]), "voting (the default) with the uncalibrated bed");
    assert!(!warned(&["--box-voting", "off"]), "no voting");
    let mut model = density_model(FeaturePath::Fast, 0.2);
    let (a, b) = (2.0, -1.0);
    model.calibration =
        Some(Calibration { a, b, detections: 0, true_positives: 0, iou: 0.25, data: String::new(), frames: 0 });
    model.write(&models.join("bed.json")).unwrap();
    assert!(!warned(&[]), "a calibrated bed");
}

/// `detect --overlay-min-score` reaches the picture: the PNG is exactly the library's overlay of the
/// detections `overlay_selection` keeps at that floor (by default 0.5, left out wherever they rank), and with
/// a floor of 1 no box is drawn at all (the picture is the RGB image).
#[test]
fn the_overlay_draws_only_calibrated_detections_above_its_floor() {
    use cog_gpu::calibration::Calibration;
    use cog_gpu::detect::{overlay_selection, DEFAULT_OVERLAY_MIN_PROBABILITY};
    use cog_gpu::nms::DEFAULT_NMS_IOU;
    let dir = tempfile::tempdir().unwrap();
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let mut model = density_model(FeaturePath::Fast, 0.2);
    // A calibration whose probability is 0.5 at the fourth best raw score: about half the best 8 above the
    // floor.
    // Without box voting, whose second NMS leaves fewer boxes (the floor is what this test is about).
    let everything = DetectOptions { min_score: Some(-100.0), box_voting: None, ..DetectOptions::default() };
    let raw = detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, &everything).unwrap().detections;
    assert!(raw.len() > 8, "{} detections", raw.len());
    let (a, midpoint) = (2.0, f64::from(raw[3].score));
    model.calibration = Some(Calibration {
        a,
        b: -a * midpoint,
        detections: 0,
        true_positives: 0,
        iou: 0.25,
        data: String::new(),
        frames: 0,
    });
    model.write(&models.join("bed.json")).unwrap();
    let name = "synth-bedroom-s52";
    let picture = |floor: Option<&str>| {
        let out = dir.path().join(format!("out-{}", floor.unwrap_or("default")));
        let mut args = vec!["--cpu", "detect", SAMPLE, "--models", models.to_str().unwrap()];
        args.extend(["--out", out.to_str().unwrap(), "--min-score", "-100", "--box-voting", "off"]);
        if let Some(floor) = floor {
            args.extend(["--overlay-min-score", floor]);
        }
        let output = run(&args);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let detections = FrameDetections::read(&out.join(format!("{name}.json"))).unwrap();
        (image::open(out.join(format!("{name}.png"))).unwrap().to_rgb8(), detections)
    };
    let (png, detections) = picture(None);
    let drawn = overlay_selection(&detections.detections, 8, DEFAULT_OVERLAY_MIN_PROBABILITY, DEFAULT_NMS_IOU);
    let unfloored = overlay_selection(&detections.detections, 8, 0.0, DEFAULT_NMS_IOU);
    assert!(!drawn.is_empty() && drawn.len() < unfloored.len(), "{} against {}", drawn.len(), unfloored.len());
    let expected = overlay(&frame, &FrameDetections { frame: name.into(), detections: drawn });
    assert!(png == expected, "the default floor's picture");
    let (png, detections) = picture(Some("0"));
    let expected = overlay(&frame, &FrameDetections { frame: name.into(), detections: unfloored });
    assert!(png == expected && detections.detections.len() > 8, "floor 0: the best 8");
    let (png, _) = picture(Some("1"));
    assert!(png == frame.rgb, "floor 1: no box");
    let output = run(&["detect", SAMPLE, "--overlay-min-score", "1.5"]);
    assert!(!output.status.success() && String::from_utf8_lossy(&output.stderr).contains("not a probability"));
}

/// `detect` of the sample frames on the CPU with `models` into `out`, without overlays, plus `extra`.
fn detect_samples(models: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["--cpu", "detect", "assets/sample", "--models", models.to_str().unwrap()];
    args.extend(["--out", out.to_str().unwrap(), "--no-overlay"]);
    args.extend(extra);
    run(&args)
}

#[test]
fn resume_keeps_finished_frames_and_detects_the_others_again() {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let out = dir.path().join("out");
    let detect = |extra: &[&str]| {
        let output = detect_samples(&models, &out, extra);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        (String::from_utf8_lossy(&output.stdout).into_owned(), String::from_utf8_lossy(&output.stderr).into_owned())
    };
    detect(&[]);
    let (synth, real) = (out.join("synth-bedroom-s52.json"), out.join("kv1-b3dodata-img_0063.json"));
    let read = |p: &Path| std::fs::read_to_string(p).unwrap();
    let (synth_first, real_first) = (read(&synth), read(&real));
    // A finished frame, marked (its detections emptied, which no detection here gives), and one whose file
    // an interrupted run cut short.
    let mut marked: serde_json::Value = serde_json::from_str(&synth_first).unwrap();
    assert!(!marked["detections"].as_array().unwrap().is_empty());
    marked["detections"] = serde_json::json!([]);
    std::fs::write(&synth, marked.to_string()).unwrap();
    std::fs::write(&real, &real_first[..real_first.len() / 2]).unwrap();
    let (stdout, stderr) = detect(&["--resume"]);
    assert_eq!(read(&synth), marked.to_string(), "the finished frame is kept as it was");
    assert_eq!(read(&real), real_first, "the cut file is detected again, as the first time");
    assert!(stderr.contains("--resume: kept 1 frame(s)"), "{stderr}");
    assert!(stdout.contains("synth-bedroom-s52: 0 detections"), "the summary reads the kept file: {stdout}");
    // Without --resume every frame is detected again; no temporary file is left behind.
    detect(&[]);
    assert_eq!(read(&synth), synth_first);
    let partial = std::fs::read_dir(&out).unwrap().flatten().any(|e| e.file_name().to_string_lossy().ends_with(".tmp"));
    assert!(!partial);
}

#[test]
fn resume_refuses_files_of_other_models_or_options() {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let out = dir.path().join("out");
    let detect = |extra: &[&str]| {
        let output = detect_samples(&models, &out, extra);
        (output.status.success(), String::from_utf8_lossy(&output.stderr).into_owned())
    };
    assert!(detect(&[]).0);
    let synth = out.join("synth-bedroom-s52.json");
    let read = |p: &Path| std::fs::read_to_string(p).unwrap();
    let first = read(&synth);
    let file: serde_json::Value = serde_json::from_str(&first).unwrap();
    let fingerprint = file["run"].as_str().unwrap().to_string();
    assert!(fingerprint.len() == 16 && fingerprint.chars().all(|c| c.is_ascii_hexdigit()), "{fingerprint}");
    // Another detection option, another model: refused before anything is detected, the files untouched.
    let (ok, stderr) = detect(&["--resume", "--max-per-category", "3"]);
    let refused = stderr.contains("2 of the detections files") && stderr.contains("other models or options");
    assert!(!ok && refused && stderr.contains(&format!("run {fingerprint}")), "{stderr}");
    assert_eq!(read(&synth), first);
    // Another normal search decides other detections: refused too; naming the default is the same run.
    let (ok, stderr) = detect(&["--resume", "--normals", "window"]);
    assert!(!ok && stderr.contains("other models or options"), "{stderr}");
    let (ok, stderr) = detect(&["--resume", "--normals", "kdtree"]);
    assert!(ok && stderr.contains("--resume: kept 2 frame(s)"), "{stderr}");
    let bed = models.join("bed.json");
    let model = read(&bed);
    let mut changed: serde_json::Value = serde_json::from_str(&model).unwrap();
    changed["threshold"] = serde_json::json!(changed["threshold"].as_f64().unwrap() + 0.5);
    std::fs::write(&bed, changed.to_string()).unwrap();
    let (ok, stderr) = detect(&["--resume"]);
    assert!(!ok && stderr.contains("other models or options"), "{stderr}");
    std::fs::write(&bed, &model).unwrap();
    // An option that changes only the pictures is not part of the run; the same run resumes.
    let (ok, stderr) = detect(&["--resume", "--overlay-top", "3"]);
    assert!(ok && stderr.contains("--resume: kept 2 frame(s)"), "{stderr}");
    // A file without a fingerprint (an older cog-gpu's) is kept, with a warning.
    let mut legacy = file.clone();
    legacy.as_object_mut().unwrap().remove("run");
    std::fs::write(&synth, legacy.to_string()).unwrap();
    let (ok, stderr) = detect(&["--resume"]);
    assert!(ok && stderr.contains("1 detections file(s)") && stderr.contains("no run fingerprint"), "{stderr}");
    assert_eq!(read(&synth), legacy.to_string());
}

#[test]
fn the_cli_names_bad_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let out = dir.path().join("out");
    let corrupt = dir.path().join("corrupt");
    std::fs::create_dir_all(&corrupt).unwrap();
    std::fs::write(corrupt.join("bed.json"), "{\"format\": \"cog-gpu-model\"").unwrap();
    let missing_frame = dir.path().join("no-such-frame");
    let cases: Vec<(Vec<&str>, String)> = vec![
        (
            vec!["detect", SAMPLE, "--models", "/nonexistent/models", "--out", out.to_str().unwrap()],
            "/nonexistent/models".into(),
        ),
        (
            vec!["detect", SAMPLE, "--models", corrupt.to_str().unwrap(), "--out", out.to_str().unwrap()],
            "bed.json".into(),
        ),
        (
            vec![
                "detect",
                missing_frame.to_str().unwrap(),
                "--models",
                models.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ],
            "no-such-frame".into(),
        ),
        (vec!["detect", SAMPLE, "--models", models.to_str().unwrap(), "--categories", "sofa"], "sofa".into()),
        (vec!["detect", SAMPLE, "--models", models.to_str().unwrap(), "--nms-iou", "2"], "IoU".into()),
        (vec!["detect", SAMPLE, "--models", models.to_str().unwrap(), "--step", "0"], "--step".into()),
        // The test's model has no calibration, so no probability cut.
        (
            vec!["detect", SAMPLE, "--models", models.to_str().unwrap(), "--min-probability", "0.5"],
            "bed.json: the 'bed' model has no calibration".into(),
        ),
        (vec!["detect", SAMPLE, "--models", models.to_str().unwrap(), "--min-probability", "1.5"], "(0, 1)".into()),
        // Two frames named alike would overwrite each other's detections file.
        (vec!["detect", SAMPLE, SAMPLE, "--models", models.to_str().unwrap()], "same name".into()),
    ];
    for (args, needle) in cases {
        let mut full = vec!["--cpu"];
        full.extend(&args);
        let output = run(&full);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(&needle), "{args:?}: expected '{needle}' in {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// `DetectStages::hypotheses_per_category` gives each model its own window's hypotheses: with two models
/// (a bed, and the same weights as a chair on a finer step), each category's count is what that model
/// scores alone (`hypotheses` of a run with it alone), the others are 0, and they add up to the total.
#[test]
fn timed_detection_counts_each_models_hypotheses() {
    use cog_gpu::category::category_index;
    use cog_gpu::detect::{detect_preprocessed_timed, DetectStages};
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let options = DetectOptions::default();
    let bed = density_model(FeaturePath::Fast, 0.3);
    let mut chair = density_model(FeaturePath::Fast, 0.2);
    chair.category = "chair".into();
    let alone = |model: &Model| {
        let mut stages = DetectStages::default();
        let models = std::slice::from_ref(model);
        detect_preprocessed_timed(&frame.name, pre.clone(), models, Backend::Cpu, &options, &mut stages).unwrap();
        stages.hypotheses
    };
    let (bed_alone, chair_alone) = (alone(&bed), alone(&chair));
    assert!(bed_alone > 0 && chair_alone > bed_alone, "{bed_alone} {chair_alone}: the finer step has more");
    let mut stages = DetectStages::default();
    let models = [bed, chair];
    detect_preprocessed_timed(&frame.name, pre, &models, Backend::Cpu, &options, &mut stages).unwrap();
    let per = stages.hypotheses_per_category;
    let (b, c) = (category_index("bed").unwrap(), category_index("chair").unwrap());
    assert_eq!((per[b], per[c]), (bed_alone, chair_alone));
    assert_eq!(per.iter().sum::<usize>(), stages.hypotheses);
    assert!(per.iter().enumerate().all(|(i, &n)| i == b || i == c || n == 0));
}

/// `detect_preprocessed_timed` detects exactly what `detect_frame` does, and its stage record adds up: every
/// stage non-negative, the fast path's tables counted only for fast models, a second call adding its own.
#[test]
fn timed_detection_is_detection_and_accumulates_its_stages() {
    use cog_gpu::detect::{detect_preprocessed_timed, DetectStages};
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let options = DetectOptions::default();
    for path in [FeaturePath::Fast, FeaturePath::Exact] {
        let models = [density_model(path, 0.3)];
        let plain = detect_frame(&frame, &models, Backend::Cpu, &options).unwrap();
        let mut stages = DetectStages::default();
        let pre = Preprocessed::from_frame(&frame).unwrap();
        let timed =
            detect_preprocessed_timed(&frame.name, pre.clone(), &models, Backend::Cpu, &options, &mut stages).unwrap();
        assert_eq!(timed, plain, "{path:?}");
        let once = stages;
        let parts = [
            once.yaw_grids_s,
            once.window_s,
            once.lattices_s,
            once.score_s,
            once.select_s,
            once.nms_s,
            once.cross_scores_s,
        ];
        assert!(parts.iter().all(|&s| s >= 0.0) && once.score_s > 0.0, "{once:?}");
        assert!((once.total_s() - parts.iter().sum::<f64>()).abs() < 1e-12);
        assert!(once.hypotheses > 0);
        match path {
            FeaturePath::Fast => assert!(once.tables_thread_s > 0.0 && once.lattices_s > 0.0, "{once:?}"),
            FeaturePath::Exact => assert_eq!((once.tables_thread_s, once.lattices_s), (0.0, 0.0), "{once:?}"),
        }
        detect_preprocessed_timed(&frame.name, pre, &models, Backend::Cpu, &options, &mut stages).unwrap();
        assert_eq!(stages.hypotheses, 2 * once.hypotheses);
        assert!(stages.score_s > once.score_s);
    }
}

/// `bench --detect` times the detection `detect` makes: per repeat one entry with the number of detections
/// `detect --json` reports for the frame, and a total that is the sum of its stages.
#[test]
fn bench_detect_times_the_detection_the_cli_makes() {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let m = models.to_str().unwrap();
    let output = run(&[
        "--cpu",
        "bench",
        "--detect",
        SAMPLE,
        "--models",
        m,
        "--json",
        "--warmup",
        "0",
        "--repeat",
        "2",
        "--in-flight",
        "2",
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let out = dir.path().join("out");
    let detected = run(&["--cpu", "detect", SAMPLE, "--models", m, "--out", out.to_str().unwrap(), "--json"]);
    assert!(detected.status.success());
    let printed: Vec<FrameDetections> = serde_json::from_slice(&detected.stdout).unwrap();
    let frames = report["paths"]["cpu"]["frames"].as_array().expect("cpu frames");
    assert_eq!(frames.len(), 2, "one entry per repeat");
    assert!(report["paths"].get("gpu").is_none(), "--cpu runs the CPU path only");
    for entry in frames {
        assert_eq!(entry["frame"], "synth-bedroom-s52");
        assert_eq!(entry["detections"].as_u64().unwrap() as usize, printed[0].detections.len());
        let stage = |k: &str| entry[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {entry}"));
        let keys = [
            "read_s",
            "preprocess_s",
            "yaw_grids_s",
            "window_s",
            "lattices_s",
            "score_s",
            "select_s",
            "nms_s",
            "cross_scores_s",
            "cascade_s",
            "layout_s",
            "output_s",
        ];
        let sum: f64 = keys.iter().map(|k| stage(k)).sum();
        assert!(keys.iter().all(|k| stage(k) >= 0.0));
        assert!((sum - stage("total_s")).abs() <= 1e-9 * sum.max(1.0), "{sum} vs {entry}");
        // Process CPU seconds: the stages' are parts of the frame's (sub-intervals of a monotonic clock),
        // and no stage uses more than every core for its whole wall time.
        let cpu_keys = [
            "preprocess_cpu_s",
            "yaw_grids_cpu_s",
            "window_cpu_s",
            "lattices_cpu_s",
            "score_cpu_s",
            "select_cpu_s",
            "nms_cpu_s",
            "cross_scores_cpu_s",
            "layout_cpu_s",
        ];
        let cpu_parts: f64 = cpu_keys.iter().map(|k| stage(k)).sum();
        assert!(cpu_keys.iter().all(|k| stage(k) >= 0.0));
        assert!(stage("cpu_s") + 1e-6 >= cpu_parts, "{entry}");
        assert!(stage("score_cpu_s") > 0.0, "scoring on the CPU takes CPU time: {entry}");
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
        for (cpu, wall) in [("score_cpu_s", "score_s"), ("cpu_s", "total_s")] {
            // (Plus the kernel's accounting granularity.)
            assert!(stage(cpu) <= cores * stage(wall) + 0.02, "{cpu} over {cores} cores × {wall}: {entry}");
        }
    }
    let mean = report["paths"]["cpu"]["mean"]["total_s"].as_f64().unwrap();
    let expected = frames.iter().map(|f| f["total_s"].as_f64().unwrap()).sum::<f64>() / 2.0;
    assert!((mean - expected).abs() <= 1e-9 * expected);
    // --in-flight 2: the two repeats again, at once, with the same detections and a wall time per detection.
    let pass = &report["paths"]["cpu"]["in_flight"];
    assert_eq!(pass["frames_in_flight"], 2, "{pass}");
    assert_eq!(pass["detections"], 2);
    assert_eq!(pass["same_as_one_at_a_time"], true, "{pass}");
    assert_eq!(pass["vs_one_at_a_time"]["frames_compared"], 2);
    let wall = pass["wall_s"].as_f64().unwrap();
    assert!(wall > 0.0 && (pass["s_per_frame"].as_f64().unwrap() - wall / 2.0).abs() <= 1e-12 * wall, "{pass}");
    // `detect`'s default box voting, reported as written; `--box-voting off` reaches the detections' options.
    assert_eq!(report["box_voting"], "0.3", "the default is detect's");
    let off =
        run(&["--cpu", "bench", "--detect", SAMPLE, "--models", m, "--json", "--warmup", "0", "--box-voting", "off"]);
    assert!(off.status.success(), "{}", String::from_utf8_lossy(&off.stderr));
    let off: serde_json::Value = serde_json::from_slice(&off.stdout).unwrap();
    assert_eq!(off["box_voting"], serde_json::Value::Null);
}

/// The GPU path (the fast kernel forced on, lavapipe included) detects the same boxes with the same scores
/// as the CPU path, checked by `bench --detect --both`, which fails when they differ.
#[test]
fn bench_detect_finds_the_gpu_and_cpu_paths_agree() {
    bench_detect_paths_agree("kdtree");
}

/// The same with the window normals, searched by the `normal_window` kernel on the GPU path and by its CPU
/// twin on the CPU path.
#[test]
fn bench_detect_finds_the_paths_agree_with_window_normals() {
    bench_detect_paths_agree("window");
}

fn bench_detect_paths_agree(normals: &str) {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    let output = Command::new(binary())
        .args(["bench", "--detect", SAMPLE, "--models", models.to_str().unwrap(), "--both", "--json", "--warmup", "0"])
        .args(["--normals", normals])
        .env("NODEVICE_SELECT", "1")
        .env("COG_GPU_FAST_KERNEL", "always")
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    if report["gpu_vs_cpu"].is_null() {
        assert_eq!(
            std::env::var("COG_GPU_SKIP_GPU_TESTS").as_deref(),
            Ok("1"),
            "no GPU adapter: install a Vulkan driver (lavapipe) or set COG_GPU_SKIP_GPU_TESTS=1"
        );
        eprintln!("skipped: no GPU adapter and COG_GPU_SKIP_GPU_TESTS=1");
        return;
    }
    assert_eq!(report["paths"]["gpu"]["fast_kernel"], true);
    assert_eq!(report["normals"], normals);
    assert_eq!(report["gpu_vs_cpu"]["same"], true, "{}", report["gpu_vs_cpu"]);
    assert_eq!(report["gpu_vs_cpu"]["frames_compared"], 1);
    assert!(report["paths"]["gpu"]["frames"][0]["detections"].as_u64().unwrap() > 0);
}

fn path_detection(category: &str, centre: [f32; 3], size: [f32; 3], score: f32) -> cog_gpu::eval::Detection {
    let cuboid = cog_gpu::geometry::Cuboid::new(glam::Vec3::from(centre), glam::Vec3::from(size), 0.0);
    cog_gpu::eval::Detection::new(category, &cuboid, score)
}

#[test]
fn path_comparison_allows_reordered_near_ties_and_alternate_sizes_only() {
    use cog_gpu::detect::{compare_paths, PATH_SCORE_TOLERANCE};
    let door = |depth: f32, score: f32| path_detection("door", [0.1, 1.8, -0.3], [0.82, depth, 2.1], score);
    let chair = |score: f32| path_detection("chair", [1.0, 2.0, -0.8], [0.5, 0.5, 0.9], score);
    let base = vec![vec![chair(0.5), door(0.093, 0.5)], vec![chair(0.2)]];
    // Identical: same, nothing alternate.
    let same = compare_paths(&base, &base);
    assert!(same.same && same.near_tie_alternates == 0 && same.frames_compared == 2, "{same:?}");
    // Two scores within rounding of each other in the other order (the backends order by score), and a
    // near-tie alternate: the same door centre with another depth, its score within the tolerance.
    let nudge = 0.5 * (1.0 + 0.5 * PATH_SCORE_TOLERANCE);
    let other = vec![vec![door(0.096, nudge), chair(0.5)], vec![chair(0.2)]];
    let agreement = compare_paths(&base, &other);
    assert!(agreement.same, "{agreement:?}");
    assert_eq!(agreement.near_tie_alternates, 1);
    assert!(agreement.max_relative_score_difference > 0.0);
    // Differences that are not near ties: a score beyond the tolerance, a moved centre, another
    // category, a missing detection — each makes its frame different.
    let beyond = 0.5 + 2.0 * PATH_SCORE_TOLERANCE;
    let moved = path_detection("door", [0.2, 1.8, -0.3], [0.82, 0.093, 2.1], 0.5);
    let renamed = path_detection("sofa", [0.1, 1.8, -0.3], [0.82, 0.093, 2.1], 0.5);
    for changed in
        [vec![chair(0.5), door(0.093, beyond)], vec![chair(0.5), moved], vec![chair(0.5), renamed], vec![chair(0.5)]]
    {
        let agreement = compare_paths(&base, &[changed.clone(), vec![chair(0.2)]]);
        assert!(!agreement.same, "{changed:?}");
        assert_eq!(agreement.frames_different, 1, "{changed:?}");
    }
}

#[test]
fn box_voting_moves_the_kept_boxes_only() {
    // Voting keeps the NMS's choice (categories, scores, yaws) and changes centres and sizes, then demotes
    // by `REVOTE_DEMOTION` the voted boxes that the NMS, run again, would drop (with no cut here, none is
    // left out); at IoU 1 only a box itself (and exact duplicates) votes, so nothing moves.
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let model = density_model(FeaturePath::Fast, 0.2);
    let plain =
        DetectOptions { max_per_category: 8, box_voting: None, min_score: Some(f32::MIN), ..DetectOptions::default() };
    let detect = |options: &DetectOptions| detect_frame(&frame, std::slice::from_ref(&model), Backend::Cpu, options);
    let unvoted = detect(&plain).unwrap().detections;
    assert!(unvoted.len() >= 3, "{} detections", unvoted.len());
    let same = detect(&DetectOptions { box_voting: Some(1.0), ..plain }).unwrap().detections;
    assert_eq!(same, unvoted);
    assert!(unvoted.windows(2).all(|w| w[0].score > w[1].score), "distinct scores, best first");
    let voted = detect(&DetectOptions { box_voting: Some(0.5), ..plain }).unwrap().detections;
    assert_eq!(voted.len(), unvoted.len(), "none dropped without a cut");
    assert!(voted.windows(2).all(|w| w[0].score >= w[1].score), "best first");
    // Each voted detection's twin is the unvoted detection of its yaw and score, or of its yaw and its score
    // plus the demotion (the model is uncalibrated: slope 1; the scores of this frame's kept boxes are
    // distinct).
    let twin_of = |v: &Detection| -> (usize, bool) {
        let found = unvoted.iter().position(|u| (&u.category, u.yaw) == (&v.category, v.yaw) && u.score == v.score);
        match found {
            Some(n) => (n, false),
            None => {
                let n = unvoted
                    .iter()
                    .position(|u| (&u.category, u.yaw) == (&v.category, v.yaw) && u.score - REVOTE_DEMOTION == v.score)
                    .expect("a twin");
                (n, true)
            }
        }
    };
    let twins: Vec<(usize, bool)> = voted.iter().map(twin_of).collect();
    let mut moved = 0;
    for (v, &(n, _)) in voted.iter().zip(&twins) {
        // A weighted mean of boxes that each overlap the kept box by IoU ≥ 0.5 stays near it.
        assert!(iou_3d(&v.cuboid(), &unvoted[n].cuboid()) >= 0.5, "{v:?} against {:?}", unvoted[n]);
        moved += usize::from(v.centre != unvoted[n].centre || v.size != unvoted[n].size);
    }
    assert!(moved > 0, "no box moved");
    // The NMS's promise holds for the boxes not demoted: no two of a category above its IoU; and each demoted
    // box overlaps above it a box not demoted that the NMS visited before it (a better unvoted twin).
    let kept: Vec<usize> = (0..voted.len()).filter(|&i| !twins[i].1).collect();
    for (k, &i) in kept.iter().enumerate() {
        for &j in &kept[k + 1..] {
            assert!(iou_3d(&voted[i].cuboid(), &voted[j].cuboid()) <= plain.nms_iou, "{:?} {:?}", voted[i], voted[j]);
        }
    }
    let demoted: Vec<usize> = (0..voted.len()).filter(|&i| twins[i].1).collect();
    assert!(!demoted.is_empty(), "no box demoted on this frame: the test does not reach the demotion");
    for &i in &demoted {
        let reason = kept
            .iter()
            .any(|&j| twins[j].0 < twins[i].0 && iou_3d(&voted[i].cuboid(), &voted[j].cuboid()) > plain.nms_iou);
        assert!(reason, "{:?} demoted without a better box over it", voted[i]);
    }
    assert!(DetectOptions { box_voting: Some(0.0), ..plain }.validate().is_err());
}

/// `cross_scores`: every detection of a cross category gets each cross-category model's exact-path score
/// of its own box — checked against the independent density (points inside over the projected hull's area)
/// for a density model and an affine copy of it, on voted boxes and on a box at a yaw of no grid —; other
/// categories' detections and models take no part.
#[test]
fn cross_scores_are_each_models_score_of_the_box() {
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let bed = density_model(FeaturePath::Exact, 0.3);
    let mut table = density_model(FeaturePath::Exact, 0.3);
    table.category = "table".into();
    table.weights[0] = 2.0;
    table.bias = 0.5;
    let mut lamp = density_model(FeaturePath::Exact, 0.3);
    lamp.category = "lamp".into();
    let options = DetectOptions { max_per_category: 4, ..DetectOptions::default() };
    let mut detections = detect_frame(&frame, std::slice::from_ref(&bed), Backend::Cpu, &options).unwrap().detections;
    assert!(!detections.is_empty());
    let first = detections[0].cuboid();
    let turned = cog_gpu::geometry::Cuboid::new(first.centre, first.size, first.yaw + 0.3);
    detections.push(cog_gpu::eval::Detection::new("table", &turned, 0.1));
    detections.push(cog_gpu::eval::Detection::new("lamp", &first, 0.1));
    let pre = Preprocessed::from_frame(&frame).unwrap();
    cog_gpu::detect::cross_scores(&pre, &[bed, lamp, table], &mut detections, Backend::Cpu);
    let camera = Camera::new(frame.intrinsics(), frame.rtilt());
    for d in &detections {
        if d.category == "lamp" {
            assert!(d.cross_scores.is_none(), "a lamp is no cross category");
            continue;
        }
        let scores = d.cross_scores.as_ref().expect("cross scores");
        assert_eq!(scores.keys().collect::<Vec<_>>(), ["bed", "table"], "the lamp model takes no part");
        let cuboid = d.cuboid();
        let inside = pre.points.iter().filter(|p| cuboid.contains(**p)).count() as f32;
        let area = projected_hull_area(&camera, &cuboid.corners()).unwrap();
        let density = inside / area.max(1.0);
        // Points exactly on a face may go either way between fixed-point and float membership.
        let tolerance = 0.005 * density + 2.0 / area;
        assert!((scores["bed"] - density).abs() <= tolerance, "{} vs {density}", scores["bed"]);
        assert!((scores["table"] - (2.0 * density + 0.5)).abs() <= 2.0 * tolerance, "{} vs {density}", scores["table"]);
    }
}

/// `detect --no-cascade` (first-stage files, on which a cascade may train) writes the cross scores; a run
/// that applies no cascade reading them does not.
#[test]
fn first_stage_files_carry_the_cross_scores() {
    let dir = tempfile::tempdir().unwrap();
    let models = models_dir(dir.path());
    for (extra, expected) in [(&["--no-cascade"][..], true), (&[][..], false)] {
        let out = dir.path().join(format!("out-{expected}"));
        let output = detect_samples(&models, &out, extra);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let text = std::fs::read_to_string(out.join("synth-bedroom-s52.json")).unwrap();
        let file: FrameDetections = serde_json::from_str(&text).unwrap();
        assert!(!file.detections.is_empty());
        for d in &file.detections {
            assert_eq!(d.cross_scores.is_some(), expected, "{extra:?}: {d:?}");
            if let Some(scores) = &d.cross_scores {
                assert_eq!(scores.keys().collect::<Vec<_>>(), ["bed"]);
            }
        }
    }
}
