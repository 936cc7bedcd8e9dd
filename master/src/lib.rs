//! Tessera's master side, the commands behind the `tessera` binary: every flag ([`cli`]), the
//! file commands `encode`, `decode` and `stats` ([`commands`]), the one-frame tile sort
//! ([`sort`]), the progressive-mesh commands ([`pm`]), rank 0 of `render` ([`render`]: the
//! frame loop, tile scheduling, the workers' handshake and silence, stats), the compositor
//! ([`composite`]), tile walls and their frusta ([`wall`]), output files that are never left
//! half-written
//! ([`output`]), and the timeline of a run's stats ([`plot`]). `main.rs` decides each process's role.

/// `println!` that returns an error instead of panicking when standard output is closed
/// (`tessera sort --json | head -c 1`): the caller propagates it with `?`, and `main` ends a
/// broken pipe quietly with a non-zero status ([`output::is_broken_pipe`]).
#[macro_export]
macro_rules! outln {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        ::std::writeln!(::std::io::stdout().lock(), $($arg)*)
    }};
}

pub mod cli;
pub mod commands;
pub mod composite;
pub mod movie;
pub mod nsp;
pub mod output;
pub mod plot;
pub mod pm;
pub mod progress;
pub mod render;
pub mod sort;
pub mod spill;
pub mod wall;
