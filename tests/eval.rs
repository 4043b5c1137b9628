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
    // No detection says which rule gave its surface: both measured ones count as "unknown".
    let unknown = cog_gpu::eval::SourceAccuracy { measured: 2, within_main: 0 };
    assert_eq!(s.by_source.into_iter().collect::<Vec<_>>(), vec![("unknown".to_string(), unknown)]);
}

/// The pooled report of several categories: the hand-made tables above and a desk in image 1 (true surface
/// 0.72, inferred 0.73) sum their counts, and the median runs over all three errors (0.02, 0.10, 0.01 → the
/// upper median 0.02), not over the categories' medians (0.10 and 0.01).
#[test]
fn pooled_surface_accuracy_by_hand() {
    use cog_gpu::eval::{surface_accuracy, SurfaceAccuracy};
    use cog_gpu::features::surface::SurfaceSource;
    use cog_gpu::frame::Object;
    let object = |category: &str, x: f32| Object { category: category.into(), label: None, cuboid: unit_box(x, 0.0) };
    let truth = vec![vec![object("table", 0.0), object("table", 5.0)], vec![object("table", 0.0), object("desk", 3.0)]];
    let supports = vec![vec![vec![0.75, 0.30], vec![0.70]], vec![vec![], vec![0.72]]];
    // The tables' surfaces from a face, the desks' from a front edge (`by_source`).
    let with = |category: &str, x: f32, score: f32, z: Option<f32>| {
        let mut d = Detection::new(category, &unit_box(x, 0.0), score);
        d.surface_z = z;
        d.surface_source = Some(if category == "table" { SurfaceSource::Face } else { SurfaceSource::FrontEdge });
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
    // By rule: the tables' two measured surfaces (main 0.75 against 0.32, 0.70 against 0.80) none within
    // 5 cm, the desk's one (0.72 against 0.73) within; the sums are the totals.
    let by: Vec<(&str, usize, usize)> =
        all.by_source.iter().map(|(k, c)| (k.as_str(), c.measured, c.within_main)).collect();
    assert_eq!(by, vec![("face", 2, 0), ("front-edge", 1, 1)]);
}

/// PASCAL VOC's devkit matching with "difficult" objects (VOCevaldet.m, written from its description, not
/// with the crate's matching): detections by score, highest first (stable); each takes the box of its
/// image with the largest overlap (strictly larger replaces, so ties go to the first box), difficult ones
/// included; at overlap ≥ `threshold` a difficult box makes the detection neither true nor false, a free
/// box a true positive (then taken), a taken box a false positive; below it a false positive. Recall over
/// the boxes that are not difficult; AP the all-point area under the non-increasing precision envelope,
/// with recall 0 → precision of the first point and the curve closed at (1, 0) as the devkit pads it.
fn voc_ap(detections: &[(usize, f32, Cuboid)], truth: &[Vec<(Cuboid, bool)>], threshold: f32) -> Option<f64> {
    let positives = truth.iter().flatten().filter(|(_, difficult)| !difficult).count();
    if positives == 0 {
        return None;
    }
    let mut order: Vec<usize> = (0..detections.len()).collect();
    order.sort_by(|&a, &b| detections[b].1.partial_cmp(&detections[a].1).unwrap());
    let mut taken: Vec<Vec<bool>> = truth.iter().map(|t| vec![false; t.len()]).collect();
    let (mut tp, mut fp) = (0usize, 0usize);
    let (mut recall, mut precision) = (vec![0.0f64], vec![0.0f64]);
    for &d in &order {
        let (image, _, cuboid) = &detections[d];
        let mut best: Option<(usize, f32)> = None;
        for (j, (box_, _)) in truth[*image].iter().enumerate() {
            let overlap = cog_gpu::geometry::iou_3d(cuboid, box_);
            if best.is_none_or(|(_, o)| overlap > o) {
                best = Some((j, overlap));
            }
        }
        match best {
            Some((j, overlap)) if overlap >= threshold => {
                if truth[*image][j].1 {
                    continue;
                }
                if taken[*image][j] {
                    fp += 1;
                } else {
                    taken[*image][j] = true;
                    tp += 1;
                }
            }
            _ => fp += 1,
        }
        recall.push(tp as f64 / positives as f64);
        precision.push(tp as f64 / (tp + fp) as f64);
    }
    recall.push(1.0);
    precision.push(0.0);
    for k in (0..precision.len() - 1).rev() {
        precision[k] = precision[k].max(precision[k + 1]);
    }
    Some((1..recall.len()).map(|k| (recall[k] - recall[k - 1]) * precision[k]).sum())
}

#[test]
fn ignored_boxes_follow_vocs_difficult_rule() {
    use cog_gpu::eval::{evaluate_categories, ignore_boxes};
    // xorshift64*: random scenes of beds and chairs crowded into a 3 m square so that boxes overlap.
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut uniform = move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut checked_with_dropped = 0;
    for trial in 0..300 {
        let frames = 1 + (uniform() * 5.0) as usize;
        let (mut truth, mut marks, mut detections) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..frames {
            let mut objects = Vec::new();
            for _ in 0..(uniform() * 5.0) as usize {
                let category = if uniform() < 0.7 { "bed" } else { "chair" };
                let size = Vec3::new(0.5 + uniform(), 0.5 + uniform(), 0.5 + uniform());
                let centre = Vec3::new(3.0 * uniform(), 3.0 * uniform(), size.z / 2.0);
                objects.push(object(category, Cuboid::new(centre, size, uniform() * 3.0)));
                // Now and then a second annotation of the same box: every detection then overlaps the two
                // equally, and the tie goes to the first (marked or not) on both sides.
                if uniform() < 0.15 {
                    objects.push(objects[objects.len() - 1].clone());
                }
            }
            let ignored: Vec<bool> = objects.iter().map(|_| uniform() < 0.35).collect();
            let mut frame = Vec::new();
            for _ in 0..(uniform() * 8.0) as usize {
                // Half near an annotated box (of either category), half anywhere.
                let cuboid = match objects.get((uniform() * 2.0 * objects.len() as f32) as usize) {
                    Some(o) => Cuboid {
                        centre: o.cuboid.centre + Vec3::new(uniform() - 0.5, uniform() - 0.5, 0.0) * 0.8,
                        ..o.cuboid
                    },
                    None => Cuboid::new(Vec3::new(3.0 * uniform(), 3.0 * uniform(), 0.5), Vec3::ONE, uniform()),
                };
                let category = if uniform() < 0.8 { "bed" } else { "chair" };
                // Scores on a coarse grid: ties happen, and both sides keep input order on them.
                frame.push(Detection::new(category, &cuboid, (uniform() * 10.0).floor() / 10.0));
            }
            truth.push(objects);
            marks.push(ignored);
            detections.push(frame);
        }
        let threshold = if trial % 2 == 0 { 0.25 } else { 0.5 };
        let kept = ignore_boxes(&truth, &marks, &detections, threshold);
        let (kept_truth, kept_detections, counts) = (kept.truth, kept.detections, kept.counts);
        let ours = evaluate_categories(&kept_truth, &kept_detections, &["bed".to_string()], threshold)[0].pr.ap;
        let voc_truth: Vec<Vec<(Cuboid, bool)>> = truth
            .iter()
            .zip(&marks)
            .map(|(objects, m)| {
                objects.iter().zip(m).filter(|(o, _)| o.category == "bed").map(|(o, &d)| (o.cuboid, d)).collect()
            })
            .collect();
        let voc_detections: Vec<(usize, f32, Cuboid)> = detections
            .iter()
            .enumerate()
            .flat_map(|(i, f)| f.iter().filter(|d| d.category == "bed").map(move |d| (i, d.score, d.cuboid())))
            .collect();
        let reference = voc_ap(&voc_detections, &voc_truth, threshold);
        match (ours, reference) {
            (None, None) => {}
            (Some(a), Some(b)) => assert!((a as f64 - b).abs() < 1e-5, "trial {trial}: {a} against VOC's {b}"),
            other => panic!("trial {trial}: {other:?}"),
        }
        // The counts: every marked box, and exactly the detections that left.
        let marked_beds = voc_truth.iter().flatten().filter(|(_, d)| *d).count();
        let bed = counts.get("bed").copied().unwrap_or_default();
        assert_eq!(bed.boxes, marked_beds, "trial {trial}");
        let left = |d: &[Vec<Detection>]| d.iter().flatten().filter(|d| d.category == "bed").count();
        assert_eq!(bed.detections, left(&detections) - left(&kept_detections), "trial {trial}");
        checked_with_dropped += (bed.detections > 0 && reference.is_some()) as usize;
    }
    assert!(checked_with_dropped > 50, "the random scenes exercise dropped detections ({checked_with_dropped})");
}

/// `surface_source` in the detections JSON: the three rules by the names `SurfaceSource::name` prints (so
/// `eval --surfaces` and the files agree), written only with a surface, and absent in older files.
#[test]
fn surface_source_in_json() {
    use cog_gpu::features::surface::SurfaceSource;
    for source in [SurfaceSource::Face, SurfaceSource::FrontEdge, SurfaceSource::LatentSlice] {
        assert_eq!(serde_json::to_string(&source).unwrap(), format!("\"{}\"", source.name()));
    }
    let mut d = Detection::new("dresser", &unit_box(1.0, 0.0), 0.5);
    assert!(!serde_json::to_string(&d).unwrap().contains("surface_source"));
    (d.surface_z, d.surface_source) = (Some(0.9), Some(SurfaceSource::FrontEdge));
    let text = serde_json::to_string(&d).unwrap();
    assert!(text.contains(r#""surface_source":"front-edge""#), "{text}");
    let back: Detection = serde_json::from_str(&text).unwrap();
    assert_eq!(back.surface_source, Some(SurfaceSource::FrontEdge));
    let older: Detection = serde_json::from_str(&text.replace(r#","surface_source":"front-edge""#, "")).unwrap();
    assert_eq!((older.surface_z, older.surface_source), (Some(0.9), None));
}
