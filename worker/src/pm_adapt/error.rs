//! [`AdaptError`]: why an adaptation could not start or a pass failed.

use thiserror::Error;

use crate::gpu::GpuError;

/// Why an adaptation could not start or a pass failed.
#[derive(Debug, Error)]
pub enum AdaptError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("GPU error: the PM stages need {need} storage buffers per shader stage; the adapter allows {allowed}")]
    TooFewStorageBuffers { need: u32, allowed: u32 },
    /// The totals read back after the classification do not add up (a GPU fault).
    #[error("GPU error: inconsistent pass totals: {vertices} vertices, {after} after, {collapses} collapses")]
    InconsistentTotals { vertices: u32, after: u32, collapses: u32 },
    /// A face read back refers to a vertex that is not active (a GPU fault).
    #[error("GPU error: face index {index} out of {vertices} vertices")]
    FaceIndex { index: u32, vertices: usize },
    /// An operation of the `.dpm` did not decode on the GPU: where (the operation's byte, and
    /// out of core its node) and why.
    #[error("corrupt .dpm data: {at}: {failure}")]
    Corrupt { at: String, failure: String },
    /// A descent stopped by the GPU's loop limit (llvmpipe: 65535 iterations an invocation),
    /// found because its loop ended without finishing: the pass would be wrong.
    #[error("the GPU ended a descent early ({at}; its loop limit): lower the descent budget")]
    LoopLimit { at: String },
    /// A base vertex's operation did not decode on the CPU, or a node could not be read.
    #[error(transparent)]
    Format(#[from] codec::pm::DpmError),
    /// An out-of-core file given to [`GpuAdapter::new`](super::GpuAdapter::new), or an in-core one to
    /// [`GpuAdapter::out_of_core`](super::GpuAdapter::out_of_core).
    #[error("{0}")]
    WrongLayout(&'static str),
    /// The adapted mesh outgrew what the device binds in one buffer.
    #[error(
        "the adapted mesh needs {elements} {what}, {bytes} bytes in one buffer, and this GPU binds at most \
         {limit}: raise --error-px"
    )]
    TooLarge { elements: u64, what: &'static str, bytes: u64, limit: u64 },
    /// The node pool's budget does not hold the largest node.
    #[error(
        "a node pool of {budget} bytes holds no node: the largest takes {slot_bytes} (raise --gpu-budget-mb or \
         --gpu-nodes-mb)"
    )]
    Budget { budget: u64, slot_bytes: u32 },
    /// The GPU budget does not hold the static buffers and the base mesh.
    #[error(
        "a GPU budget of {budget} bytes does not hold the model's tables, nodes and base mesh ({need} bytes): raise \
         --gpu-budget-mb"
    )]
    MeshBudget { budget: u64, need: u64 },
    /// A node pool given as large as the whole budget or larger.
    #[error("a node pool of {pool} bytes (--gpu-nodes-mb) leaves nothing of a GPU budget of {budget} for the mesh")]
    PoolOverBudget { pool: u64, budget: u64 },
    /// The node pool was asked to hold more nodes than it has slots (a bug of the cache).
    #[error("GPU error: the node pool's {slots} slots are all taken")]
    PoolFull { slots: u32 },
    /// A node larger than a slot (a node table that lies).
    #[error("corrupt .dpm data: node {node}: {bytes} bytes, more than the {slot_bytes} of a slot")]
    NodeSize { node: u32, bytes: usize, slot_bytes: u32 },
}
