//! docs/scenes.md cannot drift from the parser: the keys each of its tables lists are the keys
//! the parser accepts there, read from the parser itself (`scene_file::keys`, its serde structs'
//! field lists, and which keys each region kind refuses), never from a copy in this test.

use std::collections::BTreeSet;

use saw_core::scene_file::{keys, parse, TABLES};

const DOC: &str = include_str!("../../docs/scenes.md");

/// The backticked first-column keys of the table after `<!-- keys: NAME -->`.
fn doc_keys(name: &str) -> BTreeSet<String> {
    let marker = format!("<!-- keys: {name} -->");
    let start = DOC
        .find(&marker)
        .unwrap_or_else(|| panic!("docs/scenes.md has no `{marker}`"));
    DOC[start + marker.len()..]
        .lines()
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| {
            let cell = l.trim_start_matches('|').split('|').next()?.trim();
            cell.strip_prefix('`')?
                .strip_suffix('`')
                .map(str::to_string)
        })
        .collect()
}

/// The keys the parser takes in table `name`: `scene_file::keys`, the field list of the
/// parser's own serde struct (what `deny_unknown_fields` checks a key against).
fn parser_keys(name: &str) -> BTreeSet<String> {
    keys(name)
        .unwrap_or_else(|| panic!("the parser has no table `{name}`"))
        .iter()
        .map(|k| k.to_string())
        .collect()
}

const REGION: &str = "[[region]]\nkind = \"off\"\n";

#[test]
fn every_table_lists_exactly_the_keys_the_parser_accepts() {
    assert_eq!(TABLES, ["top", "substrate", "limits", "region", "lines"]);
    for name in TABLES {
        let parser = parser_keys(name);
        let mut doc = doc_keys(name);
        if name == "region" {
            // The region table lists the keys every kind has; each kind's table the rest.
            for kind in KINDS {
                doc.extend(doc_keys(&format!("region.{kind}")));
            }
        }
        assert_eq!(
            doc, parser,
            "docs/scenes.md `{name}` keys (left) differ from the parser's (right)"
        );
        // And the parser refuses a key outside that list in that table.
        let probe = match name {
            "top" => format!("zzz_unknown = 1\n{REGION}"),
            "region" => format!("{REGION}zzz_unknown = 1\n"),
            "lines" => format!("{REGION}[lines]\nzzz_unknown = 1\n"),
            _ => format!("[{name}]\nzzz_unknown = 1\n{REGION}"),
        };
        let e = parse("probe.toml", &probe).unwrap_err();
        assert!(
            e.message.starts_with("unknown key `zzz_unknown`"),
            "{name}: {e}"
        );
    }
}

const KINDS: [&str; 5] = ["off", "constant", "grating", "material", "random"];

/// Whether kind `kind` takes `key` (the parser refuses a key of another kind by name).
fn kind_takes(kind: &str, key: &str) -> bool {
    let value = match key {
        "render" => "\"position\"",
        "seed" => "1",
        _ => "1.0",
    };
    let text = format!("[[region]]\nkind = \"{kind}\"\n{key} = {value}\n");
    match parse("probe.toml", &text) {
        Ok(_) => true,
        Err(e) => !e
            .message
            .contains(&format!("`{key}` is not a field of kind `{kind}`")),
    }
}

#[test]
fn each_kind_takes_exactly_the_keys_its_table_lists() {
    let region = parser_keys("region");
    let common = doc_keys("region");
    // Every kind's documented keys come from the parser's region keys.
    let mut kinds_seen = BTreeSet::new();
    for kind in KINDS {
        let doc = doc_keys(&format!("region.{kind}"));
        let takes: BTreeSet<String> = region
            .iter()
            .filter(|k| !common.contains(*k))
            .filter(|k| kind_takes(kind, k))
            .cloned()
            .collect();
        assert_eq!(doc, takes, "kind `{kind}`: docs (left) vs parser (right)");
        kinds_seen.insert(kind);
    }
    // And the kinds are the parser's kinds.
    let e = parse("probe.toml", "[[region]]\nkind = \"zzz\"\n").unwrap_err();
    let listed: BTreeSet<&str> = e
        .message
        .split_once("expected one of ")
        .unwrap()
        .1
        .split(", ")
        .map(str::trim)
        .collect();
    assert_eq!(kinds_seen, listed, "{e}");
}

/// The table's rows: key and range cell.
fn doc_rows(name: &str) -> Vec<(String, String)> {
    let marker = format!("<!-- keys: {name} -->");
    let start = DOC.find(&marker).unwrap();
    DOC[start + marker.len()..]
        .lines()
        .skip(3)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.trim_matches('|').split('|').map(str::trim).collect();
            (cells[0].trim_matches('`').to_string(), cells[2].to_string())
        })
        .collect()
}

/// `LO to HI` at the start of a range cell, when both are plain numbers.
fn numeric_range(cell: &str) -> Option<(f64, f64)> {
    let head = cell.split([';', ',', '(']).next()?.trim();
    let (lo, hi) = head.split_once(" to ")?;
    let num = |s: &str| s.replace(' ', "").parse::<f64>().ok();
    Some((num(lo)?, num(hi)?))
}

/// A minimal valid file with `key = value` in table `name`.
fn probe(name: &str, key: &str, value: f64) -> String {
    let v = format!("{value:?}");
    match name {
        "top" => format!("{key} = {v}\n{REGION}"),
        "substrate" => {
            let mut t = String::from("[substrate]\n");
            for (k, d) in [
                ("length_mm", "63.0"),
                ("code_at_start", "1310"),
                ("code_at_end", "64225"),
            ] {
                if k != key {
                    t += &format!("{k} = {d}\n");
                }
            }
            // The codes are integers in the file.
            let v = if key.starts_with("code") || key.starts_with("rail") {
                format!("{}", value as i64)
            } else {
                v
            };
            format!("{t}{key} = {v}\n{REGION}")
        }
        "limits" => format!("[limits]\n{key} = {v}\n{REGION}"),
        "lines" => {
            let base = if key == "positions_mm" {
                String::new()
            } else {
                "positions_mm = [10]\n".into()
            };
            format!("{REGION}[lines]\n{base}{key} = {v}\n")
        }
        kind => {
            let kind = kind.trim_start_matches("region.");
            // What each kind cannot do without, as in scenes/*.toml.
            const EQ12: [(&str, &str); 7] = [
                ("e_object_pa", "2.0e9"),
                ("nu_object", "0.35"),
                ("e_skin_pa", "1.0e6"),
                ("nu_skin", "0.49"),
                ("sigma_um", "10.0"),
                ("beta_um", "80.0"),
                ("shear_strength_diff_pa", "3.0e3"),
            ];
            let needs: Vec<(&str, &str)> = match kind {
                "constant" | "random" => vec![("f_b_hz", "1.0")],
                "grating" => vec![("wavelength_mm", "1.0")],
                "material" if EQ12.iter().any(|(k, _)| *k == key) => EQ12.to_vec(),
                "material" => vec![("delta_mu", "1.0")],
                _ => vec![],
            };
            let base: String = needs
                .iter()
                .filter(|(k, _)| *k != key)
                .map(|(k, d)| format!("{k} = {d}\n"))
                .collect();
            format!("[[region]]\nkind = \"{kind}\"\n{base}{key} = {v}\n")
        }
    }
}

/// Whether the parser refuses `value` for `key` (an error naming that field).
fn refused(name: &str, key: &str, value: f64) -> Option<String> {
    let text = probe(name, key, value);
    match parse("probe.toml", &text) {
        Ok(_) => None,
        Err(e) if e.field.ends_with(key) => Some(e.to_string()),
        // Refused by a later check (eq. 12's result out of range at an extreme input): this
        // field's own range let the value through.
        Err(e) if e.field.ends_with("delta_mu") => None,
        Err(e) => panic!("probe for `{key}` = {value} refused for another reason: {e}\n{text}"),
    }
}

/// Every plain `LO to HI` range in the doc is the parser's: both ends accepted, just outside
/// refused, naming the field.
#[test]
fn documented_ranges_are_the_parsers() {
    let mut checked = 0;
    for name in [
        "top",
        "substrate",
        "limits",
        "lines",
        "region.constant",
        "region.grating",
        "region.material",
        "region.random",
    ] {
        for (key, cell) in doc_rows(name) {
            // u64 seed: its top is not an f64; the codes' top is u16::MAX.
            let Some((lo, hi)) = numeric_range(&cell).filter(|_| key != "seed") else {
                continue;
            };
            let step = |x: f64| if x.abs() >= 1.0 { x.abs() * 1e-3 } else { 1e-4 };
            assert_eq!(
                refused(name, &key, lo),
                None,
                "{name}.{key} = {lo} (docs: {cell})"
            );
            assert_eq!(
                refused(name, &key, hi),
                None,
                "{name}.{key} = {hi} (docs: {cell})"
            );
            let above = if key.starts_with("code") {
                hi + 1.0
            } else {
                hi + step(hi)
            };
            assert!(
                refused(name, &key, above).is_some(),
                "{name}.{key} = {above} accepted (docs: {cell})"
            );
            if lo > 0.0 {
                assert!(
                    refused(name, &key, lo - step(lo).min(lo / 2.0)).is_some(),
                    "{name}.{key} below {lo} accepted (docs: {cell})"
                );
            } else {
                assert!(
                    refused(name, &key, -1.0).is_some(),
                    "{name}.{key} = -1 accepted (docs: {cell})"
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 25, "only {checked} ranges checked");
}
