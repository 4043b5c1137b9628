//! The `room_layout` kernel (`shaders/room_layout.wgsl`): integer scores of room-layout hypotheses.
//!
//! The host flattens one frame's binned cells and fixed-point contribution tables
//! ([`crate::room_layout::voxels::ScoringTables`]) into [`LayoutInputs`]; one invocation per hypothesis sums
//! the contributions of its orientation's cells (integers: exact, order-free). [`room_layout_cpu`] is the
//! twin and reads like the shader (same names, the same four cells per loop iteration); both must equal
//! [`crate::room_layout::voxels::scores_cpu`], the plain reference (tested on lavapipe).

use bytemuck::{Pod, Zeroable};

use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::room_layout::voxels::{
    cubical_region, manhattan_region, Discretisation, ScoringTables, YawCells, NO_REGION,
};
use crate::room_layout::RoomBox;

/// The pipeline description, built into [`super::Kernels::room_layout`].
pub const KERNEL: KernelSpec = KernelSpec {
    label: "room_layout",
    source: include_str!("../../shaders/room_layout.wgsl"),
    entry_point: "room_layout",
    bindings: &[
        Binding::Uniform,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageRead,
        Binding::StorageReadWrite,
    ],
};

/// Cells handled per loop iteration (WGSL `CELLS_PER_ITERATION`).
pub const CELLS_PER_ITERATION: u32 = 4;
/// Lavapipe leaves a loop after 65535 iterations per invocation: the most cells one orientation may have.
pub const MAX_CELLS_PER_YAW: u32 = 65_535 * CELLS_PER_ITERATION;
/// WGSL `DISCRETISATION_MANHATTAN` / `DISCRETISATION_CUBICAL`.
pub const DISCRETISATION_MANHATTAN: u32 = 0;
pub const DISCRETISATION_CUBICAL: u32 = 1;

/// Twin of WGSL `struct LayoutParams` in `shaders/room_layout.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct LayoutParams {
    pub hypothesis_count: u32,
    pub regions: u32,
    pub discretisation: u32,
    pub pad: u32,
}
const _: () = assert!(std::mem::size_of::<LayoutParams>() == 16);

/// Twin of WGSL `struct YawRange`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct YawRange {
    pub first_cell: u32,
    pub cell_count: u32,
    pub first_contribution: u32,
    pub pad: u32,
}
const _: () = assert!(std::mem::size_of::<YawRange>() == 16);

/// Twin of WGSL `struct RoomBox`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct GpuRoomBox {
    pub yaw_index: u32,
    pub u0: i32,
    pub u1: i32,
    pub v0: i32,
    pub v1: i32,
}
const _: () = assert!(std::mem::size_of::<GpuRoomBox>() == 20);

impl From<&RoomBox> for GpuRoomBox {
    fn from(b: &RoomBox) -> Self {
        GpuRoomBox { yaw_index: b.yaw_index, u0: b.u0, u1: b.u1, v0: b.v0, v1: b.v1 }
    }
}

impl GpuRoomBox {
    fn room_box(&self) -> RoomBox {
        RoomBox { yaw_index: self.yaw_index, u0: self.u0, u1: self.u1, v0: self.v0, v1: self.v1 }
    }
}

/// The kernel's buffers, flattened.
#[derive(Clone, Debug)]
pub struct LayoutInputs {
    pub params: LayoutParams,
    pub yaws: Vec<YawRange>,
    pub centres: Vec<[i32; 2]>,
    pub contributions: Vec<i32>,
    pub boxes: Vec<GpuRoomBox>,
}

impl LayoutInputs {
    pub fn new(cells: &[YawCells], tables: &ScoringTables, boxes: &[RoomBox]) -> Result<LayoutInputs> {
        let regions = tables.discretisation.regions();
        let mut yaws = Vec::with_capacity(cells.len());
        let mut centres = Vec::new();
        let mut contributions = Vec::new();
        for (yaw, table) in cells.iter().zip(&tables.contributions) {
            if yaw.centres.len() as u64 > MAX_CELLS_PER_YAW as u64 {
                return Err(Error::Input(format!(
                    "room_layout: {} cells in one orientation, the kernel handles at most {MAX_CELLS_PER_YAW}",
                    yaw.centres.len()
                )));
            }
            yaws.push(YawRange {
                first_cell: centres.len() as u32,
                cell_count: yaw.centres.len() as u32,
                first_contribution: contributions.len() as u32,
                pad: 0,
            });
            centres.extend_from_slice(&yaw.centres);
            contributions.extend_from_slice(table);
        }
        if let Some(b) = boxes.iter().find(|b| b.yaw_index as usize >= yaws.len() || b.u1 <= b.u0 || b.v1 <= b.v0) {
            return Err(Error::Input(format!("room_layout: bad hypothesis {b:?}")));
        }
        let discretisation = match tables.discretisation {
            Discretisation::Manhattan => DISCRETISATION_MANHATTAN,
            Discretisation::Cubical => DISCRETISATION_CUBICAL,
        };
        Ok(LayoutInputs {
            params: LayoutParams { hypothesis_count: boxes.len() as u32, regions, discretisation, pad: 0 },
            yaws,
            centres,
            contributions,
            boxes: boxes.iter().map(GpuRoomBox::from).collect(),
        })
    }
}

// ---- CPU twin, written like the shader ----

fn region(params: &LayoutParams, u: i32, v: i32, b: &RoomBox) -> u32 {
    if params.discretisation == DISCRETISATION_CUBICAL {
        return cubical_region(u, v, b);
    }
    manhattan_region(u, v, b)
}

fn cell_contribution(inputs: &LayoutInputs, yaw: &YawRange, cell: u32, b: &RoomBox) -> i32 {
    let centre = inputs.centres[(yaw.first_cell + cell) as usize];
    let r = region(&inputs.params, centre[0], centre[1], b);
    if r == NO_REGION {
        return 0;
    }
    inputs.contributions[(yaw.first_contribution + cell * inputs.params.regions + r) as usize]
}

fn score_box(inputs: &LayoutInputs, gpu_box: &GpuRoomBox) -> i32 {
    let b = gpu_box.room_box();
    let yaw = &inputs.yaws[b.yaw_index as usize];
    let mut total = 0i32;
    let mut cell = 0u32;
    while cell < yaw.cell_count {
        total = total.wrapping_add(cell_contribution(inputs, yaw, cell, &b));
        for extra in 1..CELLS_PER_ITERATION {
            if cell + extra < yaw.cell_count {
                total = total.wrapping_add(cell_contribution(inputs, yaw, cell + extra, &b));
            }
        }
        cell += CELLS_PER_ITERATION;
    }
    total
}

/// The CPU twin of the kernel: one score per hypothesis.
pub fn room_layout_cpu(inputs: &LayoutInputs) -> Vec<i32> {
    inputs.boxes.iter().map(|b| score_box(inputs, b)).collect()
}

/// Scores on the GPU (one dispatch).
pub fn room_layout_gpu(ctx: &GpuContext, inputs: &LayoutInputs) -> Result<Vec<i32>> {
    let count = inputs.boxes.len();
    if count == 0 {
        return Ok(Vec::new());
    }
    let kernel = &ctx.kernels.room_layout;
    ctx.checked("room_layout", || {
        let uniform = ctx.uniform_buffer("room_layout params", &inputs.params);
        let yaws = ctx.storage_buffer("room_layout yaws", &inputs.yaws);
        let centres = ctx.storage_buffer("room_layout centres", &inputs.centres);
        let contributions = ctx.storage_buffer("room_layout contributions", &inputs.contributions);
        let boxes = ctx.storage_buffer("room_layout boxes", &inputs.boxes);
        let output = ctx.output_buffer("room_layout scores", count as u64 * 4);
        let bind_group = ctx.bind_group(kernel, &[&uniform, &yaws, &centres, &contributions, &boxes, &output]);
        ctx.dispatch_and_read::<i32>(kernel, &bind_group, count as u32, &output, count)
    })
}

/// Scores of `boxes` on the GPU, as [`crate::room_layout::voxels::scores_cpu`] gives them.
pub fn scores_gpu(ctx: &GpuContext, cells: &[YawCells], tables: &ScoringTables, boxes: &[RoomBox]) -> Result<Vec<i32>> {
    room_layout_gpu(ctx, &LayoutInputs::new(cells, tables, boxes)?)
}
