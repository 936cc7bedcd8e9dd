//! Why a worker stops ([`WorkerError`], one tile's [`TileError`]) and what [`super::run`]
//! returns ([`RankError`]): the reasons rank 0 prints as `rank R failed: <reason>`.

use codec::bft::BftError;
use codec::pm::DpmError;
use protocol::ProtocolError;
use thiserror::Error;

use crate::gpu::GpuError;
use crate::pm_adapt::AdaptError;
use crate::render::RenderError;

/// Why a worker stopped: the reason it sends rank 0 in [`ToMaster::Failed`](protocol::ToMaster::Failed).
#[derive(Debug, Error)]
pub enum WorkerError {
    /// The GPU could not be opened.
    #[error(transparent)]
    Gpu(#[from] GpuError),
    /// Transport: a message from a rank other than 0.
    #[error("unexpected message from rank {0}")]
    UnexpectedSender(usize),
    /// Transport: nothing from rank 0 for `MASTER_SILENCE`.
    #[error("no message from rank 0 for an hour")]
    MasterSilent,
    /// Transport: rank 0's end is closed (reported to no one: there is no one to tell).
    #[error("rank 0 is gone")]
    MasterGone,
    /// Protocol: bytes from rank 0 that are no message.
    #[error("bad message from rank 0: {0}")]
    BadMessage(ProtocolError),
    /// Protocol: a `PmFrame` before any `Model`.
    #[error("a progressive-mesh frame arrived before its model")]
    FrameBeforeModel,
    /// Decode: the `Model` message's `.dpm` bytes, or the head of a `DpmFile`'s file.
    #[error("cannot decode the progressive mesh: {0}")]
    Model(DpmError),
    /// The `DpmFile` message's file could not be opened or read.
    #[error("{path}: {error}")]
    ModelFile { path: String, error: DpmError },
    /// GPU: the progressive mesh could not be uploaded.
    #[error(transparent)]
    Upload(AdaptError),
    /// The `.nsp` model or one of its cells.
    #[error("the .nsp model: {0}")]
    Nsp(codec::nsp::NspError),
    /// Protocol: an `NspFrame` before any `NspModel`, or naming a cell it does not select.
    #[error("an .nsp frame {0}")]
    NspFrame(&'static str),
    /// The `fail` hook of `TESSERA_FAULT`.
    #[error("injected failure (TESSERA_FAULT)")]
    Injected,
    /// One tile of a frame.
    #[error("tile {index}: {error}")]
    Tile { index: u32, error: TileError },
}

/// Why a tile could not be rendered.
#[derive(Debug, Error)]
pub enum TileError {
    #[error("cannot decode the submesh: {0}")]
    Decode(BftError),
    #[error("border normal for vertex {slot}, but the stream has {vertices}")]
    BorderNormal { slot: u32, vertices: usize },
    #[error("cannot decode chunk {0} of the model: {1}")]
    ChunkDecode(u32, BftError),
    #[error("the master named chunk {0}, which this worker does not hold")]
    MissingChunk(u32),
    #[error("rect {0:?} is not a non-empty part of the frame")]
    BadRect([u32; 4]),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Adapt(#[from] AdaptError),
}

impl TileError {
    pub(super) fn at(self, index: u32) -> WorkerError {
        WorkerError::Tile { index, error: self }
    }
}

/// What [`run`](super::run) returns when a worker stops on an error: its rank and the reason, displayed
/// `rank R: <reason>`.
#[derive(Debug, Error)]
#[error("rank {rank}: {reason}")]
pub struct RankError {
    pub rank: usize,
    pub reason: WorkerError,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::RenderError;

    /// The reasons rank 0 prints (`rank R failed: <reason>`), which scripts and
    /// `tests/cluster_faults.rs` match, word for word.
    #[test]
    fn failure_reasons_keep_their_wording() {
        let cases = [
            (WorkerError::UnexpectedSender(3), "unexpected message from rank 3"),
            (WorkerError::MasterSilent, "no message from rank 0 for an hour"),
            (WorkerError::MasterGone, "rank 0 is gone"),
            (
                WorkerError::BadMessage(ProtocolError::Truncated("header")),
                "bad message from rank 0: message is truncated (while reading header)",
            ),
            (WorkerError::FrameBeforeModel, "a progressive-mesh frame arrived before its model"),
            (WorkerError::Injected, "injected failure (TESSERA_FAULT)"),
            (TileError::BadRect([4, 0, 2, 9]).at(7), "tile 7: rect [4, 0, 2, 9] is not a non-empty part of the frame"),
            (
                TileError::BorderNormal { slot: 12, vertices: 10 }.at(2),
                "tile 2: border normal for vertex 12, but the stream has 10",
            ),
            (
                TileError::Render(RenderError::NormalCount { positions: 3, normals: 0 }).at(0),
                "tile 0: mesh has 3 positions but 0 normals",
            ),
            (
                TileError::Adapt(AdaptError::FaceIndex { index: 9, vertices: 4 }).at(5),
                "tile 5: GPU error: face index 9 out of 4 vertices",
            ),
            (
                TileError::Adapt(AdaptError::corrupt(10, 3 * 65536 + 17, true)).at(1),
                "tile 1: corrupt .dpm data: node 3: operation at byte 17: bad operation pointer",
            ),
            (
                TileError::Adapt(AdaptError::TooLarge { elements: 9, what: "vertices", bytes: 1152, limit: 1024 }).at(0),
                "tile 0: the adapted mesh needs 9 vertices, 1152 bytes in one buffer, and this GPU binds at most 1024: \
                 raise --error-px",
            ),
        ];
        for (error, reason) in cases {
            assert_eq!(error.to_string(), reason);
        }
        let stopped = RankError { rank: 2, reason: WorkerError::MasterGone };
        assert_eq!(stopped.to_string(), "rank 2: rank 0 is gone");
    }
}
