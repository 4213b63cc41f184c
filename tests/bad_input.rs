//! Garbage in, no panic out: every file format jderobot reads (conf, simulator
//! world, camera, progeo world, kernel, fuzzy controller) is fed thousands of
//! mutations of its own example files — tokens replaced by numbers out of range,
//! NaN, infinities, junk words, lines dropped, doubled and cut short. Each parse
//! must return `Ok` or a clear `file:line` error, and whatever it accepts must
//! then be usable (projected, convolved, inferred, simulated) without a panic. The
//! shell gets the same treatment: mutated command lines against a live runtime are
//! answered, and only `quit`/`exit` end it.
//!
//! Deterministic (a fixed xorshift seed), so a failure names a reproducible case.
#![cfg(feature = "simulator")]

use crate::common;

use common::Rng;

use std::path::Path;

use jderobot::{
    Conf,
    drivers::simulator::{RobotModel, Sim},
    fuzzy::Controller,
    interfaces::{Image, Laser, Sonars},
    progeo::{HPoint3D, PinholeCamera, World as CamWorld},
    vision::{Kernel, convolve},
    world::World as SimWorld,
};

/// Tokens a mutation may put in place of another: the numbers and words that
/// break naive parsers.
const JUNK: &[&str] = &[
    "0",
    "-1",
    "1e30",
    "-1e30",
    "1e400",
    "NaN",
    "nan",
    "inf",
    "-inf",
    "0.5",
    "99999999999999999999",
    "-0",
    "x",
    "=",
    "(",
    ")",
    "AND",
    "THEN",
    "#",
    "end_driver",
    "end_schema",
    "é",
    "255,0,0",
    "1,2",
    "",
];

/// A random mutation of `text`: one to four edits of its tokens and lines.
fn mutate(text: &str, rng: &mut Rng) -> String {
    let mut lines: Vec<Vec<String>> = text
        .lines()
        .map(|l| l.split_whitespace().map(String::from).collect())
        .collect();
    for _ in 0..1 + rng.below(4) {
        if lines.is_empty() {
            lines.push(Vec::new());
        }
        let i = rng.below(lines.len());
        match rng.below(6) {
            // Replace a token.
            0 | 1 => {
                let junk = JUNK[rng.below(JUNK.len())].to_string();
                let l = &mut lines[i];
                if l.is_empty() {
                    l.push(junk);
                } else {
                    let k = rng.below(l.len());
                    l[k] = junk;
                }
            }
            // Cut the line short.
            2 => {
                let keep = rng.below(lines[i].len() + 1);
                lines[i].truncate(keep);
            }
            // Add a token.
            3 => {
                let junk = JUNK[rng.below(JUNK.len())].to_string();
                lines[i].push(junk);
            }
            // Drop or double the line.
            4 => {
                lines.remove(i);
            }
            _ => {
                let l = lines[i].clone();
                lines.insert(i, l);
            }
        }
    }
    lines
        .iter()
        .map(|l| l.join(" "))
        .collect::<Vec<_>>()
        .join("\n")
}

fn read(path: &str) -> String {
    std::fs::read_to_string(common::root().join(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// Runs `check` on `cases` mutations of each file; reports how many parsed.
fn fuzz(files: &[&str], cases: usize, seed: u64, mut check: impl FnMut(&str, &Path) -> bool) {
    let mut rng = Rng::new(seed);
    for file in files {
        let text = read(file);
        let path = Path::new(file);
        assert!(check(&text, path), "{file} itself must parse");
        let mut accepted = 0;
        for n in 0..cases {
            let m = mutate(&text, &mut rng);
            let ok = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&m, path)))
                .unwrap_or_else(|_| panic!("{file}: mutation {n} panicked:\n{m}"));
            accepted += ok as usize;
        }
        eprintln!("{file}: {accepted} of {cases} mutations accepted, the rest refused with errors");
    }
}

/// Errors name the file and a line.
fn names_file_and_line(e: &dyn std::fmt::Display, path: &Path) {
    let s = e.to_string();
    assert!(
        s.contains(&format!("{}:", path.display())),
        "error without file:line: {s}"
    );
}

#[test]
fn confs() {
    let files = [
        "examples/introrob.conf",
        "examples/simulator.conf",
        "examples/pingpong.conf",
        "examples/teleoperator.conf",
    ];
    fuzz(&files, 1500, 1, |text, path| {
        match Conf::parse(text, path) {
            Ok(_) => true,
            Err(e) => {
                names_file_and_line(&e, path);
                false
            }
        }
    });
}

#[test]
fn simulator_worlds_then_simulated() {
    let files = ["assets/worlds/simple.world", "assets/worlds/field.world"];
    let mut laser = Laser::default();
    let mut sonars = Sonars::default();
    fuzz(&files, 600, 2, |text, path| {
        match SimWorld::parse(text, path) {
            Ok(w) => {
                let mut sim = Sim::new(w, 1);
                let r = sim.add_robot("r", RobotModel::default(), 1000.0, 1000.0, 90.0);
                for _ in 0..5 {
                    sim.step(0.01);
                }
                sim.laser(r, &mut laser);
                sim.sonars(r, &mut sonars);
                true
            }
            Err(e) => {
                names_file_and_line(&e, path);
                false
            }
        }
    });
}

#[test]
fn cameras_then_projected() {
    fuzz(
        &["assets/cameras/cam-in", "assets/cameras/isight-640x480"],
        1500,
        3,
        |text, path| match PinholeCamera::parse(text, path) {
            Ok(mut cam) => {
                cam.update_camera_matrix();
                let p = cam.project(HPoint3D::point(1000.0, 2000.0, 300.0));
                let q = cam.project(HPoint3D::point(-5000.0, 100.0, 0.0));
                let _ = cam.backproject(p);
                let _ = cam.displayline(p, q);
                true
            }
            Err(e) => {
                names_file_and_line(&e, path);
                false
            }
        },
    );
}

#[test]
fn progeo_worlds() {
    fuzz(
        &["assets/cameras/room.world"],
        1500,
        4,
        |text, path| match CamWorld::parse(text, path) {
            Ok(_) => true,
            Err(e) => {
                names_file_and_line(&e, path);
                false
            }
        },
    );
}

#[test]
fn kernels_then_convolved() {
    let img = Image::new(16, 12);
    let files = [
        "assets/kernels/sharpen.kernel",
        "assets/kernels/gaussian5.kernel",
    ];
    fuzz(&files, 1500, 5, |text, path| {
        match Kernel::parse(text, path) {
            Ok(k) => {
                let _ = convolve(&img, &k);
                true
            }
            Err(e) => {
                names_file_and_line(&e, path);
                false
            }
        }
    });
}

#[test]
fn fuzzy_controllers_then_inferred() {
    fuzz(
        &["assets/fuzzy/example.fzz", "assets/fuzzy/test.fzz"],
        1500,
        6,
        |text, path| match Controller::parse_lenient(text, path) {
            Ok((mut c, _warnings)) => {
                let vars: Vec<String> = c.variables().map(String::from).collect();
                for (i, v) in vars.iter().enumerate() {
                    c.set_input(v, [12000.0, 500.0, f32::NAN, 1e30][i % 4]);
                }
                for v in &vars {
                    let _ = c.output(v);
                }
                let saved = c.to_fzz_string();
                let _ = Controller::parse_lenient(&saved, path);
                true
            }
            Err(e) => {
                names_file_and_line(&e, path);
                false
            }
        },
    );
}

/// Whatever is typed, the shell explains and carries on: mutations of a script that
/// uses every command, run against a live simulator and schemas.
#[test]
fn shell_command_lines() {
    use jderobot::shell::{Flow, Shell};
    let script = "help\nhelp run\nls\nps\nrun myschema\nstop myschema\nshow myschema\n\
                  hide myschema\necho encoders\necho encoders 1\nset motors v=100 w=5\n\
                  set pantiltmotors longitude=10\nzoom myschema\nrun\nstop\ninit\nterminate\n\
                  exit\npwd\ndir\nview examples/myschema.conf\nload_schema ping\n\
                  load_driver simulator\nshow_license\ncd .\n";
    let text = format!(
        "driver simulator\nworld {}\nprovides encoders\nprovides motors\nprovides laser\n\
         speed 20\nend_driver\nschema myschema\ncycle 20\nend_schema\nload_driver simulator\n\
         load_schema myschema\n",
        common::world_path("simple.world")
    );
    // The schemas' `on`/`off` lines would flood the test log.
    jderobot::output::set_sink(Some(Box::new(|_| {})));
    let rt = common::start_conf(&text);
    let conf = Conf::parse(&text, Path::new("test.conf")).unwrap();
    let mut shell = Shell::new(rt.clone(), conf);
    let cwd = std::env::current_dir().unwrap();
    let mut rng = Rng::new(7);
    let (mut out, mut err) = (Vec::new(), Vec::new());
    for n in 0..300 {
        let m = mutate(script, &mut rng);
        for line in m.lines() {
            // Only `quit`/`exit` may end the shell; everything else must be answered.
            let flow = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                shell.execute(line, &mut out, &mut err)
            }))
            .unwrap_or_else(|_| panic!("mutation {n}: `{line}` panicked"));
            let first = line.split_whitespace().next().unwrap_or("");
            assert!(
                flow == Flow::Continue || ["quit", "exit"].contains(&first),
                "`{line}` ended the shell"
            );
        }
        std::env::set_current_dir(&cwd).unwrap();
    }
    rt.shutdown();
    assert!(!err.is_empty() && !out.is_empty());
}

/// Issue 28, C1: every reader of a file a conf names (camera, progeo world,
/// kernel, fuzzy controller, simulator world) reads regular files only, with a
/// size limit: a directory, a FIFO (which would block), `/dev/zero` (which would
/// fill memory) and a 64 MiB text file are errors that say what is wrong, at
/// once.
#[test]
fn file_readers_take_regular_files_of_a_sane_size_only() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe.txt");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let huge = dir.path().join("huge.txt");
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(64 << 20)
        .unwrap();
    let cases: [(&Path, &str); 4] = [
        (dir.path(), "is a directory, not a regular file"),
        (&fifo, "is a FIFO (named pipe), not a regular file"),
        (
            Path::new("/dev/zero"),
            "is a character device, not a regular file",
        ),
        (
            &huge,
            "is 67108864 bytes, more than the 16777216 bytes this reads",
        ),
    ];
    for (p, want) in cases {
        let errors = [
            (
                "camera",
                PinholeCamera::load(p).err().map(|e| e.to_string()),
            ),
            (
                "progeo world",
                CamWorld::load(p).err().map(|e| e.to_string()),
            ),
            ("kernel", Kernel::load(p).err().map(|e| e.to_string())),
            (
                "fuzzy",
                Controller::from_file(p).err().map(|e| e.to_string()),
            ),
            ("world", SimWorld::load(p).err().map(|e| e.to_string())),
        ];
        for (what, e) in errors {
            let e = e.unwrap_or_else(|| panic!("the {what} reader accepted {}", p.display()));
            assert!(e.contains(want), "{what} reader on {}: {e}", p.display());
        }
    }
}
