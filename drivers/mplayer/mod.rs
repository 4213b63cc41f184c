//! mplayer: any video the `mplayer` program plays (files, URLs, V4L2 devices), as
//! JDE 4.3's `mplayer` driver.
//!
//! 4.3 ran mplayer and mencoder through named pipes. We run the real `mplayer`
//! (Debian package `mplayer`) as a child process with `-vo yuv4mpeg:file=/dev/fd/3`:
//! it writes a YUV4MPEG2 stream (a one-line header with size and frame rate, then
//! 4:2:0 frames) on a pipe that is its file descriptor 3, while its messages go to
//! its standard output and error, which we keep for error messages. yuv4mpeg is
//! the raw video output mplayer has on every build (there is no raw BGR one) and
//! its header carries the frame rate; `-vf scale=W:H` sizes the frames and we
//! convert 4:2:0 to BGR ([`crate::media::y4m`]). mplayer runs with `-benchmark`
//! (no sleeping of its own) and the pipe's back-pressure holds it: the driver paces
//! the frames at the rate in the header, or not at all with `unpaced`. The child
//! never outlives jderobot (see [`crate::media::child`]).
//!
//! # Conf (the seed's lines)
//! ```text
//! driver mplayer
//! provides colorA clip.avi repeat_on               # FILE|URL repeat_on|off: 320x240
//! provides varcolorB clip.avi 640 480 repeat_off   # FILE W H repeat_on|off
//! provides colorC v4l /dev/video0 composite        # cam|tv|composite|s-video
//! provides varcolorD http://host/stream.mp4 320 240 repeat_off unpaced
//! end_driver
//! ```
//! A trailing `unpaced` publishes frames as fast as mplayer decodes them instead of
//! at the video's rate. Relative file names are relative to the conf file. The v4l
//! inputs map to mplayer's `-tv driver=v4l2:device=DEV:input=N`: `cam` and `tv`
//! input 0, `composite` 1, `s-video` 2.
//!
//! # Interfaces
//! `colorA..D` (320x240) and `varcolorA..D` (W x H), BGR. Frames are decoded only
//! while the interface is used (a suspended file is paused; a device is closed),
//! the clock moves once per new frame. At the end of a file mplayer starts again
//! with `repeat_on`; with `repeat_off` the last frame stays, the interface is
//! marked stale ("end of the video") and the video plays again after the next
//! stop and run. A missing `mplayer` program is an error when the driver loads;
//! a file mplayer cannot play, an mplayer that dies or a device that goes away
//! marks the interface stale with mplayer's own message, and the driver retries
//! every 2 s while the interface is used.

use std::{path::Path, process::Command, sync::Arc};

use anyhow::Context as _;

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{self, Form, choice, int, word},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    media::{
        MediaError,
        child::{Child, FramePipe, Killer},
        is_url, require_program,
        stream::{Frames, Stream, StreamSpec},
        y4m::{self, Y4mHeader},
    },
    runtime::{Driver, Runtime},
};

/// Where the video comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Input {
    /// A file (resolved) or a URL.
    File(String),
    /// A V4L2 device and input number.
    V4l { device: String, input: u32 },
}

/// One `provides` line, parsed.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    pub interface: String,
    pub input: Input,
    pub width: u32,
    pub height: u32,
    pub repeat: bool,
    pub pace: bool,
}

fn file_or_url(conf: &ComponentConf, s: &str) -> String {
    if is_url(s) {
        s.to_string()
    } else {
        conf.resolve(s).display().to_string()
    }
}

/// `repeat_on|repeat_off`: start again at the end of the file, or stop there.
const REPEAT: settings::Arg = choice("repeat_on|repeat_off", &["repeat_on", "repeat_off"]);
/// `unpaced`: as fast as it decodes.
const UNPACED: settings::Arg = choice("unpaced", &["unpaced"]).optional();

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help mplayer`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and the video it shows",
            &[
                Form::new(
                    "v4l",
                    "320x240 from a V4L2 device's input",
                    &[
                        settings::COLOR,
                        choice("v4l", &["v4l"]),
                        word("DEV"),
                        choice("INPUT", &["cam", "tv", "composite", "s-video"]),
                    ],
                ),
                Form::new(
                    "color",
                    "a file or URL at 320x240",
                    &[settings::COLOR, word("FILE|URL"), REPEAT, UNPACED],
                ),
                Form::new(
                    "varcolor",
                    "a file or URL at W x H",
                    &[
                        settings::VARCOLOR,
                        word("FILE|URL"),
                        int("W", "px", 2, 8192),
                        int("H", "px", 2, 8192),
                        REPEAT,
                        UNPACED,
                    ],
                ),
            ],
        )
        .required(),
    }
}

#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "v4l")]
    V4l(String, serde::de::IgnoredAny, String, String),
    #[serde(rename = "color")]
    Color(String, String, String, Option<String>),
    #[serde(rename = "varcolor")]
    Varcolor(String, String, u32, u32, String, Option<String>),
}

/// Parses the driver's lines.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Vec<(Source, ConfLine)>> {
    let lines: Lines = conf.read()?;
    let mut out: Vec<(Source, ConfLine)> = Vec::new();
    for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
        let file =
            |interface: String, f: &str, (width, height), repeat: &str, unpaced: Option<String>| {
                Source {
                    interface,
                    input: Input::File(file_or_url(conf, f)),
                    width,
                    height,
                    repeat: repeat == "repeat_on",
                    pace: unpaced.is_none(),
                }
            };
        let src = match p {
            Provides::V4l(interface, _, device, input) => Source {
                interface,
                input: Input::V4l {
                    device,
                    input: match input.as_str() {
                        "composite" => 1,
                        "s-video" => 2,
                        _ => 0, // cam, tv
                    },
                },
                width: COLOR_WIDTH,
                height: COLOR_HEIGHT,
                repeat: false,
                pace: false,
            },
            Provides::Color(i, f, r, u) => file(i, &f, (COLOR_WIDTH, COLOR_HEIGHT), &r, u),
            Provides::Varcolor(i, f, w, h, r, u) => file(i, &f, (w, h), &r, u),
        };
        if out.iter().any(|(s, _)| s.interface == src.interface) {
            return Err(l
                .error(format!("`{}` is provided twice", src.interface))
                .into());
        }
        out.push((src, l.clone()));
    }
    Ok(out)
}

/// The mplayer command line for a source.
pub fn command(mplayer: &Path, src: &Source) -> Command {
    let mut cmd = Command::new(mplayer);
    cmd.args([
        "-quiet",
        "-noconsolecontrols",
        "-nolirc",
        "-nojoystick",
        "-nomouseinput",
        "-nosound",
        "-noaspect",
        "-benchmark",
        "-vo",
        "yuv4mpeg:file=/dev/fd/3",
        "-vf",
    ])
    .arg(format!("scale={}:{}", src.width, src.height));
    match &src.input {
        Input::File(f) => {
            cmd.arg("--").arg(f);
        }
        Input::V4l { device, input } => {
            cmd.arg("-tv")
                .arg(format!("driver=v4l2:device={device}:input={input}"))
                .arg("tv://");
        }
    }
    cmd
}

/// A YUV4MPEG2 stream from an mplayer child.
struct Y4m {
    child: Child,
    header: Option<Y4mHeader>,
    width: u32,
    height: u32,
    buf: Vec<u8>,
    label: String,
}

impl Y4m {
    fn said(&self) -> String {
        let s = self.child.said(|l| {
            !l.starts_with("BENCHMARK") && !l.starts_with("Exiting") && !l.starts_with("MPlayer")
        });
        let lines: Vec<&str> = s.split(" | ").collect();
        lines[lines.len().saturating_sub(4)..].join(" | ")
    }

    fn fail(&self, what: impl std::fmt::Display) -> MediaError {
        let said = self.said();
        MediaError::Child(if said.is_empty() {
            format!("{}: {what}", self.label)
        } else {
            format!("{}: {what}; mplayer said: {said}", self.label)
        })
    }
}

impl Y4m {
    /// Reads the stream header (size and rate) that mplayer writes first.
    fn start(&mut self) -> Result<(), MediaError> {
        let h = match y4m::read_header(self.child.frames()) {
            Ok(Some(h)) => h,
            Ok(None) => {
                // Let mplayer finish printing why before we quote it.
                std::thread::sleep(std::time::Duration::from_millis(100));
                return Err(self.fail("no frames (a file or device mplayer cannot play?)"));
            }
            Err(e) => return Err(self.fail(e)),
        };
        if h.width < self.width || h.height < self.height {
            return Err(self.fail(format!(
                "mplayer wrote {}x{} frames, expected {}x{}",
                h.width, h.height, self.width, self.height
            )));
        }
        self.header = Some(h);
        Ok(())
    }
}

impl Frames for Y4m {
    fn rate(&self) -> Option<f64> {
        self.header.and_then(|h| h.rate)
    }

    fn read(&mut self) -> Result<bool, MediaError> {
        let Some(h) = self.header else {
            return Err(self.fail("no stream header"));
        };
        y4m::read_frame(self.child.frames(), &h, &mut self.buf).map_err(|e| self.fail(e))
    }

    fn fill(&self, out: &mut Image) {
        let Some(h) = self.header else { return };
        out.width = self.width;
        out.height = self.height;
        out.data
            .resize(self.width as usize * self.height as usize * 3, 0);
        y4m::i420_to_bgr(
            &self.buf,
            h.width as usize,
            h.height as usize,
            self.width as usize,
            self.height as usize,
            &mut out.data,
        );
    }

    fn finish(self: Box<Self>) -> Result<(), MediaError> {
        let label = self.label.clone();
        self.child
            .finish()
            .map_err(|e| MediaError::Child(format!("{label}: {e}")))
    }
}

struct MPlayer {
    streams: Vec<Stream>,
}

impl Driver for MPlayer {
    fn terminate(&mut self) {
        for s in &mut self.streams {
            s.stop();
        }
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let sources = parse(conf)?;
    let mplayer = require_program("mplayer", "mplayer")
        .map_err(|e| anyhow::anyhow!("mplayer driver: {e}"))?;
    let mut streams = Vec::new();
    for (src, line) in sources {
        let (label, live) = match &src.input {
            Input::File(f) => {
                if !is_url(f) && !Path::new(f).exists() {
                    return Err(line.error(format!("{f}: no such video file")).into());
                }
                (format!("mplayer {f}"), is_url(f))
            }
            Input::V4l { device, .. } => (format!("mplayer {device}"), true),
        };
        let iface: Arc<Interface<Image>> = rt.interfaces.provide_value(
            &src.interface,
            &conf.name,
            Image::new(src.width, src.height),
        )?;
        let (s2, m2, l2) = (src.clone(), mplayer.clone(), label.clone());
        let open = move |killer: &Killer| -> Result<Box<dyn Frames>, MediaError> {
            let child = Child::spawn(command(&m2, &s2), FramePipe::Fd3, killer, "mplayer")?;
            let mut y = Y4m {
                child,
                header: None,
                width: s2.width,
                height: s2.height,
                buf: Vec::new(),
                label: l2.clone(),
            };
            y.start()?;
            Ok(Box::new(y))
        };
        let spec = StreamSpec {
            label,
            open: Box::new(open),
            pace: src.pace,
            repeat: src.repeat,
            pause: !live,
        };
        streams.push(Stream::start(spec, iface).context("cannot start an mplayer thread")?);
    }
    Ok(Box::new(MPlayer { streams }))
}

crate::register_driver!(
    Driver,
    "mplayer",
    "any video the mplayer program plays (files, URLs, V4L2) on colorA..D / varcolorA..D",
    create,
    lines = Lines
);
