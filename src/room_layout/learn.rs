//! Learning the layout model (paper §5): the structural SVM of eq. 4, solved by `crate::learn`'s cutting
//! planes through its [`SeparationOracle`] trait.
//!
//! - **Outputs**: the frame's hypotheses ([`super::hypotheses`]).
//! - **Ground truth**: annotations need not be Manhattan, so (paper) the ground truth is the hypothesis with
//!   the largest free-space IoU with the annotation (first on ties).
//! - **Loss** (eq. 5 with free-space IoU, orientation modulo 90°): `Δ(h) = IoU(ĥ, A) − IoU(h, A)·(1 +
//!   cos δ)/2`, with `A` the annotation, `ĥ` the ground-truth hypothesis and `δ` the difference between the
//!   yaws of `h` and `ĥ` taken modulo 90° into [−45°, 45°). It is eq. 5's `1 − IoU·(1 + cos δ)/2` with the
//!   IoU measured against the annotation instead of against `ĥ` (one summed-area lookup per hypothesis,
//!   [`super::free_space::YawFreeSpace`], instead of a frustum intersection of two turned boxes), shifted so
//!   that `Δ(ĥ) = 0`; it lies in [0, 1].
//! - **Loss-augmented inference** scores every hypothesis exactly with the fixed-point tables of
//!   [`super::voxels::ScoringTables`] (the same code as prediction) and adds the loss.

use glam::Vec2;

use super::free_space::YawFreeSpace;
use super::voxels::{features, Descriptor, ScoringTables, YawCells};
use super::{hypotheses, orientation_yaw, LayoutScene, RoomBox, ORIENTATIONS};
use crate::error::{Error, Result};
use crate::frame::RoomLayout;
use crate::learn::{Constraint, SeparationOracle};

/// One training frame: its binned points, hypotheses, their losses and the ground-truth hypothesis.
#[derive(Clone, Debug)]
pub struct LayoutExample {
    pub name: String,
    pub cells: Vec<YawCells>,
    pub boxes: Vec<RoomBox>,
    /// Free-space IoU of each hypothesis with the annotation.
    pub ious: Vec<f32>,
    pub losses: Vec<f32>,
    pub truth: usize,
}

/// Yaw difference modulo 90°, in [−45°, 45°) (radians).
pub fn yaw_difference_mod_90(a: f32, b: f32) -> f32 {
    let quarter = std::f32::consts::FRAC_PI_2;
    (a - b + quarter / 2.0).rem_euclid(quarter) - quarter / 2.0
}

/// Footprint extent `[u_lo, u_hi, v_lo, v_hi]` (metres) of the hypotheses of orientation `k`.
fn extent_of(boxes: &[RoomBox], k: usize) -> [f32; 4] {
    boxes.iter().filter(|b| b.yaw_index as usize == k).fold([f32::MAX, f32::MIN, f32::MAX, f32::MIN], |e, b| {
        [
            e[0].min(b.u0 as f32 / 1000.0),
            e[1].max(b.u1 as f32 / 1000.0),
            e[2].min(b.v0 as f32 / 1000.0),
            e[3].max(b.v1 as f32 / 1000.0),
        ]
    })
}

/// Free-space IoU of every hypothesis with `truth`.
pub fn hypothesis_ious(scene: &LayoutScene, boxes: &[RoomBox], truth: &RoomLayout) -> Vec<f32> {
    let tables: Vec<Option<YawFreeSpace>> = (0..ORIENTATIONS)
        .map(|k| {
            boxes.iter().any(|b| b.yaw_index as usize == k).then(|| {
                YawFreeSpace::new(
                    k,
                    &scene.camera,
                    scene.image_size,
                    scene.floor,
                    scene.ceiling,
                    truth,
                    extent_of(boxes, k),
                )
            })
        })
        .collect();
    boxes.iter().map(|b| tables[b.yaw_index as usize].as_ref().map_or(0.0, |t| t.counts(b).iou() as f32)).collect()
}

impl LayoutExample {
    /// The example of one annotated frame, with what `descriptor`'s features need.
    pub fn new(name: &str, scene: &LayoutScene, truth: &RoomLayout, descriptor: Descriptor) -> Result<LayoutExample> {
        let (cells, boxes) = hypotheses(scene, descriptor.cog, descriptor.edges);
        if boxes.is_empty() {
            return Err(Error::Input(format!("frame '{name}': no layout hypotheses")));
        }
        let ious = hypothesis_ious(scene, &boxes, truth);
        let truth_index = (0..boxes.len()).fold(0, |best, i| if ious[i] > ious[best] { i } else { best });
        let truth_yaw = boxes[truth_index].yaw();
        let best = ious[truth_index];
        let losses = boxes
            .iter()
            .zip(&ious)
            .map(|(b, &iou)| {
                let delta = yaw_difference_mod_90(b.yaw(), truth_yaw);
                (best - iou * (1.0 + delta.cos()) / 2.0).max(0.0)
            })
            .collect();
        Ok(LayoutExample { name: name.to_string(), cells, boxes, ious, losses, truth: truth_index })
    }

    /// Upright corners of the ground-truth hypothesis.
    pub fn truth_corners(&self) -> [Vec2; 4] {
        self.boxes[self.truth].corners()
    }
}

/// The structural-SVM oracle over layout examples.
pub struct LayoutOracle {
    pub descriptor: Descriptor,
    pub examples: Vec<LayoutExample>,
}

/// Index of the largest value (first on ties).
pub fn argmax(values: impl Iterator<Item = f64>) -> usize {
    values.enumerate().fold((0, f64::NEG_INFINITY), |best, (i, v)| if v > best.1 { (i, v) } else { best }).0
}

impl SeparationOracle for LayoutOracle {
    fn num_examples(&self) -> usize {
        self.examples.len()
    }

    fn dim(&self) -> usize {
        self.descriptor.dim()
    }

    fn ground_truth_features(&self, example: usize) -> Result<Vec<f32>> {
        let e = &self.examples[example];
        let b = &e.boxes[e.truth];
        Ok(features(self.descriptor, &e.cells[b.yaw_index as usize], b))
    }

    fn most_violated(&self, example: usize, w: &[f64]) -> Result<Constraint> {
        let e = &self.examples[example];
        let tables = ScoringTables::new(self.descriptor, &e.cells, w);
        let scores = super::voxels::scores_cpu(&e.cells, &tables, &e.boxes);
        let totals = tables.totals(&e.cells, &e.boxes, &scores);
        let best = argmax(totals.iter().zip(&e.losses).map(|(&t, &l)| l as f64 + t as f64 / tables.scale));
        let b = &e.boxes[best];
        Ok(Constraint {
            loss: e.losses[best] as f64,
            features: features(self.descriptor, &e.cells[b.yaw_index as usize], b),
        })
    }
}

/// Yaw of orientation `k` in degrees (for reports).
pub fn yaw_degrees(k: u32) -> f32 {
    orientation_yaw(k as usize).to_degrees()
}
