//! Helpers shared by the GPU test files (`mod common;` in each).

use cog_gpu::gpu::GpuContext;

/// The GPU context for a GPU test: `None` (the test skips, saying so) only when there is no adapter and
/// `COG_GPU_SKIP_GPU_TESTS=1`; without that variable a missing adapter fails the test, so that CI cannot
/// pass without running the GPU tests.
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
