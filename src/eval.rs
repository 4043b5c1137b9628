//! Evaluation with the SUN RGB-D 3D detection benchmark's rules: average precision at a 3D IoU threshold.
//!
//! For one category:
//! 1. the detections of all images are sorted by score, highest first (ties keep their input order:
//!    image order, then the order within the image's detection file);
//! 2. each detection takes the ground-truth cuboid of its image with the highest 3D IoU
//!    ([`crate::geometry::iou_3d`]); it is a true positive when that IoU ≥ the threshold and that ground
//!    truth was not already taken by a higher-scoring detection, else a false positive (a duplicate of a
//!    taken box is a false positive even when a second, less-overlapping box is free — the benchmark's rule);
//! 3. precision and recall are accumulated along that order, recall over the number of ground-truth boxes
//!    of the category in all images;
//! 4. AP is the all-point interpolated area under the precision–recall curve (PASCAL VOC 2010 and later):
//!    precision is made non-increasing from the right, then summed over the recall steps. Not 11-point.
//!
//! A category with no ground truth in the evaluated images has no AP (`None`) and is left out of the mAP.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::category::{category_index, is_cross_score_category, normalise_name, CATEGORIES, CROSS_SCORE_CATEGORIES};
use crate::error::{Error, Result};
use crate::features::surface::SurfaceSource;
use crate::features::weights::MAX_WEIGHT;
use crate::geometry::{iou_3d, Cuboid};
use crate::limits::{MAX_COORDINATE_M, MAX_OBJECT_SIZE_M};

/// One detected object, as written in a frame's detections JSON (upright frame; yaw as in
/// [`crate::geometry`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Detection {
    pub category: String,
    pub centre: [f32; 3],
    /// (width, depth, height) in metres.
    pub size: [f32; 3],
    /// Radians, the width axis' angle from +x, counter-clockwise seen from above.
    pub yaw: f32,
    /// The ranking score: the calibrated probability of a true positive when the model has a
    /// calibration, else the raw score.
    pub score: f32,
    /// The model's raw score `w·φ + bias`, when `score` is calibrated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub raw_score: Option<f32>,
    /// When the context cascade rescored the detection ([`crate::cascade`]): the first stage's calibrated
    /// probability, which `score` replaced.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_stage_score: Option<f32>,
    /// When the context cascade rescored the detection: its second-stage score `z'` (the cascade's `score`
    /// is the calibrated `raw_score + context_score`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub context_score: Option<f32>,
    /// The height (upright z, metres, the frame's coordinates like `centre`) of the detection's support
    /// surface: for a category with one ([`crate::category::SURFACE_CATEGORIES`]) measured from the points
    /// in the box ([`crate::features::surface::category_surface_height`]); where that finds none, and for
    /// the other models with latent surfaces, measured in the chosen slice ([`Detection::latent_slice`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_z: Option<f32>,
    /// Which rule gave `surface_z` (written as `"face"`, `"front-edge"` or `"latent-slice"`; absent with
    /// `surface_z`, and in files written before 2026-12-07).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface_source: Option<SurfaceSource>,
    /// For a model with latent support surfaces ([`crate::features::surface`]): the best-scoring of the
    /// cuboid's seven horizontal slices, `h` = 0 (bottom) … 6, the latent variable of its score.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latent_slice: Option<u8>,
    /// For a detection of one of [`crate::category::CROSS_SCORE_CATEGORIES`], when `detect` computed them
    /// ([`crate::detect::cross_scores`]): the raw score (`w·φ + bias`, exact path, cuboid weights) of each
    /// of those categories' models on this detection's box, by category — what the context cascade's
    /// feature set v7 reads.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cross_scores: Option<BTreeMap<String, f32>>,
    /// When cross-category exclusion demoted the detection ([`crate::exclusion`]): its score before, which
    /// `score` replaced (`score = score_before_exclusion · (1 − weight · p)`, `p` the competitor's score).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score_before_exclusion: Option<f32>,
    /// When cross-category exclusion demoted the detection: the category of the more confident overlapping
    /// detection that did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excluded_by: Option<String>,
    /// When the cascade has a final calibration ([`crate::cascade::Cascade::final_calibration`]): the score
    /// before it (after the stages and the exclusion), which `score` replaced (`logit score = a·ln p −
    /// b·ln(1 − p) + c`, [`crate::calibration::final_calibration::FinalCalibration::recalibrate`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub score_before_final_calibration: Option<f32>,
}

impl Detection {
    pub fn cuboid(&self) -> Cuboid {
        Cuboid::new(Vec3::from(self.centre), Vec3::from(self.size), self.yaw)
    }

    pub fn new(category: impl Into<String>, cuboid: &Cuboid, score: f32) -> Self {
        Detection {
            category: category.into(),
            centre: cuboid.centre.to_array(),
            size: cuboid.size.to_array(),
            yaw: cuboid.yaw,
            score,
            raw_score: None,
            first_stage_score: None,
            context_score: None,
            surface_z: None,
            surface_source: None,
            latent_slice: None,
            cross_scores: None,
            score_before_exclusion: None,
            excluded_by: None,
            score_before_final_calibration: None,
        }
    }
}

/// The detections of one frame: `{"frame": NAME, "detections": [...]}`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameDetections {
    pub frame: String,
    pub detections: Vec<Detection>,
}

impl FrameDetections {
    /// Reads and checks a detections file: finite numbers, positive sizes.
    pub fn read(path: &Path) -> Result<FrameDetections> {
        FrameDetections::parse(path, &crate::frame::read_text(path)?)
    }

    /// [`FrameDetections::read`] on the file's text, already read (errors name `path`).
    pub fn parse(path: &Path, text: &str) -> Result<FrameDetections> {
        if text.trim_start().starts_with('[') {
            return Err(Error::invalid(
                path,
                "holds a JSON array; a detections file is one object {\"frame\": NAME, \"detections\": [...]} \
                 (`detect --json` prints an array of them on stdout; the files are those in detect's --out)",
            ));
        }
        let parsed: FrameDetections =
            serde_json::from_str(text).map_err(|e| Error::invalid(path, format!("not a detections file: {e}")))?;
        for (i, d) in parsed.detections.iter().enumerate() {
            // A category spelt otherwise than cog-gpu writes it would match no annotation and no
            // `--categories` entry: its detections would drop out of every evaluation without a word.
            if category_index(&d.category).is_none() {
                let known = normalise_name(&d.category).0;
                let hint = if category_index(&known).is_some() {
                    format!("write '{known}'")
                } else {
                    format!("the categories are {}", CATEGORIES.join(", "))
                };
                return Err(Error::invalid(
                    path,
                    format!("detections[{i}] has category '{}', not one of cog-gpu's ({hint})", d.category),
                ));
            }
            let finite = d
                .centre
                .iter()
                .chain(&d.size)
                .chain([&d.yaw, &d.score])
                .chain(&d.raw_score)
                .chain(&d.first_stage_score)
                .chain(&d.context_score)
                .chain(&d.surface_z)
                .chain(&d.score_before_exclusion)
                .chain(&d.score_before_final_calibration)
                .all(|v| v.is_finite());
            if !finite {
                return Err(Error::invalid(path, format!("detections[{i}] has a non-finite number")));
            }
            check_cross_scores(d).map_err(|m| Error::invalid(path, format!("detections[{i}]: {m}")))?;
            if d.size.iter().any(|s| *s <= 0.0) {
                return Err(Error::invalid(path, format!("detections[{i}] has a non-positive size {:?}", d.size)));
            }
            if d.size.iter().any(|&s| s > MAX_OBJECT_SIZE_M)
                || d.centre.iter().any(|&c| c.abs() as f64 > MAX_COORDINATE_M)
            {
                return Err(Error::invalid(
                    path,
                    format!(
                        "detections[{i}] (centre {:?}, size {:?}) lies beyond ±{MAX_COORDINATE_M} m or is larger than \
                         {MAX_OBJECT_SIZE_M} m",
                        d.centre, d.size
                    ),
                ));
            }
        }
        Ok(parsed)
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::invalid(path, e.to_string()))?;
        crate::error::write_whole(path, text.as_bytes())
    }
}

/// A detection's `cross_scores` as `detect` writes them: each key one of
/// [`crate::category::CROSS_SCORE_CATEGORIES`] (another name is a model no cascade has a weight for, and
/// would be read as nothing), each value a raw score within ±[`MAX_WEIGHT`] (the bound of a model's
/// weights; real raw scores are a few units) — the cascade's v7 stages multiply them by their weights, so
/// one absurd value would decide a detection's probability alone.
fn check_cross_scores(d: &Detection) -> std::result::Result<(), String> {
    for (category, &score) in d.cross_scores.iter().flatten() {
        if !is_cross_score_category(category) {
            return Err(format!(
                "cross_scores has '{category}', not one of the categories that make cross scores ({})",
                CROSS_SCORE_CATEGORIES.join(", ")
            ));
        }
        if !score.is_finite() || score.abs() > MAX_WEIGHT {
            return Err(format!("cross_scores['{category}'] = {score} is not a raw score within ±{MAX_WEIGHT:e}"));
        }
    }
    Ok(())
}

/// A scored cuboid of one image, the input of [`average_precision`].
#[derive(Clone, Copy, Debug)]
pub struct ScoredBox {
    pub image: usize,
    pub score: f32,
    pub cuboid: Cuboid,
}

/// The precision–recall curve and AP of one category.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrecisionRecall {
    /// Precision after each detection, in score order.
    pub precision: Vec<f32>,
    /// Recall after each detection, in score order.
    pub recall: Vec<f32>,
    /// Whether each detection, in score order, is a true positive.
    pub true_positive: Vec<bool>,
    /// Number of ground-truth boxes.
    pub positives: usize,
    /// All-point interpolated AP; `None` without ground truth.
    pub ap: Option<f32>,
}

/// Evaluates one category: `detections` over all images, `ground_truth[image]` the category's boxes in
/// each image (see the module doc for the rules).
pub fn average_precision(
    detections: &[ScoredBox],
    ground_truth: &[Vec<Cuboid>],
    iou_threshold: f32,
) -> PrecisionRecall {
    let positives: usize = ground_truth.iter().map(Vec::len).sum();
    let order = score_order(detections);
    let true_positive: Vec<bool> =
        match_in_order(detections, &order, ground_truth, iou_threshold).iter().map(Option::is_some).collect();
    let (mut tp, mut precision, mut recall) = (0usize, Vec::new(), Vec::new());
    for (k, &hit) in true_positive.iter().enumerate() {
        tp += hit as usize;
        precision.push(tp as f32 / (k + 1) as f32);
        recall.push(if positives > 0 { tp as f32 / positives as f32 } else { 0.0 });
    }
    let ap = (positives > 0).then(|| interpolated_ap(&precision, &recall));
    PrecisionRecall { precision, recall, true_positive, positives, ap }
}

/// The benchmark's matching (module doc): visiting `detections` in `order`, the ground-truth box (index
/// into its image's list) each takes as a true positive, `None` for a false positive; in visiting order.
fn match_in_order(
    detections: &[ScoredBox],
    order: &[usize],
    ground_truth: &[Vec<Cuboid>],
    iou_threshold: f32,
) -> Vec<Option<usize>> {
    let mut taken: Vec<Vec<bool>> = ground_truth.iter().map(|g| vec![false; g.len()]).collect();
    let mut matches = Vec::with_capacity(order.len());
    for &d in order {
        let det = &detections[d];
        let truths = ground_truth.get(det.image).map(Vec::as_slice).unwrap_or(&[]);
        let hit = match best_truth(&det.cuboid, truths.iter().enumerate()) {
            Some((g, iou)) if iou >= iou_threshold && !taken[det.image][g] => {
                taken[det.image][g] = true;
                Some(g)
            }
            _ => None,
        };
        matches.push(hit);
    }
    matches
}

/// The ground-truth box a detection `cuboid` takes under the benchmark's matching (module doc): of
/// `truths` (index, box), the one with the highest 3D IoU, ties to the first — a later box replaces the best
/// only when strictly better —, with that IoU; `None` without boxes.
fn best_truth<'a>(cuboid: &Cuboid, truths: impl Iterator<Item = (usize, &'a Cuboid)>) -> Option<(usize, f32)> {
    truths.map(|(g, truth)| (g, iou_3d(cuboid, truth))).fold(None, |best, (g, iou)| match best {
        Some((_, b)) if b >= iou => best,
        _ => Some((g, iou)),
    })
}

/// For each of `boxes`, **in input order**, the ground-truth box of its image that it takes as a true
/// positive under [`average_precision`]'s matching (`None` for a false positive).
pub fn matched_truth_in_input_order(
    boxes: &[ScoredBox],
    ground_truth: &[Vec<Cuboid>],
    iou_threshold: f32,
) -> Vec<Option<usize>> {
    let order = score_order(boxes);
    let mut matched = vec![None; boxes.len()];
    for (&n, hit) in order.iter().zip(match_in_order(boxes, &order, ground_truth, iou_threshold)) {
        matched[n] = hit;
    }
    matched
}

/// The indices of `detections` in the order [`average_precision`] visits them: score descending, equal
/// scores in input order (a stable sort).
pub fn score_order(detections: &[ScoredBox]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    order.sort_by(|&a, &b| detections[b].score.total_cmp(&detections[a].score));
    order
}

/// All-point interpolated area under a precision–recall curve given in detection order (VOC 2010+):
/// `Σ (r_k − r_{k−1}) · max_{j ≥ k} p_j`, with r_0 = 0.
pub fn interpolated_ap(precision: &[f32], recall: &[f32]) -> f32 {
    let mut envelope = precision.to_vec();
    for k in (0..envelope.len().saturating_sub(1)).rev() {
        envelope[k] = envelope[k].max(envelope[k + 1]);
    }
    let mut ap = 0.0f64;
    let mut previous_recall = 0.0f32;
    for (k, &r) in recall.iter().enumerate() {
        ap += (r - previous_recall) as f64 * envelope[k] as f64;
        previous_recall = r;
    }
    ap as f32
}

/// Mean of the defined APs (`None` when none is defined).
pub fn mean_ap<'a>(aps: impl IntoIterator<Item = &'a Option<f32>>) -> Option<f32> {
    let defined: Vec<f32> = aps.into_iter().flatten().copied().collect();
    (!defined.is_empty()).then(|| defined.iter().sum::<f32>() / defined.len() as f32)
}

// ---------------------------------------------------------------------------------------------------------
// Many categories over a set of images

/// The evaluation of one category over a set of images.
#[derive(Clone, Debug, PartialEq)]
pub struct CategoryEvaluation {
    pub category: String,
    /// Number of ground-truth boxes of the category.
    pub ground_truth: usize,
    /// Number of detections of the category.
    pub detections: usize,
    pub pr: PrecisionRecall,
}

/// The detections of `category` over all images as [`ScoredBox`]es (`detections[i]` are image `i`'s), in
/// image order, then file order.
pub fn scored_boxes(detections: &[Vec<Detection>], category: &str) -> Vec<ScoredBox> {
    detections
        .iter()
        .enumerate()
        .flat_map(|(image, dets)| {
            dets.iter().filter(|d| d.category == category).map(move |d| ScoredBox {
                image,
                score: d.score,
                cuboid: d.cuboid(),
            })
        })
        .collect()
}

/// `categories`, or when it is empty every cog-gpu category (in [`crate::category::CATEGORIES`]' order) with
/// a ground-truth box in `truth`: the categories a fit over held-out frames reads by default.
pub fn chosen_or_annotated_categories(categories: &[String], truth: &[Vec<crate::frame::Object>]) -> Vec<String> {
    if !categories.is_empty() {
        return categories.to_vec();
    }
    crate::category::CATEGORIES
        .iter()
        .filter(|c| truth.iter().flatten().any(|o| o.category == **c))
        .map(|c| c.to_string())
        .collect()
}

/// Each image's ground-truth cuboids of `category` (`truth[i]`: image `i`'s annotated objects).
pub fn category_truth(truth: &[Vec<crate::frame::Object>], category: &str) -> Vec<Vec<Cuboid>> {
    truth.iter().map(|objects| objects.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect()).collect()
}

/// Whether each of `boxes`, **in input order**, is a true positive under [`average_precision`]'s
/// matching (which visits them in score order).
pub fn true_positives_in_input_order(
    boxes: &[ScoredBox],
    ground_truth: &[Vec<Cuboid>],
    iou_threshold: f32,
) -> Vec<bool> {
    let pr = average_precision(boxes, ground_truth, iou_threshold);
    let mut labels = vec![false; boxes.len()];
    for (&n, &hit) in score_order(boxes).iter().zip(&pr.true_positive) {
        labels[n] = hit;
    }
    labels
}

/// Evaluates each of `categories` over the same images: `truth[i]` holds the annotated objects of image
/// `i` and `detections[i]` its detections (both of any category; the others are ignored). A missing
/// `detections[i]` (shorter slice) counts as no detections.
pub fn evaluate_categories(
    truth: &[Vec<crate::frame::Object>],
    detections: &[Vec<Detection>],
    categories: &[String],
    iou_threshold: f32,
) -> Vec<CategoryEvaluation> {
    categories
        .iter()
        .map(|category| {
            let ground_truth = category_truth(truth, category);
            let scored = scored_boxes(detections, category);
            let pr = average_precision(&scored, &ground_truth, iou_threshold);
            CategoryEvaluation { category: category.clone(), ground_truth: pr.positives, detections: scored.len(), pr }
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------------------
// Ignored ground truth (PASCAL VOC's "difficult" objects)

/// How many ground-truth boxes and detections of one category [`ignore_boxes`] took out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct IgnoredCounts {
    pub boxes: usize,
    pub detections: usize,
}

/// What [`ignore_boxes`] leaves of an evaluation's inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct WithoutIgnored {
    /// Per image, its ground-truth boxes that are not ignored, in their order.
    pub truth: Vec<Vec<crate::frame::Object>>,
    /// Per image, the index in the image's annotation of each box of `truth` (what a report that names
    /// boxes by their index must print).
    pub annotation_index: Vec<Vec<usize>>,
    /// Per image, its detections that are not dropped, in their order.
    pub detections: Vec<Vec<Detection>>,
    /// Per category (of the boxes and detections taken out, evaluated or not), what was taken out.
    pub counts: BTreeMap<String, IgnoredCounts>,
}

/// The images' ground truth and detections with the boxes marked in `ignored` (`ignored[i][o]`: image `i`'s
/// object `o`; a shorter list marks nothing) taken out as PASCAL VOC's devkit takes out its "difficult"
/// objects: an ignored box is no longer a positive, and a detection whose best box is an ignored one at IoU ≥
/// `iou_threshold` is dropped — neither a true nor a false positive. "Best" is [`average_precision`]'s
/// choice among the image's boxes of the detection's category, ignored ones included: the highest 3D IoU,
/// ties to the first box in the list. Everything else keeps its order.
///
/// Evaluating the result with [`evaluate_categories`] is VOC's rule exactly: a kept detection whose best
/// box was a kept one takes the same best box among the kept (removing others cannot change a maximum they
/// did not hold, and a tie went to the first, which is then kept); one whose best box was ignored at an IoU
/// below the threshold is a false positive in both (no kept box overlaps it more).
pub fn ignore_boxes(
    truth: &[Vec<crate::frame::Object>],
    ignored: &[Vec<bool>],
    detections: &[Vec<Detection>],
    iou_threshold: f32,
) -> WithoutIgnored {
    let mut counts: BTreeMap<String, IgnoredCounts> = BTreeMap::new();
    let is_ignored =
        |image: usize, object: usize| ignored.get(image).and_then(|m| m.get(object)).copied() == Some(true);
    let mut kept_truth = Vec::with_capacity(truth.len());
    let mut annotation_index = Vec::with_capacity(truth.len());
    let mut kept_detections = Vec::with_capacity(detections.len());
    for (image, objects) in truth.iter().enumerate() {
        let mut kept = Vec::with_capacity(objects.len());
        let mut index = Vec::with_capacity(objects.len());
        for (o, object) in objects.iter().enumerate() {
            if is_ignored(image, o) {
                counts.entry(object.category.clone()).or_default().boxes += 1;
            } else {
                kept.push(object.clone());
                index.push(o);
            }
        }
        kept_truth.push(kept);
        annotation_index.push(index);
    }
    for (image, frame) in detections.iter().enumerate() {
        let objects = truth.get(image).map(Vec::as_slice).unwrap_or(&[]);
        let mut kept = Vec::with_capacity(frame.len());
        for detection in frame {
            let same_category = objects.iter().enumerate().filter(|(_, o)| o.category == detection.category);
            match best_truth(&detection.cuboid(), same_category.map(|(o, object)| (o, &object.cuboid))) {
                Some((o, iou)) if iou >= iou_threshold && is_ignored(image, o) => {
                    counts.entry(detection.category.clone()).or_default().detections += 1;
                }
                _ => kept.push(detection.clone()),
            }
        }
        kept_detections.push(kept);
    }
    WithoutIgnored { truth: kept_truth, annotation_index, detections: kept_detections, counts }
}

// ---------------------------------------------------------------------------------------------------------
// Bootstrap intervals over frames

/// How [`bootstrap_aps`] resamples: `resamples` draws of as many frames as the set has, with replacement,
/// from a SplitMix64 stream seeded by `seed` ([`crate::synth::rng::Rng`], written in the crate so that an
/// interval never changes with a dependency's version).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bootstrap {
    pub resamples: usize,
    pub seed: u64,
}

/// The frames of each resample: `resamples` lists of `frames` indices drawn uniformly with replacement.
/// Frames, not boxes, are the unit: a frame's detections and ground truth stay together (their matching
/// is within the frame), and a frame drawn twice counts as two frames.
pub fn bootstrap_frames(frames: usize, bootstrap: Bootstrap) -> Vec<Vec<usize>> {
    let mut rng = crate::synth::rng::Rng::new(bootstrap.seed);
    (0..bootstrap.resamples)
        .map(|_| (0..frames).map(|_| if frames == 0 { 0 } else { rng.int(0, frames - 1) }).collect())
        .collect()
}

/// The APs of every resample ([`bootstrap_frames`]) for each of several detection sets of the same frames,
/// with the same resamples for every set (so that differences between sets are paired):
/// `result[set][resample][category]`, `None` where a resample holds no ground truth of the category.
/// Each resample is evaluated exactly as [`evaluate_categories`] evaluates a dataset made of the drawn
/// frames in draw order.
pub fn bootstrap_aps(
    truth: &[Vec<crate::frame::Object>],
    detection_sets: &[&[Vec<Detection>]],
    categories: &[String],
    iou_threshold: f32,
    bootstrap: Bootstrap,
) -> Vec<Vec<Vec<Option<f32>>>> {
    use rayon::prelude::*;
    let draws = bootstrap_frames(truth.len(), bootstrap);
    // Per category, each frame's ground truth and (per set) its scored boxes, gathered once.
    let truth_of: Vec<Vec<Vec<Cuboid>>> = categories.iter().map(|category| category_truth(truth, category)).collect();
    detection_sets
        .iter()
        .map(|detections| {
            let boxes_of: Vec<Vec<Vec<ScoredBox>>> = categories
                .iter()
                .map(|category| {
                    (0..truth.len())
                        .map(|f| {
                            let frame = detections.get(f).map(Vec::as_slice).unwrap_or(&[]);
                            frame
                                .iter()
                                .filter(|d| &d.category == category)
                                .map(|d| ScoredBox { image: f, score: d.score, cuboid: d.cuboid() })
                                .collect()
                        })
                        .collect()
                })
                .collect();
            draws
                .par_iter()
                .map(|draw| {
                    (0..categories.len())
                        .map(|c| {
                            let ground_truth: Vec<Vec<Cuboid>> = draw.iter().map(|&f| truth_of[c][f].clone()).collect();
                            let scored: Vec<ScoredBox> = draw
                                .iter()
                                .enumerate()
                                .flat_map(|(image, &f)| boxes_of[c][f].iter().map(move |b| ScoredBox { image, ..*b }))
                                .collect();
                            average_precision(&scored, &ground_truth, iou_threshold).ap
                        })
                        .collect()
                })
                .collect()
        })
        .collect()
}

/// A category's detections reduced to what AP needs once they are matched: in the order
/// [`average_precision`] visits them, each one's frame and whether it is a true positive, and each frame's
/// number of ground-truth boxes. Matching happens within a frame, so a frame that a bootstrap resample
/// draws `k` times adds its detections `k` times with the same labels: a resample's AP needs no IoU
/// ([`MatchedDetections::resampled_ap`]), which makes thousands of resamples cheap (the cascade's
/// cross-validated gain, [`crate::cascade`]).
#[derive(Clone, Debug)]
pub struct MatchedDetections {
    /// Per detection in score order: its frame.
    frames: Vec<usize>,
    /// Per detection in score order: whether it is a true positive.
    true_positive: Vec<bool>,
    /// Per frame: its number of ground-truth boxes.
    positives: Vec<usize>,
}

impl MatchedDetections {
    /// `detections[n].image` indexes `ground_truth`, which has one entry per frame.
    pub fn new(detections: &[ScoredBox], ground_truth: &[Vec<Cuboid>], iou_threshold: f32) -> Self {
        let order = score_order(detections);
        let pr = average_precision(detections, ground_truth, iou_threshold);
        MatchedDetections {
            frames: order.iter().map(|&n| detections[n].image).collect(),
            true_positive: pr.true_positive,
            positives: ground_truth.iter().map(Vec::len).collect(),
        }
    }

    /// The AP of the data set made of every frame `f` taken `counts[f]` times (`counts` has one entry per
    /// frame; 0 leaves it out): [`average_precision`] on that data set, exactly, whenever no two of the
    /// category's detections tie in score — tied ones may be visited in another order, here each detection's
    /// copies one after the other, there copy by copy of its frame; two tied detections of one frame drawn
    /// twice, a hit and a miss, are visited hit, hit, miss, miss here and hit, miss, hit, miss there.
    /// `None` without ground truth.
    pub fn resampled_ap(&self, counts: &[u32]) -> Option<f32> {
        let positives: usize = self.positives.iter().zip(counts).map(|(&p, &k)| p * k as usize).sum();
        if positives == 0 {
            return None;
        }
        let (mut tp, mut visited, mut precision, mut recall) = (0usize, 0usize, Vec::new(), Vec::new());
        for (&frame, &hit) in self.frames.iter().zip(&self.true_positive) {
            for _ in 0..counts[frame] {
                tp += hit as usize;
                visited += 1;
                precision.push(tp as f32 / visited as f32);
                recall.push(tp as f32 / positives as f32);
            }
        }
        Some(interpolated_ap(&precision, &recall))
    }
}

/// The central `level` interval of `values` by percentiles (the percentile bootstrap): the
/// `(1 − level)/2` and `(1 + level)/2` quantiles, each interpolated linearly between the two nearest
/// order statistics (position `q · (n − 1)` in the sorted values, the usual "type 7" definition).
/// `None` for no values.
pub fn percentile_interval(values: &[f32], level: f32) -> Option<(f32, f32)> {
    if values.is_empty() {
        return None;
    }
    let mut sorted = values.to_vec();
    sorted.sort_by(f32::total_cmp);
    let quantile = |q: f32| {
        let position = q * (sorted.len() - 1) as f32;
        let below = position.floor() as usize;
        let above = (below + 1).min(sorted.len() - 1);
        let t = position - below as f32;
        sorted[below] + (sorted[above] - sorted[below]) * t
    };
    Some((quantile((1.0 - level) / 2.0), quantile((1.0 + level) / 2.0)))
}

// ---------------------------------------------------------------------------------------------------------
// Precision–recall plot

/// Width and height of [`precision_recall_plot`]'s image.
pub const PLOT_SIZE: (u32, u32) = (480, 400);

/// A precision–recall plot: recall on x and precision on y, both 0..1 with a grid every 0.1 and labels
/// every 0.2; the raw curve (precision after each detection) in grey dots; the interpolated precision
/// envelope whose area is the AP as a step line in `colour`; `title` on top (e.g. `"bed AP=75.0"`).
pub fn precision_recall_plot(pr: &PrecisionRecall, title: &str, colour: crate::draw::Colour) -> image::RgbImage {
    use crate::draw::{draw_line, draw_text, fill_rect, text_size, BLACK};
    use glam::Vec2;
    let (width, height) = PLOT_SIZE;
    let mut img = image::RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
    let (left, right, top, bottom) = (56.0f32, width as f32 - 24.0, 40.0f32, height as f32 - 48.0);
    let at = |recall: f32, precision: f32| {
        Vec2::new(left + recall.clamp(0.0, 1.0) * (right - left), bottom - precision.clamp(0.0, 1.0) * (bottom - top))
    };
    let grid = [225, 225, 225];
    for step in 0..=10 {
        let v = step as f32 / 10.0;
        draw_line(&mut img, at(v, 0.0), at(v, 1.0), grid, 1);
        draw_line(&mut img, at(0.0, v), at(1.0, v), grid, 1);
        if step % 2 == 0 {
            let label = format!("{v:.1}");
            let (tw, th) = text_size(&label, 1);
            let x_tick = at(v, 0.0);
            draw_text(&mut img, x_tick.x as i64 - tw as i64 / 2, x_tick.y as i64 + 6, &label, BLACK, 1);
            let y_tick = at(0.0, v);
            draw_text(&mut img, y_tick.x as i64 - tw as i64 - 6, y_tick.y as i64 - th as i64 / 2, &label, BLACK, 1);
        }
    }
    draw_line(&mut img, at(0.0, 0.0), at(1.0, 0.0), BLACK, 1);
    draw_line(&mut img, at(0.0, 0.0), at(0.0, 1.0), BLACK, 1);
    let (lw, _) = text_size("recall", 1);
    draw_text(&mut img, ((left + right) / 2.0) as i64 - lw as i64 / 2, bottom as i64 + 24, "recall", BLACK, 1);
    draw_text(&mut img, 8, top as i64 - 14, "precision", BLACK, 1);
    let (tw, _) = text_size(title, 2);
    draw_text(&mut img, (width as i64 - tw as i64) / 2, 8, title, BLACK, 2);

    for (&p, &r) in pr.precision.iter().zip(&pr.recall) {
        let dot = at(r, p);
        fill_rect(&mut img, dot.x.round() as i64 - 1, dot.y.round() as i64 - 1, 3, 3, [150, 150, 150]);
    }
    // The envelope as a step function: precision env[k] over (r[k-1], r[k]], so the area under the line is
    // exactly the AP of `interpolated_ap`.
    let mut envelope = pr.precision.clone();
    for k in (0..envelope.len().saturating_sub(1)).rev() {
        envelope[k] = envelope[k].max(envelope[k + 1]);
    }
    let mut previous_recall = 0.0f32;
    for (k, (&env, &r)) in envelope.iter().zip(&pr.recall).enumerate() {
        draw_line(&mut img, at(previous_recall, env), at(r, env), colour, 2);
        if let Some(&next) = envelope.get(k + 1) {
            draw_line(&mut img, at(r, env), at(r, next), colour, 2);
        }
        previous_recall = r;
    }
    img
}

// ---------------------------------------------------------------------------------------------------------
// Support surfaces

/// How close the detections' support surfaces ([`Detection::surface_z`]) lie to the true ones, over the
/// true positives of one category (the benchmark's matching at the given IoU).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SurfaceAccuracy {
    pub category: String,
    /// True positives, and of those the ones with an inferred surface and a known true one.
    pub true_positives: usize,
    pub measured: usize,
    /// Of `measured`, those within `tolerance_m` of the nearest of the object's true support surfaces, and
    /// of its main (first, topmost) one.
    pub within_nearest: usize,
    pub within_main: usize,
    /// Median distance to the nearest true surface (metres).
    pub median_error_m: Option<f32>,
    pub tolerance_m: f32,
    /// The distances to the nearest true surface of the `measured` true positives, ascending (metres; not
    /// written to JSON).
    #[serde(skip)]
    pub errors_m: Vec<f32>,
    /// `measured` and `within_main` split by the rule that gave the surface
    /// ([`Detection::surface_source`]; `"unknown"` for files written before it was recorded).
    pub by_source: BTreeMap<String, SourceAccuracy>,
}

/// One surface rule's share of a [`SurfaceAccuracy`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct SourceAccuracy {
    pub measured: usize,
    pub within_main: usize,
}

impl SurfaceAccuracy {
    /// Several categories' accuracies together (named `"all"`): the sums of their counts and the median over
    /// all their errors — how `eval --surfaces` states a target set on several categories at once (the
    /// accuracy issue's beds, tables, desks, dressers and nightstands). The parts share one tolerance.
    pub fn pooled(parts: &[SurfaceAccuracy]) -> SurfaceAccuracy {
        let mut all = SurfaceAccuracy { category: "all".to_string(), ..Default::default() };
        for part in parts {
            all.true_positives += part.true_positives;
            all.measured += part.measured;
            all.within_nearest += part.within_nearest;
            all.within_main += part.within_main;
            all.tolerance_m = part.tolerance_m;
            all.errors_m.extend(&part.errors_m);
            for (source, counts) in &part.by_source {
                let sum = all.by_source.entry(source.clone()).or_default();
                sum.measured += counts.measured;
                sum.within_main += counts.within_main;
            }
        }
        all.median_error_m = crate::frame::upper_median(&mut all.errors_m);
        all
    }
}

/// [`SurfaceAccuracy`] of `category`: `truth[i]` are image `i`'s annotated objects, `supports[i][k]` the
/// true support-surface heights (upright z, the main one first; empty when unknown) of its object `k`, and
/// `detections[i]` its detections.
pub fn surface_accuracy(
    truth: &[Vec<crate::frame::Object>],
    supports: &[Vec<Vec<f32>>],
    detections: &[Vec<Detection>],
    category: &str,
    iou_threshold: f32,
    tolerance_m: f32,
) -> SurfaceAccuracy {
    let boxes = scored_boxes(detections, category);
    let surfaces: Vec<(Option<f32>, Option<SurfaceSource>)> = detections
        .iter()
        .flat_map(|d| d.iter().filter(|d| d.category == category).map(|d| (d.surface_z, d.surface_source)))
        .collect();
    // Each image's true surfaces of the category's objects, in category_truth's order.
    let true_surfaces: Vec<Vec<&[f32]>> = truth
        .iter()
        .enumerate()
        .map(|(i, objects)| {
            objects
                .iter()
                .enumerate()
                .filter(|(_, o)| o.category == category)
                .map(|(k, _)| supports.get(i).and_then(|s| s.get(k)).map_or(&[][..], Vec::as_slice))
                .collect()
        })
        .collect();
    let matched = matched_truth_in_input_order(&boxes, &category_truth(truth, category), iou_threshold);
    let mut result = SurfaceAccuracy { category: category.to_string(), tolerance_m, ..Default::default() };
    let mut errors = Vec::new();
    for ((b, hit), (surface, source)) in boxes.iter().zip(&matched).zip(&surfaces) {
        let Some(g) = hit else { continue };
        result.true_positives += 1;
        let heights = true_surfaces[b.image][*g];
        let (Some(z), Some(&main)) = (surface, heights.first()) else { continue };
        result.measured += 1;
        let nearest = heights.iter().map(|h| (h - z).abs()).fold(f32::INFINITY, f32::min);
        let main_within = (main - z).abs() <= tolerance_m;
        result.within_nearest += (nearest <= tolerance_m) as usize;
        result.within_main += main_within as usize;
        let by_source = result.by_source.entry(source.map_or("unknown", SurfaceSource::name).to_string()).or_default();
        by_source.measured += 1;
        by_source.within_main += main_within as usize;
        errors.push(nearest);
    }
    result.median_error_m = crate::frame::upper_median(&mut errors);
    result.errors_m = errors;
    result
}
