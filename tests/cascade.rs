//! The context cascade: the linear SVM against closed-form solutions, the context features against a hand
//! computation, and training on constructed frames where only the context tells true from false.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

mod common;

use cog_gpu::cascade::{
    check_cross_scores, feature_dim, frame_context_features, stage_checkpoint_path, train_cascade,
    train_cascade_resumable, wall_context, Cascade, CascadeFrame, CascadeTraining, FeatureSet, Room, StageRule,
    FEATURES, GEOMETRY_FEATURES, LAYOUT_FEATURES, NEIGHBOURHOOD_MARGIN, PREVIOUS_FEATURES, RBF_CENTRES, RBF_WIDTHS,
    V4_FEATURES, V5_FEATURES, V6_FEATURES,
};
use cog_gpu::category::CROSS_SCORE_CATEGORIES;
use cog_gpu::eval::{average_precision, Detection, FrameDetections, ScoredBox};
use cog_gpu::frame::Object;
use cog_gpu::geometry::Cuboid;
use cog_gpu::learn::binary_svm::{balanced_costs, train_linear_svm};
use glam::{Vec2, Vec3};

#[test]
fn hard_margin_svm_is_the_perpendicular_bisector() {
    // (0, 0) negative, (2, 0) positive: the maximum-margin line is x = 1, so w = (1, 0), b = −1 (both points
    // on the margin). A large C makes the soft margin hard.
    let samples = vec![vec![0.0, 0.0], vec![2.0, 0.0]];
    let labels = [false, true];
    let svm = train_linear_svm(&samples, &labels, &[1e4, 1e4]).unwrap();
    assert!((svm.weights[0] - 1.0).abs() < 1e-4, "{svm:?}");
    assert!(svm.weights[1].abs() < 1e-4, "{svm:?}");
    assert!((svm.bias + 1.0).abs() < 1e-4, "{svm:?}");
}

#[test]
fn soft_margin_svm_shrinks_as_the_closed_form_says() {
    // x = −1 negative, x = +1 positive, each with cost c: for w < 1 both slacks are 1 − w (at b = 0, and
    // no b does better), so ½w² + 2c(1 − w) is smallest at w = 2c. Balanced costs at C give c = C here.
    let samples = vec![vec![-1.0], vec![1.0]];
    let labels = [false, true];
    let costs = balanced_costs(&labels, 0.1);
    assert_eq!(costs, vec![0.1, 0.1]);
    let svm = train_linear_svm(&samples, &labels, &costs).unwrap();
    assert!((svm.weights[0] - 0.2).abs() < 1e-4, "{svm:?}");
    assert!(train_linear_svm(&samples, &[true, true], &costs).is_err());
}

#[test]
fn balanced_costs_give_each_class_the_same_weight() {
    let labels = [true, false, false, false];
    let costs = balanced_costs(&labels, 2.0);
    let positive: f64 = costs.iter().zip(&labels).filter(|(_, &y)| y).map(|(c, _)| c).sum();
    let negative: f64 = costs.iter().zip(&labels).filter(|(_, &y)| !y).map(|(c, _)| c).sum();
    assert!((positive - negative).abs() < 1e-12 && (positive + negative - 2.0 * 4.0).abs() < 1e-12);
}

fn detection(category: &str, centre: [f32; 3], size: [f32; 3], probability: f32, raw: f32) -> Detection {
    let mut d = Detection::new(category, &Cuboid::new(Vec3::from(centre), Vec3::from(size), 0.0), probability);
    d.raw_score = Some(raw);
    d
}

fn names(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

#[test]
fn context_features_match_a_hand_computation() {
    let detections = vec![
        // i: a unit table box at the origin, p = 0.5.
        detection("table", [0.0, 0.0, 0.5], [1.0, 1.0, 1.0], 0.5, 0.0),
        // The most confident overlapping bed: x from −0.5 to 1.5, so the overlap is the whole table (1 m³).
        detection("bed", [0.5, 0.0, 0.5], [2.0, 1.0, 1.0], 0.8, 0.0),
        // A less confident overlapping bed, and a more confident bed that does not overlap: both ignored.
        detection("bed", [0.0, 0.2, 0.5], [1.0, 1.0, 1.0], 0.3, 0.0),
        detection("bed", [5.0, 0.0, 0.5], [2.0, 1.0, 1.0], 0.9, 0.0),
        // A chair far away: its block stays zero.
        detection("chair", [0.0, 6.0, 0.5], [0.5, 0.5, 1.0], 0.7, 0.0),
    ];
    let categories = names(&["bed", "chair", "table"]);
    let psi = &frame_context_features(&detections, &categories, None, FeatureSet::V4)[0];
    assert_eq!(psi.len(), feature_dim(3));
    // S1 = O/V_i = 1, S2 = O/V_j = 0.5, S3 = O/U = 1/(1 + 2 − 1) = 0.5.
    let expected = [
        0.5, 0.25, // p_i, p_i²
        0.8, 0.8, 0.4, 0.4, 0.4, // bed: p_j, p_j·S1, p_j·S2, p_j·S3, p_i·p_j
        0.0, 0.0, 0.0, 0.0, 0.0, // chair
        0.0, 0.0, 0.0, 0.0, 0.0, // table: no other table
        1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, // no room
    ];
    assert_close(psi, &expected, "ψ");
    // v5 begins with the same numbers.
    let v5 = &frame_context_features(&detections, &categories, None, FeatureSet::V5)[0];
    assert_eq!(v5.len(), FeatureSet::V5.dim(3));
    assert_close(&v5[..expected.len()], &expected, "ψ v5's first part");
}

/// The neighbourhood and geometry parts of ψ (v5) against a hand computation: which detections are
/// neighbours (footprints within the margin, 3D overlap not needed), the sum of their confidences, and the
/// box's sides, height and bottom above the room's floor.
#[test]
fn neighbourhood_and_geometry_features_match_a_hand_computation() {
    assert_eq!(NEIGHBOURHOOD_MARGIN, 0.5, "the distances below are chosen around a 0.5 m margin");
    let detections = vec![
        // i: a table 1.2 m (y) × 0.8 m (x) × 0.75 m standing on the floor at z = −1.2 (the camera at 0).
        detection("table", [0.0, 0.0, -0.825], [0.8, 1.2, 0.75], 0.6, 0.0),
        // Chairs: one 0.3 m beyond the table's +x side (x from 0.7 to 1.2: a neighbour without any
        // overlap), one 0.6 m beyond its −y side (y from −1.2 to −1.7 is 0.6 m off: not a neighbour), one
        // overlapping the table.
        detection("chair", [0.95, 0.0, -0.75], [0.5, 0.5, 0.9], 0.4, 0.0),
        detection("chair", [0.0, -1.45, -0.75], [0.5, 0.5, 0.9], 0.9, 0.0),
        detection("chair", [0.2, 0.5, -0.75], [0.5, 0.5, 0.9], 0.25, 0.0),
        // A desk 0.45 m beyond the +y side, raised far above (its footprint still counts).
        detection("desk", [0.0, 1.3, 1.0], [0.8, 0.5, 0.75], 0.3, 0.0),
        // Another table 0.2 m off the −x side.
        detection("table", [-0.9, 0.0, -0.825], [0.6, 0.6, 0.75], 0.5, 0.0),
    ];
    let categories = names(&["chair", "desk", "table"]);
    let room = Room {
        corners: vec![Vec2::new(-3.0, -3.0), Vec2::new(3.0, -3.0), Vec2::new(3.0, 3.0), Vec2::new(-3.0, 3.0)],
        floor: -1.2,
    };
    let psi = &frame_context_features(&detections, &categories, Some(&room), FeatureSet::V5)[0];
    assert_eq!(psi.len(), FeatureSet::V5.dim(3));
    let neighbourhood = 2 + 5 * 3 + LAYOUT_FEATURES;
    // Chairs: 0.4 + 0.25 (the one 0.6 m off is out); the desk: 0.3; other tables: 0.5.
    assert_close(&psi[neighbourhood..neighbourhood + 3], &[0.65, 0.3, 0.5], "neighbourhood");
    // l = 1.2, s = 0.8, h = 0.75, bottom = −1.2 − (−1.2) = 0 above the floor.
    let geometry = &psi[neighbourhood + 3..];
    assert_eq!(geometry.len(), GEOMETRY_FEATURES);
    assert_close(geometry, &[1.2, 1.44, 0.8, 0.64, 0.75, 0.5625, 0.0, 0.0], "geometry");
    // The raised desk (i = 4): bottom 1.0 − 0.375 + 1.2 = 1.825 m above the floor; without a room, 0.
    let desk = &frame_context_features(&detections, &categories, Some(&room), FeatureSet::V5)[4];
    assert_close(&desk[neighbourhood + 3..], &[0.8, 0.64, 0.5, 0.25, 0.75, 0.5625, 1.825, 1.825 * 1.825], "desk");
    let roomless = &frame_context_features(&detections, &categories, None, FeatureSet::V5)[4];
    assert_close(&roomless[neighbourhood + 9..], &[0.0, 0.0], "desk without a room");
}

/// Every number of `got` within 1e-6 of `want`, lengths equal.
fn assert_close(got: &[f64], want: &[f64], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?}");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() < 1e-6, "{what}[{k}] = {g}, expected {w} ({got:?})");
    }
}

/// The paper's top-down overlap for small objects (§6.1): a monitor standing on a desk touches it (no 3D
/// overlap), yet sees it through their footprints; the desk, a large category, keeps the 3D rule, so it
/// does not see the monitor, and sees a chair pushed under it with the 3D S2, which differs from the
/// top-down one here.
#[test]
fn small_objects_see_their_supporters_from_above() {
    let detections = vec![
        // The desk: 1.2 × 0.6 m, top at 0.75 m, p = 0.8.
        detection("desk", [0.0, 0.0, 0.375], [1.2, 0.6, 0.75], 0.8, 0.0),
        // The monitor on it: 0.5 × 0.2 m footprint inside the desk's, from 0.75 m up, p = 0.5.
        detection("monitor", [0.1, 0.0, 0.95], [0.5, 0.2, 0.4], 0.5, 0.0),
        // A chair pushed 0.1 m under the desk (y from 0.2 to 1.0 m), 0.9 m tall, p = 0.6.
        detection("chair", [0.0, 0.6, 0.45], [0.5, 0.8, 0.9], 0.6, 0.0),
    ];
    let categories = names(&["chair", "desk", "monitor"]);
    let psi = frame_context_features(&detections, &categories, None, FeatureSet::V5);
    let block = |i: usize, k: usize| -> &[f64] { &psi[i][2 + 5 * k..2 + 5 * k + 5] };
    let close = |got: &[f64], want: [f64; 5], what: &str| assert_close(got, &want, what);
    // Monitor (i = 1) and desk: O = 0.1 m², V_i = 0.1, V_j = 0.72, U = 0.72.
    let (o, a_desk) = (0.5 * 0.2, 1.2 * 0.6);
    close(block(1, 1), [0.8, 0.8, 0.8 * o / a_desk, 0.8 * o / a_desk, 0.5 * 0.8], "monitor/desk");
    // Desk (i = 0, large) and monitor: the desk keeps the 3D overlap, in which the two boxes only touch,
    // so the desk does not see the monitor.
    close(block(0, 2), [0.0; 5], "desk/monitor");
    // Monitor and chair: apart from above (the monitor's y from −0.1 to 0.1 m), so nothing.
    close(block(1, 0), [0.0; 5], "monitor/chair");
    // Desk and chair (both large, 3D): footprint overlap 0.5 × 0.1 m = 0.05 m², heights 0–0.75 and 0–0.9:
    // O = 0.05 · 0.75 m³, V_desk = 0.54, V_chair = 0.36 (from above S2 would be 0.05 / 0.4 = 0.125, not 0.104).
    let o3 = 0.05 * 0.75;
    let (v_desk, v_chair) = (1.2 * 0.6 * 0.75, 0.5 * 0.8 * 0.9);
    let u = v_desk + v_chair - o3;
    close(block(0, 0), [0.6, 0.6 * o3 / v_desk, 0.6 * o3 / v_chair, 0.6 * o3 / u, 0.8 * 0.6], "desk/chair");
}

/// A cascade file of the v4 feature set (no neighbourhood or geometry parts) is read and rescores with v4's
/// ψ, for any categories; the sets before it are read when the categories are all large (whose features
/// did not change) and refused with the file named when one is small.
#[test]
fn earlier_feature_sets_are_read_and_rescore_with_their_own_features() {
    let training: Vec<_> = (0..20).map(frame).collect();
    let (mut cascade, _) =
        train_cascade(&training, &names(&["bed", "table"]), 0.25, CascadeTraining::default(), &[FeatureSet::V5])
            .unwrap();
    assert_eq!(cascade.features, V5_FEATURES);
    assert_eq!(FEATURES, V4_FEATURES, "the default set");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cascade.json");
    cascade.write(&path).unwrap();
    assert_eq!(Cascade::read(&path).unwrap().feature_set(), Some(FeatureSet::V5));
    // A v4 file: the same stages cut to v4's length.
    let v4_dim = FeatureSet::V4.dim(2);
    for stage in cascade.stages.values_mut() {
        stage.weights.truncate(v4_dim);
    }
    for name in [V4_FEATURES].into_iter().chain(PREVIOUS_FEATURES) {
        cascade.features = name.to_string();
        cascade.write(&path).unwrap();
        let read = Cascade::read(&path).unwrap();
        assert_eq!(read, cascade);
        assert_eq!(read.feature_set(), Some(FeatureSet::V4));
    }
    // Rescoring with the v4 file is the v4 ψ's dot product.
    let mut detections = frame(3).detections;
    let psi = frame_context_features(&detections, &cascade.categories, None, FeatureSet::V4);
    let stage = &cascade.stages["table"];
    let expected: Vec<f32> = (0..detections.len())
        .filter(|&i| detections[i].category == "table")
        .map(|i| {
            let context = stage.weights.iter().zip(&psi[i]).map(|(w, v)| w * v).sum::<f64>() + stage.bias;
            stage.calibration.probability(detections[i].raw_score.unwrap() + context as f32)
        })
        .collect();
    cascade.rescore(&mut detections, None).unwrap();
    let mut got: Vec<(f32, f32)> =
        detections.iter().filter(|d| d.category == "table").map(|d| (d.first_stage_score.unwrap(), d.score)).collect();
    got.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut want: Vec<(f32, f32)> =
        frame(3).detections.iter().filter(|d| d.category == "table").map(|d| d.score).zip(expected).collect();
    want.sort_by(|a, b| b.0.total_cmp(&a.0));
    assert_eq!(got, want);
    // With a small category: v4 is read, the sets before it are not.
    let stage = cascade.stages["table"].clone();
    cascade.categories.push("pillow".to_string());
    let mut longer = stage;
    longer.weights = vec![0.0; FeatureSet::V4.dim(3)];
    cascade.stages.insert("table".to_string(), longer);
    cascade.stages.remove("bed");
    for previous in PREVIOUS_FEATURES {
        cascade.features = previous.to_string();
        write_unchecked(&cascade, &path);
        let err = Cascade::read(&path).unwrap_err().to_string();
        assert!(err.contains("cascade.json") && err.contains(previous), "{err}");
    }
    cascade.features = V4_FEATURES.to_string();
    cascade.write(&path).unwrap();
    assert!(Cascade::read(&path).is_ok(), "the same file as v4 is read");
    // v4's length under v5's name: refused.
    cascade.features = V5_FEATURES.to_string();
    write_unchecked(&cascade, &path);
    let err = Cascade::read(&path).unwrap_err().to_string();
    assert!(err.contains("cascade.json") && err.contains("weights"), "{err}");
}

/// Frame `f` of a constructed set: a bed and a table (ground truth); the first stage finds the bed
/// (p 0.9) and two tables: the real one, and a "piece" of the bed that the table model scores higher.
fn frame(f: usize) -> CascadeFrame {
    let object = |category: &str, centre: [f32; 3], size: [f32; 3]| Object {
        category: category.into(),
        label: None,
        cuboid: Cuboid::new(Vec3::from(centre), Vec3::from(size), 0.0),
    };
    let bed = ([0.0, 2.0, 0.5], [2.0, 1.6, 1.0]);
    let table = ([4.0, 2.0, 0.4], [1.0, 0.6, 0.8]);
    let truth = vec![object("bed", bed.0, bed.1), object("table", table.0, table.1)];
    let noise = (f as f32 * 1.7).sin() * 0.3;
    let (raw_false, raw_true) = (1.0 + noise, 0.7 - noise);
    let sigmoid = |s: f32| 1.0 / (1.0 + (-s).exp());
    let detections = vec![
        detection("bed", bed.0, bed.1, 0.9, 2.0),
        detection("table", [0.2, 2.0, 0.6], [1.0, 0.6, 0.8], sigmoid(raw_false), raw_false),
        detection("table", table.0, table.1, sigmoid(raw_true), raw_true),
    ];
    CascadeFrame { truth, detections, room: None }
}

fn category_ap(frames: &[CascadeFrame], category: &str) -> f32 {
    let boxes: Vec<ScoredBox> = frames
        .iter()
        .enumerate()
        .flat_map(|(image, frame)| {
            frame.detections.iter().filter(move |d| d.category == category).map(move |d| ScoredBox {
                image,
                score: d.score,
                cuboid: d.cuboid(),
            })
        })
        .collect();
    let truth: Vec<Vec<Cuboid>> = frames
        .iter()
        .map(|frame| frame.truth.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect())
        .collect();
    average_precision(&boxes, &truth, 0.25).ap.unwrap()
}

fn table_ap(frames: &[CascadeFrame]) -> f32 {
    category_ap(frames, "table")
}

#[test]
fn the_cascade_learns_that_a_table_on_a_bed_is_a_piece_of_the_bed() {
    let training: Vec<_> = (0..40).map(frame).collect();
    let categories = names(&["bed", "table"]);
    let (cascade, results) =
        train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V4]).unwrap();
    // Every bed detection is correct: no second stage can be learnt for it.
    assert!(results["bed"].chosen().is_err(), "{:?}", results["bed"].chosen());
    let stage = results["table"].chosen().unwrap();
    assert!(stage.cv_ap_cascade > stage.cv_ap_first_stage + 0.1, "{stage:?}");

    // Held-out frames: the first stage ranks the pieces of beds above most real tables; after the
    // cascade every real table is ranked above every piece.
    let mut test: Vec<_> = (100..140).map(frame).collect();
    let before = table_ap(&test);
    assert!(before < 0.8, "first-stage AP {before}");
    for CascadeFrame { detections, .. } in &mut test {
        cascade.rescore(detections, None).unwrap();
        assert!(detections.windows(2).all(|w| w[0].score >= w[1].score), "sorted by score");
        let bed = detections.iter().find(|d| d.category == "bed").unwrap();
        assert_eq!((bed.score, bed.context_score), (0.9, None), "a category without a stage is unchanged");
    }
    assert!((table_ap(&test) - 1.0).abs() < 1e-6, "cascade AP {}", table_ap(&test));
    assert!(test[0].detections.iter().filter(|d| d.category == "table").all(|d| d.first_stage_score.is_some()));

    // The rescoring reads only the first-stage list: any input order gives the same scores.
    let mut forward = frame(7).detections;
    let mut reversed = frame(7).detections;
    reversed.reverse();
    cascade.rescore(&mut forward, None).unwrap();
    cascade.rescore(&mut reversed, None).unwrap();
    let by_box = |dets: &[Detection]| -> BTreeMap<String, f32> {
        dets.iter().map(|d| (format!("{} {:?}", d.category, d.centre), d.score)).collect()
    };
    assert_eq!(by_box(&forward), by_box(&reversed));
    // Rescored detections are not first-stage input any more.
    let err = cascade.rescore(&mut forward, None).unwrap_err().to_string();
    assert!(err.contains("already rescored"), "{err}");
}

#[test]
fn cascade_files_round_trip_and_are_checked() {
    let training: Vec<_> = (0..20).map(frame).collect();
    let (cascade, _) =
        train_cascade(&training, &names(&["bed", "table"]), 0.25, CascadeTraining::default(), &[FeatureSet::V4])
            .unwrap();
    let dir = std::env::temp_dir().join(format!("cog-cascade-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cascade.json");
    cascade.write(&path).unwrap();
    assert_eq!(Cascade::read(&path).unwrap(), cascade);
    // One weight too few: refused with the file named — by the reader, and by `write` (nothing is
    // written that its readers would refuse).
    let mut broken = cascade.clone();
    broken.stages.get_mut("table").unwrap().weights.pop();
    let err = broken.write(&path).unwrap_err().to_string();
    assert!(err.contains("not written") && err.contains("weights"), "{err}");
    assert_eq!(Cascade::read(&path).unwrap(), cascade, "the file before is left alone");
    write_unchecked(&broken, &path);
    let err = Cascade::read(&path).unwrap_err().to_string();
    assert!(err.contains("cascade.json") && err.contains("weights"), "{err}");
    // The gain's interval out of order: refused, the stage named; absent (older files): read.
    let mut reversed = cascade.clone();
    reversed.stages.get_mut("table").unwrap().cv_gain_interval = Some([0.2, 0.1]);
    write_unchecked(&reversed, &path);
    let err = Cascade::read(&path).unwrap_err().to_string();
    assert!(err.contains("cascade.json") && err.contains("'table'") && err.contains("cv_gain_interval"), "{err}");
    let mut older = cascade.clone();
    older.stages.get_mut("table").unwrap().cv_gain_interval = None;
    write_unchecked(&older, &path);
    assert_eq!(Cascade::read(&path).unwrap(), older);
    assert!(!std::fs::read_to_string(&path).unwrap().contains("cv_gain_interval"));
    // Not a cascade at all (another JSON file, or no JSON): the file named and what it is not.
    for text in ["{\"format\": \"cog-gpu-model\"}", "hello"] {
        std::fs::write(&path, text).unwrap();
        let err = Cascade::read(&path).unwrap_err().to_string();
        assert!(err.contains("cascade.json") && err.contains("not a cog-gpu cascade file"), "{err}");
    }
    // The nested gain (`--keep nested-gain`): round-trips; outside [−1, 1] (not a difference of two APs),
    // refused.
    let mut nested = cascade.clone();
    nested.stages.get_mut("table").unwrap().cv_gain_nested = Some(0.125);
    nested.write(&path).unwrap();
    assert_eq!(Cascade::read(&path).unwrap(), nested);
    for bad in [1.5, -1.25] {
        nested.stages.get_mut("table").unwrap().cv_gain_nested = Some(bad);
        write_unchecked(&nested, &path);
        let err = Cascade::read(&path).unwrap_err().to_string();
        assert!(err.contains("'table'") && err.contains("cv_gain_nested"), "{err}");
    }
    // Uncalibrated detections (no raw score) are refused.
    let mut raw_only = vec![Detection::new("table", &Cuboid::new(Vec3::ZERO, Vec3::ONE, 0.0), 0.3)];
    assert!(cascade.rescore(&mut raw_only, None).unwrap_err().to_string().contains("calibrated"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `Cascade::check_models` refuses a model whose calibration is not the one the cascade recorded (a
/// retrained model), names it, and passes the recorded calibration, a category it recorded nothing for,
/// and a cascade that recorded nothing (files written before the record).
#[test]
fn a_cascade_refuses_first_stage_models_it_was_not_trained_with() {
    use cog_gpu::calibration::Calibration;
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/models");
    let models =
        cog_gpu::model::read_models_dir(std::path::Path::new(shipped), Some(&names(&["bed", "table"]))).unwrap();
    let calibration = |a: f64, b: f64| Calibration {
        a,
        b,
        detections: 10,
        true_positives: 2,
        iou: 0.25,
        data: String::new(),
        frames: 1,
    };
    let mut cascade = Cascade {
        format: cog_gpu::cascade::FORMAT.into(),
        version: cog_gpu::cascade::VERSION,
        features: FEATURES.into(),
        categories: names(&["bed", "table"]),
        stages: BTreeMap::new(),
        training: CascadeTraining::default(),
        exclusion: None,
        final_calibration: None,
    };
    cascade.check_models(&models).unwrap();
    let bed = models.iter().find(|m| m.category == "bed").unwrap().calibration.clone().unwrap();
    cascade.training.calibrations.insert("bed".into(), bed.clone());
    cascade.check_models(&models).unwrap();
    cascade.training.calibrations.insert("bed".into(), calibration(bed.a, bed.b + 0.5));
    let err = cascade.check_models(&models).unwrap_err().to_string();
    assert!(err.contains("another 'bed' model"), "{err}");
    // A model without a calibration is not the recorded one either.
    cascade.training.calibrations.insert("bed".into(), bed);
    let mut uncalibrated = models.clone();
    uncalibrated.iter_mut().for_each(|m| m.calibration = None);
    let err = cascade.check_models(&uncalibrated).unwrap_err().to_string();
    assert!(err.contains("'bed'") && err.contains("no calibration"), "{err}");
}

#[test]
fn cli_trains_a_cascade_and_rescores_files() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, first, rescored) = (tmp.path().join("data"), tmp.path().join("first"), tmp.path().join("rescored"));
    std::fs::create_dir_all(&first).unwrap();
    for f in 0..30 {
        let CascadeFrame { truth: objects, detections, .. } = frame(f);
        let name = format!("f{f:02}");
        common::write_tiny_frame(&data, &name, objects);
        FrameDetections { frame: name.clone(), detections }.write(&first.join(format!("{name}.json"))).unwrap();
    }
    let cascade_file = tmp.path().join("cascade.json");
    let run = |args: &[&str]| Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(args).output().unwrap();
    // The shipped bed and table models with the calibrations that made the constructed scores (tables
    // σ(raw), the bed 0.9 at raw 2: a = 1, b = ln 9 − 2), as `cascade --models` expects the models that
    // made its detections.
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/models");
    let models_dir = tmp.path().join("first-stage-models");
    std::fs::create_dir_all(&models_dir).unwrap();
    for (category, b) in [("bed", 9f64.ln() - 2.0), ("table", 0.0)] {
        let text = std::fs::read_to_string(format!("{shipped}/{category}.json")).unwrap();
        let mut model: serde_json::Value = serde_json::from_str(&text).unwrap();
        model["calibration"]["a"] = 1.0.into();
        model["calibration"]["b"] = b.into();
        std::fs::write(models_dir.join(format!("{category}.json")), model.to_string()).unwrap();
    }
    let models = models_dir.to_str().unwrap();
    let train = |detections: &std::path::Path| {
        run(&[
            "cascade",
            "--data",
            data.to_str().unwrap(),
            "--detections",
            detections.to_str().unwrap(),
            "--models",
            models,
            "--categories",
            "bed,table",
            "--out",
            cascade_file.to_str().unwrap(),
        ])
    };
    // Models whose table calibration is not the one that made the detections' scores: refused before any
    // training, the first file named (a cascade was trained and written before 2026-12-08, which `rescore`
    // then refused on its own training files). And an `--out` in a directory not made yet, with the
    // checkpoints elsewhere, is made before the training (the write failed after it before).
    let other_models = tmp.path().join("other-models");
    std::fs::create_dir_all(&other_models).unwrap();
    std::fs::copy(models_dir.join("bed.json"), other_models.join("bed.json")).unwrap();
    let mut table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(models_dir.join("table.json")).unwrap()).unwrap();
    table["calibration"]["b"] = 1.0.into();
    std::fs::write(other_models.join("table.json"), table.to_string()).unwrap();
    // `cascade` on the first-stage files with `models`, `--out out` and `extra` arguments.
    let cascade_run = |models: &str, out: &std::path::Path, extra: &[&str]| {
        let mut args = vec!["cascade", "--data", data.to_str().unwrap(), "--detections", first.to_str().unwrap()];
        args.extend(["--models", models, "--out", out.to_str().unwrap()]);
        args.extend(extra);
        run(&args)
    };
    let refused = cascade_run(other_models.to_str().unwrap(), &tmp.path().join("o/c.json"), &[]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        stderr.contains("f00.json") && stderr.contains("'table' detection") && stderr.contains("another model"),
        "{stderr}"
    );
    let fresh_out = tmp.path().join("new-dir/cascade.json");
    let elsewhere = tmp.path().join("elsewhere");
    let out =
        cascade_run(models, &fresh_out, &["--categories", "bed,table", "--checkpoints", elsewhere.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(fresh_out.is_file());
    let out = train(&first);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().any(|l| l.starts_with("bed") && l.contains("no second stage")), "{text}");
    assert!(text.contains("wrote the cascade (1 of 2 categories)"), "{text}");
    // Its stage checkpoints (default `<out>.stages`) are gone once the cascade is written.
    let mut stages_dir = cascade_file.clone().into_os_string();
    stages_dir.push(".stages");
    assert!(!std::path::Path::new(&stages_dir).exists());
    // `--features v7` needs the cross scores, which these files lack: refused, the first file named.
    // `cascade` on the first-stage files with `--out <tmp>/out` and `extra` arguments.
    let train_with = |out: &str, extra: &[&str]| {
        let out = tmp.path().join(out);
        let mut args = vec!["cascade", "--data", data.to_str().unwrap(), "--detections", first.to_str().unwrap()];
        args.extend(["--models", models, "--categories", "bed,table", "--out", out.to_str().unwrap()]);
        args.extend(extra);
        run(&args)
    };
    let refused = train_with("v7.json", &["--features", "v7"]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(stderr.contains("f00.json") && stderr.contains("has no cross_scores"), "{stderr}");
    // `--keep nested-gain` reports the nested gain and, on these 30 frames, warns that the rule was measured
    // to help only on 2 000.
    let nested = train_with("nested.json", &["--keep", "nested-gain"]);
    let (stdout, stderr) = (String::from_utf8_lossy(&nested.stdout), String::from_utf8_lossy(&nested.stderr));
    assert!(nested.status.success(), "{stderr}");
    assert!(stderr.contains("--keep nested-gain on 30 frames"), "{stderr}");
    assert!(stdout.contains("nested gain") && stdout.lines().any(|l| l.starts_with("table")), "{stdout}");
    // `--features best` trains both sets and reports each one's cross-validated AP beside the choice.
    let best_file = tmp.path().join("best.json");
    let mut args: Vec<String> = ["cascade", "--data", data.to_str().unwrap(), "--detections", first.to_str().unwrap()]
        .map(String::from)
        .to_vec();
    args.extend(["--models", models, "--out", best_file.to_str().unwrap(), "--features", "best"].map(String::from));
    let out = Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(&args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let best_text = String::from_utf8_lossy(&out.stdout);
    assert!(best_text.lines().next().is_some_and(|h| h.contains("CV AP v4") && h.contains("CV AP v5")), "{best_text}");
    let best = Cascade::read(&best_file).unwrap();
    assert_eq!(best.features, V4_FEATURES);
    let table = &best.stages["table"];
    let set = best.stage_feature_set(table).unwrap();
    let row = best_text.lines().find(|l| l.starts_with("table")).unwrap();
    assert_eq!(row.split_whitespace().nth(1), Some(set.short_name()), "{best_text}");
    assert!(best_text.lines().next().is_some_and(|h| h.contains("CV AP v6")), "{best_text}");
    // With kept checkpoints, a rerun reads every stage's outcome and writes the same cascade.
    let kept = tmp.path().join("kept-stages");
    let mut resumable = args.clone();
    resumable.extend(["--checkpoints".to_string(), kept.to_str().unwrap().to_string(), "--keep-checkpoints".into()]);
    for round in 0..2 {
        let out = Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(&resumable).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8_lossy(&out.stdout);
        assert_eq!(text.contains("resumed"), round == 1, "{text}");
        assert_eq!(Cascade::read(&best_file).unwrap(), best, "round {round}");
    }
    assert!(kept.join("table.v6.json").is_file());
    // `merge-cascades` of the three sets trained one at a time gives the cascade `best` trains.
    let one_set = |set: &str| {
        let file = tmp.path().join(format!("{set}.json"));
        let mut args = args.clone();
        let n = args.len();
        args[n - 3] = file.to_str().unwrap().to_string();
        args[n - 1] = set.to_string();
        let out = Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(&args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        file.to_str().unwrap().to_string()
    };
    let (v4_file, v5_file, v6_file) = (one_set("v4"), one_set("v5"), one_set("v6"));
    let merged_file = tmp.path().join("merged.json");
    let merged_path = merged_file.to_str().unwrap();
    let out = run(&["merge-cascades", &v4_file, &v5_file, &v6_file, "--out", merged_path]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(Cascade::read(&merged_file).unwrap(), best);
    let merge_text = String::from_utf8_lossy(&out.stdout);
    assert!(merge_text.lines().any(|l| l.starts_with("table") && l.contains(".json")), "{merge_text}");
    // A cascade of other frames: refused, both files named.
    let mut other = Cascade::read(std::path::Path::new(&v6_file)).unwrap();
    other.training.frames += 1;
    let other_file = tmp.path().join("other.json");
    other.write(&other_file).unwrap();
    let out = run(&["merge-cascades", &v4_file, other_file.to_str().unwrap(), "--out", merged_path]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("other.json") && err.contains("v4.json") && err.contains("not trained on the same"), "{err}");
    assert!(err.contains(" frames") && !err.contains("data '") && !err.contains("calibrations"), "{err}");
    // The output may not overwrite an input.
    let out = run(&["merge-cascades", &v4_file, &v6_file, "--out", &v6_file]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--out"));

    let cascade = Cascade::read(&cascade_file).unwrap();
    assert_eq!(cascade.categories, names(&["bed", "table"]));
    assert_eq!(cascade.training.frames, 30);
    // The cascade records the calibrations of the models it was trained with.
    let recorded: Vec<(&str, f64, f64)> =
        cascade.training.calibrations.iter().map(|(c, k)| (c.as_str(), k.a, k.b)).collect();
    assert_eq!(recorded, [("bed", 1.0, 9f64.ln() - 2.0), ("table", 1.0, 0.0)]);
    // A models directory may hold the cascade (and a layout model): they are not detector models.
    let dir = tmp.path().join("models");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::copy(format!("{models}/bed.json"), dir.join("bed.json")).unwrap();
    std::fs::copy(&cascade_file, dir.join("cascade.json")).unwrap();
    std::fs::write(dir.join("layout.json"), "{}").unwrap();
    let read = cog_gpu::model::read_models_dir(&dir, None).unwrap();
    assert_eq!(read.iter().map(|m| m.category.as_str()).collect::<Vec<_>>(), ["bed"]);

    // f03 carries a room, as `detect` writes it with a layout model: rescoring keeps it.
    let f03 = first.join("f03.json");
    let mut with_room: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&f03).unwrap()).unwrap();
    let layout =
        serde_json::json!({"method": "manhattan", "corners": [[-2, -1], [6, -1], [6, 4], [-2, 4]], "floor": 0.0});
    with_room["layout"] = layout.clone();
    std::fs::write(&f03, with_room.to_string()).unwrap();
    let out = run(&[
        "rescore",
        "--detections",
        first.to_str().unwrap(),
        "--out",
        rescored.to_str().unwrap(),
        "--cascade",
        cascade_file.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let file = FrameDetections::read(&rescored.join("f03.json")).unwrap();
    let kept: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rescored.join("f03.json")).unwrap()).unwrap();
    assert_eq!(kept["layout"], layout);
    let tables: Vec<&Detection> = file.detections.iter().filter(|d| d.category == "table").collect();
    assert_eq!(tables.len(), 2);
    assert!(tables.iter().all(|d| d.context_score.is_some() && d.first_stage_score.is_some()));
    // The real table (x = 4) now outranks the piece of the bed.
    assert!(tables[0].centre[0] > 3.0, "{tables:?}");
    // Numbers are written as `detect` writes them: each f32 in its shortest form, not widened to f64.
    let score = tables[0].score;
    let text = std::fs::read_to_string(rescored.join("f03.json")).unwrap();
    let written = [",", "\n"].iter().any(|end| text.contains(&format!("\"score\": {score}{end}")));
    assert!(written, "{score} not written as {score}: {text}");

    // Files whose scores another calibration made (a bed at 0.5 for raw 2) are refused, the file named.
    let other = tmp.path().join("other-model");
    std::fs::create_dir_all(&other).unwrap();
    let mut detections = frame(0).detections;
    detections[0].score = 0.5;
    FrameDetections { frame: "f00".into(), detections }.write(&other.join("f00.json")).unwrap();
    // A good file read before it: nothing is written all the same (it was).
    std::fs::copy(first.join("f01.json"), other.join("a01.json")).unwrap();
    let other_rescored = tmp.path().join("other-rescored");
    let out = run(&[
        "rescore",
        "--detections",
        other.to_str().unwrap(),
        "--out",
        other_rescored.to_str().unwrap(),
        "--cascade",
        cascade_file.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("f00.json") && err.contains("another model than the one the cascade"), "{err}");
    assert!(!other_rescored.join("a01.json").exists(), "a refused run wrote part of its files");

    // Rescoring in place would lose the first-stage files: refused. Rescored files are not cascade input.
    let out = run(&["rescore", "--detections", first.to_str().unwrap(), "--out", first.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1));
    let out = train(&rescored);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("already rescored"));
}

/// The wall distance and angle of the layout features by hand, in a 4 m × 3 m room with corners at the
/// origin and (4, 3).
#[test]
fn wall_distance_and_angle_match_a_hand_computation() {
    let room = [Vec2::new(0.0, 0.0), Vec2::new(4.0, 0.0), Vec2::new(4.0, 3.0), Vec2::new(0.0, 3.0)];
    let cuboid = |x: f32, y: f32, yaw_deg: f32| {
        Cuboid::new(Vec3::new(x, y, 0.4), Vec3::new(1.0, 0.6, 0.8), yaw_deg.to_radians())
    };
    // Footprint x 0.7..1.7, y 0.5..1.1: the wall y = 0 is 0.5 m away (x = 0 is 0.7 m), parallel: A = 0.
    let (d, a) = wall_context(&cuboid(1.2, 0.8, 0.0), &room).unwrap();
    assert!((d - 0.5).abs() < 1e-6 && a.abs() < 1e-6, "{d} {a}");
    // Turned by 90°: footprint x 0.9..1.5, y 0.3..1.3; the wall y = 0 at 0.3 m, still parallel modulo 90°.
    let (d, a) = wall_context(&cuboid(1.2, 0.8, 90.0), &room).unwrap();
    assert!((d - 0.3).abs() < 1e-5 && a.abs() < 1e-5, "{d} {a}");
    // Turned by 30° near the wall x = 4: the lowest corner decides; 30° folds to 30/45.
    let c = cuboid(3.0, 1.5, 30.0);
    let nearest = c.corners()[..4].iter().map(|p| 4.0 - p.x).fold(f32::INFINITY, f32::min);
    let (d, a) = wall_context(&c, &room).unwrap();
    assert!((d - nearest as f64).abs() < 1e-5, "{d} vs {nearest}");
    assert!((a - 30.0 / 45.0).abs() < 1e-5, "{a}");
    // 60° folds to 30° as well (modulo 90°, then the smaller side).
    let (_, a) = wall_context(&cuboid(2.0, 1.5, 60.0), &room).unwrap();
    assert!((a - 30.0 / 45.0).abs() < 1e-5, "{a}");
    // The polygon's orientation does not matter.
    let clockwise: Vec<Vec2> = room.iter().rev().copied().collect();
    let (d, a) = wall_context(&c, &clockwise).unwrap();
    assert!((d - nearest as f64).abs() < 1e-5 && (a - 30.0 / 45.0).abs() < 1e-5, "{d} {a}");
    // Centre outside the room: negative distance. A degenerate polygon: no wall.
    let (d, _) = wall_context(&cuboid(5.0, 1.5, 0.0), &room).unwrap();
    assert!((d + 0.5).abs() < 1e-6, "{d}");
    assert!(wall_context(&cuboid(1.0, 1.0, 0.0), &[Vec2::ZERO, Vec2::ZERO, Vec2::ZERO]).is_none());
}

/// The layout part of ψ in a room: `no_room` 0, `A`, `p·A`, the radial basis values of `D` and their
/// products with `p`, computed here from the definition.
#[test]
fn layout_features_follow_their_definition() {
    let corners = vec![Vec2::new(0.0, 0.0), Vec2::new(4.0, 0.0), Vec2::new(4.0, 3.0), Vec2::new(0.0, 3.0)];
    let room = Room { corners, floor: 0.0 };
    // Footprint x 0.7..1.7, y 0.5..1.1 (D = 0.5 m to the wall y = 0), width axis along x (A = 0).
    let detections = vec![detection("nightstand", [1.2, 0.8, 0.4], [1.0, 0.6, 0.8], 0.4, 0.0)];
    let categories = names(&["nightstand"]);
    let psi = &frame_context_features(&detections, &categories, Some(&room), FeatureSet::V4)[0];
    let layout = &psi[psi.len() - LAYOUT_FEATURES..];
    assert_eq!(&layout[..3], &[0.0, 0.0, 0.0]);
    for (m, (c, sigma)) in RBF_CENTRES.iter().zip(RBF_WIDTHS).enumerate() {
        let r = (-(0.5 - c) * (0.5 - c) / (2.0 * sigma * sigma)).exp();
        assert!((layout[3 + m] - r).abs() < 1e-6, "r_{m}: {} vs {r}", layout[3 + m]);
        assert!((layout[3 + RBF_CENTRES.len() + m] - 0.4 * r).abs() < 1e-6);
    }
    // The centre's basis function (c = 0.5 m) is the largest.
    assert!((layout[5] - 1.0).abs() < 1e-6);
}

/// Frame `f` of a constructed set: one annotated `category` object at `truth` (centre, size) detected there,
/// and a false detection at `false_box`, with overlapping first-stage scores, the false ones higher on
/// average, so that no function of the score alone separates them.
fn true_and_false_frame(
    category: &str,
    truth: ([f32; 3], [f32; 3]),
    false_box: ([f32; 3], [f32; 3]),
    f: usize,
    room: Option<Room>,
) -> CascadeFrame {
    let (raw_false, raw_true) = (1.0 + 0.5 * (f as f32 * 1.3).sin(), 0.8 + 0.5 * (f as f32 * 2.1).cos());
    let sigmoid = |s: f32| 1.0 / (1.0 + (-s).exp());
    let objects = vec![Object {
        category: category.into(),
        label: None,
        cuboid: Cuboid::new(Vec3::from(truth.0), Vec3::from(truth.1), 0.0),
    }];
    let detections = vec![
        detection(category, false_box.0, false_box.1, sigmoid(raw_false), raw_false),
        detection(category, truth.0, truth.1, sigmoid(raw_true), raw_true),
    ];
    CascadeFrame { truth: objects, detections, room }
}

/// A constructed set where only the room tells true from false: true nightstands stand against a wall,
/// false ones (scored higher by the first stage) stand in the middle of the room. With the room the cascade
/// ranks every true nightstand first on held-out frames; without rooms it cannot.
#[test]
fn the_cascade_learns_that_nightstands_stand_against_walls() {
    let room = vec![Vec2::new(0.0, 0.0), Vec2::new(5.0, 0.0), Vec2::new(5.0, 4.0), Vec2::new(0.0, 4.0)];
    let make = |f: usize, with_room: bool| {
        let size = [0.5, 0.4, 0.6];
        let wall = ([0.3 + 0.1 * (f % 7) as f32, 0.25, 0.3], size);
        let middle = ([2.5, 2.0 + 0.1 * (f % 5) as f32, 0.3], size);
        true_and_false_frame(
            "nightstand",
            wall,
            middle,
            f,
            with_room.then(|| Room { corners: room.clone(), floor: 0.0 }),
        )
    };
    let categories = names(&["nightstand"]);
    let training: Vec<_> = (0..40).map(|f| make(f, true)).collect();
    let (cascade, results) =
        train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V4]).unwrap();
    let stage = results["nightstand"].chosen().unwrap();
    assert!(stage.cv_ap_cascade > stage.cv_ap_first_stage + 0.1, "{stage:?}");
    let mut test: Vec<_> = (100..140).map(|f| make(f, true)).collect();
    let before = category_ap(&test, "nightstand");
    assert!(before < 0.8, "first-stage AP {before}");
    for frame in &mut test {
        let room = frame.room.clone();
        cascade.rescore(&mut frame.detections, room.as_ref()).unwrap();
    }
    assert!((category_ap(&test, "nightstand") - 1.0).abs() < 1e-6, "{}", category_ap(&test, "nightstand"));
    // Trained and applied without rooms, the context has nothing to go on: far from separated.
    let roomless: Vec<_> = (0..40).map(|f| make(f, false)).collect();
    let (blind, _) =
        train_cascade(&roomless, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V4]).unwrap();
    let mut test: Vec<_> = (100..140).map(|f| make(f, false)).collect();
    for frame in &mut test {
        blind.rescore(&mut frame.detections, None).unwrap();
    }
    assert!(category_ap(&test, "nightstand") < 0.9, "{}", category_ap(&test, "nightstand"));
}

/// The room a detections file carries: read from `"layout"."corners"` as `detect` writes it, absent without
/// a layout, and a clear error naming the file for corners that are no polygon.
#[test]
fn rooms_are_read_from_detections_files() {
    use cog_gpu::cascade::read_detections_and_room;
    let read_room = |path: &std::path::Path| read_detections_and_room(path).map(|(_, room)| room);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.json");
    let write = |layout: &str| {
        std::fs::write(&path, format!("{{\"frame\": \"f\", \"detections\": []{layout}}}")).unwrap();
    };
    write(", \"layout\": {\"method\": \"manhattan\", \"corners\": [[0, 0], [4, 0], [4, 3], [0, 3]], \"floor\": 0}");
    let room = read_room(&path).unwrap().unwrap();
    assert_eq!(room.corners, vec![Vec2::new(0.0, 0.0), Vec2::new(4.0, 0.0), Vec2::new(4.0, 3.0), Vec2::new(0.0, 3.0)]);
    assert_eq!(room.floor, 0.0);
    // A layout without its floor height: the geometry features need it.
    write(", \"layout\": {\"corners\": [[0, 0], [4, 0], [4, 3], [0, 3]]}");
    let err = read_room(&path).unwrap_err().to_string();
    assert!(err.contains("f.json") && err.contains("floor"), "{err}");
    write("");
    assert_eq!(read_room(&path).unwrap(), None);
    write(", \"layout\": {\"corners\": [[0, 0], [4, 0]]}");
    let err = read_room(&path).unwrap_err().to_string();
    assert!(err.contains("f.json") && err.contains("polygon"), "{err}");
}

/// A constructed set where only the box's proportions tell true from false: true tables are 1.0 m deep,
/// false ones (scored higher by the first stage) 0.6 m, each alone in the frame. The v5 cascade (geometry
/// part) ranks every true table first on held-out frames; v4, which sees no size, cannot.
#[test]
fn the_v5_cascade_learns_a_tables_proportions() {
    let make = |f: usize| {
        let true_table = ([1.0 + 0.1 * (f % 5) as f32, 1.0, 0.375], [1.2, 1.0, 0.75]);
        let false_table = ([4.0, 3.0 + 0.1 * (f % 3) as f32, 0.375], [1.2, 0.6, 0.75]);
        true_and_false_frame("table", true_table, false_table, f, None)
    };
    let categories = names(&["table"]);
    let training: Vec<_> = (0..40).map(make).collect();
    let before = category_ap(&(100..140).map(make).collect::<Vec<_>>(), "table");
    assert!(before < 0.8, "first-stage AP {before}");
    let ap_with = |set: FeatureSet| {
        let (cascade, _) = train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[set]).unwrap();
        assert_eq!(cascade.features, set.name());
        let mut test: Vec<_> = (100..140).map(make).collect();
        for frame in &mut test {
            cascade.rescore(&mut frame.detections, None).unwrap();
        }
        category_ap(&test, "table")
    };
    let v5 = ap_with(FeatureSet::V5);
    assert!((v5 - 1.0).abs() < 1e-6, "v5 AP {v5}");
    // v4 gets no stage (cross-validation) or one that cannot separate them.
    let v4 = ap_with(FeatureSet::V4);
    assert!(v4 < 0.9, "v4 AP {v4}");
}

/// The scene part of ψ (v6) against a hand computation: per context category the largest confidence of
/// its detections anywhere in the frame (near or far, overlapping or not), the detection itself left out,
/// 0 for a category without a detection.
#[test]
fn scene_features_match_a_hand_computation() {
    let detections = vec![
        detection("toilet", [0.0, 0.0, 0.4], [0.4, 0.7, 0.8], 0.6, 0.0),
        // A sink 3 m away (no overlap, no neighbour) and a weaker one on the toilet.
        detection("sink", [3.0, 0.0, 0.85], [0.5, 0.4, 0.2], 0.7, 0.0),
        detection("sink", [0.0, 0.0, 0.5], [0.5, 0.4, 0.2], 0.2, 0.0),
        // Two more toilets: the stronger one far away.
        detection("toilet", [0.0, 4.0, 0.4], [0.4, 0.7, 0.8], 0.9, 0.0),
        detection("toilet", [0.5, 0.0, 0.4], [0.4, 0.7, 0.8], 0.3, 0.0),
    ];
    let categories = names(&["bed", "sink", "toilet"]);
    let psi = frame_context_features(&detections, &categories, None, FeatureSet::V6);
    let scene = FeatureSet::V5.dim(3);
    assert_eq!(psi[0].len(), scene + 3);
    assert_eq!(FeatureSet::V6.dim(3), scene + 3);
    // The first toilet: no bed; sinks 0.7 (the far one); other toilets 0.9.
    assert_close(&psi[0][scene..], &[0.0, 0.7, 0.9], "toilet 0");
    // The strongest toilet sees the best of the others, 0.6; the far sink sees the near one, 0.2.
    assert_close(&psi[3][scene..], &[0.0, 0.7, 0.6], "toilet 3");
    assert_close(&psi[1][scene..], &[0.0, 0.2, 0.9], "sink 1");
}

/// A frame of the scene test: one toilet detection (true when `truth_here`) and, 3 m away, a sink (with a
/// true toilet) or a bed (with a false one). True and false toilets draw their raw scores from one
/// distribution, so no function of the score alone can rank them.
fn toilet_frame(f: usize, truth_here: bool) -> CascadeFrame {
    let toilet_at = [1.0 + 0.1 * (f % 5) as f32, 1.0, 0.4];
    let toilet_size = [0.4, 0.7, 0.8];
    let sigmoid = |s: f32| 1.0 / (1.0 + (-s).exp());
    let raw = 1.0 + 0.5 * (f as f32 * 1.3).sin();
    let context = if truth_here { "sink" } else { "bed" };
    let p_context = 0.6 + 0.3 * (f as f32 * 0.7).sin().abs();
    let truth = if truth_here {
        vec![Object {
            category: "toilet".into(),
            label: None,
            cuboid: Cuboid::new(Vec3::from(toilet_at), Vec3::from(toilet_size), 0.0),
        }]
    } else {
        vec![]
    };
    let detections = vec![
        detection("toilet", toilet_at, toilet_size, sigmoid(raw), raw),
        detection(context, [4.5, 3.5, 0.5], [0.6, 0.5, 0.3], p_context, 0.0),
    ];
    CascadeFrame { truth, detections, room: None }
}

/// A constructed set where only the scene tells true from false: a true toilet shares its frame with a
/// sink detected 3 m away, a false one (scored like the true ones by the first stage) with a bed as far away; nothing
/// overlaps or neighbours the toilet, and every toilet has the same box. The v6 cascade (scene part) ranks
/// every true toilet first on held-out frames; v5 cannot.
#[test]
fn the_v6_cascade_learns_which_rooms_hold_toilets() {
    // Not every other frame: the cross-validation folds are the even and the odd frames.
    let make = |f: usize| toilet_frame(f, f % 4 < 2);
    let categories = names(&["bed", "sink", "toilet"]);
    let training: Vec<_> = (0..40).map(make).collect();
    let before = category_ap(&(100..140).map(make).collect::<Vec<_>>(), "toilet");
    assert!(before < 0.8, "first-stage AP {before}");
    let ap_with = |set: FeatureSet| {
        // Beds and sinks have no true positive here, so no stage; they are context.
        let (cascade, _) = train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[set]).unwrap();
        assert_eq!(cascade.stages.keys().collect::<Vec<_>>(), ["toilet"]);
        let mut test: Vec<_> = (100..140).map(make).collect();
        for frame in &mut test {
            cascade.rescore(&mut frame.detections, None).unwrap();
        }
        category_ap(&test, "toilet")
    };
    let v6 = ap_with(FeatureSet::V6);
    assert!((v6 - 1.0).abs() < 1e-6, "v6 AP {v6}");
    let v5 = ap_with(FeatureSet::V5);
    assert!(v5 < 0.9, "v5 AP {v5}");
}

/// Each set's ψ is a prefix of the next one's (v4 of v5, v5 of v6), detection by detection, with and
/// without a room (what a cascade with stages of several sets relies on when it computes the widest ψ once).
#[test]
fn v4_features_are_a_prefix_of_v5_features() {
    let room = Room {
        corners: vec![Vec2::new(-1.0, -1.0), Vec2::new(6.0, -1.0), Vec2::new(6.0, 5.0), Vec2::new(-1.0, 5.0)],
        floor: -0.1,
    };
    let categories = names(&["bed", "table", "pillow"]);
    let mut detections = frame(5).detections;
    detections.push(detection("pillow", [0.1, 2.1, 1.05], [0.5, 0.3, 0.1], 0.4, -0.3));
    for room in [None, Some(&room)] {
        let v4 = frame_context_features(&detections, &categories, room, FeatureSet::V4);
        let v5 = frame_context_features(&detections, &categories, room, FeatureSet::V5);
        for (a, b) in v4.iter().zip(&v5) {
            assert_eq!(a.len(), FeatureSet::V4.dim(3));
            assert_eq!(b.len(), FeatureSet::V5.dim(3));
            assert_eq!(a[..], b[..a.len()]);
        }
        let v6 = frame_context_features(&detections, &categories, room, FeatureSet::V6);
        for (b, c) in v5.iter().zip(&v6) {
            assert_eq!(c.len(), FeatureSet::V6.dim(3));
            assert_eq!(b[..], c[..b.len()]);
        }
    }
}

/// `--features best`: each category keeps the set whose cross-validated AP is higher (ties: v4), each
/// stage equal to the one that set alone trains; the table, whose true and false boxes differ only in
/// proportions, takes v5. The file names v4, the v5 stage names its own set; written, read back, and
/// rescoring gives each category the scores of the cascade of its own set.
#[test]
fn the_best_feature_set_is_chosen_per_category_by_cross_validation() {
    let room = vec![Vec2::new(0.0, 0.0), Vec2::new(5.0, 0.0), Vec2::new(5.0, 4.0), Vec2::new(0.0, 4.0)];
    let make = |f: usize| -> CascadeFrame {
        // Tables: only the depth of the box tells (1.0 m true, 0.6 m false); nightstands: the wall.
        let true_table = ([1.0 + 0.1 * (f % 5) as f32, 1.0, 0.375], [1.2, 1.0, 0.75]);
        let false_table = ([4.0, 3.0 + 0.1 * (f % 3) as f32, 0.375], [1.2, 0.6, 0.75]);
        let size = [0.5, 0.4, 0.6];
        let wall = ([0.3 + 0.1 * (f % 7) as f32, 0.25, 0.3], size);
        let middle = ([2.5, 2.0 + 0.1 * (f % 5) as f32, 0.3], size);
        let room = Some(Room { corners: room.clone(), floor: 0.0 });
        if f.is_multiple_of(3) {
            true_and_false_frame("nightstand", wall, middle, f, room)
        } else {
            true_and_false_frame("table", true_table, false_table, f, room)
        }
    };
    let categories = names(&["nightstand", "table"]);
    let training: Vec<_> = (0..60).map(make).collect();
    let train =
        |sets: &[FeatureSet]| train_cascade(&training, &categories, 0.25, CascadeTraining::default(), sets).unwrap();
    let (v4, v4_results) = train(&[FeatureSet::V4]);
    let (v5, v5_results) = train(&[FeatureSet::V5]);
    let (best, best_results) = train(&[FeatureSet::V4, FeatureSet::V5]);
    assert_eq!(best.features, V4_FEATURES);
    for category in &categories {
        let (a, b) = (v4_results[category].chosen(), v5_results[category].chosen());
        let expected = match (a, b) {
            (Ok(a), Ok(b)) if b.cv_ap_cascade > a.cv_ap_cascade => Some((FeatureSet::V5, b)),
            (Ok(a), _) => Some((FeatureSet::V4, a)),
            (Err(_), Ok(b)) => Some((FeatureSet::V5, b)),
            (Err(_), Err(_)) => None,
        };
        let outcome = &best_results[category];
        assert_eq!(outcome.candidates.len(), 2);
        match expected {
            None => assert!(outcome.chosen().is_err()),
            Some((set, stage)) => {
                let chosen = outcome.chosen().unwrap();
                assert_eq!(best.stage_feature_set(chosen), Some(set), "{category}");
                assert_eq!(chosen.features.as_deref(), (set == FeatureSet::V5).then_some(V5_FEATURES));
                assert_eq!(chosen.weights, stage.weights, "{category}: the stage its set alone trains");
                assert_eq!((chosen.bias, chosen.c), (stage.bias, stage.c));
                assert_eq!(chosen.calibration, stage.calibration);
            }
        }
    }
    let table = best.stages["table"].clone();
    assert_eq!(best.stage_feature_set(&table), Some(FeatureSet::V5), "the table needs its proportions");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cascade.json");
    best.write(&path).unwrap();
    let read = Cascade::read(&path).unwrap();
    assert_eq!(read, best);
    // Rescoring: each category's scores are those of the cascade of its chosen set.
    for f in 100..130 {
        let rescored_by = |cascade: &Cascade| {
            let mut frame = make(f);
            let room = frame.room.clone();
            cascade.rescore(&mut frame.detections, room.as_ref()).unwrap();
            frame.detections
        };
        let got = rescored_by(&read);
        for category in &categories {
            let Some(stage) = read.stages.get(category) else { continue };
            let own = if read.stage_feature_set(stage) == Some(FeatureSet::V5) { &v5 } else { &v4 };
            let want = rescored_by(own);
            let pick = |d: &[Detection]| -> Vec<(f32, f32)> {
                d.iter().filter(|d| &d.category == category).map(|d| (d.raw_score.unwrap(), d.score)).collect()
            };
            assert_eq!(pick(&got), pick(&want), "frame {f}, {category}");
        }
    }
    // A stage naming a set this build does not know: refused, the file and the category named.
    let mut broken = read.clone();
    broken.stages.get_mut("table").unwrap().features = Some("object-overlap-v9".to_string());
    write_unchecked(&broken, &path);
    let err = Cascade::read(&path).unwrap_err().to_string();
    assert!(err.contains("cascade.json") && err.contains("'table'") && err.contains("object-overlap-v9"), "{err}");
}

/// Merging a cascade of v4 and v5 (`--features best` before v6) with one of v6 gives exactly the cascade
/// the three sets train together: per category the stage of the highest cross-validated AP, ties to the
/// earlier set. Three kinds of frames make each set win somewhere: nightstands told by the wall (v4),
/// tables by their proportions (v5), toilets by the scene (v6). Cascades of other frames or categories
/// are refused.
#[test]
fn merging_cascades_of_different_sets_equals_training_them_together() {
    let room = vec![Vec2::new(0.0, 0.0), Vec2::new(5.0, 0.0), Vec2::new(5.0, 4.0), Vec2::new(0.0, 4.0)];
    let make = |f: usize| -> CascadeFrame {
        let room = Some(Room { corners: room.clone(), floor: 0.0 });
        match f % 3 {
            0 => {
                let size = [0.5, 0.4, 0.6];
                let wall = ([0.3 + 0.1 * (f % 7) as f32, 0.25, 0.3], size);
                let middle = ([2.5, 2.0 + 0.1 * (f % 5) as f32, 0.3], size);
                true_and_false_frame("nightstand", wall, middle, f, room)
            }
            1 => {
                let true_table = ([1.0 + 0.1 * (f % 5) as f32, 1.0, 0.375], [1.2, 1.0, 0.75]);
                let false_table = ([4.0, 3.0 + 0.1 * (f % 3) as f32, 0.375], [1.2, 0.6, 0.75]);
                true_and_false_frame("table", true_table, false_table, f, room)
            }
            // f = 2, 5, 8, 11, ...: f / 6 alternates within the even and within the odd frames.
            _ => toilet_frame(f, (f / 6).is_multiple_of(2)),
        }
    };
    let categories = names(&["bed", "nightstand", "sink", "table", "toilet"]);
    let training: Vec<_> = (0..90).map(make).collect();
    let train =
        |sets: &[FeatureSet]| train_cascade(&training, &categories, 0.25, CascadeTraining::default(), sets).unwrap().0;
    let v4_v5 = train(&[FeatureSet::V4, FeatureSet::V5]);
    let v6 = train(&[FeatureSet::V6]);
    let together = train(&[FeatureSet::V4, FeatureSet::V5, FeatureSet::V6]);
    let merged = v4_v5.merged_with(&v6).unwrap();
    assert_eq!(merged, together);
    assert_eq!(
        together.stage_feature_set(&together.stages["toilet"]),
        Some(FeatureSet::V6),
        "the toilet needs the scene: {:?}",
        together.stages.get("toilet").map(|s| s.cv_ap_cascade)
    );
    assert!(together.stages.values().any(|s| together.stage_feature_set(s) != Some(FeatureSet::V6)));
    // The merged file names v4 and each stage of another set its own.
    assert_eq!(merged.features, V4_FEATURES);
    assert_eq!(merged.stages["toilet"].features.as_deref(), Some(V6_FEATURES));
    // Other frames (their number) or other categories: refused, saying what differs.
    let fewer = train_cascade(
        &training[..60],
        &categories,
        0.25,
        CascadeTraining { frames: 60, ..Default::default() },
        &[FeatureSet::V6],
    )
    .unwrap()
    .0;
    let err = v4_v5.merged_with(&fewer).unwrap_err();
    assert!(err.contains("not trained on the same") && err.contains("60 frames"), "{err}");
    // Only a model's calibration differs: the message names that model, not the data (it named every field).
    let mut recalibrated = v6.clone();
    let calibration = cog_gpu::calibration::Calibration {
        a: 2.0,
        b: -1.0,
        detections: 10,
        true_positives: 3,
        iou: 0.25,
        data: String::new(),
        frames: 5,
    };
    recalibrated.training.calibrations.insert("bed".into(), calibration);
    let err = v4_v5.merged_with(&recalibrated).unwrap_err();
    assert!(err.ends_with("the first-stage calibrations of bed"), "{err}");
    let mut other_categories = v6.clone();
    other_categories.categories.pop();
    let err = v4_v5.merged_with(&other_categories).unwrap_err();
    assert!(err.contains("different categories"), "{err}");
}

/// An interrupted cascade training resumes from its stage checkpoints: a second run reads every
/// (category, set) outcome instead of training it (a checkpoint altered on disk comes back as altered)
/// and gives the same cascade; a run on other detections, or a checkpoint that does not parse, trains
/// again; a checkpoint read by a run with another file set names its own set.
#[test]
fn cascade_training_resumes_from_its_stage_checkpoints() {
    let frames: Vec<_> = (0..20).map(frame).collect();
    let categories = names(&["bed", "table"]);
    let sets = [FeatureSet::V4, FeatureSet::V5];
    let dir = tempfile::tempdir().unwrap();
    let run = |frames: &[CascadeFrame], sets: &[FeatureSet]| {
        train_cascade_resumable(
            frames,
            &categories,
            0.25,
            CascadeTraining::default(),
            sets,
            Some(dir.path()),
            StageRule::AnyGain,
        )
        .unwrap()
    };
    let (fresh, _, resumed) = run(&frames, &sets);
    assert_eq!(resumed, 0);
    assert_eq!(fresh, train_cascade(&frames, &categories, 0.25, CascadeTraining::default(), &sets).unwrap().0);
    for category in &categories {
        for set in sets {
            assert!(stage_checkpoint_path(dir.path(), category, set).is_file(), "{category} {set:?}");
        }
    }
    let (again, _, resumed) = run(&frames, &sets);
    assert_eq!((resumed, &again), (4, &fresh));
    // The table's v5 checkpoint altered: the resumed run reads it (and keeps it: its CV AP is now best).
    let path = stage_checkpoint_path(dir.path(), "table", FeatureSet::V5);
    let mut stored: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    stored["stage"]["cv_ap_cascade"] = serde_json::json!(2.0);
    stored["stage"]["bias"] = serde_json::json!(-123.0);
    std::fs::write(&path, stored.to_string()).unwrap();
    let (altered, _, resumed) = run(&frames, &sets);
    assert_eq!(resumed, 4);
    assert_eq!((altered.stages["table"].bias, altered.stages["table"].cv_ap_cascade), (-123.0, 2.0));
    assert_eq!(altered.stages["table"].features.as_deref(), Some(V5_FEATURES));
    // Read by a run whose file set is v5, the same checkpoint's stage names no set of its own.
    let (v5_only, _, resumed) = run(&frames, &[FeatureSet::V5]);
    assert_eq!((resumed, v5_only.stages["table"].bias, v5_only.stages["table"].features.clone()), (2, -123.0, None));
    // Other detections (one score changed): nothing is resumed, the result is a fresh training's.
    let mut other = frames.clone();
    other[3].detections[1].raw_score = Some(0.1);
    other[3].detections[1].score = 1.0 / (1.0 + (-0.1f32).exp());
    let (retrained, _, resumed) = run(&other, &sets);
    assert_eq!(resumed, 0);
    assert_eq!(retrained, train_cascade(&other, &categories, 0.25, CascadeTraining::default(), &sets).unwrap().0);
    // A checkpoint of another C grid (another build's) is trained again.
    let path = stage_checkpoint_path(dir.path(), "table", FeatureSet::V4);
    let mut stored: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(stored["c_grid"], serde_json::json!(cog_gpu::cascade::C_GRID));
    stored["c_grid"] = serde_json::json!([0.001, 0.01, 0.1, 1.0, 10.0]);
    std::fs::write(&path, stored.to_string()).unwrap();
    let (_, _, resumed) = run(&other, &sets);
    assert_eq!(resumed, 3);
    // A checkpoint that does not parse is trained again.
    std::fs::write(stage_checkpoint_path(dir.path(), "bed", FeatureSet::V4), "{ not json").unwrap();
    let (_, _, resumed) = run(&other, &sets);
    assert_eq!(resumed, 3);
    // A stage checkpoint without the gain's interval (written before it was recorded) is trained again.
    let path = stage_checkpoint_path(dir.path(), "table", FeatureSet::V5);
    let mut stored: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert!(stored["stage"]["cv_gain_interval"].is_array(), "{stored}");
    stored["stage"].as_object_mut().unwrap().remove("cv_gain_interval");
    std::fs::write(&path, stored.to_string()).unwrap();
    let (_, _, resumed) = run(&other, &sets);
    assert_eq!(resumed, 3);
}

/// `StageRule::SignificantGain` keeps the stage whose cross-validated gain is far beyond the noise (the
/// table on the bed: every piece of a bed falls below every real table) and refuses one whose gain is
/// only noise: a category whose context says nothing (each frame's true chair and false chair have the
/// same neighbours, their first-stage scores ranked by chance). The checkpoints hold the stages as trained,
/// so a run with the other rule reads them all.
#[test]
fn the_significant_gain_rule_keeps_real_gains_and_drops_noise() {
    let table_frames: Vec<_> = (0..40).map(frame).collect();
    let categories = names(&["bed", "table"]);
    let dir = tempfile::tempdir().unwrap();
    let run = |frames: &[CascadeFrame], categories: &[String], rule| {
        train_with_checkpoints(frames, categories, &[FeatureSet::V4], dir.path(), rule)
    };
    let (any, _, _) = run(&table_frames, &categories, StageRule::AnyGain);
    let (significant, outcomes, resumed) = run(&table_frames, &categories, StageRule::SignificantGain);
    assert_eq!(resumed, 2, "both outcomes read from the checkpoints");
    assert_eq!(significant, any, "the table's gain is beyond the noise: the same cascade");
    let table = &significant.stages["table"];
    let [low, high] = table.cv_gain_interval.unwrap();
    let gain = table.cv_ap_cascade - table.cv_ap_first_stage;
    assert!(0.1 < low && low <= gain && gain <= high, "{low} {gain} {high}");
    assert!(outcomes["bed"].chosen().is_err());

    let chair_frames = chance_chair_frames();
    let chair = names(&["chair"]);
    let (_, outcomes, _) = run(&chair_frames, &chair, StageRule::AnyGain);
    let (kept, refused, _) = run(&chair_frames, &chair, StageRule::SignificantGain);
    assert!(kept.stages.is_empty(), "{:?}", kept.stages);
    let reason = refused["chair"].chosen().unwrap_err();
    // These draws give the chairs' stage a cross-validated gain by chance (+4.5 AP points; other draws give
    // none, and about one in twenty a significant one, as a 95 % bound should): any-gain keeps it, the
    // rule does not.
    let stage = outcomes["chair"].chosen().unwrap();
    let [low, high] = stage.cv_gain_interval.unwrap();
    assert!(stage.cv_ap_cascade > stage.cv_ap_first_stage + 0.03 && low <= 0.0 && high > 0.03, "{stage:?}");
    assert!(reason.contains("within the noise"), "{reason}");
}

/// `train_cascade_resumable` at IoU 0.25 with its checkpoints in `dir`.
fn train_with_checkpoints(
    frames: &[CascadeFrame],
    categories: &[String],
    sets: &[FeatureSet],
    dir: &Path,
    rule: StageRule,
) -> (Cascade, BTreeMap<String, cog_gpu::cascade::StageOutcome>, usize) {
    train_cascade_resumable(frames, categories, 0.25, CascadeTraining::default(), sets, Some(dir), rule).unwrap()
}

/// Chairs whose context says nothing: in each of 60 frames a true chair and a false one 2 m away, both
/// alone, with scores of the same distribution; the context features of the two are the same up to their
/// own score.
fn chance_chair_frames() -> Vec<CascadeFrame> {
    (0..60)
        .map(|f| {
            let place = |x: f32| Cuboid::new(Vec3::new(x, 1.0, 0.45), Vec3::new(0.5, 0.5, 0.9), 0.0);
            let truth = vec![Object { category: "chair".into(), label: None, cuboid: place(0.0) }];
            // Both scores drawn independently from one distribution (a hash of the frame): nothing tells them
            // apart.
            let draw = |k: usize| ((k as f32 * 12.9898).sin() * 43_758.547).rem_euclid(1.0) * 2.0 - 1.0;
            let (raw_true, raw_false) = (draw(2 * f + 15), draw(2 * f + 16));
            let sigmoid = |s: f32| 1.0 / (1.0 + (-s).exp());
            let detections = vec![
                detection("chair", [0.0, 1.0, 0.45], [0.5, 0.5, 0.9], sigmoid(raw_true), raw_true),
                detection("chair", [2.0, 1.0, 0.45], [0.5, 0.5, 0.9], sigmoid(raw_false), raw_false),
            ];
            CascadeFrame { truth, detections, room: None }
        })
        .collect()
}

/// `StageRule::NestedGain` keeps the table's stage (the same stage as any-gain's, with its nested gain
/// recorded) and refuses the chance chairs' stage, whose cross-validated gain is the best of eight choices
/// of set and `C` on noise. Its checkpoints carry the nested numbers: a checkpoint written without them is
/// trained again, one written with them is read by either rule.
#[test]
fn the_nested_gain_rule_keeps_real_gains_and_drops_chance_ones() {
    let dir = tempfile::tempdir().unwrap();
    let run = |frames: &[CascadeFrame], categories: &[String], rule| {
        train_with_checkpoints(frames, categories, &[FeatureSet::V4, FeatureSet::V5], dir.path(), rule)
    };
    let table_frames: Vec<_> = (0..40).map(frame).collect();
    let categories = names(&["bed", "table"]);
    let (any, _, _) = run(&table_frames, &categories, StageRule::AnyGain);
    let (nested, outcomes, resumed) = run(&table_frames, &categories, StageRule::NestedGain);
    // The bed's checkpoints (no true and false positives both) and the table's lack the numbers.
    assert_eq!(resumed, 0, "checkpoints without the nested numbers are trained again");
    let table = &nested.stages["table"];
    let gain = table.cv_gain_nested.expect("recorded under the nested rule");
    assert_eq!(outcomes["table"].nested_gain, Some(gain));
    assert!(gain > 0.1, "the table on the bed is told apart in every fold: {gain}");
    assert_eq!(cog_gpu::cascade::SecondStage { cv_gain_nested: None, ..table.clone() }, any.stages["table"]);
    assert!(any.stages["table"].cv_gain_nested.is_none());
    let (_, _, resumed) = run(&table_frames, &categories, StageRule::NestedGain);
    assert_eq!(resumed, 2 * 2 - 2, "the table's two sets read; the bed's (no numbers) trained again");
    let (again, _, resumed) = run(&table_frames, &categories, StageRule::AnyGain);
    assert_eq!((resumed, &again), (4, &any), "any-gain reads the checkpoints with the numbers alike");

    let chair = names(&["chair"]);
    let chair_frames = chance_chair_frames();
    let (kept_any, outcomes_any, _) = run(&chair_frames, &chair, StageRule::AnyGain);
    let (kept, outcomes, _) = run(&chair_frames, &chair, StageRule::NestedGain);
    let stage = outcomes_any["chair"].chosen().unwrap();
    assert!(stage.cv_ap_cascade > stage.cv_ap_first_stage + 0.03, "any-gain keeps a chance gain: {stage:?}");
    assert!(kept_any.stages.contains_key("chair"));
    assert!(kept.stages.is_empty(), "{:?}", kept.stages);
    let gain = outcomes["chair"].nested_gain.unwrap();
    assert!(gain <= 0.0, "{gain}");
    let reason = outcomes["chair"].chosen().unwrap_err();
    assert!(reason.contains("nested cross-validated gain") && reason.contains("of 8 choices"), "{reason}");
}

/// A category's trainings run in parallel (its feature sets, the two folds of each cross-validation, the
/// nested rule's inner cross-validations beside the stage's own): the cascade and every outcome are the
/// same, bit for bit, on one thread and on four — the numbers are combined in a fixed order, whatever
/// finishes first.
#[test]
fn cascade_training_is_the_same_on_one_thread_and_on_four() {
    let mut frames: Vec<_> = (0..40).map(frame).collect();
    // The chance chairs too: a category the nested rule refuses, beside the table it keeps.
    for (f, chairs) in frames.iter_mut().zip(chance_chair_frames()) {
        f.truth.extend(chairs.truth);
        f.detections.extend(chairs.detections);
    }
    let categories = names(&["bed", "chair", "table"]);
    let train = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            train_cascade_resumable(
                &frames,
                &categories,
                0.25,
                CascadeTraining::default(),
                &[FeatureSet::V4, FeatureSet::V5, FeatureSet::V6],
                None,
                StageRule::NestedGain,
            )
            .unwrap()
        })
    };
    let (one, one_outcomes, _) = train(1);
    let (four, four_outcomes, _) = train(4);
    assert!(one.stages.contains_key("table"), "{:?}", one_outcomes["table"].chosen());
    assert_eq!(one, four);
    // Debug prints each float's shortest exact form: equal text, equal bits.
    assert_eq!(format!("{one_outcomes:?}"), format!("{four_outcomes:?}"));
    assert_eq!(serde_json::to_string(&one).unwrap(), serde_json::to_string(&four).unwrap());
}

/// Writes `cascade` as `Cascade::write` does but without its check: the damaged files the readers must
/// refuse.
fn write_unchecked(cascade: &Cascade, path: &Path) {
    std::fs::write(path, serde_json::to_string_pretty(cascade).unwrap()).unwrap();
}

/// A cross-scores map with `value(c)` for every category of [`CROSS_SCORE_CATEGORIES`].
fn cross_map(value: impl Fn(&str) -> f32) -> BTreeMap<String, f32> {
    CROSS_SCORE_CATEGORIES.iter().map(|c| (c.to_string(), value(c))).collect()
}

/// The cross part of ψ (v7): each detection of the eleven categories reads its own map in
/// `CROSS_SCORE_CATEGORIES`' order, clamped to ±5; a detection of another category reads zeros; v6's ψ is
/// its prefix.
#[test]
fn cross_features_match_a_hand_computation() {
    let mut table = detection("table", [0.0, 0.0, 0.4], [1.0, 0.6, 0.8], 0.6, 0.4);
    table.cross_scores = Some(cross_map(|c| match c {
        "desk" => 1.25,
        "table" => 0.5,
        "counter" => -7.0, // clamped to −5
        "bed" => 9.0,      // clamped to 5
        _ => -0.75,
    }));
    let mut pillow = detection("pillow", [0.0, 0.0, 0.85], [0.5, 0.3, 0.1], 0.3, -0.2);
    // A pillow is not a cross category: a map on it is ignored.
    pillow.cross_scores = Some(cross_map(|_| 2.0));
    let detections = vec![table, pillow];
    let categories = names(&["table", "desk", "pillow"]);
    let v6 = frame_context_features(&detections, &categories, None, FeatureSet::V6);
    let v7 = frame_context_features(&detections, &categories, None, FeatureSet::V7);
    let start = FeatureSet::V6.dim(3);
    assert_eq!(FeatureSet::V7.dim(3), start + 11);
    assert_eq!(CROSS_SCORE_CATEGORIES.len(), 11);
    for (a, b) in v6.iter().zip(&v7) {
        assert_eq!(b.len(), FeatureSet::V7.dim(3));
        assert_eq!(a[..], b[..start], "v6 is a prefix of v7");
    }
    // Hand-written in the constant's order: bed chair sofa table desk toilet bathtub dresser nightstand
    // bookshelf counter.
    let want = [5.0, -0.75, -0.75, 0.5, 1.25, -0.75, -0.75, -0.75, -0.75, -0.75, -5.0];
    assert_close(&v7[0][start..], &want, "table");
    assert_close(&v7[1][start..], &[0.0; 11], "pillow");
}

/// A detection of a cross category without its cross scores (or with one missing, or not finite) is refused
/// by a cascade with a v7 stage, with a message that says how to get them; a cascade without one rescores
/// it.
#[test]
fn a_cross_stage_refuses_detections_without_cross_scores() {
    let make = |f: usize| cross_frame(f, f % 4 < 2);
    let training: Vec<_> = (0..40).map(make).collect();
    let categories = names(&["desk", "table"]);
    let (cascade, _) =
        train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V7]).unwrap();
    assert!(cascade.reads_cross_scores());
    let (v6, _) = train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V6]).unwrap();
    assert!(!v6.reads_cross_scores());
    let without = |edit: &dyn Fn(&mut Detection)| {
        let mut detections = make(3).detections;
        edit(&mut detections[0]);
        detections
    };
    let none = without(&|d| d.cross_scores = None);
    let partial = without(&|d| {
        d.cross_scores.as_mut().unwrap().remove("counter");
    });
    let infinite = without(&|d| {
        d.cross_scores.as_mut().unwrap().insert("bed".into(), f32::NAN);
    });
    for (mut detections, says) in
        [(none, "has no cross_scores"), (partial, "no cross score of the 'counter' model"), (infinite, "not finite")]
    {
        let err = cascade.rescore(&mut detections, None).unwrap_err().to_string();
        assert!(err.contains(says) && err.contains("detect --no-cascade"), "{err}");
        assert!(check_cross_scores(&detections).is_err());
        v6.rescore(&mut detections, None).unwrap();
    }
    assert!(check_cross_scores(&make(3).detections).is_ok());
}

/// The stage checkpoints know the cross scores: a v7 training on detections whose cross scores changed (one
/// score of one detection) is not resumed from the checkpoints of the old ones — its stage would read
/// other features — while a rerun on the same detections is.
#[test]
fn a_cross_stage_checkpoint_is_not_resumed_for_other_cross_scores() {
    let frames: Vec<_> = (0..40).map(|f| cross_frame(f, f % 4 < 2)).collect();
    let categories = names(&["desk", "table"]);
    let dir = tempfile::tempdir().unwrap();
    let run = |frames: &[CascadeFrame]| {
        train_cascade_resumable(
            frames,
            &categories,
            0.25,
            CascadeTraining::default(),
            &[FeatureSet::V7],
            Some(dir.path()),
            StageRule::AnyGain,
        )
        .unwrap()
    };
    let (fresh, _, resumed) = run(&frames);
    assert_eq!(resumed, 0);
    let (again, _, resumed) = run(&frames);
    assert_eq!((resumed, &again), (2, &fresh));
    let mut other = frames.clone();
    let scores = other[5].detections[0].cross_scores.as_mut().unwrap();
    *scores.get_mut("desk").unwrap() += 0.5;
    let (retrained, _, resumed) = run(&other);
    assert_eq!(resumed, 0, "a checkpoint of other cross scores is trained over");
    let direct = train_cascade(&other, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V7]).unwrap().0;
    assert_eq!(retrained, direct);
}

/// `--features best-cross` trains v7 only for the categories with cross scores: beside v6, a pillow's v7
/// stage is not trained (no checkpoint written; its reason says so) while the table's is; with v7 alone the
/// pillow is trained as any category is.
#[test]
fn v7_is_trained_beside_v6_only_for_the_cross_categories() {
    let frames: Vec<_> = (0..40).map(|f| cross_frame(f, f % 4 < 2)).collect();
    let categories = names(&["pillow", "table"]);
    let dir = tempfile::tempdir().unwrap();
    let sets = [FeatureSet::V6, FeatureSet::V7];
    let (_, outcomes, _) = train_cascade_resumable(
        &frames,
        &categories,
        0.25,
        CascadeTraining::default(),
        &sets,
        Some(dir.path()),
        StageRule::AnyGain,
    )
    .unwrap();
    let pillow = &outcomes["pillow"].candidates;
    let skipped = pillow[1].1.as_ref().unwrap_err();
    assert!(skipped.contains("not trained") && skipped.contains("v6 is the same"), "{skipped}");
    assert!(!pillow[0].1.as_ref().unwrap_err().contains("not trained"), "v6 is trained: {pillow:?}");
    assert!(!stage_checkpoint_path(dir.path(), "pillow", FeatureSet::V7).exists());
    assert!(stage_checkpoint_path(dir.path(), "pillow", FeatureSet::V6).is_file());
    assert!(outcomes["table"].candidates[1].1.is_ok(), "the table's v7 stage is trained");
    assert!(cog_gpu::cascade::v7_adds_nothing(FeatureSet::V7, "pillow", &sets));
    assert!(!cog_gpu::cascade::v7_adds_nothing(FeatureSet::V7, "counter", &sets));
    assert!(!cog_gpu::cascade::v7_adds_nothing(FeatureSet::V7, "pillow", &[FeatureSet::V7]));
    let (_, alone) = train_cascade(&frames, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V7]).unwrap();
    let reason = alone["pillow"].candidates[0].1.as_ref().unwrap_err();
    assert!(!reason.contains("not trained"), "v7 alone trains every category: {reason}");
}

/// A frame of the cross test: one table detection (true when `truth_here`) alone in its frame, whose raw
/// score comes from the same distribution either way; the desk model's score on its box is low on a true
/// table and high on a false one (a desk taken for a table), with noise.
fn cross_frame(f: usize, truth_here: bool) -> CascadeFrame {
    let at = [1.0 + 0.1 * (f % 5) as f32, 1.0, 0.4];
    let size = [1.2, 0.7, 0.75];
    let sigmoid = |s: f32| 1.0 / (1.0 + (-s).exp());
    let raw = 0.5 + 0.5 * (f as f32 * 1.3).sin();
    let desk = if truth_here { -1.0 } else { 1.0 } + 0.3 * (f as f32 * 0.7).sin();
    let truth = if truth_here {
        vec![Object {
            category: "table".into(),
            label: None,
            cuboid: Cuboid::new(Vec3::from(at), Vec3::from(size), 0.0),
        }]
    } else {
        vec![]
    };
    let mut table = detection("table", at, size, sigmoid(raw), raw);
    table.cross_scores = Some(cross_map(|c| match c {
        "desk" => desk,
        "table" => raw,
        _ => -1.0,
    }));
    CascadeFrame { truth, detections: vec![table], room: None }
}

/// A constructed set where only the cross scores tell true tables from false ones: nothing else is in
/// the frames, the boxes are alike and the first stage scores both alike. The v7 cascade ranks every true
/// table first on held-out frames; v6 cannot.
#[test]
fn the_v7_cascade_learns_what_the_desk_model_says_about_a_table() {
    let make = |f: usize| cross_frame(f, f % 4 < 2);
    let categories = names(&["desk", "table"]);
    let training: Vec<_> = (0..40).map(make).collect();
    let before = category_ap(&(100..140).map(make).collect::<Vec<_>>(), "table");
    assert!(before < 0.8, "first-stage AP {before}");
    let ap_with = |set: FeatureSet| {
        let (cascade, _) = train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[set]).unwrap();
        let mut test: Vec<_> = (100..140).map(make).collect();
        for frame in &mut test {
            cascade.rescore(&mut frame.detections, None).unwrap();
        }
        category_ap(&test, "table")
    };
    let v7 = ap_with(FeatureSet::V7);
    assert!((v7 - 1.0).abs() < 1e-6, "v7 AP {v7}");
    let v6 = ap_with(FeatureSet::V6);
    assert!(v6 < 0.9, "v6 AP {v6}");
}

/// Held-out frame `f` for recalibration: [`frame`]'s, but odd frames lose their bed detection (the bed is
/// still annotated), so that the context cannot tell their tables apart and the labels are not separable
/// by the combined score (a separable set would send any logistic fit's slope to its prior's bound).
fn held_out_frame(f: usize) -> CascadeFrame {
    let mut held_out = frame(f);
    if f % 2 == 1 {
        held_out.detections.retain(|d| d.category != "bed");
    }
    held_out
}

/// `Cascade::recalibrated` against the same fit on hand-labelled samples, and the properties of a maximum
/// likelihood Platt fit: its probabilities sum to the number of true positives (the intercept's equation,
/// up to the prior), it loses less log-likelihood than the calibration the cascade was trained with, and
/// the order of the scores — every AP — does not change.
#[test]
fn a_cascade_is_recalibrated_on_held_out_frames() {
    use cog_gpu::calibration::fit_logistic;
    use cog_gpu::cascade::HeldOutFrame;
    let training: Vec<_> = (0..40).map(frame).collect();
    let categories = names(&["bed", "table"]);
    let (cascade, _) =
        train_cascade(&training, &categories, 0.25, CascadeTraining::default(), &[FeatureSet::V4]).unwrap();
    let held_out: Vec<_> = (100..160).map(held_out_frame).collect();
    let frames: Vec<HeldOutFrame> =
        held_out.iter().map(|f| HeldOutFrame { detections: &f.detections, room: None, truth: &f.truth }).collect();
    let (recalibrated, report) = cascade.recalibrated(&frames, &[], 0.25, "held-out").unwrap();

    // By hand: every table detection's combined score z + z', the real table (x = 4) the true positive.
    let mut samples = Vec::new();
    let mut rescored = Vec::new();
    for f in &held_out {
        let mut detections = f.detections.clone();
        cascade.rescore(&mut detections, None).unwrap();
        for t in detections.iter().filter(|d| d.category == "table") {
            samples.push((t.raw_score.unwrap() + t.context_score.unwrap(), t.centre[0] > 3.0));
        }
        rescored.push(CascadeFrame { detections, ..f.clone() });
    }
    let positives = samples.iter().filter(|s| s.1).count();
    assert_eq!((samples.len(), positives), (120, 60));
    assert!(samples.iter().any(|&(z, y)| !y && samples.iter().any(|&(z2, y2)| y2 && z > z2)), "not separable");
    let (a, b) = fit_logistic(&samples).unwrap();
    let stage = &recalibrated.stages["table"];
    let calibration = &stage.calibration;
    assert!((calibration.a - a).abs() < 1e-9 * a.abs() && (calibration.b - b).abs() < 1e-9 * (1.0 + b.abs()));
    assert_eq!((calibration.detections, calibration.true_positives, calibration.frames), (120, 60, 60));
    assert_eq!((calibration.data.as_str(), calibration.iou), ("held-out", 0.25));
    // Only the calibration changed; the bed has no stage and gets none.
    let before = &cascade.stages["table"];
    assert_eq!(&cog_gpu::cascade::SecondStage { calibration: before.calibration.clone(), ..stage.clone() }, before);
    assert_eq!(recalibrated.stages.keys().collect::<Vec<_>>(), cascade.stages.keys().collect::<Vec<_>>());
    assert!(!recalibrated.stages.contains_key("bed"));
    // The intercept's equation: Σ p = true positives, up to the prior's pull on b (10⁻³ · b).
    let sum: f64 = samples.iter().map(|&(z, _)| f64::from(calibration.probability(z))).sum();
    assert!((sum - 60.0).abs() < 1e-3 * (1.0 + b.abs()) + 1e-3, "Σ p = {sum}");
    // The report: the trained calibration's expected true positives and both log losses, by hand.
    let [row] = report.as_slice() else { panic!("{report:?}") };
    let expected: f64 = samples.iter().map(|&(z, _)| f64::from(before.calibration.probability(z))).sum();
    assert!((row.expected_true_positives_before - expected).abs() < 1e-6 * expected, "{row:?}");
    let loss = |c: &cog_gpu::calibration::Calibration| {
        samples
            .iter()
            .map(|&(z, y)| {
                let p = f64::from(c.probability(z)).clamp(1e-6, 1.0 - 1e-6);
                -(if y { p } else { 1.0 - p }).ln()
            })
            .sum::<f64>()
            / samples.len() as f64
    };
    assert!((row.log_loss_before - loss(&before.calibration)).abs() < 1e-9, "{row:?}");
    assert!((row.log_loss_after - loss(calibration)).abs() < 1e-9, "{row:?}");
    // Trained on separable frames, the cascade's own calibration is far too sure of itself here.
    assert!(row.log_loss_after < row.log_loss_before, "{row:?}");
    // The refit is the likelihood's optimum: moving a or b by 5 % either way loses more.
    for (da, db) in [(1.05, 1.0), (0.95, 1.0), (1.0, 1.05), (1.0, 0.95)] {
        let moved = cog_gpu::calibration::Calibration { a: a * da, b: b * db, ..calibration.clone() };
        assert!(loss(&moved) > row.log_loss_after, "a × {da}, b × {db}: {} ≤ {}", loss(&moved), row.log_loss_after);
    }
    // The same order, so the same AP.
    let mut again: Vec<CascadeFrame> = held_out.clone();
    for f in &mut again {
        recalibrated.rescore(&mut f.detections, None).unwrap();
    }
    assert_eq!(table_ap(&again), table_ap(&rescored));

    // A category without a stage, and held-out frames without a true table: errors, nothing returned.
    let err = cascade.recalibrated(&frames, &names(&["bed"]), 0.25, "held-out").unwrap_err().to_string();
    assert!(err.contains("no stage for 'bed'"), "{err}");
    let no_truth: Vec<HeldOutFrame> =
        held_out.iter().map(|f| HeldOutFrame { detections: &f.detections, room: None, truth: &[] }).collect();
    let err = cascade.recalibrated(&no_truth, &[], 0.25, "held-out").unwrap_err().to_string();
    assert!(err.contains("table") && err.contains("true and false positives"), "{err}");
}

/// `calibrate --cascade`: the cascade's stages fitted on held-out first-stage files and written to
/// `--out`, the input cascade left as it was; a category without a stage is refused and nothing written.
#[test]
fn cli_calibrates_a_cascade_on_held_out_files() {
    let tmp = tempfile::tempdir().unwrap();
    let (data, first) = (tmp.path().join("data"), tmp.path().join("first"));
    std::fs::create_dir_all(&first).unwrap();
    let mut frames = Vec::new();
    for f in 100..130 {
        let held_out = held_out_frame(f);
        let name = format!("h{f}");
        common::write_tiny_frame(&data, &name, held_out.truth.clone());
        FrameDetections { frame: name, detections: held_out.detections.clone() }
            .write(&first.join(format!("h{f}.json")))
            .unwrap();
        frames.push(held_out);
    }
    let training: Vec<_> = (0..40).map(frame).collect();
    let (cascade, _) =
        train_cascade(&training, &names(&["bed", "table"]), 0.25, CascadeTraining::default(), &[FeatureSet::V4])
            .unwrap();
    let (input, output) = (tmp.path().join("cascade.json"), tmp.path().join("calibrated.json"));
    cascade.write(&input).unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["calibrate", "--cascade", input.to_str().unwrap(), "--data", data.to_str().unwrap()];
        args.extend(["--detections", first.to_str().unwrap(), "--out", output.to_str().unwrap()]);
        args.extend(extra);
        Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(&args).output().unwrap()
    };
    let out = run(&[]);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.lines().any(|l| l.starts_with("table") && l.split_whitespace().nth(2) == Some("30")), "{stdout}");
    assert!(stdout.contains("fitted on 30 frames"), "{stdout}");
    let held_out: Vec<cog_gpu::cascade::HeldOutFrame> = frames
        .iter()
        .map(|f| cog_gpu::cascade::HeldOutFrame { detections: &f.detections, room: None, truth: &f.truth })
        .collect();
    let (expected, _) = cascade.recalibrated(&held_out, &[], 0.25, data.to_str().unwrap()).unwrap();
    assert_eq!(Cascade::read(&output).unwrap(), expected);
    assert_eq!(Cascade::read(&input).unwrap(), cascade, "the input cascade is left as it was");

    std::fs::remove_file(&output).unwrap();
    // `--check` reports the same table and writes nothing.
    let mut args = vec!["calibrate", "--cascade", input.to_str().unwrap(), "--data", data.to_str().unwrap()];
    args.extend(["--detections", first.to_str().unwrap(), "--check"]);
    let checked = Command::new(env!("CARGO_BIN_EXE_cog-gpu")).args(&args).output().unwrap();
    let checked_stdout = String::from_utf8_lossy(&checked.stdout);
    assert!(checked.status.success(), "{}", String::from_utf8_lossy(&checked.stderr));
    assert_eq!(checked_stdout.lines().nth(1), stdout.lines().nth(1), "{checked_stdout}");
    assert!(checked_stdout.contains("30 true positives found") && checked_stdout.contains("nothing written"));
    assert!(!output.exists());
    assert_eq!(Cascade::read(&input).unwrap(), cascade);
    let out = run(&["--categories", "bed"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("no stage for 'bed'") && stderr.contains("cascade.json"), "{stderr}");
    assert!(!output.exists());
    // A name that is no category at all is refused by name before anything is read.
    let out = run(&["--categories", "tabel"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("'tabel' is not one of cog-gpu's 19 categories"), "{stderr}");
    assert!(!output.exists());
}
