//! How a side of a mission (the rover or the viewer) fails: the machinery both
//! sides run on (topics, the event log, the MCAP file), or what is the side's own.

use crate::eval::McapWriteError;
use crate::mission::topics::{TopicOpenError, TopicSendError};

/// Why a side of a mission could not run: a failure of the machinery both sides
/// share, or `F`, one of the side's own.
#[derive(Debug, thiserror::Error)]
pub enum RunError<F> {
    /// A topic could not be opened.
    #[error(transparent)]
    Open(#[from] TopicOpenError),
    /// A message could not be sent.
    #[error(transparent)]
    Send(#[from] TopicSendError),
    /// The event log could not be created.
    #[error("cannot create the event log: {0}")]
    Log(#[from] std::io::Error),
    /// The mission's MCAP file could not be written.
    #[error(transparent)]
    Mcap(#[from] McapWriteError),
    /// What only this side fails at.
    #[error(transparent)]
    Side(F),
}
