//! What a display rank (`render --display-ranks D`) is sent by rank 0: the tiles of a view to
//! expect from the workers, the swap that shows a view, or the end of the run. (The workers'
//! pixels come as [`crate::ToMaster::Pixels`], and the display rank answers rank 0 with
//! [`crate::ToMaster::DisplayReady`].)

use crate::wire::{Body, Reader, Writer};
use crate::{ProtocolError, KEEP_ALIVE, SHUTDOWN};

/// A message from rank 0 to a display rank.
#[derive(Clone, Debug, PartialEq)]
pub enum ToDisplay {
    /// Kind 12: the tiles whose pixels the workers send it for a view.
    DisplayFrame(DisplayFrameJob),
    /// Kind 13: every display has the view; show (write) it.
    Swap(Swap),
    /// Kind 2: the run is over.
    Shutdown,
    /// Kind 17: an idle live run's rank 0 is still there.
    KeepAlive,
}

const DISPLAY_FRAME: u8 = 12;
const SWAP: u8 = 13;

/// A view for a display rank: its number in the workers' messages, its frame and eye
/// (0 mono, 1 left, 2 right), and the tiles of its displays that workers render for it
/// (tiles no worker renders stay transparent).
///
/// ```text
/// view u32, frame u32, eye u8 (0 mono, 1 left, 2 right), tile count u32, then the tiles
/// whose pixels workers send it, u32 each
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct DisplayFrameJob {
    pub view: u32,
    pub frame: u32,
    pub eye: u8,
    pub tiles: Vec<u32>,
}

impl Body for DisplayFrameJob {
    fn write(&self, w: &mut Writer) {
        w.u32(self.view);
        w.u32(self.frame);
        w.u8(self.eye);
        w.u32(self.tiles.len() as u32);
        self.tiles.iter().for_each(|&t| w.u32(t));
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let (view, frame) = (r.u32("view")?, r.u32("frame")?);
        let eye = r.u8("eye")?;
        if eye > 2 {
            return Err(ProtocolError::Invalid(format!("eye {eye}")));
        }
        let n = r.count(4, "tiles")?;
        let tiles = (0..n).map(|_| r.u32("tile index")).collect::<Result<_, _>>()?;
        Ok(DisplayFrameJob { view, frame, eye, tiles })
    }
}

/// Show (write) a view's displays: every display rank has them.
///
/// ```text
/// view u32
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Swap {
    pub view: u32,
}

impl Body for Swap {
    fn write(&self, w: &mut Writer) {
        w.u32(self.view);
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        Ok(Swap { view: r.u32("view")? })
    }
}

impl ToDisplay {
    /// The message's kind, for errors that name one without dumping its contents.
    pub fn name(&self) -> &'static str {
        match self {
            ToDisplay::DisplayFrame(_) => "a display frame",
            ToDisplay::Swap(_) => "a swap",
            ToDisplay::Shutdown => "a shutdown",
            ToDisplay::KeepAlive => "a keep-alive",
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        match self {
            ToDisplay::DisplayFrame(f) => Writer::message(DISPLAY_FRAME, f),
            ToDisplay::Swap(s) => Writer::message(SWAP, s),
            ToDisplay::Shutdown => Writer::new(SHUTDOWN).finish(),
            ToDisplay::KeepAlive => Writer::new(KEEP_ALIVE).finish(),
        }
    }

    pub fn decode(b: &[u8]) -> Result<ToDisplay, ProtocolError> {
        let (r, kind) = Reader::open(b)?;
        Ok(match kind {
            DISPLAY_FRAME => ToDisplay::DisplayFrame(r.body()?),
            SWAP => ToDisplay::Swap(r.body()?),
            SHUTDOWN => {
                r.body::<()>()?;
                ToDisplay::Shutdown
            }
            KEEP_ALIVE => {
                r.body::<()>()?;
                ToDisplay::KeepAlive
            }
            k => return Err(ProtocolError::UnknownKind(k)),
        })
    }
}
