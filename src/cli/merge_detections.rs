//! `cog-gpu merge-detections --base DIR --update DIR --categories a,b --out DIR [--models DIR]`: replaces,
//! in every first-stage detections file of `--base` (from `detect --no-cascade`), the detections of
//! `--categories` by those of the same frame in `--update` (`detect --no-cascade --categories a,b` with new
//! models of those categories and the same other options), and writes the merged files to `--out`
//! ([`cog_gpu::detect::replace_categories`]): what detecting the whole set again with the new models would
//! write, at the cost of detecting only the changed categories. So a change of one first-stage model
//! re-detects one category of the cascade's training set (`cog-gpu cascade`) instead of all 19.
//!
//! A replaced category of [`cog_gpu::category::CROSS_SCORE_CATEGORIES`] changes the cross scores of every
//! cross-category box (the new model scores the kept boxes too): with `--data DIR` (the frames' dataset)
//! each merged frame is read and preprocessed as `detect --cpu` does and the cross scores are computed
//! again on the CPU ([`cog_gpu::detect::cross_scores`]), so the files equal a full `detect --cpu`'s; without it they are
//! dropped (a cascade with a v7 stage then refuses the files), with a warning.
//!
//! Refused: cascaded files (merge the first stage, then `rescore`); a replaced category on whose detections
//! a surface model (monitor on desks, sink on counters) that is not replaced searches; a frame of one
//! directory missing from the other; an `--update` without any detection of the categories.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use cog_gpu::backend::Backend;
use cog_gpu::category::normalise_name;
use cog_gpu::detect::{cross_scores, replace_categories, replacement_problem};
use cog_gpu::eval::{Detection, FrameDetections};
use cog_gpu::features::Preprocessed;
use cog_gpu::frame::{unique_frame_names, Dataset, DepthSource, Frame};
use cog_gpu::model::read_models_dir;

use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    /// First-stage detections of every category (`<frame>.json` files from `detect --no-cascade`).
    #[arg(long)]
    pub base: PathBuf,
    /// The same frames detected again with the new models of --categories (`detect --no-cascade
    /// --categories ...`, every other option as for --base); its detections of other categories are ignored.
    #[arg(long)]
    pub update: PathBuf,
    /// The categories whose detections --update replaces (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    pub categories: Vec<String>,
    /// The models of the merged detections (--base's, with the new ones of --categories): they say which
    /// models search support surfaces, for the order `detect` writes detections in and for the check that
    /// no kept category depends on a replaced one.
    #[arg(long, default_value = super::detect::SHIPPED_MODELS)]
    pub models: PathBuf,
    /// Where to write the merged files (neither --base nor --update).
    #[arg(long)]
    pub out: PathBuf,
    /// The dataset the detections are of (every frame directory below it): when a replaced category is
    /// one whose model scores the other large categories' boxes (the cascade's cross scores), each merged
    /// frame is read and preprocessed on the CPU and every box's cross scores are computed again with the
    /// merged models, as `detect --cpu` writes them. Without it they are dropped.
    #[arg(long)]
    pub data: Option<PathBuf>,
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    let mut categories: Vec<String> = Vec::new();
    // Each category once (`chair,chair` printed its report row twice).
    for category in super::options::names("--categories", &args.categories)?.iter().map(|c| normalise_name(c).0) {
        if !categories.contains(&category) {
            categories.push(category);
        }
    }
    let models_dir = super::detect::shipped_or(&args.models, super::detect::SHIPPED_MODELS);
    let models = read_models_dir(&models_dir, None)?;
    for category in &categories {
        if !models.iter().any(|m| &m.category == category) {
            bail!("{}: no model for category '{category}' ({category}.json)", models_dir.display());
        }
    }
    if let Some(problem) = replacement_problem(&categories, &models) {
        bail!("--categories {}: {problem}", categories.join(","));
    }
    for (dir, flag) in [(&args.base, "--base"), (&args.update, "--update")] {
        if !dir.is_dir() {
            bail!("{}: {flag} detections directory not found", dir.display());
        }
        if super::options::same_path(dir, &args.out) {
            bail!(
                "{}: --out must differ from {flag} (its files are read while the merged ones are written)",
                dir.display()
            );
        }
    }
    let crossed = categories.iter().any(|c| cog_gpu::category::is_cross_score_category(c));
    // Frame name → directory, only when the cross scores are computed again.
    let frame_dirs: Option<BTreeMap<String, PathBuf>> = match (&args.data, crossed) {
        (Some(data), true) => {
            let dataset = Dataset::open(data)?;
            let names = unique_frame_names(&dataset.frames)?;
            Some(names.into_iter().zip(dataset.frames).collect())
        }
        (Some(data), false) => {
            log::info!(
                "--data {}: not read, no replaced category's model makes cross scores (the kept ones stay valid)",
                data.display()
            );
            None
        }
        (None, _) => None,
    };
    let normals = match &frame_dirs {
        Some(_) => Some(super::detect::normal_search_for(&models_dir, &models, None)?),
        None => None,
    };
    let base_files = detection_files(&args.base)?;
    let update_files = detection_files(&args.update)?;
    if base_files.is_empty() {
        bail!("{}: no detections files (<frame>.json)", args.base.display());
    }
    if let Some(extra) = update_files.iter().find(|name| !base_files.contains(name)) {
        bail!("{}: has no counterpart {} in --base {}", args.update.join(extra).display(), extra, args.base.display());
    }
    let mut added = vec![0usize; categories.len()];
    let mut removed = vec![0usize; categories.len()];
    let mut merged_files = Vec::with_capacity(base_files.len());
    let bar = indicatif::ProgressBar::new(base_files.len() as u64);
    if frame_dirs.is_some() {
        bar.set_style(indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames, cross scores ({eta})")?);
    } else {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    for name in &base_files {
        let (base_path, update_path) = (args.base.join(name), args.update.join(name));
        if !update_path.is_file() {
            bail!(
                "{}: missing: --update must hold every frame of --base ({})",
                update_path.display(),
                args.base.display()
            );
        }
        let base_text = cog_gpu::frame::read_text(&base_path)?;
        let base = first_stage(&base_path, &base_text)?;
        let update = first_stage(&update_path, &cog_gpu::frame::read_text(&update_path)?)?;
        if update.frame != base.frame {
            bail!("{}: frame '{}', but the --base file is frame '{}'", update_path.display(), update.frame, base.frame);
        }
        let unmodelled = |d: &&Detection| !models.iter().any(|m| m.category == d.category);
        let stray = base.detections.iter().find(unmodelled).map(|d| (&base_path, d));
        if let Some((path, d)) = stray.or_else(|| update.detections.iter().find(unmodelled).map(|d| (&update_path, d)))
        {
            bail!(
                "{}: a '{}' detection, and {} has no {}.json: --models must hold the models of every category \
                 in the detections",
                path.display(),
                d.category,
                models_dir.display(),
                d.category
            );
        }
        for (n, category) in categories.iter().enumerate() {
            removed[n] += base.detections.iter().filter(|d| &d.category == category).count();
            added[n] += update.detections.iter().filter(|d| &d.category == category).count();
        }
        let mut detections = replace_categories(&base.detections, &update.detections, &categories, &models);
        if let (Some(dirs), Some(search)) = (&frame_dirs, normals) {
            let dir = dirs.get(&base.frame).with_context(|| {
                let data = args.data.as_deref().unwrap_or(Path::new("")).display();
                format!("{}: frame '{}' is not in --data {data}", base_path.display(), base.frame)
            })?;
            let frame = Frame::read(dir, DepthSource::Raw)?;
            let pre = Preprocessed::from_frame_with(&frame, search)?;
            cross_scores(&pre, &models, &mut detections, Backend::Cpu);
        }
        let file = super::options::with_detections(&base_text, &base_path, &detections)?;
        merged_files.push((name.clone(), file));
        bar.inc(1);
    }
    bar.finish_and_clear();
    if added.iter().all(|&n| n == 0) {
        bail!(
            "{}: holds no detection of {} in any frame: was it made with `detect --categories {}`?",
            args.update.display(),
            categories.join(", "),
            categories.join(",")
        );
    }
    if let Some(category) = categories.iter().find(|c| cog_gpu::category::is_cross_score_category(c)) {
        if frame_dirs.is_none() {
            log::warn!(
                "the merged detections carry no cross scores: '{category}' is one of the categories whose models \
                 score each other's boxes, so the kept boxes' cross scores would be the old model's (a cascade \
                 with a v7 stage refuses them; give the frames with --data to compute them again)"
            );
        }
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    for (name, file) in &merged_files {
        let out = args.out.join(name);
        cog_gpu::error::write_whole(&out, serde_json::to_string_pretty(file)?.as_bytes())?;
    }
    out!("{:<12} {:>10} {:>10}", "category", "removed", "added");
    for (n, category) in categories.iter().enumerate() {
        out!("{category:<12} {:>10} {:>10}", removed[n], added[n]);
        if added[n] == 0 {
            log::warn!("{}: no {category} detection in any frame", args.update.display());
        }
    }
    out!(
        "merged {} frame(s) of {} with {} of {} into {}",
        merged_files.len(),
        args.base.display(),
        categories.join(","),
        args.update.display(),
        args.out.display()
    );
    Ok(())
}

/// The `<frame>.json` file names of a detections directory, sorted.
fn detection_files(dir: &Path) -> anyhow::Result<Vec<String>> {
    let paths = super::options::json_files(dir)?;
    Ok(paths.iter().filter_map(|p| p.file_name().and_then(|n| n.to_str()).map(String::from)).collect())
}

/// A detections file's contents, refused when the cascade rescored it.
fn first_stage(path: &Path, text: &str) -> anyhow::Result<FrameDetections> {
    let frame = FrameDetections::parse(path, text)?;
    if frame.detections.iter().any(|d| d.first_stage_score.is_some() || d.context_score.is_some()) {
        bail!(
            "{}: rescored by the context cascade: merge first-stage files (`detect --no-cascade`), then \
             `rescore` the merged ones",
            path.display()
        );
    }
    Ok(frame)
}
