//! The real binary: the README's commands, `check`, `list`, and every shell
//! command and error through piped standard input.

use std::{
    io::Write,
    path::Path,
    process::{Command, Output},
    thread,
    time::Duration,
};

use crate::common;

const BIN: &str = env!("CARGO_BIN_EXE_jderobot");

/// Runs the binary with `args`, feeding `input` on stdin after `delay`.
fn run_with_input(args: &[&str], input: impl AsRef<[u8]>, delay: Duration) -> Output {
    let mut child = common::jderobot(args).spawn().expect("spawn jderobot");
    let mut stdin = child.stdin.take().unwrap();
    let input = input.as_ref().to_vec();
    let feeder = thread::spawn(move || {
        thread::sleep(delay);
        let _ = stdin.write_all(&input);
    });
    let out = child.wait_with_output().expect("wait");
    feeder.join().unwrap();
    out
}

/// `jderobot check CONF`.
fn check(conf: impl AsRef<std::ffi::OsStr>) -> Output {
    Command::new(BIN)
        .arg("check")
        .arg(conf)
        .output()
        .expect("run jderobot check")
}

/// Writes `text` as `dir/name` and runs `jderobot check` on it.
fn check_text(dir: &Path, name: &str, text: &str) -> (std::path::PathBuf, Output) {
    let file = dir.join(name);
    std::fs::write(&file, text).unwrap();
    let out = check(&file);
    (file, out)
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The command the foundations issue names:
/// `(sleep 1; printf 'ps\nquit\n') | jderobot --headless examples/myschema.conf`.
#[test]
fn myschema_hello_world_headless_with_ps() {
    let out = run_with_input(
        &["--headless", "examples/myschema.conf"],
        "ps\nquit\n",
        Duration::from_secs(1),
    );
    let stdout = text(&out.stdout);
    assert!(
        out.status.success(),
        "exit {:?}\n{stdout}\n{}",
        out.status,
        text(&out.stderr)
    );
    assert!(stdout.contains("myschema: on\n"), "{stdout}");
    assert!(stdout.matches("-->Hello world!\n").count() >= 3, "{stdout}");
    let ps = stdout
        .lines()
        .find(|l| l.starts_with("myschema: ") && l.contains(" ips, winner ()"))
        .unwrap_or_else(|| panic!("no ps line in {stdout}"));
    let ips: f64 = ps["myschema: ".len()..]
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(ips > 0.0, "{ps}");
    assert!(stdout.contains("myschema: off"), "{stdout}");
}

#[test]
fn pingpong_example_runs_children_under_arbitration() {
    let out = run_with_input(
        &["--headless", "examples/pingpong.conf"],
        "ps\nstop pingpong\nps\nquit\n",
        Duration::from_millis(1500),
    );
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(
        stdout.contains("ping 1\n") && stdout.contains("pong 1\n"),
        "{stdout}"
    );
    assert!(
        stdout.contains("pingpong: ") && stdout.contains("winner (ping pong)"),
        "{stdout}"
    );
    // Exactly one of the two is winner, the other ready, in the first ps.
    let first_ps: Vec<&str> = stdout
        .lines()
        .filter(|l| (l.starts_with("ping: ") || l.starts_with("pong: ")) && l.contains(" ips, "))
        .take(2)
        .collect();
    assert_eq!(
        first_ps.iter().filter(|l| l.contains("winner")).count(),
        1,
        "{first_ps:?}"
    );
    assert_eq!(
        first_ps.iter().filter(|l| l.contains("ready")).count(),
        1,
        "{first_ps:?}"
    );
    assert!(
        stdout.contains("ping: off") && stdout.contains("pong: off"),
        "{stdout}"
    );
}

#[test]
fn check_reports_file_and_line_and_exits_nonzero() {
    let dir = tempfile::tempdir().unwrap();
    let (bad, out) = check_text(
        dir.path(),
        "bad.conf",
        "load_schema myschema\nrun myschema\nfrobnicate\n",
    );
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains(&format!(
            "{}:3: unknown keyword `frobnicate`",
            bad.display()
        )),
        "{err}"
    );

    let (_, out) = check_text(dir.path(), "nosuch.conf", "load_driver nosuch\n");
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(err.contains(":1: no driver called `nosuch`"), "{err}");
    assert!(
        err.contains("cargo features that add components: "),
        "{err}"
    );
    assert!(err.contains("myschema"), "{err}");

    // A component's own lines are checked too, by building it as a run would.
    let (cycle, out) = check_text(
        dir.path(),
        "cycle.conf",
        "schema myschema\ncycle abc\nend_schema\nload_schema myschema\nrun myschema\n",
    );
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains(&format!(
            "{}:2: `cycle`: MS (argument 1) is `abc`, expected a whole number between 1 and 10000 ms",
            cycle.display()
        )),
        "{err}"
    );
    assert!(
        !text(&out.stdout).contains("Hello world"),
        "check runs nothing"
    );

    let out = check("examples/myschema.conf");
    assert!(out.status.success(), "{}", text(&out.stderr));
}

#[test]
fn running_a_bad_conf_fails_before_starting() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.conf");
    std::fs::write(&bad, "driver x\n").unwrap();
    let out = run_with_input(&["--headless", bad.to_str().unwrap()], "", Duration::ZERO);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains(":1: `driver x` section is never closed"));
    let out = run_with_input(&["--headless", "/nonexistent.conf"], "", Duration::ZERO);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("cannot read conf file"));
}

#[test]
fn list_help_version() {
    let out = Command::new(BIN).arg("list").output().unwrap();
    let s = text(&out.stdout);
    assert!(out.status.success());
    assert!(
        s.lines()
            .any(|l| l.starts_with("schema") && l.contains("myschema")),
        "{s}"
    );
    let out = Command::new(BIN).arg("--help").output().unwrap();
    let s = text(&out.stdout);
    assert!(
        s.contains("check") && s.contains("list") && s.contains("--headless"),
        "{s}"
    );
    let out = Command::new(BIN).arg("--version").output().unwrap();
    assert!(text(&out.stdout).starts_with("jderobot "));
}

/// Every shell command through piped stdin, in main and schema state.
#[test]
fn every_shell_command_piped() {
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("jde.conf");
    std::fs::write(
        &conf,
        "schema myschema\ncycle 20\nend_schema\nload_schema myschema\n",
    )
    .unwrap();
    let own = dir.path().join("pp.conf");
    std::fs::write(&own, "turn 2\n").unwrap();
    let script = format!(
        "help\n? ps\npwd\ncd {d}\npwd\ndir\nview jde.conf\nls\n\
         load_schema ping\nload pong\nload_schema pingpong {own}\n\
         run myschema\nps\nstop myschema\nmyschema\nstop myschema\nshow myschema\nhide myschema\n\
         zoom myschema\nhelp\nrun\nstop\nshow\nhide\ninit\nresume\nsuspend\nterminate\nexit\n\
         show_license\nquit\n",
        d = dir.path().display(),
        own = own.display()
    );
    let out = run_with_input(
        &["--headless", conf.to_str().unwrap()],
        &script,
        Duration::ZERO,
    );
    let stdout = text(&out.stdout);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    for expected in [
        "help [COMMAND]",
        "ps                          Print schemas",
        &format!(
            "Current directory is {}",
            dir.path().canonicalize().unwrap().display()
        ),
        "jde.conf  (",
        "cycle 20",
        "ping loaded",
        "pong loaded",
        "pingpong loaded",
        "myschema: on",
        "myschema: off",
        "init [CONF]",
        "myschema initialized",
        "myschema terminated",
        "GNU General Public License",
    ] {
        assert!(
            stdout.contains(expected),
            "missing {expected:?} in\n{stdout}\n--\n{stderr}"
        );
    }
    assert!(
        stderr.is_empty() || !stderr.contains("No such command"),
        "{stderr}"
    );
}

/// Every mistake gets a one-line explanation and the program carries on.
#[test]
fn shell_errors_explain_and_never_kill() {
    let script = "frobnicate\nrun\nrun nosuch\nrun myschema\nstop myschema\nstop myschema\n\
                  load_driver nosuch\nload_driver myschema\nload_schema myschema\n\
                  load_schema ping /nonexistent.conf\nload_schema a b c\nzoom nosuch\n\
                  view /nonexistent\ncd /nonexistent\necho nosuch\necho motors\nset motors v=1\n\
                  zoom myschema\nfrobnicate\nexit\nhelp nosuch\nps\nquit\n";
    let out = run_with_input(
        &["--headless", "examples/myschema.conf"],
        script,
        Duration::ZERO,
    );
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.starts_with("Configuration from"))
        .collect();
    let expected = [
        "frobnicate: No such command for jderobot.",
        "run: Argument required. Usage: run NAME",
        "run: `nosuch` is not loaded; loaded: myschema",
        "run: `myschema` is already running",
        "stop: `myschema` is not running",
        "load_driver: no driver called `nosuch`",
        "load_driver: `myschema` is a schema, not a driver",
        "load_schema: `myschema` is already loaded",
        "load_schema: conf file `/nonexistent.conf` of schema `ping` does not exist",
        "load_schema command accepts 1 or 2 args only",
        "zoom: `nosuch` is not a loaded schema",
        "view: /nonexistent:",
        "cd: /nonexistent:",
        "echo: no interface `nosuch` is provided",
        "set: no interface `motors` is provided",
        "frobnicate: No such command in schema state.",
        "No commands match `nosuch'.",
    ];
    for e in expected {
        assert!(
            errors.iter().any(|l| l.contains(e)),
            "missing error {e:?} in:\n{stderr}"
        );
    }
    // One line per mistake.
    assert!(errors.len() <= expected.len() + 2, "{stderr}");
    assert!(
        text(&out.stdout).contains("myschema: "),
        "ps still works at the end"
    );
}

/// Binary garbage on standard input is refused a line at a time; the commands
/// after it still run (nothing typed is lost).
#[test]
fn a_line_that_is_not_text_is_refused_and_the_rest_runs() {
    let out = run_with_input(
        &["--headless", "examples/myschema.conf"],
        b"\xff\xfe\x00garbage\nps\nquit\n",
        Duration::ZERO,
    );
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("line 1 of standard input is not UTF-8 text; ignored"),
        "{stderr}"
    );
    assert!(text(&out.stdout).contains("myschema: "), "ps ran after it");
}

#[test]
fn run_for_ends_a_headless_run() {
    let out = Command::new(BIN)
        .args([
            "--headless",
            "--no-shell",
            "--for",
            "0.5",
            "examples/myschema.conf",
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(text(&out.stdout).contains("-->Hello world!"));
}

#[test]
fn every_example_conf_passes_check() {
    for entry in std::fs::read_dir("examples").unwrap() {
        let p = entry.unwrap().path();
        // own_schema.conf loads a schema that only the own_schema example binary has.
        if p.extension().is_some_and(|e| e == "conf") && !p.ends_with("own_schema.conf") {
            let out = check(&p);
            assert!(
                out.status.success(),
                "{}: {}",
                p.display(),
                text(&out.stderr)
            );
        }
    }
    assert!(Path::new("examples/myschema.conf").exists());
}
