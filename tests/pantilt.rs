//! The pantilt driver against an emulated Directed Perception PTU on a
//! pseudo-terminal (tests/emulators/ptu.rs, written from the unit's command
//! reference): the real binary driven through its shell, the exact bytes of 4.3's
//! init sequence and commands, and the faults (missing port, not a serial device,
//! silence, garbage, `!` replies, unplugging and plugging back).
#![cfg(feature = "pantilt")]

use crate::common;
use crate::ptu;

use std::{path::Path, sync::Arc, time::Duration};

use common::{eventually, process::Proc, start_conf};
use jderobot::interfaces::{Interface, PtEncoders, PtMotors};
use ptu::{Faults, Ptu};

const ENC: f64 = 3.086 / 60.0;

/// 4.3's init sequence, byte for byte, then the limit queries.
const INIT: &[u8] =
    b"\xFF\xFF\nI\nCI\nPB1000\nTB1000\nPU6000\nTU6000\nPL31\nTL31\nPS2900\nTS2900\n\
PA9000\nTA9000\nPHL\nPML\nTHL\nTML\nPP0\nTP0\nLE\nPN\nPX\nTN\nTX\n";

fn conf(port: &std::path::Path, extra: &str) -> String {
    format!(
        "driver pantilt\nserial {}\n{extra}provides pantiltencoders\nprovides pantiltmotors\nend_driver\nload_driver pantilt\n",
        port.display()
    )
}

fn contains(hay: &[u8], needle: &[u8]) -> bool {
    hay.windows(needle.len()).any(|w| w == needle)
}

#[test]
fn shell_sets_the_head_and_echo_follows() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("ptu");
    let unit = Ptu::start(&port);
    let file = dir.path().join("pantilt.conf");
    std::fs::write(&file, conf(&port, "poll 100\n")).unwrap();
    let mut shell = Proc::start(&file);
    // The init sequence and the limit queries, exactly as 4.3 sent them.
    eventually("the init sequence and limit queries", || {
        unit.received().starts_with(INIT)
    });
    // Once the driver has provided the interface (a `set` before is refused).
    shell.ask_until("echo pantiltmotors", "the pantiltmotors interface", |l| {
        l.contains("pantiltmotors clock=")
    });
    unit.clear_received();
    shell.send("set pantiltmotors longitude=30 latitude=-10");
    // 30 deg = 583.3 steps, -10 deg = -194.4 steps; only the positions changed.
    eventually("PP583 and TP-194 on the wire", || {
        let r = unit.received();
        contains(&r, b"PP583\n") && contains(&r, b"TP-194\n")
    });
    let sent: Vec<u8> = unit
        .received()
        .split(|&c| c == b'\n')
        .filter(|l| !l.is_empty() && *l != b"PP" && *l != b"TP")
        .flat_map(|l| l.iter().copied().chain([b'\n']))
        .collect();
    assert_eq!(
        String::from_utf8_lossy(&sent),
        "PP583\nTP-194\n",
        "only the changed positions are sent"
    );
    eventually("the unit reaches (583, -194)", || {
        unit.position() == (583, -194)
    });
    std::thread::sleep(Duration::from_millis(400)); // two polls
    let echo = shell.ask_until("echo pantiltencoders", "an echo line", |l| {
        l.contains("pantiltencoders clock=")
    });
    let status = shell.quit();
    let field = |name: &str| -> f64 {
        let i = echo
            .find(name)
            .unwrap_or_else(|| panic!("{name} in {echo}"))
            + name.len();
        echo[i..].split(' ').next().unwrap().parse().unwrap()
    };
    assert!((field("pan_angle=") - 583.0 * ENC).abs() < 0.006, "{echo}");
    assert!((field("tilt_angle=") + 194.0 * ENC).abs() < 0.006, "{echo}");
    assert!(!echo.contains("STALE"), "{echo}");
    assert!(status.success(), "{status:?}");
}

/// Sets fields on a copy of the latest command and publishes it.
fn set(m: &Interface<PtMotors>, f: impl FnOnce(&mut PtMotors)) {
    let mut v = m.read().value;
    f(&mut v);
    m.publish(v).unwrap();
}

/// The emulated unit at `dir/ptu` and a runtime polling it every 50 ms,
/// once it runs.
fn running(dir: &Path) -> (std::path::PathBuf, Ptu, Arc<jderobot::Runtime>) {
    let port = dir.join("ptu");
    let unit = Ptu::start(&port);
    let rt = start_conf(&conf(&port, "poll 50\nreply_timeout 300\n"));
    let enc: Arc<Interface<PtEncoders>> = rt.interfaces.get("pantiltencoders").unwrap();
    eventually("running", || enc.clock() > 2 && enc.stale().is_none());
    (port, unit, rt)
}

fn ifaces(rt: &jderobot::Runtime) -> (Arc<Interface<PtEncoders>>, Arc<Interface<PtMotors>>) {
    (
        rt.interfaces.get("pantiltencoders").unwrap(),
        rt.interfaces.get("pantiltmotors").unwrap(),
    )
}

#[test]
fn limits_from_the_unit_commands_on_change_and_speed_zero() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("ptu");
    let unit = Ptu::start(&port);
    let rt = start_conf(&conf(&port, "poll 50\n"));
    let (enc, mot) = ifaces(&rt);
    eventually("limits read", || mot.read().max_longitude != 159.13);
    let m = mot.read().value;
    assert!(
        (m.max_longitude as f64 - 3090.0 * ENC).abs() < 1e-3,
        "{m:?}"
    );
    assert!(
        (m.min_longitude as f64 + 3090.0 * ENC).abs() < 1e-3,
        "{m:?}"
    );
    assert!((m.max_latitude as f64 - 604.0 * ENC).abs() < 1e-3, "{m:?}");
    assert!((m.min_latitude as f64 + 907.0 * ENC).abs() < 1e-3, "{m:?}");
    assert_eq!(m.max_longitude_speed, 205.89);
    eventually("encoders polled", || enc.clock() > 2);
    unit.clear_received();
    let moves = |u: &Ptu| -> Vec<String> {
        String::from_utf8_lossy(&u.received())
            .split('\n')
            .filter(|l| !l.is_empty() && *l != "PP" && *l != "TP")
            .map(str::to_string)
            .collect()
    };
    // A new speed and position: speed first; beyond the limit: clamped to it.
    set(&mot, |m| {
        m.longitude = 500.0;
        m.longitude_speed = 100.0;
    });
    eventually("PS and PP sent", || moves(&unit).len() >= 2);
    // 100 deg/s = 1944.3 steps/s.
    assert_eq!(moves(&unit), ["PS1944", "PP3090"]);
    // The same command again: nothing new on the wire.
    set(&mot, |m| m.longitude = 500.0);
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(moves(&unit).len(), 2, "{:?}", moves(&unit));
    // Speed 0: PS0 alone (4.3), the axis stops where it is.
    set(&mot, |m| m.longitude_speed = 0.0);
    eventually("PS0", || moves(&unit).len() >= 3);
    assert_eq!(moves(&unit)[2], "PS0");
    let stopped_at = unit.position().0;
    std::thread::sleep(Duration::from_millis(200));
    assert_eq!(unit.position().0, stopped_at);
    assert!(stopped_at < 3090);
    // A speed again: the position goes out again.
    set(&mot, |m| m.longitude_speed = 205.89);
    eventually("PS4003 PP3090", || moves(&unit).len() >= 5);
    assert_eq!(moves(&unit)[3..5], ["PS4003", "PP3090"]);
    rt.shutdown();
}

#[test]
fn missing_port_and_a_file_are_clear_errors_and_the_run_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("ttyUSB9");
    let rt = start_conf(&conf(&missing, ""));
    let (enc, mot) = ifaces(&rt);
    // Both stale (the driver marks one after the other).
    eventually("stale", || enc.stale().is_some() && mot.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(why.contains(&missing.display().to_string()), "{why}");
    assert!(why.contains("does not exist"), "{why}");
    // The port appears: the driver finds it, runs the init and the staleness clears.
    let unit = Ptu::start(&missing);
    eventually("the unit found once plugged in", || {
        enc.stale().is_none() && enc.clock() > 0
    });
    assert!(unit.received().starts_with(INIT));
    rt.shutdown();

    let file = dir.path().join("notatty");
    std::fs::write(&file, "").unwrap();
    let rt = start_conf(&conf(&file, ""));
    let (enc, _) = ifaces(&rt);
    eventually("stale", || enc.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(
        why.contains("notatty") && why.contains("not a serial device"),
        "{why}"
    );
    rt.shutdown();
}

#[test]
fn silence_garbage_refusal_and_unplugging_mark_the_head_stale_until_it_answers() {
    let dir = tempfile::tempdir().unwrap();
    let (port, unit, rt) = running(dir.path());
    let (enc, mot) = ifaces(&rt);
    let name = port.display().to_string();
    for (faults, expect) in [
        (
            Faults {
                silent: true,
                ..Faults::default()
            },
            "no reply to `",
        ),
        (
            Faults {
                garbage: true,
                ..Faults::default()
            },
            "unexpected reply `$GPGGA",
        ),
        (
            Faults {
                refuse: true,
                ..Faults::default()
            },
            "the unit refused `",
        ),
    ] {
        unit.set_faults(faults);
        eventually(expect, || enc.stale().is_some() && mot.stale().is_some());
        let why = enc.stale().unwrap();
        assert!(why.contains(&name) && why.contains(expect), "{why}");
        // It answers again: reopened, init again, fresh values.
        unit.clear_received();
        unit.set_faults(Faults::default());
        eventually("recovered", || {
            enc.stale().is_none() && mot.stale().is_none()
        });
        assert!(
            unit.received().windows(3).any(|w| w == b"LE\n"),
            "init again"
        );
    }
    // Unplugged: the port goes away; plugged back at the same path: it comes back.
    unit.unplug();
    eventually("stale after unplugging", || enc.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(why.contains(&name), "{why}");
    let unit = Ptu::start(&port);
    eventually("back after plugging in", || enc.stale().is_none());
    let c = enc.clock();
    eventually("polling again", || enc.clock() > c + 2);
    assert!(unit.received().starts_with(INIT));
    rt.shutdown();
}

#[test]
fn a_position_out_of_the_units_range_is_refused_not_written() {
    let dir = tempfile::tempdir().unwrap();
    let (_, unit, rt) = running(dir.path());
    let (enc, _mot) = ifaces(&rt);
    unit.set_faults(Faults {
        pan_position: Some(3_090_000),
        ..Faults::default()
    });
    eventually("refused", || enc.stale().is_some());
    let why = enc.stale().unwrap();
    assert!(why.contains("`PP` answered 3090000 steps, out of"), "{why}");
    let pan = enc.read().pan_angle;
    assert!(pan.abs() <= 160.0, "never written: {pan} deg");
    unit.set_faults(Faults::default());
    eventually("recovered", || enc.stale().is_none());
    assert!(enc.read().pan_angle.abs() <= 160.0);
    rt.shutdown();
}

#[test]
fn conf_errors_name_the_line() {
    for (text, expect) in [
        (
            "driver pantilt\nprovides pantiltencoders\nend_driver\nload_driver pantilt\n",
            "serial DEVICE",
        ),
        (
            "driver pantilt\nserial /dev/null\nprovides laser\nend_driver\nload_driver pantilt\n",
            "INTERFACE (argument 1) is `laser`, expected one of pantiltencoders, pantiltmotors",
        ),
        (
            "driver pantilt\nserial /dev/null\nbaud x\nprovides pantiltencoders\nend_driver\nload_driver pantilt\n",
            "test.conf:3",
        ),
        (
            "driver pantilt\nserial /dev/null\npoll 0\nprovides pantiltencoders\nend_driver\nload_driver pantilt\n",
            "test.conf:3: `poll`: MS (argument 1) is `0`, expected a whole number between 10 and 10000 ms",
        ),
    ] {
        let err = common::start_error(text);
        assert!(err.contains(expect), "{err}");
    }
}

/// `jderobot help pantilt` prints its declared lines; `jderobot check` names every
/// value out of range at its line, with the range, before any port is opened.
#[test]
fn help_prints_the_lines_and_check_names_every_range() {
    common::assert_help_names(
        "pantilt",
        &[
            "serial DEVICE",
            "baud RATE",
            "poll MS",
            "reply_timeout MS",
            "provides INTERFACE",
            "default: 300",
        ],
    );
    common::assert_check_names(
        "driver pantilt\nserial /nonexistent/tty\npoll 0\nbaud 9\nprovides pantiltencoders\nend_driver\nload_driver pantilt\n",
        &[
            "t.conf:3: `poll`: MS (argument 1) is `0`, expected a whole number between 10 and 10000 ms",
            "t.conf:4: `baud`: RATE (argument 1) is `9`, expected a whole number between 300 and 115200 baud",
        ],
    );
}

/// Not a test: an emulated PTU to try `examples/pantilt.conf` without a unit.
/// `PTU_PATH=/tmp/ptu cargo test --features full --test pantilt -- --ignored --nocapture emulator`
/// then `serial /tmp/ptu` in the conf; it runs for `PTU_SECONDS` (default 600).
#[test]
#[ignore = "an emulator for trying the example by hand"]
fn emulator() {
    common::emulate_by_hand("PTU", ("PTU_PATH", "/tmp/ptu"), "PTU_SECONDS", Ptu::start);
}
