//! The 1-slack formulation of the structural SVM (Joachims, Finley & Yu 2009, §4) on top of the n-slack
//! solver, as an oracle wrapper.
//!
//! ```text
//! min_{w, ξ ≥ 0}  ½‖w‖² + C ξ
//! s.t.  (1/n) Σ_i wᵀψ_i(ȳ_i) ≥ (1/n) Σ_i Δ(y_i, ȳ_i) − ξ    for all (ȳ_1, …, ȳ_n)
//! ```
//!
//! has the same optimum `w` as the n-slack problem of [`super::ssvm`] with `(C/n) Σ ξ_i` (Theorem 1 of
//! that paper), but its cutting-plane loop adds **one** aggregated constraint per iteration instead of up
//! to n. With thousands of examples the n-slack working set grows to thousands of 12k-dimensional
//! constraints and the dense QP (clarabel) takes seconds to minutes per solve; the 1-slack working set
//! stays at tens to a few hundred constraints, and the number of iterations to reach ε does not grow
//! with n.
//!
//! [`OneSlack`] presents an oracle with n examples as an oracle with **one** example: its ground truth is
//! the mean of the n ground-truth feature vectors, its most violated output the mean of the n most
//! violated outputs' features with the mean loss. Run through [`super::CuttingPlane`] unchanged (one
//! example: the slack bound is C), this is exactly the 1-slack cutting-plane algorithm. ε is then a
//! tolerance on the **mean** violation over the examples (the paper's 1-slack ε), not on each example's.

use std::sync::Mutex;

use rayon::prelude::*;

use super::checkpoint::{fnv1a, FNV_OFFSET};
use super::{Constraint, SeparationOracle};
use crate::error::{Error, Result};

/// Per-example figures of the latest pass, for reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PassSummary {
    /// Examples whose most violated output has positive slack `Δ − wᵀψ_i > 0`.
    pub examples_with_slack: usize,
    /// The largest per-example slack `Δ − wᵀψ_i` (the n-slack "largest violation" at an empty working set).
    pub max_example_slack: f64,
    /// Mean loss of the most violated outputs.
    pub mean_loss: f64,
}

/// An n-example oracle seen as the single example of the 1-slack problem (see the module doc).
pub struct OneSlack<'a, O: SeparationOracle + ?Sized> {
    inner: &'a O,
    ground_truth: Vec<Vec<f32>>,
    mean_ground_truth: Vec<f32>,
    /// The inner examples' fingerprints folded in order: the one example's identity.
    fingerprint: u64,
    last: Mutex<PassSummary>,
}

impl<'a, O: SeparationOracle + ?Sized> OneSlack<'a, O> {
    /// Reads the inner oracle's ground-truth features once.
    pub fn new(inner: &'a O) -> Result<Self> {
        let n = inner.num_examples();
        let dim = inner.dim();
        if n == 0 || dim == 0 {
            return Err(Error::Input(format!("1-slack SSVM: the oracle has {n} examples of dimension {dim}")));
        }
        let ground_truth: Vec<Vec<f32>> =
            (0..n).into_par_iter().map(|i| inner.ground_truth_features(i)).collect::<Result<_>>()?;
        for (i, features) in ground_truth.iter().enumerate() {
            super::check_features("ground-truth features", i, features, dim)?;
        }
        let mean_ground_truth = mean_rows(ground_truth.iter().map(Vec::as_slice), dim, n);
        // The mean alone cannot tell the detector's negatives apart (all "no object"): fold in which
        // examples they are, and every example's features, not only their mean.
        let fingerprint = ground_truth.iter().enumerate().fold(FNV_OFFSET, |hash, (i, features)| {
            let hash = fnv1a(hash, bytemuck::cast_slice(features));
            fnv1a(hash, &inner.example_fingerprint(i).to_le_bytes())
        });
        Ok(OneSlack { inner, ground_truth, mean_ground_truth, fingerprint, last: Mutex::new(PassSummary::default()) })
    }

    /// What the latest call to the inner oracle found, per example.
    pub fn last_pass(&self) -> PassSummary {
        self.last.lock().map(|s| s.clone()).unwrap_or_default()
    }
}

/// The mean of `count` rows of length `dim`, summed in f64 in the rows' order (deterministic).
fn mean_rows<'r>(rows: impl Iterator<Item = &'r [f32]>, dim: usize, count: usize) -> Vec<f32> {
    let mut total = vec![0.0f64; dim];
    for row in rows {
        for (t, v) in total.iter_mut().zip(row) {
            *t += f64::from(*v);
        }
    }
    total.into_iter().map(|t| (t / count as f64) as f32).collect()
}

impl<O: SeparationOracle + ?Sized> SeparationOracle for OneSlack<'_, O> {
    fn num_examples(&self) -> usize {
        1
    }

    fn dim(&self) -> usize {
        self.inner.dim()
    }

    fn ground_truth_features(&self, _example: usize) -> Result<Vec<f32>> {
        Ok(self.mean_ground_truth.clone())
    }

    fn example_fingerprint(&self, _example: usize) -> u64 {
        self.fingerprint
    }

    fn run_state(&self) -> Vec<u64> {
        self.inner.run_state()
    }

    fn restore_run_state(&self, state: &[u64]) -> Result<()> {
        self.inner.restore_run_state(state)
    }

    fn most_violated(&self, _example: usize, w: &[f64]) -> Result<Constraint> {
        let n = self.inner.num_examples();
        let dim = self.inner.dim();
        let examples: Vec<usize> = (0..n).collect();
        let answers = self.inner.most_violated_batch(&examples, w)?;
        if answers.len() != n {
            return Err(Error::Input(format!("1-slack SSVM: the oracle answered {} of {n} examples", answers.len())));
        }
        let mut summary = PassSummary { max_example_slack: f64::NEG_INFINITY, ..PassSummary::default() };
        for (i, answer) in answers.iter().enumerate() {
            super::check_loss(i, answer.loss)?;
            super::check_features("features of the most violated output", i, &answer.features, dim)?;
            let margin: f64 = self.ground_truth[i]
                .iter()
                .zip(&answer.features)
                .zip(w)
                .map(|((t, f), wk)| wk * (f64::from(*t) - f64::from(*f)))
                .sum();
            let slack = answer.loss - margin;
            summary.max_example_slack = summary.max_example_slack.max(slack);
            summary.examples_with_slack += usize::from(slack > 1e-9);
            summary.mean_loss += answer.loss / n as f64;
        }
        let features = mean_rows(answers.iter().map(|a| a.features.as_slice()), dim, n);
        if let Ok(mut last) = self.last.lock() {
            *last = summary.clone();
        }
        Ok(Constraint { loss: summary.mean_loss, features })
    }
}
