//! Image gradients (paper §3.2) through the `image_gradients` kernel's table: the CPU twin against the
//! definition ([`pixel_gradient`]) on frames and on noise images whose channels tie, the kernel against its
//! twin on the GPU (lavapipe in CI) bit for bit, and the shader's constants and
//! struct checked against the Rust side by naga.

mod common;

use std::path::Path;

use cog_gpu::features::preprocess::{gradient_table, pixel_gradient, table_gradient, ImageGradients, GRADIENT_LEVELS};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::gpu::image_gradients::{image_gradients_gpu, ImageGradientsParams};
use cog_gpu::gpu::normal_window::normal_window_cpu;
use cog_gpu::gpu::preprocess::{gradients_and_normals_gpu, preprocess_gpu, PointGrid};
use cog_gpu::synth::{self, SynthOptions};
use common::{gpu_context, shader_module, wgsl_const, wgsl_struct_size};

/// A `width × height` image of channel values below `levels` from a fixed xorshift sequence: with few
/// levels, channels often tie in their integer squared magnitude.
fn noise_image(width: u32, height: u32, levels: u32, seed: u64) -> image::RgbImage {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    image::RgbImage::from_fn(width, height, |_, _| {
        image::Rgb(std::array::from_fn(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 32) % levels as u64) as u8
        }))
    })
}

fn frame_images() -> Vec<(String, image::RgbImage)> {
    let mut images =
        vec![("synthetic".to_string(), synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap().frame.rgb)];
    for name in ["kv1-b3dodata-img_0063", "synth-bedroom-s52"] {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/sample").join(name);
        let frame = Frame::read(&dir, DepthSource::Raw).unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()));
        images.push((name.to_string(), frame.rgb));
    }
    images
}

/// Frames, and noise images of every shape the borders care about (one pixel, one row, one column).
fn test_images() -> Vec<(String, image::RgbImage)> {
    let mut images = frame_images();
    for (i, (width, height, levels)) in
        [(1, 1, 256), (7, 1, 256), (1, 7, 256), (13, 11, 256), (64, 48, 6), (64, 48, 3), (101, 37, 2)]
            .into_iter()
            .enumerate()
    {
        images
            .push((format!("noise {width}×{height} of {levels} levels"), noise_image(width, height, levels, i as u64)));
    }
    images
}

fn bits(g: [f32; 2]) -> [u32; 2] {
    g.map(f32::to_bits)
}

#[test]
fn the_twin_equals_the_definition_bit_for_bit() {
    let table = gradient_table();
    for (name, rgb) in test_images() {
        let (width, height) = rgb.dimensions();
        let computed = ImageGradients::compute(&rgb);
        for row in 0..height {
            for col in 0..width {
                let want = pixel_gradient(&rgb, col, row).to_array();
                let twin = table_gradient(rgb.as_raw(), width, height, table, col, row).to_array();
                assert_eq!(bits(twin), bits(want), "{name}: pixel ({col}, {row})");
                assert_eq!(bits(computed.at(col, row).to_array()), bits(want), "{name}: pixel ({col}, {row})");
            }
        }
    }
}

/// Why the table holds squares and not only differences: where two channels tie in their integer squared
/// magnitude (e.g. (3, 4) and (5, 0)), the definition's f32 sums decide, and they do not always pick the
/// first channel. A kernel comparing integers would differ from the CPU there; the twin does not.
#[test]
fn integer_ties_between_channels_are_decided_by_the_f32_sums() {
    let rgb = image::RgbImage::from_fn(3, 3, |col, row| {
        // Pixel (1, 1): red (right − left, down − up) = (3, 4), green (5, 0), blue (0, 5).
        let red = [[0, 0, 0], [0, 0, 3], [0, 4, 0]][row as usize][col as usize];
        let green = if col == 2 { 5 } else { 0 };
        let blue = if row == 2 { 5 } else { 0 };
        image::Rgb([red, green, blue])
    });
    let level = |b: u32| b as f32 * (1.0 / 255.0);
    let sq = |dx: u32, dy: u32| {
        let (x, y) = (level(dx) - level(0), level(dy) - level(0));
        (x * x + y * y, [x, y])
    };
    // The expectation by hand: the first channel of the largest f32 sum.
    let candidates = [sq(3, 4), sq(5, 0), sq(0, 5)];
    let mut want = candidates[0];
    for c in &candidates[1..] {
        if c.0 > want.0 {
            want = *c;
        }
    }
    let got = table_gradient(rgb.as_raw(), 3, 3, gradient_table(), 1, 1).to_array();
    assert_eq!(bits(got), bits(want.1));
    assert_eq!(bits(got), bits(pixel_gradient(&rgb, 1, 1).to_array()));

    // Over noise images of few levels, count the pixels where an integer comparison (first channel on
    // ties) would choose another gradient than the definition: the cases the table's squares are for.
    let integer_rule = |rgb: &image::RgbImage, col: u32, row: u32| {
        let (w, h) = rgb.dimensions();
        let at = |c: u32, r: u32, ch: usize| rgb.get_pixel(c, r).0[ch] as i32;
        let (l, r, u, d) = (col.saturating_sub(1), (col + 1).min(w - 1), row.saturating_sub(1), (row + 1).min(h - 1));
        let mut best = (-1, [0.0f32; 2]);
        for ch in 0..3 {
            let (dx, dy) = (at(r, row, ch) - at(l, row, ch), at(col, d, ch) - at(col, u, ch));
            if dx * dx + dy * dy > best.0 {
                let g = [
                    level(at(r, row, ch) as u32) - level(at(l, row, ch) as u32),
                    level(at(col, d, ch) as u32) - level(at(col, u, ch) as u32),
                ];
                best = (dx * dx + dy * dy, g);
            }
        }
        best.1
    };
    let mut differing = 0;
    for seed in 0..8 {
        let rgb = noise_image(64, 48, 6, seed);
        for row in 0..48 {
            for col in 0..64 {
                differing +=
                    (bits(integer_rule(&rgb, col, row)) != bits(pixel_gradient(&rgb, col, row).to_array())) as u32;
            }
        }
    }
    assert!(differing > 0, "no pixel where integer and f32 comparisons part: the tie case is not exercised");
}

#[test]
fn the_table_holds_the_definitions_differences_and_squares() {
    let table = gradient_table();
    assert_eq!(table.len(), (GRADIENT_LEVELS * GRADIENT_LEVELS) as usize);
    for (high, low) in [(0u32, 0u32), (255, 0), (0, 255), (128, 127), (3, 200)] {
        let d = high as f32 * (1.0 / 255.0) - low as f32 * (1.0 / 255.0);
        assert_eq!(bits(table[(high * GRADIENT_LEVELS + low) as usize]), bits([d, d * d]));
    }
    assert_eq!(table[(255 * GRADIENT_LEVELS) as usize][0], 1.0);
}

#[test]
fn image_gradients_shader_shares_its_constants_and_struct_with_rust() {
    let module = shader_module("image_gradients.wgsl");
    assert_eq!(wgsl_const(&module, "GRADIENT_LEVELS"), GRADIENT_LEVELS as i64);
    assert_eq!(wgsl_struct_size(&module, "ImageGradientsParams"), std::mem::size_of::<ImageGradientsParams>());
}

#[test]
fn image_gradients_kernel_equals_its_cpu_twin() {
    let Some(ctx) = gpu_context() else { return };
    for (name, rgb) in test_images() {
        let gpu = image_gradients_gpu(&ctx, &rgb).unwrap();
        let cpu: Vec<[f32; 2]> = ImageGradients::compute(&rgb).gradients.iter().map(|g| g.to_array()).collect();
        assert_eq!(gpu.len(), cpu.len(), "{name}");
        let differing = gpu.iter().zip(&cpu).filter(|(g, c)| bits(**g) != bits(**c)).count();
        assert_eq!(differing, 0, "{name}: {differing} of {} gradients differ", cpu.len());
    }
    // An empty image is an error, not a dispatch of nothing.
    let error = image_gradients_gpu(&ctx, &image::RgbImage::new(0, 4)).unwrap_err().to_string();
    assert!(error.contains("0×4 image"), "{error}");
}

/// The GPU path's preprocessing: both kernels in one submission through the context's pooled buffers give
/// what each gives alone and what the CPU twins give, frame after frame of different sizes (the pooled
/// buffers grown by a large frame and reused, not cleared, for smaller ones), and the same `Preprocessed`
/// as the CPU path.
#[test]
fn both_preprocessing_kernels_in_one_submission_equal_the_twins() {
    use cog_gpu::features::preprocess::{point_grid, window_normals, NormalSearch, Preprocessed};
    let Some(ctx) = gpu_context() else { return };
    let frames: Vec<Frame> = ["kv1-b3dodata-img_0063", "synth-bedroom-s52"]
        .into_iter()
        .map(|name| {
            Frame::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/sample").join(name), DepthSource::Raw)
                .unwrap()
        })
        .chain([synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap().frame])
        .collect();
    // Large, small, large again: the second large frame reads buffers the small one left stale.
    for frame in frames.iter().chain(&frames[..1]) {
        let (width, height) = (frame.width(), frame.height());
        let cloud = frame.point_cloud();
        let grid = point_grid([width, height], &cloud.points, &cloud.pixels);
        let both = preprocess_gpu(&ctx, Some(&frame.rgb), Some(PointGrid { grid: &grid, width, height })).unwrap();
        let gradients = both.gradients.expect("gradients asked for");
        let masks = both.masks.expect("masks asked for");
        let want_gradients: Vec<[f32; 2]> =
            ImageGradients::compute(&frame.rgb).gradients.iter().map(|g| g.to_array()).collect();
        assert!(gradients.iter().zip(&want_gradients).all(|(g, c)| bits(*g) == bits(*c)), "{}", frame.name);
        assert_eq!(gradients.len(), want_gradients.len());
        assert_eq!(masks, normal_window_cpu(&grid, width, height).unwrap(), "{}", frame.name);
        // The gradients kernel alone, through the same pooled buffers, gives the same floats.
        let alone = image_gradients_gpu(&ctx, &frame.rgb).unwrap();
        assert_eq!(alone.len(), gradients.len());
        assert!(alone.iter().zip(&gradients).all(|(a, b)| bits(*a) == bits(*b)), "{}", frame.name);
        // The whole stage as the GPU path runs it, against the CPU path's.
        let (image, normals) = gradients_and_normals_gpu(&ctx, &frame.rgb, &cloud, NormalSearch::Window).unwrap();
        let cpu = ImageGradients::compute(&frame.rgb);
        assert!(image.gradients.iter().zip(&cpu.gradients).all(|(g, c)| bits(g.to_array()) == bits(c.to_array())));
        let want_normals = window_normals([width, height], &cloud.points, &cloud.pixels);
        assert!(normals
            .iter()
            .zip(&want_normals)
            .all(|(g, c)| g.to_array().map(f32::to_bits) == c.to_array().map(f32::to_bits)));
        let via_kernels = Preprocessed::from_frame_using(frame, |rgb, cloud| {
            gradients_and_normals_gpu(&ctx, rgb, cloud, NormalSearch::KdTree)
        })
        .unwrap();
        let on_cpu = Preprocessed::from_frame(frame).unwrap();
        assert_eq!(via_kernels.gradients, on_cpu.gradients);
        assert_eq!(via_kernels.normals, on_cpu.normals);
        assert_eq!(via_kernels.points, on_cpu.points);
    }
    // Nothing asked, nothing done.
    let nothing = preprocess_gpu(&ctx, None, None).unwrap();
    assert!(nothing.gradients.is_none() && nothing.masks.is_none());
}
