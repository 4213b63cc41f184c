//! The recorder's load, for the benches that write it (recorder, foxglove): one
//! second of 640x480 BGR at 30 fps, encoders at 20 Hz, laser and sonars at 10 Hz.

use std::{
    sync::Arc,
    time::{Duration, Instant, SystemTime},
};

use jderobot::{
    interfaces::{Encoders, Image, Laser, Sample, Sonars},
    mcapfmt::Snapshot,
};

/// A sample of `value` at clock `clock` and time `t`.
pub fn sample<T>(clock: u64, t: SystemTime, value: T) -> Arc<Sample<T>> {
    Arc::new(Sample {
        clock,
        stamp: Instant::now(),
        time: t,
        value,
    })
}

/// A 640x480 frame like a camera's (a gradient and a little noise), by `seed`.
pub fn noisy_image(seed: u64) -> Image {
    let mut img = Image::new(640, 480);
    let mut x = seed | 1;
    for (i, b) in img.data.iter_mut().enumerate() {
        // Smooth gradient plus a little noise: like a camera, not like random bytes.
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        *b = ((i / 3 % 640) as u64 / 3 + (x & 7)) as u8;
    }
    img
}

/// One second of the load: (channel, snapshot) in time order.
pub fn one_second(t0: SystemTime, second: u64) -> Vec<(&'static str, Snapshot)> {
    let mut v = Vec::new();
    let img = noisy_image(second + 1);
    for k in 0..60u64 {
        // 60 slots of 1/60 s
        let t = t0 + Duration::from_secs(second) + Duration::from_millis(k * 1000 / 60);
        if k.is_multiple_of(2) {
            v.push((
                "camera",
                Snapshot::Image(sample(second * 30 + k / 2 + 1, t, img.clone())),
            ));
        }
        if k.is_multiple_of(3) {
            let e = Encoders {
                x: k as f32,
                y: 2.0,
                theta: 1.0,
                cos: 0.5,
                sin: 0.8,
            };
            v.push((
                "encoders",
                Snapshot::Encoders(sample(second * 20 + k / 3 + 1, t, e)),
            ));
        }
        if k.is_multiple_of(6) {
            let l = Laser {
                readings: (0..180).map(|i| 1000 + i * 7 + k as i32).collect(),
                resolution: 1.0,
                ..Laser::default()
            };
            v.push((
                "laser",
                Snapshot::Laser(sample(second * 10 + k / 6 + 1, t, l)),
            ));
            let s = Sonars {
                us: (0..16).map(|i| 500.0 + i as f32).collect(),
            };
            v.push((
                "sonars",
                Snapshot::Sonars(sample(second * 10 + k / 6 + 1, t, s)),
            ));
        }
    }
    v
}
