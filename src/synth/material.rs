//! Surface materials: procedural textures with real image gradients, and what the depth sensor sees.
//!
//! Every category draws its materials from the same shared pools (woods, fabrics, paints, plastics,
//! metals, ceramics...), with per-instance colours and pattern parameters, so no category has a colour or
//! texture of its own a detector could key on. Textures are evaluated in the part's own metric frame, so they
//! move with the object and keep a physical scale (planks ≈ 12 cm, tiles ≈ 20–60 cm, weave ≈ cm).

use glam::Vec3;

use super::rng::{cell_unit, fbm3, value_noise3, Rng};

/// The procedural pattern of a material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pattern {
    /// Paint or plaster: soft low-frequency tone variation only.
    Plain,
    /// Wood grain along the part's longest axis: `freq` rings per metre.
    Wood { freq: f32, dark: Vec3 },
    /// Floor boards: `width`-wide planks of varying tone with dark seams.
    Planks { width: f32, length: f32, dark: Vec3 },
    /// Square tiles of `size` metres with `grout`-wide joints.
    Tiles { size: f32, grout: f32, grout_colour: Vec3 },
    /// Parallel stripes of `period` metres along one in-plane axis.
    Stripes { period: f32, second: Vec3 },
    /// A check pattern of `period` metres.
    Checks { period: f32, second: Vec3 },
    /// Two-tone organic blotches (floral prints, camouflage, marble): `scale` metres.
    Blotches { scale: f32, second: Vec3 },
    /// Fine speckle (carpet, stone, cardboard): `amount` of per-cm variation.
    Speckle { amount: f32 },
    /// Vertical spines of books: `period` metres wide, each a different colour.
    Spines { period: f32 },
    /// A lit display: smooth coloured blobs (a picture), scale in metres.
    Display { scale: f32 },
}

/// A surface material.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Linear-light base albedo.
    pub colour: Vec3,
    pub pattern: Pattern,
    /// Amplitude of the low-frequency tone variation (0..0.3).
    pub tone_noise: f32,
    /// Strength of a Blinn–Phong highlight (0 = matte).
    pub specular: f32,
    pub shininess: f32,
    /// Emitted radiance (lit lamp shades, screens, windows), added after shading.
    pub emission: Vec3,
    /// Infrared reflectance seen by the depth sensor (low → missing depth).
    pub infrared: f32,
    /// Specularity for the depth sensor (glass, screens, polished metal → missing depth).
    pub gloss: f32,
}

/// sRGB byte colour to linear light.
pub fn srgb(r: u8, g: u8, b: u8) -> Vec3 {
    let f = |c: u8| {
        let c = c as f32 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    Vec3::new(f(r), f(g), f(b))
}

fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

impl Material {
    fn base(colour: Vec3, pattern: Pattern) -> Self {
        let lum = luminance(colour);
        Material {
            colour,
            pattern,
            tone_noise: 0.06,
            specular: 0.0,
            shininess: 20.0,
            emission: Vec3::ZERO,
            // Near-infrared reflectance tracks visible brightness loosely; very dark dyes and black plastics
            // absorb the projector's pattern.
            infrared: (0.15 + 1.4 * lum.sqrt()).min(1.0),
            gloss: 0.0,
        }
    }

    /// Albedo at the local point `p` (metres, in the part's frame) on a face whose dominant local axis is
    /// `axis` (0, 1, 2); `grain` is the axis wood grain runs along; `seed` varies the texture per part.
    pub fn albedo(&self, p: Vec3, axis: usize, grain: usize, seed: u32) -> Vec3 {
        let (a, b) = match axis {
            0 => (p.y, p.z),
            1 => (p.x, p.z),
            _ => (p.x, p.y),
        };
        let tone = 1.0 + self.tone_noise * fbm3(seed, p * 2.5);
        let c = match self.pattern {
            Pattern::Plain => self.colour * (1.0 + 0.03 * value_noise3(seed ^ 0x51, p * 30.0)),
            Pattern::Wood { freq, dark } => {
                let along = p[grain];
                let (x1, x2) = match grain {
                    0 => (p.y, p.z),
                    1 => (p.x, p.z),
                    _ => (p.x, p.y),
                };
                let warp = 1.8 * value_noise3(seed, Vec3::new(along * 1.5, x1 * 6.0, x2 * 6.0));
                let ring = (x1 + 0.7 * x2) * freq + warp;
                let s = 0.5 + 0.5 * (ring * std::f32::consts::TAU).sin();
                let fine = 0.06 * value_noise3(seed ^ 0x77, Vec3::new(along * 4.0, x1 * 80.0, x2 * 80.0));
                self.colour.lerp(dark, s * s * 0.7) * (1.0 + fine)
            }
            Pattern::Planks { width, length, dark } => {
                let row = (b / width).floor();
                let offset = cell_unit(seed, row as i32, 7, 0) * length;
                let col = ((a + offset) / length).floor();
                let (fa, fb) = ((a + offset) / length - col, b / width - row);
                let edge = fa.min(1.0 - fa) * length < 0.003 || fb.min(1.0 - fb) * width < 0.003;
                if edge {
                    dark * 0.6
                } else {
                    let plank_tone = 0.8 + 0.4 * cell_unit(seed, row as i32, col as i32, 1);
                    let grain = 0.5
                        + 0.5 * ((b * 90.0 + 2.0 * value_noise3(seed, Vec3::new(a * 2.0, b * 40.0, 0.0))) * 3.0).sin();
                    self.colour.lerp(dark, 0.35 * grain) * plank_tone
                }
            }
            Pattern::Tiles { size, grout, grout_colour } => {
                let (i, j) = ((a / size).floor(), (b / size).floor());
                let (fa, fb) = (a - i * size, b - j * size);
                if fa < grout || fb < grout {
                    grout_colour
                } else {
                    let t = 0.9 + 0.2 * cell_unit(seed, i as i32, j as i32, 3);
                    self.colour * t * (1.0 + 0.04 * value_noise3(seed ^ 0x33, p * 25.0))
                }
            }
            Pattern::Stripes { period, second } => {
                let s = (a / period).rem_euclid(1.0);
                if s < 0.5 {
                    self.colour
                } else {
                    second
                }
            }
            Pattern::Checks { period, second } => {
                let parity = ((a / period).floor() + (b / period).floor()) as i64 & 1;
                if parity == 0 {
                    self.colour
                } else {
                    self.colour.lerp(second, 0.7)
                }
            }
            Pattern::Blotches { scale, second } => {
                let v = value_noise3(seed ^ 0x99, p / scale) + 0.4 * value_noise3(seed ^ 0x98, p * (2.3 / scale));
                let m = ((v - 0.1) * 6.0).clamp(0.0, 1.0);
                self.colour.lerp(second, m)
            }
            Pattern::Speckle { amount } => {
                let v = value_noise3(seed ^ 0x5e, p * 120.0) + 0.5 * value_noise3(seed ^ 0x5f, p * 35.0);
                self.colour * (1.0 + amount * v)
            }
            Pattern::Spines { period } => {
                let k = (a / period).floor() as i32;
                let hue = cell_unit(seed, k, 0, 11);
                let c = spine_colour(hue, cell_unit(seed, k, 0, 12));
                let f = (a / period).rem_euclid(1.0);
                if f < 0.06 {
                    c * 0.4
                } else {
                    c
                }
            }
            Pattern::Display { scale } => {
                let q = Vec3::new(a, b, 0.0) / scale;
                Vec3::new(
                    0.5 + 0.5 * value_noise3(seed ^ 1, q),
                    0.5 + 0.5 * value_noise3(seed ^ 2, q),
                    0.5 + 0.5 * value_noise3(seed ^ 3, q),
                ) * self.colour
            }
        };
        (c * tone).clamp(Vec3::ZERO, Vec3::ONE)
    }
}

fn spine_colour(hue: f32, value: f32) -> Vec3 {
    const SPINES: [(u8, u8, u8); 10] = [
        (150, 30, 30),
        (30, 60, 120),
        (230, 220, 200),
        (40, 100, 50),
        (20, 20, 25),
        (200, 150, 40),
        (110, 60, 30),
        (180, 180, 190),
        (120, 40, 90),
        (230, 120, 40),
    ];
    let (r, g, b) = SPINES[(hue * SPINES.len() as f32) as usize % SPINES.len()];
    srgb(r, g, b) * (0.6 + 0.6 * value)
}

/// Jitters a palette colour per instance (brightness and a little hue).
fn jitter(rng: &mut Rng, c: Vec3, amount: f32) -> Vec3 {
    let k = 1.0 + amount * (2.0 * rng.f32() - 1.0);
    let tint = Vec3::new(
        1.0 + 0.3 * amount * rng.normal(),
        1.0 + 0.3 * amount * rng.normal(),
        1.0 + 0.3 * amount * rng.normal(),
    );
    (c * k * tint).clamp(Vec3::splat(0.003), Vec3::splat(0.95))
}

fn pick_colour(rng: &mut Rng, palette: &[(u8, u8, u8)], amount: f32) -> Vec3 {
    let (r, g, b) = *rng.pick(palette);
    jitter(rng, srgb(r, g, b), amount)
}

const WOODS: [(u8, u8, u8); 8] = [
    (190, 150, 105),
    (160, 110, 70),
    (120, 80, 50),
    (90, 60, 40),
    (210, 180, 140),
    (70, 45, 30),
    (175, 125, 80),
    (140, 100, 75),
];

const FABRICS: [(u8, u8, u8); 18] = [
    (200, 200, 195),
    (230, 225, 215),
    (120, 120, 125),
    (60, 60, 65),
    (150, 40, 40),
    (40, 60, 110),
    (80, 120, 160),
    (70, 110, 70),
    (170, 150, 110),
    (190, 170, 150),
    (110, 80, 60),
    (200, 120, 130),
    (220, 190, 90),
    (90, 60, 100),
    (30, 30, 35),
    (160, 170, 180),
    (180, 100, 50),
    (100, 140, 130),
];

const PAINTS: [(u8, u8, u8); 12] = [
    (235, 232, 225),
    (225, 220, 205),
    (215, 215, 220),
    (240, 235, 215),
    (200, 210, 200),
    (215, 200, 180),
    (190, 200, 215),
    (230, 215, 200),
    (180, 175, 170),
    (210, 190, 160),
    (225, 225, 225),
    (170, 190, 180),
];

const PLASTICS: [(u8, u8, u8); 10] = [
    (30, 30, 32),
    (235, 235, 235),
    (120, 120, 125),
    (60, 60, 65),
    (180, 40, 40),
    (40, 80, 160),
    (220, 200, 60),
    (70, 140, 80),
    (200, 200, 190),
    (90, 90, 95),
];

const METALS: [(u8, u8, u8); 5] = [(170, 170, 175), (120, 120, 125), (60, 60, 62), (200, 195, 185), (40, 40, 42)];

const CERAMICS: [(u8, u8, u8); 5] =
    [(240, 240, 238), (235, 232, 222), (225, 228, 232), (245, 245, 245), (210, 205, 195)];

const STONES: [(u8, u8, u8); 6] =
    [(200, 195, 185), (60, 60, 62), (150, 145, 140), (230, 225, 215), (110, 100, 90), (180, 170, 150)];

/// Natural or stained wood.
pub fn wood(rng: &mut Rng) -> Material {
    let colour = pick_colour(rng, &WOODS, 0.15);
    let mut m =
        Material::base(colour, Pattern::Wood { freq: rng.range(12.0, 40.0), dark: colour * rng.range(0.55, 0.8) });
    m.tone_noise = 0.08;
    m.specular = rng.range(0.0, 0.15);
    m
}

/// Melamine or painted board: flat colour, sometimes a wood-look print.
pub fn laminate(rng: &mut Rng) -> Material {
    if rng.chance(0.35) {
        let mut m = wood(rng);
        m.specular = 0.1;
        return m;
    }
    let colour = if rng.chance(0.5) { pick_colour(rng, &PAINTS, 0.1) } else { pick_colour(rng, &PLASTICS, 0.1) };
    let mut m = Material::base(colour, Pattern::Plain);
    m.specular = rng.range(0.05, 0.25);
    m.tone_noise = 0.04;
    m
}

/// Upholstery and bedding: plain, striped, checked or printed.
pub fn fabric(rng: &mut Rng) -> Material {
    let colour = pick_colour(rng, &FABRICS, 0.15);
    let second = pick_colour(rng, &FABRICS, 0.15);
    let pattern = match rng.weighted(&[0.45, 0.15, 0.12, 0.18, 0.1]) {
        0 => Pattern::Speckle { amount: rng.range(0.04, 0.12) },
        1 => Pattern::Stripes { period: rng.range(0.02, 0.15), second },
        2 => Pattern::Checks { period: rng.range(0.03, 0.15), second },
        3 => Pattern::Blotches { scale: rng.range(0.05, 0.2), second },
        _ => Pattern::Plain,
    };
    let mut m = Material::base(colour, pattern);
    m.tone_noise = rng.range(0.05, 0.15);
    m
}

/// Leather or vinyl: darkish, a soft sheen.
pub fn leather(rng: &mut Rng) -> Material {
    const LEATHERS: [(u8, u8, u8); 5] = [(40, 30, 25), (90, 55, 35), (20, 20, 22), (140, 100, 70), (200, 190, 175)];
    let mut m = Material::base(pick_colour(rng, &LEATHERS, 0.15), Pattern::Speckle { amount: 0.08 });
    m.specular = rng.range(0.15, 0.35);
    m.tone_noise = 0.12;
    m
}

/// Wall paint.
pub fn paint(rng: &mut Rng) -> Material {
    let mut m = Material::base(pick_colour(rng, &PAINTS, 0.08), Pattern::Plain);
    m.tone_noise = rng.range(0.03, 0.1);
    m
}

/// Moulded plastic.
pub fn plastic(rng: &mut Rng) -> Material {
    let mut m = Material::base(pick_colour(rng, &PLASTICS, 0.1), Pattern::Plain);
    m.specular = rng.range(0.1, 0.4);
    m.shininess = 40.0;
    m.tone_noise = 0.03;
    m
}

/// Metal (steel, aluminium, chrome, black powder coat).
pub fn metal(rng: &mut Rng) -> Material {
    let mut m = Material::base(pick_colour(rng, &METALS, 0.08), Pattern::Speckle { amount: 0.05 });
    m.specular = rng.range(0.3, 0.7);
    m.shininess = 60.0;
    m.gloss = rng.range(0.1, 0.4);
    m
}

/// Glazed ceramic (toilets, sinks, bathtubs).
pub fn ceramic(rng: &mut Rng) -> Material {
    let mut m = Material::base(pick_colour(rng, &CERAMICS, 0.04), Pattern::Plain);
    m.specular = rng.range(0.4, 0.7);
    m.shininess = 80.0;
    m.tone_noise = 0.02;
    m.gloss = 0.15;
    m
}

/// Stone or composite worktop.
pub fn stone(rng: &mut Rng) -> Material {
    let colour = pick_colour(rng, &STONES, 0.08);
    let pattern = if rng.chance(0.3) {
        Pattern::Blotches { scale: rng.range(0.05, 0.2), second: colour * 0.7 }
    } else {
        Pattern::Speckle { amount: rng.range(0.1, 0.3) }
    };
    let mut m = Material::base(colour, pattern);
    m.specular = rng.range(0.2, 0.5);
    m
}

/// A display: off (black, glossy: the depth sensor mostly loses it) or on (a bright picture).
pub fn screen(rng: &mut Rng, on: bool) -> Material {
    if on {
        let mut m = Material::base(Vec3::splat(0.05), Pattern::Display { scale: rng.range(0.05, 0.25) });
        m.emission = Vec3::new(rng.range(0.5, 0.9), rng.range(0.5, 0.9), rng.range(0.6, 1.0)) * rng.range(0.6, 1.2);
        m.colour = Vec3::ONE;
        m.infrared = 0.25;
        m.gloss = 0.5;
        m.specular = 0.3;
        m
    } else {
        let mut m = Material::base(Vec3::splat(rng.range(0.008, 0.03)), Pattern::Plain);
        m.specular = 0.6;
        m.shininess = 120.0;
        m.infrared = 0.1;
        m.gloss = 0.8;
        m
    }
}

/// Window glass showing a bright outside.
pub fn window_glass(rng: &mut Rng) -> Material {
    let mut m =
        Material::base(Vec3::splat(0.1), Pattern::Blotches { scale: rng.range(0.3, 1.0), second: Vec3::splat(0.6) });
    let sky = Vec3::new(rng.range(0.8, 1.0), rng.range(0.85, 1.0), rng.range(0.9, 1.1));
    m.emission = sky * rng.range(1.2, 2.2);
    m.infrared = 0.05;
    m.gloss = 1.0;
    m
}

/// Mirror: reflects a smear of the room; glossy for the sensor.
pub fn mirror(rng: &mut Rng) -> Material {
    let mut m =
        Material::base(Vec3::splat(rng.range(0.3, 0.5)), Pattern::Blotches { scale: 0.3, second: Vec3::splat(0.7) });
    m.specular = 0.8;
    m.shininess = 200.0;
    m.infrared = 0.3;
    m.gloss = 0.9;
    m
}

/// Corrugated cardboard.
pub fn cardboard(rng: &mut Rng) -> Material {
    const BOARD: [(u8, u8, u8); 4] = [(180, 140, 95), (165, 125, 85), (200, 170, 130), (225, 215, 200)];
    let mut m = Material::base(pick_colour(rng, &BOARD, 0.1), Pattern::Speckle { amount: 0.1 });
    m.tone_noise = 0.1;
    m
}

/// Carpet or rug.
pub fn carpet(rng: &mut Rng) -> Material {
    let colour = pick_colour(rng, &FABRICS, 0.2);
    let pattern = if rng.chance(0.3) {
        // Worn or mottled: a darker shade of the same colour.
        Pattern::Blotches { scale: rng.range(0.1, 0.4), second: colour * rng.range(0.7, 0.9) }
    } else {
        Pattern::Speckle { amount: rng.range(0.15, 0.35) }
    };
    let mut m = Material::base(colour, pattern);
    m.tone_noise = 0.12;
    m
}

/// Floor tiles or wall tiles, `size_range` metres square.
pub fn tiles(rng: &mut Rng, size_range: (f32, f32)) -> Material {
    let size = rng.range(size_range.0, size_range.1);
    let colour = if rng.chance(0.5) { pick_colour(rng, &CERAMICS, 0.08) } else { pick_colour(rng, &STONES, 0.1) };
    let grout_colour = colour * rng.range(0.5, 0.8);
    let mut m = Material::base(colour, Pattern::Tiles { size, grout: rng.range(0.003, 0.008), grout_colour });
    m.specular = rng.range(0.1, 0.4);
    m
}

/// Wooden floor boards.
pub fn planks(rng: &mut Rng) -> Material {
    let colour = pick_colour(rng, &WOODS, 0.15);
    let mut m = Material::base(
        colour,
        Pattern::Planks {
            width: rng.range(0.08, 0.2),
            length: rng.range(0.6, 1.8),
            dark: colour * rng.range(0.5, 0.75),
        },
    );
    m.specular = rng.range(0.05, 0.25);
    m
}

/// Book spines.
pub fn books(rng: &mut Rng) -> Material {
    let mut m = Material::base(Vec3::splat(0.5), Pattern::Spines { period: rng.range(0.02, 0.045) });
    m.tone_noise = 0.1;
    m
}

/// Leaves.
pub fn foliage(rng: &mut Rng) -> Material {
    let colour = Vec3::new(rng.range(0.02, 0.08), rng.range(0.08, 0.25), rng.range(0.02, 0.06));
    let mut m = Material::base(colour, Pattern::Blotches { scale: rng.range(0.02, 0.05), second: colour * 2.2 });
    m.tone_noise = 0.2;
    m
}

/// A lamp shade, glowing when the lamp is on.
pub fn lamp_shade(rng: &mut Rng, lit: bool) -> Material {
    let mut m = if rng.chance(0.6) { fabric(rng) } else { paper(rng) };
    if lit {
        m.emission = Vec3::new(1.0, 0.85, 0.6) * rng.range(0.4, 1.0);
    }
    m
}

/// Paper, whiteboard or printed matter.
pub fn paper(rng: &mut Rng) -> Material {
    let mut m = Material::base(pick_colour(rng, &CERAMICS, 0.05), Pattern::Speckle { amount: 0.03 });
    m.tone_noise = 0.03;
    m
}

/// Any furniture surface: a draw over the shared pools (wood, laminate, plastic, metal, fabric).
pub fn any_hard(rng: &mut Rng) -> Material {
    match rng.weighted(&[0.4, 0.3, 0.15, 0.15]) {
        0 => wood(rng),
        1 => laminate(rng),
        2 => plastic(rng),
        _ => metal(rng),
    }
}

/// Any soft surface: fabric or leather.
pub fn any_soft(rng: &mut Rng) -> Material {
    if rng.chance(0.8) {
        fabric(rng)
    } else {
        leather(rng)
    }
}
