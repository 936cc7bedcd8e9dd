//! The graphics memory an adapter takes (its `MemoryBudget`): the budget, the error scale that
//! keeps the mesh within it, and the byte arithmetic of its buffers ("Memory budget" in
//! docs/design.md).

use codec::pm::Levels;

use super::adapter::GpuAdapter;
use super::buffers::{VertexSet, POINT_BYTES, STATE_BYTES};
use super::error::AdaptError;

impl GpuAdapter {
    /// Bytes of GPU memory the dynamic (per adapted mesh) buffers take now, at their capacities.
    pub fn dynamic_bytes(&self) -> u64 {
        let sets: u64 = self.sets.iter().map(VertexSet::bytes).sum();
        let faces = self.faces.idx.buffer.size() + self.faces.fvid.buffer.size() + self.faces.owner.buffer.size();
        let tmp = self.vcnt.buffer.size() + self.fcnt.buffer.size() + self.list.buffer.size() + self.hole.buffer.size();
        let marks: u64 = self.marks.iter().map(|b| b.buffer.size()).sum();
        let levels: u64 = self.scan_levels.iter().map(|l| l.sums.buffer.size() + l.uniform.size()).sum();
        sets + faces + tmp + marks + levels
    }

    /// Bytes of GPU memory the adapter takes besides the adapted mesh: the static buffers,
    /// the occlusion pyramid, the per-pass records and the descents' stacks.
    pub(super) fn fixed_bytes(&self) -> u64 {
        self.fixed_bytes_within(self.memory.bytes)
    }

    /// [`Self::fixed_bytes`] under `budget`: with a budget, an all-levels adapter counts its
    /// descent stacks at the most they may grow to.
    pub(super) fn fixed_bytes_within(&self, budget: Option<u64>) -> u64 {
        let records =
            self.params.size() + self.stats.size() + self.errors.size() + self.readback.size() + self.queue.size();
        let reserve = match (budget, self.tuning.levels) {
            (Some(_), Levels::All) => self.stack_max_bytes(budget),
            _ => 0,
        };
        let scratch = self.scratch.buffer.size() + self.sc_faces.buffer.size();
        let scratch_reserve = match (budget, self.tuning.levels) {
            (Some(_), Levels::All) => self.scratch_max_bytes(budget),
            _ => 0,
        };
        self.static_bytes()
            + self.occ.buffer.size()
            + records
            + self.stack.buffer.size().max(reserve)
            + scratch.max(scratch_reserve)
    }

    /// The most bytes the count's scratch area may take under `budget`: the scratch limit
    /// ([`Self::set_scratch_limit`]), at most a 64th of the budget.
    pub(super) fn scratch_max_bytes(&self, budget: Option<u64>) -> u64 {
        budget.map_or(self.tuning.scratch_limit, |b| (b / 64).min(self.tuning.scratch_limit))
    }

    /// Bytes of GPU memory the adapter takes now: [`Self::static_bytes`], the adapted mesh's
    /// buffers at their capacities ([`Self::dynamic_bytes`]), the occlusion pyramid, the
    /// per-pass records and the descents' stacks. With a budget ([`Self::set_budget`]) it
    /// stays within it.
    pub fn gpu_bytes(&self) -> u64 {
        self.fixed_bytes() + self.dynamic_bytes()
    }

    /// At most how many bytes the adapted mesh's buffers take with `v` active vertices (in
    /// either of the two sets) and `f` faces, by the `n_alloc` policy (a buffer holds at most
    /// its need and `2 n_alloc` elements more): per vertex its FVID, state and point in both
    /// sets, the three per-pass counts and the four all-levels marks, per face its indices,
    /// FVIDs, owner and a hole slot, per scan block 8 bytes, and a few levels' records.
    pub(super) fn mesh_bytes(&self, v: u64, f: u64) -> u64 {
        const VERTEX: u64 = 2 * (4 + STATE_BYTES + POINT_BYTES) + 7 * 4 + 1;
        const FACE: u64 = 12 + 12 + 4 + 4;
        let slack = 2 * self.n_alloc as u64;
        (v + 1 + slack) * VERTEX + (f + slack) * FACE + 4096
    }

    /// Whether a mesh of `v` vertices and `f` faces (with the `n_alloc` slack) would take the
    /// adapter past its budget or one of its buffers past the device's binding limit.
    pub(super) fn exceeds(&self, v: u64, f: u64) -> bool {
        let na = self.n_alloc as u64;
        let limit = self.gpu.device().limits().max_storage_buffer_binding_size;
        let bound = (v + na) * STATE_BYTES > limit || (f + na) * 12 > limit;
        bound || self.memory.bytes.is_some_and(|b| self.fixed_bytes() + self.mesh_bytes(v, f) > b)
    }

    /// Whether the mesh takes at most half the room the budget leaves it and half the
    /// binding limit (so that one [`SCALE_STEP`] finer may fit: if it does not, the pass
    /// that overflows raises the error back and stops it there for the view).
    pub(super) fn fits_finer(&self) -> bool {
        let (v, f) = (self.n as u64, self.m as u64);
        let room = self.memory.bytes.map_or(u64::MAX, |b| b.saturating_sub(self.fixed_bytes()));
        let limit = self.gpu.device().limits().max_storage_buffer_binding_size;
        self.mesh_bytes(v, f).saturating_mul(2) <= room && (v * STATE_BYTES).saturating_mul(2) <= limit
    }

    /// Bounds the adapter's graphics memory ([`Self::gpu_bytes`]) by `bytes` (`None`: only
    /// by the device's binding limit), and goes back to the base mesh. A pass whose splits
    /// would take the mesh past it splits nothing and raises the error the passes after it
    /// adapt to ([`Self::error_scale`]); once converged with room to spare, the error comes
    /// back down. The `n_alloc` slack shrinks to at most an eighth of the room the budget
    /// leaves the mesh. Fails if the budget does not hold the static buffers and the base
    /// mesh.
    pub fn set_budget(&mut self, bytes: Option<u64>) -> Result<(), AdaptError> {
        if let Some(b) = bytes {
            let per_element = self.mesh_bytes(1, 1) - self.mesh_bytes(0, 0);
            let room = b.saturating_sub(self.fixed_bytes_within(bytes));
            self.n_alloc = self.n_alloc.min((room / 16 / per_element).max(1) as u32);
            let base = &self.shared.base;
            let need =
                self.fixed_bytes_within(bytes) + self.mesh_bytes(base.fvid.len() as u64, base.face_idx.len() as u64);
            if need > b {
                return Err(AdaptError::MeshBudget { budget: b, need });
            }
        }
        self.memory.bytes = bytes;
        (self.memory.error_scale, self.memory.floor, self.memory.last_view) = (1.0, 1.0, None);
        self.reset();
        Ok(())
    }

    /// The factor on the view's pixel error the mesh is adapted to now: 1 unless the budget
    /// ([`Self::set_budget`]) or the binding limit held splits back.
    pub fn error_scale(&self) -> f32 {
        self.memory.error_scale
    }

    /// Bytes of the static (per progressive mesh) buffers: the compressed operations, the
    /// decoding tables and parameters.
    pub fn static_bytes(&self) -> u64 {
        self.shared.ops.size() + self.shared.tables.size() + self.shared.decode.size()
    }
}
