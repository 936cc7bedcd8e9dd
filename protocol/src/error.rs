//! The one error of every decode.

use crate::VERSION;
use thiserror::Error;

/// A message that does not parse.
#[derive(Debug, Error, PartialEq)]
pub enum ProtocolError {
    #[error("message is truncated (while reading {0})")]
    Truncated(&'static str),
    #[error("message does not start with the protocol's magic number")]
    BadMagic,
    #[error(
        "a message of protocol version {0}; this build speaks version {VERSION}: run the same build on every rank"
    )]
    Version(u8),
    #[error("unknown message kind {0}")]
    UnknownKind(u8),
    #[error("unexpected message: {0}")]
    Unexpected(String),
    #[error("{0} trailing bytes after the message")]
    Trailing(usize),
    #[error("invalid message: {0}")]
    Invalid(String),
}
