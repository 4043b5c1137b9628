//! The latent structural SVM (Yu & Joachims 2009, "Learning structural SVMs with latent variables";
//! the paper's §4.1, where the latent variable is the height of a support surface) trained by CCCP on
//! top of the cutting-plane solver, which it reuses unchanged.
//!
//! ```text
//! min_w  ½‖w‖² + C · (1/n) Σ_i [ max_{ȳ,h̄} (Δ(y_i, ȳ) + wᵀφ(x_i, ȳ, h̄)) − max_h wᵀφ(x_i, y_i, h) ]
//! ```
//!
//! The bracket is a convex function minus a convex function of w. CCCP (the concave–convex procedure)
//! replaces the subtracted max by its linearisation at the current w, i.e. it **imputes** each ground
//! truth's latent `h_i = argmax_h wᵀφ(x_i, y_i, h)`; what is left is an ordinary structural SVM whose
//! ground-truth features are `φ(x_i, y_i, h_i)`, solved by [`super::CuttingPlane`] (n-slack) or through
//! [`super::OneSlack`] (1-slack, the detector's choice: same optimum). Each round starts a fresh cutting-
//! plane run, because the ground-truth features changed (a checkpoint refuses other ground truths).
//!
//! Choices (where the paper is silent):
//! * the first round's latents are given by the caller (the paper initialises the surface model from the
//!   centre slice, i.e. the middle latent value);
//! * ties in the imputation go to the smallest latent index, so rounds are deterministic;
//! * stopping: after a round whose imputation changes no latent (the next round would solve the same
//!   problem again: a fixed point), or when the latent objective fell by less than `tolerance` since the
//!   previous round, or after `max_rounds`. With exact solves the objective never increases (CCCP's
//!   guarantee); the cutting-plane solves are ε-approximate, so it may rise by up to about `C·ε`.

use rayon::prelude::*;

use super::{check_features, check_loss, Constraint, OneSlack, SeparationOracle, SsvmOptions};
use crate::error::{Error, Result};

/// The problem-specific half of the latent structural SVM.
///
/// Contract as [`SeparationOracle`]'s, plus: every example's ground truth has `num_latents(i) ≥ 1` latent
/// values (1 for an example without a latent choice, e.g. "no object"), and `most_violated` maximises
/// `Δ + wᵀφ` jointly over the outputs and their latents (its output space should hold the ground truth
/// with every latent, at loss 0, so that slacks are ≥ 0).
pub trait LatentOracle: Sync {
    fn num_examples(&self) -> usize;
    fn dim(&self) -> usize;
    /// Number of latent values of example `i`'s ground truth.
    fn num_latents(&self, example: usize) -> usize;
    /// `φ(x_i, y_i, h)`.
    fn ground_truth_features(&self, example: usize, latent: usize) -> Result<Vec<f32>>;
    /// As [`SeparationOracle::example_fingerprint`].
    fn example_fingerprint(&self, _example: usize) -> u64 {
        0
    }
    /// `argmax_{ȳ,h̄} Δ(y_i, ȳ) + wᵀφ(x_i, ȳ, h̄)`.
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint>;
}

/// A latent oracle with its ground truths' latents fixed: an ordinary [`SeparationOracle`].
pub struct Imputed<'a, O: LatentOracle + ?Sized> {
    pub oracle: &'a O,
    pub latents: &'a [usize],
}

impl<O: LatentOracle + ?Sized> SeparationOracle for Imputed<'_, O> {
    fn num_examples(&self) -> usize {
        self.oracle.num_examples()
    }
    fn dim(&self) -> usize {
        self.oracle.dim()
    }
    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        self.oracle.ground_truth_features(example, self.latents[example])
    }
    fn example_fingerprint(&self, example: usize) -> u64 {
        self.oracle.example_fingerprint(example)
    }
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        self.oracle.most_violated(example, w)
    }
}

/// Settings of [`train_cccp`].
#[derive(Clone, Debug)]
pub struct CccpOptions {
    /// The settings of every round's cutting-plane run (a checkpoint path, if any, is used per round and
    /// overwritten by the next).
    pub ssvm: SsvmOptions,
    /// Solve each round in the 1-slack form ([`OneSlack`]) instead of the n-slack one.
    pub one_slack: bool,
    /// Most CCCP rounds (each a full S-SVM solve).
    pub max_rounds: usize,
    /// Stop when the latent objective fell by less than this since the previous round.
    pub tolerance: f64,
}

/// What one CCCP round did.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CccpRound {
    /// Primal objective of the round's S-SVM (with the latents it was given).
    pub ssvm_objective: f64,
    /// The latent objective (module doc) at the round's w, with the latents imputed from it.
    pub objective: f64,
    /// How many examples' imputed latent differs from the one the round was trained with.
    pub changed: usize,
    /// Cutting-plane iterations of the round, and whether it converged.
    pub iterations: usize,
    pub converged: bool,
    /// How many examples chose each latent value after the round (index = latent value).
    pub histogram: Vec<usize>,
}

/// The result of [`train_cccp`].
#[derive(Clone, Debug)]
pub struct CccpSolution {
    pub w: Vec<f64>,
    /// Each example's latent imputed from the final `w`.
    pub latents: Vec<usize>,
    pub rounds: Vec<CccpRound>,
    /// Whether CCCP stopped at a fixed point or below the tolerance (not at `max_rounds`).
    pub converged: bool,
}

/// `h_i = argmax_h wᵀφ(x_i, y_i, h)` for every example (ties: the smallest `h`).
pub fn impute<O: LatentOracle + ?Sized>(oracle: &O, w: &[f64]) -> Result<Vec<usize>> {
    (0..oracle.num_examples()).into_par_iter().map(|i| Ok(best_latent(oracle, i, w)?.0)).collect()
}

/// The best latent of example `i`'s ground truth at `w` and its score.
fn best_latent<O: LatentOracle + ?Sized>(oracle: &O, example: usize, w: &[f64]) -> Result<(usize, f64)> {
    let count = oracle.num_latents(example);
    if count == 0 {
        return Err(Error::Input(format!("latent S-SVM: example {example} has no latent value")));
    }
    let mut best = (0, f64::NEG_INFINITY);
    for latent in 0..count {
        let features = oracle.ground_truth_features(example, latent)?;
        check_features("ground-truth features", example, &features, oracle.dim())?;
        let score = dot(w, &features);
        if score > best.1 {
            best = (latent, score);
        }
    }
    Ok(best)
}

fn dot(w: &[f64], features: &[f32]) -> f64 {
    w.iter().zip(features).map(|(a, &b)| a * b as f64).sum()
}

/// The latent objective `½‖w‖² + C · mean_i max(0, max_{ȳ,h̄}(Δ + wᵀφ) − max_h wᵀφ(x_i, y_i, h))` and the
/// latents that attain the inner max.
pub fn latent_objective<O: LatentOracle + ?Sized>(oracle: &O, w: &[f64], c: f64) -> Result<(f64, Vec<usize>)> {
    let n = oracle.num_examples();
    let per_example: Vec<(usize, f64)> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (latent, truth_score) = best_latent(oracle, i, w)?;
            let violated = oracle.most_violated(i, w)?;
            check_loss(i, violated.loss)?;
            check_features("most violated features", i, &violated.features, oracle.dim())?;
            Ok((latent, (violated.loss + dot(w, &violated.features) - truth_score).max(0.0)))
        })
        .collect::<Result<_>>()?;
    let mean_slack = per_example.iter().map(|p| p.1).sum::<f64>() / n.max(1) as f64;
    let norm: f64 = w.iter().map(|v| v * v).sum();
    Ok((0.5 * norm + c * mean_slack, per_example.into_iter().map(|p| p.0).collect()))
}

/// CCCP for the latent S-SVM (module doc), starting from `initial_latents` (one per example).
pub fn train_cccp<O: LatentOracle + ?Sized>(
    oracle: &O,
    initial_latents: Vec<usize>,
    options: &CccpOptions,
) -> Result<CccpSolution> {
    let n = oracle.num_examples();
    if initial_latents.len() != n {
        return Err(Error::Input(format!("latent S-SVM: {} initial latents for {n} examples", initial_latents.len())));
    }
    if let Some(i) = (0..n).find(|&i| initial_latents[i] >= oracle.num_latents(i)) {
        return Err(Error::Input(format!(
            "latent S-SVM: example {i}'s initial latent {} is not below its {} latent values",
            initial_latents[i],
            oracle.num_latents(i)
        )));
    }
    if options.max_rounds == 0 {
        return Err(Error::Input("latent S-SVM: max_rounds must be at least 1".into()));
    }
    let mut latents = initial_latents;
    let mut rounds: Vec<CccpRound> = Vec::new();
    let mut w = vec![0.0; oracle.dim()];
    let mut converged = false;
    for round in 0..options.max_rounds {
        let imputed = Imputed { oracle, latents: &latents };
        let solution = if options.one_slack {
            super::train(&OneSlack::new(&imputed)?, options.ssvm.clone())?
        } else {
            super::train(&imputed, options.ssvm.clone())?
        };
        let (objective, new_latents) = latent_objective(oracle, &solution.w, options.ssvm.c)?;
        let changed = new_latents.iter().zip(&latents).filter(|(a, b)| a != b).count();
        let mut histogram = vec![0usize; new_latents.iter().max().map_or(0, |m| m + 1)];
        for &latent in &new_latents {
            histogram[latent] += 1;
        }
        log::info!(
            "CCCP round {}: S-SVM objective {:.6}, latent objective {objective:.6}, {changed} latents changed, \
             chosen latents {histogram:?}",
            round + 1,
            solution.primal
        );
        let previous = rounds.last().map(|r| r.objective);
        rounds.push(CccpRound {
            ssvm_objective: solution.primal,
            objective,
            changed,
            iterations: solution.iterations,
            converged: solution.converged,
            histogram,
        });
        w = solution.w;
        latents = new_latents;
        if changed == 0 || previous.is_some_and(|p| p - objective < options.tolerance) {
            converged = true;
            break;
        }
    }
    Ok(CccpSolution { w, latents, rounds, converged })
}
