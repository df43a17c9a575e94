//! The 2D closed loop (issue #36): a finger path ([`crate::trajectory2d`]) on the 4-wire overlay
//! model ([`crate::touch`]), read frame by frame at the board's touch `Schedule`, through the
//! core's `TouchSensor` and `Controller2d` into host-sim's burst-timer model; and what came out:
//! window switches, edge pulses, lift-offs and faults, each placed with the TRUE finger and the
//! scene's geometry (computed here in f64 from the outlines, not by the controller), plus the
//! trace the 2D chart draws.
//!
//! Timing: frame k runs from k·F to (k+1)·F (F the schedule's frame, rounded up to the µs); the
//! model holds the finger where the path has it at the frame's start (it models whole frames
//! only, docs/touch.md), the reading is stamped and acted on at the frame's end. An event's
//! position is the true finger at that action time: what the finger feels, latency included.

use saw_boards::BoardDef;
use saw_core::burst::{BurstCommand, SafetyLimits};
use saw_core::gate::GateAction;
use saw_core::plane::{
    Config2d, Config2dError, Controller2d, OrientedGrating, PlaneTexture, PointUm as CorePoint,
    Polygon, Scene2d, SegmentUm, Telemetry2d, Window2d,
};
use saw_core::plane::{Place, TouchFault};
use saw_core::texture::{Grating, GratingRender, Texture};
use saw_core::touch::calibration::{Affine, CalPoint};
use saw_core::touch::fault::RailBands;
use saw_core::touch::frame::{Reading, TouchSensor};
use saw_core::touch::plates::{AdcTiming, Schedule};
use saw_core::touch::pressure::PressureConfig;
use serde::Serialize;

use crate::sim::burst_timer;
use crate::timer::{LevelPort, TimerModel};
use crate::touch::{Finger, Overlay, TouchModel};
use crate::trajectory2d::Trajectory2d;

/// The overlay's active area, mm: x = 0 at X−, 1 at X+ spans this width, y likewise the
/// height (the 4.3-inch panel docs/touch.md takes for its interlayer capacitance).
pub const SCREEN_MM: (f64, f64) = (95.0, 54.0);

/// A 2D run's parameters.
#[derive(Clone, Debug)]
pub struct Params2d {
    /// Board: burst timer, ADC conversion time (→ the touch schedule), RF level port.
    pub board: &'static BoardDef,
    /// The finger's path, µm.
    pub trajectory: Trajectory2d,
    /// Simulated time, s.
    pub duration_s: f64,
    /// The scene.
    pub config: Config2d,
    /// The plates, contact law and noise.
    pub overlay: Overlay,
    /// The overlay's touch area, µm: the scene's plate (`[screen] size_mm`), calibrated as
    /// `serve` calibrates its overlay; [`SCREEN_MM`] unless set.
    pub plate_um: (u32, u32),
    /// Noise seed.
    pub seed: u64,
    /// Press force while touching, N.
    pub force_n: f64,
    /// The finger lifts at this time, s, and stays off.
    pub lift_at_s: Option<f64>,
}

impl Params2d {
    /// `trajectory` on `board` over `config` for `duration_s`: default overlay (2 LSB), seed 1,
    /// 1 N, no lift.
    pub fn new(
        board: &'static BoardDef,
        trajectory: Trajectory2d,
        duration_s: f64,
        config: Config2d,
    ) -> Self {
        Self {
            board,
            trajectory,
            duration_s,
            config,
            overlay: Overlay::default(),
            plate_um: ((SCREEN_MM.0 * 1e3) as u32, (SCREEN_MM.1 * 1e3) as u32),
            seed: 1,
            force_n: 1.0,
            lift_at_s: None,
        }
    }
}

/// Why a 2D run cannot start.
#[derive(Debug)]
pub enum Sim2dError {
    /// The touch schedule refused the board's ADC timing or the plates.
    Schedule(String),
    /// The scene refused by the controller.
    Config(Config2dError),
    /// The calibration of the sensor on the model failed.
    Calibration(String),
    /// The duration is not a positive number of seconds the frame stamps (u32 µs) can hold.
    Duration(f64),
}

impl std::fmt::Display for Sim2dError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Sim2dError::Schedule(e) => write!(f, "touch schedule: {e}"),
            Sim2dError::Config(e) => write!(f, "2D scene refused: {e}"),
            Sim2dError::Calibration(e) => write!(f, "touch calibration on the model: {e}"),
            Sim2dError::Duration(d) => write!(
                f,
                "duration {d} s: must be above 0 and at most {MAX_DURATION_S} s"
            ),
        }
    }
}

impl std::error::Error for Sim2dError {}

/// Longest 2D run, s: frame stamps are u32 µs (4 295 s); a run keeps its trace in memory.
pub const MAX_DURATION_S: f64 = 600.0;

/// The board's touch acquisition as saw-boards states it (`saw_boards::touch::touch_adc`: its
/// ADC's conversion time, the conversions summed a position and a pressure phase, the ones
/// discarded after each switch), as the core's `AdcTiming`. The firmware's build script builds
/// the same from the same figures.
pub fn adc_timing(board: &BoardDef) -> AdcTiming {
    let t = saw_boards::touch::touch_adc(board);
    AdcTiming {
        conversion_ns: t.conversion_ns,
        conversions_position: t.conversions_position,
        conversions_pressure: t.conversions_pressure,
        discard: t.discard,
    }
}

/// The board's touch schedule on `overlay`'s plates.
pub fn schedule(board: &BoardDef, overlay: &Overlay) -> Result<Schedule, Sim2dError> {
    Schedule::new(&overlay.rc, &adc_timing(board)).map_err(|e| Sim2dError::Schedule(e.to_string()))
}

/// One frame, µs, rounded up (frames never come faster than the schedule allows).
pub fn frame_period_us(schedule: &Schedule) -> u32 {
    schedule.frame_ns().div_ceil(1_000).min(u32::MAX as u64) as u32
}

/// The frame period of `board` on the default plates, µs (what a 2D scene file is checked
/// against); None if the schedule refuses the board's timing.
pub fn board_frame_period_us(board: &BoardDef) -> Option<u32> {
    schedule(board, &Overlay::default())
        .ok()
        .map(|s| frame_period_us(&s))
}

/// A window switch: the finger left `from` for `to`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WindowSwitch {
    /// When the controller acted, s.
    pub t_s: f64,
    /// The true finger then, mm.
    pub x_mm: f64,
    /// The true finger then, mm.
    pub y_mm: f64,
    /// The window left (None: the background).
    pub from: Option<u8>,
    /// The window entered (None: the background).
    pub to: Option<u8>,
    /// The window whose outline was crossed: `to` when entered (above `from`, or from the
    /// background), else `from` (left).
    pub outline: u8,
    /// Signed distance of the true finger from that outline, mm (positive inside it).
    pub distance_mm: f64,
}

/// An edge pulse that fired.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EdgePulseEvent {
    /// When the controller fired it, s.
    pub t_s: f64,
    /// The true finger then, mm.
    pub x_mm: f64,
    /// The true finger then, mm.
    pub y_mm: f64,
    /// The edge's index (flagged outlines' sides in window and vertex order, then free edges).
    pub edge: u8,
    /// Signed distance of the true finger from the edge's line, mm: positive inside the window
    /// for an outline's side, on the left of a→b for a free edge.
    pub distance_mm: f64,
}

/// A rendering finger lifted.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LiftEvent {
    /// The reading that said `Lifted`, s.
    pub t_s: f64,
    /// When the finger left the plate, s (from the run's lift time; None: it left the plate's
    /// area).
    pub lifted_at_s: Option<f64>,
    /// The enable line was low from that reading on (checked on the timer model).
    pub line_low: bool,
}

/// A fault's onset.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaultEvent {
    /// When, s.
    pub t_s: f64,
    /// What, as the controller names it.
    pub fault: String,
}

/// One frame of the trace (what the chart draws).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TracePoint2d {
    /// The frame's end, s.
    pub t_s: f64,
    /// True finger at the frame's end, mm.
    pub x_mm: f64,
    /// True finger at the frame's end, mm.
    pub y_mm: f64,
    /// The finger is on the plate.
    pub touching: bool,
    /// The periodic burst running after this frame, Hz (None: off or a one-pulse).
    pub fb_hz: Option<f64>,
    /// A one-pulse that is not an edge's started on this frame (a ridge of a grating).
    pub ridge_pulse: bool,
}

/// What a 2D run produced.
#[derive(Clone, Debug)]
pub struct Run2d {
    /// The frame period, µs.
    pub frame_period_us: u32,
    /// Frames simulated.
    pub frames: u64,
    /// The overlay's touch area, mm (the scene's plate).
    pub plate_mm: (f64, f64),
    /// Frames whose path point was off the plate (not counting a lift): the finger was off
    /// the overlay there, and nothing rendered.
    pub off_plate_frames: u64,
    /// The first such frame's start, s.
    pub first_off_plate_s: Option<f64>,
    /// Frames the sensor read a finger on (landing or down): 0 when the finger never pressed
    /// the overlay (off the plate, or lighter than the touch-down threshold).
    pub pressed_frames: u64,
    /// Window switches, in time order.
    pub window_switches: Vec<WindowSwitch>,
    /// Edge pulses, in time order.
    pub edge_pulses: Vec<EdgePulseEvent>,
    /// Lift-offs.
    pub lifts: Vec<LiftEvent>,
    /// Fault onsets.
    pub faults: Vec<FaultEvent>,
    /// Every frame.
    pub trace: Vec<TracePoint2d>,
    /// The controller's counters at the end.
    pub telemetry: Telemetry2d,
    /// Gate actions with their time, s (for checks on the line).
    pub actions: Vec<(f64, GateAction)>,
    /// The enable line's level changes, s, true = high (from the timer model).
    pub line: Vec<(f64, bool)>,
}

impl Run2d {
    /// The enable line's level at `t_s` (the model's edges; low before the first).
    pub fn line_high_at(&self, t_s: f64) -> bool {
        self.line
            .iter()
            .take_while(|(t, _)| *t <= t_s)
            .last()
            .is_some_and(|(_, h)| *h)
    }
}

// ---------------------------------------------------------------------------------------------
// Geometry, in f64, from the scene's outlines and segments (independent of the core's f32 and
// i64 code, so the events check the controller rather than repeat it).

/// A point, mm.
type P = (f64, f64);

fn mm(p: CorePoint) -> P {
    (p.x_um as f64 / 1e3, p.y_um as f64 / 1e3)
}

/// Distance from `p` to the segment a–b.
pub fn segment_distance_mm(p: P, a: P, b: P) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p.0 - a.0 - t * dx).hypot(p.1 - a.1 - t * dy)
}

/// Even-odd ray casting.
fn inside(vertices: &[P], p: P) -> bool {
    let mut inside = false;
    let n = vertices.len();
    for i in 0..n {
        let (a, b) = (vertices[i], vertices[(i + 1) % n]);
        if (a.1 > p.1) != (b.1 > p.1) {
            let x = a.0 + (p.1 - a.1) * (b.0 - a.0) / (b.1 - a.1);
            if p.0 < x {
                inside = !inside;
            }
        }
    }
    inside
}

fn vertices_mm(poly: &Polygon) -> Vec<P> {
    poly.vertices.iter().map(|v| mm(*v)).collect()
}

/// Signed distance from `p` to the outline, mm: positive inside.
pub fn outline_distance_mm(poly: &Polygon, p: P) -> f64 {
    let v = vertices_mm(poly);
    let n = v.len();
    let d = (0..n)
        .map(|i| segment_distance_mm(p, v[i], v[(i + 1) % n]))
        .fold(f64::INFINITY, f64::min);
    if inside(&v, p) {
        d
    } else {
        -d
    }
}

/// One edge of a scene: its ends and the unit normal its signed distance is taken along.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeGeom {
    /// Start, mm.
    pub a: P,
    /// End, mm.
    pub b: P,
    /// Unit normal, pointing into the window for an outline's side, left of a→b for a free
    /// edge.
    pub n: P,
    /// The window whose outline it is (None: a free edge).
    pub window: Option<u8>,
}

impl EdgeGeom {
    /// Signed distance of `p` from the edge's line, mm.
    pub fn signed_distance_mm(&self, p: P) -> f64 {
        (p.0 - self.a.0) * self.n.0 + (p.1 - self.a.1) * self.n.1
    }
}

fn left_normal(a: P, b: P) -> P {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let l = dx.hypot(dy).max(f64::MIN_POSITIVE);
    (-dy / l, dx / l)
}

/// The scene's edges in the controller's index order: the sides of every window with `edge`
/// set, window by window, each from vertex i to i + 1; then the free segments.
pub fn scene_edges(scene: &Scene2d) -> Vec<EdgeGeom> {
    let mut out = Vec::new();
    for (w, win) in scene.windows.iter().enumerate() {
        if !win.edge {
            continue;
        }
        let v = vertices_mm(&win.outline);
        let n = v.len();
        // Shoelace: positive area is counter-clockwise, whose interior is on the left.
        let area2: f64 = (0..n)
            .map(|i| v[i].0 * v[(i + 1) % n].1 - v[(i + 1) % n].0 * v[i].1)
            .sum();
        for i in 0..n {
            let (a, b) = (v[i], v[(i + 1) % n]);
            let l = left_normal(a, b);
            let inward = if area2 >= 0.0 { l } else { (-l.0, -l.1) };
            out.push(EdgeGeom {
                a,
                b,
                n: inward,
                window: Some(w as u8),
            });
        }
    }
    for s in &scene.free_edges {
        let (a, b) = (mm(s.a), mm(s.b));
        out.push(EdgeGeom {
            a,
            b,
            n: left_normal(a, b),
            window: None,
        });
    }
    out
}

// ---------------------------------------------------------------------------------------------
// The demonstration scene.

fn rect(x0_mm: i32, y0_mm: i32, x1_mm: i32, y1_mm: i32) -> Option<Polygon> {
    Polygon::rectangle(
        CorePoint::new(x0_mm * 1_000, y0_mm * 1_000),
        CorePoint::new(x1_mm * 1_000, y1_mm * 1_000),
    )
    .ok()
}

/// The windows of [`demo_config`], for tests and the README: 0 coarse, 1 fine, 2 and 3 the
/// outlined buttons, 4 the oriented grating.
pub const DEMO_WINDOWS: [(&str, [i32; 4]); 5] = [
    ("coarse: constant 220 Hz", [4, 4, 22, 50]),
    ("fine: constant 90 Hz", [24, 4, 42, 50]),
    ("button, felt outline", [48, 8, 68, 24]),
    ("button, felt outline", [48, 30, 68, 46]),
    ("grating, ridges along y every 2 mm", [72, 4, 91, 50]),
];

/// The free edge of [`demo_config`], mm: between the two buttons, along x.
pub const DEMO_FREE_EDGE: [i32; 4] = [46, 27, 70, 27];

/// A fig. 12-like screen on the 95 × 54 mm overlay: two windows of different roughness (constant
/// bursts at 220 and 90 Hz), two off buttons whose outlines pulse when crossed, a window of
/// position-phase ridges along y (normal (1, 0), λ 2 mm), a free edge between the buttons, the
/// background off, the default band (200 µm), pulse (10 ms triangle) and re-arm (100 µm).
/// An edge crossed over a running burst stops it and pulses on the next reading (docs/plane.md).
pub fn demo_config() -> Config2d {
    let constant = |hz: u32| {
        PlaneTexture::Plain(Texture::Constant(BurstCommand {
            burst_millihz: hz * 1_000,
            duty_permille: 300,
        }))
    };
    let mut grating = Grating::new(2_000);
    grating.render = GratingRender::PositionPhase;
    grating.duty_permille = 300;
    let textures = [
        (constant(220), false),
        (constant(90), false),
        (PlaneTexture::Plain(Texture::Off), true),
        (PlaneTexture::Plain(Texture::Off), true),
        (
            PlaneTexture::Oriented(OrientedGrating {
                grating,
                normal: (1, 0),
            }),
            false,
        ),
    ];
    let mut c = Config2d {
        limits: SafetyLimits::default(),
        ..Config2d::default()
    };
    for ((_, [x0, y0, x1, y1]), (texture, edge)) in DEMO_WINDOWS.iter().zip(textures) {
        // Whole-mm rectangles inside the plane's ±1 m: always valid (a test loads the scene).
        if let Some(outline) = rect(*x0, *y0, *x1, *y1) {
            let _ = c.scene.windows.push(Window2d {
                outline,
                texture,
                edge,
            });
        }
    }
    let [ax, ay, bx, by] = DEMO_FREE_EDGE;
    let _ = c.scene.free_edges.push(SegmentUm {
        a: CorePoint::new(ax * 1_000, ay * 1_000),
        b: CorePoint::new(bx * 1_000, by * 1_000),
    });
    c
}

// ---------------------------------------------------------------------------------------------
// The loop.

/// A sensor calibrated on a noiseless copy of the overlay: three touches at (0.1, 0.1),
/// (0.9, 0.5), (0.5, 0.9) of the plate, targets at those fractions of [`SCREEN_MM`], as a
/// three-point calibration on a panel would be done. The virtual board (`serve`) uses it too.
pub(crate) fn calibrated_sensor(
    overlay: &Overlay,
    schedule: &Schedule,
    adc: &AdcTiming,
    plate_um: (u32, u32),
) -> Result<TouchSensor, Sim2dError> {
    let mut quiet = TouchModel::new(
        Overlay {
            noise_lsb: 0.0,
            ..*overlay
        },
        0,
    );
    let (w_um, h_um) = (plate_um.0 as f64, plate_um.1 as f64);
    let cal = [(0.1, 0.1), (0.9, 0.5), (0.5, 0.9)].map(|(x, y)| {
        let f = Finger { x, y, force_n: 1.0 };
        // The first frame after a touch-down settles the model's filters; the second is read.
        quiet.frame(schedule, adc, Some(&f), 0);
        let fr = quiet.frame(schedule, adc, Some(&f), 0);
        CalPoint {
            x_code: fr.x_code,
            y_code: fr.y_code,
            x_um: (x * w_um).round() as i32,
            y_um: (y * h_um).round() as i32,
        }
    });
    let map = Affine::from_points(cal, &RailBands::default())
        .map_err(|e| Sim2dError::Calibration(e.to_string()))?;
    TouchSensor::new(PressureConfig::DEFAULT, RailBands::default(), map)
        .map_err(|e| Sim2dError::Calibration(e.to_string()))
}

/// The burst frequency of periodic settings, Hz.
fn fb_hz(clock_hz: u32, s: &saw_core::burst::TimerSettings) -> f64 {
    clock_hz as f64 / s.period_clocks().max(1) as f64
}

/// Runs `params`: frames of the model through the sensor and the controller into the timer
/// model, with the events placed on the true finger.
pub fn run(params: &Params2d) -> Result<Run2d, Sim2dError> {
    if !(params.duration_s > 0.0 && params.duration_s <= MAX_DURATION_S) {
        return Err(Sim2dError::Duration(params.duration_s));
    }
    let board = params.board;
    let adc = adc_timing(board);
    let sched = schedule(board, &params.overlay)?;
    let frame_us = frame_period_us(&sched);
    let timer = burst_timer(board);
    let mut ctrl = Controller2d::new(timer, frame_us).map_err(Sim2dError::Config)?;
    ctrl.load(&params.config).map_err(Sim2dError::Config)?;
    let plate_um = params.plate_um;
    let plate_mm = (plate_um.0 as f64 / 1e3, plate_um.1 as f64 / 1e3);
    let mut sensor = calibrated_sensor(&params.overlay, &sched, &adc, plate_um)?;
    let mut model = TouchModel::new(params.overlay, params.seed);
    let mut tm = TimerModel::new(timer.clock_hz, timer.counter_bits, true).with_level(
        LevelPort::new(board.rf_level.table, board.rf_level.envelope_timer_clk_hz),
    );
    let clock = timer.clock_hz as u64;
    let clk = |t_us: u64| t_us * clock / 1_000_000;
    let edges = scene_edges(&params.config.scene);
    let windows = &params.config.scene.windows;
    let frames = (params.duration_s * 1e6 / frame_us as f64).ceil() as u64;
    let mut run = Run2d {
        frame_period_us: frame_us,
        frames,
        plate_mm,
        off_plate_frames: 0,
        first_off_plate_s: None,
        pressed_frames: 0,
        window_switches: Vec::new(),
        edge_pulses: Vec::new(),
        lifts: Vec::new(),
        faults: Vec::new(),
        trace: Vec::with_capacity(frames as usize),
        telemetry: Telemetry2d::default(),
        actions: Vec::new(),
        line: Vec::new(),
    };
    let mut last_place: Option<Place> = None;
    let mut periodic: Option<f64> = None;
    let mut fault: Option<TouchFault> = None;
    let mut was_rendering = false;
    for k in 0..frames {
        let (t0_us, t_us) = (k * frame_us as u64, (k + 1) * frame_us as u64);
        let t_s = t_us as f64 * 1e-6;
        let start = params.trajectory.state(t0_us as f64 * 1e-6);
        let (fx, fy) = (start.x_um / 1e3 / plate_mm.0, start.y_um / 1e3 / plate_mm.1);
        let lifted = params.lift_at_s.is_some_and(|l| t0_us as f64 * 1e-6 >= l);
        let on_plate = (0.0..=1.0).contains(&fx) && (0.0..=1.0).contains(&fy);
        if !on_plate && !lifted {
            run.off_plate_frames += 1;
            run.first_off_plate_s.get_or_insert(t0_us as f64 * 1e-6);
        }
        let finger = (!lifted && on_plate).then_some(Finger {
            x: fx,
            y: fy,
            force_n: params.force_n,
        });
        let frame = model.frame(&sched, &adc, finger.as_ref(), t_us as u32);
        let reading = sensor.on_frame(&frame);
        if reading != Reading::Lifted {
            run.pressed_frames += 1;
        }
        let out = ctrl.on_reading(t_us as u32, reading);
        // The port's order (`apply2d`): level and envelope, then the line.
        if let Some(e) = out.envelope {
            tm.set_envelope(e);
        }
        if let Some(a) = out.amplitude_permille {
            tm.set_amplitude(clk(t_us), a);
        }
        if let Some(a) = out.action {
            tm.apply(clk(t_us), a);
            run.actions.push((t_s, a));
            periodic = match a {
                GateAction::Start(s) | GateAction::Update(s) => Some(fb_hz(timer.clock_hz, &s)),
                GateAction::Off | GateAction::Pulse(_) => None,
            };
        }
        tm.advance_to(clk(t_us));
        let now = params.trajectory.state(t_s);
        let p = (now.x_um / 1e3, now.y_um / 1e3);
        if let Some(e) = out.edge {
            let distance_mm = edges
                .get(e as usize)
                .map_or(f64::NAN, |g| g.signed_distance_mm(p));
            run.edge_pulses.push(EdgePulseEvent {
                t_s,
                x_mm: p.0,
                y_mm: p.1,
                edge: e,
                distance_mm,
            });
        }
        match (last_place, out.place) {
            (Some(from), Some(to)) if from != to => {
                let idx = |pl: Place| match pl {
                    Place::Background => None,
                    Place::Window(i) => Some(i),
                };
                let (f, t) = (idx(from), idx(to));
                // Entered: a window above the one left (lower index), or any from the
                // background; else the one left was left.
                let outline = match (f, t) {
                    (None, Some(t)) => t,
                    (Some(f), Some(t)) if t < f => t,
                    (Some(f), _) => f,
                    (None, None) => 0,
                };
                let distance_mm = windows
                    .get(outline as usize)
                    .map_or(f64::NAN, |w| outline_distance_mm(&w.outline, p));
                run.window_switches.push(WindowSwitch {
                    t_s,
                    x_mm: p.0,
                    y_mm: p.1,
                    from: f,
                    to: t,
                    outline,
                    distance_mm,
                });
            }
            _ => {}
        }
        last_place = out.place;
        if reading == Reading::Lifted && was_rendering {
            run.lifts.push(LiftEvent {
                t_s,
                lifted_at_s: params.lift_at_s.filter(|l| *l <= t_s),
                line_low: !tm.is_high(),
            });
        }
        was_rendering = out.place.is_some();
        if out.fault.is_some() && out.fault != fault {
            if let Some(f) = out.fault {
                run.faults.push(FaultEvent {
                    t_s,
                    fault: format!("{f:?}"),
                });
            }
        }
        fault = out.fault;
        // The stale watchdog's tick half a frame later, as the 1D loop ticks.
        let tick_us = t_us + frame_us as u64 / 2;
        if let Some(a) = ctrl.on_tick(tick_us as u32) {
            tm.apply(clk(tick_us), a);
            run.actions.push((tick_us as f64 * 1e-6, a));
            periodic = None;
        }
        run.trace.push(TracePoint2d {
            t_s,
            x_mm: p.0,
            y_mm: p.1,
            touching: finger.is_some(),
            fb_hz: periodic.filter(|_| tm.is_running()),
            ridge_pulse: out.edge.is_none() && matches!(out.action, Some(GateAction::Pulse(_))),
        });
    }
    let end = clk(frames * frame_us as u64 + frame_us as u64);
    let wave = tm.finish(end);
    run.line = wave
        .edges
        .iter()
        .map(|e| (wave.clocks_to_s(e.t), e.high))
        .collect();
    run.telemetry = ctrl.telemetry();
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn poly(points: &[(i32, i32)]) -> Polygon {
        let pts: Vec<CorePoint> = points
            .iter()
            .map(|&(x, y)| CorePoint::new(x * 1_000, y * 1_000))
            .collect();
        Polygon::from_points(&pts).unwrap()
    }

    /// An L (concave; 0,0 – 20,0 – 20,10 – 10,10 – 10,20 – 0,20) given clockwise and
    /// counter-clockwise: the outline distance is positive inside and negative outside (to a
    /// side, or to a corner's vertex beyond it), with the values worked by hand, and every side's normal points inside (a point just inside
    /// each side's midpoint reads +0.5 mm from it) whichever way the outline runs.
    #[test]
    fn outline_distances_and_inward_normals_either_way_round() {
        let ccw = [(0, 0), (20, 0), (20, 10), (10, 10), (10, 20), (0, 20)];
        let mut cw = ccw;
        cw.reverse();
        for pts in [ccw, cw] {
            let p = poly(&pts);
            // Inside the foot, 3 mm from the bottom (nearest side).
            assert!((outline_distance_mm(&p, (15.0, 3.0)) - 3.0).abs() < 1e-12);
            // In the notch at (15, 15): 5 mm from the sides x = 10 and y = 10, outside.
            assert!((outline_distance_mm(&p, (15.0, 15.0)) + 5.0).abs() < 1e-12);
            // Beyond the convex corner (20, 10): √8 from it, outside.
            let d = outline_distance_mm(&p, (22.0, 12.0));
            assert!((d + 8f64.sqrt()).abs() < 1e-12, "{d}");
            let mut scene = Scene2d::default();
            let _ = scene.windows.push(Window2d {
                outline: p.clone(),
                texture: PlaneTexture::default(),
                edge: true,
            });
            let edges = scene_edges(&scene);
            assert_eq!(edges.len(), 6);
            for (i, e) in edges.iter().enumerate() {
                assert_eq!((e.a, e.b), (pts[i].map_f(), pts[(i + 1) % 6].map_f()));
                let mid = ((e.a.0 + e.b.0) / 2.0, (e.a.1 + e.b.1) / 2.0);
                let inside = (mid.0 + 0.5 * e.n.0, mid.1 + 0.5 * e.n.1);
                assert!(
                    (outline_distance_mm(&p, inside) - 0.5).abs() < 1e-9,
                    "side {i}"
                );
                assert!((e.signed_distance_mm(inside) - 0.5).abs() < 1e-12);
            }
        }
    }

    trait MapF {
        fn map_f(self) -> (f64, f64);
    }
    impl MapF for (i32, i32) {
        fn map_f(self) -> (f64, f64) {
            (self.0 as f64, self.1 as f64)
        }
    }
}
