//! One frame's sliding window from end to end: preprocessing, yaw grids and hypotheses, then scoring on
//! either path ([`crate::backend::Backend`]). Used by the `score` and `bench` commands and the benchmark.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;

use super::hypotheses::{default_yaws, sliding_window, HypothesisSet, SizeQuantiles, WindowOptions};
use super::preprocess::Preprocessed;
use super::scene::FeatureScene;
use crate::error::Result;
use crate::frame::Frame;

/// The SUN RGB-D size statistics the hypotheses' sizes default to (relative to the crate root).
pub const DEFAULT_SIZE_STATS: &str = "../shared/data/sunrgbd-size-stats.json";

/// A frame made ready for scoring.
pub struct PreparedWindow {
    pub scene: FeatureScene,
    pub set: HypothesisSet,
    /// Seconds for preprocessing, the yaw grids and the hypotheses (CPU, shared by both paths).
    pub preprocess_s: f64,
}

impl PreparedWindow {
    /// Preprocesses `frame` and enumerates the sliding window with `sizes`, the 16 yaws, centre step
    /// `step` and at least `min_points` points inside.
    pub fn new(frame: &Frame, sizes: Vec<Vec3>, step: f32, min_points: u32) -> Result<PreparedWindow> {
        let start = Instant::now();
        let pre = Preprocessed::from_frame(frame)?;
        super::budget::check_window(&pre, &default_yaws(), step, sizes.len())?;
        let scene = FeatureScene::new(pre, &default_yaws(), step);
        let set = sliding_window(&scene, &WindowOptions { sizes, min_points });
        Ok(PreparedWindow { scene, set, preprocess_s: start.elapsed().as_secs_f64() })
    }
}

/// The 45 sizes of `category` from a size statistics file.
pub fn category_sizes(stats: &Path, category: &str) -> Result<Vec<Vec3>> {
    Ok(SizeQuantiles::from_stats_file(stats, category)?.sizes())
}
