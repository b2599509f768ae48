//! Whether a command may write its output files: checked before it opens a board or fits
//! anything, so a refusal costs nothing. An existing file or a non-empty session directory is
//! kept unless `--force`; an output that is also an input (the same file, by any path or link)
//! is never written, since writing it would destroy what is being read; a place that cannot be
//! written is refused up front rather than after the work is done.

use std::path::{Path, PathBuf};

use thiserror::Error;

/// A path a command is about to write.
#[derive(Debug, Clone, Copy)]
pub(in crate::cli) enum Output<'a> {
    /// A file in a directory that must exist.
    File(&'a Path),
    /// A file in a directory the command creates when it is missing (`report -o DIR`).
    FileInNewDir(&'a Path),
    /// A directory the command fills with files of its own (a session, a report directory).
    Dir(&'a Path),
}

/// Why an output is refused.
#[derive(Debug, Error)]
pub(in crate::cli) enum OutputRefused {
    /// The file exists and `--force` was not given.
    #[error("`{0}` already exists; choose another name, or pass --force to replace it")]
    Exists(String),
    /// The directory holds files and `--force` was not given.
    #[error(
        "`{0}` already holds files (an earlier session or report?); choose another directory, \
         or pass --force to write into it"
    )]
    NonEmptyDir(String),
    /// The output is one of the command's inputs.
    #[error(
        "`{output}` is also the input `{input}`; writing it would destroy what is being read, \
         so choose another name for the output"
    )]
    SameAsInput {
        /// The output as given.
        output: String,
        /// The input as given.
        input: String,
    },
    /// A directory stands where a file is to be written.
    #[error("`{0}` is a directory; name a file to write")]
    IsADirectory(String),
    /// Something other than a directory stands where a directory is to be written.
    #[error("`{0}` exists and is not a directory; choose another name for the directory")]
    NotADirectory(String),
    /// The file's directory does not exist.
    #[error("the directory `{dir}` of `{output}` does not exist; create it first, or choose another place")]
    MissingDir {
        /// The output as given.
        output: String,
        /// Its directory.
        dir: String,
    },
    /// The directory that would hold the output cannot be written.
    #[error("`{output}` cannot be written: {place} {why}; choose a place you can write to")]
    Unwritable {
        /// The output as given.
        output: String,
        /// What refuses: the directory that would hold it, or the existing file.
        place: String,
        /// What is wrong with it.
        why: String,
    },
}

/// Refuses, before anything is done, outputs that would overwrite a file or fill a non-empty
/// directory (unless `force`), outputs that are also `inputs`, and outputs that cannot be
/// written where they are named.
pub(in crate::cli) fn check_outputs(
    outputs: &[Output<'_>],
    inputs: &[PathBuf],
    force: bool,
) -> Result<(), OutputRefused> {
    for output in outputs {
        check_one(*output, inputs, force)?;
    }
    Ok(())
}

fn shown(path: &Path) -> String {
    path.display().to_string()
}

fn check_one(output: Output<'_>, inputs: &[PathBuf], force: bool) -> Result<(), OutputRefused> {
    let (path, is_dir) = match output {
        Output::File(p) | Output::FileInNewDir(p) => (p, false),
        Output::Dir(p) => (p, true),
    };
    if !is_dir {
        if let Some(input) = same_input(path, inputs) {
            return Err(OutputRefused::SameAsInput {
                output: shown(path),
                input: shown(input),
            });
        }
    }
    // `symlink_metadata` would refuse a link to a directory the user meant; follow links.
    match std::fs::metadata(path) {
        Ok(meta) if is_dir => {
            if !meta.is_dir() {
                return Err(OutputRefused::NotADirectory(shown(path)));
            }
            if !force && holds_entries(path) {
                return Err(OutputRefused::NonEmptyDir(shown(path)));
            }
            return writable(path, path);
        }
        Ok(meta) if meta.is_dir() => return Err(OutputRefused::IsADirectory(shown(path))),
        Ok(meta) if meta.is_file() && !force => return Err(OutputRefused::Exists(shown(path))),
        // Replaced in place: the file must take writes (opened without truncating it).
        Ok(meta) if meta.is_file() => {
            return std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .map(drop)
                .map_err(|e| OutputRefused::Unwritable {
                    output: shown(path),
                    place: "the file".to_string(),
                    why: format!("cannot be written ({e})"),
                });
        }
        // A device or a FIFO (`-o /dev/stdout`) is written to, not replaced: opening a FIFO
        // here would wait for its reader, so it is left to the command.
        Ok(_) => return Ok(()),
        Err(_) => {}
    }
    let parent = parent_of(path);
    match output {
        Output::File(_) if std::fs::metadata(&parent).is_err() => Err(OutputRefused::MissingDir {
            output: shown(path),
            dir: shown(&parent),
        }),
        _ => writable(path, &nearest_existing(&parent)),
    }
}

/// The directory a relative or bare name lands in.
fn parent_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// The path itself or its closest ancestor that exists (what `create_dir_all` starts from).
fn nearest_existing(path: &Path) -> PathBuf {
    path.ancestors()
        .find(|p| !p.as_os_str().is_empty() && std::fs::metadata(p).is_ok())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

fn holds_entries(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut entries| entries.next().is_some())
}

/// The input that is the same file as `output`. Inputs that cannot be resolved (`-`, a missing
/// file) cannot be overwritten by it.
fn same_input<'i>(output: &Path, inputs: &'i [PathBuf]) -> Option<&'i PathBuf> {
    inputs.iter().find(|input| same_file(output, input))
}

/// Whether `output` and `input` are one file on disk: the same device and inode, so another
/// spelling, a symbolic link and a hard link are all caught (a hard link has its own path).
#[cfg(unix)]
fn same_file(output: &Path, input: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(output), std::fs::metadata(input)) {
        (Ok(o), Ok(i)) => o.dev() == i.dev() && o.ino() == i.ino(),
        _ => false,
    }
}

/// Whether `output` and `input` are one file, by canonical path (without inodes to compare).
#[cfg(not(unix))]
fn same_file(output: &Path, input: &Path) -> bool {
    canonical_target(output).is_some_and(|t| std::fs::canonicalize(input).is_ok_and(|c| c == t))
}

/// Where writing `path` would land: its canonical path, or its canonical directory and name.
#[cfg(not(unix))]
fn canonical_target(path: &Path) -> Option<PathBuf> {
    if let Ok(c) = std::fs::canonicalize(path) {
        return Some(c);
    }
    let name = path.file_name()?;
    std::fs::canonicalize(parent_of(path))
        .ok()
        .map(|dir| dir.join(name))
}

/// Whether files can be created in `dir`: a probe file is created there and removed, which
/// also catches read-only mounts and access lists that permission bits do not show.
fn writable(output: &Path, dir: &Path) -> Result<(), OutputRefused> {
    let refused = |why: String| OutputRefused::Unwritable {
        output: shown(output),
        place: format!("`{}`", dir.display()),
        why,
    };
    if !dir.is_dir() {
        return Err(refused("is not a directory".to_string()));
    }
    let probe = dir.join(format!(".imucal-write-check-{}", std::process::id()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(file) => {
            drop(file);
            // A probe that cannot be removed is harmless; the directory was writable.
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(refused(format!("cannot be written in ({e})"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("imucal-outputs-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir writable");
        dir
    }

    #[test]
    fn an_output_named_differently_from_its_input_is_still_the_input() {
        let dir = scratch("same");
        let input = dir.join("p.json");
        std::fs::write(&input, "{}").unwrap();
        let other_spelling = dir.join(".").join("p.json");
        let error = check_outputs(&[Output::File(&other_spelling)], &[input], true).unwrap_err();
        assert!(
            matches!(error, OutputRefused::SameAsInput { .. }),
            "{error}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn force_replaces_a_file_and_fills_a_directory_but_never_an_input() {
        let dir = scratch("force");
        let file = dir.join("old.csv");
        std::fs::write(&file, "t_s\n").unwrap();
        assert!(check_outputs(&[Output::File(&file)], &[], true).is_ok());
        assert!(check_outputs(&[Output::Dir(&dir)], &[], true).is_ok());
        assert!(matches!(
            check_outputs(&[Output::Dir(&dir)], &[], false),
            Err(OutputRefused::NonEmptyDir(_))
        ));
        assert!(matches!(
            check_outputs(&[Output::Dir(&file)], &[], true),
            Err(OutputRefused::NotADirectory(_))
        ));
        std::fs::remove_dir_all(&dir).ok();
    }

    #[cfg(unix)]
    #[test]
    fn a_device_is_written_to_and_not_refused_as_existing() {
        let null = Path::new("/dev/null");
        assert!(check_outputs(&[Output::File(null)], &[], false).is_ok());
    }

    #[test]
    fn a_file_in_a_missing_directory_is_refused_unless_the_command_creates_it() {
        let dir = scratch("missing");
        let nested = dir.join("new").join("report.html");
        assert!(matches!(
            check_outputs(&[Output::File(&nested)], &[], false),
            Err(OutputRefused::MissingDir { .. })
        ));
        assert!(check_outputs(&[Output::FileInNewDir(&nested)], &[], false).is_ok());
        std::fs::remove_dir_all(&dir).ok();
    }
}
