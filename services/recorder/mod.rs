//! recorder: records interfaces into an MCAP file (the log format of ROS 2,
//! Foxglove and copper-rs) that the `replay` driver, Foxglove Studio and Python's
//! `mcap` package read. See `docs/recording.md` and `examples/recorder.conf`.
//!
//! One channel per interface (topic = its name), with Foxglove's schemas where
//! they fit: `foxglove.RawImage` / `foxglove.CompressedImage` and
//! `foxglove.LaserScan` in protobuf, `foxglove.PoseInFrame` (encoders) in JSON, and
//! `jderobot.KIND` JSON schemas for the rest (a laser channel's range limits,
//! which `foxglove.LaserScan` has no fields for, in its metadata); every message carries the
//! interface's clock (the MCAP sequence) and the sample's wall time (the format is
//! `crate::mcapfmt`'s).
//!
//! # Conf
//! ```text
//! service recorder
//! records laser encoders colorA    # interfaces to record (repeatable); `records all` (default):
//!                                  #   every interface of a kind jderobot records, provided
//!                                  #   by the drivers loaded before the recorder
//! file run.mcap                    # relative to the conf; default recording-YYYYMMDD-HHMMSS.mcap
//!                                  #   in the current directory (UTC)
//! split 500 MB                     # start a new file (NAME-1.mcap, ...) past 500 MB, or `split 10 min`
//! compression zstd                 # zstd (default) | lz4 | none: chunk compression
//! images raw                       # raw: foxglove.RawImage bgr8 (default); jpeg [QUALITY]:
//!                                  #   foxglove.CompressedImage (quality 1..100, default 90)
//! profile foxglove                 # foxglove (default): Foxglove schemas (protobuf, JSON); ros2: rosbag2
//!                                  #   (CDR: LaserScan, Image, Odometry, Twist, Imu; other kinds skipped)
//! queue 64                         # messages waiting for the disk at most; more are dropped
//! start on                         # on (default): record from the start; off: wait for `record start`
//! end_service
//! ```
//!
//! # Interfaces and name space
//! It provides no interface. It uses the recorded ones (as a user, so drivers that
//! compute sensors only on demand compute them). It exports `recorder.status`
//! ([`RecorderStatus`](crate::mcapfmt::RecorderStatus)): the shell's `ps` and
//! `record status` print it (file, seconds, messages, MB, **dropped**), and
//! `record start|stop` switch it.
//!
//! Writing never blocks a schema: a poller thread, woken by each new value, takes
//! each new sample (shared, no copy; from the interface's short history, so a
//! wake-up delayed by a loaded machine loses nothing) into a bounded queue and a writer thread
//! encodes and writes it; when the queue is full the sample is dropped and counted.
//! Chunks are closed at least once a second, so a run killed mid-write loses at
//! most the last second.
//! Each closed chunk leaves its index (about 0.25 KB) in memory for the file's
//! summary until the file closes: about 1 MB per hour of one file, which `split`
//! bounds (see `docs/recording.md`, "Memory"; `scripts/soak.sh` measures it).
//!
//! Recording starts 0.3 s after the recorder is loaded (so that `jderobot check`,
//! which builds and shuts down every component at once, leaves no file behind);
//! the first message of each channel is the interface's latest value then.
//!
//! No system package is needed (zstd and lz4 are compiled in).

use std::{
    fs::File,
    path::{Path, PathBuf},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
        mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel},
    },
    thread::JoinHandle,
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use anyhow::Context as _;

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, choice, int, on_off, path, rest},
    },
    interfaces::{Interfaces, Watch},
    mcapfmt::{self, RecorderStatus, Snapshot, Source},
    runtime::{Driver, Runtime},
};

/// Where a file is cut into the next.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Split {
    None,
    Bytes(u64),
    Time(Duration),
}

/// The recorder's settings.
#[derive(Clone, Debug)]
struct Settings {
    records: Option<Vec<String>>,
    file: PathBuf,
    split: Split,
    compression: Option<mcap::Compression>,
    queue: usize,
    start: bool,
    /// The `ros2` profile: rosbag2-compatible CDR messages.
    ros2: bool,
    /// `images jpeg [QUALITY]`: foxglove.CompressedImage at this quality.
    jpeg: Option<u8>,
}

impl Settings {
    fn profile(&self) -> mcapfmt::Profile {
        if self.ros2 {
            mcapfmt::Profile::Ros2
        } else {
            mcapfmt::Profile::Foxglove { jpeg: self.jpeg }
        }
    }
}

fn utc_stamp(t: SystemTime) -> String {
    let secs = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0) as i64;
    let (days, rem) = (secs.div_euclid(86400), secs.rem_euclid(86400));
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

crate::declare_lines! {
    /// The recorder's lines, declared once (`jderobot help recorder`).
    struct Lines {
        records: Vec<Vec<String>> = Setting::new(
            "records",
            "interfaces to record, or all: every interface of a kind jderobot records, provided by \
             the drivers loaded before the recorder",
            &[rest("NAME...|all")],
        )
        .repeats(),
        file: Option<PathBuf> = Setting::new(
            "file",
            "the file (default recording-YYYYMMDD-HHMMSS.mcap in the current directory, UTC)",
            &[path("PATH")],
        ),
        split: Option<(u64, String)> = Setting::new(
            "split",
            "start a new file (NAME-1.mcap, ...) past this size or time",
            &[int("N", "", 1, 1_000_000), choice("UNIT", &["MB", "min"])],
        ),
        compression: String = Setting::new(
            "compression",
            "chunk compression",
            &[choice("COMPRESSION", &["zstd", "lz4", "none"])],
        )
        .default("zstd"),
        images: (String, Option<u8>) = Setting::new(
            "images",
            "raw: foxglove.RawImage bgr8; jpeg: foxglove.CompressedImage at QUALITY (default 90)",
            &[
                choice("FORMAT", &["raw", "jpeg"]),
                int("QUALITY", "", 1, 100).optional(),
            ],
        )
        .default("raw"),
        queue: usize = Setting::new(
            "queue",
            "messages waiting for the disk at most; more are dropped and counted",
            &[int("MESSAGES", "", 1, 100_000)],
        )
        .default("64"),
        profile: String = Setting::new(
            "profile",
            "foxglove: Foxglove schemas (protobuf, JSON); ros2: rosbag2 (CDR)",
            &[choice("PROFILE", &["foxglove", "ros2"])],
        )
        .default("foxglove"),
        start: bool = Setting::new(
            "start",
            "record from the start, or wait for `record start`",
            &[on_off("SWITCH")],
        )
        .default("on"),
    }
}
fn parse(conf: &ComponentConf) -> Result<Settings, crate::conf::ConfError> {
    let l: Lines = conf.read()?;
    // `records all` (or no records line): None; else every name on every line.
    let mut records: Option<Vec<String>> = None;
    for (line, words) in conf.lines_with("records").zip(&l.records) {
        if words.len() == 1 && words[0] == "all" {
            records = None;
        } else {
            let names = records.get_or_insert_with(Vec::new);
            for i in 0..words.len() {
                names.push(line.interface(i)?);
            }
        }
    }
    Ok(Settings {
        records,
        file: l.file.unwrap_or_else(|| {
            PathBuf::from(format!("recording-{}.mcap", utc_stamp(SystemTime::now())))
        }),
        split: match l.split {
            None => Split::None,
            Some((n, unit)) if unit == "MB" => Split::Bytes(n * 1_000_000),
            Some((n, _)) => Split::Time(Duration::from_secs(n * 60)),
        },
        compression: match l.compression.as_str() {
            "zstd" => Some(mcap::Compression::Zstd),
            "lz4" => Some(mcap::Compression::Lz4),
            _ => None,
        },
        queue: l.queue,
        start: l.start,
        ros2: l.profile == "ros2",
        jpeg: (l.images.0 == "jpeg").then_some(l.images.1.unwrap_or(90)),
    })
}

/// The running recorder.
pub struct Recorder {
    stop: Arc<AtomicBool>,
    poller: Option<JoinHandle<()>>,
    writer: Option<JoinHandle<()>>,
    status: Arc<RecorderStatus>,
    used: Vec<Source>,
}

/// Recording starts this long after the recorder is loaded.
const STARTUP_GRACE: Duration = Duration::from_millis(300);

type Item = (usize, Arc<str>, Snapshot);

/// The name of the `n`th file of a split recording: `run.mcap`, `run-1.mcap`, ...
fn nth_file(base: &Path, n: u32) -> PathBuf {
    if n == 0 {
        return base.to_path_buf();
    }
    let stem = base
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("recording");
    let ext = base.extension().and_then(|s| s.to_str()).unwrap_or("mcap");
    base.with_file_name(format!("{stem}-{n}.{ext}"))
}

/// Finds the sources to record (all recordable interfaces, or the named ones).
fn sources(interfaces: &Interfaces, records: &Option<Vec<String>>) -> anyhow::Result<Vec<Source>> {
    match records {
        None => Ok(interfaces
            .names()
            .iter()
            .filter_map(|n| Source::find(interfaces, n))
            .collect()),
        Some(names) => names
            .iter()
            .map(|n| {
                let any = interfaces
                    .get_any(n)
                    .with_context(|| format!("recorder: cannot record `{n}`"))?;
                Source::find(interfaces, n).ok_or_else(|| {
                    anyhow::anyhow!(
                        "recorder: `{n}` is a {} interface; jderobot records {}",
                        any.kind(),
                        crate::interfaces::Kind::NAMES.join(", ")
                    )
                })
            })
            .collect(),
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let settings = parse(conf)?;
    let status = Arc::new(RecorderStatus::default());
    status.want.store(settings.start, Ordering::Release);
    rt.names
        .export_arc("recorder", "status", status.clone())
        .context("recorder: only one recorder can run")?;
    let mut srcs = sources(&rt.interfaces, &settings.records)?;
    if srcs.is_empty() {
        tracing::warn!("recorder: no interface to record (load the drivers before the recorder)");
    }
    for s in &srcs {
        if !s.any().is_actuator() {
            s.any().resume();
        }
    }
    let used = srcs.clone();
    let (tx, rx) = sync_channel::<Item>(settings.queue);
    let stop = Arc::new(AtomicBool::new(false));
    let writer = {
        let status = status.clone();
        let settings = settings.clone();
        std::thread::Builder::new()
            .name("recorder-writer".into())
            .spawn(move || write_loop(rx, settings, status))?
    };
    let poller = {
        let status = status.clone();
        let stop = stop.clone();
        std::thread::Builder::new()
            .name("recorder-poller".into())
            .spawn(move || {
                poll_loop(&mut srcs, tx, &status, &stop);
            })?
    };
    Ok(Box::new(Recorder {
        stop,
        poller: Some(poller),
        writer: Some(writer),
        status,
        used,
    }))
}

/// Takes every new sample of every source into the queue; drops (and counts)
/// what does not fit.
fn poll_loop(
    srcs: &mut [Source],
    tx: SyncSender<Item>,
    status: &RecorderStatus,
    stop: &AtomicBool,
) {
    let names: Vec<Arc<str>> = srcs.iter().map(|s| Arc::from(s.any().name())).collect();
    let mut last: Vec<u64> = vec![0; srcs.len()];
    let mut was_recording = false;
    let mut fresh: Vec<(usize, Snapshot)> = Vec::with_capacity(srcs.len());
    let mut taken: Vec<Snapshot> = Vec::new();
    // A grace period: `jderobot check` builds and shuts down a recorder at once,
    // and must not leave a file behind.
    let t0 = Instant::now();
    while t0.elapsed() < STARTUP_GRACE {
        if stop.load(Ordering::Acquire) {
            return;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    // Woken by every new value instead of polling: no pass over the interfaces
    // while nothing changes, and a sample is taken within microseconds.
    let watch = Watch::for_current_thread();
    for s in srcs.iter() {
        s.any().watch(watch.clone());
        s.keep_history(true);
    }
    'poll: while !stop.load(Ordering::Acquire) {
        let want = status.want.load(Ordering::Acquire);
        if want && !was_recording {
            // A new file starts with the latest value of each interface.
            last.iter_mut().for_each(|l| *l = 0);
        }
        was_recording = want;
        if want {
            fresh.clear();
            for (i, s) in srcs.iter().enumerate() {
                let clock = s.any().clock();
                if clock == 0 || clock == last[i] {
                    continue;
                }
                if last[i] == 0 {
                    taken.push(s.snapshot());
                } else {
                    // Every sample since the last one taken, from the interface's
                    // history: a late wake-up loses nothing unless it is very late.
                    let gone = s.since(last[i], &mut taken);
                    status.dropped.fetch_add(gone, Ordering::Relaxed);
                }
                if let Some(newest) = taken.last() {
                    last[i] = newest.clock();
                }
                fresh.extend(taken.drain(..).map(|snap| (i, snap)));
            }
            // In publication order (a command and the sensing it caused can be
            // new in one pass): what a lock-step replay relies on.
            fresh.sort_by_key(|(_, s)| s.time());
            for (i, snap) in fresh.drain(..) {
                match tx.try_send((i, names[i].clone(), snap)) {
                    Ok(()) => {}
                    Err(TrySendError::Full(_)) => {
                        status.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                    Err(TrySendError::Disconnected(_)) => break 'poll,
                }
            }
        }
        // The timeout only bounds how late `stop` and `record start` are seen.
        watch.wait(Duration::from_millis(50));
    }
    for s in srcs.iter() {
        s.any().unwatch(&*watch);
        s.keep_history(false);
    }
}

/// One open file.
struct Open {
    writer: mcap::Writer<std::io::BufWriter<File>>,
    path: PathBuf,
    opened: Instant,
    channels: Vec<Option<u16>>,
}

fn open(settings: &Settings, n: u32) -> anyhow::Result<Open> {
    let path = nth_file(&settings.file, n);
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("recorder: cannot create directory {}", dir.display()))?;
    }
    let file = File::create(&path)
        .with_context(|| format!("recorder: cannot create {}", path.display()))?;
    let writer = mcapfmt::writer(file, settings.compression, settings.profile())
        .with_context(|| format!("recorder: cannot start {}", path.display()))?;
    Ok(Open {
        writer,
        path,
        opened: Instant::now(),
        channels: Vec::new(),
    })
}

fn close(o: Open, status: &RecorderStatus) {
    let Open {
        mut writer, path, ..
    } = o;
    if let Err(e) = writer.finish() {
        *status.error.lock() = Some(format!("{}: {e}", path.display()));
    }
    drop(writer);
    if let Ok(m) = std::fs::metadata(&path) {
        status.bytes.store(m.len(), Ordering::Relaxed);
    }
    status.recording.store(false, Ordering::Release);
}

fn write_one(
    o: &mut Open,
    item: &Item,
    buf: &mut Vec<u8>,
    settings: &Settings,
) -> anyhow::Result<()> {
    let profile = settings.profile();
    let (i, name, snap) = item;
    if o.channels.len() <= *i {
        o.channels.resize(*i + 1, None);
    }
    let channel = match o.channels[*i] {
        Some(c) => c,
        None => {
            let kind = snap.kind();
            let c = mcapfmt::add_sample_channel(&mut o.writer, name, snap, profile)?
                .unwrap_or_else(|| {
                    // Not in the profile: never written (said once, at the first sample).
                    tracing::warn!(
                        "recorder: profile ros2 carries {}; `{name}` ({kind}) is not recorded",
                        mcapfmt::ros2::kinds()
                            .iter()
                            .map(|k| k.name())
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                    u16::MAX
                });
            o.channels[*i] = Some(c);
            c
        }
    };
    if channel != u16::MAX {
        mcapfmt::write_sample(&mut o.writer, profile, channel, name, snap, buf)?;
    }
    Ok(())
}

/// Encodes and writes what the poller queues; opens, splits and closes files.
fn write_loop(rx: Receiver<Item>, settings: Settings, status: Arc<RecorderStatus>) {
    let mut file: Option<Open> = None;
    let mut n = 0u32;
    let mut buf = Vec::new();
    let mut flushed = Instant::now();
    loop {
        let item = rx.recv_timeout(Duration::from_millis(100));
        let want = status.want.load(Ordering::Acquire);
        if !want && let Some(o) = file.take() {
            close(o, &status);
        }
        match item {
            Ok(item) => {
                if !want {
                    continue;
                }
                if file.is_none() {
                    match open(&settings, n) {
                        Ok(o) => {
                            n += 1;
                            *status.file.lock() = Some((o.path.clone(), Instant::now()));
                            status.messages.store(0, Ordering::Relaxed);
                            status.bytes.store(0, Ordering::Relaxed);
                            status.recording.store(true, Ordering::Release);
                            file = Some(o);
                        }
                        Err(e) => {
                            tracing::error!("{e:#}");
                            *status.error.lock() = Some(format!("{e:#}"));
                            status.want.store(false, Ordering::Release);
                            continue;
                        }
                    }
                }
                let o = file.as_mut().expect("opened above");
                if let Err(e) = write_one(o, &item, &mut buf, &settings) {
                    let msg = format!("{}: {e:#}", o.path.display());
                    tracing::error!("recorder: {msg}; recording stops");
                    *status.error.lock() = Some(msg);
                    status.want.store(false, Ordering::Release);
                    continue;
                }
                status.messages.fetch_add(1, Ordering::Relaxed);
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if flushed.elapsed() >= Duration::from_secs(1) {
            flushed = Instant::now();
            if let Some(o) = file.as_mut() {
                // Close the chunk: a run killed now loses at most the last second.
                if let Err(e) = o.writer.flush() {
                    *status.error.lock() = Some(format!("{}: {e}", o.path.display()));
                }
                let len = std::fs::metadata(&o.path).map(|m| m.len()).unwrap_or(0);
                status.bytes.store(len, Ordering::Relaxed);
                let split = match settings.split {
                    Split::None => false,
                    Split::Bytes(b) => len >= b,
                    Split::Time(t) => o.opened.elapsed() >= t,
                };
                if split && let Some(o) = file.take() {
                    close(o, &status);
                }
            }
        }
    }
    if let Some(o) = file.take() {
        close(o, &status);
    }
}

impl Driver for Recorder {
    fn terminate(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(p) = self.poller.take() {
            let _ = p.join();
        }
        // The poller dropped its sender: the writer drains the queue and closes the file.
        if let Some(w) = self.writer.take() {
            let _ = w.join();
        }
        for s in &self.used {
            if !s.any().is_actuator() {
                s.any().suspend();
            }
        }
        tracing::info!("recorder: {}", self.status.line());
    }
}

/// The shell's `record start|stop|status`: through the loaded recorder's
/// `recorder.status`.
fn record(rt: &Runtime, args: &[&str], out: &mut dyn std::io::Write) -> Result<(), String> {
    use std::sync::atomic::Ordering;
    let status = rt
        .names
        .import::<RecorderStatus>("recorder", "status")
        .map_err(|_| "record: no recorder is loaded (load_service recorder)".to_string())?;
    let line = match args {
        ["start"] => {
            status.want.store(true, Ordering::Release);
            "recording".to_string()
        }
        ["stop"] => {
            status.want.store(false, Ordering::Release);
            // The writer closes the file within 0.1 s.
            let t0 = std::time::Instant::now();
            while status.recording.load(Ordering::Acquire)
                && t0.elapsed() < std::time::Duration::from_secs(5)
            {
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            status.line()
        }
        ["status"] | [] => status.line(),
        _ => return Err("record: Usage: record start|stop|status".into()),
    };
    writeln!(out, "{line}").map_err(|e| format!("record: {e}"))
}

crate::register_command!(
    "recorder",
    "record",
    "start|stop|status",
    "Start or stop the loaded recorder, or print what it wrote",
    record
);

crate::register_ps_line!("recorder", |rt| {
    rt.names
        .import::<RecorderStatus>("recorder", "status")
        .ok()
        .map(|s| s.line())
});

crate::register_driver!(
    Service,
    "recorder",
    "records interfaces into an MCAP file (Foxglove schemas, zstd/lz4) for replay, Foxglove and Python",
    create,
    lines = Lines
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_stamps() {
        assert_eq!(utc_stamp(UNIX_EPOCH), "19700101-000000");
        assert_eq!(
            utc_stamp(UNIX_EPOCH + Duration::from_secs(1_764_023_400)),
            "20251124-223000"
        );
    }

    #[test]
    fn split_names() {
        assert_eq!(
            nth_file(Path::new("a/run.mcap"), 0),
            Path::new("a/run.mcap")
        );
        assert_eq!(
            nth_file(Path::new("a/run.mcap"), 2),
            Path::new("a/run-2.mcap")
        );
    }
}
