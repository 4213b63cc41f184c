//! The 3D panels' frame time and the GUI's idle CPU with them.
//!
//! 1. Frame time: a real eframe window (glow; under Xvfb, Mesa's llvmpipe) shows
//!    one panel at a time in its central area, the GL view 640x480 pixels, while
//!    the simulator runs the `cave` world (assets/worlds/cave.world, ~110 wall
//!    faces) with a 180-reading laser and the robot turning in place (so the laser
//!    fan changes every simulator step). The window repaints continuously without
//!    vsync; the time between frames is measured over 300 frames after 30 of
//!    warm-up, for: the same window with no 3D panel (the reference), opengldemo
//!    (rotate on: the camera orbits every frame) and opengl_viewer (following the
//!    robot). Prints medians and the ratio to the reference, and whether 30 fps
//!    holds (median under 33 ms).
//! 2. Idle CPU: the real binary with its window, nothing moving (robot still,
//!    rotate off), both 3D schemas loaded and running, their panels shown or
//!    hidden (mastergui shown in both), % of one core over 8 s after 3 s of
//!    warm-up, median of 3 runs each; with introrob and teleoperator compiled in,
//!    also two of today's 2D panels shown instead (introrob's world view,
//!    teleoperator's software wireframe), for comparison.
//!
//! `xvfb-run -a -s "-screen 0 1280x800x24" cargo bench --features full --bench opengl`

mod common;
use common::median;

use std::{
    path::{Path, PathBuf},
    process::Command,
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{Conf, Runtime, interfaces::Motors};

const WARMUP_FRAMES: usize = 30;
const FRAMES: usize = 300;

fn bench_conf() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    format!(
        "driver simulator\nworld {}\nrobot robot1 0 0 0\nprovides encoders\nprovides motors\n\
         provides laser 180 1\nprovides sonars\nprovides pantiltencoders\nend_driver\n\
         schema opengldemo\nrotate on\nrotate_speed 30\ncycle 10\nend_schema\n\
         schema opengl_viewer\nfollow on\nend_schema\n\
         load_driver simulator\nload_schema opengldemo\nload_schema opengl_viewer\n\
         run opengldemo\nrun opengl_viewer\n",
        root.join("assets/worlds/cave.world").display()
    )
}

struct App {
    rt: Arc<Runtime>,
    motors: Arc<jderobot::Interface<Motors>>,
    phases: Vec<(&'static str, Option<&'static str>)>,
    phase: usize,
    frame: usize,
    last: Option<Instant>,
    times: Vec<f64>,
    results: Vec<Row>,
}

/// A phase's name, median and 90th percentile frame time (ms).
type Row = (&'static str, f64, f64);

impl eframe::App for App {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        if self.phase >= self.phases.len() {
            ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
            return;
        }
        // Keep the robot turning (the command goes stale after motors_timeout).
        let _ = self.motors.write(|m| {
            m.v = 0.0;
            m.w = 20.0;
        });
        let now = Instant::now();
        if let Some(t) = self.last
            && self.frame > WARMUP_FRAMES
        {
            self.times
                .push(now.duration_since(t).as_secs_f64() * 1000.0);
        }
        self.last = Some(now);
        self.frame += 1;
        if self.times.len() >= FRAMES {
            let t = std::mem::take(&mut self.times);
            let p90 = {
                let mut s = t.clone();
                s.sort_by(f64::total_cmp);
                s[s.len() * 9 / 10]
            };
            self.results
                .push((self.phases[self.phase].0, median(t), p90));
            self.phase += 1;
            self.frame = 0;
            self.last = None;
            if self.phase >= self.phases.len() {
                ui.ctx().send_viewport_cmd(egui::ViewportCommand::Close);
                return;
            }
        }
        let (name, schema) = self.phases[self.phase];
        egui::CentralPanel::default().show(ui, |ui| match schema.and_then(|s| self.rt.schema(s)) {
            Some(slot) => {
                if let Some(p) = slot.panel.lock().as_mut() {
                    p.ui(ui, &self.rt);
                }
            }
            None => {
                ui.label(format!("{name}: no 3D panel"));
                let (r, _) = ui.allocate_exact_size(
                    egui::vec2(ui.available_width(), 480.0),
                    egui::Sense::hover(),
                );
                ui.painter()
                    .rect_filled(r, 0.0, egui::Color32::from_gray(30));
            }
        });
        ui.ctx().request_repaint();
    }
}

/// % of one core that the binary uses with `conf`'s window, over 8 s after 3 s.
fn cpu_percent(conf: &Path) -> f64 {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_jderobot"));
    cmd.arg("--no-shell").arg(conf);
    common::cpu_percent(cmd, Duration::from_secs(3), Duration::from_secs(8))
}

/// Which panels the idle-CPU window shows (besides mastergui).
#[derive(Clone, Copy, PartialEq)]
enum Shown {
    /// None: the reference.
    Nothing,
    /// opengldemo and opengl_viewer.
    Gl,
    /// Two 2D panels of today, for comparison: introrob's (world view) and
    /// teleoperator's (its software-drawn 3D wireframe).
    Flat,
}

fn idle_conf(dir: &Path, shown: Shown) -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut text = format!(
        "driver simulator\nworld {}\nrobot robot1 0 0 0\nprovides encoders\nprovides motors\n\
         provides laser 180 1\nprovides sonars\nprovides pantiltencoders\nend_driver\n\
         load_driver simulator\nload_service gui\nload_schema mastergui\nrun mastergui\n\
         show mastergui\n",
        root.join("assets/worlds/cave.world").display()
    );
    // Every run loads and runs the 3D schemas (so the simulator computes the same
    // sensors for them); only the `Gl` run shows their panels.
    text.push_str(
        "schema opengldemo\nrotate off\nend_schema\nschema opengl_viewer\nend_schema\n\
         load_schema opengldemo\nload_schema opengl_viewer\nrun opengldemo\nrun opengl_viewer\n",
    );
    match shown {
        Shown::Nothing => {}
        Shown::Gl => text.push_str("show opengldemo\nshow opengl_viewer\n"),
        Shown::Flat => text.push_str(
            "schema introrob\nbehaviour stop\nend_schema\nload_schema introrob\nrun introrob\n\
             show introrob\nload_schema teleoperator\nshow teleoperator\n",
        ),
    }
    let f = dir.join(match shown {
        Shown::Nothing => "idle.conf",
        Shown::Gl => "idle_3d.conf",
        Shown::Flat => "idle_2d.conf",
    });
    std::fs::write(&f, text).unwrap();
    f
}

fn main() {
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        eprintln!(
            "opengl: needs a display; run `xvfb-run -a -s \"-screen 0 1280x800x24\" cargo bench --features full --bench opengl`"
        );
        return;
    }
    let conf = Conf::parse(&bench_conf(), Path::new("bench.conf")).expect("conf");
    let rt = jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"));
    let motors = rt.interfaces.get::<Motors>("motors").expect("motors");
    let app = App {
        rt: rt.clone(),
        motors,
        phases: vec![
            ("reference (no 3D panel)", None),
            ("opengldemo, rotate on", Some("opengldemo")),
            ("opengl_viewer, following", Some("opengl_viewer")),
        ],
        phase: 0,
        frame: 0,
        last: None,
        times: Vec::new(),
        results: Vec::new(),
    };
    let results = Arc::new(parking_lot::Mutex::new(Vec::new()));
    let out = results.clone();
    // The central panel's inner width is the window's minus 2 x 8 points of margin:
    // the GL view is 640 x 480 (its height is 3/4 of its width).
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_inner_size([656.0, 760.0]),
        depth_buffer: 24,
        ..Default::default()
    };
    let r = eframe::run_native(
        "opengl bench",
        options,
        Box::new(move |_cc| {
            Ok(Box::new(Wrap {
                app,
                out: out.clone(),
            }))
        }),
    );
    if let Err(e) = r {
        eprintln!("opengl: cannot open a window: {e}");
        rt.shutdown();
        return;
    }
    rt.shutdown();
    let results = results.lock().clone();
    println!(
        "Frame time, ms between frames, {FRAMES} frames (after {WARMUP_FRAMES}), GL view 640x480, cave world, 180-reading laser:"
    );
    let reference = results.first().map(|r| r.1).unwrap_or(f64::NAN);
    for (name, med, p90) in &results {
        println!(
            "  {name:28} median {med:6.2} ms  p90 {p90:6.2} ms  ({:.2}x the reference; {})",
            med / reference,
            if *med < 33.3 {
                "30 fps holds"
            } else {
                "under 30 fps"
            }
        );
    }
    let dir = tempfile_dir();
    let cpu = |shown: Shown| {
        let f = idle_conf(&dir, shown);
        median((0..3).map(|_| cpu_percent(&f)).collect::<Vec<f64>>())
    };
    let (without, with) = (cpu(Shown::Nothing), cpu(Shown::Gl));
    println!(
        "Idle CPU (nothing moving), % of one core, median of 3 runs of 8 s: 3D panels hidden {without:.1} %, \
         opengldemo and opengl_viewer shown {with:.1} % ({:+.1} points)",
        with - without
    );
    if cfg!(all(feature = "introrob", feature = "teleoperator")) {
        let flat = cpu(Shown::Flat);
        println!(
            "  for comparison, two 2D panels of today shown instead (introrob, teleoperator): {flat:.1} % ({:+.1} points)",
            flat - without
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

fn tempfile_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("jde-opengl-bench-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Hands the results out when the window closes.
struct Wrap {
    app: App,
    out: Arc<parking_lot::Mutex<Vec<Row>>>,
}

impl eframe::App for Wrap {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        self.app.ui(ui, frame);
        *self.out.lock() = self.app.results.clone();
    }
}
