//! An emulator of a Sony EVI-D100 camera's VISCA interface on a pseudo-terminal,
//! written from Sony's VISCA documents (the EVI-D100/D100P technical manual's
//! command list and its "VISCA communication" section), not from the driver:
//!
//! - Packets end in `FF`; the controller sends `8x ...` to camera x (or `88` to all);
//!   the camera answers `90 ...` (camera 1).
//! - A command is acknowledged `90 4z FF` (z = the socket, 1 or 2, it runs in) and
//!   answered `90 5z FF` when it completes; with both sockets busy it is refused with
//!   `90 60 03 FF` (buffer full). An unknown message gets `90 60 02 FF` (syntax
//!   error); a command the camera cannot execute now (e.g. a move while the power
//!   is off) `90 6z 41 FF`. Inquiries (`8x 09 ...`) are answered `90 50 ... FF` at once.
//! - Address set `88 30 01 FF` → `88 30 02 FF`; IF_Clear `88 01 00 01 FF` → the same.
//! - Power `8x 01 04 00 02/03 FF`; power inquiry `8x 09 04 00 FF` → `90 50 02/03 FF`.
//! - Pan-tilt absolute `8x 01 06 02 VV WW 0Y0Y0Y0Y 0Z0Z0Z0Z FF`: VV pan speed 01..18h,
//!   WW tilt speed 01..14h; positions in 16-bit two's complement, pan F725..08DB
//!   (−100..+100°), tilt FE70..0190 (−25..+25°). Inquiry `8x 09 06 12 FF` →
//!   `90 50 0Y0Y0Y0Y 0Z0Z0Z0Z FF`.
//! - Zoom direct `8x 01 04 47 0p0q0r0s FF`, 0000 (wide) .. 4000 (optical tele) ..
//!   7000 (digital); inquiry `8x 09 04 47 FF` → `90 50 0p0q0r0s FF`.
//! - The head moves at the speed of its mode (the D100's pan speed table, deg/s);
//!   the zoom goes wide to tele in about 2 s. A new move replaces a running move
//!   (whose socket completes).
//!
//! Faults the tests inject: `silent`, `garbage` (answers in ASCII like another
//! device), `syntax` (every message is a syntax error), `full` (every command finds
//! the buffer full), and unplugging.
#![allow(dead_code)]

use std::{
    path::{Path, PathBuf},
    sync::{Arc, atomic::Ordering},
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use super::ptu::{Cable, read_fd, write_fd};

/// Pan speeds, deg/s, of modes 1..24 (EVI-D100 specification).
const SPEEDS: [f64; 24] = [
    2.0, 2.4, 3.0, 3.7, 4.7, 6.1, 7.4, 9.1, 11.0, 14.0, 18.0, 22.0, 27.0, 34.0, 42.0, 52.0, 65.0,
    81.0, 100.0, 125.0, 155.0, 190.0, 240.0, 300.0,
];
const PAN_PER_DEG: f64 = 2267.0 / 100.0;
const TILT_PER_DEG: f64 = 400.0 / 25.0;

#[derive(Clone, Copy, Debug, Default)]
pub struct Faults {
    pub silent: bool,
    pub garbage: bool,
    pub syntax: bool,
    /// Both sockets taken by something else: every command gets buffer full.
    pub full: bool,
    /// The pan-tilt inquiry answers these device units, whatever the position.
    pub pantilt: Option<(i32, i32)>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Job {
    Move,
    Zoom,
}

pub struct State {
    pub power: bool,
    pub pan: f64,
    pub tilt: f64,
    pan_target: f64,
    tilt_target: f64,
    pan_speed: f64,
    tilt_speed: f64,
    pub zoom: f64,
    zoom_target: f64,
    sockets: [Option<Job>; 2],
    pub received: Vec<u8>,
    /// When the latest bytes arrived.
    pub last_rx: Option<Instant>,
    pub faults: Faults,
    /// Bytes to write on the line once, as they are (a burst of noise).
    pub raw: Vec<u8>,
}

impl State {
    fn new() -> Self {
        State {
            power: false,
            pan: 0.0,
            tilt: 0.0,
            pan_target: 0.0,
            tilt_target: 0.0,
            pan_speed: 0.0,
            tilt_speed: 0.0,
            zoom: 0.0,
            zoom_target: 0.0,
            sockets: [None, None],
            received: Vec::new(),
            last_rx: None,
            faults: Faults::default(),
            raw: Vec::new(),
        }
    }

    fn step(&mut self, dt: f64, out: &mut Vec<u8>) {
        let go = |x: &mut f64, t: f64, v: f64| {
            let d = t - *x;
            *x = if d.abs() <= v * dt {
                t
            } else {
                *x + v * dt * d.signum()
            };
        };
        go(&mut self.pan, self.pan_target, self.pan_speed * PAN_PER_DEG);
        go(
            &mut self.tilt,
            self.tilt_target,
            self.tilt_speed * TILT_PER_DEG,
        );
        go(&mut self.zoom, self.zoom_target, 0x4000 as f64 / 2.0);
        for (i, s) in self.sockets.iter_mut().enumerate() {
            let done = match s {
                Some(Job::Move) => self.pan == self.pan_target && self.tilt == self.tilt_target,
                Some(Job::Zoom) => self.zoom == self.zoom_target,
                None => false,
            };
            if done {
                *s = None;
                out.extend_from_slice(&[0x90, 0x51 + i as u8, 0xFF]);
            }
        }
    }

    fn nib(v: f64) -> [u8; 4] {
        let u = v.round() as i32 as u16;
        [
            (u >> 12) as u8 & 15,
            (u >> 8) as u8 & 15,
            (u >> 4) as u8 & 15,
            u as u8 & 15,
        ]
    }

    fn value(n: &[u8]) -> Option<i32> {
        if n.iter().any(|&b| b > 15) {
            return None;
        }
        let u = ((n[0] as u16) << 12) | ((n[1] as u16) << 8) | ((n[2] as u16) << 4) | n[3] as u16;
        Some(u as i16 as i32)
    }

    /// Starts a job: its ACK, or buffer full. A new move replaces a running move.
    fn start(&mut self, job: Job, out: &mut Vec<u8>) -> bool {
        if let Some(i) = self.sockets.iter().position(|s| *s == Some(job)) {
            self.sockets[i] = None;
            out.extend_from_slice(&[0x90, 0x51 + i as u8, 0xFF]);
        }
        match self.sockets.iter().position(|s| s.is_none()) {
            Some(i) => {
                self.sockets[i] = Some(job);
                out.extend_from_slice(&[0x90, 0x41 + i as u8, 0xFF]);
                true
            }
            None => {
                out.extend_from_slice(&[0x90, 0x60, 0x03, 0xFF]);
                false
            }
        }
    }

    fn immediate(&mut self, out: &mut Vec<u8>) {
        out.extend_from_slice(&[0x90, 0x41, 0xFF, 0x90, 0x51, 0xFF]);
    }

    fn handle(&mut self, p: &[u8], out: &mut Vec<u8>) {
        let syntax = [0x90, 0x60, 0x02, 0xFF];
        if self.faults.syntax {
            out.extend_from_slice(&syntax);
            return;
        }
        if self.faults.full && p.len() > 2 && p[0] == 0x81 && p[1] == 0x01 {
            out.extend_from_slice(&[0x90, 0x60, 0x03, 0xFF]);
            return;
        }
        match p {
            [0x88, 0x30, 0x01, 0xFF] => out.extend_from_slice(&[0x88, 0x30, 0x02, 0xFF]),
            [0x88, 0x01, 0x00, 0x01, 0xFF] => out.extend_from_slice(p),
            [0x81, 0x01, 0x04, 0x00, on @ (0x02 | 0x03), 0xFF] => {
                self.power = *on == 0x02;
                self.immediate(out);
            }
            [0x81, 0x09, 0x04, 0x00, 0xFF] => {
                out.extend_from_slice(&[0x90, 0x50, if self.power { 0x02 } else { 0x03 }, 0xFF])
            }
            [0x81, 0x09, 0x06, 0x12, 0xFF] => {
                let (pan, tilt) = match self.faults.pantilt {
                    Some((p, t)) => (p as f64, t as f64),
                    None => (self.pan, self.tilt),
                };
                out.extend_from_slice(&[0x90, 0x50]);
                out.extend_from_slice(&Self::nib(pan));
                out.extend_from_slice(&Self::nib(tilt));
                out.push(0xFF);
            }
            [0x81, 0x09, 0x04, 0x47, 0xFF] => {
                out.extend_from_slice(&[0x90, 0x50]);
                out.extend_from_slice(&Self::nib(self.zoom));
                out.push(0xFF);
            }
            [0x81, 0x01, 0x06, 0x02, vv, ww, rest @ .., 0xFF] if rest.len() == 8 => {
                let (Some(pan), Some(tilt)) = (Self::value(&rest[..4]), Self::value(&rest[4..]))
                else {
                    out.extend_from_slice(&syntax);
                    return;
                };
                if !(1..=0x18).contains(vv)
                    || !(1..=0x14).contains(ww)
                    || !(-2267..=2267).contains(&pan)
                    || !(-400..=400).contains(&tilt)
                {
                    out.extend_from_slice(&syntax);
                    return;
                }
                if !self.power {
                    out.extend_from_slice(&[0x90, 0x61, 0x41, 0xFF]);
                    return;
                }
                if self.start(Job::Move, out) {
                    self.pan_target = pan as f64;
                    self.tilt_target = tilt as f64;
                    self.pan_speed = SPEEDS[*vv as usize - 1];
                    self.tilt_speed = SPEEDS[*ww as usize - 1];
                }
            }
            [0x81, 0x01, 0x04, 0x47, rest @ .., 0xFF] if rest.len() == 4 => {
                let Some(z) = Self::value(rest).filter(|z| (0..=0x7000).contains(z)) else {
                    out.extend_from_slice(&syntax);
                    return;
                };
                if !self.power {
                    out.extend_from_slice(&[0x90, 0x61, 0x41, 0xFF]);
                    return;
                }
                if self.start(Job::Zoom, out) {
                    self.zoom_target = z as f64;
                }
            }
            _ => out.extend_from_slice(&syntax),
        }
    }
}

/// A running emulated camera at a path (a symlink to its pty).
pub struct Evi {
    pub link: PathBuf,
    pub state: Arc<Mutex<State>>,
    _cable: Cable,
}

impl Evi {
    /// Plugs a camera in at `link`; it starts with the power off (standby).
    pub fn start(link: &Path) -> Evi {
        let state = Arc::new(Mutex::new(State::new()));
        let st = state.clone();
        let cable = Cable::plug(link, move |pty, sp| {
            let mut packet = Vec::new();
            let mut buf = [0u8; 256];
            let mut last = Instant::now();
            while !sp.load(Ordering::Acquire) {
                let n = read_fd(&pty.master, Duration::from_millis(5), &mut buf).unwrap_or(0);
                let mut out = Vec::new();
                let mut s = st.lock();
                let now = Instant::now();
                s.step(now.duration_since(last).as_secs_f64(), &mut out);
                last = now;
                s.received.extend_from_slice(&buf[..n]);
                if n > 0 {
                    s.last_rx = Some(Instant::now());
                }
                for &b in &buf[..n] {
                    packet.push(b);
                    if b == 0xFF {
                        let f = s.faults;
                        if f.garbage {
                            out.extend_from_slice(b"OK\r\n");
                        } else if !f.silent {
                            let p = std::mem::take(&mut packet);
                            s.handle(&p, &mut out);
                        }
                        packet.clear();
                    } else if packet.len() > 16 {
                        packet.clear();
                        out.extend_from_slice(&[0x90, 0x60, 0x01, 0xFF]);
                    }
                }
                if s.faults.silent {
                    out.clear();
                }
                out.append(&mut s.raw);
                drop(s);
                if !out.is_empty() {
                    write_fd(&pty.master, &out);
                }
            }
        });
        Evi {
            link: link.to_path_buf(),
            state,
            _cable: cable,
        }
    }

    pub fn received(&self) -> Vec<u8> {
        self.state.lock().received.clone()
    }
    pub fn clear_received(&self) {
        self.state.lock().received.clear();
    }
    pub fn set_faults(&self, f: Faults) {
        self.state.lock().faults = f;
    }
    /// Pan, tilt, zoom in device units.
    pub fn position(&self) -> (i32, i32, i32) {
        let s = self.state.lock();
        (
            s.pan.round() as i32,
            s.tilt.round() as i32,
            s.zoom.round() as i32,
        )
    }
    pub fn power(&self) -> bool {
        self.state.lock().power
    }
    /// Switches the camera's power (as its remote would).
    pub fn set_power(&self, on: bool) {
        self.state.lock().power = on;
    }
    /// The camera goes away: its pty closes and its path disappears.
    pub fn unplug(self) {}
}
