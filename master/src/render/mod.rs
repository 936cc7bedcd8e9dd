//! `tessera render`, rank 0's side: the sort-first frame loop.
//!
//! Per frame: place the camera, sort the model into compressed tile submeshes, assign the
//! tiles to workers, send each worker its tiles (non-blocking, all at once), receive the
//! tile pixels, stitch them, write the PNG (or one per display of a tile wall) and a stats
//! line per rank. Without `mpirun` the same loop drives one worker thread over channels.
//!
//! A progressive mesh (`.dpm`) takes another path through the same loop: rank 0 sends the
//! file to every worker once, then per frame only the camera and each worker's tiles; each
//! worker adapts the mesh on its GPU to each tile's sub-frustum and renders it.
//!
//! `main` decides the role of the process (rank 0 this module, ranks above it
//! `worker::node`); the files here are one concern each:
//!
//! | file | what |
//! |---|---|
//! | `run.rs` | rank 0 under mpirun, or alone with a worker thread |
//! | `control.rs` | a live run's control port: JSON commands that steer the frames |
//! | `plan.rs` | what is checked before any rank talks to another, and the output files' names |
//! | `scene/` | the model rank 0 holds, a file per kind (`.bft`, chunked `.bft`, `.dpm`, `.nsp`), and each frame's messages to the workers |
//! | `frame_loop.rs` | the frame loop |
//! | `schedule.rs` | which worker renders which tile (round robin, or balanced by cost) |
//! | `sorter.rs` | a rank that helps rank 0 sort a chunked model (`--sorters K`) |
//! | `link.rs` | the handshake, heartbeats and silence, receiving the tiles' pixels |
//! | `display.rs` | direct send: display ranks that assemble and write a wall's displays at a swap barrier |
//! | `stats.rs` | the `--stats` JSON lines of rank 0 and of the workers |

pub mod control;
mod display;
mod eye;
mod frame_loop;
mod link;
mod plan;
mod run;
mod scene;
mod schedule;
mod sorter;
pub mod stats;

pub use display::{run_display, DirectSend};
pub use frame_loop::{orbit, orbit_by, Present, Window};
pub use plan::{frame_path, plan, plan_view, Plan};
pub use run::{run_alone, run_alone_live, run_master, run_windowed};
pub use schedule::assign;
pub use sorter::run_sorter;
