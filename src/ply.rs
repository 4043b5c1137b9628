//! ASCII PLY output of a coloured point cloud with line sets (cuboid and room edges), readable by Open3D
//! (`read_point_cloud` for the points, `read_line_set` for the edges) and MeshLab:
//!
//! ```text
//! ply
//! format ascii 1.0
//! comment <free text>
//! element vertex N          (the points, then the line sets' vertices)
//! property float x / y / z  (upright metres: x right, y forward, z up)
//! property uchar red / green / blue
//! element edge M
//! property int vertex1 / vertex2   (0-based indices into the vertices)
//! property uchar red / green / blue
//! end_header
//! ```

use std::io::Write;
use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result};

/// One set of coloured segments between its own vertices.
#[derive(Clone, Debug, Default)]
pub struct LineSet {
    pub vertices: Vec<Vec3>,
    pub edges: Vec<[u32; 2]>,
    pub colour: [u8; 3],
}

impl LineSet {
    /// The 12 edges of a box given by its 8 corners in [`crate::geometry::Cuboid::corners`] order (bottom
    /// four counter-clockwise, then the top four above them).
    pub fn from_box_corners(corners: &[Vec3; 8], colour: [u8; 3]) -> LineSet {
        let mut edges = Vec::with_capacity(12);
        for i in 0..4u32 {
            edges.push([i, (i + 1) % 4]);
            edges.push([4 + i, 4 + (i + 1) % 4]);
            edges.push([i, 4 + i]);
        }
        LineSet { vertices: corners.to_vec(), edges, colour }
    }

    /// A prism's edges: the polygon at `bottom` and at `top` and the vertical edges at its corners.
    pub fn from_prism(polygon: &[glam::Vec2], bottom: f32, top: f32, colour: [u8; 3]) -> LineSet {
        let n = polygon.len() as u32;
        let mut vertices: Vec<Vec3> = polygon.iter().map(|c| c.extend(bottom)).collect();
        vertices.extend(polygon.iter().map(|c| c.extend(top)));
        let mut edges = Vec::new();
        for i in 0..n {
            edges.push([i, (i + 1) % n]);
            edges.push([n + i, n + (i + 1) % n]);
            edges.push([i, n + i]);
        }
        LineSet { vertices, edges, colour }
    }
}

/// Writes `points` (with `colours`, same length) and the line sets to `path`.
pub fn write_ply(path: &Path, comment: &str, points: &[Vec3], colours: &[[u8; 3]], lines: &[LineSet]) -> Result<()> {
    if points.len() != colours.len() {
        return Err(Error::Input(format!("{} points but {} colours", points.len(), colours.len())));
    }
    let vertex_count = points.len() + lines.iter().map(|l| l.vertices.len()).sum::<usize>();
    let edge_count: usize = lines.iter().map(|l| l.edges.len()).sum();
    // Written into memory, then put in place at once (`write_whole`): no half-written file is left.
    let mut out = Vec::new();
    let comment = comment.replace(['\n', '\r'], " ");
    let write = |out: &mut Vec<u8>| -> std::io::Result<()> {
        write!(
            out,
            "ply\nformat ascii 1.0\ncomment {comment}\nelement vertex {vertex_count}\nproperty float x\n\
             property float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
             element edge {edge_count}\nproperty int vertex1\nproperty int vertex2\nproperty uchar red\n\
             property uchar green\nproperty uchar blue\nend_header\n"
        )?;
        for (p, c) in points.iter().zip(colours) {
            writeln!(out, "{} {} {} {} {} {}", p.x, p.y, p.z, c[0], c[1], c[2])?;
        }
        for line in lines {
            for p in &line.vertices {
                let c = line.colour;
                writeln!(out, "{} {} {} {} {} {}", p.x, p.y, p.z, c[0], c[1], c[2])?;
            }
        }
        let mut first = points.len() as u32;
        for line in lines {
            let c = line.colour;
            for e in &line.edges {
                writeln!(out, "{} {} {} {} {}", first + e[0], first + e[1], c[0], c[1], c[2])?;
            }
            first += line.vertices.len() as u32;
        }
        Ok(())
    };
    write(&mut out).map_err(|e| Error::io(path, e))?;
    crate::error::write_whole(path, &out)
}
