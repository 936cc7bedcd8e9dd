//! The adaptation's fixed limits and defaults: what a software adapter's loop limit allows,
//! the descent stacks' and scratch area's caps, the error scale's steps, and the node pool's
//! share of a budget.

use super::error::AdaptError;

/// The most steps a descent slot runs in one dispatch on a software adapter (lavapipe), a
/// step being one vertex visited (its operation's head decoded, and the rest where it
/// splits): llvmpipe ends every loop of an invocation after 65535 iterations in all,
/// silently, and as it counts them (a loop per symbol of eight lanes, running as long as the
/// longest code of any lane) a step took up to 256-512: the dragon's and the bunny's lockstep
/// paths ran in rounds of 128 steps and reached the limit in rounds of 256 (the pass then
/// fails, `loops_alive` of `descent.wgsl`). So a slot pauses its descent after 64 steps and
/// the next dispatch of the same stage goes on with it (as fast as 128: 231 against 229 ms an
/// orbit frame). Hardware GPUs never pause.
pub const SOFTWARE_ROUND_STEPS: u32 = 64;

/// The descent slots (threads of `count` and `descend`) on a software adapter, which takes
/// a descent from the queue whenever it finished one: a few per lane of its cores, so that
/// the lanes of a core stay busy until the queue is empty. A hardware GPU gets as many as
/// the stacks hold, up to one per descent.
pub const SOFTWARE_DESCENT_SLOTS: u32 = 1024;

/// Vectors of a descent's resume record after the stacks (`RESUME_VECS` of `descent.wgsl`).
pub(crate) const RESUME_VECS: u64 = 12;

/// Unless [`GpuAdapter::set_levels`](super::GpuAdapter::set_levels) chose one kind of pass: the splits a descent averages in
/// an all-levels pass past which the later passes for the same view run one level. Measured
/// on lavapipe (the dragon at 1920x1080, 0.5 px): from the base mesh the passes average
/// 14-23, and all levels took 2.5-3.2 s to converge against 1.0-1.3 s in one-level passes; a
/// 22.5 degree orbit step averages about 2-6 and converges in one all-levels pass (11x a
/// converged pass) against 10 one-level passes (24x).
pub const DEEP_DESCENT: u32 = 8;

/// The one-level passes that changed the mesh after which a view switched to them by
/// [`DEEP_DESCENT`] goes back to all levels for good: its split trees are deeper than a
/// one-level pass a level can follow (planar regions, whose errors tie, make long chains:
/// from the base mesh the alligator took 1,110 passes, the fandisk 682), and an all-levels
/// pass moves up to `LEVELS_PER_PASS` (32) levels. The dragon from its base mesh converges
/// in fewer (25 one-level passes in all).
pub const DEEP_PASSES: u32 = 32;

/// Words of one entry of a descent's stack (`STACK_WORDS` of `descent.wgsl`).
pub(crate) const STACK_WORDS: u64 = 24;

/// The most bytes the descent stacks take (a memory budget of `b` bytes allows at most
/// `b / 64`): 10,922 slots, 32 entries each (a slot each for the dragon's 5,000-9,000
/// descents an orbit frame at 1920x1080).
pub const MAX_STACK_BYTES: u64 = 32 << 20;

/// The most bytes the count's scratch area takes (a memory budget of `b` bytes allows at
/// most `b / 64`): 147,000 leaves with their splits and three faces a split. A pass that
/// keeps more (from the base mesh of a large model) walks its descents again instead.
pub const MAX_SCRATCH_BYTES: u64 = 32 << 20;

/// The default of the paper's `n_alloc`: spare elements a reallocated buffer gets.
pub const DEFAULT_N_ALLOC: u32 = 1 << 15;

/// The factor by which a pass held back by the memory budget raises the error the passes
/// after it adapt to, and by which a converged mesh with room to spare lowers it again.
/// A step of 1.5 changes the mesh by up to 2.25x (screen-space error e leaves about 1/e^2 of
/// the triangles of a distant view; a close one, whose coarse spheres hold the eye, changes
/// far less: the bunny seen from close needs 57.7x the error for 43% of its triangles).
/// `GpuAdapter::fits_finer` lowers the error where the mesh takes at most half the room,
/// and a view goes no lower than the scale that last overflowed for it.
pub(crate) const SCALE_STEP: f32 = 1.5;
/// The largest error scale (a budget that cannot hold even a coarse mesh ends here).
pub(crate) const MAX_SCALE: f32 = 1e6;

/// The share of `--gpu-budget-mb` an out-of-core worker gives its node pool by default; the
/// rest is for the tables and the adapted mesh. The 102M-triangle armadillo at 1920x1080
/// requires 345-460 nodes of 64 kB (22-29 MB) at 3 px and adapts 180-210 MiB of mesh, so a
/// quarter of 512 MiB holds the required nodes four times over, with room for the
/// lower-priority ones.
pub const DEFAULT_POOL_SHARE: f64 = 0.25;

/// The bytes of an out-of-core worker's node pool: `nodes` where given (less than the
/// budget), else [`DEFAULT_POOL_SHARE`] of `budget`, else (no budget) every node.
pub fn pool_bytes(budget: Option<u64>, nodes: Option<u64>) -> Result<u64, AdaptError> {
    match (budget, nodes) {
        (Some(b), Some(n)) if n >= b => Err(AdaptError::PoolOverBudget { pool: n, budget: b }),
        (_, Some(n)) => Ok(n),
        (Some(b), None) => Ok((b as f64 * DEFAULT_POOL_SHARE) as u64),
        (None, None) => Ok(u64::MAX),
    }
}
