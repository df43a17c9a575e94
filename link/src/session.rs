//! The board's side of the link: what each request does, the active scene's copy and id, the
//! counters' reset point and the link's own counters. The board glue implements [`Board`]
//! (how a scene reaches the sample path, how flash is written) and only moves bytes; every
//! decision about a request is made here, the same on the firmware and the virtual board.

use saw_core::controller::Telemetry;
use saw_core::scene::Config;

use crate::frame::{self, Refusal};
use crate::msg::{
    Counters, Header, Hello, LinkCounters, LinkError, Reply, Request, SceneSource, StoreFault,
    NAME_BYTES, PROTOCOL_VERSION,
};
use crate::scene_id;

/// What the session needs from the board it runs on.
#[allow(async_fn_in_trait)] // used with concrete types only; no `Send` bound is wanted on target
pub trait Board {
    /// Compiles `config` and makes it active from the next sample, or refuses it with nothing
    /// changed (the controller's compile step: `Controller::load`). Records of the samples it
    /// runs carry `stamp`, and the first of them is sent whatever the decimation
    /// ([`crate::stream::Decimator::force_next`]).
    async fn apply(
        &mut self,
        config: &Config,
        stamp: Stamp,
    ) -> Result<(), saw_core::controller::ConfigError>;
    /// The board's clock, µs since boot.
    fn now_us(&mut self) -> u64;
    /// The control core's counters now (on the firmware the control loop hands them over
    /// between two samples).
    async fn telemetry(&mut self) -> Telemetry;
    /// Stream one record every `every_samples` samples from now (0: stop).
    fn stream(&mut self, every_samples: u16);
    /// Telemetry records (dropped, sent) since boot.
    fn stream_counts(&mut self) -> (u32, u32);
    /// Stores `config` as the scene to boot into. The board keeps the carrier off and the
    /// watchdog fed while the flash is busy.
    async fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault>;
}

/// Which scene a sample ran under: what every stream record carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stamp {
    /// The scene's id ([`crate::scene_id`]).
    pub scene_id: u32,
    /// Scene changes since boot (0: the scene the board booted into).
    pub change: u32,
}

/// Who the board is, for [`Request::Hello`].
#[derive(Clone, Copy, Debug)]
pub struct Identity {
    /// Firmware name and version.
    pub firmware: &'static str,
    /// Board name.
    pub board: &'static str,
    /// Samples per second of the control loop.
    pub sample_rate_hz: u32,
}

/// One board's link session.
#[derive(Debug)]
pub struct Session {
    identity: Identity,
    active: Config,
    scene_id: u32,
    source: SceneSource,
    /// Scene changes applied since boot.
    change: u32,
    /// The scene the board booted into (or saved last) and where it came from: a change back
    /// to it (a bench restoring a boundary) reports that source again, not "over the link".
    origin: (u32, SceneSource),
    every_samples: u16,
    link: LinkCounters,
    /// Counter values at the last reset.
    base: Counters,
}

impl Session {
    /// A session over the scene the board booted into (already applied).
    pub fn new(identity: Identity, active: Config, source: SceneSource) -> Self {
        let id = scene_id(&active);
        Self {
            identity,
            scene_id: id,
            active,
            source,
            change: 0,
            origin: (id, source),
            every_samples: 0,
            link: LinkCounters::default(),
            base: Counters::default(),
        }
    }

    /// The active scene.
    pub fn active(&self) -> &Config {
        &self.active
    }

    /// The active scene's id.
    pub fn scene_id(&self) -> u32 {
        self.scene_id
    }

    /// The active scene's stamp: what the board's records carry (the glue stamps the scene
    /// it booted into with this before the first sample).
    pub fn stamp(&self) -> Stamp {
        Stamp {
            scene_id: self.scene_id,
            change: self.change,
        }
    }

    /// Where the active scene came from.
    pub fn source(&self) -> SceneSource {
        self.source
    }

    /// The stream's decimation in force (0: stopped).
    pub fn every_samples(&self) -> u16 {
        self.every_samples
    }

    /// Answers one whole frame (the payload [`frame::Receiver`] reported). The returned header
    /// and reply are what the board sends back.
    pub async fn on_frame<B: Board>(&mut self, board: &mut B, payload: &[u8]) -> (Header, Reply) {
        match frame::request(payload) {
            Ok((header, request)) => {
                self.link.frames_ok = self.link.frames_ok.wrapping_add(1);
                let reply = self.handle(board, request).await;
                (reply_header(header.seq), reply)
            }
            Err(Refusal { seq, error }) => self.on_bad_frame(seq, error),
        }
    }

    /// Counts a refused frame and gives the error reply (seq 0 when the header did not decode).
    pub fn on_bad_frame(&mut self, seq: Option<u32>, error: LinkError) -> (Header, Reply) {
        self.link.frames_bad = self.link.frames_bad.wrapping_add(1);
        (reply_header(seq.unwrap_or(0)), Reply::Error(error))
    }

    async fn handle<B: Board>(&mut self, board: &mut B, request: Request) -> Reply {
        match request {
            Request::Hello => Reply::Hello(Hello {
                protocol: PROTOCOL_VERSION,
                firmware: name(self.identity.firmware),
                board: name(self.identity.board),
                sample_rate_hz: self.identity.sample_rate_hz,
                scene_id: self.scene_id,
                scene_source: self.source,
            }),
            Request::GetScene => Reply::Scene {
                scene_id: self.scene_id,
                source: self.source,
                config: self.active.clone(),
            },
            Request::LoadScene(config) => self.apply(board, config).await,
            Request::MoveBoundary { index, at_um } => match self.active.with_boundary(index, at_um)
            {
                Ok(next) => self.apply(board, next).await,
                Err(e) => Reply::Refused(e),
            },
            Request::SetTexture { region, texture } => {
                match self.active.with_texture(region, texture) {
                    Ok(next) => self.apply(board, next).await,
                    Err(e) => Reply::Refused(e),
                }
            }
            Request::SetDrive(drive) => {
                let next = self.active.with_drive(drive);
                self.apply(board, next).await
            }
            Request::Counters { reset } => {
                let now = self.counters(board).await;
                let since = since(&now, &self.base);
                if reset {
                    self.base = now;
                }
                Reply::Counters(since)
            }
            Request::Stream { every_samples } => {
                // Read before the decimation changes: every record of this stream is of this
                // time or later.
                let from_us = board.now_us();
                self.every_samples = every_samples;
                board.stream(every_samples);
                Reply::Streaming {
                    every_samples,
                    sample_rate_hz: self.identity.sample_rate_hz,
                    from_us,
                }
            }
            Request::Ping => Reply::Pong {
                board_time_us: board.now_us(),
            },
            Request::Save => match board.save(self.scene_id, &self.active).await {
                Ok(()) => {
                    self.source = SceneSource::Saved;
                    self.origin = (self.scene_id, SceneSource::Saved);
                    Reply::Saved {
                        scene_id: self.scene_id,
                    }
                }
                Err(e) => Reply::SaveFailed(e),
            },
        }
    }

    async fn apply<B: Board>(&mut self, board: &mut B, next: Config) -> Reply {
        let stamp = Stamp {
            scene_id: scene_id(&next),
            change: self.change.wrapping_add(1),
        };
        match board.apply(&next, stamp).await {
            Ok(()) => {
                self.scene_id = stamp.scene_id;
                self.change = stamp.change;
                self.active = next;
                self.source = if stamp.scene_id == self.origin.0 {
                    self.origin.1
                } else {
                    SceneSource::Link
                };
                Reply::Applied {
                    scene_id: self.scene_id,
                }
            }
            Err(e) => Reply::Refused(e),
        }
    }

    async fn counters<B: Board>(&self, board: &mut B) -> Counters {
        let (dropped, sent) = board.stream_counts();
        Counters {
            core: board.telemetry().await,
            link: LinkCounters {
                records_dropped: dropped,
                records_sent: sent,
                ..self.link
            },
        }
    }
}

fn reply_header(seq: u32) -> Header {
    Header {
        version: PROTOCOL_VERSION,
        seq,
    }
}

fn name(s: &str) -> heapless::String<NAME_BYTES> {
    let mut out = heapless::String::new();
    for c in s.chars() {
        if out.push(c).is_err() {
            break;
        }
    }
    out
}

/// Counts since `base`; the core's last values (position, velocity, region, f_b) as they are.
fn since(now: &Counters, base: &Counters) -> Counters {
    let (n, b) = (&now.core, &base.core);
    Counters {
        core: Telemetry {
            samples: n.samples.wrapping_sub(b.samples),
            faults: n.faults.wrapping_sub(b.faults),
            region_switches: n.region_switches.wrapping_sub(b.region_switches),
            gate_actions: n.gate_actions.wrapping_sub(b.gate_actions),
            clamped: n.clamped.wrapping_sub(b.clamped),
            line_pulses: n.line_pulses.wrapping_sub(b.line_pulses),
            lines_skipped: n.lines_skipped.wrapping_sub(b.lines_skipped),
            ridge_pulses: n.ridge_pulses.wrapping_sub(b.ridge_pulses),
            ridges_skipped: n.ridges_skipped.wrapping_sub(b.ridges_skipped),
            ..*n
        },
        link: LinkCounters {
            frames_ok: now.link.frames_ok.wrapping_sub(base.link.frames_ok),
            frames_bad: now.link.frames_bad.wrapping_sub(base.link.frames_bad),
            records_dropped: now
                .link
                .records_dropped
                .wrapping_sub(base.link.records_dropped),
            records_sent: now.link.records_sent.wrapping_sub(base.link.records_sent),
        },
    }
}
