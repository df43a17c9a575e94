//! The 2D golden vectors (issue #36), shared by the host generator (`host-sim/src/bin/golden.rs`
//! includes this file with `#[path]`) and the emulator image. no_std, no allocation.
//!
//! The scene is built here, by the same source on both sides, rather than encoded field by
//! field: the 8-window, 16-edge layout of `plane::work` (core/src/plane/mod.rs) with mixed
//! textures. That both sides built the same one is checked: each hashes the scene's `Debug` text
//! ([`config_crc`]) and the image compares its hash with the host's (in `golden2d.bin`).
//!
//! `golden2d.bin` (little-endian):
//!
//! ```text
//! magic "SAW2" u32 version
//! timer: clock_hz u32, counter_bits u8, max_burst_hz u32; sample_period_us u32
//! config_crc u32 (CRC-32 of the Config2d's Debug text)
//! calibration: 3 × (x_code u16, y_code u16, x_um i32, y_um i32)
//! n_vectors u8, per vector: name, n u32,
//!     inputs n × (frame: x u16, y u16, z1 u16, z2 u16, t_us u32; reading: see encode_reading),
//!     out_len u32, outputs (records, see encode_output2d), crc32 of the outputs u32
//! ```
//!
//! The readings are what the host's `TouchSensor` made of the frames: the image replays them
//! into `Controller2d::on_reading` alone, and the frames through its own `TouchSensor` and the
//! controller; both must give the host's output records.

use core::fmt::Write as _;

use super::format::{Reader, Record, Sink};

use saw_core::burst::TimerSettings;
use saw_core::gate::{DriveMode, Envelope, GateAction};
use saw_core::plane::{
    Config2d, EdgePulse, OrientedGrating, Output2d, Place, PlaneTexture, PointUm, Polygon,
    SegmentUm, TouchFault, VelocityUmS, Window2d,
};
use saw_core::position::SensorFault;
use saw_core::texture::{Grating, GratingRender, Material, RandomBurst, Texture};
use saw_core::touch::calibration::{Affine, CalPoint};
use saw_core::touch::fault::{Axis, AxisFault, RailBands};
use saw_core::touch::frame::{Frame, Reading, TouchSensor};
use saw_core::touch::pressure::PressureConfig;

/// File magic.
pub const MAGIC: &[u8; 4] = b"SAW2";
/// Format version.
pub const VERSION: u32 = 1;
/// Longest encoded output record.
pub const MAX_RECORD: usize = 48;

fn pt(x: i32, y: i32) -> PointUm {
    PointUm::new(x, y)
}

/// The outline of window `k` of the 4 × 2 grid: 12 × 15 mm, 14.5 mm apart in x, 18 mm in y,
/// windows 1 and 6 L-shaped (concave), as `plane::work`.
fn outline(k: i32) -> Polygon {
    let (x0, y0) = (2_000 + (k % 4) * 14_500, 3_000 + (k / 4) * 18_000);
    let p = if k == 1 || k == 6 {
        Polygon::from_points(&[
            pt(x0, y0),
            pt(x0 + 12_000, y0),
            pt(x0 + 12_000, y0 + 7_000),
            pt(x0 + 6_000, y0 + 7_000),
            pt(x0 + 6_000, y0 + 15_000),
            pt(x0, y0 + 15_000),
        ])
    } else {
        Polygon::rectangle(pt(x0, y0), pt(x0 + 12_000, y0 + 15_000))
    };
    p.unwrap_or_else(|_| unreachable!("the grid's outlines are valid"))
}

/// The windows' textures, window 0 first: off under both flagged outlines, then every kind a
/// window may hold (an edge crossed over a running burst stops it and pulses on the next
/// reading, docs/plane.md).
fn texture(k: i32) -> PlaneTexture {
    let oriented = |normal, render| {
        PlaneTexture::Oriented(OrientedGrating {
            grating: Grating {
                render,
                ..Grating::new(1_000)
            },
            normal,
        })
    };
    match k {
        0 | 5 => PlaneTexture::Plain(Texture::Off),
        1 => PlaneTexture::Plain(Texture::constant_hz(80)),
        2 => oriented((1, 1), GratingRender::PositionPhase),
        3 => PlaneTexture::Plain(Texture::Material(Material::fig5(0.3))),
        4 => PlaneTexture::Plain(Texture::Random(RandomBurst {
            center_millihz: 40_000,
            spread_permille: 300,
            amplitude_permille: 800,
            amplitude_spread_permille: 200,
            duty_permille: 400,
            seed: 1,
        })),
        6 => oriented((1, 0), GratingRender::PositionPhase),
        _ => PlaneTexture::Plain(Texture::Grating(Grating {
            render: GratingRender::VelocitySynthesis,
            ..Grating::new(2_000)
        })),
    }
}

/// The 2D scene: 8 windows over an off background (windows 0 and 5 flagged: their 8 sides are
/// edges) and 8 free diagonal segments: 16 edges. Default caps, band, pulse (10 ms triangles)
/// and re-arm.
pub fn config() -> Config2d {
    let mut c = Config2d::default();
    for k in 0..8 {
        let w = Window2d {
            outline: outline(k),
            texture: texture(k),
            edge: k == 0 || k == 5,
        };
        let _ = c.scene.windows.push(w);
    }
    for k in 0..8 {
        let x = 4_000 + k * 7_000;
        let _ = c.scene.free_edges.push(SegmentUm {
            a: pt(x, 10_000),
            b: pt(x + 3_000, 30_000),
        });
    }
    c.scene.edge_pulse = EdgePulse::default();
    c
}

/// The touch sensor of the vectors: default pressure thresholds and rail bands, the three-point
/// calibration the host took on its overlay model.
pub fn sensor(cal: [CalPoint; 3]) -> Option<TouchSensor> {
    let rails = RailBands::default();
    let map = Affine::from_points(cal, &rails).ok()?;
    TouchSensor::new(PressureConfig::DEFAULT, rails, map).ok()
}

/// CRC-32 of a value's `Debug` text, without allocating.
pub fn config_crc(c: &Config2d) -> u32 {
    struct Crc(u32);
    impl core::fmt::Write for Crc {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            self.0 = super::format::crc32_update(self.0, s.as_bytes());
            Ok(())
        }
    }
    let mut w = Crc(0);
    let _ = write!(w, "{c:?}");
    w.0
}

/// One 2D output record's buffer.
pub type Rec = Record<MAX_RECORD>;

/// Encodes a calibration pair.
pub fn encode_cal<O: Sink>(o: &mut O, c: &CalPoint) {
    o.u16(c.x_code);
    o.u16(c.y_code);
    o.u32(c.x_um as u32);
    o.u32(c.y_um as u32);
}

/// Decodes [`encode_cal`].
pub fn decode_cal(r: &mut Reader) -> CalPoint {
    CalPoint {
        x_code: r.u16(),
        y_code: r.u16(),
        x_um: r.i32(),
        y_um: r.i32(),
    }
}

/// Encodes a frame.
pub fn encode_frame<O: Sink>(o: &mut O, f: &Frame) {
    o.u16(f.x_code);
    o.u16(f.y_code);
    o.u16(f.z1_code);
    o.u16(f.z2_code);
    o.u32(f.t_us);
}

/// Decodes [`encode_frame`].
pub fn decode_frame(r: &mut Reader) -> Frame {
    Frame {
        x_code: r.u16(),
        y_code: r.u16(),
        z1_code: r.u16(),
        z2_code: r.u16(),
        t_us: r.u32(),
    }
}

fn encode_axis_fault<O: Sink>(o: &mut O, f: &AxisFault) {
    let axis = match f.axis {
        Axis::X => 0,
        Axis::Y => 1,
    };
    let rail = match f.fault {
        SensorFault::RailLow => 0,
        SensorFault::RailHigh => 1,
        _ => 2,
    };
    o.u8(axis << 4 | rail);
}

fn decode_axis_fault(r: &mut Reader) -> AxisFault {
    let b = r.u8();
    AxisFault {
        axis: if b >> 4 == 0 { Axis::X } else { Axis::Y },
        fault: match b & 15 {
            0 => SensorFault::RailLow,
            1 => SensorFault::RailHigh,
            _ => SensorFault::Stale,
        },
    }
}

/// Encodes a reading: a tag, then its fields.
pub fn encode_reading<O: Sink>(o: &mut O, r: &Reading) {
    match *r {
        Reading::Lifted => o.u8(0),
        Reading::Landing { x_um, y_um } => {
            o.u8(1);
            o.u32(x_um as u32);
            o.u32(y_um as u32);
        }
        Reading::Down {
            x_um,
            y_um,
            r_touch_ohm,
        } => {
            o.u8(2);
            o.u32(x_um as u32);
            o.u32(y_um as u32);
            o.u32(r_touch_ohm);
        }
        Reading::Fault(f) => {
            o.u8(3);
            encode_axis_fault(o, &f);
        }
    }
}

/// Decodes [`encode_reading`].
pub fn decode_reading(r: &mut Reader) -> Reading {
    match r.u8() {
        0 => Reading::Lifted,
        1 => Reading::Landing {
            x_um: r.i32(),
            y_um: r.i32(),
        },
        2 => Reading::Down {
            x_um: r.i32(),
            y_um: r.i32(),
            r_touch_ohm: r.u32(),
        },
        _ => Reading::Fault(decode_axis_fault(r)),
    }
}

const F_POS: u16 = 1;
const F_VEL: u16 = 2;
const F_PLACE: u16 = 4;
const F_ACTION: u16 = 8;
const F_AMP: u16 = 16;
const F_ENV: u16 = 32;
const F_DRIVE: u16 = 64;
const F_EDGE: u16 = 128;
const F_FAULT: u16 = 256;

/// Encodes every field of one output: a flag word, then the fields present.
pub fn encode_output2d<O: Sink>(o: &mut O, out: &Output2d) {
    let flags = (out.position.is_some() as u16 * F_POS)
        | (out.velocity.is_some() as u16 * F_VEL)
        | (out.place.is_some() as u16 * F_PLACE)
        | (out.action.is_some() as u16 * F_ACTION)
        | (out.amplitude_permille.is_some() as u16 * F_AMP)
        | (out.envelope.is_some() as u16 * F_ENV)
        | (out.drive.is_some() as u16 * F_DRIVE)
        | (out.edge.is_some() as u16 * F_EDGE)
        | (out.fault.is_some() as u16 * F_FAULT);
    o.u16(flags);
    if let Some(p) = out.position {
        o.u32(p.x_um as u32);
        o.u32(p.y_um as u32);
    }
    if let Some(v) = out.velocity {
        o.u32(v.vx_um_s as u32);
        o.u32(v.vy_um_s as u32);
    }
    if let Some(p) = out.place {
        o.u8(match p {
            Place::Background => 255,
            Place::Window(i) => i,
        });
    }
    if let Some(a) = out.action {
        let (kind, ts) = match a {
            GateAction::Off => (0, None),
            GateAction::Start(t) => (1, Some(t)),
            GateAction::Update(t) => (2, Some(t)),
            GateAction::Pulse(t) => (3, Some(t)),
        };
        o.u8(kind);
        if let Some(t) = ts {
            o.u16(t.psc);
            o.u32(t.arr);
            o.u32(t.ccr);
        }
    }
    if let Some(a) = out.amplitude_permille {
        o.u16(a);
    }
    if let Some(e) = out.envelope {
        o.u8(match e {
            Envelope::Rectangular => 0,
            Envelope::Triangular => 1,
        });
    }
    if let Some(d) = out.drive {
        o.u8(match d {
            DriveMode::Standing => 0,
            DriveMode::Progressive => 1,
        });
    }
    if let Some(e) = out.edge {
        o.u8(e);
    }
    if let Some(f) = out.fault {
        match f {
            TouchFault::Stale => o.u8(0xff),
            TouchFault::Rail(a) => encode_axis_fault(o, &a),
        }
    }
}

/// Decodes [`encode_output2d`].
pub fn decode_output2d(r: &mut Reader) -> Output2d {
    let flags = r.u16();
    let mut o = Output2d::default();
    if flags & F_POS != 0 {
        o.position = Some(PointUm::new(r.i32(), r.i32()));
    }
    if flags & F_VEL != 0 {
        o.velocity = Some(VelocityUmS {
            vx_um_s: r.i32(),
            vy_um_s: r.i32(),
        });
    }
    if flags & F_PLACE != 0 {
        o.place = Some(match r.u8() {
            255 => Place::Background,
            i => Place::Window(i),
        });
    }
    if flags & F_ACTION != 0 {
        let kind = r.u8();
        let ts = |r: &mut Reader| TimerSettings {
            psc: r.u16(),
            arr: r.u32(),
            ccr: r.u32(),
        };
        o.action = Some(match kind {
            0 => GateAction::Off,
            1 => GateAction::Start(ts(r)),
            2 => GateAction::Update(ts(r)),
            _ => GateAction::Pulse(ts(r)),
        });
    }
    if flags & F_AMP != 0 {
        o.amplitude_permille = Some(r.u16());
    }
    if flags & F_ENV != 0 {
        o.envelope = Some(if r.u8() == 0 {
            Envelope::Rectangular
        } else {
            Envelope::Triangular
        });
    }
    if flags & F_DRIVE != 0 {
        o.drive = Some(if r.u8() == 0 {
            DriveMode::Standing
        } else {
            DriveMode::Progressive
        });
    }
    if flags & F_EDGE != 0 {
        o.edge = Some(r.u8());
    }
    if flags & F_FAULT != 0 {
        let b = r.data[r.pos];
        o.fault = Some(if b == 0xff {
            r.pos += 1;
            TouchFault::Stale
        } else {
            TouchFault::Rail(decode_axis_fault(r))
        });
    }
    o
}
