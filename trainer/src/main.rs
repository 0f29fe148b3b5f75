//! The `trainer` command-line tool: one subcommand per module in `cli/`.
//!
//! Errors go to stderr as one line naming the file and what is wrong, with exit code 1.

use clap::{Parser, Subcommand};

mod cli;

/// Skinfield trainer: bone heat, synthetic captures, SkinNet training, export, evaluation.
#[derive(Parser)]
#[command(name = "trainer", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the version.
    Version,
    /// Describe a glTF/GLB or .skf file as one JSON object.
    Inspect(cli::inspect::Args),
    /// World-space skinned positions of a glTF asset at clip times, computed by the runtime.
    Pose(cli::pose::Args),
    // Each subcommand: `Name(cli::name::Args)`, dispatched below to `cli::name::run`.
}

fn main() {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {
        Command::Version => {
            println!("{}", env!("CARGO_PKG_VERSION"));
            Ok(())
        }
        Command::Inspect(args) => cli::inspect::run(args),
        Command::Pose(args) => cli::pose::run(args),
    };
    if let Err(e) = result {
        // One line: the context chain joined, so the file and the field are both named.
        eprintln!("trainer: {e:#}");
        std::process::exit(1);
    }
}
