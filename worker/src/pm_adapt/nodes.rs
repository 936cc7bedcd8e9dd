//! The resident nodes of an out-of-core `.dpm` in graphics memory (section 5.7 of the paper):
//! a pool of equal slots, each holding one node's compressed operations as they are in the
//! file, and the page table the decoder looks a node up in (`decode.wgsl`: an address is
//! `node * 2^16 + local`, read at `slot * slot_bytes + local`). What is resident is decided on
//! the host ([`codec::pm::NodeCache`], by the paper's priority within the budget); the pool
//! follows it between passes, so a pass sees one page table from start to end.

use std::collections::{HashMap, HashSet};

use codec::pm::NONE;

use super::buffers::VERTEX_USAGE;
use super::error::AdaptError;

pub(crate) struct NodePool {
    /// The slots, `slots * slot_bytes` bytes: the decoder's `ops`.
    pub(crate) ops: wgpu::Buffer,
    slot_bytes: u32,
    slot_of: HashMap<u32, u32>,
    free: Vec<u32>,
    /// Per node its slot, `NONE` where not resident: the words at `page_at` of the tables.
    page: Vec<u32>,
    /// Byte offset of the page table in the decoder's `tables` buffer.
    page_at: u64,
}

impl NodePool {
    /// A pool of `slots` slots of `slot_bytes` for `nodes` nodes, none resident; the page
    /// table is at word `page_at` of the decoder's tables (written there by [`Self::sync`]).
    pub(crate) fn new(device: &wgpu::Device, nodes: usize, slots: u32, slot_bytes: u32, page_at: u32) -> NodePool {
        let ops = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("pm: node pool"),
            size: (slots as u64 * slot_bytes as u64).max(16),
            usage: VERTEX_USAGE,
            mapped_at_creation: false,
        });
        NodePool {
            ops,
            slot_bytes,
            slot_of: HashMap::new(),
            free: (0..slots).rev().collect(),
            page: vec![NONE; nodes],
            page_at: page_at as u64 * 4,
        }
    }

    /// Nodes the pool can hold.
    pub(crate) fn slots(&self) -> u32 {
        (self.slot_of.len() + self.free.len()) as u32
    }

    /// Makes the pool hold exactly the nodes `resident` lists with their bytes: the others'
    /// slots are freed first, then the new ones uploaded into free slots, then the page table
    /// written if it changed. Returns the bytes uploaded.
    pub(crate) fn sync<'a>(
        &mut self,
        queue: &wgpu::Queue,
        tables: &wgpu::Buffer,
        resident: impl IntoIterator<Item = (u32, &'a [u8])>,
    ) -> Result<u64, AdaptError> {
        let resident: Vec<(u32, &[u8])> = resident.into_iter().collect();
        let keep: HashSet<u32> = resident.iter().map(|&(i, _)| i).collect();
        let mut changed = false;
        let gone: Vec<u32> = self.slot_of.keys().copied().filter(|i| !keep.contains(i)).collect();
        for i in gone {
            let slot = self.slot_of.remove(&i).expect("listed above");
            self.free.push(slot);
            self.page[i as usize] = NONE;
            changed = true;
        }
        let mut uploaded = 0;
        for (i, bytes) in resident {
            if self.slot_of.contains_key(&i) {
                continue;
            }
            let Some(slot) = self.free.pop() else {
                return Err(AdaptError::PoolFull { slots: self.slots() });
            };
            if bytes.len() > self.slot_bytes as usize || i as usize >= self.page.len() {
                return Err(AdaptError::NodeSize { node: i, bytes: bytes.len(), slot_bytes: self.slot_bytes });
            }
            // Copies are in whole words; the tail of the last word is never read (the decoder
            // reads below the node's length).
            let mut padded;
            let data = if bytes.len().is_multiple_of(4) {
                bytes
            } else {
                padded = bytes.to_vec();
                padded.resize(bytes.len().next_multiple_of(4), 0);
                &padded[..]
            };
            if !data.is_empty() {
                queue.write_buffer(&self.ops, slot as u64 * self.slot_bytes as u64, data);
            }
            uploaded += bytes.len() as u64;
            self.slot_of.insert(i, slot);
            self.page[i as usize] = slot;
            changed = true;
        }
        if changed && !self.page.is_empty() {
            queue.write_buffer(tables, self.page_at, bytemuck::cast_slice(&self.page));
        }
        Ok(uploaded)
    }
}
