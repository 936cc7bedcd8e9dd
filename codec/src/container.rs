//! The container both of Tessera's file formats use (`.bft`, `.dpm`), and LEB128 integers.
//!
//! ```text
//! offset  size  field
//! 0       8     magic number (per format)
//! 8       2     version (u16 LE)
//! 10      2     header length H in bytes (u16 LE)
//! 12      H     header (per format)
//! 12+H    4     CRC-32 of the header bytes
//! then the format's sections, in a fixed order, each
//!         4     tag (ASCII)
//!         4     payload length N (u32 LE)
//!         N     payload
//!         4     CRC-32 of the payload
//! ```
//! Nothing may follow the last section. Each format turns [`ContainerError`] into its own
//! error type.

/// What can be wrong with a container, before any format-specific check.
#[derive(Debug, PartialEq)]
pub(crate) enum ContainerError {
    BadMagic,
    UnsupportedVersion(u16),
    Truncated(&'static str),
    Checksum(&'static str),
    /// A section other than the named one stands where it should.
    WrongSection(&'static str),
    TrailingBytes(usize),
    /// A LEB128 integer longer than 64 bits.
    Overlong(&'static str),
}

/// A format's container: its magic number, version, and section tags with readable names.
pub(crate) struct Layout<const N: usize> {
    pub magic: [u8; 8],
    pub version: u16,
    pub tags: [[u8; 4]; N],
    pub names: [&'static str; N],
}

struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], ContainerError> {
        if self.b.len() - self.pos < n {
            return Err(ContainerError::Truncated(what));
        }
        self.pos += n;
        Ok(&self.b[self.pos - n..self.pos])
    }

    fn u16(&mut self, what: &'static str) -> Result<u16, ContainerError> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into().unwrap()))
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, ContainerError> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
}

impl<const N: usize> Layout<N> {
    pub fn write(&self, header: &[u8], sections: [&[u8]; N]) -> Vec<u8> {
        let mut out = Vec::with_capacity(header.len() + sections.iter().map(|s| s.len() + 12).sum::<usize>() + 16);
        out.extend_from_slice(&self.magic);
        out.extend_from_slice(&self.version.to_le_bytes());
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header);
        out.extend_from_slice(&crc32fast::hash(header).to_le_bytes());
        for (tag, s) in self.tags.iter().zip(sections) {
            out.extend_from_slice(tag);
            out.extend_from_slice(&(s.len() as u32).to_le_bytes());
            out.extend_from_slice(s);
            out.extend_from_slice(&crc32fast::hash(s).to_le_bytes());
        }
        out
    }

    /// Checks magic, version, lengths and checksums; returns the header and the sections.
    /// A prefix of the magic number reads as truncated, anything else there as bad magic.
    pub fn parse<'a>(&self, bytes: &'a [u8]) -> Result<(&'a [u8], [&'a [u8]; N]), ContainerError> {
        let mut r = Reader { b: bytes, pos: 0 };
        let magic = r.take(8, "magic number").map_err(|e| {
            if self.magic.starts_with(bytes) {
                e
            } else {
                ContainerError::BadMagic
            }
        })?;
        if magic != self.magic {
            return Err(ContainerError::BadMagic);
        }
        let version = r.u16("version")?;
        if version != self.version {
            return Err(ContainerError::UnsupportedVersion(version));
        }
        let hlen = r.u16("header length")? as usize;
        let header = r.take(hlen, "header")?;
        if r.u32("header checksum")? != crc32fast::hash(header) {
            return Err(ContainerError::Checksum("header"));
        }
        let mut sections: [&[u8]; N] = [&[]; N];
        for (i, s) in sections.iter_mut().enumerate() {
            let name = self.names[i];
            if r.take(4, name)? != self.tags[i] {
                return Err(ContainerError::WrongSection(name));
            }
            let n = r.u32(name)? as usize;
            *s = r.take(n, name)?;
            if r.u32(name)? != crc32fast::hash(s) {
                return Err(ContainerError::Checksum(name));
            }
        }
        if r.pos != bytes.len() {
            return Err(ContainerError::TrailingBytes(bytes.len() - r.pos));
        }
        Ok((header, sections))
    }
}

pub(crate) fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

pub(crate) fn get_varint(b: &[u8], pos: &mut usize, what: &'static str) -> Result<u64, ContainerError> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = *b.get(*pos).ok_or(ContainerError::Truncated(what))?;
        *pos += 1;
        v |= ((byte & 0x7f) as u64) << shift;
        if byte & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(ContainerError::Overlong(what))
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAYOUT: Layout<2> =
        Layout { magic: *b"TESTFMT\x1a", version: 3, tags: [*b"AAAA", *b"BBBB"], names: ["a", "b"] };

    #[test]
    fn round_trip_and_errors() {
        let bytes = LAYOUT.write(b"head", [b"one", b""]);
        assert_eq!(LAYOUT.parse(&bytes), Ok((&b"head"[..], [&b"one"[..], &b""[..]])));
        assert_eq!(LAYOUT.parse(&bytes[..3]), Err(ContainerError::Truncated("magic number")));
        assert_eq!(LAYOUT.parse(b"nope"), Err(ContainerError::BadMagic));
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(LAYOUT.parse(&longer), Err(ContainerError::TrailingBytes(1)));
        let mut v = Vec::new();
        put_varint(&mut v, u64::MAX);
        let mut pos = 0;
        assert_eq!(get_varint(&v, &mut pos, "x"), Ok(u64::MAX));
        assert_eq!(get_varint(&[0x80; 11], &mut 0, "x"), Err(ContainerError::Overlong("x")));
    }
}
