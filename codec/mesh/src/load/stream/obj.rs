//! OBJ for the streaming reader, line for line as tobj 4 reads it with the options
//! `load_path` uses (`triangulate: false`, `single_index: false`, materials never found).
//!
//! What tobj makes of a file, and so what this reader reproduces:
//! * lines are split at `\n` (a `\r` before it dropped); a line that is not UTF-8 is an
//!   error; words are split at any whitespace; the first word says what the line is;
//! * `v x y z` with an optional `w` (the position is divided by it; 0 is an error) or
//!   three colour values (counted; 2 or more than 3 extra words are an error);
//!   `vt` needs two numbers, `vn` three (more are ignored);
//! * `f` and `l` alike: corners `v`, `v/vt`, `v//vn`, `v/vt/vn`, 1-based, negative ones
//!   relative to the count of their kind so far;
//! * an `o` or `g` line after faces ends the current object; each object gets the vertices
//!   its faces use, in the order of first use, and the indices are checked when the object
//!   ends, against the counts at that time (so a face may use a vertex defined after it in
//!   the same object): a position index out of range is an error, and so is a texture
//!   coordinate or normal index out of range when the file has any of that kind by then, or
//!   a vertex beyond those with colours when some vertices have colours;
//! * `usemtl` without a name is an error; with one, it changes nothing here: the material
//!   is never found, as `load_path` loads no material library, so no object is split;
//! * anything else is ignored.

use std::collections::HashMap;
use std::str::SplitWhitespace;

use super::emitter::Emitter;
use super::source::{Input, Source};
use crate::load::error::{err, LoadError};
use crate::Mesh;

/// "No slot": a file vertex no object has used yet.
const NONE: u32 = u32::MAX;

/// tobj's index for an absent texture coordinate or normal (and what index 0 resolves to).
const MISSING: usize = usize::MAX;

/// A face corner as tobj resolves it: the 0-based indices of its position, texture
/// coordinate and normal, [`MISSING`] where absent.
type Corner = [usize; 3];

/// How many of each kind of line have been read so far.
#[derive(Clone, Copy, Default)]
struct Counts {
    v: usize,
    vt: usize,
    vn: usize,
    /// Colour values read from `v` lines.
    colors: usize,
}

enum Line {
    /// A vertex, with how many colour values tobj keeps of it.
    Vertex(usize),
    TexCoord,
    Normal,
    /// A face or line, its corners in the scanner's buffer.
    Face,
    Group,
    /// A `p` (points) or `l` (polyline) element: no triangle, counted as ignored; its
    /// vertices are not used (as `load_path` skips these lines before tobj reads the file).
    Points,
    Other,
}

/// A line's text: without `\n` (and a `\r` before it), and without a comment (from `#` to
/// the end of the line, which tobj would read as words of the line).
fn text(line: &[u8]) -> Option<&str> {
    let line = match line.strip_suffix(b"\n") {
        Some(l) => l.strip_suffix(b"\r").unwrap_or(l),
        None => line,
    };
    let line = line.iter().position(|&b| b == b'#').map_or(line, |k| &line[..k]);
    std::str::from_utf8(line).ok()
}

/// Whether the next `n` words are numbers (tobj's `parse_floatn`; later words are ignored).
fn floats(words: &mut SplitWhitespace, n: usize) -> bool {
    let mut k = 0;
    for w in words.take(n) {
        if w.parse::<f32>().is_err() {
            return false;
        }
        k += 1;
    }
    k == n
}

/// The words after `v`: the position (divided by `w` if given) and how many colour values
/// tobj keeps (those before the first that is not a number).
fn vertex(words: SplitWhitespace) -> Result<([f32; 3], usize), &'static str> {
    vertex_colour(words).map(|(p, n, _)| (p, n))
}

/// [`vertex`] with the colour values themselves (meaningful when all three are numbers).
fn vertex_colour(mut words: SplitWhitespace) -> Result<([f32; 3], usize, [f32; 3]), &'static str> {
    let mut p = [0.0f32; 3];
    for c in &mut p {
        *c = words.next().and_then(|w| w.parse().ok()).ok_or("a 'v' line needs three numbers")?;
    }
    if !p.iter().all(|c| c.is_finite()) {
        return Err("a 'v' line with a non-finite coordinate");
    }
    let Some(first) = words.next() else {
        return Ok((p, 0, [1.0; 3]));
    };
    match (words.next(), words.next()) {
        (None, _) => {
            let w: f32 = first.parse().map_err(|_| "the w of a 'v' line is not a number")?;
            if w == 0.0 {
                return Err("a 'v' line with w = 0");
            }
            for c in &mut p {
                *c /= w;
            }
            Ok((p, 0, [1.0; 3]))
        }
        (Some(second), Some(third)) if words.next().is_none() => {
            let values = [first, second, third].map(|c| c.parse::<f32>().ok());
            let n = values.iter().take_while(|c| c.is_some()).count();
            Ok((p, n, values.map(|c| c.unwrap_or(1.0))))
        }
        _ => Err("a 'v' line needs 3, 4 or 6 values"),
    }
}

/// A face corner as tobj's `VertexIndices::parse` resolves it.
fn corner(word: &str, counts: &Counts) -> Option<Corner> {
    let mut corner = [MISSING; 3];
    let sizes = [counts.v, counts.vt, counts.vn];
    for (i, piece) in word.split('/').enumerate() {
        if piece.is_empty() {
            continue;
        }
        let x: isize = piece.parse().ok()?;
        let size = *sizes.get(i)?;
        corner[i] = if x < 0 { (size as isize).wrapping_add(x) as usize } else { (x - 1) as usize };
    }
    Some(corner)
}

fn parse(text: &str, counts: &Counts, corners: &mut Vec<Corner>) -> Result<Line, String> {
    let mut words = text.split_whitespace();
    Ok(match words.next() {
        Some("v") => {
            let (_, colors) = vertex(words)?;
            Line::Vertex(colors)
        }
        Some("vt") if floats(&mut words, 2) => Line::TexCoord,
        Some("vt") => return Err("a 'vt' line needs two numbers".into()),
        Some("vn") if floats(&mut words, 3) => Line::Normal,
        Some("vn") => return Err("a 'vn' line needs three numbers".into()),
        Some("f") => {
            corners.clear();
            for w in words {
                corners.push(corner(w, counts).ok_or_else(|| format!("'{w}' is not a face corner"))?);
            }
            if corners.is_empty() {
                return Err("a face without vertices".into());
            }
            Line::Face
        }
        Some("o" | "g") => Line::Group,
        Some("p" | "l") => Line::Points,
        Some("usemtl") if text.split_once(' ').unwrap_or_default().1.trim().is_empty() => {
            return Err("'usemtl' without a material name".into())
        }
        _ => Line::Other,
    })
}

/// Numbers the vertices of each object in the order its faces first use them, as tobj does:
/// a vertex's *slot* is its index in the concatenated positions.
struct Slots {
    /// Per file vertex: its slot in the latest object that used it, or [`NONE`].
    remap: Vec<u32>,
    /// Vertices the current object used before their `v` line (or never defined), with
    /// their slots.
    ahead: HashMap<usize, u32>,
    /// The current object's first slot, and the next slot to give.
    base: u64,
    next: u64,
    /// Pass 1 only: (vertex, slot) for the slots vertices got in objects before the one
    /// they were last used in.
    older: Option<Vec<(usize, u32)>>,
    /// Whether the current object has faces, and the largest indices they use, with the
    /// line of each, checked when the object ends.
    faces: bool,
    max_v: Option<(usize, u64)>,
}

/// Describes a resolved 0-based index as its line could have written it.
fn describe(i: usize) -> String {
    match i {
        MISSING => "index 0 or none".into(),
        i if i > isize::MAX as usize => "a relative index before the first".into(),
        i => format!("{}", i + 1),
    }
}

impl Slots {
    fn new(keep_older: bool) -> Self {
        Slots {
            remap: Vec::new(),
            ahead: HashMap::new(),
            base: 0,
            next: 0,
            older: keep_older.then(Vec::new),
            faces: false,
            max_v: None,
        }
    }

    fn new_slot(&mut self) -> Result<u32, String> {
        let s =
            u32::try_from(self.next).ok().filter(|&s| s != NONE).ok_or("more vertices than 32-bit indices address")?;
        self.next += 1;
        Ok(s)
    }

    /// The slot of file vertex `v` in the current object, given one if it has none yet.
    fn slot(&mut self, v: usize) -> Result<u32, String> {
        let Some(&old) = self.remap.get(v) else {
            // Not defined yet: resolved when the object ends.
            if let Some(&s) = self.ahead.get(&v) {
                return Ok(s);
            }
            let s = self.new_slot()?;
            self.ahead.insert(v, s);
            return Ok(s);
        };
        if old != NONE && u64::from(old) >= self.base {
            return Ok(old);
        }
        if let Some(&s) = self.ahead.get(&v) {
            return Ok(s);
        }
        let s = self.new_slot()?;
        if let (Some(older), true) = (&mut self.older, old != NONE) {
            older.push((v, old));
        }
        self.remap[v] = s;
        Ok(s)
    }

    /// Notes a face's indices, to be checked when its object ends.
    fn face(&mut self, corners: &[Corner], line: u64) {
        self.faces = true;
        for c in corners {
            // A position index of 0 or none is MISSING too, and out of range.
            if self.max_v.is_none_or(|(m, _)| c[0] > m) {
                self.max_v = Some((c[0], line));
            }
        }
    }

    /// Ends the current object: checks its indices as tobj does, against the counts now.
    fn end_object(&mut self, counts: &Counts) -> Result<(), String> {
        if let Some((v, line)) = self.max_v {
            if v >= counts.v {
                return Err(format!(
                    "line {line}: a face uses vertex {}, but the file has {} vertices by the end of its object",
                    describe(v),
                    counts.v
                ));
            }
        }
        // Texture coordinate and normal indices are not checked: positions are what is read,
        // and a file whose positions are fine loads whatever its other indices say.
        // Every vertex used ahead of its definition is defined now (checked above).
        for (v, s) in self.ahead.drain() {
            self.remap[v] = s;
        }
        self.base = self.next;
        (self.faces, self.max_v) = (false, None);
        Ok(())
    }
}

/// Reads the file through, numbering slots; with `out`, hands it the triangles.
fn scan(
    input: Input,
    progress: &mut dyn FnMut(u64),
    slots: &mut Slots,
    mut out: Option<&mut Emitter>,
) -> Result<(Counts, u64), LoadError> {
    let path = input.path;
    let mut src = Source::open(input, progress)?;
    let (mut line, mut corners) = (Vec::new(), Vec::new());
    let mut counts = Counts::default();
    let mut line_no = 0u64;
    while src.line(&mut line, usize::MAX)? {
        line_no += 1;
        let at = |what: String| err(path, format!("line {line_no}: {what}"));
        let text = text(&line).ok_or_else(|| at("not UTF-8 text".into()))?;
        match parse(text, &counts, &mut corners).map_err(at)? {
            Line::Vertex(colors) => {
                counts.v += 1;
                counts.colors += colors;
                slots.remap.push(NONE);
            }
            Line::TexCoord => counts.vt += 1,
            Line::Normal => counts.vn += 1,
            Line::Face => {
                slots.face(&corners, line_no);
                match out.as_deref_mut() {
                    Some(out) => emit(out, slots, &corners, line_no)?,
                    None => {
                        for c in &corners {
                            slots.slot(c[0]).map_err(at)?;
                        }
                    }
                }
            }
            Line::Group if slots.faces => slots.end_object(&counts).map_err(|e| err(path, e))?,
            Line::Points => {
                if let Some(out) = out.as_deref_mut() {
                    out.ignored += 1;
                }
            }
            Line::Group | Line::Other => {}
        }
    }
    slots.end_object(&counts).map_err(|e| err(path, e))?;
    Ok((counts, src.raw_len))
}

/// Hands out a face's triangles as `load_path` makes them: a polygon triangulated; a point
/// or a line (an `f` of one or two corners, a `p` or an `l`) is counted as ignored.
fn emit(out: &mut Emitter, slots: &mut Slots, corners: &[Corner], line: u64) -> Result<(), LoadError> {
    out.corners.clear();
    for c in corners {
        let s = slots.slot(c[0]).map_err(|e| err(out.path, format!("line {line}: {e}")))?;
        out.corners.push(s);
    }
    if let Some(s) = out.missing_corner() {
        let n = out.positions.count();
        let what = format!("line {line}: the positions given are not this file's: a face has vertex {s} of {n}");
        return Err(err(out.path, what));
    }
    if out.corners.len() < 3 {
        out.ignored += 1;
        return Ok(());
    }
    out.polygon()
}

/// Pass 1 for OBJ: numbers the slots in one read, then fills them from the `v` lines in a
/// second.
/// Pass 1 for OBJ: the positions in tobj's order, and their colours where the file has the
/// `v x y z r g b` extension (values 0 to 1; vertices without them white).
pub(super) fn vertices(input: Input, progress: &mut dyn FnMut(u64)) -> Result<Mesh, LoadError> {
    let path = input.path;
    let mut slots = Slots::new(true);
    let (counts, read) = scan(input, &mut *progress, &mut slots, None)?;
    let mut older = slots.older.take().unwrap_or_default();
    older.sort_unstable();
    let mut positions = vec![[0.0f32; 3]; slots.next as usize];
    let mut colors = vec![[255u8; 4]; if counts.colors > 0 { slots.next as usize } else { 0 }];
    let mut base_progress = |n: u64| progress(read + n);
    let mut src = Source::open(input, &mut base_progress)?;
    let (mut line, mut v, mut k, mut line_no) = (Vec::new(), 0usize, 0usize, 0u64);
    let changed = || err(path, "the file changed while it was read");
    while v < counts.v {
        if !src.line(&mut line, usize::MAX)? {
            return Err(changed());
        }
        line_no += 1;
        let mut words = text(&line).ok_or_else(changed)?.split_whitespace();
        if words.next() != Some("v") {
            continue;
        }
        let (p, n, c) = vertex_colour(words).map_err(|e| err(path, format!("line {line_no}: {e}")))?;
        let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        let c = if n == 3 { [byte(c[0]), byte(c[1]), byte(c[2]), 255] } else { [255; 4] };
        let mut put = |s: u32| {
            if let Some(slot) = colors.get_mut(s as usize) {
                *slot = c;
            }
            positions.get_mut(s as usize).map(|slot| *slot = p).ok_or_else(changed)
        };
        if let Some(&s) = slots.remap.get(v).filter(|&&s| s != NONE) {
            put(s)?;
        }
        while let Some(&(_, s)) = older.get(k).filter(|(w, _)| *w == v) {
            put(s)?;
            k += 1;
        }
        v += 1;
    }
    Ok(Mesh { positions, triangles: Vec::new(), colors, normals: Vec::new() })
}

/// Pass 2 for OBJ.
pub(super) fn triangles(input: Input, out: &mut Emitter, progress: &mut dyn FnMut(u64)) -> Result<(), LoadError> {
    let path = input.path;
    let mut slots = Slots::new(false);
    scan(input, progress, &mut slots, Some(&mut *out))?;
    if slots.next != out.positions.count() as u64 {
        let what = format!(
            "the positions given are not this file's: {} of them for {} slots",
            out.positions.count(),
            slots.next
        );
        return Err(err(path, what));
    }
    Ok(())
}
