//! Figures of merit of a run: commanded vs produced f_b per region (from the gate edges), region
//! switches against the scene's boundaries, velocity error and delay, faults, pulse integrity;
//! tangible lines' pulses on their own; and the same figures per minute of the run ([`Minute`]),
//! which a long run's chart draws.

use std::collections::{HashSet, VecDeque};

use saw_core::burst::TimerSettings;
use saw_core::gate::GateAction;
use saw_core::texture::Texture;

use crate::sim::{CoreOut, SimResult, TracePoint};
use crate::timer::Edge;
use crate::trajectory::State;

/// The f_b a texture asks for with the finger at `true_vel_um_s`, Hz, by the models the core
/// uses: f = |V|/λ for a grating (one pulse per ridge crossed, or periodic bursts at that rate),
/// the stick-slip frequency for a material. None for `off`, a
/// constant texture (it has a commanded f_b) and a finger at rest. For random draws it is the
/// rate the draws give (a harmonic mean), which is what the gate's period count measures.
pub fn expected_hz(texture: &Texture, true_vel_um_s: f64) -> Option<f64> {
    let speed_um_s = true_vel_um_s.abs();
    match texture {
        Texture::Grating(g) if speed_um_s > 0.0 => Some(speed_um_s / g.wavelength_um as f64),
        Texture::Material(m) if speed_um_s > 0.0 => {
            Some(m.stick_slip_hz((speed_um_s * 1e-6) as f32) as f64)
        }
        Texture::Random(r) => {
            // f uniform on c(1 ± s): the rate of bursts is 1/E[1/f] = c·2s / ln((1 + s)/(1 − s)).
            let c = r.center_millihz as f64 / 1000.0;
            let spread = r.spread_permille as f64 / 1000.0;
            Some(if spread > 0.0 {
                c * 2.0 * spread / ((1.0 + spread) / (1.0 - spread)).ln()
            } else {
                c
            })
        }
        _ => None,
    }
}

/// Burst figures of one region.
#[derive(Clone, Debug, PartialEq)]
pub struct RegionStats {
    /// Region index.
    pub region: u8,
    /// f_b the scene asks for, Hz (None for an off or motion-dependent texture).
    pub commanded_hz: Option<f64>,
    /// f_b measured on the gate line while the finger was in this region, Hz.
    pub produced_hz: Option<f64>,
    /// (produced − commanded) / commanded, %.
    pub error_pct: Option<f64>,
    /// For a texture driven by motion or chance (grating, material, random): the f_b its model
    /// gives at the finger's true speed, over the measured intervals (the number of intervals
    /// over the sum of the expected periods, as `produced_hz` is over the measured ones), Hz.
    pub expected_hz: Option<f64>,
    /// Pulses that started in this region.
    pub pulses: usize,
    /// Rise-to-rise intervals used for the measurement (whole intervals inside the region).
    pub intervals: usize,
    /// Mean on-time / period of those intervals, %.
    pub duty_pct: Option<f64>,
    /// Time spent in the region, s.
    pub time_s: f64,
}

/// One region switch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Switch {
    /// Sample time, µs.
    pub t_us: u64,
    /// Region left.
    pub from: u8,
    /// Region entered.
    pub to: u8,
    /// The boundary crossed, µm.
    pub boundary_um: f64,
    /// True finger position at the switch, µm.
    pub true_um: f64,
    /// Measured position at the switch, µm.
    pub meas_um: Option<i32>,
    /// How far past the boundary (in the direction of travel) the finger was, µm; negative if
    /// the switch came early.
    pub past_um: f64,
}

/// Velocity estimate quality.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelocityStats {
    /// RMS of estimate − true velocity at the same instant, µm/s.
    pub rms_err_um_s: f64,
    /// The lag that best aligns the estimate with the true velocity, µs (a whole number of
    /// sample periods).
    pub delay_us: f64,
    /// RMS error against the true velocity delayed by that lag, µm/s.
    pub rms_err_at_delay_um_s: f64,
    /// Samples compared (every sample with an estimate and no fault).
    pub samples: usize,
}

/// The figures of one minute of a run (the last one may be shorter): what a long run's chart
/// draws over the whole run. A pulse counts in the minute its rise falls in, a sample in the
/// minute of its time.
#[derive(Clone, Debug, PartialEq)]
pub struct Minute {
    /// Start of the minute, s.
    pub start_s: f64,
    /// Time of the run inside it (sample periods), s.
    pub span_s: f64,
    /// Per region: f_b produced, its model's f_b and pulses in this minute.
    pub regions: Vec<MinuteRegion>,
    /// Line pulses whose rise is in this minute (every line together).
    pub line_pulses: usize,
    /// Region switches.
    pub switches: usize,
    /// The least and the most a switch came past its boundary, µm (None without switches).
    pub switch_past_um: Option<(f64, f64)>,
    /// RMS velocity error at zero lag, µm/s (None without an estimate).
    pub velocity_rms_um_s: Option<f64>,
    /// RMS velocity error against the true velocity delayed by the whole run's best-fit delay
    /// ([`VelocityStats::delay_us`]), µm/s.
    pub velocity_rms_at_delay_um_s: Option<f64>,
    /// Fault onsets.
    pub fault_onsets: usize,
    /// Samples with a fault in force.
    pub fault_samples: usize,
    /// Samples.
    pub samples: usize,
}

/// One region's figures in one [`Minute`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MinuteRegion {
    /// f_b measured on the gate line over the whole periods that rose in this minute, Hz.
    pub produced_hz: Option<f64>,
    /// The model's f_b over the same periods (motion- or chance-driven textures), Hz.
    pub expected_hz: Option<f64>,
    /// Pulses (region bursts, not line pulses) that rose in this minute.
    pub pulses: usize,
    /// Whole periods measured.
    pub intervals: usize,
    /// Time the finger spent in the region in this minute, s.
    pub time_s: f64,
}

/// The length of a [`Minute`], µs.
pub const MINUTE_US: u64 = 60_000_000;

/// Where the finger left the calibrated travel (0 … the scene's length).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OffTravel {
    /// Samples with the true position outside the travel.
    pub samples: usize,
    /// Time of the first of them, µs.
    pub first_us: Option<u64>,
}

/// All figures of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    /// Per region.
    pub regions: Vec<RegionStats>,
    /// Every switch, in order (the first [`SWITCHES_LISTED`]).
    pub switches: Vec<Switch>,
    /// How many switches there were.
    pub switch_count: usize,
    /// The least and the most any switch came past its boundary, µm (None without switches).
    pub switch_past_um: Option<(f64, f64)>,
    /// Velocity estimate quality (None if the estimator never produced a value).
    pub velocity: Option<VelocityStats>,
    /// Fault onsets seen in the trace.
    pub fault_onsets: usize,
    /// Samples with a fault in force.
    pub fault_samples: usize,
    /// Samples simulated.
    pub samples: usize,
    /// Complete pulses on the line.
    pub pulses: usize,
    /// Pulses whose (period, on-time) matches none of the planned region settings, i.e. runts,
    /// doubled or stretched pulses. Pulses ended by an Off or followed by a restart are judged on
    /// on-time only.
    pub malformed_pulses: usize,
    /// How long the line stayed without a rising edge while the core had periodic bursts
    /// running, beyond two of their periods.
    pub stall: Stall,
    /// Samples with the finger off the travel.
    pub off_travel: OffTravel,
    /// Pulses per tangible line (scene order), counted apart from every region's bursts.
    pub line_pulses: Vec<usize>,
    /// The run minute by minute.
    pub minutes: Vec<Minute>,
}

/// A gate that stopped making the bursts the core asked for (without preload, a 32-bit counter
/// that has passed a shortened ARR counts on to 2^32 before it wraps: with ARPE = 0 the new ARR
/// takes effect at once, RM0390 §18.3.1 time-base unit for TIM2–5, §17.3.1 for TIM1/8).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stall {
    /// Total time the line was silent longer than two burst periods while a burst ran, s.
    pub total_s: f64,
    /// The longest such silence, s.
    pub longest_s: f64,
}

/// Lags, in sample periods, the velocity estimate is compared with the true velocity at
/// (0 … 100: up to 10 ms at 10 kHz).
pub const VELOCITY_LAGS: usize = 101;
/// Lags the per-sample sums run over: [`VELOCITY_LAGS`] padded to a whole AVX register (8
/// f32), so the lags past the [`LAG_GROUP`]s are one register kept over the batch instead of
/// a scalar loop a lag. The padding lags (101–103 periods back) are summed and never read.
const LAG_SLOTS: usize = VELOCITY_LAGS.div_ceil(8) * 8;
/// Samples summed in f32 before the sums move to f64 (bounds the rounding error of the
/// per-lag sums while keeping the per-sample loop in SIMD-wide f32).
const LAG_BLOCK: u32 = 256;
/// Region switches listed one by one; beyond this they are counted and summarised only.
pub const SWITCHES_LISTED: usize = 1_000;
/// Estimates whose lag sums wait to be added together: each group of lags then stays in
/// registers over the batch instead of being loaded and stored for every sample.
const LAG_BATCH: usize = 16;
/// True velocities the lag window slides over before it is moved back to the buffer's end
/// (the windows of the batch must stay in place until it is added).
const TRUE_BUFFER: usize = 1024 + LAG_SLOTS;
/// Recent sample points the gate's edges are placed against (an edge is placed once the point
/// covering it has arrived, so two or three are enough; eight leave room).
const RING: usize = 8;

/// What the metrics remember of one recent sample point.
#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    /// Sample index (u64::MAX: empty).
    index: u64,
    region: Option<u8>,
    /// Identifies the run of equal regions this point belongs to (a point without a region is
    /// a run of its own).
    run: u64,
    true_vel_um_s: f64,
}

/// What the metrics remember of the point before the current one.
#[derive(Clone, Copy, Debug)]
struct Prev {
    region: Option<u8>,
    /// A fault was in force.
    fault: bool,
}

/// What [`Online::period`] reads of a sample period besides the core's estimates.
#[derive(Clone, Copy, Debug)]
struct Parts {
    t_us: u64,
    true_um: f64,
    true_vel_um_s: f64,
    region: Option<u8>,
    fault: Option<saw_core::position::SensorFault>,
    line: Option<u8>,
}

/// A pulse as the metrics follow it: where its rise was placed.
#[derive(Clone, Copy, Debug)]
struct Placed {
    rise: u64,
    /// The region of the sample before the rise (whose settings the rise latched).
    region: Option<u8>,
    /// The run of the sample before that one, if it was in the same region: the interval to
    /// the next rise counts for the region only if that run lasts until the next rise.
    run_before: Option<u64>,
    /// The f_b the texture's model gives at the finger's speed at the rise, Hz.
    expected_hz: Option<f64>,
    /// The tangible line this pulse was fired for (then it is no burst of `region`).
    line: Option<u8>,
}

/// Per-region running sums.
#[derive(Clone, Copy, Debug, Default)]
struct RegionSums {
    pulses: usize,
    intervals: usize,
    interval_clk: u64,
    on_clk: u64,
    expected_period_s: f64,
    expected_n: usize,
    samples: usize,
}

/// One minute's running sums.
#[derive(Clone, Debug)]
struct MinuteSums {
    regions: Vec<RegionSums>,
    line_pulses: usize,
    switches: usize,
    switch_past_um: Option<(f64, f64)>,
    fault_onsets: usize,
    fault_samples: usize,
    samples: usize,
    vel_n: usize,
    lag_sums: [f64; VELOCITY_LAGS],
}

impl MinuteSums {
    fn new(regions: usize) -> Self {
        Self {
            regions: vec![RegionSums::default(); regions],
            line_pulses: 0,
            switches: 0,
            switch_past_um: None,
            fault_onsets: 0,
            fault_samples: 0,
            samples: 0,
            vel_n: 0,
            lag_sums: [0.0; VELOCITY_LAGS],
        }
    }
}

/// Widens `range` to hold `x`.
fn widen(range: Option<(f64, f64)>, x: f64) -> Option<(f64, f64)> {
    Some(match range {
        None => (x, x),
        Some((lo, hi)) => (lo.min(x), hi.max(x)),
    })
}

/// The metrics of a run computed as it goes, in memory that does not grow with its length:
/// feed every trace point in order with [`Online::point`] and the gate's edges (in time order,
/// at any time before the points after them) with [`Online::edges`], then [`Online::finish`].
/// [`compute`] feeds a recorded run through it, so both paths give the same figures.
#[derive(Clone, Debug)]
pub struct Online {
    textures: Vec<Texture>,
    boundaries_um: Vec<f64>,
    length_um: f64,
    clock_hz: u32,
    period_clk: u64,
    sample_period_us: u32,
    ring: [Slot; RING],
    points: u64,
    run: u64,
    /// The minute and region of the last points, and how many of them in a row (not yet in
    /// the sums): one count a point instead of three sums in memory touched every point.
    counting: (usize, Option<u8>),
    counted: usize,
    /// What the next point needs of the one before it (None before the first): its region
    /// and whether a fault was in force. Kept instead of the whole point, which the metrics
    /// would copy on every sample.
    prev: Option<Prev>,
    pending: VecDeque<Edge>,
    open: Option<Placed>,
    awaiting: Option<(Placed, u64)>,
    sums: Vec<RegionSums>,
    planned: HashSet<(u64, u64)>,
    /// The (on, period) pair last put in `planned`: most actions repeat the settings before
    /// them, and the set already holds those.
    last_planned: Option<(u64, u64)>,
    pulses: usize,
    malformed: usize,
    // The stall figure (see [`Stall`]).
    last_rise_clk: Option<u64>,
    running_period_clk: Option<u64>,
    replaced_period_clk: u64,
    /// The kernel clock after which the line counts as silent, from the three above (u64::MAX:
    /// no burst running or no rise yet): worked out when one of them changes, so each point
    /// tests one comparison.
    silent_after_clk: u64,
    stall_clk: (u64, u64, u64),
    fault_onsets: usize,
    fault_samples: usize,
    off: OffTravel,
    switches: Vec<Switch>,
    switch_count: usize,
    switch_past_um: Option<(f64, f64)>,
    vel_n: usize,
    /// The true velocity of recent points, newest first from `true_at`, so the window of the
    /// last [`VELOCITY_LAGS`] of any point since the last move is one contiguous slice (mm/s).
    true_buf: Vec<f32>,
    true_at: usize,
    /// Estimates not yet added to the lag sums: (where their window starts in `true_buf`, the
    /// estimate in mm/s), in order.
    lag_pending: Vec<(usize, f32)>,
    /// Σ (estimate − true velocity `lag` points earlier)², per lag: this block's (f32) and the
    /// run's (f64), (mm/s)².
    lag_block: [f32; LAG_SLOTS],
    lag_sums: [f64; VELOCITY_LAGS],
    block_n: u32,
    /// The minute the current f32 block of lag sums belongs to (flushed when it changes).
    lag_minute: usize,
    minutes: Vec<MinuteSums>,
    /// The minute [`Online::minute`] last looked up, and its start (µs): most lookups are of
    /// it, and need no division.
    minute_at: usize,
    minute_from_us: u64,
    /// Gate actions not yet reached by a placed rise: (kernel clock it acts at, the line it
    /// fires for). The first rise after a line's pulse is that line's.
    actions: VecDeque<(u64, Option<u8>)>,
    line_armed: Option<u8>,
    latency_clk: u64,
    line_pulses: Vec<usize>,
    /// The CPU has AVX: the lag sums take [`add_lags_avx`].
    #[cfg(target_arch = "x86_64")]
    avx: bool,
}

impl Online {
    /// Metrics of a run of `params` on a burst timer clocked at `clock_hz`, sampled every
    /// `sample_period_us`; `region_settings` are the settings the planner gives each region's
    /// texture (None where they depend on the motion).
    pub fn new(
        params: &crate::sim::SimParams,
        clock_hz: u32,
        sample_period_us: u32,
        region_settings: &[Option<TimerSettings>],
    ) -> Self {
        let scene = &params.config.scene;
        Self {
            textures: scene.textures.iter().copied().collect(),
            boundaries_um: scene.boundaries_um.iter().map(|&b| b as f64).collect(),
            length_um: params.config.calibration.length_um as f64,
            clock_hz,
            period_clk: sample_period_us as u64 * clock_hz as u64 / 1_000_000,
            sample_period_us,
            ring: [Slot {
                index: u64::MAX,
                ..Slot::default()
            }; RING],
            points: 0,
            run: 0,
            counting: (usize::MAX, None),
            counted: 0,
            prev: None,
            pending: VecDeque::new(),
            open: None,
            awaiting: None,
            sums: vec![RegionSums::default(); scene.textures.len()],
            planned: region_settings
                .iter()
                .flatten()
                .map(|s| (s.on_clocks(), s.period_clocks()))
                .collect(),
            last_planned: None,
            pulses: 0,
            malformed: 0,
            last_rise_clk: None,
            running_period_clk: None,
            replaced_period_clk: 0,
            silent_after_clk: u64::MAX,
            stall_clk: (0, 0, 0),
            fault_onsets: 0,
            fault_samples: 0,
            off: OffTravel::default(),
            switches: Vec::new(),
            switch_count: 0,
            switch_past_um: None,
            vel_n: 0,
            true_buf: Vec::new(),
            true_at: 0,
            lag_pending: Vec::with_capacity(LAG_BATCH),
            lag_block: [0.0; LAG_SLOTS],
            lag_sums: [0.0; VELOCITY_LAGS],
            block_n: 0,
            lag_minute: 0,
            minutes: Vec::new(),
            minute_at: 0,
            // No time is in this "minute" (the first lookup works its minute out).
            minute_from_us: u64::MAX - MINUTE_US,
            actions: VecDeque::new(),
            line_armed: None,
            latency_clk: params.action_latency_us as u64 * clock_hz as u64 / 1_000_000,
            line_pulses: vec![0; scene.lines.positions_um.len()],
            #[cfg(target_arch = "x86_64")]
            avx: std::arch::is_x86_feature_detected!("avx"),
        }
    }

    /// The index of the minute `t_us` falls in, its running sums there.
    #[inline(always)]
    fn minute_index(&mut self, t_us: u64) -> usize {
        if t_us.wrapping_sub(self.minute_from_us) < MINUTE_US {
            self.minute_at
        } else {
            self.new_minute_index(t_us)
        }
    }

    /// [`Self::minute_index`] of a minute other than the last looked up.
    #[cold]
    #[inline(never)]
    fn new_minute_index(&mut self, t_us: u64) -> usize {
        let i = (t_us / MINUTE_US) as usize;
        while self.minutes.len() <= i {
            self.minutes.push(MinuteSums::new(self.textures.len()));
        }
        self.minute_at = i;
        self.minute_from_us = i as u64 * MINUTE_US;
        i
    }

    /// The running sums of the minute `t_us` falls in.
    #[inline]
    fn minute(&mut self, t_us: u64) -> &mut MinuteSums {
        let i = self.minute_index(t_us);
        &mut self.minutes[i]
    }

    /// The minute's running sums of the rise at kernel clock `clk` (a rise at the run's very
    /// end counts in its last minute, which has samples).
    fn minute_of_clock(&mut self, clk: u64) -> &mut MinuteSums {
        let last_us = self.points.saturating_sub(1) * self.sample_period_us as u64;
        let t_us = (clk * 1_000_000 / self.clock_hz as u64).min(last_us);
        self.minute(t_us)
    }

    fn clocks(&self, t_us: u64) -> u64 {
        t_us * self.clock_hz as u64 / 1_000_000
    }

    fn slot(&self, index: u64) -> Option<Slot> {
        let s = self.ring[(index % RING as u64) as usize];
        (s.index == index).then_some(s)
    }

    /// The gate's edges, in time order after those fed before.
    pub fn edges(&mut self, edges: &[Edge]) {
        self.pending.extend(edges.iter().copied());
    }

    /// The next trace point.
    pub fn point(&mut self, p: &TracePoint) {
        self.period(p.t_us, &p.state(), &p.core_out(), p.action.as_ref());
    }

    /// The next sample period, given as its parts: [`Self::point`] of the trace point with
    /// time `t_us`, the finger at `state`, the core's `out` and the gate `action` (a
    /// pipelined run hands on only the core's part and the actions, [`crate::sim::CoreOut`]).
    pub fn period(&mut self, t_us: u64, state: &State, out: &CoreOut, action: Option<&GateAction>) {
        let p = Parts {
            t_us,
            true_um: state.position_um,
            true_vel_um_s: state.velocity_um_s,
            region: out.region,
            fault: out.fault,
            line: out.line,
        };
        let k = self.points;
        self.points += 1;
        let same_run = self
            .prev
            .is_some_and(|q| q.region.is_some() && q.region == p.region);
        if !same_run {
            self.run += 1;
        }
        self.ring[(k % RING as u64) as usize] = Slot {
            index: k,
            region: p.region,
            run: self.run,
            true_vel_um_s: p.true_vel_um_s,
        };
        let minute = self.minute_index(p.t_us);
        if self.counting == (minute, p.region) {
            self.counted += 1;
        } else {
            self.add_counted();
            self.counting = (minute, p.region);
            self.counted = 1;
        }
        if let Some(GateAction::Start(s) | GateAction::Update(s) | GateAction::Pulse(s)) = action {
            let planned = (s.on_clocks(), s.period_clocks());
            if self.last_planned != Some(planned) {
                self.last_planned = Some(planned);
                self.planned.insert(planned);
            }
        }
        if let Some(a) = action {
            let line = match a {
                GateAction::Pulse(_) => p.line,
                _ => None,
            };
            let at = self.clocks(p.t_us) + self.latency_clk;
            self.actions.push_back((at, line));
        }
        // Edges up to this point's time are placed now: the point covering them is known.
        let now = self.clocks(p.t_us);
        while self.pending.front().is_some_and(|e| e.t <= now) {
            if let Some(e) = self.pending.pop_front() {
                self.edge(e, k);
            }
        }
        // Actions up to now that no rise has reached: every rise up to now is placed, so only
        // the last one's line matters for the next rise (and the queue stays as short as the
        // action latency, however long a run goes without a rise).
        while self.actions.front().is_some_and(|a| a.0 <= now) {
            if let Some((_, line)) = self.actions.pop_front() {
                self.line_armed = line;
            }
        }
        self.stall_point(action, now);
        // Faults, travel, switches, velocity.
        if p.fault.is_some() {
            let onset = self.prev.is_none_or(|q| !q.fault);
            self.fault_samples += 1;
            self.fault_onsets += usize::from(onset);
            let minute = self.minute(p.t_us);
            minute.fault_samples += 1;
            minute.fault_onsets += usize::from(onset);
        }
        if !(0.0..=self.length_um).contains(&p.true_um) {
            self.off.samples += 1;
            self.off.first_us.get_or_insert(p.t_us);
        }
        if let Some(w) = self
            .prev
            .and_then(|q| switch_between(q.region, t_us, state, out, &self.boundaries_um))
        {
            self.switch_count += 1;
            self.switch_past_um = widen(self.switch_past_um, w.past_um);
            let minute = self.minute(p.t_us);
            minute.switches += 1;
            minute.switch_past_um = widen(minute.switch_past_um, w.past_um);
            if self.switches.len() < SWITCHES_LISTED {
                self.switches.push(w);
            }
        }
        // An estimate under a fault is not compared.
        let est = out.est_vel_um_s.filter(|_| p.fault.is_none());
        self.velocity_point(p.t_us, p.true_vel_um_s, est);
        self.prev = Some(Prev {
            region: p.region,
            fault: p.fault.is_some(),
        });
    }

    /// The velocity figures' sums for one point: its true velocity enters the lag window, and
    /// its estimate (given only when it has one and no fault) is compared with every lag's.
    fn velocity_point(&mut self, t_us: u64, true_vel_um_s: f64, est_vel_um_s: Option<i32>) {
        let v = (true_vel_um_s * 1e-3) as f32;
        if self.true_buf.is_empty() {
            // Before the run the finger moved as at its start (the trajectory at t = 0).
            self.true_buf = vec![v; TRUE_BUFFER];
            self.true_at = TRUE_BUFFER - (LAG_SLOTS - 1);
        }
        if self.true_at == 0 {
            // The batch's windows are about to move: add them first, then carry the last
            // points' velocities to the buffer's end.
            self.add_pending_lags();
            let keep = LAG_SLOTS - 1;
            self.true_buf.copy_within(..keep, TRUE_BUFFER - keep);
            self.true_at = TRUE_BUFFER - keep;
        }
        self.true_at -= 1;
        self.true_buf[self.true_at] = v;
        let Some(est) = est_vel_um_s else {
            return;
        };
        // A block of f32 sums belongs to one minute: a new minute flushes the last one's.
        let minute = self.minute_index(t_us);
        if minute != self.lag_minute {
            self.flush_lags();
            self.lag_minute = minute;
        }
        self.lag_pending.push((self.true_at, est as f32 * 1e-3));
        if self.lag_pending.len() == LAG_BATCH {
            self.add_pending_lags();
        }
        self.vel_n += 1;
        self.block_n += 1;
        if self.block_n == LAG_BLOCK {
            self.flush_lags();
        }
    }

    /// Adds the waiting estimates to this block's lag sums, in their order.
    fn add_pending_lags(&mut self) {
        let (acc, buf, pending) = (&mut self.lag_block, &self.true_buf, &self.lag_pending);
        match () {
            // SAFETY: `avx` is set only where the CPU has AVX (`Online::new`).
            #[cfg(target_arch = "x86_64")]
            () if self.avx => unsafe { add_lags_avx(acc, buf, pending) },
            () => add_lags(acc, buf, pending),
        }
        self.lag_pending.clear();
    }

    /// Adds this block's lag sums, and its estimates' count, to its minute's and the run's.
    /// (The block's estimates are all of its minute, so the minute counts them here, not one
    /// by one.)
    fn flush_lags(&mut self) {
        self.add_pending_lags();
        let minute = self.lag_minute as u64 * MINUTE_US;
        let (block, block_n) = (self.lag_block, self.block_n);
        let minute = self.minute(minute);
        minute.vel_n += block_n as usize;
        let sums = &mut minute.lag_sums;
        for (sum, acc) in sums.iter_mut().zip(&block) {
            *sum += *acc as f64;
        }
        for (sum, acc) in self.lag_sums.iter_mut().zip(&self.lag_block) {
            *sum += *acc as f64;
        }
        // The padding lags too, or their sums would grow without bound.
        self.lag_block = [0.0; LAG_SLOTS];
        self.block_n = 0;
    }

    /// One edge, placed against the points up to `latest`.
    fn edge(&mut self, e: Edge, latest: u64) {
        // A rise after the last point (the run's end) has no sample before it: not placed.
        if e.high {
            // The actions in force at this rise: the first rise after a line's pulse is it.
            while self.actions.front().is_some_and(|a| a.0 <= e.t) {
                if let Some((_, line)) = self.actions.pop_front() {
                    self.line_armed = line;
                }
            }
            let line = self.line_armed.take();
            if let Some((done, fall)) = self.awaiting.take() {
                // A line's pulse cuts the bursts before it short: their last period is none.
                let next = if line.is_some() { None } else { Some(e.t) };
                self.complete(done, fall, next, latest);
            }
            let idx = e.t.saturating_sub(1) / self.period_clk;
            let at = self.slot(idx);
            let region = at.and_then(|s| s.region);
            let before = self.slot(idx.saturating_sub(1));
            let run_before = match (region, before) {
                (Some(r), Some(b)) if b.region == Some(r) => Some(b.run),
                _ => None,
            };
            let expected_hz = match (region, at) {
                (Some(r), Some(s)) => self
                    .textures
                    .get(r as usize)
                    .and_then(|t| expected_hz(t, s.true_vel_um_s)),
                _ => None,
            };
            // The stall figure counts every rise the line makes.
            self.last_rise_clk = Some(e.t);
            self.replaced_period_clk = 0;
            self.arm_stall();
            self.open = Some(Placed {
                rise: e.t,
                region,
                run_before,
                expected_hz,
                line,
            });
        } else if let Some(p) = self.open.take() {
            self.pulses += 1;
            if let Some(l) = p.line {
                if let Some(n) = self.line_pulses.get_mut(l as usize) {
                    *n += 1;
                }
                self.minute_of_clock(p.rise).line_pulses += 1;
            } else if let Some(r) = p.region {
                if let Some(s) = self.sums.get_mut(r as usize) {
                    s.pulses += 1;
                }
                if let Some(s) = self.minute_of_clock(p.rise).regions.get_mut(r as usize) {
                    s.pulses += 1;
                }
            }
            self.awaiting = Some((p, e.t));
        }
    }

    /// A pulse whose next rise (if any) is known: its interval for its region and its shape.
    fn complete(&mut self, p: Placed, fall: u64, next_rise: Option<u64>, latest: u64) {
        let on = fall - p.rise;
        let period = next_rise.map(|n| n - p.rise);
        if !pulse_matches(on, period, &self.planned) {
            self.malformed += 1;
        }
        let (Some(region), Some(run), Some(next), None) =
            (p.region, p.run_before, next_rise, p.line)
        else {
            return;
        };
        let last = (next / self.period_clk).min(latest);
        if self.slot(last).is_some_and(|s| s.run == run) {
            let add = |s: &mut RegionSums| {
                s.intervals += 1;
                s.interval_clk += next - p.rise;
                s.on_clk += on;
                if let Some(f) = p.expected_hz {
                    s.expected_period_s += 1.0 / f;
                    s.expected_n += 1;
                }
            };
            if let Some(s) = self.sums.get_mut(region as usize) {
                add(s);
            }
            if let Some(s) = self
                .minute_of_clock(p.rise)
                .regions
                .get_mut(region as usize)
            {
                add(s);
            }
        }
    }

    /// Adds the points counted since the last change of minute or region to their sums.
    fn add_counted(&mut self) {
        let ((minute, region), n) = (self.counting, self.counted);
        let Some(m) = self.minutes.get_mut(minute) else {
            return;
        };
        m.samples += n;
        if let Some(r) = region {
            if let Some(s) = m.regions.get_mut(r as usize) {
                s.samples += n;
            }
            if let Some(s) = self.sums.get_mut(r as usize) {
                s.samples += n;
            }
        }
        self.counted = 0;
    }

    /// The stall figure's bookkeeping for one point (its rises already placed).
    #[inline]
    fn stall_point(&mut self, action: Option<&GateAction>, now: u64) {
        if let Some(a) = action {
            match a {
                GateAction::Start(s) => {
                    self.running_period_clk = Some(s.period_clocks());
                    self.last_rise_clk = Some(now);
                }
                GateAction::Update(s) => {
                    // With preload an update acts at the next update event: until the next
                    // rise the period replaced still runs, so it counts for the allowance too.
                    self.replaced_period_clk = self
                        .replaced_period_clk
                        .max(self.running_period_clk.unwrap_or(0));
                    self.running_period_clk = Some(s.period_clocks());
                }
                GateAction::Off | GateAction::Pulse(_) => self.running_period_clk = None,
            }
            self.arm_stall();
        }
        let (total, longest, current) = &mut self.stall_clk;
        if now > self.silent_after_clk {
            *current += self.period_clk;
            *total += self.period_clk;
            *longest = (*longest).max(*current);
        } else {
            *current = 0;
        }
    }

    /// Works out when the line falls silent: a burst running and no rise for more than two of
    /// its periods (or of the period an update replaced), i.e. `now − rise > 2 · period`, as
    /// `now > rise + 2 · period` (false alike for a `now` before the rise).
    fn arm_stall(&mut self) {
        self.silent_after_clk = match (self.running_period_clk, self.last_rise_clk) {
            (Some(period), Some(rise)) => {
                rise.saturating_add(period.max(self.replaced_period_clk).saturating_mul(2))
            }
            _ => u64::MAX,
        };
    }

    /// The figures of everything fed.
    pub fn finish(mut self) -> Metrics {
        self.add_counted();
        let latest = self.points.saturating_sub(1);
        while let Some(e) = self.pending.pop_front() {
            self.edge(e, latest);
        }
        if let Some((p, fall)) = self.awaiting.take() {
            self.complete(p, fall, None, latest);
        }
        let clock = self.clock_hz as f64;
        let regions = self
            .sums
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let commanded_hz = self.textures[i]
                    .fixed_command()
                    .map(|c| c.burst_millihz as f64 / 1000.0);
                let (produced_hz, duty_pct) = if s.intervals == 0 {
                    (None, None)
                } else {
                    (
                        Some(clock * s.intervals as f64 / s.interval_clk as f64),
                        Some(100.0 * s.on_clk as f64 / s.interval_clk as f64),
                    )
                };
                let expected_hz =
                    (s.expected_n > 0).then(|| s.expected_n as f64 / s.expected_period_s);
                let error_pct = match (commanded_hz, produced_hz) {
                    (Some(c), Some(p)) => Some(100.0 * (p - c) / c),
                    _ => None,
                };
                RegionStats {
                    region: i as u8,
                    commanded_hz,
                    expected_hz,
                    produced_hz,
                    error_pct,
                    pulses: s.pulses,
                    intervals: s.intervals,
                    duty_pct,
                    time_s: s.samples as f64 * self.sample_period_us as f64 * 1e-6,
                }
            })
            .collect();
        let velocity = self.velocity();
        let minutes = self.minutes_done(velocity.as_ref());
        let (total, longest, _) = self.stall_clk;
        Metrics {
            regions,
            switches: self.switches,
            switch_count: self.switch_count,
            switch_past_um: self.switch_past_um,
            velocity,
            fault_onsets: self.fault_onsets,
            fault_samples: self.fault_samples,
            samples: self.points as usize,
            pulses: self.pulses,
            malformed_pulses: self.malformed,
            stall: Stall {
                total_s: total as f64 / clock,
                longest_s: longest as f64 / clock,
            },
            off_travel: self.off,
            line_pulses: self.line_pulses,
            minutes,
        }
    }

    /// The minutes' figures (after [`Self::velocity`], whose flush closes the last block and
    /// whose delay the minutes' velocity error is taken at).
    fn minutes_done(&self, velocity: Option<&VelocityStats>) -> Vec<Minute> {
        let clock = self.clock_hz as f64;
        // Whole µs first, one rounding after: a full minute is 60 s exactly.
        let secs = |samples: usize| (samples as u64 * self.sample_period_us as u64) as f64 / 1e6;
        let lag = velocity.map_or(0, |v| (v.delay_us / self.sample_period_us as f64) as usize);
        self.minutes
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let rms =
                    |k: usize| (m.vel_n > 0).then(|| (m.lag_sums[k] / m.vel_n as f64).sqrt() * 1e3);
                Minute {
                    start_s: (i as u64 * MINUTE_US) as f64 * 1e-6,
                    span_s: secs(m.samples),
                    regions: m
                        .regions
                        .iter()
                        .map(|s| MinuteRegion {
                            produced_hz: (s.intervals > 0)
                                .then(|| clock * s.intervals as f64 / s.interval_clk as f64),
                            expected_hz: (s.expected_n > 0)
                                .then(|| s.expected_n as f64 / s.expected_period_s),
                            pulses: s.pulses,
                            intervals: s.intervals,
                            time_s: secs(s.samples),
                        })
                        .collect(),
                    line_pulses: m.line_pulses,
                    switches: m.switches,
                    switch_past_um: m.switch_past_um,
                    velocity_rms_um_s: rms(0),
                    velocity_rms_at_delay_um_s: rms(lag),
                    fault_onsets: m.fault_onsets,
                    fault_samples: m.fault_samples,
                    samples: m.samples,
                }
            })
            .collect()
    }

    /// Velocity RMS error at zero lag and at the best lag, over every sample with an estimate
    /// and no fault. The lag is searched over whole sample periods (0 … [`VELOCITY_LAGS`] − 1):
    /// between them the error against a trajectory with reversals (a triangle's velocity is a
    /// square wave) moves in steps as samples cross the reversal, so a finer lag is no better
    /// defined (`host-sim/tests/streaming.rs` checks the lag found against a 5 µs search).
    fn velocity(&mut self) -> Option<VelocityStats> {
        if self.vel_n == 0 {
            return None;
        }
        self.flush_lags();
        let n = self.vel_n as f64;
        let mse: Vec<f64> = self.lag_sums.iter().map(|s| s / n).collect();
        let (best, &best_mse) = mse.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
        let period_us = self.sample_period_us as f64;
        Some(VelocityStats {
            rms_err_um_s: mse[0].sqrt() * 1e3,
            delay_us: best as f64 * period_us,
            rms_err_at_delay_um_s: best_mse.sqrt() * 1e3,
            samples: self.vel_n,
        })
    }
}

/// Adds, for each `(at, e)` of `pending` in order, (`e` − t)² to each lag's sum in `acc`, t
/// the true velocity that lag back (`window[at + lag]`): the velocity figures' per-sample work
/// (101 lags, padded to [`LAG_SLOTS`]). Each lag's sum takes the same IEEE operations in the
/// same order as one sample at a time would; [`LAG_GROUP`] lags at once, and then the
/// [`LAG_REST`] after them, stay in registers over the batch.
#[inline(always)]
fn add_lags(acc: &mut [f32; LAG_SLOTS], window: &[f32], pending: &[(usize, f32)]) {
    let mut lags = acc.chunks_exact_mut(LAG_GROUP);
    let mut lag0 = 0;
    for group in &mut lags {
        let mut a = [0f32; LAG_GROUP];
        a.copy_from_slice(group);
        for &(at, e) in pending {
            let w = &window[at + lag0..at + lag0 + LAG_GROUP];
            for (a, &t) in a.iter_mut().zip(w) {
                *a += (e - t) * (e - t);
            }
        }
        group.copy_from_slice(&a);
        lag0 += LAG_GROUP;
    }
    let rest = lags.into_remainder();
    let mut a = [0f32; LAG_REST];
    a.copy_from_slice(rest);
    for &(at, e) in pending {
        let w = &window[at + lag0..at + lag0 + LAG_REST];
        for (a, &t) in a.iter_mut().zip(w) {
            *a += (e - t) * (e - t);
        }
    }
    rest.copy_from_slice(&a);
}

/// Lags [`add_lags`] keeps in registers at once: four AVX registers, four independent sums
/// in flight.
const LAG_GROUP: usize = 32;
/// The lags after the last whole [`LAG_GROUP`]: one AVX register.
const LAG_REST: usize = LAG_SLOTS % LAG_GROUP;

/// [`add_lags`] compiled for AVX: eight lags an instruction instead of SSE2's four. Each lag
/// gets the same IEEE subtraction, product and sum in the same order (Rust fuses no
/// multiply-add and reorders no float arithmetic), so the sums are bit for bit the same.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn add_lags_avx(acc: &mut [f32; LAG_SLOTS], window: &[f32], pending: &[(usize, f32)]) {
    add_lags(acc, window, pending)
}

/// Computes the metrics of a recorded run (through [`Online`], as a streamed run does).
pub fn compute(r: &SimResult) -> Metrics {
    let mut m = Online::new(
        &r.params,
        r.timer.clock_hz,
        r.sample_period_us,
        &r.region_settings,
    );
    m.edges(&r.waveform.edges);
    for p in &r.trace {
        m.point(p);
    }
    m.finish()
}

/// True when a pulse is one of `planned` (the (on-time, period) pairs of the settings, kernel
/// clocks): on-time and period both equal to one setting's. A pulse not followed by another rise
/// of the same run (Off, restart, end) is checked for on-time ≤ the setting's only, since Off
/// cuts it short by design.
fn pulse_matches(on: u64, period: Option<u64>, planned: &HashSet<(u64, u64)>) -> bool {
    if period.is_some_and(|p| planned.contains(&(on, p))) {
        return true;
    }
    planned.iter().any(|&(s_on, s_period)| match period {
        // A pulse cut by Off and restarted later: shorter on-time, longer gap.
        Some(p) => on <= s_on && p > s_period,
        None => on <= s_on,
    })
}

/// The switch between consecutive points, the first in region `from` and `b`, if their regions
/// differ (both present).
fn switch_between(
    from: Option<u8>,
    t_us: u64,
    state: &State,
    b: &CoreOut,
    boundaries_um: &[f64],
) -> Option<Switch> {
    let (Some(from), Some(to)) = (from, b.region) else {
        return None;
    };
    if from == to {
        return None;
    }
    let up = to > from;
    let bi = if up { to as usize - 1 } else { to as usize };
    let boundary_um = boundaries_um.get(bi).copied().unwrap_or(f64::NAN);
    let true_um = state.position_um;
    let past_um = if up {
        true_um - boundary_um
    } else {
        boundary_um - true_um
    };
    Some(Switch {
        t_us,
        from,
        to,
        boundary_um,
        true_um,
        meas_um: b.meas_um,
        past_um,
    })
}

/// Region switches: consecutive samples that both have a region and differ. A region regained
/// after a fault (no region in between) is not a switch, as in the controller's own count.
pub fn switches(r: &SimResult) -> Vec<Switch> {
    let boundaries: Vec<f64> = r
        .params
        .config
        .scene
        .boundaries_um
        .iter()
        .map(|&b| b as f64)
        .collect();
    r.trace
        .windows(2)
        .filter_map(|w| {
            let b = &w[1];
            switch_between(w[0].region, b.t_us, &b.state(), &b.core_out(), &boundaries)
        })
        .collect()
}

/// One burst of a grating against the ridge it renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RidgeHit {
    /// Rising edge, s.
    pub t_s: f64,
    /// True finger position at the rising edge minus the nearest ridge (a multiple of λ),
    /// signed along the motion (positive: the burst came after the ridge), µm.
    pub error_um: f64,
    /// On-time, s.
    pub on_s: f64,
    /// True speed at the rising edge, µm/s.
    pub speed_um_s: f64,
}

/// Where every burst of a run landed against a grating of period `wavelength_um` whose ridges
/// sit at the multiples of λ.
pub fn ridge_hits(r: &SimResult, wavelength_um: f64) -> Vec<RidgeHit> {
    let clock = r.waveform.clock_hz as f64;
    r.waveform
        .pulses()
        .iter()
        .map(|p| {
            let t_s = p.rise as f64 / clock;
            let st = r.params.trajectory.state(t_s);
            let (x, v) = (st.position_um, st.velocity_um_s);
            let off = x - (x / wavelength_um).round() * wavelength_um;
            RidgeHit {
                t_s,
                error_um: if v < 0.0 { -off } else { off },
                on_s: p.on() as f64 / clock,
                speed_um_s: v.abs(),
            }
        })
        .collect()
}

/// Ridges (multiples of `wavelength_um`) the true finger position crossed during the run,
/// counted on the trace's sampling grid.
pub fn ridges_crossed(r: &SimResult, wavelength_um: f64) -> u64 {
    let cells = r
        .trace
        .iter()
        .map(|t| (t.true_um / wavelength_um).floor() as i64);
    cells
        .clone()
        .zip(cells.skip(1))
        .map(|(a, b)| a.abs_diff(b))
        .sum()
}

#[cfg(test)]
mod expected_tests {
    use super::*;
    use saw_core::texture::{Grating, Material, RandomBurst};

    /// Hand-worked: 60 mm/s over a 1 mm grating is 60 Hz, either direction; fig. 5's finger
    /// (Δμ 0.3) at 40 mm/s is 28.811 Hz (worked in the core's controller tests); draws uniform
    /// on 40 Hz ± 30 % come at 40 · 0.6 / ln(13/7) = 24 / (2.564949 − 1.945910) = 38.770 Hz; a constant texture and a
    /// finger at rest have none.
    /// The batched lag sums, AVX and portable, are those of one estimate at a time, bit for
    /// bit, over sums grown from zero with estimates and true velocities that differ in sign,
    /// size and by nothing at all.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn batched_lag_sums_are_those_of_one_estimate_at_a_time() {
        if !std::arch::is_x86_feature_detected!("avx") {
            return;
        }
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            ((x >> 11) as f64 / (1u64 << 53) as f64 * 600.0 - 300.0) as f32
        };
        // One buffer of true velocities; batches of 1 … 16 estimates whose windows start at
        // overlapping places, as the metrics' sliding buffer gives them.
        let buf: Vec<f32> = (0..4 * LAG_SLOTS).map(|_| next()).collect();
        let (mut a, mut b, mut one) = ([0f32; LAG_SLOTS], [0f32; LAG_SLOTS], [0f32; LAG_SLOTS]);
        let mut at = 3 * LAG_SLOTS;
        for i in 0..2_000 {
            let batch: Vec<(usize, f32)> = (0..1 + i % LAG_BATCH)
                .map(|j| {
                    at = if at == 0 { 3 * LAG_SLOTS } else { at - 1 };
                    let e = if (i + j) % 7 == 0 {
                        buf[at + 3]
                    } else {
                        next()
                    };
                    (at, e)
                })
                .collect();
            add_lags(&mut a, &buf, &batch);
            // SAFETY: AVX was detected above.
            unsafe { add_lags_avx(&mut b, &buf, &batch) };
            // The reference: one estimate at a time, lag by lag.
            for &(at, e) in &batch {
                for (lag, sum) in one.iter_mut().enumerate() {
                    let t = buf[at + lag];
                    *sum += (e - t) * (e - t);
                }
            }
        }
        assert_eq!(a.map(f32::to_bits), one.map(f32::to_bits));
        assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits));
        assert!(a.iter().all(|s| *s > 0.0));
    }

    #[test]
    fn expected_rates_by_hand() {
        let g = Texture::Grating(Grating::new(1_000));
        assert_eq!(expected_hz(&g, 60_000.0), Some(60.0));
        assert_eq!(expected_hz(&g, -60_000.0), Some(60.0));
        assert_eq!(expected_hz(&g, 0.0), None);
        let m = Texture::Material(Material::fig5(0.3));
        let f = expected_hz(&m, 40_000.0).unwrap();
        assert!((f - 28.811).abs() < 0.01, "{f}");
        let r = Texture::Random(RandomBurst {
            center_millihz: 40_000,
            spread_permille: 300,
            amplitude_permille: 1000,
            amplitude_spread_permille: 0,
            duty_permille: 400,
            seed: 1,
        });
        let f = expected_hz(&r, 0.0).unwrap();
        assert!((f - 38.770).abs() < 0.001, "{f}");
        assert_eq!(expected_hz(&Texture::constant_hz(80), 60_000.0), None);
        assert_eq!(expected_hz(&Texture::Off, 60_000.0), None);
    }
}
