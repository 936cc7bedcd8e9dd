//! One tile's output stream during the tile sort.
//!
//! A `TileWriter` keeps exactly the state the ordinary decoder will have when it reads the
//! tile (its frontier, visited degrees, positions, context models), so it can code each
//! rewritten command in the decoder's context and predict each new vertex as the decoder
//! will. It is the decoder of `decode.rs` run forwards: same frontier methods, same models,
//! same predictions, encoding where the decoder decodes.

use super::attributes::{self, SlotAttributes};
use super::format::{self, put_varint, AttributeFlags, Coding, Header};
use super::frontier::{Frontier, NONE};
use super::model::{basis_position, predict, Degrees, Prediction, SymbolSink};
use crate::command::Command;

pub(crate) struct TileWriter<S> {
    pub f: Frontier,
    deg: Degrees,
    positions: Vec<[u32; 3]>,
    /// Tile slot -> the model's slot (ascending: tile slots are created in model order).
    pub global: Vec<u32>,
    sink: S,
    prev: Command,
    max: u32,
    commands: u32,
    seeds: u32,
    pub triangles: u32,
    tail_slots: u32,
    loose: Vec<[u32; 3]>,
    /// The tile's triangles over its slots, kept when the model has attributes (whose
    /// predictions use them), in the order the decoder will have them.
    record: Option<Vec<[u32; 3]>>,
}

impl<S: SymbolSink> TileWriter<S> {
    /// A writer for about `commands` commands: its buffers start that large, so that they
    /// do not grow and copy themselves while the tile is written.
    pub fn new(quant_bits: u8, commands: usize, attributes: bool) -> Self {
        let vertices = commands / 2 + 16;
        TileWriter {
            f: Frontier { entries: Vec::with_capacity(commands * 2), head: 0 },
            deg: Degrees::with_capacity(S::DEGREES, vertices),
            positions: Vec::with_capacity(vertices),
            global: Vec::with_capacity(vertices),
            sink: S::with_capacity(commands, vertices),
            prev: Command::Seed,
            max: (1u32 << quant_bits) - 1,
            commands: 0,
            seeds: 0,
            triangles: 0,
            tail_slots: 0,
            loose: Vec::new(),
            record: attributes.then(|| Vec::with_capacity(commands)),
        }
    }

    #[inline]
    fn code(&mut self, cmd: Command) {
        self.sink.command(self.deg.context(S::DEGREES, self.prev, &self.f), cmd);
        self.prev = cmd;
        self.commands += 1;
    }

    #[inline]
    fn slot_pos(&self, slot: u32) -> [u32; 3] {
        basis_position(&self.positions, slot, self.max)
    }

    fn new_slot(&mut self, global: u32, q: [u32; 3], kind: Prediction, basis: [u32; 3]) -> u32 {
        let pred = predict(kind, self.slot_pos(basis[0]), self.slot_pos(basis[1]), self.slot_pos(basis[2]), self.max);
        self.sink.position(kind, q, pred);
        let s = self.positions.len() as u32;
        self.positions.push(q);
        self.deg.add_slot(S::DEGREES);
        self.global.push(global);
        s
    }

    fn prev_slot(&self) -> u32 {
        self.positions.len().checked_sub(1).map_or(NONE, |s| s as u32)
    }

    #[inline]
    fn emit(&mut self, t: [u32; 3]) {
        self.deg.count(S::DEGREES, t);
        self.triangles += 1;
        if let Some(r) = &mut self.record {
            r.push(t);
        }
    }

    /// `NEW` with the model's slot `global` at position `q`.
    pub fn new_vertex(&mut self, global: u32, q: [u32; 3]) {
        self.code(Command::New);
        let (l, r) = (self.f.at(0), self.f.at(1));
        let kind = if l.apex != NONE { Prediction::Parallelogram } else { Prediction::Midpoint };
        let s = self.new_slot(global, q, kind, [l.slot, r.slot, l.apex]);
        self.f.insert(s);
        self.emit([l.slot, r.slot, s]);
    }

    pub fn rf0(&mut self) {
        self.code(Command::Rf0);
        let t = [self.f.at(0).slot, self.f.at(1).slot, self.f.at(2).slot];
        self.f.remove_right(true);
        self.emit(t);
    }

    pub fn lf0(&mut self) {
        self.code(Command::Lf0);
        let len = self.f.len();
        let t = [self.f.at(0).slot, self.f.at(1).slot, self.f.at(len - 1).slot];
        self.f.remove_left(true);
        self.emit(t);
    }

    /// A generic `RF<k>`/`LF<k>` to the tile frontier position `i >= 2`, whichever offset is
    /// smaller (both change the frontier alike).
    pub fn existing(&mut self, i: usize) {
        let len = self.f.len();
        debug_assert!(i >= 2 && i < len);
        let (cmd, k) = if i - 2 <= len - 1 - i { (Command::Rf, i - 2) } else { (Command::Lf, len - 1 - i) };
        self.code(cmd);
        self.sink.offset(cmd, k as u32);
        let t = [self.f.at(0).slot, self.f.at(1).slot, self.f.at(i).slot];
        self.f.insert(t[2]);
        self.emit(t);
    }

    pub fn null(&mut self) {
        self.code(Command::Null);
        self.f.skip();
    }

    pub fn dl(&mut self) {
        self.code(Command::Dl);
        self.f.remove_left(false);
    }

    pub fn dr(&mut self) {
        self.code(Command::Dr);
        self.f.remove_right(false);
    }

    pub fn add_new(&mut self, global: u32, q: [u32; 3]) {
        self.code(Command::AddNew);
        let prev = self.prev_slot();
        let s = self.new_slot(global, q, Prediction::Previous, [prev, NONE, NONE]);
        self.f.add(s);
    }

    /// `ADD<k>` of the vertex at tile frontier position `i`.
    pub fn add_ref(&mut self, i: usize) {
        let len = self.f.len();
        self.code(Command::AddRef);
        self.sink.offset(Command::AddRef, (len - 1 - i) as u32);
        let x = self.f.at(i).slot;
        self.f.add(x);
    }

    pub fn seed(&mut self, global: [u32; 3], q: [[u32; 3]; 3]) {
        self.code(Command::Seed);
        self.seeds += 1;
        let prev = self.prev_slot();
        let s = self.new_slot(global[0], q[0], Prediction::Previous, [prev, NONE, NONE]);
        self.new_slot(global[1], q[1], Prediction::Previous, [s, NONE, NONE]);
        self.new_slot(global[2], q[2], Prediction::Midpoint, [s, s + 1, NONE]);
        self.f.seed(s);
        self.emit([s, s + 2, s + 1]);
    }

    pub fn clear(&mut self) {
        self.code(Command::Clear);
        self.f.clear();
    }

    /// A vertex only loose triangles use, after the command stream.
    pub fn tail_vertex(&mut self, global: u32, q: [u32; 3]) {
        let prev = self.prev_slot();
        self.new_slot(global, q, Prediction::Previous, [prev, NONE, NONE]);
        self.tail_slots += 1;
    }

    /// A loose triangle over model slots, all of which this tile has.
    pub fn loose(&mut self, t: [u32; 3]) {
        let local = t.map(|g| self.global.binary_search(&g).expect("tile has every vertex of its triangles") as u32);
        self.loose.push(local);
        self.triangles += 1;
    }

    /// The tile's `.bft` bytes: the model's quantization, this tile's counts and streams,
    /// coded as `coding` (the sink's), and its slots' values of the model's `attributes`; and
    /// the model slot of each of its vertices.
    pub fn finish(self, model: &Header, model_attributes: &SlotAttributes, coding: Coding) -> (Vec<u8>, Vec<u32>) {
        let slots = self.positions.len() as u32;
        let header = Header {
            input_vertices: slots,
            slots,
            triangles: self.triangles,
            loose_triangles: self.loose.len() as u32,
            commands: self.commands,
            seeds: self.seeds,
            duplicates: 0,
            tail_slots: self.tail_slots,
            components: 0,
            quant_bits: model.quant_bits,
            coding,
            bbox_min: model.bbox_min,
            step: model.step,
            bbox_max: model.bbox_max,
            attributes: AttributeFlags { order: false, ..model.attributes },
        };
        let mut dups = Vec::new();
        put_varint(&mut dups, 0);
        let mut loose = Vec::new();
        for s in self.loose.iter().flatten() {
            put_varint(&mut loose, *s as u64);
        }
        let (mut colors, mut normals) = (Vec::new(), Vec::new());
        if let Some(mut triangles) = self.record {
            triangles.extend_from_slice(&self.loose);
            let input = attributes::Input { positions: &self.positions, triangles: &triangles, duplicates: &[] };
            let a = model_attributes.select(&self.global);
            if header.attributes.colors {
                colors = attributes::encode_colors(&input, &a.colors, a.alpha);
            }
            if header.attributes.normal_bits > 0 {
                normals = attributes::encode_normals(&input, &a.normals, a.normal_bits, coding);
            }
        }
        let [conn, geom] = self.sink.finish();
        (format::write(&header, [&conn, &geom, &dups, &loose, &colors, &normals, &[]]), self.global)
    }
}
