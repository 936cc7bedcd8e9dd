//! Which mesh format a file is ([`Format`]): by its content, and by its name where the
//! content is silent.

use std::path::Path;

use super::error::{err, LoadError};

/// Mesh file formats Tessera reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Obj,
    Ply,
    Stl,
    /// glTF 2.0: `.gltf` (JSON) or `.glb` (binary container).
    Gltf,
}

impl Format {
    /// The format named by a file's extension, looking through a trailing `.gz`.
    pub fn from_path(path: &Path) -> Option<Format> {
        let name = path.file_name()?.to_str()?.to_ascii_lowercase();
        let name = name.strip_suffix(".gz").unwrap_or(&name);
        match Path::new(name).extension()?.to_str()? {
            "obj" => Some(Format::Obj),
            "ply" => Some(Format::Ply),
            "stl" => Some(Format::Stl),
            "gltf" | "glb" => Some(Format::Gltf),
            _ => None,
        }
    }

    /// The format of the file at `path`, told by its content (looking through gzip) and
    /// only where the content is silent by its name: PLY by its first line, STL by a binary
    /// file's exact size or an ASCII file's `solid`, OBJ by the keyword of its first line
    /// that is not blank or a comment. A file that cannot be read gets the format its name
    /// says, so that reading it reports why. A Tessera model (`.bft`, `.dpm`, `.nsp`) or
    /// anything else is an error that says what the file is.
    pub fn of_file(path: &Path) -> Result<Format, LoadError> {
        let Ok((file, len)) = crate::input::open_regular(path) else {
            return Format::from_path(path).ok_or_else(|| err(path, UNKNOWN));
        };
        let mut head = Vec::with_capacity(SNIFF);
        let mut magic = [0u8; 2];
        let mut raw = std::io::BufReader::new(file);
        let gzip = std::io::Read::read_exact(&mut raw, &mut magic).is_ok() && magic == [0x1f, 0x8b];
        let rest = std::io::Read::chain(&magic[..], raw);
        // A prefix is enough; a read error past it is for the loader to report.
        let _ = if gzip {
            std::io::Read::read_to_end(
                &mut std::io::Read::take(flate2::read::MultiGzDecoder::new(rest), SNIFF as u64),
                &mut head,
            )
        } else {
            std::io::Read::read_to_end(&mut std::io::Read::take(rest, SNIFF as u64), &mut head)
        };
        if let Some(kind) = tessera_model(&head) {
            return Err(err(path, format!("this is {kind}, not a mesh file (OBJ, PLY, STL or glTF)")));
        }
        Format::sniff(&head, (!gzip).then_some(len))
            .or_else(|| Format::from_path(path))
            .ok_or_else(|| err(path, UNKNOWN))
    }

    /// The format of a file starting with `head`, of `len` bytes if known uncompressed.
    fn sniff(head: &[u8], len: Option<u64>) -> Option<Format> {
        if head.starts_with(b"ply\n") || head.starts_with(b"ply\r") {
            return Some(Format::Ply);
        }
        // A GLB container, or a JSON object with glTF's mandatory `asset`.
        let text = head.trim_ascii_start();
        if head.starts_with(b"glTF") || (text.starts_with(b"{") && text.windows(7).any(|w| w == b"\"asset\"")) {
            return Some(Format::Gltf);
        }
        if let (Some(len), Some(count)) = (len, head.get(80..84)) {
            let n = u32::from_le_bytes([count[0], count[1], count[2], count[3]]) as u64;
            if len >= 84 && 84 + 50 * n == len {
                return Some(Format::Stl);
            }
        }
        if text.len() >= 5 && text[..5].eq_ignore_ascii_case(b"solid") {
            return Some(Format::Stl);
        }
        // The first line that says something (the prefix may cut the last line short).
        let line = head
            .split(|&b| b == b'\n' || b == b'\r')
            .map(<[u8]>::trim_ascii)
            .find(|l| !l.is_empty() && !l.starts_with(b"#"))?;
        let word = line.split(|b| b.is_ascii_whitespace()).next()?;
        const OBJ: [&[u8]; 12] = [b"v", b"vt", b"vn", b"vp", b"f", b"l", b"p", b"o", b"g", b"s", b"mtllib", b"usemtl"];
        OBJ.contains(&word).then_some(Format::Obj)
    }
}

/// How much of a file [`Format::of_file`] reads.
const SNIFF: usize = 4096;

const UNKNOWN: &str = "not a mesh file Tessera reads: expected OBJ, PLY, STL or glTF (optionally gzipped)";

/// What Tessera model a file starting with `head` is, in words, if it is one.
fn tessera_model(head: &[u8]) -> Option<&'static str> {
    use crate::kind::ModelKind;
    match ModelKind::by_magic(head)? {
        ModelKind::Bft => Some("a .bft model (tessera decode writes it as a mesh)"),
        ModelKind::Dpm => Some("a .dpm progressive mesh (tessera pm stats describes it)"),
        ModelKind::Nsp => Some("an .nsp model (tessera nsp stats describes it)"),
        ModelKind::Mesh => None,
    }
}
