//! replay: provides the interfaces recorded in an MCAP file (by the `recorder`
//! service) with their recorded clocks, values and wall times, so any schema runs
//! on a recording as on the robot. See `docs/recording.md` and `examples/replay.conf`.
//!
//! # Conf
//! ```text
//! driver replay
//! file run.mcap          # relative to the conf file
//! provides laser         # interfaces to provide (repeatable); none: every channel of the file
//! provides encoders
//! speed 1.0              # 1.0 = as recorded; N = N times faster; max = as fast as possible
//! loop off               # on: start again at the end
//! start 2.5              # seconds after the recording's first message (default 0)
//! end 8                  # seconds after the first message (default: the end)
//! stepped off            # on: publish only when the shell says `step [N]` (N messages);
//!                        #   motors: lock-step with the controller (below)
//! end_driver
//! ```
//!
//! Both profiles of the recorder are read: jderobot's (Foxglove schemas: images
//! and laser in protobuf, the rest JSON) and `ros2` (CDR: LaserScan, Image,
//! Odometry, Twist), where topic `/laser/robot2` is interface `laser.robot2`;
//! the clock is the MCAP message sequence (JSON messages carry it too).
//!
//! # Interfaces
//! Each recorded channel becomes the interface of the same name and kind (image
//! BGR, laser mm, encoders mm/rad, sonars mm, ...; see `crate::interfaces`). Each
//! message is published with its recorded clock (`Interface::publish_recorded`),
//! so a schema sees the clocks of the original run. Actuator channels (motors,
//! pantiltmotors) are provided so schemas can write them, but the recorded values
//! are not published and what schemas write moves nothing (a recorder running
//! beside the replay records it). When the replay ends (without `loop`), sensor
//! interfaces are marked stale ("replay: end of FILE"). In a loop, the clocks go on
//! increasing: the second pass publishes clock + the last clock of the first pass.
//!
//! A file cut short (a run killed mid-write) replays up to its last complete
//! chunk, with a warning naming what was lost; a corrupt chunk (its CRC, size or
//! records wrong) is skipped with a warning naming its offset, and the rest
//! replays (see `crate::mcapfmt::reader`); a file that is not MCAP, or a channel
//! of a kind jderobot does not know, is a clear error at load.
//!
//! # Lock-step (`stepped motors`): deterministic replay
//! The recording's motors messages cut it into steps: what the robot sensed after
//! each command. The replay publishes the first step at once, then the next one
//! each time a schema writes a new command to `motors`, whatever the schema's
//! timing. A controller that is a function of what it senses (introrob's VFF) then
//! sees the same inputs in the same order as in the live run (which ran the
//! simulator with `stepped MS`) and gives the same commands.
//!
//! # Name space
//! In `stepped on`, exports `replay.step` ([`StepGate`]); the shell's `step [N]`,
//! a command this driver registers, lets N messages through. Always exports the
//! run's clock `run.clock` ([`RunClock`]): the recorded time of the last message
//! published (the `ros2` service publishes it on `/clock`).
//!
//! No system package is needed. The file is read into memory whole (a regular
//! file of at most `mcapfmt::MAX_FILE_BYTES`).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use std::{collections::BTreeMap, ops::ControlFlow, path::PathBuf, sync::Arc};

use anyhow::{Context as _, bail};

use crate::{
    conf::{
        ComponentConf,
        settings::{NumberOr, Setting, choice, float, float_or, on_off, path, rest},
    },
    interfaces::Kind,
    mcapfmt::{self, Source, Summary},
    runtime::{Driver, RunClock, Runtime, Worker},
};

/// The replay's settings.
#[derive(Clone, Debug)]
struct Settings {
    file: PathBuf,
    provides: Vec<String>,
    /// None: as fast as possible.
    speed: Option<f64>,
    looping: bool,
    start: f64,
    end: Option<f64>,
    stepped: bool,
    /// Lock-step with the controller on the recording's `motors` channel.
    lockstep: bool,
}

crate::declare_lines! {
    /// The lines `replay` takes (`jderobot help replay` prints them).
    struct Lines {
        file: Option<String> = Setting::new(
            "file",
            "the MCAP recording to replay (required)",
            &[path("PATH.mcap")],
        ),
        provides: Vec<Vec<String>> = Setting::new(
            "provides",
            "the channels to provide (recorded names, robot suffixes included); none: every channel of the file",
            &[rest("NAME")],
        )
        .repeats(),
        speed: NumberOr = Setting::new(
            "speed",
            "the replay speed: 1 = as recorded, N = N times faster, max = as fast as possible",
            &[float_or("FACTOR", "", 0.001, 1000.0, "max")],
        )
        .default("1"),
        r#loop: bool = Setting::new("loop", "start again at the end", &[on_off("SWITCH")]).default("off"),
        start: f64 = Setting::new(
            "start",
            "where to begin, after the recording's first message",
            &[float("SECONDS", "s", 0.0, f64::MAX)],
        )
        .default("0"),
        end: Option<f64> = Setting::new(
            "end",
            "where to stop, after the recording's first message (default: the end)",
            &[float("SECONDS", "s", 0.0, f64::MAX)],
        ),
        stepped: Stepped = Setting::new(
            "stepped",
            "on: publish only when the shell says `step [N]`; motors: lock-step with the controller",
            &[choice("MODE", &["on", "off", "motors"])],
        )
        .default("off"),
    }
}

/// How a `stepped` line paces the replay.
#[derive(Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
enum Stepped {
    Off,
    On,
    /// Lock-step with the controller: a message per new motors command.
    Motors,
}

fn parse(conf: &ComponentConf) -> Result<Settings, crate::conf::ConfError> {
    let lines: Lines = conf.read()?;
    let mut s = Settings {
        file: PathBuf::new(),
        provides: lines.provides.into_iter().flatten().collect(),
        speed: match lines.speed {
            NumberOr::Number(n) => Some(n),
            NumberOr::Word => None,
        },
        looping: lines.r#loop,
        start: lines.start,
        end: lines.end,
        stepped: lines.stepped == Stepped::On,
        lockstep: lines.stepped == Stepped::Motors,
    };
    if lines.file.is_some()
        && let Some(line) = conf.line("file")
    {
        s.file = line.existing_file(0, "an MCAP file")?;
    }
    if let (Some(e), st) = (s.end, s.start)
        && e <= st
    {
        let line = conf.line("end").expect("end was read");
        return Err(line.error(format!("`end {e}` must be after `start {st}`")));
    }
    Ok(s)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let settings = parse(conf)?;
    if settings.file.as_os_str().is_empty() {
        bail!(
            "{}: driver {} needs a `file PATH.mcap` line",
            conf.file.display(),
            conf.name
        );
    }
    let (summary, bytes) = Summary::read(&settings.file)?;
    for c in &summary.corrupt {
        tracing::warn!(
            "replay: {} is corrupt {c}; that part is skipped, the rest is replayed",
            settings.file.display()
        );
    }
    if summary.orphans > 0 {
        tracing::warn!(
            "replay: {}: {} messages are skipped (their channel was defined in a corrupt chunk)",
            settings.file.display(),
            summary.orphans
        );
    }
    if let Some(lost) = &summary.lost {
        tracing::warn!(
            "replay: {} was cut short; it replays its {} complete messages ({lost})",
            settings.file.display(),
            summary.messages
        );
    }
    let wanted: Vec<String> = if settings.provides.is_empty() {
        summary.channels.iter().map(|c| c.name.clone()).collect()
    } else {
        settings.provides.clone()
    };
    let mut targets: BTreeMap<String, (Kind, Source)> = BTreeMap::new();
    for name in &wanted {
        let Some(c) = summary
            .channels
            .iter()
            .find(|c| &c.name == name || &c.topic == name)
        else {
            bail!(
                "replay: {} has no channel `{name}`; it has {}",
                settings.file.display(),
                summary
                    .channels
                    .iter()
                    .map(|c| c.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        };
        let Some(name) = c.kind.clone() else {
            bail!(
                "replay: channel `{}` of {} (schema `{}`, encoding `{}`) was not written by jderobot's recorder",
                c.topic,
                settings.file.display(),
                c.schema,
                c.encoding
            );
        };
        let kind = Kind::parse_or_list(&name)
            .map_err(|e| anyhow::anyhow!("replay: channel `{}`: {e}", c.name))?;
        if matches!(kind, Kind::Image | Kind::Laser) && c.encoding == "json" {
            bail!(
                "replay: channel `{}` of {} is a JSON {kind} channel (`{}`), recorded before jderobot wrote images and laser scans as protobuf; it is not read (record it again)",
                c.topic,
                settings.file.display(),
                c.schema
            );
        }
        let target = Source::provide(&rt.interfaces, &c.name, kind, &conf.name)
            .map_err(|e| anyhow::anyhow!("replay: channel `{}`: {e}", c.name))?;
        targets.insert(c.topic.clone(), (kind, target));
    }
    if settings.lockstep && !targets.values().any(|(kind, _)| *kind == Kind::Motors) {
        bail!(
            "{}: `stepped motors` needs a motors channel in {} (provided)",
            conf.name,
            settings.file.display()
        );
    }
    let gate = if settings.stepped {
        let g = Arc::new(StepGate::default());
        rt.names
            .export_arc("replay", "step", g.clone())
            .context("replay: only one stepped replay can run")?;
        Some(g)
    } else {
        None
    };
    let clock = RunClock::export(&rt.names, settings.lockstep)
        .map_err(|e| tracing::warn!("replay: its time is not the run's clock: {e}"))
        .ok();
    let stop = Arc::new(AtomicBool::new(false));
    let worker = {
        let flag = stop.clone();
        Worker::start("replay", stop, move || {
            run(
                &bytes,
                &summary,
                &settings,
                &targets,
                (gate.as_deref(), clock.as_deref()),
                &flag,
            )
        })?
    };
    Ok(Box::new(worker))
}

/// Publishes the file's messages, paced, until the end (or forever in a loop).
fn run(
    bytes: &[u8],
    summary: &Summary,
    settings: &Settings,
    targets: &BTreeMap<String, (Kind, Source)>,
    (gate, run_clock): (Option<&StepGate>, Option<&RunClock>),
    stop: &AtomicBool,
) {
    let from = summary.start_ns + (settings.start * 1e9) as u64;
    let to = settings
        .end
        .map(|e| summary.start_ns + (e * 1e9) as u64)
        .unwrap_or(u64::MAX);
    // Clocks keep increasing across loop passes.
    let mut offset = 0u64;
    let mut last_clock = 0u64;
    let mut errors = 0u32;
    // Lock-step: the motors interface and the clock of the last command seen.
    let motors = targets.values().find_map(|(_, t)| match t {
        Source::Motors(m) if settings.lockstep => Some(m.clone()),
        _ => None,
    });
    let mut seen = motors.as_ref().map(|m| m.clock()).unwrap_or(0);
    'passes: loop {
        let t0 = Instant::now();
        // The file was read whole once (the summary): its damage is known and
        // logged, and the same readable messages come again.
        let read = mcapfmt::reader::read_messages(bytes, |m| {
            if stop.load(Ordering::Acquire) {
                return ControlFlow::Break(());
            }
            if m.log_time < from || m.log_time > to {
                return ControlFlow::Continue(());
            }
            let Some((kind, target)) = targets.get(&m.channel.topic) else {
                return ControlFlow::Continue(());
            };
            if let (Some(motors), Source::Motors(_)) = (&motors, target) {
                // A recorded command: the next step waits for the schema's own.
                while motors.clock() == seen {
                    if stop.load(Ordering::Acquire) {
                        return ControlFlow::Break(());
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                seen = motors.clock();
                return ControlFlow::Continue(());
            }
            if motors.is_some() {
                // lock-step: no pacing
            } else if let Some(g) = gate {
                while !g.take(Duration::from_millis(100)) {
                    if stop.load(Ordering::Acquire) {
                        return ControlFlow::Break(());
                    }
                }
            } else if let Some(speed) = settings.speed {
                let due = t0 + Duration::from_secs_f64((m.log_time - from) as f64 / 1e9 / speed);
                while let Some(wait) = due.checked_duration_since(Instant::now()) {
                    if stop.load(Ordering::Acquire) {
                        return ControlFlow::Break(());
                    }
                    std::thread::sleep(wait.min(Duration::from_millis(50)));
                }
            }
            match mcapfmt::decode_read(*kind, m) {
                Ok(d) => {
                    last_clock = last_clock.max(d.clock.saturating_add(offset));
                    let (clock, time) = (
                        d.clock.saturating_add(offset),
                        mcapfmt::from_nanos(d.time_ns),
                    );
                    if let Some(c) = run_clock {
                        c.set(time);
                    }
                    if let Err(e) = target.publish_recorded(clock, time, d.value) {
                        errors += 1;
                        if errors <= 5 {
                            tracing::warn!("replay: {e}");
                        }
                    }
                }
                Err(e) => {
                    errors += 1;
                    if errors <= 5 {
                        tracing::warn!("replay: {}: {e}", settings.file.display());
                    }
                }
            }
            if let Some(g) = gate {
                g.published.fetch_add(1, Ordering::Relaxed);
            }
            ControlFlow::Continue(())
        });
        match read {
            Ok(o) if o.stopped => return,
            Ok(_) => {}
            Err(e) => {
                tracing::error!("replay: {}: {e}", settings.file.display());
                break;
            }
        }
        if !settings.looping {
            break 'passes;
        }
        offset = last_clock;
    }
    let why = format!("replay: end of {}", settings.file.display());
    for (_, t) in targets.values() {
        if !t.any().is_actuator() {
            t.any().set_stale(&why);
        }
    }
}

/// The replay's step gate in `stepped` mode, exported as `replay.step`: the shell's
/// `step [N]` lets N more messages through.
#[derive(Default)]
pub struct StepGate {
    permits: parking_lot::Mutex<u64>,
    cv: parking_lot::Condvar,
    /// Messages published so far.
    pub published: std::sync::atomic::AtomicU64,
}

impl StepGate {
    /// Lets `n` more messages through.
    pub fn step(&self, n: u64) {
        *self.permits.lock() += n;
        self.cv.notify_all();
    }

    /// Takes one permit, waiting up to `timeout`; false if none came.
    pub fn take(&self, timeout: Duration) -> bool {
        let mut p = self.permits.lock();
        if *p == 0 {
            self.cv.wait_for(&mut p, timeout);
        }
        if *p > 0 {
            *p -= 1;
            true
        } else {
            false
        }
    }
}

/// The shell's `step [N]`: lets a stepped replay publish N more messages.
fn step(rt: &Runtime, args: &[&str], out: &mut dyn std::io::Write) -> Result<(), String> {
    use std::sync::atomic::Ordering;
    let n = match args {
        [] => 1,
        [n] => n
            .parse::<u64>()
            .ok()
            .filter(|n| (1..=1_000_000).contains(n))
            .ok_or_else(|| format!("step: `{n}` is not a count from 1 to 1000000"))?,
        _ => return Err("step: Usage: step [N]".into()),
    };
    let gate = rt.names.import::<StepGate>("replay", "step").map_err(|_| {
        "step: no stepped replay is loaded (driver replay with `stepped on`)".to_string()
    })?;
    let before = gate.published.load(Ordering::Acquire);
    gate.step(n);
    let t0 = std::time::Instant::now();
    while gate.published.load(Ordering::Acquire) < before + n
        && t0.elapsed() < Duration::from_secs(2)
    {
        std::thread::sleep(Duration::from_millis(2));
    }
    writeln!(
        out,
        "replay: {} messages published",
        gate.published.load(Ordering::Acquire)
    )
    .map_err(|e| format!("step: {e}"))
}

crate::register_command!(
    "replay",
    "step",
    "[N]",
    "Let a stepped replay publish its next N messages (default 1)",
    step
);

crate::register_driver!(
    Driver,
    "replay",
    "provides the interfaces recorded in an MCAP file, with their recorded clocks (speed, loop, start/end, stepped)",
    create,
    lines = Lines
);
