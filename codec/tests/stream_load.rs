//! The streaming reader (`codec::load::stream`) gives exactly what `load_path` gives: on
//! every shared PLY and OBJ mesh, on small hand-written files that reach the corners of
//! both formats, and on thousands of corrupted copies of them (where both must refuse the
//! same files). Plus an ignored timing test (`stream_timings`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use codec::load::load_path_streamed_counted;
use codec::load::stream::{can_stream, for_each_triangle, read_positions};
use codec::{load_path, LoadError, Mesh};
use testkit::{all_shared_meshes, mesh_path, XorShift};

/// Reads a mesh with the streaming reader, checking that progress only grows and stays
/// within what the passes read.
fn stream(path: &Path) -> Result<Mesh, LoadError> {
    let len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    let progress = || {
        let mut last = 0;
        move |n: u64| {
            assert!(n >= last && n <= 2 * len, "{}: progress {n} after {last}", path.display());
            last = n;
        }
    };
    let positions = read_positions(path, &mut progress())?;
    let mut triangles = Vec::new();
    let mut collect = |t| {
        triangles.push(t);
        Ok(())
    };
    let count = for_each_triangle(path, &positions, &mut collect, &mut progress())?.triangles;
    assert_eq!(count, triangles.len() as u64);
    Ok(Mesh::new(positions, triangles))
}

/// Whether two meshes are the same to the bit (NaN equal to itself, -0 unequal to 0).
fn identical(a: &Mesh, b: &Mesh) -> bool {
    let bits = |m: &Mesh| m.positions.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
    a.triangles == b.triangles && bits(a) == bits(b)
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, bytes).unwrap();
    gz.finish().unwrap()
}

/// A temporary folder for a test's files.
struct Files(tempfile::TempDir);

impl Files {
    fn new() -> Self {
        Files(tempfile::tempdir().unwrap())
    }

    fn put(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let path = self.0.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    }

    /// Writes `bytes` as `name` and as `name.gz`; both readers must agree on both and
    /// load them; returns the mesh.
    fn same(&self, name: &str, bytes: &[u8]) -> Mesh {
        let mesh = load_path(&self.put(name, bytes)).unwrap_or_else(|e| panic!("load_path: {e}"));
        for (name, bytes) in [(name.to_string(), bytes.to_vec()), (format!("{name}.gz"), gzip(bytes))] {
            let streamed = stream(&self.put(&name, &bytes)).unwrap_or_else(|e| panic!("stream: {e}"));
            assert!(identical(&streamed, &mesh), "{name}:\nstream {streamed:?}\nload_path {mesh:?}");
            let loaded = load_path_streamed_counted(&self.put(&name, &bytes)).unwrap_or_else(|e| panic!("{e}"));
            assert!(identical(&loaded.mesh, &mesh), "{name}: load_path_streamed_counted differs");
        }
        mesh
    }

    /// Writes `bytes` as `name`; both readers must refuse it. Returns the streaming
    /// reader's message.
    fn refused(&self, name: &str, bytes: &[u8]) -> String {
        let path = self.put(name, bytes);
        if let Ok(m) = load_path(&path) {
            panic!("load_path read {name}: {m:?}");
        }
        let e = stream(&path).expect_err(name).to_string();
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        let whole = load_path_streamed_counted(&path).expect_err(name).to_string();
        assert!(whole.starts_with(&path.display().to_string()) && !whole.contains('\n'), "{whole}");
        assert!(!e.contains('\n'), "{e}");
        e
    }
}

#[test]
fn every_shared_ply_and_obj_mesh_streams_as_load_path_reads_it() {
    let files: Vec<_> = all_shared_meshes().into_iter().filter(|p| can_stream(p)).collect();
    assert!(files.len() >= 50, "expected the shared PLY and OBJ meshes, found {}", files.len());
    for path in files {
        let mesh = load_path(&path).unwrap();
        let streamed = stream(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(streamed.positions.len(), mesh.positions.len(), "{}", path.display());
        assert!(identical(&streamed, &mesh), "{}: the meshes differ", path.display());
        // What `tessera pm build` loads with: the same mesh, not holding the file.
        let loaded = load_path_streamed_counted(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(loaded, codec::load::load_path_counted(&path).unwrap(), "{}", path.display());
    }
}

#[test]
fn only_ply_and_obj_stream() {
    assert!(can_stream(Path::new("a/b.PLY")) && can_stream(Path::new("x.obj.gz")));
    assert!(!can_stream(Path::new("x.stl")) && !can_stream(Path::new("x.off")));
    let e = read_positions(&mesh_path("missing.stl"), &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("PLY and OBJ"), "{e}");
    // By content, whatever the name says: a PLY named .stl streams, an STL named .obj not.
    let files = Files::new();
    assert!(can_stream(&files.put("p.stl", ASCII_PLY.as_bytes())));
    assert!(!can_stream(&files.put("s.obj", b"solid x\nendsolid x\n")));
}

const ASCII_PLY: &str = "ply\r\nformat ascii 1.0\r\ncomment by hand\r\nobj_info none\r\n\
element vertex 6\r\nproperty float x\r\nproperty float y\r\nproperty double z\r\nproperty uchar red\r\n\
element face 4\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
0 0 0 255\r\n3 0 0 0 7 7\r\n3 1 0 1\r\n1 1 0.5e-1 2\r\n 1 2 -0 3 \r\n0 2 1e2 4\r\n\
6 0 1 2 3 4 5\r\n3 0 1 2\r\n2 -7 1\r\n4 5 4 3 2\r\n";

#[test]
fn ascii_ply() {
    let files = Files::new();
    let m = files.same("a.ply", ASCII_PLY.as_bytes());
    assert_eq!(m.positions.len(), 6);
    assert_eq!(m.positions[3], [1.0, 1.0, 0.05]);
    // The hexagon's triangles, the triangle, (the 2-corner face is dropped), the quad's.
    assert!(m.triangles.len() >= 4 + 1 + 2, "{:?}", m.triangles);
    assert_eq!(&m.triangles[m.triangles.len() - 3..], &[[0, 1, 2], [5, 4, 3], [5, 3, 2]]);
}

/// Binary PLY in either byte order, built value by value.
struct Binary {
    big: bool,
    bytes: Vec<u8>,
}

macro_rules! put {
    ($name:ident, $t:ty) => {
        fn $name(&mut self, v: $t) -> &mut Self {
            let b = if self.big { v.to_be_bytes() } else { v.to_le_bytes() };
            self.bytes.extend_from_slice(&b);
            self
        }
    };
}

impl Binary {
    fn new(header: &str) -> Self {
        let big = header.contains("binary_big_endian");
        Binary { big, bytes: header.as_bytes().to_vec() }
    }
    put!(i8, i8);
    put!(u8, u8);
    put!(i16, i16);
    put!(u16, u16);
    put!(i32, i32);
    put!(u32, u32);
    put!(f32, f32);
    put!(f64, f64);
}

/// Big-endian, a type of every size for the coordinates, extra properties around them,
/// faces by `vertex_index` with a ushort count and uint indices, and a property after them.
fn big_endian_odd_types() -> Vec<u8> {
    let mut b = Binary::new(
        "ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty int8 flag\nproperty float64 x\n\
property short y\nproperty uchar z\nproperty float32 confidence\nelement face 3\n\
property list ushort uint vertex_index\nproperty uchar kind\nend_header\n",
    );
    for (i, (x, y, z)) in
        [(0.5, -3, 0), (2.0, 0, 0), (2.0, 2, 0), (0.0, 2, 0), (-1e10, i16::MIN, 255)].into_iter().enumerate()
    {
        b.i8(-(i as i8)).f64(x).i16(y).u8(z).f32(1.0 / 3.0);
    }
    b.u16(4).u32(0).u32(1).u32(2).u32(3).u8(9);
    b.u16(3).u32(4).u32(0).u32(1).u8(9);
    b.u16(1).u32(70_000).u8(9);
    b.bytes
}

/// Little-endian, an element before the vertices and one between them and the faces, each
/// with lists; a list among the vertex properties; faces by `vertex_indices` with a char
/// count, a float list of the same name ignored; strips after the faces.
fn little_endian_with_lists() -> Vec<u8> {
    let mut b = Binary::new(
        "ply\nformat binary_little_endian 1.0\nelement material 2\nproperty list uchar uchar name\n\
property float shine\nelement vertex 4\nproperty float x\nproperty float y\nproperty list uchar float normal\n\
property float z\nproperty uint16 id\nelement edge 1\nproperty int vertex1\nproperty int32 vertex2\n\
element face 2\nproperty list uint8 float vertex_index\nproperty list char int16 vertex_indices\n\
element tristrips 1\nproperty list int int vertex_indices\nend_header\n",
    );
    b.u8(3).u8(b'r').u8(b'e').u8(b'd').f32(0.5);
    b.u8(0).f32(0.25);
    for (i, p) in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]].iter().enumerate() {
        b.f32(p[0]).f32(p[1]).u8(i as u8);
        for _ in 0..i {
            b.f32(9.0);
        }
        b.f32(p[2]).u16(i as u16);
    }
    b.i32(0).i32(1);
    b.u8(1).f32(0.0).i8(4).i16(0).i16(1).i16(2).i16(3);
    b.u8(0).i8(2).i16(-1).i16(5);
    b.i32(8).i32(0).i32(1).i32(2).i32(3).i32(-1).i32(3).i32(2).i32(1);
    b.bytes
}

/// Little-endian with the usual layout (faces with only their corner list), which the
/// reader decodes on a faster path: a triangle, a quad, a dropped 2-corner face with a
/// negative index, a concave pentagon.
fn little_endian_usual() -> Vec<u8> {
    let mut b = Binary::new(
        "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for p in [[0.0f32, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 2.0, 0.0], [1.0, 0.5, 0.0], [0.0, 2.0, 0.0]] {
        b.f32(p[0]).f32(p[1]).f32(p[2]);
    }
    b.u8(3).i32(0).i32(1).i32(2);
    b.u8(4).i32(0).i32(1).i32(2).i32(4);
    b.u8(2).i32(-5).i32(1);
    b.u8(5).i32(0).i32(1).i32(2).i32(3).i32(4);
    b.bytes
}

#[test]
fn binary_ply_little_endian_usual_layout() {
    let files = Files::new();
    let bytes = little_endian_usual();
    let m = files.same("u.ply", &bytes);
    assert_eq!(&m.triangles[..3], &[[0, 1, 2], [0, 1, 2], [0, 2, 4]]);
    assert_eq!(m.triangles.len(), 3 + 3, "the pentagon is concave at corner 3: 3 triangles");
    // Errors in the last face and in the first.
    let last = bytes.len() - 4;
    for (at, bad, what) in
        [(last, 5, "element 'face' 3 uses vertex 5"), (last, -2, "element 'face' 3: vertex index -2")]
    {
        let mut b = bytes.clone();
        b[at..].copy_from_slice(&i32::to_le_bytes(bad));
        let e = files.refused("u.ply", &b);
        assert!(e.contains(what), "{e}");
    }
    let first = bytes.len() - 4 * 14 - 4 + 1;
    let mut b = bytes.clone();
    b[first..first + 4].copy_from_slice(&i32::to_le_bytes(9));
    let e = files.refused("u.ply", &b);
    assert!(e.contains("element 'face' 0 uses vertex 9"), "{e}");
}

#[test]
fn binary_ply_big_endian_with_odd_types() {
    let m = Files::new().same("b.ply", &big_endian_odd_types());
    assert_eq!(m.positions[0], [0.5, -3.0, 0.0]);
    assert_eq!(m.positions[4], [-1e10, -32768.0, 255.0]);
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [4, 0, 1]]);
}

#[test]
fn binary_ply_with_lists_and_other_elements() {
    let m = Files::new().same("l.ply", &little_endian_with_lists());
    assert_eq!(m.positions, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]]);
    // The strip's triangles come first, as load_path orders them, then the quad's.
    assert_eq!(m.triangles, vec![[0, 1, 2], [2, 1, 3], [3, 2, 1], [0, 1, 2], [0, 2, 3]]);
}

#[test]
fn faces_before_strips_are_read_in_a_second_pass() {
    let mut b = Binary::new(
        "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nelement face 1\nproperty list uchar int vertex_indices\nelement tristrips 1\n\
property list int int vertex_indices\nend_header\n",
    );
    for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]] {
        b.f32(p[0]).f32(p[1]).f32(p[2]);
    }
    b.u8(3).i32(3).i32(2).i32(1);
    b.i32(4).i32(0).i32(1).i32(2).i32(3);
    let m = Files::new().same("fs.ply", &b.bytes);
    assert_eq!(m.triangles, vec![[0, 1, 2], [2, 1, 3], [3, 2, 1]]);
}

#[test]
fn truncated_binary_ply_is_an_error_at_every_length() {
    let files = Files::new();
    for bytes in [big_endian_odd_types(), little_endian_with_lists(), little_endian_usual()] {
        let header = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        for len in 0..bytes.len() {
            let e = files.refused("t.ply", &bytes[..len]);
            if len >= header {
                assert!(e.contains("truncated PLY") && e.contains("element '"), "{len}: {e}");
            }
        }
    }
}

const OBJ: &str = "# by hand\nmtllib none.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 2 0 2\nvt 0 0\nvt 1 0\nvn 0 0 1\n\
f -4/-2/-1 -3/-1/-1 -2//-1\nf 1/1 3/2/1 4//1\nusemtl none\nl 2 3\nf 2\n\
v 9 9 9\n\
o second\nf 5 1 2\nf 6 5 7 8\nv 0 0 1\nv 3 0 0\nv 3 1 0\n\
g third # shares vertices 1, 2 with the other objects\ng\nf 1 2 8 7\ns 1\nf 3 1 2 4 5\n";

#[test]
fn obj_relative_indices_objects_points_and_lines() {
    let files = Files::new();
    let m = files.same("o.obj", OBJ.as_bytes());
    // Each object has the vertices its faces use, in the order of first use; vertex 9 9 9
    // (5) comes only in the second object, which also uses 6 to 8 before their lines.
    assert_eq!(m.positions.len(), 4 + 6 + 7);
    assert_eq!(m.positions[3], [0.0, 1.0, 0.0], "w divides the position");
    assert_eq!(m.positions[4], [9.0, 9.0, 9.0]);
    // The line `l 2 3` and the point `f 2` are skipped, not made triangles without area.
    assert_eq!(&m.triangles[..3], &[[0, 1, 2], [0, 2, 3], [4, 5, 6]]);
    assert!(m.triangles.iter().all(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]), "{:?}", m.triangles);
    // Colours on every vertex or on some only; comments after values; texture and normal
    // indices out of range (the positions are what is read).
    let a = files.same("c.obj", b"v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n");
    let b = files.same("c2.obj", b"v 0 0 0\nv 1 0 0 0 1 0 # red\nv 0 1 0\nvt 0 0\nf 1/1/9 2/7 3//4 # one\n");
    assert!(identical(&a, &b));
}

#[test]
fn out_of_range_indices_name_the_face() {
    let files = Files::new();
    let ply = ASCII_PLY.replace("3 0 1 2\r\n", "3 0 1 6\r\n");
    let e = files.refused("r.ply", ply.as_bytes());
    assert!(e.contains("line 20, element 'face' 1 uses vertex 6, but the file has only 6 vertices"), "{e}");
    let e = files.refused("n.ply", ASCII_PLY.replace("3 0 1 2\r\n", "3 0 -1 2\r\n").as_bytes());
    assert!(e.contains("element 'face' 1: vertex index -1 is out of range"), "{e}");
    let mut b = big_endian_odd_types();
    let at = b.len() - 20;
    b[at..at + 4].copy_from_slice(&5u32.to_be_bytes());
    let e = files.refused("r2.ply", &b);
    assert!(e.contains("element 'face' 1 uses vertex 5, but the file has only 5 vertices"), "{e}");
    let e = files.refused("r.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n");
    assert!(e.contains("line 5: a face uses vertex 9, but the file has 3 vertices"), "{e}");
    let e = files.refused("r2.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n");
    assert!(e.contains("line 4: a face uses vertex index 0 or none"), "{e}");
}

#[test]
fn positions_of_another_file_are_refused() {
    let path = mesh_path("odedstein/cube.obj");
    let mut nothing = |_| Ok(());
    let e = for_each_triangle(&path, &[[0.0; 3]; 3], &mut nothing, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("not this file's"), "{e}");
    let e = for_each_triangle(&mesh_path("classic/horse.ply.gz"), &[], &mut nothing, &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("not this file's"), "{e}");
}

#[test]
fn an_error_from_the_callback_stops_the_pass() {
    let path = mesh_path("classic/horse.ply.gz");
    let positions = read_positions(&path, &mut |_| {}).unwrap();
    let mut seen = 0;
    let mut stop = |_| {
        seen += 1;
        if seen == 10 {
            return Err(LoadError { path: "caller".into(), message: "enough".into() });
        }
        Ok(())
    };
    let e = for_each_triangle(&path, &positions, &mut stop, &mut |_| {}).unwrap_err();
    assert_eq!((e.to_string().as_str(), seen), ("caller: enough", 10));
}

/// A copy of `text` with one to three edits: a word replaced by a tricky one, a line
/// repeated or removed, a byte changed, or the end cut off.
fn mutated(text: &[u8], rng: &mut XorShift) -> Vec<u8> {
    const WORDS: &[&str] = &[
        "0",
        "1",
        "-1",
        "2",
        "3",
        "9",
        "-4",
        "0.5",
        "1e5",
        "1.",
        ".5",
        "nan",
        "inf",
        "x",
        "",
        "1/1",
        "1//1",
        "2/9/1",
        "1/2/3/4",
        "1/x",
        "v",
        "vt",
        "vn",
        "f",
        "l",
        "o",
        "g",
        "usemtl",
        "#",
        "255",
        "65536",
        "-129",
        "4294967296",
        "+3",
        "element",
        "property",
        "float",
        "uchar",
        "list",
        "vertex",
        "face",
        "tristrips",
        "vertex_indices",
        "end_header",
        "comment",
        "ascii",
        "binary_little_endian",
        "binary_big_endian",
        "format",
        "double",
        "int",
        "obj_info",
        "x",
        "y",
        "z",
        "vertex_index",
        "-2/-1/-1",
        "f 1 2 3\n",
        "v 1 2 3\n",
        "3 0 1 2\n",
        "0/1",
        "1//",
        "usemtl x",
        "o x",
        "1 2 3 4 5 6 7",
        "element vertex 1\n",
        "property list uchar int vertex_indices\n",
        "-0",
        "1e-50",
        "3.4e39",
        "65535",
        "\r",
        "\t",
        "1 2",
    ];
    let mut b = text.to_vec();
    for _ in 0..1 + rng.next_u64() % 3 {
        let r = rng.next_u64();
        let at = (rng.next_u64() % (b.len() as u64 + 1)) as usize;
        let word_end =
            |from: usize| b[from..].iter().position(|c| c.is_ascii_whitespace()).map_or(b.len(), |k| from + k);
        let line_start = b[..at].iter().rposition(|&c| c == b'\n').map_or(0, |k| k + 1);
        let line_end = b[at..].iter().position(|&c| c == b'\n').map_or(b.len(), |k| at + k + 1);
        match r % 8 {
            0..=3 => {
                let start = b[..at].iter().rposition(|c| c.is_ascii_whitespace()).map_or(0, |k| k + 1);
                let word = WORDS[(r >> 8) as usize % WORDS.len()].as_bytes().to_vec();
                let end = word_end(start);
                b.splice(start..end, word);
            }
            4 => {
                let line = b[line_start..line_end].to_vec();
                b.splice(line_start..line_start, line);
            }
            5 => {
                b.drain(line_start..line_end);
            }
            6 if at < b.len() => b[at] = (r >> 8) as u8,
            _ => b.truncate(at),
        }
    }
    b
}

#[test]
fn corrupted_files_are_read_alike_or_refused_alike() {
    let files = Files::new();
    let bases: [(&str, Vec<u8>); 6] = [
        ("m.ply", ASCII_PLY.as_bytes().to_vec()),
        ("m.ply", ASCII_PLY.replace("face 4", "tristrips 1").replace("6 0 1 2 3 4 5", "7 0 1 2 -1 3 4 5").into_bytes()),
        ("m.ply", big_endian_odd_types()),
        ("m.ply", little_endian_with_lists()),
        ("m.ply", little_endian_usual()),
        ("m.obj", OBJ.as_bytes().to_vec()),
    ];
    let mut rng = XorShift(0x5EED_0F57_12EA);
    let (mut loaded, mut refused) = (0, 0);
    for (name, base) in &bases {
        for _ in 0..600 {
            let bytes = mutated(base, &mut rng);
            let path = files.put(name, &bytes);
            // ply-rs panics on some headers (a count beyond u64); nothing to compare then.
            let Ok(expected) = std::panic::catch_unwind(|| load_path(&path)) else { continue };
            let text = String::from_utf8_lossy(&bytes);
            match (expected, stream(&path)) {
                (Ok(m), Ok(s)) => {
                    assert!(identical(&m, &s), "{name} read differently:\n{text}\nload_path {m:?}\nstream {s:?}");
                    loaded += 1;
                }
                (Err(_), Err(e)) => {
                    assert!(!e.to_string().contains('\n'), "{e}");
                    refused += 1;
                }
                (Ok(m), Err(e)) => panic!("{name}: only load_path reads it ({e}):\n{text}\n{m:?}"),
                (Err(e), Ok(s)) => panic!("{name}: only the stream reads it ({e}):\n{text}\n{s:?}"),
            }
        }
    }
    assert!(loaded > 300 && refused > 300, "{loaded} loaded, {refused} refused");
}

/// Times the streaming passes and `load_path` on the dragon, or on the file named by
/// `STREAM_FILE`; `STREAM_READER=stream` or `load_path` times one of them only (the
/// default for `STREAM_FILE` is `stream`: a file too large to load whole), so that
/// `/usr/bin/time -v` on the test binary gives that reader's peak memory.
/// `cargo test --release -p tessera-codec --test stream_load -- --ignored --nocapture`
#[test]
#[ignore]
fn stream_timings() {
    let file = std::env::var_os("STREAM_FILE").map(PathBuf::from);
    let reader = std::env::var("STREAM_READER").unwrap_or(if file.is_some() { "stream" } else { "both" }.into());
    let path = file.unwrap_or_else(|| mesh_path("stanford/dragon_vrip.ply.gz"));
    let mut mesh = None;
    if reader == "load_path" || reader == "both" {
        let t = Instant::now();
        let m = load_path(&path).unwrap();
        let s = t.elapsed().as_secs_f64();
        let (v, n) = (m.positions.len(), m.triangles.len());
        println!("load_path {}: {v} vertices, {n} triangles in {s:.3} s", path.display());
        mesh = Some(m);
    }
    if reader == "load_path" {
        return;
    }
    let t = Instant::now();
    let positions = read_positions(&path, &mut |_| {}).unwrap();
    let p = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let mut sum = 0u64;
    let mut add = |t: [u32; 3]| {
        sum = sum.wrapping_add(u64::from(t[0] ^ t[1] ^ t[2]));
        Ok(())
    };
    let n = for_each_triangle(&path, &positions, &mut add, &mut |_| {}).unwrap().triangles;
    let f = t.elapsed().as_secs_f64();
    if let Some(m) = mesh {
        assert!(identical(&stream(&path).unwrap(), &m), "the readers differ");
    }
    println!(
        "stream {}: read_positions {} vertices in {p:.3} s, for_each_triangle {n} triangles in {f:.3} s \
         ({:.1} M triangles/s; both passes {:.3} s, {:.1} M triangles/s; checksum {sum})",
        path.display(),
        positions.len(),
        n as f64 / f / 1e6,
        p + f,
        n as f64 / (p + f) / 1e6,
    );
}

#[test]
fn ply_lines_may_end_in_bare_carriage_returns() {
    // As some CAD exporters write them: the ASCII file with `\r` for `\r\n` reads as the
    // original, and so does a binary file whose header lines end in `\r`.
    let files = Files::new();
    let lf = files.same("lf.ply", ASCII_PLY.as_bytes());
    let cr = files.same("cr.ply", ASCII_PLY.replace("\r\n", "\r").as_bytes());
    assert!(identical(&lf, &cr));
    assert!(!lf.triangles.is_empty());
    let binary = little_endian_usual();
    let end = binary.windows(11).position(|w| w == b"end_header\n").expect("a header") + 11;
    let mut bare = binary[..end].to_vec();
    for b in &mut bare {
        if *b == b'\n' {
            *b = b'\r';
        }
    }
    bare.extend_from_slice(&binary[end..]);
    let a = files.same("b.ply", &binary);
    let b = files.same("bcr.ply", &bare);
    assert!(identical(&a, &b));
    // Two kinds of line break in one header: refused by both readers, naming the line.
    let mixed = ASCII_PLY.replace("\r\n", "\r").replacen("element vertex 6\r", "element vertex 6\n", 1);
    let e = files.refused("mixed.ply", mixed.as_bytes());
    assert!(e.contains("line feed") || e.contains("line break"), "{e}");
}

#[test]
fn points_and_lines_are_counted_and_a_file_without_triangles_is_refused() {
    let files = Files::new();
    let path = files.put("m.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\np 1\nf 1 2\nf 1 2 3\n");
    let positions = read_positions(&path, &mut |_| {}).unwrap();
    let counts = for_each_triangle(&path, &positions, &mut |_| Ok(()), &mut |_| {}).unwrap();
    assert_eq!((counts.triangles, counts.ignored), (1, 3));
    for (name, bytes) in
        [("l.obj", &b"v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\n"[..]), ("e.obj", b""), ("p.obj", b"v 1 2 3\n")]
    {
        let e = files.refused(name, bytes);
        assert!(e.contains("no triangles"), "{e}");
    }
}
