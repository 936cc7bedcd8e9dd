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

// The paths the modules were written with when they were one crate (`crate::mesh`),
// kept for the crate's own files.
#[allow(unused_imports)]
pub(crate) use tessera_entropy::{container, huffman, rangecoder, Format, FormatError};
#[allow(unused_imports)]
pub(crate) use tessera_mesh::{csr, input, kind, load, mesh, LoadError, Mesh, MeshError, Quantization};

pub mod canonical;
pub mod complex;
pub mod decode;
pub mod encode;
mod error;
pub mod format;
pub mod ooc;
mod params;
pub mod tree;
pub mod view;

pub use canonical::{Canonical, Cube, Simplex};
pub use decode::{CellState, NspFile};
pub use encode::{encode, Built};
pub use error::NspError;
pub use params::{morton, Params, MAX_ADVANCE, MAX_BITS};
pub use tree::Tree;
pub use view::{decode_all, decode_uniform};
