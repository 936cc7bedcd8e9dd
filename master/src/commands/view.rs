//! `tessera view MODEL`: one process, one window. Rank 0's frame loop and one worker thread
//! run as `render` runs alone, sort-first through the same tiles; the window (`crate::window`)
//! shows each composited frame and turns its mouse and keys into the commands of the control
//! port (`render::control`), which rank 0 applies to the next frame it sorts. Nothing
//! changes, nothing is drawn: the event loop sleeps until an event, and rank 0 until a
//! command.
//!
//! Its mouse and keys are those of every live window (`crate::window`'s table).
//! A resized window is re-planned at its size (same tile grid) and the frame sorted again.

use anyhow::Result;

use crate::cli::RenderArgs;
use crate::window::{Behaviour, WindowSpec};

/// `tessera view`: the window on a thread of its own, the frame loop on this one and its
/// worker on another.
pub fn run(args: &RenderArgs) -> Result<()> {
    let plan = crate::render::plan_view(args)?;
    let behaviour = Behaviour { resize: true, hud: true, ..Behaviour::of(&plan) };
    crate::render::run_windowed(&plan, vec![WindowSpec::frame(&plan)], behaviour, crate::render::run_alone_live)
}
