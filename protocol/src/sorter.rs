//! What a sorter rank (`render --sorters K`) is sent: a frame to sort its share of, or the
//! end of the run.

use crate::wire::{Body, Reader, Writer};
use crate::{ProtocolError, KEEP_ALIVE, SHUTDOWN};

/// A message from rank 0 to a sorter rank.
#[derive(Clone, Debug, PartialEq)]
pub enum ToSorter {
    /// Kind 9: sort your share of the chunks for this frame.
    Sort(SortJob),
    /// Kind 2: the run is over.
    Shutdown,
    /// Kind 17: nothing to do yet; rank 0 is there (an idle live run).
    KeepAlive,
}

/// The kind byte of [`ToSorter::Sort`].
const SORT: u8 = 9;

/// A frame for a sorter rank: the view, the screen error a level-of-detail file's cut is
/// taken at, and the worker rank of every tile of the grid.
///
/// ```text
/// frame u32, view_proj 16 x f32, error_px f32, tile count u32, then per tile the worker
/// rank that renders it, u32
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct SortJob {
    pub frame: u32,
    pub view_proj: [f32; 16],
    pub error_px: f32,
    pub owners: Vec<u32>,
}

impl Body for SortJob {
    fn write(&self, w: &mut Writer) {
        w.u32(self.frame);
        w.matrix(&self.view_proj);
        w.f32(self.error_px);
        w.u32(self.owners.len() as u32);
        self.owners.iter().for_each(|&o| w.u32(o));
    }
    fn read(r: &mut Reader) -> Result<Self, ProtocolError> {
        let frame = r.u32("frame")?;
        let view_proj = r.matrix("view_proj")?;
        let error_px = r.f32("error_px")?;
        let n = r.count(4, "owners")?;
        let owners = (0..n).map(|_| r.u32("owner")).collect::<Result<_, _>>()?;
        Ok(SortJob { frame, view_proj, error_px, owners })
    }
}

impl ToSorter {
    /// The message's kind, for errors that name one without dumping its contents.
    pub fn name(&self) -> &'static str {
        match self {
            ToSorter::Sort(_) => "a sort job",
            ToSorter::Shutdown => "a shutdown",
            ToSorter::KeepAlive => "a keep-alive",
        }
    }

    pub fn encode(&self) -> Vec<u8> {
        match self {
            ToSorter::Sort(j) => Writer::message(SORT, j),
            ToSorter::Shutdown => Writer::new(SHUTDOWN).finish(),
            ToSorter::KeepAlive => Writer::new(KEEP_ALIVE).finish(),
        }
    }

    pub fn decode(b: &[u8]) -> Result<ToSorter, ProtocolError> {
        let (r, kind) = Reader::open(b)?;
        Ok(match kind {
            SORT => ToSorter::Sort(r.body()?),
            SHUTDOWN => {
                r.body::<()>()?;
                ToSorter::Shutdown
            }
            KEEP_ALIVE => {
                r.body::<()>()?;
                ToSorter::KeepAlive
            }
            k => return Err(ProtocolError::UnknownKind(k)),
        })
    }
}
