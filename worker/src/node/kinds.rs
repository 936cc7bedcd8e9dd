//! Which kind of model a message sets up: the one place that knows every kind.

use std::path::Path;

use protocol::{DpmFile, NspModel, PmModel, ToWorker};

use super::bft::BftTiles;
use super::model::{wrong_kind, Model};
use super::nsp::NspView;
use super::pm::PmTiles;
use super::WorkerError;
use crate::gpu::Gpu;

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
