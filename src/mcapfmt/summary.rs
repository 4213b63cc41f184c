//! What a file holds, read message by message with the bounded reader
//! ([`read_messages`]), so a file cut short or corrupt still says what it has
//! and where it is damaged: for `jderobot info`, the replay driver and `check`.

use std::{collections::BTreeMap, fmt::Write as _, io::Read as _, ops::ControlFlow, path::Path};

use super::{channel_kind_name, interface_name, reader::read_messages};

/// One channel of a file.
#[derive(Clone, Debug, Default)]
pub struct ChannelSummary {
    pub topic: String,
    /// The interface it replays into (`laser` for topic `/laser` in a ros2 file).
    pub name: String,
    /// The interface kind (`laser`...), if the channel is one jderobot reads.
    pub kind: Option<String>,
    pub schema: String,
    pub encoding: String,
    pub messages: u64,
    pub first_ns: u64,
    pub last_ns: u64,
}

impl ChannelSummary {
    /// Messages per second over the channel's span.
    pub fn rate(&self) -> f64 {
        if self.messages < 2 || self.last_ns <= self.first_ns {
            return 0.0;
        }
        (self.messages - 1) as f64 / ((self.last_ns - self.first_ns) as f64 / 1e9)
    }
}

/// What a file holds.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub channels: Vec<ChannelSummary>,
    pub messages: u64,
    pub start_ns: u64,
    pub end_ns: u64,
    pub bytes: u64,
    /// The MCAP profile (`ros2` for rosbag2 files, empty for jderobot's own).
    pub profile: String,
    /// The file ends with its footer and magic (it was closed properly).
    pub complete: bool,
    /// Why reading stopped early (a file cut short: the rest is lost).
    pub lost: Option<String>,
    /// The corrupt places (`at byte N: what`), each skipped; the rest was read.
    pub corrupt: Vec<String>,
    /// Messages whose channel record is lost (in a corrupt chunk).
    pub orphans: u64,
}

/// Errors reading a file.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: not an MCAP file ({error})")]
    NotMcap { path: String, error: String },
    #[error(
        "{path}: {what}; jderobot reads recordings from regular files of at most {max} bytes (it holds them in memory)"
    )]
    NotReadable {
        path: String,
        what: String,
        max: u64,
    },
}

/// The largest file read (it is held in memory whole).
pub const MAX_FILE_BYTES: u64 = 16 << 30;

/// Reads a regular file of at most `max` bytes whole (a device or FIFO would
/// never end, a file growing meanwhile is read up to its length when opened).
fn read_bounded(path: &Path, max: u64) -> Result<Vec<u8>, ReadError> {
    let io = |error| ReadError::Io {
        path: path.display().to_string(),
        error,
    };
    let not = |what: String| ReadError::NotReadable {
        path: path.display().to_string(),
        what,
        max,
    };
    // The one checked open (crate::files): a FIFO named here does not hang it.
    let (file, len) = crate::files::open_checked(path, max).map_err(|e| match e {
        crate::files::FileError::Io { source, .. } => io(source),
        crate::files::FileError::TooBig { size, .. } => not(format!("it is {size} bytes")),
        other => not(format!("it {}", other.reason())),
    })?;
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(len).read_to_end(&mut bytes).map_err(io)?;
    Ok(bytes)
}

impl Summary {
    /// Reads `path` whole (it is kept in memory) and summarises it.
    pub fn read(path: &Path) -> Result<(Summary, Vec<u8>), ReadError> {
        let bytes = read_bounded(path, MAX_FILE_BYTES)?;
        let s = Summary::of(&bytes).map_err(|error| ReadError::NotMcap {
            path: path.display().to_string(),
            error,
        })?;
        Ok((s, bytes))
    }

    /// Summarises the bytes of a file; an error if they are not MCAP at all.
    /// Damage is in `lost` (cut short) and `corrupt` (see [`read_messages`]).
    pub fn of(bytes: &[u8]) -> Result<Summary, String> {
        let mut by_id: BTreeMap<u16, ChannelSummary> = BTreeMap::new();
        let mut s = Summary {
            bytes: bytes.len() as u64,
            ..Summary::default()
        };
        let outcome = read_messages(bytes, |m| {
            let c = by_id.entry(m.channel.id).or_insert_with(|| {
                let schema = m.channel.schema.as_ref().map(|s| s.name.clone());
                ChannelSummary {
                    topic: m.channel.topic.clone(),
                    name: interface_name(&m.channel.topic, &m.channel.metadata),
                    kind: channel_kind_name(&m.channel.metadata, schema.as_deref()),
                    schema: schema.unwrap_or_default(),
                    encoding: m.channel.message_encoding.clone(),
                    first_ns: m.log_time,
                    ..ChannelSummary::default()
                }
            });
            c.messages += 1;
            c.first_ns = c.first_ns.min(m.log_time);
            c.last_ns = c.last_ns.max(m.log_time);
            if s.messages == 0 {
                s.start_ns = m.log_time;
            }
            s.messages += 1;
            s.start_ns = s.start_ns.min(m.log_time);
            s.end_ns = s.end_ns.max(m.log_time);
            ControlFlow::Continue(())
        })?;
        s.profile = outcome.profile.clone();
        s.complete = outcome.complete;
        s.orphans = outcome.orphans;
        s.lost = outcome.cut_short().map(|p| p.to_string());
        s.corrupt = outcome.corrupt().map(|p| p.to_string()).collect();
        if outcome.more_problems > 0 {
            s.corrupt
                .push(format!("and {} more damaged places", outcome.more_problems));
        }
        s.channels = by_id.into_values().collect();
        Ok(s)
    }

    /// Nothing is damaged: no corruption, not cut short.
    pub fn intact(&self) -> bool {
        self.lost.is_none() && self.corrupt.is_empty()
    }

    /// Seconds from the first message to the last.
    pub fn duration(&self) -> f64 {
        self.end_ns.saturating_sub(self.start_ns) as f64 / 1e9
    }

    /// The text `jderobot info` prints.
    pub fn report(&self, path: &Path) -> String {
        let mut o = String::new();
        let _ = writeln!(
            o,
            "file: {} ({} bytes, profile `{}`)",
            path.display(),
            self.bytes,
            self.profile
        );
        let _ = writeln!(
            o,
            "duration: {:.3} s, {} messages, {} channels",
            self.duration(),
            self.messages,
            self.channels.len()
        );
        let _ = writeln!(
            o,
            "{:<20} {:<10} {:<24} {:>9} {:>9}",
            "channel", "kind", "schema", "messages", "rate Hz"
        );
        for c in &self.channels {
            let _ = writeln!(
                o,
                "{:<20} {:<10} {:<24} {:>9} {:>9.2}",
                c.topic,
                c.kind.as_deref().unwrap_or("(foreign)"),
                c.schema,
                c.messages,
                c.rate()
            );
        }
        for c in &self.corrupt {
            let _ = writeln!(o, "corrupt: {c}");
        }
        if self.orphans > 0 {
            let _ = writeln!(
                o,
                "{} messages were skipped: their channel was defined in a corrupt chunk",
                self.orphans
            );
        }
        if !self.corrupt.is_empty() {
            let _ = writeln!(
                o,
                "complete: NO, the file is corrupt in {} places (above), which were skipped; the rest was read",
                self.corrupt.len()
            );
        }
        match &self.lost {
            None if self.corrupt.is_empty() => {
                let _ = writeln!(o, "complete: yes");
            }
            None => {}
            Some(why) => {
                let _ = writeln!(
                    o,
                    "complete: NO, the file was cut short; read up to its last complete chunk, the rest is lost ({why})"
                );
            }
        }
        o
    }
}
