//! The room-layout commands through the binary on small synthetic frames: `train-layout` → `layout`
//! (JSON, overlay, PLY) → `eval --layout` (with `--bootstrap --versus`); `detect` with a layout model beside the detector models; and
//! bad inputs, which must exit with status 1 naming the file, never panic.

use std::path::Path;
use std::process::{Command, Output};

use cog_gpu::eval::{bootstrap_frames, percentile_interval, Bootstrap};
use serde_json::Value;

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
        .arg("--cpu")
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .env("RUST_LOG", "warn")
        .output()
        .expect("run cog-gpu")
}

fn ok(args: &[&str]) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{args:?} failed: {err}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs a command that must fail with exit code 1 and `needle` in its error; returns the error text.
fn rejected(args: &[&str], needle: &str) -> String {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{args:?} should fail: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert!(err.contains(needle), "{args:?}: expected '{needle}' in: {err}");
    err
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn train_layout_eval_and_detect_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    ok(&[
        "synth",
        "--out",
        &p("data"),
        "--frames",
        "3",
        "--seed",
        "5",
        "--width",
        "160",
        "--height",
        "120",
        "--sensor",
        "xtion",
    ]);
    ok(&["train-layout", "--data", &p("data"), "--out", &p("layout.json"), "--max-iterations", "3"]);
    let model = json(&dir.path().join("layout.json"));
    assert_eq!(model["format"], "cog-gpu-layout-model");
    // 288 Manhattan-voxel weights and 16 box-feature weights.
    assert_eq!(model["weights"].as_array().unwrap().len(), 304);
    assert_eq!(model["version"], 3);
    assert_eq!(model["provenance"]["data_seed"], 5);
    // A checkpoint after every iteration: one iteration, then `--resume` to three, ends with the weights
    // of the uninterrupted three; a resume without a checkpoint, or with another C, is refused.
    assert_eq!(model["provenance"]["qp_solves"], 3, "the run must go past the interruption");
    assert!(dir.path().join("layout.json.ckpt").is_file());
    ok(&["train-layout", "--data", &p("data"), "--out", &p("split.json"), "--max-iterations", "1"]);
    let resumed = Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
        .args(["--cpu", "train-layout", "--data", &p("data"), "--out", &p("split.json"), "--max-iterations", "3"])
        .arg("--resume")
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&resumed.stderr);
    assert!(resumed.status.success(), "{log}");
    // It continued at the checkpoint's iteration 1 (a fresh run starts at 0).
    assert!(log.contains("SSVM iteration 1:") && !log.contains("SSVM iteration 0:"), "{log}");
    let split = json(&dir.path().join("split.json"));
    assert!(split["weights"] == model["weights"], "the resumed run ends with other weights");
    assert_eq!(split["provenance"]["qp_solves"], 3);
    rejected(&["train-layout", "--data", &p("data"), "--out", &p("none.json"), "--resume"], "no checkpoint");
    rejected(&["train-layout", "--data", &p("data"), "--out", &p("split.json"), "--c", "1", "--resume"], "C = 10");
    let checkpoint = dir.path().join("split.json.ckpt");
    let mut bytes = std::fs::read(&checkpoint).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0xff;
    std::fs::write(&checkpoint, bytes).unwrap();
    rejected(&["train-layout", "--data", &p("data"), "--out", &p("split.json"), "--resume"], "checksum");

    // With the image-gradient features: 648 COG weights after the voxel weights, 2 edge weights at the end;
    // the file says so and `layout` follows it.
    ok(&["train-layout", "--data", &p("data"), "--out", &p("cog.json"), "--max-iterations", "3", "--cog", "--edges"]);
    let cog_model = json(&dir.path().join("cog.json"));
    assert_eq!(cog_model["weights"].as_array().unwrap().len(), 288 + 648 + 16 + 2);
    assert_eq!((cog_model["cog"].as_bool(), cog_model["edges"].as_bool()), (Some(true), Some(true)));
    ok(&["layout", &p("data"), "--model", &p("cog.json"), "--out", &p("cog-out"), "--no-overlay"]);
    assert_eq!(json(&dir.path().join("cog-out/synth-000000.json"))["layout"]["method"], "manhattan+cog+edges");
    // A file without the fields (written before them) is a model without them; with a wrong weight count
    // for what it claims, it is refused.
    let mut old = model.clone();
    old.as_object_mut().unwrap().remove("cog");
    old.as_object_mut().unwrap().remove("edges");
    std::fs::write(dir.path().join("old.json"), old.to_string()).unwrap();
    ok(&["layout", &p("data"), "--model", &p("old.json"), "--out", &p("old-out"), "--no-overlay"]);
    assert_eq!(json(&dir.path().join("old-out/synth-000000.json"))["layout"]["method"], "manhattan");
    old["edges"] = Value::Bool(true);
    std::fs::write(dir.path().join("claims-edges.json"), old.to_string()).unwrap();
    rejected(&["layout", &p("data"), "--model", &p("claims-edges.json"), "--out", &p("x")], "claims-edges.json");

    ok(&["layout", &p("data"), "--model", &p("layout.json"), "--out", &p("out"), "--ply"]);
    let frame = "synth-000000";
    let record = json(&dir.path().join(format!("out/{frame}.json")));
    assert_eq!(record["frame"], frame);
    assert_eq!(record["layout"]["corners"].as_array().unwrap().len(), 4);
    assert!(record["layout"]["floor"].as_f64().unwrap() < record["layout"]["ceiling"].as_f64().unwrap());
    assert!(dir.path().join(format!("out/{frame}.png")).is_file());
    let ply = std::fs::read_to_string(dir.path().join(format!("out/{frame}.ply"))).unwrap();
    assert!(ply.starts_with("ply\nformat ascii 1.0\n") && ply.contains("element edge 12\n"));

    let report: Value =
        serde_json::from_str(&ok(&["eval", "--layout", "--data", &p("data"), "--detections", &p("out"), "--json"]))
            .unwrap();
    assert_eq!(report["frames"], 3);
    for f in report["per_frame"].as_array().unwrap() {
        let iou = f["iou"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&iou), "{f}");
    }
    // The heuristic baseline writes the same files.
    ok(&["layout", &p("data"), "--heuristic", "--out", &p("heuristic"), "--no-overlay"]);
    assert_eq!(json(&dir.path().join(format!("heuristic/{frame}.json")))["layout"]["method"], "heuristic");

    // `--bootstrap --versus`: the intervals are those of the per-frame IoUs resampled by the library's
    // frame draws (recomputed here from the printed IoUs), the difference is the difference of the means,
    // and a directory against itself differs by exactly 0.
    let eval_json = |versus: &str| -> Value {
        let (data, out, versus) = (p("data"), p("out"), p(versus));
        let args = ["eval", "--layout", "--data", &data, "--detections", &out, "--json", "--bootstrap", "300"];
        let args = [&args[..], &["--bootstrap-seed", "7", "--versus", &versus]].concat();
        serde_json::from_str(&ok(&args)).unwrap()
    };
    let report = eval_json("heuristic");
    let column = |key: &str| -> Vec<f64> {
        report["per_frame"].as_array().unwrap().iter().map(|f| f[key].as_f64().unwrap_or(0.0)).collect()
    };
    let (ious, other) = (column("iou"), column("versus_iou"));
    let draws = bootstrap_frames(3, Bootstrap { resamples: 300, seed: 7 });
    let interval = |values: &[f64]| -> (f32, f32) {
        let means: Vec<f32> =
            draws.iter().map(|d| (d.iter().map(|&f| values[f]).sum::<f64>() / d.len() as f64) as f32).collect();
        percentile_interval(&means, 0.9).unwrap()
    };
    let pair = |v: &Value| (v[0].as_f64().unwrap() as f32, v[1].as_f64().unwrap() as f32);
    let b = &report["bootstrap"];
    assert_eq!((b["resamples"].as_u64(), b["seed"].as_u64()), (Some(300), Some(7)));
    assert_eq!(pair(&b["mean_iou_interval"]), interval(&ious));
    assert_eq!(pair(&b["versus"]["mean_iou_interval"]), interval(&other));
    let differences: Vec<f64> = ious.iter().zip(&other).map(|(a, b)| a - b).collect();
    assert_eq!(pair(&b["versus"]["difference_interval"]), interval(&differences));
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!((b["versus"]["difference"].as_f64().unwrap() - (mean(&ious) - mean(&other))).abs() < 1e-12);
    let (lo, hi) = pair(&b["mean_iou_interval"]);
    // Means of resampled frames lie between the smallest and the largest frame's IoU.
    let (min, max) = ious.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert!(lo <= hi && lo as f64 >= min - 1e-6 && hi as f64 <= max + 1e-6, "{lo} {hi} {ious:?}");
    let itself = eval_json("out");
    assert_eq!(itself["bootstrap"]["versus"]["difference"].as_f64(), Some(0.0));
    assert_eq!(pair(&itself["bootstrap"]["versus"]["difference_interval"]), (0.0, 0.0));

    // A models directory with a detector and the layout model: detect reads both.
    let models = dir.path().join("models");
    std::fs::create_dir(&models).unwrap();
    let bed = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/models/bed.json");
    std::fs::copy(&bed, models.join("bed.json")).unwrap();
    std::fs::copy(dir.path().join("layout.json"), models.join("layout.json")).unwrap();
    ok(&["detect", &p(&format!("data/{frame}")), "--models", &p("models"), "--out", &p("det"), "--ply"]);
    let detections = json(&dir.path().join(format!("det/{frame}.json")));
    assert!(detections["detections"].is_array());
    assert_eq!(detections["layout"]["method"], "manhattan");
    assert!(std::fs::read_to_string(dir.path().join(format!("det/{frame}.ply"))).unwrap().contains("element edge"));

    // `detect --json` prints the same entry on stdout: the detections and the room, which is the room the
    // `layout` command found with the same model.
    let frame_dir = p(&format!("data/{frame}"));
    let detect_json = |out: &str| -> Value {
        let args = ["detect", &frame_dir, "--models", &p("models"), "--out", &p(out), "--json", "--no-overlay"];
        serde_json::from_str(&ok(&args)).unwrap()
    };
    let printed = detect_json("det-json");
    assert_eq!(printed.as_array().unwrap().len(), 1);
    assert_eq!(printed[0], detections);
    assert_eq!(printed[0]["layout"], record["layout"]);
    // Without a layout model the entries have no "layout".
    std::fs::remove_file(models.join("layout.json")).unwrap();
    let printed = detect_json("det-plain");
    assert_eq!(printed[0]["frame"], frame);
    assert!(printed[0]["detections"].is_array());
    assert!(printed[0].get("layout").is_none(), "{}", printed[0]);
}

#[test]
fn bad_layout_inputs_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let p = |s: &str| dir.path().join(s).to_string_lossy().into_owned();
    rejected(&["layout", &p("nowhere"), "--heuristic", "--out", &p("out")], "nowhere");
    std::fs::write(dir.path().join("garbage.json"), "{not json").unwrap();
    rejected(&["layout", "--model", &p("garbage.json"), "--out", &p("out")], "garbage.json");
    let short =
        r#"{"format": "cog-gpu-layout-model", "version": 3, "discretisation": "manhattan", "weights": [1.0, 2.0]}"#;
    std::fs::write(dir.path().join("short.json"), short).unwrap();
    rejected(&["layout", "--model", &p("short.json"), "--out", &p("out")], "short.json");
    let nan = format!(
        r#"{{"format": "cog-gpu-layout-model", "version": 3, "discretisation": "cubical", "weights": [{}]}}"#,
        vec!["1e30"; 400].join(",")
    );
    std::fs::write(dir.path().join("huge.json"), nan).unwrap();
    rejected(&["layout", "--model", &p("huge.json"), "--out", &p("out")], "huge.json");
    // Older files (version 1 before the box features, version 2 before their reach) are refused with the
    // way out.
    for (version, dim) in [(1, 288), (2, 295)] {
        let old = format!(
            r#"{{"format": "cog-gpu-layout-model", "version": {version}, "discretisation": "manhattan", "weights": [{}]}}"#,
            vec!["0.5"; dim].join(",")
        );
        std::fs::write(dir.path().join("old.json"), old).unwrap();
        let stderr = rejected(&["layout", "--model", &p("old.json"), "--out", &p("out")], "old.json");
        assert!(stderr.contains("train-layout"), "{stderr}");
    }
    rejected(&["eval", "--layout", "--data", &p("nowhere"), "--detections", &p("out")], "nowhere");
    rejected(&["train-layout", "--data", &p("nowhere"), "--out", &p("m.json")], "nowhere");
}

/// A frame seen from half a metre before a wall (its points span 0.64 m across, under the layout's 1 m
/// sides): `layout` fails naming that cause, and `detect` with a layout model keeps the frame's detections
/// and writes them without a room (it skipped the whole frame before 2026-12-08).
#[test]
fn a_frame_too_close_to_a_wall_for_a_room_keeps_its_detections() {
    let root = tempfile::tempdir().unwrap();
    let data = root.path().join("data");
    let frame = cog_gpu::frame::Frame {
        name: "wall".into(),
        rgb: image::RgbImage::from_fn(64, 48, |x, y| image::Rgb([(x * 4) as u8, (y * 5) as u8, 90])),
        depth_mm: vec![500; 64 * 48],
        k: [[50.0, 0.0, 32.5], [0.0, 50.0, 24.5], [0.0, 0.0, 1.0]],
        extrinsics: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        scene: None,
        objects: Vec::new(),
        layout: None,
    };
    frame.write(data.join("wall")).unwrap();
    let models = root.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/models");
    for file in ["chair.json", "layout.json"] {
        std::fs::copy(shipped.join(file), models.join(file)).unwrap();
    }
    let (data_arg, models_arg) = (data.to_str().unwrap(), models.to_str().unwrap());
    let out = root.path().join("out");
    rejected(
        &[
            "layout",
            data_arg,
            "--model",
            &shipped.join("layout.json").to_string_lossy(),
            "--out",
            &out.to_string_lossy(),
        ],
        "no room hypothesis",
    );
    let detections = root.path().join("detections");
    let run_out =
        run(&["detect", data_arg, "--models", models_arg, "--out", detections.to_str().unwrap(), "--no-overlay"]);
    let err = String::from_utf8_lossy(&run_out.stderr);
    assert!(run_out.status.success(), "{err}");
    assert!(err.contains("wall: no room laid out"), "{err}");
    let written = json(&detections.join("wall.json"));
    assert_eq!(written["frame"], "wall");
    assert!(written.get("layout").is_none_or(Value::is_null), "{written}");
    assert!(written["detections"].is_array());
}
