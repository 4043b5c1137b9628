//! Structural SVM solver against independent answers: a closed form in 1-D, and a small multiclass
//! problem solved here with all constraints at once by a projected-gradient (FISTA) dual solver that
//! shares no code with the cutting-plane/clarabel solver; KKT conditions of the primal; resume; bad input.

use cog_gpu::learn::{Checkpoint, Constraint};
use cog_gpu::learn::{CuttingPlane, OneSlack, SeparationOracle, SsvmOptions};
use cog_gpu::{Error, Result};

/// Multiclass SVM as a structural SVM: φ(x, y) places x in block y, Δ is the 0/1 loss.
struct Multiclass {
    xs: Vec<[f32; 2]>,
    labels: Vec<usize>,
    classes: usize,
}

impl Multiclass {
    fn six_points() -> Self {
        // Class 2 has a point inside the others' region, so the data are not separable with margin
        // and some slacks are positive at the optimum.
        Multiclass {
            xs: vec![[1.0, 0.0], [0.8, 0.3], [0.0, 1.0], [-0.2, 0.9], [-1.0, -1.0], [0.5, 0.5]],
            labels: vec![0, 0, 1, 1, 2, 2],
            classes: 3,
        }
    }

    /// `count` points of `classes` classes around the unit circle with a deterministic jitter
    /// (a linear congruential generator), overlapping enough to need several cutting-plane rounds.
    fn scattered(count: usize, classes: usize) -> Self {
        let mut state = 12345u64;
        let mut uniform = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut xs = Vec::new();
        let mut labels = Vec::new();
        for index in 0..count {
            let label = index % classes;
            let angle = std::f32::consts::TAU * label as f32 / classes as f32;
            xs.push([angle.cos() + 1.2 * (uniform() - 0.5), angle.sin() + 1.2 * (uniform() - 0.5)]);
            labels.push(label);
        }
        Multiclass { xs, labels, classes }
    }

    fn phi(&self, example: usize, label: usize) -> Vec<f32> {
        let mut features = vec![0.0; 2 * self.classes];
        features[2 * label..2 * label + 2].copy_from_slice(&self.xs[example]);
        features
    }

    fn loss(&self, example: usize, label: usize) -> f64 {
        if label == self.labels[example] {
            0.0
        } else {
            1.0
        }
    }

    /// Every constraint of the full problem: (example, loss, ψ) for all labels.
    fn all_constraints(&self) -> Vec<(usize, f64, Vec<f64>)> {
        let mut all = Vec::new();
        for example in 0..self.xs.len() {
            let truth = self.phi(example, self.labels[example]);
            for label in 0..self.classes {
                let other = self.phi(example, label);
                let psi = truth.iter().zip(&other).map(|(a, b)| f64::from(a - b)).collect();
                all.push((example, self.loss(example, label), psi));
            }
        }
        all
    }
}

impl SeparationOracle for Multiclass {
    fn num_examples(&self) -> usize {
        self.xs.len()
    }
    fn dim(&self) -> usize {
        2 * self.classes
    }
    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        Ok(self.phi(example, self.labels[example]))
    }
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let score = |label: usize| {
            let features = self.phi(example, label);
            self.loss(example, label) + features.iter().zip(w).map(|(f, w)| f64::from(*f) * w).sum::<f64>()
        };
        let best = (0..self.classes).max_by(|a, b| score(*a).total_cmp(&score(*b))).unwrap();
        Ok(Constraint { loss: self.loss(example, best), features: self.phi(example, best) })
    }
}

/// 1-D toy: outputs ±1, φ(x, y) = y·x, 0/1 loss. Both examples give ψ = 2 for the wrong answer, so
/// the primal is ½w² + C·max(0, 1 − 2w): w* = min(2C, ½).
struct OneDimensional;

impl SeparationOracle for OneDimensional {
    fn num_examples(&self) -> usize {
        2
    }
    fn dim(&self) -> usize {
        1
    }
    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        let (x, y) = [(1.0f32, 1.0f32), (-1.0, -1.0)][example];
        Ok(vec![x * y])
    }
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let (x, y) = [(1.0f32, 1.0f32), (-1.0, -1.0)][example];
        let right = f64::from(x * y) * w[0];
        let wrong = 1.0 + f64::from(-x * y) * w[0];
        Ok(if wrong > right {
            Constraint { loss: 1.0, features: vec![-x * y] }
        } else {
            Constraint { loss: 0.0, features: vec![x * y] }
        })
    }
}

fn options(c: f64) -> SsvmOptions {
    SsvmOptions { c, epsilon: 1e-7, max_iterations: 200, quiet: true, ..SsvmOptions::default() }
}

/// Primal objective by brute force over all outputs.
fn primal_objective(problem: &Multiclass, w: &[f64], c: f64) -> (f64, Vec<f64>) {
    let n = problem.xs.len();
    let mut slacks = vec![0.0f64; n];
    for (example, loss, psi) in problem.all_constraints() {
        let margin = loss - psi.iter().zip(w).map(|(p, w)| p * w).sum::<f64>();
        slacks[example] = slacks[example].max(margin);
    }
    let norm: f64 = w.iter().map(|v| v * v).sum();
    (0.5 * norm + c / n as f64 * slacks.iter().sum::<f64>(), slacks)
}

/// Euclidean projection onto {a ≥ 0, Σa ≤ bound}.
fn project_capped(values: &mut [f64], bound: f64) {
    let clipped_sum: f64 = values.iter().map(|v| v.max(0.0)).sum();
    if clipped_sum <= bound {
        values.iter_mut().for_each(|v| *v = v.max(0.0));
        return;
    }
    // Projection onto the simplex of mass `bound` (sort-based threshold).
    let mut sorted = values.to_vec();
    sorted.sort_by(|a, b| b.total_cmp(a));
    let mut cumulative = 0.0;
    let mut threshold = 0.0;
    for (index, value) in sorted.iter().enumerate() {
        cumulative += value;
        let candidate = (cumulative - bound) / (index + 1) as f64;
        if value - candidate > 0.0 {
            threshold = candidate;
        }
    }
    values.iter_mut().for_each(|v| *v = (*v - threshold).max(0.0));
}

/// The full-constraint dual solved by FISTA: returns (w, dual objective).
fn reference_solution(problem: &Multiclass, c: f64) -> (Vec<f64>, f64) {
    let constraints = problem.all_constraints();
    let n = problem.xs.len();
    let bound = c / n as f64;
    let m = constraints.len();
    let dim = constraints[0].2.len();
    let gram: Vec<Vec<f64>> = (0..m)
        .map(|k| (0..m).map(|l| constraints[k].2.iter().zip(&constraints[l].2).map(|(a, b)| a * b).sum()).collect())
        .collect();
    let lipschitz: f64 = (0..m).map(|k| gram[k][k]).sum::<f64>().max(1e-12);
    let mut alpha = vec![0.0f64; m];
    let mut momentum_point = alpha.clone();
    let mut t = 1.0f64;
    for _ in 0..40_000 {
        let gradient: Vec<f64> =
            (0..m).map(|k| constraints[k].1 - (0..m).map(|l| gram[k][l] * momentum_point[l]).sum::<f64>()).collect();
        let mut next: Vec<f64> = (0..m).map(|k| momentum_point[k] + gradient[k] / lipschitz).collect();
        for example in 0..n {
            let indices: Vec<usize> = (0..m).filter(|k| constraints[*k].0 == example).collect();
            let mut block: Vec<f64> = indices.iter().map(|k| next[*k]).collect();
            project_capped(&mut block, bound);
            for (k, value) in indices.iter().zip(block) {
                next[*k] = value;
            }
        }
        let t_next = (1.0 + (1.0 + 4.0 * t * t).sqrt()) / 2.0;
        momentum_point = (0..m).map(|k| next[k] + (t - 1.0) / t_next * (next[k] - alpha[k])).collect();
        alpha = next;
        t = t_next;
    }
    let mut w = vec![0.0; dim];
    for (a, (_, _, psi)) in alpha.iter().zip(&constraints) {
        for (total, p) in w.iter_mut().zip(psi) {
            *total += a * p;
        }
    }
    let linear: f64 = alpha.iter().zip(&constraints).map(|(a, k)| a * k.1).sum();
    let norm: f64 = w.iter().map(|v| v * v).sum();
    (w, linear - 0.5 * norm)
}

#[test]
fn one_dimensional_closed_form() {
    for (c, expected_w, expected_objective) in [(0.1, 0.2, 0.02 + 0.1 * 0.6), (1.0, 0.5, 0.125)] {
        let solution = cog_gpu::learn::train(&OneDimensional, options(c)).unwrap();
        assert!(solution.converged);
        assert!((solution.w[0] - expected_w).abs() < 1e-6, "C={c}: w={} expected {expected_w}", solution.w[0]);
        assert!((solution.primal - expected_objective).abs() < 1e-6, "C={c}: primal {}", solution.primal);
        assert!((solution.dual - expected_objective).abs() < 1e-6, "C={c}: dual {}", solution.dual);
    }
}

#[test]
fn multiclass_satisfies_kkt_conditions() {
    for (problem, c) in [(Multiclass::six_points(), 1.0), (Multiclass::scattered(20, 5), 3.0)] {
        check_kkt(&problem, c);
    }
}

fn check_kkt(problem: &Multiclass, c: f64) {
    let n = problem.xs.len();
    let bound = c / n as f64;
    let mut solver = CuttingPlane::new(options(c)).unwrap();
    let solution = solver.train(problem).unwrap();
    assert!(solution.converged);
    let w = solver.w().to_vec();
    let (_, slacks) = primal_objective(problem, &w, c);
    assert!(slacks.iter().any(|s| *s > 1e-3), "the problem should have active slacks: {slacks:?}");

    // Dual feasibility: α ≥ 0 and Σ_{k∈W_i} α_k ≤ C/n.
    let working_set = solver.working_set();
    let mut alpha_sums = vec![0.0f64; n];
    for constraint in working_set {
        assert!(constraint.alpha >= 0.0);
        alpha_sums[constraint.example] += constraint.alpha;
    }
    for sum in &alpha_sums {
        assert!(*sum <= bound + 1e-9, "α sum {sum} over C/n {bound}");
    }
    // Stationarity: w = Σ α_k ψ_k.
    for (j, w_j) in w.iter().enumerate() {
        let combination: f64 = working_set.iter().map(|k| k.alpha * f64::from(k.psi[j])).sum();
        assert!((combination - w_j).abs() < 1e-9);
    }
    // Complementary slackness, with slacks from the brute-force primal (all outputs):
    // α_k > 0 ⇒ constraint k is tight; ξ_i > 0 ⇒ Σ_{k∈W_i} α_k = C/n.
    for constraint in working_set {
        if constraint.alpha > 1e-6 {
            let margin = constraint.loss - constraint.psi.iter().zip(&w).map(|(p, w)| f64::from(*p) * w).sum::<f64>();
            assert!((margin - slacks[constraint.example]).abs() < 1e-5, "active constraint not tight");
        }
    }
    for (example, slack) in slacks.iter().enumerate() {
        if *slack > 1e-5 {
            assert!(
                (alpha_sums[example] - bound).abs() < 1e-6,
                "example {example}: ξ>0 but α sum {}",
                alpha_sums[example]
            );
        }
    }
    // Strong duality on the reported objectives; the dual never decreases as constraints are added.
    assert!(solution.primal - solution.dual < 1e-6 && solution.primal - solution.dual > -1e-9);
    for pair in solution.history.windows(2) {
        assert!(pair[1].dual >= pair[0].dual - 1e-9, "dual decreased: {:?}", solution.history);
    }
}

#[test]
fn cutting_plane_matches_full_constraint_qp() {
    for (problem, c) in [
        (Multiclass::six_points(), 0.3),
        (Multiclass::six_points(), 1.0),
        (Multiclass::six_points(), 10.0),
        (Multiclass::scattered(20, 5), 1.0),
    ] {
        let (reference_w, reference_dual) = reference_solution(&problem, c);
        let (reference_primal, _) = primal_objective(&problem, &reference_w, c);
        assert!((reference_primal - reference_dual).abs() < 1e-7, "reference solver not converged at C={c}");

        let solution = cog_gpu::learn::train(&problem, options(c)).unwrap();
        let (primal, _) = primal_objective(&problem, &solution.w, c);
        assert!((primal - reference_primal).abs() < 1e-4, "C={c}: {primal} vs {reference_primal}");
        assert!((solution.primal - primal).abs() < 1e-9, "reported primal differs from brute force");
        for (a, b) in solution.w.iter().zip(&reference_w) {
            assert!((a - b).abs() < 1e-3, "C={c}: w {:?} vs {reference_w:?}", solution.w);
        }
        // Pruning constraints whose α stays zero must not change the optimum.
        let pruned = cog_gpu::learn::train(&problem, SsvmOptions { prune_after: Some(1), ..options(c) }).unwrap();
        let (pruned_primal, _) = primal_objective(&problem, &pruned.w, c);
        assert!((pruned_primal - reference_primal).abs() < 1e-4, "pruned, C={c}: {pruned_primal}");
    }
}

#[test]
fn resume_reaches_the_same_weights() {
    let problem = Multiclass::scattered(20, 5);
    let c = 10.0;
    let uninterrupted = cog_gpu::learn::train(&problem, options(c)).unwrap();
    assert!(uninterrupted.converged);
    eprintln!("uninterrupted: {} iterations, {} constraints", uninterrupted.iterations, uninterrupted.num_constraints);
    assert!(uninterrupted.iterations > 2, "needs more than 2 iterations to test resume");

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ssvm.ckpt");
    let first = SsvmOptions { max_iterations: 2, checkpoint: Some(path.clone()), ..options(c) };
    let partial = cog_gpu::learn::train(&problem, first).unwrap();
    assert!(!partial.converged);
    assert_eq!(partial.iterations, 2);
    assert!(!dir.path().join("ssvm.ckpt.tmp").exists());
    assert_eq!(Checkpoint::read(&path).unwrap().iteration, 2);

    let mut resumed =
        CuttingPlane::resume(SsvmOptions { checkpoint: Some(path.clone()), ..options(c) }, &path).unwrap();
    let finished = resumed.train(&problem).unwrap();
    assert!(finished.converged);
    assert_eq!(finished.iterations, uninterrupted.iterations);
    for (a, b) in finished.w.iter().zip(&uninterrupted.w) {
        assert!((a - b).abs() < 1e-6, "{:?} vs {:?}", finished.w, uninterrupted.w);
    }
    assert_eq!(Checkpoint::read(&path).unwrap().iteration, uninterrupted.iterations);
}

/// Wraps the multiclass oracle and damages one answer.
struct Damaged {
    inner: Multiclass,
    nan_answer: bool,
    nan_ground_truth: bool,
    short_answer: bool,
}

impl SeparationOracle for Damaged {
    fn num_examples(&self) -> usize {
        self.inner.num_examples()
    }
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        let mut features = self.inner.ground_truth_features(example)?;
        if self.nan_ground_truth && example == 3 {
            features[1] = f32::NAN;
        }
        Ok(features)
    }
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let mut answer = self.inner.most_violated(example, w)?;
        if example == 3 && self.nan_answer {
            answer.features[0] = f32::NAN;
        }
        if example == 3 && self.short_answer {
            answer.features.pop();
        }
        Ok(answer)
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let cases =
        [(true, false, false, "non-finite"), (false, true, false, "non-finite"), (false, false, true, "dimension")];
    for (nan_answer, nan_ground_truth, short_answer, expected) in cases {
        let oracle = Damaged { inner: Multiclass::six_points(), nan_answer, nan_ground_truth, short_answer };
        match cog_gpu::learn::train(&oracle, options(1.0)) {
            Err(Error::Input(message)) => {
                assert!(message.contains("example 3") && message.contains(expected), "{message}")
            }
            other => panic!("expected an input error, got {other:?}"),
        }
    }
    assert!(matches!(CuttingPlane::new(SsvmOptions { c: f64::NAN, ..options(1.0) }), Err(Error::Input(_))));

    // A corrupted checkpoint and a checkpoint of other data are refused.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ssvm.ckpt");
    let partial = SsvmOptions { max_iterations: 1, checkpoint: Some(path.clone()), ..options(1.0) };
    cog_gpu::learn::train(&Multiclass::six_points(), partial).unwrap();
    let mut other_data = Multiclass::six_points();
    other_data.xs[0] = [0.9, 0.1];
    let mut resumed = CuttingPlane::resume(options(1.0), &path).unwrap();
    assert!(matches!(resumed.train(&other_data), Err(Error::Input(_))));
    assert!(matches!(CuttingPlane::resume(options(2.0), &path), Err(Error::Invalid { .. })));
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 5]).unwrap();
    assert!(matches!(CuttingPlane::resume(options(1.0), &path), Err(Error::Invalid { .. })));
}

/// The multiclass oracle with an identity per example beyond its features (as the detector's frame names).
struct Named {
    inner: Multiclass,
    fingerprints: Vec<u64>,
}

impl SeparationOracle for Named {
    fn num_examples(&self) -> usize {
        self.inner.num_examples()
    }
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        self.inner.ground_truth_features(example)
    }
    fn example_fingerprint(&self, example: usize) -> u64 {
        self.fingerprints[example]
    }
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        self.inner.most_violated(example, w)
    }
}

/// A checkpoint resumes only on the same examples, told apart by their fingerprints when their features
/// are equal (the detector's negatives, all "no object"): directly and through the 1-slack wrapper, whose
/// one example's features are only the mean of the inner ones.
#[test]
fn resume_refuses_examples_that_differ_only_in_their_fingerprints() {
    let dir = tempfile::tempdir().unwrap();
    let named = |fingerprints: Vec<u64>| Named { inner: Multiclass::six_points(), fingerprints };
    let saved = named(vec![1, 2, 3, 4, 5, 6]);
    let same = named(vec![1, 2, 3, 4, 5, 6]);
    let other = named(vec![1, 2, 3, 4, 5, 7]);
    let swapped = named(vec![1, 2, 3, 4, 6, 5]);
    let refused = |result: Result<cog_gpu::learn::Solution>| match result {
        Err(Error::Input(message)) => assert!(message.contains("data hash"), "{message}"),
        other => panic!("expected a refusal, got {other:?}"),
    };
    // n-slack: the data hash folds each example's fingerprint after its features.
    let path = dir.path().join("n.ckpt");
    let partial = SsvmOptions { max_iterations: 1, checkpoint: Some(path.clone()), ..options(1.0) };
    cog_gpu::learn::train(&saved, partial).unwrap();
    refused(CuttingPlane::resume(options(1.0), &path).unwrap().train(&other));
    refused(CuttingPlane::resume(options(1.0), &path).unwrap().train(&swapped));
    assert!(CuttingPlane::resume(options(1.0), &path).unwrap().train(&same).is_ok());
    // 1-slack: equal mean ground truth, so only the folded fingerprints tell the runs apart.
    let path = dir.path().join("one.ckpt");
    let partial = SsvmOptions { max_iterations: 1, checkpoint: Some(path.clone()), ..options(1.0) };
    cog_gpu::learn::train(&OneSlack::new(&saved).unwrap(), partial).unwrap();
    for changed in [&other, &swapped] {
        let wrapped = OneSlack::new(changed).unwrap();
        assert_eq!(
            wrapped.ground_truth_features(0).unwrap(),
            OneSlack::new(&saved).unwrap().ground_truth_features(0).unwrap()
        );
        refused(CuttingPlane::resume(options(1.0), &path).unwrap().train(&wrapped));
    }
    assert!(CuttingPlane::resume(options(1.0), &path).unwrap().train(&OneSlack::new(&same).unwrap()).is_ok());
}

/// Scale probe, not part of CI: `cargo test --test learn -- --ignored --nocapture scale_probe`.
/// 40 classes of 300-D points (dim 12 000, like the paper's feature vector), 60 examples.
#[test]
#[ignore]
fn scale_probe() {
    struct Wide {
        xs: Vec<Vec<f32>>,
        labels: Vec<usize>,
        classes: usize,
        width: usize,
    }
    impl Wide {
        fn phi(&self, example: usize, label: usize) -> Vec<f32> {
            let mut features = vec![0.0; self.width * self.classes];
            features[self.width * label..self.width * (label + 1)].copy_from_slice(&self.xs[example]);
            features
        }
    }
    impl SeparationOracle for Wide {
        fn num_examples(&self) -> usize {
            self.xs.len()
        }
        fn dim(&self) -> usize {
            self.width * self.classes
        }
        fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
            Ok(self.phi(example, self.labels[example]))
        }
        fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
            let score = |label: usize| {
                let loss = if label == self.labels[example] { 0.0 } else { 1.0 };
                let block = &w[self.width * label..self.width * (label + 1)];
                loss + block.iter().zip(&self.xs[example]).map(|(w, x)| w * f64::from(*x)).sum::<f64>()
            };
            let best = (0..self.classes).max_by(|a, b| score(*a).total_cmp(&score(*b))).unwrap();
            let loss = if best == self.labels[example] { 0.0 } else { 1.0 };
            Ok(Constraint { loss, features: self.phi(example, best) })
        }
    }
    let (classes, width, count) = (40, 300, 60);
    let mut state = 7u64;
    let mut uniform = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
    let labels: Vec<usize> = (0..count).map(|i| i % classes).collect();
    let xs = labels
        .iter()
        .map(|l| (0..width).map(|j| uniform() + if j % classes == *l { 0.3 } else { 0.0 }).collect())
        .collect();
    let problem = Wide { xs, labels, classes, width };
    let dir = tempfile::tempdir().unwrap();
    let start = std::time::Instant::now();
    // COG_SSVM_PRUNE=k sets `prune_after: Some(k)`.
    let prune_after = std::env::var("COG_SSVM_PRUNE").ok().and_then(|v| v.parse().ok());
    let options = SsvmOptions { epsilon: 1e-3, checkpoint: Some(dir.path().join("c")), prune_after, ..options(10.0) };
    let solution = cog_gpu::learn::train(&problem, options).unwrap();
    eprintln!(
        "dim {} n {count}: {} iterations, {} constraints, primal {:.6} dual {:.6}, {:.2} s",
        problem.dim(),
        solution.iterations,
        solution.num_constraints,
        solution.primal,
        solution.dual,
        start.elapsed().as_secs_f64()
    );
}
