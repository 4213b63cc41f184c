//! The GUI's CPU: the real binary's window under the current display (CI: Xvfb with
//! software GL), with introrob driving (examples/introrob.conf) and with the robot
//! standing still (benches/data/gui_still.conf). Prints the process's CPU (% of
//! one core, user + system from /proc) over 8 s after 3 s of warm-up, median of
//! 3 runs each, with the window and `--headless`: the difference is the GUI's.
//!
//! With `JDEROBOT_BEFORE=/path/to/old/jderobot` it runs that binary the same way,
//! in the same process, and prints the ratios (after / before).
//!
//! `xvfb-run -a cargo bench --bench gui_cpu` (needs a display).

mod common;
use common::median;

use std::{
    path::{Path, PathBuf},
    process::Command,
    time::Duration,
};

const RUNS: usize = 3;
const WARMUP: Duration = Duration::from_secs(3);
const WINDOW: Duration = Duration::from_secs(8);

/// % of one core that `bin` uses running `conf` (with its window unless `headless`).
fn cpu_percent(bin: &Path, conf: &str, headless: bool) -> f64 {
    let mut cmd = Command::new(bin);
    cmd.args(["--no-shell", conf])
        .args(headless.then_some("--headless"))
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")));
    common::cpu_percent(cmd, WARMUP, WINDOW)
}

fn main() {
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        eprintln!("gui_cpu: needs a display; run `xvfb-run -a cargo bench --bench gui_cpu`");
        return;
    }
    let now = PathBuf::from(env!("CARGO_BIN_EXE_jderobot"));
    let before = std::env::var_os("JDEROBOT_BEFORE").map(PathBuf::from);
    let cases = [
        ("introrob driving", "examples/introrob.conf"),
        ("nothing moving", "benches/data/gui_still.conf"),
    ];
    println!(
        "CPU, % of one core, median of {RUNS} runs of {} s: window, headless, and the GUI's part (window - headless)",
        WINDOW.as_secs()
    );
    for (what, conf) in cases {
        let mut runs: Vec<(String, [Vec<f64>; 2])> =
            vec![("this build".into(), Default::default())];
        if let Some(b) = &before {
            runs.push((format!("before ({})", b.display()), Default::default()));
        }
        for _ in 0..RUNS {
            // The binaries and modes alternate so all see the same machine load.
            for (i, (_, cpu)) in runs.iter_mut().enumerate() {
                let bin = if i == 0 {
                    &now
                } else {
                    before.as_ref().unwrap()
                };
                cpu[0].push(cpu_percent(bin, conf, false));
                cpu[1].push(cpu_percent(bin, conf, true));
            }
        }
        let mut gui = Vec::new();
        for (name, [window, headless]) in runs {
            let (w, h) = (median(window), median(headless));
            gui.push(w - h);
            println!(
                "{what:<18} {name:<28} window {w:6.1} %  headless {h:6.1} %  GUI {:6.1} %",
                w - h
            );
        }
        if let [a, b] = gui[..] {
            println!(
                "{what:<18} GUI ratio this build / before: {:.2}",
                a / b.max(1e-9)
            );
        }
    }
}
