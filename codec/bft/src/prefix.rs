//! [`Coding::Prefix`](super::Coding::Prefix) and
//! [`Coding::PrefixByDegree`](super::Coding::PrefixByDegree): the same symbols as the
//! range-coded streams (commands in context, offsets and residuals by bit length), coded with
//! static canonical Huffman codes built for the one stream, and stored at its head.
//!
//! Why a second coding: the tile sort re-codes every tile every frame, and with the adaptive
//! range coder that coding was most of the sort (a binary decision, with its multiply and
//! renormalisation, for every bit of every class symbol, ~20 per vertex). Here a symbol is one
//! table lookup and one write of its code, followed by its sign and mantissa bits raw, and the
//! decoder reads a symbol with one peek. The writer buffers the stream's symbols, counts them,
//! builds the tables, then writes; a tile's symbols are known before it is sent, so the tables
//! are exact for the tile, and cost about a hundred bytes.
//!
//! Stream layout, MSB-first bits, padded to a byte:
//! - `CONN`: [`COMMAND_TABLES`] command tables (12 symbols, by [`Context::prefix_table`] of the
//!   command context: the previous command; by [`Context::prefix_table_by_degree`] in
//!   [`Coding::PrefixByDegree`](super::Coding::PrefixByDegree)), 3 offset tables (`RF<k>`,
//!   `LF<k>`, `ADD<k>`; the offset's bit length 0..=32), then per command its code, and after
//!   an offset command the offset's length code and the bits below its leading one.
//! - `GEOM`: 9 residual tables (prediction kind x axis; the residual's bit length 0..=25),
//!   then per axis of each coded position the length code, and for a nonzero residual its sign
//!   and the bits below its leading one.
//! - `NORM` (version 6, a stream with normals): its tables in this form, then per slot its
//!   normal's residual classes' codes and raw bits ([`super::attributes`]).
//! - A table is 6 bits `n` (symbols up to the last with a code), then `n` 4-bit code lengths
//!   (0: no code), at most [`MAX_CODE_LEN`].

use super::format::{corrupt, BftError};
use super::model::{decode_positions, Context, Prediction, ResidualSource, SymbolSink, SymbolSource};
use crate::command::Command;
use crate::huffman::{BitReader, BitWriter, SmallCode, SmallTable};

/// Longest code: lengths are stored in 4 bits.
pub const MAX_CODE_LEN: u8 = 15;
/// Command tables: one per previous command (or, by degree, the previous command's class (3)
/// times the left vertex's visited degree: 0, 1, 2, 3 or more).
pub const COMMAND_TABLES: usize = 12;
const COMMANDS: usize = Command::ALL.len();
const OFFSET_SYMBOLS: usize = 33;
const GEOMETRY_TABLES: usize = 9;
/// Residual lengths: 0..=25 (24-bit grids plus one for the sign-free magnitude bound).
const RESIDUAL_SYMBOLS: usize = 26;

const BY_CODE: [Command; COMMANDS] = Command::ALL;

#[inline]
fn offset_table(cmd: Command) -> usize {
    match cmd {
        Command::Rf => 0,
        Command::Lf => 1,
        _ => 2,
    }
}

#[inline]
fn has_offset(cmd: Command) -> bool {
    matches!(cmd, Command::Rf | Command::Lf | Command::AddRef)
}

#[inline]
fn bit_length(v: u32) -> u32 {
    32 - v.leading_zeros()
}

/// Writes `v` as its bit length's code and the bits below its leading one.
#[inline]
fn put_number(w: &mut BitWriter, table: &SmallCode, v: u32) {
    let len = bit_length(v);
    let (code, code_len) = table.code(len as u8);
    w.put(code, code_len);
    if len >= 2 {
        w.put(v & ((1 << (len - 1)) - 1), (len - 1) as u8);
    }
}

pub(crate) fn write_table(w: &mut BitWriter, t: &SmallCode) {
    let n = t.lens().iter().rposition(|&l| l > 0).map_or(0, |i| i + 1);
    w.put(n as u32, 6);
    for &l in &t.lens()[..n] {
        w.put(l as u32, 4);
    }
}

/// The most symbols of any table read with [`read_table`] (the normals' tables,
/// [`super::attributes`], included): each is read into a [`SmallTable`], which holds them and
/// their codes' lengths.
const MOST_SYMBOLS: usize = crate::huffman::SMALL_SYMBOLS;
const _: () = assert!(
    COMMANDS <= MOST_SYMBOLS
        && OFFSET_SYMBOLS <= MOST_SYMBOLS
        && RESIDUAL_SYMBOLS <= MOST_SYMBOLS
        && MAX_CODE_LEN <= crate::huffman::SMALL_MAX_LEN
);

/// Reads a code table of at most `symbols` symbols into `table`.
pub(crate) fn read_table(
    r: &mut BitReader,
    symbols: usize,
    what: &str,
    table: &mut SmallTable,
) -> Result<(), BftError> {
    let truncated = || BftError::Truncated("a prefix code table");
    let n = r.bits(6).ok_or_else(truncated)? as usize;
    if n > symbols {
        return Err(corrupt(format!("a {what} code table of {n} symbols (at most {symbols})")));
    }
    let mut lens = [0u8; MOST_SYMBOLS];
    for l in &mut lens[..n] {
        *l = r.bits(4).ok_or_else(truncated)? as u8;
    }
    if table.set(&lens[..symbols]) {
        Ok(())
    } else {
        Err(corrupt(format!("invalid {what} code lengths")))
    }
}

pub(crate) fn tables<const N: usize, const T: usize>(counts: &[[u64; N]; T]) -> [SmallCode; T] {
    counts.each_ref().map(|c| SmallCode::from_counts(c, MAX_CODE_LEN))
}

/// The command table of `ctx` in the coding `BY_DEGREE` names.
#[inline(always)]
fn command_table<const BY_DEGREE: bool>(ctx: Context) -> usize {
    if BY_DEGREE {
        ctx.prefix_table_by_degree()
    } else {
        ctx.prefix_table()
    }
}

/// The writer: buffers and counts the stream's symbols, then codes them in
/// [`SymbolSink::finish`]. `BY_DEGREE` writes [`Coding::PrefixByDegree`](super::Coding::PrefixByDegree).
pub(crate) struct PrefixSink<const BY_DEGREE: bool = false> {
    /// Per command `table << 4 | command`, followed by its offset for `RF<k>`, `LF<k>`, `ADD<k>`.
    conn: Vec<u32>,
    /// Per axis of each position: `table << 5 | bit length`, and the residual's magnitude
    /// with its sign as bit 31.
    geom: Vec<(u16, u32)>,
    /// The symbols counted as they come, per table.
    cmd_counts: [[u64; COMMANDS]; COMMAND_TABLES],
    off_counts: [[u64; OFFSET_SYMBOLS]; 3],
    geo_counts: [[u64; RESIDUAL_SYMBOLS]; GEOMETRY_TABLES],
}

impl<const BY_DEGREE: bool> SymbolSink for PrefixSink<BY_DEGREE> {
    const DEGREES: bool = BY_DEGREE;

    fn with_capacity(commands: usize, positions: usize) -> Self {
        PrefixSink {
            conn: Vec::with_capacity(commands + commands / 8),
            geom: Vec::with_capacity(positions * 3),
            cmd_counts: [[0; COMMANDS]; COMMAND_TABLES],
            off_counts: [[0; OFFSET_SYMBOLS]; 3],
            geo_counts: [[0; RESIDUAL_SYMBOLS]; GEOMETRY_TABLES],
        }
    }

    #[inline]
    fn command(&mut self, ctx: Context, cmd: Command) {
        let table = command_table::<BY_DEGREE>(ctx);
        self.cmd_counts[table][cmd as usize] += 1;
        self.conn.push((table as u32) << 4 | cmd as u32);
    }

    #[inline]
    fn offset(&mut self, cmd: Command, k: u32) {
        self.off_counts[offset_table(cmd)][bit_length(k) as usize] += 1;
        self.conn.push(k);
    }

    #[inline]
    fn position(&mut self, kind: Prediction, actual: [u32; 3], pred: [u32; 3]) {
        for axis in 0..3 {
            let r = actual[axis] as i64 - pred[axis] as i64;
            let m = r.unsigned_abs() as u32;
            let (table, len) = (kind as usize * 3 + axis, bit_length(m));
            self.geo_counts[table][len as usize] += 1;
            self.geom.push(((table as u16) << 5 | len as u16, m | ((r < 0) as u32) << 31));
        }
    }

    fn finish(self) -> [Vec<u8>; 2] {
        let (cmd_tables, off_tables) = (tables(&self.cmd_counts), tables(&self.off_counts));
        let mut w = BitWriter::default();
        cmd_tables.iter().chain(&off_tables).for_each(|t| write_table(&mut w, t));
        let mut i = 0;
        while i < self.conn.len() {
            let (table, cmd) = ((self.conn[i] >> 4) as usize, BY_CODE[(self.conn[i] & 15) as usize]);
            let (code, len) = cmd_tables[table].code(cmd as u8);
            w.put(code, len);
            if has_offset(cmd) {
                put_number(&mut w, &off_tables[offset_table(cmd)], self.conn[i + 1]);
                i += 1;
            }
            i += 1;
        }
        let conn = w.finish();

        let geo_tables = tables(&self.geo_counts);
        let mut w = BitWriter::default();
        geo_tables.iter().for_each(|t| write_table(&mut w, t));
        for &(s, v) in &self.geom {
            let len = (s & 31) as u32;
            let (code, code_len) = geo_tables[(s >> 5) as usize].code(len as u8);
            // The length's code, the sign, then the bits below the leading one; in one write
            // when they fit in 32 bits, as they mostly do.
            let raw = if len > 0 { v >> 31 << (len - 1) | (v & ((1 << (len - 1)) - 1)) } else { 0 };
            if code_len as u32 + len <= 32 {
                w.put(((code as u64) << len | raw as u64) as u32, code_len + len as u8);
            } else {
                w.put(code, code_len);
                w.put(raw, len as u8);
            }
        }
        [conn, w.finish()]
    }
}

/// Bits of a command's code that [`PrefixSource`]'s flat lookup table resolves; nearly all
/// commands' codes are shorter.
const COMMAND_LUT_BITS: u32 = 8;

fn command_lut(tables: &[SmallTable]) -> Vec<u16> {
    let k = COMMAND_LUT_BITS;
    let mut lut = vec![0u16; tables.len() << k];
    for (t, table) in tables.iter().enumerate() {
        for (sym, &len) in table.lens().iter().enumerate() {
            let len = len as u32;
            if len == 0 || len > k {
                continue;
            }
            // Every index the code starts.
            let start = t << k | (table.code(sym as u8).0 << (k - len)) as usize;
            lut[start..start + (1 << (k - len))].fill((sym as u16) << 4 | len as u16);
        }
    }
    lut
}

/// Bits of a residual, its length's code and raw bits together, that [`PrefixSource`]'s
/// residual lookup tables resolve.
const RESIDUAL_LUT_BITS: u32 = 11;

fn residual_lut(tables: &[SmallTable]) -> Vec<i32> {
    let k = RESIDUAL_LUT_BITS;
    let mut lut = vec![0i32; tables.len() << k];
    for (t, table) in tables.iter().enumerate() {
        for (len, &code_len) in table.lens().iter().enumerate() {
            let (len, code_len) = (len as u32, code_len as u32);
            let total = code_len + len;
            if code_len == 0 || total > k {
                continue;
            }
            let code = (table.code(len as u8).0 as usize) << len;
            for raw in 0..1usize << len {
                let window = if len == 0 { 0 } else { (raw as u64) << (64 - len) };
                let start = t << k | (code | raw) << (k - total);
                lut[start..start + (1 << (k - total))].fill((residual(window, len) as i32) << 8 | total as i32);
            }
        }
    }
    lut
}

/// A residual `r` as [`residual`] reads it back: its bit length, and its sign followed by
/// the bits below its leading one (`len` bits in all for a nonzero residual). The normals'
/// coder writes its residuals so ([`super::attributes`]).
#[inline]
pub(crate) fn residual_bits(r: i64) -> (u32, u32) {
    let m = r.unsigned_abs() as u32;
    let len = bit_length(m);
    let raw = if len > 0 { ((r < 0) as u32) << (len - 1) | (m & ((1 << (len - 1)) - 1)) } else { 0 };
    (len, raw)
}

/// The residual of bit length `len` whose sign and bits below the leading one start
/// `window`. Without a branch on `len` or the sign, which no predictor guesses.
#[inline(always)]
pub(crate) fn residual(window: u64, len: u32) -> i64 {
    let raw = (window >> 1 >> (63 - len)) as i64;
    let lead = (1i64 << len) >> 1;
    let m = lead | (raw & (lead - 1).max(0));
    let negative = -((raw & lead != 0) as i64);
    (m ^ negative) - negative
}

/// The reader; `BY_DEGREE` reads [`Coding::PrefixByDegree`](super::Coding::PrefixByDegree).
pub(crate) struct PrefixSource<'a, const BY_DEGREE: bool = false> {
    conn: BitReader<'a>,
    geom: BitReader<'a>,
    /// The stream's code tables in its order: [`COMMAND_TABLES`] command tables, 3 offset
    /// tables, [`GEOMETRY_TABLES`] residual tables (one allocation, filled in place).
    tables: Vec<SmallTable>,
    /// The command tables' first [`COMMAND_LUT_BITS`] bits side by side, `symbol << 4 |
    /// length` (0 for a longer code, which [`SmallTable::lookup`] decodes; empty below
    /// [`LUT_COMMANDS`]): with the previous command as the context, the next command's entry
    /// is one index away from this one's.
    cmd_lut: Vec<u16>,
    /// Per residual table, per value of the next [`RESIDUAL_LUT_BITS`] bits: the residual
    /// they code, `value << 8 | bits` (code and raw bits together), or 0 where they do not
    /// hold all of it (empty below [`LUT_COMMANDS`]).
    geo_lut: Vec<i32>,
}

/// Where the offset and residual tables start in [`PrefixSource`]'s tables.
const OFFSET_TABLES_AT: usize = COMMAND_TABLES;
const GEOMETRY_TABLES_AT: usize = OFFSET_TABLES_AT + 3;

/// Commands a stream has at least for [`PrefixSource`] to build its lookup tables (78 KB):
/// a smaller one decodes through each code table's own. Measured on the 16-bit dragon's
/// tiles (all of a grid's, best of 30): building them always doubled the decode of a 64x64
/// grid's 605 bunny tiles of 170 triangles (17.5-17.8 ms against 8.7-8.8), broke even on a
/// 32x32 grid's dragon tiles of 5,300 (36.2-37.4 Mtri/s against 36.4-37.9), and gained 9-13%
/// on 16x16 and 8x8 grids (46.0-47.2 against 41.6-42.4). Measured again once the code
/// tables were built inline ([`SmallTable`]): always building them took the bunny's 64x64
/// tiles from 5.4-5.5 ms to 13.6, its 32x32 tiles from 2.7-3.0 to 5.1, and the dragon's
/// 32x32 and 16x16 tiles 2-4% longer; a threshold of 1024 or 16384 commands was within 5%
/// of this one (a scratch example, two alternated runs).
const LUT_COMMANDS: u32 = 4096;

impl<'a, const BY_DEGREE: bool> PrefixSource<'a, BY_DEGREE> {
    /// The reader of a stream of `commands` commands.
    pub fn new(conn: &'a [u8], geom: &'a [u8], commands: u32) -> Result<Self, BftError> {
        let (mut c, mut g) = (BitReader::new(conn, 0), BitReader::new(geom, 0));
        let mut tables = vec![SmallTable::EMPTY; GEOMETRY_TABLES_AT + GEOMETRY_TABLES];
        let (cmd_tables, rest) = tables.split_at_mut(OFFSET_TABLES_AT);
        let (off_tables, geo_tables) = rest.split_at_mut(GEOMETRY_TABLES_AT - OFFSET_TABLES_AT);
        cmd_tables.iter_mut().try_for_each(|t| read_table(&mut c, COMMANDS, "command", t))?;
        off_tables.iter_mut().try_for_each(|t| read_table(&mut c, OFFSET_SYMBOLS, "offset", t))?;
        geo_tables.iter_mut().try_for_each(|t| read_table(&mut g, RESIDUAL_SYMBOLS, "residual", t))?;
        let (cmd_lut, geo_lut) = if commands >= LUT_COMMANDS {
            (command_lut(cmd_tables), residual_lut(geo_tables))
        } else {
            (Vec::new(), Vec::new())
        };
        Ok(PrefixSource { conn: c, geom: g, tables, cmd_lut, geo_lut })
    }
}

/// `GEOM`'s reader and tables, for [`decode_positions`].
struct Residuals<'a, 't> {
    r: BitReader<'a>,
    tables: &'t [SmallTable],
    lut: &'t [i32],
}

impl ResidualSource for Residuals<'_, '_> {
    /// Per axis, the residual's bit length, then for a nonzero residual its sign and the
    /// bits below its leading one: mostly one lookup of both.
    #[inline(always)]
    fn position(&mut self, kind: Prediction, pred: [u32; 3], max: u32) -> Option<[u32; 3]> {
        let mut out = [0u32; 3];
        for axis in 0..3 {
            let t = kind as usize * 3 + axis;
            // A residual is at most 15 bits of code and 25 raw.
            let w = self.r.window_of::<40>();
            let e = self.lut.get(t << RESIDUAL_LUT_BITS | (w >> (64 - RESIDUAL_LUT_BITS)) as usize);
            let (d, bits) = if let Some(&e) = e.filter(|&&e| e != 0) {
                ((e >> 8) as i64, e as u32 & 255)
            } else {
                let (len, code_len) = self.tables[t].lookup(w)?;
                let len = len as u32;
                if len >= RESIDUAL_SYMBOLS as u32 {
                    return None;
                }
                (residual(w << code_len, len), code_len + len)
            };
            self.r.consume(bits);
            let v = pred[axis] as i64 + d;
            if v < 0 || v > max as i64 {
                return None;
            }
            out[axis] = v as u32;
        }
        Some(out)
    }

    fn overrun(&self) -> usize {
        self.r.overrun().div_ceil(8) as usize
    }
}

/// Reads a number coded as its bit length's symbol of `table` and the bits below its
/// leading one, from one window of the stream. `None` for no code or a length above
/// `max_len`. Past the end of the data it reads zeros, which [`SymbolSource::overrun`]
/// reports.
#[inline(always)]
fn read_number(r: &mut BitReader, table: &SmallTable, max_len: u32) -> Option<u32> {
    // A code and at most 31 bits below the leading one.
    let w = r.window_of::<{ MAX_CODE_LEN as u32 + 31 }>();
    let (len, code_len) = table.lookup(w)?;
    let len = len as u32;
    if len > max_len {
        return None;
    }
    let mantissa = len.saturating_sub(1);
    // `>> 1 >> (63 - m)`: no bits for m = 0 without a shift by 64.
    let low = (w << code_len >> 1 >> (63 - mantissa)) as u32;
    r.consume(code_len + mantissa);
    Some(if len >= 2 { 1 << mantissa | low } else { len })
}

impl<const BY_DEGREE: bool> SymbolSource for PrefixSource<'_, BY_DEGREE> {
    const DEGREES: bool = BY_DEGREE;

    #[inline(always)]
    fn command(&mut self, ctx: Context) -> Option<Command> {
        let w = self.conn.window_of::<{ MAX_CODE_LEN as u32 }>();
        let table = command_table::<BY_DEGREE>(ctx);
        let e = self.cmd_lut.get(table << COMMAND_LUT_BITS | (w >> (64 - COMMAND_LUT_BITS)) as usize);
        let (sym, code_len) = match e {
            Some(&e) if e != 0 => ((e >> 4) as u8, e as u32 & 15),
            _ => self.tables[table].lookup(w)?,
        };
        self.conn.consume(code_len);
        BY_CODE.get(sym as usize).copied()
    }

    #[inline(always)]
    fn offset(&mut self, cmd: Command) -> Option<u32> {
        read_number(&mut self.conn, &self.tables[OFFSET_TABLES_AT + offset_table(cmd)], 32)
    }

    fn positions(&mut self, slots: &mut [[u32; 3]], dups: &[(u32, u32)], max: u32) -> Result<(), BftError> {
        // The reader is copied into a local for the pass and written back after it, so
        // that the pass's loop keeps its state in locals (no gain measured on its own).
        let mut geom =
            Residuals { r: self.geom.clone(), tables: &self.tables[GEOMETRY_TABLES_AT..], lut: &self.geo_lut };
        let result = decode_positions(&mut geom, slots, dups, max);
        self.geom = geom.r;
        result
    }

    /// Bytes read past the end of each stream (as zeros).
    fn overrun(&self) -> [usize; 2] {
        [self.conn.overrun().div_ceil(8) as usize, self.geom.overrun().div_ceil(8) as usize]
    }
}
