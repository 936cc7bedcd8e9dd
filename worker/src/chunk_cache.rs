//! The verbatim chunks a worker keeps between frames (chunked `.bft` models), least recently
//! used out first, within a bound in bytes.
//!
//! The master keeps a mirror of every worker's cache (the same type with `()` values) and
//! applies the same operations in the same order as the worker will: at the start of a frame
//! [`ChunkCache::set_limit`] with the frame's bound, then for each of the worker's tiles in
//! message order, for each verbatim chunk, [`ChunkCache::get`] if the mirror holds it (the
//! message names the chunk only) or else [`ChunkCache::insert`] (the message carries its
//! bytes). Both caches therefore hold the same chunks after every step, and the master never
//! names a chunk the worker has dropped, without any message telling it what was dropped.
//! A chunk's cost is what the worker keeps of it: its compressed stream and its border
//! normals (`node::kept_cost`), which the master knows from the message it sends.

use std::collections::HashMap;

/// A chunk cache bounded in bytes, least recently used out first.
#[derive(Debug)]
pub struct ChunkCache<V> {
    limit: u64,
    used: u64,
    clock: u64,
    entries: HashMap<u32, Entry<V>>,
}

#[derive(Debug)]
struct Entry<V> {
    value: V,
    cost: u64,
    last: u64,
}

impl<V> Default for ChunkCache<V> {
    fn default() -> Self {
        ChunkCache { limit: 0, used: 0, clock: 0, entries: HashMap::new() }
    }
}

impl<V> ChunkCache<V> {
    /// Sets the bound, dropping the least recently used chunks until the cache fits it.
    pub fn set_limit(&mut self, limit: u64) {
        self.limit = limit;
        self.evict();
    }

    /// Bytes held.
    pub fn used(&self) -> u64 {
        self.used
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The chunk, if held, which becomes the most recently used.
    pub fn get(&mut self, chunk: u32) -> Option<&V> {
        self.clock += 1;
        let now = self.clock;
        self.entries.get_mut(&chunk).map(|e| {
            e.last = now;
            &e.value
        })
    }

    /// Keeps a chunk as the most recently used, then drops the least recently used others
    /// until the cache fits its bound. A chunk larger than the bound is not kept.
    pub fn insert(&mut self, chunk: u32, cost: u64, value: V) {
        self.clock += 1;
        if cost > self.limit {
            return;
        }
        if let Some(old) = self.entries.insert(chunk, Entry { value, cost, last: self.clock }) {
            self.used -= old.cost;
        }
        self.used += cost;
        self.evict();
    }

    fn evict(&mut self) {
        while self.used > self.limit {
            let (&victim, _) = self.entries.iter().min_by_key(|(_, e)| e.last).expect("over the bound, so not empty");
            let e = self.entries.remove(&victim).expect("present");
            self.used -= e.cost;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_recently_used_goes_first_and_the_bound_holds() {
        let mut c = ChunkCache::default();
        c.set_limit(100);
        c.insert(1, 40, 'a');
        c.insert(2, 40, 'b');
        assert_eq!(c.get(1), Some(&'a'));
        c.insert(3, 40, 'c'); // 2 is the least recently used
        assert_eq!(c.get(2), None);
        assert_eq!(c.get(1), Some(&'a'));
        assert_eq!(c.get(3), Some(&'c'));
        assert_eq!(c.used(), 80);
        c.insert(4, 101, 'd'); // larger than the bound: not kept, nothing dropped
        assert_eq!(c.get(4), None);
        assert_eq!(c.len(), 2);
        c.set_limit(50); // 1 was used before 3
        assert_eq!(c.get(1), None);
        assert_eq!(c.get(3), Some(&'c'));
        assert!(c.used() <= 50);
    }

    /// A mirror fed the same operations holds the same chunks, whatever the sequence.
    #[test]
    fn a_mirror_agrees_with_the_cache() {
        let mut rng = 0x2545F4914F6CDD1Du64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            rng
        };
        let (mut worker, mut master) = (ChunkCache::<String>::default(), ChunkCache::<()>::default());
        for frame in 0..200 {
            let limit = 500 + next() % 2000;
            worker.set_limit(limit);
            master.set_limit(limit);
            for _ in 0..next() % 20 {
                let (chunk, cost) = ((next() % 50) as u32, 1 + next() % 400);
                if master.get(chunk).is_some() {
                    assert!(worker.get(chunk).is_some(), "frame {frame}: the worker lost chunk {chunk}");
                } else {
                    master.insert(chunk, cost, ());
                    worker.insert(chunk, cost, format!("{chunk}"));
                }
                assert_eq!(master.used(), worker.used());
                assert!(worker.used() <= limit);
            }
        }
    }
}
