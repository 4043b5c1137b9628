//! The feature layout: THE one place that fixes the order of a hypothesis' feature vector. Model files
//! name it by [`FeatureLayout::id`] and must be rejected when the id differs.
//!
//! # Order of the feature vector
//! ```text
//! for ℓ in 0..voxel_count:            ℓ = (k·ny + j)·nx + i   (i fastest)
//!     [ℓ·35 + 0]        density        N/A                       (group Density)
//!     [ℓ·35 + 1 ..= 25] normal bins    count in bin / A          (group Normals; bins: preprocess::normal_bin)
//!     [ℓ·35 + 26 ..= 34] COG bins 0..8 φ/√(‖φ‖² + ε)              (group Cog)
//! [voxel_count·35 + 0 ..= 10]          view RBFs, centres −1, −0.8, …, 1   (group View)
//! [voxel_count·35 + 11]                view bias = 1                        (group View)
//! [voxel_count·35 + 12 + ℓ]            1 when voxel ℓ's centre is out of the picture, else 0
//!                                      (group OutOfView; present only when it is on)
//! ```
//! Voxel index `(i, j, k)` of the (possibly expanded) grid `[nx, ny, nz]`: `i` along the cuboid's width
//! axis from its left side, `j` along the depth axis from its **front**, `k` up from the bottom — the same
//! convention as [`crate::geometry::voxel_corners`]. With `expanded`, the grid is the base grid plus one voxel
//! layer on each side (5×5×5 → 7×7×7) and the voxels keep the base grid's size, so the expanded box is
//! the cuboid scaled by `(n+2)/n` per axis about its centre.
//!
//! Switching a group off does not change the order or the length: its entries are zero in the feature
//! vector (the engine skips them) and a model's weights for them must be zero. The exception is the
//! out-of-view group ([`Groups::out_of_view`], added 2026-12-06, after every model before it was
//! trained): its `voxel_count` entries follow the view features only when it is on, so the layouts
//! without it keep their length and their id, and every earlier model file stays valid.
//!
//! # Out of view (not in the paper)
//! A voxel whose centre does not project onto the image (or lies less than
//! [`crate::geometry::MIN_PROJECT_DEPTH`] in front of the camera) has no points — or only those of its
//! part in view — because the camera cannot see it, not because it is empty; its 35 features look like
//! those of an empty voxel all the same.
//! The group's entry ℓ is 1 for such a voxel, so a model can learn, per voxel position, what the
//! missing evidence is worth — a bed beside the camera whose foot alone is in the picture scores its
//! out-of-view voxels with those weights instead of nothing. Occlusion is not considered (a voxel behind
//! a nearer surface counts as in view). Computed by [`super::out_of_view`] alike for every path. The id names the grid,
//! expansion and the groups, so a model trained with "Geom" features only cannot be applied to a
//! Geom+COG layout by mistake.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Features per voxel: density, 25 normal bins, 9 COG bins.
pub const PER_VOXEL: usize = 35;
/// Offset of the density inside a voxel's block.
pub const DENSITY: usize = 0;
/// Offset of the first normal bin inside a voxel's block.
pub const NORMALS: usize = 1;
/// Offset of the first COG bin inside a voxel's block.
pub const COG: usize = 26;
/// Number of COG orientation bins.
pub const COG_BINS: usize = 9;
/// View-to-camera features: 11 RBFs and a bias.
pub const VIEW: usize = 12;
/// Number of view RBFs.
pub const VIEW_RBFS: usize = 11;
/// RBF bandwidth of the view features (paper §3.3.1).
pub const VIEW_SIGMA: f32 = 0.5;
/// ε of the COG normalisation `φ/√(‖φ‖² + ε)`. Gradients are on [0, 1] intensities (magnitudes ≤ √2), so
/// a voxel whose accumulated magnitudes have norm 0.1 — a handful of weak edge pixels — is scaled to ~0.7
/// and noise in near-empty voxels is not blown up to unit length.
pub const COG_EPSILON: f32 = 0.01;
/// Version of the layout definition (bump when the meaning of any entry changes).
pub const LAYOUT_VERSION: u32 = 1;

/// Feature groups that can be switched off (the paper's ablation, Table 1; "expanded" is
/// [`FeatureLayout::expanded`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Groups {
    pub density: bool,
    pub normals: bool,
    pub cog: bool,
    pub view: bool,
    /// Per-voxel out-of-view indicators (see the module doc). Written into a file only when on, so the
    /// files of layouts without it read and write as before it existed.
    #[serde(default, skip_serializing_if = "is_false")]
    pub out_of_view: bool,
}

fn is_false(on: &bool) -> bool {
    !*on
}

impl Groups {
    /// The paper's groups (the out-of-view indicators are not among them).
    pub const ALL: Groups = Groups { density: true, normals: true, cog: true, view: true, out_of_view: false };
    /// The paper's "Geom": density and normals.
    pub const GEOM: Groups = Groups { density: true, normals: true, cog: false, view: false, out_of_view: false };
    /// No group on (to switch groups on one by one).
    pub const NONE: Groups = Groups { density: false, normals: false, cog: false, view: false, out_of_view: false };

    fn names(&self) -> Vec<&'static str> {
        let mut names = Vec::new();
        for (on, name) in [
            (self.density, "density"),
            (self.normals, "normals"),
            (self.cog, "cog"),
            (self.view, "view"),
            (self.out_of_view, "out-of-view"),
        ] {
            if on {
                names.push(name);
            }
        }
        names
    }
}

/// Grid, expansion and groups of a feature vector.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FeatureLayout {
    /// Voxels of the cuboid itself along (width, depth, height).
    pub base_grid: [u32; 3],
    /// Add one voxel layer on each side (paper §3.3.2).
    pub expanded: bool,
    pub groups: Groups,
}

/// Largest voxel count along z the kernels accept (per-thread accumulators are sized to it).
pub const MAX_GRID_Z: u32 = 9;
/// Largest `nx·ny` the kernels accept (one invocation per voxel column, one workgroup per hypothesis).
pub const MAX_COLUMNS: u32 = 64;

impl Default for FeatureLayout {
    /// The paper's: 5×5×5 expanded to 7×7×7, all groups (12017 dimensions).
    fn default() -> Self {
        FeatureLayout { base_grid: [5, 5, 5], expanded: true, groups: Groups::ALL }
    }
}

impl FeatureLayout {
    pub fn new(base_grid: [u32; 3], expanded: bool, groups: Groups) -> Result<FeatureLayout> {
        let layout = FeatureLayout { base_grid, expanded, groups };
        layout.validate()?;
        Ok(layout)
    }

    /// Checks the grid against the kernels' limits: every axis ≥ 1, `nz ≤` [`MAX_GRID_Z`],
    /// `nx·ny ≤` [`MAX_COLUMNS`] (after expansion).
    pub fn validate(&self) -> Result<()> {
        let g = self.grid();
        if self.base_grid.contains(&0) {
            return Err(Error::Input(format!("voxel grid {:?} has an empty axis", self.base_grid)));
        }
        if g[2] > MAX_GRID_Z || g[0] * g[1] > MAX_COLUMNS {
            return Err(Error::Input(format!(
                "voxel grid {}x{}x{} is too large: at most {MAX_GRID_Z} voxels along z and {MAX_COLUMNS} columns (nx·ny)",
                g[0], g[1], g[2]
            )));
        }
        Ok(())
    }

    /// The voxel grid features are computed on (the base grid, expanded by 2 per axis when `expanded`).
    pub fn grid(&self) -> [u32; 3] {
        let extra = if self.expanded { 2 } else { 0 };
        self.base_grid.map(|n| n + extra)
    }

    pub fn voxel_count(&self) -> usize {
        self.grid().iter().map(|&n| n as usize).product()
    }

    /// Length of the feature vector.
    pub fn dim(&self) -> usize {
        self.out_of_view_offset() + self.out_of_view_len()
    }

    /// Offset of the out-of-view indicators (the end of the vector when the group is off).
    pub fn out_of_view_offset(&self) -> usize {
        self.view_offset() + VIEW
    }

    /// Number of out-of-view indicators: one per voxel when the group is on, else 0.
    pub fn out_of_view_len(&self) -> usize {
        if self.groups.out_of_view {
            self.voxel_count()
        } else {
            0
        }
    }

    /// The layout with the out-of-view group off: the part of the vector every path computes from the
    /// points (the GPU kernels compute it; the indicators are added on the CPU, [`super::out_of_view`]).
    pub fn without_out_of_view(&self) -> FeatureLayout {
        FeatureLayout { groups: Groups { out_of_view: false, ..self.groups }, ..*self }
    }

    /// Voxel index ℓ of voxel (i, j, k).
    pub fn voxel_index(&self, i: u32, j: u32, k: u32) -> usize {
        let [nx, ny, _] = self.grid();
        ((k * ny + j) * nx + i) as usize
    }

    /// Offset of the view features.
    pub fn view_offset(&self) -> usize {
        self.voxel_count() * PER_VOXEL
    }

    /// Scale from the cuboid's size to the box the voxel grid covers (`(n+2)/n` per axis when expanded).
    pub fn expansion(&self) -> [f32; 3] {
        let g = self.grid();
        [0, 1, 2].map(|a| g[a] as f32 / self.base_grid[a] as f32)
    }

    /// The layout id written into model files, e.g.
    /// `cog-v1 grid=5x5x5 expanded=1 groups=density,normals,cog,view`.
    pub fn id(&self) -> String {
        let [x, y, z] = self.base_grid;
        format!(
            "cog-v{LAYOUT_VERSION} grid={x}x{y}x{z} expanded={} groups={}",
            u8::from(self.expanded),
            self.groups.names().join(",")
        )
    }

    /// Per-entry mask: `true` where the entry belongs to a group that is switched on.
    pub fn mask(&self) -> Vec<bool> {
        let mut mask = Vec::with_capacity(self.dim());
        for _ in 0..self.voxel_count() {
            mask.push(self.groups.density);
            mask.extend(std::iter::repeat_n(self.groups.normals, COG - NORMALS));
            mask.extend(std::iter::repeat_n(self.groups.cog, COG_BINS));
        }
        mask.extend(std::iter::repeat_n(self.groups.view, VIEW));
        mask.extend(std::iter::repeat_n(true, self.out_of_view_len()));
        mask
    }

    /// Human-readable name of entry `index` (for reports and debugging).
    pub fn describe(&self, index: usize) -> String {
        if index >= self.dim() {
            return format!("#{index} (past the end)");
        }
        let [nx, ny, _] = self.grid();
        let voxel_name = |voxel: usize| {
            let (i, j, k) = (voxel as u32 % nx, (voxel as u32 / nx) % ny, voxel as u32 / (nx * ny));
            format!("voxel ({i},{j},{k})")
        };
        if index >= self.out_of_view_offset() {
            return format!("{} out of view", voxel_name(index - self.out_of_view_offset()));
        }
        if index >= self.view_offset() {
            let v = index - self.view_offset();
            return if v < VIEW_RBFS { format!("view rbf {v}") } else { "view bias".into() };
        }
        let (voxel, slot) = (index / PER_VOXEL, index % PER_VOXEL);
        let what = match slot {
            DENSITY => "density".to_string(),
            s if s < COG => format!("normal bin {}", s - NORMALS),
            s => format!("cog bin {}", s - COG),
        };
        format!("{} {what}", voxel_name(voxel))
    }
}

/// The 12 view-to-camera features of a hypothesis (paper §3.3.1) from `x`, the cosine of the horizontal
/// angle between the cuboid's front and the direction from the cuboid's centre to the camera (1: facing
/// the camera, −1: facing away): `exp(−(x − μ_j)²/(2σ²))` for μ_j = −1 + 0.2·j, j = 0..10, then 1.
pub fn view_features(x: f32) -> [f32; VIEW] {
    let mut out = [1.0f32; VIEW];
    for (j, slot) in out.iter_mut().take(VIEW_RBFS).enumerate() {
        let mu = -1.0 + 0.2 * j as f32;
        let d = x - mu;
        *slot = (-(d * d) / (2.0 * VIEW_SIGMA * VIEW_SIGMA)).exp();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_layout_has_the_papers_dimension() {
        assert_eq!(FeatureLayout::default().dim(), 343 * 35 + 12);
        assert_eq!(FeatureLayout::default().dim(), 12017);
        let small = FeatureLayout::new([3, 1, 3], true, Groups::ALL).unwrap();
        assert_eq!(small.grid(), [5, 3, 5]);
        assert_eq!(small.dim(), 75 * 35 + 12);
    }

    #[test]
    fn describe_inverts_the_index_order() {
        let layout = FeatureLayout::default();
        let idx = layout.voxel_index(2, 3, 4) * PER_VOXEL + COG + 5;
        assert_eq!(layout.describe(idx), "voxel (2,3,4) cog bin 5");
        assert_eq!(layout.describe(layout.dim() - 1), "view bias");
        let with = FeatureLayout::new([5, 5, 5], true, Groups { out_of_view: true, ..Groups::ALL }).unwrap();
        assert_eq!(with.describe(with.dim() - 1), "voxel (6,6,6) out of view");
        assert_eq!(with.describe(with.out_of_view_offset() + 8), "voxel (1,1,0) out of view");
        assert_eq!(with.describe(with.out_of_view_offset() - 1), "view bias");
    }

    #[test]
    fn out_of_view_entries_follow_the_view_only_when_on() {
        let without = FeatureLayout::default();
        let with = FeatureLayout { groups: Groups { out_of_view: true, ..Groups::ALL }, ..without };
        assert_eq!(with.dim(), 12017 + 343);
        assert_eq!(with.out_of_view_offset(), 12017);
        assert_eq!(with.without_out_of_view(), without);
        assert_eq!(without.id(), "cog-v1 grid=5x5x5 expanded=1 groups=density,normals,cog,view");
        assert_eq!(with.id(), "cog-v1 grid=5x5x5 expanded=1 groups=density,normals,cog,view,out-of-view");
        let mask = with.mask();
        assert_eq!(mask.len(), with.dim());
        assert!(mask[12017..].iter().all(|&m| m));
        // A model file written before the group existed reads with the group off.
        let text = r#"{"density":true,"normals":true,"cog":true,"view":false}"#;
        let old: Groups = serde_json::from_str(text).unwrap();
        assert_eq!(old, Groups { view: false, ..Groups::ALL });
        assert_eq!(serde_json::to_string(&old).unwrap(), text, "written as before the group existed");
        assert!(serde_json::to_string(&with.groups).unwrap().ends_with(r#""view":true,"out_of_view":true}"#));
    }

    #[test]
    fn mask_follows_groups() {
        let layout = FeatureLayout::new([1, 1, 1], false, Groups::GEOM).unwrap();
        let mask = layout.mask();
        assert_eq!(mask.len(), 35 + 12);
        assert_eq!(mask.iter().filter(|&&m| m).count(), 26);
        assert!(layout.id().contains("groups=density,normals"));
    }

    #[test]
    fn view_rbf_peaks_at_its_centre() {
        let f = view_features(0.2);
        assert!((f[6] - 1.0).abs() < 1e-6); // μ_6 = 0.2
        assert!((f[5] - (-0.04f32 / 0.5).exp()).abs() < 1e-6); // (0.2 − 0)²/(2·0.25)
        assert_eq!(f[11], 1.0);
    }
}
