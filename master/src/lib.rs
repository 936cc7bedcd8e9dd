//! Tessera's master side, the commands behind the `tessera` binary: every flag ([`cli`]),
//! the camera a command asks for and its precision checks ([`camera`]), one
//! file per subcommand ([`commands`]: encode, decode, stats, sort, render, pm, nsp, plot),
//! opening any model kind and its bounds ([`model`]), rank 0 of `render` and the other ranks'
//! roles ([`render`]: the frame loop, tile scheduling, the workers' handshake and silence,
//! sorters, display ranks, stats), the compositor ([`composite`]), tile walls and their frusta
//! ([`wall`]), the windows of live runs ([`window`]), output files that are never left half-written ([`output`]), movies
//! ([`movie`]), progress bars ([`progress`]) and the spilling allocator of `pm build`
//! ([`spill`]). `main.rs` parses the flags and calls the command.

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

pub mod camera;
pub mod cli;
pub mod commands;
pub mod composite;
pub mod model;
pub mod movie;
pub mod output;
pub mod progress;
pub mod render;
pub mod spill;
pub mod wall;
pub mod window;
