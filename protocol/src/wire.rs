//! The bytes every message is made of: the header (magic, version, kind) and little-endian
//! numbers, written by [`Writer`] and read back, checked, by [`Reader`]. Each message's
//! layout is the [`Body`] impl beside its type.

use crate::{ProtocolError, VERSION};

const MAGIC: &[u8; 4] = b"TSRM";

/// A message's body: written after the header, read back from it. Each impl is the
/// message's layout, its two directions side by side.
pub(crate) trait Body: Sized {
    fn write(&self, w: &mut Writer);
    fn read(r: &mut Reader) -> Result<Self, ProtocolError>;
}

/// A message being written.
pub(crate) struct Writer(Vec<u8>);

impl Writer {
    /// A message of `kind`, its header written.
    pub(crate) fn new(kind: u8) -> Writer {
        let mut v = Vec::with_capacity(64);
        v.extend_from_slice(MAGIC);
        v.push(VERSION);
        v.push(kind);
        Writer(v)
    }
    /// A message of `kind` whose body is `body`.
    pub(crate) fn message(kind: u8, body: &impl Body) -> Vec<u8> {
        let mut w = Writer::new(kind);
        body.write(&mut w);
        w.0
    }
    pub(crate) fn finish(self) -> Vec<u8> {
        self.0
    }
    pub(crate) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    pub(crate) fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub(crate) fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    /// A length (`u32`) and the bytes.
    pub(crate) fn bytes(&mut self, b: &[u8]) {
        self.u32(b.len() as u32);
        self.0.extend_from_slice(b);
    }
    pub(crate) fn rect(&mut self, r: &[u32; 4]) {
        r.iter().for_each(|&v| self.u32(v));
    }
    pub(crate) fn matrix(&mut self, m: &[f32; 16]) {
        m.iter().for_each(|&v| self.f32(v));
    }
    /// A tile list: count u32, then per tile index u32, rect 4 x u32.
    pub(crate) fn tiles(&mut self, tiles: &[(u32, [u32; 4])]) {
        self.u32(tiles.len() as u32);
        for (index, rect) in tiles {
            self.u32(*index);
            self.rect(rect);
        }
    }
}

/// A message being read: every read checks what is left.
pub(crate) struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// Checks the magic number and the version, and returns the reader and the kind.
    pub(crate) fn open(b: &'a [u8]) -> Result<(Reader<'a>, u8), ProtocolError> {
        if b.len() >= 4 && &b[..4] != MAGIC {
            return Err(ProtocolError::BadMagic);
        }
        if b.len() < 6 {
            return Err(ProtocolError::Truncated("header"));
        }
        if b[4] != VERSION {
            return Err(ProtocolError::Version(b[4]));
        }
        Ok((Reader { b, pos: 6 }, b[5]))
    }
    /// The body of `T`, which must be the whole rest of the message.
    pub(crate) fn body<T: Body>(mut self) -> Result<T, ProtocolError> {
        let body = T::read(&mut self)?;
        self.end()?;
        Ok(body)
    }
    pub(crate) fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], ProtocolError> {
        if self.b.len() - self.pos < n {
            return Err(ProtocolError::Truncated(what));
        }
        self.pos += n;
        Ok(&self.b[self.pos - n..self.pos])
    }
    pub(crate) fn u8(&mut self, what: &'static str) -> Result<u8, ProtocolError> {
        Ok(self.take(1, what)?[0])
    }
    pub(crate) fn u32(&mut self, what: &'static str) -> Result<u32, ProtocolError> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    pub(crate) fn f32(&mut self, what: &'static str) -> Result<f32, ProtocolError> {
        Ok(f32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    pub(crate) fn f64(&mut self, what: &'static str) -> Result<f64, ProtocolError> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    pub(crate) fn u64(&mut self, what: &'static str) -> Result<u64, ProtocolError> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
    pub(crate) fn bytes(&mut self, what: &'static str) -> Result<&'a [u8], ProtocolError> {
        let n = self.u32(what)? as usize;
        self.take(n, what)
    }
    /// A count of items of at least `min_size` bytes each, checked against what is left, so
    /// a corrupt count cannot make the reader allocate wildly.
    pub(crate) fn count(&mut self, min_size: usize, what: &'static str) -> Result<usize, ProtocolError> {
        let n = self.u32(what)? as usize;
        if n.saturating_mul(min_size) > self.b.len() - self.pos {
            return Err(ProtocolError::Truncated(what));
        }
        Ok(n)
    }
    pub(crate) fn string(&mut self, what: &'static str) -> Result<String, ProtocolError> {
        String::from_utf8(self.bytes(what)?.to_vec())
            .map_err(|_| ProtocolError::Invalid(format!("{what} is not UTF-8")))
    }
    /// `x0 y0 x1 y1`, not inverted.
    pub(crate) fn rect(&mut self) -> Result<[u32; 4], ProtocolError> {
        let r = [self.u32("rect")?, self.u32("rect")?, self.u32("rect")?, self.u32("rect")?];
        if r[0] > r[2] || r[1] > r[3] {
            return Err(ProtocolError::Invalid(format!("tile rectangle {r:?} is inverted")));
        }
        Ok(r)
    }
    pub(crate) fn matrix(&mut self, what: &'static str) -> Result<[f32; 16], ProtocolError> {
        let mut m = [0.0f32; 16];
        for v in &mut m {
            *v = self.f32(what)?;
        }
        Ok(m)
    }
    /// A tile list as [`Writer::tiles`] writes it.
    pub(crate) fn tiles(&mut self) -> Result<Vec<(u32, [u32; 4])>, ProtocolError> {
        let n = self.count(20, "tiles")?;
        let mut tiles = Vec::with_capacity(n);
        for _ in 0..n {
            tiles.push((self.u32("tile index")?, self.rect()?));
        }
        Ok(tiles)
    }
    fn end(self) -> Result<(), ProtocolError> {
        match self.b.len() - self.pos {
            0 => Ok(()),
            n => Err(ProtocolError::Trailing(n)),
        }
    }
}

/// The empty body of a message that is its kind alone (`Shutdown`, `Heartbeat`).
impl Body for () {
    fn write(&self, _: &mut Writer) {}
    fn read(_: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(())
    }
}
