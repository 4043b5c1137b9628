//! The `normal_window` kernel: for every pixel with a point, the plane-fit neighbours of
//! [`NormalSearch::Window`](crate::features::preprocess::NormalSearch) (the 15 nearest points among the
//! 7×7 pixels around it) as a bit mask of window slots.
//!
//! Shader: `shaders/normal_window.wgsl`. Its CPU twin is
//! [`window_neighbour_mask`], which the CPU path of
//! `detect --normals window` runs: distances are compared as integers, so both choose the same neighbours
//! bit for bit, and the plane fits that follow
//! ([`normals_from_window_masks`](crate::features::preprocess::normals_from_window_masks), double precision)
//! run on the CPU for both paths — the normals, and so the detections, are the same on either.
//!
//! Input: the frame's points laid out by pixel ([`point_grid`](crate::features::preprocess::point_grid));
//! output: one `[u32; 2]` mask per pixel. The GPU path runs it beside `image_gradients` in one submission
//! ([`super::preprocess`]).

use bytemuck::{Pod, Zeroable};

use super::preprocess::{preprocess_gpu, PointGrid};
use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::preprocess::window_neighbour_mask;

/// The pipeline description, built into [`super::Kernels::normal_window`].
pub const KERNEL: KernelSpec = KernelSpec {
    label: "normal_window",
    source: include_str!("../../shaders/normal_window.wgsl"),
    entry_point: "normal_window",
    bindings: &[Binding::Uniform, Binding::StorageRead, Binding::StorageReadWrite],
};

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
    pub(crate) fn check(&self, grid: &[[f32; 4]]) -> Result<()> {
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

/// The masks of every pixel computed on the GPU; same contract as [`normal_window_cpu`], in one
/// submission with the context's pooled buffers ([`preprocess_gpu`]).
pub fn normal_window_gpu(ctx: &GpuContext, grid: &[[f32; 4]], width: u32, height: u32) -> Result<Vec<[u32; 2]>> {
    let output = preprocess_gpu(ctx, None, Some(PointGrid { grid, width, height }))?;
    Ok(output.masks.unwrap_or_default())
}
