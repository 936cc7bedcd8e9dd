//! Level of detail in the compression domain: a chunked file whose chunks form a hierarchy
//! (a DAG of simplification groups, as Nanite's clusters do), so that a frame sorts a cut
//! of chunks whose error projects under `--error-px` instead of the whole model.
//!
//! # The hierarchy
//!
//! The first `level0` chunks are the full-resolution model, as a flat chunked file holds it.
//! A **group** takes a few adjacent chunks of one level (its inputs), simplifies their
//! triangles together to about half with every vertex that a chunk outside the group uses
//! locked in place, and cuts the result into chunks of the next level (its outputs). Every
//! chunk is made by at most one group (its *producer*; none at level 0) and simplified by at
//! most one (its *consumer*; none for a root). A group stores its object-space error (the
//! simplifier's, and never below its inputs' producers') and a sphere that holds its
//! vertices and its inputs' producers' spheres.
//!
//! # The cut
//!
//! A group's error projects to `error * scale / w`, with `w` the nearest clip-space depth of
//! its sphere (infinite where the sphere reaches the eye plane). A chunk is in the cut when
//! its producer's error projects to at most `error_px` pixels and its consumer's does not
//! (a root's consumer is infinitely coarse, a level-0 chunk's producer exact). Since a
//! group's sphere holds its inputs' producers' spheres and its error is no smaller, the
//! projection only grows toward the roots, so for every group either its inputs or its
//! outputs (or neither, when a coarser group stands for both) are drawn, never both: the cut
//! covers the surface once. Where an input and an output meet, they meet on the group's
//! locked border, whose vertices both hold at the same quantized positions, so the cut has
//! no cracks (tested on closed meshes).
//!
//! # Layout (version 5)
//!
//! A version 5 file is a version 3 file (`super`) with this section between the directory's
//! checksum and the first chunk:
//! ```text
//! 4       level0: chunks of the full-resolution model (the first ones)
//! 4       G: groups
//! 20*G    per group: error, sphere centre (3), radius, all f32 LE
//! 8*C     per chunk: producer group, consumer group (u32 LE; 0xFFFFFFFF for none)
//! 4       CRC-32 of the section
//! ```
//! The header's counts (triangles, slots, border entries, unique vertices) are level 0's:
//! the model's. A chunk above level 0 stores its vertices' full-resolution normals in its
//! stream (every vertex of a simplified chunk is an input vertex), so it shades as the
//! surface it stands for and meets its neighbours of any level without a seam; its border
//! table is empty.

use std::io;

use glam::{Mat4, Vec3, Vec4};
use rayon::prelude::*;

use super::error::{chunk_err, corrupt};
use super::partition::{localize, split, vertices_of};
use super::spill::{batches, ChunkWriter, Chunks};
use crate::container::FormatError;
use crate::csr::Csr;

/// "No group": a level-0 chunk's producer, a root's consumer.
pub const NONE: u32 = u32::MAX;
const GROUP_LEN: usize = 20;
/// Chunks a group takes, at most (Nanite groups 8-32 clusters of 128 triangles; a chunk
/// holds thousands, so a group of four simplifies 16K triangles to two chunks).
pub const GROUP_CHUNKS: usize = 4;
/// Times a group is simplified again with more vertices locked where the simplifier pinched
/// it, before it is simplified less.
const PINCH_RETRIES: usize = 4;
/// A group's error limit, in mean edge lengths of its input: a group that cannot halve
/// within it simplifies less. Without a limit, the few groups that must collapse a feature
/// to halve (a thin part) take errors far above their level's, and since a group's error is
/// raised to its inputs', those spread to nearly every group above: the errors plateau and
/// the cut hardly shrinks with distance (the 13.9M-triangle dragon at 1 px from 1, 2, 4 and
/// 8 model sizes away: 2.25M, 1.17M, 0.61M and 0.41M triangles; with the limit 2.23M,
/// 0.92M, 0.26M and 0.08M, for a file 3.8% larger). Raising the limit for the groups that
/// cannot halve brought the plateau back (0.15M at 8 sizes); a level that hardly shrinks is
/// built again with a limit 4 times looser for all its groups, up to [`EDGE_ERROR_MAX`],
/// then without one, so that a coarse model still reaches a few roots.
const EDGE_ERROR: f32 = 0.5;
const EDGE_ERROR_MAX: f32 = 32.0;
/// The simplifier's options. Errors are absolute (object units, so groups compare). Clamped:
/// without it a group's error was its normals' where they vary most, up to 3 object units on
/// the 223M-triangle model 0.2 across (its subdivision's noise), so the cut kept levels 1-3
/// everywhere; clamped to the scale of the position error, the 13.9M model's root error is
/// 0.017 instead of 1.2, and the dragon keeps its 99.2-99.4% of pixels at 1 px. Regularized
/// lightly: rounder triangles, which predict better (the 13.9M file 1.4% smaller).
const SIMPLIFY_OPTIONS: meshopt::SimplifyOptions = meshopt::SimplifyOptions::ErrorAbsolute
    .union(meshopt::SimplifyOptions::ErrorClamped)
    .union(meshopt::SimplifyOptions::RegularizeLight);

/// The default weight of normals in the simplifier's error, against positions scaled to the
/// group's extent: a group's error then grows where its shading would change, and the cut
/// keeps finer chunks there. Measured on the dragon at 1920x1080, `--error-px 1`, three
/// views (docs/results.md, "Level of detail"): weight 0 draws 76K triangles with 85-87% of
/// covered pixels within 8/255 of the full model's frame, 0.5 draws 111K with 95.5-96.3%, 1
/// draws 210K with 98.2-98.6%, 2 draws 322K with 99.3-99.4%, 8 the whole model.
pub const NORMAL_WEIGHT: f32 = 2.0;

/// A simplification group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Group {
    /// Object-space error of the group's outputs against the full-resolution surface.
    pub error: f32,
    pub center: [f32; 3],
    pub radius: f32,
}

/// A file's hierarchy (see the module doc).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Hierarchy {
    pub level0: u32,
    pub groups: Vec<Group>,
    pub producer: Vec<u32>,
    pub consumer: Vec<u32>,
}

/// One level of a hierarchy, as `tessera stats` reports it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LevelSummary {
    pub chunks: u32,
    pub triangles: u64,
    /// Bytes of its chunks (streams and border tables).
    pub bytes: u64,
    /// Of them: the streams' connectivity (commands, offsets, seeds), geometry (positions),
    /// attributes (normals above level 0; colours, normals and vertex order as the input
    /// had), and the border tables; the rest is the streams' headers.
    pub connectivity_bytes: u64,
    pub geometry_bytes: u64,
    pub attribute_bytes: u64,
    pub border_bytes: u64,
    /// The largest error of a group that made one of its chunks (object units; 0 at level 0).
    pub max_error: f32,
}

/// What a view needs to project a group's error: the clip-space `w` row and pixels per
/// object unit at `w = 1`.
#[derive(Clone, Copy, Debug)]
pub struct Projection {
    w_row: Vec4,
    w_norm: f32,
    scale: f32,
}

impl Projection {
    /// For `view_proj` on a frame `height` pixels tall.
    pub fn new(view_proj: Mat4, height: u32) -> Projection {
        let w_row = view_proj.row(3);
        let y_row = view_proj.row(1);
        Projection { w_row, w_norm: w_row.truncate().length(), scale: 0.5 * height as f32 * y_row.truncate().length() }
    }
}

impl Hierarchy {
    /// Bytes of the section for `chunks` chunks and `groups` groups.
    pub fn section_len(chunks: usize, groups: usize) -> usize {
        8 + GROUP_LEN * groups + 8 * chunks + 4
    }

    /// The section's bytes, checksum included.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(Self::section_len(self.producer.len(), self.groups.len()));
        b.extend_from_slice(&self.level0.to_le_bytes());
        b.extend_from_slice(&(self.groups.len() as u32).to_le_bytes());
        for g in &self.groups {
            for v in [g.error, g.center[0], g.center[1], g.center[2], g.radius] {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        for (p, c) in self.producer.iter().zip(&self.consumer) {
            b.extend_from_slice(&p.to_le_bytes());
            b.extend_from_slice(&c.to_le_bytes());
        }
        let crc = crc32fast::hash(&b);
        b.extend_from_slice(&crc.to_le_bytes());
        b
    }

    /// The group count a section starting with `head` (its first 8 bytes) declares.
    pub(crate) fn groups_in(head: &[u8]) -> u32 {
        u32::from_le_bytes(head[4..8].try_into().unwrap())
    }

    /// Parses and checks a section of a file of `chunks` chunks (`b` exactly its bytes).
    pub(crate) fn from_bytes(b: &[u8], chunks: usize) -> Result<Hierarchy, FormatError> {
        if b.len() < 12 {
            return Err(FormatError::Truncated("level-of-detail hierarchy"));
        }
        let (body, crc) = b.split_at(b.len() - 4);
        if u32::from_le_bytes(crc.try_into().unwrap()) != crc32fast::hash(body) {
            return Err(FormatError::Checksum("level-of-detail hierarchy"));
        }
        let u = |off: usize| u32::from_le_bytes(body[off..off + 4].try_into().unwrap());
        let f = |off: usize| f32::from_le_bytes(body[off..off + 4].try_into().unwrap());
        let (level0, groups) = (u(0), u(4) as usize);
        if body.len() != 8 + GROUP_LEN * groups + 8 * chunks {
            return Err(corrupt(format!(
                "the hierarchy section is {} bytes, not those of {groups} groups and {chunks} chunks",
                b.len()
            )));
        }
        let groups: Vec<Group> = (0..groups)
            .map(|g| {
                let o = 8 + GROUP_LEN * g;
                Group { error: f(o), center: [f(o + 4), f(o + 8), f(o + 12)], radius: f(o + 16) }
            })
            .collect();
        let o = 8 + GROUP_LEN * groups.len();
        let producer = (0..chunks).map(|i| u(o + 8 * i)).collect();
        let consumer = (0..chunks).map(|i| u(o + 8 * i + 4)).collect();
        let h = Hierarchy { level0, groups, producer, consumer };
        h.check()?;
        Ok(h)
    }

    /// Checks the hierarchy, naming the chunk at fault: level 0 first and made by no group,
    /// groups in range, each group's outputs after all of its inputs (so no cycle), finite
    /// errors and spheres, and errors and spheres that never shrink toward the roots.
    pub fn check(&self) -> Result<(), FormatError> {
        let chunks = self.producer.len();
        let groups = self.groups.len();
        if self.level0 == 0 || self.level0 as usize > chunks {
            return Err(corrupt(format!("the hierarchy's level 0 has {} of {chunks} chunks", self.level0)));
        }
        let (mut last_input, mut first_output) = (vec![None::<usize>; groups], vec![None::<usize>; groups]);
        for i in 0..chunks {
            let (p, c) = (self.producer[i], self.consumer[i]);
            for (what, g) in [("producer", p), ("consumer", c)] {
                if g != NONE && g as usize >= groups {
                    return Err(chunk_err(i, format!("its {what} group {g} is out of range ({groups} groups)")));
                }
            }
            if (i < self.level0 as usize) != (p == NONE) {
                return Err(chunk_err(
                    i,
                    if p == NONE {
                        "it is above level 0 and no group made it"
                    } else {
                        "it is in level 0 and a group made it"
                    },
                ));
            }
            if p != NONE {
                first_output[p as usize].get_or_insert(i);
            }
            if c != NONE {
                last_input[c as usize] = Some(i);
            }
        }
        for (g, group) in self.groups.iter().enumerate() {
            let name = first_output[g].or(last_input[g]);
            let err = |msg: String| match name {
                Some(i) => chunk_err(i, msg),
                None => corrupt(format!("group {g}: {msg}")),
            };
            match (last_input[g], first_output[g]) {
                (Some(last), Some(first)) if last >= first => {
                    return Err(chunk_err(
                        first,
                        format!("group {g} makes it from chunk {last}, which does not come before it (the hierarchy has a cycle)"),
                    ))
                }
                (Some(_), Some(_)) => {}
                _ => return Err(err(format!("group {g} has no input or no output chunk"))),
            }
            let finite =
                group.error.is_finite() && group.radius.is_finite() && group.center.iter().all(|c| c.is_finite());
            if !finite || group.error < 0.0 || group.radius < 0.0 {
                return Err(err(format!("group {g}'s error or sphere is not finite and non-negative")));
            }
        }
        for i in 0..chunks {
            let (p, c) = (self.producer[i], self.consumer[i]);
            if p == NONE || c == NONE {
                continue;
            }
            let (own, parent) = (&self.groups[p as usize], &self.groups[c as usize]);
            if parent.error < own.error {
                return Err(chunk_err(
                    i,
                    format!(
                        "its error {} is above its parent group's {} (errors shrink toward the root)",
                        own.error, parent.error
                    ),
                ));
            }
            let reach = Vec3::from(own.center).distance(Vec3::from(parent.center)) + own.radius;
            if reach > parent.radius * (1.0 + 1e-5) + 1e-6 {
                return Err(chunk_err(i, "its parent group's sphere does not hold its own"));
            }
        }
        Ok(())
    }

    /// Group `g`'s error in pixels under `p` (infinite for [`NONE`] and where the sphere
    /// reaches the eye plane).
    pub fn projected(&self, g: u32, p: &Projection) -> f32 {
        let Some(group) = self.groups.get(g as usize) else { return f32::INFINITY };
        let w = p.w_row.dot(Vec3::from(group.center).extend(1.0)) - group.radius * p.w_norm;
        if w <= 1e-6 {
            f32::INFINITY
        } else {
            group.error * p.scale / w
        }
    }

    /// Whether chunk `i` is in the cut at `error_px` (see the module doc).
    pub fn in_cut(&self, i: usize, p: &Projection, error_px: f32) -> bool {
        let own = if self.producer[i] == NONE { 0.0 } else { self.projected(self.producer[i], p) };
        own <= error_px && self.projected(self.consumer[i], p) > error_px
    }

    /// Each chunk's level: 0 for the model's, else one above its producer's inputs'.
    pub fn levels(&self) -> Vec<u32> {
        let mut group_level = vec![0u32; self.groups.len()];
        let mut level = vec![0u32; self.producer.len()];
        // Inputs come before their group's outputs (checked), so one pass in chunk order.
        for i in 0..self.producer.len() {
            if self.producer[i] != NONE {
                level[i] = group_level[self.producer[i] as usize];
            }
            if self.consumer[i] != NONE {
                let g = &mut group_level[self.consumer[i] as usize];
                *g = (*g).max(level[i] + 1);
            }
        }
        level
    }
}

/// What [`build`] made above level 0.
pub(super) struct Built {
    /// The levels above level 0, in order (their chunks follow level 0's in the file).
    pub levels: Vec<Chunks>,
    pub hierarchy: Hierarchy,
}

/// The model's vertices as the hierarchy's build reads them, by input vertex.
pub(super) struct Vertices<'a> {
    /// How many there are.
    pub count: usize,
    /// Where a vertex is drawn (its quantized position).
    pub position: &'a (dyn Fn(u32) -> [f32; 3] + Sync),
    /// Its full-resolution normal.
    pub normal: &'a (dyn Fn(u32) -> [f32; 3] + Sync),
}

/// A set of vertices, one bit each: a level's locked vertices, looked up for every vertex of
/// every group (a binary search of a sorted list of them there took 8% of gathering a
/// group's triangles).
pub(super) struct Bits(Vec<u64>);

impl Bits {
    fn new(n: usize) -> Bits {
        Bits(vec![0; n.div_ceil(64)])
    }

    fn set(&mut self, v: u32) {
        self.0[v as usize / 64] |= 1 << (v % 64);
    }

    fn get(&self, v: u32) -> bool {
        self.0[v as usize / 64] >> (v % 64) & 1 != 0
    }
}

fn sphere_of(positions: &[[f32; 3]]) -> (Vec3, f32) {
    let (lo, hi) = crate::mesh::bounding_box(positions.iter()).unwrap_or(([0.0; 3], [0.0; 3]));
    let c = (Vec3::from(lo) + Vec3::from(hi)) * 0.5;
    let r = positions.iter().map(|&p| Vec3::from(p).distance(c)).fold(0.0f32, f32::max);
    (c, r)
}

/// The vertices that several chunks of `chunks` use, each with every chunk that uses it, as
/// sorted `(vertex, chunk)` pairs. One pass over the level, with a chunk number per vertex of
/// the model.
fn shared(chunks: &Chunks, vertices: usize) -> io::Result<Vec<(u32, u32)>> {
    let mut owner = vec![NONE; vertices];
    let mut pairs = Vec::new();
    for batch in batches(chunks.len()) {
        let used: Vec<Vec<u32>> =
            batch.clone().into_par_iter().map(|c| Ok(vertices_of(&chunks.read(c)?))).collect::<io::Result<_>>()?;
        for (c, used) in batch.zip(used) {
            for v in used {
                match owner[v as usize] {
                    NONE => owner[v as usize] = c as u32,
                    first => pairs.extend([(v, first), (v, c as u32)]),
                }
            }
        }
    }
    pairs.par_sort_unstable();
    pairs.dedup();
    Ok(pairs)
}

/// Groups the chunks of a level by adjacency: from each ungrouped chunk in file order
/// (spatial order), the ungrouped neighbour sharing most vertices with the group joins it,
/// up to [`GROUP_CHUNKS`].
fn group_chunks(chunks: usize, users: &[(u32, u32)]) -> Vec<Vec<u32>> {
    let mut adjacency: Vec<rustc_hash::FxHashMap<u32, u32>> = vec![Default::default(); chunks];
    for run in users.chunk_by(|a, b| a.0 == b.0) {
        for a in run {
            for b in run {
                if a.1 != b.1 {
                    *adjacency[a.1 as usize].entry(b.1).or_insert(0) += 1;
                }
            }
        }
    }
    let mut grouped = vec![false; chunks];
    let mut groups = Vec::new();
    for start in 0..chunks {
        if grouped[start] {
            continue;
        }
        grouped[start] = true;
        let mut members = vec![start as u32];
        let mut weight: rustc_hash::FxHashMap<u32, u32> = Default::default();
        while members.len() < GROUP_CHUNKS {
            for (&n, &w) in &adjacency[*members.last().unwrap() as usize] {
                if !grouped[n as usize] {
                    *weight.entry(n).or_insert(0) += w;
                }
            }
            weight.retain(|n, _| !grouped[*n as usize]);
            let Some((&best, _)) = weight.iter().max_by_key(|(&n, &w)| (w, std::cmp::Reverse(n))) else { break };
            grouped[best as usize] = true;
            members.push(best);
        }
        members.sort_unstable();
        groups.push(members);
    }
    groups
}

/// Welds a group's unlocked vertices into a vertex at the same position (a locked one where
/// there is one), and drops the triangles that become degenerate. The simplifier takes
/// distinct vertices at one position for a seam, which it collapses only along the seam:
/// the input's coincident vertices (the dragon's 27.6K, and every midpoint between them in
/// its subdivisions) then survive every level, and the hierarchy stops shrinking (on the
/// 13.9M-triangle dragon, half of the top level's vertices were such). Locked vertices keep
/// their own index, so chunks meet by vertex as before; and since an unlocked vertex is no
/// neighbour of a border vertex, welding it gives no vertex a new border neighbour.
fn weld_unlocked(local: &mut Vec<u32>, pos: &[[f32; 3]], lock: &[bool]) {
    // By position, then locked first, then by vertex: one integer a vertex (its position's
    // bits above the unlocked flag and the index), so that the sort compares plain integers.
    debug_assert!(pos.len() < 1 << 31);
    let mut order: Vec<u128> = (0..pos.len())
        .map(|v| {
            let [x, y, z] = pos[v].map(|c| c.to_bits() as u128);
            x << 96 | y << 64 | z << 32 | ((!lock[v]) as u128) << 31 | v as u128
        })
        .collect();
    order.sort_unstable();
    let vertex = |k: u128| (k as u32) & 0x7fff_ffff;
    let mut to: Vec<u32> = (0..pos.len() as u32).collect();
    for run in order.chunk_by(|&a, &b| a >> 32 == b >> 32) {
        for &k in &run[1..] {
            if !lock[vertex(k) as usize] {
                to[vertex(k) as usize] = vertex(run[0]);
            }
        }
    }
    let welded: Vec<u32> = local.iter().map(|&v| to[v as usize]).collect();
    local.clear();
    local.extend(welded.chunks_exact(3).filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]).flatten());
}

/// A group simplified: its chunks of the next level, its error and its vertices' sphere.
struct Simplified {
    leaves: Vec<Vec<[u32; 3]>>,
    error: f32,
    center: Vec3,
    radius: f32,
}

/// The mean edge length of `indices` (a triangle list) on `pos`, each edge counted once a
/// face.
fn mean_edge(indices: &[u32], pos: &[[f32; 3]]) -> f32 {
    let mut sum = 0.0f64;
    for t in indices.chunks_exact(3) {
        for k in 0..3 {
            sum += Vec3::from(pos[t[k] as usize]).distance(Vec3::from(pos[t[(k + 1) % 3] as usize])) as f64;
        }
    }
    (sum / indices.len().max(1) as f64) as f32
}

/// The undirected edges of `tris` (over `vertices` vertices) to which they give more than
/// two faces, sorted, with their face counts. Edges are grouped by their lower vertex
/// ([`Csr`]), where each group holds a few.
fn crowded_edges(tris: &[[u32; 3]], vertices: usize) -> Vec<(u64, u32)> {
    let mut by_lower = Csr::build(vertices, || {
        tris.iter().flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
    });
    let mut crowded = Vec::new();
    for a in 0..vertices {
        let others = &mut by_lower.values[by_lower.start[a] as usize..by_lower.start[a + 1] as usize];
        if others.len() > 2 {
            others.sort_unstable();
            for run in others.chunk_by(|x, y| x == y).filter(|run| run.len() > 2) {
                crowded.push(((a as u64) << 32 | run[0] as u64, run.len() as u32));
            }
        }
    }
    crowded
}

/// The edges to which `out` gives more faces than two and than the `input` (a triangle
/// list; both over `vertices` vertices) gives them, sorted, each as its two ends (lower
/// first): the simplifier can squash a thin part into two sheets that share an edge (found
/// on the armadillo: an edge of four faces in one group's output), which no cut may draw.
/// The input's faces are counted only on those edges, which are few (maps of every input
/// and output edge were 4% of a hierarchy's build in `perf`).
fn pinched_edges(input: &[u32], out: &[[u32; 3]], vertices: usize) -> Vec<[u32; 2]> {
    let crowded = crowded_edges(out, vertices);
    if crowded.is_empty() {
        return Vec::new();
    }
    let mut before = vec![0u32; crowded.len()];
    for t in input.chunks_exact(3) {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b) as u64) << 32 | a.max(b) as u64;
            if let Ok(i) = crowded.binary_search_by_key(&key, |e| e.0) {
                before[i] += 1;
            }
        }
    }
    crowded
        .iter()
        .zip(&before)
        .filter(|((_, after), &before)| *after > before)
        .map(|(&(e, _), _)| [(e >> 32) as u32, e as u32])
        .collect()
}

/// Mends the `pinched` edges of a group's simplified triangles `out` (its welded `input`,
/// both over `pos`) by collapsing each edge onto one of its ends: the two sheets the
/// simplifier squashed onto the edge (a collapse that the link condition would have
/// refused) then meet at a vertex, as the welded input's sheets do where they touch. The
/// removed end must be free to move (not `lock`ed), the kept one off the group's `border`
/// (so that no new edge reaches the border), and no triangle may turn over; an edge whose
/// one end breaks a rule goes the other way. Returns the mended triangles and the
/// collapses' error, or `None` where an edge can go neither way; the caller checks the
/// result for pinches again.
fn unpinch(
    input: &[u32],
    out: &[[u32; 3]],
    pinched: &[[u32; 2]],
    lock: &[bool],
    border: &[bool],
    pos: &[[f32; 3]],
) -> Option<(Vec<[u32; 3]>, f32)> {
    let mut to: Vec<u32> = (0..pos.len() as u32).collect();
    let find = |to: &[u32], mut v: u32| {
        while to[v as usize] != v {
            v = to[v as usize];
        }
        v
    };
    let p = |v: u32| Vec3::from(pos[v as usize]);
    let normal = |t: [u32; 3]| (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
    // Whether moving `gone` onto `keep` (after the collapses chosen so far) turns over a
    // triangle that keeps its area.
    let turns = |to: &[u32], gone: u32, keep: u32| {
        out.iter().any(|&t| {
            let now = t.map(|v| find(to, v));
            if !now.contains(&gone) || now.contains(&keep) {
                return false;
            }
            let then = now.map(|v| if v == gone { keep } else { v });
            normal(now).dot(normal(then)) < 0.0
        })
    };
    for &[a, b] in pinched {
        let (a, b) = (find(&to, a), find(&to, b));
        if a == b {
            continue;
        }
        let (keep, gone) = [(a, b), (b, a)]
            .into_iter()
            .find(|&(keep, gone)| !lock[gone as usize] && !border[keep as usize] && !turns(&to, gone, keep))?;
        to[gone as usize] = keep;
    }
    // The collapses' error measured as the simplifier measures its own: how far each
    // removed vertex's new place lies off the planes of its triangles in the input.
    let mut moved = 0.0f32;
    for t in input.chunks_exact(3) {
        let t = [t[0], t[1], t[2]];
        for v in t {
            let k = find(&to, v);
            if k != v {
                moved = moved.max(normal(t).normalize_or_zero().dot(p(k) - p(v)).abs());
            }
        }
    }
    let mut mended: Vec<[u32; 3]> =
        out.iter().map(|t| t.map(|v| find(&to, v))).filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]).collect();
    cancel_folds(&mut mended);
    Some((mended, moved))
}

/// Removes pairs of triangles on the same three vertices facing opposite ways: the
/// simplifier folds a thin part flat into such a pair, which gives its edges three or four
/// faces and covers no area.
fn cancel_folds(tris: &mut Vec<[u32; 3]>) {
    let key = |t: &[u32; 3]| {
        let mut k = *t;
        k.sort_unstable();
        k
    };
    // Each triangle's first triangle on the same vertices; the few repeats are listed apart
    // (a list per triangle, and maps that grew as they filled, made this and the pinch check
    // three times slower on the 13.9M-triangle dragon's build).
    let mut first: rustc_hash::FxHashMap<[u32; 3], u32> =
        rustc_hash::FxHashMap::with_capacity_and_hasher(tris.len(), Default::default());
    let mut repeats: Vec<(u32, u32)> = Vec::new();
    for (i, t) in tris.iter().enumerate() {
        match first.entry(key(t)) {
            std::collections::hash_map::Entry::Occupied(o) => repeats.push((*o.get(), i as u32)),
            std::collections::hash_map::Entry::Vacant(v) => {
                v.insert(i as u32);
            }
        }
    }
    if repeats.is_empty() {
        return;
    }
    repeats.sort_unstable();
    let mut drop = vec![false; tris.len()];
    for run in repeats.chunk_by(|a, b| a.0 == b.0) {
        let same = std::iter::once(run[0].0).chain(run.iter().map(|r| r.1));
        // A rotation of the sorted vertices keeps the orientation; the others reverse it.
        let facing = |t: &[u32; 3]| {
            let k = key(t);
            (0..3).any(|r| [t[r], t[(r + 1) % 3], t[(r + 2) % 3]] == k)
        };
        let (mut up, mut down): (Vec<u32>, Vec<u32>) = same.partition(|&i| facing(&tris[i as usize]));
        while let (Some(a), Some(b)) = (up.pop(), down.pop()) {
            drop[a as usize] = true;
            drop[b as usize] = true;
        }
    }
    let mut i = 0;
    tris.retain(|_| {
        i += 1;
        !drop[i - 1]
    });
}

/// Builds the hierarchy above `level0` (the model's chunks, triangles on input vertices):
/// levels of groups simplified with `meshopt`'s simplifier, borders locked, until one chunk
/// is left or a level no longer shrinks by an eighth. `target` is the chunk size; `weight`
/// the normals' weight in the simplifier's error ([`NORMAL_WEIGHT`], 0 for positions
/// alone); each level is spilled to a [`ChunkWriter`] that `spill` makes.
///
/// Out of core: a level is read chunk by chunk, twice (once for which chunks share
/// vertices, once to simplify its groups a batch at a time), and written as it is made, so
/// that memory holds 4 bytes per vertex of the model while a level's shared vertices are
/// found, its shared vertices, its directory and a bit per vertex of the model (the locked
/// ones), and one batch of groups.
pub(super) fn build(
    vertices: &Vertices,
    level0: &Chunks,
    target: usize,
    weight: f32,
    spill: &dyn Fn() -> io::Result<ChunkWriter>,
    progress: &mut dyn FnMut(u64),
) -> io::Result<Built> {
    let mut levels: Vec<Chunks> = Vec::new();
    let mut groups: Vec<Group> = Vec::new();
    let mut producer: Vec<u32> = vec![NONE; level0.len()];
    let mut consumer: Vec<u32> = vec![NONE; level0.len()];
    let mut done = 0u64;
    let mut edge_error = EDGE_ERROR;
    loop {
        let level = levels.last().unwrap_or(level0);
        if level.len() <= 1 {
            break;
        }
        // The level's chunks are the last ones made: their numbers in the file start here.
        let first = producer.len() - level.len();
        let level_users = shared(level, vertices.count)?;
        let grouping = group_chunks(level.len(), &level_users);
        let mut group_of = vec![0u32; level.len()];
        for (g, members) in grouping.iter().enumerate() {
            for &c in members {
                group_of[c as usize] = g as u32;
            }
        }
        // A vertex used by chunks of two groups is locked in both.
        let mut locked = Bits::new(vertices.count);
        for run in level_users.chunk_by(|a, b| a.0 == b.0) {
            if run.iter().any(|p| group_of[p.1 as usize] != group_of[run[0].1 as usize]) {
                locked.set(run[0].0);
            }
        }
        drop(level_users);
        drop(group_of);
        let before = level.triangles();
        // Where the level hardly shrinks within the limit: again with a looser one (the same
        // for every group of the level, so that their errors stay alike), then without.
        let (next, made, next_producer) = loop {
            let attempt = simplify_level(
                vertices,
                level,
                &grouping,
                &locked,
                &producer[first..],
                &groups,
                target,
                weight,
                edge_error,
                spill,
            )?;
            if attempt.0.triangles() * 8 <= before * 7 || !edge_error.is_finite() {
                break attempt;
            }
            edge_error = if edge_error < EDGE_ERROR_MAX { edge_error * 4.0 } else { f32::INFINITY };
        };
        if next.triangles() * 8 > before * 7 {
            break;
        }
        for (g, members) in grouping.iter().enumerate() {
            for &c in members {
                consumer[first + c as usize] = (groups.len() + g) as u32;
            }
        }
        groups.extend(made);
        consumer.resize(consumer.len() + next_producer.len(), NONE);
        producer.extend(next_producer);
        levels.push(next);
        done += before;
        progress(done);
    }
    let hierarchy = Hierarchy { level0: level0.len() as u32, groups, producer, consumer };
    debug_assert!(hierarchy.check().is_ok(), "{:?}", hierarchy.check());
    Ok(Built { levels, hierarchy })
}

/// Simplifies each group of `level` (`grouping`, its `locked` vertices) within `edge_error`
/// ([`simplify`]) and spills the next level: its chunks, the groups made (numbered after
/// `groups`; each error and sphere covers its inputs' producers', `producer` by chunk of
/// `level`), and each new chunk's producer.
#[allow(clippy::too_many_arguments)]
fn simplify_level(
    vertices: &Vertices,
    level: &Chunks,
    grouping: &[Vec<u32>],
    locked: &Bits,
    producer: &[u32],
    groups: &[Group],
    target: usize,
    weight: f32,
    edge_error: f32,
    spill: &dyn Fn() -> io::Result<ChunkWriter>,
) -> io::Result<(Chunks, Vec<Group>, Vec<u32>)> {
    let mut next = spill()?;
    let (mut made, mut next_producer) = (Vec::new(), Vec::new());
    for batch in batches(grouping.len()) {
        let results: Vec<Simplified> = grouping[batch.clone()]
            .par_iter()
            .map(|members| simplify(vertices, level, members, locked, target, weight, edge_error))
            .collect::<io::Result<_>>()?;
        for (g, (Simplified { leaves, error, center, radius }, members)) in
            batch.clone().zip(results.into_iter().zip(&grouping[batch]))
        {
            // The group's error and sphere cover its inputs' producers'.
            let (mut error, mut center, mut radius) = (error, center, radius);
            for &c in members {
                let p = producer[c as usize];
                if p != NONE {
                    let child = groups[p as usize];
                    error = error.max(child.error);
                    let (cc, cr) = (Vec3::from(child.center), child.radius);
                    let d = cc.distance(center);
                    if cr >= d + radius {
                        (center, radius) = (cc, cr);
                    } else if d + cr > radius {
                        // The smallest sphere holding both.
                        let new_r = (radius + d + cr) * 0.5;
                        if d > 0.0 {
                            center += (cc - center) * ((new_r - radius) / d);
                        }
                        radius = new_r;
                    }
                }
            }
            // Room for the rounding of the checks and of the reader's projection.
            radius = radius * (1.0 + 1e-5) + 1e-6 * center.abs().max_element();
            made.push(Group { error, center: center.to_array(), radius });
            for leaf in leaves {
                next.push(leaf.into_iter())?;
                next_producer.push((groups.len() + g) as u32);
            }
        }
    }
    Ok((next.finish()?, made, next_producer))
}

/// Simplifies the group of `level`'s chunks `members` to about half within `edge_error`
/// mean edges (infinite: no limit), its `locked` vertices (sorted) and their neighbours
/// kept, and cuts the result into chunks of `target`.
fn simplify(
    vertices: &Vertices,
    level: &Chunks,
    members: &[u32],
    locked: &Bits,
    target: usize,
    weight: f32,
    edge_error: f32,
) -> io::Result<Simplified> {
    let mut tris: Vec<[u32; 3]> = Vec::new();
    for &c in members {
        tris.extend(level.read(c as usize)?);
    }
    let (verts, mut local) = localize(&tris);
    let pos: Vec<[f32; 3]> = verts.iter().map(|&v| (vertices.position)(v)).collect();
    let mut lock: Vec<bool> = verts.iter().map(|&v| locked.get(v)).collect();
    let adapter = meshopt::VertexDataAdapter::new(bytemuck::cast_slice(&pos), 12, 0).expect("positions");
    // The vertices next to the border are locked too. Locking the border alone lets the
    // simplifier join two border vertices by a new edge (collapsing the vertex between
    // them), and the group on the other side of the border may join the same two: an edge
    // of four faces where a cut meets. A collapse makes new edges only from the vertex it
    // keeps to the removed one's neighbours, so with every neighbour of a border vertex
    // locked no new edge ever reaches the border (the first strip of triangles stays).
    let border = lock.clone();
    for t in local.chunks_exact(3) {
        if t.iter().any(|&v| border[v as usize]) {
            for &v in t {
                lock[v as usize] = true;
            }
        }
    }
    weld_unlocked(&mut local, &pos, &lock);
    let attributes: Vec<f32> =
        if weight > 0.0 { verts.iter().flat_map(|&v| (vertices.normal)(v)).collect() } else { Vec::new() };
    // About half the triangles, within an error of `edge_error` times the group's mean edge
    // (fewer where the limit stops the simplifier). Where the simplifier pinches the surface
    // (two sheets squashed onto one edge), the pinched edges' ends and their neighbours in
    // the input are locked and the group simplified again, a few times; then less, down to
    // none (the group's triangles as they are, error 0).
    let limit = if edge_error.is_finite() { edge_error * mean_edge(&local, &pos) } else { f32::MAX };
    let mut simplified = Vec::new();
    let mut error = 0.0f32;
    for eighths in std::iter::repeat_n(4, PINCH_RETRIES + 1).chain([5, 6, 7]) {
        let target_indices = tris.len() * eighths / 8 * 3;
        let out = if weight > 0.0 {
            meshopt::simplify_with_attributes_and_locks(
                &local,
                &adapter,
                &attributes,
                &[weight; 3],
                12,
                &lock,
                target_indices,
                limit,
                SIMPLIFY_OPTIONS,
                Some(&mut error),
            )
        } else {
            meshopt::simplify_with_locks(
                &local,
                &adapter,
                &lock,
                target_indices,
                limit,
                SIMPLIFY_OPTIONS,
                Some(&mut error),
            )
        };
        let mut out: Vec<[u32; 3]> = out.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        cancel_folds(&mut out);
        let mut pinched = pinched_edges(&local, &out, pos.len());
        if !out.is_empty() && !pinched.is_empty() {
            // Mended in place where that leaves no pinch, rather than simplified again: a
            // pinch is a few edges, most of them where the welded input's sheets touch.
            if let Some((mended, moved)) = unpinch(&local, &out, &pinched, &lock, &border, &pos) {
                if !mended.is_empty() && pinched_edges(&local, &mended, pos.len()).is_empty() {
                    (out, pinched) = (mended, Vec::new());
                    error = error.max(moved);
                }
            }
        }
        if !out.is_empty() && pinched.is_empty() {
            simplified = out;
            break;
        }
        let mut ends: Vec<u32> = pinched.into_iter().flatten().collect();
        ends.sort_unstable();
        for t in local.chunks_exact(3) {
            if t.iter().any(|v| ends.binary_search(v).is_ok()) {
                for &v in t {
                    lock[v as usize] = true;
                }
            }
        }
    }
    if simplified.is_empty() {
        // A group must make a chunk: one whose triangles all collapse away (a small separate
        // part), or that the simplifier only pinches, stays as it is.
        simplified = tris.iter().map(|t| t.map(|v| verts.binary_search(&v).expect("own vertex") as u32)).collect();
        error = 0.0;
    }
    let (center, radius) = sphere_of(&pos);
    let (idx, leaves) = split(&pos, &simplified, target);
    let leaves = leaves
        .into_iter()
        .map(|leaf| idx[leaf].iter().map(|&t| simplified[t as usize].map(|l| verts[l as usize])).collect())
        .collect();
    Ok(Simplified { leaves, error, center, radius })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pinch_is_an_edge_given_more_faces_than_the_input() {
        // A fan of two triangles and, apart from it, another: no edge has more than two faces.
        let input: Vec<u32> = vec![0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7];
        let same: Vec<[u32; 3]> = bytemuck::cast_slice(&input).to_vec();
        assert!(pinched_edges(&input, &same, 8).is_empty());
        // Vertices 4 and 6 collapsed onto 0 and 2: the two sheets meet on the edge 0-2 with
        // four faces.
        let squashed = vec![[0, 1, 2], [0, 2, 3], [0, 5, 2], [0, 2, 7]];
        assert_eq!(pinched_edges(&input, &squashed, 8), vec![[0, 2]]);
        // An edge the input already gives four faces (a non-manifold model) may keep them,
        // and one it gives three may not gain a fourth.
        let fins: Vec<u32> = vec![0, 1, 2, 0, 2, 3, 0, 5, 2, 0, 2, 7];
        assert!(pinched_edges(&fins, bytemuck::cast_slice(&fins), 8).is_empty());
        let three: Vec<u32> = vec![0, 1, 2, 0, 2, 3, 0, 5, 2];
        assert_eq!(pinched_edges(&three, bytemuck::cast_slice(&fins), 8), vec![[0, 2]]);
    }

    #[test]
    fn a_pinch_is_mended_by_collapsing_its_edge() {
        // Two sheets squashed onto the edge 0-2 (faces 0-1, 0-3 of one; 0-6, 0-7 of the
        // other), and a triangle 2-4-1 beside it; 2 stands a little above the others.
        let pos: Vec<[f32; 3]> = vec![
            [0.0, 0.0, 0.0],
            [0.5, 1.0, 0.0],
            [1.0, 0.0, 0.2],
            [0.5, -1.0, 0.0],
            [1.2, 1.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.5, 1.0, 0.1],
            [0.5, -1.0, 0.1],
        ];
        let input: Vec<u32> = vec![0, 2, 1, 0, 3, 2, 2, 4, 1, 5, 2, 6, 5, 7, 2];
        let out = vec![[0, 2, 1], [0, 3, 2], [2, 4, 1], [0, 2, 6], [0, 7, 2]];
        let pinched = pinched_edges(&input, &out, 8);
        assert_eq!(pinched, vec![[0, 2]]);
        let free = vec![false; 8];
        // 2 goes onto 0: the four faces on the edge go, 2-4-1 becomes 0-4-1, and the error
        // is 0's distance from the plane of 2's input triangle 2-4-1 (it lies in the others').
        let (mended, moved) = unpinch(&input, &out, &pinched, &free, &free, &pos).unwrap();
        assert_eq!(mended, vec![[0, 4, 1]]);
        assert!(pinched_edges(&input, &mended, 8).is_empty());
        let p = |v: usize| Vec3::from(pos[v]);
        let plane = (p(4) - p(2)).cross(p(1) - p(2)).normalize();
        assert!((moved - plane.dot(p(0) - p(2)).abs()).abs() < 1e-6 && moved > 0.19, "{moved}");
        // A locked end stays: 0 goes onto 2.
        let mut lock = free.clone();
        lock[2] = true;
        assert_eq!(unpinch(&input, &out, &pinched, &lock, &free, &pos).unwrap().0, vec![[2, 4, 1]]);
        // Nor onto a vertex of the group's border (which is locked): the edges 0-4 and 0-1
        // would be new edges reaching it.
        let mut border = free.clone();
        border[0] = true;
        assert!(unpinch(&input, &out, &pinched, &border, &border, &pos).is_none());
        // A collapse that would turn a triangle over goes the other way: with 4 and 1 on the
        // line between the ends, 2-4-1 turns over if 2 goes onto 0, so 0 goes onto 2.
        let mut flat = pos.clone();
        (flat[4], flat[1]) = ([0.5, -0.5, 0.0], [0.5, 0.5, 0.0]);
        assert_eq!(unpinch(&input, &out, &pinched, &free, &free, &flat).unwrap().0, vec![[2, 4, 1]]);
        // And none is made where both ways turn one over (0-4-1 as well).
        let both: Vec<[u32; 3]> = out.iter().copied().chain([[0, 4, 1]]).collect();
        assert!(unpinch(&input, &both, &pinched, &free, &free, &flat).is_none());
    }
}
