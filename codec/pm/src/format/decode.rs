//! The `.dpm` decoder. [`Dpm::parse`] checks the container and reads the header, the tables
//! and the base mesh; [`Dpm::decode_op`] decodes any single operation from its address and
//! context, which is all the runtime does; [`decode`] walks the split forest from the base
//! vertices in the file's pre-order and decodes every operation, checking the counts against
//! the header. Every way the bytes can be wrong is a [`DpmError`], never a panic
//! (`fuzz/fuzz_targets/decode_dpm.rs` fuzzes this, behind the checksums too).

use std::sync::Arc;

use super::fields::KINDS;
use super::header::max_q;
use super::header::{
    corrupt, get_varint, Header, FLOAT_VERSION, LAYOUT, NODELESS_VERSION, NODE_BYTES, PAIRLESS_VERSION,
};
use super::nodes::{read_node_table, NodeInfo};
use super::op::{read_op, DecodedOp, OpContext};
use super::quantize::{dequantize_position, oct_decode, valid_oct};
use super::tables::read_tables;
use super::DpmError;
use crate::huffman::Table;
use crate::progressive::ProgressiveMesh;

/// A LEB128 number of the base mesh section that must fit in 32 bits.
fn get_u32(b: &[u8], pos: &mut usize, what: &'static str) -> Result<u32, DpmError> {
    u32::try_from(get_varint(b, pos, what)?).map_err(|_| corrupt(format!("number out of range in {what}")))
}

/// The parsed container: header, tables, the base mesh, the node table and the operation
/// bytes (out of core: none, see [`Dpm::parse_prefix`]).
#[derive(Clone, Debug)]
pub struct Dpm<'a> {
    pub header: Header,
    tables: Vec<Arc<Table>>,
    /// Base vertex FVIDs, ascending.
    pub base_vertices: Vec<u32>,
    pub base_positions: Vec<[u32; 3]>,
    pub base_normals: Vec<[u32; 2]>,
    /// Per base vertex: the address of its first operation.
    pub roots: Vec<Option<usize>>,
    pub base_faces: Vec<[u32; 3]>,
    /// The out-of-core hierarchy's nodes (none in core), parents before children.
    pub nodes: Vec<NodeInfo>,
    /// The operations section (empty where parsed with [`Dpm::parse_prefix`]).
    pub ops: &'a [u8],
    /// The sizes of the sections TABL, BASE, NODE, OPER.
    pub(super) section_lens: [usize; 4],
}

impl<'a> Dpm<'a> {
    /// Checks the container and reads the tables, the base mesh and the node table (not the
    /// operations).
    pub fn parse(bytes: &'a [u8]) -> Result<Self, DpmError> {
        let c = LAYOUT.parse(bytes).map_err(outdated)?;
        let ops = c.sections[3];
        if ops.len() >= 1 << 31 && c.sections[2].is_empty() {
            return Err(corrupt("operations section of 2 GiB or more"));
        }
        Self::from_parts(c.header, [c.sections[0], c.sections[1], c.sections[2]], ops, ops.len() as u64)
    }

    /// Parses an out-of-core file's bytes up to its operations (as [`NodeFile`] reads them):
    /// the tables, the base mesh and the node table, checked; its nodes are read one by one and
    /// checked by their own checksums ([`NodeInfo::check`]).
    ///
    /// [`NodeFile`]: super::NodeFile
    pub fn parse_prefix(prefix: &'a [u8]) -> Result<Self, DpmError> {
        let c = LAYOUT.parse_prefix(prefix).map_err(outdated)?;
        if c.sections[2].is_empty() {
            return Err(corrupt("an in-core file (no node table) read out of core"));
        }
        Self::from_parts(c.header, [c.sections[0], c.sections[1], c.sections[2]], &[], c.last_len)
    }

    fn from_parts(hb: &[u8], sections: [&[u8]; 3], ops: &'a [u8], ops_len: u64) -> Result<Self, DpmError> {
        let header = Header::from_bytes(hb)?;
        let tables = read_tables(sections[0])?;
        let nodes = read_node_table(sections[2], &header, ops_len)?;
        // Base mesh.
        let bb = sections[1];
        let nb = header.base_vertices as usize;
        if nb > bb.len() / 7 || header.base_faces as usize > bb.len() / 3 || header.splits as u64 > ops_len {
            return Err(corrupt("counts larger than the data"));
        }
        let mut pos = 0;
        let (mut base_vertices, mut base_positions, mut base_normals, mut roots) =
            (Vec::with_capacity(nb), Vec::with_capacity(nb), Vec::with_capacity(nb), Vec::with_capacity(nb));
        let mut next = 0u64;
        for _ in 0..nb {
            let f = next + get_varint(bb, &mut pos, "base vertices")?;
            if f >= header.vertices as u64 {
                return Err(corrupt("base vertex FVID out of range"));
            }
            base_vertices.push(f as u32);
            next = f + 1;
            let mut p = [0u32; 3];
            for x in &mut p {
                *x = get_u32(bb, &mut pos, "base vertices")?;
                if *x > max_q(header.position_bits) {
                    return Err(corrupt("base position out of range"));
                }
            }
            let mut q = [0u32; 2];
            for x in &mut q {
                *x = get_u32(bb, &mut pos, "base vertices")?;
            }
            if !valid_oct(q, header.normal_bits) {
                return Err(corrupt("base normal out of range"));
            }
            base_positions.push(p);
            base_normals.push(q);
            let root = get_varint(bb, &mut pos, "base vertices")?;
            let in_range = |a: u64| {
                if nodes.is_empty() {
                    a < ops_len
                } else {
                    let node = nodes.get((a / NODE_BYTES as u64) as usize);
                    node.is_some_and(|n| (a % NODE_BYTES as u64) < n.len as u64)
                }
            };
            roots.push(match root {
                0 => None,
                a if in_range(a - 1) => Some(a as usize - 1),
                _ => return Err(corrupt("root operation address out of range")),
            });
        }
        if nb > 0 && base_vertices[0] != 0 || (nb == 0 && header.vertices != 0) {
            return Err(corrupt("the first base vertex must have FVID 0"));
        }
        let mut base_faces = Vec::with_capacity(header.base_faces as usize);
        for _ in 0..header.base_faces {
            let mut t = [0u32; 3];
            for x in &mut t {
                *x = get_u32(bb, &mut pos, "base faces")?;
                if *x >= header.vertices {
                    return Err(corrupt("base face FVID out of range"));
                }
            }
            base_faces.push(t);
        }
        if pos != bb.len() {
            return Err(corrupt("bytes after the base mesh"));
        }
        Ok(Dpm {
            header,
            tables,
            base_vertices,
            base_positions,
            base_normals,
            roots,
            base_faces,
            nodes,
            ops,
            section_lens: [sections[0].len(), sections[1].len(), sections[2].len(), ops_len as usize],
        })
    }

    /// Whether the file has an out-of-core hierarchy (its addresses name nodes).
    pub fn out_of_core(&self) -> bool {
        !self.nodes.is_empty()
    }

    /// The node of address `addr` of an out-of-core file.
    pub fn node_of(addr: usize) -> u32 {
        (addr / NODE_BYTES) as u32
    }

    /// The bytes of node `i` within the operations section this was parsed with.
    pub fn node_bytes(&self, i: u32) -> &'a [u8] {
        let n = &self.nodes[i as usize];
        self.ops.get(n.offset as usize..n.offset as usize + n.len as usize).unwrap_or(&[])
    }

    /// The probability tables, one per context ([`super::TABLES`] of them, in the order the format's
    /// fields list them).
    pub fn tables(&self) -> &[Arc<Table>] {
        &self.tables
    }

    /// The position of quantized position `q` (as [`decode`] gives it).
    pub fn position(&self, q: [u32; 3]) -> [f32; 3] {
        dequantize_position(q, &self.header)
    }

    /// The unit normal (or zero) of octahedral code `q` (as [`decode`] gives it).
    pub fn normal(&self, q: [u32; 2]) -> [f32; 3] {
        oct_decode(q, self.header.normal_bits)
    }

    /// Decodes the single operation at `addr` (a byte of the operations section in core, a node
    /// and a local address out of core); an error names the operation by its address (and
    /// node).
    pub fn decode_op(&self, addr: usize, ctx: &OpContext) -> Result<DecodedOp, DpmError> {
        self.read(addr, ctx, None)
    }

    /// Decodes the operation at `addr` of an out-of-core file from `node`, the bytes of its
    /// node (read and checked by the caller, [`NodeInfo::check`]).
    pub fn decode_in(&self, node: &[u8], addr: usize, ctx: &OpContext) -> Result<DecodedOp, DpmError> {
        self.read_in(node, addr, ctx, None)
    }

    pub(super) fn read_in(
        &self,
        node: &[u8],
        addr: usize,
        ctx: &OpContext,
        bits: Option<&mut [u64; KINDS]>,
    ) -> Result<DecodedOp, DpmError> {
        read_op(&self.header, &self.tables, node, addr % NODE_BYTES, Some(Self::node_of(addr)), ctx, bits)
            .map_err(|e| naming(addr, true, e))
    }

    fn read(&self, addr: usize, ctx: &OpContext, bits: Option<&mut [u64; KINDS]>) -> Result<DecodedOp, DpmError> {
        if self.nodes.is_empty() {
            return read_op(&self.header, &self.tables, self.ops, addr, None, ctx, bits)
                .map_err(|e| naming(addr, false, e));
        }
        let n = Self::node_of(addr);
        if n as usize >= self.nodes.len() {
            return Err(naming(addr, true, corrupt("operation address past the last node")));
        }
        self.read_in(self.node_bytes(n), addr, ctx, bits)
    }

    /// Decodes every operation (pre-order over the forest), optionally counting bits per field.
    pub(super) fn decode_all(&self, mut bits: Option<&mut [u64; KINDS]>) -> Result<Decoded, DpmError> {
        let h = &self.header;
        check_counts(h)?;
        let n = h.vertices as usize;
        let mut positions = vec![[0f32; 3]; n];
        let mut normals = vec![[0f32; 3]; n];
        for (b, &v) in self.base_vertices.iter().enumerate() {
            positions[v as usize] = dequantize_position(self.base_positions[b], h);
            normals[v as usize] = oct_decode(self.base_normals[b], h.normal_bits);
        }
        let mut splits = Vec::with_capacity(h.splits as usize);
        let mut criteria = Vec::with_capacity(h.splits as usize);
        let mut addresses = Vec::with_capacity(h.splits as usize);
        let mut contexts = Vec::with_capacity(h.splits as usize);
        self.walk(&mut |addr, ctx| self.read(addr, ctx, bits.as_deref_mut()), &mut |addr, ctx, op| {
            let v_u = op.split.v_u as usize;
            positions[v_u] = dequantize_position(op.position_u, h);
            normals[v_u] = oct_decode(op.normal_u, h.normal_bits);
            addresses.push(addr);
            contexts.push(*ctx);
            criteria.push(op.criteria);
            splits.push(op.split);
        })?;
        Ok(Decoded {
            pm: ProgressiveMesh {
                base_vertices: self.base_vertices.clone(),
                base_faces: self.base_faces.clone(),
                splits,
                positions,
                fvid_of_input: (0..h.vertices).collect(),
                normals,
                criteria,
            },
            header: *h,
            addresses,
            contexts,
        })
    }

    /// Walks every operation in pre-order over the forest, reading each with `read` (its
    /// address and context) and handing it to `visit`, and checks the split tree against the
    /// FVID ranges and the header's operation and triangle counts. Keeps a stack of the
    /// operations still to read, nothing per operation.
    pub(super) fn walk(
        &self,
        read: &mut dyn FnMut(usize, &OpContext) -> Result<DecodedOp, DpmError>,
        visit: &mut dyn FnMut(usize, &OpContext, DecodedOp),
    ) -> Result<(), DpmError> {
        let h = &self.header;
        let (mut ops, mut triangles) = (0u64, self.base_faces.len() as u64);
        let mut stack: Vec<(usize, OpContext)> = vec![];
        for b in 0..self.base_vertices.len() {
            let v = self.base_vertices[b];
            let v_end = self.base_vertices.get(b + 1).copied().unwrap_or(h.vertices);
            let Some(root) = self.roots[b] else {
                if v_end - v != 1 {
                    return Err(corrupt("split tree inconsistent with the FVID ranges"));
                }
                continue;
            };
            stack.push((
                root,
                OpContext {
                    v,
                    v_end,
                    parent_criteria: [0; 4],
                    position: self.base_positions[b],
                    normal: self.base_normals[b],
                },
            ));
            while let Some((addr, ctx)) = stack.pop() {
                if ops >= h.splits as u64 {
                    return Err(corrupt("more operations than the header says"));
                }
                ops += 1;
                let op = read(addr, &ctx)?;
                let v_u = op.split.v_u;
                triangles += op.split.faces.len() as u64;
                if let Some(a) = op.right {
                    stack.push((
                        a,
                        OpContext {
                            v: v_u,
                            v_end: ctx.v_end,
                            parent_criteria: op.criteria_q,
                            position: op.position_u,
                            normal: op.normal_u,
                        },
                    ));
                }
                if let Some(a) = op.left {
                    stack.push((a, OpContext { v_end: v_u, parent_criteria: op.criteria_q, ..ctx }));
                }
                visit(addr, &ctx, op);
            }
        }
        if ops != h.splits as u64 {
            return Err(corrupt("fewer operations than the header says"));
        }
        if triangles != h.triangles as u64 {
            return Err(corrupt("triangle count differs from the header"));
        }
        Ok(())
    }
}

/// Refuses a header whose whole-file decode ([`decode`]) would take more than the cap on
/// decompressed input ([`crate::input::max_decompressed_bytes`]) before anything is
/// allocated: per vertex a position, a normal and its FVID (28 bytes), per split what the
/// progressive mesh keeps of it (its split with up to two faces, criteria, address and
/// context), per triangle of the fully refined mesh 12 bytes. An out-of-core reader
/// ([`super::NodeFile`]) reads node by node and is not bounded by this.
fn check_counts(h: &Header) -> Result<(), DpmError> {
    use std::mem::size_of;
    let per_split = size_of::<crate::pm::Split>()
        + 2 * size_of::<[u32; 3]>()
        + size_of::<crate::pm::Criteria>()
        + size_of::<usize>()
        + size_of::<OpContext>();
    let check = |field: &str, count: u32, unit: &str, each: usize| {
        crate::input::check_decoded(&format!("header field {field}"), count.into(), unit, each as u64)
            .map_err(DpmError::TooLarge)
    };
    check("vertices", h.vertices, "vertices", 28)?;
    check("splits", h.splits, "splits", per_split)?;
    check("triangles", h.triangles, "triangles", 12)?;
    Ok(())
}

/// A container error, with versions 2, 3 and 4 named as outdated and how to get a current file.
pub(super) fn outdated(e: DpmError) -> DpmError {
    match e {
        DpmError::UnsupportedVersion { format, found: FLOAT_VERSION, known } => DpmError::Outdated {
            format,
            found: FLOAT_VERSION,
            known,
            remedy: "its operations decode with floating-point steps a GPU may round differently; \
                     rebuild it from its source mesh with `tessera pm build`",
        },
        DpmError::UnsupportedVersion { format, found: NODELESS_VERSION, known } => DpmError::Outdated {
            format,
            found: NODELESS_VERSION,
            known,
            remedy: "it has no node table; rebuild it from its source mesh with `tessera pm build`",
        },
        DpmError::UnsupportedVersion { format, found: PAIRLESS_VERSION, known } => DpmError::Outdated {
            format,
            found: PAIRLESS_VERSION,
            known,
            remedy: "its out-of-core pointers are coded differently; rebuild it from its source mesh with \
                     `tessera pm build`",
        },
        e => e,
    }
}

/// An operation's error, naming the operation by its address (where the section or node ends
/// inside an operation, the data is corrupt: the container or the node table has checked the
/// length); out of core by its node and local address.
fn naming(addr: usize, out_of_core: bool, e: DpmError) -> DpmError {
    let at = if out_of_core {
        format!("node {}: operation at byte {}", addr / NODE_BYTES, addr % NODE_BYTES)
    } else {
        format!("operation at byte {addr}")
    };
    let ends = if out_of_core { "the node" } else { "the operations section" };
    match e {
        DpmError::Corrupt(f, m) => DpmError::Corrupt(f, format!("{at}: {m}")),
        DpmError::Truncated(_) => corrupt(format!("{at}: {ends} ends inside it")),
        e => e,
    }
}

/// A decoded `.dpm` file.
#[derive(Clone, Debug)]
pub struct Decoded {
    /// The progressive mesh, splits in the file's (pre-)order, numbered by FVID.
    pub pm: ProgressiveMesh,
    pub header: Header,
    /// Per split: its operation's address in the operations section, and its context.
    pub addresses: Vec<usize>,
    pub contexts: Vec<OpContext>,
}

/// Decodes a `.dpm` file.
pub fn decode(bytes: &[u8]) -> Result<Decoded, DpmError> {
    Dpm::parse(bytes)?.decode_all(None)
}
