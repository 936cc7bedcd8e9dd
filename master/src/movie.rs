//! `render --out movie.mp4`: the frames piped to `ffmpeg` as raw RGBA, encoded into any
//! container whose extension is in [`EXTENSIONS`] (H.264 in `.mp4`, `.mkv` and `.mov`, VP9
//! in `.webm`, MPEG-4 part 2 in `.avi`), at `--fps` frames a second. `scripts/setup.sh`
//! installs ffmpeg.
//!
//! As every output, the movie follows [`crate::output`]'s rules and never exists
//! half-written: ffmpeg writes a temporary file in the destination's folder, renamed over the
//! destination once ffmpeg has finished without error (a symlink's target is replaced, the
//! link stays), or copied into a destination that is a device or a FIFO, which stays what it
//! is; the temporary file is removed on any failure (or on SIGINT, SIGTERM, SIGHUP, through
//! the registry of temporary files in [`crate::output`]). An ffmpeg that stops reading frames
//! for `--timeout` is an error, not a hang. Odd frame sizes are padded by one pixel, as
//! 4:2:0 video needs even sizes.

use std::io::Write;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

/// The containers `--out` may name for a movie.
pub const EXTENSIONS: [&str; 5] = ["mp4", "mkv", "mov", "webm", "avi"];

/// Whether `path` names a movie (by its extension).
pub fn is_movie(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Checks, before any work, that ffmpeg can be run.
pub fn check_ffmpeg() -> Result<()> {
    let ok = Command::new("ffmpeg").arg("-version").stdout(Stdio::null()).stderr(Stdio::null()).status();
    match ok {
        Ok(s) if s.success() => Ok(()),
        _ => bail!("a movie output needs ffmpeg on the PATH (scripts/setup.sh installs it)"),
    }
}

/// An ffmpeg process encoding frames into a temporary file beside the destination.
pub struct Movie {
    child: Child,
    stdin: Option<ChildStdin>,
    tmp: PathBuf,
    dest: Dest,
    size: (u32, u32),
    frames: u64,
    /// How long ffmpeg may leave a frame unread (`--timeout`).
    timeout: Duration,
}

/// Where the finished movie goes.
enum Dest {
    /// Renamed over this regular file (symlinks resolved).
    Replace(PathBuf),
    /// Copied into this device or FIFO, which is written in place.
    InPlace(PathBuf),
}

impl Movie {
    /// Starts ffmpeg for frames of `width` x `height` at `fps`, into `dest`; a frame ffmpeg
    /// leaves unread for `timeout` ends the movie with an error.
    pub fn start(dest: &Path, width: u32, height: u32, fps: f32, timeout: Duration) -> Result<Movie> {
        let ext = dest.extension().and_then(|e| e.to_str()).unwrap_or("mp4").to_ascii_lowercase();
        let dest = match crate::output::target(dest)? {
            crate::output::Target::Regular(p) => Dest::Replace(p),
            crate::output::Target::Special(p) => Dest::InPlace(p),
            crate::output::Target::Stdout => bail!("a movie cannot go to standard output: name a file"),
        };
        let dir = match &dest {
            Dest::Replace(p) => match p.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            },
            // A device's folder (/dev) is no place for a temporary file.
            Dest::InPlace(_) => std::env::temp_dir(),
        };
        let tmp = dir.join(format!(".tessera-movie-{}.{ext}", std::process::id()));
        crate::output::register_in_flight(&tmp);
        let codec: &[&str] = match ext.as_str() {
            "webm" => &["-c:v", "libvpx-vp9", "-b:v", "0", "-crf", "32", "-deadline", "realtime"],
            "avi" => &["-c:v", "mpeg4", "-q:v", "3"],
            _ => &["-c:v", "libx264", "-preset", "veryfast", "-crf", "18"],
        };
        let child = Command::new("ffmpeg")
            .args(["-hide_banner", "-loglevel", "error", "-nostdin", "-y", "-f", "rawvideo", "-pix_fmt", "rgba"])
            .args(["-s", &format!("{width}x{height}"), "-framerate", &format!("{fps}"), "-i", "pipe:0"])
            .args(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p"])
            .args(codec)
            .arg(&tmp)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn();
        let mut child = match child {
            Ok(c) => c,
            Err(e) => {
                crate::output::unregister_in_flight(&tmp);
                return Err(e).context("cannot start ffmpeg (scripts/setup.sh installs it)");
            }
        };
        let stdin = child.stdin.take();
        if let Some(s) = &stdin {
            // Non-blocking, so that `frame` can wait for the pipe with a deadline.
            // Safety: fcntl on a descriptor the ChildStdin owns.
            unsafe {
                let fd = s.as_raw_fd();
                libc::fcntl(fd, libc::F_SETFL, libc::fcntl(fd, libc::F_GETFL) | libc::O_NONBLOCK);
            }
        }
        Ok(Movie { child, stdin, tmp, dest, size: (width, height), frames: 0, timeout })
    }

    /// Appends one frame (RGBA, rows top first, the size given at the start).
    pub fn frame(&mut self, rgba: &[u8]) -> Result<()> {
        let want = self.size.0 as usize * self.size.1 as usize * 4;
        if rgba.len() != want {
            bail!("a movie frame of {} bytes, the movie's frames have {want}", rgba.len());
        }
        let stdin = self.stdin.as_mut().context("the movie is finished")?;
        match write_within(stdin, rgba, self.timeout) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                self.stdin = None;
                let _ = self.child.kill();
                bail!(
                    "ffmpeg read nothing of frame {} for {:.0} s (--timeout); stopping the movie",
                    self.frames + 1,
                    self.timeout.as_secs_f64()
                );
            }
            Err(_) => {
                // ffmpeg stopped reading: its own message says why.
                self.stdin = None;
                let why = self.wait_error();
                bail!("ffmpeg failed on frame {}: {why}", self.frames + 1);
            }
        }
        self.frames += 1;
        Ok(())
    }

    /// Ends the stream, waits for ffmpeg and moves the movie into place.
    pub fn finish(mut self) -> Result<()> {
        self.stdin = None;
        let status = self.child.wait().context("cannot wait for ffmpeg")?;
        if !status.success() {
            let why = self.stderr_line();
            bail!("ffmpeg failed ({status}): {why}");
        }
        match &self.dest {
            Dest::Replace(dest) => std::fs::rename(&self.tmp, dest)
                .with_context(|| format!("cannot move the movie into {}", dest.display()))?,
            Dest::InPlace(dest) => {
                let copied = (|| {
                    let mut from = std::fs::File::open(&self.tmp)?;
                    let mut to = std::fs::OpenOptions::new().append(true).open(dest)?;
                    std::io::copy(&mut from, &mut to).map(drop)
                })();
                let _ = std::fs::remove_file(&self.tmp);
                copied.with_context(|| format!("cannot write the movie into {}", dest.display()))?;
            }
        }
        crate::output::unregister_in_flight(&self.tmp);
        Ok(())
    }

    fn wait_error(&mut self) -> String {
        let _ = self.child.wait();
        self.stderr_line()
    }

    /// The last line ffmpeg wrote on its standard error.
    fn stderr_line(&mut self) -> String {
        let mut text = String::new();
        if let Some(mut e) = self.child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut e, &mut text);
        }
        let line = text.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").trim();
        // ffmpeg names the file it writes, which is our temporary file: name the movie instead.
        let dest = match &self.dest {
            Dest::Replace(p) | Dest::InPlace(p) => p.display().to_string(),
        };
        line.replace(&self.tmp.display().to_string(), &dest)
    }
}

/// Writes all of `buf` to a non-blocking pipe, waiting at most `timeout` for the reader to
/// make room each time the pipe is full (`TimedOut` if it never does).
fn write_within(pipe: &mut ChildStdin, mut buf: &[u8], timeout: Duration) -> std::io::Result<()> {
    let mut since = Instant::now();
    while !buf.is_empty() {
        match pipe.write(buf) {
            Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
            Ok(n) => {
                buf = &buf[n..];
                since = Instant::now();
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                let left = timeout.saturating_sub(since.elapsed());
                if left.is_zero() {
                    return Err(std::io::ErrorKind::TimedOut.into());
                }
                let mut fd = libc::pollfd { fd: pipe.as_raw_fd(), events: libc::POLLOUT, revents: 0 };
                let ms = left.as_millis().clamp(1, i32::MAX as u128) as i32;
                // Safety: one valid pollfd.
                unsafe { libc::poll(&mut fd, 1, ms) };
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

impl Drop for Movie {
    /// A movie not finished (an error, a panic) leaves nothing behind.
    fn drop(&mut self) {
        self.stdin = None;
        if self.tmp.exists() || self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
            let _ = std::fs::remove_file(&self.tmp);
            crate::output::unregister_in_flight(&self.tmp);
        }
    }
}
