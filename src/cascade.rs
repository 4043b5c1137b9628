//! The context cascade (paper §6): second-stage classifiers that rescore every first-stage detection from
//! the detections of all categories around it, so that a "piece" of a large object detected as a smaller
//! one (a table on a chair, a bathtub on a bed) loses to the evidence of the object it is a piece of.
//!
//! # Features (paper §6.1; choices where it is terse)
//! For detection `i` of category `c` with first-stage calibrated probability `p_i` ([`crate::calibration`],
//! so that confidences of different categories share one scale), and for each context category `k` of the
//! cascade (its [`Cascade::categories`], `c` itself included), `j` is the detection of `k` other than `i`
//! whose box overlaps `i`'s (intersection volume > 0) with the largest `p_j` — the paper's `i_c`, "the
//! instance of category c with maximum confidence" (ties: the first in the frame's list). With the
//! overlap `O`, the volumes `V` and the union `U`: `S1 = O/V_i`, `S2 = O/V_j`, `S3 = O/U` (the paper's
//! three). **Small objects** (paper §6.1: "for small objects that are placed on the support surfaces of
//! large objects, 3D overlap features are noisy. We replace 3D overlap with 2D overlap scores from the
//! top-down view"): when `c` is not one of the ten large categories
//! ([`crate::category::LARGE_CATEGORIES`]; choice: the paper does not list its small ones, ours are the
//! other nine of its Table 2), `O`, `V` and `U` are the footprints' overlap and areas seen from above
//! ([`crate::geometry::footprint_overlap_area`]; "overlaps" then means a footprint overlap > 0), for
//! every context category `k`, so that a monitor standing on a desk, whose boxes only touch, still sees
//! the desk. A large category keeps the 3D overlap for every `k` (choice: the rule is read as the paper
//! words it, "for small objects"; the first version also gave a large `c` the top-down overlap with a
//! small `k` (feature set `object-overlap-layout-v3`), and on the cascade set's cross-validation the ten
//! large categories did better with the 3D overlap for every pair — 44.2 against 43.7 mean AP — and the
//! bathtub got a stage only with it). A cascade of the ten large categories thus has the same features as
//! the earlier sets ([`PREVIOUS_FEATURES`] are read for such a cascade).
//! The paper's "quadratic function" of `z_i` and `S1..3` is taken as the products with the
//! confidences, which keeps a category that is absent (`p_j = 0`) from contributing anything:
//!
//! ```text
//! ψ_i = [p_i, p_i²] ++ for each k: [p_j, p_j·S1, p_j·S2, p_j·S3, p_i·p_j]     (zeros when no j)
//! ```
//!
//! then the room layout's part (the paper's "distance `D` and angle `A` of cuboid `B_i` to the closest
//! wall", `A` linear and `D` through a radial basis expansion, each also times `p_i` as the quadratic
//! function the paper names):
//!
//! ```text
//!   ++ [no_room, A, p_i·A, r_1(D) … r_5(D), p_i·r_1(D) … p_i·r_5(D)]
//! ```
//!
//! then (feature set v5, [`V5_FEATURES`], `cascade --features v5`; our addition, beyond the paper's §6.1;
//! not the default until measured to help, [`FeatureSet::DEFAULT`]) the **neighbourhood** and the
//! **geometry** of the detection's own box:
//!
//! ```text
//!   ++ for each k: n_k  ++  [l, l², s, s², h, h², b, b²]
//! ```
//!
//! `n_k` is the sum of the confidences `p_j` of the detections of `k` other than `i` whose footprint meets
//! `i`'s footprint grown by [`NEIGHBOURHOOD_MARGIN`] = 0.5 m on every side (seen from above, heights
//! ignored): the chairs pulled out around a table, which need not touch it, against the one chair at a desk;
//! a sum rather than a maximum so that several weak neighbours count. `l` and `s` are the footprint's longer
//! and shorter sides, `h` the height and `b` the bottom's height above the room's floor (0 without a room):
//! the first stage's features are normalised to the box, so its score does not say whether the box has a
//! table's or a desk's proportions, or stands on the floor or on a bed; the squares let a linear stage
//! prefer a middle range. So `dim = 2 + 5·K + 13` for v4 ([`V4_FEATURES`], the default, [`feature_dim`])
//! and `2 + 6·K + 13 + 8` for v5 ([`FeatureSet::dim`]). The room is the frame's predicted
//! layout (its floor polygon and floor height, written by `detect` under `"layout"` when the models
//! directory has a layout model; [`read_detections_and_room`]).
//! Then (feature set v6, [`V6_FEATURES`], `cascade --features v6`; our addition) the **scene**:
//!
//! ```text
//!   ++ for each k: s_k
//! ```
//!
//! `s_k` is the largest confidence `p_j` of a detection of `k` other than `i` anywhere in the frame (0 when
//! there is none): what kind of room the frame shows, which the overlap and the neighbourhood, both local,
//! do not say — a toilet in a frame with a bed and a desk but no sink, a TV in a bathroom. The synthetic
//! test set's highest-scoring false positives of the bathtub, door, lamp, sink and TV are mostly in frames
//! without the category at all (README, "Diagnosis"). A maximum, not a sum, so that the many weak
//! detections every model leaves in every frame do not add up to a room. `dim = V5's + K`.
//! Then (feature set v7, [`V7_FEATURES`], `cascade --features v7`; our addition) the **cross scores**:
//!
//! ```text
//!   ++ for each c of CROSS_SCORE_CATEGORIES: clamp(x_c, −5, 5)
//! ```
//!
//! `x_c` is the raw score of category `c`'s first-stage model on `i`'s own box
//! ([`Detection::cross_scores`], computed by `detect`, [`crate::detect::cross_scores`]), for a detection of
//! one of the eleven [`CROSS_SCORE_CATEGORIES`] (the ten large and the counter); zeros for the others. The
//! diagnosis puts most of the large categories' highest-scoring false positives on objects of another of
//! them (tables on desks, dressers on counters, sofas on beds), and the overlap part sees the other
//! category only where its model kept a box of its own sizes there; the cross part asks every model about
//! this very box. Clamped to ±5 (raw scores of the shipped models lie within about ±3 on their
//! detections) so that a box no model was made for cannot dominate ψ. `dim = V6's + 11`. A detection of
//! those categories without all eleven scores is an error for a v7 stage (files written before the cross
//! scores existed, or with a subset of the models): detect them again.
//! `D` ([`wall_context`]) is the smallest distance from a corner of the cuboid's footprint to a wall
//! segment of the polygon, negative when the cuboid's centre lies outside the polygon; the closest wall
//! is the segment that gives it. `A` is the angle between the cuboid's width axis and that wall, folded
//! modulo 90° into [0°, 45°] and divided by 45°. `r_m(D) = exp(−(D − c_m)² / (2σ_m²))` with centres
//! `c = 0, 0.25, 0.5, 1, 2` m and widths `σ = 0.15, 0.15, 0.25, 0.5, 1` m ([`RBF_CENTRES`],
//! [`RBF_WIDTHS`]): furniture stands against a wall (nightstands, beds, dressers, bookshelves, toilets),
//! a little off it (chairs at desks) or in the open (tables, sofas facing a TV), and pieces of other
//! objects do not keep those distances. Without a room (`no_room` = 1) the rest of the part is zero.
//! Among segments equally close, the first in the polygon's order gives `A` (no tie rule: the shipped
//! cascades were trained on these values).
//! The file format's `features` name says which set a cascade uses ([`FEATURES`]).
//!
//! # Learning (paper §6.2)
//! Per category, a linear SVM ([`crate::learn::binary_svm`]; the paper's RBF kernel is "only slightly"
//! better) on the first-stage detections of held-out frames, labelled with the benchmark's matching
//! ([`crate::eval::average_precision`]: true when IoU ≥ the threshold with a ground-truth box not taken by
//! a better detection), classes balanced ([`crate::learn::binary_svm::balanced_costs`]). `C` is chosen
//! from [`C_GRID`] by two-fold cross-validation over the frames (even and odd frames), maximising the
//! mean AP of the combined score; ties go to the smaller `C` (each fold's fits go from the largest `C`
//! down, each started from the one before: the same optima in fewer working-set rounds,
//! [`crate::learn::binary_svm::train_linear_svm_from`]). A category whose cross-validated AP with
//! the context is not above its first stage's gets no second stage (its scores are left alone rather
//! than made worse). **Per-category feature sets** (`cascade --features best`; our addition): each
//! category's stage is trained with v4, v5 and v6 (`--features best-cross`: and v7, for the categories of
//! [`CROSS_SCORE_CATEGORIES`] only — another category's detections read zeros in v7's cross part, so its
//! v7 stage would be its v6 one with unused weights: [`v7_adds_nothing`]) and keeps the set whose
//! cross-validated AP is highest
//! (ties: the smaller set); the same folds and the same first-stage AP for all, so the choice is made on
//! the cascade's own held-out frames, never on a test set. The file's `features` is then v4 and a stage of
//! another set names its own ([`SecondStage::features`]); since each set's ψ is a prefix of the next one's,
//! rescoring computes the widest ψ once and a stage reads its prefix. A stage's training reads only its
//! own set, so cascades of different sets trained on the same detections can be merged afterwards with
//! the same rule ([`Cascade::merged_with`], `cog-gpu merge-cascades`). Which of the chosen stages a
//! cascade keeps is [`StageRule`]'s (`cascade --keep`): every one that beats the first stage, or only
//! those beyond the noise, or only those of a category whose training gains in a nested cross-validation
//! ([`nested`]).
//!
//! # Prediction (paper §6.3)
//! The second-stage score is `z'_i = w·ψ_i + b` and the combined score `z_i + z'_i`, with `z_i` the first
//! stage's raw score (as the paper adds them). Combined scores are calibrated like the first stage's (a
//! Platt fit on the training frames' detections, [`crate::calibration::fit_logistic`]) so that they
//! still compare across categories. Features are computed from the first-stage detections only, so the
//! result does not depend on the order the detections are rescored in. Detections of a category the
//! cascade has no classifier for keep their first-stage score. After the stages, a cascade file with a
//! cross-category exclusion ([`Cascade::exclusion`], our addition, [`crate::exclusion`]) demotes each
//! detection under a more confident overlapping one of another category ([`Cascade::rescore`]; the
//! stages alone: [`Cascade::rescore_stages`]).

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::calibration::final_calibration::{FinalCalibration, ScoreSummary};
use crate::calibration::{fit_logistic, label_detections, Calibration};
use crate::category::{category_index, is_cross_score_category, CROSS_SCORE_CATEGORIES, LARGE_CATEGORIES};
use crate::error::{Error, Result};
use crate::eval::{
    average_precision, bootstrap_frames, percentile_interval, true_positives_in_input_order, Bootstrap, Detection,
    FrameDetections, MatchedDetections, ScoredBox,
};
use crate::exclusion::Exclusion;
use crate::frame::Object;
use crate::geometry::{footprint_overlap_area, intersection_volume, polygon_contains, Cuboid};
use crate::learn::binary_svm::{balanced_costs, train_linear_svm_from, SvmSolution};
use crate::learn::checkpoint::{fnv1a, FNV_OFFSET};
use crate::model::{check_weight_magnitudes, Model};
use glam::{Vec2, Vec3};

pub mod nested;
pub use nested::NestedFolds;

/// The `format` field of a cascade file.
pub const FORMAT: &str = "cog-gpu-cascade";
/// The file format's version.
pub const VERSION: u32 = 1;
/// Name of the feature set with the neighbourhood and geometry parts (module doc; `cascade --features v5`).
pub const V5_FEATURES: &str = "object-overlap-layout-geometry-v5";
/// Name of the feature set that adds the scene part to v5 (module doc; `cascade --features v6`).
pub const V6_FEATURES: &str = "object-overlap-layout-geometry-scene-v6";
/// Name of the feature set that adds the cross scores to v6 (module doc; `cascade --features v7`).
pub const V7_FEATURES: &str = "object-overlap-layout-geometry-scene-cross-v7";
/// The largest magnitude of a cross score in ψ (module doc).
pub const CROSS_SCORE_CLAMP: f32 = 5.0;
/// The feature set without them: ψ's first part, a prefix of [`V5_FEATURES`]'s (the shipped cascade's).
pub const V4_FEATURES: &str = "object-overlap-layout-v4";
/// The feature set `cascade` trains by default ([`FeatureSet::DEFAULT`]): v4 until v5 has been measured
/// to do better on held-out frames (README, "Context cascade").
pub const FEATURES: &str = V4_FEATURES;
/// Earlier feature sets, equal to [`V4_FEATURES`] when every context category is large (v2: the 3D overlap
/// for every pair; v3: also the top-down overlap for a large category with a small context category), so
/// such a cascade file is still read.
pub const PREVIOUS_FEATURES: [&str; 2] = ["object-overlap-layout-v2", "object-overlap-layout-v3"];
/// The cascade's file name inside a models directory (next to `<category>.json`).
pub const FILE_NAME: &str = "cascade.json";
/// Values of the SVM's `C` tried by cross-validation.
pub const C_GRID: [f64; 4] = [0.01, 0.1, 1.0, 10.0];
/// The level of [`SecondStage::cv_gain_interval`].
pub const GAIN_LEVEL: f32 = 0.9;
/// The bootstrap behind [`SecondStage::cv_gain_interval`]: resamples and seed (fixed, so that training
/// twice gives the same interval).
pub const GAIN_BOOTSTRAP: Bootstrap = Bootstrap { resamples: 1000, seed: 20_261_204 };
/// Features per context category.
const PER_CATEGORY: usize = 5;
/// Centres of the radial basis expansion of the wall distance `D` (metres; module doc).
pub const RBF_CENTRES: [f64; 5] = [0.0, 0.25, 0.5, 1.0, 2.0];
/// Widths σ of the radial basis functions (metres).
pub const RBF_WIDTHS: [f64; 5] = [0.15, 0.15, 0.25, 0.5, 1.0];
/// Length of the room layout's part of ψ: `no_room`, `A`, `p_i·A`, 5 `r(D)`, 5 `p_i·r(D)`.
pub const LAYOUT_FEATURES: usize = 3 + 2 * RBF_CENTRES.len();

/// How far (metres) around a detection's footprint its neighbourhood reaches: a detection of another
/// category counts as a neighbour when its footprint meets the detection's footprint grown by this much on
/// every side (module doc).
pub const NEIGHBOURHOOD_MARGIN: f32 = 0.5;
/// Length of the geometry part of ψ: `l, l², s, s², h, h², b, b²` (module doc).
pub const GEOMETRY_FEATURES: usize = 8;

/// A cascade's feature set: which parts ψ has (module doc). Each set's ψ is a prefix of the next one's,
/// so the order is that of inclusion.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum FeatureSet {
    /// Overlap and layout parts ([`V4_FEATURES`], and [`PREVIOUS_FEATURES`] for large categories).
    V4,
    /// Also the neighbourhood and geometry parts ([`V5_FEATURES`]).
    V5,
    /// Also the scene part ([`V6_FEATURES`]).
    V6,
    /// Also the cross scores ([`V7_FEATURES`]).
    V7,
}

impl FeatureSet {
    /// The set `cascade` trains unless told otherwise ([`FEATURES`]).
    pub const DEFAULT: FeatureSet = FeatureSet::V4;

    /// The name a cascade file stores.
    pub fn name(self) -> &'static str {
        match self {
            FeatureSet::V4 => V4_FEATURES,
            FeatureSet::V5 => V5_FEATURES,
            FeatureSet::V6 => V6_FEATURES,
            FeatureSet::V7 => V7_FEATURES,
        }
    }

    /// What a stage of this set stores as its [`SecondStage::features`] in a file of `file_set`: its name
    /// when the two differ, else nothing (it reads the file's).
    pub fn name_unless(self, file_set: FeatureSet) -> Option<String> {
        (self != file_set).then(|| self.name().to_string())
    }

    /// The set a cascade file names, given whether its context categories are all large; `None` when this
    /// build cannot compute it.
    pub fn named(name: &str, all_large: bool) -> Option<FeatureSet> {
        match name {
            V7_FEATURES => Some(FeatureSet::V7),
            V6_FEATURES => Some(FeatureSet::V6),
            V5_FEATURES => Some(FeatureSet::V5),
            V4_FEATURES => Some(FeatureSet::V4),
            _ if all_large && PREVIOUS_FEATURES.contains(&name) => Some(FeatureSet::V4),
            _ => None,
        }
    }

    /// The short name `cascade --features` takes: `v4`, `v5`, `v6` or `v7`.
    pub fn short_name(self) -> &'static str {
        match self {
            FeatureSet::V4 => "v4",
            FeatureSet::V5 => "v5",
            FeatureSet::V6 => "v6",
            FeatureSet::V7 => "v7",
        }
    }

    /// Length of ψ for `context_categories` categories.
    pub fn dim(self, context_categories: usize) -> usize {
        let v4 = 2 + PER_CATEGORY * context_categories + LAYOUT_FEATURES;
        let v5 = v4 + context_categories + GEOMETRY_FEATURES;
        match self {
            FeatureSet::V4 => v4,
            FeatureSet::V5 => v5,
            FeatureSet::V6 => v5 + context_categories,
            FeatureSet::V7 => v5 + context_categories + CROSS_SCORE_CATEGORIES.len(),
        }
    }
}

/// Length of ψ of the default feature set ([`FEATURES`]) for `context_categories` categories.
pub fn feature_dim(context_categories: usize) -> usize {
    FeatureSet::DEFAULT.dim(context_categories)
}

/// One frame of a cascade's training set: its annotated objects, its first-stage detections and its
/// predicted room (floor polygon, upright x-y), when the detections file has one.
#[derive(Clone, Debug)]
pub struct CascadeFrame {
    pub truth: Vec<Object>,
    pub detections: Vec<Detection>,
    pub room: Option<Room>,
}

/// A frame's predicted room as the cascade reads it: the floor polygon (upright x-y, metres) and the
/// floor's height (upright z), both as `detect` writes them under `"layout"`.
#[derive(Clone, Debug, PartialEq)]
pub struct Room {
    pub corners: Vec<Vec2>,
    pub floor: f32,
}

/// A detections file (`path`, its `text`) with its room: the floor polygon and floor height that `detect`
/// writes under `"layout"` (the `corners` and `floor` of `room_layout::output::LayoutRecord`), or `None`
/// when the file has none.
pub fn read_detections_and_room(path: &Path) -> Result<(FrameDetections, Option<Room>)> {
    let text = crate::frame::read_text(path)?;
    Ok((FrameDetections::parse(path, &text)?, room_in(path, &text)?))
}

/// The room of a detections file's `text` (see [`read_detections_and_room`]); errors name `path`.
pub fn room_in(path: &Path, text: &str) -> Result<Option<Room>> {
    #[derive(Deserialize)]
    struct File {
        layout: Option<Layout>,
    }
    #[derive(Deserialize)]
    struct Layout {
        corners: Vec<[f32; 2]>,
        floor: Option<f32>,
        ceiling: Option<f32>,
    }
    let file: File = serde_json::from_str(text).map_err(|e| Error::invalid(path, e.to_string()))?;
    let Some(layout) = file.layout else { return Ok(None) };
    // A missing floor (NaN) fails the check: the geometry features need it.
    let floor = layout.floor.unwrap_or(f32::NAN);
    // The layout file's own rules: a room beyond them is no room `detect` predicts, and its wall distances
    // would drive the stages' features far outside anything they were trained on.
    crate::room_layout::output::check_room(&layout.corners, floor, layout.ceiling)
        .map_err(|problem| Error::invalid(path, problem))?;
    Ok(Some(Room { corners: layout.corners.into_iter().map(Vec2::from).collect(), floor }))
}

/// `(D, A)` of the module doc: the signed distance (metres) from the nearest of `cuboid`'s four footprint
/// corners to the closest wall segment of `room` (a footprint across a wall keeps its corners' distance,
/// not 0), and its angle to that wall folded into [0, 1] (1 = 45°). `None` when the polygon has no segment
/// of positive length.
pub fn wall_context(cuboid: &Cuboid, room: &[Vec2]) -> Option<(f64, f64)> {
    let footprint = cuboid.footprint();
    let mut closest: Option<(f32, Vec2)> = None;
    for (n, &a) in room.iter().enumerate() {
        let b = room[(n + 1) % room.len()];
        let along = b - a;
        let length_sq = along.length_squared();
        if length_sq <= 0.0 || !length_sq.is_finite() {
            continue;
        }
        for &p in &footprint {
            let distance = crate::geometry::point_segment_distance(p, a, b);
            if closest.is_none_or(|(d, _)| distance < d) {
                closest = Some((distance, along));
            }
        }
    }
    let (distance, wall) = closest?;
    let inside = polygon_contains(room, cuboid.centre.truncate());
    let d = if inside { f64::from(distance) } else { -f64::from(distance) };
    let width_axis = Vec2::new(cuboid.yaw.cos(), cuboid.yaw.sin());
    let wall = wall.normalize();
    // The angle between the two directions, folded modulo 90° into [0°, 45°].
    let angle = width_axis.perp_dot(wall).atan2(width_axis.dot(wall)).abs() as f64;
    let folded = angle % std::f64::consts::FRAC_PI_2;
    let folded = folded.min(std::f64::consts::FRAC_PI_2 - folded);
    Some((d, folded / std::f64::consts::FRAC_PI_4))
}

/// One category's second stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SecondStage {
    /// The stage's own feature set, when it is not the file's [`Cascade::features`] (a cascade trained
    /// with `cascade --features best` picks each category's set by cross-validation); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub features: Option<String>,
    pub weights: Vec<f64>,
    pub bias: f64,
    /// The SVM's C (chosen by cross-validation).
    pub c: f64,
    /// Cross-validated AP of the first-stage score and of the combined score (the choice of `C`).
    pub cv_ap_first_stage: f32,
    pub cv_ap_cascade: f32,
    /// The central 90 % ([`GAIN_LEVEL`]) bootstrap interval of the cross-validated gain `cv_ap_cascade −
    /// cv_ap_first_stage` (a paired bootstrap over the cascade set's frames; see [`StageRule`]); absent in
    /// files written before it was recorded (2026-12-04).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cv_gain_interval: Option<[f32; 2]>,
    /// The nested cross-validated gain of the training procedure that chose this stage ([`nested`]: `C` and
    /// the feature set chosen inside each fold), recorded when the cascade was trained with
    /// [`StageRule::NestedGain`]; absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cv_gain_nested: Option<f32>,
    /// Maps the combined score `z + z'` to a probability.
    pub calibration: Calibration,
}

impl SecondStage {
    /// Its numbers are usable: weights and bias finite and within ±[`MAX_WEIGHT`](crate::model::MAX_WEIGHT) as a model's (larger ones
    /// would overflow the `f32` scores to infinity), the gain's interval (when recorded) finite and in
    /// order, and a valid calibration.
    pub fn check_numbers(&self) -> std::result::Result<(), String> {
        if self.weights.iter().chain([&self.bias]).any(|v| !v.is_finite()) {
            return Err("a weight is not finite".into());
        }
        // The models' check, on the weights as the scores use them (`f32`: beyond its range, infinite).
        let weights: Vec<f32> = self.weights.iter().map(|&w| w as f32).collect();
        check_weight_magnitudes(&weights, self.bias as f32)?;
        if let Some([low, high]) = self.cv_gain_interval {
            if !(low.is_finite() && high.is_finite() && low <= high) {
                return Err(format!("cv_gain_interval [{low}, {high}] is not an interval"));
            }
        }
        if let Some(gain) = self.cv_gain_nested {
            if !(-1.0..=1.0).contains(&gain) {
                return Err(format!("cv_gain_nested {gain} is not a difference of two APs"));
            }
        }
        self.calibration.validate()
    }

    /// Whether this stage replaces `incumbent` when stages of several feature sets compete for a category
    /// (`--features best`, [`StageOutcome::chosen`], [`Cascade::merged_with`]): a strictly higher
    /// cross-validated AP, so that ties keep the incumbent (the earlier set or file).
    pub fn outranks(&self, incumbent: Option<&SecondStage>) -> bool {
        incumbent.is_none_or(|other| self.cv_ap_cascade > other.cv_ap_cascade)
    }
}

/// Which trained stages a cascade keeps (`cascade --keep`). A stage's cross-validated gain is the largest
/// of [`C_GRID`]'s (and, with several feature sets, of every set's): a maximum over noisy estimates, which
/// overstates the gain most where the category has few examples (the TV's stage on the 2 000-frame
/// cascade set of 2026-12-04: +0.2 cross-validated on 41 true positives, −20.9 on the test set).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StageRule {
    /// Every stage whose cross-validated AP is above the first stage's (the rule of every cascade shipped
    /// so far).
    #[default]
    AnyGain,
    /// Only stages whose gain is beyond the noise of the frames: the lower end of its 90 % interval
    /// ([`SecondStage::cv_gain_interval`]) above 0 — one-sided, the gain is positive at 95 %.
    SignificantGain,
    /// Only stages of a category whose training procedure gains in a nested cross-validation
    /// ([`nested`]: `C` and the feature set chosen inside each fold, the gain measured on the other):
    /// the gain's estimate without the bias of choosing the best of many. Applied to a category's
    /// candidates together ([`StageOutcome`]), not to one stage.
    NestedGain,
}

impl StageRule {
    /// Whether training must compute the nested cross-validation's numbers ([`NestedFolds`]).
    pub fn needs_nested(self) -> bool {
        self == StageRule::NestedGain
    }

    /// `Ok` when the rule keeps `stage`, or why it does not.
    pub fn admits(self, stage: &SecondStage) -> std::result::Result<(), String> {
        match (self, stage.cv_gain_interval) {
            (StageRule::AnyGain | StageRule::NestedGain, _) => Ok(()),
            (StageRule::SignificantGain, Some([low, high])) if low <= 0.0 => Err(format!(
                "the context's cross-validated gain {:+.1} is within the noise (its {:.0} % interval [{:+.1}, {:+.1}] \
                 reaches 0)",
                100.0 * (stage.cv_ap_cascade - stage.cv_ap_first_stage),
                100.0 * GAIN_LEVEL,
                100.0 * low,
                100.0 * high
            )),
            (StageRule::SignificantGain, Some(_)) => Ok(()),
            (StageRule::SignificantGain, None) => {
                Err("no interval of the cross-validated gain recorded (a stage trained before 2026-12-04)".into())
            }
        }
    }
}

/// Where a cascade came from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CascadeTraining {
    /// Data directory and number of frames the detections came from.
    pub data: String,
    pub frames: usize,
    /// The detections directory and the first-stage models that produced it.
    pub detections: String,
    pub iou: f32,
    /// The calibration of every first-stage model the cascade was trained with, by category. A stage adds
    /// its context score to its model's raw score and every context feature reads calibrated
    /// probabilities, so the cascade holds only for these models: a retrained (hence recalibrated) model
    /// changes its calibration, and [`Cascade::check_models`] refuses it. Empty in files written before
    /// it was recorded (then nothing can be checked).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub calibrations: BTreeMap<String, Calibration>,
}

impl CascadeTraining {
    /// What differs between two trainings' records, one phrase per field (data, detections, frames, IoU,
    /// and the categories whose model calibration differs or is recorded in one only).
    pub fn differences(&self, other: &CascadeTraining) -> Vec<String> {
        let mut differences = Vec::new();
        if self.data != other.data {
            differences.push(format!("data '{}' and '{}'", self.data, other.data));
        }
        if self.detections != other.detections {
            differences.push(format!("detections '{}' and '{}'", self.detections, other.detections));
        }
        if self.frames != other.frames {
            differences.push(format!("{} and {} frames", self.frames, other.frames));
        }
        if self.iou != other.iou {
            differences.push(format!("IoU {} and {}", self.iou, other.iou));
        }
        let categories: std::collections::BTreeSet<&String> =
            self.calibrations.keys().chain(other.calibrations.keys()).collect();
        let recalibrated: Vec<&str> = categories
            .into_iter()
            .filter(|c| self.calibrations.get(*c) != other.calibrations.get(*c))
            .map(String::as_str)
            .collect();
        if !recalibrated.is_empty() {
            differences.push(format!("the first-stage calibrations of {}", recalibrated.join(", ")));
        }
        differences
    }
}

/// A trained cascade: the context categories (feature order) and a second stage per category.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cascade {
    pub format: String,
    pub version: u32,
    pub features: String,
    pub categories: Vec<String>,
    pub stages: BTreeMap<String, SecondStage>,
    pub training: CascadeTraining,
    /// Cross-category exclusion applied after the stages ([`crate::exclusion`]), when fitted on held-out
    /// frames (`calibrate --cascade C --exclusion`); absent in files without it (no exclusion).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exclusion: Option<Exclusion>,
    /// One map of every detection's score applied last, after the stages and the exclusion
    /// ([`crate::calibration::final_calibration`]), when fitted on held-out frames
    /// (`calibrate --cascade C --final`); absent in files without it (the scores as the exclusion leaves
    /// them). Refitting the stages' calibrations or the exclusion drops it (it was fitted on their scores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub final_calibration: Option<FinalCalibration>,
}

impl Cascade {
    /// Reads and checks a cascade file.
    pub fn read(path: &Path) -> Result<Cascade> {
        let text = crate::frame::read_text(path)?;
        let cascade: Cascade = serde_json::from_str(&text)
            .map_err(|e| Error::invalid(path, format!("not a cog-gpu cascade file: {e}")))?;
        cascade.check().map_err(|problem| Error::invalid(path, problem))?;
        Ok(cascade)
    }

    /// Errors unless every model of a category the cascade recorded a calibration for
    /// ([`CascadeTraining::calibrations`]) carries that calibration (the same `a` and `b`): a cascade
    /// applied to other first-stage models than its own would rescore with scores on another scale.
    /// Models of other categories, and cascades that recorded nothing, pass.
    pub fn check_models(&self, models: &[Model]) -> Result<()> {
        for model in models {
            let Some(trained) = self.training.calibrations.get(&model.category) else { continue };
            let same = model.calibration.as_ref().is_some_and(|c| c.a == trained.a && c.b == trained.b);
            if !same {
                let loaded = model
                    .calibration
                    .as_ref()
                    .map_or("no calibration".to_string(), |c| format!("calibration a = {}, b = {}", c.a, c.b));
                return Err(Error::Input(format!(
                    "the cascade was trained with another '{}' model (calibration a = {}, b = {}; the loaded \
                     model has {loaded}): retrain the cascade on this model's detections (cog-gpu cascade)",
                    model.category, trained.a, trained.b
                )));
            }
        }
        Ok(())
    }

    /// Errors unless every detection of a category with a recorded calibration
    /// ([`CascadeTraining::calibrations`]) has the score that calibration gives its raw score (within
    /// 10⁻⁵ relative, for files written by other builds): detections of another model than the cascade's
    /// (as [`Cascade::check_models`] refuses for `detect`), found in the files `rescore` reads.
    fn check_scores(&self, detections: &[Detection]) -> Result<()> {
        match score_off_its_calibration(&self.training.calibrations, detections) {
            Some((d, raw, expected)) => Err(Error::Input(format!(
                "a '{}' detection has score {} where the cascade's '{}' model gives its raw score {raw} the \
                 probability {expected}: the detections come from another model than the one the cascade was \
                 trained with (retrain the cascade on them: cog-gpu cascade)",
                d.category, d.score, d.category
            ))),
            None => Ok(()),
        }
    }

    /// Writes the file — only a cascade that [`Cascade::check`] accepts, so that nothing this writes is
    /// refused by its readers (a stage resumed from a damaged checkpoint, say).
    pub fn write(&self, path: &Path) -> Result<()> {
        self.check().map_err(|problem| Error::invalid(path, format!("not written: {problem}")))?;
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::invalid(path, e.to_string()))?;
        crate::error::write_replacing(path, text.as_bytes())
    }

    /// The stored numbers are usable: known format and features; context categories that are cog-gpu's,
    /// each once; stages of cog-gpu's categories with weights of the right length, finite and within
    /// ±[`MAX_WEIGHT`](crate::model::MAX_WEIGHT) as a model's (larger ones would overflow the `f32` scores to infinity).
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.format != FORMAT || self.version != VERSION {
            return Err(format!(
                "not a {FORMAT} version {VERSION} file (format '{}', version {})",
                self.format, self.version
            ));
        }
        if self.categories.is_empty() {
            return Err("no context categories".into());
        }
        // The calibrations recorded at training (every first-stage model's, since they were recorded) are
        // what `detect` and `rescore` check their models and files against; one left out of a file that
        // has them would pass another model's detections unchecked.
        if !self.training.calibrations.is_empty() {
            if let Some(category) = self.stages.keys().find(|c| !self.training.calibrations.contains_key(*c)) {
                return Err(format!(
                    "training.calibrations has no entry for the stage '{category}' (it records every first-stage \
                     model's calibration)"
                ));
            }
        }
        for (n, category) in self.categories.iter().enumerate() {
            if category_index(category).is_none() {
                return Err(format!("context category '{category}' is not one of cog-gpu's"));
            }
            if self.categories[..n].contains(category) {
                return Err(format!("context category '{category}' is listed twice"));
            }
        }
        let unknown = |name: &str| {
            format!(
                "feature set '{name}' is not one of this build's '{V7_FEATURES}', '{V6_FEATURES}', '{V5_FEATURES}', \
                 '{V4_FEATURES}'"
            )
        };
        self.feature_set().ok_or_else(|| unknown(&self.features))?;
        for (category, stage) in &self.stages {
            let set = self
                .stage_feature_set(stage)
                .ok_or_else(|| format!("'{category}': {}", unknown(stage.features.as_deref().unwrap_or_default())))?;
            let dim = set.dim(self.categories.len());
            if stage.weights.len() != dim {
                return Err(format!("'{category}': {} weights, expected {dim}", stage.weights.len()));
            }
            if category_index(category).is_none() {
                return Err(format!("a stage for '{category}', which is not one of cog-gpu's categories"));
            }
            stage.check_numbers().map_err(|e| format!("'{category}': {e}"))?;
        }
        if let Some(exclusion) = &self.exclusion {
            exclusion.check()?;
        }
        if let Some(calibration) = &self.final_calibration {
            calibration.validate()?;
        }
        Ok(())
    }

    /// The feature set the file names (`None` when this build cannot compute it): every stage's, but for
    /// a stage that names its own ([`SecondStage::features`]).
    pub fn feature_set(&self) -> Option<FeatureSet> {
        FeatureSet::named(&self.features, self.all_large())
    }

    /// The feature set `stage` reads: its own when it names one, else the file's ([`Cascade::feature_set`]);
    /// `None` when this build cannot compute it.
    pub fn stage_feature_set(&self, stage: &SecondStage) -> Option<FeatureSet> {
        match &stage.features {
            Some(name) => FeatureSet::named(name, self.all_large()),
            None => self.feature_set(),
        }
    }

    /// Combines `self` with `other`, a cascade trained on the same frames, detections and first-stage
    /// models (the same [`Cascade::categories`], in order, and the same [`CascadeTraining`]) with other
    /// feature sets: per category the stage with the higher cross-validated AP (ties: `self`'s), as
    /// `cascade --features best` chooses among its sets. A stage's training reads only its own set, so
    /// merging a cascade of `--features best` (v4 and v5) with one of `--features v6` gives the cascade
    /// that the three sets together would train. The merged file names `self`'s set, and a stage taken
    /// from `other` whose set differs names its own ([`SecondStage::features`]). Errors say what differs.
    pub fn merged_with(&self, other: &Cascade) -> std::result::Result<Cascade, String> {
        if self.categories != other.categories {
            return Err(format!(
                "the cascades have different categories ({} and {}): they were not trained on the same detections",
                self.categories.join(","),
                other.categories.join(",")
            ));
        }
        if self.training != other.training {
            return Err(format!(
                "the cascades were not trained on the same frames, detections and models: {}",
                self.training.differences(&other.training).join(", ")
            ));
        }
        if self.exclusion != other.exclusion {
            return Err(format!(
                "the cascades have different cross-category exclusions ({:?} and {:?}): merge cascades without \
                 one, then fit it on the merged cascade (calibrate --cascade --exclusion)",
                self.exclusion, other.exclusion
            ));
        }
        if self.final_calibration != other.final_calibration {
            return Err("the cascades have different final calibrations: merge cascades without one, then fit it \
                        on the merged cascade (calibrate --cascade --final)"
                .to_string());
        }
        let file_set = self.feature_set().ok_or_else(|| format!("unknown feature set '{}'", self.features))?;
        let mut merged = self.clone();
        for (category, stage) in &other.stages {
            let set = other
                .stage_feature_set(stage)
                .ok_or_else(|| format!("'{category}': unknown feature set of the second cascade"))?;
            if stage.outranks(merged.stages.get(category)) {
                let features = set.name_unless(file_set);
                merged.stages.insert(category.clone(), SecondStage { features, ..stage.clone() });
            }
        }
        merged.check()?;
        Ok(merged)
    }

    /// Whether a stage reads the cross scores (feature set v7): `detect` computes them then.
    pub fn reads_cross_scores(&self) -> bool {
        self.stages.values().any(|stage| self.stage_feature_set(stage).is_some_and(|set| set >= FeatureSet::V7))
    }

    /// Whether every context category is large (the earlier feature sets are read only then).
    fn all_large(&self) -> bool {
        self.categories.iter().all(|c| is_large(c))
    }

    /// Rescores one frame's first-stage detections (module doc) in the frame's predicted `room` (floor
    /// polygon; `None` without a layout), applies the cross-category exclusion when the cascade has one
    /// ([`Cascade::exclusion`]) and then its final calibration when it has one
    /// ([`Cascade::final_calibration`]), and sorts them by score, best first (stable). Detections must be
    /// the first stage's, calibrated (`raw_score` present) and not rescored.
    pub fn rescore(&self, detections: &mut [Detection], room: Option<&Room>) -> Result<()> {
        self.rescore_before_final_calibration(detections, room)?;
        if let Some(calibration) = &self.final_calibration {
            calibration.apply(detections);
        }
        Ok(())
    }

    /// [`Cascade::rescore`] without the final calibration: the stages' scores after the exclusion, sorted
    /// best first (stable) — what the final calibration is fitted on.
    pub fn rescore_before_final_calibration(&self, detections: &mut [Detection], room: Option<&Room>) -> Result<()> {
        self.rescore_stages(detections, room)?;
        if let Some(exclusion) = &self.exclusion {
            exclusion.apply(detections);
            detections.sort_by(|a, b| b.score.total_cmp(&a.score));
        }
        Ok(())
    }

    /// [`Cascade::rescore`] without the exclusion: the stages' scores, sorted best first (stable) — what
    /// the stages' calibration and the exclusion are fitted on.
    pub fn rescore_stages(&self, detections: &mut [Detection], room: Option<&Room>) -> Result<()> {
        check_first_stage(detections)?;
        self.check_scores(detections)?;
        // ψ of the widest set any stage reads: each set's ψ is a prefix of the next one's (module doc), so
        // a stage's weights (as long as its own set's ψ) take their prefix of it.
        let mut widest = FeatureSet::V4;
        for stage in self.stages.values() {
            let set = self.stage_feature_set(stage).ok_or_else(|| {
                Error::Input(format!("unknown feature set '{}'", stage.features.as_deref().unwrap_or(&self.features)))
            })?;
            widest = widest.max(set);
        }
        if widest >= FeatureSet::V7 {
            check_cross_scores(detections)?;
        }
        let features = frame_context_features(detections, &self.categories, room, widest);
        let rescored: Vec<Option<(f32, f32)>> = (0..detections.len())
            .map(|i| {
                let stage = self.stages.get(&detections[i].category)?;
                // Zipping stops at the stage's own length: its set's prefix of ψ.
                let decision: f64 = stage.weights.iter().zip(&features[i]).map(|(w, v)| w * v).sum::<f64>();
                let context = (decision + stage.bias) as f32;
                Some((context, stage.calibration.probability(combined(&detections[i], context))))
            })
            .collect();
        for (d, new) in detections.iter_mut().zip(rescored) {
            if let Some((context, probability)) = new {
                d.first_stage_score = Some(d.score);
                d.context_score = Some(context);
                d.score = probability;
            }
        }
        detections.sort_by(|a, b| b.score.total_cmp(&a.score));
        Ok(())
    }
}

/// One stage's calibration fitted again on held-out frames ([`Cascade::recalibrated`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Recalibration {
    pub category: String,
    /// The stage's calibration before (as trained: a Platt fit on the cascade set's own detections, scored
    /// by the SVM trained on them) and after (fitted on the held-out frames).
    pub before: Calibration,
    pub after: Calibration,
    /// The held-out detections' mean negative log-likelihood of their labels under each calibration.
    pub log_loss_before: f64,
    pub log_loss_after: f64,
    /// The expected number of true positives under the calibration before (the sum of its probabilities
    /// over the held-out detections); the fit's own `true_positives` is the number found.
    pub expected_true_positives_before: f64,
}

/// One held-out frame as [`Cascade::recalibrated`] reads it: its first-stage detections (`detect
/// --no-cascade`), their predicted room, and its annotated objects.
pub struct HeldOutFrame<'a> {
    pub detections: &'a [Detection],
    pub room: Option<&'a Room>,
    pub truth: &'a [Object],
}

impl Cascade {
    /// This cascade with the calibration of every stage of `categories` (every stage when empty) fitted
    /// again on held-out frames: each frame's first-stage detections rescored by the stages, each
    /// detection's combined score `z + z'` labelled by the benchmark's matching at `iou_threshold` (in the
    /// order of those scores), and a Platt fit ([`fit_logistic`]) per category on `(z + z', true
    /// positive)`. Weights, biases and every other number stay; the scores' order within a category, hence
    /// its AP, does not change. `data` names the frames in the calibration's provenance.
    ///
    /// Why (our choice; the paper calibrates nothing): `cascade` fits a stage's calibration on the very
    /// detections its SVM was trained on, whose combined scores may separate true from false positives
    /// better than on any other frames, which would make its probabilities too confident — and the overlay,
    /// `--min-probability` and `--overlay-min-score` compare probabilities across categories. Fitting them
    /// on frames the cascade never saw is what `calibrate` does for the first stage. (Measured on the
    /// shipped cascade, README "The cascade's calibration": its stored calibrations are not too confident
    /// on held-out frames, and a refit gained no overlay precision, so it ships as trained.) Errors (naming the categories) when a category has no true or no false positive among
    /// the held-out detections: nothing is returned, so no cascade is half recalibrated. A final
    /// calibration ([`Cascade::final_calibration`]) was fitted on the stages' old probabilities: the result
    /// has none (fit it again: `calibrate --cascade --final`).
    pub fn recalibrated(
        &self,
        frames: &[HeldOutFrame],
        categories: &[String],
        iou_threshold: f32,
        data: &str,
    ) -> Result<(Cascade, Vec<Recalibration>)> {
        if let Some(unknown) = categories.iter().find(|c| !self.stages.contains_key(*c)) {
            return Err(Error::Input(format!("the cascade has no stage for '{unknown}'")));
        }
        // Each detection with its combined score in `raw_score`, the score `label_detections` reads.
        let mut combined_detections = Vec::with_capacity(frames.len());
        let mut truth = Vec::with_capacity(frames.len());
        for frame in frames {
            let mut detections = frame.detections.to_vec();
            self.rescore_stages(&mut detections, frame.room)?;
            for d in &mut detections {
                if let Some(context) = d.context_score {
                    d.raw_score = Some(combined(d, context));
                }
            }
            combined_detections.push(detections);
            truth.push(frame.truth.to_vec());
        }
        let mut cascade = Cascade { final_calibration: None, ..self.clone() };
        let mut report = Vec::new();
        let mut failures = Vec::new();
        for (category, stage) in &mut cascade.stages {
            if !categories.is_empty() && !categories.contains(category) {
                continue;
            }
            let samples = label_detections(&combined_detections, &truth, category, iou_threshold);
            let (a, b) = match fit_logistic(&samples) {
                Ok(fit) => fit,
                Err(err) => {
                    failures.push(format!("{category}: {err}"));
                    continue;
                }
            };
            let after = Calibration {
                a,
                b,
                detections: samples.len(),
                true_positives: samples.iter().filter(|s| s.1).count(),
                iou: iou_threshold,
                data: data.to_string(),
                frames: frames.len(),
            };
            let before = ScoreSummary::of(&samples, |z| stage.calibration.probability(z));
            report.push(Recalibration {
                category: category.clone(),
                before: stage.calibration.clone(),
                log_loss_before: before.log_loss,
                log_loss_after: ScoreSummary::of(&samples, |z| after.probability(z)).log_loss,
                expected_true_positives_before: before.expected_true_positives,
                after: after.clone(),
            });
            stage.calibration = after;
        }
        if !failures.is_empty() {
            return Err(Error::Input(format!(
                "cannot calibrate the cascade's stages on these detections: {}",
                failures.join("; ")
            )));
        }
        cascade.check().map_err(Error::Input)?;
        Ok((cascade, report))
    }
}

/// `z + z'`: the first stage's raw score plus the context score.
fn combined(detection: &Detection, context: f32) -> f32 {
    detection.raw_score.unwrap_or(detection.score) + context
}

/// Errors unless every detection is a calibrated first-stage one.
pub fn check_first_stage(detections: &[Detection]) -> Result<()> {
    let rescored = |d: &&Detection| {
        d.context_score.is_some() || d.score_before_exclusion.is_some() || d.score_before_final_calibration.is_some()
    };
    if let Some(d) = detections.iter().find(rescored) {
        return Err(Error::Input(format!(
            "a '{}' detection was already rescored by a cascade; the cascade takes first-stage detections \
             (detect --no-cascade)",
            d.category
        )));
    }
    if let Some(d) = detections.iter().find(|d| d.raw_score.is_none()) {
        return Err(Error::Input(format!(
            "a '{}' detection has no raw_score: the cascade needs calibrated first-stage models \
             (cog-gpu calibrate) so that confidences compare across categories",
            d.category
        )));
    }
    Ok(())
}

/// ψ of every detection of one frame's first-stage `detections` (module doc), in their order, in the
/// frame's predicted `room`; `p` is each detection's `score` (the first stage's calibrated probability).
/// The detections' rows are independent, so they are computed in parallel (the same numbers on any
/// number of threads).
pub fn frame_context_features(
    detections: &[Detection],
    categories: &[String],
    room: Option<&Room>,
    set: FeatureSet,
) -> Vec<Vec<f64>> {
    let frame = FrameContext::new(detections, categories);
    (0..detections.len()).into_par_iter().map(|i| context_features(&frame, i, room, set)).collect()
}

/// What every ψ of one frame reads, computed once per frame: the detections' cuboids, each context
/// category's detections (indices in the frame's order) and its [`scene_maxima`]. ψ pairs each detection
/// with the others (module doc), so a frame of `n` detections costs `n²` pair visits; grouping them by
/// category once makes each visit one comparison of scores or one overlap test, instead of a search of
/// the category list for every pair (a frame of 88 354 detections took over two minutes before).
struct FrameContext<'a> {
    detections: &'a [Detection],
    categories: &'a [String],
    boxes: Vec<Cuboid>,
    /// Per context category, the indices of its detections, ascending.
    members: Vec<Vec<usize>>,
    scene: Vec<TopTwo>,
}

impl<'a> FrameContext<'a> {
    fn new(detections: &'a [Detection], categories: &'a [String]) -> Self {
        let mut members = vec![Vec::new(); categories.len()];
        for (j, detection) in detections.iter().enumerate() {
            if let Some(k) = categories.iter().position(|c| c == &detection.category) {
                members[k].push(j);
            }
        }
        FrameContext {
            detections,
            categories,
            boxes: detections.iter().map(Detection::cuboid).collect(),
            scene: scene_maxima(detections, categories),
            members,
        }
    }
}

/// ψ of detection `i` of `frame`.
fn context_features(frame: &FrameContext, i: usize, room: Option<&Room>, set: FeatureSet) -> Vec<f64> {
    let (detections, boxes, categories) = (frame.detections, &frame.boxes, frame.categories);
    let own = boxes[i];
    let p_i = f64::from(detections[i].score);
    let mut psi = vec![0.0; set.dim(categories.len())];
    psi[0] = p_i;
    psi[1] = p_i * p_i;
    // A small object sees every context category from above (module doc).
    let top_down = !is_large(&detections[i].category);
    for (k, members) in frame.members.iter().enumerate() {
        // (p_j, overlap, j) of the most confident overlapping detection of the category (ties: the
        // earliest in the frame).
        let mut best: Option<(f64, f64, usize)> = None;
        for &j in members {
            let d = &detections[j];
            if j == i || best.is_some_and(|b| f64::from(d.score) <= b.0) {
                continue;
            }
            let overlap = overlap_measure(&own, &boxes[j], top_down);
            if overlap > 0.0 {
                best = Some((f64::from(d.score), overlap, j));
            }
        }
        let Some((p_j, overlap, j)) = best else { continue };
        let (v_i, v_j) = (size_measure(&own, top_down), size_measure(&boxes[j], top_down));
        let union = v_i + v_j - overlap;
        let base = 2 + PER_CATEGORY * k;
        psi[base] = p_j;
        psi[base + 1] = p_j * overlap / v_i;
        psi[base + 2] = p_j * overlap / v_j;
        psi[base + 3] = if union > 0.0 { p_j * overlap / union } else { 0.0 };
        psi[base + 4] = p_i * p_j;
    }
    let layout = 2 + PER_CATEGORY * categories.len();
    match room.and_then(|room| wall_context(&own, &room.corners)) {
        None => psi[layout] = 1.0,
        Some((d, a)) => {
            psi[layout + 1] = a;
            psi[layout + 2] = p_i * a;
            for (m, (c, sigma)) in RBF_CENTRES.iter().zip(RBF_WIDTHS).enumerate() {
                let r = (-(d - c) * (d - c) / (2.0 * sigma * sigma)).exp();
                psi[layout + 3 + m] = r;
                psi[layout + 3 + RBF_CENTRES.len() + m] = p_i * r;
            }
        }
    }
    if set >= FeatureSet::V5 {
        let neighbourhood = layout + LAYOUT_FEATURES;
        psi[neighbourhood..neighbourhood + categories.len()].copy_from_slice(&neighbourhood_confidences(frame, i));
        let geometry = neighbourhood + categories.len();
        psi[geometry..geometry + GEOMETRY_FEATURES].copy_from_slice(&geometry_features(&own, room));
    }
    if set >= FeatureSet::V6 {
        let start = FeatureSet::V5.dim(categories.len());
        for (value, top) in psi[start..].iter_mut().zip(&frame.scene) {
            *value = scene_confidence(top, i);
        }
    }
    if set >= FeatureSet::V7 {
        let start = FeatureSet::V6.dim(categories.len());
        psi[start..start + CROSS_SCORE_CATEGORIES.len()].copy_from_slice(&cross_features(&detections[i]));
    }
    psi
}

/// The cross part of ψ for `detection` (module doc): its [`Detection::cross_scores`] in
/// [`CROSS_SCORE_CATEGORIES`]' order, clamped to ±[`CROSS_SCORE_CLAMP`]; zeros for a detection of another
/// category. A missing score reads 0 here: [`check_cross_scores`] refuses such detections before.
fn cross_features(detection: &Detection) -> [f64; CROSS_SCORE_CATEGORIES.len()] {
    let mut out = [0.0; CROSS_SCORE_CATEGORIES.len()];
    if !is_cross_score_category(&detection.category) {
        return out;
    }
    if let Some(scores) = &detection.cross_scores {
        for (value, category) in out.iter_mut().zip(CROSS_SCORE_CATEGORIES) {
            if let Some(&raw) = scores.get(category) {
                *value = f64::from(raw.clamp(-CROSS_SCORE_CLAMP, CROSS_SCORE_CLAMP));
            }
        }
    }
    out
}

/// Errors unless every detection of [`CROSS_SCORE_CATEGORIES`] carries a finite cross score of each of
/// them (what a v7 stage reads); the message names the first that does not and how to get them.
pub fn check_cross_scores(detections: &[Detection]) -> Result<()> {
    for d in detections.iter().filter(|d| is_cross_score_category(&d.category)) {
        let missing = match &d.cross_scores {
            None => Some("has no cross_scores".to_string()),
            Some(scores) => CROSS_SCORE_CATEGORIES.iter().find_map(|c| match scores.get(*c) {
                None => Some(format!("has no cross score of the '{c}' model")),
                Some(x) if !x.is_finite() => Some(format!("has a cross score of the '{c}' model that is not finite")),
                Some(_) => None,
            }),
        };
        if let Some(problem) = missing {
            return Err(Error::Input(format!(
                "a '{}' detection {problem}: feature set v7 reads the scores of the {} models {} on every \
                 detection of theirs; detect with all of them and this build (detect --no-cascade writes them)",
                d.category,
                CROSS_SCORE_CATEGORIES.len(),
                CROSS_SCORE_CATEGORIES.join(", ")
            )));
        }
    }
    Ok(())
}

/// A category's two most confident detections in a frame, `(confidence, index)`, best first (ties: the
/// earlier in the frame's list first); `None` where the frame has fewer.
type TopTwo = [Option<(f32, usize)>; 2];

/// Per context category its [`TopTwo`] in the frame: computed once per frame, so that each detection's
/// scene part ([`scene_confidence`]) is read off rather than searched for.
fn scene_maxima(detections: &[Detection], categories: &[String]) -> Vec<TopTwo> {
    let mut maxima = vec![[None; 2]; categories.len()];
    for (j, detection) in detections.iter().enumerate() {
        let Some(k) = categories.iter().position(|c| c == &detection.category) else { continue };
        let entry = Some((detection.score, j));
        let top = &mut maxima[k];
        if top[0].is_none_or(|(p, _)| detection.score > p) {
            *top = [entry, top[0]];
        } else if top[1].is_none_or(|(p, _)| detection.score > p) {
            top[1] = entry;
        }
    }
    maxima
}

/// `s_k` of detection `i` from its category's [`TopTwo`]: the largest confidence of a detection of `k`
/// other than `i` anywhere in the frame, 0 when there is none (the scene part, module doc).
fn scene_confidence(top: &TopTwo, i: usize) -> f64 {
    let other = match top {
        [Some((_, j)), second] if *j == i => *second,
        [first, _] => *first,
    };
    other.map_or(0.0, |(p, _)| f64::from(p))
}

/// For each context category `k`, `n_k`: the sum of the confidences of the detections of `k` other than
/// `i` whose footprint meets `i`'s grown by [`NEIGHBOURHOOD_MARGIN`] on every side (module doc), added in
/// the frame's order.
fn neighbourhood_confidences(frame: &FrameContext, i: usize) -> Vec<f64> {
    let own = frame.boxes[i];
    let grown = Cuboid::new(own.centre, own.size + Vec3::new(2.0, 2.0, 0.0) * NEIGHBOURHOOD_MARGIN, own.yaw);
    frame
        .members
        .iter()
        .map(|members| {
            members
                .iter()
                .filter(|&&j| j != i && footprint_overlap_area(&grown, &frame.boxes[j]) > 0.0)
                .map(|&j| f64::from(frame.detections[j].score))
                .fold(0.0, |sum, p| sum + p)
        })
        .collect()
}

/// The geometry part of ψ (module doc): the footprint's longer side `l` and shorter side `s`, the height
/// `h` and the bottom's height above the room's floor `b` (0 without a room), each with its square.
fn geometry_features(cuboid: &Cuboid, room: Option<&Room>) -> [f64; GEOMETRY_FEATURES] {
    let l = f64::from(cuboid.size.x.max(cuboid.size.y));
    let s = f64::from(cuboid.size.x.min(cuboid.size.y));
    let h = f64::from(cuboid.size.z);
    let b = room.map_or(0.0, |room| f64::from(cuboid.bottom() - room.floor));
    [l, l * l, s, s * s, h, h * h, b, b * b]
}

/// Whether `category` is one of the ten large categories, which keep the 3D overlap (module doc).
fn is_large(category: &str) -> bool {
    LARGE_CATEGORIES.contains(&category)
}

/// The overlap `O` of two boxes: their intersection's volume (m³), or with `top_down` the overlap of
/// their footprints seen from above (m²; module doc).
fn overlap_measure(a: &Cuboid, b: &Cuboid, top_down: bool) -> f64 {
    f64::from(if top_down { footprint_overlap_area(a, b) } else { intersection_volume(a, b) })
}

/// The size `V` that goes with [`overlap_measure`]: volume, or with `top_down` the footprint's area.
fn size_measure(b: &Cuboid, top_down: bool) -> f64 {
    if top_down {
        f64::from(b.size.x) * f64::from(b.size.y)
    } else {
        f64::from(b.volume())
    }
}

/// One category's training samples over frames: ψ, the combined-score base `z` (first-stage raw score),
/// the benchmark label, and the frame each came from.
struct Samples {
    psi: Vec<Vec<f64>>,
    raw: Vec<f32>,
    labels: Vec<bool>,
    frame: Vec<usize>,
    cuboids: Vec<Cuboid>,
    /// The category's ground-truth boxes per frame (for the cross-validated AP).
    truth: Vec<Vec<Cuboid>>,
}

/// The samples of `category` (labels as the benchmark matches the first-stage scores).
fn samples_of(
    frames: &[CascadeFrame],
    category: &str,
    categories: &[String],
    iou_threshold: f32,
    set: FeatureSet,
) -> Samples {
    let mut s = Samples { psi: vec![], raw: vec![], labels: vec![], frame: vec![], cuboids: vec![], truth: vec![] };
    let mut boxes = Vec::new();
    for (f, frame) in frames.iter().enumerate() {
        s.truth.push(frame.truth.iter().filter(|o| o.category == category).map(|o| o.cuboid).collect());
        let detections = &frame.detections;
        let context = FrameContext::new(detections, categories);
        for (i, d) in detections.iter().enumerate().filter(|(_, d)| d.category == category) {
            // ψ of this category's detections only (every category's stage reads the same frames).
            let room = frame.room.as_ref();
            s.psi.push(context_features(&context, i, room, set));
            s.raw.push(d.raw_score.unwrap_or(d.score));
            s.frame.push(f);
            s.cuboids.push(d.cuboid());
            boxes.push(ScoredBox { image: f, score: d.raw_score.unwrap_or(d.score), cuboid: d.cuboid() });
        }
    }
    s.labels = true_positives_in_input_order(&boxes, &s.truth, iou_threshold);
    s
}

/// AP on the frames of fold `fold` ([`in_fold`]) of their samples `subset` scored by `scores` (one per
/// sample of `subset`): the ground truth of every frame of the fold counts, also of a frame without a
/// detection of the category (until 2026-12-08 only the frames holding one of `subset`'s samples counted,
/// which left such a frame's boxes out and raised both APs, each fold by its own factor — so the mean
/// gain could change sign — while [`cv_gain_interval`] counted them).
fn subset_ap(s: &Samples, subset: &[usize], scores: &[f32], fold: usize, iou_threshold: f32) -> f32 {
    let boxes: Vec<ScoredBox> = subset
        .iter()
        .zip(scores)
        .map(|(&n, &score)| ScoredBox { image: s.frame[n], score, cuboid: s.cuboids[n] })
        .collect();
    let truth: Vec<Vec<Cuboid>> =
        s.truth.iter().enumerate().map(|(f, t)| if in_fold(f, fold) { t.clone() } else { vec![] }).collect();
    average_precision(&boxes, &truth, iou_threshold).ap.unwrap_or(0.0)
}

/// Trains an SVM on the samples `subset` at `c`, started from `start` (see
/// [`crate::learn::binary_svm::train_linear_svm_from`]).
fn fit_subset(s: &Samples, subset: &[usize], c: f64, start: Option<&[f64]>) -> Result<SvmSolution> {
    let psi: Vec<Vec<f64>> = subset.iter().map(|&n| s.psi[n].clone()).collect();
    let labels: Vec<bool> = subset.iter().map(|&n| s.labels[n]).collect();
    train_linear_svm_from(&psi, &labels, &balanced_costs(&labels, c), start)
}

/// The frames of cross-validation fold `fold` (0 or 1): the even and the odd frames.
fn in_fold(frame: usize, fold: usize) -> bool {
    frame % 2 == fold
}

/// One `C`'s cross-validation: the mean over the folds of the first-stage and of the combined score's AP,
/// and every sample's held-out combined score (from the SVM of the fold that did not train on it).
struct Validated {
    ap_first: f32,
    ap_cascade: f32,
    held_out: Vec<f32>,
    /// The first-stage and the combined score's AP on each fold's frames (for [`nested`]).
    fold_first: [f32; 2],
    fold_cascade: [f32; 2],
}

/// Cross-validated (two folds: even and odd frames) mean AP of the first-stage and of the combined score
/// at each `C` of [`C_GRID`] (in its order); `None` where a fold lacks a class. Each fold's SVMs are
/// trained from the largest `C` down, each started from the one before with its α scaled by the ratio
/// of the `C`s (feasible with balanced costs): the same optima, reached in fewer working-set rounds.
/// The two folds are trained in parallel (each fit is single-threaded and reads only its fold; the
/// results are then added in fold order), so a category's stage is not one thread's work: the same
/// numbers as one fold after the other, bit for bit.
fn cross_validate(s: &Samples, iou_threshold: f32) -> Vec<Option<Validated>> {
    let folds: Vec<FoldScores> = (0..2).into_par_iter().map(|fold| fold_scores(s, fold, iou_threshold)).collect();
    let mut results: Vec<Option<Validated>> = (0..C_GRID.len())
        .map(|_| {
            Some(Validated {
                ap_first: 0.0,
                ap_cascade: 0.0,
                held_out: vec![0.0; s.labels.len()],
                fold_first: [0.0; 2],
                fold_cascade: [0.0; 2],
            })
        })
        .collect();
    for (fold, scores) in folds.into_iter().enumerate() {
        for (k, per_c) in scores.per_c.into_iter().enumerate() {
            let Some((combined, cascade)) = per_c else {
                results[k] = None;
                continue;
            };
            if let Some(v) = results[k].as_mut() {
                // Sums here, halved below (the arithmetic of every cascade trained before).
                v.ap_first += scores.first;
                v.ap_cascade += cascade;
                v.fold_first[fold] = scores.first;
                v.fold_cascade[fold] = cascade;
                for (&n, &score) in scores.test.iter().zip(&combined) {
                    v.held_out[n] = score;
                }
            }
        }
    }
    for v in results.iter_mut().flatten() {
        v.ap_first /= 2.0;
        v.ap_cascade /= 2.0;
    }
    results
}

/// One fold of [`cross_validate`]: its samples, the first stage's AP on them and, per `C` of [`C_GRID`],
/// the combined scores of the SVM trained on the other fold and their AP (`None` where it could not be
/// fitted).
struct FoldScores {
    test: Vec<usize>,
    first: f32,
    per_c: Vec<Option<(Vec<f32>, f32)>>,
}

fn fold_scores(s: &Samples, fold: usize, iou_threshold: f32) -> FoldScores {
    let train: Vec<usize> = (0..s.labels.len()).filter(|&n| !in_fold(s.frame[n], fold)).collect();
    let test: Vec<usize> = (0..s.labels.len()).filter(|&n| in_fold(s.frame[n], fold)).collect();
    let base: Vec<f32> = test.iter().map(|&n| s.raw[n]).collect();
    let first = subset_ap(s, &test, &base, fold, iou_threshold);
    let per_c = combined_scores_per_c(s, &train, &test)
        .into_iter()
        .map(|combined| {
            combined.map(|combined| {
                let cascade = subset_ap(s, &test, &combined, fold, iou_threshold);
                (combined, cascade)
            })
        })
        .collect();
    FoldScores { test, first, per_c }
}

/// The combined scores of the samples `test` given by the SVM trained on the samples `fit` at each `C` of
/// [`C_GRID`] (in its order; `None` where it could not be fitted). The fits go from the largest `C` down,
/// each started from the one before with its α scaled by the ratio of the `C`s (feasible with balanced
/// costs): the same optima, reached in fewer working-set rounds.
fn combined_scores_per_c(s: &Samples, fit: &[usize], test: &[usize]) -> Vec<Option<Vec<f32>>> {
    let mut scores = vec![None; C_GRID.len()];
    let mut previous: Option<(f64, Vec<f64>)> = None;
    for (k, &c) in C_GRID.iter().enumerate().rev() {
        let start = previous.as_ref().map(|(pc, alpha)| alpha.iter().map(|a| a * c / pc).collect::<Vec<f64>>());
        let Ok(solution) = fit_subset(s, fit, c, start.as_deref()) else { continue };
        scores[k] = Some(test.iter().map(|&n| s.raw[n] + solution.svm.decision(&s.psi[n]) as f32).collect());
        previous = Some((c, solution.alpha));
    }
    scores
}

/// The central [`GAIN_LEVEL`] interval of the cross-validated gain — the mean over the two folds of
/// (AP of `held_out` − AP of the first-stage score) on the fold's frames — by a paired percentile
/// bootstrap over frames ([`GAIN_BOOTSTRAP`]): each resample draws each fold's frames anew from that fold
/// (as many as it has, with replacement; a frame and its detections stay together) and scores both
/// rankings on the same draw. `held_out` are the samples' cross-validated combined scores
/// ([`Validated::held_out`]). The SVMs are not retrained per resample: the interval is the noise of
/// the frames the gain was measured on, not of training.
fn cv_gain_interval(s: &Samples, held_out: &[f32], iou_threshold: f32) -> Option<[f32; 2]> {
    let folds: Vec<(Vec<usize>, MatchedDetections, MatchedDetections)> = (0..2)
        .map(|fold| {
            let frames: Vec<usize> = (0..s.truth.len()).filter(|&f| in_fold(f, fold)).collect();
            let samples: Vec<usize> = (0..s.labels.len()).filter(|&n| in_fold(s.frame[n], fold)).collect();
            let truth: Vec<Vec<Cuboid>> =
                s.truth.iter().enumerate().map(|(f, t)| if in_fold(f, fold) { t.clone() } else { vec![] }).collect();
            let boxes = |scores: &dyn Fn(usize) -> f32| -> Vec<ScoredBox> {
                samples
                    .iter()
                    .map(|&n| ScoredBox { image: s.frame[n], score: scores(n), cuboid: s.cuboids[n] })
                    .collect()
            };
            let first = MatchedDetections::new(&boxes(&|n| s.raw[n]), &truth, iou_threshold);
            let cascade = MatchedDetections::new(&boxes(&|n| held_out[n]), &truth, iou_threshold);
            (frames, first, cascade)
        })
        .collect();
    // One stream of draws per fold, each seeded apart.
    let draws: Vec<Vec<Vec<usize>>> = folds
        .iter()
        .enumerate()
        .map(|(fold, (frames, _, _))| {
            bootstrap_frames(frames.len(), Bootstrap { seed: GAIN_BOOTSTRAP.seed + fold as u64, ..GAIN_BOOTSTRAP })
        })
        .collect();
    let gains: Vec<f32> = (0..GAIN_BOOTSTRAP.resamples)
        .map(|r| {
            let mut gain = 0.0;
            for (fold, (frames, first, cascade)) in folds.iter().enumerate() {
                let mut counts = vec![0u32; s.truth.len()];
                for &i in &draws[fold][r] {
                    counts[frames[i]] += 1;
                }
                // As `subset_ap`: a fold without ground truth scores 0.
                let ap = |m: &MatchedDetections| m.resampled_ap(&counts).unwrap_or(0.0);
                gain += (ap(cascade) - ap(first)) / 2.0;
            }
            gain
        })
        .collect();
    percentile_interval(&gains, GAIN_LEVEL).map(|(low, high)| [low, high])
}

/// Outcome of training one category: its stage, or why there is none.
pub type StageResult = std::result::Result<SecondStage, String>;

/// What training did for one category: each candidate feature set's own outcome, in the order the sets
/// were given (one entry when one set was given); [`StageOutcome::chosen`] is the stage it keeps.
#[derive(Clone, Debug)]
pub struct StageOutcome {
    pub candidates: Vec<(FeatureSet, StageResult)>,
    /// The nested cross-validated gain of the category's training ([`StageRule::NestedGain`]; `None`
    /// under another rule or without samples of both labels).
    pub nested_gain: Option<f32>,
    /// Why the rule refused the category's chosen stage as a whole (the nested rule), if it did.
    pub refused: Option<String>,
}

impl StageOutcome {
    /// The stage with the highest cross-validated AP among the candidates that have one (ties: the
    /// earlier); without any, the reasons of each, named by set when there are several; the rule's reason
    /// when it refused the category ([`StageOutcome::refused`]).
    pub fn chosen(&self) -> std::result::Result<&SecondStage, String> {
        if let Some(reason) = &self.refused {
            return Err(reason.clone());
        }
        let mut best: Option<&SecondStage> = None;
        for stage in self.candidates.iter().filter_map(|(_, r)| r.as_ref().ok()) {
            if stage.outranks(best) {
                best = Some(stage);
            }
        }
        best.ok_or_else(|| {
            let several = self.candidates.len() > 1;
            let reasons: Vec<String> = self
                .candidates
                .iter()
                .filter_map(|(set, r)| r.as_ref().err().map(|reason| (set, reason)))
                .map(|(set, reason)| if several { format!("{}: {reason}", set.short_name()) } else { reason.clone() })
                .collect();
            reasons.join("; ")
        })
    }
}

impl StageOutcome {
    /// [`StageRule::NestedGain`]: records the nested cross-validated gain of the candidates' `numbers` (in
    /// the candidates' order) and refuses the chosen stage when it is not above 0.
    fn judge_nested(&mut self, numbers: &[NestedFolds]) {
        self.nested_gain = nested::nested_gain(&numbers.iter().collect::<Vec<_>>());
        if let (Ok(stage), Some(gain)) = (self.chosen(), self.nested_gain) {
            if gain <= 0.0 {
                self.refused = Some(format!(
                    "the training's nested cross-validated gain, {:+.1}, is not above 0 (the chosen stage's own \
                     cross-validated gain {:+.1} is the best of {} choices of set and C)",
                    100.0 * gain,
                    100.0 * (stage.cv_ap_cascade - stage.cv_ap_first_stage),
                    numbers.len() * C_GRID.len()
                ));
            }
        }
    }
}

/// The first detection of a category with a calibration in `calibrations` whose score is not the probability
/// that calibration gives its raw score (within 10⁻⁵ relative, for files written by other builds), with its
/// raw score and that probability: a detection of another model than the one the calibration is of.
pub fn score_off_its_calibration<'a>(
    calibrations: &BTreeMap<String, Calibration>,
    detections: &'a [Detection],
) -> Option<(&'a Detection, f32, f32)> {
    detections.iter().find_map(|d| {
        let (calibration, raw) = (calibrations.get(&d.category)?, d.raw_score?);
        let expected = calibration.probability(raw);
        ((d.score - expected).abs() > 1e-5 * d.score.abs().max(expected.abs())).then_some((d, raw, expected))
    })
}

/// Trains the second stage of each of `categories` on `frames` (annotated objects and first-stage
/// detections per frame), with `categories` also the context categories. Each category's stage is trained
/// with every feature set of `sets` (not empty) and keeps the one with the highest cross-validated AP
/// (ties: the earlier in `sets`); the file's [`Cascade::features`] is `sets[0]` and a stage of another set
/// names its own ([`SecondStage::features`]). A category whose detections hold no true or no false
/// positive, whose cross-validation folds do, or whose cross-validated AP the context does not raise with
/// any of the sets gets no stage (the reasons are returned): its detections keep their first-stage scores.
pub fn train_cascade(
    frames: &[CascadeFrame],
    categories: &[String],
    iou_threshold: f32,
    training: CascadeTraining,
    sets: &[FeatureSet],
) -> Result<(Cascade, BTreeMap<String, StageOutcome>)> {
    train_cascade_resumable(frames, categories, iou_threshold, training, sets, None, StageRule::AnyGain)
        .map(|(c, r, _)| (c, r))
}

/// [`train_cascade`] with checkpoints: with `checkpoints` (a directory, created when missing), each
/// (category, feature set) training writes its outcome there as soon as it is done
/// ([`stage_checkpoint_path`]), and one whose checkpoint is already there — for the same categories,
/// IoU, feature set, `C` grid ([`C_GRID`]) and first-stage detections and ground truth
/// ([`frames_fingerprint`]) — is read
/// instead of trained again, so an interrupted run resumes where it stopped with the same result. A
/// checkpoint of other inputs is trained over (and replaced). Also returns how many outcomes were read.
/// `rule` then decides which trained stages are kept ([`StageRule`]; a stage it refuses is an outcome
/// without a stage, its reason given; checkpoints hold the stages as trained, so a rerun with another rule
/// reads them).
pub fn train_cascade_resumable(
    frames: &[CascadeFrame],
    categories: &[String],
    iou_threshold: f32,
    training: CascadeTraining,
    sets: &[FeatureSet],
    checkpoints: Option<&Path>,
    rule: StageRule,
) -> Result<(Cascade, BTreeMap<String, StageOutcome>, usize)> {
    let Some(&file_set) = sets.first() else {
        return Err(Error::Input("the cascade needs at least one feature set to train with".to_string()));
    };
    for frame in frames {
        check_first_stage(&frame.detections)?;
        // The training records these calibrations as those of the models its detections came from
        // (`detect` and `rescore` refuse detections or models that disagree with them): detections of other
        // models are refused here too (since 2026-12-08; they trained a cascade its own files were refused by).
        if let Some((d, raw, expected)) = score_off_its_calibration(&training.calibrations, &frame.detections) {
            return Err(Error::Input(format!(
                "a '{}' detection has score {} where the '{}' model's calibration gives its raw score {raw} the \
                 probability {expected}: the detections come from another model than the models the cascade is \
                 trained for (detect them again with those models, or give the models they came from)",
                d.category, d.score, d.category
            )));
        }
    }
    if let Some(dir) = checkpoints {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let fingerprint = format!("{:016x}", frames_fingerprint(frames));
    // Progress: a category's stage takes minutes with ~10 000 detections (the SVM's QP solves).
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let resumed = std::sync::atomic::AtomicUsize::new(0);
    let results: Vec<(String, StageOutcome)> = categories
        .par_iter()
        .map(|category| -> Result<(String, StageOutcome)> {
            // The feature sets' trainings are independent: in parallel, collected in the sets' order.
            let trained: Vec<(FeatureSet, StageResult, Option<NestedFolds>)> = sets
                .par_iter()
                .map(|&set| -> Result<(FeatureSet, StageResult, Option<NestedFolds>)> {
                    if v7_adds_nothing(set, category, sets) {
                        let reason = format!("not trained: a {category} detection has no cross scores, v6 is the same");
                        return Ok((set, Err(reason), None));
                    }
                    let key = StageKey {
                        category,
                        set,
                        categories,
                        iou: iou_threshold,
                        fingerprint: &fingerprint,
                        nested: rule.needs_nested(),
                    };
                    let stored = checkpoints.and_then(|dir| key.read(dir));
                    let (result, numbers) = match stored {
                        Some(outcome) => {
                            resumed.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            outcome
                        }
                        None => {
                            let outcome =
                                train_stage(frames, category, categories, iou_threshold, set, rule.needs_nested());
                            if let Some(dir) = checkpoints {
                                key.write(dir, &outcome.0, outcome.1.as_ref())?;
                            }
                            outcome
                        }
                    };
                    // Named here, for fresh and resumed stages alike (a checkpoint may come from a run whose
                    // file set was another).
                    let result = result
                        .and_then(|stage| rule.admits(&stage).map(|()| stage))
                        .map(|stage| SecondStage { features: set.name_unless(file_set), ..stage });
                    Ok((set, result, numbers))
                })
                .collect::<Result<_>>()?;
            let mut candidates: Vec<(FeatureSet, StageResult)> = Vec::with_capacity(sets.len());
            let mut nested_numbers: Vec<NestedFolds> = Vec::new();
            for (set, result, numbers) in trained {
                nested_numbers.extend(numbers);
                candidates.push((set, result));
            }
            let mut outcome = StageOutcome { candidates, nested_gain: None, refused: None };
            if rule.needs_nested() {
                outcome.judge_nested(&nested_numbers);
            }
            let done = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            log::info!("cascade: '{category}' done ({done} of {})", categories.len());
            Ok((category.clone(), outcome))
        })
        .collect::<Result<_>>()?;
    let stages = results
        .iter()
        .filter_map(|(c, r)| {
            r.chosen().ok().map(|s| (c.clone(), SecondStage { cv_gain_nested: r.nested_gain, ..s.clone() }))
        })
        .collect();
    let cascade = Cascade {
        format: FORMAT.into(),
        version: VERSION,
        features: file_set.name().into(),
        categories: categories.to_vec(),
        stages,
        training,
        exclusion: None,
        final_calibration: None,
    };
    Ok((cascade, results.into_iter().collect(), resumed.into_inner()))
}

/// Whether training `category`'s stage with `set` among `sets` is skipped ([`train_cascade_resumable`]): v7
/// beside v6 for a category outside [`CROSS_SCORE_CATEGORIES`]. Such a category's detections carry no
/// cross scores (their cross part of ψ is zeros), so its v7 training is v6's with columns of zeros: the same
/// stage up to the solver's rounding, which the choice would keep v6 over (ties go to the earlier set). On
/// the shipped 19 categories that skips eight of the 19 v7 trainings.
pub fn v7_adds_nothing(set: FeatureSet, category: &str, sets: &[FeatureSet]) -> bool {
    set == FeatureSet::V7 && !is_cross_score_category(category) && sets.contains(&FeatureSet::V6)
}

/// The `format` of a stage checkpoint file ([`train_cascade_resumable`]).
pub const STAGE_CHECKPOINT_FORMAT: &str = "cog-gpu-cascade-stage";

/// Where [`train_cascade_resumable`] keeps the outcome of `category`'s training with `set` inside the
/// checkpoint directory `dir`: `<category>.<set's short name>.json`.
pub fn stage_checkpoint_path(dir: &Path, category: &str, set: FeatureSet) -> std::path::PathBuf {
    dir.join(format!("{category}.{}.json", set.short_name()))
}

/// A 64-bit FNV-1a fingerprint of a cascade's training inputs: every frame's ground truth (categories and
/// boxes), first-stage detections (categories, boxes, scores, raw scores, cross scores where present) and
/// room, in order, as raw bits.
/// Two runs on the same detections files give the same fingerprint; a re-detection that changes any score
/// or box changes it (up to hash collisions), so a checkpoint of other detections is not resumed.
pub fn frames_fingerprint(frames: &[CascadeFrame]) -> u64 {
    let floats = |hash: u64, values: &[f32]| values.iter().fold(hash, |h, v| fnv1a(h, &v.to_bits().to_le_bytes()));
    let text = |hash: u64, value: &str| fnv1a(fnv1a(hash, &(value.len() as u64).to_le_bytes()), value.as_bytes());
    let mut hash = fnv1a(FNV_OFFSET, &(frames.len() as u64).to_le_bytes());
    for frame in frames {
        hash = fnv1a(hash, &(frame.truth.len() as u64).to_le_bytes());
        for object in &frame.truth {
            let c = object.cuboid;
            hash = floats(
                text(hash, &object.category),
                &[c.centre.x, c.centre.y, c.centre.z, c.size.x, c.size.y, c.size.z, c.yaw],
            );
        }
        hash = fnv1a(hash, &(frame.detections.len() as u64).to_le_bytes());
        for d in &frame.detections {
            hash = floats(text(hash, &d.category), &d.centre);
            hash = floats(hash, &d.size);
            hash = floats(hash, &[d.yaw, d.score, d.raw_score.unwrap_or(f32::NAN)]);
            // The cross scores (v7 reads them) only where present, so files without them keep the
            // fingerprint they had before there were cross scores.
            if let Some(scores) = &d.cross_scores {
                hash = fnv1a(hash, &(scores.len() as u64).to_le_bytes());
                for (category, score) in scores {
                    hash = floats(text(hash, category), &[*score]);
                }
            }
        }
        match &frame.room {
            None => hash = fnv1a(hash, &[0]),
            Some(room) => {
                hash = fnv1a(hash, &[1]);
                hash = floats(hash, &[room.floor]);
                for corner in &room.corners {
                    hash = floats(hash, &[corner.x, corner.y]);
                }
            }
        }
    }
    hash
}

/// What a stage checkpoint must match to be resumed ([`train_cascade_resumable`]).
struct StageKey<'a> {
    category: &'a str,
    set: FeatureSet,
    categories: &'a [String],
    iou: f32,
    fingerprint: &'a str,
    /// Whether the nested cross-validation's numbers are needed: a checkpoint without them is trained again.
    nested: bool,
}

/// A stage checkpoint file: the outcome of one (category, feature set) training and what it was trained on.
#[derive(Serialize, Deserialize)]
struct StageCheckpoint {
    format: String,
    version: u32,
    category: String,
    features: String,
    categories: Vec<String>,
    iou: f32,
    /// [`frames_fingerprint`] in hexadecimal (JSON numbers do not hold 64 bits).
    inputs: String,
    /// The `C` values the cross-validation tried ([`C_GRID`]): a build with another grid trains again.
    c_grid: Vec<f64>,
    /// The stage, or why there is none.
    stage: Option<SecondStage>,
    no_stage: Option<String>,
    /// The nested cross-validation's numbers, when the training computed them (`--keep nested-gain`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    nested: Option<NestedFolds>,
}

impl StageKey<'_> {
    /// The stored outcome when the checkpoint exists, reads and matches; `None` (train it) otherwise,
    /// with a warning naming the file when one is there but unusable.
    fn read(&self, dir: &Path) -> Option<(StageResult, Option<NestedFolds>)> {
        let path = stage_checkpoint_path(dir, self.category, self.set);
        let text = std::fs::read_to_string(&path).ok()?;
        let stored: StageCheckpoint = match serde_json::from_str(&text) {
            Ok(stored) => stored,
            Err(e) => {
                log::warn!("{}: not a stage checkpoint ({e}); training the stage again", path.display());
                return None;
            }
        };
        let same = stored.format == STAGE_CHECKPOINT_FORMAT
            && stored.version == VERSION
            && stored.category == self.category
            && stored.features == self.set.name()
            && stored.categories == self.categories
            && stored.iou == self.iou
            && stored.inputs == self.fingerprint
            && stored.c_grid == C_GRID;
        if !same {
            log::warn!(
                "{}: a checkpoint of other detections, categories, IoU, feature set or C grid; training the stage \
                 again",
                path.display()
            );
            return None;
        }
        let nested = match stored.nested {
            Some(numbers) if numbers.check().is_ok() => Some(numbers),
            // (A category without samples of both labels has none: trained again, at once.)
            _ if self.nested => {
                log::info!(
                    "{}: a checkpoint without the nested cross-validation's numbers; training the stage again",
                    path.display()
                );
                return None;
            }
            _ => None,
        };
        let result = match (stored.stage, stored.no_stage) {
            // A stage trained before the gain's interval was recorded is trained again (the rule may need it).
            (Some(stage), None)
                if stage.weights.len() == self.set.dim(self.categories.len())
                    && stage.check_numbers().is_ok()
                    && stage.cv_gain_interval.is_some() =>
            {
                Ok(stage)
            }
            (None, Some(reason)) => Err(reason),
            _ => {
                log::warn!("{}: an inconsistent stage checkpoint; training the stage again", path.display());
                return None;
            }
        };
        Some((result, nested))
    }

    /// Writes `result` as the checkpoint (to a temporary file renamed over it: an interruption mid-write
    /// leaves no half-written checkpoint).
    fn write(&self, dir: &Path, result: &StageResult, nested: Option<&NestedFolds>) -> Result<()> {
        let path = stage_checkpoint_path(dir, self.category, self.set);
        let checkpoint = StageCheckpoint {
            format: STAGE_CHECKPOINT_FORMAT.to_string(),
            version: VERSION,
            category: self.category.to_string(),
            features: self.set.name().to_string(),
            categories: self.categories.to_vec(),
            iou: self.iou,
            inputs: self.fingerprint.to_string(),
            c_grid: C_GRID.to_vec(),
            stage: result.as_ref().ok().cloned(),
            no_stage: result.as_ref().err().cloned(),
            nested: nested.cloned(),
        };
        let text = serde_json::to_string(&checkpoint).map_err(|e| Error::invalid(&path, e.to_string()))?;
        crate::error::write_replacing(&path, text.as_bytes())
    }
}

/// One category's stage (module doc): C by cross-validation, then the SVM and calibration on all frames.
/// Its `features` is left `None`: the caller names the set when it is not the file's. With `nested`, also
/// the numbers of the nested cross-validation ([`nested`]; `None` without, or without samples of both
/// labels).
fn train_stage(
    frames: &[CascadeFrame],
    category: &str,
    categories: &[String],
    iou_threshold: f32,
    set: FeatureSet,
    nested: bool,
) -> (StageResult, Option<NestedFolds>) {
    let s = samples_of(frames, category, categories, iou_threshold, set);
    let positives = s.labels.iter().filter(|&&y| y).count();
    if positives == 0 || positives == s.labels.len() {
        return (Err(format!("{positives} true positives among {} detections", s.labels.len())), None);
    }
    // The stage's cross-validation and the nested one's inner cross-validations are independent: run
    // side by side (each fit single-threaded; the same numbers as one after the other).
    let (validated, inner) = rayon::join(
        || cross_validate(&s, iou_threshold),
        || nested.then(|| nested::inner_validations(&s, iou_threshold)),
    );
    let numbers = inner.map(|inner| nested::nested_folds(&validated, &inner));
    (stage_of(&s, validated, frames.len(), iou_threshold), numbers)
}

/// The stage of the samples `s` (of `frames` frames) given their cross-validation at each `C`.
fn stage_of(s: &Samples, validated: Vec<Option<Validated>>, frames: usize, iou_threshold: f32) -> StageResult {
    let positives = s.labels.iter().filter(|&&y| y).count();
    let mut best: Option<(f64, Validated)> = None;
    for (c, validated) in C_GRID.into_iter().zip(validated) {
        if let Some(v) = validated {
            if best.as_ref().is_none_or(|(_, b)| v.ap_cascade > b.ap_cascade) {
                best = Some((c, v));
            }
        }
    }
    let (c, validated) =
        best.ok_or_else(|| "a cross-validation fold holds no true or no false positive".to_string())?;
    let (cv_first, cv_cascade) = (validated.ap_first, validated.ap_cascade);
    if cv_cascade <= cv_first {
        return Err(format!(
            "the context does not help: cross-validated AP {:.1} with it, {:.1} without",
            100.0 * cv_cascade,
            100.0 * cv_first
        ));
    }
    let all: Vec<usize> = (0..s.labels.len()).collect();
    let svm = fit_subset(s, &all, c, None).map_err(|e| e.to_string())?.svm;
    let scored: Vec<(f32, bool)> =
        all.iter().map(|&n| (s.raw[n] + svm.decision(&s.psi[n]) as f32, s.labels[n])).collect();
    let (a, b) = fit_logistic(&scored).map_err(|e| e.to_string())?;
    Ok(SecondStage {
        features: None,
        weights: svm.weights,
        bias: svm.bias,
        c,
        cv_ap_first_stage: cv_first,
        cv_ap_cascade: cv_cascade,
        cv_gain_interval: cv_gain_interval(s, &validated.held_out, iou_threshold),
        cv_gain_nested: None,
        calibration: Calibration {
            a,
            b,
            detections: scored.len(),
            true_positives: positives,
            iou: iou_threshold,
            data: String::new(),
            frames,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A detections file's room is read only within the layout file's rules: a ceiling at or below the
    /// floor and a coordinate beyond ±100 m are errors naming the file (they were read as rooms before).
    #[test]
    fn a_room_out_of_the_layout_files_rules_is_an_error() {
        let path = Path::new("frame.json");
        let file = |corners: &str, floor: f32, ceiling: f32| {
            format!(
                r#"{{"frame": "f", "detections": [], "layout": {{"corners": {corners}, "floor": {floor}, "ceiling": {ceiling}}}}}"#
            )
        };
        let square = "[[-2, 1], [2, 1], [2, 5], [-2, 5]]";
        let room = room_in(path, &file(square, -1.3, 1.2)).unwrap().unwrap();
        assert_eq!((room.corners.len(), room.floor), (4, -1.3));
        for (text, says) in [
            (file(square, 5.0, 1.3), "below the ceiling"),
            (file(square, -1.3, -1.3), "below the ceiling"),
            (file(square, 1e6, 2e6), "beyond ±100 m"),
            (file("[[-2, 1], [2, 1], [1000000, 1000000]]", -1.3, 1.2), "beyond ±100 m"),
        ] {
            let err = room_in(path, &text).unwrap_err().to_string();
            assert!(err.contains("frame.json") && err.contains(says), "{err}");
        }
        // A file without a ceiling (older writers) is still read.
        let no_ceiling = format!(r#"{{"layout": {{"corners": {square}, "floor": -1.3}}}}"#);
        assert!(room_in(path, &no_ceiling).unwrap().is_some());
    }

    /// Twelve frames of one category with 0–2 true boxes each and three detections per frame (hits and
    /// misses, every score distinct, so that [`MatchedDetections::resampled_ap`] is exact).
    fn samples() -> Samples {
        let unit = |x: f32| Cuboid::new(Vec3::new(x, 0.0, 0.5), Vec3::ONE, 0.0);
        let mut s = Samples { psi: vec![], raw: vec![], labels: vec![], frame: vec![], cuboids: vec![], truth: vec![] };
        for f in 0..12 {
            let boxes = f % 3;
            s.truth.push((0..boxes).map(|b| unit(3.0 * b as f32)).collect());
            for d in 0..3 {
                s.frame.push(f);
                // Detection d sits on box d when the frame has it, on empty floor otherwise.
                s.cuboids.push(unit(3.0 * d as f32 + if d < boxes { 0.0 } else { 0.3 * f as f32 + 20.0 }));
                s.raw.push(((f * 7 + d * 13) % 37) as f32 / 37.0 + 0.001 * (f * 3 + d) as f32);
                s.psi.push(vec![]);
                s.labels.push(false);
            }
        }
        s
    }

    /// A fold's AP counts the boxes of its frames without a detection: fold 0 holds frames 0 and 2, each
    /// with one box; frame 0's one detection hits its box, frame 2 has none. Recall reaches ½ at
    /// precision 1: AP ½ (it read 1 when frame 2 was left out).
    #[test]
    fn a_folds_ap_counts_the_boxes_of_its_frames_without_detections() {
        let unit = Cuboid::new(Vec3::new(0.0, 0.0, 0.5), Vec3::ONE, 0.0);
        let s = Samples {
            psi: vec![vec![]],
            raw: vec![1.0],
            labels: vec![true],
            frame: vec![0],
            cuboids: vec![unit],
            truth: vec![vec![unit], vec![], vec![unit], vec![unit]],
        };
        assert_eq!(subset_ap(&s, &[0], &[1.0], 0, 0.25), 0.5);
        // Fold 1 (frames 1 and 3): one box, no detection.
        assert_eq!(subset_ap(&s, &[], &[], 1, 0.25), 0.0);
    }

    /// The interval is the percentile interval of the gains that the materialised resamples give: each
    /// fold's drawn frames made into a data set (a frame drawn twice is two frames) and evaluated by
    /// [`average_precision`], the benchmark's own implementation, for both rankings.
    #[test]
    fn the_gain_interval_is_that_of_the_materialised_resamples() {
        let s = samples();
        // A held-out ranking that puts the hits first in some frames only.
        let held_out: Vec<f32> = (0..s.raw.len())
            .map(|n| if s.frame[n].is_multiple_of(4) { 2.0 - s.raw[n] } else { s.raw[n] + 0.5 })
            .collect();
        let got = cv_gain_interval(&s, &held_out, 0.25).unwrap();
        let mut gains = vec![0.0f32; GAIN_BOOTSTRAP.resamples];
        for fold in 0..2 {
            let frames: Vec<usize> = (0..12).filter(|&f| in_fold(f, fold)).collect();
            let draws =
                bootstrap_frames(frames.len(), Bootstrap { seed: GAIN_BOOTSTRAP.seed + fold as u64, ..GAIN_BOOTSTRAP });
            for (r, draw) in draws.iter().enumerate() {
                let truth: Vec<Vec<Cuboid>> = draw.iter().map(|&i| s.truth[frames[i]].clone()).collect();
                let ap = |scores: &[f32]| {
                    let mut boxes = Vec::new();
                    for (image, &i) in draw.iter().enumerate() {
                        for n in (0..s.raw.len()).filter(|&n| s.frame[n] == frames[i]) {
                            boxes.push(ScoredBox { image, score: scores[n], cuboid: s.cuboids[n] });
                        }
                    }
                    average_precision(&boxes, &truth, 0.25).ap.unwrap_or(0.0)
                };
                gains[r] += (ap(&held_out) - ap(&s.raw)) / 2.0;
            }
        }
        let (low, high) = percentile_interval(&gains, GAIN_LEVEL).unwrap();
        assert_eq!(got, [low, high]);
        assert!(low < high, "the frames differ, so the resamples do: {got:?}");
        // The same ranking twice gains nothing on every resample.
        assert_eq!(cv_gain_interval(&s, &s.raw, 0.25), Some([0.0, 0.0]));
    }

    #[test]
    fn the_rule_keeps_a_stage_only_when_its_gain_is_beyond_the_noise() {
        let stage = |interval: Option<[f32; 2]>| SecondStage {
            features: None,
            weights: vec![],
            bias: 0.0,
            c: 1.0,
            cv_ap_first_stage: 0.30,
            cv_ap_cascade: 0.32,
            cv_gain_interval: interval,
            cv_gain_nested: None,
            calibration: Calibration {
                a: 1.0,
                b: 0.0,
                detections: 1,
                true_positives: 1,
                iou: 0.25,
                data: String::new(),
                frames: 1,
            },
        };
        for interval in [Some([-0.01, 0.05]), Some([0.0, 0.05]), Some([0.001, 0.05]), None] {
            assert_eq!(StageRule::AnyGain.admits(&stage(interval)), Ok(()));
        }
        assert_eq!(StageRule::SignificantGain.admits(&stage(Some([0.001, 0.05]))), Ok(()));
        let refused = StageRule::SignificantGain.admits(&stage(Some([-0.01, 0.05]))).unwrap_err();
        assert!(refused.contains("+2.0") && refused.contains("[-1.0, +5.0]"), "{refused}");
        assert!(StageRule::SignificantGain.admits(&stage(Some([0.0, 0.05]))).is_err(), "0 is not above 0");
        assert!(StageRule::SignificantGain.admits(&stage(None)).is_err());
    }
}
