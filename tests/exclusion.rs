//! Cross-category exclusion (`cog_gpu::exclusion`): the demotion against a hand computation, the fit on
//! constructed frames whose best parameters are known, the cascade file that carries it, and the CLI.

use std::process::Command;

mod common;

use cog_gpu::cascade::Cascade;
use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::exclusion::{competitors, fit_exclusion, Exclusion, IOU_GRID, WEIGHT_GRID};
use cog_gpu::frame::Object;
use cog_gpu::geometry::Cuboid;
use glam::Vec3;

fn detection(category: &str, centre: [f32; 3], size: [f32; 3], probability: f32) -> Detection {
    let mut d = Detection::new(category, &Cuboid::new(Vec3::from(centre), Vec3::from(size), 0.0), probability);
    d.raw_score = Some(probability.ln() - (1.0 - probability).ln());
    d
}

fn object(category: &str, centre: [f32; 3], size: [f32; 3]) -> Object {
    Object { category: category.into(), label: None, cuboid: Cuboid::new(Vec3::from(centre), Vec3::from(size), 0.0) }
}

/// A frame whose overlaps are known by hand: table T and desk D on the same unit box (IoU 1), a second
/// table T3 there too; a chair C shifted 0.95 m along x (overlap 0.05 m³, IoU 0.05 / 1.95 = 0.0256); far
/// away a table T2 with a pillow P inside it (0.4 × 0.4 × 0.2: IoU 0.032).
fn hand_frame() -> Vec<Detection> {
    vec![
        detection("table", [0.0, 0.0, 0.5], [1.0, 1.0, 1.0], 0.5), // T
        detection("desk", [0.0, 0.0, 0.5], [1.0, 1.0, 1.0], 0.8),  // D
        detection("table", [0.0, 0.0, 0.5], [1.0, 1.0, 1.0], 0.9), // T3
        detection("chair", [0.95, 0.0, 0.5], [1.0, 1.0, 1.0], 0.95), // C
        detection("table", [5.0, 0.0, 0.5], [1.0, 1.0, 1.0], 0.3), // T2
        detection("pillow", [5.0, 0.0, 0.3], [0.4, 0.4, 0.2], 0.9), // P
    ]
}

fn assert_demoted(d: &Detection, before: f32, competitor: f32, weight: f32, by: &str) {
    let want = before * (1.0 - weight * competitor);
    assert!((d.score - want).abs() < 1e-6, "{} score {} want {want}", d.category, d.score);
    assert_eq!(d.score_before_exclusion, Some(before), "{}", d.category);
    assert_eq!(d.excluded_by.as_deref(), Some(by), "{}", d.category);
}

fn assert_untouched(d: &Detection, score: f32) {
    assert_eq!(d.score, score, "{}", d.category);
    assert_eq!(d.score_before_exclusion, None, "{}", d.category);
    assert_eq!(d.excluded_by, None, "{}", d.category);
}

#[test]
fn exclusion_matches_a_hand_computation() {
    // IoU 0.05: only the boxes on the same unit box compete. T gives way to D (a table to a desk), D to T3
    // (a more confident table), T3 and C to nobody (nothing more confident overlaps them enough); T2's
    // pillow is inside it, but a pillow on a table is no confusion (IoU 0.032).
    let mut d = hand_frame();
    Exclusion { iou: 0.05, weight: 0.75 }.apply(&mut d);
    assert_demoted(&d[0], 0.5, 0.8, 0.75, "desk");
    assert_demoted(&d[1], 0.8, 0.9, 0.75, "table");
    assert_untouched(&d[2], 0.9);
    assert_untouched(&d[3], 0.95);
    assert_untouched(&d[4], 0.3);
    assert_untouched(&d[5], 0.9);

    // IoU 0.02: the chair's sliver (0.0256) and the pillow (0.032) count too; the most confident
    // competitor decides (the chair, 0.95, over the desk for T and over T3 for D).
    let mut d = hand_frame();
    Exclusion { iou: 0.02, weight: 0.75 }.apply(&mut d);
    assert_demoted(&d[0], 0.5, 0.95, 0.75, "chair");
    assert_demoted(&d[1], 0.8, 0.95, 0.75, "chair");
    assert_demoted(&d[2], 0.9, 0.95, 0.75, "chair");
    assert_untouched(&d[3], 0.95);
    assert_demoted(&d[4], 0.3, 0.9, 0.75, "pillow");
    assert_untouched(&d[5], 0.9);

    // The competitors' IoUs are the hand values.
    let c = competitors(&hand_frame(), 0.01);
    assert_eq!(c[0].len(), 2);
    assert!((c[0][0].iou - 1.0).abs() < 1e-5 && c[0][0].category == "desk");
    assert!((c[0][1].iou - 0.05 / 1.95).abs() < 1e-5 && c[0][1].category == "chair");
    assert!((c[4][0].iou - 0.032).abs() < 1e-5 && c[4][0].category == "pillow");

    // Weight 0 changes nothing; the result does not depend on the detections' order (every competitor is
    // read before anything is demoted).
    let mut d = hand_frame();
    Exclusion { iou: 0.02, weight: 0.0 }.apply(&mut d);
    assert_eq!(d, hand_frame());
    let mut forward = hand_frame();
    Exclusion { iou: 0.02, weight: 0.75 }.apply(&mut forward);
    let mut backward: Vec<Detection> = hand_frame().into_iter().rev().collect();
    Exclusion { iou: 0.02, weight: 0.75 }.apply(&mut backward);
    backward.reverse();
    assert_eq!(forward, backward);
}

#[test]
fn exclusion_parameters_are_checked() {
    assert!(Exclusion { iou: 0.05, weight: 1.0 }.check().is_ok());
    assert!(Exclusion { iou: 0.0, weight: 0.5 }.check().unwrap_err().contains("IoU 0"));
    assert!(Exclusion { iou: 1.5, weight: 0.5 }.check().is_err());
    assert!(Exclusion { iou: 0.1, weight: 1.5 }.check().unwrap_err().contains("weight 1.5"));
    assert!(Exclusion { iou: 0.1, weight: f32::NAN }.check().is_err());
}

/// `n` frames holding a desk, each with a confident desk detection and a less confident table on the same
/// box (a confusion), and `n` frames holding a table found with probability 0.4 and nothing else. The
/// tables' AP without exclusion: n false positives at 0.6 above n true ones at 0.4, so the precision only
/// rises, and the all-point interpolated AP is the final precision, 1/2.
fn confusion_frames(n: usize) -> (Vec<Vec<Detection>>, Vec<Vec<Object>>) {
    let unit = ([0.0, 0.0, 0.4], [1.2, 0.6, 0.8]);
    let mut detections = Vec::new();
    let mut truth = Vec::new();
    for _ in 0..n {
        detections.push(vec![detection("desk", unit.0, unit.1, 0.8), detection("table", unit.0, unit.1, 0.6)]);
        truth.push(vec![object("desk", unit.0, unit.1)]);
        detections.push(vec![detection("table", unit.0, unit.1, 0.4)]);
        truth.push(vec![object("table", unit.0, unit.1)]);
    }
    (detections, truth)
}

fn assert_aps(got: &[Option<f32>], want: &[f32]) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        assert!((g.unwrap() - w).abs() < 1e-6, "{got:?} want {want:?}");
    }
}

#[test]
fn the_fit_finds_the_smallest_exclusion_that_resolves_a_confusion() {
    let (detections, truth) = confusion_frames(10);
    let fit = fit_exclusion(&detections, &truth, &[], 0.25);
    assert_eq!(fit.categories, ["table", "desk"], "the categories with ground truth, in cog-gpu's order");
    assert_eq!(fit.trials.len(), 1 + (WEIGHT_GRID.len() - 1) * IOU_GRID.len());
    let without = fit.without();
    assert_eq!(without.exclusion.weight, 0.0);
    assert_aps(&without.aps, &[0.5, 1.0]);
    assert!((without.mean_ap.unwrap() - 0.75).abs() < 1e-6);
    // A table at 0.6 under a desk at 0.8 becomes 0.6 · (1 − w · 0.8): 0.48 (w = 0.25) still above the
    // true tables' 0.4, 0.36 (w = 0.5) below. Every IoU of the grid sees the boxes (IoU 1): the smallest
    // weight that sorts the tables, at the smallest IoU.
    for t in &fit.trials[1..] {
        let table = if t.exclusion.weight >= 0.5 { 1.0 } else { 0.5 };
        assert_aps(&t.aps, &[table, 1.0]);
    }
    assert_eq!(fit.chosen, Some(Exclusion { iou: IOU_GRID[0], weight: 0.5 }));
    assert!((fit.best().mean_ap.unwrap() - 1.0).abs() < 1e-6);
    // Applying the chosen exclusion to the frames gives the trial's numbers.
    let mut applied = detections.clone();
    for frame in &mut applied {
        fit.chosen.unwrap().apply(frame);
    }
    let refit = fit_exclusion(&applied, &truth, &["table".to_string()], 0.25);
    assert_aps(&refit.without().aps, &[1.0]);
}

#[test]
fn the_fit_chooses_no_exclusion_when_the_more_confident_category_is_wrong() {
    // Here the table under the desk is the true object and the desk the false positive; other frames hold a
    // lone false table at 0.45. Demoting the true tables below 0.45 only costs AP.
    let unit = ([0.0, 0.0, 0.4], [1.2, 0.6, 0.8]);
    let mut detections = Vec::new();
    let mut truth = Vec::new();
    for _ in 0..8 {
        detections.push(vec![detection("desk", unit.0, unit.1, 0.7), detection("table", unit.0, unit.1, 0.5)]);
        truth.push(vec![object("table", unit.0, unit.1)]);
        detections.push(vec![detection("table", unit.0, unit.1, 0.45)]);
        truth.push(vec![]);
    }
    let fit = fit_exclusion(&detections, &truth, &[], 0.25);
    assert_eq!(fit.categories, ["table"]);
    assert_aps(&fit.without().aps, &[1.0]);
    assert_eq!(fit.chosen, None);
    assert_eq!(fit.best(), fit.without());
}

fn cascade_without_stages(exclusion: Option<Exclusion>) -> Cascade {
    common::cascade_without_stages(exclusion, None)
}

#[test]
fn the_cascade_file_carries_the_exclusion_and_applies_it_after_its_stages() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("cascade.json");
    let exclusion = Exclusion { iou: 0.05, weight: 0.75 };
    let cascade = cascade_without_stages(Some(exclusion));
    cascade.write(&path).unwrap();
    assert_eq!(Cascade::read(&path).unwrap(), cascade);
    // A file without the field (every cascade before it) reads as no exclusion.
    let text = std::fs::read_to_string(&path).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json.as_object_mut().unwrap().remove("exclusion");
    std::fs::write(&path, json.to_string()).unwrap();
    assert_eq!(Cascade::read(&path).unwrap().exclusion, None);
    // Parameters out of range are refused, naming the file.
    json["exclusion"] = serde_json::json!({"iou": 0.05, "weight": 2.0});
    std::fs::write(&path, json.to_string()).unwrap();
    let err = Cascade::read(&path).unwrap_err().to_string();
    assert!(err.contains("cascade.json") && err.contains("weight 2"), "{err}");

    // Rescoring = the stages (none here), the exclusion, then best first.
    let mut rescored = hand_frame();
    cascade.rescore(&mut rescored, None).unwrap();
    let mut expected = hand_frame();
    exclusion.apply(&mut expected);
    expected.sort_by(|a, b| b.score.total_cmp(&a.score));
    assert_eq!(rescored, expected);
    let mut stages_only = hand_frame();
    cascade.rescore_stages(&mut stages_only, None).unwrap();
    assert!(stages_only.iter().all(|d| d.score_before_exclusion.is_none()));
    // Demoted detections are not first-stage ones: rescoring them again is refused.
    let err = cascade.rescore(&mut rescored, None).unwrap_err().to_string();
    assert!(err.contains("already rescored"), "{err}");
    // Cascades with different exclusions are not merged.
    let err = cascade.merged_with(&cascade_without_stages(None)).unwrap_err();
    assert!(err.contains("exclusion"), "{err}");
}

#[test]
fn cli_fits_the_exclusion_and_rescore_applies_it() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, first) = (tmp.path().join("data"), tmp.path().join("first"));
    std::fs::create_dir_all(&first).unwrap();
    let (detections, truth) = confusion_frames(6);
    for (f, (frame, objects)) in detections.iter().zip(&truth).enumerate() {
        let name = format!("c{f:02}");
        common::write_tiny_frame(&data, &name, objects.clone());
        FrameDetections { frame: name.clone(), detections: frame.clone() }
            .write(&first.join(format!("{name}.json")))
            .unwrap();
    }
    let (input, output) = (tmp.path().join("cascade.json"), tmp.path().join("excluding.json"));
    cascade_without_stages(None).write(&input).unwrap();
    let run = |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(args).output().unwrap();
    let base = ["calibrate", "--cascade", input.to_str().unwrap(), "--exclusion", "--data", data.to_str().unwrap()];
    let base: Vec<&str> = base.into_iter().chain(["--detections", first.to_str().unwrap()]).collect();

    let checked = run(&[base.as_slice(), &["--check"]].concat());
    let stdout = String::from_utf8_lossy(&checked.stdout);
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stderr));
    assert!(stdout.contains("without: 75.00"), "{stdout}");
    // The grid's row for weight 0.25 (tables still above) and for 0.5 (sorted), every IoU alike.
    assert!(
        stdout
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>() == ["0.25", "75.00", "75.00", "75.00", "75.00", "75.00"]),
        "{stdout}"
    );
    assert!(
        stdout
            .lines()
            .any(|l| l.split_whitespace().collect::<Vec<_>>()
                == ["0.5", "100.00", "100.00", "100.00", "100.00", "100.00"]),
        "{stdout}"
    );
    assert!(stdout.lines().any(|l| l.split_whitespace().collect::<Vec<_>>() == ["table", "50.0", "100.0"]), "{stdout}");
    assert!(stdout.contains("chosen: IoU 0.02, weight 0.5") && stdout.contains("nothing written"), "{stdout}");
    assert!(!output.exists());

    // An unknown category, and categories without ground truth in the frames: errors, nothing written.
    for (categories, message) in [("tabel", "'tabel' is not one of"), ("bed,sofa", "no ground-truth box of bed, sofa")]
    {
        let out = run(&[base.as_slice(), &["--out", output.to_str().unwrap(), "--categories", categories]].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains(message), "{stderr}");
        assert!(!output.exists());
    }

    let written = run(&[base.as_slice(), &["--out", output.to_str().unwrap()]].concat());
    assert!(written.status.success(), "{}", String::from_utf8_lossy(&written.stderr));
    let excluding = Cascade::read(&output).unwrap();
    assert_eq!(excluding, cascade_without_stages(Some(Exclusion { iou: 0.02, weight: 0.5 })));
    assert_eq!(Cascade::read(&input).unwrap(), cascade_without_stages(None), "the input is left as it was");

    // `rescore` with it: the confused table's file says what demoted it and by how much.
    let rescored = tmp.path().join("rescored");
    let out = run(&[
        "rescore",
        "--detections",
        first.to_str().unwrap(),
        "--out",
        rescored.to_str().unwrap(),
        "--cascade",
        output.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let file = FrameDetections::read(&rescored.join("c00.json")).unwrap();
    let table = file.detections.iter().find(|d| d.category == "table").unwrap();
    assert_eq!(table.score_before_exclusion, Some(0.6));
    assert_eq!(table.excluded_by.as_deref(), Some("desk"));
    assert!((table.score - 0.6 * (1.0 - 0.5 * 0.8)).abs() < 1e-6);
    assert_eq!(file.detections[0].category, "desk", "best first after the exclusion");
}
