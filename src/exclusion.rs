//! Cross-category exclusion (our addition after the paper's context cascade, §6): one piece of furniture
//! is one object, so a box that another category claims with more confidence is less likely to be this
//! category's.
//!
//! The first stage and the cascade score each category on its own, and their diagnosis (`eval --diagnose`,
//! README "Diagnosis: `cog-gpu eval --diagnose`") finds most of the remaining false positives of the confusable
//! categories on objects of another one: tables on desks, dressers on counters, garbage bins on boxes. The
//! cascade's overlap features see the other category's detection, but a linear stage cannot say "the
//! other one is *more* confident than I am". This step does, after the cascade:
//!
//! ```text
//!   p'_i = p_i · (1 − weight · max { p_j : category_j ≠ category_i, IoU_3D(i, j) ≥ iou, p_j > p_i })
//! ```
//!
//! (no such `j`: `p'_i = p_i`). Choices:
//! * `p` is the detection's `score` before exclusion (the cascade's calibrated probability, or the first
//!   stage's for a category without a stage), for `i` and for every competitor `j`: one pass over the
//!   scores as they came, so the result does not depend on the detections' order, and a category's scores
//!   depend only on its own parameters and the other categories' *input* scores — demoting the tables
//!   never changes a desk.
//! * Only a strictly more confident competitor demotes (`p_j > p_i`): of two boxes on one object the less
//!   likely reading gives way; the more likely one is left alone.
//! * The factor `1 − weight · p_j` (≥ 0 for `weight` ≤ 1): the more confident the competitor, the more the
//!   detection is demoted; a detection is never removed, so recall is unchanged and only the ranking moves.
//! * Overlap by 3D IoU ([`crate::geometry::iou_3d`], as the benchmark's), with a low threshold: confusions
//!   are boxes of similar sizes on the same object, while a pillow on a bed or a monitor on a desk have a
//!   3D IoU near zero (a pillow's volume is about 1 % of a bed's).
//! * `iou` and `weight` are fitted on held-out frames ([`fit_exclusion`], `cog-gpu calibrate --cascade C
//!   --exclusion`) over [`IOU_GRID`] × [`WEIGHT_GRID`] by the mean AP of the chosen categories; ties go to
//!   the smaller weight, then the smaller IoU; a best weight of 0 means no exclusion. One pair for all
//!   categories: a pair per category (19 times the parameters) did about as well on the other half of the
//!   selection set, +1.0 against +0.9 19-class mAP over the two halves (README, "Cross-category
//!   exclusion").
//!
//! The parameters live in the cascade file ([`crate::cascade::Cascade::exclusion`]): the step is applied
//! with the cascade (`detect`, `rescore`) and never to first-stage files, which stay the cascade's input.

use serde::{Deserialize, Serialize};

use crate::eval::{chosen_or_annotated_categories, evaluate_categories, mean_ap, Detection};
use crate::frame::Object;
use crate::geometry::iou_3d;

/// The exclusion's parameters (module doc).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Exclusion {
    /// The 3D IoU from which a more confident detection of another category demotes a detection.
    pub iou: f32,
    /// How much: the score is multiplied by `1 − weight · p_j`; in [0, 1].
    pub weight: f32,
}

/// The IoU thresholds [`fit_exclusion`] tries.
pub const IOU_GRID: [f32; 5] = [0.02, 0.05, 0.1, 0.2, 0.3];
/// The weights [`fit_exclusion`] tries (0: no exclusion).
pub const WEIGHT_GRID: [f32; 5] = [0.0, 0.25, 0.5, 0.75, 1.0];

impl Exclusion {
    /// The parameters are usable: `iou` in (0, 1], `weight` in [0, 1].
    pub fn check(&self) -> std::result::Result<(), String> {
        if !(self.iou > 0.0 && self.iou <= 1.0) {
            return Err(format!("exclusion IoU {} is not in (0, 1]", self.iou));
        }
        if !(0.0..=1.0).contains(&self.weight) {
            return Err(format!("exclusion weight {} is not in [0, 1]", self.weight));
        }
        Ok(())
    }

    /// Demotes `detections` (one frame's) in place (module doc): a demoted detection's `score` becomes
    /// `p_i · (1 − weight · p_j)`, its [`Detection::score_before_exclusion`] keeps `p_i` and
    /// [`Detection::excluded_by`] names the competitor's category. The order of `detections` is kept.
    pub fn apply(&self, detections: &mut [Detection]) {
        let competitors = competitors(detections, self.iou);
        for (d, competing) in detections.iter_mut().zip(competitors) {
            let Some((factor, by)) = self.demotion(&competing) else { continue };
            if factor < 1.0 {
                d.score_before_exclusion = Some(d.score);
                d.excluded_by = Some(by.category.clone());
                d.score *= factor;
            }
        }
    }

    /// The factor `1 − weight · p_j` a detection's score is multiplied by, and the competitor `j` that
    /// sets it: the most confident of `competing` (the detection's [`competitors`], of any IoU) with an
    /// IoU of at least `iou`; `None` when there is none. The one formula of [`Exclusion::apply`] and
    /// [`fit_exclusion`].
    pub fn demotion<'a>(&self, competing: &'a [Competitor]) -> Option<(f32, &'a Competitor)> {
        let strongest = competing.iter().filter(|c| c.iou >= self.iou).max_by(|a, b| a.score.total_cmp(&b.score))?;
        Some((1.0 - self.weight * strongest.score, strongest))
    }
}

/// A more confident detection of another category overlapping a detection: its IoU with it, its score, its
/// category.
#[derive(Clone, Debug, PartialEq)]
pub struct Competitor {
    pub iou: f32,
    pub score: f32,
    pub category: String,
}

/// For each of `detections` (one frame's), every detection of another category with a strictly higher
/// score and a 3D IoU of at least `min_iou` with it, in the detections' order.
pub fn competitors(detections: &[Detection], min_iou: f32) -> Vec<Vec<Competitor>> {
    let boxes: Vec<_> = detections.iter().map(|d| d.cuboid()).collect();
    // Centre distance beyond the sum of the boxes' half diagonals: no overlap (skips most IoU computations).
    let radii: Vec<f32> = boxes.iter().map(|b| 0.5 * b.size.length()).collect();
    (0..detections.len())
        .map(|i| {
            (0..detections.len())
                .filter(|&j| {
                    detections[j].category != detections[i].category && detections[j].score > detections[i].score
                })
                .filter(|&j| boxes[i].centre.distance(boxes[j].centre) < radii[i] + radii[j])
                .filter_map(|j| {
                    let iou = iou_3d(&boxes[i], &boxes[j]);
                    (iou >= min_iou).then(|| Competitor {
                        iou,
                        score: detections[j].score,
                        category: detections[j].category.clone(),
                    })
                })
                .collect()
        })
        .collect()
}

/// One pair of parameters tried by [`fit_exclusion`]: the mean AP and each category's AP (`None`: no
/// ground truth) it gives the held-out frames.
#[derive(Clone, Debug, PartialEq)]
pub struct ExclusionTrial {
    pub exclusion: Exclusion,
    pub mean_ap: Option<f32>,
    pub aps: Vec<Option<f32>>,
}

/// What [`fit_exclusion`] found: every trial (weight 0 once, as `WEIGHT_GRID`'s first, with the smallest
/// IoU), the categories in the order of each trial's `aps`, and the chosen parameters (`None` when no
/// weight above 0 raises the mean AP).
#[derive(Clone, Debug, PartialEq)]
pub struct ExclusionFit {
    pub categories: Vec<String>,
    pub trials: Vec<ExclusionTrial>,
    pub chosen: Option<Exclusion>,
}

impl ExclusionFit {
    /// The trial without exclusion (weight 0).
    pub fn without(&self) -> &ExclusionTrial {
        &self.trials[0]
    }

    /// The chosen trial (the one without exclusion when nothing was chosen).
    pub fn best(&self) -> &ExclusionTrial {
        self.chosen.and_then(|c| self.trials.iter().find(|t| t.exclusion == c)).unwrap_or(self.without())
    }
}

/// Fits the exclusion's parameters (module doc) on held-out frames: `detections[f]` are frame `f`'s
/// detections as the cascade scored them (without exclusion), `truth[f]` its annotated objects. Every
/// pair of [`IOU_GRID`] × [`WEIGHT_GRID`] is applied and scored by the mean AP over `categories` (empty:
/// every cog-gpu category with ground truth) at `iou_threshold`; the best pair wins, ties to the smaller
/// weight, then the smaller IoU, and a weight of 0 (no exclusion) wins its ties.
pub fn fit_exclusion(
    detections: &[Vec<Detection>],
    truth: &[Vec<Object>],
    categories: &[String],
    iou_threshold: f32,
) -> ExclusionFit {
    let categories = chosen_or_annotated_categories(categories, truth);
    // Only what the AP reads: the category, the box and the score (not the cross scores, cloned per trial).
    let detections: Vec<Vec<Detection>> = detections
        .iter()
        .map(|frame| frame.iter().map(|d| Detection::new(d.category.clone(), &d.cuboid(), d.score)).collect())
        .collect();
    let all_competitors: Vec<Vec<Vec<Competitor>>> = {
        use rayon::prelude::*;
        detections.par_iter().map(|frame| competitors(frame, IOU_GRID[0])).collect()
    };
    let trial = |exclusion: Exclusion| {
        let demoted: Vec<Vec<Detection>> = detections
            .iter()
            .zip(&all_competitors)
            .map(|(frame, competitors)| {
                frame
                    .iter()
                    .zip(competitors)
                    .map(|(d, competing)| {
                        let mut demoted = d.clone();
                        if let Some((factor, _)) = exclusion.demotion(competing) {
                            demoted.score *= factor;
                        }
                        demoted
                    })
                    .collect()
            })
            .collect();
        let aps: Vec<Option<f32>> =
            evaluate_categories(truth, &demoted, &categories, iou_threshold).iter().map(|e| e.pr.ap).collect();
        ExclusionTrial { exclusion, mean_ap: mean_ap(&aps), aps }
    };
    let mut trials = vec![trial(Exclusion { iou: IOU_GRID[0], weight: 0.0 })];
    for &weight in &WEIGHT_GRID[1..] {
        for &iou in &IOU_GRID {
            trials.push(trial(Exclusion { iou, weight }));
        }
    }
    // The first trial with the highest mean AP, in the order tried (weight 0 first, then the smaller
    // weight, then the smaller IoU): ties to the smaller change.
    let mut best = 0;
    for (n, t) in trials.iter().enumerate() {
        if t.mean_ap.unwrap_or(f32::NEG_INFINITY) > trials[best].mean_ap.unwrap_or(f32::NEG_INFINITY) {
            best = n;
        }
    }
    let chosen = (best > 0).then_some(trials[best].exclusion);
    ExclusionFit { categories, trials, chosen }
}
