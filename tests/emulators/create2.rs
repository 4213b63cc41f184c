//! An emulator of an iRobot Create 2 on a pseudo-terminal, written from iRobot's
//! *Create 2 Open Interface (OI) Specification based on the iRobot Roomba 600*
//! (not from the driver):
//!
//! - "Serial Port Settings": 115200 baud, 8N1 (a pty has no baud rate).
//! - "Modes" and "Open Interface Command Reference": Start (128) → Passive; Safe
//!   (131), Full (132); Stop (173) → Off, streams stop; Reset (7). Actuator commands
//!   such as Drive Direct (145: right velocity, left velocity, signed 16-bit high
//!   byte first, −500..500 mm/s) are obeyed only in Safe and Full mode.
//! - "Stream" (148): `148 N id1 .. idN`; the robot then sends every 15 ms
//!   `19 n [id data]... checksum`, n the number of bytes between n and the checksum,
//!   the checksum making the 8-bit sum of every byte of the frame 0. Pause/Resume
//!   Stream (150): 0 pauses, 1 resumes.
//! - "Sensor Packets": sizes from the packet table; 7 bumps and wheel drops (bit 0
//!   bump right, 1 bump left, 2 wheel drop right, 3 wheel drop left); 21 charging
//!   state; 22 voltage mV; 23 current mA (signed); 25 charge, 26 capacity mAh; 35 OI
//!   mode (0 Off, 1 Passive, 2 Safe, 3 Full); 43/44 left/right encoder counts (16-bit,
//!   rolling over; 508.8 counts per revolution of a 72 mm wheel); 45 light bumper
//!   bits; 46..51 light bump signals 0..4095 (left, front left, centre left, centre
//!   right, front right, right).
//! - The robot: wheel base 235 mm, a 348 mm disc in the shared room
//!   (tests/emulators/room.rs); it stops at a wall with its bumper pressed (the side
//!   the wall touches), its wheels stalled.
//!
//! - Drive (137): velocity (−500..500 mm/s) and radius (−2000..2000 mm, 32768 or
//!   32767 straight, −1 and 1 turning in place), both signed 16-bit high byte first;
//!   velocity 0 stops the robot. Obeyed in Safe and Full mode like Drive Direct.
//!
//! Every command is logged with the time it arrived (`commands`), for the tests
//! that measure how soon a stop comes.
//!
//! Faults the tests inject: `garbage` bytes, a `bad_checksum` frame, a `half`
//! frame, `jump` (the encoder counters jump by 5000, as after a reset), `silent`
//! (no stream), `other` (a GPS's NMEA text instead), `noise`
//! (uniformly random bytes at the line's rate instead of frames), and `unplug`
//! (the pty closes and its path disappears; `plug` brings it back, same room).
#![allow(dead_code)]

use std::{
    path::Path,
    sync::atomic::{AtomicBool, Ordering},
    time::{Duration, Instant},
};

use parking_lot::Mutex;

use super::room::{Device, ROBOT_RADIUS, Shared, read_fd, wrap, write_fd};

pub const WHEEL_BASE: f64 = 235.0;
pub const COUNTS_PER_MM: f64 = 508.8 / (std::f64::consts::PI * 72.0);

/// The data size of sensor packet `id` (the specification's packet table).
pub fn packet_size(id: u8) -> Option<usize> {
    Some(match id {
        7..=18 => 1,
        19 | 20 => 2,
        21 => 1,
        22 | 23 => 2,
        24 => 1,
        25..=31 => 2,
        32 => 1,
        33 => 2,
        34..=38 => 1,
        39..=44 => 2,
        45 => 1,
        46..=51 => 2,
        52 | 53 => 1,
        54..=57 => 2,
        58 => 1,
        _ => return None,
    })
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Faults {
    pub silent: bool,
    pub other: bool,
    /// Bytes of garbage to send instead of the next frame.
    pub garbage: usize,
    /// The next frame's checksum is wrong.
    pub bad_checksum: bool,
    /// The next frame is cut in half.
    pub half: bool,
    /// Uniformly random bytes instead of frames, as many as 115200 baud carries.
    pub noise: bool,
    /// The encoder counters jump by 5000 (as after a reset), once.
    pub jump: bool,
}

pub struct State {
    pub mode: u8,
    /// Wheel velocities (right, left), mm/s.
    pub wheels: (i16, i16),
    pub stream: Vec<u8>,
    pub streaming: bool,
    /// Encoder counts (left, right), before the 16-bit roll-over.
    pub counts: (f64, f64),
    pub bump: (bool, bool),
    pub received: Vec<u8>,
    pub faults: Faults,
    pub frames: u64,
    /// When each Drive Direct was applied (for the latency benchmark).
    pub last_drive: Option<(Instant, (i16, i16))>,
    /// Every command received, with the time it arrived.
    pub commands: Vec<(Instant, Vec<u8>)>,
    /// When the last good frame was sent.
    pub last_frame_at: Option<Instant>,
}

/// The robot on its serial cable.
pub type Create2 = Device<State>;

impl Create2 {
    /// The robot on a pty reached through `link` (a symlink), in `room`. Its
    /// encoders start near the 16-bit roll-over, so the driver meets it. When
    /// plugged in again it keeps its state (and, as a real one, its last Drive
    /// Direct).
    pub fn start(link: &Path, room: Shared) -> Create2 {
        let state = State {
            mode: 0,
            wheels: (0, 0),
            stream: Vec::new(),
            streaming: false,
            counts: (65_000.0, 64_800.0),
            bump: (false, false),
            received: Vec::new(),
            faults: Faults::default(),
            frames: 0,
            last_drive: None,
            commands: Vec::new(),
            last_frame_at: None,
        };
        Device::new(link, room, state, serve)
    }

    pub fn faults(&self, f: impl FnOnce(&mut Faults)) {
        f(&mut self.state.lock().faults);
    }

    pub fn received(&self) -> Vec<u8> {
        self.state.lock().received.clone()
    }

    /// When the first stop (Drive Direct 0 0, or Drive with velocity 0) arrived
    /// after `t`, if one did.
    pub fn stop_after(&self, t: Instant) -> Option<Instant> {
        self.state
            .lock()
            .commands
            .iter()
            .find(|(at, c)| *at >= t && is_stop(c))
            .map(|(at, _)| *at)
    }
}

/// Drive Direct with both wheels 0, or Drive with velocity 0.
pub fn is_stop(cmd: &[u8]) -> bool {
    matches!(cmd, [145, 0, 0, 0, 0] | [137, 0, 0, _, _])
}

/// Bytes of each command after its opcode (the command reference).
fn data_len(op: u8, next: Option<u8>) -> Option<usize> {
    Some(match op {
        128 | 131 | 132 | 173 | 7 | 133 | 134 | 135 | 136 | 143 => 0,
        129 | 150 => 1,
        137 | 145 | 146 => 4,
        139 => 3,
        138 => 1,
        144 => 3,
        142 => 1,
        148 | 149 => return next.map(|n| 1 + n as usize),
        _ => 0,
    })
}

fn apply(st: &mut State, cmd: &[u8]) {
    match cmd[0] {
        128 => st.mode = 1,
        131 => st.mode = 2,
        132 => st.mode = 3,
        173 => {
            st.mode = 0;
            st.streaming = false;
            st.wheels = (0, 0);
        }
        7 => {
            st.mode = 0;
            st.streaming = false;
            st.wheels = (0, 0);
        }
        137 if st.mode >= 2 => {
            let v = i16::from_be_bytes([cmd[1], cmd[2]]).clamp(-500, 500) as f64;
            let r = i16::from_be_bytes([cmd[3], cmd[4]]);
            let w = match r {
                -32768 | 32767 => 0.0,
                -1 => -2.0 * v.abs() / WHEEL_BASE,
                1 => 2.0 * v.abs() / WHEEL_BASE,
                r => v / r.clamp(-2000, 2000) as f64,
            };
            let half = w * WHEEL_BASE / 2.0;
            let (r, l) = ((v + half).round() as i16, (v - half).round() as i16);
            st.wheels = (r, l);
            st.last_drive = Some((Instant::now(), (r, l)));
        }
        145 if st.mode >= 2 => {
            let r = i16::from_be_bytes([cmd[1], cmd[2]]).clamp(-500, 500);
            let l = i16::from_be_bytes([cmd[3], cmd[4]]).clamp(-500, 500);
            st.wheels = (r, l);
            st.last_drive = Some((Instant::now(), (r, l)));
        }
        148 => {
            st.stream = cmd[2..].to_vec();
            st.streaming = true;
        }
        150 => st.streaming = cmd[1] == 1,
        _ => {}
    }
    // Passive mode: the wheels do not obey (a robot left in Passive stops).
    if st.mode < 2 {
        st.wheels = (0, 0);
    }
}

fn physics(st: &mut State, room: &Shared, dt: f64) {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (vr, vl) = (st.wheels.0 as f64, st.wheels.1 as f64);
    let mut r = room.lock();
    let v = (vr + vl) / 2.0;
    let w = (vr - vl) / WHEEL_BASE;
    let th = r.theta + w * dt / 2.0;
    let (nx, ny) = (r.x + v * dt * th.cos(), r.y + v * dt * th.sin());
    // Moving into a wall: the robot stops there, its wheels stalled.
    let dir = if v >= 0.0 { th } else { th + PI };
    let blocked = v != 0.0
        && r.contacts(nx, ny, 0.0)
            .into_iter()
            .any(|c| wrap(c - dir).abs() < FRAC_PI_2);
    if blocked {
        r.touched = true;
        // Turning in place still turns the wheels.
        let spin = (vr - vl) / 2.0;
        st.counts.0 -= spin * dt * COUNTS_PER_MM;
        st.counts.1 += spin * dt * COUNTS_PER_MM;
    } else {
        r.x = nx;
        r.y = ny;
        st.counts.0 += vl * dt * COUNTS_PER_MM;
        st.counts.1 += vr * dt * COUNTS_PER_MM;
    }
    r.theta = wrap(r.theta + w * dt);
    // The bumper is the front half: a wall within 5 mm of it presses it, on the
    // side the wall is (both near the centre).
    let front: Vec<f64> = r
        .contacts(r.x, r.y, 5.0)
        .into_iter()
        .map(|c| wrap(c - r.theta))
        .filter(|a| a.abs() < FRAC_PI_2)
        .collect();
    st.bump = (
        front.iter().any(|a| *a < 0.35),
        front.iter().any(|a| *a > -0.35),
    );
}

fn light(room: &Shared, i: usize) -> u16 {
    // Sensors at ±72°, ±43°, ±12° of the front (left to right), ~15 cm reach.
    let dirs = [72.0f64, 43.0, 12.0, -12.0, -43.0, -72.0];
    let r = room.lock();
    let a = r.theta + dirs[i].to_radians();
    let d = r.ray(r.x, r.y, a) - ROBOT_RADIUS;
    if d >= 150.0 {
        0
    } else {
        (4095.0 * (1.0 - d.max(0.0) / 150.0)) as u16
    }
}

fn frame(st: &State, room: &Shared) -> Vec<u8> {
    let mut f = vec![19u8, 0];
    for &id in &st.stream {
        let Some(size) = packet_size(id) else {
            continue;
        };
        f.push(id);
        let v: u16 = match id {
            7 => st.bump.0 as u16 | (st.bump.1 as u16) << 1,
            21 => 0,
            22 => 15_800,
            23 => (-310i16) as u16,
            25 => 2_100,
            26 => 2_696,
            35 => st.mode as u16,
            43 => (st.counts.0.floor() as i64).rem_euclid(65_536) as u16,
            44 => (st.counts.1.floor() as i64).rem_euclid(65_536) as u16,
            45 => (0..6).fold(0, |b, i| b | ((light(room, i) > 100) as u16) << i),
            46..=51 => light(room, (id - 46) as usize),
            _ => 0,
        };
        if size == 1 {
            f.push(v as u8);
        } else {
            f.extend(v.to_be_bytes());
        }
    }
    f[1] = (f.len() - 2) as u8;
    let sum = f.iter().fold(0u8, |a, &b| a.wrapping_add(b));
    f.push(0u8.wrapping_sub(sum));
    f
}

fn serve(pty: super::room::Pty, state: &Mutex<State>, room: &Shared, stop: &AtomicBool) {
    let mut buf = [0u8; 256];
    let mut pending: Vec<u8> = Vec::new();
    let mut last = Instant::now();
    let mut next_frame = Instant::now();
    let mut lcg: u64 = 0x2545_F491_4F6C_DD1D;
    while !stop.load(Ordering::Acquire) {
        let n = read_fd(&pty.master, Duration::from_millis(2), &mut buf).unwrap_or(0);
        let arrived = Instant::now();
        let mut out = Vec::new();
        {
            let mut st = state.lock();
            st.received.extend_from_slice(&buf[..n]);
            pending.extend_from_slice(&buf[..n]);
            while let Some(&op) = pending.first() {
                let Some(len) = data_len(op, pending.get(1).copied()) else {
                    break;
                };
                if pending.len() < 1 + len {
                    break;
                }
                let cmd: Vec<u8> = pending.drain(..1 + len).collect();
                apply(&mut st, &cmd);
                st.commands.push((arrived, cmd));
            }
            let now = Instant::now();
            physics(&mut st, room, now.duration_since(last).as_secs_f64());
            last = now;
            if now >= next_frame {
                next_frame += Duration::from_millis(15);
                if next_frame < now {
                    next_frame = now + Duration::from_millis(15);
                }
                if std::mem::take(&mut st.faults.jump) {
                    st.counts.0 += 5000.0;
                    st.counts.1 += 5000.0;
                }
                let f = &mut st.faults;
                if f.noise {
                    // 15 ms of the line: 173 bytes at 115200 baud.
                    out.extend((0..173).map(|_| {
                        lcg = lcg
                            .wrapping_mul(6_364_136_223_846_793_005)
                            .wrapping_add(1_442_695_040_888_963_407);
                        (lcg >> 56) as u8
                    }));
                } else if f.other {
                    out.extend_from_slice(
                        b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n",
                    );
                } else if st.faults.garbage > 0 {
                    let g = std::mem::take(&mut st.faults.garbage);
                    out.extend((0..g).map(|i| (i * 37 + 5) as u8 | 0x80));
                } else if st.streaming && !st.faults.silent {
                    let mut fr = frame(&st, room);
                    let damaged = st.faults.bad_checksum || st.faults.half;
                    if std::mem::take(&mut st.faults.bad_checksum) {
                        *fr.last_mut().unwrap() ^= 0x5A;
                    }
                    if std::mem::take(&mut st.faults.half) {
                        fr.truncate(fr.len() / 2);
                    }
                    out.extend(fr);
                    st.frames += 1;
                    if !damaged {
                        st.last_frame_at = Some(now);
                    }
                }
            }
        }
        if !out.is_empty() {
            write_fd(&pty.master, &out);
        }
    }
}
