//! `host-sim touch-budget`: the 4-wire overlay's frame budget per board, charted (issue #36,
//! docs/touch.md "Rate"): each phase's settling and conversions (X, Y, Z1, Z2) laid along the
//! frame period, and the per-axis rate that frame gives. Every figure is the core's touch
//! schedule (`saw_core::touch::plates::Schedule`, built by `sim2d::schedule` from the board's
//! conversion time and the default plates), never a number typed here.

use std::path::{Path, PathBuf};

use clap::Parser;
use plotters::prelude::*;
use saw_boards::BoardDef;
use saw_core::touch::plates::Phase;

use crate::touch::Overlay;

/// One phase's slot, µs from the frame's start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slot {
    /// Its name (X, Y, Z1, Z2).
    pub phase: &'static str,
    /// Pin switch, µs.
    pub start_us: f64,
    /// Settling, µs.
    pub settle_us: f64,
    /// Conversions, µs.
    pub convert_us: f64,
}

/// One board's touch frame.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameBudget {
    /// The board's name.
    pub board: &'static str,
    /// Conversion time, ns (the board's ADC plan).
    pub conversion_ns: u32,
    /// Conversions summed in each phase.
    pub conversions: [u32; 4],
    /// Conversions discarded at the start of each phase (before the summed ones).
    pub discard: u32,
    /// The phases in order.
    pub slots: [Slot; 4],
    /// The frame, µs.
    pub frame_us: f64,
    /// Readings of each axis per second.
    pub per_axis_hz: u32,
    /// Share of the frame spent settling, ‰.
    pub settle_permille: u32,
}

fn name(p: Phase) -> &'static str {
    match p {
        Phase::X => "X",
        Phase::Y => "Y",
        Phase::Z1 => "Z1",
        Phase::Z2 => "Z2",
    }
}

/// `board`'s frame on `overlay`'s plates, from the core's schedule.
pub fn frame_budget(board: &'static BoardDef, overlay: &Overlay) -> Result<FrameBudget, String> {
    let adc = crate::sim2d::adc_timing(board);
    let s = crate::sim2d::schedule(board, overlay).map_err(|e| e.to_string())?;
    let us = |ns: u64| ns as f64 / 1e3;
    Ok(FrameBudget {
        board: board.name,
        conversion_ns: adc.conversion_ns,
        conversions: s.slots.map(|sl| {
            if sl.phase.is_position() {
                adc.conversions_position
            } else {
                adc.conversions_pressure
            }
        }),
        discard: adc.discard,
        slots: s.slots.map(|sl| Slot {
            phase: name(sl.phase),
            start_us: us(sl.start_ns),
            settle_us: us(sl.settle_ns),
            convert_us: us(sl.convert_ns),
        }),
        frame_us: us(s.frame_ns()),
        per_axis_hz: s.per_axis_rate_hz(),
        settle_permille: s.settle_share_permille(),
    })
}

/// Every board's frame on the default plates.
pub fn budgets() -> Result<Vec<FrameBudget>, String> {
    saw_boards::ALL
        .iter()
        .map(|b| frame_budget(b, &Overlay::default()))
        .collect()
}

/// The line a board's bar is labelled with.
pub fn row_label(b: &FrameBudget) -> String {
    format!(
        "{}: frame {:.1} µs → {} Hz per axis; {} ns a conversion; settling {:.1} % of the frame",
        b.board,
        b.frame_us,
        b.per_axis_hz,
        b.conversion_ns,
        b.settle_permille as f64 / 10.0
    )
}

/// A phase segment's label: its settling, then its conversions as discarded + summed.
pub fn segment_label(s: &Slot, discard: u32, conversions: u32) -> (String, String) {
    (
        format!("{} settle {:.1}", s.phase, s.settle_us),
        format!(
            "{} {}+{}× {:.1}",
            s.phase, discard, conversions, s.convert_us
        ),
    )
}

/// Draws the budgets as a timeline per board: settle (light) then conversions (dark) for each
/// phase, the frame period marked, the per-axis rate in the row's label.
pub fn chart(path: &Path, budgets: &[FrameBudget]) -> Result<(), String> {
    let rows = budgets.len().max(1);
    let root = BitMapBackend::new(path, (1400, 160 + 170 * rows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let longest = budgets.iter().map(|b| b.frame_us).fold(1.0, f64::max);
    let x_max = longest * 1.08;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Touch frame budget per board: each phase settles (light), then converts (dark); \
             one X and one Y per frame",
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(20)
        .build_cartesian_2d(0f64..x_max, 0f64..rows as f64)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .y_labels(0)
        .x_desc("time from the frame's start, µs (core::touch::plates::Schedule, default plates: 1 nF filters)")
        .draw()
        .map_err(|e| e.to_string())?;
    let colours = [
        RGBColor(31, 119, 180),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
    ];
    for (row, b) in budgets.iter().enumerate() {
        // Row 0 at the top.
        let y0 = (rows - 1 - row) as f64 + 0.25;
        let y1 = y0 + 0.4;
        for (i, s) in b.slots.iter().enumerate() {
            let c = colours[i % colours.len()];
            let settle_end = s.start_us + s.settle_us;
            let end = settle_end + s.convert_us;
            if s.settle_us > 0.0 {
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(s.start_us, y0), (settle_end, y1)],
                        c.mix(0.3).filled(),
                    )))
                    .map_err(|e| e.to_string())?;
            }
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(settle_end, y0), (end, y1)],
                    c.filled(),
                )))
                .map_err(|e| e.to_string())?;
            let (settle, convert) = segment_label(s, b.discard, b.conversions[i]);
            let style = ("sans-serif", 13).into_font().color(&BLACK);
            if s.settle_us > 0.0 {
                chart
                    .draw_series(std::iter::once(Text::new(
                        settle,
                        (s.start_us + 0.5, y1 + 0.12),
                        style.clone(),
                    )))
                    .map_err(|e| e.to_string())?;
            }
            // A phase without settling (Z2) has its label above the bar, where a settling label
            // would be: below, it would run into the short Z1 conversions' label.
            let at = if s.settle_us > 0.0 {
                y0 - 0.03
            } else {
                y1 + 0.12
            };
            chart
                .draw_series(std::iter::once(Text::new(
                    convert,
                    (settle_end + 0.5, at),
                    style,
                )))
                .map_err(|e| e.to_string())?;
        }
        // The frame period.
        chart
            .draw_series(LineSeries::new(
                vec![(b.frame_us, y0 - 0.1), (b.frame_us, y1 + 0.1)],
                BLACK.stroke_width(2),
            ))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Text::new(
                row_label(b),
                (0.5, y1 + 0.3),
                ("sans-serif", 16).into_font().color(&BLACK),
            )))
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}

/// `host-sim touch-budget`: the touch frame's phases against its period, per board.
#[derive(Parser, Debug)]
#[command(
    name = "host-sim touch-budget",
    about = "Chart the 4-wire touch frame per board: each phase's settling and conversions \
             (X, Y, Z1, Z2) against the frame period, and the per-axis rate, from the core's \
             touch schedule (docs/touch.md)"
)]
pub struct TouchBudgetArgs {
    /// The chart to write (a .png path).
    #[arg(short = 'o', long = "out", value_name = "PATH", default_value = "out/touch-budget.png", value_parser = png_path)]
    pub out: PathBuf,
}

/// `-o`: a path ending in `.png` (checked at the door).
fn png_path(s: &str) -> Result<PathBuf, String> {
    let p = PathBuf::from(s);
    if p.extension().and_then(|e| e.to_str()) != Some("png") {
        return Err(format!("{s:?} must end in .png"));
    }
    Ok(p)
}

/// `host-sim touch-budget …` from the process's arguments; None for any other command.
pub fn run_from_env() -> Option<std::process::ExitCode> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let (cmd, rest) = args.split_first()?;
    if cmd != "touch-budget" {
        return None;
    }
    let argv = std::iter::once(std::ffi::OsString::from("host-sim touch-budget"))
        .chain(rest.iter().cloned());
    let a = match TouchBudgetArgs::try_parse_from(argv) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    let run = || -> Result<(), String> {
        let b = budgets()?;
        if let Some(dir) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| {
                format!(
                    "-o {}: cannot create {}: {e}",
                    a.out.display(),
                    dir.display()
                )
            })?;
        }
        chart(&a.out, &b)?;
        for x in &b {
            println!("{}", row_label(x));
            for (s, n) in x.slots.iter().zip(x.conversions) {
                println!(
                    "  {:<2} from {:>6.1} µs: settle {:>5.1} µs, {} discarded + {n} summed conversions {:>5.1} µs",
                    s.phase, s.start_us, s.settle_us, x.discard, s.convert_us
                );
            }
        }
        println!("chart: {}", a.out.display());
        Ok(())
    };
    Some(match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use saw_core::touch::plates::{AdcTiming, PlateRc, Schedule};

    /// The chart's figures are the schedule's: every slot, the frame and the rate equal what
    /// `Schedule::new` gives for the board's conversion time (built here from the boards' own
    /// `conversion_ns`, not through `sim2d`), on the default plates and on 10 nF filters; and
    /// the labels drawn carry them.
    #[test]
    fn the_charts_figures_come_from_the_schedule() {
        for board in saw_boards::ALL.iter() {
            for c_filter_pf in [1_000, 10_000] {
                let overlay = Overlay {
                    rc: PlateRc {
                        c_filter_pf,
                        ..PlateRc::DEFAULT
                    },
                    ..Overlay::default()
                };
                let b = frame_budget(board, &overlay).unwrap();
                // The board's acquisition as saw-boards states it, built here field by field.
                let t = saw_boards::touch::touch_adc(board);
                let adc = AdcTiming {
                    conversion_ns: saw_boards::touch::conversion_ns(board),
                    conversions_position: t.conversions_position,
                    conversions_pressure: t.conversions_pressure,
                    discard: t.discard,
                };
                let s = Schedule::new(&overlay.rc, &adc).unwrap();
                for (slot, want) in b.slots.iter().zip(s.slots) {
                    assert_eq!(slot.start_us * 1e3, want.start_ns as f64);
                    assert_eq!(slot.settle_us * 1e3, want.settle_ns as f64);
                    assert_eq!(slot.convert_us * 1e3, want.convert_ns as f64);
                }
                assert_eq!(b.frame_us * 1e3, s.frame_ns() as f64);
                assert_eq!(b.per_axis_hz, s.per_axis_rate_hz());
                let label = row_label(&b);
                assert!(label.contains(&format!("{} Hz per axis", s.per_axis_rate_hz())));
                let (settle, convert) = segment_label(&b.slots[0], 1, 15);
                assert_eq!(
                    settle,
                    format!("X settle {:.1}", s.slots[0].settle_ns as f64 / 1e3)
                );
                assert!(convert.starts_with("X 1+15× "), "{convert}");
            }
        }
        // docs/touch.md's two tested rows (1 discarded + 15 a position phase, 1 + 4 a pressure
        // phase; core's `discarded_conversions_take_their_time_in_the_slot` works them by hand):
        // 3 577 Hz on the F446, 4 550 Hz on the G474.
        let rates: Vec<(&str, u32)> = budgets()
            .unwrap()
            .iter()
            .map(|b| (b.board, b.per_axis_hz))
            .collect();
        assert!(rates.contains(&("nucleo-f446re", 3_577)), "{rates:?}");
        assert!(rates.contains(&("nucleo-g474re", 4_550)), "{rates:?}");
        // Settling then conversions, back to back, to the frame's end.
        for b in budgets().unwrap() {
            let last = b.slots[3];
            assert_eq!(last.start_us + last.settle_us + last.convert_us, b.frame_us);
        }
    }

    #[test]
    fn the_chart_is_written() {
        let dir = std::env::temp_dir().join(format!("touch-budget-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("touch-budget.png");
        chart(&path, &budgets().unwrap()).unwrap();
        assert!(std::fs::metadata(&path).unwrap().len() > 10_000);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
