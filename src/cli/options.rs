//! One range check per numeric option, shared by every command that takes it (`score`, `bench`, `train`,
//! `detect`, `eval`), as clap value parsers: a value out of range is refused before any work starts, with
//! clap's message naming the flag, the value and the allowed range, e.g.
//! `invalid value '0' for '--subdivisions <SUBDIVISIONS>': 0 is not in 1..=16`.

use cog_gpu::limits::{check_step, MAX_SUBDIVISIONS};

/// Largest `--candidates` (feature vectors cached per training example).
pub const MAX_CANDIDATES: u64 = 10_000;
/// Largest `--max-iterations`, `--full-every`, `--max-full-passes` and `--prune-after`.
pub const MAX_ITERATIONS: u64 = 100_000;
/// Largest `train --cache-gib` (a machine's memory, not a frame's structure, bounds the cache).
pub const MAX_CACHE_GIB: f64 = 1024.0;
/// Largest `--positives` and `--negatives`.
pub const MAX_EXAMPLES: u64 = 1_000_000;

/// `--step`, `--detect-step`: a centre step in metres within [`cog_gpu::limits::MIN_STEP_M`] …
/// [`cog_gpu::limits::MAX_STEP_M`].
pub fn step(text: &str) -> Result<f32, String> {
    let value: f32 = text.trim().parse().map_err(|_| format!("'{text}' is not a number"))?;
    check_step("the step", value).map_err(|e| e.to_string())?;
    Ok(value)
}

/// `--min-points`: at most one point a pixel of the largest frame ([`cog_gpu::limits::check_min_points`]).
pub fn min_points(text: &str) -> Result<u32, String> {
    let value: u32 = text.trim().parse().map_err(|_| format!("'{text}' is not a whole number ≥ 0"))?;
    cog_gpu::limits::check_min_points("--min-points", value).map_err(|e| e.to_string())?;
    Ok(value)
}

/// `--normals`: how the points' normals find their neighbours (`kdtree`, `window`, `kdtree-40`).
pub fn normal_search(text: &str) -> Result<cog_gpu::features::preprocess::NormalSearch, String> {
    text.trim().parse().map_err(|e: cog_gpu::error::Error| e.to_string())
}

/// A finite number (clap adds the flag and the value to the message).
fn number(text: &str) -> Result<f64, String> {
    let value: f64 = text.trim().parse().map_err(|_| format!("'{text}' is not a number"))?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(format!("{value} is not a finite number"))
    }
}

/// A number in (0, 1]; the error names what it should have been.
fn above_zero_up_to_one(text: &str, what: &str) -> Result<f32, String> {
    let value = number(text)?;
    if value > 0.0 && value <= 1.0 {
        Ok(value as f32)
    } else {
        Err(format!("{value} is not {what} in (0, 1]"))
    }
}

/// `--iou` of `eval` and `calibrate`: a 3D IoU in (0, 1].
pub fn iou(text: &str) -> Result<f32, String> {
    above_zero_up_to_one(text, "an IoU")
}

/// `detect --box-voting` (and `bench --detect --box-voting`): an IoU in (0, 1] ([`iou`]), or `off`
/// (`None`); by default [`DEFAULT_VOTE_IOU`](cog_gpu::nms::DEFAULT_VOTE_IOU), the one place both commands
/// take it from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoxVoting(pub Option<f32>);

impl Default for BoxVoting {
    fn default() -> Self {
        BoxVoting(Some(cog_gpu::nms::DEFAULT_VOTE_IOU))
    }
}

impl std::fmt::Display for BoxVoting {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some(iou) => write!(f, "{iou}"),
            None => f.write_str("off"),
        }
    }
}

pub fn box_voting(text: &str) -> Result<BoxVoting, String> {
    if text == "off" {
        Ok(BoxVoting(None))
    } else {
        iou(text).map(|iou| BoxVoting(Some(iou))).map_err(|e| format!("{e}; give an IoU or `off`"))
    }
}

/// `--unseen-floor on|off` of `detect`, `bench --detect` and `eval --diagnose --models`: whether a frame
/// whose floor is not seen is searched on a second floor too; by default `on`, as
/// [`DetectOptions::default`](cog_gpu::detect::DetectOptions), the one place the three commands take it
/// from. A type of its own rather than `bool`: clap gives a `bool` field the `SetTrue` action, which would
/// hand the parser "true" instead of the word given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnseenFloor(pub bool);

impl Default for UnseenFloor {
    fn default() -> Self {
        UnseenFloor(cog_gpu::detect::DetectOptions::default().unseen_floor)
    }
}

impl std::fmt::Display for UnseenFloor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.0 { "on" } else { "off" })
    }
}

pub fn unseen_floor(text: &str) -> Result<UnseenFloor, String> {
    match text {
        "on" => Ok(UnseenFloor(true)),
        "off" => Ok(UnseenFloor(false)),
        _ => Err(format!("'{text}': give `on` or `off`")),
    }
}

/// `detect --support-min-score`: a probability in [0, 1].
pub fn probability(text: &str) -> Result<f32, String> {
    let value = number(text)?;
    if (0.0..=1.0).contains(&value) {
        Ok(value as f32)
    } else {
        Err(format!("{value} is not a probability in [0, 1]"))
    }
}

/// `eval --ignore-out-of-view`, `train --skip-out-of-view`: a share of a box's volume, in (0, 1].
pub fn share(text: &str) -> Result<f32, String> {
    above_zero_up_to_one(text, "a share")
}

/// `train --c`: the regularisation constant, finite and > 0.
pub fn positive(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if value > 0.0 {
        Ok(value)
    } else {
        Err(format!("{value} is not > 0"))
    }
}

/// `train --eps`: finite and ≥ 0.
pub fn non_negative(text: &str) -> Result<f64, String> {
    let value = number(text)?;
    if value >= 0.0 {
        Ok(value)
    } else {
        Err(format!("{value} is not ≥ 0"))
    }
}

/// A whole number within `min..=max` (clap adds the flag and the value to the message).
fn count(text: &str, min: u64, max: u64) -> Result<u64, String> {
    let value: u64 = text.trim().parse().map_err(|_| format!("'{text}' is not a whole number ≥ 0"))?;
    if (min..=max).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{value} is not in {min}..={max}"))
    }
}

/// `--subdivisions`: 1..=[`MAX_SUBDIVISIONS`].
pub fn subdivisions(text: &str) -> Result<u32, String> {
    Ok(count(text, 1, MAX_SUBDIVISIONS as u64)? as u32)
}

/// `--candidates`: 1..=[`MAX_CANDIDATES`].
pub fn candidates(text: &str) -> Result<usize, String> {
    Ok(count(text, 1, MAX_CANDIDATES)? as usize)
}

/// `--cache-gib`: a finite number of GiB above 0 and at most [`MAX_CACHE_GIB`].
pub fn cache_gib(text: &str) -> Result<f64, String> {
    let value: f64 = text.trim().parse().map_err(|_| format!("'{text}' is not a number of GiB"))?;
    if !(value > 0.0 && value <= MAX_CACHE_GIB) {
        return Err(format!("{text} GiB: the candidate cache's limit must be above 0 and at most {MAX_CACHE_GIB}"));
    }
    Ok(value)
}

/// `--max-iterations`, `--max-full-passes`: 1..=[`MAX_ITERATIONS`].
pub fn iterations(text: &str) -> Result<usize, String> {
    Ok(count(text, 1, MAX_ITERATIONS)? as usize)
}

/// `--full-every` (0 means "never on a schedule"): 0..=[`MAX_ITERATIONS`].
pub fn every(text: &str) -> Result<usize, String> {
    Ok(count(text, 0, MAX_ITERATIONS)? as usize)
}

/// `--positives`: 1..=[`MAX_EXAMPLES`].
pub fn positives(text: &str) -> Result<usize, String> {
    Ok(count(text, 1, MAX_EXAMPLES)? as usize)
}

/// `--negatives`: 0..=[`MAX_EXAMPLES`].
pub fn negatives(text: &str) -> Result<usize, String> {
    Ok(count(text, 0, MAX_EXAMPLES)? as usize)
}

/// `--prune-after`: 1..=u32::MAX solves.
pub fn positive_u32(text: &str) -> Result<u32, String> {
    Ok(count(text, 1, u64::from(u32::MAX))? as u32)
}

/// Counts that must be at least 1 (`--limit`, `--max-per-category`).
pub fn at_least_one(text: &str) -> Result<usize, String> {
    Ok(count(text, 1, usize::MAX as u64)? as usize)
}

/// Comma-separated names (`--categories`, `--rooms`): trimmed; an empty entry ("bed,," or "") is an error
/// naming the flag instead of a silently dropped or empty name.
pub fn names(flag: &str, values: &[String]) -> anyhow::Result<Vec<String>> {
    let names: Vec<String> = values.iter().map(|v| v.trim().to_string()).collect();
    if names.is_empty() {
        return Ok(names);
    }
    if let Some(n) = names.iter().position(String::is_empty) {
        anyhow::bail!("{flag} '{}' has an empty name at position {} (a stray comma?)", values.join(","), n + 1);
    }
    Ok(names)
}

/// Checks, before hours of training, that the model file `out` can be written at the end: its directory is
/// made (as the write would need), `out` is not a directory, and a file can be created beside it (a probe,
/// `<out>.write-check`, removed at once). Errors name the path.
pub fn writable_output_file(out: &std::path::Path) -> anyhow::Result<()> {
    use anyhow::Context;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating the model directory {}", dir.display()))?;
    }
    if out.is_dir() {
        anyhow::bail!("{}: --out is a directory; give the model file's path", out.display());
    }
    let probe = std::path::PathBuf::from(format!("{}.write-check", out.display()));
    std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .open(&probe)
        .with_context(|| format!("{}: cannot write the model file here", out.display()))?;
    std::fs::remove_file(&probe).with_context(|| format!("removing {}", probe.display()))?;
    Ok(())
}

/// `path` made absolute through its nearest existing ancestor (canonicalised: links and `..` resolved),
/// with the parts that do not exist yet appended — a path not created yet can be compared with others.
pub fn resolved(path: &std::path::Path) -> std::path::PathBuf {
    let mut existing = path.to_path_buf();
    let mut rest = Vec::new();
    loop {
        if let Ok(canonical) = existing.canonicalize() {
            return rest.iter().rev().fold(canonical, |p, part| p.join(part));
        }
        match (existing.file_name().map(|n| n.to_os_string()), existing.parent()) {
            (Some(name), Some(parent)) => {
                rest.push(name);
                existing =
                    if parent.as_os_str().is_empty() { std::path::PathBuf::from(".") } else { parent.to_path_buf() };
            }
            _ => return path.to_path_buf(),
        }
    }
}

/// Whether two paths name the same existing directory or file (false when either does not exist yet): an
/// output that is also an input would be overwritten while it is read.
pub fn same_path(a: &std::path::Path, b: &std::path::Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// The `*.json` files of a directory (a detections directory: one `<frame>.json` per frame), sorted.
pub fn json_files(dir: &std::path::Path) -> anyhow::Result<Vec<std::path::PathBuf>> {
    use anyhow::Context;
    let mut paths: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json") && p.is_file())
        .collect();
    paths.sort();
    Ok(paths)
}

/// A detections file read from `text` (of `path`) with its detections replaced by `detections` and every
/// other field kept (the room under "layout"), except `detect`'s `"run"` fingerprint: the result comes from
/// no single detect run (`rescore`, `merge-detections`). Through text, not `to_value`: a value keeps each
/// f32 as the f64 it widens to (0.999159574508667), text keeps the f32's shortest form (0.9991596), as
/// `detect` writes it.
pub fn with_detections(
    text: &str,
    path: &std::path::Path,
    detections: &[cog_gpu::eval::Detection],
) -> anyhow::Result<serde_json::Value> {
    use anyhow::Context;
    let mut file: serde_json::Value = serde_json::from_str(text).with_context(|| format!("{}", path.display()))?;
    file["detections"] = serde_json::from_str(&serde_json::to_string(detections)?)?;
    if let Some(fields) = file.as_object_mut() {
        fields.remove("run");
    }
    Ok(file)
}
