//! `tessera decode`: a `.bft` back into a mesh file.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use codec::bft;
use codec::kind::ModelKind;

use crate::model::{expect_kind, read_input};
use crate::output::{mesh_output, summary, write_atomic};

/// `tessera decode IN.bft -o OUT.ply|OUT.obj`.
pub fn run(input: &Path, output: &Path) -> Result<()> {
    let writer = mesh_output(input, output, "the output of decode")?;
    expect_kind(input, ModelKind::Bft, "decode", "decode")?;
    let bytes = read_input(input)?;
    let start = Instant::now();
    let decoded = bft::decode(&bytes).with_context(|| format!("{}", input.display()))?;
    let mesh = decoded.to_mesh();
    let secs = start.elapsed().as_secs_f64();
    write_atomic(output, |w| writer(&mesh, w))?;
    summary(
        output,
        format_args!(
            "{} -> {}: {} triangles, {} vertices, decoded in {:.1} ms",
            input.display(),
            output.display(),
            mesh.triangles.len(),
            mesh.positions.len(),
            secs * 1e3
        ),
    )?;
    Ok(())
}
