//! The few libdc1394 2.x functions the firewire driver calls, declared by hand
//! from `<dc1394/*.h>` (Debian `libdc1394-dev`, 2.2.x); linked with `-ldc1394`.
//! Enums are C `int`s with the header's values.
#![allow(non_camel_case_types, dead_code)]

use std::{
    ffi::{CStr, c_char, c_int, c_void},
    sync::Mutex,
};

pub type dc1394error_t = c_int;
pub type dc1394video_mode_t = c_int;
pub type dc1394framerate_t = c_int;
pub type dc1394color_coding_t = c_int;
pub type dc1394color_filter_t = c_int;
pub type dc1394feature_t = c_int;
pub type dc1394feature_mode_t = c_int;
pub type dc1394bool_t = c_int;
pub type dc1394log_t = c_int;

pub const DC1394_SUCCESS: dc1394error_t = 0;

pub const DC1394_VIDEO_MODE_160X120_YUV444: dc1394video_mode_t = 64;
pub const DC1394_VIDEO_MODE_FORMAT7_0: dc1394video_mode_t = 88;
pub const DC1394_VIDEO_MODE_NUM: usize = 32;
pub const DC1394_VIDEO_MODE_EXIF: dc1394video_mode_t = 87;

pub const DC1394_FRAMERATE_1_875: dc1394framerate_t = 32;
pub const DC1394_FRAMERATE_NUM: usize = 8;

pub const DC1394_COLOR_CODING_MONO8: dc1394color_coding_t = 352;
pub const DC1394_COLOR_CODING_YUV411: dc1394color_coding_t = 353;
pub const DC1394_COLOR_CODING_YUV422: dc1394color_coding_t = 354;
pub const DC1394_COLOR_CODING_YUV444: dc1394color_coding_t = 355;
pub const DC1394_COLOR_CODING_RGB8: dc1394color_coding_t = 356;
pub const DC1394_COLOR_CODING_MONO16: dc1394color_coding_t = 357;
pub const DC1394_COLOR_CODING_RAW8: dc1394color_coding_t = 361;

pub const DC1394_COLOR_FILTER_RGGB: dc1394color_filter_t = 512;
pub const DC1394_COLOR_FILTER_GBRG: dc1394color_filter_t = 513;
pub const DC1394_COLOR_FILTER_GRBG: dc1394color_filter_t = 514;
pub const DC1394_COLOR_FILTER_BGGR: dc1394color_filter_t = 515;

pub const DC1394_BYTE_ORDER_UYVY: u32 = 800;
pub const DC1394_BYTE_ORDER_YUYV: u32 = 801;

pub const DC1394_BAYER_METHOD_BILINEAR: c_int = 2;

pub const DC1394_ISO_SPEED_400: c_int = 2;
pub const DC1394_CAPTURE_POLICY_POLL: c_int = 673;
pub const DC1394_CAPTURE_FLAGS_DEFAULT: u32 = 4;
pub const DC1394_OFF: c_int = 0;
pub const DC1394_ON: c_int = 1;

pub const DC1394_FEATURE_FOCUS: dc1394feature_t = 426;
pub const DC1394_FEATURE_MODE_MANUAL: dc1394feature_mode_t = 736;
pub const DC1394_FEATURE_MODE_AUTO: dc1394feature_mode_t = 737;

pub const DC1394_LOG_ERROR: dc1394log_t = 768;
pub const DC1394_LOG_WARNING: dc1394log_t = 769;

#[repr(C)]
pub struct dc1394_t {
    _p: [u8; 0],
}

/// `dc1394camera_t`: only the leading `guid` is read; the rest is opaque.
#[repr(C)]
pub struct dc1394camera_t {
    pub guid: u64,
    _rest: [u8; 0],
}

#[repr(C)]
pub struct dc1394camera_id_t {
    pub guid: u64,
    pub unit: c_int,
}

#[repr(C)]
pub struct dc1394camera_list_t {
    pub num: u32,
    pub ids: *mut dc1394camera_id_t,
}

#[repr(C)]
pub struct dc1394video_modes_t {
    pub num: u32,
    pub modes: [dc1394video_mode_t; DC1394_VIDEO_MODE_NUM],
}

#[repr(C)]
pub struct dc1394framerates_t {
    pub num: u32,
    pub framerates: [dc1394framerate_t; DC1394_FRAMERATE_NUM],
}

/// `dc1394video_frame_t` (video.h), field for field.
#[repr(C)]
pub struct dc1394video_frame_t {
    pub image: *mut u8,
    pub size: [u32; 2],
    pub position: [u32; 2],
    pub color_coding: dc1394color_coding_t,
    pub color_filter: dc1394color_filter_t,
    pub yuv_byte_order: u32,
    pub data_depth: u32,
    pub stride: u32,
    pub video_mode: dc1394video_mode_t,
    pub total_bytes: u64,
    pub image_bytes: u32,
    pub padding_bytes: u32,
    pub packet_size: u32,
    pub packets_per_frame: u32,
    pub timestamp: u64,
    pub frames_behind: u32,
    pub camera: *mut dc1394camera_t,
    pub id: u32,
    pub allocated_image_bytes: u64,
    pub little_endian: dc1394bool_t,
    pub data_in_padding: dc1394bool_t,
}

type LogHandler = unsafe extern "C" fn(dc1394log_t, *const c_char, *mut c_void);

#[link(name = "dc1394")]
unsafe extern "C" {
    pub fn dc1394_new() -> *mut dc1394_t;
    pub fn dc1394_free(d: *mut dc1394_t);
    pub fn dc1394_camera_enumerate(
        d: *mut dc1394_t,
        list: *mut *mut dc1394camera_list_t,
    ) -> dc1394error_t;
    pub fn dc1394_camera_free_list(list: *mut dc1394camera_list_t);
    pub fn dc1394_camera_new_unit(d: *mut dc1394_t, guid: u64, unit: c_int) -> *mut dc1394camera_t;
    pub fn dc1394_camera_free(c: *mut dc1394camera_t);
    pub fn dc1394_video_get_supported_modes(
        c: *mut dc1394camera_t,
        modes: *mut dc1394video_modes_t,
    ) -> dc1394error_t;
    pub fn dc1394_video_get_supported_framerates(
        c: *mut dc1394camera_t,
        mode: dc1394video_mode_t,
        rates: *mut dc1394framerates_t,
    ) -> dc1394error_t;
    pub fn dc1394_get_image_size_from_video_mode(
        c: *mut dc1394camera_t,
        mode: dc1394video_mode_t,
        w: *mut u32,
        h: *mut u32,
    ) -> dc1394error_t;
    pub fn dc1394_get_color_coding_from_video_mode(
        c: *mut dc1394camera_t,
        mode: dc1394video_mode_t,
        coding: *mut dc1394color_coding_t,
    ) -> dc1394error_t;
    pub fn dc1394_video_set_iso_speed(c: *mut dc1394camera_t, speed: c_int) -> dc1394error_t;
    pub fn dc1394_video_set_mode(c: *mut dc1394camera_t, mode: dc1394video_mode_t)
    -> dc1394error_t;
    pub fn dc1394_video_set_framerate(
        c: *mut dc1394camera_t,
        rate: dc1394framerate_t,
    ) -> dc1394error_t;
    pub fn dc1394_capture_setup(c: *mut dc1394camera_t, buffers: u32, flags: u32) -> dc1394error_t;
    pub fn dc1394_capture_stop(c: *mut dc1394camera_t) -> dc1394error_t;
    pub fn dc1394_capture_get_fileno(c: *mut dc1394camera_t) -> c_int;
    pub fn dc1394_video_set_transmission(c: *mut dc1394camera_t, on: c_int) -> dc1394error_t;
    pub fn dc1394_capture_dequeue(
        c: *mut dc1394camera_t,
        policy: c_int,
        frame: *mut *mut dc1394video_frame_t,
    ) -> dc1394error_t;
    pub fn dc1394_capture_enqueue(
        c: *mut dc1394camera_t,
        frame: *mut dc1394video_frame_t,
    ) -> dc1394error_t;
    pub fn dc1394_feature_set_mode(
        c: *mut dc1394camera_t,
        feature: dc1394feature_t,
        mode: dc1394feature_mode_t,
    ) -> dc1394error_t;
    pub fn dc1394_error_get_string(e: dc1394error_t) -> *const c_char;
    pub fn dc1394_log_register_handler(
        kind: dc1394log_t,
        handler: Option<LogHandler>,
        user: *mut c_void,
    ) -> dc1394error_t;
    pub fn dc1394_convert_to_RGB8(
        src: *mut u8,
        dest: *mut u8,
        width: u32,
        height: u32,
        byte_order: u32,
        source_coding: dc1394color_coding_t,
        bits: u32,
    ) -> dc1394error_t;
    pub fn dc1394_bayer_decoding_8bit(
        bayer: *const u8,
        rgb: *mut u8,
        width: u32,
        height: u32,
        tile: dc1394color_filter_t,
        method: c_int,
    ) -> dc1394error_t;
    pub fn dc1394_convert_frames(
        inp: *mut dc1394video_frame_t,
        out: *mut dc1394video_frame_t,
    ) -> dc1394error_t;
}

/// libdc1394's text for an error code.
pub fn error_string(e: dc1394error_t) -> String {
    // SAFETY: libdc1394 returns a static string for every code (or "Unknown error").
    let p = unsafe { dc1394_error_get_string(e) };
    if p.is_null() {
        return format!("libdc1394 error {e}");
    }
    // SAFETY: non-null, NUL-terminated static string.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

/// The messages libdc1394 logged (errors and warnings), newest last; the driver
/// reports them instead of letting the library print to stderr.
static LOG: Mutex<Vec<String>> = Mutex::new(Vec::new());

unsafe extern "C" fn log_handler(kind: dc1394log_t, msg: *const c_char, _user: *mut c_void) {
    if msg.is_null() {
        return;
    }
    // SAFETY: libdc1394 passes a NUL-terminated message.
    let m = unsafe { CStr::from_ptr(msg) }
        .to_string_lossy()
        .into_owned();
    let what = if kind == DC1394_LOG_ERROR {
        "error"
    } else {
        "warning"
    };
    if let Ok(mut l) = LOG.lock() {
        if l.len() >= 32 {
            l.remove(0);
        }
        l.push(format!("{what}: {}", m.trim()));
    }
}

/// Routes libdc1394's error and warning log to [`take_log`] (idempotent).
pub fn capture_log() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // SAFETY: registering a plain function with a null user pointer.
        unsafe {
            dc1394_log_register_handler(DC1394_LOG_ERROR, Some(log_handler), std::ptr::null_mut());
            dc1394_log_register_handler(
                DC1394_LOG_WARNING,
                Some(log_handler),
                std::ptr::null_mut(),
            );
        }
    });
}

/// What libdc1394 logged since the last call, joined with "; ".
pub fn take_log() -> String {
    LOG.lock()
        .map(|mut l| std::mem::take(&mut *l).join("; "))
        .unwrap_or_default()
}
