//! One module per `trainer` subcommand: its clap `Args` and a `run(args) -> anyhow::Result<()>`.

pub mod inspect;
pub mod pose;
