//! The cascade's final calibration (our addition): one more map of every detection's score, applied last.
//!
//! The context cascade ([`crate::cascade`]) calibrates each stage on its own training frames and then
//! demotes detections by cross-category exclusion, so its final scores need not hold as probabilities
//! (on held-out frames they were too low in the middle and a little too high at the top: README "The
//! scores as probabilities"). A cascade file may therefore carry one more map
//! ([`crate::cascade::Cascade::final_calibration`]), applied to every detection's score `p` whatever its
//! category — **beta calibration** (Kull, Silva Filho & Flach, "Beyond sigmoids: how to obtain
//! well-calibrated probabilities from binary classifiers with beta calibration", EJS 2017):
//!
//! ```text
//! logit p' = a·ln p − b·ln(1 − p) + c,   a, b ≥ 10⁻³
//! ```
//!
//! ([`FinalCalibration::recalibrate`]). Choices:
//! * **One map for all categories, strictly increasing**: with `a, b > 0` a higher score never maps below a
//!   lower one, so no detection passes another — no AP, no top-k overlay order changes (f32 rounding can
//!   only make two scores equal, never swap them) — and only what reads the scores as probabilities does
//!   (`detect`'s overlay threshold, `--min-probability`, a user). A map per category would also reorder the
//!   categories, from far fewer true positives each: on the two halves of the selection set it fitted the
//!   other half worse than one map (README, "The cascade's final calibration").
//! * **Beta, not Platt on the log-odds**: `a = b` is the Platt map `σ(a·logit p + c)` (`a = b = 1, c = 0`
//!   the identity); with `a ≠ b` the map can lift the low scores and lower the top ones at once, the shape
//!   the cascade's scores need, which a shift and a slope of the log-odds cannot follow. Measured on the
//!   halves (README): it fits the other half better than the two-parameter map, and about as well as a
//!   log-odds map with two slopes, which needs a knot to be chosen.
//! * **Fit** ([`fit_final_calibration`]): maximum likelihood of `(ln p, −ln(1 − p), true positive)` over every
//!   detection of the chosen categories of held-out frames, each category's detections labelled by the
//!   benchmark's matching in the order of their scores ([`label_scores`]); damped Newton's method with the
//!   first-stage calibration's weak prior, from the identity. A slope that comes out below
//!   [`MIN_SLOPE`] is held there and the rest refitted (Kull et al. drop the term; we keep
//!   it at the minimum so that the map stays strictly increasing). Scores of exactly 0 and 1 (f32 rounding
//!   of the stages' σ) count as the f32 rounding boundaries next to them ([`FIT_MIN_SCORE`],
//!   [`FIT_MAX_SCORE`]); applied, the map keeps 0 and 1 where they are.

use serde::{Deserialize, Serialize};

use super::{check_iou, check_samples, negative_log_likelihood, sigmoid, MAX_COEFFICIENT, MIN_SLOPE, PRIOR};
use crate::error::Result;
use crate::eval::{
    category_truth, chosen_or_annotated_categories, scored_boxes, true_positives_in_input_order, Detection,
};
use crate::frame::Object;

/// The smallest score a fit reads: `2⁻¹⁵⁰`, below which f32 rounds to 0 (a score of 0 counts as this).
pub const FIT_MIN_SCORE: f64 = 7.006_492_321_624_085e-46;
/// The largest score a fit reads: `1 − 2⁻²⁵`, from which f32 rounds to 1 (a score of 1 counts as this).
pub const FIT_MAX_SCORE: f64 = 0.999_999_970_197_677_6;

/// A fitted final calibration (module doc) and where it came from, stored in the cascade file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FinalCalibration {
    /// Weight of `ln p` (≥ [`MIN_SLOPE`]).
    pub a: f64,
    /// Weight of `−ln(1 − p)` (≥ [`MIN_SLOPE`]).
    pub b: f64,
    /// Offset.
    pub c: f64,
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

impl FinalCalibration {
    /// The map of a score `p` in [0, 1] (module doc), computed in f64; 0 and 1 stay 0 and 1. Increasing in
    /// `p` (strictly in f64; f32 rounding can only make two scores equal).
    pub fn recalibrate(&self, p: f32) -> f32 {
        if p <= 0.0 || p >= 1.0 {
            return p.clamp(0.0, 1.0);
        }
        let [ln_p, minus_ln_q] = log_features(f64::from(p));
        sigmoid(self.a * ln_p + self.b * minus_ln_q + self.c) as f32
    }

    /// Maps every detection's score of one frame (`detections`, in place) and sorts them by score, best
    /// first (stable; the map keeps their order but for f32 ties): each keeps the score before it in
    /// [`Detection::score_before_final_calibration`]. The one place the map meets detections
    /// ([`crate::cascade::Cascade::rescore`], `calibrate --cascade --final`'s report).
    pub fn apply(&self, detections: &mut [Detection]) {
        for d in detections.iter_mut() {
            d.score_before_final_calibration = Some(d.score);
            d.score = self.recalibrate(d.score);
        }
        detections.sort_by(|a, b| b.score.total_cmp(&a.score));
    }

    /// Checks the stored numbers: finite, both slopes in [[`MIN_SLOPE`], [`MAX_COEFFICIENT`]] (increasing,
    /// as a fit leaves them), the offset within ±[`MAX_COEFFICIENT`], the IoU in (0, 1].
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(self.a.is_finite() && self.b.is_finite() && self.c.is_finite()) {
            return Err(format!(
                "final calibration has a non-finite coefficient (a = {}, b = {}, c = {})",
                self.a, self.b, self.c
            ));
        }
        let slope = MIN_SLOPE..=MAX_COEFFICIENT;
        if !(slope.contains(&self.a) && slope.contains(&self.b)) {
            return Err(format!(
                "final calibration slopes a = {}, b = {} must be in [{MIN_SLOPE}, {MAX_COEFFICIENT:e}] (the map must \
                 be increasing; a fit holds them at {MIN_SLOPE} at least)",
                self.a, self.b
            ));
        }
        if self.c.abs() > MAX_COEFFICIENT {
            return Err(format!(
                "final calibration offset c = {} is beyond ±{MAX_COEFFICIENT:e}: not a fitted map",
                self.c
            ));
        }
        check_iou(self.iou).map_err(|e| format!("final {e}"))
    }
}

/// `[ln p, −ln(1 − p)]`, the map's two terms.
fn log_features(p: f64) -> [f64; 2] {
    [p.ln(), -(-p).ln_1p()]
}

/// The two terms of a score as a fit reads them: the score clamped to [[`FIT_MIN_SCORE`], [`FIT_MAX_SCORE`]]
/// first (module doc), so that they are finite.
pub fn fit_features(p: f32) -> [f64; 2] {
    log_features(f64::from(p).clamp(FIT_MIN_SCORE, FIT_MAX_SCORE))
}

/// Labels the detections of one category over several frames by their **`score`** (not the raw score
/// [`super::label_detections`] reads): `(score, true positive)` per detection in input order (frame by
/// frame), matched with the benchmark's rules in score order.
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

/// How scores hold as probabilities on labelled detections: the mean negative log-likelihood of the labels
/// (probabilities clamped to [10⁻⁶, 1 − 10⁻⁶], so that one confident mistake is a large loss, not an
/// infinite one) and the true positives they expect (the sum of the probabilities).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScoreSummary {
    pub log_loss: f64,
    pub expected_true_positives: f64,
}

impl ScoreSummary {
    /// The summary of `scores` (`(score, true positive)` pairs) read through `map`.
    pub fn of(scores: &[(f32, bool)], map: impl Fn(f32) -> f32) -> ScoreSummary {
        let (mut loss, mut expected) = (0.0, 0.0);
        for &(score, true_positive) in scores {
            let p = f64::from(map(score));
            expected += p;
            let p = p.clamp(1e-6, 1.0 - 1e-6);
            loss -= (if true_positive { p } else { 1.0 - p }).ln();
        }
        ScoreSummary { log_loss: loss / scores.len().max(1) as f64, expected_true_positives: expected }
    }
}

/// What [`fit_final_calibration`] found on held-out frames: the fitted map (its `true_positives` is the
/// number found), the categories whose detections it saw, and how the scores held as probabilities without
/// a map (`before`), with the fitted one (`after`) and with `stored`, the map given to compare with (a
/// cascade file's), if any.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalCalibrationFit {
    pub calibration: FinalCalibration,
    pub categories: Vec<String>,
    pub before: ScoreSummary,
    pub after: ScoreSummary,
    pub stored: Option<ScoreSummary>,
}

/// Fits a final calibration (module doc) on held-out frames: `detections[f]` are frame `f`'s detections
/// with the scores to be mapped (the cascade's after its exclusion,
/// [`crate::cascade::Cascade::rescore_before_final_calibration`]), `truth[f]` its annotated objects. Every
/// detection of `categories` (empty: every cog-gpu category with ground truth in `truth`) is labelled at
/// `iou` ([`label_scores`]); `data` names the frames in the result's provenance; `stored` (a cascade file's
/// map) is summarised on the same detections. Errors when the detections hold no true or no false
/// positive.
pub fn fit_final_calibration(
    detections: &[Vec<Detection>],
    truth: &[Vec<Object>],
    categories: &[String],
    iou: f32,
    data: &str,
    stored: Option<&FinalCalibration>,
) -> Result<FinalCalibrationFit> {
    let categories = chosen_or_annotated_categories(categories, truth);
    let scores: Vec<(f32, bool)> =
        categories.iter().flat_map(|category| label_scores(detections, truth, category, iou)).collect();
    let [a, b, c] = fit_beta(&scores)?;
    let calibration = FinalCalibration {
        a,
        b,
        c,
        detections: scores.len(),
        true_positives: scores.iter().filter(|s| s.1).count(),
        iou,
        data: data.to_string(),
        frames: truth.len(),
    };
    Ok(FinalCalibrationFit {
        before: ScoreSummary::of(&scores, |p| p),
        after: ScoreSummary::of(&scores, |p| calibration.recalibrate(p)),
        stored: stored.map(|map| ScoreSummary::of(&scores, |p| map.recalibrate(p))),
        calibration,
        categories,
    })
}

/// `[a, b, c]` of the map fitted to `(score, true positive)` pairs (module doc): unconstrained first, then
/// with each slope that came out below [`MIN_SLOPE`] held there, until none does.
fn fit_beta(scores: &[(f32, bool)]) -> Result<[f64; 3]> {
    check_samples(scores, "final calibration")?;
    let samples: Vec<([f64; 2], bool)> = scores.iter().map(|&(p, y)| (fit_features(p), y)).collect();
    let mut fixed = [None, None];
    loop {
        let theta = newton(&samples, fixed);
        let low: Vec<usize> = (0..2).filter(|&k| fixed[k].is_none() && theta[k] < MIN_SLOPE).collect();
        if low.is_empty() {
            return Ok(theta);
        }
        for k in low {
            fixed[k] = Some(MIN_SLOPE);
        }
    }
}

/// The penalised negative log-likelihood of `theta = [a, b, c]`.
fn objective(samples: &[([f64; 2], bool)], theta: &[f64; 3]) -> f64 {
    let prior = 0.5 * PRIOR * theta.iter().map(|t| t * t).sum::<f64>();
    prior + samples.iter().map(|&(x, y)| negative_log_likelihood(linear(theta, &x), y)).sum::<f64>()
}

/// `a·x₀ + b·x₁ + c`.
fn linear(theta: &[f64; 3], x: &[f64; 2]) -> f64 {
    theta[0] * x[0] + theta[1] * x[1] + theta[2]
}

/// Damped Newton's method on [`objective`] from the identity map (`a = b = 1, c = 0`; the step halved until
/// the objective decreases, so it cannot diverge); a slope given in `fixed` keeps that value.
fn newton(samples: &[([f64; 2], bool)], fixed: [Option<f64>; 2]) -> [f64; 3] {
    let mut theta = [fixed[0].unwrap_or(1.0), fixed[1].unwrap_or(1.0), 0.0];
    let mut current = objective(samples, &theta);
    for _ in 0..200 {
        let mut gradient = theta.map(|t| PRIOR * t);
        let mut hessian = [[PRIOR, 0.0, 0.0], [0.0, PRIOR, 0.0], [0.0, 0.0, PRIOR]];
        for (x, y) in samples {
            let row = [x[0], x[1], 1.0];
            let p = sigmoid(linear(&theta, x));
            let residual = p - f64::from(u8::from(*y));
            let weight = (p * (1.0 - p)).max(1e-12);
            for k in 0..3 {
                gradient[k] += residual * row[k];
                for l in 0..3 {
                    hessian[k][l] += weight * row[k] * row[l];
                }
            }
        }
        // A held slope does not move: its equation of the Newton system reads "step = 0".
        for k in (0..2).filter(|&k| fixed[k].is_some()) {
            gradient[k] = 0.0;
            for row in hessian.iter_mut() {
                row[k] = 0.0;
            }
            hessian[k] = [0.0; 3];
            hessian[k][k] = 1.0;
        }
        let Some(direction) = solve_3x3(&hessian, &gradient) else { break };
        let mut step = 1.0;
        let mut improved = false;
        for _ in 0..40 {
            let candidate = [0, 1, 2].map(|k| theta[k] - step * direction[k]);
            let value = objective(samples, &candidate);
            if value <= current {
                (theta, current, improved) = (candidate, value, true);
                break;
            }
            step *= 0.5;
        }
        let small = (0..3).all(|k| (step * direction[k]).abs() < 1e-10 * (1.0 + theta[k].abs()));
        if !improved || small {
            break;
        }
    }
    theta
}

/// `m⁻¹ v` by Cramer's rule; `None` when `m` is singular.
fn solve_3x3(m: &[[f64; 3]; 3], v: &[f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    if !d.is_finite() || d.abs() < 1e-300 {
        return None;
    }
    Some([0, 1, 2].map(|k| {
        let mut replaced = *m;
        for (row, value) in replaced.iter_mut().zip(v) {
            row[k] = *value;
        }
        det(&replaced) / d
    }))
}
