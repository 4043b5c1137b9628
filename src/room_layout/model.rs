//! The layout model file, `layout.json` in a models directory beside the detector models
//! (`crate::model::read_models_dir` skips it by name, [`crate::model::LAYOUT_MODEL_FILE`]).
//!
//! ```json
//! {"format": "cog-gpu-layout-model", "version": 3, "discretisation": "manhattan" | "cubical",
//!  "cog": false | true, "edges": false | true,
//!  "weights": [304 or 400 numbers without COG, 952 or 1264 with: the voxel weights in the order of
//!              room_layout::voxels::feature_index, then (with "cog") the COG weights in the order of
//!              room_layout::voxels::Descriptor::cog_index, then the 16 box-feature weights of
//!              room_layout::voxels::box_features, then (with "edges") the 2 edge-orientation weights of
//!              room_layout::orientation::edge_orientation_features],
//!  "provenance": {free-form: the training command, data, seeds, counts, solver figures}}
//! ```

use std::path::Path;

use super::voxels::Descriptor;
use crate::error::{Error, Result};

pub const FORMAT: &str = "cog-gpu-layout-model";
/// Version 2 added the box features (`room_layout::voxels::box_features`), version 3 their reach features
/// (with the hypotheses beyond the farthest point); an older file lacks them and is refused (retrain it with
/// `cog-gpu train-layout`).
pub const VERSION: u32 = 3;
/// Largest |weight| accepted (a larger one is no trained model and would overflow the fixed-point scores).
pub const MAX_WEIGHT: f32 = 1e6;

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct LayoutModel {
    pub format: String,
    pub version: u32,
    /// `discretisation`, `cog` and `edges` at the top level of the file (the last two absent in files
    /// written before them: false).
    #[serde(flatten)]
    pub descriptor: Descriptor,
    pub weights: Vec<f32>,
    #[serde(default)]
    pub provenance: serde_json::Value,
}

impl LayoutModel {
    pub fn new(descriptor: Descriptor, weights: Vec<f32>, provenance: serde_json::Value) -> LayoutModel {
        LayoutModel { format: FORMAT.into(), version: VERSION, descriptor, weights, provenance }
    }

    /// What is wrong with the model, if anything.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.format != FORMAT {
            return Err(format!("format is '{}', expected '{FORMAT}'", self.format));
        }
        if self.version != VERSION {
            return Err(format!(
                "version {} (this build reads version {VERSION}, which adds the box features' reach; retrain \
                 the model with `cog-gpu train-layout`)",
                self.version
            ));
        }
        let dim = self.descriptor.dim();
        if self.weights.len() != dim {
            return Err(format!("{} weights; a {} layout model has {dim}", self.weights.len(), self.descriptor.name()));
        }
        if let Some(i) = self.weights.iter().position(|w| !w.is_finite() || w.abs() > MAX_WEIGHT) {
            return Err(format!("weight {i} is {} (must be finite, |w| <= {MAX_WEIGHT})", self.weights[i]));
        }
        Ok(())
    }

    pub fn read(path: &Path) -> Result<LayoutModel> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
        let model: LayoutModel =
            serde_json::from_str(text).map_err(|e| Error::invalid(path, format!("not a layout model file: {e}")))?;
        model.check().map_err(|m| Error::invalid(path, m))?;
        Ok(model)
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        self.check().map_err(|m| Error::invalid(path, m))?;
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::invalid(path, e.to_string()))?;
        crate::error::write_replacing(path, (text + "\n").as_bytes())
    }

    pub fn weights_f64(&self) -> Vec<f64> {
        self.weights.iter().map(|&w| w as f64).collect()
    }
}
