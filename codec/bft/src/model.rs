//! Context models for the two BFT streams. Encoder, decoder and tile sort share them, so a
//! context is computed one way only.

use super::format::{corrupt, BftError};
use super::frontier::{Frontier, NONE};
use crate::command::Command;
use crate::rangecoder::{BitTree, Decoder, Encoder, UIntCoder, PROB_INIT};

/// Visited degrees above this share a context.
const DEG_CAP: u8 = 6;
const DEG_CTX: usize = DEG_CAP as usize + 1;
/// Previous-command classes: 0 = triangle opening (`NEW`, `RF<k>`, `LF<k>`, `SEED`),
/// 1 = closing (`RF0`, `LF0`), 2 = anything else.
const PREV_CTX: usize = 3;
pub const COMMAND_CONTEXTS: usize = PREV_CTX * DEG_CTX * DEG_CTX;

/// The context of the next command: the previous command, its class, and the visited
/// degrees (triangles coded so far, capped) of the current edge's vertices. The range coder
/// takes its [`Context::index`], the prefix coder its [`Context::prefix_table`] (or, in
/// streams of [`Coding::PrefixByDegree`](super::Coding::PrefixByDegree),
/// [`Context::prefix_table_by_degree`]); all derive from the parts, since taking an index
/// apart by division costs an eighth of a prefix-coded tile's decode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Context {
    prev: Command,
    class: u8,
    deg_l: u8,
    deg_r: u8,
}

#[inline]
pub fn command_context(prev: Command, deg_l: u8, deg_r: u8) -> Context {
    let class = match prev {
        Command::New | Command::Rf | Command::Lf | Command::Seed => 0,
        Command::Rf0 | Command::Lf0 => 1,
        _ => 2,
    };
    Context { prev, class, deg_l: deg_l.min(DEG_CAP), deg_r: deg_r.min(DEG_CAP) }
}

impl Context {
    /// The range coder's context, below [`COMMAND_CONTEXTS`].
    #[inline]
    pub fn index(self) -> usize {
        (self.class as usize * DEG_CTX + self.deg_l as usize) * DEG_CTX + self.deg_r as usize
    }

    /// The prefix coder's table: the previous command. It needs nothing of the frontier,
    /// so a decoder reads the next command before it carries out this one; and it predicts
    /// better than [`Context::prefix_table_by_degree`]: the dragon's whole tile (14 bits) is
    /// 1,240,392 bytes against 1,258,278, its 8x8 tiles at 16 bits 1,586,400 against
    /// 1,603,976 (`docs/results.md`).
    #[inline]
    pub fn prefix_table(self) -> usize {
        self.prev as usize
    }

    /// The first prefix coding's table ([`Coding::PrefixByDegree`](super::Coding::PrefixByDegree)):
    /// the previous command's class times the left vertex's degree, capped at 3.
    #[inline]
    pub fn prefix_table_by_degree(self) -> usize {
        self.class as usize * 4 + self.deg_l.min(3) as usize
    }
}

/// The visited degree of every slot (the triangles coded so far that use it), which the
/// command contexts of the range coding and of
/// [`Coding::PrefixByDegree`](super::Coding::PrefixByDegree) hold. Encoder, decoder and tile
/// writer keep them with these methods alone, and only where their coding's contexts use them
/// (`on`: their [`SymbolSink::DEGREES`] or [`SymbolSource::DEGREES`]); otherwise they keep
/// nothing and a context is the previous command's.
pub(crate) struct Degrees(Vec<u8>);

impl Degrees {
    /// Room for `slots` slots where `on`.
    pub fn with_capacity(on: bool, slots: usize) -> Self {
        Degrees(if on { Vec::with_capacity(slots) } else { Vec::new() })
    }

    /// A new slot, of no triangle yet.
    #[inline]
    pub fn add_slot(&mut self, on: bool) {
        if on {
            self.0.push(0);
        }
    }

    /// The triangle `t` is coded.
    #[inline]
    pub fn count(&mut self, on: bool, t: [u32; 3]) {
        if on {
            for s in t {
                let d = &mut self.0[s as usize];
                *d = d.saturating_add(1);
            }
        }
    }

    /// The context of the command after `prev` on the frontier `f`.
    #[inline]
    pub fn context(&self, on: bool, prev: Command, f: &Frontier) -> Context {
        if !on {
            return command_context(prev, 0, 0);
        }
        let len = f.len();
        let dl = if len >= 1 { self.0[f.at(0).slot as usize] } else { 0 };
        let dr = if len >= 2 { self.0[f.at(1).slot as usize] } else { 0 };
        command_context(prev, dl, dr)
    }
}

/// Binary decomposition of [`Command`], per context:
/// node 0: triangle-producing (0) or not (1);
/// node 1: `NEW` (0) or an existing third vertex (1); node 2: closing (0) or generic (1);
/// node 3: `RF0`/`LF0`; node 4: `RF`/`LF`; nodes 8..16: a 3-bit tree over the others.
const OTHERS: [Command; 7] =
    [Command::Null, Command::Dl, Command::Dr, Command::AddNew, Command::AddRef, Command::Seed, Command::Clear];

pub struct CommandModel {
    probs: Vec<[u16; 5]>,
    others: Vec<BitTree<8>>,
    /// Offsets of `RF<k>`, `LF<k>`, `ADD<k>`.
    offsets: [UIntCoder; 3],
}

impl Default for CommandModel {
    fn default() -> Self {
        CommandModel {
            probs: vec![[PROB_INIT; 5]; COMMAND_CONTEXTS],
            others: vec![BitTree::default(); COMMAND_CONTEXTS],
            offsets: Default::default(),
        }
    }
}

impl CommandModel {
    #[inline]
    pub fn encode(&mut self, enc: &mut Encoder, ctx: usize, cmd: Command) {
        let p = &mut self.probs[ctx];
        match cmd {
            Command::New => {
                enc.bit(&mut p[0], false);
                enc.bit(&mut p[1], false);
            }
            Command::Rf0 | Command::Lf0 => {
                enc.bit(&mut p[0], false);
                enc.bit(&mut p[1], true);
                enc.bit(&mut p[2], false);
                enc.bit(&mut p[3], cmd == Command::Lf0);
            }
            Command::Rf | Command::Lf => {
                enc.bit(&mut p[0], false);
                enc.bit(&mut p[1], true);
                enc.bit(&mut p[2], true);
                enc.bit(&mut p[4], cmd == Command::Lf);
            }
            other => {
                enc.bit(&mut p[0], true);
                let i = OTHERS.iter().position(|&c| c == other).expect("every command is coded") as u32;
                self.others[ctx].encode(enc, i);
            }
        }
    }

    /// Decodes a command; `None` for the one unused code.
    #[inline]
    pub fn decode(&mut self, dec: &mut Decoder, ctx: usize) -> Option<Command> {
        let p = &mut self.probs[ctx];
        if !dec.bit(&mut p[0]) {
            if !dec.bit(&mut p[1]) {
                return Some(Command::New);
            }
            Some(if !dec.bit(&mut p[2]) {
                if dec.bit(&mut p[3]) {
                    Command::Lf0
                } else {
                    Command::Rf0
                }
            } else if dec.bit(&mut p[4]) {
                Command::Lf
            } else {
                Command::Rf
            })
        } else {
            OTHERS.get(self.others[ctx].decode(dec) as usize).copied()
        }
    }

    #[inline]
    fn offset_index(cmd: Command) -> usize {
        match cmd {
            Command::Rf => 0,
            Command::Lf => 1,
            _ => 2,
        }
    }

    #[inline]
    pub fn encode_offset(&mut self, enc: &mut Encoder, cmd: Command, k: u32) {
        self.offsets[Self::offset_index(cmd)].encode(enc, k);
    }

    #[inline]
    pub fn decode_offset(&mut self, dec: &mut Decoder, cmd: Command) -> Option<u32> {
        self.offsets[Self::offset_index(cmd)].decode(dec)
    }
}

/// How a new vertex's position was predicted; part of the residual context.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Prediction {
    /// `l + r - apex` across the current edge.
    Parallelogram,
    /// The midpoint of the current edge, when the edge has no apex.
    Midpoint,
    /// The previous slot's position (seeds, adds, loose-only vertices).
    Previous,
}

/// The position a prediction uses for `slot`: the slot's decoded position, or the grid's
/// center for [`NONE`] (the first vertex of a stream has nothing before it).
#[inline]
pub fn basis_position(positions: &[[u32; 3]], slot: u32, max: u32) -> [u32; 3] {
    if slot == NONE {
        [max / 2 + 1; 3]
    } else {
        positions[slot as usize]
    }
}

/// Predicts a quantized position. Inputs are positions of already decoded slots.
#[inline]
pub fn predict(kind: Prediction, a: [u32; 3], b: [u32; 3], c: [u32; 3], max: u32) -> [u32; 3] {
    match kind {
        Prediction::Parallelogram => {
            let f = |i: usize| (a[i] as i64 + b[i] as i64 - c[i] as i64).clamp(0, max as i64) as u32;
            [f(0), f(1), f(2)]
        }
        Prediction::Midpoint => {
            let f = |i: usize| ((a[i] as u64 + b[i] as u64) / 2) as u32;
            [f(0), f(1), f(2)]
        }
        Prediction::Previous => a,
    }
}

const CLASS_CTX: usize = 4;

/// Residual coder: per axis, the bit length of `|residual|` through a bit tree (context:
/// prediction kind and the previous residual's length on that axis), then the sign, the
/// bit below the leading one adaptively, and the rest as direct bits.
pub struct GeometryModel {
    class: Vec<BitTree<32>>,
    sign: [u16; 3],
    second: [[u16; 32]; 3],
    prev_class: [u32; 3],
}

impl Default for GeometryModel {
    fn default() -> Self {
        GeometryModel {
            class: vec![BitTree::default(); 3 * 3 * CLASS_CTX],
            sign: [PROB_INIT; 3],
            second: [[PROB_INIT; 32]; 3],
            prev_class: [0; 3],
        }
    }
}

impl GeometryModel {
    #[inline]
    fn ctx(&self, kind: Prediction, axis: usize) -> usize {
        let k = kind as usize;
        let p = (self.prev_class[axis] as usize / 3).min(CLASS_CTX - 1);
        (k * 3 + axis) * CLASS_CTX + p
    }

    #[inline]
    pub fn encode(&mut self, enc: &mut Encoder, kind: Prediction, actual: [u32; 3], pred: [u32; 3]) {
        for axis in 0..3 {
            let r = actual[axis] as i64 - pred[axis] as i64;
            let m = r.unsigned_abs() as u32;
            let class = 32 - m.leading_zeros();
            let ctx = self.ctx(kind, axis);
            self.class[ctx].encode(enc, class);
            if class > 0 {
                enc.bit(&mut self.sign[axis], r < 0);
                if class >= 2 {
                    let rest = class - 1;
                    enc.bit(&mut self.second[axis][class as usize], (m >> (rest - 1)) & 1 != 0);
                    enc.direct_bits(m, rest - 1);
                }
            }
            self.prev_class[axis] = class;
        }
    }

    /// Decodes a position; `None` if it falls outside `0..=max`.
    #[inline]
    pub fn decode(&mut self, dec: &mut Decoder, kind: Prediction, pred: [u32; 3], max: u32) -> Option<[u32; 3]> {
        let mut out = [0u32; 3];
        for axis in 0..3 {
            let ctx = self.ctx(kind, axis);
            let class = self.class[ctx].decode(dec);
            let mut m: u32 = 0;
            let mut neg = false;
            if class > 0 {
                if class > 25 {
                    return None;
                }
                neg = dec.bit(&mut self.sign[axis]);
                m = 1 << (class - 1);
                if class >= 2 {
                    let rest = class - 1;
                    let top = dec.bit(&mut self.second[axis][class as usize]) as u32;
                    m |= top << (rest - 1) | dec.direct_bits(rest - 1);
                }
            }
            let v = pred[axis] as i64 + if neg { -(m as i64) } else { m as i64 };
            if v < 0 || v > max as i64 {
                return None;
            }
            out[axis] = v as u32;
            self.prev_class[axis] = class;
        }
        Some(out)
    }
}

/// Where a stream's commands, offsets and positions go: the tile writer codes through it,
/// so one writer serves both [`super::Coding`]s.
pub(crate) trait SymbolSink {
    /// Whether a command's context holds the frontier's degrees ([`SymbolSource::DEGREES`]);
    /// where it does not, the writer keeps none.
    const DEGREES: bool = true;
    /// A sink for about this many commands and coded positions.
    fn with_capacity(commands: usize, positions: usize) -> Self;
    fn command(&mut self, ctx: Context, cmd: Command);
    fn offset(&mut self, cmd: Command, k: u32);
    fn position(&mut self, kind: Prediction, actual: [u32; 3], pred: [u32; 3]);
    /// The `CONN` and `GEOM` streams.
    fn finish(self) -> [Vec<u8>; 2];
}

/// Where the decoder reads them from. `None` for a code that is not valid here.
pub(crate) trait SymbolSource {
    /// Whether a command's context holds the frontier's degrees. Where it does not (only the
    /// commands before it), the decoder keeps no degrees and reads each command before it
    /// carries out the one before.
    const DEGREES: bool = true;
    fn command(&mut self, ctx: Context) -> Option<Command>;
    fn offset(&mut self, cmd: Command) -> Option<u32>;
    /// Decodes every slot's position from `GEOM` ([`decode_positions`]).
    fn positions(&mut self, slots: &mut [[u32; 3]], dups: &[(u32, u32)], max: u32) -> Result<(), BftError>;
    /// Bytes wanted past the end of the `CONN` and the `GEOM` stream.
    fn overrun(&self) -> [usize; 2];
}

/// The geometry half of a [`SymbolSource`]: one position's residuals.
pub(crate) trait ResidualSource {
    fn position(&mut self, kind: Prediction, pred: [u32; 3], max: u32) -> Option<[u32; 3]>;
    /// Bytes wanted past the end of the `GEOM` stream.
    fn overrun(&self) -> usize;
}

/// Decodes the positions of all slots, in slot order, once the connectivity is decoded:
/// `slots` holds each slot's basis in its place, `[previous, NONE, NONE]` to predict from
/// the previous slot, `[l, r, NONE]` from the midpoint of `l` and `r`, `[l, r, apex]` by the
/// parallelogram, and `dups` the duplicate table (`(slot, source)` by slot), whose slots
/// take their source's position and read nothing. A basis slot precedes its slot, so its
/// position is decoded when it is needed.
///
/// Why a pass of its own: the connectivity loop, whose commands the prefix coding reads
/// ahead, stays small, and the residuals' reader is held in locals for the pass (see
/// `PrefixSource::positions`). Measured no slower than decoding each position as its slot is
/// made (the dragon's whole tile, 26.3 against 26.0 Mtri/s, alternated, before the residual
/// lookup tables).
#[inline(always)]
pub(crate) fn decode_positions<R: ResidualSource>(
    source: &mut R,
    slots: &mut [[u32; 3]],
    dups: &[(u32, u32)],
    max: u32,
) -> Result<(), BftError> {
    // Past the stream's end positions decode from zeros: the overrun is checked once a
    // block, which reads a bounded number of bits.
    const BLOCK: usize = 1024;
    let mut dups = dups.iter().peekable();
    let mut start = 0;
    while start < slots.len() {
        let end = (start + BLOCK).min(slots.len());
        for s in start..end {
            let p = match dups.peek() {
                Some(&&(slot, source)) if slot as usize == s => {
                    dups.next();
                    slots[source as usize]
                }
                _ => {
                    let b = slots[s];
                    let kind = if b[1] == NONE {
                        Prediction::Previous
                    } else if b[2] == NONE {
                        Prediction::Midpoint
                    } else {
                        Prediction::Parallelogram
                    };
                    let at = |slot: u32| basis_position(slots, slot, max);
                    let pred = predict(kind, at(b[0]), at(b[1]), at(b[2]), max);
                    source
                        .position(kind, pred, max)
                        .ok_or_else(|| corrupt(format!("position of vertex {s} is outside the quantization grid")))?
                }
            };
            slots[s] = p;
        }
        if source.overrun() > 8 {
            return Err(BftError::Truncated("geometry stream"));
        }
        start = end;
    }
    Ok(())
}

/// [`super::Coding::Range`]: the adaptive context models over two range coders.
#[derive(Default)]
pub(crate) struct RangeSink {
    conn: Encoder,
    geom: Encoder,
    cmodel: CommandModel,
    gmodel: GeometryModel,
}

impl SymbolSink for RangeSink {
    fn with_capacity(_: usize, _: usize) -> Self {
        RangeSink::default()
    }

    #[inline]
    fn command(&mut self, ctx: Context, cmd: Command) {
        self.cmodel.encode(&mut self.conn, ctx.index(), cmd);
    }

    #[inline]
    fn offset(&mut self, cmd: Command, k: u32) {
        self.cmodel.encode_offset(&mut self.conn, cmd, k);
    }

    #[inline]
    fn position(&mut self, kind: Prediction, actual: [u32; 3], pred: [u32; 3]) {
        self.gmodel.encode(&mut self.geom, kind, actual, pred);
    }

    fn finish(self) -> [Vec<u8>; 2] {
        [self.conn.finish(), self.geom.finish()]
    }
}

pub(crate) struct RangeSource<'a> {
    conn: Decoder<'a>,
    geom: Decoder<'a>,
    cmodel: CommandModel,
    gmodel: GeometryModel,
}

impl<'a> RangeSource<'a> {
    pub fn new(conn: &'a [u8], geom: &'a [u8]) -> Self {
        RangeSource {
            conn: Decoder::new(conn),
            geom: Decoder::new(geom),
            cmodel: CommandModel::default(),
            gmodel: GeometryModel::default(),
        }
    }
}

impl SymbolSource for RangeSource<'_> {
    #[inline]
    fn command(&mut self, ctx: Context) -> Option<Command> {
        self.cmodel.decode(&mut self.conn, ctx.index())
    }

    #[inline]
    fn offset(&mut self, cmd: Command) -> Option<u32> {
        self.cmodel.decode_offset(&mut self.conn, cmd)
    }

    fn positions(&mut self, slots: &mut [[u32; 3]], dups: &[(u32, u32)], max: u32) -> Result<(), BftError> {
        decode_positions(self, slots, dups, max)
    }

    fn overrun(&self) -> [usize; 2] {
        [self.conn.overrun(), self.geom.overrun()]
    }
}

impl ResidualSource for RangeSource<'_> {
    #[inline]
    fn position(&mut self, kind: Prediction, pred: [u32; 3], max: u32) -> Option<[u32; 3]> {
        self.gmodel.decode(&mut self.geom, kind, pred, max)
    }

    fn overrun(&self) -> usize {
        self.geom.overrun()
    }
}
