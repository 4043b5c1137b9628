//! The fast path's layer tables built on the GPU (`shaders/fast_tables.wgsl`): step 2 of
//! [`crate::features::fast`] from one yaw's lattice points, so that the GPU path uploads each yaw's points
//! once per call instead of every (yaw, bottom, height) table.
//!
//! # Design
//! Tables are built by three dispatches (scatter the points with atomic `u32` adds, running sums along s,
//! then along t) into a zeroed range of a buffer; [`crate::gpu::fast`] records them once for all the
//! tables of a batch (workgroup z is the table, [`TableParams`] per table say where its words and its
//! yaw's points lie), before the scoring dispatches of the same submission. The integer sums
//! wrap exactly as on the CPU, so the table is the same words as [`LayerTable`](crate::features::fast::LayerTable)'s whatever the order of the
//! atomic adds (tested against `LayerTable::build` and the twins, on lavapipe).
//!
//! Each point's layer is `⌊(z − z_lo) · inv_step⌋` with `z_lo` and `inv_step` computed once on the CPU
//! ([`TableSpan`]): a subtraction and a multiplication, correctly rounded on both sides (Vulkan requires it
//! of `OpFSub`/`OpFMul`), so a point falls in the same layer on the GPU and the CPU.
//!
//! # CPU twins
//! [`scatter_main`] and [`scan_main`] are the entry points in Rust, one invocation per call;
//! [`build_table_reference`] runs them over a whole table in invocation order.

use bytemuck::{Pod, Zeroable};

use super::{Binding, GpuContext, KernelSpec};
use crate::error::{Error, Result};
use crate::features::fast::{CellRegion, LatticePoint, TableSpan, YawLattice, CHANNELS};
use crate::features::feature_layout::COG;

const BINDINGS: &[Binding] = &[Binding::StorageRead, Binding::StorageRead, Binding::StorageReadWrite];

/// The scatter entry point (registered in [`super::Kernels`]).
pub const SCATTER_KERNEL: KernelSpec = KernelSpec {
    label: "fast_tables scatter",
    source: include_str!("../../shaders/fast_tables.wgsl"),
    entry_point: "scatter",
    bindings: BINDINGS,
};

/// The scan entry point (registered in [`super::Kernels`]).
pub const SCAN_KERNEL: KernelSpec = KernelSpec {
    label: "fast_tables scan",
    source: include_str!("../../shaders/fast_tables.wgsl"),
    entry_point: "scan",
    bindings: BINDINGS,
};

/// The shader's `SCAN_ROWS`: running sums along s.
pub const SCAN_ROWS: u32 = 1;
/// The shader's `SCAN_COLUMNS`: running sums along t.
pub const SCAN_COLUMNS: u32 = 2;

/// Twin of WGSL `struct TablePoint`: one lattice point — the fast path's own [`LatticePoint`], uploaded as
/// the lattice holds it.
pub type TablePoint = LatticePoint;

/// Twin of WGSL `struct TableParams`: one table's shape, z layers and place, and the dispatch's job.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TableParams {
    /// Entries per row (cells_s + 1), rows per layer (cells_t + 1), layers, cells_s.
    pub shape: [u32; 4],
    /// Point count, scan mode ([`SCAN_ROWS`] or [`SCAN_COLUMNS`]; unused by the scatter), first word of the
    /// table in the tables buffer, first point of the yaw in the points buffer.
    pub job: [u32; 4],
    /// z_lo, 1 / layer height, unused, unused.
    pub span: [f32; 4],
    /// The first lattice cell along s and t of the table's region ([`CellRegion`]; the table holds the
    /// cells `lo ≤ c < lo + shape − 1`, and the scatter drops the points outside), unused, unused.
    pub region: [u32; 4],
}
const _: () = assert!(std::mem::size_of::<TableParams>() == 64);
// The shader hard-codes the entry layout: CHANNELS words, the COG bins from word COG.
const _: () = assert!(CHANNELS == 36 && COG == 26);

/// The lattice's points as the shader reads them.
pub fn table_points(lattice: &YawLattice) -> &[TablePoint] {
    lattice.points()
}

/// The params of a table of `span` over the whole of `lattice`, for the dispatch `mode` (0 for the
/// scatter), alone in its buffers (its words and its points from 0).
pub fn table_params(lattice: &YawLattice, span: TableSpan, mode: u32) -> TableParams {
    table_params_at(lattice, span, mode, 0, 0, CellRegion::whole(lattice))
}

/// The params of a table of `span` over `region` of `lattice` whose words start at word `first_word` of
/// the tables buffer and whose yaw's points start at point `first_point` of the points buffer.
pub fn table_params_at(
    lattice: &YawLattice,
    span: TableSpan,
    mode: u32,
    first_word: u32,
    first_point: u32,
    region: CellRegion,
) -> TableParams {
    let [row, rows] = region.table_stride();
    let [lo_s, lo_t] = region.lo();
    TableParams {
        shape: [row as u32, rows as u32, span.layers as u32, lattice.cells()[0] as u32],
        job: [lattice.points().len() as u32, mode, first_word, first_point],
        span: [span.z_lo, span.inv_step, 0.0, 0.0],
        region: [lo_s as u32, lo_t as u32, 0, 0],
    }
}

/// Words of the table `params` describes.
pub fn table_words(params: &TableParams) -> usize {
    let [row, rows, layers, _] = params.shape.map(|v| v as usize);
    layers * rows * row * CHANNELS
}

/// Invocations of each of the three dispatches that build the table of `params`: scatter, rows, columns.
pub fn table_invocations(params: &TableParams) -> [u32; 3] {
    let [row, rows, layers, _] = params.shape;
    let channels = CHANNELS as u32;
    [params.job[0], layers * rows * channels, layers * row * channels]
}

/// The shader's `scatter` for invocation `n` of table `t` (workgroup z).
pub fn scatter_main(tables: &[TableParams], points: &[TablePoint], table: &mut [u32], t: usize, n: usize) {
    let params = &tables[t];
    if n >= params.job[0] as usize {
        return;
    }
    let p = points[params.job[3] as usize + n];
    let layer = ((p.z - params.span[0]) * params.span[1]).floor();
    if !(layer >= 0.0 && layer < params.shape[2] as f32) {
        return;
    }
    let [row, rows, _, cells_s] = params.shape.map(|v| v as usize);
    let [lo_s, lo_t] = [params.region[0] as usize, params.region[1] as usize];
    let cell_s = p.cell as usize % cells_s;
    let cell_t = p.cell as usize / cells_s;
    // Only the region's cells, `lo ≤ c < lo + shape − 1`.
    if cell_s < lo_s || cell_t < lo_t || cell_s - lo_s >= row - 1 || cell_t - lo_t >= rows - 1 {
        return;
    }
    let (x, y) = (cell_s - lo_s, cell_t - lo_t);
    // Cell (x, y) of the region is entry (x + 1, y + 1) before the prefix sums.
    let base = params.job[2] as usize + ((layer as usize * rows + y + 1) * row + x + 1) * CHANNELS;
    let mut atomic_add = |at: usize, value: u32| table[at] = table[at].wrapping_add(value);
    atomic_add(base, 1);
    atomic_add(base + 1 + (p.bins & 0xff) as usize, 1);
    atomic_add(base + COG + ((p.bins >> 8) & 0xff) as usize, p.share0);
    atomic_add(base + COG + ((p.bins >> 16) & 0xff) as usize, p.share1);
}

/// The shader's `scan` for invocation `n` of table `t` (workgroup z; the mode is its `job[1]`).
pub fn scan_main(tables: &[TableParams], table: &mut [u32], t: usize, n: usize) {
    let params = &tables[t];
    let [row, rows, layers, _] = params.shape.map(|v| v as usize);
    let start = params.job[2] as usize;
    let c = n % CHANNELS;
    if params.job[1] == SCAN_ROWS {
        if n >= layers * rows * CHANNELS {
            return;
        }
        // n / CHANNELS = k·rows + y: the row's first entry.
        let first = start + (n / CHANNELS) * row * CHANNELS + c;
        let mut acc = 0u32;
        for x in 1..row {
            let at = first + x * CHANNELS;
            acc = acc.wrapping_add(table[at]);
            table[at] = acc;
        }
    } else {
        if n >= layers * row * CHANNELS {
            return;
        }
        let x = (n / CHANNELS) % row;
        let k = n / (CHANNELS * row);
        let mut acc = 0u32;
        for y in 1..rows {
            let at = start + ((k * rows + y) * row + x) * CHANNELS + c;
            acc = acc.wrapping_add(table[at]);
            table[at] = acc;
        }
    }
}

/// The twins over a whole table: every scatter invocation, then every row scan, then every column scan.
pub fn build_table_reference(lattice: &YawLattice, span: TableSpan) -> Vec<u32> {
    let points = table_points(lattice);
    let scatter = table_params(lattice, span, 0);
    let mut table = vec![0u32; table_words(&scatter)];
    let [point_count, row_jobs, column_jobs] = table_invocations(&scatter);
    for n in 0..point_count as usize {
        scatter_main(&[scatter], points, &mut table, 0, n);
    }
    for n in 0..row_jobs as usize {
        scan_main(&[table_params(lattice, span, SCAN_ROWS)], &mut table, 0, n);
    }
    for n in 0..column_jobs as usize {
        scan_main(&[table_params(lattice, span, SCAN_COLUMNS)], &mut table, 0, n);
    }
    table
}

/// Several tables built together, as a batch of the scoring path builds them: `tables[t]` the scatter
/// params of table `t` (mode 0; its words from `job[2]`, its yaw's points from `job[3]` of `points`), the
/// buffer `words` long. The twins in dispatch order: every scatter invocation of every table, then every row
/// scan, then every column scan.
pub fn build_tables_reference(tables: &[TableParams], points: &[TablePoint], words: usize) -> Vec<u32> {
    let mut table = vec![0u32; words];
    for (t, params) in tables.iter().enumerate() {
        for n in 0..table_invocations(params)[0] as usize {
            scatter_main(tables, points, &mut table, t, n);
        }
    }
    for (step, mode) in [(1, SCAN_ROWS), (2, SCAN_COLUMNS)] {
        let phase: Vec<TableParams> =
            tables.iter().map(|p| TableParams { job: [p.job[0], mode, p.job[2], p.job[3]], ..*p }).collect();
        for (t, params) in phase.iter().enumerate() {
            for n in 0..table_invocations(params)[step] as usize {
                scan_main(&phase, &mut table, t, n);
            }
        }
    }
    table
}

/// [`build_tables_reference`] on the GPU: one dispatch per phase for all the tables (workgroup z).
pub fn build_tables_gpu(
    ctx: &GpuContext,
    tables: &[TableParams],
    points: &[TablePoint],
    words: usize,
) -> Result<Vec<u32>> {
    ctx.checked("fast_tables kernels", || {
        let point_buffer = ctx.storage_buffer("table points", points);
        let table = ctx.output_buffer("fast tables", (words * 4) as u64);
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fast_tables") });
        for (step, mode) in [0, SCAN_ROWS, SCAN_COLUMNS].into_iter().enumerate() {
            let kernel = if step == 0 { &ctx.kernels.fast_table_scatter } else { &ctx.kernels.fast_table_scan };
            let phase: Vec<TableParams> =
                tables.iter().map(|p| TableParams { job: [p.job[0], mode, p.job[2], p.job[3]], ..*p }).collect();
            let params = ctx.storage_buffer("table params", &phase);
            let bind_group = ctx.bind_group(kernel, &[&params, &point_buffer, &table]);
            let invocations = phase.iter().map(|p| table_invocations(p)[step]).max().unwrap_or(0);
            ctx.encode_layered_dispatches(
                &mut encoder,
                kernel,
                &[(&bind_group, invocations, phase.len() as u32)],
                None,
            )?;
        }
        ctx.read_buffer_after(encoder, &table, words)
    })
}

/// One table built on the GPU and read back (for tests and benchmarks; the scoring path builds its tables
/// inside its own submission, see [`crate::gpu::fast`]).
pub fn build_table_gpu(ctx: &GpuContext, lattice: &YawLattice, span: TableSpan) -> Result<Vec<u32>> {
    let points = table_points(lattice);
    let scatter = table_params(lattice, span, 0);
    let words = table_words(&scatter);
    let max_binding = ctx.limits.max_storage_buffer_binding_size.min(ctx.limits.max_buffer_size);
    if (words * 4) as u64 > max_binding {
        return Err(Error::Gpu(format!(
            "fast_tables: a table of {} bytes exceeds the storage-binding limit of {max_binding} bytes",
            words * 4
        )));
    }
    ctx.checked("fast_tables kernels", || {
        let point_buffer = ctx.storage_buffer("table points", points);
        let table = ctx.output_buffer("fast table", (words * 4) as u64);
        let invocations = table_invocations(&scatter);
        let mut encoder =
            ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("fast_tables") });
        for (step, mode) in [0, SCAN_ROWS, SCAN_COLUMNS].into_iter().enumerate() {
            let kernel = if step == 0 { &ctx.kernels.fast_table_scatter } else { &ctx.kernels.fast_table_scan };
            let params = ctx.storage_buffer("table params", &[table_params(lattice, span, mode)]);
            let bind_group = ctx.bind_group(kernel, &[&params, &point_buffer, &table]);
            ctx.encode_dispatch(&mut encoder, kernel, &bind_group, invocations[step])?;
        }
        ctx.read_buffer_after(encoder, &table, words)
    })
}
