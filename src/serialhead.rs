//! The serial-head core: what the drivers of heads on a serial line (`pantilt`, a
//! PTU-46; `evi`, an EVI-D100) share.
//!
//! - Their shared lines, declared once: [`SERIAL`], [`POLL`] (each head gives its
//!   own default), [`REPLY_TIMEOUT`]; a head puts them and its `provides` line in
//!   the group [`HEAD`], read as [`HeadLines`] and checked by [`HeadConf::new`].
//! - [`open_port`]: the one place a serial port is opened, with errors that say
//!   what to check (a missing device, a file that is not a tty, permissions);
//!   [`read_some`], the one way a head's link reads it.
//! - [`PollClock`], the position polls' schedule, and [`supervise`], a head under
//!   the supervisor (retried every second).
//!
//! Each driver keeps its protocol, its link and its session; the supervisor
//! ([`crate::runtime::Supervisor`]) owns their threads, retries and stale marking.

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{Setting, int, word},
    },
    interfaces::{AnyInterface, canonical},
    runtime::{Backoff, Device, Supervision, Supervisor},
};

/// `serial DEVICE`: the port the head is on (required).
pub const SERIAL: Setting = Setting::new(
    "serial",
    "the serial port the head is on, e.g. /dev/ttyUSB0",
    &[word("DEVICE")],
)
.required();
/// `poll MS`: the time between position queries (give the head's default).
pub const POLL: Setting = Setting::new(
    "poll",
    "the time between position queries",
    &[int("MS", "ms", 10, 10_000)],
);
/// `reply_timeout MS`: how long an answer may take.
pub const REPLY_TIMEOUT: Setting = Setting::new(
    "reply_timeout",
    "how long an answer may take before the head counts as silent",
    &[int("MS", "ms", 10, 60_000)],
)
.default("1000");

/// The group of a head's shared lines (`serial`, `poll`, `reply_timeout`,
/// `provides`: [`crate::conf::settings::Setting::group`]), read as [`HeadLines`].
pub const HEAD: &str = "head";

/// The values of the group [`HEAD`].
#[derive(serde::Deserialize)]
pub struct HeadLines {
    pub serial: String,
    pub poll: u64,
    pub reply_timeout: u64,
    pub provides: Vec<String>,
}

/// The shared lines of a head, read and checked.
#[derive(Clone, Debug)]
pub struct HeadConf {
    pub serial: String,
    pub poll: Duration,
    pub reply_timeout: Duration,
    /// The provided interfaces, canonical names (4.3's aliases resolved).
    pub provides: Vec<String>,
}

impl HeadConf {
    /// From the values of the shared lines (`provides` as written). `offered`
    /// names what the head can provide, for the error when it provides nothing.
    pub fn new(conf: &ComponentConf, l: HeadLines, offered: &[&str]) -> anyhow::Result<HeadConf> {
        if l.provides.is_empty() {
            anyhow::bail!(
                "{}: driver {} provides nothing; add one or more of `provides {}`",
                conf.file.display(),
                conf.name,
                offered.join("`, `provides ")
            );
        }
        Ok(HeadConf {
            serial: l.serial,
            poll: Duration::from_millis(l.poll),
            reply_timeout: Duration::from_millis(l.reply_timeout),
            provides: l.provides.iter().map(|p| canonical(p)).collect(),
        })
    }

    /// Whether `name` (canonical) is provided.
    pub fn provides(&self, name: &str) -> bool {
        self.provides.iter().any(|p| p == name)
    }

    /// Opens the `serial` port at `baud`; `device` names what should be on it.
    pub fn open(
        &self,
        baud: u32,
        device: &str,
    ) -> Result<Box<dyn serialport::SerialPort>, PortError> {
        open_port(&self.serial, baud, device).map_err(|what| PortError::Open {
            port: self.serial.clone(),
            what,
        })
    }
}

/// A head's port that could not be opened, or failed in use.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    #[error("{port}: {what}")]
    Open { port: String, what: String },
    /// `device` names what is on the port ("the unit").
    #[error("{port}: the port failed ({what}); was {device} unplugged?")]
    Io {
        port: String,
        what: String,
        device: &'static str,
    },
}

/// Opens `path` as a serial port at `baud` (reads time out after 5 ms), or says
/// what is wrong and what to check; `device` names what should be on it ("the
/// unit").
pub fn open_port(
    path: &str,
    baud: u32,
    device: &str,
) -> Result<Box<dyn serialport::SerialPort>, String> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(format!(
                "does not exist (is {device} plugged in? `ls /dev/ttyUSB* /dev/ttyS*` lists the ports)"
            ));
        }
        Err(e) => return Err(format!("cannot be read: {e}")),
        Ok(m) if m.is_file() || m.is_dir() => {
            return Err(
                "is not a serial device (a regular file or directory); check the `serial` line"
                    .into(),
            );
        }
        Ok(_) => {}
    }
    serialport::new(path, baud)
        .timeout(Duration::from_millis(5))
        .open()
        .map_err(|e| match e.kind() {
            serialport::ErrorKind::Io(std::io::ErrorKind::PermissionDenied) => format!(
                "permission denied ({e}); add your user to the group that owns it (`ls -l {path}`, usually `dialout`)"
            ),
            serialport::ErrorKind::NoDevice => {
                format!("no device ({e}); is {device} plugged in?")
            }
            _ => format!("cannot be opened as a serial port: {e}"),
        })
}

/// Reads what has arrived on `port` into `buf`: `Some(bytes)`, or `None` when
/// nothing came within the port's timeout; a port that ends (unplugged) is an
/// `UnexpectedEof` error.
pub fn read_some(
    port: &mut dyn serialport::SerialPort,
    buf: &mut [u8],
) -> std::io::Result<Option<usize>> {
    match port.read(buf) {
        Ok(0) => Err(std::io::ErrorKind::UnexpectedEof.into()),
        Ok(n) => Ok(Some(n)),
        Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Ok(None),
        Err(e) => Err(e),
    }
}

/// When a head's position is polled: every `period` on absolute deadlines (the
/// period does not drift with the reply time; a late poll does not bunch up).
pub struct PollClock {
    next: Instant,
    period: Duration,
}

impl PollClock {
    /// A poll is due at once.
    pub fn new(period: Duration) -> PollClock {
        PollClock {
            next: Instant::now(),
            period,
        }
    }

    /// Whether a poll is due (then the next one is scheduled).
    pub fn due(&mut self) -> bool {
        let now = Instant::now();
        if now < self.next {
            return false;
        }
        self.next += self.period;
        if self.next < now {
            self.next = now + self.period;
        }
        true
    }

    /// Sleeps until the next poll, half a millisecond at most: commands go out
    /// within that of being set, polls on time.
    pub fn pause(&self) {
        let wait = self.next.saturating_duration_since(Instant::now());
        std::thread::sleep(wait.min(Duration::from_micros(500)));
    }
}

/// Starts supervising `head` as `provider` with its `interfaces` (those provided):
/// a port that cannot be opened, or a head that does not answer, is tried again
/// every second; the rest of the run goes on.
pub fn supervise<D: Device>(
    provider: &str,
    interfaces: impl IntoIterator<Item = Option<Arc<dyn AnyInterface>>>,
    head: D,
) -> anyhow::Result<Supervisor> {
    Supervisor::start(
        Supervision {
            name: provider.to_string(),
            interfaces: interfaces.into_iter().flatten().collect(),
            on_demand: false,
            backoff: Backoff::fixed(Duration::from_secs(1)),
            absent: None,
        },
        head,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conf::Kind;

    #[test]
    fn open_port_says_what_the_path_is() {
        let e = open_port("/nonexistent/tty", 9600, "the unit")
            .err()
            .unwrap();
        assert!(e.contains("does not exist (is the unit plugged in?"), "{e}");
        let e = open_port("/", 9600, "the unit").err().unwrap();
        assert!(e.contains("not a serial device"), "{e}");
    }

    #[test]
    fn serial_and_provides_are_required() {
        let conf = ComponentConf::from_text(Kind::Driver, "head", "").unwrap();
        let e = conf.check(&[SERIAL]).unwrap_err().to_string();
        assert!(
            e.contains("has no `serial` line") && e.contains("serial DEVICE"),
            "{e}"
        );
        let lines = |provides: &[&str]| HeadLines {
            serial: "/dev/x".into(),
            poll: 100,
            reply_timeout: 1000,
            provides: provides.iter().map(|p| p.to_string()).collect(),
        };
        let e = HeadConf::new(&conf, lines(&[]), &["a", "b"]);
        let e = e.unwrap_err().to_string();
        assert!(
            e.contains("add one or more of `provides a`, `provides b`"),
            "{e}"
        );
        let c = HeadConf::new(&conf, lines(&["ptmotors"]), &[]);
        assert!(c.unwrap().provides("pantiltmotors"));
    }
}
