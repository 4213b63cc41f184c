//! The board: the memory a python schema shares with its program's worker
//! process. jderobot writes the sensors on it as they are published; the worker
//! reads them with no system call (a HAL call costs what it cost in one
//! process); the worker writes the signs of life jderobot's keeper watches.
//!
//! One `memfd` mapped by both processes: a [`Header`] of atomics, then one
//! [`Slot`] per sensor. A slot is a sequence lock: the writer (jderobot's keeper,
//! the only one) makes its sequence odd, writes, makes it even; a reader copies
//! and retries if the sequence moved meanwhile. Neither ever waits for the
//! other, so a worker that dies (or is stopped) holding nothing can't block
//! jderobot, and jderobot never trusts what the worker writes beyond the header's
//! counters.

use std::{
    io,
    os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd},
    ptr::NonNull,
    sync::atomic::{AtomicU32, AtomicU64, Ordering, fence},
};

/// The signs of life and the small values both sides read and write.
#[repr(C)]
pub struct Header {
    magic: AtomicU64,
    /// Worker: HAL, GUI and Frequency calls so far (each shows it is alive).
    pub calls: AtomicU64,
    /// Worker: 1 while the program waits in `time.sleep` or `Frequency.tick`.
    pub sleeping: AtomicU32,
    /// jderobot: 1 while the silence limit holds the motors stopped (the
    /// worker's next setV/setW is sent even if it repeats the last one).
    pub silenced: AtomicU32,
    /// Worker: `Frequency.tick` calls and the loop's rate it measured (Hz, f64 bits).
    pub ticks: AtomicU64,
    pub tick_rate: AtomicU64,
    /// jderobot: the run's clock, ns since the Unix epoch (0: none, the wall clock's).
    pub sim_clock: AtomicU64,
}

/// One sensor's latest value, under a sequence lock.
#[repr(C)]
struct SlotHeader {
    seq: AtomicU64,
    /// The interface's clock of the value (0: none yet).
    clock: AtomicU64,
    /// When it was published, ns since the Unix epoch.
    time: AtomicU64,
    len: AtomicU64,
}

/// The sensors, in the order of the board's slots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    Encoders = 0,
    Laser = 1,
    Bumpers = 2,
    Camera = 3,
}

/// Each slot's room for the value's bytes: the encoders' 5 floats, 16,384 laser
/// readings, 256 bumpers, a 4K BGR image.
const CAPACITY: [usize; 4] = [64, 32 + 4 * 16_384, 256, 8 + 3840 * 2160 * 3];

const MAGIC: u64 = 0x6a64_6572_6f62_7031; // "jderobp1"

fn align(n: usize) -> usize {
    n.next_multiple_of(64)
}

fn slot_offset(s: Sensor) -> usize {
    let mut at = align(size_of::<Header>());
    for c in &CAPACITY[..s as usize] {
        at += align(size_of::<SlotHeader>() + c);
    }
    at
}

fn board_len() -> usize {
    slot_offset(Sensor::Camera) + align(size_of::<SlotHeader>() + CAPACITY[3])
}

/// A mapped board (either side).
pub struct Board {
    base: NonNull<u8>,
    len: usize,
    fd: OwnedFd,
}

// SAFETY: the mapping lives as long as the Board; every shared field is an
// atomic or read under a slot's sequence lock.
unsafe impl Send for Board {}
unsafe impl Sync for Board {}

impl Board {
    /// jderobot's side: a new board (its pages are taken only as they are written).
    pub fn create() -> io::Result<Board> {
        // SAFETY: a plain system call; the name is a C string.
        let fd = unsafe { libc::memfd_create(c"jderobot-python".as_ptr(), libc::MFD_CLOEXEC) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: memfd_create gave us this descriptor.
        let fd = unsafe { OwnedFd::from_raw_fd(fd) };
        // SAFETY: resizes the file we own.
        if unsafe { libc::ftruncate(fd.as_raw_fd(), board_len() as libc::off_t) } != 0 {
            return Err(io::Error::last_os_error());
        }
        let b = Board::map(fd)?;
        b.header().magic.store(MAGIC, Ordering::Release);
        Ok(b)
    }

    /// The worker's side: the board jderobot handed over as descriptor `fd`.
    pub fn open(fd: RawFd) -> io::Result<Board> {
        // SAFETY: the descriptor was passed to this process for this use.
        let b = Board::map(unsafe { OwnedFd::from_raw_fd(fd) })?;
        if b.header().magic.load(Ordering::Acquire) != MAGIC {
            return Err(io::Error::other("descriptor 3 is not a jderobot board"));
        }
        Ok(b)
    }

    fn map(fd: OwnedFd) -> io::Result<Board> {
        let len = board_len();
        // SAFETY: maps the whole file, shared, readable and writable.
        let p = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                fd.as_raw_fd(),
                0,
            )
        };
        if p == libc::MAP_FAILED {
            return Err(io::Error::last_os_error());
        }
        Ok(Board {
            base: NonNull::new(p.cast()).expect("mmap gave a non-null address"),
            len,
            fd,
        })
    }

    /// The descriptor, to hand to the worker.
    pub fn fd(&self) -> RawFd {
        self.fd.as_raw_fd()
    }

    pub fn header(&self) -> &Header {
        // SAFETY: the header is at the start of the mapping, which is aligned.
        unsafe { &*self.base.as_ptr().cast::<Header>() }
    }

    fn slot(&self, s: Sensor) -> (&SlotHeader, *mut u8) {
        let at = slot_offset(s);
        // SAFETY: offsets inside the mapping, 64-byte aligned.
        unsafe {
            let h = self.base.as_ptr().add(at);
            (&*h.cast::<SlotHeader>(), h.add(size_of::<SlotHeader>()))
        }
    }

    /// Writes a sensor's value (jderobot's keeper only); a value too big for
    /// its slot is cut to it (the caps are beyond any interface's).
    pub fn write(&self, s: Sensor, clock: u64, time_ns: u64, parts: &[&[u8]]) {
        let (h, data) = self.slot(s);
        let seq = h.seq.load(Ordering::Relaxed);
        h.seq.store(seq + 1, Ordering::Relaxed);
        fence(Ordering::Release);
        let mut at = 0;
        for p in parts {
            let n = p.len().min(CAPACITY[s as usize] - at);
            // SAFETY: inside the slot; readers detect the overlap by the sequence.
            unsafe { std::ptr::copy_nonoverlapping(p.as_ptr(), data.add(at), n) };
            at += n;
        }
        h.len.store(at as u64, Ordering::Relaxed);
        h.clock.store(clock, Ordering::Relaxed);
        h.time.store(time_ns, Ordering::Relaxed);
        h.seq.store(seq + 2, Ordering::Release);
    }

    /// The clock of a sensor's latest value (0: none yet).
    pub fn clock(&self, s: Sensor) -> u64 {
        self.slot(s).0.clock.load(Ordering::Acquire)
    }

    /// Hands a sensor's latest value to `take` (which copies what it needs),
    /// again if it was being written meanwhile; returns its (clock, time ns) and
    /// what `take` gave, None before the first value.
    pub fn read<R>(&self, s: Sensor, mut take: impl FnMut(&[u8]) -> R) -> Option<(u64, u64, R)> {
        let (h, data) = self.slot(s);
        loop {
            let seq = h.seq.load(Ordering::Acquire);
            if seq & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let clock = h.clock.load(Ordering::Relaxed);
            if clock == 0 {
                return None;
            }
            let len = (h.len.load(Ordering::Relaxed) as usize).min(CAPACITY[s as usize]);
            let time = h.time.load(Ordering::Relaxed);
            // SAFETY: inside the slot. The bytes may change under `take` (the
            // sequence lock's race); a concurrent write is detected below and
            // what `take` made is thrown away.
            let r = take(unsafe { std::slice::from_raw_parts(data, len) });
            fence(Ordering::Acquire);
            if h.seq.load(Ordering::Relaxed) == seq {
                return Some((clock, time, r));
            }
        }
    }
}

impl Drop for Board {
    fn drop(&mut self) {
        // SAFETY: unmaps what map mapped.
        unsafe { libc::munmap(self.base.as_ptr().cast(), self.len) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_written_is_read_back_on_a_second_mapping() {
        let a = Board::create().unwrap();
        // SAFETY: a second descriptor of the same memfd, as the worker gets it.
        let b = Board::open(unsafe { libc::dup(a.fd()) }).unwrap();
        assert!(b.read(Sensor::Laser, <[u8]>::to_vec).is_none());
        a.write(Sensor::Laser, 7, 42, &[&[1, 2, 3], &[4]]);
        assert_eq!(
            b.read(Sensor::Laser, <[u8]>::to_vec),
            Some((7, 42, vec![1, 2, 3, 4]))
        );
        a.header().calls.store(5, Ordering::Release);
        assert_eq!(b.header().calls.load(Ordering::Acquire), 5);
    }
}

/// The sensors' values on the board: how jderobot writes each and the worker
/// reads it back (little-endian floats; the interfaces' own units).
pub mod values {
    use super::{Board, Sensor};
    use crate::interfaces::{Encoders, Image, Laser, Mount};
    use std::time::{Duration, SystemTime, UNIX_EPOCH};

    fn ns(t: SystemTime) -> u64 {
        t.duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64)
    }

    /// A time on the board as a [`SystemTime`].
    pub fn time(ns: u64) -> SystemTime {
        UNIX_EPOCH + Duration::from_nanos(ns)
    }

    fn floats<const N: usize>(b: &[u8]) -> [f32; N] {
        std::array::from_fn(|i| {
            b.get(4 * i..4 * i + 4)
                .map_or(0.0, |x| f32::from_le_bytes(x.try_into().expect("4 bytes")))
        })
    }

    fn bytes_of(fs: &[f32]) -> Vec<u8> {
        fs.iter().flat_map(|f| f.to_le_bytes()).collect()
    }

    pub fn put_encoders(b: &Board, clock: u64, t: SystemTime, e: &Encoders) {
        b.write(
            Sensor::Encoders,
            clock,
            ns(t),
            &[&bytes_of(&[e.x, e.y, e.theta, e.cos, e.sin])],
        );
    }

    pub fn encoders(b: &Board) -> Option<(Encoders, SystemTime)> {
        let (_, t, [x, y, theta, cos, sin]) = b.read(Sensor::Encoders, floats::<5>)?;
        Some((
            Encoders {
                x,
                y,
                theta,
                cos,
                sin,
            },
            time(t),
        ))
    }

    pub fn put_laser(b: &Board, clock: u64, t: SystemTime, l: &Laser) {
        let head = bytes_of(&[
            l.resolution,
            l.start,
            l.min_range,
            l.max_range,
            l.mount.x,
            l.mount.y,
            l.mount.yaw,
        ]);
        let readings: Vec<u8> = l.readings.iter().flat_map(|r| r.to_le_bytes()).collect();
        b.write(Sensor::Laser, clock, ns(t), &[&head, &readings]);
    }

    pub fn laser(b: &Board) -> Option<(Laser, SystemTime)> {
        let (_, t, l) = b.read(Sensor::Laser, |bytes| {
            let [resolution, start, min_range, max_range, x, y, yaw] = floats::<7>(bytes);
            let readings = bytes
                .get(28..)
                .unwrap_or_default()
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect();
            Laser {
                readings,
                resolution,
                start,
                min_range,
                max_range,
                mount: Mount { x, y, yaw },
            }
        })?;
        Some((l, time(t)))
    }

    pub fn put_bumpers(b: &Board, clock: u64, t: SystemTime, bumpers: &[u8]) {
        b.write(Sensor::Bumpers, clock, ns(t), &[bumpers]);
    }

    pub fn bumpers(b: &Board) -> Option<Vec<u8>> {
        b.read(Sensor::Bumpers, <[u8]>::to_vec).map(|(_, _, v)| v)
    }

    pub fn put_image(b: &Board, clock: u64, t: SystemTime, img: &Image) {
        let mut head = [0u8; 8];
        head[..4].copy_from_slice(&img.width.to_le_bytes());
        head[4..].copy_from_slice(&img.height.to_le_bytes());
        b.write(Sensor::Camera, clock, ns(t), &[&head, &img.data]);
    }

    /// The camera's image as `make(width, height, BGR bytes)` makes it (one copy,
    /// `make`'s own).
    pub fn image<R>(b: &Board, mut make: impl FnMut(u32, u32, &[u8]) -> R) -> Option<R> {
        b.read(Sensor::Camera, |bytes| {
            let [w, h] = [0, 4].map(|i| {
                bytes
                    .get(i..i + 4)
                    .map_or(0, |x| u32::from_le_bytes(x.try_into().expect("4 bytes")))
            });
            let pixels = bytes.get(8..).unwrap_or_default();
            let n = (w as usize * h as usize * 3).min(pixels.len());
            make(w, h, &pixels[..n])
        })
        .map(|(_, _, r)| r)
    }
}
