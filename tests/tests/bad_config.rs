//! Bad configurations through the public API: `load` returns the specific error and the scene
//! that was running keeps running — same outputs and same gate waveform for the same input as a
//! controller that never saw the bad configuration.

use host_sim::adc::{AdcModel, AdcParams};
use host_sim::sim::burst_timer;
use host_sim::timer::TimerModel;
use host_sim::trajectory::Trajectory;
use saw_core::burst::{BurstCommand, BurstError};
use saw_core::position::{Calibration, CalibrationError};
use saw_core::region::RegionError;
use saw_core::texture::Texture;
use saw_core::{Config, ConfigError, Controller, Output};

fn bad_configs(max_burst_hz: u32) -> Vec<(&'static str, Config, ConfigError)> {
    let good = saw_core::default_config();
    let mut v = Vec::new();
    let mut c = good.clone();
    c.calibration = Calibration {
        code_at_start: good.calibration.code_at_end,
        code_at_end: good.calibration.code_at_start,
        ..good.calibration
    };
    v.push((
        "calibration ends swapped",
        c,
        ConfigError::Calibration(CalibrationError::EndsSwapped {
            code_at_start: good.calibration.code_at_end,
            code_at_end: good.calibration.code_at_start,
        }),
    ));
    let mut c = good.clone();
    c.calibration.code_at_end = c.calibration.code_at_start + 4_000;
    v.push((
        "calibration ends too close",
        c,
        ConfigError::Calibration(CalibrationError::EndsTooClose {
            span_code: 4_000,
            min_span_code: saw_core::position::MIN_SPAN_CODE,
        }),
    ));
    let mut c = good.clone();
    c.scene.boundaries_um[1] = c.scene.boundaries_um[0];
    let b = good.scene.boundaries_um.clone();
    v.push((
        "overlapping boundaries",
        c,
        ConfigError::Region(RegionError::Unsorted {
            index: 1,
            at_um: b[0],
            previous_um: b[0],
        }),
    ));
    let mut c = good.clone();
    c.scene.boundaries_um.swap(0, 1);
    v.push((
        "unsorted boundaries",
        c,
        ConfigError::Region(RegionError::Unsorted {
            index: 1,
            at_um: b[0],
            previous_um: b[1],
        }),
    ));
    for (what, millihz, duty, error) in [
        ("f_b = 0", 0, 400, BurstError::ZeroFrequency),
        (
            "f_b above the board limit",
            max_burst_hz * 1000 + 1,
            400,
            BurstError::AboveBoardLimit {
                burst_millihz: max_burst_hz * 1000 + 1,
                max_millihz: max_burst_hz * 1000,
            },
        ),
        (
            "duty 0",
            80_000,
            0,
            BurstError::BadDuty { duty_permille: 0 },
        ),
        (
            "duty above the cap",
            80_000,
            good.limits.max_duty_permille + 1,
            BurstError::DutyAboveCap {
                duty_permille: good.limits.max_duty_permille + 1,
                cap_permille: good.limits.max_duty_permille,
            },
        ),
    ] {
        let mut c = good.clone();
        c.scene.textures[2] = Texture::Constant(BurstCommand {
            burst_millihz: millihz,
            duty_permille: duty,
        });
        v.push((what, c, ConfigError::Texture { region: 2, error }));
    }
    v
}

/// Feeds a seeded stroke (all three regions) into `ctrl` from `t0_us`; returns the outputs and
/// the gate edges.
fn stroke(
    ctrl: &mut Controller,
    tm: &mut TimerModel,
    t0_us: u64,
) -> (Vec<Output>, Vec<host_sim::timer::Edge>) {
    let timer = *ctrl.timer();
    let clk = |t_us: u64| t_us * timer.clock_hz as u64 / 1_000_000;
    let mut adc = AdcModel::new(Calibration::default(), AdcParams::default()).unwrap();
    let traj = Trajectory::Triangle {
        a_um: 30_000.0,
        b_um: 60_000.0,
        speed_um_s: 100_000.0,
    };
    let mut outs = Vec::new();
    for k in 0..6_000u64 {
        let t = t0_us + k * 100;
        let pos = traj.state(k as f64 * 1e-4).position_um;
        let s = adc.sample(pos, t).unwrap();
        let out = ctrl.on_sample(s);
        if let Some(a) = out.action {
            tm.apply(clk(t), a);
        }
        outs.push(out);
    }
    tm.advance_to(clk(t0_us + 600_000));
    let from = clk(t0_us);
    let edges = tm
        .waveform()
        .edges
        .into_iter()
        .filter(|e| e.t >= from)
        .collect();
    (outs, edges)
}

#[test]
fn rejected_configs_name_their_error_and_keep_the_running_scene() {
    for board in saw_boards::ALL {
        let timer = burst_timer(board);
        let mut ctrl = Controller::new(timer, 100).unwrap();
        ctrl.load(&saw_core::default_config()).unwrap();
        let mut tm = TimerModel::new(timer.clock_hz, timer.counter_bits, true);
        let mut t0 = 0u64;
        let (warm, _) = stroke(&mut ctrl, &mut tm, t0);
        assert!(warm.iter().any(|o| o.region == Some(2)));
        t0 += 600_000;
        for (what, cfg, want) in bad_configs(board.max_burst_hz) {
            let mut reference = ctrl.clone();
            let mut ref_tm = tm.clone();
            assert_eq!(ctrl.load(&cfg), Err(want), "{}: {what}", board.name);
            let (got, got_edges) = stroke(&mut ctrl, &mut tm, t0);
            let (exp, exp_edges) = stroke(&mut reference, &mut ref_tm, t0);
            assert_eq!(
                got, exp,
                "{}: outputs changed after rejected {what}",
                board.name
            );
            assert_eq!(
                got_edges, exp_edges,
                "{}: gate changed after {what}",
                board.name
            );
            // And the scene is really running: regions and bursts, not a dead controller.
            assert!(got.iter().any(|o| o.region == Some(2)));
            assert!(got_edges.len() > 100, "{what}: {} edges", got_edges.len());
            assert_eq!(tm.protocol_errors, 0);
            t0 += 600_000;
        }
        assert_eq!(
            ctrl.telemetry().burst_millihz,
            80_000,
            "stroke ends at 30 mm, region 1"
        );
    }
}
