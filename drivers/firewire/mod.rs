//! firewire (and `firewire22`, the same driver under 4.3's second name): IEEE 1394
//! IIDC cameras (Apple iSight, Unibrain Fire-i, Point Grey...) through the system's
//! libdc1394 2.x (Debian `libdc1394-dev` to build, `libdc1394-25` to run; linked
//! with `-ldc1394` through the small hand-written FFI in [`ffi`], no C source).
//!
//! # Conf (the seed's lines)
//! ```text
//! driver firewire
//! provides varcolorA 0 640 480 autofocus_off   # varcolorX CAM W H [autofocus_on|autofocus_off]
//! provides colorB 1 autofocus_on               # colorX CAM [autofocus_on|autofocus_off]: 320x240
//! bayer 1 RGGB                                 # beyond 4.3: camera 1 sends a Bayer mosaic in
//!                                              #   its MONO8 modes (RGGB, GBRG, GRBG or BGGR)
//! end_driver
//! ```
//! `CAM` numbers the cameras as 4.3 did: the index (0, 1, ...) in the list of
//! cameras libdc1394 finds on the bus (`dc1394_camera_enumerate`).
//!
//! # Interfaces
//! `colorA..D` (320x240 BGR) and `varcolorA..D` (W x H BGR). The camera is set to
//! the IIDC fixed video mode of exactly that size (RGB8 preferred, then YUV 4:2:2,
//! 4:4:4, 4:1:1, MONO8) at the fastest frame rate the camera offers for it (4.3:
//! 320x240 at 30 fps, 640x480 at 15 fps on the iSight). Frames are converted to BGR
//! by [`crate::vision::pixfmt`] with libdc1394's own formulas (tested equal to
//! `dc1394_convert_to_RGB8` and `dc1394_bayer_decoding_8bit`). The clock moves once
//! per frame.
//!
//! # Behaviour
//! - The camera transmits only while someone uses the interface (resume/suspend):
//!   capture is set up on the first user and stopped (transmission off, ISO
//!   bandwidth released) when the last one leaves.
//! - At start the driver checks that camera `CAM` exists; with no bus or no such
//!   camera it prints a message naming the conf line, the camera number and what
//!   libdc1394 found, and the interface is stale with that reason (shown by `ps`,
//!   `echo` and mastergui) until the camera appears: the driver tries again every
//!   2 s while the interface is used. A size the camera has no mode for is an
//!   error when the camera is opened (listing its modes), shown the same way.
//! - A camera unplugged while running (dequeue fails, or no frame for 5 s) marks
//!   the interface stale with the reason; the driver tries to open camera `CAM`
//!   again every 2 s and goes on when it is back. Nothing blocks other schemas:
//!   each camera has its own thread, which waits for frames with `poll` and a
//!   200 ms timeout.

pub mod ffi;

use std::{
    ffi::c_int,
    sync::Arc,
    time::{Duration, Instant},
};

use crate::{
    conf::{
        ComponentConf,
        settings::{self, Form, Setting},
    },
    interfaces::{COLOR_HEIGHT, COLOR_WIDTH, Image, Interface},
    runtime::{Device, Driver, Runtime, Supervision, Supervisor},
    supervisor::{Absent, CAMERA_NO_FRAME},
    vision::pixfmt::{self, Bayer, Yuv422Order, YuvMatrix},
};

use ffi::*;

/// One camera to capture from, parsed from a `provides` line.
#[derive(Clone, Debug, PartialEq)]
pub struct CamConf {
    /// The interface name (`colorA`, `varcolorB`...).
    pub iface: String,
    /// 4.3's camera number: index in libdc1394's camera list.
    pub cam: u32,
    pub width: u32,
    pub height: u32,
    /// `Some(true)` = autofocus_on, `Some(false)` = autofocus_off, None = leave it.
    pub autofocus: Option<bool>,
    /// The mosaic of MONO8 frames (`bayer CAM PATTERN`), if any.
    pub bayer: Option<Bayer>,
    /// Where the line is (`file:line`), for errors at run time.
    pub at: String,
}

/// `autofocus_on|autofocus_off`: what a line may say of the camera's focus.
const AUTOFOCUS: settings::Arg = settings::choice(
    "autofocus_on|autofocus_off",
    &["autofocus_on", "autofocus_off"],
)
.optional();

crate::declare_lines! {
    /// The driver's lines, declared once (`jderobot help firewire`).
    struct Lines {
        provides: Vec<Provides> = settings::provides_forms(
            "an image interface and the camera it comes from (CAM: 0, 1, ... in the bus's order)",
            &[
                Form::new(
                    "color",
                    "320x240 from camera CAM",
                    &[settings::COLOR, settings::int("CAM", "", 0, 63), AUTOFOCUS],
                ),
                Form::new(
                    "varcolor",
                    "W x H from camera CAM (a size it has an IIDC mode for)",
                    &[
                        settings::VARCOLOR,
                        settings::int("CAM", "", 0, 63),
                        settings::pixels("W", 8192),
                        settings::pixels("H", 8192),
                        AUTOFOCUS,
                    ],
                ),
            ],
        )
        .required(),
        bayer: Vec<(u32, String)> = Setting::new(
            "bayer",
            "camera CAM sends a Bayer mosaic in this pattern (decoded to BGR)",
            &[
                settings::int("CAM", "", 0, 63),
                settings::choice(
                    "PATTERN",
                    &[
                        "RGGB", "GBRG", "GRBG", "BGGR", "rggb", "gbrg", "grbg", "bggr",
                    ],
                ),
            ],
        )
        .repeats(),
    }
}
#[derive(serde::Deserialize)]
enum Provides {
    #[serde(rename = "color")]
    Color(String, u32, Option<String>),
    #[serde(rename = "varcolor")]
    Varcolor(String, u32, u32, u32, Option<String>),
}

/// Parses the driver's lines.
pub fn parse(conf: &ComponentConf) -> anyhow::Result<Vec<CamConf>> {
    let lines: Lines = conf.read()?;
    let mut cams: Vec<CamConf> = Vec::new();
    for (p, l) in lines.provides.into_iter().zip(conf.provides()) {
        let (iface, cam, (width, height), focus) = match p {
            Provides::Color(i, c, f) => (i, c, (COLOR_WIDTH, COLOR_HEIGHT), f),
            Provides::Varcolor(i, c, w, h, f) => (i, c, (w, h), f),
        };
        cams.push(CamConf {
            iface,
            cam,
            width,
            height,
            autofocus: focus.map(|f| f == "autofocus_on"),
            bayer: None,
            at: l.at.to_string(),
        });
    }
    for (cam, p) in lines.bayer {
        // The declaration lists only the patterns `Bayer::parse` reads.
        let Some(p) = Bayer::parse(&p) else { continue };
        for c in cams.iter_mut().filter(|c| c.cam == cam) {
            c.bayer = Some(p);
        }
    }
    Ok(cams)
}

/// A libdc1394 context (`dc1394_new`), freed on drop.
struct Ctx(*mut dc1394_t);

impl Ctx {
    fn new() -> Result<Ctx, String> {
        capture_log();
        let _ = take_log();
        // SAFETY: plain constructor; null on failure.
        let p = unsafe { dc1394_new() };
        if p.is_null() {
            let log = take_log();
            return Err(format!(
                "libdc1394 could not start: no IEEE 1394 bus found (no FireWire controller, or no \
                 /dev/fw* device readable by this user){}",
                if log.is_empty() {
                    String::new()
                } else {
                    format!("; libdc1394 said: {log}")
                }
            ));
        }
        Ok(Ctx(p))
    }

    /// The (guid, unit) of every camera on the bus, in libdc1394's order.
    fn cameras(&self) -> Result<Vec<(u64, c_int)>, String> {
        let mut list: *mut dc1394camera_list_t = std::ptr::null_mut();
        // SAFETY: valid context; list is an out pointer.
        let e = unsafe { dc1394_camera_enumerate(self.0, &mut list) };
        if e != DC1394_SUCCESS || list.is_null() {
            let log = take_log();
            return Err(format!(
                "libdc1394 could not list the cameras on the IEEE 1394 bus: {}{}",
                error_string(e),
                if log.is_empty() {
                    String::new()
                } else {
                    format!(" ({log})")
                }
            ));
        }
        // SAFETY: enumerate filled `list` with `num` ids; freed right after.
        let ids = unsafe {
            let l = &*list;
            let v = (0..l.num as usize)
                .map(|i| {
                    let id = &*l.ids.add(i);
                    (id.guid, id.unit)
                })
                .collect();
            dc1394_camera_free_list(list);
            v
        };
        Ok(ids)
    }
}

impl Drop for Ctx {
    fn drop(&mut self) {
        // SAFETY: created by dc1394_new, freed once.
        unsafe { dc1394_free(self.0) }
    }
}

/// Checks that camera `cam` is on the bus; the error says what libdc1394 found.
pub fn probe(cam: u32) -> Result<u64, String> {
    let ctx = Ctx::new().map_err(|e| format!("camera {cam}: {e}"))?;
    let ids = ctx.cameras().map_err(|e| format!("camera {cam}: {e}"))?;
    match ids.get(cam as usize) {
        Some((guid, _)) => Ok(*guid),
        None => Err(format!(
            "camera {cam} not found: libdc1394 found {} camera(s) on the IEEE 1394 bus{}{}{}",
            ids.len(),
            bus_note(),
            if ids.is_empty() { "" } else { ": " },
            ids.iter()
                .enumerate()
                .map(|(i, (g, u))| format!("{i} = guid {g:016x} unit {u}"))
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// Whether the kernel shows any FireWire node (`/dev/fw*`), for error messages.
fn bus_note() -> &'static str {
    let any = std::fs::read_dir("/dev")
        .map(|d| {
            d.flatten()
                .any(|e| e.file_name().to_string_lossy().starts_with("fw"))
        })
        .unwrap_or(false);
    if any {
        ""
    } else {
        " (there is no /dev/fw* node: no FireWire controller, or the firewire-ohci module is not loaded)"
    }
}

fn coding_name(c: dc1394color_coding_t) -> &'static str {
    match c {
        DC1394_COLOR_CODING_MONO8 => "MONO8",
        DC1394_COLOR_CODING_YUV411 => "YUV411",
        DC1394_COLOR_CODING_YUV422 => "YUV422",
        DC1394_COLOR_CODING_YUV444 => "YUV444",
        DC1394_COLOR_CODING_RGB8 => "RGB8",
        DC1394_COLOR_CODING_MONO16 => "MONO16",
        DC1394_COLOR_CODING_RAW8 => "RAW8",
        _ => "other",
    }
}

/// An open camera, capturing; stops and frees everything on drop.
struct Session {
    cam: *mut dc1394camera_t,
    fd: c_int,
    _ctx: Ctx,
}

impl Session {
    fn open(c: &CamConf) -> Result<Session, String> {
        let ctx = Ctx::new().map_err(|e| format!("camera {}: {e}", c.cam))?;
        let ids = ctx
            .cameras()
            .map_err(|e| format!("camera {}: {e}", c.cam))?;
        let Some(&(guid, unit)) = ids.get(c.cam as usize) else {
            return Err(probe(c.cam).err().unwrap_or_else(|| {
                format!(
                    "camera {} not found: libdc1394 finds {} camera(s) on the bus",
                    c.cam,
                    ids.len()
                )
            }));
        };
        // SAFETY: valid context and an id libdc1394 just listed.
        let cam = unsafe { dc1394_camera_new_unit(ctx.0, guid, unit) };
        if cam.is_null() {
            return Err(format!(
                "camera {} (guid {guid:016x}): libdc1394 could not open it ({})",
                c.cam,
                take_log()
            ));
        }
        // From here on, `session` owns the camera (Drop stops and frees it).
        let mut session = Session {
            cam,
            fd: -1,
            _ctx: ctx,
        };
        let mode = session.choose_mode(c)?;
        let ck = |e: dc1394error_t, what: &str| -> Result<(), String> {
            if e == DC1394_SUCCESS {
                Ok(())
            } else {
                Err(format!(
                    "camera {}: {what} failed: {} {}",
                    c.cam,
                    error_string(e),
                    take_log()
                ))
            }
        };
        // SAFETY: `cam` is a valid open camera in every call below.
        unsafe {
            ck(
                dc1394_video_set_iso_speed(cam, DC1394_ISO_SPEED_400),
                "setting ISO speed 400",
            )?;
            ck(dc1394_video_set_mode(cam, mode.0), "setting the video mode")?;
            ck(
                dc1394_video_set_framerate(cam, mode.1),
                "setting the frame rate",
            )?;
            if let Some(on) = c.autofocus {
                let m = if on {
                    DC1394_FEATURE_MODE_AUTO
                } else {
                    DC1394_FEATURE_MODE_MANUAL
                };
                if dc1394_feature_set_mode(cam, DC1394_FEATURE_FOCUS, m) != DC1394_SUCCESS {
                    tracing::warn!(
                        "firewire: camera {} has no settable focus; autofocus_{} ignored",
                        c.cam,
                        if on { "on" } else { "off" }
                    );
                    let _ = take_log();
                }
            }
            ck(
                dc1394_capture_setup(cam, 4, DC1394_CAPTURE_FLAGS_DEFAULT),
                "setting up capture",
            )?;
            session.fd = dc1394_capture_get_fileno(cam);
            ck(
                dc1394_video_set_transmission(cam, DC1394_ON),
                "starting transmission",
            )?;
        }
        Ok(session)
    }

    /// The fixed IIDC mode of exactly the wanted size and its fastest frame rate.
    fn choose_mode(&self, c: &CamConf) -> Result<(dc1394video_mode_t, dc1394framerate_t), String> {
        let mut modes = dc1394video_modes_t {
            num: 0,
            modes: [0; DC1394_VIDEO_MODE_NUM],
        };
        // SAFETY: valid camera; `modes` is the header's struct.
        if unsafe { dc1394_video_get_supported_modes(self.cam, &mut modes) } != DC1394_SUCCESS {
            return Err(format!(
                "camera {}: cannot read its video modes ({})",
                c.cam,
                take_log()
            ));
        }
        let mut offered = Vec::new();
        let mut best: Option<(usize, dc1394video_mode_t)> = None;
        let rank = [
            DC1394_COLOR_CODING_RGB8,
            DC1394_COLOR_CODING_YUV422,
            DC1394_COLOR_CODING_YUV444,
            DC1394_COLOR_CODING_YUV411,
            DC1394_COLOR_CODING_MONO8,
        ];
        for &m in &modes.modes[..(modes.num as usize).min(DC1394_VIDEO_MODE_NUM)] {
            if m >= DC1394_VIDEO_MODE_EXIF {
                continue; // EXIF and Format7 are not used
            }
            let (mut w, mut h, mut cc) = (0u32, 0u32, 0);
            // SAFETY: valid camera and mode; out pointers.
            unsafe {
                dc1394_get_image_size_from_video_mode(self.cam, m, &mut w, &mut h);
                dc1394_get_color_coding_from_video_mode(self.cam, m, &mut cc);
            }
            offered.push(format!("{w}x{h} {}", coding_name(cc)));
            if (w, h) == (c.width, c.height)
                && let Some(r) = rank.iter().position(|&x| x == cc)
                && best.is_none_or(|(br, _)| r < br)
            {
                best = Some((r, m));
            }
        }
        let Some((_, mode)) = best else {
            return Err(format!(
                "camera {}: no video mode of {}x{} (the conf at {} asks for it); the camera offers: {}",
                c.cam,
                c.width,
                c.height,
                c.at,
                offered.join(", ")
            ));
        };
        let mut rates = dc1394framerates_t {
            num: 0,
            framerates: [0; DC1394_FRAMERATE_NUM],
        };
        // SAFETY: as above.
        unsafe { dc1394_video_get_supported_framerates(self.cam, mode, &mut rates) };
        let rate = rates.framerates[..(rates.num as usize).min(DC1394_FRAMERATE_NUM)]
            .iter()
            .copied()
            .max()
            .unwrap_or(DC1394_FRAMERATE_1_875 + 3); // 15 fps
        Ok((mode, rate))
    }

    /// Waits up to `timeout` for a frame and converts it into `out`; Ok(false) on
    /// timeout.
    fn grab(&mut self, c: &CamConf, timeout: Duration, out: &mut Vec<u8>) -> Result<bool, String> {
        if self.fd >= 0 {
            let mut p = libc::pollfd {
                fd: self.fd,
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd.
            let n = unsafe { libc::poll(&mut p, 1, timeout.as_millis() as c_int) };
            if n == 0 {
                return Ok(false);
            }
            if n < 0 || p.revents & (libc::POLLERR | libc::POLLHUP | libc::POLLNVAL) != 0 {
                return Err(format!(
                    "camera {}: the capture device failed (unplugged?)",
                    c.cam
                ));
            }
        } else {
            std::thread::sleep(Duration::from_millis(5));
        }
        let mut f: *mut dc1394video_frame_t = std::ptr::null_mut();
        // SAFETY: capturing camera; POLL policy never blocks.
        let e = unsafe { dc1394_capture_dequeue(self.cam, DC1394_CAPTURE_POLICY_POLL, &mut f) };
        if e != DC1394_SUCCESS {
            return Err(format!(
                "camera {}: capture failed: {} (unplugged?) {}",
                c.cam,
                error_string(e),
                take_log()
            ));
        }
        if f.is_null() {
            return Ok(false);
        }
        // SAFETY: a dequeued frame stays valid until enqueued below.
        let r = unsafe {
            let fr = &*f;
            let len = fr.image_bytes as usize;
            let data = std::slice::from_raw_parts(fr.image, len);
            let r = convert_frame(
                data,
                fr.size[0],
                fr.size[1],
                fr.color_coding,
                fr.yuv_byte_order,
                fr.color_filter,
                c.bayer,
                out,
            );
            dc1394_capture_enqueue(self.cam, f);
            r
        };
        r.map(|()| true)
            .map_err(|e| format!("camera {}: {e}", c.cam))
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        // SAFETY: valid camera; stopping an idle capture is harmless.
        unsafe {
            dc1394_video_set_transmission(self.cam, DC1394_OFF);
            dc1394_capture_stop(self.cam);
            dc1394_camera_free(self.cam);
        }
        let _ = take_log();
    }
}

/// Converts one IIDC frame to BGR with libdc1394's formulas.
#[allow(clippy::too_many_arguments)]
pub fn convert_frame(
    data: &[u8],
    w: u32,
    h: u32,
    coding: dc1394color_coding_t,
    yuv_order: u32,
    filter: dc1394color_filter_t,
    bayer: Option<Bayer>,
    out: &mut Vec<u8>,
) -> Result<(), String> {
    let r = match coding {
        DC1394_COLOR_CODING_RGB8 => pixfmt::rgb_to_bgr(data, w, h, out),
        DC1394_COLOR_CODING_YUV422 => {
            let order = if yuv_order == DC1394_BYTE_ORDER_YUYV {
                Yuv422Order::Yuyv
            } else {
                Yuv422Order::Uyvy
            };
            pixfmt::yuv422_to_bgr(data, w, h, order, YuvMatrix::Iidc, out)
        }
        DC1394_COLOR_CODING_YUV411 => pixfmt::yuv411_to_bgr(data, w, h, out),
        DC1394_COLOR_CODING_YUV444 => pixfmt::yuv444_to_bgr(data, w, h, out),
        DC1394_COLOR_CODING_MONO8 => match bayer {
            Some(p) => pixfmt::bayer_to_bgr(data, w, h, p, out),
            None => pixfmt::grey_to_bgr(data, w, h, out),
        },
        DC1394_COLOR_CODING_RAW8 => {
            let p = bayer.unwrap_or(match filter {
                DC1394_COLOR_FILTER_GBRG => Bayer::Gbrg,
                DC1394_COLOR_FILTER_GRBG => Bayer::Grbg,
                DC1394_COLOR_FILTER_BGGR => Bayer::Bggr,
                _ => Bayer::Rggb,
            });
            pixfmt::bayer_to_bgr(data, w, h, p, out)
        }
        other => {
            return Err(format!(
                "frames in colour coding {} ({other}) are not supported",
                coding_name(other)
            ));
        }
    };
    r.map_err(|e| e.to_string())
}

/// One camera under the runtime's [`Supervisor`]: it opens the camera while its
/// interface is used, and serves it a frame at a time.
struct Camera {
    c: CamConf,
    iface: Arc<Interface<Image>>,
    buf: Vec<u8>,
    last_frame: Instant,
}

impl Device for Camera {
    type Session = Session;
    fn open(&mut self) -> Result<Session, String> {
        let s = Session::open(&self.c)?;
        self.last_frame = Instant::now();
        Ok(s)
    }
    fn step(&mut self, d: &mut Session) -> Result<(), String> {
        if d.grab(&self.c, Duration::from_millis(200), &mut self.buf)? {
            self.last_frame = Instant::now();
            self.iface
                .publish_frame(self.c.width, self.c.height, &mut self.buf);
        } else if self.last_frame.elapsed() > CAMERA_NO_FRAME {
            self.iface.set_stale(format!(
                "camera {}: no frame for {} s",
                self.c.cam,
                self.last_frame.elapsed().as_secs()
            ));
        }
        Ok(())
    }
}

fn create(conf: &ComponentConf, rt: &Runtime) -> anyhow::Result<Box<dyn Driver>> {
    if conf.name == "firewire22" {
        tracing::info!("firewire22: the same driver as firewire (libdc1394 2.x)");
    }
    let cams = parse(conf)?;
    let mut cameras = Vec::new();
    for c in cams {
        let iface =
            rt.interfaces
                .provide_value(&c.iface, &conf.name, Image::new(c.width, c.height))?;
        // An absent camera (or bus) is not fatal: the interface is stale with the
        // reason until the camera appears, and the capture thread keeps trying.
        let absent = probe(c.cam).err();
        let until = format!("camera {} appears", c.cam);
        let how = Supervision::camera(
            format!("firewire camera {}", c.cam),
            iface.clone(),
            absent.map(|why| Absent::new(&c.at, &conf.name, why, &until)),
        );
        cameras.push(Supervisor::start(
            how,
            Camera {
                c,
                iface,
                buf: Vec::new(),
                last_frame: Instant::now(),
            },
        )?);
    }
    Ok(Box::new(cameras))
}

crate::register_driver!(
    Driver,
    "firewire",
    "IEEE 1394 (IIDC) cameras through libdc1394 2.x: colorA..D, varcolorA..D",
    create,
    lines = Lines
);

crate::register_driver!(
    Driver,
    "firewire22",
    "the firewire driver under 4.3's libdc1394-2.2 name: colorA..D, varcolorA..D",
    create,
    "firewire22",
    lines = Lines
);
