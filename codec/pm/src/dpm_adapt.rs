//! The parallel view-dependent adaptation of [`super::adapt`] run straight from a `.dpm` file's
//! compressed operations, as the paper runs it on the GPU: nothing is decoded at load, every
//! operation is decoded from its address and context when a vertex needs it, and the state is
//! per *active* vertex, so memory follows the adapted mesh, not the model. It reaches the same
//! states as [`Adapter`](super::Adapter) over the decoded mesh, pass for pass (tested in
//! `tests/pm_adapt.rs`); it is the reference the GPU version of this state follows.
//!
//! **Where a collapse finds its operation.** [`Adapter`](super::Adapter) keeps a static split
//! tree: a collapsing vertex learns its parent's parent from it. Decoding an operation needs
//! its context, its parent's criteria among them (criteria are coded as differences to the
//! parent's), so an operation cannot be decoded from below, and a static table of parents or
//! criteria would cost bytes per operation in graphics memory. The paper is silent on this.
//! What makes it free here is a bijection: every performed split `P` has a right child whose
//! FVID is `P.v_u`, and the vertex with the smallest FVID of that right child's subtree keeps
//! it, so every active vertex whose FVID `f` is not a base vertex's is the leftmost leaf of the
//! right subtree of exactly one performed split, `f`'s *creator*. Each active vertex carries its
//! creator's descriptor (address, context, criteria): a split hands its own operation to its
//! right child as that child's creator and its creator to its left child unchanged; a collapse
//! of a right child into its target makes the target's vertex the creator's vertex again
//! (its operation, context and criteria, from the right child's descriptor) while the target
//! keeps its own descriptor, which the FVID it keeps still names. A vertex is the right child
//! of its creator exactly when its FVID range ends where the creator's did; only right children
//! collapse (Algorithm 1 as in [`super::adapt`]).
//!
//! Per active vertex: FVID, its operation's address and context (range end, parent criteria,
//! quantized position and normal), the split cache (its operation's criteria, position and
//! normal), and its creator's address, context and criteria (the collapse cache). A face's
//! owner is its split's `v_u` (unique per split, and the FVID of the split's creator vertex,
//! so a collapsing vertex recognises its split's faces by its own FVID).

use std::borrow::Cow;

use glam::Vec3;
use rayon::prelude::*;

use super::adapt::{Eval, Levels, DESCENT_BUDGET};
use super::format::{DecodedOp, Dpm, DpmError, OpContext};
use super::one_level::{active_of, Cached};
use super::ooc::NodeCache;
use super::{all_levels, one_level};
use crate::adapt::Viewpoint;
use crate::pass_stats::PassStats;
use crate::progressive::NONE;

/// Where the operations are: the file in memory, or the resident nodes of an out-of-core one.
#[derive(Clone, Copy)]
enum Source<'s> {
    InCore,
    Nodes(&'s NodeCache),
}

impl Source<'_> {
    /// The operation at `addr`, `None` where its node is not resident.
    fn decode(self, dpm: &Dpm, addr: u32, ctx: &OpContext) -> Result<Option<DecodedOp>, DpmError> {
        match self {
            Source::InCore => dpm.decode_op(addr as usize, ctx).map(Some),
            Source::Nodes(cache) => cache.decode(dpm, addr as usize, ctx),
        }
    }

    /// Whether the operation at `addr` can be decoded now.
    fn resident(self, addr: u32) -> bool {
        match self {
            Source::InCore => true,
            Source::Nodes(cache) => cache.get(Dpm::node_of(addr as usize)).is_some(),
        }
    }
}

/// The compressed operations' state, borrowed for a pass of one level ([`one_level::Form`]): a
/// splitting vertex decodes its operation from its address and context, and a face's owner is
/// its split's `v_u`.
struct Compressed<'s> {
    dpm: &'s Dpm<'s>,
    src: Source<'s>,
    vertices: &'s [Vertex],
    descent_budget: u32,
}

impl one_level::Form for Compressed<'_> {
    type Vertex = Vertex;
    type Op = DecodedOp;
    type Error = DpmError;

    fn len(&self) -> usize {
        self.vertices.len()
    }

    fn fvid(&self, i: usize) -> u32 {
        self.vertices[i].fvid()
    }

    fn target(&self, i: usize) -> u32 {
        self.vertices[i].target()
    }

    fn splits(&self, i: usize, need: one_level::Need) -> bool {
        DpmAdapter::splits(&self.vertices[i], need, self.src)
    }

    fn collapse_cache(&self, i: usize) -> &Cached {
        &self.vertices[i].creator.cache
    }

    fn op(&self, v: &Vertex) -> Result<DecodedOp, DpmError> {
        // A splitting vertex's operation is resident (`DpmAdapter::splits`).
        Ok(self.src.decode(self.dpm, v.own.addr, &v.own.ctx)?.expect("a splitting vertex's node is resident"))
    }

    fn split<'a>(&'a self, op: &'a DecodedOp) -> (&'a [[u32; 3]], u32, u32, u32) {
        (&op.split.faces[..], op.split.v, op.split.v_u, op.split.v_u)
    }

    fn owner(&self, i: usize) -> u32 {
        self.vertices[i].fvid()
    }

    fn kept(&self, i: usize) -> Vertex {
        self.vertices[i]
    }

    fn collapsed_into(&self, i: usize) -> Vertex {
        // The target becomes its creator's vertex again and keeps its own creator.
        Vertex { own: self.vertices[i + 1].creator, creator: self.vertices[i].creator }
    }

    fn children(&self, v: &Vertex, op: &DecodedOp) -> Result<[Vertex; 2], DpmError> {
        DpmAdapter::children(self.dpm, self.src, v, op)
    }

    fn fvid_of(v: &Vertex) -> u32 {
        v.fvid()
    }
}

impl all_levels::Form for Compressed<'_> {
    fn fvids(&self) -> Cow<'_, [u32]> {
        Cow::Owned(self.vertices.par_iter().map(Vertex::fvid).collect())
    }

    fn descent_budget(&self) -> u32 {
        self.descent_budget
    }

    /// Tagged by the vertex that carries the split as its creator.
    fn undone(&self, i: usize, need: one_level::Need) -> Option<(u32, u32, u32)> {
        let c = &self.vertices[i].creator;
        if c.addr == NONE || need(&c.cache) {
            return None;
        }
        Some((c.ctx.v, c.ctx.v_end, i as u32))
    }

    fn region_vertex(&self, i: usize, j: u32) -> Vertex {
        // The region's split, carried by vertex `j` as its creator, done again; the first
        // vertex keeps its own creator.
        Vertex { own: self.vertices[j as usize].creator, creator: self.vertices[i].creator }
    }

    fn descends(&self, v: &Vertex, need: one_level::Need) -> bool {
        DpmAdapter::splits(v, need, self.src)
    }

    /// A face is owned by its split's `v_u`, which lies strictly inside the region's FVID
    /// range exactly when the split is undone.
    fn undoes(&self, owner: u32, start: u32, j: u32) -> bool {
        start < owner && owner < self.vertices[j as usize].creator.ctx.v_end
    }
}

/// An operation as a vertex carries it: its address ([`NONE`]: none) and its context.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Op {
    addr: u32,
    ctx: OpContext,
    /// Its centre, normal and criteria (decoded once, when the vertex gets the operation).
    cache: Cached,
    /// Out of core: its node was not resident when the vertex got it, so `cache` is not
    /// decoded yet (the vertex does not split until it is).
    pending: bool,
}

/// One active vertex.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Vertex {
    /// Its operation; `own.ctx` holds its FVID, range end, quantized position and normal.
    own: Op,
    /// Its creator (the split whose `v_u` is this FVID), `addr` [`NONE`] for a base FVID.
    creator: Op,
}

impl Vertex {
    fn fvid(&self) -> u32 {
        self.own.ctx.v
    }

    /// The FVID of the vertex this one collapses into, if it is the right child of its
    /// creator (its range ends where the creator's did).
    fn target(&self) -> u32 {
        if self.creator.addr != NONE && self.own.ctx.v_end == self.creator.ctx.v_end {
            self.creator.ctx.v
        } else {
            NONE
        }
    }
}

/// View-dependent adaptation from the compressed operations (see the module docs).
#[derive(Clone, Debug)]
pub struct DpmAdapter<'a> {
    dpm: &'a Dpm<'a>,
    /// Active vertices, sorted by FVID.
    vertices: Vec<Vertex>,
    /// Faces: current vertex indices, finest FVIDs, and the address of the split that created
    /// them ([`NONE`] for base faces).
    face_idx: Vec<[u32; 3]>,
    face_fvid: Vec<[u32; 3]>,
    face_owner: Vec<u32>,
    levels: Levels,
    descent_budget: u32,
}

impl<'a> DpmAdapter<'a> {
    /// Starts at the base mesh of `dpm`.
    pub fn new(dpm: &'a Dpm<'a>) -> Result<Self, DpmError> {
        let h = &dpm.header;
        let n = dpm.base_vertices.len();
        let mut vertices = Vec::with_capacity(n);
        for b in 0..n {
            let ctx = OpContext {
                v: dpm.base_vertices[b],
                v_end: dpm.base_vertices.get(b + 1).copied().unwrap_or(h.vertices),
                parent_criteria: [0; 4],
                position: dpm.base_positions[b],
                normal: dpm.base_normals[b],
            };
            let addr = dpm.roots[b].map_or(NONE, |a| a as u32);
            let own = if dpm.out_of_core() {
                Op { addr, ctx, cache: Cached::default(), pending: addr != NONE }
            } else {
                op(dpm, Source::InCore, addr, ctx)?
            };
            vertices.push(Vertex { own, creator: Op { addr: NONE, ..Op::default() } });
        }
        let fvid: Vec<u32> = vertices.iter().map(Vertex::fvid).collect();
        let face_idx = dpm.base_faces.iter().map(|t| t.map(|f| active_of(&fvid, f))).collect();
        Ok(DpmAdapter {
            dpm,
            vertices,
            face_idx,
            face_fvid: dpm.base_faces.clone(),
            face_owner: vec![NONE; dpm.base_faces.len()],
            levels: Levels::One,
            descent_budget: DESCENT_BUDGET,
        })
    }

    /// Sets how far one pass moves a vertex in the split tree (see [`Levels`]).
    pub fn with_levels(mut self, levels: Levels) -> Self {
        self.levels = levels;
        self
    }

    /// Sets the most splits one vertex's descent performs in an all-levels pass (at least 1;
    /// [`DESCENT_BUDGET`] by default), as [`super::Adapter::set_descent_budget`].
    pub fn set_descent_budget(&mut self, splits: u32) {
        self.descent_budget = splits.max(1);
    }

    /// One adaptation pass for `view` (Algorithms 1 to 5, or their all-levels form) of an
    /// in-core file.
    pub fn adapt(&mut self, view: &Viewpoint) -> Result<PassStats, DpmError> {
        let eval = Eval::new(view);
        match self.levels {
            Levels::One => self.pass(&|c| eval.needs(c), Source::InCore),
            Levels::All => self.pass_all_levels(&|c| eval.needs(c), Source::InCore),
        }
    }

    /// One adaptation pass for `view` of an out-of-core file, from the nodes resident in
    /// `nodes`: a vertex whose operation's node is not resident does not split this pass.
    pub fn adapt_resident(&mut self, view: &Viewpoint, nodes: &NodeCache) -> Result<PassStats, DpmError> {
        let eval = Eval::new(view);
        match self.levels {
            Levels::One => self.pass(&|c| eval.needs(c), Source::Nodes(nodes)),
            Levels::All => self.pass_all_levels(&|c| eval.needs(c), Source::Nodes(nodes)),
        }
    }

    /// One pass that splits every active vertex that has a split (and collapses nothing).
    pub fn refine_step(&mut self) -> Result<PassStats, DpmError> {
        self.pass(&|_| true, Source::InCore)
    }

    /// Active vertices whose operation waits for its node.
    pub fn pending(&self) -> usize {
        self.vertices.iter().filter(|v| v.own.pending).count()
    }

    /// Active vertex FVIDs, ascending.
    pub fn active(&self) -> Vec<u32> {
        self.vertices.iter().map(Vertex::fvid).collect()
    }

    /// The active vertices' positions, in [`Self::active`]'s order (dequantized as
    /// [`super::format::decode`] dequantizes them, so the same floats).
    pub fn positions(&self) -> Vec<[f32; 3]> {
        self.vertices.par_iter().map(|v| self.dpm.position(v.own.ctx.position)).collect()
    }

    /// The current faces as indices into [`Self::active`].
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.face_idx
    }

    /// The current faces as FVID triples of active vertices.
    pub fn face_fvids(&self) -> Vec<[u32; 3]> {
        self.face_idx.par_iter().map(|t| t.map(|i| self.vertices[i as usize].fvid())).collect()
    }

    /// Bytes of adaptation state: per active vertex and per face (what memory follows; the
    /// file's bytes are the only other data).
    pub fn state_bytes(&self) -> usize {
        self.vertices.len() * std::mem::size_of::<Vertex>() + self.face_idx.len() * (12 + 12 + 4)
    }

    /// Out of core: decodes the operations whose nodes have come in since their vertices got
    /// them.
    fn refresh_pending(&mut self, src: Source) -> Result<(), DpmError> {
        let dpm = self.dpm;
        self.vertices.par_iter_mut().filter(|v| v.own.pending).try_for_each(|v| -> Result<(), DpmError> {
            let o = op(dpm, src, v.own.addr, v.own.ctx)?;
            if !o.pending {
                v.own = o;
            }
            Ok(())
        })
    }

    /// Whether vertex `v` splits this pass: it has an operation, decoded and resident, that the
    /// view asks for.
    fn splits(v: &Vertex, need: &(dyn Fn(&Cached) -> bool + Sync), src: Source) -> bool {
        v.own.addr != NONE && !v.own.pending && need(&v.own.cache) && src.resident(v.own.addr)
    }

    /// The two children of a splitting vertex `v` whose operation decoded to `d`: `v` keeps
    /// its creator, `v_u` gets `v`'s operation as its creator.
    fn children(dpm: &Dpm, src: Source, v: &Vertex, d: &DecodedOp) -> Result<[Vertex; 2], DpmError> {
        let ctx = v.own.ctx;
        let left = OpContext { v_end: d.split.v_u, parent_criteria: d.criteria_q, ..ctx };
        let right = OpContext {
            v: d.split.v_u,
            v_end: ctx.v_end,
            parent_criteria: d.criteria_q,
            position: d.position_u,
            normal: d.normal_u,
        };
        let addr = |a: Option<usize>| a.map_or(NONE, |a| a as u32);
        Ok([
            Vertex { own: op(dpm, src, addr(d.left), left)?, creator: v.creator },
            Vertex { own: op(dpm, src, addr(d.right), right)?, creator: v.own },
        ])
    }

    /// One pass of one level ([`one_level::pass`] over the compressed operations).
    fn pass(&mut self, need: &(dyn Fn(&Cached) -> bool + Sync), src: Source) -> Result<PassStats, DpmError> {
        self.refresh_pending(src)?;
        let form = Compressed { dpm: self.dpm, src, vertices: &self.vertices, descent_budget: self.descent_budget };
        let faces =
            one_level::Faces { idx: &mut self.face_idx, fvid: &mut self.face_fvid, owner: &mut self.face_owner };
        let done = one_level::pass(&form, faces, need)?;
        if let Some(m) = done.moved {
            self.vertices = m.vertices;
        }
        Ok(done.stats)
    }

    /// One pass of [`Levels::All`], as [`super::Adapter`]'s: every done split is the creator of
    /// one active vertex, whose creator descriptor holds its FVID range; the outermost undone
    /// ones are regions, whose first vertex takes the region's operation (the outermost
    /// creator's descriptor, carried by the vertex at its `v_u`) and keeps its own creator. A
    /// splitting vertex decodes its operation and goes on down while the view asks and the
    /// operations are resident. A face's owner is its split's `v_u`, which lies strictly inside
    /// a region's FVID range exactly when the split is undone.
    fn pass_all_levels(&mut self, need: &(dyn Fn(&Cached) -> bool + Sync), src: Source) -> Result<PassStats, DpmError> {
        self.refresh_pending(src)?;
        let form = Compressed { dpm: self.dpm, src, vertices: &self.vertices, descent_budget: self.descent_budget };
        let faces =
            one_level::Faces { idx: &mut self.face_idx, fvid: &mut self.face_fvid, owner: &mut self.face_owner };
        let done = all_levels::pass(&form, faces, need)?;
        if let Some(m) = done.moved {
            self.vertices = m.vertices;
        }
        Ok(done.stats)
    }
}

/// The operation at `addr` ([`NONE`]: none) in context `ctx`, its split cache decoded: the
/// centre and normal of the vertex and the operation's criteria; pending where its node is not
/// resident.
fn op(dpm: &Dpm, src: Source, addr: u32, ctx: OpContext) -> Result<Op, DpmError> {
    if addr == NONE {
        return Ok(Op { addr, ctx, cache: Cached::default(), pending: false });
    }
    Ok(match src.decode(dpm, addr, &ctx)? {
        Some(d) => Op {
            addr,
            ctx,
            cache: Cached {
                center: Vec3::from(dpm.position(ctx.position)),
                normal: Vec3::from(dpm.normal(ctx.normal)),
                crit: d.criteria,
            },
            pending: false,
        },
        None => Op { addr, ctx, cache: Cached::default(), pending: true },
    })
}
