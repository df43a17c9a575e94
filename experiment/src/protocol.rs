//! Protocol files (TOML): the stimuli, the design of each block, the response scale and the
//! timing, checked at the door like scene files — a refusal is `file:line:col: field: sentence`.
//!
//! The format is documented in docs/experiment.md ("Protocol files"); `experiments/` holds the
//! seed paper's study as a shipped protocol.

use std::collections::BTreeMap;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::staircase::{StaircaseSpec, StepScale};

/// A protocol file refused: where, which field, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProtocolError {
    /// The file's name as given.
    pub file: String,
    /// 1-based line (0: the file as a whole).
    pub line: usize,
    /// 1-based column.
    pub column: usize,
    /// The field at fault, as a path (`block[1].variant`).
    pub field: String,
    /// What is wrong: a sentence naming the value and the rule.
    pub message: String,
}

impl fmt::Display for ProtocolError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (field, message) = (one_line(&self.field), one_line(&self.message));
        if self.line == 0 {
            write!(f, "{}: {field}: {message}", one_line(&self.file))
        } else {
            write!(
                f,
                "{}:{}:{}: {field}: {message}",
                one_line(&self.file),
                self.line,
                self.column
            )
        }
    }
}

/// `text` on one line: line breaks and other control characters a file's value may hold are
/// written as escapes (`\n`), so an error quoting the value stays one line.
pub fn one_line(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

impl std::error::Error for ProtocolError {}

/// Scheffé's paired comparison in the variant a block uses (who judges which pairs, and
/// whether the order of presentation is an effect of its own).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PairedVariant {
    /// Scheffé (1952): order matters; each subject judges one ordered pair.
    Scheffe,
    /// Ura (1958): order matters; every subject judges every ordered pair.
    Ura,
    /// Haga: no order effect; each subject judges one pair, in one order.
    Haga,
    /// Nakaya (1970): no order effect; every subject judges every unordered pair once.
    Nakaya,
}

impl PairedVariant {
    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Scheffe => "scheffe",
            Self::Ura => "ura",
            Self::Haga => "haga",
            Self::Nakaya => "nakaya",
        }
    }
}

/// How a stimulus is put in front of the participant.
#[derive(Clone, Debug, PartialEq)]
pub enum StimulusSource {
    /// A scene for the board: the scene file's text (a file the protocol names, or one built
    /// from an inline region over the base scene's substrate and limits).
    Scene {
        /// Where it came from, for messages (`stimulus[0].region` or the file's path).
        origin: String,
        /// The scene file's text.
        text: String,
        /// An inline region's table (the staircase varies one of its keys).
        region: Option<toml::Table>,
    },
    /// An object the experimenter hands over (a sandpaper): the board's RF is off meanwhile.
    External {
        /// What the experimenter is told.
        prompt: String,
        /// For the simulated participant only: the object's mean radius of projections, µm
        /// (its stick-slip frequency stands for f_b).
        beta_um: Option<f64>,
    },
}

/// A stimulus with its name.
#[derive(Clone, Debug, PartialEq)]
pub struct Stimulus {
    /// The name responses and analyses use.
    pub name: String,
    /// How it is presented.
    pub source: StimulusSource,
}

/// The design of one block.
#[derive(Clone, Debug, PartialEq)]
pub enum Design {
    /// Paired comparisons of `stimuli` (indices into [`Protocol::stimuli`]) by `variant`,
    /// every pair the variant asks for `repeats` times.
    Paired {
        /// The variant.
        variant: PairedVariant,
        /// The stimuli compared.
        stimuli: Vec<usize>,
        /// How many times each pair is judged per subject.
        repeats: u32,
    },
    /// The method of constant stimuli: two intervals, the standard and the standard with
    /// `vary` raised by a level; every level `repeats` times in random order.
    Constant {
        /// The standard (an inline-region stimulus).
        standard: usize,
        /// The region key the level is added to (`f_b_hz`, `wavelength_mm`, …).
        vary: String,
        /// The levels, in the key's unit.
        levels: Vec<f64>,
        /// Presentations of each level.
        repeats: u32,
    },
    /// Transformed up-down staircases (interleaved when more than one): two intervals as
    /// [`Design::Constant`], the level set by each track.
    Staircase {
        /// The standard (an inline-region stimulus).
        standard: usize,
        /// The region key the level is added to.
        vary: String,
        /// The tracks.
        tracks: Vec<StaircaseSpec>,
    },
}

impl Design {
    /// The design's name in files and in the CSV.
    pub fn name(&self) -> &'static str {
        match self {
            Design::Paired { .. } => "paired",
            Design::Constant { .. } => "constant",
            Design::Staircase { .. } => "staircase",
        }
    }
}

/// A block of trials.
#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    /// Its name.
    pub name: String,
    /// Its design.
    pub design: Design,
    /// The question asked after each trial (the protocol's when the block sets none).
    pub question: String,
    /// The response words: for paired comparisons an odd number of grades, the middle one
    /// "no difference"; for two-interval designs exactly two (first, second interval).
    pub words: Vec<String>,
}

/// Timing of a trial.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// How long each stimulus is explored, s.
    pub explore_s: f64,
    /// The pause between the stimuli of a trial and between trials, s (RF off meanwhile when
    /// `rf_off_between`).
    pub pause_s: f64,
    /// The carrier off between stimuli (the board runs an `off` scene).
    pub rf_off_between: bool,
}

/// A protocol, checked.
#[derive(Clone, Debug, PartialEq)]
pub struct Protocol {
    /// The file's name as given.
    pub file: String,
    /// The experiment's name.
    pub name: String,
    /// The seed every order derives from (with the subject's id).
    pub seed: u64,
    /// Shown before the first trial.
    pub instructions: String,
    /// The stimuli.
    pub stimuli: Vec<Stimulus>,
    /// The blocks, in the order of the first subject.
    pub blocks: Vec<Block>,
    /// Rotate the block order across subjects (subject n starts at block n mod blocks).
    pub counterbalance_blocks: bool,
    /// A break (the participant continues when ready) after every this many trials; 0: only
    /// between blocks.
    pub break_every: u32,
    /// Timing.
    pub timing: Timing,
    /// The scene the board runs while RF is off (between stimuli, during external stimuli).
    pub off_scene: String,
    /// The protocol's text, kept with the session so a log says exactly what was run.
    pub text: String,
}

// ---- the file as written ----

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileSpec {
    experiment: Spanned<ExperimentSpec>,
    #[serde(default)]
    timing: Option<Spanned<TimingSpec>>,
    #[serde(default)]
    response: Option<Spanned<ResponseSpec>>,
    #[serde(default)]
    board: Option<Spanned<BoardSpec>>,
    #[serde(default)]
    stimulus: Vec<Spanned<StimulusSpec>>,
    #[serde(default)]
    block: Vec<Spanned<BlockSpec>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ExperimentSpec {
    name: Spanned<String>,
    seed: Spanned<i64>,
    #[serde(default)]
    instructions: Option<String>,
    #[serde(default)]
    counterbalance_blocks: Option<bool>,
    #[serde(default)]
    break_every: Option<Spanned<i64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TimingSpec {
    #[serde(default)]
    explore_s: Option<Spanned<f64>>,
    #[serde(default)]
    pause_s: Option<Spanned<f64>>,
    #[serde(default)]
    rf_off_between: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ResponseSpec {
    #[serde(default)]
    question: Option<String>,
    #[serde(default)]
    words: Option<Spanned<Vec<String>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BoardSpec {
    /// The scene whose substrate, limits and drive inline regions run on.
    #[serde(default)]
    scene: Option<Spanned<String>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StimulusSpec {
    name: Spanned<String>,
    #[serde(default)]
    scene: Option<Spanned<String>>,
    #[serde(default)]
    region: Option<Spanned<toml::Table>>,
    #[serde(default)]
    external: Option<Spanned<String>>,
    #[serde(default)]
    beta_um: Option<Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BlockSpec {
    name: Spanned<String>,
    design: Spanned<String>,
    #[serde(default)]
    variant: Option<Spanned<String>>,
    #[serde(default)]
    stimuli: Option<Spanned<Vec<Spanned<String>>>>,
    #[serde(default)]
    repeats: Option<Spanned<i64>>,
    #[serde(default)]
    standard: Option<Spanned<String>>,
    #[serde(default)]
    vary: Option<Spanned<String>>,
    #[serde(default)]
    levels: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    question: Option<String>,
    #[serde(default)]
    words: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    staircase: Vec<Spanned<TrackSpec>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TrackSpec {
    name: Spanned<String>,
    start: Spanned<f64>,
    #[serde(default)]
    down: Option<Spanned<i64>>,
    #[serde(default)]
    up: Option<Spanned<i64>>,
    steps: Spanned<Vec<f64>>,
    #[serde(default)]
    scale: Option<Spanned<String>>,
    min: Spanned<f64>,
    max: Spanned<f64>,
    #[serde(default)]
    max_trials: Option<Spanned<i64>>,
    #[serde(default)]
    max_reversals: Option<Spanned<i64>>,
    #[serde(default)]
    threshold_reversals: Option<Spanned<i64>>,
}

/// The default question and words of paired comparisons: five grades, as the seed paper's
/// evaluation ("the difference of the roughness of the pairs in five grades").
pub const PAIRED_WORDS: [&str; 5] = [
    "second much rougher",
    "second rougher",
    "no difference",
    "first rougher",
    "first much rougher",
];
/// The default words of two-interval designs.
pub const INTERVAL_WORDS: [&str; 2] = ["first", "second"];

/// Exploration windows allowed, s.
pub const EXPLORE_S: Range<f64> = 0.05..600.0;
/// Pauses allowed, s.
pub const PAUSE_S: Range<f64> = 0.0..600.0;

/// Where a file's relative paths are read from, and how they are read (tests give a map).
pub trait Files {
    /// The text of `path`, or the error's sentence.
    fn read(&self, path: &Path) -> Result<String, String>;
}

/// The file system, relative to the protocol's directory.
pub struct Disk(pub PathBuf);

impl Files for Disk {
    fn read(&self, path: &Path) -> Result<String, String> {
        let p = self.0.join(path);
        std::fs::read_to_string(&p).map_err(|e| format!("cannot read {}: {e}", p.display()))
    }
}

/// Reads a protocol file from disk: its relative scene paths from its directory.
pub fn load(path: &Path) -> Result<Protocol, ProtocolError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| ProtocolError {
        file: file.clone(),
        line: 0,
        column: 0,
        field: "(file)".into(),
        message: format!("cannot be read: {e}"),
    })?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    parse(&file, &text, &Disk(dir))
}

struct Cx<'a> {
    file: &'a str,
    text: &'a str,
}

impl Cx<'_> {
    fn err(&self, span: Range<usize>, field: &str, message: impl fmt::Display) -> ProtocolError {
        let start = span.start.min(self.text.len());
        let before = &self.text[..start];
        ProtocolError {
            file: self.file.to_string(),
            line: before.matches('\n').count() + 1,
            column: start - before.rfind('\n').map(|i| i + 1).unwrap_or(0) + 1,
            field: field.to_string(),
            message: message.to_string(),
        }
    }

    fn range(
        &self,
        v: &Spanned<f64>,
        field: &str,
        unit: &str,
        r: Range<f64>,
    ) -> Result<f64, ProtocolError> {
        let x = *v.get_ref();
        if !x.is_finite() || x < r.start || x >= r.end {
            return Err(self.err(
                v.span(),
                field,
                format_args!(
                    "{x} {unit} is outside the allowed {} to {} {unit}",
                    r.start, r.end
                ),
            ));
        }
        Ok(x)
    }

    fn count(&self, v: &Spanned<i64>, field: &str, lo: i64, hi: i64) -> Result<u32, ProtocolError> {
        let x = *v.get_ref();
        if x < lo || x > hi {
            return Err(self.err(
                v.span(),
                field,
                format_args!("{x} is outside the allowed {lo} to {hi}"),
            ));
        }
        Ok(x as u32)
    }
}

/// Parses and checks a protocol; `file` names it in errors, `files` reads the scene files it
/// names.
pub fn parse(file: &str, text: &str, files: &dyn Files) -> Result<Protocol, ProtocolError> {
    let cx = Cx { file, text };
    let spec: FileSpec = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        // toml's message is several lines with a caret drawing; its first line of prose is
        // the sentence.
        let msg = e.message().lines().next().unwrap_or("").to_string();
        cx.err(span, "(file)", msg)
    })?;

    let ex = spec.experiment.get_ref();
    let name = ex.name.get_ref().trim().to_string();
    if name.is_empty() {
        return Err(cx.err(ex.name.span(), "experiment.name", "must not be empty"));
    }
    let seed = *ex.seed.get_ref();
    if seed < 0 {
        return Err(cx.err(
            ex.seed.span(),
            "experiment.seed",
            format_args!("{seed} is negative; a seed is a whole number from 0"),
        ));
    }
    let break_every = match &ex.break_every {
        Some(b) => cx.count(b, "experiment.break_every", 0, 10_000)?,
        None => 0,
    };

    let timing = {
        let t = spec.timing.as_ref().map(|t| t.get_ref());
        let explore_s = match t.and_then(|t| t.explore_s.as_ref()) {
            Some(v) => cx.range(v, "timing.explore_s", "s", EXPLORE_S)?,
            None => 4.0,
        };
        let pause_s = match t.and_then(|t| t.pause_s.as_ref()) {
            Some(v) => cx.range(v, "timing.pause_s", "s", PAUSE_S)?,
            None => 1.0,
        };
        Timing {
            explore_s,
            pause_s,
            rf_off_between: t.and_then(|t| t.rf_off_between).unwrap_or(true),
        }
    };

    let (question, words) = match &spec.response {
        Some(r) => (r.get_ref().question.clone(), r.get_ref().words.clone()),
        None => (None, None),
    };

    // The base scene inline regions run on: its substrate, limits, drive and hysteresis.
    let base_text = match spec.board.as_ref().and_then(|b| b.get_ref().scene.as_ref()) {
        Some(p) => files
            .read(Path::new(p.get_ref()))
            .map_err(|e| cx.err(p.span(), "board.scene", e))?,
        None => DEFAULT_BASE.to_string(),
    };
    let base: toml::Table = toml::from_str(&base_text).map_err(|e| {
        cx.err(
            spec.board.as_ref().map_or(0..0, |b| b.span()),
            "board.scene",
            format_args!("is not a scene file: {}", e.message()),
        )
    })?;
    let off_scene = scene_with_region(&base, &off_region());

    let mut stimuli: Vec<Stimulus> = Vec::new();
    for (i, s) in spec.stimulus.iter().enumerate() {
        let sp = s.get_ref();
        let field = |k: &str| format!("stimulus[{i}].{k}");
        let name = sp.name.get_ref().trim().to_string();
        if name.is_empty() {
            return Err(cx.err(sp.name.span(), &field("name"), "must not be empty"));
        }
        if name.contains(['\n', '\r', '"']) {
            return Err(cx.err(
                sp.name.span(),
                &field("name"),
                format_args!(
                    "{name:?} holds a quote or a line break, which the CSV cannot keep whole"
                ),
            ));
        }
        if let Some(j) = stimuli.iter().position(|o| o.name == name) {
            return Err(cx.err(
                sp.name.span(),
                &field("name"),
                format_args!("\"{name}\" is already the name of stimulus[{j}]; names must differ"),
            ));
        }
        let given = [
            sp.scene.is_some(),
            sp.region.is_some(),
            sp.external.is_some(),
        ];
        if given.iter().filter(|g| **g).count() != 1 {
            return Err(cx.err(
                s.span(),
                &format!("stimulus[{i}]"),
                format_args!(
                    "\"{name}\" must give exactly one of scene (a scene file), region (an inline region) or external (an object handed over)"
                ),
            ));
        }
        if let (Some(b), None) = (&sp.beta_um, &sp.external) {
            return Err(cx.err(
                b.span(),
                &field("beta_um"),
                "only an external stimulus has a projection radius (the board's own give their f_b)",
            ));
        }
        let source = if let Some(p) = &sp.scene {
            let text = files
                .read(Path::new(p.get_ref()))
                .map_err(|e| cx.err(p.span(), &field("scene"), e))?;
            check_scene(&text).map_err(|e| cx.err(p.span(), &field("scene"), e))?;
            StimulusSource::Scene {
                origin: p.get_ref().clone(),
                text,
                region: None,
            }
        } else if let Some(r) = &sp.region {
            let text = scene_with_region(&base, r.get_ref());
            check_scene(&text).map_err(|e| cx.err(r.span(), &field("region"), e))?;
            StimulusSource::Scene {
                origin: field("region"),
                text,
                region: Some(r.get_ref().clone()),
            }
        } else if let Some(e) = &sp.external {
            let beta_um = match &sp.beta_um {
                Some(b) => Some(cx.range(b, &field("beta_um"), "µm", 1.0..10_000.0)?),
                None => None,
            };
            StimulusSource::External {
                prompt: e.get_ref().clone(),
                beta_um,
            }
        } else {
            unreachable!("exactly one source was checked above")
        };
        stimuli.push(Stimulus { name, source });
    }
    if stimuli.is_empty() {
        return Err(whole(
            file,
            "stimulus",
            "the protocol has no [[stimulus]]; a design needs at least two",
        ));
    }
    let index_of = |n: &Spanned<String>, field: &str| -> Result<usize, ProtocolError> {
        stimuli
            .iter()
            .position(|s| &s.name == n.get_ref())
            .ok_or_else(|| {
                let known: Vec<&str> = stimuli.iter().map(|s| s.name.as_str()).collect();
                cx.err(
                    n.span(),
                    field,
                    format_args!(
                        "\"{}\" is not a stimulus of this file (they are: {})",
                        n.get_ref(),
                        known.join(", ")
                    ),
                )
            })
    };

    let mut blocks = Vec::new();
    for (i, b) in spec.block.iter().enumerate() {
        let bp = b.get_ref();
        let field = |k: &str| format!("block[{i}].{k}");
        let design_name = bp.design.get_ref().as_str();
        let block_name = bp.name.get_ref().trim();
        if block_name.is_empty() {
            return Err(cx.err(bp.name.span(), &field("name"), "must not be empty"));
        }
        if let Some(j) = spec.block[..i]
            .iter()
            .position(|o| o.get_ref().name.get_ref().trim() == block_name)
        {
            return Err(cx.err(
                bp.name.span(),
                &field("name"),
                format_args!("\"{block_name}\" is already the name of block[{j}]; the analysis tells blocks apart by name"),
            ));
        }
        let repeats = match &bp.repeats {
            Some(r) => cx.count(r, &field("repeats"), 1, 100)?,
            None => 1,
        };
        // Keys a design does not read are refused, not ignored: a misplaced key is a mistake.
        let not_for = |present: bool, key: &str, span: Range<usize>| -> Result<(), ProtocolError> {
            if present {
                Err(cx.err(
                    span,
                    &field(key),
                    format_args!("a {design_name} block has no {key}"),
                ))
            } else {
                Ok(())
            }
        };
        let design = match design_name {
            "paired" => {
                not_for(
                    bp.standard.is_some(),
                    "standard",
                    bp.standard.as_ref().map_or(0..0, |s| s.span()),
                )?;
                not_for(
                    bp.vary.is_some(),
                    "vary",
                    bp.vary.as_ref().map_or(0..0, |s| s.span()),
                )?;
                not_for(
                    bp.levels.is_some(),
                    "levels",
                    bp.levels.as_ref().map_or(0..0, |s| s.span()),
                )?;
                not_for(
                    !bp.staircase.is_empty(),
                    "staircase",
                    bp.staircase.first().map_or(0..0, |s| s.span()),
                )?;
                let variant = match &bp.variant {
                    None => PairedVariant::Ura,
                    Some(v) => match v.get_ref().as_str() {
                        "scheffe" => PairedVariant::Scheffe,
                        "ura" => PairedVariant::Ura,
                        "haga" => PairedVariant::Haga,
                        "nakaya" => PairedVariant::Nakaya,
                        other => {
                            return Err(cx.err(
                                v.span(),
                                &field("variant"),
                                format_args!("\"{other}\" is not a variant; it is one of scheffe, ura, haga, nakaya"),
                            ))
                        }
                    },
                };
                let list = bp.stimuli.as_ref().ok_or_else(|| {
                    cx.err(
                        b.span(),
                        &field("stimuli"),
                        "a paired block names its stimuli (at least two)",
                    )
                })?;
                let mut idx: Vec<usize> = Vec::new();
                for (j, n) in list.get_ref().iter().enumerate() {
                    let k = index_of(n, &format!("block[{i}].stimuli[{j}]"))?;
                    if idx.contains(&k) {
                        return Err(cx.err(
                            n.span(),
                            &format!("block[{i}].stimuli[{j}]"),
                            format_args!("\"{}\" is listed twice", n.get_ref()),
                        ));
                    }
                    idx.push(k);
                }
                if idx.len() < 2 {
                    return Err(cx.err(
                        list.span(),
                        &field("stimuli"),
                        format_args!(
                            "{} stimulus listed; paired comparisons need at least two",
                            idx.len()
                        ),
                    ));
                }
                if idx.len() > 20 {
                    return Err(cx.err(
                        list.span(),
                        &field("stimuli"),
                        format_args!(
                            "{} stimuli listed; at most 20 (380 ordered pairs)",
                            idx.len()
                        ),
                    ));
                }
                {
                    // The variants' analyses have no replication within a subject: a second
                    // judgment of a pair by one subject is refused by the analysis, so it is
                    // refused here, before anyone is asked.
                    if let (Some(r), true) = (&bp.repeats, repeats > 1) {
                        return Err(cx.err(
                            r.span(),
                            &field("repeats"),
                            format_args!("{repeats} for a paired block: each subject judges each pair once in Scheffé's method and its variants; more judgments come from more subjects"),
                        ));
                    }
                    Design::Paired {
                        variant,
                        stimuli: idx,
                        repeats,
                    }
                }
            }
            "constant" | "staircase" => {
                not_for(
                    bp.variant.is_some(),
                    "variant",
                    bp.variant.as_ref().map_or(0..0, |s| s.span()),
                )?;
                not_for(
                    bp.stimuli.is_some(),
                    "stimuli",
                    bp.stimuli.as_ref().map_or(0..0, |s| s.span()),
                )?;
                let std_name = bp.standard.as_ref().ok_or_else(|| {
                    cx.err(
                        b.span(),
                        &field("standard"),
                        format_args!(
                            "a {design_name} block names its standard (an inline-region stimulus)"
                        ),
                    )
                })?;
                let standard = index_of(std_name, &field("standard"))?;
                let region = match &stimuli[standard].source {
                    StimulusSource::Scene { region: Some(r), .. } => r.clone(),
                    _ => {
                        return Err(cx.err(std_name.span(), &field("standard"), format_args!("\"{}\" is not an inline region; a level is added to one of a region's keys", std_name.get_ref())))
                    }
                };
                let vary_given = bp.vary.as_ref();
                if let Some(v) =
                    vary_given.filter(|v| ["until_mm", "kind"].contains(&v.get_ref().as_str()))
                {
                    return Err(cx.err(
                        v.span(),
                        &field("vary"),
                        format_args!("{} cannot be varied: a stimulus' region covers the whole travel and keeps its kind; vary one of its texture's numbers (such as f_b_hz)", v.get_ref()),
                    ));
                }
                let vary = bp.vary.as_ref().ok_or_else(|| {
                    cx.err(
                        b.span(),
                        &field("vary"),
                        "names the standard's region key the level is added to (such as f_b_hz)",
                    )
                })?;
                let base_value = match region.get(vary.get_ref()) {
                    Some(toml::Value::Float(f)) => *f,
                    Some(toml::Value::Integer(n)) => *n as f64,
                    _ => {
                        return Err(cx.err(vary.span(), &field("vary"), format_args!("the standard \"{}\" has no number {}; the level is added to a number the region gives", std_name.get_ref(), vary.get_ref())))
                    }
                };
                // Every level the block can reach must make a scene the board accepts:
                // checked here at the extremes, not found out mid-session.
                let probe =
                    |level: f64, span: Range<usize>, f: &str| -> Result<(), ProtocolError> {
                        let mut r = region.clone();
                        r.insert(
                            vary.get_ref().clone(),
                            toml::Value::Float(base_value + level),
                        );
                        check_scene(&scene_with_region(&base, &r)).map_err(|e| {
                            cx.err(
                                span,
                                f,
                                format_args!(
                                    "at level {level} the standard's {} would be {}: {e}",
                                    vary.get_ref(),
                                    base_value + level
                                ),
                            )
                        })
                    };
                if design_name == "constant" {
                    not_for(
                        !bp.staircase.is_empty(),
                        "staircase",
                        bp.staircase.first().map_or(0..0, |s| s.span()),
                    )?;
                    let levels = bp.levels.as_ref().ok_or_else(|| {
                        cx.err(
                            b.span(),
                            &field("levels"),
                            "a constant block lists its levels (at least two)",
                        )
                    })?;
                    if levels.get_ref().len() < 2 {
                        return Err(cx.err(levels.span(), &field("levels"), format_args!("{} level listed; the method of constant stimuli needs at least two", levels.get_ref().len())));
                    }
                    for l in levels.get_ref() {
                        if !l.is_finite() {
                            return Err(cx.err(
                                levels.span(),
                                &field("levels"),
                                format_args!("{l} is not a number"),
                            ));
                        }
                        probe(*l, levels.span(), &field("levels"))?;
                    }
                    Design::Constant {
                        standard,
                        vary: vary.get_ref().clone(),
                        levels: levels.get_ref().clone(),
                        repeats,
                    }
                } else {
                    not_for(
                        bp.levels.is_some(),
                        "levels",
                        bp.levels.as_ref().map_or(0..0, |s| s.span()),
                    )?;
                    not_for(
                        bp.repeats.is_some(),
                        "repeats",
                        bp.repeats.as_ref().map_or(0..0, |s| s.span()),
                    )?;
                    if bp.staircase.is_empty() {
                        return Err(cx.err(
                            b.span(),
                            &field("staircase"),
                            "a staircase block has at least one [[block.staircase]] track",
                        ));
                    }
                    let mut tracks: Vec<StaircaseSpec> = Vec::new();
                    for (k, t) in bp.staircase.iter().enumerate() {
                        let tf = |key: &str| format!("block[{i}].staircase[{k}].{key}");
                        let spec = track(&cx, t, &tf)?;
                        if tracks.iter().any(|o| o.name == spec.name) {
                            return Err(cx.err(
                                t.get_ref().name.span(),
                                &tf("name"),
                                format_args!("\"{}\" names two tracks of this block", spec.name),
                            ));
                        }
                        probe(spec.min, t.get_ref().min.span(), &tf("min"))?;
                        probe(spec.max, t.get_ref().max.span(), &tf("max"))?;
                        tracks.push(spec);
                    }
                    Design::Staircase {
                        standard,
                        vary: vary.get_ref().clone(),
                        tracks,
                    }
                }
            }
            other => {
                return Err(cx.err(
                    bp.design.span(),
                    &field("design"),
                    format_args!(
                        "\"{other}\" is not a design; it is one of paired, constant, staircase"
                    ),
                ))
            }
        };
        let words: Vec<String> = match bp.words.as_ref().or(words.as_ref()) {
            Some(w) => w.get_ref().clone(),
            None => match design {
                Design::Paired { .. } => PAIRED_WORDS.iter().map(|s| s.to_string()).collect(),
                _ => INTERVAL_WORDS.iter().map(|s| s.to_string()).collect(),
            },
        };
        if let Some(k) = words.iter().position(|w| w.trim().is_empty()) {
            let (span, key) = match bp.words.as_ref().or(words_span(&spec)) {
                Some(w) => (
                    w.span(),
                    if bp.words.is_some() {
                        field("words")
                    } else {
                        "response.words".into()
                    },
                ),
                None => (b.span(), field("words")),
            };
            return Err(cx.err(
                span,
                &key,
                format_args!(
                    "word {} is empty; every response needs a word the participant reads",
                    k + 1
                ),
            ));
        }
        let words_span = bp
            .words
            .as_ref()
            .or(words_span(&spec))
            .map_or(b.span(), |w| w.span());
        let words_field = if bp.words.is_some() {
            field("words")
        } else {
            "response.words".into()
        };
        match design {
            Design::Paired { .. }
                if words.len() < 3 || words.len() % 2 == 0 || words.len() > 11 =>
            {
                return Err(cx.err(words_span, &words_field, format_args!("{} words for block \"{}\": paired grades are an odd number from 3 to 11, the middle one no difference; a block sets its own with words = [...]", words.len(), bp.name.get_ref())));
            }
            Design::Constant { .. } | Design::Staircase { .. } if words.len() != 2 => {
                return Err(cx.err(words_span, &words_field, format_args!("{} words for block \"{}\": a two-interval block answers with two (the first interval, the second); a block sets its own with words = [...]", words.len(), bp.name.get_ref())));
            }
            _ => {}
        }
        let question = bp
            .question
            .clone()
            .or(question.clone())
            .unwrap_or_else(|| match design {
                Design::Paired { .. } => "Which was rougher, and by how much?".to_string(),
                _ => "Which interval felt different?".to_string(),
            });
        blocks.push(Block {
            name: bp.name.get_ref().clone(),
            design,
            question,
            words,
        });
    }
    if blocks.is_empty() {
        return Err(whole(
            file,
            "block",
            "the protocol has no [[block]]; there is nothing to run",
        ));
    }

    Ok(Protocol {
        file: file.to_string(),
        name,
        seed: seed as u64,
        instructions: ex.instructions.clone().unwrap_or_default(),
        stimuli,
        blocks,
        counterbalance_blocks: ex.counterbalance_blocks.unwrap_or(true),
        break_every,
        timing,
        off_scene,
        text: text.to_string(),
    })
}

/// An error about the file as a whole (no line to point at).
fn whole(file: &str, field: &str, message: &str) -> ProtocolError {
    ProtocolError {
        file: file.to_string(),
        line: 0,
        column: 0,
        field: field.to_string(),
        message: message.to_string(),
    }
}

fn words_span(spec: &FileSpec) -> Option<&Spanned<Vec<String>>> {
    spec.response
        .as_ref()
        .and_then(|r| r.get_ref().words.as_ref())
}

fn track(
    cx: &Cx<'_>,
    t: &Spanned<TrackSpec>,
    f: &dyn Fn(&str) -> String,
) -> Result<StaircaseSpec, ProtocolError> {
    let tp = t.get_ref();
    let whole = |v: &Option<Spanned<i64>>,
                 key: &str,
                 lo: i64,
                 hi: i64|
     -> Result<Option<u32>, ProtocolError> {
        v.as_ref().map(|v| cx.count(v, &f(key), lo, hi)).transpose()
    };
    let finite = |v: &Spanned<f64>, key: &str| -> Result<f64, ProtocolError> {
        let x = *v.get_ref();
        if x.is_finite() {
            Ok(x)
        } else {
            Err(cx.err(v.span(), &f(key), format_args!("{x} is not a number")))
        }
    };
    let scale = match &tp.scale {
        None => StepScale::Linear,
        Some(s) => match s.get_ref().as_str() {
            "linear" => StepScale::Linear,
            "log" => StepScale::Log,
            other => {
                return Err(cx.err(
                    s.span(),
                    &f("scale"),
                    format_args!("\"{other}\" is not a step scale; it is linear or log"),
                ))
            }
        },
    };
    // A track stopped only by reversals may never stop (answered right at its floor, it never
    // turns): a trial limit is required.
    if tp.max_trials.is_none() {
        return Err(cx.err(
            t.span(),
            &f("max_trials"),
            "is missing: every track needs a trial limit (a track stopped only by reversals may never stop); max_reversals may stop it sooner",
        ));
    }
    let spec = StaircaseSpec {
        name: tp.name.get_ref().clone(),
        start: finite(&tp.start, "start")?,
        down: whole(&tp.down, "down", 1, 10)?.unwrap_or(2),
        up: whole(&tp.up, "up", 1, 10)?.unwrap_or(1),
        steps: tp.steps.get_ref().clone(),
        scale,
        min: finite(&tp.min, "min")?,
        max: finite(&tp.max, "max")?,
        max_trials: whole(&tp.max_trials, "max_trials", 1, 10_000)?,
        max_reversals: whole(&tp.max_reversals, "max_reversals", 1, 1_000)?,
        threshold_reversals: whole(&tp.threshold_reversals, "threshold_reversals", 1, 1_000)?
            .unwrap_or(6),
    };
    if let Some(maxr) = spec.max_reversals {
        if spec.threshold_reversals > maxr {
            // At the threshold's count when written, else at the limit (the count's default
            // is 6).
            let (span, key) = match (&tp.threshold_reversals, &tp.max_reversals) {
                (Some(t), _) => (t.span(), "threshold_reversals"),
                (None, Some(m)) => (m.span(), "max_reversals"),
                (None, None) => (t.span(), "max_reversals"),
            };
            return Err(cx.err(
                span,
                &f(key),
                format_args!(
                    "the threshold averages the last {} reversals, more than max_reversals = {maxr}: the track would stop before it has them",
                    spec.threshold_reversals
                ),
            ));
        }
    }
    // The staircase's own rules (steps, bounds, a stopping rule), at the track's table.
    spec.check()
        .map_err(|e| cx.err(t.span(), &f("(track)").replace(".(track)", ""), e))?;
    Ok(spec)
}

/// The region the board runs while RF is off.
fn off_region() -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("kind".into(), toml::Value::String("off".into()));
    t
}

/// The base scene with its regions and lines replaced by one region over the whole travel.
pub fn scene_with_region(base: &toml::Table, region: &toml::Table) -> String {
    let mut scene = base.clone();
    scene.remove("lines");
    let mut r = region.clone();
    r.remove("until_mm");
    scene.insert(
        "region".into(),
        toml::Value::Array(vec![toml::Value::Table(r)]),
    );
    toml::to_string(&scene).unwrap_or_default()
}

/// A scene checked as every supported board checks it (the reader, then the controller's
/// compile with the board's burst timer): a stimulus no board would run is refused here, not
/// found out mid-session. The sentence on refusal.
fn check_scene(text: &str) -> Result<(), String> {
    for b in saw_boards::ALL {
        let timer = saw_core::burst::BurstTimer {
            clock_hz: b.burst_timer_clk_hz,
            counter_bits: b.burst_timer_bits,
            max_burst_hz: b.max_burst_hz,
        };
        let config = saw_core::scene_file::load_for_board(
            "(region)",
            text,
            timer,
            1_000_000 / b.sample_rate_hz,
        )
        .map_err(|e| format!("{} (on the {})", e.message, b.name))?;
        // A constant burst longer than the on-time cap is played shorter, not refused, by the
        // board (its log warns): as a stimulus it would not be the one the protocol names.
        for t in config.scene.textures.iter() {
            if let saw_core::texture::Texture::Constant(c) = t {
                let f_b_hz = c.burst_millihz as f64 / 1000.0;
                let on_ms = c.duty_permille as f64 / 10.0 / 100.0 / f_b_hz * 1000.0;
                let cap_ms = config.limits.max_on_time_us as f64 / 1000.0;
                if c.burst_millihz > 0 && on_ms > cap_ms {
                    return Err(format!(
                        "f_b {f_b_hz} Hz at {} % duty is a burst of {on_ms:.0} ms, over the scene's on-time cap of {cap_ms} ms: the board would play a shorter one ({:.1} % duty); lower the duty, raise f_b or the cap",
                        c.duty_permille as f64 / 10.0,
                        cap_ms / 1000.0 * f_b_hz * 100.0
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The substrate, limits and drive of the built-in default scene (scenes/default.toml): the
/// base of inline regions when a protocol names no `[board] scene`.
const DEFAULT_BASE: &str = include_str!("../../scenes/default.toml");

/// The stimuli by name.
impl Protocol {
    /// The index of the stimulus called `name`.
    pub fn stimulus(&self, name: &str) -> Option<usize> {
        self.stimuli.iter().position(|s| s.name == name)
    }

    /// The scene text of a two-interval block's comparison at `level`: the standard's region
    /// with its varied key raised by `level`.
    pub fn comparison_scene(&self, standard: usize, vary: &str, level: f64) -> Option<String> {
        let StimulusSource::Scene {
            region: Some(r), ..
        } = &self.stimuli.get(standard)?.source
        else {
            return None;
        };
        let base_value = match r.get(vary)? {
            toml::Value::Float(f) => *f,
            toml::Value::Integer(n) => *n as f64,
            _ => return None,
        };
        let mut r = r.clone();
        r.insert(vary.to_string(), toml::Value::Float(base_value + level));
        let base: toml::Table = toml::from_str(self.base_text()).ok()?;
        Some(scene_with_region(&base, &r))
    }

    /// The base scene's text (the off scene carries its substrate and limits).
    fn base_text(&self) -> &str {
        &self.off_scene
    }
}

/// A map of file names to texts, for tests and for protocols held in memory.
pub struct InMemory(pub BTreeMap<String, String>);

impl Files for InMemory {
    fn read(&self, path: &Path) -> Result<String, String> {
        self.0
            .get(&path.display().to_string())
            .cloned()
            .ok_or_else(|| format!("no file {}", path.display()))
    }
}
