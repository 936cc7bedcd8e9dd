//! The build's parameters (`--bits`, `--root-bits`, `--splits`, `--min-simplices`,
//! `--advance`) with their checks, and the Morton order the partition sorts by.

use super::error::NspError;

/// Build parameters (NSP.md 1.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// `p`: bits per quantized coordinate.
    pub bits: u8,
    /// `p_r`: the root's maximal precision.
    pub root_bits: u8,
    /// `n`: splits per axis of a cell (a power of 2, at least 2).
    pub splits: u32,
    /// `N_min`: a cell splits only if it holds at least this many top-simplices.
    pub min_simplices: u32,
    /// `m`: bits of geometry advance (section 7).
    pub advance: u8,
}

impl Default for Params {
    fn default() -> Self {
        Params { bits: 16, root_bits: 7, splits: 4, min_simplices: 8000, advance: 0 }
    }
}

/// The largest geometry advance, in bits (descendants are kept as suffixes of `3m` bits).
pub const MAX_ADVANCE: u8 = 4;

/// The largest precision (kd keys of `3p` bits and the level bit live in a `u128`; grid
/// coordinates and their shifts stay inside a `u32`).
pub const MAX_BITS: u8 = 30;

impl Params {
    pub fn validate(&self) -> Result<(), NspError> {
        if !(1..=MAX_BITS).contains(&self.bits) {
            return Err(NspError::Params(format!("--bits must be 1 to {MAX_BITS}, not {}", self.bits)));
        }
        if !(self.splits.is_power_of_two() && (2..=16).contains(&self.splits)) {
            return Err(NspError::Params(format!("--splits must be 2, 4, 8 or 16, not {}", self.splits)));
        }
        if self.root_bits < self.level_bits() || self.root_bits > self.bits {
            return Err(NspError::Params(format!(
                "--root-bits must be at least log2(--splits) = {} and at most --bits = {}, not {}",
                self.level_bits(),
                self.bits,
                self.root_bits
            )));
        }
        if self.min_simplices == 0 {
            return Err(NspError::Params("--min-simplices must be at least 1".into()));
        }
        if self.advance > MAX_ADVANCE {
            return Err(NspError::Params(format!("--advance must be 0 to {MAX_ADVANCE}, not {}", self.advance)));
        }
        Ok(())
    }

    /// `p_l = log2 n`.
    pub fn level_bits(&self) -> u8 {
        self.splits.trailing_zeros() as u8
    }

    /// Children per split cell, `n^3`.
    pub fn fan_out(&self) -> u32 {
        self.splits.pow(3)
    }

    /// The maximal precision of an internal cell at `depth`, capped at `p`.
    pub fn max_prec_at(&self, depth: u8) -> u8 {
        (self.root_bits as u32 + self.level_bits() as u32 * depth as u32).min(self.bits as u32) as u8
    }

    /// The Morton index of a child from its local coordinates (x the most significant).
    pub fn child_index(&self, local: [u32; 3]) -> u32 {
        let mut i = 0;
        for b in (0..self.level_bits()).rev() {
            i = (i << 3) | ((local[0] >> b) & 1) << 2 | ((local[1] >> b) & 1) << 1 | ((local[2] >> b) & 1);
        }
        i
    }

    /// The coordinates of child `k` of the cell at `coords`.
    pub fn child_coords(&self, coords: [u32; 3], k: u32) -> [u32; 3] {
        let pl = self.level_bits() as u32;
        let mut local = [0u32; 3];
        for b in 0..pl {
            let bits = k >> (3 * b);
            local[0] |= ((bits >> 2) & 1) << b;
            local[1] |= ((bits >> 1) & 1) << b;
            local[2] |= (bits & 1) << b;
        }
        [(coords[0] << pl) | local[0], (coords[1] << pl) | local[1], (coords[2] << pl) | local[2]]
    }
}

/// The Morton code of a point of `bits` bits per coordinate: bit `b` of x, y, z from the top,
/// x first, so that the prefix of length `L` is the point's kd-cell at kd level `L`.
#[inline]
pub fn morton(q: [u32; 3], bits: u8) -> u128 {
    let mut m = 0u128;
    for b in (0..bits).rev() {
        m = (m << 3) | (((q[0] >> b) & 1) << 2 | ((q[1] >> b) & 1) << 1 | ((q[2] >> b) & 1)) as u128;
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_prefixes_are_kd_cells() {
        let q = [0b1011, 0b0110, 0b1100];
        let m = morton(q, 4);
        for level in 0..=12u8 {
            let prefix = m >> (12 - level);
            let xyz = crate::complex::xyz_of(prefix, level);
            for a in 0..3 {
                // Axis a has consumed ceil((level - a) / 3) bits: the top ones of q[a].
                let used = (level as u32 + 2 - a as u32) / 3;
                assert_eq!(xyz[a], q[a] >> (4 - used), "level {level} axis {a}");
            }
        }
    }

    #[test]
    fn children_round_trip() {
        let p = Params::default();
        for k in 0..64 {
            let c = p.child_coords([1, 2, 3], k);
            let local = [c[0] & 3, c[1] & 3, c[2] & 3];
            assert_eq!(p.child_index(local), k);
            assert_eq!([c[0] >> 2, c[1] >> 2, c[2] >> 2], [1, 2, 3]);
        }
    }
}
