//! Static canonical Huffman codes over byte symbols, and MSB-first bit streams. Two formats
//! use them: the `.dpm` operations (the "shared probability tables" of the PM paper's
//! section 4.2, stored once in the file, so that every operation decodes from its start
//! alone) and the prefix-coded tile streams of `.bft` (a table per context, per tile).

/// Longest code length a table may have.
pub const MAX_LEN: u8 = 24;

/// One static code table over symbols `0..lens.len()` (at most 256): a code length per
/// symbol, 0 for a symbol without a code, and the canonical codes.
#[derive(Clone, Debug)]
pub struct Table {
    pub lens: Vec<u8>,
    codes: Vec<u32>,
    /// Per length `l` (index `l`): the first canonical code of that length, how many codes
    /// have it, and where its symbols start in `sorted`.
    first: [u32; MAX_LEN as usize + 1],
    count: [u32; MAX_LEN as usize + 1],
    offset: [u32; MAX_LEN as usize + 1],
    sorted: Vec<u8>,
    /// The longest length in use.
    longest: u8,
    /// The decoder's lookup table (empty in an encoder's table, [`Table::from_counts`]): per
    /// value of the next [`Table::lut_bits`] bits, `symbol << 4 | length` of the code they
    /// start with, or 0 where that code is longer.
    lut: Vec<u16>,
    lut_bits: u8,
}

/// Two tables are the same code when their lengths are: the codes are canonical, and the
/// lookup table only speeds decoding.
impl PartialEq for Table {
    fn eq(&self, other: &Table) -> bool {
        self.lens == other.lens
    }
}

/// The most bits a decoder's lookup table is indexed by: 1024 entries (2 KB), which the
/// codes of `.dpm` operations almost always fit in. (Prefix-coded tiles read
/// [`SmallTable`]s.)
const LUT_BITS: u8 = 10;

impl Table {
    /// The code for these symbol counts, at most `max_len` bits long: symbols with a count
    /// get a code, the others none. A lone symbol gets a one-bit code.
    pub fn from_counts(counts: &[u64], max_len: u8) -> Table {
        assert!(counts.len() <= 1 << max_len.min(8) && (1..=MAX_LEN).contains(&max_len), "no code fits");
        let present: Vec<usize> = (0..counts.len()).filter(|&s| counts[s] > 0).collect();
        let mut lens = vec![0u8; counts.len()];
        match present.len() {
            0 => {}
            1 => lens[present[0]] = 1,
            _ => {
                let mut freq: Vec<u64> = present.iter().map(|&s| counts[s]).collect();
                loop {
                    let l = huffman_lengths(&freq);
                    if l.iter().all(|&l| l <= max_len) {
                        for (&s, l) in present.iter().zip(l) {
                            lens[s] = l;
                        }
                        break;
                    }
                    // Flatten the distribution until the longest code fits.
                    for f in &mut freq {
                        *f = (*f >> 1) + 1;
                    }
                }
            }
        }
        Table::canonical_of(&lens).expect("Huffman lengths are a complete code")
    }

    /// The canonical code for these lengths, if they form a complete prefix code (or a
    /// lone one-bit code, or no code at all), with its decoder's lookup table.
    pub fn from_lens(lens: &[u8]) -> Option<Table> {
        let mut t = Table::canonical_of(lens)?;
        // Decoding by table instead of length by length measured 1.5x faster on the dragon's
        // prefix-coded tile (11.5-12.7 to 18.1-18.5 Mtri/s); codes longer than the table's
        // bits still decode length by length.
        t.lut_bits = t.longest.min(LUT_BITS);
        t.lut = vec![0; 1 << t.lut_bits];
        fill_lut(&mut t.lut, &t.lens, &t.codes);
        Some(t)
    }

    fn canonical_of(lens: &[u8]) -> Option<Table> {
        if lens.len() > 256 {
            return None;
        }
        const N: usize = MAX_LEN as usize + 1;
        let (mut first, mut count, mut offset) = ([0u32; N], [0u32; N], [0u32; N]);
        let (mut sorted, mut codes) = (vec![0u8; lens.len()], vec![0u32; lens.len()]);
        let used = canonical_code(lens, MAX_LEN, [&mut first, &mut count, &mut offset], &mut sorted, &mut codes)?;
        sorted.truncate(used);
        let longest = lens.iter().copied().max().unwrap_or(0);
        Some(Table { lens: lens.to_vec(), codes, first, count, offset, sorted, longest, lut: Vec::new(), lut_bits: 0 })
    }

    /// The canonical decoding tables, for a decoder elsewhere (the WGSL one of `.dpm`
    /// operations): per length `l` in `0..=MAX_LEN` the first code of that length, the number
    /// of codes with it and where its symbols start in the symbols by code; those symbols; and
    /// the longest length in use. A code of length `l` decodes as
    /// `sorted[offset[l] + code - first[l]]` when `first[l] <= code < first[l] + count[l]`.
    pub fn canonical(&self) -> Canonical<'_> {
        Canonical {
            first: &self.first,
            count: &self.count,
            offset: &self.offset,
            sorted: &self.sorted,
            longest: self.longest,
        }
    }

    /// `sym`'s code and its length.
    #[inline]
    pub fn code(&self, sym: u8) -> (u32, u8) {
        code_of(&self.lens, &self.codes, sym)
    }

    /// Writes `sym`'s code; the symbol must have one.
    #[inline]
    pub fn encode(&self, w: &mut BitWriter, sym: u8) {
        let (code, len) = self.code(sym);
        w.put(code, len);
    }

    /// The symbol whose code starts `window` (a [`BitReader::window`]) and the code's length,
    /// or `None` for a bit pattern that is no code. The caller consumes the bits, so that a
    /// symbol and the raw bits after it can leave the window in one step.
    #[inline(always)]
    pub fn lookup(&self, window: u64) -> Option<(u8, u32)> {
        // `>> 1 >> (63 - k)`: a table of one entry (k = 0) must not shift by 64.
        if let Some(&e) = self.lut.get((window >> 1 >> (63 - self.lut_bits as u32)) as usize) {
            if e != 0 {
                return Some(((e >> 4) as u8, e as u32 & 15));
            }
        }
        (self.lut_bits as usize + 1..=self.longest as usize).find_map(|l| {
            let code = (window >> (64 - l)) as u32;
            let d = code.wrapping_sub(self.first[l]);
            (code >= self.first[l] && d < self.count[l]).then(|| (self.sorted[(self.offset[l] + d) as usize], l as u32))
        })
    }

    /// The next symbol, or `None` past the end of the data or for a bit pattern that is no
    /// code.
    #[inline]
    pub fn decode(&self, r: &mut BitReader) -> Option<u8> {
        // The peeked bits, left-aligned as a window: a code is at most MAX_LEN of them.
        let (sym, len) = self.lookup((r.peek() as u64) << (64 - MAX_LEN as u32))?;
        r.skip(len)?;
        Some(sym)
    }
}

/// The canonical code of `lens` (none longer than `max_len`), which [`Table`] and
/// [`SmallTable`] both build: into `[first, count, offset]` per length `l` in `1..=max_len`,
/// the first code of that length, how many codes have it and where its symbols start in
/// `sorted`; into `sorted` the symbols with a code, by length and then by symbol; into
/// `codes` each symbol's code. Returns how many symbols have a code, or `None` unless the
/// lengths form a complete prefix code, a lone one-bit code or no code at all. Inlined, so
/// that each caller's `max_len` is a constant of its loops.
#[inline(always)]
fn canonical_code(
    lens: &[u8],
    max_len: u8,
    [first, count, offset]: [&mut [u32]; 3],
    sorted: &mut [u8],
    codes: &mut [u32],
) -> Option<usize> {
    let n = max_len as usize + 1;
    count[..n].fill(0);
    for &l in lens {
        if l > max_len {
            return None;
        }
        count[l as usize] += 1;
    }
    let used = lens.len() as u32 - count[0];
    count[0] = 0;
    // Kraft equality: exactly complete, unless a single symbol has a one-bit code.
    let kraft: u64 = (1..n).map(|l| (count[l] as u64) << (n - 1 - l)).sum();
    if used > 1 && kraft != 1u64 << max_len || used == 1 && count[1] != 1 {
        return None;
    }
    let (mut code, mut off) = (0u32, 0u32);
    for l in 1..n {
        if l > 1 {
            code = (code + count[l - 1]) << 1;
        }
        first[l] = code;
        offset[l] = off;
        off += count[l];
    }
    // A counting sort: each symbol goes to the next place of its length's run, visited in
    // symbol order.
    let mut place = [0u32; MAX_LEN as usize + 1];
    let mut next = [0u32; MAX_LEN as usize + 1];
    place[..n].copy_from_slice(&offset[..n]);
    next[..n].copy_from_slice(&first[..n]);
    for (s, &l) in lens.iter().enumerate() {
        let l = l as usize;
        if l > 0 {
            sorted[place[l] as usize] = s as u8;
            place[l] += 1;
            codes[s] = next[l];
            next[l] += 1;
        }
    }
    Some(off as usize)
}

/// Fills a decoder's lookup table of `lut.len()` (a power of two) entries: per value of
/// that many next bits, `symbol << 4 | length` of the code they start with, or 0 where that
/// code is longer.
fn fill_lut(lut: &mut [u16], lens: &[u8], codes: &[u32]) {
    let k = lut.len().trailing_zeros();
    lut.fill(0);
    for (sym, &len) in lens.iter().enumerate() {
        let len = len as u32;
        if len > 0 && len <= k {
            let start = (codes[sym] << (k - len)) as usize;
            lut[start..start + (1 << (k - len))].fill((sym as u16) << 4 | len as u16);
        }
    }
}

/// Symbols a [`SmallTable`] holds at most.
pub const SMALL_SYMBOLS: usize = 64;
/// The longest code of a [`SmallTable`].
pub const SMALL_MAX_LEN: u8 = 15;
/// Bits of a [`SmallTable`]'s lookup table: 256 entries inline.
const SMALL_LUT_BITS: u8 = 8;

/// A decoder of a canonical prefix code of at most [`SMALL_SYMBOLS`] symbols and
/// [`SMALL_MAX_LEN`] bits, held inline. A prefix-coded tile reads two dozen code tables for
/// a few hundred symbols, and building each as a [`Table`] (five allocations, a 2 KB lookup
/// table, its moves and frees) took about half the decode of a tile of 170 triangles
/// (`perf` of every tile of a 64x64 grid's sort of the bunny); this one allocates nothing
/// and fills at most as many lookup entries as its longest code needs. It decodes what a
/// [`Table`] of the same lengths decodes (tested).
#[derive(Clone)]
pub struct SmallTable {
    /// The lengths and codes (as an encoder holds them).
    code: SmallCode,
    first: [u32; SMALL_MAX_LEN as usize + 1],
    count: [u32; SMALL_MAX_LEN as usize + 1],
    offset: [u32; SMALL_MAX_LEN as usize + 1],
    sorted: [u8; SMALL_SYMBOLS],
    longest: u8,
    lut_bits: u8,
    /// Per value of the next `lut_bits` bits, `symbol << 4 | length` of the code they start
    /// with, or 0 where that code is longer.
    lut: [u16; 1 << SMALL_LUT_BITS],
}

impl SmallTable {
    /// The canonical code for these lengths, if they form a complete prefix code (or a
    /// lone one-bit code, or no code at all) of at most [`SMALL_SYMBOLS`] symbols and
    /// [`SMALL_MAX_LEN`] bits: the code [`Table::from_lens`] makes of them.
    pub fn from_lens(lens: &[u8]) -> Option<SmallTable> {
        let mut t = SmallTable::EMPTY;
        t.set(lens).then_some(t)
    }

    /// No code: every lookup fails.
    pub const EMPTY: SmallTable = SmallTable {
        code: SmallCode { lens: [0; SMALL_SYMBOLS], codes: [0; SMALL_SYMBOLS], symbols: 0 },
        first: [0; SMALL_MAX_LEN as usize + 1],
        count: [0; SMALL_MAX_LEN as usize + 1],
        offset: [0; SMALL_MAX_LEN as usize + 1],
        sorted: [0; SMALL_SYMBOLS],
        longest: 0,
        lut_bits: 0,
        lut: [0; 1 << SMALL_LUT_BITS],
    };

    /// Makes this table the code [`SmallTable::from_lens`] makes of `lens`, in place (a
    /// reader of many tables fills them where they lie rather than moving each into place),
    /// or returns false, leaving a table that decodes nothing, for lengths that are no code.
    pub fn set(&mut self, lens: &[u8]) -> bool {
        let ok = self.build(lens);
        if !ok {
            (self.code.symbols, self.longest, self.lut_bits, self.lut[0]) = (0, 0, 0, 0);
        }
        ok
    }

    /// [`SmallTable::set`]'s work: it writes every field that a lookup of the new code
    /// reads, and no more.
    fn build(&mut self, lens: &[u8]) -> bool {
        if lens.len() > SMALL_SYMBOLS {
            return false;
        }
        let t = self;
        let tables = [&mut t.first[..], &mut t.count[..], &mut t.offset[..]];
        if canonical_code(lens, SMALL_MAX_LEN, tables, &mut t.sorted, &mut t.code.codes).is_none() {
            return false;
        }
        t.code.symbols = lens.len() as u8;
        t.code.lens[..lens.len()].copy_from_slice(lens);
        t.longest = lens.iter().copied().max().unwrap_or(0);
        t.lut_bits = t.longest.min(SMALL_LUT_BITS);
        fill_lut(&mut t.lut[..1 << t.lut_bits], lens, &t.code.codes);
        true
    }

    /// The code lengths, by symbol.
    pub fn lens(&self) -> &[u8] {
        self.code.lens()
    }

    /// `sym`'s code and its length.
    #[inline]
    pub fn code(&self, sym: u8) -> (u32, u8) {
        self.code.code(sym)
    }

    /// The symbol whose code starts `window` (a [`BitReader::window`]) and the code's length,
    /// or `None` for a bit pattern that is no code (as [`Table::lookup`]).
    #[inline(always)]
    pub fn lookup(&self, window: u64) -> Option<(u8, u32)> {
        // `>> 1 >> (63 - k)`: a table of one entry (k = 0) must not shift by 64.
        let e = self.lut[(window >> 1 >> (63 - self.lut_bits as u32)) as usize];
        if e != 0 {
            return Some(((e >> 4) as u8, e as u32 & 15));
        }
        (self.lut_bits as usize + 1..=self.longest as usize).find_map(|l| {
            let code = (window >> (64 - l)) as u32;
            let d = code.wrapping_sub(self.first[l]);
            (code >= self.first[l] && d < self.count[l]).then(|| (self.sorted[(self.offset[l] + d) as usize], l as u32))
        })
    }
}

/// A [`Table`]'s canonical decoding tables ([`Table::canonical`]).
#[derive(Clone, Copy, Debug)]
pub struct Canonical<'a> {
    pub first: &'a [u32; MAX_LEN as usize + 1],
    pub count: &'a [u32; MAX_LEN as usize + 1],
    pub offset: &'a [u32; MAX_LEN as usize + 1],
    pub sorted: &'a [u8],
    pub longest: u8,
}

/// Huffman code lengths for positive frequencies (two-queue construction).
fn huffman_lengths(freq: &[u64]) -> Vec<u8> {
    let n = freq.len();
    let mut lens = vec![0u8; n];
    let (mut order, mut weight) = (vec![0usize; n], vec![0u64; 2 * n - 1]);
    let (mut parent, mut depth) = (vec![0usize; 2 * n - 1], vec![0u32; 2 * n - 1]);
    huffman_lengths_into(freq, &mut lens, &mut order, &mut weight, &mut parent, &mut depth);
    lens
}

/// [`huffman_lengths`] into the caller's buffers (`lens` and `order` of `freq.len()`, the
/// others of `2 * freq.len() - 1`), so that [`SmallCode`] builds its codes on the stack.
#[inline(always)]
fn huffman_lengths_into(
    freq: &[u64],
    lens: &mut [u8],
    order: &mut [usize],
    weight: &mut [u64],
    parent: &mut [usize],
    depth: &mut [u32],
) {
    let n = freq.len();
    order.iter_mut().enumerate().for_each(|(i, o)| *o = i);
    order.sort_by_key(|&i| freq[i]);
    // Nodes: leaves 0..n, inner n..2n-1; parent links.
    for (w, &i) in weight.iter_mut().zip(order.iter()) {
        *w = freq[i];
    }
    parent.fill(usize::MAX);
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
        let a = take(weight, &mut leaf, &mut inner, made);
        let b = take(weight, &mut leaf, &mut inner, made);
        weight[made] = weight[a] + weight[b];
        parent[a] = made;
        parent[b] = made;
    }
    depth[2 * n - 2] = 0;
    for i in (0..2 * n - 2).rev() {
        depth[i] = depth[parent[i]] + 1;
    }
    for (k, &i) in order.iter().enumerate() {
        lens[i] = depth[k].min(255) as u8;
    }
}

/// An encoder's canonical prefix code of at most [`SMALL_SYMBOLS`] symbols and
/// [`SMALL_MAX_LEN`] bits, built on the stack: the code [`Table::from_counts`] makes of the
/// same counts (tested). A prefix-coded tile piece builds about thirty code tables, and
/// building each as a [`Table`] (eleven allocations) was a tenth of a level-of-detail cut's
/// sort in `perf`.
#[derive(Clone)]
pub struct SmallCode {
    lens: [u8; SMALL_SYMBOLS],
    codes: [u32; SMALL_SYMBOLS],
    symbols: u8,
}

impl SmallCode {
    /// The code for these symbol counts, at most `max_len` bits long (as
    /// [`Table::from_counts`]).
    pub fn from_counts(counts: &[u64], max_len: u8) -> SmallCode {
        const N: usize = SMALL_SYMBOLS;
        assert!(counts.len() <= N && (1..=SMALL_MAX_LEN).contains(&max_len), "no small code fits");
        let (mut present, mut np) = ([0u8; N], 0);
        for (s, &c) in counts.iter().enumerate() {
            if c > 0 {
                present[np] = s as u8;
                np += 1;
            }
        }
        let mut lens = [0u8; N];
        match np {
            0 => {}
            1 => lens[present[0] as usize] = 1,
            _ => {
                let mut freq = [0u64; N];
                for i in 0..np {
                    freq[i] = counts[present[i] as usize];
                }
                let (mut l, mut order) = ([0u8; N], [0usize; N]);
                let (mut weight, mut parent, mut depth) = ([0u64; 2 * N], [0usize; 2 * N], [0u32; 2 * N]);
                let m = 2 * np - 1;
                loop {
                    huffman_lengths_into(
                        &freq[..np],
                        &mut l[..np],
                        &mut order[..np],
                        &mut weight[..m],
                        &mut parent[..m],
                        &mut depth[..m],
                    );
                    if l[..np].iter().all(|&l| l <= max_len) {
                        for i in 0..np {
                            lens[present[i] as usize] = l[i];
                        }
                        break;
                    }
                    // Flatten the distribution until the longest code fits.
                    for f in &mut freq[..np] {
                        *f = (*f >> 1) + 1;
                    }
                }
            }
        }
        const L: usize = SMALL_MAX_LEN as usize + 1;
        let (mut first, mut count, mut offset) = ([0u32; L], [0u32; L], [0u32; L]);
        let (mut sorted, mut codes) = ([0u8; N], [0u32; N]);
        let tables = [&mut first[..], &mut count[..], &mut offset[..]];
        canonical_code(&lens[..counts.len()], SMALL_MAX_LEN, tables, &mut sorted, &mut codes)
            .expect("Huffman lengths are a complete code");
        SmallCode { lens, codes, symbols: counts.len() as u8 }
    }

    /// The code lengths, by symbol.
    pub fn lens(&self) -> &[u8] {
        &self.lens[..self.symbols as usize]
    }

    /// `sym`'s code and its length.
    #[inline]
    pub fn code(&self, sym: u8) -> (u32, u8) {
        code_of(&self.lens, &self.codes, sym)
    }
}

/// `sym`'s code and its length, from a table's codes and lengths by symbol.
#[inline(always)]
fn code_of(lens: &[u8], codes: &[u32], sym: u8) -> (u32, u8) {
    debug_assert!(lens[sym as usize] > 0, "symbol {sym} has no code");
    (codes[sym as usize], lens[sym as usize])
}

/// MSB-first bit writer; [`Self::finish`] pads the last byte with zeros.
#[derive(Default)]
pub struct BitWriter {
    bytes: Vec<u8>,
    /// Pending bits in the low `nbits` (bits above them are stale and never written).
    acc: u64,
    nbits: u32,
}

impl BitWriter {
    /// Writes the low `len` bits of `code` (at most 32), most significant first.
    #[inline]
    pub fn put(&mut self, code: u32, len: u8) {
        debug_assert!(len <= 32 && (len == 32 || code >> len == 0));
        // Fewer than 32 bits pend before a put, so 64 always hold them and the new ones; a
        // whole word goes out at once.
        self.acc = (self.acc << len) | code as u64;
        self.nbits += len as u32;
        if self.nbits >= 32 {
            self.nbits -= 32;
            self.bytes.extend_from_slice(&((self.acc >> self.nbits) as u32).to_be_bytes());
        }
    }

    pub fn finish(mut self) -> Vec<u8> {
        while self.nbits >= 8 {
            self.nbits -= 8;
            self.bytes.push((self.acc >> self.nbits) as u8);
        }
        if self.nbits > 0 {
            self.bytes.push((self.acc << (8 - self.nbits)) as u8);
        }
        self.bytes
    }
}

/// Bits a [`BitReader::window`] holds at least: a code of [`MAX_LEN`] bits and 32 raw bits.
pub const WINDOW: u32 = 56;

/// MSB-first bit reader over a byte slice from a starting byte. Reads past the end fail
/// (`None`) and consume nothing; a [`BitReader::window`] shows zeros past the end, and
/// [`BitReader::overrun`] counts what was consumed of them.
#[derive(Clone)]
pub struct BitReader<'a> {
    data: &'a [u8],
    start: usize,
    /// The next byte to load into `buf`.
    pos: usize,
    /// Loaded bits, left-aligned; zeros past the end of the data.
    buf: u64,
    nbits: u32,
    /// Bits in the data from `start`.
    avail: u64,
}

impl<'a> BitReader<'a> {
    pub fn new(data: &'a [u8], start: usize) -> Self {
        let avail = data.len().saturating_sub(start) as u64 * 8;
        BitReader { data, start, pos: start, buf: 0, nbits: 0, avail }
    }

    #[inline]
    fn fill(&mut self) {
        // Eight bytes in one big-endian load where the data has them: a `window` is refilled
        // before nearly every symbol. Bits below `nbits` are zeros or the stream's next bits,
        // so loading a byte's bits twice over is harmless.
        if let Some(word) = self.data.get(self.pos..self.pos + 8) {
            let word = u64::from_be_bytes(word.try_into().expect("eight bytes"));
            self.buf |= word >> self.nbits;
            let bytes = (63 - self.nbits) >> 3;
            self.pos += bytes as usize;
            self.nbits += bytes * 8;
            return;
        }
        while self.nbits <= 56 {
            let b = self.data.get(self.pos).copied().unwrap_or(0);
            self.buf |= (b as u64) << (56 - self.nbits);
            self.nbits += 8;
            self.pos += 1;
        }
    }

    /// The next [`MAX_LEN`] bits, without consuming them (zeros past the end).
    #[inline]
    pub fn peek(&mut self) -> u32 {
        if self.nbits < 32 {
            self.fill();
        }
        (self.buf >> (64 - MAX_LEN as u32)) as u32
    }

    /// Consumes `n <= 32` bits; fails past the end of the data.
    #[inline]
    pub fn skip(&mut self, n: u32) -> Option<()> {
        if self.read() + n as u64 > self.avail {
            return None;
        }
        if self.nbits < n {
            self.fill();
        }
        self.buf <<= n;
        self.nbits -= n;
        Some(())
    }

    /// The next `n <= 32` bits as a number, most significant first.
    #[inline]
    pub fn bits(&mut self, n: u32) -> Option<u32> {
        if n == 0 {
            return Some(0);
        }
        if self.nbits < n {
            self.fill();
        }
        let v = (self.buf >> (64 - n)) as u32;
        self.skip(n)?;
        Some(v)
    }

    #[inline]
    pub fn bit(&mut self) -> Option<bool> {
        self.bits(1).map(|b| b == 1)
    }

    /// The next bits, left-aligned: at least [`WINDOW`] of them are the stream's (zeros past
    /// its end). For decoders that take a symbol and its raw bits from one window and then
    /// [`BitReader::consume`] them, checking [`BitReader::overrun`] where it bounds their work
    /// instead of at every read.
    #[inline(always)]
    pub fn window(&mut self) -> u64 {
        if self.nbits < WINDOW {
            self.fill();
        }
        self.buf
    }

    /// The next bits, left-aligned, of which at least `N` (at most [`WINDOW`]) are the
    /// stream's: a decoder whose symbols take at most `N` bits refills once every few symbols
    /// instead of before nearly every one, keeping the refill off most symbols' chain.
    #[inline(always)]
    pub fn window_of<const N: u32>(&mut self) -> u64 {
        if self.nbits < N {
            self.fill();
        }
        self.buf
    }

    /// Consumes `n <= WINDOW` bits of the last [`BitReader::window`], past the end of the
    /// data too.
    #[inline(always)]
    pub fn consume(&mut self, n: u32) {
        debug_assert!(n <= self.nbits, "consumed more than the window");
        self.buf <<= n;
        self.nbits -= n;
    }

    /// Bits read so far: those loaded less those still in the window. Derived rather than
    /// counted, so that a consume updates two fields, not three (no decode speed change
    /// measured either way).
    #[inline]
    pub fn read(&self) -> u64 {
        (self.pos - self.start) as u64 * 8 - self.nbits as u64
    }

    /// How many bits have been consumed past the end of the data.
    #[inline]
    pub fn overrun(&self) -> u64 {
        self.read().saturating_sub(self.avail)
    }

    /// The byte just past the last one touched (the end of a byte-aligned stream).
    pub fn end(&self) -> usize {
        self.start + self.read().div_ceil(8) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip() {
        let mut counts = [0u64; 256];
        for (i, c) in counts.iter_mut().enumerate() {
            *c = if i < 4 { 1_000_000 >> i } else { (i % 7) as u64 + 1 };
        }
        let t = Table::from_counts(&counts, MAX_LEN);
        assert_eq!(Table::from_lens(&t.lens).unwrap(), t);
        let mut w = BitWriter::default();
        for s in 0..=255u8 {
            t.encode(&mut w, s);
        }
        let bytes = w.finish();
        // The decoder's table (codes up to its lookup bits by table, longer ones length by
        // length) and the encoder's (length by length) read the same symbols.
        let decoder = Table::from_lens(&t.lens).unwrap();
        assert!(decoder.lut_bits == LUT_BITS && t.longest > LUT_BITS, "both paths are taken");
        for table in [&decoder, &t] {
            let mut r = BitReader::new(&bytes, 0);
            for s in 0..=255u8 {
                assert_eq!(table.decode(&mut r), Some(s));
            }
            assert_eq!(r.end(), bytes.len());
        }
        // A window read (a symbol and the raw bits after it at once) reads the same, and
        // counts what it reads past the end instead of failing there.
        let mut w = BitWriter::default();
        for s in 0..=255u8 {
            t.encode(&mut w, s);
            w.put(s as u32 * 131 % 4096, 12);
        }
        let bytes = w.finish();
        let mut r = BitReader::new(&bytes, 0);
        for s in 0..=255u8 {
            let window = r.window();
            let (sym, len) = decoder.lookup(window).expect("a code");
            assert_eq!(sym, s);
            assert_eq!((window << len >> 52) as u32, s as u32 * 131 % 4096);
            r.consume(len + 12);
        }
        let padding = bytes.len() as u64 * 8 - r.read();
        assert!(padding < 8 && r.overrun() == 0);
        r.window();
        r.consume(16);
        assert_eq!(r.overrun(), 16 - padding);
        assert_eq!(r.window() >> 56, 0, "zeros past the end");
    }

    #[test]
    fn small_codes_are_the_codes_tables_make() {
        // Empty, lone, skewed past the length limit (flattened), and random alphabets.
        let mut rng = 0x2545_F491_4F6C_DD1Du64;
        let mut cases: Vec<Vec<u64>> =
            vec![vec![], vec![0; 9], vec![0, 5, 0], (0..40).map(|i| 1u64 << i.min(39)).collect()];
        for n in 1..=SMALL_SYMBOLS {
            cases.push(
                (0..n)
                    .map(|_| {
                        rng ^= rng << 13;
                        rng ^= rng >> 7;
                        rng ^= rng << 17;
                        if rng.is_multiple_of(4) {
                            0
                        } else {
                            rng % 1000
                        }
                    })
                    .collect(),
            );
        }
        for counts in &cases {
            let (t, small) = (Table::from_counts(counts, SMALL_MAX_LEN), SmallCode::from_counts(counts, SMALL_MAX_LEN));
            assert_eq!(small.lens(), &t.lens[..], "{counts:?}");
            for s in (0..counts.len()).filter(|&s| t.lens[s] > 0) {
                assert_eq!(small.code(s as u8), t.code(s as u8), "{counts:?}");
            }
        }
        assert!(
            cases[3].len() == 40 && SmallCode::from_counts(&cases[3], SMALL_MAX_LEN).lens().iter().all(|&l| l <= 15)
        );
    }

    #[test]
    fn small_tables_decode_as_tables_do() {
        // Codes of 1 to 64 symbols, short and up to 15 bits long, some symbols without a
        // code; every window of a stream of them reads alike through both.
        let mut longest = 0;
        for n in [1usize, 2, 3, 12, 26, 33, 64] {
            for skew in [1u64, 3, 9] {
                let counts: Vec<u64> = (0..n)
                    .map(|i| if i % 5 == 4 && n > 2 { 0 } else { (skew.pow((n - i).min(12) as u32)).max(1) })
                    .collect();
                let t = Table::from_counts(&counts, SMALL_MAX_LEN);
                let small = SmallTable::from_lens(&t.lens).expect("a complete code");
                assert_eq!(small.lens(), &t.lens[..]);
                longest = longest.max(small.longest);
                let mut w = BitWriter::default();
                let coded: Vec<u8> = (0..n as u8).filter(|&s| t.lens[s as usize] > 0).cycle().take(300).collect();
                for &s in &coded {
                    assert_eq!(small.code(s), t.code(s));
                    t.encode(&mut w, s);
                }
                let bytes = w.finish();
                let mut r = BitReader::new(&bytes, 0);
                for &s in &coded {
                    let window = r.window();
                    assert_eq!(small.lookup(window), Table::from_lens(&t.lens).unwrap().lookup(window));
                    let (sym, len) = small.lookup(window).expect("a code");
                    assert_eq!(sym, s);
                    r.consume(len);
                }
            }
        }
        assert!(longest > SMALL_LUT_BITS, "codes past the lookup table are read too");
        // Lengths that are no code, or too many symbols or bits for a small table.
        assert!(SmallTable::from_lens(&[2, 2, 2]).is_none(), "incomplete");
        assert!(SmallTable::from_lens(&[1, 1, 1]).is_none(), "oversubscribed");
        assert!(SmallTable::from_lens(&[1; 65]).is_none(), "65 symbols");
        let long: Vec<u8> = (1..=16).chain([16]).collect();
        assert!(Table::from_lens(&long).is_some() && SmallTable::from_lens(&long).is_none(), "16 bits");
        // A table set over another decodes as a fresh one; one set to no code, nothing.
        let (a, b) = (Table::from_counts(&[9, 1, 1, 1, 1, 1, 1, 1, 1], 15), Table::from_counts(&[1, 1, 1], 15));
        let mut t = SmallTable::from_lens(&a.lens).unwrap();
        assert!(t.set(&b.lens));
        for window in [0u64, 1 << 62, 2 << 62, 3 << 62] {
            assert_eq!(t.lookup(window), SmallTable::from_lens(&b.lens).unwrap().lookup(window));
        }
        assert!(!t.set(&[2, 2, 2]));
        assert!(t.lens().is_empty() && [0u64, 1 << 63, u64::MAX].iter().all(|&w| t.lookup(w).is_none()));
        // No code at all, and a lone one-bit code.
        assert_eq!(SmallTable::from_lens(&[0, 0]).unwrap().lookup(0), None);
        assert_eq!(SmallTable::from_lens(&[0, 1]).unwrap().lookup(0), Some((1, 1)));
    }

    #[test]
    fn partial_alphabets_and_truncation() {
        let counts = [0u64, 5, 0, 1, 1, 0, 9];
        let t = Table::from_counts(&counts, 15);
        assert_eq!(t.lens.iter().filter(|&&l| l > 0).count(), 4);
        let lone = Table::from_counts(&[0, 0, 3], 15);
        assert_eq!(lone.lens, vec![0, 0, 1]);
        assert!(Table::from_lens(&[2, 2, 2]).is_none(), "incomplete");
        assert!(Table::from_lens(&[1, 1, 1]).is_none(), "oversubscribed");
        let mut w = BitWriter::default();
        for &s in &[6u8, 1, 3, 4, 6, 6] {
            t.encode(&mut w, s);
        }
        lone.encode(&mut w, 2);
        w.put(0x1_2345, 17);
        let bytes = w.finish();
        let mut r = BitReader::new(&bytes, 0);
        for &s in &[6u8, 1, 3, 4, 6, 6] {
            assert_eq!(t.decode(&mut r), Some(s));
        }
        assert_eq!(lone.decode(&mut r), Some(2));
        assert_eq!(r.bits(17), Some(0x1_2345));
        // Only padding is left: nothing more than it decodes.
        assert_eq!(r.bits(8), None);
        assert!(Table::from_counts(&[1_000_000, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1], 5)
            .lens
            .iter()
            .all(|&l| (1..=5).contains(&l)));
    }
}
