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
//! | `laser` | `foxglove.LaserScan` | protobuf | `ranges` in m (the mm readings / 1000), angles in rad (−π/2 first; `end_angle` gives the resolution back); the range limits in the channel's metadata ([`MIN_RANGE_KEY`]) |
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
//! corrupt: see [`reader`]) for `jderobot info`; [`RecorderStatus`] is what
//! the recorder exports in the name space (`recorder.status`) for its shell
//! command and mastergui.

#[cfg(feature = "ros2")]
pub mod dds;
pub mod protobuf;
pub mod reader;
pub mod ros2;
mod status;
mod summary;

pub use status::RecorderStatus;
pub use summary::{ChannelSummary, MAX_FILE_BYTES, ReadError, Summary};

use std::{
    collections::BTreeMap,
    sync::Arc,
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use serde::Deserialize;
use serde_json::Value;

use crate::interfaces::{
    AnyInterface, Image, Interface, Interfaces, Kind, MAX_RANGE_MM, Sample, for_each_kind,
};

/// The metadata key of a channel that names the interface kind.
pub const KIND_KEY: &str = "jderobot.kind";
/// The metadata key of a channel that names the interface (in the `ros2`
/// profile, where the topic is `/laser`).
pub const NAME_KEY: &str = "jderobot.interface";
/// The metadata keys of a laser channel's range limits (mm, as the shortest text
/// that reads back the same f32), which `foxglove.LaserScan` has no fields for:
/// the limits of the channel's first scan (a laser's limits do not change while
/// it runs). Written by [`add_sample_channel`] in the Foxglove profile (the
/// `ros2` LaserScan carries them in each message), read back by [`decode_read`]
/// and [`decode_mcap`].
pub const MIN_RANGE_KEY: &str = "jderobot.laser.min_range";
/// See [`MIN_RANGE_KEY`].
pub const MAX_RANGE_KEY: &str = "jderobot.laser.max_range";

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

/// Builds, from the table of interface kinds, the enums over every kind and their
/// per-kind dispatch: adding a kind to the table adds it here.
macro_rules! kind_enums {
    (; $(($t:ident, $k:literal)),*) => {
        /// One recorded value, whatever its interface kind.
        #[derive(Clone, Debug, PartialEq)]
        pub enum Recorded {
            $($t(crate::interfaces::$t),)*
        }

        /// A sample shared with its interface (no copy), ready to encode.
        #[derive(Clone)]
        pub enum Snapshot {
            $($t(Arc<Sample<crate::interfaces::$t>>),)*
        }

        /// A typed interface: polled for new samples (recorder), or published into
        /// (replay).
        #[derive(Clone)]
        pub enum Source {
            $($t(Arc<Interface<crate::interfaces::$t>>),)*
        }

        impl Snapshot {
            pub fn clock(&self) -> u64 {
                match self { $(Snapshot::$t(s) => s.clock,)* }
            }
            pub fn time(&self) -> SystemTime {
                match self { $(Snapshot::$t(s) => s.time,)* }
            }
            /// The interface kind (`AnyInterface::kind`).
            pub fn kind(&self) -> Kind {
                match self { $(Snapshot::$t(_) => Kind::$t,)* }
            }

            /// Encodes the sample as its ROS 2 message (CDR); false for a kind without one.
            fn ros2(&self, name: &str, out: &mut Vec<u8>) -> bool {
                match self { $(Snapshot::$t(s) => ros2::encode(name, &**s, out),)* }
            }
        }

        /// A sample serializes as its value: its fields in its units.
        impl serde::Serialize for Snapshot {
            fn serialize<S: serde::Serializer>(&self, ser: S) -> Result<S::Ok, S::Error> {
                match self { $(Snapshot::$t(s) => s.value.serialize(ser),)* }
            }
        }

        impl Source {
            /// The typed interface `name`, or `None` when there is none.
            pub fn find(interfaces: &Interfaces, name: &str) -> Option<Source> {
                match interfaces.get_any(name).ok()?.kind() {
                    $(Kind::$t => Some(Source::$t(interfaces.get(name).ok()?)),)*
                }
            }

            /// Provides interface `name` of kind `kind` for `provider`.
            pub fn provide(
                interfaces: &Interfaces,
                name: &str,
                kind: Kind,
                provider: &str,
            ) -> Result<Source, String> {
                match kind {
                    $(Kind::$t => interfaces.provide(name, provider).map(Source::$t).map_err(|e| e.to_string()),)*
                }
            }

            pub fn any(&self) -> &dyn AnyInterface {
                match self { $(Source::$t(i) => &**i,)* }
            }

            /// The latest sample, shared (no copy).
            pub fn snapshot(&self) -> Snapshot {
                match self { $(Source::$t(i) => Snapshot::$t(i.snapshot()),)* }
            }

            /// Keeps the interface's recent samples for [`since`](Self::since)
            /// (`Interface::keep_history`).
            pub fn keep_history(&self, on: bool) {
                match self { $(Source::$t(i) => i.keep_history(on),)* }
            }

            /// The samples after clock `after`, oldest first, into `out`; returns
            /// how many of them are gone (`Interface::since`).
            pub fn since(&self, after: u64, out: &mut Vec<Snapshot>) -> u64 {
                match self {
                    $(Source::$t(i) => {
                        let mut taken = Vec::new();
                        let gone = i.since(after, &mut taken);
                        out.extend(taken.into_iter().map(Snapshot::$t));
                        gone
                    })*
                }
            }

            /// Publishes a recorded value with its clock and wall time; an actuator
            /// is left to whoever commands it (nothing is published).
            pub fn publish_recorded(
                &self,
                clock: u64,
                time: SystemTime,
                value: Recorded,
            ) -> Result<(), String> {
                if self.any().is_actuator() {
                    return Ok(());
                }
                let r = match (self, value) {
                    $((Source::$t(i), Recorded::$t(v)) => i.publish_recorded(clock, time, v),)*
                    (_, v) => {
                        return Err(format!(
                            "a {} value on a {} interface",
                            v.kind(),
                            self.any().kind()
                        ));
                    }
                };
                r.map(|_| ()).map_err(|e| e.to_string())
            }
        }

        impl Recorded {
            /// The value as a sample of clock `clock` taken at `time`.
            #[cfg(test)]
            fn sample(self, clock: u64, time: SystemTime) -> Snapshot {
                let stamp = std::time::Instant::now();
                match self {
                    $(Recorded::$t(value) => Snapshot::$t(Arc::new(Sample { clock, stamp, time, value })),)*
                }
            }
            /// The interface kind (`AnyInterface::kind`).
            pub fn kind(&self) -> Kind {
                match self { $(Recorded::$t(_) => Kind::$t,)* }
            }
            /// A value of kind `kind` from the `jderobot` object of a JSON message.
            fn from_json(topic: &str, kind: Kind, j: &Value) -> Result<Recorded, FormatError> {
                match kind {
                    $(Kind::$t => crate::interfaces::$t::deserialize(j)
                        .map(Recorded::$t)
                        .map_err(|e| bad(topic, format!("`jderobot` is not a {} value: {e}", $k))),)*
                }
            }
            /// A CDR message of kind `kind` ([`ros2::decode`]): (time ns, value).
            fn from_cdr(
                topic: &str,
                kind: Kind,
                data: &[u8],
                log_time: u64,
            ) -> Result<(u64, Recorded), FormatError> {
                match kind {
                    $(Kind::$t => ros2::decode::<crate::interfaces::$t>(topic, data, log_time)
                        .map(|(t, v)| (t, Recorded::$t(v))),)*
                }
            }
        }
    };
}
for_each_kind!(kind_enums! {});

/// Nanoseconds since the Unix epoch.
pub fn nanos(t: SystemTime) -> u64 {
    t.duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

impl Snapshot {
    /// Its MCAP record header on channel `channel_id`: the interface's clock is the
    /// message's sequence (mod 2^32), its time both the log and the publish time.
    pub fn header(&self, channel_id: u16) -> mcap::records::MessageHeader {
        let t = nanos(self.time());
        mcap::records::MessageHeader {
            channel_id,
            sequence: self.clock() as u32,
            log_time: t,
            publish_time: t,
        }
    }
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

/// Adds the schema and the channel of interface `name` (of kind `kind`) to
/// `writer`: the channel id, or `None` when the profile does not carry the kind
/// (`ros2`: laser, image, encoders and motors only).
pub fn add_channel<W: std::io::Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
    name: &str,
    kind: Kind,
    profile: Profile,
) -> Result<Option<u16>, mcap::McapError> {
    add_channel_with(writer, name, kind, profile, BTreeMap::new())
}

/// [`add_channel`] for a channel whose first sample is `snap`, as the recorder
/// adds them: in the Foxglove profile a laser channel's metadata also carries
/// the scan's range limits ([`MIN_RANGE_KEY`], [`MAX_RANGE_KEY`]).
pub fn add_sample_channel<W: std::io::Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
    name: &str,
    snap: &Snapshot,
    profile: Profile,
) -> Result<Option<u16>, mcap::McapError> {
    let mut extra = BTreeMap::new();
    if let (Profile::Foxglove { .. }, Snapshot::Laser(l)) = (profile, snap) {
        extra.insert(MIN_RANGE_KEY.to_string(), l.value.min_range.to_string());
        extra.insert(MAX_RANGE_KEY.to_string(), l.value.max_range.to_string());
    }
    add_channel_with(writer, name, snap.kind(), profile, extra)
}

fn add_channel_with<W: std::io::Write + std::io::Seek>(
    writer: &mut mcap::Writer<W>,
    name: &str,
    kind: Kind,
    profile: Profile,
    extra: BTreeMap<String, String>,
) -> Result<Option<u16>, mcap::McapError> {
    let mut meta = metadata(kind);
    meta.extend(extra);
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
        (Profile::Foxglove { jpeg: None }, Kind::Image) => {
            ("foxglove.RawImage", protobuf::RAW_IMAGE)
        }
        (Profile::Foxglove { jpeg: Some(_) }, Kind::Image) => {
            ("foxglove.CompressedImage", protobuf::COMPRESSED_IMAGE)
        }
        (_, Kind::Laser) => ("foxglove.LaserScan", protobuf::LASER_SCAN),
        (
            Profile::Foxglove { .. },
            Kind::Sonars
            | Kind::Encoders
            | Kind::Motors
            | Kind::PtEncoders
            | Kind::PtMotors
            | Kind::ZoomEncoders
            | Kind::ZoomMotors
            | Kind::Bumpers
            | Kind::Imu,
        ) => {
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
        (Profile::Ros2, _) => return snap.ros2(name, out),
        (Profile::Foxglove { jpeg: Some(q) }, Snapshot::Image(img)) => {
            encode_jpeg(name, img, q, out)
        }
        (_, Snapshot::Image(img)) => protobuf::raw_image(name, ns, img, out),
        (_, Snapshot::Laser(l)) => protobuf::laser_scan(name, ns, l, out),
        _ => encode_json(snap, out),
    }
    true
}

/// Encodes `snap` as the recorder writes it: the message is `head` (encoded into
/// it) followed by the returned slice, a raw image's pixels borrowed from the
/// sample, so a frame reaches the file without a copy (the rest: all in `head`,
/// an empty slice). `None` for a sample the profile does not carry.
pub fn encode_parts<'a>(
    profile: Profile,
    name: &str,
    snap: &'a Snapshot,
    head: &mut Vec<u8>,
) -> Option<&'a [u8]> {
    match (profile, snap) {
        (Profile::Ros2, Snapshot::Image(img)) => {
            ros2::image_head(name, img, head);
            Some(&img.value.data)
        }
        (Profile::Foxglove { jpeg: None }, Snapshot::Image(img)) => {
            protobuf::raw_image_head(name, nanos(img.time), img, head);
            Some(&img.value.data)
        }
        _ => encode(profile, name, snap, head).then_some(&[]),
    }
}

/// Writes `snap` on `channel` as the recorder does ([`encode_parts`], `buf` for the
/// encoded part); `Ok(false)` when the profile does not carry it.
pub fn write_sample<W: std::io::Write + std::io::Seek>(
    w: &mut mcap::Writer<W>,
    profile: Profile,
    channel: u16,
    name: &str,
    snap: &Snapshot,
    buf: &mut Vec<u8>,
) -> mcap::McapResult<bool> {
    let Some(tail) = encode_parts(profile, name, snap, buf) else {
        return Ok(false);
    };
    w.write_parts_to_known_channel(&snap.header(channel), &[buf, tail])?;
    Ok(true)
}

/// The JSON schema (name, schema text) of an interface kind written as JSON:
/// `foxglove.PoseInFrame` for encoders, `jderobot.KIND` for the rest.
pub fn json_schema(kind: Kind) -> (String, String) {
    use serde_json::json;
    let number = json!({"type": "number"});
    let vec3 = json!({"type": "object", "properties": {"x": number, "y": number, "z": number}});
    let quat = json!({"type": "object",
        "properties": {"x": number, "y": number, "z": number, "w": number}});
    let timestamp = json!({"type": "object", "title": "time", "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}});
    let clock =
        json!({"type": "integer", "description": "the interface's clock: the sample's number"});
    let (name, description, mut properties) = match kind {
        Kind::Encoders => (
            "foxglove.PoseInFrame".to_string(),
            "Odometry (jderobot encoders: x, y mm, theta rad in jderobot)".to_string(),
            json!({"frame_id": {"type": "string"},
                "pose": {"type": "object", "properties": {"position": vec3, "orientation": quat}}}),
        ),
        other => (
            format!("jderobot.{other}"),
            format!("a jderobot {other} interface value in its units (see src/interfaces)"),
            json!({}),
        ),
    };
    properties["timestamp"] = timestamp;
    properties["clock"] = clock;
    properties["jderobot"] = json!({"type": "object"});
    let schema = json!({"title": name, "description": description, "type": "object",
        "properties": properties});
    (name, schema.to_string())
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

/// An MCAP writer on `file` as the recorder writes ([`write_options`]), through a
/// 64 KiB buffer: a message's record header and an index are not system calls
/// of their own (pixels go straight through), and [`mcap::Writer::flush`] still
/// hands everything to the kernel.
pub fn writer(
    file: std::fs::File,
    compression: Option<mcap::Compression>,
    profile: Profile,
) -> mcap::McapResult<mcap::Writer<std::io::BufWriter<std::fs::File>>> {
    write_options(compression, profile).create(std::io::BufWriter::with_capacity(64 << 10, file))
}

/// Encodes a sample of a JSON channel (encoders and the kinds without a Foxglove
/// schema) into `out`, cleared first: the timestamp, the clock, (for encoders)
/// Foxglove's pose, and `jderobot`, the value's fields in its units.
/// The JSON message of a sample: its time and clock, for encoders Foxglove's
/// `PoseInFrame` (m, quaternion), and the value itself under `jderobot`.
#[derive(serde::Serialize)]
struct Envelope<'a> {
    timestamp: Time,
    clock: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    frame_id: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pose: Option<Pose>,
    jderobot: &'a Snapshot,
}

#[derive(serde::Serialize)]
struct Time {
    sec: u64,
    nsec: u64,
}

#[derive(serde::Serialize)]
struct Pose {
    position: Xyzw,
    orientation: Xyzw,
}

#[derive(serde::Serialize)]
struct Xyzw {
    x: f64,
    y: f64,
    z: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    w: Option<f64>,
}

fn encode_json(snap: &Snapshot, out: &mut Vec<u8>) {
    out.clear();
    let ns = nanos(snap.time());
    let pose = match snap {
        Snapshot::Encoders(e) => {
            let half = e.theta as f64 / 2.0;
            Some(Pose {
                position: Xyzw {
                    x: e.x as f64 / 1000.0,
                    y: e.y as f64 / 1000.0,
                    z: 0.0,
                    w: None,
                },
                orientation: Xyzw {
                    x: 0.0,
                    y: 0.0,
                    z: half.sin(),
                    w: Some(half.cos()),
                },
            })
        }
        _ => None,
    };
    let envelope = Envelope {
        timestamp: Time {
            sec: ns / 1_000_000_000,
            nsec: ns % 1_000_000_000,
        },
        clock: snap.clock(),
        frame_id: pose.as_ref().map(|_| "odom"),
        pose,
        jderobot: snap,
    };
    let r = serde_json::to_writer(&mut *out, &envelope);
    debug_assert!(r.is_ok(), "a sample always serializes");
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
pub fn metadata(kind: Kind) -> BTreeMap<String, String> {
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
    kind: Kind,
    schema: &str,
    encoding: &str,
    sequence: u32,
    log_time: u64,
    data: &[u8],
) -> Result<Decoded, FormatError> {
    match encoding {
        "protobuf" => {
            let (time_ns, value) = match (kind, schema) {
                (Kind::Image, "foxglove.RawImage") => {
                    protobuf::decode_image(topic, false, data, log_time)?
                }
                (Kind::Image, "foxglove.CompressedImage") => {
                    protobuf::decode_image(topic, true, data, log_time)?
                }
                (Kind::Laser, "foxglove.LaserScan") => {
                    protobuf::decode_laser(topic, data, log_time)?
                }
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
        "cdr" => {
            let (time_ns, value) = Recorded::from_cdr(topic, kind, data, log_time)?;
            Ok(Decoded {
                clock: sequence as u64,
                time_ns,
                value,
            })
        }
        other => Err(bad(
            topic,
            format!("message encoding `{other}`; jderobot reads protobuf, json and cdr"),
        )),
    }
}

/// Decodes an MCAP message of a channel of interface kind `kind` ([`decode_message`]
/// with the message's channel, sequence and log time).
pub fn decode_mcap(kind: Kind, m: &mcap::Message) -> Result<Decoded, FormatError> {
    let d = decode_message(
        &m.channel.topic,
        kind,
        m.channel.schema.as_ref().map_or("", |s| s.name.as_str()),
        &m.channel.message_encoding,
        m.sequence,
        m.log_time,
        &m.data,
    )?;
    channel_limits(&m.channel.topic, &m.channel.metadata, d)
}

/// Decodes a message read by [`reader`] ([`decode_message`] with its channel,
/// sequence and log time).
pub fn decode_read(kind: Kind, m: &reader::Message<'_>) -> Result<Decoded, FormatError> {
    let d = decode_message(
        &m.channel.topic,
        kind,
        m.channel.schema.as_ref().map_or("", |s| s.name.as_str()),
        &m.channel.message_encoding,
        m.sequence,
        m.log_time,
        m.data,
    )?;
    channel_limits(&m.channel.topic, &m.channel.metadata, d)
}

/// A decoded laser with the range limits its channel's metadata records
/// ([`MIN_RANGE_KEY`], [`MAX_RANGE_KEY`]); without them, what the message gave
/// (a `foxglove.LaserScan` of another program: see [`protobuf::decode_laser`]).
fn channel_limits(
    topic: &str,
    metadata: &BTreeMap<String, String>,
    mut d: Decoded,
) -> Result<Decoded, FormatError> {
    let Recorded::Laser(l) = &mut d.value else {
        return Ok(d);
    };
    let Some(max) = metadata.get(MAX_RANGE_KEY) else {
        return Ok(d);
    };
    let min = metadata.get(MIN_RANGE_KEY).map_or("0", |s| s.as_str());
    let (min, max) = (min.parse::<f32>(), max.parse::<f32>());
    match (min, max) {
        (Ok(min), Ok(max)) if 0.0 <= min && min <= max && max <= MAX_RANGE_MM => {
            (l.min_range, l.max_range) = (min, max);
            Ok(d)
        }
        _ => Err(bad(
            topic,
            format!(
                "metadata {MIN_RANGE_KEY}, {MAX_RANGE_KEY} are not mm with 0 <= min <= max <= {MAX_RANGE_MM}"
            ),
        )),
    }
}

/// The interface kind a channel names, as written: its metadata, or what its
/// schema name says (`jderobot info` shows it even when it is no kind of ours).
pub fn channel_kind_name(
    metadata: &BTreeMap<String, String>,
    schema: Option<&str>,
) -> Option<String> {
    if let Some(k) = metadata.get(KIND_KEY) {
        return Some(k.clone());
    }
    match schema? {
        "foxglove.RawImage" | "foxglove.CompressedImage" => Some(Kind::Image.to_string()),
        "foxglove.LaserScan" => Some(Kind::Laser.to_string()),
        "foxglove.PoseInFrame" => Some(Kind::Encoders.to_string()),
        s => ros2::kind_of(s)
            .map(|k| k.to_string())
            .or_else(|| s.strip_prefix("jderobot.").map(str::to_string)),
    }
}

/// The interface kind of a channel ([`channel_kind_name`]), if it is one of ours.
pub fn channel_kind(metadata: &BTreeMap<String, String>, schema: Option<&str>) -> Option<Kind> {
    Kind::parse(&channel_kind_name(metadata, schema)?)
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

/// Decodes a JSON message (encoders and the kinds without a Foxglove schema) of
/// interface kind `kind` on channel `topic`.
pub fn decode(topic: &str, kind: Kind, data: &[u8]) -> Result<Decoded, FormatError> {
    let v: Value = serde_json::from_slice(data)
        .map_err(|e| bad(topic, format!("the message is not JSON: {e}")))?;
    let ts = get(&v, "timestamp", topic)?;
    let time_ns = num(ts, "sec", topic)? as u64 * 1_000_000_000 + num(ts, "nsec", topic)? as u64;
    let clock = get(&v, "clock", topic)?
        .as_u64()
        .ok_or_else(|| bad(topic, "`clock` is not a whole number"))?;
    if matches!(kind, Kind::Image | Kind::Laser) {
        return Err(bad(
            topic,
            format!(
                "a JSON {kind} message: jderobot writes images and laser scans as protobuf (recordings made before that are not read)"
            ),
        ));
    }
    let value = Recorded::from_json(topic, kind, get(&v, "jderobot", topic)?)?;
    Ok(Decoded {
        clock,
        time_ns,
        value,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interfaces::{Bumpers, Encoders, Imu, Laser, PtMotors, Sonars, ZoomMotors};
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
        let values = vec![
            Recorded::Laser(Laser {
                readings: vec![1, 8000, 123, -1],
                resolution: 1.0,
                min_range: 20.0,
                max_range: 5600.5,
                ..Laser::default()
            }),
            Recorded::Encoders(Encoders {
                x: 1000.25,
                y: -3.1,
                theta: 5.5,
                cos: 0.1,
                sin: 0.3,
            }),
            Recorded::Sonars(Sonars {
                us: vec![0.1, 5000.0, 333.3],
            }),
            Recorded::Image(Image {
                width: 2,
                height: 1,
                data: vec![1, 2, 3, 250, 251, 252],
            }),
            Recorded::Imu(Imu {
                wz: 0.1,
                az: 9.81,
                ..Imu::default()
            }),
            Recorded::PtMotors(PtMotors {
                longitude: 0.3,
                ..PtMotors::default()
            }),
            Recorded::ZoomMotors(ZoomMotors {
                zoom: 1.7,
                ..ZoomMotors::default()
            }),
            Recorded::Bumpers(Bumpers {
                bumpers: vec![0, 1, 1],
            }),
        ];
        let time = from_nanos(1_700_000_000_123_456_789);
        let cases: Vec<(Snapshot, Recorded, Kind)> = values
            .into_iter()
            .zip(3..)
            .map(|(v, clock)| (v.clone().sample(clock, time), v.clone(), v.kind()))
            .collect();
        // Written into an MCAP file as the recorder does, read back as the replay does.
        let profile = Profile::Foxglove { jpeg: None };
        let mut w = write_options(None, profile)
            .create(std::io::Cursor::new(Vec::new()))
            .unwrap();
        let mut buf = Vec::new();
        for (i, (snap, _, kind)) in cases.iter().enumerate() {
            let name = format!("x{i}");
            let id = add_sample_channel(&mut w, &name, snap, profile)
                .unwrap()
                .unwrap();
            assert_eq!(snap.kind(), *kind);
            assert!(write_sample(&mut w, profile, id, &name, snap, &mut buf).unwrap());
        }
        w.finish().unwrap();
        let file = w.into_inner().into_inner();
        let mut n = 0;
        for (m, (snap, value, kind)) in mcap::MessageStream::new(&file).unwrap().zip(&cases) {
            let d = decode_mcap(*kind, &m.unwrap()).unwrap();
            assert_eq!(&d.value, value);
            assert_eq!(d.clock, snap.clock());
            assert_eq!(d.time_ns, 1_700_000_000_123_456_789);
            n += 1;
        }
        assert_eq!(n, cases.len());
        // The same through jderobot's own reader (what replay uses).
        let mut back = Vec::new();
        let o = reader::read_messages(&file, |m| {
            back.push(
                decode_read(Kind::parse(&m.channel.metadata[KIND_KEY]).unwrap(), m)
                    .unwrap()
                    .value,
            );
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
        assert!(o.problems.is_empty() && o.complete, "{o:?}");
        let want: Vec<Recorded> = cases.iter().map(|c| c.1.clone()).collect();
        assert_eq!(back, want);
    }

    #[test]
    fn a_laser_channel_without_limits_gets_4_3s_and_bad_limits_are_an_error() {
        let scan = Laser {
            readings: vec![300, 9000],
            min_range: 20.0,
            max_range: 12000.0,
            ..Laser::default()
        };
        let mut data = Vec::new();
        protobuf::laser_scan("laser", 5, &scan, &mut data);
        let decode = |meta: &[(&str, &str)]| {
            let d = decode_message(
                "laser",
                Kind::Laser,
                "foxglove.LaserScan",
                "protobuf",
                1,
                5,
                &data,
            )
            .unwrap();
            let meta = meta
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect();
            channel_limits("laser", &meta, d).map(|d| match d.value {
                Recorded::Laser(l) => (l.min_range, l.max_range),
                _ => unreachable!(),
            })
        };
        // Another program's file: from 0 to the farthest reading, at least 8000 mm.
        assert_eq!(decode(&[]).unwrap(), (0.0, 9000.0));
        let both = [(MIN_RANGE_KEY, "20"), (MAX_RANGE_KEY, "12000")];
        assert_eq!(decode(&both).unwrap(), (20.0, 12000.0));
        for bad in [
            [(MIN_RANGE_KEY, "30"), (MAX_RANGE_KEY, "20")],
            [(MIN_RANGE_KEY, "0"), (MAX_RANGE_KEY, "far")],
        ] {
            let e = decode(&bad).unwrap_err().to_string();
            assert!(e.contains("laser") && e.contains(MAX_RANGE_KEY), "{e}");
        }
    }

    #[test]
    fn an_image_in_parts_is_the_same_message_as_in_one_piece() {
        let mut img = Image::new(4, 3);
        img.data
            .iter_mut()
            .enumerate()
            .for_each(|(i, p)| *p = i as u8);
        let snap = Recorded::Image(img).sample(9, from_nanos(1_700_000_000_000_000_005));
        for profile in [Profile::Foxglove { jpeg: None }, Profile::Ros2] {
            let (mut whole, mut head) = (Vec::new(), Vec::new());
            assert!(encode(profile, "colorA", &snap, &mut whole));
            let tail = encode_parts(profile, "colorA", &snap, &mut head).unwrap();
            assert_eq!(
                tail.len(),
                36,
                "{profile:?}: the pixels are the part borrowed"
            );
            assert_eq!([&head[..], tail].concat(), whole, "{profile:?}");
        }
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
            Kind::Encoders,
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
        let e = decode("laser", Kind::Laser, b"{not json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("laser") && e.contains("not JSON"), "{e}");
        let e = decode(
            "motors",
            Kind::Motors,
            br#"{"timestamp":{"sec":1,"nsec":2},"clock":1}"#,
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("jderobot"), "{e}");
    }
}
