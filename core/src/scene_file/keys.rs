//! The keys each table of a scene file takes, read from the parser's own serde structs (the list
//! `deny_unknown_fields` checks against), and the sentence for a key that is none of them: the
//! nearest key by edit distance ("did you mean"), else a short list — the keys of that table, or
//! of that region's kind — rather than all 25 region keys.

extern crate std;

use std::format;
use std::string::String;
use std::vec::Vec as StdVec;

use serde::de::{self, Deserialize, Deserializer, Visitor};

use super::spec::{self, File, Limits, LinesSpec, RegionSpec, Substrate};
use super::spec2d::{
    BackgroundSpec, EdgeSpec, EdgesSpec, File2d, ScreenSpec, SensorSpec, WindowSpec,
};

/// The tables a scene file has, by the names docs/scenes.md gives them.
pub const TABLES: [&str; 5] = ["top", "substrate", "limits", "region", "lines"];

/// The tables of a 2D scene file (issue #36) besides `limits`, which it shares with 1D files,
/// by the names docs/scenes.md gives them.
pub const TABLES_2D: [&str; 7] = [
    "2d.top",
    "2d.sensor",
    "2d.screen",
    "2d.background",
    "2d.window",
    "2d.edge",
    "2d.edges",
];

/// The keys table `table` takes (one of [`TABLES`] or [`TABLES_2D`]), as the parser's struct declares them; None
/// for a name that is no table.
pub fn keys(table: &str) -> Option<&'static [&'static str]> {
    Some(match table {
        "top" => fields_of::<File>(),
        "substrate" => fields_of::<Substrate>(),
        "limits" => fields_of::<Limits>(),
        "region" => fields_of::<RegionSpec>(),
        "lines" => fields_of::<LinesSpec>(),
        "2d.top" => fields_of::<File2d>(),
        "2d.sensor" => fields_of::<SensorSpec>(),
        "2d.screen" => fields_of::<ScreenSpec>(),
        "2d.background" => fields_of::<BackgroundSpec>(),
        "2d.window" => fields_of::<WindowSpec>(),
        "2d.edge" => fields_of::<EdgeSpec>(),
        "2d.edges" => fields_of::<EdgesSpec>(),
        _ => return None,
    })
}

/// The field names serde's derive hands `deserialize_struct`: asked of a deserializer that only
/// records them, so the list is the derive's own and cannot drift from the struct.
fn fields_of<'de, T: Deserialize<'de>>() -> &'static [&'static str] {
    let mut seen: &'static [&'static str] = &[];
    let _ = T::deserialize(FieldNames(&mut seen));
    seen
}

struct FieldNames<'a>(&'a mut &'static [&'static str]);

/// Only a probe's way out: [`FieldNames`] never produces a value.
#[derive(Debug)]
struct Probed;

impl core::fmt::Display for Probed {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("field names probed")
    }
}

impl std::error::Error for Probed {}

impl de::Error for Probed {
    fn custom<T: core::fmt::Display>(_: T) -> Self {
        Probed
    }
}

impl<'de> Deserializer<'de> for FieldNames<'_> {
    type Error = Probed;

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Probed> {
        Err(Probed)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Probed> {
        *self.0 = fields;
        Err(Probed)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
        ignored_any
    }
}

/// The key of `candidates` nearest `typed`, if near enough to be a slip: the same key with its
/// unit left off (`duty` for `duty_percent`), or within one edit in three characters (at least
/// one, at most three: `f_b_hx` → `f_b_hz`, `wavelenght_mm` → `wavelength_mm`).
pub(super) fn nearest<'a>(typed: &str, candidates: &[&'a str]) -> Option<&'a str> {
    if let Some(k) = candidates.iter().find(|k| {
        k.strip_prefix(typed)
            .is_some_and(|rest| rest.starts_with('_'))
    }) {
        return Some(k);
    }
    let limit = (typed.chars().count() / 3).clamp(1, 3);
    candidates
        .iter()
        .map(|k| (strsim::damerau_levenshtein(typed, k), *k))
        .filter(|(d, _)| *d <= limit)
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

/// `a`, `a` and `b`, or `a`, `b` and `c`, each backticked.
fn listed(keys: &[&str]) -> String {
    let ticked: StdVec<String> = keys.iter().map(|k| format!("`{k}`")).collect();
    match ticked.split_last() {
        None => String::new(),
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
    }
}

/// The backticked words of `text`, in order.
fn ticked(text: &str) -> StdVec<&str> {
    text.split('`').skip(1).step_by(2).collect()
}

/// The sentence for serde's "unknown field `x`, expected …" or "unknown variant `x`, expected
/// …" (`message`), or None for any other message. `region_kind` is the kind of the region the
/// key is in, when it is in one.
pub(super) fn unknown(message: &str, region_kind: Option<&str>) -> Option<String> {
    let (what, rest) = if let Some(rest) = message.strip_prefix("unknown field ") {
        ("key", rest)
    } else if let Some(rest) = message.strip_prefix("unknown variant ") {
        ("value", rest)
    } else {
        return None;
    };
    let (typed, expected) = rest.split_once(", expected")?;
    let typed = ticked(typed).first().copied()?;
    let expected = ticked(expected);
    // A 2D scene's table in a file read as 1D: the file does not name its sensor.
    if what == "key"
        && keys("top").is_some_and(|k| k == expected.as_slice())
        && keys("2d.top").is_some_and(|k| k.contains(&typed))
    {
        return Some(format!(
            "unknown key `{typed}`: `{typed}` is a 2D scene's table, and a file without \
             `[sensor]` is a 1D scene for the rheostat: add `[sensor] kind = \"4-wire\"` for \
             the touch overlay"
        ));
    }
    let kind_keys = region_kind
        .and_then(|k| spec::kind_fields(k).map(|f| (k, f)))
        .filter(|_| what == "key" && keys("region").is_some_and(|r| r == expected.as_slice()));
    // A region's key: its own kind's keys first, then any region key (the next refusal then
    // says which kind takes it).
    let near = kind_keys
        .and_then(|(_, f)| {
            let own: StdVec<&str> = ["kind", "until_mm"].iter().chain(f).copied().collect();
            nearest(typed, &own)
        })
        .or_else(|| nearest(typed, &expected));
    if let Some(k) = near {
        return Some(format!("unknown {what} `{typed}`: did you mean `{k}`?"));
    }
    if what == "value" {
        return Some(format!(
            "unknown value `{typed}`: it must be {}",
            listed(&expected).replacen(" and ", " or ", 1)
        ));
    }
    let table = TABLES
        .iter()
        .chain(TABLES_2D.iter())
        .find(|t| keys(t).is_some_and(|k| k == expected.as_slice()));
    Some(match (table, kind_keys) {
        (_, Some((kind, f))) => {
            let own: StdVec<&str> = ["kind", "until_mm"].iter().chain(f).copied().collect();
            // "an `off` region", "a `constant` region".
            let a = if kind.starts_with(['a', 'e', 'i', 'o', 'u']) {
                "an"
            } else {
                "a"
            };
            format!(
                "unknown key `{typed}`: {a} `{kind}` region takes {} (docs/scenes.md lists every \
                 kind's keys)",
                listed(&own)
            )
        }
        (Some(&"region"), None) => format!(
            "unknown key `{typed}`: a region takes `kind`, `until_mm` and its kind's keys \
             (docs/scenes.md)"
        ),
        (Some(&"top"), _) => format!(
            "unknown key `{typed}`: the top level takes {}",
            listed(&expected)
        ),
        (Some(&"2d.top"), _) => format!(
            "unknown key `{typed}`: the top level of a 2D scene takes {}",
            listed(&expected)
        ),
        // A texture table: the 25 keys are too many to list; the kinds' are in the docs.
        (Some(&"2d.window"), _) => format!(
            "unknown key `{typed}`: a window takes `rect_mm` or `polygon_mm`, `outline`, \
             `kind`, its kind's keys as a region's and, for a grating, `ridge_angle_deg` \
             (docs/scenes.md)"
        ),
        (Some(&"2d.background"), _) => format!(
            "unknown key `{typed}`: the background takes `kind`, its kind's keys as a \
             region's and, for a grating, `ridge_angle_deg` (docs/scenes.md)"
        ),
        (Some(&"2d.edge"), _) => format!(
            "unknown key `{typed}`: [[edge]] takes {}",
            listed(&expected)
        ),
        (Some(t), _) => format!(
            "unknown key `{typed}`: [{}] takes {}",
            t.trim_start_matches("2d."),
            listed(&expected)
        ),
        (None, _) => format!("unknown key `{typed}`: expected {}", listed(&expected)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_takes_slips_and_leaves_strangers() {
        let region = keys("region").unwrap();
        assert_eq!(nearest("f_b_hx", region), Some("f_b_hz"));
        assert_eq!(nearest("wavelenght_mm", region), Some("wavelength_mm"));
        assert_eq!(nearest("duty", region), Some("duty_percent"));
        assert_eq!(nearest("untill_mm", region), Some("until_mm"));
        assert_eq!(nearest("colour", region), None);
        assert_eq!(nearest("frequency", region), None);
        assert_eq!(nearest("min_speed", region), Some("min_speed_mm_s"));
        // One edit in three characters: 2 edits in 5 is too far, 1 in 8 near.
        assert_eq!(nearest("speed", &["seed"]), Some("seed"));
        assert_eq!(nearest("spees", &["seed"]), None);
        assert_eq!(nearest("pulse_us", &["pulse_ms"]), Some("pulse_ms"));
        // Two edits in ten characters (two letters dropped): near (⌊10 / 3⌋ = 3 allowed).
        assert_eq!(nearest("duty_prcnt", region), Some("duty_percent"));
    }

    #[test]
    fn the_tables_keys_are_the_structs_fields() {
        assert_eq!(
            keys("substrate").unwrap(),
            [
                "length_mm",
                "code_at_start",
                "code_at_end",
                "rail_margin_code"
            ]
        );
        assert_eq!(keys("region").unwrap().len(), 25);
        assert_eq!(keys("nope"), None);
    }

    /// An unknown value is matched against the choice's values only, never against the keys of
    /// the region it is written in (`rearm` would be `rearm_mm`'s unit left off).
    #[test]
    fn an_unknown_value_is_no_key() {
        let serde = "unknown variant `rearm`, expected one of `position`, `hybrid`, `velocity`";
        assert_eq!(
            unknown(serde, Some("grating")).unwrap(),
            "unknown value `rearm`: it must be `position`, `hybrid` or `velocity`"
        );
        assert_eq!(unknown("invalid type: string", Some("grating")), None);
    }

    #[test]
    fn lists_read_as_english() {
        assert_eq!(listed(&["a"]), "`a`");
        assert_eq!(listed(&["a", "b"]), "`a` and `b`");
        assert_eq!(listed(&["a", "b", "c"]), "`a`, `b` and `c`");
    }
}
