//! Preview images: the RGB frame with the ground-truth cuboids drawn on it (12 edges each, the front face
//! brighter), and beside it the raw depth as a colour map (black = missing).

use glam::{Vec2, Vec3};
use image::{Rgb, RgbImage};

use crate::frame::Frame;
use crate::geometry::{Camera, MIN_PROJECT_DEPTH};

/// A turbo-like colour map for t in [0, 1] (blue near, red far).
fn colour_map(t: f32) -> [u8; 3] {
    let t = t.clamp(0.0, 1.0);
    let r = (0.1357 + t * (4.5974 - t * (42.3277 - t * (130.5887 - t * (150.5666 - t * 58.1375))))).clamp(0.0, 1.0);
    let g = (0.0914 + t * (2.1856 + t * (4.8052 - t * (14.0195 - t * (4.2109 + t * 2.7747))))).clamp(0.0, 1.0);
    let b = (0.1067 + t * (12.5925 - t * (60.1097 - t * (109.0745 - t * (88.5066 - t * 26.8183))))).clamp(0.0, 1.0);
    [(r * 255.0) as u8, (g * 255.0) as u8, (b * 255.0) as u8]
}

fn draw_line(img: &mut RgbImage, a: Vec2, b: Vec2, colour: [u8; 3], thick: bool) {
    let steps = (b - a).abs().max_element().ceil().clamp(1.0, 10_000.0) as usize;
    for k in 0..=steps {
        let p = a + (b - a) * (k as f32 / steps as f32);
        let offsets: &[(i32, i32)] = if thick { &[(0, 0), (1, 0), (0, 1), (1, 1)] } else { &[(0, 0)] };
        for (dx, dy) in offsets {
            let (x, y) = (p.x.round() as i32 + dx, p.y.round() as i32 + dy);
            if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
                img.put_pixel(x as u32, y as u32, Rgb(colour));
            }
        }
    }
}

/// Projects a 3D segment, clipping it at the camera's near plane.
fn project_segment(cam: &Camera, a: Vec3, b: Vec3) -> Option<(Vec2, Vec2)> {
    let (ca, cb) = (cam.to_camera(a), cam.to_camera(b));
    let near = MIN_PROJECT_DEPTH * 10.0;
    if ca.z < near && cb.z < near {
        return None;
    }
    let clip = |p: Vec3, q: Vec3| -> Vec3 {
        if p.z >= near {
            p
        } else {
            p + (q - p) * ((near - p.z) / (q.z - p.z))
        }
    };
    let (pa, pb) = (clip(ca, cb), clip(cb, ca));
    let [fx, fy, cx, cy] = cam.intrinsics;
    let px = |c: Vec3| Vec2::new(fx * c.x / c.z + cx - 1.0, fy * c.y / c.z + cy - 1.0);
    Some((px(pa), px(pb)))
}

/// The preview of a frame: RGB with cuboids | depth colour map.
pub fn preview(frame: &Frame) -> RgbImage {
    let (w, h) = (frame.width(), frame.height());
    let mut img = RgbImage::new(2 * w, h);
    for (x, y, p) in frame.rgb.enumerate_pixels() {
        img.put_pixel(x, y, *p);
    }
    let cam = Camera::new(frame.intrinsics(), frame.rtilt());
    for obj in &frame.objects {
        let colour = crate::draw::category_colour(&obj.category);
        let c = obj.cuboid.corners();
        const EDGES: [(usize, usize); 12] =
            [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)];
        for (i, j) in EDGES {
            // The front face is p1 p2 (bottom) and their tops: drawn thick.
            let front = matches!((i, j), (0, 1) | (4, 5) | (0, 4) | (1, 5));
            if let Some((a, b)) = project_segment(&cam, c[i], c[j]) {
                draw_line(&mut img, a, b, colour, front);
            }
        }
    }
    let far = frame.depth_mm.iter().copied().max().unwrap_or(1).max(1) as f32;
    for y in 0..h {
        for x in 0..w {
            let mm = frame.depth_mm[(y * w + x) as usize];
            let colour = if mm == 0 { [0, 0, 0] } else { colour_map(mm as f32 / far) };
            img.put_pixel(w + x, y, Rgb(colour));
        }
    }
    img
}
