//! An X server of our own (Xvfb, which `scripts/setup.sh` installs) for the tests of windows:
//! input sent with `xdotool`, pixels read back with `xwd`.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use super::pixels;

/// An X server of our own on a free display number, ended with the test.
pub struct Xvfb {
    child: Child,
    pub display: String,
}

impl Xvfb {
    pub fn start() -> Xvfb {
        for n in (100 + std::process::id() % 400..).take(50) {
            if Path::new(&format!("/tmp/.X{n}-lock")).exists() {
                continue;
            }
            let display = format!(":{n}");
            let child = Command::new("Xvfb")
                .args([&display, "-screen", "0", "1024x768x24", "-nolisten", "tcp"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("Xvfb (scripts/setup.sh installs it)");
            let mut x = Xvfb { child, display };
            let deadline = Instant::now() + Duration::from_secs(20);
            while Instant::now() < deadline {
                if Path::new(&format!("/tmp/.X11-unix/X{n}")).exists() {
                    return x;
                }
                if x.child.try_wait().unwrap().is_some() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = x.child.kill();
        }
        panic!("no Xvfb display could be started");
    }

    pub fn xdotool(&self, args: &[&str]) -> String {
        let out = Command::new("xdotool").env("DISPLAY", &self.display).args(args).output().expect("xdotool");
        assert!(out.status.success(), "xdotool {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }

    /// The window's pixels as the X server holds them, `0x00RRGGBB` rows top first, read with
    /// `xwd` (its format: a big-endian header, a colour map, then the pixels).
    pub fn pixels_of(&self, window: &str) -> (u32, u32, Vec<u32>) {
        let out = Command::new("xwd")
            .env("DISPLAY", &self.display)
            .args(["-silent", "-id", window])
            .output()
            .expect("xwd (x11-apps)");
        assert!(out.status.success(), "xwd: {}", String::from_utf8_lossy(&out.stderr));
        let d = out.stdout;
        let field = |i: usize| u32::from_be_bytes(d[i * 4..i * 4 + 4].try_into().unwrap());
        let (header, width, height, lsb, bpp, bpl, colors) =
            (field(0), field(4), field(5), field(7) == 0, field(11), field(12), field(19));
        assert_eq!(bpp, 32, "a 24-bit screen stores 32 bits a pixel");
        let start = (header + colors * 12) as usize;
        let mut px = Vec::with_capacity((width * height) as usize);
        for y in 0..height as usize {
            for x in 0..width as usize {
                let b: [u8; 4] = d[start + y * bpl as usize + x * 4..][..4].try_into().unwrap();
                px.push(if lsb { u32::from_le_bytes(b) } else { u32::from_be_bytes(b) } & 0xff_ffff);
            }
        }
        (width, height, px)
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `render`'s frame as the window shows it: RGB where drawn, black where not.
pub fn as_shown(png: &Path) -> Vec<u32> {
    let (_, _, rgba) = pixels(png);
    rgba.chunks(4).map(|p| if p[3] == 0 { 0 } else { (p[0] as u32) << 16 | (p[1] as u32) << 8 | p[2] as u32 }).collect()
}
