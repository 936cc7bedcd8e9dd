//! The model rank 0 holds for `tessera render`, one file per kind behind [`Scene`]: a BFT
//! model it sorts every frame (`bft.rs`), a chunked one whose sort it may share with sorter
//! ranks (`chunked.rs`), a progressive mesh that the workers adapt themselves (`pm.rs`), and
//! an `.nsp` model whose cells it sends as the view selects them (`nsp.rs`). Each kind opens
//! its file, frames its camera, says what the workers get once, and makes every frame's
//! messages; the frame loop sees only [`Scene`] (`contract.rs`). A new kind is a file here, a
//! line in [`load`] (`load.rs`), and its messages.

mod bft;
mod chunked;
mod contract;
mod load;
mod nsp;
mod pm;

pub(super) use chunked::{ChunkedScene, Share};
pub(super) use contract::{frame_messages, FrameContext, FrameJobs, Scene, ShareContext};
pub(super) use load::{load, load_path};
