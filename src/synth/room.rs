//! Rooms: Manhattan floor plans (rectangles or L shapes), walls with door and window openings, and the
//! room structure (floor, ceiling, walls, baseboards, windows, ceiling fixtures) as render primitives.
//!
//! Rooms live in a world frame with the floor at z = 0 and the walls along the axes; the camera pose later
//! maps the world into SUN RGB-D's camera-centred upright frame.

use glam::{Mat3, Vec2, Vec3};

use super::material::{self as mat, Material};
use super::rng::Rng;
use super::shape::{Prim, Shape};

/// The room types of the generator (SUN RGB-D scene names).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RoomType {
    Bedroom,
    Office,
    LivingRoom,
    Bathroom,
    DiningRoom,
    Classroom,
    Kitchen,
}

impl RoomType {
    pub const ALL: [RoomType; 7] = [
        RoomType::Bedroom,
        RoomType::Office,
        RoomType::LivingRoom,
        RoomType::Bathroom,
        RoomType::DiningRoom,
        RoomType::Classroom,
        RoomType::Kitchen,
    ];

    /// The SUN RGB-D scene name written to `scene.txt`.
    pub fn name(self) -> &'static str {
        match self {
            RoomType::Bedroom => "bedroom",
            RoomType::Office => "office",
            RoomType::LivingRoom => "living_room",
            RoomType::Bathroom => "bathroom",
            RoomType::DiningRoom => "dining_room",
            RoomType::Classroom => "classroom",
            RoomType::Kitchen => "kitchen",
        }
    }

    /// Parses a room type name (`living_room`, `living-room` and `livingroom` are all accepted).
    pub fn parse(name: &str) -> Option<RoomType> {
        let key: String = name.trim().to_ascii_lowercase().chars().filter(|c| c.is_ascii_alphabetic()).collect();
        RoomType::ALL.into_iter().find(|r| r.name().replace('_', "") == key)
    }

    /// Relative frequency in the generated mix (roughly SUN RGB-D's scene mix for these types).
    pub fn weight(self) -> f32 {
        match self {
            RoomType::Bedroom => 0.22,
            RoomType::Office => 0.2,
            RoomType::LivingRoom => 0.14,
            RoomType::Bathroom => 0.1,
            RoomType::DiningRoom => 0.1,
            RoomType::Classroom => 0.12,
            RoomType::Kitchen => 0.12,
        }
    }

    /// Side length ranges (metres) of the room's bounding rectangle.
    fn extent(self) -> ((f32, f32), (f32, f32)) {
        match self {
            RoomType::Bedroom => ((2.8, 5.0), (3.0, 5.5)),
            RoomType::Office => ((3.0, 8.0), (3.0, 8.0)),
            RoomType::LivingRoom => ((3.5, 7.0), (3.5, 8.0)),
            RoomType::Bathroom => ((2.5, 3.6), (2.5, 4.0)),
            RoomType::DiningRoom => ((3.2, 6.0), (3.5, 7.0)),
            RoomType::Classroom => ((5.0, 8.0), (6.0, 8.0)),
            RoomType::Kitchen => ((2.6, 5.0), (3.0, 6.0)),
        }
    }
}

/// An opening in a wall: along the wall from `s0` to `s1` (metres from the wall's start corner), from
/// height `z0` to `z1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Opening {
    pub wall: usize,
    pub s0: f32,
    pub s1: f32,
    pub z0: f32,
    pub z1: f32,
    pub window: bool,
}

/// One wall: from `a` to `b` along the counter-clockwise floor polygon; `normal` points into the room.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    pub a: Vec2,
    pub b: Vec2,
    pub dir: Vec2,
    pub normal: Vec2,
    pub length: f32,
}

impl Wall {
    /// World point at `s` metres along the wall and `offset` metres into the room.
    pub fn point(&self, s: f32, offset: f32) -> Vec2 {
        self.a + self.dir * s + self.normal * offset
    }

    /// Yaw of an object whose front faces into the room from this wall (its back against the wall).
    pub fn facing_yaw(&self) -> f32 {
        self.normal.x.atan2(-self.normal.y)
    }
}

/// A room.
#[derive(Clone, Debug)]
pub struct Room {
    pub kind: RoomType,
    /// Floor polygon, counter-clockwise, metres.
    pub polygon: Vec<Vec2>,
    pub height: f32,
    pub wall_thickness: f32,
    pub openings: Vec<Opening>,
    pub floor_material: Material,
    pub wall_material: Material,
    pub ceiling_material: Material,
    pub trim_material: Material,
    /// Baseboard (height, thickness), if any.
    pub baseboard: Option<(f32, f32)>,
    /// Ceiling light positions (world).
    pub ceiling_lights: Vec<Vec3>,
}

impl Room {
    /// A plain rectangular room `[0, width] × [0, length]` of the given height with neutral materials.
    pub fn rectangle(kind: RoomType, width: f32, length: f32, height: f32) -> Room {
        let mut rng = Rng::new(0);
        let mut wall_material = mat::paint(&mut rng);
        wall_material.colour = Vec3::splat(0.6);
        wall_material.infrared = 0.9;
        Room {
            kind,
            polygon: vec![Vec2::ZERO, Vec2::new(width, 0.0), Vec2::new(width, length), Vec2::new(0.0, length)],
            height,
            wall_thickness: 0.15,
            openings: Vec::new(),
            floor_material: wall_material,
            wall_material,
            ceiling_material: wall_material,
            trim_material: wall_material,
            baseboard: None,
            ceiling_lights: vec![Vec3::new(0.5 * width, 0.5 * length, height - 0.1)],
        }
    }

    /// Draws a room of a type: size, shape (20% L-shaped when large enough), height 2.4–3.2 m, materials.
    pub fn sample(rng: &mut Rng, kind: RoomType) -> Room {
        let ((w0, w1), (l0, l1)) = kind.extent();
        let (w, l) = (rng.range(w0, w1), rng.range(l0, l1));
        let height = rng.range(2.4, 3.2);
        let mut polygon = vec![Vec2::ZERO, Vec2::new(w, 0.0), Vec2::new(w, l), Vec2::new(0.0, l)];
        if w >= 3.5 && l >= 3.5 && kind != RoomType::Bathroom && rng.chance(0.2) {
            let (cw, cl) = (w * rng.range(0.25, 0.42), l * rng.range(0.25, 0.42));
            polygon = vec![
                Vec2::ZERO,
                Vec2::new(w, 0.0),
                Vec2::new(w, l - cl),
                Vec2::new(w - cw, l - cl),
                Vec2::new(w - cw, l),
                Vec2::new(0.0, l),
            ];
            // Mirror to put the missing corner anywhere; a mirror flips the orientation back to CCW by
            // reversing the list.
            if rng.chance(0.5) {
                polygon = polygon.iter().rev().map(|p| Vec2::new(w - p.x, p.y)).collect();
            }
            if rng.chance(0.5) {
                polygon = polygon.iter().rev().map(|p| Vec2::new(p.x, l - p.y)).collect();
            }
        }
        let floor_material = match kind {
            RoomType::Bathroom => mat::tiles(rng, (0.15, 0.45)),
            RoomType::Kitchen => {
                if rng.chance(0.6) {
                    mat::tiles(rng, (0.2, 0.6))
                } else {
                    mat::planks(rng)
                }
            }
            RoomType::Office | RoomType::Classroom => match rng.int(0, 2) {
                0 => mat::carpet(rng),
                1 => mat::tiles(rng, (0.3, 0.6)),
                _ => mat::planks(rng),
            },
            _ => {
                if rng.chance(0.65) {
                    mat::planks(rng)
                } else {
                    mat::carpet(rng)
                }
            }
        };
        let wall_material = if matches!(kind, RoomType::Bathroom | RoomType::Kitchen) && rng.chance(0.5) {
            mat::tiles(rng, (0.1, 0.3))
        } else {
            mat::paint(rng)
        };
        let mut ceiling_material = mat::paint(&mut rng.fork());
        ceiling_material.colour = Vec3::splat(rng.range(0.7, 0.85));
        let trim_material = if rng.chance(0.5) { mat::paint(rng) } else { mat::wood(rng) };
        let baseboard = if rng.chance(0.6) { Some((rng.range(0.05, 0.12), rng.range(0.008, 0.015))) } else { None };
        let mut room = Room {
            kind,
            polygon,
            height,
            wall_thickness: rng.range(0.12, 0.2),
            openings: Vec::new(),
            floor_material,
            wall_material,
            ceiling_material,
            trim_material,
            baseboard,
            ceiling_lights: Vec::new(),
        };
        let (lo, hi) = room.bounds();
        let n_lights = if (hi - lo).x * (hi - lo).y > 20.0 { 2 } else { 1 };
        for _ in 0..n_lights {
            for _ in 0..20 {
                let p = Vec2::new(rng.range(lo.x + 0.8, hi.x - 0.8), rng.range(lo.y + 0.8, hi.y - 0.8));
                if room.contains(p) {
                    room.ceiling_lights.push(p.extend(height - 0.12));
                    break;
                }
            }
        }
        if room.ceiling_lights.is_empty() {
            room.ceiling_lights.push(room.centroid().extend(height - 0.12));
        }
        room
    }

    pub fn walls(&self) -> Vec<Wall> {
        let n = self.polygon.len();
        (0..n)
            .map(|i| {
                let (a, b) = (self.polygon[i], self.polygon[(i + 1) % n]);
                let length = (b - a).length();
                let dir = (b - a) / length;
                Wall { a, b, dir, normal: dir.perp(), length }
            })
            .collect()
    }

    pub fn bounds(&self) -> (Vec2, Vec2) {
        self.polygon
            .iter()
            .fold((Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    pub fn centroid(&self) -> Vec2 {
        // Area-weighted centroid of the polygon.
        let n = self.polygon.len();
        let (mut area, mut c) = (0.0f32, Vec2::ZERO);
        for i in 0..n {
            let (p, q) = (self.polygon[i], self.polygon[(i + 1) % n]);
            let cross = p.perp_dot(q);
            area += cross;
            c += (p + q) * cross;
        }
        c / (3.0 * area)
    }

    pub fn area(&self) -> f32 {
        let n = self.polygon.len();
        0.5 * (0..n).map(|i| self.polygon[i].perp_dot(self.polygon[(i + 1) % n])).sum::<f32>()
    }

    /// Whether a floor point is inside the polygon (even-odd rule).
    pub fn contains(&self, p: Vec2) -> bool {
        crate::geometry::polygon_contains(&self.polygon, p)
    }

    /// Distance from a floor point to the nearest wall segment.
    pub fn wall_distance(&self, p: Vec2) -> f32 {
        self.walls()
            .iter()
            .map(|w| {
                let s = (p - w.a).dot(w.dir).clamp(0.0, w.length);
                (w.a + w.dir * s - p).length()
            })
            .fold(f32::INFINITY, f32::min)
    }

    /// Whether the wall's interval [s0, s1] is free of openings (with a margin).
    pub fn wall_free(&self, wall: usize, s0: f32, s1: f32, margin: f32) -> bool {
        self.openings.iter().filter(|o| o.wall == wall).all(|o| s1 + margin <= o.s0 || s0 - margin >= o.s1)
    }

    /// Whether the polygon turns left (a convex corner) at vertex `i`.
    fn convex_at(&self, i: usize) -> bool {
        let n = self.polygon.len();
        let (p, c, q) = (self.polygon[(i + n - 1) % n], self.polygon[i], self.polygon[(i + 1) % n]);
        (c - p).perp_dot(q - c) > 0.0
    }

    /// Appends the room structure's primitives (instance 0) and materials.
    pub fn structure(&self, rng: &mut Rng, materials: &mut Vec<Material>, prims: &mut Vec<Prim>) {
        let mut add_mat = |m: Material| {
            materials.push(m);
            (materials.len() - 1) as u32
        };
        let floor = add_mat(self.floor_material);
        let wall_m = add_mat(self.wall_material);
        let ceiling = add_mat(self.ceiling_material);
        let trim = add_mat(self.trim_material);
        let glass = add_mat(mat::window_glass(rng));
        let frame = add_mat(if rng.chance(0.6) { mat::paint(rng) } else { mat::metal(rng) });
        let fixture = add_mat({
            let mut m = mat::paper(rng);
            m.emission = Vec3::new(1.0, 0.95, 0.85) * 1.5;
            m
        });
        let th = self.wall_thickness;
        let (lo, hi) = self.bounds();
        let mut seed = || rng.next_u64() as u32;
        let aabb = |lo: Vec3, hi: Vec3, m: u32, s: u32| {
            Prim::new(Shape::Box, 0.5 * (lo + hi), Mat3::IDENTITY, 0.5 * (hi - lo), m, 0, s)
        };
        prims.push(aabb((lo - Vec2::splat(th)).extend(-0.1), (hi + Vec2::splat(th)).extend(0.0), floor, seed()));
        prims.push(aabb(
            (lo - Vec2::splat(th)).extend(self.height),
            (hi + Vec2::splat(th)).extend(self.height + 0.1),
            ceiling,
            seed(),
        ));
        let n = self.polygon.len();
        for (i, w) in self.walls().iter().enumerate() {
            let rot = Mat3::from_cols(w.dir.extend(0.0), w.normal.extend(0.0), Vec3::Z);
            // A box on this wall from s0 to s1 along it, from `n0` to `n1` along the inward normal.
            let mut piece = |s0: f32, s1: f32, n0: f32, n1: f32, z0: f32, z1: f32, m: u32, s: u32| {
                if s1 - s0 < 1e-4 || z1 - z0 < 1e-4 {
                    return;
                }
                let c = w.point(0.5 * (s0 + s1), 0.5 * (n0 + n1)).extend(0.5 * (z0 + z1));
                prims.push(Prim::new(
                    Shape::Box,
                    c,
                    rot,
                    Vec3::new(0.5 * (s1 - s0), 0.5 * (n1 - n0), 0.5 * (z1 - z0)),
                    m,
                    0,
                    s,
                ));
            };
            let start = if self.convex_at(i) { -th } else { 0.0 };
            let end = if self.convex_at((i + 1) % n) { w.length + th } else { w.length };
            let mut openings: Vec<Opening> = self.openings.iter().copied().filter(|o| o.wall == i).collect();
            openings.sort_by(|a, b| a.s0.total_cmp(&b.s0));
            let wall_seed = seed();
            let mut cursor = start;
            for o in &openings {
                piece(cursor, o.s0, -th, 0.0, 0.0, self.height, wall_m, wall_seed);
                piece(o.s0, o.s1, -th, 0.0, 0.0, o.z0, wall_m, wall_seed);
                piece(o.s0, o.s1, -th, 0.0, o.z1, self.height, wall_m, wall_seed);
                cursor = o.s1;
                if o.window {
                    let pane = -0.6 * th;
                    piece(o.s0, o.s1, pane - 0.01, pane, o.z0, o.z1, glass, seed());
                    let bar = 0.05;
                    let fs = seed();
                    piece(o.s0, o.s0 + bar, pane - 0.03, pane + 0.03, o.z0, o.z1, frame, fs);
                    piece(o.s1 - bar, o.s1, pane - 0.03, pane + 0.03, o.z0, o.z1, frame, fs);
                    piece(o.s0, o.s1, pane - 0.03, pane + 0.03, o.z0, o.z0 + bar, frame, fs);
                    piece(o.s0, o.s1, pane - 0.03, pane + 0.03, o.z1 - bar, o.z1, frame, fs);
                    if o.s1 - o.s0 > 1.0 {
                        let m = 0.5 * (o.s0 + o.s1);
                        piece(m - 0.5 * bar, m + 0.5 * bar, pane - 0.03, pane + 0.03, o.z0, o.z1, frame, fs);
                    }
                    piece(o.s0 - 0.05, o.s1 + 0.05, -0.02, 0.035, o.z0 - 0.03, o.z0, trim, seed());
                }
            }
            piece(cursor, end, -th, 0.0, 0.0, self.height, wall_m, wall_seed);
            if let Some((bh, bt)) = self.baseboard {
                let trim_seed = seed();
                let mut cursor = 0.0;
                // Baseboards stop at door casings (which reach past the opening).
                for o in openings.iter().filter(|o| o.z0 < bh) {
                    piece(cursor, o.s0 - 0.1, 0.0, bt, 0.0, bh, trim, trim_seed);
                    cursor = o.s1 + 0.1;
                }
                piece(cursor, w.length, 0.0, bt, 0.0, bh, trim, trim_seed);
            }
        }
        for l in &self.ceiling_lights {
            let r = 0.15 + 0.15 * (seed() as f32 / u32::MAX as f32);
            prims.push(Prim::new(
                Shape::Frustum { bottom: 0.8, top: 1.0 },
                Vec3::new(l.x, l.y, self.height - 0.03),
                Mat3::IDENTITY,
                Vec3::new(r, r, 0.03),
                fixture,
                0,
                seed(),
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_rooms_are_counter_clockwise() {
        for r in RoomType::ALL {
            assert_eq!(RoomType::parse(r.name()), Some(r));
        }
        assert_eq!(RoomType::parse("Living-Room"), Some(RoomType::LivingRoom));
        assert_eq!(RoomType::parse("garage"), None);
        for i in 0..200 {
            let mut rng = Rng::new(i);
            let room = Room::sample(&mut rng, RoomType::ALL[i as usize % 7]);
            assert!(room.area() > 0.0);
            let c = room.centroid();
            assert!(room.contains(c) || room.polygon.len() == 6);
            for w in room.walls() {
                // The inward normal points inside: a point 5 cm in from the wall's middle is in the room.
                assert!(room.contains(w.point(0.5 * w.length, 0.05)));
                assert!(!room.contains(w.point(0.5 * w.length, -0.05)));
            }
        }
    }
}
