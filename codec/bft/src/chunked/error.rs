//! Errors of a chunk, named by the chunk.

use crate::container::{Format, FormatError};

/// A corrupt `.bft` error with this message.
pub(crate) fn corrupt(msg: impl Into<String>) -> FormatError {
    FormatError::Corrupt(Format::Bft, msg.into())
}

/// A corrupt `.bft` error of chunk `i`.
pub(crate) fn chunk_err(i: usize, msg: impl std::fmt::Display) -> FormatError {
    corrupt(format!("chunk {i}: {msg}"))
}

/// An error of chunk `i`'s own stream, named by its chunk: a corrupt stream's message once
/// ("corrupt .bft data: chunk 3: ..."), a stream too large for the cap still too large, and a
/// read that failed as it was.
pub(crate) fn in_chunk(i: usize, e: FormatError) -> FormatError {
    match e {
        FormatError::Corrupt(f, m) => FormatError::Corrupt(f, format!("chunk {i}: {m}")),
        FormatError::TooLarge(m) => FormatError::TooLarge(format!("chunk {i}: {m}")),
        FormatError::Checksum(what) => chunk_err(i, format!("checksum mismatch in its {what}")),
        FormatError::Truncated(what) => chunk_err(i, format!("its {what} is truncated")),
        e @ FormatError::Io(_) => e,
        e => chunk_err(i, e),
    }
}
