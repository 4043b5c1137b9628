//! Helpers shared by test files (`mod common;` in each; a file uses some of them).

use std::path::Path;

use cog_gpu::frame::{Frame, Object};
use cog_gpu::gpu::GpuContext;

/// The GPU context for a GPU test: `None` (the test skips, saying so) only when there is no adapter and
/// `COG_GPU_SKIP_GPU_TESTS=1`; without that variable a missing adapter fails the test, so that CI cannot
/// pass without running the GPU tests.
#[allow(dead_code)]
pub fn gpu_context() -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(ctx) => Some(ctx),
        Err(e) if std::env::var("COG_GPU_SKIP_GPU_TESTS").as_deref() == Ok("1") => {
            eprintln!("skipped: no GPU adapter ({e}) and COG_GPU_SKIP_GPU_TESTS=1");
            None
        }
        Err(e) => panic!(
            "no GPU adapter for the GPU tests: {e}. Install a Vulkan driver (mesa-vulkan-drivers gives lavapipe) \
             and run with NODEVICE_SELECT=1, or set COG_GPU_SKIP_GPU_TESTS=1 to skip them"
        ),
    }
}

/// Writes a tiny frame (8×6 pixels at 2 m, identity extrinsics) with `objects` as its annotation to
/// `root/name`: enough for commands that read only the annotations (eval, calibrate, cascade).
#[allow(dead_code)]
pub fn write_tiny_frame(root: &Path, name: &str, objects: Vec<Object>) {
    let frame = Frame {
        name: name.into(),
        rgb: image::RgbImage::from_pixel(8, 6, image::Rgb([90, 120, 150])),
        depth_mm: vec![2000; 48],
        k: [[10.0, 0.0, 4.5], [0.0, 10.0, 3.5], [0.0, 0.0, 1.0]],
        extrinsics: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        scene: None,
        objects,
        layout: None,
    };
    frame.write(root.join(name)).unwrap();
}

/// The WGSL module `shaders/<file>`, parsed by naga.
#[allow(dead_code)]
pub fn shader_module(file: &str) -> naga::Module {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders").join(file);
    let source = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    naga::front::wgsl::parse_str(&source).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The initialiser of WGSL `const NAME` in `module`.
#[allow(dead_code)]
fn wgsl_const_init<'m>(module: &'m naga::Module, name: &str) -> &'m naga::Expression {
    let (_, constant) = module
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no const {name} in the shader"));
    &module.global_expressions[constant.init]
}

/// The value of WGSL `const NAME` (an integer literal) in `module`, as i64.
#[allow(dead_code)]
pub fn wgsl_const(module: &naga::Module, name: &str) -> i64 {
    match *wgsl_const_init(module, name) {
        naga::Expression::Literal(naga::Literal::U32(v)) => v as i64,
        naga::Expression::Literal(naga::Literal::I32(v)) => v as i64,
        ref other => panic!("const {name} is {other:?}, expected an integer literal"),
    }
}

/// The value of WGSL `const NAME` (an `f32` literal, or an abstract float naga has concretised) in
/// `module`.
#[allow(dead_code)]
pub fn wgsl_const_f32(module: &naga::Module, name: &str) -> f32 {
    match *wgsl_const_init(module, name) {
        naga::Expression::Literal(naga::Literal::F32(v)) => v,
        naga::Expression::Literal(naga::Literal::AbstractFloat(v)) => v as f32,
        ref other => panic!("const {name} is {other:?}, expected a float literal"),
    }
}

/// The size in bytes of WGSL struct `name` in `module`, as naga lays it out.
#[allow(dead_code)]
pub fn wgsl_struct_size(module: &naga::Module, name: &str) -> usize {
    let mut layouter = naga::proc::Layouter::default();
    layouter.update(module.to_ctx()).unwrap();
    let (handle, _) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("no struct {name}"));
    layouter[handle].size as usize
}

/// `count` pseudo-random weight vectors in [−1, 1) (a 64-bit LCG per vector).
#[allow(dead_code)]
pub fn random_weights(layout: &cog_gpu::features::FeatureLayout, count: usize, seed: u64) -> Vec<Vec<f32>> {
    (0..count as u64)
        .map(|w| {
            let mut state = (seed * 1000 + w).wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (0..layout.dim())
                .map(|_| {
                    state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
                })
                .collect()
        })
        .collect()
}

/// The shipped size statistics that the tests' windows take their sizes from.
#[allow(dead_code)]
pub const SIZE_STATS: &str = "../shared/data/sunrgbd-size-stats.json";

/// A small synthetic frame (160×120, seed 3, frame 0) and its `category` window at 0.1 m with at least 50
/// points per box.
#[allow(dead_code)]
pub fn synthetic_window(category: &str) -> cog_gpu::features::PreparedWindow {
    let frame = cog_gpu::synth::generate_frame(3, 0, &cog_gpu::synth::SynthOptions::small(160, 120)).unwrap().frame;
    let sizes = cog_gpu::features::SizeQuantiles::from_stats_file(Path::new(SIZE_STATS), category).unwrap().sizes();
    cog_gpu::features::PreparedWindow::new(&frame, sizes, 0.1, 50).unwrap()
}

/// Up to `count` of `window`'s kept hypotheses, evenly spread (so all yaws and sizes appear).
#[allow(dead_code)]
pub fn spread_sample(window: &cog_gpu::features::PreparedWindow, count: usize) -> Vec<cog_gpu::features::Hypothesis> {
    let kept = &window.set.hypotheses;
    kept.iter().step_by((kept.len() / count).max(1)).take(count).copied().collect()
}

/// The floor's sliding window (`"support": "floor"`, walls' yaws, the camera's lattice, every supporter) at
/// `step` metres with at least `min_points` points a box: the window most test models use.
#[allow(dead_code)]
pub fn floor_window(step: f32, min_points: u32) -> cog_gpu::model::WindowSettings {
    cog_gpu::model::WindowSettings {
        step,
        min_points,
        yaw_anchor: cog_gpu::features::YawAnchor::Walls,
        support: cog_gpu::features::Support::Floor,
        lattice: cog_gpu::features::LatticePhase::Camera,
        supporters: cog_gpu::category::SurfaceCategories::ALL,
    }
}

/// Runs the `cog-gpu` binary with `args` (`NODEVICE_SELECT=1`, silencing the loader's warning).
#[allow(dead_code)]
pub fn run_cog_gpu(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
        .args(args)
        .env("NODEVICE_SELECT", "1")
        .output()
        .expect("run cog-gpu")
}

/// A cascade file with no stages over the context categories table and desk (feature set v4): the
/// exclusion and the final calibration given, applied to first-stage scores as they are.
#[allow(dead_code)]
pub fn cascade_without_stages(
    exclusion: Option<cog_gpu::exclusion::Exclusion>,
    final_calibration: Option<cog_gpu::calibration::final_calibration::FinalCalibration>,
) -> cog_gpu::cascade::Cascade {
    cog_gpu::cascade::Cascade {
        format: cog_gpu::cascade::FORMAT.into(),
        version: cog_gpu::cascade::VERSION,
        features: cog_gpu::cascade::FEATURES.into(),
        categories: ["table", "desk"].map(String::from).to_vec(),
        stages: std::collections::BTreeMap::new(),
        training: cog_gpu::cascade::CascadeTraining::default(),
        exclusion,
        final_calibration,
    }
}

/// Borrowed views of owned command-line arguments (for `run_cog_gpu` and the like).
#[allow(dead_code)]
pub fn strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}
