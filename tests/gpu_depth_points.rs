//! The depth_points kernel against its CPU twin, the independent f64 `Frame::point_cloud`, and hand-computed
//! cases; plus the adapter choice of `gpu::acquire`.
//!
//! GPU tests fail when no adapter can be had (install mesa-vulkan-drivers for lavapipe, run with
//! NODEVICE_SELECT=1), unless COG_GPU_SKIP_GPU_TESTS=1, in which case they say they skip. Set
//! COG_GPU_EXPECT_ADAPTER=<substring> to also check which adapter was chosen (e.g. `llvmpipe`).

use std::path::Path;
use std::sync::{Mutex, OnceLock};

use cog_gpu::frame::{decode_depth_value, encode_depth_value, DepthSource, Frame};
use cog_gpu::gpu::depth_points::{
    decode_depth_mm, depth_points_cpu, depth_points_gpu, depth_points_gpu_chunked, pack_stored_depth, stored_depth_of,
    DepthPointsParams,
};
use cog_gpu::gpu::{self, GpuContext};
use glam::{Mat3, Vec3};

const FRAME_DIR: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";

/// GPU vs CPU twin, per coordinate: |gpu − cpu| ≤ TOL·max(1, |cpu|). Both run the same f32 operations in
/// the same order, but WGSL only bounds f32 division to 2.5 ULP and lets drivers fuse a·b + c into an FMA;
/// each of the ~8 operations on the way to a coordinate of at most ~8 m may then differ by a few ULP
/// (1 ULP at 8 m is 9.5e-7 m), so 1e-5 leaves room for that while still catching any real bug (a wrong
/// pixel, axis or sign is off by centimetres at least).
const GPU_TOL: f32 = 1e-5;

/// CPU twin (f32, intrinsics and Rtilt rounded to f32) vs `Frame::point_cloud` (f64, rounded once), in
/// metres: ~8 f32 operations at ≤ 0.5 ULP each plus the f32 rounding of K and Rtilt (relative ~6e-8)
/// give a few 1e-6 m at 8 m.
const REFERENCE_TOL_M: f32 = 1e-5;

static GPU: OnceLock<Option<GpuContext>> = OnceLock::new();

/// The shared context, or `None` (after saying so) when COG_GPU_SKIP_GPU_TESTS=1 and there is no GPU.
fn gpu_or_skip(test: &str) -> Option<&'static GpuContext> {
    let ctx = GPU
        .get_or_init(|| {
            let _ = env_logger::builder().is_test(true).try_init();
            gpu::acquire(false)
        })
        .as_ref();
    if ctx.is_none() {
        if std::env::var("COG_GPU_SKIP_GPU_TESTS").as_deref() == Ok("1") {
            eprintln!("{test}: skipped, no GPU adapter and COG_GPU_SKIP_GPU_TESTS=1");
            return None;
        }
        panic!(
            "{test}: no GPU adapter (Vulkan/Metal/DX12). Install mesa-vulkan-drivers (lavapipe) and run with \
             NODEVICE_SELECT=1, or set COG_GPU_SKIP_GPU_TESTS=1 to skip the GPU tests"
        );
    }
    ctx
}

fn real_frame() -> &'static Frame {
    static FRAME: OnceLock<Frame> = OnceLock::new();
    FRAME.get_or_init(|| {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(FRAME_DIR);
        Frame::read(&dir, DepthSource::Raw).unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
    })
}

/// Largest |a − b| / max(1, |b|) over xyz, and whether the validity (w) agrees everywhere.
fn compare(a: &[[f32; 4]], b: &[[f32; 4]]) -> (f32, usize) {
    assert_eq!(a.len(), b.len(), "point counts differ");
    let mut worst = 0.0f32;
    let mut mask_mismatches = 0;
    for (p, q) in a.iter().zip(b) {
        if p[3] != q[3] {
            mask_mismatches += 1;
        }
        for k in 0..3 {
            worst = worst.max((p[k] - q[k]).abs() / q[k].abs().max(1.0));
        }
    }
    (worst, mask_mismatches)
}

fn valid_count(points: &[[f32; 4]]) -> usize {
    points.iter().filter(|p| p[3] == 1.0).count()
}

// ---------------------------------------------------------------------------------------------------------
// Hand-computed cases (CPU twin exact, GPU within GPU_TOL)

/// A 3×2 image with fx = 2, fy = 4, cx = 2, cy = 1.5 (1-based) and depths chosen so every value is exact
/// in binary. Pixel (col, row) has u = col + 1, v = row + 1; camera point x = (u − cx)·z/fx,
/// y = (v − cy)·z/fy; upright point (x, z, −y) for the identity Rtilt.
fn synthetic_3x2() -> (DepthPointsParams, Vec<u16>, Vec<[f32; 4]>) {
    let depth_mm: [u16; 6] = [1000, 0, 2000, 500, 9000, 1500];
    let stored: Vec<u16> = depth_mm.iter().map(|&mm| encode_depth_value(mm)).collect();
    let params = DepthPointsParams::new([2.0, 4.0, 2.0, 1.5], Mat3::IDENTITY, 3, 2);
    let expected = vec![
        // (0,0): u=1 v=1 z=1: x=(1−2)·1/2=−0.5, y=(1−1.5)·1/4=−0.125
        [-0.5, 1.0, 0.125, 1.0],
        // (1,0): no depth
        [0.0, 0.0, 0.0, 0.0],
        // (2,0): u=3 v=1 z=2: x=1·2/2=1, y=−0.5·2/4=−0.25
        [1.0, 2.0, 0.25, 1.0],
        // (0,1): u=1 v=2 z=0.5: x=−1·0.5/2=−0.25, y=0.5·0.5/4=0.0625
        [-0.25, 0.5, -0.0625, 1.0],
        // (1,1): u=2 v=2, 9000 mm clamped to z=8: x=0, y=0.5·8/4=1
        [0.0, 8.0, -1.0, 1.0],
        // (2,1): u=3 v=2 z=1.5: x=1·1.5/2=0.75, y=0.5·1.5/4=0.1875
        [0.75, 1.5, -0.1875, 1.0],
    ];
    (params, stored, expected)
}

/// Rtilt turning the upright frame by +90° about z: (a, b, c) ↦ (−b, a, c). Not symmetric, so a
/// transposed upload (rows for columns) would give (b, −a, c) instead.
fn quarter_turn() -> Mat3 {
    Mat3::from_cols(Vec3::new(0.0, 1.0, 0.0), Vec3::new(-1.0, 0.0, 0.0), Vec3::Z)
}

fn quarter_turned(points: &[[f32; 4]]) -> Vec<[f32; 4]> {
    points.iter().map(|p| [-p[1], p[0], p[2], p[3]]).collect()
}

#[test]
fn cpu_twin_matches_hand_computed_points() {
    let (params, stored, expected) = synthetic_3x2();
    assert_eq!(depth_points_cpu(&params, &stored).unwrap(), expected);
    let turned = DepthPointsParams::new(params.intrinsics, quarter_turn(), 3, 2);
    assert_eq!(depth_points_cpu(&turned, &stored).unwrap(), quarter_turned(&expected));
}

#[test]
fn gpu_matches_hand_computed_points() {
    let Some(ctx) = gpu_or_skip("gpu_matches_hand_computed_points") else { return };
    let (params, stored, expected) = synthetic_3x2();
    let turned = DepthPointsParams::new(params.intrinsics, quarter_turn(), 3, 2);
    for (params, expected) in [(params, expected.clone()), (turned, quarter_turned(&expected))] {
        let got = depth_points_gpu(ctx, &params, &stored).unwrap();
        let (worst, mask_mismatches) = compare(&got, &expected);
        assert_eq!(mask_mismatches, 0, "validity differs: {got:?} vs {expected:?}");
        assert!(worst <= GPU_TOL, "worst error {worst:e}: {got:?} vs {expected:?}");
    }
}

/// (stored PNG value, millimetres), worked by hand: mm = ((d >> 3) | (d << 13)) & 0xffff.
const DECODE_CASES: [(u16, u16); 7] = [
    (0, 0),           // missing stays missing
    (8, 1),           // 0b1000 >> 3
    (9872, 1234),     // 1234 << 3 = 9872, no bits wrap
    (1, 8192),        // bit 0 wraps to bit 13
    (0x000C, 0x8001), // 0b1100: bit 3 → bit 0, bit 2 → bit 15
    (0xffff, 0xffff), // all ones stay all ones
    (0xfff8, 0x1fff), // the 13 high bits move down, nothing wraps in
];

#[test]
fn decode_rule_on_hand_picked_values() {
    for (stored, mm) in DECODE_CASES {
        assert_eq!(decode_depth_mm(stored as u32), mm as u32, "stored {stored:#06x}");
    }
    // The twin's shift-and-mask agrees with the frame module's rotate_right on every 16-bit value.
    for stored in 0..=u16::MAX {
        assert_eq!(decode_depth_mm(stored as u32), decode_depth_value(stored) as u32, "stored {stored:#06x}");
    }
}

#[test]
fn gpu_decodes_hand_picked_values() {
    let Some(ctx) = gpu_or_skip("gpu_decodes_hand_picked_values") else { return };
    // One row; with identity Rtilt the output's y is z = min(mm / 1000, 8). An odd count exercises the
    // half-filled last word.
    let stored: Vec<u16> = DECODE_CASES.iter().map(|&(s, _)| s).collect();
    let params = DepthPointsParams::new([500.0, 500.0, 4.0, 1.0], Mat3::IDENTITY, stored.len() as u32, 1);
    let got = depth_points_gpu(ctx, &params, &stored).unwrap();
    for (point, (stored, mm)) in got.iter().zip(DECODE_CASES) {
        if mm == 0 {
            assert_eq!(*point, [0.0; 4], "stored {stored:#06x} has no depth");
            continue;
        }
        let z = (mm as f32 / 1000.0).min(8.0);
        assert_eq!(point[3], 1.0, "stored {stored:#06x} has depth");
        assert!((point[1] - z).abs() <= GPU_TOL * z.max(1.0), "stored {stored:#06x}: z {} ≠ {z}", point[1]);
    }
}

#[test]
fn packing_puts_even_pixels_in_the_low_half() {
    assert_eq!(pack_stored_depth(&[0x1111, 0x2222, 0x3333]), vec![0x2222_1111, 0x0000_3333]);
    assert!(pack_stored_depth(&[]).is_empty());
}

#[test]
fn bad_jobs_are_errors_not_panics() {
    let (params, stored, _) = synthetic_3x2();
    assert!(depth_points_cpu(&params, &stored[..5]).is_err(), "5 values for a 3×2 image");
    let past_end = DepthPointsParams { first_pixel: 4, pixel_count: 3, ..params };
    assert!(depth_points_cpu(&past_end, &stored).is_err(), "pixels 4..7 of 6");
    let no_focal = DepthPointsParams { intrinsics: [0.0, 4.0, 2.0, 1.5], ..params };
    assert!(depth_points_cpu(&no_focal, &stored).is_err(), "fx = 0");
    if let Some(ctx) = gpu_or_skip("bad_jobs_are_errors_not_panics") {
        assert!(depth_points_gpu(ctx, &past_end, &stored).is_err());
    }
}

// ---------------------------------------------------------------------------------------------------------
// The real frame

#[test]
fn cpu_twin_matches_the_f64_point_cloud() {
    let frame = real_frame();
    let points = depth_points_cpu(&DepthPointsParams::from_frame(frame), &stored_depth_of(frame)).unwrap();
    let cloud = frame.point_cloud();
    assert!(cloud.len() > 100_000, "the frame should have most of its 561×427 pixels, has {}", cloud.len());
    assert_eq!(valid_count(&points), cloud.len(), "valid pixels");
    let width = frame.width();
    let mut worst = 0.0f32;
    for (reference, [col, row]) in cloud.points.iter().zip(&cloud.pixels) {
        let p = points[(row * width + col) as usize];
        assert_eq!(p[3], 1.0, "pixel ({col}, {row}) has depth");
        worst = worst.max((Vec3::new(p[0], p[1], p[2]) - *reference).abs().max_element());
    }
    eprintln!("CPU twin vs f64 point cloud: {} points, worst |Δ| = {worst:.3e} m", cloud.len());
    assert!(worst <= REFERENCE_TOL_M, "worst difference {worst:e} m");
}

#[test]
fn gpu_matches_cpu_twin_on_the_real_frame() {
    let Some(ctx) = gpu_or_skip("gpu_matches_cpu_twin_on_the_real_frame") else { return };
    let frame = real_frame();
    let params = DepthPointsParams::from_frame(frame);
    let stored = stored_depth_of(frame);
    let cpu = depth_points_cpu(&params, &stored).unwrap();
    let gpu = depth_points_gpu(ctx, &params, &stored).unwrap();
    assert_eq!(gpu.len(), (frame.width() * frame.height()) as usize);
    assert_eq!(valid_count(&gpu), valid_count(&cpu), "valid-pixel count");
    assert_eq!(valid_count(&gpu), frame.valid_depth(), "valid pixels are the pixels with depth");
    let (worst, mask_mismatches) = compare(&gpu, &cpu);
    let exact = gpu.iter().zip(&cpu).filter(|(g, c)| g == c).count();
    eprintln!(
        "GPU ({}) vs CPU twin: {} pixels, {exact} bit-identical, worst relative difference {worst:.3e}",
        ctx.adapter_summary(),
        gpu.len()
    );
    assert_eq!(mask_mismatches, 0, "validity mask differs at {mask_mismatches} pixels");
    assert!(gpu.iter().all(|p| p[3] == 1.0 || *p == [0.0; 4]), "missing pixels are all-zero");
    assert!(worst <= GPU_TOL, "worst relative difference {worst:e}");
}

#[test]
fn gpu_chunks_and_sub_jobs_match_the_whole_image() {
    let Some(ctx) = gpu_or_skip("gpu_chunks_and_sub_jobs_match_the_whole_image") else { return };
    let frame = real_frame();
    let params = DepthPointsParams::from_frame(frame);
    let stored = stored_depth_of(frame);
    let whole = depth_points_gpu(ctx, &params, &stored).unwrap();
    // An odd chunk size makes chunks start on odd pixels and mid-row.
    let chunked = depth_points_gpu_chunked(ctx, &params, &stored, 40_009).unwrap();
    assert!(chunked == whole, "7 chunks of 40 009 pixels must reproduce the single dispatch exactly");
    let job = DepthPointsParams { first_pixel: 100_001, pixel_count: 1_235, ..params };
    let sub = depth_points_gpu(ctx, &job, &stored).unwrap();
    assert!(sub[..] == whole[100_001..100_001 + 1_235], "a sub-job gives the same points as the whole image");
    let sub_cpu = depth_points_cpu(&job, &stored).unwrap();
    let (worst, mask_mismatches) = compare(&sub, &sub_cpu);
    assert!(mask_mismatches == 0 && worst <= GPU_TOL);
}

#[test]
fn gpu_errors_come_back_as_errors() {
    let Some(ctx) = gpu_or_skip("gpu_errors_come_back_as_errors") else { return };
    let spec = gpu::depth_points::KERNEL;
    // The shader's binding 0 is a uniform; declaring it as storage must fail pipeline creation.
    let wrong_layout = gpu::KernelSpec {
        bindings: &[gpu::Binding::StorageRead, gpu::Binding::StorageRead, gpu::Binding::StorageReadWrite],
        ..spec
    };
    let err = gpu::Kernel::new(&ctx.device, &wrong_layout).expect_err("layout mismatch");
    assert!(err.to_string().contains("depth_points"), "{err}");
    let no_entry = gpu::KernelSpec { entry_point: "main", ..spec };
    assert!(gpu::Kernel::new(&ctx.device, &no_entry).is_err(), "missing entry point");
    // A bind group missing a binding is a wgpu validation error, captured by `checked`.
    let kernel = &ctx.kernels.depth_points;
    let result = ctx.checked("incomplete bind group", || {
        let buffer = ctx.output_buffer("lonely", 16);
        Ok(ctx.bind_group(kernel, &[&buffer]))
    });
    let err = result.expect_err("a bind group with 1 of 3 bindings");
    assert!(err.to_string().contains("incomplete bind group"), "{err}");
    // Reading more than a buffer holds is refused before touching the GPU.
    let small = ctx.output_buffer("small", 16);
    assert!(ctx.read_buffer::<[f32; 4]>(&small, 2).is_err());
    assert_eq!(ctx.read_buffer::<[f32; 4]>(&small, 1).unwrap(), vec![[0.0; 4]], "new buffers are zeroed");
}

// ---------------------------------------------------------------------------------------------------------
// Adapter choice

#[test]
fn adapter_is_on_a_primary_backend() {
    let Some(ctx) = gpu_or_skip("adapter_is_on_a_primary_backend") else { return };
    let summary = ctx.adapter_summary();
    eprintln!("adapter: {summary}");
    assert!(
        matches!(ctx.info.backend, wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12),
        "{summary}"
    );
    assert!(summary.contains(&ctx.info.name) && summary.contains(&format!("{:?}", ctx.info.backend)));
    assert_eq!(ctx.limits.max_compute_workgroup_storage_size, 16384, "WebGPU default kept");
    assert!(ctx.limits.max_storage_buffer_binding_size >= 128 << 20);
    if let Ok(expected) = std::env::var("COG_GPU_EXPECT_ADAPTER") {
        assert!(summary.to_lowercase().contains(&expected.to_lowercase()), "expected '{expected}', got {summary}");
    }
}

#[test]
fn force_cpu_gives_no_context() {
    assert!(gpu::acquire(true).is_none());
}

/// Records log lines, for the child process of the test below.
struct Recorder(Mutex<Vec<(log::Level, String, String)>>);

impl log::Log for Recorder {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::Level::Warn
    }
    fn log(&self, record: &log::Record) {
        if self.enabled(record.metadata()) {
            let entry = (record.level(), record.target().to_string(), record.args().to_string());
            self.0.lock().unwrap_or_else(|p| p.into_inner()).push(entry);
        }
    }
    fn flush(&self) {}
}

const CHILD_ENV: &str = "COG_GPU_TEST_ACQUIRE_CHILD";

/// With WGPU_ADAPTER_NAME matching no adapter, acquire gives None and logs exactly one warning. The
/// environment variable must be set before the process touches wgpu and must not leak into the other
/// tests, so the test re-runs itself in a child process with the variable set; the child does the checks.
#[test]
fn unknown_adapter_name_gives_none_and_one_warning() {
    if std::env::var_os(CHILD_ENV).is_some() {
        static RECORDER: OnceLock<Recorder> = OnceLock::new();
        let recorder = RECORDER.get_or_init(|| Recorder(Mutex::new(Vec::new())));
        log::set_logger(recorder).expect("the child installs the only logger");
        log::set_max_level(log::LevelFilter::Warn);
        let ctx = gpu::acquire(false);
        let lines = recorder.0.lock().unwrap().clone();
        for (level, target, message) in &lines {
            println!("child log: {level} {target}: {message}");
        }
        assert!(ctx.is_none(), "WGPU_ADAPTER_NAME matches nothing, yet got {ctx:?}");
        assert_eq!(lines.len(), 1, "exactly one warning line, got {lines:?}");
        let (level, target, message) = &lines[0];
        assert_eq!(*level, log::Level::Warn);
        assert!(target.starts_with("cog_gpu"), "{target}");
        assert!(message.contains("CPU path") && message.contains("WGPU_ADAPTER_NAME"), "{message}");
        assert!(!message.contains('\n'), "one line: {message}");
        return;
    }
    let exe = std::env::current_exe().expect("test executable");
    let output = std::process::Command::new(exe)
        .args(["--exact", "unknown_adapter_name_gives_none_and_one_warning", "--nocapture", "--test-threads=1"])
        .env(CHILD_ENV, "1")
        .env("WGPU_ADAPTER_NAME", "nonexistent-adapter-for-cog-gpu-tests")
        .output()
        .expect("running the child test");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    eprintln!("{stdout}");
    assert!(output.status.success(), "child failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains("1 passed"), "the child must have run the test:\n{stdout}");
}

/// Read-backs from several threads at once on one context (as the engines' concurrent fast-path calls and
/// the tests sharing this context do) each return their own buffer's contents: a thread whose map callback
/// another thread's poll collected still waits for it (`GpuContext::wait_for_mapping`; before, such a
/// read-back failed with "not mapped after the GPU went idle": once in CI, and in one of two runs of this
/// test on lavapipe on the 2-core machine).
#[test]
fn concurrent_read_backs_on_one_context_each_get_their_buffer() {
    let Some(ctx) = gpu_or_skip("concurrent_read_backs_on_one_context_each_get_their_buffer") else { return };
    std::thread::scope(|scope| {
        for thread in 0..8u32 {
            scope.spawn(move || {
                for round in 0..100u32 {
                    let data: Vec<u32> = (0..1024).map(|i| i ^ (thread << 20) ^ (round << 12)).collect();
                    let buffer = ctx.storage_buffer("read-back test", &data);
                    let read: Vec<u32> = ctx.read_buffer(&buffer, data.len()).unwrap();
                    assert_eq!(read, data, "thread {thread}, round {round}");
                }
            });
        }
    });
}
