//! Declared settings: the inputs that were accepted silently before (issue 28, C2)
//! are refused, and a required line is named when absent (every declaration is
//! tried, value by value, in tests/declarations.rs).

use crate::common;

/// `jderobot help` of a component with units, and of one that does not exist
/// (every component's help is tried in tests/declarations.rs).
#[test]
fn help_names_units_and_unknown_components() {
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
    for (entry, decl) in common::declared() {
        for s in decl.iter().filter(|s| s.required) {
            let p = common::line_problems(&entry.kind.to_string(), entry.name, "# nothing");
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
