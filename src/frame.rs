//! RGB-D frames in the SUN RGB-D directory layout: reading, writing, and the gravity-aligned point cloud.
//!
//! # The layout of one frame directory
//! ```text
//! FRAME/
//!   image/<name>.jpg|png        RGB, 8 bits per channel
//!   depth/<name>.png            raw depth, 16-bit grey (see below)
//!   depth_bfx/<name>.png        filled depth (optional; read with DepthSource::Filled)
//!   intrinsics.txt              K, 3×3 row-major, whitespace separated
//!   extrinsics/<stamp>.txt      3×4 [E | 0], row-major; the last file by name is used
//!   scene.txt                   scene type (optional)
//!   annotation3Dfinal/index.json   3D boxes (optional)
//!   annotation3Dlayout/index.json  room polygon (optional)
//! ```
//!
//! # Conventions (the SUN RGB-D toolbox's `read3dPoints`)
//! * A depth PNG value `d` holds millimetres rotated left by 3 bits: `mm = ((d >> 3) | (d << 13)) & 0xffff`.
//!   0 means missing; metres = mm / 1000, clamped at 8 m.
//! * Pixel coordinates are 1-based: the pixel in column `col`, row `row` (0-based in memory) has
//!   `u = col + 1`, `v = row + 1`, and the camera point is `x = (u − cx)·z/fx`, `y = (v − cy)·z/fy`, `z`.
//! * `Rtilt = P·E·Pᵀ` with `P = [[1,0,0],[0,0,1],[0,−1,0]]`, and the upright point is `Rtilt·(x, z, −y)`:
//!   x right, y forward, z up.
//! * Annotation polygons are in E's frame (Y down): upright `(x, y) = (X, Z)`, and the box spans
//!   `z ∈ [−Ymax, −Ymin]`. Names may be `class:label`; null objects are skipped, and so are the room
//!   structure names (wall, floor, ceiling).
//! * The layout file's object named `room` is the room polygon; floor at `−Ymax`, ceiling at `−Ymin`.

use std::fs;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3, Mat3, Vec2, Vec3};
use serde_json::{json, Value};

use crate::category::{normalise_name, STRUCTURE_NAMES};
use crate::error::{Error, Result};
use crate::geometry::{polygon_problem, Cuboid};
use crate::limits::{
    MAX_COORDINATE_M, MAX_FOCAL_PER_SIZE, MAX_OBJECT_SIZE_M, MAX_PIXELS, MIN_FOCAL_PER_SIZE, PRINCIPAL_POINT_MARGIN,
};

/// Depth beyond this many metres is clamped to it (the toolbox's convention).
pub const MAX_DEPTH_M: f32 = 8.0;

/// `P` of `Rtilt = P·E·Pᵀ`: swaps the camera's (x, y down, z forward) for (x, z, −y).
pub fn axis_swap() -> DMat3 {
    // glam matrices are built from columns.
    DMat3::from_cols(DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 0.0, -1.0), DVec3::new(0.0, 1.0, 0.0))
}

/// Decodes one stored depth PNG value into millimetres (undoes the 3-bit left rotation).
pub fn decode_depth_value(stored: u16) -> u16 {
    stored.rotate_right(3)
}

/// Encodes millimetres into the stored depth PNG value (rotate left by 3 bits).
pub fn encode_depth_value(mm: u16) -> u16 {
    mm.rotate_left(3)
}

/// Metres of a decoded millimetre value, clamped at [`MAX_DEPTH_M`]; 0 stays 0 (missing).
pub fn depth_metres(mm: u16) -> f32 {
    (mm as f32 / 1000.0).min(MAX_DEPTH_M)
}

/// Which depth image of a frame to read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DepthSource {
    /// `depth/`: the sensor's raw depth, with holes.
    #[default]
    Raw,
    /// `depth_bfx/`: the toolbox's filled depth.
    Filled,
}

impl DepthSource {
    pub fn dir_name(self) -> &'static str {
        match self {
            DepthSource::Raw => "depth",
            DepthSource::Filled => "depth_bfx",
        }
    }
}

/// One annotated object: a category (normalised class name), its optional label and its cuboid.
#[derive(Clone, Debug, PartialEq)]
pub struct Object {
    pub category: String,
    pub label: Option<String>,
    pub cuboid: Cuboid,
}

/// The room layout: a floor polygon (upright x, y) between floor and ceiling heights.
#[derive(Clone, Debug, PartialEq)]
pub struct RoomLayout {
    pub corners: Vec<Vec2>,
    pub floor: f32,
    pub ceiling: f32,
}

impl RoomLayout {
    /// Whether the ground-plane point lies inside the room polygon (even-odd rule; the polygon may be
    /// non-convex, as real annotations are).
    pub fn contains_xy(&self, p: Vec2) -> bool {
        crate::geometry::polygon_contains(&self.corners, p)
    }

    /// Whether the point is inside the polygon and between floor and ceiling (inclusive).
    pub fn contains(&self, p: Vec3) -> bool {
        p.z >= self.floor && p.z <= self.ceiling && self.contains_xy(p.truncate())
    }
}

/// One RGB-D frame as stored on disk.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Directory name of the frame (its identity in a dataset).
    pub name: String,
    /// RGB image.
    pub rgb: image::RgbImage,
    /// Decoded depth in millimetres, row-major, `width × height`, 0 = missing (not yet clamped at 8 m).
    pub depth_mm: Vec<u16>,
    /// K, row-major, in the 1-based pixel convention.
    pub k: [[f64; 3]; 3],
    /// E, the 3×3 rotation of the extrinsics file (row-major).
    pub extrinsics: [[f64; 3]; 3],
    pub scene: Option<String>,
    pub objects: Vec<Object>,
    pub layout: Option<RoomLayout>,
}

/// The gravity-aligned point cloud of a frame: one entry per pixel with valid depth, in row-major pixel
/// order.
#[derive(Clone, Debug, Default)]
pub struct PointCloud {
    /// Upright points (metres).
    pub points: Vec<Vec3>,
    /// (column, row) of each point's pixel, 0-based.
    pub pixels: Vec<[u32; 2]>,
    /// RGB colour of each point's pixel.
    pub colours: Vec<[u8; 3]>,
}

impl PointCloud {
    pub fn len(&self) -> usize {
        self.points.len()
    }
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
    /// The `q`-quantile of the points' heights (z), linearly interpolated between order statistics as
    /// numpy's default does (`None` when empty). The paper's layout section estimates the floor and the
    /// ceiling as the 0.001 and 0.999 quantiles.
    pub fn height_quantile(&self, q: f32) -> Option<f32> {
        let mut heights: Vec<f32> = self.points.iter().map(|p| p.z).collect();
        quantile_of_unsorted(&mut heights, q)
    }

    /// Component-wise minimum and maximum of the points (`None` when empty).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let first = *self.points.first()?;
        Some(self.points.iter().fold((first, first), |(lo, hi), p| (lo.min(*p), hi.max(*p))))
    }
}

/// The upper median of `values` (element `n/2` in ascending order: an order statistic, never an
/// interpolation); reorders `values`. `None` when empty.
pub fn upper_median(values: &mut [f32]) -> Option<f32> {
    values.sort_by(f32::total_cmp);
    values.get(values.len() / 2).copied()
}

/// The `q`-quantile (0 ≤ q ≤ 1) of `values` with linear interpolation between order statistics
/// (numpy's default); reorders `values`. `None` when empty.
pub fn quantile_of_unsorted(values: &mut [f32], q: f32) -> Option<f32> {
    if values.is_empty() {
        return None;
    }
    values.sort_unstable_by(f32::total_cmp);
    let position = q.clamp(0.0, 1.0) as f64 * (values.len() - 1) as f64;
    let below = position.floor() as usize;
    let above = (below + 1).min(values.len() - 1);
    let t = (position - below as f64) as f32;
    Some(values[below] + (values[above] - values[below]) * t)
}

fn to_dmat3(rows: &[[f64; 3]; 3]) -> DMat3 {
    DMat3::from_cols_array_2d(rows).transpose()
}

fn to_rows(m: DMat3) -> [[f64; 3]; 3] {
    m.transpose().to_cols_array_2d()
}

impl Frame {
    pub fn width(&self) -> u32 {
        self.rgb.width()
    }
    pub fn height(&self) -> u32 {
        self.rgb.height()
    }

    /// `Rtilt = P·E·Pᵀ` (double precision).
    pub fn rtilt_f64(&self) -> DMat3 {
        let p = axis_swap();
        p * to_dmat3(&self.extrinsics) * p.transpose()
    }

    /// `Rtilt` in single precision, as the kernels use it.
    pub fn rtilt(&self) -> Mat3 {
        self.rtilt_f64().as_mat3()
    }

    /// Sets E from a wanted Rtilt (`E = Pᵀ·Rtilt·P`).
    pub fn set_rtilt(&mut self, rtilt: DMat3) {
        let p = axis_swap();
        self.extrinsics = to_rows(p.transpose() * rtilt * p);
    }

    /// (fx, fy, cx, cy) in the 1-based pixel convention.
    pub fn intrinsics(&self) -> [f32; 4] {
        [self.k[0][0] as f32, self.k[1][1] as f32, self.k[0][2] as f32, self.k[1][2] as f32]
    }

    /// Number of pixels with depth.
    pub fn valid_depth(&self) -> usize {
        self.depth_mm.iter().filter(|&&d| d > 0).count()
    }

    /// The upright point of pixel (`col`, `row`) (0-based; the toolbox's pixel centres are 1-based) at
    /// camera depth `z` metres, in double precision: `Rtilt · (x, z, −y)` with `x = (col + 1 − cx)·z / fx`,
    /// `y = (row + 1 − cy)·z / fy`. At `z = 1` it is the pixel's upright ray direction, bit for bit the
    /// point at depth 1 (multiplying by 1 is exact).
    pub fn upright_point(&self, rtilt: &DMat3, col: u32, row: u32, z: f64) -> DVec3 {
        let (fx, fy, cx, cy) = (self.k[0][0], self.k[1][1], self.k[0][2], self.k[1][2]);
        let x = ((col + 1) as f64 - cx) * z / fx;
        let y = ((row + 1) as f64 - cy) * z / fy;
        *rtilt * DVec3::new(x, z, -y)
    }

    /// The gravity-aligned point cloud (see the module doc for the conventions). Computed in double
    /// precision and rounded once to f32, so it is the reference the f32 GPU kernel is compared with.
    pub fn point_cloud(&self) -> PointCloud {
        let (w, h) = (self.width(), self.height());
        let rtilt = self.rtilt_f64();
        let mut cloud = PointCloud::default();
        for row in 0..h {
            for col in 0..w {
                let mm = self.depth_mm[(row * w + col) as usize];
                if mm == 0 {
                    continue;
                }
                let z = (mm as f64 / 1000.0).min(MAX_DEPTH_M as f64);
                cloud.points.push(self.upright_point(&rtilt, col, row, z).as_vec3());
                cloud.pixels.push([col, row]);
                cloud.colours.push(self.rgb.get_pixel(col, row).0);
            }
        }
        cloud
    }

    /// Reads a frame directory with the toolbox's conventions.
    pub fn read(dir: impl AsRef<Path>, depth: DepthSource) -> Result<Frame> {
        read_frame(dir.as_ref(), depth)
    }

    /// Writes the frame in the SUN RGB-D layout (RGB as PNG, depth into `depth/`).
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<()> {
        write_frame(dir.as_ref(), self)
    }
}

// ---------------------------------------------------------------------------------------------------------
// Reading

/// Reads a UTF-8 text file; a leading byte-order mark (which Windows editors write) is dropped.
pub fn read_text(path: &Path) -> Result<String> {
    let text = fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// Parses whitespace-separated finite numbers; names the file and the offending token on error.
fn parse_numbers(path: &Path, text: &str) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|tok| {
            let v: f64 = tok.parse().map_err(|_| Error::invalid(path, format!("'{tok}' is not a number")))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(Error::invalid(path, format!("non-finite value '{tok}'")))
            }
        })
        .collect()
}

fn read_intrinsics(path: &Path) -> Result<[[f64; 3]; 3]> {
    let v = parse_numbers(path, &read_text(path)?)?;
    if v.len() != 9 {
        return Err(Error::invalid(path, format!("expected 9 numbers (3×3 K), found {}", v.len())));
    }
    let k = [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]];
    if !(k[0][0] > 0.0 && k[1][1] > 0.0) {
        return Err(Error::invalid(path, format!("focal lengths must be positive, got fx={} fy={}", k[0][0], k[1][1])));
    }
    if k[1][0] != 0.0 || k[2][0] != 0.0 || k[2][1] != 0.0 || (k[2][2] - 1.0).abs() > 1e-9 {
        return Err(Error::invalid(path, "K must be upper triangular with K[2][2] = 1"));
    }
    Ok(k)
}

/// Checks that K is plausible for a `width`×`height` image (see [`crate::limits`]): focal lengths within
/// [`MIN_FOCAL_PER_SIZE`]…[`MAX_FOCAL_PER_SIZE`] × the larger side, the principal point within
/// [`PRINCIPAL_POINT_MARGIN`] × the size of the image, and no skew (the toolbox's back-projection, and so
/// every point cloud here, ignores it: a K with skew would silently give wrong points).
pub fn check_intrinsics(path: &Path, k: &[[f64; 3]; 3], width: u32, height: u32) -> Result<()> {
    let side = width.max(height) as f64;
    let (lo, hi) = (MIN_FOCAL_PER_SIZE * side, MAX_FOCAL_PER_SIZE * side);
    for (name, f) in [("fx", k[0][0]), ("fy", k[1][1])] {
        if !(lo..=hi).contains(&f) {
            return Err(Error::invalid(
                path,
                format!(
                    "{name} = {f} is implausible for a {width}×{height} image (allowed {lo:.1} to {hi:.1} pixels: \
                     {MIN_FOCAL_PER_SIZE} to {MAX_FOCAL_PER_SIZE} × the larger side)"
                ),
            ));
        }
    }
    for (name, c, size) in [("cx", k[0][2], width as f64), ("cy", k[1][2], height as f64)] {
        let margin = PRINCIPAL_POINT_MARGIN * size;
        if !(-margin..=size + 1.0 + margin).contains(&c) {
            return Err(Error::invalid(
                path,
                format!(
                    "{name} = {c} lies far outside the {width}×{height} image (allowed {:.1} to {:.1})",
                    -margin,
                    size + 1.0 + margin
                ),
            ));
        }
    }
    if k[0][1] != 0.0 {
        return Err(Error::invalid(
            path,
            format!("K[0][1] (skew) = {} is not supported: the point cloud assumes square pixel axes", k[0][1]),
        ));
    }
    Ok(())
}

/// The last `*.txt` file by name in `extrinsics/` (SUN RGB-D names them by time stamp; an editor's backup
/// `…txt~` or another file beside them is not one).
fn extrinsics_file(dir: &Path) -> Result<PathBuf> {
    let ext_dir = dir.join("extrinsics");
    let entries = fs::read_dir(&ext_dir).map_err(|e| Error::io(&ext_dir, e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|x| x == "txt"))
        .collect();
    files.sort();
    files.pop().ok_or_else(|| Error::missing(&ext_dir, "no extrinsics file (<stamp>.txt)"))
}

fn read_extrinsics(path: &Path) -> Result<[[f64; 3]; 3]> {
    let v = parse_numbers(path, &read_text(path)?)?;
    let rows: [[f64; 3]; 3] = match v.len() {
        12 => {
            // SUN RGB-D's extrinsics are a rotation with a zero translation column; the points are read
            // in the camera's frame, so a translation would be dropped without a word.
            let translation = [v[3], v[7], v[11]];
            if translation.iter().any(|t| t.abs() > 1e-6) {
                return Err(Error::invalid(
                    path,
                    format!("the 4th column {translation:?} is not 0: cog-gpu reads [E | 0] (SUN RGB-D's), a rotation alone"),
                ));
            }
            [[v[0], v[1], v[2]], [v[4], v[5], v[6]], [v[8], v[9], v[10]]]
        }
        9 => [[v[0], v[1], v[2]], [v[3], v[4], v[5]], [v[6], v[7], v[8]]],
        n => return Err(Error::invalid(path, format!("expected a 3×4 (or 3×3) matrix, found {n} numbers"))),
    };
    let e = to_dmat3(&rows);
    let orthogonality =
        (e * e.transpose() - DMat3::IDENTITY).to_cols_array().iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if orthogonality > 1e-3 || (e.determinant() - 1.0).abs() > 1e-3 {
        return Err(Error::invalid(
            path,
            format!("the 3×3 block is not a rotation (|E·Eᵀ − I| = {orthogonality:.2e}, det = {:.4})", e.determinant()),
        ));
    }
    Ok(rows)
}

/// The single image file in `dir/sub/` (jpg or png), by name order.
fn single_image(dir: &Path, sub: &str) -> Result<PathBuf> {
    let d = dir.join(sub);
    let entries = fs::read_dir(&d).map_err(|e| Error::io(&d, e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            matches!(
                p.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref(),
                Some("jpg" | "jpeg" | "png")
            )
        })
        .collect();
    files.sort();
    match files.len() {
        0 => Err(Error::missing(&d, "no .jpg or .png image")),
        1 => Ok(files.remove(0)),
        n => Err(Error::invalid(&d, format!("expected one image, found {n}"))),
    }
}

/// Decodes an image strictly: its size is checked against [`MAX_PIXELS`] before any pixel is decoded,
/// and a JPEG must be whole — end with its end-of-image marker, and hold the data of every row
/// ([`jpeg_runs_out`]): the decoder fills a truncated JPEG with grey and reports no error.
fn open_image(path: &Path) -> Result<image::DynamicImage> {
    let image_error = |e| Error::Image { path: path.to_path_buf(), source: e };
    let reader = image::ImageReader::open(path)
        .map_err(|e| Error::io(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?;
    let format = reader.format();
    let decoder = reader.into_decoder().map_err(image_error)?;
    let (w, h) = image::ImageDecoder::dimensions(&decoder);
    if w == 0 || h == 0 || w as u64 * h as u64 > MAX_PIXELS {
        return Err(Error::invalid(
            path,
            format!("the image is {w}×{h} pixels; cog-gpu reads images of 1 to {MAX_PIXELS} pixels"),
        ));
    }
    if format == Some(image::ImageFormat::Jpeg) {
        let bytes = fs::read(path).map_err(|e| Error::io(path, e))?;
        if !jpeg_is_complete(&bytes) {
            return Err(Error::invalid(path, "truncated JPEG: the file ends before its end-of-image marker"));
        }
        if let Some(why) = jpeg_runs_out(&bytes) {
            return Err(Error::invalid(path, format!("truncated JPEG: its image data runs out {why}")));
        }
    }
    image::DynamicImage::from_decoder(decoder).map_err(image_error)
}

/// Whether a JPEG file ends with the end-of-image marker `FF D9` (trailing padding allowed).
fn jpeg_is_complete(bytes: &[u8]) -> bool {
    bytes[..jpeg_data_end(bytes)].ends_with(&[0xFF, 0xD9])
}

/// Where a JPEG's data ends: before any trailing padding — zero bytes and ASCII white space (a file saved
/// by a tool that appends a newline is whole; decoders stop at the end-of-image marker and ignore them).
fn jpeg_data_end(bytes: &[u8]) -> usize {
    bytes.iter().rposition(|&b| b != 0 && !b.is_ascii_whitespace()).map_or(0, |i| i + 1)
}

/// Why a JPEG's entropy-coded data runs out before its last rows, if it does. A file cut short with an
/// end-of-image marker after the cut passes [`jpeg_is_complete`], and JPEG decoders (zune-jpeg, which
/// `image` uses, in its strict mode too; libjpeg's and jpeg-decoder's likewise) read the bits missing before
/// a marker as zeros, without an error. So the file is decoded twice by zune-jpeg, as it is and with
/// [`JPEG_FILLER`] bytes put before its final marker: a whole file's decoder stops after its last block and
/// never reads them, so both give the same pixels; a truncated file's decoder reads them in place of the
/// zeros, and the pixels differ. Two extra decodes per JPEG read, about 5 ms for a 730×530 frame (the synthetic frames
/// are PNGs, unaffected). A file zune-jpeg cannot decode at all is left to `image`'s decoder, which reports it.
fn jpeg_runs_out(bytes: &[u8]) -> Option<String> {
    let decode = |data: &[u8]| {
        let options = zune_core::options::DecoderOptions::default()
            .jpeg_set_out_colorspace(zune_core::colorspace::ColorSpace::RGB)
            .set_strict_mode(false);
        zune_jpeg::JpegDecoder::new_with_options(zune_core::bytestream::ZCursor::new(data), options).decode().ok()
    };
    let marker = jpeg_data_end(bytes).checked_sub(2)?;
    let mut filled = Vec::with_capacity(bytes.len() + JPEG_FILLER.len());
    filled.extend_from_slice(&bytes[..marker]);
    filled.extend_from_slice(&JPEG_FILLER);
    filled.extend_from_slice(&bytes[marker..]);
    let (as_is, with_filler) = (decode(bytes)?, decode(&filled)?);
    if as_is == with_filler {
        return None;
    }
    let first = as_is.iter().zip(&with_filler).position(|(a, b)| a != b).unwrap_or(0);
    let through = 100.0 * first as f64 / as_is.len().max(1) as f64;
    Some(format!("about {through:.0} % of the way through the image"))
}

/// Bytes that [`jpeg_runs_out`] puts before a JPEG's final marker: no `0xFF` (which would start a marker),
/// and ones and zeros mixed, so that Huffman codes read from them differ from codes read from zeros.
const JPEG_FILLER: [u8; 64] = [0x5A; 64];

/// The frame's colour picture as 8-bit RGB. Colour and 8-bit grey images convert as `image` converts them
/// (16-bit colour scaled to 8 bits, grey copied to the three channels); a 16-bit grey image is refused:
/// it is the frame's depth map put where its picture belongs (SUN RGB-D's depth PNGs are 16-bit grey),
/// and read as a picture it gave gradients of the depth's bit pattern, without an error.
fn colour_image(path: &Path, image: image::DynamicImage) -> Result<image::RgbImage> {
    use image::ColorType::{La16, L16};
    if matches!(image.color(), L16 | La16) {
        return Err(Error::invalid(
            path,
            "is a 16-bit grey image (a depth map?), where the frame's colour picture belongs: image/ takes an \
             RGB (or 8-bit grey) JPEG or PNG, depth/ the 16-bit depth PNG",
        ));
    }
    Ok(image.to_rgb8())
}

/// Reads a depth PNG (16-bit grey, the toolbox's encoding) into decoded millimetres.
pub fn read_depth_png(path: &Path) -> Result<(u32, u32, Vec<u16>)> {
    let img = open_image(path)?;
    let (w, h) = (img.width(), img.height());
    match img {
        image::DynamicImage::ImageLuma16(buf) => {
            Ok((w, h, buf.into_raw().into_iter().map(decode_depth_value).collect()))
        }
        other => Err(Error::invalid(path, format!("depth must be a 16-bit grey PNG, found {:?}", other.color()))),
    }
}

/// Writes `img` as a PNG at `path`: encoded in memory, then put in place by
/// [`crate::error::write_whole`], so that a failed write (a full disk) is an error naming the file and
/// leaves no truncated picture — `image`'s own `save` writes through a buffer whose last flush error it
/// drops, leaving a truncated file and no error.
pub fn write_png<P>(img: &image::ImageBuffer<P, Vec<P::Subpixel>>, path: &Path) -> Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| Error::invalid(path, format!("cannot encode the PNG: {e}")))?;
    crate::error::write_whole(path, &bytes.into_inner())
}

/// Writes decoded millimetres as a depth PNG with the toolbox's encoding.
pub fn write_depth_png(path: &Path, width: u32, height: u32, depth_mm: &[u16]) -> Result<()> {
    let stored: Vec<u16> = depth_mm.iter().map(|&d| encode_depth_value(d)).collect();
    let buf = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(width, height, stored)
        .ok_or_else(|| Error::invalid(path, format!("depth buffer does not hold {width}×{height} values")))?;
    write_png(&buf, path)
}

fn read_json(path: &Path) -> Result<Value> {
    serde_json::from_str(&read_text(path)?).map_err(|e| Error::invalid(path, format!("malformed JSON: {e}")))
}

/// One SUN RGB-D annotation polygon: corners (X, Z) and the vertical range (Ymin, Ymax) in E's frame.
struct Polygon {
    xs: Vec<f64>,
    zs: Vec<f64>,
    y_min: f64,
    y_max: f64,
}

impl Polygon {
    /// Why the polygon cannot be used (corners beyond ±[`MAX_COORDINATE_M`], zero area, crossing edges,
    /// see [`polygon_problem`]), or `None`.
    fn problem(&self) -> Option<String> {
        let coordinates = self.xs.iter().chain(&self.zs).chain([&self.y_min, &self.y_max]);
        if coordinates.into_iter().any(|v| v.abs() > MAX_COORDINATE_M) {
            return Some(format!("has a coordinate beyond ±{MAX_COORDINATE_M} m"));
        }
        let corners: Vec<Vec2> = self.xs.iter().zip(&self.zs).map(|(&x, &z)| Vec2::new(x as f32, z as f32)).collect();
        polygon_problem(&corners).map(str::to_string)
    }
}

fn number_array(path: &Path, v: &Value, what: &str) -> Result<Vec<f64>> {
    let arr = v.as_array().ok_or_else(|| Error::invalid(path, format!("{what} must be an array of numbers")))?;
    arr.iter()
        .map(|x| {
            x.as_f64()
                .filter(|f| f.is_finite())
                .ok_or_else(|| Error::invalid(path, format!("{what} holds a non-number or non-finite value: {x}")))
        })
        .collect()
}

fn parse_polygon(path: &Path, obj: &Value, what: &str) -> Result<Option<Polygon>> {
    let Some(polys) = obj.get("polygon") else {
        return Err(Error::invalid(path, format!("{what} has no 'polygon'")));
    };
    let polys = polys.as_array().ok_or_else(|| Error::invalid(path, format!("{what}: 'polygon' must be an array")))?;
    let Some(poly) = polys.first() else { return Ok(None) };
    let field =
        |name: &str| poly.get(name).ok_or_else(|| Error::invalid(path, format!("{what}: polygon has no '{name}'")));
    let xs = number_array(path, field("X")?, &format!("{what}: X"))?;
    let zs = number_array(path, field("Z")?, &format!("{what}: Z"))?;
    if xs.len() != zs.len() {
        return Err(Error::invalid(path, format!("{what}: X has {} values but Z has {}", xs.len(), zs.len())));
    }
    let scalar = |name: &str| -> Result<f64> {
        field(name)?
            .as_f64()
            .filter(|f| f.is_finite())
            .ok_or_else(|| Error::invalid(path, format!("{what}: '{name}' must be a finite number")))
    };
    let (y_min, y_max) = (scalar("Ymin")?, scalar("Ymax")?);
    if y_min > y_max {
        return Err(Error::invalid(path, format!("{what}: Ymin {y_min} > Ymax {y_max}")));
    }
    Ok(Some(Polygon { xs, zs, y_min, y_max }))
}

fn objects_array<'a>(path: &Path, root: &'a Value) -> Result<&'a Vec<Value>> {
    root.get("objects")
        .and_then(Value::as_array)
        .ok_or_else(|| Error::invalid(path, "expected an object with an 'objects' array"))
}

/// Reads `annotation3Dfinal/index.json` into objects. Null entries, room structure and entries without a
/// polygon are skipped; a polygon that is not a 4-corner footprint, or is degenerate, is skipped with a
/// warning (the real dataset has a few); a file of the wrong shape is an error.
pub fn read_objects(path: &Path) -> Result<Vec<Object>> {
    Ok(read_positioned_objects(path)?.into_iter().map(|(_, object)| object).collect())
}

/// [`read_objects`] with each object's position in the file's `objects` array (which counts the entries
/// it skips), so that a report can name the entry a user finds in the file.
pub fn read_positioned_objects(path: &Path) -> Result<PositionedObjects> {
    let root = read_json(path)?;
    let mut objects = Vec::new();
    for (i, entry) in objects_array(path, &root)?.iter().enumerate() {
        if entry.is_null() {
            continue;
        }
        let what = format!("objects[{i}]");
        let name = entry
            .get("name")
            .and_then(Value::as_str)
            .ok_or_else(|| Error::invalid(path, format!("{what} has no string 'name'")))?;
        let (category, label) = normalise_name(name);
        if STRUCTURE_NAMES.contains(&category.as_str()) {
            continue;
        }
        if category.is_empty() {
            log::warn!("{}: {what} has an empty name; skipped", path.display());
            continue;
        }
        let Some(poly) = parse_polygon(path, entry, &what)? else { continue };
        if poly.xs.len() != 4 {
            log::warn!("{}: {what} ('{name}') has {} corners, not 4; skipped", path.display(), poly.xs.len());
            continue;
        }
        if let Some(problem) = poly.problem() {
            log::warn!("{}: {what} ('{name}'): its footprint {problem}; skipped", path.display());
            continue;
        }
        let corners = [0, 1, 2, 3].map(|j| Vec2::new(poly.xs[j] as f32, poly.zs[j] as f32));
        match Cuboid::from_polygon(corners, -poly.y_max as f32, -poly.y_min as f32) {
            Some(cuboid) if cuboid.size.max_element() <= MAX_OBJECT_SIZE_M => {
                objects.push((i, Object { category, label, cuboid }))
            }
            Some(cuboid) => log::warn!(
                "{}: {what} ('{name}') is {:?} m, larger than {MAX_OBJECT_SIZE_M} m on a side; skipped",
                path.display(),
                cuboid.size.to_array()
            ),
            None => log::warn!("{}: {what} ('{name}') is a degenerate box; skipped", path.display()),
        }
    }
    Ok(objects)
}

/// Reads `annotation3Dlayout/index.json`: the object named `room`.
pub fn read_layout(path: &Path) -> Result<Option<RoomLayout>> {
    let root = read_json(path)?;
    let objects = objects_array(path, &root)?;
    let is_room = |e: &Value| !e.is_null() && e.get("name").and_then(Value::as_str) == Some("room");
    for (i, entry) in objects.iter().enumerate() {
        if !is_room(entry) {
            continue;
        }
        let Some(poly) = parse_polygon(path, entry, &format!("objects[{i}]"))? else { continue };
        if poly.xs.len() < 3 {
            return Err(Error::invalid(path, format!("room polygon has {} corners (needs ≥ 3)", poly.xs.len())));
        }
        if let Some(problem) = poly.problem() {
            log::warn!("{}: objects[{i}] (room): the room polygon {problem}; the layout is skipped", path.display());
            return Ok(None);
        }
        let corners = poly.xs.iter().zip(&poly.zs).map(|(&x, &z)| Vec2::new(x as f32, z as f32)).collect();
        let rooms = objects.iter().filter(|e| is_room(e)).count();
        if rooms > 1 {
            log::warn!("{}: {rooms} objects named 'room'; the first, objects[{i}], is the layout", path.display());
        }
        return Ok(Some(RoomLayout { corners, floor: -poly.y_max as f32, ceiling: -poly.y_min as f32 }));
    }
    Ok(None)
}

/// Reads a frame directory's annotations (objects of `annotation3Dfinal/index.json` and the room of
/// `annotation3Dlayout/index.json`, each optional) without decoding its images, for evaluating many frames.
/// Gives the same objects and layout as [`Frame::read`].
pub fn read_annotations(dir: &Path) -> Result<(Vec<Object>, Option<RoomLayout>)> {
    let (objects, layout) = read_positioned_annotations(dir)?;
    Ok((objects.into_iter().map(|(_, object)| object).collect(), layout))
}

/// Objects, each with its position in its annotation file's `objects` array ([`read_positioned_objects`]).
pub type PositionedObjects = Vec<(usize, Object)>;

/// [`read_annotations`] with each object's position in `annotation3Dfinal/index.json`'s `objects` array
/// ([`read_positioned_objects`]).
pub fn read_positioned_annotations(dir: &Path) -> Result<(PositionedObjects, Option<RoomLayout>)> {
    if !dir.is_dir() {
        return Err(not_a_frame_dir(dir));
    }
    let objects_path = dir.join("annotation3Dfinal").join("index.json");
    let objects = if objects_path.is_file() { read_positioned_objects(&objects_path)? } else { Vec::new() };
    let layout_path = dir.join("annotation3Dlayout").join("index.json");
    let layout = if layout_path.is_file() { read_layout(&layout_path)? } else { None };
    Ok((objects, layout))
}

/// The error for a frame path that is not a directory: a regular file, or nothing.
fn not_a_frame_dir(dir: &Path) -> Error {
    if dir.exists() {
        Error::invalid(dir, "is a file, not a frame directory (intrinsics.txt, image/, depth/, extrinsics/)")
    } else {
        Error::missing(dir, "frame directory")
    }
}

fn read_frame(dir: &Path, depth_source: DepthSource) -> Result<Frame> {
    if !dir.is_dir() {
        return Err(not_a_frame_dir(dir));
    }
    // A data set's directory given where one frame is expected said only that `image/` was missing.
    if !dir.join("image").exists() && !dir.join("intrinsics.txt").exists() {
        let frames = fs::read_dir(dir)
            .map(|entries| entries.flatten().filter(|e| e.path().join("intrinsics.txt").is_file()).count())
            .unwrap_or(0);
        if frames > 0 {
            return Err(Error::invalid(
                dir,
                format!("is a directory of {frames} frame(s), not a frame: give one of its frame directories"),
            ));
        }
    }
    let name = frame_name(dir);
    let rgb_path = single_image(dir, "image")?;
    let rgb = colour_image(&rgb_path, open_image(&rgb_path)?)?;
    let depth_path = single_image(dir, depth_source.dir_name())?;
    let (dw, dh, depth_mm) = read_depth_png(&depth_path)?;
    if (dw, dh) != rgb.dimensions() {
        return Err(Error::invalid(
            &depth_path,
            format!("depth is {dw}×{dh} but the RGB image {} is {}×{}", rgb_path.display(), rgb.width(), rgb.height()),
        ));
    }
    let k_path = dir.join("intrinsics.txt");
    let k = read_intrinsics(&k_path)?;
    check_intrinsics(&k_path, &k, rgb.width(), rgb.height())?;
    let extrinsics = read_extrinsics(&extrinsics_file(dir)?)?;
    let scene_path = dir.join("scene.txt");
    let scene = if scene_path.is_file() { Some(read_text(&scene_path)?.trim().to_string()) } else { None };
    let (objects, layout) = read_annotations(dir)?;
    Ok(Frame { name, rgb, depth_mm, k, extrinsics, scene, objects, layout })
}

// ---------------------------------------------------------------------------------------------------------
// Writing

fn create_dir(path: &Path) -> Result<()> {
    fs::create_dir_all(path).map_err(|e| Error::io(path, e))
}

fn write_text(path: &Path, text: &str) -> Result<()> {
    fs::write(path, text).map_err(|e| Error::io(path, e))
}

fn matrix_text(rows: &[[f64; 3]; 3], translation: bool) -> String {
    rows.iter()
        .map(|r| {
            let mut cols: Vec<String> = r.iter().map(|v| format!("{v}")).collect();
            if translation {
                cols.push("0".into());
            }
            cols.join(" ")
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n"
}

/// The annotation polygon of an object: footprint corners as X/Z, Ymin = −top, Ymax = −bottom.
fn polygon_json(corners: &[Vec2], bottom: f32, top: f32, rectangle: bool) -> Value {
    json!([{
        "X": corners.iter().map(|c| c.x as f64).collect::<Vec<_>>(),
        "Z": corners.iter().map(|c| c.y as f64).collect::<Vec<_>>(),
        "Ymin": -(top as f64),
        "Ymax": -(bottom as f64),
        "rectangle": rectangle,
    }])
}

fn annotation_json(frame: &Frame) -> Value {
    let objects: Vec<Value> = frame
        .objects
        .iter()
        .map(|o| {
            let name = match &o.label {
                Some(label) => format!("{}:{label}", o.category),
                None => o.category.clone(),
            };
            json!({ "name": name, "polygon": polygon_json(&o.cuboid.footprint(), o.cuboid.bottom(), o.cuboid.top(), true) })
        })
        .collect();
    json!({ "name": frame.name, "frames": [{}], "objects": objects })
}

fn layout_json(frame: &Frame, layout: &RoomLayout) -> Value {
    json!({
        "name": frame.name,
        "frames": [{}],
        "objects": [{ "name": "room", "polygon": polygon_json(&layout.corners, layout.floor, layout.ceiling, false) }],
    })
}

fn write_json(path: &Path, value: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Error::invalid(path, e.to_string()))?;
    write_text(path, &text)
}

/// Writes `frame` into `dir` in the SUN RGB-D layout. RGB goes to `image/<name>.png` (lossless), depth to
/// `depth/<name>.png`; the extrinsics file is `extrinsics/00000000000000.txt`. Reading the directory back
/// gives identical RGB, depth, K, E and the objects within f32 rounding.
fn write_frame(dir: &Path, frame: &Frame) -> Result<()> {
    let (w, h) = (frame.width(), frame.height());
    if frame.depth_mm.len() != (w * h) as usize {
        return Err(Error::Input(format!(
            "frame '{}': depth has {} values, the {w}×{h} RGB needs {}",
            frame.name,
            frame.depth_mm.len(),
            w * h
        )));
    }
    for sub in ["image", "depth", "extrinsics"] {
        create_dir(&dir.join(sub))?;
    }
    let rgb_path = dir.join("image").join(format!("{}.png", frame.name));
    write_png(&frame.rgb, &rgb_path)?;
    write_depth_png(&dir.join("depth").join(format!("{}.png", frame.name)), w, h, &frame.depth_mm)?;
    write_text(&dir.join("intrinsics.txt"), &matrix_text(&frame.k, false))?;
    write_text(&dir.join("extrinsics").join("00000000000000.txt"), &matrix_text(&frame.extrinsics, true))?;
    if let Some(scene) = &frame.scene {
        write_text(&dir.join("scene.txt"), scene)?;
    }
    let ann_dir = dir.join("annotation3Dfinal");
    create_dir(&ann_dir)?;
    write_json(&ann_dir.join("index.json"), &annotation_json(frame))?;
    if let Some(layout) = &frame.layout {
        let layout_dir = dir.join("annotation3Dlayout");
        create_dir(&layout_dir)?;
        write_json(&layout_dir.join("index.json"), &layout_json(frame, layout))?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------------------
// Datasets

/// A frame directory's name, its identity among a dataset's frames and in a detections directory
/// (`<name>.json`): its last component — that of its canonical path when it has none (`.` or `..`, a
/// frame detected from inside it, would otherwise be named `.`) — or the whole path when neither has one.
pub fn frame_name(dir: &Path) -> String {
    let last = |path: &Path| path.file_name().map(|n| n.to_string_lossy().into_owned());
    last(dir)
        .or_else(|| fs::canonicalize(dir).ok().and_then(|canonical| last(&canonical)))
        .unwrap_or_else(|| dir.display().to_string())
}

/// The [`frame_name`] of each of `frames`, in order; an error naming both directories when two share a
/// name, since their files (`<name>.json`: detections, layouts) would be one file — read for both, or
/// written over each other.
pub fn unique_frame_names(frames: &[PathBuf]) -> Result<Vec<String>> {
    let names: Vec<String> = frames.iter().map(|dir| frame_name(dir)).collect();
    let mut first: std::collections::HashMap<&str, &Path> = std::collections::HashMap::new();
    for (name, dir) in names.iter().zip(frames) {
        if let Some(other) = first.insert(name, dir) {
            return Err(Error::Input(format!(
                "frames {} and {} have the same name '{name}', so they would share the file {name}.json: rename \
                 one of them",
                other.display(),
                dir.display()
            )));
        }
    }
    Ok(names)
}

/// Whether a directory looks like a frame: it has `intrinsics.txt` and an `image/` directory.
pub fn is_frame_dir(dir: &Path) -> bool {
    dir.join("intrinsics.txt").is_file() && dir.join("image").is_dir()
}

/// A dataset: a directory tree whose frame directories are found recursively.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub root: PathBuf,
    /// Frame directories, sorted by path.
    pub frames: Vec<PathBuf>,
}

impl Dataset {
    /// Finds every frame directory under `root` (a frame directory is not searched further).
    pub fn open(root: impl AsRef<Path>) -> Result<Dataset> {
        let root = root.as_ref().to_path_buf();
        if !root.is_dir() {
            return Err(Error::missing(&root, "dataset directory"));
        }
        let mut frames = Vec::new();
        let mut stack = vec![root.clone()];
        // Directories already walked, by canonical path: a symbolic link back up the tree (or to itself)
        // would otherwise make the walk endless.
        let mut visited = std::collections::HashSet::new();
        while let Some(dir) = stack.pop() {
            let canonical = fs::canonicalize(&dir).map_err(|e| Error::io(&dir, e))?;
            if !visited.insert(canonical) {
                log::warn!("{}: already searched (a symbolic link loop or a second link); skipped", dir.display());
                continue;
            }
            if is_frame_dir(&dir) {
                frames.push(dir);
                continue;
            }
            let entries = fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
            for entry in entries.flatten() {
                let path = entry.path();
                if path.is_dir() {
                    stack.push(path);
                }
            }
        }
        frames.sort();
        Ok(Dataset { root, frames })
    }

    /// Restricts the dataset to a split list: a text file with one frame directory per line, relative to
    /// the dataset root (or absolute); blank lines and lines starting with `#` are ignored. A listed
    /// directory that is not a frame, or a frame listed twice (it would count twice in training and
    /// evaluation), is an error naming the list and the line.
    pub fn with_split(mut self, list: impl AsRef<Path>) -> Result<Dataset> {
        let list = list.as_ref();
        let text = read_text(list)?;
        let mut frames = Vec::new();
        let mut listed: std::collections::HashMap<PathBuf, usize> = std::collections::HashMap::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let path = if Path::new(line).is_absolute() { PathBuf::from(line) } else { self.root.join(line) };
            if !is_frame_dir(&path) {
                return Err(Error::invalid(
                    list,
                    format!("line {}: '{}' is not a frame directory", n + 1, path.display()),
                ));
            }
            let canonical = fs::canonicalize(&path).map_err(|e| Error::io(&path, e))?;
            if let Some(first) = listed.insert(canonical, n + 1) {
                return Err(Error::invalid(
                    list,
                    format!("line {}: '{}' is listed already on line {first}", n + 1, path.display()),
                ));
            }
            frames.push(path);
        }
        self.frames = frames;
        Ok(self)
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}
