//! Direct send to display ranks (`render --wall W --display-ranks D`): the last D ranks of
//! the job own the wall's displays (display `i` belongs to display rank `i mod D`); workers
//! send each display rank the pixels of the tiles that fall on its displays, rank 0 only
//! their times, so no display pixel passes through rank 0. A display rank assembles its
//! displays of a view, tells rank 0 when each is complete, and writes them when rank 0's
//! swap says every display has the view: the swap barrier, so no display shows frame k+1
//! before every display has frame k.
//!
//! With `--present` a display rank shows its displays in windows instead of writing them. It
//! opens them before it says it is ready, sending heartbeats while the X server takes its
//! time, so the start-up cannot deadlock: rank 0 waits for every rank's `Ready` (silence
//! past `--timeout` ends the run, a failure to open names itself) and sends nothing to a
//! display rank before. At a swap every window is drawn before the rank takes its next
//! message, and it reports view k+1 complete only after that; rank 0 swaps view k+1 only
//! when every display rank has, so every display shows frame k before any shows k+1. The
//! window of the wall's first display steers the run: its input goes to rank 0 as control
//! commands (`ToMaster::Input`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use codec::view::TileGrid;
use protocol::{unix_ms, DisplayFrameJob, DisplayReady, Pixels, Ready, Swap, ToDisplay, ToMaster};
use worker::transport::{RecvError, Transport};

use super::plan::{display_path, eye_path, frame_path, Plan};
use crate::camera::StereoOutput;
use crate::composite::{intersection, Image};
use crate::wall::Wall;
use crate::window::{Behaviour, Input, WindowSpec, Windows};

/// Which display rank owns which display, and so which ranks a tile's pixels go to.
#[derive(Clone, Debug)]
pub struct DirectSend {
    /// The displays' rectangles in the frame.
    rects: Vec<[u32; 4]>,
    /// The first display rank; display ranks are `first..first + ranks`.
    first: usize,
    ranks: usize,
}

impl DirectSend {
    /// The layout of a job of `size` ranks whose last `ranks` are display ranks.
    pub fn new(wall: &Wall, size: usize, ranks: usize) -> DirectSend {
        DirectSend { rects: wall.displays.iter().map(|d| d.rect).collect(), first: size - ranks, ranks }
    }

    /// The rank that owns display `i`.
    pub fn owner(&self, i: usize) -> usize {
        self.first + i % self.ranks
    }

    /// The display ranks whose displays the pixel rectangle `rect` reaches, in order.
    pub fn route(&self, rect: [u32; 4]) -> Vec<usize> {
        let mut to: Vec<usize> = (0..self.rects.len())
            .filter(|&i| intersection(self.rects[i], rect).is_some())
            .map(|i| self.owner(i))
            .collect();
        to.sort_unstable();
        to.dedup();
        to
    }

    /// Rank 0's message to every display rank for a view: the tiles sent to workers (by
    /// index) whose pixels reach that rank's displays.
    pub fn frame_messages(
        &self,
        view: u32,
        frame: u32,
        eye: u8,
        tiles: &[u32],
        grid: &TileGrid,
    ) -> Vec<(usize, Vec<u8>)> {
        (self.first..self.first + self.ranks)
            .map(|rank| {
                let tiles =
                    tiles.iter().copied().filter(|&i| self.route(grid.tile_rect(i as usize)).contains(&rank)).collect();
                (rank, ToDisplay::DisplayFrame(DisplayFrameJob { view, frame, eye, tiles }).encode())
            })
            .collect()
    }

    /// The display ranks.
    pub fn display_ranks(&self) -> std::ops::Range<usize> {
        self.first..self.first + self.ranks
    }
}

/// One view on a display rank: what rank 0 said to expect, what came, the images.
#[derive(Default)]
struct View {
    job: Option<DisplayFrameJob>,
    /// Tile indices received so far.
    received: Vec<u32>,
    /// This rank's displays (in `mine` order), transparent until their tiles come.
    images: Vec<Image>,
    /// When each display had every tile it expects (Unix ms).
    ready: Vec<Option<f64>>,
    /// Time spent decoding its coded pixels.
    decode_ms: f64,
    reported: bool,
}

/// A display rank (`render --display-ranks D`, the `index`-th of them): assembles, reports
/// and, at each swap, writes its displays.
pub fn run_display(t: &dyn Transport, plan: &Plan, index: usize) -> Result<()> {
    super::link::report_failure(t, &format!("display rank {index}: "), serve(t, plan, index))
}

fn serve(t: &dyn Transport, plan: &Plan, index: usize) -> Result<()> {
    let wall = plan.wall.as_ref().context("--display-ranks needs --wall")?;
    let layout = DirectSend::new(wall, t.size(), plan.display_ranks as usize);
    let mine: Vec<usize> = (0..wall.displays.len()).filter(|&i| layout.owner(i) == t.rank()).collect();
    let windows = if plan.present { Some(open_windows(t, plan, wall, &mine)?) } else { None };
    t.send(
        0,
        &ToMaster::Ready(Ready { adapter: format!("display rank {index}"), max_texture_side: u32::MAX }).encode(),
    );
    let new_view = || View {
        images: mine
            .iter()
            .map(|&i| {
                let [x0, y0, x1, y1] = wall.displays[i].rect;
                Image::new(x1 - x0, y1 - y0)
            })
            .collect(),
        ready: vec![None; mine.len()],
        ..View::default()
    };
    let mut views: BTreeMap<u32, View> = BTreeMap::new();
    // The end of the run: the windows close, saying why if they failed.
    let end = |windows: Option<Windows>| windows.map_or(Ok(()), Windows::close);
    loop {
        let (from, bytes) = match t.recv(std::time::Duration::from_secs(3600)) {
            Ok(m) => m,
            Err(RecvError::Timeout) => bail!("no message for an hour"),
            Err(RecvError::Disconnected) => return end(windows),
        };
        let view = if from == 0 {
            match ToDisplay::decode(&bytes).context("bad message from rank 0")? {
                ToDisplay::Shutdown => return end(windows),
                ToDisplay::DisplayFrame(job) => {
                    let v = job.view;
                    views.entry(v).or_insert_with(new_view).job = Some(job);
                    v
                }
                ToDisplay::Swap(Swap { view }) => {
                    let v = views
                        .remove(&view)
                        .with_context(|| format!("a swap of view {view}, which it does not hold"))?;
                    if !v.reported {
                        bail!("a swap of view {view} before its displays were complete");
                    }
                    let job = v.job.expect("reported views have their job");
                    match &windows {
                        Some(w) => w.show_each(v.images, plan.timeout)?,
                        None => {
                            for (&i, image) in mine.iter().zip(&v.images) {
                                image.save_png(&display_file(plan, &job, &wall.displays[i].name))?;
                            }
                        }
                    }
                    continue;
                }
                ToDisplay::KeepAlive => continue,
            }
        } else {
            match ToMaster::decode(&bytes).with_context(|| format!("bad message from rank {from}"))? {
                ToMaster::Pixels(Pixels { frame, tiles, .. }) => {
                    let v = views.entry(frame).or_insert_with(new_view);
                    for tile in tiles {
                        let [x0, y0, x1, y1] = tile.rect;
                        let start = std::time::Instant::now();
                        let rgba = worker::pixels::decode(&tile).with_context(|| format!("rank {from}"))?;
                        v.decode_ms += start.elapsed().as_secs_f64() * 1e3;
                        let pixels = Image { width: x1 - x0, height: y1 - y0, rgba };
                        for (&i, image) in mine.iter().zip(v.images.iter_mut()) {
                            let d = wall.displays[i].rect;
                            if let Some(r) = intersection(d, tile.rect) {
                                let part = pixels.crop([r[0] - x0, r[1] - y0, r[2] - x0, r[3] - y0]);
                                image.blit([r[0] - d[0], r[1] - d[1], r[2] - d[0], r[3] - d[1]], &part.rgba)?;
                            }
                        }
                        v.received.push(tile.index);
                    }
                    frame
                }
                ToMaster::Heartbeat => continue,
                other => bail!("unexpected message from rank {from}: {}", other.name()),
            }
        };
        // A display is complete when every tile rank 0 said reaches it has come.
        let v = views.get_mut(&view).expect("just touched");
        let Some(job) = &v.job else { continue };
        if v.reported {
            continue;
        }
        let now = unix_ms();
        for (k, &i) in mine.iter().enumerate() {
            let rect = wall.displays[i].rect;
            let done = job
                .tiles
                .iter()
                .filter(|&&tile| intersection(rect, plan.grid.tile_rect(tile as usize)).is_some())
                .all(|tile| v.received.contains(tile));
            if done && v.ready[k].is_none() {
                v.ready[k] = Some(now);
            }
        }
        if v.ready.iter().all(Option::is_some) {
            v.reported = true;
            let ready = mine.iter().zip(&v.ready).map(|(&i, r)| (i as u32, r.expect("all ready"))).collect();
            t.send(0, &ToMaster::DisplayReady(DisplayReady { view, ready, decode_ms: v.decode_ms }).encode());
        }
    }
}

/// This rank's windows (`--present`), one per display it owns, placed as the wall file says;
/// the wall's first display's window steers, its input sent to rank 0. Heartbeats go to rank
/// 0 while the windows open.
fn open_windows(t: &dyn Transport, plan: &Plan, wall: &Wall, mine: &[usize]) -> Result<Windows> {
    let specs = mine.iter().map(|&i| WindowSpec::display(plan, &wall.displays[i], false)).collect();
    let behaviour = Behaviour { steer: mine.first() == Some(&0), ..Behaviour::of(plan) };
    let send = t.sender(0);
    let input: Input = Box::new(move |command| match serde_json::to_string(&command) {
        Ok(json) => send(&ToMaster::Input(protocol::Input { json }).encode()),
        Err(e) => eprintln!("tessera: a window's command: {e}"),
    });
    let beat = t.sender(0);
    let heartbeat = ToMaster::Heartbeat.encode();
    if let Some(delay) = slow_window_fault(t.rank()) {
        let start = std::time::Instant::now();
        while start.elapsed() < delay {
            beat(&heartbeat);
            std::thread::sleep(worker::node::HEARTBEAT.min(delay - start.elapsed().min(delay)));
        }
    }
    Windows::open(specs, behaviour, input, worker::node::HEARTBEAT, &mut || beat(&heartbeat))
}

/// A test hook, unset in normal runs: `TESSERA_FAULT=window:R:MS` makes display rank R take
/// MS milliseconds longer to open its windows (a slow X server), heartbeats going on.
fn slow_window_fault(rank: usize) -> Option<std::time::Duration> {
    let v = std::env::var("TESSERA_FAULT").ok()?;
    let mut parts = v.split(':');
    if parts.next()? != "window" || parts.next()?.parse::<usize>().ok()? != rank {
        return None;
    }
    Some(std::time::Duration::from_millis(parts.next()?.parse().ok()?))
}

/// The file of display `name` for a view.
fn display_file(plan: &Plan, job: &DisplayFrameJob, name: &str) -> PathBuf {
    let path = frame_path(&plan.out, job.frame, plan.frames);
    let path = match (job.eye, plan.stereo) {
        (1, Some(StereoOutput::Separate)) => eye_path(&path, "left"),
        (2, Some(StereoOutput::Separate)) => eye_path(&path, "right"),
        _ => path,
    };
    display_path(&path, name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_go_to_the_owners_of_the_displays_they_reach() {
        let wall =
            Wall::parse("columns = 3\nrows = 1\ndisplay_width = 10\ndisplay_height = 10\nbezel_x = 2\n").unwrap();
        // Ranks 0 (master), 1-2 (workers), 3-4 (display ranks): displays 0 and 2 on rank 3.
        let layout = DirectSend::new(&wall, 5, 2);
        assert_eq!((layout.owner(0), layout.owner(1), layout.owner(2)), (3, 4, 3));
        assert_eq!(layout.route([0, 0, 5, 5]), [3]);
        assert_eq!(layout.route([8, 0, 14, 5]), [3, 4]);
        // A tile on a bezel alone goes nowhere.
        assert_eq!(layout.route([10, 0, 12, 10]), Vec::<usize>::new());
        assert_eq!(layout.route([0, 0, 34, 10]), [3, 4]);
        let grid = TileGrid::new(34, 10, 4, 1).unwrap();
        let msgs = layout.frame_messages(7, 3, 0, &[0, 1, 3], &grid);
        let tiles = |m: &[u8]| match ToDisplay::decode(m).unwrap() {
            ToDisplay::DisplayFrame(j) => j.tiles,
            other => panic!("{other:?}"),
        };
        // Tiles are 8 or 9 pixels wide: 0..8, 8..17, 17..25, 25..34.
        assert_eq!((msgs[0].0, tiles(&msgs[0].1)), (3, vec![0, 1, 3]));
        assert_eq!((msgs[1].0, tiles(&msgs[1].1)), (4, vec![1]));
    }
}
