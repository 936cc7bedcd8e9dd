//! What a loader gives ([`Loaded`]), and the checks every loader's mesh passes.

use std::path::Path;

use super::error::{err, no_triangles, LoadError};
use crate::mesh::Mesh;

/// A loaded mesh, and what the file held that is not a triangle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Loaded {
    pub mesh: Mesh,
    /// Elements skipped because they are not triangles: OBJ points (`p`, `f` of one corner)
    /// and lines (`l`, `f` of two corners).
    pub ignored: u64,
}

/// The checks every loader's mesh passes: its faces' vertices exist, and it has a face.
pub(super) fn checked(path: &Path, mesh: Mesh, ignored: u64) -> Result<Loaded, LoadError> {
    if let Some(bad) = mesh.triangles.iter().flatten().find(|&&i| i as usize >= mesh.positions.len()) {
        return Err(err(
            path,
            format!("a face uses vertex {bad}, but the file has only {} vertices", mesh.positions.len()),
        ));
    }
    if mesh.triangles.is_empty() {
        return Err(err(path, no_triangles(ignored)));
    }
    Ok(Loaded { mesh, ignored })
}
