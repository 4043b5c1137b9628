// room_layout: integer scores of room-layout hypotheses (Manhattan or cubical voxels).
//
// CPU twin: `score_box` and the region functions in src/room_layout/voxels.rs (same names, same integer
// operations). One invocation per hypothesis; it walks the occupied ground cells of its orientation,
// finds each cell's region from the cell centre and the four wall positions (integer millimetres), and
// adds the precomputed fixed-point contribution of (cell, region). Integers only: the result is exact and
// independent of any order. The cell loop takes CELLS_PER_ITERATION cells per iteration so that
// lavapipe's cap of 65535 loop iterations per invocation is only reached beyond 262140 cells (the host
// checks the count).

// Twin of the Rust `LayoutParams` (16 bytes).
struct LayoutParams {
    hypothesis_count: u32,
    // Regions per cell (12 Manhattan, 16 cubical): the stride of `contributions`.
    regions: u32,
    // DISCRETISATION_MANHATTAN or DISCRETISATION_CUBICAL.
    discretisation: u32,
    pad: u32,
}

// Twin of the Rust `YawRange` (16 bytes): one orientation's cells and contributions.
struct YawRange {
    first_cell: u32,
    cell_count: u32,
    first_contribution: u32,
    pad: u32,
}

// Twin of the Rust `GpuRoomBox` (20 bytes): a hypothesis, walls in millimetres of its room frame.
struct RoomBox {
    yaw_index: u32,
    u0: i32,
    u1: i32,
    v0: i32,
    v1: i32,
}

const WORKGROUP_SIZE: u32 = 64u;
const CELLS_PER_ITERATION: u32 = 4u;
const BAND_MM: i32 = 150;
const CUBICAL_SPLITS: i32 = 4;
const NO_REGION: u32 = 0xffffffffu;
const DISCRETISATION_MANHATTAN: u32 = 0u;
const DISCRETISATION_CUBICAL: u32 = 1u;

@group(0) @binding(0) var<uniform> params: LayoutParams;
@group(0) @binding(1) var<storage, read> yaws: array<YawRange>;
@group(0) @binding(2) var<storage, read> centres: array<vec2<i32>>;
@group(0) @binding(3) var<storage, read> contributions: array<i32>;
@group(0) @binding(4) var<storage, read> boxes: array<RoomBox>;
@group(0) @binding(5) var<storage, read_write> scores: array<i32>;

// Nearest wall inside, farthest-out wall outside; interior, band within BAND_MM, or exterior.
fn manhattan_region(u: i32, v: i32, b: RoomBox) -> u32 {
    let d = array<i32, 4>(b.v1 - v, u - b.u0, v - b.v0, b.u1 - u);
    var wall = 0u;
    var dmin = d[0];
    for (var w = 1u; w < 4u; w++) {
        if d[w] < dmin {
            dmin = d[w];
            wall = w;
        }
    }
    if dmin > BAND_MM {
        return wall;
    } else if dmin >= -BAND_MM {
        return 4u + wall;
    }
    return 8u + wall;
}

// A 4 × 4 grid inside the cuboid; NO_REGION outside.
fn cubical_region(u: i32, v: i32, b: RoomBox) -> u32 {
    if u < b.u0 || u > b.u1 || v < b.v0 || v > b.v1 {
        return NO_REGION;
    }
    let i = min(CUBICAL_SPLITS * (u - b.u0) / (b.u1 - b.u0), CUBICAL_SPLITS - 1);
    let j = min(CUBICAL_SPLITS * (v - b.v0) / (b.v1 - b.v0), CUBICAL_SPLITS - 1);
    return u32(j * CUBICAL_SPLITS + i);
}

fn region(u: i32, v: i32, b: RoomBox) -> u32 {
    if params.discretisation == DISCRETISATION_CUBICAL {
        return cubical_region(u, v, b);
    }
    return manhattan_region(u, v, b);
}

// Contribution of cell `cell` (index within its orientation) to hypothesis `b`.
fn cell_contribution(yaw: YawRange, cell: u32, b: RoomBox) -> i32 {
    let centre = centres[yaw.first_cell + cell];
    let r = region(centre.x, centre.y, b);
    if r == NO_REGION {
        return 0;
    }
    return contributions[yaw.first_contribution + cell * params.regions + r];
}

fn score_box(b: RoomBox) -> i32 {
    let yaw = yaws[b.yaw_index];
    var total = 0;
    for (var cell = 0u; cell < yaw.cell_count; cell += CELLS_PER_ITERATION) {
        total += cell_contribution(yaw, cell, b);
        if cell + 1u < yaw.cell_count {
            total += cell_contribution(yaw, cell + 1u, b);
        }
        if cell + 2u < yaw.cell_count {
            total += cell_contribution(yaw, cell + 2u, b);
        }
        if cell + 3u < yaw.cell_count {
            total += cell_contribution(yaw, cell + 3u, b);
        }
    }
    return total;
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn room_layout(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) num_workgroups: vec3<u32>) {
    // 1-D job dispatched over x and y (see src/gpu/mod.rs, "1-D dispatch convention").
    let h = gid.x + gid.y * num_workgroups.x * WORKGROUP_SIZE;
    if h >= params.hypothesis_count {
        return;
    }
    scores[h] = score_box(boxes[h]);
}
