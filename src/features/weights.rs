//! Weight files: one linear detector per file, the start of the model format.
//!
//! ```json
//! {
//!   "format": "cog-gpu-weights",
//!   "version": 1,
//!   "layout_id": "cog-v1 grid=5x5x5 expanded=1 groups=density,normals,cog,view",
//!   "layout": {"base_grid": [5, 5, 5], "expanded": true,
//!              "groups": {"density": true, "normals": true, "cog": true, "view": true}},
//!   "category": "bed",
//!   "bias": 0.0,
//!   "weights": [ ... layout.dim() numbers in the order of `features::feature_layout` ... ]
//! }
//! ```
//! The score of a hypothesis is `weights · φ + bias`. Reading checks that `layout_id` is the id of
//! `layout` under this build's layout definition (so a file written for another feature order is
//! rejected), that there are exactly `layout.dim()` finite weights, and that weights of switched-off groups
//! are zero.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::feature_layout::FeatureLayout;
use crate::error::{Error, Result};

pub const WEIGHTS_FORMAT: &str = "cog-gpu-weights";
pub const WEIGHTS_VERSION: u32 = 1;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightsFile {
    pub format: String,
    pub version: u32,
    pub layout_id: String,
    pub layout: FeatureLayout,
    pub category: String,
    #[serde(default)]
    pub bias: f32,
    pub weights: Vec<f32>,
}

impl WeightsFile {
    pub fn new(layout: FeatureLayout, category: &str, weights: Vec<f32>, bias: f32) -> Result<WeightsFile> {
        let file = WeightsFile {
            format: WEIGHTS_FORMAT.into(),
            version: WEIGHTS_VERSION,
            layout_id: layout.id(),
            layout,
            category: category.into(),
            bias,
            weights,
        };
        file.check().map_err(Error::Input)?;
        Ok(file)
    }

    fn check(&self) -> std::result::Result<(), String> {
        if self.format != WEIGHTS_FORMAT {
            return Err(format!("format is '{}', expected '{WEIGHTS_FORMAT}'", self.format));
        }
        if self.version != WEIGHTS_VERSION {
            return Err(format!("version {} is not supported (this build reads {WEIGHTS_VERSION})", self.version));
        }
        self.layout.validate().map_err(|e| e.to_string())?;
        if self.layout_id != self.layout.id() {
            return Err(format!(
                "layout_id '{}' is not this build's id for the file's layout, '{}'",
                self.layout_id,
                self.layout.id()
            ));
        }
        if self.weights.len() != self.layout.dim() {
            return Err(format!("{} weights, the layout has {} features", self.weights.len(), self.layout.dim()));
        }
        if let Some(n) = self.weights.iter().position(|w| !w.is_finite()) {
            return Err(format!("weight {n} is not finite"));
        }
        if !self.bias.is_finite() {
            return Err("bias is not finite".into());
        }
        check_weight_magnitudes(&self.weights, self.bias)?;
        let mask = self.layout.mask();
        if let Some(n) = (0..mask.len()).find(|&n| !mask[n] && self.weights[n] != 0.0) {
            return Err(format!(
                "weight {n} ({}) belongs to a switched-off group but is not 0",
                self.layout.describe(n)
            ));
        }
        Ok(())
    }

    pub fn read(path: &Path) -> Result<WeightsFile> {
        let text = crate::frame::read_text(path)?;
        let file: WeightsFile =
            serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("not a weights file: {e}")))?;
        file.check().map_err(|m| Error::invalid(path, m))?;
        Ok(file)
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| Error::invalid(path, e.to_string()))?;
        crate::error::write_replacing(path, text.as_bytes())
    }
}

/// Largest absolute weight or bias a model or weights file may hold: features are bounded (densities and
/// bin counts per projected pixel, normalised COG, view RBFs), so any real model's weights are many orders
/// of magnitude below it, and with it no score of the 12 017 dimensions can overflow to infinity or NaN.
pub const MAX_WEIGHT: f32 = 1e6;

/// Checks every weight and the bias against ±[`MAX_WEIGHT`].
pub fn check_weight_magnitudes(weights: &[f32], bias: f32) -> std::result::Result<(), String> {
    if let Some(i) = weights.iter().position(|w| w.abs() > MAX_WEIGHT) {
        return Err(format!("weights[{i}] = {} is beyond ±{MAX_WEIGHT:e}: not a trained model", weights[i]));
    }
    if bias.abs() > MAX_WEIGHT {
        return Err(format!("bias = {bias} is beyond ±{MAX_WEIGHT:e}: not a trained model"));
    }
    Ok(())
}
