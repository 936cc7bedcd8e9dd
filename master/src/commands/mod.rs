//! One file per subcommand of `tessera`, each with its `run`; `main.rs` calls them, one line
//! each. What several commands share lives beside them: opening models
//! ([`crate::model`]), outputs ([`crate::output`]), the flags ([`crate::cli`]).

pub mod decode;
pub mod encode;
pub mod nsp;
pub mod plot;
pub mod pm;
pub mod render;
pub mod sort;
pub mod stats;
pub mod view;
