//! The out-of-view group of the feature layout (not in the paper; see [`super::feature_layout`]): which
//! voxels of a hypothesis the camera cannot see. One rule, used alike by the exact and the fast path on
//! the CPU and added on the CPU to the GPU kernels' scores and features, so that every path gives the same
//! indicators bit for bit.
//!
//! Voxel ℓ = (i, j, k) of the expanded grid is **out of view** when its centre — the rotated-frame point
//! `lo + (i + ½, j + ½, k + ½)·cell` of [`ExpandedBox`], taken to the camera by the yaw grid's
//! `camera_from_rotated`, as the fast path's projected areas are — lies less than
//! [`crate::geometry::MIN_PROJECT_DEPTH`] in front of the camera or projects off the image
//! ([`crate::geometry::on_image`], the rule of [`crate::geometry::in_view_share`]). A box whose eight
//! corners all project onto the image has every voxel centre in view (the image's viewing frustum is
//! convex), so its voxels are not tested one by one: most hypotheses of a frame cost eight projections.

use glam::Vec3;

use super::cpu::ExpandedBox;
use super::feature_layout::FeatureLayout;
use super::hypotheses::Hypothesis;
use super::scene::FeatureScene;
use crate::geometry::on_image;

/// Calls `visit(ℓ)` for every out-of-view voxel of `hyp`'s expanded grid under `layout`, in increasing ℓ.
/// Visits nothing when the layout's out-of-view group is off.
pub fn for_each_out_of_view_voxel(
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hyp: &Hypothesis,
    mut visit: impl FnMut(usize),
) {
    if !layout.groups.out_of_view {
        return;
    }
    let expanded = ExpandedBox::new(layout, hyp);
    let m = scene.yaws[hyp.yaw_index as usize].camera_from_rotated;
    let camera = &scene.pre.camera;
    let size = scene.pre.image_size;
    let in_view = |rotated: Vec3| camera.project_camera(m * rotated).is_some_and(|uv| on_image(uv, size));
    let lo = Vec3::from(expanded.lo);
    let corners_in_view = (0..8u32).all(|c| {
        let corner = Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, (c >> 2) as f32);
        in_view(lo + corner * expanded.extent)
    });
    if corners_in_view {
        return;
    }
    let g = layout.grid();
    for k in 0..g[2] {
        for j in 0..g[1] {
            for i in 0..g[0] {
                if !in_view(expanded.voxel_centre([i, j, k])) {
                    visit(layout.voxel_index(i, j, k));
                }
            }
        }
    }
}

/// Writes the out-of-view indicators of `hyp` into `row` (a whole feature vector of `layout.dim()`
/// entries): 1 at `out_of_view_offset() + ℓ` for every out-of-view voxel ℓ, the other entries untouched
/// (the caller's row starts at zero).
pub fn write_out_of_view(scene: &FeatureScene, layout: &FeatureLayout, hyp: &Hypothesis, row: &mut [f32]) {
    let offset = layout.out_of_view_offset();
    for_each_out_of_view_voxel(scene, layout, hyp, |voxel| row[offset + voxel] = 1.0);
}

/// The out-of-view voxels of `hyp`, in increasing ℓ (empty when the group is off).
pub fn out_of_view_voxels(scene: &FeatureScene, layout: &FeatureLayout, hyp: &Hypothesis) -> Vec<usize> {
    let mut voxels = Vec::new();
    for_each_out_of_view_voxel(scene, layout, hyp, |voxel| voxels.push(voxel));
    voxels
}

/// `w · indicators` of the out-of-view `voxels` of a hypothesis: their weights summed in increasing ℓ
/// (`w` a whole weight vector of `layout.dim()` entries).
pub fn out_of_view_score(layout: &FeatureLayout, voxels: &[usize], w: &[f32]) -> f32 {
    let offset = layout.out_of_view_offset();
    voxels.iter().map(|&voxel| w[offset + voxel]).sum()
}

/// Adds each weight vector's [`out_of_view_score`] to fused scores `scores[h·W + w]` (the GPU paths, whose
/// kernels score the layout without the group). Nothing to do when the group is off.
pub fn add_out_of_view_scores(
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    scores: &mut [f32],
) {
    use rayon::prelude::*;
    if !layout.groups.out_of_view || weights.is_empty() {
        return;
    }
    scores.par_chunks_mut(weights.len()).zip(hypotheses.par_iter()).for_each(|(row, hyp)| {
        let voxels = out_of_view_voxels(scene, layout, hyp);
        for (score, w) in row.iter_mut().zip(weights) {
            *score += out_of_view_score(layout, &voxels, w);
        }
    });
}

/// Widens feature rows of `layout.without_out_of_view()` (the GPU kernels' output) to `layout`'s, the
/// indicators written after each row's view features.
pub fn widen_with_out_of_view(
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    narrow: Vec<f32>,
) -> Vec<f32> {
    use rayon::prelude::*;
    if !layout.groups.out_of_view {
        return narrow;
    }
    let (narrow_dim, dim) = (layout.without_out_of_view().dim(), layout.dim());
    let mut out = vec![0.0f32; hypotheses.len() * dim];
    out.par_chunks_mut(dim).zip(narrow.par_chunks(narrow_dim.max(1))).zip(hypotheses.par_iter()).for_each(
        |((row, part), hyp)| {
            row[..narrow_dim].copy_from_slice(part);
            write_out_of_view(scene, layout, hyp, row);
        },
    );
    out
}
