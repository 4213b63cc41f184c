//! Image frames: a frame is written with one `writev` straight from the
//! interface's shared sample (the header from a small buffer, the pixels from the
//! sample: no copy), and a writer that waits for a frame is woken by the image's
//! publish ([`FrameWake`]).

use std::{
    io,
    net::TcpStream,
    sync::{
        Weak,
        atomic::{Ordering, fence},
    },
};

use crate::{
    interfaces::{Image, Interface, Notify},
    netwire,
};

use super::serve::Client;

/// Sends the latest frame of `iface` as image `netid` (`1020` header and pixels)
/// and records its clock in `last`. `out` is scratch space for the header.
pub(super) fn send(
    w: &mut &TcpStream,
    out: &mut Vec<u8>,
    netid: u32,
    iface: &Interface<Image>,
    last: &mut u64,
) -> io::Result<()> {
    let s = iface.snapshot();
    *last = s.clock;
    out.clear();
    netwire::write_image_header(out, s.clock, netid, s.width, s.height);
    netwire::write_all_vectored(w, &[out.as_slice(), &s.data])
}

/// Wakes a client's writer when a served image has a new frame, if it sleeps
/// waiting for one (instead of polling for it; a busy writer costs the camera's
/// thread one atomic load). It takes the client's lock, so the writer is asleep
/// on the condition variable, not between its last look and its wait.
pub(super) struct FrameWake(pub(super) Weak<Client>);

impl Notify for FrameWake {
    fn notify(&self) {
        fence(Ordering::SeqCst);
        if let Some(cl) = self.0.upgrade()
            && cl.waiting_frame.load(Ordering::Relaxed)
        {
            let _st = cl.st.lock();
            cl.cv.notify_all();
        }
    }
}
