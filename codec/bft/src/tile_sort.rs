//! Compression-domain tile sort: one BFT submesh per screen tile, in one pass over the
//! command stream.
//!
//! This work is based on: T. Mitra and T. Chiueh, "Compression-Domain Parallel Rendering",
//! section 3 (`shared/papers/bft-compression-domain-sort-first.txt`): vertex bounding boxes
//! (3.2), the modification rules of Table 2 with the `Add` command (3.1.4), and offsets
//! rewritten from counters of unclipped frontier entries (3.1.3).
//!
//! At load, the model's commands are resolved once against the model's frontier (which
//! slots and frontier positions each touches); that walk does not depend on the view.
//! Per frame:
//! 1. project every vertex slot (rayon), with its side of each frustum plane and its tile;
//! 2. pass 1: the pixel box of every triangle clipped to the frustum gives its tile box
//!    `[t]` (no clipping for triangles wholly inside); a vertex's box `[v]` is the union of
//!    its triangles' boxes, gathered per vertex in parallel;
//! 3. pass 2, all tiles in one traversal of the command stream, in chunks in parallel:
//!    each command is rewritten by [`rewrite`] (Table 2) for every tile in the boxes of its
//!    vertices and appended to the lists of the tiles where it does something. Then every
//!    tile, in parallel, follows its list with a `TileWriter`, which holds the state the
//!    ordinary decoder will have for the tile and codes each rewritten command. Offsets
//!    come from the paper's counters of unclipped entries, kept per tile as the model
//!    frontier position of each of the tile's entries.
//!
//! A tile's submesh then decodes, with the ordinary decoder, to exactly the triangles `t`
//! with the tile in `[t]`, orientation kept: a vertex is unclipped for tile `b` iff `b` is
//! in `[v]`, and a triangle is emitted iff `b` is in `[t]`, never merely because its three
//! vertices are unclipped.

use glam::Mat4;
use rayon::prelude::*;
use thiserror::Error;

use super::decode::{decode_ops, Decoded, Op};
use super::format::{BftError, Coding};
use super::frontier::Frontier;
use super::model::{RangeSink, SymbolSink};
use super::prefix::PrefixSink;
use super::tile_writer::TileWriter;
use crate::command::Command;
use crate::csr::Csr;
use crate::view::{triangle_tile_boxes_into, ClipVertex, TileBox, TileGrid};

/// Why a tile sort failed.
#[derive(Debug, Error)]
pub enum SortError {
    #[error(transparent)]
    Bft(#[from] BftError),
    #[error("the model's command stream holds {0:?}, which only tile streams may contain")]
    TileCommand(Command),
    #[error("the model's frontier takes {0} entries; the tile sort counts them in 32 bits")]
    TooLarge(usize),
}

/// A model ready for sorting: its decoded slots and triangles, float positions, and its
/// command stream. Loaded once; sorted every frame.
pub struct TileModel {
    pub decoded: Decoded,
    pub positions: Vec<[f32; 3]>,
    /// Each slot's triangles: pass 1 gathers a vertex's box from them, one vertex per task,
    /// instead of scattering every triangle's box into its vertices one triangle after the
    /// other.
    fans: Csr<u32>,
    /// The commands resolved against the model's frontier.
    steps: Vec<Step>,
    /// The first slot that only loose triangles use, and the first loose triangle.
    tail_start: u32,
    loose_start: usize,
}

impl TileModel {
    pub fn from_bytes(bytes: &[u8]) -> Result<TileModel, SortError> {
        let (decoded, ops) = decode_ops(bytes)?;
        let (steps, tail_start, loose_start) = resolve(&ops)?;
        let q = decoded.quantization();
        let positions: Vec<[f32; 3]> = decoded.positions.iter().map(|&p| q.dequantize(p)).collect();
        let fans = Csr::build(positions.len(), || {
            decoded.triangles.iter().enumerate().flat_map(|(t, tri)| tri.map(|s| (s, t as u32)))
        });
        Ok(TileModel { decoded, positions, fans, steps, tail_start, loose_start })
    }

    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.decoded.triangles
    }

    /// The bytes its tables take on the heap (what a cache of models counts).
    pub fn heap_bytes(&self) -> usize {
        use std::mem::size_of_val;
        let d = &self.decoded;
        size_of_val(&d.positions[..])
            + size_of_val(&d.triangles[..])
            + size_of_val(&d.duplicates[..])
            + size_of_val(&self.positions[..])
            + size_of_val(&self.fans.start[..])
            + size_of_val(&self.fans.values[..])
            + size_of_val(&self.steps[..])
    }
}

/// One non-empty tile of a sorted frame.
#[derive(Clone, Debug)]
pub struct Tile {
    /// `row * cols + col`.
    pub index: usize,
    /// The tile's submesh as a `.bft` stream.
    pub bytes: Vec<u8>,
    pub triangles: u32,
    /// The model slot of each of the tile's vertices, in the tile's slot order.
    pub slots: Vec<u32>,
}

/// Pass 1: the tile box of every triangle and every vertex slot.
#[derive(Default)]
pub struct Boxes {
    pub triangles: Vec<TileBox>,
    /// `[v]`: the union of the boxes of the slot's triangles.
    pub vertices: Vec<TileBox>,
    /// The projected slots, kept for the next frame's allocation.
    clip: Vec<ClipVertex>,
}

/// Projects the slots and computes `[t]` and `[v]`, all in parallel.
pub fn boxes(model: &TileModel, view_proj: Mat4, grid: &TileGrid) -> Boxes {
    let mut b = Boxes::default();
    boxes_into(model, view_proj, grid, &mut b);
    b
}

/// [`boxes`] into the buffers of an earlier frame's `Boxes`, which a frame loop keeps: fresh
/// buffers cost the dragon's sort a few milliseconds of page faults every frame.
pub fn boxes_into(model: &TileModel, view_proj: Mat4, grid: &TileGrid, out: &mut Boxes) {
    triangle_tile_boxes_into(
        &model.positions,
        &model.decoded.triangles,
        view_proj,
        grid,
        &mut out.clip,
        &mut out.triangles,
    );
    let triangles = &out.triangles;
    (0..model.positions.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|s| model.fans.get(s).iter().fold(TileBox::EMPTY, |u, &t| u.union(&triangles[t as usize])))
        .collect_into_vec(&mut out.vertices);
}

impl Boxes {
    /// Whether every triangle of `slot` is in tile `(c, r)` (a renderer of the tile sees
    /// the slot's whole fan). Most slots answer from their own box: one inside the frustum
    /// whose box is that one tile has all its triangles there (none of them can be culled).
    /// The rest look at their triangles' boxes, which pass 1 therefore does not intersect
    /// for every slot (that cost the dragon 2.7 ms a frame).
    pub fn whole_fan_in(&self, model: &TileModel, slot: u32, c: u16, r: u16) -> bool {
        let s = slot as usize;
        let b = &self.vertices[s];
        if self.clip[s].is_inside() && b.c0 == c && b.c1 == c && b.r0 == r && b.r1 == r {
            return true;
        }
        model.fans.get(s).iter().all(|&t| self.triangles[t as usize].contains(c, r))
    }
}

/// What a command becomes in one tile: Table 2 of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Rewrite {
    /// The input command itself (offsets rewritten).
    Same,
    Null,
    /// `ADD` of the third vertex (a new vertex, or one on the frontier).
    Add,
    /// `<Null, Add>`.
    NullAdd,
    Dl,
    Dr,
    /// No output.
    Nothing,
}

impl Rewrite {
    const ALL: [Rewrite; 7] =
        [Rewrite::Same, Rewrite::Null, Rewrite::Add, Rewrite::NullAdd, Rewrite::Dl, Rewrite::Dr, Rewrite::Nothing];

    /// The record code of pass 2: the variant's index, or [`SKIP`] for `Nothing`.
    #[inline]
    fn code(self) -> u32 {
        if self == Rewrite::Nothing {
            SKIP
        } else {
            self as u32
        }
    }

    #[inline]
    fn from_code(code: u32) -> Rewrite {
        Rewrite::ALL[code as usize]
    }
}

/// Table 2 (Mitra & Chiueh): the rewrite of input command `c` for a tile, given whether
/// the left, right and third vertices are unclipped for the tile (the tile is in their
/// vertex boxes) and whether the triangle is (the tile is in `[t]`).
///
/// ```text
/// c            tile                     v_l  v_r  v_x  t    c'
/// New/RF/LF    [t]                      NC   NC   NC   NC   New/RF/LF
/// New/RF/LF    ([v_l] ∩ [v_x]) − [t]    NC   X    NC   C    <Null, Add>
/// New/RF/LF    ([v_l] − [v_x]) − [t]    NC   X    C    C    Null
/// New/RF/LF    ([v_x] − [v_l]) − [t]    C    X    NC   C    Add
/// RF0          [t]                      NC   NC   NC   NC   RF0
/// RF0          ([v_r] ∩ [v_l]) − [t]    NC   NC   X    C    DR
/// RF0          ([v_r] − [v_l]) − [t]    C    NC   X    C    DL
/// DR           [v_r] ∩ [v_l]            NC   NC   -    -    DR
/// DR           [v_r] − [v_l]            C    NC   -    -    DL
/// LF0          [t]                      NC   NC   NC   NC   LF0
/// LF0          [v_l] − [t]              NC   X    X    C    DL
/// DL           [v_l]                    NC   X    -    -    DL
/// Null         [v_l]                    NC   X    -    -    Null
/// other combinations                                        (nothing)
/// ```
/// `SEED` (not in the paper) becomes `SEED` in `[t]`; elsewhere the tile's frontier is
/// cleared and each unclipped vertex of the seed added; see [`sort`].
#[inline]
pub fn rewrite(c: Command, l: bool, r: bool, x: bool, t: bool) -> Rewrite {
    use Rewrite::*;
    match c {
        Command::New | Command::Rf | Command::Lf => match (t, l, x) {
            (true, _, _) => Same,
            (false, true, true) => NullAdd,
            (false, true, false) => Null,
            (false, false, true) => Add,
            (false, false, false) => Nothing,
        },
        Command::Rf0 if t => Same,
        Command::Rf0 | Command::Dr => match (l, r) {
            (true, true) => Dr,
            (false, true) => Dl,
            _ => Nothing,
        },
        Command::Lf0 if t => Same,
        Command::Lf0 | Command::Dl => {
            if l {
                Dl
            } else {
                Nothing
            }
        }
        Command::Null => {
            if l {
                Null
            } else {
                Nothing
            }
        }
        Command::Seed | Command::AddNew | Command::AddRef | Command::Clear => Nothing,
    }
}

/// One model command resolved against the model's frontier. The model's frontier walk is
/// the same for every view, so it runs once, at load; each frame reads these instead.
#[derive(Clone, Copy, Debug)]
struct Step {
    cmd: Command,
    /// The current edge's slots (`r == l` when the frontier holds one entry).
    l: u32,
    r: u32,
    /// The third vertex (`NEW`, `RF<k>`, `LF<k>`), or the first of a `SEED`'s three.
    x: u32,
    /// The model frontier position of `x`'s entry (`RF<k>`, `LF<k>`).
    x_pos: u32,
    /// Model frontier pushes before this command: its own pushes (`l` then `x`, the `NULL`'s
    /// `l`, a seed's three) are at `push`, `push + 1`, ...
    push: u32,
    /// Its triangle's index, for commands that code one.
    tri: u32,
    /// `SEED`s up to and including this command.
    seeds: u32,
}

/// Resolves every command of the model against its frontier (see [`Step`]). Also returns
/// the first slot no command creates and the first triangle no command codes. `ops` are
/// those of a stream the decoder accepted, so every offset is within the frontier.
fn resolve(ops: &[Op]) -> Result<(Vec<Step>, u32, usize), SortError> {
    let mut f = Frontier::default();
    let (mut next_slot, mut tri, mut seeds, mut base) = (0u32, 0u32, 0u32, 0usize);
    let mut steps = Vec::with_capacity(ops.len());
    for op in ops {
        let push = (base + f.back_pos()) as u32;
        let mut st = Step { cmd: op.cmd, l: 0, r: 0, x: 0, x_pos: 0, push, tri, seeds };
        if !f.is_empty() {
            st.l = f.at(0).slot;
            st.r = if f.len() >= 2 { f.at(1).slot } else { st.l };
        }
        match op.cmd {
            Command::New | Command::Rf | Command::Lf => {
                let (len, k) = (f.len(), op.offset as usize);
                let i = match op.cmd {
                    Command::New => {
                        next_slot += 1;
                        st.x = next_slot - 1;
                        usize::MAX
                    }
                    Command::Rf => 2 + k,
                    _ => len - 1 - k,
                };
                if i != usize::MAX {
                    st.x = f.at(i).slot;
                    st.x_pos = (base + f.head + i) as u32;
                }
                tri += 1;
                f.insert(st.x);
            }
            Command::Rf0 => {
                tri += 1;
                f.remove_right(true)
            }
            Command::Lf0 => {
                tri += 1;
                f.remove_left(true)
            }
            Command::Dr => f.remove_right(false),
            Command::Dl => f.remove_left(false),
            Command::Null => f.skip(),
            Command::Seed => {
                st.x = next_slot;
                next_slot += 3;
                tri += 1;
                seeds += 1;
                st.seeds = seeds;
                f.seed(st.x);
            }
            Command::AddNew | Command::AddRef | Command::Clear => return Err(SortError::TileCommand(op.cmd)),
        }
        steps.push(st);
        base += f.compact();
    }
    if base + f.back_pos() >= u32::MAX as usize {
        return Err(SortError::TooLarge(base + f.back_pos()));
    }
    Ok((steps, next_slot, tri as usize))
}

/// Sorts the model into tiles for one view. Returns the non-empty tiles, by index.
pub fn sort(model: &TileModel, view_proj: Mat4, grid: &TileGrid) -> Result<Vec<Tile>, SortError> {
    let bx = boxes(model, view_proj, grid);
    sort_with_boxes(model, &bx, grid)
}

/// Pass 2 of [`sort`], given pass 1's boxes. A one-off [`Sorter`]; a frame loop should
/// keep one `Sorter` and call [`Sorter::sort`], which reuses its buffers.
pub fn sort_with_boxes(model: &TileModel, bx: &Boxes, grid: &TileGrid) -> Result<Vec<Tile>, SortError> {
    Sorter::default().sort(model, bx, grid)
}

/// A tile's share of one command: what the tile's writer needs of it, copied out of the
/// command's [`Step`] by the bucketing step, which reads the steps in order, so that the
/// writer reads only its own list and never the steps scattered through the stream.
#[derive(Clone, Copy, Debug)]
struct Record {
    /// `NEW`, `SEED`: the (first) new slot; `RF<k>`, `LF<k>`: `x_pos`; a tail vertex: its
    /// slot; a loose triangle: its index.
    a: u32,
    push: u32,
    seeds: u32,
    /// A [`Command`], or [`TAIL`] or [`LOOSE`].
    cmd: u8,
    /// What the tile does: a [`Rewrite`] code, or for `SEED` bit 0 = the tile is in `[t]`
    /// and bits 1..3 = which of the three vertices are unclipped.
    code: u8,
}

const TAIL: u8 = 254;
const LOOSE: u8 = 255;
/// What `bucket` returns for a tile where a command does nothing.
const SKIP: u32 = u32::MAX;

/// Pass 2's working memory, kept from frame to frame so that a frame loop does not pay for
/// fresh pages every frame.
#[derive(Default)]
pub struct Sorter {
    /// Per chunk of the command stream, per tile, that tile's records in stream order.
    chunks: Vec<Vec<Vec<Record>>>,
    /// How the tiles' streams are entropy-coded.
    pub coding: Coding,
}

impl Sorter {
    /// A sorter whose tiles are coded as `coding`.
    pub fn new(coding: Coding) -> Sorter {
        Sorter { chunks: Vec::new(), coding }
    }

    /// Pass 2, in two parallel steps that never replay the model's frontier (its walk was
    /// resolved at load):
    /// 1. bucket: chunks of the command stream in parallel, each command rewritten by
    ///    Table 2 for every tile of its vertices' boxes, and a record appended to the lists
    ///    of the tiles where it does something;
    /// 2. write: the tiles in parallel, each following its records in stream order with its
    ///    own `TileWriter`, frontier positions and entropy coders.
    ///
    /// No tile waits on another and no thread repeats another's work, so pass 2 scales with
    /// cores, heaviest tiles first.
    pub fn sort(&mut self, model: &TileModel, bx: &Boxes, grid: &TileGrid) -> Result<Vec<Tile>, SortError> {
        self.sort_tiles(model, bx, grid, None)
    }

    /// [`Sorter::sort`] of the tiles `only` marks (indexed by tile), or of every tile for
    /// `None`: each tile's stream is the same as in a sort of them all.
    pub fn sort_tiles(
        &mut self,
        model: &TileModel,
        bx: &Boxes,
        grid: &TileGrid,
        only: Option<&[bool]>,
    ) -> Result<Vec<Tile>, SortError> {
        let tiles = grid.tiles();
        let n_ops = model.steps.len();
        let n_slots = model.positions.len();
        let n_items = n_ops + (n_slots - model.tail_start as usize) + (model.triangles().len() - model.loose_start);
        let n_chunks = (rayon::current_num_threads() * 4).clamp(1, n_items.div_ceil(4096).max(1));
        self.chunks.resize_with(n_chunks, Vec::new);
        let per = n_items.div_ceil(n_chunks);
        self.chunks.par_iter_mut().enumerate().for_each(|(k, lists)| {
            lists.resize_with(tiles, Vec::new);
            lists.iter_mut().for_each(Vec::clear);
            bucket(model, bx, grid, k * per..((k + 1) * per).min(n_items), only, lists);
        });
        let (chunks, coding) = (&self.chunks, self.coding);
        let mut busy: Vec<(usize, usize)> =
            (0..tiles).map(|b| (b, chunks.iter().map(|c| c[b].len()).sum::<usize>())).filter(|&(_, n)| n > 0).collect();
        busy.sort_by_key(|&(_, n)| std::cmp::Reverse(n));
        let mut out: Vec<Tile> = busy
            .par_iter()
            .with_max_len(1)
            .filter_map(|&(b, n)| {
                let lists = chunks.iter().map(|c| c[b].as_slice());
                match coding {
                    Coding::Range => write_tile::<RangeSink>(model, lists, n, b, coding),
                    Coding::PrefixByDegree => write_tile::<PrefixSink<true>>(model, lists, n, b, coding),
                    Coding::Prefix => write_tile::<PrefixSink>(model, lists, n, b, coding),
                }
            })
            .collect();
        out.sort_by_key(|t| t.index);
        Ok(out)
    }
}

/// Step 1 of pass 2 for the items `range`: appends each tile's records to `lists`.
fn bucket(
    model: &TileModel,
    bx: &Boxes,
    grid: &TileGrid,
    range: std::ops::Range<usize>,
    only: Option<&[bool]>,
    lists: &mut [Vec<Record>],
) {
    match only {
        None => bucket_in(model, bx, grid, range, |_| true, lists),
        Some(only) => bucket_in(model, bx, grid, range, |b| only[b], lists),
    }
}

/// [`bucket`] for the tiles `wanted` takes (generic, so that sorting every tile tests
/// nothing).
fn bucket_in(
    model: &TileModel,
    bx: &Boxes,
    grid: &TileGrid,
    range: std::ops::Range<usize>,
    wanted: impl Fn(usize) -> bool + Copy,
    lists: &mut [Vec<Record>],
) {
    let cols = grid.cols as usize;
    let n_ops = model.steps.len();
    let n_tail = model.positions.len() - model.tail_start as usize;
    // Generic, not `dyn`, so that each command's rewrite inlines into its loop.
    #[inline(always)]
    fn put(
        lists: &mut [Vec<Record>],
        cols: usize,
        wanted: impl Fn(usize) -> bool,
        rect: TileBox,
        rec: Record,
        code: impl Fn(u16, u16) -> u32,
    ) {
        if rect.is_empty() {
            return;
        }
        for r in rect.r0..=rect.r1 {
            for c in rect.c0..=rect.c1 {
                let b = r as usize * cols + c as usize;
                if !wanted(b) {
                    continue;
                }
                let code = code(c, r);
                if code != SKIP {
                    lists[b].push(Record { code: code as u8, ..rec });
                }
            }
        }
    }
    for i in range {
        if i >= n_ops {
            // After the commands: vertices only loose triangles use, then the loose triangles.
            let (rect, rec) = if i < n_ops + n_tail {
                let s = model.tail_start as usize + i - n_ops;
                (bx.vertices[s], Record { a: s as u32, push: 0, seeds: 0, cmd: TAIL, code: 0 })
            } else {
                let t = model.loose_start + i - n_ops - n_tail;
                (bx.triangles[t], Record { a: t as u32, push: 0, seeds: 0, cmd: LOOSE, code: 0 })
            };
            put(lists, cols, wanted, rect, rec, |_, _| Rewrite::Same.code());
            continue;
        }
        let st = &model.steps[i];
        let (vl, vr) = (&bx.vertices[st.l as usize], &bx.vertices[st.r as usize]);
        let a = if matches!(st.cmd, Command::Rf | Command::Lf) { st.x_pos } else { st.x };
        let rec = Record { a, push: st.push, seeds: st.seeds, cmd: st.cmd as u8, code: 0 };
        match st.cmd {
            Command::New | Command::Rf | Command::Lf => {
                let (vx, bt) = (&bx.vertices[st.x as usize], &bx.triangles[st.tri as usize]);
                put(lists, cols, wanted, vl.union(vx), rec, |c, r| {
                    rewrite(st.cmd, vl.contains(c, r), vr.contains(c, r), vx.contains(c, r), bt.contains(c, r)).code()
                });
            }
            Command::Rf0 | Command::Lf0 | Command::Dr | Command::Dl | Command::Null => {
                let bt = if matches!(st.cmd, Command::Rf0 | Command::Lf0) {
                    bx.triangles[st.tri as usize]
                } else {
                    TileBox::EMPTY
                };
                let rect = if matches!(st.cmd, Command::Rf0 | Command::Dr) { vl.union(vr) } else { *vl };
                put(lists, cols, wanted, rect, rec, |c, r| {
                    rewrite(st.cmd, vl.contains(c, r), vr.contains(c, r), false, bt.contains(c, r)).code()
                });
            }
            Command::Seed => {
                let bt = &bx.triangles[st.tri as usize];
                let v = [0, 1, 2].map(|j| &bx.vertices[(st.x + j) as usize]);
                put(lists, cols, wanted, v[0].union(v[1]).union(v[2]), rec, |c, r| {
                    let inside = v.map(|v| v.contains(c, r) as u32);
                    if bt.contains(c, r) {
                        1
                    } else {
                        inside[0] << 1 | inside[1] << 2 | inside[2] << 3
                    }
                });
            }
            Command::AddNew | Command::AddRef | Command::Clear => unreachable!("resolve rejects tile commands"),
        }
    }
}

/// Step 2 of pass 2: tile `index`'s stream from its records, or `None` if it has no
/// triangle.
fn write_tile<'a, S: SymbolSink>(
    model: &TileModel,
    lists: impl Iterator<Item = &'a [Record]>,
    records: usize,
    index: usize,
    coding: Coding,
) -> Option<Tile> {
    let d = &model.decoded;
    let q = &d.positions;
    let mut w = TileWriter::<S>::new(d.header.quant_bits, records, !d.attributes.is_empty());
    // The model frontier position of each of this tile's frontier entries, by the tile's
    // position: both queues grow in the same order, so this is sorted, and an entry of the
    // model is found in the tile by binary search. These are the paper's counters of
    // unclipped entries, kept as the positions themselves.
    let mut pos: Vec<u32> = Vec::with_capacity(records * 2);
    let find = |w: &TileWriter<S>, pos: &[u32], x_pos: u32| {
        let i = pos[w.f.head..].partition_point(|&p| p < x_pos);
        debug_assert_eq!(pos[w.f.head + i], x_pos, "the tile holds the entry");
        i
    };
    const NEW: u8 = Command::New as u8;
    const RF: u8 = Command::Rf as u8;
    const LF: u8 = Command::Lf as u8;
    const RF0: u8 = Command::Rf0 as u8;
    const SEED: u8 = Command::Seed as u8;
    let mut seen_seeds = 0;
    for &rec in lists.flatten() {
        let (x, push, code) = (rec.a, rec.push, rec.code);
        match rec.cmd {
            TAIL => {
                w.tail_vertex(x, q[x as usize]);
                continue;
            }
            LOOSE => {
                w.loose(d.triangles[x as usize]);
                continue;
            }
            _ => {}
        }
        // A `SEED` of the model clears its frontier: this tile's too, before its next command.
        if rec.seeds - (rec.cmd == SEED) as u32 > seen_seeds && !w.f.is_empty() {
            w.clear();
        }
        seen_seeds = rec.seeds;
        match rec.cmd {
            NEW | RF | LF => {
                let rw = Rewrite::from_code(code as u32);
                if rw == Rewrite::Same {
                    if rec.cmd == NEW {
                        w.new_vertex(x, q[x as usize]);
                    } else {
                        let k = find(&w, &pos, x);
                        w.existing(k);
                    }
                    pos.extend([push, push + 1]);
                    continue;
                }
                if matches!(rw, Rewrite::Null | Rewrite::NullAdd) {
                    w.null();
                    pos.push(push);
                }
                if matches!(rw, Rewrite::Add | Rewrite::NullAdd) {
                    if rec.cmd == NEW {
                        w.add_new(x, q[x as usize]);
                    } else {
                        let k = find(&w, &pos, x);
                        w.add_ref(k);
                    }
                    pos.push(push + 1);
                }
            }
            SEED => {
                if code & 1 != 0 {
                    w.seed([x, x + 1, x + 2], [q[x as usize], q[x as usize + 1], q[x as usize + 2]]);
                    pos.extend([push, push + 1, push + 2]);
                } else {
                    if !w.f.is_empty() {
                        w.clear();
                    }
                    for j in 0..3 {
                        if code & (2 << j) != 0 {
                            w.add_new(x + j, q[(x + j) as usize]);
                            pos.push(push + j);
                        }
                    }
                }
            }
            // RF0, LF0, DR, DL, NULL.
            _ => match Rewrite::from_code(code as u32) {
                Rewrite::Same if rec.cmd == RF0 => w.rf0(),
                Rewrite::Same => w.lf0(),
                Rewrite::Dr => w.dr(),
                Rewrite::Dl => w.dl(),
                Rewrite::Null => {
                    w.null();
                    pos.push(push);
                }
                _ => {}
            },
        }
        debug_assert_eq!(pos.len(), w.f.back_pos());
    }
    (w.triangles > 0).then(|| {
        let triangles = w.triangles;
        let (bytes, slots) = w.finish(&d.header, &d.attributes, coding);
        Tile { index, bytes, triangles, slots }
    })
}
