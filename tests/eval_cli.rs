//! `cog-gpu eval` on a tiny hand-made dataset, against APs computed by hand.

use std::path::Path;
use std::process::{Command, Output};

use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::frame::{Frame, Object};
use cog_gpu::geometry::Cuboid;
use glam::Vec3;
use serde_json::Value;

mod common;

fn unit_box(x: f32, y: f32) -> Cuboid {
    Cuboid::new(Vec3::new(x, y, 0.5), Vec3::ONE, 0.0)
}

fn object(category: &str, cuboid: Cuboid) -> Object {
    Object { category: category.into(), label: None, cuboid }
}

use common::write_tiny_frame as write_frame;

fn write_detections(dir: &Path, frame: &str, detections: Vec<Detection>) {
    FrameDetections { frame: frame.into(), detections }.write(&dir.join(format!("{frame}.json"))).unwrap();
}

/// Ground truth:
/// * f1: beds at x = 0 and x = 5, a chair at y = 6;
/// * f2: a bed at x = 0;
/// * f3: nothing;
/// * f4: a chair (and no detections file).
///
/// Detections (bed, by score): 0.95 f2 far away (FP), 0.9 f1 exact (TP), 0.7 f3 (FP: no ground truth
/// there), 0.6 f1 shifted by half a width from the bed at x = 5 (IoU 1/3: TP at 0.25, FP at 0.5), 0.5 f2
/// exact but turned by π (IoU 1: TP). Chair: 0.8 f1 exact (TP). Sofa: one detection, no ground truth.
/// An extra file names no frame.
fn dataset(root: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let data = root.join("data");
    let dets = root.join("dets");
    std::fs::create_dir_all(&dets).unwrap();
    write_frame(
        &data,
        "f1",
        vec![object("bed", unit_box(0.0, 3.0)), object("bed", unit_box(5.0, 3.0)), object("chair", unit_box(0.0, 6.0))],
    );
    write_frame(&data, "f2", vec![object("bed", unit_box(0.0, 3.0))]);
    write_frame(&data, "f3", vec![]);
    write_frame(&data, "f4", vec![object("chair", unit_box(3.0, 3.0))]);
    write_detections(
        &dets,
        "f1",
        vec![
            Detection::new("bed", &unit_box(0.0, 3.0), 0.9),
            Detection::new("bed", &unit_box(5.5, 3.0), 0.6),
            Detection::new("chair", &unit_box(0.0, 6.0), 0.8),
            Detection::new("sofa", &unit_box(10.0, 10.0), 0.4),
        ],
    );
    let turned = Cuboid { yaw: std::f32::consts::PI, ..unit_box(0.0, 3.0) };
    write_detections(
        &dets,
        "f2",
        vec![Detection::new("bed", &unit_box(20.0, 3.0), 0.95), Detection::new("bed", &turned, 0.5)],
    );
    write_detections(&dets, "f3", vec![Detection::new("bed", &unit_box(0.0, 3.0), 0.7)]);
    write_detections(&dets, "not-a-frame", vec![Detection::new("bed", &unit_box(0.0, 3.0), 0.99)]);
    (data, dets)
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cog-gpu")).arg("eval").args(args).output().expect("run cog-gpu")
}

fn run_json(args: &[&str]) -> Value {
    let out = run(&[args, &["--json"]].concat());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "cog-gpu eval failed: {stderr}");
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("stdout is not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

fn close(value: &Value, expected: f64) -> bool {
    value.as_f64().is_some_and(|v| (v - expected).abs() < 1e-5)
}

#[test]
fn aps_match_hand_computation() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = dataset(tmp.path());
    let (data, dets) = (data.to_str().unwrap(), dets.to_str().unwrap());

    // IoU 0.25. Bed: FP, TP, FP, TP, TP with 3 boxes → precision 0, 1/2, 1/3, 1/2, 3/5, recall 0, 1/3, 1/3,
    // 2/3, 1; envelope 3/5 throughout → AP = 3/5. Chair: one TP of 2 boxes → AP = 1/2.
    let report = run_json(&["--data", data, "--detections", dets]);
    assert!(close(&report["iou"], 0.25));
    let ap = report["ap"].as_object().unwrap();
    assert_eq!(ap.len(), 10, "the default categories are the ten large ones: {ap:?}");
    assert!(close(&ap["bed"], 0.6), "{ap:?}");
    assert!(close(&ap["chair"], 0.5), "{ap:?}");
    assert!(ap["sofa"].is_null() && ap["toilet"].is_null());
    assert!(close(&report["map"], 0.55));
    assert_eq!(report["frames"], 4);
    assert_eq!(report["missing_detection_files"], 1);
    assert_eq!(report["ground_truth"]["bed"], 3);
    assert_eq!(report["detections"]["bed"], 5);
    assert_eq!(report["detections"]["sofa"], 1);

    // IoU 0.5: the shifted bed becomes a FP: FP, TP, FP, FP, TP → precision 0, 1/2, 1/3, 1/4, 2/5,
    // recall 0, 1/3, 1/3, 1/3, 2/3; envelope 1/2, 1/2, 2/5, 2/5, 2/5 → AP = 1/3·1/2 + 1/3·2/5 = 0.3.
    let strict = run_json(&["--data", data, "--detections", dets, "--iou", "0.5"]);
    assert!(close(&strict["ap"]["bed"], 0.3), "{strict}");
    assert!(close(&strict["map"], 0.4), "{strict}");
}

#[test]
fn categories_split_and_all() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = dataset(tmp.path());
    let list = tmp.path().join("split.txt");
    std::fs::write(&list, "# only the first frame\nf1\n").unwrap();
    let (data, dets, list) = (data.to_str().unwrap(), dets.to_str().unwrap(), list.to_str().unwrap());

    // Only f1: both of its beds are found (0.9 exact, 0.6 at IoU 1/3) and its chair: AP 1 each.
    let report = run_json(&["--data", data, "--detections", dets, "--split", list, "--categories", "bed,chair"]);
    let ap = report["ap"].as_object().unwrap();
    assert_eq!(ap.keys().collect::<Vec<_>>(), ["bed", "chair"]);
    assert!(close(&ap["bed"], 1.0) && close(&ap["chair"], 1.0) && close(&report["map"], 1.0), "{report}");
    assert_eq!(report["frames"], 1);

    let all = run_json(&["--data", data, "--detections", dets, "--categories", "all"]);
    assert_eq!(all["ap"].as_object().unwrap().len(), 19);
    assert!(close(&all["map"], 0.55));

    let out = run(&["--data", data, "--detections", dets, "--categories", "beds"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("'beds'"));
}

#[test]
fn table_and_plots() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = dataset(tmp.path());
    let plots = tmp.path().join("pr");
    let out = run(&[
        "--data",
        data.to_str().unwrap(),
        "--detections",
        dets.to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let table = String::from_utf8_lossy(&out.stdout);
    let bed_line = table.lines().find(|l| l.starts_with("bed ")).expect("a bed row");
    assert_eq!(bed_line.split_whitespace().collect::<Vec<_>>(), ["bed", "3", "5", "60.0"]);
    let map_line = table.lines().find(|l| l.starts_with("mAP")).expect("an mAP row");
    assert!(map_line.ends_with("55.0"), "{map_line}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not-a-frame.json"), "the unknown frame's file is not reported: {stderr}");
    assert!(stderr.contains("1 of 4 frames"), "missing files are not reported: {stderr}");

    // One plot per category with ground truth.
    for category in ["bed", "chair"] {
        let img = image::open(plots.join(format!("{category}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), cog_gpu::eval::PLOT_SIZE);
    }
    assert!(!plots.join("sofa.png").exists());
}

#[test]
fn bad_detection_files_are_errors_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = dataset(tmp.path());
    std::fs::write(dets.join("f2.json"), "{ \"frame\": \"f2\", \"detections\": [ {").unwrap();
    // The bad frame is reported and left out, the others are evaluated, and the run fails at the end.
    let out = run(&["--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap(), "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("f2.json") && stderr.contains("1 of 4 frames failed"), "{stderr}");
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["frames"], 3);
    // --fail-fast: the first bad frame stops the run before any report.
    let out = run(&["--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap(), "--json", "--fail-fast"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("f2.json"), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.stdout.is_empty());

    std::fs::write(
        dets.join("f2.json"),
        r#"{"frame": "f2", "detections": [{"category": "bed", "centre": [0, 3, 0.5], "size": [1, -1, 1], "yaw": 0, "score": 1}]}"#,
    )
    .unwrap();
    let out = run(&["--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("f2.json") && stderr.contains("size"), "{stderr}");

    let out = run(&["--data", data.to_str().unwrap(), "--detections", tmp.path().join("nowhere").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("nowhere"));
}

#[test]
fn annotations_read_without_images_match_the_full_reader() {
    let dir = Path::new("../shared/data/sunrgbd/kv1-b3dodata-img_0063");
    let frame = Frame::read(dir, Default::default()).unwrap();
    let (objects, layout) = cog_gpu::frame::read_annotations(dir).unwrap();
    assert!(!objects.is_empty());
    assert_eq!(objects, frame.objects);
    assert_eq!(layout, frame.layout);
    assert!(cog_gpu::frame::read_annotations(&dir.join("missing")).is_err());
}

#[test]
fn bootstrap_intervals_and_paired_differences() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = dataset(tmp.path());
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let (data, dets, empty) = (data.to_str().unwrap(), dets.to_str().unwrap(), empty.to_str().unwrap());
    let args = ["--data", data, "--detections", dets, "--categories", "bed,chair,sofa", "--bootstrap", "300"];

    let report = run_json(&args);
    let boot = &report["bootstrap"];
    assert_eq!(boot["resamples"], 300);
    assert!(close(&boot["level"], 0.9));
    for category in ["bed", "chair"] {
        let interval = boot["ap_interval"][category].as_array().expect("an interval");
        let (lo, hi) = (interval[0].as_f64().unwrap(), interval[1].as_f64().unwrap());
        assert!((0.0..=1.0).contains(&lo) && lo <= hi && hi <= 1.0, "{category}: {interval:?}");
    }
    assert!(boot["ap_interval"]["sofa"].is_null(), "no sofa ground truth, no interval");
    // Same seed, same intervals; the plain AP report is unchanged by --bootstrap.
    assert_eq!(run_json(&args)["bootstrap"], *boot);
    assert!(close(&report["ap"]["bed"], 0.6) && close(&report["map"], 0.55));

    // Against itself: every paired difference is exactly 0.
    let same = run_json(&[&args[..], &["--versus", dets]].concat());
    let versus = &same["bootstrap"]["versus"];
    assert!(close(&versus["ap"]["bed"], 0.6));
    for category in ["bed", "chair"] {
        assert_eq!(versus["difference_interval"][category], serde_json::json!([0.0, 0.0]));
    }
    // Against no detections (AP 0 in every resample): the difference's interval is the AP's own.
    let nothing = run_json(&[&args[..], &["--versus", empty]].concat());
    let versus = &nothing["bootstrap"]["versus"];
    assert!(close(&versus["ap"]["bed"], 0.0) && close(&versus["map"], 0.0));
    for category in ["bed", "chair"] {
        assert_eq!(versus["difference_interval"][category], boot["ap_interval"][category], "{category}");
    }
    assert_eq!(versus["map_difference_interval"], boot["map_interval"]);

    // The table prints the intervals; --versus needs --bootstrap; one resample is not a bootstrap (bad
    // options exit with 1, as every error).
    let out = run(&args);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("90 % percentile intervals") && table.lines().any(|l| l.starts_with("bed ") && l.contains('[')),
        "{table}"
    );
    let out = run(&["--data", data, "--detections", dets, "--versus", empty]);
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    let out = run(&["--data", data, "--detections", dets, "--bootstrap", "1"]);
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn ignore_out_of_view_by_hand() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = dataset(tmp.path());
    let (data, dets) = (data.to_str().unwrap(), dets.to_str().unwrap());
    // The tiny frames' camera (fx = fy = 10, 0-based principal point (3.5, 2.5), 8 × 6 pixels, Rtilt = I)
    // sees u = 10·x/y + 3.5 ∈ [−0.5, 7.5), i.e. |x/y| < 0.4. In view: the beds at x = 0 (90 %, see
    // tests/diagnose.rs) and f1's chair at y = 6 (x/y ≤ 0.09, z/y ≤ 0.2: all of it). Out of view (none of
    // it): f1's bed at x = 5 (x/y ≥ 4.5/3.5) and f4's chair at x = 3 (x/y ≥ 2.5/3.5).
    // IoU 0.25: the 0.6 bed detection's best box is the ignored bed at x = 5 (IoU 1/3): dropped. Bed: FP
    // (0.95), TP (0.9), FP (0.7), TP (0.5) of 2 boxes → precision 0, 1/2, 1/3, 1/2, recall 0, 1/2, 1/2, 1;
    // envelope 1/2 → AP 1/2. Chair: its one detection finds the one box left → AP 1. mAP 3/4.
    let args = ["--data", data, "--detections", dets, "--categories", "bed,chair", "--ignore-out-of-view", "0.25"];
    let report = run_json(&args);
    assert!(close(&report["ap"]["bed"], 0.5), "{report}");
    assert!(close(&report["ap"]["chair"], 1.0), "{report}");
    assert!(close(&report["map"], 0.75), "{report}");
    assert_eq!((report["ground_truth"]["bed"].as_u64(), report["detections"]["bed"].as_u64()), (Some(2), Some(4)));
    let ignored = &report["ignored"];
    assert!(close(&ignored["min_in_view"], 0.25));
    assert_eq!(ignored["ignored"]["bed"], serde_json::json!({"boxes": 1, "detections": 1}));
    assert_eq!(ignored["ignored"]["chair"], serde_json::json!({"boxes": 1, "detections": 0}));
    // Without the option nothing is ignored and there is no "ignored" key (the AP of aps_match_hand_computation).
    let plain = run_json(&args[..6]);
    assert!(close(&plain["ap"]["bed"], 0.6) && plain.get("ignored").is_none(), "{plain}");
    // IoU 0.5: the 0.6 detection's best box is still the ignored one, but at IoU 1/3 < 0.5 it takes
    // nothing and stays a false positive: FP, TP, FP, FP, TP of 2 → precision 0, 1/2, 1/3, 1/4, 2/5, recall
    // 0, 1/2, 1/2, 1/2, 1; envelope 1/2, 1/2, 2/5, 2/5, 2/5 → AP 1/2·1/2 + 1/2·2/5 = 0.45.
    let strict = run_json(&[&args[..], &["--iou", "0.5"]].concat());
    assert!(close(&strict["ap"]["bed"], 0.45), "{strict}");
    assert_eq!(strict["ignored"]["ignored"]["bed"], serde_json::json!({"boxes": 1, "detections": 0}));
    // A share of 1 also ignores the beds 90 % in view: no bed is left (AP null), all five detections but
    // the far one (best box at IoU 0) and f3's (no box) are dropped.
    let all = run_json(&[&args[..6], &["--ignore-out-of-view", "1"]].concat());
    assert!(all["ap"]["bed"].is_null(), "{all}");
    assert_eq!(all["ignored"]["ignored"]["bed"], serde_json::json!({"boxes": 3, "detections": 3}));

    // --versus drops the other set's detections by the same rule: against itself every difference is 0 and
    // its bed AP is the 1/2 above (0.45 if its shifted bed were kept and counted false).
    let versus = run_json(&[&args[..], &["--bootstrap", "200", "--versus", dets]].concat());
    let versus = &versus["bootstrap"]["versus"];
    assert!(close(&versus["ap"]["bed"], 0.5), "{versus}");
    assert_eq!(versus["difference_interval"]["bed"], serde_json::json!([0.0, 0.0]));

    // The table says what it left out; the diagnosis runs on what is left (2 bed boxes).
    let out = run(&args);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("ignored (--ignore-out-of-view 0.25): 2 ground-truth boxes"), "{table}");
    assert!(table.contains("bed 1/1, chair 1/0"), "{table}");
    let diagnosis = run_json(&[&args[..], &["--diagnose"]].concat());
    assert_eq!(diagnosis["diagnosis"]["bed"]["gt_boxes"], 2, "{diagnosis}");
    assert!(diagnosis["ignored"].is_object());
    // A share outside (0, 1] and the option with --layout are refused.
    for bad in [
        &["--ignore-out-of-view", "0"][..],
        &["--ignore-out-of-view", "1.5"],
        &["--layout", "--ignore-out-of-view", "0.5"],
    ] {
        let out = run(&[&["--data", data, "--detections", dets][..], bad].concat());
        assert_eq!(out.status.code(), Some(1), "{bad:?}: {}", String::from_utf8_lossy(&out.stderr));
    }
}
