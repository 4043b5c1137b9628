//! Model files: round trip and every validation failure, each naming the file and the problem.

use cog_gpu::features::Support;
use std::path::Path;

use cog_gpu::features::LatticePhase;
use cog_gpu::features::YawAnchor;
use cog_gpu::features::{FeatureLayout, Groups, SizeQuantiles};
use cog_gpu::model::{read_models_dir, FeaturePath, FeatureSettings, Model, WindowSettings};

fn sizes() -> SizeQuantiles {
    SizeQuantiles { widths: vec![0.5, 0.6, 0.7, 0.8, 0.9], depths: vec![0.5, 0.6, 0.7], heights: vec![0.7, 0.8, 0.9] }
}

fn model(category: &str) -> Model {
    let layout = FeatureLayout::new([3, 3, 3], false, Groups::GEOM).unwrap();
    let mask = layout.mask();
    let weights = (0..layout.dim()).map(|n| if mask[n] { (n % 7) as f32 * 0.1 - 0.3 } else { 0.0 }).collect();
    Model::new(
        category,
        layout,
        sizes(),
        WindowSettings {
            step: 0.1,
            min_points: 50,
            yaw_anchor: YawAnchor::Walls,
            support: Support::Floor,
            lattice: LatticePhase::Camera,
            supporters: cog_gpu::category::SurfaceCategories::ALL,
        },
        FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
        weights,
        serde_json::json!({"note": "test"}),
    )
    .unwrap()
}

#[test]
fn a_model_survives_a_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chair.json");
    let m = model("chair");
    m.write(&path).unwrap();
    assert_eq!(Model::read(&path).unwrap(), m);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"format\":\"cog-gpu-model\"") && text.contains("\"path\":\"fast\""));
}

#[test]
fn the_yaw_anchor_is_stored_and_old_files_mean_camera() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chair.json");
    let m = model("chair");
    assert_eq!(m.window.yaw_anchor, YawAnchor::Walls);
    m.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"yaw_anchor\":\"walls\""), "{text}");
    // A file written before the anchor existed: no field, trained on the camera's yaws.
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["window"].as_object_mut().unwrap().remove("yaw_anchor");
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    assert_eq!(Model::read(&path).unwrap().window.yaw_anchor, YawAnchor::Camera);
    // An unknown anchor is rejected, naming the file.
    value["window"]["yaw_anchor"] = "north".into();
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    assert!(Model::read(&path).unwrap_err().to_string().contains("chair.json"));
}

#[test]
fn the_support_is_stored_and_old_files_mean_floor() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("pillow.json");
    let mut m = model("pillow");
    m.window.support = Support::Surfaces;
    m.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"support\":\"surfaces\""), "{text}");
    assert_eq!(Model::read(&path).unwrap().window.support, Support::Surfaces);
    m.window.support = Support::Free;
    m.write(&path).unwrap();
    assert!(std::fs::read_to_string(&path).unwrap().contains("\"support\":\"free\""));
    assert_eq!(Model::read(&path).unwrap().window.support, Support::Free);
    m.window.support = Support::FloorAndSurfaces;
    m.write(&path).unwrap();
    assert!(std::fs::read_to_string(&path).unwrap().contains("\"support\":\"floor+surfaces\""));
    assert_eq!(Model::read(&path).unwrap().window.support, Support::FloorAndSurfaces);
    // The supporters: written when not all seven, read back; absent means all; a name without a surface
    // is refused with the file named.
    assert!(!std::fs::read_to_string(&path).unwrap().contains("supporters"));
    assert!(Model::read(&path).unwrap().window.supporters.is_all());
    m.window.supporters = cog_gpu::category::SurfaceCategories::NONE.with("counter").unwrap();
    m.write(&path).unwrap();
    assert!(std::fs::read_to_string(&path).unwrap().contains("\"supporters\":[\"counter\"]"));
    assert_eq!(Model::read(&path).unwrap().window.supporters, m.window.supporters);
    let mut value: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    value["window"]["supporters"] = serde_json::json!(["counter", "lamp"]);
    std::fs::write(&path, value.to_string()).unwrap();
    let error = Model::read(&path).unwrap_err().to_string();
    assert!(
        error.contains("pillow.json") && error.contains("'lamp' is not a category with a support surface"),
        "{error}"
    );
    m.window.supporters = cog_gpu::category::SurfaceCategories::ALL;
    // A file written before the support existed: no field, a floor model.
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["window"].as_object_mut().unwrap().remove("support");
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    assert_eq!(Model::read(&path).unwrap().window.support, Support::Floor);
    value["window"]["support"] = "ceiling".into();
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    assert!(Model::read(&path).unwrap_err().to_string().contains("pillow.json"));
}

#[test]
fn the_lattice_is_stored_and_old_files_mean_camera() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("door.json");
    let mut m = model("door");
    m.window.lattice = LatticePhase::Walls;
    m.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("\"lattice\":\"walls\""), "{text}");
    assert_eq!(Model::read(&path).unwrap().window.lattice, LatticePhase::Walls);
    // Models that differ only in the lattice search different yaw grids.
    assert_ne!(m.window.scene_key(), model("door").window.scene_key());
    // A file written before the lattice existed: no field, the camera's lattice.
    let mut value: serde_json::Value = serde_json::from_str(&text).unwrap();
    value["window"].as_object_mut().unwrap().remove("lattice");
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    assert_eq!(Model::read(&path).unwrap().window.lattice, LatticePhase::Camera);
    value["window"]["lattice"] = "floor".into();
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    assert!(Model::read(&path).unwrap_err().to_string().contains("door.json"));
}

/// A model detected at another step than it was trained at is flagged when its thinnest size is below the
/// coarser of the two steps' lattice cells (step / subdivisions): by hand, a 0.09 m deep door trained at
/// 0.2 m (cell 0.1 m) and detected at 0.1 m is; the same door at its training step, a 0.5 m deep model at
/// either step, and a model without a recorded training step are not.
#[test]
fn a_thin_model_detected_at_another_step_is_flagged() {
    let mut door = model("door");
    door.training = serde_json::json!({"training_step": 0.2});
    door.window.step = 0.2;
    assert_eq!(door.step_mismatch(), None, "same step");
    door.window.step = 0.1;
    assert_eq!(door.step_mismatch(), None, "0.5 m deep: thicker than the 0.1 m cell");
    door.sizes.depths = vec![0.09, 0.095, 0.1];
    let warning = door.step_mismatch().expect("a 0.09 m door below the 0.1 m cell");
    assert!(warning.contains("door") && warning.contains("0.090") && warning.contains("0.100"), "{warning}");
    // Three subdivisions: the cell is 0.2 / 3 = 0.067 m, below the door's 0.09 m.
    door.features.subdivisions = 3;
    assert_eq!(door.step_mismatch(), None);
    door.features.subdivisions = 2;
    door.training = serde_json::json!({"note": "no step recorded"});
    assert_eq!(door.step_mismatch(), None);
}

/// Writes `m` as JSON, applies `edit` to the JSON value, and returns the read error message.
fn read_error(dir: &Path, edit: impl Fn(&mut serde_json::Value)) -> String {
    let path = dir.join("chair.json");
    let mut value = serde_json::to_value(model("chair")).unwrap();
    edit(&mut value);
    std::fs::write(&path, serde_json::to_string(&value).unwrap()).unwrap();
    let err = Model::read(&path).expect_err("the edited model must be rejected").to_string();
    assert!(err.contains("chair.json"), "the error must name the file: {err}");
    err
}

#[test]
fn every_invalid_field_is_rejected_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert!(read_error(d, |v| v["format"] = "cog-gpu-weights".into()).contains("format"));
    assert!(read_error(d, |v| v["version"] = 7.into()).contains("version 7"));
    assert!(read_error(d, |v| v["category"] = "spaceship".into()).contains("spaceship"));
    assert!(read_error(d, |v| v["layout_id"] = "cog-v0 grid=3x3x3".into()).contains("layout_id"));
    assert!(read_error(d, |v| {
        v["weights"].as_array_mut().unwrap().pop();
    })
    .contains("weights has"));
    assert!(read_error(d, |v| v["weights"][3] = serde_json::Value::Null).contains("not a cog-gpu model file"));
    // The COG block of voxel 0 is switched off in a GEOM layout: entry 26.
    assert!(read_error(d, |v| v["weights"][26] = 0.5.into()).contains("switched-off"));
    assert!(read_error(d, |v| v["sizes"]["widths"] = serde_json::json!([0.5, 0.6])).contains("sizes.widths"));
    assert!(read_error(d, |v| v["sizes"]["heights"][1] = (-1.0).into()).contains("sizes.heights"));
    assert!(read_error(d, |v| v["window"]["step"] = 0.0.into()).contains("window.step"));
    assert!(read_error(d, |v| v["features"]["path"] = "magic".into()).contains("not a cog-gpu model file"));
    assert!(read_error(d, |v| v["features"]["subdivisions"] = 0.into()).contains("subdivisions"));
    std::fs::write(d.join("chair.json"), "{ truncated").unwrap();
    assert!(Model::read(&d.join("chair.json")).unwrap_err().to_string().contains("chair.json"));
}

#[test]
fn a_models_directory_is_read_by_category() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let missing = read_models_dir(&d.join("nowhere"), None).unwrap_err().to_string();
    assert!(missing.contains("nowhere"), "{missing}");
    assert!(read_models_dir(d, None).unwrap_err().to_string().contains("no model files"));
    model("sofa").write(&d.join("sofa.json")).unwrap();
    model("bed").write(&d.join("bed.json")).unwrap();
    std::fs::write(d.join("notes.txt"), "not a model").unwrap();
    let all = read_models_dir(d, None).unwrap();
    assert_eq!(all.iter().map(|m| m.category.as_str()).collect::<Vec<_>>(), ["bed", "sofa"]);
    let some = read_models_dir(d, Some(&["sofa".to_string()])).unwrap();
    assert_eq!(some.len(), 1);
    let absent = read_models_dir(d, Some(&["toilet".to_string()])).unwrap_err().to_string();
    assert!(absent.contains("toilet"), "{absent}");
    // A file whose name is not its category.
    model("bed").write(&d.join("desk.json")).unwrap();
    let misnamed = read_models_dir(d, None).unwrap_err().to_string();
    assert!(misnamed.contains("desk.json") && misnamed.contains("'bed'"), "{misnamed}");
}

/// Version 2: a model with latent support surfaces keeps its surface weights through a file; a version-2
/// file without them, a version-1 file with them, and malformed surface weights are refused.
#[test]
fn a_surface_model_is_version_2_and_checked() {
    use cog_gpu::features::surface::{SurfaceWeights, SLICES, SLICE_DIM};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chair.json");
    let slice: Vec<f32> = (0..SLICE_DIM).map(|k| (k % 11) as f32 * 0.01 - 0.05).collect();
    let indicator = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];
    let m = model("chair").with_surface(SurfaceWeights::new(slice, indicator).unwrap()).unwrap();
    assert_eq!(m.version, 2);
    m.write(&path).unwrap();
    assert_eq!(Model::read(&path).unwrap(), m);
    let value = serde_json::to_value(&m).unwrap();
    let refused = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut v = value.clone();
        edit(&mut v);
        std::fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
        let err = Model::read(&path).expect_err("must be refused").to_string();
        assert!(err.contains("chair.json"), "{err}");
        err
    };
    assert!(refused(&|v| v["version"] = 1.into()).contains("no \"surface\""));
    assert!(refused(&|v| {
        v.as_object_mut().unwrap().remove("surface");
    })
    .contains("needs its \"surface\""));
    assert!(refused(&|v| {
        v["surface"]["slice"].as_array_mut().unwrap().pop();
    })
    .contains("slice entries"));
    assert!(refused(&|v| v["surface"]["indicator"] = serde_json::json!(vec![0.0; SLICES - 1]))
        .contains("not a cog-gpu model file"));
    assert!(refused(&|v| v["surface"]["slice"][0] = 1e12.into()).contains("surface.slice"));
    // A plain model stays version 1 without a "surface" field.
    let text = serde_json::to_string(&model("chair")).unwrap();
    assert!(text.contains("\"version\":1") && !text.contains("surface"), "{text}");
}
