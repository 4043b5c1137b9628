//! The cascade's final calibration (`cog_gpu::calibration`, "The cascade's final calibration"): the map
//! against hand values, the fit on constructed frames whose best map is known in closed form, the cascade
//! file that carries it, and the CLI (`calibrate --cascade --final`, then `rescore`).

mod common;

use cog_gpu::calibration::{fit_final_calibration, fit_log_odds, Calibration, LOG_ODDS_OF_ONE, LOG_ODDS_OF_ZERO};
use cog_gpu::cascade::Cascade;
use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::exclusion::Exclusion;
use cog_gpu::frame::Object;
use cog_gpu::geometry::Cuboid;
use glam::Vec3;

fn map(a: f64, b: f64) -> Calibration {
    Calibration { a, b, detections: 0, true_positives: 0, iou: 0.25, data: String::new(), frames: 0 }
}

fn sigmoid(x: f64) -> f32 {
    (1.0 / (1.0 + (-x).exp())) as f32
}

fn unit_box(x: f32) -> Cuboid {
    Cuboid::new(Vec3::new(x, 0.0, 0.5), Vec3::ONE, 0.0)
}

/// A calibrated first-stage detection of `category` on the unit box at `x` with probability `p`.
fn detection(category: &str, x: f32, p: f32) -> Detection {
    let mut d = Detection::new(category, &unit_box(x), p);
    d.raw_score = Some(p.ln() - (1.0 - p).ln());
    d
}

#[test]
fn the_map_matches_hand_values_keeps_the_ends_and_never_reorders() {
    // a = 1, b = ln 2 doubles the odds: 1/2 → 2/3, 1/3 → 1/2.
    let double = map(1.0, 2f64.ln());
    assert!((double.recalibrate(0.5) - 2.0 / 3.0).abs() < 1e-7);
    assert!((double.recalibrate(1.0 / 3.0) - 0.5).abs() < 1e-7);
    // a = 2, b = 0 squares the odds: 1/3 (odds 1/2) → 1/5 (odds 1/4).
    assert!((map(2.0, 0.0).recalibrate(1.0 / 3.0) - 0.2).abs() < 1e-7);
    // The identity map gives every score back (to the f32 it came from).
    let identity = map(1.0, 0.0);
    for p in [1e-30f32, 1e-6, 0.01, 0.3, 0.5, 0.77, 0.999, 1.0 - 6e-8] {
        assert_eq!(identity.recalibrate(p), p, "{p}");
    }
    // 0 and 1 stay; the map never puts a lower score above a higher one.
    for calibration in [map(0.5, 0.4), map(1.0, 0.44), map(2.0, -1.0), map(1e-3, 3.0)] {
        assert_eq!(calibration.recalibrate(0.0), 0.0);
        assert_eq!(calibration.recalibrate(1.0), 1.0);
        let mut previous = 0.0f32;
        let mut p = 1e-38f32;
        while p < 1.0 {
            let mapped = calibration.recalibrate(p);
            assert!(mapped >= previous && (0.0..=1.0).contains(&mapped), "{p} → {mapped} after {previous}");
            previous = mapped;
            p = if p < 0.999 { p * 1.01 } else { p.next_up() };
        }
    }
    // The fit's log-odds of 0 and 1 are those of the f32 rounding boundaries, 2⁻¹⁵⁰ and 1 − 2⁻²⁵.
    assert_eq!(fit_log_odds(0.0), LOG_ODDS_OF_ZERO);
    assert_eq!(fit_log_odds(1.0), LOG_ODDS_OF_ONE);
    let logit = |p: f64| (p / (1.0 - p)).ln() as f32;
    assert_eq!(LOG_ODDS_OF_ZERO, logit(2f64.powi(-150)));
    assert_eq!(LOG_ODDS_OF_ONE, logit(1.0 - 2f64.powi(-25)));
    assert!((fit_log_odds(0.25) - logit(0.25)).abs() < 1e-6);
    assert!(fit_log_odds(1.0 - 6e-8) < LOG_ODDS_OF_ONE && fit_log_odds(1e-45) > LOG_ODDS_OF_ZERO);
}

/// Frames of one table each, with one table detection each: 40 at probability σ(−1), 10 of them on their
/// frame's table (true positives), and 40 at σ(1), 30 of them true; plus in every frame a desk detection
/// (no desk is annotated). The logistic fit of two score values fits their frequencies exactly (up to the
/// fit's weak prior): logit(1/4) = −a + b and logit(3/4) = a + b give a = ln 3, b = 0.
fn two_level_frames() -> (Vec<Vec<Detection>>, Vec<Vec<Object>>) {
    let (low, high) = (sigmoid(-1.0), sigmoid(1.0));
    let mut detections = Vec::new();
    let mut truth = Vec::new();
    for f in 0..80 {
        let (p, hit) = if f < 40 { (low, f < 10) } else { (high, f < 70) };
        let x = if hit { 0.0 } else { 5.0 };
        detections.push(vec![detection("table", x, p), detection("desk", 2.0, 0.9)]);
        truth.push(vec![Object { category: "table".into(), label: None, cuboid: unit_box(0.0) }]);
    }
    (detections, truth)
}

#[test]
fn the_fit_recovers_the_closed_form_map() {
    let (detections, truth) = two_level_frames();
    let fit = fit_final_calibration(&detections, &truth, &[], 0.25, "two levels").unwrap();
    // Default categories: those with ground truth (the table), so the desk's false detections are not seen.
    assert_eq!(fit.categories, ["table"]);
    let c = &fit.calibration;
    assert!((c.a - 3f64.ln()).abs() < 2e-3 && c.b.abs() < 2e-3, "a {} b {}", c.a, c.b);
    assert_eq!((c.detections, c.true_positives, c.frames), (80, 40, 80));
    assert_eq!(c.data, "two levels");
    // Before: the scores expect 40·σ(−1) + 40·σ(1) = 40 true positives — right in sum, wrong per level; the
    // fit's probabilities 1/4 and 3/4 expect 40 too, and lose less.
    assert!((fit.expected_true_positives_before - 40.0).abs() < 1e-4);
    assert!((fit.expected_true_positives_after - 40.0).abs() < 0.05);
    let loss = |p: f64, hits: f64| -(hits * p.ln() + (40.0 - hits) * (1.0 - p).ln());
    let (low, high) = (f64::from(sigmoid(-1.0)), f64::from(sigmoid(1.0)));
    assert!((fit.log_loss_before - (loss(low, 10.0) + loss(high, 30.0)) / 80.0).abs() < 1e-6);
    assert!((fit.log_loss_after - (loss(0.25, 10.0) + loss(0.75, 30.0)) / 80.0).abs() < 1e-4);
    assert!((c.recalibrate(sigmoid(-1.0)) - 0.25).abs() < 1e-3);

    // With the desk among the categories, its 80 false detections at 0.9 count: the fit moves (lower b).
    let with_desk = fit_final_calibration(&detections, &truth, &["table".into(), "desk".into()], 0.25, "").unwrap();
    assert_eq!(with_desk.calibration.detections, 160);
    assert!(with_desk.calibration.recalibrate(0.9) < 0.5);
    // Only true or only false positives: no map, an error that says so.
    let err = fit_final_calibration(&detections, &truth, &["desk".into()], 0.25, "").unwrap_err().to_string();
    assert!(err.contains("final calibration") && err.contains("0 true"), "{err}");
}

fn cascade(exclusion: Option<Exclusion>, final_calibration: Option<Calibration>) -> Cascade {
    common::cascade_without_stages(exclusion, final_calibration)
}

#[test]
fn the_cascade_file_carries_the_map_and_applies_it_last() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cascade.json");
    let exclusion = Exclusion { iou: 0.05, weight: 0.5 };
    let with_map = cascade(Some(exclusion), Some(map(1.0, 2f64.ln())));
    with_map.write(&path).unwrap();
    assert_eq!(Cascade::read(&path).unwrap(), with_map);
    // A file without the field (every cascade before it) reads as no final calibration.
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    json.as_object_mut().unwrap().remove("final_calibration");
    std::fs::write(&path, json.to_string()).unwrap();
    assert_eq!(Cascade::read(&path).unwrap().final_calibration, None);
    // A slope ≤ 0 would reorder the detections: refused, naming the file.
    json["final_calibration"] = serde_json::to_value(map(-1.0, 0.0)).unwrap();
    std::fs::write(&path, json.to_string()).unwrap();
    let err = Cascade::read(&path).unwrap_err().to_string();
    assert!(err.contains("cascade.json") && err.contains("final calibration slope"), "{err}");

    // A desk at 0.8 and a table at 0.5 on one box, a table at 0.2 alone: the exclusion demotes the first
    // table to 0.5 · (1 − 0.5 · 0.8) = 0.3, then the map doubles every odds: 0.8 → 8/9, 0.3 → 6/13,
    // 0.2 → 1/3; best first.
    let frame = vec![detection("table", 0.0, 0.5), detection("desk", 0.0, 0.8), detection("table", 5.0, 0.2)];
    let mut rescored = frame.clone();
    with_map.rescore(&mut rescored, None).unwrap();
    let got: Vec<(&str, f32, Option<f32>)> =
        rescored.iter().map(|d| (d.category.as_str(), d.score, d.score_before_final_calibration)).collect();
    let want = [("desk", 8.0 / 9.0, 0.8), ("table", 6.0 / 13.0, 0.3), ("table", 1.0 / 3.0, 0.2)];
    for (g, w) in got.iter().zip(want) {
        assert_eq!(g.0, w.0);
        assert!((g.1 - w.1).abs() < 1e-6 && (g.2.unwrap() - w.2).abs() < 1e-6, "{got:?}");
    }
    assert_eq!(rescored[1].score_before_exclusion, Some(0.5));
    // Without the map: the same detections in the same order, the exclusion's scores.
    let mut before = frame.clone();
    with_map.rescore_before_final_calibration(&mut before, None).unwrap();
    assert!(before.iter().all(|d| d.score_before_final_calibration.is_none()));
    assert_eq!(
        before.iter().map(|d| (&d.category, d.score)).collect::<Vec<_>>(),
        rescored.iter().map(|d| (&d.category, d.score_before_final_calibration.unwrap())).collect::<Vec<_>>()
    );
    // Mapped detections are not first-stage ones: rescoring them again is refused, also when the exclusion
    // demoted none of them.
    let mut again = vec![rescored[0].clone()];
    assert!(again[0].score_before_exclusion.is_none());
    let err = with_map.rescore(&mut again, None).unwrap_err().to_string();
    assert!(err.contains("already rescored"), "{err}");
    // Cascades with different maps are not merged; refitting the stages' calibrations drops the map.
    let err = with_map.merged_with(&cascade(Some(exclusion), None)).unwrap_err();
    assert!(err.contains("final calibration"), "{err}");
    let (refitted, report) = with_map.recalibrated(&[], &[], 0.25, "").unwrap();
    assert!(report.is_empty());
    assert_eq!(refitted, cascade(Some(exclusion), None));
}

#[test]
fn cli_fits_the_map_and_rescore_applies_it() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, first) = (tmp.path().join("data"), tmp.path().join("first"));
    std::fs::create_dir_all(&first).unwrap();
    let (detections, truth) = two_level_frames();
    for (f, (frame, objects)) in detections.iter().zip(&truth).enumerate() {
        let name = format!("t{f:02}");
        common::write_tiny_frame(&data, &name, objects.clone());
        FrameDetections { frame: name.clone(), detections: frame.clone() }
            .write(&first.join(format!("{name}.json")))
            .unwrap();
    }
    let (input, output) = (tmp.path().join("cascade.json"), tmp.path().join("mapped.json"));
    // The input's own map is replaced, not composed with: the fit reads the scores before it.
    cascade(None, Some(map(5.0, 5.0))).write(&input).unwrap();
    let base = ["calibrate", "--cascade", input.to_str().unwrap(), "--final", "--data", data.to_str().unwrap()];
    let base: Vec<&str> = base.into_iter().chain(["--detections", first.to_str().unwrap()]).collect();

    let checked = common::run_cog_gpu(&[base.as_slice(), &["--check"]].concat());
    let stdout = String::from_utf8_lossy(&checked.stdout);
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stderr));
    // a = ln 3 = 1.0986, b = 0 (to the fit's prior).
    assert!(
        stdout.contains("a = 1.098") && (stdout.contains("b = 0.000") || stdout.contains("b = -0.000")),
        "{stdout}"
    );
    assert!(stdout.contains("1 categories, 80 frames, 80 detections, 40 true positives"), "{stdout}");
    assert!(stdout.contains("(replaced)") && stdout.contains("nothing written"), "{stdout}");
    // The reliability bins before (40 detections at 0.269 with 10 true, 40 at 0.731 with 30) and after
    // (at 0.250 and 0.750).
    for bin in [
        ["[0.2,", "0.3)", "40", "10", "10.8", "0.269", "0.250"],
        ["[0.7,", "0.8)", "40", "30", "29.2", "0.731", "0.750"],
        ["[0.2,", "0.3)", "40", "10", "10.0", "0.250", "0.250"],
        ["[0.7,", "0.8)", "40", "30", "30.0", "0.750", "0.750"],
    ] {
        assert!(stdout.lines().any(|l| l.split_whitespace().collect::<Vec<_>>() == bin), "{bin:?}\n{stdout}");
    }
    assert!(!output.exists());
    assert!(!stdout.contains("desk"));

    // --final and --exclusion are two fits: asking for both is an error.
    let both = common::run_cog_gpu(&[base.as_slice(), &["--exclusion"]].concat());
    let stderr = String::from_utf8_lossy(&both.stderr);
    assert!(!both.status.success() && stderr.contains("cannot be used with"), "{stderr}");

    let written = common::run_cog_gpu(&[base.as_slice(), &["--out", output.to_str().unwrap()]].concat());
    assert!(written.status.success(), "{}", String::from_utf8_lossy(&written.stderr));
    let mapped = Cascade::read(&output).unwrap();
    let stored = mapped.final_calibration.clone().unwrap();
    let library = fit_final_calibration(&detections, &truth, &[], 0.25, data.to_str().unwrap()).unwrap();
    assert_eq!(stored, library.calibration);
    assert_eq!(Cascade { final_calibration: None, ..mapped }, cascade(None, None));

    // `rescore` with it: every score mapped, the score before it kept.
    let rescored = tmp.path().join("rescored");
    let args = ["rescore", "--detections", first.to_str().unwrap(), "--out", rescored.to_str().unwrap()];
    let out = common::run_cog_gpu(&[args.as_slice(), &["--cascade", output.to_str().unwrap()]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let file = FrameDetections::read(&rescored.join("t00.json")).unwrap();
    let table = file.detections.iter().find(|d| d.category == "table").unwrap();
    assert_eq!(table.score_before_final_calibration, Some(sigmoid(-1.0)));
    assert!((table.score - 0.25).abs() < 1e-3, "{}", table.score);

    // Fitting the exclusion again drops the map, and says so.
    let excluded = tmp.path().join("excluded.json");
    let args = ["calibrate", "--cascade", output.to_str().unwrap(), "--exclusion", "--data", data.to_str().unwrap()];
    let args: Vec<&str> = args
        .into_iter()
        .chain(["--detections", first.to_str().unwrap(), "--out", excluded.to_str().unwrap()])
        .collect();
    let out = common::run_cog_gpu(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("final calibration was fitted on the scores before"));
    assert_eq!(Cascade::read(&excluded).unwrap().final_calibration, None);
}
