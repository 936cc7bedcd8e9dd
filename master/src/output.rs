//! Output files that never destroy anything.
//!
//! - A regular file (or a new one) is written to a temporary file in the destination's folder
//!   and renamed over it only once complete, so a failed or interrupted command leaves the
//!   old file as it was. A symlink to a regular file is followed: the file it points to is
//!   replaced, the link stays a link.
//! - Anything else that exists (a device, a FIFO, a socket, or a symlink to one) is opened
//!   and written directly, never replaced: `-o /dev/null` discards, a FIFO's reader gets the
//!   bytes. `-` is standard output.
//! - The temporary files in flight are registered: SIGINT, SIGTERM and SIGHUP remove them
//!   before the process exits ([`install_signal_handler`]).
//! - [`Identity`] compares files by device and inode, so that a command can refuse, before
//!   any work, an output that is one of its inputs or another of its outputs
//!   ([`check_distinct`]).

use std::collections::HashSet;
use std::io::{BufWriter, Write};
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{bail, Context, Result};

/// Temporary files not yet renamed into place.
static IN_FLIGHT: Mutex<Option<HashSet<PathBuf>>> = Mutex::new(None);

/// Registers a temporary file another process writes (ffmpeg's movie), or a temporary
/// folder (a build's scratch space: removed with everything in it), so that a signal removes
/// it as it removes this process's own temporary files.
pub fn register_in_flight(path: &Path) {
    IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner()).get_or_insert_with(HashSet::new).insert(path.to_path_buf());
}

/// Makes a temporary folder in `parent` (named `prefix` and random letters) and registers it
/// under the registry's lock, so that no signal can come between its making and its
/// registration; [`unregister_in_flight`] it, and remove it, once done.
pub fn temp_dir_in_flight(parent: &Path, prefix: &str) -> std::io::Result<PathBuf> {
    let mut in_flight = IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::Builder::new().prefix(prefix).tempdir_in(parent)?.keep();
    in_flight.get_or_insert_with(HashSet::new).insert(dir.clone());
    Ok(dir)
}

/// The file registered with [`register_in_flight`] is in place or gone.
pub fn unregister_in_flight(path: &Path) {
    unregister(path);
}

fn unregister(path: &Path) {
    if let Some(set) = IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner()).as_mut() {
        set.remove(path);
    }
}

/// Removes every temporary file in flight and ends the process with `code`, holding the
/// registry's lock so that no thread can create another temporary file in between (creation
/// and registration happen under the same lock, see [`write_atomic`]). `_exit`, not `exit`:
/// the other threads are still running (the writer in an `fsync`, rayon, MPI's), and `exit`
/// would run the C library's and MPI's exit handlers and free what they are using.
fn remove_in_flight_and_exit(code: i32) -> ! {
    let mut guard = IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(set) = guard.as_mut() {
        for p in set.drain() {
            match std::fs::symlink_metadata(&p) {
                // Another thread may still be creating files in it: try again once.
                Ok(m) if m.is_dir() => {
                    if std::fs::remove_dir_all(&p).is_err() {
                        let _ = std::fs::remove_dir_all(&p);
                    }
                }
                _ => drop(std::fs::remove_file(&p)),
            }
        }
    }
    // Straight to the file descriptor: the message must not wait for a lock another thread
    // holds.
    let msg = b"tessera: interrupted\n";
    // Safety: writing a static buffer to fd 2, then ending the process without unwinding.
    unsafe {
        libc::write(2, msg.as_ptr().cast(), msg.len());
        libc::_exit(code)
    }
}

/// The signals that interrupt a command.
const INTERRUPTS: [libc::c_int; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];

/// On SIGINT, SIGTERM or SIGHUP: remove the temporary files in flight, say so, and exit with
/// 130 (the shell's code for an interrupted command). Call once, at start-up, before any
/// other thread exists: the three signals are blocked in the calling thread, so every thread
/// started later inherits the mask, and one thread of their own takes them with `sigwait`.
/// No signal handler runs, so no thread is ever interrupted inside `malloc` or an `fsync`.
pub fn install_signal_handler() {
    // Safety: plain libc calls on a local signal set.
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for s in INTERRUPTS {
            // A shell without job control starts background commands with SIGINT ignored,
            // and an ignored signal never reaches `sigwait`: the three are taken whatever
            // they inherited, except SIGHUP under `nohup`, which stays ignored.
            let before = libc::signal(s, libc::SIG_DFL);
            if s == libc::SIGHUP && before == libc::SIG_IGN {
                libc::signal(s, libc::SIG_IGN);
                continue;
            }
            libc::sigaddset(&mut set, s);
        }
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        set
    };
    let spawned = std::thread::Builder::new().name("signals".into()).spawn(move || loop {
        let mut sig = 0;
        // Safety: `set` is a valid signal set; sigwait only writes `sig`.
        if unsafe { libc::sigwait(&set, &mut sig) } == 0 {
            remove_in_flight_and_exit(130);
        }
    });
    if spawned.is_err() {
        // Without the waiting thread the signals must not stay blocked.
        // Safety: as above.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &set, std::ptr::null_mut()) };
    }
}

/// An error as the one line a user reads: its causes joined by `: ` (anyhow's `{:#}`), and
/// any line breaks a cause carries (a parser's snippet, a tool's message) joined by `; `.
pub fn one_line(e: &anyhow::Error) -> String {
    let text = format!("{e:#}");
    text.lines().map(str::trim).filter(|l| !l.is_empty()).collect::<Vec<_>>().join("; ")
}

/// Whether an error comes from writing to a closed pipe (`tessera sort --json | head -c 1`):
/// `main` then ends quietly with a non-zero status, as a command in a pipeline should.
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe))
}

/// Where an output goes.
pub(crate) enum Target {
    Stdout,
    /// An existing file that is not regular (device, FIFO, socket): written in place.
    Special(PathBuf),
    /// A regular file, existing or new, at this path (symlinks resolved).
    Regular(PathBuf),
}

pub(crate) fn target(path: &Path) -> Result<Target> {
    if path.as_os_str() == "-" {
        return Ok(Target::Stdout);
    }
    match std::fs::metadata(path) {
        Ok(meta) if meta.is_dir() => bail!("{} is a directory", path.display()),
        Ok(meta) if !meta.is_file() => Ok(Target::Special(path.to_path_buf())),
        // `/dev/stdout`, `/dev/fd/N`, `/proc/self/fd/N` name a process's stream even when it
        // is redirected to a regular file: write to the stream, never replace the file.
        Ok(_) if path.starts_with("/dev") || path.starts_with("/proc") => Ok(Target::Special(path.to_path_buf())),
        Ok(_) => {
            Ok(Target::Regular(path.canonicalize().with_context(|| format!("cannot resolve {}", path.display()))?))
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                bail!("{} is a symlink to a missing file", path.display());
            }
            Ok(Target::Regular(path.to_path_buf()))
        }
        Err(e) => Err(e).with_context(|| format!("cannot write {}", path.display())),
    }
}

/// Writes `path` with `fill`: atomically for a regular file (on any error the destination is
/// untouched), in place for a special file, or to standard output for `-`.
pub fn write_atomic(path: &Path, fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let cannot = || format!("cannot write {}", path.display());
    let dest = match target(path)? {
        Target::Stdout => {
            let mut w = BufWriter::new(std::io::stdout().lock());
            fill(&mut w).with_context(cannot)?;
            return w.flush().with_context(cannot);
        }
        Target::Special(p) => {
            let f = std::fs::OpenOptions::new().append(true).open(&p).with_context(cannot)?;
            let mut w = BufWriter::new(f);
            fill(&mut w).with_context(cannot)?;
            return w.flush().with_context(cannot);
        }
        Target::Regular(p) => p,
    };
    let dir = match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    // Created with mode 0666 less the umask, as an ordinary `create` would be (tempfile's
    // default is 0600); an existing file's mode is kept below.
    let tmp = {
        let mut in_flight = IN_FLIGHT.lock().unwrap_or_else(|e| e.into_inner());
        let tmp = tempfile::Builder::new()
            .prefix(".tessera-")
            .permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666))
            .tempfile_in(dir)
            .with_context(|| format!("cannot create a temporary file in {}", dir.display()))?;
        in_flight.get_or_insert_with(HashSet::new).insert(tmp.path().to_path_buf());
        tmp
    };
    let tmp_path = tmp.path().to_path_buf();
    slow_write_hook();
    let result = (|| {
        let mut w = BufWriter::new(tmp);
        fill(&mut w).with_context(cannot)?;
        let tmp = w.into_inner().map_err(|e| e.into_error()).with_context(cannot)?;
        tmp.as_file().sync_all().ok();
        if let Some(mode) = existing_mode(&dest) {
            let _ = std::fs::set_permissions(tmp.path(), std::os::unix::fs::PermissionsExt::from_mode(mode));
        }
        tmp.persist(&dest)
            .map_err(|e| e.error)
            .with_context(|| format!("cannot move the output into {}", path.display()))?;
        Ok(())
    })();
    unregister(&tmp_path);
    result
}

/// Test hook: `TESSERA_FAULT=slow-write:MS` pauses MS milliseconds while a temporary file is
/// in flight, so a test can signal the process then. Unset in normal runs.
fn slow_write_hook() {
    if let Some(ms) = std::env::var("TESSERA_FAULT").ok().and_then(|v| v.strip_prefix("slow-write:")?.parse().ok()) {
        std::thread::sleep(std::time::Duration::from_millis(ms));
    }
}

fn existing_mode(path: &Path) -> Option<u32> {
    std::fs::metadata(path).ok().map(|m| m.mode() & 0o7777)
}

/// Prints a command's summary line: on stdout, unless the output itself goes there (`-o -`).
pub fn summary(output: &Path, line: std::fmt::Arguments) -> std::io::Result<()> {
    if output.as_os_str() == "-" {
        eprintln!("{line}");
        Ok(())
    } else {
        crate::outln!("{line}")
    }
}

/// Checks, before any work, a mesh output (`.ply`, `.obj`, or `-` for PLY on stdout) that
/// must not be `input`, and returns its writer.
pub fn mesh_output(input: &Path, output: &Path, what: &str) -> Result<codec::save::WriteMesh> {
    check_extension(output, &["ply", "obj"], what)?;
    check_distinct(&[input], &[output])?;
    Ok(codec::save::writer_for(output).unwrap_or(|m, w| codec::save::write_ply(m, w)))
}

/// Writes bytes (see [`write_atomic`]).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// What a path names, for telling whether two paths are the same file: device and inode of
/// an existing file (symlinks followed), or of a new file's folder and its name; standard
/// output for `-`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Identity {
    Stdout,
    File { dev: u64, ino: u64 },
    New { dev: u64, ino: u64, name: std::ffi::OsString },
}

impl Identity {
    pub fn of(path: &Path) -> Result<Identity> {
        if path.as_os_str() == "-" {
            return Ok(Identity::Stdout);
        }
        if let Ok(m) = std::fs::metadata(path) {
            return Ok(Identity::File { dev: m.dev(), ino: m.ino() });
        }
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let name = path.file_name().with_context(|| format!("{} names no file", path.display()))?;
        let m = std::fs::metadata(dir)
            .with_context(|| format!("cannot write {}: no folder {}", path.display(), dir.display()))?;
        if !m.is_dir() {
            bail!("cannot write {}: {} is not a folder", path.display(), dir.display());
        }
        Ok(Identity::New { dev: m.dev(), ino: m.ino(), name: name.to_os_string() })
    }
}

/// Refuses, before any work, an output that is the same file as an input or as another
/// output (by device and inode, so hard links, symlinks and `./` spellings are caught), an
/// output whose folder does not exist, and one whose folder cannot be written (a probe file
/// is created there and removed: this finds a read-only file system or an immutable folder,
/// which permission bits do not show to root). Linear in the number of paths.
pub fn check_distinct(inputs: &[&Path], outputs: &[&Path]) -> Result<()> {
    let mut seen: std::collections::HashMap<Identity, (&Path, &str)> = std::collections::HashMap::new();
    for &p in inputs {
        if let Ok(id @ Identity::File { .. }) = Identity::of(p) {
            seen.entry(id).or_insert((p, "input"));
        }
    }
    let mut probed: HashSet<PathBuf> = HashSet::new();
    for &p in outputs {
        let id = Identity::of(p)?;
        if let Some((other, role)) = seen.get(&id) {
            if other.as_os_str() == p.as_os_str() {
                bail!("{} is given twice as an output", p.display());
            }
            bail!(
                "the output {} is the same file as the {role} {}; refusing to overwrite it",
                p.display(),
                other.display()
            );
        }
        if let Ok(Target::Regular(dest)) = target(p) {
            let dir = folder_of(&dest).to_path_buf();
            if probed.insert(dir.clone()) {
                probe_writable(p, &dir)?;
            }
        }
        seen.insert(id, (p, "output"));
    }
    Ok(())
}

/// The folder a regular output's temporary file goes to.
fn folder_of(dest: &Path) -> &Path {
    match dest.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Creates and removes a temporary file in `dir`, where `output` will be written.
pub fn probe_writable(output: &Path, dir: &Path) -> Result<()> {
    match tempfile::Builder::new().prefix(".tessera-").tempfile_in(dir) {
        Ok(_) => Ok(()),
        Err(e) => bail!("cannot write {}: its folder {} is not writable ({e})", output.display(), dir.display()),
    }
}

/// Refuses an output path whose extension is not one of `allowed` (`-`, standard output,
/// is always allowed).
pub fn check_extension(path: &Path, allowed: &[&str], what: &str) -> Result<()> {
    if path.as_os_str() == "-" {
        return Ok(());
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !ext.as_deref().is_some_and(|e| allowed.contains(&e)) {
        let list: Vec<String> = allowed.iter().map(|e| format!(".{e}")).collect();
        bail!("{}: {what} must end in {}", path.display(), list.join(" or "));
    }
    Ok(())
}

/// A line-oriented output that is appended to and flushed line by line (`--stats`), so an
/// interrupted run keeps every line written so far. Opened (and checked) before any work.
pub struct LineLog {
    out: Box<dyn Write + Send>,
    path: PathBuf,
}

impl LineLog {
    /// Creates or truncates `path` (a special file is opened in place, `-` is standard
    /// output). A regular file is locked (`flock`) for as long as the log is open, so two
    /// runs given the same stats file cannot interleave their lines: the second is refused
    /// before it truncates anything.
    pub fn create(path: &Path) -> Result<LineLog> {
        let cannot = || format!("cannot write {}", path.display());
        let out: Box<dyn Write + Send> = match target(path)? {
            Target::Stdout => Box::new(std::io::stdout()),
            Target::Special(p) => Box::new(std::fs::OpenOptions::new().append(true).open(p).with_context(cannot)?),
            Target::Regular(p) => {
                let f = std::fs::OpenOptions::new()
                    .write(true)
                    .create(true)
                    .truncate(false)
                    .open(&p)
                    .with_context(cannot)?;
                use std::os::fd::AsRawFd;
                // Safety: flock on a descriptor this function owns; the lock ends with it.
                if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
                    bail!(
                        "{} is being written by another tessera run; give each run its own stats file",
                        path.display()
                    );
                }
                f.set_len(0).with_context(cannot)?;
                Box::new(f)
            }
        };
        Ok(LineLog { out, path: path.to_path_buf() })
    }

    /// Appends one line and flushes it.
    pub fn line(&mut self, line: &str) -> Result<()> {
        let cannot = || format!("cannot write {}", self.path.display());
        self.out.write_all(line.as_bytes()).with_context(cannot)?;
        self.out.write_all(b"\n").with_context(cannot)?;
        self.out.flush().with_context(cannot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn special_files_are_written_in_place_and_regular_ones_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_bytes(&fifo, b"through the fifo").unwrap();
        assert_eq!(reader.join().unwrap(), b"through the fifo");
        assert!(std::os::unix::fs::FileTypeExt::is_fifo(&std::fs::symlink_metadata(&fifo).unwrap().file_type()));

        // A symlink to a regular file stays a link; the file it names is replaced.
        let file = dir.path().join("file");
        std::fs::write(&file, b"old").unwrap();
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(&file, &link).unwrap();
        write_bytes(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read(&file).unwrap(), b"new");
        // A symlink to a FIFO is written through, not replaced.
        let flink = dir.path().join("flink");
        std::os::unix::fs::symlink(&fifo, &flink).unwrap();
        let reader = std::thread::spawn(move || std::fs::read(fifo).unwrap());
        write_bytes(&flink, b"x").unwrap();
        assert_eq!(reader.join().unwrap(), b"x");
        assert!(std::fs::symlink_metadata(&flink).unwrap().file_type().is_symlink());
        // No temporary file is left behind.
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert!(names.iter().all(|n| !n.to_string_lossy().starts_with(".tessera-")), "{names:?}");
    }

    #[test]
    fn new_files_get_the_umask_mode() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        write_bytes(&p, b"1").unwrap();
        let plain = dir.path().join("plain.bin");
        std::fs::write(&plain, b"1").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().mode() & 0o777;
        assert_eq!(mode(&p), mode(&plain));
        // An existing file keeps its mode.
        std::fs::set_permissions(&p, std::os::unix::fs::PermissionsExt::from_mode(0o640)).unwrap();
        write_bytes(&p, b"2").unwrap();
        assert_eq!(mode(&p), 0o640);
    }

    #[test]
    fn same_files_are_refused_by_inode() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.obj");
        std::fs::write(&a, b"v 0 0 0").unwrap();
        let hard = dir.path().join("hard.bft");
        std::fs::hard_link(&a, &hard).unwrap();
        let e = check_distinct(&[&a], &[&hard]).unwrap_err().to_string();
        assert!(e.contains("same file as the input"), "{e}");
        let dotted = dir.path().join(".").join("a.obj");
        assert!(check_distinct(&[&a], &[&dotted]).is_err());
        let new = dir.path().join("new.png");
        let new2 = dir.path().join("./new.png");
        let e = check_distinct(&[&a], &[&new, &new2]).unwrap_err().to_string();
        assert!(e.contains("same file as the output"), "{e}");
        assert!(check_distinct(&[&a], &[&new, &dir.path().join("other.png")]).is_ok());
        assert!(check_distinct(&[&a], &[&dir.path().join("missing/x.png")]).is_err());
    }

    #[test]
    fn extensions_are_checked() {
        assert!(check_extension(Path::new("a.PLY"), &["ply", "obj"], "the mesh").is_ok());
        let e = check_extension(Path::new("a.obj"), &["bft"], "the output").unwrap_err().to_string();
        assert!(e.contains("must end in .bft"), "{e}");
        assert!(check_extension(Path::new("-"), &["bft"], "the output").is_ok());
    }
}
