//! Opening the plan's model as the [`Scene`] of its kind.

use anyhow::{bail, Result};
use codec::kind::ModelKind;

use super::chunked::ChunkedScene;
use super::contract::Scene;
use super::{bft, nsp, pm};
use crate::render::plan::Plan;

/// Loads the plan's model, of the kind its magic bytes say (BFT tiles coded as the plan says).
pub(crate) fn load(plan: &Plan) -> Result<Box<dyn Scene>> {
    load_path(plan, &plan.model)
}

/// Loads the model at `path` with the plan's settings (a live run's `load`).
pub(crate) fn load_path(plan: &Plan, path: &std::path::Path) -> Result<Box<dyn Scene>> {
    let coding = plan.coding;
    if let Some(scene) = ChunkedScene::open(plan, path)? {
        return Ok(Box::new(scene));
    }
    if plan.sorters > 1 {
        bail!(
            "{}: --sorters shares the sort of a chunked .bft model (tessera encode writes one above --chunk-triangles)",
            path.display()
        );
    }
    Ok(match ModelKind::of(path) {
        ModelKind::Nsp => Box::new(nsp::NspScene::open(path)?),
        ModelKind::Dpm => Box::new(pm::PmScene::open(path, plan)?),
        _ => Box::new(bft::BftScene::open(path, coding)?),
    })
}
