//! A component brings its shell commands and `ps` lines through the registry, as
//! it brings its conf lines: the shell runs and lists them, `jderobot help`
//! prints the compiled-in ones from the same registration, and the shell's own
//! source names no component.

use std::sync::Arc;

use jderobot::{
    conf::Conf,
    registry,
    runtime::Runtime,
    shell::{Flow, Shell},
};

/// A test component's command: `greet [NAME]`.
fn greet(_: &Runtime, args: &[&str], out: &mut dyn std::io::Write) -> Result<(), String> {
    match args {
        [] => writeln!(out, "hello").map_err(|e| e.to_string()),
        [n] => writeln!(out, "hello {n}").map_err(|e| e.to_string()),
        _ => Err("greet: Usage: greet [NAME]".into()),
    }
}

jderobot::register_command!(
    "greeter",
    "greet",
    "[NAME]",
    "Say hello (a test component's command)",
    greet
);
jderobot::register_ps_line!("greeter", |_| Some("2 greetings".into()));

fn run(shell: &mut Shell, line: &str) -> (Flow, String, String) {
    let (mut out, mut err) = (Vec::new(), Vec::new());
    let flow = shell.execute(line, &mut out, &mut err);
    (
        flow,
        String::from_utf8(out).unwrap(),
        String::from_utf8(err).unwrap(),
    )
}

#[test]
fn a_component_brings_its_command_and_ps_line() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("jde.conf");
    let rt: Arc<Runtime> = Runtime::new(&file);
    let mut shell = Shell::new(rt.clone(), Conf::parse("", &file).unwrap());
    let (_, out, err) = run(&mut shell, "greet robot");
    assert_eq!((out.as_str(), err.as_str()), ("hello robot\n", ""));
    let (_, _, err) = run(&mut shell, "greet a b");
    assert_eq!(err, "greet: Usage: greet [NAME]\n");
    let (_, help, _) = run(&mut shell, "help");
    assert!(
        help.contains("greet [NAME]") && help.contains("Say hello"),
        "{help}"
    );
    // The compiled-in components' commands are listed from the same registration.
    for c in registry::commands() {
        assert!(help.contains(&format!("{} {}", c.name, c.usage)), "{help}");
    }
    let (_, ps, _) = run(&mut shell, "ps");
    assert!(ps.contains("greeter: 2 greetings"), "{ps}");
    rt.shutdown();
}

#[test]
fn recorder_replay_and_foxglove_bring_theirs() {
    let names: Vec<(&str, &str)> = registry::commands()
        .iter()
        .map(|c| (c.component, c.name))
        .collect();
    assert!(names.contains(&("recorder", "record")), "{names:?}");
    assert!(names.contains(&("replay", "step")), "{names:?}");
    let ps: Vec<&str> = registry::ps_lines().iter().map(|p| p.component).collect();
    assert!(
        ps.contains(&"recorder") && ps.contains(&"foxglove"),
        "{ps:?}"
    );
    for (component, name) in [("recorder", "record"), ("replay", "step")] {
        let text = crate::common::help(component);
        assert!(
            text.contains("Shell commands it brings:") && text.contains(name),
            "{text}"
        );
    }
    let out = crate::common::jderobot(["help"]).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("record start|stop|status") && text.contains("(replay)"),
        "{text}"
    );
}

#[test]
fn the_shell_names_no_component() {
    let src =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/src/shell.rs")).unwrap();
    let code: String = src
        .lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n");
    for entry in registry::components() {
        // Words a shell has for its own (the `gui` service's name is a word of its own).
        if ["gui", "mastergui"].contains(&entry.name) {
            continue;
        }
        assert!(
            !code.contains(&format!("\"{}\"", entry.name))
                && !code.contains(&format!("::{}", entry.name))
                && !code.contains(&format!("{}.", entry.name)),
            "src/shell.rs names component `{}`",
            entry.name
        );
    }
    for word in ["record", "replay", "foxglove", "mcapfmt", "_mcap"] {
        assert!(!code.contains(word), "src/shell.rs says `{word}`");
    }
}
