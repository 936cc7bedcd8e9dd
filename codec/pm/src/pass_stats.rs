//! [`PassStats`]: what one adaptation pass did, on the CPU or the GPU.

/// What one pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PassStats {
    pub splits: usize,
    pub collapses: usize,
    /// Collapses cancelled because their target split (Algorithm 2).
    pub cancelled: usize,
    /// Active vertices and faces after the pass.
    pub vertices: usize,
    pub faces: usize,
    /// The pass kept its splits back, or changed the error it adapts to, to stay within a
    /// memory budget (the GPU adapter's `set_budget`; never the CPU's): not converged.
    pub held: bool,
}

impl PassStats {
    /// No split, no collapse and nothing held back: the state is converged for this view.
    pub fn converged(&self) -> bool {
        self.splits == 0 && self.collapses == 0 && !self.held
    }
}
