//! Model files: one trained category per JSON file, `<category>.json` in a models directory.
//!
//! ```json
//! {
//!   "format": "cog-gpu-model", "version": 1, "category": "bed",
//!   "layout_id": "cog-v1 grid=5x5x5 expanded=1 groups=density,normals,cog,view",
//!   "layout": {"base_grid": [5, 5, 5], "expanded": true,
//!              "groups": {"density": true, "normals": true, "cog": true, "view": true}},
//!              (and "out_of_view": true when that group is on: `features::feature_layout`)
//!   "sizes": {"widths": [5 numbers], "depths": [3], "heights": [3]},
//!   "window": {"step": 0.1, "min_points": 50, "yaw_anchor": "walls", "support": "floor", "lattice": "camera"},
//!   "features": {"path": "fast", "subdivisions": 2},
//!   "bias": 0.0, "threshold": 0.0,
//!   "weights": [layout.dim() numbers, in the order of `features::feature_layout`],
//!   "training": {free-form provenance: data, C, ε, iterations, seconds, ...},
//!   "calibration": {"a": 2.1, "b": -1.3, "detections": 5210, "true_positives": 212, "iou": 0.25,
//!                   "data": "...", "frames": 150}   (optional, written by `cog-gpu calibrate`)
//!   "surface": {"slice": [875 numbers], "indicator": [7 numbers]}   (version 2 only)
//! }
//! ```
//!
//! **Version 2** is a model with latent support surfaces (paper §4.1, [`crate::features::surface`]): its
//! `surface` holds `w_slice` (25 voxels × 35 features of one horizontal slice of a 5×5×7 grid of the
//! cuboid, in the order of [`crate::features::surface`]) and the seven height biases `u_h`, and a
//! hypothesis scores `weights · φ + bias + max_h (w_slice · φ_surface(h) + u_h)`; detections report the
//! best slice's height. A version-1 file has no `surface`; a build that reads only version 1 refuses a
//! version-2 file instead of silently ignoring its surface.
//!
//! The raw score of a hypothesis is `weights · φ + bias`; detection of an uncalibrated model drops
//! hypotheses whose raw score is below `threshold` (a calibrated model is cut at a calibrated probability
//! by default, [`crate::detect::DEFAULT_MIN_PROBABILITY`]). With a `calibration` ([`crate::calibration`]), a detection's reported `score` is
//! the calibrated probability `σ(a·raw + b)` and `raw_score` keeps the raw one. The structural SVM puts the "no object" answer at score 0 and asks true boxes to score ≥ 1
//! and wrong ones ≤ −1 (up to slack), so the default threshold 0 reports exactly the boxes the model
//! prefers to "no object". Evaluation wants the whole precision–recall curve: run `detect --min-score -1`
//! (or lower) for it.
//!
//! Reading checks everything a model is used for, with errors that name the file and the field: format
//! and version, that `layout_id` is this build's id of `layout` (feature order), the weights' length and
//! finiteness, zero weights on switched-off groups, the sizes (5/3/3 positive), the window step and the
//! category.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::calibration::Calibration;
use crate::category::{normalise_name, SurfaceCategories, CATEGORIES};
use crate::error::{Error, Result};
use crate::features::fast::FastOptions;
use crate::features::hypotheses::{FrameYaws, Support, YawAnchor};
use crate::features::preprocess::NormalSearch;
use crate::features::scene::LatticePhase;
use crate::features::surface::SurfaceWeights;
/// The weight bounds live with the weight vectors' definition ([`crate::features::weights`]).
pub use crate::features::weights::{check_weight_magnitudes, MAX_WEIGHT};
use crate::features::{FeatureLayout, SizeQuantiles};
use crate::features::{FeatureScene, Preprocessed};
use crate::limits::{check_step, check_subdivisions, MAX_OBJECT_SIZE_M, MIN_OBJECT_SIZE_M};

pub const MODEL_FORMAT: &str = "cog-gpu-model";
pub const MODEL_VERSION: u32 = 1;
/// The version of a model with latent support surfaces (see the module doc).
pub const MODEL_VERSION_SURFACES: u32 = 2;
/// Default raw-score cut of a model without a calibration (see the module doc).
pub const DEFAULT_THRESHOLD: f32 = 0.0;

/// Which feature implementation a model was trained with (and is scored with).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FeaturePath {
    /// `features::cpu` / the GPU kernel: exact, slow.
    Exact,
    /// `features::fast`: shared-work approximation.
    Fast,
}

/// Feature settings of a model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureSettings {
    pub path: FeaturePath,
    /// Lattice cells per centre step of the fast path.
    #[serde(default = "default_subdivisions")]
    pub subdivisions: u32,
    /// How the points' normals found their neighbours when the model was trained (`train --normals`);
    /// `detect` preprocesses with it. Absent: the k-d tree's.
    #[serde(default, skip_serializing_if = "NormalSearch::is_default")]
    pub normals: NormalSearch,
}

fn default_subdivisions() -> u32 {
    crate::features::fast::DEFAULT_SUBDIVISIONS
}

impl FeatureSettings {
    pub fn fast_options(&self) -> FastOptions {
        FastOptions { subdivisions: self.subdivisions }
    }
}

/// Sliding-window settings of a model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WindowSettings {
    /// Centre step (metres).
    pub step: f32,
    /// Hypotheses with fewer points inside are skipped.
    pub min_points: u32,
    /// Where the 16 yaws start ([`YawAnchor`]): `"walls"` (the frame's wall direction) or `"camera"`. The
    /// model was trained on that window and detection searches the same one. Absent in files written
    /// before the anchor existed, which were trained with `"camera"`.
    #[serde(default)]
    pub yaw_anchor: YawAnchor,
    /// Where the boxes stand ([`Support`]): `"floor"` (the sliding window), `"surfaces"` (the support
    /// surfaces of the frame's detections of [`Self::supporters`], searched after them), `"free"` (every
    /// bottom from the floor to 1.5 m), `"floor+surfaces"` (both the floor's and the surfaces') or
    /// `"resting"` (the free window's boxes on the floor or on a top seen around them). Absent in files
    /// written before it existed, which are floor models. It is the window of detection; a model may have
    /// been trained on another one (`training.training_support`, `train --detect-support`).
    #[serde(default)]
    pub support: Support,
    /// Where each yaw's lattice of centres starts ([`LatticePhase`]): `"camera"` (multiples of the step
    /// from the camera) or `"walls"` (a row of centres on the walls seen in the yaw's frame). Absent in
    /// files written before it existed, which were trained with `"camera"`.
    #[serde(default)]
    pub lattice: LatticePhase,
    /// The categories whose detections' surfaces a window with surfaces ([`Support::uses_surfaces`])
    /// searches ([`SurfaceCategories`]; written by `train`: those whose annotated surfaces held a training
    /// positive). Absent (files written before it existed, and models without surfaces): every surface
    /// category.
    #[serde(default, skip_serializing_if = "SurfaceCategories::is_all")]
    pub supporters: SurfaceCategories,
}

/// What decides a frame's yaw grids: the window step (its bits), the yaw anchor and the lattice phase.
/// Models with equal keys share one [`crate::features::FeatureScene`] per frame.
pub type SceneKey = (u32, YawAnchor, LatticePhase);

impl WindowSettings {
    /// The key of the yaw grids this window searches ([`SceneKey`]).
    pub fn scene_key(&self) -> SceneKey {
        (self.step.to_bits(), self.yaw_anchor, self.lattice)
    }
}

/// The yaw grids the windows of `models` search on one frame: one [`FeatureScene`] per distinct
/// [`SceneKey`], shared by the models that agree (detection and the diagnosis's window recall).
pub fn window_scenes<'m>(
    pre: &Preprocessed,
    frame_yaws: &FrameYaws,
    models: impl IntoIterator<Item = &'m Model>,
) -> BTreeMap<SceneKey, FeatureScene> {
    use rayon::prelude::*;
    // The distinct settings, then their scenes built in parallel (each scene's yaws in parallel too).
    let mut settings = BTreeMap::new();
    for model in models {
        settings.entry(model.window.scene_key()).or_insert(model.window);
    }
    let settings: Vec<(SceneKey, WindowSettings)> = settings.into_iter().collect();
    settings
        .into_par_iter()
        .map(|(key, WindowSettings { step, yaw_anchor, lattice, .. })| {
            (key, FeatureScene::with_lattice(pre.clone(), &frame_yaws.yaws(yaw_anchor), step, lattice))
        })
        .collect::<Vec<_>>()
        .into_iter()
        .collect()
}

/// One category's detector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Model {
    pub format: String,
    pub version: u32,
    pub category: String,
    pub layout_id: String,
    pub layout: FeatureLayout,
    pub sizes: SizeQuantiles,
    pub window: WindowSettings,
    pub features: FeatureSettings,
    #[serde(default)]
    pub bias: f32,
    #[serde(default = "default_threshold")]
    pub threshold: f32,
    pub weights: Vec<f32>,
    #[serde(default)]
    pub training: serde_json::Value,
    /// Raw score → probability of a true positive, fitted on held-out frames by `cog-gpu calibrate`
    /// ([`crate::calibration`]); `null` until then (detections then report the raw score).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<Calibration>,
    /// The latent support surface's weights (version 2; see the module doc).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub surface: Option<SurfaceWeights>,
}

/// The normal search of `models` (their `features.normals`, the one each was trained with): a frame is
/// preprocessed once for all its models, so they must agree; an error names two that do not. The default
/// search for no models.
pub fn common_normal_search(models: &[Model]) -> Result<NormalSearch> {
    let Some(first) = models.first() else { return Ok(NormalSearch::default()) };
    match models.iter().find(|m| m.features.normals != first.features.normals) {
        None => Ok(first.features.normals),
        Some(other) => Err(Error::Input(format!(
            "the models were trained with different normal searches ({}: {}, {}: {}); a frame's models share \
             one preprocessing — retrain them alike, or choose one with --normals",
            first.category,
            first.features.normals.name(),
            other.category,
            other.features.normals.name()
        ))),
    }
}

fn default_threshold() -> f32 {
    DEFAULT_THRESHOLD
}

impl Model {
    /// A checked model with bias 0 and the default threshold.
    pub fn new(
        category: &str,
        layout: FeatureLayout,
        sizes: SizeQuantiles,
        window: WindowSettings,
        features: FeatureSettings,
        weights: Vec<f32>,
        training: serde_json::Value,
    ) -> Result<Model> {
        let model = Model {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            category: category.into(),
            layout_id: layout.id(),
            layout,
            sizes,
            window,
            features,
            bias: 0.0,
            threshold: DEFAULT_THRESHOLD,
            weights,
            training,
            calibration: None,
            surface: None,
        };
        model.check().map_err(Error::Input)?;
        Ok(model)
    }

    /// The model with latent support surfaces (version 2), checked.
    pub fn with_surface(mut self, surface: SurfaceWeights) -> Result<Model> {
        self.version = MODEL_VERSION_SURFACES;
        self.surface = Some(surface);
        self.check().map_err(Error::Input)?;
        Ok(self)
    }

    /// The hypothesis sizes (45 for the paper's quantiles).
    pub fn sizes(&self) -> Vec<Vec3> {
        self.sizes.sizes()
    }

    /// Why detecting with this model's window step may not match its training (`None` when it does): the
    /// fast path snaps voxel faces to a lattice of side `step / subdivisions`, so a model whose thinnest
    /// size (the smallest width or depth quantile) is below that cell at its training step or at its
    /// detection step — a door's 9 cm at 0.2 m — sees different features when the two steps differ (the
    /// faces that coincided in training come apart, or the reverse). Models trained before the training
    /// step was recorded, and the exact path, are not judged.
    pub fn step_mismatch(&self) -> Option<String> {
        let trained = self.training.get("training_step")?.as_f64()? as f32;
        let detected = self.window.step;
        if self.features.path != FeaturePath::Fast || (trained - detected).abs() <= 1e-6 * trained.max(detected) {
            return None;
        }
        let cell = trained.max(detected) / self.features.subdivisions.max(1) as f32;
        let thinnest = self.sizes.widths.iter().chain(&self.sizes.depths).copied().fold(f32::INFINITY, f32::min);
        (thinnest < cell).then(|| {
            format!(
                "{}: detecting at step {detected} m, trained at {trained} m, and its thinnest size ({thinnest:.3} m) is \
                 below the fast path's lattice cell ({cell:.3} m): its features will not match its training; detect \
                 at the training step or retrain with --step {detected}",
                self.category
            )
        })
    }

    /// Everything reading checks (see the module doc).
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.format != MODEL_FORMAT {
            return Err(format!("format is '{}', expected '{MODEL_FORMAT}'", self.format));
        }
        match (self.version, &self.surface) {
            (MODEL_VERSION, None) | (MODEL_VERSION_SURFACES, Some(_)) => {}
            (MODEL_VERSION, Some(_)) => {
                return Err(format!(
                    "a version-{MODEL_VERSION} model has no \"surface\" (version {MODEL_VERSION_SURFACES} has)"
                ))
            }
            (MODEL_VERSION_SURFACES, None) => {
                return Err(format!("a version-{MODEL_VERSION_SURFACES} model needs its \"surface\" weights"))
            }
            (version, _) => {
                return Err(format!(
                    "version {version} is not supported (this build reads versions {MODEL_VERSION} and \
                     {MODEL_VERSION_SURFACES})"
                ))
            }
        }
        let (category, _) = normalise_name(&self.category);
        if category != self.category || !CATEGORIES.contains(&category.as_str()) {
            return Err(format!("category '{}' is not one of: {}", self.category, CATEGORIES.join(", ")));
        }
        self.layout.validate().map_err(|e| format!("layout: {e}"))?;
        if self.layout_id != self.layout.id() {
            return Err(format!(
                "layout_id '{}' is not this build's id for the model's layout, '{}' (the model was written \
                 for another feature order; retrain it)",
                self.layout_id,
                self.layout.id()
            ));
        }
        if self.weights.len() != self.layout.dim() {
            return Err(format!("weights has {} numbers, the layout needs {}", self.weights.len(), self.layout.dim()));
        }
        if let Some(i) = self.weights.iter().position(|w| !w.is_finite()) {
            return Err(format!("weights[{i}] is not a finite number"));
        }
        let mask = self.layout.mask();
        if let Some(i) = self.weights.iter().zip(&mask).position(|(w, on)| !on && *w != 0.0) {
            return Err(format!(
                "weights[{i}] ({}) belongs to a switched-off feature group and must be 0",
                self.layout.describe(i)
            ));
        }
        check_sizes(&self.sizes)?;
        check_step("window.step", self.window.step).map_err(|e| e.to_string())?;
        crate::limits::check_min_points("window.min_points", self.window.min_points).map_err(|e| e.to_string())?;
        check_subdivisions("features.subdivisions", self.features.subdivisions).map_err(|e| e.to_string())?;
        if !self.bias.is_finite() || self.threshold.is_nan() {
            return Err("bias must be finite and threshold a number".into());
        }
        check_weight_magnitudes(&self.weights, self.bias)?;
        if let Some(calibration) = &self.calibration {
            calibration.validate()?;
        }
        if let Some(surface) = &self.surface {
            SurfaceWeights::new(surface.slice.clone(), surface.indicator).map_err(|e| format!("surface: {e}"))?;
            if !self.features.path.eq(&FeaturePath::Fast) {
                return Err("a model with surfaces must use the fast feature path".into());
            }
            check_weight_magnitudes(&surface.slice, 0.0).map_err(|e| format!("surface.slice: {e}"))?;
            check_weight_magnitudes(&surface.indicator, 0.0).map_err(|e| format!("surface.indicator: {e}"))?;
        }
        Ok(())
    }

    /// Reads and checks a model file.
    pub fn read(path: &Path) -> Result<Model> {
        let text = crate::frame::read_text(path)?;
        let model: Model =
            serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("not a cog-gpu model file: {e}")))?;
        model.check().map_err(|e| Error::invalid(path, e))?;
        Ok(model)
    }

    /// Writes the model (checked first), via a temporary file and a rename so a crash never leaves half a
    /// model.
    pub fn write(&self, path: &Path) -> Result<()> {
        self.check().map_err(|e| Error::invalid(path, e))?;
        let text = serde_json::to_string(self).map_err(|e| Error::invalid(path, e.to_string()))?;
        crate::error::write_replacing(path, text.as_bytes())
    }
}

/// Checks hypothesis sizes: 5 widths, 3 depths and 3 heights, each within
/// [[`MIN_OBJECT_SIZE_M`], [`MAX_OBJECT_SIZE_M`]] metres.
pub fn check_sizes(sizes: &SizeQuantiles) -> std::result::Result<(), String> {
    let lists = [("widths", &sizes.widths, 5), ("depths", &sizes.depths, 3), ("heights", &sizes.heights, 3)];
    for (name, values, count) in lists {
        if values.len() != count
            || values.iter().any(|v| !(v.is_finite() && (MIN_OBJECT_SIZE_M..=MAX_OBJECT_SIZE_M).contains(v)))
        {
            return Err(format!(
                "sizes.{name} must hold {count} sizes in [{MIN_OBJECT_SIZE_M}, {MAX_OBJECT_SIZE_M}] m, found {values:?}"
            ));
        }
    }
    Ok(())
}

/// File name of the room-layout model in a models directory (`crate::room_layout::model`).
pub const LAYOUT_MODEL_FILE: &str = "layout.json";

/// Files of a models directory that belong to later stages, not detector models: the context cascade
/// (`cascade.json`, [`crate::cascade`]) and the room layout model ([`LAYOUT_MODEL_FILE`]).
pub const OTHER_STAGE_FILES: &[&str] = &["cascade.json", LAYOUT_MODEL_FILE];

/// The models of a directory (`*.json` except [`OTHER_STAGE_FILES`]), sorted by category. With `categories`, exactly those (each must
/// have a model); without, every model file. A directory without models is an error.
pub fn read_models_dir(dir: &Path, categories: Option<&[String]>) -> Result<Vec<Model>> {
    if dir.is_file() {
        return Err(Error::invalid(dir, "is a file; give the models directory, which holds <category>.json files"));
    }
    if !dir.is_dir() {
        return Err(Error::missing(dir, "models directory"));
    }
    let mut models = Vec::new();
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut paths: Vec<_> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json") && p.is_file())
        // The later stages' files live beside the detectors; they are no category.
        .filter(|p| !p.file_name().and_then(|s| s.to_str()).is_some_and(|name| OTHER_STAGE_FILES.contains(&name)))
        .collect();
    paths.sort();
    for path in paths {
        let model = Model::read(&path)?;
        if path.file_stem().and_then(|s| s.to_str()) != Some(model.category.as_str()) {
            return Err(Error::invalid(
                &path,
                format!("holds a '{}' model; name it {}.json", model.category, model.category),
            ));
        }
        models.push(model);
    }
    if let Some(wanted) = categories {
        for category in wanted {
            if !models.iter().any(|m| &m.category == category) {
                return Err(Error::invalid(dir, format!("no model for category '{category}' ({category}.json)")));
            }
        }
        models.retain(|m| wanted.contains(&m.category));
    }
    if models.is_empty() {
        return Err(Error::invalid(dir, "holds no model files (<category>.json)"));
    }
    models.sort_by(|a, b| a.category.cmp(&b.category));
    Ok(models)
}
