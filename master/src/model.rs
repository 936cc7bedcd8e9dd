//! Opening models: what kind a file is by its content (a Tessera model by its magic number,
//! a mesh file by its format), bounded reads, mesh files loaded with a spinner (or streamed),
//! and the sorted models rank 0 holds (a single-stream `.bft` decoded into its sort tables,
//! a chunked one read by the part a frame needs) with their default cameras.

use std::path::Path;

use anyhow::{bail, Context, Result};
use codec::bft::tile_sort::TileModel;
use codec::bft::{self, EncodeOptions};
use codec::kind::ModelKind;
use codec::view::{Camera, TileGrid};
use codec::Mesh;

use crate::camera::CameraSpec;
use crate::progress;

/// The kind of the file at `path` by its content alone: a Tessera model by its magic number,
/// a mesh file by [`codec::load::Format::of_file`]; `None` if it is neither (its reader
/// then says what is wrong).
fn content_kind(path: &Path) -> Option<ModelKind> {
    let mut magic = Vec::with_capacity(8);
    let file = std::fs::File::open(path).ok()?;
    std::io::Read::read_to_end(&mut std::io::Read::take(file, 8), &mut magic).ok()?;
    ModelKind::by_magic(&magic).or_else(|| codec::load::Format::of_file(path).ok().map(|_| ModelKind::Mesh))
}

/// Refuses, before any work, an input whose content is another kind of file than `want`,
/// saying which command takes it: `verb` is what the user asked for (`stats`, `adapt`,
/// `decode`), `command` the command that refuses.
pub fn expect_kind(path: &Path, want: ModelKind, command: &str, verb: &str) -> Result<()> {
    let Some(kind) = content_kind(path) else { return Ok(()) };
    if kind == want {
        return Ok(());
    }
    let what = |k: ModelKind| match k {
        ModelKind::Bft => "a .bft model",
        ModelKind::Dpm => "a .dpm progressive mesh",
        ModelKind::Nsp => "an .nsp model",
        ModelKind::Mesh => "a mesh file",
    };
    let instead = match (kind, verb) {
        (ModelKind::Bft, "stats") => "tessera stats",
        (ModelKind::Bft, _) => "tessera decode",
        (ModelKind::Dpm, "stats") => "tessera pm stats",
        (ModelKind::Dpm, _) => "tessera pm adapt",
        (ModelKind::Nsp, "stats") => "tessera nsp stats",
        (ModelKind::Nsp, _) => "tessera nsp adapt",
        (ModelKind::Mesh, _) => "tessera encode, pm build or nsp build to make a model of it",
    };
    anyhow::bail!("{}: this is {}; tessera {command} reads {}: use {instead}", path.display(), what(kind), what(want))
}

/// Reads an input file whole: regular files only (see [`codec::input::read_file`]).
pub fn read_input(path: &Path) -> Result<Vec<u8>> {
    codec::input::read_file(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Loads a mesh file (OBJ, PLY, STL, glTF, optionally gzipped), with a spinner while it parses;
/// points and lines it skipped are reported on stderr.
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    load_with(path, codec::load::load_path_counted)
}

/// As [`load_mesh`], reading a PLY or OBJ file in two streaming passes instead of whole into
/// memory (for the large models `pm build` takes: the memory then follows the mesh), calling
/// `between` with the vertex count before the triangles are read
/// ([`codec::load::load_path_streamed_between`]).
pub fn load_mesh_streamed(path: &Path, between: &mut dyn FnMut(usize)) -> Result<Mesh> {
    load_with(path, |p| codec::load::load_path_streamed_between(p, between))
}

fn load_with(path: &Path, load: impl FnOnce(&Path) -> Result<codec::load::Loaded, codec::LoadError>) -> Result<Mesh> {
    let pb = progress::spinner(format!("loading {}", path.display()));
    let loaded = load(path);
    pb.finish_and_clear();
    let loaded = loaded?;
    note_ignored(path, loaded.ignored);
    Ok(loaded.mesh)
}

/// Says on stderr how many points and lines a mesh file held that were skipped.
pub(crate) fn note_ignored(path: &Path, ignored: u64) {
    if ignored > 0 {
        eprintln!("note: {}: {ignored} point and line elements skipped (only triangles are kept)", path.display());
    }
}

/// A model held by the master: its `.bft` bytes and the sort-ready form.
pub struct Model {
    pub bytes: Vec<u8>,
    pub tiles: TileModel,
}

/// Loads a `.bft` file as it is, or encodes a mesh file (OBJ, PLY, STL, glTF) on load with `options`.
pub fn load_model(path: &Path, options: EncodeOptions) -> Result<Model> {
    let kind = codec::kind::ModelKind::of(path);
    if kind == codec::kind::ModelKind::Dpm {
        bail!("{}: a progressive mesh (.dpm); this command takes a .bft or a mesh file", path.display());
    }
    if kind == codec::kind::ModelKind::Nsp {
        bail!(
            "{}: an nSP-tree store (.nsp); this command takes a .bft or a mesh file (see tessera nsp)",
            path.display()
        );
    }
    let bytes = if kind == codec::kind::ModelKind::Bft {
        read_input(path)?
    } else {
        let mesh = load_mesh(path)?;
        bft::encode(&mesh, options).with_context(|| format!("cannot encode {}", path.display()))?.bytes
    };
    let tiles = TileModel::from_bytes(&bytes).with_context(|| format!("{}", path.display()))?;
    Ok(Model { bytes, tiles })
}

/// A chunked `.bft` model (version 3), read with positioned reads: only its header and
/// directory are read here, each chunk when a frame needs it (a file truncated meanwhile is an
/// error naming the chunk, not a SIGBUS as a mapping would give).
pub type Chunked = codec::bft::chunked::sort::ChunkedModel<codec::bft::chunked::FileSource>;

/// Opens `path` as a chunked model if it is one (`None` otherwise), with a cache of
/// `cache_bytes` for its straddling chunks' tables.
pub fn open_chunked(path: &Path, cache_bytes: usize) -> Result<Option<Chunked>> {
    use std::io::Read;
    if codec::kind::ModelKind::of(path) != codec::kind::ModelKind::Bft {
        return Ok(None);
    }
    let file = std::fs::File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let mut head = [0u8; 10];
    if !file.metadata().is_ok_and(|m| m.is_file())
        || (&file).take(10).read(&mut head).ok() != Some(10)
        || !codec::bft::chunked::is_chunked(&head)
    {
        return Ok(None);
    }
    drop(file);
    let source = codec::bft::chunked::FileSource::open(path)?;
    let file = codec::bft::chunked::ChunkedFile::open(source).with_context(|| format!("{}", path.display()))?;
    truncate_hook(path, file.entries.first().map_or(0, |e| e.offset));
    Ok(Some(codec::bft::chunked::sort::ChunkedModel::new(file, cache_bytes)))
}

/// Test hook: `TESSERA_FAULT=truncate-after-open` cuts a chunked model to its header and
/// directory (`head` bytes) once they are read, so a test sees what a file truncated while
/// in use gives. Unset in normal runs.
fn truncate_hook(path: &Path, head: u64) {
    if std::env::var_os("TESSERA_FAULT").is_some_and(|v| v == "truncate-after-open") {
        if let Ok(f) = std::fs::OpenOptions::new().write(true).open(path) {
            let _ = f.set_len(head);
        }
    }
}

/// The camera of a chunked model: the flags given, the rest framing its bounding box.
pub fn chunked_camera(model: &Chunked, args: &CameraSpec, grid: &TileGrid) -> Result<Camera> {
    let h = model.file.header;
    args.camera(h.bbox_min, h.bbox_max, grid.aspect())
}

impl Model {
    pub fn camera(&self, args: &CameraSpec, grid: &TileGrid) -> Result<Camera> {
        let d = &self.tiles.decoded;
        let h = d.header;
        // The three-quarter view fits the vertices (dequantized: the box's own scale).
        let points: Option<Vec<[f32; 3]>> = (args.view == crate::camera::ViewPreset::ThreeQuarter).then(|| {
            let q = d.quantization();
            d.positions.iter().map(|&p| q.dequantize(p)).collect()
        });
        args.camera_fitting(h.bbox_min, h.bbox_max, points.as_deref(), grid.aspect())
    }
}

/// A box around every vertex of an out-of-core `.dpm`, from its head alone: the union of the
/// base vertices and of the nodes' boxes (which hold every operation's bounding sphere, so
/// every vertex), cut to the quantization grid (the header's lower corner and its largest
/// extent), which holds every position. The spheres of coarse operations reach far past the
/// model: uncut, the 102M-triangle armadillo's default camera framed it at a fraction of the
/// frame.
pub fn dpm_file_bbox(dpm: &codec::pm::format::Dpm) -> ([f32; 3], [f32; 3]) {
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    let points = dpm.base_positions.iter().map(|&q| {
        let p = dpm.position(q);
        (p, p)
    });
    for (a, b) in points.chain(dpm.nodes.iter().map(|n| (n.bbox_min, n.bbox_max))) {
        for k in 0..3 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(b[k]);
        }
    }
    let top = (1u32 << dpm.header.position_bits) - 1;
    let (grid_lo, grid_hi) = (dpm.position([0; 3]), dpm.position([top; 3]));
    for k in 0..3 {
        lo[k] = lo[k].max(grid_lo[k]);
        hi[k] = hi[k].min(grid_hi[k]);
    }
    (lo, hi)
}

/// The bounding box of a progressive mesh's positions; a unit box for an empty one.
pub fn pm_bbox(p: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    codec::mesh::bounding_box(p).unwrap_or(([0.0; 3], [1.0; 3]))
}

/// The model's bounding box, from the header.
pub fn nsp_bbox(file: &codec::nsp::NspFile) -> ([f32; 3], [f32; 3]) {
    let c = &file.header.cube;
    let e = file.header.extent;
    let lo = [c.origin[0] as f32, c.origin[1] as f32, c.origin[2] as f32];
    let hi = [(c.origin[0] + e[0]) as f32, (c.origin[1] + e[1]) as f32, (c.origin[2] + e[2]) as f32];
    (lo, hi)
}
