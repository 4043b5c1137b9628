//! The fast path's layer tables built by `shaders/fast_tables.wgsl` against the CPU's `LayerTable` and the
//! kernels' twins (exact: integer words), against brute-force counts over the lattice points, and the
//! constants and struct layouts the fast kernels share with Rust (read from the WGSL by naga).
//!
//! Without an adapter the GPU tests fail with a clear message, unless `COG_GPU_SKIP_GPU_TESTS=1`. Run with
//! `NODEVICE_SELECT=1`.

mod common;

use common::{shader_module, wgsl_const, wgsl_const_f32, wgsl_struct_size};

use std::path::Path;

use cog_gpu::features::cpu::VIEW_MIN_DISTANCE;
use cog_gpu::features::fast::{CellRegion, FastEngine, FastOptions, CHANNELS};
use cog_gpu::features::feature_layout::{FeatureLayout, Groups, COG, COG_EPSILON, VIEW, VIEW_RBFS, VIEW_SIGMA};
use cog_gpu::features::{Hypothesis, PreparedWindow, SizeQuantiles};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::MIN_PROJECT_DEPTH;
use cog_gpu::gpu::fast::{FastParams, FastRecord, MAX_WEIGHTS, WORKGROUP};
use cog_gpu::gpu::fast_tables::{
    build_table_gpu, build_table_reference, build_tables_gpu, build_tables_reference, table_params, table_params_at,
    table_points, table_words, TableParams, TablePoint, SCAN_COLUMNS, SCAN_ROWS,
};
use cog_gpu::gpu::TexelRows;
use cog_gpu::synth::{self, SynthOptions};

const FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";
const STATS: &str = "../shared/data/sunrgbd-size-stats.json";

fn window(frame: &Frame, category: &str) -> PreparedWindow {
    let sizes = SizeQuantiles::from_stats_file(Path::new(STATS), category).unwrap().sizes();
    PreparedWindow::new(frame, sizes, 0.2, 50).unwrap()
}

/// Hypotheses with distinct tables (yaw, bottom, height), at most `count`, spread over the window.
fn distinct_tables(window: &PreparedWindow, count: usize) -> Vec<Hypothesis> {
    let mut seen = Vec::new();
    let mut out = Vec::new();
    let kept = &window.set.hypotheses;
    for hyp in kept.iter().step_by((kept.len() / (8 * count)).max(1)) {
        let key = (hyp.yaw_index, hyp.bottom.to_bits(), hyp.size.z.to_bits());
        if !seen.contains(&key) {
            seen.push(key);
            out.push(*hyp);
        }
        if out.len() == count {
            break;
        }
    }
    out
}

/// GPU, twins and `LayerTable::build` give the same words for every table of `hyps`.
fn assert_tables_agree(engine: &FastEngine, hyps: &[Hypothesis], what: &str) {
    let ctx = common::gpu_context();
    for (n, hyp) in hyps.iter().enumerate() {
        let lattice = engine.lattice(hyp.yaw_index as usize);
        let span = engine.table_span_of(hyp);
        let cpu = engine.table_words_of(hyp);
        let twin = build_table_reference(lattice, span);
        assert_eq!(twin.len(), cpu.len(), "{what}: table {n} size");
        assert!(twin == cpu, "{what}: table {n}: the twins differ from LayerTable::build");
        if let Some(ctx) = &ctx {
            let gpu = build_table_gpu(ctx, lattice, span).unwrap();
            assert!(gpu == cpu, "{what}: table {n}: the GPU table differs from LayerTable::build");
        }
    }
    eprintln!("{what}: {} tables identical", hyps.len());
}

#[test]
fn gpu_tables_equal_the_cpu_tables_on_a_real_and_a_synthetic_frame() {
    let real = Frame::read(FRAME, DepthSource::Raw).unwrap();
    let synthetic = synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap().frame;
    for (frame, category, what) in [(&real, "bed", "real frame"), (&synthetic, "chair", "synthetic frame")] {
        let window = window(frame, category);
        let hyps = distinct_tables(&window, 12);
        assert!(hyps.len() >= 6, "{what}: only {} distinct tables", hyps.len());
        for layout in [FeatureLayout::default(), FeatureLayout::new([3, 1, 3], true, Groups::ALL).unwrap()] {
            let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
            assert_tables_agree(&engine, &hyps, &format!("{what}, {}", layout.id()));
        }
    }
}

#[test]
fn tables_built_together_equal_each_built_alone() {
    // Several tables of several yaws in one buffer, at offsets that are not zero, with the yaws' points
    // packed one after the other (as a batch of the scoring path builds them): each table's words must be
    // those of the CPU's LayerTable, built by the twins and on the GPU, and the gaps between them stay zero.
    // Every other table covers only a region of its lattice (as the scoring path's, the cells its boxes
    // reach): its entries must also be the whole lattice table's sums over the region's cells.
    let frame = synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap().frame;
    let window = window(&frame, "chair");
    let engine = FastEngine::new(&window.scene, &FeatureLayout::default(), FastOptions::default());
    let hyps = distinct_tables(&window, 6);
    assert!(hyps.len() >= 4, "only {} distinct tables", hyps.len());
    let yaws: Vec<usize> = {
        let mut y: Vec<usize> = hyps.iter().map(|h| h.yaw_index as usize).collect();
        y.sort_unstable();
        y.dedup();
        y
    };
    assert!(yaws.len() >= 2, "the tables should come from at least two yaws");
    let mut points = Vec::new();
    let mut first_point = vec![0u32; engine.scene().yaws.len()];
    for &yaw in &yaws {
        first_point[yaw] = points.len() as u32;
        points.extend(table_points(engine.lattice(yaw)));
    }
    let mut words = 7; // a gap before the first table
    let mut tables = Vec::new();
    let mut alone = Vec::new();
    let mut regions = 0;
    for (n, hyp) in hyps.iter().enumerate() {
        let yaw = hyp.yaw_index as usize;
        let (lattice, span) = (engine.lattice(yaw), engine.table_span_of(hyp));
        let [cs, ct] = lattice.cells();
        let region = if n % 2 == 1 {
            // The middle of the lattice, not touching its edges: a fifth to four fifths along each axis.
            CellRegion::new(lattice, [cs / 5, ct / 5], [cs * 4 / 5, ct * 4 / 5]).unwrap()
        } else {
            CellRegion::whole(lattice)
        };
        let params = table_params_at(lattice, span, 0, words as u32, first_point[yaw], region);
        tables.push(params);
        // The CPU's own LayerTable (`LayerTable::build`), not the twins.
        let cpu = engine.region_table_words_of(hyp, region);
        if region != CellRegion::whole(lattice) {
            assert_region_table_is_a_part_of_the_whole(
                &cpu,
                &engine.table_words_of(hyp),
                region,
                lattice.cells(),
                span.layers,
            );
            regions += 1;
        }
        alone.push((words, cpu));
        words += table_words(&params) + 5; // and a gap after each
    }
    assert!(regions >= 2, "only {regions} region tables");
    let twin = build_tables_reference(&tables, &points, words);
    let check = |built: &[u32], what: &str| {
        let mut covered = vec![false; words];
        for (n, (at, table)) in alone.iter().enumerate() {
            assert!(built[*at..at + table.len()] == table[..], "{what}: table {n} differs from the table built alone");
            covered[*at..at + table.len()].iter_mut().for_each(|c| *c = true);
        }
        assert!(
            built.iter().zip(&covered).all(|(&w, &c)| c || w == 0),
            "{what}: a word between the tables was written"
        );
    };
    check(&twin, "twins");
    if let Some(ctx) = common::gpu_context() {
        check(&build_tables_gpu(&ctx, &tables, &points, words).unwrap(), "GPU");
    }
}

/// `region_table` (a table over `region` of a lattice of `cells`) holds, at entry (x, y) of layer k, the
/// sums over the region's first x cells along s and first y along t: the difference of four entries of
/// `whole`, the table of the whole lattice.
fn assert_region_table_is_a_part_of_the_whole(
    region_table: &[u32],
    whole: &[u32],
    region: CellRegion,
    cells: [usize; 2],
    layers: usize,
) {
    let [row, rows] = region.table_stride();
    let [lo_s, lo_t] = region.lo();
    let (whole_row, whole_rows) = (cells[0] + 1, cells[1] + 1);
    assert_eq!(region_table.len(), layers * rows * row * CHANNELS);
    let at = |k: usize, x: usize, y: usize, c: usize| whole[((k * whole_rows + y) * whole_row + x) * CHANNELS + c];
    for k in 0..layers {
        for y in 0..rows {
            for x in 0..row {
                for c in 0..CHANNELS {
                    let expected = at(k, lo_s + x, lo_t + y, c)
                        .wrapping_sub(at(k, lo_s, lo_t + y, c))
                        .wrapping_sub(at(k, lo_s + x, lo_t, c))
                        .wrapping_add(at(k, lo_s, lo_t, c));
                    let got = region_table[((k * rows + y) * row + x) * CHANNELS + c];
                    assert_eq!(got, expected, "layer {k}, entry ({x}, {y}), channel {c}");
                }
            }
        }
    }
}

/// Brute force: the points of lattice cells `[x0, x1) × [y0, y1)` in layer `k`, from the points themselves.
fn brute_count(points: &[TablePoint], params: &TableParams, k: usize, x: [usize; 2], y: [usize; 2]) -> u32 {
    let cells_s = params.shape[3] as usize;
    points
        .iter()
        .filter(|p| {
            let layer = ((p.z - params.span[0]) * params.span[1]).floor();
            let (px, py) = (p.cell as usize % cells_s, p.cell as usize / cells_s);
            layer == k as f32 && (x[0]..x[1]).contains(&px) && (y[0]..y[1]).contains(&py)
        })
        .count() as u32
}

#[test]
fn table_differences_count_the_points_of_any_rectangle() {
    let frame = synth::generate_frame(6, 0, &SynthOptions::small(160, 120)).unwrap().frame;
    let window = window(&frame, "table");
    let engine = FastEngine::new(&window.scene, &FeatureLayout::default(), FastOptions::default());
    let ctx = common::gpu_context();
    for hyp in distinct_tables(&window, 3) {
        let lattice = engine.lattice(hyp.yaw_index as usize);
        let span = engine.table_span_of(&hyp);
        let params = table_params(lattice, span, 0);
        let points = table_points(lattice);
        let table = match &ctx {
            Some(ctx) => build_table_gpu(ctx, lattice, span).unwrap(),
            None => build_table_reference(lattice, span),
        };
        let [row, rows, layers, _] = params.shape.map(|v| v as usize);
        let entry = |k: usize, x: usize, y: usize, c: usize| table[((k * rows + y) * row + x) * CHANNELS + c];
        let mut rectangles = 0;
        let mut nonempty = 0;
        for k in 0..layers {
            // The whole layer, and a spread of sub-rectangles (a fixed LCG picks the corners).
            let mut state = 12345u64 + k as u64;
            let mut next = |n: usize| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 33) as usize % n
            };
            let mut boxes = vec![([0, row - 1], [0, rows - 1])];
            for _ in 0..20 {
                let (a, b) = (next(row), next(row));
                let (c, d) = (next(rows), next(rows));
                boxes.push(([a.min(b), a.max(b)], [c.min(d), c.max(d)]));
            }
            for (x, y) in boxes {
                let sum = |c: usize| {
                    entry(k, x[1], y[1], c)
                        .wrapping_sub(entry(k, x[0], y[1], c))
                        .wrapping_sub(entry(k, x[1], y[0], c))
                        .wrapping_add(entry(k, x[0], y[0], c))
                };
                let count = brute_count(points, &params, k, x, y);
                assert_eq!(sum(0), count, "layer {k}, cells {x:?} × {y:?}");
                // Every point has one normal bin: the 25 normal channels add up to the count.
                let normals: u32 = (1..COG).map(sum).fold(0, u32::wrapping_add);
                assert_eq!(normals, count, "layer {k}, cells {x:?} × {y:?}: normal bins");
                rectangles += 1;
                nonempty += usize::from(count > 0);
            }
        }
        assert!(nonempty >= 10, "only {nonempty} of {rectangles} rectangles hold points");
    }
}

#[test]
fn fast_kernels_share_their_constants_and_structs_with_rust() {
    let tables = shader_module("fast_tables.wgsl");
    assert_eq!(wgsl_const(&tables, "CHANNELS"), CHANNELS as i64);
    assert_eq!(wgsl_const(&tables, "COG"), COG as i64);
    assert_eq!(wgsl_const(&tables, "SCAN_ROWS"), SCAN_ROWS as i64);
    assert_eq!(wgsl_const(&tables, "SCAN_COLUMNS"), SCAN_COLUMNS as i64);
    assert_eq!(wgsl_struct_size(&tables, "TablePoint"), std::mem::size_of::<TablePoint>());
    assert_eq!(wgsl_struct_size(&tables, "TableParams"), std::mem::size_of::<TableParams>());
    let scores = shader_module("fast_scores.wgsl");
    assert_eq!(wgsl_const(&scores, "MAX_WEIGHTS"), MAX_WEIGHTS as i64);
    assert_eq!(wgsl_const(&scores, "WORKGROUP"), WORKGROUP as i64);
    assert_eq!(wgsl_const(&scores, "TEXELS_PER_ROW"), i64::from(TexelRows::WIDTH));
    assert_eq!(wgsl_const(&scores, "VIEW"), VIEW as i64);
    assert_eq!(wgsl_const(&scores, "VIEW_RBFS"), VIEW_RBFS as i64);
    assert_eq!(wgsl_const_f32(&scores, "VIEW_SIGMA").to_bits(), VIEW_SIGMA.to_bits());
    assert_eq!(wgsl_const_f32(&scores, "VIEW_MIN_DISTANCE").to_bits(), VIEW_MIN_DISTANCE.to_bits());
    assert_eq!(wgsl_const_f32(&scores, "COG_EPSILON").to_bits(), COG_EPSILON.to_bits());
    assert_eq!(wgsl_const_f32(&scores, "MIN_PROJECT_DEPTH").to_bits(), MIN_PROJECT_DEPTH.to_bits());
    assert_eq!(wgsl_struct_size(&scores, "FastParams"), std::mem::size_of::<FastParams>());
    assert_eq!(wgsl_struct_size(&scores, "FastRecord"), std::mem::size_of::<FastRecord>());
}
