//! A linear binary SVM with per-sample costs, solved with `clarabel` — the paper's second-stage
//! classifiers (§6.2; the paper reports its RBF kernel "only slightly" better than linear, and the
//! linear one keeps the cascade's model a plain weight vector).
//!
//! ```text
//! min_{w, b, ξ}  ½‖w‖² + Σ_i c_i ξ_i   s.t.  y_i (w·x_i + b) ≥ 1 − ξ_i,  ξ_i ≥ 0,   y_i ∈ {−1, +1}
//! ```
//!
//! **Solved in its dual form, with w kept as a variable** (our choice, for speed; the optimum is the
//! same):
//!
//! ```text
//! min_{w, α}  ½‖w‖² − Σ_i α_i   s.t.  w − Σ_i α_i y_i x_i = 0,  Σ_i α_i y_i = 0,  0 ≤ α_i ≤ c_i
//! ```
//!
//! written for clarabel over `x = [w (d), α (n)]` as `min ½ xᵀPx + qᵀx` with `Ax + s = r`: `P = diag(1,
//! …, 1, 0, …)`, `q = [0, −1]`, the d + 1 equality rows (zero cone), then `−α_i + s = 0` and `α_i + s =
//! c_i` (nonnegative cone). The bias is the multiplier of the row `Σ α_i y_i = 0` (clarabel's
//! stationarity `Px + q + Aᵀz = 0` gives, for a sample on the margin, `y_i (w·x_i + z_b) = 1`). Why not
//! the primal (`x = [w, b, ξ]`, the form used before): its n margin rows all touch the d weights, and the
//! fill-reducing ordering of clarabel's LDL factorisation, which sets such dense columns aside, then
//! eliminates each margin row before its ξ_i, filling every ξ_i with all d weights — about three times
//! the factor's entries and flops of the dual, where each α_i touches only its two bound rows besides the
//! d + 1 dense ones. Measured on random problems of the cascade's shape (ψ of 44 values, one positive in
//! ten): 17.9 s against 4.5 s at n = 18 000 samples, 28 against 17 interior-point iterations, the same
//! objective to 1e-10 relative (the unit test below compares the two forms).
//!
//! **Working sets** (our choice, for speed; the optimum is the same). Each interior-point iteration
//! factors a system in which every α_i touches the d weights, about n·d² operations, and a stage of the
//! cascade has n ≈ 7 000–20 000 detections with d = 110–156 (19 context categories): 8–14 s per solve
//! (7 000 samples) and growing like n^1.6. Yet at the optimum most α are at a bound — 0 for the
//! detections outside the margin, c_i for those inside it —, and only the few on the margin (at most
//! about d + 1) are free. So [`train_linear_svm`] solves the same dual by decomposition (Osuna, Freund
//! & Girosi 1997; Joachims 1999, SVMlight): each round solves, with clarabel, the QP over a working set
//! of about a thousand samples while every other α is held at its value (their part of `w` and of
//! `Σ α_i y_i` moves to the right-hand sides), then checks the whole set's optimality without the bias
//! (Keerthi et al. 2001): with `G_i = y_i − w·x_i`, no sample whose α may rise for y = +1 or fall for
//! y = −1 may have a G above one whose α may fall for y = +1 or rise for y = −1, to 10⁻⁶. The next working
//! set is the free samples and the most violating of each side, half each; every subproblem is feasible
//! (the held α are a feasible point's) and each round's optimum is at least as good as the last. It
//! stops when the gap is within 10⁻⁶ or when every violator left is in the set just solved (the gap left
//! is then that of α within 10⁻⁶ of a bound, taken as at it, and the interior-point solver's tolerance;
//! on the test problems it changes the objective by less than 10⁻⁷ of itself); after rounds holding 20 n samples in all it solves the
//! whole QP instead (a safeguard, not reached on the cascade's stages). Selecting by G rather than by
//! each sample's margin at the subproblem's bias matters: that bias rests on the few free samples, and
//! working sets chosen by it swung between the two kinds of violators for dozens of rounds.
//! [`train_linear_svm_from`] starts from another solution's α (the cascade's cross-validation goes
//! through its `C` grid from the largest down, each fit started from the last one's α scaled by the
//! ratio of the `C`s, which balanced costs keep feasible). Measured on the cascade's own samples (the
//! v6 stages of 376 cascade frames, n = 6 500–7 500, d = 156, `C` from 10 down to 0.01, the whole QP
//! against working sets): 3.9–40 s against 2.7–5.7 s per category for the four fits, the objectives
//! equal to 10⁻⁹ relative.

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

/// The quadratic term `P` over `variables` variables whose first `d` are the weights: 1 on their diagonal.
fn weights_regulariser(variables: usize, d: usize) -> CscMatrix<f64> {
    CscMatrix::new(variables, variables, (0..=variables).map(|j| j.min(d)).collect(), (0..d).collect(), vec![1.0; d])
}

/// Trains the SVM on `samples` (rows of equal length `d`) with `labels` (true = +1) and `costs`.
/// Needs at least one sample of each class. Solved by working sets (module doc, "Working sets").
pub fn train_linear_svm(samples: &[Vec<f64>], labels: &[bool], costs: &[f64]) -> Result<LinearSvm> {
    Ok(train_linear_svm_from(samples, labels, costs, None)?.svm)
}

/// An SVM, its dual variables α (one per sample; those within `BOUND_SNAP` of a bound at the bound) and
/// the working-set rounds that found it (1: the first working set held every support vector).
#[derive(Clone, Debug)]
pub struct SvmSolution {
    pub svm: LinearSvm,
    pub alpha: Vec<f64>,
    pub rounds: usize,
}

/// [`train_linear_svm`] started from `start`, the α of a solution of the same samples — with other
/// costs, typically another `C` scaled (α·C'/C of a solution at C is feasible at C' with
/// [`balanced_costs`]). A start that is not feasible (outside the costs' box, or Σ α_i y_i ≠ 0) is
/// ignored. The optimum does not depend on the start; the rounds to reach it do.
pub fn train_linear_svm_from(
    samples: &[Vec<f64>],
    labels: &[bool],
    costs: &[f64],
    start: Option<&[f64]>,
) -> Result<SvmSolution> {
    check_problem(samples, labels, costs)?;
    let start = start.filter(|a| feasible(a, labels, costs));
    solve_by_working_sets(samples, labels, costs, start)
}

/// Whether `alpha` is a feasible point: within the costs' box, Σ α_i y_i = 0 to 10⁻⁶ of Σ c_i (a solution's
/// α, snapped to its bounds, is within about `BOUND_SNAP` of that sum; the first subproblem absorbs the
/// rest, since the held α enter its equality as they are).
fn feasible(alpha: &[f64], labels: &[bool], costs: &[f64]) -> bool {
    let scale: f64 = costs.iter().sum();
    alpha.len() == costs.len()
        && alpha.iter().zip(costs).all(|(&a, &c)| (0.0..=c).contains(&a))
        && alpha.iter().zip(labels).map(|(&a, &y)| a * sign(y)).sum::<f64>().abs() <= 1e-6 * scale
}

/// The same SVM solved as one QP over every sample (the form before working sets; the reference the
/// working-set solve is tested against).
pub fn train_linear_svm_whole(samples: &[Vec<f64>], labels: &[bool], costs: &[f64]) -> Result<LinearSvm> {
    check_problem(samples, labels, costs)?;
    Ok(solve_whole(samples, labels, costs, 0)?.svm)
}

/// The dual QP over every sample at once, reported as found after `rounds` earlier working-set rounds.
fn solve_whole(samples: &[Vec<f64>], labels: &[bool], costs: &[f64], rounds: usize) -> Result<SvmSolution> {
    let n = samples.len();
    let all: Vec<usize> = (0..n).collect();
    let (svm, alpha) = solve_subproblem(samples, labels, costs, &all, &vec![0.0; n])?;
    Ok(SvmSolution { svm, alpha, rounds: rounds + 1 })
}

fn check_problem(samples: &[Vec<f64>], labels: &[bool], costs: &[f64]) -> Result<()> {
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
    Ok(())
}

fn sign(label: bool) -> f64 {
    if label {
        1.0
    } else {
        -1.0
    }
}

/// The dual QP over the samples `work` (sorted, distinct), every other sample's α held at its value in
/// `alpha`: returns the SVM (w over all samples, the bias) and the new α of `work`, in its order. Feasible
/// whenever `alpha` is (`alpha` restricted to `work` is a feasible point).
fn solve_subproblem(
    samples: &[Vec<f64>],
    labels: &[bool],
    costs: &[f64],
    work: &[usize],
    alpha: &[f64],
) -> Result<(LinearSvm, Vec<f64>)> {
    let (n, m, d) = (samples.len(), work.len(), samples[0].len());
    // The held samples' part of w = Σ α_i y_i x_i and of Σ α_i y_i: the right-hand sides of the d + 1
    // equality rows.
    let mut in_work = vec![false; n];
    work.iter().for_each(|&i| in_work[i] = true);
    let mut held = vec![0.0; d + 1];
    for i in (0..n).filter(|&i| !in_work[i] && alpha[i] != 0.0) {
        let a = alpha[i] * sign(labels[i]);
        held.iter_mut().zip(&samples[i]).for_each(|(h, v)| *h += a * v);
        held[d] += a;
    }
    let variables = d + m;
    let p = weights_regulariser(variables, d);
    let mut q = vec![0.0; d];
    q.extend(std::iter::repeat_n(-1.0, m));
    // A, column by column. Rows: 0..d the weights' equalities, d the bias row, then α_i ≥ 0 (row d + 1 + k)
    // and α_i ≤ c_i (row d + 1 + m + k) for the k-th working sample.
    let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
    for j in 0..d {
        rowval.push(j);
        nzval.push(1.0);
        colptr.push(rowval.len());
    }
    for (k, &i) in work.iter().enumerate() {
        for (j, &v) in samples[i].iter().enumerate().filter(|(_, v)| **v != 0.0) {
            rowval.push(j);
            nzval.push(-sign(labels[i]) * v);
        }
        rowval.extend([d, d + 1 + k, d + 1 + m + k]);
        nzval.extend([sign(labels[i]), -1.0, 1.0]);
        colptr.push(rowval.len());
    }
    let a = CscMatrix::new(d + 1 + 2 * m, variables, colptr, rowval, nzval);
    let mut rhs = held[..d].to_vec();
    rhs.push(-held[d]);
    rhs.extend(std::iter::repeat_n(0.0, m));
    rhs.extend(work.iter().map(|&i| costs[i]));
    let cones = [SupportedConeT::ZeroConeT(d + 1), SupportedConeT::NonnegativeConeT(2 * m)];
    let settings = DefaultSettings::<f64> { verbose: false, max_iter: 500, ..DefaultSettings::default() };
    let mut solver = DefaultSolver::new(&p, &q, &a, &rhs, &cones, settings)
        .map_err(|e| Error::Solver(format!("SVM setup with {m} of {n} samples: {e}")))?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved => {}
        SolverStatus::AlmostSolved => log::warn!("SVM with {m} of {n} samples solved to reduced accuracy"),
        status => return Err(Error::Solver(format!("SVM with {m} of {n} samples: clarabel status {status:?}"))),
    }
    let (x, z) = (&solver.solution.x, &solver.solution.z);
    if x.iter().chain([&z[d]]).any(|v| !v.is_finite()) {
        return Err(Error::Solver("SVM solution is not finite".into()));
    }
    let work_alpha = x[d..].to_vec();
    Ok((LinearSvm { weights: x[..d].to_vec(), bias: z[d] }, work_alpha))
}

/// The solve stops when the optimality gap (the highest `up` G less the lowest `low` G, `solve`) is at
/// most this, in units of the margin (1).
const KKT_TOLERANCE: f64 = 1e-6;
/// An α within this fraction of its cost from a bound is at the bound (an interior-point solution
/// approaches its bounds without reaching them): held there, out of the next working set.
const BOUND_SNAP: f64 = 1e-6;
/// When the rounds' working sets together hold more than this many times the samples, the whole QP is
/// solved instead (a safeguard: on the cascade's stages the rounds converge long before).
const ROUNDS_BUDGET: usize = 20;
/// Most violators taken into the next working set (at least as many as its free samples).
const WORKING_SET_ADDITIONS: usize = 1000;

/// Working-set decomposition of the dual (module doc, "Working sets").
fn solve_by_working_sets(
    samples: &[Vec<f64>],
    labels: &[bool],
    costs: &[f64],
    start: Option<&[f64]>,
) -> Result<SvmSolution> {
    let n = samples.len();
    let spread = WORKING_SET_ADDITIONS.min(n);
    let (mut alpha, mut work): (Vec<f64>, Vec<usize>) = match start {
        // The start's free samples and an even spread of the rest; the others held at its α.
        Some(start) => {
            let free = (0..n).filter(|&i| start[i] > 0.0 && start[i] < costs[i]);
            (start.to_vec(), free.chain((0..spread).map(|k| k * n / spread)).collect())
        }
        // Every positive (rare among detections, and mostly support vectors) and an even spread of
        // the rest, the others at α = 0.
        None => (vec![0.0; n], (0..n).filter(|&i| labels[i]).chain((0..spread).map(|k| k * n / spread)).collect()),
    };
    work.sort_unstable();
    work.dedup();
    if !work.iter().any(|&i| !labels[i]) {
        work.push((0..n).find(|&i| !labels[i]).expect("checked: both classes"));
        work.sort_unstable();
    }
    let mut solved = 0usize;
    for round in 0.. {
        solved += work.len();
        let (svm, work_alpha) = match solve_subproblem(samples, labels, costs, &work, &alpha) {
            Ok(r) => r,
            // Not expected (every subproblem is feasible: the held α are a feasible point's), but the
            // whole QP does not depend on the rounds before.
            Err(e) if work.len() < n => {
                log::debug!("SVM working set round {round}: {e}; solving the whole QP");
                return solve_whole(samples, labels, costs, round);
            }
            Err(e) => return Err(e),
        };
        let mut in_work = vec![false; n];
        work.iter().for_each(|&i| in_work[i] = true);
        for (&i, &a) in work.iter().zip(&work_alpha) {
            let c = costs[i];
            alpha[i] = if a <= BOUND_SNAP * c {
                0.0
            } else if a >= (1.0 - BOUND_SNAP) * c {
                c
            } else {
                a
            };
        }
        // Optimality without the bias (Keerthi et al. 2001; Lin 2001): with G_i = y_i − w·x_i, α is
        // optimal when no G of the samples whose α may rise for y = +1 or fall for y = −1 (`up`)
        // exceeds a G of those whose α may fall for y = +1 or rise for y = −1 (`low`): any bias
        // between the two then satisfies every margin condition.
        let g: Vec<f64> = (0..n).map(|i| sign(labels[i]) - svm.decision(&samples[i]) + svm.bias).collect();
        let up = |i: usize| if labels[i] { alpha[i] < costs[i] } else { alpha[i] > 0.0 };
        let low = |i: usize| if labels[i] { alpha[i] > 0.0 } else { alpha[i] < costs[i] };
        let highest_up = (0..n).filter(|&i| up(i)).map(|i| g[i]).fold(f64::NEG_INFINITY, f64::max);
        let lowest_low = (0..n).filter(|&i| low(i)).map(|i| g[i]).fold(f64::INFINITY, f64::min);
        let free: Vec<usize> = work.iter().copied().filter(|&i| alpha[i] > 0.0 && alpha[i] < costs[i]).collect();
        log::trace!(
            "SVM working set round {round}: {} samples, {} free, gap {:.3e}",
            work.len(),
            free.len(),
            highest_up - lowest_low
        );
        if highest_up - lowest_low <= KKT_TOLERANCE {
            return Ok(SvmSolution { svm, alpha, rounds: round + 1 });
        }
        if solved > ROUNDS_BUDGET * n {
            log::debug!("SVM working sets: {round} rounds without convergence; solving the whole QP");
            return solve_whole(samples, labels, costs, round + 1);
        }
        // The most violating of each side (SVMlight's choice of a working set, Joachims 1999): `up`
        // samples by G descending above the lowest `low` G, `low` samples by G ascending below the
        // highest `up` G, half the additions each, and the free samples.
        let additions = WORKING_SET_ADDITIONS.max(free.len());
        let mut ups: Vec<usize> = (0..n).filter(|&i| up(i) && g[i] > lowest_low + KKT_TOLERANCE).collect();
        let mut lows: Vec<usize> = (0..n).filter(|&i| low(i) && g[i] < highest_up - KKT_TOLERANCE).collect();
        ups.sort_by(|&a, &b| g[b].total_cmp(&g[a]).then(a.cmp(&b)));
        lows.sort_by(|&a, &b| g[a].total_cmp(&g[b]).then(a.cmp(&b)));
        let take_ups = (additions / 2).max(additions.saturating_sub(lows.len())).min(ups.len());
        let take_lows = (additions - take_ups).min(lows.len());
        let mut next: Vec<usize> =
            free.into_iter().chain(ups[..take_ups].iter().copied()).chain(lows[..take_lows].iter().copied()).collect();
        next.sort_unstable();
        next.dedup();
        if next.iter().all(|&i| in_work[i]) {
            // Every violation left is inside the working set just solved: what is left of the gap
            // comes from α snapped to a bound and the solver's own tolerance.
            return Ok(SvmSolution { svm, alpha, rounds: round + 1 });
        }
        work = next;
    }
    unreachable!("the loop returns")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The primal form (`x = [w, b, ξ]`), the solver's form before the dual replaced it: the reference
    /// the dual must agree with.
    fn primal_reference(samples: &[Vec<f64>], labels: &[bool], costs: &[f64]) -> LinearSvm {
        let (n, d) = (samples.len(), samples[0].len());
        let sign = |i: usize| if labels[i] { 1.0 } else { -1.0 };
        let variables = d + 1 + n;
        let p = weights_regulariser(variables, d);
        let mut q = vec![0.0; d + 1];
        q.extend_from_slice(costs);
        let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
        for j in 0..d {
            for (i, x) in samples.iter().enumerate() {
                rowval.push(i);
                nzval.push(-sign(i) * x[j]);
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
        let settings = DefaultSettings::<f64> { verbose: false, ..DefaultSettings::default() };
        let mut solver = DefaultSolver::new(&p, &q, &a, &rhs, &cones, settings).unwrap();
        solver.solve();
        assert_eq!(solver.solution.status, SolverStatus::Solved);
        let x = &solver.solution.x;
        LinearSvm { weights: x[..d].to_vec(), bias: x[d] }
    }

    /// The SVM's objective at (w, b), with the optimal slacks.
    fn objective(svm: &LinearSvm, samples: &[Vec<f64>], labels: &[bool], costs: &[f64]) -> f64 {
        let hinge: f64 = samples
            .iter()
            .zip(labels)
            .zip(costs)
            .map(|((x, &y), c)| c * (1.0 - if y { 1.0 } else { -1.0 } * svm.decision(x)).max(0.0))
            .sum();
        0.5 * svm.weights.iter().map(|w| w * w).sum::<f64>() + hinge
    }

    /// Samples like the cascade's: `d` features in [0, 1), a positive in `1/ratio` of them, positives
    /// shifted by 0.3 in the first few features (overlapping classes, so slacks are active).
    fn problem(n: usize, d: usize, ratio: u64, seed: u64) -> (Vec<Vec<f64>>, Vec<bool>) {
        let mut state = seed;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut samples = Vec::new();
        let mut labels = Vec::new();
        for _ in 0..n {
            let y = next() < 1.0 / ratio as f64;
            samples.push((0..d).map(|j| next() + if y && j < 3 { 0.3 } else { 0.0 }).collect());
            labels.push(y);
        }
        (samples, labels)
    }

    #[test]
    fn working_sets_find_the_whole_qps_optimum() {
        // More samples than one working set holds, so the held α and several rounds are exercised.
        for (n, d, ratio, c, seed) in
            [(3000, 5, 10, 0.01, 5), (3000, 5, 10, 1.0, 6), (2500, 40, 10, 0.1, 7), (2500, 12, 3, 10.0, 8)]
        {
            let (samples, labels) = problem(n, d, ratio, seed);
            let costs = balanced_costs(&labels, c);
            let whole = train_linear_svm_whole(&samples, &labels, &costs).unwrap();
            let solution = train_linear_svm_from(&samples, &labels, &costs, None).unwrap();
            assert!(solution.rounds > 1, "n {n} C {c}: one round, the working sets were not exercised");
            let (f_whole, f_sets) =
                (objective(&whole, &samples, &labels, &costs), objective(&solution.svm, &samples, &labels, &costs));
            assert!((f_sets - f_whole).abs() <= 1e-7 * f_whole, "n {n} C {c}: {f_sets} against {f_whole}");
            let scale = whole.weights.iter().map(|w| w.abs()).fold(0.0, f64::max);
            for (a, b) in solution.svm.weights.iter().zip(&whole.weights) {
                assert!((a - b).abs() <= 1e-4 * scale, "n {n} C {c}: weights {a} against {b}");
            }
            // α is a feasible point, and w is its Σ α_i y_i x_i.
            let sum: f64 = solution.alpha.iter().zip(&labels).map(|(a, &y)| a * sign(y)).sum();
            assert!(sum.abs() <= 1e-6 * costs.iter().sum::<f64>());
            assert!(solution.alpha.iter().zip(&costs).all(|(a, c)| (0.0..=*c).contains(a)));
            for (j, w) in whole.weights.iter().enumerate() {
                let from_alpha: f64 =
                    solution.alpha.iter().zip(&samples).zip(&labels).map(|((a, x), &y)| a * sign(y) * x[j]).sum();
                assert!((from_alpha - w).abs() <= 1e-4 * scale, "n {n} C {c}: w[{j}] {from_alpha} against {w}");
            }
        }
    }

    #[test]
    fn a_scaled_solution_starts_the_next_c_and_an_infeasible_start_is_ignored() {
        let (samples, labels) = problem(3000, 8, 10, 9);
        let at = |c: f64, start: Option<&[f64]>| {
            let costs = balanced_costs(&labels, c);
            let solution = train_linear_svm_from(&samples, &labels, &costs, start).unwrap();
            (objective(&solution.svm, &samples, &labels, &costs), solution)
        };
        let (_, at_one) = at(1.0, None);
        let scaled: Vec<f64> = at_one.alpha.iter().map(|a| a * 0.1).collect();
        let (cold, _) = at(0.1, None);
        let (warm, _) = at(0.1, Some(&scaled));
        assert!((warm - cold).abs() <= 1e-7 * cold, "{warm} against {cold}");
        // Σ α_i y_i ≠ 0: not a feasible point, so not used (the same optimum all the same).
        let unbalanced: Vec<f64> =
            balanced_costs(&labels, 0.1).iter().zip(&labels).map(|(c, &y)| if y { *c } else { 0.0 }).collect();
        assert!(!feasible(&unbalanced, &labels, &balanced_costs(&labels, 0.1)));
        let (ignored, _) = at(0.1, Some(&unbalanced));
        assert!((ignored - cold).abs() <= 1e-7 * cold, "{ignored} against {cold}");
    }

    #[test]
    fn the_dual_form_finds_the_primal_forms_optimum() {
        for (n, d, ratio, c, seed) in
            [(300, 5, 10, 0.01, 1), (300, 5, 10, 1.0, 2), (400, 12, 3, 10.0, 3), (200, 2, 2, 0.1, 4)]
        {
            let (samples, labels) = problem(n, d, ratio, seed);
            let costs = balanced_costs(&labels, c);
            let dual = train_linear_svm_whole(&samples, &labels, &costs).unwrap();
            let primal = primal_reference(&samples, &labels, &costs);
            let (f_dual, f_primal) =
                (objective(&dual, &samples, &labels, &costs), objective(&primal, &samples, &labels, &costs));
            assert!((f_dual - f_primal).abs() <= 1e-6 * f_primal, "n {n} C {c}: {f_dual} against {f_primal}");
            // The weights are unique (½‖w‖² is strictly convex; both agree to the solvers' tolerance, about
            // 1e-6 of the largest weight); the bias need not be — at C = 0.01 every
            // sample lies inside the margin, and with balanced costs the objective is flat in b over an
            // interval (the two forms land at different points of it) — so it is checked by the objective.
            let scale = primal.weights.iter().map(|w| w.abs()).fold(0.0, f64::max);
            for (a, b) in dual.weights.iter().zip(&primal.weights) {
                assert!((a - b).abs() <= 1e-4 * scale, "n {n} C {c}: {dual:?} against {primal:?}");
            }
        }
    }
}
