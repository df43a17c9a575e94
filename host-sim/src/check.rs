//! `host-sim check FILE…`: reads scene files as a board would take them (the reader and the
//! controller's dry run, as `host-sim --scene`, `saw push` and `SAW_SCENE` read them) and says,
//! per file and board, what the scene is or why it is refused, without running anything.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use saw_boards::BoardDef;
use saw_core::scene_file::{self, SensorKind};

/// Check scene files against the boards, 1D or 2D, without running them: one line per file and
/// board, `ok` with what the scene is, or the refusal at its file:line:col. Exit 0 when every
/// file is taken by every board checked, 1 when any is refused.
#[derive(Parser, Debug)]
#[command(name = "host-sim check")]
pub struct CheckArgs {
    /// Scene files (TOML, docs/scenes.md).
    #[arg(value_name = "FILE", required = true)]
    pub files: Vec<PathBuf>,
    /// Only this board (default: every board the firmware supports).
    #[arg(long, value_parser = crate::cli::board_parser())]
    pub board: Option<&'static BoardDef>,
}

/// One file on one board: what the scene is, or the refusal.
pub fn check(file: &str, text: &str, board: &'static BoardDef) -> Result<String, String> {
    let kind = scene_file::sensor_of(file, text).map_err(|e| e.to_string())?;
    match kind {
        SensorKind::Rheostat => {
            let c = scene_file::load_for_board(
                file,
                text,
                crate::sim::burst_timer(board),
                crate::sim::sample_period_us(board),
            )
            .map_err(|e| e.to_string())?;
            let n = c.scene.textures.len();
            let lines = c.scene.lines.positions_um.len();
            Ok(format!(
                "1D, {n} region{} and {lines} line{} over {} mm of travel",
                if n == 1 { "" } else { "s" },
                if lines == 1 { "" } else { "s" },
                c.calibration.length_um as f64 / 1e3
            ))
        }
        SensorKind::FourWire => {
            let frame_us = crate::sim2d::board_frame_period_us(board)
                .ok_or_else(|| format!("{file}: {} reads no 4-wire overlay", board.name))?;
            let c =
                scene_file::load_2d_for_board(file, text, crate::sim::burst_timer(board), frame_us)
                    .map_err(|e| e.to_string())?;
            let (w, h) = scene_file::plate_um_of(file, text).map_err(|e| e.to_string())?;
            let n = c.scene.windows.len();
            let sides: usize = c
                .scene
                .windows
                .iter()
                .filter(|w| w.edge)
                .map(|w| w.outline.vertices.len())
                .sum();
            let edges = sides + c.scene.free_edges.len();
            Ok(format!(
                "2D, {n} window{} and {edges} edge{} on a {} x {} mm plate ({frame_us} µs frames)",
                if n == 1 { "" } else { "s" },
                if edges == 1 { "" } else { "s" },
                w as f64 / 1e3,
                h as f64 / 1e3
            ))
        }
        // A sensor this build does not know: the reader names it.
        #[allow(unreachable_patterns)]
        _ => Err(format!("{file}: a sensor this host-sim does not read")),
    }
}

/// `host-sim check …`, or None for another command.
pub fn run_from_env() -> Option<ExitCode> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let (cmd, rest) = args.split_first()?;
    if cmd != "check" {
        return None;
    }
    let argv =
        std::iter::once(std::ffi::OsString::from("host-sim check")).chain(rest.iter().cloned());
    let a = match CheckArgs::try_parse_from(argv) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    let boards: Vec<&'static BoardDef> = match a.board {
        Some(b) => vec![b],
        None => saw_boards::ALL.iter().collect(),
    };
    let mut refused = false;
    for path in &a.files {
        let file = path.display().to_string();
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) => {
                println!("{file}: refused: cannot read it: {e}");
                refused = true;
                continue;
            }
        };
        for board in &boards {
            match check(&file, &text, board) {
                Ok(what) => println!("{file}: ok on {}: {what}", board.name),
                Err(e) => {
                    println!("{file}: refused on {}: {e}", board.name);
                    refused = true;
                }
            }
        }
    }
    Some(if refused {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}
