//! The limits every command checks its input against, in one place, so that `score`, `bench`, `train`,
//! `detect` and `eval` agree (the command line's range checks are built from these constants).
//!
//! * **Frames**: at most [`MAX_PIXELS`] pixels (depth sensors give at most 1920×1080; larger images are
//!   rejected before they are decoded); focal lengths in [[`MIN_FOCAL_PER_SIZE`],
//!   [`MAX_FOCAL_PER_SIZE`]] × the image's larger side (fields of view from 0.6° to 136°: small crops of a
//!   real camera pass, a focal length that would fan the points out over kilometres does not); the
//!   principal point at most [`PRINCIPAL_POINT_MARGIN`] × the image size outside the image; no skew.
//! * **Annotations**: coordinates within ±[`MAX_COORDINATE_M`] of the camera; boxes larger than
//!   [`MAX_OBJECT_SIZE_M`] on a side are not objects; hypothesis sizes lie in [[`MIN_OBJECT_SIZE_M`],
//!   [`MAX_OBJECT_SIZE_M`]].
//! * **Options**: the sliding-window centre step in [[`MIN_STEP_M`], [`MAX_STEP_M`]], the fast path's
//!   subdivisions in 1..=[`MAX_SUBDIVISIONS`].
//! * **Memory**: every structure whose size comes from the input (yaw grids, count tables, hypothesis sets,
//!   fast-path tables, training caches) is sized before it is allocated and refused above
//!   [`MEMORY_BUDGET_BYTES`] with an error that says what would be too large and what to change.

use crate::error::{Error, Result};

/// Largest image (pixels) a frame may have.
pub const MAX_PIXELS: u64 = 1 << 22;
/// Smallest and largest focal length, in units of the image's larger side.
pub const MIN_FOCAL_PER_SIZE: f64 = 0.2;
pub const MAX_FOCAL_PER_SIZE: f64 = 100.0;
/// How far outside the image the principal point may lie, as a fraction of the image's width (height).
pub const PRINCIPAL_POINT_MARGIN: f64 = 0.25;
/// Largest absolute coordinate (metres) of an annotation corner or height.
pub const MAX_COORDINATE_M: f64 = 100.0;
/// Smallest and largest side (metres) of a hypothesis box (model sizes, size statistics); annotated
/// boxes may be smaller (a thin picture) but not larger.
pub const MIN_OBJECT_SIZE_M: f32 = 0.01;
pub const MAX_OBJECT_SIZE_M: f32 = 20.0;
/// Range of the sliding-window centre step (metres).
pub const MIN_STEP_M: f32 = 0.01;
pub const MAX_STEP_M: f32 = 1.0;
/// Largest number of fast-path lattice cells per centre step.
pub const MAX_SUBDIVISIONS: u32 = 16;
/// Largest size (bytes) of one input-driven structure (all yaws of it together).
pub const MEMORY_BUDGET_BYTES: u64 = 3 << 30;

/// Checks that `what` — `count` items of `bytes_each` bytes — fits in [`MEMORY_BUDGET_BYTES`]; `hint` says
/// what to change when it does not. `count` is a float so that no product of input-driven sizes can
/// overflow before the comparison.
pub fn check_memory(what: &str, count: f64, bytes_each: f64, hint: &str) -> Result<()> {
    check_memory_within(what, count, bytes_each, MEMORY_BUDGET_BYTES as f64, hint)
}

/// [`check_memory`] against another budget of `budget_bytes` (`train --cache-gib`: a training run may
/// be given more memory than one per-frame structure).
pub fn check_memory_within(what: &str, count: f64, bytes_each: f64, budget_bytes: f64, hint: &str) -> Result<()> {
    let bytes = count * bytes_each;
    if bytes.is_finite() && bytes <= budget_bytes {
        return Ok(());
    }
    Err(Error::Input(format!("{what} would need {} (limit {}); {hint}", human_bytes(bytes), human_bytes(budget_bytes))))
}

/// `bytes` as "12.3 GiB" (or "inf").
pub fn human_bytes(bytes: f64) -> String {
    if !bytes.is_finite() {
        return "an unbounded amount of memory".into();
    }
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if value >= 1024.0 {
        return format!("{bytes:.3e} B");
    }
    format!("{value:.1} {}", units[unit])
}

/// Checks a sliding-window centre step (metres) against [[`MIN_STEP_M`], [`MAX_STEP_M`]]; `what` names it.
pub fn check_step(what: &str, step: f32) -> Result<()> {
    if step.is_finite() && (MIN_STEP_M..=MAX_STEP_M).contains(&step) {
        Ok(())
    } else {
        Err(Error::Input(format!("{what} must be between {MIN_STEP_M} and {MAX_STEP_M} metre, got {step}")))
    }
}

/// Checks a window's minimum points per box against 0..=[`MAX_PIXELS`] (a box holds at most one point a
/// pixel: a larger minimum keeps no hypothesis, and the model written with it never detects); `what`
/// names it.
pub fn check_min_points(what: &str, min_points: u32) -> Result<()> {
    if u64::from(min_points) <= MAX_PIXELS {
        Ok(())
    } else {
        Err(Error::Input(format!(
            "{what} must be at most {MAX_PIXELS} (a box holds at most one point a pixel), got {min_points}"
        )))
    }
}

/// Checks fast-path subdivisions against 1..=[`MAX_SUBDIVISIONS`]; `what` names them.
pub fn check_subdivisions(what: &str, subdivisions: u32) -> Result<()> {
    if (1..=MAX_SUBDIVISIONS).contains(&subdivisions) {
        Ok(())
    } else {
        Err(Error::Input(format!("{what} must be in 1..={MAX_SUBDIVISIONS}, got {subdivisions}")))
    }
}
