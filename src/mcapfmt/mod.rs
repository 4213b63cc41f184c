//! mcapfmt: interfaces as MCAP messages, the format that the `recorder` service
//! writes and the `replay` driver and `jderobot info` read (see `docs/recording.md`).
//!
//! One MCAP channel per interface (topic = the interface name; the channel
//! metadata `jderobot.kind` names the interface kind). The default profile uses
//! Foxglove's schemas where they fit, so Foxglove shows the file as it is: in
//! Foxglove's binary encoding, protobuf (schema data: Foxglove's own
//! `FileDescriptorSet`s, `assets/foxglove/`), where the jderobot value comes back
//! exactly from Foxglove's fields, and JSON (a JSON schema per channel) elsewhere:
//!
//! | interface kind | schema | encoding | message |
//! |---|---|---|---|
//! | `image` | `foxglove.RawImage` | protobuf | `encoding` `bgr8`, `data` the BGR bytes as they are |
//! | `image` (`images jpeg`) | `foxglove.CompressedImage` | protobuf | `format` `jpeg` |
//! | `laser` | `foxglove.LaserScan` | protobuf | `ranges` in m (the mm readings / 1000), angles in rad (−π/2 first; `end_angle` gives the resolution back) |
//! | `encoders` | `foxglove.PoseInFrame` | JSON | position in m, orientation a quaternion about z; `jderobot` = the exact value |
//! | others | `jderobot.KIND` | JSON | `jderobot` = the interface's fields in its units |
//!
//! The interface's clock (the sample's number) is the MCAP message `sequence`
//! (mod 2³², as in the `ros2` profile: 4.5 years of a 30 Hz interface, 49 days of a
//! 1 kHz one); JSON messages also carry it whole in `clock`. The Foxglove
//! `timestamp` and the MCAP log and publish times are the sample's wall time (ns
//! since the Unix epoch). Replay is bit-identical: the protobuf fields give the
//! value back exactly (mm / 1000 in a double, the resolution from the angles), and
//! JSON messages carry the f32 values as their shortest round-trip text. Encoders
//! stay JSON because a quaternion cannot give back jderobot's `cos` and `sin`
//! (computed from the unnormalised angle, or received as they are from a remote
//! robot) and Foxglove's protobuf `PoseInFrame` has no field for them; at 20 Hz the
//! JSON costs nothing. Images and laser scans recorded as JSON (before the
//! protobuf encoding) are not read.
//!
//! [`Source`] polls a typed interface for new samples without copying them;
//! [`add_channel`] and [`encode`] write a sample into an MCAP writer,
//! [`decode_message`] (or [`decode_read`] for a message of [`reader`], the bounded
//! reader that replay and `jderobot info` use; [`decode_mcap`] for the `mcap`
//! crate's) reads it back; [`Summary`] reads a file (complete, cut short or
//! corrupt: see [`reader`]) for `jderobot info`; [`RecorderStatus`]
//! and [`StepGate`] are what the recorder and replay export in the name space
//! (keys `recorder.status` and `replay.step`) for the shell.

mod protobuf;
pub mod reader;
pub mod ros2;
mod status;
mod summary;

pub use status::{RecorderStatus, StepGate};
pub use summary::{ChannelSummary, MAX_FILE_BYTES, ReadError, Summary};

use std::{
    collections::BTreeMap,
    fmt::Write as _,
    sync::Arc,
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use serde_json::{Value, json};

use crate::interfaces::{
    AnyInterface, Bumpers, Encoders, Image, Interface, Interfaces, Laser, Motors, PtEncoders,
    PtMotors, Sample, Sonars,
};

/// The metadata key of a channel that names the interface kind.
pub const KIND_KEY: &str = "jderobot.kind";
/// The metadata key of a channel that names the interface (in the `ros2`
/// profile, where the topic is `/laser`).
pub const NAME_KEY: &str = "jderobot.interface";

/// Errors decoding a message.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("channel `{topic}`: {what}")]
    Bad { topic: String, what: String },
    #[error("channel `{topic}`: interface kind `{kind}` is not one jderobot records")]
    Kind { topic: String, kind: String },
}

fn bad(topic: &str, what: impl Into<String>) -> FormatError {
    FormatError::Bad {
        topic: topic.into(),
        what: what.into(),
    }
}

/// One recorded value, whatever its interface kind.
#[derive(Clone, Debug, PartialEq)]
pub enum Recorded {
    Image(Image),
    Laser(Laser),
    Encoders(Encoders),
    Motors(Motors),
    Sonars(Sonars),
    Bumpers(Bumpers),
    PtEncoders(PtEncoders),
    PtMotors(PtMotors),
}

/// The interface kinds jderobot records (`AnyInterface::kind`).
pub const KINDS: &[&str] = &[
    "image",
    "laser",
    "encoders",
    "motors",
    "sonars",
    "bumpers",
    "pantiltencoders",
    "pantiltmotors",
];

/// A sample shared with its interface (no copy), ready to encode.
#[derive(Clone)]
pub enum Snapshot {
    Image(Arc<Sample<Image>>),
    Laser(Arc<Sample<Laser>>),
    Encoders(Arc<Sample<Encoders>>),
    Motors(Arc<Sample<Motors>>),
    Sonars(Arc<Sample<Sonars>>),
    Bumpers(Arc<Sample<Bumpers>>),
    PtEncoders(Arc<Sample<PtEncoders>>),
    PtMotors(Arc<Sample<PtMotors>>),
}

impl Snapshot {
    pub fn clock(&self) -> u64 {
        match self {
            Snapshot::Image(s) => s.clock,
            Snapshot::Laser(s) => s.clock,
            Snapshot::Encoders(s) => s.clock,
            Snapshot::Motors(s) => s.clock,
            Snapshot::Sonars(s) => s.clock,
            Snapshot::Bumpers(s) => s.clock,
            Snapshot::PtEncoders(s) => s.clock,
            Snapshot::PtMotors(s) => s.clock,
        }
    }
    pub fn time(&self) -> SystemTime {
        match self {
            Snapshot::Image(s) => s.time,
            Snapshot::Laser(s) => s.time,
            Snapshot::Encoders(s) => s.time,
            Snapshot::Motors(s) => s.time,
            Snapshot::Sonars(s) => s.time,
            Snapshot::Bumpers(s) => s.time,
            Snapshot::PtEncoders(s) => s.time,
            Snapshot::PtMotors(s) => s.time,
        }
    }
}

/// A typed interface to poll for new samples.
#[derive(Clone)]
pub enum Source {
    Image(Arc<Interface<Image>>),
    Laser(Arc<Interface<Laser>>),
    Encoders(Arc<Interface<Encoders>>),
    Motors(Arc<Interface<Motors>>),
    Sonars(Arc<Interface<Sonars>>),
    Bumpers(Arc<Interface<Bumpers>>),
    PtEncoders(Arc<Interface<PtEncoders>>),
    PtMotors(Arc<Interface<PtMotors>>),
}

impl Source {
    /// The typed interface `name`, or `None` when its kind is not recorded.
    pub fn find(interfaces: &Interfaces, name: &str) -> Option<Source> {
        let kind = interfaces.get_any(name).ok()?.kind();
        Some(match kind {
            "image" => Source::Image(interfaces.get(name).ok()?),
            "laser" => Source::Laser(interfaces.get(name).ok()?),
            "encoders" => Source::Encoders(interfaces.get(name).ok()?),
            "motors" => Source::Motors(interfaces.get(name).ok()?),
            "sonars" => Source::Sonars(interfaces.get(name).ok()?),
            "bumpers" => Source::Bumpers(interfaces.get(name).ok()?),
            "pantiltencoders" => Source::PtEncoders(interfaces.get(name).ok()?),
            "pantiltmotors" => Source::PtMotors(interfaces.get(name).ok()?),
            _ => return None,
        })
    }

    pub fn any(&self) -> &dyn AnyInterface {
        match self {
            Source::Image(i) => &**i,
            Source::Laser(i) => &**i,
            Source::Encoders(i) => &**i,
            Source::Motors(i) => &**i,
            Source::Sonars(i) => &**i,
            Source::Bumpers(i) => &**i,
            Source::PtEncoders(i) => &**i,
            Source::PtMotors(i) => &**i,
        }
    }

    /// The latest sample, shared (no copy).
    pub fn snapshot(&self) -> Snapshot {
        match self {
            Source::Image(i) => Snapshot::Image(i.snapshot()),
            Source::Laser(i) => Snapshot::Laser(i.snapshot()),
            Source::Encoders(i) => Snapshot::Encoders(i.snapshot()),
            Source::Motors(i) => Snapshot::Motors(i.snapshot()),
            Source::Sonars(i) => Snapshot::Sonars(i.snapshot()),
            Source::Bumpers(i) => Snapshot::Bumpers(i.snapshot()),
            Source::PtEncoders(i) => Snapshot::PtEncoders(i.snapshot()),
            Source::PtMotors(i) => Snapshot::PtMotors(i.snapshot()),
        }
    }
}

/// Nanoseconds since the Unix epoch.
pub fn nanos(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// The time `ns` nanoseconds after the Unix epoch.
pub fn from_nanos(ns: u64) -> SystemTime {
    UNIX_EPOCH + Duration::from_nanos(ns)
}

/// What a file holds: the profile and, in the default one, how images are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// Foxglove's schemas (protobuf for images and laser, JSON for the rest);
    /// images as JPEG of this quality (1..=100) when set, else raw BGR.
    Foxglove { jpeg: Option<u8> },
    /// rosbag2: ros2msg schemas, CDR messages (see [`ros2`]).
    Ros2,
}

impl Snapshot {
    /// The interface kind (`AnyInterface::kind`).
    pub fn kind(&self) -> &'static str {
        match self {
            Snapshot::Image(_) => "image",
            Snapshot::Laser(_) => "laser",
            Snapshot::Encoders(_) => "encoders",
            Snapshot::Motors(_) => "motors",
            Snapshot::Sonars(_) => "sonars",
            Snapshot::Bumpers(_) => "bumpers",
            Snapshot::PtEncoders(_) => "pantiltencoders",
            Snapshot::PtMotors(_) => "pantiltmotors",
        }
    }
}

/// Adds the schema and the channel of interface `name` (of kind `kind`) to
/// `writer`: the channel id, or `None` when the profile does not carry the kind
/// (`ros2`: laser, image, encoders and motors only).
pub fn add_channel<W: std::io::Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
    name: &str,
    kind: &str,
    profile: Profile,
) -> Result<Option<u16>, mcap::McapError> {
    let mut meta = metadata(kind);
    let (schema, data) = match (profile, kind) {
        (Profile::Ros2, _) => {
            let Some((type_name, def)) = ros2::schema(kind) else {
                return Ok(None);
            };
            meta.insert(NAME_KEY.into(), name.to_string());
            meta.insert("offered_qos_profiles".into(), String::new());
            let sid = writer.add_schema(type_name, "ros2msg", def.as_bytes())?;
            return writer
                .add_channel(sid, &ros2::topic(name), "cdr", &meta)
                .map(Some);
        }
        (Profile::Foxglove { jpeg: None }, "image") => ("foxglove.RawImage", protobuf::RAW_IMAGE),
        (Profile::Foxglove { jpeg: Some(_) }, "image") => {
            ("foxglove.CompressedImage", protobuf::COMPRESSED_IMAGE)
        }
        (_, "laser") => ("foxglove.LaserScan", protobuf::LASER_SCAN),
        _ => {
            let (schema_name, text) = json_schema(kind);
            let sid = writer.add_schema(&schema_name, "jsonschema", text.as_bytes())?;
            return writer.add_channel(sid, name, "json", &meta).map(Some);
        }
    };
    let sid = writer.add_schema(schema, "protobuf", data)?;
    writer.add_channel(sid, name, "protobuf", &meta).map(Some)
}

/// Encodes a sample of interface `name` into `out` (cleared first) as its channel
/// of [`add_channel`] says; false (and nothing) for a kind the profile does not
/// carry. The MCAP message's `sequence` is the sample's clock (mod 2³²), its log
/// and publish times its wall time ([`nanos`]).
pub fn encode(profile: Profile, name: &str, snap: &Snapshot, out: &mut Vec<u8>) -> bool {
    let ns = nanos(snap.time());
    match (profile, snap) {
        (Profile::Ros2, _) => return ros2::encode(name, snap, out),
        (Profile::Foxglove { jpeg: Some(q) }, Snapshot::Image(img)) => {
            encode_jpeg(name, img, q, out)
        }
        (_, Snapshot::Image(img)) => protobuf::raw_image(name, ns, img, out),
        (_, Snapshot::Laser(l)) => protobuf::laser_scan(name, ns, l, out),
        _ => encode_json(snap, out),
    }
    true
}

/// The JSON schema (name, schema text) of an interface kind written as JSON:
/// `foxglove.PoseInFrame` for encoders, `jderobot.KIND` for the rest.
pub fn json_schema(kind: &str) -> (String, String) {
    let ts = r#""timestamp":{"type":"object","title":"time","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}},"clock":{"type":"integer","description":"the interface's clock: the sample's number"}"#;
    let vec3 = r#"{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}"#;
    let quat = r#"{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}"#;
    let pose =
        format!(r#"{{"type":"object","properties":{{"position":{vec3},"orientation":{quat}}}}}"#);
    match kind {
        "encoders" => (
            "foxglove.PoseInFrame".into(),
            format!(
                r#"{{"title":"foxglove.PoseInFrame","description":"Odometry (jderobot encoders: x, y mm, theta rad in jderobot)","type":"object","properties":{{{ts},"frame_id":{{"type":"string"}},"pose":{pose},"jderobot":{{"type":"object"}}}}}}"#
            ),
        ),
        other => (
            format!("jderobot.{other}"),
            format!(
                r#"{{"title":"jderobot.{other}","description":"a jderobot {other} interface value in its units (see src/interfaces)","type":"object","properties":{{{ts},"jderobot":{{"type":"object"}}}}}}"#
            ),
        ),
    }
}

fn f32_json(v: f32) -> Value {
    // JSON has no NaN or infinity; jderobot's values are finite (validated).
    serde_json::Number::from_f64(v as f64)
        .map(Value::Number)
        .unwrap_or(Value::Null)
}

/// How the recorder writes MCAP: chunks of 4 MiB (closed at least every second by
/// the recorder, so a kill loses at most that), `compression`, the `ros2` profile or
/// none. Each chunk carries its CRC; the data-section CRC (a second pass over every
/// byte, checkable only on a complete file) is left out, as MCAP allows.
pub fn write_options(
    compression: Option<mcap::Compression>,
    profile: Profile,
) -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(compression)
        .profile(if profile == Profile::Ros2 { "ros2" } else { "" })
        .library(concat!("jderobot ", env!("CARGO_PKG_VERSION")))
        .chunk_size(Some(4 * 1024 * 1024))
        .calculate_data_section_crc(false)
}

/// Encodes a sample of a JSON channel (encoders and the kinds without a Foxglove
/// schema) into `out`, cleared first.
fn encode_json(snap: &Snapshot, out: &mut Vec<u8>) {
    out.clear();
    let ns = nanos(snap.time());
    let mut s = String::with_capacity(256);
    let _ = write!(
        s,
        r#"{{"timestamp":{{"sec":{},"nsec":{}}},"clock":{}"#,
        ns / 1_000_000_000,
        ns % 1_000_000_000,
        snap.clock()
    );
    let j = match snap {
        Snapshot::Encoders(e) => {
            let half = e.theta as f64 / 2.0;
            let _ = write!(
                s,
                r#","frame_id":"odom","pose":{{"position":{{"x":{},"y":{},"z":0}},"orientation":{{"x":0,"y":0,"z":{},"w":{}}}}}"#,
                e.x as f64 / 1000.0,
                e.y as f64 / 1000.0,
                half.sin(),
                half.cos(),
            );
            json!({"x": f32_json(e.x), "y": f32_json(e.y), "theta": f32_json(e.theta),
                   "cos": f32_json(e.cos), "sin": f32_json(e.sin)})
        }
        Snapshot::Motors(m) => json!({"v": f32_json(m.v), "w": f32_json(m.w)}),
        Snapshot::Sonars(v) => {
            json!({ "us": v.us.iter().map(|x| f32_json(*x)).collect::<Vec<_>>() })
        }
        Snapshot::Bumpers(b) => json!({ "bumpers": b.bumpers }),
        Snapshot::PtEncoders(p) => {
            json!({"pan_angle": f32_json(p.pan_angle), "tilt_angle": f32_json(p.tilt_angle)})
        }
        Snapshot::PtMotors(p) => json!({
            "longitude": f32_json(p.longitude), "latitude": f32_json(p.latitude),
            "longitude_speed": f32_json(p.longitude_speed),
            "latitude_speed": f32_json(p.latitude_speed),
            "max_longitude": f32_json(p.max_longitude), "min_longitude": f32_json(p.min_longitude),
            "max_latitude": f32_json(p.max_latitude), "min_latitude": f32_json(p.min_latitude),
            "max_longitude_speed": f32_json(p.max_longitude_speed),
            "max_latitude_speed": f32_json(p.max_latitude_speed),
        }),
        // Never: `encode` writes images and laser scans as protobuf.
        Snapshot::Image(_) | Snapshot::Laser(_) => Value::Null,
    };
    let _ = write!(s, r#","jderobot":{j}}}"#);
    out.extend_from_slice(s.as_bytes());
}

/// Encodes an image sample as a `foxglove.CompressedImage` JPEG message (quality
/// 1..=100, protobuf) into `out`.
pub fn encode_jpeg(name: &str, snap: &Sample<Image>, quality: u8, out: &mut Vec<u8>) {
    let jpeg = jpeg(snap, quality).unwrap_or_default();
    protobuf::compressed_image(name, nanos(snap.time), "jpeg", &jpeg, out);
}

/// The JPEG file of an image (quality 1..=100); `None` if the encoder fails.
pub fn jpeg(img: &Image, quality: u8) -> Option<Vec<u8>> {
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, quality)
        .encode(
            &img.to_rgb(),
            img.width,
            img.height,
            image::ExtendedColorType::Rgb8,
        )
        .ok()?;
    Some(jpeg)
}

/// A `jpeg` or `png` file back to a BGR image; the error says what was wrong.
pub fn decompress(format: &str, data: &[u8]) -> Result<Image, String> {
    let fmt = match format {
        "jpeg" => image::ImageFormat::Jpeg,
        "png" => image::ImageFormat::Png,
        other => {
            return Err(format!(
                "compressed image format `{other}`; jderobot reads jpeg and png"
            ));
        }
    };
    let rgb = image::load_from_memory_with_format(data, fmt)
        .map_err(|e| format!("the {format} image does not decode: {e}"))?
        .to_rgb8();
    let (width, height) = rgb.dimensions();
    Ok(Image::from_rgb(width, height, rgb.into_raw()))
}

/// A compressed image (`jpeg` or `png`) back to BGR.
fn decode_compressed(topic: &str, format: &str, data: &[u8]) -> Result<Recorded, FormatError> {
    decompress(format, data)
        .map(Recorded::Image)
        .map_err(|e| bad(topic, e))
}

/// The channel metadata of an interface kind.
pub fn metadata(kind: &str) -> BTreeMap<String, String> {
    BTreeMap::from([(KIND_KEY.to_string(), kind.to_string())])
}

/// The interface a channel replays into: its `jderobot.interface` metadata, or
/// the topic (`/laser/robot2` → `laser.robot2`).
pub fn interface_name(topic: &str, metadata: &BTreeMap<String, String>) -> String {
    if let Some(n) = metadata.get(NAME_KEY) {
        return n.clone();
    }
    topic.trim_start_matches('/').replace('/', ".")
}

/// Decodes a message by its channel's encoding: `protobuf` (images, laser: the
/// clock is the MCAP `sequence`), `json` (the clock is in the message) or `cdr`
/// (the `ros2` profile; the clock is the `sequence`). `schema` is the channel's
/// schema name (it tells a raw image from a compressed one).
pub fn decode_message(
    topic: &str,
    kind: &str,
    schema: &str,
    encoding: &str,
    sequence: u32,
    log_time: u64,
    data: &[u8],
) -> Result<Decoded, FormatError> {
    match encoding {
        "protobuf" => {
            let (time_ns, value) = match (kind, schema) {
                ("image", "foxglove.RawImage") => {
                    protobuf::decode_image(topic, false, data, log_time)?
                }
                ("image", "foxglove.CompressedImage") => {
                    protobuf::decode_image(topic, true, data, log_time)?
                }
                ("laser", "foxglove.LaserScan") => protobuf::decode_laser(topic, data, log_time)?,
                _ => {
                    return Err(bad(
                        topic,
                        format!(
                            "a protobuf `{schema}` channel of kind `{kind}`; jderobot reads foxglove.RawImage, foxglove.CompressedImage and foxglove.LaserScan"
                        ),
                    ));
                }
            };
            Ok(Decoded {
                clock: sequence as u64,
                time_ns,
                value,
            })
        }
        "json" => decode(topic, kind, data),
        "cdr" => ros2::decode(topic, kind, data, sequence as u64, log_time),
        other => Err(bad(
            topic,
            format!("message encoding `{other}`; jderobot reads protobuf, json and cdr"),
        )),
    }
}

/// Decodes an MCAP message of a channel of interface kind `kind` ([`decode_message`]
/// with the message's channel, sequence and log time).
pub fn decode_mcap(kind: &str, m: &mcap::Message) -> Result<Decoded, FormatError> {
    decode_message(
        &m.channel.topic,
        kind,
        m.channel.schema.as_ref().map_or("", |s| s.name.as_str()),
        &m.channel.message_encoding,
        m.sequence,
        m.log_time,
        &m.data,
    )
}

/// Decodes a message read by [`reader`] ([`decode_message`] with its channel,
/// sequence and log time).
pub fn decode_read(kind: &str, m: &reader::Message<'_>) -> Result<Decoded, FormatError> {
    decode_message(
        &m.channel.topic,
        kind,
        m.channel.schema.as_ref().map_or("", |s| s.name.as_str()),
        &m.channel.message_encoding,
        m.sequence,
        m.log_time,
        m.data,
    )
}

/// The interface kind of a channel: its metadata, or what its schema name says.
pub fn channel_kind(metadata: &BTreeMap<String, String>, schema: Option<&str>) -> Option<String> {
    if let Some(k) = metadata.get(KIND_KEY) {
        return Some(k.clone());
    }
    match schema? {
        "foxglove.RawImage" | "foxglove.CompressedImage" => Some("image".into()),
        "foxglove.LaserScan" => Some("laser".into()),
        "foxglove.PoseInFrame" => Some("encoders".into()),
        s => ros2::kind_of(s)
            .map(str::to_string)
            .or_else(|| s.strip_prefix("jderobot.").map(str::to_string)),
    }
}

/// A decoded message: the interface's clock, its wall time and its value.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded {
    pub clock: u64,
    pub time_ns: u64,
    pub value: Recorded,
}

fn get<'a>(v: &'a Value, key: &str, topic: &str) -> Result<&'a Value, FormatError> {
    v.get(key)
        .ok_or_else(|| bad(topic, format!("the message has no `{key}`")))
}

fn num(v: &Value, key: &str, topic: &str) -> Result<f64, FormatError> {
    get(v, key, topic)?
        .as_f64()
        .ok_or_else(|| bad(topic, format!("`{key}` is not a number")))
}

fn f32_of(v: &Value, key: &str, topic: &str) -> Result<f32, FormatError> {
    Ok(num(v, key, topic)? as f32)
}

fn f32_array(v: &Value, key: &str, topic: &str) -> Result<Vec<f32>, FormatError> {
    get(v, key, topic)?
        .as_array()
        .ok_or_else(|| bad(topic, format!("`{key}` is not an array")))?
        .iter()
        .map(|x| {
            x.as_f64()
                .map(|f| f as f32)
                .ok_or_else(|| bad(topic, format!("`{key}` holds a non-number")))
        })
        .collect()
}

/// Decodes a JSON message (encoders and the kinds without a Foxglove schema) of
/// interface kind `kind` on channel `topic`.
pub fn decode(topic: &str, kind: &str, data: &[u8]) -> Result<Decoded, FormatError> {
    let v: Value = serde_json::from_slice(data)
        .map_err(|e| bad(topic, format!("the message is not JSON: {e}")))?;
    let ts = get(&v, "timestamp", topic)?;
    let time_ns = num(ts, "sec", topic)? as u64 * 1_000_000_000 + num(ts, "nsec", topic)? as u64;
    let clock = get(&v, "clock", topic)?
        .as_u64()
        .ok_or_else(|| bad(topic, "`clock` is not a whole number"))?;
    let value = match kind {
        "image" | "laser" => {
            return Err(bad(
                topic,
                format!(
                    "a JSON {kind} message: jderobot writes images and laser scans as protobuf (recordings made before that are not read)"
                ),
            ));
        }
        "encoders" => {
            let j = get(&v, "jderobot", topic)?;
            Recorded::Encoders(Encoders {
                x: f32_of(j, "x", topic)?,
                y: f32_of(j, "y", topic)?,
                theta: f32_of(j, "theta", topic)?,
                cos: f32_of(j, "cos", topic)?,
                sin: f32_of(j, "sin", topic)?,
            })
        }
        "motors" => {
            let j = get(&v, "jderobot", topic)?;
            Recorded::Motors(Motors {
                v: f32_of(j, "v", topic)?,
                w: f32_of(j, "w", topic)?,
            })
        }
        "sonars" => Recorded::Sonars(Sonars {
            us: f32_array(get(&v, "jderobot", topic)?, "us", topic)?,
        }),
        "bumpers" => {
            let j = get(&v, "jderobot", topic)?;
            let bumpers = get(j, "bumpers", topic)?
                .as_array()
                .ok_or_else(|| bad(topic, "`bumpers` is not an array"))?
                .iter()
                .map(|x| {
                    x.as_u64()
                        .map(|b| b as u8)
                        .ok_or_else(|| bad(topic, "a bumper is not 0 or 1"))
                })
                .collect::<Result<Vec<_>, _>>()?;
            Recorded::Bumpers(Bumpers { bumpers })
        }
        "pantiltencoders" => {
            let j = get(&v, "jderobot", topic)?;
            Recorded::PtEncoders(PtEncoders {
                pan_angle: f32_of(j, "pan_angle", topic)?,
                tilt_angle: f32_of(j, "tilt_angle", topic)?,
            })
        }
        "pantiltmotors" => {
            let j = get(&v, "jderobot", topic)?;
            Recorded::PtMotors(PtMotors {
                longitude: f32_of(j, "longitude", topic)?,
                latitude: f32_of(j, "latitude", topic)?,
                longitude_speed: f32_of(j, "longitude_speed", topic)?,
                latitude_speed: f32_of(j, "latitude_speed", topic)?,
                max_longitude: f32_of(j, "max_longitude", topic)?,
                min_longitude: f32_of(j, "min_longitude", topic)?,
                max_latitude: f32_of(j, "max_latitude", topic)?,
                min_latitude: f32_of(j, "min_latitude", topic)?,
                max_longitude_speed: f32_of(j, "max_longitude_speed", topic)?,
                max_latitude_speed: f32_of(j, "max_latitude_speed", topic)?,
            })
        }
        other => {
            return Err(FormatError::Kind {
                topic: topic.into(),
                kind: other.into(),
            });
        }
    };
    Ok(Decoded {
        clock,
        time_ns,
        value,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Instant;

    fn sample<T>(clock: u64, value: T) -> Arc<Sample<T>> {
        Arc::new(Sample {
            clock,
            stamp: Instant::now(),
            time: from_nanos(1_700_000_000_123_456_789),
            value,
        })
    }

    #[test]
    fn values_round_trip_exactly() {
        let cases = vec![
            (
                Snapshot::Laser(sample(
                    3,
                    Laser {
                        readings: vec![1, 8000, 123, -1],
                        resolution: 1.0,
                    },
                )),
                Recorded::Laser(Laser {
                    readings: vec![1, 8000, 123, -1],
                    resolution: 1.0,
                }),
                "laser",
            ),
            (
                Snapshot::Encoders(sample(
                    4,
                    Encoders {
                        x: 1000.25,
                        y: -3.1,
                        theta: 5.5,
                        cos: 0.1,
                        sin: 0.3,
                    },
                )),
                Recorded::Encoders(Encoders {
                    x: 1000.25,
                    y: -3.1,
                    theta: 5.5,
                    cos: 0.1,
                    sin: 0.3,
                }),
                "encoders",
            ),
            (
                Snapshot::Sonars(sample(
                    5,
                    Sonars {
                        us: vec![0.1, 5000.0, 333.3],
                    },
                )),
                Recorded::Sonars(Sonars {
                    us: vec![0.1, 5000.0, 333.3],
                }),
                "sonars",
            ),
            (
                Snapshot::Image(sample(
                    6,
                    Image {
                        width: 2,
                        height: 1,
                        data: vec![1, 2, 3, 250, 251, 252],
                    },
                )),
                Recorded::Image(Image {
                    width: 2,
                    height: 1,
                    data: vec![1, 2, 3, 250, 251, 252],
                }),
                "image",
            ),
        ];
        // Written into an MCAP file as the recorder does, read back as the replay does.
        let profile = Profile::Foxglove { jpeg: None };
        let mut w = write_options(None, profile)
            .create(std::io::Cursor::new(Vec::new()))
            .unwrap();
        let mut buf = Vec::new();
        for (i, (snap, _, kind)) in cases.iter().enumerate() {
            let name = format!("x{i}");
            let id = add_channel(&mut w, &name, kind, profile).unwrap().unwrap();
            assert!(encode(profile, &name, snap, &mut buf));
            let t = nanos(snap.time());
            let header = mcap::records::MessageHeader {
                channel_id: id,
                sequence: snap.clock() as u32,
                log_time: t,
                publish_time: t,
            };
            w.write_to_known_channel(&header, &buf).unwrap();
        }
        w.finish().unwrap();
        let file = w.into_inner().into_inner();
        let mut n = 0;
        for (m, (snap, value, kind)) in mcap::MessageStream::new(&file).unwrap().zip(&cases) {
            let d = decode_mcap(kind, &m.unwrap()).unwrap();
            assert_eq!(&d.value, value);
            assert_eq!(d.clock, snap.clock());
            assert_eq!(d.time_ns, 1_700_000_000_123_456_789);
            n += 1;
        }
        assert_eq!(n, cases.len());
        // The same through jderobot's own reader (what replay uses).
        let mut back = Vec::new();
        let o = reader::read_messages(&file, |m| {
            back.push(decode_read(&m.channel.metadata[KIND_KEY], m).unwrap().value);
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
        assert!(o.problems.is_empty() && o.complete, "{o:?}");
        let want: Vec<Recorded> = cases.iter().map(|c| c.1.clone()).collect();
        assert_eq!(back, want);
    }

    #[test]
    fn encoders_keep_cos_and_sin_exactly() {
        // cos and sin of the unnormalised angle: not what θ (normalised) gives.
        let e = Encoders::from_pose(1.5, -2.25, -7.3);
        let snap = Snapshot::Encoders(sample(9, e));
        let mut buf = Vec::new();
        assert!(encode(
            Profile::Foxglove { jpeg: None },
            "encoders",
            &snap,
            &mut buf
        ));
        let d = decode_message(
            "encoders",
            "encoders",
            "foxglove.PoseInFrame",
            "json",
            0,
            0,
            &buf,
        )
        .unwrap();
        assert_eq!(d.value, Recorded::Encoders(e));
        assert_eq!(d.clock, 9);
    }

    #[test]
    fn garbage_is_a_clear_error() {
        let e = decode("laser", "laser", b"{not json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("laser") && e.contains("not JSON"), "{e}");
        let e = decode(
            "motors",
            "motors",
            br#"{"timestamp":{"sec":1,"nsec":2},"clock":1}"#,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("jderobot"), "{e}");
    }
}
