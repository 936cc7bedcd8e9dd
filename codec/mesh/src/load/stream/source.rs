//! Where a pass reads ([`Input`]) and the buffered reader over it ([`Source`]): plain or
//! gzip, bounded by the file's length, reporting progress.

use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;

use flate2::read::MultiGzDecoder;

use crate::load::error::{err, LoadError};

/// Where a pass reads: a file, or bytes already in memory (plain or gzip) that stand for the
/// file at `path` (named in messages).
#[derive(Clone, Copy)]
pub struct Input<'a> {
    pub path: &'a Path,
    pub bytes: Option<&'a [u8]>,
}

impl<'a> Input<'a> {
    pub fn file(path: &'a Path) -> Self {
        Input { path, bytes: None }
    }
}

/// The bytes the file holds: read no further than its length when opened (a file that grows
/// while read cannot make a reader go on without end), reporting progress.
struct RawFile<'p> {
    pub(super) file: Box<dyn ReadSeek + 'p>,
    pub(super) pos: u64,
    pub(super) len: u64,
    pub(super) progress: &'p mut dyn FnMut(u64),
}

impl RawFile<'_> {
    /// Moves `n` bytes forward; false if that is past the end (then left at the end).
    fn seek_forward(&mut self, n: u64) -> std::io::Result<bool> {
        let room = self.len - self.pos;
        let ok = n <= room;
        self.pos += n.min(room);
        self.file.seek(SeekFrom::Start(self.pos))?;
        (self.progress)(self.pos);
        Ok(ok)
    }
}

impl Read for RawFile<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let room = (self.len - self.pos).min(buf.len() as u64) as usize;
        if room == 0 {
            return Ok(0);
        }
        let n = self.file.read(&mut buf[..room])?;
        self.pos += n as u64;
        (self.progress)(self.pos);
        Ok(n)
    }
}

enum Inner<'p> {
    Plain(RawFile<'p>),
    Gzip {
        decoder: Box<MultiGzDecoder<BufReader<RawFile<'p>>>>,
        /// Decompressed bytes so far, and the most allowed.
        total: u64,
        limit: u64,
    },
}

/// What a [`RawFile`] reads: a file, or bytes in memory.
trait ReadSeek: Read + Seek {}

impl<T: Read + Seek> ReadSeek for T {}

/// Buffer size of a [`Source`]: the bound on what a pass holds of the file.
const BUFFER: usize = 1 << 20;

/// A buffered reader over a mesh file, plain or gzip, whose errors are [`LoadError`]s
/// worded as the in-core loader words them.
pub(super) struct Source<'a> {
    pub(super) path: &'a Path,
    inner: Inner<'a>,
    /// The file's length as stored (compressed, for gzip).
    pub(super) raw_len: u64,
    pub(super) buf: Vec<u8>,
    /// Unread bytes are `buf[pos..end]`.
    pub(super) pos: usize,
    pub(super) end: usize,
    /// Whether [`Source::line`] ends lines at a carriage return instead of a line feed (a PLY
    /// file whose lines end in bare carriage returns, see [`Source::detect_cr_lines`]).
    pub(super) cr_lines: bool,
}

impl<'a> Source<'a> {
    /// Opens `path` (a regular file), decompressing it if it starts with gzip's magic bytes,
    /// and reporting the bytes of the file read to `progress`.
    pub(super) fn open(input: Input<'a>, progress: &'a mut dyn FnMut(u64)) -> Result<Self, LoadError> {
        let path = input.path;
        let (mut file, len): (Box<dyn ReadSeek + 'a>, u64) = match input.bytes {
            Some(bytes) => (Box::new(std::io::Cursor::new(bytes)), bytes.len() as u64),
            None => {
                let (file, len) = crate::input::open_regular(path).map_err(|e| err(path, e))?;
                (Box::new(file), len)
            }
        };
        let cannot = |e: std::io::Error| err(path, format!("cannot read: {e}"));
        let mut magic = Vec::with_capacity(2);
        (&mut file).take(2).read_to_end(&mut magic).map_err(cannot)?;
        file.seek(SeekFrom::Start(0)).map_err(cannot)?;
        let raw = RawFile { file, pos: 0, len, progress };
        let inner = if magic == [0x1f, 0x8b] {
            Inner::Gzip {
                decoder: Box::new(MultiGzDecoder::new(BufReader::with_capacity(256 << 10, raw))),
                total: 0,
                limit: crate::input::max_decompressed_bytes(),
            }
        } else {
            Inner::Plain(raw)
        };
        Ok(Source { path, inner, raw_len: len, buf: vec![0; BUFFER], pos: 0, end: 0, cr_lines: false })
    }

    /// An upper bound on the bytes this source yields: the file's length, or the cap on
    /// decompressed bytes. Bounds what a header's counts may make a reader reserve.
    pub(super) fn size_bound(&self) -> u64 {
        match &self.inner {
            Inner::Plain(raw) => raw.len,
            Inner::Gzip { limit, .. } => *limit,
        }
    }

    /// One read into `buf[at..]`, its errors worded as `load_bytes` words them.
    fn read_inner(&mut self, at: usize) -> Result<usize, LoadError> {
        let buf = &mut self.buf[at..];
        let result = loop {
            let r = match &mut self.inner {
                Inner::Plain(raw) => raw.read(buf),
                Inner::Gzip { decoder, .. } => decoder.read(buf),
            };
            match r {
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                r => break r,
            }
        };
        let message = match (&mut self.inner, result) {
            (Inner::Plain(_), Ok(n)) => return Ok(n),
            (Inner::Plain(_), Err(e)) => format!("cannot read: {e}"),
            (Inner::Gzip { total, limit, .. }, Ok(n)) => {
                *total += n as u64;
                if *total <= *limit {
                    return Ok(n);
                }
                format!("decompresses to more than {limit} bytes, the limit (raise it with --max-decompressed BYTES)")
            }
            (Inner::Gzip { .. }, Err(e)) => format!("corrupt gzip data: {e}"),
        };
        Err(err(self.path, message))
    }

    /// Reads more bytes after the unread ones (moving those to the front); false at the end.
    fn fill(&mut self) -> Result<bool, LoadError> {
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.end, 0);
            self.end -= self.pos;
            self.pos = 0;
        }
        if self.end == self.buf.len() {
            return Ok(true);
        }
        let n = self.read_inner(self.end)?;
        self.end += n;
        Ok(n > 0)
    }

    /// Makes at least `n` unread bytes available in [`Self::unread`]; false if the file
    /// ends first.
    #[inline]
    pub(super) fn ensure(&mut self, n: usize) -> Result<bool, LoadError> {
        if n > self.buf.len() {
            self.buf.resize(n, 0);
        }
        while self.end - self.pos < n {
            if !self.fill()? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    #[inline]
    pub(super) fn unread(&self) -> &[u8] {
        &self.buf[self.pos..self.end]
    }

    #[inline]
    pub(super) fn consume(&mut self, n: usize) {
        self.pos += n;
    }

    /// Skips `n` bytes, seeking in a plain file; false if the file ends first.
    pub(super) fn skip(&mut self, n: u64) -> Result<bool, LoadError> {
        let buffered = (self.end - self.pos) as u64;
        if n <= buffered {
            self.pos += n as usize;
            return Ok(true);
        }
        let mut left = n - buffered;
        (self.pos, self.end) = (0, 0);
        if let Inner::Plain(raw) = &mut self.inner {
            return raw.seek_forward(left).map_err(|e| err(self.path, format!("cannot read: {e}")));
        }
        while left > 0 {
            if !self.fill()? {
                return Ok(false);
            }
            let k = (self.end as u64).min(left);
            left -= k;
            self.pos = k as usize;
        }
        Ok(true)
    }

    /// Whether the unread bytes start with `magic` followed by a bare carriage return (not
    /// `\r\n`): then lines end at carriage returns from here on, as some CAD exporters write
    /// PLY headers. Looks no further than the first `magic.len() + 2` bytes.
    pub(super) fn detect_cr_lines(&mut self, magic: &[u8]) -> Result<bool, LoadError> {
        while self.end - self.pos < magic.len() + 2 && self.fill()? {}
        let head = &self.buf[self.pos..self.end];
        let n = magic.len();
        self.cr_lines = head.starts_with(magic) && head.get(n) == Some(&b'\r') && head.get(n + 1) != Some(&b'\n');
        Ok(self.cr_lines)
    }

    /// Reads the next line, with its line break (`\n`, or `\r` after
    /// [`Source::detect_cr_lines`] found bare carriage returns), into `line` (cleared first);
    /// false at the end of the file. Refuses a line longer than `max` bytes.
    pub(super) fn line(&mut self, line: &mut Vec<u8>, max: usize) -> Result<bool, LoadError> {
        line.clear();
        let end = if self.cr_lines { b'\r' } else { b'\n' };
        loop {
            let unread = &self.buf[self.pos..self.end];
            let (take, done) = match unread.iter().position(|&b| b == end) {
                Some(i) => (i + 1, true),
                None => (unread.len(), false),
            };
            line.extend_from_slice(&unread[..take]);
            self.pos += take;
            if line.len() > max {
                return Err(err(self.path, format!("a line longer than {max} bytes")));
            }
            if done || !self.fill()? {
                return Ok(done || !line.is_empty());
            }
        }
    }
}
