//! Feature-engine throughput on the real frame: preprocessing, fused scoring of a fixed, evenly spread
//! subset of the bed sliding window on the exact CPU path and (when an adapter exists) the GPU path, and the
//! fast path on the whole bed window (lattice, tables and scores) on the CPU and (when an adapter exists)
//! with the GPU scoring kernel (`gpu::fast`).
//! `cargo bench --bench features`; `cog-gpu bench` reports the full window with the same code.

use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use cog_gpu::features::fast::{FastEngine, FastOptions};
use cog_gpu::features::window::{category_sizes, DEFAULT_SIZE_STATS};
use cog_gpu::features::{cpu, FeatureLayout, Hypothesis, PreparedWindow, Preprocessed};
use cog_gpu::frame::{DepthSource, Frame};

const FRAME: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";
/// Hypotheses scored per iteration (evenly spread over the kept ones).
const SUBSET: usize = 64;

fn subset(all: &[Hypothesis]) -> Vec<Hypothesis> {
    let step = (all.len() / SUBSET).max(1);
    all.iter().step_by(step).take(SUBSET).copied().collect()
}

fn weights(dim: usize) -> Vec<Vec<f32>> {
    vec![(0..dim).map(|n| ((n * 7919) % 200) as f32 / 100.0 - 1.0).collect()]
}

fn bench(c: &mut Criterion) {
    let frame = Frame::read(FRAME, DepthSource::Raw).expect("real frame");
    let mut group = c.benchmark_group("features");
    group.sample_size(10);
    group.bench_function("preprocess", |b| b.iter(|| Preprocessed::from_frame(&frame).expect("preprocess")));
    let sizes = category_sizes(Path::new(DEFAULT_SIZE_STATS), "bed").expect("size statistics");
    let window = PreparedWindow::new(&frame, sizes, 0.1, 50).expect("window");
    let hyps = subset(&window.set.hypotheses);
    let layout = FeatureLayout::default();
    let w = weights(layout.dim());
    group.throughput(Throughput::Elements(hyps.len() as u64));
    group.bench_function("score_cpu", |b| b.iter(|| cpu::scores(&window.scene, &layout, &hyps, &w)));
    let gpu = cog_gpu::gpu::acquire(false);
    if let Some(ctx) = &gpu {
        group.bench_function("score_gpu", |b| {
            b.iter(|| cog_gpu::gpu::features::scores_gpu(ctx, &window.scene, &layout, &hyps, &w).expect("gpu scoring"))
        });
    }
    let all = &window.set.hypotheses;
    group.throughput(Throughput::Elements(all.len() as u64));
    group.bench_function("score_fast_full_window", |b| {
        b.iter(|| FastEngine::new(&window.scene, &layout, FastOptions::default()).scores(all, &w))
    });
    if let Some(ctx) = &gpu {
        group.bench_function("score_fast_gpu_full_window", |b| {
            b.iter(|| {
                let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
                cog_gpu::gpu::fast::fast_scores_gpu(ctx, &engine, all, &w).expect("fast gpu scoring")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
