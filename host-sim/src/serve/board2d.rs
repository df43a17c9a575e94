//! The virtual board with the 4-wire touch overlay (issue #36): a finger path
//! ([`crate::trajectory2d`]) on the overlay model ([`crate::touch`]), read frame by frame at the
//! board's touch schedule through the core's `TouchSensor` and `Controller2d` into the
//! burst-timer model, as `sim2d::run` does, but incrementally, in real time, behind the link.
//! The link's decisions are `saw_link::session`'s (`Session::new_2d`), as for the 1D board.

use std::collections::VecDeque;

use saw_boards::BoardDef;
use saw_core::controller::{ConfigError, Telemetry};
use saw_core::gate::GateAction;
use saw_core::plane::{Controller2d, Telemetry2d, TouchFault};
use saw_core::scene::Config;
use saw_core::touch::fault::Axis;
use saw_core::touch::frame::{Reading, TouchSensor};
use saw_core::touch::plates::{AdcTiming, Schedule};
use saw_link::msg::{Fault2d, Header, PlaneScene, Record2d, Reply, StoreFault};
use saw_link::session::{Apply2dError, Board, Stamp};
use saw_link::stream::{Batcher2d, Decimator, QUEUE_RECORDS};

use crate::sim::burst_timer;
use crate::sim2d::{adc_timing, frame_period_us, schedule, SCREEN_MM};
use crate::timer::{LevelPort, TimerModel};
use crate::touch::{Finger, Overlay, TouchModel};
use crate::trajectory2d::Trajectory2d;

/// Frames of the timer model kept before they are dropped: the virtual board runs for hours.
const HISTORY_FRAMES: u64 = 3_000;

/// The overlay's touch area, µm: `sim2d::SCREEN_MM`, the panel the model's plates stand for.
pub fn plate_um() -> (u32, u32) {
    (
        (SCREEN_MM.0 * 1e3).round() as u32,
        (SCREEN_MM.1 * 1e3).round() as u32,
    )
}

/// A Nucleo with the touch overlay, on the host.
pub struct VirtualBoard2d {
    ctrl: Controller2d,
    sensor: TouchSensor,
    model: TouchModel,
    sched: Schedule,
    adc: AdcTiming,
    tm: TimerModel,
    trajectory: Trajectory2d,
    force_n: f64,
    frame_us: u32,
    next_k: u64,
    /// The burst frequency of the periodic settings running, mHz (0: none).
    burst_millihz: u32,
    decimator: Decimator,
    queue: VecDeque<Record2d>,
    batcher: Batcher2d,
    dropped: u32,
    sent: u32,
    stamp: Stamp,
    now_us: u64,
}

/// Why the 2D board cannot start.
pub type Boot2dError = String;

impl VirtualBoard2d {
    /// Boots with `scene` (checked by `load_2d_for_board` at this board's frame period) and the
    /// finger on `trajectory`: 2 LSB of noise per conversion unless `noise_lsb` says otherwise.
    pub fn boot(
        board: &'static BoardDef,
        scene: &PlaneScene,
        trajectory: Trajectory2d,
        noise_lsb: f64,
        seed: u64,
    ) -> Result<Self, Boot2dError> {
        let overlay = Overlay {
            noise_lsb,
            ..Overlay::default()
        };
        let adc = adc_timing(board);
        let sched = schedule(board, &overlay).map_err(|e| e.to_string())?;
        let frame_us = frame_period_us(&sched);
        let timer = burst_timer(board);
        let mut ctrl = Controller2d::new(timer, frame_us).map_err(|e| e.to_string())?;
        ctrl.load(&scene.config).map_err(|e| e.to_string())?;
        let sensor =
            crate::sim2d::calibrated_sensor(&overlay, &sched, &adc).map_err(|e| e.to_string())?;
        let tm = TimerModel::new(timer.clock_hz, timer.counter_bits, true).with_level(
            LevelPort::new(board.rf_level.table, board.rf_level.envelope_timer_clk_hz),
        );
        Ok(Self {
            ctrl,
            sensor,
            model: TouchModel::new(overlay, seed),
            sched,
            adc,
            tm,
            trajectory,
            force_n: 1.0,
            frame_us,
            next_k: 0,
            burst_millihz: 0,
            decimator: Decimator::default(),
            queue: VecDeque::with_capacity(QUEUE_RECORDS),
            batcher: Batcher2d::default(),
            dropped: 0,
            sent: 0,
            stamp: Stamp::default(),
            now_us: 0,
        })
    }

    /// The touch frame period, µs.
    pub fn frame_us(&self) -> u32 {
        self.frame_us
    }

    /// Stamps the records from now on (the scene booted into: `Session::stamp`).
    pub fn set_stamp(&mut self, stamp: Stamp) {
        self.stamp = stamp;
    }

    /// Runs every frame that ends before `t_us` (board time since boot): the finger where the
    /// path has it at the frame's start, the reading acted on at the frame's end (`sim2d`).
    pub fn run_until(&mut self, t_us: u64) {
        self.now_us = self.now_us.max(t_us);
        let f = self.frame_us as u64;
        let clock = self.tm.clock_hz() as u64;
        let clk = |t_us: u64| t_us * clock / 1_000_000;
        while (self.next_k + 1) * f < t_us {
            let k = self.next_k;
            let (t0_us, t_us) = (k * f, (k + 1) * f);
            let start = self.trajectory.state(t0_us as f64 * 1e-6);
            let (fx, fy) = (
                start.x_um / 1e3 / SCREEN_MM.0,
                start.y_um / 1e3 / SCREEN_MM.1,
            );
            let on_plate = (0.0..=1.0).contains(&fx) && (0.0..=1.0).contains(&fy);
            let finger = on_plate.then_some(Finger {
                x: fx,
                y: fy,
                force_n: self.force_n,
            });
            // Frame stamps are the controller's u32 µs (they wrap after 71 minutes, as the
            // firmware's would; the controller compares them by differences).
            let frame = self
                .model
                .frame(&self.sched, &self.adc, finger.as_ref(), t_us as u32);
            let reading = self.sensor.on_frame(&frame);
            let out = self.ctrl.on_reading(t_us as u32, reading);
            if let Some(e) = out.envelope {
                self.tm.set_envelope(e);
            }
            if let Some(a) = out.amplitude_permille {
                self.tm.set_amplitude(clk(t_us), a);
            }
            if let Some(a) = out.action {
                self.tm.apply(clk(t_us), a);
                self.burst_millihz = millihz(clock, a);
            }
            self.tm.advance_to(clk(t_us));
            if self.decimator.take() {
                let record = Record2d {
                    time_us: t_us,
                    scene_id: self.stamp.scene_id,
                    change: self.stamp.change,
                    position: out.position,
                    velocity_um_s: out.velocity.map(|v| (v.vx_um_s, v.vy_um_s)),
                    place: out.place,
                    edge: out.edge,
                    burst_millihz: if self.tm.is_running() {
                        self.burst_millihz
                    } else {
                        0
                    },
                    bursting: self.tm.is_running(),
                    lifted: reading == Reading::Lifted,
                    fault: out.fault.map(fault_2d),
                };
                if self.queue.len() < QUEUE_RECORDS {
                    self.queue.push_back(record);
                } else {
                    self.dropped = self.dropped.wrapping_add(1);
                }
            }
            // The stale watchdog's tick half a frame later, as `sim2d` ticks.
            let tick_us = t_us + f / 2;
            if let Some(a) = self.ctrl.on_tick(tick_us as u32) {
                self.tm.apply(clk(tick_us), a);
                self.burst_millihz = 0;
            }
            if k.is_multiple_of(HISTORY_FRAMES) {
                self.tm.forget_history();
            }
            self.next_k += 1;
        }
    }

    /// The next stream frame to send: a full batch, or (with `flush`) what is gathered.
    pub fn next_frame(&mut self, flush: bool) -> Option<(Header, Reply)> {
        while let Some(r) = self.queue.pop_front() {
            self.sent = self.sent.wrapping_add(1);
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
        self.batcher = Batcher2d::default();
    }

    /// Records dropped since boot.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }
}

/// The f_b of a gate action's periodic settings, mHz (0 for an off or a pulse).
fn millihz(clock_hz: u64, a: GateAction) -> u32 {
    match a {
        GateAction::Start(s) | GateAction::Update(s) => {
            (clock_hz * 1000 / s.period_clocks().max(1) as u64).min(u32::MAX as u64) as u32
        }
        GateAction::Off | GateAction::Pulse(_) => 0,
    }
}

fn fault_2d(f: TouchFault) -> Fault2d {
    match f {
        TouchFault::Rail(a) => Fault2d::Rail {
            y_axis: a.axis == Axis::Y,
            fault: a.fault,
        },
        TouchFault::Stale => Fault2d::Stale,
    }
}

impl Board for VirtualBoard2d {
    async fn apply(&mut self, _config: &Config, _stamp: Stamp) -> Result<(), ConfigError> {
        // Never asked: the session refuses 1D scenes on a board with the overlay before the
        // glue sees them. Refused here too, should that change.
        Err(ConfigError::Limits(
            saw_core::burst::BurstError::ZeroFrequency,
        ))
    }

    fn now_us(&mut self) -> u64 {
        self.now_us
    }

    async fn telemetry(&mut self) -> Telemetry {
        Telemetry::default()
    }

    fn stream(&mut self, every_samples: u16) {
        self.decimator.set(every_samples);
        self.queue.clear();
    }

    fn stream_counts(&mut self) -> (u32, u32) {
        (self.dropped, self.sent)
    }

    async fn save(&mut self, _scene_id: u32, _config: &Config) -> Result<(), StoreFault> {
        Err(StoreFault::NoStore)
    }

    async fn apply_2d(&mut self, scene: &PlaneScene, stamp: Stamp) -> Result<(), Apply2dError> {
        self.ctrl
            .load(&scene.config)
            .map_err(Apply2dError::Config)?;
        self.stamp = stamp;
        self.decimator.force_next();
        Ok(())
    }

    async fn telemetry_2d(&mut self) -> Telemetry2d {
        self.ctrl.telemetry()
    }
}
