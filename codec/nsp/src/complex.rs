//! The state of one cell: its kd-cells (the vertices at their current precision) and its
//! top-simplices, and the two operations that refine it by one kd level, shared by the
//! encoder and the decoder so that both run exactly the same steps.
//!
//! The paper's minimal structure (section 6.1): a list of top-simplices, each naming its
//! kd-cells, and per kd-cell the list of its incident top-simplices; no face hierarchy.
//! Kd-cells are never freed while a cell refines (a split keeps `v` as `v0` and adds `v1`),
//! top-simplices are recycled through a free list. Kd-cell ids are arena positions that the
//! encoder and the decoder create in the same order (a cell's starting kd-cells in kd-index
//! order, each split appending its `v1`), so the stream may depend on them: a split's star
//! is ordered by kd-cell id (sorting 4-byte ids, not 16-byte kd-indices, measured 1.3x
//! faster decoding). Top-simplex ids differ between the two (a parent's restriction and a
//! child's own clustering list them differently) and never decide anything.

use rustc_hash::FxHashMap as HashMap;

use smallvec::SmallVec;

use super::canonical::{top_simplices, Simplex};

/// Contexts: geometry per (kd level, valence bucket, binary node), then connectivity per
/// (dimension, allowed symbols, binary node, side of the split plane), then orientation.
pub const GEOMETRY_CONTEXTS: usize = 2 * 3 * super::params::MAX_BITS as usize * VALENCE_BUCKETS;

/// Which halves of a kd-cell its split leaves occupied.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Halves {
    First,
    Second,
    Both,
}

impl Halves {
    /// From whether each half is occupied (the first, where neither is).
    fn of(first: bool, second: bool) -> Halves {
        match (first, second) {
            (true, true) => Halves::Both,
            (_, true) => Halves::Second,
            (_, false) => Halves::First,
        }
    }
}
/// A kd-cell's number of incident top-simplices, bucketed: more simplices, more likely
/// several points inside.
const VALENCE_BUCKETS: usize = 4;
const CONN_BASE: usize = GEOMETRY_CONTEXTS;
/// Where the other vertex `w` of an edge `v·w` lies against the plane that splits `v`:
/// across it, or on `v0`'s or `v1`'s side, adjacent or farther.
const SIDES: usize = 5;
const CONN_CONTEXTS: usize = 3 * 16 * 3 * SIDES;
const ORIENT_BASE: usize = CONN_BASE + CONN_CONTEXTS;
/// Total number of contexts, so of probabilities in a file's table.
pub const CONTEXTS: usize = ORIENT_BASE + 4;

/// One binary decision, coded or decoded. The encoder records `value` and returns it; the
/// decoder ignores it and returns what the stream says.
pub trait BitIo {
    fn bit(&mut self, ctx: usize, value: bool) -> bool;

    /// The geometry of the kd-cells `order[from..]` at kd `level`, each moved one level down
    /// and pushed on `next`, up to the first one whose two halves are occupied: that one is
    /// pushed but not moved, and its index returned (`order.len()` if none). A coder may run
    /// these shared steps on a copy of its registers.
    #[inline]
    fn geometry_run(
        &mut self,
        oracle: &mut impl Oracle,
        cells: &mut [KdCell],
        order: &[u32],
        from: usize,
        level: u8,
        next: &mut Vec<u32>,
    ) -> usize
    where
        Self: Sized,
    {
        geometry_run(self, oracle, cells, order, from, level, next)
    }

    /// The vertex split of `v0` into `v0` and `v1` (a coder may run it on a copy of its
    /// registers).
    #[inline]
    fn split(&mut self, cx: &mut Complex, v0: u32, v1: u32, oracle: &mut impl Oracle) -> Result<(), ApplyError>
    where
        Self: Sized,
    {
        cx.split(v0, v1, self, oracle)
    }
}

/// [`BitIo::geometry_run`]'s steps, shared by every coder.
#[inline(always)]
pub(super) fn geometry_run(
    io: &mut impl BitIo,
    oracle: &mut impl Oracle,
    cells: &mut [KdCell],
    order: &[u32],
    from: usize,
    level: u8,
    next: &mut Vec<u32>,
) -> usize {
    let axis = (level % 3) as usize;
    for (i, &v) in order[from..].iter().enumerate() {
        let (both, second) = oracle.geometry(v, level);
        let cell = &mut cells[v as usize];
        let ctx = 2 * (level as usize * VALENCE_BUCKETS + valence_bucket(cell.degree as usize));
        next.push(v);
        if io.bit(ctx, both) {
            return from + i;
        }
        let second = io.bit(ctx + 1, second);
        cell.level += 1;
        cell.xyz[axis] = cell.xyz[axis] << 1 | second as u32;
    }
    order.len()
}

/// What the encoder knows and the decoder learns from the stream. The decoder's oracle
/// answers anything: its answers go to [`BitIo::bit`] as values, which the decoder ignores.
pub trait Oracle {
    /// The occupancy of kd-cell `cell`'s two halves at kd `level`: (both, second only).
    fn geometry(&mut self, cell: u32, level: u8) -> (bool, bool);
    /// Called when `v0` (the old `v`) splits off `v1`, before the connectivity is coded.
    fn before_split(&mut self, v0: u32, v1: u32);
    /// The symbol of the star simplex `v·τ` (0 `v0·τ`, 1 `v1·τ`, 2 both, 3 both and the cone).
    fn symbol(&mut self, v0: u32, v1: u32, tau: &[u32]) -> u8;
    /// Whether `t` has the true orientation of the triangle on its vertex set.
    fn oriented(&mut self, t: [u32; 3]) -> bool;
    /// With a geometry advance: the occupancy of the halves of the kd-cell `prefix` at kd
    /// `level` among the cell's finest points (both, second only).
    fn occupancy(&mut self, prefix: u128, level: u8) -> (bool, bool);
}

/// The decoder's oracle: it knows nothing.
pub struct Blind;

impl Oracle for Blind {
    fn geometry(&mut self, _: u32, _: u8) -> (bool, bool) {
        (false, false)
    }
    fn before_split(&mut self, _: u32, _: u32) {}
    fn symbol(&mut self, _: u32, _: u32, _: &[u32]) -> u8 {
        0
    }
    fn oriented(&mut self, _: [u32; 3]) -> bool {
        true
    }
    fn occupancy(&mut self, _: u128, _: u8) -> (bool, bool) {
        (false, false)
    }
}

/// A [`BitIo`] that codes nothing and keeps the oracle's answers (the encoder's way of
/// deriving what the decoder inherits rather than reads).
pub struct Silent;

impl BitIo for Silent {
    #[inline]
    fn bit(&mut self, _: usize, value: bool) -> bool {
        value
    }
}

/// The geometry advance of section 7: geometry runs `levels` kd levels ahead of
/// connectivity, so each kd-cell knows its non-empty descendants that many levels below it
/// (fewer near `top`, the kd level of the cell's finest points), and is drawn at their mean.
#[derive(Clone, Debug, Default)]
pub struct Ahead {
    /// `3m` (0: no advance).
    pub levels: u8,
    /// The kd level where geometry stops: `3 min(q + m, p)` for a cell of maximal precision `q`.
    pub top: u8,
    /// Per kd-cell: its non-empty descendants [`Complex::ahead_depth`] levels below it, as
    /// suffixes of that many bits, ascending.
    pub desc: Vec<SmallVec<[u16; 4]>>,
}

/// A kd-cell: its place and how many top-simplices it has. 16 bytes: the per-level loop and
/// the split's side test read only these, in a dense array apart from the lists of
/// incident simplices ([`Complex::incident`]; with the lists inline a kd-cell took 56 bytes;
/// the split measured no faster or slower on the dragon). The kd-index's prefix is derived
/// from the place ([`KdCell::prefix`]: one field less to shift at every level, measured
/// faster).
#[derive(Clone, Copy, Debug)]
pub struct KdCell {
    /// The cell's integer coordinates: axis `a` holds the bits consumed so far on it.
    pub xyz: [u32; 3],
    pub level: u8,
    /// Incident top-simplices, up to 255 (the geometry contexts look at up to 10).
    pub degree: u8,
}

/// The per-axis coordinates of the kd-cell `prefix` at `level` (bits consumed per axis).
pub fn xyz_of(prefix: u128, level: u8) -> [u32; 3] {
    let mut q = [0u32; 3];
    for i in 0..level as u32 {
        let axis = (i % 3) as usize;
        q[axis] = (q[axis] << 1) | ((prefix >> (level as u32 - 1 - i)) & 1) as u32;
    }
    q
}

/// The centre of the kd-cell at `level` with per-axis coordinates `xyz`, in grid units of
/// `bits` bits per axis.
pub fn centre(level: u8, xyz: [u32; 3], bits: u8) -> [f64; 3] {
    [0, 1, 2].map(|a| (xyz[a] as f64 + 0.5) * (1u64 << (bits as u32 - used(level, a))) as f64)
}

/// Bits consumed on `axis` at kd `level`.
#[inline]
fn used(level: u8, axis: usize) -> u32 {
    (level as u32 + 2 - axis as u32) / 3
}

/// 0 for up to 3 simplices, 1 for 4 to 6, 2 for 7 to 9, 3 for more (a table rather than a
/// `match`, which compiled to a chain of unpredictable branches).
#[inline]
fn valence_bucket(tops: usize) -> usize {
    const BUCKET: [u8; 11] = [0, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3];
    BUCKET[tops.min(10)] as usize
}

impl KdCell {
    /// The kd-index: a total order on kd-cells of any levels (`1 << level | prefix`).
    #[inline]
    pub fn index(&self) -> u128 {
        (1u128 << self.level) | self.prefix()
    }

    /// The `level` bits of the cell's path from the root, first split first: the axes'
    /// coordinates interleaved x, y, z from their most significant bits ([`xyz_of`]'s
    /// inverse).
    pub fn prefix(&self) -> u128 {
        let mut p = 0u128;
        for i in 0..self.level as u32 {
            let axis = (i % 3) as usize;
            let bit = used(self.level, axis) - 1 - i / 3;
            p = (p << 1) | ((self.xyz[axis] >> bit) & 1) as u128;
        }
        p
    }
}

/// A top-simplex on kd-cell ids; `dim` is `DEAD` for a free slot.
#[derive(Clone, Copy, Debug)]
pub struct Top {
    pub v: [u32; 3],
    pub dim: u8,
}

const DEAD: u8 = u8::MAX;

/// Why a stream cannot be applied (only a corrupt stream gets here).
#[derive(Debug, PartialEq)]
pub enum ApplyError {
    /// A triangle of the star has no possible image: the stream is not one the encoder wrote.
    NoSymbol,
    /// More kd-cells or top-simplices than the cell table allows.
    TooLarge,
}

/// The complex of one cell at a uniform or (during a level) mixed precision.
#[derive(Clone, Debug, Default)]
pub struct Complex {
    pub cells: Vec<KdCell>,
    /// Per kd-cell, its incident top-simplices (inline up to a typical valence: no
    /// allocation per vertex).
    pub incident: Vec<SmallVec<[u32; 8]>>,
    pub tops: Vec<Top>,
    free: Vec<u32>,
    live_tops: usize,
    /// The most live top-simplices there have been at once.
    pub peak_tops: usize,
    /// Kd-cells sorted by kd-index at the current level (all cells are at `level`).
    pub order: Vec<u32>,
    pub level: u8,
    scratch_verts: Vec<u32>,
    scratch_opposite: Vec<Opposite>,
    scratch_syms: Vec<u8>,
    scratch_edges: Vec<[u32; 2]>,
    scratch_tris: Vec<NewTri>,
    scratch_first: Vec<u32>,
    scratch_old: SmallVec<[u32; 8]>,
    /// Per kd-cell: the split that last listed it in its star's vertices, and its position
    /// there (a mark instead of sorting duplicates away, and no search for a triangle's
    /// corners).
    marks: Vec<[u32; 2]>,
    stamp: u32,
    scratch_sorted: Vec<Opposite>,
    pub ahead: Ahead,
}

/// A triangle `v·w·x` of the star: the ids of `w` and `x` (ascending), the oriented
/// triangle and its top-simplex id.
#[derive(Clone, Copy, Debug, Default)]
struct Opposite {
    /// The positions of `w` and `x` in the star's vertices, as one sortable integer.
    key: u64,
    w: [u32; 2],
    tri: [u32; 3],
    id: u32,
}

/// A triangle of a split's new star: its vertices (oriented once the orientation is
/// decoded), the orientation context (1 for a triangle both `v0` and `v1` inherit), whether
/// it is a cone `v0·v1·w`, and the star triangle whose top-simplex it takes over (`NONE`
/// for a new one).
#[derive(Clone, Copy, Debug)]
struct NewTri {
    v: [u32; 3],
    kind: usize,
    cone: bool,
    reuse: u32,
    /// A cone's `w`: its position in the star's vertices.
    at: u32,
}

const NONE: u32 = u32::MAX;

/// Stars up to this size sort by counting ranks (quadratic, but free of branches).
const SMALL_STAR: usize = 16;

impl Complex {
    /// The root's starting state: one kd-cell (the cube) and one point.
    pub fn root() -> Complex {
        let mut c = Complex::default();
        c.cells.push(KdCell { level: 0, xyz: [0; 3], degree: 0 });
        c.incident.push(SmallVec::new());
        c.add_top(Top { v: [0, 0, 0], dim: 0 });
        c.order = vec![0];
        c
    }

    /// The clustering of `simplices` (on point ids) at kd `level`, `prefix[i]` being point
    /// `i`'s kd-cell there. Returns the complex and each point's kd-cell id.
    pub fn cluster(level: u8, prefix: &[u128], simplices: &[Simplex]) -> (Complex, Vec<u32>) {
        let mut distinct: Vec<u128> = prefix.to_vec();
        distinct.sort_unstable();
        distinct.dedup();
        let id: HashMap<u128, u32> = distinct.iter().enumerate().map(|(i, &p)| (p, i as u32)).collect();
        let pcell: Vec<u32> = prefix.iter().map(|p| id[p]).collect();
        let mut c = Complex { level, ..Complex::default() };
        c.cells = distinct.iter().map(|&prefix| KdCell { level, xyz: xyz_of(prefix, level), degree: 0 }).collect();
        c.incident = vec![SmallVec::new(); c.cells.len()];
        let images = simplices.iter().map(|s| {
            let mut t = *s;
            for k in 0..=s.dim as usize {
                t.v[k] = pcell[s.v[k] as usize];
            }
            t
        });
        for s in top_simplices(distinct.len(), images) {
            c.add_top(Top { v: s.v, dim: s.dim });
        }
        c.order = (0..c.cells.len() as u32).collect();
        (c, pcell)
    }

    /// The part of `self` (at a uniform level) that touches the kd-cells `inside`: the
    /// top-simplices with a vertex there, and all their vertices, in kd-index order. `rank`
    /// gives each kd-cell's position in `self.order` (kd-index order at a uniform level).
    ///
    /// The kept top-simplices and kd-cells are marked in bit sets over the parent's ids and
    /// ranks, which list them in order without sorting, and a kept kd-cell's new id is the
    /// count of marked ranks below its own (sorting the marks instead took 60% of this
    /// function on the dragon's cells).
    pub fn restrict(&self, inside: &[u32], rank: &[u32]) -> Complex {
        let mut c = Complex { level: self.level, ..Complex::default() };
        let mut keep = vec![0u64; self.tops.len().div_ceil(64)];
        for &v in inside {
            for &t in &self.incident[v as usize] {
                keep[t as usize / 64] |= 1 << (t % 64);
            }
        }
        let mut ranks = vec![0u64; self.cells.len().div_ceil(64)];
        for t in ones(&keep) {
            for &v in self.top_verts(t) {
                let r = rank[v as usize];
                ranks[r as usize / 64] |= 1 << (r % 64);
            }
        }
        let mut before = Vec::with_capacity(ranks.len());
        let mut count = 0;
        for w in &ranks {
            before.push(count);
            count += w.count_ones();
        }
        c.cells.reserve(count as usize);
        c.incident.resize(count as usize, SmallVec::new());
        for r in ones(&ranks) {
            let k = &self.cells[self.order[r as usize] as usize];
            c.cells.push(KdCell { level: k.level, xyz: k.xyz, degree: 0 });
        }
        if self.ahead.levels > 0 {
            c.ahead.levels = self.ahead.levels;
            c.ahead.top = self.ahead.top;
            c.ahead.desc = ones(&ranks).map(|r| self.ahead.desc[self.order[r as usize] as usize].clone()).collect();
        }
        let map = |v: u32| {
            let r = rank[v as usize] as usize;
            before[r / 64] + (ranks[r / 64] & ((1u64 << (r % 64)) - 1)).count_ones()
        };
        // As `add_top` would, with the degrees set once at the end.
        for t in ones(&keep) {
            let mut top = self.tops[t as usize];
            let id = c.tops.len() as u32;
            for k in 0..=top.dim as usize {
                top.v[k] = map(top.v[k]);
                c.incident[top.v[k] as usize].push(id);
            }
            c.tops.push(top);
        }
        for (cell, list) in c.cells.iter_mut().zip(&c.incident) {
            cell.degree = list.len().min(255) as u8;
        }
        c.live_tops = c.tops.len();
        c.peak_tops = c.live_tops;
        c.order = (0..c.cells.len() as u32).collect();
        c
    }

    pub fn top_verts(&self, t: u32) -> &[u32] {
        let top = &self.tops[t as usize];
        &top.v[..top.dim as usize + 1]
    }

    /// Live top-simplices.
    pub fn live_tops(&self) -> usize {
        self.live_tops
    }

    /// Live top-simplices, in arena order.
    pub fn iter_tops(&self) -> impl Iterator<Item = &Top> {
        self.tops.iter().filter(|t| t.dim != DEAD)
    }

    /// Lists top-simplex `t` as incident to kd-cell `u`.
    #[inline]
    fn link(&mut self, u: u32, t: u32) {
        let list = &mut self.incident[u as usize];
        list.push(t);
        self.cells[u as usize].degree = list.len().min(255) as u8;
    }

    fn add_top(&mut self, top: Top) -> u32 {
        let id = match self.free.pop() {
            Some(id) => {
                self.tops[id as usize] = top;
                id
            }
            None => {
                self.tops.push(top);
                self.tops.len() as u32 - 1
            }
        };
        for k in 0..=top.dim as usize {
            self.link(top.v[k], id);
        }
        self.live_tops += 1;
        self.peak_tops = self.peak_tops.max(self.live_tops);
        id
    }

    /// Refines every kd-cell by one kd level, in kd-index order.
    pub fn refine_level(
        &mut self,
        io: &mut impl BitIo,
        oracle: &mut impl Oracle,
        max_cells: usize,
        max_tops: usize,
    ) -> Result<(), ApplyError> {
        if self.ahead.levels > 0 {
            return self.refine_level_ahead(io, oracle, max_cells, max_tops);
        }
        let level = self.level;
        let order = std::mem::take(&mut self.order);
        let mut next = Vec::with_capacity(order.len() * 2);
        let mut i = 0;
        while i < order.len() {
            i = io.geometry_run(oracle, &mut self.cells, &order, i, level, &mut next);
            if let Some(&v) = order.get(i) {
                // Both halves of `v` are occupied.
                if let Some(v1) = self.descend(v, Halves::Both, io, oracle, max_cells, max_tops)? {
                    next.push(v1);
                }
                i += 1;
            }
        }
        self.order = next;
        self.level = level + 1;
        Ok(())
    }

    /// Moves kd-cell `v` one kd level down, into its second half if `second`, or when `both`
    /// halves are occupied keeps `v` as the first and appends the second as `v1`, applying the
    /// connectivity change of the split; returns `v1`.
    #[inline]
    fn descend(
        &mut self,
        v: u32,
        halves: Halves,
        io: &mut impl BitIo,
        oracle: &mut impl Oracle,
        max_cells: usize,
        max_tops: usize,
    ) -> Result<Option<u32>, ApplyError> {
        let cell = &mut self.cells[v as usize];
        let axis = (cell.level % 3) as usize;
        cell.level += 1;
        cell.xyz[axis] <<= 1;
        if halves != Halves::Both {
            cell.xyz[axis] |= (halves == Halves::Second) as u32;
            return Ok(None);
        }
        let level = cell.level;
        let mut xyz = cell.xyz;
        xyz[axis] |= 1;
        if self.cells.len() >= max_cells {
            return Err(ApplyError::TooLarge);
        }
        let v1 = self.cells.len() as u32;
        self.cells.push(KdCell { level, xyz, degree: 0 });
        self.incident.push(SmallVec::new());
        oracle.before_split(v, v1);
        io.split(self, v, v1, oracle)?;
        if self.live_tops > max_tops {
            return Err(ApplyError::TooLarge);
        }
        Ok(Some(v1))
    }

    /// Turns the geometry advance on: `levels` kd levels ahead, up to kd level `top`. Every
    /// kd-cell starts with no known descendant ([`Complex::grow_fresh`] or an inherited list
    /// fills them in).
    pub fn enable_ahead(&mut self, levels: u8, top: u8) {
        self.ahead = Ahead { levels, top, desc: vec![SmallVec::new(); self.cells.len()] };
    }

    /// How many kd levels below a kd-cell at `level` its known descendants lie.
    #[inline]
    pub fn ahead_depth(&self, level: u8) -> u8 {
        self.ahead.levels.min(self.ahead.top.saturating_sub(level))
    }

    /// Codes kd-cell `v`'s descendants from `v` itself down to [`Complex::ahead_depth`]
    /// levels (a cell stream's prologue: the root's kd-cell, and a child's kd-cells that lie
    /// outside it, whose descendants the parent knew only as its own simplices see them).
    pub fn grow_fresh(&mut self, v: u32, io: &mut impl BitIo, oracle: &mut impl Oracle) {
        let depth = self.ahead_depth(self.cells[v as usize].level);
        let mut list: SmallVec<[u16; 4]> = SmallVec::new();
        list.push(0);
        for rel in 0..depth {
            list = self.extend(v, &list, rel, io, oracle);
        }
        self.ahead.desc[v as usize] = list;
    }

    /// The known descendants of `v`, `rel` levels below it, each refined by one kd level:
    /// one occupancy code (both halves, or which one) per descendant, in kd order.
    fn extend(
        &self,
        v: u32,
        list: &[u16],
        rel: u8,
        io: &mut impl BitIo,
        oracle: &mut impl Oracle,
    ) -> SmallVec<[u16; 4]> {
        let kd = &self.cells[v as usize];
        let level = kd.level + rel;
        let ctx = 2 * (level as usize * VALENCE_BUCKETS + valence_bucket(kd.degree as usize));
        let mut out = SmallVec::with_capacity(list.len() * 2);
        for &s in list {
            let (both, second) = oracle.occupancy((kd.prefix() << rel) | s as u128, level);
            if io.bit(ctx, both) {
                out.push(s << 1);
                out.push(s << 1 | 1);
            } else {
                out.push(s << 1 | io.bit(ctx + 1, second) as u16);
            }
        }
        out
    }

    /// [`Complex::refine_level`] with the geometry advance: each kd-cell splits as its known
    /// descendants say (no geometry code), its connectivity change is coded as without the
    /// advance, then the descendants of the new kd-cells are refined one level further.
    fn refine_level_ahead(
        &mut self,
        io: &mut impl BitIo,
        oracle: &mut impl Oracle,
        max_cells: usize,
        max_tops: usize,
    ) -> Result<(), ApplyError> {
        let level = self.level;
        let order = std::mem::take(&mut self.order);
        let mut next = Vec::with_capacity(order.len() * 2);
        let depth = self.ahead_depth(level);
        if depth == 0 {
            return Err(ApplyError::NoSymbol);
        }
        let top_bit = 1u16 << (depth - 1);
        let mask = top_bit - 1;
        let grows = self.ahead_depth(level + 1) == depth;
        for &v in &order {
            let desc = std::mem::take(&mut self.ahead.desc[v as usize]);
            let has0 = desc.iter().any(|&s| s & top_bit == 0);
            let has1 = desc.iter().any(|&s| s & top_bit != 0);
            if !has0 && !has1 {
                return Err(ApplyError::NoSymbol);
            }
            // The encoder's truth follows the split (and learns the level) here.
            oracle.geometry(v, level);
            next.push(v);
            let Some(v1) = self.descend(v, Halves::of(has0, has1), io, oracle, max_cells, max_tops)? else {
                let list: SmallVec<[u16; 4]> = desc.iter().map(|&s| s & mask).collect();
                self.ahead.desc[v as usize] = if grows { self.extend(v, &list, depth - 1, io, oracle) } else { list };
                continue;
            };
            next.push(v1);
            self.ahead.desc.push(SmallVec::new());
            let (zeros, ones): (SmallVec<[u16; 4]>, SmallVec<[u16; 4]>) =
                desc.iter().copied().partition(|&s| s & top_bit == 0);
            for (w, list) in [(v, zeros), (v1, ones)] {
                let list: SmallVec<[u16; 4]> = list.iter().map(|&s| s & mask).collect();
                self.ahead.desc[w as usize] = if grows { self.extend(w, &list, depth - 1, io, oracle) } else { list };
            }
        }
        self.order = next;
        self.level = level + 1;
        Ok(())
    }

    /// Where kd-cell `v` is drawn, in grid units of `bits` bits per axis: its centre, or with
    /// the advance the mean of its known descendants' centres.
    pub fn position(&self, v: u32, bits: u8) -> [f64; 3] {
        let kd = &self.cells[v as usize];
        let depth = if self.ahead.levels > 0 { self.ahead_depth(kd.level) } else { 0 };
        let desc = self.ahead.desc.get(v as usize).map(SmallVec::as_slice).unwrap_or(&[]);
        if depth == 0 || desc.is_empty() {
            return centre(kd.level, kd.xyz, bits);
        }
        let mut sum = [0f64; 3];
        for &s in desc {
            let mut xyz = kd.xyz;
            for i in 0..depth {
                let a = ((kd.level + i) % 3) as usize;
                xyz[a] = (xyz[a] << 1) | ((s >> (depth - 1 - i)) & 1) as u32;
            }
            let c = centre(kd.level + depth, xyz, bits);
            for a in 0..3 {
                sum[a] += c[a];
            }
        }
        sum.map(|x| x / desc.len() as f64)
    }

    /// The generalised vertex split of `v` (now `v0`) into `v0` and `v1` (NSP.md 1.6).
    ///
    /// Hand-written small-vector code rather than hash maps: stars hold a dozen simplices at
    /// fine levels, and this runs once per vertex split (measured 5x faster than with
    /// `HashMap`/`HashSet` scratch).
    #[inline(always)]
    pub(super) fn split(
        &mut self,
        v0: u32,
        v1: u32,
        io: &mut impl BitIo,
        oracle: &mut impl Oracle,
    ) -> Result<(), ApplyError> {
        // v0's list starts afresh (reusing the spare list's room); the old one is read.
        let spare = std::mem::take(&mut self.scratch_old);
        let old = std::mem::replace(&mut self.incident[v0 as usize], spare);
        self.cells[v0 as usize].degree = 0;
        // The star of v: every τ with v·τ in the closure of v's top-simplices: the vertex
        // itself, its neighbours (edges v·w) and its opposite edges (triangles v·w·x), each in
        // kd-cell id order.
        let mut verts = std::mem::take(&mut self.scratch_verts);
        verts.clear();
        let stamp = self.next_stamp();
        let mut opposite = std::mem::take(&mut self.scratch_opposite);
        opposite.clear();
        // Branch-free where the branches were unpredictable (which corner is v0, whether a
        // neighbour was met before): measured faster on the dragon.
        verts.resize(2 * old.len(), 0);
        let mut nv = 0;
        // Edges and points of the star (triangles stay in place, these go).
        let mut lower = 0;
        for &t in &old {
            let top = self.tops[t as usize];
            let [a, b, c] = top.v;
            let (x, y, n) = match top.dim {
                2 => {
                    let (x, y) = if a == v0 {
                        (b, c)
                    } else if b == v0 {
                        (c, a)
                    } else {
                        (a, b)
                    };
                    opposite.push(Opposite { key: 0, w: [x.min(y), x.max(y)], tri: top.v, id: t });
                    (x, y, 2)
                }
                1 => {
                    let x = if a == v0 { b } else { a };
                    (x, x, 1)
                }
                _ => (0, 0, 0),
            };
            lower += (top.dim != 2) as usize;
            for &u in &[x, y][..n] {
                let m = &mut self.marks[u as usize][0];
                verts[nv] = u;
                nv += (*m != stamp) as usize;
                *m = stamp;
            }
        }
        verts.truncate(nv);
        if verts.len() <= SMALL_STAR {
            // Distinct values: each one's rank is the count of smaller ones (no branch).
            let mut held = [0u32; SMALL_STAR];
            held[..verts.len()].copy_from_slice(&verts);
            for &u in &held[..verts.len()] {
                let rank = held[..verts.len()].iter().map(|&x| (x < u) as u32).sum::<u32>();
                self.marks[u as usize][1] = rank;
                verts[rank as usize] = u;
            }
        } else {
            verts.sort_unstable();
            for (j, &u) in verts.iter().enumerate() {
                self.marks[u as usize][1] = j as u32;
            }
        }
        for o in opposite.iter_mut() {
            o.key = (self.marks[o.w[0] as usize][1] as u64) << 32 | self.marks[o.w[1] as usize][1] as u64;
        }
        if opposite.len() <= SMALL_STAR {
            let mut sorted = std::mem::take(&mut self.scratch_sorted);
            sorted.clear();
            sorted.resize(opposite.len(), Opposite::default());
            for o in opposite.iter() {
                let rank = opposite.iter().map(|p| (p.key < o.key) as usize).sum::<usize>();
                sorted[rank] = *o;
            }
            self.scratch_sorted = std::mem::replace(&mut opposite, sorted);
        } else {
            opposite.sort_unstable_by_key(|o| o.key);
        }

        // Symbols, coarse faces first; a vertex τ's symbol constrains its triangles.
        let mut syms = std::mem::take(&mut self.scratch_syms);
        syms.clear();
        let mut edges = std::mem::take(&mut self.scratch_edges);
        edges.clear();
        let mut tris = std::mem::take(&mut self.scratch_tris);
        tris.clear();
        // Per star vertex: the first inherited triangle with it as a corner.
        let mut first = std::mem::take(&mut self.scratch_first);
        first.clear();
        first.resize(verts.len(), NONE);
        // Whether v0 and v1 end up in any simplex (else each is an isolated point).
        let mut has_simplex = [false; 2];
        let cone_edge = code_symbol(io, 0, 0b1100, 0, oracle.symbol(v0, v1, &[])) == 3;
        for (j, &w) in verts.iter().enumerate() {
            let allowed = 0b0111 | if cone_edge { 0b1000 } else { 0 };
            let truth = oracle.symbol(v0, v1, &[w]);
            let side = self.side(v1, w);
            let sym = code_symbol(io, 1, allowed, side, truth);
            // Bits 2 and 3: whether a triangle covers the edge v0·w, v1·w (filled below).
            syms.push(sym);
            if sym == 3 {
                tris.push(NewTri { v: [v0, v1, w], kind: 0, cone: true, reuse: NONE, at: j as u32 });
                has_simplex = [true, true];
                *syms.last_mut().expect("just pushed") |= 0b1100;
            }
        }
        for o in opposite.iter() {
            let (ja, jb) = ((o.key >> 32) as usize, o.key as u32 as usize);
            let (a, b) = (syms[ja] & 3, syms[jb] & 3);
            let has0 = |s: u8| s != 1;
            let has1 = |s: u8| s != 0;
            let m0 = has0(a) && has0(b);
            let m1 = has1(a) && has1(b);
            let allowed = (m0 as u8) | (m1 as u8) << 1 | ((m0 && m1) as u8) << 2;
            if allowed == 0 {
                self.scratch_first = first;
                self.restore(verts, opposite, syms, edges, tris);
                return Err(ApplyError::NoSymbol);
            }
            let truth = oracle.symbol(v0, v1, &o.w);
            let sym = code_symbol(io, 2, allowed, 0, truth);
            let t = o.tri;
            let sub = |x: u32| t.map(|u| if u == v0 { x } else { u });
            // A star triangle goes on as the v0 triangle, or as the v1 one if it has no v0 one:
            // the same top-simplex, so w's and x's lists need no change.
            if sym != 1 {
                first[ja] = first[ja].min(tris.len() as u32);
                first[jb] = first[jb].min(tris.len() as u32);
                tris.push(NewTri { v: sub(v0), kind: (sym == 2) as usize, cone: false, reuse: o.id, at: NONE });
                syms[ja] |= 0b0100;
                syms[jb] |= 0b0100;
                has_simplex[0] = true;
            }
            if sym != 0 {
                let reuse = if sym == 1 { o.id } else { NONE };
                first[ja] = first[ja].min(tris.len() as u32);
                first[jb] = first[jb].min(tris.len() as u32);
                tris.push(NewTri { v: sub(v1), kind: (sym == 2) as usize, cone: false, reuse, at: NONE });
                syms[ja] |= 0b1000;
                syms[jb] |= 0b1000;
                has_simplex[1] = true;
            }
        }
        // The edges no triangle covers, in star order (coverage read from the flags above
        // rather than by sorting the triangles' edges: measured faster).
        for (j, &w) in verts.iter().enumerate() {
            let sym = syms[j];
            has_simplex[0] |= sym & 3 != 1;
            has_simplex[1] |= sym & 3 != 0;
            if sym & 3 != 1 && sym & 0b0100 == 0 {
                edges.push([v0, w]);
            }
            if sym & 3 != 0 && sym & 0b1000 == 0 {
                edges.push([v1, w]);
            }
        }
        // A cone triangle covers v0·v1; there is one only if the edge is there.
        if cone_edge {
            has_simplex = [true, true];
            if !tris.iter().any(|t| t.cone) {
                edges.push([v0, v1]);
            }
        }

        // Orientation: inherited triangles first (against their parent), then cones
        // (against a neighbour across v0·w or v1·w among the inherited ones).
        for t in tris.iter_mut() {
            if t.cone {
                continue;
            }
            let right = oracle.oriented(t.v);
            if io.bit(ORIENT_BASE + t.kind, !right) {
                t.v.swap(1, 2);
            }
        }
        for i in 0..tris.len() {
            if !tris[i].cone {
                continue;
            }
            let w = tris[i].v[2];
            let mut predicted = [v0, v1, w];
            let mut found = false;
            // The first inherited triangle with an edge v0·w or v1·w: the first with w as a
            // corner (each has one of v0 and v1, and its other corners are older than v1),
            // noted as they were made rather than searched for.
            if let Some(t) = tris.get(first[tris[i].at as usize] as usize) {
                let t = &t.v;
                if let Some(dir) = directed(t, v0, w) {
                    predicted = if dir { [v0, v1, w] } else { [v1, v0, w] };
                    found = true;
                } else if let Some(dir) = directed(t, v1, w) {
                    predicted = if dir { [v1, v0, w] } else { [v0, v1, w] };
                    found = true;
                }
            }
            let right = oracle.oriented(predicted);
            let flip = io.bit(ORIENT_BASE + 2 + found as usize, !right);
            tris[i].v = if flip { [predicted[1], predicted[0], predicted[2]] } else { predicted };
        }

        // Replace the old star by the new top-simplices. Star triangles stay where they are
        // (rewritten in place, listed again under v0 or v1); its edges and points go.
        for &t in old.iter().take(if lower > 0 { old.len() } else { 0 }) {
            let top = self.tops[t as usize];
            if top.dim == 2 {
                continue;
            }
            for &u in &top.v[..top.dim as usize + 1] {
                if u != v0 {
                    let list = &mut self.incident[u as usize];
                    if let Some(pos) = list.iter().position(|&x| x == t) {
                        list.swap_remove(pos);
                    }
                    self.cells[u as usize].degree = list.len().min(255) as u8;
                }
            }
            self.tops[t as usize].dim = DEAD;
            self.free.push(t);
            self.live_tops -= 1;
        }
        for t in tris.iter() {
            if t.reuse == NONE {
                self.add_top(Top { v: t.v, dim: 2 });
            } else {
                self.tops[t.reuse as usize].v = t.v;
                let has_v0 = (t.v[0] == v0) | (t.v[1] == v0) | (t.v[2] == v0);
                let owner = if has_v0 { v0 } else { v1 };
                self.link(owner, t.reuse);
            }
        }
        for e in edges.iter() {
            self.add_top(Top { v: [e[0], e[1], 0], dim: 1 });
        }
        for (k, &v) in [v0, v1].iter().enumerate() {
            if !has_simplex[k] {
                self.add_top(Top { v: [v, 0, 0], dim: 0 });
            }
        }
        let mut old = old;
        old.clear();
        self.scratch_old = old;
        self.scratch_first = first;
        self.restore(verts, opposite, syms, edges, tris);
        Ok(())
    }

    /// A fresh mark for [`Complex::split`], with room for every kd-cell.
    fn next_stamp(&mut self) -> u32 {
        if self.marks.len() < self.cells.len() {
            self.marks.resize(self.cells.len(), [0, 0]);
        }
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.marks.iter_mut().for_each(|m| m[0] = 0);
            self.stamp = 1;
        }
        self.stamp
    }

    /// Where `w` lies against the plane between `v0` and `v1` (the lower face of `v1`):
    /// 0 across it, 1 or 2 on `v0`'s side (adjacent to the plane within one cell of `v1`'s
    /// size along the axis, or farther), 3 or 4 on `v1`'s.
    #[inline(always)]
    fn side(&self, v1: u32, w: u32) -> usize {
        let (a, b) = (&self.cells[v1 as usize], &self.cells[w as usize]);
        let axis = ((a.level - 1) % 3) as usize;
        let (ua, ub) = (used(a.level, axis), used(b.level, axis));
        let u = ua.max(ub);
        let plane = (a.xyz[axis] as u64) << (u - ua);
        let size = 1u64 << (u - ua);
        let lo = (b.xyz[axis] as u64) << (u - ub);
        let hi = (b.xyz[axis] as u64 + 1) << (u - ub);
        if hi <= plane {
            1 + (plane - hi >= size) as usize
        } else if lo >= plane {
            3 + (lo - plane >= size) as usize
        } else {
            0
        }
    }

    fn restore(
        &mut self,
        verts: Vec<u32>,
        opposite: Vec<Opposite>,
        syms: Vec<u8>,
        edges: Vec<[u32; 2]>,
        tris: Vec<NewTri>,
    ) {
        self.scratch_verts = verts;
        self.scratch_opposite = opposite;
        self.scratch_syms = syms;
        self.scratch_edges = edges;
        self.scratch_tris = tris;
    }
}

/// The positions of the set bits of a bit set, ascending.
fn ones(bits: &[u64]) -> impl Iterator<Item = u32> + '_ {
    bits.iter().enumerate().flat_map(|(i, &w)| {
        let mut w = w;
        std::iter::from_fn(move || {
            (w != 0).then(|| {
                let b = w.trailing_zeros();
                w &= w - 1;
                i as u32 * 64 + b
            })
        })
    })
}

/// Whether triangle `t` holds the directed edge a→b (`Some(true)`), b→a (`Some(false)`), or
/// neither.
fn directed(t: &[u32; 3], a: u32, b: u32) -> Option<bool> {
    for k in 0..3 {
        let (x, y) = (t[k], t[(k + 1) % 3]);
        if x == a && y == b {
            return Some(true);
        }
        if x == b && y == a {
            return Some(false);
        }
    }
    None
}

/// Codes one symbol from the `allowed` set (bit `s` for symbol `s`) in at most two binary
/// decisions: the group ({0,1} or {2,3}), then the member; forced decisions cost nothing.
#[inline(always)]
fn code_symbol(io: &mut impl BitIo, dim: usize, allowed: u8, side: usize, truth: u8) -> u8 {
    let node = |n: usize| CONN_BASE + ((dim * 16 + allowed as usize) * 3 + n) * SIDES + side;
    let lo = allowed & 0b0011 != 0;
    let hi = allowed & 0b1100 != 0;
    let group = if lo && hi { io.bit(node(0), truth >= 2) } else { hi };
    let (a, b) = if group { (2u8, 3u8) } else { (0u8, 1u8) };
    let (has_a, has_b) = (allowed >> a & 1 != 0, allowed >> b & 1 != 0);
    if has_a && has_b {
        if io.bit(node(1 + group as usize), truth == b) {
            b
        } else {
            a
        }
    } else if has_a {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kd_cells_prefix_is_the_path_its_coordinates_were_read_from() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for level in 0..=3 * crate::MAX_BITS {
            for _ in 0..50 {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let prefix = (seed as u128 | (seed as u128) << 64) & ((1u128 << level) - 1);
                let cell = KdCell { xyz: xyz_of(prefix, level), level, degree: 0 };
                assert_eq!(cell.prefix(), prefix, "level {level}");
                assert_eq!(cell.index(), 1u128 << level | prefix);
            }
        }
    }

    #[test]
    fn ones_lists_the_set_bits_in_order() {
        let bits = [0b1001u64, 0, 1 << 63 | 1];
        assert_eq!(ones(&bits).collect::<Vec<_>>(), vec![0, 3, 128, 191]);
        assert_eq!(ones(&[]).count(), 0);
    }

    #[test]
    fn valence_buckets_follow_their_bounds() {
        let got: Vec<usize> = (0..14).map(valence_bucket).collect();
        assert_eq!(got, [0, 0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 3]);
        assert_eq!(valence_bucket(usize::MAX), 3);
    }
}
