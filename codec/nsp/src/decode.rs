//! Reading an `.nsp`: the file's tables, and the state of one cell refined from its parent's.

use rustc_hash::FxHashMap as HashMap;
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use super::complex::{self, ApplyError, BitIo, Blind, Complex, KdCell, Oracle};
use super::error::NspError;
use super::format::{self, CellEntry, Header, FOOTER_LEN, MIN_TABLE_LEN, PREFIX_LEN};
use super::tree::Tree;
use crate::rangecoder::{Decoder, DecoderState};

enum Source {
    Bytes(Arc<[u8]>),
    File(std::fs::File),
    /// A worker's: the prefixes of cell streams it was sent.
    Received(HashMap<u32, Vec<u8>>),
}

/// An opened `.nsp`: header, probability table, tree and cell table in memory; cell streams
/// read one at a time when asked for.
pub struct NspFile {
    pub header: Header,
    pub table: Arc<[u16]>,
    pub tree: Tree,
    pub entries: Vec<CellEntry>,
    source: Source,
    /// Bytes read from the file so far (header and tables included).
    pub bytes_read: AtomicU64,
    pub file_len: u64,
    /// Bytes of header and probability table (where the cell streams start).
    pub prefix_len: u64,
    /// The file without its cell streams: prefix, cell table and footer.
    skeleton: Vec<u8>,
}

impl NspFile {
    /// Opens a file in memory.
    pub fn from_bytes(bytes: impl Into<Arc<[u8]>>) -> Result<NspFile, NspError> {
        let bytes: Arc<[u8]> = bytes.into();
        let n = bytes.len();
        if n < PREFIX_LEN + MIN_TABLE_LEN + FOOTER_LEN {
            return Err(NspError::Format(format!("{n} bytes is shorter than any .nsp file")));
        }
        let (header, table, start) = format::read_prefix(&bytes[..n - FOOTER_LEN])?;
        let (offset, cells) = format::read_footer(&bytes[n - FOOTER_LEN..], n as u64, start)?;
        let entries = format::read_entries(&bytes[offset as usize..n - FOOTER_LEN], offset, start)?;
        check_count(cells, &entries)?;
        let read = (start + (n - offset as usize)) as u64;
        let skeleton = [&bytes[..start], &bytes[offset as usize..]].concat();
        Self::assemble(header, table, entries, Source::Bytes(bytes), read, n as u64, skeleton)
    }

    /// Opens a file on disk, reading only its header, tables and footer.
    pub fn open(path: &Path) -> Result<NspFile, NspError> {
        let io = |e: std::io::Error| NspError::Format(format!("cannot read: {e}"));
        let (mut file, len) = crate::input::open_regular(path).map_err(NspError::Format)?;
        if len < (PREFIX_LEN + MIN_TABLE_LEN + FOOTER_LEN) as u64 {
            return Err(NspError::Format(format!("{len} bytes is shorter than any .nsp file")));
        }
        let mut prefix = vec![0u8; PREFIX_LEN + 2];
        file.read_exact(&mut prefix).map_err(io)?;
        let want = format::prefix_len(&prefix)?;
        if want as u64 + FOOTER_LEN as u64 > len {
            return Err(NspError::Format("the file is shorter than its probability table".into()));
        }
        prefix.resize(want, 0);
        file.read_exact(&mut prefix[PREFIX_LEN + 2..]).map_err(io)?;
        let (header, table, start) = format::read_prefix(&prefix)?;
        let mut footer = [0u8; FOOTER_LEN];
        file.seek(SeekFrom::Start(len - FOOTER_LEN as u64)).map_err(io)?;
        file.read_exact(&mut footer).map_err(io)?;
        let (offset, cells) = format::read_footer(&footer, len, start)?;
        let mut rows = vec![0u8; (len - FOOTER_LEN as u64 - offset) as usize];
        file.seek(SeekFrom::Start(offset)).map_err(io)?;
        file.read_exact(&mut rows).map_err(io)?;
        let entries = format::read_entries(&rows, offset, start)?;
        check_count(cells, &entries)?;
        let read = (prefix.len() + rows.len() + FOOTER_LEN) as u64;
        let skeleton = [&prefix[..], &rows, &footer].concat();
        Self::assemble(header, table, entries, Source::File(file), read, len, skeleton)
    }

    fn assemble(
        header: Header,
        table: Vec<u16>,
        entries: Vec<CellEntry>,
        source: Source,
        read: u64,
        file_len: u64,
        skeleton: Vec<u8>,
    ) -> Result<NspFile, NspError> {
        let prefix_len = format::prefix_len(&skeleton)?;
        if header.cells as usize != entries.len() {
            return Err(NspError::Format(format!(
                "the header counts {} cells, the cell table {}",
                header.cells,
                entries.len()
            )));
        }
        let split: Vec<bool> = entries.iter().map(|e| e.split).collect();
        let tree = Tree::from_split_flags(header.params, &split)?;
        Ok(NspFile {
            header,
            table: table.into(),
            tree,
            entries,
            source,
            bytes_read: AtomicU64::new(read),
            file_len,
            prefix_len: prefix_len as u64,
            skeleton,
        })
    }

    /// The file without its cell streams (header, tables, cell table, footer): what a
    /// worker needs before any cell ([`NspFile::from_skeleton`]).
    pub fn skeleton(&self) -> &[u8] {
        &self.skeleton
    }

    /// A file known by its skeleton, whose cells arrive later ([`NspFile::receive`]).
    pub fn from_skeleton(skeleton: Vec<u8>) -> Result<NspFile, NspError> {
        let n = skeleton.len();
        let start = format::prefix_len(&skeleton)?;
        if n < start + 4 + FOOTER_LEN {
            return Err(NspError::Format("a skeleton shorter than its tables".into()));
        }
        let (header, table, start) = format::read_prefix(&skeleton[..n - FOOTER_LEN])?;
        let footer = &skeleton[n - FOOTER_LEN..];
        let offset = u64::from_le_bytes(footer[..8].try_into().unwrap());
        let rows = &skeleton[start..n - FOOTER_LEN];
        // The footer names the table's place in the whole file; the skeleton holds it right
        // after the prefix.
        let whole_len = offset + (n - start) as u64;
        let (offset, cells) = format::read_footer(footer, whole_len, start)?;
        let entries = format::read_entries(rows, offset, start)?;
        check_count(cells, &entries)?;
        Self::assemble(header, table, entries, Source::Received(HashMap::default()), n as u64, whole_len, skeleton)
    }

    /// Stores received bytes `from..` of cell `c`'s stream (whole segments, checked when
    /// used); they continue what was received before.
    pub fn receive(&mut self, c: u32, from: u32, bytes: Vec<u8>) -> Result<(), NspError> {
        let e = self.entries.get(c as usize).ok_or(NspError::Cell { cell: c, what: "no such cell".into() })?;
        let len = e.len;
        match &mut self.source {
            Source::Received(cells) => {
                let held = cells.entry(c).or_default();
                if from as usize != held.len() || from as u64 + bytes.len() as u64 > len as u64 {
                    return Err(NspError::Cell {
                        cell: c,
                        what: format!("received bytes {from}.. of its stream, holding {} of {len}", held.len()),
                    });
                }
                held.extend_from_slice(&bytes);
                Ok(())
            }
            _ => Err(NspError::Cell { cell: c, what: "received for a file read from disk".into() }),
        }
    }

    /// Bytes `from..to` of cell `c`'s stream (segment boundaries), checked against their
    /// segments' CRCs.
    pub fn cell_range(&self, c: u32, from: u32, to: u32) -> Result<Vec<u8>, NspError> {
        let e = self.entries.get(c as usize).ok_or(NspError::Cell { cell: c, what: "no such cell".into() })?;
        if from > to || to > e.len || !e.is_boundary(from) || !e.is_boundary(to) {
            return Err(NspError::Cell { cell: c, what: format!("bytes {from}..{to} are not whole segments") });
        }
        let range = (e.offset + from as u64) as usize..(e.offset + to as u64) as usize;
        let bytes: Vec<u8> = match &self.source {
            Source::Bytes(b) => b[range].to_vec(),
            Source::File(f) => {
                use std::os::unix::fs::FileExt;
                let mut buf = vec![0u8; (to - from) as usize];
                f.read_exact_at(&mut buf, range.start as u64)
                    .map_err(|err| NspError::Cell { cell: c, what: format!("cannot read its stream: {err}") })?;
                buf
            }
            Source::Received(cells) => {
                let held = cells.get(&c).map(Vec::as_slice).unwrap_or(&[]);
                if held.len() < to as usize {
                    return Err(NspError::Cell {
                        cell: c,
                        what: format!("needs {to} bytes of its stream, {} were received", held.len()),
                    });
                }
                held[from as usize..to as usize].to_vec()
            }
        };
        self.bytes_read.fetch_add((to - from) as u64, Ordering::Relaxed);
        if let Err(k) = e.check(&bytes, from) {
            return Err(NspError::Cell { cell: c, what: format!("stream checksum mismatch (segment {k})") });
        }
        Ok(bytes)
    }

    /// The bytes of cell `c`'s stream a decoder needs to hold it at `bits` of precision (with
    /// the geometry advance, the first segment even at its minimal precision: it starts with
    /// the prologue).
    pub fn needed(&self, c: u32, bits: u8) -> u32 {
        let min = self.tree.min_prec(c);
        let bits = if self.header.params.advance > 0 { bits.max(min + 1) } else { bits };
        self.entries[c as usize].needed(min, bits)
    }

    /// The root's state at its minimal precision (0 bits: one point).
    pub fn root_state(&self) -> Result<CellState, NspError> {
        let c = self.tree.root();
        CellState::new(self, c, Complex::root())
    }

    /// Child `c`'s state at its minimal precision, from its parent's state at the parent's
    /// maximal precision.
    pub fn child_state(&self, parent: &CellState, c: u32) -> Result<CellState, NspError> {
        let node = &self.tree.nodes[c as usize];
        debug_assert_eq!(node.parent, parent.cell);
        let bits = self.tree.min_prec(c);
        if parent.precision() != bits {
            return Err(NspError::Cell { cell: c, what: "its parent is not at its maximal precision".into() });
        }
        let groups = parent.by_child.get_or_init(|| {
            // Each kd-cell of the parent (all inside the parent or outside it) grouped by the
            // child holding it, once per parent state rather than once per child.
            let params = &self.header.params;
            let pl = params.level_bits() as u32;
            let pnode = &self.tree.nodes[parent.cell as usize];
            let shift = bits as u32 - pl * (pnode.depth as u32 + 1);
            let mask = (1u32 << pl) - 1;
            let mut groups = vec![Vec::new(); params.fan_out() as usize];
            let mut rank = vec![0u32; parent.cx.cells.len()];
            for (r, &k) in parent.cx.order.iter().enumerate() {
                rank[k as usize] = r as u32;
            }
            for &k in &parent.cx.order {
                let kd = &parent.cx.cells[k as usize];
                // At the parent's maximal precision every axis has `bits` bits.
                let q = kd.xyz;
                if (0..3).all(|a| q[a] >> (shift + pl) == pnode.coords[a]) {
                    let local = [(q[0] >> shift) & mask, (q[1] >> shift) & mask, (q[2] >> shift) & mask];
                    groups[params.child_index(local) as usize].push(k);
                }
            }
            (groups, rank)
        });
        let (groups, rank) = (&groups.0, &groups.1);
        let k = self.tree.nodes[parent.cell as usize].children.iter().position(|&x| x == c);
        let inside = k.map(|k| groups[k].as_slice()).unwrap_or(&[]);
        let cx = parent.cx.restrict(inside, rank);
        CellState::new(self, c, cx)
    }
}

/// The kd level where cell `c`'s geometry stops with the advance: `3 min(q + m, p)`.
pub(super) fn ahead_top(tree: &Tree, c: u32) -> u8 {
    3 * (tree.max_prec(c) + tree.params.advance).min(tree.params.bits)
}

/// The kd-cells of cell `c`'s starting state (at its minimal precision, in kd order) whose
/// descendants its stream's prologue codes: all of the root's, and a child's kd-cells that
/// lie outside it (its parent knew their descendants as the parent's simplices see them, a
/// child knows them as its own do; inside the child the two agree).
pub(super) fn fresh_cells(tree: &Tree, c: u32, cx: &Complex) -> Vec<u32> {
    let node = &tree.nodes[c as usize];
    if node.parent == u32::MAX {
        return cx.order.clone();
    }
    // At the cell's minimal precision every axis of a kd-cell has that many bits.
    let bits = tree.min_prec(c);
    cx.order.iter().copied().filter(|&v| !tree.contains(c, cx.cells[v as usize].xyz, bits)).collect()
}

/// The footer's count of cells against the cell table's rows.
fn check_count(cells: u32, entries: &[CellEntry]) -> Result<(), NspError> {
    if cells as usize != entries.len() {
        return Err(NspError::Format(format!("the footer counts {cells} cells, the cell table has {}", entries.len())));
    }
    Ok(())
}

/// One cell's decoded state: its complex at its current precision and where its stream
/// stands.
#[derive(Clone)]
pub struct CellState {
    pub cell: u32,
    pub cx: Complex,
    /// The stream's bytes fetched so far (a prefix, whole segments).
    bytes: Vec<u8>,
    table: Arc<[u16]>,
    at: Option<DecoderState>,
    min_level: u8,
    max_level: u8,
    max_cells: usize,
    max_tops: usize,
    /// Kd-cells split so far (vertex splits decoded), for throughput figures.
    pub splits: u64,
    /// At the maximal precision of a split cell: its kd-cells grouped by child, and each
    /// kd-cell's rank in kd-index order.
    by_child: std::sync::OnceLock<(Vec<Vec<u32>>, Vec<u32>)>,
    /// With the geometry advance: the kd-cells whose descendants the stream's prologue codes.
    fresh: Vec<u32>,
}

struct Static<'a, 'b> {
    dec: &'a mut Decoder<'b>,
    table: &'a [u16],
}

impl Static<'_, '_> {
    /// Runs `f` on a copy of the decoder, which the compiler keeps in registers through `f`'s
    /// loops (through `self.dec` every decision stored and reloaded them: measured slower),
    /// and takes its state back.
    #[inline(always)]
    fn on_copy<R>(&mut self, f: impl FnOnce(&mut Static<'_, '_>) -> R) -> R {
        let mut dec = self.dec.clone();
        let out = f(&mut Static { dec: &mut dec, table: self.table });
        *self.dec = dec;
        out
    }
}

impl BitIo for Static<'_, '_> {
    #[inline]
    fn bit(&mut self, ctx: usize, _: bool) -> bool {
        self.dec.bit_static(self.table[ctx])
    }

    fn geometry_run(
        &mut self,
        oracle: &mut impl Oracle,
        cells: &mut [KdCell],
        order: &[u32],
        from: usize,
        level: u8,
        next: &mut Vec<u32>,
    ) -> usize {
        self.on_copy(|io| complex::geometry_run(io, oracle, cells, order, from, level, next))
    }

    fn split(&mut self, cx: &mut Complex, v0: u32, v1: u32, oracle: &mut impl Oracle) -> Result<(), ApplyError> {
        self.on_copy(|io| cx.split(v0, v1, io, oracle))
    }
}

impl CellState {
    fn new(file: &NspFile, c: u32, mut cx: Complex) -> Result<CellState, NspError> {
        let e = &file.entries[c as usize];
        let m = file.header.params.advance;
        let fresh = if m > 0 {
            let top = ahead_top(&file.tree, c);
            if cx.ahead.levels == 0 {
                cx.enable_ahead(3 * m, top);
            }
            cx.ahead.top = top;
            fresh_cells(&file.tree, c, &cx)
        } else {
            Vec::new()
        };
        let (min_level, max_level) = (3 * file.tree.min_prec(c), 3 * file.tree.max_prec(c));
        if cx.cells.len() > e.max_cells as usize || cx.live_tops() > e.max_tops as usize {
            return Err(NspError::Cell {
                cell: c,
                what: "its parent's state is larger than the cell table allows".into(),
            });
        }
        if cx.cells.is_empty() != (e.len == 0) {
            return Err(NspError::Cell {
                cell: c,
                what: if e.len == 0 { "holds simplices but has no stream" } else { "is empty but has a stream" }.into(),
            });
        }
        Ok(CellState {
            cell: c,
            cx,
            bytes: Vec::new(),
            table: file.table.clone(),
            at: None,
            min_level,
            max_level,
            max_cells: e.max_cells as usize,
            max_tops: e.max_tops as usize,
            splits: 0,
            by_child: std::sync::OnceLock::new(),
            fresh,
        })
    }

    /// The current precision in bits.
    pub fn precision(&self) -> u8 {
        self.cx.level / 3
    }

    pub fn min_precision(&self) -> u8 {
        self.min_level / 3
    }

    pub fn max_precision(&self) -> u8 {
        self.max_level / 3
    }

    /// Whether bringing the cell to `bits` of precision means coarsening it: a state refines
    /// only, so the cell then restarts from a fresh starting state ([`CellState::inherit`]).
    /// (A state does not keep a copy of its start for this: the copy cost 3% of a full
    /// decode and as much memory as the cell's start, and a navigator holds the parent
    /// a fresh start is restricted from anyway.)
    pub fn coarsens(&self, bits: u8) -> bool {
        !self.cx.cells.is_empty() && (3 * bits).clamp(self.min_level, self.max_level) < self.cx.level
    }

    /// Takes over the stream bytes `old` (a state of the same cell) fetched and its count of
    /// splits, so that a fresh start re-decodes without reading the file again.
    pub fn inherit(&mut self, old: CellState) {
        debug_assert_eq!(self.cell, old.cell);
        self.bytes = old.bytes;
        self.splits = old.splits;
    }

    /// Brings the cell to `bits` of precision (clamped to its range) by continuing its
    /// stream; a state coarser than its current one is refused ([`CellState::coarsens`]).
    pub fn set_precision(&mut self, file: &NspFile, bits: u8) -> Result<(), NspError> {
        let target = (3 * bits).clamp(self.min_level, self.max_level);
        if self.cx.cells.is_empty() {
            self.cx.level = target;
            return Ok(());
        }
        // Only the segments up to the target precision are read.
        let need = file.needed(self.cell, target / 3);
        if (self.bytes.len() as u32) < need {
            let more = file.cell_range(self.cell, self.bytes.len() as u32, need)?;
            self.bytes.extend_from_slice(&more);
        }
        if target < self.cx.level {
            return Err(NspError::Cell {
                cell: self.cell,
                what: "coarsened in place (restart it from its parent's state)".into(),
            });
        }
        self.by_child = std::sync::OnceLock::new();
        // Nothing to decode: no decoder is started, as one started over the bytes held so
        // far (none at the minimal precision) would read zeros ahead, and resuming it once
        // more bytes came would decode from those zeros. (With the geometry advance the
        // prologue is decoded even at the minimal precision; its segment is always held.)
        if self.cx.level >= target && (self.at.is_some() || self.cx.ahead.levels == 0) {
            return Ok(());
        }
        let cell = self.cell;
        let err = |what: &str| NspError::Cell { cell, what: what.into() };
        let mut dec = match self.at {
            Some(s) => Decoder::resume(&self.bytes, s),
            None => {
                let mut dec = Decoder::new(&self.bytes);
                if self.cx.ahead.levels > 0 {
                    for &v in &self.fresh {
                        self.cx.grow_fresh(v, &mut Static { dec: &mut dec, table: &self.table }, &mut Blind);
                    }
                    if self.cx.ahead.desc.iter().map(|d| d.len()).sum::<usize>()
                        > self.max_cells << self.cx.ahead.levels
                    {
                        return Err(err("corrupt stream (more descendants in its prologue than its table allows)"));
                    }
                }
                dec
            }
        };
        while self.cx.level < target {
            let before = self.cx.cells.len();
            self.cx
                .refine_level(
                    &mut Static { dec: &mut dec, table: &self.table },
                    &mut Blind,
                    self.max_cells,
                    self.max_tops,
                )
                .map_err(|e| match e {
                    ApplyError::NoSymbol => err("corrupt stream (a connectivity symbol with no possible value)"),
                    ApplyError::TooLarge => {
                        err("corrupt stream (more kd-cells or simplices than its table entry allows)")
                    }
                })?;
            self.splits += (self.cx.cells.len() - before) as u64;
            if dec.overrun() > 4 {
                return Err(err("truncated stream (it ends before its last decision)"));
            }
        }
        self.at = Some(dec.state());
        Ok(())
    }
}

/// The cells to draw at a uniform precision `bits`, decoded: the cut of the tree where each
/// cell's precision range holds `bits` (a split cell at exactly its maximal precision gives
/// way to its children). Returns the states of the drawn cells.
pub fn decode_uniform_states(file: &NspFile, bits: u8) -> Result<Vec<CellState>, NspError> {
    let bits = bits.min(file.header.params.bits);
    let mut out = Vec::new();
    let mut root = file.root_state()?;
    let mut todo = Vec::new();
    let tree = &file.tree;
    let root_id = tree.root();
    if tree.is_leaf(root_id) || bits < tree.max_prec(root_id) {
        root.set_precision(file, bits)?;
        out.push(root);
    } else {
        root.set_precision(file, tree.max_prec(root_id))?;
        todo.push(root);
    }
    while let Some(parent) = todo.pop() {
        let children = tree.nodes[parent.cell as usize].children.clone();
        let states: Vec<Result<(CellState, bool), NspError>> = {
            use rayon::prelude::*;
            children
                .par_iter()
                .filter(|&&c| file.entries[c as usize].len > 0)
                .map(|&c| {
                    let mut s = file.child_state(&parent, c)?;
                    let leaf = tree.is_leaf(c);
                    if leaf || bits < tree.max_prec(c) {
                        s.set_precision(file, bits)?;
                        Ok((s, true))
                    } else {
                        s.set_precision(file, tree.max_prec(c))?;
                        Ok((s, false))
                    }
                })
                .collect()
        };
        for r in states {
            let (s, drawn) = r?;
            if drawn {
                out.push(s);
            } else {
                todo.push(s);
            }
        }
    }
    out.sort_by_key(|s| s.cell);
    Ok(out)
}
