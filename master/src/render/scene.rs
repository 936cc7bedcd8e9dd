//! The model rank 0 holds for `tessera render`: a BFT model it sorts every frame, or a
//! progressive mesh that the workers adapt themselves.

use std::path::Path;

use anyhow::{bail, Context, Result};
use codec::bft::normals::BorderNormals;
use codec::bft::tile_sort::{Boxes, Sorter};
use codec::kind::ModelKind;
use codec::view::{Camera, TileGrid};

use worker::chunk_cache::ChunkCache;

use crate::cli::{CameraArgs, RenderArgs};
use crate::model::{
    chunked_camera, dpm_file_bbox, load_model, nsp_bbox, open_chunked, pm_bbox, read_input, Chunked, Model,
};

const MB: usize = 1 << 20;

/// What rank 0 renders.
pub(super) enum Scene {
    Bft(BftScene),
    Chunked(Box<ChunkedScene>),
    Pm(PmScene),
    Nsp(Box<NspScene>),
}

/// An `.nsp` model: its header and cell tables (the streams stay on disk until a worker
/// needs them), and the bytes of each cell's stream each worker holds (workers keep what
/// they are sent: the segments up to the highest precision they were asked for).
pub(super) struct NspScene {
    pub file: codec::nsp::NspFile,
    /// Indexed by worker rank - 1: cell -> bytes held.
    pub held: Vec<std::collections::HashMap<u32, u32>>,
}

/// A chunked BFT model, memory-mapped, and rank 0's mirror of every worker's chunk cache
/// (`worker::chunk_cache`), from which it knows which verbatim chunks a worker holds.
pub(super) struct ChunkedScene {
    pub model: Chunked,
    pub coding: codec::bft::Coding,
    /// Indexed by worker rank - 1.
    pub mirrors: Vec<ChunkCache<()>>,
    /// Each worker's chunk cache bound in bytes.
    pub worker_cache: u64,
    /// Ranks sharing the sort (`--sorters`), and this frame's worker of every tile of the
    /// grid when there are several (rank 0 decides it and tells the others).
    pub sorters: usize,
    pub owners: Vec<usize>,
}

/// A BFT model (or a mesh encoded on load), with what its per-frame sort reuses.
pub(super) struct BftScene {
    pub model: Box<Model>,
    /// The whole mesh's normals, for the tiles' border vertices.
    pub normals: BorderNormals,
    pub sorter: Sorter,
    pub boxes: Box<Boxes>,
}

/// A progressive mesh: rank 0 keeps its file for the workers (or, out of core, its path:
/// each worker reads the nodes it needs itself) and its bounding box for the camera and for
/// the tiles it can reach.
pub(super) struct PmScene {
    pub source: PmSource,
    pub bbox: ([f32; 3], [f32; 3]),
}

pub(super) enum PmSource {
    /// An in-core file's bytes, sent to every worker, and the bytes of graphics memory each
    /// worker's adaptation may take.
    Bytes { bytes: Vec<u8>, gpu_budget: u64 },
    /// An out-of-core file's absolute path, the bytes of graphics memory each worker's
    /// adaptation may take, those of them it keeps of the nodes, and the node slots they make
    /// (at most one per node).
    File { path: String, gpu_budget: u64, pool_bytes: u64, slots: u32 },
}

impl Scene {
    /// Loads the model at `path`, of the kind its magic bytes say; BFT tiles will be coded
    /// with `coding`.
    pub fn load(path: &Path, coding: codec::bft::Coding, args: &RenderArgs) -> Result<Scene> {
        if let Some(model) = open_chunked(path, args.cache_mb as usize * MB)? {
            let worker_cache = args.worker_cache_mb * MB as u64;
            let sorters = args.sorters as usize;
            return Ok(Scene::Chunked(Box::new(ChunkedScene {
                model,
                coding,
                mirrors: Vec::new(),
                worker_cache,
                sorters,
                owners: Vec::new(),
            })));
        }
        if args.sorters > 1 {
            bail!(
                "{}: --sorters shares the sort of a chunked .bft model (tessera encode writes one above --chunk-triangles)",
                path.display()
            );
        }
        if ModelKind::of(path) == ModelKind::Nsp {
            let file = codec::nsp::NspFile::open(path).with_context(|| format!("{}", path.display()))?;
            return Ok(Scene::Nsp(Box::new(NspScene { file, held: Vec::new() })));
        }
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
        let named = || format!("{}", path.display());
        let gpu_budget = (args.gpu_budget_mb as f64 * MB as f64) as u64;
        if let Some(file) = codec::pm::format::NodeFile::open_out_of_core(path).with_context(named)? {
            let nodes = args.gpu_nodes_mb.map(|mb| (mb as f64 * MB as f64) as u64);
            return PmScene::out_of_core(path, &file, gpu_budget, nodes).map(Scene::Pm);
        }
        let bytes = read_input(path)?;
        // Decoded here once, so that a corrupt file fails before any worker sees it.
        let pm = codec::pm::format::decode(&bytes).with_context(|| format!("{}", path.display()))?.pm;
        let (lo, hi) = pm_bbox(&pm.positions);
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
            bail!("{}: a bad model: its bounding box {lo:?} .. {hi:?} is not finite", path.display());
        }
        Ok(Scene::Pm(PmScene { source: PmSource::Bytes { bytes, gpu_budget }, bbox: (lo, hi) }))
    }

    /// The camera of the first frame: the flags given, the rest framing the model.
    pub fn camera(&self, args: &CameraArgs, grid: &TileGrid) -> Result<Camera> {
        match self {
            Scene::Bft(s) => s.model.camera(args, grid),
            Scene::Chunked(s) => chunked_camera(&s.model, args, grid),
            Scene::Pm(PmScene { bbox: (lo, hi), .. }) => args.camera(*lo, *hi, grid.aspect()),
            Scene::Nsp(s) => {
                let (lo, hi) = nsp_bbox(&s.file);
                args.camera(lo, hi, grid.aspect())
            }
        }
    }
}

impl PmScene {
    /// An out-of-core `.dpm`: its head is read and checked here (the nodes are checked by
    /// their checksums as workers read them); its box is [`dpm_file_bbox`].
    fn out_of_core(
        path: &Path,
        file: &codec::pm::format::NodeFile,
        gpu_budget: u64,
        nodes: Option<u64>,
    ) -> Result<PmScene> {
        let named = || format!("{}", path.display());
        let dpm = codec::pm::format::Dpm::parse_prefix(file.prefix()).with_context(named)?;
        let (lo, hi) = dpm_file_bbox(&dpm);
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) || lo.iter().zip(&hi).any(|(a, b)| a > b) {
            bail!("{}: a bad model: its bounding box {lo:?} .. {hi:?} is not finite", path.display());
        }
        // Each worker's pool holds slots of the largest node's size: a pool below one slot
        // is refused here, before any worker starts on it.
        let pool_bytes = worker::pm_adapt::pool_bytes(Some(gpu_budget), nodes)?;
        let slot_bytes = worker::pm_adapt::decoder::slot_bytes(&dpm);
        if pool_bytes < slot_bytes as u64 {
            return Err(worker::pm_adapt::AdaptError::Budget { budget: pool_bytes, slot_bytes }.into());
        }
        let abs = std::fs::canonicalize(path).with_context(named)?;
        let path = abs.to_str().with_context(|| format!("{}: the path is not UTF-8", abs.display()))?.to_string();
        let slots = worker::pm_adapt::decoder::slots_within(&dpm, pool_bytes);
        Ok(PmScene { source: PmSource::File { path, gpu_budget, pool_bytes, slots }, bbox: (lo, hi) })
    }
}
