//! Bounded reads of input files.
//!
//! Every file Tessera reads (meshes, `.bft`, `.dpm`, wall descriptions) goes through
//! [`read_file`]: it refuses anything that is not a regular file (after following symlinks),
//! so `/dev/zero`, a FIFO or a terminal cannot feed a reader without end, and it reads a
//! regular file's known length, nothing more. Gzip input is decompressed through
//! [`read_capped`], which stops at [`max_decompressed_bytes`] with an error that names the
//! limit and the flag that raises it (`--max-decompressed`): a few megabytes of gzip can
//! expand a thousandfold.
//!
//! Formats with headers (`.bft`, `.dpm`) also refuse a header that claims more than the
//! file holds before they allocate; that check lives with each format.

use std::io::Read;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The default cap on decompressed input, 1 GiB: about 40M triangles of binary PLY, and
/// far beyond any real mesh's gzip ratio at the sizes a user feeds one process.
pub const DEFAULT_MAX_DECOMPRESSED_BYTES: u64 = 1 << 30;

static MAX_DECOMPRESSED: AtomicU64 = AtomicU64::new(DEFAULT_MAX_DECOMPRESSED_BYTES);

/// Sets the cap on decompressed input for this process (the `--max-decompressed` flag).
pub fn set_max_decompressed_bytes(bytes: u64) {
    MAX_DECOMPRESSED.store(bytes, Ordering::Relaxed);
}

/// The cap on decompressed input now in force.
pub fn max_decompressed_bytes() -> u64 {
    MAX_DECOMPRESSED.load(Ordering::Relaxed)
}

static ALLOW_OUTSIDE_URIS: AtomicBool = AtomicBool::new(false);

/// Lets a glTF file's buffer and image URIs name files outside its folder (absolute paths,
/// `..` that leaves it, symlinks that lead out of it) for this process: the
/// `--allow-outside-uris` flag. Off by default, so a model file cannot make Tessera read any
/// other file on the machine.
pub fn set_allow_outside_uris(allow: bool) {
    ALLOW_OUTSIDE_URIS.store(allow, Ordering::Relaxed);
}

/// Whether glTF URIs may leave the model's folder ([`set_allow_outside_uris`]).
pub fn allow_outside_uris() -> bool {
    ALLOW_OUTSIDE_URIS.load(Ordering::Relaxed)
}

/// Refuses, before anything is allocated, `count` values of `each` bytes that a file's
/// `field` asks for when they would take more than [`max_decompressed_bytes`]: the message
/// names the field, the count and the memory, and the flag that raises the cap.
pub fn check_decoded(field: &str, count: u64, unit: &str, each: u64) -> Result<(), String> {
    let cap = max_decompressed_bytes();
    let need = count.saturating_mul(each);
    if need > cap {
        return Err(format!(
            "{field}: {count} {unit} would take {} decoded, above the cap on decompressed input of {} \
             (raise it with --max-decompressed)",
            mib(need),
            mib(cap)
        ));
    }
    Ok(())
}

/// Bytes in MiB for messages ("3.2 MiB", "49152 MiB").
fn mib(bytes: u64) -> String {
    let m = bytes as f64 / (1u64 << 20) as f64;
    if m < 10.0 {
        format!("{m:.1} MiB")
    } else {
        format!("{m:.0} MiB")
    }
}

/// Reads a whole regular file. Anything else (a device, a FIFO, a socket, a directory, or a
/// symlink to one) is refused without reading, with a message that says what it is.
pub fn read_file(path: &Path) -> Result<Vec<u8>, String> {
    let (mut file, len) = open_regular(path)?;
    let mut out = Vec::with_capacity(len.min(isize::MAX as u64) as usize);
    // Read no more than the length the file had when opened, so a file that grows while we
    // read it cannot make us read without end.
    (&mut file).take(len).read_to_end(&mut out).map_err(|e| format!("cannot read: {e}"))?;
    Ok(out)
}

/// Opens a regular file for reading, refusing anything else as [`read_file`] does, and
/// returns it with its length when opened (the most a reader should take from it). For
/// readers that stream a file instead of reading it whole (`load::stream`).
pub fn open_regular(path: &Path) -> Result<(std::fs::File, u64), String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("cannot read: {e}"))?;
    if !meta.is_file() {
        return Err(format!("not a regular file ({}); inputs must be regular files", kind(&meta)));
    }
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read: {e}"))?;
    Ok((file, meta.len()))
}

/// What kind of non-regular file `meta` describes, in words.
fn kind(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "a directory"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Reads `reader` to its end, or fails once it yields more than `limit` bytes.
pub fn read_capped(reader: impl Read, limit: u64, out: &mut Vec<u8>) -> Result<(), String> {
    let n = reader.take(limit.saturating_add(1)).read_to_end(out).map_err(|e| e.to_string())?;
    if n as u64 > limit {
        return Err(format!(
            "decompresses to more than {limit} bytes, the limit (raise it with --max-decompressed BYTES)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn special_files_are_refused() {
        let e = read_file(Path::new("/dev/zero")).unwrap_err();
        assert!(e.contains("character device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let e = read_file(dir.path()).unwrap_err();
        assert!(e.contains("directory"), "{e}");
        let fifo = dir.path().join("f");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let e = read_file(&fifo).unwrap_err();
        assert!(e.contains("FIFO"), "{e}");
        let link = dir.path().join("l");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        assert!(read_file(&link).unwrap_err().contains("character device"));
        let file = dir.path().join("r");
        std::fs::write(&file, b"abc").unwrap();
        assert_eq!(read_file(&file).unwrap(), b"abc");
    }

    #[test]
    fn capped_reads_stop_at_the_limit() {
        let mut out = Vec::new();
        read_capped(&[7u8; 10][..], 10, &mut out).unwrap();
        assert_eq!(out.len(), 10);
        out.clear();
        let e = read_capped(std::io::repeat(0), 1000, &mut out).unwrap_err();
        assert!(e.contains("more than 1000 bytes") && e.contains("--max-decompressed"), "{e}");
        assert!(out.len() <= 1001);
    }
}
