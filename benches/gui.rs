//! The GUI never waits for a schema and a schema never waits for the GUI.
//!
//! 1. Frame rate with a slow schema: the window's contents ([`GuiHost::ui`], with
//!    mastergui docked and a camera panel showing a 320x240 image that the schema
//!    publishes) are drawn and tessellated headlessly with `egui::Context::run_ui`
//!    as fast as possible, while a schema whose iteration takes 200 ms runs (once
//!    sleeping, once spinning a core). A frame must stay well under 33 ms (30 fps).
//! 2. Schema ips with a busy GUI: a 10 ms schema's iterations per second, alone and
//!    while a GUI loop draws unpaced and another thread hammers `Runtime::status()`.
//!
//! Run: `cargo bench --features full --bench gui`. Prints medians and ratios.

use std::{
    path::Path,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::{Duration, Instant},
};

use jderobot::{
    ComponentConf, Context, Kind, Runtime, Schema,
    gui::GuiHost,
    interfaces::{Image, Interface},
    registry,
    runtime::Panel,
    widgets::ImageView,
};

/// A schema whose iteration takes `work` (sleeping or spinning) and publishes an image.
struct Slow {
    cycle: Duration,
    work: Duration,
    spin: bool,
    image: Arc<Interface<Image>>,
    count: Arc<AtomicU64>,
}

impl Schema for Slow {
    fn cycle(&self) -> Duration {
        self.cycle
    }
    fn iteration(&mut self, _: &Context) -> anyhow::Result<()> {
        let t = Instant::now();
        if self.spin {
            while t.elapsed() < self.work {
                std::hint::spin_loop();
            }
        } else if !self.work.is_zero() {
            std::thread::sleep(self.work);
        }
        let n = self.count.fetch_add(1, Ordering::Relaxed) as u8;
        let _ = self.image.write(|img| {
            for (i, b) in img.data.iter_mut().enumerate() {
                *b = (i as u8).wrapping_add(n);
            }
        });
        Ok(())
    }
    fn panel(&mut self) -> Option<Box<dyn Panel>> {
        Some(Box::new(CameraPanel {
            image: self.image.clone(),
            view: ImageView::new("camera"),
        }))
    }
}

struct CameraPanel {
    image: Arc<Interface<Image>>,
    view: ImageView,
}

impl Panel for CameraPanel {
    fn ui(&mut self, ui: &mut egui::Ui, _: &Runtime) {
        let s = self.image.read();
        self.view.show_sample(ui, &s);
    }
}

fn runtime(
    cycle: Duration,
    work: Duration,
    spin: bool,
    name: &str,
) -> (Arc<Runtime>, Arc<AtomicU64>) {
    let path = Path::new("jde.conf");
    let rt = Runtime::new(path);
    if let Some(c) = registry::find("mastergui") {
        let _ = jderobot::loader::load_entry(
            &rt,
            c,
            &ComponentConf::empty(Kind::Schema, "mastergui", path),
        );
        let _ = rt.run("mastergui");
        let _ = rt.show("mastergui");
    }
    let image = rt
        .interfaces
        .provide_value(&format!("varcolor{name}"), name, Image::new(320, 240))
        .expect("provide image");
    let count = Arc::new(AtomicU64::new(0));
    rt.add_schema(
        name,
        "benchmark schema",
        Box::new(Slow {
            cycle,
            work,
            spin,
            image,
            count: count.clone(),
        }),
    )
    .expect("add schema");
    let _ = rt.show(name);
    (rt, count)
}

fn raw_input(t: f64) -> egui::RawInput {
    egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(
            egui::Pos2::ZERO,
            egui::vec2(1280.0, 800.0),
        )),
        time: Some(t),
        ..Default::default()
    }
}

/// Draws frames back to back for `dur`; returns frame times in ms.
fn frames(ctx: &egui::Context, host: &mut GuiHost, dur: Duration) -> Vec<f64> {
    let start = Instant::now();
    let mut times = Vec::new();
    while start.elapsed() < dur {
        let t0 = Instant::now();
        let mut out = ctx.run_ui(raw_input(start.elapsed().as_secs_f64()), |ui| host.ui(ui));
        // No GPU here: the texture uploads are dropped (a renderer would apply them).
        out.textures_delta.clear();
        let prims = ctx.tessellate(out.shapes, out.pixels_per_point);
        std::hint::black_box(prims);
        times.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    times
}

fn pct(v: &[f64], p: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    if s.is_empty() {
        return 0.0;
    }
    s[((s.len() - 1) as f64 * p).round() as usize]
}

fn frame_rate_case(label: &str, work: Duration, spin: bool) -> (f64, f64) {
    let (rt, count) = runtime(Duration::from_millis(200), work, spin, "slow");
    rt.run("slow").expect("run");
    // Wait for the first iteration to be under way.
    std::thread::sleep(Duration::from_millis(50));
    let mut host = GuiHost::new(rt.clone());
    let ctx = egui::Context::default();
    let _ = frames(&ctx, &mut host, Duration::from_millis(500)); // warm-up (font atlas)
    let t = frames(&ctx, &mut host, Duration::from_secs(3));
    // As the window runs: one frame every 33 ms (absolute deadlines) for 3 s.
    let start = Instant::now();
    let mut n = 0u32;
    while start.elapsed() < Duration::from_secs(3) {
        let _ = frames(&ctx, &mut host, Duration::ZERO);
        n += 1;
        let next = start + jderobot::gui::FRAME_PERIOD * n;
        if let Some(d) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
    }
    let paced_fps = n as f64 / start.elapsed().as_secs_f64();
    let iters = count.load(Ordering::Relaxed);
    rt.shutdown();
    let (p50, p99, max) = (pct(&t, 0.5), pct(&t, 0.99), pct(&t, 1.0));
    let late = t.iter().filter(|&&ms| ms > 1000.0 / 30.0).count();
    println!(
        "frames, {label:<28} {:>5} frames in 3 s: median {p50:6.2} ms ({:5.0} fps possible), p99 {p99:6.2} ms, max {max:6.2} ms, {late} over 33.3 ms; paced at 30 fps: {paced_fps:5.1} fps; schema iterations {iters}",
        t.len(),
        1000.0 / p50,
    );
    (p99, paced_fps)
}

fn ips_case(label: &str, gui: bool) -> f64 {
    let (rt, count) = runtime(Duration::from_millis(10), Duration::ZERO, false, "fast");
    rt.run("fast").expect("run");
    std::thread::sleep(Duration::from_millis(300));
    let stop = Arc::new(AtomicBool::new(false));
    let mut helpers = Vec::new();
    if gui {
        let (rt2, stop2) = (rt.clone(), stop.clone());
        helpers.push(std::thread::spawn(move || {
            let mut n = 0u64;
            while !stop2.load(Ordering::Relaxed) {
                std::hint::black_box(rt2.status());
                n += 1;
            }
            n
        }));
        let (rt3, stop3) = (rt.clone(), stop.clone());
        helpers.push(std::thread::spawn(move || {
            let mut host = GuiHost::new(rt3);
            let ctx = egui::Context::default();
            let mut n = 0u64;
            while !stop3.load(Ordering::Relaxed) {
                n += frames(&ctx, &mut host, Duration::from_millis(100)).len() as u64;
            }
            n
        }));
    }
    let c0 = count.load(Ordering::Relaxed);
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs(3));
    let ips = (count.load(Ordering::Relaxed) - c0) as f64 / t0.elapsed().as_secs_f64();
    let cronos = rt
        .schema_status("fast")
        .map(|s| s.timing.ips)
        .unwrap_or(0.0);
    stop.store(true, Ordering::Relaxed);
    let done: Vec<u64> = helpers.into_iter().map(|h| h.join().unwrap_or(0)).collect();
    rt.shutdown();
    let extra = if gui {
        format!(
            " (meanwhile {} status() calls and {} GUI frames)",
            done.first().copied().unwrap_or(0),
            done.get(1).copied().unwrap_or(0)
        )
    } else {
        String::new()
    };
    println!(
        "ips, 10 ms schema, {label:<22} {ips:6.2} ips counted, {cronos:6.2} ips by cronos{extra}"
    );
    ips
}

fn main() {
    // `cargo bench` passes --bench; `cargo test --benches` runs this too: keep it short then.
    let quick = !std::env::args().any(|a| a == "--bench");
    if quick {
        println!("gui bench: run with `cargo bench --features full --bench gui` for figures");
        return;
    }
    println!("== 1. frames while a schema's iteration takes 200 ms (30 fps = 33.3 ms)");
    let (base, base_fps) = frame_rate_case("idle schema (200 ms cycle)", Duration::ZERO, false);
    let (sleeping, sleeping_fps) = frame_rate_case(
        "200 ms iteration, sleeping",
        Duration::from_millis(200),
        false,
    );
    let (spinning, spinning_fps) = frame_rate_case(
        "200 ms iteration, spinning",
        Duration::from_millis(200),
        true,
    );
    let worst_fps = base_fps.min(sleeping_fps).min(spinning_fps);
    println!(
        "p99 frame time ratio slow/idle: sleeping {:.2}, spinning {:.2}; paced fps ratio slow/idle: sleeping {:.3}, spinning {:.3}; worst paced {worst_fps:.1} fps ({})",
        sleeping / base,
        spinning / base,
        sleeping_fps / base_fps,
        spinning_fps / base_fps,
        if worst_fps >= 29.5 {
            "holds 30 fps"
        } else {
            "BELOW 30 fps"
        }
    );
    println!("== 2. a 10 ms schema's ips, alone and with a busy GUI");
    let alone = ips_case("alone", false);
    let busy = ips_case("with a busy GUI", true);
    println!(
        "ips ratio busy/alone: {:.3} ({:+.1} %)",
        busy / alone,
        (busy / alone - 1.0) * 100.0
    );
}
