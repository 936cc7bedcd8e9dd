//! A worker rank: start the renderer, report ready, then for every frame decode each tile
//! it was sent, render the tile's part of the frame, and send the pixels back to rank 0.
//! Any failure is reported to rank 0 with its reason before the worker exits.
//!
//! With a progressive mesh (a `Model` message, then `PmFrame`s) the worker uploads the mesh
//! once and keeps one GPU adaptation per tile it has rendered: every frame it adapts each of
//! its tiles to the tile's sub-frustum ([`codec::pm::Viewpoint::for_tile`]), starting from the
//! tile's mesh of the frame before, and renders it from the GPU buffers.
//!
//! Everything that stops a worker is a [`WorkerError`]; its display is the reason rank 0
//! receives and prints as `rank R failed: <reason>`.
//!
//! The worker's rooms, one concern each; each model kind is one file, behind [`Model`]:
//!
//! | file | what |
//! |---|---|
//! | `rank.rs` | the loop: start the GPU, say ready, take messages, answer with pixels; heartbeats and test faults |
//! | `model.rs` | the [`Model`] a kind implements |
//! | `kinds.rs` | which kind a message sets up |
//! | `bft.rs` | `.bft` models, single-stream and chunked: tiles' streams decoded and drawn, chunks kept between frames, a frame's shares from several sorters joined |
//! | `pm.rs` | a progressive mesh (`.dpm`), in core or out of core, adapted on the GPU |
//! | `nsp.rs` | an `.nsp` model: cells received, refined to the frame's selection and drawn |
//! | `tiles.rs` | tiles drawn together and cut out of one draw (the `.dpm` and `.nsp` kinds) |
//! | `error.rs` | why a worker stops, in the words rank 0 prints |

mod bft;
mod error;
mod kinds;
mod model;
mod nsp;
mod pm;
mod rank;
mod tiles;

pub use bft::{kept_cost, KeptChunk};
pub use error::{RankError, TileError, WorkerError};
pub use model::Model;
pub use rank::{run, run_routed, Route, HEARTBEAT};
pub use tiles::MAX_DRAWS;
