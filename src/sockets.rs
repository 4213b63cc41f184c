//! Socket calls that std does not have, for the components that talk to peers:
//! an int socket option (`SO_RCVLOWAT`, `SO_SNDBUF`, ...) and a wait until a
//! socket has something to read. Linux (and any Unix) through `libc`.

use std::{io, os::fd::AsRawFd, time::Duration};

/// Sets the int socket option `name` of `level` (as setsockopt(2) names them).
pub fn set_int_option(
    s: &impl AsRawFd,
    level: libc::c_int,
    name: libc::c_int,
    value: libc::c_int,
) -> io::Result<()> {
    // SAFETY: setsockopt on a descriptor the caller holds open, with an int we own.
    let r = unsafe {
        libc::setsockopt(
            s.as_raw_fd(),
            level,
            name,
            (&value as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

/// Waits until `fd` has something to read (or is closed, or failed) or `timeout`
/// passes (whole milliseconds). An error (EINTR) returns early: the caller looks
/// again.
pub fn wait_readable(fd: &impl AsRawFd, timeout: Duration) {
    let mut p = libc::pollfd {
        fd: fd.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    let ms = timeout.as_millis().min(i32::MAX as u128) as libc::c_int;
    // SAFETY: one valid pollfd for the duration of the call.
    unsafe { libc::poll(&mut p, 1, ms) };
}
