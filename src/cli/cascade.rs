//! `cog-gpu cascade --data DIR --detections DIR [--models assets/models] [--out FILE] [--iou 0.25]
//! [--categories a,b,...] [--features v4|v5|v6|v7|best|best-cross] [--keep any-gain|significant-gain|nested-gain] [--checkpoints DIR]
//! [--keep-checkpoints]`: trains the context cascade ([`cog_gpu::cascade`]) on the first-stage detections
//! of held-out frames and writes it as `<models>/cascade.json`, which `detect` then applies.
//!
//! The detections are those of `cog-gpu detect --no-cascade --min-score -3` with the calibrated models the
//! cascade will sit on (the cascade's inputs are their calibrated scores, so recalibrating or retraining a
//! model means retraining the cascade). The frames must be neither training frames of the models nor
//! test frames. Choices: the categories default to every model in `--models` (they are also the context
//! categories); a category whose detections hold no true or no false positive gets no second stage and
//! keeps its first-stage scores (reported, not an error).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{bail, Context};
use cog_gpu::cascade::{
    check_cross_scores, check_first_stage, score_off_its_calibration, stage_checkpoint_path, train_cascade_resumable,
    v7_adds_nothing, Cascade, CascadeFrame, CascadeTraining, FeatureSet, StageOutcome, StageRule, FILE_NAME,
    GAIN_LEVEL,
};

use super::calibrate::{read_labelled_detections, HeldOutArgs, LabelledDetections};
use super::GlobalOptions;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub held_out: HeldOutArgs,
    /// Where to write the cascade; default `<models>/cascade.json`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The feature set: v4 (the paper's overlap and layout features), v5 (also each detection's
    /// neighbourhood and its box's geometry), v6 (also the scene: each category's best detection in the
    /// frame), v7 (also the cross scores: every large category's and the counter's model scoring the
    /// detection's own box; needs detections files that carry them, `detect --no-cascade` writes them),
    /// best (per category the one of v4, v5 and v6 with the highest cross-validated AP on these frames;
    /// trains all three) or best-cross (the same among v4 to v7, v7 only for the categories with cross
    /// scores; the shipped cascade's recipe since 2026-12-05); README, "Context cascade".
    #[arg(long, value_enum, default_value = "v4")]
    pub features: FeaturesArg,
    /// Which trained stages the cascade keeps: any-gain (every stage whose cross-validated AP is above the
    /// first stage's), significant-gain (only those whose gain's 90 % bootstrap interval over the frames
    /// lies above 0) or nested-gain (only a category whose training — C and feature set chosen by
    /// cross-validation — gains in a nested cross-validation, the choices made inside each fold; about
    /// 1.1× the training time; measured to help on 2 000 cascade frames and to drop helpful stages on 500,
    /// so it warns below 2 000); README, "Which stages to keep".
    #[arg(long, value_enum, default_value = "any-gain")]
    pub keep: KeepArg,
    /// Directory of the per-stage checkpoints (default: the output path with `.stages` appended): each
    /// category's training with each feature set is written there when done, and a rerun of an
    /// interrupted training on the same detections reads them instead of training again.
    #[arg(long)]
    pub checkpoints: Option<PathBuf>,
    /// Keep the checkpoints after the cascade is written (by default they are removed then), e.g. to
    /// train another `--features` choice on the same detections reusing the stages already trained.
    #[arg(long)]
    pub keep_checkpoints: bool,
}

/// Below this many cascade frames `--keep nested-gain` warns: the smallest set it was measured to help on.
const NESTED_FRAMES_MEASURED: usize = 2000;

/// `--keep`.
// The variants are the option's values (`any-gain`, ...), each a kind of gain.
#[allow(clippy::enum_variant_names)]
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum KeepArg {
    AnyGain,
    SignificantGain,
    NestedGain,
}

impl From<KeepArg> for StageRule {
    fn from(keep: KeepArg) -> Self {
        match keep {
            KeepArg::AnyGain => StageRule::AnyGain,
            KeepArg::SignificantGain => StageRule::SignificantGain,
            KeepArg::NestedGain => StageRule::NestedGain,
        }
    }
}

/// `--features`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum FeaturesArg {
    V4,
    V5,
    V6,
    V7,
    Best,
    BestCross,
}

impl FeaturesArg {
    /// The candidate sets, the file's own first.
    fn sets(self) -> Vec<FeatureSet> {
        match self {
            FeaturesArg::V4 => vec![FeatureSet::V4],
            FeaturesArg::V5 => vec![FeatureSet::V5],
            FeaturesArg::V6 => vec![FeatureSet::V6],
            FeaturesArg::V7 => vec![FeatureSet::V7],
            FeaturesArg::Best => vec![FeatureSet::V4, FeatureSet::V5, FeatureSet::V6],
            FeaturesArg::BestCross => vec![FeatureSet::V4, FeatureSet::V5, FeatureSet::V6, FeatureSet::V7],
        }
    }
}

pub fn run(args: Args, _options: &GlobalOptions) -> anyhow::Result<()> {
    let held_out = &args.held_out;
    let models = held_out.models()?;
    if let Some(model) = models.iter().find(|m| m.calibration.is_none()) {
        bail!(
            "{}: the '{}' model is not calibrated; the cascade needs calibrated models (cog-gpu calibrate)",
            held_out.models.display(),
            model.category
        );
    }
    let categories: Vec<String> = models.iter().map(|m| m.category.clone()).collect();
    let LabelledDetections { frames, names, truth, detections, rooms } =
        read_labelled_detections(&held_out.data, &held_out.detections)?;
    let with_room = rooms.iter().filter(|r| r.is_some()).count();
    if with_room < frames {
        log::warn!(
            "{} of {frames} detections files have no room layout (detect writes it when --models holds a layout \
             model): their layout features say 'no room'",
            frames - with_room
        );
    }
    let inputs: Vec<CascadeFrame> = truth
        .into_iter()
        .zip(detections)
        .zip(rooms)
        .map(|((truth, detections), room)| CascadeFrame { truth, detections, room })
        .collect();
    let training = CascadeTraining {
        data: held_out.data.display().to_string(),
        frames,
        detections: held_out.detections.display().to_string(),
        iou: held_out.iou,
        // Checked above: every model is calibrated.
        calibrations: models.iter().filter_map(|m| Some((m.category.clone(), m.calibration.clone()?))).collect(),
    };
    // Detections of other models than `--models` (whose calibrations the cascade records as theirs): refused
    // here, naming the file, as `detect` and `rescore` would refuse the cascade with them.
    for (name, input) in names.iter().zip(&inputs) {
        let file = || held_out.detections.join(format!("{name}.json"));
        check_first_stage(&input.detections).with_context(|| file().display().to_string())?;
        if let Some((d, raw, expected)) = score_off_its_calibration(&training.calibrations, &input.detections) {
            bail!(
                "{}: a '{}' detection has score {} where the calibration of the '{}' model in {} gives its raw score \
                 {raw} the probability {expected}: these detections come from another model (detect them again \
                 with --models, or give the models they came from)",
                file().display(),
                d.category,
                d.score,
                d.category,
                held_out.models.display()
            );
        }
    }
    let out = args.out.clone().unwrap_or_else(|| held_out.models.join(FILE_NAME));
    // Before the training, not after it: its directory made, the file writable.
    super::options::writable_output_file(&out)?;
    let checkpoints = args.checkpoints.clone().unwrap_or_else(|| {
        let mut name = out.clone().into_os_string();
        name.push(".stages");
        PathBuf::from(name)
    });
    log::info!(
        "training the second stage of {} categories on {frames} frames (checkpoints in {})",
        categories.len(),
        checkpoints.display()
    );
    let sets = args.features.sets();
    if sets.contains(&FeatureSet::V7) {
        // The cross part needs every cross-category detection's cross scores (`detect --no-cascade` writes
        // them since 2026-12-05).
        for (name, input) in names.iter().zip(&inputs) {
            if let Err(problem) = check_cross_scores(&input.detections) {
                bail!("{}: {problem}", held_out.detections.join(format!("{name}.json")).display());
            }
        }
    }
    if matches!(args.keep, KeepArg::NestedGain) && frames < NESTED_FRAMES_MEASURED {
        // Its inner SVMs train on a quarter of the frames: with few frames they are weaker than the stage,
        // and the estimate errs low.
        log::warn!(
            "--keep nested-gain on {frames} frames: its inner fits see a quarter of them; on a 500-frame cascade set \
             it dropped five stages that helped on the test set (19-class mAP -1.3 against any-gain), on 2 000 \
             frames only the one that hurt (docs/measurements.md, \"Nested cross-validation\")"
        );
    }
    let (cascade, results, resumed) = train_cascade_resumable(
        &inputs,
        &categories,
        held_out.iou,
        training,
        &sets,
        Some(&checkpoints),
        args.keep.into(),
    )?;
    if resumed > 0 {
        // Of the trainings that run: a skipped v7 training (`v7_adds_nothing`) has no checkpoint to resume.
        let trainings: usize =
            categories.iter().map(|c| sets.iter().filter(|&&set| !v7_adds_nothing(set, c, &sets)).count()).sum();
        out!("resumed {resumed} of {trainings} stage trainings from the checkpoints in {}", checkpoints.display());
    }
    print_stages(&cascade, &results, &sets, StageRule::from(args.keep).needs_nested())?;
    if cascade.stages.is_empty() {
        bail!("{}: no category could be trained; nothing written", held_out.detections.display());
    }
    cascade.write(&out)?;
    out!("wrote the cascade ({} of {} categories) to {}", cascade.stages.len(), categories.len(), out.display());
    if !args.keep_checkpoints {
        // Only the files this training reads and writes, then the directory if that left it empty: a
        // `--checkpoints` directory may hold other things.
        for category in &categories {
            for &set in &sets {
                let path = stage_checkpoint_path(&checkpoints, category, set);
                if path.exists() {
                    std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
                }
            }
        }
        let _ = std::fs::remove_dir(&checkpoints);
    }
    Ok(())
}

/// The stages' table: per category the chosen stage (its feature set, detections, true positives, C,
/// cross-validated APs and the gain's interval) or why it has none; with several candidate sets, each
/// one's cross-validated AP ("none" for a set without a stage, or whose stage `--keep` refused); with
/// `nested`, the nested cross-validated gain of the category's training.
fn print_stages(
    cascade: &Cascade,
    results: &BTreeMap<String, StageOutcome>,
    sets: &[FeatureSet],
    nested: bool,
) -> anyhow::Result<()> {
    let several = sets.len() > 1;
    let mut header = format!(
        "{:<12} {:>8} {:>10} {:>6} {:>7} {:>12} {:>13} {:>16}",
        "category",
        "features",
        "detections",
        "TP",
        "C",
        "CV AP first",
        "CV AP cascade",
        format!("gain {:.0} % int.", 100.0 * GAIN_LEVEL)
    );
    if nested {
        header.push_str(&format!(" {:>12}", "nested gain"));
    }
    if several {
        for set in sets {
            header.push_str(&format!(" {:>12}", format!("CV AP {}", set.short_name())));
        }
    }
    out!("{header}");
    for (category, outcome) in results {
        let chosen = outcome.chosen();
        let mut line = match &chosen {
            Ok(stage) => format!(
                "{:<12} {:>8} {:>10} {:>6} {:>7} {:>12.1} {:>13.1} {:>16}",
                category,
                cascade.stage_feature_set(stage).map_or("?", FeatureSet::short_name),
                stage.calibration.detections,
                stage.calibration.true_positives,
                stage.c,
                100.0 * stage.cv_ap_first_stage,
                100.0 * stage.cv_ap_cascade,
                stage.cv_gain_interval.map_or("-".to_string(), |[low, high]| format!(
                    "[{:+.1}, {:+.1}]",
                    100.0 * low,
                    100.0 * high
                ))
            ),
            Err(reason) => format!("{category:<12} no second stage (keeps its first-stage scores): {reason}"),
        };
        if nested && chosen.is_ok() {
            line.push_str(&format!(
                " {:>12}",
                outcome.nested_gain.map_or("-".into(), |g| format!("{:+.1}", 100.0 * g))
            ));
        }
        if several && chosen.is_ok() {
            for (_, result) in &outcome.candidates {
                match result {
                    Ok(stage) => line.push_str(&format!(" {:>12.1}", 100.0 * stage.cv_ap_cascade)),
                    Err(_) => line.push_str(&format!(" {:>12}", "none")),
                }
            }
        }
        out!("{line}");
    }
    Ok(())
}
