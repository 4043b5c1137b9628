//! Small raster drawing on [`image::RgbImage`]: clipped lines with a thickness, filled and outlined
//! rectangles, projected cuboid wireframes, a per-category palette and text in an embedded 5×7 bitmap font.
//!
//! Used by the detection overlays, the precision–recall plots of `cog-gpu eval` and (later) the synthetic
//! previews. No anti-aliasing: pixels are set, never blended.
//!
//! # Coordinates
//! Pixel coordinates are 0-based, `x` to the right and `y` down, and the pixel in column `col`, row `row`
//! is centred on `(col, row)` — the convention of [`Camera::project`], so projected points can be passed
//! straight in. Everything is clipped to the image: any input (huge, negative, non-finite) draws only the
//! visible part, or nothing, and never panics.

use glam::{DVec2, Vec2, Vec3};
use image::{Rgb, RgbImage};

use crate::category::{category_index, CATEGORIES};
use crate::geometry::{Camera, Cuboid};

/// An RGB colour.
pub type Colour = [u8; 3];

pub const WHITE: Colour = [255, 255, 255];
pub const BLACK: Colour = [0, 0, 0];

/// Sets one pixel when it lies inside the image.
pub fn put_pixel(img: &mut RgbImage, x: i64, y: i64, colour: Colour) {
    if x >= 0 && y >= 0 && x < img.width() as i64 && y < img.height() as i64 {
        img.put_pixel(x as u32, y as u32, Rgb(colour));
    }
}

/// Fills the `width × height` rectangle whose top-left pixel is `(x, y)`, clipped to the image.
pub fn fill_rect(img: &mut RgbImage, x: i64, y: i64, width: u32, height: u32, colour: Colour) {
    let x0 = x.max(0);
    let y0 = y.max(0);
    let x1 = (x + width as i64).min(img.width() as i64);
    let y1 = (y + height as i64).min(img.height() as i64);
    for row in y0..y1 {
        for col in x0..x1 {
            img.put_pixel(col as u32, row as u32, Rgb(colour));
        }
    }
}

/// Blends `colour` with weight `alpha` (0–1) into every pixel whose centre `(x + ½, y + ½)` lies inside the
/// convex polygon `points` (either winding; on an edge counts as inside), clipped to the image. Used to
/// shade a detection's support surface on the overlay.
pub fn shade_convex_polygon(img: &mut RgbImage, points: &[Vec2], colour: Colour, alpha: f32) {
    if points.len() < 3 || points.iter().any(|p| !p.is_finite()) {
        return;
    }
    let lo = points.iter().fold(Vec2::splat(f32::INFINITY), |a, p| a.min(*p));
    let hi = points.iter().fold(Vec2::splat(f32::NEG_INFINITY), |a, p| a.max(*p));
    let x0 = (lo.x.floor() as i64).max(0);
    let y0 = (lo.y.floor() as i64).max(0);
    let x1 = (hi.x.ceil() as i64).min(img.width() as i64);
    let y1 = (hi.y.ceil() as i64).min(img.height() as i64);
    // Signed edge functions: inside when all have the same sign (or are zero).
    let side = |p: Vec2, a: Vec2, b: Vec2| (b - a).perp_dot(p - a);
    let alpha = alpha.clamp(0.0, 1.0);
    for y in y0..y1 {
        for x in x0..x1 {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let sides = (0..points.len()).map(|k| side(p, points[k], points[(k + 1) % points.len()]));
            let (mut negative, mut positive) = (false, false);
            for value in sides {
                negative |= value < 0.0;
                positive |= value > 0.0;
            }
            if negative && positive {
                continue;
            }
            let pixel = img.get_pixel_mut(x as u32, y as u32);
            for (channel, &c) in pixel.0.iter_mut().zip(&colour) {
                *channel = (*channel as f32 * (1.0 - alpha) + c as f32 * alpha).round() as u8;
            }
        }
    }
}

/// Outlines the `width × height` rectangle whose top-left pixel is `(x, y)` with lines `thickness` pixels
/// wide, drawn inwards (the outline stays within the rectangle).
pub fn draw_rect(img: &mut RgbImage, x: i64, y: i64, width: u32, height: u32, colour: Colour, thickness: u32) {
    let t = thickness.max(1).min(width.min(height).div_ceil(2).max(1));
    fill_rect(img, x, y, width, t, colour);
    fill_rect(img, x, y + height as i64 - t as i64, width, t, colour);
    fill_rect(img, x, y, t, height, colour);
    fill_rect(img, x + width as i64 - t as i64, y, t, height, colour);
}

/// Clips the segment `a`–`b` to the box `[lo, hi]` (Liang–Barsky, in f64 so that endpoints far outside
/// still give exact border crossings); `None` when nothing is inside.
fn clip_segment(a: DVec2, b: DVec2, lo: DVec2, hi: DVec2) -> Option<(DVec2, DVec2)> {
    if !a.is_finite() || !b.is_finite() {
        return None;
    }
    let d = b - a;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    // Each pair (p, q): the segment is inside the half-plane where p·t ≤ q.
    for (p, q) in [(-d.x, a.x - lo.x), (d.x, hi.x - a.x), (-d.y, a.y - lo.y), (d.y, hi.y - a.y)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
            if t0 > t1 {
                return None;
            }
        }
    }
    Some((a + d * t0, a + d * t1))
}

/// Draws the segment from `from` to `to` (pixel centres, see the module doc) with Bresenham's algorithm,
/// `thickness` pixels wide (a square brush of that side centred on each line pixel; 0 counts as 1).
///
/// The segment is first clipped to the image (widened by the brush) in floating point, so a line far
/// outside sets no pixel and costs nothing, and a partly visible one stops at the border. A one-pixel line
/// between integer points sets exactly `max(|dx|, |dy|) + 1` pixels, both endpoints included.
pub fn draw_line(img: &mut RgbImage, from: Vec2, to: Vec2, colour: Colour, thickness: u32) {
    let thickness = thickness.max(1);
    let margin = thickness as f64;
    let lo = DVec2::splat(-margin);
    let hi = DVec2::new(img.width() as f64 - 1.0 + margin, img.height() as f64 - 1.0 + margin);
    let Some((a, b)) = clip_segment(from.as_dvec2(), to.as_dvec2(), lo, hi) else { return };
    let (mut x, mut y) = (a.x.round() as i64, a.y.round() as i64);
    let (x1, y1) = (b.x.round() as i64, b.y.round() as i64);
    let (dx, dy) = ((x1 - x).abs(), -(y1 - y).abs());
    let (sx, sy) = (if x < x1 { 1 } else { -1 }, if y < y1 { 1 } else { -1 });
    let before = (thickness as i64 - 1) / 2;
    let mut err = dx + dy;
    loop {
        if thickness == 1 {
            put_pixel(img, x, y, colour);
        } else {
            fill_rect(img, x - before, y - before, thickness, thickness, colour);
        }
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// Cuboids

/// Segments are clipped this far (metres along the optical axis) in front of the camera before projection.
/// Larger than [`crate::geometry::MIN_PROJECT_DEPTH`] so the clipped endpoint's image stays within a few
/// hundred image widths (it is clipped to the image afterwards anyway).
pub const NEAR_PLANE: f32 = 0.01;

/// The 12 edges of [`Cuboid::corners`] (bottom p1..p4, top p1..p4).
pub const CUBOID_EDGES: [(usize, usize); 12] =
    [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)];

/// Whether an edge of [`CUBOID_EDGES`] bounds the front face (p1 p2 at the bottom and the top: the
/// cuboid's front, `-b`, see [`crate::geometry`]).
pub fn is_front_edge(edge: (usize, usize)) -> bool {
    matches!(edge, (0, 1) | (4, 5) | (0, 4) | (1, 5))
}

/// Projects the upright segment `a`–`b` to 0-based image coordinates, keeping only its part at least
/// [`NEAR_PLANE`] in front of the camera. `None` when all of it is behind.
pub fn project_segment(camera: &Camera, a: Vec3, b: Vec3) -> Option<(Vec2, Vec2)> {
    let (ca, cb) = (camera.to_camera(a), camera.to_camera(b));
    if !(ca.z >= NEAR_PLANE || cb.z >= NEAR_PLANE) {
        return None;
    }
    let clip = |p: Vec3, q: Vec3| if p.z >= NEAR_PLANE { p } else { p + (q - p) * ((NEAR_PLANE - p.z) / (q.z - p.z)) };
    let (pa, pb) = (clip(ca, cb), clip(cb, ca));
    let [fx, fy, cx, cy] = camera.intrinsics;
    // The same formula as `Camera::project` (1-based intrinsics, 0-based result).
    let image = |c: Vec3| Vec2::new(fx * c.x / c.z + cx - 1.0, fy * c.y / c.z + cy - 1.0);
    Some((image(pa), image(pb)))
}

/// Draws a cuboid's 12 edges projected through `camera`, one pixel wide, with the 4 edges of the front
/// face 3 pixels wide so the yaw (which way the object faces) is visible. Edges are clipped at the
/// camera's near plane: a box partly behind the camera draws its visible part.
pub fn draw_cuboid(img: &mut RgbImage, camera: &Camera, cuboid: &Cuboid, colour: Colour) {
    draw_cuboid_with(img, camera, cuboid, colour, 1, 3);
}

/// [`draw_cuboid`] with chosen thicknesses for the other edges and the front-face edges (for large images).
pub fn draw_cuboid_with(
    img: &mut RgbImage,
    camera: &Camera,
    cuboid: &Cuboid,
    colour: Colour,
    thickness: u32,
    front_thickness: u32,
) {
    let corners = cuboid.corners();
    // Back and side edges first, so the front face is drawn on top.
    for front in [false, true] {
        for &(i, j) in CUBOID_EDGES.iter().filter(|e| is_front_edge(**e) == front) {
            if let Some((a, b)) = project_segment(camera, corners[i], corners[j]) {
                draw_line(img, a, b, colour, if front { front_thickness } else { thickness });
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------------------
// Colours

/// One distinct colour per category of [`CATEGORIES`], in that order (Sasha Trubetskoy's list of 20
/// distinct colours without white; the synth previews use the same list).
pub const CATEGORY_PALETTE: [Colour; 19] = [
    [230, 25, 75],
    [60, 180, 75],
    [255, 225, 25],
    [0, 130, 200],
    [245, 130, 48],
    [145, 30, 180],
    [70, 240, 240],
    [240, 50, 230],
    [210, 245, 60],
    [250, 190, 212],
    [0, 128, 128],
    [220, 190, 255],
    [170, 110, 40],
    [255, 250, 200],
    [128, 0, 0],
    [170, 255, 195],
    [128, 128, 0],
    [255, 215, 180],
    [0, 0, 128],
];

// The palette has one entry per category.
const _: () = assert!(CATEGORY_PALETTE.len() == CATEGORIES.len());

/// The colour of a category by name; white for a name outside [`CATEGORIES`].
pub fn category_colour(category: &str) -> Colour {
    category_index(category).map(|i| CATEGORY_PALETTE[i]).unwrap_or(WHITE)
}

/// Black or white, whichever reads better on `background` (by its luma).
pub fn contrasting(background: Colour) -> Colour {
    let luma = 0.299 * background[0] as f32 + 0.587 * background[1] as f32 + 0.114 * background[2] as f32;
    if luma > 140.0 {
        BLACK
    } else {
        WHITE
    }
}

// ---------------------------------------------------------------------------------------------------------
// Text

/// Glyph width in font pixels.
pub const GLYPH_WIDTH: u32 = 5;
/// Glyph height in font pixels.
pub const GLYPH_HEIGHT: u32 = 7;
/// Horizontal distance between consecutive characters in font pixels (glyph + 1 column of spacing).
pub const ADVANCE: u32 = 6;
/// Vertical distance between lines in font pixels (glyph + 1 row of spacing).
pub const LINE_HEIGHT: u32 = 8;

/// The 5×7 glyphs of ASCII 32 (space) to 126 (`~`): 7 rows from the top, bit 4 of each row is the
/// leftmost column. Hand-drawn in the style of the classic HD44780 LCD font.
const FONT: [[u8; 7]; 95] = [
    [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00], // ' '
    [0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04], // '!'
    [0x0a, 0x0a, 0x0a, 0x00, 0x00, 0x00, 0x00], // '"'
    [0x0a, 0x0a, 0x1f, 0x0a, 0x1f, 0x0a, 0x0a], // '#'
    [0x04, 0x0f, 0x14, 0x0e, 0x05, 0x1e, 0x04], // '$'
    [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03], // '%'
    [0x0c, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0d], // '&'
    [0x04, 0x04, 0x04, 0x00, 0x00, 0x00, 0x00], // "'"
    [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02], // '('
    [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08], // ')'
    [0x00, 0x04, 0x15, 0x0e, 0x15, 0x04, 0x00], // '*'
    [0x00, 0x04, 0x04, 0x1f, 0x04, 0x04, 0x00], // '+'
    [0x00, 0x00, 0x00, 0x00, 0x0c, 0x04, 0x08], // ','
    [0x00, 0x00, 0x00, 0x1f, 0x00, 0x00, 0x00], // '-'
    [0x00, 0x00, 0x00, 0x00, 0x00, 0x0c, 0x0c], // '.'
    [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00], // '/'
    [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e], // '0'
    [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e], // '1'
    [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f], // '2'
    [0x1f, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0e], // '3'
    [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02], // '4'
    [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e], // '5'
    [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e], // '6'
    [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08], // '7'
    [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e], // '8'
    [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c], // '9'
    [0x00, 0x0c, 0x0c, 0x00, 0x0c, 0x0c, 0x00], // ':'
    [0x00, 0x0c, 0x0c, 0x00, 0x0c, 0x04, 0x08], // ';'
    [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02], // '<'
    [0x00, 0x00, 0x1f, 0x00, 0x1f, 0x00, 0x00], // '='
    [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08], // '>'
    [0x0e, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04], // '?'
    [0x0e, 0x11, 0x01, 0x0d, 0x15, 0x15, 0x0e], // '@'
    [0x0e, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11], // 'A'
    [0x1e, 0x11, 0x11, 0x1e, 0x11, 0x11, 0x1e], // 'B'
    [0x0e, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0e], // 'C'
    [0x1c, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1c], // 'D'
    [0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x1f], // 'E'
    [0x1f, 0x10, 0x10, 0x1e, 0x10, 0x10, 0x10], // 'F'
    [0x0e, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0f], // 'G'
    [0x11, 0x11, 0x11, 0x1f, 0x11, 0x11, 0x11], // 'H'
    [0x0e, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e], // 'I'
    [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0c], // 'J'
    [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11], // 'K'
    [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1f], // 'L'
    [0x11, 0x1b, 0x15, 0x15, 0x11, 0x11, 0x11], // 'M'
    [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11], // 'N'
    [0x0e, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e], // 'O'
    [0x1e, 0x11, 0x11, 0x1e, 0x10, 0x10, 0x10], // 'P'
    [0x0e, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0d], // 'Q'
    [0x1e, 0x11, 0x11, 0x1e, 0x14, 0x12, 0x11], // 'R'
    [0x0f, 0x10, 0x10, 0x0e, 0x01, 0x01, 0x1e], // 'S'
    [0x1f, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04], // 'T'
    [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0e], // 'U'
    [0x11, 0x11, 0x11, 0x11, 0x11, 0x0a, 0x04], // 'V'
    [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0a], // 'W'
    [0x11, 0x11, 0x0a, 0x04, 0x0a, 0x11, 0x11], // 'X'
    [0x11, 0x11, 0x11, 0x0a, 0x04, 0x04, 0x04], // 'Y'
    [0x1f, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1f], // 'Z'
    [0x0e, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0e], // '['
    [0x00, 0x10, 0x08, 0x04, 0x02, 0x01, 0x00], // '\\'
    [0x0e, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0e], // ']'
    [0x04, 0x0a, 0x11, 0x00, 0x00, 0x00, 0x00], // '^'
    [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1f], // '_'
    [0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00], // '`'
    [0x00, 0x00, 0x0e, 0x01, 0x0f, 0x11, 0x0f], // 'a'
    [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1e], // 'b'
    [0x00, 0x00, 0x0e, 0x10, 0x10, 0x11, 0x0e], // 'c'
    [0x01, 0x01, 0x0d, 0x13, 0x11, 0x11, 0x0f], // 'd'
    [0x00, 0x00, 0x0e, 0x11, 0x1f, 0x10, 0x0e], // 'e'
    [0x06, 0x09, 0x08, 0x1c, 0x08, 0x08, 0x08], // 'f'
    [0x00, 0x0f, 0x11, 0x11, 0x0f, 0x01, 0x0e], // 'g'
    [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11], // 'h'
    [0x04, 0x00, 0x0c, 0x04, 0x04, 0x04, 0x0e], // 'i'
    [0x02, 0x00, 0x06, 0x02, 0x02, 0x12, 0x0c], // 'j'
    [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12], // 'k'
    [0x0c, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0e], // 'l'
    [0x00, 0x00, 0x1a, 0x15, 0x15, 0x11, 0x11], // 'm'
    [0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11], // 'n'
    [0x00, 0x00, 0x0e, 0x11, 0x11, 0x11, 0x0e], // 'o'
    [0x00, 0x00, 0x1e, 0x11, 0x1e, 0x10, 0x10], // 'p'
    [0x00, 0x00, 0x0d, 0x13, 0x0f, 0x01, 0x01], // 'q'
    [0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10], // 'r'
    [0x00, 0x00, 0x0e, 0x10, 0x0e, 0x01, 0x1e], // 's'
    [0x08, 0x08, 0x1c, 0x08, 0x08, 0x09, 0x06], // 't'
    [0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0d], // 'u'
    [0x00, 0x00, 0x11, 0x11, 0x11, 0x0a, 0x04], // 'v'
    [0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0a], // 'w'
    [0x00, 0x00, 0x11, 0x0a, 0x04, 0x0a, 0x11], // 'x'
    [0x00, 0x00, 0x11, 0x11, 0x0f, 0x01, 0x0e], // 'y'
    [0x00, 0x00, 0x1f, 0x02, 0x04, 0x08, 0x1f], // 'z'
    [0x02, 0x04, 0x04, 0x08, 0x04, 0x04, 0x02], // '{'
    [0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04], // '|'
    [0x08, 0x04, 0x04, 0x02, 0x04, 0x04, 0x08], // '}'
    [0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00], // '~'
];

/// The glyph of a character; characters outside ASCII 32..126 are drawn as `?`.
fn glyph(c: char) -> &'static [u8; 7] {
    let code = c as u32;
    let index = if (32..=126).contains(&code) { code - 32 } else { '?' as u32 - 32 };
    &FONT[index as usize]
}

/// Size in pixels of the box [`draw_text`] lays `text` out in at `scale` (0 counts as 1): the widest line
/// is `chars × ADVANCE × scale` wide (the last column is spacing), each line `LINE_HEIGHT × scale` high.
/// Lines are split at `\n`.
pub fn text_size(text: &str, scale: u32) -> (u32, u32) {
    let scale = scale.max(1);
    let lines: Vec<&str> = text.split('\n').collect();
    let widest = lines.iter().map(|l| l.chars().count() as u32).max().unwrap_or(0);
    (widest * ADVANCE * scale, lines.len() as u32 * LINE_HEIGHT * scale)
}

/// Draws `text` with its top-left corner at `(x, y)`, each font pixel a `scale × scale` square (0 counts
/// as 1), clipped to the image. `\n` starts a new line. Returns [`text_size`].
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, colour: Colour, scale: u32) -> (u32, u32) {
    let scale = scale.max(1);
    let step = scale as i64;
    for (line_no, line) in text.split('\n').enumerate() {
        let top = y + line_no as i64 * (LINE_HEIGHT * scale) as i64;
        for (char_no, c) in line.chars().enumerate() {
            let left = x + char_no as i64 * (ADVANCE * scale) as i64;
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..GLYPH_WIDTH {
                    if bits & (1 << (GLYPH_WIDTH - 1 - col)) != 0 {
                        fill_rect(img, left + col as i64 * step, top + row as i64 * step, scale, scale, colour);
                    }
                }
            }
        }
    }
    text_size(text, scale)
}

/// A label's box on the image: top-left corner and size in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LabelBox {
    pub x: i64,
    pub y: i64,
    pub width: u32,
    pub height: u32,
}

impl LabelBox {
    fn overlaps(&self, other: &LabelBox) -> bool {
        self.x < other.x + other.width as i64
            && other.x < self.x + self.width as i64
            && self.y < other.y + other.height as i64
            && other.y < self.y + self.height as i64
    }

    fn fits_rows(&self, image_height: u32) -> bool {
        self.y >= 0 && self.y + self.height as i64 <= image_height as i64
    }
}

/// Where labels go so that none hides another: `wanted` in priority order (the first keeps its place),
/// each moved only along y, to the nearest free place inside the image rows. A label that overlaps one
/// already placed takes, of the places flush below or flush above each placed label in its column, the
/// free one nearest its wanted `y` (on a tie the lower one). A label with no free place keeps its wanted
/// place (drawn under the better ones), as does one that does not fit the rows where it is wanted.
/// Deterministic: the same boxes give the same places.
///
/// Why only along y: a label names the box whose top-left corner it sits at; a label moved sideways
/// would read as naming its neighbour, one moved up or down stays in the box's column.
pub fn place_labels(wanted: &[LabelBox], image_height: u32) -> Vec<LabelBox> {
    let mut placed: Vec<LabelBox> = Vec::with_capacity(wanted.len());
    for &label in wanted {
        let free =
            |candidate: &LabelBox| candidate.fits_rows(image_height) && placed.iter().all(|p| !p.overlaps(candidate));
        let chosen = if free(&label) || !label.fits_rows(image_height) {
            label
        } else {
            // Each free place a label can move to is flush with a placed label's bottom or top edge.
            let candidates =
                placed.iter().filter(|p| p.x < label.x + label.width as i64 && label.x < p.x + p.width as i64);
            candidates
                .flat_map(|p| [p.y + p.height as i64, p.y - label.height as i64])
                .map(|y| LabelBox { y, ..label })
                .filter(|c| free(c))
                .min_by_key(|c| ((c.y - label.y).abs(), std::cmp::Reverse(c.y)))
                .unwrap_or(label)
        };
        placed.push(chosen);
    }
    placed
}

/// Size in pixels of the box [`draw_label`] draws for `text` at `scale` (0 counts as 1): the text's
/// [`text_size`] plus `scale` pixels of padding on every side.
pub fn label_size(text: &str, scale: u32) -> (u32, u32) {
    let scale = scale.max(1);
    let (w, h) = text_size(text, scale);
    (w + 2 * scale, h + 2 * scale)
}

/// Draws `text` on a filled `background` box for legibility: the box is the text's [`text_size`] plus
/// `scale` pixels of padding on every side, with its top-left corner at `(x, y)`. Returns the box size.
pub fn draw_label(
    img: &mut RgbImage,
    x: i64,
    y: i64,
    text: &str,
    colour: Colour,
    background: Colour,
    scale: u32,
) -> (u32, u32) {
    let scale = scale.max(1);
    let (box_w, box_h) = label_size(text, scale);
    fill_rect(img, x, y, box_w, box_h, background);
    draw_text(img, x + scale as i64, y + scale as i64, text, colour, scale);
    (box_w, box_h)
}
