//! View-dependent navigation: which cells a view draws at which precision, and drawing
//! cells of different precisions together with the paper's border rule (section 5.3).

use rustc_hash::FxHashMap as HashMap;

use glam::Mat4;

use super::complex::centre;
use super::decode::{decode_uniform_states, CellState, NspFile};
use super::error::NspError;
use tessera_mesh::view::{box_screen_rect, Camera};

/// Triangles drawn from a set of cells, with shared vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Drawn {
    pub positions: Vec<[f32; 3]>,
    /// Triangles, oriented as the stream says.
    pub triangles: Vec<[u32; 3]>,
    /// Edges and points among the drawn cells' top-simplices (not drawn).
    pub edges: u64,
    pub points: u64,
    /// Copies of border triangles left to another cell by the border rule.
    pub left_to_others: u64,
    /// Triangles whose corners were moved to a coarser neighbour's kd-cell.
    pub stitched: u64,
    /// Stitched triangles that collapsed (two corners in one coarse kd-cell) or repeated
    /// another stitched triangle, so were not drawn.
    pub collapsed: u64,
    pub merged: u64,
    /// With the geometry advance: kd-cells drawn at two positions (a kd-cell is drawn where
    /// the cell it lies in puts it, but one spanning several cells, or in none drawn, where
    /// the drawing cell puts it), and the largest such distance in world units.
    pub split_vertices: u64,
    pub split_distance: f32,
}

impl Drawn {
    pub fn to_mesh(&self) -> crate::Mesh {
        crate::Mesh::new(self.positions.clone(), self.triangles.clone())
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Loc {
    /// In the selected cell (precision, cell).
    Drawn(u8, u32),
    /// Larger than a cell of the tree whose drawn descendants inside it reach this
    /// (precision, cell).
    Spanning(u8, u32),
    /// In no drawn cell.
    Nowhere,
}

/// A drawn corner: a kd-cell's level and its per-axis coordinates there.
type Corner = (u8, [u32; 3]);

/// What [`walk`] counts besides the triangles it hands out.
#[derive(Default)]
struct Counts {
    edges: u64,
    points: u64,
    left_to_others: u64,
    stitched: u64,
    collapsed: u64,
    merged: u64,
}

/// The border rule over `states`, as [`draw`] describes it: calls `emit` with each drawn
/// triangle's corners and their positions in grid units, cell by cell in postorder, each
/// cell's triangles in arena order.
fn walk(
    file: &NspFile,
    selection: &[(u32, u8)],
    states: &[&CellState],
    mut emit: impl FnMut([Corner; 3], [[f64; 3]; 3]),
) -> Counts {
    let tree = &file.tree;
    let bits = file.header.params.bits;
    let pl = file.header.params.level_bits() as u32;
    let mut selected: Vec<Option<u8>> = vec![None; tree.nodes.len()];
    for &(c, b) in selection {
        selected[c as usize] = Some(b.clamp(tree.min_prec(c), tree.max_prec(c)));
    }
    let locate = |level: u8, xyz: [u32; 3]| -> Loc {
        let used: [u8; 3] = [0, 1, 2].map(|a| ((level as usize + 2 - a) / 3) as u8);
        let corner: [u32; 3] = [0, 1, 2].map(|a| xyz[a] << (bits - used[a]));
        let mut node = tree.root();
        loop {
            if let Some(b) = selected[node as usize] {
                return Loc::Drawn(b, node);
            }
            let n = &tree.nodes[node as usize];
            if n.children.is_empty() {
                return Loc::Nowhere;
            }
            let need = pl * (n.depth as u32 + 1);
            if used.iter().all(|&u| u as u32 >= need) {
                let shift = bits as u32 - need;
                let mask = (1u32 << pl) - 1;
                let local = [(corner[0] >> shift) & mask, (corner[1] >> shift) & mask, (corner[2] >> shift) & mask];
                node = n.children[file.header.params.child_index(local) as usize];
                continue;
            }
            // The kd-cell spans several children: the best selected cell below it.
            let mut best: Option<(u8, u32)> = None;
            let mut stack = vec![node];
            while let Some(x) = stack.pop() {
                if let Some(b) = selected[x as usize] {
                    if best.is_none_or(|old| (b, x) > old) {
                        best = Some((b, x));
                    }
                    continue;
                }
                for &ch in &tree.nodes[x as usize].children {
                    if overlaps(tree, ch, corner, used, bits, pl) {
                        stack.push(ch);
                    }
                }
            }
            return match best {
                Some((p, c)) => Loc::Spanning(p, c),
                None => Loc::Nowhere,
            };
        }
    };
    let mut counts = Counts::default();
    // Stitching can map two border triangles of finer cells onto the same coarse triangle;
    // the complex is a set, so it is drawn once. (A stitched triangle keeps a corner finer
    // than any coarser cell's, so it can only repeat another stitched one.)
    let mut stitched_seen: rustc_hash::FxHashSet<[Corner; 3]> = rustc_hash::FxHashSet::default();
    let mut states: Vec<&CellState> = states.to_vec();
    states.sort_by_key(|s| s.cell);
    // With the geometry advance a kd-cell is drawn where the cell it lies in puts it: that
    // cell sees all of its descendants, a neighbour only those its own simplices reach.
    let ahead = file.header.params.advance > 0;
    let owner_position = |o: u32, level: u8, prefix: u128| -> Option<[f64; 3]> {
        let st = states[states.binary_search_by_key(&o, |s| s.cell).ok()?];
        if st.cx.level != level {
            return None;
        }
        let cells = &st.cx.cells;
        let k = st.cx.order.binary_search_by_key(&prefix, |&id| cells[id as usize].prefix()).ok()?;
        Some(st.cx.position(st.cx.order[k], bits))
    };
    let mut locs: Vec<Option<Loc>> = Vec::new();
    let mut own: Vec<Option<[f64; 3]>> = Vec::new();
    for &s in &states {
        let pc = s.precision();
        let me = (pc, s.cell);
        locs.clear();
        locs.resize(s.cx.cells.len(), None);
        own.clear();
        own.resize(s.cx.cells.len(), None);
        for top in s.cx.iter_tops() {
            match top.dim {
                0 => counts.points += 1,
                1 => counts.edges += 1,
                _ => {}
            }
            if top.dim != 2 {
                continue;
            }
            let mut corners = [(0u8, [0u32; 3]); 3];
            let mut at = [[0f64; 3]; 3];
            let mut dropped = false;
            let mut moved = false;
            for ((corner, pos), &v) in corners.iter_mut().zip(at.iter_mut()).zip(&top.v) {
                let kd = &s.cx.cells[v as usize];
                let loc = *locs[v as usize].get_or_insert_with(|| locate(kd.level, kd.xyz));
                *corner = (kd.level, kd.xyz);
                *pos = *own[v as usize].get_or_insert_with(|| s.cx.position(v, bits));
                match loc {
                    Loc::Drawn(_, c) if c == s.cell => {}
                    Loc::Drawn(p, c) | Loc::Spanning(p, c) => {
                        if (p, c) > me {
                            dropped = true;
                            break;
                        }
                        if let Loc::Drawn(..) = loc {
                            let level = 3 * p;
                            if level < kd.level {
                                let xyz = [0, 1, 2].map(|a| {
                                    let (fine, coarse) = ((kd.level as u32 + 2 - a) / 3, (level as u32 + 2 - a) / 3);
                                    kd.xyz[a as usize] >> (fine - coarse)
                                });
                                *corner = (level, xyz);
                                *pos = centre(level, xyz, bits);
                                moved = true;
                            }
                            if ahead {
                                if let Some(there) = owner_position(c, corner.0, kd.prefix() >> (kd.level - corner.0)) {
                                    *pos = there;
                                }
                            }
                        }
                    }
                    Loc::Nowhere => {}
                }
            }
            if dropped {
                counts.left_to_others += 1;
                continue;
            }
            if corners[0] == corners[1] || corners[1] == corners[2] || corners[0] == corners[2] {
                counts.collapsed += 1;
                continue;
            }
            if moved {
                counts.stitched += 1;
                let mut key = corners;
                key.sort_unstable();
                if !stitched_seen.insert(key) {
                    counts.merged += 1;
                    continue;
                }
            }
            emit(corners, at);
        }
    }
    counts
}

/// Draws the cells of `states` as members of the view `selection` (the cells drawn and
/// their precisions, an antichain of the tree; every state's cell is in it), with the border
/// rule: a border triangle is drawn once, by the cell of highest (precision, postorder
/// index) among the selected cells its corners lie in; its corners in coarser selected cells
/// move to those cells' kd-cells that hold them (the ancestor at that precision). Cells not
/// selected count as `-inf` (NSP.md 1.10: the paper's `p_i = p_c` would drop triangles at the
/// edge of the view). A triangle depends only on its own cell's state and the selection, so
/// drawing any subset of the selected cells gives exactly those cells' triangles of the
/// whole drawing, in the same order (the cluster relies on it).
pub fn draw(file: &NspFile, selection: &[(u32, u8)], states: &[&CellState]) -> Drawn {
    let mut out = Drawn::default();
    // A vertex is a kd-cell at a position: with the geometry advance a kd-cell spanning
    // several cells can be drawn at two (rare: a second map holds those).
    let mut vertex: HashMap<Corner, (u32, [f64; 3])> = HashMap::default();
    let mut apart: HashMap<(Corner, [u64; 3]), u32> = HashMap::default();
    let cube = &file.header.cube;
    let counts = walk(file, selection, states, |corners, at| {
        let ids = [0, 1, 2].map(|k| {
            let positions = &mut out.positions;
            let (id, there) = *vertex.entry(corners[k]).or_insert_with(|| {
                positions.push(cube.world(at[k]));
                (positions.len() as u32 - 1, at[k])
            });
            if there == at[k] {
                return id;
            }
            *apart.entry((corners[k], at[k].map(f64::to_bits))).or_insert_with(|| {
                out.split_vertices += 1;
                let d = (0..3).map(|a| (there[a] - at[k][a]).powi(2)).sum::<f64>().sqrt();
                out.split_distance = out.split_distance.max((d * cube.side / (1u64 << cube.bits) as f64) as f32);
                positions.push(cube.world(at[k]));
                positions.len() as u32 - 1
            })
        });
        out.triangles.push(ids);
    });
    out.edges = counts.edges;
    out.points = counts.points;
    out.left_to_others = counts.left_to_others;
    out.stitched = counts.stitched;
    out.collapsed = counts.collapsed;
    out.merged = counts.merged;
    out
}

/// [`draw`]'s triangles as three positions each (what a flat-shaded render needs; no
/// vertex is shared, so none is looked up).
pub fn draw_flat(file: &NspFile, selection: &[(u32, u8)], states: &[&CellState]) -> Vec<[[f32; 3]; 3]> {
    let mut out = Vec::new();
    let cube = &file.header.cube;
    walk(file, selection, states, |_, at| out.push(at.map(|g| cube.world(g))));
    out
}

fn overlaps(tree: &super::tree::Tree, c: u32, corner: [u32; 3], used: [u8; 3], bits: u8, pl: u32) -> bool {
    let n = &tree.nodes[c as usize];
    let side = bits as u32 - pl * n.depth as u32;
    (0..3).all(|a| {
        let (lo, hi) = ((n.coords[a] as u64) << side, ((n.coords[a] as u64) + 1) << side);
        let klo = corner[a] as u64;
        let khi = klo + (1u64 << (bits - used[a]));
        lo < khi && klo < hi
    })
}

/// The world box a cell's triangles can be drawn in: its simplices' bounding box, grown by
/// two kd-cells at its minimal precision (a drawn corner is the centre of a kd-cell holding
/// its vertex, at the cell's precision or, stitched, at a coarser neighbour's).
pub fn reach_box(file: &NspFile, c: u32) -> ([f32; 3], [f32; 3]) {
    let cube = &file.header.cube;
    let e = &file.entries[c as usize];
    let margin = (1u64 << (file.header.params.bits - file.tree.min_prec(c))) as f64 * 2.0;
    let lo = cube.world([0, 1, 2].map(|a| e.reach[0][a] as f64 - margin));
    let hi = cube.world([0, 1, 2].map(|a| e.reach[1][a] as f64 + 1.0 + margin));
    (lo, hi)
}

/// A view: camera, screen and the error allowed on screen.
#[derive(Clone, Copy, Debug)]
pub struct View {
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    /// Allowed projected error of a vertex, in pixels.
    pub error_px: f32,
}

impl View {
    fn view_proj(&self) -> Mat4 {
        self.camera.view_proj(self.width as f32 / self.height as f32)
    }

    /// The precision (bits) that keeps a vertex of a cell at distance `dist` from the eye
    /// within the error: the kd-cell's half diagonal `S 2^-b sqrt(3)/2` projects to at most
    /// `error_px` pixels, `f = (H/2) / tan(fovy/2)` being the focal length in pixels.
    pub fn wanted_bits(&self, side: f64, dist: f64) -> f64 {
        let f = self.height as f64 * 0.5 / (self.camera.fovy as f64 * 0.5).to_radians().tan();
        let need = side * 3f64.sqrt() * 0.5 * f / (self.error_px as f64 * dist.max(1e-30));
        need.log2().ceil()
    }
}

/// The cells a view draws, with their precisions (postorder index, bits), from the cell
/// boxes alone: cells outside the frustum are not drawn; a cell whose wanted precision is
/// above its maximal precision gives way to its non-empty children. With the geometry
/// advance the precision is the connectivity's, `m` bits below the positions' precision.
pub fn select(file: &NspFile, view: &View) -> Vec<(u32, u8)> {
    let tree = &file.tree;
    let cube = file.header.cube;
    let vp = view.view_proj();
    let pl = file.header.params.level_bits() as u32;
    let eye = view.camera.eye.as_dvec3();
    let mut out = Vec::new();
    let mut todo = vec![tree.root()];
    while let Some(c) = todo.pop() {
        let n = &tree.nodes[c as usize];
        let size = cube.side / (1u64 << (pl * n.depth as u32)) as f64;
        let lo = [
            cube.origin[0] + n.coords[0] as f64 * size,
            cube.origin[1] + n.coords[1] as f64 * size,
            cube.origin[2] + n.coords[2] as f64 * size,
        ];
        let (rlo, rhi) = reach_box(file, c);
        if box_screen_rect(rlo, rhi, vp, view.width, view.height).is_none() {
            continue;
        }
        let closest = glam::DVec3::new(
            eye.x.clamp(lo[0], lo[0] + size),
            eye.y.clamp(lo[1], lo[1] + size),
            eye.z.clamp(lo[2], lo[2] + size),
        );
        // With `m` bits of geometry advance the positions are refined `m` bits beyond the
        // connectivity (section 7): the error bound asks for connectivity `m` bits coarser.
        let want = view.wanted_bits(cube.side, (closest - eye).length()) - file.header.params.advance as f64;
        let (min, max) = (tree.min_prec(c), tree.max_prec(c));
        if !n.children.is_empty() && want > max as f64 {
            todo.extend(n.children.iter().copied().filter(|&ch| file.entries[ch as usize].len > 0));
            continue;
        }
        out.push((c, (want.max(min as f64).min(max as f64)) as u8));
    }
    out.sort_unstable();
    out
}

/// A viewer's decoded cells: drawn cells at their precisions, and their ancestors at their
/// maximal precisions (a child starts from its parent's state).
#[derive(Default)]
pub struct Navigator {
    states: HashMap<u32, CellState>,
    /// Vertex splits decoded over the navigator's life.
    pub splits: u64,
}

impl Navigator {
    /// Brings the decoded cells to `selection` (from [`select`]): decodes what is missing,
    /// refines or coarsens what changed, drops what is no longer needed. Returns the drawn
    /// cells' states in selection order.
    pub fn update(&mut self, file: &NspFile, selection: &[(u32, u8)]) -> Result<Vec<&CellState>, NspError> {
        let tree = &file.tree;
        let mut want: HashMap<u32, u8> = HashMap::default();
        for &(c, b) in selection {
            want.insert(c, b);
            let mut a = tree.nodes[c as usize].parent;
            while a != u32::MAX {
                want.insert(a, tree.max_prec(a));
                a = tree.nodes[a as usize].parent;
            }
        }
        self.states.retain(|c, _| want.contains_key(c));
        // Depth by depth, top-down: a parent is ready before its children, and the cells of
        // one depth decode in parallel.
        let mut by_depth: Vec<Vec<u32>> = Vec::new();
        for &c in want.keys() {
            let d = tree.nodes[c as usize].depth as usize;
            if by_depth.len() <= d {
                by_depth.resize(d + 1, Vec::new());
            }
            by_depth[d].push(c);
        }
        for mut cells in by_depth {
            use rayon::prelude::*;
            cells.sort_unstable();
            let mut mine: Vec<(u32, Option<CellState>)> = cells.iter().map(|&c| (c, self.states.remove(&c))).collect();
            let states = &self.states;
            let done: Vec<Result<(u32, CellState, u64), NspError>> = mine
                .par_iter_mut()
                .map(|(c, existing)| {
                    // A cell starts from its parent's state (held at its maximal precision)
                    // when it is new, and again when it coarsens.
                    let fresh = || {
                        let parent = tree.nodes[*c as usize].parent;
                        if parent == u32::MAX {
                            file.root_state()
                        } else {
                            file.child_state(&states[&parent], *c)
                        }
                    };
                    let mut s = match existing.take() {
                        Some(old) if old.coarsens(want[c]) => {
                            let mut s = fresh()?;
                            s.inherit(old);
                            s
                        }
                        Some(s) => s,
                        None => fresh()?,
                    };
                    let before = s.splits;
                    s.set_precision(file, want[c])?;
                    let n = s.splits - before;
                    Ok((*c, s, n))
                })
                .collect();
            for r in done {
                let (c, s, n) = r?;
                self.splits += n;
                self.states.insert(c, s);
            }
        }
        Ok(selection.iter().map(|(c, _)| &self.states[c]).collect())
    }

    /// Decoded cells (drawn and ancestors).
    pub fn cells(&self) -> usize {
        self.states.len()
    }
}

/// Decodes every cell to a uniform precision and draws them with the border rule.
pub fn decode_uniform(file: &NspFile, bits: u8) -> Result<Drawn, NspError> {
    let states = decode_uniform_states(file, bits)?;
    let selection: Vec<(u32, u8)> = states.iter().map(|s| (s.cell, s.precision())).collect();
    Ok(draw(file, &selection, &states.iter().collect::<Vec<_>>()))
}

/// Decodes every cell to full precision: the canonical complex.
pub fn decode_all(file: &NspFile) -> Result<Drawn, NspError> {
    decode_uniform(file, file.header.params.bits)
}
