//! A stream written as CSV: one row per record, each with the board's time, the host's time it
//! maps to, the scene in force and the change count; and the counts a run's summary reports.
//! `saw stream` and `saw session` share it.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use saw_link::client::{Client, ClientError};
use saw_link::clock::{Alignment, Ping};
use saw_link::msg::{Fault2d, Header, Record, Record2d, Stream, Stream2d};
use serde_json::{json, Value};

use crate::{scene_hex, Failure};

/// The columns, in order (docs/link.md, "Records").
pub const CSV_HEADER: &str =
    "time_us,host_time_us,scene_id,change,position_um,velocity_um_s,region,f_b_hz,bursting,fault";

/// A record's CSV row; `host_us`: the host time its board time maps to.
pub fn csv_line(r: &Record, host_us: u64) -> String {
    let opt = |v: Option<i32>| v.map_or(String::new(), |v| v.to_string());
    format!(
        "{},{},{},{},{},{},{},{},{},{}",
        r.time_us,
        host_us,
        scene_hex(r.scene_id),
        r.change,
        opt(r.position_um),
        opt(r.velocity_um_s),
        r.region.map_or(String::new(), |v| v.to_string()),
        r.burst_millihz as f64 / 1000.0,
        u8::from(r.bursting),
        r.fault.map_or(String::new(), |f| format!("{f:?}"))
    )
}

/// The columns of a 2D board's records (issue #36; docs/link.md, "Records").
pub const CSV_HEADER_2D: &str = "time_us,host_time_us,scene_id,change,x_um,y_um,vx_um_s,vy_um_s,window,edge,f_b_hz,bursting,lifted,fault";

/// A 2D record's CSV row. `window`: the window's index, `background`, or empty while nothing
/// renders (lifted, landing, a fault).
pub fn csv_line_2d(r: &Record2d, host_us: u64) -> String {
    use saw_core::plane::Place;
    let opt = |v: Option<i32>| v.map_or(String::new(), |v| v.to_string());
    format!(
        "{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        r.time_us,
        host_us,
        scene_hex(r.scene_id),
        r.change,
        opt(r.position.map(|p| p.x_um)),
        opt(r.position.map(|p| p.y_um)),
        opt(r.velocity_um_s.map(|v| v.0)),
        opt(r.velocity_um_s.map(|v| v.1)),
        match r.place {
            Some(Place::Window(i)) => i.to_string(),
            Some(Place::Background) => "background".into(),
            None => String::new(),
        },
        r.edge.map_or(String::new(), |e| e.to_string()),
        r.burst_millihz as f64 / 1000.0,
        u8::from(r.bursting),
        u8::from(r.lifted),
        r.fault.map_or(String::new(), fault_2d_name)
    )
}

/// A 2D fault as the CSV names it: `RailLow-x`, `RailHigh-y`, `Stale`.
pub fn fault_2d_name(f: Fault2d) -> String {
    match f {
        Fault2d::Rail { y_axis, fault } => {
            format!("{fault:?}-{}", if y_axis { "y" } else { "x" })
        }
        Fault2d::Stale => "Stale".into(),
        other => format!("{other:?}"),
    }
}

/// Round trips taken in a burst for an alignment: the quickest of them is fitted.
pub const PINGS: usize = 8;

/// `n` pings, `gap` apart.
pub fn pings<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    n: usize,
    gap: Duration,
) -> Result<Vec<Ping>, ClientError> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        if i > 0 && !gap.is_zero() {
            std::thread::sleep(gap);
        }
        out.push(client.ping()?);
    }
    Ok(out)
}

/// An alignment as JSON: the board's boot on the host's clock, the drift, the error bound.
pub fn alignment_json(a: &Alignment) -> Value {
    json!({
        "board_boot_host_us": a.host_us(0).round(),
        "drift_ppm": a.drift_ppm(),
        "drift_error_ppm": a.drift_error_ppm(),
        "error_us": a.error_us,
        "span_us": a.span_us,
    })
}

/// Records to a CSV file, counting as it goes.
pub struct Recorder {
    out: std::io::BufWriter<std::fs::File>,
    name: String,
    /// Board time → host time: from the pings before the stream (offset; the drift is
    /// measured after, and reported).
    pub align: Alignment,
    /// Records written.
    pub records: u64,
    /// Stream frames read.
    pub frames: u64,
    /// Frames missing from the numbering (lost on the line).
    pub frames_lost: u64,
    last_seq: Option<u32>,
    /// Board time of the first and last record written, µs.
    pub span_us: Option<(u64, u64)>,
    /// Scene changes seen in the stream (the change count stepping between records).
    pub changes: u64,
    last_change: Option<u32>,
    /// The board runs 2D scenes: its records are [`Record2d`]s.
    plane: bool,
}

impl Recorder {
    /// A new CSV file at `path` with its header (`plane`: a 2D board's columns).
    pub fn create(path: &Path, align: Alignment, plane: bool) -> Result<Self, Failure> {
        let name = path.display().to_string();
        let file = std::fs::File::create(path)
            .map_err(|e| Failure::input(format!("--csv {name}: {e}")))?;
        let mut r = Self {
            out: std::io::BufWriter::new(file),
            name,
            align,
            records: 0,
            frames: 0,
            frames_lost: 0,
            last_seq: None,
            span_us: None,
            changes: 0,
            last_change: None,
            plane,
        };
        let header = if plane { CSV_HEADER_2D } else { CSV_HEADER };
        writeln!(r.out, "{header}").map_err(|e| r.io(e))?;
        Ok(r)
    }

    fn io(&self, e: std::io::Error) -> Failure {
        Failure::input(format!("--csv {}: {e}", self.name))
    }

    /// Writes a frame's records.
    pub fn write(&mut self, h: &Header, s: &Stream) -> Result<(), Failure> {
        self.frame(h);
        for r in &s.records {
            let host_us = self.align.host_us(r.time_us).round().max(0.0) as u64;
            self.row(&csv_line(r, host_us), r.time_us, r.change)?;
        }
        Ok(())
    }

    /// Writes a 2D frame's records.
    pub fn write_2d(&mut self, h: &Header, s: &Stream2d) -> Result<(), Failure> {
        self.frame(h);
        for r in &s.records {
            let host_us = self.align.host_us(r.time_us).round().max(0.0) as u64;
            self.row(&csv_line_2d(r, host_us), r.time_us, r.change)?;
        }
        Ok(())
    }

    fn frame(&mut self, h: &Header) {
        if let Some(prev) = self.last_seq {
            self.frames_lost += h.seq.wrapping_sub(prev).saturating_sub(1) as u64;
        }
        self.last_seq = Some(h.seq);
        self.frames += 1;
    }

    fn row(&mut self, line: &str, time_us: u64, change: u32) -> Result<(), Failure> {
        if let Err(e) = writeln!(self.out, "{line}") {
            return Err(self.io(e));
        }
        self.records += 1;
        self.span_us = Some(match self.span_us {
            Some((first, _)) => (first, time_us),
            None => (time_us, time_us),
        });
        if self.last_change.is_some_and(|c| c != change) {
            self.changes += 1;
        }
        self.last_change = Some(change);
        Ok(())
    }

    /// Reads and writes stream frames until `deadline`.
    pub fn drain_until<P: std::io::Read + std::io::Write>(
        &mut self,
        client: &mut Client<P>,
        deadline: Instant,
    ) -> Result<(), Failure> {
        if self.plane {
            while let Some((h, s)) = client.next_stream_2d(deadline)? {
                self.write_2d(&h, &s)?;
            }
        } else {
            while let Some((h, s)) = client.next_stream(deadline)? {
                self.write(&h, &s)?;
            }
        }
        Ok(())
    }

    /// Flushes the file.
    pub fn finish(&mut self) -> Result<(), Failure> {
        self.out.flush().map_err(|e| self.io(e))
    }

    /// The board time the records span, s.
    pub fn span_s(&self) -> f64 {
        self.span_us
            .map_or(0.0, |(a, b)| b.saturating_sub(a) as f64 * 1e-6)
    }
}
