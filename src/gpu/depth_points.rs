//! The `depth_points` kernel: raw depth PNG values → upright points, one `[x, y, z, w]` per pixel.
//!
//! Shader: `shaders/depth_points.wgsl`. The CPU twin below reads like it (same names, same f32 operation
//! order): `depth_points_main` is the entry point, looping `depth_point` over the invocations.
//!
//! Conventions (those of [`crate::frame`]): `mm = ((d >> 3) | (d << 13)) & 0xffff`, `z = min(mm / 1000, 8)`,
//! `u = col + 1`, `v = row + 1`, `x = (u − cx)·z/fx`, `y = (v − cy)·z/fy`, `p = Rtilt·(x, z, −y)`.
//! A pixel with depth gives `(p, 1)`, a pixel without gives `(0, 0, 0, 0)`, so `w` is the validity mask.
//!
//! Input layout: the stored 16-bit values are packed two per u32 ([`pack_stored_depth`]), halving the
//! upload compared with one value per word.

use bytemuck::{Pod, Zeroable};
use glam::Mat3;

use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::frame::{encode_depth_value, Frame, MAX_DEPTH_M};

/// The pipeline description, built into [`super::Kernels::depth_points`].
pub const KERNEL: KernelSpec = KernelSpec {
    label: "depth_points",
    source: include_str!("../../shaders/depth_points.wgsl"),
    entry_point: "depth_points",
    bindings: &[Binding::Uniform, Binding::StorageRead, Binding::StorageReadWrite],
};

/// Bytes of one output point (`vec4<f32>`).
const POINT_BYTES: u64 = 16;

/// Uniform parameters; twin of WGSL `struct DepthPointsParams` in `shaders/depth_points.wgsl`.
///
/// Rtilt travels as three columns padded to vec4 (WGSL uniform vec3/mat3 columns are 16-byte aligned).
/// A job covers pixels `first_pixel .. first_pixel + pixel_count` of the row-major image;
/// [`DepthPointsParams::new`] and [`DepthPointsParams::from_frame`] make it the whole image.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct DepthPointsParams {
    pub rtilt_col0: [f32; 4],
    pub rtilt_col1: [f32; 4],
    pub rtilt_col2: [f32; 4],
    /// (fx, fy, cx, cy), 1-based pixel convention.
    pub intrinsics: [f32; 4],
    pub width: u32,
    pub height: u32,
    pub first_pixel: u32,
    pub pixel_count: u32,
}

const _: () = assert!(std::mem::size_of::<DepthPointsParams>() == 80);

impl DepthPointsParams {
    /// Parameters for the whole `width × height` image.
    pub fn new(intrinsics: [f32; 4], rtilt: Mat3, width: u32, height: u32) -> Self {
        let col = |c: glam::Vec3| c.extend(0.0).to_array();
        Self {
            rtilt_col0: col(rtilt.x_axis),
            rtilt_col1: col(rtilt.y_axis),
            rtilt_col2: col(rtilt.z_axis),
            intrinsics,
            width,
            height,
            first_pixel: 0,
            pixel_count: width.saturating_mul(height),
        }
    }

    /// Parameters for the whole image of `frame` (its intrinsics and f32 Rtilt).
    pub fn from_frame(frame: &Frame) -> Self {
        Self::new(frame.intrinsics(), frame.rtilt(), frame.width(), frame.height())
    }

    /// Checks the job against the image: a clear error instead of an out-of-bounds read.
    fn check(&self, stored_depth: &[u16]) -> Result<()> {
        let pixels = self.width as u64 * self.height as u64;
        if pixels > u32::MAX as u64 {
            return Err(Error::Input(format!(
                "depth_points: {}×{} image has too many pixels",
                self.width, self.height
            )));
        }
        if stored_depth.len() as u64 != pixels {
            return Err(Error::Input(format!(
                "depth_points: {} depth values for a {}×{} image",
                stored_depth.len(),
                self.width,
                self.height
            )));
        }
        if self.first_pixel as u64 + self.pixel_count as u64 > pixels {
            return Err(Error::Input(format!(
                "depth_points: pixels {}..{} lie outside the {pixels}-pixel image",
                self.first_pixel,
                self.first_pixel as u64 + self.pixel_count as u64
            )));
        }
        let [fx, fy, ..] = self.intrinsics;
        if !(fx.is_finite() && fy.is_finite() && fx != 0.0 && fy != 0.0)
            || self.intrinsics.iter().any(|v| !v.is_finite())
        {
            return Err(Error::Input(format!("depth_points: bad intrinsics {:?}", self.intrinsics)));
        }
        Ok(())
    }

    /// The same job restricted to its pixels `start .. start + count`.
    fn sub_job(&self, start: u32, count: u32) -> Self {
        Self { first_pixel: self.first_pixel + start, pixel_count: count, ..*self }
    }
}

/// The stored (PNG) depth values of a frame: its decoded millimetres re-encoded.
pub fn stored_depth_of(frame: &Frame) -> Vec<u16> {
    frame.depth_mm.iter().map(|&mm| encode_depth_value(mm)).collect()
}

/// Packs 16-bit values two per word: value `2k` in the low half of word `k`, `2k + 1` in the high half.
pub fn pack_stored_depth(values: &[u16]) -> Vec<u32> {
    values.chunks(2).map(|pair| pair[0] as u32 | (pair.get(1).copied().unwrap_or(0) as u32) << 16).collect()
}

// ---------------------------------------------------------------------------------------------------------
// CPU twin of shaders/depth_points.wgsl

/// Undoes the toolbox's 3-bit left rotation of the 16-bit millimetre value.
pub fn decode_depth_mm(stored: u32) -> u32 {
    ((stored >> 3) | (stored << 13)) & 0xffff
}

/// The stored 16-bit value of the job's pixel `local`.
fn stored_value(stored_depth: &[u32], local: u32) -> u32 {
    let word = stored_depth[(local >> 1) as usize];
    (word >> ((local & 1) * 16)) & 0xffff
}

/// One invocation: the point of the job's pixel `local`.
fn depth_point(params: &DepthPointsParams, stored_depth: &[u32], local: u32) -> [f32; 4] {
    let pixel = params.first_pixel + local;
    let col = pixel % params.width;
    let row = pixel / params.width;
    let mm = decode_depth_mm(stored_value(stored_depth, local));
    if mm == 0 {
        return [0.0, 0.0, 0.0, 0.0];
    }
    let z = (mm as f32 / 1000.0).min(MAX_DEPTH_M);
    // 1-based pixel coordinates.
    let u = (col + 1) as f32;
    let v = (row + 1) as f32;
    let [fx, fy, cx, cy] = params.intrinsics;
    let x = (u - cx) * z / fx;
    let y = (v - cy) * z / fy;
    // p = Rtilt·(x, z, −y), column by column as in the shader.
    let (c0, c1, c2) = (params.rtilt_col0, params.rtilt_col1, params.rtilt_col2);
    let p = [0, 1, 2].map(|k| c0[k] * x + c1[k] * z + c2[k] * (-y));
    [p[0], p[1], p[2], 1.0]
}

/// The entry point `depth_points`: every invocation of the job, in order.
fn depth_points_main(params: &DepthPointsParams, stored_depth: &[u32], points: &mut [[f32; 4]]) {
    for local in 0..params.pixel_count {
        points[local as usize] = depth_point(params, stored_depth, local);
    }
}

/// CPU twin: the points of the job's pixels (`params.pixel_count` of them) from the image's stored depth
/// values (`width × height`, row-major, as in the PNG).
pub fn depth_points_cpu(params: &DepthPointsParams, stored_depth: &[u16]) -> Result<Vec<[f32; 4]>> {
    params.check(stored_depth)?;
    let first = params.first_pixel as usize;
    let words = pack_stored_depth(&stored_depth[first..first + params.pixel_count as usize]);
    let mut points = vec![[0.0f32; 4]; params.pixel_count as usize];
    depth_points_main(params, &words, &mut points);
    Ok(points)
}

// ---------------------------------------------------------------------------------------------------------
// GPU

/// The largest job one dispatch can take: the output buffer (16 bytes a pixel) within the storage binding
/// and buffer size limits.
pub fn max_pixels_per_dispatch(ctx: &GpuContext) -> u32 {
    let bytes = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    (bytes / POINT_BYTES).min(u32::MAX as u64) as u32
}

/// The points of the job's pixels computed on the GPU; same contract as [`depth_points_cpu`]. Jobs larger
/// than [`max_pixels_per_dispatch`] are split into consecutive dispatches.
pub fn depth_points_gpu(ctx: &GpuContext, params: &DepthPointsParams, stored_depth: &[u16]) -> Result<Vec<[f32; 4]>> {
    depth_points_gpu_chunked(ctx, params, stored_depth, max_pixels_per_dispatch(ctx))
}

/// [`depth_points_gpu`] with at most `chunk_pixels` pixels per dispatch (clamped to
/// [`max_pixels_per_dispatch`]); smaller chunks bound the GPU memory of one dispatch.
pub fn depth_points_gpu_chunked(
    ctx: &GpuContext,
    params: &DepthPointsParams,
    stored_depth: &[u16],
    chunk_pixels: u32,
) -> Result<Vec<[f32; 4]>> {
    params.check(stored_depth)?;
    let chunk_pixels = chunk_pixels.clamp(1, max_pixels_per_dispatch(ctx).max(1));
    let kernel = &ctx.kernels.depth_points;
    let mut points = Vec::with_capacity(params.pixel_count as usize);
    let mut start = 0u32;
    while start < params.pixel_count {
        let count = chunk_pixels.min(params.pixel_count - start);
        let job = params.sub_job(start, count);
        let first = job.first_pixel as usize;
        let words = pack_stored_depth(&stored_depth[first..first + count as usize]);
        let chunk = ctx.checked("depth_points", || {
            let uniform = ctx.uniform_buffer("depth_points params", &job);
            let input = ctx.storage_buffer("depth_points stored depth", &words);
            let output = ctx.output_buffer("depth_points points", count as u64 * POINT_BYTES);
            let bind_group = ctx.bind_group(kernel, &[&uniform, &input, &output]);
            ctx.dispatch_and_read::<[f32; 4]>(kernel, &bind_group, count, &output, count as usize)
        })?;
        points.extend_from_slice(&chunk);
        start += count;
    }
    Ok(points)
}

/// The job on the GPU when a context is given, else on the CPU.
pub fn depth_points(
    ctx: Option<&GpuContext>,
    params: &DepthPointsParams,
    stored_depth: &[u16],
) -> Result<Vec<[f32; 4]>> {
    match ctx {
        Some(ctx) => depth_points_gpu(ctx, params, stored_depth),
        None => depth_points_cpu(params, stored_depth),
    }
}
