//! Out-of-core memory management of section 5.7: the nodes of an out-of-core `.dpm` file kept
//! in memory within a budget, chosen by the paper's priority `p = d_n / d_v`
//! ([`NodeInfo::priority`]) and read by a second thread.
//!
//! Every frame [`NodeCache::schedule`] ranks the nodes by priority for the view: the nodes of
//! priority at least 1 are required (only they can hold an operation the view asks for), and,
//! as the paper does against the delay of loading, nodes of lower priority are kept or loaded
//! too while the budget has room. Resident nodes outside the budget's best are evicted when
//! space is needed, that is when a wanted node arrives; a node that arrives no longer wanted
//! is dropped, so the resident nodes never exceed the budget (a pool of GPU slots relies on
//! it). Loads are asked of the loader thread in priority order; what it has read
//! is installed by [`NodeCache::install`] (the adaptation never waits for the disk: a vertex
//! whose operation is in a node not yet loaded just does not split yet). Evicting a node is
//! always safe: collapses need no decoding (their operations' criteria are in the vertices'
//! state), and an operation is decoded only from a resident node.

use std::collections::{HashMap, HashSet};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use super::format::{DecodedOp, Dpm, DpmError, NodeFile, NodeInfo, OpContext, NODE_BYTES};
use super::Viewpoint;

/// What a cache did in one [`NodeCache::schedule`] and [`NodeCache::install`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CacheStats {
    /// Nodes of priority at least 1 for the view, and how many of them are resident.
    pub required: usize,
    pub required_resident: usize,
    /// Nodes and bytes resident.
    pub resident: usize,
    pub resident_bytes: u64,
    /// Nodes and bytes installed since the last report, and evicted.
    pub loaded: usize,
    pub loaded_bytes: u64,
    pub evicted: usize,
    /// Nodes read but no longer wanted when they arrived (the view moved on), not installed.
    pub discarded: usize,
}

/// The nodes of an out-of-core file in memory (see the module docs).
pub struct NodeCache {
    nodes: Vec<NodeInfo>,
    resident: HashMap<u32, Arc<[u8]>>,
    budget: u64,
    /// What a node costs of the budget: its length, or a fixed slot size (a GPU pool of
    /// slots, [`NodeCache::with_slots`]).
    slot_bytes: Option<u64>,
    /// What the resident nodes cost of the budget.
    used: u64,
    /// The nodes the last schedule wants resident (they fit the budget), and every node's
    /// place in its priority order.
    wanted: HashSet<u32>,
    rank: Vec<u32>,
    /// Nodes asked of the loader and not yet installed.
    in_flight: HashSet<u32>,
    loader: Loader,
    stats: CacheStats,
}

/// A node the loader thread read, or why it could not.
type Loaded = (u32, Result<Vec<u8>, DpmError>);

enum Loader {
    /// Reads in [`NodeCache::schedule`] (tests, tools that want every frame converged).
    Inline(Arc<NodeFile>),
    /// A second thread reads; requests go out in priority order.
    Thread {
        requests: Option<Sender<u32>>,
        /// In a mutex only so that the cache can be shared with the adaptation's threads.
        done: Mutex<Receiver<Loaded>>,
        handle: Option<JoinHandle<()>>,
    },
}

impl NodeCache {
    /// A cache of at most `budget` bytes of nodes of `file` (whose node table `dpm` holds),
    /// read by a thread of its own when `background`, else while scheduling.
    pub fn new(dpm: &Dpm, file: Arc<NodeFile>, budget: u64, background: bool) -> NodeCache {
        Self::make(dpm, file, budget, None, background)
    }

    /// A cache of at most `slots` nodes, each taking a slot of `slot_bytes` whatever its
    /// length (what a pool of fixed slots in graphics memory holds).
    pub fn with_slots(dpm: &Dpm, file: Arc<NodeFile>, slots: u64, slot_bytes: u64, background: bool) -> NodeCache {
        Self::make(dpm, file, slots * slot_bytes, Some(slot_bytes), background)
    }

    fn make(dpm: &Dpm, file: Arc<NodeFile>, budget: u64, slot_bytes: Option<u64>, background: bool) -> NodeCache {
        let loader = if background {
            let (requests, rx) = channel::<u32>();
            let (tx, done) = channel();
            let handle = std::thread::Builder::new()
                .name("dpm node loader".into())
                .spawn(move || {
                    for i in rx {
                        if tx.send((i, file.read_node(i))).is_err() {
                            break;
                        }
                    }
                })
                .expect("spawning the node loader thread");
            Loader::Thread { requests: Some(requests), done: Mutex::new(done), handle: Some(handle) }
        } else {
            Loader::Inline(file)
        };
        NodeCache {
            nodes: dpm.nodes.clone(),
            resident: HashMap::new(),
            budget,
            slot_bytes,
            used: 0,
            wanted: HashSet::new(),
            rank: vec![0; dpm.nodes.len()],
            in_flight: HashSet::new(),
            loader,
            stats: CacheStats::default(),
        }
    }

    /// The bytes of node `i`, if resident.
    pub fn get(&self, i: u32) -> Option<&[u8]> {
        self.resident.get(&i).map(|b| &b[..])
    }

    /// The resident nodes, in no particular order.
    pub fn resident_nodes(&self) -> impl Iterator<Item = u32> + '_ {
        self.resident.keys().copied()
    }

    /// Nodes asked of the loader thread and not installed yet.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// What node `i` costs of the budget.
    fn cost(&self, i: u32) -> u64 {
        self.slot_bytes.unwrap_or(self.nodes[i as usize].len as u64)
    }

    /// Decodes the operation at `addr` of `dpm` if its node is resident.
    pub fn decode(&self, dpm: &Dpm, addr: usize, ctx: &OpContext) -> Result<Option<DecodedOp>, DpmError> {
        self.get((addr / NODE_BYTES) as u32).map(|b| dpm.decode_in(b, addr, ctx)).transpose()
    }

    /// Ranks the nodes for `view`, evicts what falls outside the budget where space is needed,
    /// and asks for the missing ones in priority order (inline: reads them now). Returns the
    /// stats of this frame (loads counted since the last call).
    pub fn schedule(&mut self, view: &Viewpoint) -> Result<CacheStats, DpmError> {
        self.schedule_culled(view, &|_| false)
    }

    /// [`Self::schedule`], the nodes `hidden` says were occluded (in the frame before: the
    /// paper culls nodes one frame late) ranked last, as no view needs them.
    pub fn schedule_culled(
        &mut self,
        view: &Viewpoint,
        hidden: &dyn Fn(&NodeInfo) -> bool,
    ) -> Result<CacheStats, DpmError> {
        let planes = view.planes();
        let priority: Vec<f32> =
            self.nodes.iter().map(|n| if hidden(n) { 0.0 } else { n.priority(view, &planes) }).collect();
        let mut order: Vec<u32> = (0..self.nodes.len() as u32).collect();
        order.sort_by(|&a, &b| priority[b as usize].total_cmp(&priority[a as usize]).then(a.cmp(&b)));
        // The best nodes that fit the budget, required ones first (the order has them first).
        let mut wanted = HashSet::new();
        let mut room = self.budget;
        for &i in &order {
            let len = self.cost(i);
            if len > room {
                if priority[i as usize] >= 1.0 {
                    continue;
                }
                break;
            }
            room -= len;
            wanted.insert(i);
        }
        // Evicting waits until a wanted node arrives and needs the space (`put`).
        for (k, &i) in order.iter().enumerate() {
            self.rank[i as usize] = k as u32;
        }
        self.wanted = wanted;
        for &i in &order {
            if !self.wanted.contains(&i) || self.resident.contains_key(&i) || self.in_flight.contains(&i) {
                continue;
            }
            match &self.loader {
                Loader::Inline(file) => {
                    let bytes = file.read_node(i)?;
                    self.put(i, bytes);
                }
                Loader::Thread { requests, .. } => {
                    if let Some(r) = requests {
                        let _ = r.send(i);
                    }
                    self.in_flight.insert(i);
                }
            }
        }
        let required: Vec<u32> = order.iter().copied().filter(|&i| priority[i as usize] >= 1.0).collect();
        self.stats.required = required.len();
        self.stats.required_resident = required.iter().filter(|i| self.resident.contains_key(i)).count();
        Ok(self.take_stats())
    }

    /// Installs what the loader thread has read so far (nothing inline); an error names the
    /// node that could not be read or failed its checksum.
    pub fn install(&mut self) -> Result<usize, DpmError> {
        let mut got = vec![];
        if let Loader::Thread { done, .. } = &self.loader {
            let done = done.lock().expect("the loader's channel");
            while let Ok(r) = done.try_recv() {
                got.push(r);
            }
        }
        let n = got.len();
        for (i, bytes) in got {
            self.in_flight.remove(&i);
            self.put(i, bytes?);
        }
        Ok(n)
    }

    /// Waits for every load asked for (tools and tests that want a frame converged).
    pub fn wait(&mut self) -> Result<(), DpmError> {
        while !self.in_flight.is_empty() {
            let Loader::Thread { done, .. } = &self.loader else { break };
            let got = done.lock().expect("the loader's channel").recv();
            let (i, bytes) = got.map_err(|_| DpmError::Io("the node loader thread stopped".into()))?;
            self.in_flight.remove(&i);
            self.put(i, bytes?);
        }
        Ok(())
    }

    /// Installs node `i` if the last schedule still wants it, evicting the resident nodes it
    /// does not want, worst first, as far as the space is needed. The wanted nodes fit the
    /// budget together, so the resident ones always do.
    fn put(&mut self, i: u32, bytes: Vec<u8>) {
        if !self.wanted.contains(&i) {
            self.stats.discarded += 1;
            return;
        }
        let cost = self.cost(i);
        while self.used + cost > self.budget {
            let worst = self
                .resident
                .keys()
                .copied()
                .filter(|j| !self.wanted.contains(j))
                .max_by_key(|&j| self.rank[j as usize]);
            let Some(j) = worst else { break };
            self.resident.remove(&j);
            self.used -= self.cost(j);
            self.stats.evicted += 1;
        }
        self.used += cost;
        self.stats.loaded += 1;
        self.stats.loaded_bytes += bytes.len() as u64;
        self.resident.insert(i, bytes.into());
    }

    fn take_stats(&mut self) -> CacheStats {
        self.stats.resident = self.resident.len();
        self.stats.resident_bytes = self.resident.values().map(|b| b.len() as u64).sum();
        let s = self.stats;
        self.stats.loaded = 0;
        self.stats.loaded_bytes = 0;
        self.stats.evicted = 0;
        self.stats.discarded = 0;
        s
    }
}

impl Drop for NodeCache {
    fn drop(&mut self) {
        if let Loader::Thread { requests, handle, .. } = &mut self.loader {
            requests.take();
            if let Some(h) = handle.take() {
                let _ = h.join();
            }
        }
    }
}
