//! How an adapter runs its passes (its `Tuning`): which levels a pass moves, the descents'
//! budget and rounds, the limits on the stacks and the scratch area without a budget, and
//! profiling; with the setters the tools and tests use.

use codec::pm::Levels;

use super::adapter::{scratch_buffers, GpuAdapter};
use super::buffers::{storage, VERTEX_USAGE};

impl GpuAdapter {
    /// How far a pass for a view moves a vertex in the split tree: every level the view asks
    /// for ([`Levels::All`]: one pass reaches the converged mesh where the descent budget
    /// allows), or one (the paper's passes). The passes are those of [`codec::pm::Adapter`]
    /// with the same setting. A full refinement ([`Self::refine_step`]) goes one level a pass
    /// either way. Setting it makes every pass for a view of that kind (the CPU references'
    /// passes, pass for pass). By default a pass for a new view runs all levels, and the
    /// later passes for the same view one level if it descended more than [`DEEP_DESCENT`](super::DEEP_DESCENT)
    /// splits a descent on average (a view far from the mesh, as from the base mesh: a
    /// descent is serial work in one thread, and one-level passes spread it over threads).
    pub fn set_levels(&mut self, levels: Levels) {
        self.tuning.levels = levels;
        self.tuning.mixed = false;
    }

    /// Sets the most splits one vertex's descent performs in an all-levels pass (at least 1):
    /// one thread's serial work. By default [`codec::pm::DESCENT_BUDGET`]. The CPU references
    /// take the same setting ([`codec::pm::Adapter::set_descent_budget`]).
    pub fn set_descent_budget(&mut self, splits: u32) {
        self.tuning.descent_budget = splits.max(1);
    }

    /// Sets the most steps (operations decoded) a descent slot runs in one dispatch before its
    /// descent pauses for the next (`u32::MAX`: no pause): [`SOFTWARE_ROUND_STEPS`](super::SOFTWARE_ROUND_STEPS) on a
    /// software adapter ([`Gpu::is_software`](crate::gpu::Gpu::is_software)), whose compiler ends an invocation's loops
    /// after 65535 iterations in all; none on hardware.
    pub fn set_round_steps(&mut self, steps: u32) {
        self.tuning.round_steps = steps.max(1);
    }

    /// The steps a descent slot runs in one dispatch now ([`Self::set_round_steps`]; halved
    /// where a software adapter's count reached its loop limit).
    pub fn round_steps(&self) -> u32 {
        self.tuning.round_steps
    }

    /// The most steps of one descent: one of `b` splits visits at most `2 b + 1` vertices,
    /// a step each.
    pub(super) fn descent_steps(&self) -> u64 {
        2 * self.tuning.descent_budget as u64 + 1
    }

    /// The dispatches (rounds) of `count` or `descend` that finish descents of `steps` steps
    /// in all, the longest `most`, in the pass's slots of `round` steps a round: while the
    /// queue is not empty every slot runs its round's steps in full, and once it is, each
    /// slot's last descent needs at most `most` more. One on hardware (no pause).
    pub(super) fn rounds_for(&self, steps: u64, most: u64, round: u32) -> u32 {
        if round == u32::MAX {
            return 1;
        }
        let per_round = self.slots.max(1) as u64 * round as u64;
        (steps / per_round + 1 + most.div_ceil(round as u64)).min(u32::MAX as u64) as u32
    }

    /// The steps a slot of `descend` runs in a round: half the count's on a software adapter
    /// (a step of `descend` also writes the faces' owners and the leaves), none paused on
    /// hardware.
    pub(super) fn descend_steps(&self) -> u32 {
        if self.tuning.round_steps == u32::MAX {
            u32::MAX
        } else {
            (self.tuning.round_steps / 2).max(1)
        }
    }

    /// The descent budget ([`Self::set_descent_budget`]).
    pub fn descent_budget(&self) -> u32 {
        self.tuning.descent_budget
    }

    /// With `true`, every pass waits until its second submission has run, so that
    /// [`Self::last_pass_ms`] can time it (a renderer would rather let it overlap).
    pub fn set_profiling(&mut self, on: bool) {
        self.tuning.profile = on;
    }

    /// Bounds the descents' stacks (all levels) by `bytes` ([`MAX_STACK_BYTES`](super::MAX_STACK_BYTES) by default;
    /// with a budget also by a 64th of it), at least one descent's; the adapter goes
    /// back to the base mesh.
    pub fn set_stack_limit(&mut self, bytes: u64) {
        self.tuning.stack_limit = bytes;
        self.stack = storage(self.gpu.device(), "pm: descent stacks", 0, 4, VERTEX_USAGE);
        self.reset();
    }

    /// Bounds the count's scratch area (all levels) by `bytes` ([`MAX_SCRATCH_BYTES`](super::MAX_SCRATCH_BYTES) by
    /// default; with a budget also by a 64th of it): a pass whose count keeps more than it
    /// holds walks its descents again (0: every pass does).
    pub fn set_scratch_limit(&mut self, bytes: u64) {
        self.tuning.scratch_limit = bytes;
        (self.scratch, self.sc_faces) = scratch_buffers(self.gpu.device(), 0);
        self.sc_cap = [0; 3];
    }
}
