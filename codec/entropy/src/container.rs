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
//! Nothing may follow the last section. A reader knows the versions it reads and refuses
//! any other with [`FormatError::UnsupportedVersion`]: a field that gains a meaning takes a
//! new version, so an older reader refuses the file instead of misreading it.

use thiserror::Error;

/// Which of Tessera's file formats a [`FormatError`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Bft,
    Dpm,
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(match self {
            Format::Bft => ".bft",
            Format::Dpm => ".dpm",
        })
    }
}

/// Everything that can be wrong with the bytes of a `.bft` or `.dpm` file: the container's
/// checks, shared by both formats, and `Corrupt` for a format's own checks of its header and
/// streams.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum FormatError {
    #[error("not a {0} file (bad magic number)")]
    BadMagic(Format),
    #[error("unsupported {format} version {found} (this build reads {})", versions(.known))]
    UnsupportedVersion { format: Format, found: u16, known: &'static [u16] },
    /// A version this build used to read and no longer does, with what to do about it.
    #[error("{format} version {found} is no longer read (this build reads {}): {remedy}", versions(.known))]
    Outdated { format: Format, found: u16, known: &'static [u16], remedy: &'static str },
    #[error("file is truncated: {0}")]
    Truncated(&'static str),
    #[error("checksum mismatch in {0}: the file is corrupt")]
    Checksum(&'static str),
    #[error("{0} trailing bytes after the last section")]
    TrailingBytes(usize),
    #[error("corrupt {0} data: {1}")]
    Corrupt(Format, String),
    /// The file could not be read (an out-of-core reader reads it while it runs).
    #[error("{0}")]
    Io(String),
    /// Well formed, but decoding it would take more memory than the cap on decompressed
    /// input allows ([`tessera_mesh::input::max_decompressed_bytes`]); the message says so, with the
    /// flag that raises the cap ([`tessera_mesh::input::check_decoded`]).
    #[error("{0}")]
    TooLarge(String),
}

/// "version 2", "versions 1 and 2", "versions 1, 2 and 3".
fn versions(known: &[u16]) -> String {
    match known {
        [v] => format!("version {v}"),
        [rest @ .., last] => {
            let rest: Vec<String> = rest.iter().map(u16::to_string).collect();
            format!("versions {} and {last}", rest.join(", "))
        }
        [] => "no version".into(),
    }
}

/// What can be wrong with a container, before any format-specific check.
#[derive(Debug, PartialEq)]
enum ContainerError {
    BadMagic,
    UnsupportedVersion(u16),
    Truncated(&'static str),
    Checksum(&'static str),
    /// A section other than the named one stands where it should.
    WrongSection(&'static str),
    TrailingBytes(usize),
}

impl ContainerError {
    /// The error in `layout`'s format.
    fn within<const N: usize>(self, layout: &Layout<N>) -> FormatError {
        let format = layout.format;
        match self {
            ContainerError::BadMagic => FormatError::BadMagic(format),
            ContainerError::UnsupportedVersion(found) => {
                FormatError::UnsupportedVersion { format, found, known: layout.reads }
            }
            ContainerError::Truncated(what) => FormatError::Truncated(what),
            ContainerError::Checksum(what) => FormatError::Checksum(what),
            ContainerError::TrailingBytes(n) => FormatError::TrailingBytes(n),
            ContainerError::WrongSection(name) => FormatError::Corrupt(format, format!("expected the {name}")),
        }
    }
}

/// A format's container: its magic number, version, and section tags with readable names.
pub struct Layout<const N: usize> {
    pub format: Format,
    pub magic: [u8; 8],
    /// The version written.
    pub version: u16,
    /// The versions read (the written one among them).
    pub reads: &'static [u16],
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
        let mut out = Vec::with_capacity(self.written_len(header, sections.map(|s| s.len())));
        self.write_pieces(&mut out, header, sections.each_ref().map(std::slice::from_ref))
            .expect("writing to a Vec does not fail");
        out
    }

    /// The length of the file [`Layout::write`] makes of `header` and sections of
    /// `section_lens` bytes.
    pub fn written_len(&self, header: &[u8], section_lens: [usize; N]) -> usize {
        self.magic.len() + 8 + header.len() + section_lens.iter().map(|l| l + 12).sum::<usize>()
    }

    /// Writes to `w` the file [`Layout::write`] makes, each section given as pieces in order,
    /// so that a large section is written from its parts without first being concatenated.
    pub fn write_pieces(
        &self,
        w: &mut dyn std::io::Write,
        header: &[u8],
        sections: [&[impl AsRef<[u8]>]; N],
    ) -> std::io::Result<()> {
        w.write_all(&self.magic)?;
        w.write_all(&self.version.to_le_bytes())?;
        w.write_all(&(header.len() as u16).to_le_bytes())?;
        w.write_all(header)?;
        w.write_all(&crc32fast::hash(header).to_le_bytes())?;
        for (tag, pieces) in self.tags.iter().zip(sections) {
            let len: usize = pieces.iter().map(|p| p.as_ref().len()).sum();
            w.write_all(tag)?;
            w.write_all(&(len as u32).to_le_bytes())?;
            let mut crc = crc32fast::Hasher::new();
            for p in pieces {
                crc.update(p.as_ref());
                w.write_all(p.as_ref())?;
            }
            w.write_all(&crc.finalize().to_le_bytes())?;
        }
        Ok(())
    }

    /// Checks magic, version, lengths and checksums; returns the version, the header and the
    /// sections. A prefix of the magic number reads as truncated, anything else there as bad
    /// magic.
    pub fn parse<'a>(&self, bytes: &'a [u8]) -> Result<Contents<'a, N>, FormatError> {
        self.parse_container(bytes, false).map_err(|e| e.within(self))
    }

    /// Checks a file's bytes up to its last section's payload ([`Layout::read_prefix`]): magic,
    /// version, the header and every section but the last, which comes back empty, with its
    /// length in `last_len`. For out-of-core readers, which check the last section in pieces.
    pub fn parse_prefix<'a>(&self, bytes: &'a [u8]) -> Result<Contents<'a, N>, FormatError> {
        self.parse_container(bytes, true).map_err(|e| e.within(self))
    }

    /// Reads from `r` the bytes [`Layout::parse_prefix`] checks: everything before the last
    /// section's payload. Fails with the error of the bytes read so far where they cannot be
    /// the start of such a file.
    pub fn read_prefix(&self, r: &mut impl std::io::Read) -> Result<Vec<u8>, FormatError> {
        let mut out = vec![];
        let mut take = |out: &mut Vec<u8>, n: usize| -> Result<(), FormatError> {
            let at = out.len();
            out.resize(at + n, 0);
            r.read_exact(&mut out[at..]).map_err(|e| match e.kind() {
                std::io::ErrorKind::UnexpectedEof => self
                    .parse_container(out, true)
                    .map_err(|e| e.within(self))
                    .err()
                    .unwrap_or(FormatError::Truncated("file")),
                _ => FormatError::Io(format!("cannot read: {e}")),
            })
        };
        take(&mut out, 12)?;
        let hlen = u16::from_le_bytes([out[10], out[11]]) as usize;
        take(&mut out, hlen + 4)?;
        for _ in 0..N - 1 {
            take(&mut out, 8)?;
            let n = u32::from_le_bytes(out[out.len() - 4..].try_into().unwrap()) as usize;
            take(&mut out, n + 4)?;
        }
        take(&mut out, 8)?;
        Ok(out)
    }

    fn parse_container<'a>(&self, bytes: &'a [u8], prefix: bool) -> Result<Contents<'a, N>, ContainerError> {
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
        if !self.reads.contains(&version) {
            return Err(ContainerError::UnsupportedVersion(version));
        }
        let hlen = r.u16("header length")? as usize;
        let header = r.take(hlen, "header")?;
        if r.u32("header checksum")? != crc32fast::hash(header) {
            return Err(ContainerError::Checksum("header"));
        }
        let mut sections: [&[u8]; N] = [&[]; N];
        let mut last_len = 0;
        for (i, s) in sections.iter_mut().enumerate() {
            let name = self.names[i];
            if r.take(4, name)? != self.tags[i] {
                return Err(ContainerError::WrongSection(name));
            }
            let n = r.u32(name)? as usize;
            if prefix && i == N - 1 {
                last_len = n as u64;
                break;
            }
            *s = r.take(n, name)?;
            if r.u32(name)? != crc32fast::hash(s) {
                return Err(ContainerError::Checksum(name));
            }
        }
        if r.pos != bytes.len() {
            return Err(ContainerError::TrailingBytes(bytes.len() - r.pos));
        }
        Ok(Contents { version, header, sections, last_len })
    }
}

/// A parsed container, borrowed from its bytes.
#[derive(Debug, PartialEq)]
pub struct Contents<'a, const N: usize> {
    pub version: u16,
    pub header: &'a [u8],
    pub sections: [&'a [u8]; N],
    /// The last section's length (where parsed with [`Layout::parse_prefix`]; else 0).
    pub last_len: u64,
}

pub fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Reads a LEB128 integer of `format`'s `what` at `*pos`, moving `pos` past it.
pub fn get_varint(format: Format, b: &[u8], pos: &mut usize, what: &'static str) -> Result<u64, FormatError> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let byte = *b.get(*pos).ok_or(FormatError::Truncated(what))?;
        *pos += 1;
        v |= ((byte & 0x7f) as u64) << shift;
        if byte & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(FormatError::Corrupt(format, format!("overlong integer in {what}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAYOUT: Layout<2> = Layout {
        format: Format::Bft,
        magic: *b"TESTFMT\x1a",
        version: 3,
        reads: &[2, 3],
        tags: [*b"AAAA", *b"BBBB"],
        names: ["a", "b"],
    };

    #[test]
    fn round_trip_and_errors() {
        let bytes = LAYOUT.write(b"head", [b"one", b""]);
        assert_eq!(
            LAYOUT.parse(&bytes),
            Ok(Contents { version: 3, header: b"head", sections: [b"one", b""], last_len: 0 })
        );
        assert_eq!(LAYOUT.parse(&bytes[..3]), Err(FormatError::Truncated("magic number")));
        assert_eq!(LAYOUT.parse(b"nope"), Err(FormatError::BadMagic(Format::Bft)));
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(LAYOUT.parse(&longer), Err(FormatError::TrailingBytes(1)));
        // Every version the layout reads parses; any other is refused, naming the known ones.
        for (v, ok) in [(0u16, false), (1, false), (2, true), (3, true), (4, false), (u16::MAX, false)] {
            let mut b = bytes.clone();
            b[8..10].copy_from_slice(&v.to_le_bytes());
            let r = LAYOUT.parse(&b);
            assert_eq!(r.is_ok(), ok, "version {v}: {r:?}");
            if let Err(e) = r {
                assert_eq!(e.to_string(), format!("unsupported .bft version {v} (this build reads versions 2 and 3)"));
            }
        }
        let mut v = Vec::new();
        put_varint(&mut v, u64::MAX);
        let mut pos = 0;
        assert_eq!(get_varint(Format::Dpm, &v, &mut pos, "x"), Ok(u64::MAX));
        assert_eq!(
            get_varint(Format::Dpm, &[0x80; 11], &mut 0, "x"),
            Err(FormatError::Corrupt(Format::Dpm, "overlong integer in x".into()))
        );
    }
}
