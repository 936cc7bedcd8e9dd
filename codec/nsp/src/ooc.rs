//! Building an `.nsp` out of core (NSP.md 1.3, 1.4 and 1.7): the same file as
//! [`super::encode()`] (byte for byte, tested), in memory that does not grow with the model.
//!
//! 1. **Positions** are streamed from the PLY (or OBJ) file into a raw file (RWP, 12 bytes
//!    a vertex) while the cube is fitted; they are never all held. The triangle pass reads
//!    them back through a small page cache (`PAGE_CACHE_BYTES`): meshes index vertices
//!    with locality, and a miss is one `pread`.
//! 2. **Buckets.** Each quantized triangle (and each unreferenced vertex, as a point) goes to
//!    every cell of a coarse grid that holds one of its corners, in temporary files.
//! 3. **The canonical complex, bucket by bucket.** Coincident corners, repeated triangles
//!    and the faces of other simplices all share a vertex with what absorbs them, so each
//!    bucket reduces its own records exactly as the whole model would (`canonical.rs`), and
//!    writes the simplices whose smallest corner is inside it: each canonical simplex once.
//!    A bucket too large to hold is cut again by a finer grid.
//! 4. **The partition**, one pass over the canonical simplices per depth of the tree,
//!    counting the simplices of the children of the cells that split (the in-core rule).
//! 5. **Leaves.** One pass writes each simplex to the batch file of every leaf holding one of
//!    its corners; batches are runs of leaves in postorder of bounded size.
//! 6. **Cells in postorder.** Leaves of a batch are encoded in parallel from their
//!    simplices; each cell hands its simplices, clustered at its minimal precision, to its
//!    parent, which encodes them when its last child is done (the paper's step 2d), so the
//!    held state is one partial parent per depth. Decisions go to a temporary file and
//!    their counts make the static tables.
//! 7. **Output**: header and tables, then each cell's decisions range-coded in turn, then the
//!    cell table.

use rustc_hash::{FxHashMap as HashMap, FxHashSet as HashSet};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;

use super::canonical::{reduce, top_simplices, Cube, Simplex};
use super::complex::CONTEXTS;
use super::encode::{code_cell, kind_of, record_local, segments, static_prob, Recorded};
use super::error::NspError;
use super::format::{self, CellEntry, Header};
use super::params::Params;
use super::tree::{Node, Tree};
use crate::load::stream;

/// Bytes of the page cache over the positions file.
const PAGE_CACHE_BYTES: usize = 8 << 20;
/// A page holds whole positions (12 bytes each).
const PAGE: usize = 12 << 12;
/// The payload that ends the positions pass at a failed write (see `build_temp`).
struct StopPass;

/// Bits per axis of the bucket grid (8^3 = 512 bucket files).
const BUCKET_BITS: u8 = 3;

/// How much one step holds at once.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// A bucket of more records than this is cut again by a finer grid.
    pub bucket_records: u64,
    /// Records per batch of leaves, at most (a leaf larger than this is a batch alone).
    pub batch_records: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits { bucket_records: 1 << 18, batch_records: 1 << 18 }
    }
}

/// Where the build stands, for a progress bar: the stage's name, then done of total.
pub type Progress<'a> = &'a (dyn Fn(&str, u64, u64) + Sync);

/// What an out-of-core build wrote.
pub struct Built {
    pub header: Header,
    pub cells: usize,
    pub bytes: u64,
    pub decisions: [u64; 3],
    pub cost_bits: [f64; 3],
    /// The largest the temporary folder grew, in bytes.
    pub temp_bytes: u64,
}

/// A simplex on the grid of some precision, with its input order (`t`: the index of its
/// first triangle; edges and points after every triangle).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rec {
    t: u32,
    dim: u8,
    q: [[u32; 3]; 3],
}

const REC_BYTES: usize = 4 + 1 + 36;

impl Rec {
    fn put(&self, out: &mut impl Write) -> std::io::Result<()> {
        let mut b = [0u8; REC_BYTES];
        b[..4].copy_from_slice(&self.t.to_le_bytes());
        b[4] = self.dim;
        for (k, v) in self.q.iter().flatten().enumerate() {
            b[5 + 4 * k..9 + 4 * k].copy_from_slice(&v.to_le_bytes());
        }
        out.write_all(&b)
    }

    fn get(b: &[u8]) -> Rec {
        let u = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        let mut q = [[0u32; 3]; 3];
        for (k, v) in q.iter_mut().flatten().enumerate() {
            *v = u(5 + 4 * k);
        }
        Rec { t: u(0), dim: b[4], q }
    }

    fn corners(&self) -> &[[u32; 3]] {
        &self.q[..self.dim as usize + 1]
    }

    /// Sorting key: triangles by input order, then edges, then points.
    fn order(&self) -> (u8, u32) {
        (2 - self.dim, self.t)
    }
}

/// A failed write of a temporary file (the folder is named once the build returns it).
fn tw(e: std::io::Error) -> NspError {
    NspError::Temp { write: true, folder: PathBuf::new(), error: e.to_string() }
}

/// A failed read of a temporary file.
fn tr(e: std::io::Error) -> NspError {
    NspError::Temp { write: false, folder: PathBuf::new(), error: e.to_string() }
}

/// A failed write of the output.
fn ow(e: std::io::Error) -> NspError {
    NspError::Output(e.to_string())
}

/// How the build makes its temporary files: in the caller's folder, each written through a
/// [`TempFile`] that shares the fault hook's budget.
struct Temp {
    left: Option<Arc<AtomicU64>>,
}

impl Temp {
    fn create(&self, path: &Path) -> Result<TempFile, NspError> {
        Ok(TempFile { file: File::create(path).map_err(tw)?, left: self.left.clone() })
    }

    fn writer(&self, path: &Path, capacity: usize) -> Result<BufWriter<TempFile>, NspError> {
        Ok(BufWriter::with_capacity(capacity, self.create(path)?))
    }
}

/// A temporary file being written. With [`Scratch::full_after`] set, a write past the budget
/// fails as on a full disk (`ENOSPC`).
struct TempFile {
    file: File,
    left: Option<Arc<AtomicU64>>,
}

impl Write for TempFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Some(left) = &self.left {
            let n = buf.len() as u64;
            if left.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |l| l.checked_sub(n)).is_err() {
                return Err(std::io::Error::from_raw_os_error(ENOSPC));
            }
        }
        self.file.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

/// Linux's "No space left on device".
const ENOSPC: i32 = 28;

fn read_recs(path: &Path) -> Result<Vec<Rec>, NspError> {
    let mut bytes = Vec::new();
    File::open(path).and_then(|mut f| f.read_to_end(&mut bytes)).map_err(tr)?;
    Ok(bytes.chunks_exact(REC_BYTES).map(Rec::get).collect())
}

/// A page of the positions file: its number and bytes.
type Page = (u64, Box<[u8]>);

/// The positions file, read back through a direct-mapped page cache. A failed read gives
/// zeros and is kept in `failed`, which the build checks once the pass is over (the
/// loader's callbacks that read positions cannot return an error of their own).
struct Positions {
    file: File,
    count: usize,
    pages: Mutex<Vec<Option<Page>>>,
    failed: Mutex<Option<std::io::Error>>,
}

impl Positions {
    fn get(&self, i: u32) -> [f32; 3] {
        use std::os::unix::fs::FileExt;
        let at = i as u64 * 12;
        let page = at / PAGE as u64;
        let mut pages = self.pages.lock().expect("not poisoned");
        let n = pages.len();
        let slot = &mut pages[(page % n as u64) as usize];
        if slot.as_ref().is_none_or(|(p, _)| *p != page) {
            let mut buf = vec![0u8; PAGE].into_boxed_slice();
            let start = page * PAGE as u64;
            let len = ((self.count as u64 * 12 - start) as usize).min(PAGE);
            if let Err(e) = self.file.read_exact_at(&mut buf[..len], start) {
                self.failed.lock().expect("not poisoned").get_or_insert(e);
            }
            *slot = Some((page, buf));
        }
        let (_, buf) = slot.as_ref().expect("filled");
        let o = (at % PAGE as u64) as usize;
        let f = |k: usize| f32::from_le_bytes(buf[o + 4 * k..o + 4 * k + 4].try_into().unwrap());
        [f(0), f(1), f(2)]
    }
}

impl stream::PositionSource for Positions {
    fn count(&self) -> usize {
        self.count
    }
    fn gather(&self, indices: &[u32], out: &mut Vec<[f32; 3]>) {
        out.extend(indices.iter().map(|&i| self.get(i)));
    }
}

/// Where an out-of-core build keeps its temporary files ([`build_in`]).
#[derive(Clone, Copy, Debug)]
pub struct Scratch<'a> {
    /// An existing folder of the caller's, which the build fills and the caller removes.
    pub dir: &'a Path,
    /// The folder messages name (the user's `--temp-dir`, not the build's own folder in it).
    pub shown: &'a Path,
    /// Test hook: once this many bytes of temporary files are written, every write fails as
    /// on a full disk (`ENOSPC`).
    pub full_after: Option<u64>,
}

/// Builds `input` (PLY or OBJ, optionally gzipped) into `out`, with temporary files in a
/// new folder under `temp_dir` (the system's if `None`), removed when done.
pub fn build_file(
    input: &Path,
    params: Params,
    temp_dir: Option<&Path>,
    out: &mut dyn Write,
    progress: Progress,
) -> Result<Built, NspError> {
    build_file_with(input, params, temp_dir, out, progress, Limits::default())
}

/// [`build_file`] with other [`Limits`] (tests make them small to cut buckets and batch
/// leaves on small models).
pub fn build_file_with(
    input: &Path,
    params: Params,
    temp_dir: Option<&Path>,
    out: &mut dyn Write,
    progress: Progress,
    limits: Limits,
) -> Result<Built, NspError> {
    params.validate()?;
    let parent = temp_dir.map_or_else(std::env::temp_dir, Path::to_path_buf);
    let dir = tempfile::Builder::new().prefix("tessera-nsp").tempdir_in(&parent).map_err(|e| NspError::Temp {
        write: true,
        folder: parent.clone(),
        error: e.to_string(),
    })?;
    build_in(input, params, Scratch { dir: dir.path(), shown: &parent, full_after: None }, out, progress, limits)
}

/// [`build_file_with`] with its temporary files in `scratch.dir`. A failed write or read of
/// them (a full disk) ends the build at once, with a message naming `scratch.shown`.
pub fn build_in(
    input: &Path,
    params: Params,
    scratch: Scratch,
    out: &mut dyn Write,
    progress: Progress,
    limits: Limits,
) -> Result<Built, NspError> {
    params.validate()?;
    let temp = Temp { left: scratch.full_after.map(|n| Arc::new(AtomicU64::new(n))) };
    build_temp(input, params, scratch.dir, &temp, out, progress, limits).map_err(|e| match e {
        NspError::Temp { write, error, .. } => NspError::Temp { write, folder: scratch.shown.to_path_buf(), error },
        e => e,
    })
}

fn build_temp(
    input: &Path,
    params: Params,
    tmp: &Path,
    temp: &Temp,
    out: &mut dyn Write,
    progress: Progress,
    limits: Limits,
) -> Result<Built, NspError> {
    let tmp = tmp.to_path_buf();
    let load = |e: crate::LoadError| NspError::Input(e.to_string());
    let file_len = std::fs::metadata(input).map(|m| m.len()).unwrap_or(0);

    // 1. Positions to RWP, and the cube.
    let rwp_path = tmp.join("positions");
    let mut rwp = temp.writer(&rwp_path, 1 << 20)?;
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let mut werr = None;
    // The loader's position callback cannot fail: a failed write unwinds out of the pass
    // (`resume_unwind` runs no panic hook) and is caught right here, so a full disk ends
    // the pass at its first failed write instead of failing once per position.
    let pass = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        stream::for_each_position(
            input,
            &mut |p| {
                if p.iter().all(|c| c.is_finite()) {
                    for a in 0..3 {
                        lo[a] = lo[a].min(p[a] as f64);
                        hi[a] = hi[a].max(p[a] as f64);
                    }
                }
                let mut b = [0u8; 12];
                for (k, c) in p.iter().enumerate() {
                    b[4 * k..4 * k + 4].copy_from_slice(&c.to_le_bytes());
                }
                if let Err(e) = rwp.write_all(&b) {
                    werr = Some(e);
                    std::panic::resume_unwind(Box::new(StopPass));
                }
            },
            &mut |n| progress("reading vertices", n, file_len),
        )
    }));
    let vertices = match pass {
        Ok(r) => r.map_err(load)?,
        Err(payload) if payload.is::<StopPass>() => {
            return Err(tw(werr.take().expect("a failed write stops the pass")))
        }
        Err(payload) => std::panic::resume_unwind(payload),
    };
    rwp.flush().map_err(tw)?;
    drop(rwp);
    if vertices > u32::MAX as u64 {
        return Err(NspError::Input(format!("{vertices} vertices; at most 2^32 are supported")));
    }
    if lo[0] > hi[0] {
        return Err(NspError::Empty);
    }
    let side = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    let cube = Cube { origin: lo, side: if side > 0.0 { side } else { 1.0 }, bits: params.bits };
    let extent = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let positions = Positions {
        file: File::open(&rwp_path).map_err(tr)?,
        count: vertices as usize,
        pages: Mutex::new((0..PAGE_CACHE_BYTES / PAGE).map(|_| None).collect()),
        failed: Mutex::new(None),
    };

    // 2. Triangles (and unreferenced vertices) to buckets.
    let buckets = Buckets::create(temp, &tmp.join("b"), params.bits, BUCKET_BITS)?;
    let mut used = vec![0u64; (vertices as usize).div_ceil(64)];
    let mut failed: Option<NspError> = None;
    let mut t = 0u64;
    let triangles = stream::for_each_triangle_from(
        input,
        &positions,
        &mut |tri| {
            let mut q = [[0u32; 3]; 3];
            for (k, &v) in tri.iter().enumerate() {
                let p = positions.get(v);
                if !p.iter().all(|c| c.is_finite()) {
                    return Err(crate::LoadError {
                        path: input.to_path_buf(),
                        message: format!(
                            "triangle {t} uses vertex {v}, whose position ({}, {}, {}) is not finite",
                            p[0], p[1], p[2]
                        ),
                    });
                }
                q[k] = cube.quantize(p);
                used[v as usize / 64] |= 1 << (v % 64);
            }
            if t >= u32::MAX as u64 {
                return Err(crate::LoadError {
                    path: input.to_path_buf(),
                    message: "more than 2^32 - 1 triangles".into(),
                });
            }
            if let Err(e) = buckets.put(&Rec { t: t as u32, dim: 2, q }) {
                // Ends the pass (the loader's error is replaced by this one below).
                failed = Some(e);
                return Err(crate::LoadError { path: input.to_path_buf(), message: String::new() });
            }
            t += 1;
            Ok(())
        },
        &mut |n| progress("reading triangles", n, file_len),
    );
    if let Some(e) = failed {
        return Err(e);
    }
    let triangles = triangles.map_err(load)?;
    for v in 0..vertices as u32 {
        if used[v as usize / 64] >> (v % 64) & 1 == 0 {
            let p = positions.get(v);
            buckets.put(&Rec { t: u32::MAX, dim: 0, q: [cube.quantize(p), [0; 3], [0; 3]] })?;
        }
    }
    drop(used);
    if let Some(e) = positions.failed.lock().expect("not poisoned").take() {
        return Err(tr(e));
    }
    drop(positions);
    let _ = std::fs::remove_file(&rwp_path);
    let mut temp_bytes = buckets.finish()?;

    // 3. The canonical complex, bucket by bucket.
    let canon_path = tmp.join("canonical");
    let mut canon = Canon::new(temp, &canon_path)?;
    let list = buckets.files();
    for (i, (path, key)) in list.iter().enumerate() {
        progress("merging coincident vertices", i as u64, list.len() as u64);
        canonicalize(temp, path, *key, params.bits, BUCKET_BITS.min(params.bits), limits.bucket_records, &mut canon)?;
        let _ = std::fs::remove_file(path);
    }
    let counts = canon.finish()?;
    temp_bytes = temp_bytes.max(counts.bytes);
    if counts.points == 0 {
        return Err(NspError::Empty);
    }

    // 4. The partition.
    let (tree, cell_counts) = partition(params, &canon_path, &progress)?;

    // 5. Leaves to batches.
    let batches = Batches::write(temp, &tree, &cell_counts, &canon_path, &tmp, limits.batch_records)?;
    temp_bytes = temp_bytes.max(counts.bytes + batches.bytes);
    let _ = std::fs::remove_file(&canon_path);

    // 6. Cells in postorder.
    let decisions_path = tmp.join("decisions");
    let mut enc = Encoding::new(temp, &tree, &decisions_path)?;
    for (i, batch) in batches.files.iter().enumerate() {
        progress("encoding cells", i as u64, batches.files.len() as u64);
        enc.batch(&tree, batch)?;
        let _ = std::fs::remove_file(&batch.path);
    }
    enc.finish_to(&tree, tree.nodes.len() as u32)?;
    let written = enc.decisions.into_inner().map_err(|e| tw(e.into_error()))?;
    drop(written);
    temp_bytes = temp_bytes.max(std::fs::metadata(&decisions_path).map(|m| m.len()).unwrap_or(0));

    // 7. Output.
    let table: Vec<u16> = enc.counts.iter().map(|c| static_prob(c[0], c[1])).collect();
    let mut decisions = [0u64; 3];
    let mut cost_bits = [0f64; 3];
    for (ctx, c) in enc.counts.iter().enumerate() {
        decisions[kind_of(ctx)] += c[0] + c[1];
        let p0 = table[ctx] as f64 / 2048.0;
        cost_bits[kind_of(ctx)] -= c[0] as f64 * p0.log2() + c[1] as f64 * (1.0 - p0).log2();
    }
    let header = Header {
        params,
        cube,
        points: counts.points,
        triangles: counts.triangles,
        edges: counts.edges,
        isolated: counts.isolated,
        input_triangles: triangles.triangles,
        input_vertices: vertices,
        cells: tree.nodes.len() as u32,
        extent,
        leaf_simplices: enc.leaf_simplices,
    };
    let prefix = format::write_prefix(&header, &table);
    out.write_all(&prefix).map_err(ow)?;
    let mut written = prefix.len() as u64;
    let mut reader = BufReader::with_capacity(1 << 20, File::open(&decisions_path).map_err(tr)?);
    let mut entries = Vec::with_capacity(tree.nodes.len());
    let mut bits: Vec<u16> = Vec::new();
    for (c, info) in enc.cells.iter().enumerate() {
        progress("writing", c as u64, tree.nodes.len() as u64);
        let mut raw = vec![0u8; info.decisions as usize * 2];
        reader.read_exact(&mut raw).map_err(tr)?;
        bits.clear();
        bits.extend(raw.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])));
        let stream = code_cell(&bits, &table);
        out.write_all(&stream).map_err(ow)?;
        let (ends, segment_crcs) = segments(&bits, &info.level_ends, &table, &stream);
        entries.push(CellEntry {
            split: !tree.is_leaf(c as u32),
            offset: written,
            len: stream.len() as u32,
            crc: crc32fast::hash(&stream),
            max_cells: info.max_cells,
            max_tops: info.max_tops,
            reach: info.reach,
            ends,
            segment_crcs,
        });
        written += stream.len() as u64;
    }
    let tail = format::write_cell_table(&entries, written);
    out.write_all(&tail).map_err(ow)?;
    written += tail.len() as u64;
    Ok(Built { header, cells: tree.nodes.len(), bytes: written, decisions, cost_bits, temp_bytes })
}

/// Bucket files of a grid of `2^bits` cells per axis (within the cell `key` of a coarser
/// grid, for a bucket cut again), opened as records arrive.
struct Buckets<'t> {
    temp: &'t Temp,
    dir: PathBuf,
    p: u8,
    bits: u8,
    writers: Mutex<HashMap<[u32; 3], BufWriter<TempFile>>>,
}

impl<'t> Buckets<'t> {
    fn create(temp: &'t Temp, dir: &Path, p: u8, bits: u8) -> Result<Buckets<'t>, NspError> {
        std::fs::create_dir_all(dir).map_err(tw)?;
        Ok(Buckets { temp, dir: dir.to_path_buf(), p, bits: bits.min(p), writers: Mutex::new(HashMap::default()) })
    }

    fn key(&self, q: [u32; 3]) -> [u32; 3] {
        let s = self.p - self.bits;
        [q[0] >> s, q[1] >> s, q[2] >> s]
    }

    fn path(&self, k: [u32; 3]) -> PathBuf {
        self.dir.join(format!("{}-{}-{}", k[0], k[1], k[2]))
    }

    /// Writes `r` to the bucket of each of its distinct corners.
    fn put(&self, r: &Rec) -> Result<(), NspError> {
        self.put_where(r, |_| true)
    }

    /// Writes `r` to the bucket of each of its distinct corners that `keep` accepts.
    fn put_where(&self, r: &Rec, keep: impl Fn([u32; 3]) -> bool) -> Result<(), NspError> {
        use std::collections::hash_map::Entry;
        let mut seen: [[u32; 3]; 3] = [[u32::MAX; 3]; 3];
        let mut writers = self.writers.lock().expect("not poisoned");
        for (k, &q) in r.corners().iter().enumerate() {
            let key = self.key(q);
            if !keep(q) || seen[..k].contains(&key) {
                continue;
            }
            seen[k] = key;
            let w = match writers.entry(key) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => e.insert(self.temp.writer(&self.path(key), 32 << 10)?),
            };
            r.put(w).map_err(tw)?;
        }
        Ok(())
    }

    /// Flushes every bucket; returns their total size.
    fn finish(&self) -> Result<u64, NspError> {
        let mut writers = self.writers.lock().expect("not poisoned");
        let mut total = 0;
        for (k, w) in writers.iter_mut() {
            w.flush().map_err(tw)?;
            total += std::fs::metadata(self.path(*k)).map(|m| m.len()).unwrap_or(0);
        }
        Ok(total)
    }

    /// The bucket files and their keys, in key order.
    fn files(&self) -> Vec<(PathBuf, [u32; 3])> {
        let mut keys: Vec<[u32; 3]> = self.writers.lock().expect("not poisoned").keys().copied().collect();
        keys.sort_unstable();
        self.writers.lock().expect("not poisoned").clear();
        keys.into_iter().map(|k| (self.path(k), k)).collect()
    }
}

/// The canonical simplices' file and its counts.
struct Canon {
    out: BufWriter<TempFile>,
    counts: CanonCounts,
}

#[derive(Default)]
struct CanonCounts {
    points: u64,
    triangles: u64,
    edges: u64,
    isolated: u64,
    bytes: u64,
}

impl Canon {
    fn new(temp: &Temp, path: &Path) -> Result<Canon, NspError> {
        Ok(Canon { out: temp.writer(path, 1 << 20)?, counts: CanonCounts::default() })
    }

    fn finish(mut self) -> Result<CanonCounts, NspError> {
        self.out.flush().map_err(tw)?;
        let c = &self.counts;
        let n = c.triangles + c.edges + c.isolated;
        Ok(CanonCounts { bytes: n * REC_BYTES as u64, ..std::mem::take(&mut self.counts) })
    }
}

/// Reduces one bucket (the grid cell `key` at `bits` bits per axis) and writes the canonical
/// simplices whose smallest corner lies in it. A bucket too large is cut by a finer grid.
fn canonicalize(
    temp: &Temp,
    path: &Path,
    key: [u32; 3],
    p: u8,
    bits: u8,
    limit: u64,
    canon: &mut Canon,
) -> Result<(), NspError> {
    let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    if size / REC_BYTES as u64 > limit && bits + 2 <= p {
        let sub = Buckets::create(temp, &path.with_extension("d"), p, bits + 2)?;
        let mut reader = BufReader::with_capacity(1 << 20, File::open(path).map_err(tr)?);
        let mut b = [0u8; REC_BYTES];
        let inside = |q: [u32; 3]| (0..3).all(|a| q[a] >> (p - bits) == key[a]);
        while reader.read_exact(&mut b).is_ok() {
            // A record goes to the finer buckets of its corners inside this bucket (its
            // corners outside brought it to other buckets already).
            sub.put_where(&Rec::get(&b), inside)?;
        }
        sub.finish()?;
        for (sub_path, sub_key) in sub.files() {
            canonicalize(temp, &sub_path, sub_key, p, bits + 2, limit, canon)?;
            let _ = std::fs::remove_file(&sub_path);
        }
        let _ = std::fs::remove_dir(path.with_extension("d"));
        return Ok(());
    }
    let mut recs = read_recs(path)?;
    recs.sort_unstable_by_key(Rec::order);
    let inside = |q: [u32; 3]| (0..3).all(|a| q[a] >> (p - bits) == key[a]);
    let mut ids: HashMap<[u32; 3], u32> = HashMap::default();
    let mut coords: Vec<[u32; 3]> = Vec::new();
    let mut order: Vec<u32> = Vec::new();
    let mut simplices = Vec::with_capacity(recs.len());
    for r in &recs {
        let mut s = Simplex { v: [0; 3], dim: r.dim };
        for (k, &q) in r.corners().iter().enumerate() {
            s.v[k] = *ids.entry(q).or_insert_with(|| {
                coords.push(q);
                coords.len() as u32 - 1
            });
        }
        if r.dim == 2 {
            order.push(r.t);
        }
        simplices.push(s);
    }
    canon.counts.points += coords.iter().filter(|&&q| inside(q)).count() as u64;
    // `top_simplices` keeps triangles in first-occurrence order: the first of each is the
    // record of smallest `t` among its copies.
    let mut first_t: HashMap<[u32; 3], u32> = HashMap::default();
    for (s, r) in simplices.iter().zip(&recs) {
        let img = reduce(*s);
        if img.dim == 2 {
            first_t.entry(img.key()).or_insert(r.t);
        }
    }
    for s in top_simplices(coords.len(), simplices.into_iter()) {
        let corners: Vec<[u32; 3]> = s.verts().iter().map(|&v| coords[v as usize]).collect();
        let smallest = *corners.iter().min().expect("a simplex has a corner");
        if !inside(smallest) {
            continue;
        }
        let t = if s.dim == 2 { first_t[&s.key()] } else { u32::MAX };
        let mut q = [[0u32; 3]; 3];
        q[..corners.len()].copy_from_slice(&corners);
        Rec { t, dim: s.dim, q }.put(&mut canon.out).map_err(tw)?;
        match s.dim {
            2 => canon.counts.triangles += 1,
            1 => canon.counts.edges += 1,
            _ => canon.counts.isolated += 1,
        }
    }
    Ok(())
}

/// Streams a file of records, one at a time.
fn for_each_rec(path: &Path, mut f: impl FnMut(&Rec) -> Result<(), NspError>) -> Result<(), NspError> {
    let mut reader = BufReader::with_capacity(1 << 20, File::open(path).map_err(tr)?);
    let mut b = [0u8; REC_BYTES];
    loop {
        match reader.read_exact(&mut b) {
            Ok(()) => f(&Rec::get(&b))?,
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(tr(e)),
        }
    }
}

/// The tree of the in-core rule, from one counting pass per depth; also every cell's count
/// of simplices (border duplicates included), by (depth, coordinates).
fn partition(params: Params, canon: &Path, progress: &Progress) -> Result<(Tree, CellCounts), NspError> {
    let p = params.bits;
    let pl = params.level_bits();
    let mut counts: CellCounts = HashMap::default();
    let mut total = 0u64;
    for_each_rec(canon, |_| {
        total += 1;
        Ok(())
    })?;
    counts.insert((0, [0; 3]), total);
    let mut splitting: HashSet<[u32; 3]> = HashSet::default();
    if total >= params.min_simplices as u64 && params.max_prec_at(0) < p {
        splitting.insert([0; 3]);
    }
    let mut split_cells: HashSet<(u8, [u32; 3])> = splitting.iter().map(|&c| (0, c)).collect();
    let mut depth = 0u8;
    while !splitting.is_empty() {
        progress("partitioning", depth as u64 + 1, 0);
        let shift = p - pl * (depth + 1);
        let mut child: HashMap<[u32; 3], u64> = HashMap::default();
        for_each_rec(canon, |r| {
            let mut seen: [[u32; 3]; 3] = [[u32::MAX; 3]; 3];
            for (k, q) in r.corners().iter().enumerate() {
                let c = [q[0] >> shift, q[1] >> shift, q[2] >> shift];
                if seen[..k].contains(&c) {
                    continue;
                }
                seen[k] = c;
                if splitting.contains(&[c[0] >> pl, c[1] >> pl, c[2] >> pl]) {
                    *child.entry(c).or_default() += 1;
                }
            }
            Ok(())
        })?;
        depth += 1;
        let mut next = HashSet::default();
        for (&c, &n) in &child {
            counts.insert((depth, c), n);
            if n >= params.min_simplices as u64 && params.max_prec_at(depth) < p {
                next.insert(c);
                split_cells.insert((depth, c));
            }
        }
        // Every split cell makes n^3 cells, empty ones included: refused here, before the
        // tree, the cell table or the next depth's counts are made.
        params.check_cells(1 + split_cells.len() as u64 * params.fan_out() as u64)?;
        splitting = next;
    }
    // The tree in postorder, every split cell with all its children.
    let mut nodes: Vec<Node> = Vec::new();
    fn build(
        params: Params,
        split: &HashSet<(u8, [u32; 3])>,
        depth: u8,
        coords: [u32; 3],
        nodes: &mut Vec<Node>,
    ) -> u32 {
        let mut children = Vec::new();
        if split.contains(&(depth, coords)) {
            for k in 0..params.fan_out() {
                children.push(build(params, split, depth + 1, params.child_coords(coords, k), nodes));
            }
        }
        let id = nodes.len() as u32;
        for &ch in &children {
            nodes[ch as usize].parent = id;
        }
        nodes.push(Node { depth, coords, children, parent: u32::MAX });
        id
    }
    build(params, &split_cells, 0, [0; 3], &mut nodes);
    Ok((Tree { params, nodes }, counts))
}

/// Simplices per cell (border duplicates included), by (depth, coordinates).
type CellCounts = HashMap<(u8, [u32; 3]), u64>;

/// Batch files of leaves: each a run of leaves in postorder.
struct Batches {
    files: Vec<Batch>,
    bytes: u64,
}

struct Batch {
    path: PathBuf,
    /// The last cell (postorder) of the batch: cells up to it are done after it.
    last: u32,
}

impl Batches {
    fn write(
        temp: &Temp,
        tree: &Tree,
        counts: &CellCounts,
        canon: &Path,
        tmp: &Path,
        limit: u64,
    ) -> Result<Batches, NspError> {
        let n = tree.nodes.len();
        // Leaves into runs of at most BATCH_RECORDS records.
        let mut batch_of = vec![u32::MAX; n];
        let mut lasts: Vec<u32> = Vec::new();
        let mut filled = 0u64;
        for c in 0..n as u32 {
            if !tree.is_leaf(c) {
                continue;
            }
            let node = &tree.nodes[c as usize];
            let k = counts.get(&(node.depth, node.coords)).copied().unwrap_or(0);
            if lasts.is_empty() || (filled + k > limit && filled > 0) {
                lasts.push(c);
                filled = 0;
            }
            *lasts.last_mut().expect("a batch") = c;
            filled += k;
            batch_of[c as usize] = lasts.len() as u32 - 1;
        }
        let mut writers: Vec<BufWriter<TempFile>> = (0..lasts.len())
            .map(|i| temp.writer(&tmp.join(format!("batch-{i}")), 16 << 10))
            .collect::<Result<_, _>>()?;
        let params = tree.params;
        let leaf_of = |q: [u32; 3]| -> u32 {
            let mut c = tree.root();
            loop {
                let node = &tree.nodes[c as usize];
                if node.children.is_empty() {
                    return c;
                }
                let shift = params.bits - params.level_bits() * (node.depth + 1);
                let mask = params.splits - 1;
                let local = [(q[0] >> shift) & mask, (q[1] >> shift) & mask, (q[2] >> shift) & mask];
                c = node.children[params.child_index(local) as usize];
            }
        };
        let mut bytes = 0u64;
        for_each_rec(canon, |r| {
            let mut seen = [u32::MAX; 3];
            for (k, &q) in r.corners().iter().enumerate() {
                let leaf = leaf_of(q);
                if seen[..k].contains(&leaf) {
                    continue;
                }
                seen[k] = leaf;
                let w = &mut writers[batch_of[leaf as usize] as usize];
                w.write_all(&leaf.to_le_bytes()).map_err(tw)?;
                r.put(w).map_err(tw)?;
                bytes += 4 + REC_BYTES as u64;
            }
            Ok(())
        })?;
        for w in &mut writers {
            w.flush().map_err(tw)?;
        }
        let files =
            lasts.iter().enumerate().map(|(i, &last)| Batch { path: tmp.join(format!("batch-{i}")), last }).collect();
        Ok(Batches { files, bytes })
    }
}

/// What the output needs of a cell once it is encoded.
#[derive(Clone, Default)]
struct CellInfo {
    decisions: u64,
    level_ends: Vec<u32>,
    max_cells: u32,
    max_tops: u32,
    reach: [[u32; 3]; 2],
}

/// The postorder pass: cells done so far, and the partial parents' simplices.
struct Encoding {
    next: u32,
    cells: Vec<CellInfo>,
    /// Per internal cell not yet encoded: its children's simplices clustered at its maximal
    /// precision, their reach, and with the geometry advance their points `m` bits finer.
    pending: HashMap<u32, Pending>,
    decisions: BufWriter<TempFile>,
    counts: Vec<[u64; 2]>,
    leaf_simplices: u64,
}

/// What a cell's children hand it (see [`Encoding::pending`]).
struct Pending {
    members: Vec<Rec>,
    reach: [[u32; 3]; 2],
    fine: Vec<[u32; 3]>,
}

fn empty_pending() -> Pending {
    Pending { members: Vec::new(), reach: [[u32::MAX; 3], [0; 3]], fine: Vec::new() }
}

/// What a cell hands its parent: its simplices clustered at its minimal precision and, with
/// the advance, its points at the parent's geometry precision (distinct).
type Up = (Vec<Rec>, Vec<[u32; 3]>);

fn union(a: [[u32; 3]; 2], b: [[u32; 3]; 2]) -> [[u32; 3]; 2] {
    [[0, 1, 2].map(|k| a[0][k].min(b[0][k])), [0, 1, 2].map(|k| a[1][k].max(b[1][k]))]
}

impl Encoding {
    fn new(temp: &Temp, tree: &Tree, path: &Path) -> Result<Encoding, NspError> {
        Ok(Encoding {
            next: 0,
            cells: vec![CellInfo::default(); tree.nodes.len()],
            pending: HashMap::default(),
            decisions: temp.writer(path, 1 << 20)?,
            counts: vec![[0; 2]; CONTEXTS],
            leaf_simplices: 0,
        })
    }

    /// Encodes the leaves of `batch` (in parallel) and every cell before its last in postorder.
    fn batch(&mut self, tree: &Tree, batch: &Batch) -> Result<(), NspError> {
        let mut by_leaf: HashMap<u32, Vec<Rec>> = HashMap::default();
        let mut raw = Vec::new();
        File::open(&batch.path).and_then(|mut f| f.read_to_end(&mut raw)).map_err(tr)?;
        for b in raw.chunks_exact(4 + REC_BYTES) {
            let leaf = u32::from_le_bytes(b[..4].try_into().unwrap());
            by_leaf.entry(leaf).or_default().push(Rec::get(&b[4..]));
        }
        drop(raw);
        // Leaves first, in parallel; then the postorder walk uses their results.
        let leaves: Vec<(u32, Vec<Rec>)> = (self.next..=batch.last)
            .filter(|&c| tree.is_leaf(c))
            .map(|c| (c, by_leaf.remove(&c).unwrap_or_default()))
            .collect();
        let sizes: HashMap<u32, u64> = leaves.iter().map(|(c, m)| (*c, m.len() as u64)).collect();
        let mut done: HashMap<u32, (Recorded, Up)> =
            leaves.into_par_iter().map(|(c, members)| (c, encode_cell(tree, c, members, Vec::new()))).collect();
        for c in self.next..=batch.last {
            let (rec, up) = match done.remove(&c) {
                Some(r) => r,
                None => {
                    let p = self.pending.remove(&c).unwrap_or_else(empty_pending);
                    let (mut rec, up) = encode_cell(tree, c, p.members, p.fine);
                    rec.reach = p.reach;
                    (rec, up)
                }
            };
            self.leaf_simplices += sizes.get(&c).copied().unwrap_or(0);
            self.done(tree, c, rec, up)?;
        }
        self.next = batch.last + 1;
        Ok(())
    }

    /// Encodes the internal cells left before `end`.
    fn finish_to(&mut self, tree: &Tree, end: u32) -> Result<(), NspError> {
        for c in self.next..end {
            let p = self.pending.remove(&c).unwrap_or_else(empty_pending);
            let (mut rec, up) = encode_cell(tree, c, p.members, p.fine);
            rec.reach = p.reach;
            self.done(tree, c, rec, up)?;
        }
        self.next = end;
        Ok(())
    }

    /// Records cell `c`'s decisions, and hands its simplices and reach to its parent (an
    /// internal cell's reach is the union of its children's: the box of its simplices).
    fn done(&mut self, tree: &Tree, c: u32, rec: Recorded, (up, fine): Up) -> Result<(), NspError> {
        let reach = rec.reach;
        for &b in &rec.bits {
            self.counts[(b & 0x7fff) as usize][(b >> 15) as usize] += 1;
            self.decisions.write_all(&b.to_le_bytes()).map_err(tw)?;
        }
        self.cells[c as usize] = CellInfo {
            decisions: rec.bits.len() as u64,
            level_ends: rec.level_ends,
            max_cells: rec.max_cells,
            max_tops: rec.max_tops,
            reach,
        };
        let parent = tree.nodes[c as usize].parent;
        if parent != u32::MAX {
            let entry = self.pending.entry(parent).or_insert_with(empty_pending);
            entry.members.extend(up);
            entry.reach = union(entry.reach, reach);
            entry.fine.extend(fine);
        }
        Ok(())
    }
}

/// Encodes cell `c` from its simplices (at its maximal precision for an internal cell, at
/// full precision for a leaf) and, for an internal cell with the geometry advance, its
/// points at its geometry precision `min(q + m, p)` (repeats allowed); returns its decisions
/// and what it hands its parent ([`Up`]).
fn encode_cell(tree: &Tree, c: u32, mut members: Vec<Rec>, mut fine: Vec<[u32; 3]>) -> (Recorded, Up) {
    if members.is_empty() {
        return (Recorded::empty(), (Vec::new(), Vec::new()));
    }
    members.sort_unstable_by_key(Rec::order);
    let p = tree.params.bits;
    let m = tree.params.advance;
    let q = tree.max_prec(c);
    let leaf = tree.is_leaf(c);
    let have = if leaf { p } else { q };
    let fine_bits = (q + m).min(p);
    if m > 0 && leaf {
        fine = members.iter().flat_map(|r| r.corners().iter().copied()).collect();
    }
    fine.sort_unstable();
    fine.dedup();
    // An internal cell's reach computed here is at its maximal precision; the caller
    // replaces it with its children's.
    let rec = record_local(tree, c, members.iter().map(|r| (r.dim, r.q)), have - q, (m > 0).then_some(&fine[..]));
    // For the parent: the simplices clustered at this cell's minimal precision, each once,
    // with the order of its first copy; with the advance, the points at the parent's
    // geometry precision (the parent's simplices are its children's, so are its points).
    let min = tree.min_prec(c);
    let down = have - min;
    let up_fine = if m > 0 {
        let shift = fine_bits - (min + m).min(p);
        let mut f: Vec<[u32; 3]> = fine.iter().map(|g| g.map(|x| x >> shift)).collect();
        f.dedup();
        f
    } else {
        Vec::new()
    };
    drop(fine);
    let mut seen: HashSet<(u8, [[u32; 3]; 3])> = HashSet::default();
    let mut up = Vec::new();
    for r in &members {
        let mut img = Rec { t: r.t, dim: r.dim, q: [[0; 3]; 3] };
        for (k, g) in r.corners().iter().enumerate() {
            img.q[k] = [g[0] >> down, g[1] >> down, g[2] >> down];
        }
        let img = reduce_rec(img);
        let mut key = img.q;
        key[..img.dim as usize + 1].sort_unstable();
        if seen.insert((img.dim, key)) {
            up.push(img);
        }
    }
    (rec, (up, up_fine))
}

/// A record reduced to its image when corners coincide (orientation kept), as `reduce`.
fn reduce_rec(r: Rec) -> Rec {
    let mut ids = [[0u32; 3]; 3];
    let mut n = 0;
    let mut s = Simplex { v: [0; 3], dim: r.dim };
    for (k, q) in r.corners().iter().enumerate() {
        let i = match ids[..n].iter().position(|x| x == q) {
            Some(i) => i,
            None => {
                ids[n] = *q;
                n += 1;
                n - 1
            }
        };
        s.v[k] = i as u32;
    }
    let s = reduce(s);
    let mut out = Rec { t: if s.dim == 2 { r.t } else { u32::MAX }, dim: s.dim, q: [[0; 3]; 3] };
    for (k, &v) in s.verts().iter().enumerate() {
        out.q[k] = ids[v as usize];
    }
    out
}
