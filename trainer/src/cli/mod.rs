//! One module per `trainer` subcommand: its clap `Args` and a `run(args) -> anyhow::Result<()>`.

pub mod ablations;
pub mod demo;
pub mod eval;
pub mod heat;
pub mod inspect;
pub mod pose;
pub mod render;
pub mod resample;
pub mod synth;
pub mod template;
pub mod track;
pub mod train;
pub mod zoo;
