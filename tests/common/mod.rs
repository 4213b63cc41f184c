//! Helpers the integration tests share; each test crate `mod common;` and uses
//! what it needs.
#![allow(dead_code)]

pub mod process;

use std::{
    path::{Path, PathBuf},
    process::{Command, Stdio},
    sync::Arc,
    time::{Duration, Instant},
};

use jderobot::{Conf, Runtime, State};

/// Runs test `name` (its path in the test binary, `module::test`) again in a
/// process of its own, and says whether that run happened and passed (true: the
/// caller returns) or this process is that run (false: the caller does the test).
/// For the tests that measure their process's memory (RSS, peak): a suite runs its
/// tests on several threads, and the tests beside would move the figure. Taking
/// turns in one process cost the network suite 70 s of waiting (docs/benchmarks.md,
/// CI); a process each lets them run beside the others.
pub fn ran_in_own_process(name: &str) -> bool {
    const INSIDE: &str = "JDE_TEST_OWN_PROCESS";
    if std::env::var_os(INSIDE).is_some() || std::env::var_os(NETNS_INSIDE).is_some() {
        return false;
    }
    let out = Command::new(std::env::current_exe().expect("the test binary"))
        .args(["--exact", name, "--nocapture", "--test-threads=1"])
        .env(INSIDE, "1")
        .output()
        .expect("run the test binary again");
    // Shown by the harness with this test's result (on failure, or with --nocapture).
    print!("{}", String::from_utf8_lossy(&out.stdout));
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "{name} failed in its own process ({}; its output is above)",
        out.status
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("test result: ok. 1 passed"),
        "no test is named {name}: pass the module path and the function's name"
    );
    true
}

/// Keeps the panics of this thread off the output until the guard drops, for tests
/// that catch panics on purpose (fuzzing, damaged files). Only this thread: a
/// process-wide silent hook would also hide the messages of the tests running beside.
pub fn quiet_panics() -> QuietPanics {
    static INSTALL: std::sync::Once = std::sync::Once::new();
    INSTALL.call_once(|| {
        let loud = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(|q| q.get()) {
                loud(info)
            }
        }));
    });
    QUIET.with(|q| q.set(true));
    QuietPanics(())
}

thread_local! {
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// See [`quiet_panics`].
pub struct QuietPanics(());

impl Drop for QuietPanics {
    fn drop(&mut self) {
        QUIET.with(|q| q.set(false));
    }
}

/// Test certificates made with openssl in a folder: EC P-256, valid 2 days.
pub mod certs {
    use std::{path::Path, process::Command};

    fn openssl(dir: &Path, args: &[&str]) {
        assert!(
            super::have("openssl"),
            "openssl is needed to make the test's certificates"
        );
        let out = Command::new("openssl")
            .args(args)
            .current_dir(dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "openssl {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    const EC: [&str; 5] = [
        "-newkey",
        "ec",
        "-pkeyopt",
        "ec_paramgen_curve:P-256",
        "-nodes",
    ];

    /// A CA, `NAME.pem` and `NAME.key` in `dir`.
    pub fn ca(dir: &Path, name: &str) {
        let (subj, key, pem) = (
            format!("/CN={name}"),
            format!("{name}.key"),
            format!("{name}.pem"),
        );
        let mut args = vec!["req", "-x509"];
        args.extend(EC);
        args.extend(["-days", "2", "-subj", &subj, "-keyout", &key, "-out", &pem]);
        openssl(dir, &args);
    }

    /// A certificate for 127.0.0.1 and localhost with common name `who`, signed by
    /// the CA `ca` of `dir`: `WHO.pem` and `WHO.key`.
    pub fn signed(dir: &Path, who: &str, ca: &str) {
        std::fs::write(
            dir.join("ext.cnf"),
            "subjectAltName=IP:127.0.0.1,DNS:localhost\nbasicConstraints=CA:FALSE\n",
        )
        .unwrap();
        let (subj, key, csr, pem) = (
            format!("/CN={who}"),
            format!("{who}.key"),
            format!("{who}.csr"),
            format!("{who}.pem"),
        );
        let (ca_pem, ca_key) = (format!("{ca}.pem"), format!("{ca}.key"));
        let mut args = vec!["req"];
        args.extend(EC);
        args.extend(["-subj", &subj, "-keyout", &key, "-out", &csr]);
        openssl(dir, &args);
        openssl(
            dir,
            &[
                "x509",
                "-req",
                "-in",
                &csr,
                "-CA",
                &ca_pem,
                "-CAkey",
                &ca_key,
                "-CAcreateserial",
                "-days",
                "2",
                "-extfile",
                "ext.cnf",
                "-out",
                &pem,
            ],
        );
    }
}

/// The `jderobot` binary with `args`, as every test runs it: warnings only in
/// the log, no display (headless), standard streams piped.
pub fn jderobot<I, S>(args: I) -> Command
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let mut c = Command::new(env!("CARGO_BIN_EXE_jderobot"));
    c.args(args)
        .env("RUST_LOG", "warn")
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c
}

/// Runs `jderobot ARGS` to its end with standard input closed; it must succeed.
#[allow(dead_code)]
pub fn jderobot_ok<I, S>(args: I) -> std::process::Output
where
    I: IntoIterator<Item = S>,
    S: AsRef<std::ffi::OsStr>,
{
    let mut c = jderobot(args);
    let out = c.stdin(Stdio::null()).output().expect("run jderobot");
    assert!(
        out.status.success(),
        "{c:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `jderobot --headless --no-shell --for SECS CONF` in the conf's folder; it must
/// succeed.
#[allow(dead_code)]
pub fn run_for(conf: &Path, secs: f64) -> std::process::Output {
    let secs = secs.to_string();
    let args = ["--headless", "--no-shell", "--for", &secs];
    let mut c = jderobot(
        args.iter()
            .map(std::ffi::OsStr::new)
            .chain([conf.as_os_str()]),
    );
    if let Some(dir) = conf.parent() {
        c.current_dir(dir);
    }
    let out = c.stdin(Stdio::null()).output().expect("run jderobot");
    assert!(
        out.status.success(),
        "jderobot {} failed: {}",
        conf.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `jderobot help NAME`'s standard output (it must succeed).
pub fn help(name: &str) -> String {
    let out = jderobot(["help", name])
        .output()
        .expect("run jderobot help");
    assert!(out.status.success(), "jderobot help {name} failed");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// `jderobot check` of a conf holding `text` (written as `dir/name`): whether it
/// passed, and its standard error.
pub fn check_text(dir: &Path, name: &str, text: &str) -> (bool, String) {
    let file = dir.join(name);
    std::fs::write(&file, text).expect("write the conf");
    let out = jderobot([Path::new("check"), &file])
        .output()
        .expect("run jderobot check");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `jderobot help NAME` names each of `lines`.
#[allow(dead_code)]
pub fn assert_help_names(name: &str, lines: &[&str]) {
    let text = help(name);
    for line in lines {
        assert!(text.contains(line), "{line}: {text}");
    }
}

/// `jderobot check` of a conf holding `text` fails, and names each of `errors`.
#[allow(dead_code)]
pub fn assert_check_names(text: &str, errors: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (ok, err) = check_text(dir.path(), "t.conf", text);
    assert!(!ok, "check passed: {text}");
    for e in errors {
        assert!(err.contains(e), "{e}: {err}");
    }
}

/// Starting a runtime from conf text (as if read from `test.conf`) must fail:
/// the error, with its causes.
#[allow(dead_code)]
pub fn start_error(text: &str) -> String {
    let conf = Conf::parse(text, Path::new("test.conf")).unwrap_or_else(|e| panic!("{e}"));
    match jderobot::loader::start(&conf) {
        Ok(rt) => {
            rt.shutdown();
            panic!("accepted: {text}");
        }
        Err(e) => format!("{e:#}"),
    }
}

/// Not a test: runs an emulated device (`start` at the path in env var
/// `path_var`, default `default`) for a person to try an example against, for
/// `secs_var` seconds (default 600).
#[allow(dead_code)]
pub fn emulate_by_hand<T>(
    what: &str,
    (path_var, default): (&str, &str),
    secs_var: &str,
    start: impl FnOnce(&Path) -> T,
) {
    let path = std::env::var(path_var).unwrap_or_else(|_| default.into());
    let secs: u64 = std::env::var(secs_var)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(600);
    let _ = std::fs::remove_file(&path);
    let _device = start(Path::new(&path));
    println!("emulated {what} at {path} for {secs} s");
    std::thread::sleep(Duration::from_secs(secs));
}

/// `jderobot check`'s problems with a conf whose `kind name` section holds `line`
/// (at line 2 of `t.conf`).
pub fn line_problems(kind: &str, name: &str, line: &str) -> Vec<String> {
    let text = format!("{kind} {name}\n{line}\nend_{kind}\nload_{kind} {name}\n");
    let conf = Conf::parse(&text, Path::new("t.conf")).expect("grammar");
    jderobot::loader::check(&conf)
        .into_iter()
        .map(|e| e.to_string())
        .collect()
}

/// Every compiled-in component that declares its lines, with its declaration.
pub fn declared() -> Vec<(
    &'static jderobot::registry::Entry,
    &'static [jderobot::conf::settings::Setting],
)> {
    jderobot::registry::components()
        .into_iter()
        .filter_map(|e| e.lines.map(|l| (e, l.decl)))
        .collect()
}

/// A small, fast, reproducible generator (xorshift64*) for random test inputs.
#[allow(dead_code)]
pub struct Rng(u64);

#[allow(dead_code)]
impl Rng {
    /// The sequence of `seed` (any value; 0 too).
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15 | 1)
    }
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// A number in 0..n (0 when n is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
    /// `n` bytes covering every value.
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| (self.next() >> 56) as u8).collect()
    }
}

/// The crate's root, where `assets/` and `examples/` are.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Polls `f` every few ms until it holds (true) or `secs` pass (false).
pub fn poll_until(secs: u64, mut f: impl FnMut() -> bool) -> bool {
    let t0 = Instant::now();
    while !f() {
        if t0.elapsed() > Duration::from_secs(secs) {
            return false;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    true
}

/// Polls `f` until it holds; fails the test after 20 s.
pub fn eventually(what: &str, f: impl FnMut() -> bool) {
    assert!(poll_until(20, f), "timed out waiting for: {what}");
}

/// A loaded schema's state.
pub fn state(rt: &Runtime, name: &str) -> State {
    rt.schema_status(name).expect("loaded").state
}

/// Starts a runtime from conf text (as if read from `test.conf`).
pub fn start_conf(text: &str) -> Arc<Runtime> {
    let conf = Conf::parse(text, Path::new("test.conf")).unwrap_or_else(|e| panic!("{e}"));
    jderobot::loader::start(&conf).unwrap_or_else(|e| panic!("{e}"))
}

/// The path of a world under `assets/worlds/`, for conf text.
pub fn world_path(name: &str) -> String {
    root()
        .join("assets/worlds")
        .join(name)
        .display()
        .to_string()
}

/// A loaded schema's panel, taken out of the runtime and drawn alone in an
/// egui_kittest harness of `size` points (headless: no display, no GPU).
#[cfg(feature = "gui")]
pub fn panel_harness(
    rt: &Arc<Runtime>,
    name: &str,
    size: egui::Vec2,
) -> egui_kittest::Harness<'static> {
    let mut panel = rt
        .schema(name)
        .expect("loaded")
        .panel
        .lock()
        .take()
        .expect("has a panel");
    let rt = rt.clone();
    egui_kittest::Harness::builder()
        .with_size(size)
        .build_ui(move |ui| panel.ui(ui, &rt))
}

/// Whether `cmd` is on the PATH.
pub fn have(cmd: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {cmd}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Whether `prog` is installed; under CI a missing program fails the test.
pub fn need(prog: &str) -> bool {
    if have(prog) {
        return true;
    }
    if std::env::var_os("CI").is_some() {
        panic!(
            "`{prog}` is not installed and CI is set: install the Debian package (ffmpeg, mplayer)"
        );
    }
    eprintln!("skipped: `{prog}` is not installed");
    false
}

/// Whether a screenshot test can run here: an X display and imagemagick's
/// `tools`. If not, says why (naming `test`): under `CI` the test fails, elsewhere
/// it skips.
pub fn can_screenshot(test: &str, tools: &[&str]) -> bool {
    // Under CI a test that cannot run fails with the reason; elsewhere it says why
    // and skips.
    let ci = std::env::var_os("CI").is_some_and(|v| !v.is_empty());
    let missing = |why: String| {
        if ci {
            panic!("{test} cannot run under CI: {why}");
        }
        eprintln!("skipped: {why}");
        false
    };
    if std::env::var_os("DISPLAY").is_none_or(|d| d.is_empty()) {
        return missing(format!(
            "DISPLAY is not set (run under `xvfb-run -a cargo test --test {test}`)"
        ));
    }
    if let Some(t) = tools.iter().find(|t| !have(t)) {
        return missing(format!("`{t}` is not installed"));
    }
    true
}

/// Starts the real binary on the X display with `conf` (relative to the crate's
/// root), standard error to `log`, standard input a pipe for shell commands.
pub fn spawn_window(conf: &str, log: &Path) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_jderobot"))
        .arg(conf)
        .current_dir(root())
        .env("LIBGL_ALWAYS_SOFTWARE", "1")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(log).expect("log file"))
        .spawn()
        .expect("start jderobot")
}

/// Types `commands` into the child's shell and waits up to 20 s for it to exit;
/// kills it and gives None if it does not.
pub fn quit(mut child: std::process::Child, commands: &str) -> Option<std::process::ExitStatus> {
    use std::io::Write;
    if let Some(stdin) = child.stdin.as_mut() {
        let _ = stdin.write_all(commands.as_bytes());
    }
    let mut status = None;
    if !poll_until(20, || {
        status = child.try_wait().ok().flatten();
        status.is_some()
    }) {
        let _ = child.kill();
        let _ = child.wait();
    }
    status
}

/// The test venv's python (`target/py-venv`, which .ci/run makes, or
/// `$JDEROBOT_PYTHON`) if it imports `modules` (`"mcap, rosbags"`); otherwise
/// None after a note, so the test skips, but it FAILS under `CI`.
/// Runs `scripts/SCRIPT FILE` with the venv's `py`; it must succeed. Its JSON line.
#[cfg(feature = "_mcap")]
#[allow(dead_code)]
pub fn python_json(py: &Path, script: &str, file: &Path) -> serde_json::Value {
    let out = Command::new(py)
        .arg(root().join("scripts").join(script))
        .arg(file)
        .output()
        .expect("run python");
    assert!(
        out.status.success(),
        "{script} {}: {}",
        file.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("a JSON line")
}

pub fn python_with(modules: &str) -> Option<PathBuf> {
    let py = std::env::var_os("JDEROBOT_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target/py-venv/bin/python"));
    let ok = Command::new(&py)
        .args(["-c", &format!("import {modules}")])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        return Some(py);
    }
    let note = format!(
        "{} cannot import {modules}; make the venv as .ci/run does",
        py.display()
    );
    assert!(std::env::var_os("CI").is_none(), "under CI: {note}");
    eprintln!("SKIPPED: {note}");
    None
}

/// A screenshot's RGB pixels, row by row from the top-left.
pub struct Shot {
    pub w: usize,
    pub h: usize,
    pub px: Vec<[u8; 3]>,
}

impl Shot {
    pub fn at(&self, x: usize, y: usize) -> [u8; 3] {
        self.px[y * self.w + x]
    }
}

/// Takes a screenshot of the X root window into `png` (imagemagick's `import`)
/// and reads it back; None if either fails.
pub fn screenshot(png: &Path) -> Option<Shot> {
    let ok = Command::new("import")
        .args(["-window", "root"])
        .arg(png)
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        return None;
    }
    read_png(png)
}

/// The RGB pixels of a PNG file; None if it cannot be read.
pub fn read_png(png: &Path) -> Option<Shot> {
    let bytes = std::fs::read(png).ok()?;
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut r = dec.read_info().ok()?;
    let mut buf = vec![0u8; r.output_buffer_size()?];
    let info = r.next_frame(&mut buf).ok()?;
    let (w, h, ch) = (
        info.width as usize,
        info.height as usize,
        info.color_type.samples(),
    );
    if ch < 3 {
        return None;
    }
    let mut px = Vec::with_capacity(w * h);
    for y in 0..h {
        let row = &buf[y * info.line_size..];
        for x in 0..w {
            px.push([row[x * ch], row[x * ch + 1], row[x * ch + 2]]);
        }
    }
    Some(Shot { w, h, px })
}

/// The window tests share one X display and read the whole screen: one real
/// window at a time in a test binary (hold this while the window is open).
pub fn x_display() -> std::sync::MutexGuard<'static, ()> {
    static DISPLAY: std::sync::Mutex<()> = std::sync::Mutex::new(());
    DISPLAY.lock().unwrap_or_else(|e| e.into_inner())
}

/// Set in the run of a test inside its network namespace ([`in_private_netns`]).
const NETNS_INSIDE: &str = "JDE_TEST_IN_NETNS";

/// Where a test that floods the network runs its body.
#[derive(Debug, PartialEq, Eq)]
pub enum Netns {
    /// Here: this process is the run inside a private network namespace (or, off
    /// CI, `unshare` is missing and the body runs on the host's loopback).
    RunHere,
    /// The run inside the namespace has happened (and passed).
    Done,
}

/// Runs test `name` (its path in the test binary, `module::test`) again inside a
/// fresh network namespace of its own (`unshare -n`, or `unshare -rn` where only
/// that works: only a loopback interface, brought up), so what it sends (multicast discovery floods) cannot reach the
/// host's network or other tests. Under CI, missing `unshare` or `ip` fails.
pub fn in_private_netns(name: &str) -> Netns {
    run_in_private_netns(&["--exact", name, "--nocapture", "--test-threads=1"], name)
}

/// Runs this test binary with `args` (a filter, `--skip`s) inside a fresh network
/// namespace whose only interface is loopback, brought up: a host without a
/// network. `what` names the run in its failure. Under CI, missing `unshare` or
/// `ip` fails; elsewhere the caller runs it here ([`Netns::RunHere`]).
pub fn run_in_private_netns(args: &[&str], what: &str) -> Netns {
    const INSIDE: &str = NETNS_INSIDE;
    if std::env::var_os(INSIDE).is_some() {
        return Netns::RunHere;
    }
    // A network namespace alone (`-n`: root with CAP_SYS_ADMIN; a user namespace is
    // refused in a chroot), else inside a user namespace of its own (`-rn`: any
    // user, where the kernel allows it).
    let flags = ["-n", "-rn"].into_iter().find(|f| {
        have("ip")
            && Command::new("unshare")
                .args([f, "true"])
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
    });
    let Some(flags) = flags else {
        let note = "`unshare -n` or `unshare -rn` (util-linux) and `ip` (iproute2) are needed to run this \
                    test in a private network namespace";
        assert!(std::env::var_os("CI").is_none(), "under CI: {note}");
        eprintln!("NOTE: {note}; running it on the host's loopback instead");
        return Netns::RunHere;
    };
    let exe = std::env::current_exe().expect("the test binary");
    let st = Command::new("unshare")
        .args([flags, "sh", "-c", r#"ip link set lo up && exec "$0" "$@""#])
        .arg(exe)
        .args(args)
        .env(INSIDE, "1")
        .status()
        .expect("run unshare");
    assert!(
        st.success(),
        "{what} failed in its network namespace (its output is above)"
    );
    Netns::Done
}

/// Two hosts on one machine: network namespaces `a` and `b` joined by a veth
/// pair (10.77.N.1/24 in `a`, 10.77.N.2/24 in `b`, multicast routed on it), each
/// with its loopback up; removed on drop. Needs root (`ip netns add`): `None`
/// after a note off CI, a failure under CI.
#[allow(dead_code)]
pub struct TwoHosts {
    pub a: String,
    pub b: String,
    /// A's address on the veth pair (B's is the same ending in .2).
    pub ip_a: String,
}

#[allow(dead_code)]
impl TwoHosts {
    pub fn new() -> Option<TwoHosts> {
        let n = std::process::id() % 250 + 1;
        let (a, b) = (format!("jdeA{n}"), format!("jdeB{n}"));
        let ip = |args: &[&str]| {
            Command::new("ip")
                .args(args)
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        let (va, vb) = (format!("jva{n}"), format!("jvb{n}"));
        let (addr_a, addr_b) = (format!("10.77.{n}.1/24"), format!("10.77.{n}.2/24"));
        let hosts = TwoHosts {
            a,
            b,
            ip_a: format!("10.77.{n}.1"),
        };
        let ok = have("ip")
            && ip(&["netns", "add", &hosts.a])
            && ip(&["netns", "add", &hosts.b])
            && ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])
            && ip(&["link", "set", &va, "netns", &hosts.a])
            && ip(&["link", "set", &vb, "netns", &hosts.b])
            && [(&hosts.a, &va, &addr_a), (&hosts.b, &vb, &addr_b)]
                .iter()
                .all(|(ns, dev, addr)| {
                    ip(&["-n", ns, "link", "set", "lo", "up"])
                        && ip(&["-n", ns, "addr", "add", addr, "dev", dev])
                        && ip(&["-n", ns, "link", "set", dev, "up", "multicast", "on"])
                        && ip(&["-n", ns, "route", "add", "224.0.0.0/4", "dev", dev])
                });
        if !ok {
            let note = "two network namespaces joined by a veth pair need root and `ip` (iproute2)";
            assert!(std::env::var_os("CI").is_none(), "under CI: {note}");
            eprintln!("NOTE: {note}; skipped");
            return None;
        }
        Some(hosts)
    }

    /// `cmd`, to be run in namespace `ns` (`ip netns exec NS PROGRAM ARGS...`).
    pub fn command(ns: &str, cmd: &Command) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", ns]).arg(cmd.get_program());
        c.args(cmd.get_args());
        for (k, v) in cmd.get_envs() {
            match v {
                Some(v) => c.env(k, v),
                None => c.env_remove(k),
            };
        }
        c.stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        c
    }
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        for ns in [&self.a, &self.b] {
            let _ = Command::new("ip")
                .args(["netns", "del", ns])
                .stderr(Stdio::null())
                .status();
        }
    }
}

/// The inodes of process `pid`'s sockets (from `/proc/PID/fd`), to find its rows in
/// `/proc/PID/net/{tcp,udp}{,6}`.
pub fn socket_inodes(pid: u32) -> Vec<String> {
    std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| {
            d.flatten()
                .filter_map(|e| std::fs::read_link(e.path()).ok())
                .filter_map(|l| {
                    let l = l.to_string_lossy().into_owned();
                    Some(l.strip_prefix("socket:[")?.strip_suffix(']')?.to_string())
                })
                .collect()
        })
        .unwrap_or_default()
}
