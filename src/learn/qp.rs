//! The dual QP over the working set, solved with `clarabel`.
//!
//! ```text
//! max_α  Σ_k α_k Δ_k − ½ αᵀGα   s.t.  α ≥ 0,  Σ_{k∈W_i} α_k ≤ C/n  for each example i,
//! ```
//!
//! written for clarabel as `min ½ αᵀGα − Δᵀα` with `Aα + s = b`, `s ≥ 0`: the rows of `A` are `−I`
//! (α ≥ 0) followed by one row of ones per example that has constraints (its box `C/n`).
//! The Gram matrix is dense (every ψ overlaps every other), passed as its upper triangle in CSC.

use crate::error::{Error, Result};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{DefaultSettings, DefaultSolver, IPSolver, SolverStatus, SupportedConeT};

/// Solves the dual for `m` constraints.
///
/// - `gram_lower[k]` holds `G_kj` for `j ≤ k` (row `k` of the lower triangle, length `k + 1`);
/// - `losses[k]` is `Δ_k`, `examples[k]` the example constraint `k` belongs to;
/// - `bound` is `C/n`; `tolerance` the interior-point gap/feasibility tolerance.
///
/// Returns α projected onto the feasible set (clamped to ≥ 0, each example's sum scaled to ≤ bound)
/// so that the dual objective computed from it is a valid lower bound.
pub fn solve_dual(
    gram_lower: &[Vec<f64>],
    losses: &[f64],
    examples: &[usize],
    bound: f64,
    tolerance: f64,
) -> Result<Vec<f64>> {
    let num_constraints = losses.len();
    if gram_lower.len() != num_constraints || examples.len() != num_constraints {
        return Err(Error::Solver(format!(
            "dual QP: {} Gram rows, {} losses, {} example ids",
            gram_lower.len(),
            num_constraints,
            examples.len()
        )));
    }
    if num_constraints == 0 {
        return Ok(Vec::new());
    }
    let group_of = compact_groups(examples);
    let num_groups = group_of.iter().copied().max().map_or(0, |g| g + 1);

    let gram_upper = upper_triangle_csc(gram_lower)?;
    let linear: Vec<f64> = losses.iter().map(|loss| -loss).collect();
    let constraint_matrix = constraint_csc(&group_of, num_groups);
    let mut rhs = vec![0.0; num_constraints];
    rhs.extend(std::iter::repeat_n(bound, num_groups));
    let cones = [SupportedConeT::NonnegativeConeT(num_constraints + num_groups)];

    let settings = DefaultSettings::<f64> {
        verbose: false,
        tol_gap_abs: tolerance,
        tol_gap_rel: tolerance,
        tol_feas: tolerance,
        max_iter: 500,
        ..DefaultSettings::default()
    };
    let mut solver = DefaultSolver::new(&gram_upper, &linear, &constraint_matrix, &rhs, &cones, settings)
        .map_err(|e| Error::Solver(format!("dual QP setup with {num_constraints} constraints: {e}")))?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved => {}
        SolverStatus::AlmostSolved => {
            log::warn!("dual QP with {num_constraints} constraints solved to reduced accuracy");
        }
        status => {
            return Err(Error::Solver(format!(
                "dual QP with {num_constraints} constraints: clarabel status {status:?}"
            )));
        }
    }
    let mut alpha = solver.solution.x.clone();
    if alpha.iter().any(|a| !a.is_finite()) {
        return Err(Error::Solver("dual QP returned non-finite multipliers".into()));
    }
    project_feasible(&mut alpha, &group_of, num_groups, bound);
    Ok(alpha)
}

/// Maps arbitrary example ids to `0..groups` in order of first appearance.
fn compact_groups(examples: &[usize]) -> Vec<usize> {
    let mut seen = std::collections::HashMap::new();
    examples
        .iter()
        .map(|example| {
            let next = seen.len();
            *seen.entry(*example).or_insert(next)
        })
        .collect()
}

/// The upper triangle of the symmetric Gram matrix as CSC: column `j` holds rows `0..=j`, which are
/// exactly `gram_lower[j]`.
fn upper_triangle_csc(gram_lower: &[Vec<f64>]) -> Result<CscMatrix<f64>> {
    let size = gram_lower.len();
    let mut colptr = Vec::with_capacity(size + 1);
    let mut rowval = Vec::with_capacity(size * (size + 1) / 2);
    let mut nzval = Vec::with_capacity(size * (size + 1) / 2);
    colptr.push(0);
    for (column, row) in gram_lower.iter().enumerate() {
        if row.len() != column + 1 {
            return Err(Error::Solver(format!("Gram row {column} has {} entries, expected {}", row.len(), column + 1)));
        }
        if row.iter().any(|v| !v.is_finite()) {
            return Err(Error::Solver(format!("Gram row {column} has a non-finite entry")));
        }
        rowval.extend(0..=column);
        nzval.extend_from_slice(row);
        colptr.push(rowval.len());
    }
    Ok(CscMatrix::new(size, size, colptr, rowval, nzval))
}

/// `A = [−I; S]` where `S[g, k] = 1` when constraint `k` belongs to group `g`.
fn constraint_csc(group_of: &[usize], num_groups: usize) -> CscMatrix<f64> {
    let size = group_of.len();
    let mut colptr = Vec::with_capacity(size + 1);
    let mut rowval = Vec::with_capacity(2 * size);
    let mut nzval = Vec::with_capacity(2 * size);
    colptr.push(0);
    for (column, group) in group_of.iter().enumerate() {
        rowval.push(column);
        nzval.push(-1.0);
        rowval.push(size + group);
        nzval.push(1.0);
        colptr.push(rowval.len());
    }
    CscMatrix::new(size + num_groups, size, colptr, rowval, nzval)
}

/// Clamps α to ≥ 0 and scales each group down to its bound (interior-point answers sit a hair
/// outside the feasible set).
fn project_feasible(alpha: &mut [f64], group_of: &[usize], num_groups: usize, bound: f64) {
    for a in alpha.iter_mut() {
        *a = a.max(0.0);
    }
    let mut sums = vec![0.0; num_groups];
    for (a, group) in alpha.iter().zip(group_of) {
        sums[*group] += *a;
    }
    for (a, group) in alpha.iter_mut().zip(group_of) {
        if sums[*group] > bound {
            *a *= bound / sums[*group];
        }
    }
}
