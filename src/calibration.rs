//! Score calibration: the structural SVM ranks hypotheses **within** one frame (and against "no object"
//! at 0); AP over a test set and a person reading the overlay rank detections **across** frames and
//! categories. Each model therefore carries a calibration fitted on held-out frames that maps its raw
//! score `s = w·φ + bias` to the probability that a detection with that score is a true positive:
//!
//! ```text
//! p(s) = 1 / (1 + exp(−(a·s + b))),   a > 0
//! ```
//!
//! (Platt scaling). Choices:
//! * **Labels**: the detections of held-out frames (the output of `detect`, after NMS), matched with the
//!   SUN RGB-D benchmark's rules ([`crate::eval`]): sorted by raw score over all frames, a detection is a
//!   true positive when its best-overlapping ground-truth box of the category has 3D IoU ≥ the threshold
//!   (0.25) and is not yet taken. So `p` estimates exactly the precision that AP integrates.
//! * **Fit**: maximum likelihood by damped Newton's method on `(a, b)` with a weak Gaussian prior
//!   (`λ = 10⁻³` on both) so that separable data stays finite. **Monotone by construction**: if the fit
//!   gives `a ≤ a_min` (`10⁻³`), `a` is set to `a_min` and only `b` is fitted, so a higher raw score never
//!   gets a lower probability and the within-category order (hence the AP) is unchanged.
//! * At least one true and one false positive are needed; otherwise the fit is an error naming the
//!   category. With fewer than [`MIN_RELIABLE_TRUE_POSITIVES`] true positives the fit is made but
//!   flagged ([`Calibration::shortage`]; `calibrate` warns): two parameters from a handful of positives
//!   give probabilities that say little (the shipped TV's, from one, puts a raw score of 0 at 0.70).
//!
//! # The cascade's final calibration (our addition)
//! The context cascade ([`crate::cascade`]) calibrates each stage on its own training frames and then
//! demotes detections by cross-category exclusion, so its final scores need not hold as probabilities
//! (measured on held-out frames they were too low: README "The scores as probabilities"). A cascade file may
//! therefore carry one more Platt fit ([`crate::cascade::Cascade::final_calibration`]), applied last to every
//! detection's score `p`, whatever its category:
//!
//! ```text
//! p' = σ(a·logit(p) + b),   logit(p) = ln(p / (1 − p)),   a > 0
//! ```
//!
//! ([`Calibration::recalibrate`]; the same [`Calibration`] numbers, read on the log-odds of the score instead
//! of a raw score). Choices:
//! * **One map for all categories**: it is monotone in `p`, so it moves no detection past another — no AP,
//!   no overlay order changes (only f32 rounding can make two scores equal; it never swaps two) — and only
//!   what reads the scores as probabilities does (`detect`'s overlay threshold, `--min-probability`). A map
//!   per category would also reorder the categories, from far fewer true positives each: on the two halves
//!   of the selection set it fitted the other half worse than one map (README).
//! * **On the log-odds**: a Platt fit on `p` itself could not reach 0 and 1; on the log-odds, `a = 1, b = 0`
//!   is the identity, `b` a shift of all odds by `e^b`, `a` a sharpening or softening.
//! * **Fit** ([`fit_final_calibration`]): [`fit_logistic`] on `(logit(p), true positive)` over every
//!   detection of the chosen categories of held-out frames, each category's detections labelled by the
//!   benchmark's matching in the order of their scores (as [`label_scores`]). Scores of exactly 0 and 1
//!   (f32 rounding of the stages' σ) get the log-odds of the f32 rounding boundaries next to them
//!   ([`fit_log_odds`]); applied, the map keeps 0 and 1 where they are.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::eval::{
    average_precision, category_truth, chosen_or_annotated_categories, scored_boxes, true_positives_in_input_order,
    Detection, ScoredBox,
};
use crate::frame::Object;

/// Smallest slope: keeps `p` strictly increasing in the raw score.
pub const MIN_SLOPE: f64 = 1e-3;
/// Fewest true positives for a calibration that `calibrate` does not warn about (our choice: about ten
/// events per fitted parameter is where a logistic fit's probabilities start to mean something).
pub const MIN_RELIABLE_TRUE_POSITIVES: usize = 20;
/// Weight of the Gaussian prior on `(a, b)`.
const PRIOR: f64 = 1e-3;

/// A fitted calibration and where it came from (stored in the model file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// Slope on the raw score (> 0).
    pub a: f64,
    /// Offset.
    pub b: f64,
    /// Detections and true positives the fit saw, and the IoU that defined a true positive.
    pub detections: usize,
    pub true_positives: usize,
    pub iou: f32,
    /// Free-form provenance (data directory, frames).
    #[serde(default)]
    pub data: String,
    #[serde(default)]
    pub frames: usize,
}

impl Calibration {
    /// The calibrated probability of a raw score.
    pub fn probability(&self, raw: f32) -> f32 {
        sigmoid(self.a * f64::from(raw) + self.b) as f32
    }

    /// The smallest raw score whose calibrated probability ([`Calibration::probability`], as computed, in
    /// f32) is at least `p` (in (0, 1)): a raw-score cut that keeps exactly the detections with
    /// probability ≥ `p`. The closed form `(logit(p) − b) / a`, then stepped to the neighbouring f32 values
    /// until the computed probability crosses `p` (σ is monotone).
    pub fn raw_score_at(&self, p: f32) -> f32 {
        let p64 = f64::from(p);
        let mut raw = (((p64 / (1.0 - p64)).ln() - self.b) / self.a) as f32;
        while raw.is_finite() && self.probability(raw) < p {
            raw = raw.next_up();
        }
        while raw.is_finite() && self.probability(raw.next_down()) >= p {
            raw = raw.next_down();
        }
        raw
    }

    /// As a final calibration (module doc): `σ(a·logit(p) + b)` of a score `p` in [0, 1], computed in f64;
    /// 0 and 1 stay 0 and 1. Non-decreasing in `p` (strictly in f64; f32 rounding can only make two
    /// scores equal).
    pub fn recalibrate(&self, p: f32) -> f32 {
        if p <= 0.0 || p >= 1.0 {
            return p.clamp(0.0, 1.0);
        }
        let p = f64::from(p);
        sigmoid(self.a * (p / (1.0 - p)).ln() + self.b) as f32
    }

    /// Why this calibration's probabilities are not to be trusted, when it was fitted on fewer than
    /// [`MIN_RELIABLE_TRUE_POSITIVES`] true positives (`None` otherwise).
    pub fn shortage(&self) -> Option<String> {
        (self.true_positives < MIN_RELIABLE_TRUE_POSITIVES).then(|| {
            format!(
                "fitted on {} true positive(s) among {} detections (fewer than {MIN_RELIABLE_TRUE_POSITIVES}): its \
                 probabilities are unreliable; calibrate on held-out frames that hold more of the category",
                self.true_positives, self.detections
            )
        })
    }

    /// Checks the stored numbers (finite, slope positive).
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(self.a.is_finite() && self.b.is_finite()) {
            return Err(format!("calibration has a non-finite coefficient (a = {}, b = {})", self.a, self.b));
        }
        if self.a <= 0.0 {
            return Err(format!("calibration slope a = {} must be > 0 (a calibration must be monotone)", self.a));
        }
        Ok(())
    }
}

fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// Fits `p(s) = σ(a·s + b)` to `(score, is true positive)` pairs (see the module doc). Returns `(a, b)`.
pub fn fit_logistic(samples: &[(f32, bool)]) -> Result<(f64, f64)> {
    let positives = samples.iter().filter(|s| s.1).count();
    if positives == 0 || positives == samples.len() {
        return Err(Error::Input(format!(
            "calibration needs true and false positives; got {positives} true of {} detections",
            samples.len()
        )));
    }
    if samples.iter().any(|s| !s.0.is_finite()) {
        return Err(Error::Input("calibration: a detection score is not finite".into()));
    }
    let (a, b) = newton(samples, None);
    if a > MIN_SLOPE {
        return Ok((a, b));
    }
    Ok((MIN_SLOPE, newton(samples, Some(MIN_SLOPE)).1))
}

/// The penalised negative log-likelihood of `(a, b)`.
fn objective(samples: &[(f32, bool)], a: f64, b: f64) -> f64 {
    let mut total = 0.5 * PRIOR * (a * a + b * b);
    for &(s, y) in samples {
        let z = a * f64::from(s) + b;
        // −log σ(z) = log(1 + e^{−z}); −log(1 − σ(z)) = log(1 + e^{z}); computed without overflow.
        let t = if y { -z } else { z };
        total += if t > 0.0 { t + (-t).exp().ln_1p() } else { t.exp().ln_1p() };
    }
    total
}

/// Damped Newton's method on the penalised negative log-likelihood (the step is halved until the
/// objective decreases, so it cannot diverge); `fixed_a` fits `b` alone.
fn newton(samples: &[(f32, bool)], fixed_a: Option<f64>) -> (f64, f64) {
    let (mut a, mut b) = (fixed_a.unwrap_or(1.0), 0.0f64);
    let mut current = objective(samples, a, b);
    for _ in 0..200 {
        // Gradient and Hessian of Σ −log-likelihood + PRIOR/2 (a² + b²).
        let (mut ga, mut gb, mut haa, mut hab, mut hbb) = (PRIOR * a, PRIOR * b, PRIOR, 0.0, PRIOR);
        for &(s, y) in samples {
            let s = f64::from(s);
            let p = sigmoid(a * s + b);
            let r = p - if y { 1.0 } else { 0.0 };
            let w = (p * (1.0 - p)).max(1e-12);
            ga += r * s;
            gb += r;
            haa += w * s * s;
            hab += w * s;
            hbb += w;
        }
        let (da, db) = if fixed_a.is_some() {
            (0.0, gb / hbb)
        } else {
            let det = haa * hbb - hab * hab;
            if det.abs() < 1e-300 {
                break;
            }
            ((hbb * ga - hab * gb) / det, (haa * gb - hab * ga) / det)
        };
        let mut step = 1.0;
        let mut improved = false;
        for _ in 0..40 {
            let (na, nb) = (a - step * da, b - step * db);
            let value = objective(samples, na, nb);
            if value <= current {
                (a, b, current, improved) = (na, nb, value, true);
                break;
            }
            step *= 0.5;
        }
        let small = (step * da).abs() < 1e-10 * (1.0 + a.abs()) && (step * db).abs() < 1e-10 * (1.0 + b.abs());
        if !improved || small {
            break;
        }
    }
    (a, b)
}

/// Log-odds of 1.0 in a final-calibration fit: those of `1 − 2⁻²⁵`, the smallest probability that f32
/// rounds to 1 (module doc).
pub const LOG_ODDS_OF_ONE: f32 = 17.328_68;
/// Log-odds of 0.0 in a final-calibration fit: those of `2⁻¹⁵⁰`, below which f32 rounds to 0.
pub const LOG_ODDS_OF_ZERO: f32 = -103.972_08;

/// The log-odds `ln(p / (1 − p))` of a score `p` in [0, 1] for a final-calibration fit (module doc): finite
/// also at 0 and 1 ([`LOG_ODDS_OF_ZERO`], [`LOG_ODDS_OF_ONE`]).
pub fn fit_log_odds(p: f32) -> f32 {
    if p <= 0.0 {
        return LOG_ODDS_OF_ZERO;
    }
    if p >= 1.0 {
        return LOG_ODDS_OF_ONE;
    }
    let p = f64::from(p);
    ((p / (1.0 - p)).ln() as f32).clamp(LOG_ODDS_OF_ZERO, LOG_ODDS_OF_ONE)
}

/// Labels the detections of one category over several frames by their **`score`** (not the raw score
/// [`label_detections`] reads): `(score, true positive)` per detection in input order (frame by frame),
/// matched with the benchmark's rules in score order.
pub fn label_scores(
    detections: &[Vec<Detection>],
    truth: &[Vec<Object>],
    category: &str,
    iou: f32,
) -> Vec<(f32, bool)> {
    let boxes = scored_boxes(detections, category);
    let labels = true_positives_in_input_order(&boxes, &category_truth(truth, category), iou);
    boxes.iter().map(|b| b.score).zip(labels).collect()
}

/// What [`fit_final_calibration`] found on held-out frames: the fitted map, the categories whose
/// detections it saw, and how the scores held as probabilities before and after it (mean negative
/// log-likelihood of the labels, probabilities clamped to [10⁻⁶, 1 − 10⁻⁶]; expected true positives = the
/// sum of the probabilities; the map's `true_positives` is the number found).
#[derive(Clone, Debug, PartialEq)]
pub struct FinalCalibrationFit {
    pub calibration: Calibration,
    pub categories: Vec<String>,
    pub log_loss_before: f64,
    pub log_loss_after: f64,
    pub expected_true_positives_before: f64,
    pub expected_true_positives_after: f64,
}

/// Fits a final calibration (module doc) on held-out frames: `detections[f]` are frame `f`'s detections
/// with the scores to be mapped (the cascade's after its exclusion, [`crate::cascade::Cascade::rescore`]
/// without a final calibration), `truth[f]` its annotated objects. Every detection of `categories` (empty:
/// every cog-gpu category with ground truth in `truth`) is labelled at `iou` ([`label_scores`]); `data`
/// names the frames in the result's provenance. Errors when the detections hold no true or no false positive.
pub fn fit_final_calibration(
    detections: &[Vec<Detection>],
    truth: &[Vec<Object>],
    categories: &[String],
    iou: f32,
    data: &str,
) -> Result<FinalCalibrationFit> {
    let categories = chosen_or_annotated_categories(categories, truth);
    let scores: Vec<(f32, bool)> =
        categories.iter().flat_map(|category| label_scores(detections, truth, category, iou)).collect();
    let log_odds: Vec<(f32, bool)> = scores.iter().map(|&(p, y)| (fit_log_odds(p), y)).collect();
    let (a, b) = fit_logistic(&log_odds).map_err(|e| Error::Input(format!("final calibration: {e}")))?;
    let calibration = Calibration {
        a,
        b,
        detections: scores.len(),
        true_positives: scores.iter().filter(|s| s.1).count(),
        iou,
        data: data.to_string(),
        frames: truth.len(),
    };
    let loss = |map: &dyn Fn(f32) -> f32| {
        let total: f64 = scores
            .iter()
            .map(|&(p, y)| {
                let p = f64::from(map(p)).clamp(1e-6, 1.0 - 1e-6);
                -(if y { p } else { 1.0 - p }).ln()
            })
            .sum();
        total / scores.len() as f64
    };
    Ok(FinalCalibrationFit {
        log_loss_before: loss(&|p| p),
        log_loss_after: loss(&|p| calibration.recalibrate(p)),
        expected_true_positives_before: scores.iter().map(|&(p, _)| f64::from(p)).sum(),
        expected_true_positives_after: scores.iter().map(|&(p, _)| f64::from(calibration.recalibrate(p))).sum(),
        calibration,
        categories,
    })
}

/// Labels the detections of one category over several frames with the benchmark's matching rules:
/// returns `(raw score, true positive)` per detection, in descending score order (ties in input order).
/// `detections[f]` and `truth[f]` are frame `f`'s detections and annotated objects (any categories; only
/// `category` is used). The raw score is [`Detection::raw_score`] when present, else `score`.
pub fn label_detections(
    detections: &[Vec<Detection>],
    truth: &[Vec<Object>],
    category: &str,
    iou_threshold: f32,
) -> Vec<(f32, bool)> {
    let boxes: Vec<ScoredBox> = detections
        .iter()
        .enumerate()
        .flat_map(|(image, dets)| {
            dets.iter().filter(|d| d.category == category).map(move |d| ScoredBox {
                image,
                score: d.raw_score.unwrap_or(d.score),
                cuboid: d.cuboid(),
            })
        })
        .collect();
    // The benchmark's matching (eval::average_precision) labels the boxes in its score order: a stable
    // descending sort, which the scores are put in here too.
    let ground_truth = category_truth(truth, category);
    let labels = average_precision(&boxes, &ground_truth, iou_threshold).true_positive;
    let mut scores: Vec<f32> = boxes.iter().map(|b| b.score).collect();
    scores.sort_by(|x, y| y.total_cmp(x));
    scores.into_iter().zip(labels).collect()
}
