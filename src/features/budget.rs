//! Memory of a sliding window, computed before anything is allocated (see [`crate::limits`]).
//!
//! The sizes of the yaw grids, the per-yaw count tables of the skipping test, the hypothesis set and the
//! fast path's layer tables all follow from the points' extent in each yaw's rotated frame and the centre
//! step; an implausible frame (points kilometres away) or option (a step of 0.1 mm) would ask for
//! gigabytes. [`check_window`] and [`check_fast`] compute those sizes exactly as the builders will and
//! return an error naming the structure, its size and what to change, instead of letting the allocation
//! abort the process.

use rayon::prelude::*;

use super::fast::CHANNELS;
use super::feature_layout::FeatureLayout;
use super::hypotheses::{Hypothesis, SURFACE_COUNT_CELL_M};
use super::preprocess::Preprocessed;
use super::scene::{extent, grid_cells, rotate, PointRecord};
use crate::error::Result;
use crate::limits::{check_memory, check_step, check_subdivisions};

/// Bytes of one fast-path lattice point (`features::fast`'s `LatticePoint`, rounded up).
const LATTICE_POINT_BYTES: f64 = 24.0;

/// Sizes of one yaw's structures.
#[derive(Clone, Copy, Debug)]
struct YawSize {
    /// Ground cells along s and t.
    cells: [f64; 2],
    /// Cell layers of the count table (floor to the highest point).
    layers: f64,
    /// Layers of the surface, free and resting windows' count tables (`SURFACE_COUNT_CELL_M` cells).
    fine_layers: f64,
}

/// Per-yaw grid sizes of `pre` at centre step `step` for the window's `yaws`, as `YawGrid::build` and the
/// count table compute them at the camera's lattice phase (the walls' phase,
/// [`super::scene::LatticePhase::Walls`], can add one cell per axis: well inside the limits' margins).
fn yaw_sizes(pre: &Preprocessed, yaws: &[f32], step: f32) -> Vec<YawSize> {
    let top = pre.points.iter().fold(pre.floor, |m, p| m.max(p.z));
    let layers_of = |cell: f32| (((top - pre.floor) / cell).floor() as f64 + 1.0).max(1.0);
    let (layers, fine_layers) = (layers_of(step), layers_of(SURFACE_COUNT_CELL_M));
    yaws.par_iter()
        .map(|&yaw| {
            let (sin, cos) = (yaw as f64).sin_cos();
            let rotated: Vec<[f32; 2]> = pre.points.iter().map(|p| rotate(p, sin as f32, cos as f32)).collect();
            YawSize { cells: grid_cells(extent(&rotated), step).1, layers, fine_layers }
        })
        .collect()
}

/// What to change when a window does not fit.
fn hint(step: f32) -> String {
    format!(
        "the point cloud is too large for a centre step of {step} m: use a larger step, or check the frame's \
         intrinsics and extrinsics (a point cloud spanning kilometres means a wrong calibration)"
    )
}

/// Checks the yaw grids, the count tables and the hypotheses of a sliding window with `sizes` box sizes,
/// the yaws `yaws` and centre step `step` on `pre` against [`crate::limits::MEMORY_BUDGET_BYTES`].
pub fn check_window(pre: &Preprocessed, yaws: &[f32], step: f32, sizes: usize) -> Result<()> {
    check_step("the centre step", step)?;
    let yaws = yaw_sizes(pre, yaws, step);
    let hint = hint(step);
    let cells: f64 = yaws.iter().map(|y| y.cells[0] * y.cells[1]).sum();
    let records = (pre.len() * yaws.len()) as f64 * std::mem::size_of::<PointRecord>() as f64;
    check_memory("the yaw grids", cells + records / 4.0, 4.0, &hint)?;
    // Each yaw's count tables live while that yaw's hypotheses are enumerated, one yaw per rayon thread:
    // the step's, and for the surface, free and resting windows two of `SURFACE_COUNT_CELL_M` layers (all
    // points, upward points; `hypotheses::windows` builds them once for all the models of a scene), counted
    // whatever the support.
    let largest = yaws
        .iter()
        .map(|y| (y.cells[0] + 1.0) * (y.cells[1] + 1.0) * ((y.layers + 1.0) + 2.0 * (y.fine_layers + 1.0)))
        .fold(0.0, f64::max);
    let concurrent = rayon::current_num_threads().min(yaws.len()) as f64;
    check_memory(
        &format!("the count tables of the skipping test ({concurrent} yaws at once, three tables each)"),
        largest * concurrent,
        4.0,
        &hint,
    )?;
    // A hypothesis per size at every cell that holds a point: at most min(points, cells) cells per yaw.
    let centres: f64 = yaws.iter().map(|y| (y.cells[0] * y.cells[1]).min(pre.len() as f64)).sum();
    check_memory(
        &format!("the sliding window (up to {:.3e} hypotheses)", centres * sizes as f64),
        centres * sizes as f64,
        std::mem::size_of::<Hypothesis>() as f64,
        &hint,
    )
}

/// Checks the fast path's lattices and the layer tables built at once (one per rayon thread) for `layout`
/// with `subdivisions` lattice cells per step `step` and the window's `yaws` on `pre`.
pub fn check_fast(
    pre: &Preprocessed,
    yaws: &[f32],
    step: f32,
    layout: &FeatureLayout,
    subdivisions: u32,
) -> Result<()> {
    check_step("the centre step", step)?;
    check_subdivisions("the fast path's subdivisions", subdivisions)?;
    let yaws = yaw_sizes(pre, yaws, step);
    let lattice_points = (pre.len() * yaws.len()) as f64;
    let hint = format!("{}; or fewer subdivisions", hint(step));
    check_memory("the fast path's lattices", lattice_points, LATTICE_POINT_BYTES, &hint)?;
    let sub = subdivisions as f64;
    let largest = yaws.iter().map(|y| (y.cells[0] * sub + 1.0) * (y.cells[1] * sub + 1.0)).fold(0.0, f64::max);
    let concurrent = rayon::current_num_threads() as f64;
    check_memory(
        &format!("the fast path's layer tables ({concurrent} built at once)"),
        largest * layout.grid()[2] as f64 * CHANNELS as f64 * concurrent,
        4.0,
        &hint,
    )
}
