//! Errors crease reports to its users.
//!
//! Every error that comes from bad input names the file and the problem in one line, so the
//! CLI can print it and exit with code 2 (see [`Error::exit_code`]).

use std::path::{Path, PathBuf};

/// The crate-wide result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What went wrong.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An input file is missing, unreadable or malformed.
    #[error("{}: {msg}", path.display())]
    Input {
        /// The offending file.
        path: PathBuf,
        /// What is wrong with it, in one line.
        msg: String,
    },
    /// The user asked for something that cannot be done (bad argument combination, bad value).
    #[error("{0}")]
    Usage(String),
    /// The run was stopped by Ctrl-C or SIGTERM; its directory can be resumed.
    #[error("interrupted; run the same command again to continue")]
    Interrupted,
    /// Writing an output failed.
    #[error("{}: {source}", path.display())]
    Output {
        /// The file being written.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },
}

impl Error {
    /// An input error about `path`.
    pub fn input(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::Input { path: path.as_ref().to_path_buf(), msg: msg.into() }
    }

    /// An output error about `path`.
    pub fn output(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Output { path: path.as_ref().to_path_buf(), source }
    }

    /// Exit code for the CLI: 2 for bad input or usage, 1 for failures while writing.
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input { .. } | Error::Usage(_) => 2,
            Error::Output { .. } => 1,
            Error::Interrupted => 130,
        }
    }
}

/// Turns an I/O error while reading `path` into an input error with a readable message.
pub fn io_input(path: &Path, e: std::io::Error) -> Error {
    let msg = match e.kind() {
        std::io::ErrorKind::NotFound => "no such file or directory".to_string(),
        std::io::ErrorKind::PermissionDenied => "permission denied".to_string(),
        std::io::ErrorKind::UnexpectedEof => "file is truncated".to_string(),
        _ => e.to_string(),
    };
    Error::input(path, msg)
}
