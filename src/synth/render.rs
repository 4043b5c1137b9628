//! Ray casting: one primary ray per pixel through a BVH, Lambertian shading from the room's lights (with
//! a shadow ray towards the main ceiling light), Blinn–Phong highlights on glossy materials, emission,
//! then a camera pipeline (exposure, white balance, slight optical blur, vignetting, sensor noise, sRGB).
//!
//! Rows are rendered in parallel with rayon; every pixel is a pure function of the scene, the view and the
//! noise seed, so the image does not depend on the number of threads.

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use super::bvh::Bvh;
use super::camera::View;
use super::material::Material;
use super::placement::Scene;
use super::rng::{hash_u64, normal_from_hash, Rng};
use super::shape::{Prim, Shape};

/// Pixel instance id of rays that hit nothing.
pub const NO_INSTANCE: u32 = u32::MAX;

/// A point light.
#[derive(Clone, Copy, Debug)]
pub struct Light {
    pub position: Vec3,
    pub intensity: Vec3,
    /// Whether a shadow ray is cast towards it (only the main ceiling light: one ray per pixel).
    pub shadows: bool,
}

/// Everything the ray caster needs.
pub struct RenderScene {
    pub bvh: Bvh,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    pub ambient: Vec3,
    /// Per-frame camera colour balance.
    pub white_balance: Vec3,
    /// Target mean linear brightness of the exposed image.
    pub exposure_target: f32,
    /// Standard deviation of the image noise (in 8-bit levels).
    pub noise_levels: f32,
}

/// Per-pixel results of a render.
#[derive(Clone, Debug)]
pub struct Buffers {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[u8; 3]>,
    /// Ideal depth along the optical axis (metres); 0 where nothing was hit.
    pub depth: Vec<f32>,
    /// Instance id per pixel (0 = room structure, i + 1 = scene item i, [`NO_INSTANCE`]).
    pub instance: Vec<u32>,
    /// Infrared reflectance and glossiness of the surface seen (for the depth sensor).
    pub infrared: Vec<f32>,
    pub gloss: Vec<f32>,
    /// |cos| of the angle between the surface normal and the viewing ray.
    pub incidence: Vec<f32>,
}

/// Builds the render scene: room structure (instance 0), every item's parts (instance i + 1), lights.
pub fn build(scene: &Scene, rng: &mut Rng) -> RenderScene {
    let mut materials = Vec::new();
    let mut prims = Vec::new();
    scene.room.structure(rng, &mut materials, &mut prims);
    for (i, item) in scene.items.iter().enumerate() {
        let base = materials.len() as u32;
        materials.extend_from_slice(&item.model.materials);
        let yaw_rot = Mat3::from_rotation_z(item.yaw);
        for part in &item.model.parts {
            let rot = yaw_rot * part.rotation();
            let centre = item.to_world(part.centre);
            let seed = rng.next_u64() as u32;
            prims.push(Prim::new(part.shape, centre, rot, part.half, base + part.material as u32, i as u32 + 1, seed));
        }
    }
    let mut lights = Vec::new();
    let main = rng.range(2.0, 4.0);
    for (k, p) in scene.room.ceiling_lights.iter().enumerate() {
        let warm = Vec3::new(1.0, rng.range(0.88, 0.97), rng.range(0.72, 0.9));
        lights.push(Light {
            position: *p - Vec3::Z * 0.05,
            intensity: warm * main * if k == 0 { 1.0 } else { 0.7 },
            shadows: k == 0,
        });
    }
    let walls = scene.room.walls();
    for o in scene.room.openings.iter().filter(|o| o.window) {
        let w = walls[o.wall];
        let c = w.point(0.5 * (o.s0 + o.s1), 0.6).extend(0.5 * (o.z0 + o.z1));
        let daylight = Vec3::new(0.9, 0.95, 1.05) * rng.range(0.8, 2.0) * (o.s1 - o.s0);
        lights.push(Light { position: c, intensity: daylight, shadows: false });
    }
    for item in &scene.items {
        if let Some(l) = item.model.light {
            lights.push(Light { position: item.to_world(l.position), intensity: l.intensity, shadows: false });
        }
    }
    RenderScene {
        bvh: Bvh::build(prims),
        materials,
        lights,
        ambient: Vec3::splat(rng.range(0.12, 0.3)),
        white_balance: Vec3::new(1.0 + 0.06 * rng.normal(), 1.0, 1.0 + 0.06 * rng.normal()),
        exposure_target: rng.range(0.14, 0.26),
        noise_levels: rng.range(1.2, 3.5),
    }
}

/// A scene with nothing but the given primitives and one light (for tests and custom scenes).
pub fn from_prims(prims: Vec<Prim>, materials: Vec<Material>, lights: Vec<Light>) -> RenderScene {
    RenderScene {
        bvh: Bvh::build(prims),
        materials,
        lights,
        ambient: Vec3::splat(0.2),
        white_balance: Vec3::ONE,
        exposure_target: 0.2,
        noise_levels: 2.0,
    }
}

struct Sample {
    radiance: Vec3,
    depth: f32,
    instance: u32,
    infrared: f32,
    gloss: f32,
    incidence: f32,
}

fn ray_direction(view: &View, to_world: &Mat3, col: u32, row: u32) -> Vec3 {
    let [fx, fy, cx, cy] = view.intrinsics;
    *to_world * Vec3::new((col as f32 + 1.0 - cx) / fx, (row as f32 + 1.0 - cy) / fy, 1.0)
}

fn trace(rs: &RenderScene, origin: Vec3, dir: Vec3, shade: bool) -> Sample {
    let Some((hit, pi)) = rs.bvh.intersect(origin, dir, 1e4) else {
        return Sample {
            radiance: Vec3::ZERO,
            depth: 0.0,
            instance: NO_INSTANCE,
            infrared: 0.0,
            gloss: 0.0,
            incidence: 0.0,
        };
    };
    let prim = &rs.bvh.prims[pi];
    let material = &rs.materials[prim.material as usize];
    let point = origin + dir * hit.t;
    let view_dir = -dir.normalize();
    let mut normal = prim.world_normal(hit.normal_canonical);
    if normal.dot(view_dir) < 0.0 {
        normal = -normal;
    }
    let incidence = normal.dot(view_dir).clamp(0.0, 1.0);
    let mut radiance = Vec3::ZERO;
    if shade {
        let nc = hit.normal_canonical.abs();
        let axis = if matches!(prim.shape, Shape::Box) {
            if nc.x >= nc.y && nc.x >= nc.z {
                0
            } else if nc.y >= nc.z {
                1
            } else {
                2
            }
        } else {
            // Curved shapes: project along the dominant local axis of the true normal.
            let n = (prim.rotation.transpose() * normal).abs();
            if n.x >= n.y && n.x >= n.z {
                0
            } else if n.y >= n.z {
                1
            } else {
                2
            }
        };
        let seed = prim.texture_seed;
        let offset = Vec3::new((seed & 0xff) as f32, ((seed >> 8) & 0xff) as f32, ((seed >> 16) & 0xff) as f32) * 0.37;
        let albedo = material.albedo(prim.local_point(point) + offset, axis, prim.grain as usize, seed);
        radiance = albedo * rs.ambient * (0.75 + 0.25 * normal.z);
        for light in &rs.lights {
            let to = light.position - point;
            let dist2 = to.length_squared();
            let dist = dist2.sqrt();
            let l = to / dist;
            let ndl = normal.dot(l);
            if ndl <= 0.0 {
                continue;
            }
            if light.shadows && rs.bvh.occluded(point + normal * 2e-3, l, dist - 0.1, None) {
                continue;
            }
            let falloff = light.intensity / (dist2 + 0.3);
            radiance += albedo * falloff * ndl;
            if material.specular > 0.0 {
                let h = (l + view_dir).normalize();
                radiance += falloff * (material.specular * normal.dot(h).max(0.0).powf(material.shininess));
            }
        }
        radiance += material.emission;
    }
    Sample {
        radiance,
        depth: hit.t,
        instance: prim.instance,
        infrared: material.infrared,
        gloss: material.gloss,
        incidence,
    }
}

/// Renders only (instance id, ideal depth) per pixel: a quick visibility probe at any resolution.
pub fn render_probe(rs: &RenderScene, view: &View) -> Vec<(u32, f32)> {
    let to_world = view.camera_to_world();
    let w = view.width;
    (0..view.height)
        .into_par_iter()
        .flat_map_iter(|row| {
            let to_world = &to_world;
            (0..w).map(move |col| {
                let s = trace(rs, view.position, ray_direction(view, to_world, col, row), false);
                (s.instance, s.depth)
            })
        })
        .collect()
}

/// Renders the full frame.
pub fn render(rs: &RenderScene, view: &View, noise_seed: u64) -> Buffers {
    let (w, h) = (view.width, view.height);
    let to_world = view.camera_to_world();
    let rows: Vec<Vec<Sample>> = (0..h)
        .into_par_iter()
        .map(|row| (0..w).map(|col| trace(rs, view.position, ray_direction(view, &to_world, col, row), true)).collect())
        .collect();
    let samples: Vec<Sample> = rows.into_iter().flatten().collect();
    let rgb = develop(rs, &samples, w, h, noise_seed);
    Buffers {
        width: w,
        height: h,
        rgb,
        depth: samples.iter().map(|s| s.depth).collect(),
        instance: samples.iter().map(|s| s.instance).collect(),
        infrared: samples.iter().map(|s| s.infrared).collect(),
        gloss: samples.iter().map(|s| s.gloss).collect(),
        incidence: samples.iter().map(|s| s.incidence).collect(),
    }
}

fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The camera pipeline: auto exposure on the mean luminance, a soft shoulder, white balance, a mild 3×3
/// blur (optics and demosaicing), vignetting, Gaussian noise per channel, sRGB, 8 bits.
fn develop(rs: &RenderScene, samples: &[Sample], w: u32, h: u32, seed: u64) -> Vec<[u8; 3]> {
    let (wu, hu) = (w as usize, h as usize);
    // Row sums in parallel, then a sequential total: deterministic for any thread count.
    let row_sums: Vec<f64> =
        samples.par_chunks(wu).map(|r| r.iter().map(|s| luminance(s.radiance) as f64).sum()).collect();
    let mean = (row_sums.iter().sum::<f64>() / samples.len().max(1) as f64) as f32;
    let exposure = rs.exposure_target / mean.max(1e-4);
    let white = 2.5f32;
    let mapped: Vec<Vec3> = samples
        .par_iter()
        .map(|s| {
            let x = s.radiance * exposure * rs.white_balance;
            x * (Vec3::ONE + x / (white * white)) / (Vec3::ONE + x)
        })
        .collect();
    let sigma = rs.noise_levels / 255.0;
    (0..hu)
        .into_par_iter()
        .flat_map_iter(|row| {
            let mapped = &mapped;
            (0..wu).map(move |col| {
                let mut acc = Vec3::ZERO;
                for (dy, wy) in [(-1i32, 1.0f32), (0, 2.0), (1, 1.0)] {
                    for (dx, wx) in [(-1i32, 1.0f32), (0, 2.0), (1, 1.0)] {
                        let r = (row as i32 + dy).clamp(0, hu as i32 - 1) as usize;
                        let c = (col as i32 + dx).clamp(0, wu as i32 - 1) as usize;
                        acc += mapped[r * wu + c] * (wx * wy);
                    }
                }
                let centre = mapped[row * wu + col];
                let blurred = 0.5 * centre + 0.5 * acc / 16.0;
                let (u, v) = ((col as f32 + 0.5) / wu as f32 - 0.5, (row as f32 + 0.5) / hu as f32 - 0.5);
                let vignette = 1.0 - 0.35 * (u * u + v * v);
                let idx = (row * wu + col) as u64;
                let mut out = [0u8; 3];
                for (ch, o) in out.iter_mut().enumerate() {
                    let lin = (blurred[ch] * vignette).max(0.0);
                    let enc = srgb_encode(lin.min(1.0));
                    let n = normal_from_hash(hash_u64(&[seed, idx, ch as u64]));
                    let noisy = enc + n * sigma * (0.6 + 0.8 * enc.sqrt());
                    *o = (noisy * 255.0 + 0.5).clamp(0.0, 255.0) as u8;
                }
                out
            })
        })
        .collect()
}
