//! Raster drawing: lines, clipping, projected cuboids and bitmap text against hand-computed pixels.

use std::collections::HashSet;

use cog_gpu::draw::{
    category_colour, draw_cuboid, draw_label, draw_line, draw_text, fill_rect, label_size, place_labels, text_size,
    LabelBox, ADVANCE, CATEGORY_PALETTE, GLYPH_HEIGHT, LINE_HEIGHT,
};
use cog_gpu::geometry::{Camera, Cuboid};
use glam::{Mat3, Vec2, Vec3};
use image::RgbImage;

const RED: [u8; 3] = [255, 0, 0];

fn lit(img: &RgbImage) -> Vec<(u32, u32)> {
    img.enumerate_pixels().filter(|(_, _, p)| p.0 != [0, 0, 0]).map(|(x, y, _)| (x, y)).collect()
}

/// (min x, min y, max x, max y) of the lit pixels.
fn bounding_box(img: &RgbImage) -> (u32, u32, u32, u32) {
    let pixels = lit(img);
    assert!(!pixels.is_empty(), "nothing drawn");
    let min_x = pixels.iter().map(|p| p.0).min().unwrap();
    let min_y = pixels.iter().map(|p| p.1).min().unwrap();
    let max_x = pixels.iter().map(|p| p.0).max().unwrap();
    let max_y = pixels.iter().map(|p| p.1).max().unwrap();
    (min_x, min_y, max_x, max_y)
}

fn is_lit(img: &RgbImage, x: u32, y: u32) -> bool {
    img.get_pixel(x, y).0 != [0, 0, 0]
}

#[test]
fn axis_aligned_lines_cover_their_pixels() {
    let mut img = RgbImage::new(20, 10);
    draw_line(&mut img, Vec2::new(2.0, 3.0), Vec2::new(10.0, 3.0), RED, 1);
    let pixels = lit(&img);
    assert_eq!(pixels.len(), 9);
    assert!(pixels.iter().all(|&(x, y)| y == 3 && (2..=10).contains(&x)));

    let mut img = RgbImage::new(20, 10);
    draw_line(&mut img, Vec2::new(4.0, 8.0), Vec2::new(4.0, 1.0), RED, 1);
    assert_eq!(lit(&img).len(), 8);
    assert!(is_lit(&img, 4, 1) && is_lit(&img, 4, 8));

    // A 3×3 brush covers the rows above and below and one more column at each end.
    let mut img = RgbImage::new(20, 10);
    draw_line(&mut img, Vec2::new(2.0, 3.0), Vec2::new(10.0, 3.0), RED, 3);
    assert_eq!(lit(&img).len(), 11 * 3);
    assert_eq!(bounding_box(&img), (1, 2, 11, 4));
}

#[test]
fn diagonal_lines_have_one_pixel_per_major_step() {
    let mut img = RgbImage::new(10, 10);
    draw_line(&mut img, Vec2::new(0.0, 0.0), Vec2::new(7.0, 7.0), RED, 1);
    let pixels = lit(&img);
    assert_eq!(pixels.len(), 8);
    assert!(pixels.iter().all(|&(x, y)| x == y));

    // dx = 5, dy = 3: 6 pixels, one per column, both endpoints, in either direction.
    for (a, b) in [(Vec2::new(1.0, 1.0), Vec2::new(6.0, 4.0)), (Vec2::new(6.0, 4.0), Vec2::new(1.0, 1.0))] {
        let mut img = RgbImage::new(10, 10);
        draw_line(&mut img, a, b, RED, 1);
        let pixels = lit(&img);
        assert_eq!(pixels.len(), 6);
        assert!(is_lit(&img, 1, 1) && is_lit(&img, 6, 4));
        let columns: HashSet<u32> = pixels.iter().map(|p| p.0).collect();
        assert_eq!(columns.len(), 6);
        // Every pixel lies within half a pixel of the ideal line y = 1 + 3/5·(x − 1).
        for (x, y) in pixels {
            let ideal = 1.0 + 0.6 * (x as f32 - 1.0);
            assert!((y as f32 - ideal).abs() <= 0.5 + 1e-6, "({x}, {y})");
        }
    }
}

#[test]
fn lines_are_clipped_to_the_image() {
    let mut img = RgbImage::new(20, 10);
    draw_line(&mut img, Vec2::new(-100.0, -100.0), Vec2::new(-50.0, -10.0), RED, 1);
    draw_line(&mut img, Vec2::new(30.0, -5.0), Vec2::new(30.0, 50.0), RED, 3);
    draw_line(&mut img, Vec2::new(-1e9, 50.0), Vec2::new(1e9, 50.0), RED, 1);
    draw_line(&mut img, Vec2::new(f32::NAN, 1.0), Vec2::new(3.0, 3.0), RED, 1);
    draw_line(&mut img, Vec2::new(1.0, 1.0), Vec2::new(f32::INFINITY, 3.0), RED, 1);
    assert!(lit(&img).is_empty());

    // Partly visible: stops at the right border.
    draw_line(&mut img, Vec2::new(5.0, 5.0), Vec2::new(50.0, 5.0), RED, 1);
    let pixels = lit(&img);
    assert_eq!(pixels.len(), 15);
    assert!(is_lit(&img, 19, 5) && is_lit(&img, 5, 5) && !is_lit(&img, 4, 5));

    // A huge line through the image crosses it completely, without walking a billion steps.
    let mut img = RgbImage::new(20, 10);
    draw_line(&mut img, Vec2::new(-1e9, 2.0), Vec2::new(1e9, 2.0), RED, 1);
    assert_eq!(lit(&img).len(), 20);
}

#[test]
fn rectangles_are_clipped() {
    let mut img = RgbImage::new(10, 10);
    fill_rect(&mut img, -3, 8, 5, 5, RED);
    assert_eq!(lit(&img).len(), 2 * 2);
    assert_eq!(bounding_box(&img), (0, 8, 1, 9));
}

/// A camera at the origin looking along +y (Rtilt = I), f = 100 px, principal point at 0-based (49, 39).
fn camera() -> Camera {
    Camera::new([100.0, 100.0, 50.0, 40.0], Mat3::IDENTITY)
}

#[test]
fn cuboid_facing_the_camera_covers_its_projected_front_rectangle() {
    // Width 1.2, depth 2, height 1 at 3 m, yaw 0: the front face (y = 2 m) spans x ∈ ±0.6, z ∈ ±0.5,
    // which projects to u = 49 ± 100·0.6/2 = 19..79 and v = 39 ∓ 100·0.5/2 = 14..64. The back face (y = 4 m)
    // projects inside it. Front edges are 3 pixels wide, so the drawing spans 18..80 × 13..65 exactly.
    let mut img = RgbImage::new(100, 80);
    let cuboid = Cuboid::new(Vec3::new(0.0, 3.0, 0.0), Vec3::new(1.2, 2.0, 1.0), 0.0);
    draw_cuboid(&mut img, &camera(), &cuboid, RED);
    for (x, y) in [(19, 14), (79, 14), (19, 64), (79, 64)] {
        assert!(is_lit(&img, x, y), "front corner ({x}, {y}) not drawn");
    }
    assert_eq!(bounding_box(&img), (18, 13, 80, 65));
    // The front face's top edge is thick (rows 13..=15) ...
    assert!(is_lit(&img, 49, 13) && is_lit(&img, 49, 15));
    // ... and the back face's left edge (u = 49 − 100·0.6/4 = 34) is one pixel wide.
    assert!(is_lit(&img, 34, 39) && !is_lit(&img, 33, 39) && !is_lit(&img, 35, 39));
    // The inside of the front face stays empty apart from the back face's edges.
    assert!(!is_lit(&img, 25, 20));

    // Turned by π the same box faces away: the thick edges are now the far face's (u = 34..64).
    let mut turned = RgbImage::new(100, 80);
    draw_cuboid(&mut turned, &camera(), &Cuboid { yaw: std::f32::consts::PI, ..cuboid }, RED);
    assert!(is_lit(&turned, 35, 39) && is_lit(&turned, 33, 39));
    assert!(is_lit(&turned, 19, 39) && !is_lit(&turned, 18, 39) && !is_lit(&turned, 20, 39));
}

#[test]
fn cuboid_partly_behind_the_camera_draws_its_visible_part() {
    // Depth 2 centred 0.5 m ahead: the back face is at y = 1.5 m, the front at −0.5 m (behind the camera).
    // The back face projects to u = 49 ± 100·0.6/1.5 = 9..89, v = 39 ∓ 100·0.45/1.5 = 9..69.
    let mut img = RgbImage::new(100, 80);
    let cuboid = Cuboid::new(Vec3::new(0.0, 0.5, 0.0), Vec3::new(1.2, 2.0, 0.9), 0.0);
    draw_cuboid(&mut img, &camera(), &cuboid, RED);
    for (x, y) in [(9, 9), (89, 9), (9, 69), (89, 69)] {
        assert!(is_lit(&img, x, y), "back corner ({x}, {y}) not drawn");
    }
    // The side edges run from the back corners towards the camera and leave the image: the top-left one
    // follows the ray through (9, 9) from the principal point (49, 39), slope 3/4, and reaches column 0
    // near row 9 − 9·3/4 ≈ 2.
    assert!((0..=4).any(|y| is_lit(&img, 0, y)), "clipped side edge does not reach the border");

    // A box entirely behind the camera draws nothing.
    let mut img = RgbImage::new(100, 80);
    draw_cuboid(&mut img, &camera(), &Cuboid::new(Vec3::new(0.0, -3.0, 0.0), Vec3::ONE, 0.3), RED);
    assert!(lit(&img).is_empty());
}

#[test]
fn text_has_the_expected_extent_and_distinct_glyphs() {
    assert_eq!(text_size("Hello", 2), (5 * ADVANCE * 2, LINE_HEIGHT * 2));
    assert_eq!(text_size("ab\nlonger", 1), (6 * ADVANCE, 2 * LINE_HEIGHT));

    // 'H' fills all 5 columns and 7 rows, so "HH" at scale 2 lights (2·6 − 1)·2 columns and 7·2 rows.
    let mut img = RgbImage::new(60, 30);
    let (w, h) = draw_text(&mut img, 3, 4, "HH", RED, 2);
    assert_eq!((w, h), (2 * ADVANCE * 2, LINE_HEIGHT * 2));
    let (x0, y0, x1, y1) = bounding_box(&img);
    assert_eq!((x0, y0), (3, 4));
    assert_eq!((x1 - x0 + 1, y1 - y0 + 1), ((2 * ADVANCE - 1) * 2, GLYPH_HEIGHT * 2));

    // A space draws nothing; every printable glyph draws something, and no two glyphs are the same.
    let mut blank = RgbImage::new(8, 8);
    draw_text(&mut blank, 0, 0, " ", RED, 1);
    assert!(lit(&blank).is_empty());
    let mut seen = HashSet::new();
    for code in 33u8..=126 {
        let mut img = RgbImage::new(8, 8);
        draw_text(&mut img, 0, 0, &(code as char).to_string(), RED, 1);
        let pixels = lit(&img);
        assert!(!pixels.is_empty(), "glyph {:?} is empty", code as char);
        assert!(seen.insert(pixels), "glyph {:?} repeats another", code as char);
    }
}

#[test]
fn labels_sit_on_a_background_box() {
    let mut img = RgbImage::new(60, 30);
    let blue = [0, 0, 200];
    let (w, h) = draw_label(&mut img, 2, 2, "AP", [255, 255, 255], blue, 1);
    assert_eq!((w, h), (2 * ADVANCE + 2, LINE_HEIGHT + 2));
    assert_eq!(bounding_box(&img), (2, 2, 2 + w - 1, 2 + h - 1));
    // The padding corner keeps the background colour; the text is white on it.
    assert_eq!(img.get_pixel(2, 2).0, blue);
    assert!(img.pixels().any(|p| p.0 == [255, 255, 255]));
}

fn label(x: i64, y: i64, width: u32, height: u32) -> LabelBox {
    LabelBox { x, y, width, height }
}

/// `label_size` is the box `draw_label` paints (the extent of its pixels on a black image), and by hand the
/// text's advance and line height plus `scale` pixels of padding on every side.
#[test]
fn label_size_is_the_painted_box() {
    for (text, scale, hand) in [
        ("AP", 1, (2 * ADVANCE + 2, LINE_HEIGHT + 2)),
        ("chair 0.54", 2, (10 * ADVANCE * 2 + 4, LINE_HEIGHT * 2 + 4)),
        ("x\ny", 3, (ADVANCE * 3 + 6, 2 * LINE_HEIGHT * 3 + 6)),
    ] {
        assert_eq!(label_size(text, scale), hand, "{text} at {scale}");
        let mut img = RgbImage::new(200, 80);
        draw_label(&mut img, 3, 4, text, [255, 255, 255], [0, 0, 200], scale);
        let (x0, y0, x1, y1) = bounding_box(&img);
        assert_eq!((x0, y0, x1 - x0 + 1, y1 - y0 + 1), (3, 4, hand.0, hand.1), "{text} at {scale}");
    }
}

/// Labels already apart keep their places; labels wanted at one place stack below the first, which keeps
/// its place, each flush with the one above (hand-computed rows); none overlaps another.
#[test]
fn labels_in_each_others_way_stack_without_overlap() {
    let apart = [label(0, 0, 20, 9), label(30, 0, 20, 9), label(0, 20, 20, 9)];
    assert_eq!(place_labels(&apart, 100), apart.to_vec());

    let same = [label(10, 5, 40, 9), label(12, 5, 30, 9), label(0, 7, 60, 9)];
    let placed = place_labels(&same, 100);
    assert_eq!(placed[0], same[0], "the first (best) label keeps its place");
    // The second overlaps [5, 14): just below it (14) is 9 rows away, just above (−4) leaves the image.
    assert_eq!(placed[1], label(12, 14, 30, 9));
    // The third (wanted at 7) overlaps both: free places 23 (below the second, 16 away) and −4 (above the
    // first, outside): 23.
    assert_eq!(placed[2], label(0, 23, 60, 9));
    for (a, b) in [(0, 1), (0, 2), (1, 2)] {
        let (p, q) = (placed[a], placed[b]);
        let apart_x = p.x + p.width as i64 <= q.x || q.x + q.width as i64 <= p.x;
        let apart_y = p.y + p.height as i64 <= q.y || q.y + q.height as i64 <= p.y;
        assert!(apart_x || apart_y, "{p:?} and {q:?} overlap");
    }
}

/// A label moves to the nearer side of the one in its way (up when that is nearer), stays inside the image
/// rows, and keeps its place when there is no free place (image too short).
#[test]
fn labels_move_to_the_nearest_free_place_inside_the_image() {
    // Wanted 3 rows above the first's top: up to 50 − 9 = 41 (6 away) is nearer than down to 59 (12 away).
    let placed = place_labels(&[label(0, 50, 20, 9), label(5, 47, 20, 9)], 100);
    assert_eq!(placed[1].y, 41);
    // Near the bottom: below (95, ending at 105) would leave the 100-row image, so up (90 − 10 = 80).
    let placed = place_labels(&[label(0, 90, 20, 5), label(0, 88, 20, 10)], 100);
    assert_eq!(placed[1].y, 80);
    // A 12-row image with a 9-row label in the way: neither 9 (ends at 18) nor −9 fits; it stays.
    let placed = place_labels(&[label(0, 0, 20, 9), label(0, 2, 20, 9)], 12);
    assert_eq!(placed[1], label(0, 2, 20, 9));
    // Equally far up and down: the lower place.
    let placed = place_labels(&[label(0, 20, 20, 10), label(0, 20, 20, 10)], 100);
    assert_eq!(placed[1].y, 30);
}

#[test]
fn palette_colours_are_distinct() {
    let distinct: HashSet<[u8; 3]> = CATEGORY_PALETTE.iter().copied().collect();
    assert_eq!(distinct.len(), 19);
    assert_eq!(category_colour("bed"), CATEGORY_PALETTE[0]);
    assert_eq!(category_colour("lamp"), CATEGORY_PALETTE[18]);
    assert_eq!(category_colour("not-a-category"), [255, 255, 255]);
}

/// Shading a convex polygon blends exactly the pixels whose centres lie inside it (edges included), by hand.
#[test]
fn shading_covers_the_pixel_centres_inside_the_polygon() {
    use cog_gpu::draw::shade_convex_polygon;
    // The square [2, 6) × [1, 4): pixel centres x + ½ in 2.5..5.5, y + ½ in 1.5..3.5 → 4 × 3 = 12 pixels.
    let mut img = RgbImage::new(10, 8);
    let square = [Vec2::new(2.0, 1.0), Vec2::new(6.0, 1.0), Vec2::new(6.0, 4.0), Vec2::new(2.0, 4.0)];
    shade_convex_polygon(&mut img, &square, [200, 100, 0], 0.5);
    let shaded = lit(&img);
    assert_eq!(shaded.len(), 12);
    assert!(shaded.iter().all(|&(x, y)| (2..6).contains(&x) && (1..4).contains(&y)));
    assert_eq!(img.get_pixel(3, 2).0, [100, 50, 0], "half of the colour over black");
    // The other winding, a triangle: (0,0), (0,4), (4,0) holds the centres with x + y ≤ 3 (10 pixels: 4+3+2+1).
    let mut img = RgbImage::new(10, 8);
    shade_convex_polygon(&mut img, &[Vec2::ZERO, Vec2::new(0.0, 4.0), Vec2::new(4.0, 0.0)], RED, 1.0);
    let shaded = lit(&img);
    assert_eq!(shaded.len(), 10, "{shaded:?}");
    assert!(shaded.iter().all(|&(x, y)| x + y <= 3));
    // Off the image or degenerate: nothing.
    let mut img = RgbImage::new(10, 8);
    shade_convex_polygon(&mut img, &[Vec2::new(20.0, 20.0), Vec2::new(30.0, 20.0), Vec2::new(30.0, 30.0)], RED, 1.0);
    shade_convex_polygon(&mut img, &[Vec2::ZERO, Vec2::new(5.0, 5.0)], RED, 1.0);
    assert!(lit(&img).is_empty());
}
