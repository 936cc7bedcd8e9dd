//! Why a file could not be read as a mesh ([`LoadError`]).

use std::path::{Path, PathBuf};

use thiserror::Error;

/// A file that could not be read as a mesh.
#[derive(Debug, Error)]
#[error("{}: {message}", path.display())]
pub struct LoadError {
    pub path: PathBuf,
    pub message: String,
}

/// A [`LoadError`] for `path`.
pub(crate) fn err(path: &Path, message: impl Into<String>) -> LoadError {
    LoadError { path: path.to_path_buf(), message: message.into() }
}

/// The message for a file that gives no triangle.
pub fn no_triangles(ignored: u64) -> String {
    if ignored > 0 {
        format!("no triangles, only points or lines ({ignored} elements; Tessera renders triangle meshes)")
    } else {
        "no triangles (an empty file or a point cloud is not a mesh)".to_string()
    }
}
