//! Why an `.nsp` cannot be built or read.

use thiserror::Error;

/// Why an `.nsp` cannot be built or read.
#[derive(Debug, Error, PartialEq)]
pub enum NspError {
    #[error("{0}")]
    Params(String),
    #[error("{0}")]
    Input(String),
    #[error("the input has no points")]
    Empty,
    #[error("not an .nsp file: {0}")]
    Format(String),
    #[error("cell {cell}: {what}")]
    Cell { cell: u32, what: String },
    /// A count the file holds, above what `--max-decompressed` lets a reader allocate.
    #[error("{0}, above the cap on decompressed input (raise it with --max-decompressed)")]
    TooLarge(String),
    /// Flags that would make more cells than a reader opens (see [`super::Params::check_cells`]).
    #[error("{0}")]
    TooManyCells(String),
    /// Writing (or reading back) the build's temporary files in `folder` failed: a full
    /// disk, a write error. The build stops at the first failure.
    #[error("cannot {} temporary files in {}: {error}", if *write { "write" } else { "read" }, folder.display())]
    Temp { write: bool, folder: std::path::PathBuf, error: String },
    /// Writing the built file failed.
    #[error("{0}")]
    Output(String),
}
