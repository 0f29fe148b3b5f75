//! The `trainer` command-line tool.

fn main() {
    eprintln!("trainer: no subcommand implemented yet");
    std::process::exit(2);
}
