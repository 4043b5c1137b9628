//! The feature kernel (`shaders/features.wgsl`): features or fused scores of many hypotheses at once.
//! CPU twin: [`crate::features::cpu`] (same stages; the definitions are in its module doc).
//!
//! Hypotheses are grouped by yaw; each yaw's point records and bucket table are uploaded once and its
//! hypotheses are dispatched in chunks of at most [`MAX_CHUNK`] (one workgroup of 64 invocations per
//! hypothesis, one invocation per voxel column), fewer in feature-writing mode so the output stays within
//! the device's storage-binding limit. Results come back in the order of the input hypotheses.

use bytemuck::{Pod, Zeroable};

use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::cpu::HypothesisRecord;
use crate::features::feature_layout::{FeatureLayout, MAX_COLUMNS, MAX_GRID_Z};
use crate::features::out_of_view::{add_out_of_view_scores, widen_with_out_of_view};
use crate::features::{FeatureScene, Hypothesis};

/// The kernel's spec (registered in [`super::Kernels`]).
pub const KERNEL: KernelSpec = KernelSpec {
    label: "features",
    source: include_str!("../../shaders/features.wgsl"),
    entry_point: "main",
    bindings: &[
        Binding::Uniform,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageReadWrite,
        Binding::StorageReadWrite,
    ],
};

/// Weight vectors scored per dispatch (the shader's `MAX_WEIGHTS`); more are done in several passes.
pub const MAX_WEIGHTS: usize = 8;
/// Largest number of hypotheses per dispatch.
pub const MAX_CHUNK: usize = 1 << 16;

/// Mirrors `Params` in the shader.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct Params {
    grid: [u32; 4],
    job: [u32; 4],
    buckets: [u32; 4],
    bucket_geom: [f32; 4],
    intrinsics: [f32; 4],
    m0: [f32; 4],
    m1: [f32; 4],
    m2: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<Params>() == 128);
const _: () = assert!(std::mem::size_of::<HypothesisRecord>() == 64);
const _: () = assert!(std::mem::size_of::<crate::features::PointRecord>() == 32);

fn group_bits(layout: &FeatureLayout) -> u32 {
    let g = layout.groups;
    u32::from(g.density) | (u32::from(g.normals) << 1) | (u32::from(g.cog) << 2) | (u32::from(g.view) << 3)
}

fn check_layout(layout: &FeatureLayout) -> Result<()> {
    layout.validate()?;
    let g = layout.grid();
    debug_assert!(g[2] <= MAX_GRID_Z && g[0] * g[1] <= MAX_COLUMNS);
    Ok(())
}

/// Indices of `hypotheses` per yaw.
fn by_yaw(scene: &FeatureScene, hypotheses: &[Hypothesis]) -> Result<Vec<Vec<usize>>> {
    let mut groups = vec![Vec::new(); scene.yaws.len()];
    for (n, h) in hypotheses.iter().enumerate() {
        groups
            .get_mut(h.yaw_index as usize)
            .ok_or_else(|| {
                Error::Input(format!(
                    "hypothesis {n} has yaw index {} but the scene has {} yaws",
                    h.yaw_index,
                    scene.yaws.len()
                ))
            })?
            .push(n);
    }
    Ok(groups)
}

enum Mode<'a> {
    Write,
    Score(&'a [Vec<f32>]),
}

/// Runs the kernel over every hypothesis; returns (out rows in input order, inside counts).
fn run(
    ctx: &GpuContext,
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    mode: Mode,
) -> Result<(Vec<f32>, Vec<u32>)> {
    check_layout(layout)?;
    let dim = layout.dim();
    let kernel = &ctx.kernels.features;
    let (row_len, weight_data, weight_count) = match &mode {
        Mode::Write => (dim, vec![0.0f32], 0usize),
        Mode::Score(w) => {
            if w.len() > MAX_WEIGHTS {
                return Err(Error::Input(format!("{} weight vectors in one pass; at most {MAX_WEIGHTS}", w.len())));
            }
            for (n, v) in w.iter().enumerate() {
                if v.len() != dim {
                    return Err(Error::Input(format!(
                        "weight vector {n} has {} entries; the layout has {dim}",
                        v.len()
                    )));
                }
            }
            (w.len(), w.iter().flatten().copied().collect(), w.len())
        }
    };
    let mut out = vec![0.0f32; hypotheses.len() * row_len];
    let mut inside = vec![0u32; hypotheses.len()];
    if hypotheses.is_empty() || row_len == 0 {
        return Ok((out, inside));
    }
    let max_binding = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    let chunk = MAX_CHUNK.min((max_binding / (row_len as u64 * 4)).max(1) as usize);
    let g = layout.grid();
    let [fx, fy, _, _] = scene.pre.camera.intrinsics;
    ctx.checked("feature kernel", || {
        let weights = ctx.storage_buffer("feature weights", &weight_data);
        for (yaw_index, members) in by_yaw(scene, hypotheses)?.into_iter().enumerate() {
            if members.is_empty() {
                continue;
            }
            let grid = &scene.yaws[yaw_index];
            let points = ctx.storage_buffer("feature points", &grid.records);
            let cell_start = ctx.storage_buffer("feature buckets", &grid.cell_start);
            let m = grid.camera_from_rotated;
            for part in members.chunks(chunk) {
                let records: Vec<HypothesisRecord> =
                    part.iter().map(|&n| HypothesisRecord::new(scene, layout, &hypotheses[n])).collect();
                let params = Params {
                    grid: [g[0], g[1], g[2], dim as u32],
                    job: [
                        part.len() as u32,
                        weight_count as u32,
                        matches!(mode, Mode::Score(_)) as u32,
                        group_bits(layout),
                    ],
                    buckets: [grid.cells[0], grid.cells[1], 0, 0],
                    bucket_geom: [grid.origin[0], grid.origin[1], grid.inv_step, 0.0],
                    intrinsics: [fx, fy, 0.0, 0.0],
                    m0: m.x_axis.extend(0.0).to_array(),
                    m1: m.y_axis.extend(0.0).to_array(),
                    m2: m.z_axis.extend(0.0).to_array(),
                };
                let uniform = ctx.uniform_buffer("feature params", &params);
                let hyps = ctx.storage_buffer("feature hypotheses", &records);
                let out_buf = ctx.output_buffer("feature out", (part.len() * row_len * 4) as u64);
                let inside_buf = ctx.output_buffer("feature inside", (part.len() * 4) as u64);
                let bind_group =
                    ctx.bind_group(kernel, &[&uniform, &points, &cell_start, &hyps, &weights, &out_buf, &inside_buf]);
                // One workgroup per hypothesis: the 1-D convention with 64 invocations per hypothesis.
                let invocations = (part.len() * kernel.invocations_per_workgroup() as usize) as u32;
                let mut encoder =
                    ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("features") });
                ctx.encode_dispatch(&mut encoder, kernel, &bind_group, invocations)?;
                let values: Vec<f32> = ctx.read_buffer_after(encoder, &out_buf, part.len() * row_len)?;
                let counts: Vec<u32> = ctx.read_buffer(&inside_buf, part.len())?;
                for (slot, &n) in part.iter().enumerate() {
                    out[n * row_len..(n + 1) * row_len].copy_from_slice(&values[slot * row_len..(slot + 1) * row_len]);
                    inside[n] = counts[slot];
                }
            }
        }
        Ok(())
    })?;
    Ok((out, inside))
}

/// Features of `hypotheses` on the GPU: row-major `len × layout.dim()` and the points inside each
/// expanded box — the same values as [`crate::features::cpu::features`] (see the tests for the tolerance).
pub fn features_gpu(
    ctx: &GpuContext,
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
) -> Result<(Vec<f32>, Vec<u32>)> {
    // The kernel computes the layout without the out-of-view group; its indicators are added on the CPU
    // by the rule every path shares (`features::out_of_view`).
    let (narrow, inside) = run(ctx, scene, &layout.without_out_of_view(), hypotheses, Mode::Write)?;
    Ok((widen_with_out_of_view(scene, layout, hypotheses, narrow), inside))
}

/// Fused scoring on the GPU: `scores[h·W + w] = weights[w] · φ(h)`, without writing the features; also
/// the total number of points inside the expanded boxes (point·voxel updates).
pub fn scores_gpu(
    ctx: &GpuContext,
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
) -> Result<(Vec<f32>, u64)> {
    let w_total = weights.len();
    let mut scores = vec![0.0f32; hypotheses.len() * w_total];
    let mut total_inside = 0u64;
    // The kernel scores the layout without the out-of-view group (each vector's leading part); the
    // indicators' part is added on the CPU (`features::out_of_view`).
    let narrow_layout = layout.without_out_of_view();
    // Without the group the vectors go to the kernel as they are (its own length check names a bad one).
    let narrow_weights: std::borrow::Cow<[Vec<f32>]> = if layout.groups.out_of_view {
        if let Some((n, w)) = weights.iter().enumerate().find(|(_, w)| w.len() != layout.dim()) {
            return Err(Error::Input(format!(
                "weight vector {n} has {} entries; the layout has {}",
                w.len(),
                layout.dim()
            )));
        }
        weights.iter().map(|w| w[..narrow_layout.dim()].to_vec()).collect()
    } else {
        weights.into()
    };
    for (pass, group) in narrow_weights.chunks(MAX_WEIGHTS).enumerate() {
        let (part, inside) = run(ctx, scene, &narrow_layout, hypotheses, Mode::Score(group))?;
        if pass == 0 {
            total_inside = inside.iter().map(|&n| n as u64).sum();
        }
        for h in 0..hypotheses.len() {
            for (w, value) in part[h * group.len()..(h + 1) * group.len()].iter().enumerate() {
                scores[h * w_total + pass * MAX_WEIGHTS + w] = *value;
            }
        }
    }
    add_out_of_view_scores(scene, layout, hypotheses, weights, &mut scores);
    Ok((scores, total_inside))
}
