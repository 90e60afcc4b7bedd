//! The library's error type. Every variant names the file and/or field that is wrong, so the
//! binary can report it as is.

use std::path::PathBuf;

/// Errors returned by the library. The binary wraps them with `anyhow`.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file could not be opened, read or written. The message names the file; the I/O error
    /// is the `source` only, so an error chain (`{:#}` in anyhow) prints it once.
    #[error("{path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file was read but its content is not what it should be (wrong magic, unknown format,
    /// a header field out of range). `field` names the header field or key.
    #[error("{path}: field `{field}`: {msg}")]
    Format {
        path: PathBuf,
        field: String,
        msg: String,
    },
    /// An argument or in-memory value is invalid. `field` names it (a CLI flag, a geometry
    /// field, a parameter group).
    #[error("invalid `{field}`: {msg}")]
    Invalid { field: String, msg: String },
    /// A NaN or infinite value where a finite one is required.
    #[error("non-finite value in {what} at index {index} ({value})")]
    NonFinite {
        what: String,
        index: usize,
        value: f64,
    },
    /// A geometry that cannot produce a useful projection (rays miss the volume, source inside
    /// the volume, ...).
    #[error("geometry: {0}")]
    Geometry(String),
    /// Training diverged: a NaN or infinite loss.
    #[error("training diverged at iteration {iteration}: {what}")]
    Diverged { iteration: usize, what: String },
}

/// Result alias of the crate.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Wrap an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
    /// A format error in `path` at `field`.
    pub fn format(
        path: impl Into<PathBuf>,
        field: impl Into<String>,
        msg: impl Into<String>,
    ) -> Self {
        Error::Format {
            path: path.into(),
            field: field.into(),
            msg: msg.into(),
        }
    }
    /// An invalid value of `field`.
    pub fn invalid(field: impl Into<String>, msg: impl Into<String>) -> Self {
        Error::Invalid {
            field: field.into(),
            msg: msg.into(),
        }
    }
}

/// Return `Err(NonFinite)` at the first non-finite value of `x`.
pub fn check_finite<T: Copy + Into<f64>>(what: &str, x: &[T]) -> Result<()> {
    match x.iter().position(|&v| !v.into().is_finite()) {
        None => Ok(()),
        Some(index) => Err(Error::NonFinite {
            what: what.to_string(),
            index,
            value: x[index].into(),
        }),
    }
}
