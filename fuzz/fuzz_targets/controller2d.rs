//! `Controller2d` over arbitrary scene configurations and readings: the fuzzer's bytes are a
//! `Config2d` (postcard, as the host link carries configurations; a fixed scene with windows,
//! edges and an oriented grating when they do not decode or load), then operations — lifted,
//! landing, down, rail-fault readings, raw frames through a calibrated `TouchSensor`, watchdog
//! ticks after arbitrary silences, clock jumps across the u32 wrap, mid-stream reloads of other
//! decoded configurations. Checked on every action, from the caps' statement rather than the
//! gate's code: no panic; every on-time within the on-time cap of the scenes in force (one timer
//! tick of rounding); no burst or pulse started on a lifted, landing or faulty reading, nor by a
//! tick; a running periodic burst stopped on such a reading.
#![no_main]

use saw_core::burst::{BurstTimer, SafetyLimits, TimerSettings};
use saw_core::gate::GateAction;
use saw_core::plane::{
    Config2d, Controller2d, OrientedGrating, PlaneTexture, PointUm, Polygon, SegmentUm, Window2d,
};
use saw_core::position::SensorFault;
use saw_core::texture::{Grating, GratingRender, Texture};
use saw_core::touch::calibration::{Affine, CalPoint};
use saw_core::touch::fault::{Axis, AxisFault, RailBands};
use saw_core::touch::frame::{Frame, Reading, TouchSensor};
use saw_core::touch::pressure::PressureConfig;
use saw_link::testing::TIMER;

struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> Option<u8> {
        let (b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(*b)
    }
    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes([self.u8()?, self.u8()?]))
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes([self.u8()?, self.u8()?, self.u8()?, self.u8()?]))
    }
    fn i32(&mut self) -> Option<i32> {
        self.u32().map(|v| v as i32)
    }
    /// A length-prefixed chunk decoded as a configuration.
    fn config(&mut self) -> Option<Option<Config2d>> {
        let n = (self.u16()? as usize).min(self.0.len());
        let (chunk, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(postcard::from_bytes::<Config2d>(chunk).ok())
    }
}

/// A scene that loads: a constant window with a felt outline, a concave L of oriented ridges,
/// a free edge.
fn fallback() -> Config2d {
    let pt = PointUm::new;
    let mut c = Config2d::default();
    let mut g = Grating::new(2_000);
    g.render = GratingRender::PositionPhase;
    g.duty_permille = 300;
    let windows = [
        (
            Polygon::rectangle(pt(5_000, 5_000), pt(30_000, 40_000)),
            PlaneTexture::Plain(Texture::constant_hz(200)),
            true,
        ),
        (
            Polygon::from_points(&[
                pt(40_000, 5_000),
                pt(90_000, 5_000),
                pt(90_000, 20_000),
                pt(60_000, 20_000),
                pt(60_000, 50_000),
                pt(40_000, 50_000),
            ]),
            PlaneTexture::Oriented(OrientedGrating {
                grating: g,
                normal: (3, 4),
            }),
            false,
        ),
    ];
    for (outline, texture, edge) in windows {
        if let Ok(outline) = outline {
            let _ = c.scene.windows.push(Window2d {
                outline,
                texture,
                edge,
            });
        }
    }
    let _ = c.scene.free_edges.push(SegmentUm {
        a: pt(30_000, 45_000),
        b: pt(60_000, 52_000),
    });
    c
}

fn sensor() -> TouchSensor {
    let cal = [
        (6_000, 7_000, 9_500, 5_400),
        (59_000, 32_000, 85_500, 27_000),
        (32_000, 58_000, 47_500, 48_600),
    ]
    .map(|(x_code, y_code, x_um, y_um)| CalPoint {
        x_code,
        y_code,
        x_um,
        y_um,
    });
    let map = Affine::from_points(cal, &RailBands::default()).expect("a calibration");
    TouchSensor::new(PressureConfig::DEFAULT, RailBands::default(), map).expect("a sensor")
}

/// The on-time cap in timer clocks, from the cap's statement (µs × clock), rounded up.
fn on_cap_clocks(limits: &SafetyLimits, timer: &BurstTimer) -> u64 {
    (limits.max_on_time_us as u64 * timer.clock_hz as u64).div_ceil(1_000_000)
}

fn check_settings(s: &TimerSettings, caps: &[SafetyLimits], what: &str) {
    // The loosest cap in force (a pulse planned under the scene before a reload).
    let cap = caps
        .iter()
        .map(|l| on_cap_clocks(l, &TIMER))
        .max()
        .unwrap_or(0);
    // One tick of the prescaled counter for rounding.
    let tick = s.psc as u64 + 1;
    assert!(
        s.on_clocks() <= cap + tick,
        "{what}: on for {} clocks above the on-time cap of {cap} clocks ({s:?})",
        s.on_clocks()
    );
}

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let Some(period_byte) = b.u8() else { return };
    let frame_us = 100 + period_byte as u32 * 4;
    let Ok(mut ctrl) = Controller2d::new(TIMER, frame_us) else {
        return;
    };
    let first = b.config().flatten();
    let mut limits = match first.as_ref().map(|c| ctrl.load(c)) {
        Some(Ok(())) => first.map(|c| c.limits),
        _ => {
            let c = fallback();
            ctrl.load(&c).expect("the fallback scene loads");
            Some(c.limits)
        }
    }
    .unwrap_or_default();
    // The caps of the scene before the last load, for pulses planned under it.
    let mut before = limits;
    let mut sensor = sensor();
    let mut t: u32 = b.u32().unwrap_or(0);
    let mut running = false;
    while let Some(op) = b.u8() {
        t = t.wrapping_add(frame_us);
        let reading = match op % 9 {
            0 => Reading::Lifted,
            1 => Reading::Landing {
                x_um: b.i32().unwrap_or(0),
                y_um: b.i32().unwrap_or(0),
            },
            // On and about a 95 × 54 mm plate, 2 µm steps.
            2 => Reading::Down {
                x_um: b.u16().unwrap_or(0) as i32 * 2 - 10_000,
                y_um: b.u16().unwrap_or(0) as i32 * 2 - 10_000,
                r_touch_ohm: b.u16().unwrap_or(0) as u32,
            },
            // Anywhere an i32 reaches.
            3 => Reading::Down {
                x_um: b.i32().unwrap_or(0),
                y_um: b.i32().unwrap_or(0),
                r_touch_ohm: b.u32().unwrap_or(0),
            },
            4 => Reading::Fault(AxisFault {
                axis: if op & 0x10 == 0 { Axis::X } else { Axis::Y },
                fault: if op & 0x20 == 0 {
                    SensorFault::RailLow
                } else {
                    SensorFault::RailHigh
                },
            }),
            5 => sensor.on_frame(&Frame {
                x_code: b.u16().unwrap_or(0),
                y_code: b.u16().unwrap_or(0),
                z1_code: b.u16().unwrap_or(0),
                z2_code: b.u16().unwrap_or(0),
                t_us: t,
            }),
            6 => {
                // Silence, then the watchdog: only ever an Off.
                t = t.wrapping_add(b.u16().unwrap_or(0) as u32 * 4);
                if let Some(a) = ctrl.on_tick(t) {
                    assert_eq!(a, GateAction::Off, "a tick may only stop the line");
                    running = false;
                }
                continue;
            }
            7 => {
                if let Some(Some(c)) = b.config() {
                    if ctrl.load(&c).is_ok() {
                        before = limits;
                        limits = c.limits;
                    }
                }
                continue;
            }
            _ => {
                t = t.wrapping_add(b.u32().unwrap_or(0));
                continue;
            }
        };
        let out = ctrl.on_reading(t, reading);
        let rendering = matches!(reading, Reading::Down { .. });
        match out.action {
            Some(GateAction::Start(s)) | Some(GateAction::Update(s)) => {
                assert!(rendering, "a burst on {reading:?}");
                check_settings(&s, &[limits, before], "a periodic on-time");
                running = true;
            }
            Some(GateAction::Pulse(s)) => {
                assert!(rendering, "a pulse on {reading:?}");
                check_settings(&s, &[limits, before], "a pulse");
                running = false;
            }
            Some(GateAction::Off) => running = false,
            None => assert!(
                rendering || !running,
                "a running burst left on through {reading:?}"
            ),
        }
        if let Some(a) = ctrl.on_tick(t.wrapping_add(frame_us / 2)) {
            assert_eq!(a, GateAction::Off, "a tick may only stop the line");
            running = false;
        }
    }
});
