//! Scaffolding shared by Tessera's tests, each piece once: where the shared meshes are, the
//! canonical form of a triangle set (orientation kept), a fixed-seed RNG, corruptions and
//! checksum refresh for the file formats' hostile tests, and the BFT round-trip check.
//! A dev-dependency of every crate; never part of a binary.

use std::path::{Path, PathBuf};

use codec::bft::{self, EncodeOptions, Encoded};
use codec::view::{Camera, TileBox, TileGrid};
use codec::{Mesh, Quantization};
use glam::Vec3;
use proptest::prelude::*;

/// `../shared/meshes`, next to the repository.
pub fn shared_meshes() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/meshes")
}

/// A shared mesh by its path under `shared/meshes`, e.g. `stanford/bunny_zipper_c3d.obj.gz`.
pub fn mesh_path(rel: &str) -> PathBuf {
    shared_meshes().join(rel)
}

/// [`mesh_path`] as a string, for command lines.
pub fn mesh_arg(rel: &str) -> String {
    mesh_path(rel).to_string_lossy().into_owned()
}

/// Loads a shared mesh, panicking with its name if it does not load.
pub fn load_mesh(rel: &str) -> Mesh {
    codec::load_path(&mesh_path(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The path under `shared/meshes` of the mesh file named like `rel`'s last component, in
/// whichever collection folder holds it.
pub fn find_mesh(rel: &str) -> String {
    let name = rel.rsplit('/').next().unwrap();
    for dir in std::fs::read_dir(shared_meshes()).expect("shared/meshes is next to the repo") {
        let p = dir.unwrap().path().join(name);
        if p.exists() {
            return p.strip_prefix(shared_meshes()).unwrap().display().to_string();
        }
    }
    panic!("{rel} not found under {}", shared_meshes().display());
}

/// Every mesh file under `shared/meshes`, sorted.
pub fn all_shared_meshes() -> Vec<PathBuf> {
    let mut out = vec![];
    for dir in std::fs::read_dir(shared_meshes()).expect("shared/meshes is next to the repo") {
        let dir = dir.unwrap().path();
        if !dir.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&dir).unwrap() {
            let f = f.unwrap().path();
            if codec::load::Format::from_path(&f).is_some() {
                out.push(f);
            }
        }
    }
    out.sort();
    out
}

/// A triangle rotated so its smallest index comes first: equal for equal triangles with
/// equal orientation.
pub fn canonical(t: [u32; 3]) -> [u32; 3] {
    let m = (0..3).min_by_key(|&i| t[i]).unwrap();
    [t[m], t[(m + 1) % 3], t[(m + 2) % 3]]
}

/// The sorted multiset of `tris` in [`canonical`] form: equal for equal triangle sets with
/// equal orientation.
pub fn sorted_canonical(tris: impl IntoIterator<Item = [u32; 3]>) -> Vec<[u32; 3]> {
    let mut v: Vec<_> = tris.into_iter().map(canonical).collect();
    v.sort_unstable();
    v
}

/// Encodes, decodes, and checks the round trip exactly: the decoded triangles, mapped back
/// to input vertex indices, are the input's multiset with orientation kept; every slot's
/// position is its input vertex quantized; the welded mesh has the same triangles by position.
pub fn assert_round_trip(mesh: &Mesh, bits: u8) -> Encoded {
    assert_round_trip_coded(mesh, bits, bft::Coding::Range)
}

/// [`assert_round_trip`] with the streams entropy-coded as `coding` says.
pub fn assert_round_trip_coded(mesh: &Mesh, bits: u8, coding: bft::Coding) -> Encoded {
    let enc = bft::encode(mesh, EncodeOptions { quant_bits: bits, coding, ..Default::default() }).expect("encodes");
    let dec = bft::decode(&enc.bytes).expect("decodes");
    assert_eq!(dec.header.coding, coding);
    assert_eq!(dec.triangles.len(), mesh.triangles.len());
    let back = dec.triangles.iter().map(|t| t.map(|s| enc.slot_vertex[s as usize]));
    assert!(
        sorted_canonical(back) == sorted_canonical(mesh.triangles.iter().copied()),
        "triangle multiset differs after the round trip"
    );
    let used = mesh.used_vertices();
    let q = Quantization::fit(&mesh.positions, Some(&used), bits).unwrap();
    assert_eq!(dec.quantization(), q);
    for (slot, p) in dec.positions.iter().enumerate() {
        assert_eq!(*p, q.quantize(mesh.positions[enc.slot_vertex[slot] as usize]), "slot {slot}");
    }
    for &(slot, source) in &dec.duplicates {
        assert_eq!(enc.slot_vertex[slot as usize], enc.slot_vertex[source as usize]);
    }
    // Attributes, exact at their quantization: colours as they were, normals as their
    // octahedral codes.
    let a = &dec.attributes;
    assert_eq!(a.colors.len(), if mesh.colors.is_empty() { 0 } else { dec.positions.len() });
    for (slot, c) in a.colors.iter().enumerate() {
        let want = mesh.colors[enc.slot_vertex[slot] as usize];
        assert_eq!(*c, if a.alpha { want } else { [want[0], want[1], want[2], 255] }, "colour of slot {slot}");
    }
    assert_eq!(a.alpha, used_alpha(mesh));
    assert_eq!(a.normals.len(), if mesh.normals.is_empty() { 0 } else { dec.positions.len() });
    for (slot, n) in a.normals.iter().enumerate() {
        let want = bft::attributes::oct_encode(mesh.normals[enc.slot_vertex[slot] as usize], a.normal_bits);
        assert_eq!(*n, want, "normal of slot {slot}");
    }
    // The welded mesh: one vertex per used input vertex, triangles equal by position.
    let welded = dec.to_mesh();
    assert_eq!(welded.positions.len(), used.iter().filter(|&&u| u).count());
    let key = |m: &Mesh, t: [u32; 3]| t.map(|i| m.positions[i as usize].map(f32::to_bits));
    let mut a: Vec<_> = welded.triangles.iter().map(|&t| rotate_min(key(&welded, t))).collect();
    let mut b: Vec<_> = mesh
        .triangles
        .iter()
        .map(|&t| rotate_min(t.map(|i| q.dequantize(q.quantize(mesh.positions[i as usize])).map(f32::to_bits))))
        .collect();
    a.sort_unstable();
    b.sort_unstable();
    assert!(a == b, "welded mesh differs by position");
    enc
}

/// Whether a used vertex has an alpha below 255 (unused vertices are not coded).
fn used_alpha(mesh: &Mesh) -> bool {
    let used = mesh.used_vertices();
    mesh.colors.iter().zip(&used).any(|(c, &u)| u && c[3] != 255)
}

/// `mesh` with colours and normals a scan might carry: colours a smooth function of
/// position plus a little sensor noise (alpha too when `alpha`), normals the area-weighted
/// vertex normals plus a little noise.
pub fn paint(mut mesh: Mesh, alpha: bool, seed: u64) -> Mesh {
    let mut rng = XorShift(seed | 1);
    let (lo, hi) = codec::mesh::bounding_box(&mesh.positions).unwrap_or(([0.0; 3], [1.0; 3]));
    let normals = bft::normals::vertex_normals(&mesh.positions, &mesh.triangles, &[]);
    mesh.colors = mesh
        .positions
        .iter()
        .map(|p| {
            let t = |a: usize| if hi[a] > lo[a] { (p[a] - lo[a]) / (hi[a] - lo[a]) } else { 0.5 };
            let mut noise = || (rng.unit() * 6.0 - 3.0) as i32;
            let c = |v: f32, n: i32| ((v * 255.0) as i32 + n).clamp(0, 255) as u8;
            let a = if alpha { c(0.5 + 0.5 * (6.0 * t(0)).sin(), 0) } else { 255 };
            [c(t(0), noise()), c(0.5 + 0.4 * (4.0 * t(1)).sin(), noise()), c(1.0 - t(2), noise()), a]
        })
        .collect();
    mesh.normals =
        normals.iter().map(|n| [n[0] + 0.02 * (rng.unit() - 0.5), n[1] + 0.02 * (rng.unit() - 0.5), n[2]]).collect();
    mesh
}

/// The lexicographically smallest rotation: canonical even when entries repeat.
fn rotate_min<T: Ord + Copy>(t: [T; 3]) -> [T; 3] {
    [[t[0], t[1], t[2]], [t[1], t[2], t[0]], [t[2], t[0], t[1]]].into_iter().min().unwrap()
}

/// A fixed-seed xorshift64 generator: the same sequence every run.
pub struct XorShift(pub u64);

impl XorShift {
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.0;
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        *s
    }

    /// A number in `[0, 1)` from the next value's top 24 bits.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// `len` bytes, the low byte of each next value.
    pub fn bytes(&mut self, len: usize) -> Vec<u8> {
        (0..len).map(|_| self.next_u64() as u8).collect()
    }
}

/// `copies` bumpy grids of `w x h` quads (two triangles each), the triangle `k` of each left
/// out where `holes[k % holes.len()]`, at offsets from each other (so many components): the
/// random meshes of the tile sort's property tests.
pub fn holed_grids(w: usize, h: usize, copies: usize, holes: &[bool], seed: u64) -> Mesh {
    let mut mesh = Mesh::default();
    for k in 0..copies {
        let base = mesh.positions.len() as u32;
        let mut rng = XorShift(seed.wrapping_add(k as u64) | 1);
        for y in 0..=h {
            for x in 0..=w {
                let p = [x as f32 / w as f32 - 0.5, y as f32 / h as f32 - 0.5, rng.unit() * 0.3];
                mesh.positions.push([p[0] + k as f32 * 0.7, p[1] - k as f32 * 0.4, p[2]]);
            }
        }
        let id = |x: usize, y: usize| base + (y * (w + 1) + x) as u32;
        let mut t = 0;
        for y in 0..h {
            for x in 0..w {
                for tri in [[id(x, y), id(x + 1, y), id(x + 1, y + 1)], [id(x, y), id(x + 1, y + 1), id(x, y + 1)]] {
                    if !holes[t % holes.len()] {
                        mesh.triangles.push(tri);
                    }
                    t += 1;
                }
            }
        }
    }
    mesh
}

/// Cameras around a bounding box: the default framing, an oblique view with the model partly
/// off-screen, a close-up from inside the box (triangles cross the near plane), and the
/// framing through an off-axis (shifted) window.
pub fn cameras_around(bbox_min: [f32; 3], bbox_max: [f32; 3], aspect: f32) -> Vec<Camera> {
    let (lo, hi) = (Vec3::from(bbox_min), Vec3::from(bbox_max));
    let (center, size) = ((lo + hi) * 0.5, (hi - lo).length());
    let framed = Camera::framing(bbox_min, bbox_max, aspect);
    let offside = Camera { target: center + Vec3::new(size * 0.45, size * 0.2, 0.0), ..framed };
    let inside = Camera {
        eye: center + Vec3::new(0.1, 0.05, 0.3) * size,
        target: center - Vec3::new(0.2, 0.1, 0.4) * size,
        up: Vec3::Y,
        fovy: 70.0,
        near: size * 0.01,
        far: size * 4.0,
        shift: [0.0; 2],
    };
    // Off-axis: a shifted window (a wall display seen from off its centre).
    let off_axis = Camera { shift: [0.4, -0.25], ..framed };
    vec![framed, offside, inside, off_axis]
}

/// Per tile of `grid`, the triangles (in [`canonical`] form) whose box `[t]` holds it: what
/// an exact tile sort must give each tile.
pub fn triangles_by_tile(triangles: &[[u32; 3]], boxes: &[TileBox], grid: &TileGrid) -> Vec<Vec<[u32; 3]>> {
    let mut tiles = vec![Vec::new(); grid.tiles()];
    for (t, b) in triangles.iter().zip(boxes) {
        if b.is_empty() {
            continue;
        }
        for r in b.r0..=b.r1 {
            for c in b.c0..=b.c1 {
                tiles[r as usize * grid.cols as usize + c as usize].push(canonical(*t));
            }
        }
    }
    tiles
}

/// Positions on a coarse grid so coincident and collinear vertices (zero-area faces) occur.
pub fn grid_positions(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = XorShift(seed | 1);
    let mut next = move || ((rng.next_u64() >> 40) % 4) as f32;
    (0..n).map(|_| [next(), next(), next()]).collect()
}

/// A triangle soup over a few vertex blocks (components), with degenerate triangles,
/// duplicates and reversed duplicates, and fans of triangles around one edge (non-manifold).
pub fn soup() -> impl Strategy<Value = Mesh> {
    (1usize..4, 2usize..24, any::<u64>())
        .prop_flat_map(|(blocks, per_block, seed)| {
            let n = (blocks * per_block) as u32;
            let tri = (0..blocks as u32, 0..per_block as u32, 0..per_block as u32, 0..per_block as u32, 0u8..10);
            (Just((n, per_block as u32, seed)), proptest::collection::vec(tri, 0..60))
        })
        .prop_map(|((n, per_block, seed), raw)| {
            let mut triangles: Vec<[u32; 3]> = vec![];
            for (block, a, b, c, kind) in raw {
                let o = block * per_block;
                let t = match kind {
                    0 => [o + a, o + a, o + b],
                    1 => [o + a, o + a, o + a],
                    2 if !triangles.is_empty() => triangles[(a + b) as usize % triangles.len()],
                    3 if !triangles.is_empty() => {
                        let [x, y, z] = triangles[(a + c) as usize % triangles.len()];
                        [z, y, x]
                    }
                    4 => [o, o + 1 % per_block, o + c],
                    _ => [o + a, o + b, o + c],
                };
                triangles.push(t);
            }
            Mesh::new(grid_positions(n as usize, seed), triangles)
        })
}

/// `count` copies of `bytes`, each with 1 to 3 random bits flipped (a fixed-seed xorshift,
/// so the corruptions are the same every run). A copy can equal the original when two
/// flips cancel.
pub fn bit_flipped_copies(bytes: &[u8], count: usize) -> Vec<Vec<u8>> {
    let mut rng = XorShift(0x9E37_79B9_7F4A_7C15);
    let mut next = || rng.next_u64();
    (0..count)
        .map(|_| {
            let mut b = bytes.to_vec();
            for _ in 0..1 + next() % 3 {
                let i = (next() % b.len() as u64) as usize;
                b[i] ^= 1 << (next() % 8);
            }
            b
        })
        .collect()
}

/// Recomputes the CRC-32 of every section of a `.bft` or `.dpm` container from `pos` (the
/// first section's tag) on, so that a corruption inside a section reaches its decoder. Stops
/// at a section whose length runs past the end.
pub fn refresh_checksums(b: &mut [u8], mut pos: usize) {
    while pos + 8 <= b.len() {
        let n = u32::from_le_bytes(b[pos + 4..pos + 8].try_into().unwrap()) as usize;
        let start = pos + 8;
        if start + n + 4 > b.len() {
            return;
        }
        let crc = crc32fast::hash(&b[start..start + n]);
        b[start + n..start + n + 4].copy_from_slice(&crc.to_le_bytes());
        pos = start + n + 4;
    }
}

/// Rewrites a `.bft` or `.dpm` container's header field (4 bytes at `offset` in the header)
/// and the header's checksum, so that only the field is wrong.
pub fn patch_header(bytes: &mut [u8], offset: usize, value: [u8; 4]) {
    let hlen = u16::from_le_bytes([bytes[10], bytes[11]]) as usize;
    bytes[12 + offset..16 + offset].copy_from_slice(&value);
    let crc = crc32fast::hash(&bytes[12..12 + hlen]);
    bytes[12 + hlen..16 + hlen].copy_from_slice(&crc.to_le_bytes());
}

/// Where a container's first section starts: after the 12-byte prefix, the header and its CRC.
pub fn sections_start(b: &[u8]) -> usize {
    12 + u16::from_le_bytes([b[10], b[11]]) as usize + 4
}

/// A path as a `&str`, for command lines.
pub fn arg(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// A finished command's standard error, as text.
pub fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}
