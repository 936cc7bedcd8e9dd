//! The size breakdown of a `.dpm` file ([`DpmStats`], what `tessera pm stats` prints): the
//! operations' bits per field kind, measured by decoding every operation, in the groups that
//! section 6 of the paper reports (refinement criteria, tree structure, connectivity, geometry,
//! and the bytes the per-operation compression wastes), and the sizes of the other sections.

use std::collections::HashMap;

use super::decode::Dpm;
use super::fields::{Kind, KINDS};
use super::header::Header;
use super::node_file::NodeFile;
use super::DpmError;

/// Nodes [`DpmStats::of_out_of_core`] keeps read (4 MiB of 64 kB nodes).
const CACHED_NODES: usize = 64;

/// Sizes of a `.dpm` file, with the paper's breakdown of the operations (section 6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DpmStats {
    pub header: Header,
    pub bytes: usize,
    /// Refinement criteria (sin alpha, errors, radius).
    pub criteria_bytes: f64,
    /// Tree pointers: the head symbol (the children code, with the face count, the faces'
    /// orientations and the radius flag) and the address offsets.
    pub tree_pointer_bytes: f64,
    /// Connectivity: `v_u`'s FVID (the split point) and the faces.
    pub connectivity_bytes: f64,
    /// Geometry: position and normal deltas.
    pub geometry_bytes: f64,
    /// Byte alignment of the operations.
    pub padding_bytes: f64,
    /// The base mesh section.
    pub base_bytes: usize,
    /// The probability tables section.
    pub table_bytes: usize,
    /// The node table (out of core; empty in core).
    pub node_table_bytes: usize,
    /// Magic, header, section framing and checksums.
    pub framing_bytes: usize,
}

impl DpmStats {
    /// Measures a file (decoding every operation).
    pub fn of(bytes: &[u8]) -> Result<DpmStats, DpmError> {
        let dpm = Dpm::parse(bytes)?;
        let mut bits = [0u64; KINDS];
        dpm.decode_all(Some(&mut bits))?;
        Ok(Self::from_bits(&dpm, &bits, bytes.len()))
    }

    /// Measures an out-of-core file from its head and its nodes, decoding every operation in
    /// the same walk as [`Self::of`] but reading the nodes as the walk reaches them, the last
    /// 64 used kept (4 MiB of 64 kB nodes): the memory follows the split tree's depth, not the model
    /// (decoding the 102M-triangle armadillo's file whole took 7.3 GB). Returns the stats and
    /// how many nodes were read (a node is read again where the walk comes back to it after
    /// it left the cache).
    pub fn of_out_of_core(file: &NodeFile) -> Result<(DpmStats, u64), DpmError> {
        let dpm = Dpm::parse_prefix(file.prefix())?;
        let mut bits = [0u64; KINDS];
        // Node id -> (bytes, last use).
        let mut cache: HashMap<u32, (Vec<u8>, u64)> = HashMap::new();
        let (mut clock, mut reads) = (0u64, 0u64);
        let mut read = |addr: usize, ctx: &super::OpContext| {
            let n = Dpm::node_of(addr);
            clock += 1;
            if !cache.contains_key(&n) {
                if cache.len() == CACHED_NODES {
                    let oldest = cache.iter().min_by_key(|(_, (_, used))| *used).map(|(&k, _)| k);
                    cache.remove(&oldest.expect("a full cache"));
                }
                reads += 1;
                cache.insert(n, (file.read_node(n)?, clock));
            }
            let (node, used) = cache.get_mut(&n).expect("inserted above");
            *used = clock;
            dpm.read_in(node, addr, ctx, Some(&mut bits))
        };
        dpm.walk(&mut read, &mut |_, _, _| {})?;
        let len = file.prefix().len() + dpm.section_lens[3] + 4;
        Ok((Self::from_bits(&dpm, &bits, len), reads))
    }

    /// The stats of `dpm`, a file of `len` bytes whose operations decode to `bits` per kind.
    fn from_bits(dpm: &Dpm, bits: &[u64; KINDS], len: usize) -> DpmStats {
        let sum = |ks: &[Kind]| ks.iter().map(|&k| bits[k as usize]).sum::<u64>() as f64 / 8.0;
        let criteria_bytes = sum(&[Kind::Sin, Kind::GeomError, Kind::AttrError, Kind::Radius]);
        let tree_pointer_bytes = sum(&[Kind::Head, Kind::Pointer]);
        let connectivity_bytes = sum(&[
            Kind::Split,
            Kind::FaceCount,
            Kind::FaceForm,
            Kind::FaceT,
            Kind::FaceU,
            Kind::FaceOther,
            Kind::FaceOtherDelta,
            Kind::FaceGeneral,
        ]);
        let geometry_bytes = sum(&[Kind::Position, Kind::Normal]);
        let [tables, base, node_table, ops] = dpm.section_lens;
        DpmStats {
            header: dpm.header,
            bytes: len,
            criteria_bytes,
            tree_pointer_bytes,
            connectivity_bytes,
            geometry_bytes,
            padding_bytes: ops as f64 - criteria_bytes - tree_pointer_bytes - connectivity_bytes - geometry_bytes,
            base_bytes: base,
            table_bytes: tables,
            node_table_bytes: node_table,
            framing_bytes: len - tables - base - node_table - ops,
        }
    }

    pub fn bytes_per_vertex(&self) -> f64 {
        self.bytes as f64 / self.header.vertices.max(1) as f64
    }

    /// A part of the breakdown per vertex.
    pub fn per_vertex(&self, bytes: f64) -> f64 {
        bytes / self.header.vertices.max(1) as f64
    }
}
