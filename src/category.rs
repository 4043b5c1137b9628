//! The 19 object categories of the paper's Table 2, and SUN RGB-D name normalisation.

/// The detector's categories, in the paper's order (Table 2). The first ten are the "large" benchmark
/// categories of SUN RGB-D.
pub const CATEGORIES: [&str; 19] = [
    "bed",
    "chair",
    "sofa",
    "table",
    "desk",
    "toilet",
    "bathtub",
    "dresser",
    "nightstand",
    "bookshelf",
    "box",
    "door",
    "counter",
    "garbage_bin",
    "sink",
    "pillow",
    "monitor",
    "tv",
    "lamp",
];

/// The ten large categories of the SUN RGB-D 3D detection benchmark: the first ten of [`CATEGORIES`].
pub const LARGE_CATEGORIES: &[&str] = CATEGORIES.split_at(10).0;

/// The categories whose models score each other's detections for the context cascade's cross part
/// (`crate::detect::cross_scores`, `crate::cascade`'s feature set v7; our addition, not in the paper): the
/// ten large categories and the counter — the furniture that stands on the floor, whose detections the
/// diagnosis finds taken for one another most often (tables for desks, dressers for counters, sofas for
/// beds). Chosen as the set of the categories confused with each other, before any measurement of the
/// cross part; kept fixed so that ψ has the same length for every cascade.
pub const CROSS_SCORE_CATEGORIES: [&str; 11] =
    ["bed", "chair", "sofa", "table", "desk", "toilet", "bathtub", "dresser", "nightstand", "bookshelf", "counter"];

/// Whether `category` is one of [`CROSS_SCORE_CATEGORIES`].
pub fn is_cross_score_category(category: &str) -> bool {
    CROSS_SCORE_CATEGORIES.contains(&category)
}

/// The categories whose objects carry a support surface that other objects stand on (paper §4: "beds,
/// tables, desks, dressers, nightstands and the like"; the like, here: a sofa's seat, which carries
/// cushions and pillows, and a counter's top, which carries sinks): detections of these report a surface
/// height (`crate::features::surface`), from the model's latent slice or measured from the points, and
/// the small categories whose models say so (`"support": "surfaces"`: the shipped monitor;
/// `"floor+surfaces"`: the shipped sink) are searched on the surfaces of their supporters
/// ([`SurfaceCategories`]; `crate::features::hypotheses::surface_window`).
pub const SURFACE_CATEGORIES: [&str; 7] = ["bed", "table", "desk", "dresser", "nightstand", "sofa", "counter"];

/// A set of [`SURFACE_CATEGORIES`] (bit `k` for category `k`): the supporters whose surfaces a model's
/// surface window searches (a model file's `window.supporters`, a list of names; absent: all of them).
/// `train` stores the categories whose annotated surfaces held at least one of its training positives —
/// the generator's sinks stand on counters only, and a basin searched on a bed is the size of a pillow.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "Vec<String>", into = "Vec<String>")]
pub struct SurfaceCategories(u8);

impl SurfaceCategories {
    /// Every surface category.
    pub const ALL: SurfaceCategories = SurfaceCategories((1 << SURFACE_CATEGORIES.len()) - 1);
    /// None.
    pub const NONE: SurfaceCategories = SurfaceCategories(0);

    /// Whether the set holds every surface category (what a file without the field means).
    pub fn is_all(&self) -> bool {
        *self == SurfaceCategories::ALL
    }

    /// Whether `category` is in the set (never, for a category that carries no surface).
    pub fn contains(self, category: &str) -> bool {
        SURFACE_CATEGORIES.iter().position(|c| *c == category).is_some_and(|k| self.0 & (1 << k) != 0)
    }

    /// The set with `category` added; `None` when it is not a surface category.
    pub fn with(self, category: &str) -> Option<SurfaceCategories> {
        let k = SURFACE_CATEGORIES.iter().position(|c| *c == category)?;
        Some(SurfaceCategories(self.0 | (1 << k)))
    }

    /// The names in the set, in [`SURFACE_CATEGORIES`] order.
    pub fn names(self) -> Vec<&'static str> {
        SURFACE_CATEGORIES.iter().enumerate().filter(|(k, _)| self.0 & (1 << k) != 0).map(|(_, c)| *c).collect()
    }
}

impl Default for SurfaceCategories {
    fn default() -> Self {
        SurfaceCategories::ALL
    }
}

impl TryFrom<Vec<String>> for SurfaceCategories {
    type Error = String;
    fn try_from(names: Vec<String>) -> Result<Self, String> {
        names.iter().try_fold(SurfaceCategories::NONE, |set, name| {
            set.with(name).ok_or_else(|| {
                format!("'{name}' is not a category with a support surface (one of {})", SURFACE_CATEGORIES.join(", "))
            })
        })
    }
}

impl From<SurfaceCategories> for Vec<String> {
    fn from(set: SurfaceCategories) -> Vec<String> {
        set.names().into_iter().map(String::from).collect()
    }
}

/// Annotation names that are room structure, not objects; the frame reader skips them.
pub const STRUCTURE_NAMES: [&str; 4] = ["wall", "floor", "ceiling", "room"];

/// Splits a SUN RGB-D annotation name `class:label` into (class, label) and normalises the class:
/// lower case, trimmed, spaces and dashes to `_`, and the dataset's spellings of our categories mapped
/// to ours (`night_stand` → `nightstand`, `garbage bin` → `garbage_bin`, `television` → `tv`, ...).
pub fn normalise_name(raw: &str) -> (String, Option<String>) {
    let (class, label) = match raw.split_once(':') {
        Some((c, l)) => (c, Some(l.trim().to_string()).filter(|l| !l.is_empty())),
        None => (raw, None),
    };
    let mut class: String =
        class.trim().to_lowercase().chars().map(|c| if c == ' ' || c == '-' { '_' } else { c }).collect();
    let alias = match class.as_str() {
        "night_stand" | "nightstands" => Some("nightstand"),
        "garbage" | "garbagebin" | "trash_can" | "trash_bin" | "recycle_bin" => Some("garbage_bin"),
        "television" | "tv_stand_tv" => Some("tv"),
        "book_shelf" | "bookcase" | "shelf_bookshelf" => Some("bookshelf"),
        "computer_monitor" => Some("monitor"),
        "bath_tub" => Some("bathtub"),
        _ => None,
    };
    if let Some(alias) = alias {
        class = alias.to_string();
    }
    (class, label)
}

/// Index of a category in [`CATEGORIES`].
pub fn category_index(name: &str) -> Option<usize> {
    CATEGORIES.iter().position(|c| *c == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_split_and_normalise() {
        assert_eq!(normalise_name("chair"), ("chair".into(), None));
        assert_eq!(normalise_name("Night Stand:left one"), ("nightstand".into(), Some("left one".into())));
        assert_eq!(normalise_name("garbage bin"), ("garbage_bin".into(), None));
        assert_eq!(normalise_name("books:"), ("books".into(), None));
        assert_eq!(category_index("lamp"), Some(18));
        assert_eq!(category_index("books"), None);
        assert_eq!(LARGE_CATEGORIES.len(), 10);
        assert_eq!(LARGE_CATEGORIES[9], "bookshelf");
    }
}
