//! The telemetry stream's two halves: [`Decimator`] in the sample path picks which samples
//! become records (one compare per sample, nothing when stopped), [`Batcher`] on the link side
//! packs records into frames and numbers them. Between them the board puts a bounded queue
//! that drops (and counts) when full, so the stream never stalls the sample path.

use heapless::Vec;

/// Records the board queues between the sample path and the link: 64 records are 6.4 ms of
/// every-sample streaming at 10 kHz, several frames' worth, so a link that keeps up never drops
/// and one that does not drops (and counts) instead of stalling anything.
pub const QUEUE_RECORDS: usize = 64;

#[cfg(not(feature = "plane-only"))]
use crate::msg::Stream;
use crate::msg::{Header, Record, Reply, PROTOCOL_VERSION, RECORDS_PER_FRAME};
#[cfg(feature = "plane")]
use crate::msg::{Record2d, Stream2d};

/// One record every `every` samples.
#[derive(Clone, Copy, Debug, Default)]
pub struct Decimator {
    every: u16,
    left: u16,
}

impl Decimator {
    /// Stopped.
    pub const fn new() -> Self {
        Self { every: 0, left: 0 }
    }

    /// Streams every `every` samples from the next one on (0: stop).
    pub fn set(&mut self, every: u16) {
        self.every = every;
        self.left = 0;
    }

    /// The next sample becomes a record (a new scene's first sample), and the count restarts
    /// there; nothing while stopped.
    pub fn force_next(&mut self) {
        self.left = 0;
    }

    /// Whether this sample becomes a record.
    #[inline]
    pub fn take(&mut self) -> bool {
        if self.every == 0 {
            return false;
        }
        if self.left == 0 {
            self.left = self.every - 1;
            true
        } else {
            self.left -= 1;
            false
        }
    }
}

/// The edge a 2D record reports: the last one crossed since the stream's previous record, so a
/// decimated stream (`--every N`) loses no edge pulse to the frames it skips. Two crossings
/// between two records report the later one (at the overlay's ~3.6 kHz frames and a re-arm
/// band of 100 µm, that takes `--every` above ~36 at 1 m/s). One store per crossing and one
/// load per record: the sample path's cost is unchanged between crossings.
#[derive(Clone, Copy, Debug, Default)]
pub struct EdgeLatch {
    edge: Option<u8>,
}

impl EdgeLatch {
    /// Nothing crossed.
    pub const fn new() -> Self {
        Self { edge: None }
    }

    /// A frame's crossing, if any (`Output2d::edge`).
    #[inline]
    pub fn note(&mut self, edge: Option<u8>) {
        if edge.is_some() {
            self.edge = edge;
        }
    }

    /// The edge for a record now: the last one noted since the last take (or the clear).
    #[inline]
    pub fn take(&mut self) -> Option<u8> {
        self.edge.take()
    }

    /// Forgets what was noted (a new stream starts: its first record reports nothing before it).
    pub fn clear(&mut self) {
        self.edge = None;
    }
}

/// A record kind the stream carries, and the reply its frame travels in.
pub trait Streamed: Sized {
    /// `records` as one stream frame's reply (`dropped`: the queue's drop count so far).
    fn frame(dropped: u32, records: Vec<Self, RECORDS_PER_FRAME>) -> Reply;
}

#[cfg(not(feature = "plane-only"))]
impl Streamed for Record {
    fn frame(dropped: u32, records: Vec<Self, RECORDS_PER_FRAME>) -> Reply {
        Reply::Stream(Stream { dropped, records })
    }
}

#[cfg(feature = "plane")]
impl Streamed for Record2d {
    fn frame(dropped: u32, records: Vec<Self, RECORDS_PER_FRAME>) -> Reply {
        Reply::Stream2d(Stream2d { dropped, records })
    }
}

/// Packs records into stream frames ([`Reply::Stream`] for 1D records, [`Reply::Stream2d`]
/// for 2D ones: [`Batcher2d`]).
#[derive(Clone, Debug)]
pub struct Batcher<R = Record> {
    records: Vec<R, RECORDS_PER_FRAME>,
    frames: u32,
}

impl<R> Default for Batcher<R> {
    fn default() -> Self {
        Self {
            records: Vec::new(),
            frames: 0,
        }
    }
}

impl<R: Streamed> Batcher<R> {
    /// Adds a record; returns a full frame to send (`dropped`: the queue's drop count so far).
    pub fn push(&mut self, record: R, dropped: u32) -> Option<(Header, Reply)> {
        // Never full here: a full batch is handed out below before the next push.
        let _ = self.records.push(record);
        if self.records.is_full() {
            self.flush(dropped)
        } else {
            None
        }
    }

    /// The records gathered so far as a frame, if any (the stream stopping, or a quiet link).
    pub fn flush(&mut self, dropped: u32) -> Option<(Header, Reply)> {
        if self.records.is_empty() {
            return None;
        }
        let header = Header {
            version: PROTOCOL_VERSION,
            seq: self.frames,
        };
        self.frames = self.frames.wrapping_add(1);
        let records = core::mem::take(&mut self.records);
        Some((header, R::frame(dropped, records)))
    }
}

/// Packs 2D records into stream frames ([`Reply::Stream2d`]).
#[cfg(feature = "plane")]
pub type Batcher2d = Batcher<Record2d>;
