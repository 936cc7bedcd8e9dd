//! Bytes the encoder sets aside while it works: in memory for a small model, in an anonymous
//! temporary file for a large one, so that its memory follows a bucket or a batch of chunks
//! and not the model.

use std::fs::File;
use std::io::{self, BufReader, BufWriter, Read, Seek, Write};
use std::path::PathBuf;

/// Spilled bytes being written.
pub(super) enum Spill {
    Mem(Vec<u8>),
    File(BufWriter<File>),
}

impl Spill {
    pub fn new(on_disk: bool, dir: &Option<PathBuf>) -> io::Result<Spill> {
        Ok(if on_disk {
            let f = match dir {
                Some(d) => tempfile::tempfile_in(d)?,
                None => tempfile::tempfile()?,
            };
            Spill::File(BufWriter::with_capacity(1 << 16, f))
        } else {
            Spill::Mem(Vec::new())
        })
    }

    pub fn write(&mut self, b: &[u8]) -> io::Result<()> {
        match self {
            Spill::Mem(v) => {
                v.extend_from_slice(b);
                Ok(())
            }
            Spill::File(w) => w.write_all(b),
        }
    }

    /// Everything written, to read back from the start.
    pub fn reader(self) -> io::Result<Box<dyn Read + Send>> {
        Ok(match self.finish()? {
            Spilled::Mem(v) => Box::new(io::Cursor::new(v)),
            Spilled::File(mut f) => {
                f.rewind()?;
                Box::new(BufReader::with_capacity(1 << 20, f))
            }
        })
    }

    /// Everything written, to read anywhere (from several threads at once).
    pub fn finish(self) -> io::Result<Spilled> {
        Ok(match self {
            Spill::Mem(v) => Spilled::Mem(v),
            Spill::File(w) => Spilled::File(w.into_inner().map_err(|e| e.into_error())?),
        })
    }
}

/// Spilled bytes, written.
pub(super) enum Spilled {
    Mem(Vec<u8>),
    File(File),
}

impl Spilled {
    fn read_at(&self, offset: u64, len: usize) -> io::Result<Vec<u8>> {
        match self {
            Spilled::Mem(v) => Ok(v[offset as usize..offset as usize + len].to_vec()),
            Spilled::File(f) => {
                use std::os::unix::fs::FileExt;
                let mut buf = vec![0u8; len];
                f.read_exact_at(&mut buf, offset)?;
                Ok(buf)
            }
        }
    }
}

/// Ranges of `n` items (chunks, groups), a few per thread, that a pass reads in parallel
/// before it takes them in order.
pub(super) fn batches(n: usize) -> impl Iterator<Item = std::ops::Range<usize>> {
    let step = rayon::current_num_threads().max(1) * 16;
    (0..n).step_by(step).map(move |s| s..(s + step).min(n))
}

/// Triangles from `r`, `n` of them (12 bytes each, little-endian vertex indices).
pub(super) fn read_triangles(r: &mut dyn Read, n: usize) -> io::Result<Vec<[u32; 3]>> {
    let mut buf = vec![0u8; n * 12];
    r.read_exact(&mut buf)?;
    Ok(triangles_of(&buf))
}

fn triangles_of(buf: &[u8]) -> Vec<[u32; 3]> {
    buf.chunks_exact(12).map(|b| [0, 4, 8].map(|o| u32::from_le_bytes(b[o..o + 4].try_into().unwrap()))).collect()
}

/// Chunks of triangles being spilled, one after another.
pub(super) struct ChunkWriter {
    spill: Spill,
    /// Where each chunk starts, in triangles, and where the last one ends.
    start: Vec<u64>,
}

impl ChunkWriter {
    pub fn new(on_disk: bool, dir: &Option<PathBuf>) -> io::Result<ChunkWriter> {
        Ok(ChunkWriter { spill: Spill::new(on_disk, dir)?, start: vec![0] })
    }

    /// Chunks written so far.
    pub fn len(&self) -> usize {
        self.start.len() - 1
    }

    /// Adds a chunk of `tris`.
    pub fn push(&mut self, tris: impl ExactSizeIterator<Item = [u32; 3]>) -> io::Result<()> {
        let n = tris.len();
        let mut b = Vec::with_capacity(n * 12);
        for t in tris {
            for v in t {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        self.spill.write(&b)?;
        self.start.push(self.start.last().unwrap() + n as u64);
        Ok(())
    }

    pub fn finish(self) -> io::Result<Chunks> {
        Ok(Chunks { data: self.spill.finish()?, start: self.start })
    }
}

/// Spilled chunks of triangles, read back one by one in any order.
pub(super) struct Chunks {
    data: Spilled,
    start: Vec<u64>,
}

impl Chunks {
    pub fn len(&self) -> usize {
        self.start.len() - 1
    }

    /// Chunk `c`'s triangle count.
    pub fn size(&self, c: usize) -> usize {
        (self.start[c + 1] - self.start[c]) as usize
    }

    /// All chunks' triangles.
    pub fn triangles(&self) -> u64 {
        *self.start.last().unwrap()
    }

    /// Chunk `c`'s triangles.
    pub fn read(&self, c: usize) -> io::Result<Vec<[u32; 3]>> {
        Ok(triangles_of(&self.data.read_at(self.start[c] * 12, self.size(c) * 12)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_read_back_in_any_order_from_memory_and_from_disk() {
        let chunks: Vec<Vec<[u32; 3]>> =
            (0..40u32).map(|c| (0..c * 7 % 13).map(|t| [c, t, c.wrapping_mul(t) ^ 0xdead_beef]).collect()).collect();
        for on_disk in [false, true] {
            let mut w = ChunkWriter::new(on_disk, &None).expect("spill");
            for c in &chunks {
                w.push(c.iter().copied()).expect("written");
            }
            assert_eq!(w.len(), chunks.len());
            let r = w.finish().expect("finished");
            assert_eq!(r.len(), chunks.len());
            assert_eq!(r.triangles(), chunks.iter().map(|c| c.len() as u64).sum::<u64>());
            for c in (0..chunks.len()).rev().chain([17, 3, 17]) {
                assert_eq!(r.size(c), chunks[c].len());
                assert_eq!(r.read(c).expect("read"), chunks[c], "chunk {c}, on disk: {on_disk}");
            }
        }
    }
}
