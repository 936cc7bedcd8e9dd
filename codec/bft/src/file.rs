//! Either kind of `.bft` file, one stream or a chunked file of many, behind one call each:
//! decode the model, or measure its sections.

use std::path::Path;

use super::chunked::ChunkedFile;
use super::decode::{decode_stream, Decoded};
use super::format::{self, is_chunked, BftError, Stats};

/// Decodes `.bft` bytes: one stream, or every chunk of a chunked file as one model
/// ([`ChunkedFile::decode_all`]).
pub fn decode(bytes: &[u8]) -> Result<Decoded, BftError> {
    if is_chunked(bytes) {
        return ChunkedFile::open(bytes)?.decode_all();
    }
    decode_stream(bytes)
}

/// Reads and decodes a `.bft` file.
pub fn decode_file(path: &Path) -> Result<Decoded, BftError> {
    let bytes = crate::input::read_file(path).map_err(|e| format::corrupt(format!("{}: {e}", path.display())))?;
    decode(&bytes)
}

impl Stats {
    /// The sizes of a single-stream or a chunked file ([`ChunkedFile::stats`]).
    pub fn of(bytes: &[u8]) -> Result<Stats, BftError> {
        if is_chunked(bytes) {
            return ChunkedFile::open(bytes)?.stats();
        }
        Stats::of_stream(bytes)
    }
}
