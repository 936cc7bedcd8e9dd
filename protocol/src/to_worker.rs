//! What a worker is sent: the model once (a progressive mesh, an out-of-core file, an
//! nSP-tree's skeleton), then frames, then the end of the run. A sorted model's frames come
//! from rank 0, or one share from each sorter rank.

use crate::frame::FrameJob;
use crate::nsp::{NspFrameJob, NspModel};
use crate::pm::{DpmFile, PmFrameJob, PmModel};
use crate::to_master::PixelCodec;
use crate::wire::{Reader, Writer};
use crate::{ProtocolError, KEEP_ALIVE, SHUTDOWN};

/// A message to a worker.
#[derive(Clone, Debug, PartialEq)]
pub enum ToWorker {
    /// Kind 1.
    Frame(FrameJob),
    /// Kind 2: the run is over.
    Shutdown,
    /// Kind 6.
    Model(PmModel),
    /// Kind 15.
    DpmFile(DpmFile),
    /// Kind 7.
    PmFrame(PmFrameJob),
    /// Kind 10.
    NspModel(NspModel),
    /// Kind 11.
    NspFrame(NspFrameJob),
    /// Kind 16: drop the model and every cache; another model follows (a live run's `load`).
    Unload,
    /// Kind 17: nothing to do yet; rank 0 is there (an idle live run).
    KeepAlive,
    /// Kind 19: how to code the pixels of the frames that follow (`--pixel-codec`).
    PixelCodec(PixelCodec),
}

const FRAME: u8 = 1;
const MODEL: u8 = 6;
const PM_FRAME: u8 = 7;
const NSP_MODEL: u8 = 10;
const NSP_FRAME: u8 = 11;
const DPM_FILE: u8 = 15;
const UNLOAD: u8 = 16;
const PIXEL_CODEC: u8 = 19;

impl ToWorker {
    /// The message's kind, for errors that name one without dumping its contents.
    pub fn name(&self) -> &'static str {
        match self {
            ToWorker::Frame(_) => "a frame",
            ToWorker::Shutdown => "a shutdown",
            ToWorker::Model(_) => "a progressive mesh",
            ToWorker::DpmFile(_) => "a progressive mesh file",
            ToWorker::PmFrame(_) => "a progressive-mesh frame",
            ToWorker::NspModel(_) => "an nSP-tree model",
            ToWorker::NspFrame(_) => "an nSP-tree frame",
            ToWorker::Unload => "an unload",
            ToWorker::KeepAlive => "a keep-alive",
            ToWorker::PixelCodec(_) => "a pixel codec",
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        match self {
            ToWorker::Frame(m) => Writer::message(FRAME, m),
            ToWorker::Shutdown => Writer::new(SHUTDOWN).finish(),
            ToWorker::Model(m) => Writer::message(MODEL, m),
            ToWorker::DpmFile(m) => Writer::message(DPM_FILE, m),
            ToWorker::PmFrame(m) => Writer::message(PM_FRAME, m),
            ToWorker::NspModel(m) => Writer::message(NSP_MODEL, m),
            ToWorker::NspFrame(m) => Writer::message(NSP_FRAME, m),
            ToWorker::Unload => Writer::new(UNLOAD).finish(),
            ToWorker::KeepAlive => Writer::new(KEEP_ALIVE).finish(),
            ToWorker::PixelCodec(c) => Writer::message(PIXEL_CODEC, c),
        }
    }

    pub fn decode(b: &[u8]) -> Result<ToWorker, ProtocolError> {
        let (r, kind) = Reader::open(b)?;
        Ok(match kind {
            FRAME => ToWorker::Frame(r.body()?),
            SHUTDOWN => {
                r.body::<()>()?;
                ToWorker::Shutdown
            }
            MODEL => ToWorker::Model(r.body()?),
            DPM_FILE => ToWorker::DpmFile(r.body()?),
            PM_FRAME => ToWorker::PmFrame(r.body()?),
            NSP_MODEL => ToWorker::NspModel(r.body()?),
            NSP_FRAME => ToWorker::NspFrame(r.body()?),
            UNLOAD => {
                r.body::<()>()?;
                ToWorker::Unload
            }
            KEEP_ALIVE => {
                r.body::<()>()?;
                ToWorker::KeepAlive
            }
            PIXEL_CODEC => ToWorker::PixelCodec(r.body()?),
            k => return Err(ProtocolError::UnknownKind(k)),
        })
    }
}
