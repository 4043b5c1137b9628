//! Average precision with the SUN RGB-D benchmark's rules, against APs computed by hand.

use cog_gpu::eval::{average_precision, interpolated_ap, mean_ap, Detection, FrameDetections, ScoredBox};
use cog_gpu::geometry::Cuboid;
use glam::Vec3;

fn unit_box(x: f32, y: f32) -> Cuboid {
    Cuboid::new(Vec3::new(x, y, 0.5), Vec3::ONE, 0.0)
}

fn det(image: usize, score: f32, cuboid: Cuboid) -> ScoredBox {
    ScoredBox { image, score, cuboid }
}

#[test]
fn duplicates_and_misses_by_hand() {
    // Image 0 holds A at x = 0 and B at x = 5. Detections by score: A (TP), A again (duplicate: FP),
    // nothing (FP), B (TP). Precision 1, 1/2, 1/3, 1/2; recall 1/2, 1/2, 1/2, 1.
    // Interpolated precision 1, 1/2, 1/2, 1/2 → AP = 1/2·1 + 1/2·1/2 = 0.75.
    let truth = vec![vec![unit_box(0.0, 0.0), unit_box(5.0, 0.0)]];
    let dets = [
        det(0, 0.8, unit_box(0.0, 0.0)),
        det(0, 0.9, unit_box(0.0, 0.0)),
        det(0, 0.6, unit_box(5.0, 0.0)),
        det(0, 0.7, unit_box(20.0, 0.0)),
    ];
    let pr = average_precision(&dets, &truth, 0.25);
    assert_eq!(pr.true_positive, [true, false, false, true]);
    assert_eq!(pr.positives, 2);
    assert!((pr.ap.unwrap() - 0.75).abs() < 1e-6, "{:?}", pr.ap);
}

#[test]
fn iou_threshold_decides() {
    // A unit box shifted by half its width: IoU = 0.5 / 1.5 = 1/3.
    let truth = vec![vec![unit_box(0.0, 0.0)]];
    let dets = [det(0, 1.0, unit_box(0.5, 0.0))];
    assert_eq!(average_precision(&dets, &truth, 0.25).ap, Some(1.0));
    assert_eq!(average_precision(&dets, &truth, 0.5).ap, Some(0.0));
}

#[test]
fn detections_only_match_their_own_image() {
    let truth = vec![vec![unit_box(0.0, 0.0)], vec![]];
    // The higher-scoring detection sits on the box's place but in image 1, which has no ground truth.
    let dets = [det(1, 0.9, unit_box(0.0, 0.0)), det(0, 0.5, unit_box(0.0, 0.0))];
    let pr = average_precision(&dets, &truth, 0.25);
    assert_eq!(pr.true_positive, [false, true]);
    // Precision 0, 1/2; recall 0, 1 → AP = 1 · 1/2.
    assert!((pr.ap.unwrap() - 0.5).abs() < 1e-6);
}

#[test]
fn all_point_interpolation_by_hand() {
    // TP, FP, TP, FP, TP with 3 positives: precision 1, .5, 2/3, .5, .6; recall 1/3, 1/3, 2/3, 2/3, 1.
    // Envelope 1, 2/3, 2/3, .6, .6 → AP = 1/3·1 + 1/3·2/3 + 1/3·.6 = 0.755 555…
    // (11-point interpolation would give (4·1 + 3·2/3 + 4·.6)/11 = 0.7636: this must not be it.)
    let precision = [1.0, 0.5, 2.0 / 3.0, 0.5, 0.6];
    let recall = [1.0 / 3.0, 1.0 / 3.0, 2.0 / 3.0, 2.0 / 3.0, 1.0];
    assert!((interpolated_ap(&precision, &recall) - 0.755_555_6).abs() < 1e-6);
}

#[test]
fn empty_cases_and_the_mean() {
    let truth = vec![vec![unit_box(0.0, 0.0)]];
    assert_eq!(average_precision(&[], &truth, 0.25).ap, Some(0.0));
    assert_eq!(average_precision(&[det(0, 1.0, unit_box(0.0, 0.0))], &[vec![]], 0.25).ap, None);
    assert_eq!(mean_ap(&[Some(0.5), None, Some(1.0)]), Some(0.75));
    assert_eq!(mean_ap(&[None]), None);
}

#[test]
fn detections_file_round_trip_and_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frame.json");
    let file = FrameDetections {
        frame: "synth-000001".into(),
        detections: vec![Detection::new(
            "bed",
            &Cuboid::new(Vec3::new(1.0, 2.0, -0.8), Vec3::new(1.6, 2.0, 0.5), 0.25),
            1.5,
        )],
    };
    file.write(&path).unwrap();
    assert_eq!(FrameDetections::read(&path).unwrap(), file);
    std::fs::write(&path, r#"{"frame": "x", "detections": [{"category": "bed", "centre": [0, 0, 0], "size": [1, 0, 1], "yaw": 0, "score": 1}]}"#).unwrap();
    let err = FrameDetections::read(&path).unwrap_err().to_string();
    assert!(err.contains("frame.json") && err.contains("non-positive size"), "{err}");
    std::fs::write(&path, r#"{"frame": "x"}"#).unwrap();
    let err = FrameDetections::read(&path).unwrap_err().to_string();
    assert!(err.contains("frame.json") && err.contains("detections"), "{err}");
}

// ---------------------------------------------------------------------------------------------------------
// Bootstrap intervals

use cog_gpu::eval::{bootstrap_aps, bootstrap_frames, evaluate_categories, percentile_interval, Bootstrap};
use cog_gpu::frame::Object;

fn object(category: &str, cuboid: Cuboid) -> Object {
    Object { category: category.into(), label: None, cuboid }
}

/// Six frames with one bed each; the detections hit the bed in frames 0, 2 and 4 (scores 0.9, 0.7, 0.5)
/// and miss it in frames 1, 3 and 5 (scores 0.8, 0.6, 0.4), so the resamples' APs differ.
fn six_frames() -> (Vec<Vec<Object>>, Vec<Vec<Detection>>) {
    let truth: Vec<Vec<Object>> = (0..6).map(|_| vec![object("bed", unit_box(0.0, 0.0))]).collect();
    let detections = (0..6)
        .map(|f| {
            let place = if f % 2 == 0 { unit_box(0.0, 0.0) } else { unit_box(9.0, 0.0) };
            vec![Detection::new("bed", &place, 0.9 - 0.1 * f as f32)]
        })
        .collect();
    (truth, detections)
}

#[test]
fn percentile_interval_by_hand() {
    // Sorted 1..=11: the 5 % quantile sits at position 0.05·10 = 0.5 → 1.5; the 95 % at 9.5 → 10.5.
    let values: Vec<f32> = [7, 3, 11, 1, 9, 5, 2, 10, 4, 8, 6].iter().map(|&v| v as f32).collect();
    let (lo, hi) = percentile_interval(&values, 0.9).unwrap();
    assert!((lo - 1.5).abs() < 1e-6 && (hi - 10.5).abs() < 1e-6, "{lo} {hi}");
    // Level 0 is the median from both sides; one value is its own interval; none has none.
    assert_eq!(percentile_interval(&values, 0.0), Some((6.0, 6.0)));
    assert_eq!(percentile_interval(&[2.5], 0.9), Some((2.5, 2.5)));
    assert_eq!(percentile_interval(&[], 0.9), None);
}

#[test]
fn bootstrap_draws_are_reproducible_and_uniform() {
    let settings = Bootstrap { resamples: 2000, seed: 7 };
    let draws = bootstrap_frames(5, settings);
    assert_eq!(draws, bootstrap_frames(5, settings));
    assert_ne!(draws, bootstrap_frames(5, Bootstrap { seed: 8, ..settings }));
    assert!(draws.iter().all(|d| d.len() == 5 && d.iter().all(|&f| f < 5)));
    // Each frame is drawn with probability 1/5: 2 000 · 5 / 5 = 2 000 times, binomial sd ≈ 40.
    for frame in 0..5 {
        let count = draws.iter().flatten().filter(|&&f| f == frame).count();
        assert!((1800..=2200).contains(&count), "frame {frame} drawn {count} times");
    }
}

#[test]
fn each_resample_is_the_ap_of_its_drawn_frames() {
    // Reference: the dataset made of the drawn frames, copied, evaluated by evaluate_categories.
    let (truth, detections) = six_frames();
    let categories = vec!["bed".to_string(), "chair".to_string()];
    let settings = Bootstrap { resamples: 40, seed: 3 };
    let aps = bootstrap_aps(&truth, &[&detections], &categories, 0.25, settings);
    let draws = bootstrap_frames(truth.len(), settings);
    let mut distinct = std::collections::BTreeSet::new();
    for (draw, resample) in draws.iter().zip(&aps[0]) {
        let drawn_truth: Vec<Vec<Object>> = draw.iter().map(|&f| truth[f].clone()).collect();
        let drawn_detections: Vec<Vec<Detection>> = draw.iter().map(|&f| detections[f].clone()).collect();
        let reference = evaluate_categories(&drawn_truth, &drawn_detections, &categories, 0.25);
        assert_eq!(resample[0], reference[0].pr.ap);
        // No chair anywhere: never an AP.
        assert_eq!(resample[1], None);
        distinct.insert(resample[0].unwrap().to_bits());
    }
    assert!(distinct.len() > 3, "the resamples should not all agree: {distinct:?}");
}

#[test]
fn identical_frames_give_a_point_interval_and_paired_differences_cancel() {
    // Every frame the same (a hit at 0.9, a miss at 0.8 in a frame with two beds): every resample has
    // the full set's AP, so the interval is that point.
    let frame_truth = vec![object("bed", unit_box(0.0, 0.0)), object("bed", unit_box(5.0, 0.0))];
    let frame_dets =
        vec![Detection::new("bed", &unit_box(0.0, 0.0), 0.9), Detection::new("bed", &unit_box(9.0, 0.0), 0.8)];
    let truth = vec![frame_truth; 8];
    let detections = vec![frame_dets; 8];
    let categories = vec!["bed".to_string()];
    let full = evaluate_categories(&truth, &detections, &categories, 0.25)[0].pr.ap.unwrap();
    let aps =
        bootstrap_aps(&truth, &[&detections, &detections], &categories, 0.25, Bootstrap { resamples: 50, seed: 1 });
    let values: Vec<f32> = aps[0].iter().map(|r| r[0].unwrap()).collect();
    let (lo, hi) = percentile_interval(&values, 0.9).unwrap();
    assert!((lo - full).abs() < 1e-6 && (hi - full).abs() < 1e-6, "{lo} {hi} vs {full}");
    // The same detections on the same resamples: paired differences are exactly 0.
    assert!(aps[0].iter().zip(&aps[1]).all(|(a, b)| a == b));
    // The other way round, the six-frame set's interval must hold its own AP and be wider than a point.
    let (truth, detections) = six_frames();
    let aps = bootstrap_aps(&truth, &[&detections], &categories, 0.25, Bootstrap { resamples: 500, seed: 2 });
    let values: Vec<f32> = aps[0].iter().map(|r| r[0].unwrap()).collect();
    let (lo, hi) = percentile_interval(&values, 0.9).unwrap();
    let full = evaluate_categories(&truth, &detections, &categories, 0.25)[0].pr.ap.unwrap();
    assert!(lo < full && full < hi, "{lo} < {full} < {hi}");
}

/// `MatchedDetections::resampled_ap` is `average_precision` of the data set made of the drawn frames (each
/// as often as drawn), with no matching redone: frames with several boxes, duplicates, misses, a frame
/// without ground truth, every score distinct.
#[test]
fn a_resampled_ap_is_the_ap_of_the_drawn_frames() {
    use cog_gpu::eval::MatchedDetections;
    let truth: Vec<Vec<Cuboid>> = (0..7).map(|f| (0..f % 3).map(|b| unit_box(4.0 * b as f32, 0.0)).collect()).collect();
    let mut detections = Vec::new();
    for (f, boxes) in truth.iter().enumerate() {
        for d in 0..3 {
            // On box d when the frame has it (detection 2 duplicates box 0), on empty floor otherwise.
            let x = if d < boxes.len() {
                4.0 * d as f32
            } else if d == 2 {
                0.0
            } else {
                30.0 + f as f32
            };
            detections.push(det(
                f,
                ((f * 5 + d * 11) % 23) as f32 / 23.0 + 0.001 * (3 * f + d) as f32,
                unit_box(x, 0.0),
            ));
        }
    }
    let matched = MatchedDetections::new(&detections, &truth, 0.25);
    assert_eq!(matched.resampled_ap(&[1; 7]), average_precision(&detections, &truth, 0.25).ap);
    let mut distinct = std::collections::BTreeSet::new();
    for draw in bootstrap_frames(7, Bootstrap { resamples: 60, seed: 11 }) {
        let mut counts = [0u32; 7];
        let mut drawn_truth = Vec::new();
        let mut drawn = Vec::new();
        for (image, &f) in draw.iter().enumerate() {
            counts[f] += 1;
            drawn_truth.push(truth[f].clone());
            drawn.extend(detections.iter().filter(|d| d.image == f).map(|d| ScoredBox { image, ..*d }));
        }
        let want = average_precision(&drawn, &drawn_truth, 0.25).ap;
        assert_eq!(matched.resampled_ap(&counts), want, "{draw:?}");
        distinct.extend(want.map(f32::to_bits));
    }
    assert!(distinct.len() > 5, "the resamples should differ: {distinct:?}");
    // Only frames without ground truth: no AP.
    assert_eq!(matched.resampled_ap(&[2, 0, 0, 1, 0, 0, 0]), None);
}

/// The support-surface report: true positives only (the benchmark's matching), the distance to the nearest
/// and to the main true surface, and the median, on a hand-made case.
#[test]
fn surface_accuracy_by_hand() {
    use cog_gpu::eval::surface_accuracy;
    use cog_gpu::frame::Object;
    let object = |x: f32| Object { category: "table".into(), label: None, cuboid: unit_box(x, 0.0) };
    // Image 0: two tables (surfaces 0.75 main and 0.30 shelf; 0.70), a chair; image 1: one table (no
    // support data).
    let truth = vec![
        vec![object(0.0), Object { category: "chair".into(), label: None, cuboid: unit_box(9.0, 0.0) }, object(5.0)],
        vec![object(0.0)],
    ];
    let supports = vec![vec![vec![0.75, 0.30], vec![0.4], vec![0.70]], vec![]];
    let with = |x: f32, score: f32, z: Option<f32>| {
        let mut d = Detection::new("table", &unit_box(x, 0.0), score);
        d.surface_z = z;
        d
    };
    let detections = vec![
        vec![
            with(0.0, 0.9, Some(0.32)), // TP on table 0: nearest 0.30 (2 cm), main 0.75 (43 cm)
            with(0.0, 0.8, Some(0.75)), // duplicate: FP, not measured
            with(5.0, 0.7, Some(0.80)), // TP on the 0.70 table: 10 cm
            with(20.0, 0.6, Some(0.5)), // FP
        ],
        vec![with(0.0, 0.5, Some(0.7))], // TP, but no true surface known
    ];
    let s = surface_accuracy(&truth, &supports, &detections, "table", 0.25, 0.05);
    assert_eq!((s.true_positives, s.measured), (3, 2));
    assert_eq!((s.within_nearest, s.within_main), (1, 0));
    // Errors 0.02 and 0.10: the median of two is the upper one (index len / 2).
    assert!((s.median_error_m.unwrap() - 0.10).abs() < 1e-6);
}

/// The pooled report of several categories: the hand-made tables above and a desk in image 1 (true surface
/// 0.72, inferred 0.73) sum their counts, and the median runs over all three errors (0.02, 0.10, 0.01 → the
/// upper median 0.02), not over the categories' medians (0.10 and 0.01).
#[test]
fn pooled_surface_accuracy_by_hand() {
    use cog_gpu::eval::{surface_accuracy, SurfaceAccuracy};
    use cog_gpu::frame::Object;
    let object = |category: &str, x: f32| Object { category: category.into(), label: None, cuboid: unit_box(x, 0.0) };
    let truth = vec![vec![object("table", 0.0), object("table", 5.0)], vec![object("table", 0.0), object("desk", 3.0)]];
    let supports = vec![vec![vec![0.75, 0.30], vec![0.70]], vec![vec![], vec![0.72]]];
    let with = |category: &str, x: f32, score: f32, z: Option<f32>| {
        let mut d = Detection::new(category, &unit_box(x, 0.0), score);
        d.surface_z = z;
        d
    };
    let detections = vec![
        vec![with("table", 0.0, 0.9, Some(0.32)), with("table", 5.0, 0.7, Some(0.80))],
        vec![with("table", 0.0, 0.5, Some(0.7)), with("desk", 3.0, 0.4, Some(0.73)), with("desk", 9.0, 0.3, Some(0.1))],
    ];
    let desk = surface_accuracy(&truth, &supports, &detections, "desk", 0.25, 0.05);
    assert_eq!((desk.true_positives, desk.measured, desk.within_nearest, desk.within_main), (1, 1, 1, 1));
    assert!((desk.errors_m[0] - 0.01).abs() < 1e-6);
    let table = surface_accuracy(&truth, &supports, &detections, "table", 0.25, 0.05);
    let all = SurfaceAccuracy::pooled(&[table, desk]);
    assert_eq!((all.category.as_str(), all.tolerance_m), ("all", 0.05));
    assert_eq!((all.true_positives, all.measured, all.within_nearest, all.within_main), (4, 3, 2, 1));
    assert!((all.median_error_m.unwrap() - 0.02).abs() < 1e-6, "{:?}", all.median_error_m);
}
