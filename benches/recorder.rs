//! recorder and replay benchmarks (harness = false; medians of 5 rounds):
//!
//! 1. Write throughput: the writer's path (encode + MCAP chunk writing, no
//!    compression and zstd) for the load "640x480 BGR at 30 fps + laser 10 Hz +
//!    encoders 20 Hz + sonars 10 Hz", as seconds of robot time written per wall
//!    second (x real time), to disk and to memory (/dev/shm). Reference, in the
//!    same alternated rounds: the frames' pixels alone written with `write_all`.
//! 2. The recorder service at 1x on that load for 5 s: messages dropped, CPU of
//!    its threads (recorder-poller + recorder-writer, from /proc) as % of one core.
//! 3. The replay driver at `speed max`: laser messages/s and 640x480 frames/s
//!    published into interfaces.
//! 4. File size of 10 s of the simulator (colorA, laser, encoders, sonars): zstd,
//!    lz4 and no compression.
//!
//! Run: `cargo bench --features full --bench recorder` (`-- write`: only 1).

mod common;
use common::{
    load::{noisy_image, one_second},
    median, percentile, threads_cpu,
};

use std::{
    io::Write,
    path::{Path, PathBuf},
    sync::{Arc, atomic::Ordering},
    time::{Duration, Instant, SystemTime},
};

use jderobot::{
    Conf, Runtime,
    conf::Kind,
    interfaces::{Encoders, Image, Interface, Laser, Sonars},
    loader,
    mcapfmt::{self, Profile, RecorderStatus, Snapshot},
};

fn write_file(
    path: &Path,
    compression: Option<mcap::Compression>,
    seconds: &[Vec<(&str, Snapshot)>],
) -> u64 {
    write_profile(path, compression, seconds, Profile::Foxglove { jpeg: None })
}

/// The recorder's writer path: a channel per interface, each sample encoded and
/// written with its clock as the sequence.
fn write_profile(
    path: &Path,
    compression: Option<mcap::Compression>,
    seconds: &[Vec<(&str, Snapshot)>],
    profile: Profile,
) -> u64 {
    let mut w =
        mcapfmt::writer(std::fs::File::create(path).unwrap(), compression, profile).unwrap();
    let mut channels = std::collections::HashMap::new();
    let mut buf = Vec::new();
    for sec in seconds {
        for (name, snap) in sec {
            let id = *channels.entry(*name).or_insert_with(|| {
                mcapfmt::add_channel(&mut w, name, snap.kind(), profile).unwrap()
            });
            if let Some(id) = id {
                mcapfmt::write_sample(&mut w, profile, id, name, snap, &mut buf).unwrap();
            }
        }
    }
    w.finish().unwrap();
    std::fs::metadata(path).unwrap().len()
}

/// The reference writer: the frames' pixels back to back with `write_all`.
fn write_raw(path: &Path, seconds: &[Vec<(&str, Snapshot)>]) -> u64 {
    let mut f = std::fs::File::create(path).unwrap();
    for (_, snap) in seconds.iter().flatten() {
        if let Snapshot::Image(s) = snap {
            f.write_all(&s.value.data).unwrap();
        }
    }
    drop(f);
    std::fs::metadata(path).unwrap().len()
}

/// x real time of each writer to each target (`[writer][target]`, 5 rounds, the
/// order reversed every other round so none always runs first) and a file's size.
fn rounds(
    targets: &[(&str, PathBuf)],
    writers: &[&dyn Fn(&Path) -> u64],
    secs: u64,
) -> (Vec<Vec<Vec<f64>>>, u64) {
    let mut xs = vec![vec![Vec::new(); targets.len()]; writers.len()];
    let mut size = 0;
    let jobs: Vec<(usize, usize)> = (0..writers.len())
        .flat_map(|w| (0..targets.len()).map(move |t| (w, t)))
        .collect();
    for round in 0..5 {
        for j in 0..jobs.len() {
            let (w, t) = jobs[if round % 2 == 0 {
                j
            } else {
                jobs.len() - 1 - j
            }];
            let start = Instant::now();
            let n = writers[w](&targets[t].1);
            xs[w][t].push(secs as f64 / start.elapsed().as_secs_f64());
            if w == 0 {
                size = n;
            }
            let _ = std::fs::remove_file(&targets[t].1);
        }
    }
    (xs, size)
}

fn main() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = SystemTime::now();
    let secs = 5u64;
    let load: Vec<_> = (0..secs).map(|s| one_second(t0, s)).collect();
    let raw_mb_s = 640.0 * 480.0 * 3.0 * 30.0 / 1e6;
    println!(
        "## recorder / replay (load: 640x480 BGR 30 fps + laser 10 Hz + encoders 20 Hz + sonars 10 Hz = {raw_mb_s:.1} MB/s of pixels)"
    );
    write_throughput(dir.path(), &load, secs);
    // `write` as an argument: only the write throughput.
    if std::env::args().any(|a| a == "write") {
        return;
    }

    recorder_service(dir.path());
    replay_speed(dir.path(), t0);
    simulator_file_size(dir.path());
}

/// Step 1, write throughput: to a file in the temporary directory (on this machine's
/// disk, through the page cache) and, where there is one, to a file in /dev/shm
/// (memory: what the recorder's own path can do, whatever the disk).
fn write_throughput(dir: &Path, load: &[Vec<(&str, Snapshot)>], secs: u64) {
    let shm = tempfile::tempdir_in("/dev/shm").ok();
    let targets: Vec<(&str, PathBuf)> = std::iter::once(("disk", dir.join("w.mcap")))
        .chain(shm.as_ref().map(|d| ("memory", d.path().join("w.mcap"))))
        .collect();
    let foxglove = Profile::Foxglove { jpeg: None };
    // The reference, in the same rounds as the recorder's path without compression:
    // the frames' pixels alone written to the same file with `write_all` (no MCAP).
    let raw = |p: &Path| write_raw(p, load);
    for (label, c, profile) in [
        ("none", None, foxglove),
        ("lz4", Some(mcap::Compression::Lz4), foxglove),
        ("zstd", Some(mcap::Compression::Zstd), foxglove),
        (
            "none, profile ros2 (CDR; sonars not carried)",
            None,
            Profile::Ros2,
        ),
    ] {
        let ours = |p: &Path| write_profile(p, c, load, profile);
        let writers: Vec<&dyn Fn(&Path) -> u64> = if label == "none" {
            vec![&ours as &dyn Fn(&Path) -> u64, &raw]
        } else {
            vec![&ours as &dyn Fn(&Path) -> u64]
        };
        let (xs, size) = rounds(&targets, &writers, secs);
        for (k, (to, _)) in targets.iter().enumerate() {
            println!(
                "write throughput to {to}, compression {label}: median {:.1}x real time, rounds {:.1}-{:.1}x ({} MB for {secs} s)",
                median(&xs[0][k]),
                percentile(&xs[0][k], 0.0),
                percentile(&xs[0][k], 1.0),
                size / 1_000_000
            );
            if writers.len() > 1 {
                let ratio: Vec<f64> = xs[0][k].iter().zip(&xs[1][k]).map(|(a, b)| a / b).collect();
                println!(
                    "  reference, the pixels alone with write_all to {to}: median {:.1}x real time; the recorder's path is {:.0} % of it (rounds {:.0}-{:.0} %)",
                    median(&xs[1][k]),
                    median(&ratio) * 100.0,
                    percentile(&ratio, 0.0) * 100.0,
                    percentile(&ratio, 1.0) * 100.0
                );
            }
        }
    }
}

/// Step 2, the recorder service at 1x: messages written and dropped, its threads' CPU.
fn recorder_service(dir: &Path) {
    let conf_path = dir.join("rec.conf");
    std::fs::write(
        &conf_path,
        "service recorder\nfile live.mcap\ncompression none\nend_service\n",
    )
    .unwrap();
    let conf = Conf::load(&conf_path).unwrap();
    let rt: Arc<Runtime> = Runtime::new(&conf_path);
    let cam: Arc<Interface<Image>> = rt.interfaces.provide("varcolorA", "bench").unwrap();
    let laser: Arc<Interface<Laser>> = rt.interfaces.provide("laser", "bench").unwrap();
    let enc: Arc<Interface<Encoders>> = rt.interfaces.provide("encoders", "bench").unwrap();
    let son: Arc<Interface<Sonars>> = rt.interfaces.provide("sonars", "bench").unwrap();
    loader::load(&rt, &conf, Some(Kind::Service), "recorder", None).unwrap();
    let status = rt
        .names
        .import::<RecorderStatus>("recorder", "status")
        .unwrap();
    std::thread::sleep(Duration::from_millis(400));
    let cpu0 = threads_cpu("recorder-");
    let start = Instant::now();
    let imgs = [noisy_image(1), noisy_image(2)];
    let mut k = 0u64;
    let run = Duration::from_secs(5);
    while start.elapsed() < run {
        let due = start + Duration::from_millis(k * 1000 / 60);
        if let Some(w) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(w);
        }
        if k.is_multiple_of(2) {
            cam.publish(imgs[(k / 2 % 2) as usize].clone()).unwrap();
        }
        if k.is_multiple_of(3) {
            enc.publish(Encoders {
                x: k as f32,
                ..Encoders::default()
            })
            .unwrap();
        }
        if k.is_multiple_of(6) {
            laser
                .publish(Laser {
                    readings: vec![1000 + k as i32; 180],
                    resolution: 1.0,
                    ..Laser::default()
                })
                .unwrap();
            son.publish(Sonars {
                us: vec![k as f32; 16],
            })
            .unwrap();
        }
        k += 1;
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = threads_cpu("recorder-") - cpu0;
    let written = status.messages.load(Ordering::Relaxed);
    let dropped = status.dropped.load(Ordering::Relaxed);
    rt.shutdown();
    println!(
        "recorder service at 1x for {wall:.1} s: {written} messages written, {dropped} dropped, recorder threads CPU {:.0} % of one core",
        cpu / wall * 100.0
    );
}

/// Step 3, the replay driver at `speed max`: laser messages/s and 640x480 frames/s.
fn replay_speed(dir: &Path, t0: SystemTime) {
    for (what, keep) in [("laser messages", "laser"), ("640x480 frames", "camera")] {
        let file = dir.join(format!("{keep}.mcap"));
        let n_secs: u64 = if keep == "laser" { 100 } else { 10 };
        let only: Vec<Vec<(&str, Snapshot)>> = (0..n_secs)
            .map(|s| {
                let mut v = one_second(t0, s);
                v.retain(|(n, _)| *n == keep);
                // laser: 10 per second; stretch to 100 per second of file
                v
            })
            .collect();
        write_file(&file, Some(mcap::Compression::Zstd), &only);
        let count: usize = only.iter().map(Vec::len).sum();
        let mut rates = Vec::new();
        for _ in 0..3 {
            let conf_path = dir.join("replay.conf");
            std::fs::write(
                &conf_path,
                format!(
                    "driver replay\nfile {}\nspeed max\nend_driver\n",
                    file.display()
                ),
            )
            .unwrap();
            let conf = Conf::load(&conf_path).unwrap();
            let rt: Arc<Runtime> = Runtime::new(&conf_path);
            let t = Instant::now();
            loader::load(&rt, &conf, Some(Kind::Driver), "replay", None).unwrap();
            let iface = rt.interfaces.get_any(keep).unwrap();
            let last = only.last().unwrap().last().unwrap().1.clock();
            while iface.clock() < last {
                std::thread::sleep(Duration::from_micros(200));
            }
            rates.push(count as f64 / t.elapsed().as_secs_f64());
            rt.shutdown();
        }
        println!(
            "replay speed max: median {:.0} {what}/s ({count} in the file)",
            median(rates)
        );
    }
}

/// Step 4, file size of 10 s of the simulator: raw, zstd and lz4.
fn simulator_file_size(dir: &Path) {
    let conf_path = dir.join("sim.conf");
    std::fs::write(
        &conf_path,
        format!(
            "driver simulator\nworld {}/assets/worlds/simple.world\nprovides encoders\nprovides motors\n\
             provides laser\nprovides sonars\nprovides colorA\npublish_always on\nend_driver\n\
             service recorder\nfile sim.mcap\ncompression none\nend_service\n\
             load_driver simulator\nload_service recorder\n",
            env!("CARGO_MANIFEST_DIR")
        ),
    )
    .unwrap();
    let conf = Conf::load(&conf_path).unwrap();
    let rt = loader::start(&conf).unwrap();
    let motors = rt
        .interfaces
        .get::<jderobot::interfaces::Motors>("motors")
        .unwrap();
    let t = Instant::now();
    while t.elapsed() < Duration::from_secs(10) {
        motors
            .publish(jderobot::interfaces::Motors { v: 200.0, w: 10.0 })
            .unwrap();
        std::thread::sleep(Duration::from_millis(100));
    }
    rt.shutdown();
    let raw = dir.join("sim.mcap");
    let raw_size = std::fs::metadata(&raw).unwrap().len();
    // The same messages rewritten with zstd and lz4 chunks.
    let bytes = std::fs::read(&raw).unwrap();
    for (label, c) in [
        ("zstd", mcap::Compression::Zstd),
        ("lz4", mcap::Compression::Lz4),
    ] {
        let out = dir.join(format!("sim-{label}.mcap"));
        let mut w = mcap::WriteOptions::new()
            .compression(Some(c))
            .chunk_size(Some(4 * 1024 * 1024))
            .create(std::fs::File::create(&out).unwrap())
            .unwrap();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            w.write(&m.unwrap()).unwrap();
        }
        w.finish().unwrap();
        let size = std::fs::metadata(&out).unwrap().len();
        println!(
            "10 s of the simulator (colorA, laser, encoders, sonars, motors): raw {:.2} MB, {label} {:.2} MB (ratio {:.1}x)",
            raw_size as f64 / 1e6,
            size as f64 / 1e6,
            raw_size as f64 / size as f64
        );
    }
}
