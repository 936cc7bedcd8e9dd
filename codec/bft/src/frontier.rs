//! The BFT frontier: the queue of slots whose transitions are documented in [`super`].
//! Encoder, decoder and tile sort all change it through these methods only, so the three
//! cannot disagree on the semantics.

/// No slot (an unknown apex, a missing vertex).
pub const NONE: u32 = u32::MAX;

/// One frontier position: a slot, and the apex of the triangle across the edge from this
/// entry to the next one (used for parallelogram prediction), or [`NONE`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    pub slot: u32,
    pub apex: u32,
}

/// The frontier as a queue with stable absolute positions: entries are only pushed at the
/// back, the front advances, and `RF0`/`DR` rewrite the second entry in place. Absolute
/// positions let the encoder keep per-vertex chains of entries.
#[derive(Clone, Debug, Default)]
pub struct Frontier {
    pub entries: Vec<Entry>,
    pub head: usize,
}

impl Frontier {
    #[inline]
    pub fn len(&self) -> usize {
        self.entries.len() - self.head
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The entry at queue position `i` (0 is the left vertex of the current edge).
    #[inline]
    pub fn at(&self, i: usize) -> Entry {
        self.entries[self.head + i]
    }

    #[inline]
    pub fn back_pos(&self) -> usize {
        self.entries.len()
    }

    #[inline]
    fn push(&mut self, slot: u32, apex: u32) {
        self.entries.push(Entry { slot, apex });
    }

    /// `NEW`, `RF<k>`, `LF<k>`: pop `l`, push `l` and `x`. Needs `len >= 2`.
    #[inline]
    pub fn insert(&mut self, x: u32) {
        let l = self.entries[self.head].slot;
        let r = self.entries[self.head + 1].slot;
        self.head += 1;
        self.push(l, r);
        self.push(x, l);
    }

    /// `RF0` and `DR`: remove `r`; `l` stays at the front. `RF0` records the apex `r` of its
    /// triangle on the new edge `l -> Q[2]`; `DR` leaves that edge without an apex.
    #[inline]
    pub fn remove_right(&mut self, closing: bool) {
        let l = self.entries[self.head].slot;
        let r = self.entries[self.head + 1].slot;
        self.head += 1;
        self.entries[self.head] = Entry { slot: l, apex: if closing { r } else { NONE } };
    }

    /// `LF0` and `DL`: pop `l`. `LF0` records its apex `l` on the new edge `Q[last] -> r`.
    #[inline]
    pub fn remove_left(&mut self, closing: bool) {
        let l = self.entries[self.head].slot;
        self.head += 1;
        if closing {
            self.entries.last_mut().expect("LF0 needs three entries").apex = l;
        }
    }

    /// `NULL`: move `l` to the back, keeping the edge `l -> r` and its apex.
    #[inline]
    pub fn skip(&mut self) {
        let e = self.entries[self.head];
        self.head += 1;
        self.entries.push(e);
    }

    /// `ADD`: push `x` with no triangle.
    #[inline]
    pub fn add(&mut self, x: u32) {
        self.push(x, NONE);
    }

    /// `SEED`: clear, then queue the new triangle `(s, s+2, s+1)` as `[s, s+1, s+2]`.
    pub fn seed(&mut self, s: u32) {
        self.clear();
        self.push(s, s + 2);
        self.push(s + 1, s);
        self.push(s + 2, s + 1);
    }

    pub fn clear(&mut self) {
        self.head = self.entries.len();
    }

    /// Drops the consumed prefix once it is most of the buffer, so the frontier's memory
    /// stays proportional to its length, not to the stream's (the live frontier of the
    /// dragon is thousands of entries; the pushes are millions). Positions shift down by
    /// the returned count, so only callers that keep no positions, or shift their own,
    /// may call it.
    #[inline]
    pub fn compact(&mut self) -> usize {
        let h = self.head;
        if h < 4096 || h * 2 < self.entries.len() {
            return 0;
        }
        self.entries.drain(..h);
        self.head = 0;
        h
    }
}
