//! An emulator of a Slamtec RPLIDAR A1 on a pseudo-terminal, written from Slamtec's
//! *RPLIDAR Interface Protocol and Application Notes* (not from the driver):
//!
//! - "Request Packets' Format": `A5 CMD`, or with a payload `A5 CMD SIZE PAYLOAD
//!   CHECKSUM` (the checksum the XOR of all bytes before it); commands with a
//!   payload have bit 7 set (e.g. MOTOR_SPEED_CTRL/PWM 0xF0).
//! - "Response Descriptor": `A5 5A` then a 30-bit length and 2-bit send mode (little
//!   endian, 0 single, 1 multiple response) then the data type.
//! - STOP (0x25): leaves the scan state, no answer. RESET (0x40): a reset (scan
//!   stops). GET_INFO (0x50): descriptor `A5 5A 14 00 00 00 04`, then model, firmware
//!   minor, firmware major, hardware, 16-byte serial number. GET_HEALTH (0x52):
//!   descriptor `A5 5A 03 00 00 00 06`, then status (0 good, 1 warning, 2 error) and a
//!   16-bit error code. SCAN (0x20): descriptor `A5 5A 05 00 00 40 81`, then 5-byte
//!   nodes until STOP: byte 0 `quality:6 !S:1 S:1` (S set on the first node of a
//!   new 360° scan), byte 1 `angle_q6[6:0] C:1` (C always 1), byte 2
//!   `angle_q6[14:7]`, bytes 3..4 `distance_q2` (mm × 4, 0: no measurement); angles
//!   in degrees × 64, clockwise seen from above.
//! - An A1 (its datasheet): about 5.5 revolutions a second, about 360 samples a
//!   revolution (the angle step not an exact degree: the first angle of each
//!   revolution drifts), range 0.15..12 m; model byte 0x18.
//! - It measures the shared room (tests/emulators/room.rs) from the robot's pose.
//!
//! Faults: `health_error` (GET_HEALTH says error 0x8001), `garbage` bytes in the
//! scan, `noise` (uniformly random bytes at the line's rate, 11520 a second,
//! instead of the scan's nodes), `other` (answers as a GPS would), `silent`, and
//! unplug/plug.
#![allow(dead_code)]

use std::{
    path::Path,
    sync::atomic::{AtomicBool, Ordering},
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use super::room::{Device, Shared, read_fd, write_fd};

pub const RATE_HZ: f64 = 5.5;
pub const SAMPLES: f64 = 360.5;
pub const MAX_MM: f64 = 12_000.0;

#[derive(Clone, Copy, Debug, Default)]
pub struct Faults {
    pub health_error: bool,
    pub garbage: usize,
    pub noise: bool,
    pub other: bool,
    pub silent: bool,
}

pub struct State {
    pub scanning: bool,
    pub received: Vec<u8>,
    pub faults: Faults,
    pub revolutions: u64,
}

/// The lidar on its serial cable; plugged in again, it is not scanning.
pub type Lidar = Device<State>;

impl Lidar {
    pub fn start(link: &Path, room: Shared) -> Lidar {
        let state = State {
            scanning: false,
            received: Vec::new(),
            faults: Faults::default(),
            revolutions: 0,
        };
        Device::new(link, room, state, serve)
    }

    pub fn faults(&self, f: impl FnOnce(&mut Faults)) {
        f(&mut self.state.lock().faults);
    }

    pub fn received(&self) -> Vec<u8> {
        self.state.lock().received.clone()
    }
}

/// One node, as "Response Packets' Format" of SCAN lays it out.
pub fn node(start: bool, angle_deg: f64, mm: f64) -> [u8; 5] {
    let q = ((angle_deg * 64.0).round() as u32 % (360 * 64)) as u16;
    let d = (mm * 4.0).round().clamp(0.0, 65535.0) as u16;
    let quality: u8 = if d == 0 { 0 } else { 47 };
    let s = start as u8;
    [
        (quality << 2) | ((1 - s) << 1) | s,
        ((q << 1) as u8) | 1,
        (q >> 7) as u8,
        d as u8,
        (d >> 8) as u8,
    ]
}

fn serve(pty: super::room::Pty, state: &Mutex<State>, room: &Shared, stop: &AtomicBool) {
    state.lock().scanning = false;
    let mut buf = [0u8; 256];
    let mut pending: Vec<u8> = Vec::new();
    // The sample clock: sample k of the scan at k / (RATE_HZ · SAMPLES) s.
    let mut t0 = Instant::now();
    let mut k: u64 = 0;
    let step = 360.0 / SAMPLES;
    let mut lcg: u64 = 0x853C_49E6_748F_EA9B;
    let mut noise_sent = 0u64;
    let mut noise_from: Option<Instant> = None;
    while !stop.load(Ordering::Acquire) {
        let n = read_fd(&pty.master, Duration::from_millis(3), &mut buf).unwrap_or(0);
        let mut out: Vec<u8> = Vec::new();
        let mut st = state.lock();
        st.received.extend_from_slice(&buf[..n]);
        pending.extend_from_slice(&buf[..n]);
        loop {
            // Find a request's start flag.
            match pending.iter().position(|&b| b == 0xA5) {
                Some(i) => {
                    pending.drain(..i);
                }
                None => {
                    pending.clear();
                    break;
                }
            }
            if pending.len() < 2 {
                break;
            }
            let cmd = pending[1];
            if cmd & 0x80 != 0 {
                // Payload: size, data, checksum.
                if pending.len() < 3 || pending.len() < 4 + pending[2] as usize {
                    break;
                }
                let len = 4 + pending[2] as usize;
                pending.drain(..len);
                continue;
            }
            pending.drain(..2);
            if st.faults.other {
                out.extend_from_slice(
                    b"$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A\r\n",
                );
                continue;
            }
            if st.faults.silent {
                continue;
            }
            match cmd {
                0x25 | 0x40 => st.scanning = false,
                0x50 => {
                    out.extend([0xA5, 0x5A, 0x14, 0, 0, 0, 0x04]);
                    out.extend([0x18, 29, 1, 7]);
                    out.extend((0..16u8).map(|i| 0x10 + i));
                }
                0x52 => {
                    out.extend([0xA5, 0x5A, 0x03, 0, 0, 0, 0x06]);
                    if st.faults.health_error {
                        out.extend([2, 0x01, 0x80]);
                    } else {
                        out.extend([0, 0, 0]);
                    }
                }
                0x20 => {
                    out.extend([0xA5, 0x5A, 0x05, 0, 0, 0x40, 0x81]);
                    st.scanning = true;
                    t0 = Instant::now();
                    k = 0;
                }
                _ => {}
            }
        }
        if st.scanning && !st.faults.silent && !st.faults.other {
            let due = (t0.elapsed().as_secs_f64() * RATE_HZ * SAMPLES) as u64;
            let g = std::mem::take(&mut st.faults.garbage);
            out.extend((0..g).map(|i| (i as u8).wrapping_mul(3) & 0xFC));
            if st.faults.noise {
                // The line's rate: 115200 baud, 10 bits a byte.
                let from = *noise_from.get_or_insert_with(|| {
                    noise_sent = 0;
                    Instant::now()
                });
                let owed = (from.elapsed().as_secs_f64() * 11_520.0) as u64;
                while noise_sent < owed {
                    lcg = lcg
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    out.push((lcg >> 56) as u8);
                    noise_sent += 1;
                }
                // The scan's clock runs on underneath.
                k = due;
            } else {
                noise_from = None;
            }
            let r = room.lock().clone();
            while k < due {
                let a = (k as f64 * step) % 360.0;
                let start = k > 0 && a < step || k == 0;
                // Clockwise device angle: the room direction is θ − a.
                let dir = r.theta - a.to_radians();
                let d = r.ray(r.x, r.y, dir);
                let d = if d > MAX_MM { 0.0 } else { d };
                out.extend(node(start, a, d));
                if start {
                    st.revolutions += 1;
                }
                k += 1;
            }
        }
        drop(st);
        if !out.is_empty() {
            write_fd(&pty.master, &out);
        }
    }
}
