//! The virtual board with the 4-wire touch overlay (issue #36): a finger path
//! ([`crate::trajectory2d`]) on the overlay model ([`crate::touch`]), read frame by frame at the
//! board's touch schedule through the core's `TouchSensor` and `Controller2d` into the
//! burst-timer model, as `sim2d::run` does, but incrementally, in real time, behind the link.
//! The link's decisions are `saw_link::session`'s (`Session::new_2d`), as for the 1D board.
//! The overlay's touch area is the plate of the scene the board boots with (a real board has one
//! overlay, so a scene pushed later for a larger plate is refused by the session); the plates'
//! electrical model (resistance, capacitance, noise) is `touch::Overlay`'s whatever the size.

use std::collections::VecDeque;

use saw_boards::BoardDef;
use saw_core::controller::{ConfigError, Telemetry};
use saw_core::plane::{Controller2d, Telemetry2d};
use saw_core::scene::Config;
use saw_core::touch::frame::{Reading, TouchSensor};
use saw_core::touch::plates::{AdcTiming, Schedule};
use saw_link::msg::{Fault2d, Header, PlaneScene, Record2d, Reply, StoreFault};
use saw_link::session::{Apply2dError, Board, Stamp};
use saw_link::stream::{Batcher2d, Decimator, EdgeLatch, QUEUE_RECORDS};

use crate::sim::burst_timer;
use crate::sim2d::{adc_timing, frame_period_us, schedule};
use crate::timer::{LevelPort, TimerModel};
use crate::touch::{Finger, Overlay, TouchModel};
use crate::trajectory2d::Trajectory2d;

/// A fault the virtual overlay injects (`host-sim serve --fault` with a 2D scene).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TouchFaultKind {
    /// One axis's position phase reads a rail: 0 (`high` false) or full scale, as an open or
    /// shorted terminal reads (the core's per-axis rail check, `RailBands`).
    Rail {
        /// The Y phase (else X).
        y_axis: bool,
        /// Full scale (else 0).
        high: bool,
    },
    /// The finger lifts off the overlay, landing again where its path is when the fault ends.
    Lift,
    /// No frames at all (the ADC or its DMA stopped): the core's stale watchdog turns the
    /// carrier off after its limit.
    Dropout,
}

/// A fault and when it lasts, µs of board time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TouchFaultWindow {
    /// What happens.
    pub kind: TouchFaultKind,
    /// From, µs since boot.
    pub start_us: u64,
    /// Until (exclusive), µs since boot.
    pub end_us: u64,
}

/// The largest code of a phase (16 conversions of 12 bits summed): a position phase at the high
/// rail.
const CODE_MAX: u16 = (saw_core::sample::CODE_FULL_SCALE - 1) as u16;

/// Frames of the timer model kept before they are dropped: the virtual board runs for hours.
const HISTORY_FRAMES: u64 = 3_000;

/// A Nucleo with the touch overlay, on the host.
pub struct VirtualBoard2d {
    ctrl: Controller2d,
    sensor: TouchSensor,
    model: TouchModel,
    sched: Schedule,
    adc: AdcTiming,
    tm: TimerModel,
    trajectory: Trajectory2d,
    /// The overlay's touch area, µm: the boot scene's plate.
    plate_um: (u32, u32),
    force_n: f64,
    frame_us: u32,
    next_k: u64,
    /// The burst frequency of the periodic settings running, mHz (0: none).
    burst_millihz: u32,
    decimator: Decimator,
    /// The edge the next record reports (the last crossed since the record before).
    edge: EdgeLatch,
    queue: VecDeque<Record2d>,
    batcher: Batcher2d,
    dropped: u32,
    sent: u32,
    stamp: Stamp,
    now_us: u64,
    /// The fault injected, if any.
    fault: Option<TouchFaultWindow>,
}

/// Why the 2D board cannot start.
pub type Boot2dError = String;

impl VirtualBoard2d {
    /// Boots with `scene` (checked by `load_2d_for_board` at this board's frame period) and the
    /// finger on `trajectory`: 2 LSB of noise per conversion unless `noise_lsb` says otherwise.
    /// The overlay's touch area is the scene's plate.
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
        let sensor = crate::sim2d::calibrated_sensor(&overlay, &sched, &adc, scene.plate_um)
            .map_err(|e| match e {
                crate::sim2d::Sim2dError::Calibration(e) => {
                    format!("the overlay's calibration: {e}")
                }
                e => e.to_string(),
            })?;
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
            plate_um: scene.plate_um,
            force_n: 1.0,
            frame_us,
            next_k: 0,
            burst_millihz: 0,
            decimator: Decimator::default(),
            edge: EdgeLatch::new(),
            queue: VecDeque::with_capacity(QUEUE_RECORDS),
            batcher: Batcher2d::default(),
            dropped: 0,
            sent: 0,
            stamp: Stamp::default(),
            now_us: 0,
            fault: None,
        })
    }

    /// Injects `fault` (frames from its start to its end, by their start time).
    pub fn inject(&mut self, fault: TouchFaultWindow) {
        self.fault = Some(fault);
    }

    /// The overlay's touch area, µm (width, height): the plate of the scene it booted with.
    pub fn plate_um(&self) -> (u32, u32) {
        self.plate_um
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
                start.x_um / self.plate_um.0 as f64,
                start.y_um / self.plate_um.1 as f64,
            );
            let on_plate = (0.0..=1.0).contains(&fx) && (0.0..=1.0).contains(&fy);
            let fault = self
                .fault
                .filter(|w| (w.start_us..w.end_us).contains(&t0_us))
                .map(|w| w.kind);
            let finger = (on_plate && fault != Some(TouchFaultKind::Lift)).then_some(Finger {
                x: fx,
                y: fy,
                force_n: self.force_n,
            });
            if fault == Some(TouchFaultKind::Dropout) {
                // No frame: nothing read, nothing recorded; the watchdog's tick still runs.
                self.tm.advance_to(clk(t_us));
                let tick_us = t_us + f / 2;
                if let Some(a) = self.ctrl.on_tick(tick_us as u32) {
                    self.tm.apply(clk(tick_us), a);
                    self.burst_millihz = 0;
                }
                self.next_k += 1;
                continue;
            }
            // Frame stamps are the controller's u32 µs (they wrap after 71 minutes, as the
            // firmware's would; the controller compares them by differences).
            let mut frame = self
                .model
                .frame(&self.sched, &self.adc, finger.as_ref(), t_us as u32);
            if let Some(TouchFaultKind::Rail { y_axis, high }) = fault {
                let code = if high { CODE_MAX } else { 0 };
                if y_axis {
                    frame.y_code = code;
                } else {
                    frame.x_code = code;
                }
            }
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
                self.burst_millihz = Record2d::millihz_of(clock as u32, a);
            }
            self.tm.advance_to(clk(t_us));
            self.edge.note(out.edge);
            if self.decimator.take() {
                let record = Record2d {
                    time_us: t_us,
                    scene_id: self.stamp.scene_id,
                    change: self.stamp.change,
                    position: out.position,
                    velocity_um_s: out.velocity.map(|v| (v.vx_um_s, v.vy_um_s)),
                    place: out.place,
                    edge: self.edge.take(),
                    burst_millihz: if self.tm.is_running() {
                        self.burst_millihz
                    } else {
                        0
                    },
                    bursting: self.tm.is_running(),
                    lifted: reading == Reading::Lifted,
                    fault: out.fault.map(Fault2d::from),
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
        self.edge.clear();
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
        // The old scene's edge numbers mean nothing in the new one.
        self.edge.clear();
        Ok(())
    }

    async fn telemetry_2d(&mut self) -> Telemetry2d {
        self.ctrl.telemetry()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory2d::PointUm as TrajPoint;
    use saw_core::position::SensorFault;

    /// `scenes/<name>` read for the F446 with its plate.
    fn scene(name: &str) -> PlaneScene {
        let path = format!("{}/../scenes/{name}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).unwrap();
        let board = &saw_boards::NUCLEO_F446RE;
        let frame_us = crate::sim2d::board_frame_period_us(board).unwrap();
        let config =
            saw_core::scene_file::load_2d_for_board(&path, &text, burst_timer(board), frame_us)
                .unwrap();
        let plate_um = saw_core::scene_file::plate_um_of(&path, &text).unwrap();
        PlaneScene { plate_um, config }
    }

    /// Every record of `until_us` of board time, the stream at every frame, drained every 5 ms.
    fn records(vb: &mut VirtualBoard2d, until_us: u64) -> Vec<Record2d> {
        Board::stream(vb, 1);
        let mut out = Vec::new();
        for t_us in (5_000..=until_us).step_by(5_000) {
            vb.run_until(t_us);
            while let Some((_, reply)) = vb.next_frame(true) {
                let Reply::Stream2d(s) = reply else {
                    panic!("not a 2D frame: {reply:?}")
                };
                out.extend(s.records.iter().copied());
            }
        }
        out
    }

    /// The finger resting in fig. 12's window 0 (20 Hz), a fault injected from 30 to 60 ms.
    fn faulted(kind: TouchFaultKind) -> Vec<Record2d> {
        let rest = Trajectory2d::rest(TrajPoint::new(17_000.0, 27_000.0)).unwrap();
        let board = &saw_boards::NUCLEO_F446RE;
        let mut vb = VirtualBoard2d::boot(board, &scene("2d-fig12.toml"), rest, 2.0, 1).unwrap();
        vb.inject(TouchFaultWindow {
            kind,
            start_us: 30_000,
            end_us: 60_000,
        });
        records(&mut vb, 150_000)
    }

    /// A rail on one axis: every reading inside the window names that axis and rail with the
    /// carrier off; none before it does, and after it the finger reads and renders again.
    #[test]
    fn an_injected_rail_is_read_as_that_axis_fault_and_turns_the_carrier_off() {
        for (y_axis, high) in [(false, false), (true, true)] {
            let r = faulted(TouchFaultKind::Rail { y_axis, high });
            let want = Fault2d::Rail {
                y_axis,
                fault: if high {
                    SensorFault::RailHigh
                } else {
                    SensorFault::RailLow
                },
            };
            // One frame (280 µs) in at each end: a frame is faulted by its start time.
            let inside: Vec<_> = r
                .iter()
                .filter(|r| (30_400..=60_000).contains(&r.time_us))
                .collect();
            assert!(inside.len() > 80, "{}", inside.len());
            assert!(
                inside.iter().all(|r| r.fault == Some(want) && !r.bursting),
                "{:?}",
                inside.iter().find(|r| r.fault != Some(want) || r.bursting)
            );
            let before: Vec<_> = r
                .iter()
                .filter(|r| (10_000..30_000).contains(&r.time_us))
                .collect();
            assert!(before
                .iter()
                .all(|r| r.fault.is_none() && r.bursting && r.position.is_some()));
            let last = r.last().unwrap();
            assert!(
                last.time_us > 140_000 && last.fault.is_none() && last.bursting,
                "{last:?}"
            );
        }
    }

    /// A lift: every reading inside the window is lifted, with no position and the carrier off;
    /// the finger lands again after it.
    #[test]
    fn an_injected_lift_reads_lifted_and_the_finger_lands_after() {
        let r = faulted(TouchFaultKind::Lift);
        let inside: Vec<_> = r
            .iter()
            .filter(|r| (30_400..=60_000).contains(&r.time_us))
            .collect();
        assert!(inside.len() > 80);
        assert!(inside
            .iter()
            .all(|r| r.lifted && r.position.is_none() && !r.bursting && r.fault.is_none()));
        let last = r.last().unwrap();
        let p = last.position.unwrap();
        assert!(
            (p.x_um - 17_000).abs() <= 300 && (p.y_um - 27_000).abs() <= 300,
            "{last:?}"
        );
        assert!(last.bursting && !last.lifted);
    }

    /// A dropout: no readings at all inside the window (so no records), the stale watchdog's
    /// fault counted (5 ms without a reading, the scene's limit), then readings again.
    #[test]
    fn an_injected_dropout_stops_the_readings() {
        let rest = Trajectory2d::rest(TrajPoint::new(17_000.0, 27_000.0)).unwrap();
        let board = &saw_boards::NUCLEO_F446RE;
        let mut vb = VirtualBoard2d::boot(board, &scene("2d-fig12.toml"), rest, 2.0, 1).unwrap();
        vb.inject(TouchFaultWindow {
            kind: TouchFaultKind::Dropout,
            start_us: 30_000,
            end_us: 60_000,
        });
        let r = records(&mut vb, 150_000);
        assert!(!r.iter().any(|r| (30_400..=60_000).contains(&r.time_us)));
        assert!(r.iter().any(|r| r.time_us < 30_000) && r.iter().any(|r| r.time_us > 60_400));
        assert!(r.last().unwrap().bursting);
        let t = embassy_futures::block_on(Board::telemetry_2d(&mut vb));
        assert_eq!(t.faults, 1, "{t:?}");
    }

    /// A decimated stream reports every edge pulse that fired, each once, on the first record
    /// after it: the finger circles fig. 12's screen (its outlines flagged) at 100 mm/s for 3 s,
    /// streamed at every 5th frame. (With each record reporting only its own frame's crossing,
    /// 4 of the 18 pulses were in the records.)
    #[test]
    fn a_decimated_stream_reports_every_edge_pulse() {
        let board = &saw_boards::NUCLEO_F446RE;
        let fig12 = scene("2d-fig12.toml");
        let (w, h) = (fig12.plate_um.0 as f64, fig12.plate_um.1 as f64);
        let circle =
            Trajectory2d::circle(TrajPoint::new(w / 2.0, h / 2.0), 0.4 * w.min(h), 100e3).unwrap();
        let mut vb = VirtualBoard2d::boot(board, &fig12, circle, 2.0, 3).unwrap();
        Board::stream(&mut vb, 5);
        let mut edges = 0u32;
        let mut records = 0u32;
        for t_us in (5_000..=3_000_000).step_by(5_000) {
            vb.run_until(t_us);
            while let Some((_, reply)) = vb.next_frame(true) {
                let Reply::Stream2d(s) = reply else {
                    panic!("not a 2D frame: {reply:?}")
                };
                records += s.records.len() as u32;
                edges += s.records.iter().filter(|r| r.edge.is_some()).count() as u32;
            }
        }
        let t = embassy_futures::block_on(Board::telemetry_2d(&mut vb));
        assert_eq!(vb.dropped(), 0);
        // 3 s of 280 µs frames, one in five a record.
        assert!((2_100..=2_150).contains(&records), "{records}");
        assert!(t.edge_pulses >= 10, "{t:?}");
        assert_eq!(edges, t.edge_pulses, "{t:?}");
    }

    /// The plate of an 80 × 60 mm scene: a resting finger is read where it rests on that plate,
    /// on both axes. (Calibrated for the fixed 95 × 54 mm screen instead, a finger at (40, 30)
    /// mm, half-way across this plate, read as (47.5, 27) mm.)
    #[test]
    fn the_overlay_is_the_boot_scenes_plate() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/2d-concave.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let board = &saw_boards::NUCLEO_F446RE;
        let frame_us = crate::sim2d::board_frame_period_us(board).unwrap();
        let config =
            saw_core::scene_file::load_2d_for_board(path, &text, burst_timer(board), frame_us)
                .unwrap();
        let scene = PlaneScene {
            plate_um: (80_000, 60_000),
            config,
        };
        for (x_mm, y_mm) in [(40.0, 30.0), (8.0, 52.0), (70.0, 3.0)] {
            let rest = Trajectory2d::rest(TrajPoint::new(x_mm * 1e3, y_mm * 1e3)).unwrap();
            let mut vb = VirtualBoard2d::boot(board, &scene, rest, 2.0, 1).unwrap();
            assert_eq!(vb.plate_um(), (80_000, 60_000));
            Board::stream(&mut vb, 1);
            let mut n = 0;
            // 100 ms of frames, drained every 5 ms (the queue holds 64 records).
            for t_us in (5_000..=100_000).step_by(5_000) {
                vb.run_until(t_us);
                while let Some((_, reply)) = vb.next_frame(true) {
                    let Reply::Stream2d(s) = reply else {
                        panic!("not a 2D frame: {reply:?}")
                    };
                    for r in s.records.iter().filter_map(|r| r.position) {
                        let (dx, dy) = (r.x_um as f64 - x_mm * 1e3, r.y_um as f64 - y_mm * 1e3);
                        assert!(
                            dx.abs() <= 300.0 && dy.abs() <= 300.0,
                            "at ({x_mm}, {y_mm}) mm read ({}, {}) µm",
                            r.x_um,
                            r.y_um
                        );
                        n += 1;
                    }
                }
            }
            assert!(n > 100, "{n} readings at ({x_mm}, {y_mm}) mm");
        }
    }
}
