//! The `normal_window` kernel: for every pixel with a point, the plane-fit neighbours of
//! [`NormalSearch::Window`](crate::features::preprocess::NormalSearch) (the 15 nearest points among the
//! 7×7 pixels around it) as a bit mask of window slots.
//!
//! Shader: `shaders/normal_window.wgsl`. Its CPU twin is
//! [`window_neighbour_mask`], which the CPU path of
//! `detect --normals window` runs: distances are compared as integers, so both choose the same neighbours
//! bit for bit, and the plane fits that follow
//! ([`normals_from_window_masks`], double precision)
//! run on the CPU for both paths — the normals, and so the detections, are the same on either.
//!
//! Input: the frame's points laid out by pixel ([`point_grid`]); output: one `[u32; 2]` mask per pixel.

use bytemuck::{Pod, Zeroable};

use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::preprocess::{normals_from_window_masks, point_grid, window_neighbour_mask};

/// The pipeline description, built into [`super::Kernels::normal_window`].
pub const KERNEL: KernelSpec = KernelSpec {
    label: "normal_window",
    source: include_str!("../../shaders/normal_window.wgsl"),
    entry_point: "normal_window",
    bindings: &[Binding::Uniform, Binding::StorageRead, Binding::StorageReadWrite],
};

/// Bytes of one output mask (`vec2<u32>`).
const MASK_BYTES: u64 = 8;
/// Bytes of one input pixel (`vec4<f32>`).
const GRID_BYTES: u64 = 16;

/// Uniform parameters; twin of WGSL `struct NormalWindowParams` in `shaders/normal_window.wgsl`. A job
/// covers the masks of pixels `first_pixel .. first_pixel + pixel_count` of the row-major image; every job
/// reads the whole grid (a window reaches three rows beyond its pixel).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct NormalWindowParams {
    pub width: u32,
    pub height: u32,
    pub first_pixel: u32,
    pub pixel_count: u32,
}

const _: () = assert!(std::mem::size_of::<NormalWindowParams>() == 16);

impl NormalWindowParams {
    /// Checks the grid against the image size: a clear error instead of an out-of-bounds read.
    fn check(&self, grid: &[[f32; 4]]) -> Result<()> {
        let pixels = self.width as u64 * self.height as u64;
        if grid.len() as u64 != pixels || pixels > u32::MAX as u64 {
            return Err(Error::Input(format!(
                "normal_window: {} grid pixels for a {}×{} image",
                grid.len(),
                self.width,
                self.height
            )));
        }
        if self.first_pixel as u64 + self.pixel_count as u64 > pixels {
            return Err(Error::Input(format!(
                "normal_window: pixels {}..{} lie outside the {pixels}-pixel image",
                self.first_pixel,
                self.first_pixel as u64 + self.pixel_count as u64
            )));
        }
        Ok(())
    }
}

/// CPU twin of the whole kernel: the masks of every pixel of the `width × height` grid (the entry point's
/// loop over its invocations).
pub fn normal_window_cpu(grid: &[[f32; 4]], width: u32, height: u32) -> Result<Vec<[u32; 2]>> {
    let params = NormalWindowParams { width, height, first_pixel: 0, pixel_count: width * height };
    params.check(grid)?;
    Ok((0..params.pixel_count)
        .map(|pixel| window_neighbour_mask(grid, width, height, pixel % width, pixel / width))
        .collect())
}

/// The largest job one dispatch can take: the grid (read whole by every job) and the output within the
/// storage binding and buffer size limits.
fn check_fits(ctx: &GpuContext, pixels: u64) -> Result<()> {
    let bytes = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    if pixels * GRID_BYTES > bytes {
        return Err(Error::Gpu(format!(
            "normal_window: a {pixels}-pixel grid ({} bytes) exceeds the device's {bytes}-byte storage binding",
            pixels * GRID_BYTES
        )));
    }
    Ok(())
}

/// The masks of every pixel computed on the GPU; same contract as [`normal_window_cpu`], in one dispatch
/// (a grid that fits a binding has masks that do: 8 bytes a pixel against 16).
pub fn normal_window_gpu(ctx: &GpuContext, grid: &[[f32; 4]], width: u32, height: u32) -> Result<Vec<[u32; 2]>> {
    let params = NormalWindowParams { width, height, first_pixel: 0, pixel_count: width.saturating_mul(height) };
    params.check(grid)?;
    check_fits(ctx, grid.len() as u64)?;
    if grid.is_empty() {
        return Ok(Vec::new());
    }
    let kernel = &ctx.kernels.normal_window;
    let count = params.pixel_count;
    ctx.checked("normal_window", || {
        let uniform = ctx.uniform_buffer("normal_window params", &params);
        let input = ctx.storage_buffer("normal_window grid", grid);
        let output = ctx.output_buffer("normal_window masks", count as u64 * MASK_BYTES);
        let bind_group = ctx.bind_group(kernel, &[&uniform, &input, &output]);
        ctx.dispatch_and_read::<[u32; 2]>(kernel, &bind_group, count, &output, count as usize)
    })
}

/// Normals of [`NormalSearch::Window`](crate::features::preprocess::NormalSearch) with the neighbour search
/// on the GPU: the points at `pixels` of a `image_size` image, one normal each, equal bit for bit to
/// [`window_normals`](crate::features::preprocess::window_normals) on the CPU.
pub fn window_normals_gpu(
    ctx: &GpuContext,
    image_size: [u32; 2],
    points: &[glam::Vec3],
    pixels: &[[u32; 2]],
) -> Result<Vec<glam::Vec3>> {
    let [width, height] = image_size;
    let grid = point_grid(image_size, points, pixels);
    let all = normal_window_gpu(ctx, &grid, width, height)?;
    let masks: Vec<[u32; 2]> = pixels.iter().map(|&[col, row]| all[(row * width + col) as usize]).collect();
    Ok(normals_from_window_masks(&grid, width, pixels, &masks))
}
