//! The fast (shared-work) feature path against a brute-force count and against the exact path.

use std::path::Path;

use cog_gpu::features::cpu;
use cog_gpu::features::fast::{FastEngine, FastOptions};
use cog_gpu::features::feature_layout::{FeatureLayout, Groups};
use cog_gpu::features::scene::FIXED_PER_METRE;
use cog_gpu::features::{Hypothesis, PreparedWindow, SizeQuantiles};
use cog_gpu::frame::{DepthSource, Frame};

const FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";
const STATS: &str = "../shared/data/sunrgbd-size-stats.json";

fn window(category: &str, step: f32) -> PreparedWindow {
    let frame = Frame::read(FRAME, DepthSource::Raw).unwrap();
    let sizes = SizeQuantiles::from_stats_file(Path::new(STATS), category).unwrap().sizes();
    PreparedWindow::new(&frame, sizes, step, 50).unwrap()
}

/// Every `n`-th kept hypothesis.
fn sample(window: &PreparedWindow, count: usize) -> Vec<Hypothesis> {
    let kept = &window.set.hypotheses;
    let stride = (kept.len() / count).max(1);
    kept.iter().step_by(stride).take(count).copied().collect()
}

fn cosine(a: &[f32], b: &[f32]) -> f64 {
    let (mut ab, mut aa, mut bb) = (0.0f64, 0.0f64, 0.0f64);
    for (&x, &y) in a.iter().zip(b) {
        ab += x as f64 * y as f64;
        aa += x as f64 * x as f64;
        bb += y as f64 * y as f64;
    }
    ab / (aa.sqrt() * bb.sqrt())
}

/// Brute force over all points, written from the module doc's rule rather than the engine's code: a point
/// belongs to voxel (i, j) when the centre of its lattice cell lies inside the voxel's ground rectangle, and
/// to layer k by its exact height.
fn brute_force_counts(
    window: &PreparedWindow,
    layout: &FeatureLayout,
    hyp: &Hypothesis,
    subdivisions: u32,
) -> Vec<u32> {
    let grid = &window.scene.yaws[hyp.yaw_index as usize];
    let cell = grid.step / subdivisions as f32;
    let g = layout.grid();
    let e = layout.expansion();
    let extent = [hyp.size.x * e[0], hyp.size.y * e[1], hyp.size.z * e[2]];
    let lo = [
        hyp.centre.x - 0.5 * extent[0],
        hyp.centre.y - 0.5 * extent[1],
        hyp.bottom + 0.5 * hyp.size.z - 0.5 * extent[2],
    ];
    let voxel = [0, 1, 2].map(|a| extent[a] / g[a] as f32);
    let cells = [0, 1].map(|a| grid.cells[a] * subdivisions);
    let mut counts = vec![0u32; layout.voxel_count()];
    for r in &grid.records {
        let q = [r.s, r.t, r.z].map(|v| v as f32 / FIXED_PER_METRE);
        let mut index = [0u32; 3];
        let mut inside = true;
        for a in 0..2 {
            let c = ((q[a] - grid.origin[a]) / cell).floor().clamp(0.0, (cells[a] - 1) as f32);
            let centre = grid.origin[a] + (c + 0.5) * cell;
            // A centre on a face (to within 10⁻⁴ cell) belongs to the voxel above it.
            let i = ((centre + 1e-4 * cell - lo[a]) / voxel[a]).floor();
            inside &= i >= 0.0 && i < g[a] as f32;
            index[a] = i.max(0.0) as u32;
        }
        let k = ((q[2] - lo[2]) / voxel[2]).floor();
        inside &= k >= 0.0 && k < g[2] as f32;
        if inside {
            counts[layout.voxel_index(index[0], index[1], k as u32)] += 1;
        }
    }
    counts
}

#[test]
fn voxel_counts_equal_a_brute_force_count() {
    let w = window("chair", 0.1);
    for layout in [FeatureLayout::default(), FeatureLayout::new([3, 1, 3], true, Groups::GEOM).unwrap()] {
        for subdivisions in [1, 2, 3] {
            let engine = FastEngine::new(&w.scene, &layout, FastOptions { subdivisions });
            for hyp in sample(&w, 12) {
                let sums = engine.voxel_sums(&hyp);
                let counts: Vec<u32> = sums.iter().map(|s| s[0]).collect();
                let expected = brute_force_counts(&w, &layout, &hyp, subdivisions);
                assert_eq!(counts, expected, "{hyp:?}, subdivisions {subdivisions}");
                // Every counted point has exactly one normal code.
                for s in &sums {
                    assert_eq!(s[1..26].iter().sum::<u32>(), s[0]);
                }
                assert!(expected.iter().sum::<u32>() > 0);
            }
        }
    }
}

#[test]
fn fast_features_approach_the_exact_ones_as_the_lattice_refines() {
    let w = window("bed", 0.1);
    let layout = FeatureLayout::default();
    let hyps = sample(&w, 40);
    let (exact, _) = cpu::features(&w.scene, &layout, &hyps);
    let mean_cosine = |subdivisions: u32| {
        let fast = FastEngine::new(&w.scene, &layout, FastOptions { subdivisions }).features(&hyps);
        let dim = layout.dim();
        let cosines: Vec<f64> = exact.chunks(dim).zip(fast.chunks(dim)).map(|(a, b)| cosine(a, b)).collect();
        let min = cosines.iter().copied().fold(1.0, f64::min);
        (cosines.iter().sum::<f64>() / cosines.len() as f64, min)
    };
    let (coarse, _) = mean_cosine(1);
    let (default, default_min) = mean_cosine(2);
    let (fine, _) = mean_cosine(4);
    assert!(default > 0.95 && default_min > 0.8, "mean {default}, min {default_min}");
    assert!(coarse < default && default < fine, "{coarse} {default} {fine}");
}

#[test]
fn fused_scores_are_the_dot_products_of_the_features_and_reproducible() {
    let w = window("table", 0.1);
    let layout = FeatureLayout::default();
    let hyps = sample(&w, 60);
    let engine = FastEngine::new(&w.scene, &layout, FastOptions::default());
    let features = engine.features(&hyps);
    let weights: Vec<Vec<f32>> = (0..3)
        .map(|seed| (0..layout.dim()).map(|n| (((n * 7919 + seed * 104729) % 2001) as f32 - 1000.0) * 1e-3).collect())
        .collect();
    let scores = engine.scores(&hyps, &weights);
    for (h, row) in features.chunks(layout.dim()).enumerate() {
        for (k, wk) in weights.iter().enumerate() {
            let expected: f64 = row.iter().zip(wk).map(|(&a, &b)| a as f64 * b as f64).sum();
            let got = scores[h * weights.len() + k] as f64;
            assert!((got - expected).abs() <= 1e-4 * (1.0 + expected.abs()), "hyp {h} w {k}: {got} vs {expected}");
        }
    }
    // The same input gives the same bits, whatever the scheduling.
    let again = FastEngine::new(&w.scene, &layout, FastOptions::default()).scores(&hyps, &weights);
    assert_eq!(
        scores.iter().map(|s| s.to_bits()).collect::<Vec<_>>(),
        again.iter().map(|s| s.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn switched_off_groups_stay_zero() {
    let w = window("chair", 0.2);
    let layout = FeatureLayout::new([5, 5, 5], true, Groups::GEOM).unwrap();
    let hyps = sample(&w, 10);
    let features = FastEngine::new(&w.scene, &layout, FastOptions::default()).features(&hyps);
    let mask = layout.mask();
    for row in features.chunks(layout.dim()) {
        assert!(row.iter().zip(&mask).all(|(&v, &on)| on || v == 0.0));
        assert!(row.iter().any(|&v| v > 0.0));
    }
}

/// The eight-lane dot product of the fast path: exact on small integers (every partial sum representable),
/// within float rounding of an f64 dot product otherwise, for every length around the lane count.
#[test]
fn lane_dot_products_equal_the_plain_dot_product() {
    use cog_gpu::features::fast::dot_lanes;
    let mut state = 12345u64;
    let mut next = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    for len in 0..=41 {
        let a: Vec<f32> = (0..len).map(|_| (next() * 8.0).round()).collect();
        let b: Vec<f32> = (0..len).map(|_| (next() * 8.0).round()).collect();
        let exact: f32 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert_eq!(dot_lanes(&a, &b), exact, "integers, length {len}");
        let a: Vec<f32> = (0..len).map(|_| next()).collect();
        let b: Vec<f32> = (0..len).map(|_| next() * 100.0).collect();
        let reference: f64 = a.iter().zip(&b).map(|(x, y)| *x as f64 * *y as f64).sum();
        let magnitude: f64 = a.iter().zip(&b).map(|(x, y)| (*x as f64 * *y as f64).abs()).sum();
        let got = dot_lanes(&a, &b) as f64;
        assert!((got - reference).abs() <= 1e-6 * magnitude.max(1e-30), "length {len}: {got} vs {reference}");
    }
}

/// Engines of one scene whose layouts differ only in the voxel grid share their per-yaw lattices
/// (`FastEngine::sharing_lattices`, used by `detect`): their scores equal those of an engine that binned
/// the points itself, bit for bit; engines that bin COG differently do not share.
#[test]
fn engines_sharing_lattices_score_as_engines_of_their_own() {
    let w = window("chair", 0.2);
    let large = FeatureLayout::default();
    let small = FeatureLayout::new([3, 3, 3], false, Groups::ALL).unwrap();
    let hyps = sample(&w, 30);
    let first = FastEngine::new(&w.scene, &large, FastOptions::default());
    let shared = FastEngine::sharing_lattices(&first, &small, FastOptions::default()).expect("same lattices");
    let own = FastEngine::new(&w.scene, &small, FastOptions::default());
    let weights = vec![(0..small.dim()).map(|n| ((n * 37 % 101) as f32 - 50.0) * 0.01).collect::<Vec<f32>>()];
    let bits = |e: &FastEngine| e.scores(&hyps, &weights).iter().map(|s| s.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&shared), bits(&own));
    assert!(bits(&own).iter().any(|&b| f32::from_bits(b) != 0.0));
    // Other subdivisions, or no COG where the first engine bins it: lattices of their own.
    assert!(FastEngine::sharing_lattices(&first, &small, FastOptions { subdivisions: 3 }).is_none());
    let geometry_only = FeatureLayout::new([3, 3, 3], false, Groups::GEOM).unwrap();
    assert!(FastEngine::sharing_lattices(&first, &geometry_only, FastOptions::default()).is_none());
}

/// The call-free floor and ceiling of the sliding window, lattices and tables equal `f32::floor` and
/// `f32::ceil` cast to i64 on every kind of f32: integers and their neighbours, halves, signed zeros, the
/// 2²⁴ boundary where every f32 becomes an integer, huge values, infinities and NaN (all saturating casts).
#[test]
fn call_free_floor_and_ceiling_equal_the_library_ones() {
    use cog_gpu::features::scene::{ceil_to_i64, floor_to_i64};
    let mut values = vec![0.0f32, -0.0, 0.5, -0.5, 1e-30, -1e-30, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, f32::MAX];
    values.push(f32::MIN);
    for k in -40..=40 {
        let x = k as f32 * 0.25;
        values.extend([x, f32::from_bits(x.to_bits().wrapping_add(1)), f32::from_bits(x.to_bits().wrapping_sub(1))]);
    }
    for e in [23, 24, 25, 31, 62, 63, 64, 70] {
        let big = 2f32.powi(e);
        values.extend([big, -big, f32::from_bits(big.to_bits() - 1), -f32::from_bits(big.to_bits() - 1)]);
    }
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..100_000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        values.push(f32::from_bits(state as u32));
    }
    for x in values {
        assert_eq!(floor_to_i64(x), x.floor() as i64, "floor of {x:e} ({:#x})", x.to_bits());
        assert_eq!(ceil_to_i64(x), x.ceil() as i64, "ceil of {x:e} ({:#x})", x.to_bits());
    }
}
