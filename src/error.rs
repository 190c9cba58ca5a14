//! Errors crease reports to its users.
//!
//! Every error that comes from bad input names the file and the problem in one line, so the
//! CLI can print it and exit with code 65 (see [`Error::exit_code`]). Where a lower layer gave a
//! cause (an I/O or a decompression error), it is kept as the error's [`source`].
//!
//! [`source`]: std::error::Error::source

use std::path::{Path, PathBuf};

/// The crate-wide result type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A lower layer's error, kept as the cause.
pub type Cause = Box<dyn std::error::Error + Send + Sync>;

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
        /// The lower layer's error, if any.
        #[source]
        source: Option<Cause>,
    },
    /// A file of a run directory is damaged (wrong format, failed checksum, truncated): the
    /// run cannot continue from it.
    #[error("{}: damaged run directory file ({what}); run again with --force to start over", path.display())]
    Damaged {
        /// The damaged file.
        path: PathBuf,
        /// What is wrong with it.
        what: String,
        /// The lower layer's error, if any.
        #[source]
        source: Option<Cause>,
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
    /// A worker thread panicked: a bug in crease, not a problem with the input.
    #[error("internal error: the {0} thread panicked ({1}); please report this")]
    Panic(String, String),
}

impl Error {
    /// An input error about `path`.
    pub fn input(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::Input { path: path.as_ref().to_path_buf(), msg: msg.into(), source: None }
    }

    /// An input error about `path` with its cause.
    pub(crate) fn input_from(path: impl AsRef<Path>, msg: impl Into<String>, source: impl Into<Cause>) -> Self {
        Error::Input { path: path.as_ref().to_path_buf(), msg: msg.into(), source: Some(source.into()) }
    }

    /// A damaged run directory file.
    pub fn damaged(path: impl AsRef<Path>, what: impl Into<String>) -> Self {
        Error::Damaged { path: path.as_ref().to_path_buf(), what: what.into(), source: None }
    }

    /// An output error about `path`.
    pub fn output(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Output { path: path.as_ref().to_path_buf(), source }
    }

    /// The error for a thread `name` that panicked with `payload`.
    pub fn panic(name: &str, payload: Box<dyn std::any::Any + Send>) -> Self {
        Error::Panic(name.to_string(), panic_message(&payload))
    }

    /// Exit code for the CLI: [`exit::USAGE`] for what the user asked (the code clap gives a
    /// bad command line too), [`exit::DATA`] for bad input data, [`exit::OUTPUT`] for failures
    /// while writing, [`exit::INTERRUPTED`] and [`exit::INTERNAL`].
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Usage(_) => exit::USAGE,
            Error::Input { .. } | Error::Damaged { .. } => exit::DATA,
            Error::Output { .. } => exit::OUTPUT,
            Error::Interrupted => exit::INTERRUPTED,
            Error::Panic(..) => exit::INTERNAL,
        }
    }
}

/// The CLI's exit codes (besides 0). Scripts can tell a mistyped command, which no retry
/// fixes, from an input that is bad, and both from a run that was stopped and can be resumed.
pub mod exit {
    /// An output could not be written (disk full, permission denied).
    pub const OUTPUT: i32 = 1;
    /// A bad command line or option value, a job that differs from the one its run directory
    /// holds (without `--force`), or a run directory in use by another run.
    pub const USAGE: i32 = 2;
    /// Bad input data: an input file that is missing, unreadable or malformed, or a run
    /// directory file that is damaged (sysexits' EX_DATAERR).
    pub const DATA: i32 = 65;
    /// An internal error (a bug in crease; sysexits' EX_SOFTWARE).
    pub const INTERNAL: i32 = 70;
    /// Stopped by Ctrl-C or SIGTERM; the same command resumes the run.
    pub const INTERRUPTED: i32 = 130;
}

/// Turns an I/O error while reading `path` into an input error with a readable message,
/// keeping the I/O error as its cause.
pub(crate) fn io_input(path: &Path, e: std::io::Error) -> Error {
    let msg = match e.kind() {
        std::io::ErrorKind::NotFound => "no such file or directory".to_string(),
        std::io::ErrorKind::PermissionDenied => "permission denied".to_string(),
        std::io::ErrorKind::UnexpectedEof => "file is truncated".to_string(),
        _ => e.to_string(),
    };
    Error::input_from(path, msg, e)
}

/// The message a panic carried.
pub(crate) fn panic_message(payload: &Box<dyn std::any::Any + Send>) -> String {
    payload.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| payload.downcast_ref::<String>().cloned()).unwrap_or_else(|| "no message".to_string())
}
