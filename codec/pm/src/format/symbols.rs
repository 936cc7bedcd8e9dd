//! How a field's values become Huffman-coded symbols and back: the paper's mapping of signed
//! values to unsigned ones (section 4.2), the two schemes of [`Scheme`] (7-bit groups whose
//! byte significance selects the table, and buckets with their low bits uncoded), and the
//! writer and reader of one operation's bit stream. The writer can also just count symbols,
//! which is how the encoder builds its tables.

use std::sync::Arc;

use super::fields::{tables_per_class, Scheme, FIELDS, KINDS, TABLE_BASE};
use super::header::corrupt;
use super::DpmError;
use crate::huffman::{BitReader, BitWriter, Table};

/// The paper's mapping of a signed value to an unsigned one (section 4.2): `2v` for `v >= 0`,
/// `2|v| - 1` below, so a distribution centred on zero stays ordered by magnitude.
pub(super) fn zigzag(v: i64) -> u64 {
    if v >= 0 {
        2 * v as u64
    } else {
        2 * v.unsigned_abs() - 1
    }
}

/// The inverse of [`zigzag`].
pub(super) fn unzigzag(u: u64) -> i64 {
    if u & 1 == 0 {
        (u >> 1) as i64
    } else {
        -(((u + 1) >> 1) as i64)
    }
}

/// Values below `2^BUCKET_EXACT_BITS` are bucket symbols of their own; above, a symbol holds
/// the bit length and the `BUCKET_MANTISSA` bits below the leading one.
const BUCKET_EXACT_BITS: u64 = 4;
const BUCKET_EXACT: u64 = 1 << BUCKET_EXACT_BITS;
const BUCKET_MANTISSA: u64 = 3;
const BUCKET_MASK: u64 = (1 << BUCKET_MANTISSA) - 1;

/// The bucket symbol of `v` and its uncoded low bits (count, value).
fn bucket(v: u64) -> (u8, u32, u64) {
    if v < BUCKET_EXACT {
        return (v as u8, 0, 0);
    }
    let b = 64 - v.leading_zeros() as u64; // bit length, above BUCKET_EXACT's
    let raw = b - 1 - BUCKET_MANTISSA;
    let sym = BUCKET_EXACT + ((b - BUCKET_EXACT_BITS - 1) << BUCKET_MANTISSA) + ((v >> raw) & BUCKET_MASK);
    debug_assert!(sym < 256, "bucket value out of range");
    (sym as u8, raw as u32, v & ((1u64 << raw) - 1))
}

/// Where op symbols go: counted (to build tables) or written.
pub(super) struct OpWriter<'a> {
    tables: Option<&'a [Table]>,
    counts: Option<&'a mut [[u64; 256]]>,
    w: BitWriter,
    /// Bits written so far.
    bits: u64,
}

impl<'a> OpWriter<'a> {
    /// A writer that only counts the symbols, per table, into `counts`.
    pub(super) fn counting(counts: &'a mut [[u64; 256]]) -> Self {
        OpWriter { tables: None, counts: Some(counts), w: BitWriter::default(), bits: 0 }
    }

    /// A writer that codes the symbols with `tables`.
    pub(super) fn coding(tables: &'a [Table]) -> Self {
        OpWriter { tables: Some(tables), counts: None, w: BitWriter::default(), bits: 0 }
    }

    /// The operation's bytes, padded to a byte, and the number of bits before the padding.
    pub(super) fn finish(self) -> (Vec<u8>, u64) {
        let bits = self.bits;
        (self.w.finish(), bits)
    }

    fn sym(&mut self, table: usize, sym: u8) {
        if let Some(c) = self.counts.as_deref_mut() {
            c[table][sym as usize] += 1;
        }
        if let Some(t) = self.tables {
            t[table].encode(&mut self.w, sym);
            self.bits += t[table].lens[sym as usize] as u64;
        }
    }

    fn raw(&mut self, mut n: u32, v: u64) {
        self.bits += n as u64;
        while n > 0 {
            let k = n.min(16);
            n -= k;
            self.w.put(((v >> n) & ((1 << k) - 1)) as u32, k as u8);
        }
    }

    /// Codes `v` in class `class` of field `f`; `v` fits in 32 bits (the encoder's bounds on
    /// vertices and section size keep every value there, and decoders refuse wider ones).
    pub(super) fn put(&mut self, f: usize, class: usize, mut v: u64) {
        debug_assert!(v <= u32::MAX as u64, "a coded value wider than 32 bits");
        let spec = FIELDS[f];
        let base = TABLE_BASE[f] + class * tables_per_class(spec.scheme);
        match spec.scheme {
            Scheme::Groups => {
                let mut i = 0;
                loop {
                    let more = v >= 0x80;
                    self.sym(base + i.min(2), (v & 0x7f) as u8 | if more { 0x80 } else { 0 });
                    v >>= 7;
                    i += 1;
                    if !more {
                        break;
                    }
                }
            }
            Scheme::Buckets => {
                let (s, n, low) = bucket(v);
                self.sym(base, s);
                if self.tables.is_some() {
                    self.raw(n, low);
                }
            }
        }
    }

    /// Codes the signed `v` in class `class` of field `f`, as its [`zigzag`].
    pub(super) fn put_signed(&mut self, f: usize, class: usize, v: i64) {
        self.put(f, class, zigzag(v));
    }
}

/// Reads one operation's values, optionally adding the bits of each to its field's kind.
pub(super) struct OpReader<'a, 'b> {
    tables: &'a [Arc<Table>],
    r: BitReader<'a>,
    bits: Option<&'b mut [u64; KINDS]>,
}

impl<'a, 'b> OpReader<'a, 'b> {
    /// A reader of the operation at byte `addr` of `ops`.
    pub(super) fn new(
        tables: &'a [Arc<Table>],
        ops: &'a [u8],
        addr: usize,
        bits: Option<&'b mut [u64; KINDS]>,
    ) -> Self {
        OpReader { tables, r: BitReader::new(ops, addr), bits }
    }

    /// One past the last byte read.
    pub(super) fn end(&self) -> usize {
        self.r.end()
    }

    fn sym(&mut self, table: usize) -> Result<u8, DpmError> {
        self.tables[table].decode(&mut self.r).ok_or(DpmError::Truncated("an operation"))
    }

    /// Reads a value of class `class` of field `f`.
    pub(super) fn get(&mut self, f: usize, class: usize) -> Result<u64, DpmError> {
        let before = self.r.read();
        let spec = FIELDS[f];
        let base = TABLE_BASE[f] + class * tables_per_class(spec.scheme);
        let v = match spec.scheme {
            Scheme::Groups => {
                let mut v = 0u64;
                let mut i = 0;
                loop {
                    if i == 5 {
                        return Err(corrupt("overlong value in an operation"));
                    }
                    let sym = self.sym(base + i.min(2))?;
                    v |= ((sym & 0x7f) as u64) << (7 * i);
                    i += 1;
                    if sym & 0x80 == 0 {
                        break v;
                    }
                }
            }
            Scheme::Buckets => {
                let s = self.sym(base)? as u64;
                if s < BUCKET_EXACT {
                    s
                } else {
                    let b = ((s - BUCKET_EXACT) >> BUCKET_MANTISSA) + BUCKET_EXACT_BITS + 1;
                    let raw = b - 1 - BUCKET_MANTISSA;
                    let mut v = ((BUCKET_MASK + 1) | ((s - BUCKET_EXACT) & BUCKET_MASK)) << raw;
                    for i in (0..raw).rev() {
                        v |= (self.r.bit().ok_or(DpmError::Truncated("an operation"))? as u64) << i;
                    }
                    v
                }
            }
        };
        if let Some(b) = self.bits.as_deref_mut() {
            b[spec.kind as usize] += self.r.read() - before;
        }
        if v > u32::MAX as u64 {
            return Err(corrupt("value out of range in an operation"));
        }
        Ok(v)
    }

    /// Reads a signed value of class `class` of field `f`.
    pub(super) fn get_signed(&mut self, f: usize, class: usize) -> Result<i64, DpmError> {
        Ok(unzigzag(self.get(f, class)?))
    }
}
