//! The closed loop on the host: trajectory → ADC model → [`Controller`] → burst-timer model.
//!
//! Samples arrive every `1 / sample_rate_hz` (10 kHz on both boards); each is run through
//! `on_sample` and its gate action applied to the timer model at the sample's time (plus an
//! optional latency). Half a period later `on_tick` runs the stale watchdog, as the firmware's
//! supervision timer does. Every sample period leaves one [`TracePoint`].
//!
//! Each board runs its own acquisition and estimator: [`SimParams::new`] takes the ADC model's
//! conversions per sample from the board ([`AdcParams::for_board`]: 16 on the F446, 32 on the
//! G474) and [`run`] (and [`stream`], the virtual board, the soak) builds the controller with the
//! board's window ([`board_controller`]: `BoardDef::velocity_window`, 32 on the F446, 26 on the
//! G474), as the firmware does.

use saw_boards::BoardDef;
use saw_core::burst::{self, BurstTimer, TimerSettings};
use saw_core::controller::WindowEstimator;
use saw_core::gate::GateAction;
use saw_core::position::SensorFault;
use saw_core::sample::Sample;
use saw_core::velocity::{LsqSlope, Median3, VelocityEstimator};
use saw_core::{Config, ConfigError, Controller, Telemetry};

use crate::adc::{AdcError, AdcModel, AdcParams, FaultWindow};
use crate::timer::{Edge, LevelEdge, LevelPort, TimerModel, Waveform};
use crate::trajectory::{State, Trajectory};

/// Everything a run needs.
#[derive(Clone, Debug)]
pub struct SimParams {
    /// The board (burst timer clock and width, f_b limit, sample rate).
    pub board: &'static BoardDef,
    /// The configuration loaded into the controller.
    pub config: Config,
    /// The finger's motion.
    pub trajectory: Trajectory,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Rheostat / ADC model ([`AdcParams::for_board`] unless changed).
    pub adc: AdcParams,
    /// Timer preload (ARPE/OCxPE) as the firmware sets it; `false` only to show what it prevents.
    pub preload: bool,
    /// Delay from a sample's timestamp to its gate action reaching the timer, µs.
    pub action_latency_us: u32,
}

impl SimParams {
    /// The default run: default scene on `board`, the given trajectory and time, 2 LSB noise on
    /// each of the board's conversions ([`AdcParams::for_board`]).
    pub fn new(board: &'static BoardDef, trajectory: Trajectory, duration_s: f64) -> Self {
        Self {
            board,
            config: saw_core::default_config(),
            trajectory,
            duration_s,
            adc: AdcParams::for_board(board),
            preload: true,
            action_latency_us: 0,
        }
    }

    /// The same run with `config` in the controller instead of the default scene.
    pub fn with_config(mut self, config: Config) -> Self {
        self.config = config;
        self
    }

    /// The same run with `noise_lsb_rms` of ADC noise drawn from `seed`
    /// ([`AdcParams::with_noise`]).
    pub fn with_noise(mut self, noise_lsb_rms: f64, seed: u64) -> Self {
        self.adc = self.adc.with_noise(noise_lsb_rms, seed);
        self
    }

    /// The same run with every conversion's noise drawn ([`AdcParams::per_conversion`]): the
    /// reference noise stream, which figures published before the tabulated sum (issue #16)
    /// were measured on, so their seeds still give the published numbers.
    pub fn with_reference_noise(mut self) -> Self {
        self.adc.per_conversion = true;
        self
    }

    /// The same run with an ADC offset of `offset_lsb`.
    pub fn with_offset(mut self, offset_lsb: f64) -> Self {
        self.adc.offset_lsb = offset_lsb;
        self
    }

    /// The same run with the ADC faulty in `faults`.
    pub fn with_faults(mut self, faults: Vec<FaultWindow>) -> Self {
        self.adc.faults = faults;
        self
    }
}

/// The burst timer of a board as the core sees it.
pub fn burst_timer(board: &BoardDef) -> BurstTimer {
    BurstTimer {
        clock_hz: board.burst_timer_clk_hz,
        counter_bits: board.burst_timer_bits,
        max_burst_hz: board.max_burst_hz,
    }
}

/// The sample period of a board, µs.
pub fn sample_period_us(board: &BoardDef) -> u32 {
    1_000_000 / board.sample_rate_hz
}

/// The default estimator at a board's window (`BoardDef::velocity_window`), chosen at run
/// time: the firmware's `Controller<WindowEstimator<{ BOARD.velocity_window }>>` for each
/// board host-sim runs. Each variant is the core's estimator itself, so a run gives what the
/// bare `WindowEstimator<N>` gives, bit for bit.
#[derive(Clone, Debug)]
pub enum BoardEstimator {
    /// 26 samples (the G474).
    Window26(WindowEstimator<26>),
    /// 32 samples (the F446; the core's `DEFAULT_WINDOW`).
    Window32(WindowEstimator<32>),
}

/// The windows [`BoardEstimator`] has, samples.
pub const BOARD_WINDOWS: [usize; 2] = [26, 32];

macro_rules! each_window {
    ($self:expr, $e:ident => $body:expr) => {
        match $self {
            BoardEstimator::Window26($e) => $body,
            BoardEstimator::Window32($e) => $body,
        }
    };
}

impl BoardEstimator {
    /// The estimator over `window` samples at `sample_period_us`; None for a window host-sim
    /// does not build ([`BOARD_WINDOWS`]).
    pub fn new(window: usize, sample_period_us: u32) -> Result<Option<Self>, ConfigError> {
        fn build<const N: usize>(period_us: u32) -> Result<WindowEstimator<N>, ConfigError> {
            let lsq = LsqSlope::<N>::new(period_us).map_err(ConfigError::Estimator)?;
            Ok(Median3::new(lsq, period_us))
        }
        Ok(match window {
            26 => Some(Self::Window26(build(sample_period_us)?)),
            32 => Some(Self::Window32(build(sample_period_us)?)),
            _ => None,
        })
    }

    /// Its window, samples.
    pub fn window(&self) -> usize {
        match self {
            Self::Window26(_) => 26,
            Self::Window32(_) => 32,
        }
    }
}

impl VelocityEstimator for BoardEstimator {
    #[inline]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        each_window!(self, e => e.update(position_um, t_us))
    }
    #[inline]
    fn reset(&mut self) {
        each_window!(self, e => e.reset())
    }
    #[inline]
    fn group_delay_us(&self) -> u32 {
        each_window!(self, e => e.group_delay_us())
    }
    #[inline]
    fn rests(&self) -> bool {
        each_window!(self, e => e.rests())
    }
    #[inline]
    fn rest(&mut self, position_um: i32, t_us: u32) {
        each_window!(self, e => e.rest(position_um, t_us))
    }
    #[inline]
    fn wake(&mut self) {
        each_window!(self, e => e.wake())
    }
    #[inline]
    fn estimate(&self) -> Option<i32> {
        each_window!(self, e => e.estimate())
    }
}

/// The controller a board's firmware runs: its burst timer, its sample period and the default
/// estimator over its window (`BoardDef::velocity_window`).
pub fn board_controller(board: &BoardDef) -> Result<Controller<BoardEstimator>, SimError> {
    let estimator = board_estimator(board)?;
    Ok(Controller::with_estimator(
        burst_timer(board),
        sample_period_us(board),
        estimator,
    ))
}

/// The default estimator over `board`'s window at its sample period.
pub fn board_estimator(board: &BoardDef) -> Result<BoardEstimator, SimError> {
    BoardEstimator::new(board.velocity_window, sample_period_us(board))
        .map_err(SimError::Controller)?
        .ok_or(SimError::Window(board.velocity_window))
}

/// One sample period of the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracePoint {
    /// Sample time, µs.
    pub t_us: u64,
    /// True finger position, µm.
    pub true_um: f64,
    /// True finger velocity, µm/s.
    pub true_vel_um_s: f64,
    /// Whether a sample arrived (false during a dropout).
    pub sampled: bool,
    /// The code the ADC delivered.
    pub code: Option<u16>,
    /// Position the core measured, µm.
    pub meas_um: Option<i32>,
    /// Velocity the core estimated, µm/s.
    pub est_vel_um_s: Option<i32>,
    /// Region the core chose.
    pub region: Option<u8>,
    /// Gate line after this sample's action.
    pub gate: bool,
    /// Fault in force after this sample (or the tick after it).
    pub fault: Option<SensorFault>,
    /// The action this sample (or its tick) produced.
    pub action: Option<GateAction>,
    /// The tangible line whose pulse this sample fired (the core's `Output::line`): the
    /// metrics count it for its line, not as a burst of the region under it.
    pub line: Option<u8>,
}

impl TracePoint {
    /// The finger's true state at the point.
    #[inline]
    pub fn state(&self) -> State {
        State {
            position_um: self.true_um,
            velocity_um_s: self.true_vel_um_s,
        }
    }

    /// What the core made of the point's sample ([`CoreOut`]).
    #[inline]
    pub fn core_out(&self) -> CoreOut {
        CoreOut {
            meas_um: self.meas_um,
            est_vel_um_s: self.est_vel_um_s,
            region: self.region,
            line: self.line,
            fault: self.fault,
        }
    }
}

/// The part of a [`TracePoint`] the metrics and the chart read that the core works out (the
/// rest is the period's time and the finger's [`State`], known before the loop runs, and the
/// rare gate action). A pipelined run hands these, 24 bytes a period, from the loop's thread to
/// the feeder instead of whole trace points (72 bytes, with `sampled`, `code` and `gate` that
/// no figure of a plain run reads).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoreOut {
    /// Position the core measured, µm.
    pub meas_um: Option<i32>,
    /// Velocity the core estimated, µm/s.
    pub est_vel_um_s: Option<i32>,
    /// Region the core chose.
    pub region: Option<u8>,
    /// The tangible line whose pulse this sample fired.
    pub line: Option<u8>,
    /// Fault in force after this sample (or the tick after it).
    pub fault: Option<SensorFault>,
}

/// A [`CoreOut`] with nothing in it.
const NO_CORE_OUT: CoreOut = CoreOut {
    meas_um: None,
    est_vel_um_s: None,
    region: None,
    line: None,
    fault: None,
};

/// What a run produced.
#[derive(Clone, Debug)]
pub struct SimResult {
    /// The parameters it ran with.
    pub params: SimParams,
    /// The burst timer.
    pub timer: BurstTimer,
    /// Sample period, µs.
    pub sample_period_us: u32,
    /// Per-sample trace.
    pub trace: Vec<TracePoint>,
    /// The enable line.
    pub waveform: Waveform,
    /// The controller's counters at the end.
    pub telemetry: Telemetry,
    /// Per region: the settings the planner gives its texture (None for motion-dependent or off).
    pub region_settings: Vec<Option<TimerSettings>>,
    /// Actions the timer model could not make sense of (should be 0).
    pub timer_protocol_errors: u32,
}

impl SimResult {
    /// Kernel-clock time of µs `t_us`.
    pub fn clocks(&self, t_us: u64) -> u64 {
        t_us * self.timer.clock_hz as u64 / 1_000_000
    }

    /// The trace point covering kernel-clock time `t` (the last sample at or before it).
    pub fn trace_at_clock(&self, t: u64) -> Option<&TracePoint> {
        let t_us = t * 1_000_000 / self.timer.clock_hz as u64;
        let i = (t_us / self.sample_period_us as u64) as usize;
        self.trace.get(i)
    }
}

/// What a summary needs of a run besides its metrics.
#[derive(Clone, Debug)]
pub struct RunHeader {
    /// The parameters it ran with.
    pub params: SimParams,
    /// The burst timer.
    pub timer: BurstTimer,
    /// Sample period, µs.
    pub sample_period_us: u32,
    /// The controller's counters at the end.
    pub telemetry: Telemetry,
    /// Actions the timer model could not make sense of (should be 0).
    pub timer_protocol_errors: u32,
}

impl SimResult {
    /// The run's header (for [`crate::report::summary`]).
    pub fn header(&self) -> RunHeader {
        RunHeader {
            params: self.params.clone(),
            timer: self.timer,
            sample_period_us: self.sample_period_us,
            telemetry: self.telemetry,
            timer_protocol_errors: self.timer_protocol_errors,
        }
    }
}

/// A run that kept no trace: its figures and chart, computed as it went.
#[derive(Clone, Debug)]
pub struct Streamed {
    /// The run.
    pub header: RunHeader,
    /// Its figures.
    pub metrics: crate::metrics::Metrics,
    /// Its chart (None when not asked for).
    pub chart: Option<crate::chart::ChartData>,
    /// Wall time of the closed loop with its metrics and chart recording, s.
    pub loop_s: f64,
    /// CPU time each of the loop's threads ran, s (the thread's CPU clock; empty where it
    /// cannot be read): on a machine busy with other work a pipelined run waits for a CPU, and
    /// its wall time says less than these. Neither this nor `loop_s` counts the bare core
    /// loop's slices ([`BareCore`]) timed in the loop's thread.
    pub busy_s: Vec<f64>,
}

/// CPU time the calling thread has run, ns (its `CLOCK_THREAD_CPUTIME_ID`: one system call,
/// to the nanosecond, cheap enough to bracket each of the bare loop's slices).
fn thread_cpu_ns() -> Option<u64> {
    let t = nix::time::clock_gettime(nix::time::ClockId::CLOCK_THREAD_CPUTIME_ID).ok()?;
    Some(u64::try_from(t.tv_sec()).ok()? * 1_000_000_000 + u64::try_from(t.tv_nsec()).ok()?)
}

/// CPU time the calling thread has run, s ([`thread_cpu_ns`]).
fn thread_cpu_s() -> Option<f64> {
    Some(thread_cpu_ns()? as f64 * 1e-9)
}

/// Why a run could not start.
#[derive(Clone, Debug, PartialEq)]
pub enum SimError {
    /// The controller refused the board's sample period.
    Controller(ConfigError),
    /// The configuration was rejected.
    Config(ConfigError),
    /// The ADC model could not be built.
    Adc(AdcError),
    /// The board's velocity window is not one host-sim builds ([`BOARD_WINDOWS`]).
    Window(usize),
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // The inner errors read as sentences; which stage refused them goes first.
        match self {
            SimError::Controller(e) => write!(f, "the controller refused the board: {e}"),
            SimError::Config(e) => write!(f, "the scene was refused: {e}"),
            SimError::Adc(e) => write!(f, "the ADC model was refused: {e}"),
            SimError::Window(w) => write!(
                f,
                "the board's velocity window of {w} samples is not one host-sim builds \
                 ({BOARD_WINDOWS:?})"
            ),
        }
    }
}

impl std::error::Error for SimError {}

/// Runs the closed loop with the default estimator over the board's window
/// ([`board_controller`]).
pub fn run(params: &SimParams) -> Result<SimResult, SimError> {
    run_controller(params, board_controller(params.board)?)
}

/// Runs the closed loop with another velocity estimator (the bench compares them).
pub fn run_with<E: VelocityEstimator>(
    params: &SimParams,
    estimator: E,
) -> Result<SimResult, SimError> {
    let timer = burst_timer(params.board);
    let ctrl = Controller::with_estimator(timer, sample_period_us(params.board), estimator);
    run_controller(params, ctrl)
}

/// The controller between the ADC model and the timer model, stepped one sample period at a
/// time: what [`run`] loops over and what the virtual board (`host-sim serve`) runs in real
/// time.
#[derive(Clone, Debug)]
pub struct ClosedLoop<E: VelocityEstimator> {
    /// The control core.
    pub ctrl: Controller<E>,
    /// The rheostat and ADC.
    pub adc: AdcModel,
    /// The burst timer.
    pub tm: TimerModel,
    clock_hz: u64,
    period_us: u32,
    action_latency_us: u32,
    /// Kernel clocks a sample period takes, where that is a whole number (both boards: their
    /// clocks are whole multiples of 10 kHz), and the action latency's: then a period's clock
    /// is `k · period + latency` exactly, one multiply, not a conversion of its time.
    period_clk: Option<u64>,
    latency_clk: u64,
    /// From a sample to the stale watchdog's tick after it, µs: half a period, or the action
    /// latency if longer.
    tick_after_us: u64,
    fault: Option<SensorFault>,
    region: Option<u8>,
}

impl<E: VelocityEstimator> ClosedLoop<E> {
    /// `ctrl` with `params.config` loaded, the ADC and timer models of `params`.
    pub fn new(params: &SimParams, mut ctrl: Controller<E>) -> Result<Self, SimError> {
        let timer = burst_timer(params.board);
        ctrl.load(&params.config).map_err(SimError::Config)?;
        // Every trace point carries the estimated velocity (the velocity figures read it), so
        // the estimator runs on every sample here; the bursts are the same either way.
        ctrl.velocity_every_sample(true);
        let adc =
            AdcModel::new(params.config.calibration, params.adc.clone()).map_err(SimError::Adc)?;
        let (period_us, clock_hz) = (sample_period_us(params.board), timer.clock_hz as u64);
        Ok(Self {
            ctrl,
            adc,
            tm: TimerModel::new(timer.clock_hz, timer.counter_bits, params.preload).with_level(
                LevelPort::new(
                    params.board.rf_level.table,
                    params.board.rf_level.envelope_timer_clk_hz,
                ),
            ),
            clock_hz: timer.clock_hz as u64,
            period_us,
            action_latency_us: params.action_latency_us,
            period_clk: (period_us as u64 * clock_hz % 1_000_000 == 0)
                .then_some(period_us as u64 * clock_hz / 1_000_000),
            latency_clk: params.action_latency_us as u64 * clock_hz / 1_000_000,
            tick_after_us: (period_us as u64 / 2).max(params.action_latency_us as u64),
            fault: None,
            region: None,
        })
    }

    /// Kernel-clock ticks at `t_us`.
    pub fn clk(&self, t_us: u64) -> u64 {
        t_us * self.clock_hz / 1_000_000
    }

    /// [`Self::clk`] of period `k`'s time `t_us` plus the action latency: ⌊(k·P + L)·f / 10⁶⌋
    /// is k·(P·f / 10⁶) + ⌊L·f / 10⁶⌋ when P·f / 10⁶ is whole.
    #[inline(always)]
    fn clk_acting(&self, k: u64, t_us: u64) -> u64 {
        match self.period_clk {
            Some(p) => k * p + self.latency_clk,
            None => self.clk(t_us + self.action_latency_us as u64),
        }
    }

    /// Sample period `k`: the finger at `state`, the sample (unless the ADC model drops it),
    /// its gate action, and the stale watchdog's tick half a period later.
    pub fn step(&mut self, k: u64, state: State) -> TracePoint {
        let sample = self
            .adc
            .sample(state.position_um, k * self.period_us as u64);
        self.step_sampled(k, state, sample)
    }

    /// [`Self::step`] with the ADC model's sample for period `k` already drawn (by
    /// [`AdcModel::samples_into`], for a block of periods: the samples do not depend on the
    /// loop, so they can be drawn ahead).
    pub fn step_sampled(&mut self, k: u64, state: State, sample: Option<Sample>) -> TracePoint {
        let mut point = BLANK_POINT;
        self.step_into(k, state, sample, &mut point);
        point
    }

    /// [`Self::step_sampled`] writing its trace point into `point` (every field), so a
    /// pipelined run builds it in its chunk's slot instead of copying it there: the copy
    /// loaded the point's fields right after their one-by-one stores, which the CPU cannot
    /// forward to wider loads, and waited for them.
    #[inline(always)]
    fn step_into(&mut self, k: u64, state: State, sample: Option<Sample>, point: &mut TracePoint) {
        let mut out = NO_CORE_OUT;
        let (action, _) = self.step_core(k, sample, &mut out);
        *point = TracePoint {
            t_us: k * self.period_us as u64,
            true_um: state.position_um,
            true_vel_um_s: state.velocity_um_s,
            sampled: sample.is_some(),
            code: sample.map(|s| s.code),
            meas_um: out.meas_um,
            est_vel_um_s: out.est_vel_um_s,
            region: out.region,
            // The line after this sample's action and its tick's (nothing moves it between).
            gate: self.tm.is_high(),
            fault: out.fault,
            action,
            line: out.line,
        };
    }

    /// Sample period `k` with its sample drawn: the core's part of its trace point into `out`
    /// (every field), its gate action (or its tick's) and `out.region` returned. The region
    /// comes back in a register for the chart recorder: read back from `out`, whose tag and
    /// value bytes are stored one by one, it was one 2-byte load that cannot be forwarded from
    /// them (a third of the loop's own samples before a long run's detail).
    /// [`Self::step_into`] builds the whole point from it; a pipelined run hands on just this.
    #[inline(always)]
    fn step_core(
        &mut self,
        k: u64,
        sample: Option<Sample>,
        out: &mut CoreOut,
    ) -> (Option<GateAction>, Option<u8>) {
        let t_us = k * self.period_us as u64;
        let latency = self.action_latency_us as u64;
        let mut action = None;
        // The region as a number (−1: none), so it is never copied as a whole option.
        let mut region_code = -1i16;
        if let Some(s) = sample {
            let o = self.ctrl.on_sample(s);
            // The port's order (`saw_core::controller::apply`): level and envelope, then line.
            if let Some(e) = o.envelope {
                self.tm.set_envelope(e);
            }
            if let Some(a) = o.amplitude_permille {
                self.tm.set_amplitude(self.clk(t_us + latency), a);
            }
            if let Some(a) = o.action {
                self.tm.apply(self.clk(t_us + latency), a);
                action = Some(a);
            }
            // The core stores each half of these options (tag, value) on its own. Copied
            // whole, two of them were one wider load (16 bytes for the position and the
            // velocity, 4 for the region and the line), which cannot take its bytes from those
            // stores and waits for them to reach the cache (the region and line's load was a
            // quarter of the loop's own samples); taken apart, each load reads one store.
            out.meas_um = None;
            out.est_vel_um_s = None;
            out.region = None;
            out.line = None;
            self.region = None;
            if let Some(m) = o.position_um {
                out.meas_um = Some(m);
            }
            if let Some(v) = o.velocity_um_s {
                out.est_vel_um_s = Some(v);
            }
            if let Some(r) = o.region {
                out.region = Some(r);
                self.region = Some(r);
                region_code = i16::from(r);
            }
            if let Some(l) = o.line {
                out.line = Some(l);
            }
            self.fault = o.fault;
        } else {
            out.meas_um = None;
            out.est_vel_um_s = None;
            out.line = None;
            let region = if self.fault.is_some() {
                None
            } else {
                self.region
            };
            out.region = region;
            region_code = region.map_or(-1, i16::from);
        }
        self.tm.advance_to(self.clk_acting(k, t_us));
        let tick_us = t_us + self.tick_after_us;
        if let Some(a) = self.ctrl.on_tick(tick_us as u32) {
            self.tm.apply(self.clk(tick_us), a);
            action = Some(a);
            self.fault = Some(SensorFault::Stale);
            self.region = None;
            out.region = None;
            region_code = -1;
        }
        out.fault = self.fault;
        let region = u8::try_from(region_code).ok();
        (action, region)
    }
}

/// A trace point's every field empty, for slots [`ClosedLoop::step_into`] fills.
const BLANK_POINT: TracePoint = TracePoint {
    t_us: 0,
    true_um: 0.0,
    true_vel_um_s: 0.0,
    sampled: false,
    code: None,
    meas_um: None,
    est_vel_um_s: None,
    region: None,
    gate: false,
    fault: None,
    action: None,
    line: None,
};

/// The settings the planner gives each region's texture (None where they depend on the motion,
/// or for off).
pub fn region_settings(params: &SimParams) -> Vec<Option<TimerSettings>> {
    let timer = burst_timer(params.board);
    params
        .config
        .scene
        .textures
        .iter()
        .map(|tex| {
            tex.fixed_command()
                .and_then(|cmd| burst::plan(&timer, &params.config.limits, &cmd).ok())
                .map(|(s, _)| s)
        })
        .collect()
}

/// Runs the closed loop with the default estimator keeping no trace: the metrics (and, with
/// `chart`, the chart's data) are computed as it goes, so memory does not grow with the
/// duration. The figures are those [`run`] + [`crate::metrics::compute`] give.
pub fn stream(params: &SimParams, chart: bool) -> Result<Streamed, SimError> {
    stream_with(params, chart, |_| {})
}

/// The process's resident memory now, bytes (Linux's /proc/self/statm; None elsewhere).
pub fn resident_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

/// [`stream`], calling `at_sample` with each sample's index after it is processed (for
/// progress and memory checkpoints). With two or more CPUs the run is pipelined over two
/// threads ([`stream_on`]); its figures and chart are those of the single-threaded run, bit
/// for bit.
pub fn stream_with(
    params: &SimParams,
    chart: bool,
    at_sample: impl FnMut(u64),
) -> Result<Streamed, SimError> {
    stream_on(params, chart, stream_threads(), at_sample)
}

/// The threads [`stream_with`] runs on: 2 where the machine has two CPUs or more, else 1.
pub fn stream_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get().min(2))
}

/// What a streamed run does with each trace point and the timer's edges settled with it: the
/// online metrics and the chart recorder, fed in the same order whichever thread runs them.
struct Sink {
    metrics: crate::metrics::Online,
    recorder: Option<crate::chart::Recorder>,
}

impl Sink {
    fn new(params: &SimParams, chart: bool) -> Self {
        let timer = burst_timer(params.board);
        let period_us = sample_period_us(params.board);
        Self {
            metrics: crate::metrics::Online::new(
                params,
                timer.clock_hz,
                period_us,
                &region_settings(params),
            ),
            recorder: chart.then(|| crate::chart::Recorder::new(params, timer.clock_hz)),
        }
    }

    /// One sample period: the edges and DAC changes settled with it, then its point.
    fn feed(&mut self, point: &TracePoint, edges: &[Edge], levels: &[LevelEdge]) {
        feed_metrics(&mut self.metrics, point, edges);
        if let Some(r) = &mut self.recorder {
            record(r, point, edges, levels);
        }
    }

    /// The edges and DAC changes after the last point (the run's end).
    fn last_edges(&mut self, edges: &[Edge], levels: &[LevelEdge]) {
        self.metrics.edges(edges);
        if let Some(r) = &mut self.recorder {
            r.edges(edges, levels);
        }
    }
}

/// The metrics' share of [`Sink::feed`] (most periods settle no edge: nothing to queue).
#[inline]
fn feed_metrics(metrics: &mut crate::metrics::Online, point: &TracePoint, edges: &[Edge]) {
    if !edges.is_empty() {
        metrics.edges(edges);
    }
    metrics.point(point);
}

/// The chart's share of [`Sink::feed`] (no edge and no DAC change: nothing to draw).
#[inline]
fn record(
    r: &mut crate::chart::Recorder,
    point: &TracePoint,
    edges: &[Edge],
    levels: &[LevelEdge],
) {
    r.point(point);
    if !edges.is_empty() || !levels.is_empty() {
        r.edges(edges, levels);
    }
}

/// Sample periods a pipelined run hands between its threads at once.
const CHUNK: usize = 8 * BLOCK;

/// A chunk of sample periods on its way through the pipeline: the finger states and ADC
/// samples (drawn by the feeder), then what the core made of each period, its gate actions and
/// the edges settled after each (the loop's), for the metrics. The loop hands on only the
/// core's part of each trace point ([`CoreOut`]; the feeder has the time and the state, and
/// actions and edges are rare), so about a third of the memory a whole point took crosses
/// between the CPUs.
#[derive(Default)]
struct Chunk {
    k0: u64,
    states: Vec<State>,
    samples: Vec<Option<Sample>>,
    outs: Vec<CoreOut>,
    /// The gate actions, each with its period's index in the chunk.
    actions: Vec<(u32, GateAction)>,
    edges: Vec<Edge>,
    /// The periods that settled edges: (index in the chunk, the end of its edges in `edges`).
    edge_ends: Vec<(u32, u32)>,
}

/// [`stream_with`] on `threads` threads. With 1 the loop draws each block's states and samples
/// and feeds the metrics and chart itself. With 2 (or more) it is a pipeline: a feeder thread
/// draws the states and ADC samples of chunks ahead (the ADC model's draws all on it, in
/// order) and feeds the metrics the points of chunks behind (in order), while the caller's
/// thread runs the controller and the timer model and records the chart: each of the ADC
/// model, the metrics and the chart recorder gets the same calls with the same values in the
/// same order as on one thread (they share nothing), so the figures and the chart are the
/// same, bit for bit.
pub fn stream_on(
    params: &SimParams,
    chart: bool,
    threads: usize,
    at_sample: impl FnMut(u64),
) -> Result<Streamed, SimError> {
    stream_timed(params, chart, threads, None, at_sample)
}

/// [`stream_on`], timing the bare core loop `bare` in slices on the loop's thread between its
/// chunks ([`BareCore`]): about [`BARE_SLICES_AIMED`] of them, spread over the run. The
/// slices' CPU time is taken out of the loop thread's `busy_s` and their wall time out of
/// `loop_s`, so both are the closed loop's own as without them; the figures and the chart are
/// the same (the bare loop shares nothing with the closed loop).
pub fn stream_timed(
    params: &SimParams,
    chart: bool,
    threads: usize,
    mut bare: Option<&mut BareCore>,
    mut at_sample: impl FnMut(u64),
) -> Result<Streamed, SimError> {
    let timer = burst_timer(params.board);
    let period_us = sample_period_us(params.board);
    let ctrl = board_controller(params.board)?;
    let mut lp = ClosedLoop::new(params, ctrl)?;
    let mut sink = Sink::new(params, chart);
    let (mut edges, mut levels) = (Vec::new(), Vec::new());
    let started = std::time::Instant::now();
    let cpu_started = thread_cpu_s();
    let mut feeder_cpu_s = None;
    let n = samples_in(params);
    // The chunks after which the bare loop runs a slice: one in `every`.
    let every = n.div_ceil(CHUNK as u64).div_ceil(BARE_SLICES_AIMED).max(1);
    let (bare_cpu0, bare_wall0) = bare.as_ref().map_or((0, 0.0), |b| b.spent());
    if threads < 2 {
        drive(&mut lp, params, n, |k, point, lp| {
            lp.tm.take_settled(&mut edges, &mut levels);
            sink.feed(&point, &edges, &levels);
            at_sample(k);
            if (k + 1) % CHUNK as u64 == 0 && ((k + 1) / CHUNK as u64) % every == 0 {
                if let Some(b) = bare.as_mut() {
                    b.slice();
                }
            }
        });
    } else {
        let adc = lp.adc.clone();
        let Sink {
            metrics,
            mut recorder,
        } = sink;
        let (adc, metrics, ran) = std::thread::scope(|scope| {
            let (to_loop, from_feeder) = std::sync::mpsc::sync_channel::<Chunk>(3);
            let (to_feeder, from_loop) = std::sync::mpsc::sync_channel::<Chunk>(3);
            let feeder = scope.spawn(move || {
                let cpu_started = thread_cpu_s();
                let ran = || Some(thread_cpu_s()? - cpu_started?);
                let (mut adc, mut metrics) = (adc, metrics);
                let mut spare: Vec<Chunk> = (0..4).map(|_| Chunk::default()).collect();
                let (mut k0, mut in_flight) = (0u64, 0usize);
                loop {
                    while k0 < n {
                        let Some(mut c) = spare.pop() else { break };
                        let len = (n - k0).min(CHUNK as u64) as usize;
                        c.k0 = k0;
                        params
                            .trajectory
                            .states_into(k0, period_us, len, &mut c.states);
                        adc.samples_into(&c.states, k0, period_us, &mut c.samples);
                        if to_loop.send(c).is_err() {
                            return (adc, metrics, ran());
                        }
                        k0 += len as u64;
                        in_flight += 1;
                    }
                    if in_flight == 0 {
                        return (adc, metrics, ran());
                    }
                    let Ok(c) = from_loop.recv() else {
                        return (adc, metrics, ran());
                    };
                    in_flight -= 1;
                    // The periods' edges and actions, found in order alongside them: the index
                    // of the next period with edges and of the next with an action (u32::MAX:
                    // none left), one comparison each a period.
                    fn next_at<T>(list: &[(u32, T)], i: usize) -> u32 {
                        list.get(i).map_or(u32::MAX, |x| x.0)
                    }
                    let (mut e0, mut ei, mut ai) = (0, 0, 0);
                    let (mut edges_at, mut action_at) =
                        (next_at(&c.edge_ends, 0), next_at(&c.actions, 0));
                    for (i, (state, out)) in c.states.iter().zip(&c.outs).enumerate() {
                        let i = i as u32;
                        if i == edges_at {
                            let e1 = c.edge_ends[ei].1 as usize;
                            metrics.edges(&c.edges[e0..e1]);
                            e0 = e1;
                            ei += 1;
                            edges_at = next_at(&c.edge_ends, ei);
                        }
                        let mut action = None;
                        if i == action_at {
                            action = Some(&c.actions[ai].1);
                            ai += 1;
                            action_at = next_at(&c.actions, ai);
                        }
                        let t_us = (c.k0 + i as u64) * period_us as u64;
                        metrics.period(t_us, state, out, action);
                    }
                    spare.push(c);
                }
            });
            for (chunk, mut c) in (1u64..).zip(from_feeder) {
                // Each period's core output is written in its slot (a chunk's slots are reused
                // as they are; every field is written).
                c.outs.resize(c.states.len(), NO_CORE_OUT);
                c.actions.clear();
                c.edges.clear();
                c.edge_ends.clear();
                let periods = c.samples.iter().zip(&mut c.outs).enumerate();
                for (i, (&sample, out)) in periods {
                    let k = c.k0 + i as u64;
                    let (action, region) = lp.step_core(k, sample, out);
                    if let Some(a) = action {
                        c.actions.push((i as u32, a));
                    }
                    lp.tm.take_settled(&mut edges, &mut levels);
                    if let Some(r) = &mut recorder {
                        r.period(k * period_us as u64, region, &c.states[i], out);
                        if !edges.is_empty() || !levels.is_empty() {
                            r.edges(&edges, &levels);
                        }
                    }
                    if !edges.is_empty() {
                        c.edges.extend_from_slice(&edges);
                        c.edge_ends.push((i as u32, c.edges.len() as u32));
                    }
                    at_sample(k);
                }
                if to_feeder.send(c).is_err() {
                    break;
                }
                // The feeder has this chunk's metrics and the next chunks' draws to work on
                // meanwhile, as it has while the loop steps a chunk.
                if chunk % every == 0 {
                    if let Some(b) = bare.as_mut() {
                        b.slice();
                    }
                }
            }
            drop(to_feeder);
            feeder.join().expect("the feeder thread panicked")
        });
        lp.adc = adc;
        sink = Sink { metrics, recorder };
        feeder_cpu_s = Some(ran);
    }
    let end = lp.clk(n * period_us as u64);
    lp.tm.advance_to(end);
    lp.tm.take_settled(&mut edges, &mut levels);
    sink.last_edges(&edges, &levels);
    let metrics = sink.metrics.finish();
    let chart = sink.recorder.map(crate::chart::Recorder::finish);
    // The bare loop's slices ran on this thread: not the closed loop's time.
    let (bare_cpu_ns, bare_wall_s) = bare.as_ref().map_or((0, 0.0), |b| {
        let (cpu, wall) = b.spent();
        (cpu - bare_cpu0, wall - bare_wall0)
    });
    let loop_s = started.elapsed().as_secs_f64() - bare_wall_s;
    let loop_cpu_s =
        cpu_started.and_then(|c| Some(thread_cpu_s()? - c - bare_cpu_ns as f64 * 1e-9));
    let busy_s = std::iter::once(loop_cpu_s)
        .chain(feeder_cpu_s)
        .collect::<Option<Vec<f64>>>()
        .unwrap_or_default();
    Ok(Streamed {
        header: RunHeader {
            params: params.clone(),
            timer,
            sample_period_us: period_us,
            telemetry: lp.ctrl.telemetry(),
            timer_protocol_errors: lp.tm.protocol_errors,
        },
        metrics,
        chart,
        loop_s,
        busy_s,
    })
}

/// Samples each timed slice of the bare core loop runs ([`BareCore::slice`]): about 45 µs of
/// it, against which the two CPU-clock reads around it (each a system call, well under 1 µs)
/// are about 1 %.
pub const BARE_SLICE: usize = 2048;
/// Samples run untimed before each slice: they bring the bare loop's code and state back into
/// the caches the closed loop's chunk has used since the last slice, so the slice times the
/// loop, not the refill.
const BARE_WARM: usize = 128;
/// Slices a streamed run spreads over its chunks ([`stream_timed`]); a run of fewer chunks has
/// one after each.
pub const BARE_SLICES_AIMED: u64 = 64;

/// The bare core loop: the controller's `on_sample` and `on_tick` alone, over samples the ADC
/// model drew beforehand along the run's trajectory (from its start), with the closed loop's
/// controller, scene and velocity every sample. It is the ceiling a closed loop on this
/// machine is measured against.
///
/// It is timed in slices of [`BARE_SLICE`] samples, each in its thread's CPU time, and its
/// figure is their mean ([`Self::ns_per_sample`]). [`stream_timed`] runs them on the closed
/// loop's own thread between its chunks, spread evenly over the run, so the bare loop and the
/// closed loop share the machine as it is during the run: the same other work, the same CPU,
/// the feeder busy on the other. The closed loop's figure is its threads' CPU time over the
/// whole run, a mean over whatever the machine did meanwhile; the slices' mean is the same
/// kind of figure over the same stretch. (On this machine's virtual CPUs the bare loop runs
/// about 23 ns a sample while the other CPU idles and about 40 ns while it compiles, and a
/// run's slices can hold both: a median would pick one of the two.)
///
/// Before, it was timed after the run as the best of five 200 000-sample passes in wall time:
/// with the feeder gone, and each pass as long as a scheduler's time slice (so other work on
/// the CPU fell into all five), it moved from 22 to 40 ns between runs on a quiet machine and
/// to 54–234 ns under load.
#[derive(Clone, Debug)]
pub struct BareCore {
    fresh: Controller<BoardEstimator>,
    ctrl: Controller<BoardEstimator>,
    input: Vec<Sample>,
    /// The next input sample.
    at: usize,
    period_us: u32,
    /// Each timed slice's CPU time per sample, ns.
    slices_ns: Vec<f64>,
    /// CPU time (ns) and wall time (s) of every slice so far, its warm-up and clock reads
    /// included: what the thread it ran on spent on it.
    spent_cpu_ns: u64,
    spent_wall_s: f64,
    /// Actions the core gave (kept so the loop's work is not optimised away).
    actions: u64,
}

impl BareCore {
    /// The bare loop of `params`' run, over `samples` samples it draws now (it starts again
    /// from the freshly loaded controller when it has run them all).
    pub fn new(params: &SimParams, samples: u64) -> Result<Self, SimError> {
        let period_us = sample_period_us(params.board);
        let mut ctrl = board_controller(params.board)?;
        ctrl.load(&params.config).map_err(SimError::Config)?;
        // The same core work as the closed loop's (which reads the velocity of every sample).
        ctrl.velocity_every_sample(true);
        let mut adc =
            AdcModel::new(params.config.calibration, params.adc.clone()).map_err(SimError::Adc)?;
        // Allocated at its size once: grown by doubling, it freed a block the allocator had
        // mapped on its own, which raises glibc's threshold for such blocks, and the run's
        // allocations after it then stayed resident (1 MB more in the run's memory marks).
        let mut input = Vec::with_capacity(usize::try_from(samples).unwrap_or(0));
        input.extend((0..samples).filter_map(|k| {
            let t_us = k * period_us as u64;
            adc.sample(
                params.trajectory.state(t_us as f64 * 1e-6).position_um,
                t_us,
            )
        }));
        Ok(Self {
            fresh: ctrl.clone(),
            ctrl,
            input,
            at: 0,
            period_us,
            slices_ns: Vec::new(),
            spent_cpu_ns: 0,
            spent_wall_s: 0.0,
            actions: 0,
        })
    }

    /// Runs the next `n` input samples through the core (from the fresh controller again at
    /// the input's end: its time cannot run backwards).
    #[inline(never)]
    fn run(&mut self, mut n: usize) {
        while n > 0 && !self.input.is_empty() {
            if self.at >= self.input.len() {
                self.ctrl = self.fresh.clone();
                self.at = 0;
            }
            let end = self.at + n.min(self.input.len() - self.at);
            let mut actions = 0u64;
            for s in &self.input[self.at..end] {
                let out = self.ctrl.on_sample(*s);
                actions += u64::from(out.action.is_some());
                if self
                    .ctrl
                    .on_tick(s.t_us.wrapping_add(self.period_us / 2))
                    .is_some()
                {
                    actions += 1;
                }
            }
            self.actions += std::hint::black_box(actions);
            n -= end - self.at;
            self.at = end;
        }
    }

    /// One slice: [`BARE_WARM`] samples untimed, then [`BARE_SLICE`] timed in the thread's
    /// CPU time (a slice whose clock cannot be read is not counted).
    pub fn slice(&mut self) {
        let wall = std::time::Instant::now();
        let c0 = thread_cpu_ns();
        self.run(BARE_WARM);
        let c1 = thread_cpu_ns();
        self.run(BARE_SLICE);
        let c2 = thread_cpu_ns();
        if let (Some(c0), Some(c1), Some(c2)) = (c0, c1, c2) {
            if !self.input.is_empty() {
                self.slices_ns
                    .push(c2.saturating_sub(c1) as f64 / BARE_SLICE as f64);
            }
            self.spent_cpu_ns += c2.saturating_sub(c0);
        }
        self.spent_wall_s += wall.elapsed().as_secs_f64();
    }

    /// Runs slices until `slices` are timed (after a run too short for them in between).
    pub fn top_up(&mut self, slices: usize) {
        // Bounded, in case the clock cannot be read.
        for _ in 0..slices {
            if self.slices_ns.len() >= slices {
                break;
            }
            self.slice();
        }
    }

    /// Slices timed.
    pub fn slices(&self) -> usize {
        self.slices_ns.len()
    }

    /// CPU time per sample, ns: the mean of the slices (all of one length), None before any.
    pub fn ns_per_sample(&self) -> Option<f64> {
        let n = self.slices_ns.len();
        (n > 0).then(|| self.slices_ns.iter().sum::<f64>() / n as f64)
    }

    /// CPU time per sample, ns, at the slices' `q` quantile (0.5: the median; nearest rank),
    /// None before any slice.
    pub fn ns_per_sample_at(&self, q: f64) -> Option<f64> {
        let mut v = self.slices_ns.clone();
        v.sort_by(f64::total_cmp);
        let last = v.len().checked_sub(1)?;
        let i = ((last as f64 * q.clamp(0.0, 1.0)).round() as usize).min(last);
        v.get(i).copied()
    }

    /// What the slices so far cost the thread they ran on: CPU time, ns, and wall time, s.
    pub fn spent(&self) -> (u64, f64) {
        (self.spent_cpu_ns, self.spent_wall_s)
    }
}

/// Sample periods whose finger states and ADC samples are worked out ahead, together.
const BLOCK: usize = 512;

/// Runs sample periods 0..`n` of `params` through `lp`, handing each period's trace point to
/// `each` (with its index, and the loop for its timer model). The trajectory and the ADC
/// model do not depend on the loop, so they are worked out a block at a time: the same states
/// and draws, in the same order, as [`ClosedLoop::step`] period by period.
fn drive<E: VelocityEstimator>(
    lp: &mut ClosedLoop<E>,
    params: &SimParams,
    n: u64,
    mut each: impl FnMut(u64, TracePoint, &mut ClosedLoop<E>),
) {
    let (mut states, mut samples) = (Vec::with_capacity(BLOCK), Vec::with_capacity(BLOCK));
    let mut k0 = 0;
    while k0 < n {
        let len = (n - k0).min(BLOCK as u64) as usize;
        params
            .trajectory
            .states_into(k0, lp.period_us, len, &mut states);
        lp.adc.samples_into(&states, k0, lp.period_us, &mut samples);
        for (i, (&state, &sample)) in states.iter().zip(&samples).enumerate() {
            let k = k0 + i as u64;
            let point = lp.step_sampled(k, state, sample);
            each(k, point, lp);
        }
        k0 += len as u64;
    }
}

/// Sample periods in a run of `params`.
pub fn samples_in(params: &SimParams) -> u64 {
    (params.duration_s * 1e6 / sample_period_us(params.board) as f64).round() as u64
}

fn run_controller<E: VelocityEstimator>(
    params: &SimParams,
    ctrl: Controller<E>,
) -> Result<SimResult, SimError> {
    let timer = burst_timer(params.board);
    let period_us = sample_period_us(params.board);
    let mut lp = ClosedLoop::new(params, ctrl)?;

    let region_settings = region_settings(params);
    let n = samples_in(params);
    let mut trace = Vec::with_capacity(n as usize);
    drive(&mut lp, params, n, |_, point, _| trace.push(point));
    let end = lp.clk(n * period_us as u64);
    let timer_protocol_errors = lp.tm.protocol_errors;
    let telemetry = lp.ctrl.telemetry();
    let waveform = lp.tm.finish(end);
    Ok(SimResult {
        params: params.clone(),
        timer,
        sample_period_us: period_us,
        trace,
        waveform,
        telemetry,
        region_settings,
        timer_protocol_errors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run driven in blocks (states and ADC samples worked out ahead) gives the trace that
    /// stepping period by period gives: the same draws in the same order, dropouts (which
    /// draw nothing) and a spike (which draws every conversion) included, across block ends.
    #[test]
    fn blocks_give_the_trace_of_single_steps() {
        use crate::adc::{FaultKind, FaultWindow};
        let params = SimParams::new(
            &saw_boards::ALL[0],
            Trajectory::Triangle {
                a_um: 1_500.0,
                b_um: 61_500.0,
                speed_um_s: 90_000.0,
            },
            0.35,
        )
        .with_noise(3.0, 11)
        .with_faults(vec![
            FaultWindow {
                kind: FaultKind::Dropout,
                start_us: 50_000,
                end_us: 51_230,
            },
            FaultWindow {
                kind: FaultKind::Spike { offset_lsb: 200 },
                start_us: 102_300,
                end_us: 102_500,
            },
        ]);
        let blocks = run(&params).unwrap();
        let ctrl = board_controller(params.board).unwrap();
        let mut lp = ClosedLoop::new(&params, ctrl).unwrap();
        let period_us = sample_period_us(params.board) as u64;
        let single: Vec<TracePoint> = (0..samples_in(&params))
            .map(|k| lp.step(k, params.trajectory.state((k * period_us) as f64 * 1e-6)))
            .collect();
        assert!(single.len() > 3 * BLOCK);
        assert!(single.iter().any(|p| !p.sampled));
        assert_eq!(blocks.trace, single);
    }

    /// A refused scene reads as the stage that refused it and the core's sentence, one line.
    #[test]
    fn refused_scene_reads_as_a_sentence() {
        let mut params = SimParams::new(
            &saw_boards::ALL[0],
            Trajectory::Rest { at_um: 30_000.0 },
            0.01,
        );
        params.config.stale_after_us = 100;
        let e = run(&params).err().unwrap();
        assert_eq!(
            e.to_string(),
            "the scene was refused: stale limit 0.1 ms must be at least two sample periods \
             (0.2 ms) and at most 1000 ms"
        );
    }
}
