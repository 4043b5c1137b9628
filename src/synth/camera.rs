//! The four SUN RGB-D sensors and camera poses.
//!
//! A [`View`] holds the image size, the intrinsics (1-based, as `intrinsics.txt`), and the pose in the
//! room's world frame: position, heading (the optical axis's direction on the floor plane), pitch (down
//! positive) and roll. SUN RGB-D's upright frame is centred on the camera with +y along the heading, so
//! `upright = Rz(π/2 − heading)·(world − position)` and `Rtilt = Rx(−pitch)·Ry(roll)`; Rtilt holds only
//! pitch and roll, as in the dataset.

use glam::{DMat3, Mat3, Vec2, Vec3};

use super::placement::Scene;
use super::rng::Rng;
use crate::geometry::{wrap_angle, Camera};

/// A depth camera of SUN RGB-D.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Sensor {
    /// Kinect v1 (NYU, B3DO): 561×427 crop, or 640×480.
    Kv1,
    /// Kinect v2: 730×530.
    Kv2,
    /// Intel RealSense: 681×441.
    RealSense,
    /// Asus Xtion (SUN3D): 640×480.
    Xtion,
}

impl Sensor {
    pub const ALL: [Sensor; 4] = [Sensor::Kv1, Sensor::Kv2, Sensor::RealSense, Sensor::Xtion];

    pub fn name(self) -> &'static str {
        match self {
            Sensor::Kv1 => "kv1",
            Sensor::Kv2 => "kv2",
            Sensor::RealSense => "realsense",
            Sensor::Xtion => "xtion",
        }
    }

    pub fn parse(name: &str) -> Option<Sensor> {
        let n = name.trim().to_ascii_lowercase();
        Sensor::ALL.into_iter().find(|s| s.name() == n)
    }

    /// Share of SUN RGB-D's 10 335 frames taken with this sensor (2003 / 3784 / 1159 / 3389).
    pub fn share(self) -> f32 {
        match self {
            Sensor::Kv1 => 2003.0,
            Sensor::Kv2 => 3784.0,
            Sensor::RealSense => 1159.0,
            Sensor::Xtion => 3389.0,
        }
    }

    /// Native (width, height, [fx, fy, cx, cy]) of one frame; Kinect v1 frames are the 561×427 crop 60% of
    /// the time. Focal lengths and principal points follow the dataset's calibration files approximately,
    /// jittered per frame (±1% focal, ±3 px centre) as the per-device calibrations differ.
    pub fn native(self, rng: &mut Rng) -> (u32, u32, [f32; 4]) {
        let (w, h, k) = match self {
            Sensor::Kv1 => {
                if rng.chance(0.6) {
                    (561, 427, [520.5, 520.7, 277.9, 215.1])
                } else {
                    (640, 480, [520.5, 520.7, 320.5, 240.5])
                }
            }
            Sensor::Kv2 => (730, 530, [529.5, 529.5, 365.0, 265.0]),
            Sensor::RealSense => (681, 441, [533.0, 533.0, 340.5, 220.5]),
            Sensor::Xtion => (640, 480, [570.3, 570.3, 320.0, 240.0]),
        };
        let f = 1.0 + rng.range(-0.01, 0.01);
        (w, h, [k[0] * f, k[1] * f, k[2] + rng.range(-3.0, 3.0), k[3] + rng.range(-3.0, 3.0)])
    }
}

/// Scales 1-based intrinsics from one image size to another (pixel centres map onto pixel centres).
pub fn scale_intrinsics(k: [f32; 4], from: (u32, u32), to: (u32, u32)) -> [f32; 4] {
    let (sx, sy) = (to.0 as f32 / from.0 as f32, to.1 as f32 / from.1 as f32);
    [k[0] * sx, k[1] * sy, (k[2] - 0.5) * sx + 0.5, (k[3] - 0.5) * sy + 0.5]
}

/// A camera: sensor, image size, intrinsics and pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    pub sensor: Sensor,
    pub width: u32,
    pub height: u32,
    /// (fx, fy, cx, cy), 1-based.
    pub intrinsics: [f32; 4],
    /// World position (z = height above the floor).
    pub position: Vec3,
    /// Direction of the optical axis on the floor plane, radians from +x.
    pub heading: f32,
    /// Downward pitch (radians).
    pub pitch: f32,
    /// Roll about the optical axis (radians).
    pub roll: f32,
}

impl View {
    /// Rtilt = Rx(−pitch)·Ry(roll) (upright from the camera's (x, z, −y)).
    pub fn rtilt(&self) -> DMat3 {
        DMat3::from_rotation_x(-self.pitch as f64) * DMat3::from_rotation_y(self.roll as f64)
    }

    /// Rotation from world directions to upright ones: Rz(π/2 − heading).
    pub fn world_to_upright(&self) -> Mat3 {
        Mat3::from_rotation_z(std::f32::consts::FRAC_PI_2 - self.heading)
    }

    pub fn to_upright(&self, world: Vec3) -> Vec3 {
        self.world_to_upright() * (world - self.position)
    }

    /// A world yaw in the upright frame, wrapped into (−π, π].
    pub fn yaw_to_upright(&self, yaw: f32) -> f32 {
        wrap_angle(yaw + std::f32::consts::FRAC_PI_2 - self.heading)
    }

    /// The camera-to-world direction matrix: world = M·(x, y, z) for camera (x right, y down, z forward).
    pub fn camera_to_world(&self) -> Mat3 {
        let rtilt = self.rtilt().as_mat3();
        // Camera (x, y, z) → (x, z, −y) → upright → world.
        let swap = Mat3::from_cols(Vec3::X, -Vec3::Z, Vec3::Y);
        self.world_to_upright().transpose() * rtilt * swap
    }

    /// The geometry module's camera for projecting upright points.
    pub fn camera(&self) -> Camera {
        Camera::new(self.intrinsics, self.rtilt().as_mat3())
    }

    /// K as the frame module stores it.
    pub fn k(&self) -> [[f64; 3]; 3] {
        let [fx, fy, cx, cy] = self.intrinsics.map(|x| x as f64);
        [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
    }
}

/// Draws a camera pose in a furnished room: standing 0.3–1.5 m in front of a wall (70%) or anywhere (30%),
/// at least 0.25 m from furniture, 1.0–1.7 m high (mean 1.3 m), looking at a random object (75%) or across
/// the room, pitched down N(14°, 8°) clamped to 0–35°, rolled N(0, 1.5°) clamped to ±5°.
pub fn sample_pose(scene: &Scene, rng: &mut Rng) -> Option<(Vec3, f32, f32, f32)> {
    let room = &scene.room;
    let walls = room.walls();
    let (lo, hi) = room.bounds();
    for _ in 0..300 {
        let p = if rng.chance(0.7) {
            let w = walls[rng.weighted(&walls.iter().map(|w| w.length).collect::<Vec<_>>())];
            w.point(rng.range(0.3, w.length - 0.3), rng.range(0.3, 1.5))
        } else {
            Vec2::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y))
        };
        if !room.contains(p) || room.wall_distance(p) < 0.3 {
            continue;
        }
        let height = rng.normal_clamped(1.3, 0.15, 1.0, 1.7);
        let blocked = scene.items.iter().any(|it| {
            if !it.collides || it.position.z > height + 0.2 {
                return false;
            }
            let c = it.cuboid();
            let local = c.to_local(p.extend(c.centre.z));
            let dx = (local.x.abs() - 0.5 * c.size.x).max(0.0);
            let dy = (local.y.abs() - 0.5 * c.size.y).max(0.0);
            (dx * dx + dy * dy).sqrt() < 0.25
        });
        if blocked {
            continue;
        }
        let labelled: Vec<usize> = (0..scene.items.len()).filter(|&i| scene.items[i].category().is_some()).collect();
        let target = if !labelled.is_empty() && rng.chance(0.75) {
            scene.items[*rng.pick(&labelled)].position.truncate()
        } else {
            room.centroid() + Vec2::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5))
        };
        let to = target - p;
        if to.length() < 0.8 {
            continue;
        }
        let heading = to.y.atan2(to.x) + rng.normal_clamped(0.0, 0.2, -0.5, 0.5);
        let pitch = rng.normal_clamped(14.0, 8.0, 0.0, 35.0).to_radians();
        let mut roll = rng.normal_clamped(0.0, 1.5, -5.0, 5.0);
        if roll.abs() < 0.1 {
            roll = 0.1f32.copysign(roll);
        }
        return Some((p.extend(height), heading, pitch, roll.to_radians()));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(heading: f32, pitch: f32, roll: f32) -> View {
        View {
            sensor: Sensor::Kv2,
            width: 730,
            height: 530,
            intrinsics: [529.5, 529.5, 365.0, 265.0],
            position: Vec3::new(1.0, 2.0, 1.4),
            heading,
            pitch,
            roll,
        }
    }

    #[test]
    fn optical_axis_follows_heading_and_pitch() {
        let v = view(0.7, 0.3, 0.0);
        let axis = v.camera_to_world() * Vec3::Z;
        let expected = Vec3::new(0.7f32.cos() * 0.3f32.cos(), 0.7f32.sin() * 0.3f32.cos(), -0.3f32.sin());
        assert!((axis - expected).length() < 1e-5, "{axis} vs {expected}");
        // The image's down direction points down in the world (pitch < 90°).
        assert!((v.camera_to_world() * Vec3::Y).z < 0.0);
        // The upright frame has +y along the heading and the camera at its origin.
        let ahead = v.position + Vec3::new(0.7f32.cos(), 0.7f32.sin(), 0.0);
        assert!((v.to_upright(ahead) - Vec3::Y).length() < 1e-5);
    }

    #[test]
    fn projection_agrees_with_ray_directions() {
        // A world point on the ray through a pixel projects back onto that pixel with geometry::Camera.
        let v = view(-1.2, 0.25, 0.04);
        let cam = v.camera();
        let (col, row) = (100.0f32, 400.0f32);
        let [fx, fy, cx, cy] = v.intrinsics;
        let dir = v.camera_to_world() * Vec3::new((col + 1.0 - cx) / fx, (row + 1.0 - cy) / fy, 1.0);
        let p = v.position + dir * 2.5;
        let px = cam.project(v.to_upright(p)).unwrap();
        assert!((px - Vec2::new(col, row)).length() < 1e-3, "{px}");
    }

    #[test]
    fn scaled_intrinsics_keep_the_field_of_view() {
        let k = scale_intrinsics([520.0, 520.0, 320.5, 240.5], (640, 480), (160, 120));
        assert_eq!(k, [130.0, 130.0, 80.5, 60.5]);
    }
}
