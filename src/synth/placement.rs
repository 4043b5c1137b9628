//! Furnishing a room like a real one.
//!
//! Each room type has a recipe: which objects appear with which probability, what stands against a wall
//! (beds, dressers, bookshelves, toilets, counters, bathtubs, wardrobes...), what goes next to what
//! (nightstands beside the bed, chairs facing desks and around tables, a coffee table in front of the sofa),
//! and what stands on which support surface (pillows on beds, lamps on nightstands and tables, monitors on
//! desks, TVs on dressers or cabinets, boxes on floors and shelves, books on shelves). Every candidate pose is
//! checked against the room polygon, the door swings and window sills, and every other item's footprint and
//! height range, so nothing interpenetrates except an item and what it stands on.

use glam::{Vec2, Vec3};

use super::furniture::{self, Model};
use super::rng::Rng;
use super::room::{Opening, Room, RoomType, Wall};
use crate::geometry::Cuboid;

/// What an item is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ItemKind {
    /// A labelled object of one of the 19 categories.
    Object(&'static str),
    /// Unlabelled clutter (plants, books, wardrobes, pictures...).
    Clutter(&'static str),
}

impl ItemKind {
    pub fn name(self) -> &'static str {
        match self {
            ItemKind::Object(n) | ItemKind::Clutter(n) => n,
        }
    }
}

/// What an item rests on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rest {
    Floor,
    /// On support surface `surface` of item `parent`.
    On {
        parent: usize,
        surface: usize,
    },
    /// Hung on (or set into) wall `wall`.
    Wall {
        wall: usize,
    },
}

/// A placed model.
#[derive(Clone, Debug)]
pub struct Item {
    pub kind: ItemKind,
    pub model: Model,
    /// World position of the model's origin (the centre of its bottom face).
    pub position: Vec3,
    pub yaw: f32,
    pub rest: Rest,
    /// Rugs and the like do not take part in collision checks.
    pub collides: bool,
}

impl Item {
    /// The item's cuboid in the world frame (the model's bounds).
    pub fn cuboid(&self) -> Cuboid {
        Cuboid::new(self.position + Vec3::Z * (0.5 * self.model.size.z), self.model.size, self.yaw)
    }

    pub fn category(&self) -> Option<&'static str> {
        match self.kind {
            ItemKind::Object(c) => Some(c),
            ItemKind::Clutter(_) => None,
        }
    }

    pub fn parent(&self) -> Option<usize> {
        match self.rest {
            Rest::On { parent, .. } => Some(parent),
            _ => None,
        }
    }

    /// World point of a model-frame point.
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        let (s, c) = self.yaw.sin_cos();
        self.position + Vec3::new(local.x * c - local.y * s, local.x * s + local.y * c, local.z)
    }

    fn obb(&self) -> Obb {
        Obb::new(self.position.truncate(), 0.5 * self.model.size.truncate(), self.yaw)
    }

    fn z_range(&self) -> (f32, f32) {
        (self.position.z, self.position.z + self.model.size.z)
    }
}

/// A furnished room.
#[derive(Clone, Debug)]
pub struct Scene {
    pub room: Room,
    pub items: Vec<Item>,
}

impl Scene {
    /// Whether `ancestor` is `item`'s parent, grandparent, ...
    pub fn is_ancestor(&self, ancestor: usize, item: usize) -> bool {
        let mut cur = self.items[item].parent();
        while let Some(p) = cur {
            if p == ancestor {
                return true;
            }
            cur = self.items[p].parent();
        }
        false
    }
}

/// An oriented rectangle on the floor plane.
#[derive(Clone, Copy, Debug)]
struct Obb {
    centre: Vec2,
    axes: [Vec2; 2],
    half: Vec2,
}

impl Obb {
    fn new(centre: Vec2, half: Vec2, yaw: f32) -> Self {
        let a = Vec2::new(yaw.cos(), yaw.sin());
        Obb { centre, axes: [a, a.perp()], half }
    }

    fn corners(&self) -> [Vec2; 4] {
        let (a, b) = (self.axes[0] * self.half.x, self.axes[1] * self.half.y);
        [self.centre - a - b, self.centre + a - b, self.centre + a + b, self.centre - a + b]
    }

    fn contains(&self, p: Vec2) -> bool {
        let d = p - self.centre;
        d.dot(self.axes[0]).abs() < self.half.x && d.dot(self.axes[1]).abs() < self.half.y
    }

    fn grown(&self, margin: f32) -> Obb {
        Obb { half: self.half + Vec2::splat(margin), ..*self }
    }

    /// Separating-axis test; `margin` is the clearance both must keep.
    fn overlaps(&self, other: &Obb, margin: f32) -> bool {
        let d = other.centre - self.centre;
        for axis in [self.axes[0], self.axes[1], other.axes[0], other.axes[1]] {
            let ra = self.half.x * self.axes[0].dot(axis).abs() + self.half.y * self.axes[1].dot(axis).abs();
            let rb = other.half.x * other.axes[0].dot(axis).abs() + other.half.y * other.axes[1].dot(axis).abs();
            if d.dot(axis).abs() >= ra + rb + margin {
                return false;
            }
        }
        true
    }
}

/// Floor or wall space no item may take: door swings, window sills.
#[derive(Clone, Copy, Debug)]
struct Zone {
    obb: Obb,
    z0: f32,
    z1: f32,
}

/// Which side of an anchor item a dependent goes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Front,
    Back,
    Left,
    Right,
}

/// Where on a support surface a small item goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Spot {
    Anywhere,
    /// Near the back edge (monitors, TVs, lamps against the wall).
    Back,
}

struct Planner<'a> {
    room: Room,
    walls: Vec<Wall>,
    items: Vec<Item>,
    zones: Vec<Zone>,
    rng: &'a mut Rng,
}

const FLOOR_GAP: f32 = 0.02;

impl<'a> Planner<'a> {
    fn new(room: Room, rng: &'a mut Rng) -> Self {
        let walls = room.walls();
        Planner { room, walls, items: Vec::new(), zones: Vec::new(), rng }
    }

    fn ancestors(&self, parent: Option<usize>) -> Vec<usize> {
        let mut out = Vec::new();
        let mut cur = parent;
        while let Some(p) = cur {
            out.push(p);
            cur = self.items[p].parent();
        }
        out
    }

    fn inside_room(&self, obb: &Obb, margin: f32) -> bool {
        let g = obb.grown(margin);
        g.corners().iter().all(|c| self.room.contains(*c)) && !self.room.polygon.iter().any(|v| g.contains(*v))
    }

    /// Whether a candidate item fits: inside the room, clear of zones and of every other item except its
    /// ancestors.
    fn fits(&self, item: &Item, margin: f32) -> bool {
        let obb = item.obb();
        let (z0, z1) = item.z_range();
        if !matches!(item.rest, Rest::Wall { .. }) && !self.inside_room(&obb, 0.012) {
            return false;
        }
        if z1 > self.room.height - 0.02 {
            return false;
        }
        if !item.collides {
            return true;
        }
        if self.zones.iter().any(|z| z.z0 < z1 && z0 < z.z1 && z.obb.overlaps(&obb, 0.0)) {
            return false;
        }
        let ancestors = self.ancestors(item.parent());
        for (j, other) in self.items.iter().enumerate() {
            if !other.collides || ancestors.contains(&j) {
                continue;
            }
            let (o0, o1) = other.z_range();
            if o0 < z1 - 1e-4 && z0 < o1 - 1e-4 && obb.overlaps(&other.obb(), margin) {
                return false;
            }
        }
        true
    }

    fn push_if_fits(&mut self, item: Item, margin: f32) -> Option<usize> {
        if self.fits(&item, margin) {
            self.items.push(item);
            Some(self.items.len() - 1)
        } else {
            None
        }
    }

    fn object(&mut self, category: &'static str, variant: Option<&'static str>) -> (ItemKind, Model) {
        let mut r = self.rng.fork();
        (ItemKind::Object(category), furniture::build(category, variant, &mut r))
    }

    fn clutter(&mut self, name: &'static str) -> (ItemKind, Model) {
        let mut r = self.rng.fork();
        (ItemKind::Clutter(name), furniture::clutter(name, &mut r))
    }

    fn random_wall(&mut self, min_length: f32) -> Option<usize> {
        let weights: Vec<f32> =
            self.walls.iter().map(|w| if w.length >= min_length { w.length } else { 0.0 }).collect();
        if weights.iter().all(|&w| w == 0.0) {
            return None;
        }
        Some(self.rng.weighted(&weights))
    }

    /// Places a model with its back against a wall (front into the room).
    fn against_wall(
        &mut self,
        (kind, model): (ItemKind, Model),
        wall: Option<usize>,
        along: Option<f32>,
        tries: usize,
    ) -> Option<usize> {
        let (w, d) = (model.size.x, model.size.y);
        for _ in 0..tries {
            let wi = wall.or_else(|| self.random_wall(w + 0.1))?;
            let wall_ = self.walls[wi];
            if wall_.length < w + 0.04 {
                continue;
            }
            let s = along.unwrap_or_else(|| self.rng.range(0.5 * w + 0.02, wall_.length - 0.5 * w - 0.02));
            let gap = self.rng.range(FLOOR_GAP + 0.005, 0.06);
            let c = wall_.point(s, gap + 0.5 * d);
            let item = Item {
                kind,
                model: model.clone(),
                position: c.extend(0.0),
                yaw: wall_.facing_yaw(),
                rest: Rest::Floor,
                collides: true,
            };
            if let Some(i) = self.push_if_fits(item, FLOOR_GAP) {
                return Some(i);
            }
            if along.is_some() && wall.is_some() {
                break;
            }
        }
        None
    }

    /// Places a model into a corner-ish spot against a wall: at one end of the wall.
    fn in_corner(&mut self, entry: (ItemKind, Model), tries: usize) -> Option<usize> {
        for _ in 0..tries {
            let wi = self.random_wall(entry.1.size.x + 0.1)?;
            let len = self.walls[wi].length;
            let half = 0.5 * entry.1.size.x + self.rng.range(0.03, 0.2);
            let s = if self.rng.chance(0.5) { half } else { len - half };
            if let Some(i) = self.against_wall(entry.clone(), Some(wi), Some(s), 1) {
                return Some(i);
            }
        }
        None
    }

    /// Places a model beside `anchor` along the same wall (nightstands by a bed).
    fn beside(&mut self, anchor: usize, entry: (ItemKind, Model), side: f32) -> Option<usize> {
        let anchor_width = self.items[anchor].model.size.x;
        let (wi, s_anchor) = self.wall_of(anchor)?;
        let gap = self.rng.range(0.02, 0.15);
        let s = s_anchor + side * (0.5 * anchor_width + gap + 0.5 * entry.1.size.x);
        self.against_wall(entry, Some(wi), Some(s), 1)
    }

    /// The wall an item stands against and its position along it.
    fn wall_of(&self, item: usize) -> Option<(usize, f32)> {
        let it = &self.items[item];
        let c = it.position.truncate();
        let front = Vec2::new(it.yaw.sin(), -it.yaw.cos());
        self.walls.iter().enumerate().find_map(|(i, w)| {
            let facing = w.normal.dot(front) > 0.99;
            let dist = (c - w.a).dot(w.normal);
            let s = (c - w.a).dot(w.dir);
            (facing && dist > 0.0 && dist < 0.5 * it.model.size.y + 0.1 && s >= 0.0 && s <= w.length).then_some((i, s))
        })
    }

    /// Places a model on one side of `anchor`, facing it (chairs at desks and tables).
    fn facing(
        &mut self,
        anchor: usize,
        entry: (ItemKind, Model),
        side: Side,
        offset: f32,
        gap: (f32, f32),
        jitter: f32,
    ) -> Option<usize> {
        let a = self.items[anchor].cuboid();
        let (wa, da) = (a.width_axis(), a.depth_axis());
        let (n, extent, along) = match side {
            Side::Front => (-da, 0.5 * a.size.y, wa),
            Side::Back => (da, 0.5 * a.size.y, wa),
            Side::Left => (-wa, 0.5 * a.size.x, da),
            Side::Right => (wa, 0.5 * a.size.x, da),
        };
        let (kind, model) = entry;
        for _ in 0..4 {
            let g = self.rng.range(gap.0, gap.1);
            let c = a.centre.truncate() + n * (extent + g + 0.5 * model.size.y) + along * offset;
            let yaw = (-n.x).atan2(n.y) + jitter * self.rng.range(-1.0, 1.0);
            let item =
                Item { kind, model: model.clone(), position: c.extend(0.0), yaw, rest: Rest::Floor, collides: true };
            if let Some(i) = self.push_if_fits(item, FLOOR_GAP) {
                return Some(i);
            }
        }
        None
    }

    /// Places a model anywhere on the floor, axis-aligned with the room (± `jitter`), optionally near a
    /// point.
    fn free(
        &mut self,
        (kind, model): (ItemKind, Model),
        near: Option<(Vec2, f32)>,
        jitter: f32,
        tries: usize,
    ) -> Option<usize> {
        let (lo, hi) = self.room.bounds();
        for _ in 0..tries {
            let c = match near {
                Some((p, r)) => p + Vec2::new(self.rng.range(-r, r), self.rng.range(-r, r)),
                None => Vec2::new(self.rng.range(lo.x, hi.x), self.rng.range(lo.y, hi.y)),
            };
            let yaw = (self.rng.int(0, 3) as f32) * std::f32::consts::FRAC_PI_2 + jitter * self.rng.range(-1.0, 1.0);
            let collides = kind != ItemKind::Clutter("rug");
            let item = Item { kind, model: model.clone(), position: c.extend(0.0), yaw, rest: Rest::Floor, collides };
            if let Some(i) = self.push_if_fits(item, FLOOR_GAP) {
                return Some(i);
            }
        }
        None
    }

    /// Places a small model on a support surface of `parent` (the first surface that fits when `surface`
    /// is `None`, trying them in random order). `turn` is the yaw relative to the parent.
    fn on(
        &mut self,
        parent: usize,
        (kind, model): (ItemKind, Model),
        surface: Option<usize>,
        spot: Spot,
        turn: f32,
        tries: usize,
    ) -> Option<usize> {
        let supports = self.items[parent].model.supports.clone();
        let mut order: Vec<usize> = match surface {
            Some(s) if s < supports.len() => vec![s],
            Some(_) => return None,
            None => (0..supports.len()).collect(),
        };
        if surface.is_none() {
            self.rng.shuffle(&mut order);
        }
        let (w, d, h) = (model.size.x, model.size.y, model.size.z);
        for si in order {
            let sup = supports[si];
            if h > sup.clearance - 0.01 {
                continue;
            }
            let (sn, cs) = turn.sin_cos();
            let ext_s = 0.5 * (cs.abs() * w + sn.abs() * d);
            let ext_t = 0.5 * (sn.abs() * w + cs.abs() * d);
            let [s0, s1, t0, t1] = sup.rect;
            if s1 - s0 < 2.0 * ext_s || t1 - t0 < 2.0 * ext_t {
                continue;
            }
            for _ in 0..tries {
                let s = self.rng.range(s0 + ext_s, s1 - ext_s);
                let t = match spot {
                    Spot::Back => t1 - ext_t - self.rng.range(0.0, 0.05).min(t1 - t0 - 2.0 * ext_t),
                    Spot::Anywhere => self.rng.range(t0 + ext_t, t1 - ext_t),
                };
                let p = self.items[parent].to_world(Vec3::new(s, t, sup.z));
                let item = Item {
                    kind,
                    model: model.clone(),
                    position: p,
                    yaw: self.items[parent].yaw + turn,
                    rest: Rest::On { parent, surface: si },
                    collides: true,
                };
                if let Some(i) = self.push_if_fits(item, 0.01) {
                    return Some(i);
                }
            }
        }
        None
    }

    /// Hangs a model on a wall with its bottom at height `z` (pictures, whiteboards, mirrors, wall TVs,
    /// upper cabinets).
    fn on_wall(
        &mut self,
        (kind, model): (ItemKind, Model),
        wall: Option<usize>,
        along: Option<f32>,
        z: (f32, f32),
        tries: usize,
    ) -> Option<usize> {
        for _ in 0..tries {
            let wi = wall.or_else(|| self.random_wall(model.size.x + 0.2))?;
            let w = self.walls[wi];
            if w.length < model.size.x + 0.1 {
                continue;
            }
            let s = along
                .unwrap_or_else(|| self.rng.range(0.5 * model.size.x + 0.05, w.length - 0.5 * model.size.x - 0.05));
            if !self.room.wall_free(wi, s - 0.5 * model.size.x, s + 0.5 * model.size.x, 0.05) {
                continue;
            }
            let bottom = self.rng.range(z.0, z.1);
            let c = w.point(s, 0.5 * model.size.y + 0.002);
            let item = Item {
                kind,
                model: model.clone(),
                position: c.extend(bottom),
                yaw: w.facing_yaw(),
                rest: Rest::Wall { wall: wi },
                collides: true,
            };
            let inside = self.inside_room(&item.obb(), 0.0);
            if inside {
                if let Some(i) = self.push_if_fits(item, 0.01) {
                    return Some(i);
                }
            }
        }
        None
    }

    /// Sets a door into a wall.
    fn door(&mut self, wall: Option<usize>) -> Option<usize> {
        let (kind, model) = self.object("door", None);
        let (ow, oh) = model.opening?;
        for _ in 0..20 {
            let wi = wall.or_else(|| self.random_wall(model.size.x + 0.4))?;
            let w = self.walls[wi];
            if w.length < model.size.x + 0.3 {
                continue;
            }
            let s = self.rng.range(0.5 * model.size.x + 0.1, w.length - 0.5 * model.size.x - 0.1);
            if !self.room.wall_free(wi, s - 0.5 * model.size.x, s + 0.5 * model.size.x, 0.1) {
                continue;
            }
            let c = w.point(s, model.wall_plane_t);
            let item = Item {
                kind,
                model: model.clone(),
                position: c.extend(0.0),
                yaw: w.facing_yaw(),
                rest: Rest::Wall { wall: wi },
                collides: true,
            };
            if !self.fits(&item, 0.01) {
                continue;
            }
            let swing = Obb::new(w.point(s, 0.45), Vec2::new(0.5 * ow + 0.05, 0.45), w.facing_yaw());
            if !self.items.iter().all(|it| !it.collides || it.z_range().0 > 2.0 || !it.obb().overlaps(&swing, 0.0)) {
                continue;
            }
            self.zones.push(Zone { obb: swing, z0: 0.0, z1: 2.1 });
            self.room.openings.push(Opening {
                wall: wi,
                s0: s - 0.5 * ow,
                s1: s + 0.5 * ow,
                z0: 0.0,
                z1: oh,
                window: false,
            });
            self.items.push(item);
            return Some(self.items.len() - 1);
        }
        None
    }

    /// Cuts a window into a wall; returns (wall, s, width, sill).
    fn window(&mut self, sill: (f32, f32)) -> Option<(usize, f32, f32, f32)> {
        for _ in 0..20 {
            let width = self.rng.range(0.6, 2.0);
            let wi = self.random_wall(width + 0.6)?;
            let w = self.walls[wi];
            let s = self.rng.range(0.5 * width + 0.3, w.length - 0.5 * width - 0.3);
            if !self.room.wall_free(wi, s - 0.5 * width, s + 0.5 * width, 0.25) {
                continue;
            }
            let z0 = self.rng.range(sill.0, sill.1);
            let z1 = (self.room.height - self.rng.range(0.15, 0.5)).min(2.4).max(z0 + 0.5);
            let zone = Zone {
                obb: Obb::new(w.point(s, 0.04), Vec2::new(0.5 * width + 0.08, 0.04), w.facing_yaw()),
                z0: z0 - 0.06,
                z1,
            };
            let (zz0, zz1) = (zone.z0, zone.z1);
            if self.items.iter().any(|it| {
                let (a, b) = it.z_range();
                a < zz1 && zz0 < b && it.obb().overlaps(&zone.obb, 0.0)
            }) {
                continue;
            }
            self.zones.push(zone);
            self.room.openings.push(Opening {
                wall: wi,
                s0: s - 0.5 * width,
                s1: s + 0.5 * width,
                z0,
                z1,
                window: true,
            });
            return Some((wi, s, width, z0));
        }
        None
    }

    fn maybe(&mut self, p: f32) -> bool {
        self.rng.chance(p)
    }

    // ---- composite helpers ----

    /// Pillows on a bed (flat near the headboard, sometimes one upright against it).
    fn pillows_on(&mut self, bed: usize, upright: bool, n: usize) {
        for k in 0..n {
            let variant = if upright && k == n - 1 { "upright" } else { "flat" };
            let entry = self.object("pillow", Some(variant));
            let spot = if variant == "upright" { Spot::Back } else { Spot::Anywhere };
            let turn = self.rng.range(-0.15, 0.15);
            self.on(bed, entry, Some(0), spot, turn, 8);
        }
    }

    /// Books along shelves and boxes on some shelves.
    fn fill_shelves(&mut self, shelf: usize, box_chance: f32) {
        let n = self.items[shelf].model.supports.len();
        for si in 0..n {
            if self.maybe(box_chance) {
                let entry = self.object("box", None);
                self.on(shelf, entry, Some(si), Spot::Anywhere, 0.0, 4);
            }
            if self.maybe(0.75) {
                for _ in 0..self.rng.int(1, 3) {
                    let entry = self.clutter("books");
                    self.on(shelf, entry, Some(si), Spot::Back, 0.0, 4);
                }
            }
        }
    }

    /// Small desk and table clutter.
    fn table_clutter(&mut self, parent: usize, n: usize) {
        const SMALL: [&str; 6] = ["cup", "bottle", "papers", "book_stack", "vase", "laptop"];
        for _ in 0..n {
            let name = *self.rng.pick(&SMALL);
            let entry = self.clutter(name);
            let turn = self.rng.range(-0.6, 0.6);
            self.on(parent, entry, Some(0), Spot::Anywhere, turn, 4);
        }
    }

    /// A desk workplace: monitor(s), keyboard, lamp, clutter, a chair in front.
    fn workplace(&mut self, desk: usize, chair_variant: Option<&'static str>, monitor_p: f32) {
        if self.maybe(monitor_p) {
            let n = if self.maybe(0.25) { 2 } else { 1 };
            for _ in 0..n {
                let entry = self.object("monitor", None);
                let turn = self.rng.range(-0.25, 0.25);
                self.on(desk, entry, Some(0), Spot::Back, turn, 6);
            }
            if self.maybe(0.6) {
                let entry = self.clutter("keyboard");
                let turn = self.rng.range(-0.1, 0.1);
                self.on(desk, entry, Some(0), Spot::Anywhere, turn, 4);
            }
        }
        if self.maybe(0.25) {
            let entry = self.object("lamp", Some("table"));
            self.on(desk, entry, Some(0), Spot::Back, 0.0, 4);
        }
        let k = self.rng.int(0, 3);
        self.table_clutter(desk, k);
        if self.maybe(0.9) {
            let entry = self.object("chair", chair_variant);
            let offset = self.rng.range(-0.15, 0.15) * self.items[desk].model.size.x;
            self.facing(desk, entry, Side::Front, offset, (0.05, 0.4), 0.4);
        }
    }

    /// Chairs around a table on its four sides.
    fn chairs_around(&mut self, table: usize, p_side: f32, p_end: f32, variant: Option<&'static str>) {
        let size = self.items[table].model.size;
        let per_side = (((size.x - 0.1) / 0.6).floor() as usize).clamp(1, 4);
        for side in [Side::Front, Side::Back] {
            if !self.maybe(p_side) {
                continue;
            }
            for k in 0..per_side {
                if self.maybe(0.15) {
                    continue;
                }
                let offset = (k as f32 + 0.5) / per_side as f32 * size.x - 0.5 * size.x;
                let entry = self.object("chair", variant);
                self.facing(table, entry, side, offset, (0.02, 0.3), 0.35);
            }
        }
        for side in [Side::Left, Side::Right] {
            if self.maybe(p_end) {
                let entry = self.object("chair", variant);
                self.facing(table, entry, side, 0.0, (0.02, 0.3), 0.35);
            }
        }
    }

    /// Floor clutter near the walls: boxes, bins, bags, plants.
    fn floor_things(&mut self, boxes: usize, bin_p: f32, bag_p: f32, plant_p: f32) {
        for _ in 0..boxes {
            let entry = self.object("box", None);
            if self.maybe(0.6) {
                self.in_corner(entry, 6);
            } else {
                self.against_wall(entry, None, None, 6);
            }
        }
        if self.maybe(bin_p) {
            let entry = self.object("garbage_bin", None);
            self.against_wall(entry, None, None, 8);
        }
        if self.maybe(bag_p) {
            let entry = self.clutter("bag");
            self.free(entry, None, 1.0, 8);
        }
        if self.maybe(plant_p) {
            let entry = self.clutter("plant");
            self.in_corner(entry, 6);
        }
    }

    fn pictures(&mut self, n: usize) {
        for _ in 0..n {
            let entry = self.clutter("picture");
            self.on_wall(entry, None, None, (1.2, 1.7), 6);
        }
    }

    /// Doors (`doors` drawn uniformly in the range, each kept with probability `door_p`) and windows.
    fn openings(
        &mut self,
        door_p: f32,
        doors: (usize, usize),
        windows: (usize, usize),
        sill: (f32, f32),
    ) -> Vec<(usize, f32, f32, f32)> {
        let n_doors = self.rng.int(doors.0, doors.1);
        for _ in 0..n_doors {
            if self.rng.chance(door_p) {
                self.door(None);
            }
        }
        let n_windows = self.rng.int(windows.0, windows.1);
        (0..n_windows).filter_map(|_| self.window(sill)).collect()
    }

    /// Curtains beside and radiators under windows.
    fn dress_windows(&mut self, windows: &[(usize, f32, f32, f32)]) {
        for &(wi, s, width, sill) in windows {
            if self.maybe(0.35) {
                for side in [-1.0f32, 1.0] {
                    let entry = self.clutter("curtain");
                    let cw = entry.1.size.x;
                    let along = s + side * (0.5 * width + 0.5 * cw + 0.02);
                    self.against_wall(entry, Some(wi), Some(along), 1);
                }
            }
            if sill > 0.6 && self.maybe(0.3) {
                let entry = self.clutter("radiator");
                if entry.1.size.z < sill - 0.12 && entry.1.size.x < width {
                    self.against_wall(entry, Some(wi), Some(s), 1);
                }
            }
        }
    }

    // ---- recipes ----

    fn bedroom(&mut self) {
        let windows = self.openings(0.85, (1, 1), (0, 2), (0.6, 1.0));
        let bed_entry = self.object("bed", None);
        let bed = self.against_wall(bed_entry, None, None, 30);
        if let Some(bed) = bed {
            for side in [-1.0f32, 1.0] {
                if self.maybe(0.7) {
                    let entry = self.object("nightstand", None);
                    if let Some(ns) = self.beside(bed, entry, side) {
                        if self.maybe(0.6) {
                            let lamp = self.object("lamp", Some("table"));
                            self.on(ns, lamp, Some(0), Spot::Back, 0.0, 6);
                        }
                        if self.maybe(0.3) {
                            let k = self.rng.int(1, 2);
                            self.table_clutter(ns, k);
                        }
                    }
                }
            }
            let n = self.rng.int(1, 4);
            let upright = self.maybe(0.2);
            self.pillows_on(bed, upright, n);
            if self.maybe(0.2) {
                let entry = self.clutter("clothes");
                self.on(bed, entry, None, Spot::Anywhere, 0.3, 4);
            }
            if self.maybe(0.1) {
                let entry = self.object("bed", Some("platform"));
                let (wi, s) = self.wall_of(bed).unwrap_or((0, 0.0));
                let offset = 0.5 * (self.items[bed].model.size.x + entry.1.size.x) + self.rng.range(0.5, 1.0);
                let side = self.rng.sign();
                self.against_wall(entry, Some(wi), Some(s + side * offset), 1);
            }
            if self.maybe(0.3) {
                let entry = self.clutter("picture");
                let (wi, s) = self.wall_of(bed).unwrap_or((0, 0.0));
                let top = self.items[bed].model.size.z + 0.1;
                self.on_wall(entry, Some(wi), Some(s), (top.max(1.1), top.max(1.1) + 0.3), 2);
            }
        }
        if self.maybe(0.6) {
            let entry = self.object("dresser", None);
            if let Some(dr) = self.against_wall(entry, None, None, 20) {
                if self.maybe(0.3) {
                    let tv = self.object("tv", Some("standing"));
                    self.on(dr, tv, Some(0), Spot::Back, 0.0, 6);
                }
                if self.maybe(0.35) {
                    let lamp = self.object("lamp", Some("table"));
                    self.on(dr, lamp, Some(0), Spot::Back, 0.0, 4);
                }
                if self.maybe(0.15) {
                    let b = self.object("box", None);
                    self.on(dr, b, Some(0), Spot::Anywhere, 0.0, 4);
                }
                let k = self.rng.int(0, 2);
                self.table_clutter(dr, k);
            }
        }
        if self.maybe(0.3) {
            let entry = self.object("desk", None);
            if let Some(desk) = self.against_wall(entry, None, None, 15) {
                self.workplace(desk, None, 0.4);
            }
        }
        if self.maybe(0.2) {
            let entry = self.object("bookshelf", None);
            if let Some(b) = self.against_wall(entry, None, None, 15) {
                self.fill_shelves(b, 0.2);
            }
        }
        if self.maybe(0.4) {
            let entry = self.clutter("wardrobe");
            self.in_corner(entry, 10);
        }
        if self.maybe(0.2) {
            let entry = self.object("chair", None);
            self.in_corner(entry, 6);
        }
        if self.maybe(0.1) {
            let entry = self.object("tv", Some("mounted"));
            self.on_wall(entry, None, None, (1.0, 1.4), 6);
        }
        if self.maybe(0.15) {
            let entry = self.object("lamp", Some("floor"));
            self.in_corner(entry, 6);
        }
        if self.maybe(0.3) {
            let entry = self.clutter("rug");
            let c = self.room.centroid();
            self.free(entry, Some((c, 1.0)), 0.0, 6);
        }
        let boxes = self.rng.int(0, 3);
        self.floor_things(boxes, 0.25, 0.3, 0.2);
        self.dress_windows(&windows);
        let k = self.rng.int(0, 2);
        self.pictures(k);
    }

    fn office(&mut self) {
        let windows = self.openings(0.9, (1, 1), (0, 3), (0.7, 1.0));
        let area = self.room.area();
        let n_desks = ((area / 8.0).round() as usize).clamp(1, 5);
        for _ in 0..n_desks {
            let entry = self.object("desk", Some("office"));
            let desk = if self.maybe(0.75) {
                self.against_wall(entry, None, None, 15)
            } else {
                let c = self.room.centroid();
                self.free(entry, Some((c, 1.2)), 0.0, 15)
            };
            if let Some(d) = desk {
                let chair = if self.maybe(0.8) { Some("office") } else { None };
                self.workplace(d, chair, 0.8);
            }
        }
        for _ in 0..self.rng.int(0, 2) {
            let entry = self.object("bookshelf", None);
            if let Some(b) = self.against_wall(entry, None, None, 15) {
                self.fill_shelves(b, 0.3);
            }
        }
        if self.maybe(0.25) {
            let entry = self.object("table", Some("dining"));
            let c = self.room.centroid();
            if let Some(t) = self.free(entry, Some((c, 1.0)), 0.0, 15) {
                self.chairs_around(t, 0.8, 0.3, None);
                let k = self.rng.int(0, 3);
                self.table_clutter(t, k);
            }
        }
        if self.maybe(0.12) {
            let entry = self.object("sofa", None);
            self.against_wall(entry, None, None, 10);
        }
        if self.maybe(0.3) {
            let entry = self.clutter("cabinet");
            if let Some(c) = self.against_wall(entry, None, None, 10) {
                if self.maybe(0.3) {
                    let b = self.object("box", None);
                    self.on(c, b, Some(0), Spot::Anywhere, 0.0, 4);
                }
            }
        }
        if self.maybe(0.3) {
            let entry = self.clutter("whiteboard");
            self.on_wall(entry, None, None, (0.8, 1.0), 6);
        }
        let boxes = self.rng.int(0, 3);
        self.floor_things(boxes, 0.6, 0.3, 0.3);
        self.dress_windows(&windows);
        let k = self.rng.int(0, 2);
        self.pictures(k);
    }

    fn living_room(&mut self) {
        let windows = self.openings(0.8, (1, 1), (1, 3), (0.4, 0.9));
        let sofa_entry = self.object("sofa", Some("sofa"));
        let sofa = self.against_wall(sofa_entry, None, None, 20);
        if let Some(sofa) = sofa {
            let n = self.rng.int(0, 4);
            for _ in 0..n {
                let entry = self.object("pillow", Some("upright"));
                let turn = self.rng.range(-0.2, 0.2);
                self.on(sofa, entry, Some(0), Spot::Back, turn, 6);
            }
            if self.maybe(0.85) {
                let entry = self.object("table", Some("coffee"));
                if let Some(t) = self.facing(sofa, entry, Side::Front, 0.0, (0.3, 0.55), 0.05) {
                    let k = self.rng.int(0, 3);
                    self.table_clutter(t, k);
                    // A coffee table's front faces away from the sofa; turn it back is not needed: tables are
                    // symmetric and their front is whichever long side faces the room.
                    for _ in 0..self.rng.int(0, 2) {
                        let entry = self.object("sofa", Some("armchair"));
                        let side = if self.maybe(0.5) { Side::Left } else { Side::Right };
                        self.facing(t, entry, side, 0.0, (0.2, 0.5), 0.3);
                    }
                }
            }
            for side in [-1.0f32, 1.0] {
                if self.maybe(0.35) {
                    let entry = self.object("table", Some("side"));
                    if let Some(st) = self.beside(sofa, entry, side) {
                        if self.maybe(0.6) {
                            let lamp = self.object("lamp", Some("table"));
                            self.on(st, lamp, Some(0), Spot::Anywhere, 0.0, 6);
                        }
                    }
                }
            }
            // The TV on a cabinet or dresser against the wall the sofa faces.
            let stand_entry = if self.maybe(0.7) { self.clutter("cabinet") } else { self.object("dresser", None) };
            let opposite = self.opposite_wall(sofa);
            if let Some(stand) = self.against_wall(stand_entry, opposite, None, 10) {
                if self.maybe(0.75) {
                    let tv = self.object("tv", Some("standing"));
                    self.on(stand, tv, Some(0), Spot::Back, 0.0, 6);
                }
                if self.maybe(0.2) {
                    let b = self.object("box", None);
                    self.on(stand, b, Some(0), Spot::Anywhere, 0.0, 4);
                }
            } else if self.maybe(0.5) {
                let tv = self.object("tv", Some("mounted"));
                self.on_wall(tv, opposite, None, (0.9, 1.3), 6);
            }
        }
        if self.maybe(0.4) {
            let entry = self.object("bookshelf", None);
            if let Some(b) = self.against_wall(entry, None, None, 15) {
                self.fill_shelves(b, 0.25);
            }
        }
        if self.maybe(0.3) {
            let entry = self.object("lamp", Some("floor"));
            self.in_corner(entry, 8);
        }
        if self.maybe(0.2) {
            let entry = self.object("chair", Some("dining"));
            self.free(entry, None, 0.5, 10);
        }
        if self.maybe(0.1) {
            let entry = self.object("desk", None);
            if let Some(d) = self.against_wall(entry, None, None, 10) {
                self.workplace(d, None, 0.5);
            }
        }
        if self.maybe(0.45) {
            let entry = self.clutter("rug");
            let c = self.room.centroid();
            self.free(entry, Some((c, 0.8)), 0.0, 6);
        }
        let boxes = self.rng.int(0, 2);
        self.floor_things(boxes, 0.1, 0.2, 0.45);
        self.dress_windows(&windows);
        let k = self.rng.int(0, 3);
        self.pictures(k);
    }

    /// The wall facing the one an item stands against (for rectangles: the opposite one).
    fn opposite_wall(&self, item: usize) -> Option<usize> {
        let (wi, _) = self.wall_of(item)?;
        let n = self.walls[wi].normal;
        self.walls
            .iter()
            .enumerate()
            .filter(|(_, w)| w.normal.dot(n) < -0.99)
            .max_by(|a, b| a.1.length.total_cmp(&b.1.length))
            .map(|(i, _)| i)
    }

    fn bathroom(&mut self) {
        let _windows = self.openings(0.9, (1, 1), (0, 1), (1.1, 1.5));
        if self.maybe(0.6) {
            let entry = self.object("bathtub", None);
            self.in_corner(entry, 15);
        }
        if self.maybe(0.95) {
            let entry = self.object("toilet", None);
            self.against_wall(entry, None, None, 20);
        }
        let sink = if self.maybe(0.5) {
            let entry = self.object("counter", Some("vanity"));
            let vanity = self.against_wall(entry, None, None, 15);
            vanity.and_then(|v| {
                let s = self.object("sink", Some("basin"));
                let sink = self.on(v, s, Some(0), Spot::Back, 0.0, 6);
                for _ in 0..self.rng.int(0, 2) {
                    let c = self.clutter("bottle");
                    self.on(v, c, Some(0), Spot::Anywhere, 0.0, 4);
                }
                sink.map(|_| v)
            })
        } else {
            let entry = self.object("sink", Some("pedestal"));
            self.against_wall(entry, None, None, 15)
        };
        if let Some(s) = sink {
            if self.maybe(0.7) {
                if let Some((wi, along)) = self.wall_of(s) {
                    let entry = self.clutter("mirror");
                    self.on_wall(entry, Some(wi), Some(along), (1.1, 1.3), 2);
                }
            }
        }
        if self.maybe(0.5) {
            let entry = self.object("garbage_bin", None);
            self.against_wall(entry, None, None, 10);
        }
        if self.maybe(0.1) {
            let entry = self.object("box", None);
            self.in_corner(entry, 6);
        }
    }

    fn dining_room(&mut self) {
        let windows = self.openings(0.8, (1, 1), (1, 2), (0.5, 0.9));
        let entry = self.object("table", Some("dining"));
        let c = self.room.centroid();
        if let Some(t) = self.free(entry, Some((c, 0.6)), 0.0, 25) {
            self.chairs_around(t, 0.9, 0.5, Some("dining"));
            let k = self.rng.int(0, 5);
            self.table_clutter(t, k);
            if self.maybe(0.15) {
                let lamp = self.object("lamp", Some("table"));
                self.on(t, lamp, Some(0), Spot::Anywhere, 0.0, 4);
            }
        }
        if self.maybe(0.4) {
            let entry = self.object("dresser", None);
            if let Some(d) = self.against_wall(entry, None, None, 15) {
                if self.maybe(0.4) {
                    let lamp = self.object("lamp", Some("table"));
                    self.on(d, lamp, Some(0), Spot::Back, 0.0, 4);
                }
                let k = self.rng.int(0, 2);
                self.table_clutter(d, k);
            }
        }
        if self.maybe(0.2) {
            let entry = self.object("counter", Some("kitchen"));
            self.against_wall(entry, None, None, 10);
        }
        if self.maybe(0.2) {
            let entry = self.object("bookshelf", None);
            if let Some(b) = self.against_wall(entry, None, None, 10) {
                self.fill_shelves(b, 0.2);
            }
        }
        if self.maybe(0.4) {
            let entry = self.clutter("cabinet");
            self.against_wall(entry, None, None, 10);
        }
        if self.maybe(0.1) {
            let entry = self.object("lamp", Some("floor"));
            self.in_corner(entry, 6);
        }
        self.floor_things(0, 0.15, 0.1, 0.4);
        self.dress_windows(&windows);
        let k = self.rng.int(0, 3);
        self.pictures(k);
    }

    fn classroom(&mut self) {
        let windows = self.openings(1.0, (1, 2), (2, 4), (0.8, 1.0));
        // The front wall: the longest one with the whiteboard.
        let front =
            (0..self.walls.len()).max_by(|&a, &b| self.walls[a].length.total_cmp(&self.walls[b].length)).unwrap_or(0);
        let board = self.clutter("whiteboard");
        let along = 0.5 * self.walls[front].length;
        self.on_wall(board, Some(front), Some(along), (0.8, 1.0), 1);
        let wall = self.walls[front];
        let yaw = wall.facing_yaw();
        let teacher = self.object("desk", Some("office"));
        let teacher_pos = wall.point(along + self.rng.range(-1.0, 1.0), 1.2);
        let t_item = Item {
            kind: teacher.0,
            model: teacher.1,
            position: teacher_pos.extend(0.0),
            yaw: yaw + std::f32::consts::PI,
            rest: Rest::Floor,
            collides: true,
        };
        if let Some(t) = self.push_if_fits(t_item, FLOOR_GAP) {
            self.workplace(t, Some("office"), 0.5);
        }
        let rows = self.rng.int(2, 5);
        let cols = self.rng.int(2, 5);
        let depth_step = self.rng.range(1.1, 1.5);
        let width_step = self.rng.range(0.8, 1.3);
        let student = self.object("desk", Some("student"));
        for r in 0..rows {
            for c in 0..cols {
                let s = along + (c as f32 - 0.5 * (cols - 1) as f32) * width_step;
                let p = wall.point(s, 2.4 + r as f32 * depth_step);
                let mut model = student.1.clone();
                if self.maybe(0.3) {
                    // A different desk model now and then.
                    model = self.object("desk", Some("student")).1;
                }
                let item = Item {
                    kind: student.0,
                    model,
                    position: p.extend(0.0),
                    yaw: yaw + self.rng.range(-0.05, 0.05),
                    rest: Rest::Floor,
                    collides: true,
                };
                if let Some(d) = self.push_if_fits(item, FLOOR_GAP) {
                    if self.maybe(0.9) {
                        let variant = if self.rng.chance(0.8) { "dining" } else { "stool" };
                        let chair = self.object("chair", Some(variant));
                        self.facing(d, chair, Side::Front, 0.0, (0.03, 0.25), 0.3);
                    }
                    if self.maybe(0.3) {
                        let k = self.rng.int(1, 2);
                        self.table_clutter(d, k);
                    }
                }
            }
        }
        if self.maybe(0.4) {
            let entry = self.object("bookshelf", None);
            if let Some(b) = self.against_wall(entry, None, None, 10) {
                self.fill_shelves(b, 0.3);
            }
        }
        if self.maybe(0.3) {
            let entry = self.object("table", None);
            self.against_wall(entry, None, None, 10);
        }
        if self.maybe(0.3) {
            let entry = self.clutter("cabinet");
            self.against_wall(entry, None, None, 10);
        }
        let boxes = self.rng.int(0, 2);
        self.floor_things(boxes, 0.6, 0.3, 0.2);
        self.dress_windows(&windows);
    }

    fn kitchen(&mut self) {
        let windows = self.openings(0.8, (1, 1), (0, 2), (0.95, 1.2));
        let n_counters = self.rng.int(1, 3);
        let mut counters = Vec::new();
        for _ in 0..n_counters {
            let entry = self.object("counter", Some("kitchen"));
            if let Some(c) = self.against_wall(entry, None, None, 15) {
                counters.push(c);
            }
        }
        if let Some(&first) = counters.first() {
            if self.maybe(0.8) {
                let s = self.object("sink", Some("basin"));
                self.on(first, s, Some(0), Spot::Back, 0.0, 6);
            }
        }
        for &c in &counters {
            for _ in 0..self.rng.int(0, 3) {
                let name = *self.rng.pick(&["bottle", "cup", "vase", "book_stack"]);
                let entry = self.clutter(name);
                let turn = self.rng.range(-0.5, 0.5);
                self.on(c, entry, Some(0), Spot::Anywhere, turn, 4);
            }
            if self.maybe(0.15) {
                let b = self.object("box", None);
                self.on(c, b, Some(0), Spot::Back, 0.0, 4);
            }
            if self.maybe(0.5) {
                if let Some((wi, s)) = self.wall_of(c) {
                    let entry = self.clutter("upper_cabinet");
                    self.on_wall(entry, Some(wi), Some(s), (1.4, 1.55), 2);
                }
            }
        }
        if self.maybe(0.7) {
            let entry = self.clutter("fridge");
            self.in_corner(entry, 10);
        }
        if self.maybe(0.5) {
            let variant = if self.maybe(0.6) { "dining" } else { "side" };
            let entry = self.object("table", Some(variant));
            let c = self.room.centroid();
            if let Some(t) = self.free(entry, Some((c, 0.8)), 0.0, 15) {
                self.chairs_around(t, 0.6, 0.3, None);
                let k = self.rng.int(0, 3);
                self.table_clutter(t, k);
            }
        }
        if self.maybe(0.05) {
            let entry = self.object("lamp", Some("floor"));
            self.in_corner(entry, 4);
        }
        let boxes = usize::from(self.rng.chance(0.3));
        self.floor_things(boxes, 0.7, 0.1, 0.2);
        self.dress_windows(&windows);
    }
}

/// Furnishes a room of the given type.
pub fn furnish(room: Room, rng: &mut Rng) -> Scene {
    let kind = room.kind;
    let mut planner = Planner::new(room, rng);
    match kind {
        RoomType::Bedroom => planner.bedroom(),
        RoomType::Office => planner.office(),
        RoomType::LivingRoom => planner.living_room(),
        RoomType::Bathroom => planner.bathroom(),
        RoomType::DiningRoom => planner.dining_room(),
        RoomType::Classroom => planner.classroom(),
        RoomType::Kitchen => planner.kitchen(),
    }
    Scene { room: planner.room, items: planner.items }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obb_overlap_matches_hand_cases() {
        let a = Obb::new(Vec2::ZERO, Vec2::new(1.0, 0.5), 0.0);
        assert!(a.overlaps(&Obb::new(Vec2::new(1.9, 0.0), Vec2::new(1.0, 0.5), 0.0), 0.0));
        assert!(!a.overlaps(&Obb::new(Vec2::new(2.1, 0.0), Vec2::new(1.0, 0.5), 0.0), 0.0));
        assert!(a.overlaps(&Obb::new(Vec2::new(2.1, 0.0), Vec2::new(1.0, 0.5), 0.0), 0.2));
        // A square turned by 45° whose corner reaches x = 1 + 0.5·√2 ≈ 1.707 from a centre at 2.2: no touch
        // with a's right edge at x = 1 (the corner is at 2.2 − 0.707 = 1.49).
        let d = Obb::new(Vec2::new(2.2, 0.0), Vec2::splat(0.5), std::f32::consts::FRAC_PI_4);
        assert!(!a.overlaps(&d, 0.0));
        let e = Obb::new(Vec2::new(1.6, 0.0), Vec2::splat(0.5), std::f32::consts::FRAC_PI_4);
        assert!(a.overlaps(&e, 0.0));
    }
}
