//! Furniture and clutter built from parts, with per-instance style variation and support surfaces.
//!
//! A [`Model`] lives in its own frame: s along the width, t along the depth, u up from the bottom; the
//! model's bounding box is centred on s = t = 0 and starts at u = 0, and its **front is at −t** — the side
//! that becomes the annotated cuboid's front (`-depth_axis`, see `geometry`). What "front" means per
//! category:
//!
//! | category    | front (−t) is the side ...                                   | width is ...                  |
//! |-------------|--------------------------------------------------------------|-------------------------------|
//! | bed         | of the foot end (headboard at +t)                            | across the bed                |
//! | chair       | the seat opens to (backrest at +t)                           | across the seat               |
//! | sofa        | the seats open to (back at +t)                               | along the seat                |
//! | table       | one long side (the one facing the room when placed)          | the longer edge               |
//! | desk        | of the knee space, where the user sits                       | along the top's front edge    |
//! | toilet      | of the bowl (tank at +t)                                     | across (tank width)           |
//! | bathtub     | of the open long side / apron (wall side at +t)              | along the tub                 |
//! | dresser     | of the drawer fronts                                         | along the drawer fronts       |
//! | nightstand  | of the drawer fronts / niche opening                         | along the drawer fronts       |
//! | bookshelf   | of the open shelves                                          | along the shelves             |
//! | box         | carrying the label (cardboard) or the lid's long side        | along that side               |
//! | door        | facing into the room, with the handle                        | along the wall                |
//! | counter     | of the cabinet doors, where the cook stands                  | along the worktop             |
//! | garbage bin | of the pedal or logo; round bins: the side facing the room   | along that side               |
//! | sink        | the user stands at (faucet at +t)                            | across the basin              |
//! | pillow      | facing the foot of the bed / the front of the sofa           | the longer horizontal edge    |
//! | monitor     | of the screen                                                | along the screen              |
//! | tv          | of the screen                                                | along the screen              |
//! | lamp        | facing the room (rotationally symmetric: set by placement)   | shade diameter                |
//!
//! Builders place every part inside the drawn size and make parts touch all six faces, so the model's
//! bounds — the annotated cuboid — equal the drawn size (a unit test checks this).

use glam::{Vec2, Vec3};

use super::material::{self as mat, Material};
use super::rng::Rng;
use super::shape::{Part, Shape};
use super::sizes::{self, SizeSpec};

/// A horizontal support surface of a model: a rectangle in the model frame at height `z` with `clearance`
/// metres of free space above it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Support {
    /// (s0, s1, t0, t1) in the model frame.
    pub rect: [f32; 4],
    pub z: f32,
    pub clearance: f32,
}

/// A light a model emits (a lit lamp): position in the model frame and intensity (linear RGB).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelLight {
    pub position: Vec3,
    pub intensity: Vec3,
}

/// A built model.
#[derive(Clone, Debug)]
pub struct Model {
    pub parts: Vec<Part>,
    pub materials: Vec<Material>,
    /// (width, depth, height) of the parts' bounds.
    pub size: Vec3,
    /// Support surfaces, the main one (top, mattress, seat) first.
    pub supports: Vec<Support>,
    pub variant: &'static str,
    /// Doors: t of the wall plane in the model frame and the wall opening (width, height).
    pub wall_plane_t: f32,
    pub opening: Option<(f32, f32)>,
    pub light: Option<ModelLight>,
}

#[derive(Default)]
struct Builder {
    parts: Vec<Part>,
    materials: Vec<Material>,
    supports: Vec<Support>,
    wall_plane_t: f32,
    opening: Option<(f32, f32)>,
    light: Option<ModelLight>,
}

impl Builder {
    fn mat(&mut self, m: Material) -> u16 {
        self.materials.push(m);
        (self.materials.len() - 1) as u16
    }

    fn part(&mut self, shape: Shape, material: u16, centre: Vec3, half: Vec3, yaw: f32, tilt: f32) {
        self.parts.push(Part { shape, centre, half, yaw, tilt, material });
    }

    /// An axis-aligned box between two corners.
    fn cube(&mut self, material: u16, lo: Vec3, hi: Vec3) {
        let (lo, hi) = (lo.min(hi), lo.max(hi));
        self.part(Shape::Box, material, 0.5 * (lo + hi), 0.5 * (hi - lo), 0.0, 0.0);
    }

    /// An upright elliptic frustum standing on `base` (centre of its bottom face).
    fn cylinder(&mut self, material: u16, base: Vec3, radii: Vec2, height: f32, bottom: f32, top: f32) {
        let half = Vec3::new(radii.x, radii.y, 0.5 * height);
        self.part(Shape::Frustum { bottom, top }, material, base + Vec3::Z * (0.5 * height), half, 0.0, 0.0);
    }

    fn ellipsoid(&mut self, material: u16, centre: Vec3, half: Vec3) {
        self.part(Shape::Ellipsoid, material, centre, half, 0.0, 0.0);
    }

    fn support(&mut self, rect: [f32; 4], z: f32, clearance: f32) {
        if rect[1] - rect[0] > 0.05 && rect[3] - rect[2] > 0.05 {
            self.supports.push(Support { rect, z, clearance });
        }
    }

    /// Recentres the parts on their bounds and returns the model.
    fn finish(mut self, variant: &'static str) -> Model {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for p in &self.parts {
            let (a, b) = p.bounds();
            lo = lo.min(a);
            hi = hi.max(b);
        }
        let shift = Vec3::new(-0.5 * (lo.x + hi.x), -0.5 * (lo.y + hi.y), -lo.z);
        for p in &mut self.parts {
            p.centre += shift;
        }
        for s in &mut self.supports {
            s.rect = [s.rect[0] + shift.x, s.rect[1] + shift.x, s.rect[2] + shift.y, s.rect[3] + shift.y];
            s.z += shift.z;
        }
        if let Some(l) = &mut self.light {
            l.position += shift;
        }
        Model {
            parts: self.parts,
            materials: self.materials,
            size: hi - lo,
            supports: self.supports,
            variant,
            wall_plane_t: self.wall_plane_t + shift.y,
            opening: self.opening,
            light: self.light,
        }
    }
}

fn v(s: f32, t: f32, u: f32) -> Vec3 {
    Vec3::new(s, t, u)
}

/// Draws a size for a variant.
fn size_of(rng: &mut Rng, spec: &SizeSpec) -> Vec3 {
    sizes::draw(rng, spec)
}

/// A light fabric (sheets, pillowcases).
fn bedding(rng: &mut Rng) -> Material {
    let mut m = mat::fabric(rng);
    if rng.chance(0.6) {
        m.colour = Vec3::splat(rng.range(0.55, 0.85)) * Vec3::new(1.0, rng.range(0.95, 1.0), rng.range(0.88, 1.0));
        m.pattern = mat::Pattern::Speckle { amount: 0.04 };
    }
    m
}

/// Builds a labelled object of `category` (`variant` chosen by the caller, or drawn when `None`).
pub fn build(category: &str, variant: Option<&'static str>, rng: &mut Rng) -> Model {
    let pick = |rng: &mut Rng, options: &[(&'static str, f32)]| -> &'static str {
        let w: Vec<f32> = options.iter().map(|o| o.1).collect();
        options[rng.weighted(&w)].0
    };
    match category {
        "bed" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("headboard", 0.8), ("platform", 0.2)]));
            bed(rng, v)
        }
        "chair" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("dining", 0.55), ("office", 0.35), ("stool", 0.1)]));
            match v {
                "office" => office_chair(rng),
                "stool" => stool(rng),
                _ => dining_chair(rng),
            }
        }
        "sofa" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("sofa", 0.7), ("armchair", 0.3)]));
            sofa(rng, v)
        }
        "table" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("dining", 0.5), ("coffee", 0.3), ("side", 0.2)]));
            table(rng, v)
        }
        "desk" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("office", 0.8), ("student", 0.2)]));
            desk(rng, v)
        }
        "toilet" => toilet(rng),
        "bathtub" => bathtub(rng),
        "dresser" => chest(rng, "dresser"),
        "nightstand" => chest(rng, "nightstand"),
        "bookshelf" => bookshelf(rng),
        "box" => cardboard_box(rng),
        "door" => door(rng),
        "counter" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("kitchen", 0.7), ("vanity", 0.3)]));
            counter(rng, v)
        }
        "garbage_bin" => garbage_bin(rng),
        "sink" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("pedestal", 0.5), ("basin", 0.5)]));
            sink(rng, v)
        }
        "pillow" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("flat", 0.6), ("upright", 0.4)]));
            pillow(rng, v)
        }
        "monitor" => monitor(rng),
        "tv" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("standing", 0.8), ("mounted", 0.2)]));
            tv(rng, v == "mounted")
        }
        "lamp" => {
            let v = variant.unwrap_or_else(|| pick(rng, &[("table", 0.7), ("floor", 0.3)]));
            lamp(rng, v)
        }
        other => clutter(other, rng),
    }
}

// ---------------------------------------------------------------------------------------------------------
// Beds

fn bed(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("bed", variant);
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let headboard = variant == "headboard";
    let mut b = Builder::default();
    let frame = b.mat(match rng.weighted(&[0.5, 0.3, 0.2]) {
        0 => mat::wood(rng),
        1 => mat::any_soft(rng),
        _ => mat::metal(rng),
    });
    let mattress = b.mat(bedding(rng));
    let duvet = b.mat(mat::fabric(rng));
    let sheet = b.mat(bedding(rng));
    let hb_t = if headboard { rng.range(0.04, 0.1) } else { 0.0 };
    let duvet_thick = rng.range(0.03, 0.07);
    let mattress_top = if headboard { rng.range(0.4, 0.62).min(h - 0.2) } else { h - duvet_thick };
    let leg_h = if rng.chance(0.4) { rng.range(0.05, 0.14).min(mattress_top - 0.25) } else { 0.0 };
    let mattress_thick = rng.range(0.15, 0.28).min(mattress_top - leg_h - 0.08);
    let frame_top = mattress_top - mattress_thick;
    let foot_t = if headboard && rng.chance(0.3) { rng.range(0.03, 0.06) } else { 0.0 };
    let (t_front, t_back) = (-0.5 * d, 0.5 * d);
    let (t_bed0, t_bed1) = (t_front + foot_t, t_back - hb_t);
    let hw = 0.5 * w;
    if leg_h > 0.0 {
        let leg = rng.range(0.04, 0.08);
        for (s, t) in [(-hw, t_bed0), (hw - leg, t_bed0), (-hw, t_bed1 - leg), (hw - leg, t_bed1 - leg)] {
            b.cube(frame, v(s, t, 0.0), v(s + leg, t + leg, leg_h));
        }
    }
    b.cube(frame, v(-hw, t_bed0, leg_h), v(hw, t_bed1, frame_top));
    let inset = rng.range(0.0, 0.04);
    b.cube(mattress, v(-hw + inset, t_bed0 + inset, frame_top), v(hw - inset, t_bed1 - 0.01, mattress_top));
    let cover_to = t_bed0 + (t_bed1 - t_bed0) * rng.range(0.6, 0.76);
    let drape = rng.range(0.08, 0.25).min(mattress_thick + 0.05);
    b.cube(
        duvet,
        v(-hw + 0.002, t_bed0 + 0.002, mattress_top - drape),
        v(hw - 0.002, cover_to, mattress_top + duvet_thick),
    );
    if headboard && rng.chance(0.5) {
        // The sheet folded back over the duvet's top edge.
        let fold = rng.range(0.1, 0.25);
        b.cube(
            sheet,
            v(-hw + 0.004, cover_to - fold, mattress_top),
            v(hw - 0.004, cover_to + 0.01, mattress_top + duvet_thick + 0.015),
        );
    }
    if headboard {
        let t0 = t_back - hb_t;
        match rng.int(0, 2) {
            0 => b.cube(frame, v(-hw, t0, leg_h.min(frame_top - 0.05)), v(hw, t_back, h)),
            1 => {
                // Posts with an inset upholstered or contrasting panel.
                let post = rng.range(0.05, 0.09);
                b.cube(frame, v(-hw, t0, 0.0), v(-hw + post, t_back, h));
                b.cube(frame, v(hw - post, t0, 0.0), v(hw, t_back, h));
                let panel = b.mat(mat::any_soft(rng));
                b.cube(panel, v(-hw + post, t0 + 0.01, frame_top), v(hw - post, t_back, h - rng.range(0.0, 0.08)));
            }
            _ => {
                // Slats between posts under a top rail.
                let post = rng.range(0.04, 0.08);
                let rail = rng.range(0.04, 0.08);
                b.cube(frame, v(-hw, t0, 0.0), v(-hw + post, t_back, h));
                b.cube(frame, v(hw - post, t0, 0.0), v(hw, t_back, h));
                b.cube(frame, v(-hw + post, t0, h - rail), v(hw - post, t_back, h));
                let n = rng.int(4, 12);
                let span = w - 2.0 * post;
                let slat = (span / n as f32) * rng.range(0.3, 0.6);
                for i in 0..n {
                    let c = -hw + post + span * (i as f32 + 0.5) / n as f32;
                    b.cube(frame, v(c - 0.5 * slat, t0 + 0.01, frame_top), v(c + 0.5 * slat, t_back - 0.01, h - rail));
                }
            }
        }
    }
    if foot_t > 0.0 {
        let top = (mattress_top + rng.range(-0.1, 0.15)).min(h);
        b.cube(frame, v(-hw, t_front, 0.0), v(hw, t_front + foot_t, top));
    }
    // Pillows lie on the mattress between the duvet's edge and the headboard.
    let pillow_from = cover_to + 0.02 + if headboard { 0.02 } else { 0.0 };
    b.support([-hw + inset + 0.02, hw - inset - 0.02, pillow_from, t_bed1 - 0.02], mattress_top, 1.0);
    b.finish(variant)
}

// ---------------------------------------------------------------------------------------------------------
// Seating

fn dining_chair(rng: &mut Rng) -> Model {
    let spec = sizes::spec("chair", "dining");
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let frame = b.mat(match rng.weighted(&[0.55, 0.25, 0.2]) {
        0 => mat::wood(rng),
        1 => mat::metal(rng),
        _ => mat::plastic(rng),
    });
    let seat_mat = if rng.chance(0.5) { frame } else { b.mat(mat::any_soft(rng)) };
    let seat_top = rng.range(0.42, 0.5).min(h - 0.28);
    let seat_th = rng.range(0.03, 0.08);
    let leg = rng.range(0.028, 0.05);
    let round = rng.chance(0.35);
    let inset = rng.range(0.0, 0.03);
    let post_t = leg.max(rng.range(0.025, 0.05));
    let legs = [
        (-hw + inset, -hd + inset, seat_top - seat_th),
        (hw - inset - leg, -hd + inset, seat_top - seat_th),
        (-hw + inset, hd - post_t, h),
        (hw - inset - leg, hd - post_t, h),
    ];
    for (i, (s, t, top)) in legs.into_iter().enumerate() {
        let depth = if i < 2 { leg } else { post_t };
        if round {
            b.cylinder(frame, v(s + 0.5 * leg, t + 0.5 * depth, 0.0), Vec2::new(0.5 * leg, 0.5 * depth), top, 1.0, 1.0);
        } else {
            b.cube(frame, v(s, t, 0.0), v(s + leg, t + depth, top));
        }
    }
    if rng.chance(0.4) {
        let z = rng.range(0.1, 0.22);
        let bar = 0.5 * leg;
        b.cube(frame, v(-hw + inset, -hd + inset + 0.25 * leg, z), v(-hw + inset + bar, hd - post_t, z + bar));
        b.cube(frame, v(hw - inset - bar, -hd + inset + 0.25 * leg, z), v(hw - inset, hd - post_t, z + bar));
    }
    b.cube(seat_mat, v(-hw, -hd, seat_top - seat_th), v(hw, hd - 0.5 * post_t, seat_top));
    let back_lo = seat_top + rng.range(0.04, 0.2);
    let (s0, s1) = (-hw + inset + leg, hw - inset - leg);
    let tb = hd - post_t;
    match rng.int(0, 2) {
        0 => b.cube(seat_mat, v(s0, tb + 0.003, back_lo), v(s1, hd - 0.003, h - rng.range(0.0, 0.06))),
        1 => {
            let n = rng.int(3, 6);
            let slat = (s1 - s0) / n as f32 * rng.range(0.3, 0.6);
            for i in 0..n {
                let c = s0 + (s1 - s0) * (i as f32 + 0.5) / n as f32;
                b.cube(frame, v(c - 0.5 * slat, tb + 0.005, back_lo), v(c + 0.5 * slat, hd - 0.005, h - 0.04));
            }
            b.cube(frame, v(s0, tb, h - 0.05), v(s1, hd, h - 0.005));
        }
        _ => {
            let n = rng.int(2, 4);
            let rail = rng.range(0.03, 0.07);
            for i in 0..n {
                let z = back_lo + (h - 0.01 - rail - back_lo) * i as f32 / (n - 1).max(1) as f32;
                b.cube(frame, v(s0, tb + 0.004, z), v(s1, hd - 0.004, z + rail));
            }
        }
    }
    b.finish("dining")
}

fn office_chair(rng: &mut Rng) -> Model {
    let spec = sizes::spec("chair", "office");
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let base_mat = b.mat(if rng.chance(0.6) { mat::plastic(rng) } else { mat::metal(rng) });
    let cushion = b.mat(mat::any_soft(rng));
    let back_mat = if rng.chance(0.7) { cushion } else { b.mat(mat::fabric(rng)) };
    let caster = 0.025;
    let radius = hw.min(hd) * rng.range(0.85, 0.98);
    let phase = rng.range(0.0, std::f32::consts::TAU);
    for k in 0..5 {
        let a = phase + k as f32 * std::f32::consts::TAU / 5.0;
        let dir = Vec2::new(a.cos(), a.sin());
        let reach = radius - caster;
        let c = dir * (0.5 * reach);
        b.part(Shape::Box, base_mat, v(c.x, c.y, 0.065), v(0.5 * reach, 0.022, 0.014), a, 0.0);
        let e = dir * reach;
        b.ellipsoid(base_mat, v(e.x, e.y, caster), Vec3::splat(caster));
    }
    let seat_top = rng.range(0.44, 0.54).min(h - 0.3);
    let seat_th = rng.range(0.06, 0.1);
    b.cylinder(base_mat, v(0.0, 0.0, 0.05), Vec2::splat(rng.range(0.022, 0.035)), seat_top - seat_th - 0.05, 1.0, 1.0);
    let arms = rng.chance(0.6);
    let arm_w = if arms { rng.range(0.04, 0.07) } else { 0.0 };
    let seat_hw = if arms { hw - arm_w - 0.01 } else { hw };
    let back_th = rng.range(0.05, 0.09);
    b.cube(cushion, v(-seat_hw, -hd, seat_top - seat_th), v(seat_hw, hd - back_th - 0.03, seat_top));
    let back_lo = seat_top + rng.range(0.05, 0.14);
    let back_hw = seat_hw * rng.range(0.8, 1.0);
    b.cube(back_mat, v(-back_hw, hd - back_th, back_lo), v(back_hw, hd, h));
    b.cube(base_mat, v(-0.03, hd - back_th - 0.03, seat_top - seat_th), v(0.03, hd - back_th * 0.5, back_lo + 0.06));
    if arms {
        let pad_z = seat_top + rng.range(0.17, 0.24);
        for side in [-1.0f32, 1.0] {
            let (s0, s1) = if side < 0.0 { (-hw, -hw + arm_w) } else { (hw - arm_w, hw) };
            let sc = 0.5 * (s0 + s1);
            b.cube(base_mat, v(sc - 0.012, -0.05, seat_top - seat_th), v(sc + 0.012, 0.05, pad_z));
            b.cube(base_mat, v(s0, -0.2 * d, pad_z), v(s1, 0.22 * d, pad_z + 0.03));
        }
    }
    b.finish("office")
}

fn stool(rng: &mut Rng) -> Model {
    let spec = sizes::spec("chair", "stool");
    let size = size_of(rng, &spec);
    let (w, h) = (size.x, size.z);
    let hw = 0.5 * w;
    let mut b = Builder::default();
    let frame = b.mat(if rng.chance(0.5) { mat::wood(rng) } else { mat::metal(rng) });
    let seat = if rng.chance(0.5) { frame } else { b.mat(mat::any_soft(rng)) };
    let seat_th = rng.range(0.03, 0.06);
    let round = rng.chance(0.5);
    if round {
        b.cylinder(seat, v(0.0, 0.0, h - seat_th), Vec2::splat(hw), seat_th, 1.0, 1.0);
    } else {
        b.cube(seat, v(-hw, -hw, h - seat_th), v(hw, hw, h));
    }
    let n = if rng.chance(0.3) { 3 } else { 4 };
    let leg_r = rng.range(0.012, 0.022);
    let r = (hw - leg_r) * if round { 0.72 } else { 0.85 };
    let mut feet = Vec::new();
    for k in 0..n {
        let a = std::f32::consts::FRAC_PI_4 + k as f32 * std::f32::consts::TAU / n as f32;
        let p = Vec2::new(a.cos(), a.sin()) * r;
        b.cylinder(frame, v(p.x, p.y, 0.0), Vec2::splat(leg_r), h - seat_th, 1.0, 1.0);
        feet.push(p);
    }
    if n == 4 && rng.chance(0.6) {
        let z = rng.range(0.18, 0.3).min(h * 0.5);
        for k in 0..4 {
            let (p, q) = (feet[k], feet[(k + 1) % 4]);
            let c = 0.5 * (p + q);
            let len = (q - p).length();
            let yaw = (q - p).y.atan2((q - p).x);
            b.part(Shape::Box, frame, v(c.x, c.y, z), v(0.5 * len, 0.008, 0.008), yaw, 0.0);
        }
    }
    // A square seat reaches ±w/2 both ways; a round one too (it is a circle of diameter w).
    b.finish("stool")
}

fn sofa(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("sofa", variant);
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let armchair = variant == "armchair";
    let mut b = Builder::default();
    let cover = b.mat(mat::any_soft(rng));
    let cushion_mat = if rng.chance(0.75) { cover } else { b.mat(mat::any_soft(rng)) };
    let leg_mat = b.mat(if rng.chance(0.6) { mat::wood(rng) } else { mat::metal(rng) });
    let arms = armchair || rng.chance(0.8);
    let arm_w = if arms { rng.range(0.08, 0.2).min(0.15 * w) } else { 0.0 };
    let leg_h = if rng.chance(0.6) { rng.range(0.04, 0.14) } else { 0.0 };
    let seat_base = rng.range(0.25, 0.33).max(leg_h + 0.1);
    let seat_top = (seat_base + rng.range(0.1, 0.16)).min(h - 0.2);
    let max_back = (d - 0.5).max(0.12);
    let back_th = rng.range(0.1, 0.2).min(max_back * 0.6);
    let back_cushions = rng.chance(0.6);
    let bc_th = if back_cushions { rng.range(0.08, 0.16).min(max_back - back_th) } else { 0.0 };
    let arm_h = (seat_top + rng.range(0.12, 0.25)).min(h - 0.02);
    let (s0, s1) = (-hw + arm_w, hw - arm_w);
    // Back frame spans the full width behind the arms.
    b.cube(cover, v(-hw, hd - back_th, leg_h), v(hw, hd, h));
    b.cube(cover, v(s0, -hd + 0.02, leg_h), v(s1, hd - back_th, seat_base));
    let n = if armchair {
        1
    } else if w < 1.5 {
        2
    } else {
        3
    };
    let gap = 0.008;
    let seat_t1 = hd - back_th - bc_th;
    for i in 0..n {
        let a = s0 + (s1 - s0) * i as f32 / n as f32;
        let c = s0 + (s1 - s0) * (i + 1) as f32 / n as f32;
        b.cube(cushion_mat, v(a + gap, -hd, seat_base), v(c - gap, seat_t1, seat_top));
        if back_cushions {
            b.cube(cushion_mat, v(a + gap, seat_t1, seat_top), v(c - gap, hd - back_th, h - rng.range(0.03, 0.1)));
        }
    }
    if arms {
        let front = -hd + rng.range(0.0, 0.05);
        b.cube(cover, v(-hw, front, leg_h), v(-hw + arm_w, hd, arm_h));
        b.cube(cover, v(hw - arm_w, front, leg_h), v(hw, hd, arm_h));
    }
    if leg_h > 0.0 {
        let r = rng.range(0.02, 0.035);
        for (s, t) in
            [(-hw + 0.05, -hd + 0.06), (hw - 0.05, -hd + 0.06), (-hw + 0.05, hd - 0.06), (hw - 0.05, hd - 0.06)]
        {
            b.cylinder(leg_mat, v(s, t, 0.0), Vec2::splat(r), leg_h, 0.7, 1.0);
        }
    } else {
        // Without legs the skirt reaches the floor: extend the base.
        b.cube(cover, v(s0, -hd + 0.02, 0.0), v(s1, hd - back_th, seat_base));
    }
    b.support([s0 + 0.03, s1 - 0.03, -hd + 0.05, seat_t1], seat_top, h - seat_top + 0.3);
    b.finish(variant)
}

// ---------------------------------------------------------------------------------------------------------
// Tables and desks

fn table(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("table", variant);
    let mut size = size_of(rng, &spec);
    let round = variant != "coffee" && rng.chance(0.25);
    if round {
        let (d0, d1) = spec.depth_range();
        size.y = size.x.clamp(d0, d1);
        size.x = size.y.max(spec.width_range().0);
    }
    if size.y > size.x {
        std::mem::swap(&mut size.x, &mut size.y);
        size = sizes::clamp(&spec, size);
    }
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let top_mat = b.mat(match rng.weighted(&[0.45, 0.35, 0.2]) {
        0 => mat::wood(rng),
        1 => mat::laminate(rng),
        _ => mat::stone(rng),
    });
    let leg_mat = if rng.chance(0.6) { top_mat } else { b.mat(mat::any_hard(rng)) };
    let top_th = rng.range(0.02, 0.06);
    let under = h - top_th;
    if round {
        b.cylinder(top_mat, v(0.0, 0.0, under), Vec2::new(hw, hd), top_th, 1.0, 1.0);
    } else {
        b.cube(top_mat, v(-hw, -hd, under), v(hw, hd, h));
    }
    let style = if round && rng.chance(0.6) {
        1
    } else if !round && rng.chance(0.15) {
        2
    } else {
        0
    };
    let leg = rng.range(0.035, 0.08);
    match style {
        1 => {
            // Pedestal: a column on a foot.
            let col = rng.range(0.04, 0.09);
            b.cylinder(leg_mat, v(0.0, 0.0, 0.03), Vec2::splat(col), under - 0.03, 1.0, rng.range(0.7, 1.0));
            let foot = (hw.min(hd) * rng.range(0.45, 0.7)).max(col + 0.05);
            b.cylinder(leg_mat, v(0.0, 0.0, 0.0), Vec2::splat(foot), 0.03, 1.0, 0.8);
        }
        2 => {
            // Trestle: two end panels joined by a stretcher.
            let panel = rng.range(0.03, 0.06);
            let inset = rng.range(0.05, 0.2).min(0.2 * w);
            for side in [-1.0f32, 1.0] {
                let s = side * (hw - inset);
                b.cube(leg_mat, v(s - 0.5 * panel, -hd + 0.08, 0.0), v(s + 0.5 * panel, hd - 0.08, under));
            }
            b.cube(leg_mat, v(-hw + inset, -0.03, 0.2), v(hw - inset, 0.03, 0.28));
        }
        _ => {
            let inset = if round { 0.29 * hw.min(hd) } else { rng.range(0.02, 0.1) };
            let round_legs = rng.chance(0.4);
            let (ls, lt) = (hw - inset - 0.5 * leg, hd - inset - 0.5 * leg);
            for (s, t) in [(-ls, -lt), (ls, -lt), (-ls, lt), (ls, lt)] {
                if round_legs {
                    b.cylinder(leg_mat, v(s, t, 0.0), Vec2::splat(0.5 * leg), under, rng.range(0.7, 1.0), 1.0);
                } else {
                    b.cube(leg_mat, v(s - 0.5 * leg, t - 0.5 * leg, 0.0), v(s + 0.5 * leg, t + 0.5 * leg, under));
                }
            }
            if !round && rng.chance(0.5) {
                let apron = rng.range(0.05, 0.12).min(under - 0.2);
                let th = 0.02;
                b.cube(leg_mat, v(-ls, -lt - 0.5 * th, under - apron), v(ls, -lt + 0.5 * th, under));
                b.cube(leg_mat, v(-ls, lt - 0.5 * th, under - apron), v(ls, lt + 0.5 * th, under));
                b.cube(leg_mat, v(-ls - 0.5 * th, -lt, under - apron), v(-ls + 0.5 * th, lt, under));
                b.cube(leg_mat, v(ls - 0.5 * th, -lt, under - apron), v(ls + 0.5 * th, lt, under));
            }
            if variant == "coffee" && rng.chance(0.4) {
                let z = rng.range(0.06, 0.12);
                let th = 0.02;
                b.cube(leg_mat, v(-ls, -lt, z), v(ls, lt, z + th));
                b.support([-ls + 0.03, ls - 0.03, -lt + 0.03, lt - 0.03], z + th, under - z - th);
            }
        }
    }
    let (rs, rt) = if round { (0.68 * hw, 0.68 * hd) } else { (hw - 0.03, hd - 0.03) };
    b.supports.insert(0, Support { rect: [-rs, rs, -rt, rt], z: h, clearance: 3.0 });
    b.finish(variant)
}

/// A block of drawers: fronts from u0 to u1 between s0 and s1, their faces at `t_face` (towards −t),
/// handles protruding to `t_handle`.
#[allow(clippy::too_many_arguments)]
fn drawers(
    b: &mut Builder,
    front: u16,
    handle: u16,
    s0: f32,
    s1: f32,
    u0: f32,
    u1: f32,
    rows: usize,
    cols: usize,
    t_face: f32,
    t_handle: f32,
    t_back: f32,
    knobs: bool,
) {
    let gap = 0.004;
    for r in 0..rows {
        let (z0, z1) = (u0 + (u1 - u0) * r as f32 / rows as f32, u0 + (u1 - u0) * (r + 1) as f32 / rows as f32);
        for c in 0..cols {
            let (x0, x1) = (s0 + (s1 - s0) * c as f32 / cols as f32, s0 + (s1 - s0) * (c + 1) as f32 / cols as f32);
            b.cube(front, v(x0 + gap, t_face, z0 + gap), v(x1 - gap, t_back, z1 - gap));
            let (xc, zc) = (0.5 * (x0 + x1), 0.5 * (z0 + z1) + 0.15 * (z1 - z0));
            if knobs {
                b.cube(handle, v(xc - 0.012, t_handle, zc - 0.012), v(xc + 0.012, t_face, zc + 0.012));
            } else {
                let hw = ((x1 - x0) * 0.18).clamp(0.03, 0.09);
                b.cube(handle, v(xc - hw, t_handle, zc - 0.008), v(xc + hw, t_face, zc + 0.008));
            }
        }
    }
}

fn desk(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("desk", variant);
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let top_mat = b.mat(if rng.chance(0.5) { mat::laminate(rng) } else { mat::wood(rng) });
    let body = if rng.chance(0.6) { top_mat } else { b.mat(mat::any_hard(rng)) };
    let handle = b.mat(mat::metal(rng));
    let top_th = rng.range(0.02, 0.05);
    let under = h - top_th;
    b.cube(top_mat, v(-hw, -hd, under), v(hw, hd, h));
    let style = if variant == "student" { 3 } else { rng.int(0, 2) };
    let panel = rng.range(0.02, 0.04);
    match style {
        0 => {
            let leg = rng.range(0.035, 0.07);
            let inset = rng.range(0.01, 0.06);
            for (s, t) in [
                (-hw + inset, -hd + inset),
                (hw - inset - leg, -hd + inset),
                (-hw + inset, hd - inset - leg),
                (hw - inset - leg, hd - inset - leg),
            ] {
                b.cube(body, v(s, t, 0.0), v(s + leg, t + leg, under));
            }
        }
        1 => {
            let ped_w = rng.range(0.35, 0.45).min(0.45 * w);
            let side = rng.sign();
            let (p0, p1) = if side < 0.0 { (-hw + 0.005, -hw + ped_w) } else { (hw - ped_w, hw - 0.005) };
            let t_face = -hd + 0.025;
            b.cube(body, v(p0, t_face + 0.018, 0.0), v(p1, hd - 0.01, under));
            drawers(
                &mut b,
                body,
                handle,
                p0,
                p1,
                0.05,
                under - 0.01,
                rng.int(2, 4),
                1,
                t_face,
                -hd + 0.005,
                t_face + 0.02,
                rng.chance(0.3),
            );
            let (q0, q1) =
                if side < 0.0 { (hw - 0.005 - panel, hw - 0.005) } else { (-hw + 0.005, -hw + 0.005 + panel) };
            b.cube(body, v(q0, -hd + 0.03, 0.0), v(q1, hd - 0.01, under));
            b.cube(body, v(p0.min(q0), hd - 0.03, rng.range(0.25, 0.45)), v(p1.max(q1), hd - 0.012, under));
        }
        2 => {
            for s in [-hw + 0.005, hw - 0.005 - panel] {
                b.cube(body, v(s, -hd + 0.02, 0.0), v(s + panel, hd - 0.01, under));
            }
            b.cube(
                body,
                v(-hw + 0.005 + panel, hd - 0.03, rng.range(0.2, 0.45)),
                v(hw - 0.005 - panel, hd - 0.012, under),
            );
            if rng.chance(0.5) {
                // A drawer under the top.
                let dw = rng.range(0.35, 0.55).min(0.6 * w);
                b.cube(body, v(-0.5 * dw, -hd + 0.03, under - 0.1), v(0.5 * dw, hd - 0.05, under));
                b.cube(handle, v(-0.06, -hd + 0.012, under - 0.06), v(0.06, -hd + 0.03, under - 0.045));
            }
        }
        _ => {
            // Student desk: a tube frame with a book tray under the top.
            let tube = rng.range(0.02, 0.035);
            for (s, t) in [(-hw, -hd + 0.02), (hw - tube, -hd + 0.02), (-hw, hd - tube), (hw - tube, hd - tube)] {
                b.cube(handle, v(s, t, 0.0), v(s + tube, t + tube, under));
            }
            b.cube(handle, v(-hw + tube, hd - tube - 0.005, 0.15), v(hw - tube, hd - 0.005, 0.15 + tube));
            let tray = b.mat(mat::any_hard(rng));
            b.cube(tray, v(-hw + tube, -hd + 0.08, under - 0.12), v(hw - tube, hd - tube, under - 0.1));
            b.cube(tray, v(-hw + tube, hd - tube - 0.01, under - 0.12), v(hw - tube, hd - tube, under));
        }
    }
    b.supports.insert(0, Support { rect: [-hw + 0.03, hw - 0.03, -hd + 0.03, hd - 0.03], z: h, clearance: 3.0 });
    b.finish(variant)
}

// ---------------------------------------------------------------------------------------------------------
// Bathroom

fn toilet(rng: &mut Rng) -> Model {
    let spec = sizes::spec("toilet", "toilet");
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let body = b.mat(mat::ceramic(rng));
    let seat_mat =
        if rng.chance(0.8) { body } else { b.mat(if rng.chance(0.5) { mat::wood(rng) } else { mat::plastic(rng) }) };
    let tank_d = rng.range(0.14, 0.22);
    let seat_top = rng.range(0.38, 0.44);
    let tank_h = rng.range(0.3, 0.42).min(h - seat_top + 0.02);
    b.cube(body, v(-hw, hd - tank_d, h - tank_h), v(hw, hd, h));
    // Flush button on the tank's front.
    b.cube(body, v(-0.025, hd - tank_d - 0.006, h - 0.09), v(0.025, hd - tank_d, h - 0.07));
    let bw = w * rng.range(0.82, 0.95);
    let bd = d - tank_d + rng.range(0.03, 0.06);
    let tc = -hd + 0.5 * bd;
    let bowl_lo = 0.12;
    b.cylinder(
        body,
        v(0.0, tc, bowl_lo),
        Vec2::new(0.5 * bw, 0.5 * bd),
        seat_top - 0.025 - bowl_lo,
        rng.range(0.65, 0.8),
        1.0,
    );
    b.cylinder(body, v(0.0, tc + 0.08 * bd, 0.0), Vec2::new(0.3 * bw, 0.33 * bd), 0.14, 1.0, 0.85);
    b.cylinder(seat_mat, v(0.0, tc, seat_top - 0.025), Vec2::new(0.5 * bw, 0.5 * bd), 0.025, 1.0, 1.0);
    if seat_top + 0.04 + bd < h && rng.chance(0.6) {
        // The lid up, leaning on the tank.
        let tilt = -rng.range(1.3, 1.48);
        let centre = v(0.0, hd - tank_d - 0.06, seat_top + 0.01 + 0.5 * bd * (-tilt).sin());
        b.part(Shape::Frustum { bottom: 1.0, top: 1.0 }, seat_mat, centre, v(0.48 * bw, 0.48 * bd, 0.01), 0.0, tilt);
    } else {
        b.cylinder(seat_mat, v(0.0, tc + 0.01, seat_top), Vec2::new(0.48 * bw, 0.48 * bd), 0.02, 1.0, 1.0);
    }
    b.finish("toilet")
}

fn bathtub(rng: &mut Rng) -> Model {
    let spec = sizes::spec("bathtub", "bathtub");
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let inner = b.mat(mat::ceramic(rng));
    let apron = if rng.chance(0.6) {
        inner
    } else {
        let m = if rng.chance(0.5) { mat::tiles(rng, (0.1, 0.3)) } else { mat::laminate(rng) };
        b.mat(m)
    };
    let wall = rng.range(0.05, 0.1);
    let floor_h = rng.range(0.08, 0.15);
    b.cube(apron, v(-hw, -hd, 0.0), v(hw, -hd + wall, h));
    b.cube(inner, v(-hw, hd - wall, 0.0), v(hw, hd, h));
    b.cube(inner, v(-hw, -hd + wall, 0.0), v(-hw + wall, hd - wall, h));
    b.cube(inner, v(hw - wall, -hd + wall, 0.0), v(hw, hd - wall, h));
    b.cube(inner, v(-hw + wall, -hd + wall, 0.0), v(hw - wall, hd - wall, floor_h));
    let metal = b.mat(mat::metal(rng));
    let end = rng.sign() * (hw - wall);
    let spout = 0.12 * -end.signum();
    b.cube(metal, v(end.min(end + spout), -0.02, h - 0.09), v(end.max(end + spout), 0.02, h - 0.06));
    b.finish("bathtub")
}

fn sink(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("sink", variant);
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let body = b.mat(mat::ceramic(rng));
    let metal = b.mat(mat::metal(rng));
    let faucet_h = rng.range(0.08, 0.15).min(h - 0.08);
    let rim = h - faucet_h;
    let basin_h = if variant == "pedestal" { rng.range(0.15, 0.22) } else { rim };
    let wall = rng.range(0.02, 0.04);
    let back = rng.range(0.06, 0.1);
    let depth = (basin_h - 0.03).min(rng.range(0.08, 0.15));
    let b0 = rim - basin_h;
    b.cube(body, v(-hw, -hd, b0), v(hw, -hd + wall, rim));
    b.cube(body, v(-hw, hd - back, b0), v(hw, hd, rim));
    b.cube(body, v(-hw, -hd + wall, b0), v(-hw + wall, hd - back, rim));
    b.cube(body, v(hw - wall, -hd + wall, b0), v(hw, hd - back, rim));
    b.cube(body, v(-hw + wall, -hd + wall, b0), v(hw - wall, hd - back, rim - depth));
    if variant == "pedestal" {
        let r = rng.range(0.07, 0.11);
        b.cylinder(body, v(0.0, 0.3 * hd, 0.0), Vec2::splat(r), b0 + 0.01, 1.0, rng.range(0.7, 1.0));
    }
    let col = rng.range(0.014, 0.024);
    let tc = hd - 0.5 * back;
    b.cylinder(metal, v(0.0, tc, rim), Vec2::splat(col), faucet_h, 1.0, 1.0);
    let spout = rng.range(0.08, 0.14);
    b.cube(metal, v(-0.015, tc - spout, h - 0.03), v(0.015, tc, h - 0.005));
    for side in [-1.0f32, 1.0] {
        if rng.chance(0.5) {
            b.cylinder(metal, v(side * 0.07, tc, rim), Vec2::splat(0.015), 0.04, 1.0, 1.0);
        }
    }
    b.finish(variant)
}

// ---------------------------------------------------------------------------------------------------------
// Storage

fn chest(rng: &mut Rng, category: &'static str) -> Model {
    let spec = sizes::spec(category, category);
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let nightstand = category == "nightstand";
    let mut b = Builder::default();
    let body = b.mat(if rng.chance(0.6) { mat::wood(rng) } else { mat::laminate(rng) });
    let front = if rng.chance(0.7) { body } else { b.mat(mat::laminate(rng)) };
    let handle = b.mat(if rng.chance(0.7) { mat::metal(rng) } else { mat::wood(rng) });
    let top_th = rng.range(0.02, 0.04);
    let handle_d = rng.range(0.015, 0.03);
    let front_d = 0.018;
    let t_face = -hd + handle_d;
    let t_carcass = t_face + front_d;
    let legs = rng.chance(0.35);
    let base_top = if legs { rng.range(0.08, if nightstand { 0.18 } else { 0.2 }) } else { rng.range(0.04, 0.1) };
    if legs {
        let leg = rng.range(0.03, 0.05);
        for (s, t) in [
            (-hw + 0.02, t_carcass),
            (hw - 0.02 - leg, t_carcass),
            (-hw + 0.02, hd - 0.02 - leg),
            (hw - 0.02 - leg, hd - 0.02 - leg),
        ] {
            b.cylinder(handle, v(s + 0.5 * leg, t + 0.5 * leg, 0.0), Vec2::splat(0.5 * leg), base_top, 0.6, 1.0);
        }
    } else {
        b.cube(body, v(-hw + 0.02, t_carcass + 0.02, 0.0), v(hw - 0.02, hd - 0.02, base_top));
    }
    let side_inset = rng.range(0.0, 0.01);
    let body_top = h - top_th;
    b.cube(body, v(-hw, t_face, body_top), v(hw, hd, h));
    let niche = nightstand && rng.chance(0.4);
    let drawer_top = if niche { base_top + (body_top - base_top) * rng.range(0.35, 0.6) } else { body_top };
    b.cube(body, v(-hw + side_inset, t_carcass, base_top), v(hw - side_inset, hd, drawer_top));
    if niche {
        let panel = 0.018;
        b.cube(body, v(-hw + side_inset, t_carcass, drawer_top), v(-hw + side_inset + panel, hd, body_top));
        b.cube(body, v(hw - side_inset - panel, t_carcass, drawer_top), v(hw - side_inset, hd, body_top));
        b.cube(body, v(-hw + side_inset + panel, hd - 0.015, drawer_top), v(hw - side_inset - panel, hd, body_top));
        let s = hw - side_inset - panel - 0.01;
        b.support([-s, s, t_carcass + 0.01, hd - 0.025], drawer_top, body_top - drawer_top);
    }
    let rows = if nightstand { rng.int(1, if niche { 2 } else { 3 }) } else { rng.int(3, 6) };
    let cols = if nightstand || w < 0.8 { 1 } else { rng.int(1, 2) };
    drawers(
        &mut b,
        front,
        handle,
        -hw + side_inset,
        hw - side_inset,
        base_top,
        drawer_top,
        rows,
        cols,
        t_face,
        -hd,
        t_carcass + 0.002,
        rng.chance(0.4),
    );
    b.supports.insert(0, Support { rect: [-hw + 0.02, hw - 0.02, t_face + 0.02, hd - 0.02], z: h, clearance: 3.0 });
    b.finish(category)
}

fn bookshelf(rng: &mut Rng) -> Model {
    let spec = sizes::spec("bookshelf", "bookshelf");
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let body = b.mat(if rng.chance(0.6) { mat::wood(rng) } else { mat::laminate(rng) });
    let back_mat = if rng.chance(0.6) { body } else { b.mat(mat::paint(rng)) };
    let side = rng.range(0.015, 0.03);
    let shelf = rng.range(0.015, 0.03);
    let back = rng.range(0.005, 0.012);
    let kick = rng.range(0.03, 0.1);
    b.cube(body, v(-hw, -hd, 0.0), v(-hw + side, hd, h));
    b.cube(body, v(hw - side, -hd, 0.0), v(hw, hd, h));
    let (s0, s1) = (-hw + side, hw - side);
    b.cube(body, v(s0, -hd, h - shelf), v(s1, hd, h));
    b.cube(body, v(s0, -hd + 0.01, 0.0), v(s1, hd, kick));
    b.cube(back_mat, v(s0, hd - back, kick), v(s1, hd, h - shelf));
    let spacing = rng.range(0.25, 0.4);
    let n = (((h - kick - shelf) / spacing).round() as usize).max(1);
    let step = (h - kick - shelf) / n as f32;
    let doors = n >= 3 && rng.chance(0.25);
    let mut floors = vec![kick];
    for k in 1..n {
        let z = kick + step * k as f32;
        b.cube(body, v(s0, -hd + 0.01, z - shelf), v(s1, hd - back, z));
        floors.push(z);
    }
    for (k, &z) in floors.iter().enumerate() {
        let ceiling = if k + 1 < floors.len() { floors[k + 1] - shelf } else { h - shelf };
        if doors && k == 0 {
            let mid = 0.5 * (s0 + s1);
            b.cube(body, v(s0 + 0.002, -hd, z), v(mid - 0.002, -hd + 0.018, ceiling));
            b.cube(body, v(mid + 0.002, -hd, z), v(s1 - 0.002, -hd + 0.018, ceiling));
            continue;
        }
        b.support([s0 + 0.01, s1 - 0.01, -hd + 0.02, hd - back - 0.01], z, ceiling - z);
    }
    b.support([-hw + 0.02, hw - 0.02, -hd + 0.02, hd - 0.02], h, 0.6);
    b.finish("bookshelf")
}

fn cardboard_box(rng: &mut Rng) -> Model {
    let spec = sizes::spec("box", "box");
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    if rng.chance(0.6) {
        let board = b.mat(mat::cardboard(rng));
        let tape = b.mat(if rng.chance(0.5) { mat::plastic(rng) } else { mat::cardboard(rng) });
        if rng.chance(0.2) {
            // Open: four walls and a bottom, flaps standing up.
            let wall_h = h * rng.range(0.65, 0.8);
            let th = 0.006;
            b.cube(board, v(-hw, -hd, 0.0), v(hw, -hd + th, wall_h));
            b.cube(board, v(-hw, hd - th, 0.0), v(hw, hd, wall_h));
            b.cube(board, v(-hw, -hd + th, 0.0), v(-hw + th, hd - th, wall_h));
            b.cube(board, v(hw - th, -hd + th, 0.0), v(hw, hd - th, wall_h));
            b.cube(board, v(-hw + th, -hd + th, 0.0), v(hw - th, hd - th, 0.01));
            b.cube(board, v(-hw, -hd, wall_h), v(hw, -hd + th, h));
            b.cube(board, v(-hw, hd - th, wall_h), v(hw, hd, h));
        } else {
            b.cube(board, v(-hw, -hd + 0.002, 0.0), v(hw, hd, h - 0.004));
            b.cube(board, v(-hw, -hd + 0.002, h - 0.004), v(-0.002, hd, h - 0.0015));
            b.cube(board, v(0.002, -hd + 0.002, h - 0.004), v(hw, hd, h - 0.0015));
            let tw = rng.range(0.02, 0.03);
            b.cube(tape, v(-tw, -hd + 0.002, h - 0.0015), v(tw, hd, h));
            let label = b.mat(mat::paper(rng));
            let lw = (0.3 * w).min(0.15);
            let lz = rng.range(0.2, 0.6) * h;
            b.cube(label, v(-lw, -hd, lz), v(lw, -hd + 0.002, (lz + 0.7 * lw).min(h - 0.01)));
        }
    } else {
        let shell = b.mat(mat::plastic(rng));
        let lid = if rng.chance(0.5) { shell } else { b.mat(mat::plastic(rng)) };
        let lid_h = rng.range(0.02, 0.04).min(0.3 * h);
        b.cube(lid, v(-hw, -hd, h - lid_h), v(hw, hd, h));
        b.cube(shell, v(-hw + 0.012, -hd + 0.012, 0.0), v(hw - 0.012, hd - 0.012, h - lid_h));
        for s in [-hw + 0.004, hw - 0.02] {
            b.cube(lid, v(s, -0.04, h - lid_h - 0.05), v(s + 0.016, 0.04, h - lid_h));
        }
    }
    b.finish("box")
}

fn door(rng: &mut Rng) -> Model {
    let spec = sizes::spec("door", "door");
    let size = size_of(rng, &spec);
    let (w, h) = (size.x, size.z);
    let hw = 0.5 * w;
    let mut b = Builder::default();
    let leaf_mat = b.mat(match rng.weighted(&[0.45, 0.35, 0.2]) {
        0 => mat::wood(rng),
        1 => mat::paint(rng),
        _ => mat::laminate(rng),
    });
    let trim_mat = if rng.chance(0.5) { leaf_mat } else { b.mat(mat::paint(rng)) };
    let metal = b.mat(mat::metal(rng));
    let trim_w = rng.range(0.04, 0.08);
    let trim_p = rng.range(0.01, 0.02);
    let recess = rng.range(0.0, 0.03);
    let leaf_th = rng.range(0.035, 0.042);
    let handle_p = rng.range(0.05, 0.065);
    let opening_w = w - 2.0 * trim_w;
    let opening_h = h - trim_w;
    let ow = 0.5 * opening_w;
    // Wall plane at t = 0; the room is at −t.
    b.cube(trim_mat, v(-hw, -trim_p, 0.0), v(-ow, 0.0, h));
    b.cube(trim_mat, v(ow, -trim_p, 0.0), v(hw, 0.0, h));
    b.cube(trim_mat, v(-ow, -trim_p, opening_h), v(ow, 0.0, h));
    let jamb = 0.015;
    let deep = recess + leaf_th;
    b.cube(trim_mat, v(-ow, 0.0, 0.0), v(-ow + jamb, deep, opening_h));
    b.cube(trim_mat, v(ow - jamb, 0.0, 0.0), v(ow, deep, opening_h));
    b.cube(trim_mat, v(-ow + jamb, 0.0, opening_h - jamb), v(ow - jamb, deep, opening_h));
    let (l0, l1) = (-ow + jamb + 0.002, ow - jamb - 0.002);
    let top = opening_h - jamb - 0.003;
    b.cube(leaf_mat, v(l0, recess, 0.008), v(l1, recess + leaf_th, top));
    if rng.chance(0.5) {
        let rows = rng.int(1, 3);
        let cols = rng.int(1, 2);
        let margin = 0.1;
        for r in 0..rows {
            for c in 0..cols {
                let (x0, x1) = (
                    l0 + margin + (l1 - l0 - 2.0 * margin) * c as f32 / cols as f32,
                    l0 + margin + (l1 - l0 - 2.0 * margin) * (c + 1) as f32 / cols as f32,
                );
                let (z0, z1) =
                    (0.12 + (top - 0.24) * r as f32 / rows as f32, 0.12 + (top - 0.24) * (r + 1) as f32 / rows as f32);
                b.cube(leaf_mat, v(x0 + 0.03, recess - 0.006, z0 + 0.03), v(x1 - 0.03, recess, z1 - 0.03));
            }
        }
    }
    let side = rng.sign();
    let hs = side * (ow - jamb - 0.08);
    let hz = rng.range(0.95, 1.05);
    b.cube(metal, v(hs - 0.025, recess - 0.01, hz - 0.04), v(hs + 0.025, recess, hz + 0.04));
    b.cube(metal, v(hs - 0.01, recess - handle_p + 0.015, hz - 0.01), v(hs + 0.01, recess - 0.01, hz + 0.01));
    let lever = -side * 0.12;
    b.cube(
        metal,
        v(hs.min(hs + lever), recess - handle_p, hz - 0.01),
        v(hs.max(hs + lever), recess - handle_p + 0.015, hz + 0.01),
    );
    b.wall_plane_t = 0.0;
    b.opening = Some((opening_w, opening_h));
    b.finish("door")
}

fn counter(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("counter", variant);
    let size = size_of(rng, &spec);
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let fronts = b.mat(if rng.chance(0.5) { mat::laminate(rng) } else { mat::wood(rng) });
    let top_mat = b.mat(if rng.chance(0.6) { mat::stone(rng) } else { mat::laminate(rng) });
    let handle = b.mat(mat::metal(rng));
    let top_th = rng.range(0.02, 0.05);
    let overhang = rng.range(0.025, 0.045);
    let handle_p = rng.range(0.015, 0.025).min(overhang - 0.005);
    let t_doors = -hd + overhang;
    let t_carcass = t_doors + 0.018;
    let plinth = rng.range(0.08, 0.15);
    let under = h - top_th;
    b.cube(top_mat, v(-hw, -hd, under), v(hw, hd, h));
    b.cube(fronts, v(-hw + 0.01, t_carcass + 0.05, 0.0), v(hw - 0.01, hd - 0.01, plinth));
    b.cube(fronts, v(-hw + 0.005, t_carcass, plinth), v(hw - 0.005, hd - 0.005, under));
    let n = ((w / rng.range(0.4, 0.6)).round() as usize).max(1);
    let drawer_row = rng.chance(0.5);
    let door_top = if drawer_row { under - rng.range(0.14, 0.2) } else { under - 0.005 };
    if drawer_row {
        drawers(
            &mut b,
            fronts,
            handle,
            -hw + 0.005,
            hw - 0.005,
            door_top,
            under - 0.005,
            1,
            n,
            t_doors,
            t_doors - handle_p,
            t_carcass + 0.002,
            false,
        );
    }
    let gap = 0.004;
    for i in 0..n {
        let (x0, x1) =
            (-hw + 0.005 + (w - 0.01) * i as f32 / n as f32, -hw + 0.005 + (w - 0.01) * (i + 1) as f32 / n as f32);
        b.cube(fronts, v(x0 + gap, t_doors, plinth + gap), v(x1 - gap, t_carcass + 0.002, door_top - gap));
        let hx = if i % 2 == 0 { x1 - 0.05 } else { x0 + 0.05 };
        b.cube(handle, v(hx - 0.008, t_doors - handle_p, door_top - 0.2), v(hx + 0.008, t_doors, door_top - 0.06));
    }
    b.supports.insert(0, Support { rect: [-hw + 0.03, hw - 0.03, -hd + 0.03, hd - 0.05], z: h, clearance: 0.6 });
    b.finish(variant)
}

fn garbage_bin(rng: &mut Rng) -> Model {
    let spec = sizes::spec("garbage_bin", "garbage_bin");
    let mut size = size_of(rng, &spec);
    let round = rng.chance(0.6);
    if round {
        let (d0, d1) = spec.depth_range();
        size.y = size.x.clamp(d0, d1);
        size.x = size.y.max(spec.width_range().0);
    }
    let (w, d, h) = (size.x, size.y, size.z);
    let (hw, hd) = (0.5 * w, 0.5 * d);
    let mut b = Builder::default();
    let shell = b.mat(if rng.chance(0.6) { mat::plastic(rng) } else { mat::metal(rng) });
    let liner = b.mat({
        let mut m = mat::plastic(rng);
        m.colour *= 0.25;
        m
    });
    let lid = rng.int(0, 2);
    let body_h = if lid == 1 { h - rng.range(0.03, 0.06) } else { h - 0.004 };
    let taper = rng.range(0.78, 0.95);
    if round {
        b.cylinder(shell, v(0.0, 0.0, 0.0), Vec2::new(hw, hd), body_h, taper, 1.0);
    } else {
        b.cube(shell, v(-hw, -hd + 0.02, 0.0), v(hw, hd, body_h));
        // A pedal at the front.
        b.cube(shell, v(-0.04, -hd, 0.0), v(0.04, -hd + 0.02, 0.03));
    }
    match lid {
        1 => {
            if round {
                b.ellipsoid(shell, v(0.0, 0.0, body_h), Vec3::new(hw, hd, h - body_h));
            } else {
                b.cube(shell, v(-hw, -hd, body_h), v(hw, hd, h));
            }
        }
        _ => {
            if round {
                b.cylinder(liner, v(0.0, 0.0, body_h), Vec2::new(0.9 * hw, 0.9 * hd), h - body_h, 1.0, 1.0);
            } else {
                b.cube(liner, v(-hw + 0.015, -hd + 0.015, body_h), v(hw - 0.015, hd - 0.015, h));
            }
        }
    }
    b.finish("garbage_bin")
}

// ---------------------------------------------------------------------------------------------------------
// Small objects

fn pillow(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("pillow", variant);
    let size = size_of(rng, &spec);
    let mut b = Builder::default();
    let cover = b.mat(if rng.chance(0.5) { bedding(rng) } else { mat::fabric(rng) });
    let half = 0.5 * size;
    let c = v(0.0, 0.0, half.z);
    b.ellipsoid(cover, c, half);
    let core = if variant == "flat" { Vec3::new(0.9, 0.82, 0.55) } else { Vec3::new(0.82, 0.55, 0.9) };
    b.cube(cover, c - half * core, c + half * core);
    b.finish(variant)
}

/// A screen in a bezel facing −t with its front at `t_screen`, spanning [u0, u1] × [−w/2, w/2].
#[allow(clippy::too_many_arguments)] // the panel's extents and state; a struct would only rename them
fn screen_panel(b: &mut Builder, rng: &mut Rng, w: f32, u0: f32, u1: f32, t_screen: f32, panel_th: f32, on: bool) {
    let bezel_mat = b.mat(if rng.chance(0.7) {
        let mut m = mat::plastic(rng);
        m.colour = Vec3::splat(rng.range(0.01, 0.08));
        m
    } else {
        mat::metal(rng)
    });
    let display = b.mat(mat::screen(rng, on));
    let hw = 0.5 * w;
    let bezel = rng.range(0.008, 0.03);
    b.cube(bezel_mat, v(-hw, t_screen + 0.002, u0), v(hw, t_screen + panel_th, u1));
    b.cube(
        display,
        v(-hw + bezel, t_screen, u0 + bezel * rng.range(1.0, 2.0)),
        v(hw - bezel, t_screen + 0.002, u1 - bezel),
    );
}

fn monitor(rng: &mut Rng) -> Model {
    let spec = sizes::spec("monitor", "monitor");
    let size = size_of(rng, &spec);
    let (w, d) = (size.x, size.y);
    let hd = 0.5 * d;
    let stand_h = rng.range(0.05, 0.14);
    let aspect = rng.range(1.3, 1.9);
    let (h0, h1) = spec.height_range();
    let screen_h = (w / aspect).clamp(h0 - stand_h, h1 - stand_h);
    let h = screen_h + stand_h;
    let mut b = Builder::default();
    let stand_mat = b.mat(if rng.chance(0.6) { mat::plastic(rng) } else { mat::metal(rng) });
    let panel_th = rng.range(0.015, 0.05);
    let t_screen = -hd + rng.range(0.02, 0.05);
    let on = rng.chance(0.5);
    screen_panel(&mut b, rng, w, stand_h, h, t_screen, panel_th, on);
    let housing_d = rng.range(0.01, 0.05).min(hd - (t_screen + panel_th) - 0.03);
    if housing_d > 0.005 {
        b.cube(
            stand_mat,
            v(-0.3 * w, t_screen + panel_th, stand_h + 0.2 * screen_h),
            v(0.3 * w, t_screen + panel_th + housing_d, h - 0.2 * screen_h),
        );
    }
    let neck_t = t_screen + panel_th;
    b.cube(stand_mat, v(-0.03, neck_t, 0.01), v(0.03, neck_t + 0.025, stand_h + 0.4 * screen_h));
    let base_hw = rng.range(0.09, 0.15).min(0.5 * w);
    if rng.chance(0.5) {
        b.cube(stand_mat, v(-base_hw, -hd, 0.0), v(base_hw, hd, 0.015));
    } else {
        b.cylinder(stand_mat, v(0.0, 0.0, 0.0), Vec2::new(base_hw, hd), 0.015, 1.0, 0.9);
    }
    b.finish("monitor")
}

fn tv(rng: &mut Rng, mounted: bool) -> Model {
    let spec = sizes::spec("tv", "tv");
    let size = size_of(rng, &spec);
    let w = size.x;
    let (h0, h1) = spec.height_range();
    let stand_h = if mounted { 0.0 } else { rng.range(0.03, 0.12) };
    let screen_h = (w * 9.0 / 16.0 + 0.04).clamp(h0 - stand_h, h1 - stand_h);
    let h = screen_h + stand_h;
    let mut b = Builder::default();
    let stand_mat = b.mat(if rng.chance(0.7) { mat::plastic(rng) } else { mat::metal(rng) });
    let panel_th = rng.range(0.03, 0.08);
    let on = rng.chance(0.35);
    if mounted {
        screen_panel(&mut b, rng, w, 0.0, h, -0.5 * panel_th - 0.01, panel_th, on);
        b.cube(stand_mat, v(-0.15, 0.5 * panel_th - 0.01, 0.3 * h), v(0.15, 0.5 * panel_th + 0.02, 0.7 * h));
        return b.finish("mounted");
    }
    let d = size.y.max(0.15);
    let hd = 0.5 * d;
    let t_screen = -0.5 * panel_th;
    screen_panel(&mut b, rng, w, stand_h, h, t_screen, panel_th, on);
    if rng.chance(0.5) {
        b.cube(
            stand_mat,
            v(-0.04, t_screen + panel_th, 0.01),
            v(0.04, t_screen + panel_th + 0.03, stand_h + 0.2 * screen_h),
        );
        let base = rng.range(0.15, 0.3).min(0.4 * w);
        b.cube(stand_mat, v(-base, -hd, 0.0), v(base, hd, 0.02));
    } else {
        for side in [-1.0f32, 1.0] {
            let s = side * 0.38 * w;
            b.cube(stand_mat, v(s - 0.02, -hd, 0.0), v(s + 0.02, hd, 0.015));
            b.cube(stand_mat, v(s - 0.015, -0.01, 0.0), v(s + 0.015, 0.01, stand_h + 0.05));
        }
    }
    b.finish("standing")
}

fn lamp(rng: &mut Rng, variant: &'static str) -> Model {
    let spec = sizes::spec("lamp", variant);
    let size = size_of(rng, &spec);
    let (w, h) = (size.x, size.z);
    let hw = 0.5 * w;
    let mut b = Builder::default();
    let lit = rng.chance(0.4);
    let shade = b.mat(mat::lamp_shade(rng, lit));
    let body = b.mat(match rng.weighted(&[0.4, 0.3, 0.3]) {
        0 => mat::ceramic(rng),
        1 => mat::metal(rng),
        _ => mat::wood(rng),
    });
    let shade_top = rng.range(0.55, 0.9);
    let (shade_h, shade_shape) = if variant == "floor" && rng.chance(0.3) {
        // Torchiere: an upturned bowl.
        (rng.range(0.1, 0.16), Shape::Frustum { bottom: rng.range(0.2, 0.4), top: 1.0 })
    } else {
        ((0.35 * h).min(rng.range(0.14, 0.32)), Shape::Frustum { bottom: 1.0, top: shade_top })
    };
    b.part(shade_shape, shade, v(0.0, 0.0, h - 0.5 * shade_h), v(hw, hw, 0.5 * shade_h), 0.0, 0.0);
    let foot =
        if variant == "floor" { rng.range(0.1, 0.17).min(hw) } else { (hw * rng.range(0.45, 0.8)).max(0.06).min(hw) };
    b.cylinder(body, v(0.0, 0.0, 0.0), Vec2::splat(foot), 0.025, 1.0, 0.85);
    if variant == "floor" {
        b.cylinder(body, v(0.0, 0.0, 0.02), Vec2::splat(rng.range(0.01, 0.018)), h - 0.5 * shade_h - 0.02, 1.0, 1.0);
    } else {
        let body_h = (h - shade_h) * rng.range(0.5, 0.9);
        let r = (foot * rng.range(0.6, 1.0)).max(0.03);
        if rng.chance(0.5) {
            b.ellipsoid(body, v(0.0, 0.0, 0.02 + 0.5 * body_h), Vec3::new(r, r, 0.5 * body_h));
        } else {
            b.cylinder(body, v(0.0, 0.0, 0.02), Vec2::splat(r), body_h, rng.range(0.6, 1.0), rng.range(0.5, 1.0));
        }
        b.cylinder(body, v(0.0, 0.0, 0.02 + body_h), Vec2::splat(0.01), h - shade_h - body_h + 0.02, 1.0, 1.0);
    }
    if lit {
        b.light = Some(ModelLight {
            position: v(0.0, 0.0, h - 0.6 * shade_h),
            intensity: Vec3::new(1.0, 0.85, 0.6) * rng.range(0.15, 0.4),
        });
    }
    b.finish(variant)
}

// ---------------------------------------------------------------------------------------------------------
// Unlabelled clutter

/// Names of the unlabelled clutter models.
pub const CLUTTER: [&str; 19] = [
    "plant",
    "bag",
    "books",
    "book_stack",
    "cup",
    "bottle",
    "keyboard",
    "laptop",
    "papers",
    "wardrobe",
    "cabinet",
    "fridge",
    "upper_cabinet",
    "whiteboard",
    "picture",
    "curtain",
    "radiator",
    "clothes",
    "rug",
];

/// Builds an unlabelled clutter model by name (see [`CLUTTER`]; `mirror` and `vase` too).
pub fn clutter(name: &str, rng: &mut Rng) -> Model {
    let mut b = Builder::default();
    let variant: &'static str = CLUTTER.iter().copied().find(|c| *c == name).unwrap_or("clutter");
    match name {
        "plant" => {
            let pot = b.mat(if rng.chance(0.5) { mat::ceramic(rng) } else { mat::plastic(rng) });
            let leaves = b.mat(mat::foliage(rng));
            let r = rng.range(0.07, 0.2);
            let ph = rng.range(0.12, 0.35);
            b.cylinder(pot, v(0.0, 0.0, 0.0), Vec2::splat(r), ph, 0.7, 1.0);
            let height = rng.range(0.2, 1.3);
            let n = rng.int(3, 8);
            for _ in 0..n {
                let c = v(rng.range(-r, r), rng.range(-r, r), ph + rng.range(0.2, 0.9) * height);
                let s = rng.range(0.4, 1.0) * (r + 0.1);
                b.ellipsoid(leaves, c, v(s, s, rng.range(0.5, 1.2) * s));
            }
        }
        "bag" => {
            let m = b.mat(mat::any_soft(rng));
            let (w, d, h) = (rng.range(0.25, 0.45), rng.range(0.1, 0.22), rng.range(0.2, 0.45));
            b.part(
                Shape::Frustum { bottom: 1.0, top: 0.85 },
                m,
                v(0.0, 0.0, 0.5 * h),
                v(0.5 * w, 0.5 * d, 0.5 * h),
                0.0,
                0.0,
            );
            b.cube(m, v(-0.1, -0.01, h), v(0.1, 0.01, h + 0.12));
        }
        "books" => {
            let length = rng.range(0.15, 0.8);
            let tallest = rng.range(0.17, 0.3);
            let depth = rng.range(0.12, 0.22);
            let palette: Vec<u16> = (0..4).map(|_| b.mat(mat::fabric(rng))).collect();
            let mut s = -0.5 * length;
            while s < 0.5 * length - 0.015 {
                let th = rng.range(0.015, 0.05).min(0.5 * length - s);
                let bh = tallest * rng.range(0.7, 1.0);
                let m = palette[rng.int(0, palette.len() - 1)];
                b.cube(m, v(s, -0.5 * depth, 0.0), v(s + th - 0.001, -0.5 * depth + depth * rng.range(0.85, 1.0), bh));
                s += th;
            }
        }
        "book_stack" => {
            let n = rng.int(2, 6);
            let mut z = 0.0;
            for _ in 0..n {
                let m = b.mat(mat::fabric(rng));
                let (w, d, th) = (rng.range(0.15, 0.3), rng.range(0.12, 0.22), rng.range(0.015, 0.05));
                b.part(
                    Shape::Box,
                    m,
                    v(0.0, 0.0, z + 0.5 * th),
                    v(0.5 * w, 0.5 * d, 0.5 * th),
                    rng.range(-0.2, 0.2),
                    0.0,
                );
                z += th;
            }
        }
        "cup" | "vase" => {
            let m = b.mat(if rng.chance(0.6) { mat::ceramic(rng) } else { mat::plastic(rng) });
            let (r, h) = if name == "cup" {
                (rng.range(0.03, 0.045), rng.range(0.07, 0.12))
            } else {
                (rng.range(0.05, 0.1), rng.range(0.15, 0.4))
            };
            b.cylinder(m, v(0.0, 0.0, 0.0), Vec2::splat(r), h, rng.range(0.7, 1.0), 1.0);
        }
        "bottle" => {
            let m = b.mat(if rng.chance(0.5) { mat::plastic(rng) } else { mat::ceramic(rng) });
            let r = rng.range(0.03, 0.045);
            let h = rng.range(0.15, 0.3);
            b.cylinder(m, v(0.0, 0.0, 0.0), Vec2::splat(r), 0.7 * h, 1.0, 1.0);
            b.cylinder(m, v(0.0, 0.0, 0.7 * h), Vec2::splat(r), 0.3 * h, 1.0, 0.35);
        }
        "keyboard" => {
            let body = b.mat({
                let mut m = mat::plastic(rng);
                m.pattern = mat::Pattern::Checks { period: 0.019, second: m.colour * 0.4 + Vec3::splat(0.1) };
                m
            });
            b.cube(body, v(-0.22, -0.075, 0.0), v(0.22, 0.075, 0.025));
        }
        "laptop" => {
            let shell = b.mat(if rng.chance(0.5) { mat::metal(rng) } else { mat::plastic(rng) });
            let on = rng.chance(0.6);
            let display = b.mat(mat::screen(rng, on));
            let (w, d) = (rng.range(0.3, 0.38), rng.range(0.21, 0.26));
            b.cube(shell, v(-0.5 * w, -0.5 * d, 0.0), v(0.5 * w, 0.5 * d, 0.02));
            let tilt = rng.range(0.15, 0.45);
            let centre = v(0.0, 0.5 * d + 0.5 * d * tilt.sin(), 0.02 + 0.5 * d * tilt.cos());
            b.part(Shape::Box, shell, centre, v(0.5 * w, 0.5 * d, 0.006), 0.0, std::f32::consts::FRAC_PI_2 - tilt);
            b.part(
                Shape::Box,
                display,
                centre - v(0.0, 0.007 * tilt.cos(), -0.007 * tilt.sin()),
                v(0.47 * w, 0.45 * d, 0.001),
                0.0,
                std::f32::consts::FRAC_PI_2 - tilt,
            );
        }
        "papers" => {
            let m = b.mat(mat::paper(rng));
            b.cube(m, v(-0.105, -0.15, 0.0), v(0.105, 0.15, rng.range(0.002, 0.03)));
        }
        "wardrobe" | "cabinet" | "fridge" | "upper_cabinet" => {
            let (w, d, h) = match name {
                "wardrobe" => (rng.range(0.8, 2.0), rng.range(0.55, 0.65), rng.range(1.8, 2.2)),
                "cabinet" => (rng.range(0.8, 1.8), rng.range(0.35, 0.5), rng.range(0.4, 0.75)),
                "fridge" => (rng.range(0.6, 0.8), rng.range(0.6, 0.72), rng.range(1.5, 1.9)),
                _ => (rng.range(0.6, 2.0), rng.range(0.3, 0.36), rng.range(0.5, 0.8)),
            };
            let body = b.mat(if name == "fridge" {
                if rng.chance(0.5) {
                    mat::metal(rng)
                } else {
                    mat::ceramic(rng)
                }
            } else {
                mat::any_hard(rng)
            });
            let handle = b.mat(mat::metal(rng));
            let (hw, hd) = (0.5 * w, 0.5 * d);
            b.cube(body, v(-hw, -hd + 0.04, 0.0), v(hw, hd, h));
            let n = if name == "fridge" { 1 } else { ((w / 0.5).round() as usize).max(1) };
            let rows = if name == "fridge" && rng.chance(0.7) { 2 } else { 1 };
            for r in 0..rows {
                let (z0, z1) = if rows == 2 {
                    if r == 0 {
                        (0.02, 0.6 * h)
                    } else {
                        (0.6 * h + 0.01, h - 0.01)
                    }
                } else {
                    (0.02, h - 0.01)
                };
                for i in 0..n {
                    let (x0, x1) = (-hw + w * i as f32 / n as f32, -hw + w * (i + 1) as f32 / n as f32);
                    b.cube(body, v(x0 + 0.003, -hd + 0.02, z0), v(x1 - 0.003, -hd + 0.041, z1));
                    let hx = if i % 2 == 0 { x1 - 0.05 } else { x0 + 0.05 };
                    let hz = if name == "upper_cabinet" { z0 + 0.08 } else { 0.5 * (z0 + z1).min(1.1) };
                    b.cube(handle, v(hx - 0.008, -hd, hz - 0.08), v(hx + 0.008, -hd + 0.02, hz + 0.08));
                }
            }
            b.support([-hw + 0.02, hw - 0.02, -hd + 0.05, hd - 0.02], h, 2.0);
        }
        "whiteboard" | "picture" | "mirror" => {
            let (w, h) = match name {
                "whiteboard" => (rng.range(1.2, 2.4), rng.range(0.9, 1.2)),
                "mirror" => (rng.range(0.4, 1.0), rng.range(0.5, 0.9)),
                _ => (rng.range(0.25, 1.0), rng.range(0.2, 0.8)),
            };
            let frame = b.mat(if rng.chance(0.5) { mat::metal(rng) } else { mat::wood(rng) });
            let face = b.mat(match name {
                "whiteboard" => mat::paper(rng),
                "mirror" => mat::mirror(rng),
                _ => {
                    let mut m = mat::fabric(rng);
                    m.pattern = mat::Pattern::Display { scale: rng.range(0.05, 0.3) };
                    m.colour = Vec3::splat(rng.range(0.5, 1.0));
                    m
                }
            });
            let (hw, th) = (0.5 * w, rng.range(0.015, 0.035));
            let f = rng.range(0.01, 0.04);
            b.cube(frame, v(-hw, -0.5 * th, 0.0), v(hw, 0.5 * th, h));
            b.cube(face, v(-hw + f, -0.5 * th - 0.002, f), v(hw - f, 0.5 * th, h - f));
        }
        "curtain" => {
            let m = b.mat({
                let mut m = mat::fabric(rng);
                m.pattern = mat::Pattern::Stripes { period: rng.range(0.06, 0.14), second: m.colour * 0.75 };
                m
            });
            let (w, d, h) = (rng.range(0.3, 0.7), rng.range(0.05, 0.12), rng.range(1.6, 2.4));
            b.cube(m, v(-0.5 * w, -0.5 * d, 0.0), v(0.5 * w, 0.5 * d, h));
        }
        "radiator" => {
            let m = b.mat({
                let mut m = mat::paint(rng);
                m.pattern = mat::Pattern::Stripes { period: rng.range(0.04, 0.08), second: m.colour * 0.6 };
                m
            });
            let (w, d, h) = (rng.range(0.6, 1.4), rng.range(0.08, 0.12), rng.range(0.4, 0.65));
            b.cube(m, v(-0.5 * w, -0.5 * d, 0.0), v(0.5 * w, 0.5 * d, h));
        }
        "clothes" => {
            let n = rng.int(2, 4);
            for _ in 0..n {
                let m = b.mat(mat::fabric(rng));
                let half = v(rng.range(0.12, 0.3), rng.range(0.1, 0.25), rng.range(0.03, 0.08));
                b.ellipsoid(m, v(rng.range(-0.15, 0.15), rng.range(-0.1, 0.1), half.z), half);
            }
        }
        "rug" => {
            let m = b.mat(if rng.chance(0.5) { mat::carpet(rng) } else { mat::fabric(rng) });
            let (w, d) = (rng.range(1.2, 2.5), rng.range(0.8, 1.8));
            b.cube(m, v(-0.5 * w, -0.5 * d, 0.0), v(0.5 * w, 0.5 * d, 0.004));
        }
        _ => {
            let m = b.mat(mat::cardboard(rng));
            b.cube(m, v(-0.1, -0.1, 0.0), v(0.1, 0.1, 0.2));
        }
    }
    b.finish(variant)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::category::CATEGORIES;

    #[test]
    fn models_fill_their_drawn_size_and_stay_in_range() {
        for cat in CATEGORIES {
            let range = sizes::size_range(cat).unwrap();
            for i in 0..200 {
                let mut rng = Rng::derive(&[11, i]);
                let m = build(cat, None, &mut rng);
                for (k, (lo, hi)) in range.iter().enumerate() {
                    let x = m.size[k];
                    assert!(x >= lo - 1e-3 && x <= hi + 1e-3, "{cat}/{} dim {k} = {x} outside [{lo}, {hi}]", m.variant);
                }
                // Bounds are centred with the bottom at u = 0.
                let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
                for p in &m.parts {
                    let (a, b) = p.bounds();
                    lo = lo.min(a);
                    hi = hi.max(b);
                }
                assert!((lo.z).abs() < 1e-5 && (lo.x + hi.x).abs() < 1e-4 && (lo.y + hi.y).abs() < 1e-4, "{cat}");
                for s in &m.supports {
                    assert!(
                        s.rect[0] >= lo.x - 1e-4 && s.rect[1] <= hi.x + 1e-4 && s.z <= m.size.z + 1e-4,
                        "{cat} support"
                    );
                }
            }
        }
    }
}
