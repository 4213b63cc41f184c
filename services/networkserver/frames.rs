//! Image frames: a frame is written with one `writev` straight from the
//! interface's shared sample (the header from a small buffer, the pixels from the
//! sample: no copy), and a client's thread that waits for a frame is woken by the
//! image's publish ([`FrameWake`] rings its [`Bell`]).

use std::{
    io::{self, Write},
    net::TcpStream,
    os::fd::{AsRawFd, FromRawFd, OwnedFd, RawFd},
    sync::{
        Weak,
        atomic::{Ordering, fence},
    },
    time::{Duration, Instant},
};

use crate::{
    interfaces::{Image, Interface, Notify},
    netwire,
};

use super::serve::Client;

/// Sends the latest frame of `iface` as image `netid` (`1020` header and pixels)
/// within `timeout` (see [`write_all_within`]) and records its clock in `last`.
/// `out` is scratch space for the header.
pub(super) fn send(
    w: &TcpStream,
    timeout: Duration,
    out: &mut Vec<u8>,
    netid: u32,
    iface: &Interface<Image>,
    last: &mut u64,
) -> io::Result<()> {
    let s = iface.snapshot();
    *last = s.clock;
    out.clear();
    netwire::write_image_header(out, s.clock, netid, s.width, s.height);
    write_all_within(w, &[out.as_slice(), &s.data], timeout)
}

/// Writes every slice (one `writev` when the socket takes it all) within
/// `timeout` in all, the socket's write timeout (set when the client came). The
/// kernel's timeout counts one call, and a client that reads a trickle lets each
/// call write a little: after a partial write the socket's timeout becomes what
/// is left (and `timeout` again at the end), so such a client is dropped like one
/// that reads nothing. A frame written whole costs no extra syscall.
pub(super) fn write_all_within(
    mut w: &TcpStream,
    parts: &[&[u8]],
    timeout: Duration,
) -> io::Result<()> {
    let deadline = Instant::now() + timeout;
    let mut slices: Vec<io::IoSlice<'_>> = parts.iter().map(|p| io::IoSlice::new(p)).collect();
    let mut bufs = &mut slices[..];
    let mut shortened = false;
    let written = loop {
        if bufs.is_empty() {
            break Ok(());
        }
        match w.write_vectored(bufs) {
            Ok(0) => {
                break Err(io::Error::new(
                    io::ErrorKind::WriteZero,
                    "the connection took no more bytes",
                ));
            }
            Ok(n) => {
                io::IoSlice::advance_slices(&mut bufs, n);
                if bufs.is_empty() {
                    continue;
                }
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    break Err(io::ErrorKind::TimedOut.into());
                }
                if let Err(e) = w.set_write_timeout(Some(left)) {
                    break Err(e);
                }
                shortened = true;
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => break Err(e),
        }
    };
    if shortened {
        let _ = w.set_write_timeout(Some(timeout));
    }
    written
}

/// Wakes a client's thread when a served image has a new frame, if it sleeps
/// waiting for one (instead of polling for it; a busy thread costs the camera's
/// thread one atomic load).
pub(super) struct FrameWake(pub(super) Weak<Client>);

impl Notify for FrameWake {
    fn notify(&self) {
        fence(Ordering::SeqCst);
        if let Some(cl) = self.0.upgrade()
            && cl.waiting_frame.load(Ordering::Relaxed)
        {
            cl.bell.ring();
        }
    }
}

/// An eventfd that another thread rings and a client's thread waits on beside
/// its socket, in one `ppoll(2)`. A ring stays until [`Bell::clear`], so one that
/// comes just before the wait is not lost.
pub(super) struct Bell(OwnedFd);

impl Bell {
    pub(super) fn new() -> io::Result<Bell> {
        // SAFETY: eventfd takes no pointers; a descriptor it returns is ours.
        let fd = unsafe { libc::eventfd(0, libc::EFD_CLOEXEC | libc::EFD_NONBLOCK) };
        if fd < 0 {
            return Err(io::Error::last_os_error());
        }
        // SAFETY: `fd` is a new descriptor that nothing else owns.
        Ok(Bell(unsafe { OwnedFd::from_raw_fd(fd) }))
    }

    pub(super) fn ring(&self) {
        let one = 1u64;
        // SAFETY: writes 8 bytes from a live u64. It can fail only when the
        // counter is full, which 2^64 rings never reach.
        unsafe { libc::write(self.0.as_raw_fd(), (&raw const one).cast(), 8) };
    }

    pub(super) fn clear(&self) {
        let mut n = 0u64;
        // SAFETY: reads at most 8 bytes into a live u64 (EAGAIN when not rung).
        unsafe { libc::read(self.0.as_raw_fd(), (&raw mut n).cast(), 8) };
    }

    /// Waits until `fd` is readable (or closed), the bell rings, or `timeout`
    /// passes: whether the bell rang, whether `fd` is readable (or closed).
    pub(super) fn wait_with(&self, fd: RawFd, timeout: Duration) -> (bool, bool) {
        let mut fds = [
            libc::pollfd {
                fd,
                events: libc::POLLIN,
                revents: 0,
            },
            libc::pollfd {
                fd: self.0.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            },
        ];
        // ppoll, not poll: poll's whole milliseconds would make pushes up to a
        // millisecond late.
        let ts = libc::timespec {
            tv_sec: timeout.as_secs().min(i32::MAX as u64) as libc::time_t,
            tv_nsec: timeout.subsec_nanos() as libc::c_long,
        };
        // SAFETY: two valid pollfds and a timespec for the duration of the call.
        // An error (EINTR) only means the caller looks again.
        unsafe { libc::ppoll(fds.as_mut_ptr(), 2, &ts, std::ptr::null()) };
        (fds[1].revents & libc::POLLIN != 0, fds[0].revents != 0)
    }
}
