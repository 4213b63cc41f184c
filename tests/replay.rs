//! replay through the real binary: a stepped replay driven by the shell's `step`,
//! recorded by the shell's `record start|stop`; `start`/`end` cut the recording;
//! motors written during a replay move nothing.
#![cfg(all(feature = "recorder", feature = "replay"))]

use crate::common;

use std::{
    io::Write,
    path::Path,
    process::{Command, Stdio},
    sync::Arc,
    time::{Duration, Instant},
};

use std::collections::BTreeMap;

use common::root;
use jderobot::{
    interfaces::{Laser, Motors, Sample},
    mcapfmt::{self, Decoded, Recorded, Snapshot, Summary},
};

const BIN: &str = env!("CARGO_BIN_EXE_jderobot");

fn recording() -> String {
    root()
        .join("assets/recordings/simple.mcap")
        .display()
        .to_string()
}

/// Runs the binary on `conf` with the shell reading `steps` (each after its pause).
fn shell(dir: &Path, conf: &str, steps: &[(u64, &str)]) -> (String, String) {
    let path = dir.join("jde.conf");
    std::fs::write(&path, conf).unwrap();
    let mut child = Command::new(BIN)
        .args(["--headless"])
        .arg(&path)
        .current_dir(dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    for (ms, line) in steps {
        std::thread::sleep(Duration::from_millis(*ms));
        stdin.write_all(format!("{line}\n").as_bytes()).unwrap();
        stdin.flush().unwrap();
    }
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn stepped_replay_advances_only_on_step_and_record_start_stop_work() {
    let dir = tempfile::tempdir().unwrap();
    let conf = format!(
        "driver replay\nfile {}\nprovides laser encoders\nstepped on\nend_driver\n\
         service recorder\nfile s.mcap\nstart off\nend_service\n\
         load_driver replay\nload_service recorder\n",
        recording()
    );
    let (out, err) = shell(
        dir.path(),
        &conf,
        &[
            (1000, "ps"),
            (0, "record start"),
            // One message at a time: the recorder polls at 1 kHz, and two messages
            // of one interface published within a millisecond keep only the second.
            (300, "step"),
            (100, "step"),
            (100, "step"),
            (300, "ps"),
            (0, "record stop"),
            (0, "step 2"),
            (0, "record status"),
            (0, "step x"),
            (0, "exit"),
        ],
    );
    // Nothing before the first step.
    assert!(out.contains("laser: 0 ips, 1 user(s), clock 0"), "{out}");
    assert!(out.contains("replay: 1 messages published"), "{out}\n{err}");
    assert!(out.contains("replay: 3 messages published"), "{out}\n{err}");
    assert!(out.contains("replay: 5 messages published"), "{out}\n{err}");
    assert!(
        out.contains("recorder: recording ") && out.contains("s.mcap: "),
        "{out}"
    );
    assert!(out.contains("s.mcap): 3 messages"), "{out}");
    assert!(err.contains("step: `x` is not a count"), "{err}");
    let (s, _) = Summary::read(&dir.path().join("s.mcap")).unwrap();
    assert_eq!(s.messages, 3);
    assert!(s.complete);
}

#[test]
fn start_and_end_cut_the_recording_and_motors_move_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (full, _) = Summary::read(Path::new(&recording())).unwrap();
    let conf = format!(
        "driver replay\nfile {}\nspeed 2\nstart 2\nend 6\nend_driver\n\
         load_driver replay\n\
         service recorder\nfile cut.mcap\nend_service\nload_service recorder\n",
        recording()
    );
    // The recording has a motors channel: the replay provides `motors` for schemas
    // to write, publishes none of the recorded commands, and a command written
    // now changes nothing that is replayed.
    let (out, err) = shell(
        dir.path(),
        &conf,
        &[(800, "set motors v=500 w=30"), (2500, "ps"), (0, "exit")],
    );
    assert!(out.contains("motors: "), "{out}\n{err}");
    let (cut, by) = messages(&dir.path().join("cut.mcap"));
    // The motors command carries today's time; the replayed channels the recording's.
    let laser = cut.channels.iter().find(|c| c.topic == "laser").unwrap();
    let span = (laser.last_ns - laser.first_ns) as f64 / 1e9;
    // (the recorder starts 0.3 s after load: 0.6 s of the recording at speed 2)
    assert!(
        span <= 4.05 && span > 2.5,
        "replayed span {span} s, wanted 2..6 s"
    );
    assert!(
        laser.first_ns >= full.start_ns + 1_950_000_000,
        "started too early"
    );
    assert!(
        laser.last_ns <= full.start_ns + 6_000_000_000,
        "ended too late"
    );
    let motors = &by["motors"];
    assert!(
        motors
            .iter()
            .all(|d| d.value == Recorded::Motors(Motors { v: 500.0, w: 30.0 })),
        "only the command written during the replay is recorded: {motors:?}"
    );
    let (_, orig) = messages(Path::new(&recording()));
    // Each replayed odometry sample is a recorded one, in the recorded order (a
    // loaded machine may let the recorder skip one: interfaces keep the latest value).
    assert!(!by["encoders"].is_empty(), "no odometry was replayed");
    let mut recorded = orig["encoders"].iter();
    for d in &by["encoders"] {
        assert!(
            recorded.any(|o| o == d),
            "the replayed odometry is the recording's, whatever the motors say: {d:?}"
        );
    }
}

fn messages(path: &Path) -> (Summary, BTreeMap<String, Vec<Decoded>>) {
    let (summary, bytes) = Summary::read(path).unwrap_or_else(|e| panic!("{e}"));
    let mut by: BTreeMap<String, Vec<Decoded>> = BTreeMap::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let kind = mcapfmt::channel_kind(&m.channel.metadata, None).unwrap();
        by.entry(m.channel.topic.clone())
            .or_default()
            .push(mcapfmt::decode_mcap(kind, &m).unwrap());
    }
    (summary, by)
}

/// foxglove.LaserScan has no range limits: the recorder keeps them in the laser
/// channel's metadata and the replay gives them back (not 0 and 8000 mm). The scan
/// comes from a ros2-profile file (its LaserScan carries them), is replayed and
/// recorded by the binary in jderobot's profile, and that file replayed again.
#[test]
fn a_replayed_laser_keeps_its_recorded_range_limits() {
    let dir = tempfile::tempdir().unwrap();
    let scan = Laser {
        readings: vec![20, 1500, 5600, 300],
        resolution: 0.5,
        start: -3.0,
        min_range: 20.0,
        max_range: 5600.0,
        ..Laser::default()
    };
    // The source: ten scans over a second, as a ros2 bag.
    let profile = mcapfmt::Profile::Ros2;
    let mut w = mcapfmt::write_options(None, profile)
        .create(std::io::Cursor::new(Vec::new()))
        .unwrap();
    let id = mcapfmt::add_channel(&mut w, "laser", jderobot::interfaces::Kind::Laser, profile)
        .unwrap()
        .unwrap();
    let mut buf = Vec::new();
    for k in 1..=10u64 {
        let snap = Snapshot::Laser(Arc::new(Sample {
            clock: k,
            stamp: Instant::now(),
            time: mcapfmt::from_nanos(1_700_000_000_000_000_000 + k * 100_000_000),
            value: scan.clone(),
        }));
        assert!(mcapfmt::write_sample(&mut w, profile, id, "laser", &snap, &mut buf).unwrap());
    }
    w.finish().unwrap();
    std::fs::write(dir.path().join("src.mcap"), w.into_inner().into_inner()).unwrap();

    // Replayed (in a loop) and recorded in jderobot's profile.
    shell(
        dir.path(),
        "driver replay\nfile src.mcap\nloop on\nend_driver\n\
         service recorder\nfile rec.mcap\nrecords laser\nend_service\n\
         load_driver replay\nload_service recorder\n",
        &[(1500, "echo laser")],
    );
    let (_, by) = messages(&dir.path().join("rec.mcap"));
    let laser = &by["laser"];
    assert!(!laser.is_empty());
    for d in laser {
        let Recorded::Laser(l) = &d.value else {
            panic!("not a laser: {d:?}")
        };
        assert_eq!((l.min_range, l.max_range), (20.0, 5600.0));
        assert_eq!(l.readings, scan.readings);
    }
    // And replayed from it.
    let (out, _) = shell(
        dir.path(),
        "driver replay\nfile rec.mcap\nloop on\nend_driver\nload_driver replay\n",
        &[(800, "echo laser")],
    );
    assert!(out.contains("range=[20, 5600] mm"), "{out}");
}
