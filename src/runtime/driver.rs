//! The driver trait (what the runtime keeps of a loaded driver or service) and the
//! worker thread most drivers run.

use std::{
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    thread::JoinHandle,
};

/// A driver or service: the factory provides its interfaces and starts its work;
/// [`Driver::terminate`] stops it (e.g. zeroes the motors, closes the device).
pub trait Driver: Send {
    fn terminate(&mut self) {}
}

/// A driver's worker thread. The thread polls its stop flag; [`Worker::stop`] (or
/// terminating or dropping the worker) sets it and waits for the thread to end. A
/// driver with nothing else to do at terminate is just its `Worker`.
pub struct Worker {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts `body` on a thread called `name`; `stop` is the flag it polls.
    pub fn start(
        name: &str,
        stop: Arc<AtomicBool>,
        body: impl FnOnce() + Send + 'static,
    ) -> anyhow::Result<Worker> {
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(body)
            .map_err(|e| anyhow::anyhow!("cannot start the {name} thread: {e}"))?;
        Ok(Worker {
            stop,
            thread: Some(thread),
        })
    }

    /// Asks the thread to stop and waits for it.
    pub fn stop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Driver for Worker {
    fn terminate(&mut self) {
        self.stop();
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.stop();
    }
}
