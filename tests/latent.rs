//! CCCP for the latent structural SVM (`learn::latent`) on a constructed multiple-instance problem whose
//! latent answer is known.
//!
//! Each example is a bag of 3 slots with 2-D features. A positive bag (ground truth "object") holds one
//! signal slot, near (1, 0), at a known position, and two distractor slots near (0, 1); a negative bag
//! ("no object", φ = 0) holds only distractors. Outputs: "object in slot h" (φ = the slot's features) or
//! "no object" (φ = 0); loss 1 for the wrong one of the two, 0 otherwise. The latent of a positive's
//! ground truth is its slot; the right answer is the signal slot, and a weight that scores signals
//! above 1 and distractors below −1 separates every bag.

use cog_gpu::error::Result;
use cog_gpu::learn::latent::{impute, latent_objective, train_cccp, CccpOptions, LatentOracle};
use cog_gpu::learn::{Constraint, SsvmOptions};

struct Bags {
    /// Per bag its 3 slots' features.
    slots: Vec<[[f32; 2]; 3]>,
    /// Per bag: Some(signal slot) for a positive bag, None for a negative one.
    signal: Vec<Option<usize>>,
}

fn bags() -> Bags {
    let mut slots = Vec::new();
    let mut signal = Vec::new();
    for k in 0..18 {
        // Small deterministic variation so that no two slots are equal.
        let jitter = |j: usize| 0.05 * (((k * 7 + j * 3) % 5) as f32 - 2.0);
        let distractor = |j: usize| [jitter(j), 1.0 + jitter(j + 1)];
        if k % 2 == 0 {
            let position = (k / 2) % 3;
            let mut bag = [distractor(0), distractor(1), distractor(2)];
            bag[position] = [1.0 + jitter(4), jitter(5)];
            slots.push(bag);
            signal.push(Some(position));
        } else {
            slots.push([distractor(0), distractor(1), distractor(2)]);
            signal.push(None);
        }
    }
    Bags { slots, signal }
}

fn score(w: &[f64], f: [f32; 2]) -> f64 {
    w[0] * f[0] as f64 + w[1] * f[1] as f64
}

impl LatentOracle for Bags {
    fn num_examples(&self) -> usize {
        self.slots.len()
    }
    fn dim(&self) -> usize {
        2
    }
    fn num_latents(&self, example: usize) -> usize {
        if self.signal[example].is_some() {
            3
        } else {
            1
        }
    }
    fn ground_truth_features(&self, example: usize, latent: usize) -> Result<Vec<f32>> {
        Ok(match self.signal[example] {
            Some(_) => self.slots[example][latent].to_vec(),
            None => vec![0.0, 0.0],
        })
    }
    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let object_loss = if self.signal[example].is_some() { 0.0 } else { 1.0 };
        let none_loss = 1.0 - object_loss;
        let mut best = Constraint { loss: none_loss, features: vec![0.0, 0.0] };
        let mut best_value = none_loss;
        for slot in self.slots[example] {
            let value = object_loss + score(w, slot);
            if value > best_value {
                best_value = value;
                best = Constraint { loss: object_loss, features: slot.to_vec() };
            }
        }
        Ok(best)
    }
}

fn options() -> CccpOptions {
    CccpOptions {
        ssvm: SsvmOptions { c: 10.0, epsilon: 1e-4, quiet: true, ..SsvmOptions::default() },
        one_slack: false,
        max_rounds: 10,
        tolerance: 1e-6,
    }
}

#[test]
fn cccp_finds_the_known_latents_from_a_wrong_start() {
    let problem = bags();
    // Start every positive at slot 0: wrong for two thirds of them (their slot 0 is a distractor, which
    // looks exactly like the negatives' slots).
    let start = vec![0; problem.slots.len()];
    let wrong_at_start = problem.signal.iter().filter(|s| matches!(s, Some(p) if *p != 0)).count();
    assert_eq!(wrong_at_start, 6);
    let solution = train_cccp(&problem, start, &options()).unwrap();
    assert!(solution.converged);
    for (i, signal) in problem.signal.iter().enumerate() {
        if let Some(position) = signal {
            assert_eq!(solution.latents[i], *position, "bag {i}");
        }
    }
    // The final w separates every bag with (almost) the full margin: signals near or above 1, distractors
    // near or below −1 (C = 10 is a soft margin: the optimum keeps slacks of a few thousandths).
    for (bag, signal) in problem.slots.iter().zip(&problem.signal) {
        for (h, &slot) in bag.iter().enumerate() {
            let s = score(&solution.w, slot);
            if *signal == Some(h) {
                assert!(s >= 0.95, "signal scored {s}");
            } else {
                assert!(s <= -0.95, "distractor scored {s}");
            }
        }
    }
    // At least two rounds (the start was wrong), the last a fixed point, and the latent objective never
    // rises (beyond the ε-approximate solves).
    let rounds = &solution.rounds;
    assert!(rounds.len() >= 2, "{rounds:?}");
    assert!(rounds[0].changed > 0);
    assert_eq!(rounds.last().unwrap().changed, 0);
    for pair in rounds.windows(2) {
        assert!(pair[1].objective <= pair[0].objective + 1e-3, "{rounds:?}");
    }
    // The histogram counts every example's latent: 3 signals at each slot, 9 negatives at latent 0.
    assert_eq!(rounds.last().unwrap().histogram, vec![12, 3, 3]);
    // The reported objective is the one recomputed from the final w.
    let (objective, latents) = latent_objective(&problem, &solution.w, 10.0).unwrap();
    assert!((objective - rounds.last().unwrap().objective).abs() < 1e-9);
    assert_eq!(latents, impute(&problem, &solution.w).unwrap());
}

#[test]
fn the_one_slack_form_reaches_the_same_latents_and_objective() {
    let problem = bags();
    let n_slack = train_cccp(&problem, vec![0; 18], &options()).unwrap();
    let one_slack = train_cccp(&problem, vec![0; 18], &CccpOptions { one_slack: true, ..options() }).unwrap();
    assert_eq!(n_slack.latents, one_slack.latents);
    let (a, b) = (n_slack.rounds.last().unwrap().objective, one_slack.rounds.last().unwrap().objective);
    assert!((a - b).abs() < 1e-2 * a.max(1.0), "n-slack {a} vs 1-slack {b}");
}

#[test]
fn a_right_start_is_a_fixed_point_and_bad_starts_are_errors() {
    let problem = bags();
    let right: Vec<usize> = problem.signal.iter().map(|s| s.unwrap_or(0)).collect();
    let solution = train_cccp(&problem, right.clone(), &options()).unwrap();
    assert_eq!(solution.rounds.len(), 1);
    assert_eq!(solution.latents, right);
    // A latent out of range, a wrong count, no rounds: errors naming the problem.
    let mut bad = right.clone();
    bad[1] = 1; // bag 1 is negative: one latent value only
    let err = train_cccp(&problem, bad, &options()).unwrap_err().to_string();
    assert!(err.contains("example 1") && err.contains("initial latent 1"), "{err}");
    let err = train_cccp(&problem, vec![0; 3], &options()).unwrap_err().to_string();
    assert!(err.contains("3 initial latents for 18 examples"), "{err}");
    let err = train_cccp(&problem, right, &CccpOptions { max_rounds: 0, ..options() }).unwrap_err().to_string();
    assert!(err.contains("max_rounds"), "{err}");
}
