//! Writing and reading frames, datasets, and the errors for bad input (each names the file and the problem).

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use cog_gpu::frame::{Dataset, DepthSource, Frame, Object, RoomLayout};
use cog_gpu::geometry::Cuboid;
use glam::{DMat3, Vec2, Vec3};

const KV1: &str = "../shared/data/sunrgbd/kv1-b3dodata-img_0063";

/// A small frame made by hand: a gradient image, depth with holes and values above 8 m, a tilted camera.
fn handmade_frame() -> Frame {
    let (w, h) = (9u32, 7u32);
    let rgb = image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 20) as u8, (y * 30) as u8, 77]));
    let depth_mm: Vec<u16> =
        (0..w * h).map(|i| if i % 5 == 0 { 0 } else { (300 + i * 137) as u16 }).chain([]).collect();
    let mut depth_mm = depth_mm;
    depth_mm[3] = 9_500; // beyond the 8 m clamp: stored as is, clamped when read as metres
    depth_mm[4] = 65_535;
    let mut frame = Frame {
        name: "handmade".into(),
        rgb,
        depth_mm,
        k: [[520.5, 0.0, 4.25], [0.0, 519.75, 3.5], [0.0, 0.0, 1.0]],
        extrinsics: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        scene: Some("office".into()),
        objects: vec![
            Object {
                category: "chair".into(),
                label: None,
                cuboid: Cuboid::new(Vec3::new(0.4, 2.1, -0.9), Vec3::new(0.5, 0.6, 0.9), 0.3),
            },
            Object {
                category: "nightstand".into(),
                label: Some("left one".into()),
                cuboid: Cuboid::new(Vec3::new(-1.25, 3.5, -1.1), Vec3::new(0.45, 0.4, 0.55), -2.9),
            },
            Object {
                category: "bed".into(),
                label: None,
                cuboid: Cuboid::new(Vec3::new(1.0, 3.0, -1.0), Vec3::new(1.6, 2.0, 0.6), 3.0),
            },
        ],
        layout: Some(RoomLayout {
            corners: vec![Vec2::new(-2.0, 0.5), Vec2::new(2.5, 0.5), Vec2::new(2.5, 5.0), Vec2::new(-2.0, 5.0)],
            floor: -1.35,
            ceiling: 1.2,
        }),
    };
    // Pitch 20° down and roll 3°, as a gravity rotation.
    let rtilt = DMat3::from_rotation_x(-20f64.to_radians()) * DMat3::from_rotation_y(3f64.to_radians());
    frame.set_rtilt(rtilt);
    frame
}

fn angle_diff(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(std::f32::consts::TAU);
    d.min(std::f32::consts::TAU - d)
}

#[test]
fn write_then_read_gives_the_frame_back() {
    let frame = handmade_frame();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("handmade");
    frame.write(&path).unwrap();
    let back = Frame::read(&path, DepthSource::Raw).unwrap();
    assert_eq!(back.name, "handmade");
    assert_eq!(back.rgb, frame.rgb, "RGB is written losslessly");
    assert_eq!(back.depth_mm, frame.depth_mm, "depth in mm is identical");
    assert_eq!(back.k, frame.k, "K is identical");
    assert_eq!(back.extrinsics, frame.extrinsics, "E is identical");
    let (r0, r1) = (frame.rtilt_f64(), back.rtilt_f64());
    assert!((r0 - r1).to_cols_array().iter().all(|x| *x == 0.0), "Rtilt is identical");
    assert_eq!(back.scene.as_deref(), Some("office"));
    assert_eq!(back.objects.len(), frame.objects.len());
    for (a, b) in frame.objects.iter().zip(&back.objects) {
        assert_eq!((&a.category, &a.label), (&b.category, &b.label));
        assert!((a.cuboid.centre - b.cuboid.centre).abs().max_element() < 1e-6, "{a:?} vs {b:?}");
        assert!((a.cuboid.size - b.cuboid.size).abs().max_element() < 1e-6, "{a:?} vs {b:?}");
        assert!(angle_diff(a.cuboid.yaw, b.cuboid.yaw) < 1e-6, "{a:?} vs {b:?}");
    }
    let (la, lb) = (frame.layout.unwrap(), back.layout.unwrap());
    assert_eq!(la.corners, lb.corners);
    assert!((la.floor - lb.floor).abs() < 1e-6 && (la.ceiling - lb.ceiling).abs() < 1e-6);
}

#[test]
fn depth_encoding_and_clamp() {
    // The toolbox stores mm rotated left by 3 bits: 1000 mm = 0b1111101000 → 0b1111101000000 = 8000.
    assert_eq!(cog_gpu::frame::encode_depth_value(1000), 8000);
    assert_eq!(cog_gpu::frame::decode_depth_value(8000), 1000);
    // The top 3 bits wrap around to the bottom: 0xE001 → 0x000F.
    assert_eq!(cog_gpu::frame::encode_depth_value(0xE001), 0x000F);
    assert_eq!(cog_gpu::frame::depth_metres(9_500), 8.0);
    assert_eq!(cog_gpu::frame::depth_metres(2_345), 2.345);
}

#[test]
fn point_cloud_of_the_handmade_frame_by_hand() {
    let mut frame = handmade_frame();
    frame.set_rtilt(DMat3::IDENTITY);
    let cloud = frame.point_cloud();
    assert_eq!(cloud.len(), frame.valid_depth());
    // Pixel (col 1, row 0) is index 1: depth 300 + 137 = 437 mm. With 1-based u = 2, v = 1:
    // x = (2 − 4.25)·0.437/520.5, y = (1 − 3.5)·0.437/519.75, upright (x, z, −y).
    let i = cloud.pixels.iter().position(|p| *p == [1, 0]).unwrap();
    let (z, x, y) = (0.437f64, (2.0 - 4.25) * 0.437 / 520.5, (1.0 - 3.5) * 0.437 / 519.75);
    let expect = Vec3::new(x as f32, z as f32, -y as f32);
    assert!((cloud.points[i] - expect).abs().max_element() < 1e-7);
    // A value above 8 m is clamped to 8 m.
    let j = cloud.pixels.iter().position(|p| *p == [3, 0]).unwrap();
    assert!((cloud.points[j].y - 8.0).abs() < 1e-6);
    assert_eq!(cloud.colours[i], [20, 0, 77]);
}

/// Copies the real frame into a temporary directory so one file can be broken.
fn copy_of_real_frame() -> (tempfile::TempDir, PathBuf) {
    fn copy_dir(from: &Path, to: &Path) {
        fs::create_dir_all(to).unwrap();
        for entry in fs::read_dir(from).unwrap() {
            let entry = entry.unwrap();
            let target = to.join(entry.file_name());
            if entry.file_type().unwrap().is_dir() {
                copy_dir(&entry.path(), &target);
            } else {
                fs::copy(entry.path(), target).unwrap();
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let frame = dir.path().join("img_0063");
    copy_dir(Path::new(KV1), &frame);
    (dir, frame)
}

fn read_error(frame: &Path) -> String {
    match Frame::read(frame, DepthSource::Raw) {
        Ok(_) => panic!("reading {} should fail", frame.display()),
        Err(e) => e.to_string(),
    }
}

fn assert_names(message: &str, file: &str, problem: &str) {
    assert!(message.contains(file), "error should name {file}: {message}");
    assert!(message.to_lowercase().contains(problem), "error should say '{problem}': {message}");
}

#[test]
fn truncated_png_is_a_clear_error() {
    let (_dir, frame) = copy_of_real_frame();
    let depth = frame.join("depth").join("img_0063_abs.png");
    let bytes = fs::read(&depth).unwrap();
    fs::write(&depth, &bytes[..bytes.len() / 2]).unwrap();
    assert_names(&read_error(&frame), "img_0063_abs.png", "decode");
}

#[test]
fn depth_of_another_size_is_a_clear_error() {
    let (_dir, frame) = copy_of_real_frame();
    let depth = frame.join("depth").join("img_0063_abs.png");
    let small = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, vec![8000u16; 12]).unwrap();
    small.save(&depth).unwrap();
    let message = read_error(&frame);
    assert_names(&message, "img_0063_abs.png", "4×3");
    assert!(message.contains("561×427"), "{message}");
}

#[test]
fn eight_number_intrinsics_is_a_clear_error() {
    let (_dir, frame) = copy_of_real_frame();
    fs::write(frame.join("intrinsics.txt"), "520 0 277 0 520 215 0 0\n").unwrap();
    assert_names(&read_error(&frame), "intrinsics.txt", "found 8");
}

#[test]
fn nan_extrinsics_is_a_clear_error() {
    let (_dir, frame) = copy_of_real_frame();
    let file = frame.join("extrinsics").join("20140915210114.txt");
    fs::write(&file, "1 0 0 0\n0 NaN 0 0\n0 0 1 0\n").unwrap();
    assert_names(&read_error(&frame), "20140915210114.txt", "non-finite");
}

#[test]
fn non_rotation_extrinsics_is_a_clear_error() {
    let (_dir, frame) = copy_of_real_frame();
    let file = frame.join("extrinsics").join("20140915210114.txt");
    fs::write(&file, "2 0 0 0\n0 1 0 0\n0 0 1 0\n").unwrap();
    assert_names(&read_error(&frame), "20140915210114.txt", "not a rotation");
}

#[test]
fn wrongly_shaped_json_is_a_clear_error() {
    let (_dir, frame) = copy_of_real_frame();
    let file = frame.join("annotation3Dfinal").join("index.json");
    fs::write(&file, r#"{"objects": {"name": "chair"}}"#).unwrap();
    assert_names(&read_error(&frame), "index.json", "'objects' array");
    fs::write(&file, r#"{"objects": [{"name": "chair", "polygon": [{"X": [1, 2, "a", 4], "Z": [1, 2, 3, 4], "Ymin": 0, "Ymax": 1}]}]}"#).unwrap();
    assert_names(&read_error(&frame), "index.json", "non-number");
    fs::write(&file, "{not json").unwrap();
    assert_names(&read_error(&frame), "index.json", "malformed json");
}

#[test]
fn missing_pieces_are_clear_errors() {
    let (dir, frame) = copy_of_real_frame();
    assert_names(&read_error(&dir.path().join("nowhere")), "nowhere", "missing");
    fs::remove_dir_all(frame.join("depth")).unwrap();
    assert_names(&read_error(&frame), "depth", "no such file");
}

#[test]
fn dataset_finds_frames_recursively_and_reads_split_lists() {
    let dir = tempfile::tempdir().unwrap();
    let frame = handmade_frame();
    for name in ["a/one", "a/b/two", "three"] {
        frame.write(dir.path().join(name)).unwrap();
    }
    fs::create_dir_all(dir.path().join("empty/dir")).unwrap();
    let dataset = Dataset::open(dir.path()).unwrap();
    let names: Vec<String> =
        dataset.frames.iter().map(|p| p.strip_prefix(dir.path()).unwrap().display().to_string()).collect();
    assert_eq!(names, ["a/b/two", "a/one", "three"]);
    let list = dir.path().join("test.txt");
    fs::write(&list, "# test split\nthree\n\na/one\n").unwrap();
    let split = Dataset::open(dir.path()).unwrap().with_split(&list).unwrap();
    assert_eq!(split.frames, [dir.path().join("three"), dir.path().join("a/one")]);
    fs::write(&list, "three\nmissing\n").unwrap();
    let err = Dataset::open(dir.path()).unwrap().with_split(&list).unwrap_err().to_string();
    assert_names(&err, "test.txt", "line 2");
}

fn cog_gpu() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cog-gpu"))
}

#[test]
fn info_json_has_the_documented_keys() {
    let out = cog_gpu().args(["info", KV1, "--json"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "width",
        "height",
        "valid_depth",
        "bounds_min",
        "bounds_max",
        "floor",
        "ceiling",
        "floor_plane_cells",
        "unseen_floor",
        "objects",
        "layout",
    ] {
        assert!(v.get(key).is_some(), "missing key {key}");
    }
    assert_eq!(v["width"], 561);
    assert_eq!(v["valid_depth"], 162_067);
    let objects = v["objects"].as_array().unwrap();
    assert_eq!(objects.len(), 7);
    for key in ["category", "centre", "size", "yaw_deg", "points_inside"] {
        assert!(objects[0].get(key).is_some(), "object misses {key}");
    }
    assert_eq!(objects[2]["category"], "chair");
    assert_eq!(objects[2]["points_inside"], 13_882);
    for key in ["corners", "floor", "ceiling", "fraction_inside"] {
        assert!(v["layout"].get(key).is_some(), "layout misses {key}");
    }
}

#[test]
fn info_on_a_broken_frame_exits_non_zero_without_panicking() {
    let (_dir, frame) = copy_of_real_frame();
    fs::write(frame.join("intrinsics.txt"), "1 2 3\n").unwrap();
    let out = cog_gpu().arg("info").arg(&frame).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("intrinsics.txt") && stderr.contains("expected 9 numbers"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
