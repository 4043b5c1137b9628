//! The `room_layout` kernel (`shaders/room_layout.wgsl`) against its CPU twin and the plain reference
//! scorer, on lavapipe (integers: exact equality), and the constants and struct sizes the shader shares
//! with Rust, read from the WGSL with naga.
//!
//! The GPU tests need a Vulkan adapter (lavapipe: mesa-vulkan-drivers; run with NODEVICE_SELECT=1) unless
//! COG_GPU_SKIP_GPU_TESTS=1, in which case they say they skip.

mod common;

use std::sync::OnceLock;

use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::gpu::room_layout::{
    room_layout_cpu, room_layout_gpu, GpuRoomBox, LayoutInputs, LayoutParams, YawRange, CELLS_PER_ITERATION,
    DISCRETISATION_CUBICAL, DISCRETISATION_MANHATTAN,
};
use cog_gpu::gpu::{self, GpuContext};
use cog_gpu::room_layout::voxels::{
    scores_cpu, Descriptor, Discretisation, ScoringTables, BAND_MM, CUBICAL_SPLITS, NO_REGION,
};
use cog_gpu::room_layout::{hypotheses, LayoutScene};
use common::{wgsl_const, wgsl_struct_size};

static GPU: OnceLock<Option<GpuContext>> = OnceLock::new();

fn gpu_or_skip(test: &str) -> Option<&'static GpuContext> {
    let ctx = GPU.get_or_init(|| gpu::acquire(false)).as_ref();
    if ctx.is_none() {
        if std::env::var("COG_GPU_SKIP_GPU_TESTS").as_deref() == Ok("1") {
            eprintln!("{test}: skipped, no GPU adapter and COG_GPU_SKIP_GPU_TESTS=1");
            return None;
        }
        panic!("{test}: no GPU adapter; install mesa-vulkan-drivers and run with NODEVICE_SELECT=1, or set COG_GPU_SKIP_GPU_TESTS=1");
    }
    ctx
}

fn real_frame() -> Frame {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/sunrgbd/kv1-b3dodata-img_0063");
    Frame::read(&dir, DepthSource::Raw).expect("the real frame")
}

#[test]
fn kernel_twin_and_reference_agree_on_a_real_frame() {
    let scene = LayoutScene::from_frame(&real_frame()).unwrap();
    let (cells, boxes) = hypotheses(&scene, true, true);
    assert!(boxes.len() > 50, "{} hypotheses", boxes.len());
    let gpu = gpu_or_skip("kernel_twin_and_reference_agree_on_a_real_frame");
    let descriptors = [Discretisation::Manhattan, Discretisation::Cubical]
        .into_iter()
        .flat_map(|d| [false, true].map(|cog| Descriptor::new(d, cog, cog)));
    for disc in descriptors {
        // Weights with both signs and no structure, so that every region, class and COG bin matters.
        let w: Vec<f64> = (0..disc.dim()).map(|i| ((i * 7919 % 211) as f64 - 105.0) / 13.0).collect();
        let tables = ScoringTables::new(disc, &cells, &w);
        let reference = scores_cpu(&cells, &tables, &boxes);
        let inputs = LayoutInputs::new(&cells, &tables, &boxes).unwrap();
        let twin = room_layout_cpu(&inputs);
        assert_eq!(twin, reference, "{disc:?}: twin vs reference");
        // The scores differ between hypotheses (the test would pass trivially on constants).
        assert!(reference.iter().any(|&s| s != reference[0]));
        if let Some(ctx) = gpu {
            let on_gpu = room_layout_gpu(ctx, &inputs).unwrap();
            assert_eq!(on_gpu, twin, "{disc:?}: GPU vs twin");
            // Same input, same output, bit for bit.
            assert_eq!(room_layout_gpu(ctx, &inputs).unwrap(), on_gpu);
        }
    }
}

/// The WGSL module, parsed by naga.
fn shader() -> naga::Module {
    common::shader_module("room_layout.wgsl")
}

#[test]
fn shared_constants_match_the_shader() {
    let module = shader();
    assert_eq!(wgsl_const(&module, "BAND_MM"), BAND_MM as i64);
    assert_eq!(wgsl_const(&module, "CUBICAL_SPLITS"), CUBICAL_SPLITS as i64);
    assert_eq!(wgsl_const(&module, "NO_REGION"), NO_REGION as i64);
    assert_eq!(wgsl_const(&module, "CELLS_PER_ITERATION"), CELLS_PER_ITERATION as i64);
    assert_eq!(wgsl_const(&module, "DISCRETISATION_MANHATTAN"), DISCRETISATION_MANHATTAN as i64);
    assert_eq!(wgsl_const(&module, "DISCRETISATION_CUBICAL"), DISCRETISATION_CUBICAL as i64);
}

#[test]
fn shared_structs_have_the_rust_sizes() {
    let module = shader();
    assert_eq!(wgsl_struct_size(&module, "LayoutParams"), std::mem::size_of::<LayoutParams>());
    assert_eq!(wgsl_struct_size(&module, "YawRange"), std::mem::size_of::<YawRange>());
    assert_eq!(wgsl_struct_size(&module, "RoomBox"), std::mem::size_of::<GpuRoomBox>());
}
