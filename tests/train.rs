//! Training: the detector's loss-augmented inference against an independent maximisation, the example
//! construction, and `cog-gpu train` end to end on a tiny synthetic dataset (model, checkpoint, resume,
//! errors).

mod common;
use cog_gpu::features::LatticePhase;
use cog_gpu::features::Support;
use common::run_cog_gpu as run;
use common::strs;
use std::path::{Path, PathBuf};

use cog_gpu::features::fast::{FastEngine, FastOptions};
use cog_gpu::features::hypotheses::{anchored_yaws, default_yaws, nearest_yaw_index};
use cog_gpu::features::{FeatureLayout, Groups, Preprocessed, SizeQuantiles, YawAnchor};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::{iou_3d, structured_loss, Cuboid};
use cog_gpu::learn::detector::{
    without_points_in, Answer, DetectorOracle, FeatureEngine, OtherInstances, PositiveTarget, TrainingExample,
    TrainingSettings,
};

const FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";

#[test]
fn nearest_yaw_wraps_around_the_circle() {
    let step = std::f32::consts::TAU / 16.0;
    let yaws = default_yaws();
    assert_eq!(nearest_yaw_index(&yaws, 0.0), 0);
    assert_eq!(nearest_yaw_index(&yaws, 0.49 * step), 0);
    assert_eq!(nearest_yaw_index(&yaws, 0.51 * step), 1);
    assert_eq!(nearest_yaw_index(&yaws, -0.4 * step), 0);
    assert_eq!(nearest_yaw_index(&yaws, -step), 15);
    assert_eq!(nearest_yaw_index(&yaws, std::f32::consts::TAU - 0.1 * step), 0);
    assert_eq!(nearest_yaw_index(&yaws, 3.0 * std::f32::consts::PI), 8);
    // Anchored at 10°: yaw k is 10° + 22.5°·k.
    let anchored = anchored_yaws(10f32.to_radians());
    assert_eq!(nearest_yaw_index(&anchored, 10f32.to_radians()), 0);
    assert_eq!(nearest_yaw_index(&anchored, 21f32.to_radians()), 0);
    assert_eq!(nearest_yaw_index(&anchored, 22f32.to_radians()), 1);
    assert_eq!(nearest_yaw_index(&anchored, (-10f32).to_radians()), 15);
    assert_eq!(nearest_yaw_index(&anchored, 190f32.to_radians()), 8);
}

fn real_frame() -> (Frame, Preprocessed) {
    let frame = Frame::read(FRAME, DepthSource::Raw).unwrap();
    let pre = Preprocessed::from_frame(&frame).unwrap();
    (frame, pre)
}

#[test]
fn other_instances_lose_exactly_their_points() {
    let (frame, pre) = real_frame();
    let others: Vec<Cuboid> = frame.objects.iter().take(2).map(|o| o.cuboid).collect();
    let inside = pre.points.iter().filter(|p| others.iter().any(|c| c.contains(**p))).count();
    assert!(inside > 1000, "the first two boxes hold {inside} points");
    let kept = without_points_in(&pre, &others);
    assert_eq!(kept.len(), pre.len() - inside);
    assert_eq!(kept.normals.len(), kept.len());
    assert_eq!(kept.gradients.len(), kept.len());
    assert!(kept.points.iter().all(|p| !others.iter().any(|c| c.contains(*p))));
}

#[test]
fn ignored_instances_keep_their_points_and_lose_only_the_boxes_that_detect_them() {
    let (frame, pre) = real_frame();
    // The frame's two bookshelves stand side by side against the wall.
    let shelves = frame_instances(&frame, "bookshelf");
    assert_eq!(shelves.len(), 2);
    let settings = small_settings(&shelves, PositiveTarget::BestWindow, false);
    let ignoring =
        TrainingExample::with_others("ignoring".into(), &pre, Some(shelves[0]), &shelves[1..], OtherInstances::Ignored);
    assert_eq!(ignoring.pre.points, pre.points);
    let kept = ignoring.window(&settings);
    // Independently: the whole window of the frame with no instance ignored, less every box with IoU ≥ 0.25
    // to the other bookshelf.
    let whole = TrainingExample::new("whole".into(), &pre, Some(shelves[0]), &[]).window(&settings);
    let all = &whole.hypotheses.hypotheses;
    let expected: Vec<usize> =
        (0..all.len()).filter(|&n| iou_3d(&shelves[1], &all[n].cuboid(&whole.scene)) < 0.25).collect();
    assert!(expected.len() < all.len(), "no box of the window detects the other bookshelf");
    assert!(expected.len() > all.len() / 2, "{} of {} boxes left", expected.len(), all.len());
    assert_eq!(kept.hypotheses.hypotheses.len(), expected.len());
    for (k, &n) in expected.iter().enumerate() {
        assert_eq!(kept.hypotheses.hypotheses[k].cuboid(&kept.scene), all[n].cuboid(&whole.scene));
    }
    // The target is the same box (none of the dropped ones is nearest the truth), the losses those of the
    // kept boxes.
    let target = kept.target.expect("a box overlaps the truth");
    assert_eq!(Some(expected[target]), whole.target);
    for (k, &n) in expected.iter().enumerate() {
        assert_eq!(kept.losses[k], whole.losses[n]);
    }
}

/// A small problem on the real frame: chair sizes, a coarse window, the 3×3×3 grid.
fn small_oracle() -> DetectorOracle {
    small_oracle_with(PositiveTarget::Exact)
}

fn small_oracle_with(target: PositiveTarget) -> DetectorOracle {
    small_oracle_full(target, false)
}

/// A full pass caches at most `cached_rows_per_example` rows per example, the size `train` plans the cache
/// by: for counts under 4 too, whose quarter of boxes nearest the truth is none (it kept every box with a
/// loss under 1 before 2026-12-08: thousands per positive).
#[test]
fn a_full_pass_caches_no_more_rows_than_planned() {
    use cog_gpu::learn::detector::{cached_rows_per_example, train_detector};
    use cog_gpu::learn::{CuttingPlane, SeparationOracle, SsvmOptions};
    for count in [1, 3, 8] {
        let mut oracle = small_oracle();
        oracle.candidate_count = count;
        let options = SsvmOptions { c: 1.0, max_iterations: 1, quiet: true, ..SsvmOptions::default() };
        train_detector(&oracle, &mut CuttingPlane::new(options).unwrap()).unwrap();
        let state = oracle.run_state();
        // [tag, batch calls, full passes, round cap, examples, then per example its count and indices]
        let (mut at, mut rows) = (5, Vec::new());
        for _ in 0..state[4] {
            rows.push(state[at] as usize);
            at += 1 + state[at] as usize;
        }
        assert_eq!(at, state.len());
        assert!(rows.iter().all(|&r| r <= cached_rows_per_example(count)), "count {count}: rows {rows:?}");
        assert!(rows[0] >= count, "the positive caches its count at least: {rows:?}");
    }
}

fn frame_instances(frame: &Frame, category: &str) -> Vec<Cuboid> {
    frame.objects.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect()
}

/// The sizes of `instances`, a coarse window, the 3×3×3 grid.
fn small_settings(instances: &[Cuboid], target: PositiveTarget, surfaces: bool) -> TrainingSettings {
    let sizes = SizeQuantiles::from_cuboids(instances).unwrap().sizes().into_iter().step_by(7).collect();
    TrainingSettings {
        layout: FeatureLayout::new([3, 3, 3], false, Groups::ALL).unwrap(),
        sizes,
        step: 0.3,
        min_points: 50,
        engine: FeatureEngine::Fast(FastOptions::default()),
        target,
        yaw_anchor: YawAnchor::Walls,
        lattice: LatticePhase::Camera,
        support: Support::Floor,
        surfaces,
    }
}

fn small_oracle_full(target: PositiveTarget, surfaces: bool) -> DetectorOracle {
    let (frame, pre) = real_frame();
    let chairs = frame_instances(&frame, "chair");
    assert!(!chairs.is_empty());
    let settings = small_settings(&chairs, target, surfaces);
    let positive = TrainingExample::new("chair".into(), &pre, Some(chairs[0]), &chairs[1..]);
    let negative = TrainingExample::new("none".into(), &pre, None, &[]);
    DetectorOracle::new(settings, vec![positive, negative]).unwrap()
}

#[test]
fn loss_augmented_inference_finds_the_maximum_over_all_answers() {
    let oracle = small_oracle();
    let layout = oracle.settings.layout;
    // Deterministic weights of both signs.
    let w: Vec<f32> = (0..layout.dim()).map(|n| (((n * 2654435761) % 1000) as f32 / 1000.0 - 0.45) * 0.3).collect();
    for (i, ex) in oracle.examples.iter().enumerate() {
        let window = ex.window(&oracle.settings);
        let hyps = &window.hypotheses.hypotheses;
        assert!(hyps.len() > 10);
        // Independent maximisation: features of every hypothesis, dot products, the loss from geometry.
        let features = FastEngine::new(&window.scene, &layout, FastOptions::default()).features(hyps);
        let mut best = if ex.truth.is_some() { 1.0f64 } else { 0.0 }; // "no object"
        for (h, row) in hyps.iter().zip(features.chunks(layout.dim())) {
            let score: f64 = row.iter().zip(&w).map(|(&a, &b)| a as f64 * b as f64).sum();
            let loss = structured_loss(ex.truth.as_ref(), Some(&h.cuboid(&window.scene))) as f64;
            best = best.max(loss + score);
        }
        let (answer, loss) = oracle.loss_augmented_argmax(i, &w).unwrap();
        let value = match answer {
            Answer::NoObject => loss as f64,
            Answer::GroundTruth => {
                let truth = window.truth_hypothesis(ex.truth.as_ref().unwrap());
                let row = FastEngine::new(&window.scene, &layout, FastOptions::default()).features(&[truth]);
                assert_eq!(loss, 0.0);
                row.iter().zip(&w).map(|(&a, &b)| a as f64 * b as f64).sum()
            }
            Answer::Hypothesis(n) => {
                let expected = structured_loss(ex.truth.as_ref(), Some(&hyps[n].cuboid(&window.scene)));
                assert!((loss - expected).abs() < 1e-6, "loss {loss} vs {expected}");
                let row = &features[n * layout.dim()..(n + 1) * layout.dim()];
                loss as f64 + row.iter().zip(&w).map(|(&a, &b)| a as f64 * b as f64).sum::<f64>()
            }
        };
        assert!(value >= best - 1e-3 * (1.0 + best.abs()), "example {i}: oracle {value} < brute force {best}");
    }
}

/// With the best-window target, the positive's output is the window's hypothesis of smallest loss and
/// every loss is a regret against it: checked against losses recomputed from the geometry and a brute-force
/// maximum over every hypothesis's features.
#[test]
fn best_window_target_inference_maximises_the_regret_augmented_score() {
    let oracle = small_oracle_with(PositiveTarget::BestWindow);
    let layout = oracle.settings.layout;
    let w: Vec<f32> = (0..layout.dim()).map(|n| (((n * 2654435761) % 1000) as f32 / 1000.0 - 0.45) * 0.3).collect();
    let dot = |row: &[f32]| row.iter().zip(&w).map(|(&a, &b)| a as f64 * b as f64).sum::<f64>();
    for (i, ex) in oracle.examples.iter().enumerate() {
        let window = ex.window(&oracle.settings);
        let hyps = &window.hypotheses.hypotheses;
        let features = FastEngine::new(&window.scene, &layout, FastOptions::default()).features(hyps);
        let raw: Vec<f32> =
            hyps.iter().map(|h| structured_loss(ex.truth.as_ref(), Some(&h.cuboid(&window.scene)))).collect();
        // The target: the first hypothesis of smallest loss below 1 (positives only).
        let target = ex.truth.and_then(|_| {
            let m = raw.iter().copied().filter(|&l| l < 1.0).fold(f32::INFINITY, f32::min);
            raw.iter().position(|&l| l == m)
        });
        assert_eq!(window.target, target, "example {i}");
        assert_eq!(ex.truth.is_some(), target.is_some(), "the real frame's chair is reachable by the window");
        let offset = target.map_or(0.0, |t| raw[t]);
        let mut best = if ex.truth.is_some() { 1.0f64 } else { 0.0 };
        for (n, row) in features.chunks(layout.dim()).enumerate() {
            let regret = (raw[n] - offset).max(0.0);
            assert!((window.losses[n] - regret).abs() < 1e-6, "example {i} hypothesis {n}");
            best = best.max(regret as f64 + dot(row));
        }
        if let Some(t) = target {
            assert_eq!(window.losses[t], 0.0);
            let truth_row = &features[t * layout.dim()..(t + 1) * layout.dim()];
            use cog_gpu::learn::SeparationOracle;
            let stored = oracle.ground_truth_features(i).unwrap();
            assert!(stored.iter().zip(truth_row).all(|(a, b)| (a - b).abs() <= 1e-6 * (1.0 + b.abs())));
        }
        let (answer, loss) = oracle.loss_augmented_argmax(i, &w).unwrap();
        let value = match answer {
            Answer::NoObject => loss as f64,
            Answer::GroundTruth => {
                let t = target.expect("only positives answer their target");
                assert_eq!(loss, 0.0);
                dot(&features[t * layout.dim()..(t + 1) * layout.dim()])
            }
            Answer::Hypothesis(n) => {
                assert!((loss - window.losses[n]).abs() < 1e-6);
                loss as f64 + dot(&features[n * layout.dim()..(n + 1) * layout.dim()])
            }
        };
        assert!(value >= best - 1e-3 * (1.0 + best.abs()), "example {i}: oracle {value} < brute force {best}");
    }
}

/// The cached pass: after a full pass at w, the candidates of every example hold its window's argmax, so a
/// cached pass at the same w gives the same answer, and its value equals the brute-force maximum over the
/// cached features (dot products only).
#[test]
fn cached_pass_answers_like_the_full_pass_at_the_same_weights() {
    use cog_gpu::learn::SeparationOracle;
    let oracle = small_oracle();
    let dim = oracle.settings.layout.dim();
    let w: Vec<f64> = (0..dim).map(|n| (((n * 40503) % 997) as f64 / 997.0 - 0.5) * 0.2).collect();
    let examples: Vec<usize> = (0..oracle.examples.len()).collect();
    let full = oracle.most_violated_batch(&examples, &w).unwrap();
    assert!(oracle.last_pass_was_full());
    let cached = oracle.most_violated_batch(&examples, &w).unwrap();
    assert!(!oracle.last_pass_was_full(), "the second batch call must be a cached pass");
    for (a, b) in full.iter().zip(&cached) {
        assert_eq!(a.loss, b.loss);
        assert_eq!(a.features, b.features);
    }
}

/// 1-slack training on the small problem: the cutting-plane loop stops with the mean violation ≤ ε, and
/// the reported objective is the 1-slack primal recomputed here from the final w and the examples'
/// brute-force most violated outputs.
#[test]
fn one_slack_training_converges_and_reports_its_objective() {
    use cog_gpu::learn::{CuttingPlane, OneSlack, SeparationOracle, SsvmOptions};
    let mut oracle = small_oracle();
    oracle.max_full_passes = 3;
    let options = SsvmOptions { c: 1.0, epsilon: 0.01, max_iterations: 200, quiet: true, ..SsvmOptions::default() };
    let mut solver = CuttingPlane::new(options).unwrap();
    let trained = cog_gpu::learn::detector::train_detector(&oracle, &mut solver).unwrap();
    assert!(trained.solution.converged, "{:?}", trained.solution.history.last());
    assert!(trained.solution.max_violation <= 0.01 + 1e-9);
    let w = &trained.solution.w;
    // Independent 1-slack primal at w: ½‖w‖² + C·max(0, mean_i (Δ_i − wᵀψ_i)) over full-window answers.
    let one = OneSlack::new(&oracle).unwrap();
    oracle.force_full_pass();
    let answer = one.most_violated(0, w).unwrap();
    let truth = one.ground_truth_features(0).unwrap();
    let margin: f64 = truth.iter().zip(&answer.features).zip(w).map(|((t, f), wk)| wk * (*t as f64 - *f as f64)).sum();
    let primal = 0.5 * w.iter().map(|v| v * v).sum::<f64>() + (answer.loss - margin).max(0.0);
    if trained.verified {
        let last = trained.solution.primal;
        assert!((primal - last).abs() <= 1e-3 * (1.0 + last.abs()), "recomputed {primal} vs reported {last}");
    }
    assert!(w.iter().any(|v| *v != 0.0));
}

/// A resumed training continues with the interrupted run's candidate cache (in the checkpoint since
/// 2026-12-08) and ends with the uninterrupted run's weights, bit for bit — also past the full-pass
/// budget, where every pass reads the cache (before, a resume refilled the cache with a full pass at the
/// checkpoint's w, and its cached passes then read other candidates: other weights). The resumed oracle is
/// a fresh one, as in a new process.
#[test]
fn a_resumed_training_reads_the_interrupted_runs_candidates_and_ends_with_its_weights() {
    use cog_gpu::learn::detector::train_detector;
    use cog_gpu::learn::{CuttingPlane, SsvmOptions};
    let dir = tempfile::tempdir().unwrap();
    let checkpoint = dir.path().join("run.ckpt");
    let options = |iterations, checkpoint: Option<PathBuf>| SsvmOptions {
        c: 1.0,
        epsilon: 1e-6,
        max_iterations: iterations,
        quiet: true,
        checkpoint,
        ..SsvmOptions::default()
    };
    // One full pass, then only cached passes: the budget is spent at the first iteration.
    let oracle = || {
        let mut oracle = small_oracle();
        oracle.max_full_passes = 1;
        oracle
    };
    let straight_oracle = oracle();
    let straight = train_detector(&straight_oracle, &mut CuttingPlane::new(options(6, None)).unwrap()).unwrap();
    assert_eq!(straight.solution.iterations, 6, "the run must reach the cap to cover the cached passes");
    let interrupted = oracle();
    train_detector(&interrupted, &mut CuttingPlane::new(options(3, Some(checkpoint.clone()))).unwrap()).unwrap();
    let resumed_oracle = oracle();
    let mut resumed_solver = CuttingPlane::resume(options(6, Some(checkpoint.clone())), &checkpoint).unwrap();
    let resumed = train_detector(&resumed_oracle, &mut resumed_solver).unwrap();
    assert!(resumed.solution.w == straight.solution.w, "a resumed run must end with the uninterrupted weights");
    assert_eq!(resumed_oracle.full_passes(), 1, "no full pass after the resume: the budget was spent");
    assert_eq!(resumed.solution.iterations, 6);
    assert!(straight.solution.w.iter().any(|&v| v != 0.0));
    // A state that is not this training's is refused: cut short, for another number of examples, or with
    // a candidate index beyond an example's window.
    use cog_gpu::learn::SeparationOracle;
    let state = straight_oracle.run_state();
    let examples = straight_oracle.examples.len();
    assert_eq!(state[4], examples as u64);
    let first_count = state[5] as usize;
    assert!(first_count > 0);
    let mut too_far = state.clone();
    too_far[5 + first_count] = u64::from(u32::MAX - 1);
    let mut other_count = state.clone();
    other_count[4] += 1;
    for (bad, why) in [
        (state[..state.len() - 1].to_vec(), "is not this training's"),
        (other_count, "is not this training's"),
        (too_far, "hypotheses of its window"),
    ] {
        let err = oracle().restore_run_state(&bad).unwrap_err().to_string();
        assert!(err.contains(why), "{err}");
    }
}

/// With latent surfaces, a CCCP round resumed from its start (its progress saved, no solver checkpoint of
/// it yet) takes back the oracle's state of the round's start from the progress — the previous round's
/// candidate cache, the counters and round cap — and training ends with the uninterrupted run's weights
/// and slices. The resumed oracle is a fresh one, as in a new process.
#[test]
fn a_cccp_round_resumed_from_its_start_ends_as_the_uninterrupted_run() {
    use cog_gpu::learn::detector::{train_latent_detector, LatentProgress, LatentSettings};
    use cog_gpu::learn::SsvmOptions;
    let ssvm = SsvmOptions { c: 1.0, epsilon: 1e-3, max_iterations: 4, quiet: true, ..SsvmOptions::default() };
    let settings = LatentSettings { max_rounds: 2, tolerance: 0.0, full_passes_per_round: 1 };
    // A full pass every third batch call, two in the first round (the second at w ≠ 0: the cache the
    // second round starts from is not the one a full pass at its w = 0 would make), one more in the second.
    let oracle = || {
        let mut oracle = small_oracle_full(PositiveTarget::BestWindow, true);
        oracle.full_every = 3;
        oracle.max_full_passes = 2;
        oracle
    };
    // The top slice for every example: the imputation moves the positive's slice, so a second round runs.
    let start = |oracle: &DetectorOracle| LatentProgress {
        next_round: 0,
        latents: vec![6; oracle.examples.len()],
        rounds: Vec::new(),
        oracle_state: Vec::new(),
    };
    let mut straight_oracle = oracle();
    let mut saved = Vec::new();
    let first = start(&straight_oracle);
    let straight = train_latent_detector(&mut straight_oracle, &ssvm, first, &settings, false, |p| {
        saved.push(p.clone());
        Ok(())
    })
    .unwrap();
    assert_eq!(saved.len(), 2, "the second round must start: {:?}", straight.rounds);
    let second_round = saved[1].clone();
    assert!(!second_round.oracle_state.is_empty(), "the progress carries the oracle's state");
    let mut resumed_oracle = oracle();
    let resumed = train_latent_detector(&mut resumed_oracle, &ssvm, second_round, &settings, true, |_| Ok(())).unwrap();
    assert!(resumed.last.solution.w == straight.last.solution.w, "the resumed round ends with other weights");
    assert_eq!(resumed.latents, straight.latents);
    assert_eq!(resumed_oracle.full_passes(), straight_oracle.full_passes());
    assert_eq!(straight_oracle.full_passes(), 3, "two full passes in the first round, one in the second");
}

/// A tiny synthetic bedroom dataset written by `cog-gpu synth`.
/// Example limits of the tests: up to 100 instances and `negatives` frames spread evenly, the other
/// instances removed, the floor window, every instance.
fn example_limits(negatives: usize) -> cog_gpu::learn::detector::ExampleLimits {
    cog_gpu::learn::detector::ExampleLimits {
        positives: 100,
        negatives,
        negative_choice: cog_gpu::learn::detector::NegativeChoice::Spread,
        others: OtherInstances::Removed,
        support: Support::Floor,
        seen: None,
        min_in_view: None,
        normals: Default::default(),
    }
}

/// The frame directories of [`tiny_dataset`], sorted.
fn tiny_frames(dir: &Path) -> Vec<PathBuf> {
    let data = tiny_dataset(dir);
    let mut frames: Vec<PathBuf> = std::fs::read_dir(&data).unwrap().map(|e| e.unwrap().path()).collect();
    frames.retain(|p| p.is_dir());
    frames.sort();
    frames
}

fn tiny_dataset(dir: &Path) -> PathBuf {
    let data = dir.join("data");
    let out = run(&[
        "synth",
        "--out",
        data.to_str().unwrap(),
        "--frames",
        "4",
        "--seed",
        "11",
        "--width",
        "160",
        "--height",
        "120",
        "--rooms",
        "bedroom",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    data
}

fn train_args<'a>(data: &'a str, out: &'a str, iterations: &'a str) -> Vec<&'a str> {
    vec![
        "train",
        "--data",
        data,
        "--category",
        "bed",
        "--out",
        out,
        "--positives",
        "3",
        "--negatives",
        "1",
        "--step",
        "0.4",
        "--max-iterations",
        iterations,
        // Every iteration a full pass: a resumed run starts with one, so the straight run must too.
        "--full-every",
        "1",
        "--max-full-passes",
        "100",
    ]
}

#[test]
fn train_writes_a_model_and_resumes_to_the_same_weights() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path());
    let data = data.to_str().unwrap();
    let straight = dir.path().join("straight/bed.json");
    let split = dir.path().join("split/bed.json");
    let out = run(&train_args(data, straight.to_str().unwrap(), "3"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(Path::new(&format!("{}.ckpt", straight.display())).is_file());
    // Two iterations, then resume to three.
    let out = run(&train_args(data, split.to_str().unwrap(), "2"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut resumed = train_args(data, split.to_str().unwrap(), "3");
    resumed.push("--resume");
    let out = run(&resumed);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let read = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let (a, b) = (read(&straight), read(&split));
    assert_eq!(a["category"], "bed");
    // The options that shape the weights are in the file (the target, pruning and cap were not).
    let training = &a["training"];
    assert_eq!(
        (&training["target"], &training["prune_after"], &training["max_iterations"]),
        (&"best-window".into(), &10.into(), &3.into())
    );
    assert_eq!(a["weights"].as_array().unwrap().len(), FeatureLayout::default().dim());
    assert_eq!(a["weights"], b["weights"], "a resumed run must end with the same weights");
    assert!(a["weights"].as_array().unwrap().iter().any(|v| v.as_f64().unwrap() != 0.0));
    // A resume under another output space is refused, also where the ground truths' features come out
    // the same (another window's minimum points, the fast path's subdivisions, the support: accepted
    // before 2026-12-07, mixing two problems' constraints).
    for extra in [["--min-points", "300"], ["--subdivisions", "1"], ["--support", "free"]] {
        let mut changed = train_args(data, split.to_str().unwrap(), "4");
        changed.extend(extra);
        changed.push("--resume");
        let out = run(&changed);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("data hash"), "{extra:?}: {err}");
        // A 1-slack run has one example whatever the data: no "1 examples against 1" (it said so).
        let error = err.lines().find(|l| l.starts_with("error:")).unwrap_or_default();
        assert!(!error.contains("1 examples"), "{extra:?}: {error}");
    }
}

/// A resumed training counts its full passes against the one `--max-full-passes` budget with the run it
/// continues (the checkpoint carries the oracle's counters since 2026-12-07; before, a resumed run counted
/// from zero, made up to the whole budget again and recorded only its own) and continues with its
/// candidate cache (since 2026-12-08; before, it refilled the cache with one more full pass). Two
/// iterations at one full pass each spend a budget of 2; the resumed process makes no full pass, records
/// 2, and ends with the weights of a run that was never interrupted.
#[test]
fn a_resumed_training_keeps_the_full_pass_budget() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path());
    let data = data.to_str().unwrap();
    let out = dir.path().join("budget/bed.json");
    let straight = dir.path().join("straight/bed.json");
    let args = |out: &Path, iterations| {
        let mut args: Vec<String> =
            train_args(data, out.to_str().unwrap(), iterations).into_iter().map(String::from).collect();
        let budget = args.iter().position(|a| *a == "--max-full-passes").unwrap() + 1;
        args[budget] = "2".into();
        args
    };
    let first = run(&strs(&args(&out, "2")));
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let mut resumed = args(&out, "6");
    resumed.push("--resume".into());
    let second = run(&strs(&resumed));
    let log = String::from_utf8_lossy(&second.stderr);
    assert!(second.status.success(), "{log}");
    assert_eq!(log.matches("full pass ").count(), 0, "the resumed process: no full pass\n{log}");
    assert!(log.contains("restored the candidate cache"), "{log}");
    let uninterrupted = run(&strs(&args(&straight, "6")));
    assert!(uninterrupted.status.success(), "{}", String::from_utf8_lossy(&uninterrupted.stderr));
    let read = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let (model, reference) = (read(&out), read(&straight));
    assert_eq!(model["training"]["full_passes"], 2, "{}", model["training"]);
    assert_eq!(reference["training"]["full_passes"], 2, "{}", reference["training"]);
    assert!(model["weights"] == reference["weights"], "the resumed run ends with other weights");
}

/// Latent support surfaces end to end: a cuboid model, then `--surfaces-from` it (CCCP rounds recorded in
/// the model, version 2, the progress file written), `--resume` from that progress, and `detect` with the
/// surface model reports each detection's surface inside its box.
#[test]
fn train_with_surfaces_writes_a_version_2_model_that_detect_uses() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path());
    let data = data.to_str().unwrap();
    let cuboid = dir.path().join("cuboid/bed.json");
    let out = run(&train_args(data, cuboid.to_str().unwrap(), "3"));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let surface = dir.path().join("surface/bed.json");
    let mut args = train_args(data, surface.to_str().unwrap(), "3");
    args.extend(["--surfaces-from", cuboid.to_str().unwrap(), "--cccp-rounds", "2"]);
    let out = run(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let read = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let model = read(&surface);
    assert_eq!(model["version"], 2);
    assert_eq!(model["surface"]["slice"].as_array().unwrap().len(), 875);
    let rounds = model["training"]["surfaces"]["rounds"].as_array().unwrap();
    assert!((1..=2).contains(&rounds.len()), "{rounds:?}");
    for round in rounds {
        // The imputed slices of the 3 positives.
        assert_eq!(round["slices"].as_array().unwrap().iter().map(|v| v.as_u64().unwrap()).sum::<u64>(), 3);
    }
    let progress = PathBuf::from(format!("{}.cccp", surface.display()));
    assert!(read(&progress)["latents"].as_array().unwrap().len() >= 3, "one slice per example");
    let mut resumed = args.clone();
    resumed.push("--resume");
    let out = run(&resumed);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(read(&surface)["version"], 2);
    // The surface of a cuboid model is refused as a start.
    let again_out = dir.path().join("again/bed.json");
    let mut again = train_args(data, again_out.to_str().unwrap(), "3");
    again.extend(["--surfaces-from", surface.to_str().unwrap()]);
    let out = run(&again);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("already a model with surfaces"));
    // Detection with the surface model.
    let found = detect_first_frame(data, surface.parent().unwrap(), &dir.path().join("detections"));
    let list = found["detections"].as_array().unwrap();
    assert!(!list.is_empty());
    for d in list {
        let z = d["surface_z"].as_f64().expect("every detection of a surface model has a surface_z");
        let (centre, height) = (d["centre"][2].as_f64().unwrap(), d["size"][2].as_f64().unwrap());
        assert!((z - centre).abs() <= height / 2.0, "surface {z} outside the box {centre} ± {height}/2");
    }
}

/// The out-of-view group end to end: `train --groups …,out-of-view` writes a model of 12 360 weights whose
/// layout names the group, and `detect` reads and uses it (on a bedroom whose beds reach out of the 160×120
/// picture, some indicator weights are learned non-zero).
#[test]
fn train_with_out_of_view_indicators_writes_a_model_that_detect_uses() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path());
    let data = data.to_str().unwrap();
    let model_path = dir.path().join("oov/bed.json");
    let mut args = train_args(data, model_path.to_str().unwrap(), "3");
    args.extend(["--groups", "density,normals,cog,view,out-of-view"]);
    let out = run(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let read = |p: &Path| -> serde_json::Value { serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap() };
    let model = read(&model_path);
    let layout = FeatureLayout {
        groups: cog_gpu::features::Groups { out_of_view: true, ..cog_gpu::features::Groups::ALL },
        ..FeatureLayout::default()
    };
    let weights: Vec<f64> = model["weights"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(weights.len(), 12360);
    assert_eq!(weights.len(), layout.dim());
    assert!(weights[layout.out_of_view_offset()..].iter().any(|&w| w != 0.0), "no indicator weight learned");
    assert!(model.to_string().contains("out-of-view"), "the model's layout names the group");
    let found = detect_first_frame(data, model_path.parent().unwrap(), &dir.path().join("detections"));
    assert!(!found["detections"].as_array().unwrap().is_empty());
}

/// `detect` of the first frame of `data` with the models of `models` (no overlay, raw scores down to −5)
/// into `out`; its detections file.
fn detect_first_frame(data: &str, models: &Path, out: &Path) -> serde_json::Value {
    let frame = std::fs::read_dir(data).unwrap().flatten().map(|e| e.path()).find(|p| p.is_dir()).unwrap();
    let args =
        ["detect", frame.to_str().unwrap(), "--models", models.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let result = run(&[&args[..], &["--min-score", "-5", "--no-overlay"]].concat());
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let name = frame.file_name().unwrap().to_str().unwrap();
    serde_json::from_str(&std::fs::read_to_string(out.join(format!("{name}.json"))).unwrap()).unwrap()
}

#[test]
fn train_rejects_bad_input_with_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nowhere");
    let out_model = dir.path().join("m/bed.json");
    let chair = |extra: &[&str]| -> Vec<String> {
        ["train", "--data", FRAME, "--category", "chair"].iter().chain(extra).map(|a| a.to_string()).collect()
    };
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["train".into(), "--data".into(), missing.display().to_string(), "--category".into(), "bed".into()],
            "nowhere",
        ),
        (
            vec!["train".into(), "--data".into(), FRAME.into(), "--category".into(), "spaceship".into()],
            "unknown category",
        ),
        // The latent training's options without --surfaces-from were accepted and did nothing.
        (chair(&["--cccp-rounds", "2"]), "--surfaces-from"),
        // 0 dropped every constraint as it came in: the run learnt nothing, with exit 0.
        (chair(&["--prune-after", "0"]), "--prune-after"),
        (
            vec![
                "train".into(),
                "--data".into(),
                FRAME.into(),
                "--category".into(),
                "bathtub".into(),
                "--out".into(),
                out_model.display().to_string(),
            ],
            "no 'bathtub'",
        ),
        (
            vec![
                "train".into(),
                "--data".into(),
                FRAME.into(),
                "--category".into(),
                "chair".into(),
                "--out".into(),
                out_model.display().to_string(),
                "--resume".into(),
            ],
            "no checkpoint",
        ),
        (
            vec![
                "train".into(),
                "--data".into(),
                FRAME.into(),
                "--category".into(),
                "chair".into(),
                "--groups".into(),
                "colour".into(),
            ],
            "unknown feature group",
        ),
    ];
    for (args, needle) in cases {
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = run(&refs);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: expected '{needle}' in: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// Latent support surfaces (paper §4.1): loss-augmented inference maximises jointly over the window's
/// hypotheses and their seven slices, checked against a brute force over features computed independently
/// (the cuboid engine and the surface engine); the answer's feature vector is `[φ_cuboid, φ_surface(h), e_h]`;
/// the ground truth's features follow the latent set for it, and imputation picks its best slice.
#[test]
fn surface_inference_maximises_over_hypotheses_and_slices() {
    use cog_gpu::features::surface::{SurfaceEngine, SLICES, SLICE_DIM};
    use cog_gpu::learn::latent::{impute, LatentOracle};
    use cog_gpu::learn::SeparationOracle;
    let oracle = small_oracle_full(PositiveTarget::BestWindow, true);
    let layout = oracle.settings.layout;
    let dim = layout.dim();
    assert_eq!(SeparationOracle::dim(&oracle), dim + SLICE_DIM + SLICES);
    let w: Vec<f64> =
        (0..SeparationOracle::dim(&oracle)).map(|n| (((n * 2654435761) % 1000) as f64 / 1000.0 - 0.45) * 0.3).collect();
    let dot = |row: &[f32], weights: &[f64]| row.iter().zip(weights).map(|(&a, &b)| a as f64 * b).sum::<f64>();
    for (i, ex) in oracle.examples.iter().enumerate() {
        let window = ex.window(&oracle.settings);
        let hyps = &window.hypotheses.hypotheses;
        let cuboid = FastEngine::new(&window.scene, &layout, FastOptions::default()).features(hyps);
        let slices = SurfaceEngine::new(&window.scene, layout.groups, FastOptions::default()).slices(hyps);
        let per_hyp = SLICES * SLICE_DIM;
        let mut best = if ex.truth.is_some() { 1.0f64 } else { 0.0 };
        for n in 0..hyps.len() {
            let cuboid_score = dot(&cuboid[n * dim..(n + 1) * dim], &w[..dim]);
            for h in 0..SLICES {
                let slice = &slices[n * per_hyp + h * SLICE_DIM..n * per_hyp + (h + 1) * SLICE_DIM];
                let value = window.losses[n] as f64
                    + cuboid_score
                    + dot(slice, &w[dim..dim + SLICE_DIM])
                    + w[dim + SLICE_DIM + h];
                best = best.max(value);
            }
        }
        let answer = SeparationOracle::most_violated(&oracle, i, &w).unwrap();
        let value = answer.loss + dot(&answer.features, &w);
        assert!((value - best).abs() <= 1e-3 * (1.0 + best.abs()), "example {i}: oracle {value}, brute force {best}");
        let indicator = &answer.features[dim + SLICE_DIM..];
        let ones = indicator.iter().filter(|&&v| v == 1.0).count();
        let zeros = indicator.iter().filter(|&&v| v == 0.0).count();
        assert!((ones, zeros) == (1, SLICES - 1) || indicator.iter().all(|&v| v == 0.0), "{indicator:?}");
        if let Some(t) = window.target {
            // φ(x, y, h) of the ground truth for each h, and the imputed slice is the best of them.
            let mut best_h = (0, f64::NEG_INFINITY);
            for h in 0..SLICES {
                let features = LatentOracle::ground_truth_features(&oracle, i, h).unwrap();
                assert_eq!(&features[..dim], &cuboid[t * dim..(t + 1) * dim]);
                let slice = &slices[t * per_hyp + h * SLICE_DIM..t * per_hyp + (h + 1) * SLICE_DIM];
                assert_eq!(&features[dim..dim + SLICE_DIM], slice);
                assert_eq!(features[dim + SLICE_DIM + h], 1.0);
                let score = dot(&features, &w);
                if score > best_h.1 {
                    best_h = (h, score);
                }
            }
            assert_eq!(oracle.num_latents(i), SLICES);
            assert_eq!(impute(&oracle, &w).unwrap()[i], best_h.0);
        } else {
            assert_eq!(oracle.num_latents(i), 1);
        }
    }
    // Setting the latents changes the ground truth's features to that slice.
    let positive = (0..oracle.examples.len()).find(|&i| oracle.examples[i].truth.is_some()).unwrap();
    let mut latents = vec![0; oracle.examples.len()];
    latents[positive] = 5;
    oracle.set_latents(&latents).unwrap();
    let truth = SeparationOracle::ground_truth_features(&oracle, positive).unwrap();
    assert_eq!(truth, LatentOracle::ground_truth_features(&oracle, positive, 5).unwrap());
    assert!(oracle.set_latents(&[7, 0]).is_err(), "slice 7 does not exist");
}

/// A window on surfaces learns its supporters from the training positives: on synthetic kitchens and
/// bathrooms (basins on counters, pedestal sinks on the floor) the sink's are exactly the categories that
/// the generator's support files name as the chosen sinks' supporters (read here only, never by
/// training); the examples keep the surfaces of every annotated surface object (other furniture's are
/// negatives to learn from); a floor window keeps every surface category (and builds no surfaces).
#[test]
fn a_surface_window_learns_its_supporters_from_the_positives() {
    use cog_gpu::category::SurfaceCategories;
    use cog_gpu::learn::detector::{collect_examples, read_all_annotations, ExampleLimits};
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let args = ["--frames", "8", "--seed", "5", "--width", "320", "--height", "240", "--rooms", "kitchen,bathroom"];
    let out = run(&[&["synth", "--out", data.to_str().unwrap()][..], &args[..]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut frames: Vec<PathBuf> = std::fs::read_dir(&data).unwrap().map(|e| e.unwrap().path()).collect();
    frames.retain(|p| p.join("synth_support.json").is_file());
    frames.sort();
    // The supporters' categories of every sink, from the support files (all sinks are chosen: 100 ≥ their count).
    let mut expected = SurfaceCategories::NONE;
    let mut sinks = 0;
    for frame in &frames {
        let support: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(frame.join("synth_support.json")).unwrap()).unwrap();
        let objects = support["objects"].as_array().unwrap();
        for o in objects.iter().filter(|o| o["category"] == "sink") {
            sinks += 1;
            if let Some(parent) = o["supported_by"]["annotation_index"].as_u64() {
                let parent = objects.iter().find(|p| p["annotation_index"].as_u64() == Some(parent)).unwrap();
                expected = expected.with(parent["category"].as_str().unwrap()).unwrap();
            }
        }
    }
    assert!(sinks > 0 && expected != SurfaceCategories::NONE, "seed 5 must give sinks on counters");
    let limits = |support| ExampleLimits { support, ..example_limits(2) };
    let collected = collect_examples(&frames, "sink", limits(Support::FloorAndSurfaces)).unwrap();
    assert_eq!(collected.supporters, expected);
    let annotations = read_all_annotations(&frames).unwrap();
    let surface_boxes: Vec<Cuboid> = annotations
        .iter()
        .flatten()
        .filter(|o| SurfaceCategories::ALL.contains(&o.category))
        .map(|o| o.cuboid)
        .collect();
    assert!(collected.examples.iter().any(|e| !e.surfaces.is_empty()));
    for example in &collected.examples {
        assert!(example.surfaces.iter().all(|s| surface_boxes.contains(&s.object)), "{}", example.name);
    }
    let floor = collect_examples(&frames, "sink", limits(Support::Floor)).unwrap();
    assert!(floor.supporters.is_all());
    assert!(floor.examples.iter().all(|e| e.surfaces.is_empty()));
}

#[test]
fn the_seen_rule_counts_the_points_above_the_floor_slab_inside_the_box() {
    use cog_gpu::learn::detector::SeenRule;
    use glam::Vec3;
    // A 1 m cube standing on the floor (z = 0) two metres ahead.
    let cube = Cuboid::new(Vec3::new(0.0, 2.0, 0.5), Vec3::ONE, 0.0);
    let points = [
        Vec3::new(0.0, 2.0, 0.5),   // inside, above the slab
        Vec3::new(0.4, 2.4, 0.9),   // inside, above the slab
        Vec3::new(-0.4, 1.6, 0.25), // inside, above the slab (0.25 > 0.2)
        Vec3::new(0.0, 2.0, 0.1),   // inside, in the floor slab
        Vec3::new(0.0, 3.0, 0.5),   // outside (y beyond 2.5)
        Vec3::new(0.6, 2.0, 0.5),   // outside (x beyond 0.5)
    ];
    let rule = |min_points| SeenRule { min_points, floor_slab: 0.2 };
    assert!(rule(3).sees(&cube, &points, 0.0));
    assert!(!rule(4).sees(&cube, &points, 0.0), "the slab point and the two outside must not count");
    // A higher floor moves the slab: z 0.25 is then within 0.2 of a floor at 0.1.
    assert!(!rule(3).sees(&cube, &points, 0.1));
    assert!(rule(2).sees(&cube, &points, 0.1));
}

/// Adds to each frame's annotation a copy of every bed moved 40 m along X; returns how many.
fn add_far_bed_copies(frames: &[PathBuf]) -> usize {
    let mut copies = 0;
    for frame in frames {
        let path = frame.join("annotation3Dfinal/index.json");
        let mut index: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let objects = index["objects"].as_array_mut().unwrap();
        let beds: Vec<serde_json::Value> =
            objects.iter().filter(|o| !o.is_null() && o["name"] == "bed").cloned().collect();
        for mut bed in beds {
            for x in bed["polygon"][0]["X"].as_array_mut().unwrap() {
                *x = serde_json::json!(x.as_f64().unwrap() + 40.0);
            }
            objects.push(bed);
            copies += 1;
        }
        std::fs::write(&path, serde_json::to_string(&index).unwrap()).unwrap();
    }
    copies
}

#[test]
fn skip_unseen_leaves_out_instances_without_points() {
    use cog_gpu::learn::detector::{collect_examples, ExampleLimits, SeenRule};
    let dir = tempfile::tempdir().unwrap();
    let frames = tiny_frames(dir.path());
    // Beside every bed, a copy 40 m away along X: far beyond any depth sensor, it holds no point.
    let far_copies = add_far_bed_copies(&frames);
    assert!(far_copies > 0, "seed 11's bedrooms must have beds");
    let is_far = |c: &Cuboid| c.centre.truncate().length() > 30.0;
    let limits = |seen| ExampleLimits { seen, ..example_limits(1) };
    let truths = |seen| -> Vec<Cuboid> {
        let collected = collect_examples(&frames, "bed", limits(seen)).unwrap();
        collected.examples.iter().filter_map(|e| e.truth).collect()
    };
    let all = truths(None);
    assert_eq!(all.iter().filter(|c| is_far(c)).count(), far_copies, "without the rule every instance is a positive");
    let seen = truths(Some(SeenRule { min_points: 50, floor_slab: 0.2 }));
    assert!(seen.iter().all(|c| !is_far(c)), "an instance without points must not be a positive");
    assert!(!seen.is_empty(), "the beds in view stay positives");
    assert_eq!(seen.len() + far_copies, all.len(), "the beds in view all hold 50 points: only the copies go");
}

#[test]
fn skip_out_of_view_leaves_out_instances_beside_the_picture() {
    use cog_gpu::frame::{DepthSource, Frame};
    use cog_gpu::geometry::{in_view_share, Camera};
    use cog_gpu::learn::detector::{collect_examples, ExampleLimits};
    let dir = tempfile::tempdir().unwrap();
    let frames = tiny_frames(dir.path());
    // Beside every bed, a copy 40 m along X: more than 10 m sideways for every metre ahead, far outside
    // any camera's field of view (none of it in the picture).
    let copies = add_far_bed_copies(&frames);
    assert!(copies > 0, "seed 11's bedrooms must have beds");
    // The originals' shares, from each frame's camera.
    let mut expected_kept = 0;
    for frame in &frames {
        let read = Frame::read(frame, DepthSource::Raw).unwrap();
        let camera = Camera::new(read.intrinsics(), read.rtilt());
        for bed in read.objects.iter().filter(|o| o.category == "bed" && o.cuboid.centre.truncate().length() < 30.0) {
            expected_kept += (in_view_share(&bed.cuboid, &camera, read.width(), read.height()) >= 0.25) as usize;
        }
    }
    let is_copy = |c: &Cuboid| c.centre.truncate().length() > 30.0;
    let truths = |min_in_view| -> Vec<Cuboid> {
        let limits = ExampleLimits { min_in_view, ..example_limits(1) };
        collect_examples(&frames, "bed", limits).unwrap().examples.iter().filter_map(|e| e.truth).collect()
    };
    let all = truths(None);
    assert_eq!(all.iter().filter(|c| is_copy(c)).count(), copies, "without the rule every instance is a positive");
    let kept = truths(Some(0.25));
    assert!(kept.iter().all(|c| !is_copy(c)), "an instance out of the picture must not be a positive");
    assert!(expected_kept > 0, "some of the beds are in the picture");
    assert_eq!(kept.len(), expected_kept, "exactly the beds with a quarter of their box in view stay");
}

/// `hardest` by hand: the highest hardness first, ties to the earlier candidate, NaN and −∞ last, and the
/// choice returned in the candidates' order.
#[test]
fn hardest_takes_the_highest_scores_in_frame_order() {
    use cog_gpu::learn::detector::hardest;
    let candidates = [3, 5, 8, 9, 12];
    let hardness = [0.2, f32::NEG_INFINITY, 0.9, 0.2, 0.5];
    assert_eq!(hardest(&candidates, &hardness, 1), vec![8]);
    assert_eq!(hardest(&candidates, &hardness, 2), vec![8, 12]);
    // 0.2 twice: the earlier candidate (3) before the later (9).
    assert_eq!(hardest(&candidates, &hardness, 3), vec![3, 8, 12]);
    assert_eq!(hardest(&candidates, &hardness, 4), vec![3, 8, 9, 12]);
    assert_eq!(hardest(&candidates, &hardness, 10), candidates.to_vec());
    assert_eq!(hardest(&candidates, &hardness, 0), Vec::<usize>::new());
    let with_nan = [f32::NAN, 0.1, -0.3];
    assert_eq!(hardest(&[0, 1, 2], &with_nan, 1), vec![1], "a NaN hardness is never the hardest");
}

/// `--hard-negatives`: the negative examples are the frames without the category that the given best
/// scores rank highest (not the even spread), and a frame without the category but without a score is
/// an error naming it.
#[test]
fn hard_negatives_are_the_frames_an_earlier_detector_scored_highest() {
    use cog_gpu::learn::detector::{collect_examples, ExampleLimits, NegativeChoice};
    use std::collections::BTreeMap;
    let dir = tempfile::tempdir().unwrap();
    let frames = tiny_frames(dir.path());
    assert_eq!(frames.len(), 4);
    let name = |f: &PathBuf| f.file_name().unwrap().to_string_lossy().into_owned();
    // Bedrooms hold no toilet: all four frames are negatives of the toilet.
    let scores = [0.1, 0.9, f32::NEG_INFINITY, 0.5];
    let best_scores: BTreeMap<String, f32> = frames.iter().map(name).zip(scores).collect();
    let limits = |negative_choice| ExampleLimits { negative_choice, ..example_limits(2) };
    let names = |choice| -> Vec<String> {
        let collected = collect_examples(&frames, "toilet", limits(choice)).unwrap();
        assert!(collected.examples.iter().all(|e| e.truth.is_none()));
        collected.examples.iter().map(|e| e.name.clone()).collect()
    };
    let expected: Vec<String> = [1, 3].iter().map(|&i| format!("{} (no toilet)", name(&frames[i]))).collect();
    let hard = |share| NegativeChoice::Hardest { best_scores: best_scores.clone(), share };
    assert_eq!(names(hard(1.0)), expected);
    // Half of the two hardest (frame 1), the other spread over frames 0, 2 and 3 (the first of them).
    let half: Vec<String> = [0, 1].iter().map(|&i| format!("{} (no toilet)", name(&frames[i]))).collect();
    assert_eq!(names(hard(0.5)), half);
    // The even spread of 2 of 4 takes frames 0 and 2: the hard choice is not the default.
    let spread: Vec<String> = [0, 2].iter().map(|&i| format!("{} (no toilet)", name(&frames[i]))).collect();
    assert_eq!(names(NegativeChoice::Spread), spread);
    let mut missing = best_scores;
    missing.remove(&name(&frames[2]));
    let err = collect_examples(&frames, "toilet", limits(NegativeChoice::Hardest { best_scores: missing, share: 1.0 }))
        .err()
        .expect("a negative frame without a score must be an error")
        .to_string();
    assert!(err.contains(&name(&frames[2])) && err.contains("no detections file"), "{err}");
}

/// `train --hard-negatives DIR` refuses a directory without detection files before any training.
#[test]
fn hard_negatives_from_an_empty_directory_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path());
    let empty = dir.path().join("no-detections");
    std::fs::create_dir(&empty).unwrap();
    let out = run(&[
        "train",
        "--data",
        data.to_str().unwrap(),
        "--category",
        "bed",
        "--out",
        dir.path().join("bed.json").to_str().unwrap(),
        "--hard-negatives",
        empty.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--hard-negatives") && stderr.contains("no detection files"), "{stderr}");
}
