//! The GPU half of a frame's preprocessing in one submission: the image gradients
//! ([`super::image_gradients`]) and, for the window search, the normals' neighbour masks
//! ([`super::normal_window`]) — inputs in one pooled upload, both kernels in one command
//! buffer, both outputs in one pooled buffer read back once. The buffers are the context's pooled ones
//! ([`GpuContext::pool`]): reused from frame to frame, none created per dispatch once they have grown to
//! the frame size; the gradients' table is resident (uploaded once per context).
//!
//! Each kernel's CPU twin gives its output bit for bit ([`table_gradient`](crate::features::preprocess::table_gradient),
//! [`window_neighbour_mask`](crate::features::preprocess::window_neighbour_mask)); the plane fits and the
//! k-d tree search stay on the CPU ([`gradients_and_normals_gpu`]).

use glam::Vec3;

use super::image_gradients::{self, ImageGradientsParams};
use super::normal_window::NormalWindowParams;
use super::{Arena, GpuContext};
use crate::error::{Error, Result};
use crate::features::preprocess::{
    estimate_normals, estimate_normals_of, normals_from_window_masks, point_grid, ImageGradients, NormalSearch,
    WIDE_NORMAL_NEIGHBOURS,
};
use crate::frame::PointCloud;

/// A frame's points laid out by pixel ([`point_grid`]) and the image's width and height.
#[derive(Clone, Copy)]
pub struct PointGrid<'a> {
    pub grid: &'a [[f32; 4]],
    pub width: u32,
    pub height: u32,
}

/// What [`preprocess_gpu`] read back: the gradients of every pixel when an image was given, the masks of
/// every pixel when a grid was.
#[derive(Debug, Default)]
pub struct PreprocessOutput {
    pub gradients: Option<Vec<[f32; 2]>>,
    pub masks: Option<Vec<[u32; 2]>>,
}

/// Bytes of a gradient (`vec2<f32>`) and of a mask (`vec2<u32>`) in the output buffer.
const GRADIENT_BYTES: u64 = 8;
const MASK_BYTES: u64 = 8;

/// Runs the `image_gradients` kernel on `rgb` and the `normal_window` kernel on `grid` (either may be
/// left out) in one submission with pooled buffers, and reads both outputs back at once.
pub fn preprocess_gpu(
    ctx: &GpuContext,
    rgb: Option<&image::RgbImage>,
    grid: Option<PointGrid>,
) -> Result<PreprocessOutput> {
    let gradient_params = rgb.map(image_gradients::params_for).transpose()?;
    let window_params = grid
        .map(|g| {
            let params = NormalWindowParams {
                width: g.width,
                height: g.height,
                first_pixel: 0,
                pixel_count: g.width.saturating_mul(g.height),
            };
            params.check(g.grid).map(|()| params)
        })
        .transpose()?;
    // The bytes as stored: the shader's `array<u32>` reads them four to a word, the first in the low bits.
    let rgb_bytes: &[u8] = rgb.map_or(&[], |image| image.as_raw());
    let grid_points: &[[f32; 4]] = grid.map_or(&[], |g| g.grid);
    let pixels = |n: Option<u32>| u64::from(n.unwrap_or(0));
    let gradient_count = pixels(gradient_params.map(|p| p.pixel_count));
    let mask_count = pixels(window_params.map(|p| p.pixel_count));
    if gradient_count == 0 && mask_count == 0 {
        return Ok(PreprocessOutput::default());
    }
    // Where everything lies: the inputs and the outputs each in one buffer, every piece at an offset
    // aligned for binding; the two uniform records at the uniform alignment.
    let storage_align = ctx.limits.min_storage_buffer_offset_alignment;
    let uniform_stride = (std::mem::size_of::<ImageGradientsParams>() as u64)
        .next_multiple_of(u64::from(ctx.limits.min_uniform_buffer_offset_alignment));
    let grid_bytes = std::mem::size_of_val(grid_points) as u64;
    let mut inputs = Arena::new(storage_align);
    let (rgb_at, grid_at) = (inputs.place(rgb_bytes.len() as u64), inputs.place(grid_bytes));
    let mut outputs = Arena::new(storage_align);
    let (gradients_at, masks_at) =
        (outputs.place(gradient_count * GRADIENT_BYTES), outputs.place(mask_count * MASK_BYTES));
    let binding = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    if inputs.len > binding || outputs.len > binding {
        return Err(Error::Gpu(format!(
            "preprocessing: a frame's {} input and {} output bytes exceed the device's {binding}-byte storage binding",
            inputs.len, outputs.len
        )));
    }
    let mut uploads = Arena::new(wgpu::COPY_BUFFER_ALIGNMENT as u32);
    let (params_region, inputs_region) = (uploads.place(2 * uniform_stride), uploads.place(inputs.len));
    ctx.checked("preprocessing", || {
        let mut pool = ctx.pool();
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        let max_size = ctx.limits.max_buffer_size;
        let input_buffer = pool.buffer(&ctx.device, "preprocess inputs", storage, inputs.len, max_size);
        let output_buffer = pool.buffer(&ctx.device, "preprocess outputs", storage, outputs.len, max_size);
        let uniform = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        let params_buffer = pool.buffer(&ctx.device, "preprocess params", uniform, 2 * uniform_stride, max_size);
        let read = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let staging = pool.buffer(&ctx.device, "preprocess staging", read, outputs.len, max_size);
        let upload = ctx.mapped_upload(&mut pool, "preprocess uploads", uploads.len)?;
        {
            let mut image = upload
                .get_mapped_range_mut(..uploads.len.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT).max(4))
                .map_err(|e| Error::Gpu(format!("writing the mapped upload buffer: {e}")))?;
            let mut put = |at: u64, bytes: &[u8]| {
                image.slice(at as usize..at as usize + bytes.len()).copy_from_slice(bytes);
            };
            if let Some(params) = &gradient_params {
                put(params_region, bytemuck::bytes_of(params));
            }
            if let Some(params) = &window_params {
                put(params_region + uniform_stride, bytemuck::bytes_of(params));
            }
            put(inputs_region + rgb_at, rgb_bytes);
            put(inputs_region + grid_at, bytemuck::cast_slice(grid_points));
        }
        pool.unmap_upload("preprocess uploads", &upload);
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("preprocessing") });
        encoder.copy_buffer_to_buffer(&upload, params_region, &params_buffer, 0, Some(2 * uniform_stride));
        let input_copy = inputs.len.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        if input_copy > 0 {
            encoder.copy_buffer_to_buffer(&upload, inputs_region, &input_buffer, 0, Some(input_copy));
        }
        let range = |at: u64, bytes: u64| bytes.max(4).next_multiple_of(4).min(input_buffer.size() - at);
        if let Some(params) = gradient_params.as_ref().filter(|p| p.pixel_count > 0) {
            let kernel = &ctx.kernels.image_gradients;
            let bind_group = ctx.bind_group_ranges(
                kernel,
                &[
                    (&params_buffer, 0, std::mem::size_of::<ImageGradientsParams>() as u64),
                    (&input_buffer, rgb_at, range(rgb_at, rgb_bytes.len() as u64)),
                    (image_gradients::resident_table(ctx), 0, image_gradients::resident_table(ctx).size()),
                    (&output_buffer, gradients_at, gradient_count * GRADIENT_BYTES),
                ],
            );
            ctx.encode_dispatch(&mut encoder, kernel, &bind_group, params.pixel_count)?;
        }
        if let Some(params) = window_params.as_ref().filter(|p| p.pixel_count > 0) {
            let kernel = &ctx.kernels.normal_window;
            let bind_group = ctx.bind_group_ranges(
                kernel,
                &[
                    (&params_buffer, uniform_stride, std::mem::size_of::<NormalWindowParams>() as u64),
                    (&input_buffer, grid_at, range(grid_at, grid_bytes)),
                    (&output_buffer, masks_at, mask_count * MASK_BYTES),
                ],
            );
            ctx.encode_dispatch(&mut encoder, kernel, &bind_group, params.pixel_count)?;
        }
        let words: Vec<u32> = ctx.read_buffer_through(encoder, &output_buffer, (outputs.len / 4) as usize, &staging)?;
        let part = |at: u64, count: u64| -> Vec<[u32; 2]> {
            let start = (at / 4) as usize;
            words[start..start + 2 * count as usize].chunks_exact(2).map(|w| [w[0], w[1]]).collect()
        };
        Ok(PreprocessOutput {
            gradients: gradient_params
                .map(|_| part(gradients_at, gradient_count).into_iter().map(|w| w.map(f32::from_bits)).collect()),
            masks: window_params.map(|_| part(masks_at, mask_count)),
        })
    })
}

/// A frame's image gradients and normals with the GPU's kernels: the gradients by `image_gradients`, and
/// for [`NormalSearch::Window`] the neighbours by `normal_window`, in one submission ([`preprocess_gpu`]);
/// the plane fits (and a k-d tree search) on the CPU. Equal bit for bit to the CPU path's
/// ([`ImageGradients::compute`], [`crate::features::preprocess::window_normals`] or [`estimate_normals`]).
pub fn gradients_and_normals_gpu(
    ctx: &GpuContext,
    rgb: &image::RgbImage,
    cloud: &PointCloud,
    search: NormalSearch,
) -> Result<(ImageGradients, Vec<Vec3>)> {
    let (width, height) = rgb.dimensions();
    let grid = match search {
        NormalSearch::Window => Some(point_grid([width, height], &cloud.points, &cloud.pixels)),
        NormalSearch::KdTree | NormalSearch::KdTreeWide => None,
    };
    let output = preprocess_gpu(ctx, Some(rgb), grid.as_deref().map(|grid| PointGrid { grid, width, height }))?;
    let gradients = output.gradients.unwrap_or_default().into_iter().map(glam::Vec2::from).collect();
    let image = ImageGradients { width, height, gradients };
    let normals = match (&grid, output.masks) {
        (Some(grid), Some(all)) => {
            let masks: Vec<[u32; 2]> =
                cloud.pixels.iter().map(|&[col, row]| all[(row * width + col) as usize]).collect();
            normals_from_window_masks(grid, width, &cloud.pixels, &masks)
        }
        _ => match search {
            NormalSearch::KdTreeWide => estimate_normals_of(&cloud.points, WIDE_NORMAL_NEIGHBOURS),
            _ => estimate_normals(&cloud.points),
        },
    };
    Ok((image, normals))
}
