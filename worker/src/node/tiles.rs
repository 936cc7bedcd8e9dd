//! Tiles drawn together: a worker's tiles of an adapted or refined mesh are drawn in as few
//! draws as their layout allows and cut out of each draw.

/// The most draws a worker makes of its adapted mesh per frame: up to this many tiles, each
/// tile is drawn under its own rectangle; beyond it, a worker's tiles are grouped by the 4x4
/// block of the frame they lie in, each group drawn once under its tiles' bounding rectangle
/// and cut into tiles (a 64x64 grid would otherwise cost 4,096 draws).
pub const MAX_DRAWS: usize = 16;

/// Tiles drawn together (see [`MAX_DRAWS`]).
pub(super) struct TileGroup {
    /// The group's key: the tile index for a tile alone, `1 << 31 | block` for a block.
    pub(super) key: u32,
    /// The bounding rectangle of the group's tiles.
    pub(super) rect: [u32; 4],
    pub(super) tiles: Vec<(u32, [u32; 4])>,
}

/// The pixels of `rect` out of an image of the pixels of `outer` (rows top first, RGBA8).
pub(super) fn crop(pixels: &[u8], outer: [u32; 4], rect: [u32; 4]) -> Vec<u8> {
    let outer_row = (outer[2] - outer[0]) as usize * 4;
    let row = (rect[2] - rect[0]) as usize * 4;
    let x = (rect[0] - outer[0]) as usize * 4;
    (rect[1]..rect[3])
        .flat_map(|y| {
            let at = (y - outer[1]) as usize * outer_row + x;
            &pixels[at..at + row]
        })
        .copied()
        .collect()
}

/// Groups a worker's tiles for drawing: one group per tile up to [`MAX_DRAWS`] tiles, else one
/// per 4x4 block of the frame (by each tile's top-left corner), in the job's order.
pub(super) fn tile_groups(tiles: &[(u32, [u32; 4])], width: u32, height: u32) -> Vec<TileGroup> {
    if tiles.len() <= MAX_DRAWS {
        return tiles.iter().map(|&(index, rect)| TileGroup { key: index, rect, tiles: vec![(index, rect)] }).collect();
    }
    let mut groups: Vec<TileGroup> = Vec::new();
    for &(index, rect) in tiles {
        let block = (rect[1] as u64 * 4 / height as u64 * 4 + rect[0] as u64 * 4 / width as u64) as u32;
        let key = 1 << 31 | block;
        match groups.iter_mut().find(|g| g.key == key) {
            Some(g) => {
                g.rect =
                    [g.rect[0].min(rect[0]), g.rect[1].min(rect[1]), g.rect[2].max(rect[2]), g.rect[3].max(rect[3])];
                g.tiles.push((index, rect));
            }
            None => groups.push(TileGroup { key, rect, tiles: vec![(index, rect)] }),
        }
    }
    groups
}
