//! The virtual board's hardware: the closed loop (finger, ADC, core, burst timer) run sample by
//! sample, the telemetry queue between the sample path and the link, and the scene store. The
//! link's decisions are `saw_link::session`'s, as on the firmware.

use std::collections::VecDeque;

use saw_core::controller::{ConfigError, Telemetry};
use saw_core::scene::Config;
use saw_core::velocity::VelocityEstimator;
use saw_core::Controller;
use saw_link::msg::{Header, Record, Reply, SceneSource, StoreFault};
use saw_link::session::{Board, Stamp};
use saw_link::stream::{Batcher, Decimator, QUEUE_RECORDS};

use crate::sim::{sample_period_us, ClosedLoop, SimError, SimParams};
use crate::trajectory::Trajectory;

/// Where the virtual board keeps its saved scene (a file standing for the flash).
pub trait Persist {
    /// The saved scene, if one is stored and readable.
    fn load(&mut self) -> Option<(u32, Config)>;
    /// Stores a scene to boot into.
    fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault>;
}

/// Records of the timer model kept before they are dropped: the virtual board runs for hours.
const HISTORY_SAMPLES: u64 = 10_000;

/// A Nucleo on the host.
pub struct VirtualBoard<E: VelocityEstimator> {
    lp: ClosedLoop<E>,
    trajectory: Trajectory,
    period_us: u32,
    next_k: u64,
    decimator: Decimator,
    queue: VecDeque<Record>,
    batcher: Batcher,
    dropped: u32,
    sent: u32,
    store: Option<Box<dyn Persist + Send>>,
    /// The scene in force, as its records carry it.
    stamp: Stamp,
    /// The board's clock, µs since boot: where `run_until` last brought it.
    now_us: u64,
}

/// What the board booted into.
pub struct Boot<E: VelocityEstimator> {
    /// The board, running.
    pub board: VirtualBoard<E>,
    /// The scene it runs.
    pub config: Config,
    /// Where that scene came from.
    pub source: SceneSource,
}

impl<E: VelocityEstimator> VirtualBoard<E> {
    /// Boots as the firmware does: the saved scene if one is stored and the controller accepts
    /// it, else `fallback` (the built-in default or the scene given at start-up).
    pub fn boot(
        params: &SimParams,
        ctrl: Controller<E>,
        fallback_source: SceneSource,
        mut store: Option<Box<dyn Persist + Send>>,
    ) -> Result<Boot<E>, SimError> {
        let mut lp = ClosedLoop::new(params, ctrl)?;
        let mut config = params.config.clone();
        let mut source = fallback_source;
        if let Some((_, saved)) = store.as_mut().and_then(|s| s.load()) {
            match lp.ctrl.load(&saved) {
                Ok(()) => {
                    log::info!("boot: the saved scene");
                    config = saved;
                    source = SceneSource::Saved;
                }
                Err(e) => log::warn!("boot: the saved scene is refused ({e}); the default runs"),
            }
        } else {
            log::info!("boot: no saved scene; the {fallback_source:?} scene runs");
        }
        Ok(Boot {
            board: VirtualBoard {
                lp,
                trajectory: params.trajectory.clone(),
                period_us: sample_period_us(params.board),
                next_k: 0,
                decimator: Decimator::default(),
                queue: VecDeque::with_capacity(QUEUE_RECORDS),
                batcher: Batcher::default(),
                dropped: 0,
                sent: 0,
                store,
                stamp: Stamp::default(),
                now_us: 0,
            },
            config,
            source,
        })
    }

    /// Stamps the records from now on (the scene the board booted into, before the first
    /// sample: `Session::stamp`).
    pub fn set_stamp(&mut self, stamp: Stamp) {
        self.stamp = stamp;
    }

    /// Runs every sample due before `t_us` (board time since boot).
    pub fn run_until(&mut self, t_us: u64) {
        self.now_us = self.now_us.max(t_us);
        while self.next_k * (self.period_us as u64) < t_us {
            let k = self.next_k;
            let t_s = (k * self.period_us as u64) as f64 * 1e-6;
            let p = self.lp.step(k, self.trajectory.state(t_s));
            if self.decimator.take() {
                let record = Record {
                    time_us: p.t_us,
                    scene_id: self.stamp.scene_id,
                    change: self.stamp.change,
                    position_um: p.meas_um,
                    velocity_um_s: p.est_vel_um_s,
                    region: p.region,
                    burst_millihz: self.lp.ctrl.burst_millihz(),
                    bursting: self.lp.tm.is_running(),
                    fault: p.fault,
                };
                if self.queue.len() < QUEUE_RECORDS {
                    self.queue.push_back(record);
                } else {
                    self.dropped = self.dropped.wrapping_add(1);
                }
            }
            if k.is_multiple_of(HISTORY_SAMPLES) {
                self.lp.tm.forget_history();
            }
            self.next_k += 1;
        }
    }

    /// The oldest queued record, counted as sent.
    pub fn pop_record(&mut self) -> Option<Record> {
        let r = self.queue.pop_front()?;
        self.sent = self.sent.wrapping_add(1);
        Some(r)
    }

    /// The next stream frame to send: a full batch, or (with `flush`) what is gathered.
    pub fn next_frame(&mut self, flush: bool) -> Option<(Header, Reply)> {
        while let Some(r) = self.pop_record() {
            if let Some(frame) = self.batcher.push(r, self.dropped) {
                return Some(frame);
            }
        }
        if flush {
            self.batcher.flush(self.dropped)
        } else {
            None
        }
    }

    /// Forgets the records gathered for a stream that stopped or restarted.
    pub fn restart_batch(&mut self) {
        self.batcher = Batcher::default();
    }

    /// Records dropped since boot.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// The sample period, µs.
    pub fn period_us(&self) -> u32 {
        self.period_us
    }
}

impl<E: VelocityEstimator> Board for VirtualBoard<E> {
    async fn apply(&mut self, config: &Config, stamp: Stamp) -> Result<(), ConfigError> {
        self.lp.ctrl.load(config)?;
        self.stamp = stamp;
        self.decimator.force_next();
        Ok(())
    }

    fn now_us(&mut self) -> u64 {
        self.now_us
    }

    async fn telemetry(&mut self) -> Telemetry {
        self.lp.ctrl.telemetry()
    }

    fn stream(&mut self, every_samples: u16) {
        self.decimator.set(every_samples);
        // Records of the stream before are stale to whoever asked: the line is not spent on them.
        self.queue.clear();
    }

    fn stream_counts(&mut self) -> (u32, u32) {
        (self.dropped, self.sent)
    }

    async fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault> {
        match self.store.as_mut() {
            Some(s) => s.save(scene_id, config),
            None => Err(StoreFault::NoStore),
        }
    }
}
