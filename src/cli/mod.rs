//! Subcommands of the `cog-gpu` binary.

pub mod bench;
pub mod calibrate;
pub mod detect;
pub mod eval;
pub mod info;
pub mod score;
pub mod synth;
pub mod train;

/// Options shared by every subcommand.
pub struct GlobalOptions {
    /// `--cpu`: never ask for a GPU adapter.
    pub force_cpu: bool,
}
