//! Random 2D scenes, fingers and touch-sensor faults for `host-sim soak --plane`
//! ([`super::plane`]): windows of every outline the plane takes (rectangles, triangles, concave
//! L shapes and stars, either way round), every texture kind with gratings oriented along random
//! normals, window outlines and free segments that pulse when crossed, random bands, re-arm
//! distances, pulses and caps; fingers that stroke, circle, rest on edges, tremble across them,
//! jump, lift off and land; rail faults per axis, stale gaps, dropped frames and code spikes; and
//! 2D scenes broken on purpose, which a load must refuse.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use saw_core::burst::{BurstCommand, SafetyLimits};
use saw_core::gate::DriveMode;
use saw_core::plane::{
    Config2d, OrientedGrating, PlaneTexture, PointUm, Polygon, SegmentUm, Window2d, MAX_WINDOWS,
};
use saw_core::texture::{Envelope, GratingRender, Texture};

use super::gen::{log_uniform, random_texture};

/// The overlay the soak's finger moves on, µm (host-sim's 95 × 54 mm, `sim2d::SCREEN_MM`).
pub const SCREEN_UM: (i32, i32) = (95_000, 54_000);

fn point(rng: &mut ChaCha8Rng) -> PointUm {
    PointUm::new(
        rng.random_range(0..=SCREEN_UM.0),
        rng.random_range(0..=SCREEN_UM.1),
    )
}

/// A simple outline: a rectangle, a triangle, a concave L, or a star (3–12 vertices at sorted
/// angles round a centre, radii drawn apart: concave as often as not); half of them clockwise.
/// About the screen, a few reaching past its sides.
pub fn random_polygon(rng: &mut ChaCha8Rng) -> Polygon {
    let c = point(rng);
    let w = rng.random_range(2_000..40_000);
    let h = rng.random_range(2_000..30_000);
    let mut v: Vec<PointUm> = match rng.random_range(0..4) {
        0 => vec![
            PointUm::new(c.x_um, c.y_um),
            PointUm::new(c.x_um + w, c.y_um),
            PointUm::new(c.x_um + w, c.y_um + h),
            PointUm::new(c.x_um, c.y_um + h),
        ],
        1 => vec![
            c,
            PointUm::new(c.x_um + w, c.y_um + rng.random_range(-h..h)),
            PointUm::new(c.x_um + rng.random_range(-w..w), c.y_um + h),
        ],
        2 => {
            // An L: the rectangle less a corner notch.
            let (nw, nh) = (rng.random_range(1..w), rng.random_range(1..h));
            vec![
                PointUm::new(c.x_um, c.y_um),
                PointUm::new(c.x_um + w, c.y_um),
                PointUm::new(c.x_um + w, c.y_um + nh),
                PointUm::new(c.x_um + nw, c.y_um + nh),
                PointUm::new(c.x_um + nw, c.y_um + h),
                PointUm::new(c.x_um, c.y_um + h),
            ]
        }
        _ => {
            let n = rng.random_range(3..=12);
            let mut angles: Vec<f64> = (0..n)
                .map(|_| rng.random_range(0.0..std::f64::consts::TAU))
                .collect();
            angles.sort_by(f64::total_cmp);
            angles
                .iter()
                .map(|a| {
                    let r = rng.random_range(0.2..1.0);
                    PointUm::new(
                        c.x_um + (a.cos() * r * w as f64) as i32,
                        c.y_um + (a.sin() * r * h as f64) as i32,
                    )
                })
                .collect()
        }
    };
    if rng.random_bool(0.5) {
        v.reverse();
    }
    // A degenerate draw (two angles alike, a collinear triangle) falls back to a rectangle.
    Polygon::from_points(&v).unwrap_or_else(|_| {
        Polygon::rectangle(c, PointUm::new(c.x_um + w, c.y_um + h))
            .unwrap_or_else(|_| unreachable_rectangle())
    })
}

/// A rectangle no check refuses (the fallback's fallback: w, h ≥ 2 mm inside ±1 m).
fn unreachable_rectangle() -> Polygon {
    Polygon {
        vertices: [
            PointUm::new(0, 0),
            PointUm::new(10_000, 0),
            PointUm::new(10_000, 10_000),
        ]
        .into_iter()
        .collect(),
    }
}

/// A window's texture: the 1D soak's kinds ([`random_texture`]), a grating rendered by position
/// or hybrid oriented along a random normal (the plane's form of it), a velocity-synthesis
/// grating plain or oriented.
pub fn random_plane_texture(rng: &mut ChaCha8Rng, max_hz: u32, cap: u16) -> PlaneTexture {
    match random_texture(rng, max_hz, cap) {
        Texture::Grating(g)
            if g.render != GratingRender::VelocitySynthesis || rng.random_bool(0.5) =>
        {
            let normal = loop {
                let n = match rng.random_range(0..3) {
                    // Along an axis, either way.
                    0 => [(1, 0), (0, 1), (-1, 0), (0, -1)][rng.random_range(0..4)],
                    1 => (
                        rng.random_range(-1000..=1000),
                        rng.random_range(-1000..=1000),
                    ),
                    _ => (
                        rng.random_range(-1_000_000..=1_000_000),
                        rng.random_range(-1_000_000..=1_000_000),
                    ),
                };
                if n != (0, 0) {
                    break n;
                }
            };
            PlaneTexture::Oriented(OrientedGrating { grating: g, normal })
        }
        t => PlaneTexture::Plain(t),
    }
}

/// A 2D scene: 0–8 windows of any outline and texture, half of them with felt outlines, 0–6
/// free edges, a background texture, random band (0–3 mm), re-arm (20 µm–3 mm), edge pulse
/// (50 µs up to the on-time cap, either envelope), caps, stale limit and drive. Some are
/// refused at load (too many edges, a duty above its cap, a pulse the board cannot time):
/// callers count those as refusals.
pub fn random_config2d(rng: &mut ChaCha8Rng, max_hz: u32) -> Config2d {
    let limits = SafetyLimits {
        max_duty_permille: if rng.random_bool(0.2) {
            rng.random_range(1..=1000)
        } else {
            rng.random_range(50..=600)
        },
        max_on_time_us: log_uniform(rng, 20.0, 100_000.0) as u32,
        max_level_permille: 1000,
    };
    let mut c = Config2d {
        limits,
        stale_after_us: rng.random_range(1_000..=10_000),
        ..Config2d::default()
    };
    let cap = limits.max_duty_permille;
    let bare = if rng.random_bool(0.5) { 0.0 } else { 0.4 };
    for _ in 0..rng.random_range(0..=MAX_WINDOWS) {
        let texture = if rng.random_bool(bare) {
            PlaneTexture::Plain(Texture::Off)
        } else {
            random_plane_texture(rng, max_hz, cap)
        };
        let _ = c.scene.windows.push(Window2d {
            outline: random_polygon(rng),
            texture,
            edge: rng.random_bool(0.5),
        });
    }
    c.scene.background = if rng.random_bool(0.5) {
        PlaneTexture::Plain(Texture::Off)
    } else {
        random_plane_texture(rng, max_hz, cap)
    };
    for _ in 0..rng.random_range(0..=6) {
        let a = point(rng);
        let b = if rng.random_bool(0.5) {
            point(rng)
        } else {
            // A short one.
            PointUm::new(
                a.x_um + rng.random_range(-5_000..=5_000),
                a.y_um + rng.random_range(-5_000..=5_000),
            )
        };
        if a != b {
            let _ = c.scene.free_edges.push(SegmentUm { a, b });
        }
    }
    c.scene.band_um = rng.random_range(0..=3_000);
    c.scene.rearm_um = log_uniform(rng, 20.0, 3_000.0) as u32;
    c.scene.edge_pulse.pulse_us = log_uniform(rng, 50.0, limits.max_on_time_us.max(50) as f64)
        .min(limits.max_on_time_us as f64) as u32;
    c.scene.edge_pulse.envelope = if rng.random_bool(0.5) {
        Envelope::Triangular
    } else {
        Envelope::Rectangular
    };
    c.scene.edge_pulse.amplitude_permille = rng.random_range(1..=1000);
    c.scene.drive = if rng.random_bool(0.5) {
        DriveMode::Standing
    } else {
        DriveMode::Progressive
    };
    c
}

/// Ways a 2D scene is broken on purpose, each refused by the core's load.
pub const BROKEN_2D: [&str; 7] = [
    "duty above the cap",
    "a self-crossing outline",
    "a position grating without a normal",
    "stale limit below two frames",
    "a zero-length free edge",
    "re-arm distance of 0",
    "duty cap of 0",
];

/// `cfg` broken in one of the [`BROKEN_2D`] ways (its index returned).
pub fn broken_config2d(rng: &mut ChaCha8Rng, cfg: &Config2d) -> (usize, Config2d) {
    let mut bad = cfg.clone();
    let how = rng.random_range(0..BROKEN_2D.len());
    match how {
        0 => {
            let cap = bad.limits.max_duty_permille;
            let over = rng.random_range(cap.saturating_add(1).min(1000)..=1000);
            if cap >= 1000 {
                bad.limits.max_duty_permille = 1001;
            }
            bad.scene.background = PlaneTexture::Plain(Texture::Constant(BurstCommand {
                burst_millihz: 20_000,
                duty_permille: over.max(1),
            }));
        }
        1 => {
            // A bow tie: its second and third corners swapped.
            let outline = Polygon {
                vertices: [
                    PointUm::new(0, 0),
                    PointUm::new(10_000, 10_000),
                    PointUm::new(10_000, 0),
                    PointUm::new(0, 10_000),
                ]
                .into_iter()
                .collect(),
            };
            let w = Window2d {
                outline,
                texture: PlaneTexture::Plain(Texture::Off),
                edge: false,
            };
            if bad.scene.windows.is_full() {
                bad.scene.windows[0] = w;
            } else {
                let _ = bad.scene.windows.push(w);
            }
        }
        2 => {
            let mut g = saw_core::texture::Grating::new(2_000);
            g.render = GratingRender::PositionPhase;
            g.duty_permille = 1;
            bad.scene.background = PlaneTexture::Plain(Texture::Grating(g));
        }
        3 => bad.stale_after_us = rng.random_range(0..200),
        4 => {
            let a = point(rng);
            if bad.scene.free_edges.is_full() || bad.scene.free_edges.is_empty() {
                bad.scene.free_edges.clear();
            }
            let _ = bad.scene.free_edges.push(SegmentUm { a, b: a });
        }
        5 => {
            bad.scene.rearm_um = 0;
            // Re-arm is the edges' only: make sure there is one.
            let _ = bad.scene.free_edges.push(SegmentUm {
                a: PointUm::new(1_000, 1_000),
                b: PointUm::new(9_000, 1_000),
            });
        }
        _ => bad.limits.max_duty_permille = 0,
    }
    (how, bad)
}

/// The running scene with one window moved by up to ±10 mm (None without windows).
pub fn moved_window(rng: &mut ChaCha8Rng, cfg: &Config2d) -> Option<Config2d> {
    if cfg.scene.windows.is_empty() {
        return None;
    }
    let mut c = cfg.clone();
    let i = rng.random_range(0..c.scene.windows.len());
    let (dx, dy) = (
        rng.random_range(-10_000..=10_000),
        rng.random_range(-10_000..=10_000),
    );
    for v in c.scene.windows[i].outline.vertices.iter_mut() {
        *v = PointUm::new(v.x_um + dx, v.y_um + dy);
    }
    Some(c)
}

/// An edge's ends, µm.
pub type EdgeUm = ((f64, f64), (f64, f64));

/// What the finger does over one piece of an episode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Move {
    /// Lifted off the plate.
    Lifted,
    /// At rest at a point, µm.
    Rest(f64, f64),
    /// A straight stroke from a to b at a speed, µm/s, then at rest at b.
    Stroke {
        /// Start, µm.
        a: (f64, f64),
        /// End, µm.
        b: (f64, f64),
        /// µm/s.
        speed: f64,
    },
    /// Round a circle, counter-clockwise from its phase.
    Circle {
        /// Centre, µm.
        c: (f64, f64),
        /// µm.
        r: f64,
        /// rad/s.
        omega: f64,
        /// rad.
        phase: f64,
    },
    /// Trembling along a direction about a point (across an edge when drawn on one).
    Tremor {
        /// Centre, µm.
        at: (f64, f64),
        /// Unit direction.
        dir: (f64, f64),
        /// Amplitude, µm.
        amp: f64,
        /// rad/s.
        omega: f64,
    },
}

/// One piece: a move from `start_s` for `len_s`, pressing with a contact of `r_touch_ohm`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Piece {
    /// Start, s from the episode's start.
    pub start_s: f64,
    /// Length, s.
    pub len_s: f64,
    /// What the finger does.
    pub mv: Move,
    /// The contact's resistance while pressing, Ω (100–1300: firmly below the 1.5 kΩ
    /// touch-down threshold, whatever the noise).
    pub r_touch_ohm: f64,
}

impl Piece {
    /// Where the finger is `t_s` into the episode (inside this piece); None while lifted.
    pub fn at(&self, t_s: f64) -> Option<(f64, f64)> {
        let dt = (t_s - self.start_s).max(0.0);
        match self.mv {
            Move::Lifted => None,
            Move::Rest(x, y) => Some((x, y)),
            Move::Stroke { a, b, speed } => {
                let len = (b.0 - a.0).hypot(b.1 - a.1);
                let f = if len > 0.0 {
                    (dt * speed / len).min(1.0)
                } else {
                    1.0
                };
                Some((a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1)))
            }
            Move::Circle { c, r, omega, phase } => {
                let th = phase + omega * dt;
                Some((c.0 + r * th.cos(), c.1 + r * th.sin()))
            }
            Move::Tremor {
                at,
                dir,
                amp,
                omega,
            } => {
                let s = amp * (omega * dt).sin();
                Some((at.0 + s * dir.0, at.1 + s * dir.1))
            }
        }
    }
}

/// Piece kinds, in the order the summary counts them.
pub const MOVES: [&str; 8] = [
    "rest",
    "rest on an edge",
    "stroke",
    "stroke across an edge",
    "circle",
    "tremor across an edge",
    "lift-off",
    "jump",
];

/// The finger over `duration_s`: pieces of 20–400 ms (lifts 1–300 ms), each from where the last
/// left the finger, or (a jump, one in eight) from anywhere; `edges` are the scene's edges
/// (µm), for the pieces that rest on, stroke across or tremble across one. Returns the pieces
/// and how many of each [`MOVES`] kind.
pub fn soak_finger(
    rng: &mut ChaCha8Rng,
    duration_s: f64,
    edges: &[EdgeUm],
) -> (Vec<Piece>, [u64; MOVES.len()]) {
    let mut pieces = Vec::new();
    let mut counts = [0; MOVES.len()];
    let rand_pt = |rng: &mut ChaCha8Rng| {
        (
            rng.random_range(0.0..SCREEN_UM.0 as f64),
            rng.random_range(0.0..SCREEN_UM.1 as f64),
        )
    };
    let mut t = 0.0;
    let mut here = rand_pt(rng);
    // Most episodes start lifted: the first touch lands.
    if rng.random_bool(0.7) {
        let len_s = log_uniform(rng, 0.001, 0.05);
        pieces.push(Piece {
            start_s: 0.0,
            len_s,
            mv: Move::Lifted,
            r_touch_ohm: 0.0,
        });
        t = len_s;
    }
    while t < duration_s {
        let r_touch_ohm = rng.random_range(100.0..1_300.0);
        if rng.random_bool(0.125) {
            here = rand_pt(rng);
            counts[7] += 1;
        }
        let mut len_s = log_uniform(rng, 0.02, 0.4);
        // A point on a random edge and that edge's unit normal.
        let on_edge = |rng: &mut ChaCha8Rng| {
            if edges.is_empty() {
                return None;
            }
            let (a, b) = edges[rng.random_range(0..edges.len())];
            let f = rng.random_range(-0.05..1.05);
            let p = (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1));
            let l = (b.0 - a.0).hypot(b.1 - a.1).max(1e-9);
            Some((p, (-(b.1 - a.1) / l, (b.0 - a.0) / l)))
        };
        let kind = rng.random_range(0..7);
        let mv = match kind {
            0 => Move::Rest(here.0, here.1),
            1 => match on_edge(rng) {
                Some((p, n)) => {
                    // On it, or a few µm either side (noise then crosses it all the time).
                    let off = rng.random_range(-30.0..30.0);
                    Move::Rest(p.0 + off * n.0, p.1 + off * n.1)
                }
                None => Move::Rest(here.0, here.1),
            },
            2 | 3 => {
                let b = match (kind, on_edge(rng)) {
                    (3, Some((p, n))) => {
                        let d = rng.random_range(500.0..5_000.0);
                        let a = (p.0 - d * n.0, p.1 - d * n.1);
                        here = a;
                        (p.0 + d * n.0, p.1 + d * n.1)
                    }
                    _ => rand_pt(rng),
                };
                let speed = if rng.random_bool(0.25) {
                    2_000_000.0
                } else {
                    log_uniform(rng, 20_000.0, 2_000_000.0)
                };
                Move::Stroke { a: here, b, speed }
            }
            4 => {
                let r = log_uniform(rng, 1_000.0, 20_000.0);
                let speed = log_uniform(rng, 20_000.0, 1_000_000.0);
                let phase = rng.random_range(0.0..std::f64::consts::TAU);
                let dir = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                Move::Circle {
                    c: (here.0 - r * phase.cos(), here.1 - r * phase.sin()),
                    r,
                    omega: dir * speed / r,
                    phase,
                }
            }
            5 => {
                let (at, dir) = on_edge(rng).unwrap_or((here, (1.0, 0.0)));
                Move::Tremor {
                    at,
                    dir,
                    amp: log_uniform(rng, 20.0, 500.0),
                    omega: std::f64::consts::TAU * rng.random_range(6.0..12.0),
                }
            }
            _ => {
                len_s = log_uniform(rng, 0.001, 0.3);
                Move::Lifted
            }
        };
        counts[if kind == 3 && edges.is_empty() {
            2
        } else {
            kind
        }] += 1;
        let p = Piece {
            start_s: t,
            len_s,
            mv,
            r_touch_ohm,
        };
        if let Some(end) = p.at(t + len_s) {
            here = end;
        }
        pieces.push(p);
        t += len_s;
    }
    (pieces, counts)
}

/// Touch faults the plane soak injects, in the order its counters list them.
pub const FAULTS_2D: [&str; 7] = [
    "rail-x",
    "rail-y",
    "rail-both",
    "stale",
    "dropped",
    "spike",
    "spike-train",
];

/// One injected touch fault over frames `[start, end)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TouchFaultWindow {
    /// Its kind: an index into [`FAULTS_2D`].
    pub tag: usize,
    /// First frame.
    pub start: u64,
    /// One past the last frame.
    pub end: u64,
    /// Rails: which end (false low, true high). Spikes: the X and Y offsets, codes.
    pub high: bool,
    /// Spike offsets, codes (16-conversion sums).
    pub offset: (i32, i32),
}

/// 0–4 fault windows over `frames` frames of `frame_us`: a rail on X, on Y or on both (an open
/// or shorted terminal, one frame to 40 ms), a stale gap (no frame for longer than the longest
/// stale limit, 10 ms), 1–3 dropped frames, a one-frame spike of ±50–3000 LSB a conversion on
/// either axis (clamped to the codes' range, a big one reaches a rail), a train of 2–10 spikes.
pub fn soak_faults2d(rng: &mut ChaCha8Rng, frames: u64, frame_us: u64) -> Vec<TouchFaultWindow> {
    let mut out = Vec::new();
    let in_frames = |us: f64| ((us / frame_us as f64).ceil() as u64).max(1);
    for _ in 0..rng.random_range(0..=4) {
        let tag = rng.random_range(0..FAULTS_2D.len());
        let start = rng.random_range(0..frames);
        let len = match tag {
            0..=2 => in_frames(log_uniform(rng, frame_us as f64, 40_000.0)),
            3 => in_frames(10_000.0 + log_uniform(rng, frame_us as f64, 50_000.0)),
            4 => rng.random_range(1..=3),
            _ => 1,
        };
        let spike = |rng: &mut ChaCha8Rng| {
            let one = |rng: &mut ChaCha8Rng| {
                let s = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                (s * log_uniform(rng, 50.0, 3_000.0) * 16.0) as i32
            };
            match rng.random_range(0..3) {
                0 => (one(rng), 0),
                1 => (0, one(rng)),
                _ => (one(rng), one(rng)),
            }
        };
        let high = rng.random_bool(0.5);
        if tag == 6 {
            let every = rng.random_range(2..=20);
            for i in 0..rng.random_range(2..=10u64) {
                let s = start + i * every;
                out.push(TouchFaultWindow {
                    tag,
                    start: s,
                    end: s + 1,
                    high,
                    offset: spike(rng),
                });
            }
        } else {
            let offset = if tag == 5 { spike(rng) } else { (0, 0) };
            out.push(TouchFaultWindow {
                tag,
                start,
                end: start + len,
                high,
                offset,
            });
        }
    }
    out
}
