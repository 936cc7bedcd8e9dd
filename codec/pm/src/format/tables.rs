//! The shared probability tables (the `TABL` section): one static canonical Huffman code over
//! byte symbols per table of [`TABLES`], built by the encoder from symbol counts in which every
//! symbol has a code, stored as code lengths, and read back once per file. The flat code (every
//! symbol 8 bits), which most tables of a fuzzer's input are, is built once per process (a
//! `OnceLock`) and shared.

use std::sync::{Arc, OnceLock};

use super::fields::TABLES;
use super::header::corrupt;
use super::symbols::{unzigzag, zigzag};
use super::DpmError;
use crate::huffman::{BitReader, BitWriter, Table, MAX_LEN};

/// A `.dpm` table: every one of the 256 symbols gets a code (a count of one more than seen),
/// so a table built before the final offsets are known still codes every symbol the final
/// pass produces.
pub(super) fn every_symbol(counts: &[u64; 256]) -> Table {
    Table::from_counts(&counts.map(|c| c + 1), MAX_LEN)
}

/// One bit stream, padded to a byte: per table a bit, 0 for a flat code (every symbol 8 bits),
/// 1 for a code whose 256 lengths follow, each as the Elias gamma code of one plus the zigzag
/// difference to the previous symbol's length (the first to 8), and after a length equal to
/// the previous one the gamma code of one plus how many more repeat it (a run): neighbouring
/// symbols mostly have equal or adjacent lengths, and the unused ones, which every table
/// codes, long runs of one length.
pub(super) fn write_tables(tables: &[Table]) -> Vec<u8> {
    let mut w = BitWriter::default();
    for t in tables {
        if t.lens == [8; 256] {
            w.put(0, 1);
            continue;
        }
        w.put(1, 1);
        let gamma = |w: &mut BitWriter, g: u32| {
            let b = 32 - g.leading_zeros();
            w.put(0, (b - 1) as u8);
            w.put(g, b as u8);
        };
        let mut prev = 8i64;
        let mut i = 0;
        while i < t.lens.len() {
            let l = t.lens[i] as i64;
            gamma(&mut w, zigzag(l - prev) as u32 + 1);
            i += 1;
            if l == prev {
                // A run: how many of the following lengths repeat this one too.
                let run = t.lens[i..].iter().take_while(|&&x| x as i64 == l).count();
                gamma(&mut w, run as u32 + 1);
                i += run;
            }
            prev = l;
        }
    }
    w.finish()
}

/// An Elias gamma code (at most 9 bits of value) read bit by bit.
fn gamma(bit: &mut impl FnMut() -> Result<bool, DpmError>) -> Result<u32, DpmError> {
    let mut zeros = 0;
    while !bit()? {
        zeros += 1;
        if zeros > 8 {
            return Err(corrupt("bad code length"));
        }
    }
    let mut g = 1u32;
    for _ in 0..zeros {
        g = (g << 1) | bit()? as u32;
    }
    Ok(g)
}

/// The flat code (every symbol 8 bits), built once and shared by every table coded as flat.
fn flat_table() -> Arc<Table> {
    static FLAT: OnceLock<Arc<Table>> = OnceLock::new();
    FLAT.get_or_init(|| Arc::new(Table::from_lens(&[8; 256]).expect("a flat code is complete"))).clone()
}

/// Reads the tables. A flat table is the shared [`flat_table`]; only tables whose lengths are
/// stored are built, each from at least 256 bits of the section, so the work is bounded by
/// the section's size (a file of flat tables, such as most fuzzer inputs, builds none).
pub(super) fn read_tables(tb: &[u8]) -> Result<Vec<Arc<Table>>, DpmError> {
    let mut r = BitReader::new(tb, 0);
    let mut bit = || r.bit().ok_or(DpmError::Truncated("tables"));
    let mut tables = Vec::with_capacity(TABLES);
    for _ in 0..TABLES {
        if !bit()? {
            tables.push(flat_table());
        } else {
            let mut lens = [8u8; 256];
            let mut prev = 8i64;
            let mut i = 0;
            while i < lens.len() {
                let x = prev + unzigzag(gamma(&mut bit)? as u64 - 1);
                if !(1..=MAX_LEN as i64).contains(&x) {
                    return Err(corrupt("bad code length"));
                }
                lens[i] = x as u8;
                i += 1;
                if x == prev {
                    let run = gamma(&mut bit)? as usize - 1;
                    if run > lens.len() - i {
                        return Err(corrupt("bad code length"));
                    }
                    lens[i..i + run].fill(x as u8);
                    i += run;
                }
                prev = x;
            }
            tables.push(Arc::new(Table::from_lens(&lens).ok_or_else(|| corrupt("invalid code lengths"))?));
        }
    }
    if r.end() != tb.len() {
        return Err(corrupt("bytes after the tables"));
    }
    Ok(tables)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_come_back_and_flat_ones_are_shared() {
        let tables: Vec<Table> = (0..TABLES)
            .map(|t| {
                let mut counts = [0u64; 256];
                if t % 3 != 0 {
                    for (s, c) in counts.iter_mut().enumerate() {
                        *c = ((s * 7919 + t * 104_729) % 1000) as u64 * (s as u64 % 5);
                    }
                }
                every_symbol(&counts)
            })
            .collect();
        let read = read_tables(&write_tables(&tables)).expect("reads");
        assert_eq!(read.len(), TABLES);
        for (a, b) in tables.iter().zip(&read) {
            assert_eq!(a.lens, b.lens);
        }
        // All-zero counts give the flat code, which is read as the shared table.
        assert!(Arc::ptr_eq(&read[0], &read[3]) && Arc::ptr_eq(&read[0], &flat_table()));
        assert!(!Arc::ptr_eq(&read[0], &read[1]));
    }

    #[test]
    fn a_byte_after_the_tables_is_an_error() {
        let mut bytes = write_tables(&vec![every_symbol(&[0; 256]); TABLES]);
        assert!(read_tables(&bytes).is_ok());
        bytes.push(0);
        assert_eq!(read_tables(&bytes).unwrap_err(), corrupt("bytes after the tables"));
        assert_eq!(read_tables(&[]).unwrap_err(), DpmError::Truncated("tables"));
    }
}
