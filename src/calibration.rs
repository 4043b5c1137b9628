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
//! The cascade's final calibration, one more map of its final scores, is [`final_calibration`].

use serde::{Deserialize, Serialize};

pub mod final_calibration;

use crate::error::{Error, Result};
use crate::eval::{average_precision, category_truth, Detection, ScoredBox};
use crate::frame::Object;

/// Smallest slope: keeps `p` strictly increasing in the raw score.
pub const MIN_SLOPE: f64 = 1e-3;
/// Fewest true positives for a calibration that `calibrate` does not warn about (our choice: about ten
/// events per fitted parameter is where a logistic fit's probabilities start to mean something).
pub const MIN_RELIABLE_TRUE_POSITIVES: usize = 20;
/// Largest magnitude of a stored calibration coefficient (the models' [`crate::model::MAX_WEIGHT`]): fits
/// on real scores give slopes and offsets of a few tens at most; beyond it a file is not a fitted
/// calibration, and would put every detection at probability 0 or 1.
pub const MAX_COEFFICIENT: f64 = 1e6;
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
    /// f32) is at least `p`: a raw-score cut that keeps exactly the detections with probability ≥ `p`
    /// (−∞ when every score reaches `p`, +∞ when none does). The computed probability is monotone in the
    /// raw score (σ of an increasing map, rounded), so the cut is found by bisection over the f32 values
    /// in their order (at most 32 evaluations). Stepping one f32 at a time from the closed form
    /// `(logit(p) − b) / a` (before 2026-12-08) took ~10⁹ steps — seconds per call, and `detect` calls it
    /// per frame and model — where the cut lies near 0 (e.g. `b = 0`, `p = 0.5`): there the f32 values
    /// are dense and the rounded probability is flat over most of them.
    pub fn raw_score_at(&self, p: f32) -> f32 {
        let reaches = |key: i64| self.probability(from_order_key(key)) >= p;
        let (mut below, mut at) = (order_key(f32::NEG_INFINITY), order_key(f32::INFINITY));
        if reaches(below) {
            return f32::NEG_INFINITY;
        }
        if !reaches(at) {
            return f32::INFINITY;
        }
        // Invariant: the probability at `below` is under p, at `at` it reaches p.
        while at - below > 1 {
            let middle = below + (at - below) / 2;
            if reaches(middle) {
                at = middle;
            } else {
                below = middle;
            }
        }
        from_order_key(at)
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

    /// Checks the stored numbers: finite, the slope in [[`MIN_SLOPE`], [`MAX_COEFFICIENT`]] (what a fit
    /// gives: monotone, and never so steep or so flat that every score becomes 1 or 0), the offset within
    /// ±[`MAX_COEFFICIENT`], the IoU in (0, 1].
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(self.a.is_finite() && self.b.is_finite()) {
            return Err(format!("calibration has a non-finite coefficient (a = {}, b = {})", self.a, self.b));
        }
        if !(MIN_SLOPE..=MAX_COEFFICIENT).contains(&self.a) {
            return Err(format!(
                "calibration slope a = {} must be in [{MIN_SLOPE}, {MAX_COEFFICIENT:e}] (a calibration must be \
                 monotone; a fit holds its slope at {MIN_SLOPE} at least)",
                self.a
            ));
        }
        if self.b.abs() > MAX_COEFFICIENT {
            return Err(format!(
                "calibration offset b = {} is beyond ±{MAX_COEFFICIENT:e}: not a fitted calibration",
                self.b
            ));
        }
        check_iou(self.iou)
    }
}

/// A stored fit's IoU threshold, the one that defined its true positives: in (0, 1], as `--iou`'s.
fn check_iou(iou: f32) -> std::result::Result<(), String> {
    if iou > 0.0 && iou <= 1.0 {
        Ok(())
    } else {
        Err(format!("calibration IoU {iou} must be in (0, 1]"))
    }
}

/// A non-NaN f32 as an integer in the floats' order (−∞ lowest, +∞ highest; −0 and +0 both 0): the
/// magnitude's bits, negated for negative numbers.
fn order_key(x: f32) -> i64 {
    let magnitude = i64::from(x.to_bits() & 0x7fff_ffff);
    if x.is_sign_negative() {
        -magnitude
    } else {
        magnitude
    }
}

/// The f32 of an [`order_key`] (0 is +0).
fn from_order_key(key: i64) -> f32 {
    let magnitude = key.unsigned_abs() as u32;
    f32::from_bits(if key < 0 { magnitude | 0x8000_0000 } else { magnitude })
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
    check_samples(samples, "calibration")?;
    let (a, b) = newton(samples, None);
    if a > MIN_SLOPE {
        return Ok((a, b));
    }
    Ok((MIN_SLOPE, newton(samples, Some(MIN_SLOPE)).1))
}

/// Errors (naming `what` is fitted) unless `samples` hold a true and a false positive and every score is
/// finite: what any fit of a probability needs.
fn check_samples(samples: &[(f32, bool)], what: &str) -> Result<()> {
    let positives = samples.iter().filter(|s| s.1).count();
    if positives == 0 || positives == samples.len() {
        return Err(Error::Input(format!(
            "{what} needs true and false positives; got {positives} true of {} detections",
            samples.len()
        )));
    }
    if samples.iter().any(|s| !s.0.is_finite()) {
        return Err(Error::Input(format!("{what}: a detection score is not finite")));
    }
    Ok(())
}

/// The penalised negative log-likelihood of `(a, b)`.
fn objective(samples: &[(f32, bool)], a: f64, b: f64) -> f64 {
    let mut total = 0.5 * PRIOR * (a * a + b * b);
    for &(s, y) in samples {
        total += negative_log_likelihood(a * f64::from(s) + b, y);
    }
    total
}

/// `−log σ(z)` for a true positive, `−log(1 − σ(z))` for a false one: `log(1 + e^{∓z})`, computed without
/// overflow.
fn negative_log_likelihood(z: f64, true_positive: bool) -> f64 {
    let t = if true_positive { -z } else { z };
    if t > 0.0 {
        t + (-t).exp().ln_1p()
    } else {
        t.exp().ln_1p()
    }
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
