// The fast path's layer tables (src/features/fast.rs, step 2: `LayerTable::build`) built on the GPU from
// the yaws' lattice points, so that a frame's tables never cross the bus.
// CPU twins: `scatter_main` and `scan_main` in src/gpu/fast_tables.rs (same names, same order).
//
// A table has `layers` layers of `rows` rows of `row` entries, CHANNELS u32 words each, over a region of
// the lattice (its first cell `region.xy`, `row - 1` cells along s, `rows - 1` along t); entry (x + 1, y + 1)
// of layer k starts as the sums of the region's cell (x, y)'s points in layer k (count, normal bin, two COG
// shares), then becomes the inclusive 2D prefix sum. Every table of a batch is built by the same three
// dispatches, in this order (workgroup z = the table's index in `tables`, whose entry says where its words
// and its yaw's points lie in the shared buffers):
//   1. `scatter`, one invocation per lattice point: atomic u32 adds (wrapping, so the sums are the same
//      integers in any order: bit-for-bit reproducible);
//   2. `scan` with mode SCAN_ROWS, one invocation per (layer, row, channel): running sum along s;
//   3. `scan` with mode SCAN_COLUMNS, one invocation per (layer, column, channel): running sum along t.
// One dispatch per phase for all tables (not one per table) keeps the GPU full: a single table's scan is
// only ~40 000 invocations of a few hundred dependent steps. The tables' range starts zeroed (cleared by
// the caller). Loops are at most `row` or `rows` iterations (a few hundred), far from gallivm's
// 65535-iteration cap (see shaders/features.wgsl).

const WORKGROUP_SIZE: u32 = 64u;
const CHANNELS: u32 = 36u;
// First COG channel of an entry (count, 25 normal bins, then 9 COG bins, then the pad).
const COG: u32 = 26u;
const SCAN_ROWS: u32 = 1u;
const SCAN_COLUMNS: u32 = 2u;

// One lattice point: ground cell t·cells_s + s, height, bins (normal | cog0 << 8 | cog1 << 16) and the
// fixed-point shares of its gradient magnitude for the two COG bins.
struct TablePoint {
    cell: u32,
    z: f32,
    bins: u32,
    share0: u32,
    share1: u32,
}

struct TableParams {
    shape: vec4<u32>, // entries per row (cells_s + 1), rows per layer (cells_t + 1), layers, cells_s
    job: vec4<u32>,   // point count, scan mode, first word of the table in `table`, first point in `points`
    span: vec4<f32>,  // z_lo, 1 / layer height, unused, unused
    region: vec4<u32>, // first lattice cell along s and t of the table's region, unused, unused
}

// One entry per table of the dispatch (workgroup z).
@group(0) @binding(0) var<storage, read> tables: array<TableParams>;
@group(0) @binding(1) var<storage, read> points: array<TablePoint>;
@group(0) @binding(2) var<storage, read_write> table: array<atomic<u32>>;

// The linear invocation index of the 1-D dispatch convention (src/gpu/mod.rs).
fn linear_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * WORKGROUP_SIZE;
}

@compute @workgroup_size(64)
fn scatter(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let params = tables[gid.z];
    let n = linear_index(gid, nwg);
    if (n >= params.job.x) {
        return;
    }
    let p = points[params.job.w + n];
    let layer = floor((p.z - params.span.x) * params.span.y);
    if (!(layer >= 0.0 && layer < f32(params.shape.z))) {
        return;
    }
    let cell_s = p.cell % params.shape.w;
    let cell_t = p.cell / params.shape.w;
    // Only the region's cells, `lo <= c < lo + shape - 1` (u32: a cell below `lo` wraps to a large value).
    let x = cell_s - params.region.x;
    let y = cell_t - params.region.y;
    if (cell_s < params.region.x || cell_t < params.region.y || x >= params.shape.x - 1u || y >= params.shape.y - 1u) {
        return;
    }
    // Cell (x, y) of the region is entry (x + 1, y + 1) before the prefix sums.
    let base = params.job.z + ((u32(layer) * params.shape.y + y + 1u) * params.shape.x + x + 1u) * CHANNELS;
    atomicAdd(&table[base], 1u);
    atomicAdd(&table[base + 1u + (p.bins & 0xffu)], 1u);
    atomicAdd(&table[base + COG + ((p.bins >> 8u) & 0xffu)], p.share0);
    atomicAdd(&table[base + COG + ((p.bins >> 16u) & 0xffu)], p.share1);
}

@compute @workgroup_size(64)
fn scan(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let params = tables[gid.z];
    let n = linear_index(gid, nwg);
    let row = params.shape.x;
    let rows = params.shape.y;
    let layers = params.shape.z;
    let start = params.job.z;
    let c = n % CHANNELS;
    // The invocation owns every word it touches: relaxed atomic loads and stores are plain accesses.
    if (params.job.y == SCAN_ROWS) {
        if (n >= layers * rows * CHANNELS) {
            return;
        }
        // n / CHANNELS = k·rows + y: the row's first entry.
        let first = start + (n / CHANNELS) * row * CHANNELS + c;
        var acc = 0u;
        for (var x = 1u; x < row; x++) {
            let at = first + x * CHANNELS;
            acc += atomicLoad(&table[at]);
            atomicStore(&table[at], acc);
        }
    } else {
        if (n >= layers * row * CHANNELS) {
            return;
        }
        let x = (n / CHANNELS) % row;
        let k = n / (CHANNELS * row);
        var acc = 0u;
        for (var y = 1u; y < rows; y++) {
            let at = start + ((k * rows + y) * row + x) * CHANNELS + c;
            acc += atomicLoad(&table[at]);
            atomicStore(&table[at], acc);
        }
    }
}
