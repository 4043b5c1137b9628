//! Diagnosis of where a detector loses average precision (`cog-gpu eval --diagnose`).
//!
//! Eight numbers, each isolating one stage of the pipeline or one kind of error:
//!
//! 1. **Window recall ceiling** ([`best_window_ious`], [`frame_window_best_ious`], [`WindowRecall`]): for
//!    each ground-truth box, the largest 3D IoU ([`crate::geometry::iou_3d`]) of any hypothesis the model's
//!    sliding window enumerates on that frame — exactly the hypotheses [`crate::detect`] scores (same
//!    scene step, sizes and `min_points`). A box no hypothesis overlaps by the evaluation's IoU cannot be
//!    found whatever the weights are.
//! 2. **In-frame ranking** ([`in_frame_ranking`]): over the frames that contain the category and have at
//!    least one detection of it, how often the frame's best-scoring detection of the category is correct
//!    (IoU ≥ the threshold with some ground-truth box of the category in that frame). It asks whether the
//!    scores order the hypotheses of one frame well.
//! 3. **Cross-frame ranking** ([`rank_average_precision`]): the AP when each detection's score is replaced
//!    by its rank within its frame and category. Comparing it with the AP tells whether the raw scores
//!    are comparable between frames: if the rank AP is higher, the scores of different frames are on
//!    different scales (calibration loses AP).
//! 4. **Overlay precision** ([`overlay_precision`]): in each frame, the best k detections (k = the frame's
//!    number of ground-truth boxes of the evaluated categories) over all evaluated categories, chosen by the
//!    overlay picture's rule ([`crate::detect::overlay_selection`]: by score, skipping a box that overlaps a
//!    better one of another category) but without its probability floor; the fraction of them that are
//!    correct. And the same for the boxes `detect`'s overlay draws ([`OverlayRule::Drawn`]: at most its
//!    `--overlay-top`, none below its `--overlay-min-score`), with the frames where it draws none.
//! 5. **False-positive kinds** ([`false_positive_kinds`]): the highest-scoring false positives (as many as
//!    the category has ground-truth boxes) split into duplicates, poor localisation, confusion with
//!    another category's object, and background in frames with or without the category — which of them
//!    a better detector must push down.
//! 6. **What each kind costs** ([`oracle_aps`]): the AP with every false positive of a kind removed (an
//!    oracle), and with all of them — the AP a perfect rescoring of the same detections would reach.
//! 7. **What became of each object** ([`object_outcomes`], [`ObjectSummary`]): per ground-truth box, the
//!    true positive that found it and how far down the category's ranking (the precision there: found
//!    ahead of the false positives or behind them), or, when missed, whether a detection of the category
//!    came near it and whether another category's detection sits on it — so that the recall the AP lacks
//!    can be traced to the objects themselves (their size, their distance from the camera, the share of
//!    their volume in the picture: [`crate::geometry::in_view_share`]).
//! 8. **Reliability of the scores as probabilities** ([`reliability`]): every detection of the evaluated
//!    categories labelled by the benchmark's matching (the AP's true positives), put in ten bins of its
//!    score; per bin how many true positives the scores expect (their sum) and how many there are — a
//!    reliability diagram in numbers — and the expected calibration error. Whether a calibrated `score`
//!    of 0.9 is right nine times in ten.
//!
//! Detections are read through [`Detection::score`] only, so other fields a detections file may carry do
//! not change the diagnosis.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::detect::overlay_selection;
use crate::eval::{
    average_precision, category_truth, interpolated_ap, scored_boxes, true_positives_in_input_order, Detection,
    PrecisionRecall, ScoredBox,
};
use crate::features::hypotheses::{window, FrameYaws, Support, WindowOptions};
use crate::features::surface::annotated_surfaces_by_category;
use crate::features::{FeatureScene, Hypothesis, Preprocessed};
use crate::frame::Object;
use crate::geometry::{iou_3d, Cuboid};
use crate::model::{window_scenes, Model};

// ---------------------------------------------------------------------------------------------------------
// 1. Window recall ceiling

/// For each of `truths`, the largest 3D IoU over `hypotheses` (of `scene`); 0 when none overlaps.
///
/// For speed, a hypothesis is skipped for a box when their footprints cannot overlap: the distance between
/// their centres on the ground plane exceeds the sum of their footprints' circumscribed radii (half
/// diagonals); and when it cannot beat the box's best so far: the IoU of two boxes is at most
/// `min(volume) / max(volume)`. Both tests are exact bounds, so the result equals the brute-force maximum.
pub fn best_window_ious(scene: &FeatureScene, hypotheses: &[Hypothesis], truths: &[Cuboid]) -> Vec<f32> {
    let mut best = vec![0.0f32; truths.len()];
    if truths.is_empty() {
        return best;
    }
    let radius = |c: &Cuboid| 0.5 * (c.size.x * c.size.x + c.size.y * c.size.y).sqrt();
    let truth_radius: Vec<f32> = truths.iter().map(radius).collect();
    let truth_volume: Vec<f32> = truths.iter().map(Cuboid::volume).collect();
    for hypothesis in hypotheses {
        let cuboid = hypothesis.cuboid(scene);
        let (r, v) = (radius(&cuboid), cuboid.volume());
        for (g, truth) in truths.iter().enumerate() {
            let reach = r + truth_radius[g];
            if cuboid.centre.truncate().distance_squared(truth.centre.truncate()) > reach * reach {
                continue;
            }
            if v.min(truth_volume[g]) / v.max(truth_volume[g]) <= best[g] {
                continue;
            }
            best[g] = best[g].max(iou_3d(&cuboid, truth));
        }
    }
    best
}

/// The window recall of one preprocessed frame: for each model whose category has ground truth in
/// `objects`, the best window IoU ([`best_window_ious`]) of each of those boxes, in `objects` order.
///
/// The window is the one [`crate::detect::detect_preprocessed`] enumerates: one [`FeatureScene`] per
/// distinct `(model.window.step, model.window.yaw_anchor)` (shared by the models with both) with the
/// frame's [`FrameYaws`], and [`sliding_window`](crate::features::hypotheses::sliding_window) with the model's sizes and `min_points` — for a model
/// searched on support surfaces, its window on the surfaces of the frame's **annotated** objects of its
/// supporters (`window.supporters`; `annotated_surfaces_by_category`: the window's ceiling given perfect
/// large-object detections; detection searches the surfaces of its own detections). Categories
/// without a model, or without ground truth in the frame, are absent from the result; no scene is built
/// when no model has ground truth. With `unseen_floor` (detection's default,
/// [`crate::detect::DetectOptions::unseen_floor`]), where the frame's floor is not seen
/// ([`Preprocessed::unseen_floor`]) the models that do not search surfaces search the second floor too, as
/// detection does, and each box's best IoU is the better of the two floors'.
pub fn frame_window_best_ious(
    pre: &Preprocessed,
    models: &[Model],
    objects: &[Object],
    unseen_floor: bool,
) -> BTreeMap<String, Vec<f32>> {
    let wanted: Vec<&Model> = models.iter().filter(|m| objects.iter().any(|o| o.category == m.category)).collect();
    let mut out = floor_window_best_ious(pre, &wanted, objects);
    if let Some(floor) = pre.unseen_floor().filter(|_| unseen_floor) {
        let lower = Preprocessed { floor, ..pre.clone() };
        // As detection: a second floor beyond the memory budget of the models that search it is not searched.
        let searching = models.iter().filter(|m| !m.window.support.uses_surfaces());
        if let Err(e) = crate::detect::check_budget(&lower, searching) {
            log::warn!("the window recall's second floor at {floor} m is not searched: {e}");
            return out;
        }
        let floor_models: Vec<&Model> = wanted.into_iter().filter(|m| !m.window.support.uses_surfaces()).collect();
        for (category, best) in floor_window_best_ious(&lower, &floor_models, objects) {
            let seen = out.get_mut(&category).expect("the same categories on both floors");
            for (a, b) in seen.iter_mut().zip(best) {
                *a = a.max(b);
            }
        }
    }
    out
}

/// [`frame_window_best_ious`] on `pre`'s floor alone, for the models `wanted` (each with ground truth).
fn floor_window_best_ious(pre: &Preprocessed, wanted: &[&Model], objects: &[Object]) -> BTreeMap<String, Vec<f32>> {
    let truths_of = |category: &str| -> Vec<Cuboid> {
        objects.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect()
    };
    let frame_yaws = FrameYaws::new(pre);
    let scenes = window_scenes(pre, &frame_yaws, wanted.iter().copied());
    let mut out = BTreeMap::new();
    for &model in wanted {
        let scene = &scenes[&model.window.scene_key()];
        let options = WindowOptions { sizes: model.sizes(), min_points: model.window.min_points };
        // The ceiling of the surface search given the true supporting furniture: the surfaces of the
        // annotated objects (detection searches those of its detections).
        let surfaces = match model.window.support {
            Support::Surfaces | Support::FloorAndSurfaces => annotated_surfaces_by_category(pre, objects)
                .into_iter()
                .filter(|(c, _)| model.window.supporters.contains(c))
                .map(|(_, s)| s)
                .collect(),
            Support::Floor | Support::Free | Support::Resting => Vec::new(),
        };
        let window = window(model.window.support, scene, &options, &surfaces);
        let truths = truths_of(&model.category);
        out.insert(model.category.clone(), best_window_ious(scene, &window.hypotheses, &truths));
    }
    out
}

/// Summary of the best window IoUs of one category's ground-truth boxes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct WindowRecall {
    /// Number of ground-truth boxes.
    pub boxes: usize,
    /// Fraction of boxes whose best window IoU is ≥ 0.25; `None` without boxes.
    pub recall_25: Option<f32>,
    /// Fraction of boxes whose best window IoU is ≥ 0.5; `None` without boxes.
    pub recall_50: Option<f32>,
    /// Mean of the best window IoUs; `None` without boxes.
    pub mean_best_iou: Option<f32>,
}

impl WindowRecall {
    pub fn from_best_ious(best: &[f32]) -> WindowRecall {
        let n = best.len();
        let fraction = |t: f32| (n > 0).then(|| best.iter().filter(|&&v| v >= t).count() as f32 / n as f32);
        WindowRecall {
            boxes: n,
            recall_25: fraction(0.25),
            recall_50: fraction(0.5),
            mean_best_iou: (n > 0).then(|| (best.iter().map(|&v| v as f64).sum::<f64>() / n as f64) as f32),
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// 2. In-frame ranking

/// The in-frame ranking of one category.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct InFrameRanking {
    /// Frames with at least one ground-truth box of the category.
    pub frames_with_category: usize,
    /// Of those, the frames with at least one detection of the category.
    pub frames_with_detections: usize,
    /// Of those, the frames whose best-scoring detection of the category is a true positive.
    pub best_is_true_positive: usize,
}

impl InFrameRanking {
    /// `best_is_true_positive / frames_with_detections`; `None` when no frame qualifies.
    pub fn fraction(&self) -> Option<f32> {
        (self.frames_with_detections > 0)
            .then(|| self.best_is_true_positive as f32 / self.frames_with_detections as f32)
    }
}

/// The index of the best-scoring detection of `category` in `detections`: highest score, the first in the
/// list among equal scores.
fn best_of(detections: &[Detection], category: &str) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, d) in detections.iter().enumerate().filter(|(_, d)| d.category == category) {
        if best.is_none_or(|b| d.score > detections[b].score) {
            best = Some(i);
        }
    }
    best
}

/// In-frame ranking of `category`: `truth[i]` and `detections[i]` are image `i`'s objects and detections
/// (of any category; a missing `detections[i]` counts as none). Only frames with ground truth of the
/// category and at least one detection of it count; the frame's best detection of the category (ties: the
/// first in its file) is a true positive when its 3D IoU with some ground-truth box of the category in the
/// frame is ≥ `iou_threshold` (one detection per frame, so no matching is involved).
pub fn in_frame_ranking(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
) -> InFrameRanking {
    let mut out = InFrameRanking::default();
    for (image, objects) in truth.iter().enumerate() {
        let truths: Vec<Cuboid> = objects.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect();
        if truths.is_empty() {
            continue;
        }
        out.frames_with_category += 1;
        let dets = detections.get(image).map(Vec::as_slice).unwrap_or(&[]);
        let Some(best) = best_of(dets, category) else { continue };
        out.frames_with_detections += 1;
        let cuboid = dets[best].cuboid();
        if truths.iter().any(|t| iou_3d(&cuboid, t) >= iou_threshold) {
            out.best_is_true_positive += 1;
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------------------
// 3. Cross-frame ranking

/// The detections of `category` in every image, with their rank within the image: 0 for the highest
/// score, ties broken by the order in the image's list. Returned as (image, rank, index in the image's
/// list).
fn in_frame_ranks(detections: &[Vec<Detection>], category: &str) -> Vec<(usize, usize, usize)> {
    let mut out = Vec::new();
    for (image, dets) in detections.iter().enumerate() {
        let mut order: Vec<usize> = (0..dets.len()).filter(|&i| dets[i].category == category).collect();
        // Stable: equal scores keep the list order.
        order.sort_by(|&a, &b| dets[b].score.total_cmp(&dets[a].score));
        out.extend(order.into_iter().enumerate().map(|(rank, i)| (image, rank, i)));
    }
    out
}

/// The "rank AP" of `category`: the AP ([`average_precision`], same matching rules) of the detections
/// ordered by their rank within their frame instead of their score. Order: rank ascending (every frame's
/// best detection first, then every frame's second, ...); between frames at the same rank, the original
/// score descending; then image order and list order. Scores are not rewritten into f32 keys (which would
/// lose ties or precision): the boxes are handed to [`average_precision`] already in this order, all with
/// the same score, and its stable sort keeps that order.
pub fn rank_average_precision(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
) -> PrecisionRecall {
    let mut ranked = in_frame_ranks(detections, category);
    // Stable: equal (rank, score) pairs keep image order (two detections of one image never share a rank).
    ranked
        .sort_by(|a, b| a.1.cmp(&b.1).then_with(|| detections[b.0][b.2].score.total_cmp(&detections[a.0][a.2].score)));
    let boxes: Vec<ScoredBox> = ranked
        .iter()
        .map(|&(image, _, i)| ScoredBox { image, score: 0.0, cuboid: detections[image][i].cuboid() })
        .collect();
    average_precision(&boxes, &category_truth(truth, category), iou_threshold)
}

// ---------------------------------------------------------------------------------------------------------
// 4. Overlay precision

/// The overlay precision over all evaluated categories.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct OverlayPrecision {
    /// Shown detections that are true positives.
    pub true_positives: usize,
    /// Detections shown (per frame at most the rule's count: see [`OverlayRule`]).
    pub shown: usize,
    /// `true_positives / shown`; `None` when nothing is shown.
    pub precision: Option<f32>,
    /// Frames evaluated, and of them those where nothing is shown.
    pub frames: usize,
    pub frames_without_boxes: usize,
    /// What the shown detections that are not true positives are.
    pub false_kinds: FalseKindCounts,
}

/// False boxes counted by kind, by the rules of [`FalsePositiveKinds`] (the first that applies; "duplicate":
/// the box of its category it overlaps at the IoU threshold was taken by a better box): an overlay's false
/// boxes ([`OverlayPrecision::false_kinds`]), and the tally behind [`false_positive_kinds`].
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FalseKindCounts {
    pub duplicate: usize,
    pub localisation: usize,
    pub confusion: usize,
    /// The confusions by the shown box's category and the annotated object's, most frequent first (ties in
    /// name order).
    pub confused: Vec<Confusion>,
    pub background_in_frame: usize,
    pub background_elsewhere: usize,
}

/// `count` shown boxes of category `shown` on annotated objects of category `object`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Confusion {
    pub shown: String,
    pub object: String,
    pub count: usize,
}

impl FalseKindCounts {
    fn add(&mut self, shown: &str, kind: FalsePositiveKind) {
        match kind {
            FalsePositiveKind::Duplicate => self.duplicate += 1,
            FalsePositiveKind::Localisation => self.localisation += 1,
            FalsePositiveKind::Confusion(object) => {
                self.confusion += 1;
                match self.confused.iter_mut().find(|c| c.shown == shown && c.object == object) {
                    Some(c) => c.count += 1,
                    None => self.confused.push(Confusion { shown: shown.into(), object: object.into(), count: 1 }),
                }
            }
            FalsePositiveKind::BackgroundInFrame => self.background_in_frame += 1,
            FalsePositiveKind::BackgroundElsewhere => self.background_elsewhere += 1,
        }
    }

    fn sort(&mut self) {
        self.confused
            .sort_by(|a, b| b.count.cmp(&a.count).then_with(|| (&a.shown, &a.object).cmp(&(&b.shown, &b.object))));
    }
}

/// How many detections a frame's overlay shows, for [`overlay_precision`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OverlayRule {
    /// k = the frame's number of ground-truth boxes of the evaluated categories, whatever the detections'
    /// probabilities (the measure: a frame shows as many boxes as it has objects).
    GroundTruthCount,
    /// What `detect` draws: at most `top`, none of them a calibrated detection below `min_probability`
    /// (`detect --overlay-top`, `--overlay-min-score`).
    Drawn { top: usize, min_probability: f32 },
}

/// Overlay precision: in each image, of its detections of `categories`, those that [`overlay_selection`]
/// picks under `rule` are "shown" (by score, highest first, ties in list order, all categories together,
/// skipping a detection with 3D IoU ≥ [`crate::detect::CROSS_CATEGORY_IOU`] with a better one of another
/// category; [`OverlayRule::GroundTruthCount`]: k of them, k = the image's ground-truth boxes of
/// `categories`). They are matched greedily in that order: a shown detection takes, among the not yet
/// matched ground-truth boxes of its own category in the image, the one with the highest 3D IoU, and is a
/// true positive (and marks that box matched) when that IoU is ≥ `iou_threshold`. (Unlike the benchmark's
/// AP rule, a detection whose best box is taken may still match a second, free box.) `same_category_iou`
/// is [`overlay_selection`]'s: the IoU at which a box gives way to a better one of its own category — the
/// detection's NMS IoU (`detect --nms-iou`; [`crate::detect::OVERLAY_SAME_CATEGORY_IOU`] for `detect`'s default).
/// The shown detections that are not true positives are counted by kind ([`FalseKindCounts`]).
pub fn overlay_precision(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    categories: &[String],
    iou_threshold: f32,
    rule: OverlayRule,
    same_category_iou: f32,
) -> OverlayPrecision {
    let evaluated = |category: &str| categories.iter().any(|c| c == category);
    let mut out = OverlayPrecision { frames: truth.len(), ..OverlayPrecision::default() };
    for (image, objects) in truth.iter().enumerate() {
        let truths: Vec<&Object> = objects.iter().filter(|o| evaluated(&o.category)).collect();
        let dets = detections.get(image).map(Vec::as_slice).unwrap_or(&[]);
        let candidates: Vec<Detection> = dets.iter().filter(|d| evaluated(&d.category)).cloned().collect();
        let order = match rule {
            OverlayRule::GroundTruthCount => overlay_selection(&candidates, truths.len(), 0.0, same_category_iou),
            OverlayRule::Drawn { top, min_probability } => {
                overlay_selection(&candidates, top, min_probability, same_category_iou)
            }
        };
        if order.is_empty() {
            out.frames_without_boxes += 1;
        }
        let mut matched = vec![false; truths.len()];
        for d in &order {
            out.shown += 1;
            let cuboid = d.cuboid();
            let best = truths
                .iter()
                .enumerate()
                .filter(|(g, t)| !matched[*g] && t.category == d.category)
                .map(|(g, t)| (g, iou_3d(&cuboid, &t.cuboid)))
                .fold(None, |best: Option<(usize, f32)>, (g, iou)| match best {
                    Some((_, b)) if b >= iou => best,
                    _ => Some((g, iou)),
                });
            match best {
                Some((g, iou)) if iou >= iou_threshold => {
                    matched[g] = true;
                    out.true_positives += 1;
                }
                _ => {
                    let own: Vec<Cuboid> =
                        truths.iter().filter(|t| t.category == d.category).map(|t| t.cuboid).collect();
                    out.false_kinds
                        .add(&d.category, false_positive_kind(objects, &own, &cuboid, &d.category, iou_threshold));
                }
            }
        }
    }
    out.false_kinds.sort();
    out.precision = (out.shown > 0).then(|| out.true_positives as f32 / out.shown as f32);
    out
}

// ---------------------------------------------------------------------------------------------------------
// 5. What the highest-scoring false positives are

/// IoU from which a false positive counts as touching a ground-truth box (localisation error with a box of
/// its own category, confusion with a box of another), as in Hoiem, Chodpathumwan & Dai, "Diagnosing error
/// in object detectors" (ECCV 2012).
pub const TOUCH_IOU: f32 = 0.1;

/// The kinds of the highest-scoring false positives of one category: the first `gt_boxes` false positives
/// in the AP's score order ([`crate::eval::score_order`]), which are the ones that cost AP before recall
/// can reach 1. Each counts once, in the first kind that applies, in this order.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FalsePositiveKinds {
    /// False positives examined (at most the category's ground-truth boxes).
    pub examined: usize,
    /// IoU ≥ the threshold with a box of the category already taken by a better detection.
    pub duplicate: usize,
    /// Best IoU with a box of the category in [[`TOUCH_IOU`], threshold).
    pub localisation: usize,
    /// IoU ≥ [`TOUCH_IOU`] with an annotated object of another category.
    pub confusion: usize,
    /// The other category most often confused with (by count; ties: the first in name order).
    pub most_confused_with: Option<String>,
    /// None of the above, in a frame with the category.
    pub background_in_frame: usize,
    /// None of the above, in a frame without the category.
    pub background_elsewhere: usize,
}

/// Classifies the highest-scoring false positives of `category` ([`FalsePositiveKinds`]); `truth[i]` and
/// `detections[i]` are image `i`'s objects (any category) and detections (a missing one: none).
pub fn false_positive_kinds(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
) -> FalsePositiveKinds {
    let (positives, ranked) = ranked_kinds(truth, detections, category, iou_threshold);
    let mut tally = FalseKindCounts::default();
    let mut examined = 0;
    for kind in ranked.into_iter().flatten().take(positives) {
        examined += 1;
        tally.add(category, kind);
    }
    // Most frequent first, ties in name order: the first pair is the most confused-with category.
    tally.sort();
    FalsePositiveKinds {
        examined,
        duplicate: tally.duplicate,
        localisation: tally.localisation,
        confusion: tally.confusion,
        most_confused_with: tally.confused.first().map(|c| c.object.clone()),
        background_in_frame: tally.background_in_frame,
        background_elsewhere: tally.background_elsewhere,
    }
}

/// The kind of one false positive ([`FalsePositiveKinds`]' rules: the first that applies).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FalsePositiveKind<'a> {
    Duplicate,
    Localisation,
    /// With the category of the annotated object it overlaps most.
    Confusion(&'a str),
    BackgroundInFrame,
    BackgroundElsewhere,
}

/// The number of the category's ground-truth boxes, and its detections in the AP's score order
/// ([`crate::eval::score_order`]), each `None` when a true positive, else its [`FalsePositiveKind`].
fn ranked_kinds<'a>(
    truth: &'a [Vec<Object>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
) -> (usize, Vec<Option<FalsePositiveKind<'a>>>) {
    let ground_truth = category_truth(truth, category);
    let scored = scored_boxes(detections, category);
    let pr = average_precision(&scored, &ground_truth, iou_threshold);
    let ranked = crate::eval::score_order(&scored)
        .iter()
        .zip(&pr.true_positive)
        .map(|(&d, &hit)| {
            let det = &scored[d];
            (!hit).then(|| {
                let (objects, own) = (&truth[det.image], &ground_truth[det.image]);
                false_positive_kind(objects, own, &det.cuboid, category, iou_threshold)
            })
        })
        .collect();
    (pr.positives, ranked)
}

/// The kind of a false positive of `category` with box `cuboid` in an image whose objects (any category)
/// are `objects` and whose boxes of `category` are `own`.
fn false_positive_kind<'a>(
    objects: &'a [Object],
    own: &[Cuboid],
    cuboid: &Cuboid,
    category: &str,
    iou_threshold: f32,
) -> FalsePositiveKind<'a> {
    let best_own = own.iter().map(|t| iou_3d(cuboid, t)).fold(0.0f32, f32::max);
    let other = objects
        .iter()
        .filter(|o| o.category != category)
        .map(|o| (o.category.as_str(), iou_3d(cuboid, &o.cuboid)))
        .fold(None, |best: Option<(&str, f32)>, (c, iou)| match best {
            Some((_, b)) if b >= iou => best,
            _ => Some((c, iou)),
        });
    if best_own >= iou_threshold {
        FalsePositiveKind::Duplicate
    } else if best_own >= TOUCH_IOU {
        FalsePositiveKind::Localisation
    } else if let Some((other_category, _)) = other.filter(|(_, iou)| *iou >= TOUCH_IOU) {
        FalsePositiveKind::Confusion(other_category)
    } else if own.is_empty() {
        FalsePositiveKind::BackgroundElsewhere
    } else {
        FalsePositiveKind::BackgroundInFrame
    }
}

// ---------------------------------------------------------------------------------------------------------
// 6. What each kind of false positive costs

/// The AP of one category with the false positives of some kinds removed — an oracle, to weigh each kind
/// of error: **every** false positive (not only the highest-scoring, as [`FalsePositiveKinds`] counts) is
/// classified by the same rules and the AP recomputed without those of the kinds named. A false positive
/// takes no ground-truth box, so removing it changes no other detection's match. `without_false_positives`
/// is the AP of the true positives alone: what a perfect rescoring of these same detections would reach
/// (the recall they leave). All `None` without ground truth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct OracleAps {
    pub without_duplicates: Option<f32>,
    pub without_localisation: Option<f32>,
    pub without_confusion: Option<f32>,
    /// Background in a frame with the category and in one without.
    pub without_background: Option<f32>,
    pub without_localisation_confusion_background: Option<f32>,
    pub without_false_positives: Option<f32>,
}

/// [`OracleAps`] of `category`; `truth[i]` and `detections[i]` are image `i`'s objects (any category) and
/// detections (a missing one: none).
pub fn oracle_aps(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
) -> OracleAps {
    let (positives, kinds) = ranked_kinds(truth, detections, category, iou_threshold);
    if positives == 0 {
        return OracleAps::default();
    }
    let without = |removed: &dyn Fn(&FalsePositiveKind) -> bool| -> Option<f32> {
        let (mut precision, mut recall) = (Vec::new(), Vec::new());
        let (mut shown, mut hits) = (0usize, 0usize);
        for kind in &kinds {
            if kind.as_ref().is_some_and(removed) {
                continue;
            }
            shown += 1;
            hits += usize::from(kind.is_none());
            precision.push(hits as f32 / shown as f32);
            recall.push(hits as f32 / positives as f32);
        }
        Some(interpolated_ap(&precision, &recall))
    };
    use FalsePositiveKind as K;
    OracleAps {
        without_duplicates: without(&|k| *k == K::Duplicate),
        without_localisation: without(&|k| *k == K::Localisation),
        without_confusion: without(&|k| matches!(k, K::Confusion(_))),
        without_background: without(&|k| matches!(k, K::BackgroundInFrame | K::BackgroundElsewhere)),
        without_localisation_confusion_background: without(&|k| *k != K::Duplicate),
        without_false_positives: without(&|_| true),
    }
}

// ---------------------------------------------------------------------------------------------------------
// 7. What became of each ground-truth box

/// Below this precision a true positive counts as found *behind* the false positives
/// ([`ObjectSummary::found_behind`]): at that point of the ranking the category has shown more false
/// positives than true ones, so the object adds little to the AP and a user reading the list by score
/// meets it late. (Choice: one half, the point where a detection is as likely wrong as right.)
pub const FOUND_AHEAD_PRECISION: f32 = 0.5;

/// What became of one ground-truth box ([`object_outcomes`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObjectOutcome {
    /// Index of its frame among the evaluated frames.
    pub image: usize,
    /// Its index among the frame's annotated objects (every category, in the annotation's order).
    pub object: usize,
    pub category: String,
    /// Width, depth, height (metres).
    pub size: [f32; 3],
    /// Distance of its centre from the camera on the ground plane (metres; the upright frame's origin is
    /// the camera).
    pub distance_m: f32,
    /// The detection of the category that takes it as a true positive under the benchmark's matching
    /// ([`crate::eval::average_precision`]); `None`: missed.
    pub found: Option<FoundBy>,
    /// The largest 3D IoU of any detection of the category in its frame with it (0 without one): for a
    /// missed box, whether a detection came near ([`TOUCH_IOU`]) or none did. A box can be missed with a
    /// detection at IoU ≥ the threshold when that detection took another box of the frame.
    pub best_iou: f32,
    /// The most confident detection of **another** category with a 3D IoU ≥ the threshold with it.
    pub other: Option<OtherDetection>,
}

/// The true positive that found a ground-truth box ([`ObjectOutcome::found`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FoundBy {
    pub score: f32,
    pub iou: f32,
    /// The category's precision over all frames when the AP's ranking reaches this detection.
    pub precision: f32,
    /// The category's false positives (all frames) ranked before it.
    pub false_positives_before: usize,
}

/// A detection of another category on a ground-truth box ([`ObjectOutcome::other`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OtherDetection {
    pub category: String,
    pub score: f32,
    pub iou: f32,
}

/// How a category's ground-truth boxes fared ([`ObjectOutcome`]s counted); the four counts add up to the
/// boxes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ObjectSummary {
    /// Found by a true positive ranked at a precision ≥ [`FOUND_AHEAD_PRECISION`].
    pub found_ahead: usize,
    /// Found by a true positive ranked at a lower precision.
    pub found_behind: usize,
    /// Missed, with a detection of the category at IoU ≥ [`TOUCH_IOU`] (poorly placed, or taken by
    /// another box).
    pub missed_near: usize,
    /// Missed, with no detection of the category at IoU ≥ [`TOUCH_IOU`].
    pub missed_far: usize,
    /// Of the missed ones, those with a detection of another category at IoU ≥ the threshold.
    pub missed_with_other: usize,
}

impl ObjectSummary {
    /// Counts `outcomes` (one category's).
    pub fn of(outcomes: &[ObjectOutcome]) -> ObjectSummary {
        let mut summary = ObjectSummary::default();
        for o in outcomes {
            match &o.found {
                Some(f) if f.precision >= FOUND_AHEAD_PRECISION => summary.found_ahead += 1,
                Some(_) => summary.found_behind += 1,
                None if o.best_iou >= TOUCH_IOU => summary.missed_near += 1,
                None => summary.missed_far += 1,
            }
            if o.found.is_none() && o.other.is_some() {
                summary.missed_with_other += 1;
            }
        }
        summary
    }
}

/// A box with less than this share of its volume in view is *mostly out of view* (choice: a quarter).
pub const MOSTLY_OUT_OF_VIEW: f32 = 0.25;

/// What became of every ground-truth box of `category` (`truth[i]` and `detections[i]`: image `i`'s
/// objects and detections, any category), in image order, then annotation order: the true positive that
/// found it (with the precision and the false positives before it in the AP's ranking), the best IoU of
/// the category's detections in its frame, and the most confident detection of another category on it.
pub fn object_outcomes(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
) -> Vec<ObjectOutcome> {
    let ground_truth = category_truth(truth, category);
    let scored = scored_boxes(detections, category);
    let matched = crate::eval::matched_truth_in_input_order(&scored, &ground_truth, iou_threshold);
    // found[image][k]: the true positive that took the image's k-th box of the category — the detection, the
    // precision when the AP's ranking reaches it, and the false positives ranked before it.
    let mut found: Vec<Vec<Option<(usize, f32, usize)>>> = ground_truth.iter().map(|g| vec![None; g.len()]).collect();
    let mut true_positives = 0;
    for (rank, &d) in crate::eval::score_order(&scored).iter().enumerate() {
        if let Some(k) = matched[d] {
            true_positives += 1;
            let precision = true_positives as f32 / (rank + 1) as f32;
            found[scored[d].image][k] = Some((d, precision, rank + 1 - true_positives));
        }
    }
    let mut outcomes = Vec::new();
    for (image, objects) in truth.iter().enumerate() {
        let frame_detections = detections.get(image).map(Vec::as_slice).unwrap_or(&[]);
        let mut k = 0;
        for (object, o) in objects.iter().enumerate() {
            if o.category != category {
                continue;
            }
            let best_iou = frame_detections
                .iter()
                .filter(|d| d.category == category)
                .map(|d| iou_3d(&d.cuboid(), &o.cuboid))
                .fold(0.0f32, f32::max);
            let other = frame_detections
                .iter()
                .filter(|d| d.category != category)
                .map(|d| (d, iou_3d(&d.cuboid(), &o.cuboid)))
                .filter(|(_, iou)| *iou >= iou_threshold)
                .fold(None, |best: Option<(&Detection, f32)>, (d, iou)| match best {
                    Some((b, _)) if b.score >= d.score => best,
                    _ => Some((d, iou)),
                })
                .map(|(d, iou)| OtherDetection { category: d.category.clone(), score: d.score, iou });
            let found = found[image][k].map(|(d, precision, false_positives_before)| FoundBy {
                score: scored[d].score,
                iou: iou_3d(&scored[d].cuboid, &o.cuboid),
                precision,
                false_positives_before,
            });
            outcomes.push(ObjectOutcome {
                image,
                object,
                category: category.to_string(),
                size: o.cuboid.size.to_array(),
                distance_m: o.cuboid.centre.truncate().length(),
                found,
                best_iou,
                other,
            });
            k += 1;
        }
    }
    outcomes
}

// ---------------------------------------------------------------------------------------------------------
// 8. Reliability of the scores as probabilities

/// Bins of [`reliability`]: ten of width 0.1 over [0, 1], each closed below and open above, the last closed.
pub const RELIABILITY_BINS: usize = 10;

/// The detections whose score falls in `[lower, upper)` ([`reliability`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ReliabilityBin {
    pub lower: f32,
    pub upper: f32,
    pub detections: usize,
    /// Of them, true positives by the benchmark's matching.
    pub true_positives: usize,
    /// The sum of their scores: the true positives the scores, read as probabilities, expect.
    pub expected_true_positives: f64,
}

impl ReliabilityBin {
    /// Mean score of the bin's detections; `None` for an empty bin.
    pub fn mean_score(&self) -> Option<f64> {
        (self.detections > 0).then(|| self.expected_true_positives / self.detections as f64)
    }

    /// Share of the bin's detections that are true positives; `None` for an empty bin.
    pub fn precision(&self) -> Option<f64> {
        (self.detections > 0).then(|| self.true_positives as f64 / self.detections as f64)
    }
}

/// How well the detections' scores hold as probabilities of being right ([`reliability`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Reliability {
    /// [`RELIABILITY_BINS`] bins, lowest first.
    pub bins: Vec<ReliabilityBin>,
    /// Detections whose score is not in [0, 1] (raw, uncalibrated scores), left out of the bins.
    pub outside_unit_interval: usize,
    /// Σ over the bins of (detections / all binned) · |precision − mean score|; `None` when nothing is
    /// binned.
    pub expected_calibration_error: Option<f64>,
}

/// The reliability of the detections' scores (number 8 of the module doc): every detection of
/// `categories` is labelled by [`true_positives_in_input_order`] — the AP's matching, the rule the
/// calibrations were fitted on (`calibrate`, `calibrate --cascade`) — and counted in its score's bin.
/// Scores outside [0, 1] are counted apart (a file of raw scores has no probabilities to check).
pub fn reliability(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    categories: &[String],
    iou_threshold: f32,
) -> Reliability {
    let width = 1.0 / RELIABILITY_BINS as f32;
    let mut out = Reliability {
        bins: (0..RELIABILITY_BINS)
            .map(|b| ReliabilityBin { lower: b as f32 * width, upper: (b + 1) as f32 * width, ..Default::default() })
            .collect(),
        ..Default::default()
    };
    for category in categories {
        let boxes = scored_boxes(detections, category);
        let labels = true_positives_in_input_order(&boxes, &category_truth(truth, category), iou_threshold);
        for (scored, hit) in boxes.iter().zip(labels) {
            if !(0.0..=1.0).contains(&scored.score) {
                out.outside_unit_interval += 1;
                continue;
            }
            let bin = ((scored.score * RELIABILITY_BINS as f32) as usize).min(RELIABILITY_BINS - 1);
            let bin = &mut out.bins[bin];
            bin.detections += 1;
            bin.true_positives += usize::from(hit);
            bin.expected_true_positives += f64::from(scored.score);
        }
    }
    let binned: usize = out.bins.iter().map(|b| b.detections).sum();
    out.expected_calibration_error = (binned > 0).then(|| {
        out.bins
            .iter()
            .filter_map(|b| Some(b.detections as f64 / binned as f64 * (b.precision()? - b.mean_score()?).abs()))
            .sum()
    });
    out
}

// ---------------------------------------------------------------------------------------------------------
// All together

/// The diagnosis of one category, as printed by `cog-gpu eval --diagnose --json`. Fractions are in
/// [0, 1]; `None` (JSON `null`) where undefined.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CategoryDiagnosis {
    #[serde(skip)]
    pub category: String,
    /// Ground-truth boxes of the category in the evaluated frames.
    pub gt_boxes: usize,
    /// Window recall at IoU 0.25 (`None` without a model for the category or without ground truth).
    pub window_recall_25: Option<f32>,
    /// Window recall at IoU 0.5.
    pub window_recall_50: Option<f32>,
    /// Mean best window IoU.
    pub window_mean_best_iou: Option<f32>,
    /// Frames with ground truth of the category.
    pub frames_with_category: usize,
    /// Of those, frames with at least one detection of the category.
    pub frames_with_detections: usize,
    /// Fraction of `frames_with_detections` whose best detection is a true positive.
    pub best_is_tp: Option<f32>,
    /// The benchmark AP ([`average_precision`] on the scores).
    pub ap: Option<f32>,
    /// The AP of the in-frame ranks ([`rank_average_precision`]).
    pub rank_ap: Option<f32>,
    /// What the highest-scoring false positives are ([`false_positive_kinds`]).
    pub false_positives: FalsePositiveKinds,
    /// The AP without the false positives of each kind ([`oracle_aps`]).
    pub oracle_ap: OracleAps,
    /// What became of its ground-truth boxes ([`object_outcomes`], counted).
    pub objects: ObjectSummary,
}

/// Diagnoses each of `categories` (numbers 2 and 3 of the module doc, and number 1 from `window`: the best
/// window IoUs of every ground-truth box of a category, over all frames; a category absent from `window`,
/// or all of them when `window` is `None`, has no window numbers).
pub fn diagnose_categories(
    truth: &[Vec<Object>],
    detections: &[Vec<Detection>],
    categories: &[String],
    iou_threshold: f32,
    window: Option<&BTreeMap<String, Vec<f32>>>,
) -> Vec<CategoryDiagnosis> {
    categories
        .iter()
        .map(|category| {
            let ground_truth = category_truth(truth, category);
            let scored = scored_boxes(detections, category);
            let pr = average_precision(&scored, &ground_truth, iou_threshold);
            let ranking = in_frame_ranking(truth, detections, category, iou_threshold);
            let rank = rank_average_precision(truth, detections, category, iou_threshold);
            let recall = window.and_then(|w| w.get(category)).map(|best| WindowRecall::from_best_ious(best));
            CategoryDiagnosis {
                category: category.clone(),
                gt_boxes: pr.positives,
                window_recall_25: recall.and_then(|r| r.recall_25),
                window_recall_50: recall.and_then(|r| r.recall_50),
                window_mean_best_iou: recall.and_then(|r| r.mean_best_iou),
                frames_with_category: ranking.frames_with_category,
                frames_with_detections: ranking.frames_with_detections,
                best_is_tp: ranking.fraction(),
                ap: pr.ap,
                rank_ap: rank.ap,
                false_positives: false_positive_kinds(truth, detections, category, iou_threshold),
                oracle_ap: oracle_aps(truth, detections, category, iou_threshold),
                objects: ObjectSummary::of(&object_outcomes(truth, detections, category, iou_threshold)),
            }
        })
        .collect()
}
