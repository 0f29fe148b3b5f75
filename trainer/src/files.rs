//! Copies of a capture folder for the commands that derive one from another (`trainer track`,
//! `trainer template`, the motion-noise example): every file hard-linked where the file system
//! allows (a capture's images are most of its bytes and the copy never writes to them), the
//! files the caller rewrites left out.

use std::path::{Path, PathBuf};

/// A file or folder that could not be read, created or copied.
#[derive(Debug, thiserror::Error)]
#[error("{what} {}: {source}", path.display())]
pub struct CopyError {
    /// What was being done (`reading`, `creating`, `copying to …`).
    pub what: String,
    /// The path it was done to.
    pub path: PathBuf,
    /// The I/O error.
    pub source: std::io::Error,
}

/// Copies every file of `from` into `to` (hard links where the file system allows), except the
/// paths in `skip` (files or whole folders), which the caller writes or leaves out. A file
/// already at a destination is replaced, never written through (it may be a link to the source).
pub fn copy_tree(from: &Path, to: &Path, skip: &[PathBuf]) -> Result<(), CopyError> {
    let fail = |what: &str, path: &Path| {
        let (what, path) = (what.to_owned(), path.to_owned());
        move |source| CopyError { what, path, source }
    };
    std::fs::create_dir_all(to).map_err(fail("creating", to))?;
    for entry in std::fs::read_dir(from).map_err(fail("reading", from))? {
        let entry = entry.map_err(fail("reading", from))?;
        let (src, dst) = (entry.path(), to.join(entry.file_name()));
        if skip.contains(&src) {
            continue;
        }
        if entry.file_type().map_err(fail("reading", &src))?.is_dir() {
            copy_tree(&src, &dst, skip)?;
        } else {
            let _ = std::fs::remove_file(&dst);
            if std::fs::hard_link(&src, &dst).is_err() {
                std::fs::copy(&src, &dst)
                    .map_err(fail(&format!("copying to {}:", dst.display()), &src))?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_every_file_but_the_skipped_and_replaces_instead_of_writing_through() {
        let dir = tempfile::tempdir().unwrap();
        let (from, to) = (dir.path().join("a"), dir.path().join("b"));
        std::fs::create_dir_all(from.join("sub/skipped")).unwrap();
        std::fs::write(from.join("keep.txt"), "keep").unwrap();
        std::fs::write(from.join("motion.json"), "old").unwrap();
        std::fs::write(from.join("sub/x.txt"), "x").unwrap();
        std::fs::write(from.join("sub/skipped/y.txt"), "y").unwrap();
        std::fs::create_dir_all(&to).unwrap();
        std::fs::write(to.join("keep.txt"), "stale").unwrap();
        let skip = [from.join("motion.json"), from.join("sub/skipped")];
        copy_tree(&from, &to, &skip).unwrap();
        assert_eq!(
            std::fs::read_to_string(to.join("keep.txt")).unwrap(),
            "keep"
        );
        assert_eq!(std::fs::read_to_string(to.join("sub/x.txt")).unwrap(), "x");
        assert!(!to.join("motion.json").exists());
        assert!(!to.join("sub/skipped").exists());
        // Rewriting the copy (remove, then write) leaves the source as it was.
        std::fs::remove_file(to.join("keep.txt")).unwrap();
        std::fs::write(to.join("keep.txt"), "new").unwrap();
        assert_eq!(
            std::fs::read_to_string(from.join("keep.txt")).unwrap(),
            "keep"
        );
        let e = copy_tree(&dir.path().join("missing"), &to, &[]).unwrap_err();
        assert!(e.to_string().contains("missing"), "{e}");
    }
}
