//! The `image_gradients` kernel: the image gradient of every pixel
//! ([`ImageGradients`](crate::features::preprocess::ImageGradients), paper §3.2), the GPU half of the frame's preprocessing with
//! [`normal_window`](super::normal_window).
//!
//! Shader: `shaders/image_gradients.wgsl`. Its CPU twin is [`table_gradient`], which the CPU path runs
//! ([`ImageGradients::compute`](crate::features::preprocess::ImageGradients::compute)); both look the channel differences and their squares up in
//! [`gradient_table`] (f32 values rounded on the CPU as [`pixel_gradient`](crate::features::preprocess::pixel_gradient)
//! rounds them), so the kernel does no float product a GPU compiler could fuse into a multiply-add, and its
//! gradients are the CPU's bit for bit.
//!
//! Input: the RGB bytes as stored (`image::RgbImage::as_raw`), which a WGSL `array<u32>` reads four to a
//! word, the first in the low bits (WebGPU buffers are little-endian); output: one `[f32; 2]` per pixel.

use bytemuck::{Pod, Zeroable};

use super::preprocess::preprocess_gpu;
use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::preprocess::gradient_table;
#[cfg(doc)]
use crate::features::preprocess::table_gradient;

/// The pipeline description, built into [`super::Kernels::image_gradients`].
pub const KERNEL: KernelSpec = KernelSpec {
    label: "image_gradients",
    source: include_str!("../../shaders/image_gradients.wgsl"),
    entry_point: "image_gradients",
    bindings: &[Binding::Uniform, Binding::StorageRead, Binding::StorageRead, Binding::StorageReadWrite],
};

/// Uniform parameters; twin of WGSL `struct ImageGradientsParams` in `shaders/image_gradients.wgsl`. A
/// dispatch covers the whole image (its bytes must fit one binding anyway).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct ImageGradientsParams {
    pub width: u32,
    pub height: u32,
    /// `width · height`.
    pub pixel_count: u32,
    pub pad: u32,
}

const _: () = assert!(std::mem::size_of::<ImageGradientsParams>() == 16);

/// The parameters of a `width × height` image, with a clear error for one the kernel cannot index (a byte
/// index past `u32`) or an empty one.
pub(crate) fn params_for(rgb: &image::RgbImage) -> Result<ImageGradientsParams> {
    let (width, height) = rgb.dimensions();
    let pixels = width as u64 * height as u64;
    if pixels == 0 || pixels * 3 > u32::MAX as u64 {
        return Err(Error::Input(format!(
            "image_gradients: a {width}×{height} image is outside what the kernel indexes (1 to {} pixels)",
            u32::MAX / 3
        )));
    }
    Ok(ImageGradientsParams { width, height, pixel_count: pixels as u32, pad: 0 })
}

/// The [`gradient_table`] on the GPU: uploaded once per context (512 KiB), shared by every frame.
pub(crate) fn resident_table(ctx: &GpuContext) -> &wgpu::Buffer {
    ctx.gradient_table.get_or_init(|| ctx.storage_buffer("image_gradients table", gradient_table()))
}

/// The gradients of every pixel computed on the GPU, row-major: equal bit for bit to
/// [`ImageGradients::compute`](crate::features::preprocess::ImageGradients::compute) (which runs the twin
/// [`table_gradient`] over the pixels), in one submission with the context's pooled buffers ([`preprocess_gpu`]).
pub fn image_gradients_gpu(ctx: &GpuContext, rgb: &image::RgbImage) -> Result<Vec<[f32; 2]>> {
    Ok(preprocess_gpu(ctx, Some(rgb), None)?.gradients.unwrap_or_default())
}
