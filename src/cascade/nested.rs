//! Nested cross-validation of a category's stage training (`cascade --keep nested-gain`,
//! [`StageRule::NestedGain`](super::StageRule::NestedGain)): an estimate of what the whole training
//! procedure gains on frames it did not see — `C` from [`C_GRID`] and the feature set chosen by
//! cross-validated AP, no stage when no choice beats the first stage —, free of the choice's bias.
//!
//! Why: a stage's own cross-validated gain ([`SecondStage::cv_ap_cascade`](super::SecondStage) minus the
//! first stage's) is the largest of |C_GRID| × |sets| noisy estimates on the same frames, so it overstates
//! the gain most where a category has few examples: the TV's stage on the 2 000-frame cascade set of
//! 2026-12-04, +0.2 cross-validated on 41 true positives, lost 15.6 AP points on the selection set and 20.3
//! on the test set (README, "Which stages to keep").
//!
//! How (choices; the stage's own two folds, even and odd frames, are the outer folds): outer fold `f` is
//! scored by the SVM trained on the other fold `g` at the (set, `C`) that an inner two-fold
//! cross-validation **within `g`** chooses — `g`'s frames split again by [`in_inner_fold`] (frame index / 2
//! even or odd), the same rule as the stage's (highest mean AP; ties: the earlier set, then the smaller `C`)
//! —, or by the first-stage score when no inner choice beats the first stage's inner AP. The outer SVMs
//! are the stage's own cross-validation's (their per-fold APs are kept, no extra fit); the inner
//! cross-validation is the stage's own run on `g`'s samples (`fold_samples`): 2 × 2 × |C_GRID| fits on
//! a quarter of the frames each. The nested gain is the mean over the two outer folds of (that AP − the
//! first stage's AP on the fold), the same arithmetic as the stage's cross-validated gain.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::{cross_validate, Samples, Validated, C_GRID};

/// Inner fold `inner` (0 or 1) of the frames of one outer fold: the frame index halved, even or odd (the
/// outer folds split on the index's parity, so halving alternates within each).
pub fn in_inner_fold(frame: usize, inner: usize) -> bool {
    (frame / 2) % 2 == inner
}

/// One (category, feature set) training's numbers for the nested estimate; per outer fold `f` (the
/// frames of cross-validation fold `f`) and, where a list, per `C` of [`C_GRID`] in its order. `None`
/// where an SVM could not be fitted (a class missing from its frames).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NestedFolds {
    /// The first-stage AP on fold `f`.
    pub first: [f32; 2],
    /// The AP on fold `f` of the combined score of the SVM trained on the other fold at each `C`.
    pub outer: [Vec<Option<f32>>; 2],
    /// The inner cross-validation within the other fold: the mean over its two inner folds of the
    /// first-stage AP ...
    pub inner_first: [f32; 2],
    /// ... and of the combined score's AP at each `C`.
    pub inner: [Vec<Option<f32>>; 2],
}

impl NestedFolds {
    /// Lists of [`C_GRID`]'s length and finite numbers (a checkpoint's are checked before use).
    pub fn check(&self) -> Result<(), String> {
        let lists = self.outer.iter().chain(&self.inner);
        if lists.clone().any(|l| l.len() != C_GRID.len()) {
            return Err(format!("a list of the nested cross-validation is not of the {} C values", C_GRID.len()));
        }
        let numbers = self.first.iter().chain(&self.inner_first).copied().chain(lists.flatten().flatten().copied());
        if numbers.clone().any(|x| !x.is_finite()) {
            return Err("a number of the nested cross-validation is not finite".into());
        }
        Ok(())
    }
}

/// The samples of the frames of parity `parity` (one outer fold), renumbered `frame / 2` (with their ground
/// truth), so that the stage's own cross-validation over them ([`cross_validate`], even and odd frame)
/// is the inner cross-validation ([`in_inner_fold`]). Labels stay those matched on all frames.
fn fold_samples(s: &Samples, parity: usize) -> Samples {
    let kept: Vec<usize> = (0..s.labels.len()).filter(|&n| s.frame[n] % 2 == parity).collect();
    Samples {
        psi: kept.iter().map(|&n| s.psi[n].clone()).collect(),
        raw: kept.iter().map(|&n| s.raw[n]).collect(),
        labels: kept.iter().map(|&n| s.labels[n]).collect(),
        frame: kept.iter().map(|&n| s.frame[n] / 2).collect(),
        cuboids: kept.iter().map(|&n| s.cuboids[n]).collect(),
        truth: s.truth.iter().skip(parity).step_by(2).cloned().collect(),
    }
}

/// The inner cross-validations of one training: the stage's own cross-validation ([`cross_validate`]) on
/// the samples of each outer training fold ([`fold_samples`]) — element `fold` for outer fold `fold`, which
/// the SVMs trained on the frames of the other parity score. The two are independent and run in parallel
/// (the same numbers as one after the other), and [`super::train_stage`] runs them beside the stage's own
/// cross-validation.
pub(super) fn inner_validations(s: &Samples, iou_threshold: f32) -> Vec<Vec<Option<Validated>>> {
    (0..2).into_par_iter().map(|fold| cross_validate(&fold_samples(s, 1 - fold), iou_threshold)).collect()
}

/// The nested numbers of one training from its cross-validation `validated` (per `C` of [`C_GRID`]; its
/// per-fold APs are the outer ones) and its [`inner_validations`]. Where no `C` could be fitted the
/// first-stage APs read 0: every choice then falls back to the first stage, whose gain is 0 whatever its
/// AP.
pub(super) fn nested_folds(
    validated: &[Option<Validated>],
    inner_validations: &[Vec<Option<Validated>>],
) -> NestedFolds {
    let first_aps = |v: &[Option<Validated>]| v.iter().flatten().next().map_or([0.0; 2], |v| v.fold_first);
    let mut inner_first = [0.0; 2];
    let mut inner: [Vec<Option<f32>>; 2] = [vec![], vec![]];
    for (fold, within) in inner_validations.iter().enumerate() {
        let [a, b] = first_aps(within);
        inner_first[fold] = (a + b) / 2.0;
        inner[fold] = within.iter().map(|v| v.as_ref().map(|v| v.ap_cascade)).collect();
    }
    NestedFolds {
        first: first_aps(validated),
        outer: [0, 1].map(|fold| validated.iter().map(|v| v.as_ref().map(|v| v.fold_cascade[fold])).collect()),
        inner_first,
        inner,
    }
}

/// The nested cross-validated gain of the training procedure over the candidate sets' numbers (in the
/// sets' order; module doc); `None` without candidates.
pub fn nested_gain(candidates: &[&NestedFolds]) -> Option<f32> {
    let reference = candidates.first()?;
    let mut gain = 0.0;
    for fold in 0..2 {
        // The inner choice: the highest inner AP over sets and C, ties to the earlier (strictly greater
        // replaces), as the stage's own choice.
        let mut best: Option<(f32, Option<f32>)> = None;
        for numbers in candidates {
            for (inner, outer) in numbers.inner[fold].iter().zip(&numbers.outer[fold]) {
                if let Some(ap) = *inner {
                    if best.is_none_or(|(b, _)| ap > b) {
                        best = Some((ap, *outer));
                    }
                }
            }
        }
        let first = reference.first[fold];
        let chosen = match best {
            // A choice whose SVM could not be fitted on the outer training fold leaves the first stage.
            Some((ap, outer)) if ap > reference.inner_first[fold] => outer.unwrap_or(first),
            _ => first,
        };
        gain += (chosen - first) / 2.0;
    }
    Some(gain)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Cuboid;
    use glam::Vec3;

    fn numbers(first: [f32; 2], outer: [[f32; 4]; 2], inner_first: [f32; 2], inner: [[f32; 4]; 2]) -> NestedFolds {
        NestedFolds {
            first,
            outer: outer.map(|l| l.map(Some).to_vec()),
            inner_first,
            inner: inner.map(|l| l.map(Some).to_vec()),
        }
    }

    /// The parity-1 samples of six frames: frames 1, 3, 5 become 0, 1, 2 with their own ground truth and
    /// samples (in order), and the stage's folds over them are the inner folds over the originals.
    #[test]
    fn fold_samples_renumber_one_outer_fold() {
        let unit = |x: f32| Cuboid::new(Vec3::new(x, 0.0, 0.5), Vec3::ONE, 0.0);
        let mut s = Samples { psi: vec![], raw: vec![], labels: vec![], frame: vec![], cuboids: vec![], truth: vec![] };
        for f in 0..6 {
            s.truth.push(vec![unit(f as f32); f % 3]);
            for d in 0..2 {
                s.psi.push(vec![f as f64, d as f64]);
                s.raw.push((10 * f + d) as f32);
                s.labels.push(d == 0);
                s.frame.push(f);
                s.cuboids.push(unit(f as f32 + 0.1 * d as f32));
            }
        }
        let odd = fold_samples(&s, 1);
        assert_eq!(odd.frame, [0, 0, 1, 1, 2, 2]);
        assert_eq!(odd.raw, [10.0, 11.0, 30.0, 31.0, 50.0, 51.0]);
        assert_eq!(odd.psi[3], [3.0, 1.0]);
        assert_eq!(odd.labels, [true, false, true, false, true, false]);
        assert_eq!(odd.cuboids[4], unit(5.0));
        assert_eq!(odd.truth, [vec![unit(1.0)], vec![], vec![unit(5.0); 2]]);
        for (j, original) in [1, 3, 5].into_iter().enumerate() {
            for inner in 0..2 {
                assert_eq!(super::super::in_fold(j, inner), in_inner_fold(original, inner));
            }
        }
    }

    #[test]
    fn the_inner_folds_split_each_outer_fold_in_two() {
        for outer in 0..2 {
            let frames: Vec<usize> = (0..40).filter(|f| f % 2 == outer).collect();
            let sizes: Vec<usize> =
                (0..2).map(|inner| frames.iter().filter(|&&f| in_inner_fold(f, inner)).count()).collect();
            assert_eq!(sizes, [10, 10], "outer fold {outer}");
        }
    }

    /// Hand computation: the outer AP of the inner choice, per fold, against the first stage's.
    #[test]
    fn the_nested_gain_takes_the_outer_ap_of_the_inner_choice() {
        let a = numbers(
            [0.40, 0.50],
            [[0.10, 0.20, 0.30, 0.90], [0.45, 0.55, 0.65, 0.75]],
            [0.30, 0.30],
            // Fold 0: the best inner AP is at C = 1 (index 2), whose outer AP is 0.30, not the outer
            // maximum 0.90. Fold 1: no C beats the inner first stage.
            [[0.31, 0.32, 0.50, 0.33], [0.29, 0.30, 0.10, 0.20]],
        );
        // (0.30 − 0.40) / 2 + 0: the selection's gain is negative though the best outer AP beats the first.
        assert!((nested_gain(&[&a]).unwrap() - -0.05).abs() < 1e-6);
        // A second set whose inner APs win on fold 1 (at C = 0.1) and tie on fold 0 (the earlier set keeps it).
        let b = numbers(
            [0.40, 0.50],
            [[0.95, 0.95, 0.95, 0.95], [0.0, 0.70, 0.0, 0.0]],
            [0.30, 0.30],
            [[0.50, 0.10, 0.10, 0.10], [0.0, 0.35, 0.0, 0.0]],
        );
        let both = nested_gain(&[&a, &b]).unwrap();
        assert!((both - ((0.30 - 0.40) / 2.0 + (0.70 - 0.50) / 2.0)).abs() < 1e-6, "{both}");
        // Order matters only for ties: b first takes fold 0 (0.95).
        let reversed = nested_gain(&[&b, &a]).unwrap();
        assert!((reversed - ((0.95 - 0.40) / 2.0 + (0.70 - 0.50) / 2.0)).abs() < 1e-6, "{reversed}");
        assert_eq!(nested_gain(&[]), None);
    }

    #[test]
    fn an_unfitted_choice_leaves_the_first_stage() {
        let mut a = numbers([0.40, 0.50], [[0.9; 4], [0.9; 4]], [0.30, 0.30], [[0.1, 0.1, 0.1, 0.8], [0.1; 4]]);
        a.outer[0][3] = None;
        a.inner[1] = vec![None; 4];
        // Fold 0 chooses C = 10, not fitted on the outer fold: the first stage, 0; fold 1 has no choice.
        assert_eq!(nested_gain(&[&a]), Some(0.0));
        assert!(a.check().is_ok());
        a.inner[0].pop();
        assert!(a.check().is_err());
        a.inner[0].push(Some(f32::NAN));
        assert!(a.check().is_err());
    }
}
