//! How ranks exchange protocol messages: MPI under `mpirun`, or in-process channels when
//! the binary runs alone (the master and one worker thread). Both carry the same bytes.

use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::*;

/// A receive that did not deliver.
#[derive(Debug, PartialEq)]
pub enum RecvError {
    /// Nothing arrived before the deadline.
    Timeout,
    /// The other side is gone (only channels can tell).
    Disconnected,
}

/// Sends one message to a fixed rank from any thread ([`Transport::sender`]).
pub type SendFn = Box<dyn Fn(&[u8]) + Send>;

/// A send that its receiver did not take while it stayed silent for the whole timeout (a
/// stopped or hung rank: a live one sends heartbeats while it works).
#[derive(Debug, PartialEq)]
pub struct Stalled {
    /// The rank that took nothing.
    pub rank: usize,
}

/// A timeout for sends whose receiver is trusted to be waiting (a worker's pixels to rank 0).
pub const NO_TIMEOUT: Duration = Duration::from_secs(1 << 40);

/// Point-to-point messaging between ranks.
pub trait Transport {
    fn rank(&self) -> usize;
    fn size(&self) -> usize;
    fn send(&self, to: usize, msg: &[u8]);
    /// Sends each `(rank, message)`, all in flight at once, and waits for them; gives up on a
    /// rank that takes nothing and says nothing for `timeout` (the job is then to end: the
    /// messages may stay with MPI).
    fn send_many(&self, msgs: Vec<(usize, Vec<u8>)>, timeout: Duration) -> Result<(), Stalled>;
    /// The next message from any rank, as `(source, bytes)`.
    fn recv(&self, timeout: Duration) -> Result<(usize, Vec<u8>), RecvError>;
    /// Ends every rank of the job with a non-zero status.
    fn abort(&self, code: i32) -> !;
    /// A handle that sends to rank `to` from another thread (a worker's heartbeat).
    fn sender(&self, to: usize) -> SendFn;
}

/// Whether this process was started by an MPI launcher (Open MPI, MPICH/Hydra, PMIx).
pub fn launched_by_mpirun() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "PMI_RANK"].iter().any(|v| std::env::var_os(v).is_some())
}

/// MPI's `COMM_WORLD`. Dropping it finalizes MPI.
///
/// MPI is initialized at `MPI_THREAD_SERIALIZED`: a worker's heartbeat thread sends while its
/// main thread renders, and every MPI call of the process takes `MPI_CALLS` first, so no
/// two threads are ever inside MPI at once.
pub struct Mpi {
    world: SimpleCommunicator,
    /// How many ranks of the job share this rank's node (`MPI_Comm_split_type` with
    /// `MPI_COMM_TYPE_SHARED`).
    ranks_on_node: usize,
    _universe: mpi::environment::Universe,
    /// Messages received while [`Transport::send_many`] waited for its sends to complete,
    /// handed out by [`Transport::recv`] first.
    stash: Mutex<std::collections::VecDeque<(usize, Vec<u8>)>>,
}

/// Held around every MPI call (see [`Mpi`]).
static MPI_CALLS: Mutex<()> = Mutex::new(());

fn mpi_lock() -> std::sync::MutexGuard<'static, ()> {
    MPI_CALLS.lock().unwrap_or_else(|e| e.into_inner())
}

impl Mpi {
    /// A message waiting from any rank, received; the caller holds the MPI lock.
    fn try_receive(&self) -> Option<(usize, Vec<u8>)> {
        let probed = self.world.any_process().immediate_matched_probe()?;
        let (bytes, status) = probed.matched_receive_vec::<u8>();
        Some((status.source_rank() as usize, bytes))
    }

    /// Initializes MPI; `None` if it was already initialized or the library cannot serialize
    /// calls from several threads.
    pub fn init() -> Option<Mpi> {
        use mpi::environment::Threading;
        let (universe, level) = mpi::initialize_with_threading(Threading::Serialized)?;
        if !matches!(level, Threading::Serialized | Threading::Multiple) {
            return None;
        }
        let world = universe.world();
        let ranks_on_node = world.split_shared(world.rank()).size().max(1) as usize;
        Some(Mpi { world, ranks_on_node, _universe: universe, stash: Mutex::new(Default::default()) })
    }

    /// How many ranks of the job run on this rank's node, this one included.
    pub fn ranks_on_node(&self) -> usize {
        self.ranks_on_node
    }
}

impl Transport for Mpi {
    fn rank(&self) -> usize {
        self.world.rank() as usize
    }

    fn size(&self) -> usize {
        self.world.size() as usize
    }

    fn send(&self, to: usize, msg: &[u8]) {
        let _calls = mpi_lock();
        self.world.process_at_rank(to as i32).send(msg);
    }

    /// Posts every send, then receives whatever arrives until they have all completed: with
    /// frames in flight, rank 0 sends frame k+1's tiles to a worker that is itself sending
    /// frame k's pixels, and two large sends facing each other would wait for each other's
    /// receive for ever. What is received meanwhile waits in the stash for [`Transport::recv`].
    /// A rank whose send has not completed and from which nothing has arrived for `timeout`
    /// is [`Stalled`]: its request is left with MPI and the messages are leaked, since MPI
    /// may still read them until the job ends.
    fn send_many(&self, msgs: Vec<(usize, Vec<u8>)>, timeout: Duration) -> Result<(), Stalled> {
        let _calls = mpi_lock();
        let start = Instant::now();
        let mut heard: std::collections::HashMap<usize, Instant> = Default::default();
        let stalled = mpi::request::scope(|scope| {
            let mut pending: Vec<_> = msgs
                .iter()
                .map(|(to, m)| Some((*to, self.world.process_at_rank(*to as i32).immediate_send(scope, &m[..]))))
                .collect();
            let mut spins = 0u32;
            loop {
                let mut left = false;
                for slot in pending.iter_mut() {
                    if let Some((to, r)) = slot.take() {
                        if let Err(r) = r.test() {
                            *slot = Some((to, r));
                            left = true;
                        }
                    }
                }
                if !left {
                    return None;
                }
                if let Some(m) = self.try_receive() {
                    heard.insert(m.0, Instant::now());
                    self.stash.lock().unwrap_or_else(|e| e.into_inner()).push_back(m);
                    spins = 0;
                    continue;
                }
                let silent = pending
                    .iter()
                    .flatten()
                    .map(|(to, _)| *to)
                    .find(|to| heard.get(to).copied().unwrap_or(start).elapsed() >= timeout);
                if let Some(rank) = silent {
                    for (_, r) in pending.into_iter().flatten() {
                        // Safety: the request stays with MPI, and its buffer (in `msgs`) is
                        // leaked below, so it outlives the request.
                        let _ = unsafe { r.into_raw() };
                    }
                    return Some(rank);
                }
                spins += 1;
                if spins > 1000 {
                    std::thread::sleep(Duration::from_micros(50));
                }
            }
        });
        match stalled {
            None => Ok(()),
            Some(rank) => {
                std::mem::forget(msgs);
                Err(Stalled { rank })
            }
        }
    }

    fn recv(&self, timeout: Duration) -> Result<(usize, Vec<u8>), RecvError> {
        // MPI has no receive with a deadline: probe, and sleep briefly between probes.
        let deadline =
            Instant::now().checked_add(timeout).unwrap_or_else(|| Instant::now() + Duration::from_secs(1 << 40));
        if let Some(m) = self.stash.lock().unwrap_or_else(|e| e.into_inner()).pop_front() {
            return Ok(m);
        }
        let (start, mut spins) = (Instant::now(), 0u32);
        loop {
            {
                let _calls = mpi_lock();
                if let Some(m) = self.try_receive() {
                    return Ok(m);
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(RecvError::Timeout);
            }
            spins += 1;
            if spins > 1000 {
                // The longer the wait, the longer the nap: at most 5% of the time waited so far
                // is added to it (from 200 us, up to 5 ms), so that an idle rank (a still live
                // view) probes 200 times a second, not 5,000 (0.80 CPU s over 5 idle s for
                // mpirun -np 3, measured, with 200 us naps).
                let nap = ((now - start) / 20).clamp(Duration::from_micros(200), Duration::from_millis(5));
                std::thread::sleep(nap);
            }
        }
    }

    fn abort(&self, code: i32) -> ! {
        // Not under the lock: aborting must not wait for a call in flight on another thread.
        self.world.abort(code)
    }

    fn sender(&self, to: usize) -> SendFn {
        Box::new(move |msg| {
            let _calls = mpi_lock();
            SimpleCommunicator::world().process_at_rank(to as i32).send(msg);
        })
    }
}

/// A message in a channel: the sender's rank and the bytes.
type Envelope = (usize, Vec<u8>);

/// One endpoint of a set of in-process channels.
pub struct Local {
    rank: usize,
    /// Senders to the other endpoints' inboxes; none to our own, so that our inbox reports
    /// `Disconnected` once every other endpoint is dropped.
    peers: Vec<Option<Sender<Envelope>>>,
    inbox: Receiver<Envelope>,
}

/// `n` fully connected in-process endpoints, ranks `0..n`.
pub fn local_ranks(n: usize) -> Vec<Local> {
    let (senders, receivers): (Vec<_>, Vec<_>) = (0..n).map(|_| channel()).unzip();
    receivers
        .into_iter()
        .enumerate()
        .map(|(rank, inbox)| {
            let peers = senders.iter().enumerate().map(|(r, s)| (r != rank).then(|| s.clone())).collect();
            Local { rank, peers, inbox }
        })
        .collect()
}

impl Transport for Local {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.peers.len()
    }

    fn send(&self, to: usize, msg: &[u8]) {
        // A peer that has exited drops its inbox; the receive side reports that.
        if let Some(peer) = &self.peers[to] {
            let _ = peer.send((self.rank, msg.to_vec()));
        }
    }

    fn send_many(&self, msgs: Vec<(usize, Vec<u8>)>, _timeout: Duration) -> Result<(), Stalled> {
        // Channels never block a sender.
        for (to, m) in &msgs {
            self.send(*to, m);
        }
        Ok(())
    }

    fn recv(&self, timeout: Duration) -> Result<(usize, Vec<u8>), RecvError> {
        self.inbox.recv_timeout(timeout).map_err(|e| match e {
            RecvTimeoutError::Timeout => RecvError::Timeout,
            RecvTimeoutError::Disconnected => RecvError::Disconnected,
        })
    }

    fn abort(&self, code: i32) -> ! {
        std::process::exit(code)
    }

    fn sender(&self, to: usize) -> SendFn {
        let (peer, rank) = (self.peers[to].clone(), self.rank);
        Box::new(move |msg| {
            if let Some(p) = &peer {
                let _ = p.send((rank, msg.to_vec()));
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_ranks_exchange_messages() {
        let mut ranks = local_ranks(3);
        let (r2, r1, r0) = (ranks.pop().unwrap(), ranks.pop().unwrap(), ranks.pop().unwrap());
        r0.send_many(vec![(1, vec![1]), (2, vec![2, 2])], NO_TIMEOUT).unwrap();
        assert_eq!(r1.recv(Duration::from_secs(1)), Ok((0, vec![1])));
        assert_eq!(r2.recv(Duration::from_secs(1)), Ok((0, vec![2, 2])));
        r2.send(0, &[7]);
        assert_eq!(r0.recv(Duration::from_secs(1)), Ok((2, vec![7])));
        assert_eq!(r0.recv(Duration::from_millis(10)), Err(RecvError::Timeout));
        // Once the others are gone, a receive says so instead of waiting.
        drop((r1, r2));
        assert_eq!(r0.recv(Duration::from_secs(60)), Err(RecvError::Disconnected));
    }
}
