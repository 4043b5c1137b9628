//! The detector's half of the structural SVM (paper §3.4): training examples made from annotated frames
//! and loss-augmented inference over the sliding window as a [`SeparationOracle`].
//!
//! # Examples (choices where the paper is terse)
//! * One example per annotated instance of the category; in a frame with several instances, each copy has
//!   the points inside the **other** instances' cuboids removed (§3.4, after Vedaldi & Zisserman).
//! * Frames without the category give "no object" examples (y = 0): their ground truth has φ = 0, and
//!   every cuboid answer costs loss 1, so they teach the detector what is not the category. The paper
//!   trains on positive images only; a few negatives keep scores of other furniture low, which matters
//!   for AP over whole images.
//! * The output space of an example is the sliding window of the category's sizes on the example's frame
//!   (centre step [`TrainingSettings::step`], coarser than detection's to keep training within its
//!   budget; the ground truth itself is always a candidate, so the margin is enforced on it exactly), plus
//!   "no object" (φ = 0, loss 1 when the example has an instance, 0 otherwise), plus the ground truth.
//! * The ground truth's features are those of its cuboid at the nearest of the 16 hypothesis yaws (the
//!   feature engine bins points per yaw); its loss is 0.
//! * Loss (eq. 5): `1 − IoU·(1 + cos Δθ)/2` ([`structured_loss`]). Hypotheses whose footprints cannot
//!   overlap the truth's have loss 1 without an IoU computation.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

use glam::Vec3;
use rayon::prelude::*;

use super::{Constraint, SeparationOracle};
use crate::error::{Error, Result};
use crate::features::cpu;
use crate::features::fast::{FastEngine, FastOptions};
use crate::features::hypotheses::{default_yaws, sliding_window, HypothesisSet, WindowOptions, YAW_COUNT};
use crate::features::{FeatureScene, Hypothesis, Layout, Preprocessed};
use crate::geometry::{structured_loss, Cuboid};

/// Which feature implementation training (and a model) uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FeatureEngine {
    /// [`crate::features::cpu`]: exact, slow.
    Exact,
    /// [`crate::features::fast`] with these options.
    Fast(FastOptions),
}

/// Settings of the detector's output space during training.
#[derive(Clone, Debug)]
pub struct TrainingSettings {
    pub layout: Layout,
    /// The 45 (or fewer) hypothesis sizes.
    pub sizes: Vec<Vec3>,
    /// Centre step of the training sliding window (metres).
    pub step: f32,
    pub min_points: u32,
    pub engine: FeatureEngine,
}

/// One training example: a frame's preprocessed points (other instances removed) and its ground truth.
#[derive(Clone, Debug)]
pub struct TrainingExample {
    /// Frame name and instance, for messages.
    pub name: String,
    pub truth: Option<Cuboid>,
    pub scene: FeatureScene,
    pub hypotheses: HypothesisSet,
    /// `Δ(truth, h)` of every hypothesis (independent of w, so computed once).
    pub losses: Vec<f32>,
}

impl TrainingExample {
    /// Builds the example: removes the points inside `others`, builds the yaw grids and the sliding
    /// window, and the losses.
    pub fn new(
        name: String,
        pre: &Preprocessed,
        truth: Option<Cuboid>,
        others: &[Cuboid],
        settings: &TrainingSettings,
    ) -> TrainingExample {
        let pre = without_points_in(pre, others);
        let scene = FeatureScene::new(pre, &default_yaws(), settings.step);
        let hypotheses =
            sliding_window(&scene, &WindowOptions { sizes: settings.sizes.clone(), min_points: settings.min_points });
        let losses =
            hypotheses.hypotheses.par_iter().map(|h| hypothesis_loss(truth.as_ref(), &h.cuboid(&scene))).collect();
        TrainingExample { name, truth, scene, hypotheses, losses }
    }

    /// The ground truth as a hypothesis of the nearest yaw.
    pub fn truth_hypothesis(&self) -> Option<Hypothesis> {
        self.truth.map(|t| Hypothesis::from_cuboid(&self.scene, nearest_yaw_index(t.yaw), &t))
    }
}

/// The loss of answering `estimate` when the truth is `truth` (eq. 5 with the presence cases).
pub fn hypothesis_loss(truth: Option<&Cuboid>, estimate: &Cuboid) -> f32 {
    if let Some(t) = truth {
        let reach = 0.5 * (t.size.truncate().length() + estimate.size.truncate().length());
        if t.centre.truncate().distance(estimate.centre.truncate()) > reach {
            return 1.0; // footprints cannot overlap: IoU 0
        }
    }
    structured_loss(truth, Some(estimate))
}

/// Index of the hypothesis yaw `2πk/16` nearest to `yaw`.
pub fn nearest_yaw_index(yaw: f32) -> usize {
    let k = (yaw / std::f32::consts::TAU * YAW_COUNT as f32).round() as i64;
    k.rem_euclid(YAW_COUNT as i64) as usize
}

/// A copy of `pre` without the points inside any of `cuboids`.
pub fn without_points_in(pre: &Preprocessed, cuboids: &[Cuboid]) -> Preprocessed {
    if cuboids.is_empty() {
        return pre.clone();
    }
    let keep: Vec<bool> = pre.points.iter().map(|p| !cuboids.iter().any(|c| c.contains(*p))).collect();
    let pick = |values: &[_]| values.iter().zip(&keep).filter(|(_, &k)| k).map(|(v, _)| *v).collect();
    Preprocessed {
        camera: pre.camera,
        image_size: pre.image_size,
        points: pick(&pre.points),
        normals: pick(&pre.normals),
        gradients: pre.gradients.iter().zip(&keep).filter(|(_, &k)| k).map(|(g, _)| *g).collect(),
        floor: pre.floor,
    }
}

/// Loss-augmented inference over training examples.
///
/// # Candidate cache
/// A full pass scores every hypothesis of every example (most of training's time). Each full pass also
/// keeps, per example, the [`DetectorOracle::candidate_count`] hypotheses of largest `Δ + w·φ`; a cached
/// pass maximises over those candidates only (plus the ground truth and "no object"), ~100× cheaper.
/// Batch calls ([`SeparationOracle::most_violated_batch`], one per cutting-plane iteration) are full
/// passes every [`DetectorOracle::full_every`] calls and cached in between. Convergence must only be
/// accepted after a full pass: `cog-gpu train` checks [`DetectorOracle::last_pass_was_full`] and, after a
/// cached pass found nothing, forces a full one ([`DetectorOracle::force_full_pass`]) and continues —
/// so the stopping rule holds over the whole output space. (A resumed run starts with a full pass, so it
/// can differ from an uninterrupted one in which a cached iteration ran there — not in its stopping rule.)
pub struct DetectorOracle {
    pub settings: TrainingSettings,
    pub examples: Vec<TrainingExample>,
    /// φ of each example's ground truth (zeros for "no object").
    truth_features: Vec<Vec<f32>>,
    /// Hypotheses kept per example by a full pass.
    pub candidate_count: usize,
    /// A full pass every this many batch calls (1: always full).
    pub full_every: usize,
    cached: AtomicBool,
    force_full: AtomicBool,
    batch_calls: AtomicUsize,
    candidates: Mutex<Vec<Vec<u32>>>,
}

impl DetectorOracle {
    pub fn new(settings: TrainingSettings, examples: Vec<TrainingExample>) -> Result<DetectorOracle> {
        if examples.is_empty() {
            return Err(Error::Input("no training examples".into()));
        }
        let dim = settings.layout.dim();
        let truth_features = examples
            .par_iter()
            .map(|ex| match ex.truth_hypothesis() {
                Some(h) => features_of(&settings, &ex.scene, &[h]),
                None => vec![0.0; dim],
            })
            .collect();
        let candidates = Mutex::new(vec![Vec::new(); examples.len()]);
        Ok(DetectorOracle {
            settings,
            examples,
            truth_features,
            candidate_count: 300,
            full_every: 1,
            cached: AtomicBool::new(false),
            force_full: AtomicBool::new(false),
            batch_calls: AtomicUsize::new(0),
            candidates,
        })
    }

    /// Whether the latest batch call was a full pass.
    pub fn last_pass_was_full(&self) -> bool {
        !self.cached.load(Ordering::SeqCst)
    }

    /// Makes the next batch call a full pass.
    pub fn force_full_pass(&self) {
        self.force_full.store(true, Ordering::SeqCst);
    }

    /// Scores of the hypotheses `subset` (indices into example `i`'s sliding window) at weights `w`.
    pub fn scores(&self, example: usize, subset: &[u32], w: &[f32]) -> Vec<f32> {
        let ex = &self.examples[example];
        let weights = vec![w.to_vec()];
        let hypotheses: Vec<Hypothesis> = subset.iter().map(|&n| ex.hypotheses.hypotheses[n as usize]).collect();
        match self.settings.engine {
            FeatureEngine::Exact => cpu::scores(&ex.scene, &self.settings.layout, &hypotheses, &weights).0,
            FeatureEngine::Fast(options) => {
                FastEngine::new(&ex.scene, &self.settings.layout, options).scores(&hypotheses, &weights)
            }
        }
    }
}

/// Features of `hypotheses` (row-major) with the settings' engine.
fn features_of(settings: &TrainingSettings, scene: &FeatureScene, hypotheses: &[Hypothesis]) -> Vec<f32> {
    match settings.engine {
        FeatureEngine::Exact => cpu::features(scene, &settings.layout, hypotheses).0,
        FeatureEngine::Fast(options) => FastEngine::new(scene, &settings.layout, options).features(hypotheses),
    }
}

/// The answer of loss-augmented inference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Answer {
    /// Hypothesis index into the example's sliding window.
    Hypothesis(usize),
    NoObject,
    GroundTruth,
}

impl DetectorOracle {
    /// `argmax Δ + w·φ` over the example's answers, with its loss.
    pub fn loss_augmented_argmax(&self, example: usize, w: &[f32]) -> Result<(Answer, f32)> {
        let ex = &self.examples[example];
        let cached = self.cached.load(Ordering::SeqCst);
        let subset: Vec<u32> = if cached {
            self.candidates.lock().map_err(|_| Error::Input("candidate cache poisoned".into()))?[example].clone()
        } else {
            (0..ex.hypotheses.hypotheses.len() as u32).collect()
        };
        let scores = self.scores(example, &subset, w);
        if !cached {
            self.keep_candidates(example, &scores)?;
        }
        let no_object_loss = if ex.truth.is_some() { 1.0 } else { 0.0 };
        let mut best = (Answer::NoObject, no_object_loss, no_object_loss);
        if ex.truth.is_some() {
            let truth_score: f32 = self.truth_features[example].iter().zip(w).map(|(a, b)| a * b).sum();
            if truth_score > best.2 {
                best = (Answer::GroundTruth, 0.0, truth_score);
            }
        }
        for (&n, &score) in subset.iter().zip(&scores) {
            let loss = ex.losses[n as usize];
            let value = loss + score;
            if value > best.2 {
                best = (Answer::Hypothesis(n as usize), loss, value);
            }
        }
        Ok((best.0, best.1))
    }

    /// Remembers the [`DetectorOracle::candidate_count`] hypotheses of largest `Δ + w·φ` of a full pass.
    fn keep_candidates(&self, example: usize, scores: &[f32]) -> Result<()> {
        let losses = &self.examples[example].losses;
        let value = |n: usize| losses[n] + scores[n];
        let mut order: Vec<u32> = (0..scores.len() as u32).collect();
        let keep = self.candidate_count.min(order.len());
        if keep < order.len() {
            order.select_nth_unstable_by(keep, |&a, &b| value(b as usize).total_cmp(&value(a as usize)));
            order.truncate(keep);
        }
        order.sort_unstable();
        self.candidates.lock().map_err(|_| Error::Input("candidate cache poisoned".into()))?[example] = order;
        Ok(())
    }
}

impl SeparationOracle for DetectorOracle {
    fn num_examples(&self) -> usize {
        self.examples.len()
    }

    fn dim(&self) -> usize {
        self.settings.layout.dim()
    }

    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        Ok(self.truth_features[example].clone())
    }

    fn most_violated_batch(&self, examples: &[usize], w: &[f64]) -> Result<Vec<Constraint>> {
        let call = self.batch_calls.fetch_add(1, Ordering::SeqCst);
        let full = self.force_full.swap(false, Ordering::SeqCst) || call.is_multiple_of(self.full_every.max(1));
        self.cached.store(!full, Ordering::SeqCst);
        examples.par_iter().map(|&example| self.most_violated(example, w)).collect()
    }

    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let w32: Vec<f32> = w.iter().map(|&v| v as f32).collect();
        let (answer, loss) = self.loss_augmented_argmax(example, &w32)?;
        let ex = &self.examples[example];
        let features = match answer {
            Answer::NoObject => vec![0.0; self.dim()],
            Answer::GroundTruth => self.truth_features[example].clone(),
            Answer::Hypothesis(n) => features_of(&self.settings, &ex.scene, &[ex.hypotheses.hypotheses[n]]),
        };
        Ok(Constraint { loss: loss as f64, features })
    }
}

/// How many examples to take from a dataset.
#[derive(Clone, Copy, Debug)]
pub struct ExampleLimits {
    /// Instances of the category (spread evenly over the dataset's instances when there are more).
    pub positives: usize,
    /// Frames without the category (spread evenly).
    pub negatives: usize,
}

/// The instances of `category` in a frame's annotations.
pub fn instances_of(objects: &[crate::frame::Object], category: &str) -> Vec<Cuboid> {
    objects.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect()
}

/// Evenly spread choice of `count` of `0..total` (all of them when `count ≥ total`).
pub fn spread(total: usize, count: usize) -> Vec<usize> {
    if count >= total {
        return (0..total).collect();
    }
    (0..count).map(|k| k * total / count).collect()
}

/// The training examples of `category` from frame directories: reads the annotations of every frame,
/// picks the instances and negative frames ([`ExampleLimits`]), preprocesses the frames they come from
/// (in parallel) and builds the examples. `settings.sizes` must already be set.
pub fn collect_examples(
    frames: &[std::path::PathBuf],
    category: &str,
    limits: ExampleLimits,
    settings: &TrainingSettings,
) -> Result<Vec<TrainingExample>> {
    let annotations = read_all_annotations(frames)?;
    let mut positives = Vec::new(); // (frame, instance)
    let mut negatives = Vec::new();
    for (f, objects) in annotations.iter().enumerate() {
        let instances = instances_of(objects, category);
        if instances.is_empty() {
            negatives.push(f);
        }
        positives.extend((0..instances.len()).map(|k| (f, k)));
    }
    let positives: Vec<(usize, usize)> =
        spread(positives.len(), limits.positives).into_iter().map(|n| positives[n]).collect();
    let negatives: Vec<usize> = spread(negatives.len(), limits.negatives).into_iter().map(|n| negatives[n]).collect();
    let mut needed: Vec<usize> = positives.iter().map(|p| p.0).chain(negatives.iter().copied()).collect();
    needed.sort_unstable();
    needed.dedup();
    let preprocessed: Vec<(usize, Preprocessed)> = needed
        .par_iter()
        .map(|&f| {
            let frame = crate::frame::Frame::read(&frames[f], crate::frame::DepthSource::Raw)?;
            Ok((f, Preprocessed::from_frame(&frame)?))
        })
        .collect::<Result<_>>()?;
    // Every frame of `jobs` is in `needed`, so the search always succeeds.
    let pre_of = |f: usize| &preprocessed[preprocessed.binary_search_by_key(&f, |p| p.0).unwrap_or(0)].1;
    let name_of = |f: usize| frames[f].file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let mut jobs: Vec<(String, usize, Option<Cuboid>, Vec<Cuboid>)> = Vec::new();
    for &(f, k) in &positives {
        let instances = instances_of(&annotations[f], category);
        let others: Vec<Cuboid> = instances.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, c)| *c).collect();
        jobs.push((format!("{} #{k}", name_of(f)), f, Some(instances[k]), others));
    }
    for &f in &negatives {
        jobs.push((format!("{} (no {category})", name_of(f)), f, None, Vec::new()));
    }
    Ok(jobs
        .into_par_iter()
        .map(|(name, f, truth, others)| TrainingExample::new(name, pre_of(f), truth, &others, settings))
        .collect())
}

/// The annotated objects of every frame (annotations only; images are not read).
pub fn read_all_annotations(frames: &[std::path::PathBuf]) -> Result<Vec<Vec<crate::frame::Object>>> {
    frames.par_iter().map(|dir| Ok(crate::frame::read_annotations(dir)?.0)).collect()
}
