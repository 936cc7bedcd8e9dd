//! What `tessera render` checks before any rank talks to another, and the names of the files
//! each frame writes.

use std::path::{Path, PathBuf};

use anyhow::Result;
use codec::view::TileGrid;

use crate::cli::RenderArgs;
use crate::composite::{Image, Wall};
use crate::output::{check_distinct, check_extension, Identity};

/// Everything checked before any rank talks to another.
pub struct Plan {
    pub grid: TileGrid,
    pub wall: Option<Wall>,
    /// The inputs' identities, which no output may be.
    pub inputs: Vec<Identity>,
}
/// Above this many output files the up-front identity check looks only at the first and
/// last frames' names (each frame is checked again as it is written).
const CHECKED_OUTPUTS: u64 = 100_000;

/// Checks the flags that need more than their own value (the wall, the grid against the
/// frame, outputs against inputs); every rank runs it before MPI starts.
pub fn plan(args: &RenderArgs) -> Result<Plan> {
    let wall = args.wall.as_deref().map(Wall::load).transpose()?;
    let (w, h) = wall.as_ref().map_or(args.size, Wall::frame_size);
    crate::cli::check_frame_size(w as u64, h as u64)?;
    let grid = TileGrid::new(w, h, args.tiles.0, args.tiles.1)?;
    let movie = crate::movie::is_movie(&args.out);
    if movie {
        if wall.is_some() {
            anyhow::bail!("a wall writes one image per display: --out must be a .png with --wall");
        }
        crate::movie::check_ffmpeg()?;
    } else {
        let mut allowed = vec!["png"];
        allowed.extend(crate::movie::EXTENSIONS);
        check_extension(&args.out, &allowed, "--out")?;
    }
    if args.decode_only && codec::input::ModelKind::of(&args.model) == codec::input::ModelKind::Dpm {
        anyhow::bail!("--decode-only applies to sorted models; a progressive mesh (.dpm) has no tiles to decode");
    }
    if args.decode_only && codec::input::ModelKind::of(&args.model) == codec::input::ModelKind::Nsp {
        anyhow::bail!("--decode-only applies to sorted models; an .nsp model has no tiles to decode");
    }
    // No output may be an input or another output.
    let mut inputs: Vec<&Path> = vec![&args.model];
    inputs.extend(args.wall.as_deref());
    let displays = wall.as_ref().map_or(0, |w| w.columns as u64 * w.rows as u64);
    let per_frame = 1 + displays;
    let frames: Vec<u32> = if movie {
        vec![0]
    } else if per_frame * args.frames as u64 <= CHECKED_OUTPUTS {
        (0..args.frames).collect()
    } else {
        vec![0, args.frames - 1]
    };
    let mut outputs: Vec<PathBuf> =
        frames.iter().flat_map(|&k| frame_outputs(&args.out, k, args.frames, wall.as_ref())).collect();
    outputs.extend(args.stats.clone());
    let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    check_distinct(&inputs, &outputs)?;
    let inputs = inputs.iter().filter_map(|p| Identity::of(p).ok()).collect();
    Ok(Plan { grid, wall, inputs })
}

/// Every file frame `k` writes: the frame, and with a wall each display's image.
pub(super) fn frame_outputs(out: &Path, k: u32, frames: u32, wall: Option<&Wall>) -> Vec<PathBuf> {
    let path = frame_path(out, k, frames);
    let mut v = vec![path.clone()];
    if let Some(wall) = wall {
        v.extend(
            (0..wall.rows).flat_map(|r| (0..wall.columns).map(move |c| (c, r))).map(|(c, r)| display_path(&path, c, r)),
        );
    }
    v
}

/// The image of display `(c, r)` beside the frame's overview `path`.
fn display_path(path: &Path, c: u32, r: u32) -> PathBuf {
    let stem = path.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    path.with_file_name(format!("{stem}-display-{c}-{r}.png"))
}

/// `frame.png` for one frame; `frame-0001.png`, ... for several; a movie is one file.
pub fn frame_path(out: &Path, k: u32, frames: u32) -> PathBuf {
    if frames == 1 || crate::movie::is_movie(out) {
        return out.to_path_buf();
    }
    let stem = out.file_stem().map_or("frame".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}-{:04}.png", k + 1))
}

/// Writes one PNG per display of `wall`, and the overview at `out`.
pub(super) fn save_wall(wall: &Wall, frame: &Image, out: &Path) -> Result<()> {
    let (displays, overview) = wall.split(frame);
    for (i, d) in displays.iter().enumerate() {
        let (c, r) = (i as u32 % wall.columns, i as u32 / wall.columns);
        d.save_png(&display_path(out, c, r))?;
    }
    overview.save_png(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_numbered() {
        assert_eq!(frame_path(Path::new("out/f.png"), 0, 1), PathBuf::from("out/f.png"));
        assert_eq!(frame_path(Path::new("out/f.png"), 2, 10), PathBuf::from("out/f-0003.png"));
    }
}
