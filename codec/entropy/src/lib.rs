//! Entropy coding and the file container of Tessera's formats: the adaptive binary range
//! coder ([`rangecoder`]) the BFT stream and the nSP-tree code their symbols with, canonical
//! Huffman codes ([`huffman`]) for the `.dpm` file's per-operation static tables (Derzapf and
//! Guthe, section 4.2), and the checksummed container with its one error type
//! ([`container`], [`FormatError`]).

pub mod container;
pub mod huffman;
pub mod rangecoder;

pub use container::{Format, FormatError};
