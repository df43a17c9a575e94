//! A sensor at either rail turns the gate off on the very sample that reads it, and the core
//! logs an error naming the fault.

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::scenario::region_sequence;
use host_sim::sim::{self, burst_timer, SimParams};
use host_sim::timer::TimerModel;
use host_sim::trajectory::Trajectory;
use saw_core::gate::GateAction;
use saw_core::position::SensorFault;
use saw_core::sample::Sample;
use saw_core::Controller;
use saw_tests::{capture_logs, feed, take_logs};

#[test]
fn rail_turns_the_gate_off_on_the_same_sample_and_logs_an_error() {
    capture_logs();
    for board in saw_boards::ALL {
        for (code, fault) in [
            (0u16, SensorFault::RailLow),
            (65_520, SensorFault::RailHigh),
        ] {
            let timer = burst_timer(board);
            let mut ctrl = Controller::new(timer, 100).unwrap();
            ctrl.load(&saw_core::default_config()).unwrap();
            let good = ctrl.mapper().unwrap().code_at_um(30_000.0) as u16;
            let mut tm = TimerModel::new(timer.clock_hz, timer.counter_bits, true);
            let clk = |t_us: u64| t_us * timer.clock_hz as u64 / 1_000_000;
            let mut t = 0u64;
            for _ in 0..200 {
                feed(&mut ctrl, &mut tm, good, t);
                t += 100;
            }
            // Run until the line is high, so Off has something to cut.
            while {
                tm.advance_to(clk(t));
                !tm.is_high()
            } {
                t += 1;
            }
            assert!(tm.is_running());
            take_logs();
            let out = ctrl.on_sample(Sample {
                code,
                t_us: t as u32,
            });
            assert_eq!(out.action, Some(GateAction::Off), "{}: {out:?}", board.name);
            assert_eq!(out.fault, Some(fault));
            tm.apply(clk(t), out.action.unwrap());
            let t_off = t;
            assert!(!tm.is_high() && !tm.is_running());
            let logs = take_logs();
            let needle = format!("{fault:?}");
            assert!(
                logs.iter()
                    .any(|l| l.level == log::Level::Error && l.message.contains(&needle)),
                "{}: no error line naming {needle}: {logs:?}",
                board.name
            );
            // Staying at the rail: no further action, the line stays off, no second log line.
            for _ in 0..100 {
                t += 100;
                let out = ctrl.on_sample(Sample {
                    code,
                    t_us: t as u32,
                });
                assert_eq!(out.action, None);
                assert_eq!(out.fault, Some(fault));
            }
            let w = tm.finish(clk(t));
            // (The line may have risen at the very instant of the Off: start one clock later.)
            assert!(!w.high_within(clk(t_off) + 1, clk(t)));
            assert_eq!(ctrl.telemetry().faults, 1);
            assert!(take_logs().iter().all(|l| l.level != log::Level::Error));
        }
    }
}

#[test]
fn rail_fault_mid_stroke_in_the_closed_loop() {
    capture_logs();
    for kind in [FaultKind::Open, FaultKind::Short] {
        // 0.5 s: the finger is at 30 mm, region 1, 80 Hz bursts running. The window starts
        // between two samples (0.50005 s), so the first faulty sample is at 0.5001 s.
        let p = SimParams::new(
            &saw_boards::NUCLEO_G474RE,
            Trajectory::Constant {
                from_um: 5_000.0,
                speed_um_s: 50_000.0,
            },
            1.1,
        )
        .with_faults(vec![FaultWindow {
            kind,
            start_us: 500_050,
            end_us: 600_000,
        }]);
        take_logs();
        let r = sim::run(&p).unwrap();
        let first = r.trace.iter().position(|t| t.t_us >= 500_050).unwrap();
        let t = &r.trace[first];
        assert_eq!(t.t_us, 500_100);
        assert_eq!(t.action, Some(GateAction::Off), "{kind:?}: {t:?}");
        assert!(t.fault.is_some());
        assert!(r.trace[first - 1].fault.is_none());
        assert!(!r.waveform.high_within(r.clocks(500_100), r.clocks(600_000)));
        // The line was on just before (so Off really cut something).
        assert!(r.waveform.high_within(r.clocks(450_000), r.clocks(500_100)));
        // After the fault the stroke resumes in region 1 and goes on to region 2.
        assert_eq!(region_sequence(&r), vec![0, 1, 2]);
        let logs = take_logs();
        assert!(logs
            .iter()
            .any(|l| l.level == log::Level::Error && l.message.contains("fault")));
        assert_eq!(r.telemetry.faults, 1);
    }
}
