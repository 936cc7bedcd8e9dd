//! glTF 2.0 in: `.gltf` (buffers embedded as data URIs or in files beside it) and `.glb`.
//!
//! The `gltf` crate parses the JSON and the GLB container and validates the document (every
//! index in range, every enum known; an accessor without a buffer view is allowed, as the
//! specification allows it); the data are read here:
//!
//! * **What is read**: every primitive of every mesh of every node of the default scene (the
//!   first scene when none is the default), under the node's world transform, in scene order,
//!   depth first. Nodes outside the scene are not read. A transform that mirrors (negative
//!   determinant) flips the winding, as the specification says, so orientation is kept.
//! * **Triangles**: `TRIANGLES`, `TRIANGLE_STRIP` (triangle `i` is `v_i, v_{i+1+i%2},
//!   v_{i+2-i%2}`) and `TRIANGLE_FAN` (`v_{i+1}, v_{i+2}, v_0`), indexed (8, 16 or 32 bits) or
//!   not. Points and lines are skipped and counted, as in OBJ. Each primitive's vertices are
//!   its own (no welding across primitives).
//! * **Accessors** are read by hand rather than with the crate's reader, which reads
//!   positions as `f32` only: every component type, `normalized` or not (so
//!   `KHR_mesh_quantization` positions, which their node's transform scales back), any byte
//!   stride, sparse substitutions, and an accessor without a buffer view (zeros). Every read
//!   is bounds-checked against its view and buffer.
//! * **Compression**: `KHR_draco_mesh_compression` primitives are decoded with `draco-core`
//!   (positions and faces from the Draco stream, attributes found by their unique id);
//!   `EXT_meshopt_compression` buffer views are decoded with meshopt's decoders (and the
//!   octahedral and exponential filters, written here from the extension's specification)
//!   into their fallback buffer before anything is read; the quaternion filter, for
//!   rotations, is refused.
//! * **Attributes**: positions only for now; `NORMAL` and `COLOR_0` are present in the
//!   files we read but the mesh does not carry attributes yet (issue 17, item 3).
//!
//! * **Files**: a buffer URI names a file in the model's folder (or below it). An absolute
//!   path, a `..` that leads out of the folder, or a symlink that does (the canonical paths
//!   compared) is refused unless `--allow-outside-uris` is given
//!   ([`crate::input::allow_outside_uris`]); a URI with a scheme other than `data:` (`http:`,
//!   `https:`, `file://`) is refused as remote. Images are not read.
//! * **Sizes**: what a file can make the reader allocate is checked before it is allocated,
//!   against the cap on decompressed input ([`crate::input::max_decompressed_bytes`],
//!   `--max-decompressed`): each accessor's values (8 bytes each, with or without a buffer
//!   view), the buffer files read and the meshopt fallback buffers together, a Draco
//!   stream's decoded values (Draco's own limits), and the running totals of the model's
//!   vertices (28 bytes each: position, normal, colour) and triangles (12), every instance of
//!   a mesh that several nodes use counted.
//!
//! Every error is one line naming what is wrong and where (buffer, view, accessor, mesh and
//! primitive by index; attributes by their glTF names).

use std::collections::HashSet;
use std::path::Path;

use base64::Engine as _;
use glam::{DMat3, DMat4, DVec3};
use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};

use super::error::{err, no_triangles, LoadError};
use super::loaded::Loaded;

/// Extensions this reader implements (removed from `extensionsRequired` before the crate
/// validates the document, which refuses required extensions it does not know).
const HANDLED: [&str; 3] = ["KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_mesh_quantization"];

/// Reads a glTF or GLB file's bytes; `path` locates external buffers and names the file.
pub(super) fn load(path: &Path, bytes: &[u8]) -> Result<Loaded, LoadError> {
    let fail = |what: String| err(path, format!("glTF: {what}"));
    let (json, bin) = if bytes.starts_with(b"glTF") {
        // The crate subtracts the 12-byte header from the header's length field unchecked
        // (an overflow the glTF fuzz target found): a length below 12 is refused here first.
        let length = bytes.get(8..12).map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")));
        if let Some(length) = length.filter(|&l| l < 12) {
            return Err(fail(format!(
                "malformed GLB container: its length field says {length} bytes, less than its header"
            )));
        }
        let glb = gltf::binary::Glb::from_slice(bytes).map_err(|e| fail(format!("malformed GLB container: {e}")))?;
        (glb.json.into_owned(), glb.bin.map(|b| b.into_owned()))
    } else {
        (bytes.to_vec(), None)
    };
    let mut root: gltf::json::Root =
        gltf::json::deserialize::from_slice(&json).map_err(|e| fail(format!("malformed JSON: {e}")))?;
    root.extensions_required.retain(|e| !HANDLED.contains(&e.as_str()));
    // gltf-json's validator indexes the accessors with a primitive's POSITION before it
    // checks the index (it panics on an index out of range): checked here first.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for (semantic, acc) in &prim.attributes {
                if acc.value() >= root.accessors.len() {
                    let semantic = semantic.to_string();
                    let what = format!("mesh {m} primitive {p}: attribute {semantic} names accessor {}", acc.value());
                    return Err(fail(format!("{what}, but the file has {}", root.accessors.len())));
                }
            }
        }
    }
    // The crate's validation, less one rule the specification does not have: an accessor
    // without a buffer view is zeros (or its sparse values, or its Draco stream's).
    let mut problems = Vec::new();
    gltf::json::validation::Validate::validate(&root, &root, gltf::json::Path::new, &mut |path, error| {
        let path = path();
        let zeros = path.as_str().starts_with("accessors[")
            && path.as_str().ends_with("].bufferView")
            && error == gltf::json::validation::Error::Missing;
        if !zeros {
            problems.push(format!("{path}: {error}"));
        }
    });
    if !problems.is_empty() {
        return Err(fail(format!("invalid document: {}", problems.join("; "))));
    }
    let doc = gltf::Document::from_json_without_validation(root);
    let mut buffers = load_buffers(path, &doc, bin)?;
    decode_meshopt_views(&doc, &mut buffers).map_err(fail)?;

    let scene = doc.default_scene().or_else(|| doc.scenes().next()).ok_or_else(|| fail("no scene".into()))?;
    let mut out = Loaded::default();
    let mut attributes = Attributes::default();
    let mut seen = HashSet::new();
    let mut stack: Vec<(gltf::Node, DMat4)> = scene.nodes().map(|n| (n, DMat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        if !seen.insert(node.index()) {
            return Err(fail(format!("node {} appears twice in the scene's hierarchy", node.index())));
        }
        let world = parent * DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                let at = |what: String| fail(format!("mesh {} primitive {}: {what}", mesh.index(), prim.index()));
                read_primitive(&doc, &prim, &buffers, &world, &mut out, &mut attributes).map_err(at)?;
            }
        }
        stack.extend(node.children().collect::<Vec<_>>().into_iter().rev().map(|c| (c, world)));
    }
    if out.mesh.triangles.is_empty() {
        return Err(err(path, no_triangles(out.ignored)));
    }
    // Normals only when every primitive has them (a renderer computes them otherwise);
    // colours when some primitive has them, white elsewhere (what COLOR_0's absence means).
    if attributes.every_normal {
        out.mesh.normals = attributes.normals;
    }
    if attributes.some_color {
        out.mesh.colors = attributes.colors;
    }
    Ok(out)
}

/// The normals and colours of the primitives read so far, a value per vertex.
struct Attributes {
    normals: Vec<[f32; 3]>,
    colors: Vec<[u8; 4]>,
    every_normal: bool,
    some_color: bool,
}

impl Default for Attributes {
    fn default() -> Self {
        Attributes { normals: Vec::new(), colors: Vec::new(), every_normal: true, some_color: false }
    }
}

/// A primitive's `NORMAL` (VEC3) or `COLOR_0` (VEC3 or VEC4) values, if it has them.
fn read_optional(
    prim: &gltf::Primitive,
    semantic: Semantic,
    buffers: &[Vec<u8>],
    n: usize,
) -> Result<Option<Vec<[f64; 4]>>, String> {
    let Some(acc) = prim.get(&semantic) else { return Ok(None) };
    let comps = match (acc.dimensions(), &semantic) {
        (Dimensions::Vec3, _) => 3,
        (Dimensions::Vec4, Semantic::Colors(_)) => 4,
        _ => return Err(format!("{} accessor {} has the wrong type", semantic.to_string(), acc.index())),
    };
    if acc.count() != n {
        let name = semantic.to_string();
        return Err(format!("{name} accessor {} has {} values for {n} vertices", acc.index(), acc.count()));
    }
    let flat = read_accessor(&acc, buffers)?;
    Ok(Some(flat.chunks_exact(comps).map(|c| [c[0], c[1], c[2], if comps == 4 { c[3] } else { 1.0 }]).collect()))
}

/// Every buffer's bytes: a data URI decoded, a file in the glTF's folder read
/// ([`resolve_uri`]), the GLB's binary chunk, or zeros for a meshopt fallback buffer (filled
/// by [`decode_meshopt_views`]). The files read and the fallback buffers take at most the cap
/// on decompressed input in all (a file may name one buffer file many times).
fn load_buffers(path: &Path, doc: &gltf::Document, bin: Option<Vec<u8>>) -> Result<Vec<Vec<u8>>, LoadError> {
    let mut bin = bin;
    let mut out = Vec::new();
    let mut total = 0u64;
    for buffer in doc.buffers() {
        let fail = |what: String| err(path, format!("glTF: buffer {}: {what}", buffer.index()));
        let len = buffer.length();
        let fallback = buffer.extension_value("EXT_meshopt_compression").is_some();
        let mut room = |bytes: u64, what: &str| {
            total = total.saturating_add(bytes);
            crate::input::check_decoded(&format!("buffers read so far ({what})"), total, "bytes", 1).map_err(fail)
        };
        let data = match buffer.source() {
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let (_, payload) =
                    uri.split_once(";base64,").ok_or_else(|| fail("a data URI that is not base64".into()))?;
                base64::engine::general_purpose::STANDARD
                    .decode(payload)
                    .map_err(|e| fail(format!("bad base64 data: {e}")))?
            }
            gltf::buffer::Source::Uri(uri) => {
                let file = resolve_uri(path, uri).map_err(|e| fail(format!("URI '{uri}': {e}")))?;
                let size = std::fs::metadata(&file).map(|m| m.len()).unwrap_or(0);
                room(size, &format!("'{uri}'"))?;
                crate::input::read_file(&file).map_err(|e| fail(format!("URI '{uri}': {e}")))?
            }
            gltf::buffer::Source::Bin if buffer.index() == 0 && bin.is_some() => bin.take().unwrap_or_default(),
            gltf::buffer::Source::Bin if fallback => {
                room(len as u64, "an EXT_meshopt_compression fallback buffer")?;
                vec![0; len]
            }
            gltf::buffer::Source::Bin => return Err(fail("no data (no URI, and not a GLB's binary chunk)".into())),
        };
        if data.len() < len {
            return Err(fail(format!("{} bytes, its byteLength says {len}", data.len())));
        }
        out.push(data);
    }
    Ok(out)
}

/// The file a buffer URI names, confined to the model's folder: a relative reference, its
/// `%XX` escapes decoded, joined to the folder of `model`. Refused unless
/// [`crate::input::allow_outside_uris`] (`--allow-outside-uris`): an absolute path, a `..`
/// that leads out of the folder, and a path that leads out through a symlink (the
/// canonical paths compared). A URI with a scheme (`http:`, `https:`, `file://`, ...) is
/// refused always: Tessera reads no network and no other URI scheme.
fn resolve_uri(model: &Path, uri: &str) -> Result<std::path::PathBuf, String> {
    let scheme = uri.split_once(':').map(|(s, _)| s).filter(|s| {
        s.len() > 1
            && s.starts_with(|c: char| c.is_ascii_alphabetic())
            && s.chars().all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c))
    });
    if let Some(scheme) = scheme {
        let lower = scheme.to_ascii_lowercase();
        if lower == "http" || lower == "https" || uri[scheme.len() + 1..].starts_with("//") {
            return Err(format!("remote URIs are not supported ({lower}:); put the data beside the model"));
        }
    }
    let relative = percent_decode(uri);
    let folder = model.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let file = folder.join(&relative);
    if crate::input::allow_outside_uris() {
        return Ok(file);
    }
    let rel = Path::new(&relative);
    if rel.has_root() {
        return Err("an absolute path; buffers must lie in the model's folder (--allow-outside-uris allows it)".into());
    }
    let mut depth = 0i64;
    for c in rel.components() {
        match c {
            std::path::Component::ParentDir => depth -= 1,
            std::path::Component::Normal(_) => depth += 1,
            _ => {}
        }
        if depth < 0 {
            return Err("'..' leads out of the model's folder (--allow-outside-uris allows it)".into());
        }
    }
    // Symlinks: the file's canonical path must lie under the folder's. A file that does not
    // exist is reported by the read that follows.
    if let (Ok(dir), Ok(target)) = (std::fs::canonicalize(folder), std::fs::canonicalize(&file)) {
        if !target.starts_with(&dir) {
            return Err(format!(
                "a symlink leads out of the model's folder, to {} (--allow-outside-uris allows it)",
                target.display()
            ));
        }
    }
    Ok(file)
}

/// A relative URI's `%XX` escapes decoded (file names with spaces are written `%20`).
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (b[i], b.get(i + 1).copied().and_then(hex), b.get(i + 2).copied().and_then(hex)) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, _, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Decodes every `EXT_meshopt_compression` buffer view into its place in its (fallback)
/// buffer.
fn decode_meshopt_views(doc: &gltf::Document, buffers: &mut [Vec<u8>]) -> Result<(), String> {
    for view in doc.views() {
        let Some(ext) = view.extension_value("EXT_meshopt_compression") else { continue };
        let fail = |what: &str| format!("buffer view {}: EXT_meshopt_compression: {what}", view.index());
        let num = |key: &str| ext.get(key).and_then(|v| v.as_u64());
        let source = num("buffer").ok_or_else(|| fail("no buffer"))? as usize;
        let offset = num("byteOffset").unwrap_or(0) as usize;
        let length = num("byteLength").ok_or_else(|| fail("no byteLength"))? as usize;
        let stride = num("byteStride").ok_or_else(|| fail("no byteStride"))? as usize;
        let count = num("count").ok_or_else(|| fail("no count"))? as usize;
        let mode = ext.get("mode").and_then(|v| v.as_str()).ok_or_else(|| fail("no mode"))?;
        let filter = ext.get("filter").and_then(|v| v.as_str()).unwrap_or("NONE");
        let src = buffers
            .get(source)
            .and_then(|b| b.get(offset..offset.checked_add(length)?))
            .ok_or_else(|| fail("its compressed bytes lie outside their buffer"))?
            .to_vec();
        let size = count
            .checked_mul(stride)
            .filter(|&s| s <= view.length())
            .ok_or_else(|| fail("count x byteStride exceeds the view"))?;
        // The view's place in its buffer, checked before its decoded bytes are allocated.
        if buffers[view.buffer().index()].len().checked_sub(view.offset()).is_none_or(|room| room < size) {
            return Err(fail("the view lies outside its buffer"));
        }
        if stride == 0
            || stride > 256
            || (mode != "ATTRIBUTES" && stride != 2 && stride != 4)
            || !stride.is_multiple_of(4) && mode == "ATTRIBUTES"
        {
            return Err(fail(&format!("byteStride {stride} is not one the mode {mode} allows")));
        }
        let mut dst = vec![0u8; size];
        // SAFETY: `dst` holds `count * stride` bytes, the decoders write at most that many and
        // read at most `src.len()` bytes of `src`; they return non-zero on malformed input.
        let rc = unsafe {
            let d = dst.as_mut_ptr().cast();
            match mode {
                "ATTRIBUTES" => meshopt::ffi::meshopt_decodeVertexBuffer(d, count, stride, src.as_ptr(), src.len()),
                "TRIANGLES" if count.is_multiple_of(3) => {
                    meshopt::ffi::meshopt_decodeIndexBuffer(d, count, stride, src.as_ptr(), src.len())
                }
                "INDICES" => meshopt::ffi::meshopt_decodeIndexSequence(d, count, stride, src.as_ptr(), src.len()),
                _ => return Err(fail(&format!("mode {mode} with count {count}"))),
            }
        };
        if rc != 0 {
            return Err(fail(&format!("corrupt compressed data (decoder error {rc})")));
        }
        match (filter, stride) {
            ("NONE", _) => {}
            ("OCTAHEDRAL", 4) => filter_oct::<1>(&mut dst),
            ("OCTAHEDRAL", 8) => filter_oct::<2>(&mut dst),
            ("EXPONENTIAL", _) if stride.is_multiple_of(4) => filter_exp(&mut dst),
            _ => return Err(fail(&format!("filter {filter} with byteStride {stride}"))),
        }
        let target = buffers[view.buffer().index()]
            .get_mut(view.offset()..view.offset() + size)
            .ok_or_else(|| fail("the view lies outside its buffer"))?;
        target.copy_from_slice(&dst);
    }
    Ok(())
}

/// The octahedral filter of `EXT_meshopt_compression` on 4-component elements of `B`-byte
/// signed integers, as its specification writes it (the meshopt crate does not build
/// meshoptimizer's filter sources): x and y in octahedral encoding, the third component
/// holding 1, become a unit vector at the same scale; the fourth is left as it is.
fn filter_oct<const B: usize>(data: &mut [u8]) {
    let max = ((1i64 << (8 * B - 1)) - 1) as f32;
    let get = |d: &[u8], k: usize| -> f32 {
        if B == 1 {
            f32::from(d[k] as i8)
        } else {
            f32::from(i16::from_le_bytes([d[2 * k], d[2 * k + 1]]))
        }
    };
    for e in data.chunks_exact_mut(4 * B) {
        let (mut x, mut y) = (get(e, 0), get(e, 1));
        let z = get(e, 2) - x.abs() - y.abs();
        let t = z.min(0.0);
        x += if x >= 0.0 { t } else { -t };
        y += if y >= 0.0 { t } else { -t };
        let s = max / (x * x + y * y + z * z).sqrt();
        for (k, v) in [x, y, z].into_iter().enumerate() {
            let q = (v * s + if v >= 0.0 { 0.5 } else { -0.5 }) as i32;
            if B == 1 {
                e[k] = q as i8 as u8;
            } else {
                e[2 * k..2 * k + 2].copy_from_slice(&(q as i16).to_le_bytes());
            }
        }
    }
}

/// The exponential filter of `EXT_meshopt_compression`: each 32-bit value, a 24-bit signed
/// mantissa and an 8-bit signed exponent, becomes the `f32` `m * 2^e`.
fn filter_exp(data: &mut [u8]) {
    for v in data.chunks_exact_mut(4) {
        let u = u32::from_le_bytes([v[0], v[1], v[2], v[3]]);
        let m = ((u << 8) as i32) >> 8;
        let e = (u as i32) >> 24;
        let f = m as f32 * 2f32.powi(e);
        v.copy_from_slice(&f.to_le_bytes());
    }
}

/// One primitive's triangles, appended to `out` under the transform `world`.
fn read_primitive(
    doc: &gltf::Document,
    prim: &gltf::Primitive,
    buffers: &[Vec<u8>],
    world: &DMat4,
    out: &mut Loaded,
    attributes: &mut Attributes,
) -> Result<(), String> {
    let mode = prim.mode();
    if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
        out.ignored += 1;
        return Ok(());
    }
    let mut draco_attributes = None;
    let (positions, indices) = if let Some(draco) = prim.extension_value("KHR_draco_mesh_compression") {
        let d = read_draco(draco, doc, buffers)?;
        draco_attributes = Some((d.normals, d.colors));
        (d.positions, d.indices)
    } else {
        let acc = prim.get(&Semantic::Positions).ok_or("no POSITION attribute")?;
        if acc.dimensions() != Dimensions::Vec3 {
            return Err(format!("POSITION accessor {} is not VEC3", acc.index()));
        }
        // The running total (below) with this primitive's count, before its values are read.
        let vertices = out.mesh.positions.len() as u64 + acc.count() as u64;
        crate::input::check_decoded("the primitives read so far", vertices, "vertices", 28)?;
        let flat = read_accessor(&acc, buffers)?;
        let positions: Vec<[f64; 3]> = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let indices = match prim.indices() {
            Some(acc) if acc.dimensions() == Dimensions::Scalar && !acc.normalized() => {
                read_accessor(&acc, buffers)?.into_iter().map(|i| i as u32).collect()
            }
            Some(acc) => return Err(format!("index accessor {} is not an unsigned integer SCALAR", acc.index())),
            None => (0..positions.len() as u32).collect(),
        };
        (positions, indices)
    };
    let n = positions.len();
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(format!("index {bad}, but it has {n} vertices"));
    }
    // The whole model so far, with this primitive: each vertex takes a position, a normal and
    // a colour (28 bytes), each triangle 12. A mesh that many nodes instance is counted at
    // every instance.
    let vertices = out.mesh.positions.len() as u64 + n as u64;
    crate::input::check_decoded("the primitives read so far", vertices, "vertices", 28)?;
    let triangles = out.mesh.triangles.len() as u64 + indices.len() as u64;
    crate::input::check_decoded("the primitives read so far", triangles, "triangles at most", 12)?;
    let base = u32::try_from(out.mesh.positions.len())
        .ok()
        .filter(|b| b.checked_add(n as u32).is_some())
        .ok_or("more than 2^32 vertices")?;
    for (k, p) in positions.iter().enumerate() {
        let q = world.transform_point3(DVec3::from(*p)).to_array().map(|c| c as f32);
        if !q.iter().all(|c| c.is_finite()) {
            return Err(format!("vertex {k}: a non-finite position ({}, {}, {})", q[0], q[1], q[2]));
        }
        out.mesh.positions.push(q);
    }
    // Normals transform by the inverse transpose of the linear part.
    let linear = DMat3::from_mat4(*world);
    let (normals, colors) = match draco_attributes {
        Some(found) => found,
        None => {
            (read_optional(prim, Semantic::Normals, buffers, n)?, read_optional(prim, Semantic::Colors(0), buffers, n)?)
        }
    };
    match normals {
        Some(normals) => {
            let to_world = linear.inverse().transpose();
            for (k, v) in normals.iter().enumerate() {
                let m = (to_world * DVec3::new(v[0], v[1], v[2])).normalize_or_zero().to_array().map(|c| c as f32);
                if !m.iter().all(|c| c.is_finite()) {
                    return Err(format!("vertex {k}: a non-finite normal ({}, {}, {})", v[0], v[1], v[2]));
                }
                attributes.normals.push(m);
            }
        }
        None => {
            attributes.every_normal = false;
            attributes.normals.resize(out.mesh.positions.len(), [0.0; 3]);
        }
    }
    match colors {
        Some(colors) => {
            attributes.some_color = true;
            let byte = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
            attributes.colors.extend(colors.iter().map(|c| [byte(c[0]), byte(c[1]), byte(c[2]), byte(c[3])]));
        }
        None => attributes.colors.resize(out.mesh.positions.len(), [255; 4]),
    }
    // A negative determinant of the linear part: a mirroring transform.
    let mirror = linear.determinant() < 0.0;
    let mut push = |t: [u32; 3]| {
        let t = t.map(|i| base + i);
        out.mesh.triangles.push(if mirror { [t[0], t[2], t[1]] } else { t });
    };
    match mode {
        Mode::Triangles => indices.chunks_exact(3).for_each(|t| push([t[0], t[1], t[2]])),
        Mode::TriangleStrip => {
            for i in 0..indices.len().saturating_sub(2) {
                let odd = i % 2;
                push([indices[i], indices[i + 1 + odd], indices[i + 2 - odd]]);
            }
        }
        _ => {
            for i in 1..indices.len().saturating_sub(1) {
                push([indices[i], indices[i + 1], indices[0]]);
            }
        }
    }
    Ok(())
}

/// A Draco-compressed primitive's values: `NORMAL` or `COLOR_0` as [`read_optional`] gives
/// them (integers scaled to 0..1 where Draco marks them normalized).
type Values = Option<Vec<[f64; 4]>>;

/// What [`read_draco`] reads.
struct DracoPrimitive {
    positions: Vec<[f64; 3]>,
    indices: Vec<u32>,
    normals: Values,
    colors: Values,
}

/// A Draco-compressed primitive's positions and corner indices, and its normals and colours
/// where the stream has them.
fn read_draco(ext: &gltf::json::Value, doc: &gltf::Document, buffers: &[Vec<u8>]) -> Result<DracoPrimitive, String> {
    let fail = |what: &str| format!("KHR_draco_mesh_compression: {what}");
    let view_index = ext.get("bufferView").and_then(|v| v.as_u64()).ok_or_else(|| fail("no bufferView"))? as usize;
    let unique = ext
        .get("attributes")
        .and_then(|a| a.get("POSITION"))
        .and_then(|v| v.as_u64())
        .ok_or_else(|| fail("no POSITION attribute"))? as u32;
    let doc_view = doc.views().nth(view_index).ok_or_else(|| fail("its bufferView does not exist"))?;
    let bytes = view_bytes(&doc_view, buffers)?;
    let mut mesh = draco_core::Mesh::new();
    // Draco's own ceilings at the cap on decompressed input: its decoded values, and as many
    // points and faces as 12 bytes each of the cap hold.
    let cap = crate::input::max_decompressed_bytes();
    let limits = draco_core::DecodeLimits::default()
        .with_max_decoded_bytes(cap)
        .with_max_points(cap / 12)
        .with_max_faces(cap / 12);
    draco_core::MeshDecoder::new().decode(&mut draco_core::DecoderBuffer::new(bytes).with_limits(limits), &mut mesh).map_err(
        |e| {
            if e.kind() == draco_core::ErrorKind::LimitExceeded {
                fail(&format!(
                    "the Draco stream decodes to more than the cap on decompressed input allows ({}; raise it with --max-decompressed)",
                    one_line(&e.to_string())
                ))
            } else {
                fail(&format!("corrupt Draco stream ({})", one_line(&e.to_string())))
            }
        },
    )?;
    let attr = mesh.attribute_by_unique_id(unique).ok_or_else(|| fail("the stream has no POSITION attribute"))?;
    if attr.num_components() != 3 {
        return Err(fail("POSITION does not have three components"));
    }
    let flat = attr.read_f32s(mesh.num_points(), 3);
    let positions = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]].map(f64::from)).collect();
    let indices = mesh.faces().iter().flat_map(|f| f.map(|p| p.0)).collect();
    let optional = |name: &str, colour: bool| -> Result<Values, String> {
        let Some(id) = ext.get("attributes").and_then(|a| a.get(name)).and_then(|v| v.as_u64()) else {
            return Ok(None);
        };
        let attr = mesh.attribute_by_unique_id(id as u32).ok_or_else(|| fail(&format!("the stream has no {name}")))?;
        let comps = attr.num_components() as usize;
        if !(comps == 3 || (colour && comps == 4)) {
            return Err(fail(&format!("{name} has {comps} components")));
        }
        let scale = match (attr.normalized(), attr.data_type()) {
            (true, draco_core::DataType::Uint8) => 1.0 / 255.0,
            (true, draco_core::DataType::Uint16) => 1.0 / 65535.0,
            _ => 1.0,
        };
        let flat = attr.read_f32s(mesh.num_points(), comps);
        let value = |c: &[f32]| {
            let v = |i: usize| f64::from(c[i]) * scale;
            [v(0), v(1), v(2), if comps == 4 { v(3) } else { 1.0 }]
        };
        Ok(Some(flat.chunks_exact(comps).map(value).collect()))
    };
    Ok(DracoPrimitive { positions, indices, normals: optional("NORMAL", false)?, colors: optional("COLOR_0", true)? })
}

/// A message from a library on one line.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The bytes of a buffer view, checked against its buffer.
fn view_bytes<'b>(view: &gltf::buffer::View, buffers: &'b [Vec<u8>]) -> Result<&'b [u8], String> {
    let buffer = &buffers[view.buffer().index()];
    view.offset()
        .checked_add(view.length())
        .and_then(|end| buffer.get(view.offset()..end))
        .ok_or_else(|| format!("buffer view {} lies outside its buffer", view.index()))
}

/// An accessor's values, flattened, as `f64`: integers as they are, or mapped to [0, 1] or
/// [-1, 1] when normalized; zeros without a buffer view; sparse substitutions applied.
fn read_accessor(acc: &gltf::Accessor, buffers: &[Vec<u8>]) -> Result<Vec<f64>, String> {
    let comps = acc.dimensions().multiplicity();
    let ty = acc.data_type();
    let csize = ty.size();
    let elem = comps * csize;
    let count = acc.count();
    let total = count
        .checked_mul(comps)
        .filter(|&t| t <= 1 << 31)
        .ok_or_else(|| format!("accessor {}: count {count} is too large", acc.index()))?;
    // Checked before allocating: an accessor without a buffer view (zeros, or its sparse
    // values) costs nothing in the file whatever its count.
    crate::input::check_decoded(&format!("accessor {} (count {count})", acc.index()), total as u64, "values", 8)?;
    let mut out = vec![0f64; total];
    let read = |bytes: &[u8], k: usize| -> f64 {
        let b = &bytes[k * csize..];
        let norm = acc.normalized();
        match ty {
            DataType::I8 => {
                let v = f64::from(b[0] as i8);
                if norm {
                    (v / 127.0).max(-1.0)
                } else {
                    v
                }
            }
            DataType::U8 => {
                let v = f64::from(b[0]);
                if norm {
                    v / 255.0
                } else {
                    v
                }
            }
            DataType::I16 => {
                let v = f64::from(i16::from_le_bytes([b[0], b[1]]));
                if norm {
                    (v / 32767.0).max(-1.0)
                } else {
                    v
                }
            }
            DataType::U16 => {
                let v = f64::from(u16::from_le_bytes([b[0], b[1]]));
                if norm {
                    v / 65535.0
                } else {
                    v
                }
            }
            DataType::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            DataType::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        }
    };
    if let Some(view) = acc.view() {
        let stride = view.stride().unwrap_or(elem);
        let bytes = view_bytes(&view, buffers)?;
        let start = acc.offset();
        if count > 0 {
            let end = stride.checked_mul(count - 1).and_then(|s| s.checked_add(start + elem));
            if end.is_none_or(|e| e > bytes.len()) || stride < elem {
                return Err(format!("accessor {} reads past the end of buffer view {}", acc.index(), view.index()));
            }
        }
        for i in 0..count {
            let at = &bytes[start + i * stride..start + i * stride + elem];
            for c in 0..comps {
                out[i * comps + c] = read(at, c);
            }
        }
    }
    if let Some(sparse) = acc.sparse() {
        let n = sparse.count();
        if n > count {
            return Err(format!("accessor {}: sparse count {n} exceeds its count {count}", acc.index()));
        }
        let (iv, vv) = (sparse.indices().view(), sparse.values().view());
        let isize = match sparse.indices().index_type() {
            gltf::accessor::sparse::IndexType::U8 => 1,
            gltf::accessor::sparse::IndexType::U16 => 2,
            gltf::accessor::sparse::IndexType::U32 => 4,
        };
        let ib = view_bytes(&iv, buffers)?;
        let vb = view_bytes(&vv, buffers)?;
        let (io, vo) = (sparse.indices().offset(), sparse.values().offset());
        let fits = |off: usize, size: usize, len: usize| {
            n.checked_mul(size).and_then(|s| s.checked_add(off)).is_some_and(|e| e <= len)
        };
        if !fits(io, isize, ib.len()) || !fits(vo, elem, vb.len()) {
            return Err(format!("accessor {}: its sparse data lie outside their buffer views", acc.index()));
        }
        for k in 0..n {
            let b = &ib[io + k * isize..];
            let i = match isize {
                1 => b[0] as usize,
                2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            };
            if i >= count {
                return Err(format!("accessor {}: sparse index {i} of {count} elements", acc.index()));
            }
            let at = &vb[vo + k * elem..vo + (k + 1) * elem];
            for c in 0..comps {
                out[i * comps + c] = read(at, c);
            }
        }
    }
    Ok(out)
}
