//! What the `layout` and `detect` commands write of a room: the JSON record, the overlay edges and the
//! PLY line set.
//!
//! Layout file (`cog-gpu layout`, `<out>/<frame>.json`; `detect` puts the same record under `"layout"`):
//!
//! ```json
//! {"frame": "NAME", "layout": {"method": "manhattan" | "cubical" (either followed by "+cog" and/or "+edges") | "heuristic",
//!   "corners": [[x, y] × 4], "floor": z, "ceiling": z, "yaw_deg": d, "score": s, "hypotheses": n}}
//! ```
//! Corners are upright metres, counter-clockwise seen from above; `yaw_deg` is the direction of the first
//! edge (corner 0 → 1) from +x, in [−45°, 45°); the heuristic's score is 0.

use std::path::Path;

use glam::Vec2;
use image::RgbImage;

use super::PredictedLayout;
use crate::draw::{draw_line, project_segment, Colour};
use crate::error::{Error, Result};
use crate::frame::RoomLayout;
use crate::geometry::Camera;
use crate::limits::MAX_COORDINATE_M;
use crate::ply::LineSet;

/// Colour of the room's edges in overlays and PLY files.
pub const ROOM_COLOUR: [u8; 3] = [255, 215, 0];

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LayoutRecord {
    pub method: String,
    pub corners: Vec<[f32; 2]>,
    pub floor: f32,
    pub ceiling: f32,
    pub yaw_deg: f32,
    pub score: f64,
    pub hypotheses: usize,
}

impl LayoutRecord {
    pub fn new(method: &str, predicted: &PredictedLayout) -> LayoutRecord {
        LayoutRecord {
            method: method.to_string(),
            corners: predicted.room.corners.iter().map(|c| c.to_array()).collect(),
            floor: predicted.room.floor,
            ceiling: predicted.room.ceiling,
            yaw_deg: predicted.room_box.yaw().to_degrees(),
            score: predicted.score,
            hypotheses: predicted.hypotheses,
        }
    }

    pub fn room(&self) -> RoomLayout {
        RoomLayout {
            corners: self.corners.iter().map(|&c| Vec2::from_array(c)).collect(),
            floor: self.floor,
            ceiling: self.ceiling,
        }
    }

    /// What is wrong with a record read from a file, if anything: as for annotated rooms, every coordinate
    /// lies within ±[`MAX_COORDINATE_M`] of the camera (the free-space measure voxelises the rooms' bounding
    /// box, so a room kilometres wide would take hours and gigabytes to score).
    fn check(&self) -> std::result::Result<(), String> {
        check_room(&self.corners, self.floor, Some(self.ceiling))
    }
}

/// The rules of a predicted room read from a file (a layout file's record, the `"layout"` of a detections
/// file, whose writers before the ceiling was recorded give none): at least 3 finite corners, a finite
/// floor below the ceiling, every coordinate within ±[`MAX_COORDINATE_M`] of the camera.
pub fn check_room(corners: &[[f32; 2]], floor: f32, ceiling: Option<f32>) -> std::result::Result<(), String> {
    let values = || corners.iter().flatten().chain([&floor]).chain(ceiling.iter());
    let finite = values().all(|v| v.is_finite());
    if corners.len() < 3 || !finite || ceiling.is_some_and(|c| floor >= c) {
        return Err("layout needs a polygon of at least 3 finite corners and a finite floor below the ceiling".into());
    }
    if values().any(|v| v.abs() as f64 > MAX_COORDINATE_M) {
        return Err(format!("layout has a coordinate beyond ±{MAX_COORDINATE_M} m of the camera"));
    }
    Ok(())
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LayoutFile {
    pub frame: String,
    pub layout: LayoutRecord,
}

impl LayoutFile {
    pub fn read(path: &Path) -> Result<LayoutFile> {
        let text = crate::frame::read_text(path)?;
        let file: LayoutFile =
            serde_json::from_str(&text).map_err(|e| Error::invalid(path, format!("not a layout file: {e}")))?;
        file.layout.check().map_err(|m| Error::invalid(path, m))?;
        Ok(file)
    }

    pub fn write(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::invalid(path, e.to_string()))?;
        crate::error::write_whole(path, (text + "\n").as_bytes())
    }
}

/// Draws the room's edges (floor and ceiling polygons and the vertical corners), clipped at the near plane.
pub fn draw_room(img: &mut RgbImage, camera: &Camera, room: &RoomLayout, thickness: u32) {
    let lines = LineSet::from_prism(&room.corners, room.floor, room.ceiling, ROOM_COLOUR);
    let colour: Colour = ROOM_COLOUR;
    for e in &lines.edges {
        let (a, b) = (lines.vertices[e[0] as usize], lines.vertices[e[1] as usize]);
        if let Some((p, q)) = project_segment(camera, a, b) {
            draw_line(img, p, q, colour, thickness);
        }
    }
}

/// The room's edges as a PLY line set.
pub fn room_line_set(room: &RoomLayout) -> LineSet {
    LineSet::from_prism(&room.corners, room.floor, room.ceiling, ROOM_COLOUR)
}
