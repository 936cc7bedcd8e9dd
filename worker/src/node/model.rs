//! What a worker holds of the model rank 0 renders: one [`Model`] implementation per kind
//! (`bft.rs` for single-stream and chunked `.bft`, `pm.rs`, `nsp.rs`). A new kind is a file
//! here and its messages; the loop (`rank.rs`) does not change.

use std::path::Path;

use protocol::{DpmFile, NspModel, PmMemory, PmModel, ProtocolError, TilePixels, ToWorker};

use super::bft::BftTiles;
use super::nsp::NspView;
use super::pm::PmTiles;
use super::WorkerError;
use crate::gpu::Gpu;
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

/// What a message from rank 0 is to the worker (other than the end of the run).
pub(super) enum Loaded {
    /// A model message: the model it sets up.
    Model(Box<dyn Model>),
    /// A frame message, for the model held.
    Frame(ToWorker),
}

/// Sets up the model a model message names (`.dpm` bytes or file, `.nsp` skeleton), or hands
/// a frame message on.
pub(super) fn load(gpu: &Gpu, msg: ToWorker) -> Result<Loaded, WorkerError> {
    Ok(Loaded::Model(match msg {
        ToWorker::Model(PmModel { dpm, gpu_budget }) => Box::new(PmTiles::new(gpu, &dpm, gpu_budget)?),
        ToWorker::DpmFile(DpmFile { path, gpu_budget, pool_bytes }) => {
            Box::new(PmTiles::open(gpu, Path::new(&path), gpu_budget, pool_bytes)?)
        }
        ToWorker::NspModel(NspModel { skeleton }) => Box::new(NspView::new(skeleton)?),
        frame => return Ok(Loaded::Frame(frame)),
    }))
}

/// The model a frame sets up when no model message came first: a `.bft` model needs none
/// (each frame carries its streams); the other kinds' frames cannot come first.
pub(super) fn for_first_frame(msg: &ToWorker) -> Result<Box<dyn Model>, WorkerError> {
    match msg {
        ToWorker::Frame(_) => Ok(Box::new(BftTiles::default())),
        other => Err(wrong_kind(other)),
    }
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
