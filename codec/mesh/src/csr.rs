//! Values grouped by a key with a counting sort (compressed sparse rows): the one way the
//! codec builds its adjacency lists (half-edges by source vertex, triangles by vertex,
//! absorbed vertices by parent).

/// Key `k`'s values, in input order, are `values[start[k]..start[k + 1]]`.
pub struct Csr<T> {
    pub start: Vec<u32>,
    pub values: Vec<T>,
}

impl<T: Copy + Default> Csr<T> {
    /// Groups the `(key, value)` pairs that `items` yields (it is called twice: once to
    /// count, once to place) by keys in `0..keys`.
    pub fn build<I: Iterator<Item = (u32, T)>>(keys: usize, items: impl Fn() -> I) -> Csr<T> {
        let mut start = vec![0u32; keys + 1];
        for (k, _) in items() {
            start[k as usize + 1] += 1;
        }
        for k in 0..keys {
            start[k + 1] += start[k];
        }
        let mut fill = start.clone();
        let mut values = vec![T::default(); start[keys] as usize];
        for (k, v) in items() {
            let i = &mut fill[k as usize];
            values[*i as usize] = v;
            *i += 1;
        }
        Csr { start, values }
    }

    /// Key `k`'s values.
    #[inline]
    pub fn get(&self, k: usize) -> &[T] {
        &self.values[self.start[k] as usize..self.start[k + 1] as usize]
    }
}
