//! Cost of reading and writing an image interface with 1 writer and 8 readers,
//! beside a `Mutex<Vec<u8>>` whose readers copy the image out (the usual
//! alternative), in the same run. Per-operation cost is each thread's CPU time
//! divided by its operations, so it does not depend on how many cores are free.
//!
//! `cargo bench --bench interfaces` (`JDEROBOT_BENCH_QUICK=1` for a short run).

mod common;
use common::median;

use std::{
    hint::black_box,
    sync::{
        Arc, Barrier, Mutex,
        atomic::{AtomicBool, Ordering},
    },
    time::Duration,
};

use jderobot::interfaces::{Image, Interface};

fn thread_cpu_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid timespec pointer.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

struct Result {
    read_ns: f64,
    write_ns: f64,
}

/// Runs 1 writer and `readers` readers for `span`; `read` and `write` are one op.
fn contend<R, W>(readers: usize, span: Duration, read: R, write: W) -> Result
where
    R: Fn() -> u8 + Send + Sync + 'static,
    W: Fn(u8) + Send + Sync + 'static,
{
    let stop = Arc::new(AtomicBool::new(false));
    let start = Arc::new(Barrier::new(readers + 2));
    let read = Arc::new(read);
    let reader_threads: Vec<_> = (0..readers)
        .map(|_| {
            let (stop, start, read) = (stop.clone(), start.clone(), read.clone());
            std::thread::spawn(move || {
                start.wait();
                let t0 = thread_cpu_ns();
                let mut ops = 0u64;
                while !stop.load(Ordering::Relaxed) {
                    black_box(read());
                    ops += 1;
                }
                (thread_cpu_ns() - t0, ops)
            })
        })
        .collect();
    let writer = {
        let (stop, start) = (stop.clone(), start.clone());
        std::thread::spawn(move || {
            start.wait();
            let t0 = thread_cpu_ns();
            let mut ops = 0u64;
            while !stop.load(Ordering::Relaxed) {
                write(ops as u8);
                ops += 1;
                // A camera-like writer: about 1000 frames/s at most.
                std::thread::sleep(Duration::from_micros(1000));
            }
            (thread_cpu_ns() - t0, ops)
        })
    };
    start.wait();
    std::thread::sleep(span);
    stop.store(true, Ordering::Relaxed);
    let (mut cpu, mut ops) = (0u64, 0u64);
    for t in reader_threads {
        let (c, o) = t.join().unwrap();
        cpu += c;
        ops += o;
    }
    let (wc, wo) = writer.join().unwrap();
    Result {
        read_ns: cpu as f64 / ops.max(1) as f64,
        write_ns: wc as f64 / wo.max(1) as f64,
    }
}

fn main() {
    let quick = std::env::var_os("JDEROBOT_BENCH_QUICK").is_some();
    let span = Duration::from_millis(if quick { 300 } else { 1000 });
    let reps = if quick { 3 } else { 5 };
    println!("image interface, 1 writer (~1 kHz) + 8 readers, CPU ns per op (median of {reps})");
    println!(
        "{:>10} | {:>12} {:>12} | {:>14} {:>14} | {:>8}",
        "size", "iface read", "iface write", "mutex-copy rd", "mutex-copy wr", "read x"
    );
    for &(w, h) in &[(320u32, 240u32), (640, 480), (1920, 1080)] {
        let frame = Image::new(w, h);
        let mut ir = Vec::new();
        let mut iw = Vec::new();
        let mut mr = Vec::new();
        let mut mw = Vec::new();
        for _ in 0..reps {
            let iface = Arc::new(Interface::with_value("varcolorA", "bench", frame.clone()));
            let src = frame.data.clone();
            let (ri, wi) = (iface.clone(), iface.clone());
            let r = contend(
                8,
                span,
                move || {
                    let s = ri.read();
                    s.value.data[s.value.data.len() / 2]
                },
                move |b| {
                    wi.write(|img| {
                        img.data.copy_from_slice(&src);
                        img.data[0] = b;
                    })
                    .unwrap();
                },
            );
            ir.push(r.read_ns);
            iw.push(r.write_ns);

            let shared = Arc::new(Mutex::new(frame.data.clone()));
            let src = frame.data.clone();
            let (rm, wm) = (shared.clone(), shared.clone());
            let r = contend(
                8,
                span,
                move || {
                    let copy = rm.lock().unwrap().clone();
                    copy[copy.len() / 2]
                },
                move |b| {
                    let mut g = wm.lock().unwrap();
                    g.copy_from_slice(&src);
                    g[0] = b;
                },
            );
            mr.push(r.read_ns);
            mw.push(r.write_ns);
        }
        let (ir, iw, mr, mw) = (median(ir), median(iw), median(mr), median(mw));
        println!(
            "{:>10} | {:>12.1} {:>12.1} | {:>14.1} {:>14.1} | {:>7.0}x",
            format!("{w}x{h}"),
            ir,
            iw,
            mr,
            mw,
            mr / ir
        );
    }
}
