//! Abuse of the machine description from outside: every shipped machine file, mutated one
//! key at a time (dropped, wrong type, zero, negative, huge, NaN, ±inf), goes through
//! `config::parse`. Whatever the mutation: no panic, and either a clear error naming the key,
//! or a machine whose numbers are all finite (a NaN or an infinity never reaches a machine
//! that starts). Deterministic: the mutations are enumerated, not drawn.
#![allow(clippy::unwrap_used)]

use hytask::config::{self, ConfigError};
use std::path::Path;

/// The shipped machine files (cell and peer files are other formats).
const MACHINE_FILES: &[&str] = &[
    "config/sim.toml",
    "config/sim-modbus.toml",
    "config/vcan.toml",
    "config/example-canopen.toml",
    "tests/fixtures/sim-fast.toml",
];

/// One leaf of a TOML document: its path of keys and indices.
#[derive(Clone, Debug)]
enum Step {
    Key(String),
    Index(usize),
}

fn path_text(path: &[Step]) -> String {
    let mut s = String::new();
    for p in path {
        match p {
            Step::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Step::Index(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

fn leaves(v: &toml::Value, path: &mut Vec<Step>, out: &mut Vec<(Vec<Step>, toml::Value)>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                path.push(Step::Key(k.clone()));
                leaves(v, path, out);
                path.pop();
            }
        }
        toml::Value::Array(a) if a.iter().all(|x| x.is_table()) && !a.is_empty() => {
            for (i, v) in a.iter().enumerate() {
                path.push(Step::Index(i));
                leaves(v, path, out);
                path.pop();
            }
        }
        other => out.push((path.clone(), other.clone())),
    }
}

/// The value at `path`'s parent, and the last step.
fn parent_mut<'a>(root: &'a mut toml::Value, path: &[Step]) -> &'a mut toml::Value {
    let mut v = root;
    for p in &path[..path.len() - 1] {
        v = match p {
            Step::Key(k) => v.get_mut(k.as_str()).unwrap(),
            Step::Index(i) => v.get_mut(*i).unwrap(),
        };
    }
    v
}

/// `doc` with the leaf at `path` replaced (`Some`) or dropped (`None`).
fn mutated(doc: &toml::Value, path: &[Step], to: Option<toml::Value>) -> String {
    let mut doc = doc.clone();
    let parent = parent_mut(&mut doc, path);
    let Some(Step::Key(k)) = path.last() else {
        unreachable!("leaves end in a key")
    };
    let table = parent.as_table_mut().unwrap();
    match to {
        Some(v) => {
            table.insert(k.clone(), v);
        }
        None => {
            table.remove(k);
        }
    }
    toml::to_string(&doc).unwrap()
}

/// What a number may be replaced with.
fn numeric_mutations() -> Vec<(&'static str, toml::Value)> {
    use toml::Value::{Boolean, Float, Integer, String as S};
    vec![
        ("nan", Float(f64::NAN)),
        ("inf", Float(f64::INFINITY)),
        ("-inf", Float(f64::NEG_INFINITY)),
        ("zero", Float(0.0)),
        ("zero int", Integer(0)),
        ("negative", Float(-1.0)),
        ("negative int", Integer(-1)),
        ("huge", Float(1e300)),
        ("-huge", Float(-1e300)),
        ("i64 max", Integer(i64::MAX)),
        ("i64 min", Integer(i64::MIN)),
        ("string", S("x".into())),
        ("bool", Boolean(true)),
    ]
}

fn other_mutations() -> Vec<(&'static str, toml::Value)> {
    use toml::Value::{Array, Float, Integer, String as S};
    vec![
        ("number", Integer(7)),
        ("nan", Float(f64::NAN)),
        ("empty string", S(String::new())),
        ("long string", S("a".repeat(100_000))),
        ("nul string", S("a\0b".into())),
        ("array", Array(vec![Integer(1)])),
    ]
}

/// Every f64 the resolved machine holds, found through its Debug text: a NaN or an
/// infinity there means nonsense got through validation.
fn non_finite(cfg: &config::MachineConfig) -> bool {
    let text = format!("{cfg:?}");
    let word = |w: &str| {
        text.match_indices(w).any(|(i, _)| {
            let before = text[..i].chars().next_back();
            let after = text[i + w.len()..].chars().next();
            !before.is_some_and(char::is_alphanumeric) && !after.is_some_and(char::is_alphanumeric)
        })
    };
    word("NaN") || word("inf")
}

/// The array element a leaf belongs to, as messages write it (`digital_outputs[1]`).
fn element_of(path: &[Step]) -> Option<String> {
    let i = path.iter().rposition(|p| matches!(p, Step::Index(_)))?;
    match (&path[i.checked_sub(1)?], &path[i]) {
        (Step::Key(k), Step::Index(n)) => Some(format!("{k}[{n}]")),
        _ => None,
    }
}

/// Runs every mutation of `file`; returns the findings (empty: everything held).
fn abuse(file: &str) -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join(file)).unwrap();
    let doc: toml::Value = toml::from_str(&text).unwrap();
    // Sanity: the file is a valid machine as shipped.
    let base = config::parse(&text, file).unwrap_or_else(|e| panic!("{file}: {e}"));
    assert!(!non_finite(&base), "{file} as shipped holds a NaN or inf");
    let mut found = Vec::new();
    let mut all = Vec::new();
    leaves(&doc, &mut Vec::new(), &mut all);
    for (path, value) in &all {
        let key = path_text(path);
        let Some(Step::Key(leaf)) = path.last() else {
            continue;
        };
        let mut cases: Vec<(&str, Option<toml::Value>)> = vec![("dropped", None)];
        let muts = if value.is_integer() || value.is_float() {
            numeric_mutations()
        } else {
            other_mutations()
        };
        cases.extend(muts.into_iter().map(|(n, v)| (n, Some(v))));
        for (what, to) in cases {
            let mutated = mutated(&doc, path, to);
            let result = std::panic::catch_unwind(|| config::parse(&mutated, "abuse.toml"));
            match result {
                Err(_) => found.push(format!("{file}: {key} {what}: panic")),
                Ok(Ok(cfg)) if non_finite(&cfg) => found.push(format!(
                    "{file}: {key} {what}: accepted, the machine holds a NaN or inf"
                )),
                Ok(Ok(_)) => {}
                Ok(Err(e)) => {
                    let message = e.to_string();
                    // A cross-reference may name the element the key belongs to instead
                    // (`axis[2] (Z).home.position: must be within the soft limits …`).
                    let element = element_of(path);
                    let names_it = element.as_deref().is_some_and(|el| message.contains(el))
                        || match &e {
                            ConfigError::Parse {
                                key: k, message: m, ..
                            } => k.contains(leaf.as_str()) || m.contains(leaf.as_str()),
                            _ => message.contains(leaf.as_str()),
                        };
                    if !names_it {
                        found.push(format!(
                            "{file}: {key} {what}: error does not name '{leaf}': {message}"
                        ));
                    }
                }
            }
        }
    }
    found
}

fn assert_held(file: &str) {
    let found = abuse(file);
    assert!(
        found.is_empty(),
        "{} findings:\n{}",
        found.len(),
        found.join("\n")
    );
}

#[test]
fn sim_toml_mutations_are_refused_by_name_or_finite() {
    assert_held(MACHINE_FILES[0]);
}

#[test]
fn sim_modbus_toml_mutations_are_refused_by_name_or_finite() {
    assert_held(MACHINE_FILES[1]);
}

#[test]
fn vcan_toml_mutations_are_refused_by_name_or_finite() {
    assert_held(MACHINE_FILES[2]);
}

#[test]
fn example_canopen_toml_mutations_are_refused_by_name_or_finite() {
    assert_held(MACHINE_FILES[3]);
}

#[test]
fn sim_fast_toml_mutations_are_refused_by_name_or_finite() {
    assert_held(MACHINE_FILES[4]);
}
