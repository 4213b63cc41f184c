//! video4linux2 (and `video4linux`, 4.3's V4L1 driver name: V4L1 is gone from
//! Linux, so its lines run on this same code with a notice): webcams, USB and PCI
//! capture cards and anything else with a V4L2 capture node (`/dev/videoN`),
//! through the `v4l` crate (its bindings are generated with bindgen at build time:
//! Debian `clang` / `libclang-dev`; no library needed at run time).
//!
//! # Conf (the seed's lines)
//! ```text
//! driver video4linux2
//! provides colorA /dev/video1 0            # colorX DEV INPUT: 320x240
//! provides varcolorA /dev/video0 0 176 144 # varcolorX DEV INPUT W H
//! end_driver
//!
//! driver video4linux                       # 4.3's V4L1 lines, input 0
//! provides varcolorA /dev/video0 640 480   # varcolorX DEV W H
//! provides colorB /dev/video1              # colorX DEV
//! end_driver
//! ```
//!
//! # Interfaces
//! `colorA..D` (320x240 BGR) and `varcolorA..D` (W x H BGR); the clock moves once
//! per captured frame. The driver selects input `INPUT` (`VIDIOC_S_INPUT`) and
//! negotiates the first pixel format the device offers at exactly W x H, in this
//! order: BGR24, RGB24, YUYV, UYVY, YUV420 (I420, YV12), MJPEG, GREY, 8-bit Bayer
//! (BA81, GBRG, GRBG, RGGB). Frames are converted to BGR by
//! [`crate::vision::pixfmt`] (YUV with BT.601 video range, as V4L2 defines it and
//! OpenCV computes it) and MJPEG is decoded with `zune-jpeg`.
//!
//! # Behaviour
//! - At start: a node that is not a V4L2 capture device, an input it does not
//!   have, or a size it cannot deliver is an error naming the conf line and, for
//!   sizes, listing what the device offers per format. A device that is not there
//!   (yet) is a printed message and a stale interface with the reason; the driver
//!   tries again every 2 s while the interface is used.
//! - The device streams only while someone uses the interface (resume/suspend).
//! - Unplugged while running (the read fails, or no frame for 5 s) → the interface
//!   is marked stale with the reason; the driver reopens the device every 2 s and
//!   goes on when it is back. Each device has its own thread; reads wait at most
//!   200 ms, so nothing else waits on a camera.

use std::{
    path::PathBuf,
    sync::Arc,
    time::{Duration, Instant},
};

use v4l::{
    Device, FourCC, buffer::Type, capability::Flags, framesize::FrameSizeEnum,
    io::traits::CaptureStream, prelude::MmapStream, video::Capture,
};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, Form, int, path, pixels},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    runtime::{self, Driver, Runtime, Supervision, Supervisor},
    supervisor::{Absent, CAMERA_NO_FRAME},
    vision::pixfmt::{self, Bayer, Yuv422Order, YuvMatrix},
};

/// One device to capture from, parsed from a `provides` line.
#[derive(Clone, Debug, PartialEq)]
pub struct DevConf {
    pub iface: String,
    pub device: PathBuf,
    pub input: u32,
    pub width: u32,
    pub height: u32,
    /// `file:line` of the provides line.
    pub at: String,
}

const INPUT: settings::Arg = int("INPUT", "", 0, 255);
const W: settings::Arg = pixels("W", 8192);
const H: settings::Arg = pixels("H", 8192);
const COLOR_FORM: Form = Form::new(
    "color",
    "320x240 from input INPUT (0 for most cameras) of device DEV",
    &[settings::COLOR, path("DEV"), INPUT],
);
const VARCOLOR_INPUT: Form = Form::new(
    "varcolor_input",
    "W x H from input INPUT of device DEV",
    &[settings::VARCOLOR, path("DEV"), INPUT, W, H],
);

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help video4linux2`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and the V4L2 device it comes from",
            &[COLOR_FORM, VARCOLOR_INPUT],
        )
        .required(),
    }
}

crate::declare_lines! {
    /// 4.3's video4linux lines (INPUT may be left out: input 0).
    struct LinesV4l1 {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and the V4L2 device it comes from",
            &[
                Form::new(
                    "color",
                    "320x240 from device DEV (input INPUT, default 0)",
                    &[settings::COLOR, path("DEV"), INPUT.optional()],
                ),
                Form::new(
                    "varcolor",
                    "W x H from input 0 of device DEV",
                    &[settings::VARCOLOR, path("DEV"), W, H],
                ),
                VARCOLOR_INPUT,
            ],
        )
        .required(),
    }
}

#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "color")]
    Color(String, PathBuf, Option<u32>),
    #[serde(rename = "varcolor")]
    Varcolor(String, PathBuf, u32, u32),
    #[serde(rename = "varcolor_input")]
    VarcolorInput(String, PathBuf, u32, u32, u32),
}

/// Parses the driver's lines; `v4l1` accepts 4.3's video4linux lines (no INPUT).
pub fn parse(conf: &ComponentConf, v4l1: bool) -> anyhow::Result<Vec<DevConf>> {
    let provides = if v4l1 {
        conf.read::<LinesV4l1>()?.provides
    } else {
        conf.read::<Lines>()?.provides
    };
    let mut out = Vec::new();
    for (p, l) in provides.into_iter().zip(conf.provides()) {
        let (iface, device, input, (width, height)) = match p {
            Provides::Color(i, d, input) => (i, d, input.unwrap_or(0), (COLOR_WIDTH, COLOR_HEIGHT)),
            Provides::Varcolor(i, d, w, h) => (i, d, 0, (w, h)),
            Provides::VarcolorInput(i, d, input, w, h) => (i, d, input, (w, h)),
        };
        out.push(DevConf {
            iface,
            device,
            input,
            width,
            height,
            at: l.at.to_string(),
        });
    }
    Ok(out)
}

/// The formats the driver can convert, in order of preference.
pub const FORMATS: &[&[u8; 4]] = &[
    b"BGR3", b"RGB3", b"YUYV", b"UYVY", b"YU12", b"YV12", b"MJPG", b"JPEG", b"GREY", b"BA81",
    b"GBRG", b"GRBG", b"RGGB",
];

/// Converts one frame of `fourcc` (`stride` bytes per row for packed formats; 0 =
/// no padding) into BGR.
pub fn convert(
    fourcc: &[u8; 4],
    data: &[u8],
    w: u32,
    h: u32,
    stride: u32,
    out: &mut Vec<u8>,
    scratch: &mut Vec<u8>,
) -> Result<(), String> {
    let bpp = match fourcc {
        b"BGR3" | b"RGB3" => 3,
        b"YUYV" | b"UYVY" => 2,
        b"GREY" | b"BA81" | b"GBRG" | b"GRBG" | b"RGGB" => 1,
        _ => 0,
    };
    // Packed formats with row padding: compact the rows first.
    let data = if bpp > 0 && stride as usize > w as usize * bpp {
        let (row, s) = (w as usize * bpp, stride as usize);
        let need = s * (h as usize - 1) + row;
        if data.len() < need {
            return Err(format!(
                "frame of {}x{h} with stride {s} needs {need} bytes, got {} (truncated frame?)",
                w,
                data.len()
            ));
        }
        scratch.clear();
        for y in 0..h as usize {
            scratch.extend_from_slice(&data[y * s..y * s + row]);
        }
        &scratch[..]
    } else {
        data
    };
    let r = match fourcc {
        b"BGR3" => pixfmt::bgr_to_bgr(data, w, h, out),
        b"RGB3" => pixfmt::rgb_to_bgr(data, w, h, out),
        b"YUYV" => pixfmt::yuv422_to_bgr(data, w, h, Yuv422Order::Yuyv, YuvMatrix::Bt601, out),
        b"UYVY" => pixfmt::yuv422_to_bgr(data, w, h, Yuv422Order::Uyvy, YuvMatrix::Bt601, out),
        b"YU12" => pixfmt::yuv420_to_bgr(data, w, h, false, out),
        b"YV12" => pixfmt::yuv420_to_bgr(data, w, h, true, out),
        b"GREY" => pixfmt::grey_to_bgr(data, w, h, out),
        b"BA81" => pixfmt::bayer_to_bgr(data, w, h, Bayer::Bggr, out),
        b"GBRG" => pixfmt::bayer_to_bgr(data, w, h, Bayer::Gbrg, out),
        b"GRBG" => pixfmt::bayer_to_bgr(data, w, h, Bayer::Grbg, out),
        b"RGGB" => pixfmt::bayer_to_bgr(data, w, h, Bayer::Rggb, out),
        b"MJPG" | b"JPEG" => {
            // A decoder bug on a corrupt frame must not take the capture thread down.
            return std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                decode_jpeg(data, w, h, out)
            }))
            .unwrap_or_else(|_| Err("MJPEG frame: the decoder failed (corrupt frame)".into()));
        }
        other => {
            return Err(format!(
                "pixel format {} is not supported",
                String::from_utf8_lossy(other)
            ));
        }
    };
    r.map_err(|e| e.to_string())
}

/// Decodes one MJPEG frame (a JPEG image) to BGR; it must be `w` x `h`.
pub fn decode_jpeg(data: &[u8], w: u32, h: u32, out: &mut Vec<u8>) -> Result<(), String> {
    use zune_jpeg::{
        JpegDecoder,
        zune_core::{colorspace::ColorSpace, options::DecoderOptions},
    };
    let opts = DecoderOptions::default().jpeg_set_out_colorspace(ColorSpace::BGR);
    let mut d = JpegDecoder::new_with_options(std::io::Cursor::new(data), opts);
    d.decode_headers()
        .map_err(|e| format!("MJPEG frame: {e:?}"))?;
    let (dw, dh) = d.dimensions().unwrap_or((0, 0));
    if (dw as u32, dh as u32) != (w, h) {
        return Err(format!(
            "MJPEG frame is {dw}x{dh}, the stream was set to {w}x{h}"
        ));
    }
    out.resize(w as usize * h as usize * 3, 0);
    d.decode_into(out)
        .map_err(|e| format!("MJPEG frame: {e:?}"))
}

fn fourcc_name(f: &FourCC) -> String {
    String::from_utf8_lossy(&f.repr).into_owned()
}

/// Opens `path` as a V4L2 capture device (clear errors for a missing node or one
/// that is not a capture device).
fn open_device(c: &DevConf) -> Result<Device, String> {
    let p = &c.device;
    if !p.exists() {
        return Err(format!(
            "{}: no such device (is the camera plugged in? `v4l2-ctl --list-devices` lists them)",
            p.display()
        ));
    }
    let dev = Device::with_path(p).map_err(|e| format!("{}: cannot open: {e}", p.display()))?;
    let caps = dev.query_caps().map_err(|e| {
        format!(
            "{}: not a video4linux2 device (VIDIOC_QUERYCAP: {e})",
            p.display()
        )
    })?;
    if !caps.capabilities.contains(Flags::VIDEO_CAPTURE)
        || !caps.capabilities.contains(Flags::STREAMING)
    {
        return Err(format!(
            "{}: `{}` ({}) is not a streaming video capture device (capabilities: {})",
            p.display(),
            caps.card,
            caps.driver,
            caps.capabilities
        ));
    }
    let mut input = c.input as std::os::raw::c_int;
    // SAFETY: VIDIOC_S_INPUT takes a pointer to an int on a valid fd.
    let r = unsafe {
        v4l::v4l2::ioctl(
            dev.handle().fd(),
            v4l::v4l2::vidioc::VIDIOC_S_INPUT,
            &mut input as *mut _ as *mut std::os::raw::c_void,
        )
    };
    if let Err(e) = r {
        return Err(format!(
            "{}: cannot select input {} ({e}); `v4l2-ctl -d {} --list-inputs` lists the inputs",
            p.display(),
            c.input,
            p.display()
        ));
    }
    Ok(dev)
}

/// Whether a frame size entry allows `w` x `h`.
fn size_fits(s: &FrameSizeEnum, w: u32, h: u32) -> bool {
    match s {
        FrameSizeEnum::Discrete(d) => d.width == w && d.height == h,
        FrameSizeEnum::Stepwise(s) => {
            (s.min_width..=s.max_width).contains(&w)
                && (s.min_height..=s.max_height).contains(&h)
                && (w - s.min_width).is_multiple_of(s.step_width.max(1))
                && (h - s.min_height).is_multiple_of(s.step_height.max(1))
        }
    }
}

fn size_text(s: &FrameSizeEnum) -> String {
    match s {
        FrameSizeEnum::Discrete(d) => format!("{}x{}", d.width, d.height),
        FrameSizeEnum::Stepwise(s) => format!(
            "{}x{}..{}x{} (step {}x{})",
            s.min_width, s.min_height, s.max_width, s.max_height, s.step_width, s.step_height
        ),
    }
}

/// Picks and sets a format of exactly the wanted size; returns (fourcc, stride).
fn negotiate(dev: &Device, c: &DevConf) -> Result<([u8; 4], u32), String> {
    let p = c.device.display();
    let formats = dev
        .enum_formats()
        .map_err(|e| format!("{p}: cannot list its formats ({e})"))?;
    let mut offered = Vec::new();
    let mut candidates = Vec::new();
    for f in &formats {
        let sizes = dev.enum_framesizes(f.fourcc).unwrap_or_default();
        offered.push(format!(
            "{} [{}]",
            fourcc_name(&f.fourcc),
            if sizes.is_empty() {
                "sizes not listed".to_string()
            } else {
                sizes
                    .iter()
                    .map(|s| size_text(&s.size))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        ));
        let Some(rank) = FORMATS.iter().position(|x| **x == f.fourcc.repr) else {
            continue;
        };
        if sizes.is_empty() || sizes.iter().any(|s| size_fits(&s.size, c.width, c.height)) {
            candidates.push((rank, f.fourcc));
        }
    }
    candidates.sort_by_key(|c| c.0);
    for (_, fourcc) in candidates {
        let want = v4l::Format::new(c.width, c.height, fourcc);
        if let Ok(got) = dev.set_format(&want)
            && got.width == c.width
            && got.height == c.height
            && got.fourcc == fourcc
        {
            return Ok((fourcc.repr, got.stride));
        }
    }
    Err(format!(
        "{p}: cannot deliver {}x{} in a format this driver converts ({}); the device offers: {}",
        c.width,
        c.height,
        FORMATS
            .iter()
            .map(|f| String::from_utf8_lossy(*f).into_owned())
            .collect::<Vec<_>>()
            .join(" "),
        if offered.is_empty() {
            "no formats".to_string()
        } else {
            offered.join("; ")
        }
    ))
}

/// What `check` found wrong.
#[derive(Debug, PartialEq)]
pub enum CheckError {
    /// The node does not exist (yet): the driver waits for it.
    Absent(String),
    /// The device is there but cannot do what the conf asks.
    Unusable(String),
}

/// Opens, selects the input and negotiates: everything `create` checks.
pub fn check(c: &DevConf) -> Result<(), CheckError> {
    if !c.device.exists() {
        return open_device(c).map(|_| ()).map_err(CheckError::Absent);
    }
    let dev = open_device(c).map_err(CheckError::Unusable)?;
    negotiate(&dev, c).map(|_| ()).map_err(CheckError::Unusable)
}

/// Stops a stream; the `v4l` crate panics in `Drop` on some errors (other than
/// ENODEV), which must not take the capture thread down.
fn drop_stream(s: MmapStream<'_>) {
    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || drop(s)));
}

/// An open device, streaming.
struct Stream {
    /// Taken at drop, before the device closes.
    stream: Option<MmapStream<'static>>,
    _dev: Device,
    fourcc: [u8; 4],
    stride: u32,
}

/// One device under the runtime's [`Supervisor`]: opened while its interface is
/// used (and closed when nobody does), a frame at a time.
struct Grabber {
    c: DevConf,
    iface: Arc<Interface<Image>>,
    out: Vec<u8>,
    scratch: Vec<u8>,
    last: Instant,
}

impl runtime::Device for Grabber {
    type Session = Stream;
    fn open(&mut self) -> Result<Stream, String> {
        let c = &self.c;
        let dev = open_device(c)?;
        let (fourcc, stride) = negotiate(&dev, c)?;
        let mut stream = MmapStream::with_buffers(&dev, Type::VideoCapture, 4)
            .map_err(|e| format!("{}: cannot map capture buffers ({e})", c.device.display()))?;
        stream.set_timeout(Duration::from_millis(200));
        self.last = Instant::now();
        Ok(Stream {
            stream: Some(stream),
            _dev: dev,
            fourcc,
            stride,
        })
    }
    fn step(&mut self, s: &mut Stream) -> Result<(), String> {
        let c = &self.c;
        let Some(stream) = s.stream.as_mut() else {
            return Err(format!("{}: the stream is closed", c.device.display()));
        };
        match stream.next() {
            Ok((buf, meta)) => {
                let used = (meta.bytesused as usize).min(buf.len());
                let data = if used > 0 { &buf[..used] } else { buf };
                let out = &mut self.out;
                match convert(
                    &s.fourcc,
                    data,
                    c.width,
                    c.height,
                    s.stride,
                    out,
                    &mut self.scratch,
                ) {
                    Ok(()) => {
                        self.last = Instant::now();
                        self.iface.publish_frame(c.width, c.height, out);
                    }
                    // A corrupt frame (MJPEG glitch): skip it.
                    Err(e) => tracing::debug!("{}: {e}", c.device.display()),
                }
                Ok(())
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                if self.last.elapsed() > CAMERA_NO_FRAME {
                    self.iface.set_stale(format!(
                        "{}: no frame for {} s",
                        c.device.display(),
                        self.last.elapsed().as_secs()
                    ));
                }
                Ok(())
            }
            Err(e) => Err(format!(
                "{}: capture failed ({e}; unplugged?)",
                c.device.display()
            )),
        }
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        if let Some(s) = self.stream.take() {
            drop_stream(s);
        }
    }
}

fn start(conf: &ComponentConf, rt: &Runtime, v4l1: bool) -> anyhow::Result<Box<dyn Driver>> {
    let devs = parse(conf, v4l1)?;
    let mut absent = Vec::new();
    for d in &devs {
        match check(d) {
            Ok(()) => absent.push(None),
            Err(CheckError::Absent(e)) => absent.push(Some(e)),
            Err(CheckError::Unusable(e)) => {
                anyhow::bail!("{}: driver {}: {e}", d.at, conf.name)
            }
        }
    }
    let mut devices = Vec::new();
    for (d, absent) in devs.into_iter().zip(absent) {
        let iface =
            rt.interfaces
                .provide_value(&d.iface, &conf.name, Image::new(d.width, d.height))?;
        let how = Supervision::camera(
            format!("video4linux2 {}", d.device.display()),
            iface.clone(),
            absent.map(|why| Absent::new(&d.at, &conf.name, why, "the device appears")),
        );
        devices.push(Supervisor::start(
            how,
            Grabber {
                c: d,
                iface,
                out: Vec::new(),
                scratch: Vec::new(),
                last: Instant::now(),
            },
        )?);
    }
    Ok(Box::new(devices))
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    start(conf, rt, false)
}

fn create_v4l1(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    crate::output::println(format!(
        "{}: V4L1 no longer exists in Linux; running the video4linux2 driver on these lines (input 0 unless given)",
        conf.name
    ));
    start(conf, rt, true)
}

crate::register_driver!(
    Driver,
    "video4linux2",
    "V4L2 capture devices (webcams, capture cards): colorA..D, varcolorA..D",
    create,
    lines = Lines
);

crate::register_driver!(
    Driver,
    "video4linux",
    "4.3's V4L1 lines, run by the video4linux2 driver: colorA..D, varcolorA..D",
    create_v4l1,
    "video4linux",
    lines = LinesV4l1
);
