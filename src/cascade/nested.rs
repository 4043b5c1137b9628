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
//! even or odd), the same rule as the stage's (highest mean AP; ties: the smaller `C`, then the earlier set)
//! —, or by the first-stage score when no inner choice beats the first stage's inner AP. The outer SVMs
//! are the stage's own cross-validation's (their per-fold APs are kept, no extra fit); the inner ones are
//! 2 × 2 × |C_GRID| fits on a quarter of the frames each (each inner fold's fits warm-started as the
//! stage's, `combined_scores_per_c`). The nested gain is the mean over the two outer folds of (that AP − the
//! first stage's AP on the fold), the same arithmetic as the stage's cross-validated gain.

use serde::{Deserialize, Serialize};

use super::{combined_scores_per_c, subset_ap, Samples, C_GRID};

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

/// The mean over the inner folds of the first-stage AP and of the combined score's AP at each `C`, within
/// the samples `train` (one outer fold's training samples).
fn inner_cross_validation(s: &Samples, train: &[usize], iou_threshold: f32) -> (f32, Vec<Option<f32>>) {
    let mut first = 0.0;
    let mut cascade: Vec<Option<f32>> = vec![Some(0.0); C_GRID.len()];
    for inner in 0..2 {
        let fit: Vec<usize> = train.iter().copied().filter(|&n| !in_inner_fold(s.frame[n], inner)).collect();
        let test: Vec<usize> = train.iter().copied().filter(|&n| in_inner_fold(s.frame[n], inner)).collect();
        let base: Vec<f32> = test.iter().map(|&n| s.raw[n]).collect();
        first += subset_ap(s, &test, &base, iou_threshold) / 2.0;
        for (k, combined) in combined_scores_per_c(s, &fit, &test).into_iter().enumerate() {
            match (combined, cascade[k].as_mut()) {
                (Some(combined), Some(sum)) => *sum += subset_ap(s, &test, &combined, iou_threshold) / 2.0,
                _ => cascade[k] = None,
            }
        }
    }
    (first, cascade)
}

/// The nested numbers of one training, from its cross-validation's per-fold APs (`outer[f][k]` on fold
/// `f` at `C_GRID[k]`) and the inner cross-validations run here; `in_fold` says which frames are in outer
/// fold `f`.
pub(super) fn nested_folds(
    s: &Samples,
    outer: [Vec<Option<f32>>; 2],
    in_fold: impl Fn(usize, usize) -> bool,
    iou_threshold: f32,
) -> NestedFolds {
    let mut first = [0.0; 2];
    let mut inner_first = [0.0; 2];
    let mut inner: [Vec<Option<f32>>; 2] = [vec![], vec![]];
    for fold in 0..2 {
        let test: Vec<usize> = (0..s.labels.len()).filter(|&n| in_fold(s.frame[n], fold)).collect();
        let base: Vec<f32> = test.iter().map(|&n| s.raw[n]).collect();
        first[fold] = subset_ap(s, &test, &base, iou_threshold);
        let train: Vec<usize> = (0..s.labels.len()).filter(|&n| !in_fold(s.frame[n], fold)).collect();
        (inner_first[fold], inner[fold]) = inner_cross_validation(s, &train, iou_threshold);
    }
    NestedFolds { first, outer, inner_first, inner }
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

    fn numbers(first: [f32; 2], outer: [[f32; 4]; 2], inner_first: [f32; 2], inner: [[f32; 4]; 2]) -> NestedFolds {
        NestedFolds {
            first,
            outer: outer.map(|l| l.map(Some).to_vec()),
            inner_first,
            inner: inner.map(|l| l.map(Some).to_vec()),
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
