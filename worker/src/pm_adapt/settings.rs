//! An adapter's settings, as plain state: its memory budget ([`MemoryBudget`]) and how it
//! runs its passes ([`Tuning`]). The arithmetic and setters over them are `GpuAdapter`'s
//! (`budget.rs`, `tuning.rs`).

use codec::pm::{Levels, Viewpoint, DESCENT_BUDGET};

use super::limits::{MAX_SCRATCH_BYTES, MAX_STACK_BYTES, SOFTWARE_ROUND_STEPS};

/// The budget and what keeps a view's mesh within it.
pub(super) struct MemoryBudget {
    /// Bytes of graphics memory the adapter may take in all ([`GpuAdapter::set_budget`](super::GpuAdapter::set_budget)).
    pub(super) bytes: Option<u64>,
    /// The factor on the view's pixel error that keeps the mesh within the budget (1 when
    /// it fits), the lowest it may go back to for the current view (the scale that last
    /// overflowed, 1 after a new view), and that view.
    pub(super) error_scale: f32,
    pub(super) floor: f32,
    pub(super) last_view: Option<Viewpoint>,
}

impl Default for MemoryBudget {
    fn default() -> Self {
        MemoryBudget { bytes: None, error_scale: 1.0, floor: 1.0, last_view: None }
    }
}

/// How an adapter runs its passes; the defaults suit the device.
pub(super) struct Tuning {
    /// How far a pass for a view moves a vertex in the split tree ([`GpuAdapter::set_levels`](super::GpuAdapter::set_levels)).
    pub(super) levels: Levels,
    /// Whether the kind of pass is the default's ([`GpuAdapter::set_levels`](super::GpuAdapter::set_levels) not called): all
    /// levels, and one level for the rest of a view once an all-levels pass descended deep.
    pub(super) mixed: bool,
    /// An all-levels pass's descent budget ([`GpuAdapter::set_descent_budget`](super::GpuAdapter::set_descent_budget)).
    pub(super) descent_budget: u32,
    /// The most steps of a descent slot in one dispatch ([`GpuAdapter::set_round_steps`](super::GpuAdapter::set_round_steps)).
    pub(super) round_steps: u32,
    /// The most bytes the scratch area and the stacks may take without a budget
    /// ([`GpuAdapter::set_scratch_limit`](super::GpuAdapter::set_scratch_limit), [`GpuAdapter::set_stack_limit`](super::GpuAdapter::set_stack_limit)).
    pub(super) scratch_limit: u64,
    pub(super) stack_limit: u64,
    /// Wait for each pass's second submission and time it ([`GpuAdapter::set_profiling`](super::GpuAdapter::set_profiling)).
    pub(super) profile: bool,
}

impl Tuning {
    /// The defaults, with rounds bounded on a software adapter ([`SOFTWARE_ROUND_STEPS`]).
    pub(super) fn for_adapter(software: bool) -> Tuning {
        Tuning {
            levels: Levels::All,
            mixed: true,
            descent_budget: DESCENT_BUDGET,
            round_steps: if software { SOFTWARE_ROUND_STEPS } else { u32::MAX },
            scratch_limit: MAX_SCRATCH_BYTES,
            stack_limit: MAX_STACK_BYTES,
            profile: false,
        }
    }
}
