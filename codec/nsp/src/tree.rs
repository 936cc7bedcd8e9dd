//! The nSP-tree: cubic cells split `n` times per axis, built over the canonical complex
//! (NSP.md 1.2 and 1.4), and the precisions of each cell.

use super::canonical::Simplex;
use super::error::NspError;
use super::params::Params;

/// One cell of the tree. Cells are stored in postorder: a split cell comes after its `n^3`
/// children, which are in Morton order (x the most significant bit of each level).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Node {
    /// Depth, 0 for the root.
    pub depth: u8,
    /// The cell's cube: the top `p_l * depth` bits of each coordinate.
    pub coords: [u32; 3],
    /// Postorder indices of the children (empty for a leaf).
    pub children: Vec<u32>,
    /// Postorder index of the parent (`u32::MAX` for the root).
    pub parent: u32,
}

/// The shape of an nSP-tree and its parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Tree {
    pub params: Params,
    pub nodes: Vec<Node>,
}

impl Tree {
    pub fn root(&self) -> u32 {
        self.nodes.len() as u32 - 1
    }

    pub fn is_leaf(&self, c: u32) -> bool {
        self.nodes[c as usize].children.is_empty()
    }

    /// The precision (bits per coordinate) a cell's stream starts from: its parent's maximal
    /// precision, 0 for the root.
    pub fn min_prec(&self, c: u32) -> u8 {
        let d = self.nodes[c as usize].depth;
        if d == 0 {
            0
        } else {
            self.params.max_prec_at(d - 1)
        }
    }

    /// The precision a cell's stream ends at: `p` for a leaf, `p_r + p_l * depth` otherwise.
    pub fn max_prec(&self, c: u32) -> u8 {
        if self.is_leaf(c) {
            self.params.bits
        } else {
            self.params.max_prec_at(self.nodes[c as usize].depth)
        }
    }

    /// Whether the full-precision-grid point `q` lies in cell `c`.
    #[inline]
    pub fn contains(&self, c: u32, q: [u32; 3], q_bits: u8) -> bool {
        let n = &self.nodes[c as usize];
        let shift = q_bits - self.params.level_bits() * n.depth;
        (0..3).all(|a| q[a] >> shift == n.coords[a])
    }

    /// Rebuilds a tree from the split flags of its cells in postorder, checking that they
    /// make exactly one tree.
    pub fn from_split_flags(params: Params, split: &[bool]) -> Result<Tree, NspError> {
        let fan = params.fan_out() as usize;
        let mut nodes: Vec<Node> = Vec::with_capacity(split.len());
        let mut stack: Vec<u32> = Vec::new();
        for (i, &s) in split.iter().enumerate() {
            let mut children = Vec::new();
            if s {
                if stack.len() < fan {
                    return Err(NspError::Format(format!(
                        "cell table: split cell {i} has fewer than {fan} cells before it"
                    )));
                }
                children = stack.split_off(stack.len() - fan);
                for &ch in &children {
                    nodes[ch as usize].parent = i as u32;
                }
            }
            nodes.push(Node { depth: 0, coords: [0; 3], children, parent: u32::MAX });
            stack.push(i as u32);
        }
        if stack.len() != 1 {
            return Err(NspError::Format(format!("cell table: {} cells are not in one tree", stack.len())));
        }
        let mut tree = Tree { params, nodes };
        // Depths and coordinates, top-down from the root.
        let root = tree.root();
        let mut todo = vec![root];
        while let Some(c) = todo.pop() {
            let (depth, coords, children) = {
                let n = &tree.nodes[c as usize];
                (n.depth, n.coords, n.children.clone())
            };
            if !children.is_empty() && params.max_prec_at(depth) >= params.bits {
                return Err(NspError::Format(format!("cell table: cell {c} at depth {depth} cannot be split")));
            }
            for (k, &ch) in children.iter().enumerate() {
                let n = &mut tree.nodes[ch as usize];
                n.depth = depth + 1;
                n.coords = params.child_coords(coords, k as u32);
                todo.push(ch);
            }
        }
        Ok(tree)
    }
}

/// The partition of a canonical complex, in core: the tree, and for every cell the ids of the
/// simplices that touch it (at least one vertex inside), in ascending order.
pub struct Partition {
    pub tree: Tree,
    pub members: Vec<Vec<u32>>,
}

/// Builds the nSP-tree over `simplices` on `points` (NSP.md 1.4): a cell splits when it holds
/// at least `N_min` top-simplices, border duplicates included, and its maximal precision is
/// below `p`; splitting makes all `n^3` children and gives each simplex to every child that
/// holds one of its vertices.
pub fn partition(params: Params, points: &[[u32; 3]], simplices: &[Simplex]) -> Partition {
    partition_with(params, points, simplices, false).expect("not capped")
}

/// [`partition`], refusing a tree of more cells than a reader opens
/// ([`Params::check_cells`]) as soon as its splits reach that many, before making them.
pub fn partition_capped(params: Params, points: &[[u32; 3]], simplices: &[Simplex]) -> Result<Partition, NspError> {
    partition_with(params, points, simplices, true)
}

fn partition_with(
    params: Params,
    points: &[[u32; 3]],
    simplices: &[Simplex],
    capped: bool,
) -> Result<Partition, NspError> {
    let mut nodes = Vec::new();
    let mut members = Vec::new();
    let all: Vec<u32> = (0..simplices.len() as u32).collect();
    let mut cells = capped.then_some(1u64);
    let mut out = Out { nodes: &mut nodes, members: &mut members, cells: &mut cells };
    build(params, points, simplices, 0, [0; 3], all, &mut out)?;
    Ok(Partition { tree: Tree { params, nodes }, members })
}

/// What [`build`] fills, and the cells made so far when capped.
struct Out<'a> {
    nodes: &'a mut Vec<Node>,
    members: &'a mut Vec<Vec<u32>>,
    cells: &'a mut Option<u64>,
}

fn build(
    params: Params,
    points: &[[u32; 3]],
    simplices: &[Simplex],
    depth: u8,
    coords: [u32; 3],
    mine: Vec<u32>,
    out: &mut Out,
) -> Result<u32, NspError> {
    let mut children = Vec::new();
    if mine.len() as u64 >= params.min_simplices as u64 && params.max_prec_at(depth) < params.bits {
        let fan = params.fan_out() as usize;
        if let Some(cells) = out.cells.as_mut() {
            *cells += fan as u64;
            params.check_cells(*cells)?;
        }
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); fan];
        let shift = params.bits - params.level_bits() * (depth + 1);
        let mask = params.splits - 1;
        for &s in &mine {
            let mut last = u32::MAX;
            let mut taken = [u32::MAX; 3];
            for (k, &v) in simplices[s as usize].verts().iter().enumerate() {
                let q = points[v as usize];
                let parent_shift = shift + params.level_bits();
                if (0..3).any(|a| q[a] >> parent_shift != coords[a]) {
                    // A vertex outside this cell names no child.
                    taken[k] = u32::MAX;
                    continue;
                }
                let local = [(q[0] >> shift) & mask, (q[1] >> shift) & mask, (q[2] >> shift) & mask];
                let child = params.child_index(local);
                if child != last && !taken[..k].contains(&child) {
                    lists[child as usize].push(s);
                }
                taken[k] = child;
                last = child;
            }
        }
        drop(mine);
        let mut mine_again = Vec::new();
        for (k, list) in lists.into_iter().enumerate() {
            let cc = params.child_coords(coords, k as u32);
            children.push(build(params, points, simplices, depth + 1, cc, list, out)?);
        }
        let id = out.nodes.len() as u32;
        for &ch in &children {
            out.nodes[ch as usize].parent = id;
        }
        // An internal cell's members are the union of its children's (each simplex once).
        for &ch in &children {
            mine_again.extend_from_slice(&out.members[ch as usize]);
        }
        mine_again.sort_unstable();
        mine_again.dedup();
        out.nodes.push(Node { depth, coords, children, parent: u32::MAX });
        out.members.push(mine_again);
        return Ok(id);
    }
    let id = out.nodes.len() as u32;
    out.nodes.push(Node { depth, coords, children, parent: u32::MAX });
    out.members.push(mine);
    Ok(id)
}
