//! Static canonical Huffman codes over byte symbols and the bit streams of the `.dpm`
//! operations: the "shared probability tables" of section 4.2, stored once in the file, so
//! that every operation is its own byte-aligned bit stream that decodes from its start alone
//! (no adaptive state is carried from one operation to the next).

/// Longest code length; every one of the 256 symbols has a code, so a table built before the
/// final offsets are known still codes every symbol the final pass produces.
pub const MAX_LEN: u8 = 24;

/// One static code table: a code length per byte symbol, and the canonical codes.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    pub lens: [u8; 256],
    codes: [u32; 256],
    /// Per length `l` (index `l`): the first canonical code of that length, how many codes
    /// have it, and where its symbols start in `sorted`.
    first: [u32; MAX_LEN as usize + 1],
    count: [u32; MAX_LEN as usize + 1],
    offset: [u32; MAX_LEN as usize + 1],
    sorted: Vec<u8>,
}

impl Table {
    /// The code for these symbol counts (every symbol gets at least a count of one).
    pub fn from_counts(counts: &[u64; 256]) -> Table {
        let mut freq: Vec<u64> = counts.iter().map(|&c| c + 1).collect();
        loop {
            let lens = huffman_lengths(&freq);
            if lens.iter().all(|&l| l <= MAX_LEN) {
                return Table::from_lens(lens).expect("valid lengths");
            }
            // Flatten the distribution until the longest code fits.
            for f in &mut freq {
                *f = (*f >> 1) + 1;
            }
        }
    }

    /// The canonical code for these lengths, if they form a complete prefix code.
    pub fn from_lens(lens: [u8; 256]) -> Option<Table> {
        let mut count = [0u32; MAX_LEN as usize + 1];
        for &l in &lens {
            if l == 0 || l > MAX_LEN {
                return None;
            }
            count[l as usize] += 1;
        }
        // Kraft equality: exactly complete.
        let kraft: u64 = (1..=MAX_LEN as usize).map(|l| (count[l] as u64) << (MAX_LEN as usize - l)).sum();
        if kraft != 1u64 << MAX_LEN {
            return None;
        }
        let mut first = [0u32; MAX_LEN as usize + 1];
        let mut offset = [0u32; MAX_LEN as usize + 1];
        let mut code = 0u32;
        let mut off = 0u32;
        for l in 1..=MAX_LEN as usize {
            code = (code + if l > 1 { count[l - 1] } else { 0 }) << if l > 1 { 1 } else { 0 };
            first[l] = code;
            offset[l] = off;
            off += count[l];
        }
        let mut sorted: Vec<u8> = (0..=255u8).collect();
        sorted.sort_by_key(|&s| (lens[s as usize], s));
        let mut codes = [0u32; 256];
        let mut next = first;
        for &s in &sorted {
            let l = lens[s as usize] as usize;
            codes[s as usize] = next[l];
            next[l] += 1;
        }
        Some(Table { lens, codes, first, count, offset, sorted })
    }

    pub fn encode(&self, w: &mut BitWriter, sym: u8) {
        w.put(self.codes[sym as usize], self.lens[sym as usize]);
    }

    /// The next symbol, or `None` past the end of the data.
    pub fn decode(&self, r: &mut BitReader) -> Option<u8> {
        let mut code = 0u32;
        for l in 1..=MAX_LEN as usize {
            code = (code << 1) | r.bit()? as u32;
            let d = code.wrapping_sub(self.first[l]);
            if code >= self.first[l] && d < self.count[l] {
                return Some(self.sorted[(self.offset[l] + d) as usize]);
            }
        }
        None // unreachable for a complete code
    }
}

/// Huffman code lengths for positive frequencies (two-queue construction).
fn huffman_lengths(freq: &[u64]) -> [u8; 256] {
    let n = freq.len();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| freq[i]);
    // Nodes: leaves 0..n, inner n..2n-1; parent links.
    let mut weight: Vec<u64> = order.iter().map(|&i| freq[i]).collect();
    let mut parent = vec![usize::MAX; 2 * n - 1];
    let (mut leaf, mut inner) = (0usize, n);
    let take = |weight: &[u64], leaf: &mut usize, inner: &mut usize, made: usize| -> usize {
        if *leaf < n && (*inner >= made || weight[*leaf] <= weight[*inner]) {
            *leaf += 1;
            *leaf - 1
        } else {
            *inner += 1;
            *inner - 1
        }
    };
    for made in n..2 * n - 1 {
        let a = take(&weight, &mut leaf, &mut inner, made);
        let b = take(&weight, &mut leaf, &mut inner, made);
        weight.push(weight[a] + weight[b]);
        parent[a] = made;
        parent[b] = made;
    }
    let mut depth = vec![0u32; 2 * n - 1];
    for i in (0..2 * n - 2).rev() {
        depth[i] = depth[parent[i]] + 1;
    }
    let mut lens = [0u8; 256];
    for (k, &i) in order.iter().enumerate() {
        lens[i] = depth[k].min(255) as u8;
    }
    lens
}

/// MSB-first bit writer; [`Self::finish`] pads the last byte with zeros.
#[derive(Default)]
pub struct BitWriter {
    bytes: Vec<u8>,
    acc: u64,
    nbits: u32,
}

impl BitWriter {
    pub fn put(&mut self, code: u32, len: u8) {
        self.acc = (self.acc << len) | code as u64;
        self.nbits += len as u32;
        while self.nbits >= 8 {
            self.nbits -= 8;
            self.bytes.push((self.acc >> self.nbits) as u8);
        }
        self.acc &= (1u64 << self.nbits) - 1;
    }

    pub fn finish(mut self) -> Vec<u8> {
        if self.nbits > 0 {
            self.bytes.push((self.acc << (8 - self.nbits)) as u8);
        }
        self.bytes
    }
}

/// MSB-first bit reader over a byte slice from a starting byte.
pub struct BitReader<'a> {
    data: &'a [u8],
    pos: usize,
    bit: u32,
    /// Bits read so far.
    pub read: u64,
}

impl<'a> BitReader<'a> {
    pub fn new(data: &'a [u8], start: usize) -> Self {
        BitReader { data, pos: start, bit: 0, read: 0 }
    }

    pub fn bit(&mut self) -> Option<bool> {
        let byte = *self.data.get(self.pos)?;
        let b = (byte >> (7 - self.bit)) & 1 == 1;
        self.bit += 1;
        if self.bit == 8 {
            self.bit = 0;
            self.pos += 1;
        }
        self.read += 1;
        Some(b)
    }

    /// The byte just past the last one touched (the end of a byte-aligned stream).
    pub fn end(&self) -> usize {
        self.pos + (self.bit > 0) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip() {
        let mut counts = [0u64; 256];
        for (i, c) in counts.iter_mut().enumerate() {
            *c = if i < 4 { 1_000_000 >> i } else { (i % 7) as u64 };
        }
        let t = Table::from_counts(&counts);
        assert_eq!(Table::from_lens(t.lens).unwrap(), t);
        let mut w = BitWriter::default();
        for s in 0..=255u8 {
            t.encode(&mut w, s);
        }
        let bytes = w.finish();
        let mut r = BitReader::new(&bytes, 0);
        for s in 0..=255u8 {
            assert_eq!(t.decode(&mut r), Some(s));
        }
    }
}
