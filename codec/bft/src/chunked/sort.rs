//! The per-frame sort of a chunked model: every chunk classified from the directory alone,
//! and only the chunks that straddle a tile border or a frustum plane tile-sorted.
//!
//! - **Culled**: all eight corners of the chunk's box are outside one frustum plane, so
//!   every triangle is (no tile holds it); its bytes are not read.
//! - **Verbatim**: the box is inside every plane and its pixel rectangle inside one tile,
//!   so every triangle's box `[t]` is that tile: the chunk's stream is the tile's piece as
//!   it is, never decoded.
//! - **Straddling**: anything else goes through pass 1 and Table 2 (`tile_sort`), on a
//!   `TileModel` built from the chunk on first use and kept in a cache bounded in bytes
//!   (least recently used out first, never one the frame uses).
//!
//! A straddling chunk sorted in the frame before keeps its boxes `[t]` and `[v]` and its
//! pieces until the next frame: a tile whose sets of triangles and of slots (those whose
//! boxes hold it) are the same has the same piece, byte for byte, since Table 2 and the
//! tile's writer see nothing else of the view. Only the tiles where a triangle or a slot
//! came or went are sorted again: along an orbit of one degree a frame, 26% of the
//! triangles in the dragon's straddling chunks' pieces (4096-triangle chunks, 8x8 tiles)
//! are in pieces of the frame before (`reused_triangles` in `tessera render --stats`).
//! What is kept follows the frame's straddling chunks (8 bytes a triangle and a slot, and
//! their pieces; dropped when a chunk stops straddling) and fits beside the tables under
//! the cache's bound (see `Cache`).
//!
//! The first two tests hold for every point of the box because a point of the box is a
//! convex combination of its corners, and so are its clip coordinates and (for `w > 0`) its
//! pixel; each test keeps a margin for the rounding of `f32` arithmetic (relative 1e-5 of the
//! magnitudes involved, far above the few ulps the projection can err by), and a chunk
//! inside that margin is simply sorted. A tile's pieces therefore decode to exactly the
//! triangles whose `[t]` holds it, as a single stream's tile does (tested).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use glam::{Mat4, Vec4};
use rayon::prelude::*;

use super::file::ChunkedFile;
use super::source::ChunkSource;
use crate::bft::format::Coding;
use crate::bft::normals::BorderNormals;
use crate::bft::tile_sort::{boxes_into, Boxes, SortError, Sorter, TileModel};
use crate::container::{Format, FormatError};
use crate::view::{plane_distances, TileBox, TileGrid};

/// What a frame does with a chunk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// Not in the level-of-detail cut ([`super::lod`]): a finer or a coarser chunk stands
    /// for it; its bytes are not read.
    NotInCut,
    Culled,
    /// Wholly in this tile (its index).
    Verbatim(u32),
    Straddling,
}

/// Classifies a box under `view_proj` on `grid` (see the module doc).
pub fn classify(lo: [f32; 3], hi: [f32; 3], view_proj: Mat4, grid: &TileGrid) -> Class {
    let m = view_proj.to_cols_array_2d();
    let mut outside_all = [true; 6];
    let mut inside = true;
    let (mut x0, mut x1, mut y0, mut y1) = (f32::INFINITY, f32::NEG_INFINITY, f32::INFINITY, f32::NEG_INFINITY);
    let (w, h) = (grid.width as f32, grid.height as f32);
    for corner in 0..8 {
        let p = [0, 1, 2].map(|a| if corner & (1 << a) == 0 { lo[a] } else { hi[a] });
        let clip = view_proj * Vec4::new(p[0], p[1], p[2], 1.0);
        // The magnitude the clip coordinates were summed from: their rounding is relative
        // to it.
        let scale = (0..4)
            .map(|r| (0..4).map(|c| m[c][r].abs() * if c < 3 { p[c].abs() } else { 1.0 }).sum::<f32>())
            .sum::<f32>();
        if !scale.is_finite() {
            return Class::Straddling;
        }
        let margin = scale * 1e-5;
        let d = plane_distances(clip);
        for k in 0..6 {
            outside_all[k] &= d[k] < -margin;
            inside &= d[k] >= margin;
        }
        if inside {
            let (px, py) = ((clip.x / clip.w + 1.0) * 0.5 * w, (1.0 - clip.y / clip.w) * 0.5 * h);
            let u = margin / clip.w * w.max(h) + 1e-3;
            x0 = x0.min(px - u);
            x1 = x1.max(px + u);
            y0 = y0.min(py - u);
            y1 = y1.max(py + u);
        }
    }
    if outside_all.iter().any(|&o| o) {
        return Class::Culled;
    }
    if !(inside && x0.is_finite() && x1.is_finite() && y0.is_finite() && y1.is_finite()) {
        return Class::Straddling;
    }
    let (c0, c1, r0, r1) = (grid.col(x0), grid.col(x1), grid.row(y0), grid.row(y1));
    if c0 == c1 && r0 == r1 {
        Class::Verbatim(r0 as u32 * grid.cols + c0 as u32)
    } else {
        Class::Straddling
    }
}

/// One chunk's share of a tile.
#[derive(Clone, Debug)]
pub struct Piece {
    pub chunk: u32,
    pub triangles: u32,
    pub kind: PieceKind,
}

#[derive(Clone, Debug)]
pub enum PieceKind {
    /// The chunk's own stream ([`ChunkedFile::chunk_bft`]); its border normals are its border
    /// table's ([`ChunkedFile::border`]).
    Verbatim,
    /// A tile submesh of a straddling chunk.
    Sorted {
        bytes: Vec<u8>,
        /// The chunk slot of each of the piece's slots.
        slots: Vec<u32>,
        /// `(piece slot, normal)` for the slots whose triangles leave the piece.
        normals: Vec<(u32, [f32; 3])>,
    },
}

/// A tile of a chunked frame: its pieces, in chunk order.
#[derive(Clone, Debug)]
pub struct ChunkedTile {
    pub index: usize,
    pub pieces: Vec<Piece>,
}

impl ChunkedTile {
    pub fn triangles(&self) -> u64 {
        self.pieces.iter().map(|p| p.triangles as u64).sum()
    }
}

/// What one frame's chunked sort did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameCounts {
    /// Chunks a level-of-detail cut leaves out.
    pub not_in_cut: u32,
    pub culled: u32,
    pub verbatim: u32,
    pub straddling: u32,
    /// Triangles of the straddling chunks (those that went through pass 1 and Table 2).
    pub straddling_triangles: u64,
    /// Straddling chunks whose tables were built this frame (not found in the cache).
    pub built: u32,
    /// Triangles with a non-empty box `[t]`: the verbatim chunks' and the straddling chunks'
    /// that are on screen.
    pub visible_triangles: u64,
    /// Triangles of straddling chunks' pieces taken from the frame before (see the module
    /// doc), not sorted again; counted as pieces count them, once per tile a triangle is
    /// in, so that a still view's may exceed `straddling_triangles`.
    pub reused_triangles: u64,
}

/// A straddling chunk's index, its `(tile, piece)`s, whether its tables were built, its
/// visible triangles, the triangles of its pieces taken from the frame before, and what it
/// keeps for the next frame, if that fits.
type SortedChunk = (usize, Vec<(usize, Piece)>, bool, u64, u64, Option<LastSort>);

/// What a kept sort takes a straddling triangle, for deciding whether to keep them: 8 bytes
/// of its box, about 4 of its slots' boxes (half a slot a triangle), and its pieces' bytes,
/// slots and border normals (the dragon's 4096-triangle chunks at 8x8 tiles: 18 bytes a triangle, against
/// 83.5 for its tables, measured as the growth of `cached_bytes` once sorts are kept),
/// rounded up.
const KEPT_BYTES_PER_TRIANGLE: f64 = 32.0;

/// A straddling chunk's tables on the heap per triangle, as the keep decision assumes them
/// before the cache holds any (a model's first frame): the dragon's take 83.5, rounded up.
/// Only the decision rests on it; what is stored is counted from its own bytes.
const TABLE_BYTES_PER_TRIANGLE: f64 = 96.0;

/// A straddling chunk's sort, kept for the next frame (see the module doc).
struct LastSort {
    grid: TileGrid,
    coding: Coding,
    /// Every triangle's box `[t]` and every slot's `[v]`.
    triangles: Vec<TileBox>,
    vertices: Vec<TileBox>,
    /// Its `(tile, piece)`s.
    pieces: Vec<(usize, Piece)>,
}

impl LastSort {
    /// The bytes it holds on the heap, as the cache's bound counts them.
    fn heap_bytes(&self) -> usize {
        Self::bytes_of(&self.triangles, &self.vertices, &self.pieces)
    }

    /// What a sort with these boxes and pieces holds.
    fn bytes_of(triangles: &[TileBox], vertices: &[TileBox], pieces: &[(usize, Piece)]) -> usize {
        let pieces: usize = pieces
            .iter()
            .map(|(_, p)| match &p.kind {
                PieceKind::Sorted { bytes, slots, normals } => {
                    bytes.len() + std::mem::size_of_val(&slots[..]) + std::mem::size_of_val(&normals[..])
                }
                PieceKind::Verbatim => 0,
            })
            .sum();
        std::mem::size_of_val(triangles) + std::mem::size_of_val(vertices) + pieces
    }

    /// The tiles whose sets of triangles or of unclipped slots differ between `self` and
    /// `boxes` (of the same chunk on `grid`), or `None` when nothing can be reused (another
    /// grid, coding or chunk). Slots count apart from triangles: a slot's box is the
    /// rectangle around its triangles', so it can lose a tile where none of its triangles
    /// was.
    fn changed_tiles(&self, grid: &TileGrid, coding: Coding, boxes: &Boxes) -> Option<Vec<bool>> {
        let same_chunk = self.triangles.len() == boxes.triangles.len() && self.vertices.len() == boxes.vertices.len();
        if self.grid != *grid || self.coding != coding || !same_chunk {
            return None;
        }
        let mut changed = vec![false; grid.tiles()];
        let old = self.triangles.iter().chain(&self.vertices);
        for (old, new) in old.zip(boxes.triangles.iter().chain(&boxes.vertices)).filter(|(o, n)| o != n) {
            let u = old.union(new);
            for r in u.r0..=u.r1 {
                for c in u.c0..=u.c1 {
                    if old.contains(c, r) != new.contains(c, r) {
                        changed[r as usize * grid.cols as usize + c as usize] = true;
                    }
                }
            }
        }
        Some(changed)
    }
}

/// A straddling chunk's tables: its `TileModel` and normals, built on first use.
pub struct Straddler {
    pub model: TileModel,
    pub normals: BorderNormals,
    bytes: usize,
}

/// The straddling chunks' tables: entries stamped with the frame that last used them.
/// Least recently used out first, but never one the current frame uses: when a frame's
/// straddling chunks need more than the bound, the chunks that do not fit are built and
/// dropped, and the cached ones stay hits next frame, instead of a cyclic scan evicting
/// each chunk just before it is needed again.
///
/// Under the same bound it keeps the straddling chunks' sorts from the frame before (see the
/// module doc), stored at the end of a frame only where they fit beside the tables (evicting
/// tables of earlier frames, never of the current one): where the frame's tables fill the
/// bound, they are worth more, since a frame cannot sort without them.
struct Cache {
    entries: HashMap<u32, (Arc<Straddler>, u64)>,
    kept: HashMap<u32, LastSort>,
    /// The tables' and the kept sorts' bytes.
    bytes: usize,
    /// The current frame's stamp.
    frame: u64,
}

impl Cache {
    /// Evicts the least recently used tables of earlier frames until `bytes` more fit
    /// under `limit`; whether they do.
    fn make_room(&mut self, bytes: usize, limit: usize) -> bool {
        let now = self.frame;
        while self.bytes + bytes > limit {
            let Some((&victim, _)) =
                self.entries.iter().filter(|(_, (_, used))| *used < now).min_by_key(|(_, (_, used))| *used)
            else {
                return false;
            };
            let (old, _) = self.entries.remove(&victim).expect("present");
            self.bytes -= old.bytes;
        }
        true
    }
}

/// A chunked model ready for sorting: the file (its directory read), the chunks' float
/// boxes, and the cache of straddling chunks' tables.
pub struct ChunkedModel<B: ChunkSource> {
    pub file: ChunkedFile<B>,
    boxes: Vec<([f32; 3], [f32; 3])>,
    cache: Mutex<Cache>,
    /// The cache's bound in bytes.
    pub cache_limit: usize,
    /// Sort buffers kept from chunk to chunk and frame to frame, one per task in flight.
    buffers: Mutex<Vec<(Sorter, Boxes)>>,
    /// A hierarchy's cut: the largest projected error in pixels, or `None` for the
    /// full-resolution model (level 0). A file without a hierarchy is always drawn whole.
    pub error_px: Option<f32>,
    /// Whether straddling chunks keep their sorts for the next frame (on by default; a
    /// benchmark of the sort itself turns it off, or a still view would time the reuse).
    pub keep_sorts: bool,
}

impl<B: ChunkSource> ChunkedModel<B> {
    pub fn new(file: ChunkedFile<B>, cache_limit: usize) -> ChunkedModel<B> {
        let boxes = (0..file.entries.len()).map(|i| file.chunk_box(i)).collect();
        ChunkedModel {
            file,
            boxes,
            cache: Mutex::new(Cache { entries: HashMap::new(), kept: HashMap::new(), bytes: 0, frame: 0 }),
            cache_limit,
            buffers: Mutex::new(Vec::new()),
            error_px: None,
            keep_sorts: true,
        }
    }

    pub fn chunks(&self) -> usize {
        self.boxes.len()
    }

    /// Bytes the cache holds now: the straddling chunks' tables and their sorts kept from
    /// the frame before.
    pub fn cached_bytes(&self) -> usize {
        self.cache.lock().expect("cache lock").bytes
    }

    /// Every chunk's class for a view.
    pub fn classify_all(&self, view_proj: Mat4, grid: &TileGrid) -> Vec<Class> {
        self.classify_chunks(view_proj, grid, 0..self.chunks())
    }

    /// The classes of the chunks `range`, in parallel: those outside the level-of-detail
    /// cut first, then the frustum and the tiles.
    fn classify_chunks(&self, view_proj: Mat4, grid: &TileGrid, range: std::ops::Range<usize>) -> Vec<Class> {
        let projection = super::lod::Projection::new(view_proj, grid.height);
        let lod = self.file.lod.as_ref();
        let first = range.start;
        self.boxes[range]
            .par_iter()
            .enumerate()
            .with_min_len(256)
            .map(|(k, &(lo, hi))| {
                let i = first + k;
                let drawn = match (lod, self.error_px) {
                    (None, _) => true,
                    (Some(h), None) => i < h.level0 as usize,
                    (Some(h), Some(t)) => h.in_cut(i, &projection, t),
                };
                if drawn {
                    classify(lo, hi, view_proj, grid)
                } else {
                    Class::NotInCut
                }
            })
            .collect()
    }

    /// Chunk `i`'s tables, from the cache or built (and then cached if they fit).
    pub fn straddler(&self, i: usize) -> Result<(Arc<Straddler>, bool), FormatError> {
        {
            let mut c = self.cache.lock().expect("cache lock");
            let now = c.frame;
            if let Some((s, used)) = c.entries.get_mut(&(i as u32)) {
                *used = now;
                return Ok((s.clone(), false));
            }
        }
        let model = TileModel::from_bytes(&self.file.chunk_bft(i)?).map_err(|e| match e {
            SortError::Bft(e) => super::error::in_chunk(i, e),
            other => FormatError::Corrupt(Format::Bft, format!("chunk {i}: {other}")),
        })?;
        self.file.check_chunk(i, &model.decoded.header, &model.decoded.positions)?;
        let mut normals = BorderNormals::of(&model.decoded);
        normals.set_border(self.file.border(i)?.slot_normals());
        let bytes = model.heap_bytes() + normals.heap_bytes();
        let s = Arc::new(Straddler { model, normals, bytes });
        let mut c = self.cache.lock().expect("cache lock");
        let now = c.frame;
        if c.make_room(bytes, self.cache_limit) && !c.entries.contains_key(&(i as u32)) {
            c.bytes += bytes;
            c.entries.insert(i as u32, (s.clone(), now));
        }
        Ok((s, true))
    }

    /// Sorts the model for one view: the non-empty tiles, by index, each with its pieces in
    /// chunk order. Straddling chunks are sorted in parallel, each coded as `coding`.
    pub fn sort(
        &self,
        view_proj: Mat4,
        grid: &TileGrid,
        coding: Coding,
    ) -> Result<(Vec<ChunkedTile>, FrameCounts), SortError> {
        self.sort_chunks(view_proj, grid, coding, 0..self.chunks())
    }

    /// [`Self::sort`] of the chunks `range` alone (one sorter's share when several ranks
    /// share the sort): the tiles hold those chunks' pieces, in chunk order.
    pub fn sort_chunks(
        &self,
        view_proj: Mat4,
        grid: &TileGrid,
        coding: Coding,
        range: std::ops::Range<usize>,
    ) -> Result<(Vec<ChunkedTile>, FrameCounts), SortError> {
        let first = range.start;
        let classes = self.classify_chunks(view_proj, grid, range.clone());
        let mut counts = FrameCounts::default();
        let mut straddling = Vec::new();
        for (i, c) in classes.iter().enumerate().map(|(j, c)| (first + j, c)) {
            match c {
                Class::NotInCut => counts.not_in_cut += 1,
                Class::Culled => counts.culled += 1,
                Class::Verbatim(_) => counts.verbatim += 1,
                Class::Straddling => {
                    counts.straddling += 1;
                    counts.straddling_triangles += self.file.entries[i].triangles as u64;
                    straddling.push(i);
                }
            }
        }
        // The frame before's sorts of this frame's straddling chunks; those of the range's
        // other chunks are dropped. Sorts are kept this frame where the straddling chunks'
        // tables and sorts would fit the bound together, at the cache's bytes a triangle for
        // tables (`TABLE_BYTES_PER_TRIANGLE` until the cache holds some) and
        // `KEPT_BYTES_PER_TRIANGLE` for sorts: where the tables fill it, sorts kept and then
        // dropped at the frame's end would only raise the frame's peak memory. Keeping from
        // the first frame on makes a still view's second frame cheap (`--no-frame-reuse`).
        let (straddling, keeping) = {
            let mut c = self.cache.lock().expect("cache lock");
            c.frame += 1;
            let (bytes, triangles) =
                c.entries.values().fold((0, 0), |(b, t), (s, _)| (b + s.bytes, t + s.model.triangles().len()));
            let tables = if triangles > 0 { bytes as f64 / triangles as f64 } else { TABLE_BYTES_PER_TRIANGLE };
            let per_triangle = tables + KEPT_BYTES_PER_TRIANGLE;
            let keeping =
                self.keep_sorts && counts.straddling_triangles as f64 * per_triangle <= self.cache_limit as f64;
            let take = |c: &mut Cache, i: u32| {
                let last = c.kept.remove(&i);
                c.bytes -= last.as_ref().map_or(0, LastSort::heap_bytes);
                last
            };
            let taken: Vec<(usize, Option<LastSort>)> =
                straddling.iter().map(|&i| (i, take(&mut c, i as u32))).collect();
            let gone: Vec<u32> = c.kept.keys().copied().filter(|&i| range.contains(&(i as usize))).collect();
            for i in gone {
                take(&mut c, i);
            }
            (taken, keeping)
        };
        let sorted: Vec<SortedChunk> = straddling
            .into_par_iter()
            .with_max_len(1)
            .map(|(i, last)| {
                let (s, built) = self.straddler(i)?;
                // Pass 1 and 2's buffers come from a pool and go back to it, so that the
                // thousands of small chunks of a frame do not each allocate them afresh (as
                // the single-stream frame loop keeps its own).
                let (mut sorter, mut boxes) = self.buffers.lock().expect("buffer pool").pop().unwrap_or_default();
                sorter.coding = coding;
                boxes_into(&s.model, view_proj, grid, &mut boxes);
                let changed = last.as_ref().and_then(|l| l.changed_tiles(grid, coding, &boxes));
                let sorted = if changed.as_ref().is_some_and(|c| !c.contains(&true)) {
                    Ok((Vec::new(), Vec::new()))
                } else {
                    sorter.sort_tiles(&s.model, &boxes, grid, changed.as_deref()).map(|tiles| {
                        let normals = s.normals.for_tiles(&s.model, &boxes, &tiles, grid);
                        (tiles, normals)
                    })
                };
                let visible = boxes.triangles.iter().filter(|b| !b.is_empty()).count() as u64;
                let (tiles, normals) = match sorted {
                    Ok(t) => t,
                    Err(e) => {
                        self.buffers.lock().expect("buffer pool").push((sorter, boxes));
                        return Err(e);
                    }
                };
                let mut pieces: Vec<(usize, Piece)> = tiles
                    .into_iter()
                    .zip(normals)
                    .map(|(t, normals)| {
                        let kind = PieceKind::Sorted { bytes: t.bytes, slots: t.slots, normals };
                        (t.index, Piece { chunk: i as u32, triangles: t.triangles, kind })
                    })
                    .collect();
                let mut reused = 0;
                if let (Some(changed), Some(last)) = (&changed, last) {
                    for (t, p) in last.pieces.into_iter().filter(|(t, _)| !changed[*t]) {
                        reused += p.triangles as u64;
                        pieces.push((t, p));
                    }
                }
                pieces.sort_by_key(|(t, _)| *t);
                // Kept if it fits now; whether it still does is decided at the frame's end.
                let bytes = LastSort::bytes_of(&boxes.triangles, &boxes.vertices, &pieces);
                let fits = keeping && self.cache.lock().expect("cache lock").bytes + bytes <= self.cache_limit;
                let keep = fits.then(|| {
                    // The boxes stay with the chunk; the pool's buffers get fresh ones.
                    let triangles = std::mem::take(&mut boxes.triangles);
                    let vertices = std::mem::take(&mut boxes.vertices);
                    LastSort { grid: *grid, coding, triangles, vertices, pieces: pieces.clone() }
                });
                self.buffers.lock().expect("buffer pool").push((sorter, boxes));
                Ok((i, pieces, built, visible, reused, keep))
            })
            .collect::<Result<_, SortError>>()?;
        let mut per_tile: Vec<Vec<Piece>> = (0..grid.tiles()).map(|_| Vec::new()).collect();
        let mut kept = Vec::with_capacity(sorted.len());
        let mut sorted = sorted.into_iter().peekable();
        for (i, c) in classes.iter().enumerate().map(|(j, c)| (first + j, c)) {
            match c {
                Class::Verbatim(t) => {
                    counts.visible_triangles += self.file.entries[i].triangles as u64;
                    per_tile[*t as usize].push(Piece {
                        chunk: i as u32,
                        triangles: self.file.entries[i].triangles,
                        kind: PieceKind::Verbatim,
                    })
                }
                Class::Straddling => {
                    let (j, pieces, built, visible, reused, keep) =
                        sorted.next().expect("one result per straddling chunk");
                    debug_assert_eq!(i, j);
                    counts.built += built as u32;
                    counts.visible_triangles += visible;
                    counts.reused_triangles += reused;
                    kept.extend(keep.map(|k| (i as u32, k)));
                    for (t, p) in pieces {
                        per_tile[t].push(p);
                    }
                }
                Class::Culled | Class::NotInCut => {}
            }
        }
        debug_assert!(sorted.peek().is_none());
        let mut c = self.cache.lock().expect("cache lock");
        for (i, keep) in kept {
            let bytes = keep.heap_bytes();
            if c.make_room(bytes, self.cache_limit) {
                c.bytes += bytes;
                c.kept.insert(i, keep);
            }
        }
        let tiles = per_tile
            .into_iter()
            .enumerate()
            .filter(|(_, p)| !p.is_empty())
            .map(|(index, pieces)| ChunkedTile { index, pieces })
            .collect();
        Ok((tiles, counts))
    }
}

/// Sorter `s`'s share of `chunks` chunks among `sorters`: contiguous, so that the shares in
/// sorter order are the chunks in file order.
pub fn share(chunks: usize, s: usize, sorters: usize) -> std::ops::Range<usize> {
    s * chunks / sorters..(s + 1) * chunks / sorters
}
