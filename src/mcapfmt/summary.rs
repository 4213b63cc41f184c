//! What a file holds, read message by message (so a file cut short still says
//! what it has): for `jderobot info` and the replay driver.

use std::{collections::BTreeMap, fmt::Write as _, path::Path};

use super::{channel_kind, interface_name};

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
}

/// Errors reading a file.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: not an MCAP file ({error})")]
    NotMcap { path: String, error: String },
}

impl Summary {
    /// Reads `path` whole (it is kept in memory) and summarises it.
    pub fn read(path: &Path) -> Result<(Summary, Vec<u8>), ReadError> {
        let bytes = std::fs::read(path).map_err(|error| ReadError::Io {
            path: path.display().to_string(),
            error,
        })?;
        let s = Summary::of(&bytes).map_err(|error| ReadError::NotMcap {
            path: path.display().to_string(),
            error,
        })?;
        Ok((s, bytes))
    }

    /// Summarises the bytes of a file; an error if they are not MCAP at all.
    pub fn of(bytes: &[u8]) -> Result<Summary, String> {
        if !bytes.starts_with(mcap::MAGIC) {
            return Err("it does not start with the MCAP magic bytes".into());
        }
        let complete = bytes.len() >= 2 * mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC);
        let stream = mcap::MessageStream::new_with_options(
            bytes,
            mcap::read::Options::IgnoreEndMagic.into(),
        )
        .map_err(|e| e.to_string())?;
        let mut by_id: BTreeMap<u16, ChannelSummary> = BTreeMap::new();
        let mut s = Summary {
            profile: profile(bytes),
            bytes: bytes.len() as u64,
            complete,
            ..Summary::default()
        };
        for m in stream {
            let m = match m {
                Ok(m) => m,
                Err(e) => {
                    s.lost = Some(e.to_string());
                    break;
                }
            };
            let c = by_id.entry(m.channel.id).or_insert_with(|| {
                let schema = m.channel.schema.as_ref().map(|s| s.name.clone());
                ChannelSummary {
                    topic: m.channel.topic.clone(),
                    name: interface_name(&m.channel.topic, &m.channel.metadata),
                    kind: channel_kind(&m.channel.metadata, schema.as_deref()),
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
        }
        if s.lost.is_none() && !complete {
            s.lost = Some("the file does not end with the MCAP footer (cut short)".into());
        }
        s.channels = by_id.into_values().collect();
        Ok(s)
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
        match &self.lost {
            None => {
                let _ = writeln!(o, "complete: yes");
            }
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

/// The profile string of the header record right after the magic.
fn profile(bytes: &[u8]) -> String {
    let m = mcap::MAGIC.len();
    // opcode (1) + record length (8) + string length (4) + string
    let Some(len) = bytes.get(m + 9..m + 13) else {
        return String::new();
    };
    let n = u32::from_le_bytes(len.try_into().expect("4")) as usize;
    bytes
        .get(m + 13..m + 13 + n)
        .map(|p| String::from_utf8_lossy(p).into_owned())
        .unwrap_or_default()
}
