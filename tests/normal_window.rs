//! Normals from an image window (`NormalSearch::Window`): the neighbour search against a reference that
//! sorts every window pixel, hand-made cases (a plane, ties, borders, missing points), the agreement
//! measure, and the `normal_window` kernel against its CPU twin on the GPU (lavapipe in CI), mask for mask
//! and normal for normal, with its constants and struct checked against the Rust side by naga.

mod common;

use std::path::Path;

use cog_gpu::features::hypotheses::default_yaws;
use cog_gpu::features::preprocess::{
    estimate_normals, normal_agreement, point_grid, window_neighbour_mask, window_normals, NormalSearch, Preprocessed,
    NORMAL_NEIGHBOURS, NORMAL_WINDOW, NORMAL_WINDOW_CLAMP, NORMAL_WINDOW_UNITS,
};
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::gpu::normal_window::{normal_window_cpu, normal_window_gpu, NormalWindowParams};
use cog_gpu::gpu::preprocess::gradients_and_normals_gpu;
use cog_gpu::synth::{self, SynthOptions};
use common::{gpu_context, shader_module, wgsl_const, wgsl_const_f32, wgsl_struct_size};
use glam::Vec3;

/// Reference search: every window pixel with a point, its squared offset computed in i64 from the same
/// fixed-point rule, sorted by (distance, slot), the first 15 kept.
fn reference_mask(grid: &[[f32; 4]], width: u32, height: u32, col: u32, row: u32) -> [u32; 2] {
    let centre = grid[(row * width + col) as usize];
    if centre[3] == 0.0 {
        return [0, 0];
    }
    let r = (NORMAL_WINDOW / 2) as i64;
    let fixed = |a: f32, b: f32| -> i64 {
        let units = ((a - b) * NORMAL_WINDOW_UNITS).floor();
        units.clamp(-NORMAL_WINDOW_CLAMP, NORMAL_WINDOW_CLAMP) as i64
    };
    let mut candidates: Vec<(i64, u32)> = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            let (c, rr) = (col as i64 + dx, row as i64 + dy);
            if c < 0 || rr < 0 || c >= width as i64 || rr >= height as i64 {
                continue;
            }
            let p = grid[(rr as u32 * width + c as u32) as usize];
            if p[3] == 0.0 {
                continue;
            }
            let d: i64 = (0..3).map(|k| fixed(p[k], centre[k]).pow(2)).sum();
            candidates.push((d, ((dy + r) * NORMAL_WINDOW as i64 + dx + r) as u32));
        }
    }
    candidates.sort();
    let mut mask = [0u32; 2];
    for &(_, slot) in candidates.iter().take(NORMAL_NEIGHBOURS) {
        mask[(slot / 32) as usize] |= 1 << (slot % 32);
    }
    mask
}

fn synthetic_frame() -> Frame {
    synth::generate_frame(5, 0, &SynthOptions::small(160, 120)).unwrap().frame
}

fn sample_frame() -> Frame {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/sample/kv1-b3dodata-img_0063");
    Frame::read(&dir, DepthSource::Raw).unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
}

fn grid_of(frame: &Frame) -> (Vec<[f32; 4]>, u32, u32) {
    let cloud = frame.point_cloud();
    (point_grid([frame.width(), frame.height()], &cloud.points, &cloud.pixels), frame.width(), frame.height())
}

#[test]
fn window_search_equals_a_sorting_reference_on_frames() {
    for frame in [synthetic_frame(), sample_frame()] {
        let (grid, width, height) = grid_of(&frame);
        // Every pixel of the small synthetic frame; every 7th of the real one (about 40 000).
        let stride = if width * height > 100_000 { 7 } else { 1 };
        let mut checked = 0;
        for pixel in (0..width * height).step_by(stride) {
            let (col, row) = (pixel % width, pixel / width);
            assert_eq!(
                window_neighbour_mask(&grid, width, height, col, row),
                reference_mask(&grid, width, height, col, row),
                "{}: pixel ({col}, {row})",
                frame.name
            );
            checked += 1;
        }
        assert!(checked > 10_000, "{checked}");
    }
}

/// A grid whose points lie on one plane, `height` rows of `width` pixels, 1 cm apart.
fn plane_grid(width: u32, height: u32, normal: Vec3) -> Vec<[f32; 4]> {
    let (u, v) = (normal.any_orthonormal_pair().0, normal.any_orthonormal_pair().1);
    let origin = Vec3::new(0.1, 2.0, -0.3);
    (0..width * height)
        .map(|pixel| {
            let (col, row) = ((pixel % width) as f32, (pixel / width) as f32);
            let p = origin + u * (0.01 * col) + v * (0.01 * row);
            [p.x, p.y, p.z, 1.0]
        })
        .collect()
}

#[test]
fn window_normals_of_a_plane_are_its_normal_toward_the_camera() {
    let (width, height) = (12u32, 9u32);
    // Tilted plane; the camera at the origin sees it from the side the normal points to after the flip.
    let normal = Vec3::new(0.3, -0.8, 0.5).normalize();
    let grid = plane_grid(width, height, normal);
    let pixels: Vec<[u32; 2]> = (0..width * height).map(|p| [p % width, p / width]).collect();
    let points: Vec<Vec3> = grid.iter().map(|p| Vec3::new(p[0], p[1], p[2])).collect();
    let normals = window_normals([width, height], &points, &pixels);
    for (p, n) in points.iter().zip(&normals) {
        let expected = if normal.dot(-*p) < 0.0 { -normal } else { normal };
        assert!((*n - expected).length() < 1e-5, "{p}: {n} against {expected}");
    }
    // The k-d tree's normals of the same points agree (all within one plane).
    let agreement = normal_agreement(&normals, &estimate_normals(&points), &default_yaws());
    assert!(agreement.same_code > 0.999 && agreement.median_angle_deg < 1e-3, "{agreement:?}");
}

#[test]
fn window_search_hand_cases() {
    let (width, height) = (9u32, 8u32);
    // All points at one place: every distance is 0, so the earliest 15 slots of the window win.
    let same = vec![[1.0f32, 2.0, 0.5, 1.0]; (width * height) as usize];
    assert_eq!(window_neighbour_mask(&same, width, height, 4, 4), [(1 << 15) - 1, 0]);
    // The corner pixel: its window holds the 4×4 pixels below and right of it, slots 24..27, 31..34,
    // 38..41, 45..48; the first 15 of those 16 in slot order.
    let corner = window_neighbour_mask(&same, width, height, 0, 0);
    let slots: Vec<u32> = (0..49).filter(|s| corner[(s / 32) as usize] >> (s % 32) & 1 == 1).collect();
    assert_eq!(slots, vec![24, 25, 26, 27, 31, 32, 33, 34, 38, 39, 40, 41, 45, 46, 47]);
    // A pixel without a point has no mask; a point with only 2 neighbours gets 3 bits.
    let mut sparse = vec![[0.0f32; 4]; (width * height) as usize];
    assert_eq!(window_neighbour_mask(&sparse, width, height, 4, 4), [0, 0]);
    for (col, row) in [(4, 4), (5, 4), (4, 6)] {
        sparse[(row * width + col) as usize] = [0.01 * col as f32, 2.0, -0.01 * row as f32, 1.0];
    }
    // Slots: centre (3,3) = 24, (4,3) = 25, (3,5) = 38.
    assert_eq!(window_neighbour_mask(&sparse, width, height, 4, 4), [1 << 24 | 1 << 25, 1 << (38 - 32)]);
    // Fewer than 3 points give the normal toward the camera.
    let lonely = [Vec3::new(0.3, 2.0, -0.4)];
    let normals = window_normals([1, 1], &lonely, &[[0, 0]]);
    assert!((normals[0] - (-lonely[0]).normalize()).length() < 1e-6);
}

#[test]
fn nearer_points_replace_farther_ones() {
    // A 7×7 window around (3, 3) whose points lie at distances growing with the slot, except that the
    // last 15 slots are moved close: they must be the chosen ones.
    let (width, height) = (7u32, 7u32);
    let mut grid = vec![[0.0f32; 4]; 49];
    for slot in 0..49u32 {
        let far = if slot == 24 {
            0.0
        } else if slot >= 34 {
            0.001 * (slot - 33) as f32
        } else {
            1.0 + 0.01 * slot as f32
        };
        grid[slot as usize] = [far, 2.0, 0.0, 1.0];
    }
    let mask = window_neighbour_mask(&grid, width, height, 3, 3);
    let slots: Vec<u32> = (0..49).filter(|s| mask[(s / 32) as usize] >> (s % 32) & 1 == 1).collect();
    let mut expected: Vec<u32> = vec![24];
    expected.extend(34..48);
    assert_eq!(slots, expected);
}

#[test]
fn agreement_of_known_normals() {
    let a: Vec<Vec3> = (0..10).map(|k| Vec3::new((k as f32).cos(), (k as f32).sin(), 0.0)).collect();
    let same = normal_agreement(&a, &a, &default_yaws());
    assert_eq!((same.points, same.same_code, same.median_angle_deg, same.within_10_deg), (10, 1.0, 0.0, 1.0));
    // Every normal turned 20° about z: angles 20° (none within 10°), and of the 16 yaws' eight 45°
    // sectors a horizontal normal keeps its sector for 25 of every 45 degrees of azimuth.
    let turn = glam::Mat3::from_rotation_z(20f32.to_radians());
    let b: Vec<Vec3> = a.iter().map(|n| turn * *n).collect();
    let turned = normal_agreement(&a, &b, &default_yaws());
    assert!((turned.median_angle_deg - 20.0).abs() < 1e-3, "{turned:?}");
    assert_eq!(turned.within_10_deg, 0.0);
    assert!(turned.same_code > 0.3 && turned.same_code < 0.8, "{turned:?}");
}

#[test]
fn normal_search_names_parse_and_bad_ones_say_which() {
    assert_eq!("kdtree".parse::<NormalSearch>().unwrap(), NormalSearch::KdTree);
    assert_eq!("window".parse::<NormalSearch>().unwrap(), NormalSearch::Window);
    assert_eq!(NormalSearch::default(), NormalSearch::KdTree);
    let error = "knn".parse::<NormalSearch>().unwrap_err().to_string();
    assert!(error.contains("'knn'") && error.contains("kdtree, window"), "{error}");
}

#[test]
fn preprocessing_with_window_normals_keeps_everything_else() {
    let frame = synthetic_frame();
    let kd = Preprocessed::from_frame_with(&frame, NormalSearch::KdTree).unwrap();
    let window = Preprocessed::from_frame_with(&frame, NormalSearch::Window).unwrap();
    assert_eq!(kd.points, window.points);
    assert_eq!(kd.gradients, window.gradients);
    assert_eq!(kd.floor, window.floor);
    let cloud = frame.point_cloud();
    assert_eq!(window.normals, window_normals([frame.width(), frame.height()], &cloud.points, &cloud.pixels));
    assert!(window.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-5));
}

#[test]
fn normal_window_shader_shares_its_constants_and_struct_with_rust() {
    let module = shader_module("normal_window.wgsl");
    assert_eq!(wgsl_const(&module, "NORMAL_WINDOW"), NORMAL_WINDOW as i64);
    assert_eq!(wgsl_const(&module, "NORMAL_NEIGHBOURS"), NORMAL_NEIGHBOURS as i64);
    assert_eq!(wgsl_const_f32(&module, "NORMAL_WINDOW_UNITS").to_bits(), NORMAL_WINDOW_UNITS.to_bits());
    assert_eq!(wgsl_const_f32(&module, "NORMAL_WINDOW_CLAMP").to_bits(), NORMAL_WINDOW_CLAMP.to_bits());
    assert_eq!(wgsl_struct_size(&module, "NormalWindowParams"), std::mem::size_of::<NormalWindowParams>());
}

#[test]
fn normal_window_kernel_equals_its_cpu_twin() {
    let Some(ctx) = gpu_context() else { return };
    for frame in [synthetic_frame(), sample_frame()] {
        let (grid, width, height) = grid_of(&frame);
        let gpu = normal_window_gpu(&ctx, &grid, width, height).unwrap();
        let cpu = normal_window_cpu(&grid, width, height).unwrap();
        assert_eq!(gpu.len(), cpu.len());
        let differing = gpu.iter().zip(&cpu).filter(|(g, c)| g != c).count();
        assert_eq!(differing, 0, "{}: {differing} of {} masks differ", frame.name, cpu.len());
        // And so the normals, bit for bit.
        let cloud = frame.point_cloud();
        let (_, on_gpu) = gradients_and_normals_gpu(&ctx, &frame.rgb, &cloud, NormalSearch::Window).unwrap();
        let on_cpu = window_normals([width, height], &cloud.points, &cloud.pixels);
        assert!(on_gpu
            .iter()
            .zip(&on_cpu)
            .all(|(g, c)| g.to_array().map(f32::to_bits) == c.to_array().map(f32::to_bits)));
    }
    // A grid of the wrong size is an error, not a read out of bounds.
    let error = normal_window_gpu(&ctx, &[[0.0; 4]; 5], 3, 2).unwrap_err().to_string();
    assert!(error.contains("5 grid pixels for a 3×2 image"), "{error}");
}

#[test]
fn model_files_record_their_normal_search_only_when_not_the_default() {
    use cog_gpu::model::{common_normal_search, Model};
    let dir = tempfile::tempdir().unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/models/bed.json");
    let bed = Model::read(&shipped).unwrap();
    assert_eq!(bed.features.normals, NormalSearch::KdTree);
    // A model of the default search is written without the field: its `features` as in the file (and the
    // `detect --resume` fingerprint, which hashes the model's JSON, as before the field existed).
    let same = dir.path().join("bed.json");
    bed.write(&same).unwrap();
    let json = |p: &Path| serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(p).unwrap()).unwrap();
    assert_eq!(json(&same)["features"], json(&shipped)["features"]);
    assert!(json(&same)["features"].get("normals").is_none());
    // With the window search the field is written and read back.
    let mut window = bed.clone();
    window.features.normals = NormalSearch::Window;
    let path = dir.path().join("window.json");
    window.write(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains(r#""normals":"window""#), "{text}");
    assert_eq!(Model::read(&path).unwrap().features.normals, NormalSearch::Window);
    // So with the 40 nearest (`kdtree-40`).
    let mut wide = bed.clone();
    wide.features.normals = NormalSearch::KdTreeWide;
    let wide_path = dir.path().join("wide.json");
    wide.write(&wide_path).unwrap();
    assert!(std::fs::read_to_string(&wide_path).unwrap().contains(r#""normals":"kdtree-40""#));
    assert_eq!(Model::read(&wide_path).unwrap().features.normals, NormalSearch::KdTreeWide);
    // The models of a run must agree; an error names two that do not.
    assert_eq!(common_normal_search(&[]).unwrap(), NormalSearch::KdTree);
    assert_eq!(common_normal_search(&[window.clone(), window.clone()]).unwrap(), NormalSearch::Window);
    let mut chair = bed.clone();
    chair.category = "chair".into();
    let error = common_normal_search(&[window, chair]).unwrap_err().to_string();
    assert!(error.contains("bed: window") && error.contains("chair: kdtree"), "{error}");
}

#[test]
fn detect_takes_the_models_normal_search_and_refuses_a_mixed_set() {
    use cog_gpu::model::Model;
    let dir = tempfile::tempdir().unwrap();
    let models = dir.path().join("models");
    std::fs::create_dir_all(&models).unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/models");
    let mut bed = Model::read(&shipped.join("bed.json")).unwrap();
    bed.features.normals = NormalSearch::Window;
    bed.write(&models.join("bed.json")).unwrap();
    let frame = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/sample/synth-bedroom-s52");
    let bench = |extra: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
            .args(["--cpu", "bench", "--detect", frame.to_str().unwrap(), "--models", models.to_str().unwrap()])
            .args(["--warmup", "0", "--json"])
            .args(extra)
            .output()
            .unwrap()
    };
    // The model's own search, unless --normals says otherwise (with a warning).
    let output = bench(&[]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(report["normals"], "window");
    let output = bench(&["--normals", "kdtree"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success() && stderr.contains("trained with the window normals"), "{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(report["normals"], "kdtree");
    // Models trained with different searches: an error naming the directory and two of them.
    std::fs::copy(shipped.join("chair.json"), models.join("chair.json")).unwrap();
    let output = bench(&[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(stderr.contains(models.to_str().unwrap()) && stderr.contains("bed: window, chair: kdtree"), "{stderr}");
}

#[test]
fn normal_search_names_parse_back_and_an_unknown_one_is_named() {
    for search in NormalSearch::ALL {
        assert_eq!(search.name().parse::<NormalSearch>().unwrap(), search);
        // The model files' spelling is the command line's.
        assert_eq!(serde_json::to_string(&search).unwrap(), format!("\"{}\"", search.name()));
    }
    let error = "octree".parse::<NormalSearch>().unwrap_err().to_string();
    assert!(error.contains("'octree'") && error.contains("kdtree, window"), "{error}");
}
