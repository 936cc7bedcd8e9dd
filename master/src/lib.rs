//! Tessera's master side: the commands behind the `tessera` binary. Rank 0 of a cluster run
//! lives here (the frame loop arrives with the cluster pipeline); so do the file commands
//! `encode`, `decode` and `stats`.

pub mod cli;
pub mod commands;
pub mod composite;
pub mod output;
pub mod pm;
pub mod progress;
pub mod render;
pub mod sort;
