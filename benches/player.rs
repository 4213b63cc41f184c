//! player benchmark: the codec and the loopback latency, medians over repetitions,
//! with ratios against a plain C-style byte-swap loop measured in the same run.
//! Run with `cargo bench --features full --bench player`.
//!
//! Goals (issue 13): a 180-reading scan decoded into the `laser` interface in
//! ≤ 2 µs; from the emulator writing a scan to the interface's clock moving,
//! p50 ≤ 100 µs over loopback.

#[path = "../tests/emulators/player.rs"]
#[allow(dead_code, clippy::all)]
mod player_emulator;

mod common;
use common::median;

use std::{
    hint::black_box,
    path::Path,
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{
    Conf,
    drivers::player::{
        LaserMap, Offset, sinks,
        xdr::{self, Addr, Header},
    },
    interfaces::{Encoders, Interface, Laser},
};

const SCAN_HEX: &str = include_str!("../tests/data/player_scan.hex");

/// Median nanoseconds per call of `f` over 51 batches of `n` calls.
fn per_call(n: usize, mut f: impl FnMut()) -> f64 {
    for _ in 0..n {
        f();
    }
    let mut v = Vec::new();
    for _ in 0..51 {
        let t = Instant::now();
        for _ in 0..n {
            f();
        }
        v.push(t.elapsed().as_nanos() as f64 / n as f64);
    }
    median(v)
}

/// The player driver on the emulator at `port`, providing `provides`.
fn start_player(port: u16, provides: &str) -> Arc<jderobot::Runtime> {
    let text = format!(
        "driver player\nhostname 127.0.0.1 port {port}\nprovides {provides}\nend_driver\nload_driver player\n"
    );
    let conf = Conf::parse(&text, Path::new("bench.conf")).unwrap();
    jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"))
}

/// The codec against the anchor, per call.
fn codec() {
    let msg = player_emulator::hex(SCAN_HEX);
    let payload = msg[40..].to_vec();

    // Anchor: what a C client does with the ranges: swap 180 big-endian floats
    // into a preallocated array of mm.
    let mut out = [0i32; 180];
    let anchor = per_call(20_000, || {
        let p = black_box(&payload[24..24 + 720]);
        for (i, o) in out.iter_mut().enumerate() {
            let j = i * 4;
            let v = f32::from_bits(u32::from_be_bytes([p[j], p[j + 1], p[j + 2], p[j + 3]]));
            *o = (v * 1000.0) as i32;
        }
        black_box(&out);
    });

    // The driver's path: decode the header fields and counts, map to N readings
    // at R per degree, publish on the interface (recycled buffer).
    let laser: Interface<Laser> = Interface::new("laser", "bench");
    let mut map = LaserMap::new(180, 1.0);
    let scan = per_call(20_000, || {
        let (info, ranges) = xdr::decode_scan(black_box(&payload)).unwrap();
        laser
            .write(|l| sinks::laser_f32(&mut map, &info, ranges, l))
            .unwrap();
    });
    assert_eq!(laser.read().readings[0], 1489);

    let pos = player_emulator::hex(
        "c01a60c2 e1b80f68 c0195087 31f6f1c2 3ff534d4 b45f86fc 3fd99999 9999999a 00000000 00000000 \
         3fd33333 33333333 00000000",
    );
    let enc: Interface<Encoders> = Interface::new("encoders", "bench");
    let off = Offset {
        x: 1000.0,
        y: 1000.0,
        theta_deg: 90.0,
    };
    let position = per_call(50_000, || {
        let p = xdr::decode_position2d(black_box(&pos)).unwrap();
        enc.publish(sinks::encoders(&p, &off)).unwrap();
    });

    let mut buf = Vec::with_capacity(128);
    let cmd = per_call(100_000, || {
        buf.clear();
        let p = xdr::cmd_vel(black_box(0.4), 0.0, black_box(0.3), true);
        Header::new(Addr::new(4, 0), 2, 1, 5, p.len()).encode(&mut buf);
        buf.extend_from_slice(&p);
        black_box(&buf);
    });

    println!("player codec (median per call):");
    println!(
        "  anchor: 180 BE floats swapped to mm (C-style loop)  {:>8.0} ns",
        anchor
    );
    println!(
        "  laser scan (180) decoded into the `laser` interface  {:>8.0} ns  ({:.2}x the anchor; goal <= 2000 ns)",
        scan,
        scan / anchor
    );
    println!(
        "  position2d decoded into `encoders`                   {:>8.0} ns  ({:.2}x the anchor)",
        position,
        position / anchor
    );
    println!(
        "  CMD_VEL encoded (header + payload)                   {:>8.0} ns  ({:.2}x the anchor)",
        cmd,
        cmd / anchor
    );
}

/// Latency over loopback: the emulator stamps each scan just before writing it;
/// we spin on the interface's clock.
fn scan_latency() -> Vec<f64> {
    let emu = player_emulator::Emulator::with_devices(vec![(6, 0)]);
    *emu.shared.period.lock().unwrap() = Duration::from_millis(5);
    let rt = start_player(emu.port, "laser 180 1");
    let laser: Arc<Interface<Laser>> = rt.interfaces.get("laser").unwrap();
    rt.run("laser").unwrap();
    let mut lat = Vec::new();
    let mut last = laser.clock();
    let t0 = Instant::now();
    while lat.len() < 400 && t0.elapsed() < Duration::from_secs(30) {
        let c = laser.clock();
        if c != last {
            let seen = Instant::now();
            last = c;
            if let Some(w) = *emu.shared.last_scan_write.lock().unwrap() {
                let d = seen.saturating_duration_since(w);
                // Skip the first few (connection warm-up).
                if c > 5 && d < Duration::from_millis(5) {
                    lat.push(d.as_secs_f64() * 1e6);
                }
            }
        }
        std::hint::spin_loop();
    }
    rt.shutdown();
    lat
}

/// Commands: from a motors publish to the server receiving it (one cycle, 75 ms,
/// at most; about half a cycle on average).
fn command_latency() -> Vec<f64> {
    let emu2 = player_emulator::Emulator::with_devices(vec![(4, 0)]);
    let rt2 = start_player(emu2.port, "motors");
    let motors: Arc<Interface<jderobot::interfaces::Motors>> =
        rt2.interfaces.get("motors").unwrap();
    rt2.run("motors").unwrap();
    let mut cmd_lat = Vec::new();
    for k in 1..=40 {
        let v = 10.0 * k as f32;
        // At a different phase of the driver's 75 ms cycle each time.
        std::thread::sleep(Duration::from_millis((k * 17 % 75) as u64));
        let t = Instant::now();
        motors
            .publish(jderobot::interfaces::Motors { v, w: 0.0 })
            .unwrap();
        loop {
            let got = emu2
                .world()
                .commands
                .iter()
                .rev()
                .find(|c| (c.0 - v as f64 / 1000.0).abs() < 1e-9)
                .map(|c| c.2);
            if let Some(at) = got {
                cmd_lat.push(at.saturating_duration_since(t).as_secs_f64() * 1e3);
                break;
            }
            if t.elapsed() > Duration::from_secs(2) {
                break;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    rt2.shutdown();
    cmd_lat.sort_by(f64::total_cmp);
    cmd_lat
}

fn main() {
    codec();
    let mut lat = scan_latency();
    let cmd_lat = command_latency();
    let n = lat.len();
    let p50 = median(lat.clone());
    lat.sort_by(f64::total_cmp);
    let p90 = lat.get(n * 9 / 10).copied().unwrap_or(f64::NAN);
    println!("player latency over loopback (emulator write -> laser clock), {n} scans:");
    println!("  p50 {p50:.0} us, p90 {p90:.0} us  (goal p50 <= 100 us)");
    println!(
        "player commands (motors publish -> server), {} commands: p50 {:.1} ms, max {:.1} ms  (goal: within one 75 ms cycle)",
        cmd_lat.len(),
        cmd_lat.get(cmd_lat.len() / 2).copied().unwrap_or(f64::NAN),
        cmd_lat.last().copied().unwrap_or(f64::NAN)
    );
}
