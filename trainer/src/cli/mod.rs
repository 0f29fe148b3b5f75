//! One module per `trainer` subcommand: its clap `Args` and a `run(args) -> anyhow::Result<()>`.

pub mod eval;
pub mod heat;
pub mod inspect;
pub mod render;
pub mod synth;
pub mod demo;
pub mod train;
