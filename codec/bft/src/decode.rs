//! BFT decoder: replays the frontier of [`super`] from the command stream.
//!
//! Every read is checked: a command the frontier cannot carry out (too short for `RF0`, an
//! offset past its end), a position outside the quantization grid, a slot index out of
//! range, a stream that ends early or counts that disagree with the header all return a
//! [`BftError`]; no input makes the decoder panic, and its loops are bounded by the
//! header's counts and the stream lengths.

use super::attributes::{self, SlotAttributes};
use super::format::{self, corrupt, get_varint, BftError, Coding, Header};
use super::frontier::{Frontier, NONE};
use super::model::{Degrees, RangeSource, SymbolSource};
use super::prefix::PrefixSource;
use crate::command::Command;
use crate::mesh::{Mesh, Quantization};

/// A decoded `.bft` file, at slot level: quantized positions per slot, triangles over
/// slots, and the duplicate table that maps repeated slots back to their first slot.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded {
    pub header: Header,
    pub positions: Vec<[u32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// `(slot, source)`: `slot` is the same input vertex as the earlier slot `source`.
    pub duplicates: Vec<(u32, u32)>,
    /// Colours and normals per slot, where the stream has them.
    pub attributes: SlotAttributes,
}

impl Decoded {
    pub fn quantization(&self) -> Quantization {
        Quantization { bits: self.header.quant_bits, min: self.header.bbox_min, step: self.header.step }
    }

    /// The decoded mesh with duplicate slots welded back: one vertex per input vertex
    /// that a triangle used, float positions, in traversal order; or, for a stream that kept
    /// the input order (`encode --keep-order`), every input vertex at its input index (those
    /// no triangle used, which are not stored, at the origin with white and +Z).
    pub fn to_mesh(&self) -> Mesh {
        let mut mesh = self.to_mesh_traversal();
        let order = &self.attributes.order;
        if order.is_empty() {
            return mesh;
        }
        // The welded vertices come in slot order of their first slots: their input indices.
        let mut duplicate = vec![false; self.positions.len()];
        for &(d, _) in &self.duplicates {
            duplicate[d as usize] = true;
        }
        let welded: Vec<u32> = (0..self.positions.len()).filter(|&s| !duplicate[s]).map(|s| order[s]).collect();
        let n = self.header.input_vertices as usize;
        let mut out = Mesh::new(vec![[0.0; 3]; n], Vec::new());
        if !mesh.colors.is_empty() {
            out.colors = vec![[255; 4]; n];
        }
        if !mesh.normals.is_empty() {
            out.normals = vec![[0.0, 0.0, 1.0]; n];
        }
        for (k, &i) in welded.iter().enumerate() {
            let i = i as usize;
            out.positions[i] = mesh.positions[k];
            if !out.colors.is_empty() {
                out.colors[i] = mesh.colors[k];
            }
            if !out.normals.is_empty() {
                out.normals[i] = mesh.normals[k];
            }
        }
        out.triangles =
            std::mem::take(&mut mesh.triangles).into_iter().map(|t| t.map(|v| welded[v as usize])).collect();
        out
    }

    fn to_mesh_traversal(&self) -> Mesh {
        let q = self.quantization();
        let n = self.positions.len();
        let mut target: Vec<u32> = (0..n as u32).collect();
        for &(slot, source) in &self.duplicates {
            target[slot as usize] = target[source as usize];
        }
        let mut remap = vec![NONE; n];
        let mut positions = Vec::with_capacity(n - self.duplicates.len());
        let a = &self.attributes;
        let (mut colors, mut normals) = (Vec::new(), Vec::new());
        for s in 0..n {
            if target[s] as usize == s {
                remap[s] = positions.len() as u32;
                positions.push(q.dequantize(self.positions[s]));
                if !a.colors.is_empty() {
                    colors.push(a.colors[s]);
                }
                if !a.normals.is_empty() {
                    normals.push(a.normal(s));
                }
            }
        }
        let triangles = self.triangles.iter().map(|t| t.map(|s| remap[target[s as usize] as usize])).collect();
        Mesh { positions, triangles, colors, normals }
    }
}

/// One command of a stream, with its offset (`RF<k>`, `LF<k>`, `ADD<k>`; 0 otherwise).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Op {
    pub cmd: Command,
    pub offset: u32,
}

/// Decodes one `.bft` stream (`super::decode` takes a chunked file too).
pub(crate) fn decode_stream(bytes: &[u8]) -> Result<Decoded, BftError> {
    decode_inner(bytes, false).map(|(d, _)| d)
}

/// Decodes `.bft` bytes and also returns the command stream, for the tile sort.
pub fn decode_ops(bytes: &[u8]) -> Result<(Decoded, Vec<Op>), BftError> {
    decode_inner(bytes, true)
}

fn decode_inner(bytes: &[u8], record: bool) -> Result<(Decoded, Vec<Op>), BftError> {
    if format::is_chunked(bytes) {
        return Err(corrupt("a chunked file (version 3) is many streams; its chunks are sorted one by one"));
    }
    let parts = format::parse(bytes)?;
    let h = parts.header;
    let [conn, geom, dup_bytes, loose_bytes, color_bytes, normal_bytes, order_bytes] = parts.sections;

    let mut duplicates = Vec::new();
    let mut pos = 0usize;
    let count = get_varint(dup_bytes, &mut pos, "duplicate table")?;
    if count != h.duplicates as u64 {
        return Err(corrupt("duplicate table size disagrees with the header"));
    }
    let mut last = 0u64;
    for i in 0..count {
        let gap = get_varint(dup_bytes, &mut pos, "duplicate table")?;
        let source = get_varint(dup_bytes, &mut pos, "duplicate table")?;
        let slot = last + gap;
        if (i > 0 && gap == 0) || slot >= h.slots as u64 || source >= slot {
            return Err(corrupt(format!("duplicate entry {i} ({slot} of {source}) is out of order or range")));
        }
        duplicates.push((slot as u32, source as u32));
        last = slot;
    }
    if pos != dup_bytes.len() {
        return Err(corrupt("trailing bytes in the duplicate table"));
    }

    let (mut decoded, ops) = match h.coding {
        Coding::Range => decode_streams(h, RangeSource::new(conn, geom), duplicates, loose_bytes, record),
        Coding::PrefixByDegree => {
            decode_streams(h, PrefixSource::<true>::new(conn, geom, h.commands)?, duplicates, loose_bytes, record)
        }
        Coding::Prefix => {
            decode_streams(h, PrefixSource::<false>::new(conn, geom, h.commands)?, duplicates, loose_bytes, record)
        }
    }?;
    let flags = h.attributes;
    let input = attributes::Input {
        positions: &decoded.positions,
        triangles: &decoded.triangles,
        duplicates: &decoded.duplicates,
    };
    let mut a = SlotAttributes { alpha: flags.alpha, normal_bits: flags.normal_bits, ..Default::default() };
    if flags.colors {
        a.colors = attributes::decode_colors(&input, color_bytes, flags.alpha)?;
    }
    if flags.normal_bits > 0 {
        a.normals = attributes::decode_normals(&input, normal_bytes, flags.normal_bits, parts.prefix_normals)?;
    }
    if flags.order {
        a.order =
            attributes::decode_order(decoded.positions.len(), &decoded.duplicates, order_bytes, h.input_vertices)?;
    }
    decoded.attributes = a;
    Ok((decoded, ops))
}

fn decode_streams<S: SymbolSource>(
    h: Header,
    source: S,
    duplicates: Vec<(u32, u32)>,
    loose_bytes: &[u8],
    record: bool,
) -> Result<(Decoded, Vec<Op>), BftError> {
    // Capacities come from the header, capped, so a forged count cannot allocate wildly.
    const CAP: usize = 1 << 22;
    let mut st = State {
        source,
        f: Frontier::default(),
        positions: Vec::with_capacity((h.slots as usize).min(CAP)),
        deg: Degrees::with_capacity(S::DEGREES, (h.slots as usize).min(CAP)),
        triangles: Vec::with_capacity((h.triangles as usize).min(CAP)),
        max: (1u32 << h.quant_bits) - 1,
        slots: h.slots,
        ops: if record { Vec::with_capacity((h.commands as usize).min(CAP)) } else { Vec::new() },
        record,
    };
    st.f.entries.reserve((h.triangles as usize).min(CAP));
    st.run(h.commands, h.triangles - h.loose_triangles)?;
    for _ in 0..h.tail_slots {
        let prev = st.positions.len().checked_sub(1).map_or(NONE, |s| s as u32);
        st.new_slot([prev, NONE, NONE])?;
    }
    if st.positions.len() != h.slots as usize {
        return Err(corrupt(format!("decoded {} vertex slots, header says {}", st.positions.len(), h.slots)));
    }
    st.source.positions(&mut st.positions, &duplicates, st.max)?;
    let [conn_over, geom_over] = st.source.overrun();
    if conn_over > 0 {
        return Err(BftError::Truncated("connectivity stream"));
    }
    if geom_over > 0 {
        return Err(BftError::Truncated("geometry stream"));
    }

    let mut pos = 0usize;
    for _ in 0..h.loose_triangles {
        let mut t = [0u32; 3];
        for v in &mut t {
            let s = get_varint(loose_bytes, &mut pos, "loose triangles")?;
            if s >= h.slots as u64 {
                return Err(corrupt(format!("loose triangle uses slot {s} of {}", h.slots)));
            }
            *v = s as u32;
        }
        st.triangles.push(t);
    }
    if pos != loose_bytes.len() {
        return Err(corrupt("trailing bytes in the loose triangle section"));
    }
    let State { positions, triangles, ops, .. } = st;
    Ok((Decoded { header: h, positions, triangles, duplicates, attributes: SlotAttributes::default() }, ops))
}

struct State<S> {
    source: S,
    f: Frontier,
    positions: Vec<[u32; 3]>,
    deg: Degrees,
    triangles: Vec<[u32; 3]>,
    max: u32,
    slots: u32,
    ops: Vec<Op>,
    record: bool,
}

impl<S: SymbolSource> State<S> {
    /// Adds a slot whose position [`SymbolSource::positions`] decodes after the
    /// connectivity, from the slots in `basis`, which stands in its place until then.
    #[inline]
    fn new_slot(&mut self, basis: [u32; 3]) -> Result<u32, BftError> {
        let s = self.positions.len() as u32;
        if s >= self.slots {
            return Err(corrupt(format!("more vertex slots than the header's {}", self.slots)));
        }
        self.positions.push(basis);
        self.deg.add_slot(S::DEGREES);
        Ok(s)
    }

    #[inline]
    fn emit(&mut self, t: [u32; 3]) {
        self.deg.count(S::DEGREES, t);
        self.triangles.push(t);
    }

    #[inline(always)]
    fn need(&self, n: usize, cmd: Command) -> Result<(), BftError> {
        if self.f.len() < n {
            return Err(corrupt(format!("{cmd:?} on a frontier of {} vertices", self.f.len())));
        }
        Ok(())
    }

    #[inline(always)]
    fn check_offset(&self, cmd: Command, k: u32, limit: usize) -> Result<usize, BftError> {
        let k = k as usize;
        if k >= limit {
            return Err(corrupt(format!("{cmd:?} offset {k} past the frontier ({} vertices)", self.f.len())));
        }
        Ok(k)
    }

    fn run(&mut self, commands: u32, triangles: u32) -> Result<(), BftError> {
        // What stops a forged stream (more triangles than the header's, reading far past the
        // data) and the frontier's compaction are checked once a block of commands: a block
        // adds at most `BLOCK` triangles and reads a bounded number of bits.
        const BLOCK: u32 = 256;
        let mut next = if commands > 0 && !S::DEGREES { self.read(Command::Seed)? } else { (Command::Seed, 0) };
        let mut done = 0;
        while done < commands {
            let block = BLOCK.min(commands - done);
            done += block;
            for i in 0..block {
                if !S::DEGREES {
                    // The next command is read before this one is carried out: its context is
                    // this command, and the reads' chain then runs on while the branch on
                    // this command's kind, which no predictor guesses, is resolved.
                    let (cmd, k) = next;
                    if done - block + i + 1 < commands {
                        next = self.read(cmd)?;
                    }
                    self.execute(cmd, k)?;
                } else {
                    next = self.read(next.0)?;
                    self.execute(next.0, next.1)?;
                }
            }
            self.f.compact();
            if self.triangles.len() > triangles as usize {
                return Err(corrupt("more triangles than the header says"));
            }
            if self.source.overrun()[0] > 8 {
                return Err(BftError::Truncated("connectivity stream"));
            }
        }
        if self.triangles.len() != triangles as usize {
            return Err(corrupt(format!("decoded {} triangles, header says {triangles}", self.triangles.len())));
        }
        Ok(())
    }

    /// Reads the command after `prev`, and its offset where it has one (0 otherwise).
    #[inline(always)]
    fn read(&mut self, prev: Command) -> Result<(Command, u32), BftError> {
        let ctx = self.deg.context(S::DEGREES, prev, &self.f);
        let cmd = self.source.command(ctx).ok_or_else(|| corrupt("invalid command code"))?;
        let k = match cmd {
            Command::Rf | Command::Lf | Command::AddRef => {
                self.source.offset(cmd).ok_or_else(|| corrupt("bad offset code"))?
            }
            _ => 0,
        };
        Ok((cmd, k))
    }

    /// Carries out `cmd` with its offset `k`.
    #[inline(always)]
    fn execute(&mut self, cmd: Command, k: u32) -> Result<(), BftError> {
        let len = self.f.len();
        match cmd {
            Command::New => {
                self.need(2, cmd)?;
                let (l, r) = (self.f.at(0), self.f.at(1));
                let s = self.new_slot([l.slot, r.slot, l.apex])?;
                self.f.insert(s);
                self.emit([l.slot, r.slot, s]);
            }
            Command::Rf0 => {
                self.need(3, cmd)?;
                let t = [self.f.at(0).slot, self.f.at(1).slot, self.f.at(2).slot];
                self.f.remove_right(true);
                self.emit(t);
            }
            Command::Lf0 => {
                self.need(3, cmd)?;
                let t = [self.f.at(0).slot, self.f.at(1).slot, self.f.at(len - 1).slot];
                self.f.remove_left(true);
                self.emit(t);
            }
            Command::Rf | Command::Lf => {
                self.need(3, cmd)?;
                let k = self.check_offset(cmd, k, len - 2)?;
                let i = if cmd == Command::Rf { 2 + k } else { len - 1 - k };
                let t = [self.f.at(0).slot, self.f.at(1).slot, self.f.at(i).slot];
                self.f.insert(t[2]);
                self.emit(t);
            }
            Command::Null => {
                self.need(1, cmd)?;
                self.f.skip();
            }
            Command::Dl => {
                self.need(1, cmd)?;
                self.f.remove_left(false);
            }
            Command::Dr => {
                self.need(2, cmd)?;
                self.f.remove_right(false);
            }
            Command::AddNew => {
                let prev_slot = self.positions.len().checked_sub(1).map_or(NONE, |s| s as u32);
                let s = self.new_slot([prev_slot, NONE, NONE])?;
                self.f.add(s);
            }
            Command::AddRef => {
                self.need(1, cmd)?;
                let k = self.check_offset(cmd, k, len)?;
                let x = self.f.at(len - 1 - k).slot;
                self.f.add(x);
            }
            Command::Seed => {
                let prev_slot = self.positions.len().checked_sub(1).map_or(NONE, |s| s as u32);
                let s = self.new_slot([prev_slot, NONE, NONE])?;
                self.new_slot([s, NONE, NONE])?;
                self.new_slot([s, s + 1, NONE])?;
                self.f.seed(s);
                self.emit([s, s + 2, s + 1]);
            }
            Command::Clear => self.f.clear(),
        }
        if self.record {
            self.ops.push(Op { cmd, offset: k });
        }
        Ok(())
    }
}
