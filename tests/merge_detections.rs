//! `cog-gpu merge-detections`: re-detecting some categories with new models and merging them into the
//! detections of the old ones gives exactly what detecting everything with the new models gives — the
//! reference is that full detection, run here — and the merges that would not are refused.

mod common;
use common::run_cog_gpu as run;
use common::strs;
use std::path::{Path, PathBuf};

fn ok(args: &[&str]) -> String {
    let out = run(args);
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn failure(args: &[&str]) -> String {
    let out = run(args);
    assert!(!out.status.success(), "{args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The shipped models of `categories` in `dir`, each one's bias moved by `shift[category]` (a different
/// model of the same category: other raw scores, so other probabilities and another order), with a
/// calibration so steep that most probabilities are exactly 0 or 1 in f32: ties across categories, whose
/// order `detect` settles by its model groups, raw scores and category order, and the merge must too.
fn models(dir: &Path, categories: &[&str], shift: &[(&str, f64)]) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    for category in categories {
        let path = format!("{}/assets/models/{category}.json", env!("CARGO_MANIFEST_DIR"));
        let mut model: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        if let Some((_, by)) = shift.iter().find(|(c, _)| c == category) {
            model["bias"] = (model["bias"].as_f64().unwrap() + by).into();
        }
        model["calibration"]["a"] = 200.0.into();
        model["calibration"]["b"] = 0.0.into();
        std::fs::write(dir.join(format!("{category}.json")), model.to_string()).unwrap();
    }
    dir.to_path_buf()
}

fn detect(data: &Path, models: &Path, out: &Path, categories: Option<&str>) {
    let mut args = vec![
        "--cpu",
        "detect",
        data.to_str().unwrap(),
        "--models",
        models.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--min-score",
        "-3",
        "--no-overlay",
        "--no-cascade",
        // Every desk's surface is searched, so that monitors are found on these small frames.
        "--support-min-score",
        "0",
    ];
    if let Some(categories) = categories {
        args.extend(["--categories", categories]);
    }
    ok(&args);
}

/// Each file of `dir` as JSON, by name, without `detect`'s `"run"` fingerprint (a merged file comes from no
/// single detect run, and `merge-detections` writes none: checked here).
fn files(dir: &Path) -> Vec<(String, serde_json::Value)> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).unwrap().flatten().map(|e| e.file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    names
        .into_iter()
        .map(|n| {
            let mut value: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(dir.join(&n)).unwrap()).unwrap();
            let run = value.as_object_mut().unwrap().remove("run");
            let merged = dir.file_name().is_some_and(|d| d.to_string_lossy().starts_with("step"));
            assert_eq!(run.is_some(), !merged, "{n} in {}", dir.display());
            (n, value)
        })
        .collect()
}

fn count(files: &[(String, serde_json::Value)], category: &str) -> usize {
    files.iter().flat_map(|(_, f)| f["detections"].as_array().unwrap()).filter(|d| d["category"] == category).count()
}

#[test]
fn merging_re_detected_categories_equals_detecting_everything_again() {
    let tmp = tempfile::tempdir().unwrap();
    let path = |name: &str| tmp.path().join(name);
    let text = |p: &PathBuf| p.to_str().unwrap().to_string();
    let data = path("data");
    ok(&[
        "synth",
        "--out",
        &text(&data),
        "--frames",
        "3",
        "--seed",
        "77",
        "--rooms",
        "office",
        "--width",
        "160",
        "--height",
        "120",
    ]);
    let all = ["chair", "desk", "monitor"];
    // The new models: the shipped ones. The old: the chair's and the desk's biases moved.
    let new = models(&path("new"), &all, &[]);
    let old = models(&path("old"), &all, &[("chair", -0.7), ("desk", 0.9)]);
    detect(&data, &new, &path("reference"), None);
    detect(&data, &old, &path("base"), None);
    let reference = files(&path("reference"));
    let base = files(&path("base"));
    assert_eq!(reference.len(), 3);
    for category in all {
        assert!(count(&reference, category) > 0, "no {category} detection to merge");
    }
    assert_ne!(base, reference, "the old models must detect differently for the test to mean anything");
    let scores: Vec<f64> = reference
        .iter()
        .flat_map(|(_, f)| f["detections"].as_array().unwrap().iter().map(|d| d["score"].as_f64().unwrap()))
        .collect();
    let saturated = |p: f64| scores.iter().filter(|&&s| s == p).count();
    assert!(saturated(0.0) > 10 && saturated(1.0) > 1, "ties at 0 and 1 expected: {scores:?}");

    // The chair alone: no surface model depends on it.
    detect(&data, &new, &path("chair-new"), Some("chair"));
    let merge = |base: &str, update: &str, categories: &str, out: &str| {
        vec![
            "merge-detections".to_string(),
            "--base".into(),
            text(&path(base)),
            "--update".into(),
            text(&path(update)),
            "--categories".into(),
            categories.into(),
            "--models".into(),
            text(&new),
            "--out".into(),
            text(&path(out)),
        ]
    };
    let summary = ok(&strs(&merge("base", "chair-new", "chair", "step1")));
    assert!(summary.lines().any(|l| l.starts_with("chair")), "{summary}");
    let step1 = files(&path("step1"));
    assert_ne!(step1, reference, "the desk and its monitors are still the old model's");
    assert_eq!(count(&step1, "chair"), count(&reference, "chair"));

    // The desk: the monitor is searched on its surfaces, so it must be replaced with it.
    let err = failure(&strs(&merge("step1", "chair-new", "desk", "refused")));
    assert!(err.contains("monitor") && err.contains("desk"), "{err}");
    assert!(!path("refused").exists());
    detect(&data, &new, &path("desk-new"), Some("desk,monitor"));
    ok(&strs(&merge("step1", "desk-new", "desk,monitor", "step2")));
    // Detection for detection and in the same order: the full detection with the new models — but for the
    // cross scores (first-stage files carry them), which a merge that replaced a chair or a desk model drops:
    // the kept boxes' would hold the old model's scores.
    let cross_scores = |files: &[(String, serde_json::Value)]| -> usize {
        files
            .iter()
            .flat_map(|(_, f)| f["detections"].as_array().unwrap())
            .filter(|d| d.get("cross_scores").is_some())
            .count()
    };
    assert!(cross_scores(&reference) > 0 && cross_scores(&base) > 0);
    assert_eq!(cross_scores(&step1), 0);
    let without_cross = |mut files: Vec<(String, serde_json::Value)>| {
        for (_, file) in &mut files {
            for d in file["detections"].as_array_mut().unwrap() {
                d.as_object_mut().unwrap().remove("cross_scores");
            }
        }
        files
    };
    let step2 = files(&path("step2"));
    assert_eq!(cross_scores(&step2), 0);
    assert_eq!(step2, without_cross(reference.clone()));
    // With the frames (--data) the cross scores are computed again: then the merge is the full detection,
    // cross scores included, bit for bit.
    let with_data = |base: &str, update: &str, categories: &str, out: &str| {
        let mut args = merge(base, update, categories, out);
        args.extend(["--data".to_string(), text(&data)]);
        args
    };
    ok(&strs(&with_data("base", "chair-new", "chair", "step1-data")));
    let step1_data = files(&path("step1-data"));
    assert_eq!(cross_scores(&step1_data), cross_scores(&reference));
    ok(&strs(&with_data("step1-data", "desk-new", "desk,monitor", "step2-data")));
    assert_eq!(files(&path("step2-data")), reference);
    // Only the chair replaced: its boxes and the kept desks' carry the new chair model's cross score, which
    // differs from the old one's (the old chair's bias was moved by −0.7), and the desks keep the old desk's.
    let chair_cross = |files: &[(String, serde_json::Value)], category: &str| -> Vec<f64> {
        files
            .iter()
            .flat_map(|(_, f)| f["detections"].as_array().unwrap())
            .filter(|d| d["category"] == category)
            .map(|d| d["cross_scores"]["chair"].as_f64().unwrap())
            .collect()
    };
    let (old_desk, new_desk) = (chair_cross(&base, "desk"), chair_cross(&step1_data, "desk"));
    assert_eq!(old_desk.len(), new_desk.len());
    for (o, n) in old_desk.iter().zip(&new_desk) {
        assert!((n - o - 0.7).abs() < 1e-4, "a desk box's chair score moves with the chair's bias: {o} → {n}");
    }
    let err = failure(&strs(&{
        let mut args = merge("base", "chair-new", "chair", "x");
        args.extend(["--data".to_string(), text(&path("new"))]);
        args
    }));
    assert!(err.contains("not in --data"), "{err}");
    // Replacing the monitor alone (no cross category) keeps the base's cross scores, box for box.
    let monitor_new = path("monitor-new");
    detect(&data, &old, &monitor_new, Some("monitor"));
    ok(&strs(&merge("base", "monitor-new", "monitor", "step-monitor")));
    assert_eq!(files(&path("step-monitor")), base);

    // Refused: cascaded files, a frame missing from --update, an --update without the categories, --out
    // equal to an input.
    let cascaded = path("cascaded");
    std::fs::create_dir_all(&cascaded).unwrap();
    for (name, mut file) in files(&path("base")) {
        file["detections"][0]["first_stage_score"] = 0.5.into();
        std::fs::write(cascaded.join(name), file.to_string()).unwrap();
    }
    let err = failure(&strs(&merge("cascaded", "chair-new", "chair", "x")));
    assert!(err.contains("cascade") && err.contains("cascaded"), "{err}");
    let partial = path("partial");
    std::fs::create_dir_all(&partial).unwrap();
    let (first, _) = &files(&path("chair-new"))[0];
    std::fs::copy(path("chair-new").join(first), partial.join(first)).unwrap();
    let err = failure(&strs(&merge("base", "partial", "chair", "x")));
    assert!(err.contains("missing") && err.contains("partial"), "{err}");
    let err = failure(&strs(&merge("base", "chair-new", "desk,monitor", "x")));
    assert!(err.contains("no detection of desk, monitor"), "{err}");
    let err = failure(&strs(&merge("base", "chair-new", "chair", "base")));
    assert!(err.contains("--out must differ"), "{err}");
    assert!(!path("x").exists());
}
