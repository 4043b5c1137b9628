//! The fast path: features and fused scores of many hypotheses with the work shared across hypotheses,
//! an approximation of the exact path ([`super::cpu`]) chosen with `--features fast` (the default of
//! `detect` and `train`; `exact` stays available everywhere).
//!
//! # Why
//! The exact path visits, for every hypothesis, every point inside its expanded box: a bed's sliding
//! window on a 640×480 frame is ~10⁹ point visits with a projected COG basis per voxel. Here the points are
//! binned once, and a hypothesis only reads sums:
//!
//! 1. **Per yaw** ([`YawLattice`]): every point of the yaw's rotated frame gets a ground cell on a lattice
//!    of side `step / subdivisions` aligned with the hypothesis centres (the centres lie on cell
//!    centres, or on cell corners for even subdivisions), its normal code, and its COG bins and fixed-point
//!    shares — the projected COG basis taken **at the point itself** instead of at its voxel's centre
//!    (the basis varies slowly; at the point it is, if anything, closer to the paper's intent).
//! 2. **Per yaw, bottom and height** ([`LayerTable`]): the sliding window puts every box on the floor, so
//!    for one (yaw, height) the voxel layers along z are the same for all hypotheses. Every point is given
//!    its exact layer, and each layer holds a 2D summed-area table over the ground cells of the 35 integer
//!    channels (count, 25 normal bins, 9 COG bins). Sums are `u32` with wrapping arithmetic: differences of
//!    the table are exact whatever the order, so the result is bit-for-bit reproducible.
//! 3. **Per hypothesis**: a voxel column covers the ground cells whose centres lie inside it (the only
//!    approximation of membership: along width and depth, voxel faces snap to the nearest cell boundary —
//!    half a cell, `step / 4` with two subdivisions: 2.5 cm at a 0.1 m step, 5 cm at the shipped models'
//!    0.2 m, at most; a cell centre on a face, or within [`TIE_CELLS`] cells below it, belongs to the voxel
//!    above the face; along z membership is the exact path's up to rounding — the layer of a point is
//!    found in f32 here, in 2⁻¹⁶ m fixed point there, so a point on a layer boundary, such as the floor's
//!    own lowest points on the bottom of an expanded box, can land in the neighbouring layer). Its 35 sums for each layer
//!    are four table reads; the 8×8 cell boundaries of a 7×7 grid are shared by all its voxels.
//! 4. **Per voxel**: density and normal bins are divided by the projected area `A` linearised at the voxel
//!    centre `P` (camera coordinates): a small box with edge vectors `e_s, e_t, e_z` projects to
//!    `fx·fy·(|S_s·P| + |S_t·P| + |S_z·P|)/P.z³` pixels², `S` the face area vectors — the exact path takes the
//!    hull of the 8 projected corners. The two differ to first order, and one way: the faces the camera
//!    sees are the near ones, which project larger than at the centre (a cube of side `v` seen face-on at
//!    distance `D`: hull / linear ≈ `(D / (D − v/2))²` ≈ 1 + v/D), so this area is the smaller and the
//!    density and normal bins the larger — an audit measured hull / linear over 1 380 voxels of 12 bed
//!    hypotheses (160×120 synthetic frame): median 1.013, 95th percentile 1.093, at most 1.38, never below 1.
//!    Models are trained and scored on the same path, so the bias is theirs throughout. A voxel whose centre
//!    is less than [`MIN_PROJECT_DEPTH`] in front of the camera has density and normal bins 0 (the exact
//!    path: any corner). COG sums are normalised as in the exact path, but the exact path's zeroing of a
//!    voxel's COG where the basis at its centre is undefined (the centre behind the camera, the front face
//!    seen edge-on) has no twin here: the basis is taken at each point.
//!
//! Hypotheses whose bottom and height differ from the sliding window's (ground truths in training) get a
//! table of their own; centres off the lattice are handled by the same boundary rule.
//!
//! The agreement with the exact path is measured by `tests/features_fast.rs` (feature cosine similarity)
//! and by `cog-gpu bench --features both`.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

use super::cpu::{cog_frame, cog_position, dot, view_cosine, ExpandedBox};
use super::feature_layout::{
    view_features, FeatureLayout, COG, COG_BINS, COG_EPSILON, DENSITY, MAX_COLUMNS, NORMALS, PER_VOXEL, VIEW,
};
use super::hypotheses::Hypothesis;
use super::out_of_view::{out_of_view_score, out_of_view_voxels, write_out_of_view};
use super::preprocess::NORMAL_BINS;
use super::scene::{floor_to_i64, FeatureScene, YawGrid, FIXED_PER_METRE};
use crate::geometry::MIN_PROJECT_DEPTH;

/// Integer channels per ground cell: count, 25 normal bins, 9 COG bins, one pad (so a cell is 144 bytes).
pub const CHANNELS: usize = 36;
/// Default lattice cells per hypothesis step along width and depth.
pub const DEFAULT_SUBDIVISIONS: u32 = 2;
/// A cell centre within this many cells below a voxel face counts as inside the voxel above the face.
pub const TIE_CELLS: f32 = 1e-4;
/// Largest COG fixed-point scale (units per unit of gradient magnitude).
const MAX_COG_SCALE: f32 = 4096.0;

/// Options of the fast path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FastOptions {
    /// Lattice cells per hypothesis step along the ground axes (1 = cells of the step itself).
    pub subdivisions: u32,
}

impl Default for FastOptions {
    fn default() -> Self {
        FastOptions { subdivisions: DEFAULT_SUBDIVISIONS }
    }
}

/// One point as the fast path bins it — in the layout the GPU's table kernels read, so that a yaw's
/// lattice is uploaded as it is (no conversion per engine call: with the 19 shipped models that was
/// ~20 ms of one thread per call and a handful of calls per frame). Twin of WGSL `struct TablePoint` in
/// `shaders/fast_tables.wgsl` ([`crate::gpu::fast_tables::TablePoint`] is this type).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct LatticePoint {
    /// Ground cell index `t·cells_s + s`.
    pub cell: u32,
    /// Height (metres).
    pub z: f32,
    /// Normal bin | COG bin 0 << 8 | COG bin 1 << 16.
    pub bins: u32,
    /// Fixed-point shares of the gradient magnitude for the two COG bins (0 when it has none).
    pub share0: u32,
    pub share1: u32,
}
const _: () = assert!(std::mem::size_of::<LatticePoint>() == 20);

impl LatticePoint {
    /// Its normal bin.
    pub fn normal_bin(&self) -> usize {
        (self.bins & 0xff) as usize
    }

    /// Its COG bin `k` (0 or 1).
    pub fn cog_bin(&self, k: usize) -> usize {
        ((self.bins >> (8 + 8 * k)) & 0xff) as usize
    }
}

/// Where the voxel layers of one [`LayerTable`] lie along z: layer `k` holds the points with
/// `⌊(z − z_lo) · inv_step⌋ = k`, `k < layers`. Computed once (`FastEngine::table_span`) for the CPU
/// table and the GPU kernel that builds the same table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableSpan {
    pub z_lo: f32,
    pub inv_step: f32,
    pub layers: usize,
}

/// Step 1 of the module doc: the points of one yaw on the ground lattice.
pub struct YawLattice {
    origin: [f32; 2],
    cell: f32,
    cells: [usize; 2],
    points: Vec<LatticePoint>,
    z_buckets: ZBuckets,
}

/// Height of the buckets of [`ZBuckets`] (metres).
const Z_BUCKET_M: f32 = 0.05;

/// The points of a [`YawLattice`] grouped by height, so that a [`LayerTable`] visits only the points near
/// its z span instead of every point of its yaw (the tables were about a third of a frame's scoring time
/// on the CPU, and a table's span holds a fraction of the points). Bucket `b` holds the points with
/// `⌊(z − z_min) / Z_BUCKET_M⌋ = b` (clamped to the last), at `points[offsets[b]..offsets[b + 1]]`, in
/// binning order within a bucket (a stable counting sort, so the order is the same on every run; the tables'
/// sums do not depend on it anyway).
struct ZBuckets {
    z_min: f32,
    offsets: Vec<usize>,
}

impl ZBuckets {
    /// Sorts `points` into buckets.
    fn sort(points: Vec<LatticePoint>) -> (Vec<LatticePoint>, ZBuckets) {
        let z_min = points.iter().map(|p| p.z).fold(f32::INFINITY, f32::min);
        let z_max = points.iter().map(|p| p.z).fold(f32::NEG_INFINITY, f32::max);
        let count = if points.is_empty() { 1 } else { (((z_max - z_min) / Z_BUCKET_M) as usize + 1).min(1 << 16) };
        let mut buckets = ZBuckets { z_min, offsets: vec![0; count + 1] };
        for p in &points {
            let b = buckets.bucket(p.z);
            buckets.offsets[b + 1] += 1;
        }
        for b in 0..count {
            buckets.offsets[b + 1] += buckets.offsets[b];
        }
        let mut next = buckets.offsets.clone();
        let mut sorted = vec![LatticePoint::default(); points.len()];
        for p in points {
            let b = buckets.bucket(p.z);
            sorted[next[b]] = p;
            next[b] += 1;
        }
        (sorted, buckets)
    }

    /// The bucket of height `z`; monotone in `z` (clamped to the first and last bucket).
    fn bucket(&self, z: f32) -> usize {
        let position = (z - self.z_min) / Z_BUCKET_M;
        if position >= 0.0 {
            (position as usize).min(self.offsets.len() - 2)
        } else {
            0
        }
    }

    /// The range of points whose buckets overlap `[z_lo, z_hi]`: every point with `z_lo ≤ z ≤ z_hi`, and
    /// some outside it (callers test each point).
    fn range(&self, z_lo: f32, z_hi: f32) -> std::ops::Range<usize> {
        self.offsets[self.bucket(z_lo)]..self.offsets[self.bucket(z_hi) + 1]
    }
}

/// Step 2 of the module doc: summed-area tables of one (yaw, bottom, height).
pub struct LayerTable {
    /// `stride[0] × stride[1]` entries per layer, each [`CHANNELS`] wide; entry (x, y) holds the sums of
    /// the cells `origin[0] ≤ s < origin[0] + x` and `origin[1] ≤ t < origin[1] + y` of the table's
    /// [`CellRegion`] (the whole lattice: origin 0, `cells + 1` entries along each axis).
    sums: Vec<u32>,
    /// Channel 0 (the point count) of every entry of `sums`, in the same order: the empty-voxel test reads
    /// these 4-byte words instead of the first words of four 144-byte entries (1/36 of the memory, so they
    /// stay in cache).
    counts: Vec<u32>,
    stride: [usize; 2],
    /// The region's first cell along s and t.
    origin: [usize; 2],
}

/// The lattice cells `lo[a] ≤ c < hi[a]` along s (a = 0) and t (a = 1) that a [`LayerTable`] covers.
///
/// A table only answers for voxel boundaries inside its region, and differences of its entries are the
/// same words as those of the whole lattice's table (the sums are of the same cells; wrapping arithmetic
/// is exact in any order), so a group of hypotheses whose voxels all lie in a small part of the lattice —
/// pillows on a bed, lamps on nightstands, the far end of a room — scores from a table of that part alone,
/// bit for bit as from the whole one: the tables were a fifth to a quarter of a frame's scoring time on
/// the CPU, and on the standard frame (docs/measurements.md, "Tables over their boxes' region") more than half of that
/// went to cells no hypothesis of the group reads.
///
/// The GPU path builds its tables over the same regions (`gpu::fast`'s packer).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellRegion {
    lo: [usize; 2],
    hi: [usize; 2],
}

impl CellRegion {
    /// Every cell of `lattice`.
    pub fn whole(lattice: &YawLattice) -> CellRegion {
        CellRegion { lo: [0, 0], hi: lattice.cells }
    }

    /// The cells `lo[a] ≤ c < hi[a]`; `None` unless `lo[a] ≤ hi[a]` and `hi` lies within `lattice`.
    pub fn new(lattice: &YawLattice, lo: [usize; 2], hi: [usize; 2]) -> Option<CellRegion> {
        let fits = (0..2).all(|a| lo[a] <= hi[a] && hi[a] <= lattice.cells[a]);
        fits.then_some(CellRegion { lo, hi })
    }

    /// The region's first cell along s and t.
    pub fn lo(&self) -> [usize; 2] {
        self.lo
    }

    /// Entries per row and rows per layer of a [`LayerTable`] over the region (cells + 1 along s and t).
    pub fn table_stride(&self) -> [usize; 2] {
        [self.hi[0] - self.lo[0] + 1, self.hi[1] - self.lo[1] + 1]
    }

    /// The smallest region holding `self` and `other`.
    pub(crate) fn union(self, other: CellRegion) -> CellRegion {
        CellRegion {
            lo: [self.lo[0].min(other.lo[0]), self.lo[1].min(other.lo[1])],
            hi: [self.hi[0].max(other.hi[0]), self.hi[1].max(other.hi[1])],
        }
    }

    /// The cells the voxels of the hypothesis with boundaries `b` cover: from its first to its last
    /// boundary along each axis (boundaries ascend).
    pub(crate) fn of(b: &VoxelBoundaries) -> CellRegion {
        let (xs, ys) = (b.xs(), b.ys());
        CellRegion { lo: [xs[0] as usize, ys[0] as usize], hi: [xs[xs.len() - 1] as usize, ys[ys.len() - 1] as usize] }
    }

    /// The smallest region holding the voxels of every hypothesis whose boundaries `bounds` yields.
    fn of_boundaries(bounds: impl IntoIterator<Item = VoxelBoundaries>) -> Option<CellRegion> {
        bounds.into_iter().map(|b| CellRegion::of(&b)).reduce(CellRegion::union)
    }
}

/// The fast path over one scene and layout.
pub struct FastEngine<'a> {
    scene: &'a FeatureScene,
    layout: FeatureLayout,
    options: FastOptions,
    /// Shared between engines of one scene whose lattices agree ([`FastEngine::sharing_lattices`]).
    lattices: Arc<Vec<YawLattice>>,
    /// COG units per unit of gradient magnitude.
    cog_scale: f32,
    /// Nanoseconds spent building layer tables (`build_table`), summed over threads (`cog-gpu bench
    /// --detect` reports it as the tables' share of scoring: the tables are built inside the parallel
    /// scoring loop, one per group, so they have no wall-clock stage of their own).
    table_nanos: AtomicU64,
}

impl<'a> FastEngine<'a> {
    /// Bins the points of every yaw of `scene` (step 1).
    pub fn new(scene: &'a FeatureScene, layout: &FeatureLayout, options: FastOptions) -> FastEngine<'a> {
        let subdivisions = options.subdivisions.max(1);
        let cog_scale = cog_scale_for(scene);
        let lattices = Arc::new(
            scene.yaws.par_iter().map(|grid| YawLattice::build(scene, grid, subdivisions, cog_scale, layout)).collect(),
        );
        Self::with_lattices(scene, layout, FastOptions { subdivisions }, cog_scale, lattices)
    }

    /// An engine for `layout` that reuses `other`'s lattices when they are the ones `layout` needs: the
    /// lattices depend on the scene, the subdivisions and whether COG is binned, not on the voxel grid or
    /// the expansion, so models with different grids on one scene (the large categories' 5×5×5 base grid, the
    /// small ones' 3×3×3 and 3×1×3) bin the points of every yaw once. `None` when they differ.
    pub fn sharing_lattices(other: &FastEngine<'a>, layout: &FeatureLayout, options: FastOptions) -> Option<Self> {
        let same =
            options.subdivisions.max(1) == other.options.subdivisions && layout.groups.cog == other.layout.groups.cog;
        same.then(|| {
            Self::with_lattices(other.scene, layout, other.options, other.cog_scale, Arc::clone(&other.lattices))
        })
    }

    fn with_lattices(
        scene: &'a FeatureScene,
        layout: &FeatureLayout,
        options: FastOptions,
        cog_scale: f32,
        lattices: Arc<Vec<YawLattice>>,
    ) -> FastEngine<'a> {
        FastEngine { scene, layout: *layout, options, lattices, cog_scale, table_nanos: AtomicU64::new(0) }
    }

    pub fn options(&self) -> FastOptions {
        self.options
    }

    /// The scene the engine was built on.
    pub fn scene(&self) -> &'a FeatureScene {
        self.scene
    }

    /// The feature layout the engine computes.
    pub fn layout(&self) -> &FeatureLayout {
        &self.layout
    }

    /// Features of `hypotheses`, row-major `hypotheses.len() × layout.dim()`.
    pub fn features(&self, hypotheses: &[Hypothesis]) -> Vec<f32> {
        let dim = self.layout.dim();
        let mut out = vec![0.0f32; hypotheses.len() * dim];
        let mut rows: Vec<Option<&mut [f32]>> = out.chunks_mut(dim.max(1)).map(Some).collect();
        let groups = group_by_table(hypotheses);
        // Hand each group the rows of its hypotheses.
        let mut work: Vec<(TableKey, GroupRows)> = Vec::with_capacity(groups.len());
        for (key, members) in groups {
            let rows_of_group = members.iter().map(|&n| (n, rows[n].take().expect("each row once"))).collect();
            work.push((key, rows_of_group));
        }
        work.into_par_iter().for_each(|(key, members)| {
            let (table, boundaries) = self.group_table(key, members.iter().map(|&(n, _)| &hypotheses[n]));
            members.into_par_iter().zip(boundaries).for_each(|((n, row), bounds)| {
                self.hypothesis(&table, &hypotheses[n], &bounds, |voxel, values| {
                    row[voxel * PER_VOXEL..(voxel + 1) * PER_VOXEL].copy_from_slice(values);
                });
                if self.layout.groups.view {
                    let offset = self.layout.view_offset();
                    row[offset..offset + VIEW].copy_from_slice(&self.view(&hypotheses[n]));
                }
                write_out_of_view(self.scene, &self.layout, &hypotheses[n], row);
            });
        });
        out
    }

    /// Fused scores `scores[h·W + w] = weights[w] · φ(h)` (each weight vector of length `layout.dim()`).
    pub fn scores(&self, hypotheses: &[Hypothesis], weights: &[Vec<f32>]) -> Vec<f32> {
        self.rows(hypotheses, weights.len(), |table, hyp, bounds, row| {
            self.hypothesis(table, hyp, bounds, |voxel, values| {
                let offset = voxel * PER_VOXEL;
                for (score, w) in row.iter_mut().zip(weights) {
                    *score += dot_lanes(&w[offset..offset + PER_VOXEL], values);
                }
            });
            if self.layout.groups.view {
                let view = self.view(hyp);
                let offset = self.layout.view_offset();
                for (score, w) in row.iter_mut().zip(weights) {
                    *score += dot(&w[offset..offset + VIEW], &view);
                }
            }
            if self.layout.groups.out_of_view {
                let voxels = out_of_view_voxels(self.scene, &self.layout, hyp);
                for (score, w) in row.iter_mut().zip(weights) {
                    *score += out_of_view_score(&self.layout, &voxels, w);
                }
            }
        })
    }

    /// Per-layer scores: `scores[h·nz + k] = Σ_{i,j} w[(j·nx + i)·35 ..][..35] · φ_{(i,j,k)}(h)`, one weight
    /// block of `nx·ny` voxels (a layer's voxels in [`FeatureLayout::voxel_index`] order) applied to every
    /// layer `k` of the grid. The support-surface part of the paper's §4 scores the `h`-th horizontal slice
    /// of a 5×5×7 grid with one weight vector for whichever slice holds the surface
    /// ([`super::surface`]). Voxels are summed in the fixed order of the visit (k, then j, then i), so the
    /// result is the same on every run.
    pub fn layer_scores(&self, hypotheses: &[Hypothesis], layer_weights: &[f32]) -> Vec<f32> {
        let g = self.layout.grid();
        let (columns, layers) = ((g[0] * g[1]) as usize, g[2] as usize);
        assert_eq!(layer_weights.len(), columns * PER_VOXEL, "one weight block per voxel of a layer");
        self.rows(hypotheses, layers, |table, hyp, bounds, row| {
            self.hypothesis(table, hyp, bounds, |voxel, values| {
                let (layer, column) = (voxel / columns, voxel % columns);
                let offset = column * PER_VOXEL;
                row[layer] += dot_lanes(&layer_weights[offset..offset + PER_VOXEL], values);
            });
        })
    }

    /// `width` numbers per hypothesis, row-major: `fill(table, hypothesis, its boundaries, zeroed row)` for
    /// each, in parallel over the hypotheses' table groups (each table built once).
    fn rows(
        &self,
        hypotheses: &[Hypothesis],
        width: usize,
        fill: impl Fn(&LayerTable, &Hypothesis, &VoxelBoundaries, &mut [f32]) + Sync,
    ) -> Vec<f32> {
        let mut out = vec![0.0f32; hypotheses.len() * width];
        if width == 0 {
            return out;
        }
        // One block of rows per group (members in order), filled in parallel, then copied to the members'
        // rows: no vector per hypothesis (there were ~6 M alive at once for a 640×480 frame at 0.1 m).
        let per_group: Vec<(Vec<usize>, Vec<f32>)> = group_by_table(hypotheses)
            .into_par_iter()
            .map(|(key, members)| {
                let (table, boundaries) = self.group_table(key, members.iter().map(|&n| &hypotheses[n]));
                let mut rows = vec![0.0f32; members.len() * width];
                rows.par_chunks_mut(width)
                    .zip(&members)
                    .zip(&boundaries)
                    .for_each(|((row, &n), bounds)| fill(&table, &hypotheses[n], bounds, row));
                (members, rows)
            })
            .collect();
        for (members, rows) in per_group {
            for (&n, row) in members.iter().zip(rows.chunks(width)) {
                out[n * width..(n + 1) * width].copy_from_slice(row);
            }
        }
        out
    }

    /// The 12 view features of `hyp` (shared with the GPU twin, which adds them on the CPU).
    pub(crate) fn view(&self, hyp: &Hypothesis) -> [f32; VIEW] {
        view_features(view_cosine(&hyp.cuboid(self.scene)))
    }

    /// Seconds spent building layer tables so far, summed over threads (see the field's doc).
    pub fn table_thread_seconds(&self) -> f64 {
        self.table_nanos.load(Ordering::Relaxed) as f64 * 1e-9
    }

    /// Step 2: the layer table of one (yaw, bottom, height), over the whole lattice (for the tests of the
    /// GPU's tables and for debugging; scoring builds each group's over its region).
    pub(crate) fn table(&self, key: TableKey) -> LayerTable {
        self.build_table(key, CellRegion::whole(&self.lattices[key.yaw_index as usize]))
    }

    /// Steps 2 and 3 for the CPU's scoring of one group: the cell boundaries of each of `members` (all of
    /// `key`), in order, and the table of `key` over the cells their voxels cover, a [`CellRegion`] (their
    /// scores are those from [`FastEngine::table`], bit for bit). The boundaries are made once here, for the
    /// region and for the scoring.
    fn group_table<'h>(
        &self,
        key: TableKey,
        members: impl Iterator<Item = &'h Hypothesis>,
    ) -> (LayerTable, Vec<VoxelBoundaries>) {
        let lattice = &self.lattices[key.yaw_index as usize];
        let g = self.layout.grid();
        let boundaries: Vec<VoxelBoundaries> =
            members.map(|hyp| voxel_boundaries(&g, &ExpandedBox::new(&self.layout, hyp), lattice)).collect();
        let region = CellRegion::of_boundaries(boundaries.iter().copied()).unwrap_or(CellRegion::whole(lattice));
        (self.build_table(key, region), boundaries)
    }

    /// The table of `key` over `region`, its build time added to [`FastEngine::table_thread_seconds`].
    pub(crate) fn build_table(&self, key: TableKey, region: CellRegion) -> LayerTable {
        let started = Instant::now();
        let table = LayerTable::build(&self.lattices[key.yaw_index as usize], self.table_span(key), region);
        self.table_nanos.fetch_add(started.elapsed().as_nanos() as u64, Ordering::Relaxed);
        table
    }

    /// The voxel layers of the table of `key` along z: the expanded box's z extent cut into the grid's
    /// `nz` layers.
    pub(crate) fn table_span(&self, key: TableKey) -> TableSpan {
        let g = self.layout.grid();
        let expansion = self.layout.expansion();
        let (bottom, height) = (f32::from_bits(key.bottom_bits), f32::from_bits(key.height_bits));
        let extent = height * expansion[2];
        let z_lo = bottom + 0.5 * height - 0.5 * extent;
        TableSpan { z_lo, inv_step: 1.0 / (extent / g[2] as f32), layers: g[2] as usize }
    }

    /// The lattice of yaw `yaw_index` (step 1), for the GPU kernel that builds tables from it.
    pub fn lattice(&self, yaw_index: usize) -> &YawLattice {
        &self.lattices[yaw_index]
    }

    /// The z layers of the table `hyp` is scored from.
    pub fn table_span_of(&self, hyp: &Hypothesis) -> TableSpan {
        self.table_span(key_of(hyp))
    }

    /// The words of the table `hyp` is scored from (step 2 on the CPU), for tests against the GPU's.
    pub fn table_words_of(&self, hyp: &Hypothesis) -> Vec<u32> {
        self.table(key_of(hyp)).sums
    }

    /// The words of the table of `hyp`'s (yaw, bottom, height) over `region` of its lattice (step 2 on the
    /// CPU), for tests against the GPU's.
    pub fn region_table_words_of(&self, hyp: &Hypothesis, region: CellRegion) -> Vec<u32> {
        self.build_table(key_of(hyp), region).sums
    }

    /// Step 3 for one hypothesis, whose cell boundaries are `boundaries`: calls `visit([i, j, k], integer
    /// sums)` for every non-empty voxel.
    fn for_each_voxel_sums(
        &self,
        table: &LayerTable,
        boundaries: &VoxelBoundaries,
        mut visit: impl FnMut([usize; 3], &[u32; CHANNELS]),
    ) {
        let g = self.layout.grid();
        let (nx, ny) = (g[0] as usize, g[1] as usize);
        // The boundaries as entries of the table, which may cover only a region of the lattice.
        let local = |cells: &[u32], origin: usize| -> [usize; MAX_BOUNDARIES] {
            let mut out = [0; MAX_BOUNDARIES];
            for (o, &c) in out.iter_mut().zip(cells) {
                *o = c as usize - origin;
            }
            out
        };
        let (xs, ys) = (local(boundaries.xs(), table.origin[0]), local(boundaries.ys(), table.origin[1]));
        // The (nx+1)×(ny+1) boundary corners of one layer are shared by its voxels; they are read in place
        // from the table (copying them out first cost ~15 % of the fast path in memcpy).
        for k in 0..g[2] as usize {
            for j in 0..ny {
                for i in 0..nx {
                    // Empty voxels are common (boxes around objects): test the count, from the compact
                    // table of counts, before reading the 36-word entries.
                    let [x0, x1, y0, y1] = [xs[i], xs[i + 1], ys[j], ys[j + 1]];
                    let count = table
                        .count(k, x1, y1)
                        .wrapping_sub(table.count(k, x0, y1))
                        .wrapping_sub(table.count(k, x1, y0))
                        .wrapping_add(table.count(k, x0, y0));
                    if count == 0 {
                        continue;
                    }
                    let high = table.entry(k, x1, y1);
                    let left = table.entry(k, x0, y1);
                    let low = table.entry(k, x1, y0);
                    let both = table.entry(k, x0, y0);
                    let mut sums = [0u32; CHANNELS];
                    for ch in 0..CHANNELS {
                        sums[ch] = high[ch].wrapping_sub(left[ch]).wrapping_sub(low[ch]).wrapping_add(both[ch]);
                    }
                    visit([i, j, k], &sums);
                }
            }
        }
    }

    /// The integer sums (count, 25 normal bins, 9 COG bins in units of 1/[`FastEngine::cog_scale`], pad)
    /// of every voxel of `hyp`, indexed by ℓ ([`FeatureLayout::voxel_index`]). For tests and debugging.
    pub fn voxel_sums(&self, hyp: &Hypothesis) -> Vec<[u32; CHANNELS]> {
        let table = self.table(key_of(hyp));
        let boundaries = self.voxel_boundaries(&ExpandedBox::new(&self.layout, hyp), hyp.yaw_index);
        let mut out = vec![[0u32; CHANNELS]; self.layout.voxel_count()];
        self.for_each_voxel_sums(&table, &boundaries, |[i, j, k], sums| {
            out[self.layout.voxel_index(i as u32, j as u32, k as u32)] = *sums;
        });
        out
    }

    /// Step 3's cell boundaries of a hypothesis (`expanded`, the box of a hypothesis of yaw `yaw_index`):
    /// voxel i along s covers the lattice cells `xs[i]..xs[i+1]`, voxel j along t `ys[j]..ys[j+1]` — the
    /// indices the scoring uses, exposed for the GPU path and its twin.
    pub(crate) fn voxel_boundaries(&self, expanded: &ExpandedBox, yaw_index: u16) -> VoxelBoundaries {
        voxel_boundaries(&self.layout.grid(), expanded, &self.lattices[yaw_index as usize])
    }

    /// COG fixed-point units per unit of gradient magnitude.
    pub fn cog_scale(&self) -> f32 {
        self.cog_scale
    }

    /// Steps 3–4 for one hypothesis, whose cell boundaries are `boundaries`: calls `visit(voxel index ℓ, its
    /// 35 features)` for every non-empty voxel (empty voxels are all zeros, as in the exact path).
    fn hypothesis(
        &self,
        table: &LayerTable,
        hyp: &Hypothesis,
        boundaries: &VoxelBoundaries,
        mut visit: impl FnMut(usize, &[f32; PER_VOXEL]),
    ) {
        let grid: &YawGrid = &self.scene.yaws[hyp.yaw_index as usize];
        let expanded = ExpandedBox::new(&self.layout, hyp);
        let m = grid.camera_from_rotated;
        let [fx, fy, _, _] = self.scene.pre.camera.intrinsics;
        let [vs, vt, vz] = expanded.cell;
        let face_areas = [vt * vz, vs * vz, vs * vt];
        let groups = self.layout.groups;
        let inv_cog_scale = 1.0 / self.cog_scale;
        self.for_each_voxel_sums(table, boundaries, |[i, j, k], sums| {
            let p = m * expanded.voxel_centre([i as u32, j as u32, k as u32]);
            let mut values = [0.0f32; PER_VOXEL];
            if p.z >= MIN_PROJECT_DEPTH {
                let area = fx
                    * fy
                    * (face_areas[0] * m.x_axis.dot(p).abs()
                        + face_areas[1] * m.y_axis.dot(p).abs()
                        + face_areas[2] * m.z_axis.dot(p).abs())
                    / (p.z * p.z * p.z);
                let inv_area = 1.0 / area.max(1.0);
                // Counts are below 2³¹ (at most the frame's points: `limits::MAX_PIXELS`, asserted at
                // compile time), so they convert as i32 — one instruction per four lanes, where u32's
                // conversion takes several without AVX-512 — to the same floats.
                if groups.density {
                    values[DENSITY] = sums[0] as i32 as f32 * inv_area;
                }
                if groups.normals {
                    for b in 0..NORMAL_BINS {
                        values[NORMALS + b] = sums[1 + b] as i32 as f32 * inv_area;
                    }
                }
            }
            if groups.cog {
                let mut norm_sq = 0.0f32;
                for b in 0..COG_BINS {
                    let v = sums[COG + b] as f32 * inv_cog_scale;
                    values[COG + b] = v;
                    norm_sq += v * v;
                }
                let scale = 1.0 / (norm_sq + COG_EPSILON).sqrt();
                for v in &mut values[COG..COG + COG_BINS] {
                    *v *= scale;
                }
            }
            visit(self.layout.voxel_index(i as u32, j as u32, k as u32), &values);
        });
    }
}

// A voxel's point counts are at most the frame's points, one per pixel (`crate::limits::MAX_PIXELS`):
// below 2³¹, so `FastEngine`'s conversion of counts through `i32` gives the same floats as through `u32`.
const _: () = assert!(crate::limits::MAX_PIXELS < 1 << 31);

/// COG fixed-point units per unit of gradient magnitude for `scene`: the largest total of one COG channel
/// — every point with the largest magnitude √2 in one voxel — stays below 2³², so wrapped differences
/// equal the true sums.
fn cog_scale_for(scene: &FeatureScene) -> f32 {
    let points = scene.pre.len().max(1) as f32;
    let mut cog_scale = MAX_COG_SCALE;
    while cog_scale > 1.0 && points * std::f32::consts::SQRT_2 * cog_scale >= u32::MAX as f32 {
        cog_scale *= 0.5;
    }
    cog_scale
}

/// Lanes of [`dot_lanes`].
const DOT_LANES: usize = 8;

/// `a·b` over `DOT_LANES` interleaved lanes — lane `l` sums, in index order, the products at the indices
/// `≡ l (mod 8)` — added pairwise in a fixed order at the end. The order is fixed, so the result is the same
/// on every run, but there are eight independent chains of additions instead of `dot`'s one, which the
/// compiler turns into SIMD: one voxel's 35-term dot product was the fast path's longest dependency chain
/// (a hot kernel, hence written out here rather than left to the iterator's `sum`).
pub fn dot_lanes(a: &[f32], b: &[f32]) -> f32 {
    debug_assert_eq!(a.len(), b.len());
    let mut lanes = [0.0f32; DOT_LANES];
    let (a_body, a_tail) = a.split_at(a.len() / DOT_LANES * DOT_LANES);
    let (b_body, b_tail) = b.split_at(a_body.len());
    for (x, y) in a_body.chunks_exact(DOT_LANES).zip(b_body.chunks_exact(DOT_LANES)) {
        for l in 0..DOT_LANES {
            lanes[l] += x[l] * y[l];
        }
    }
    for (l, (x, y)) in a_tail.iter().zip(b_tail).enumerate() {
        lanes[l] += x * y;
    }
    ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5])) + ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]))
}

/// Boundaries of one hypothesis, both axes: `nx + 1 + ny + 1 ≤ nx·ny + 3 ≤` [`MAX_COLUMNS`]` + 3` (for
/// positive integers, `nx + ny ≤ nx·ny + 1`).
const MAX_BOUNDARIES: usize = MAX_COLUMNS as usize + 3;

/// Step 3's cell boundaries of one hypothesis (see [`voxel_boundaries`]): the `nx + 1` along s, then the
/// `ny + 1` along t, in one small array on the stack — they are made for every hypothesis scored, on the
/// CPU path and when the GPU path packs its records (two vectors per hypothesis before).
#[derive(Clone, Copy, Debug)]
pub(crate) struct VoxelBoundaries {
    cells: [u32; MAX_BOUNDARIES],
    /// nx + 1, ny + 1.
    counts: [usize; 2],
}

impl VoxelBoundaries {
    /// The `nx + 1` boundaries along s.
    pub(crate) fn xs(&self) -> &[u32] {
        &self.cells[..self.counts[0]]
    }

    /// The `ny + 1` boundaries along t.
    pub(crate) fn ys(&self) -> &[u32] {
        &self.cells[self.counts[0]..self.counts[0] + self.counts[1]]
    }

    /// Both, s first: the GPU record's order.
    pub(crate) fn all(&self) -> &[u32] {
        &self.cells[..self.counts[0] + self.counts[1]]
    }
}

/// Step 3's membership rule: voxel i along s covers the lattice cells `xs[i]..xs[i+1]` (those whose centre
/// lies in it), likewise `ys` along t; `nx + 1` and `ny + 1` boundaries.
///
/// Boundary `i` along an axis is `ceil((lo + i·cell − origin) / lattice_cell − ½ − TIE_CELLS)` clamped to
/// `0..=cells` ([`boundary_scalar`], the rule written out). Here it is computed eight boundaries at a time
/// in fixed-size lanes without branches, so that the compiler vectorises it: the same IEEE operations per
/// lane, hence the same numbers (tested against [`boundary_scalar`] for every lane, ties, out-of-range and
/// NaN positions included). The packing of every hypothesis for the GPU spent ~60 % of its time here.
fn voxel_boundaries(g: &[u32; 3], expanded: &ExpandedBox, lattice: &YawLattice) -> VoxelBoundaries {
    const LANES: usize = 8;
    let counts = [g[0] as usize + 1, g[1] as usize + 1];
    let mut boundaries = VoxelBoundaries { cells: [0; MAX_BOUNDARIES], counts };
    let mut at = 0;
    for (axis, &count) in counts.iter().enumerate() {
        let (lo, cell, origin) = (expanded.lo[axis], expanded.cell[axis], lattice.origin[axis]);
        // A lattice has far fewer than 2²⁴ cells along an axis (its table would not fit in memory), so the
        // limit is exact in f32 and i32.
        let limit = lattice.cells[axis].min(1 << 24) as i32;
        let limit_f = limit as f32;
        for first in (0..count).step_by(LANES) {
            let mut lanes = [0u32; LANES];
            for (l, lane) in lanes.iter_mut().enumerate() {
                let face = lo + (first + l) as f32 * cell;
                let position = (face - origin) / lattice.cell - 0.5 - TIE_CELLS;
                // Clamped to [−1, limit] first (NaN to −1, as `ceil_to_i64` makes it 0 and the clamp below
                // keeps 0): the ceiling of the clamped position, clamped to 0..=limit, is that of the
                // position, and the truncation below stays in i32 range.
                let clamped = position.max(-1.0).min(limit_f);
                let t = clamped as i32;
                let ceiling = t + i32::from((t as f32) < clamped);
                *lane = ceiling.clamp(0, limit) as u32;
            }
            let take = LANES.min(count - first);
            boundaries.cells[at + first..at + first + take].copy_from_slice(&lanes[..take]);
        }
        at += count;
    }
    boundaries
}

/// Boundary `i` along `axis` by the rule's formula, one at a time (the reference of [`voxel_boundaries`]).
#[cfg(test)]
fn boundary_scalar(expanded: &ExpandedBox, lattice: &YawLattice, axis: usize, i: usize) -> u32 {
    let face = expanded.lo[axis] + i as f32 * expanded.cell[axis];
    // Ties (a cell centre on a face, common: centres and sizes are round numbers) go to the voxel above
    // the face, robustly against rounding.
    let first = super::scene::ceil_to_i64((face - lattice.origin[axis]) / lattice.cell - 0.5 - TIE_CELLS);
    first.clamp(0, lattice.cells[axis] as i64) as u32
}

pub(crate) fn key_of(hyp: &Hypothesis) -> TableKey {
    TableKey { yaw_index: hyp.yaw_index, bottom_bits: hyp.bottom.to_bits(), height_bits: hyp.size.z.to_bits() }
}

/// The output rows of one table group's hypotheses, with their hypothesis indices.
type GroupRows<'a> = Vec<(usize, &'a mut [f32])>;

/// Hypotheses that share a [`LayerTable`]: same yaw, bottom and height.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct TableKey {
    pub(crate) yaw_index: u16,
    bottom_bits: u32,
    height_bits: u32,
}

/// Groups hypothesis indices by table key, in a deterministic order.
pub(crate) fn group_by_table(hypotheses: &[Hypothesis]) -> Vec<(TableKey, Vec<usize>)> {
    // Pieces grouped in parallel, merged in piece order: each group's members stay in ascending order.
    const PIECE: usize = 1 << 16;
    let pieces: Vec<FxHashMap<TableKey, Vec<usize>>> = hypotheses
        .par_chunks(PIECE)
        .enumerate()
        .map(|(p, piece)| {
            let mut groups: FxHashMap<TableKey, Vec<usize>> = FxHashMap::default();
            for (n, hyp) in piece.iter().enumerate() {
                groups.entry(key_of(hyp)).or_default().push(p * PIECE + n);
            }
            groups
        })
        .collect();
    let mut groups: FxHashMap<TableKey, Vec<usize>> = FxHashMap::default();
    for piece in pieces {
        for (key, members) in piece {
            groups.entry(key).or_default().extend(members);
        }
    }
    let mut groups: Vec<_> = groups.into_iter().collect();
    groups.sort_by_key(|(key, _)| *key);
    groups
}

impl YawLattice {
    /// Cells along s and t.
    pub fn cells(&self) -> [usize; 2] {
        self.cells
    }

    /// The binned points, grouped by height (in binning order within each 5 cm height bucket).
    pub fn points(&self) -> &[LatticePoint] {
        &self.points
    }

    fn build(
        scene: &FeatureScene,
        grid: &YawGrid,
        subdivisions: u32,
        cog_scale: f32,
        layout: &FeatureLayout,
    ) -> YawLattice {
        let cell = grid.step / subdivisions as f32;
        let cells = [0, 1].map(|a| (grid.cells[a] * subdivisions) as usize);
        let origin = grid.origin;
        let intrinsics = scene.pre.camera.intrinsics;
        let use_cog = layout.groups.cog;
        let points = grid
            .records
            .par_iter()
            .map(|r| {
                let q = Vec3::new(r.s as f32, r.t as f32, r.z as f32) / FIXED_PER_METRE;
                let index = |axis: usize| -> usize {
                    floor_to_i64((q[axis] - origin[axis]) / cell).clamp(0, cells[axis] as i64 - 1) as usize
                };
                // A normal bin below 2⁸ (25 bins): the packed `bins` hold it whole.
                let mut point = LatticePoint {
                    cell: (index(1) * cells[0] + index(0)) as u32,
                    z: q.z,
                    bins: r.normal_bin & 0xff,
                    ..LatticePoint::default()
                };
                if use_cog && r.magnitude > 0.0 {
                    if let Some(frame) = cog_frame(grid, intrinsics, q) {
                        let (bin0, frac) = cog_position(&frame, r.gx, r.gy);
                        let scaled = r.magnitude * cog_scale;
                        point.bins |= ((bin0 as u32) << 8) | ((((bin0 + 1) % COG_BINS) as u32) << 16);
                        point.share0 = ((1.0 - frac) * scaled + 0.5) as u32;
                        point.share1 = (frac * scaled + 0.5) as u32;
                    }
                }
                point
            })
            .collect();
        let (points, z_buckets) = ZBuckets::sort(points);
        YawLattice { origin, cell, cells, points, z_buckets }
    }
}

impl LayerTable {
    /// The table of `span`'s layers over the cells of `region`.
    fn build(lattice: &YawLattice, span: TableSpan, region: CellRegion) -> LayerTable {
        let TableSpan { z_lo, inv_step, layers } = span;
        let CellRegion { lo, hi } = region;
        let stride = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1];
        let cs = lattice.cells[0];
        let per_layer = stride[0] * stride[1];
        let mut sums = vec![0u32; layers * per_layer * CHANNELS];
        // Only the points of the buckets around the span, each tested as before: a point is in layer
        // `⌊(z − z_lo)·inv_step⌋` when that is in `0..layers` (truncation is the floor for positions ≥ 0). The
        // upper end has one layer of margin: the test, not the bucket range, decides.
        let z_hi = z_lo + (layers + 1) as f32 / inv_step;
        for p in &lattice.points[lattice.z_buckets.range(z_lo, z_hi)] {
            let position = (p.z - z_lo) * inv_step;
            if !(position >= 0.0 && position < layers as f32) {
                continue;
            }
            let layer = position as usize;
            let (x, y) = (p.cell as usize % cs, p.cell as usize / cs);
            if x < lo[0] || x >= hi[0] || y < lo[1] || y >= hi[1] {
                continue;
            }
            let (x, y) = (x - lo[0], y - lo[1]);
            // Cell (x, y) of the region is stored at table entry (x + 1, y + 1) before the prefix sums.
            let base = ((layer * stride[1] + y + 1) * stride[0] + x + 1) * CHANNELS;
            let entry = &mut sums[base..base + CHANNELS];
            entry[0] += 1;
            entry[1 + p.normal_bin()] += 1;
            entry[COG + p.cog_bin(0)] = entry[COG + p.cog_bin(0)].wrapping_add(p.share0);
            entry[COG + p.cog_bin(1)] = entry[COG + p.cog_bin(1)].wrapping_add(p.share1);
        }
        // Inclusive 2D prefix sums per layer in one pass over the rows (a layer is often larger than the
        // cache; two passes, along s then along t, read it twice): entry (x, y) = entry (x, y − 1) + the
        // running sum of row y up to x. Row 0 and column 0 are the zero border. The counts (channel 0) are
        // copied out in the same pass.
        let mut counts = vec![0u32; layers * per_layer];
        sums.par_chunks_mut(per_layer * CHANNELS).zip(counts.par_chunks_mut(per_layer)).for_each(
            |(layer, layer_counts)| {
                let row_words = stride[0] * CHANNELS;
                for y in 1..stride[1] {
                    let (rows_before, rows_from) = layer.split_at_mut(y * row_words);
                    let above = &rows_before[(y - 1) * row_words..];
                    let row = &mut rows_from[..row_words];
                    let row_counts = &mut layer_counts[y * stride[0]..(y + 1) * stride[0]];
                    let mut running = [0u32; CHANNELS];
                    for x in 1..stride[0] {
                        let entry = &mut row[x * CHANNELS..(x + 1) * CHANNELS];
                        let up = &above[x * CHANNELS..(x + 1) * CHANNELS];
                        for ch in 0..CHANNELS {
                            running[ch] = running[ch].wrapping_add(entry[ch]);
                            entry[ch] = up[ch].wrapping_add(running[ch]);
                        }
                        row_counts[x] = entry[0];
                    }
                }
            },
        );
        LayerTable { sums, counts, stride, origin: lo }
    }

    /// All entries, layer by layer, `(k·stride[1] + y)·stride[0] + x` entries of [`CHANNELS`] words each
    /// (the GPU's layout).
    pub(crate) fn sums(&self) -> &[u32] {
        &self.sums
    }

    /// The point count of layer `k` at entry (x, y) (channel 0 of [`LayerTable::entry`], from the compact
    /// table).
    fn count(&self, k: usize, x: usize, y: usize) -> u32 {
        self.counts[(k * self.stride[1] + y) * self.stride[0] + x]
    }

    /// Entry (x, y) of layer `k` — the sums over the region's first `x` cells along s and first `y` along
    /// t — in place.
    fn entry(&self, k: usize, x: usize, y: usize) -> &[u32; CHANNELS] {
        let base = ((k * self.stride[1] + y) * self.stride[0] + x) * CHANNELS;
        self.sums[base..base + CHANNELS].try_into().expect("CHANNELS entries")
    }
}

/// Convenience: fused scores on the fast path, the same signature as [`super::cpu::scores`] but without
/// the point·voxel count (the fast path does not visit points per hypothesis; 0 is returned).
pub fn scores(
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    weights: &[Vec<f32>],
    options: FastOptions,
) -> (Vec<f32>, u64) {
    let engine = FastEngine::new(scene, layout, options);
    (engine.scores(hypotheses, weights), 0)
}

/// Convenience: features on the fast path (row-major).
pub fn features(
    scene: &FeatureScene,
    layout: &FeatureLayout,
    hypotheses: &[Hypothesis],
    options: FastOptions,
) -> Vec<f32> {
    FastEngine::new(scene, layout, options).features(hypotheses)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scores from the tables of the groups' regions ([`CellRegion`], what `scores` builds) equal, bit for
    /// bit, scores from the whole lattice's tables with the voxels added in index order: on the real frame,
    /// the bed's and the chair's windows at 0.2 m, all hypotheses, and the half of them on one side of the
    /// room (whose regions are smaller than the lattice).
    #[test]
    fn tables_of_a_region_score_as_the_whole_lattices_tables() {
        use crate::features::hypotheses::SizeQuantiles;
        use crate::features::window::{PreparedWindow, DEFAULT_SIZE_STATS};
        use crate::frame::{DepthSource, Frame};
        use std::collections::HashMap;

        let frame = Frame::read("../shared/data/sunrgbd/kv1-b3dodata-img_0063", DepthSource::Raw).unwrap();
        let layout = FeatureLayout::default();
        let mut smaller_regions = 0;
        for category in ["bed", "chair"] {
            let sizes = SizeQuantiles::from_stats_file(std::path::Path::new(DEFAULT_SIZE_STATS), category).unwrap();
            let window = PreparedWindow::new(&frame, sizes.sizes(), 0.2, 50).unwrap();
            let engine = FastEngine::new(&window.scene, &layout, FastOptions::default());
            let weights: Vec<f32> = (0..layout.dim()).map(|n| ((n * 7919 % 2001) as f32 - 1000.0) * 1e-3).collect();
            let all = &window.set.hypotheses;
            let middle = {
                let mut s: Vec<f32> = all.iter().map(|h| h.centre.x).collect();
                s.sort_by(f32::total_cmp);
                s[s.len() / 2]
            };
            let half: Vec<Hypothesis> = all.iter().filter(|h| h.centre.x < middle).copied().collect();
            assert!(all.len() > 1000 && !half.is_empty());
            let mut whole_tables: HashMap<TableKey, LayerTable> = HashMap::new();
            for hypotheses in [all.as_slice(), half.as_slice()] {
                let scores = engine.scores(hypotheses, std::slice::from_ref(&weights));
                for (hyp, &score) in hypotheses.iter().zip(&scores) {
                    let table = whole_tables.entry(key_of(hyp)).or_insert_with(|| engine.table(key_of(hyp)));
                    let mut dots = vec![0.0f32; layout.voxel_count()];
                    let bounds = engine.voxel_boundaries(&ExpandedBox::new(&layout, hyp), hyp.yaw_index);
                    engine.hypothesis(table, hyp, &bounds, |voxel, values| {
                        dots[voxel] = dot_lanes(&weights[voxel * PER_VOXEL..(voxel + 1) * PER_VOXEL], values);
                    });
                    let mut expected = dots.iter().fold(0.0f32, |sum, &d| sum + d);
                    let offset = layout.view_offset();
                    expected += dot(&weights[offset..offset + VIEW], &engine.view(hyp));
                    assert_eq!(score.to_bits(), expected.to_bits(), "{category} {hyp:?}: {score} vs {expected}");
                }
                for (key, members) in group_by_table(hypotheses) {
                    let lattice = engine.lattice(key.yaw_index as usize);
                    let bounds = members.iter().map(|&n| {
                        voxel_boundaries(&layout.grid(), &ExpandedBox::new(&layout, &hypotheses[n]), lattice)
                    });
                    let region = CellRegion::of_boundaries(bounds).unwrap();
                    smaller_regions += usize::from(region != CellRegion::whole(lattice));
                }
            }
        }
        assert!(smaller_regions > 0);
    }

    /// `voxel_boundaries` (eight lanes at a time) equals the rule applied one boundary at a time, for grids
    /// of every width up to 19 boundaries per axis, boxes inside, across and outside the lattice, faces on
    /// cell-centre ties, and NaN positions.
    #[test]
    fn lane_boundaries_equal_the_rule_one_at_a_time() {
        let lattice = |origin: [f32; 2], cell: f32, cells: [usize; 2]| YawLattice {
            origin,
            cell,
            cells,
            points: Vec::new(),
            z_buckets: ZBuckets { z_min: 0.0, offsets: Vec::new() },
        };
        let lattices = [
            lattice([-3.05, 0.45], 0.05, [140, 96]),
            lattice([0.0, 0.0], 0.1, [7, 3]),
            lattice([-1.0e-3, 2.5], 0.025, [1, 400]),
        ];
        let mut seed = 11u64;
        let mut uniform = |lo: f32, hi: f32| {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((seed >> 40) as f32 / (1u64 << 24) as f32)
        };
        let mut checked = 0;
        for lattice in &lattices {
            for n in 0..3000 {
                let g = [1 + n % 18, 1 + (n / 18) % 18, 1];
                let cell = [uniform(0.01, 0.6), uniform(0.01, 0.6), 0.1];
                let mut lo = [uniform(-10.0, 10.0), uniform(-10.0, 10.0), 0.0];
                if n % 5 == 0 {
                    // Faces on cell-centre ties: lo at origin + (k + ½)·cell, a cell that divides the lattice's.
                    for (l, origin) in lo.iter_mut().zip(lattice.origin) {
                        *l = origin + ((n % 37) as f32 + 0.5) * lattice.cell;
                    }
                }
                if n == 7 {
                    lo[0] = f32::NAN;
                }
                let expanded = ExpandedBox { lo, cell, extent: Vec3::ZERO };
                let got = voxel_boundaries(&g, &expanded, lattice);
                let expected: Vec<u32> = (0..2)
                    .flat_map(|axis| (0..=g[axis] as usize).map(move |i| (axis, i)))
                    .map(|(axis, i)| boundary_scalar(&expanded, lattice, axis, i))
                    .collect();
                assert_eq!(got.all(), expected.as_slice(), "grid {g:?}, box {lo:?} {cell:?}");
                assert_eq!(got.xs().len(), g[0] as usize + 1);
                checked += expected.len();
            }
        }
        assert!(checked > 100_000);
    }
}
