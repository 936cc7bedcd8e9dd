//! Rank 0's side of the conversation with the workers: the handshake, the heartbeats that
//! tell a busy worker from a dead one, and receiving each frame's tile pixels.

use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use codec::view::TileGrid;
use protocol::{FrameSpan, Pixels, PmMemory, TilePixels, ToMaster};
use worker::transport::{RecvError, Transport};

/// How a rank that helps rank 0 (a sorter, a display rank) ends: a failure is reported to
/// rank 0, which ends the job with it (`prefix` says who failed), and returned.
pub(super) fn report_failure(t: &dyn Transport, prefix: &str, result: Result<()>) -> Result<()> {
    if let Err(e) = &result {
        t.send(
            0,
            &ToMaster::Failed(protocol::Failed { reason: format!("{prefix}{}", crate::output::one_line(e)) }).encode(),
        );
    }
    result
}

/// Sends `msgs` all at once (see [`Transport::send_many`]); a rank that takes nothing and
/// says nothing for `timeout` (`--timeout`) ends the run, as silence does while receiving.
pub(super) fn send_all(t: &dyn Transport, msgs: Vec<(usize, Vec<u8>)>, timeout: Duration) -> Result<()> {
    t.send_many(msgs, timeout).map_err(|s| {
        anyhow::anyhow!(
            "rank {} took no message and sent nothing for {:.0} s (--timeout); counting it as dead",
            s.rank,
            timeout.as_secs_f64()
        )
    })
}

/// When each worker was last heard from, for telling a dead worker from a busy one: a worker
/// sends heartbeats while it works, so only silence longer than the timeout counts.
pub(super) struct Silence {
    timeout: Duration,
    last: Vec<Instant>,
    /// The workers whose answer the current wait needs.
    /// Answers each rank owes (frames in flight it was sent work for).
    pending: Vec<u32>,
}

impl Silence {
    pub(super) fn new(workers: usize, timeout: Duration) -> Silence {
        Silence { timeout, last: vec![Instant::now(); workers + 1], pending: vec![0; workers + 1] }
    }

    /// Starts a wait for answers from `ranks`, counting their silence from now.
    pub(super) fn expect(&mut self, ranks: &[usize]) {
        let now = Instant::now();
        for &r in ranks {
            if self.pending[r] == 0 {
                self.last[r] = now;
            }
            self.pending[r] += 1;
        }
    }

    fn heard(&mut self, rank: usize) {
        if let Some(t) = self.last.get_mut(rank) {
            *t = Instant::now();
        }
    }

    fn answered(&mut self, rank: usize) {
        if let Some(p) = self.pending.get_mut(rank) {
            *p = p.saturating_sub(1);
        }
    }

    /// How many answers `rank` owes.
    fn owes(&self, rank: usize) -> u32 {
        self.pending.get(rank).copied().unwrap_or(0)
    }

    /// How long to wait for the next message, and the worker silent the longest.
    fn next_wait(&self) -> (Duration, usize) {
        let (rank, last) = (1..self.last.len())
            .filter(|&r| self.pending[r] > 0)
            .map(|r| (r, self.last[r]))
            .min_by_key(|&(_, t)| t)
            .unwrap_or((0, Instant::now()));
        (self.timeout.saturating_sub(last.elapsed()), rank)
    }
}

/// Waits for every worker's `Ready`; a `Failed` or silence ends the run with its reason.
pub(super) fn handshake(t: &dyn Transport, timeout: Duration, grid: &TileGrid) -> Result<Vec<String>> {
    let mut adapters = vec![String::new(); t.size()];
    let mut ready = vec![false; t.size()];
    ready[0] = true;
    let mut last = Instant::now();
    while ready.iter().any(|r| !r) {
        let (rank, bytes) = match t.recv(timeout.saturating_sub(last.elapsed())) {
            Ok(m) => m,
            Err(RecvError::Timeout) => {
                bail!("{} did not start within {:.0} s", missing(&ready), timeout.as_secs_f64())
            }
            Err(RecvError::Disconnected) => bail!("{} exited before it was ready", missing(&ready)),
        };
        match ToMaster::decode(&bytes).with_context(|| format!("bad message from rank {rank}"))? {
            // Workers still starting (a device can take seconds to open) say so.
            ToMaster::Heartbeat => last = Instant::now(),
            ToMaster::Ready(protocol::Ready { adapter, max_texture_side }) => {
                if grid.width > max_texture_side || grid.height > max_texture_side {
                    bail!(
                        "the {}x{} frame does not fit rank {rank}'s adapter ({adapter}), whose largest texture side is {max_texture_side}",
                        grid.width,
                        grid.height
                    );
                }
                ready[rank] = true;
                adapters[rank] = format!("rank {rank}: {adapter}");
            }
            ToMaster::Failed(protocol::Failed { reason }) => bail!("rank {rank} failed: {reason}"),
            // A window's input before the first frame: nothing to steer yet.
            ToMaster::Input(_) => {}
            other => bail!("rank {rank} sent {} before it was ready", other.name()),
        }
    }
    Ok(adapters.split_off(1))
}

fn missing(flags: &[bool]) -> String {
    let ranks: Vec<String> = flags.iter().enumerate().filter(|(_, &f)| !f).map(|(r, _)| r.to_string()).collect();
    format!("rank {}", ranks.join(", rank "))
}

/// Pixels that came in for a frame later than the one being composited (with frames in
/// flight, a fast worker answers frame k+1 before a slow one answers frame k), and display
/// ranks' readiness that came in while rank 0 waited for pixels, by view.
#[derive(Default)]
pub(super) struct Early {
    pixels: std::collections::BTreeMap<u32, Vec<Answer>>,
    ready: std::collections::BTreeMap<u32, Vec<Ready>>,
    /// Control commands from display ranks' windows (JSON), for the control channel.
    pub inputs: Vec<String>,
}

/// A display rank's readiness for a view: its displays and when each was assembled (Unix ms).
pub(super) struct Ready {
    pub rank: usize,
    pub displays: Vec<(u32, f64)>,
    /// Its time decoding the view's coded pixels.
    pub decode_ms: f64,
}

/// A worker's answer to a frame: its rank, its tiles' pixels and when it worked on them.
pub(super) struct Answer {
    pub rank: usize,
    pub tiles: Vec<TilePixels>,
    pub span: FrameSpan,
    /// What its progressive mesh held (zeros for other models).
    pub pm: PmMemory,
}

/// The next worker's pixels for `frame`; heartbeats in between keep a busy worker alive, and
/// a worker silent for the whole timeout ends the run.
pub(super) fn receive_pixels(
    t: &dyn Transport,
    frame: u32,
    silence: &mut Silence,
    early: &mut Early,
) -> Result<Answer> {
    receive_until(t, frame, Want::Pixels, silence, early)?;
    Ok(early.pixels.get_mut(&frame).and_then(Vec::pop).expect("received"))
}

/// The next display rank's readiness for `view` (`render --display-ranks`); workers'
/// heartbeats and early pixels in between are kept as [`receive_pixels`] keeps them, and a
/// display rank silent for the whole timeout ends the run.
pub(super) fn receive_ready(t: &dyn Transport, view: u32, silence: &mut Silence, early: &mut Early) -> Result<Ready> {
    receive_until(t, view, Want::Ready, silence, early)?;
    Ok(early.ready.get_mut(&view).and_then(Vec::pop).expect("received"))
}

/// What rank 0 waits for.
#[derive(Clone, Copy, PartialEq)]
enum Want {
    Pixels,
    Ready,
}

/// Receives until `early` holds what `want` asks of `view`, keeping in `early` what comes
/// first: a worker's pixels for this or a later view, a display rank's readiness for any.
fn receive_until(t: &dyn Transport, view: u32, want: Want, silence: &mut Silence, early: &mut Early) -> Result<()> {
    let start = Instant::now();
    loop {
        let held = match want {
            Want::Pixels => early.pixels.get(&view).is_some_and(|v| !v.is_empty()),
            Want::Ready => early.ready.get(&view).is_some_and(|v| !v.is_empty()),
        };
        if held {
            return Ok(());
        }
        let (wait, quiet) = match want {
            Want::Pixels => silence.next_wait(),
            Want::Ready => (silence.timeout.saturating_sub(start.elapsed()), 0),
        };
        let (rank, bytes) = match (t.recv(wait), want) {
            (Ok(m), _) => m,
            (Err(RecvError::Timeout), Want::Pixels) => bail!(
                "rank {quiet} sent nothing for {:.0} s during frame {} (--timeout); counting it as dead",
                silence.timeout.as_secs_f64(),
                view + 1
            ),
            (Err(RecvError::Timeout), Want::Ready) => bail!(
                "no display rank finished view {} for {:.0} s (--timeout); counting it as dead",
                view,
                silence.timeout.as_secs_f64()
            ),
            (Err(RecvError::Disconnected), Want::Pixels) => bail!("the worker exited during frame {}", view + 1),
            (Err(RecvError::Disconnected), Want::Ready) => bail!("a display rank exited during view {view}"),
        };
        silence.heard(rank);
        match ToMaster::decode(&bytes).with_context(|| format!("bad message from rank {rank}"))? {
            ToMaster::Heartbeat => continue,
            ToMaster::Pixels(Pixels { frame: f, tiles, span, pm })
                if (f == view && want == Want::Pixels) || (f > view && silence.owes(rank) > 0) =>
            {
                silence.answered(rank);
                early.pixels.entry(f).or_default().insert(0, Answer { rank, tiles, span, pm });
            }
            ToMaster::DisplayReady(protocol::DisplayReady { view: v, ready, decode_ms }) => {
                early.ready.entry(v).or_default().push(Ready { rank, displays: ready, decode_ms })
            }
            ToMaster::Pixels(Pixels { frame: f, .. }) => match want {
                Want::Pixels => bail!("rank {rank} answered frame {f} during frame {view}"),
                Want::Ready => bail!("rank {rank} answered frame {f} during view {view}'s swap"),
            },
            ToMaster::Failed(protocol::Failed { reason }) => bail!("rank {rank} failed: {reason}"),
            ToMaster::Ready(_) => bail!("rank {rank} sent Ready twice"),
            ToMaster::Input(protocol::Input { json }) => early.inputs.push(json),
        }
    }
}

/// What came while rank 0 was idle (a live run between commands), without waiting: display
/// ranks' window input, kept in `early`; heartbeats; a failure ends the run.
pub(super) fn receive_inputs(t: &dyn Transport, early: &mut Early) -> Result<()> {
    while let Ok((rank, bytes)) = t.recv(Duration::ZERO) {
        match ToMaster::decode(&bytes).with_context(|| format!("bad message from rank {rank}"))? {
            ToMaster::Input(protocol::Input { json }) => early.inputs.push(json),
            ToMaster::Heartbeat => {}
            ToMaster::Failed(protocol::Failed { reason }) => bail!("rank {rank} failed: {reason}"),
            other => bail!("rank {rank} sent {} with no frame in flight", other.name()),
        }
    }
    Ok(())
}
