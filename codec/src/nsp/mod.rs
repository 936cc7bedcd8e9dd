//! The nSP-tree store (Jamin, Gandoin & Akkouche, "A Compact Data Structure For The
//! Interactive Navigation Into Arbitrary Meshes"; `../shared/NSP.md` is our reading of it):
//! a lossless, progressive `.nsp` file cut into cubic cells that decode independently, so a
//! viewer loads and refines only the cells a view needs, each to the precision it needs.
//!
//! # What is coded
//!
//! Points are quantized to `p` bits per coordinate over a **cube** anchored at the minimum
//! corner of the bounding box ([`Cube`]). A kd-tree splits space with axes cycling x, y, z
//! (kd level `L` splits axis `L mod 3` at bit `p-1-L/3`); a precision of `b` bits is kd level
//! `3b`. Each split of a non-empty kd-cell codes one of three **occupancy** events (first
//! half, second half, both: two binary decisions, one static probability per kd level each).
//! When both halves are occupied the kd-cell `v` becomes `v0` and `v1` and the
//! **connectivity** change is coded as a generalised vertex split (NSP.md 1.6): one symbol per
//! simplex `v·τ` of the star of `v` (the vertex, its edges, its triangles, in kd-cell id order:
//! encoder and decoder create kd-cells in the same order, [`complex`]),
//! saying whether it becomes `v0·τ`, `v1·τ`, both, or both plus the cone `v0·v1·τ`. Symbols
//! the faces already force cost nothing. Every triangle a split creates gets an **orientation**
//! bit against a prediction (its parent triangle's orientation, or for a cone the orientation
//! that agrees with a neighbour across `v0 w` or `v1 w`). The decoder applies exactly the
//! operations the encoder applied ([`complex`]), so nothing is ever re-derived differently.
//!
//! All probabilities are **static**: the encoder first records every binary decision of
//! every cell with its context, then counts them and writes one 11-bit probability per
//! context into the file (the paper's "pre-calculated statistical prediction"), then
//! range-codes each cell with those fixed probabilities. A cell's stream is a separately
//! flushed range-coder stream, so any cell decodes alone.
//!
//! # The nSP partition
//!
//! The cube is cut into an nSP-tree ([`tree`]): a cell at depth `k` splits into `n^3` equal
//! children when it holds at least `N_min` top-simplices (duplicates across cells included)
//! and its maximal precision `p_r + p_l·k` (`p_l = log2 n`) is below `p`. A simplex belongs to
//! every cell holding one of its vertices. A cell's stream refines all of its simplices'
//! vertices, those outside it included, from its minimal precision (its parent's maximal
//! precision, 0 for the root) to its maximal one (`p` for a leaf). A child's starting state
//! is the part of its parent's final state that touches it, which equals the clustering of
//! the child's own simplices at that precision; that is why a child decodes from its parent
//! alone. The paper's parameters reproduce Table 1's cell counts exactly (1,473 for the
//! dragon at 28 bits, 65 for the bunny at 16; golden tests).
//!
//! # What lossless means (the contract)
//!
//! An `.nsp` decodes, when every cell is refined to `p` bits, to the **canonical complex** of
//! its input ([`Canonical`]), the paper's semantics (NSP.md 5.4.1):
//! - positions are quantized to `p` bits and drawn at their grid cell's centre;
//! - input vertices with the same quantized position are one vertex;
//! - a triangle whose corners merge becomes an edge or a point, and a simplex that is a face
//!   of another disappears (an edge of a triangle, a vertex of an edge);
//! - the complex is a set: repeated triangles (same three vertices, either orientation) are
//!   one triangle, with the orientation of its first occurrence in the input;
//! - every input vertex is a point of the model, unreferenced ones included (the paper's
//!   bunny counts its 1,113 isolated vertices).
//!
//! At any uniform precision `b < p` the decoded complex is the **vertex clustering** of the
//! canonical complex on the `b`-bit grid, under the same rules (tested).
//!
//! # Decisions where the paper is silent
//!
//! - Contexts: two per kd level for geometry; per (dimension of `v·τ`, set of allowed
//!   symbols, binary node) for connectivity; four for orientation (NSP.md 1.5 measured one
//!   table per level to be the best of the static choices).
//! - Coarsening re-decodes a cell from the start of its stream to the lower precision
//!   (NSP.md 5.4.5 proposes this first): the state at a precision is a pure function of the
//!   stream, so refine-then-coarsen gives back the same state (tested). The start is
//!   restricted again from the parent's state, which a navigator holds at its maximal
//!   precision anyway, rather than kept as a copy in every cell; the stream bytes already
//!   fetched are kept. Refining keeps the coder's position and continues.
//! - The **geometry advance** of section 7 (`--advance m`, 0 by default): geometry runs
//!   `3m` kd levels ahead of connectivity ([`complex::Ahead`]). Each kd-cell keeps its
//!   non-empty descendants `3m` levels below (fewer near the cell's finest points,
//!   `min(q + m, p)` bits for a cell of maximal precision `q`), so its split needs no code,
//!   and each new kd-cell's descendants are refined one level (one occupancy code each) right
//!   after its connectivity change. A kd-cell is drawn at the unweighted mean of its
//!   descendants' centres (NSP.md 1.8). The root's stream starts with a prologue coding the
//!   first `3m` levels. A child inherits from its parent the descendants of its kd-cells
//!   that lie inside it (there both saw all points); those outside it the child codes again
//!   in its own prologue as its own simplices see them (the paper's bold red box of Fig. 5;
//!   we code them for every child that holds them rather than leave one copy in the
//!   parent). A vertex is drawn where the cell it lies in puts it, so neighbours agree (a
//!   worker holds that cell whenever the triangle is in its tiles: its reach box holds the
//!   triangle). The view asks for connectivity `m` bits below the precision the error
//!   bound wants. The partition and the full-precision decode are unchanged (tested).
//! - Edges and points are kept, counted, and not drawn.
//! - **Bounds.** A reader checks every count it allocates from against `--max-decompressed`
//!   before allocating ([`mod@format`]: the footer's cells, the table's bytes, each row's
//!   kd-cells and top-simplices), and refuses a header whose cube does not fit `f32`. A build
//!   makes no more cells than a reader opens under the same cap ([`Params::check_cells`]):
//!   `--splits 16 --min-simplices 1` would otherwise make thousands of cells per triangle.

pub mod canonical;
pub mod complex;
pub mod decode;
pub mod encode;
pub mod format;
pub mod ooc;
pub mod tree;
pub mod view;

pub use canonical::{Canonical, Cube, Simplex};
pub use decode::{decode_all, decode_uniform, CellState, NspFile};
pub use encode::{encode, Built};
pub use tree::Tree;

use thiserror::Error;

/// Why an `.nsp` cannot be built or read.
#[derive(Debug, Error, PartialEq)]
pub enum NspError {
    #[error("{0}")]
    Params(String),
    #[error("{0}")]
    Input(String),
    #[error("the input has no points")]
    Empty,
    #[error("not an .nsp file: {0}")]
    Format(String),
    #[error("cell {cell}: {what}")]
    Cell { cell: u32, what: String },
    /// A count the file holds, above what `--max-decompressed` lets a reader allocate.
    #[error("{0}, above the cap on decompressed input (raise it with --max-decompressed)")]
    TooLarge(String),
    /// Flags that would make more cells than a reader opens (see [`Params::check_cells`]).
    #[error("{0}")]
    TooManyCells(String),
    /// Writing (or reading back) the build's temporary files in `folder` failed: a full
    /// disk, a write error. The build stops at the first failure.
    #[error("cannot {} temporary files in {}: {error}", if *write { "write" } else { "read" }, folder.display())]
    Temp { write: bool, folder: std::path::PathBuf, error: String },
    /// Writing the built file failed.
    #[error("{0}")]
    Output(String),
}

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

    /// Refuses a tree of at least `cells` cells where a reader would not open it
    /// ([`format::max_cells`]): how many cells a model is cut into follows from `--splits`
    /// and `--min-simplices` (with `--bits` and `--root-bits`, the depth), so the message
    /// names them.
    pub fn check_cells(&self, cells: u64) -> Result<(), NspError> {
        if cells <= format::max_cells() {
            return Ok(());
        }
        Err(NspError::TooManyCells(format!(
            "--splits {} with --min-simplices {} cuts this model into at least {cells} cells, more than the {} \
                 a reader opens under --max-decompressed ({} MiB at {} bytes a cell); raise --min-simplices or \
                 lower {}",
            self.splits,
            self.min_simplices,
            format::max_cells(),
            crate::input::max_decompressed_bytes() >> 20,
            format::CELL_BYTES,
            if self.splits > 2 { "--splits" } else { "--bits" }
        )))
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
            let xyz = complex::xyz_of(prefix, level);
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
