//! Fuzzes the wall-file parser (`render --wall`): any bytes must parse into a wall or return
//! an error, never panic, hang or allocate without bound, and a wall that parses lays out
//! displays that lie inside its frame and split a frame of its size.
//! Run: `cd fuzz && cargo fuzz run parse_wall`
//! (on stable Rust: `RUSTC_BOOTSTRAP=1 cargo fuzz run parse_wall`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use master::composite::{Image, Wall};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(wall) = Wall::parse(text) else { return };
    let (w, h) = wall.frame_size();
    assert!(wall.displays.len() as u64 <= master::composite::MAX_DISPLAYS);
    for d in &wall.displays {
        let [x0, y0, x1, y1] = d.rect;
        assert!(x0 < x1 && y0 < y1 && x1 <= w && y1 <= h, "display {} outside its {w}x{h} wall", d.name);
    }
    // Splitting a frame allocates the frame and every display: only for small walls here.
    if (w as u64) * (h as u64) <= 1 << 20 {
        let (images, overview) = wall.split(&Image::new(w, h));
        assert_eq!((images.len(), overview.width, overview.height), (wall.displays.len(), w, h));
    }
    if let Some(eye) = wall.eye {
        let _ = wall.check_eye(eye);
    }
});
