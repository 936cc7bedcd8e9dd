//! `render --out movie.mp4`: the frames piped to `ffmpeg` as raw RGBA, encoded into any
//! container whose extension is in [`EXTENSIONS`] (H.264 in `.mp4`, `.mkv` and `.mov`, VP9
//! in `.webm`, MPEG-4 part 2 in `.avi`), at `--fps` frames a second. `scripts/setup.sh`
//! installs ffmpeg.
//!
//! As every output, the movie never exists half-written: ffmpeg writes a temporary file in
//! the destination's folder, renamed over the destination once ffmpeg has finished without
//! error, and removed on any failure (or on SIGINT, SIGTERM, SIGHUP, through the registry of
//! temporary files in [`crate::output`]). Odd frame sizes are padded by one pixel, as
//! 4:2:0 video needs even sizes.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

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
    dest: PathBuf,
    size: (u32, u32),
    frames: u64,
}

impl Movie {
    /// Starts ffmpeg for frames of `width` x `height` at `fps`, into `dest`.
    pub fn start(dest: &Path, width: u32, height: u32, fps: f32) -> Result<Movie> {
        let ext = dest.extension().and_then(|e| e.to_str()).unwrap_or("mp4").to_ascii_lowercase();
        let dir = match dest.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
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
        Ok(Movie { child, stdin, tmp, dest: dest.to_path_buf(), size: (width, height), frames: 0 })
    }

    /// Appends one frame (RGBA, rows top first, the size given at the start).
    pub fn frame(&mut self, rgba: &[u8]) -> Result<()> {
        let want = self.size.0 as usize * self.size.1 as usize * 4;
        if rgba.len() != want {
            bail!("a movie frame of {} bytes, the movie's frames have {want}", rgba.len());
        }
        let stdin = self.stdin.as_mut().context("the movie is finished")?;
        if stdin.write_all(rgba).is_err() {
            // ffmpeg stopped reading: its own message says why.
            self.stdin = None;
            let why = self.wait_error();
            bail!("ffmpeg failed on frame {}: {why}", self.frames + 1);
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
        std::fs::rename(&self.tmp, &self.dest)
            .with_context(|| format!("cannot move the movie into {}", self.dest.display()))?;
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
        text.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("no message").trim().to_string()
    }
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
