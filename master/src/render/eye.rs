//! A stereo eye, which the frame loop renders and the stats lines name.

/// A stereo eye.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum Eye {
    Left,
    Right,
}
