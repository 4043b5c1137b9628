//! Malformed inputs for every reader and every command's numeric options, run through the binary as a
//! careless or unlucky user would: each case must end with exit status 1 (0 where the input is to be
//! accepted with a warning), never a panic, an abort or a hang, and its message must name the file or the
//! flag. The frames are tiny (32×24) so that the whole file runs in seconds.

use cog_gpu::features::Support;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use cog_gpu::features::LatticePhase;
use cog_gpu::features::YawAnchor;
use cog_gpu::features::{FeatureLayout, Groups, SizeQuantiles};
use cog_gpu::frame::{Frame, Object, RoomLayout};
use cog_gpu::geometry::Cuboid;
use cog_gpu::model::{FeaturePath, FeatureSettings, Model, WindowSettings};
use glam::{Vec2, Vec3};
use serde_json::Value;

const WIDTH: u32 = 32;
const HEIGHT: u32 = 24;
/// Longest any case may run: every case here is refused or finishes in well under a second.
const DEADLINE: Duration = Duration::from_secs(60);

/// The binary with `args`, quiet device selection, no backtraces, stdout and stderr piped.
fn cog_gpu(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_cog-gpu"));
    command
        .args(args)
        .env("NODEVICE_SELECT", "1")
        .env("RUST_BACKTRACE", "0")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    command
}

/// Runs the binary (on the CPU path) with a deadline (a hang fails the test instead of blocking it).
fn run(args: &[&str]) -> Output {
    let mut child = cog_gpu(&[&["--cpu"], args].concat()).spawn().expect("run cog-gpu");
    let start = Instant::now();
    while child.try_wait().expect("wait").is_none() {
        if start.elapsed() > DEADLINE {
            child.kill().ok();
            panic!("cog-gpu {args:?} did not finish in {DEADLINE:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("output")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The command fails with status 1, without a panic, and its message contains every `needles` entry.
fn assert_rejected(args: &[&str], needles: &[&str]) -> String {
    let out = run(args);
    let err = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{args:?} should fail with status 1: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for needle in needles {
        assert!(err.contains(needle), "{args:?}: expected '{needle}' in: {err}");
    }
    err
}

/// The command succeeds without a panic; returns stdout and stderr.
fn assert_accepted(args: &[&str]) -> (String, String) {
    let out = run(args);
    let err = stderr(&out);
    assert!(out.status.success(), "{args:?} should succeed: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    (String::from_utf8_lossy(&out.stdout).into_owned(), err)
}

/// A plausible frame: a wall 2–3 m away seen by a 32×24 camera (fx = 30), a bed annotated in front.
fn good_frame(name: &str) -> Frame {
    let depth_mm = (0..WIDTH * HEIGHT).map(|i| 2000 + (i % WIDTH) as u16 * 30).collect();
    let rgb = image::RgbImage::from_fn(WIDTH, HEIGHT, |x, y| image::Rgb([(x * 7) as u8, (y * 9) as u8, 90]));
    let bed = Cuboid::new(Vec3::new(0.0, 2.4, -0.2), Vec3::new(1.0, 0.8, 0.6), 0.0);
    Frame {
        name: name.into(),
        rgb,
        depth_mm,
        k: [[30.0, 0.0, 16.5], [0.0, 30.0, 12.5], [0.0, 0.0, 1.0]],
        extrinsics: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        scene: Some("bedroom".into()),
        objects: vec![Object { category: "bed".into(), label: None, cuboid: bed }],
        layout: Some(RoomLayout {
            corners: vec![Vec2::new(-3.0, 0.0), Vec2::new(3.0, 0.0), Vec2::new(3.0, 4.0), Vec2::new(-3.0, 4.0)],
            floor: -1.5,
            ceiling: 1.5,
        }),
    }
}

fn write_frame(dir: &Path, frame: &Frame) -> PathBuf {
    let path = dir.join(&frame.name);
    frame.write(&path).unwrap();
    path
}

fn text(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// A one-voxel density model (weight 1 on the density) for `category`.
fn model(category: &str) -> Model {
    let layout = FeatureLayout::new([1, 1, 1], false, Groups::GEOM).unwrap();
    let mut weights = vec![0.0; layout.dim()];
    weights[0] = 1.0;
    let sizes =
        SizeQuantiles { widths: vec![0.8, 0.9, 1.0, 1.1, 1.2], depths: vec![0.7, 0.8, 0.9], heights: vec![0.5; 3] };
    Model::new(
        category,
        layout,
        sizes,
        WindowSettings {
            step: 0.2,
            min_points: 5,
            yaw_anchor: YawAnchor::Walls,
            support: Support::Floor,
            lattice: LatticePhase::Camera,
            supporters: cog_gpu::category::SurfaceCategories::ALL,
        },
        FeatureSettings { path: FeaturePath::Fast, subdivisions: 2, normals: Default::default() },
        weights,
        Value::Null,
    )
    .unwrap()
}

fn models_dir(dir: &Path) -> PathBuf {
    let models = dir.join("models");
    std::fs::create_dir_all(&models).unwrap();
    model("bed").write(&models.join("bed.json")).unwrap();
    models
}

/// The annotation file of a frame with one object whose footprint has corners `xs`, `zs`.
fn annotation_with(xs: [f64; 4], zs: [f64; 4]) -> String {
    serde_json::json!({"objects": [{"name": "bed", "polygon": [{"X": xs, "Z": zs, "Ymin": -0.5, "Ymax": 0.5}]}]})
        .to_string()
}

#[test]
fn implausible_calibrations_are_rejected_naming_the_file_and_value() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, &[&str]); 7] = [
        ("0.01 0 16.5\n0 0.01 12.5\n0 0 1\n", &["intrinsics.txt", "fx = 0.01"]),
        ("1 0 16.5\n0 1 12.5\n0 0 1\n", &["intrinsics.txt", "fx = 1", "allowed"]),
        ("30 0 1e9\n0 30 12.5\n0 0 1\n", &["intrinsics.txt", "cx = 1000000000"]),
        ("30 0 16.5\n0 30 -1e9\n0 0 1\n", &["intrinsics.txt", "cy"]),
        ("30 2 16.5\n0 30 12.5\n0 0 1\n", &["intrinsics.txt", "skew"]),
        ("30 0 16.5\n0 -30 12.5\n0 0 1\n", &["intrinsics.txt", "positive"]),
        ("30 0 16.5\n0 30 12.5\n0 0\n", &["intrinsics.txt", "9 numbers"]),
    ];
    for (n, (k, needles)) in cases.iter().enumerate() {
        let dir = write_frame(tmp.path(), &good_frame(&format!("k{n}")));
        std::fs::write(dir.join("intrinsics.txt"), k).unwrap();
        assert_rejected(&["info", text(&dir)], needles);
    }
    let dir = write_frame(tmp.path(), &good_frame("e"));
    std::fs::write(dir.join("extrinsics/00000000000000.txt"), "2 0 0 0\n0 1 0 0\n0 0 1 0\n").unwrap();
    assert_rejected(&["info", text(&dir)], &["extrinsics", "rotation"]);
}

#[test]
fn broken_images_are_errors() {
    let tmp = tempfile::tempdir().unwrap();
    // A JPEG cut short in its entropy-coded data decodes without complaint in the decoder (the missing
    // part comes out grey): the reader must notice. A textured 256×192 image has enough of that data.
    let mut textured = good_frame("jpeg");
    let (w, h) = (WIDTH * 8, HEIGHT * 8);
    textured.rgb = image::RgbImage::from_fn(w, h, |x, y| {
        let v = (x.wrapping_mul(2654435761) ^ y.wrapping_mul(40503)).rotate_left(x % 13) as u8;
        image::Rgb([v, v.wrapping_mul(3), v ^ 0x5a])
    });
    textured.depth_mm = vec![2500; (w * h) as usize];
    textured.k = [[240.0, 0.0, 128.5], [0.0, 240.0, 96.5], [0.0, 0.0, 1.0]];
    let dir = write_frame(tmp.path(), &textured);
    let png = dir.join("image/jpeg.png");
    let jpeg = dir.join("image/jpeg.jpg");
    image::open(&png).unwrap().save(&jpeg).unwrap();
    std::fs::remove_file(&png).unwrap();
    assert_accepted(&["info", text(&dir)]);
    let bytes = std::fs::read(&jpeg).unwrap();
    std::fs::write(&jpeg, &bytes[..bytes.len() * 2 / 3]).unwrap();
    assert_rejected(&["info", text(&dir)], &["jpeg.jpg", "truncated"]);
    // The same cut with an end-of-image marker appended: the file ends as a JPEG should, but its
    // entropy-coded data runs out before the last rows.
    // Cut at two thirds, and just before the final marker (the last block's data incomplete).
    let marker = bytes.len() - 2;
    assert_eq!(bytes[marker..], [0xFF, 0xD9]);
    for cut in [bytes.len() * 2 / 3, marker - 3] {
        let mut cut_with_end = bytes[..cut].to_vec();
        cut_with_end.extend_from_slice(&[0xFF, 0xD9]);
        std::fs::write(&jpeg, &cut_with_end).unwrap();
        assert_rejected(&["info", text(&dir)], &["jpeg.jpg", "truncated", "image data runs out"]);
    }
    std::fs::write(&jpeg, &bytes).unwrap();
    assert_accepted(&["info", text(&dir)]);
    // A whole JPEG with padding after its end marker (a newline some tools append, zeros) is whole; a cut
    // one with the same padding is still truncated.
    for padding in [&b"\n"[..], b"\r\n \0\0\n"] {
        std::fs::write(&jpeg, [&bytes[..], padding].concat()).unwrap();
        assert_accepted(&["info", text(&dir)]);
        std::fs::write(&jpeg, [&bytes[..bytes.len() * 2 / 3], padding].concat()).unwrap();
        assert_rejected(&["info", text(&dir)], &["jpeg.jpg", "truncated"]);
    }
    std::fs::write(&jpeg, &bytes).unwrap();

    // A progressive JPEG and one with restart markers (`cjpeg -progressive`, `cjpeg -restart 1` of a
    // textured 96×64 image; tests/data/): read whole, and refused when cut short with an end marker.
    for fixture in ["progressive.jpg", "restart-markers.jpg"] {
        let bytes = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(fixture)).unwrap();
        let mut frame = good_frame("coded");
        frame.rgb = image::load_from_memory(&bytes).unwrap().to_rgb8();
        assert_eq!(frame.rgb.dimensions(), (96, 64), "{fixture}");
        frame.depth_mm = vec![2500; 96 * 64];
        frame.k = [[90.0, 0.0, 48.5], [0.0, 90.0, 32.5], [0.0, 0.0, 1.0]];
        let dir = write_frame(tmp.path(), &frame);
        std::fs::remove_file(dir.join("image/coded.png")).unwrap();
        let jpeg = dir.join("image/coded.jpg");
        std::fs::write(&jpeg, &bytes).unwrap();
        assert_accepted(&["info", text(&dir)]);
        let mut cut_with_end = bytes[..bytes.len() * 2 / 3].to_vec();
        cut_with_end.extend_from_slice(&[0xFF, 0xD9]);
        std::fs::write(&jpeg, &cut_with_end).unwrap();
        assert_rejected(&["info", text(&dir)], &["coded.jpg", "truncated", "image data runs out"]);
    }

    let dir = write_frame(tmp.path(), &good_frame("png"));
    let depth = dir.join("depth/png.png");
    let bytes = std::fs::read(&depth).unwrap();
    std::fs::write(&depth, &bytes[..bytes.len() - 12]).unwrap();
    assert_rejected(&["info", text(&dir)], &["depth/png.png"]);

    let dir = write_frame(tmp.path(), &good_frame("garbage"));
    std::fs::write(dir.join("image/garbage.png"), b"not an image at all").unwrap();
    assert_rejected(&["info", text(&dir)], &["garbage.png"]);

    // Too many pixels: refused from the header, before decoding.
    let dir = write_frame(tmp.path(), &good_frame("huge"));
    image::GrayImage::new(2100, 2100).save(dir.join("image/huge.png")).unwrap();
    assert_rejected(&["info", text(&dir)], &["huge.png", "pixels"]);

    // The depth map put where the picture belongs (a 16-bit grey PNG in image/) is refused; an 8-bit grey
    // picture is a picture (its grey in every channel) and is read.
    let dir = write_frame(tmp.path(), &good_frame("swapped"));
    std::fs::copy(dir.join("depth/swapped.png"), dir.join("image/swapped.png")).unwrap();
    assert_rejected(&["info", text(&dir)], &["image/swapped.png", "16-bit grey", "depth map"]);
    let grey = image::GrayImage::from_fn(WIDTH, HEIGHT, |x, y| image::Luma([(x * 7 + y * 3) as u8]));
    grey.save(dir.join("image/swapped.png")).unwrap();
    let (stdout, _) = assert_accepted(&["info", text(&dir)]);
    let frame = Frame::read(&dir, cog_gpu::frame::DepthSource::Raw).unwrap();
    assert_eq!(frame.rgb.get_pixel(5, 3).0, [44, 44, 44], "{stdout}");

    let dir = write_frame(tmp.path(), &good_frame("size"));
    let mut small = good_frame("size");
    small.rgb = image::RgbImage::new(WIDTH / 2, HEIGHT / 2);
    small.rgb.save(dir.join("image/size.png")).unwrap();
    assert_rejected(&["info", text(&dir)], &["depth/size.png", "RGB image"]);

    let file = tmp.path().join("plain.txt");
    std::fs::write(&file, "x").unwrap();
    assert_rejected(&["info", text(&file)], &["plain.txt", "is a file"]);
}

#[test]
fn bad_annotations_are_skipped_with_a_warning_naming_frame_and_object() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, String, &str); 5] = [
        ("collinear", annotation_with([0.0, 1.0, 2.0, 3.0], [2.0, 2.0, 2.0, 2.0]), "zero area"),
        ("bowtie", annotation_with([0.0, 2.0, 0.0, 3.0], [2.0, 4.0, 4.0, 2.0]), "intersects itself"),
        ("far", annotation_with([-1e30, 1e30, 1e30, -1e30], [2.0, 2.0, 1e30, 1e30]), "beyond"),
        ("point", annotation_with([1.0, 1.0, 1.0, 1.0], [2.0, 2.0, 2.0, 2.0]), "zero area"),
        ("huge", annotation_with([0.0, 50.0, 50.0, 0.0], [2.0, 2.0, 60.0, 60.0]), "larger than"),
    ];
    for (name, annotation, needle) in &cases {
        let dir = write_frame(tmp.path(), &good_frame(name));
        std::fs::write(dir.join("annotation3Dfinal/index.json"), annotation).unwrap();
        let (stdout, err) = assert_accepted(&["info", text(&dir), "--json"]);
        let info: Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(info["objects"].as_array().unwrap().len(), 0, "{name}: the object was kept");
        for expected in [*name, "objects[0]", "bed", needle] {
            assert!(err.contains(expected), "{name}: expected '{expected}' in the warning: {err}");
        }
    }
    // Room polygons: zero area and self-intersecting ones are skipped, the frame is kept.
    for (name, xs, zs) in
        [("flatroom", [0.0, 1.0, 2.0, 3.0], [0.0; 4]), ("bowroom", [0.0, 4.0, 0.0, 4.0], [0.0, 4.0, 4.0, 0.0])]
    {
        let dir = write_frame(tmp.path(), &good_frame(name));
        let layout = serde_json::json!({"objects": [{"name": "room", "polygon": [{"X": xs, "Z": zs, "Ymin": -1.5, "Ymax": 1.5}]}]});
        std::fs::write(dir.join("annotation3Dlayout/index.json"), layout.to_string()).unwrap();
        let (stdout, err) = assert_accepted(&["info", text(&dir), "--json"]);
        let info: Value = serde_json::from_str(&stdout).unwrap();
        assert!(info["layout"].is_null(), "{name}: the room was kept");
        assert!(err.contains(name) && err.contains("room polygon"), "{name}: {err}");
    }
    // An object without a name (it was read as category '') is skipped; of two rooms the first is the
    // layout, with a warning.
    let dir = write_frame(tmp.path(), &good_frame("noname"));
    std::fs::write(
        dir.join("annotation3Dfinal/index.json"),
        annotation_with([0.0, 1.0, 1.0, 0.0], [2.0, 2.0, 3.0, 3.0]).replace("\"bed\"", "\"\""),
    )
    .unwrap();
    let room = |x: f64| serde_json::json!({"name": "room", "polygon": [{"X": [-x, x, x, -x], "Z": [0.5, 0.5, 5.0, 5.0], "Ymin": -1.5, "Ymax": 1.5}]});
    std::fs::write(
        dir.join("annotation3Dlayout/index.json"),
        serde_json::json!({"objects": [room(2.0), room(3.0)]}).to_string(),
    )
    .unwrap();
    let (stdout, err) = assert_accepted(&["info", text(&dir), "--json"]);
    let info: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(info["objects"].as_array().unwrap().len(), 0, "{err}");
    assert!(err.contains("objects[0] has an empty name") && err.contains("2 objects named 'room'"), "{err}");
    assert!(!info["layout"].is_null());
    // A byte-order mark is accepted: the object is read.
    let dir = write_frame(tmp.path(), &good_frame("bom"));
    let path = dir.join("annotation3Dfinal/index.json");
    let original = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, format!("\u{feff}{original}")).unwrap();
    let (stdout, _) = assert_accepted(&["info", text(&dir), "--json"]);
    let info: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(info["objects"].as_array().unwrap().len(), 1);
    // A file of the wrong shape is an error naming it.
    std::fs::write(&path, "[1, 2, 3]").unwrap();
    assert_rejected(&["info", text(&dir)], &["annotation3Dfinal/index.json", "objects"]);
}

#[test]
fn numeric_options_are_range_checked_naming_flag_value_and_range() {
    let tmp = tempfile::tempdir().unwrap();
    let frame = write_frame(tmp.path(), &good_frame("f"));
    let f = text(&frame);
    let weights = tmp.path().join("w.json");
    let synth_out = tmp.path().join("s");
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (vec!["score", f, "--weights", text(&weights), "--step", "0"], vec!["--step", "'0'", "0.01", "1 metre"]),
        (vec!["score", f, "--weights", text(&weights), "--step", "NaN"], vec!["--step", "NaN"]),
        (vec!["score", f, "--weights", text(&weights), "--step=-0.1"], vec!["--step", "-0.1"]),
        (vec!["score", f, "--weights", text(&weights), "--step", "0.0001"], vec!["--step", "0.0001"]),
        (vec!["bench", "--frame", f, "--step", "0.001"], vec!["--step", "0.001"]),
        (vec!["bench", "--frame", f, "--subdivisions", "0"], vec!["--subdivisions", "1..=16"]),
        (vec!["bench", "--frame", f, "--subdivisions", "1000"], vec!["--subdivisions", "1000"]),
        (vec!["bench", "--frame", f, "--limit", "0"], vec!["--limit", "'0'"]),
        (
            vec!["train", "--data", f, "--category", "bed", "--subdivisions", "17"],
            vec!["--subdivisions", "17", "1..=16"],
        ),
        (vec!["train", "--data", f, "--category", "bed", "--max-iterations", "0"], vec!["--max-iterations", "'0'"]),
        (vec!["train", "--data", f, "--category", "bed", "--positives", "0"], vec!["--positives", "'0'"]),
        (vec!["train", "--data", f, "--category", "bed", "--candidates", "0"], vec!["--candidates", "'0'"]),
        (vec!["train", "--data", f, "--category", "bed", "--cache-gib", "0"], vec!["--cache-gib", "0 GiB", "above 0"]),
        (vec!["train", "--data", f, "--category", "bed", "--cache-gib", "NaN"], vec!["--cache-gib", "NaN"]),
        (vec!["train", "--data", f, "--category", "bed", "--cache-gib", "2000"], vec!["--cache-gib", "at most 1024"]),
        (vec!["train", "--data", f, "--category", "bed", "--step", "0"], vec!["--step", "'0'"]),
        (vec!["train", "--data", f, "--category", "bed", "--detect-step", "5"], vec!["--detect-step", "'5'"]),
        (vec!["train", "--data", f, "--category", "bed", "--c", "0"], vec!["--c", "'0'", "> 0"]),
        (vec!["train", "--data", f, "--category", "bed", "--c", "NaN"], vec!["--c", "NaN"]),
        (vec!["train", "--data", f, "--category", "bed", "--eps=-1"], vec!["--eps", "-1"]),
        (vec!["eval", "--data", f, "--detections", f, "--iou", "0"], vec!["--iou", "(0, 1]"]),
        (vec!["eval", "--data", f, "--detections", f, "--iou", "inf"], vec!["--iou", "inf"]),
        (vec!["eval", "--data", f, "--detections", f, "--overlay-top", "3"], vec!["--overlay-top", "--diagnose"]),
        (vec!["calibrate", "--data", f, "--detections", f, "--iou", "2"], vec!["--iou", "'2'"]),
        (vec!["detect", f, "--step", "0.0001"], vec!["--step", "0.0001"]),
        (vec!["detect", f, "--max-per-category", "0"], vec!["--max-per-category", "'0'"]),
        // `score --top 0` scored the whole window to print an empty table.
        (vec!["score", f, "--weights", f, "--top", "0"], vec!["--top", "'0'"]),
        (vec!["detect", f, "--support-min-score", "NaN"], vec!["--support-min-score", "NaN"]),
        (vec!["detect", f, "--support-min-score", "1.5"], vec!["--support-min-score", "1.5", "[0, 1]"]),
        (vec!["detect", f, "--overlay-min-score=-0.1"], vec!["--overlay-min-score", "-0.1", "[0, 1]"]),
        (vec!["train", "--data", f, "--category", "pillow", "--grid", "3x0x3"], vec!["--grid", "3x0x3"]),
        (vec!["train", "--data", f, "--category", "pillow", "--grid", "3x3"], vec!["--grid", "'3x3'"]),
        (vec!["train", "--data", f, "--category", "pillow", "--grid", "9x9x9"], vec!["too large"]),
        (vec!["detect", f, "--categories", "bed,"], vec!["--categories", "empty name"]),
        (
            vec!["eval", "--data", f, "--detections", f, "--categories", "bed,,chair"],
            vec!["--categories", "empty name"],
        ),
        (vec!["calibrate", "--data", f, "--detections", f, "--categories", ",bed"], vec!["--categories", "empty name"]),
        (vec!["eval", "--data", f, "--detections", f, "--diagnose", "--models", f, "--step", "0"], vec!["--step"]),
        (
            vec!["merge-detections", "--base", f, "--update", f, "--categories", "bed,,chair", "--out", f],
            vec!["--categories", "empty name"],
        ),
        (
            vec!["merge-detections", "--base", f, "--update", f, "--categories", "wardrobe", "--out", f],
            vec!["no model for category 'wardrobe'"],
        ),
        (
            vec!["merge-detections", "--base", f, "--update", f, "--categories", "bed", "--out", f],
            vec!["--out must differ from --base"],
        ),
        (vec!["synth", "--out", text(&synth_out), "--frames", "1", "--rooms", ""], vec!["--rooms"]),
    ];
    for (args, needles) in &cases {
        assert_rejected(args, needles);
    }
    assert!(!synth_out.exists(), "synth wrote frames for an empty --rooms");
}

#[test]
fn bad_model_and_detection_files_are_errors_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let frame = write_frame(tmp.path(), &good_frame("f"));
    let dir = tmp.path().join("bad-models");
    std::fs::create_dir_all(&dir).unwrap();
    let mut huge: Value = serde_json::to_value(model("bed")).unwrap();
    huge["weights"][0] = 1e38.into();
    std::fs::write(dir.join("bed.json"), huge.to_string()).unwrap();
    assert_rejected(&["detect", text(&frame), "--models", text(&dir)], &["bed.json", "weights[0]"]);
    let mut array = serde_json::to_value(model("bed")).unwrap();
    array["features"]["subdivisions"] = 0.into();
    std::fs::write(dir.join("bed.json"), array.to_string()).unwrap();
    assert_rejected(&["detect", text(&frame), "--models", text(&dir)], &["bed.json", "subdivisions"]);
    let mut tiny = serde_json::to_value(model("bed")).unwrap();
    tiny["sizes"]["widths"] = serde_json::json!([1e-30, 1e-30, 1e-30, 1e-30, 1e-30]);
    std::fs::write(dir.join("bed.json"), tiny.to_string()).unwrap();
    assert_rejected(&["detect", text(&frame), "--models", text(&dir)], &["bed.json", "sizes.widths"]);
    std::fs::write(dir.join("bed.json"), "[]").unwrap();
    assert_rejected(&["detect", text(&frame), "--models", text(&dir)], &["bed.json"]);

    // Detections files: a JSON array (what `detect --json` prints) and a BOM.
    let dets = tmp.path().join("dets");
    std::fs::create_dir_all(&dets).unwrap();
    std::fs::write(dets.join("f.json"), "[{\"frame\": \"f\", \"detections\": []}]").unwrap();
    assert_rejected(&["eval", "--data", text(&frame), "--detections", text(&dets)], &["f.json", "JSON array"]);
    let far = r#"{"frame": "f", "detections": [{"category": "bed", "centre": [1e30, 2, 0], "size": [1, 1, 1], "yaw": 0, "score": 1}]}"#;
    std::fs::write(dets.join("f.json"), far).unwrap();
    assert_rejected(&["eval", "--data", text(&frame), "--detections", text(&dets)], &["f.json", "detections[0]"]);
    std::fs::write(dets.join("f.json"), "\u{feff}{\"frame\": \"f\", \"detections\": []}").unwrap();
    assert_accepted(&["eval", "--data", text(&frame), "--detections", text(&dets)]);
    // An I/O error names the file and quotes the system's message once.
    let err = assert_rejected(
        &["score", text(&frame), "--weights", text(&tmp.path().join("nowhere.json"))],
        &["nowhere.json"],
    );
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
}

#[test]
fn a_point_cloud_too_large_for_the_step_is_refused_before_allocating() {
    let tmp = tempfile::tempdir().unwrap();
    // The widest calibration allowed (fx = 0.2 × width, principal point well outside the image) and the
    // far end of the depth range: the points span tens of metres.
    let mut wide = good_frame("wide");
    wide.k = [[6.4, 0.0, -8.0], [0.0, 6.4, 30.0], [0.0, 0.0, 1.0]];
    wide.depth_mm = vec![7990; (WIDTH * HEIGHT) as usize];
    let dir = write_frame(tmp.path(), &wide);
    let models = models_dir(tmp.path());
    let out = tmp.path().join("out");
    assert_rejected(
        &["detect", text(&dir), "--models", text(&models), "--out", text(&out), "--step", "0.01"],
        &["wide", "would need", "limit", "larger step"],
    );
}

#[test]
fn batch_detect_and_eval_go_on_past_a_bad_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    for name in ["a-bad", "b-good", "c-good"] {
        write_frame(&data, &good_frame(name));
    }
    std::fs::write(data.join("a-bad/intrinsics.txt"), "1 2 3").unwrap();
    // A symbolic link loop in the dataset must not make the walks endless.
    #[cfg(unix)]
    {
        std::fs::create_dir_all(data.join("sub")).unwrap();
        std::os::unix::fs::symlink("..", data.join("sub/up")).unwrap();
        std::os::unix::fs::symlink("self", data.join("sub/self")).unwrap();
    }
    let models = models_dir(tmp.path());
    let out = tmp.path().join("out");
    let err = assert_rejected(
        &["detect", text(&data), "--models", text(&models), "--out", text(&out), "--no-overlay"],
        &["1 of 3 frames failed", "a-bad", "intrinsics.txt"],
    );
    for good in ["b-good", "c-good"] {
        assert!(out.join(format!("{good}.json")).is_file(), "{good} was not detected: {err}");
    }
    assert!(!out.join("a-bad.json").exists());
    // Several frames in flight: the same failure report and the same files.
    let together = tmp.path().join("together");
    assert_rejected(
        &[
            "detect",
            text(&data),
            "--models",
            text(&models),
            "--out",
            text(&together),
            "--no-overlay",
            "--in-flight",
            "3",
        ],
        &["1 of 3 frames failed", "a-bad", "intrinsics.txt"],
    );
    for good in ["b-good", "c-good"] {
        let file = format!("{good}.json");
        let (one, three) = (std::fs::read(out.join(&file)).unwrap(), std::fs::read(together.join(&file)).unwrap());
        assert!(one == three, "{good}: --in-flight 3 wrote another detections file");
    }
    assert!(!together.join("a-bad.json").exists());

    let fast = tmp.path().join("fast");
    assert_rejected(
        &["detect", text(&data), "--models", text(&models), "--out", text(&fast), "--no-overlay", "--fail-fast"],
        &["a-bad", "intrinsics.txt"],
    );
    assert!(!fast.join("b-good.json").exists(), "--fail-fast went on after the bad frame");

    // eval reads annotations only, so the bad calibration does not matter; a bad detections file does.
    std::fs::write(out.join("b-good.json"), "{").unwrap();
    let out_eval = run(&["eval", "--data", text(&data), "--detections", text(&out), "--json"]);
    assert_eq!(out_eval.status.code(), Some(1));
    let err = stderr(&out_eval);
    assert!(err.contains("b-good.json") && err.contains("1 of 3 frames failed"), "{err}");
    let report: Value = serde_json::from_slice(&out_eval.stdout).unwrap();
    assert_eq!(report["frames"], 2);
}

#[test]
fn training_skips_positives_without_points_and_reports_them() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    write_frame(&data, &good_frame("seen"));
    // A bed annotated far behind the wall: no point inside it.
    let mut hidden = good_frame("hidden");
    hidden.objects[0].cuboid.centre = Vec3::new(0.0, 9.0, -0.2);
    write_frame(&data, &hidden);
    let model = tmp.path().join("bed.json");
    let (_, err) = assert_accepted(&[
        "train",
        "--data",
        text(&data),
        "--category",
        "bed",
        "--out",
        text(&model),
        "--max-iterations",
        "1",
        "--min-points",
        "1",
        "--candidates",
        "5",
        "--max-full-passes",
        "1",
    ]);
    assert!(err.contains("1 positive examples have no point inside their box"), "{err}");
    let written: Value = serde_json::from_str(&std::fs::read_to_string(&model).unwrap()).unwrap();
    assert_eq!(written["training"]["positives"], 1);
}

/// The candidate cache is sized before any window is built and refused above `--cache-gib`, naming the
/// cache, its size and the flag; the same run fits under the default limit.
#[test]
fn a_candidate_cache_above_its_limit_is_refused_naming_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    write_frame(&data, &good_frame("seen"));
    let model = tmp.path().join("bed.json");
    let args = |limit: &'static str| -> Vec<String> {
        let mut args: Vec<String> = ["train", "--data", text(&data), "--category", "bed", "--out", text(&model)]
            .iter()
            .map(|s| s.to_string())
            .collect();
        args.extend(
            ["--max-iterations", "1", "--min-points", "1", "--candidates", "5", "--max-full-passes", "1"]
                .map(String::from),
        );
        args.extend(["--cache-gib", limit].map(String::from));
        args
    };
    // One example's 5 candidates (and its nearest boxes) of a 5×5×5 expanded layout are far above 1 KiB.
    let small = args("0.000001");
    let err = assert_rejected(
        &small.iter().map(String::as_str).collect::<Vec<_>>(),
        &["the candidate cache", "limit 1.0 KiB", "--cache-gib"],
    );
    assert!(!model.exists(), "a model was written past a refused cache: {err}");
    let default = args("3");
    assert_accepted(&default.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(model.exists());
}

/// `cog-gpu ... | head`: output into a pipe whose reader has gone ends the process quietly (SIGPIPE's
/// default action, like `cat`), not with a panic in `println!` (status 101).
#[cfg(unix)]
#[test]
fn a_closed_output_pipe_ends_the_process_without_a_panic() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("frames");
    let mut child =
        cog_gpu(&["synth", "--out", out.to_str().unwrap(), "--frames", "2", "--width", "64", "--height", "48"])
            .spawn()
            .expect("run cog-gpu");
    // Close the reading end before the binary writes its summary line.
    drop(child.stdout.take());
    let output = child.wait_with_output().expect("output");
    let err = stderr(&output);
    assert!(!err.contains("panicked"), "panicked: {err}");
    assert_eq!(output.status.signal(), Some(13), "expected the end by SIGPIPE, got {:?}: {err}", output.status);
}

/// Inputs that were read without complaint and gave a wrong answer, a hang or an abort (found by a probe
/// of the binary, 2026-12-02): each is now refused naming the file and the problem, or handled.
#[test]
fn duplicates_misspelt_categories_huge_rooms_and_stages_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let f = write_frame(&data, &good_frame("f"));
    write_frame(&data, &good_frame("g"));

    // A detection's category spelt otherwise than cog-gpu writes it matched nothing, silently.
    let dets = tmp.path().join("dets");
    std::fs::create_dir_all(&dets).unwrap();
    let sofa = r#"{"frame": "f", "detections": [{"category": "Sofa", "centre": [0, 2, 0], "size": [1, 1, 1], "yaw": 0, "score": 1}]}"#;
    std::fs::write(dets.join("f.json"), sofa).unwrap();
    assert_rejected(
        &["eval", "--data", text(&data), "--detections", text(&dets)],
        &["f.json", "'Sofa'", "write 'sofa'"],
    );
    std::fs::write(dets.join("f.json"), sofa.replace("Sofa", "wardrobe")).unwrap();
    assert_rejected(
        &["eval", "--data", text(&data), "--detections", text(&dets)],
        &["f.json", "'wardrobe'", "nightstand"],
    );
    std::fs::write(dets.join("f.json"), sofa.replace("Sofa", "sofa")).unwrap();
    assert_accepted(&["eval", "--data", text(&data), "--detections", text(&dets)]);

    // A split list naming a frame twice counted it twice.
    let split = tmp.path().join("split.txt");
    std::fs::write(&split, "f\ng\nf\n").unwrap();
    assert_rejected(
        &["eval", "--data", text(&data), "--detections", text(&dets), "--split", text(&split)],
        &["split.txt", "line 3", "line 1"],
    );

    // Two frames of one name in two directories were both matched with the one file of that name.
    let twins = tmp.path().join("twins");
    write_frame(&twins.join("a"), &good_frame("f"));
    write_frame(&twins.join("b"), &good_frame("f"));
    assert_rejected(&["calibrate", "--data", text(&twins), "--detections", text(&dets)], &["same name 'f'"]);
    assert_rejected(&["eval", "--layout", "--data", text(&twins), "--detections", text(&dets)], &["same name 'f'"]);

    // A predicted room kilometres wide: the free-space measure voxelised it for minutes and gigabytes.
    let layouts = tmp.path().join("layouts");
    std::fs::create_dir_all(&layouts).unwrap();
    let room = |c: f64| {
        serde_json::json!({"frame": "f", "layout": {"method": "model", "corners": [[-c, -c], [c, -c], [c, c], [-c, c]],
            "floor": -1.5, "ceiling": 1.5, "yaw_deg": 0.0, "score": 0.0, "hypotheses": 1}})
        .to_string()
    };
    std::fs::write(layouts.join("f.json"), room(1e3)).unwrap();
    assert_rejected(
        &["eval", "--layout", "--data", text(&data), "--detections", text(&layouts), "--fail-fast"],
        &["f.json", "beyond ±100 m"],
    );
    std::fs::write(layouts.join("f.json"), room(3.0)).unwrap();
    let (_, err) = assert_accepted(&["eval", "--layout", "--data", text(&data), "--detections", text(&layouts)]);
    assert!(!err.contains("its \"frame\""), "{err}");
    // A layout file whose "frame" is another frame's is used for its file name's frame, with a warning.
    std::fs::write(layouts.join("f.json"), room(3.0).replace("\"frame\":\"f\"", "\"frame\":\"g\"")).unwrap();
    let (_, err) = assert_accepted(&["eval", "--layout", "--data", text(&data), "--detections", text(&layouts)]);
    assert!(err.contains("its \"frame\" is 'g', not 'f'"), "{err}");

    // A frame detected from inside its directory (`detect .`) was written as `..json`.
    let out = tmp.path().join("out");
    let models = models_dir(tmp.path());
    let status = cog_gpu(&["--cpu", "detect", ".", "--models", text(&models), "--out", text(&out), "--no-overlay"])
        .current_dir(&f)
        .output()
        .unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    assert!(out.join("f.json").is_file(), "{:?}", std::fs::read_dir(&out).unwrap().collect::<Vec<_>>());

    // A cascade stage whose weights overflow the scores to infinity (written as null) is refused.
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/models/cascade.json");
    let mut cascade: Value = serde_json::from_str(&std::fs::read_to_string(shipped).unwrap()).unwrap();
    let stage = &mut cascade["stages"]["bed"];
    let n = stage["weights"].as_array().unwrap().len();
    stage["weights"] = serde_json::json!(vec![1e300; n]);
    let bad = tmp.path().join("cascade.json");
    std::fs::write(&bad, cascade.to_string()).unwrap();
    assert_rejected(
        &["rescore", "--detections", text(&dets), "--out", text(&tmp.path().join("r")), "--cascade", text(&bad)],
        &["cascade.json", "'bed'", "beyond"],
    );
    let mut cascade: Value = serde_json::from_str(&std::fs::read_to_string(shipped).unwrap()).unwrap();
    cascade["categories"][1] = cascade["categories"][0].clone();
    std::fs::write(&bad, cascade.to_string()).unwrap();
    assert_rejected(
        &["rescore", "--detections", text(&dets), "--out", text(&tmp.path().join("r")), "--cascade", text(&bad)],
        &["cascade.json", "twice"],
    );

    // synth beyond six-digit frame names panicked allocating.
    assert_rejected(
        &["synth", "--out", text(&tmp.path().join("s")), "--frames", "18446744073709551615"],
        &["--frames", "at most 1000000"],
    );
}

/// Found by an audit of the binary's readers and writers (2026-12-07, night): inputs read without
/// complaint that decided the answer alone, an input overwritten by its own output, training that failed
/// only at its end, an AP of 0 for a directory without a single detections file, and a panic when the
/// report could not be written. Each is now refused naming the file or the problem.
#[test]
fn extreme_numbers_unwritable_outputs_and_empty_directories_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("data");
    let frame = write_frame(&data, &good_frame("f"));

    // Calibrations: a fit gives a slope of at least 1e-3 and coefficients of a few tens; one of 1e308 put
    // every detection at probability 1, one of 1e-300 every one at 0.
    let models = tmp.path().join("cal-models");
    std::fs::create_dir_all(&models).unwrap();
    let calibration = |a: f64, b: f64, iou: f64| {
        let mut m = serde_json::to_value(model("bed")).unwrap();
        m["calibration"] = serde_json::json!({"a": a, "b": b, "detections": 10, "true_positives": 5, "iou": iou});
        std::fs::write(models.join("bed.json"), m.to_string()).unwrap();
    };
    for (a, b, iou, says) in [
        (1.0, 1e308, 0.25, "offset b"),
        (1e300, 0.0, 0.25, "slope a"),
        (1e-300, 0.0, 0.25, "slope a"),
        (1.0, 0.0, 7.0, "IoU 7"),
    ] {
        calibration(a, b, iou);
        assert_rejected(&["detect", text(&frame), "--models", text(&models), "--no-overlay"], &["bed.json", says]);
    }
    calibration(11.27, -5.11, 0.25);
    assert_accepted(&[
        "detect",
        text(&frame),
        "--models",
        text(&models),
        "--no-overlay",
        "--out",
        text(&tmp.path().join("o")),
    ]);

    // The cascade's final calibration likewise.
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/models/cascade.json");
    let mut cascade: Value = serde_json::from_str(&std::fs::read_to_string(shipped).unwrap()).unwrap();
    cascade["final_calibration"]["c"] = 1e300.into();
    let bad_cascade = tmp.path().join("cascade.json");
    std::fs::write(&bad_cascade, cascade.to_string()).unwrap();
    let dets = tmp.path().join("dets");
    std::fs::create_dir_all(&dets).unwrap();
    std::fs::write(dets.join("f.json"), r#"{"frame": "f", "detections": []}"#).unwrap();
    let rescored = tmp.path().join("rescored");
    assert_rejected(
        &["rescore", "--detections", text(&dets), "--out", text(&rescored), "--cascade", text(&bad_cascade)],
        &["cascade.json", "offset c"],
    );

    // A detections file's room: a ceiling below the floor or a wall a thousand kilometres away gave the
    // cascade's layout features any value (scores of 1); now the layout file's own rules.
    for (layout, says) in [
        (r#"{"corners": [[-2, 1], [2, 1], [2, 5]], "floor": 5, "ceiling": 1.29}"#, "below the ceiling"),
        (r#"{"corners": [[-2, 1], [2, 1], [2, 5]], "floor": 1e6, "ceiling": 2e6}"#, "beyond ±100 m"),
        (r#"{"corners": [[-2, 1], [2, 1], [1e6, 1e6]], "floor": -1.3, "ceiling": 1.2}"#, "beyond ±100 m"),
    ] {
        std::fs::write(dets.join("f.json"), format!(r#"{{"frame": "f", "detections": [], "layout": {layout}}}"#))
            .unwrap();
        assert_rejected(
            &["rescore", "--detections", text(&dets), "--out", text(&rescored), "--cascade", shipped],
            &["f.json", says],
        );
    }

    // A cascade whose recorded calibrations leave out a stage's model checked nothing for it.
    let mut cascade: Value = serde_json::from_str(&std::fs::read_to_string(shipped).unwrap()).unwrap();
    cascade["training"]["calibrations"].as_object_mut().unwrap().remove("bed");
    std::fs::write(&bad_cascade, cascade.to_string()).unwrap();
    assert_rejected(
        &["rescore", "--detections", text(&dets), "--out", text(&rescored), "--cascade", text(&bad_cascade)],
        &["cascade.json", "no entry for the stage 'bed'"],
    );

    // Cross scores: a name that makes none and a value no model gives.
    let bed = |cross: &str| {
        format!(
            r#"{{"frame": "f", "detections": [{{"category": "bed", "centre": [0, 2, 0], "size": [1, 1, 1], "yaw": 0,
                "score": 0.5, "raw_score": 0.1, "cross_scores": {cross}}}]}}"#
        )
    };
    for (cross, says) in [(r#"{"flux": 1.0}"#, "'flux'"), (r#"{"bed": 1e30}"#, "cross_scores['bed']")] {
        std::fs::write(dets.join("f.json"), bed(cross)).unwrap();
        assert_rejected(&["eval", "--data", text(&data), "--detections", text(&dets)], &["f.json", says]);
    }
    std::fs::write(dets.join("f.json"), bed(r#"{"bed": 0.1, "desk": -1.2}"#)).unwrap();
    assert_accepted(&["eval", "--data", text(&data), "--detections", text(&dets)]);

    // A detections directory without a file for any frame (the data set itself, swapped arguments) gave
    // mAP 0 and exit 0; an empty one is still no detections, a frame without its file only a warning.
    assert_rejected(&["eval", "--data", text(&data), "--detections", text(&data)], &["no detections file for any"]);
    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    assert_accepted(&["eval", "--data", text(&data), "--detections", text(&empty)]);
    write_frame(&data, &good_frame("g"));
    let (_, err) = assert_accepted(&["eval", "--data", text(&data), "--detections", text(&dets)]);
    assert!(err.contains("1 of 2 frames have no detections file"), "{err}");

    // merge-cascades --out an input under another spelling overwrote it.
    let first = tmp.path().join("first.json");
    std::fs::copy(shipped, &first).unwrap();
    let before = std::fs::read(&first).unwrap();
    let respelt = format!("{}/./first.json", tmp.path().display());
    assert_rejected(&["merge-cascades", text(&first), shipped, "--out", &respelt], &["--out must not be"]);
    assert_eq!(std::fs::read(&first).unwrap(), before);

    // train and train-layout with --out a directory failed only after the whole training.
    let taken = tmp.path().join("taken");
    std::fs::create_dir_all(&taken).unwrap();
    assert_rejected(
        &["train", "--data", text(&data), "--category", "bed", "--out", text(&taken)],
        &["taken", "is a directory"],
    );
    assert_rejected(&["train-layout", "--data", text(&data), "--out", text(&taken)], &["taken", "is a directory"]);

    // synth into a directory of another set overwrote part of it (frames 2–5 of an old set of 6 stayed
    // under a manifest of 2); the same options again complete or repeat the set.
    let set = tmp.path().join("set");
    let set_dir = text(&set).to_string();
    let synth = |frames: &'static str| {
        ["synth", "--out", set_dir.as_str(), "--frames", frames, "--seed", "3", "--width", "64", "--height", "48"]
    };
    assert_accepted(&synth("3"));
    assert_accepted(&synth("3"));
    assert_rejected(&synth("2"), &["manifest.json", "other options"]);
    std::fs::remove_file(set.join("manifest.json")).unwrap();
    assert_rejected(&synth("3"), &["no manifest.json"]);

    // detect --out into the frame's own folders wrote a second picture into image/, breaking the frame;
    // a folder of its own inside the frame is fine.
    for inside in [frame.join("image"), frame.clone()] {
        assert_rejected(
            &["detect", text(&frame), "--models", text(&models), "--out", text(&inside)],
            &["writes into the frame"],
        );
    }
    assert_accepted(&["info", text(&frame)]);
    assert_accepted(&["detect", text(&frame), "--models", text(&models), "--out", text(&frame.join("detections"))]);
    // A model file given as the models directory said "missing".
    assert_rejected(&["detect", text(&frame), "--models", text(&models.join("bed.json"))], &["bed.json", "is a file"]);
    // A minimum of points no box can hold wrote a model that never detects.
    assert_rejected(
        &["train", "--data", text(&data), "--category", "bed", "--min-points", "4000000000"],
        &["--min-points", "at most 4194304"],
    );
    let mut never = serde_json::to_value(model("bed")).unwrap();
    never["window"]["min_points"] = 4_000_000_000u32.into();
    std::fs::write(models.join("bed.json"), never.to_string()).unwrap();
    assert_rejected(&["detect", text(&frame), "--models", text(&models)], &["bed.json", "window.min_points"]);

    // Frames: a translation in the extrinsics was dropped silently; an editor's backup beside the
    // extrinsics was read as the last file; a data set given as a frame said only "image/ missing".
    let odd = write_frame(tmp.path(), &good_frame("odd"));
    let extrinsics = odd.join("extrinsics/00000000000000.txt");
    std::fs::write(&extrinsics, "1 0 0 0.5\n0 1 0 0\n0 0 1 0\n").unwrap();
    assert_rejected(&["info", text(&odd)], &["00000000000000.txt", "4th column"]);
    std::fs::write(&extrinsics, "1 0 0 0\n0 1 0 0\n0 0 1 0\n").unwrap();
    std::fs::write(odd.join("extrinsics/00000000000000.txt~"), "not numbers").unwrap();
    assert_accepted(&["info", text(&odd)]);
    assert_rejected(&["info", text(&data)], &["directory of", "frame(s), not a frame"]);

    // A report that cannot be written (a full disk) panicked in println!: the text report and the JSON one.
    for args in [vec!["--cpu", "info", text(&frame)], vec!["--cpu", "info", "--json", text(&frame)]] {
        let full = std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap();
        let out = cog_gpu(&args).stdout(full).output().unwrap();
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains("error: writing standard output") && !err.contains("panicked"), "{args:?}: {err}");
    }
}
