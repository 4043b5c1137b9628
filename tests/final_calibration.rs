//! The cascade's final calibration (`cog_gpu::calibration`, "The cascade's final calibration"): the map
//! against hand values, the fit on constructed frames whose best map is known in closed form, the cascade
//! file that carries it, and the CLI (`calibrate --cascade --final`, then `rescore`).

mod common;

use cog_gpu::calibration::final_calibration::{
    fit_features, fit_final_calibration, FinalCalibration, FIT_MAX_SCORE, FIT_MIN_SCORE,
};
use cog_gpu::calibration::MIN_SLOPE;
use cog_gpu::cascade::Cascade;
use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::exclusion::Exclusion;
use cog_gpu::frame::Object;
use cog_gpu::geometry::Cuboid;
use glam::Vec3;

fn map(a: f64, b: f64, c: f64) -> FinalCalibration {
    FinalCalibration { a, b, c, detections: 0, true_positives: 0, iou: 0.25, data: String::new(), frames: 0 }
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
    // logit p' = a·ln p − b·ln(1 − p) + c. With a = b it is a map of the log-odds: a = b = 1, c = ln 2
    // doubles the odds (1/2 → 2/3, 1/3 → 1/2), a = b = 2 squares them (1/3, odds 1/2 → odds 1/4: 1/5).
    let close = |got: f32, want: f64| (f64::from(got) - want).abs() < 1e-7;
    let double = map(1.0, 1.0, 2f64.ln());
    assert!(close(double.recalibrate(0.5), 2.0 / 3.0) && close(double.recalibrate(1.0 / 3.0), 0.5));
    assert!(close(map(2.0, 2.0, 0.0).recalibrate(1.0 / 3.0), 0.2));
    // a ≠ b: a = 2, b = 1 gives 1/2 the log-odds 2·ln ½ − ln ½ = −ln 2 (1/3), and 1/3 the log-odds
    // 2·ln ⅓ − ln ⅔ = ln ⅙ (1/7).
    let skewed = map(2.0, 1.0, 0.0);
    assert!(close(skewed.recalibrate(0.5), 1.0 / 3.0) && close(skewed.recalibrate(1.0 / 3.0), 1.0 / 7.0));
    // The identity map gives every score back (to the f32 it came from).
    let identity = map(1.0, 1.0, 0.0);
    for p in [1e-30f32, 1e-6, 0.01, 0.3, 0.5, 0.77, 0.999, 1.0 - 6e-8] {
        assert_eq!(identity.recalibrate(p), p, "{p}");
    }
    // 0 and 1 stay; the map never puts a lower score above a higher one.
    for calibration in [map(0.5, 0.5, 0.4), map(1.17, 0.37, 1.2), map(2.0, 0.1, -1.0), map(MIN_SLOPE, 3.0, 3.0)] {
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
    // A fit reads 0 and 1 as the f32 rounding boundaries 2⁻¹⁵⁰ and 1 − 2⁻²⁵: finite terms.
    assert_eq!((FIT_MIN_SCORE, FIT_MAX_SCORE), (2f64.powi(-150), 1.0 - 2f64.powi(-25)));
    assert_eq!(fit_features(0.0), [FIT_MIN_SCORE.ln(), -(-FIT_MIN_SCORE).ln_1p()]);
    assert_eq!(fit_features(1.0), [FIT_MAX_SCORE.ln(), 25.0 * 2f64.ln()]);
    assert_eq!(fit_features(0.25), [0.25f64.ln(), -(0.75f64.ln())]);
}

/// 120 frames of one table each, with one table detection each: 40 at score 0.2, 10 of them on their
/// frame's table (true positives), 40 at 0.5 with `hits[1]` true, 40 at 0.8 with `hits[2]` true; plus in
/// every frame a desk detection (no desk is annotated).
fn three_level_frames(hits: [usize; 3]) -> (Vec<Vec<Detection>>, Vec<Vec<Object>>) {
    let levels = [0.2f32, 0.5, 0.8];
    let mut detections = Vec::new();
    let mut truth = Vec::new();
    for f in 0..120 {
        let (level, n) = (f / 40, f % 40);
        let x = if n < hits[level] { 0.0 } else { 5.0 };
        detections.push(vec![detection("table", x, levels[level]), detection("desk", 2.0, 0.9)]);
        truth.push(vec![Object { category: "table".into(), label: None, cuboid: unit_box(0.0) }]);
    }
    (detections, truth)
}

/// The map through three points: `(a, b, c)` with `a·ln pᵢ − b·ln(1 − pᵢ) + c = logit qᵢ`, by Cramer's rule.
fn through(points: [(f64, f64); 3]) -> [f64; 3] {
    let rows = points.map(|(p, _)| [p.ln(), -(1.0 - p).ln(), 1.0]);
    let rhs = points.map(|(_, q)| (q / (1.0 - q)).ln());
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    [0, 1, 2].map(|k| {
        let mut m = rows;
        for i in 0..3 {
            m[i][k] = rhs[i];
        }
        det(m) / det(rows)
    })
}

#[test]
fn the_fit_recovers_the_map_through_the_frequencies() {
    // Three score levels right 10, 24 and 36 times in 40: three parameters fit three frequencies exactly
    // (up to the fit's weak prior), so the map is the one through (0.2, 1/4), (0.5, 3/5), (0.8, 9/10):
    // a = 0.866, b = 1.511, c = −0.041 — both slopes positive, and unequal (no map of the log-odds fits).
    let (detections, truth) = three_level_frames([10, 24, 36]);
    let fit = fit_final_calibration(&detections, &truth, &[], 0.25, "three levels", None).unwrap();
    // Default categories: those with ground truth (the table), so the desk's false detections are not seen.
    assert_eq!(fit.categories, ["table"]);
    let c = &fit.calibration;
    let want = through([(0.2, 0.25), (0.5, 0.6), (0.8, 0.9)]);
    assert!((want[0] - 0.866).abs() < 1e-3 && (want[1] - 1.511).abs() < 1e-3 && (want[2] + 0.041).abs() < 1e-3);
    for (got, want) in [c.a, c.b, c.c].into_iter().zip(want) {
        assert!((got - want).abs() < 5e-3, "{:?} against {want:?}", [c.a, c.b, c.c]);
    }
    for (p, q) in [(0.2, 0.25), (0.5, 0.6), (0.8, 0.9)] {
        assert!((f64::from(c.recalibrate(p)) - q).abs() < 1e-3, "{p} → {}", c.recalibrate(p));
    }
    assert_eq!((c.detections, c.true_positives, c.frames), (120, 70, 120));
    assert_eq!(c.data, "three levels");
    // Before: the scores expect 8 + 20 + 32 = 60 true positives; the fit's probabilities expect the 70
    // found, and lose less (log losses by hand).
    assert!((fit.before.expected_true_positives - 60.0).abs() < 1e-4);
    assert!((fit.after.expected_true_positives - 70.0).abs() < 0.05);
    let loss = |p: f64, hits: f64| -(hits * p.ln() + (40.0 - hits) * (1.0 - p).ln());
    let before = (loss(0.2, 10.0) + loss(0.5, 24.0) + loss(0.8, 36.0)) / 120.0;
    let after = (loss(0.25, 10.0) + loss(0.6, 24.0) + loss(0.9, 36.0)) / 120.0;
    assert!((fit.before.log_loss - before).abs() < 1e-6 && (fit.after.log_loss - after).abs() < 1e-4);

    // Frequencies 1/4, 1/2, 9/10: the map through them has a = −0.042 < 0 (a higher score, a lower
    // probability near 0): a is held at the minimum slope and b, c refitted, so the map stays increasing.
    let unconstrained = through([(0.2, 0.25), (0.5, 0.5), (0.8, 0.9)]);
    assert!(unconstrained[0] < 0.0);
    let (detections, truth) = three_level_frames([10, 20, 36]);
    let held = fit_final_calibration(&detections, &truth, &[], 0.25, "", None).unwrap().calibration;
    assert_eq!(held.a, MIN_SLOPE);
    assert!(
        held.b > 1.0 && held.recalibrate(0.2) < held.recalibrate(0.5) && held.recalibrate(0.5) < held.recalibrate(0.8)
    );

    // With the desk among the categories, its 120 false detections at 0.9 count: the fit moves.
    let (detections, truth) = three_level_frames([10, 24, 36]);
    let with_desk =
        fit_final_calibration(&detections, &truth, &["table".into(), "desk".into()], 0.25, "", None).unwrap();
    assert_eq!(with_desk.calibration.detections, 240);
    assert!(with_desk.calibration.recalibrate(0.9) < 0.5);
    // Only true or only false positives: no map, an error that says so.
    let err = fit_final_calibration(&detections, &truth, &["desk".into()], 0.25, "", None).unwrap_err().to_string();
    assert!(err.contains("final calibration") && err.contains("0 true"), "{err}");
}

fn cascade(exclusion: Option<Exclusion>, final_calibration: Option<FinalCalibration>) -> Cascade {
    common::cascade_without_stages(exclusion, final_calibration)
}

#[test]
fn the_cascade_file_carries_the_map_and_applies_it_last() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cascade.json");
    let exclusion = Exclusion { iou: 0.05, weight: 0.5 };
    let with_map = cascade(Some(exclusion), Some(map(1.0, 1.0, 2f64.ln())));
    with_map.write(&path).unwrap();
    assert_eq!(Cascade::read(&path).unwrap(), with_map);
    // A file without the field (every cascade before it) reads as no final calibration.
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    json.as_object_mut().unwrap().remove("final_calibration");
    std::fs::write(&path, json.to_string()).unwrap();
    assert_eq!(Cascade::read(&path).unwrap().final_calibration, None);
    // A slope ≤ 0 would reorder the detections: refused, naming the file.
    for (a, b) in [(-1.0, 1.0), (1.0, 0.0)] {
        json["final_calibration"] = serde_json::to_value(map(a, b, 0.0)).unwrap();
        std::fs::write(&path, json.to_string()).unwrap();
        let err = Cascade::read(&path).unwrap_err().to_string();
        assert!(err.contains("cascade.json") && err.contains("final calibration slopes"), "{err}");
    }

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
    let (detections, truth) = three_level_frames([10, 24, 36]);
    for (f, (frame, objects)) in detections.iter().zip(&truth).enumerate() {
        let name = format!("t{f:03}");
        common::write_tiny_frame(&data, &name, objects.clone());
        FrameDetections { frame: name.clone(), detections: frame.clone() }
            .write(&first.join(format!("{name}.json")))
            .unwrap();
    }
    let (input, output) = (tmp.path().join("cascade.json"), tmp.path().join("mapped.json"));
    // The input's own map is replaced, not composed with: the fit reads the scores before it.
    cascade(None, Some(map(5.0, 5.0, 5.0))).write(&input).unwrap();
    let base = ["calibrate", "--cascade", input.to_str().unwrap(), "--final", "--data", data.to_str().unwrap()];
    let base: Vec<&str> = base.into_iter().chain(["--detections", first.to_str().unwrap()]).collect();

    let checked = common::run_cog_gpu(&[base.as_slice(), &["--check"]].concat());
    let stdout = String::from_utf8_lossy(&checked.stdout);
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stderr));
    // The map through the frequencies (the_fit_recovers_the_map_through_the_frequencies): a = 0.866,
    // b = 1.511, c = −0.041, to the fit's prior.
    for number in ["a = 0.86", "b = 1.51", "c = -0.04"] {
        assert!(stdout.contains(number), "{number}: {stdout}");
    }
    assert!(stdout.contains("1 categories, 120 frames, 120 detections, 70 true positives"), "{stdout}");
    assert!(stdout.contains("nothing written"), "{stdout}");
    // The file's own map, summarised on the same detections: logit p' = 5·logit p + 5 puts 0.2 at
    // σ(5·ln ¼ + 5) = 0.127 and the other two levels above 0.99; the expected true positives and the mean
    // log loss by hand.
    let stored = |p: f64| 1.0 / (1.0 + (-(5.0 * (p / (1.0 - p)).ln() + 5.0)).exp());
    let levels = [(0.2f32, 10.0), (0.5, 24.0), (0.8, 36.0)];
    let expected: f64 = levels.iter().map(|&(p, _)| 40.0 * stored(f64::from(p))).sum();
    let loss: f64 = levels
        .iter()
        .map(|&(p, hits)| {
            let q = stored(f64::from(p)).clamp(1e-6, 1.0 - 1e-6);
            -(hits * q.ln() + (40.0 - hits) * (1.0 - q).ln())
        })
        .sum::<f64>()
        / 120.0;
    // (The map's f32 output near 1 moves the loss in the fourth decimal.)
    let line = stdout
        .lines()
        .find(|l| l.starts_with("the file's map (a = 5.0000, b = 5.0000, c = 5.0000):"))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(line.ends_with(&format!("expected true positives {expected:.1}")), "{expected}: {line}");
    let printed: f64 = line.split("mean log loss ").nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
    assert!((printed - loss).abs() < 1e-3, "{loss}: {line}");
    // The reliability bins before (40 detections each at 0.2, 0.5 and 0.8, with 10, 24 and 36 true) and
    // after (at 0.25, 0.6 and 0.9: the last on the edge of two bins, so its bin is not asserted).
    let rows: Vec<Vec<&str>> = stdout.lines().map(|l| l.split_whitespace().collect()).collect();
    for bin in [
        ["[0.2,", "0.3)", "40", "10", "8.0", "0.200", "0.250"],
        ["[0.5,", "0.6)", "40", "24", "20.0", "0.500", "0.600"],
        ["[0.8,", "0.9)", "40", "36", "32.0", "0.800", "0.900"],
        ["[0.2,", "0.3)", "40", "10", "10.0", "0.250", "0.250"],
        ["[0.6,", "0.7)", "40", "24", "24.0", "0.600", "0.600"],
        ["[0.1,", "0.2)", "40", "10", "5.1", "0.127", "0.250"],
    ] {
        assert!(rows.iter().any(|r| r == &bin), "{bin:?}\n{stdout}");
    }
    assert!(rows.iter().any(|r| r.len() == 7 && r[2..] == ["40", "36", "36.0", "0.900", "0.900"]), "{stdout}");
    assert!(!output.exists());
    assert!(!stdout.contains("desk"));

    // --final and --exclusion are two fits: asking for both is an error.
    let both = common::run_cog_gpu(&[base.as_slice(), &["--exclusion"]].concat());
    let stderr = String::from_utf8_lossy(&both.stderr);
    assert!(!both.status.success() && stderr.contains("cannot be used with"), "{stderr}");

    let written = common::run_cog_gpu(&[base.as_slice(), &["--out", output.to_str().unwrap()]].concat());
    assert!(written.status.success(), "{}", String::from_utf8_lossy(&written.stderr));
    assert!(String::from_utf8_lossy(&written.stdout).contains("(the map it had replaced)"));
    let mapped = Cascade::read(&output).unwrap();
    let stored = mapped.final_calibration.clone().unwrap();
    let library = fit_final_calibration(&detections, &truth, &[], 0.25, data.to_str().unwrap(), None).unwrap();
    assert_eq!(stored, library.calibration);
    assert_eq!(Cascade { final_calibration: None, ..mapped }, cascade(None, None));

    // `rescore` with it: every score mapped, the score before it kept.
    let rescored = tmp.path().join("rescored");
    let args = ["rescore", "--detections", first.to_str().unwrap(), "--out", rescored.to_str().unwrap()];
    let out = common::run_cog_gpu(&[args.as_slice(), &["--cascade", output.to_str().unwrap()]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let file = FrameDetections::read(&rescored.join("t000.json")).unwrap();
    let table = file.detections.iter().find(|d| d.category == "table").unwrap();
    assert_eq!(table.score_before_final_calibration, Some(0.2));
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
