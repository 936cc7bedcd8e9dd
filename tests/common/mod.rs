//! The end-to-end tests' harness, shared by every file in `tests/` (`mod common;`): the
//! binary under test, the environments it runs in (alone, under `mpirun`), what a run must
//! show (`ok`, `refused` and its stricter forms), and PNGs read back and compared. Each test
//! file uses part of it.
#![allow(dead_code)]

use std::io::BufRead;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use testkit::stderr;

pub mod xvfb;

/// The `tessera` binary cargo built for these tests.
pub fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_tessera")
}

/// The longest one command of a test may run. A run that hangs (a deadlock of ours, or
/// mpirun's own: Open MPI 4.1's can hang at exit) then fails its test, showing what it
/// printed, instead of holding the whole suite until CI's limit.
const COMMAND_LIMIT: Duration = Duration::from_secs(300);

/// `cmd`'s output, as `Command::output` gives it, but failing the test if the command runs
/// past [`COMMAND_LIMIT`].
pub fn output(cmd: &mut Command) -> Output {
    output_within(cmd, COMMAND_LIMIT)
}

/// [`output`] with a limit of `limit`. The command gets a process group of its own, so that
/// mpirun and its ranks end together: SIGTERM first (mpirun passes it on), SIGKILL 5 s later.
pub fn output_within(cmd: &mut Command, limit: Duration) -> Output {
    let child = cmd
        .process_group(0)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {:?}: {e}", cmd.get_program()));
    let group = child.id() as i32;
    let (done, finished) = mpsc::channel::<()>();
    // Returns whether it had to end the command.
    let watchdog = std::thread::spawn(move || {
        if finished.recv_timeout(limit) != Err(mpsc::RecvTimeoutError::Timeout) {
            return false;
        }
        // Safety: signals to the command's own process group.
        unsafe { libc::kill(-group, libc::SIGTERM) };
        if finished.recv_timeout(Duration::from_secs(5)) == Err(mpsc::RecvTimeoutError::Timeout) {
            unsafe { libc::kill(-group, libc::SIGKILL) };
        }
        true
    });
    let out = child.wait_with_output().expect("waits for the command");
    drop(done);
    let timed_out = watchdog.join().unwrap();
    assert!(
        !timed_out,
        "{:?} {:?} ran past {} s and was ended\nstdout: {}\nstderr: {}",
        cmd.get_program(),
        cmd.get_args().collect::<Vec<_>>(),
        limit.as_secs_f64(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `tessera ARGS` in the test process's own environment, as a user's shell runs it.
pub fn bare(args: &[&str]) -> Output {
    output(Command::new(bin()).args(args))
}

/// The private runtime folder every run gets (`XDG_RUNTIME_DIR`), made if missing.
fn xdg_runtime_dir() -> PathBuf {
    let xdg = std::env::temp_dir().join("tessera-xdg");
    std::fs::create_dir_all(&xdg).unwrap();
    xdg
}

/// A folder of its own for one MPI job's session files. Open MPI puts every job's under
/// one folder per host and user, and a job that ends removes that folder when it is empty:
/// a job starting beside it in another test then failed to create its own there ("A call
/// to mkdir was unable to create the desired directory", once in CI). Each job gets its own
/// folder under one per test process; Open MPI removes what it made inside.
fn ompi_session_base() -> PathBuf {
    static JOBS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let job = JOBS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("tessera-ompi/{}-{job}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A `tessera` command with the runtime folder set and no `TESSERA_FAULT` inherited, so a
/// test injects only the faults it names.
pub fn cmd() -> Command {
    let mut c = Command::new(bin());
    c.env("XDG_RUNTIME_DIR", xdg_runtime_dir()).env_remove("TESSERA_FAULT");
    c
}

/// `tessera ARGS` through [`cmd`].
pub fn tessera(args: &[&str]) -> Output {
    output(cmd().args(args))
}

/// `tessera ARGS` through [`cmd`], with `env` added.
pub fn tessera_env(env: &[(&str, &str)], args: &[&str]) -> Output {
    let mut c = cmd();
    for (k, v) in env {
        c.env(k, v);
    }
    output(c.args(args))
}

/// The MPI environment: the runtime folder, and Open MPI allowed to run as root and to
/// oversubscribe the cores.
pub fn mpi_env(cmd: &mut Command) -> &mut Command {
    cmd.env("XDG_RUNTIME_DIR", xdg_runtime_dir())
        .env("OMPI_MCA_orte_tmpdir_base", ompi_session_base())
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env("OMPI_MCA_rmaps_base_oversubscribe", "1")
}

/// `tessera ARGS` without mpirun, in the MPI environment: the master and one in-process
/// worker.
pub fn alone(args: &[&str]) -> Output {
    output(mpi_env(&mut Command::new(bin())).args(args))
}

/// `mpirun --oversubscribe -np N tessera ARGS`, with `extra_env` exported to every rank.
pub fn mpirun(n: usize, extra_env: &[(&str, &str)], args: &[&str]) -> Output {
    let mut cmd = Command::new("mpirun");
    mpi_env(&mut cmd).args(["--oversubscribe", "-np", &n.to_string()]);
    for (k, v) in extra_env {
        cmd.args(["-x", &format!("{k}={v}")]);
    }
    output(cmd.arg(bin()).args(args))
}

/// The JSON lines of a file (`--stats`).
pub fn json_lines(path: impl AsRef<Path>) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

/// Succeeded; otherwise fails showing the run's stdout and stderr.
pub fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "failed: {}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Fails with an error that contains `needle`, and no panic.
pub fn refused(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "must fail; stderr: {err}");
    assert_ne!(o.status.code(), Some(101), "panicked: {err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains(needle), "stderr should mention '{needle}': {err}");
}

/// [`refused`], not by a signal, with one error line holding the whole message and nothing
/// after it (a render's progress lines may precede it).
pub fn refused_last_line(o: &Output, needle: &str) {
    refused(o, needle);
    let err = stderr(o);
    assert!(o.status.code().is_some(), "killed by a signal: {:?}; stderr: {err}", o.status);
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error")).collect();
    assert!(errors.len() == 1 && errors[0].contains(needle), "one line: {err}");
    assert!(err.trim_end().ends_with(errors[0]), "nothing after the error: {err}");
}

/// [`refused`] with exit status 1 (an error, not a crash or a signal), stderr one line, and
/// no Debug output.
pub fn refused_one_line(o: &Output, needle: &str) {
    refused(o, needle);
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "an error, not a crash or a signal: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    for debug in ["{ ", "Some(", "Error {", "kind:", "Os {"] {
        assert!(!err.contains(debug), "no Debug output: {err}");
    }
}

/// Entries of a folder, by name, sorted.
pub fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

/// Decoded RGBA pixels of a PNG, with its width and height.
pub fn pixels(path: &Path) -> (u32, u32, Vec<u8>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgba);
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

/// Pixels differing by more than 2/255 in some channel.
pub fn differing(a: &Path, b: &Path) -> usize {
    let (pa, pb) = (pixels(a), pixels(b));
    assert_eq!((pa.0, pa.1), (pb.0, pb.1));
    pa.2.chunks(4).zip(pb.2.chunks(4)).filter(|(x, y)| x.iter().zip(*y).any(|(u, v)| u.abs_diff(*v) > 2)).count()
}

/// Exactly equal images (every byte of every pixel).
pub fn identical(a: &Path, b: &Path) -> bool {
    pixels(a) == pixels(b)
}

/// Pixels covered by the model (alpha 255; every alpha is 0 or 255).
pub fn covered(path: &Path) -> usize {
    let (_, _, px) = pixels(path);
    assert!(px.chunks(4).all(|p| p[3] == 0 || p[3] == 255), "alpha is 0 or 255");
    px.chunks(4).filter(|p| p[3] == 255).count()
}

/// The reference: the whole frame as one tile, in one process (`DIR/reference.png`).
pub fn reference(model: &str, size: &str, dir: &Path) -> PathBuf {
    let out = dir.join("reference.png");
    ok(&alone(&["render", model, "--size", size, "--tiles", "1x1", "--out", out.to_str().unwrap()]));
    out
}

/// A live run (`render --control`, `view`) in a process group of its own, with the address
/// its control port announced; killed with its group if the test ends before it does.
pub struct LiveRun {
    pub child: Child,
    pub addr: String,
}

impl LiveRun {
    /// Starts `cmd` with `stdin`, reads its standard error up to the control port's line,
    /// and copies the rest to the test's standard error (`echo`) or drops it, so that the
    /// run never blocks on a full pipe.
    pub fn start(cmd: &mut Command, stdin: Stdio, echo: bool) -> LiveRun {
        cmd.process_group(0).stdin(stdin).stdout(Stdio::null()).stderr(Stdio::piped());
        let mut child = cmd.spawn().unwrap();
        let mut err = std::io::BufReader::new(child.stderr.take().unwrap());
        let mut line = String::new();
        let deadline = Instant::now() + Duration::from_secs(120);
        let addr = loop {
            line.clear();
            assert!(Instant::now() < deadline, "no control port announced");
            assert!(err.read_line(&mut line).unwrap() > 0, "the run ended before its control port opened");
            if let Some(a) = line.trim().strip_prefix("tessera: control port on ") {
                break a.to_string();
            }
        };
        std::thread::spawn(move || match echo {
            true => std::io::copy(&mut err, &mut std::io::stderr()),
            false => std::io::copy(&mut err, &mut std::io::sink()),
        });
        LiveRun { child, addr }
    }

    /// Waits up to a minute for the run to end by itself; its exit status.
    pub fn wait(mut self) -> ExitStatus {
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(Instant::now() < deadline, "the run did not end");
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Sends one command to the run's control port on a connection of its own; its answer.
    pub fn ask(&self, line: &str) -> serde_json::Value {
        use std::io::Write;
        let mut s = std::net::TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
        s.write_all(format!("{line}\n").as_bytes()).unwrap();
        let mut answer = String::new();
        std::io::BufReader::new(s).read_line(&mut answer).unwrap();
        serde_json::from_str(&answer).unwrap()
    }

    /// The run's status once it has shown `frames` frames (a window has been handed the last).
    pub fn wait_frames(&self, frames: u64) -> serde_json::Value {
        let deadline = Instant::now() + Duration::from_secs(120);
        loop {
            let status = self.ask(r#"{"cmd":"status"}"#);
            if status["frames"].as_u64() >= Some(frames) {
                return status;
            }
            assert!(Instant::now() < deadline, "{status}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// CPU seconds the run's process has used (user and system, from /proc).
    pub fn cpu_seconds(&self) -> f64 {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", self.child.id())).unwrap();
        let fields: Vec<&str> = stat.rsplit_once(')').unwrap().1.split_whitespace().collect();
        // utime and stime are fields 14 and 15 of the line, 12 and 13 after the command.
        let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
        ticks / unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64
    }
}

impl Drop for LiveRun {
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            // Safety: signals the run's own process group.
            unsafe { libc::kill(-(self.child.id() as i32), libc::SIGKILL) };
            let _ = self.child.wait();
        }
    }
}
