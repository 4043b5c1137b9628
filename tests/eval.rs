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
