//! The three kinds of model Tessera reads, and the mesh files beside them, told apart by
//! their magic numbers (each format's own) and, failing that, their extensions.

use std::io::Read;
use std::path::Path;

/// The magic number a `.bft` file starts with (`bft::MAGIC`).
pub const BFT_MAGIC: [u8; 8] = *b"TESSBFT\x1a";
/// The magic number a `.dpm` file starts with (`pm::format::MAGIC`).
pub const DPM_MAGIC: [u8; 8] = *b"TESSDPM\x1a";
/// The magic number an `.nsp` file starts with (`nsp::format::MAGIC`).
pub const NSP_MAGIC: [u8; 4] = *b"TNSP";

/// The three kinds of model Tessera reads, told apart by their magic bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelKind {
    /// A `.bft` file (BFT command stream), which rank 0 sorts into tiles.
    Bft,
    /// A `.dpm` file (dependency-free progressive mesh), which workers adapt.
    Dpm,
    /// An `.nsp` file (nSP-tree store), whose cells workers refine.
    Nsp,
    /// Anything else: a mesh file for the loaders (OBJ, PLY, STL, glTF, optionally gzipped).
    Mesh,
}

impl ModelKind {
    /// The Tessera model whose magic number `head` (a file's first bytes) starts with, if
    /// any: never [`ModelKind::Mesh`].
    pub fn by_magic(head: &[u8]) -> Option<ModelKind> {
        if head.starts_with(&BFT_MAGIC) {
            Some(ModelKind::Bft)
        } else if head.starts_with(&DPM_MAGIC) {
            Some(ModelKind::Dpm)
        } else if head.starts_with(&NSP_MAGIC) {
            Some(ModelKind::Nsp)
        } else {
            None
        }
    }

    /// The kind of the model at `path`, from its first 8 bytes. A file without either magic
    /// number whose extension is `.bft` or `.dpm` is taken for that kind, so that the
    /// format's reader reports what is wrong with it ("bad magic number") rather than the
    /// mesh loaders. A file that cannot be read is a mesh here; reading it reports why.
    pub fn of(path: &Path) -> ModelKind {
        let mut magic = [0u8; 8];
        let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
        let read = regular && std::fs::File::open(path).and_then(|mut f| f.read_exact(&mut magic)).is_ok();
        if let Some(kind) = read.then(|| ModelKind::by_magic(&magic)).flatten() {
            return kind;
        }
        match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
            Some("bft") => ModelKind::Bft,
            Some("dpm") => ModelKind::Dpm,
            Some("nsp") => ModelKind::Nsp,
            _ => ModelKind::Mesh,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_kinds_by_magic_then_extension() {
        let dir = tempfile::tempdir().unwrap();
        let put = |name: &str, bytes: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            p
        };
        let mut bft = BFT_MAGIC.to_vec();
        bft.extend_from_slice(b"rest");
        assert_eq!(ModelKind::of(&put("model.obj", &bft)), ModelKind::Bft);
        assert_eq!(ModelKind::of(&put("pm.bin", &DPM_MAGIC)), ModelKind::Dpm);
        assert_eq!(ModelKind::of(&put("bad.BFT", b"garbage!")), ModelKind::Bft);
        assert_eq!(ModelKind::of(&put("bad.dpm", b"")), ModelKind::Dpm);
        assert_eq!(ModelKind::of(&put("mesh.ply", b"ply\nformat ascii 1.0\n")), ModelKind::Mesh);
        assert_eq!(ModelKind::of(Path::new("/dev/zero")), ModelKind::Mesh);
    }
}
