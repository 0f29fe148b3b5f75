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

use std::path::{Path, PathBuf};

use anyhow::Context;

/// Copies every file of `from` into `to` (hard links where the file system allows), except the
/// paths in `skip` (files or whole folders), which the caller writes or leaves out.
pub fn copy_tree(from: &Path, to: &Path, skip: &[PathBuf]) -> anyhow::Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for entry in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let entry = entry?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        if skip.contains(&src) {
            continue;
        }
        if entry.file_type()?.is_dir() {
            copy_tree(&src, &dst, skip)?;
        } else {
            let _ = std::fs::remove_file(&dst);
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst)
                    .with_context(|| format!("copying {} to {}", src.display(), dst.display()))?;
            }
        }
    }
    Ok(())
}
