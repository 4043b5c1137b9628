//! The feature engine (paper §3): per-frame preprocessing, the feature layout, sliding-window cuboid
//! hypotheses and their features — density, normal histograms, Clouds of Oriented Gradients and view
//! features — on the CPU (exact reference, rayon) and on the GPU (`crate::gpu::features`), and the
//! support-surface slices of §4 ([`surface`]).
//!
//! Flow: [`Preprocessed::from_frame`] → [`FeatureScene::new`] (per-yaw point grids shared by every
//! hypothesis of a yaw) → [`sliding_window`] → [`cpu::features`] / [`cpu::scores`] or the GPU twins.

pub mod budget;
pub mod cpu;
pub mod fast;
pub mod feature_layout;
pub mod hypotheses;
pub mod out_of_view;
pub mod preprocess;
pub mod scene;
pub mod surface;

pub use feature_layout::{FeatureLayout, Groups};
pub use hypotheses::{
    default_yaws, free_window, resting_window, sliding_window, surface_window, window_yaws, yaws_under, FrameYaws,
    Hypothesis, HypothesisSet, SizeQuantiles, Support, SupportSurface, WindowOptions, YawAnchor,
};
pub use preprocess::{ImageGradients, Preprocessed};
pub use scene::{FeatureScene, LatticePhase, PointRecord, YawGrid};
pub mod weights;
pub mod window;

pub use weights::WeightsFile;
pub use window::PreparedWindow;
