//! `cog-gpu merge-cascades FIRST SECOND [MORE...] --out FILE`: combines cascades trained on the same
//! frames, detections and first-stage models with different feature sets into one, keeping per category the
//! stage with the highest cross-validated AP (ties: the earlier file's), as `cascade --features best` does
//! among its sets ([`cog_gpu::cascade::Cascade::merged_with`]). So the sets can be trained one at a time
//! (or on several machines) and the cascade of all of them assembled without training any again.

use std::path::PathBuf;

use anyhow::{bail, Context};
use cog_gpu::cascade::{Cascade, FeatureSet};

use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    /// Cascade files (`cog-gpu cascade --out`), at least two; the first one's feature set is the merged
    /// file's, and a tie keeps the earlier file's stage.
    #[arg(required = true, num_args = 2..)]
    pub cascades: Vec<PathBuf>,
    /// Where to write the merged cascade (not one of the inputs).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    // The same file under another spelling (`./a.json`, a link) counts too: it would be overwritten.
    if args.cascades.iter().any(|c| super::options::same_path(c, &args.out)) {
        bail!("{}: --out must not be one of the cascades merged", args.out.display());
    }
    let cascades: Vec<Cascade> = args.cascades.iter().map(|p| Cascade::read(p)).collect::<Result<_, _>>()?;
    let mut merged = cascades[0].clone();
    for (cascade, path) in cascades.iter().zip(&args.cascades).skip(1) {
        merged = merged.merged_with(cascade).map_err(|problem| {
            anyhow::anyhow!("{}: cannot be merged with {}: {problem}", path.display(), args.cascades[0].display())
        })?;
    }
    out!("{:<12} {:>8} {:>13}   from", "category", "features", "CV AP cascade");
    for category in &merged.categories {
        let Some(stage) = merged.stages.get(category) else {
            out!("{category:<12} no second stage in any of the cascades");
            continue;
        };
        // The first file whose stage is the one kept.
        let from = cascades
            .iter()
            .zip(&args.cascades)
            .find(|(c, _)| c.stages.get(category).is_some_and(|s| s.weights == stage.weights && s.bias == stage.bias))
            .map_or("?".to_string(), |(_, p)| p.display().to_string());
        out!(
            "{category:<12} {:>8} {:>13.1}   {from}",
            merged.stage_feature_set(stage).map_or("?", FeatureSet::short_name),
            100.0 * stage.cv_ap_cascade
        );
    }
    merged.write(&args.out).with_context(|| format!("writing {}", args.out.display()))?;
    out!(
        "wrote the merged cascade ({} of {} categories) to {}",
        merged.stages.len(),
        merged.categories.len(),
        args.out.display()
    );
    Ok(())
}
