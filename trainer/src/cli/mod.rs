//! One module per `trainer` subcommand: its clap `Args` and a `run(args) -> anyhow::Result<()>`.

pub mod heat;
pub mod inspect;
pub mod synth;
pub mod eval;
pub mod render;
