//! opencv: images from a file, a capture device or a video file, with JDE 4.3's
//! `opencv` driver's conf lines (the name is 4.3's; no OpenCV is needed).
//!
//! - `image PATH`: a still image (PNM, PNG, JPEG, BMP), published when the
//!   interface is used and again when the file changes (see `imagefile`).
//! - `video DEV`: a V4L2 capture device (`/dev/video0`), captured by the `ffmpeg`
//!   program (`-f v4l2`).
//! - `videofile PATH`: any video FFmpeg decodes, by the `ffmpeg` program as a child
//!   process writing raw BGR frames (`-f rawvideo -pix_fmt bgr24`) to a pipe. We run
//!   the program rather than link libav* (the `ffmpeg-next` crate): linking needs
//!   bindgen, libclang and headers matching the system's FFmpeg exactly, adds
//!   minutes to every clean build and breaks on FFmpeg upgrades, and a decoder
//!   crash inside our process would take the robot's controller down with it; the
//!   program is one `apt-get install ffmpeg` away, a crash is a child's exit status
//!   (the interface goes stale with ffmpeg's own message), and it decodes 640x480
//!   far faster than a camera's rate (see `benches/media.rs`). The size and frame
//!   rate come from `ffprobe` when the driver loads.
//!
//! System packages: `ffmpeg` (for `video` and `videofile`; it also provides
//! `ffprobe`).
//!
//! # Conf
//! ```text
//! driver opencv
//! provides varcolorA videofile clip.mp4 640 480   # scaled to W x H
//! provides varcolorB videofile clip.mp4 autosize loop   # the file's own size; start again at the end
//! provides varcolorC videofile clip.mp4 640 480 unpaced # as fast as it decodes
//! provides colorA video /dev/video0               # 320x240 from a V4L2 device
//! provides varcolorD image casaleft.pnm 640 480   # a still image
//! end_driver
//! ```
//! `provides varcolorX image|video|videofile PATH [W H|autosize] [loop] [unpaced]`
//! (no size = autosize), `provides colorX image|video|videofile PATH [loop]
//! [unpaced]` (320x240). Relative paths are relative to the conf file.
//!
//! # Interfaces
//! `colorA..D` (320x240) and `varcolorA..D` (any size), BGR. A video file plays
//! at its own frame rate (`unpaced`: as fast as it decodes), only while the
//! interface is used (a suspended file is paused where it was; a device is
//! closed); the clock moves once per new frame. At the end of a file it starts
//! again with `loop`, else the interface is marked stale ("end of the video") and
//! plays again after the next stop and run. A device that disappears, or an
//! ffmpeg that dies, marks the interface stale with the reason, and the driver
//! retries every 2 s while the interface is used.

use std::{
    io::Read,
    path::{Path, PathBuf},
    process::Command,
    sync::Arc,
    time::{Duration, Instant},
};

use anyhow::Context as _;

use crate::{
    conf::{
        ComponentConf, ConfLine,
        settings::{self, Form, choice, flags, pixels, word},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    media::{
        MediaError,
        child::{Child, FramePipe, Killer},
        require_program,
        still::MAX_PIXELS,
        stills::{Fit, StillSpec, Stills, load_fitted},
        stream::{Frames, Stream, StreamSpec},
    },
    runtime::{Driver, Runtime},
};

/// The sources a `provides` line names.
const SOURCES: settings::Arg = choice("image|video|videofile", &["image", "video", "videofile"]);

/// What a `provides` line reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Input {
    Image,
    Video,
    VideoFile,
}

/// One `provides` line, parsed.
#[derive(Clone, Debug, PartialEq)]
pub struct Source {
    pub interface: String,
    pub kind: Input,
    pub path: PathBuf,
    /// W x H, or None for autosize.
    pub size: Option<(u32, u32)>,
    pub repeat: bool,
    pub pace: bool,
}

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help opencv`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and its source: a still image, a V4L2 device or a video file",
            &[
                Form::new(
                    "color",
                    "320x240 from PATH; `loop`: start a file again at its end; `unpaced`: as fast as it decodes",
                    &[
                        settings::COLOR,
                        SOURCES,
                        word("PATH"),
                        flags("OPTIONS", &["loop", "unpaced"]),
                    ],
                ),
                Form::new(
                    "sized",
                    "PATH scaled to W x H",
                    &[
                        settings::VARCOLOR,
                        SOURCES,
                        word("PATH"),
                        pixels("W", 16384),
                        pixels("H", 16384),
                        flags("OPTIONS", &["loop", "unpaced"]),
                    ],
                ),
                Form::new(
                    "autosize",
                    "PATH at its own size (`autosize`, or no size)",
                    &[
                        settings::VARCOLOR,
                        SOURCES,
                        word("PATH"),
                        choice("autosize", &["autosize"]).optional(),
                        flags("OPTIONS", &["loop", "unpaced"]),
                    ],
                ),
            ],
        )
        .required(),
    }
}

#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "color")]
    Color(String, Input, String, Vec<String>),
    #[serde(rename = "sized")]
    Sized(String, Input, String, u32, u32, Vec<String>),
    #[serde(rename = "autosize")]
    Autosize(String, Input, String, serde::de::IgnoredAny, Vec<String>),
}

/// Parses the driver's lines.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Vec<(Source, ConfLine)>> {
    let lines: Lines = conf.read()?;
    let mut out: Vec<(Source, ConfLine)> = Vec::new();
    for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
        let (iface, kind, path, size, options) = match p {
            Provides::Color(i, k, p, o) => (i, k, p, Some((COLOR_WIDTH, COLOR_HEIGHT)), o),
            Provides::Sized(i, k, p, w, h, o) => {
                if w as u64 * h as u64 > MAX_PIXELS {
                    return Err(l
                        .error(format!(
                            "`provides {i}`: {w}x{h} is too large (at most {MAX_PIXELS} pixels)"
                        ))
                        .into());
                }
                (i, k, p, Some((w, h)), o)
            }
            Provides::Autosize(i, k, p, _, o) => (i, k, p, None, o),
        };
        if out.iter().any(|(s, _)| s.interface == iface) {
            return Err(l.error(format!("`{iface}` is provided twice")).into());
        }
        let path = if kind == Input::Video && path.starts_with("/dev/") {
            PathBuf::from(&path)
        } else {
            conf.resolve(&path)
        };
        out.push((
            Source {
                interface: iface,
                kind,
                path,
                size,
                repeat: options.iter().any(|o| o == "loop"),
                pace: !options.iter().any(|o| o == "unpaced"),
            },
            l.clone(),
        ));
    }
    Ok(out)
}

/// What `ffprobe` says about a video: size and frame rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probe {
    pub width: u32,
    pub height: u32,
    pub rate: Option<f64>,
}

fn parse_rate(s: &str) -> Option<f64> {
    let (n, d) = s.split_once('/').unwrap_or((s, "1"));
    let (n, d) = (n.trim().parse::<f64>().ok()?, d.trim().parse::<f64>().ok()?);
    (n > 0.0 && d > 0.0)
        .then(|| n / d)
        .filter(|r| r.is_finite() && *r < 10_000.0)
}

/// Runs `ffprobe` on a file (or a V4L2 device) for its first video stream's size
/// and rate; gives up after 15 s.
pub fn probe(path: &Path, device: bool) -> Result<Probe, MediaError> {
    let ffprobe = require_program("ffprobe", "ffmpeg")?;
    let mut cmd = Command::new(ffprobe);
    cmd.args(["-v", "error"]);
    if device {
        cmd.args(["-f", "v4l2"]);
    }
    cmd.args([
        "-select_streams",
        "v:0",
        "-show_entries",
        "stream=width,height,avg_frame_rate,r_frame_rate",
        "-of",
        "default=nw=1",
    ])
    .arg(path);
    cmd.stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let mut child = cmd
        .spawn()
        .map_err(|e| MediaError::Child(format!("cannot start ffprobe: {e}")))?;
    let mut out = child.stdout.take();
    let mut err = child.stderr.take();
    let reader = std::thread::spawn(move || {
        let (mut o, mut e) = (String::new(), String::new());
        if let Some(out) = out.as_mut() {
            let _ = out.take(64 * 1024).read_to_string(&mut o);
        }
        if let Some(err) = err.as_mut() {
            let _ = err.take(64 * 1024).read_to_string(&mut e);
        }
        (o, e)
    });
    let t0 = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => break Some(s),
            Ok(None) if t0.elapsed() > Duration::from_secs(15) => {
                let _ = child.kill();
                let _ = child.wait();
                break None;
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(10)),
            Err(_) => break None,
        }
    };
    let (text, said) = reader.join().unwrap_or_default();
    let said: String = said
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .chars()
        .take(400)
        .collect();
    let (mut w, mut h, mut avg, mut r) = (0, 0, None, None);
    for line in text.lines() {
        match line.split_once('=') {
            Some(("width", v)) => w = v.trim().parse().unwrap_or(0),
            Some(("height", v)) => h = v.trim().parse().unwrap_or(0),
            Some(("avg_frame_rate", v)) => avg = parse_rate(v),
            Some(("r_frame_rate", v)) => r = parse_rate(v),
            _ => {}
        }
    }
    if w == 0 || h == 0 {
        let why = match status {
            None => "ffprobe did not answer in 15 s".to_string(),
            Some(_) if said.is_empty() => "ffprobe found no video stream in it".to_string(),
            Some(_) => format!("ffprobe: {said}"),
        };
        return Err(MediaError::format(
            path,
            format!("not a video FFmpeg can read: {why}"),
        ));
    }
    if w as u64 * h as u64 > MAX_PIXELS {
        return Err(MediaError::format(
            path,
            format!("{w}x{h} video is too large (at most {MAX_PIXELS} pixels); give a size W H"),
        ));
    }
    Ok(Probe {
        width: w,
        height: h,
        rate: avg.or(r),
    })
}

/// Raw BGR frames from an ffmpeg child.
struct RawBgr {
    child: Child,
    width: u32,
    height: u32,
    rate: Option<f64>,
    buf: Vec<u8>,
    label: String,
}

impl RawBgr {
    fn spawn(
        src: &Source,
        w: u32,
        h: u32,
        rate: Option<f64>,
        killer: &Killer,
    ) -> Result<RawBgr, MediaError> {
        let ffmpeg = require_program("ffmpeg", "ffmpeg")?;
        let mut cmd = Command::new(ffmpeg);
        cmd.args(["-nostdin", "-hide_banner", "-loglevel", "error"]);
        if src.kind == Input::Video {
            cmd.args(["-f", "v4l2"]);
        }
        cmd.arg("-i").arg(&src.path);
        cmd.args(["-map", "0:v:0", "-an", "-sn", "-dn", "-vf"])
            .arg(format!("scale={w}:{h}"))
            .args(["-pix_fmt", "bgr24", "-f", "rawvideo", "pipe:1"]);
        let child = Child::spawn(cmd, FramePipe::Stdout, killer, "ffmpeg")?;
        Ok(RawBgr {
            child,
            width: w,
            height: h,
            rate,
            buf: vec![0; w as usize * h as usize * 3],
            label: format!("ffmpeg {}", src.path.display()),
        })
    }
}

impl Frames for RawBgr {
    fn rate(&self) -> Option<f64> {
        self.rate
    }

    fn read(&mut self) -> Result<bool, MediaError> {
        let mut filled = 0;
        let pipe = self.child.frames();
        while filled < self.buf.len() {
            match pipe.read(&mut self.buf[filled..]) {
                Ok(0) if filled == 0 => return Ok(false),
                Ok(0) => {
                    return Err(MediaError::Child(format!(
                        "{}: the stream ended in the middle of a frame ({}: {})",
                        self.label,
                        filled,
                        self.child.said(|_| true)
                    )));
                }
                Ok(n) => filled += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(MediaError::Child(format!("{}: {e}", self.label))),
            }
        }
        Ok(true)
    }

    fn fill(&self, out: &mut Image) {
        out.width = self.width;
        out.height = self.height;
        out.data.clear();
        out.data.extend_from_slice(&self.buf);
    }

    fn finish(self: Box<Self>) -> Result<(), MediaError> {
        let label = self.label.clone();
        self.child
            .finish()
            .map_err(|e| MediaError::Child(format!("{label}: {e}")))
    }
}

enum Worker {
    Stills(Stills),
    Stream(Stream),
}

struct OpenCv {
    workers: Vec<Worker>,
}

impl Driver for OpenCv {
    fn terminate(&mut self) {
        for w in &mut self.workers {
            match w {
                Worker::Stills(s) => s.stop(),
                Worker::Stream(s) => s.stop(),
            }
        }
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let sources = parse(conf)?;
    let mut stills = Vec::new();
    let mut workers = Vec::new();
    for (src, line) in sources {
        let at = |e: MediaError| line.error(e.to_string());
        match src.kind {
            Input::Image => {
                let fit = match src.size {
                    Some((w, h)) => Fit::Scale(w, h),
                    None => Fit::Auto,
                };
                let img = load_fitted(&src.path, fit, &src.interface).map_err(at)?;
                let iface: Arc<Interface<Image>> = rt.interfaces.provide_value(
                    &src.interface,
                    &conf.name,
                    Image::new(img.width, img.height),
                )?;
                stills.push(StillSpec {
                    path: src.path.clone(),
                    fit,
                    iface,
                    first: Some(img),
                });
            }
            Input::Video | Input::VideoFile => {
                require_program("ffmpeg", "ffmpeg").map_err(at)?;
                let device = src.kind == Input::Video;
                if !src.path.exists() {
                    return Err(line
                        .error(format!(
                            "{}: no such {}",
                            src.path.display(),
                            if device {
                                "capture device"
                            } else {
                                "video file"
                            }
                        ))
                        .into());
                }
                let probed = if device && src.size.is_some() {
                    None
                } else {
                    Some(probe(&src.path, device).map_err(at)?)
                };
                let (w, h) = src
                    .size
                    .or(probed.map(|p| (p.width, p.height)))
                    .unwrap_or((COLOR_WIDTH, COLOR_HEIGHT));
                let rate = if device {
                    None
                } else {
                    probed.and_then(|p| p.rate)
                };
                let iface: Arc<Interface<Image>> =
                    rt.interfaces
                        .provide_value(&src.interface, &conf.name, Image::new(w, h))?;
                let s2 = src.clone();
                let spec = StreamSpec {
                    label: format!("ffmpeg {}", src.path.display()),
                    open: Box::new(move |killer: &Killer| {
                        RawBgr::spawn(&s2, w, h, rate, killer)
                            .map(|f| Box::new(f) as Box<dyn Frames>)
                    }),
                    pace: src.pace && !device,
                    repeat: src.repeat,
                    pause: !device,
                };
                workers.push(Worker::Stream(
                    Stream::start(spec, iface).context("cannot start an opencv stream thread")?,
                ));
            }
        }
    }
    if !stills.is_empty() {
        workers.push(Worker::Stills(
            Stills::start("opencv images", stills)
                .context("cannot start the opencv image thread")?,
        ));
    }
    Ok(Box::new(OpenCv { workers }))
}

crate::register_driver!(
    Driver,
    "opencv",
    "images, V4L2 capture devices and video files (through FFmpeg) on colorA..D / varcolorA..D",
    create,
    lines = Lines
);
