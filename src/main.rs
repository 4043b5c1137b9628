//! The `cog-gpu` command line. Each subcommand lives in `src/cli/<name>.rs` with its clap `Args` and `run`.

mod cli;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "cog-gpu",
    version,
    about = "3D object detection in indoor RGB-D images (Clouds of Oriented Gradients, on the GPU)"
)]
struct Cli {
    /// Force the CPU path even when a GPU adapter is available.
    #[arg(long, global = true)]
    cpu: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Describe one SUN RGB-D frame directory: sizes, calibration, point cloud, annotations.
    Info(cli::info::Args),
    /// Generate synthetic indoor RGB-D frames in the SUN RGB-D layout.
    Synth(cli::synth::Args),
    /// Score one frame's sliding-window hypotheses with a weights file and print the best.
    Score(cli::score::Args),
    /// Throughput of one category's sliding window on one frame, CPU and GPU paths side by side.
    Bench(cli::bench::Args),
    /// Average precision of detection files against a dataset's ground truth (SUN RGB-D rules).
    Eval(cli::eval::Args),
    /// Detect objects with trained models: per frame a detections JSON and an overlay picture.
    Detect(cli::detect::Args),
    /// Fit each model's score calibration (raw score -> probability of a true positive) on held-out frames.
    Calibrate(cli::calibrate::Args),
    /// Train the context cascade (second-stage rescoring from the other detections) on held-out frames.
    Cascade(cli::cascade::Args),
    /// Apply a context cascade to first-stage detections files without detecting again.
    Rescore(cli::rescore::Args),
    /// Combine cascades trained with different feature sets: per category the best cross-validated stage.
    MergeCascades(cli::merge_cascades::Args),
    /// Replace some categories' first-stage detections by those of new models, without detecting the rest.
    MergeDetections(cli::merge_detections::Args),
    /// Train one category's detector (structural SVM) on annotated frames and write a model file.
    Train(cli::train::Args),
    /// Room layout of frames: a Manhattan cuboid per frame (JSON, overlay picture, optional PLY).
    Layout(cli::layout::Args),
    /// Train the room-layout model (structural SVM over layout hypotheses) on annotated frames.
    TrainLayout(cli::train_layout::Args),
}

/// `cog-gpu detect DIR | head` must end quietly when `head` has read enough, as command-line tools do.
/// Rust ignores SIGPIPE, so a write to the closed pipe would fail (`println!` panics, status 101; the
/// commands' `cli::out!` would report an error); with the default action restored the process ends by the
/// signal, like `cat`.
fn restore_default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: runs first in `main`, before any other thread exists; SIG_DFL is a valid disposition.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

fn main() {
    restore_default_sigpipe();
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("info")).format_timestamp(None).init();
    // Bad options exit with status 1 like every other error (README); --help and --version with 0.
    let cli = Cli::try_parse().unwrap_or_else(|err| {
        if err.use_stderr() {
            let _ = err.print();
            std::process::exit(1);
        }
        err.exit()
    });
    let options = cli::GlobalOptions { force_cpu: cli.cpu };
    let result = match cli.command {
        Command::Info(args) => cli::info::run(args, &options),
        Command::Synth(args) => cli::synth::run(args, &options),
        Command::Score(args) => cli::score::run(args, &options),
        Command::Bench(args) => cli::bench::run(args, &options),
        Command::Eval(args) => cli::eval::run(args, &options),
        Command::Train(args) => cli::train::run(args, &options),
        Command::Detect(args) => cli::detect::run(args, &options),
        Command::Calibrate(args) => cli::calibrate::run(args, &options),
        Command::Cascade(args) => cli::cascade::run(args, &options),
        Command::Rescore(args) => cli::rescore::run(args, &options),
        Command::MergeCascades(args) => cli::merge_cascades::run(args, &options),
        Command::MergeDetections(args) => cli::merge_detections::run(args, &options),
        Command::Layout(args) => cli::layout::run(args, &options),
        Command::TrainLayout(args) => cli::train_layout::run(args, &options),
    };
    // Reports are written with `cli::out!`, whose failed writes are errors; what is still buffered is
    // flushed here, so that a failure to write it is one too.
    let result = result.and_then(|()| cli::flush_stdout());
    if let Err(err) = result {
        eprintln!("error: {}", cli::error_text(&err));
        std::process::exit(1);
    }
}
