//! The shipped default (`assets/models/` on `assets/sample/`): every model loads with this build's feature
//! layout, and the README's main command finds the objects of the shipped synthetic bedroom.

use std::path::Path;

use cog_gpu::category::LARGE_CATEGORIES;
use cog_gpu::detect::{detect_frame, DetectOptions};
use cog_gpu::features::{Backend, Layout};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::iou_3d;
use cog_gpu::model::{read_models_dir, FeaturePath};

const MODELS: &str = "assets/models";
const SAMPLE: &str = "assets/sample/synth-bedroom-s52";

#[test]
fn the_ten_shipped_models_load_with_this_builds_layout() {
    let models = read_models_dir(Path::new(MODELS), None).unwrap();
    let mut categories: Vec<&str> = models.iter().map(|m| m.category.as_str()).collect();
    categories.sort_unstable();
    let mut expected: Vec<&str> = LARGE_CATEGORIES.to_vec();
    expected.sort_unstable();
    assert_eq!(categories, expected);
    let full = Layout::default();
    for model in &models {
        assert_eq!(model.layout.id(), full.id(), "{}: the shipped models use the full feature set", model.category);
        assert_eq!(model.features.path, FeaturePath::Fast, "{}", model.category);
        // A trained model: weights on every feature group, not a zero vector.
        let norm: f32 = model.weights.iter().map(|w| w * w).sum::<f32>().sqrt();
        assert!(norm > 0.1, "{}: |w| = {norm}", model.category);
        assert!(model.training.get("converged").is_some(), "{}: training provenance missing", model.category);
    }
}

/// The shipped synthetic bedroom holds a bed, a nightstand and a dresser: the shipped models must put a
/// detection on the bed (3D IoU ≥ 0.25, the benchmark's threshold) among their best three bed boxes.
#[test]
fn the_shipped_bed_model_finds_the_sample_bed() {
    let frame = Frame::read(SAMPLE, DepthSource::Raw).unwrap();
    let models = read_models_dir(Path::new(MODELS), Some(&["bed".to_string()])).unwrap();
    let options = DetectOptions { max_per_category: 3, ..DetectOptions::default() };
    let result = detect_frame(&frame, &models, Backend::Cpu, &options).unwrap();
    let truth = frame.objects.iter().find(|o| o.category == "bed").expect("the sample has a bed").cuboid;
    let best = result.detections.iter().map(|d| iou_3d(&d.cuboid(), &truth)).fold(0.0f32, f32::max);
    assert!(best >= 0.25, "best IoU with the sample's bed {best}; detections {:?}", result.detections);
}
