//! A stream written as CSV: one row per record, each with the board's time, the host's time it
//! maps to, the scene in force and the change count; and the counts a run's summary reports.
//! `saw stream` and `saw session` share it.

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use saw_link::client::{Client, ClientError};
use saw_link::clock::{Alignment, Ping};
use saw_link::msg::{Header, Record, Stream};
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
}

impl Recorder {
    /// A new CSV file at `path` with its header.
    pub fn create(path: &Path, align: Alignment) -> Result<Self, Failure> {
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
        };
        writeln!(r.out, "{CSV_HEADER}").map_err(|e| r.io(e))?;
        Ok(r)
    }

    fn io(&self, e: std::io::Error) -> Failure {
        Failure::input(format!("--csv {}: {e}", self.name))
    }

    /// Writes a frame's records.
    pub fn write(&mut self, h: &Header, s: &Stream) -> Result<(), Failure> {
        if let Some(prev) = self.last_seq {
            self.frames_lost += h.seq.wrapping_sub(prev).saturating_sub(1) as u64;
        }
        self.last_seq = Some(h.seq);
        self.frames += 1;
        for r in &s.records {
            let host_us = self.align.host_us(r.time_us).round().max(0.0) as u64;
            if let Err(e) = writeln!(self.out, "{}", csv_line(r, host_us)) {
                return Err(self.io(e));
            }
            self.records += 1;
            self.span_us = Some(match self.span_us {
                Some((first, _)) => (first, r.time_us),
                None => (r.time_us, r.time_us),
            });
            if self.last_change.is_some_and(|c| c != r.change) {
                self.changes += 1;
            }
            self.last_change = Some(r.change);
        }
        Ok(())
    }

    /// Reads and writes stream frames until `deadline`.
    pub fn drain_until<P: std::io::Read + std::io::Write>(
        &mut self,
        client: &mut Client<P>,
        deadline: Instant,
    ) -> Result<(), Failure> {
        while let Some((h, s)) = client.next_stream(deadline)? {
            self.write(&h, &s)?;
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
