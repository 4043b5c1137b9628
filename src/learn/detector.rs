//! The detector's half of the structural SVM (paper §3.4): training examples made from annotated frames
//! and loss-augmented inference over the sliding window as a [`SeparationOracle`], and the training loop
//! that alternates cheap passes over cached candidates with full passes over the window
//! ([`train_detector`]).
//!
//! # Examples (choices where the paper is terse)
//! * One example per annotated instance of the category; in a frame with several instances, each copy has
//!   the points inside the **other** instances' cuboids removed (§3.4, after Vedaldi & Zisserman;
//!   [`OtherInstances::Removed`]), or, with [`OtherInstances::Ignored`], keeps them and leaves the
//!   hypotheses that would detect another instance (IoU ≥ [`IGNORED_INSTANCE_IOU`]) out of its output
//!   space: the model then sees, in training, chairs next to chairs as detection does, and boxes straddling
//!   two instances are negatives.
//! * Frames without the category give "no object" examples (y = 0): their ground truth has φ = 0, and
//!   every cuboid answer costs loss 1, so they teach the detector what is not the category. The paper
//!   trains on positive images only; negatives from many frames are what make scores comparable across
//!   frames (a box in a frame without the category must score below 0), which AP over a test set needs.
//! * The output space of an example is the sliding window of the category's sizes on the example's frame
//!   (centre step [`TrainingSettings::step`], coarser than detection's to keep training within its
//!   budget), plus "no object" (φ = 0, loss 1 when the example has an instance, 0 otherwise), plus the
//!   positive's target output (loss 0), so the margin is enforced on it exactly.
//! * The target output ([`PositiveTarget`], default [`PositiveTarget::BestWindow`]) is the window's
//!   hypothesis nearest the annotation, with every other hypothesis's loss taken as its regret against
//!   it: the detector is taught to rank the boxes it can actually output, not the exact annotated cuboid
//!   it never sees at test time. [`PositiveTarget::Exact`] (the paper's choice) uses the annotated cuboid
//!   at the nearest of the window's 16 yaws (the feature engine bins points per yaw).
//! * Loss (eq. 5): `1 − IoU·(1 + cos Δθ)/2` ([`structured_loss`]). Hypotheses whose footprints cannot
//!   overlap the truth's have loss 1 without an IoU computation.
//!
//! # Latent support surfaces (paper §4.1)
//! With [`TrainingSettings::surfaces`], φ is `[φ_cuboid, φ_surface(h), e_h]` ([`crate::features::surface`]):
//! every answer (a window box, or the ground truth) maximises over its seven slices, the cache keeps each
//! candidate's slices, and the ground truths' slices are latent, imputed by CCCP
//! ([`train_latent_detector`]). "No object" has φ = 0 and a single latent value.
//!
//! # What is cached per example (memory against time)
//! An example keeps its preprocessed points (other instances removed, ~2 MB at 320×240) and, after every
//! full pass, its [`DetectorOracle::candidate_count`] candidates: their **feature vectors**, losses and
//! window indices. A cached pass is then only `candidates × dim` multiply-adds per example (≈ 1 ms),
//! independent of the frame. The per-yaw grids, the sliding window, its losses and the fast path's
//! lattices and tables do not depend on w either, but they take 30–60 MB per example at 320×240; for
//! hundreds of examples that does not fit in memory, so a full pass rebuilds them (≈ 10 % of its time;
//! the rest is scoring every hypothesis, which depends on w).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Mutex;

use glam::Vec3;
use rayon::prelude::*;

use super::latent::{impute, CccpRound, LatentOracle};
use super::one_slack::{OneSlack, PassSummary};
use super::{Constraint, CuttingPlane, SeparationOracle, Solution, SsvmOptions};
use crate::category::SurfaceCategories;
use crate::error::{Error, Result};
use crate::features::cpu;
use crate::features::fast::{FastEngine, FastOptions};
use crate::features::feature_layout::{NORMALS, PER_VOXEL};
use crate::features::hypotheses::{
    self, frame_wall_direction, nearest_yaw_index, yaws_under, HypothesisSet, Support, SupportSurface, WindowOptions,
    YawAnchor,
};
use crate::features::preprocess::NormalSearch;
use crate::features::scene::LatticePhase;
use crate::features::surface::{
    annotated_surfaces_by_category, best_slice, SurfaceEngine, SurfaceWeights, SLICES, SLICE_DIM, SLICE_VOXELS,
};
use crate::features::{FeatureLayout, FeatureScene, Hypothesis, Preprocessed};
use crate::geometry::{iou_3d, structured_loss, Cuboid};

/// Offset, within a voxel's features, of the normal histogram's up bin (bin 0 of
/// [`crate::features::preprocess::normal_bin`]).
const PER_VOXEL_NORMALS_UP: usize = NORMALS;

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
    pub layout: FeatureLayout,
    /// The 45 (or fewer) hypothesis sizes.
    pub sizes: Vec<Vec3>,
    /// Centre step of the training sliding window (metres).
    pub step: f32,
    pub min_points: u32,
    pub engine: FeatureEngine,
    /// What a positive example's ground-truth output is (see [`PositiveTarget`]).
    pub target: PositiveTarget,
    /// Where the window's 16 yaws start (see [`crate::features::hypotheses`]).
    pub yaw_anchor: YawAnchor,
    /// Where each yaw's lattice of centres starts (see [`crate::features::scene`]).
    pub lattice: LatticePhase,
    /// Where the window's boxes stand: on the floor (the sliding window) or on the example's
    /// [`TrainingExample::surfaces`] ([`crate::features::hypotheses::surface_window`]).
    pub support: Support,
    /// Latent support surfaces (paper §4.1, [`crate::features::surface`]): the joint feature vector is
    /// `[φ_cuboid, φ_surface(h), e_h]` ([`TrainingSettings::dim`]) and every answer maximises over the
    /// seven slices `h`; the fast path only.
    pub surfaces: bool,
}

impl TrainingSettings {
    /// Length of the joint feature vector: the layout's, plus [`SLICE_DIM`] + [`SLICES`] with surfaces.
    pub fn dim(&self) -> usize {
        self.layout.dim() + if self.surfaces { SURFACE_DIM } else { 0 }
    }
}

/// Length of the surface part of a latent model's weights: `w_slice` and the seven height biases `u_h`.
pub const SURFACE_DIM: usize = SLICE_DIM + SLICES;

/// The output a positive example's margin is enforced for.
///
/// The annotated cuboid itself is not in the detector's output space: the window's centres lie on a
/// grid, its sizes are a few quantiles and its yaws 16 angles. Features of the exact cuboid (voxels
/// aligned with the object's faces) are then a pattern the detector never meets at test time, where
/// every hypothesis is off by up to half a step; a model taught to put the exact cuboid first learns
/// to rank a precisely aligned pattern above everything, and ranks the misaligned test-time windows
/// near the object no better than clutter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PositiveTarget {
    /// The annotated cuboid at the nearest hypothesis yaw (the paper's choice).
    Exact,
    /// The window's hypothesis with the smallest loss to the annotation (the best output the detector
    /// can give; the exact cuboid when no hypothesis overlaps it). Losses are then measured as regret
    /// against it, `max(0, Δ(h) − Δ(h*))`, so that it has loss 0 and no hypothesis must beat it by more
    /// than it is better. The default.
    BestWindow,
}

/// What a positive example does with the **other** instances of its category in the same frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OtherInstances {
    /// Their points are removed (the paper's choice, after Vedaldi & Zisserman): the example's frame
    /// holds one instance. The default.
    Removed,
    /// Their points stay; the window's hypotheses with IoU ≥ [`IGNORED_INSTANCE_IOU`] to one of them (a
    /// correct detection of that instance) are not among the example's answers, neither target nor
    /// negative.
    Ignored,
}

/// IoU with another instance at and above which a hypothesis is left out of a positive example's answers
/// under [`OtherInstances::Ignored`]: the evaluation's threshold of a correct detection (0.25), so that
/// no box `eval` would count as a true positive is taught as a negative.
pub const IGNORED_INSTANCE_IOU: f32 = 0.25;

/// One training example: a frame's preprocessed points (other instances removed, or ignored) and its
/// ground truth.
#[derive(Clone, Debug)]
pub struct TrainingExample {
    /// Frame name and instance, for messages.
    pub name: String,
    pub truth: Option<Cuboid>,
    /// The frame's points, without those inside the other instances of the category under
    /// [`OtherInstances::Removed`].
    pub pre: Preprocessed,
    /// The other instances whose detections are left out of the answers ([`OtherInstances::Ignored`];
    /// empty otherwise).
    pub ignored: Vec<Cuboid>,
    /// The whole frame's wall direction (as detection sees the frame, before the other instances' points
    /// are removed), which places the window's yaws under [`YawAnchor::Walls`].
    pub wall_direction: Option<f32>,
    /// The frame's support surfaces, searched by a [`Support::Surfaces`] window: in training, those of the
    /// annotated objects of [`crate::category::SURFACE_CATEGORIES`], measured from the whole frame's points
    /// ([`annotated_surfaces_by_category`]); empty unless set with [`TrainingExample::on_surfaces`].
    pub surfaces: Vec<SupportSurface>,
}

/// The parts of an example that do not depend on w, rebuilt by every full pass (see the module doc).
pub struct ExampleWindow {
    pub scene: FeatureScene,
    pub hypotheses: HypothesisSet,
    /// The loss of every hypothesis: `Δ(truth, h)`, or its regret against [`ExampleWindow::target`].
    pub losses: Vec<f32>,
    /// With [`PositiveTarget::BestWindow`], the index of the hypothesis that is the positive's output.
    pub target: Option<usize>,
}

impl TrainingExample {
    /// Builds the example: removes the points inside `others` ([`OtherInstances::Removed`]).
    pub fn new(name: String, pre: &Preprocessed, truth: Option<Cuboid>, others: &[Cuboid]) -> TrainingExample {
        TrainingExample::with_others(name, pre, truth, others, OtherInstances::Removed)
    }

    /// Builds the example with `others`, the frame's other instances of the category, treated as `mode`
    /// says: their points removed, or kept with the hypotheses that detect one of them left out of the
    /// window.
    pub fn with_others(
        name: String,
        pre: &Preprocessed,
        truth: Option<Cuboid>,
        others: &[Cuboid],
        mode: OtherInstances,
    ) -> TrainingExample {
        let wall_direction = frame_wall_direction(pre);
        let (pre, ignored) = match mode {
            OtherInstances::Removed => (without_points_in(pre, others), Vec::new()),
            OtherInstances::Ignored => (pre.clone(), others.to_vec()),
        };
        TrainingExample { name, truth, pre, ignored, wall_direction, surfaces: Vec::new() }
    }

    /// The example with `surfaces` as its frame's support surfaces.
    pub fn on_surfaces(mut self, surfaces: Vec<SupportSurface>) -> TrainingExample {
        self.surfaces = surfaces;
        self
    }

    /// The window's 16 yaws under `anchor`.
    pub fn yaws(&self, anchor: YawAnchor) -> Vec<f32> {
        yaws_under(anchor, self.wall_direction)
    }

    /// The example's yaw grids, sliding window and losses under `settings`.
    pub fn window(&self, settings: &TrainingSettings) -> ExampleWindow {
        let scene = FeatureScene::with_lattice(
            self.pre.clone(),
            &self.yaws(settings.yaw_anchor),
            settings.step,
            settings.lattice,
        );
        let options = WindowOptions { sizes: settings.sizes.clone(), min_points: settings.min_points };
        let mut hypotheses = hypotheses::window(settings.support, &scene, &options, &self.surfaces);
        if !self.ignored.is_empty() {
            let detects_another = |h: &Hypothesis| {
                let cuboid = h.cuboid(&scene);
                self.ignored.iter().any(|other| iou_3d(other, &cuboid) >= IGNORED_INSTANCE_IOU)
            };
            // rayon's collect keeps the window's order.
            hypotheses.hypotheses =
                std::mem::take(&mut hypotheses.hypotheses).into_par_iter().filter(|h| !detects_another(h)).collect();
        }
        let truth = self.truth;
        let mut losses: Vec<f32> =
            hypotheses.hypotheses.par_iter().map(|h| hypothesis_loss(truth.as_ref(), &h.cuboid(&scene))).collect();
        let target = match (truth, settings.target) {
            (Some(_), PositiveTarget::BestWindow) => best_window_target(&losses),
            _ => None,
        };
        if let Some(t) = target {
            let offset = losses[t];
            losses.iter_mut().for_each(|l| *l = (*l - offset).max(0.0));
        }
        ExampleWindow { scene, hypotheses, losses, target }
    }
}

impl ExampleWindow {
    /// The ground truth `truth` as a hypothesis of the nearest yaw.
    pub fn truth_hypothesis(&self, truth: &Cuboid) -> Hypothesis {
        Hypothesis::from_cuboid(&self.scene, nearest_yaw_index(&self.scene.yaw_angles(), truth.yaw), truth)
    }
}

/// The index of the smallest loss below 1 (the first of equals), if any: the hypothesis nearest the truth.
pub fn best_window_target(losses: &[f32]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (n, &loss) in losses.iter().enumerate() {
        if loss < 1.0 && best.is_none_or(|b| loss < losses[b]) {
            best = Some(n);
        }
    }
    best
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

/// Features (row-major) and fused scores of hypotheses with the settings' engine on one scene.
enum Scorer<'a> {
    Exact(&'a FeatureScene, FeatureLayout),
    Fast(FastEngine<'a>),
}

/// The cuboid scorer and, with surfaces, the slices' engine of one scene.
struct ExampleScorer<'a> {
    cuboid: Scorer<'a>,
    surface: Option<SurfaceEngine<'a>>,
}

impl<'a> ExampleScorer<'a> {
    fn new(settings: &TrainingSettings, scene: &'a FeatureScene) -> ExampleScorer<'a> {
        let surface = match (settings.surfaces, settings.engine) {
            (true, FeatureEngine::Fast(options)) => Some(SurfaceEngine::new(scene, settings.layout.groups, options)),
            _ => None,
        };
        ExampleScorer { cuboid: Scorer::new(settings, scene), surface }
    }

    /// Cuboid features (row-major, `layout.dim()` per hypothesis) and, with surfaces, the slices (row-major,
    /// `SLICES × SLICE_DIM` per hypothesis; empty without).
    fn features(&self, hypotheses: &[Hypothesis]) -> (Vec<f32>, Vec<f32>) {
        let slices = self.surface.as_ref().map_or_else(Vec::new, |s| s.slices(hypotheses));
        (self.cuboid.features(hypotheses), slices)
    }

    /// `max_h w·φ(hypothesis, h)` (or `w·φ` without surfaces) of every hypothesis.
    fn scores(&self, hypotheses: &[Hypothesis], w: &[f32], cuboid_dim: usize) -> Vec<f32> {
        let mut scores = self.cuboid.scores(hypotheses, &w[..cuboid_dim]);
        if let Some(surface) = &self.surface {
            let weights = surface_weights(&w[cuboid_dim..]);
            for (score, slices) in scores.iter_mut().zip(surface.slice_scores(hypotheses, &weights)) {
                *score += best_slice(&slices).1;
            }
        }
        scores
    }
}

/// The surface part of a joint weight vector (`w_slice`, then `u_h`).
pub fn surface_weights(surface_part: &[f32]) -> SurfaceWeights {
    SurfaceWeights {
        slice: surface_part[..SLICE_DIM].to_vec(),
        indicator: std::array::from_fn(|h| surface_part[SLICE_DIM + h]),
    }
}

/// `w_slice·φ_surface(h) + u_h` of each slice, from the `SLICES × SLICE_DIM` slices of one hypothesis.
fn slice_values(slices: &[f32], surface_part: &[f32]) -> [f32; SLICES] {
    std::array::from_fn(|h| {
        dot(&slices[h * SLICE_DIM..(h + 1) * SLICE_DIM], &surface_part[..SLICE_DIM]) + surface_part[SLICE_DIM + h]
    })
}

/// The joint feature vector `[φ_cuboid, φ_surface(h), e_h]`.
fn joint_features(cuboid: &[f32], slices: &[f32], h: usize) -> Vec<f32> {
    let mut features = Vec::with_capacity(cuboid.len() + SURFACE_DIM);
    features.extend_from_slice(cuboid);
    features.extend_from_slice(&slices[h * SLICE_DIM..(h + 1) * SLICE_DIM]);
    features.extend((0..SLICES).map(|k| if k == h { 1.0 } else { 0.0 }));
    features
}

impl<'a> Scorer<'a> {
    fn new(settings: &TrainingSettings, scene: &'a FeatureScene) -> Scorer<'a> {
        match settings.engine {
            FeatureEngine::Exact => Scorer::Exact(scene, settings.layout),
            FeatureEngine::Fast(options) => Scorer::Fast(FastEngine::new(scene, &settings.layout, options)),
        }
    }

    fn features(&self, hypotheses: &[Hypothesis]) -> Vec<f32> {
        match self {
            Scorer::Exact(scene, layout) => cpu::features(scene, layout, hypotheses).0,
            Scorer::Fast(engine) => engine.features(hypotheses),
        }
    }

    fn scores(&self, hypotheses: &[Hypothesis], w: &[f32]) -> Vec<f32> {
        let weights = vec![w.to_vec()];
        match self {
            Scorer::Exact(scene, layout) => cpu::scores(scene, layout, hypotheses, &weights).0,
            Scorer::Fast(engine) => engine.scores(hypotheses, &weights),
        }
    }
}

/// The answer of loss-augmented inference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Answer {
    /// Hypothesis index into the example's sliding window ([`TrainingExample::window`]).
    Hypothesis(usize),
    NoObject,
    GroundTruth,
}

/// An example's cached candidates (see the module doc): window indices, losses and feature rows.
#[derive(Clone, Debug, Default)]
struct Candidates {
    indices: Vec<u32>,
    losses: Vec<f32>,
    /// `indices.len() × layout.dim()`, row-major: the cuboid features.
    features: Vec<f32>,
    /// With surfaces, `indices.len() × SLICES × SLICE_DIM`, row-major: each candidate's seven slices.
    slices: Vec<f32>,
}

/// How many of the boxes nearest a positive's truth a full pass caches besides its `candidate_count`
/// best-valued hypotheses (a quarter of the count).
pub fn nearest_truth_count(candidate_count: usize) -> usize {
    candidate_count / 4
}

/// The most feature rows one example caches: its candidates plus, for a positive, the boxes nearest its
/// truth (for sizing the cache before training).
pub fn cached_rows_per_example(candidate_count: usize) -> usize {
    candidate_count + nearest_truth_count(candidate_count)
}

/// Deterministic pseudo-random tie-break key of a hypothesis index (a 32-bit integer hash): among
/// candidates of equal value (all loss-1 hypotheses at w = 0) the cache then holds a spread-out random
/// sample of the window instead of its first hypotheses.
fn tie_key(n: u32) -> u32 {
    let mut x = n.wrapping_mul(0x9E37_79B9) ^ 0x85EB_CA6B;
    x ^= x >> 16;
    x = x.wrapping_mul(0x7FEB_352D);
    x ^= x >> 15;
    x
}

/// The first word of [`SeparationOracle::run_state`]'s form with the candidate cache (ASCII "COGCACHE"),
/// which tells it from the older forms of two numbers or none.
const CANDIDATE_STATE_TAG: u64 = u64::from_be_bytes(*b"COGCACHE");

/// Loss-augmented inference over training examples.
///
/// # Candidate cache
/// A full pass scores every hypothesis of every example (most of training's time) and keeps, per
/// example, the [`DetectorOracle::candidate_count`] hypotheses of largest `Δ + w·φ` (ties broken by a
/// fixed hash of the index) — plus, for a positive example, the quarter of that count with the smallest
/// loss (the boxes nearest the truth, which teach localisation) — with their feature vectors. A cached
/// pass maximises over those candidates only (plus the ground truth and "no object"): dot products, no
/// feature work. The first batch call is always a full pass; later ones are cached unless
/// [`DetectorOracle::force_full_pass`] was called or a periodic full pass is due
/// ([`DetectorOracle::full_every`]); at most [`DetectorOracle::max_full_passes`] full passes run.
/// [`train_detector`] accepts convergence only after a full pass found no violation (or says so).
pub struct DetectorOracle {
    pub settings: TrainingSettings,
    pub examples: Vec<TrainingExample>,
    /// The cuboid part of φ of each example's ground truth (zeros for "no object").
    truth_features: Vec<Vec<f32>>,
    /// With surfaces, the seven slices of each positive's ground truth (`SLICES × SLICE_DIM`; empty for
    /// "no object").
    truth_slices: Vec<Vec<f32>>,
    /// With surfaces, each ground truth's imputed slice ([`DetectorOracle::set_latents`]).
    latents: Vec<AtomicUsize>,
    /// Hypotheses kept per example by a full pass.
    pub candidate_count: usize,
    /// A periodic full pass every this many batch calls (0: only when forced).
    pub full_every: usize,
    /// Most full passes (the first included).
    pub max_full_passes: usize,
    /// With latent surfaces, the current CCCP round's cap on the full passes counted since the run began
    /// ([`DetectorOracle::allow_more_full_passes`]); 0 until a round sets it: the cap is then
    /// `max_full_passes`.
    round_full_pass_cap: AtomicUsize,
    cached: AtomicBool,
    force_full: AtomicBool,
    /// Set by [`SeparationOracle::restore_run_state`] from a checkpoint without the candidate cache (one
    /// written before 2026-12-08): a resumed run's first batch call is then a full pass, whatever the
    /// budget (it counts as one).
    refill: AtomicBool,
    batch_calls: AtomicUsize,
    full_passes: AtomicUsize,
    /// Hypotheses scored by full passes, and their wall time in microseconds.
    scored_hypotheses: AtomicU64,
    full_pass_micros: AtomicU64,
    /// One lock per example, so that rayon's workers never wait on each other's examples.
    candidates: Vec<Mutex<Candidates>>,
    /// FNV-1a of `settings` (their `Debug` text), part of every [`SeparationOracle::example_fingerprint`]:
    /// a checkpoint resumed under another output space — another window (`--min-points`, `--support`),
    /// other features (`--subdivisions`) — is refused even where the ground truths' features come out the
    /// same (they did for those three, and such a resume mixed two problems' constraints).
    settings_fingerprint: u64,
}

impl DetectorOracle {
    pub fn new(settings: TrainingSettings, examples: Vec<TrainingExample>) -> Result<DetectorOracle> {
        let settings_fingerprint =
            super::checkpoint::fnv1a(super::checkpoint::FNV_OFFSET, format!("{settings:?}").as_bytes());
        if examples.is_empty() {
            return Err(Error::Input("no training examples".into()));
        }
        if settings.surfaces && settings.engine == FeatureEngine::Exact {
            return Err(Error::Input("latent support surfaces need the fast feature path (--features fast)".into()));
        }
        let dim = settings.layout.dim();
        let truths: Vec<(Vec<f32>, Vec<f32>)> = examples
            .par_iter()
            .map(|ex| match &ex.truth {
                Some(truth) if settings.target == PositiveTarget::BestWindow => {
                    let window = ex.window(&settings);
                    let hypothesis = match window.target {
                        Some(t) => window.hypotheses.hypotheses[t],
                        None => window.truth_hypothesis(truth),
                    };
                    ExampleScorer::new(&settings, &window.scene).features(&[hypothesis])
                }
                Some(truth) => {
                    let yaws = ex.yaws(settings.yaw_anchor);
                    let scene = FeatureScene::with_lattice(ex.pre.clone(), &yaws, settings.step, settings.lattice);
                    let hypothesis = Hypothesis::from_cuboid(&scene, nearest_yaw_index(&yaws, truth.yaw), truth);
                    ExampleScorer::new(&settings, &scene).features(&[hypothesis])
                }
                None => (vec![0.0; dim], Vec::new()),
            })
            .collect();
        let (truth_features, truth_slices) = truths.into_iter().unzip();
        let candidates = (0..examples.len()).map(|_| Mutex::new(Candidates::default())).collect();
        let latents = (0..examples.len()).map(|_| AtomicUsize::new(SLICES / 2)).collect();
        Ok(DetectorOracle {
            settings,
            examples,
            truth_features,
            truth_slices,
            latents,
            candidate_count: 100,
            full_every: 0,
            max_full_passes: 4,
            round_full_pass_cap: AtomicUsize::new(0),
            cached: AtomicBool::new(false),
            force_full: AtomicBool::new(false),
            refill: AtomicBool::new(false),
            batch_calls: AtomicUsize::new(0),
            full_passes: AtomicUsize::new(0),
            scored_hypotheses: AtomicU64::new(0),
            full_pass_micros: AtomicU64::new(0),
            candidates,
            settings_fingerprint,
        })
    }

    /// Sets the ground truths' surface slices (one per example; ignored for "no object" examples), which
    /// fix [`SeparationOracle::ground_truth_features`] for the next S-SVM solve (a CCCP round).
    pub fn set_latents(&self, latents: &[usize]) -> Result<()> {
        if latents.len() != self.examples.len() || latents.iter().any(|&h| h >= SLICES) {
            return Err(Error::Input(format!(
                "{} latent slices for {} examples (each below {SLICES})",
                latents.len(),
                self.examples.len()
            )));
        }
        for (slot, &h) in self.latents.iter().zip(latents) {
            slot.store(h, Ordering::SeqCst);
        }
        Ok(())
    }

    /// Each ground truth's slice with the most upward-facing points (the sum over its 25 voxels of the
    /// normal histogram's up bin, [`crate::features::preprocess::normal_bin`] 0) among slices 1–6: the
    /// geometric evidence of a horizontal surface, for initialising CCCP. Slice 0 is left out because its
    /// upward points are mostly the floor the object stands on (visible under tables and around every
    /// box that is a little too large), not a surface of the object. Ties go to the lowest slice; a
    /// ground truth without upward points gets the centre slice, a "no object" example its only latent, 0.
    pub fn upward_slices(&self) -> Vec<usize> {
        let up = PER_VOXEL_NORMALS_UP;
        self.truth_slices
            .iter()
            .map(|slices| {
                if slices.is_empty() {
                    return 0;
                }
                let upward = |h: usize| -> f32 {
                    (0..SLICE_VOXELS)
                        .map(|v| slices.get(h * SLICE_DIM + v * PER_VOXEL + up).copied().unwrap_or(0.0))
                        .sum()
                };
                // Slice 0 never wins: it scores below any upward point elsewhere.
                let (h, most) = best_slice(&std::array::from_fn(|h| if h == 0 { -1.0 } else { upward(h) }));
                if most > 0.0 {
                    h
                } else {
                    SLICES / 2
                }
            })
            .collect()
    }

    /// The ground truths' current surface slices.
    pub fn latents(&self) -> Vec<usize> {
        self.latents.iter().map(|h| h.load(Ordering::SeqCst)).collect()
    }

    /// Allows `extra` more full passes from now on (each CCCP round after the first gets its own budget; the
    /// cached candidates of the previous round stay). A resumed round gets its cap back from the
    /// checkpoint ([`SeparationOracle::restore_run_state`]).
    pub fn allow_more_full_passes(&self, extra: usize) {
        self.round_full_pass_cap.store(self.full_passes() + extra, Ordering::SeqCst);
    }

    /// The most full passes, counted since the run began, that may have run when the next one is
    /// considered (at least 1).
    fn full_pass_cap(&self) -> usize {
        match self.round_full_pass_cap.load(Ordering::SeqCst) {
            0 => self.max_full_passes.max(1),
            cap => cap,
        }
    }

    /// Whether the latest batch call was a full pass.
    pub fn last_pass_was_full(&self) -> bool {
        !self.cached.load(Ordering::SeqCst)
    }

    /// Makes the next batch call a full pass (if [`DetectorOracle::max_full_passes`] allows).
    pub fn force_full_pass(&self) {
        self.force_full.store(true, Ordering::SeqCst);
    }

    /// Full passes run so far.
    pub fn full_passes(&self) -> usize {
        self.full_passes.load(Ordering::SeqCst)
    }

    /// Hypotheses scored by full passes, and the passes' wall time in seconds.
    pub fn inference_throughput(&self) -> (u64, f64) {
        (self.scored_hypotheses.load(Ordering::SeqCst), self.full_pass_micros.load(Ordering::SeqCst) as f64 * 1e-6)
    }

    fn lock_candidates(&self, example: usize) -> Result<std::sync::MutexGuard<'_, Candidates>> {
        self.candidates[example].lock().map_err(|_| Error::Input("candidate cache poisoned".into()))
    }

    /// Whether example `example` needs a full pass now: outside a cached pass, or without candidates yet.
    fn needs_full_pass(&self, example: usize) -> Result<bool> {
        Ok(!self.cached.load(Ordering::SeqCst) || self.lock_candidates(example)?.indices.is_empty())
    }

    /// `argmax Δ + w·φ` over the example's answers (the whole window on a full pass, the cached candidates
    /// otherwise; with surfaces jointly over each answer's seven slices), with its loss and features.
    fn argmax(&self, example: usize, w: &[f32], full: bool) -> Result<(Answer, f32, Vec<f32>)> {
        let ex = &self.examples[example];
        let dim = self.settings.layout.dim();
        if full {
            self.refresh_candidates(example, w)?;
        }
        let cache = self.lock_candidates(example)?;
        let candidates = &*cache;
        let surfaces = self.settings.surfaces;
        let slice_len = SLICES * SLICE_DIM;
        let no_object_loss = if ex.truth.is_some() { 1.0 } else { 0.0 };
        // (answer, loss, value, candidate row, slice)
        let mut best = (Answer::NoObject, no_object_loss, no_object_loss, None, 0);
        if ex.truth.is_some() {
            let (truth_score, h) = self.truth_score(example, w);
            if truth_score > best.2 {
                best = (Answer::GroundTruth, 0.0, truth_score, None, h);
            }
        }
        for (row, (&n, &loss)) in candidates.indices.iter().zip(&candidates.losses).enumerate() {
            let mut value = loss + dot(&candidates.features[row * dim..(row + 1) * dim], &w[..dim]);
            let mut h = 0;
            if surfaces {
                let slices = &candidates.slices[row * slice_len..(row + 1) * slice_len];
                let (best_h, slice_value) = best_slice(&slice_values(slices, &w[dim..]));
                value += slice_value;
                h = best_h;
            }
            if value > best.2 {
                best = (Answer::Hypothesis(n as usize), loss, value, Some(row), h);
            }
        }
        let features = match (best.0, best.3) {
            (Answer::GroundTruth, _) => self.truth_joint_features(example, best.4),
            (Answer::Hypothesis(_), Some(row)) if surfaces => joint_features(
                &candidates.features[row * dim..(row + 1) * dim],
                &candidates.slices[row * slice_len..(row + 1) * slice_len],
                best.4,
            ),
            (Answer::Hypothesis(_), Some(row)) => candidates.features[row * dim..(row + 1) * dim].to_vec(),
            _ => vec![0.0; self.settings.dim()],
        };
        Ok((best.0, best.1, features))
    }

    /// The ground truth's best score over its latent slices at `w` and that slice (0 without surfaces).
    fn truth_score(&self, example: usize, w: &[f32]) -> (f32, usize) {
        let dim = self.settings.layout.dim();
        let cuboid = dot(&self.truth_features[example], &w[..dim]);
        if !self.settings.surfaces || self.truth_slices[example].is_empty() {
            return (cuboid, 0);
        }
        let (h, value) = best_slice(&slice_values(&self.truth_slices[example], &w[dim..]));
        (cuboid + value, h)
    }

    /// `φ(x_i, y_i, h)`: the ground truth's features with slice `h` (zeros for "no object").
    fn truth_joint_features(&self, example: usize, h: usize) -> Vec<f32> {
        if !self.settings.surfaces {
            return self.truth_features[example].clone();
        }
        if self.truth_slices[example].is_empty() {
            return vec![0.0; self.settings.dim()];
        }
        joint_features(&self.truth_features[example], &self.truth_slices[example], h)
    }

    /// A full pass over one example: scores its whole window at `w` and replaces its cached candidates.
    fn refresh_candidates(&self, example: usize, w: &[f32]) -> Result<()> {
        let ex = &self.examples[example];
        let window = ex.window(&self.settings);
        let scorer = ExampleScorer::new(&self.settings, &window.scene);
        let hypotheses = &window.hypotheses.hypotheses;
        // At w = 0 (the first pass of a fresh run) every score is 0: no need to compute them.
        let scores = if w.iter().all(|&v| v == 0.0) {
            vec![0.0; hypotheses.len()]
        } else {
            self.scored_hypotheses.fetch_add(hypotheses.len() as u64, Ordering::SeqCst);
            scorer.scores(hypotheses, w, self.settings.layout.dim())
        };
        let value = |n: u32| window.losses[n as usize] + scores[n as usize];
        let mut order: Vec<u32> = (0..hypotheses.len() as u32).collect();
        let keep = self.candidate_count.max(1).min(order.len());
        let by_value = |a: &u32, b: &u32| value(*b).total_cmp(&value(*a)).then(tie_key(*a).cmp(&tie_key(*b)));
        if keep < order.len() {
            order.select_nth_unstable_by(keep, by_value);
            order.truncate(keep);
        }
        if ex.truth.is_some() {
            // The boxes nearest the truth (smallest loss), a quarter of the count, if not already in.
            let mut nearest: Vec<u32> =
                (0..hypotheses.len() as u32).filter(|&n| window.losses[n as usize] < 1.0).collect();
            let extra = nearest_truth_count(self.candidate_count).min(nearest.len());
            // None for a count under 4 (until 2026-12-08 a quarter of 0 kept them all: every box with a
            // loss under 1, nearly the whole window under the regret target — gigabytes of features).
            if extra < nearest.len() {
                let by_loss =
                    |a: &u32, b: &u32| window.losses[*a as usize].total_cmp(&window.losses[*b as usize]).then(a.cmp(b));
                nearest.select_nth_unstable_by(extra, by_loss);
                nearest.truncate(extra);
            }
            order.extend(nearest);
        }
        order.sort_unstable();
        order.dedup();
        self.store_candidates(example, &window, &scorer, order)
    }

    /// Caches the window's hypotheses `indices` (ascending) as example `example`'s candidates, with their
    /// losses and features.
    fn store_candidates(
        &self,
        example: usize,
        window: &ExampleWindow,
        scorer: &ExampleScorer,
        indices: Vec<u32>,
    ) -> Result<()> {
        let chosen: Vec<Hypothesis> = indices.iter().map(|&n| window.hypotheses.hypotheses[n as usize]).collect();
        let (features, slices) = scorer.features(&chosen);
        let losses = indices.iter().map(|&n| window.losses[n as usize]).collect();
        *self.lock_candidates(example)? = Candidates { indices, losses, features, slices };
        Ok(())
    }

    /// Rebuilds each example's candidate cache from the window indices a checkpoint stored: its window
    /// again (as a full pass builds it) and the features of those hypotheses, without scoring the window.
    /// The features come from the same code on the same hypotheses, so the cache is the interrupted run's
    /// bit for bit. Indices that are not ascending or not in the example's window are an error (the
    /// checkpoint's data hash already tied it to these examples and settings).
    fn restore_candidates(&self, cached: Vec<Vec<u32>>) -> Result<()> {
        let started = std::time::Instant::now();
        let restored = cached.iter().filter(|indices| !indices.is_empty()).count();
        cached.into_par_iter().enumerate().try_for_each(|(example, indices)| {
            if indices.is_empty() {
                *self.lock_candidates(example)? = Candidates::default();
                return Ok(());
            }
            let window = self.examples[example].window(&self.settings);
            let count = window.hypotheses.hypotheses.len();
            let ascending = indices.windows(2).all(|pair| pair[0] < pair[1]);
            if !ascending || indices.last().is_some_and(|&n| n as usize >= count) {
                return Err(Error::Input(format!(
                    "the checkpoint's candidates of example {example} ({}) are not {} hypotheses of its window \
                     of {count}",
                    self.examples[example].name,
                    indices.len()
                )));
            }
            let scorer = ExampleScorer::new(&self.settings, &window.scene);
            self.store_candidates(example, &window, &scorer, indices)
        })?;
        log::info!(
            "restored the candidate cache of {restored} examples from the checkpoint in {:.1} s",
            started.elapsed().as_secs_f64()
        );
        Ok(())
    }

    /// The latent objective `½‖w‖² + C·mean_i max(0, max(Δ + wᵀφ) − max_h wᵀφ(x_i, y_i, h))` with the
    /// inner max over each example's cached candidates (plus the ground truth and "no object"); no window
    /// is scored.
    pub fn cached_objective(&self, w: &[f64], c: f64) -> Result<f64> {
        let w32: Vec<f32> = w.iter().map(|&v| v as f32).collect();
        let slacks: Vec<f64> = (0..self.examples.len())
            .into_par_iter()
            .map(|i| {
                let (_, loss, features) = self.argmax(i, &w32, false)?;
                let value = loss as f64 + features.iter().zip(w).map(|(&f, &v)| f as f64 * v).sum::<f64>();
                let truth: f64 = if self.examples[i].truth.is_some() {
                    let (score, _) = self.truth_score(i, &w32);
                    score as f64
                } else {
                    0.0
                };
                Ok((value - truth).max(0.0))
            })
            .collect::<Result<_>>()?;
        let norm: f64 = w.iter().map(|v| v * v).sum();
        Ok(0.5 * norm + c * slacks.iter().sum::<f64>() / slacks.len().max(1) as f64)
    }

    /// `argmax Δ + w·φ` over the example's answers, with its loss: a full pass over the window when the
    /// example has no candidates yet or the oracle is not in a cached pass.
    pub fn loss_augmented_argmax(&self, example: usize, w: &[f32]) -> Result<(Answer, f32)> {
        let full = self.needs_full_pass(example)?;
        let (answer, loss, _) = self.argmax(example, w, full)?;
        Ok((answer, loss))
    }
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

impl SeparationOracle for DetectorOracle {
    fn num_examples(&self) -> usize {
        self.examples.len()
    }

    fn dim(&self) -> usize {
        self.settings.dim()
    }

    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        Ok(self.truth_joint_features(example, self.latents[example].load(Ordering::SeqCst)))
    }

    /// The example's frame name: which frames the negatives are (their features are all "no object").
    fn example_fingerprint(&self, example: usize) -> u64 {
        let name = super::checkpoint::fnv1a(super::checkpoint::FNV_OFFSET, self.examples[example].name.as_bytes());
        super::checkpoint::fnv1a(name, &self.settings_fingerprint.to_le_bytes())
    }

    /// Everything a resumed run needs to continue exactly where the interrupted one stood:
    /// `[CANDIDATE_STATE_TAG, batch calls, full passes, round cap, examples, then per example its cached
    /// candidates' count and window indices]`. The counters keep the periodic schedule (`--full-every`)
    /// and the one budget (`--max-full-passes`; with latent surfaces the round's cap,
    /// [`DetectorOracle::allow_more_full_passes`]); the indices let [`SeparationOracle::restore_run_state`]
    /// rebuild the candidate cache, so the resumed run's cached passes read the interrupted run's
    /// candidates (about 1 MB for a thousand examples of 125 candidates).
    fn run_state(&self) -> Vec<u64> {
        let mut state = vec![
            CANDIDATE_STATE_TAG,
            self.batch_calls.load(Ordering::SeqCst) as u64,
            self.full_passes() as u64,
            self.round_full_pass_cap.load(Ordering::SeqCst) as u64,
            self.examples.len() as u64,
        ];
        for example in 0..self.examples.len() {
            // A poisoned lock (a panicked worker) leaves that example's cache out: refilled on resume.
            let indices = self.lock_candidates(example).map(|c| c.indices.clone()).unwrap_or_default();
            state.push(indices.len() as u64);
            state.extend(indices.iter().map(|&n| u64::from(n)));
        }
        state
    }

    /// Takes back [`SeparationOracle::run_state`]: the counters, and the candidate cache rebuilt from its
    /// indices. The two older forms still read: `[batch calls, full passes]` (checkpoints of 2026-12-07,
    /// without surfaces) and `[]` (before, and with surfaces until 2026-12-08) restore what they hold and
    /// make the next batch call a full pass, which refills the cache.
    fn restore_run_state(&self, state: &[u64]) -> Result<()> {
        let refused = || {
            Error::Input(format!(
                "the checkpoint's oracle state ({} numbers, starting {:?}) is not this training's",
                state.len(),
                &state[..state.len().min(5)]
            ))
        };
        match *state {
            [] => self.refill.store(true, Ordering::SeqCst),
            [batch_calls, full_passes] if !self.settings.surfaces => {
                self.batch_calls.store(batch_calls as usize, Ordering::SeqCst);
                self.full_passes.store(full_passes as usize, Ordering::SeqCst);
                self.refill.store(true, Ordering::SeqCst);
            }
            [CANDIDATE_STATE_TAG, batch_calls, full_passes, round_cap, examples, ref rest @ ..]
                if examples == self.examples.len() as u64 =>
            {
                let mut cached = Vec::with_capacity(self.examples.len());
                let mut rest = rest;
                for _ in 0..examples {
                    let (&count, after) = rest.split_first().ok_or_else(refused)?;
                    let count = usize::try_from(count).ok().filter(|&c| c <= after.len()).ok_or_else(refused)?;
                    let indices =
                        after[..count].iter().map(|&n| u32::try_from(n)).collect::<std::result::Result<Vec<_>, _>>();
                    cached.push(indices.map_err(|_| refused())?);
                    rest = &after[count..];
                }
                if !rest.is_empty() {
                    return Err(refused());
                }
                self.batch_calls.store(batch_calls as usize, Ordering::SeqCst);
                self.full_passes.store(full_passes as usize, Ordering::SeqCst);
                self.round_full_pass_cap.store(round_cap as usize, Ordering::SeqCst);
                self.restore_candidates(cached)?;
            }
            _ => return Err(refused()),
        }
        Ok(())
    }

    fn most_violated_batch(&self, examples: &[usize], w: &[f64]) -> Result<Vec<Constraint>> {
        let call = self.batch_calls.fetch_add(1, Ordering::SeqCst);
        let forced = self.force_full.swap(false, Ordering::SeqCst);
        let periodic = self.full_every > 0 && call > 0 && call.is_multiple_of(self.full_every);
        // The first call of a run, or of a resumed one (its cache is empty): a full pass.
        let refill = self.refill.swap(false, Ordering::SeqCst);
        let first = refill || self.full_passes() == 0;
        let full = first || ((forced || periodic) && self.full_passes() < self.full_pass_cap());
        self.cached.store(!full, Ordering::SeqCst);
        let started = std::time::Instant::now();
        let w32: Vec<f32> = w.iter().map(|&v| v as f32).collect();
        let answers = examples
            .par_iter()
            .map(|&example| {
                let (_, loss, features) = self.argmax(example, &w32, full)?;
                Ok(Constraint { loss: loss as f64, features })
            })
            .collect::<Result<Vec<_>>>()?;
        if full {
            self.full_passes.fetch_add(1, Ordering::SeqCst);
            if w.iter().any(|&v| v != 0.0) {
                self.full_pass_micros.fetch_add(started.elapsed().as_micros() as u64, Ordering::SeqCst);
            }
            log::info!(
                "full pass {} over {} examples in {:.1} s",
                self.full_passes(),
                examples.len(),
                started.elapsed().as_secs_f64()
            );
        }
        Ok(answers)
    }

    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let w32: Vec<f32> = w.iter().map(|&v| v as f32).collect();
        let full = self.needs_full_pass(example)?;
        let (_, loss, features) = self.argmax(example, &w32, full)?;
        Ok(Constraint { loss: loss as f64, features })
    }
}

impl LatentOracle for DetectorOracle {
    fn num_examples(&self) -> usize {
        self.examples.len()
    }

    fn dim(&self) -> usize {
        self.settings.dim()
    }

    /// Seven slices for a positive with surfaces; one (no choice) otherwise.
    fn num_latents(&self, example: usize) -> usize {
        if self.settings.surfaces && !self.truth_slices[example].is_empty() {
            SLICES
        } else {
            1
        }
    }

    fn ground_truth_features(&self, example: usize, latent: usize) -> Result<Vec<f32>> {
        Ok(self.truth_joint_features(example, latent))
    }

    fn example_fingerprint(&self, example: usize) -> u64 {
        SeparationOracle::example_fingerprint(self, example)
    }

    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        SeparationOracle::most_violated(self, example, w)
    }
}

/// The outcome of [`train_detector`].
#[derive(Clone, Debug)]
pub struct DetectorSolution {
    pub solution: Solution,
    /// Converged, and the last pass that found no violation was a full pass over every window.
    pub verified: bool,
    pub full_passes: usize,
    /// Per-example figures of the last pass.
    pub last_pass: PassSummary,
    /// Hypotheses per second of the full passes' loss-augmented inference (windows rebuilt included).
    pub inference_hypotheses_per_second: f64,
}

/// Trains the detector with the 1-slack cutting-plane algorithm ([`super::one_slack`]) over the oracle's
/// examples: cached passes until no cached candidate is violated by more than ε, then a full pass to
/// check (and refresh the candidates), until a full pass finds nothing (verified convergence), the
/// iteration cap, or [`DetectorOracle::max_full_passes`].
pub fn train_detector(oracle: &DetectorOracle, solver: &mut CuttingPlane) -> Result<DetectorSolution> {
    let one_slack = OneSlack::new(oracle)?;
    let (solution, verified) = loop {
        let solution = solver.train(&one_slack)?;
        if !solution.converged {
            break (solution, false);
        }
        if oracle.last_pass_was_full() {
            break (solution, true);
        }
        if oracle.full_passes() >= oracle.full_pass_cap() {
            log::info!("converged on the cached candidates; the full-pass budget is spent, so not verified");
            break (solution, false);
        }
        log::info!("no violation among the cached candidates: checking the whole sliding window");
        oracle.force_full_pass();
    };
    let (scored, seconds) = oracle.inference_throughput();
    Ok(DetectorSolution {
        solution,
        verified,
        full_passes: oracle.full_passes(),
        last_pass: one_slack.last_pass(),
        inference_hypotheses_per_second: if seconds > 0.0 { scored as f64 / seconds } else { 0.0 },
    })
}

/// Settings of [`train_latent_detector`].
#[derive(Clone, Debug)]
pub struct LatentSettings {
    /// Most CCCP rounds (each a full [`train_detector`] run).
    pub max_rounds: usize,
    /// Stop when the objective over the cached candidates fell by less than this since the previous round.
    pub tolerance: f64,
    /// Full passes over the sliding windows allowed to each round after the first (the first round has the
    /// oracle's [`DetectorOracle::max_full_passes`]); every round keeps the previous round's candidates.
    pub full_passes_per_round: usize,
}

/// The outcome of [`train_latent_detector`].
#[derive(Clone, Debug)]
pub struct LatentDetectorSolution {
    /// The last round's solve.
    pub last: DetectorSolution,
    /// The ground truths' slices imputed from the final w.
    pub latents: Vec<usize>,
    pub rounds: Vec<CccpRound>,
    /// Stopped at a fixed point (no imputed slice changed) or below the tolerance, not at the round cap.
    pub converged: bool,
}

/// The latent S-SVM of the detector with support surfaces, solved by CCCP ([`super::latent`]'s algorithm
/// with [`train_detector`]'s cached and full passes as the inner solve): each round fixes the ground
/// truths' slices ([`DetectorOracle::set_latents`]), solves the S-SVM from scratch (a fresh cutting-plane
/// run; the candidate cache stays), then imputes every positive's slice `h_i = argmax_h wᵀφ(x_i, y_i, h)`
/// ([`super::latent::impute`]).
///
/// `progress` says where to start (round 0 with the initial slices, or where an interrupted run stood);
/// `save` is called with the progress before every round. With `resume_checkpoint`, the first round run
/// continues from the solver's checkpoint (`ssvm.checkpoint`) when there is one.
///
/// A round's reported `objective` is the latent objective evaluated over the **cached** candidates (plus
/// the ground truth and "no object") with the re-imputed slices: a full pass over every window per round
/// would cost as much as the round's own full passes. `ssvm_objective` is the round's 1-slack primal with
/// the slices it was given, an upper bound on the latent objective at its w (re-imputing only raises the
/// ground truths' scores), up to the solver's ε.
pub fn train_latent_detector(
    oracle: &mut DetectorOracle,
    ssvm: &SsvmOptions,
    progress: LatentProgress,
    settings: &LatentSettings,
    resume_checkpoint: bool,
    mut save: impl FnMut(&LatentProgress) -> Result<()>,
) -> Result<LatentDetectorSolution> {
    if !oracle.settings.surfaces {
        return Err(Error::Input("latent training needs an oracle with surfaces".into()));
    }
    if settings.max_rounds == 0 {
        return Err(Error::Input("latent training: at least one CCCP round".into()));
    }
    let LatentProgress { next_round, mut latents, mut rounds, oracle_state: resumed_state } = progress;
    let mut initial = [0usize; SLICES];
    (0..latents.len()).filter(|&i| oracle.num_latents(i) > 1).for_each(|i| initial[latents[i].min(SLICES - 1)] += 1);
    log::info!("CCCP starts at round {} with the slices (bottom to top) {initial:?}", next_round + 1);
    let mut converged = false;
    let mut last = None;
    for round in next_round..settings.max_rounds.max(next_round + 1) {
        oracle.set_latents(&latents)?;
        let resumed_round = resume_checkpoint && round == next_round;
        if !resumed_round {
            // The round starts from scratch: the previous round's solver checkpoint goes before the
            // progress names this round, so that a checkpoint beside a progress file is always its round's
            // (interrupted between the two, the previous round is solved again; the other way round, a
            // resume met the previous round's checkpoint with this round's slices and was refused).
            if let Some(path) = ssvm.checkpoint.as_ref().filter(|p| p.is_file()) {
                std::fs::remove_file(path).map_err(|e| Error::io(path, e))?;
            }
        }
        let solver_checkpoint = ssvm.checkpoint.as_ref().filter(|p| resumed_round && p.is_file());
        // A round resumed from its start (no solver checkpoint of it yet) takes back the oracle's state
        // of the round's start — the previous rounds' candidate cache and counters — so that it runs as
        // the uninterrupted round did; one resumed from a solver checkpoint gets the later state from it.
        if resumed_round && solver_checkpoint.is_none() {
            SeparationOracle::restore_run_state(&*oracle, &resumed_state)?;
        }
        let oracle_state = if resumed_round { resumed_state.clone() } else { oracle.run_state() };
        save(&LatentProgress { next_round: round, latents: latents.clone(), rounds: rounds.clone(), oracle_state })?;
        if round > 0 {
            oracle.allow_more_full_passes(settings.full_passes_per_round.max(1));
        }
        let mut solver = match solver_checkpoint {
            Some(path) => CuttingPlane::resume(ssvm.clone(), path)?,
            None => CuttingPlane::new(ssvm.clone())?,
        };
        let trained = train_detector(oracle, &mut solver)?;
        let w = &trained.solution.w;
        let imputed = impute(&*oracle, w)?;
        let changed = imputed.iter().zip(&latents).filter(|(a, b)| a != b).count();
        oracle.set_latents(&imputed)?;
        let objective = oracle.cached_objective(w, ssvm.c)?;
        let mut histogram = vec![0usize; SLICES];
        for (i, &h) in imputed.iter().enumerate() {
            if oracle.num_latents(i) > 1 {
                histogram[h] += 1;
            }
        }
        log::info!(
            "CCCP round {}: S-SVM objective {:.5}, latent objective over the cached candidates {objective:.5}, \
             {changed} slices changed, imputed slices (bottom to top) {histogram:?}",
            round + 1,
            trained.solution.primal
        );
        let previous = rounds.last().map(|r: &CccpRound| r.objective);
        rounds.push(CccpRound {
            ssvm_objective: trained.solution.primal,
            objective,
            changed,
            iterations: trained.solution.iterations,
            converged: trained.solution.converged,
            histogram,
        });
        latents = imputed;
        last = Some(trained);
        if changed == 0 || previous.is_some_and(|p| p - objective < settings.tolerance) {
            converged = true;
            break;
        }
    }
    let last = last.ok_or_else(|| Error::Input("latent training ran no round".into()))?;
    Ok(LatentDetectorSolution { last, latents, rounds, converged })
}

/// Where latent training stands between rounds (saved before each round, so that `--resume` continues the
/// interrupted round from its cutting-plane checkpoint with the slices it was started with).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LatentProgress {
    /// The round (0-based) that runs next with `latents`.
    pub next_round: usize,
    /// The ground truths' slices for that round, one per example.
    pub latents: Vec<usize>,
    /// The rounds done so far.
    pub rounds: Vec<CccpRound>,
    /// The oracle's [`SeparationOracle::run_state`] when the round started (its candidate cache and
    /// counters), restored when the round is resumed from its start, without a solver checkpoint of it.
    /// Empty in progress files written before 2026-12-08: such a resumed round starts with a full pass.
    #[serde(default)]
    pub oracle_state: Vec<u64>,
}

/// How many examples to take from a dataset.
#[derive(Clone, Debug)]
pub struct ExampleLimits {
    /// Instances of the category (spread evenly over the dataset's instances when there are more).
    pub positives: usize,
    /// Frames without the category (chosen by [`ExampleLimits::negative_choice`]).
    pub negatives: usize,
    /// How the `negatives` frames are chosen among the frames without the category.
    pub negative_choice: NegativeChoice,
    /// What a positive example does with the other instances in its frame.
    pub others: OtherInstances,
    /// The window the examples are for. With [`Support::Surfaces`] every example gets its frame's
    /// [`annotated_surfaces_by_category`], and an instance that stands on none of them (a floor lamp, a TV
    /// on the wall: [`SupportSurface::holds`] with [`SURFACE_HEIGHT_TOLERANCE_M`]) is not a positive
    /// example — the window can never output it. Negative frames are then taken among those with an
    /// annotated object of a surface category (on the others the window is empty). With
    /// [`Support::FloorAndSurfaces`] every example gets its surfaces too, but every instance is a positive
    /// and every frame without one a negative, as with the floor window.
    pub support: Support,
    /// Instances whose annotated box holds fewer than `seen.min_points` of the frame's points more than
    /// `seen.floor_slab` above the floor are not positives: objects the depth sensor did not see (beyond
    /// its range, hidden), which no hypothesis of the window can fit — the window keeps a box only with
    /// `min_points` points above its floor slab, so its best box for such an instance is a neighbouring
    /// wall or floor box whose IoU with the annotation is low, and training toward it teaches the model
    /// empty boxes. `None` trains on every instance (as every shipped model was trained). The choice among
    /// the seen instances is [`spread`] over them, as over all.
    pub seen: Option<SeenRule>,
    /// Instances with less than this share of their annotated box in the picture
    /// ([`crate::geometry::in_view_share`]: the box's volume that projects onto the image, occlusion
    /// ignored) are not positives: a bed beside the camera whose foot is in the picture keeps its whole box
    /// under synth's annotation rules, and the window's best box for it fits the visible part or an empty
    /// corner — training toward it teaches the model boxes that hold little of their object. `None` trains
    /// on every instance (as every shipped model was trained). The choice among the kept instances is
    /// [`spread`] over them, as over all.
    pub min_in_view: Option<f32>,
    /// How the frames' normals find their neighbours (the model records it: `features.normals`).
    pub normals: NormalSearch,
}

/// How [`collect_examples`] chooses its negative frames (frames without the category) when there are more
/// than [`ExampleLimits::negatives`].
#[derive(Clone, Debug, Default, PartialEq)]
pub enum NegativeChoice {
    /// Spread evenly over the dataset ([`spread`]): every shipped model was trained so.
    #[default]
    Spread,
    /// The hardest frames ([`hardest`]): those where an earlier detector of the category scored highest,
    /// `best_scores[frame directory name]` being the best score of a detection of the category in that
    /// frame (`f32::NEG_INFINITY` when it has none). Every frame without the category must have an entry
    /// (an error names the first that has none). The classic hard-negative mining of sliding-window
    /// detectors, over frames rather than boxes: the frames where a confusable object (a desk for a
    /// table, a bathroom counter for a dresser) stands are the ones the model must learn to score low,
    /// and an even spread over a room mix holds few of them. Only `share` (in [0, 1]) of the negatives
    /// are the hardest; the rest are [`spread`] over the frames left, so that the easy backgrounds the
    /// scores must also rank low stay represented (on the table and the dresser neither share 1 nor 0.5
    /// helped: README, "Training").
    Hardest { best_scores: BTreeMap<String, f32>, share: f32 },
}

/// The `count` of `candidates` with the highest `hardness` (`hardness[i]` belongs to `candidates[i]`;
/// NaN counts as −∞; ties: the earlier candidate first), returned in the candidates' order. All of them when
/// `count ≥ candidates.len()`.
pub fn hardest(candidates: &[usize], hardness: &[f32], count: usize) -> Vec<usize> {
    assert_eq!(candidates.len(), hardness.len(), "one hardness per candidate");
    let key = |i: usize| if hardness[i].is_nan() { f32::NEG_INFINITY } else { hardness[i] };
    let mut order: Vec<usize> = (0..candidates.len()).collect();
    order.sort_by(|&a, &b| key(b).total_cmp(&key(a)).then(a.cmp(&b)));
    let mut chosen: Vec<usize> = order.into_iter().take(count).collect();
    chosen.sort_unstable();
    chosen.into_iter().map(|i| candidates[i]).collect()
}

/// When an annotated instance counts as seen by the depth sensor ([`ExampleLimits::seen`]): the window's
/// own keep rule ([`crate::features::hypotheses::WindowOptions::min_points`], points more than one
/// window step above the floor) applied to the annotated box, its points counted exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeenRule {
    pub min_points: u32,
    /// Height above the frame's floor ([`crate::features::preprocess::floor_height`]) below which points
    /// do not count (metres): the window's step, its floor slab.
    pub floor_slab: f32,
}

impl SeenRule {
    /// Whether `cuboid` holds at least `min_points` of `points` more than `floor_slab` above `floor`.
    pub fn sees(&self, cuboid: &Cuboid, points: &[Vec3], floor: f32) -> bool {
        let above = floor + self.floor_slab;
        let mut count = 0u32;
        for p in points {
            if p.z > above && cuboid.contains(*p) {
                count += 1;
                if count >= self.min_points {
                    return true;
                }
            }
        }
        count >= self.min_points
    }
}

/// How far (metres) an annotated small object's bottom may lie from a measured surface and still stand
/// on it (the measured height is the median of the surface's points; an annotation's bottom can sit a
/// few centimetres above or below it).
pub const SURFACE_HEIGHT_TOLERANCE_M: f32 = 0.1;

/// Whether `cuboid` stands on one of `surfaces` (see [`ExampleLimits::support`]).
pub fn stands_on_a_surface(cuboid: &Cuboid, surfaces: &[SupportSurface]) -> bool {
    surfaces.iter().any(|s| s.holds(cuboid.centre.truncate(), cuboid.bottom(), SURFACE_HEIGHT_TOLERANCE_M))
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

/// The `(frame, instance)` pairs of `candidates` (in order) that `keep` keeps: it gets each frame with
/// candidates, read, and the frame's instances of `category`, and says which to keep (one flag each).
fn kept_positives(
    frames: &[std::path::PathBuf],
    annotations: &[Vec<crate::frame::Object>],
    category: &str,
    candidates: &[(usize, usize)],
    keep: impl Fn(&crate::frame::Frame, &[Cuboid]) -> Vec<bool> + Sync,
) -> Result<Vec<(usize, usize)>> {
    let mut with_instances: Vec<usize> = candidates.iter().map(|p| p.0).collect();
    with_instances.dedup();
    let flags: Vec<(usize, Vec<bool>)> = with_instances
        .par_iter()
        .map(|&f| {
            let frame = crate::frame::Frame::read(&frames[f], crate::frame::DepthSource::Raw)?;
            Ok((f, keep(&frame, &instances_of(&annotations[f], category))))
        })
        .collect::<Result<_>>()?;
    Ok(candidates
        .iter()
        .copied()
        .filter(|&(f, k)| flags.binary_search_by_key(&f, |s| s.0).is_ok_and(|i| flags[i].1[k]))
        .collect())
}

/// The `(frame, instance)` pairs of `candidates` whose instance `rule` sees in its frame's point cloud,
/// in order; logs how many were left out.
fn seen_positives(
    frames: &[std::path::PathBuf],
    annotations: &[Vec<crate::frame::Object>],
    category: &str,
    candidates: &[(usize, usize)],
    rule: SeenRule,
) -> Result<Vec<(usize, usize)>> {
    let kept = kept_positives(frames, annotations, category, candidates, |frame, instances| {
        let points = frame.point_cloud().points;
        let floor = crate::features::preprocess::floor_height(&points);
        instances.iter().map(|c| rule.sees(c, &points, floor)).collect()
    })?;
    log::info!(
        "{} of {} instances of '{category}' hold fewer than {} points above the floor slab (unseen by the depth \
         sensor); not trained on",
        candidates.len() - kept.len(),
        candidates.len(),
        rule.min_points
    );
    Ok(kept)
}

/// The `(frame, instance)` pairs of `candidates` with at least `min_share` of their box in view of their
/// frame's camera ([`crate::geometry::in_view_share`]), in order; logs how many were left out.
fn in_view_positives(
    frames: &[std::path::PathBuf],
    annotations: &[Vec<crate::frame::Object>],
    category: &str,
    candidates: &[(usize, usize)],
    min_share: f32,
) -> Result<Vec<(usize, usize)>> {
    let kept = kept_positives(frames, annotations, category, candidates, |frame, instances| {
        let camera = crate::geometry::Camera::new(frame.intrinsics(), frame.rtilt());
        let share = |c: &Cuboid| crate::geometry::in_view_share(c, &camera, frame.width(), frame.height());
        instances.iter().map(|c| share(c) >= min_share).collect()
    })?;
    log::info!(
        "{} of {} instances of '{category}' have less than {:.0} % of their box in the picture; not trained on",
        candidates.len() - kept.len(),
        candidates.len(),
        100.0 * min_share
    );
    Ok(kept)
}

/// What [`collect_examples`] gathers.
pub struct CollectedExamples {
    pub examples: Vec<TrainingExample>,
    /// With a window that uses surfaces ([`Support::uses_surfaces`]): the categories whose annotated
    /// surfaces hold at least one chosen positive ([`stands_on_a_surface`]) — the only surfaces the
    /// model's detection searches (`window.supporters`). Otherwise every surface category. The examples
    /// keep the surfaces of every surface category: a box on another category's surface (a basin-sized
    /// box on a bed's pillows) is a negative worth learning from, and costs nothing at detection.
    pub supporters: SurfaceCategories,
}

/// The negative frames of [`collect_examples`]: `limits.negatives` of `candidates` (indices into `frames`,
/// ascending; the frames without the category) chosen as [`ExampleLimits::negative_choice`] says, ascending.
fn choose_negatives(
    frames: &[std::path::PathBuf],
    category: &str,
    candidates: &[usize],
    limits: &ExampleLimits,
) -> Result<Vec<usize>> {
    let (best_scores, share) = match &limits.negative_choice {
        NegativeChoice::Spread => {
            return Ok(spread(candidates.len(), limits.negatives).into_iter().map(|n| candidates[n]).collect())
        }
        NegativeChoice::Hardest { best_scores, share } => (best_scores, *share),
    };
    let hardness = candidates
        .iter()
        .map(|&f| {
            let name = crate::frame::frame_name(&frames[f]);
            best_scores.get(&name).copied().ok_or_else(|| {
                Error::invalid(
                    &frames[f],
                    format!(
                        "hard negatives: the frame '{name}' holds no '{category}', so it is a negative \
                         candidate, but has no detections file to rank it by (detect every frame of the \
                         training set)"
                    ),
                )
            })
        })
        .collect::<Result<Vec<f32>>>()?;
    let count = limits.negatives.min(candidates.len());
    let hard_count = ((count as f32 * share.clamp(0.0, 1.0)).round() as usize).min(count);
    let hard = hardest(candidates, &hardness, hard_count);
    let scores: Vec<f32> =
        candidates.iter().zip(&hardness).filter(|(f, _)| hard.binary_search(f).is_ok()).map(|(_, &h)| h).collect();
    let rest: Vec<usize> = candidates.iter().copied().filter(|f| hard.binary_search(f).is_err()).collect();
    let mut chosen: Vec<usize> =
        spread(rest.len(), count - hard_count).into_iter().map(|n| rest[n]).chain(hard.iter().copied()).collect();
    chosen.sort_unstable();
    let range = match (scores.iter().copied().reduce(f32::min), scores.iter().copied().reduce(f32::max)) {
        (Some(low), Some(high)) => format!(" (their best detection scores {low:.3} to {high:.3})"),
        _ => String::new(),
    };
    log::info!(
        "{category}: as negatives the {} hardest of {} frames without one{range} and {} spread over the others",
        hard.len(),
        candidates.len(),
        count - hard_count,
    );
    Ok(chosen)
}

/// The training examples of `category` from frame directories: reads the annotations of every frame,
/// picks the instances and negative frames ([`ExampleLimits`]), preprocesses the frames they come from
/// (in parallel) and builds the examples; with a window on surfaces, also the supporters (see
/// [`CollectedExamples::supporters`]).
pub fn collect_examples(
    frames: &[std::path::PathBuf],
    category: &str,
    limits: ExampleLimits,
) -> Result<CollectedExamples> {
    let annotations = read_all_annotations(frames)?;
    let mut positives = Vec::new(); // (frame, instance)
    let mut negatives = Vec::new();
    for (f, objects) in annotations.iter().enumerate() {
        let instances = instances_of(objects, category);
        let has_supporter =
            || objects.iter().any(|o| crate::category::SURFACE_CATEGORIES.contains(&o.category.as_str()));
        // A surface window on a frame without supporting furniture is empty: such a frame teaches nothing.
        if instances.is_empty() && (limits.support != Support::Surfaces || has_supporter()) {
            negatives.push(f);
        }
        positives.extend((0..instances.len()).map(|k| (f, k)));
    }
    let positives = match limits.seen {
        Some(rule) => seen_positives(frames, &annotations, category, &positives, rule)?,
        None => positives,
    };
    let positives = match limits.min_in_view {
        Some(share) => in_view_positives(frames, &annotations, category, &positives, share)?,
        None => positives,
    };
    let positives: Vec<(usize, usize)> =
        spread(positives.len(), limits.positives).into_iter().map(|n| positives[n]).collect();
    let negatives = choose_negatives(frames, category, &negatives, &limits)?;
    let mut needed: Vec<usize> = positives.iter().map(|p| p.0).chain(negatives.iter().copied()).collect();
    needed.sort_unstable();
    needed.dedup();
    let preprocessed: Vec<(usize, Preprocessed)> = needed
        .par_iter()
        .map(|&f| {
            let frame = crate::frame::Frame::read(&frames[f], crate::frame::DepthSource::Raw)?;
            Ok((f, Preprocessed::from_frame_with(&frame, limits.normals)?))
        })
        .collect::<Result<_>>()?;
    // The support surfaces of every preprocessed frame, in the same order, with their categories (which
    // choose the supporters).
    let all_surfaces: Vec<Vec<(&str, SupportSurface)>> = preprocessed
        .par_iter()
        .map(|(f, pre)| {
            if limits.support.uses_surfaces() {
                annotated_surfaces_by_category(pre, &annotations[*f])
            } else {
                Vec::new()
            }
        })
        .collect();
    // Every frame of `jobs` is in `needed`, so the search always succeeds.
    let index_of = |f: usize| preprocessed.binary_search_by_key(&f, |p| p.0).unwrap_or(0);
    let pre_of = |f: usize| &preprocessed[index_of(f)].1;
    let supporters = if limits.support.uses_surfaces() {
        let held = positives.iter().fold(SurfaceCategories::NONE, |set, &(f, k)| {
            let instance = instances_of(&annotations[f], category)[k];
            all_surfaces[index_of(f)]
                .iter()
                .filter(|(_, s)| stands_on_a_surface(&instance, std::slice::from_ref(s)))
                .fold(set, |set, (c, _)| set.with(c).unwrap_or(set))
        });
        log::info!("{category}: searched on the surfaces of {}", held.names().join(", "));
        held
    } else {
        SurfaceCategories::ALL
    };
    let surfaces: Vec<Vec<SupportSurface>> =
        all_surfaces.iter().map(|frame| frame.iter().map(|(_, s)| *s).collect()).collect();
    let surfaces_of = |f: usize| &surfaces[index_of(f)];
    let name_of = |f: usize| crate::frame::frame_name(&frames[f]);
    let mut jobs: Vec<(String, usize, Option<Cuboid>, Vec<Cuboid>)> = Vec::new();
    let mut off_surface = 0;
    for &(f, k) in &positives {
        let instances = instances_of(&annotations[f], category);
        if limits.support == Support::Surfaces && !stands_on_a_surface(&instances[k], surfaces_of(f)) {
            off_surface += 1;
            continue;
        }
        let others: Vec<Cuboid> = instances.iter().enumerate().filter(|(j, _)| *j != k).map(|(_, c)| *c).collect();
        jobs.push((format!("{} #{k}", name_of(f)), f, Some(instances[k]), others));
    }
    if off_surface > 0 {
        log::info!("{off_surface} instances of '{category}' stand on no annotated support surface; not trained on");
    }
    for &f in &negatives {
        jobs.push((format!("{} (no {category})", name_of(f)), f, None, Vec::new()));
    }
    let examples = jobs
        .into_par_iter()
        .map(|(name, f, truth, others)| {
            TrainingExample::with_others(name, pre_of(f), truth, &others, limits.others)
                .on_surfaces(surfaces_of(f).clone())
        })
        .collect();
    Ok(CollectedExamples { examples, supporters })
}

/// The annotated objects of every frame (annotations only; images are not read).
pub fn read_all_annotations(frames: &[std::path::PathBuf]) -> Result<Vec<Vec<crate::frame::Object>>> {
    frames.par_iter().map(|dir| Ok(crate::frame::read_annotations(dir)?.0)).collect()
}
