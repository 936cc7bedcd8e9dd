//! The out-of-core hierarchy's nodes as a file stores them (section 4.1 and 5.7): the node
//! table (`NODE`) and what a reader keeps of every node in main memory
//! (`node_file.rs` reads an out-of-core file's nodes one at a time).
//!
//! The `NODE` section holds per node, in the hierarchy's pre-order (a parent before its
//! children): its length less one (LEB128; 1 to [`NODE_BYTES`] bytes, the nodes stored one after
//! the other in the operations section, in this order), its distance to its parent (LEB128; 0
//! for the root, node 0 only), the box around the bounding spheres of its operations (6 `f32`,
//! minimum then maximum), the greatest geometric and attribute errors of its operations (2
//! `f32`, as they decode), and the CRC-32 of its bytes (`u32`): 38 to 42 bytes a node; the
//! paper keeps 35 in main memory.

use glam::Vec3;

use super::header::{corrupt, get_varint, Header, NODE_BYTES};
use super::DpmError;
use crate::container::put_varint;
use crate::pm::Viewpoint;

/// What a reader keeps of a node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NodeInfo {
    /// Where its bytes start in the operations section.
    pub offset: u64,
    /// Its bytes (1 to [`NODE_BYTES`]).
    pub len: u32,
    pub parent: Option<u32>,
    /// The box around the bounding spheres of its operations.
    pub bbox_min: [f32; 3],
    pub bbox_max: [f32; 3],
    /// The greatest geometric and attribute errors of its operations.
    pub geometric_error: f32,
    pub attribute_error: f32,
    pub crc: u32,
}

impl NodeInfo {
    /// Checks node `i`'s bytes against its length and checksum.
    pub fn check(&self, i: u32, bytes: &[u8]) -> Result<(), DpmError> {
        if bytes.len() != self.len as usize {
            return Err(corrupt(format!("node {i}: {} bytes, the node table says {}", bytes.len(), self.len)));
        }
        if crc32fast::hash(bytes) != self.crc {
            return Err(corrupt(format!("node {i}: checksum mismatch")));
        }
        Ok(())
    }

    /// The paper's priority `p = d_n / d_v` (section 5.7) of the node for `view`: `d_n` the
    /// distance beyond which none of its operations needs a split (from its greatest error
    /// and the view's threshold), `d_v` the distance from the eye to its box, with the `c_LOD`
    /// falloff outside the frustum as the refinement test has it. No operation of a node with
    /// `p < 1` passes that test: every operation's sphere lies in the box, so its distance
    /// and its distance outside the frustum are at least the box's. Infinite where the eye is
    /// in the box.
    pub fn priority(&self, view: &Viewpoint, planes: &[glam::Vec4; 6]) -> f32 {
        let err = self.geometric_error.max(view.attribute_scale * self.attribute_error);
        if err.is_nan() || err <= 0.0 {
            return 0.0;
        }
        let (lo, hi) = (Vec3::from(self.bbox_min), Vec3::from(self.bbox_max));
        let dist = (view.eye.clamp(lo, hi) - view.eye).length();
        let mut outside = 0.0f32;
        for p in planes {
            let n = p.truncate();
            // The box's point farthest along the plane's normal.
            let far = Vec3::select(n.cmpge(Vec3::ZERO), hi, lo);
            outside = outside.max(-(n.dot(far) + p.w));
        }
        let d_v = dist + view.c_lod * outside;
        let d_n = err * view.pixels_per_unit / view.error_px;
        if d_v <= 0.0 {
            f32::INFINITY
        } else {
            d_n / d_v
        }
    }
}

/// The `NODE` section of `nodes`.
pub(super) fn write_node_table(nodes: &[NodeInfo]) -> Vec<u8> {
    let mut b = Vec::with_capacity(nodes.len() * 40);
    for (i, n) in nodes.iter().enumerate() {
        put_varint(&mut b, n.len as u64 - 1);
        put_varint(&mut b, n.parent.map_or(0, |p| i as u64 - p as u64));
        for x in n.bbox_min.iter().chain(&n.bbox_max).chain(&[n.geometric_error, n.attribute_error]) {
            b.extend_from_slice(&x.to_le_bytes());
        }
        b.extend_from_slice(&n.crc.to_le_bytes());
    }
    b
}

/// Reads the `NODE` section: `h.nodes` nodes whose lengths add up to `ops_len`, node 0 the
/// only root, parents before children, boxes and errors finite.
pub(super) fn read_node_table(b: &[u8], h: &Header, ops_len: u64) -> Result<Vec<NodeInfo>, DpmError> {
    let count = h.nodes as usize;
    if count > b.len() / 38 {
        return Err(corrupt("node table shorter than the header's node count"));
    }
    let mut nodes = Vec::with_capacity(count);
    let (mut pos, mut offset) = (0usize, 0u64);
    for i in 0..count {
        let len = get_varint(b, &mut pos, "node table")? + 1;
        let up = get_varint(b, &mut pos, "node table")?;
        if len > NODE_BYTES as u64 || (up == 0) != (i == 0) || up > i as u64 {
            return Err(corrupt(format!("node {i}: bad length or parent in the node table")));
        }
        let Some(fixed) = b.get(pos..pos + 36) else {
            return Err(DpmError::Truncated("node table"));
        };
        pos += 36;
        let f = |k: usize| f32::from_le_bytes(fixed[4 * k..4 * k + 4].try_into().unwrap());
        let n = NodeInfo {
            offset,
            len: len as u32,
            parent: (up > 0).then(|| (i as u64 - up) as u32),
            bbox_min: [f(0), f(1), f(2)],
            bbox_max: [f(3), f(4), f(5)],
            geometric_error: f(6),
            attribute_error: f(7),
            crc: u32::from_le_bytes(fixed[32..36].try_into().unwrap()),
        };
        let box_ok =
            (0..3).all(|k| n.bbox_min[k].is_finite() && n.bbox_max[k].is_finite() && n.bbox_min[k] <= n.bbox_max[k]);
        let err_ok = [n.geometric_error, n.attribute_error].iter().all(|e| e.is_finite() && *e >= 0.0);
        if !box_ok || !err_ok {
            return Err(corrupt(format!("node {i}: bad box or errors in the node table")));
        }
        offset += len;
        nodes.push(n);
    }
    if pos != b.len() {
        return Err(corrupt("bytes after the node table"));
    }
    if count > 0 && offset != ops_len {
        return Err(corrupt("the node lengths do not add up to the operations section"));
    }
    Ok(nodes)
}
