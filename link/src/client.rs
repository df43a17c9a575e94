//! The host's side of the link: a blocking client over any byte stream (a serial port, a pty).
//! One request at a time; each waits for the reply with its number, keeping stream frames that
//! arrive meanwhile. Bad frames from the board are counted and skipped (the next zero
//! resynchronises), so a burst of noise costs the frames it hit and nothing else.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use crate::frame::{self, Receiver, Refusal, MAX_ENCODED};
use crate::msg::{Header, Hello, LinkError, Reply, Request, Stream, PROTOCOL_VERSION};

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
    bad_frames: u64,
    /// Bytes read from the port and not yet framed.
    inbox: Vec<u8>,
    inbox_pos: usize,
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
            bad_frames: 0,
            inbox: Vec::with_capacity(4096),
            inbox_pos: 0,
        }
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

    /// The next stream frame, waiting until `deadline`; `None` when none came.
    pub fn next_stream(
        &mut self,
        deadline: Instant,
    ) -> Result<Option<(Header, Stream)>, ClientError> {
        if let Some(s) = self.streams.pop_front() {
            return Ok(Some(s));
        }
        loop {
            match self.read_frame(deadline)? {
                Some((h, Reply::Stream(s))) => return Ok(Some((h, s))),
                Some(_) => {}
                None => return Ok(None),
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
