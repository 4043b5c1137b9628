//! Learning: the n-slack structural SVM with margin rescaling (paper eq. 4), solved by cutting planes
//! (Joachims, Finley & Yu 2009, "Cutting-plane training of structural SVMs").
//!
//! The solver knows nothing about cuboids or features: everything problem-specific sits behind
//! [`SeparationOracle`], so the solver can be tested on small problems with known optima and the
//! detector plugs its GPU loss-augmented inference in as the oracle.
//!
//! Problem (for `n` examples with ground truths `y_i`):
//!
//! ```text
//! min_{w, ξ ≥ 0}  ½‖w‖² + (C/n) Σ_i ξ_i
//! s.t.  wᵀψ_i(ȳ) ≥ Δ(y_i, ȳ) − ξ_i   for all ȳ, i,    ψ_i(ȳ) = φ(x_i, y_i) − φ(x_i, ȳ).
//! ```
//!
//! The QP over the working set W is solved in its dual with `clarabel`:
//! `max Σ_k α_k Δ_k − ½ αᵀGα` s.t. `α ≥ 0`, `Σ_{k∈W_i} α_k ≤ C/n`, with `G_kl = ψ_kᵀψ_l`, and
//! `w = Σ_k α_k ψ_k`. See [`ssvm`] for the outer loop and [`checkpoint`] for the file format.
//!
//! # Latent extension (paper §4.1)
//! The latent structural SVM with CCCP (Yu & Joachims 2009) is [`latent`]: an outer loop alternates (1)
//! imputing the latent (the paper's support height) of every ground truth with the current `w`
//! (`h_i = argmax_h wᵀφ(x_i, y_i, h)`), which fixes [`SeparationOracle::ground_truth_features`], and (2) a
//! fresh [`CuttingPlane::train`] run whose oracle maximises over `(ȳ, h̄)` jointly. The detector's
//! surface features that would feed it are not built yet (issue "latent support surfaces").

pub mod binary_svm;
pub mod checkpoint;
pub mod detector;
pub mod latent;
pub mod one_slack;
pub mod qp;
pub mod ssvm;

pub use checkpoint::{Checkpoint, WorkingConstraint};
pub use one_slack::{OneSlack, PassSummary};
pub use ssvm::{train, CuttingPlane, IterationReport, Solution, SsvmOptions};

use crate::error::{Error, Result};
use rayon::prelude::*;

/// One answer of loss-augmented inference for one example: the output ȳ that maximises
/// `Δ(y_i, ȳ) + wᵀφ(x_i, ȳ)`, given by its loss and its (dense) joint feature vector `φ(x_i, ȳ)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    /// `Δ(y_i, ȳ)`, finite and ≥ 0 (0 when ȳ is the ground truth or the correct "no object").
    pub loss: f64,
    /// `φ(x_i, ȳ)`, length [`SeparationOracle::dim`].
    pub features: Vec<f32>,
}

/// The problem-specific half of the structural SVM.
///
/// Contract:
/// - examples are `0..num_examples()`; every feature vector has length `dim()`, finite values;
/// - `most_violated(i, w)` returns `argmax_ȳ Δ(y_i, ȳ) + wᵀφ(x_i, ȳ)` over the output space of
///   example `i`, which should include the ground truth itself (loss 0) so that violations are ≥ 0;
///   an approximate maximiser is allowed (the solver then certifies optimality only over the
///   outputs the oracle can find);
/// - the answers must depend only on `(i, w)`: resuming from a checkpoint replays the same calls.
///
/// The detector implements it with GPU scoring over all cuboid hypotheses plus the "no object"
/// answer. Oracles that score many examples at once (one GPU pass) override
/// [`SeparationOracle::most_violated_batch`].
pub trait SeparationOracle: Sync {
    /// Number of training examples `n`.
    fn num_examples(&self) -> usize;
    /// Length of the joint feature vector φ.
    fn dim(&self) -> usize;
    /// `φ(x_i, y_i)`, the features of the ground-truth output of example `i`.
    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>>;
    /// What identifies example `i` beyond its ground-truth features (the detector: the frame it was cut
    /// from), folded into a checkpoint's data hash so that a run resumes only on the same examples. Every
    /// negative of the detector has the same "no object" features: without this, another choice of
    /// negative frames of the same count would resume someone else's run silently. Default 0: the
    /// features alone identify the example.
    fn example_fingerprint(&self, _example: usize) -> u64 {
        0
    }
    /// The oracle's own state that a resumed run needs to continue where the interrupted one stood (its
    /// counters, caches; stored in every checkpoint, [`checkpoint::Checkpoint::oracle_state`]). Default:
    /// none.
    fn run_state(&self) -> Vec<u64> {
        Vec::new()
    }
    /// Takes back [`SeparationOracle::run_state`] from a checkpoint, on the first solve of a resumed run
    /// (an empty state: a checkpoint written before there was one). Default: nothing to restore.
    fn restore_run_state(&self, _state: &[u64]) -> Result<()> {
        Ok(())
    }
    /// Loss-augmented inference for example `i` at weights `w` (length `dim()`).
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint>;
    /// Loss-augmented inference for several examples at the same `w`, in the order given.
    /// The default calls [`SeparationOracle::most_violated`] in parallel with rayon.
    fn most_violated_batch(&self, examples: &[usize], w: &[f64]) -> Result<Vec<Constraint>> {
        examples.par_iter().map(|&example| self.most_violated(example, w)).collect()
    }
}

/// Checks one feature vector from an oracle: right length, all finite.
pub(crate) fn check_features(what: &str, example: usize, features: &[f32], dim: usize) -> Result<()> {
    if features.len() != dim {
        return Err(Error::Input(format!(
            "{what} of example {example} has {} values, the oracle's dimension is {dim}",
            features.len()
        )));
    }
    if let Some(position) = features.iter().position(|value| !value.is_finite()) {
        return Err(Error::Input(format!(
            "{what} of example {example} has a non-finite value ({}) at index {position}",
            features[position]
        )));
    }
    Ok(())
}

/// Checks one loss from an oracle: finite and ≥ 0.
pub(crate) fn check_loss(example: usize, loss: f64) -> Result<()> {
    if !loss.is_finite() || loss < 0.0 {
        return Err(Error::Input(format!(
            "loss of the most violated output of example {example} is {loss}; it must be finite and >= 0"
        )));
    }
    Ok(())
}
