//! Golden-vector file format, shared by the host generator (`host-sim/src/bin/golden.rs`
//! includes this file with `#[path]`) and the emulator image. no_std, no allocation.
//!
//! All integers little-endian. `golden.bin`:
//!
//! ```text
//! magic "SAWG" u32 version
//! timer: clock_hz u32, counter_bits u8, max_burst_hz u32; sample_period_us u32
//! n_scenes u8, per scene: name (u8 len + bytes), config (see encode_config)
//! n_vectors u8, per vector: name, scene index u8, n_samples u32,
//!     inputs (n × [code u16, t_us u32]), out_len u32, outputs (records, see encode_output),
//!     crc32 of the outputs u32
//! ```
//!
//! The config encoding carries every field of `saw_core::Config` (f32 as raw bits), so the image
//! rebuilds exactly the `Config` the host ran (the host checks the round trip).

use saw_core::burst::{BurstCommand, BurstTimer, SafetyLimits, TimerSettings};
use saw_core::gate::{DriveMode, GateAction};
use saw_core::position::{Calibration, SensorFault};
use saw_core::scene::{Config, Scene};
use saw_core::texture::{Envelope, Grating, GratingRender, Lines, Material, RandomBurst, Texture};
use saw_core::Output;

/// File magic.
pub const MAGIC: &[u8; 4] = b"SAWG";
/// Format version.
pub const VERSION: u32 = 1;
/// Longest encoded output record.
pub const MAX_RECORD: usize = 32;

/// Where encoded bytes go.
pub trait Sink {
    /// Appends bytes.
    fn put(&mut self, bytes: &[u8]);
    /// Appends a u8.
    fn u8(&mut self, v: u8) {
        self.put(&[v])
    }
    /// Appends a u16.
    fn u16(&mut self, v: u16) {
        self.put(&v.to_le_bytes())
    }
    /// Appends a u32.
    fn u32(&mut self, v: u32) {
        self.put(&v.to_le_bytes())
    }
    /// Appends a u64.
    fn u64(&mut self, v: u64) {
        self.put(&v.to_le_bytes())
    }
    /// Appends a name (u8 length + bytes).
    fn name(&mut self, s: &str) {
        self.u8(s.len() as u8);
        self.put(s.as_bytes());
    }
}

/// A fixed buffer sink of `N` bytes (one output record; the 2D records are longer, see
/// `plane2d::Rec`).
pub struct Record<const N: usize> {
    /// Bytes.
    pub bytes: [u8; N],
    /// Used length.
    pub len: usize,
}

/// A 1D output record's buffer.
pub type Buf = Record<MAX_RECORD>;

impl<const N: usize> Record<N> {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            bytes: [0; N],
            len: 0,
        }
    }
    /// The used bytes.
    pub fn as_slice(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl<const N: usize> Sink for Record<N> {
    fn put(&mut self, b: &[u8]) {
        self.bytes[self.len..self.len + b.len()].copy_from_slice(b);
        self.len += b.len();
    }
}

/// A cursor over encoded bytes. Panics on truncated input (a broken build, not a runtime case).
pub struct Reader<'a> {
    /// The bytes.
    pub data: &'a [u8],
    /// Position.
    pub pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `data`.
    pub const fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }
    /// Takes `n` bytes.
    pub fn take(&mut self, n: usize) -> &'a [u8] {
        let s = &self.data[self.pos..self.pos + n];
        self.pos += n;
        s
    }
    /// Reads a u8.
    pub fn u8(&mut self) -> u8 {
        self.take(1)[0]
    }
    /// Reads a u16.
    pub fn u16(&mut self) -> u16 {
        let b = self.take(2);
        u16::from_le_bytes([b[0], b[1]])
    }
    /// Reads a u32.
    pub fn u32(&mut self) -> u32 {
        let b = self.take(4);
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
    /// Reads an i32.
    pub fn i32(&mut self) -> i32 {
        self.u32() as i32
    }
    /// Reads a u64.
    pub fn u64(&mut self) -> u64 {
        (self.u32() as u64) | ((self.u32() as u64) << 32)
    }
    /// Reads an f32 from its bits.
    pub fn f32(&mut self) -> f32 {
        f32::from_bits(self.u32())
    }
    /// Reads a name.
    pub fn name(&mut self) -> &'a str {
        let n = self.u8() as usize;
        core::str::from_utf8(self.take(n)).unwrap_or("?")
    }
    /// True at the end.
    pub fn done(&self) -> bool {
        self.pos >= self.data.len()
    }
}

/// Encodes the board's burst timer and sample period.
pub fn encode_timer<S: Sink>(s: &mut S, t: &BurstTimer, sample_period_us: u32) {
    s.u32(t.clock_hz);
    s.u8(t.counter_bits);
    s.u32(t.max_burst_hz);
    s.u32(sample_period_us);
}

/// Decodes [`encode_timer`].
pub fn decode_timer(r: &mut Reader) -> (BurstTimer, u32) {
    let t = BurstTimer {
        clock_hz: r.u32(),
        counter_bits: r.u8(),
        max_burst_hz: r.u32(),
    };
    (t, r.u32())
}

/// Encodes every field of a configuration. Panics on a texture kind this format does not know.
pub fn encode_config<S: Sink>(s: &mut S, c: &Config) {
    let cal = &c.calibration;
    s.u16(cal.code_at_start);
    s.u16(cal.code_at_end);
    s.u32(cal.length_um);
    s.u16(cal.rail_margin_code);
    s.u16(c.limits.max_duty_permille);
    s.u32(c.limits.max_on_time_us);
    s.u32(c.stale_after_us);
    let sc = &c.scene;
    s.u32(sc.hysteresis_um);
    s.u8(match sc.drive {
        DriveMode::Standing => 0,
        DriveMode::Progressive => 1,
    });
    s.u8(sc.boundaries_um.len() as u8);
    for &b in &sc.boundaries_um {
        s.u32(b);
    }
    s.u8(sc.textures.len() as u8);
    for t in &sc.textures {
        match t {
            Texture::Off => s.u8(0),
            Texture::Constant(c) => {
                s.u8(1);
                s.u32(c.burst_millihz);
                s.u16(c.duty_permille);
            }
            Texture::Grating(g) => {
                s.u8(2);
                s.u32(g.wavelength_um);
                s.u16(g.duty_permille);
                s.u32(g.min_speed_um_s);
                s.u16(g.amplitude_permille);
                s.u8(match g.render {
                    GratingRender::PositionPhase => 0,
                    GratingRender::VelocitySynthesis => 1,
                    GratingRender::Hybrid => 2,
                });
                s.u32(g.rearm_um);
            }
            Texture::Material(m) => {
                s.u8(3);
                s.u32(m.delta_mu.to_bits());
                s.u32(m.normal_force_n.to_bits());
                s.u32(m.mass_kg.to_bits());
                s.u32(m.stiffness_n_per_m.to_bits());
                s.u16(m.duty_permille);
                s.u32(m.min_speed_um_s);
            }
            Texture::Random(r) => {
                s.u8(4);
                s.u32(r.center_millihz);
                s.u16(r.spread_permille);
                s.u16(r.amplitude_permille);
                s.u16(r.amplitude_spread_permille);
                s.u16(r.duty_permille);
                s.u64(r.seed);
            }
            #[allow(unreachable_patterns)]
            _ => panic!("golden format: unknown texture kind"),
        }
    }
    let l = &sc.lines;
    s.u8(l.positions_um.len() as u8);
    for &p in &l.positions_um {
        s.u32(p);
    }
    s.u32(l.pulse_us);
    s.u8(match l.envelope {
        Envelope::Rectangular => 0,
        Envelope::Triangular => 1,
    });
    s.u16(l.amplitude_permille);
    s.u32(l.hysteresis_um);
}

/// Decodes [`encode_config`].
pub fn decode_config(r: &mut Reader) -> Config {
    let calibration = Calibration {
        code_at_start: r.u16(),
        code_at_end: r.u16(),
        length_um: r.u32(),
        rail_margin_code: r.u16(),
    };
    let limits = SafetyLimits {
        max_duty_permille: r.u16(),
        max_on_time_us: r.u32(),
        // Not in the golden-vector format: the vectors predate the level cap (full drive).
        max_level_permille: 1000,
    };
    let stale_after_us = r.u32();
    let hysteresis_um = r.u32();
    let drive = if r.u8() == 0 {
        DriveMode::Standing
    } else {
        DriveMode::Progressive
    };
    // Start from the default config so the heapless vectors need not be named (the host crate
    // has no heapless dependency); every field is overwritten below.
    let mut base = saw_core::default_config();
    let mut boundaries_um = core::mem::take(&mut base.scene.boundaries_um);
    boundaries_um.clear();
    for _ in 0..r.u8() {
        let _ = boundaries_um.push(r.u32());
    }
    let mut textures = core::mem::take(&mut base.scene.textures);
    textures.clear();
    for _ in 0..r.u8() {
        let t = match r.u8() {
            0 => Texture::Off,
            1 => Texture::Constant(BurstCommand {
                burst_millihz: r.u32(),
                duty_permille: r.u16(),
            }),
            2 => Texture::Grating(Grating {
                wavelength_um: r.u32(),
                duty_permille: r.u16(),
                min_speed_um_s: r.u32(),
                amplitude_permille: r.u16(),
                render: match r.u8() {
                    0 => GratingRender::PositionPhase,
                    2 => GratingRender::Hybrid,
                    _ => GratingRender::VelocitySynthesis,
                },
                rearm_um: r.u32(),
            }),
            3 => Texture::Material(Material {
                delta_mu: r.f32(),
                normal_force_n: r.f32(),
                mass_kg: r.f32(),
                stiffness_n_per_m: r.f32(),
                duty_permille: r.u16(),
                min_speed_um_s: r.u32(),
            }),
            4 => Texture::Random(RandomBurst {
                center_millihz: r.u32(),
                spread_permille: r.u16(),
                amplitude_permille: r.u16(),
                amplitude_spread_permille: r.u16(),
                duty_permille: r.u16(),
                seed: r.u64(),
            }),
            k => panic!("golden format: texture tag {}", k),
        };
        let _ = textures.push(t);
    }
    let mut positions_um = core::mem::take(&mut base.scene.lines.positions_um);
    positions_um.clear();
    for _ in 0..r.u8() {
        let _ = positions_um.push(r.u32());
    }
    let lines = Lines {
        positions_um,
        pulse_us: r.u32(),
        envelope: if r.u8() == 0 {
            Envelope::Rectangular
        } else {
            Envelope::Triangular
        },
        amplitude_permille: r.u16(),
        hysteresis_um: r.u32(),
    };
    Config {
        calibration,
        scene: Scene {
            boundaries_um,
            textures,
            hysteresis_um,
            lines,
            drive,
        },
        limits,
        stale_after_us,
    }
}

/// Presence flags of an output record.
const F_POS: u8 = 1;
const F_VEL: u8 = 2;
const F_REGION: u8 = 4;
const F_ACTION: u8 = 8;
const F_AMP: u8 = 16;
const F_DRIVE: u8 = 32;
const F_LINE: u8 = 64;
const F_FAULT: u8 = 128;

/// Encodes one output: a flag byte, then only the fields present.
pub fn encode_output<S: Sink>(s: &mut S, o: &Output) {
    let flags = (o.position_um.is_some() as u8 * F_POS)
        | (o.velocity_um_s.is_some() as u8 * F_VEL)
        | (o.region.is_some() as u8 * F_REGION)
        | (o.action.is_some() as u8 * F_ACTION)
        | (o.amplitude_permille.is_some() as u8 * F_AMP)
        | (o.drive.is_some() as u8 * F_DRIVE)
        | (o.line.is_some() as u8 * F_LINE)
        | (o.fault.is_some() as u8 * F_FAULT);
    s.u8(flags);
    if let Some(p) = o.position_um {
        s.u32(p as u32);
    }
    if let Some(v) = o.velocity_um_s {
        s.u32(v as u32);
    }
    if let Some(r) = o.region {
        s.u8(r);
    }
    if let Some(a) = o.action {
        // The flag byte is full: a pulse's envelope (sent only with a pulse) rides in its kind.
        let (kind, ts) = match (a, o.envelope) {
            (GateAction::Off, _) => (0, None),
            (GateAction::Start(t), _) => (1, Some(t)),
            (GateAction::Update(t), _) => (2, Some(t)),
            (GateAction::Pulse(t), None) => (3, Some(t)),
            (GateAction::Pulse(t), Some(Envelope::Rectangular)) => (4, Some(t)),
            (GateAction::Pulse(t), Some(Envelope::Triangular)) => (5, Some(t)),
        };
        s.u8(kind);
        // A pulse's delay (issue #17: the line rises arr + 1 − ccr ticks after the start,
        // `TimerSettings::pulse_delay_clocks`) rides in arr: a delayed pulse is encoded, compared
        // and printed (the DIFF line's defmt `TimerSettings`) with psc, arr and ccr like any other.
        if let Some(t) = ts {
            s.u16(t.psc);
            s.u32(t.arr);
            s.u32(t.ccr);
        }
    }
    if let Some(a) = o.amplitude_permille {
        s.u16(a);
    }
    if let Some(d) = o.drive {
        s.u8(d as u8);
    }
    if let Some(l) = o.line {
        s.u8(l);
    }
    if let Some(f) = o.fault {
        s.u8(match f {
            SensorFault::RailLow => 0,
            SensorFault::RailHigh => 1,
            SensorFault::Stale => 2,
            #[allow(unreachable_patterns)]
            _ => 255,
        });
    }
}

/// Decodes one record of [`encode_output`] (fault 255 decodes as Stale: never produced).
pub fn decode_output(r: &mut Reader) -> Output {
    let flags = r.u8();
    let mut o = Output::default();
    if flags & F_POS != 0 {
        o.position_um = Some(r.i32());
    }
    if flags & F_VEL != 0 {
        o.velocity_um_s = Some(r.i32());
    }
    if flags & F_REGION != 0 {
        o.region = Some(r.u8());
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
        o.envelope = match kind {
            4 => Some(Envelope::Rectangular),
            5 => Some(Envelope::Triangular),
            _ => None,
        };
    }
    if flags & F_AMP != 0 {
        o.amplitude_permille = Some(r.u16());
    }
    if flags & F_DRIVE != 0 {
        o.drive = Some(if r.u8() == 0 {
            DriveMode::Standing
        } else {
            DriveMode::Progressive
        });
    }
    if flags & F_LINE != 0 {
        o.line = Some(r.u8());
    }
    if flags & F_FAULT != 0 {
        o.fault = Some(match r.u8() {
            0 => SensorFault::RailLow,
            1 => SensorFault::RailHigh,
            _ => SensorFault::Stale,
        });
    }
    o
}

/// The tolerance applied where f32 arithmetic sits inside (grating, material, random): the
/// timer's ARR and CCR may each differ by this many ticks; everything else must be identical.
pub const TICK_TOLERANCE: u32 = 1;

/// True when `a` and `b` differ only by ARR/CCR within [`TICK_TOLERANCE`] (same action kind,
/// same prescaler, all other fields equal).
pub fn within_tolerance(a: &Output, b: &Output) -> bool {
    let settings = |o: &Output| match o.action {
        Some(GateAction::Start(t) | GateAction::Update(t) | GateAction::Pulse(t)) => Some(t),
        _ => None,
    };
    let kind = |o: &Output| o.action.map(|a| core::mem::discriminant(&a));
    let (sa, sb) = (settings(a), settings(b));
    let settings_ok = match (sa, sb) {
        (Some(x), Some(y)) => {
            x.psc == y.psc
                && x.arr.abs_diff(y.arr) <= TICK_TOLERANCE
                && x.ccr.abs_diff(y.ccr) <= TICK_TOLERANCE
        }
        (None, None) => true,
        _ => false,
    };
    let mut a2 = *a;
    let mut b2 = *b;
    a2.action = None;
    b2.action = None;
    settings_ok && kind(a) == kind(b) && a2 == b2
}

/// CRC-32 (IEEE 802.3, reflected, poly 0xEDB88320), bitwise: small, and outside every timed loop.
pub fn crc32_update(mut crc: u32, data: &[u8]) -> u32 {
    crc = !crc;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
        }
    }
    !crc
}
