//! Building an `.nsp` (NSP.md 1.3 to 1.7): partition, one recorded decision sequence per
//! cell, static probability tables from all of them, then each cell range-coded alone.
//!
//! Each cell is encoded from its own simplices, independently of the others (in parallel):
//! its starting state is the clustering of its simplices at its minimal precision, which is
//! what a decoder derives from the parent's final state. The encoder runs the decoder's own
//! state machine ([`Complex::refine_level`]) and answers its questions from the truth, the
//! clustering of the cell's simplices at the current (mixed) precision.

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};

use rayon::prelude::*;

use super::canonical::{top_simplices, Canonical, Simplex};
use super::complex::{BitIo, Complex, Oracle, Silent, CONTEXTS};
use super::error::NspError;
use super::format::{self, CellEntry, Header};
use super::params::{morton, Params};
use super::tree::{partition_capped, Tree};
use crate::rangecoder::Encoder;

/// An encoded model and what it is made of.
pub struct Built {
    pub bytes: Vec<u8>,
    pub tree: Tree,
    pub header: Header,
    /// Recorded binary decisions by kind: geometry, connectivity, orientation.
    pub decisions: [u64; 3],
    /// Their cost in bits under the static tables (the streams' size before range-coder
    /// overhead), by kind.
    pub cost_bits: [f64; 3],
    /// Bytes of cell streams (all cells).
    pub stream_bytes: u64,
    /// Sum over the leaves of the simplices each holds (duplicates across cells counted).
    pub leaf_simplices: u64,
}

/// One cell's recorded decisions: context in the low 15 bits, the bit in the top one.
pub(super) struct Recorded {
    pub bits: Vec<u16>,
    /// Decisions recorded by the end of each bit of precision (every third kd level).
    pub level_ends: Vec<u32>,
    pub max_cells: u32,
    pub max_tops: u32,
    pub reach: [[u32; 3]; 2],
}

impl Recorded {
    pub(super) fn empty() -> Recorded {
        Recorded { bits: Vec::new(), level_ends: Vec::new(), max_cells: 0, max_tops: 0, reach: [[u32::MAX; 3], [0; 3]] }
    }
}

struct Record<'a>(&'a mut Vec<u16>);

impl BitIo for Record<'_> {
    #[inline]
    fn bit(&mut self, ctx: usize, value: bool) -> bool {
        self.0.push(ctx as u16 | (value as u16) << 15);
        value
    }
}

/// Encodes a canonical complex. `progress` is called with the number of cells done.
pub fn encode(canon: &Canonical, params: Params, progress: &(dyn Fn(u64) + Sync)) -> Result<Built, NspError> {
    params.validate()?;
    if canon.cube.bits != params.bits {
        return Err(NspError::Params(format!(
            "the complex is quantized to {} bits, the parameters ask for {}",
            canon.cube.bits, params.bits
        )));
    }
    if canon.points.is_empty() {
        return Err(NspError::Empty);
    }
    let part = partition_capped(params, &canon.points, &canon.simplices)?;
    let tree = &part.tree;
    let done = std::sync::atomic::AtomicU64::new(0);
    let recorded: Vec<Recorded> = (0..tree.nodes.len() as u32)
        .into_par_iter()
        .map(|c| {
            let r = record_cell(tree, c, &part.members[c as usize], canon);
            progress(done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1);
            r
        })
        .collect();
    let mut counts = vec![[0u64; 2]; CONTEXTS];
    let mut decisions = [0u64; 3];
    for r in &recorded {
        for &b in &r.bits {
            let ctx = (b & 0x7fff) as usize;
            counts[ctx][(b >> 15) as usize] += 1;
            decisions[kind_of(ctx)] += 1;
        }
    }
    let table: Vec<u16> = counts.iter().map(|c| static_prob(c[0], c[1])).collect();
    let mut cost_bits = [0f64; 3];
    for (ctx, c) in counts.iter().enumerate() {
        let p0 = table[ctx] as f64 / 2048.0;
        cost_bits[kind_of(ctx)] -= c[0] as f64 * p0.log2() + c[1] as f64 * (1.0 - p0).log2();
    }
    let streams: Vec<Vec<u8>> = recorded.par_iter().map(|r| code_cell(&r.bits, &table)).collect();
    let entries: Vec<CellEntry> = streams
        .par_iter()
        .zip(&recorded)
        .enumerate()
        .map(|(c, (s, r))| {
            let (ends, segment_crcs) = segments(&r.bits, &r.level_ends, &table, s);
            CellEntry {
                split: !tree.is_leaf(c as u32),
                offset: 0,
                len: s.len() as u32,
                crc: crc32fast::hash(s),
                max_cells: r.max_cells,
                max_tops: r.max_tops,
                reach: r.reach,
                ends,
                segment_crcs,
            }
        })
        .collect();
    let leaf_simplices =
        (0..tree.nodes.len()).filter(|&c| tree.is_leaf(c as u32)).map(|c| part.members[c].len() as u64).sum();
    let mut header = Header::new(params, canon);
    header.leaf_simplices = leaf_simplices;
    let stream_bytes = streams.iter().map(|s| s.len() as u64).sum();
    let bytes = format::write(&header, &table, &streams, &entries);
    Ok(Built { bytes, tree: part.tree, header, decisions, cost_bits, stream_bytes, leaf_simplices })
}

pub(super) fn kind_of(ctx: usize) -> usize {
    use super::complex::GEOMETRY_CONTEXTS;
    if ctx < GEOMETRY_CONTEXTS {
        0
    } else if ctx < CONTEXTS - 4 {
        1
    } else {
        2
    }
}

/// The static probability of a 0 (11 bits, never 0 or 1) from the counts of 0s and 1s.
pub(super) fn static_prob(zeros: u64, ones: u64) -> u16 {
    let p = (zeros as f64 + 0.5) / ((zeros + ones) as f64 + 1.0);
    ((p * 2048.0).round() as i64).clamp(1, 2047) as u16
}

/// The end of each precision's bytes in a coded cell (decode its decisions, noting where
/// the decoder stands at each precision's last one), and each segment's CRC-32.
pub(super) fn segments(bits: &[u16], level_ends: &[u32], table: &[u16], stream: &[u8]) -> (Vec<u32>, Vec<u32>) {
    if stream.is_empty() {
        return (Vec::new(), Vec::new());
    }
    let mut dec = crate::rangecoder::Decoder::new(stream);
    let mut ends = Vec::with_capacity(level_ends.len());
    let mut done = 0usize;
    for &end in level_ends {
        while done < end as usize {
            let mut p = table[(bits[done] & 0x7fff) as usize];
            dec.bit(&mut p);
            done += 1;
        }
        ends.push(dec.position().min(stream.len()) as u32);
    }
    if let Some(last) = ends.last_mut() {
        *last = stream.len() as u32;
    }
    let mut crcs = Vec::with_capacity(ends.len());
    let mut start = 0;
    for &end in &ends {
        crcs.push(crc32fast::hash(&stream[start as usize..end as usize]));
        start = end;
    }
    (ends, crcs)
}

pub(super) fn code_cell(bits: &[u16], table: &[u16]) -> Vec<u8> {
    if bits.is_empty() {
        return Vec::new();
    }
    let mut enc = Encoder::new();
    for &b in bits {
        let mut p = table[(b & 0x7fff) as usize];
        enc.bit(&mut p, b >> 15 != 0);
    }
    enc.finish()
}

/// Runs cell `c`'s refinement from its minimal to its maximal precision on its simplices
/// (ids into `canon.simplices`, ascending), recording every decision.
fn record_cell(tree: &Tree, c: u32, members: &[u32], canon: &Canonical) -> Recorded {
    let shift = tree.params.bits - tree.max_prec(c);
    let corners = members.iter().map(|&s| {
        let t = canon.simplices[s as usize];
        let mut q = [[0u32; 3]; 3];
        for (corner, &v) in q.iter_mut().zip(t.verts()) {
            *corner = canon.points[v as usize];
        }
        (t.dim, q)
    });
    record_local(tree, c, corners, shift, None)
}

/// Records cell `c`'s decisions from its simplices, each given by its dimension and corners
/// on a grid `shift` bits finer than the cell's maximal precision `q`, in input order
/// (triangles by first occurrence first). The reach is the box of the corners as given.
/// With the geometry advance the cell's points at `min(q + m, p)` bits are `fine` (distinct,
/// ascending), or when `None` the corners, which must then be at least that fine.
pub(super) fn record_local(
    tree: &Tree,
    c: u32,
    simplices: impl Iterator<Item = (u8, [[u32; 3]; 3])>,
    shift: u8,
    fine_points: Option<&[[u32; 3]]>,
) -> Recorded {
    // The cell's points at its maximal precision, and its simplices on them.
    let mut reach = [[u32::MAX; 3], [0u32; 3]];
    let mut local: HashMap<[u32; 3], u32> = HashMap::default();
    let mut coords: Vec<[u32; 3]> = Vec::new();
    // With the advance: the cell's points on the grid geometry runs to, min(q + m, p) bits.
    let q = tree.max_prec(c);
    let fine_bits = (q + tree.params.advance).min(tree.params.bits);
    let from_corners = tree.params.advance > 0 && fine_points.is_none();
    let fine_shift = if from_corners { shift - (fine_bits - q) } else { 0 };
    let mut fine: Vec<u128> = fine_points.unwrap_or(&[]).iter().map(|&g| morton(g, fine_bits)).collect();
    let mapped: Vec<Simplex> = simplices
        .map(|(dim, corners)| {
            let mut t = Simplex { v: [0; 3], dim };
            for (k, g) in corners[..dim as usize + 1].iter().enumerate() {
                for a in 0..3 {
                    reach[0][a] = reach[0][a].min(g[a]);
                    reach[1][a] = reach[1][a].max(g[a]);
                }
                if from_corners {
                    fine.push(morton([g[0] >> fine_shift, g[1] >> fine_shift, g[2] >> fine_shift], fine_bits));
                }
                let g = [g[0] >> shift, g[1] >> shift, g[2] >> shift];
                t.v[k] = *local.entry(g).or_insert_with(|| {
                    coords.push(g);
                    coords.len() as u32 - 1
                });
            }
            t
        })
        .collect();
    if mapped.is_empty() {
        return Recorded::empty();
    }
    let mut bits = Vec::new();
    let simplices = top_simplices(coords.len(), mapped.into_iter());
    let codes: Vec<u128> = coords.iter().map(|&g| morton(g, q)).collect();
    let l0 = 3 * tree.min_prec(c);
    let top = 3 * q;
    let prefixes: Vec<u128> = codes.iter().map(|&m| if top == l0 { m } else { m >> (top - l0) }).collect();
    let (mut cx, pcell) = Complex::cluster(l0, &prefixes, &simplices);
    let mut oracle = Truth::new(codes, q, pcell, &simplices, cx.cells.len());
    if tree.params.advance > 0 {
        fine.sort_unstable();
        fine.dedup();
        oracle.fine = fine;
        oracle.fine_levels = 3 * fine_bits;
        cx.enable_ahead(3 * tree.params.advance, super::decode::ahead_top(tree, c));
        // The prologue codes the descendants the decoder cannot inherit; the others it
        // inherits from the parent, which saw them exactly as this cell does.
        let fresh = super::decode::fresh_cells(tree, c, &cx);
        for v in 0..cx.cells.len() as u32 {
            if fresh.binary_search(&v).is_ok() {
                cx.grow_fresh(v, &mut Record(&mut bits), &mut oracle);
            } else {
                cx.grow_fresh(v, &mut Silent, &mut oracle);
            }
        }
    }
    let mut max_cells = cx.cells.len();
    let mut max_tops = cx.live_tops();
    let mut level_ends = Vec::with_capacity((top - l0) as usize / 3);
    for level in l0..top {
        cx.refine_level(&mut Record(&mut bits), &mut oracle, usize::MAX, usize::MAX)
            .expect("the encoder's own answers are always consistent");
        max_cells = max_cells.max(cx.cells.len());
        max_tops = max_tops.max(cx.peak_tops);
        if (level + 1 - l0).is_multiple_of(3) {
            level_ends.push(bits.len() as u32);
        }
    }
    Recorded { bits, level_ends, max_cells: max_cells as u32, max_tops: max_tops as u32, reach }
}

/// The encoder's knowledge: which points each kd-cell holds, and after each split, the
/// closure of the star of `v0` and `v1` in the clustering of the cell's simplices.
struct Truth<'a> {
    codes: Vec<u128>,
    q: u8,
    level: u8,
    pcell: Vec<u32>,
    points_of: Vec<Vec<u32>>,
    simplices: &'a [Simplex],
    /// Point → simplices (CSR).
    inc_start: Vec<u32>,
    inc: Vec<u32>,
    mark: Vec<u32>,
    epoch: u32,
    star: HashSet<[u32; 4]>,
    orient: HashMap<[u32; 3], (u32, [u32; 3])>,
    /// With the advance: the Morton codes of the cell's points at `fine_levels / 3` bits,
    /// ascending and distinct.
    fine: Vec<u128>,
    fine_levels: u8,
    /// Where the last occupancy question's range started in `fine`.
    cursor: usize,
}

/// The first index at or after `from` whose value is at least `key` (`v` ascending, every
/// value before `from` below `key`), by doubling steps then a binary search: a walk in kd
/// order over `v` costs the log of each step, not of `v`'s length.
fn gallop(v: &[u128], from: usize, key: u128) -> usize {
    let mut lo = from;
    let mut step = 1;
    let mut hi = from;
    while hi < v.len() && v[hi] < key {
        lo = hi + 1;
        hi = from + step;
        step *= 2;
    }
    let hi = hi.min(v.len());
    lo + v[lo..hi].partition_point(|&x| x < key)
}

impl<'a> Truth<'a> {
    fn new(codes: Vec<u128>, q: u8, pcell: Vec<u32>, simplices: &'a [Simplex], cells: usize) -> Self {
        let mut points_of = vec![Vec::new(); cells];
        for (i, &c) in pcell.iter().enumerate() {
            points_of[c as usize].push(i as u32);
        }
        let mut inc_start = vec![0u32; codes.len() + 1];
        for s in simplices {
            for &v in s.verts() {
                inc_start[v as usize + 1] += 1;
            }
        }
        for i in 0..codes.len() {
            inc_start[i + 1] += inc_start[i];
        }
        let mut fill = inc_start.clone();
        let mut inc = vec![0u32; inc_start[codes.len()] as usize];
        for (si, s) in simplices.iter().enumerate() {
            for &v in s.verts() {
                inc[fill[v as usize] as usize] = si as u32;
                fill[v as usize] += 1;
            }
        }
        Truth {
            codes,
            q,
            level: 0,
            pcell,
            points_of,
            simplices,
            inc_start,
            inc,
            mark: vec![u32::MAX; simplices.len()],
            epoch: 0,
            star: HashSet::default(),
            orient: HashMap::default(),
            fine: Vec::new(),
            fine_levels: 0,
            cursor: 0,
        }
    }

    #[inline]
    fn bit_at(&self, point: u32, level: u8) -> bool {
        (self.codes[point as usize] >> (3 * self.q as u32 - 1 - level as u32)) & 1 != 0
    }
}

fn star_key(mut v: [u32; 3], dim: u8) -> [u32; 4] {
    v[..dim as usize + 1].sort_unstable();
    for x in &mut v[dim as usize + 1..] {
        *x = u32::MAX;
    }
    [v[0], v[1], v[2], dim as u32]
}

impl Oracle for Truth<'_> {
    fn geometry(&mut self, cell: u32, level: u8) -> (bool, bool) {
        self.level = level;
        let pts = &self.points_of[cell as usize];
        let ones = pts.iter().filter(|&&p| self.bit_at(p, level)).count();
        (ones > 0 && ones < pts.len(), ones == pts.len())
    }

    fn before_split(&mut self, v0: u32, v1: u32) {
        let level = self.level;
        let pts = std::mem::take(&mut self.points_of[v0 as usize]);
        let (ones, zeros): (Vec<u32>, Vec<u32>) = pts.into_iter().partition(|&p| self.bit_at(p, level));
        for &p in &ones {
            self.pcell[p as usize] = v1;
        }
        if self.points_of.len() <= v1 as usize {
            self.points_of.resize(v1 as usize + 1, Vec::new());
        }
        self.points_of[v0 as usize] = zeros;
        self.points_of[v1 as usize] = ones;
        // The truth: images of every simplex incident to a point of v0 or v1.
        self.epoch += 1;
        self.star.clear();
        self.orient.clear();
        for &cell in &[v0, v1] {
            for &pt in &self.points_of[cell as usize] {
                for &si in &self.inc[self.inc_start[pt as usize] as usize..self.inc_start[pt as usize + 1] as usize] {
                    if self.mark[si as usize] == self.epoch {
                        continue;
                    }
                    self.mark[si as usize] = self.epoch;
                    let s = self.simplices[si as usize];
                    let mut img = s;
                    for k in 0..=s.dim as usize {
                        img.v[k] = self.pcell[s.v[k] as usize];
                    }
                    let img = super::canonical::reduce(img);
                    let n = img.dim as usize + 1;
                    for mask in 1u32..(1 << n) {
                        let mut sub = [u32::MAX; 3];
                        let mut k = 0;
                        let mut hit = false;
                        for (j, &x) in img.v[..n].iter().enumerate() {
                            if mask >> j & 1 != 0 {
                                sub[k] = x;
                                k += 1;
                                hit |= x == v0 || x == v1;
                            }
                        }
                        if hit {
                            self.star.insert(star_key(sub, k as u8 - 1));
                        }
                    }
                    if img.dim == 2 {
                        let key = img.key();
                        let e = self.orient.entry(key).or_insert((si, img.v));
                        if si < e.0 {
                            *e = (si, img.v);
                        }
                    }
                }
            }
        }
    }

    fn symbol(&mut self, v0: u32, v1: u32, tau: &[u32]) -> u8 {
        let has = |extra: &[u32]| {
            let mut v = [u32::MAX; 3];
            let n = extra.len() + tau.len();
            v[..extra.len()].copy_from_slice(extra);
            v[extra.len()..n].copy_from_slice(tau);
            self.star.contains(&star_key(v, n as u8 - 1))
        };
        let a = has(&[v0]);
        let b = has(&[v1]);
        let cone = tau.len() < 2 && has(&[v0, v1]);
        match (a, b, cone) {
            (true, false, _) => 0,
            (false, true, _) => 1,
            (_, _, false) => 2,
            _ => 3,
        }
    }

    fn occupancy(&mut self, prefix: u128, level: u8) -> (bool, bool) {
        let free = (self.fine_levels - level) as u32;
        let lo = prefix << free;
        let mid = (2 * prefix + 1) << (free - 1);
        let hi = (prefix + 1) << free;
        // Within a level the questions come in kd order: search onward from the last answer
        // (galloping), from the start when the order restarts.
        let from =
            if self.cursor > 0 && self.fine.get(self.cursor - 1).is_some_and(|&x| x >= lo) { 0 } else { self.cursor };
        let a = gallop(&self.fine, from, lo);
        let b = gallop(&self.fine, a, mid);
        self.cursor = a;
        let has0 = b > a;
        let has1 = self.fine.get(b).is_some_and(|&x| x < hi);
        (has0 && has1, !has0)
    }

    fn oriented(&mut self, t: [u32; 3]) -> bool {
        let mut key = t;
        key.sort_unstable();
        let truth = self.orient[&key].1;
        (0..3).any(|r| [truth[r], truth[(r + 1) % 3], truth[(r + 2) % 3]] == t)
    }
}
