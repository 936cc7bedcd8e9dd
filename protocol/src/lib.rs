//! The protocol every rank of `tessera render` speaks: every message between rank 0, the
//! workers, the sorters and the display ranks, with its byte layout. Both transports (MPI,
//! and channels for a run without mpirun) carry these same bytes, and every receive checks
//! what it got. It depends on nothing of Tessera, so the fuzz target reads it as it is.
//!
//! All integers are little-endian. A message starts with the 4-byte magic `TSRM`, the
//! 1-byte protocol version ([`VERSION`]; a message of another version is refused by name, so
//! ranks of different builds cannot misread each other) and a 1-byte kind; lengths are `u32`
//! and precede what they count. Each message's body is laid out in the doc of its type,
//! beside the code that writes and reads it:
//!
//! | to | kind | message | body |
//! |---|---|---|---|
//! | a worker ([`ToWorker`]) | 1 | `Frame` | [`FrameJob`] (from rank 0, or a share from each sorter) |
//! | | 6 | `Model` | [`PmModel`] |
//! | | 15 | `DpmFile` | [`DpmFile`] |
//! | | 7 | `PmFrame` | [`PmFrameJob`] |
//! | | 10 | `NspModel` | [`NspModel`] |
//! | | 11 | `NspFrame` | [`NspFrameJob`] |
//! | a sorter ([`ToSorter`]) | 9 | `Sort` | [`SortJob`] |
//! | a display rank ([`ToDisplay`]) | 12 | `DisplayFrame` | [`DisplayFrameJob`] |
//! | | 13 | `Swap` | [`Swap`] |
//! | | 16 | `Unload` | nothing: drop the model and every cache, another follows (a live run's `load`) |
//! | any of the three | 2 | `Shutdown` | nothing |
//! | a worker or a sorter | 17 | `KeepAlive` | nothing: a live run is idle, rank 0 is there |
//! | rank 0 ([`ToMaster`]) | 3 | `Ready` | [`Ready`] |
//! | | 8 | `Heartbeat` | nothing: alive and working |
//! | | 4 | `Pixels` | [`Pixels`] (workers send them to display ranks too) |
//! | | 5 | `Failed` | [`Failed`] |
//! | | 14 | `DisplayReady` | [`DisplayReady`] (from a display rank) |
//!
//! A tile is one or more `.bft` streams (a chunked model's verbatim chunks and sorted
//! pieces; one stream for a single-stream model), drawn one after the other. The normals of
//! a stream are those of its vertices that have triangles outside it: the worker computes
//! every other normal from the stream's own triangles, and these make the shading at tile and
//! chunk borders the same as in a whole-frame render. A chunk to keep goes into the worker's
//! chunk cache (`worker::chunk_cache::ChunkCache`) with its normals applied; a chunk kept
//! before is taken from there (the master mirrors the cache, so it names only chunks the
//! worker holds).

mod display;
mod error;
mod frame;
mod nsp;
mod pm;
mod sorter;
mod to_master;
mod to_worker;
mod wire;

pub use display::{DisplayFrameJob, Swap, ToDisplay};
pub use error::ProtocolError;
pub use frame::{FrameJob, StreamSource, TileJob, TileStream};
pub use nsp::{NspFrameJob, NspModel};
pub use pm::{DpmFile, PmFrameJob, PmModel};
pub use sorter::{SortJob, ToSorter};
pub use to_master::{
    DisplayReady, Failed, FrameSpan, Input, PixelCodec, Pixels, PmMemory, Ready, TilePixels, TileTimes, ToMaster,
};
pub use to_worker::ToWorker;

/// The protocol version this build speaks. 2 added the `Frame` flags byte, 3 the streams of
/// a tile and the chunk cache, 4 the `.nsp` messages, 5 the frame span of `Pixels` and the
/// display ranks' messages, 6 out-of-core `.dpm` files (`DpmFile`) and the memory of `Pixels`,
/// 7 the GPU budget of `Model` and `DpmFile`, the node pool of `DpmFile` and the error scale
/// of `Pixels`, 8 `Unload` and `KeepAlive`, 9 a window's `Input` and the pixel codec of
/// `Pixels`, 10 the screen error of `SortJob`; version 1 messages had no version byte, so
/// they read as version = their kind byte and are refused.
pub const VERSION: u8 = 10;

/// The kind of `Shutdown`, the same to workers, sorters and display ranks: rank 0 sends one
/// message to every rank.
const SHUTDOWN: u8 = 2;

/// The kind of `KeepAlive`, the same to workers, sorters and display ranks: an idle live run's rank 0 sends
/// it now and then, so that their silence limit measures rank 0's life, not the user's pause.
const KEEP_ALIVE: u8 = 17;

/// Now, in milliseconds since the Unix epoch (the clock of [`FrameSpan`] and of rank 0's
/// timeline).
pub fn unix_ms() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64() * 1e3)
}

/// What the fuzz target `decode_protocol` checks (the fuzzer and the workspace's regression
/// test over `fuzz/regressions/` run this): any bytes decode as a message to each kind of
/// rank, or are refused, never panic or allocate without bound; and a message that decodes
/// encodes back to the same bytes (the layout has no slack).
pub fn fuzz_round_trip(data: &[u8]) {
    if let Ok(m) = ToWorker::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to a worker encodes back to its bytes");
    }
    if let Ok(m) = ToSorter::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to a sorter encodes back to its bytes");
    }
    if let Ok(m) = ToDisplay::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to a display rank encodes back to its bytes");
    }
    if let Ok(m) = ToMaster::decode(data) {
        assert_eq!(m.encode(), data, "a decoded message to the master encodes back to its bytes");
    }
}

#[cfg(test)]
mod tests;
