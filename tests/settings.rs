//! Declared settings: every component that declares its lines is checked from its
//! declaration (one bad value per line, each an error at file:line naming the
//! range or choices), `jderobot help NAME` prints every line it accepts, and the
//! inputs that were accepted silently before (issue 28, C2) are refused.

use crate::common;

use jderobot::{
    conf::{
        Conf,
        settings::{ArgType, Setting},
    },
    loader, registry,
};

/// A word that `ty` refuses, if there is one.
fn bad_word(ty: &ArgType) -> Option<String> {
    Some(match ty {
        ArgType::Int { max, .. } if *max < i64::MAX => (max + 1).to_string(),
        ArgType::Int { .. } => "x".into(),
        ArgType::Float { max, .. } if *max < f64::MAX => format!("{}", max * 2.0 + 1.0),
        ArgType::Float { .. } => "nan".into(),
        ArgType::Choice(_) => "no_such_choice".into(),
        ArgType::OnOff => "maybe".into(),
        ArgType::Interface => "lazer".into(),
        ArgType::Path | ArgType::Word | ArgType::Rest => return None,
    })
}

/// A word that `ty` accepts.
fn good_word(ty: &ArgType) -> String {
    match ty {
        ArgType::Int { min, max } => (*min.max(&0).min(max)).to_string(),
        ArgType::Float { min, max } => format!("{}", min.max(0.0).min(*max)),
        ArgType::Choice(c) => c[0].to_string(),
        ArgType::OnOff => "on".into(),
        ArgType::Interface => "none".into(),
        ArgType::Path | ArgType::Word | ArgType::Rest => "word".into(),
    }
}

/// `check` of a conf with `component`'s section holding `line` (at line 2).
fn problems(kind: &str, name: &str, line: &str) -> Vec<String> {
    let text = format!("{kind} {name}\n{line}\nend_{kind}\nload_{kind} {name}\n");
    let conf = Conf::parse(&text, std::path::Path::new("t.conf")).expect("grammar");
    loader::check(&conf)
        .into_iter()
        .map(|e| e.to_string())
        .collect()
}

fn declared() -> Vec<(&'static registry::Entry, &'static [Setting])> {
    registry::components()
        .into_iter()
        .filter_map(|e| e.lines.map(|l| (e, l)))
        .collect()
}

#[test]
fn every_declared_line_refuses_a_bad_value_at_its_line() {
    let mut tried = 0;
    for (entry, decl) in declared() {
        let kind = entry.kind.to_string();
        for s in decl {
            for (i, a) in s.args.iter().enumerate() {
                let Some(bad) = bad_word(&a.ty) else { continue };
                let mut words: Vec<String> = s.args.iter().map(|a| good_word(&a.ty)).collect();
                words[i] = bad.clone();
                let line = format!("{} {}", s.key, words.join(" "));
                let p = problems(&kind, entry.name, &line);
                assert!(
                    p.iter().any(|e| e.starts_with("t.conf:2: ")
                        && e.contains(&format!("is `{bad}`"))
                        && e.contains("expected")),
                    "{} `{line}`: {p:?}",
                    entry.name
                );
                tried += 1;
            }
            // Too many words.
            if !s.args.iter().any(|a| matches!(a.ty, ArgType::Rest)) {
                let mut words: Vec<String> = s.args.iter().map(|a| good_word(&a.ty)).collect();
                words.push("extra".into());
                let line = format!("{} {}", s.key, words.join(" "));
                let p = problems(&kind, entry.name, &line);
                assert!(
                    p.iter()
                        .any(|e| e.starts_with("t.conf:2: ") && e.contains("usage: ")),
                    "{} `{line}`: {p:?}",
                    entry.name
                );
            }
        }
        let p = problems(&kind, entry.name, "no_such_line 1");
        assert!(
            p.iter().any(|e| e.starts_with("t.conf:2: ")
                && e.contains("`no_such_line`")
                && e.contains(&format!("jderobot help {}", entry.name))),
            "{}: {p:?}",
            entry.name
        );
    }
    assert!(tried > 20, "only {tried} bad values tried");
}

#[test]
fn help_prints_every_line_a_component_accepts() {
    let declared = declared();
    assert!(declared.len() >= 6, "{} declared", declared.len());
    for (entry, decl) in declared {
        let text = common::help(entry.name);
        assert!(text.contains(entry.summary), "{text}");
        for s in decl {
            assert!(text.contains(&s.usage()), "help {}: {text}", entry.name);
            assert!(text.contains(s.help), "help {}: {text}", entry.name);
            if let Some(d) = s.default {
                assert!(text.contains(&format!("default: {d}")), "{text}");
            }
            // Each line with its good values is accepted: help tells the truth.
            let words: Vec<String> = s.args.iter().map(|a| good_word(&a.ty)).collect();
            let line = format!("{} {}", s.key, words.join(" "));
            let p = problems(&entry.kind.to_string(), entry.name, &line);
            // (A line the component needs and the test left out is another matter.)
            assert!(
                p.iter()
                    .all(|e| !e.starts_with("t.conf:2: ") || e.contains(", and needs one: ")),
                "{} `{line}`: {p:?}",
                entry.name
            );
        }
    }
    let text = common::help("naooperator");
    assert!(
        text.contains("head LONGITUDE LATITUDE") && text.contains("in deg"),
        "{text}"
    );
    let out = common::jderobot(["help", "nosuch"]).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no component called `nosuch`"));
}

/// Issue 28, C2: each was accepted silently; each is now an error naming its line.
#[test]
fn values_accepted_silently_before_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            "schema myschema\nend_schema extra words\nload_schema myschema\n",
            ":2: `end_schema` takes no words after it",
        ),
        (
            "driver simulator\nend_driver now\nload_driver simulator\n",
            ":2: `end_driver` takes no words after it",
        ),
        (
            "schema naooperator\nhead 0 18446744073709551616\nend_schema\nload_schema naooperator\n",
            ":2: `head`: LATITUDE (argument 2) is `18446744073709551616`, expected a number between -90 and 90 deg",
        ),
        (
            "schema teleoperator\npantilt -9223372036854775809 -10\nend_schema\nload_schema teleoperator\n",
            ":2: `pantilt`: LONGITUDE (argument 1) is `-9223372036854775809`, expected a number between -180 and 180 deg",
        ),
        (
            "schema pingpong\nturn 50000000000\nend_schema\nload_schema pingpong\n",
            ":2: `turn`: N (argument 1) is `50000000000`, expected a whole number between 1 and 1000000 iterations",
        ),
        (
            "schema introrob\nmax_v 4000000000000\nend_schema\nload_schema introrob\n",
            ":2: `max_v`: V (argument 1) is `4000000000000`, expected a number between 1 and 1000 mm/s",
        ),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let name = format!("c{i}.conf");
        let (ok, err) = common::check_text(dir.path(), &name, text);
        assert!(!ok, "accepted: {text}");
        let file = dir.path().join(name);
        assert!(
            err.contains(&format!("{}{want}", file.display())),
            "{text}: {err}"
        );
    }
}

/// A line a component needs (a serial port, a `provides`) is named when absent,
/// with its usage and where to read more.
#[test]
fn every_required_line_is_named_when_absent() {
    let mut tried = 0;
    for (entry, decl) in declared() {
        for s in decl.iter().filter(|s| s.required) {
            let p = problems(&entry.kind.to_string(), entry.name, "# nothing");
            assert!(
                p.iter()
                    .any(|e| e.contains(&format!("has no `{}` line", s.key))
                        && e.contains(&s.usage())
                        && e.contains(&format!("jderobot help {}", entry.name))),
                "{}: {p:?}",
                entry.name
            );
            tried += 1;
        }
    }
    assert!(tried >= 10, "only {tried} required lines");
}
