//! Detection: every model's sliding window on a frame, scores, threshold, 3D non-maximum suppression, and
//! the overlay picture.
//!
//! Per frame the preprocessing (gradients, normals, floor) and the per-yaw grids are computed once and
//! shared by all models with the same window step; each model then enumerates its own sizes' hypotheses
//! and scores them with its feature path (`fast`: [`crate::features::fast`], its tables built on the CPU and
//! scored by the GPU kernel [`crate::gpu::fast`] when an adapter is present, else on the CPU; `exact`: the
//! GPU kernel when an adapter is present, else the CPU reference). Of each category the best
//! hypotheses scoring at least the model's threshold (all, or the best [`DetectOptions::candidates`]) go
//! through 3D NMS
//! ([`crate::nms`], IoU [`DetectOptions::nms_iou`]) and at most [`DetectOptions::max_per_category`] are
//! reported; models with a calibration report calibrated probabilities ([`calibrate`]), and all
//! detections are sorted by score over all categories.
//!
//! Models whose window stands on support surfaces ([`Support::Surfaces`]: small categories;
//! [`Support::FloorAndSurfaces`]: sinks, on the floor as well) run after
//! the others (floor, [`Support::Free`] and [`Support::Resting`] models): their hypotheses stand on the
//! surfaces of the frame's
//! detections of
//! [`SURFACE_CATEGORIES`] whose calibrated score is at least [`DetectOptions::support_min_score`]
//! ([`detected_surfaces`], [`surface_window`](crate::features::hypotheses::surface_window)), scored, selected and suppressed the same way.

use std::collections::BTreeMap;
use std::time::Instant;

use glam::Vec3;
use image::RgbImage;
use rayon::prelude::*;

use crate::backend::{Backend, FastJob};
use crate::category::{category_index, is_cross_score_category, SurfaceCategories, CATEGORIES, SURFACE_CATEGORIES};
use crate::draw::{
    category_colour, contrasting, draw_cuboid_with, draw_label, label_size, place_labels, shade_convex_polygon, Colour,
    LabelBox,
};
use crate::error::{Error, Result};
use crate::eval::{Detection, FrameDetections};
use crate::features::budget;
use crate::features::fast::FastEngine;
use crate::features::hypotheses::{
    free_bottoms, windows, FrameYaws, HypothesisSet, Support, SupportSurface, WindowOptions, WindowRequest,
    DEFAULT_STEP,
};
use crate::features::preprocess::NormalSearch;
use crate::features::scene::rotate;
use crate::features::surface::{best_slice, category_surface, refined_surface_height, SurfaceEngine, SurfaceSource};
use crate::features::{FeatureScene, Hypothesis, Preprocessed};
use crate::frame::Frame;
use crate::geometry::{iou_3d, Camera, Cuboid};
use crate::model::{window_scenes, FeaturePath, Model, SceneKey};
use crate::nms::{suppress_in_order, vote, NmsOptions, VoteOptions, DEFAULT_NMS_IOU, DEFAULT_VOTE_IOU};

/// Settings of [`detect_frame`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectOptions {
    /// NMS IoU threshold.
    pub nms_iou: f32,
    /// Detections kept per category after NMS.
    pub max_per_category: usize,
    /// Highest-scoring hypotheses per category that enter NMS; `None`: all above the threshold. A limit
    /// starves NMS: the best few thousand boxes of a sliding window crowd around a handful of places (all
    /// sizes and yaws of one object), so after suppression only a few detections would be left.
    pub candidates: Option<usize>,
    /// Overrides every model's cut with this raw score (`w·φ + bias`, before calibration).
    pub min_score: Option<f32>,
    /// Keeps the detections whose calibrated probability is at least this; every model must carry a
    /// calibration ([`DetectOptions::threshold`]). `None` (with no `min_score`): the default cut,
    /// [`DEFAULT_MIN_PROBABILITY`] for a calibrated model and its raw `threshold` for one without a
    /// calibration.
    pub min_probability: Option<f32>,
    /// Smallest calibrated probability of a detection of a surface category whose support surface the
    /// surface models (small objects) search ([`detected_surfaces`]).
    pub support_min_score: f32,
    /// How the points' normals find their plane-fit neighbours ([`NormalSearch`]; the shipped models were
    /// trained with the default, [`NormalSearch::KdTree`]).
    pub normals: NormalSearch,
    /// Box voting after the NMS ([`crate::nms::vote`]): each kept box becomes the weighted mean of the
    /// candidates whose 3D IoU with it is at least this, and the voted boxes go through the NMS again (at
    /// `nms_iou`, since 2026-12-05: a voted box that moved onto a better one is demoted by
    /// [`REVOTE_DEMOTION`] since 2026-12-06, dropped before); `None`: the kept
    /// hypotheses' own boxes (the only behaviour before 2026-12-04). Default [`DEFAULT_VOTE_IOU`].
    pub box_voting: Option<f32>,
    /// Whether every detection of [`CROSS_SCORE_CATEGORIES`](crate::category::CROSS_SCORE_CATEGORIES) gets the raw scores of those categories'
    /// models on its box ([`cross_scores`]; what the context cascade's feature set v7 reads). Default
    /// `false`: the CLI turns it on for first-stage files (`detect --no-cascade`, on which a cascade may be
    /// trained) and when the cascade it applies reads them.
    pub cross_scores: bool,
    /// Whether the floor's models search a second floor where the camera does not see the floor
    /// ([`Preprocessed::unseen_floor`], since 2026-12-07; README, "The floor where it is not seen"): their
    /// window then runs on both floors and each model's detections of the two go through its NMS together
    /// ([`merge_floors`]). Default `true`; `false`: the lowest points' floor alone, as before.
    pub unseen_floor: bool,
}

impl Default for DetectOptions {
    fn default() -> Self {
        DetectOptions {
            nms_iou: DEFAULT_NMS_IOU,
            max_per_category: 20,
            candidates: None,
            min_score: None,
            min_probability: None,
            support_min_score: DEFAULT_SUPPORT_MIN_SCORE,
            normals: NormalSearch::default(),
            box_voting: Some(DEFAULT_VOTE_IOU),
            cross_scores: false,
            unseen_floor: true,
        }
    }
}

impl DetectOptions {
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.nms_iou) {
            return Err(Error::Input(format!("the NMS IoU must be in [0, 1], got {}", self.nms_iou)));
        }
        if self.max_per_category == 0 || self.candidates == Some(0) {
            return Err(Error::Input("max detections per category and candidates must be at least 1".into()));
        }
        if !(0.0..=1.0).contains(&self.support_min_score) {
            return Err(Error::Input(format!(
                "the support surfaces' minimum score must be a probability in [0, 1], got {}",
                self.support_min_score
            )));
        }
        if self.box_voting.is_some_and(|iou| !(iou > 0.0 && iou <= 1.0)) {
            return Err(Error::Input(format!("the box voting IoU must be in (0, 1], got {:?}", self.box_voting)));
        }
        if self.min_score.is_some_and(|s| s.is_nan()) {
            return Err(Error::Input("the minimum score is not a number".into()));
        }
        if let Some(p) = self.min_probability {
            if !(p > 0.0 && p < 1.0) {
                return Err(Error::Input(format!("the minimum probability must be in (0, 1), got {p}")));
            }
            if self.min_score.is_some() {
                return Err(Error::Input("give a minimum raw score or a minimum probability, not both".into()));
            }
        }
        Ok(())
    }

    /// The raw-score cut for `model`'s hypotheses: the minimum raw score when given, else the raw score at
    /// the minimum probability ([`crate::calibration::Calibration::raw_score_at`]; an error for a model
    /// without calibration), else the default: the raw score at [`DEFAULT_MIN_PROBABILITY`] for a
    /// calibrated model, the model's own raw `threshold` for one without a calibration.
    pub fn threshold(&self, model: &Model) -> Result<f32> {
        match (self.min_score, self.min_probability) {
            (Some(score), _) => Ok(score),
            (None, Some(p)) => model.calibration.as_ref().map(|c| c.raw_score_at(p)).ok_or_else(|| {
                Error::Input(format!(
                    "the '{}' model has no calibration, so a minimum probability means nothing for it: \
                     calibrate it (cog-gpu calibrate) or give a minimum raw score instead",
                    model.category
                ))
            }),
            (None, None) => {
                Ok(model.calibration.as_ref().map_or(model.threshold, |c| c.raw_score_at(DEFAULT_MIN_PROBABILITY)))
            }
        }
    }
}

/// Log-odds by which a voted box is demoted when the NMS run again over the voted boxes would drop it
/// ([`DetectOptions::box_voting`]): its raw score is lowered by this over its model's calibration slope (1
/// without a calibration), about 400 times lower odds. Chosen on the selection set, seeds 2500–2506, no test
/// frame (README, "Box voting", "Demoted, not dropped"): 3, 6 and 20 gave the same first-stage AP there.
pub const REVOTE_DEMOTION: f32 = 6.0;

/// Voters of [`crate::nms::vote`] whose weight (odds ratio against the kept box) is below this are not
/// visited: a thousand times less likely right than the box they would move.
const VOTE_MIN_WEIGHT: f32 = 1e-3;

/// The default cut of a calibrated model's detections ([`DetectOptions::threshold`]): a calibrated
/// probability of 10⁻³, the same meaning for every model.
///
/// Why a probability, and why this one: the models' own raw cut 0 (the S-SVM's "no object" score) means a
/// different probability for each model (σ(b), from below 10⁻⁵ for the lamp and the pillow to 0.71 for
/// the TV), and it is not what the calibrations and the context cascade were fitted on: both saw every
/// first-stage detection down to raw −3 (`assets/reproduce-models.sh`). Cutting at raw 0 before the
/// cascade starved it of the weak detections it had learned from. Chosen on the calibration set (220
/// frames, held out from the models' and the cascade's training; the shipped 19 models' first-stage
/// detections at raw ≥ −3, cut, then rescored by the shipped cascade; 19-class mAP@0.25): raw ≥ 0 38.0,
/// p ≥ 10⁻⁴ 41.0, **10⁻³ 41.2**, 3·10⁻³ 41.1, 10⁻² 41.1, 5·10⁻² 38.7, no cut (raw ≥ −3) 41.0 — a plateau
/// from 10⁻⁴ to 10⁻², its best point taken (README, "Detection: `cog-gpu detect`").
pub const DEFAULT_MIN_PROBABILITY: f32 = 1e-3;

/// The fast-path engines of one frame: one per (scene, feature layout, fast options); the per-yaw lattices
/// depend on the scene, the subdivisions and whether COG is binned only, so engines that differ in their
/// voxel grid share them ([`FastEngine::sharing_lattices`]) instead of binning every point of every yaw
/// again.
pub struct FastEngines<'a> {
    engines: Vec<FastEngine<'a>>,
}

impl<'a> FastEngines<'a> {
    pub fn new() -> Self {
        FastEngines { engines: Vec::new() }
    }

    /// The engine of `model` on `scene`, built on first use.
    pub fn get(&mut self, scene: &'a FeatureScene, model: &Model) -> &FastEngine<'a> {
        let index = match self.position(scene, model) {
            Some(index) => index,
            None => {
                let options = model.features.fast_options();
                let shared = self
                    .engines
                    .iter()
                    .filter(|e| std::ptr::eq(e.scene(), scene))
                    .find_map(|e| FastEngine::sharing_lattices(e, &model.layout, options));
                self.engines.push(shared.unwrap_or_else(|| FastEngine::new(scene, &model.layout, options)));
                self.engines.len() - 1
            }
        };
        &self.engines[index]
    }

    /// Index of the engine that serves `model` on `scene`, if built.
    fn position(&self, scene: &FeatureScene, model: &Model) -> Option<usize> {
        let options = model.features.fast_options();
        self.engines
            .iter()
            .position(|e| std::ptr::eq(e.scene(), scene) && *e.layout() == model.layout && e.options() == options)
    }

    /// Seconds the engines spent building layer tables, summed over threads.
    pub fn table_thread_seconds(&self) -> f64 {
        self.engines.iter().map(FastEngine::table_thread_seconds).sum()
    }
}

impl Default for FastEngines<'_> {
    fn default() -> Self {
        Self::new()
    }
}

/// Scores of `hypotheses` for one model (`w·φ + bias`, plus `max_h` of the surface part for a model with
/// latent support surfaces), with the model's feature path; fast-path engines come from (and go into)
/// `engines`.
pub fn score_hypotheses<'a>(
    scene: &'a FeatureScene,
    model: &Model,
    hypotheses: &[Hypothesis],
    backend: Backend,
    engines: &mut FastEngines<'a>,
) -> Result<Vec<f32>> {
    Ok(score_hypotheses_with_slices(scene, model, hypotheses, backend, engines)?.0)
}

/// [`score_hypotheses`] and, for a model with latent support surfaces, each hypothesis's best slice
/// ([`crate::features::surface::best_slice`]). The surface part is scored by the backend too
/// ([`Backend::slice_scores`]: on the GPU by the fast path's kernel on the surface grid's tables).
pub fn score_hypotheses_with_slices<'a>(
    scene: &'a FeatureScene,
    model: &Model,
    hypotheses: &[Hypothesis],
    backend: Backend,
    engines: &mut FastEngines<'a>,
) -> Result<(Vec<f32>, Option<Vec<u8>>)> {
    let weights = std::slice::from_ref(&model.weights);
    let scores = match model.features.path {
        FeaturePath::Fast => backend.fast_scores(engines.get(scene, model), hypotheses, weights),
        FeaturePath::Exact => backend.scores(scene, &model.layout, hypotheses, weights)?.0,
    };
    Ok(finish_scores(scene, model, hypotheses, scores, backend))
}

/// One model's scores of its hypotheses and, with latent support surfaces, each one's best slice.
pub type ModelScores = (Vec<f32>, Option<Vec<u8>>);

/// Every model's [`score_hypotheses_with_slices`] at once (`scenes[m]` and `hypotheses[m]` are model m's):
/// the fast-path models that share an engine are scored in one [`Backend::fast_scores_jobs`] call (on the
/// GPU: one submission per batch for all of them, tables shared). The scores equal the one-by-one ones.
pub fn score_models<'a>(
    scenes: &[&'a FeatureScene],
    models: &[&Model],
    hypotheses: &[&[Hypothesis]],
    backend: Backend,
    engines: &mut FastEngines<'a>,
) -> Result<Vec<ModelScores>> {
    let mut raw: Vec<Option<Vec<f32>>> = vec![None; models.len()];
    // Fast-path models grouped by engine, in model order.
    let mut by_engine: Vec<(usize, Vec<usize>)> = Vec::new();
    for (m, model) in models.iter().enumerate() {
        if model.features.path == FeaturePath::Fast {
            engines.get(scenes[m], model);
            let index = engines.position(scenes[m], model).expect("built above");
            match by_engine.iter_mut().find(|(e, _)| *e == index) {
                Some((_, members)) => members.push(m),
                None => by_engine.push((index, vec![m])),
            }
        }
    }
    // The engines' calls run concurrently: on the GPU one call's packing on the CPU overlaps another's
    // batches on the GPU (each batch holds the context's buffer pool from its uploads to its read-back).
    let engine_scores: Vec<Vec<Vec<f32>>> = by_engine
        .par_iter()
        .map(|(index, members)| {
            let jobs: Vec<FastJob> = members
                .iter()
                .map(|&m| FastJob { hypotheses: hypotheses[m], weights: std::slice::from_ref(&models[m].weights) })
                .collect();
            backend.fast_scores_jobs(&engines.engines[*index], &jobs)
        })
        .collect();
    for ((_, members), scores) in by_engine.iter().zip(engine_scores) {
        for (&m, scores) in members.iter().zip(scores) {
            raw[m] = Some(scores);
        }
    }
    let mut out = Vec::with_capacity(models.len());
    for (m, model) in models.iter().enumerate() {
        let scores = match raw[m].take() {
            Some(scores) => scores,
            None => backend.scores(scenes[m], &model.layout, hypotheses[m], std::slice::from_ref(&model.weights))?.0,
        };
        out.push(finish_scores(scenes[m], model, hypotheses[m], scores, backend));
    }
    Ok(out)
}

/// Adds the bias and, for a model with latent support surfaces, the best slice's surface score to the
/// voxel scores `scores` of `hypotheses`; returns the scores and the chosen slices (the slices scored by
/// `backend`).
fn finish_scores(
    scene: &FeatureScene,
    model: &Model,
    hypotheses: &[Hypothesis],
    mut scores: Vec<f32>,
    backend: Backend,
) -> (Vec<f32>, Option<Vec<u8>>) {
    scores.iter_mut().for_each(|s| *s += model.bias);
    let slices = model.surface.as_ref().map(|surface| {
        let engine = SurfaceEngine::new(scene, model.layout.groups, model.features.fast_options());
        backend
            .slice_scores(&engine, hypotheses, surface)
            .iter()
            .zip(scores.iter_mut())
            .map(|(slice_scores, score)| {
                let (h, value) = best_slice(slice_scores);
                *score += value;
                h as u8
            })
            .collect()
    });
    (scores, slices)
}

/// Detects every model's category in `frame`.
pub fn detect_frame(
    frame: &Frame,
    models: &[Model],
    backend: Backend,
    options: &DetectOptions,
) -> Result<FrameDetections> {
    options.validate()?;
    let pre = backend.preprocess(frame, options.normals)?;
    detect_preprocessed(&frame.name, pre, models, backend, options)
}

/// Checks the memory of every model's sliding window and fast-path tables on `pre` (see
/// [`crate::features::budget`]) before any of them is built; each distinct setting is checked once.
pub fn check_budget<'a>(pre: &Preprocessed, models: impl IntoIterator<Item = &'a Model>) -> Result<()> {
    check_budget_with(pre, &FrameYaws::new(pre), models)
}

/// [`check_budget`] with the frame's yaws (shared with the scenes that follow).
fn check_budget_with<'a>(
    pre: &Preprocessed,
    frame_yaws: &FrameYaws,
    models: impl IntoIterator<Item = &'a Model>,
) -> Result<()> {
    let mut checked = Vec::new();
    for model in models {
        let anchor = model.window.yaw_anchor;
        // The free window holds the sizes at each of its bottoms: as many hypotheses as that many sizes.
        let layers = match model.window.support {
            Support::Free | Support::Resting => free_bottoms(0.0, model.window.step).len(),
            Support::Floor | Support::Surfaces => 1,
            // The floor's layer and, for the surfaces', one more: a frame's few pieces of furniture cover
            // its lattice about once (an estimate, as for the surface window's one layer).
            Support::FloorAndSurfaces => 2,
        };
        let sizes = model.sizes().len() * layers;
        let key = (model.window.step.to_bits(), anchor, sizes, model.features.path, model.layout.grid()[2]);
        if checked.contains(&key) {
            continue;
        }
        checked.push(key);
        let yaws = frame_yaws.yaws(anchor);
        budget::check_window(pre, &yaws, model.window.step, sizes)?;
        if model.features.path == FeaturePath::Fast {
            budget::check_fast(pre, &yaws, model.window.step, &model.layout, model.features.subdivisions)?;
        }
    }
    Ok(())
}

/// Wall-clock seconds of the stages of one frame's detection after preprocessing
/// ([`detect_preprocessed_timed`]; `cog-gpu bench --detect` adds reading, preprocessing and output).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct DetectStages {
    /// The frame's wall directions, the memory check and the per-yaw grids of each window step and yaw
    /// anchor ([`FeatureScene::new`]).
    pub yaw_grids_s: f64,
    /// Every model's sliding-window hypotheses.
    pub window_s: f64,
    /// The fast path's per-yaw lattices ([`FastEngine::new`]), once per shared setting.
    pub lattices_s: f64,
    /// Scoring: the fast path's per-(yaw, height) summed-area tables and the scores (on the GPU path also
    /// the uploads, dispatches and read-back), or the exact path's scores.
    pub score_s: f64,
    /// Of `score_s`'s work, the seconds spent building the fast path's tables, summed over threads (the
    /// tables are built inside the parallel scoring loop, so they have no wall-clock stage of their own;
    /// divide by the threads for a wall-clock share).
    pub tables_thread_s: f64,
    /// Thresholds, ordering and the candidates' cuboids.
    pub select_s: f64,
    /// 3D NMS and the calibration of the survivors.
    pub nms_s: f64,
    /// The detections' [`cross_scores`] (0 unless [`DetectOptions::cross_scores`]).
    pub cross_scores_s: f64,
    /// Hypotheses scored, over all models.
    pub hypotheses: usize,
    /// Hypotheses scored per category, in [`CATEGORIES`] order (a category without a model: 0): which
    /// model's window costs what (`cog-gpu bench --detect` prints them per frame).
    pub hypotheses_per_category: [usize; CATEGORIES.len()],
    /// Process CPU seconds (user + system, summed over all threads, the GPU driver's included) during each
    /// stage, as [`process_cpu_seconds`] counts them: against the wall-clock seconds times the threads,
    /// how busy the stage keeps the cores; on the GPU path, the CPU work left beside the GPU's. Only
    /// meaningful when nothing else in the process runs meanwhile (one frame at a time).
    pub yaw_grids_cpu_s: f64,
    pub window_cpu_s: f64,
    pub lattices_cpu_s: f64,
    pub score_cpu_s: f64,
    pub select_cpu_s: f64,
    pub nms_cpu_s: f64,
    pub cross_scores_cpu_s: f64,
}

/// A stage of [`DetectStages`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    YawGrids,
    Window,
    Lattices,
    Score,
    Select,
    Nms,
    CrossScores,
}

impl DetectStages {
    /// The sum of the wall-clock stages (`tables_thread_s` is inside `score_s`).
    pub fn total_s(&self) -> f64 {
        self.yaw_grids_s
            + self.window_s
            + self.lattices_s
            + self.score_s
            + self.select_s
            + self.nms_s
            + self.cross_scores_s
    }

    /// Adds `lap` to `stage`'s wall-clock and CPU seconds.
    pub fn add(&mut self, stage: Stage, lap: Lap) {
        let (wall, cpu) = match stage {
            Stage::YawGrids => (&mut self.yaw_grids_s, &mut self.yaw_grids_cpu_s),
            Stage::Window => (&mut self.window_s, &mut self.window_cpu_s),
            Stage::Lattices => (&mut self.lattices_s, &mut self.lattices_cpu_s),
            Stage::Score => (&mut self.score_s, &mut self.score_cpu_s),
            Stage::Select => (&mut self.select_s, &mut self.select_cpu_s),
            Stage::Nms => (&mut self.nms_s, &mut self.nms_cpu_s),
            Stage::CrossScores => (&mut self.cross_scores_s, &mut self.cross_scores_cpu_s),
        };
        *wall += lap.wall_s;
        *cpu += lap.cpu_s;
    }
}

/// Seconds of CPU time (user + system, all threads) the process has used so far (`getrusage`); 0 on a
/// platform without it (then every stage's CPU seconds read 0).
pub fn process_cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        // SAFETY: getrusage only writes the struct it is given, which is plain data and zeroed first.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) } == 0 {
            let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            return seconds(usage.ru_utime) + seconds(usage.ru_stime);
        }
    }
    0.0
}

/// One [`Stopwatch`] lap: wall-clock seconds and the process's CPU seconds over the same interval.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Lap {
    pub wall_s: f64,
    pub cpu_s: f64,
}

/// Wall-clock and process-CPU laps for stage timings.
pub struct Stopwatch {
    wall: Instant,
    cpu: f64,
}

impl Stopwatch {
    pub fn start() -> Stopwatch {
        Stopwatch { wall: Instant::now(), cpu: process_cpu_seconds() }
    }

    /// Seconds since the previous lap (or the start).
    pub fn lap(&mut self) -> Lap {
        let now = Instant::now();
        let cpu = process_cpu_seconds();
        let lap = Lap { wall_s: now.duration_since(self.wall).as_secs_f64(), cpu_s: (cpu - self.cpu).max(0.0) };
        (self.wall, self.cpu) = (now, cpu);
        lap
    }
}

/// [`detect_frame`] on an already preprocessed frame.
pub fn detect_preprocessed(
    name: &str,
    pre: Preprocessed,
    models: &[Model],
    backend: Backend,
    options: &DetectOptions,
) -> Result<FrameDetections> {
    detect_preprocessed_timed(name, pre, models, backend, options, &mut DetectStages::default())
}

/// [`detect_preprocessed`], adding each stage's wall-clock seconds to `stages`.
pub fn detect_preprocessed_timed(
    name: &str,
    pre: Preprocessed,
    models: &[Model],
    backend: Backend,
    options: &DetectOptions,
    stages: &mut DetectStages,
) -> Result<FrameDetections> {
    let mut clock = Stopwatch::start();
    let mut lap = || clock.lap();
    let frame_yaws = FrameYaws::new(&pre);
    check_budget_with(&pre, &frame_yaws, models)?;
    // One scene per distinct window step, yaw anchor and lattice (the yaw grids' cell is the step).
    let scenes = window_scenes(&pre, &frame_yaws, models);
    stages.add(Stage::YawGrids, lap());
    let scene_of = |m: &Model| &scenes[&m.window.scene_key()];
    let mut engines = FastEngines::new();
    // The floor (and free-window) models first; the surface models then search the surfaces of their
    // detections.
    let (floor_models, surface_models): (Vec<&Model>, Vec<&Model>) =
        models.iter().partition(|m| !m.window.support.uses_surfaces());
    // Each model's window (the surface models' on the surfaces `surfaces_of` gives them): the models of
    // one scene in one call of `windows` (their yaws and models in parallel; each yaw's count tables built
    // once for all of them), the scenes one after the other, gathered in model order.
    let windows_of = |scenes: &BTreeMap<SceneKey, FeatureScene>,
                      models: &[&Model],
                      surfaces_of: &(dyn Fn(&Model) -> Vec<SupportSurface> + Sync)|
     -> Vec<HypothesisSet> {
        let options: Vec<WindowOptions> = models
            .iter()
            .map(|model| WindowOptions { sizes: model.sizes(), min_points: model.window.min_points })
            .collect();
        let surfaces: Vec<Vec<SupportSurface>> = models.iter().map(|model| surfaces_of(model)).collect();
        let mut sets: Vec<Option<HypothesisSet>> = models.iter().map(|_| None).collect();
        let mut keys: Vec<SceneKey> = models.iter().map(|model| model.window.scene_key()).collect();
        keys.sort();
        keys.dedup();
        for key in keys {
            let members: Vec<usize> = (0..models.len()).filter(|&m| models[m].window.scene_key() == key).collect();
            let requests: Vec<WindowRequest> = members
                .iter()
                .map(|&m| WindowRequest {
                    support: models[m].window.support,
                    options: &options[m],
                    surfaces: &surfaces[m],
                })
                .collect();
            for (m, set) in members.iter().zip(windows(&scenes[&key], &requests)) {
                sets[*m] = Some(set);
            }
        }
        sets.into_iter().map(|set| set.expect("every model's scene is searched")).collect()
    };
    let windows = windows_of(&scenes, &floor_models, &|_| Vec::new());
    stages.add(Stage::Window, lap());
    let mut detections =
        detect_windows(name, &pre, &floor_models, &windows, scene_of, backend, options, &mut engines, stages)?;
    lap(); // detect_windows timed its own stages

    // The same models on the second floor where the floor is not seen: the frame's points with the floor
    // moved (the yaws, from the normals, are the same), their own scenes, tables and window. A second floor
    // beyond the memory budget of those models (its boxes reach more layers) is skipped with a warning, not
    // an error: the frame is still detected as without it.
    let second_floor = pre.unseen_floor().filter(|_| options.unseen_floor && !floor_models.is_empty());
    let lower = second_floor.and_then(|floor| {
        let lower = Preprocessed { floor, ..pre.clone() };
        match check_budget_with(&lower, &frame_yaws, floor_models.iter().copied()) {
            Ok(()) => Some(lower),
            Err(e) => {
                log::warn!(
                    "frame '{name}': the floor is not seen, but a second floor at {floor} m is not searched: {e}"
                );
                None
            }
        }
    });
    if let Some(lower) = lower {
        let why = pre.lowest_points_not_floor().map(|why| format!(", {why}")).unwrap_or_default();
        log::info!(
            "frame '{name}': no floor seen (the lowest points at {:.2} m{why}); the floor's models also search a \
             floor at {} m (--unseen-floor)",
            pre.floor,
            lower.floor
        );
        let lower_scenes = window_scenes(&lower, &frame_yaws, floor_models.iter().copied());
        stages.add(Stage::YawGrids, lap());
        let windows = windows_of(&lower_scenes, &floor_models, &|_| Vec::new());
        stages.add(Stage::Window, lap());
        let lower_scene_of = |m: &Model| &lower_scenes[&m.window.scene_key()];
        let mut lower_engines = FastEngines::new();
        let lower_detections = detect_windows(
            name,
            &lower,
            &floor_models,
            &windows,
            lower_scene_of,
            backend,
            options,
            &mut lower_engines,
            stages,
        )?;
        lap();
        stages.tables_thread_s += lower_engines.table_thread_seconds();
        detections = merge_floors(detections, lower_detections, options);
        stages.add(Stage::Select, lap());
    }
    if !surface_models.is_empty() {
        // Each surface model searches the surfaces of its own supporters' detections.
        let surfaces_of =
            |model: &Model| detected_surfaces(&detections, models, options.support_min_score, model.window.supporters);
        let windows = windows_of(&scenes, &surface_models, &surfaces_of);
        stages.add(Stage::Window, lap());
        detections.extend(detect_windows(
            name,
            &pre,
            &surface_models,
            &windows,
            scene_of,
            backend,
            options,
            &mut engines,
            stages,
        )?);
        lap();
    }
    stages.tables_thread_s += engines.table_thread_seconds();
    calibrate(&mut detections, models);
    stages.add(Stage::Nms, lap());
    if options.cross_scores {
        cross_scores(&pre, models, &mut detections, backend);
        stages.add(Stage::CrossScores, lap());
    }
    backend.end_frame();
    Ok(FrameDetections { frame: name.to_string(), detections })
}

/// Sets the [`Detection::cross_scores`] of every detection of [`CROSS_SCORE_CATEGORIES`](crate::category::CROSS_SCORE_CATEGORIES): the raw score
/// `w·φ + bias` of each of `models` of those categories on the detection's own box (our addition, read by
/// the context cascade's feature set v7, `crate::cascade`): whether the box looks more like a table or
/// like a desk to the two models — the first stage's diagnosis finds most of the high-scoring false
/// positives of the large categories on objects of another one, and each model only ever scores boxes of
/// its own sizes. Choices:
/// * The **exact** feature path, whatever the model's own path: a detection's box — voted, so neither on a
///   model's lattice nor of its sizes — is no hypothesis of the fast path's tables, and a frame has only a
///   few hundred such boxes. The box's own model scores it too (its exact-path score, next to the
///   fast-path `raw_score`). On `backend` ([`Backend::box_scores`], since 2026-12-06): the exact kernel
///   where the GPU's kernels run, the CPU's exact path elsewhere (before, the CPU on every backend) — the
///   two within 1e-5 of Σ|wᵢφᵢ| of each other.
/// * The **cuboid** weights alone: a model with latent support surfaces (the table) is scored without its
///   surface part.
/// * Models of other categories are not used; a category of [`CROSS_SCORE_CATEGORIES`](crate::category::CROSS_SCORE_CATEGORIES) without a model in
///   `models` is missing from the maps (the cascade's v7 refuses such detections).
///
/// Each box's score is computed on its own, so the scores are the same on any number of threads.
pub fn cross_scores(pre: &Preprocessed, models: &[Model], detections: &mut [Detection], backend: Backend) {
    let scorers: Vec<&Model> = models.iter().filter(|m| is_cross_score_category(&m.category)).collect();
    let chosen: Vec<usize> =
        (0..detections.len()).filter(|&i| is_cross_score_category(&detections[i].category)).collect();
    if scorers.is_empty() || chosen.is_empty() {
        return;
    }
    // One yaw grid per distinct yaw of the chosen boxes, in ascending order.
    let mut yaws: Vec<f32> = chosen.iter().map(|&i| detections[i].yaw).collect();
    yaws.sort_by(f32::total_cmp);
    yaws.dedup_by(|a, b| a.to_bits() == b.to_bits());
    let scene = FeatureScene::new(pre.clone(), &yaws, DEFAULT_STEP);
    let hypotheses: Vec<Hypothesis> = chosen
        .iter()
        .map(|&i| {
            let d = &detections[i];
            let yaw_index = yaws.binary_search_by(|y| y.total_cmp(&d.yaw)).expect("every chosen yaw has a grid");
            box_hypothesis(&scene, yaw_index, &d.cuboid())
        })
        .collect();
    // Models that share a feature layout are scored in one pass: each box's features are computed once and
    // dotted with every weight vector (the shipped eleven share one layout).
    let mut per_model: Vec<Vec<f32>> = vec![Vec::new(); scorers.len()];
    let mut done = vec![false; scorers.len()];
    for first in 0..scorers.len() {
        if done[first] {
            continue;
        }
        let group: Vec<usize> =
            (first..scorers.len()).filter(|&m| scorers[m].layout == scorers[first].layout).collect();
        let weights: Vec<Vec<f32>> = group.iter().map(|&m| scorers[m].weights.clone()).collect();
        let scores = backend.box_scores(&scene, &scorers[first].layout, &hypotheses, &weights);
        for (w, &m) in group.iter().enumerate() {
            per_model[m] = (0..hypotheses.len()).map(|h| scores[h * group.len() + w] + scorers[m].bias).collect();
            done[m] = true;
        }
    }
    for (h, &i) in chosen.iter().enumerate() {
        let map = scorers.iter().zip(&per_model).map(|(m, scores)| (m.category.clone(), scores[h])).collect();
        detections[i].cross_scores = Some(map);
    }
}

/// The cuboid `c` as a hypothesis of `scene`'s yaw grid `yaw_index` (whose yaw must be `c`'s): its centre
/// rotated into the grid's (s, t) frame, its bottom, its size ([`Hypothesis::cuboid`] inverted).
pub fn box_hypothesis(scene: &FeatureScene, yaw_index: usize, c: &Cuboid) -> Hypothesis {
    let grid = &scene.yaws[yaw_index];
    let [s, t] = rotate(&c.centre, grid.sin, grid.cos);
    Hypothesis {
        yaw_index: yaw_index as u16,
        size_index: 0,
        centre: glam::Vec2::new(s, t),
        bottom: c.centre.z - 0.5 * c.size.z,
        size: c.size,
        points_inside: 0,
    }
}

/// Default of [`DetectOptions::support_min_score`].
pub const DEFAULT_SUPPORT_MIN_SCORE: f32 = 0.1;

/// The support surfaces that a surface model searches: those of the `detections` of its `supporters`
/// (a set of [`SURFACE_CATEGORIES`], the model's `window.supporters`) with a surface height whose
/// calibrated probability (its model's calibration; the raw score for a model without one) is at least
/// `min_score`.
pub fn detected_surfaces(
    detections: &[Detection],
    models: &[Model],
    min_score: f32,
    supporters: SurfaceCategories,
) -> Vec<SupportSurface> {
    detections
        .iter()
        .filter(|d| supporters.contains(&d.category))
        .filter_map(|d| {
            let model = models.iter().find(|m| m.category == d.category)?;
            let score = model.calibration.as_ref().map_or(d.score, |c| c.probability(d.score));
            let z = d.surface_z.filter(|_| score >= min_score)?;
            Some(SupportSurface { object: d.cuboid(), z })
        })
        .collect()
}

/// Scores `windows[m]` with `models[m]` (all together: one GPU submission per batch), keeps each model's
/// hypotheses at or above its threshold, runs NMS and measures the survivors' support surfaces; the
/// scores are still raw (see [`calibrate`]).
#[allow(clippy::too_many_arguments)]
fn detect_windows<'a>(
    name: &str,
    pre: &Preprocessed,
    models: &[&Model],
    windows: &[HypothesisSet],
    scene_of: impl Fn(&Model) -> &'a FeatureScene,
    backend: Backend,
    options: &DetectOptions,
    engines: &mut FastEngines<'a>,
    stages: &mut DetectStages,
) -> Result<Vec<Detection>> {
    let mut clock = Stopwatch::start();
    let mut lap = || clock.lap();
    let model_scenes: Vec<&FeatureScene> = models.iter().map(|m| scene_of(m)).collect();
    if models.iter().any(|m| m.features.path == FeaturePath::Fast) {
        for (model, scene) in models.iter().zip(&model_scenes) {
            if model.features.path == FeaturePath::Fast {
                engines.get(scene, model);
            }
        }
        stages.add(Stage::Lattices, lap());
    }
    let all_hypotheses: Vec<&[Hypothesis]> = windows.iter().map(|w| w.hypotheses.as_slice()).collect();
    let all_scores = score_models(&model_scenes, models, &all_hypotheses, backend, engines)?;
    stages.add(Stage::Score, lap());
    // Each model's candidates, models in parallel, gathered in model order (the first error in model order
    // wins, as in a sequential loop).
    stages.hypotheses += all_hypotheses.iter().map(|h| h.len()).sum::<usize>();
    for (model, hypotheses) in models.iter().zip(&all_hypotheses) {
        if let Some(index) = category_index(&model.category) {
            stages.hypotheses_per_category[index] += hypotheses.len();
        }
    }
    let per_model: Vec<Result<Vec<Detection>>> = models
        .par_iter()
        .zip(&model_scenes)
        .zip(&all_hypotheses)
        .zip(all_scores)
        .map(|(((model, scene), hypotheses), (scores, slices))| {
            model_detections(name, model, scene, hypotheses, &scores, slices.as_deref(), options)
        })
        .collect();
    let mut detections = Vec::new();
    for model_detections in per_model {
        detections.extend(model_detections?);
    }
    // As `nms_detections` orders its survivors: by score, best first, a stable sort over the categories in
    // model order.
    detections.sort_by(|a, b| b.score.total_cmp(&a.score));
    stages.add(Stage::Select, lap());
    // The survivors' surfaces (a few per category; every point visited): for a surface category measured
    // from the points alone, which finds the top — a latent slice need not be the top, only help the score
    // (on the 1 500-frame selection set, true positives' surfaces within 5 cm of the top: 52.5 % by the
    // latent table's slices, 94.7 % measured for the cuboid table's; README, "Detections format") —, else
    // measured in a latent model's chosen slice.
    detections.par_iter_mut().for_each(|d| {
        let cuboid = d.cuboid();
        let measured = SURFACE_CATEGORIES
            .contains(&d.category.as_str())
            .then(|| category_surface(pre, &cuboid, &d.category))
            .flatten();
        let surface = measured.or_else(|| {
            d.latent_slice.map(|h| (refined_surface_height(pre, &cuboid, h as usize), SurfaceSource::LatentSlice))
        });
        (d.surface_z, d.surface_source) = surface.unzip();
    });
    stages.add(Stage::Nms, lap());
    Ok(detections)
}

/// One model's detections: its hypotheses scoring at or above its threshold, best first (ties in hypothesis
/// order), at most `options.candidates` of them, through greedy 3D NMS (`options.nms_iou`, at most
/// `options.max_per_category` kept), with raw scores: the boxes that
/// [`nms_detections`](crate::nms::nms_detections) keeps of all the candidates, but a candidate's box is made
/// only when the NMS visits it ([`suppress_in_order`]), which stops once the category is full — a model may
/// have 10⁵ candidates above its threshold.
fn model_detections(
    name: &str,
    model: &Model,
    scene: &FeatureScene,
    hypotheses: &[Hypothesis],
    scores: &[f32],
    slices: Option<&[u8]>,
    options: &DetectOptions,
) -> Result<Vec<Detection>> {
    if let Some(n) = scores.iter().position(|s| !s.is_finite()) {
        return Err(Error::Input(format!(
            "frame '{name}': the '{}' model gives hypothesis {n} the score {} (weights or features out of range)",
            model.category, scores[n]
        )));
    }
    let threshold = options.threshold(model)?;
    let mut order: Vec<usize> = (0..hypotheses.len()).filter(|&n| scores[n] >= threshold).collect();
    let by_score = |a: &usize, b: &usize| scores[*b].total_cmp(&scores[*a]).then(a.cmp(b));
    if let Some(limit) = options.candidates.filter(|&k| order.len() > k) {
        order.select_nth_unstable_by(limit - 1, by_score);
        order.truncate(limit);
    }
    order.sort_by(by_score);
    let detection = |n: usize| {
        let mut detection = Detection::new(&model.category, &hypotheses[n].cuboid(scene), scores[n]);
        if let Some(slices) = slices {
            detection.latent_slice = Some(slices[n]);
        }
        detection
    };
    let nms =
        NmsOptions { iou_threshold: options.nms_iou, max_detections: Some(options.max_per_category), top_k: None };
    // The hypothesis's cuboid is the detection's (`Detection::cuboid` stores and returns its fields), the box
    // `nms_detections` compares; no detection is made for a candidate the NMS drops.
    let kept = suppress_in_order(order.iter().copied(), |n| hypotheses[n].cuboid(scene), &nms);
    let mut detections: Vec<Detection> = kept.iter().map(|&n| detection(n)).collect();
    if let (Some(iou), false) = (options.box_voting, kept.is_empty()) {
        let slope = model.calibration.as_ref().map_or(1.0, |c| c.a as f32);
        let vote_options = VoteOptions { iou, slope, min_weight: VOTE_MIN_WEIGHT };
        // Every hypothesis may vote, whatever the cut (`vote` skips those too light for every kept box): a
        // kept box is then the same under every cut that keeps it (the cut property of
        // `DetectOptions::threshold`). In hypothesis order, the order of the sums: no sort.
        let voters = 0..hypotheses.len();
        let voted = vote(&kept, voters, |n| hypotheses[n].cuboid(scene), |n| scores[n], &vote_options);
        for (d, cuboid) in detections.iter_mut().zip(voted) {
            d.centre = cuboid.centre.to_array();
            d.size = cuboid.size.to_array();
        }
        // Voting can move two kept boxes onto one object — a weak kept box beside a strong one takes the
        // strong one's boxes as voters, whose odds outweigh its own —: the NMS again over the voted boxes,
        // in the same order and at the same IoU (since 2026-12-05; README, "Box voting", "The NMS after the
        // vote"). A box it would drop is demoted by `REVOTE_DEMOTION` instead (since 2026-12-06, "Demoted,
        // not dropped"): often it is the one that hits the object, and the better box beside it is poorly
        // placed; demoted, it ranks below the box that took its place (its odds e⁶ ≈ 400 times lower) and
        // counts only where nothing scores better. A demoted box below the cut is dropped, so a greedy
        // visit in score order keeps, above any cut, the same boxes with the same scores: the cut property holds.
        let survivors = suppress_in_order(
            0..detections.len(),
            |i| detections[i].cuboid(),
            &NmsOptions { max_detections: None, ..nms },
        );
        let mut survives = vec![false; detections.len()];
        for i in survivors {
            survives[i] = true;
        }
        let demotion = REVOTE_DEMOTION / slope;
        for (d, &kept) in detections.iter_mut().zip(&survives) {
            if !kept {
                d.score -= demotion;
            }
        }
        detections.retain(|d| d.score >= threshold);
        // As `nms_detections` orders its survivors (a stable sort: ties keep the visiting order).
        detections.sort_by(|a, b| b.score.total_cmp(&a.score));
    }
    Ok(detections)
}

/// The detections of the floor's models on the two floors of a frame whose floor is not seen
/// ([`DetectOptions::unseen_floor`]): all of them by score, best first (raw scores, one model's on both
/// floors; ties: the lowest points' floor first, then each list's order), each box dropped when a kept box
/// of its category *from the other floor* overlaps it by more than `options.nms_iou` — the greedy NMS of
/// each model's detections (`model_detections`) between the floors, so of two boxes of one object on the
/// two floors the better one stays, while within a floor its own NMS and box voting have decided (a
/// demoted box stays demoted, as on one floor) —, at most `options.max_per_category` per category.
pub fn merge_floors(seen: Vec<Detection>, lower: Vec<Detection>, options: &DetectOptions) -> Vec<Detection> {
    let mut all: Vec<(bool, Detection)> =
        seen.into_iter().map(|d| (false, d)).chain(lower.into_iter().map(|d| (true, d))).collect();
    all.sort_by(|a, b| b.1.score.total_cmp(&a.1.score));
    let mut kept: Vec<(bool, Detection, Cuboid)> = Vec::with_capacity(all.len());
    for (on_lower, d) in all {
        let cuboid = d.cuboid();
        let same = || kept.iter().filter(|(_, k, _)| k.category == d.category);
        let full = same().count() >= options.max_per_category;
        let overlapped = same().any(|(floor, _, k)| *floor != on_lower && iou_3d(&cuboid, k) > options.nms_iou);
        if !full && !overlapped {
            kept.push((on_lower, d, cuboid));
        }
    }
    kept.into_iter().map(|(_, d, _)| d).collect()
}

/// Replaces each detection's raw score by its model's calibrated probability (keeping the raw score in
/// `raw_score`) where the model has a calibration, then sorts all detections by score, best first (a
/// stable sort: ties keep their order). The calibration is monotone, so the order within a category and
/// the NMS result are unchanged.
pub fn calibrate(detections: &mut [Detection], models: &[Model]) {
    for d in detections.iter_mut() {
        if let Some(calibration) = models.iter().find(|m| m.category == d.category).and_then(|m| m.calibration.as_ref())
        {
            d.raw_score = Some(d.score);
            d.score = calibration.probability(d.score);
        }
    }
    detections.sort_by(|a, b| b.score.total_cmp(&a.score));
}

/// Why the first-stage detections of `categories` cannot be replaced on their own (by
/// [`replace_categories`]) among those of `models`: a surface model ([`Support::uses_surfaces`]) searches
/// the surfaces of its supporters' detections, so when one of its supporters is replaced and it is not,
/// its kept detections stand on surfaces that are no longer there. `None` when they can; the message
/// names the dependent categories to replace as well.
pub fn replacement_problem(categories: &[String], models: &[Model]) -> Option<String> {
    let mut problems = Vec::new();
    for model in models.iter().filter(|m| m.window.support.uses_surfaces()) {
        if categories.contains(&model.category) {
            continue;
        }
        let replaced: Vec<&String> = categories.iter().filter(|c| model.window.supporters.contains(c)).collect();
        if !replaced.is_empty() {
            let names: Vec<&str> = replaced.iter().map(|c| c.as_str()).collect();
            problems.push(format!("{} (searched on the surfaces of {})", model.category, names.join(", ")));
        }
    }
    (!problems.is_empty()).then(|| {
        format!(
            "the detections of {} depend on the replaced categories' detections: detect those categories \
             again too and replace them with the others",
            problems.join("; ")
        )
    })
}

/// One frame's first-stage detections (from `detect` with `models`, no cascade) with those of
/// `categories` replaced by those of `update` (the same frame detected again, with the same options, with
/// new models of `categories`; its detections of other categories are ignored), in the order `detect` with
/// all the new models writes them: detect lists the floor (and free-window) models' detections sorted by
/// raw score, ties in category order, then the surface models' likewise, and finally sorts all of them
/// by calibrated score, a stable sort ([`calibrate`]); so the merged list is sorted by (calibrated score
/// descending, floor before surface models, raw score descending, category), stably, each category's
/// detections keeping their order. A category without a model in `models` counts as a floor model
/// (the caller checks that every category has one). Chosen so that re-detecting one category of a large
/// set and merging it gives, detection for detection, what detecting the whole set again would give
/// (`tests/merge_detections.rs` checks it against a full detection), at the cost of one model's detection.
/// It requires [`replacement_problem`] to be `None`.
///
/// The [`Detection::cross_scores`] hold every cross-category model's score of each box, so replacing a
/// model of [`CROSS_SCORE_CATEGORIES`](crate::category::CROSS_SCORE_CATEGORIES) makes those of the kept detections stale (the old model's), and
/// those of the update may miss the models it was not run with: then the merged detections carry none
/// (a cascade with a cross stage refuses them; [`cross_scores`] on the frame computes them again, as
/// `merge-detections --data` does). Replacing only other categories keeps them, as detecting everything
/// again would give them.
pub fn replace_categories(
    base: &[Detection],
    update: &[Detection],
    categories: &[String],
    models: &[Model],
) -> Vec<Detection> {
    let replaced = |d: &&Detection| categories.contains(&d.category);
    let mut merged: Vec<Detection> =
        base.iter().filter(|d| !replaced(d)).chain(update.iter().filter(replaced)).cloned().collect();
    let on_surfaces = |d: &Detection| {
        models.iter().find(|m| m.category == d.category).is_some_and(|m| m.window.support.uses_surfaces())
    };
    merged.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then(on_surfaces(a).cmp(&on_surfaces(b)))
            .then(b.raw_score.unwrap_or(b.score).total_cmp(&a.raw_score.unwrap_or(a.score)))
            .then(a.category.cmp(&b.category))
    });
    if categories.iter().any(|c| is_cross_score_category(c)) {
        for d in &mut merged {
            d.cross_scores = None;
        }
    }
    merged
}

/// 3D IoU above which a lower-scoring detection of another category is taken for the same piece of
/// furniture by [`overlay_selection`].
pub const CROSS_CATEGORY_IOU: f32 = 0.4;

/// `detect --overlay-top`'s default: the most boxes an overlay draws (a picture with more is unreadable).
pub const DEFAULT_OVERLAY_TOP: usize = 8;

/// `detect --overlay-min-score`'s default: the overlay draws a calibrated detection only when it is more
/// likely right than wrong. Chosen by that meaning of a calibrated probability, not fitted to any frames;
/// the README ("Detection", the overlay) gives the precision and the boxes per frame it leads to.
pub const DEFAULT_OVERLAY_MIN_PROBABILITY: f32 = 0.5;

/// The 3D IoU from which the overlay skips a detection overlapping an already chosen one **of its own
/// category** ([`overlay_selection`]) where the detection's NMS IoU is not known (`eval --diagnose`): the
/// NMS's default, [`DEFAULT_NMS_IOU`] — a box the NMS would have dropped, or one exactly at its IoU (the NMS
/// keeps that one: it drops above the threshold, the overlay skips from it); `detect` passes its own
/// `--nms-iou`. Since 2026-12-06 the NMS run again after box voting demotes such boxes instead of dropping
/// them (for the AP, "Demoted, not dropped"), and the context cascade can lift one back above its keeper,
/// so one object could be drawn twice (on the selection set, seeds 2500–2506, one of the 388 drawn boxes).
pub const OVERLAY_SAME_CATEGORY_IOU: f32 = DEFAULT_NMS_IOU;

/// The detections an overlay draws: in score order over all categories (calibrated scores compare across
/// categories), each skipped when it overlaps an already chosen detection of another category with 3D
/// IoU ≥ [`CROSS_CATEGORY_IOU`] (one object is not drawn as two categories) or one of its own category
/// with 3D IoU ≥ `same_category_iou` (nor twice: the NMS's IoU, [`OVERLAY_SAME_CATEGORY_IOU`] by
/// default), until `count` are chosen. A calibrated detection (one with a `raw_score`, whose `score` is a
/// probability) whose score is below `min_probability` is not drawn; an uncalibrated one's score is raw,
/// on no common scale, so the floor does not apply to it (0 draws the best `count` whatever they are).
pub fn overlay_selection(
    detections: &[Detection],
    count: usize,
    min_probability: f32,
    same_category_iou: f32,
) -> Vec<Detection> {
    let mut order: Vec<&Detection> = detections.iter().collect();
    order.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut chosen: Vec<Detection> = Vec::new();
    for d in order {
        if chosen.len() >= count {
            break;
        }
        if d.raw_score.is_some() && d.score < min_probability {
            continue;
        }
        let cuboid = d.cuboid();
        let clash = chosen.iter().any(|c| {
            let limit = if c.category == d.category { same_category_iou } else { CROSS_CATEGORY_IOU };
            crate::geometry::iou_3d(&c.cuboid(), &cuboid) >= limit
        });
        if !clash {
            chosen.push(d.clone());
        }
    }
    chosen
}

/// The RGB image with each detection's cuboid projected in its category's colour (front face thick) and a
/// "category score" label at the top of its projection; the best detection is drawn last (on top).
pub fn overlay(frame: &Frame, detections: &FrameDetections) -> RgbImage {
    let mut image = frame.rgb.clone();
    let camera = Camera::new(frame.intrinsics(), frame.rtilt());
    let scale = if image.width() >= 480 { 2 } else { 1 };
    let mut order: Vec<&Detection> = detections.detections.iter().collect();
    order.sort_by(|a, b| a.score.total_cmp(&b.score));
    for d in &order {
        let cuboid = d.cuboid();
        if let Some(z) = d.surface_z {
            // The inferred support surface: the footprint at its height, shaded in the category's colour.
            let corners: Option<Vec<_>> =
                cuboid.corners()[..4].iter().map(|c| camera.project(Vec3::new(c.x, c.y, z))).collect();
            if let Some(corners) = corners {
                shade_convex_polygon(&mut image, &corners, category_colour(&d.category), 0.4);
            }
        }
        draw_cuboid_with(&mut image, &camera, &cuboid, category_colour(&d.category), scale, 2 * scale + 1);
    }
    // Labels, best first, each at the top-left of its box's projection and moved down or up where a
    // better one's label is in the way (`place_labels`); drawn worst first, so that any overlap left shows
    // the better label on top.
    let mut labels: Vec<(LabelBox, String, Colour)> = Vec::new();
    for d in order.iter().rev() {
        let cuboid = d.cuboid();
        let projected: Vec<_> = cuboid.corners().iter().filter_map(|&c| camera.project(c)).collect();
        if projected.is_empty() {
            continue;
        }
        let x = projected.iter().map(|p| p.x).fold(f32::INFINITY, f32::min);
        let y = projected.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
        let text = format!("{} {:.2}", d.category, d.score);
        let (width, height) = label_size(&text, scale);
        let x = (x as i64).clamp(0, image.width() as i64 - 1);
        let y = (y as i64 - 10 * scale as i64).clamp(0, (image.height() as i64 - height as i64).max(0));
        labels.push((LabelBox { x, y, width, height }, text, category_colour(&d.category)));
    }
    let wanted: Vec<LabelBox> = labels.iter().map(|l| l.0).collect();
    let places = place_labels(&wanted, image.height());
    for (place, (_, text, colour)) in places.iter().zip(&labels).rev() {
        draw_label(&mut image, place.x, place.y, text, contrasting(*colour), *colour, scale);
    }
    image
}

/// Relative score difference (over max(|score|, 1)) within which two paths' detections count as the same
/// (`cog-gpu bench --detect --both`, [`compare_paths`]).
pub const PATH_SCORE_TOLERANCE: f32 = 1e-5;
/// Centre, size and yaw difference within which two paths' boxes count as the same (metres, radians).
pub const PATH_BOX_TOLERANCE: f32 = 1e-4;

/// How two backends' detections of the same frames compare ([`compare_paths`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PathAgreement {
    pub frames_compared: usize,
    /// Frames with a detection matched by neither rule below, or a different number of detections.
    pub frames_different: usize,
    /// The largest relative score difference (over max(|score|, 1)) of the matched detections.
    pub max_relative_score_difference: f32,
    /// Detections matched as near-tie alternates (see [`compare_paths`]), over all frames.
    pub near_tie_alternates: usize,
    /// No frame different.
    pub same: bool,
}

/// Compares two backends' detections, frame by frame (`a[f]` with `b[f]`). Each frame's detections are put
/// in one canonical order (category, centre, yaw, size): the backends order them by score, and two scores
/// within rounding of each other may come in either order. Then the `k`-th detections must be of the same
/// category, with scores within [`PATH_SCORE_TOLERANCE`], and either
/// - the same box: centre, size and yaw within [`PATH_BOX_TOLERANCE`]; or
/// - **near-tie alternates**: the same centre and yaw but another size. The GPU and the CPU sum a score's
///   terms in different orders (~1e-7 relative apart), so where two sizes at one centre score within that
///   of each other, the NMS may keep one on one backend and the other on the other (measured on an H200:
///   one door of 551 detections on 4 frames, depths 0.093 and 0.096 m, raw scores −0.0386296 both); no
///   order of summation shared by both backends removes such ties. They are counted, not failed.
pub fn compare_paths(a: &[Vec<Detection>], b: &[Vec<Detection>]) -> PathAgreement {
    let close = |u: &[f32], v: &[f32]| u.iter().zip(v).all(|(s, t)| (s - t).abs() <= PATH_BOX_TOLERANCE);
    let canonical = |frame: &[Detection]| -> Vec<Detection> {
        let mut sorted = frame.to_vec();
        sorted.sort_by(|p, q| {
            let key = |d: &Detection| [d.centre[0], d.centre[1], d.centre[2], d.yaw, d.size[0], d.size[1], d.size[2]];
            p.category.cmp(&q.category).then_with(|| {
                key(p)
                    .iter()
                    .zip(key(q))
                    .map(|(s, t)| s.total_cmp(&t))
                    .find(|o| o.is_ne())
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
        });
        sorted
    };
    let mut agreement = PathAgreement { frames_compared: a.len().min(b.len()), ..Default::default() };
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (canonical(x), canonical(y));
        let mut same = x.len() == y.len();
        for (p, q) in x.iter().zip(&y) {
            let difference = (p.score - q.score).abs() / p.score.abs().max(1.0);
            agreement.max_relative_score_difference = agreement.max_relative_score_difference.max(difference);
            let placed = p.category == q.category
                && close(&p.centre, &q.centre)
                && close(&[p.yaw], &[q.yaw])
                && difference <= PATH_SCORE_TOLERANCE;
            if placed && !close(&p.size, &q.size) {
                agreement.near_tie_alternates += 1;
            }
            same &= placed;
        }
        if !same {
            agreement.frames_different += 1;
        }
    }
    agreement.same = agreement.frames_different == 0;
    agreement
}
