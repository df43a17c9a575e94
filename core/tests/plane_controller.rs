//! Property test of the 2D controller against the caps (issue #36): random strokes, jumps,
//! lift-offs, landings, rail faults, silences past the stale limit and scene reloads, on a
//! scene with every texture kind the plane takes and edges, under random caps. What the
//! controller emitted (readings and ticks) is replayed into the line a timer would drive
//! (tests/common, written from the timer's manual, not from the gate) and checked: every
//! window of the stated length holds at most cap × window of on-time (one periodic run: plus
//! its partial period), every continuous on-time is at most the on-time cap; and every
//! lift-off, landing and fault leaves the line low from that reading on.
//!
//! With `textured` the background is a 1 kHz burst and every outline pulses: edges stop
//! running bursts (and ridge pulses) before their own pulse, and no Pulse may reach the port
//! while a burst runs. Of 48 cases about 30 are textured: there 120 edge pulses fired, 216
//! crossings skipped (caps down to 2 %, pulse + rest windows). Seen failing (2026-11-29) with
//! the edge's Pulse sent over the running burst instead of after its Off ("a pulse sent over
//! a running burst", found at once).
//!
//! Seen failing (2026-11-29) on two planted defects: an edge pulse sent although the gate
//! refused it (the 2 % cap broken: 23 ‰ in a 27.8 ms window), and a lift-off that left the
//! line as it was ("Lifted at 19000 µs left the line high").

use proptest::prelude::*;
use saw_core::burst::{BurstCommand, BurstTimer, SafetyLimits};
use saw_core::gate::GateAction;
use saw_core::plane::{
    Config2d, Controller2d, OrientedGrating, PlaneTexture, PointUm, Polygon, SegmentUm, Window2d,
};
use saw_core::position::SensorFault;
use saw_core::texture::{Grating, GratingRender, Material, RandomBurst, Texture};
use saw_core::touch::fault::{Axis, AxisFault};
use saw_core::touch::frame::Reading;

mod common;
use common::LineModel;

const T: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};
const PERIOD_US: u32 = 100;

/// Six 20 mm windows (a 3 × 2 grid over 60 × 40 mm), one texture kind each, rotated by
/// `shift` (a reload brings another layout); the background off; edges on two
/// outlines and two free diagonals. Every duty at most the cap, the pulse at most the on-time.
/// `textured`: every outline pulses and the background is a 1 kHz constant burst, so edges
/// preempt running bursts and ridge pulses everywhere.
fn scene(limits: &SafetyLimits, shift: usize, textured: bool) -> Config2d {
    let duty = 400u16.min(limits.max_duty_permille);
    let constant = |hz: u32| {
        PlaneTexture::Plain(Texture::Constant(BurstCommand {
            burst_millihz: hz * 1000,
            duty_permille: duty,
        }))
    };
    let grating = |render| {
        let mut g = Grating::new(1_000);
        g.render = render;
        g.duty_permille = duty;
        g
    };
    let mut material = Material::fig5(0.3);
    material.duty_permille = duty;
    let kinds = [
        constant(20),
        PlaneTexture::Oriented(OrientedGrating {
            grating: grating(GratingRender::PositionPhase),
            normal: (1, 1),
        }),
        PlaneTexture::Plain(Texture::Material(material)),
        PlaneTexture::Plain(Texture::Grating(grating(GratingRender::VelocitySynthesis))),
        PlaneTexture::Plain(Texture::Random(RandomBurst {
            center_millihz: 200_000,
            spread_permille: 500,
            amplitude_permille: 1000,
            amplitude_spread_permille: 300,
            duty_permille: duty,
            seed: 9,
        })),
        PlaneTexture::Oriented(OrientedGrating {
            grating: grating(GratingRender::Hybrid),
            normal: (0, 1),
        }),
    ];
    let mut c = Config2d {
        limits: *limits,
        ..Config2d::default()
    };
    for k in 0..6 {
        let (x0, y0) = ((k % 3) as i32 * 20_000, (k / 3) as i32 * 20_000);
        let outline =
            Polygon::rectangle(PointUm::new(x0, y0), PointUm::new(x0 + 20_000, y0 + 20_000))
                .unwrap();
        c.scene
            .windows
            .push(Window2d {
                outline,
                texture: kinds[(k + shift) % 6],
                edge: textured || k == 1 || k == 5,
            })
            .unwrap();
    }
    // Off, or a burst every edge over it must stop before its pulse.
    c.scene.background = if textured {
        constant(1_000)
    } else {
        PlaneTexture::Plain(Texture::Off)
    };
    for (a, b) in [
        ((5_000, 5_000), (25_000, 35_000)),
        ((50_000, 2_000), (30_000, 38_000)),
    ] {
        c.scene
            .free_edges
            .push(SegmentUm {
                a: PointUm::new(a.0, a.1),
                b: PointUm::new(b.0, b.1),
            })
            .unwrap();
    }
    c.scene.edge_pulse.pulse_us = 10_000.min(limits.max_on_time_us);
    c
}

#[derive(Clone, Copy, Debug)]
enum Op {
    /// Readings moving (dx, dy) µm a reading, with ± `noise` µm.
    Slide(i32, i32, i32),
    /// The finger jumps to (x, y) (a reading far from the last).
    Jump(i32, i32),
    Lift,
    Landing,
    Fault,
    /// No reading for this long, µs (ticks every period meanwhile).
    Silence(u32),
    /// The scene reloaded with another layout.
    Reload(usize),
}

fn op() -> impl Strategy<Value = (Op, u16)> {
    prop_oneof![
        8 => ((-40i32..=40, -40i32..=40, 0i32..=20).prop_map(|(x, y, n)| Op::Slide(x, y, n)), 1u16..2_000),
        1 => ((-5_000i32..=65_000, -5_000i32..=45_000).prop_map(|(x, y)| Op::Jump(x, y)), Just(1u16)),
        2 => (Just(Op::Lift), 1u16..50),
        1 => (Just(Op::Landing), 1u16..30),
        1 => (Just(Op::Fault), 1u16..30),
        1 => ((0u32..=20_000).prop_map(Op::Silence), Just(1u16)),
        1 => ((0usize..6).prop_map(Op::Reload), Just(1u16)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn random_touches_never_exceed_the_caps(
        duty in prop_oneof![100u16..=1000, 20u16..=100],
        on_us in 2_000u32..=60_000,
        t0 in any::<u32>(),
        ops in prop::collection::vec(op(), 1..40),
        textured in any::<bool>(),
    ) {
        let limits = SafetyLimits { max_duty_permille: duty, max_on_time_us: on_us, ..SafetyLimits::default() };
        let mut c = Controller2d::new(T, PERIOD_US).unwrap();
        c.load(&scene(&limits, 0, textured)).unwrap();
        let mut line = LineModel::new(&T);
        let mut t = 0u64;
        let mut p = (30_000i32, 20_000i32);
        let mut lcg = t0 | 1;
        let mut jitter = |n: i32| {
            lcg = lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            if n == 0 { 0 } else { (lcg >> 8) as i32 % (2 * n + 1) - n }
        };
        let (mut pulses, mut starts) = (0u32, 0u32);
        // The port's protocol: a Pulse only from a stopped timer (after an Off), never over a
        // running burst (the model would cut the burst and hide the overlap).
        let (mut running, mut pulse_over_burst) = (false, None);
        let mut apply = |line: &mut LineModel, t: u64, a: Option<GateAction>| {
            if let Some(a) = a {
                pulses += matches!(a, GateAction::Pulse(_)) as u32;
                starts += matches!(a, GateAction::Start(_)) as u32;
                match a {
                    GateAction::Start(_) => running = true,
                    GateAction::Off => running = false,
                    GateAction::Pulse(_) if running => {
                        pulse_over_burst.get_or_insert(t);
                    }
                    _ => {}
                }
                line.apply(t, a);
            }
        };
        for (op, n) in ops {
            for _ in 0..n {
                let now = t0.wrapping_add(t as u32);
                let reading = match op {
                    Op::Slide(dx, dy, noise) => {
                        p = ((p.0 + dx).clamp(-5_000, 65_000), (p.1 + dy).clamp(-5_000, 45_000));
                        Reading::Down { x_um: p.0 + jitter(noise), y_um: p.1 + jitter(noise), r_touch_ohm: 400 }
                    }
                    Op::Jump(x, y) => {
                        p = (x, y);
                        Reading::Down { x_um: x, y_um: y, r_touch_ohm: 400 }
                    }
                    Op::Lift => Reading::Lifted,
                    Op::Landing => Reading::Landing { x_um: p.0, y_um: p.1 },
                    Op::Fault => Reading::Fault(AxisFault { axis: Axis::Y, fault: SensorFault::RailHigh }),
                    Op::Silence(us) => {
                        let mut s = 0;
                        while s < us {
                            s += PERIOD_US;
                            let a = c.on_tick(t0.wrapping_add((t + s as u64) as u32));
                            apply(&mut line, t + s as u64, a);
                        }
                        t += us as u64;
                        continue;
                    }
                    Op::Reload(shift) => {
                        c.load(&scene(&limits, shift, textured)).unwrap();
                        let a = c.on_tick(now);
                        apply(&mut line, t, a);
                        continue;
                    }
                };
                let out = c.on_reading(now, reading);
                apply(&mut line, t, out.action);
                if !matches!(reading, Reading::Down { .. }) {
                    // Off from this reading on: nothing high after it.
                    line.advance(line.clocks(t));
                    let at = line.clocks(t);
                    prop_assert!(!line.high_within(at, at + line.clocks(1_000_000)),
                        "{reading:?} at {t} µs left the line high");
                }
                let a = c.on_tick(now);
                apply(&mut line, t, a);
                t += PERIOD_US as u64;
            }
        }
        let end = t + 2 * common::stated_window_us(duty as u64, on_us as u64);
        line.advance(line.clocks(end));
        line.apply(end, GateAction::Off);
        prop_assert_eq!(line.protocol_errors, 0);
        prop_assert_eq!(pulse_over_burst, None, "a pulse sent over a running burst");
        let window = line.clocks(common::stated_window_us(duty as u64, on_us as u64));
        let max_on = limits.max_on_time_clocks(&T);
        if let Err(e) = common::check_caps(&line.on, duty as u64, max_on, window) {
            prop_assert!(false, "{} (cap {} ‰, on-time cap {} µs, {} pulses, {} starts)", e, duty, on_us, pulses, starts);
        }
    }
}
