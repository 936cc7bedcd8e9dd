//! [`NodeFile`]: an out-of-core `.dpm` read from its head and then node by node, each node
//! checked by its own checksum.

use std::path::Path;

use super::decode::{outdated, Dpm};
use super::header::{corrupt, Header, LAYOUT};
use super::nodes::NodeInfo;
use super::DpmError;

/// An out-of-core `.dpm` file on disk: its bytes up to the operations read and checked at
/// [`NodeFile::open`], its nodes read one at a time ([`NodeFile::read_node`], safe from several
/// threads), each checked by its checksum. The operations section's own checksum, which would
/// take reading it whole, is not checked.
#[derive(Debug)]
pub struct NodeFile {
    file: std::fs::File,
    prefix: Vec<u8>,
    /// Where the operations section's payload starts in the file.
    ops_start: u64,
    nodes: Vec<NodeInfo>,
}

impl NodeFile {
    /// Opens `path` and reads everything before its operations (checked as
    /// [`Dpm::parse_prefix`] checks it) and the file's length against the node table's.
    pub fn open(path: &Path) -> Result<NodeFile, DpmError> {
        Self::open_out_of_core(path)?.ok_or_else(|| corrupt("an in-core file (no node table) read out of core"))
    }

    /// [`Self::open`] if the `.dpm` file at `path` is out of core (its header counts nodes),
    /// `None` for an in-core file, from its head alone: a reader that must not read a large
    /// file whole asks this first.
    pub fn open_out_of_core(path: &Path) -> Result<Option<NodeFile>, DpmError> {
        let (mut file, len) = crate::input::open_regular(path).map_err(DpmError::Io)?;
        let prefix = LAYOUT.read_prefix(&mut file)?;
        let c = LAYOUT.parse_prefix(&prefix).map_err(outdated)?;
        if Header::from_bytes(c.header)?.nodes == 0 {
            return Ok(None);
        }
        let dpm = Dpm::parse_prefix(&prefix)?;
        let ops_len = dpm.nodes.iter().map(|n| n.len as u64).sum::<u64>();
        let ops_start = prefix.len() as u64;
        if len != ops_start + ops_len + 4 {
            return Err(if len < ops_start + ops_len + 4 {
                DpmError::Truncated("operations section")
            } else {
                DpmError::TrailingBytes((len - ops_start - ops_len - 4) as usize)
            });
        }
        let nodes = dpm.nodes.clone();
        Ok(Some(NodeFile { file, prefix, ops_start, nodes }))
    }

    /// The file's bytes up to its operations: [`Dpm::parse_prefix`] parses them.
    pub fn prefix(&self) -> &[u8] {
        &self.prefix
    }

    /// Reads and checks node `i`.
    pub fn read_node(&self, i: u32) -> Result<Vec<u8>, DpmError> {
        use std::os::unix::fs::FileExt;
        let Some(n) = self.nodes.get(i as usize) else {
            return Err(corrupt(format!("node {i}: past the last node")));
        };
        let mut bytes = vec![0u8; n.len as usize];
        self.file
            .read_exact_at(&mut bytes, self.ops_start + n.offset)
            .map_err(|e| DpmError::Io(format!("node {i}: cannot read: {e}")))?;
        n.check(i, &bytes)?;
        Ok(bytes)
    }
}
