//! The progressive-mesh messages: the model (its bytes, or the path of an out-of-core file)
//! once, then per frame the camera and the error bound.

use crate::wire::{Body, Reader, Writer};
use crate::ProtocolError;

/// `Model`: the progressive mesh (`.dpm` bytes) that the following `PmFrame`s show, sent once
/// before them, and the bytes of graphics memory its adaptation may take on each worker.
///
/// ```text
/// dpm length u32 + bytes, GPU budget u64 (bytes)
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PmModel {
    pub dpm: Vec<u8>,
    pub gpu_budget: u64,
}

impl Body for PmModel {
    fn write(&self, w: &mut Writer) {
        w.bytes(&self.dpm);
        w.u64(self.gpu_budget);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(PmModel { dpm: r.bytes("model")?.to_vec(), gpu_budget: r.u64("GPU budget")? })
    }
}

/// `DpmFile`: an out-of-core `.dpm` by its path, which every worker opens itself (a shared
/// file system) and reads node by node, sent once before its `PmFrame`s; the bytes of
/// graphics memory each worker's adaptation may take, and those of them its node pool takes.
///
/// ```text
/// path length u32 + UTF-8 bytes, GPU budget u64, node pool u64 (bytes)
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct DpmFile {
    pub path: String,
    pub gpu_budget: u64,
    pub pool_bytes: u64,
}

impl Body for DpmFile {
    fn write(&self, w: &mut Writer) {
        w.bytes(self.path.as_bytes());
        w.u64(self.gpu_budget);
        w.u64(self.pool_bytes);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(DpmFile { path: r.string("model path")?, gpu_budget: r.u64("GPU budget")?, pool_bytes: r.u64("node pool")? })
    }
}

/// `PmFrame`: a frame of a progressive mesh: the whole frame's camera and the error bound;
/// each worker adapts the mesh to its tiles' sub-frusta and renders it.
///
/// ```text
/// frame u32, width u32, height u32, view_proj 16 x f32, eye 3 x f32, pixels_per_unit f32,
/// error_px f32, c_lod f32, attribute_scale f32, max_passes u32,
/// occlusion u8 (1: cull with the worker's last frame's depth; 0 off),
/// tile count u32, then per tile: index u32, rect 4 x u32
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct PmFrameJob {
    pub frame: u32,
    pub width: u32,
    pub height: u32,
    pub view_proj: [f32; 16],
    pub eye: [f32; 3],
    pub pixels_per_unit: f32,
    pub error_px: f32,
    pub c_lod: f32,
    pub attribute_scale: f32,
    /// Adaptation passes per tile and frame at most (each pass performs every split and
    /// collapse the view asks of the active vertices; the tile stops early when converged).
    pub max_passes: u32,
    /// Cull what the worker's last frame hid (occlusion culling one frame late).
    pub occlusion: bool,
    /// `(tile index, rect)`.
    pub tiles: Vec<(u32, [u32; 4])>,
}

impl Body for PmFrameJob {
    fn write(&self, w: &mut Writer) {
        for v in [self.frame, self.width, self.height] {
            w.u32(v);
        }
        w.matrix(&self.view_proj);
        self.eye.iter().for_each(|&v| w.f32(v));
        for v in [self.pixels_per_unit, self.error_px, self.c_lod, self.attribute_scale] {
            w.f32(v);
        }
        w.u32(self.max_passes);
        w.u8(self.occlusion as u8);
        w.tiles(&self.tiles);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let (frame, width, height) = (r.u32("frame")?, r.u32("width")?, r.u32("height")?);
        let view_proj = r.matrix("view_proj")?;
        let eye = [r.f32("eye")?, r.f32("eye")?, r.f32("eye")?];
        let (pixels_per_unit, error_px) = (r.f32("pixels per unit")?, r.f32("error")?);
        let (c_lod, attribute_scale) = (r.f32("c_lod")?, r.f32("attribute scale")?);
        let max_passes = r.u32("max passes")?;
        let occlusion = match r.u8("occlusion")? {
            0 => false,
            1 => true,
            v => return Err(ProtocolError::Invalid(format!("occlusion flag {v}"))),
        };
        let tiles = r.tiles()?;
        Ok(PmFrameJob {
            frame,
            width,
            height,
            view_proj,
            eye,
            pixels_per_unit,
            error_px,
            c_lod,
            attribute_scale,
            max_passes,
            occlusion,
            tiles,
        })
    }
}
