//! The conf grammar and every error it reports, plus the registry's answers.

use std::path::{Path, PathBuf};

use jderobot::{
    Kind,
    conf::{Action, Conf},
    registry,
};

fn parse(text: &str) -> Result<Conf, String> {
    Conf::parse(text, Path::new("jde.conf")).map_err(|e| e.to_string())
}

fn check(text: &str) -> Vec<String> {
    jderobot::loader::check(&parse(text).unwrap())
        .into_iter()
        .map(|e| e.to_string())
        .collect()
}

#[test]
fn the_seed_manuals_sections_parse() {
    let conf = Conf::load(Path::new("tests/data/seed_sections.conf")).unwrap();
    let names: Vec<&str> = conf.sections.iter().map(|s| s.name.as_str()).collect();
    for expected in [
        "networkserver",
        "networkclient",
        "imagefile",
        "player",
        "firewire",
        "video4linux2",
        "opencv",
        "simulated3D",
        "gazebo",
    ] {
        assert!(
            names.contains(&expected),
            "{expected} missing from {names:?}"
        );
    }
    let player = conf.section(Kind::Driver, "player").unwrap();
    let provides: Vec<String> = player
        .lines
        .iter()
        .filter(|l| l.keyword() == "provides")
        .map(|l| l.args().join(" "))
        .collect();
    assert_eq!(provides, ["laser 180 1", "sonars", "encoders", "motors"]);
    // Commented-out lines inside sections are comments.
    let ns = conf.section(Kind::Driver, "networkserver").unwrap();
    assert!(ns.lines.iter().all(|l| !l.keyword().starts_with('#')));
    // Indented sections (video4linux2 in the manual) are fine.
    assert!(conf.section(Kind::Driver, "video4linux2").is_some());
}

#[test]
fn every_keyword_and_synonym() {
    let c = parse(
        "path /usr/lib:/usr/local/lib\n\
         load_driver d1\nload_service s1 own.conf\nload_schema a\nload b\n\
         run a\nresume a\non a\nshow a\nguiresume a\nguion a\n",
    )
    .unwrap();
    assert_eq!(c.path.len(), 2);
    let actions: Vec<Action> = c.directives.iter().map(|d| d.action.clone()).collect();
    assert_eq!(
        actions[1],
        Action::Load {
            kind: Some(Kind::Service),
            name: "s1".into(),
            file: Some(PathBuf::from("own.conf"))
        }
    );
    assert_eq!(
        actions[3],
        Action::Load {
            kind: None,
            name: "b".into(),
            file: None
        }
    );
    assert_eq!(&actions[4..7], &vec![Action::Run("a".into()); 3][..]);
    assert_eq!(&actions[7..], &vec![Action::Show("a".into()); 3][..]);
    assert_eq!(c.directives[4].at.line, 6);
}

#[test]
fn comments_blank_lines_and_indentation() {
    let c = parse(
        "\n# top\n   # indented comment\n\t\n  driver x  \n\t provides laser # why\n  end_driver\n",
    )
    .unwrap();
    assert_eq!(c.sections[0].lines.len(), 1);
    assert_eq!(c.sections[0].lines[0].words, ["provides", "laser"]);
    assert_eq!(c.sections[0].lines[0].at.line, 6);
}

#[test]
fn unknown_keyword() {
    let e = parse("load_schema a\nfrobnicate now\n").unwrap_err();
    assert!(
        e.starts_with("jde.conf:2: unknown keyword `frobnicate`; expected one of: path"),
        "{e}"
    );
}

#[test]
fn unclosed_nested_and_stray_sections() {
    let e = parse("driver a\nprovides x\n").unwrap_err();
    assert!(
        e.contains("jde.conf:1: `driver a` section is never closed; expected `end_driver`"),
        "{e}"
    );
    let e = parse("driver a\nschema b\nend_driver\n").unwrap_err();
    assert!(
        e.contains("jde.conf:2: `schema` section inside the `driver a` section"),
        "{e}"
    );
    let e = parse("end_schema\n").unwrap_err();
    assert!(
        e.contains("jde.conf:1: `end_schema` without an open `schema NAME` section"),
        "{e}"
    );
    let e = parse("driver a\nend_schema\nend_driver\n").unwrap_err();
    assert!(
        e.contains("jde.conf:2: `end_schema` closes a schema section"),
        "{e}"
    );
    let e = parse("driver\nend_driver\n").unwrap_err();
    assert!(
        e.contains("jde.conf:1: `driver` must be followed by exactly one name"),
        "{e}"
    );
}

#[test]
fn wrong_argument_counts() {
    let e = parse("run\n").unwrap_err();
    assert!(
        e.contains("jde.conf:1: `run` takes 1 argument(s), got 0; usage: run NAME"),
        "{e}"
    );
    let e = parse("load_schema a b c\n").unwrap_err();
    assert!(
        e.contains("`load_schema` takes 1 to 2 arguments, got 3"),
        "{e}"
    );
}

#[test]
fn all_problems_are_reported_in_order() {
    let e = parse("bad1\nload_schema a\nbad2\n").unwrap_err();
    let lines: Vec<&str> = e.lines().collect();
    assert_eq!(lines.len(), 2);
    assert!(lines[0].starts_with("jde.conf:1:") && lines[1].starts_with("jde.conf:3:"));
}

#[test]
fn run_or_show_of_something_not_loaded() {
    let errs = check("run myschema\n");
    assert_eq!(errs.len(), 1);
    assert!(
        errs[0].starts_with(
            "jde.conf:1: `run myschema`: no schema `myschema` is loaded before this line"
        ),
        "{errs:?}"
    );
    let errs = check("load_schema myschema\nshow nosuch\n");
    assert!(errs[0].starts_with("jde.conf:2: `show nosuch`"), "{errs:?}");
    assert!(check("load_schema myschema\nrun myschema\nshow myschema\n").is_empty());
}

#[test]
fn missing_own_conf_file() {
    let errs = check("load_schema myschema /nonexistent/own.conf\n");
    assert!(
        errs[0].contains(
            "jde.conf:1: conf file `/nonexistent/own.conf` of schema `myschema` does not exist"
        ),
        "{errs:?}"
    );
}

#[test]
fn component_not_compiled_in_names_the_features() {
    let errs = check("load_driver nosuch\n");
    assert!(
        errs[0].starts_with("jde.conf:1: no driver called `nosuch`"),
        "{errs:?}"
    );
    assert!(
        errs[0].contains("cargo features that add components:"),
        "{errs:?}"
    );
    for f in registry::ALL_COMPONENT_FEATURES {
        assert!(errs[0].contains(f), "feature {f} not named in {errs:?}");
    }
}

#[test]
fn wrong_kind_and_double_load() {
    let errs = check("load_driver myschema\n");
    assert!(
        errs[0]
            .contains("`myschema` is a schema, not a driver; load it with `load_schema myschema`"),
        "{errs:?}"
    );
    let errs = check("load_schema myschema\nload myschema\n");
    assert!(
        errs[0].contains("jde.conf:2: `myschema` is loaded twice"),
        "{errs:?}"
    );
}

#[test]
fn component_reads_its_section_or_its_own_file() {
    let dir = tempfile::tempdir().unwrap();
    let own = dir.path().join("own.conf");
    std::fs::write(&own, "# own file\ncycle 20\n").unwrap();
    let main = dir.path().join("jde.conf");
    let text = "schema myschema\ncycle 50\nend_schema\n";
    std::fs::write(&main, text).unwrap();
    let conf = Conf::load(&main).unwrap();
    let from_section = conf.component_conf(Kind::Schema, "myschema", None).unwrap();
    assert_eq!(from_section.line("cycle").unwrap().args(), ["50"]);
    let from_file = conf
        .component_conf(Kind::Schema, "myschema", Some(&own))
        .unwrap();
    assert_eq!(from_file.line("cycle").unwrap().args(), ["20"]);
    assert_eq!(from_file.line("cycle").unwrap().at.line, 2);
    // An own file may hold the component's section too.
    std::fs::write(
        &own,
        "schema other\ncycle 1\nend_schema\nschema myschema\ncycle 7\nend_schema\n",
    )
    .unwrap();
    let from_file = conf
        .component_conf(Kind::Schema, "myschema", Some(&own))
        .unwrap();
    assert_eq!(from_file.line("cycle").unwrap().args(), ["7"]);
}

#[test]
fn typed_argument_errors_name_the_line() {
    let conf = parse("schema myschema\ncycle fast\nend_schema\n").unwrap();
    let cc = conf.component_conf(Kind::Schema, "myschema", None).unwrap();
    let e = cc
        .value_or("cycle", "milliseconds", 100u64)
        .unwrap_err()
        .to_string();
    assert_eq!(
        e,
        "jde.conf:2: `cycle`: argument 1 is `fast`, expected milliseconds"
    );
}

#[test]
fn registry_lists_compiled_components_with_features() {
    let all = registry::components();
    let my = all
        .iter()
        .find(|c| c.name == "myschema")
        .expect("myschema compiled in");
    assert_eq!(my.kind, Kind::Schema);
    assert_eq!(my.feature, "myschema");
    assert!(!my.summary.is_empty());
    for c in &all {
        assert!(
            registry::ALL_COMPONENT_FEATURES.contains(&c.feature),
            "{} has feature {} that Cargo.toml does not declare",
            c.name,
            c.feature
        );
    }
    // Every component feature compiled in has at least one component.
    for f in registry::ALL_COMPONENT_FEATURES {
        assert!(
            all.iter().any(|c| c.feature == *f),
            "feature {f} registers no component"
        );
    }
}

/// Runs `jderobot check` on `text` (written as `dir/jde.conf`) with at most 1 GiB
/// of address space and 30 s: a check that reads a device into memory or blocks
/// on a FIFO fails here instead of taking the machine or the test run with it.
/// Returns whether it passed and its standard error.
#[cfg(feature = "full")]
fn check_bin(dir: &Path, text: &str) -> (bool, String) {
    use std::{
        io::Read,
        os::unix::process::CommandExt,
        process::{Command, Stdio},
        time::{Duration, Instant},
    };
    let conf = dir.join("jde.conf");
    std::fs::write(&conf, text).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_jderobot"));
    cmd.arg("check")
        .arg(&conf)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    // SAFETY: setrlimit is async-signal-safe; nothing else runs in the child.
    unsafe {
        cmd.pre_exec(|| {
            let lim = libc::rlimit {
                rlim_cur: 1 << 30,
                rlim_max: 1 << 30,
            };
            libc::setrlimit(libc::RLIMIT_AS, &lim);
            Ok(())
        });
    }
    let mut child = cmd.spawn().unwrap();
    let mut err = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > Duration::from_secs(30) {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "`jderobot check` hung on:\n{}",
                &text[..text.len().min(300)]
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (status.success(), reader.join().unwrap())
}

/// Issue 28, C1 and C3: `provides varcolorA /dev/zero` made `check` read the
/// device into 4.2 GB, `/dev/urandom` and a FIFO hung it, and `world /dev/zero`
/// and `file /` were reported as "does not exist". Only regular files are read,
/// and the error says what the path is.
#[cfg(feature = "full")]
#[test]
fn devices_fifos_and_directories_are_named_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fifo = d.join("pipe.ppm");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let fifo = fifo.display().to_string();
    let cases: &[(String, &str)] = &[
        (
            "driver imagefile\nprovides varcolorA /dev/zero\nend_driver\nload_driver imagefile\n"
                .into(),
            "/dev/zero: is a character device, not a regular file",
        ),
        (
            "driver imagefile\nprovides varcolorA /dev/urandom\nend_driver\nload_driver imagefile\n"
                .into(),
            "/dev/urandom: is a character device, not a regular file",
        ),
        (
            format!("driver imagefile\nprovides varcolorA {fifo}\nend_driver\nload_driver imagefile\n"),
            "is a FIFO (named pipe), not a regular file",
        ),
        (
            "driver simulator\nworld /dev/zero\nend_driver\nload_driver simulator\n".into(),
            "`/dev/zero` is a character device, not a regular file",
        ),
        (
            format!("driver simulator\nworld {fifo}\nend_driver\nload_driver simulator\n"),
            "is a FIFO (named pipe), not a regular file",
        ),
        (
            "driver replay\nfile /\nend_driver\nload_driver replay\n".into(),
            "`/` is a directory, not a regular file",
        ),
        (
            "load_schema introrob /dev/zero\n".into(),
            "`/dev/zero` of schema `introrob` is a character device, not a regular file",
        ),
    ];
    for (text, want) in cases {
        let (ok, err) = check_bin(d, text);
        assert!(!ok, "check passed:\n{text}");
        assert!(err.contains(want), "{want:?} missing in:\n{err}");
    }
}

/// Issue 28, C3: a 1 MB word was echoed whole (up to 3 times) in `check`'s
/// errors. An echoed word is cut to 60 characters with `…` and its length.
#[cfg(feature = "full")]
#[test]
fn a_huge_word_is_cut_in_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let big = "x".repeat(1 << 20);
    let cases = [
        format!("load_driver {big}\n"),
        format!("{big} 1\n"),
        format!("driver simulator\n{big} 1 2\nend_driver\nload_driver simulator\n"),
        format!(
            "driver networkserver\nsocket 0\ntoken {big}\nend_driver\nload_service networkserver\n"
        ),
        format!("driver networkserver\nsocket {big}\nend_driver\nload_service networkserver\n"),
        format!("driver imagefile\nprovides {big} a.ppm\nend_driver\nload_driver imagefile\n"),
        format!("driver simulator\nworld {big}\nend_driver\nload_driver simulator\n"),
    ];
    for text in &cases {
        let (ok, err) = check_bin(d, text);
        assert!(!ok, "check passed");
        assert!(
            err.len() < 4000,
            "{} bytes of errors, starting: {}",
            err.len(),
            &err[..300.min(err.len())]
        );
    }
}
