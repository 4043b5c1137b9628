//! 3D non-maximum suppression against hand cases and a brute-force reference.

use cog_gpu::eval::Detection;
use cog_gpu::geometry::{iou_3d, Cuboid};
use cog_gpu::nms::{nms_detections, suppress, vote, NmsOptions, VoteOptions, DEFAULT_NMS_IOU};
use glam::Vec3;

fn unit_box(x: f32, y: f32) -> Cuboid {
    Cuboid::new(Vec3::new(x, y, 0.5), Vec3::ONE, 0.0)
}

fn options(iou: f32) -> NmsOptions {
    NmsOptions { iou_threshold: iou, max_detections: None, top_k: None }
}

#[test]
fn two_overlapping_and_one_far() {
    // B is A shifted by 0.2: IoU = 0.8 / 1.2 = 2/3. C is far away.
    let boxes = [unit_box(0.2, 0.0), unit_box(5.0, 0.0), unit_box(0.0, 0.0)];
    let scores = [0.8, 0.7, 0.9];
    assert_eq!(suppress(&boxes, &scores, &options(DEFAULT_NMS_IOU)), [2, 1]);
    // Nothing overlaps by more than 2/3.
    assert_eq!(suppress(&boxes, &scores, &options(0.7)), [2, 0, 1]);
}

#[test]
fn chain_a_suppresses_b_but_not_c() {
    // Shifts of 0.5: IoU(A, B) = IoU(B, C) = 0.5 / 1.5 = 1/3, IoU(A, C) = 0 (they touch).
    // B goes, and a suppressed box suppresses nothing, so C stays.
    let boxes = [unit_box(0.0, 0.0), unit_box(0.5, 0.0), unit_box(1.0, 0.0)];
    let scores = [0.9, 0.8, 0.7];
    assert_eq!(suppress(&boxes, &scores, &options(0.25)), [0, 2]);
    // Above the threshold 1/3 nothing is suppressed; the comparison is strict (`>`).
    assert_eq!(suppress(&boxes, &scores, &options(0.4)), [0, 1, 2]);
    // With C scoring highest, C then A are kept (IoU 0) and B, overlapping both, goes.
    assert_eq!(suppress(&boxes, &[0.8, 0.7, 0.9], &options(0.25)), [2, 0]);
}

#[test]
fn ties_keep_input_order() {
    let boxes = [unit_box(0.0, 0.0), unit_box(0.0, 0.0), unit_box(3.0, 0.0), unit_box(3.1, 0.0)];
    let scores = [0.5, 0.5, 0.5, 0.5];
    assert_eq!(suppress(&boxes, &scores, &options(0.25)), [0, 2]);
    // The same with a top-K prefilter, which selects among equal scores by position too.
    let top3 = NmsOptions { top_k: Some(3), ..options(0.25) };
    assert_eq!(suppress(&boxes, &scores, &top3), [0, 2]);
}

#[test]
fn nested_and_thin_boxes() {
    // A unit box inside a 2 m cube: IoU = 1/8, kept at 0.25. A box 0.9 m high in the unit box: IoU 0.9.
    let boxes = [
        Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::splat(2.0), 0.0),
        unit_box(0.0, 0.0),
        Cuboid::new(Vec3::new(0.0, 0.0, 0.45), Vec3::new(1.0, 1.0, 0.9), std::f32::consts::FRAC_PI_2),
    ];
    assert_eq!(suppress(&boxes, &[0.9, 0.8, 0.7], &options(0.25)), [0, 1]);
    // Stacked boxes (disjoint heights) never suppress each other, whatever the footprints.
    let stacked = [unit_box(0.0, 0.0), Cuboid::new(Vec3::new(0.0, 0.0, 1.5), Vec3::ONE, 0.0)];
    assert_eq!(suppress(&stacked, &[0.9, 0.8], &options(0.0)), [0, 1]);
}

#[test]
fn limits_and_non_finite_scores() {
    let boxes: Vec<Cuboid> = (0..5).map(|i| unit_box(3.0 * i as f32, 0.0)).collect();
    let scores = [0.1, 0.5, f32::NAN, 0.9, 0.3];
    assert_eq!(suppress(&boxes, &scores, &options(0.25)), [3, 1, 4, 0]);
    let at_most_two = NmsOptions { max_detections: Some(2), ..options(0.25) };
    assert_eq!(suppress(&boxes, &scores, &at_most_two), [3, 1]);
    let top_one = NmsOptions { top_k: Some(1), ..options(0.25) };
    assert_eq!(suppress(&boxes, &scores, &top_one), [3]);
    assert!(NmsOptions::with_iou(1.5).is_err());
    assert!(NmsOptions::with_iou(f32::NAN).is_err());
}

#[test]
fn categories_do_not_suppress_each_other() {
    let b = unit_box(0.0, 0.0);
    let dets = vec![
        Detection::new("chair", &b, 0.6),
        Detection::new("bed", &b, 0.9),
        Detection::new("bed", &unit_box(0.1, 0.0), 0.8),
        Detection::new("chair", &unit_box(0.1, 0.0), 0.95),
    ];
    let kept = nms_detections(&dets, &NmsOptions::default());
    let summary: Vec<(&str, f32)> = kept.iter().map(|d| (d.category.as_str(), d.score)).collect();
    assert_eq!(summary, [("chair", 0.95), ("bed", 0.9)]);
}

/// Plain greedy NMS without any shortcut: the reference for the cheap rejections.
fn reference(boxes: &[Cuboid], scores: &[f32], threshold: f32) -> Vec<usize> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| scores[b].partial_cmp(&scores[a]).unwrap());
    let mut kept: Vec<usize> = Vec::new();
    for i in order {
        if kept.iter().all(|&k| iou_3d(&boxes[i], &boxes[k]) <= threshold) {
            kept.push(i);
        }
    }
    kept
}

#[test]
fn matches_brute_force_on_random_boxes() {
    // A small linear congruential generator keeps the test deterministic without a dependency.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut boxes = Vec::new();
    let mut scores = Vec::new();
    for i in 0..400 {
        let centre = Vec3::new(4.0 * next(), 4.0 * next(), 0.3 + 0.6 * next());
        let size = Vec3::new(0.3 + 1.5 * next(), 0.3 + 1.5 * next(), 0.3 + 1.0 * next());
        boxes.push(Cuboid::new(centre, size, std::f32::consts::TAU * next()));
        // Distinct scores so that the reference's unstable tie handling does not matter.
        scores.push(next() + i as f32 * 1e-3);
    }
    for threshold in [0.05, 0.25, 0.5] {
        let kept = suppress(&boxes, &scores, &options(threshold));
        assert_eq!(kept, reference(&boxes, &scores, threshold), "threshold {threshold}");
        assert!(kept.len() > 5 && kept.len() < 400);
    }
}

// Box voting (`nms::vote`): each kept box becomes the weighted mean of the candidates around it.

fn vote_options(slope: f32) -> VoteOptions {
    VoteOptions { iou: 0.5, slope, min_weight: 1e-3 }
}

#[test]
fn voting_averages_the_voters_by_their_odds_ratio() {
    // Kept K at x = 0 (score 2); V at x = 0.2 (IoU 2/3, score 2 − ln 3 with slope 1: weight 1/3);
    // W at x = 0.6 (IoU 0.4 / 1.6 = 0.25 < 0.5: no vote). Mean x = (0 · 1 + 0.2 · 1/3) / (4/3) = 0.05.
    let boxes = [unit_box(0.0, 0.0), unit_box(0.2, 0.0), unit_box(0.6, 0.0)];
    let scores = [2.0, 2.0 - 3.0f32.ln(), 1.0];
    let voted = vote(&[0], [0, 1, 2], |i| boxes[i], |i| scores[i], &vote_options(1.0));
    assert_eq!(voted.len(), 1);
    assert!((voted[0].centre.x - 0.05).abs() < 1e-6, "{:?}", voted[0]);
    assert!((voted[0].centre.y).abs() < 1e-6 && (voted[0].centre.z - 0.5).abs() < 1e-6);
    assert!((voted[0].size - Vec3::ONE).abs().max_element() < 1e-6);
    // The slope scales the weights: with slope 2 the weight is 1/9, the mean x 0.2 · (1/9) / (10/9) = 0.02.
    let voted = vote(&[0], [0, 1, 2], |i| boxes[i], |i| scores[i], &vote_options(2.0));
    assert!((voted[0].centre.x - 0.02).abs() < 1e-6, "{:?}", voted[0]);
}

#[test]
fn voting_maps_a_quarter_turn_into_the_kept_axes_and_skips_other_yaws() {
    // K: 2 × 1 × 1 at yaw 0. V: the same box given as 1 × 2.4 × 1 at yaw π/2 (width and depth swapped;
    // 2.4 along x: IoU 2/2.4), equal score: the mean size along K's width is (2 + 2.4) / 2 = 2.2.
    // U: yaw π/4 off, overlapping by more than 0.5, does not vote.
    let k = Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::new(2.0, 1.0, 1.0), 0.0);
    let v = Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::new(1.0, 2.4, 1.0), std::f32::consts::FRAC_PI_2);
    let u = Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::new(2.0, 1.0, 1.0), 0.1);
    assert!(iou_3d(&k, &v) >= 0.5 && iou_3d(&k, &u) >= 0.5);
    let boxes = [k, v, u];
    let voted = vote(&[0], [0, 1, 2], |i| boxes[i], |_| 1.0, &vote_options(1.0));
    assert!((voted[0].size - Vec3::new(2.2, 1.0, 1.0)).abs().max_element() < 1e-6, "{:?}", voted[0]);
    assert_eq!(voted[0].yaw, 0.0);
    // A half turn is the same box's axes: sizes are not swapped.
    let h = Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::new(2.4, 1.0, 1.0), std::f32::consts::PI);
    let boxes = [k, h];
    let voted = vote(&[0], [0, 1], |i| boxes[i], |_| 1.0, &vote_options(1.0));
    assert!((voted[0].size - Vec3::new(2.2, 1.0, 1.0)).abs().max_element() < 1e-6, "{:?}", voted[0]);
}

#[test]
fn voting_stops_below_the_weight_floor_and_each_kept_box_gets_its_own_voters() {
    // Two kept boxes far apart, each with a voter beside it; a third candidate next to the first scores
    // so low (weight e^−10 < 10⁻³) that it is not counted. A voter of both? None here: they are 5 m apart.
    let boxes = [unit_box(0.0, 0.0), unit_box(5.0, 0.0), unit_box(0.2, 0.0), unit_box(5.2, 0.0), unit_box(-0.2, 0.0)];
    let scores = [3.0, 2.0, 3.0, 2.0, -7.0];
    let voted = vote(&[0, 1], [0, 2, 1, 3, 4], |i| boxes[i], |i| scores[i], &vote_options(1.0));
    assert!((voted[0].centre.x - 0.1).abs() < 1e-6, "{:?}", voted[0]);
    assert!((voted[1].centre.x - 5.1).abs() < 1e-6, "{:?}", voted[1]);
    // The low box alone would pull the first to −0.1 if it counted with weight 1.
    let voted = vote(&[0], [0, 4], |i| boxes[i], |i| scores[i], &vote_options(1.0));
    assert_eq!(voted[0], boxes[0]);
}

#[test]
fn voting_can_move_a_weak_kept_box_onto_a_strong_one_which_the_nms_run_again_drops() {
    // A (x = 0, score 5) and B (x = 0.8, score 0) are both kept by the NMS at 0.15 (IoU 0.2 / 1.8 = 0.11);
    // C (x = 0.4, score 5 − 10⁻³, so that A is kept first) is suppressed by A (IoU 0.6 / 1.4 = 0.43). At
    // voting IoU 0.3, C votes for both (IoU 0.43 with each): for A with weight e^−0.001 ≈ 1 (A moves to
    // x ≈ 0.2), for B with weight e^4.999 ≈ 148 against B's own 1, so B moves to x ≈ 0.403 — onto A's
    // object: IoU ≈ 0.80 / 1.20 with the voted A. The NMS run again over the voted boxes (as `detect`
    // does) keeps A alone.
    let boxes = [unit_box(0.0, 0.0), unit_box(0.8, 0.0), unit_box(0.4, 0.0)];
    let scores = [5.0, 0.0, 5.0 - 1e-3];
    let kept = suppress(&boxes, &scores, &options(DEFAULT_NMS_IOU));
    assert_eq!(kept, vec![0, 1]);
    let voting = VoteOptions { iou: 0.3, slope: 1.0, min_weight: 1e-3 };
    let voted = vote(&kept, [0, 1, 2], |i| boxes[i], |i| scores[i], &voting);
    let (wa, wb) = ((-1e-3f32).exp(), (5.0f32 - 1e-3).exp());
    assert!((voted[0].centre.x - 0.4 * wa / (1.0 + wa)).abs() < 1e-5, "{:?}", voted[0]);
    assert!((voted[1].centre.x - (0.8 + 0.4 * wb) / (1.0 + wb)).abs() < 1e-5, "{:?}", voted[1]);
    assert!(iou_3d(&voted[0], &voted[1]) > 0.6, "{}", iou_3d(&voted[0], &voted[1]));
    let detections: Vec<Detection> =
        voted.iter().zip(&kept).map(|(c, &k)| Detection::new("bed", c, scores[k])).collect();
    let again = nms_detections(&detections, &options(DEFAULT_NMS_IOU));
    assert_eq!(again, vec![detections[0].clone()]);
}

/// The cheap bound's slack widens it (it shrank it before 2026-12-08): a box whose exact IoU with a kept one
/// is a rounding step above the threshold is suppressed, and a voter whose IoU is exactly the vote IoU
/// votes. Boxes on one footprint from one bottom: their IoU is the ratio of their heights, and the bound
/// (footprints' overlap × heights' overlap) is exact.
#[test]
fn a_box_a_rounding_step_above_the_threshold_is_suppressed_and_a_voter_at_it_votes() {
    let tall = Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::ONE, 0.0);
    let threshold = 0.15f32;
    let height = threshold.next_up();
    let low = Cuboid::new(Vec3::new(0.0, 0.0, 0.5 * height), Vec3::new(1.0, 1.0, height), 0.0);
    let iou = iou_3d(&tall, &low);
    assert!(iou > threshold && iou < threshold * (1.0 + 1e-6), "{iou}");
    assert_eq!(suppress(&[tall, low], &[1.0, 0.5], &options(threshold)), [0]);
    // A voter of half the height: IoU exactly 0.5, the vote IoU. Equal scores, weight 1 each: the mean
    // centre height (0.5 + 0.25) / 2, the mean height (1 + 0.5) / 2.
    let half = Cuboid::new(Vec3::new(0.0, 0.0, 0.25), Vec3::new(1.0, 1.0, 0.5), 0.0);
    assert_eq!(iou_3d(&tall, &half), 0.5);
    let boxes = [tall, half];
    let voted = vote(&[0], [0, 1], |i| boxes[i], |_| 1.0, &vote_options(1.0));
    assert!((voted[0].centre.z - 0.375).abs() < 1e-6 && (voted[0].size.z - 0.75).abs() < 1e-6, "{:?}", voted[0]);
}
