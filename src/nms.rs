//! 3D non-maximum suppression: greedy by score, per category.
//!
//! Candidates are visited from the highest score down; a candidate is kept unless its [`iou_3d`] with an
//! already kept box **exceeds** the threshold (`>`; a box at exactly the threshold is kept). Equal scores
//! keep their input order (a stable sort), so ties are decided by position. Candidates with a non-finite
//! score are dropped.
//!
//! # The default threshold, 0.15
//! The SUN RGB-D benchmark counts a detection as correct at 3D IoU ≥ 0.25, and the paper and the SUN RGB-D
//! baselines suppress in 3D at about 0.25–0.3. Suppressing at the evaluation threshold still leaves boxes
//! that overlap a kept box by less than 0.25 but the kept box's object by more: `eval --diagnose` counted a
//! quarter of the bed's and sofa's highest-scoring false positives as such duplicates. On held-out frames
//! (the 200 frames of the cascade set, seeds 1700–1703, first-stage detections of the shipped models, NMS
//! redone on them at a lower threshold) the ten-category mAP@0.25 was 36.4 at 0.25, 37.4 at 0.2, 37.4 at
//! 0.15 and 37.8 at 0.1 (bed 70.2 → 73.6, sofa 51.2 → 53.1 at 0.15; no category lost more than 0.4). The
//! default is 0.15, within the noise of the best and less likely than 0.1 to merge two real objects of one
//! category side by side (desks in a row, a chair pair), whose boxes touch but seldom overlap.
//!
//! # Cost
//! Each candidate is compared with the boxes kept so far only, and each comparison first tries a cheap
//! rejection before the exact [`iou_3d`] (a polygon clip): an upper bound of the IoU from the footprints'
//! axis-aligned bounding rectangles, the height ranges and the volumes (it also rejects disjoint boxes).
//! The cost is O(N·kept) bound tests. Measured on 10 000 random boxes in a 5 m room (dev profile, one
//! core): 15 ms at IoU 0.25 (128 kept), 110 ms at 0.5 (1051 kept), 0.85 s at 0.7 (6346 kept).
//!
//! The top-K prefilter ([`NmsOptions::top_k`], default [`DEFAULT_TOP_K`] = 10 000) first keeps only the K
//! highest-scoring candidates (a linear-time selection), so a sliding window's 10⁵–10⁶ scored hypotheses
//! cost O(N + K·log K + K·kept). It is an approximation: a box ranked below K that no higher box
//! suppresses is lost. With K far above the number of detections a frame reports per category, only very
//! low-scoring boxes are affected, which add little to the AP; set `top_k: None` for exact greedy NMS.

use crate::error::{Error, Result};
use crate::eval::Detection;
use glam::Vec3;

use crate::geometry::{iou_3d, Cuboid};

/// Default IoU above which a lower-scoring box is suppressed (see the module doc).
pub const DEFAULT_NMS_IOU: f32 = 0.15;

/// Default number of highest-scoring candidates that take part in the suppression.
pub const DEFAULT_TOP_K: usize = 10_000;

/// Settings of [`suppress`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NmsOptions {
    /// A box whose IoU with a kept box is above this is suppressed; in [0, 1].
    pub iou_threshold: f32,
    /// Keep at most this many boxes (per category for [`nms_detections`]); `None`: no limit.
    pub max_detections: Option<usize>,
    /// Only the `top_k` highest-scoring candidates are considered; `None`: all.
    pub top_k: Option<usize>,
}

impl Default for NmsOptions {
    fn default() -> Self {
        NmsOptions { iou_threshold: DEFAULT_NMS_IOU, max_detections: None, top_k: Some(DEFAULT_TOP_K) }
    }
}

impl NmsOptions {
    /// Default options with the given IoU threshold, checked to be a number in [0, 1].
    pub fn with_iou(iou_threshold: f32) -> Result<Self> {
        let options = NmsOptions { iou_threshold, ..Default::default() };
        options.validate()?;
        Ok(options)
    }

    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.iou_threshold) {
            return Err(Error::Input(format!("NMS IoU threshold must be in [0, 1], got {}", self.iou_threshold)));
        }
        Ok(())
    }
}

/// What the cheap rejection test needs of a box: its footprint's axis-aligned bounding rectangle, its
/// height range and its volume.
struct Bounds {
    min: glam::Vec2,
    max: glam::Vec2,
    bottom: f32,
    top: f32,
    volume: f32,
}

impl Bounds {
    fn of(c: &Cuboid) -> Self {
        let (sin, cos) = c.yaw.sin_cos();
        let (half_w, half_d) = (0.5 * c.size.x, 0.5 * c.size.y);
        let half = glam::Vec2::new(cos.abs() * half_w + sin.abs() * half_d, sin.abs() * half_w + cos.abs() * half_d);
        let centre = c.centre.truncate();
        Bounds { min: centre - half, max: centre + half, bottom: c.bottom(), top: c.top(), volume: c.volume() }
    }

    /// Whether the IoU of the two boxes certainly does not exceed `threshold`, from bounds alone.
    ///
    /// The intersection volume is at most the overlap of the footprints' bounding rectangles times the
    /// overlap of the height ranges, and at most the smaller volume; IoU = I / (va + vb − I) grows with I,
    /// so that bound on I bounds the IoU. A relative slack of 1e-6 keeps rounding from rejecting a pair
    /// whose exact IoU is just above the threshold.
    fn cannot_exceed(&self, other: &Bounds, threshold: f32) -> bool {
        let dz = self.top.min(other.top) - self.bottom.max(other.bottom);
        let overlap = self.max.min(other.max) - self.min.max(other.min);
        if dz <= 0.0 || overlap.x <= 0.0 || overlap.y <= 0.0 {
            return true;
        }
        let (va, vb) = (self.volume as f64, other.volume as f64);
        let intersection = (overlap.x as f64 * overlap.y as f64 * dz as f64).min(va.min(vb));
        let union = va + vb - intersection;
        union > 0.0 && intersection / union * (1.0 + 1e-6) <= threshold as f64
    }
}

/// Greedy 3D NMS over one category's candidates. Returns the indices of the kept boxes, highest score
/// first (ties in input order). `cuboids` and `scores` must have the same length (extra entries of the
/// longer one are ignored).
pub fn suppress(cuboids: &[Cuboid], scores: &[f32], options: &NmsOptions) -> Vec<usize> {
    let n = cuboids.len().min(scores.len());
    let mut order: Vec<usize> = (0..n).filter(|&i| scores[i].is_finite()).collect();
    let by_score = |a: &usize, b: &usize| scores[*b].total_cmp(&scores[*a]).then(a.cmp(b));
    if let Some(k) = options.top_k {
        if order.len() > k {
            if k == 0 {
                return Vec::new();
            }
            // Partial selection first; the index tie-break keeps the choice among equal scores stable.
            order.select_nth_unstable_by(k - 1, by_score);
            order.truncate(k);
        }
    }
    order.sort_by(by_score);
    suppress_in_order(order, |i| cuboids[i], options)
}

/// The greedy loop of [`suppress`] over candidates already in visiting order (best first, ties decided),
/// the cuboid of each made by `cuboid_of` only when the candidate is visited: for a caller that sorted its
/// own candidates and would otherwise build a box for every one of them (the visit stops once
/// `max_detections` are kept). `top_k` is not applied. Returns the kept candidates in order.
pub fn suppress_in_order(
    order: impl IntoIterator<Item = usize>,
    cuboid_of: impl Fn(usize) -> Cuboid,
    options: &NmsOptions,
) -> Vec<usize> {
    let limit = options.max_detections.unwrap_or(usize::MAX);
    let threshold = options.iou_threshold;
    let mut kept: Vec<usize> = Vec::new();
    let mut kept_boxes: Vec<(Cuboid, Bounds)> = Vec::new();
    for i in order {
        if kept.len() >= limit {
            break;
        }
        let cuboid = cuboid_of(i);
        let bounds = Bounds::of(&cuboid);
        let suppressed =
            kept_boxes.iter().any(|(kc, kb)| !bounds.cannot_exceed(kb, threshold) && iou_3d(&cuboid, kc) > threshold);
        if !suppressed {
            kept.push(i);
            kept_boxes.push((cuboid, bounds));
        }
    }
    kept
}

/// The candidates of one category, with their positions in the input.
#[derive(Default)]
struct CategoryGroup<'a> {
    category: &'a str,
    cuboids: Vec<Cuboid>,
    scores: Vec<f32>,
    indices: Vec<usize>,
}

/// [`suppress`] per category: detections of different categories never suppress each other. The result
/// is sorted by score, highest first (ties: category in order of first appearance, then input order);
/// `max_detections` applies per category.
pub fn nms_detections(detections: &[Detection], options: &NmsOptions) -> Vec<Detection> {
    // One group per category, in order of first appearance.
    let mut groups: Vec<CategoryGroup> = Vec::new();
    for (i, d) in detections.iter().enumerate() {
        let slot = match groups.iter().position(|g| g.category == d.category) {
            Some(p) => p,
            None => {
                groups.push(CategoryGroup { category: &d.category, ..Default::default() });
                groups.len() - 1
            }
        };
        let group = &mut groups[slot];
        group.cuboids.push(d.cuboid());
        group.scores.push(d.score);
        group.indices.push(i);
    }
    let mut kept: Vec<usize> = Vec::new();
    for group in &groups {
        kept.extend(suppress(&group.cuboids, &group.scores, options).into_iter().map(|k| group.indices[k]));
    }
    // `kept` is grouped by category in order of first appearance; a stable sort by score keeps that order
    // among ties.
    kept.sort_by(|&a, &b| detections[b].score.total_cmp(&detections[a].score));
    kept.into_iter().map(|i| detections[i].clone()).collect()
}

/// Settings of [`vote`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoteOptions {
    /// A candidate votes for a kept box when their 3D IoU is at least this.
    pub iou: f32,
    /// The slope `a` of the weights `exp(a · (s − s_kept))`: the model's calibration slope, so that a
    /// weight is the ratio of the two boxes' odds of being right (1 for an uncalibrated model).
    pub slope: f32,
    /// Candidates whose weight would be below this are not visited (their scores are far below every kept
    /// box's).
    pub min_weight: f32,
}

/// Default IoU of a voter with the box it votes for, `detect`'s default. Chosen on held-out frames (200 of
/// the cascade set, seeds 1700–1703 — no test frame —, the ten large categories' first-stage detections of
/// the shipped models): Gidaris & Komodakis's 0.5 gained ten-large mAP@0.25 +0.5 [0.1, 1.0] over no voting,
/// and 0.3 another +0.5 [0.1, 1.1] over 0.5 (on 159 of those frames; README, "Box voting").
pub const DEFAULT_VOTE_IOU: f32 = 0.3;

/// Box voting (Gidaris & Komodakis, *Object detection via a multi-region & semantic segmentation-aware CNN
/// model*, ICCV 2015, §5 "box voting"): each box that [`suppress_in_order`] kept is replaced by the
/// weighted mean of the candidates around it — every candidate (itself, the boxes NMS suppressed, other
/// kept boxes) whose 3D IoU with it is at least `options.iou` —, so that a kept box a little beside its
/// object moves toward where the high-scoring boxes agree. The sliding window's boxes lie on a lattice
/// of centres and a few sizes; their mean need not.
///
/// Our choices, where the 2D method has none: weights `exp(a · (s − s_kept))` (`a` the calibration slope:
/// the odds ratio of the voter against the kept box, instead of the raw 2D score, which for an S-SVM can
/// be negative); only voters of the kept box's orientation up to quarter turns vote (a voter a quarter
/// turn off has its width and depth swapped into the kept box's axes; a voter of another yaw bin is
/// skipped, so the yaw is the kept box's and the mean is of centres and sizes only). `candidates` may
/// come in any order — it is the order of the sums, so a fixed order gives the same boxes bit for bit —
/// and should include `kept` (a kept box votes for itself, with weight 1, only through `candidates`). The
/// score and every other field of a kept detection stay its own. A weak kept box beside a strong one can
/// be voted onto it (the strong one's boxes vote for it with weights above 1), so the voted boxes need
/// not keep the NMS's promise: `detect` runs the NMS over them again (`crate::detect`, `model_detections`).
pub fn vote(
    kept: &[usize],
    candidates: impl IntoIterator<Item = usize>,
    cuboid_of: impl Fn(usize) -> Cuboid,
    score_of: impl Fn(usize) -> f32,
    options: &VoteOptions,
) -> Vec<Cuboid> {
    let kept_boxes: Vec<(Cuboid, Bounds, f32)> = kept
        .iter()
        .map(|&k| {
            let c = cuboid_of(k);
            (c, Bounds::of(&c), score_of(k))
        })
        .collect();
    // Weighted sums of centres and sizes (in f64: many small weights), and of the weights.
    let mut sums = vec![([0.0f64; 6], 0.0f64); kept.len()];
    let lowest = kept_boxes.iter().map(|(_, _, s)| *s).fold(f32::INFINITY, f32::min);
    let floor = lowest + options.min_weight.ln() / options.slope;
    for v in candidates {
        let score = score_of(v);
        if score < floor {
            continue;
        }
        let cuboid = cuboid_of(v);
        let bounds = Bounds::of(&cuboid);
        for ((kc, kb, ks), (sum, weights)) in kept_boxes.iter().zip(sums.iter_mut()) {
            // The cheap geometric tests first: the exponential only for a box that overlaps.
            let Some(swapped) = quarter_turns_apart(kc.yaw, cuboid.yaw) else { continue };
            if bounds.cannot_exceed(kb, options.iou.next_down()) {
                continue;
            }
            let size = if swapped { Vec3::new(cuboid.size.y, cuboid.size.x, cuboid.size.z) } else { cuboid.size };
            if aligned_iou(kc, cuboid.centre, size) < options.iou {
                continue;
            }
            let weight = (f64::from(options.slope) * f64::from(score - ks)).exp();
            if weight < f64::from(options.min_weight) {
                continue;
            }
            let values = [cuboid.centre.x, cuboid.centre.y, cuboid.centre.z, size.x, size.y, size.z];
            for (s, x) in sum.iter_mut().zip(values) {
                *s += weight * f64::from(x);
            }
            *weights += weight;
        }
    }
    kept_boxes
        .iter()
        .zip(&sums)
        .map(|((kc, _, _), (sum, weights))| {
            if *weights <= 0.0 {
                return *kc;
            }
            let mean = |i: usize| (sum[i] / weights) as f32;
            Cuboid::new(Vec3::new(mean(0), mean(1), mean(2)), Vec3::new(mean(3), mean(4), mean(5)), kc.yaw)
        })
        .collect()
}

/// The 3D IoU of `kept` with a box of the same axes (a voter turned into them: its yaw a whole number of
/// quarter turns from `kept`'s, `size` along `kept`'s width, depth and height) centred at `centre`: both
/// are axis-aligned in `kept`'s frame, so the overlap is a product of three interval overlaps — what
/// [`iou_3d`]'s polygon clip gives for such a pair (to the 10⁻³ rad that [`quarter_turns_apart`] allows),
/// at a fraction of its cost; the voters are most of a window's candidates.
fn aligned_iou(kept: &Cuboid, centre: Vec3, size: Vec3) -> f32 {
    let offset = (centre - kept.centre).truncate();
    let along = Vec3::new(offset.dot(kept.width_axis()), offset.dot(kept.depth_axis()), centre.z - kept.centre.z);
    let overlap = |d: f32, a: f32, b: f32| (0.5 * (a + b) - d.abs()).clamp(0.0, a.min(b));
    let intersection = overlap(along.x, kept.size.x, size.x)
        * overlap(along.y, kept.size.y, size.y)
        * overlap(along.z, kept.size.z, size.z);
    let union = kept.volume() + size.x * size.y * size.z - intersection;
    if union > 0.0 {
        intersection / union
    } else {
        0.0
    }
}

/// Whether two yaws differ by a whole number of quarter turns (to 10⁻³ rad): `Some(true)` for an odd
/// number (width and depth swap), `Some(false)` for an even one, `None` otherwise.
fn quarter_turns_apart(a: f32, b: f32) -> Option<bool> {
    let quarter = std::f32::consts::FRAC_PI_2;
    let turns = (b - a) / quarter;
    let nearest = turns.round();
    ((turns - nearest).abs() * quarter <= 1e-3).then_some((nearest as i64).rem_euclid(2) == 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The voters' IoU in the kept box's axes equals the polygon clip's for boxes a whole number of quarter
    /// turns apart (a reference implementation: [`iou_3d`]).
    #[test]
    fn aligned_iou_is_the_polygon_clips_for_quarter_turns() {
        let mut seed = 7u64;
        let mut uniform = |lo: f32, hi: f32| {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            lo + (hi - lo) * ((seed >> 40) as f32 / (1u64 << 24) as f32)
        };
        let mut overlapping = 0;
        for _ in 0..2000 {
            let yaw = uniform(-3.2, 3.2);
            let kept = Cuboid::new(
                Vec3::new(uniform(-1.0, 1.0), uniform(-1.0, 1.0), uniform(0.2, 1.0)),
                Vec3::new(uniform(0.3, 2.0), uniform(0.3, 2.0), uniform(0.3, 2.0)),
                yaw,
            );
            let turns = (uniform(0.0, 4.0) as i32) as f32;
            let voter = Cuboid::new(
                kept.centre + Vec3::new(uniform(-1.0, 1.0), uniform(-1.0, 1.0), uniform(-0.5, 0.5)),
                Vec3::new(uniform(0.3, 2.0), uniform(0.3, 2.0), uniform(0.3, 2.0)),
                yaw + turns * std::f32::consts::FRAC_PI_2,
            );
            let swapped = quarter_turns_apart(kept.yaw, voter.yaw).expect("quarter turns apart");
            assert_eq!(swapped, turns as i32 % 2 == 1);
            let size = if swapped { Vec3::new(voter.size.y, voter.size.x, voter.size.z) } else { voter.size };
            let (fast, reference) = (aligned_iou(&kept, voter.centre, size), iou_3d(&kept, &voter));
            assert!((fast - reference).abs() < 1e-4, "{fast} against {reference}: {kept:?} {voter:?}");
            overlapping += usize::from(reference > 0.0);
        }
        assert!(overlapping > 500, "{overlapping} overlapping pairs");
        assert_eq!(quarter_turns_apart(0.0, 0.3), None);
    }
}
