//! A bounded MCAP reader: every message of a file, whatever damage it has, with
//! each damaged place reported (what, at which byte) and the readable rest used.
//! `jderobot info` ([`Summary`](super::Summary)), the replay driver and `check` of
//! a replay conf read files only through it.
//!
//! # Why not the `mcap` crate's reader
//! `mcap` 0.26 (still used to write) trusts the sizes a file gives: one flipped
//! byte in a length made its linear reader panic (`capacity overflow`) or abort the
//! process (`memory allocation of 9184950150487834496 bytes failed`), and a 225 KB
//! file took 1 GB. It does not check chunk CRCs, and stops at the first damaged
//! record, which it reports as the end of the file. Fixing that would need every
//! size check inside its parser, so this is a thin reader of the documented format
//! (<https://mcap.dev/spec>) instead: records are `opcode u8, length u64 LE, body`.
//!
//! # Bounds (nothing is allocated from a size before it is checked)
//! - A record's length must fit in what is left of the file.
//! - A chunk's declared `uncompressed_size` must be at most [`MAX_CHUNK_BYTES`]
//!   and at most the file's length times the codec's greatest ratio (none: exactly
//!   the records' length; lz4: 256; zstd: 2¹⁵); it is decompressed into a buffer
//!   that grows with the data that really comes (from 8 times the compressed
//!   size, doubling, never past the declared size: more or fewer bytes and the
//!   chunk is corrupt), so a damaged size costs at most twice the real data. One chunk is held at a time. zstd's window is at most 2²⁷
//!   bytes (its default), lz4's blocks 4 MiB.
//! - Strings, maps and byte arrays are borrowed from the file or the chunk;
//!   schema data is not kept. At most [`MAX_PROBLEMS`] problems are listed.
//!
//! So reading a file takes at most its length, plus one chunk (≤ 256 MiB), plus
//! its channel table (≤ its length).
//!
//! # CRCs (0 means "not set", as MCAP says)
//! Each chunk's `uncompressed_crc`, the data section's `data_section_crc`, each
//! attachment's `crc` and the footer's `summary_crc` are checked.
//!
//! # Damage
//! A chunk whose CRC, compression or records are wrong is skipped and reported
//! as corrupt at its offset; reading goes on with the next record. When the
//! framing itself is broken (an unknown opcode, a length past the end, a record
//! that does not parse), the reader looks for the next chunk record whose header
//! parses exactly and goes on from there (a linear scan). A record running past
//! the end of a file without a footer, with no chunk after it, is where the file
//! was cut short (a run killed mid-write); anywhere else it is corruption. A
//! file without a footer is always reported cut short.
//! Channels are taken from the data section, and from the summary section (where
//! the writer repeats them) when their own record was in a damaged chunk.
//! Top-level messages (unchunked files) after broken framing are not recovered.

use std::{collections::HashMap, fmt, io::Read, ops::ControlFlow};

/// The MCAP magic bytes, at the start and the end of a file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// The largest chunk (decompressed) that is read.
pub const MAX_CHUNK_BYTES: u64 = 256 * 1024 * 1024;
/// The most problems listed (the rest are counted).
pub const MAX_PROBLEMS: usize = 32;
/// The greatest decompression ratio of lz4 (its format's limit is about 255).
const LZ4_RATIO: u64 = 256;
/// The ratio allowed for zstd, over the whole file's length.
const ZSTD_RATIO: u64 = 1 << 15;

mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const ATTACHMENT: u8 = 0x09;
    pub const ATTACHMENT_INDEX: u8 = 0x0A;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// A channel's schema (its data is not kept).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Schema {
    pub id: u16,
    pub name: String,
    pub encoding: String,
}

/// A channel of the file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Channel {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub metadata: std::collections::BTreeMap<String, String>,
    pub schema: Option<Schema>,
}

/// A message, borrowed from the file or its chunk.
#[derive(Debug)]
pub struct Message<'a> {
    pub channel: &'a Channel,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: &'a [u8],
}

/// What kind of damage.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Damage {
    /// The bytes are there but wrong (a CRC, a length, an opcode...).
    Corrupt,
    /// The file ends in the middle of a record: everything after is lost.
    CutShort,
}

/// A damaged place of a file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Problem {
    pub damage: Damage,
    /// Where it starts (bytes from the start of the file).
    pub offset: u64,
    pub what: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "at byte {}: {}", self.offset, self.what)
    }
}

/// What reading a file found besides its messages.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// The header's profile (`ros2`, or empty for jderobot's own).
    pub profile: String,
    /// The file ends with a footer and the magic (it was closed properly).
    pub complete: bool,
    /// Damaged places, in file order (at most [`MAX_PROBLEMS`]).
    pub problems: Vec<Problem>,
    /// Problems found beyond [`MAX_PROBLEMS`].
    pub more_problems: u64,
    /// Messages whose channel is not defined anywhere readable.
    pub orphans: u64,
    /// The callback asked to stop.
    pub stopped: bool,
}

impl Outcome {
    fn problem(&mut self, damage: Damage, offset: usize, what: impl Into<String>) {
        // A cut is always listed (it ends the reading).
        if self.problems.len() < MAX_PROBLEMS || damage == Damage::CutShort {
            self.problems.push(Problem {
                damage,
                offset: offset as u64,
                what: what.into(),
            });
        } else {
            self.more_problems += 1;
        }
    }

    /// The file was cut short (the last problem says where).
    pub fn cut_short(&self) -> Option<&Problem> {
        self.problems.iter().find(|p| p.damage == Damage::CutShort)
    }

    /// The corrupt places.
    pub fn corrupt(&self) -> impl Iterator<Item = &Problem> {
        self.problems.iter().filter(|p| p.damage == Damage::Corrupt)
    }
}

/// A little-endian cursor over a record body; every read is checked.
struct Cur<'a> {
    b: &'a [u8],
}

type R<T> = Result<T, String>;

impl<'a> Cur<'a> {
    fn take(&mut self, n: u64, what: &str) -> R<&'a [u8]> {
        if n > self.b.len() as u64 {
            return Err(format!(
                "{what} declares {n} bytes, but only {} are left in the record",
                self.b.len()
            ));
        }
        let (h, t) = self.b.split_at(n as usize);
        self.b = t;
        Ok(h)
    }
    fn u16(&mut self, what: &str) -> R<u16> {
        Ok(u16::from_le_bytes(
            self.take(2, what)?.try_into().unwrap_or_default(),
        ))
    }
    fn u32(&mut self, what: &str) -> R<u32> {
        Ok(u32::from_le_bytes(
            self.take(4, what)?.try_into().unwrap_or_default(),
        ))
    }
    fn u64(&mut self, what: &str) -> R<u64> {
        Ok(u64::from_le_bytes(
            self.take(8, what)?.try_into().unwrap_or_default(),
        ))
    }
    fn bytes32(&mut self, what: &str) -> R<&'a [u8]> {
        let n = self.u32(what)?;
        self.take(n as u64, what)
    }
    fn bytes64(&mut self, what: &str) -> R<&'a [u8]> {
        let n = self.u64(what)?;
        self.take(n, what)
    }
    fn str(&mut self, what: &str) -> R<&'a str> {
        std::str::from_utf8(self.bytes32(what)?).map_err(|_| format!("{what} is not UTF-8"))
    }
    fn string_map(&mut self, what: &str) -> R<std::collections::BTreeMap<String, String>> {
        let mut c = Cur {
            b: self.bytes32(what)?,
        };
        let mut m = std::collections::BTreeMap::new();
        while !c.b.is_empty() {
            let k = c.str(what)?;
            let v = c.str(what)?;
            m.insert(k.to_string(), v.to_string());
        }
        Ok(m)
    }
    /// A map or array of fixed-size entries (`entry` bytes each).
    fn fixed_array(&mut self, entry: u64, what: &str) -> R<()> {
        let b = self.bytes32(what)?;
        if !(b.len() as u64).is_multiple_of(entry) {
            return Err(format!(
                "{what} is {} bytes, not a whole number of {entry}-byte entries",
                b.len()
            ));
        }
        Ok(())
    }
    fn end(&self, what: &str) -> R<()> {
        if self.b.is_empty() {
            Ok(())
        } else {
            Err(format!(
                "{what} has {} bytes left over after its fields",
                self.b.len()
            ))
        }
    }
}

/// A chunk's header fields and its compressed records.
struct Chunk<'a> {
    uncompressed_size: u64,
    uncompressed_crc: u32,
    compression: &'a str,
    records: &'a [u8],
}

fn parse_chunk(body: &[u8]) -> R<Chunk<'_>> {
    let mut c = Cur { b: body };
    c.u64("the chunk's message_start_time")?;
    c.u64("the chunk's message_end_time")?;
    let uncompressed_size = c.u64("the chunk's uncompressed_size")?;
    let uncompressed_crc = c.u32("the chunk's uncompressed_crc")?;
    let compression = c.str("the chunk's compression")?;
    let records = c.bytes64("the chunk's records")?;
    c.end("the chunk")?;
    if !matches!(compression, "" | "zstd" | "lz4") {
        return Err(format!(
            "the chunk's compression is `{}`; MCAP files use none, zstd or lz4",
            compression.escape_debug()
        ));
    }
    Ok(Chunk {
        uncompressed_size,
        uncompressed_crc,
        compression,
        records,
    })
}

/// Checks that a record of the data or summary section parses whole (the
/// records that carry nothing jderobot reads).
fn check_record(opcode: u8, body: &[u8]) -> R<()> {
    let mut c = Cur { b: body };
    match opcode {
        op::HEADER => {
            c.str("the header's profile")?;
            c.str("the header's library")?;
        }
        op::FOOTER => {
            c.take(20, "the footer")?;
        }
        op::MESSAGE_INDEX => {
            c.u16("the message index's channel")?;
            c.fixed_array(16, "the message index")?;
        }
        op::CHUNK_INDEX => {
            c.take(32, "the chunk index's times and offsets")?;
            c.fixed_array(10, "the chunk index's message index offsets")?;
            c.u64("the chunk index's message_index_length")?;
            c.str("the chunk index's compression")?;
            c.take(16, "the chunk index's sizes")?;
        }
        op::ATTACHMENT => {
            c.take(16, "the attachment's times")?;
            c.str("the attachment's name")?;
            c.str("the attachment's media type")?;
            c.bytes64("the attachment's data")?;
            c.u32("the attachment's crc")?;
        }
        op::ATTACHMENT_INDEX => {
            c.take(40, "the attachment index's offsets, times and size")?;
            c.str("the attachment index's name")?;
            c.str("the attachment index's media type")?;
        }
        op::STATISTICS => {
            c.take(42, "the statistics' counts and times")?;
            c.fixed_array(10, "the statistics' channel message counts")?;
        }
        op::METADATA => {
            c.str("the metadata's name")?;
            c.string_map("the metadata")?;
        }
        op::METADATA_INDEX => {
            c.take(16, "the metadata index's offset and length")?;
            c.str("the metadata index's name")?;
        }
        op::SUMMARY_OFFSET => {
            c.take(17, "the summary offset")?;
        }
        op::DATA_END => {
            c.u32("the data end's crc")?;
        }
        _ => return Ok(()),
    }
    c.end(&format!("record {opcode:#04x}"))
}

/// The records of a chunk (or the file's top level): schemas, channels, messages.
#[derive(Default)]
struct Tables {
    schemas: HashMap<u16, Schema>,
    channels: HashMap<u16, Channel>,
}

impl Tables {
    fn schema(&mut self, body: &[u8]) -> R<()> {
        let mut c = Cur { b: body };
        let id = c.u16("the schema's id")?;
        let name = c.str("the schema's name")?;
        let encoding = c.str("the schema's encoding")?;
        c.bytes32("the schema's data")?;
        c.end("the schema")?;
        self.schemas.insert(
            id,
            Schema {
                id,
                name: name.into(),
                encoding: encoding.into(),
            },
        );
        Ok(())
    }

    fn channel(&mut self, body: &[u8]) -> R<()> {
        let mut c = Cur { b: body };
        let id = c.u16("the channel's id")?;
        let schema_id = c.u16("the channel's schema id")?;
        let topic = c.str("the channel's topic")?;
        let message_encoding = c.str("the channel's message encoding")?;
        let metadata = c.string_map("the channel's metadata")?;
        c.end("the channel")?;
        self.channels.insert(
            id,
            Channel {
                id,
                topic: topic.into(),
                message_encoding: message_encoding.into(),
                metadata,
                // Schema 0: none. An unknown one is left out (its name is not known).
                schema: self.schemas.get(&schema_id).cloned(),
            },
        );
        Ok(())
    }
}

/// A record of a byte slice: its opcode, body, and the offset after it.
fn record_at(b: &[u8], at: usize) -> Result<(u8, &[u8], usize), RecErr> {
    let left = b.len().saturating_sub(at);
    if left < 9 {
        return Err(RecErr::PastEnd(format!(
            "a record header needs 9 bytes, {left} are left"
        )));
    }
    let opcode = b[at];
    let len = u64::from_le_bytes(b[at + 1..at + 9].try_into().unwrap_or_default());
    if len > (left - 9) as u64 {
        return Err(RecErr::PastEnd(format!(
            "a record (opcode {opcode:#04x}) declares {len} bytes, {} are left",
            left - 9
        )));
    }
    let end = at + 9 + len as usize;
    Ok((opcode, &b[at + 9..end], end))
}

enum RecErr {
    /// The record runs past the end of the bytes.
    PastEnd(String),
}

/// Reads every message of `bytes` (a whole MCAP file) in file order, calling `f`
/// for each one (`ControlFlow::Break` stops). Damage is reported in the
/// [`Outcome`], never by a panic; an error only if the bytes are not MCAP at all.
pub fn read_messages(
    bytes: &[u8],
    mut f: impl FnMut(&Message<'_>) -> ControlFlow<()>,
) -> Result<Outcome, String> {
    if !bytes.starts_with(MAGIC) {
        return Err("it does not start with the MCAP magic bytes".into());
    }
    let mut out = Outcome {
        complete: bytes.len() >= 2 * MAGIC.len() && bytes.ends_with(MAGIC),
        ..Outcome::default()
    };
    // The summary section's channels (a fallback for damaged chunks).
    let (summary, data_end) = summary_section(bytes, &mut out);
    let mut tables = Tables::default();
    let mut at = MAGIC.len();
    let mut first = true;
    let mut ended = false;
    while at < data_end {
        let (opcode, body, next) = match record_at(&bytes[..data_end], at) {
            Ok(r) => r,
            Err(RecErr::PastEnd(why)) => match skip_past_end(bytes, data_end, at, &why, &mut out) {
                Some(n) => {
                    at = n;
                    continue;
                }
                None => break,
            },
        };
        // Err: the framing is broken here; Ok(Some): only this record is damaged.
        let checked = if first && opcode != op::HEADER {
            Err(format!(
                "the file starts with record {opcode:#04x}, not the header"
            ))
        } else if !first && opcode == op::HEADER {
            Err("a second header record".into())
        } else {
            let rec = Record {
                opcode,
                body,
                at,
                next,
            };
            read_record(bytes, &rec, &mut tables, &summary, &mut out, &mut f)
        };
        if out.stopped {
            return Ok(out);
        }
        first = false;
        match checked {
            Ok(damage) => {
                if let Some(why) = damage {
                    out.problem(Damage::Corrupt, at, why);
                }
                if opcode == op::DATA_END || opcode == op::FOOTER {
                    ended = true;
                    break;
                }
                at = next;
            }
            Err(why) => {
                // Broken framing: go on at the next chunk that parses.
                let n = resync(bytes, data_end, at + 1);
                let upto = n.map_or("the end of the data".to_string(), |n| format!("byte {n}"));
                out.problem(Damage::Corrupt, at, format!("{why}; skipped up to {upto}"));
                match n {
                    Some(n) => at = n,
                    None => break,
                }
            }
        }
    }
    if !ended && !out.complete && out.cut_short().is_none() {
        out.problem(
            Damage::CutShort,
            bytes.len(),
            "the file ends without its data end and footer: it was cut short",
        );
    }
    out.problems.sort_by_key(|p| p.offset);
    Ok(out)
}

/// A record of the data section: its opcode, body and where it starts and ends.
struct Record<'a> {
    opcode: u8,
    body: &'a [u8],
    at: usize,
    next: usize,
}

/// A record that runs past the end at `at` (`why`): the next readable chunk to
/// go on at, or None when the rest is lost; the damage noted in `out`.
fn skip_past_end(
    bytes: &[u8],
    data_end: usize,
    at: usize,
    why: &str,
    out: &mut Outcome,
) -> Option<usize> {
    // Cut short, or a damaged length: a readable chunk further on tells.
    if let Some(n) = resync(bytes, data_end, at + 1) {
        out.problem(
            Damage::Corrupt,
            at,
            format!("{why}: a damaged length; bytes {at}..{n} are skipped"),
        );
        return Some(n);
    }
    let (damage, what) = if out.complete {
        (
            Damage::Corrupt,
            format!("{why}: a damaged length; the data after it is skipped"),
        )
    } else {
        (
            Damage::CutShort,
            format!("{why}: the file was cut short there; the rest is lost"),
        )
    };
    out.problem(damage, at, what);
    None
}

/// Reads one record after the header checks: Err when the framing is broken
/// here, Ok(Some(why)) when only this record is damaged.
fn read_record(
    bytes: &[u8],
    rec: &Record<'_>,
    tables: &mut Tables,
    summary: &Tables,
    out: &mut Outcome,
    f: &mut impl FnMut(&Message<'_>) -> ControlFlow<()>,
) -> R<Option<String>> {
    let Record {
        opcode,
        body,
        at,
        next,
    } = *rec;
    match opcode {
        op::HEADER => {
            let mut c = Cur { b: body };
            c.str("the header's profile").map(|p| {
                out.profile = p.into();
                None
            })
        }
        op::SCHEMA => tables.schema(body).map(|()| None),
        op::CHANNEL => tables.channel(body).map(|()| None),
        op::MESSAGE => message(body, tables, summary, out, f).map(|()| None),
        op::CHUNK => parse_chunk(body)
            .map_err(|why| format!("a chunk record that does not parse: {why}"))
            .map(|c| {
                chunk(bytes.len(), &c, tables, summary, out, f)
                    .err()
                    .map(|why| {
                        format!(
                            "chunk of {} bytes: {why}; its messages are skipped",
                            next - at
                        )
                    })
            }),
        op::ATTACHMENT => check_record(opcode, body).map(|()| {
            attachment_crc(body)
                .err()
                .map(|why| format!("{why}; it is skipped"))
        }),
        op::DATA_END => check_record(opcode, body).map(|()| data_crc(bytes, at, body, out).err()),
        op::FOOTER | 0x07..=0x0E => check_record(opcode, body).map(|()| None),
        _ => Err(format!(
            "record opcode {opcode:#04x} is not an MCAP record jderobot knows (0x01–0x0F)"
        )),
    }
}

/// Where the data section ends (the summary section or the footer starts) and
/// the summary's channels, if the file is complete and its footer is sound.
fn summary_section(bytes: &[u8], out: &mut Outcome) -> (Tables, usize) {
    let mut t = Tables::default();
    if !out.complete {
        return (t, bytes.len());
    }
    // footer record: opcode, length 20, summary_start, summary_offset_start, crc; magic
    let footer_at = bytes.len().saturating_sub(MAGIC.len() + 9 + 20);
    let Ok((op::FOOTER, body, _)) =
        record_at(&bytes[..bytes.len() - MAGIC.len()], footer_at).map_err(|_| ())
    else {
        out.problem(Damage::Corrupt, footer_at, "the footer record is damaged (the file ends with the magic, but not after a footer); the summary is not read");
        return (t, bytes.len() - MAGIC.len());
    };
    if body.len() != 20 || footer_at < MAGIC.len() {
        out.problem(
            Damage::Corrupt,
            footer_at,
            "the footer record is damaged (its length is not 20)",
        );
        return (t, bytes.len() - MAGIC.len());
    }
    let mut c = Cur { b: body };
    let start = c.u64("").unwrap_or(0);
    let _ = c.u64("");
    let crc = c.u32("").unwrap_or(0);
    if start == 0 {
        return (t, footer_at);
    }
    if start < MAGIC.len() as u64 || start > footer_at as u64 {
        out.problem(Damage::Corrupt, footer_at, format!("the footer says the summary starts at byte {start}, outside the file's data; the summary is not read"));
        return (t, footer_at);
    }
    let start = start as usize;
    if crc != 0 {
        let got = crc32fast::hash(&bytes[start..footer_at + 9 + 16]);
        if got != crc {
            out.problem(Damage::Corrupt, start, format!("the summary section's CRC is {crc:#010x}, its bytes give {got:#010x}; it is not used"));
            return (t, start);
        }
    }
    let mut at = start;
    while at < footer_at {
        let Ok((opcode, body, next)) = record_at(&bytes[..footer_at], at) else {
            out.problem(
                Damage::Corrupt,
                at,
                "a summary record runs past the footer; the rest of the summary is not used",
            );
            break;
        };
        let r = match opcode {
            op::SCHEMA => t.schema(body),
            op::CHANNEL => t.channel(body),
            _ => check_record(opcode, body),
        };
        if let Err(why) = r {
            out.problem(
                Damage::Corrupt,
                at,
                format!("summary record {opcode:#04x}: {why}; the rest of the summary is not used"),
            );
            break;
        }
        at = next;
    }
    (t, start)
}

/// Checks an attachment's `crc` (0: not set) over its other fields (it parses).
fn attachment_crc(body: &[u8]) -> R<()> {
    let covered = body.len().saturating_sub(4);
    let crc = u32::from_le_bytes(body[covered..].try_into().unwrap_or_default());
    let got = crc32fast::hash(&body[..covered]);
    if crc != 0 && crc != got {
        return Err(format!(
            "the attachment's CRC is {crc:#010x}, its bytes give {got:#010x}"
        ));
    }
    Ok(())
}

/// Checks the data end's `data_section_crc` (0: not set) over bytes `..at`.
fn data_crc(bytes: &[u8], at: usize, body: &[u8], out: &Outcome) -> R<()> {
    let crc = u32::from_le_bytes(body[..4].try_into().unwrap_or_default());
    if crc == 0 || out.corrupt().next().is_some() {
        // Not set, or the damage is already known (and located).
        return Ok(());
    }
    let got = crc32fast::hash(&bytes[..at]);
    if got != crc {
        return Err(format!(
            "the data section's CRC is {crc:#010x}, its bytes give {got:#010x}: the data is corrupt somewhere before byte {at}"
        ));
    }
    Ok(())
}

/// A message record: handed to `f` if its channel is known.
fn message(
    body: &[u8],
    tables: &Tables,
    summary: &Tables,
    out: &mut Outcome,
    f: &mut impl FnMut(&Message<'_>) -> ControlFlow<()>,
) -> R<()> {
    let mut c = Cur { b: body };
    let channel = c.u16("the message's channel")?;
    let sequence = c.u32("the message's sequence")?;
    let log_time = c.u64("the message's log time")?;
    let publish_time = c.u64("the message's publish time")?;
    let Some(ch) = tables
        .channels
        .get(&channel)
        .or_else(|| summary.channels.get(&channel))
    else {
        out.orphans += 1;
        return Ok(());
    };
    let m = Message {
        channel: ch,
        sequence,
        log_time,
        publish_time,
        data: c.b,
    };
    if f(&m).is_break() {
        out.stopped = true;
    }
    Ok(())
}

/// The largest `uncompressed_size` a chunk of a file of `file_len` bytes may declare.
fn chunk_limit(file_len: usize, c: &Chunk<'_>) -> u64 {
    let ratio_bound = match c.compression {
        "" => c.records.len() as u64,
        "lz4" => (c.records.len() as u64).saturating_mul(LZ4_RATIO) + 64,
        _ => (file_len as u64).saturating_mul(ZSTD_RATIO),
    };
    ratio_bound.min(MAX_CHUNK_BYTES)
}

/// Decompresses `c` into exactly its declared size (bounded first), checks its CRC.
fn decompress(file_len: usize, c: &Chunk<'_>) -> R<Option<Vec<u8>>> {
    let size = c.uncompressed_size;
    let limit = chunk_limit(file_len, c);
    if c.compression.is_empty() {
        if size != c.records.len() as u64 {
            return Err(format!(
                "it declares {size} uncompressed bytes but holds {} (uncompressed)",
                c.records.len()
            ));
        }
        return Ok(None);
    }
    if size > limit {
        return Err(format!(
            "it declares {size} bytes decompressed, more than the {limit} a {} chunk of {} bytes may hold here",
            c.compression,
            c.records.len()
        ));
    }
    // Most chunks hold no more than 8 times their compressed size: one allocation.
    let first = c.records.len().saturating_mul(8).max(64 * 1024);
    let r = match c.compression {
        "zstd" => zstd::stream::read::Decoder::with_buffer(c.records)
            .map_err(|e| e.to_string())
            .and_then(|d| fill(d, size as usize, first)),
        _ => lz4::Decoder::new(c.records)
            .map_err(|e| e.to_string())
            .and_then(|d| fill(d, size as usize, first)),
    };
    r.map(Some)
        .map_err(|e| format!("its {} data does not decompress ({e})", c.compression))
}

/// Reads exactly `size` bytes from `r` and checks that nothing follows. The
/// buffer grows with what really comes (from `first` bytes, doubling, never past
/// `size`), so a damaged size costs at most twice the real data (or `first`).
fn fill(mut r: impl Read, size: usize, first: usize) -> Result<Vec<u8>, String> {
    let mut buf: Vec<u8> = Vec::new();
    let mut n = 0;
    while n < size {
        if n == buf.len() {
            let to = (buf.len() * 2).max(first).min(size);
            buf.resize(to, 0);
        }
        match r.read(&mut buf[n..]) {
            Ok(0) => {
                return Err(format!(
                    "it gives {n} bytes, not the {size} the chunk declares"
                ));
            }
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.to_string()),
        }
    }
    let mut more = [0u8; 1];
    loop {
        match r.read(&mut more) {
            Ok(0) => return Ok(buf),
            Ok(_) => {
                return Err(format!(
                    "it gives more than the {size} bytes the chunk declares"
                ));
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e.to_string()),
        }
    }
}

/// A chunk: checked whole (size, CRC, records) before any of its messages is used.
fn chunk(
    file_len: usize,
    c: &Chunk<'_>,
    tables: &mut Tables,
    summary: &Tables,
    out: &mut Outcome,
    f: &mut impl FnMut(&Message<'_>) -> ControlFlow<()>,
) -> R<()> {
    let owned = decompress(file_len, c)?;
    let records = owned.as_deref().unwrap_or(c.records);
    if c.uncompressed_crc != 0 {
        let got = crc32fast::hash(records);
        if got != c.uncompressed_crc {
            return Err(format!(
                "its CRC is {:#010x}, its bytes give {got:#010x}",
                c.uncompressed_crc
            ));
        }
    }
    // Every record parses first: a chunk is used whole or not at all.
    let mut scratch = Tables::default();
    let mut at = 0;
    while at < records.len() {
        match record_at(records, at) {
            Ok((opcode, body, next))
                if matches!(opcode, op::SCHEMA | op::CHANNEL | op::MESSAGE) =>
            {
                let r = match opcode {
                    op::SCHEMA => scratch.schema(body),
                    op::CHANNEL => scratch.channel(body),
                    _ if body.len() < 22 => {
                        Err(format!("a message of {} bytes (at least 22)", body.len()))
                    }
                    _ => Ok(()),
                };
                r.map_err(|why| format!("its record at byte {at} of them: {why}"))?;
                at = next;
            }
            Ok((opcode, _, _)) => {
                return Err(format!(
                    "its record at byte {at} (of the decompressed records) has opcode {opcode:#04x}; chunks hold schemas, channels and messages"
                ));
            }
            Err(RecErr::PastEnd(why)) => {
                return Err(format!("its records break at byte {at} of them ({why})"));
            }
        }
    }
    let mut at = 0;
    while at < records.len() && !out.stopped {
        let Ok((opcode, body, next)) = record_at(records, at) else {
            break;
        };
        let r = match opcode {
            op::SCHEMA => tables.schema(body),
            op::CHANNEL => tables.channel(body),
            _ => message(body, tables, summary, out, f),
        };
        r.map_err(|why| format!("its record at byte {at} of them: {why}"))?;
        at = next;
    }
    Ok(())
}

/// After broken framing at `from - 1`: the offset of the next chunk record whose
/// header parses exactly (its length, fields and compression agree), or None.
/// Its contents are checked when it is read, as any chunk's; the scan is linear
/// (nothing is decompressed here), so a crafted file cannot make it quadratic.
fn resync(bytes: &[u8], data_end: usize, from: usize) -> Option<usize> {
    let data = &bytes[..data_end];
    let mut at = from;
    while at < data.len() {
        at += data[at..].iter().position(|&b| b == op::CHUNK)?;
        if let Ok((op::CHUNK, body, _)) = record_at(data, at)
            && parse_chunk(body).is_ok()
        {
            return Some(at);
        }
        at += 1;
    }
    None
}
