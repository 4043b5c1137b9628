//! Geometric primitives: parts of models in a model's local frame, and the world-space primitives the
//! ray caster intersects.
//!
//! Every primitive is a canonical shape (the cube [-1, 1]³, a frustum of a unit cylinder along z, the unit
//! sphere) under a scale (`half` extents), a rotation and a translation. Rays are mapped into the canonical
//! frame with one 3×3 matrix; since the map is linear, the ray parameter `t` is the same in both frames.

use glam::{Mat3, Vec3};

/// The canonical shape of a primitive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// The box [-hx, hx] × [-hy, hy] × [-hz, hz].
    Box,
    /// An elliptic frustum along z: radius fraction `bottom` at z = -hz and `top` at z = +hz of (hx, hy);
    /// the larger of the two should be 1 so `half` bounds the shape.
    Frustum { bottom: f32, top: f32 },
    /// The ellipsoid with semi-axes `half`.
    Ellipsoid,
}

/// A part of a model, in the model's local frame (s along the width, t along the depth with the front at
/// −t, u up from the model's bottom).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Part {
    pub shape: Shape,
    pub centre: Vec3,
    pub half: Vec3,
    /// Rotation of the part about u (radians).
    pub yaw: f32,
    /// Rotation of the part about s after the yaw (radians; leaning backrests, laptop screens).
    pub tilt: f32,
    /// Index into the model's material list.
    pub material: u16,
}

impl Part {
    /// The part's rotation in the model frame.
    pub fn rotation(&self) -> Mat3 {
        Mat3::from_rotation_z(self.yaw) * Mat3::from_rotation_x(self.tilt)
    }

    /// Axis-aligned bounds (min, max) of the part in the model frame.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        shape_bounds(self.shape, self.centre, self.rotation(), self.half)
    }
}

/// Axis-aligned bounds of a shape under rotation `rot` at `centre`. Exact for boxes and ellipsoids; for a
/// frustum the bounds of its box (exact when it is upright).
pub fn shape_bounds(shape: Shape, centre: Vec3, rot: Mat3, half: Vec3) -> (Vec3, Vec3) {
    let ext = match shape {
        Shape::Ellipsoid => {
            let m = rot * Mat3::from_diagonal(half);
            Vec3::new(m.row(0).length(), m.row(1).length(), m.row(2).length())
        }
        Shape::Box | Shape::Frustum { .. } => {
            let a = rot.abs();
            a * half
        }
    };
    (centre - ext, centre + ext)
}

/// A world-space primitive ready for ray casting.
#[derive(Clone, Copy, Debug)]
pub struct Prim {
    pub shape: Shape,
    pub centre: Vec3,
    /// Maps a world vector into the canonical frame: `S⁻¹·Rᵀ`.
    pub to_canonical: Mat3,
    /// Local-to-world rotation R.
    pub rotation: Mat3,
    pub half: Vec3,
    /// Index into the scene's material list.
    pub material: u32,
    /// Which scene instance the primitive belongs to (0 = room structure).
    pub instance: u32,
    /// Per-primitive texture seed.
    pub texture_seed: u32,
    /// Local axis the wood grain runs along (the longest one).
    pub grain: u8,
}

/// A ray hit: distance, canonical-frame normal.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    pub normal_canonical: Vec3,
}

/// Rays hitting closer than this (in ray parameter units) are ignored (self-intersection of shadow rays).
pub const T_EPSILON: f32 = 1e-4;

impl Prim {
    pub fn new(
        shape: Shape,
        centre: Vec3,
        rotation: Mat3,
        half: Vec3,
        material: u32,
        instance: u32,
        texture_seed: u32,
    ) -> Self {
        let half = half.max(Vec3::splat(1e-4));
        let to_canonical = Mat3::from_diagonal(half.recip()) * rotation.transpose();
        let grain = if half.x >= half.y && half.x >= half.z {
            0
        } else if half.y >= half.z {
            1
        } else {
            2
        };
        Prim { shape, centre, to_canonical, rotation, half, material, instance, texture_seed, grain }
    }

    pub fn bounds(&self) -> (Vec3, Vec3) {
        shape_bounds(self.shape, self.centre, self.rotation, self.half)
    }

    /// The nearest intersection with `t` in (T_EPSILON, t_max).
    #[inline]
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        let o = self.to_canonical * (origin - self.centre);
        let d = self.to_canonical * dir;
        match self.shape {
            Shape::Box => intersect_cube(o, d, t_max),
            Shape::Ellipsoid => intersect_sphere(o, d, t_max),
            Shape::Frustum { bottom, top } => intersect_frustum(o, d, bottom, top, t_max),
        }
    }

    /// World normal from a canonical one (inverse transpose of the linear map).
    pub fn world_normal(&self, normal_canonical: Vec3) -> Vec3 {
        (self.to_canonical.transpose() * normal_canonical).normalize_or(Vec3::Z)
    }

    /// Metric point in the primitive's own (rotated, unscaled) frame.
    pub fn local_point(&self, world: Vec3) -> Vec3 {
        self.rotation.transpose() * (world - self.centre)
    }
}

#[inline]
fn intersect_cube(o: Vec3, d: Vec3, t_max: f32) -> Option<Hit> {
    let inv = d.recip();
    let t0 = (Vec3::splat(-1.0) - o) * inv;
    let t1 = (Vec3::splat(1.0) - o) * inv;
    let tmin = t0.min(t1);
    let tmax = t0.max(t1);
    let t_enter = tmin.max_element();
    let t_exit = tmax.min_element();
    if t_enter > t_exit || t_exit < T_EPSILON || t_enter >= t_max || t_enter < T_EPSILON {
        return None;
    }
    let normal = if tmin.x >= tmin.y && tmin.x >= tmin.z {
        Vec3::new(-d.x.signum(), 0.0, 0.0)
    } else if tmin.y >= tmin.z {
        Vec3::new(0.0, -d.y.signum(), 0.0)
    } else {
        Vec3::new(0.0, 0.0, -d.z.signum())
    };
    Some(Hit { t: t_enter, normal_canonical: normal })
}

#[inline]
fn intersect_sphere(o: Vec3, d: Vec3, t_max: f32) -> Option<Hit> {
    let a = d.dot(d);
    let b = o.dot(d);
    let c = o.dot(o) - 1.0;
    let disc = b * b - a * c;
    if disc < 0.0 {
        return None;
    }
    let t = (-b - disc.sqrt()) / a;
    if t < T_EPSILON || t >= t_max {
        return None;
    }
    Some(Hit { t, normal_canonical: o + d * t })
}

#[inline]
fn intersect_frustum(o: Vec3, d: Vec3, bottom: f32, top: f32, t_max: f32) -> Option<Hit> {
    // Radius r(z) = rm + k·z for z in [-1, 1].
    let rm = 0.5 * (bottom + top);
    let k = 0.5 * (top - bottom);
    let mut best: Option<Hit> = None;
    let mut limit = t_max;
    let a = d.x * d.x + d.y * d.y - k * k * d.z * d.z;
    let r0 = rm + k * o.z;
    let b = o.x * d.x + o.y * d.y - k * r0 * d.z;
    let c = o.x * o.x + o.y * o.y - r0 * r0;
    if a.abs() > 1e-12 {
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            let (mut t1, mut t2) = ((-b - sq) / a, (-b + sq) / a);
            if t1 > t2 {
                std::mem::swap(&mut t1, &mut t2);
            }
            for t in [t1, t2] {
                if t > T_EPSILON && t < limit {
                    let z = o.z + t * d.z;
                    if (-1.0..=1.0).contains(&z) && rm + k * z >= 0.0 {
                        let p = o + d * t;
                        best = Some(Hit { t, normal_canonical: Vec3::new(p.x, p.y, -k * (rm + k * z)) });
                        limit = t;
                        break;
                    }
                }
            }
        }
    }
    if d.z.abs() > 1e-12 {
        for (z, r, nz) in [(-1.0f32, bottom, -1.0f32), (1.0, top, 1.0)] {
            let t = (z - o.z) / d.z;
            if t > T_EPSILON && t < limit {
                let (x, y) = (o.x + t * d.x, o.y + t * d.y);
                if x * x + y * y <= r * r {
                    best = Some(Hit { t, normal_canonical: Vec3::new(0.0, 0.0, nz) });
                    limit = t;
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prim(shape: Shape, centre: Vec3, yaw: f32, half: Vec3) -> Prim {
        Prim::new(shape, centre, Mat3::from_rotation_z(yaw), half, 0, 0, 0)
    }

    #[test]
    fn box_hit_distance_and_normal() {
        let p = prim(Shape::Box, Vec3::new(0.0, 5.0, 0.0), 0.3, Vec3::new(1.0, 0.5, 1.0));
        // Straight along +y from the origin: the face nearest the origin, rotated by 0.3 rad about z.
        let hit = p.intersect(Vec3::ZERO, Vec3::Y, 100.0).unwrap();
        let n = p.world_normal(hit.normal_canonical);
        let face_normal = Mat3::from_rotation_z(0.3) * Vec3::new(0.0, -1.0, 0.0);
        assert!((n - face_normal).length() < 1e-5);
        // The hit point lies on the plane of that face: distance 0.5 from the centre along the normal.
        let q = Vec3::Y * hit.t;
        assert!(((q - p.centre).dot(face_normal) - 0.5).abs() < 1e-4);
        assert!(p.intersect(Vec3::ZERO, Vec3::X, 100.0).is_none());
    }

    #[test]
    fn sphere_and_cylinder_hits() {
        let s = prim(Shape::Ellipsoid, Vec3::new(0.0, 4.0, 0.0), 0.0, Vec3::splat(1.0));
        assert!((s.intersect(Vec3::ZERO, Vec3::Y, 100.0).unwrap().t - 3.0).abs() < 1e-5);
        // An ellipsoid stretched along y by 2.
        let e = prim(Shape::Ellipsoid, Vec3::new(0.0, 4.0, 0.0), 0.0, Vec3::new(1.0, 2.0, 1.0));
        assert!((e.intersect(Vec3::ZERO, Vec3::Y, 100.0).unwrap().t - 2.0).abs() < 1e-5);
        // A cylinder of radius 0.5 standing at y = 3: the side at y = 2.5, the top cap from above.
        let c = prim(Shape::Frustum { bottom: 1.0, top: 1.0 }, Vec3::new(0.0, 3.0, 0.0), 0.0, Vec3::new(0.5, 0.5, 1.0));
        let side = c.intersect(Vec3::ZERO, Vec3::Y, 100.0).unwrap();
        assert!((side.t - 2.5).abs() < 1e-5);
        assert!((c.world_normal(side.normal_canonical) - Vec3::new(0.0, -1.0, 0.0)).length() < 1e-5);
        let cap = c.intersect(Vec3::new(0.0, 3.0, 5.0), -Vec3::Z, 100.0).unwrap();
        assert!((cap.t - 4.0).abs() < 1e-5);
        // A cone (top radius 0): at height z (canonical), radius = 0.5·(1 − z)/2 along x.
        let cone = prim(Shape::Frustum { bottom: 1.0, top: 0.0 }, Vec3::ZERO, 0.0, Vec3::new(1.0, 1.0, 1.0));
        let h = cone.intersect(Vec3::new(-5.0, 0.0, 0.0), Vec3::X, 100.0).unwrap();
        assert!((h.t - 4.5).abs() < 1e-4, "{}", h.t);
    }
}
