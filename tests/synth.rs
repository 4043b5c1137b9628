//! Tests of `cog-gpu synth`: the generated frames read back through the frame reader, their annotations
//! agree with the rendered geometry, placements are physical, runs are deterministic, and the depth sensor
//! model behaves as documented.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use cog_gpu::category::CATEGORIES;
use cog_gpu::frame::{DepthSource, Frame};
use cog_gpu::geometry::{wrap_angle, Cuboid};
use cog_gpu::synth::{
    self, camera::Sensor, furniture, render, rng::Rng, sizes, AnnotationRule, Item, ItemKind, Rest, Room, RoomType,
    Scene, Support, SynthFrame, SynthOptions, View,
};
use glam::{Vec2, Vec3};

fn small() -> SynthOptions {
    SynthOptions::small(160, 120)
}

/// Whether instance `maybe_descendant` rests (directly or not) on instance `ancestor`.
fn rests_on(f: &SynthFrame, maybe_descendant: usize, ancestor: usize) -> bool {
    let mut cur = maybe_descendant;
    while let Support::On { parent, .. } = f.instances[cur].support {
        if parent == ancestor {
            return true;
        }
        cur = parent;
    }
    false
}

#[test]
fn frames_round_trip_through_the_frame_reader() {
    let dir = tempfile::tempdir().unwrap();
    for index in [0u64, 5] {
        let f = synth::generate_frame(7, index, &small()).unwrap();
        assert!(!f.frame.objects.is_empty(), "frame {index} has no annotated object");
        let path = dir.path().join(&f.frame.name);
        f.write(&path, None).unwrap();
        let back = Frame::read(&path, DepthSource::Raw).unwrap();
        assert_eq!(back.name, f.frame.name);
        assert_eq!(back.rgb, f.frame.rgb);
        assert_eq!(back.depth_mm, f.frame.depth_mm);
        assert_eq!(back.k, f.frame.k);
        assert_eq!(back.scene.as_deref(), Some(f.room_type.name()));
        for r in 0..3 {
            for c in 0..3 {
                assert!((back.extrinsics[r][c] - f.frame.extrinsics[r][c]).abs() < 1e-12);
            }
        }
        assert_eq!(back.objects.len(), f.frame.objects.len());
        for (a, b) in back.objects.iter().zip(&f.frame.objects) {
            assert_eq!(a.category, b.category);
            assert!((a.cuboid.centre - b.cuboid.centre).abs().max_element() < 1e-5, "{a:?} vs {b:?}");
            assert!((a.cuboid.size - b.cuboid.size).abs().max_element() < 1e-5, "{a:?} vs {b:?}");
            assert!(wrap_angle(a.cuboid.yaw - b.cuboid.yaw).abs() < 1e-5, "{a:?} vs {b:?}");
        }
        let (la, lb) = (back.layout.clone().unwrap(), f.frame.layout.clone().unwrap());
        assert!((la.floor - lb.floor).abs() < 1e-5 && (la.ceiling - lb.ceiling).abs() < 1e-5);
        assert_eq!(la.corners.len(), lb.corners.len());
        // Rtilt is a proper rotation with pitch and roll only, and it is not the identity.
        let rtilt = back.rtilt_f64();
        assert!((rtilt.determinant() - 1.0).abs() < 1e-9);
        // No yaw: the optical axis (0, 1, 0) in (x, z, −y) coordinates stays in the upright y–z plane.
        assert!((rtilt.y_axis.x).abs() < 1e-9, "Rtilt holds no yaw");
        assert!((rtilt - glam::DMat3::IDENTITY).to_cols_array().iter().any(|v| v.abs() > 1e-4));
        let filled = Frame::read(&path, DepthSource::Filled).unwrap();
        assert_eq!(filled.depth_mm, f.depth_filled_mm);
        assert!(filled.valid_depth() >= back.valid_depth());
        let support: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path.join(synth::SUPPORT_FILE)).unwrap()).unwrap();
        assert_eq!(support["objects"].as_array().unwrap().len(), f.frame.objects.len());
    }
}

#[test]
fn annotated_cuboids_contain_their_points_and_few_others() {
    let mut checked = 0;
    for index in 0..8u64 {
        let f = synth::generate_frame(11, index, &small()).unwrap();
        // Back-project the noiseless depth with the frame module (its own conventions), so sensor noise does
        // not blur the test; points beyond the toolbox's 8 m clamp are left out.
        let mut ideal = f.frame.clone();
        ideal.depth_mm = f.depth_ideal.iter().map(|&z| if z < 7.9 { (z * 1000.0).round() as u16 } else { 0 }).collect();
        let cloud = ideal.point_cloud();
        let w = f.frame.width();
        let owner: Vec<u32> = cloud.pixels.iter().map(|p| f.pixel_instance[(p[1] * w + p[0]) as usize]).collect();
        for (inst_id, inst) in f.instances.iter().enumerate() {
            let Some(k) = inst.annotation else { continue };
            let cuboid = f.frame.objects[k].cuboid;
            let grown = Cuboid::new(cuboid.centre, cuboid.size + Vec3::splat(0.02), cuboid.yaw);
            let shrunk =
                Cuboid::new(cuboid.centre, (cuboid.size - Vec3::splat(0.04)).max(Vec3::splat(1e-3)), cuboid.yaw);
            let mut own = 0usize;
            let mut own_inside = 0usize;
            let mut others_inside = 0usize;
            for (p, &o) in cloud.points.iter().zip(&owner) {
                if o as usize == inst_id {
                    own += 1;
                    own_inside += usize::from(grown.contains(*p));
                } else if (o as usize) < f.instances.len() && rests_on(&f, o as usize, inst_id) {
                    // What stands on the object (books on shelves, pillows on a bed) may be inside its box.
                } else if shrunk.contains(*p) {
                    others_inside += 1;
                }
            }
            if own < 10 {
                continue;
            }
            checked += 1;
            assert!(
                own_inside as f32 >= 0.97 * own as f32,
                "frame {index} {}: {own_inside}/{own} of its points inside",
                inst.name
            );
            assert!(
                others_inside as f32 <= 0.05 * own as f32 + 3.0,
                "frame {index} {}: {others_inside} foreign points inside ({own} own)",
                inst.name
            );
        }
    }
    assert!(checked >= 15, "only {checked} objects checked");
}

fn scenes(seed: u64, n: u64, options: &SynthOptions) -> Vec<Scene> {
    (0..n).map(|i| synth::generate_scene(seed, i, options).unwrap()).collect()
}

#[test]
fn supported_objects_rest_on_their_support() {
    let mut checked = BTreeMap::<(&str, &str), usize>::new();
    for scene in scenes(21, 60, &SynthOptions::default()) {
        for (i, item) in scene.items.iter().enumerate() {
            let Rest::On { parent, surface } = item.rest else { continue };
            let parent_item = &scene.items[parent];
            let child = item.cuboid();
            let base = parent_item.cuboid();
            // The metadata: the child's bottom is at the parent's surface height; for the main surface of
            // furniture with a top (nightstand, table, desk, dresser, counter) that is the parent's box top.
            let surface_z = parent_item.position.z + parent_item.model.supports[surface].z;
            assert!((child.bottom() - surface_z).abs() < 1e-4);
            if surface == 0
                && matches!(parent_item.category(), Some("nightstand" | "table" | "desk" | "dresser" | "counter"))
            {
                assert!(
                    (child.bottom() - base.top()).abs() < 0.01,
                    "{} on {}: {} vs {}",
                    item.kind.name(),
                    parent_item.kind.name(),
                    child.bottom(),
                    base.top()
                );
            }
            // The geometry: without the child (and what stands on it), a ray cast down from 5 cm above the
            // child's bottom centre meets the parent's surface 5 ± 1 cm below.
            let mut without = scene.clone();
            for (j, other) in without.items.iter_mut().enumerate() {
                if j == i || scene.is_ancestor(i, j) {
                    other.model.parts.clear();
                }
            }
            let rs = render::build(&without, &mut Rng::new(1));
            let origin = child.centre.truncate().extend(child.bottom() + 0.05);
            let (hit, prim) = rs.bvh.intersect(origin, -Vec3::Z, 10.0).expect("something below");
            assert_eq!(
                rs.bvh.prims[prim].instance as usize,
                parent + 1,
                "{} on {}",
                item.kind.name(),
                parent_item.kind.name()
            );
            assert!(
                (hit.t - 0.05).abs() < 0.01,
                "{} on {}: surface {} cm below",
                item.kind.name(),
                parent_item.kind.name(),
                100.0 * hit.t
            );
            *checked.entry((item.kind.name(), parent_item.kind.name())).or_default() += 1;
        }
    }
    for pair in [("lamp", "nightstand"), ("pillow", "bed"), ("monitor", "desk")] {
        assert!(checked.get(&pair).copied().unwrap_or(0) >= 2, "too few {pair:?}: {checked:?}");
    }
}

/// Area of the intersection of two convex polygons (Sutherland–Hodgman clipping, then the shoelace
/// formula).
fn overlap_area(a: &[Vec2], b: &[Vec2]) -> f32 {
    let mut poly = a.to_vec();
    for i in 0..b.len() {
        let (p, q) = (b[i], b[(i + 1) % b.len()]);
        let inside = |x: Vec2| (q - p).perp_dot(x - p) >= 0.0;
        let mut out = Vec::new();
        for j in 0..poly.len() {
            let (s, e) = (poly[j], poly[(j + 1) % poly.len()]);
            let cross = |s: Vec2, e: Vec2| {
                let d = e - s;
                let t = (q - p).perp_dot(p - s) / (q - p).perp_dot(d);
                s + d * t
            };
            match (inside(s), inside(e)) {
                (true, true) => out.push(e),
                (true, false) => out.push(cross(s, e)),
                (false, true) => {
                    out.push(cross(s, e));
                    out.push(e);
                }
                (false, false) => {}
            }
        }
        poly = out;
        if poly.is_empty() {
            return 0.0;
        }
    }
    0.5 * (0..poly.len()).map(|i| poly[i].perp_dot(poly[(i + 1) % poly.len()])).sum::<f32>().abs()
}

#[test]
fn objects_do_not_interpenetrate_and_stay_in_the_room() {
    let mut pairs = 0usize;
    for scene in scenes(33, 120, &SynthOptions::default()) {
        let room = &scene.room;
        for (i, a) in scene.items.iter().enumerate() {
            if !a.collides {
                continue;
            }
            let ca = a.cuboid();
            if !matches!(a.rest, Rest::Wall { .. }) {
                for corner in ca.footprint() {
                    assert!(point_in_polygon(&room.polygon, corner), "{} leaves the room", a.kind.name());
                }
            }
            assert!(ca.bottom() >= -1e-5 && ca.top() <= room.height, "{} pierces floor or ceiling", a.kind.name());
            for (j, b) in scene.items.iter().enumerate().skip(i + 1) {
                if !b.collides || scene.is_ancestor(i, j) || scene.is_ancestor(j, i) {
                    continue;
                }
                let cb = b.cuboid();
                let vertical = (ca.top().min(cb.top()) - ca.bottom().max(cb.bottom())).max(0.0);
                if vertical <= 0.0 {
                    continue;
                }
                pairs += 1;
                let area = overlap_area(&ca.footprint(), &cb.footprint());
                assert!(
                    area * vertical < 1e-6,
                    "{} and {} overlap by {} m³",
                    a.kind.name(),
                    b.kind.name(),
                    area * vertical
                );
            }
        }
    }
    assert!(pairs > 1000, "{pairs}");
}

fn point_in_polygon(poly: &[Vec2], p: Vec2) -> bool {
    let mut inside = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

#[test]
fn every_category_appears_with_sizes_in_range() {
    let mut counts = BTreeMap::<&str, usize>::new();
    let mut rooms = BTreeSet::new();
    let all = scenes(5, 400, &SynthOptions::default());
    for scene in &all {
        rooms.insert(scene.room.kind);
        let (lo, hi) = scene.room.bounds();
        let side = hi - lo;
        assert!(side.min_element() >= 2.5 - 1e-4 && side.max_element() <= 8.0 + 1e-4, "room {side}");
        assert!((2.4..=3.2).contains(&scene.room.height));
        for item in &scene.items {
            let Some(cat) = item.category() else { continue };
            *counts.entry(cat).or_default() += 1;
            let range = sizes::size_range(cat).unwrap();
            for (k, (a, b)) in range.iter().enumerate() {
                let x = item.model.size[k];
                assert!(x >= a - 1e-3 && x <= b + 1e-3, "{cat} dimension {k} = {x} outside [{a}, {b}]");
            }
            // Co-occurrence like real rooms.
            let parent = item.parent().map(|p| scene.items[p].kind.name());
            match cat {
                "pillow" => assert!(matches!(parent, Some("bed" | "sofa")), "pillow on {parent:?}"),
                "monitor" => assert!(matches!(parent, Some("desk" | "table")), "monitor on {parent:?}"),
                "tv" => assert!(parent.is_none() || matches!(parent, Some("dresser" | "cabinet")), "tv on {parent:?}"),
                "sink" => assert!(parent.is_none() || parent == Some("counter"), "sink on {parent:?}"),
                "lamp" if item.model.variant == "table" => assert!(parent.is_some(), "table lamp on the floor"),
                "bed" | "toilet" | "bathtub" | "bookshelf" | "counter" | "dresser" => {
                    assert_eq!(item.rest, Rest::Floor)
                }
                _ => {}
            }
        }
    }
    for cat in CATEGORIES {
        assert!(
            counts.get(cat).copied().unwrap_or(0) >= 5,
            "{cat} appears {} times in 400 scenes: {counts:?}",
            counts.get(cat).copied().unwrap_or(0)
        );
    }
    assert_eq!(rooms.len(), RoomType::ALL.len());
    // Beds stand with their headboard at a wall: the back edge is within 7 cm of a wall.
    for scene in &all {
        for item in scene.items.iter().filter(|i| i.category() == Some("bed")) {
            let c = item.cuboid();
            let back = c.centre.truncate() + c.depth_axis() * (0.5 * c.size.y);
            assert!(
                scene.room.wall_distance(back) < 0.07,
                "bed back {} m from the wall",
                scene.room.wall_distance(back)
            );
        }
    }
}

#[test]
fn size_ranges_cover_the_real_sun_rgbd_medians() {
    let path = Path::new("../shared/data/sunrgbd-size-stats.json");
    let Ok(text) = std::fs::read_to_string(path) else {
        eprintln!("{} not found; skipped", path.display());
        return;
    };
    let stats: serde_json::Value = serde_json::from_str(&text).unwrap();
    for (name, entry) in stats.as_object().unwrap() {
        let cat = cog_gpu::category::normalise_name(name).0;
        let range = sizes::size_range(&cat).unwrap_or_else(|| panic!("{cat} has no size range"));
        // Median of width (q 0.5 is the third of five), depth (second of three), height (second of three).
        let median = |key: &str, i: usize| entry[key]["v"][i].as_f64().unwrap() as f32;
        for (k, m) in [median("width_m", 2), median("depth_m", 1), median("height_m", 1)].into_iter().enumerate() {
            assert!(m >= range[k].0 && m <= range[k].1, "{cat} dimension {k}: real median {m} outside {:?}", range[k]);
        }
    }
}

#[test]
fn identical_seed_and_options_give_identical_bytes() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let options = SynthOptions { size: Some((96, 72)), ..Default::default() };
    let sa = synth::generate_dataset(a.path(), 3, 4, &options, true, &|| {}).unwrap();
    let sb = synth::generate_dataset(b.path(), 3, 4, &options, true, &|| {}).unwrap();
    assert_eq!(sa, sb);
    let files = |root: &Path| -> BTreeMap<String, Vec<u8>> {
        let mut out = BTreeMap::new();
        let mut stack = vec![root.to_path_buf()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    out.insert(p.strip_prefix(root).unwrap().display().to_string(), std::fs::read(&p).unwrap());
                }
            }
        }
        out
    };
    let (fa, fb) = (files(a.path()), files(b.path()));
    assert!(fa.len() > 4 * 8, "{} files", fa.len());
    assert_eq!(fa.keys().collect::<Vec<_>>(), fb.keys().collect::<Vec<_>>());
    for (k, v) in &fa {
        assert!(v == &fb[k], "{k} differs");
    }
    // A frame does not depend on the others: frame 2 alone equals frame 2 of the run.
    let alone = synth::generate_frame(3, 2, &options).unwrap();
    let read = Frame::read(a.path().join(synth::frame_name(2)), DepthSource::Raw).unwrap();
    assert_eq!(read.rgb, alone.frame.rgb);
    assert_eq!(read.depth_mm, alone.frame.depth_mm);
    // Another seed gives another dataset.
    let other = synth::generate_frame(4, 2, &options).unwrap();
    assert_ne!(other.frame.rgb, alone.frame.rgb);
}

/// A camera facing a bare wall `distance` metres away, head on.
fn wall_frame(sensor: Sensor, distance: f32, seed: u64) -> (SynthFrame, View) {
    let room = Room::rectangle(RoomType::Office, 8.0, 8.0, 3.0);
    let scene = Scene { room, items: Vec::new() };
    let rs = render::build(&scene, &mut Rng::new(2));
    let (w, h) = (320, 240);
    let view = View {
        sensor,
        width: w,
        height: h,
        intrinsics: [520.0, 520.0, 160.5, 120.5],
        position: Vec3::new(4.0, 8.0 - distance, 1.5),
        heading: std::f32::consts::FRAC_PI_2,
        pitch: 0.0,
        roll: 0.0,
    };
    (synth::render_frame(scene, &rs, view, RoomType::Office, seed, 0, AnnotationRule::Depth), view)
}

/// A Kinect v1 (no return beyond 5.5 m) looking along +y at two dressers, one 3 m away, one 9 m away, in a
/// 12 m deep room, annotated by `rule`.
fn near_and_far_dressers(rule: AnnotationRule) -> SynthFrame {
    let room = Room::rectangle(RoomType::Bedroom, 12.0, 12.0, 3.0);
    let dresser = |x: f32, y: f32, seed: u64| Item {
        kind: ItemKind::Object("dresser"),
        model: furniture::build("dresser", None, &mut Rng::new(seed)),
        position: Vec3::new(x, y, 0.0),
        yaw: std::f32::consts::PI,
        rest: Rest::Floor,
        collides: true,
    };
    let scene = Scene { room, items: vec![dresser(5.4, 4.0, 1), dresser(7.0, 10.0, 2)] };
    let rs = render::build(&scene, &mut Rng::new(2));
    let view = View {
        sensor: Sensor::Kv1,
        width: 320,
        height: 240,
        intrinsics: [260.0, 260.0, 160.5, 120.5],
        position: Vec3::new(6.0, 1.0, 1.5),
        heading: std::f32::consts::FRAC_PI_2,
        pitch: 0.2,
        roll: 0.0,
    };
    synth::render_frame(scene, &rs, view, RoomType::Bedroom, 5, 0, rule)
}

#[test]
fn the_depth_rule_annotates_what_the_sensor_sees() {
    let by_depth = near_and_far_dressers(AnnotationRule::Depth);
    let by_pixels = near_and_far_dressers(AnnotationRule::Visible);
    // The rule changes the annotations only: the same images.
    assert_eq!(by_depth.frame.rgb, by_pixels.frame.rgb);
    assert_eq!(by_depth.frame.depth_mm, by_pixels.frame.depth_mm);
    // Each instance's counts, recounted from the instance buffer and the raw depth.
    for (id, inst) in by_depth.instances.iter().enumerate() {
        let shown: Vec<usize> =
            (0..by_depth.pixel_instance.len()).filter(|&p| by_depth.pixel_instance[p] as usize == id).collect();
        assert_eq!(inst.pixels, shown.len(), "instance {id}");
        assert_eq!(
            inst.depth_pixels,
            shown.iter().filter(|&&p| by_depth.frame.depth_mm[p] > 0).count(),
            "instance {id}"
        );
    }
    let min = synth::min_annotated_pixels(320, 240);
    let (near, far) = (&by_depth.instances[1], &by_depth.instances[2]);
    assert!(near.pixels >= min && near.depth_pixels >= min, "near: {} / {} pixels", near.depth_pixels, near.pixels);
    // 9 m is beyond the Kinect v1's 5.5 m: plainly visible, no depth.
    assert!(far.pixels >= min, "far: {} pixels", far.pixels);
    assert_eq!(far.depth_pixels, 0);
    assert_eq!(by_pixels.frame.objects.len(), 2);
    assert_eq!(by_depth.frame.objects.len(), 1);
    assert!((by_depth.frame.objects[0].cuboid.centre - by_pixels.frame.objects[0].cuboid.centre).length() < 1e-6);
    assert_eq!((near.annotation, far.annotation), (Some(0), None));
    assert_eq!(by_pixels.instances[2].annotation, Some(1));
    // synth_support.json lists the annotated objects only, with both counts.
    let support = by_depth.support_json();
    assert_eq!(support["objects"].as_array().unwrap().len(), 1);
    assert_eq!(support["objects"][0]["depth_pixels"].as_u64(), Some(near.depth_pixels as u64));
}

#[test]
fn annotation_rules_parse_and_the_default_is_depth() {
    assert_eq!(AnnotationRule::parse(" Depth "), Some(AnnotationRule::Depth));
    assert_eq!(AnnotationRule::parse("visible"), Some(AnnotationRule::Visible));
    assert_eq!(AnnotationRule::parse("pixels"), None);
    assert_eq!(SynthOptions::default().annotate, AnnotationRule::Depth);
    for rule in [AnnotationRule::Depth, AnnotationRule::Visible] {
        assert_eq!(AnnotationRule::parse(rule.name()), Some(rule));
    }
    // 0.0004·W·H, at least 12: 30 pixels at 320×240, 12 at 160×120 (7.68).
    assert_eq!(synth::min_annotated_pixels(320, 240), 30);
    assert_eq!(synth::min_annotated_pixels(160, 120), 12);
}

#[test]
fn depth_noise_on_a_flat_wall_follows_the_sensor_model() {
    // Kinect v1: axial noise σ(z) = 1.2 mm + 1.9 mm·(z − 0.4)² (Nguyen et al. 2012) and disparity
    // quantised to 1/8 px with a 7.5 cm baseline: step z²/(8·fx·0.075); decoded in whole millimetres.
    // Kinect v2: σ(z) = 1.5 mm + 0.3 mm·z², millimetre output.
    let cases = [(Sensor::Kv1, 1.0f32), (Sensor::Kv1, 2.0), (Sensor::Kv1, 3.0), (Sensor::Kv2, 2.0), (Sensor::Kv2, 4.0)];
    for (sensor, z) in cases {
        let (f, view) = wall_frame(sensor, z, 17);
        let fx = view.intrinsics[0];
        let (sigma, step) = match sensor {
            Sensor::Kv1 => (0.0012 + 0.0019 * (z - 0.4) * (z - 0.4), z * z / (8.0 * fx * 0.075)),
            _ => (0.0015 + 0.0003 * z * z, 0.0),
        };
        let expected = (sigma * sigma + step * step / 12.0 + 1e-6 / 12.0).sqrt();
        let (w, h) = (view.width as usize, view.height as usize);
        let mut values = Vec::new();
        let mut missing = 0usize;
        for row in h / 4..3 * h / 4 {
            for col in w / 4..3 * w / 4 {
                let mm = f.frame.depth_mm[row * w + col];
                assert!((f.depth_ideal[row * w + col] - z).abs() < 1e-4, "the wall is at {z} m");
                if mm == 0 {
                    missing += 1;
                } else {
                    values.push(mm as f64 / 1000.0);
                }
            }
        }
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let sd = (values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n).sqrt() as f32;
        assert!(missing as f64 / (n + missing as f64) < 0.02, "{sensor:?} at {z} m: {missing} missing");
        assert!((mean as f32 - z).abs() < 0.15 * expected + 0.0015, "{sensor:?} at {z} m: mean {mean}");
        assert!((sd / expected - 1.0).abs() < 0.15, "{sensor:?} at {z} m: spread {sd} vs {expected}");
    }
    // Beyond the Kinect v1's range nothing comes back; the filled depth still has the wall, clamped at 8 m
    // like the toolbox would.
    let (far, _) = wall_frame(Sensor::Kv1, 6.0, 3);
    assert_eq!(far.frame.valid_depth(), 0);
    assert!(far.depth_filled_mm.iter().all(|&d| (5990..=8000).contains(&d)));
}

#[test]
fn bad_command_lines_fail_with_clear_errors() {
    let exe = env!("CARGO_BIN_EXE_cog-gpu");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let run = |extra: &[&str]| {
        let mut args = vec!["synth", "--out", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        std::process::Command::new(exe).args(&args).output().unwrap()
    };
    for (extra, needle) in [
        (&["--frames", "2", "--rooms", "bedroom,garage"][..], "unknown room type 'garage'"),
        (&["--frames", "0"][..], "--frames must be at least 1"),
        // Beyond six-digit frame names (it panicked allocating before the limit).
        (&["--frames", "18446744073709551615"][..], "at most 1000000"),
        (&["--frames", "1", "--width", "5", "--height", "4"][..], "outside"),
        (&["--frames", "1", "--sensor", "kinect9"][..], "unknown sensor"),
    ] {
        let o = run(extra);
        assert!(!o.status.success(), "{extra:?} succeeded");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "{extra:?}: {err}");
    }
    let o = run(&[
        "--frames",
        "2",
        "--seed",
        "9",
        "--width",
        "64",
        "--height",
        "48",
        "--rooms",
        "kitchen,bathroom",
        "--sensor",
        "xtion",
        "--preview",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["seed"], 9);
    assert_eq!(manifest["options"]["rooms"], serde_json::json!(["kitchen", "bathroom"]));
    let preview = image::open(out.join("preview").join("synth-000001.png")).unwrap();
    assert_eq!((preview.width(), preview.height()), (128, 48));
    let ds = cog_gpu::frame::Dataset::open(&out).unwrap();
    assert_eq!(ds.len(), 2);
    for frame_dir in &ds.frames {
        let f = Frame::read(frame_dir, DepthSource::Raw).unwrap();
        assert!(matches!(f.scene.as_deref(), Some("kitchen" | "bathroom")));
        // Xtion's fx ≈ 570 px at 640 wide, scaled to 64 wide.
        assert!((f.k[0][0] - 57.0).abs() < 1.5, "fx {}", f.k[0][0]);
    }
}
