//! gige benchmark: Aravis's fake camera (`Fake_1`, the library's own camera,
//! stream and buffer path) at 640x480 and 30 frames/s into `varcolorA` for 10 s:
//! the delivered rate and the frames lost (incomplete buffers, gaps in the frame
//! ids). Goal (issue 14): the configured rate with none dropped. Run with
//! `cargo bench --features full --bench gige`.

use std::{
    path::Path,
    sync::atomic::Ordering,
    time::{Duration, Instant},
};

use jderobot::{Conf, drivers::gige, interfaces::Image};

fn main() {
    let text = "driver gige\nprovides varcolorA Fake_1 640 480 Mono8\nframerate Fake_1 30\n\
                end_driver\nload_driver gige\n";
    let conf = Conf::parse(text, Path::new("bench.conf")).unwrap();
    let rt = jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"));
    let img = rt.interfaces.get::<Image>("varcolorA").unwrap();
    img.resume();
    let t0 = Instant::now();
    while img.clock() < 3 {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no frames from Fake_1"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let (c0, d0, s0) = (
        img.clock(),
        gige::DROPPED.load(Ordering::Relaxed),
        gige::SKIPPED.load(Ordering::Relaxed),
    );
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs(10));
    let secs = t0.elapsed().as_secs_f64();
    let frames = img.clock() - c0;
    let dropped = gige::DROPPED.load(Ordering::Relaxed) - d0;
    let skipped = gige::SKIPPED.load(Ordering::Relaxed) - s0;
    let s = img.snapshot();
    println!(
        "gige Fake_1 {}x{} Mono8 at 30 fps: {frames} frames in {secs:.2} s = {:.2} frames/s \
         ({:.1} % of 30); incomplete buffers {dropped}, frame-id gaps {skipped}",
        s.value.width,
        s.value.height,
        frames as f64 / secs,
        100.0 * frames as f64 / secs / 30.0
    );
    img.suspend();
    rt.shutdown();
}
