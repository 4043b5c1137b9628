//! `cog_gpu::diagnose` against hand-computed numbers, the window recall on a synthetic frame, and
//! `cog-gpu eval --diagnose` end to end.

use cog_gpu::features::Support;
use std::process::Command;

mod common;

use cog_gpu::detect::OVERLAY_SAME_CATEGORY_IOU;
use cog_gpu::diagnose::{
    best_window_ious, diagnose_categories, false_positive_kinds, frame_window_best_ious, in_frame_ranking,
    object_outcomes, oracle_aps, overlay_precision, rank_average_precision, reliability, ObjectSummary, OverlayRule,
    WindowRecall, RELIABILITY_BINS,
};
use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::features::hypotheses::{sliding_window, window_yaws, WindowOptions};
use cog_gpu::features::LatticePhase;
use cog_gpu::features::YawAnchor;
use cog_gpu::features::{FeatureLayout, FeatureScene, Groups, Preprocessed, SizeQuantiles};
use cog_gpu::frame::{Frame, Object};
use cog_gpu::geometry::{in_view_share, iou_3d, Camera, Cuboid};
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};
use cog_gpu::synth::{self, SynthOptions};
use glam::Vec3;
use serde_json::Value;

fn unit_box(x: f32, y: f32) -> Cuboid {
    Cuboid::new(Vec3::new(x, y, 0.5), Vec3::ONE, 0.0)
}

fn object(category: &str, cuboid: Cuboid) -> Object {
    Object { category: category.into(), label: None, cuboid }
}

fn det(category: &str, cuboid: Cuboid, score: f32) -> Detection {
    Detection::new(category, &cuboid, score)
}

fn close(a: Option<f32>, b: f32) -> bool {
    a.is_some_and(|a| (a - b).abs() < 1e-5)
}

const FAR: f32 = 20.0;

#[test]
fn in_frame_best_is_true_positive() {
    // f0: a bed at x = 0; two bed detections with the same score 0.9, the exact one listed first: ties go
    //     to the first in the list → best is the exact box → TP.
    // f1: a bed at x = 0; the best bed detection (0.8) is far away → FP (the exact one at 0.7 is not the
    //     best and does not count).
    // f2: a bed at x = 0 and only a chair detection on it → no bed detection, the frame is left out of
    //     frames_with_detections.
    // The detections list is one shorter than the frames (f2 has none at all would be the same).
    let truth = vec![
        vec![object("bed", unit_box(0.0, 3.0))],
        vec![object("bed", unit_box(0.0, 3.0))],
        vec![object("bed", unit_box(0.0, 3.0)), object("chair", unit_box(0.0, 6.0))],
    ];
    let detections = vec![
        vec![det("bed", unit_box(0.0, 3.0), 0.9), det("bed", unit_box(FAR, 3.0), 0.9)],
        vec![det("bed", unit_box(FAR, 3.0), 0.8), det("bed", unit_box(0.0, 3.0), 0.7)],
        vec![det("chair", unit_box(0.0, 3.0), 0.95)],
    ];
    let bed = in_frame_ranking(&truth, &detections, "bed", 0.25);
    assert_eq!((bed.frames_with_category, bed.frames_with_detections, bed.best_is_true_positive), (3, 2, 1));
    assert!(close(bed.fraction(), 0.5));

    // Reversing f0's tie makes its best the far box: 0 of 2.
    let mut swapped = detections.clone();
    swapped[0].reverse();
    assert_eq!(in_frame_ranking(&truth, &swapped, "bed", 0.25).best_is_true_positive, 0);

    // The chair of f2 has its detection 3 m off → FP; a missing detections entry counts as none.
    let chair = in_frame_ranking(&truth, &detections[..2], "chair", 0.25);
    assert_eq!((chair.frames_with_category, chair.frames_with_detections), (1, 0));
    assert_eq!(chair.fraction(), None);

    // The IoU threshold: a best detection shifted by half a width (IoU 1/3) is a TP at 0.25, not at 0.5.
    let shifted = vec![vec![det("bed", unit_box(0.5, 3.0), 0.9)]];
    assert_eq!(in_frame_ranking(&truth[..1], &shifted, "bed", 0.25).best_is_true_positive, 1);
    assert_eq!(in_frame_ranking(&truth[..1], &shifted, "bed", 0.5).best_is_true_positive, 0);
}

#[test]
fn rank_ap_differs_from_ap_as_computed_by_hand() {
    // Frame A: a bed; detections TP 0.9, FP 0.8 (far). Frame B: a bed; detection TP 0.3.
    let truth = vec![vec![object("bed", unit_box(0.0, 3.0))], vec![object("bed", unit_box(0.0, 3.0))], vec![]];
    let mut detections = vec![
        vec![det("bed", unit_box(0.0, 3.0), 0.9), det("bed", unit_box(FAR, 3.0), 0.8)],
        vec![det("bed", unit_box(0.0, 3.0), 0.3)],
        vec![],
    ];
    let categories = vec!["bed".to_string()];
    // Score order: A-TP, A-FP, B-TP → precision 1, 1/2, 2/3; recall 1/2, 1/2, 1; envelope 1, 2/3, 2/3 →
    // AP = 1/2·1 + 1/2·2/3 = 5/6.
    // Rank order: rank 0: A-TP (0.9), B-TP (0.3); rank 1: A-FP → precision 1, 1, 2/3; recall 1/2, 1, 1 →
    // rank AP = 1.
    let d = &diagnose_categories(&truth, &detections, &categories, 0.25, None)[0];
    assert!(close(d.ap, 5.0 / 6.0), "{d:?}");
    assert!(close(d.rank_ap, 1.0), "{d:?}");
    assert!(close(rank_average_precision(&truth, &detections, "bed", 0.25).ap, 1.0));

    // Frame C (no ground truth) gets a FP bed at 0.95: rank 0 as well. At equal rank, higher original score
    // first: C-FP (0.95), A-TP (0.9), B-TP (0.3), then A-FP → precision 0, 1/2, 2/3, 1/2; recall 0, 1/2, 1,
    // 1; envelope 2/3, 2/3, 2/3, 1/2 → rank AP = 1/2·2/3 + 1/2·2/3 = 2/3. (Ascending scores would give
    // B-TP, A-TP, C-FP, A-FP → rank AP 1: the tie-break matters.)
    // Score order: C-FP, A-TP, A-FP, B-TP → precision 0, 1/2, 1/3, 1/2; recall 0, 1/2, 1/2, 1; envelope
    // 1/2 throughout → AP = 1/2.
    detections[2].push(det("bed", unit_box(0.0, 3.0), 0.95));
    let d = &diagnose_categories(&truth, &detections, &categories, 0.25, None)[0];
    assert!(close(d.ap, 0.5), "{d:?}");
    assert!(close(d.rank_ap, 2.0 / 3.0), "{d:?}");
    let pr = rank_average_precision(&truth, &detections, "bed", 0.25);
    assert_eq!(pr.true_positive, [false, true, true, false]);

    // No ground truth: no rank AP.
    assert_eq!(rank_average_precision(&truth, &detections, "chair", 0.25).ap, None);
}

#[test]
fn overlay_precision_by_hand() {
    let categories = vec!["bed".to_string(), "chair".to_string()];
    let truth = vec![
        // f0: k = 2.
        vec![
            object("bed", unit_box(0.0, 3.0)),
            object("chair", unit_box(0.0, 6.0)),
            object("sofa", unit_box(9.0, 9.0)),
        ],
        // f1: two beds side by side (x = 0 and 1.05), k = 2.
        vec![object("bed", unit_box(0.0, 3.0)), object("bed", unit_box(1.05, 3.0))],
        // f2: k = 1, no detections.
        vec![object("chair", unit_box(0.0, 6.0))],
        // f3: k = 0.
        vec![],
    ];
    let detections = vec![
        // The sofa is not evaluated (ignored, even though it scores best); top 2: bed 0.9 (TP), then its
        // duplicate 0.8 is skipped (the same object: IoU 1 ≥ the overlay's same-category limit, the NMS's
        // 0.15), so the chair 0.7 is shown, 0.8 m off its box (IoU 0.2/1.8 = 0.11): FP; the exact chair
        // at 0.6 is the third, not shown.
        vec![
            det("sofa", unit_box(9.0, 9.0), 0.99),
            det("bed", unit_box(0.0, 3.0), 0.9),
            det("bed", unit_box(0.0, 3.0), 0.8),
            det("chair", unit_box(0.0, 6.8), 0.7),
            det("chair", unit_box(0.0, 6.0), 0.6),
        ],
        // Bed at x = −0.3 (0.9) takes the bed at x = 0 (IoU 0.7/1.3 = 0.54); bed at x = 0.5 (0.8; IoU
        // 0.2/1.8 = 0.11 with the first, under 0.15: shown): its best box, x = 0 (0.5/1.5 = 0.33), is
        // taken, the free one at x = 1.05 overlaps it by 0.45/1.55 = 0.29 ≥ 0.25 → TP as well.
        vec![det("bed", unit_box(-0.3, 3.0), 0.9), det("bed", unit_box(0.5, 3.0), 0.8)],
        vec![],
        vec![det("bed", unit_box(0.0, 3.0), 0.9)],
    ];
    // Under the ground-truth count with `detect`'s default same-category limit.
    let by_count = |detections: &[Vec<Detection>], iou: f32| {
        overlay_precision(
            &truth,
            detections,
            &categories,
            iou,
            OverlayRule::GroundTruthCount,
            OVERLAY_SAME_CATEGORY_IOU,
        )
    };
    // Shown 2 + 2 + 0 + 0 = 4, true positives 1 + 2 = 3.
    let o = by_count(&detections, 0.25);
    assert_eq!((o.true_positives, o.shown), (3, 4));
    assert!(close(o.precision, 0.75));
    // At IoU 0.5 the second bed of f1 misses (0.29): 2 of 4.
    let o = by_count(&detections, 0.5);
    assert_eq!((o.true_positives, o.shown), (2, 4));
    // With `detect --nms-iou 0.1` (the same-category limit under f1's beds' IoU of 0.11) f1's second bed
    // gives way to its first and nothing replaces it: f0 as before (1 of 2), f1 1 of 1.
    let o = overlay_precision(&truth, &detections, &categories, 0.25, OverlayRule::GroundTruthCount, 0.1);
    assert_eq!((o.true_positives, o.shown), (2, 3));
    // A detection of another category on the box does not count: a chair on f1's bed.
    let chair_on_bed = vec![vec![], vec![det("chair", unit_box(0.0, 3.0), 0.9)]];
    let o = by_count(&chair_on_bed, 0.25);
    assert_eq!((o.true_positives, o.shown, o.precision), (0, 1, Some(0.0)));
    let none = by_count(&[], 0.25);
    assert_eq!((none.shown, none.precision), (0, None));
    assert_eq!((none.frames, none.frames_without_boxes), (4, 4));
    // Under the ground-truth count, f2 (no detections) and f3 (k = 0) show nothing.
    let o = by_count(&detections, 0.25);
    assert_eq!((o.frames, o.frames_without_boxes), (4, 2));
}

/// The overlay's false boxes by kind, each kind once, by hand (the rules of `false_positive_kinds`).
#[test]
fn overlay_false_kinds_by_hand() {
    let categories = vec!["bed".to_string(), "chair".to_string(), "desk".to_string()];
    let truth = vec![
        // f0: k = 3.
        vec![
            object("bed", unit_box(0.0, 3.0)),
            object("chair", unit_box(0.0, 6.0)),
            object("desk", unit_box(5.0, 0.0)),
        ],
        // f1: k = 2.
        vec![object("chair", unit_box(0.0, 0.0)), object("bed", unit_box(10.0, 10.0))],
        // f2: k = 1.
        vec![object("chair", unit_box(0.0, 0.0))],
        // f3: two desks, k = 2.
        vec![object("desk", unit_box(0.0, 0.0)), object("desk", unit_box(3.0, 0.0))],
    ];
    let detections = vec![
        vec![
            // IoU 0.7/1.3 = 0.54 with the bed: true positive.
            det("bed", unit_box(-0.3, 3.0), 0.9),
            // IoU 0.15/1.85 = 0.08 with the first (under the same-category limit 0.15: shown), 0.45/1.55 =
            // 0.29 with the bed, which the first took: a duplicate.
            det("bed", unit_box(0.55, 3.0), 0.8),
            // On the desk (IoU 1), nowhere near the chair: a chair on a desk.
            det("chair", unit_box(5.0, 0.0), 0.7),
        ],
        vec![
            // 0.8 m off the chair: IoU 0.2/1.8 = 0.11, poorly placed.
            det("chair", unit_box(0.8, 0.0), 0.9),
            // No desk in f1, nothing near: background elsewhere.
            det("desk", unit_box(20.0, 20.0), 0.8),
        ],
        // A chair far from f2's chair: background in a frame with its category.
        vec![det("chair", unit_box(FAR, FAR), 0.9)],
        // Beds on both desks: two beds on desks.
        vec![det("bed", unit_box(0.0, 0.0), 0.9), det("bed", unit_box(3.0, 0.0), 0.8)],
    ];
    let o = overlay_precision(&truth, &detections, &categories, 0.25, OverlayRule::GroundTruthCount, 0.15);
    assert_eq!((o.true_positives, o.shown), (1, 8));
    let k = &o.false_kinds;
    assert_eq!(
        (k.duplicate, k.localisation, k.confusion, k.background_in_frame, k.background_elsewhere),
        (1, 1, 3, 1, 1)
    );
    // Most frequent first.
    let pairs: Vec<(&str, &str, usize)> =
        k.confused.iter().map(|c| (c.shown.as_str(), c.object.as_str(), c.count)).collect();
    assert_eq!(pairs, [("bed", "desk", 2), ("chair", "desk", 1)]);
    // At IoU 0.5 f0's first bed (0.54) still hits and the second (0.29) is poorly placed, no duplicate.
    let o = overlay_precision(&truth, &detections, &categories, 0.5, OverlayRule::GroundTruthCount, 0.15);
    assert_eq!((o.false_kinds.duplicate, o.false_kinds.localisation), (0, 2));
}

/// What `detect` draws: at most `top` a frame, calibrated detections below the floor left out (wherever
/// they rank), by hand.
#[test]
fn drawn_overlay_precision_by_hand() {
    let categories = vec!["bed".to_string(), "chair".to_string()];
    let truth = vec![
        vec![object("bed", unit_box(0.0, 3.0)), object("chair", unit_box(0.0, 6.0))],
        vec![object("chair", unit_box(0.0, 6.0))],
        vec![],
    ];
    let calibrated = |category: &str, cuboid: Cuboid, probability: f32| {
        let mut d = det(category, cuboid, probability);
        d.raw_score = Some(0.0);
        d
    };
    let detections = vec![
        // f0: bed 0.9 (TP), a false chair 0.6, the exact chair 0.4 (below 0.5), a false bed 0.55.
        vec![
            calibrated("bed", unit_box(0.0, 3.0), 0.9),
            calibrated("chair", unit_box(20.0, 6.0), 0.6),
            calibrated("chair", unit_box(0.0, 6.0), 0.4),
            calibrated("bed", unit_box(30.0, 3.0), 0.55),
        ],
        // f1: the chair at 0.3 only: nothing drawn.
        vec![calibrated("chair", unit_box(0.0, 6.0), 0.3)],
        // f2: no ground truth, a false bed at 0.7: drawn, false.
        vec![calibrated("bed", unit_box(0.0, 3.0), 0.7)],
    ];
    let drawn = |top: usize, min_probability: f32| {
        let rule = OverlayRule::Drawn { top, min_probability };
        let o = overlay_precision(&truth, &detections, &categories, 0.25, rule, OVERLAY_SAME_CATEGORY_IOU);
        (o.true_positives, o.shown, o.frames_without_boxes)
    };
    // Floor 0.5, top 8: f0 shows bed, chair 0.6, bed 0.55 (1 TP of 3); f1 none; f2 one false.
    assert_eq!(drawn(8, 0.5), (1, 4, 1));
    // Top 2: f0 shows bed and the false chair.
    assert_eq!(drawn(2, 0.5), (1, 3, 1));
    // No floor: f0's exact chair is drawn too (2 of 4), f1's chair (TP): 3 of 6.
    assert_eq!(drawn(8, 0.0), (3, 6, 0));
}

#[test]
fn false_positive_kinds_by_hand() {
    // Frame 0: six chairs (two of them detected), a sofa; frame 1: a table, no chair.
    let chairs = [0.0, 3.0, 30.0, 40.0, 50.0, 60.0].map(|x| object("chair", unit_box(x, 0.0)));
    let mut frame0 = chairs.to_vec();
    frame0.push(object("sofa", unit_box(6.0, 0.0)));
    let truth = vec![frame0, vec![object("table", unit_box(0.0, 0.0))]];
    let detections = vec![
        vec![
            det("chair", unit_box(0.0, 0.0), 0.9),  // true positive (takes the chair at 0)
            det("chair", unit_box(0.3, 0.0), 0.8),  // IoU 0.7/1.3 with the taken chair: duplicate
            det("chair", unit_box(3.8, 0.0), 0.7),  // IoU 0.2/1.8 = 0.11 with the chair at 3: localisation
            det("chair", unit_box(6.0, 0.0), 0.6),  // on the sofa: confusion
            det("chair", unit_box(10.0, 0.0), 0.5), // nothing there, frame has chairs
        ],
        vec![
            det("chair", unit_box(20.0, 0.0), 0.4), // nothing there, frame without chairs
            det("chair", unit_box(0.0, 0.0), 0.3),  // on the table: confusion
            det("chair", unit_box(90.0, 0.0), 0.2), // the seventh false positive: not examined (6 chairs)
        ],
    ];
    let kinds = false_positive_kinds(&truth, &detections, "chair", 0.25);
    assert_eq!(kinds.examined, 6);
    assert_eq!((kinds.duplicate, kinds.localisation, kinds.confusion), (1, 1, 2));
    assert_eq!((kinds.background_in_frame, kinds.background_elsewhere), (1, 1));
    // One sofa and one table: the tie goes to the first name.
    assert_eq!(kinds.most_confused_with.as_deref(), Some("sofa"));
    // A category without detections examines nothing.
    let none = false_positive_kinds(&truth, &detections, "table", 0.25);
    assert_eq!((none.examined, none.most_confused_with), (0, None));
}

/// Frame 0: chairs at 0, 3 and 30 (the one at 30 never detected), a sofa at 6, and seven chair detections;
/// frame 1: a table at (0, 4), no chair, one chair detection far away.
fn chairs_case() -> (Vec<Vec<Object>>, Vec<Vec<Detection>>) {
    let mut frame0: Vec<Object> = [0.0, 3.0, 30.0].map(|x| object("chair", unit_box(x, 0.0))).to_vec();
    frame0.push(object("sofa", unit_box(6.0, 0.0)));
    let truth = vec![frame0, vec![object("table", unit_box(0.0, 4.0))]];
    let detections = vec![
        vec![
            det("chair", unit_box(6.0, 0.0), 0.9),  // on the sofa: confusion
            det("chair", unit_box(0.0, 0.0), 0.8),  // true positive
            det("chair", unit_box(3.8, 0.0), 0.6),  // IoU 0.2/1.8 = 0.11 with the chair at 3: localisation
            det("chair", unit_box(3.0, 0.0), 0.5),  // true positive
            det("chair", unit_box(0.3, 0.0), 0.45), // IoU 0.7/1.3 with the taken chair at 0: duplicate
            det("chair", unit_box(10.0, 0.0), 0.4), // nothing there, frame with chairs
        ],
        vec![det("chair", unit_box(20.0, 0.0), 0.7)], // nothing there, frame without chairs
    ];
    (truth, detections)
}

#[test]
fn oracle_aps_by_hand() {
    let (truth, detections) = chairs_case();
    // In score order: conf, TP, bg, loc, TP, dup, bg; 3 chairs. All-point interpolated AP, by hand:
    //   all:            precision 0, 1/2, 1/3, 1/4, 2/5, …  → 1/3·1/2 + 1/3·2/5 = 0.3
    //   without dup:    the same up to the last true positive → 0.3
    //   without loc:    0, 1/2, 1/3, 2/4 → 1/3·1/2 + 1/3·1/2 = 1/3
    //   without conf:   1, 1/2, 1/3, 2/4 → 1/3·1 + 1/3·1/2 = 1/2
    //   without bg:     0, 1/2, 1/3, 2/4 → 1/3
    //   without loc, conf and bg, or without every false positive: 1, 1 → 2/3 (the chair at 30 is missed)
    let oracle = oracle_aps(&truth, &detections, "chair", 0.25);
    let ap = diagnose_categories(&truth, &detections, &["chair".into()], 0.25, None)[0].ap;
    assert!(close(ap, 0.3), "{ap:?}");
    assert!(close(oracle.without_duplicates, 0.3), "{oracle:?}");
    assert!(close(oracle.without_localisation, 1.0 / 3.0), "{oracle:?}");
    assert!(close(oracle.without_confusion, 0.5), "{oracle:?}");
    assert!(close(oracle.without_background, 1.0 / 3.0), "{oracle:?}");
    assert!(close(oracle.without_localisation_confusion_background, 2.0 / 3.0), "{oracle:?}");
    assert!(close(oracle.without_false_positives, 2.0 / 3.0), "{oracle:?}");
    // Without ground truth: nothing to measure.
    assert_eq!(oracle_aps(&truth, &detections, "bed", 0.25), Default::default());
}

#[test]
fn object_outcomes_by_hand() {
    // The case of `oracle_aps_by_hand`: in score order conf (0.9), TP chair 0 (0.8), bg (0.7), loc (0.6),
    // TP chair 3 (0.5), dup (0.45), bg (0.4); the chair at 30 is never detected. Frame 1's table gets a
    // table detection 0.8 m off (IoU 0.2/1.8 = 0.11: near, not found), two desks on it (0.6 and 0.3,
    // exact) and a sofa 0.5 m off (IoU 0.5/1.5 = 1/3) at 0.95: the most confident other category's
    // detection at IoU ≥ 0.25 is the sofa, though the desks overlap more.
    let (truth, mut detections) = chairs_case();
    detections[1].extend([
        det("table", unit_box(0.8, 4.0), 0.5),
        det("desk", unit_box(0.0, 4.0), 0.6),
        det("desk", unit_box(0.0, 4.0), 0.3),
        det("sofa", unit_box(0.5, 4.0), 0.95),
    ]);
    let chairs = object_outcomes(&truth, &detections, "chair", 0.25);
    assert_eq!(chairs.len(), 3);
    assert_eq!(chairs.iter().map(|o| (o.image, o.object)).collect::<Vec<_>>(), [(0, 0), (0, 1), (0, 2)]);
    // Chair 0: the second in the ranking, after one false positive: precision 1/2.
    let found = chairs[0].found.as_ref().expect("chair 0 is found");
    assert_eq!((found.score, found.false_positives_before), (0.8, 1));
    assert!((found.precision - 0.5).abs() < 1e-6 && (found.iou - 1.0).abs() < 1e-6, "{found:?}");
    // Chair 3: fifth, after three false positives (conf, bg of frame 1, loc): precision 2/5.
    let found = chairs[1].found.as_ref().expect("chair 3 is found");
    assert_eq!((found.score, found.false_positives_before), (0.5, 3));
    assert!((found.precision - 0.4).abs() < 1e-6, "{found:?}");
    assert!((chairs[1].distance_m - 3.0).abs() < 1e-6 && (chairs[1].best_iou - 1.0).abs() < 1e-6);
    // Chair 30: missed, no chair detection near it, nothing else on it.
    assert!(chairs[2].found.is_none() && chairs[2].best_iou == 0.0 && chairs[2].other.is_none());
    assert_eq!(
        ObjectSummary::of(&chairs),
        ObjectSummary { found_ahead: 1, found_behind: 1, missed_near: 0, missed_far: 1, missed_with_other: 0 }
    );
    let tables = object_outcomes(&truth, &detections, "table", 0.25);
    assert_eq!(tables.len(), 1);
    let table = &tables[0];
    assert!(table.found.is_none());
    assert!((table.best_iou - 0.2 / 1.8).abs() < 1e-5, "{table:?}");
    assert!((table.distance_m - 4.0).abs() < 1e-6 && table.size == [1.0, 1.0, 1.0]);
    let other = table.other.as_ref().expect("other categories on the table");
    assert_eq!((other.category.as_str(), other.score), ("sofa", 0.95));
    assert!((other.iou - 1.0 / 3.0).abs() < 1e-5, "{other:?}");
    assert_eq!(
        ObjectSummary::of(&tables),
        ObjectSummary { found_ahead: 0, found_behind: 0, missed_near: 1, missed_far: 0, missed_with_other: 1 }
    );
    // diagnose_categories carries the same counts; a category without ground truth has none.
    let diagnosis = diagnose_categories(&truth, &detections, &["chair".into(), "bed".into()], 0.25, None);
    assert_eq!(diagnosis[0].objects, ObjectSummary::of(&chairs));
    assert_eq!(diagnosis[1].objects, ObjectSummary::default());
    assert!(object_outcomes(&truth, &detections, "bed", 0.25).is_empty());
}

#[test]
fn in_view_share_analytic() {
    // Upright = camera axes (Rtilt = I: x right, y forward = depth, z up); fx = fy = 100 and the principal
    // point at the centre of a 100 × 100 image: pixel u = 100·x/y + 49.5 (0-based), inside for u in
    // [−0.5, 99.5), i.e. x/y in [−0.5, 0.5), and likewise −z/y.
    let camera = Camera::new([100.0, 100.0, 50.5, 50.5], glam::Mat3::IDENTITY);
    let small = |x: f32, y: f32| Cuboid::new(Vec3::new(x, y, 0.0), Vec3::new(0.2, 0.01, 0.2), 0.0);
    assert_eq!(in_view_share(&small(0.0, 3.0), &camera, 100, 100), 1.0, "in front, in the middle");
    assert_eq!(in_view_share(&small(0.0, -3.0), &camera, 100, 100), 0.0, "behind the camera");
    assert_eq!(in_view_share(&small(3.0, 1.0), &camera, 100, 100), 0.0, "beside the image");
    // Centred on the left edge's plane x = −y/2 at depth 2: of the 10 cells along x (centres −1.09 …
    // −0.91), the five at x ≥ −0.99 project inside (x/y ≥ −0.99/1.995 > −0.5), the five at x ≤ −1.01
    // outside (x/y ≤ −1.01/2.005 < −0.5), at every depth of the thin box.
    assert_eq!(in_view_share(&small(-1.0, 2.0), &camera, 100, 100), 0.5);
    // The image's size counts: in a 60-pixel-tall picture the cells below v = 59.5 (−z/y ≥ 0.1, z ≤ −0.3
    // at depth 3) would be lost — none of this box's; in a 50-pixel-wide one every cell at x/y ≥ 0 is
    // outside: half.
    assert_eq!(in_view_share(&small(0.0, 3.0), &camera, 100, 60), 1.0);
    assert_eq!(in_view_share(&small(0.0, 3.0), &camera, 50, 100), 0.5);
}

#[test]
fn window_recall_summary() {
    let r = WindowRecall::from_best_ious(&[0.1, 0.3, 0.6, 1.0]);
    assert_eq!(r.boxes, 4);
    assert!(close(r.recall_25, 0.75) && close(r.recall_50, 0.5) && close(r.mean_best_iou, 0.5));
    assert_eq!(WindowRecall::from_best_ious(&[]), WindowRecall::default());
}

#[test]
fn window_recall_on_a_synthetic_frame() {
    let frame = synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap().frame;
    assert!(!frame.objects.is_empty());
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let step = 0.25;
    // The window detection searches: the 16 yaws anchored at the frame's wall direction.
    let scene = FeatureScene::new(pre.clone(), &window_yaws(&pre, YawAnchor::Walls), step);
    let sizes = SizeQuantiles {
        widths: vec![0.5, 0.8, 1.1, 1.4, 1.8],
        depths: vec![0.5, 1.0, 2.0],
        heights: vec![0.4, 0.8, 1.6],
    };
    let min_points = 20;
    let window = sliding_window(&scene, &WindowOptions { sizes: sizes.sizes(), min_points });
    let hypotheses = &window.hypotheses;
    assert!(hypotheses.len() > 10, "{} hypotheses", hypotheses.len());

    // Two ground-truth boxes equal to window hypotheses get IoU 1; the frame's own boxes get the brute-force
    // maximum (the culling is exact), in [0, 1].
    let picked = [hypotheses[0].cuboid(&scene), hypotheses[hypotheses.len() / 2].cuboid(&scene)];
    let truths: Vec<Cuboid> = picked.iter().copied().chain(frame.objects.iter().map(|o| o.cuboid)).collect();
    let best = best_window_ious(&scene, hypotheses, &truths);
    assert_eq!(best.len(), truths.len());
    assert!(best[0] > 1.0 - 1e-5 && best[1] > 1.0 - 1e-5, "{best:?}");
    for (g, truth) in truths.iter().enumerate() {
        let brute = hypotheses.iter().map(|h| iou_3d(&h.cuboid(&scene), truth)).fold(0.0f32, f32::max);
        assert!((0.0..=1.0).contains(&best[g]), "{best:?}");
        assert_eq!(best[g], brute, "box {g}");
    }

    // The per-frame function with a model: the same hypotheses (its step, sizes, min_points), the frame's
    // boxes of the model's category; other categories absent.
    let category = frame.objects[0].category.clone();
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::GEOM).unwrap();
    let model = Model::new(
        &category,
        layout,
        sizes,
        WindowSettings {
            step,
            min_points,
            yaw_anchor: YawAnchor::Walls,
            support: Support::Floor,
            lattice: LatticePhase::Camera,
            supporters: cog_gpu::category::SurfaceCategories::ALL,
        },
        FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
        vec![0.0; layout.dim()],
        serde_json::Value::Null,
    )
    .unwrap();
    let per_frame = frame_window_best_ious(&pre, std::slice::from_ref(&model), &frame.objects, true);
    assert_eq!(per_frame.keys().collect::<Vec<_>>(), [&category]);
    let own: Vec<Cuboid> = frame.objects.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect();
    assert_eq!(per_frame[&category], best_window_ious(&scene, hypotheses, &own));
    // Without ground truth of the model's category nothing is computed.
    let others: Vec<Object> = frame.objects.iter().filter(|o| o.category != category).cloned().collect();
    assert!(frame_window_best_ious(&pre, &[model], &others, true).is_empty());
}

/// The reliability bins on a hand-worked case: labels by the AP's matching (a duplicate is false even on
/// its object), a score of exactly 1 in the last bin, a score outside [0, 1] matched but not binned, a
/// category not evaluated ignored; the expected calibration error by hand.
#[test]
fn reliability_by_hand() {
    let truth = vec![
        vec![object("chair", unit_box(0.0, 0.0)), object("table", unit_box(5.0, 0.0))],
        vec![object("chair", unit_box(0.0, 0.0))],
    ];
    let detections = vec![
        vec![
            det("chair", unit_box(0.0, 0.0), 0.95),  // true, bin 9
            det("chair", unit_box(0.0, 0.0), 0.85),  // its duplicate: false, bin 8
            det("chair", unit_box(10.0, 0.0), 0.15), // false, bin 1
            det("chair", unit_box(30.0, 0.0), -0.5), // false, outside [0, 1]
            det("table", unit_box(5.0, 0.0), 1.0),   // true, bin 9 (the last bin is closed)
            det("table", unit_box(5.0, 0.0), 0.55),  // duplicate: false, bin 5
            det("table", unit_box(20.0, 0.0), 0.05), // false, bin 0
            det("sofa", unit_box(0.0, 0.0), 0.5),    // not evaluated
        ],
        vec![det("chair", unit_box(0.0, 0.0), 0.15)], // true, bin 1
    ];
    let categories = vec!["chair".to_string(), "table".to_string()];
    let r = reliability(&truth, &detections, &categories, 0.25);
    assert_eq!(r.bins.len(), RELIABILITY_BINS);
    for (n, bin) in r.bins.iter().enumerate() {
        assert!((bin.lower - n as f32 * 0.1).abs() < 1e-6 && (bin.upper - (n + 1) as f32 * 0.1).abs() < 1e-6);
    }
    let counts: Vec<(usize, usize)> = r.bins.iter().map(|b| (b.detections, b.true_positives)).collect();
    assert_eq!(counts, [(1, 0), (2, 1), (0, 0), (0, 0), (0, 0), (1, 0), (0, 0), (0, 0), (1, 0), (2, 2)]);
    let expected = [0.05, 0.30, 0.0, 0.0, 0.0, 0.55, 0.0, 0.0, 0.85, 1.95];
    for (bin, e) in r.bins.iter().zip(expected) {
        assert!((bin.expected_true_positives - e).abs() < 1e-6, "{bin:?}");
    }
    assert!(r.bins[2].mean_score().is_none() && r.bins[2].precision().is_none());
    assert!((r.bins[1].precision().unwrap() - 0.5).abs() < 1e-12);
    assert_eq!(r.outside_unit_interval, 1);
    // Σ n_b/N |precision_b − mean_b| over the 7 binned: (0.05 + 2·0.35 + 0.55 + 0.85 + 2·0.025) / 7.
    assert!((r.expected_calibration_error.unwrap() - 2.2 / 7.0).abs() < 1e-6);
    // Nothing binned: no error to report.
    let raw = vec![vec![det("chair", unit_box(0.0, 0.0), 2.5)], vec![]];
    let r = reliability(&truth, &raw, &categories, 0.25);
    assert_eq!((r.outside_unit_interval, r.expected_calibration_error), (1, None));
}

use common::write_tiny_frame as write_frame;

#[test]
fn cli_diagnose_json_and_table() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = (tmp.path().join("data"), tmp.path().join("dets"));
    std::fs::create_dir_all(&dets).unwrap();
    // The rank-AP case of `rank_ap_differs_from_ap_as_computed_by_hand` (AP 5/6, rank AP 1) as files.
    write_frame(&data, "a", vec![object("bed", unit_box(0.0, 3.0))]);
    write_frame(&data, "b", vec![object("bed", unit_box(0.0, 3.0))]);
    let write = |frame: &str, detections: Vec<Detection>| {
        FrameDetections { frame: frame.into(), detections }.write(&dets.join(format!("{frame}.json"))).unwrap();
    };
    write("a", vec![det("bed", unit_box(0.0, 3.0), 0.9), det("bed", unit_box(FAR, 3.0), 0.8)]);
    write("b", vec![det("bed", unit_box(0.0, 3.0), 0.3)]);
    let run = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
            .args(["eval", "--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap(), "--diagnose"])
            .args(extra)
            .output()
            .unwrap()
    };

    let out = run(&["--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    let diagnosis = report["diagnosis"].as_object().unwrap();
    assert_eq!(diagnosis.len(), 10, "the ten large categories");
    let bed = diagnosis["bed"].as_object().unwrap();
    let keys = [
        "gt_boxes",
        "window_recall_25",
        "window_recall_50",
        "window_mean_best_iou",
        "frames_with_category",
        "frames_with_detections",
        "best_is_tp",
        "ap",
        "rank_ap",
        "false_positives",
        "oracle_ap",
        "objects",
    ];
    let mut expected: Vec<&str> = keys.to_vec();
    expected.sort();
    assert_eq!(bed.keys().map(String::as_str).collect::<Vec<_>>(), expected);
    assert_eq!(bed["gt_boxes"], 2);
    assert!(bed["window_recall_25"].is_null(), "no --models: no window recall");
    assert_eq!((bed["frames_with_category"].as_u64(), bed["frames_with_detections"].as_u64()), (Some(2), Some(2)));
    let num = |v: &Value| v.as_f64().unwrap();
    assert!((num(&bed["best_is_tp"]) - 1.0).abs() < 1e-6);
    assert!((num(&bed["ap"]) - 5.0 / 6.0).abs() < 1e-5);
    assert!((num(&bed["rank_ap"]) - 1.0).abs() < 1e-6);
    assert!(diagnosis["sofa"]["ap"].is_null() && diagnosis["sofa"]["best_is_tp"].is_null());
    // The one false positive (a's far box) is background in a frame with a bed.
    let fp = &bed["false_positives"];
    assert_eq!((fp["examined"].as_u64(), fp["background_in_frame"].as_u64()), (Some(1), Some(1)));
    // Overlay: one box per frame, a's best (TP) and b's (TP).
    let overlay = &report["overlay_precision"];
    assert_eq!((overlay["true_positives"].as_u64(), overlay["shown"].as_u64()), (Some(2), Some(2)));
    assert!((num(&overlay["precision"]) - 1.0).abs() < 1e-6);
    // As drawn (detect's defaults: 8 a frame, floor 0.5 — which these uncalibrated scores are not cut
    // by): a's two boxes (one false) and b's.
    let drawn = &report["overlay_drawn"];
    assert_eq!((drawn["top"].as_u64(), num(&drawn["min_probability"])), (Some(8), 0.5));
    let counts = |d: &Value| ["true_positives", "shown", "frames", "frames_without_boxes"].map(|k| d[k].as_u64());
    assert_eq!(counts(drawn), [Some(2), Some(3), Some(2), Some(0)]);
    // Its false one, a's far box, is background in a frame with a bed; the top-k line has none.
    let kinds = |d: &Value| {
        ["duplicate", "localisation", "confusion", "background_in_frame", "background_elsewhere"]
            .map(|k| d["false_kinds"][k].as_u64())
    };
    assert_eq!(kinds(drawn), [Some(0), Some(0), Some(0), Some(1), Some(0)]);
    assert_eq!(kinds(overlay), [Some(0); 5]);
    // The scores as probabilities: a's 0.9 (true) and 0.8 (false) in the two top bins, b's 0.3 (true).
    let bins = report["reliability"]["bins"].as_array().unwrap();
    let binned: Vec<[Option<u64>; 2]> =
        bins.iter().map(|b| [b["detections"].as_u64(), b["true_positives"].as_u64()]).collect();
    let [none, one, hit] = [[Some(0), Some(0)], [Some(1), Some(0)], [Some(1), Some(1)]];
    assert_eq!(binned, [none, none, none, hit, none, none, none, none, one, hit]);
    assert!((num(&report["reliability"]["expected_calibration_error"]) - (0.7 + 0.8 + 0.1) / 3.0).abs() < 1e-6);
    let out = run(&["--json", "--overlay-top", "1"]);
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(counts(&report["overlay_drawn"]), [Some(2), Some(2), Some(2), Some(0)]);

    let out = run(&[]);
    assert!(out.status.success());
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains(
            "false ones: 0 duplicates, 0 poorly placed (IoU 0.1–0.25 with one of their category), 0 on \
                        another category's object, 1 on background (1 in frames with their category, 0 without)"
        ),
        "the drawn line's false boxes by kind: {table}"
    );
    let bed_line = table.lines().find(|l| l.starts_with("bed ")).expect("a bed row");
    assert_eq!(
        bed_line.split_whitespace().collect::<Vec<_>>(),
        ["bed", "2", "-", "-", "-", "2", "2", "100.0", "83.3", "100.0"]
    );
    assert!(table.contains("2/2 = 100.0"), "{table}");
    assert!(table.contains("expected calibration error 0.5333 over 3 detections"), "{table}");
    assert!(table.contains("2/3 = 66.7; 1.50 boxes per frame, 0 of 2 frames without a box"), "{table}");
    // The oracle table: a's far box is background; without it both true positives come first.
    let oracle = table.split("AP without the false positives").nth(1).expect("the oracle table");
    for name in ["bed", "mean"] {
        let line = oracle.lines().find(|l| l.starts_with(&format!("{name} "))).expect("a row");
        assert_eq!(
            line.split_whitespace().collect::<Vec<_>>(),
            [name, "83.3", "83.3", "83.3", "83.3", "100.0", "100.0", "100.0"],
            "{table}"
        );
    }
    assert_eq!(bed["oracle_ap"]["without_background"].as_f64(), Some(1.0));
    // Both beds found: a's first (precision 1), b's after a's far box (precision 2/3) — both ahead.
    let objects = &bed["objects"];
    let counts = ["found_ahead", "found_behind", "missed_near", "missed_far", "missed_with_other"];
    assert_eq!(counts.map(|k| objects[k].as_u64()), [Some(2), Some(0), Some(0), Some(0), Some(0)]);
    assert!(report.get("objects").is_none(), "the list only with --objects");
    let summary = table.split("ground-truth boxes: found ahead").nth(1).expect("the objects table");
    let line = summary.lines().find(|l| l.starts_with("bed ")).expect("a bed row");
    assert_eq!(line.split_whitespace().collect::<Vec<_>>(), ["bed", "2", "2", "0", "0", "0", "0"]);
    let out = run(&["--json", "--objects"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let listed: Value = serde_json::from_slice(&out.stdout).unwrap();
    let listed = listed["objects"].as_array().expect("--objects lists the boxes");
    assert_eq!(listed.len(), 2);
    assert_eq!((listed[0]["frame"].as_str(), listed[1]["frame"].as_str()), (Some("a"), Some("b")));
    assert_eq!(listed[1]["category"], "bed");
    assert_eq!(listed[1]["found"]["false_positives_before"], 1);
    assert!((num(&listed[1]["found"]["precision"]) - 2.0 / 3.0).abs() < 1e-6);
    assert!((num(&listed[1]["distance_m"]) - 3.0).abs() < 1e-6);
    // The share in view, by hand from the tiny frame's camera (fx = fy = 10, principal point (4.5, 3.5)
    // 1-based, 8 × 6 pixels, Rtilt = I): u = 10·x/y + 3.5 stays inside for every cell of the unit box at
    // y ∈ [2.5, 3.5] (|x|/y ≤ 0.18 < 0.4); v = 2.5 − 10·z/y is inside for z/y ≤ 0.3. Cell centres z = 0.05 …
    // 0.95 against y = 2.55 … 3.45: 8, 8, 8, 9, 9, 9, 9, 10, 10, 10 of the ten z per y → 90 of 100.
    assert!((num(&listed[1]["in_view"]) - 0.9).abs() < 1e-6, "{}", listed[1]["in_view"]);
    let out = run(&["--objects"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines()
            .any(|l| l.starts_with("b #0 bed") && l.contains("found at 0.300") && l.contains("1 false positives")),
        "{text}"
    );
    let words = |l: &str| l.split_whitespace().map(str::to_string).collect::<Vec<_>>();
    assert!(text.lines().any(|l| words(l).starts_with(&["bed", "0", "of", "2"].map(String::from))), "{text}");

    // Flags: --models needs --diagnose; a missing models directory is named.
    let plain = Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
        .args(["eval", "--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap(), "--models", "x"])
        .output()
        .unwrap();
    assert!(!plain.status.success());
    let out = run(&["--models", tmp.path().join("no-models").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-models"), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn cli_window_recall_with_models() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets, models) = (tmp.path().join("data"), tmp.path().join("dets"), tmp.path().join("models"));
    std::fs::create_dir_all(&dets).unwrap();
    std::fs::create_dir_all(&models).unwrap();
    let synthetic = synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap();
    let frame_dir = data.join(&synthetic.frame.name);
    synthetic.write(&frame_dir, None).unwrap();
    let category = synthetic.frame.objects[0].category.clone();
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::GEOM).unwrap();
    let model = Model::new(
        &category,
        layout,
        SizeQuantiles {
            widths: vec![0.5, 0.8, 1.1, 1.4, 1.8],
            depths: vec![0.5, 1.0, 2.0],
            heights: vec![0.4, 0.8, 1.6],
        },
        WindowSettings {
            step: 0.1,
            min_points: 20,
            yaw_anchor: YawAnchor::Walls,
            support: Support::Floor,
            lattice: LatticePhase::Camera,
            supporters: cog_gpu::category::SurfaceCategories::ALL,
        },
        FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
        vec![0.0; layout.dim()],
        serde_json::Value::Null,
    )
    .unwrap();
    model.write(&models.join(format!("{category}.json"))).unwrap();

    let out = Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
        .args(["eval", "--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap()])
        .args(["--diagnose", "--json", "--categories", &category, "--models", models.to_str().unwrap()])
        .args(["--step", "0.3"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    let entry = &report["diagnosis"][&category];

    // The same computation in the library, on the frame as read back, at the --step override.
    let frame = Frame::read(&frame_dir, Default::default()).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    let mut stepped = model.clone();
    stepped.window.step = 0.3;
    let best = frame_window_best_ious(&pre, &[stepped], &frame.objects, true);
    let expected = WindowRecall::from_best_ious(&best[&category]);
    assert_eq!(entry["gt_boxes"].as_u64(), Some(expected.boxes as u64));
    for (key, value) in [
        ("window_recall_25", expected.recall_25),
        ("window_recall_50", expected.recall_50),
        ("window_mean_best_iou", expected.mean_best_iou),
    ] {
        let got = entry[key].as_f64().unwrap_or_else(|| panic!("{key} is {}", entry[key]));
        assert!((0.0..=1.0).contains(&got));
        assert!((got - value.unwrap() as f64).abs() < 1e-6, "{key}: {got} vs {value:?}");
    }
    // No detection files: no detections, no AP beyond 0, overlay shows nothing.
    assert_eq!(entry["frames_with_detections"], 0);
    assert_eq!(report["overlay_precision"]["shown"], 0);
    assert!(report["overlay_precision"]["precision"].is_null());
}

/// `--objects` names each ground-truth box by its index in the frame's annotation, with boxes left out
/// by `--ignore-out-of-view` too: those runs named the kept boxes by their place among the kept ones (a
/// chair #5 became #4 after an ignored bed). Twelve synthetic frames (seed 7, boxes mostly out of the
/// picture among them) without detections: every box the run with the option lists is the run without
/// it's box of that frame and index — same category, size and share in view — and some ignored box
/// comes before a kept one of its frame, so the indices had something to shift.
#[test]
fn objects_keep_their_annotation_index_when_out_of_view_boxes_are_ignored() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, dets) = (tmp.path().join("data"), tmp.path().join("dets"));
    std::fs::create_dir_all(&dets).unwrap();
    for index in 0..12 {
        let synthetic = synth::generate_frame(7, index, &SynthOptions::small(320, 240)).unwrap();
        synthetic.write(&data.join(&synthetic.frame.name), None).unwrap();
        FrameDetections { frame: synthetic.frame.name.clone(), detections: vec![] }
            .write(&dets.join(format!("{}.json", synthetic.frame.name)))
            .unwrap();
    }
    let objects = |extra: &[&str]| -> Vec<Value> {
        let out = Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
            .args(["eval", "--data", data.to_str().unwrap(), "--detections", dets.to_str().unwrap()])
            .args(["--diagnose", "--objects", "--categories", "all", "--json"])
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let report: Value = serde_json::from_slice(&out.stdout).unwrap();
        report["objects"].as_array().unwrap().clone()
    };
    let all = objects(&[]);
    let kept = objects(&["--ignore-out-of-view", "0.25"]);
    let key = |o: &Value| (o["frame"].as_str().unwrap().to_string(), o["object"].as_u64().unwrap());
    let by_key: std::collections::BTreeMap<_, _> = all.iter().map(|o| (key(o), o)).collect();
    assert!(kept.len() < all.len(), "no box was ignored: {} boxes", all.len());
    for o in &kept {
        let same = by_key.get(&key(o)).unwrap_or_else(|| panic!("{:?} is no box of the annotation", key(o)));
        for field in ["category", "size", "in_view"] {
            assert_eq!(o[field], same[field], "{:?}: {field}", key(o));
        }
    }
    let kept_keys: std::collections::BTreeSet<_> = kept.iter().map(key).collect();
    let shifted = all.iter().map(key).any(|(frame, object)| {
        !kept_keys.contains(&(frame.clone(), object)) && kept_keys.iter().any(|(f, o)| *f == frame && *o > object)
    });
    assert!(shifted, "no ignored box comes before a kept one of its frame");

    // The index is the box's position in the file's `objects` array: with a null entry and a wall put
    // before the boxes of one frame's file (entries the reader skips), that frame's boxes are listed two
    // further on, and each names its own entry (it named the position among the boxes read, 2026-12-08).
    let first = all[0]["frame"].as_str().unwrap().to_string();
    let file = data.join(&first).join("annotation3Dfinal/index.json");
    let mut annotation: Value = serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    let entries = annotation["objects"].as_array_mut().unwrap();
    entries.insert(0, serde_json::json!({"name": "wall"}));
    entries.insert(0, Value::Null);
    std::fs::write(&file, annotation.to_string()).unwrap();
    let moved = objects(&[]);
    assert_eq!(moved.len(), all.len());
    for (before, after) in all.iter().zip(&moved) {
        let shift = if before["frame"] == first.as_str() { 2 } else { 0 };
        assert_eq!(after["object"].as_u64().unwrap(), before["object"].as_u64().unwrap() + shift, "{after}");
        if shift == 2 {
            let entry = &annotation["objects"][after["object"].as_u64().unwrap() as usize];
            let name = entry["name"].as_str().unwrap().to_lowercase();
            let category = after["category"].as_str().unwrap();
            assert!(name.starts_with(category), "entry {entry} for a {category}");
        }
    }
}
