//! The host's side of the link: a blocking client over any byte stream (a serial port, a pty).
//! One request at a time; each waits for the reply with its number, keeping stream frames that
//! arrive meanwhile. Bad frames from the board are counted and skipped (the next zero
//! resynchronises), so a burst of noise costs the frames it hit and nothing else.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::clock::Ping;
use crate::frame::{self, Receiver, Refusal, MAX_ENCODED};
use crate::msg::{Header, Hello, LinkError, Reply, Request, Stream, Stream2d, PROTOCOL_VERSION};

/// The host clock's origin: the Unix time read between two monotonic readings, the tightest
/// of a few tries (a thread preempted between the readings would put the origin off by the
/// time it was away).
fn anchor() -> (Instant, u64) {
    (0..5)
        .map(|_| {
            let before = Instant::now();
            let unix_us = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_micros() as u64);
            let after = Instant::now();
            (after - before, before + (after - before) / 2, unix_us)
        })
        .min_by_key(|(gap, _, _)| *gap)
        .map(|(_, at, unix_us)| (at, unix_us))
        .unwrap_or_else(|| (Instant::now(), 0))
}

/// A stream the board started: what [`Client::start_stream`] returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamStart {
    /// Records every this many samples.
    pub every_samples: u16,
    /// Samples per second of the board's control loop.
    pub sample_rate_hz: u32,
    /// The board's clock when it started the stream, µs since boot: no record before it is
    /// handed on.
    pub from_us: u64,
}

/// Why a request got no usable answer. Each reads as one sentence.
#[derive(Debug)]
#[non_exhaustive]
pub enum ClientError {
    /// Reading or writing the port failed.
    Io(io::Error),
    /// No reply within the timeout.
    NoAnswer {
        /// How long the client waited, ms.
        waited_ms: u64,
    },
    /// The board speaks another protocol version.
    WrongVersion {
        /// The board's version.
        board: u16,
        /// This tool's version.
        host: u16,
    },
    /// The board refused the request's frame.
    Link(LinkError),
    /// The board answered with a reply of another kind.
    Unexpected(Box<Reply>),
}

impl std::fmt::Display for ClientError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ClientError::Io(e) => write!(f, "the port failed: {e}"),
            ClientError::NoAnswer { waited_ms } => write!(
                f,
                "no answer within {waited_ms} ms: is the board powered, running this firmware and on this port?"
            ),
            ClientError::WrongVersion { board, host } => write!(
                f,
                "the board speaks protocol version {board} and this tool version {host}: flash the firmware built with this tool (or use the tool built with it)"
            ),
            ClientError::Link(e) => write!(f, "the board refused the request: {e}"),
            ClientError::Unexpected(r) => write!(f, "the board answered with an unexpected reply: {r:?}"),
        }
    }
}

impl std::error::Error for ClientError {}

impl From<io::Error> for ClientError {
    fn from(e: io::Error) -> Self {
        ClientError::Io(e)
    }
}

/// A blocking client. `P` reads with a short timeout of its own (a serial port's) or returns
/// `WouldBlock`; the client keeps its own deadline.
pub struct Client<P: Read + Write> {
    port: P,
    seq: u32,
    timeout: Duration,
    rx: Receiver<MAX_ENCODED>,
    streams: VecDeque<(Header, Stream)>,
    /// 2D stream frames (a board with the touch overlay) that came while waiting for a reply.
    streams_2d: VecDeque<(Header, Stream2d)>,
    bad_frames: u64,
    /// Bytes read from the port and not yet framed.
    inbox: Vec<u8>,
    inbox_pos: usize,
    /// The stream started by this client: records of an earlier board time are stale.
    from_us: Option<u64>,
    /// Stale records dropped.
    stale_records: u64,
    /// The host clock's origin: an instant and the Unix time it stands for.
    anchor: (Instant, u64),
}

impl<P: Read + Write> Client<P> {
    /// A client waiting up to `timeout` for each reply.
    pub fn new(port: P, timeout: Duration) -> Self {
        Self {
            port,
            seq: 0,
            timeout,
            rx: Receiver::default(),
            streams: VecDeque::new(),
            streams_2d: VecDeque::new(),
            bad_frames: 0,
            inbox: Vec::with_capacity(4096),
            inbox_pos: 0,
            from_us: None,
            stale_records: 0,
            anchor: anchor(),
        }
    }

    /// The host's clock: µs since the Unix epoch, read once when the client was made and
    /// carried on by the monotonic clock (a wall-clock step does not jump it).
    pub fn host_us(&self, at: Instant) -> u64 {
        self.anchor.1 + at.saturating_duration_since(self.anchor.0).as_micros() as u64
    }

    /// One round trip of [`Request::Ping`], timed on [`Self::host_us`]'s clock.
    pub fn ping(&mut self) -> Result<Ping, ClientError> {
        let sent = Instant::now();
        match self.request(&Request::Ping)? {
            Reply::Pong { board_time_us } => Ok(Ping {
                host_sent_us: self.host_us(sent),
                host_received_us: self.host_us(Instant::now()),
                board_us: board_time_us,
            }),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Starts (or restarts) the stream at one record every `every_samples` samples. Frames
    /// still in transit from an earlier stream (this client's or another's) are dropped, and so
    /// is every record older than the board's answer: what [`Self::next_stream`] hands on was
    /// sampled after this call reached the board.
    pub fn start_stream(&mut self, every_samples: u16) -> Result<StreamStart, ClientError> {
        match self.request(&Request::Stream { every_samples })? {
            Reply::Streaming {
                every_samples,
                sample_rate_hz,
                from_us,
            } => {
                self.from_us = Some(from_us);
                let stale: usize = self.streams.iter().map(|(_, s)| s.records.len()).sum();
                let stale_2d: usize = self.streams_2d.iter().map(|(_, s)| s.records.len()).sum();
                self.stale_records += (stale + stale_2d) as u64;
                self.streams.clear();
                self.streams_2d.clear();
                Ok(StreamStart {
                    every_samples,
                    sample_rate_hz,
                    from_us,
                })
            }
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Stops the stream; frames that arrive after are dropped until the next start.
    pub fn stop_stream(&mut self) -> Result<(), ClientError> {
        self.from_us = Some(u64::MAX);
        match self.request(&Request::Stream { every_samples: 0 })? {
            Reply::Streaming { .. } => {
                self.streams.clear();
                self.streams_2d.clear();
                Ok(())
            }
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// Records dropped as stale: sampled before the stream this client started.
    pub fn stale_records(&self) -> u64 {
        self.stale_records
    }

    /// Frames from the board that were refused (noise on the line).
    pub fn bad_frames(&self) -> u64 {
        self.bad_frames
    }

    /// The port, for tests that inject faults.
    pub fn port_mut(&mut self) -> &mut P {
        &mut self.port
    }

    /// Sends `request` and waits for its reply.
    pub fn request(&mut self, request: &Request) -> Result<Reply, ClientError> {
        self.request_within(request, self.timeout)
    }

    /// Sends `request` and waits up to `timeout` for its reply: for a request whose answer
    /// takes longer than the client's usual wait (a save that erases a 128 KiB sector).
    pub fn request_within(
        &mut self,
        request: &Request,
        timeout: Duration,
    ) -> Result<Reply, ClientError> {
        self.seq = self.seq.wrapping_add(1).max(1);
        let header = Header {
            version: PROTOCOL_VERSION,
            seq: self.seq,
        };
        let mut out = [0u8; MAX_ENCODED + 1];
        // A leading zero closes whatever partial frame an earlier client left on the board.
        let n = frame::encode(&header, request, &mut out[1..]).map_err(|e| {
            ClientError::Io(io::Error::new(io::ErrorKind::InvalidInput, e.to_string()))
        })?;
        self.port.write_all(&out[..n + 1])?;
        self.port.flush()?;
        let start = Instant::now();
        loop {
            match self.read_frame(start + timeout)? {
                Some((h, Reply::Stream(s))) => self.streams.push_back((h, s)),
                Some((h, Reply::Stream2d(s))) => self.streams_2d.push_back((h, s)),
                Some((h, Reply::Error(e))) if h.seq == self.seq => {
                    return Err(ClientError::Link(e))
                }
                // A frame refused before its number was read: maybe ours, maybe what an earlier
                // client left half-sent (closed by our leading zero). Only noise to count; if it
                // was ours, no reply comes and the timeout says so.
                Some((h, Reply::Error(_))) if h.seq == 0 => self.bad_frames += 1,
                Some((h, reply)) if h.seq == self.seq => return Ok(reply),
                // A stale reply to an earlier request that timed out.
                Some(_) => {}
                None => {
                    return Err(ClientError::NoAnswer {
                        waited_ms: timeout.as_millis() as u64,
                    })
                }
            }
        }
    }

    /// Says hello and checks the protocol version.
    pub fn hello(&mut self) -> Result<Hello, ClientError> {
        match self.request(&Request::Hello)? {
            Reply::Hello(h) if h.protocol == PROTOCOL_VERSION => Ok(h),
            Reply::Hello(h) => Err(ClientError::WrongVersion {
                board: h.protocol,
                host: PROTOCOL_VERSION,
            }),
            other => Err(ClientError::Unexpected(Box::new(other))),
        }
    }

    /// The next stream frame, waiting until `deadline`; `None` when none came. After
    /// [`Self::start_stream`], records sampled before the stream started are taken out (a frame
    /// left with none is skipped).
    pub fn next_stream(
        &mut self,
        deadline: Instant,
    ) -> Result<Option<(Header, Stream)>, ClientError> {
        self.next_frame(deadline)
    }

    /// The next 2D stream frame (a board with the touch overlay), as [`Self::next_stream`]:
    /// records sampled before the stream started are taken out.
    pub fn next_stream_2d(
        &mut self,
        deadline: Instant,
    ) -> Result<Option<(Header, Stream2d)>, ClientError> {
        self.next_frame(deadline)
    }

    /// The next stream frame of kind `S`: one queued while waiting for a reply, else read from
    /// the port (frames of other kinds passed over), with its stale records taken out.
    fn next_frame<S: StreamFrame>(
        &mut self,
        deadline: Instant,
    ) -> Result<Option<(Header, S)>, ClientError> {
        loop {
            let next = match S::queue(self).pop_front() {
                Some(s) => Some(s),
                None => loop {
                    match self.read_frame(deadline)? {
                        Some((h, reply)) => {
                            if let Some(s) = S::from_reply(reply) {
                                break Some((h, s));
                            }
                        }
                        None => break None,
                    }
                },
            };
            let Some((h, mut s)) = next else {
                return Ok(None);
            };
            if s.keep_fresh(self.from_us, &mut self.stale_records) {
                return Ok(Some((h, s)));
            }
        }
    }

    /// Reads until a whole, decodable frame arrives or `deadline` passes.
    fn read_frame(&mut self, deadline: Instant) -> Result<Option<(Header, Reply)>, ClientError> {
        loop {
            while self.inbox_pos < self.inbox.len() {
                let byte = self.inbox[self.inbox_pos];
                self.inbox_pos += 1;
                match self.rx.push(byte) {
                    None => {}
                    Some(Ok(len)) => match frame::message::<Reply>(self.rx.payload(len)) {
                        Ok(m) => return Ok(Some(m)),
                        Err(Refusal {
                            error: LinkError::WrongVersion { ours, theirs },
                            ..
                        }) => {
                            return Err(ClientError::WrongVersion {
                                board: theirs,
                                host: ours,
                            })
                        }
                        Err(_) => self.bad_frames += 1,
                    },
                    Some(Err(_)) => self.bad_frames += 1,
                }
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            self.inbox.clear();
            self.inbox_pos = 0;
            self.inbox.resize(4096, 0);
            match self.port.read(&mut self.inbox) {
                Ok(n) => {
                    self.inbox.truncate(n);
                    if n == 0 {
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::WouldBlock
                            | io::ErrorKind::Interrupted
                    ) =>
                {
                    self.inbox.clear();
                    std::thread::sleep(Duration::from_micros(200));
                }
                Err(e) => {
                    self.inbox.clear();
                    return Err(e.into());
                }
            }
        }
    }
}

/// A stream frame of one kind (1D or 2D), so one loop reads both.
trait StreamFrame: Sized {
    /// The frame, if `reply` is one of this kind.
    fn from_reply(reply: Reply) -> Option<Self>;
    /// Where frames of this kind wait while the client waits for a reply.
    fn queue<P: Read + Write>(client: &mut Client<P>) -> &mut VecDeque<(Header, Self)>;
    /// Takes out the records sampled before `from_us` ([`keep_fresh`]).
    fn keep_fresh(&mut self, from_us: Option<u64>, stale: &mut u64) -> bool;
}

impl StreamFrame for Stream {
    fn from_reply(reply: Reply) -> Option<Self> {
        match reply {
            Reply::Stream(s) => Some(s),
            _ => None,
        }
    }
    fn queue<P: Read + Write>(client: &mut Client<P>) -> &mut VecDeque<(Header, Self)> {
        &mut client.streams
    }
    fn keep_fresh(&mut self, from_us: Option<u64>, stale: &mut u64) -> bool {
        keep_fresh(&mut self.records, from_us, |r| r.time_us, stale)
    }
}

impl StreamFrame for Stream2d {
    fn from_reply(reply: Reply) -> Option<Self> {
        match reply {
            Reply::Stream2d(s) => Some(s),
            _ => None,
        }
    }
    fn queue<P: Read + Write>(client: &mut Client<P>) -> &mut VecDeque<(Header, Self)> {
        &mut client.streams_2d
    }
    fn keep_fresh(&mut self, from_us: Option<u64>, stale: &mut u64) -> bool {
        keep_fresh(&mut self.records, from_us, |r| r.time_us, stale)
    }
}

/// Takes out of a stream frame's `records` those sampled before the stream started
/// (`from_us`), counting them in `stale`; false when none are left (the frame is skipped).
fn keep_fresh<R, const N: usize>(
    records: &mut heapless::Vec<R, N>,
    from_us: Option<u64>,
    time_us: impl Fn(&R) -> u64,
    stale: &mut u64,
) -> bool {
    let Some(from_us) = from_us else {
        return true;
    };
    let before = records.len();
    records.retain(|r| time_us(r) >= from_us);
    *stale += (before - records.len()) as u64;
    !records.is_empty()
}
