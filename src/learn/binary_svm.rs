//! A linear binary SVM with per-sample costs, solved in the primal with `clarabel` — the paper's
//! second-stage classifiers (§6.2; the paper reports its RBF kernel "only slightly" better than linear,
//! and the linear one keeps the cascade's model a plain weight vector).
//!
//! ```text
//! min_{w, b, ξ}  ½‖w‖² + Σ_i c_i ξ_i   s.t.  y_i (w·x_i + b) ≥ 1 − ξ_i,  ξ_i ≥ 0,   y_i ∈ {−1, +1}
//! ```
//!
//! written for clarabel over `x = [w (d), b, ξ (n)]` as `min ½ xᵀPx + qᵀx` with `Ax + s = r`, `s ≥ 0`:
//! `P = diag(1, …, 1, 0, …)` (w only: the bias is not regularised), `q = [0, 0, c]`, and the rows
//! `−y_i x_i·w − y_i b − ξ_i + s_i = −1` (the margin) followed by `−ξ_i + s = 0` (ξ ≥ 0).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

use crate::error::{Error, Result};

/// A trained linear classifier: `decision(x) = w·x + b`.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearSvm {
    pub weights: Vec<f64>,
    pub bias: f64,
}

impl LinearSvm {
    pub fn decision(&self, x: &[f64]) -> f64 {
        self.weights.iter().zip(x).map(|(w, v)| w * v).sum::<f64>() + self.bias
    }
}

/// Per-sample costs `c_i` that give both classes the same total weight `C·n/2` (positives are rare among
/// detections): `c_i = C·n / (2·n_{y_i})`.
pub fn balanced_costs(labels: &[bool], c: f64) -> Vec<f64> {
    let n = labels.len() as f64;
    let positives = labels.iter().filter(|&&y| y).count().max(1) as f64;
    let negatives = labels.iter().filter(|&&y| !y).count().max(1) as f64;
    labels.iter().map(|&y| c * n / (2.0 * if y { positives } else { negatives })).collect()
}

/// Trains the SVM on `samples` (rows of equal length `d`) with `labels` (true = +1) and `costs`.
/// Needs at least one sample of each class.
pub fn train_linear_svm(samples: &[Vec<f64>], labels: &[bool], costs: &[f64]) -> Result<LinearSvm> {
    let n = samples.len();
    if labels.len() != n || costs.len() != n {
        return Err(Error::Solver(format!("SVM: {n} samples, {} labels, {} costs", labels.len(), costs.len())));
    }
    let positives = labels.iter().filter(|&&y| y).count();
    if positives == 0 || positives == n {
        return Err(Error::Input(format!("an SVM needs both classes; got {positives} positive of {n} samples")));
    }
    let d = samples[0].len();
    if samples.iter().any(|x| x.len() != d || x.iter().any(|v| !v.is_finite())) {
        return Err(Error::Input("SVM samples must have equal lengths and finite values".into()));
    }
    if costs.iter().any(|c| !(c.is_finite() && *c > 0.0)) {
        return Err(Error::Input("SVM costs must be positive and finite".into()));
    }
    let sign = |i: usize| if labels[i] { 1.0 } else { -1.0 };
    let variables = d + 1 + n;
    // P: 1 on the diagonal of w.
    let p = CscMatrix::new(
        variables,
        variables,
        (0..=variables).map(|j| j.min(d)).collect(),
        (0..d).collect(),
        vec![1.0; d],
    );
    let mut q = vec![0.0; d + 1];
    q.extend_from_slice(costs);
    // A, column by column: w_j (margin rows), b (margin rows), ξ_i (its margin row and its sign row).
    let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
    for j in 0..d {
        for (i, x) in samples.iter().enumerate() {
            if x[j] != 0.0 {
                rowval.push(i);
                nzval.push(-sign(i) * x[j]);
            }
        }
        colptr.push(rowval.len());
    }
    for i in 0..n {
        rowval.push(i);
        nzval.push(-sign(i));
    }
    colptr.push(rowval.len());
    for i in 0..n {
        rowval.extend([i, n + i]);
        nzval.extend([-1.0, -1.0]);
        colptr.push(rowval.len());
    }
    let a = CscMatrix::new(2 * n, variables, colptr, rowval, nzval);
    let mut rhs = vec![-1.0; n];
    rhs.extend(std::iter::repeat_n(0.0, n));
    let cones = [SupportedConeT::NonnegativeConeT(2 * n)];
    let settings = DefaultSettings::<f64> { verbose: false, max_iter: 500, ..DefaultSettings::default() };
    let mut solver = DefaultSolver::new(&p, &q, &a, &rhs, &cones, settings)
        .map_err(|e| Error::Solver(format!("SVM setup with {n} samples: {e}")))?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved => {}
        SolverStatus::AlmostSolved => log::warn!("SVM with {n} samples solved to reduced accuracy"),
        status => return Err(Error::Solver(format!("SVM with {n} samples: clarabel status {status:?}"))),
    }
    let x = &solver.solution.x;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(Error::Solver("SVM solution is not finite".into()));
    }
    Ok(LinearSvm { weights: x[..d].to_vec(), bias: x[d] })
}
