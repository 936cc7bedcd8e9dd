//! BFT encoder: one breadth-first traversal that codes commands and positions as it goes.
//!
//! The traversal follows the frontier semantics of [`super`]; the choices it makes are:
//! the third vertex is looked up among the unvisited triangles on the directed current edge
//! (a CSR adjacency sorted by target, no hashing: see [`Traversal::find`]); an existing third vertex takes the frontier occurrence
//! with the smallest offset, preferring `RF0`/`LF0`; a null edge deletes a vertex whose
//! triangles are all visited (`DL` before `DR`), else it is skipped (`NULL`); a full
//! rotation without a triangle, or a frontier without unvisited triangles, starts a `SEED`
//! at the next unvisited triangle in input order.

use super::attributes::{self, oct_encode, DEFAULT_NORMAL_BITS};
use super::format::{self, put_varint, AttributeFlags, Coding, Header};
use super::frontier::{Frontier, NONE};
use super::model::{predict, Degrees, Prediction, RangeSink, SymbolSink};
use super::prefix::PrefixSink;
use crate::command::Command;
use crate::csr::Csr;
use crate::mesh::{Mesh, MeshError, Quantization};

/// Encoder settings.
#[derive(Clone, Copy, Debug)]
pub struct EncodeOptions {
    /// Bits per quantized coordinate, 8 to 24.
    pub quant_bits: u8,
    /// Bits per octahedral normal coordinate, 4 to 16.
    pub normal_bits: u8,
    /// Code the mesh's colours, if it has any.
    pub colors: bool,
    /// Code the mesh's normals, if it has any.
    pub normals: bool,
    /// Store each vertex's input index, so that decoding gives the input's vertex order
    /// (`encode --keep-order`) instead of the traversal's.
    pub keep_order: bool,
    /// How the connectivity and geometry streams are entropy-coded (`encode --coding`):
    /// [`Coding::Range`] by default; [`Coding::Prefix`] a few percent larger as one stream
    /// (a chunked file's small streams can come out smaller) and decoded 2-3x faster.
    pub coding: Coding,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        EncodeOptions {
            quant_bits: Quantization::DEFAULT_BITS,
            normal_bits: DEFAULT_NORMAL_BITS,
            colors: true,
            normals: true,
            keep_order: false,
            coding: Coding::Range,
        }
    }
}

impl EncodeOptions {
    /// Whether `mesh`'s colours and normals are coded.
    fn coded(&self, mesh: &Mesh) -> (bool, bool) {
        (self.colors && !mesh.colors.is_empty(), self.normals && !mesh.normals.is_empty())
    }
}

/// What the encoder did, for reports and tests.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EncodeStats {
    pub triangles: usize,
    pub unused_vertices: usize,
    pub duplicates: usize,
    pub loose_triangles: usize,
    pub seeds: usize,
    pub commands: usize,
    /// Commands per kind, indexed by `Command as usize`.
    pub command_counts: [usize; 12],
    /// Offsets of generic `RF<k>`/`LF<k>`: how many were `k = 1, 2, 3, 4..7, 8..`.
    pub offset_histogram: [usize; 5],
    /// Steps of the traversal's inner loops: commands, half-edges looked at to find a
    /// triangle, and frontier occurrences examined for the third vertex. It is linear in the
    /// triangle count whatever the valence (a test bounds it), where a linear scan of a
    /// vertex's half-edges was quadratic on a fan.
    pub work: u64,
}

/// An encoded mesh.
#[derive(Clone, Debug)]
pub struct Encoded {
    pub bytes: Vec<u8>,
    pub header: Header,
    pub stats: EncodeStats,
    /// The input vertex each decoded slot stands for (duplicates included).
    pub slot_vertex: Vec<u32>,
    /// Where the encoder was asked to keep them (or the mesh has attributes): the triangles
    /// over slots in the order the decoder will have them, and the duplicate table
    /// `(slot, source)`; otherwise empty.
    pub slot_triangles: Vec<[u32; 3]>,
    pub duplicates: Vec<(u32, u32)>,
}

/// Encodes a mesh into `.bft` bytes.
pub fn encode(mesh: &Mesh, options: EncodeOptions) -> Result<Encoded, MeshError> {
    encode_with_progress(mesh, options, &mut |_, _| {})
}

/// As [`encode`], calling `progress(triangles_done, triangles_total)` now and then.
pub fn encode_with_progress(
    mesh: &Mesh,
    options: EncodeOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Encoded, MeshError> {
    mesh.validate()?;
    let used = mesh.used_vertices();
    let quant = Quantization::fit(&mesh.positions, Some(&used), options.quant_bits)?;
    encode_quantized(mesh, &used, quant, &options, None, false, progress)
}

/// As [`encode_with_progress`], on a quantization given by the caller (a chunked file's
/// chunks share the whole model's), with the mesh already validated and `used` its used
/// vertices. Every used position must lie in the quantization's box (it is clamped).
/// `keep_slots` keeps [`Encoded::slot_triangles`] and [`Encoded::duplicates`], the decoder's
/// view of the triangles, so that a caller needs no decode to sum face normals as a decoder
/// of the stream does.
#[allow(clippy::too_many_arguments)]
pub(crate) fn encode_quantized(
    mesh: &Mesh,
    used: &[bool],
    quant: Quantization,
    options: &EncodeOptions,
    input_index: Option<(&[u32], u32)>,
    keep_slots: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Encoded, MeshError> {
    match options.coding {
        Coding::Range => encode_with::<RangeSink>(mesh, used, quant, options, input_index, keep_slots, progress),
        Coding::PrefixByDegree => {
            encode_with::<PrefixSink<true>>(mesh, used, quant, options, input_index, keep_slots, progress)
        }
        Coding::Prefix => {
            encode_with::<PrefixSink<false>>(mesh, used, quant, options, input_index, keep_slots, progress)
        }
    }
}

/// [`encode_quantized`] with the streams coded by `S`.
fn encode_with<S: SymbolSink>(
    mesh: &Mesh,
    used: &[bool],
    quant: Quantization,
    options: &EncodeOptions,
    input_index: Option<(&[u32], u32)>,
    keep_slots: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Encoded, MeshError> {
    let (colors, normals) = options.coded(mesh);
    if normals && !(4..=16).contains(&options.normal_bits) {
        return Err(MeshError::NormalBits(options.normal_bits));
    }
    let q: Vec<[u32; 3]> =
        mesh.positions.iter().zip(used).map(|(p, &u)| if u { quant.quantize(*p) } else { [0; 3] }).collect();
    let loose: Vec<bool> = mesh.triangles.iter().map(|t| t[0] == t[1] || t[1] == t[2] || t[0] == t[2]).collect();

    let mut tr = Traversal::<S>::new(mesh, q, quant.max_level(), &loose);
    tr.record = colors || normals || keep_slots;
    tr.run(progress);

    // Vertices that only loose triangles use get slots after the traversal.
    let mut tail_slots = 0u32;
    let mut loose_bytes = Vec::new();
    let loose_count = loose.iter().filter(|&&l| l).count();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if !loose[t] {
            continue;
        }
        for &v in tri {
            if tr.slot_of[v as usize] == NONE {
                let prev = tr.vertex_of.len().checked_sub(1).map_or(NONE, |s| s as u32);
                tr.new_slot(v, Prediction::Previous, [prev, NONE, NONE]);
                tail_slots += 1;
            }
            put_varint(&mut loose_bytes, tr.slot_of[v as usize] as u64);
        }
        if tr.record {
            tr.slot_triangles.push(tri.map(|v| tr.slot_of[v as usize]));
        }
    }
    let mut flags = AttributeFlags { order: options.keep_order, ..Default::default() };
    let (mut color_bytes, mut normal_bytes, mut order_bytes) = (Vec::new(), Vec::new(), Vec::new());
    if options.keep_order {
        let index = |v: u32| input_index.map_or(v, |(g, _)| g[v as usize]);
        let values: Vec<u32> = tr.vertex_of.iter().map(|&v| index(v)).collect();
        order_bytes = attributes::encode_order(&values, &tr.dups);
    }
    if tr.record {
        let slot_q: Vec<[u32; 3]> = tr.vertex_of.iter().map(|&v| tr.q[v as usize]).collect();
        let input = attributes::Input { positions: &slot_q, triangles: &tr.slot_triangles, duplicates: &tr.dups };
        if colors {
            let values: Vec<[u8; 4]> = tr.vertex_of.iter().map(|&v| mesh.colors[v as usize]).collect();
            flags.colors = true;
            flags.alpha = values.iter().any(|c| c[3] != 255);
            color_bytes = attributes::encode_colors(&input, &values, flags.alpha);
        }
        if normals {
            let bits = options.normal_bits;
            let values: Vec<[u16; 2]> =
                tr.vertex_of.iter().map(|&v| oct_encode(mesh.normals[v as usize], bits)).collect();
            flags.normal_bits = bits;
            normal_bytes = attributes::encode_normals(&input, &values, bits, options.coding);
        }
    }
    let mut dup_bytes = Vec::new();
    put_varint(&mut dup_bytes, tr.dups.len() as u64);
    let mut last = 0u32;
    for &(slot, source) in &tr.dups {
        put_varint(&mut dup_bytes, (slot - last) as u64);
        put_varint(&mut dup_bytes, source as u64);
        last = slot;
    }

    let used_count = used.iter().filter(|&&u| u).count();
    let mut bbox_max = [0.0f32; 3];
    for (a, m) in bbox_max.iter_mut().enumerate() {
        *m = quant.min[a] + quant.step * tr.max_q[a] as f32;
    }
    let header = Header {
        // A chunk's stream that keeps the order names the whole model's vertices.
        input_vertices: match input_index {
            Some((_, n)) if options.keep_order => n,
            _ => mesh.positions.len() as u32,
        },
        slots: tr.vertex_of.len() as u32,
        triangles: mesh.triangles.len() as u32,
        loose_triangles: loose_count as u32,
        commands: tr.commands as u32,
        seeds: tr.seeds as u32,
        duplicates: tr.dups.len() as u32,
        tail_slots,
        components: mesh.components() as u32,
        quant_bits: quant.bits,
        coding: options.coding,
        bbox_min: quant.min,
        step: quant.step,
        bbox_max,
        attributes: flags,
    };
    let stats = EncodeStats {
        triangles: mesh.triangles.len(),
        unused_vertices: mesh.positions.len() - used_count,
        duplicates: tr.dups.len(),
        loose_triangles: loose_count,
        seeds: tr.seeds,
        commands: tr.commands,
        command_counts: tr.command_counts,
        offset_histogram: tr.offset_histogram,
        work: tr.work,
    };
    let Traversal { sink, vertex_of, slot_triangles, dups, .. } = tr;
    let [conn, geom] = sink.finish();
    let bytes =
        format::write(&header, [&conn, &geom, &dup_bytes, &loose_bytes, &color_bytes, &normal_bytes, &order_bytes]);
    let (slot_triangles, duplicates) = if keep_slots { (slot_triangles, dups) } else { (Vec::new(), Vec::new()) };
    Ok(Encoded { bytes, header, stats, slot_vertex: vertex_of, slot_triangles, duplicates })
}

/// One directed edge `a -> target` of triangle `tri`, whose remaining vertex is `third`.
#[derive(Clone, Copy, Default)]
struct HalfEdge {
    target: u32,
    tri: u32,
    third: u32,
}

struct Traversal<'a, S> {
    triangles: &'a [[u32; 3]],
    loose: &'a [bool],
    q: Vec<[u32; 3]>,
    max: u32,
    max_q: [u32; 3],
    /// The outgoing half-edges of each vertex, sorted by target, in input order per target.
    edges: Csr<HalfEdge>,
    /// Per half-edge that starts a run of equal targets in its vertex's list: the first one
    /// of the run that may be unvisited (visited triangles before it are skipped for good).
    first_open: Vec<u32>,
    /// See [`EncodeStats::work`].
    work: u64,
    visited: Vec<bool>,
    /// Unvisited non-loose triangles per vertex.
    remaining: Vec<u32>,
    slot_of: Vec<u32>,
    vertex_of: Vec<u32>,
    deg: Degrees,
    frontier: Frontier,
    /// Per frontier position: the previous position holding the same vertex (a chain).
    prev_same: Vec<u32>,
    last_entry: Vec<u32>,
    entry_count: Vec<u32>,
    /// Frontier entries whose vertex still has unvisited triangles.
    incomplete: usize,
    /// Where commands, offsets and positions are coded.
    sink: S,
    prev: Command,
    dups: Vec<(u32, u32)>,
    commands: usize,
    command_counts: [usize; 12],
    offset_histogram: [usize; 5],
    seeds: usize,
    done: usize,
    /// Whether to keep `slot_triangles` (the attributes' predictions need them).
    record: bool,
    /// The triangles over slots, in the order the decoder will have them.
    slot_triangles: Vec<[u32; 3]>,
}

impl<'a, S: SymbolSink> Traversal<'a, S> {
    fn new(mesh: &'a Mesh, q: Vec<[u32; 3]>, max: u32, loose: &'a [bool]) -> Self {
        let n = mesh.positions.len();
        let half_edges = || {
            mesh.triangles.iter().enumerate().filter(|&(t, _)| !loose[t]).flat_map(|(t, &[a, b, c])| {
                [(a, b, c), (b, c, a), (c, a, b)]
                    .map(|(from, to, third)| (from, HalfEdge { target: to, tri: t as u32, third }))
            })
        };
        // Grouped by target, then (stably) by source: each vertex's half-edges come sorted by
        // target, and those with the same target keep the input order (two counting sorts).
        let by_target = Csr::build(n, || half_edges().map(|(from, e)| (e.target, (from, e))));
        let edges = Csr::build(n, || by_target.values.iter().copied());
        drop(by_target);
        let first_open = (0..edges.values.len() as u32).collect();
        // One half-edge leaves each corner, so a vertex starts with as many unvisited
        // triangles as it has half-edges.
        let remaining: Vec<u32> = edges.start.windows(2).map(|w| w[1] - w[0]).collect();
        Traversal {
            triangles: &mesh.triangles,
            loose,
            q,
            max,
            max_q: [0; 3],
            edges,
            first_open,
            work: 0,
            visited: vec![false; mesh.triangles.len()],
            remaining,
            slot_of: vec![NONE; n],
            vertex_of: Vec::with_capacity(n),
            deg: Degrees::with_capacity(S::DEGREES, n),
            frontier: Frontier::default(),
            prev_same: Vec::new(),
            last_entry: vec![NONE; n],
            entry_count: vec![0; n],
            incomplete: 0,
            sink: S::with_capacity(mesh.triangles.len() + mesh.triangles.len() / 8, n),
            prev: Command::Seed,
            dups: Vec::new(),
            commands: 0,
            command_counts: [0; 12],
            offset_histogram: [0; 5],
            seeds: 0,
            done: 0,
            record: false,
            slot_triangles: Vec::new(),
        }
    }

    fn run(&mut self, progress: &mut dyn FnMut(usize, usize)) {
        let total = self.triangles.len();
        let mut cursor = 0usize;
        let mut null_run = 0usize;
        let mut next_report = 1 << 16;
        loop {
            if self.done >= next_report {
                progress(self.done, total);
                next_report = self.done + (1 << 16);
            }
            let len = self.frontier.len();
            if self.incomplete == 0 || len < 2 || null_run > len {
                while cursor < total && (self.visited[cursor] || self.loose[cursor]) {
                    cursor += 1;
                }
                if cursor == total {
                    break;
                }
                self.seed(cursor);
                null_run = 0;
                continue;
            }
            let l = self.frontier.at(0);
            let r = self.frontier.at(1);
            let (lv, rv) = (self.vertex_of[l.slot as usize], self.vertex_of[r.slot as usize]);
            if let Some((t, x)) = self.find(lv, rv) {
                null_run = 0;
                if !self.defer(x, len) {
                    self.triangle(t, x);
                    continue;
                }
                // Skip the edge: the next one closes `Q[2]` with RF0, and this triangle then
                // comes back as an LF0 instead of splitting the frontier with RF<1>.
                self.code(Command::Null);
                self.on_remove(l.slot);
                self.frontier.skip();
                self.on_push(self.frontier.back_pos() - 1);
            } else if self.remaining[lv as usize] == 0 {
                null_run = 0;
                self.code(Command::Dl);
                self.on_remove(l.slot);
                self.frontier.remove_left(false);
            } else if self.remaining[rv as usize] == 0 {
                null_run = 0;
                self.code(Command::Dr);
                self.on_remove(r.slot);
                self.frontier.remove_right(false);
            } else {
                null_run += 1;
                self.code(Command::Null);
                self.on_remove(l.slot);
                self.frontier.skip();
                self.on_push(self.frontier.back_pos() - 1);
            }
        }
        progress(self.done, total);
    }

    /// Whether to skip the current edge rather than code its triangle `(l, r, x)`: when `x`
    /// is `Q[3]` (an `RF<1>`, which would split the frontier) and the next edge `(r, Q[2])`
    /// has the triangle `(r, Q[2], x)`, skipping gives `NULL, RF0, LF0` and no split.
    #[inline]
    fn defer(&mut self, x: u32, len: usize) -> bool {
        if len < 5 {
            return false;
        }
        let f = &self.frontier;
        let at = |i: usize| self.vertex_of[f.at(i).slot as usize];
        let (q1, q2, q3) = (at(1), at(2), at(3));
        q3 == x && q2 != x && self.find(q1, q2).is_some_and(|(_, third)| third == x)
    }

    /// The first unvisited triangle, in input order, on the directed edge `l -> r`, and its
    /// third vertex. `l`'s half-edges are sorted by target: a short list is scanned, a long
    /// one (a vertex of high valence) binary-searched, so a lookup costs `O(log valence)`;
    /// then the run of half-edges to `r` is walked from its first open one, which advances
    /// past visited triangles for good (amortized constant, also over repeated triangles).
    #[inline]
    fn find(&mut self, l: u32, r: u32) -> Option<(u32, u32)> {
        const SCAN: usize = 16;
        let (lo, hi) = (self.edges.start[l as usize] as usize, self.edges.start[l as usize + 1] as usize);
        let list = &self.edges.values[lo..hi];
        let run = if list.len() <= SCAN {
            let k = list.iter().position(|e| e.target >= r).unwrap_or(list.len());
            self.work += k as u64 + 1;
            k
        } else {
            self.work += u64::from(usize::BITS - list.len().leading_zeros());
            list.partition_point(|e| e.target < r)
        };
        if run == list.len() || list[run].target != r {
            return None;
        }
        let mut i = self.first_open[lo + run] as usize - lo;
        while i < list.len() && list[i].target == r && self.visited[list[i].tri as usize] {
            i += 1;
            self.work += 1;
        }
        self.first_open[lo + run] = (lo + i) as u32;
        list.get(i).filter(|e| e.target == r).map(|e| (e.tri, e.third))
    }

    /// Codes `cmd` in the context the decoder will see before reading it.
    #[inline]
    fn code(&mut self, cmd: Command) {
        self.sink.command(self.deg.context(S::DEGREES, self.prev, &self.frontier), cmd);
        self.prev = cmd;
        self.commands += 1;
        self.work += 1;
        self.command_counts[cmd as usize] += 1;
    }

    #[inline]
    fn slot_pos(&self, slot: u32) -> [u32; 3] {
        if slot == NONE {
            [self.max / 2 + 1; 3]
        } else {
            self.q[self.vertex_of[slot as usize] as usize]
        }
    }

    /// Gives vertex `v` a new slot; codes its position, or records it as a duplicate.
    fn new_slot(&mut self, v: u32, kind: Prediction, basis: [u32; 3]) -> u32 {
        let s = self.vertex_of.len() as u32;
        self.vertex_of.push(v);
        self.deg.add_slot(S::DEGREES);
        let first = self.slot_of[v as usize];
        if first != NONE {
            self.dups.push((s, first));
        } else {
            self.slot_of[v as usize] = s;
            let pred =
                predict(kind, self.slot_pos(basis[0]), self.slot_pos(basis[1]), self.slot_pos(basis[2]), self.max);
            let actual = self.q[v as usize];
            for (m, v) in self.max_q.iter_mut().zip(actual) {
                *m = (*m).max(v);
            }
            self.sink.position(kind, actual, pred);
        }
        s
    }

    #[inline]
    fn on_push(&mut self, pos: usize) {
        let v = self.vertex_of[self.frontier.entries[pos].slot as usize] as usize;
        if self.prev_same.len() <= pos {
            self.prev_same.resize(pos + 1, NONE);
        }
        self.prev_same[pos] = self.last_entry[v];
        self.last_entry[v] = pos as u32;
        self.entry_count[v] += 1;
        if self.remaining[v] > 0 {
            self.incomplete += 1;
        }
    }

    #[inline]
    fn on_remove(&mut self, slot: u32) {
        let v = self.vertex_of[slot as usize] as usize;
        self.entry_count[v] -= 1;
        if self.remaining[v] > 0 {
            self.incomplete -= 1;
        }
    }

    fn visit(&mut self, t: u32, slots: [u32; 3]) {
        self.visited[t as usize] = true;
        if self.record {
            self.slot_triangles.push(slots);
        }
        self.done += 1;
        for s in slots {
            let v = self.vertex_of[s as usize] as usize;
            self.remaining[v] -= 1;
            if self.remaining[v] == 0 {
                self.incomplete -= self.entry_count[v] as usize;
            }
        }
        self.deg.count(S::DEGREES, slots);
    }

    fn seed(&mut self, t: usize) {
        let [a, b, c] = self.triangles[t];
        self.code(Command::Seed);
        self.seeds += 1;
        for i in 0..self.frontier.len() {
            let slot = self.frontier.at(i).slot;
            self.on_remove(slot);
        }
        // Frontier [a, c, b] = slots [s, s+1, s+2]; the triangle (a, b, c) is (s, s+2, s+1).
        let prev = self.vertex_of.len().checked_sub(1).map_or(NONE, |s| s as u32);
        let s = self.new_slot(a, Prediction::Previous, [prev, NONE, NONE]);
        self.new_slot(c, Prediction::Previous, [s, NONE, NONE]);
        self.new_slot(b, Prediction::Midpoint, [s, s + 1, NONE]);
        self.frontier.seed(s);
        let end = self.frontier.back_pos();
        for pos in end - 3..end {
            self.on_push(pos);
        }
        self.visit(t as u32, [s, s + 2, s + 1]);
    }

    /// Codes the triangle `t` found across the current edge, with third vertex `x`.
    fn triangle(&mut self, t: u32, x: u32) {
        let l = self.frontier.at(0);
        let r = self.frontier.at(1);
        let len = self.frontier.len();
        let head = self.frontier.head;
        // The frontier occurrence of `x` with the cheapest code: RF0/LF0, else the smallest offset.
        let mut best: Option<(usize, u32)> = None;
        if self.slot_of[x as usize] != NONE {
            let mut pos = self.last_entry[x as usize];
            while pos != NONE && pos as usize >= head + 2 {
                self.work += 1;
                let p = pos as usize;
                if self.vertex_of[self.frontier.entries[p].slot as usize] != x {
                    break;
                }
                let i = p - head;
                let cost = if i == 2 || i == len - 1 { 0 } else { (i - 2).min(len - 1 - i) as u32 };
                if best.is_none_or(|(_, c)| cost < c) {
                    best = Some((i, cost));
                }
                if cost == 0 {
                    break;
                }
                pos = self.prev_same[p];
            }
        }
        match best {
            None => {
                self.code(Command::New);
                let kind = if l.apex != NONE { Prediction::Parallelogram } else { Prediction::Midpoint };
                let s = self.new_slot(x, kind, [l.slot, r.slot, l.apex]);
                self.on_remove(l.slot);
                self.frontier.insert(s);
                let end = self.frontier.back_pos();
                self.on_push(end - 2);
                self.on_push(end - 1);
                self.visit(t, [l.slot, r.slot, s]);
            }
            Some((2, _)) => {
                let xs = self.frontier.at(2).slot;
                self.code(Command::Rf0);
                self.on_remove(r.slot);
                self.frontier.remove_right(true);
                self.visit(t, [l.slot, r.slot, xs]);
            }
            Some((i, _)) if i == len - 1 => {
                let xs = self.frontier.at(i).slot;
                self.code(Command::Lf0);
                self.on_remove(l.slot);
                self.frontier.remove_left(true);
                self.visit(t, [l.slot, r.slot, xs]);
            }
            Some((i, _)) => {
                let xs = self.frontier.at(i).slot;
                let (cmd, k) = if i - 2 <= len - 1 - i { (Command::Rf, i - 2) } else { (Command::Lf, len - 1 - i) };
                self.code(cmd);
                self.sink.offset(cmd, k as u32);
                self.offset_histogram[match k {
                    0 | 1 => 0,
                    2 => 1,
                    3 => 2,
                    4..=7 => 3,
                    _ => 4,
                }] += 1;
                self.on_remove(l.slot);
                self.frontier.insert(xs);
                let end = self.frontier.back_pos();
                self.on_push(end - 2);
                self.on_push(end - 1);
                self.visit(t, [l.slot, r.slot, xs]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What `keep_slots` keeps is what the decoder has: the triangles over slots in its order
    /// and its duplicate table, on a mesh with a non-manifold vertex and edge (duplicate
    /// slots) and a degenerate triangle (loose, with a vertex only it uses); and keeping them
    /// changes no byte.
    #[test]
    fn kept_slots_are_the_decoders_view() {
        let positions = (0..8).map(|i| [i as f32, (i * i % 5) as f32, (i % 3) as f32]).collect();
        let triangles = vec![[0, 1, 2], [0, 2, 3], [0, 4, 5], [0, 5, 6], [1, 1, 7], [2, 0, 7]];
        let mesh = Mesh::new(positions, triangles);
        let used = mesh.used_vertices();
        let quant = Quantization::fit(&mesh.positions, Some(&used), 12).unwrap();
        let options = EncodeOptions::default();
        let kept = encode_quantized(&mesh, &used, quant, &options, None, true, &mut |_, _| {}).unwrap();
        let plain = encode_quantized(&mesh, &used, quant, &options, None, false, &mut |_, _| {}).unwrap();
        let d = crate::bft::decode(&kept.bytes).unwrap();
        assert!(!d.duplicates.is_empty() && d.header.loose_triangles > 0, "{:?}", d.header);
        assert_eq!(kept.slot_triangles, d.triangles);
        assert_eq!(kept.duplicates, d.duplicates);
        assert!(plain.bytes == kept.bytes && plain.slot_triangles.is_empty() && plain.duplicates.is_empty());
    }
}
