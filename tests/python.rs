//! The python schema: Robotics Academy programs (HAL, GUI) in the embedded
//! interpreter. Each exercise's solution runs headless on the simulator, lock-stepped
//! (`stepped`, deterministic) and is judged on the simulator's own truth (its
//! encoders, bumpers, laser and the exported balls), not on what the program says;
//! then every failure case of issue 35: a syntax error with its line (at load and
//! in `jderobot check`), a traceback with the program's lines, a program stuck in
//! `while True: pass` (or in `time.sleep`) stopped within 100 ms with its motors
//! zeroed, other schemas unaffected, reload on save, a print flood, venvs, a
//! missing interface, the shell's `run`/`stop`/`reload`, and the panel.
#![cfg(all(feature = "python", feature = "simulator"))]

use crate::common;
#[cfg(feature = "player")]
#[path = "emulators/player.rs"]
mod player_emulator;

use std::{
    io::Write,
    path::{Path, PathBuf},
    sync::Arc,
    time::{Duration, Instant},
};

use common::{eventually, poll_until, start_conf, state};
use jderobot::{
    Runtime, State,
    interfaces::{Bumpers, Encoders, Laser, Motors},
    schemas::python::{Shared, shared},
};

fn exercise(name: &str) -> PathBuf {
    common::root().join("assets/exercises").join(name)
}

/// A runtime with the simulator in simple.world (robot at X Y THETA) lock-stepped
/// `step_ms` of simulated time per command, and the python schema on `program`.
fn academy(program: &Path, pose: (i32, i32, i32), python_lines: &str, more: &str) -> Arc<Runtime> {
    start_conf(&format!(
        "driver simulator\nworld {}\nrobot robot1 {} {} {}\nprovides encoders\nprovides motors\n\
         provides laser 180 1\nprovides bumpers\nprovides colorA\nstepped 50\nseed 1\nend_driver\n\
         schema python\nfile {}\ncycle 10\n{python_lines}end_schema\n{more}\
         load_driver simulator\nload_schema python\n",
        common::world_path("simple.world"),
        pose.0,
        pose.1,
        pose.2,
        program.display()
    ))
}

/// For the programs that never call `getImage` (the Academy's robot for them has no
/// camera): a camera the schema resumes is rendered at every step, 80 % of these
/// tests' CPU in a debug build. Without it an iteration takes about 0.7 ms, so they
/// run lock-stepped every 5 ms instead of 10: the same simulated run in half the
/// time (docs/benchmarks.md, CI).
const NO_CAMERA: &str = "camera none\ncycle 5\n";

fn console(s: &Shared) -> String {
    s.console
        .lock()
        .lines
        .iter()
        .cloned()
        .collect::<Vec<_>>()
        .join("\n")
}

fn write_program(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Runs until the simulator's clock (encoders, 20 per simulated second) has
/// advanced `sim_secs`, calling `each` with every new pose.
fn run_sim(rt: &Runtime, sim_secs: f64, mut each: impl FnMut(&Encoders)) {
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let start = enc.clock();
    let want = start + (sim_secs * 20.0) as u64;
    let t0 = Instant::now();
    let mut seen = start;
    while enc.clock() < want {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "the simulation stalled at clock {}; console:\n{}",
            enc.clock(),
            console(&shared(rt, "python"))
        );
        let c = enc.clock();
        if c != seen {
            seen = c;
            each(&enc.read().value);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn vacuum_solution_bounces_off_walls_and_sweeps_the_room() {
    let rt = academy(
        &exercise("vacuum_solution.py"),
        (1000, 1000, 90),
        NO_CAMERA,
        "",
    );
    let bumpers = rt.interfaces.get::<Bumpers>("bumpers").unwrap();
    rt.run("python").unwrap();
    let (mut bumps, mut was) = (0, false);
    let mut cells = std::collections::HashSet::new();
    let mut track: Vec<(f32, f32)> = Vec::new();
    run_sim(&rt, 90.0, |e| {
        let now = bumpers.read().value.bumpers.iter().any(|&b| b != 0);
        if now && !was {
            bumps += 1;
        }
        was = now;
        cells.insert(((e.x / 1000.0) as i32, (e.y / 1000.0) as i32));
        track.push((e.x, e.y));
    });
    let text = console(&shared(&rt, "python"));
    assert_eq!(state(&rt, "python"), State::Winner, "console:\n{text}");
    assert!(
        bumps >= 3,
        "it bumped {bumps} times in 90 s; console:\n{text}"
    );
    assert!(
        cells.len() >= 6,
        "it visited {} of the room's 24 square metres: {cells:?}",
        cells.len()
    );
    // Never stuck: it moves in every 10 s window (200 poses).
    for w in track.windows(200).step_by(50) {
        let (a, b) = (w[0], w[w.len() - 1]);
        let moved = w.iter().any(|p| (p.0 - a.0).hypot(p.1 - a.1) > 300.0);
        assert!(
            moved,
            "stuck near ({:.0}, {:.0}) .. ({:.0}, {:.0})",
            a.0, a.1, b.0, b.1
        );
    }
    assert!(text.contains("bump on the"), "{text}");
    rt.shutdown();
}

#[test]
fn avoid_solution_wanders_without_touching_anything() {
    let rt = academy(
        &exercise("avoid_solution.py"),
        (1000, 1000, 90),
        NO_CAMERA,
        "",
    );
    let bumpers = rt.interfaces.get::<Bumpers>("bumpers").unwrap();
    let laser = rt.interfaces.get::<Laser>("laser").unwrap();
    rt.run("python").unwrap();
    let (mut path, mut last) = (0.0f32, None::<(f32, f32)>);
    let mut closest = i32::MAX;
    let mut touched = false;
    run_sim(&rt, 60.0, |e| {
        touched |= bumpers.read().value.bumpers.iter().any(|&b| b != 0);
        let l = laser.read();
        if let Some(m) = l.value.readings.iter().min() {
            closest = closest.min(*m);
        }
        if let Some(p) = last {
            path += (e.x - p.0).hypot(e.y - p.1);
        }
        last = Some((e.x, e.y));
    });
    let text = console(&shared(&rt, "python"));
    assert_eq!(state(&rt, "python"), State::Winner, "console:\n{text}");
    assert!(!touched, "a bumper touched something; console:\n{text}");
    assert!(path > 6000.0, "it drove only {path:.0} mm in 60 s");
    assert!(closest >= 250, "it came within {closest} mm of an obstacle");
    assert!(text.contains("180 readings from -90 to 89 deg"), "{text}");
    rt.shutdown();
}

#[test]
fn followball_solution_turns_to_the_ball_and_approaches_it() {
    // The ball is at (4500, 1200); the robot starts 1.7 m away, the ball behind it
    // on its right (-147°).
    let rt = academy(
        &exercise("followball_solution.py"),
        (3600, 2600, 90),
        "",
        "",
    );
    let balls = jderobot::world::balls(&rt.names).expect("the simulator exports its balls");
    let ball = || {
        let b = balls.load();
        (b[0].pos[0] as f32, b[0].pos[1] as f32)
    };
    let bearing = |e: &Encoders| {
        let (bx, by) = ball();
        let a = (by - e.y).atan2(bx - e.x) - e.theta;
        (
            a.sin().atan2(a.cos()).to_degrees(),
            (bx - e.x).hypot(by - e.y),
        )
    };
    let enc = rt.interfaces.get::<Encoders>("encoders").unwrap();
    let (b0, d0) = bearing(&enc.read().value);
    assert!(b0.abs() > 90.0, "the ball starts behind ({b0:.0}°)");
    rt.run("python").unwrap();
    let mut last = (0.0f32, 0.0f32);
    run_sim(&rt, 40.0, |e| last = bearing(e));
    let s = shared(&rt, "python");
    assert_eq!(state(&rt, "python"), State::Winner, "{}", console(&s));
    assert!(
        last.0.abs() < 10.0,
        "the ball is {:.1}° off the heading; console:\n{}",
        last.0,
        console(&s)
    );
    assert!(
        last.1 < d0 - 500.0,
        "it came from {d0:.0} mm only to {:.0} mm",
        last.1
    );
    // GUI.showImage showed its mask (grey, as BGR) in the panel every iteration.
    let img = s.image.lock().clone().expect("an image shown");
    assert_eq!((img.width, img.height), (320, 240));
    assert!(img.data.iter().all(|&p| p == 0 || p == 255));
    assert!(s.images.load(std::sync::atomic::Ordering::Acquire) > 100);
    rt.shutdown();
}

#[test]
fn a_syntax_error_is_file_line_message_at_load_and_in_check() {
    let dir = tempfile::tempdir().unwrap();
    let prog = write_program(
        dir.path(),
        "bad.py",
        "from HAL import HAL\nx = 1\nif x > 0\n    HAL.setV(0.1)\n",
    );
    let conf = dir.path().join("bad.conf");
    std::fs::write(
        &conf,
        "driver simulator\nprovides motors\nend_driver\nschema python\nfile bad.py\nend_schema\n\
         load_driver simulator\nload_schema python\n",
    )
    .unwrap();
    let out = common::jderobot(["check".as_ref(), conf.as_os_str()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    let want = format!("{}:3: expected ':'", prog.display());
    assert!(err.contains(&want), "wanted `{want}` in: {err}");
    // At load (the binary): the same message, and it does not start.
    let out = common::jderobot(["--headless", "--no-shell", "--for", "1"])
        .arg(&conf)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains(&want), "{err}");
}

/// A runtime where the python schema runs `text` beside myschema, which must keep
/// running whatever the program does.
fn with_other_schema(dir: &Path, text: &str, python_lines: &str) -> (Arc<Runtime>, PathBuf) {
    let prog = write_program(dir, "prog.py", text);
    let rt = academy(
        &prog,
        (1000, 1000, 90),
        python_lines,
        "schema myschema\ncycle 20\nend_schema\nload_schema myschema\n",
    );
    rt.run("myschema").unwrap();
    (rt, prog)
}

fn motors(rt: &Runtime) -> Motors {
    rt.interfaces.get::<Motors>("motors").unwrap().read().value
}

#[test]
fn an_exception_prints_the_programs_traceback_stops_it_zeroes_its_motors_only() {
    let dir = tempfile::tempdir().unwrap();
    let (rt, prog) = with_other_schema(
        dir.path(),
        "from HAL import HAL\n\ndef speed(n):\n    return 1 / (3 - n)\n\nn = 0\nwhile True:\n    \
         HAL.setV(0.2 * speed(n))\n    n += 1\n",
        "",
    );
    rt.run("python").unwrap();
    eventually("the program fails", || state(&rt, "python") == State::Slept);
    let s = rt.schema_status("python").unwrap();
    let err = s.last_error.clone().unwrap_or_default();
    assert!(
        err.contains(&format!("{}:4: ZeroDivisionError", prog.display())),
        "{err}"
    );
    let text = console(&shared(&rt, "python"));
    let p = prog.display();
    for want in [
        "Traceback (most recent call last):".to_string(),
        format!("File \"{p}\", line 8, in <module>"),
        format!("File \"{p}\", line 4, in speed"),
        "ZeroDivisionError: division by zero".to_string(),
    ] {
        assert!(text.contains(&want), "no `{want}` in:\n{text}");
    }
    assert!(!text.contains("runner"), "our own frames leak: {text}");
    assert_eq!(shared(&rt, "python").error.lock().as_ref().unwrap().0, 4);
    assert_eq!(motors(&rt), Motors { v: 0.0, w: 0.0 });
    let before = rt.schema_status("myschema").unwrap().timing.iterations;
    eventually("myschema runs on", || {
        rt.schema_status("myschema").unwrap().timing.iterations > before + 3
    });
    assert_eq!(state(&rt, "myschema"), State::Winner);
    rt.shutdown();
}

/// Stops a program stuck in `body` and returns how long the stop took to zero
/// the motors and end the Python code.
fn stop_stuck(body: &str) -> Duration {
    let dir = tempfile::tempdir().unwrap();
    let (rt, _) = with_other_schema(
        dir.path(),
        &format!("from HAL import HAL\nimport time\nHAL.setV(0.3)\nwhile True:\n{body}\n"),
        "",
    );
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    eventually("the program is stuck in its loop", || {
        s.in_python.load(std::sync::atomic::Ordering::Acquire) && *s.phase.lock() == "loop"
    });
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(
        motors(&rt).v,
        300.0,
        "the init's command reached the motors"
    );
    let t = Instant::now();
    rt.stop("python").unwrap();
    assert!(poll_until(5, || {
        motors(&rt).v == 0.0 && !s.in_python.load(std::sync::atomic::Ordering::Acquire)
    }));
    let took = t.elapsed();
    assert_eq!(state(&rt, "myschema"), State::Winner);
    // And it runs again from the start.
    rt.run("python").unwrap();
    eventually("it runs again", || *s.phase.lock() == "loop");
    rt.shutdown();
    took
}

#[test]
fn a_program_stuck_in_while_true_pass_stops_within_100_ms() {
    let took = stop_stuck("    while True:\n        pass");
    assert!(took < Duration::from_millis(100), "took {took:?}");
}

#[test]
fn a_program_sleeping_stops_within_100_ms() {
    let took = stop_stuck("    time.sleep(30)");
    assert!(took < Duration::from_millis(100), "took {took:?}");
}

#[test]
fn saving_the_file_reloads_it() {
    let dir = tempfile::tempdir().unwrap();
    let v1 = "from HAL import HAL\nprint('version 1')\nwhile True:\n    HAL.setV(0.1)\n";
    let (rt, prog) = with_other_schema(dir.path(), v1, "");
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    eventually("version 1 runs", || console(&s).contains("version 1"));
    eventually("v = 100", || motors(&rt).v == 100.0);
    std::thread::sleep(Duration::from_millis(50));
    let v2 = "from HAL import HAL\nprint('version 2')\nwhile True:\n    HAL.setV(0.2)\n";
    let mut f = std::fs::File::create(&prog).unwrap();
    f.write_all(v2.as_bytes()).unwrap();
    f.set_modified(std::time::SystemTime::now() + Duration::from_secs(1))
        .unwrap();
    drop(f);
    eventually("version 2 runs", || console(&s).contains("version 2"));
    eventually("v = 200", || motors(&rt).v == 200.0);
    assert!(
        s.source.lock().contains("version 2"),
        "the panel shows the new text"
    );
    // A syntax error on save: the program stops with FILE:LINE, motors zero.
    let mut f = std::fs::File::create(&prog).unwrap();
    f.write_all(b"while True:\n    HAL.setV(0.2\n").unwrap();
    f.set_modified(std::time::SystemTime::now() + Duration::from_secs(2))
        .unwrap();
    drop(f);
    eventually("the bad save stops it", || {
        state(&rt, "python") == State::Slept
    });
    let err = rt.schema_status("python").unwrap().last_error.unwrap();
    assert!(err.contains(&format!("{}:2:", prog.display())), "{err}");
    assert_eq!(motors(&rt).v, 0.0);
    assert_eq!(state(&rt, "myschema"), State::Winner);
    rt.shutdown();
}

#[test]
fn a_print_flood_is_bounded_and_does_not_stall_the_loop() {
    let dir = tempfile::tempdir().unwrap();
    let (rt, _) = with_other_schema(
        dir.path(),
        "from HAL import HAL\nn = 0\nwhile True:\n    for i in range(300):\n        \
         print('flood', n, i)\n    n += 1\n    HAL.setV(0.05)\n",
        "",
    );
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    eventually("many iterations", || {
        rt.schema_status("python").unwrap().timing.iterations > 100
    });
    let c = s.console.lock();
    assert!(c.lines.len() <= jderobot::schemas::python::CONSOLE_LINES);
    assert!(c.total > 20_000, "{} lines printed", c.total);
    drop(c);
    assert_eq!(state(&rt, "python"), State::Winner);
    assert_eq!(state(&rt, "myschema"), State::Winner);
    rt.shutdown();
}

#[test]
fn a_missing_interface_is_a_python_error_naming_the_conf_line() {
    let dir = tempfile::tempdir().unwrap();
    let (rt, prog) = with_other_schema(
        dir.path(),
        "from HAL import HAL\nprint(HAL.getPose3d())\nd = HAL.getLaserData()\n",
        "laser none\n",
    );
    rt.run("python").unwrap();
    eventually("the program fails", || state(&rt, "python") == State::Slept);
    let err = rt.schema_status("python").unwrap().last_error.unwrap();
    assert!(
        err.contains(&format!(
            "{}:3: RuntimeError: HAL.getLaserData: this robot has no laser",
            prog.display()
        )),
        "{err}"
    );
    assert!(console(&shared(&rt, "python")).contains("Pose3d: x=1.000 y=1.000"));
    rt.shutdown();
}

#[test]
fn the_api_gives_the_academys_units() {
    let dir = tempfile::tempdir().unwrap();
    let (rt, _) = with_other_schema(
        dir.path(),
        "import math\nfrom HAL import HAL\np = HAL.getPose3d()\nprint('pose', p.x, p.y, round(p.yaw, 4), p.z, p.roll, p.pitch)\n\
         l = HAL.getLaserData()\nprint('laser', len(l.values), round(l.minAngle, 4), round(l.maxAngle, 4), l.minRange, l.maxRange)\n\
         print('ahead', round(l.values[90], 2))\nb = HAL.getBumperData()\nprint('bumper', b.state, b.bumper)\n\
         img = HAL.getImage()\nprint('image', img.shape, img.dtype, img.flags.writeable)\n\
         HAL.setV(0.25)\nHAL.setW(math.pi / 4)\n",
        "",
    );
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    eventually("it ran", || *s.phase.lock() == "finished");
    let text = console(&s);
    // Robot at (1000, 1000) mm heading 90°: yaw π/2; straight ahead the laser (at
    // 19 mm in front of the centre) sees the green box's side at y = 3249 mm, in m;
    // the camera 320x240 BGR.
    assert!(text.contains("pose 1.0 1.0 1.5708 0.0 0.0 0.0"), "{text}");
    assert!(text.contains("laser 180 -1.5708 1.5533 0.0 8.0"), "{text}");
    assert!(text.contains("ahead 2.23"), "{text}");
    assert!(text.contains("bumper 0 -1"), "{text}");
    assert!(text.contains("image (240, 320, 3) uint8 True"), "{text}");
    // 0.25 m/s, π/4 rad/s → 250 mm/s, 45 deg/s.
    let m = motors(&rt);
    assert_eq!(m.v, 250.0);
    assert!((m.w - 45.0).abs() < 1e-3, "{m:?}");
    rt.shutdown();
}

#[test]
fn a_break_ends_the_loop_and_runs_what_follows() {
    let dir = tempfile::tempdir().unwrap();
    let (rt, _) = with_other_schema(
        dir.path(),
        "n = 0\nwhile True:\n    n += 1\n    if n < 3:\n        continue\n    print('iteration', n)\n    \
         if n == 5:\n        break\nprint('after', n)\n",
        "",
    );
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    eventually("it ended", || *s.phase.lock() == "finished");
    let text = console(&s);
    assert!(
        text.contains("iteration 3\niteration 4\niteration 5\nafter 5"),
        "{text}"
    );
    assert_eq!(state(&rt, "python"), State::Winner);
    rt.shutdown();
}

#[test]
fn a_venv_line_adds_its_packages() {
    let dir = tempfile::tempdir().unwrap();
    let v = format!(
        "python{}",
        String::from_utf8(
            std::process::Command::new("/usr/bin/python3")
                .args([
                    "-c",
                    "import sys; print(f'{sys.version_info[0]}.{sys.version_info[1]}')"
                ])
                .output()
                .unwrap()
                .stdout
        )
        .unwrap()
        .trim()
    );
    let site = dir.path().join("venv/lib").join(v).join("site-packages");
    std::fs::create_dir_all(&site).unwrap();
    std::fs::write(site.join("studentlib.py"), "ANSWER = 42\n").unwrap();
    let (rt, _) = with_other_schema(
        dir.path(),
        "import studentlib\nprint('answer', studentlib.ANSWER)\n",
        &format!("venv {}\n", dir.path().join("venv").display()),
    );
    rt.run("python").unwrap();
    let s = shared(&rt, "python");
    eventually("it ran", || console(&s).contains("answer 42"));
    rt.shutdown();
}

#[test]
fn the_shell_runs_stops_and_reloads_a_program() {
    let dir = tempfile::tempdir().unwrap();
    let prog = write_program(
        dir.path(),
        "p.py",
        "print('hello from python')\nwhile True:\n    pass\n",
    );
    let conf = dir.path().join("p.conf");
    std::fs::write(
        &conf,
        format!(
            "driver simulator\nworld {}\nprovides motors\nprovides encoders\nend_driver\n\
             schema python\nfile p.py\nwatch off\nend_schema\nload_driver simulator\nload_schema python\n",
            common::world_path("simple.world")
        ),
    )
    .unwrap();
    let mut child = common::jderobot(["--headless".as_ref(), conf.as_os_str()])
        .current_dir(dir.path())
        .spawn()
        .unwrap();
    let out = common::process::collect_output(&mut child);
    let mut stdin = child.stdin.take().unwrap();
    let wait_for = |what: &str| {
        assert!(
            poll_until(20, || out.lock().unwrap().contains(what)),
            "no `{what}` in:\n{}",
            out.lock().unwrap()
        )
    };
    writeln!(stdin, "run python").unwrap();
    wait_for("python> hello from python");
    std::fs::write(&prog, "print('hello again')\nwhile True:\n    pass\n").unwrap();
    writeln!(stdin, "reload python").unwrap();
    wait_for("python reloaded");
    wait_for("python> hello again");
    writeln!(stdin, "stop python").unwrap();
    wait_for("python: off");
    writeln!(stdin, "quit").unwrap();
    drop(stdin);
    let status = child.wait().unwrap();
    assert!(status.success(), "{}", out.lock().unwrap());
}

#[cfg(feature = "gui")]
#[test]
fn the_panel_shows_the_program_its_error_and_plays_and_stops() {
    use egui_kittest::kittest::Queryable;
    let dir = tempfile::tempdir().unwrap();
    let (rt, prog) = with_other_schema(
        dir.path(),
        "from HAL import HAL\nprint('panel test')\nwhile True:\n    HAL.setV(1 / 0)\n",
        "",
    );
    let mut h = common::panel_harness(&rt, "python", egui::vec2(700.0, 700.0));
    h.run_steps(8);
    assert!(
        h.query_by_label_contains("HAL.setV(1 / 0)").is_some()
            || h.query_by_label_contains("while").is_some()
    );
    h.get_by_label("Play").click();
    h.run_steps(8);
    eventually("it fails", || {
        rt.schema_status("python").unwrap().last_error.is_some()
    });
    h.run_steps(8);
    assert!(
        h.query_all_by_label_contains("ZeroDivisionError")
            .next()
            .is_some()
    );
    assert!(h.query_all_by_label_contains("panel test").next().is_some());
    // Fixed in an editor and reloaded from the panel: the error goes, Play runs it.
    std::fs::write(
        &prog,
        "from HAL import HAL\nwhile True:\n    HAL.setV(0.1)\n",
    )
    .unwrap();
    h.get_by_label("Reload").click();
    h.run_steps(8);
    assert!(
        h.query_all_by_label_contains("ZeroDivisionError")
            .next()
            .is_none()
    );
    assert!(
        h.query_all_by_label_contains("HAL.setV(0.1)")
            .next()
            .is_some()
    );
    h.get_by_label("Play").click();
    h.run_steps(8);
    eventually("it runs again", || state(&rt, "python") == State::Winner);
    eventually("v = 100", || motors(&rt).v == 100.0);
    h.run_steps(8);
    assert!(h.query_all_by_label_contains("Hz").next().is_some());
    h.get_by_label("Stop").click();
    h.run_steps(8);
    eventually("stopped", || state(&rt, "python") == State::Slept);
    rt.shutdown();
}

/// The avoid exercise's solution, unchanged, on a Player/Stage robot: the Player
/// server emulator (tests/emulators/player.rs: a 6 m x 4 m box, Stage's units).
#[cfg(feature = "player")]
#[test]
fn the_same_program_drives_a_player_stage_robot() {
    let emu = player_emulator::Emulator::start();
    let rt = start_conf(&format!(
        "driver player\nhostname 127.0.0.1 port {}\nprovides encoders\nprovides motors\n\
         provides laser\nprovides bumpers\nend_driver\n\
         schema python\nfile {}\ncycle 50\nend_schema\n\
         load_driver player\nload_schema python\nrun python\n",
        emu.port,
        exercise("avoid_solution.py").display()
    ));
    let s = shared(&rt, "python");
    let t = Instant::now();
    let (mut path, mut last, mut closest) = (0.0f64, None::<(f64, f64)>, f64::MAX);
    while t.elapsed() < Duration::from_secs(15) {
        let w = emu.world().clone();
        let wall = (w.x - w.xmin)
            .min(w.xmax - w.x)
            .min(w.y - w.ymin)
            .min(w.ymax - w.y);
        closest = closest.min(wall);
        if let Some(p) = last {
            path += (w.x - p.0).hypot(w.y - p.1);
        }
        last = Some((w.x, w.y));
        std::thread::sleep(Duration::from_millis(20));
    }
    let text = console(&s);
    assert_eq!(state(&rt, "python"), State::Winner, "{text}");
    assert!(text.contains("180 readings from -90 to 89 deg"), "{text}");
    assert!(path > 2.0, "it drove {path:.2} m in 15 s; console:\n{text}");
    assert!(closest > 0.3, "it came within {closest:.2} m of a wall");
    // What reached the server: m/s and rad/s.
    assert!(
        emu.world()
            .commands
            .iter()
            .any(|(v, _, _)| (*v - 0.4).abs() < 1e-6)
    );
    rt.shutdown();
}
