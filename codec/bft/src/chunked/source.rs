//! Where a chunked file's bytes come from.

use std::borrow::Cow;
use std::path::{Path, PathBuf};

use crate::container::FormatError;

/// Where a chunked file's bytes come from: bytes in memory (anything `AsRef<[u8]>`: a `Vec`,
/// a slice, a memory map) or a file read with positioned reads ([`FileSource`]). A chunk is
/// read when it is used, so a file larger than memory is never held whole.
pub trait ChunkSource: Sync {
    /// The file's length (when it was opened, for a file).
    fn len(&self) -> u64;

    /// Whether the file has no bytes.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// `len` bytes at `offset`, borrowed from memory or read; `what` names them in an error
    /// ("chunk 12", "the chunk directory").
    fn read_at(&self, offset: u64, len: usize, what: &str) -> Result<Cow<'_, [u8]>, FormatError>;
}

impl<B: AsRef<[u8]> + Sync> ChunkSource for B {
    fn len(&self) -> u64 {
        self.as_ref().len() as u64
    }

    fn read_at(&self, offset: u64, len: usize, what: &str) -> Result<Cow<'_, [u8]>, FormatError> {
        let b = self.as_ref();
        usize::try_from(offset).ok().and_then(|o| b.get(o..o.checked_add(len)?)).map(Cow::Borrowed).ok_or_else(|| {
            FormatError::Io(format!("{what}: {len} bytes at offset {offset} lie past the end ({} bytes)", b.len()))
        })
    }
}

/// A chunked file on disk, read with `pread` (`FileExt::read_exact_at`) chunk by chunk
/// instead of memory-mapped: a file truncated while in use gives an error that names it and
/// the chunk, where a mapping would kill the process with SIGBUS. A file replaced by a rename
/// is still read through the descriptor opened here, unchanged; one rewritten in place is
/// caught by each chunk's checksums (its stream's header and sections, its border table) and
/// its directory entry (counts and box), as any corrupt chunk is.
pub struct FileSource {
    file: std::fs::File,
    path: PathBuf,
    len: u64,
}

impl FileSource {
    /// Opens a regular file (anything else is refused, as [`crate::input::read_file`] does).
    pub fn open(path: &Path) -> Result<FileSource, FormatError> {
        let (file, len) =
            crate::input::open_regular(path).map_err(|e| FormatError::Io(format!("{}: {e}", path.display())))?;
        Ok(FileSource { file, path: path.to_path_buf(), len })
    }

    /// The path the file was opened by.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl ChunkSource for FileSource {
    fn len(&self) -> u64 {
        self.len
    }

    fn read_at(&self, offset: u64, len: usize, what: &str) -> Result<Cow<'_, [u8]>, FormatError> {
        use std::os::unix::fs::FileExt;
        let mut buf = vec![0u8; len];
        self.file.read_exact_at(&mut buf, offset).map_err(|e| {
            let path = self.path.display();
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                FormatError::Io(format!(
                    "{path}: {what}: the file was truncated or replaced while in use (expected {len} bytes at offset {offset})"
                ))
            } else {
                FormatError::Io(format!("{path}: {what}: cannot read {len} bytes at offset {offset}: {e}"))
            }
        })?;
        Ok(Cow::Owned(buf))
    }
}
