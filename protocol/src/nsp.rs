//! The nSP-tree messages: the model's skeleton once, then per frame the view's selection and
//! the pieces of cell streams the worker lacks.

use crate::wire::{Body, Reader, Writer};
use crate::ProtocolError;

/// `NspModel`: the skeleton of the `.nsp` model (the file without its cell streams) that the
/// following `NspFrame`s show, sent once before them.
///
/// ```text
/// skeleton length u32 + bytes
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct NspModel {
    pub skeleton: Vec<u8>,
}

impl Body for NspModel {
    fn write(&self, w: &mut Writer) {
        w.bytes(&self.skeleton);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(NspModel { skeleton: r.bytes("nsp skeleton")?.to_vec() })
    }
}

/// `NspFrame`: a frame of an `.nsp` model: the view's selection (every cell drawn, with its
/// precision), the cells of it this worker draws (those whose triangles can reach its
/// tiles), the pieces of cell streams it lacks for those precisions (it keeps what it was
/// sent: a piece continues the bytes it holds of that cell), and its tiles.
///
/// ```text
/// frame u32, width u32, height u32, view_proj 16 x f32,
/// selection count u32, then per selected cell: cell u32, bits u8;
/// draw count u32, then the cells this worker draws, u32 each;
/// piece count u32, then per piece: cell u32, offset u32 (the bytes it holds already),
///   length u32 + bytes;
/// tile count u32, then per tile: index u32, rect 4 x u32
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct NspFrameJob {
    pub frame: u32,
    pub width: u32,
    pub height: u32,
    pub view_proj: [f32; 16],
    pub selection: Vec<(u32, u8)>,
    pub draw: Vec<u32>,
    pub cells: Vec<(u32, u32, Vec<u8>)>,
    pub tiles: Vec<(u32, [u32; 4])>,
}

impl Body for NspFrameJob {
    fn write(&self, w: &mut Writer) {
        for v in [self.frame, self.width, self.height] {
            w.u32(v);
        }
        w.matrix(&self.view_proj);
        w.u32(self.selection.len() as u32);
        for &(c, b) in &self.selection {
            w.u32(c);
            w.u8(b);
        }
        w.u32(self.draw.len() as u32);
        self.draw.iter().for_each(|&c| w.u32(c));
        w.u32(self.cells.len() as u32);
        for (c, from, bytes) in &self.cells {
            w.u32(*c);
            w.u32(*from);
            w.bytes(bytes);
        }
        w.tiles(&self.tiles);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let (frame, width, height) = (r.u32("frame")?, r.u32("width")?, r.u32("height")?);
        let view_proj = r.matrix("view_proj")?;
        let n = r.count(5, "selection")?;
        let mut selection = Vec::with_capacity(n);
        for _ in 0..n {
            selection.push((r.u32("selected cell")?, r.u8("cell bits")?));
        }
        let n = r.count(4, "drawn cells")?;
        let draw = (0..n).map(|_| r.u32("drawn cell")).collect::<Result<_, _>>()?;
        let n = r.count(12, "cell stream pieces")?;
        let mut cells = Vec::with_capacity(n);
        for _ in 0..n {
            cells.push((r.u32("cell")?, r.u32("piece offset")?, r.bytes("cell stream piece")?.to_vec()));
        }
        let tiles = r.tiles()?;
        Ok(NspFrameJob { frame, width, height, view_proj, selection, draw, cells, tiles })
    }
}
