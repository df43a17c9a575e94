//! The analysis' input: rows read from CSV text — a session CSV of `saw experiment run`, or a
//! lab's own paired-comparison data with columns `subject,first,second,score` — as data. The
//! caller reads the files; this reads text.

use std::fmt;

use serde::Serialize;

/// A paired judgment: `score` in grades, positive = the first presented judged more.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairedRow {
    /// The block (a lab's CSV: its file name).
    pub block: String,
    /// The subject.
    pub subject: String,
    /// The stimulus presented first.
    pub first: String,
    /// The stimulus presented second.
    pub second: String,
    /// The grade.
    pub score: f64,
}

/// A two-interval trial (constant stimuli or a staircase).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IntervalRow {
    /// The block.
    pub block: String,
    /// The subject.
    pub subject: String,
    /// The staircase track (None: constant stimuli).
    pub track: Option<String>,
    /// The trial's number in the session.
    pub trial: u32,
    /// The level.
    pub level: f64,
    /// The comparison's interval chosen.
    pub correct: bool,
    /// A staircase reversal at this trial.
    pub reversal: bool,
}

/// Everything read.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Dataset {
    /// Paired judgments.
    pub paired: Vec<PairedRow>,
    /// Two-interval trials.
    pub intervals: Vec<IntervalRow>,
}

/// A file the analysis cannot read: which, where, why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputError {
    /// The file.
    pub file: String,
    /// 1-based line (0: the file).
    pub line: usize,
    /// The column at fault.
    pub column: String,
    /// The sentence.
    pub message: String,
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use crate::protocol::one_line;
        if self.line == 0 {
            write!(f, "{}: {}", one_line(&self.file), one_line(&self.message))
        } else {
            write!(
                f,
                "{}:{}: {}: {}",
                one_line(&self.file),
                self.line,
                one_line(&self.column),
                one_line(&self.message)
            )
        }
    }
}

impl std::error::Error for InputError {}

/// The columns of a lab's own paired-comparison CSV.
pub const LAB_COLUMNS: [&str; 4] = ["subject", "first", "second", "score"];

/// Reads one CSV's text (named `file` in errors) into `into`.
pub fn read_csv(file: &str, text: &str, into: &mut Dataset) -> Result<(), InputError> {
    let err = |line: usize, column: &str, message: String| InputError {
        file: file.to_string(),
        line,
        column: column.to_string(),
        message,
    };
    let mut r = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(text.as_bytes());
    let headers = r
        .headers()
        .map_err(|e| err(1, "(header)", format!("not CSV: {e}")))?
        .clone();
    let col = |name: &str| headers.iter().position(|h| h.trim() == name);
    // A session CSV is told by the columns only `saw experiment run` writes together; a lab's
    // own file may have a `design` or `block` column of its own.
    let session = ["design", "trial", "target_interval", "response_word"]
        .iter()
        .all(|c| col(c).is_some());
    let need: &[&str] = if session {
        &[
            "subject", "trial", "block", "design", "first", "second", "score", "level", "correct",
            "reversal", "track",
        ]
    } else {
        &LAB_COLUMNS
    };
    for n in need {
        if col(n).is_none() {
            return Err(err(
                1,
                n,
                format!(
                    "the header has no column {n}; a lab's CSV has the columns {} (docs/experiment.md), a session CSV is what `saw experiment run` wrote",
                    LAB_COLUMNS.join(",")
                ),
            ));
        }
    }
    let idx = |n: &str| col(n).unwrap_or(0);
    for (k, rec) in r.records().enumerate() {
        let line = k + 2;
        let rec = rec.map_err(|e| err(line, "(row)", format!("not a CSV row: {e}")))?;
        let get = |n: &str| rec.get(idx(n)).unwrap_or("").trim().to_string();
        let number = |n: &str| -> Result<f64, InputError> {
            let s = get(n);
            match s.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(err(line, n, format!("{s:?} is not a finite number"))),
            }
        };
        let flag = |n: &str, empty_is_false: bool| -> Result<bool, InputError> {
            match get(n).as_str() {
                "1" => Ok(true),
                "0" => Ok(false),
                "" if empty_is_false => Ok(false),
                s => Err(err(line, n, format!("{s:?} is not 0 or 1"))),
            }
        };
        // A lab's file may name blocks in a `block` column; without one the file is a block.
        let block = if col("block").is_some() && !get("block").is_empty() {
            get("block")
        } else {
            file.to_string()
        };
        // Names with line breaks (a quoted field left open) would break every sentence and
        // chart label that quotes them.
        for c in ["subject", "first", "second", "block", "track"] {
            if col(c).is_some() && get(c).chars().any(char::is_control) {
                return Err(err(
                    line,
                    c,
                    format!(
                        "{:?} holds a line break or another control character (an unclosed quote?)",
                        get(c)
                    ),
                ));
            }
        }
        let subject = get("subject");
        if subject.is_empty() {
            return Err(err(
                line,
                "subject",
                "is empty; every row names its subject".into(),
            ));
        }
        let design = if session {
            get("design")
        } else {
            "paired".to_string()
        };
        match design.as_str() {
            "paired" => {
                let (first, second) = (get("first"), get("second"));
                if first.is_empty() || second.is_empty() {
                    return Err(err(
                        line,
                        if first.is_empty() { "first" } else { "second" },
                        "is empty; a paired row names both stimuli".into(),
                    ));
                }
                if first == second {
                    return Err(err(
                        line,
                        "second",
                        format!("\"{second}\" is compared with itself"),
                    ));
                }
                into.paired.push(PairedRow {
                    block,
                    subject,
                    first,
                    second,
                    score: number("score")?,
                });
            }
            "constant" | "staircase" => {
                let track = get("track");
                into.intervals.push(IntervalRow {
                    block,
                    subject,
                    track: (design == "staircase").then_some(track),
                    trial: number("trial")? as u32,
                    level: number("level")?,
                    // A two-interval trial was answered right or wrong: an empty `correct` is
                    // refused, not read as wrong. `reversal` is empty for constant stimuli.
                    correct: flag("correct", false)?,
                    reversal: flag("reversal", true)?,
                });
            }
            other => {
                return Err(err(
                    line,
                    "design",
                    format!("\"{other}\" is not a design (paired, constant, staircase)"),
                ))
            }
        }
    }
    Ok(())
}

/// What a session's sidecar (`<subject>.json` beside its CSV) tells the analysis from the
/// protocol it kept: each block's stimuli in the protocol's order (for correlating two blocks'
/// scales), each paired block's variant, each staircase track's threshold rule. Text that is
/// not a sidecar adds nothing.
pub fn sidecar_options(sidecar_text: &str, into: &mut super::report::Options) {
    use crate::staircase::StepScale;
    let Ok(v) = serde_json::from_str::<serde_json::Value>(sidecar_text) else {
        return;
    };
    let Some(Ok(t)) = v["session"]["protocol_text"]
        .as_str()
        .map(|s| s.parse::<toml::Table>())
    else {
        return;
    };
    for b in t
        .get("block")
        .and_then(|b| b.as_array())
        .into_iter()
        .flatten()
    {
        let Some(block) = b.get("name").and_then(|n| n.as_str()) else {
            continue;
        };
        if let Some(list) = b.get("stimuli").and_then(|s| s.as_array()) {
            into.block_stimuli.insert(
                block.to_string(),
                list.iter()
                    .filter_map(|s| s.as_str().map(str::to_string))
                    .collect(),
            );
        }
        if b.get("design").and_then(|d| d.as_str()) == Some("paired") {
            use super::paired::Variant;
            // The protocol reader's default is Ura's.
            let variant = match b.get("variant").and_then(|v| v.as_str()) {
                Some("scheffe") => Variant::Scheffe,
                Some("haga") => Variant::Haga,
                Some("nakaya") => Variant::Nakaya,
                _ => Variant::Ura,
            };
            into.block_methods.insert(block.to_string(), variant);
        }
        for tr in b
            .get("staircase")
            .and_then(|s| s.as_array())
            .into_iter()
            .flatten()
        {
            let Some(name) = tr.get("name").and_then(|n| n.as_str()) else {
                continue;
            };
            // The protocol reader's defaults: the last 6 reversals, linear steps.
            let last = tr
                .get("threshold_reversals")
                .and_then(|v| v.as_integer())
                .map_or(6, |v| v.max(1) as usize);
            let scale = match tr.get("scale").and_then(|v| v.as_str()) {
                Some("log") => StepScale::Log,
                _ => StepScale::Linear,
            };
            into.track_rules
                .insert((block.to_string(), name.to_string()), (last, scale));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_labs_block_column_splits_blocks_and_a_design_column_is_not_a_session() {
        let mut d = Dataset::default();
        read_csv(
            "lab.csv",
            "subject,block,design,first,second,score\ns1,real,x,a,b,1\ns1,virtual,x,c,d,2\n",
            &mut d,
        )
        .unwrap();
        let blocks: Vec<&str> = d.paired.iter().map(|r| r.block.as_str()).collect();
        assert_eq!(blocks, ["real", "virtual"]);
    }

    #[test]
    fn an_empty_correct_is_refused_for_a_two_interval_row() {
        let head = "subject,subject_index,trial,block,design,track,level,target_interval,first,second,response,response_word,score,correct,reversal\n";
        let mut d = Dataset::default();
        let e = read_csv(
            "s.csv",
            &format!("{head}s,0,0,b,constant,,4,1,x,y,1,first,,,\n"),
            &mut d,
        )
        .unwrap_err();
        assert_eq!((e.line, e.column.as_str()), (2, "correct"), "{e}");
        read_csv(
            "s.csv",
            &format!("{head}s,0,0,b,constant,,4,1,x,y,1,first,,1,\n"),
            &mut d,
        )
        .unwrap();
        assert!(d.intervals[0].correct && !d.intervals[0].reversal);
    }

    #[test]
    fn a_labs_csv_is_read_and_its_mistakes_located() {
        let mut d = Dataset::default();
        read_csv(
            "lab.csv",
            "subject,first,second,score\ns1,a,b,2\ns1,b,a,-1.5\n",
            &mut d,
        )
        .unwrap();
        assert_eq!(d.paired.len(), 2);
        assert_eq!(d.paired[1].score, -1.5);
        assert_eq!(d.paired[0].block, "lab.csv");

        let e = read_csv("lab.csv", "subject,first,second,score\ns1,a,b,x\n", &mut d).unwrap_err();
        assert_eq!((e.line, e.column.as_str()), (2, "score"), "{e}");
        let e = read_csv(
            "lab.csv",
            "subject,first,second,score\ns1,a,b,NaN\n",
            &mut d,
        )
        .unwrap_err();
        assert!(e.to_string().contains("not a finite number"), "{e}");
        let e = read_csv("lab.csv", "subject,first,score\n", &mut d).unwrap_err();
        assert_eq!(e.column, "second", "{e}");
        let e = read_csv("lab.csv", "subject,first,second,score\ns1,a,a,1\n", &mut d).unwrap_err();
        assert!(e.to_string().contains("compared with itself"), "{e}");
    }
}
