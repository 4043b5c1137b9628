//! Synthetic indoor RGB-D scenes written in the SUN RGB-D layout (`cog-gpu synth`).
//!
//! A frame is made in five steps, each from its own random stream derived from (seed, frame index):
//! 1. **Scene** ([`generate_scene`]): a room type from the allowed list, a Manhattan room
//!    ([`room::Room`]), furnished by the room type's recipe ([`placement`]) with models built from parts
//!    ([`furniture`]).
//! 2. **Camera** ([`camera`]): a sensor, its image size and intrinsics, and a pose at 1.0–1.7 m pitched down
//!    0–35° with a small roll; among up to eight candidate poses the first that sees at least two labelled
//!    objects in a 80×60 probe render, with less than a fifth of it closer than 0.6 m, is kept (else the
//!    best).
//! 3. **Rendering** ([`render`]): ray casting with rayon, ideal depth and per-pixel instance ids.
//! 4. **Depth sensor** ([`sensor`]): noise, quantisation, holes.
//! 5. **Annotation** ([`AnnotationRule`]): every labelled object with at least `max(12, 0.0004·W·H)`
//!    visible pixels — by default counting only the pixels where the sensor returned a depth — gets its
//!    full cuboid (annotators box the whole object, also where it is occluded or cut by the border), in the
//!    camera-centred upright frame; the room polygon goes to the layout file; support relations to
//!    `synth_support.json`.
//!
//! Frames are independent: frame `i` is the same whatever the number of frames or threads, and the same
//! seed and options give byte-identical files.

pub mod bvh;
pub mod camera;
pub mod furniture;
pub mod material;
pub mod placement;
pub mod preview;
pub mod render;
pub mod rng;
pub mod room;
pub mod sensor;
pub mod shape;
pub mod sizes;

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde_json::{json, Value};

pub use camera::{Sensor, View};
pub use placement::{Item, ItemKind, Rest, Scene};
pub use room::{Room, RoomType};
pub use sensor::DepthModel;

use crate::error::{Error, Result};
use crate::frame::{write_depth_png, Frame, Object, RoomLayout};
use crate::geometry::Cuboid;
use rng::{hash_u64, Rng};

/// Version of the generator's output; bumped whenever the same seed and options would give other files.
/// `synth-2`: the annotation rule ([`AnnotationRule`], default `depth`); `synth-1` annotated by visible
/// pixels alone, which `--annotate visible` still gives (the same images and annotations, this version).
pub const GENERATOR_VERSION: &str = "synth-2";

/// Name of the per-frame file with support relations (not part of SUN RGB-D; detectors never read it).
pub const SUPPORT_FILE: &str = "synth_support.json";

/// Smallest accepted image side, and largest.
pub const MIN_SIDE: u32 = 32;
pub const MAX_SIDE: u32 = 4096;

/// Which sensor(s) frames are taken with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SensorChoice {
    One(Sensor),
    /// Each frame draws a sensor with SUN RGB-D's proportions.
    Mixed,
}

impl SensorChoice {
    pub fn parse(name: &str) -> Option<SensorChoice> {
        if name.trim().eq_ignore_ascii_case("mixed") {
            Some(SensorChoice::Mixed)
        } else {
            Sensor::parse(name).map(SensorChoice::One)
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SensorChoice::One(s) => s.name(),
            SensorChoice::Mixed => "mixed",
        }
    }
}

/// Which labelled objects get a 3D box.
///
/// SUN RGB-D's annotators drew each 3D box on the top view of the frame's point cloud (Song, Lichtenberg
/// & Xiao, *SUN RGB-D*, CVPR 2015, §3), so an object that the depth does not see — beyond the sensor's
/// range, black, glossy — has no 3D box there, however plainly the RGB shows it. [`AnnotationRule::Depth`]
/// (the default) follows that: an object is annotated when at least `max(12, 0.0004·W·H)` of its visible
/// pixels carry a raw depth. [`AnnotationRule::Visible`] counts the visible pixels alone, as generator
/// version `synth-1` did (the shipped models' data sets were made that way; the images are the same under
/// both rules, only the annotations and `synth_support.json` differ).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AnnotationRule {
    /// Visible pixels with a raw depth.
    #[default]
    Depth,
    /// Visible pixels, with or without depth (`synth-1`).
    Visible,
}

impl AnnotationRule {
    pub fn parse(name: &str) -> Option<AnnotationRule> {
        match name.trim().to_ascii_lowercase().as_str() {
            "depth" => Some(AnnotationRule::Depth),
            "visible" => Some(AnnotationRule::Visible),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            AnnotationRule::Depth => "depth",
            AnnotationRule::Visible => "visible",
        }
    }

    /// Whether an object with `visible` pixels, `with_depth` of them carrying a raw depth, is annotated in a
    /// frame whose threshold is `min_pixels`.
    pub fn annotates(self, visible: usize, with_depth: usize, min_pixels: usize) -> bool {
        match self {
            AnnotationRule::Depth => with_depth >= min_pixels,
            AnnotationRule::Visible => visible >= min_pixels,
        }
    }
}

/// The smallest number of (counted) pixels that gets an object annotated in a `width`×`height` frame.
pub fn min_annotated_pixels(width: u32, height: u32) -> usize {
    (0.0004 * (width * height) as f32).max(12.0) as usize
}

/// Generator options (everything but the seed and the frame index).
#[derive(Clone, Debug, PartialEq)]
pub struct SynthOptions {
    pub sensor: SensorChoice,
    /// Image size overriding the sensor's own (intrinsics are scaled to keep the field of view).
    pub size: Option<(u32, u32)>,
    /// Room types to draw from (with their relative frequencies); all when empty.
    pub rooms: Vec<RoomType>,
    /// Which labelled objects are annotated (the images do not depend on it).
    pub annotate: AnnotationRule,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            sensor: SensorChoice::Mixed,
            size: None,
            rooms: RoomType::ALL.to_vec(),
            annotate: AnnotationRule::default(),
        }
    }
}

impl SynthOptions {
    /// Small frames of the given size (for tests and quick data).
    pub fn small(width: u32, height: u32) -> Self {
        SynthOptions { size: Some((width, height)), ..Default::default() }
    }

    /// Checks the options; names the problem.
    pub fn validate(&self) -> Result<()> {
        if let Some((w, h)) = self.size {
            for (name, v) in [("width", w), ("height", h)] {
                if !(MIN_SIDE..=MAX_SIDE).contains(&v) {
                    return Err(Error::Input(format!("image {name} {v} is outside {MIN_SIDE}..={MAX_SIDE}")));
                }
            }
            let aspect = w as f32 / h as f32;
            if !(0.5..=3.0).contains(&aspect) {
                return Err(Error::Input(format!("image size {w}×{h} has an aspect ratio {aspect:.2} outside 0.5–3")));
            }
        }
        Ok(())
    }

    fn room_types(&self) -> Vec<RoomType> {
        if self.rooms.is_empty() {
            RoomType::ALL.to_vec()
        } else {
            self.rooms.clone()
        }
    }
}

/// Random stream identifiers (the third word of each stream's derivation).
const STREAM_SENSOR: u64 = 1;
const STREAM_SCENE: u64 = 2;
const STREAM_CAMERA: u64 = 3;
const STREAM_RENDER: u64 = 4;
const STREAM_NOISE: u64 = 5;
const STREAM_DEPTH: u64 = 6;

/// Most frames one data set may have: frame names have six digits ([`frame_name`]).
pub const MAX_FRAMES: u64 = 1_000_000;

/// The directory name of frame `index`: `synth-000042`.
pub fn frame_name(index: u64) -> String {
    format!("synth-{index:06}")
}

/// The room type and furnished scene of frame `index` (no camera, no rendering: fast).
pub fn generate_scene(seed: u64, index: u64, options: &SynthOptions) -> Result<Scene> {
    options.validate()?;
    let types = options.room_types();
    let mut rng = Rng::derive(&[seed, index, STREAM_SCENE]);
    let weights: Vec<f32> = types.iter().map(|t| t.weight()).collect();
    let kind = types[rng.weighted(&weights)];
    let room = Room::sample(&mut rng, kind);
    Ok(placement::furnish(room, &mut rng))
}

/// What rests on what, for one instance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Support {
    Floor,
    Wall,
    /// On instance `parent`'s support surface `surface`.
    On {
        parent: usize,
        surface: usize,
    },
}

/// One thing in a generated frame, in the frame's upright (camera-centred) coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct Instance {
    /// Category (labelled objects) or clutter name; `room` for the structure (instance 0).
    pub name: &'static str,
    /// The category of a labelled object.
    pub category: Option<&'static str>,
    /// Model variant (e.g. `office` chair, `floor` lamp).
    pub variant: &'static str,
    /// The full cuboid in the upright frame (`None` for the room structure).
    pub cuboid: Option<Cuboid>,
    pub support: Support,
    /// Heights (upright z) of this instance's own support surfaces, the main one first.
    pub support_surfaces: Vec<SupportSurface>,
    /// Index into `frame.objects` when annotated.
    pub annotation: Option<usize>,
    /// Number of pixels showing it.
    pub pixels: usize,
    /// Number of those pixels where the sensor returned a depth (raw depth > 0).
    pub depth_pixels: usize,
}

/// Per instance id below `instances`, the pixels showing it and those of them with a raw depth (> 0 mm).
pub fn instance_pixels(pixel_instance: &[u32], raw_depth_mm: &[u16], instances: usize) -> (Vec<usize>, Vec<usize>) {
    let mut pixels = vec![0usize; instances];
    let mut with_depth = vec![0usize; instances];
    for (&id, &d) in pixel_instance.iter().zip(raw_depth_mm) {
        if (id as usize) < instances {
            pixels[id as usize] += 1;
            with_depth[id as usize] += usize::from(d > 0);
        }
    }
    (pixels, with_depth)
}

/// A support surface in upright coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct SupportSurface {
    pub z: f32,
    /// Free height above it.
    pub clearance: f32,
    /// Its rectangle's corners (upright x, y), counter-clockwise.
    pub corners: [Vec2; 4],
}

/// A generated frame with everything the generator knows about it.
#[derive(Clone, Debug)]
pub struct SynthFrame {
    pub index: u64,
    pub room_type: RoomType,
    pub view: View,
    /// The frame as written: RGB, raw depth (sensor model), K, E, scene type, annotations, layout.
    pub frame: Frame,
    /// Noiseless depth along the optical axis (metres, 0 = nothing), row-major.
    pub depth_ideal: Vec<f32>,
    /// The filled depth written to `depth_bfx/` (millimetres).
    pub depth_filled_mm: Vec<u16>,
    /// Instance id per pixel: an index into `instances` (0 = room structure), or [`render::NO_INSTANCE`].
    pub pixel_instance: Vec<u32>,
    /// Instance 0 is the room structure; instance i + 1 is scene item i.
    pub instances: Vec<Instance>,
    /// The scene in its world frame (floor at z = 0).
    pub scene: Scene,
}

/// Generates frame `index`: scene, camera, rendering, sensor, annotations.
pub fn generate_frame(seed: u64, index: u64, options: &SynthOptions) -> Result<SynthFrame> {
    let scene = generate_scene(seed, index, options)?;
    let mut sensor_rng = Rng::derive(&[seed, index, STREAM_SENSOR]);
    let sensor = match options.sensor {
        SensorChoice::One(s) => s,
        SensorChoice::Mixed => Sensor::ALL[sensor_rng.weighted(&Sensor::ALL.map(|s| s.share()))],
    };
    let (nw, nh, k) = sensor.native(&mut sensor_rng);
    let (width, height) = options.size.unwrap_or((nw, nh));
    let intrinsics = camera::scale_intrinsics(k, (nw, nh), (width, height));
    let render_scene = render::build(&scene, &mut Rng::derive(&[seed, index, STREAM_RENDER]));
    let view = choose_view(
        &scene,
        &render_scene,
        sensor,
        width,
        height,
        intrinsics,
        &mut Rng::derive(&[seed, index, STREAM_CAMERA]),
    );
    let kind = scene.room.kind;
    Ok(render_frame(scene, &render_scene, view, kind, seed, index, options.annotate))
}

/// Picks the camera pose: the first of up to eight candidates whose 80×60 probe shows at least two
/// labelled objects (≥ 4 probe pixels each) and is not blocked (a fifth of it closer than 0.6 m), else the
/// candidate showing the most.
fn choose_view(
    scene: &Scene,
    rs: &render::RenderScene,
    sensor: Sensor,
    width: u32,
    height: u32,
    intrinsics: [f32; 4],
    rng: &mut Rng,
) -> View {
    let mut best: Option<(usize, View)> = None;
    for _ in 0..8 {
        let (position, heading, pitch, roll) = camera::sample_pose(scene, rng).unwrap_or_else(|| {
            let c = scene.room.centroid();
            (c.extend(1.3), 0.0, 0.2, 0.01)
        });
        let view = View { sensor, width, height, intrinsics, position, heading, pitch, roll };
        let probe = View {
            width: 80,
            height: 60,
            intrinsics: camera::scale_intrinsics(intrinsics, (width, height), (80, 60)),
            ..view
        };
        let probe = render::render_probe(rs, &probe);
        let mut counts = vec![0usize; scene.items.len() + 1];
        for &(id, _) in &probe {
            if (id as usize) < counts.len() {
                counts[id as usize] += 1;
            }
        }
        let seen =
            (0..scene.items.len()).filter(|&i| scene.items[i].category().is_some() && counts[i + 1] >= 4).count();
        // A view blocked by something right in front of the lens is kept only as a last resort.
        let blocked = probe.iter().filter(|p| p.1 < 0.6).count() * 5 > probe.len();
        let seen = if blocked { 0 } else { seen };
        if seen >= 2 {
            return view;
        }
        if best.as_ref().is_none_or(|(n, _)| seen > *n) {
            best = Some((seen, view));
        }
    }
    best.map(|b| b.1).expect("eight candidates were tried")
}

/// Renders a scene from a view and annotates it by `annotate` (the lower-level entry point: custom scenes
/// and views).
pub fn render_frame(
    scene: Scene,
    render_scene: &render::RenderScene,
    view: View,
    room_type: RoomType,
    seed: u64,
    index: u64,
    annotate: AnnotationRule,
) -> SynthFrame {
    let buffers = render::render(render_scene, &view, hash_u64(&[seed, index, STREAM_NOISE]));
    let model = DepthModel::for_sensor(view.sensor);
    let input = sensor::SensorInput {
        width: view.width,
        height: view.height,
        fx: view.intrinsics[0],
        depth: &buffers.depth,
        infrared: &buffers.infrared,
        gloss: &buffers.gloss,
        incidence: &buffers.incidence,
    };
    let raw = sensor::simulate(&model, &input, hash_u64(&[seed, index, STREAM_DEPTH]));
    let filled = sensor::filled(&raw, &buffers.depth);
    let (pixels, depth_pixels) = instance_pixels(&buffers.instance, &raw, scene.items.len() + 1);
    let min_pixels = min_annotated_pixels(view.width, view.height);
    let mut instances = vec![Instance {
        name: "room",
        category: None,
        variant: "room",
        cuboid: None,
        support: Support::Floor,
        support_surfaces: Vec::new(),
        annotation: None,
        pixels: pixels[0],
        depth_pixels: depth_pixels[0],
    }];
    let mut objects = Vec::new();
    for (i, item) in scene.items.iter().enumerate() {
        let c = item.cuboid();
        let cuboid = Cuboid::new(view.to_upright(c.centre), c.size, view.yaw_to_upright(c.yaw));
        let annotation = match item.category() {
            Some(cat) if annotate.annotates(pixels[i + 1], depth_pixels[i + 1], min_pixels) => {
                objects.push(Object { category: cat.to_string(), label: None, cuboid });
                Some(objects.len() - 1)
            }
            _ => None,
        };
        let support = match item.rest {
            Rest::Floor => Support::Floor,
            Rest::Wall { .. } => Support::Wall,
            Rest::On { parent, surface } => Support::On { parent: parent + 1, surface },
        };
        let support_surfaces = item
            .model
            .supports
            .iter()
            .map(|s| {
                let [s0, s1, t0, t1] = s.rect;
                let corner = |a: f32, b: f32| view.to_upright(item.to_world(Vec3::new(a, b, s.z))).truncate();
                SupportSurface {
                    z: view.to_upright(item.to_world(Vec3::new(0.0, 0.0, s.z))).z,
                    clearance: s.clearance,
                    corners: [corner(s0, t0), corner(s1, t0), corner(s1, t1), corner(s0, t1)],
                }
            })
            .collect();
        instances.push(Instance {
            name: item.kind.name(),
            category: item.category(),
            variant: item.model.variant,
            cuboid: Some(cuboid),
            support,
            support_surfaces,
            annotation,
            pixels: pixels[i + 1],
            depth_pixels: depth_pixels[i + 1],
        });
    }
    let rot = view.world_to_upright();
    let layout = RoomLayout {
        corners: scene.room.polygon.iter().map(|p| (rot * (p.extend(0.0) - view.position)).truncate()).collect(),
        floor: -view.position.z,
        ceiling: scene.room.height - view.position.z,
    };
    let rgb = image::RgbImage::from_fn(view.width, view.height, |x, y| {
        image::Rgb(buffers.rgb[(y * view.width + x) as usize])
    });
    let mut frame = Frame {
        name: frame_name(index),
        rgb,
        depth_mm: raw,
        k: view.k(),
        extrinsics: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        scene: Some(room_type.name().to_string()),
        objects,
        layout: Some(layout),
    };
    frame.set_rtilt(view.rtilt());
    SynthFrame {
        index,
        room_type,
        view,
        frame,
        depth_ideal: buffers.depth,
        depth_filled_mm: filled,
        pixel_instance: buffers.instance,
        instances,
        scene,
    }
}

/// The true support-surface heights (upright z, the main one first) of each annotated object of a synthetic
/// frame, from its [`SUPPORT_FILE`], indexed like the frame's annotations (`objects` of them; an object the
/// file does not list gets none). `Ok(None)` when the frame has no support file (not a synthetic frame).
/// For evaluation and tests only: detectors never read it.
pub fn read_support_heights(dir: &std::path::Path, objects: usize) -> crate::error::Result<Option<Vec<Vec<f32>>>> {
    use crate::error::Error;
    let path = dir.join(SUPPORT_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let text = crate::frame::read_text(&path)?;
    let value: Value =
        serde_json::from_str(&text).map_err(|e| Error::invalid(&path, format!("not a support file: {e}")))?;
    let listed = value["objects"].as_array().ok_or_else(|| Error::invalid(&path, "has no \"objects\" list"))?;
    let mut heights = vec![Vec::new(); objects];
    for (n, object) in listed.iter().enumerate() {
        let index = object["annotation_index"]
            .as_u64()
            .ok_or_else(|| Error::invalid(&path, format!("objects[{n}] has no annotation_index")))?
            as usize;
        if index >= objects {
            return Err(Error::invalid(
                &path,
                format!("objects[{n}] names annotation {index}, the frame has {objects} annotated objects"),
            ));
        }
        let surfaces = object["support_surfaces"].as_array().map(Vec::as_slice).unwrap_or(&[]);
        heights[index] = surfaces
            .iter()
            .map(|s| {
                s["z"].as_f64().map(|z| z as f32).ok_or_else(|| {
                    Error::invalid(&path, format!("objects[{n}] has a support surface without a numeric z"))
                })
            })
            .collect::<crate::error::Result<_>>()?;
    }
    Ok(Some(heights))
}

fn round4(x: f32) -> f64 {
    ((x as f64) * 1e4).round() / 1e4
}

impl SynthFrame {
    /// The support relations and support-surface heights of the annotated objects (`synth_support.json`).
    pub fn support_json(&self) -> Value {
        let floor = -self.view.position.z;
        let objects: Vec<Value> = self
            .instances
            .iter()
            .filter(|inst| inst.annotation.is_some())
            .map(|inst| {
                let c = inst.cuboid.expect("annotated instances have cuboids");
                let (rests_on, parent) = match inst.support {
                    Support::Floor => ("floor", None),
                    Support::Wall => ("wall", None),
                    Support::On { parent, surface } => ("object", Some((parent, surface))),
                };
                let parent_json = parent.map(|(p, s)| {
                    let pi = &self.instances[p];
                    json!({
                        "annotation_index": pi.annotation,
                        "name": pi.name,
                        "labelled": pi.category.is_some(),
                        "surface": s,
                        "surface_z": pi.support_surfaces.get(s).map(|x| round4(x.z)),
                    })
                });
                json!({
                    "annotation_index": inst.annotation,
                    "category": inst.category,
                    "variant": inst.variant,
                    "visible_pixels": inst.pixels,
                    "depth_pixels": inst.depth_pixels,
                    "bottom_z": round4(c.bottom()),
                    "rests_on": rests_on,
                    "supported_by": parent_json,
                    "support_surfaces": inst.support_surfaces.iter().map(|s| json!({
                        "z": round4(s.z),
                        "height_above_floor": round4(s.z - floor),
                        "clearance": round4(s.clearance),
                        "corners": s.corners.iter().map(|p| [round4(p.x), round4(p.y)]).collect::<Vec<_>>(),
                    })).collect::<Vec<_>>(),
                })
            })
            .collect();
        json!({
            "frame": self.frame.name,
            "generator_version": GENERATOR_VERSION,
            "room_type": self.room_type.name(),
            "sensor": self.view.sensor.name(),
            "camera": {
                "height_m": round4(self.view.position.z),
                "pitch_deg": round4(self.view.pitch.to_degrees()),
                "roll_deg": round4(self.view.roll.to_degrees()),
            },
            "floor_z": round4(floor),
            "ceiling_z": round4(self.scene.room.height - self.view.position.z),
            "objects": objects,
        })
    }

    /// Writes the frame directory (SUN RGB-D layout + `depth_bfx/` + `synth_support.json`) and, when given,
    /// the preview PNG.
    pub fn write(&self, dir: &Path, preview_path: Option<&Path>) -> Result<()> {
        self.frame.write(dir)?;
        let bfx = dir.join("depth_bfx");
        std::fs::create_dir_all(&bfx).map_err(|e| Error::io(&bfx, e))?;
        write_depth_png(
            &bfx.join(format!("{}.png", self.frame.name)),
            self.frame.width(),
            self.frame.height(),
            &self.depth_filled_mm,
        )?;
        let support_path = dir.join(SUPPORT_FILE);
        let text = serde_json::to_string_pretty(&self.support_json())
            .map_err(|e| Error::invalid(&support_path, e.to_string()))?;
        std::fs::write(&support_path, text).map_err(|e| Error::io(&support_path, e))?;
        if let Some(path) = preview_path {
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
            }
            crate::frame::write_png(&preview::preview(&self.frame), path)?;
        }
        Ok(())
    }
}

/// What a dataset run produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Summary {
    pub frames: usize,
    /// Annotated objects per category.
    pub objects: BTreeMap<String, usize>,
    pub sensors: BTreeMap<String, usize>,
    pub rooms: BTreeMap<String, usize>,
}

/// The manifest written at the output root.
pub fn manifest(seed: u64, frames: u64, options: &SynthOptions, preview: bool) -> Value {
    json!({
        "generator": "cog-gpu synth",
        "generator_version": GENERATOR_VERSION,
        "crate_version": env!("CARGO_PKG_VERSION"),
        "seed": seed,
        "frames": frames,
        "options": {
            "sensor": options.sensor.name(),
            "width": options.size.map(|s| s.0),
            "height": options.size.map(|s| s.1),
            "rooms": options.room_types().iter().map(|r| r.name()).collect::<Vec<_>>(),
            "annotate": options.annotate.name(),
            "preview": preview,
        },
        "layout": "SUN RGB-D frame directories synth-NNNNNN/ (image/, depth/, depth_bfx/, intrinsics.txt, extrinsics/, scene.txt, annotation3Dfinal/, annotation3Dlayout/) plus synth_support.json",
    })
}

/// Generates `frames` frames into `out` in parallel (frame `i` into `out/synth-<i>`), then the manifest;
/// calls `progress` after each frame. With `preview`, writes `out/preview/synth-<i>.png` too.
pub fn generate_dataset(
    out: &Path,
    seed: u64,
    frames: u64,
    options: &SynthOptions,
    preview: bool,
    progress: &(dyn Fn() + Sync),
) -> Result<Summary> {
    options.validate()?;
    if !(1..=MAX_FRAMES).contains(&frames) {
        return Err(Error::Input(format!("the number of frames must be in 1..={MAX_FRAMES}, got {frames}")));
    }
    let path = out.join("manifest.json");
    let text = serde_json::to_string_pretty(&manifest(seed, frames, options, preview))
        .map_err(|e| Error::invalid(&path, e.to_string()))?;
    refuse_another_set(out, &path, &text)?;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    // The manifest first: a run interrupted leaves its options beside its frames, so that running it again
    // completes the set and another run is refused.
    std::fs::write(&path, &text).map_err(|e| Error::io(&path, e))?;
    let results: Vec<Result<(Vec<String>, &'static str, &'static str)>> = (0..frames)
        .into_par_iter()
        .map(|i| {
            let f = generate_frame(seed, i, options)?;
            let name = frame_name(i);
            let preview_path = preview.then(|| out.join("preview").join(format!("{name}.png")));
            f.write(&out.join(&name), preview_path.as_deref())?;
            progress();
            Ok((f.frame.objects.iter().map(|o| o.category.clone()).collect(), f.view.sensor.name(), f.room_type.name()))
        })
        .collect();
    let mut summary = Summary::default();
    for r in results {
        let (cats, sensor, room) = r?;
        summary.frames += 1;
        for c in cats {
            *summary.objects.entry(c).or_default() += 1;
        }
        *summary.sensors.entry(sensor.to_string()).or_default() += 1;
        *summary.rooms.entry(room.to_string()).or_default() += 1;
    }
    Ok(summary)
}

/// A directory that already holds a set made with other options (its `manifest.json` differs from this
/// run's), or synthetic frames without a manifest, is refused: its frames would be overwritten in part —
/// a set of 6 frames written again with 2 kept frames 2–5 of the old one under a manifest of 2. The same
/// options again (a run interrupted or repeated: byte-identical frames) and a directory without frames
/// are written.
fn refuse_another_set(out: &Path, manifest_path: &Path, manifest: &str) -> Result<()> {
    let another = "the output directory holds a synthetic set made with other options (seed, frames, size, \
                   rooms, rule); write the new set to another directory, or remove this one first";
    match std::fs::read_to_string(manifest_path) {
        Ok(existing) if existing != manifest => Err(Error::invalid(manifest_path, another)),
        Ok(_) => Ok(()),
        Err(_) => {
            let frames = std::fs::read_dir(out)
                .map(|entries| entries.flatten().any(|e| e.file_name().to_string_lossy().starts_with("synth-")))
                .unwrap_or(false);
            if frames {
                return Err(Error::invalid(
                    out,
                    "holds synthetic frames (synth-*) but no manifest.json: another run's; write the new set to \
                     another directory, or remove this one first",
                ));
            }
            Ok(())
        }
    }
}
