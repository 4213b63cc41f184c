//! gige (beyond 4.3): GigE Vision and USB3 Vision industrial cameras through
//! Aravis 0.8 (Debian `libaravis-dev` to build, which needs `libusb-1.0-0-dev`
//! for its pkg-config file; `libaravis-0.8-0` to run) and the `aravis` crate.
//!
//! # Conf
//! ```text
//! driver gige
//! provides varcolorA Fake_1 640 480 Mono8  # varcolorX CAMERA_ID [W H] [PIXEL_FORMAT]
//! provides colorB 192.168.1.20             # colorX CAMERA_ID [PIXEL_FORMAT]: 320x240
//! exposure Fake_1 10000                    # exposure CAMERA_ID MICROSECONDS|auto
//! gain Fake_1 2.5                          # gain CAMERA_ID DB|auto
//! framerate Fake_1 30                      # framerate CAMERA_ID FPS
//! end_driver
//! ```
//! `CAMERA_ID` is what Aravis calls the camera (`arv-tool-0.8` lists them:
//! `Vendor-Model-Serial`), its IP address, or `Fake_1`, Aravis's built-in fake
//! camera (the driver then enables Aravis's `Fake` interface). Without W H the
//! camera keeps its current region (varcolorX) or is set to 320x240 (colorX);
//! `PIXEL_FORMAT` is a GenICam name (`Mono8`, `RGB8`/`RGB8Packed`, `BGR8`/
//! `BGR8Packed`, `YUV422_8`, `YUV422Packed`, `BayerRG8`, `BayerGB8`, `BayerGR8`,
//! `BayerBG8`); without it the first of these the camera offers is used.
//!
//! # Interfaces
//! `colorA..D` (320x240 BGR), `varcolorA..D` (W x H BGR); the clock moves once per
//! complete frame (incomplete buffers are counted and dropped). Conversions are
//! [`crate::vision::pixfmt`]'s (YUV: BT.601 video range; Bayer: bilinear).
//!
//! # Behaviour
//! - At start: a camera that does not answer (unknown id, unplugged, unreachable)
//!   is a printed message naming the conf line and the cameras Aravis can see, and
//!   a stale interface with that reason; the driver tries again every 2 s while
//!   the interface is used. A size or pixel format the camera refuses is an error
//!   with the camera's bounds / formats.
//! - Acquisition runs only while someone uses the interface (resume/suspend).
//! - A camera that stops answering (no frame for 5 s, or the stream fails) marks
//!   the interface stale; the driver reopens it every 2 s. Each camera has its
//!   own thread, which waits for buffers at most 200 ms at a time.

use aravis::{Buffer, BufferStatus, Camera, CameraExt, CameraExtManual, PixelFormat, StreamExt};
use std::{
    collections::HashMap,
    ffi::{CString, c_char},
    sync::{
        Arc,
        atomic::{AtomicU64, Ordering},
    },
    time::Instant,
};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, Form, NumberOr, Setting as Line},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    runtime::{Device, Driver, Runtime, Supervision, Supervisor},
    supervisor::{Absent, CAMERA_NO_FRAME},
    vision::pixfmt::{self, Bayer, Yuv422Order, YuvMatrix},
};

unsafe extern "C" {
    // libaravis-0.8 (linked by aravis-sys).
    fn arv_enable_interface(interface_id: *const c_char);
    fn arv_update_device_list();
    fn arv_get_n_devices() -> u32;
    fn arv_get_device_id(index: u32) -> *const c_char;
}

/// Exposure or gain: a value or the camera's automatic mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Setting {
    Value(f64),
    Auto,
}

/// One camera to capture from.
#[derive(Clone, Debug, PartialEq)]
pub struct GigeConf {
    pub iface: String,
    pub camera: String,
    /// None = keep the camera's region (varcolorX without W H).
    pub size: Option<(u32, u32)>,
    pub pixel_format: Option<String>,
    /// Microseconds.
    pub exposure: Option<Setting>,
    /// dB.
    pub gain: Option<Setting>,
    pub framerate: Option<f64>,
    pub at: String,
}

/// `PIXEL_FORMAT`: a GenICam name the driver converts.
const PIXEL_FORMAT: settings::Arg = settings::choice("PIXEL_FORMAT", FORMAT_NAMES).optional();

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help gige`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and its camera (an Aravis id, an IP address, or Fake_1)",
            &[
                Form::new(
                    "color",
                    "320x240 from CAMERA_ID",
                    &[settings::COLOR, settings::word("CAMERA_ID"), PIXEL_FORMAT],
                ),
                Form::new(
                    "varcolor",
                    "W x H from CAMERA_ID (without W H: the camera's current region)",
                    &[
                        settings::VARCOLOR,
                        settings::word("CAMERA_ID"),
                        settings::pixels("W", 16384).optional(),
                        settings::pixels("H", 16384),
                        PIXEL_FORMAT,
                    ],
                ),
            ],
        )
        .required(),
        exposure: Vec<(String, NumberOr)> = Line::new(
            "exposure",
            "a camera's exposure time, or auto",
            &[
                settings::word("CAMERA_ID"),
                settings::float_or("MICROSECONDS", "µs", 0.0, 1e9, "auto"),
            ],
        )
        .repeats(),
        gain: Vec<(String, NumberOr)> = Line::new(
            "gain",
            "a camera's gain, or auto",
            &[
                settings::word("CAMERA_ID"),
                settings::float_or("DB", "dB", 0.0, 1000.0, "auto"),
            ],
        )
        .repeats(),
        framerate: Vec<(String, f64)> = Line::new(
            "framerate",
            "a camera's frame rate",
            &[
                settings::word("CAMERA_ID"),
                settings::float("FPS", "frames/s", 0.001, 10_000.0),
            ],
        )
        .repeats(),
    }
}
#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "color")]
    Color(String, String, Option<String>),
    #[serde(rename = "varcolor")]
    Varcolor(String, String, Option<u32>, Option<u32>, Option<String>),
}

impl From<NumberOr> for Setting {
    fn from(v: NumberOr) -> Setting {
        match v {
            NumberOr::Number(v) => Setting::Value(v),
            NumberOr::Word => Setting::Auto,
        }
    }
}

/// Parses the driver's lines.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Vec<GigeConf>> {
    let lines: Lines = conf.read()?;
    let mut cams: Vec<GigeConf> = Vec::new();
    for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
        let (iface, camera, size, pixel_format) = match p {
            Provides::Color(i, c, f) => (i, c, Some((COLOR_WIDTH, COLOR_HEIGHT)), f),
            Provides::Varcolor(i, c, Some(w), Some(h), f) => (i, c, Some((w, h)), f),
            Provides::Varcolor(i, c, _, _, f) => (i, c, None, f),
        };
        cams.push(GigeConf {
            iface,
            camera,
            size,
            pixel_format,
            exposure: None,
            gain: None,
            framerate: None,
            at: l.at.to_string(),
        });
    }
    let exposure: HashMap<String, Setting> = lines
        .exposure
        .into_iter()
        .map(|(c, v)| (c, v.into()))
        .collect();
    let gain: HashMap<String, Setting> =
        lines.gain.into_iter().map(|(c, v)| (c, v.into())).collect();
    let rate: HashMap<String, f64> = lines.framerate.into_iter().collect();
    for known in exposure.keys().chain(gain.keys()).chain(rate.keys()) {
        if !cams.iter().any(|c| &c.camera == known) {
            anyhow::bail!(
                "driver {} ({}): a setting names camera `{known}`, which no `provides` line uses",
                conf.name,
                conf.file.display()
            );
        }
    }
    for c in &mut cams {
        c.exposure = exposure.get(&c.camera).copied();
        c.gain = gain.get(&c.camera).copied();
        c.framerate = rate.get(&c.camera).copied();
    }
    Ok(cams)
}

/// GenICam names the driver converts, in order of preference.
pub const FORMAT_NAMES: &[&str] = &[
    "BGR8",
    "BGR8Packed",
    "RGB8",
    "RGB8Packed",
    "YUV422_8",
    "YUV422_YUYV_Packed",
    "YUV422_8_UYVY",
    "YUV422Packed",
    "BayerRG8",
    "BayerGB8",
    "BayerGR8",
    "BayerBG8",
    "Mono8",
];

/// The pixel format value of a GenICam name the driver converts.
pub fn format_of(name: &str) -> Option<PixelFormat> {
    Some(match name {
        "BGR8" | "BGR8Packed" => PixelFormat::BGR_8_PACKED,
        "RGB8" | "RGB8Packed" => PixelFormat::RGB_8_PACKED,
        "YUV422_8" | "YUV422_YUYV_Packed" => PixelFormat::YUV_422_YUYV_PACKED,
        "YUV422_8_UYVY" | "YUV422Packed" => PixelFormat::YUV_422_PACKED,
        "BayerRG8" => PixelFormat::BAYER_RG_8,
        "BayerGB8" => PixelFormat::BAYER_GB_8,
        "BayerGR8" => PixelFormat::BAYER_GR_8,
        "BayerBG8" => PixelFormat::BAYER_BG_8,
        "Mono8" => PixelFormat::MONO_8,
        _ => return None,
    })
}

/// Converts one frame of GenICam pixel format `f` to BGR.
pub fn convert(
    f: PixelFormat,
    data: &[u8],
    w: u32,
    h: u32,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let r = match f {
        PixelFormat::BGR_8_PACKED => pixfmt::bgr_to_bgr(data, w, h, out),
        PixelFormat::RGB_8_PACKED => pixfmt::rgb_to_bgr(data, w, h, out),
        PixelFormat::YUV_422_YUYV_PACKED => {
            pixfmt::yuv422_to_bgr(data, w, h, Yuv422Order::Yuyv, YuvMatrix::Bt601, out)
        }
        PixelFormat::YUV_422_PACKED => {
            pixfmt::yuv422_to_bgr(data, w, h, Yuv422Order::Uyvy, YuvMatrix::Bt601, out)
        }
        PixelFormat::BAYER_RG_8 => pixfmt::bayer_to_bgr(data, w, h, Bayer::Rggb, out),
        PixelFormat::BAYER_GB_8 => pixfmt::bayer_to_bgr(data, w, h, Bayer::Gbrg, out),
        PixelFormat::BAYER_GR_8 => pixfmt::bayer_to_bgr(data, w, h, Bayer::Grbg, out),
        PixelFormat::BAYER_BG_8 => pixfmt::bayer_to_bgr(data, w, h, Bayer::Bggr, out),
        PixelFormat::MONO_8 => pixfmt::grey_to_bgr(data, w, h, out),
        other => {
            return Err(format!(
                "pixel format 0x{:08x} is not supported",
                other.raw()
            ));
        }
    };
    r.map_err(|e| e.to_string())
}

/// Enables Aravis's Fake interface (camera `Fake_1`); idempotent.
pub fn enable_fake() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: a static NUL-terminated interface name.
        unsafe { arv_enable_interface(c"Fake".as_ptr()) }
    });
}

/// The ids of the cameras Aravis finds now.
pub fn device_ids() -> Vec<String> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _g = LOCK.lock();
    // SAFETY: Aravis's global device list, serialised by LOCK; strings copied at once.
    unsafe {
        arv_update_device_list();
        (0..arv_get_n_devices())
            .filter_map(|i| {
                let p = arv_get_device_id(i);
                (!p.is_null()).then(|| std::ffi::CStr::from_ptr(p).to_string_lossy().into_owned())
            })
            .collect()
    }
}

fn gerr(e: aravis::glib::Error) -> String {
    e.message().to_string()
}

/// An open, configured camera.
struct Session {
    camera: Camera,
    stream: aravis::Stream,
    w: u32,
    h: u32,
    payload: usize,
    acquiring: bool,
}

impl Session {
    fn open(c: &GigeConf) -> Result<Session, String> {
        Self::configure(Self::connect(c)?, c)
    }

    /// Finds and opens the camera (fails when it is absent).
    fn connect(c: &GigeConf) -> Result<Camera, String> {
        if c.camera.starts_with("Fake") {
            enable_fake();
        }
        if CString::new(c.camera.clone()).is_err() {
            return Err(format!("camera id `{}` contains a NUL byte", c.camera));
        }
        Camera::new(Some(&c.camera)).map_err(|e| {
            let ids = device_ids();
            format!(
                "camera `{}`: Aravis cannot open it ({}); Aravis sees {}",
                c.camera,
                gerr(e),
                if ids.is_empty() {
                    "no camera (GigE discovery does not cross subnets: try the camera's IP address)"
                        .to_string()
                } else {
                    ids.join(", ")
                }
            )
        })
    }

    /// Sets the camera up as the conf says (fails when it cannot do it).
    fn configure(camera: Camera, c: &GigeConf) -> Result<Session, String> {
        let fail = |what: &str, e: aravis::glib::Error| {
            format!("camera `{}`: {what}: {}", c.camera, gerr(e))
        };
        // Pixel format: the conf's, or the first convertible one the camera offers.
        let offered: Vec<String> = camera
            .dup_available_pixel_formats_as_strings()
            .map(|v| v.into_iter().map(|s| s.to_string()).collect())
            .unwrap_or_default();
        let name = match &c.pixel_format {
            Some(f) => f.clone(),
            None => FORMAT_NAMES
                .iter()
                .find(|n| offered.iter().any(|o| o == *n))
                .map(|s| s.to_string())
                .ok_or_else(|| {
                    format!(
                        "camera `{}` offers no pixel format this driver converts (it offers {}; the driver converts {})",
                        c.camera,
                        offered.join(", "),
                        FORMAT_NAMES.join(", ")
                    )
                })?,
        };
        camera.set_pixel_format_from_string(&name).map_err(|e| {
            format!(
                "camera `{}`: pixel format {name} refused ({}); it offers: {}",
                c.camera,
                gerr(e),
                offered.join(", ")
            )
        })?;
        if let Some((w, h)) = c.size {
            let wb = camera.width_bounds().unwrap_or((0, i32::MAX));
            let hb = camera.height_bounds().unwrap_or((0, i32::MAX));
            if !(wb.0..=wb.1).contains(&(w as i32)) || !(hb.0..=hb.1).contains(&(h as i32)) {
                return Err(format!(
                    "camera `{}`: {w}x{h} (conf {}) is outside what it offers: width {}..{}, height {}..{}",
                    c.camera, c.at, wb.0, wb.1, hb.0, hb.1
                ));
            }
            camera
                .set_region(0, 0, w as i32, h as i32)
                .map_err(|e| fail(&format!("setting the region to {w}x{h}"), e))?;
        }
        let (_, _, w, h) = camera.region().map_err(|e| fail("reading the region", e))?;
        if let Some((cw, ch)) = c.size
            && (w as u32, h as u32) != (cw, ch)
        {
            return Err(format!(
                "camera `{}`: asked for {cw}x{ch}, it set {w}x{h} (size steps?)",
                c.camera
            ));
        }
        match c.exposure {
            Some(Setting::Auto) => camera
                .set_exposure_time_auto(aravis::Auto::Continuous)
                .map_err(|e| fail("automatic exposure", e))?,
            Some(Setting::Value(us)) => camera
                .set_exposure_time(us)
                .map_err(|e| fail(&format!("exposure {us} us"), e))?,
            None => {}
        }
        match c.gain {
            Some(Setting::Auto) => camera
                .set_gain_auto(aravis::Auto::Continuous)
                .map_err(|e| fail("automatic gain", e))?,
            Some(Setting::Value(db)) => camera
                .set_gain(db)
                .map_err(|e| fail(&format!("gain {db} dB"), e))?,
            None => {}
        }
        if let Some(f) = c.framerate {
            camera
                .set_frame_rate(f)
                .map_err(|e| fail(&format!("frame rate {f}"), e))?;
        }
        let payload = camera
            .payload()
            .map_err(|e| fail("reading the payload size", e))? as usize;
        let stream = camera
            .create_stream()
            .map_err(|e| fail("creating the stream", e))?;
        for _ in 0..8 {
            stream.push_buffer(Buffer::new_allocate(payload));
        }
        Ok(Session {
            camera,
            stream,
            w: w as u32,
            h: h as u32,
            payload,
            acquiring: false,
        })
    }

    fn start(&mut self) -> Result<(), String> {
        if !self.acquiring {
            self.camera
                .start_acquisition()
                .map_err(|e| format!("starting acquisition: {}", gerr(e)))?;
            self.acquiring = true;
        }
        Ok(())
    }

    fn stop(&mut self) {
        if self.acquiring {
            let _ = self.camera.stop_acquisition();
            self.acquiring = false;
        }
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        self.stop();
    }
}

/// Frames a driver thread dropped (incomplete buffers), for tests and benchmarks.
pub static DROPPED: AtomicU64 = AtomicU64::new(0);
/// Frames the camera sent that never reached the driver (gaps in the buffers'
/// frame ids while acquiring), for tests and benchmarks.
pub static SKIPPED: AtomicU64 = AtomicU64::new(0);

/// One camera under the runtime's [`Supervisor`]: opened while its interface is
/// used, acquiring a frame at a time; acquisition pauses while nobody uses it.
struct Capture {
    c: GigeConf,
    iface: Arc<Interface<Image>>,
    out: Vec<u8>,
    last_frame: Instant,
    last_id: Option<u64>,
}

impl Device for Capture {
    type Session = Session;
    fn open(&mut self) -> Result<Session, String> {
        Session::open(&self.c)
    }
    fn step(&mut self, d: &mut Session) -> Result<(), String> {
        let c = &self.c;
        if !d.acquiring {
            d.start()
                .map_err(|e| format!("camera `{}`: {e}", c.camera))?;
            self.last_frame = Instant::now();
            self.last_id = None;
        }
        let Some(buf) = d.stream.timeout_pop_buffer(200_000) else {
            if self.last_frame.elapsed() > CAMERA_NO_FRAME {
                return Err(format!(
                    "camera `{}`: no frame for {} s (unplugged or unreachable?)",
                    c.camera,
                    self.last_frame.elapsed().as_secs()
                ));
            }
            return Ok(());
        };
        let id = buf.frame_id();
        if let Some(l) = self.last_id
            && id > l + 1
        {
            SKIPPED.fetch_add(id - l - 1, Ordering::Relaxed);
        }
        self.last_id = Some(id);
        if buf.status() == BufferStatus::Success {
            let (w, h) = (buf.image_width() as u32, buf.image_height() as u32);
            let (p, len) = buf.data();
            // SAFETY: the buffer owns `len` bytes at `p` until it is pushed back.
            let data = unsafe { std::slice::from_raw_parts(p as *const u8, len) };
            match convert(buf.image_pixel_format(), data, w, h, &mut self.out) {
                Ok(()) => {
                    self.last_frame = Instant::now();
                    self.iface.publish_frame(w, h, &mut self.out);
                }
                Err(e) => self.iface.set_stale(format!("camera `{}`: {e}", c.camera)),
            }
        } else {
            DROPPED.fetch_add(1, Ordering::Relaxed);
        }
        d.stream.push_buffer(buf);
        Ok(())
    }
    fn idle(&mut self, d: &mut Session) -> bool {
        d.stop();
        true
    }
}

/// What `check` found wrong.
#[derive(Debug, PartialEq)]
pub enum CheckError {
    /// Aravis cannot find or open the camera: the driver waits for it.
    Absent(String),
    /// The camera is there but cannot do what the conf asks.
    Unusable(String),
}

/// Opens and configures camera `c` once (what `create` checks): Ok((w, h, payload)).
pub fn check(c: &GigeConf) -> Result<(u32, u32, usize), CheckError> {
    let camera = Session::connect(c).map_err(CheckError::Absent)?;
    Session::configure(camera, c)
        .map(|o| (o.w, o.h, o.payload))
        .map_err(CheckError::Unusable)
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    let cams = parse(conf)?;
    // (size, why absent) per camera.
    let mut found = Vec::new();
    for c in &cams {
        match check(c) {
            Ok((w, h, _)) => {
                if c.iface.starts_with("color") && (w, h) != (COLOR_WIDTH, COLOR_HEIGHT) {
                    anyhow::bail!("{}: {} needs 320x240, camera gives {w}x{h}", c.at, c.iface);
                }
                found.push(((w, h), None));
            }
            Err(CheckError::Absent(e)) => found.push((c.size.unwrap_or((0, 0)), Some(e))),
            Err(CheckError::Unusable(e)) => anyhow::bail!("{}: driver {}: {e}", c.at, conf.name),
        }
    }
    let mut cameras = Vec::new();
    for (c, ((w, h), absent)) in cams.into_iter().zip(found) {
        let iface = rt
            .interfaces
            .provide_value(&c.iface, &conf.name, Image::new(w, h))?;
        let how = Supervision::camera(
            format!("gige camera `{}`", c.camera),
            iface.clone(),
            absent.map(|why| Absent::new(&c.at, &conf.name, why, "the camera answers")),
        );
        cameras.push(Supervisor::start(
            how,
            Capture {
                c,
                iface,
                out: Vec::new(),
                last_frame: Instant::now(),
                last_id: None,
            },
        )?);
    }
    Ok(Box::new(cameras))
}

crate::register_driver!(
    Driver,
    "gige",
    "GigE Vision / USB3 Vision cameras through Aravis 0.8: colorA..D, varcolorA..D",
    create,
    lines = Lines
);
