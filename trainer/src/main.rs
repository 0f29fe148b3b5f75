//! The `trainer` command-line tool: one subcommand per module in `cli/`.
//!
//! Errors go to stderr as one line naming the file and what is wrong, with exit code 1.

use clap::{Parser, Subcommand};

mod cli;

/// mimalloc instead of glibc's allocator: glibc hands the large buffers a training iteration
/// allocates (posed batches, gradients, per-view lists) back to the kernel and maps them again
/// the next iteration, which cost a third of the static baseline's CPU time in page faults and
/// TLB shootdowns (`docs/experiments/training-speed.md`). Results are bit-identical.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

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
    /// Write the built-in synthetic multi-view capture (procedural clothed character).
    Synth(cli::synth::Args),
    /// Score skinnings against a capture's ground-truth test meshes (M2S, S2M, Chamfer in cm).
    Eval(cli::eval::Args),
    /// Draw a posed mesh over a captured image, or coloured by its error against the ground truth.
    Render(cli::render::Args),
    /// Describe a glTF/GLB, BVH, .skf file or a capture folder as one JSON object.
    Inspect(cli::inspect::Args),
    /// Bone-heat (Pinocchio) skinning weights for a glTF character, written back as glTF.
    Heat(cli::heat::Args),
    /// Train SkinNet (stage 1) or the static baseline on a capture.
    Train(cli::train::Args),
    /// Synthesise the built-in capture, train, export, evaluate and print the table.
    Demo(cli::demo::Args),
    /// World-space skinned positions of a glTF asset at clip times, computed by the runtime.
    Pose(cli::pose::Args),
    /// Simplify or subdivide a template to vertex counts (glTF), timing resample and bind.
    Resample(cli::resample::Args),
    /// The character zoo: capture, train and score every shared character; one table.
    Zoo(cli::zoo::Args),
    /// Skeletal motion from the capture's 2D keypoints, written as a copy of the capture.
    Track(cli::track::Args),
    /// Reconstruct the template (mesh, colours, part labels) from a capture frame's images.
    Template(cli::template::Args),
    // Each subcommand: `Name(cli::name::Args)`, dispatched below to `cli::name::run`.
}

fn main() {
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match cli.command {
        Command::Version => {
            println!("{}", env!("CARGO_PKG_VERSION"));
            Ok(())
        }
        Command::Synth(args) => cli::synth::run(args),
        Command::Eval(args) => cli::eval::run(args),
        Command::Render(args) => cli::render::run(args),
        Command::Inspect(args) => cli::inspect::run(args),
        Command::Heat(args) => cli::heat::run(args),
        Command::Train(args) => cli::train::run(args),
        Command::Demo(args) => cli::demo::run(args),
        Command::Pose(args) => cli::pose::run(args),
        Command::Resample(args) => cli::resample::run(args),
        Command::Zoo(args) => cli::zoo::run(args),
        Command::Track(args) => cli::track::run(args),
        Command::Template(args) => cli::template::run(args),
    };
    if let Err(e) = result {
        eprintln!("trainer: {}", one_line(&e));
        std::process::exit(1);
    }
}

/// The error and its causes on one line, so the file and the field are both named. A cause that
/// the message above it already ends with is said once: the library errors name their I/O
/// cause in their own message (for callers that print only that) and also report it as their
/// source.
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !out.is_empty() && out.ends_with(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    use super::{Cli, one_line};

    #[test]
    fn a_cause_is_said_once() {
        #[derive(Debug, thiserror::Error)]
        #[error("capture/template.json: {source}")]
        struct Read {
            #[source]
            source: std::io::Error,
        }
        let io = || std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = anyhow::Error::new(Read { source: io() }).context("loading the capture");
        assert_eq!(
            one_line(&e),
            "loading the capture: capture/template.json: no such file"
        );
        // A cause the message does not contain is still printed.
        let e = anyhow::Error::new(io()).context("reading capture/template.json");
        assert_eq!(one_line(&e), "reading capture/template.json: no such file");
    }

    /// Clap's own consistency checks (duplicate argument ids from flattened groups, conflicting
    /// names, bad defaults), which otherwise surface only when a user runs the command.
    #[test]
    fn command_line_is_well_formed() {
        Cli::command().debug_assert();
    }
}
