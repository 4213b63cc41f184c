//! recorder and replay through the real binary and real files: 10 s of the
//! simulator recorded headless, replayed and recorded again, compared message by
//! message (clock, wall time, value); a recording killed with SIGKILL replays what
//! it wrote; `jderobot info` on good, cut and foreign files; conf errors.
//! No test depends on timing beyond generous bounds.
#![cfg(all(feature = "recorder", feature = "replay", feature = "simulator"))]

use crate::common;

use std::{
    collections::BTreeMap,
    path::{Path, PathBuf},
    process::{Command, Stdio},
    time::{Duration, Instant},
};

use common::{run_for, world_path};
use jderobot::mcapfmt::{self, Decoded, Recorded, Summary};

const BIN: &str = env!("CARGO_BIN_EXE_jderobot");

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn write(dir: &Path, name: &str, body: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, body).unwrap();
    p
}

/// The simulator with every sensor and a recorder. The imu publishes at 20 Hz
/// here, as the encoders do: a replay that falls behind on a loaded machine
/// publishes back to back, and re-recording it could skip a 50 Hz sample.
fn simulator_conf(dir: &Path, file: &str) -> PathBuf {
    write(
        dir,
        "record.conf",
        &format!(
            "driver simulator\nworld {}\nprovides encoders\nprovides motors\nprovides laser\n\
             provides sonars\nprovides colorA\nprovides imu\nperiod imu 50\nseed 7\nnoise laser 5\nend_driver\n\
             service recorder\nfile {file}\ncompression zstd\nend_service\n\
             load_driver simulator\nload_service recorder\n",
            world_path("simple.world")
        ),
    )
}

/// Every message of a file by channel, decoded, in order.
fn messages(path: &Path) -> (Summary, BTreeMap<String, Vec<Decoded>>) {
    let (summary, bytes) = Summary::read(path).unwrap_or_else(|e| panic!("{e}"));
    let mut by: BTreeMap<String, Vec<Decoded>> = BTreeMap::new();
    let stream =
        mcap::MessageStream::new_with_options(&bytes, mcap::read::Options::IgnoreEndMagic.into())
            .unwrap();
    for m in stream {
        let Ok(m) = m else { break };
        let kind = mcapfmt::channel_kind(
            &m.channel.metadata,
            m.channel.schema.as_ref().map(|s| s.name.as_str()),
        )
        .expect("a jderobot channel");
        let d =
            mcapfmt::decode_mcap(kind, &m).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(d.time_ns, m.log_time, "log time is the sample's time");
        by.entry(m.channel.topic.clone()).or_default().push(d);
    }
    (summary, by)
}

#[test]
fn ten_seconds_of_the_simulator_come_back_with_clocks_and_values() {
    let dir = tempfile::tempdir().unwrap();
    let conf = simulator_conf(dir.path(), "a.mcap");
    run_for(&conf, 10.5);
    let a = dir.path().join("a.mcap");
    let (summary, recorded) = messages(&a);
    assert!(summary.complete && summary.lost.is_none(), "{summary:?}");
    for (name, min) in [
        ("laser", 60),
        ("encoders", 120),
        ("sonars", 60),
        ("colorA", 60),
        ("imu", 120),
    ] {
        let v = recorded
            .get(name)
            .unwrap_or_else(|| panic!("no channel {name}: {:?}", recorded.keys()));
        assert!(v.len() >= min, "{name}: {} messages in 10 s", v.len());
        // The recorder took every sample: clocks are consecutive.
        for w in v.windows(2) {
            assert_eq!(w[1].clock, w[0].clock + 1, "{name}: a sample was missed");
            assert!(w[1].time_ns > w[0].time_ns, "{name}: time goes back");
        }
    }
    match &recorded["colorA"][0].value {
        Recorded::Image(i) => {
            assert_eq!((i.width, i.height, i.data.len()), (320, 240, 320 * 240 * 3))
        }
        other => panic!("colorA holds {other:?}"),
    }
    match &recorded["imu"][0].value {
        Recorded::Imu(i) => assert_eq!(i.az, 9.80665, "gravity, as the accelerometer reads it"),
        other => panic!("imu holds {other:?}"),
    }
    match &recorded["laser"][0].value {
        Recorded::Laser(l) => {
            assert_eq!(l.readings.len(), 180);
            assert!(l.readings.iter().all(|&r| r > 0 && r <= 8000));
        }
        other => panic!("laser holds {other:?}"),
    }

    // Replay it (in real time, so that a loaded machine keeps up) into the same interfaces, recorded again.
    let replay = write(
        dir.path(),
        "replay.conf",
        "driver replay\nfile a.mcap\nspeed 1\nend_driver\n\
         service recorder\nfile b.mcap\ncompression lz4\nend_service\n\
         load_driver replay\nload_service recorder\n",
    );
    run_for(&replay, 12.0);
    let (_, replayed) = messages(&dir.path().join("b.mcap"));
    for (name, orig) in &recorded {
        let back = &replayed[name];
        // The replay's recorder starts 0.3 s after load: it may miss the first
        // messages; from its first one on, everything comes back identical.
        let first = orig
            .iter()
            .position(|d| d.clock == back[0].clock)
            .unwrap_or_else(|| {
                panic!(
                    "{name}: replayed clock {} was never recorded",
                    back[0].clock
                )
            });
        assert!(
            first < orig.len() / 5,
            "{name}: the replay started at message {first}"
        );
        assert_eq!(
            &orig[first..],
            &back[..],
            "{name}: the replay differs from the recording"
        );
    }
}

#[test]
fn a_recording_killed_with_sigkill_replays_what_it_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let conf = simulator_conf(dir.path(), "k.mcap");
    let file = dir.path().join("k.mcap");
    let mut child = Command::new(BIN)
        .args(["--headless", "--no-shell"])
        .arg(&conf)
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Chunks are closed every second: wait until a few are on disk.
    let t0 = Instant::now();
    let enough = loop {
        let n = Summary::read(&file).map(|(s, _)| s.messages).unwrap_or(0);
        if n >= 100 {
            break true;
        }
        if t0.elapsed() > Duration::from_secs(60) {
            break false;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(enough, "the recorder wrote fewer than 100 messages in 60 s");

    let info = Command::new(BIN).arg("info").arg(&file).output().unwrap();
    let report = text(&info.stdout);
    assert!(info.status.success(), "{}", text(&info.stderr));
    assert!(report.contains("complete: NO"), "{report}");
    assert!(
        report.contains("laser") && report.contains("foxglove.LaserScan"),
        "{report}"
    );

    let (summary, written) = messages(&file);
    assert!(summary.messages >= 100);
    let replay = write(
        dir.path(),
        "replay.conf",
        "driver replay\nfile k.mcap\nspeed max\nprovides laser\nend_driver\n\
         service recorder\nfile back.mcap\nrecords laser\nend_service\n\
         load_driver replay\nload_service recorder\n",
    );
    // speed max publishes everything at once: the recorder keeps the latest.
    let out = run_for(&replay, 2.0);
    let err = text(&out.stderr);
    assert!(err.contains("cut short"), "the replay should warn: {err}");
    let (_, back) = messages(&dir.path().join("back.mcap"));
    let last = written["laser"].last().unwrap();
    let got = back["laser"].last().unwrap();
    assert_eq!(
        got, last,
        "the replay ends on the last complete laser message"
    );
}

/// Writes an MCAP file of one message: its schema (name, encoding, data), its
/// channel (topic, message encoding, metadata) and the message's bytes.
fn one_message_file(
    path: &Path,
    (schema, schema_encoding, schema_data): (&str, &str, &[u8]),
    (topic, encoding, metadata): (&str, &str, BTreeMap<String, String>),
    data: &[u8],
) {
    let mut w = mcap::Writer::new(std::fs::File::create(path).unwrap()).unwrap();
    let s = w.add_schema(schema, schema_encoding, schema_data).unwrap();
    let c = w.add_channel(s, topic, encoding, &metadata).unwrap();
    let header = mcap::records::MessageHeader {
        channel_id: c,
        sequence: 1,
        log_time: 1,
        publish_time: 1,
    };
    w.write_to_known_channel(&header, data).unwrap();
    w.finish().unwrap();
}

#[test]
fn info_and_replay_refuse_foreign_files_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let junk = write(dir.path(), "junk.mcap", "this is not an mcap file\n");
    let out = Command::new(BIN).arg("info").arg(&junk).output().unwrap();
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("junk.mcap") && err.contains("not an MCAP file"),
        "{err}"
    );

    // A real MCAP file whose channel jderobot did not write.
    let foreign = dir.path().join("foreign.mcap");
    one_message_file(
        &foreign,
        ("pkg/Thing", "ros2msg", b"int32 x"),
        ("/thing", "cdr", BTreeMap::new()),
        &[0, 1, 0, 0, 7, 0, 0, 0],
    );
    let out = Command::new(BIN)
        .arg("info")
        .arg(&foreign)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(
        text(&out.stdout).contains("(foreign)"),
        "{}",
        text(&out.stdout)
    );
    let conf = write(
        dir.path(),
        "f.conf",
        "driver replay\nfile foreign.mcap\nend_driver\nload_driver replay\n",
    );
    let out = Command::new(BIN).arg("check").arg(&conf).output().unwrap();
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("/thing") && err.contains("not written by jderobot"),
        "{err}"
    );

    // A recording of before images were protobuf (JSON foxglove.RawImage, base64).
    let old = dir.path().join("old.mcap");
    one_message_file(
        &old,
        ("foxglove.RawImage", "jsonschema", b"{}"),
        (
            "colorA",
            "json",
            BTreeMap::from([("jderobot.kind".to_string(), "image".to_string())]),
        ),
        br#"{"timestamp":{"sec":0,"nsec":1},"clock":1,"width":1,"height":1,"encoding":"bgr8","step":3,"data":"AAAA"}"#,
    );
    let conf = write(
        dir.path(),
        "o.conf",
        "driver replay\nfile old.mcap\nend_driver\nload_driver replay\n",
    );
    let out = Command::new(BIN).arg("check").arg(&conf).output().unwrap();
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("colorA") && err.contains("before") && err.contains("protobuf"),
        "{err}"
    );
}

#[test]
fn bad_conf_lines_name_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    for (body, want) in [
        (
            "service recorder\ncompression gzip\nend_service\nload_service recorder\n",
            "f.conf:2",
        ),
        (
            "service recorder\nsplit 10 GB\nend_service\nload_service recorder\n",
            "f.conf:2",
        ),
        (
            "service recorder\nimages jpeg 0\nend_service\nload_service recorder\n",
            "f.conf:2",
        ),
        (
            "service recorder\nrecords nosuch\nend_service\nload_service recorder\n",
            "nosuch",
        ),
        (
            "driver replay\nfile missing.mcap\nend_driver\nload_driver replay\n",
            "f.conf:2",
        ),
        (
            "driver replay\nspeed fast\nend_driver\nload_driver replay\n",
            "f.conf:2",
        ),
        (
            "driver replay\nbogus 1\nend_driver\nload_driver replay\n",
            "f.conf:2",
        ),
    ] {
        let conf = write(dir.path(), "f.conf", body);
        let out = Command::new(BIN).arg("check").arg(&conf).output().unwrap();
        let err = text(&out.stderr);
        assert!(!out.status.success(), "{body} passed check");
        assert!(err.contains(want), "{body}: {err}");
    }
    // `jderobot check` of a recorder conf leaves no file behind.
    let conf = simulator_conf(dir.path(), "never.mcap");
    let out = Command::new(BIN).arg("check").arg(&conf).output().unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(!dir.path().join("never.mcap").exists());
}

#[test]
fn split_starts_new_files_that_each_read_alone() {
    let dir = tempfile::tempdir().unwrap();
    let conf = write(
        dir.path(),
        "split.conf",
        &format!(
            "driver simulator\nworld {}\nprovides laser\nprovides colorA\nend_driver\n\
             service recorder\nfile parts/run.mcap\ncompression none\nsplit 1 MB\nend_service\n\
             load_driver simulator\nload_service recorder\n",
            world_path("simple.world")
        ),
    );
    run_for(&conf, 4.0);
    let parts = dir.path().join("parts");
    let mut files: Vec<_> = std::fs::read_dir(&parts)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    files.sort();
    // ~2.3 MB/s of 320x240 images: several files of about 1 MB (closed each second).
    assert!(files.len() >= 3, "{files:?}");
    assert!(
        files.contains(&"run.mcap".into()) && files.contains(&"run-1.mcap".into()),
        "{files:?}"
    );
    let mut last_clock = 0;
    for f in ["run.mcap", "run-1.mcap", "run-2.mcap"] {
        let (s, by) = messages(&parts.join(f));
        assert!(s.complete, "{f} is not closed");
        let laser = &by["laser"];
        assert!(
            laser[0].clock > last_clock,
            "{f}: clocks go on across files"
        );
        last_clock = laser.last().unwrap().clock;
    }
}

#[test]
fn jpeg_images_come_back_close_to_the_raw_ones() {
    // The robot stands still: every frame of a run is the same picture.
    let dir = tempfile::tempdir().unwrap();
    let mut firsts = Vec::new();
    for (file, images) in [("raw.mcap", "raw"), ("jpeg.mcap", "jpeg 90")] {
        let conf = write(
            dir.path(),
            "j.conf",
            &format!(
                "driver simulator\nworld {}\nprovides colorA\nend_driver\n\
                 service recorder\nfile {file}\nimages {images}\nend_service\n\
                 load_driver simulator\nload_service recorder\n",
                world_path("simple.world")
            ),
        );
        run_for(&conf, 1.5);
        let (summary, by) = messages(&dir.path().join(file));
        let schema = &summary.channels[0].schema;
        assert_eq!(
            schema,
            if images == "raw" {
                "foxglove.RawImage"
            } else {
                "foxglove.CompressedImage"
            }
        );
        match &by["colorA"][0].value {
            Recorded::Image(i) => firsts.push(i.clone()),
            other => panic!("{other:?}"),
        }
    }
    let (raw, jpeg) = (&firsts[0], &firsts[1]);
    assert_eq!((jpeg.width, jpeg.height), (raw.width, raw.height));
    let diff: f64 = raw
        .data
        .iter()
        .zip(&jpeg.data)
        .map(|(a, b)| (*a as f64 - *b as f64).abs())
        .sum::<f64>()
        / raw.data.len() as f64;
    assert!(
        diff < 4.0,
        "JPEG differs from raw by {diff:.2} per channel on average"
    );
    let sizes: Vec<u64> = ["raw.mcap", "jpeg.mcap"]
        .iter()
        .map(|f| std::fs::metadata(dir.path().join(f)).unwrap().len())
        .collect();
    eprintln!("raw {} bytes, jpeg {} bytes", sizes[0], sizes[1]);
}
