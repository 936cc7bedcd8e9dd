//! The model rank 0 holds for `tessera render`: a BFT model it sorts every frame, or a
//! progressive mesh that the workers adapt themselves.

use std::path::Path;

use anyhow::{bail, Context, Result};
use codec::bft::normals::BorderNormals;
use codec::bft::tile_sort::{Boxes, Sorter};
use codec::input::ModelKind;
use codec::view::{Camera, TileGrid};

use crate::cli::CameraArgs;
use crate::sort::{load_model, Model};

/// What rank 0 renders.
pub(super) enum Scene {
    Bft(BftScene),
    Pm(PmScene),
}

/// A BFT model (or a mesh encoded on load), with what its per-frame sort reuses.
pub(super) struct BftScene {
    pub model: Box<Model>,
    /// The whole mesh's normals, for the tiles' border vertices.
    pub normals: BorderNormals,
    pub sorter: Sorter,
    pub boxes: Box<Boxes>,
}

/// A progressive mesh: rank 0 keeps its file for the workers and its bounding box for the
/// camera and for the tiles it can reach.
pub(super) struct PmScene {
    pub bytes: Vec<u8>,
    pub bbox: ([f32; 3], [f32; 3]),
}

impl Scene {
    /// Loads the model at `path`, of the kind its magic bytes say; BFT tiles will be coded
    /// with `coding`.
    pub fn load(path: &Path, coding: codec::bft::Coding) -> Result<Scene> {
        if ModelKind::of(path) != ModelKind::Dpm {
            let model = load_model(path, codec::bft::EncodeOptions::default())?;
            let normals = BorderNormals::of(&model.tiles.decoded);
            return Ok(Scene::Bft(BftScene {
                model: Box::new(model),
                normals,
                sorter: Sorter::new(coding),
                boxes: Box::default(),
            }));
        }
        let bytes = crate::commands::read_input(path)?;
        // Decoded here once, so that a corrupt file fails before any worker sees it.
        let pm = codec::pm::format::decode(&bytes).with_context(|| format!("{}", path.display()))?.pm;
        let (lo, hi) = crate::pm::bbox(&pm.positions);
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
            bail!("{}: a bad model: its bounding box {lo:?} .. {hi:?} is not finite", path.display());
        }
        Ok(Scene::Pm(PmScene { bytes, bbox: (lo, hi) }))
    }

    /// The camera of the first frame: the flags given, the rest framing the model.
    pub fn camera(&self, args: &CameraArgs, grid: &TileGrid) -> Result<Camera> {
        match self {
            Scene::Bft(s) => s.model.camera(args, grid),
            Scene::Pm(PmScene { bbox: (lo, hi), .. }) => args.camera(*lo, *hi, grid.aspect()),
        }
    }
}
