//! What a worker holds of the model rank 0 renders: one [`Model`] implementation per kind
//! (`bft.rs` for single-stream and chunked `.bft`, `pm.rs`, `nsp.rs`), chosen in `kinds.rs`.
//! A new kind is a file here, an arm there, and its messages; the loop (`rank.rs`) does not
//! change.

use protocol::{PmMemory, ProtocolError, TilePixels, ToWorker};

use super::WorkerError;
use crate::render::Renderer;

/// A model on a worker, of one kind: it takes that kind's frame messages and renders them.
pub trait Model {
    /// Takes one frame message; renders when the frame is whole (a `.bft` frame from several
    /// sorters comes in shares: `None` until the last), or fails naming the reason.
    fn frame(&mut self, renderer: &mut Renderer, msg: ToWorker) -> Result<Option<Rendered>, WorkerError>;
}

/// A frame rendered by a [`Model`]: its tiles' pixels and what the stats line reports.
pub struct Rendered {
    pub frame: u32,
    pub tiles: Vec<TilePixels>,
    /// The progressive mesh's memory (zero for the other kinds).
    pub memory: PmMemory,
    /// When the tiles were ready to draw (Unix ms), where the model knows it; otherwise the
    /// span is made from the tiles' times.
    pub prepared_ms: Option<f64>,
}

/// The error for a frame that is not of the held model's kind.
pub(super) fn wrong_kind(msg: &ToWorker) -> WorkerError {
    match msg {
        ToWorker::PmFrame(_) => WorkerError::FrameBeforeModel,
        ToWorker::NspFrame(_) => WorkerError::NspFrame("arrived before its model"),
        other => {
            WorkerError::BadMessage(ProtocolError::Unexpected(format!("{} for a model of another kind", other.name())))
        }
    }
}
