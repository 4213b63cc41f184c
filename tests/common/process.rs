//! A real `jderobot` process driven through its shell (tests that run two
//! processes talking over the network).

use std::{
    io::{BufRead, BufReader, Write},
    path::Path,
    process::Child,
    sync::{Arc, Mutex},
    time::Duration,
};

/// Everything a child writes on its piped stdout and stderr, line by line, as it
/// comes (a thread per pipe).
pub fn collect_output(child: &mut Child) -> Arc<Mutex<String>> {
    let out = Arc::new(Mutex::new(String::new()));
    for pipe in [
        Box::new(child.stdout.take().unwrap()) as Box<dyn std::io::Read + Send>,
        Box::new(child.stderr.take().unwrap()),
    ] {
        let out = out.clone();
        std::thread::spawn(move || {
            for l in BufReader::new(pipe).lines().map_while(Result::ok) {
                let mut o = out.lock().unwrap();
                o.push_str(&l);
                o.push('\n');
            }
        });
    }
    out
}

/// A peer's stdout lines with when each arrived (a thread reads them as they come).
pub type TimedLines = Arc<Mutex<Vec<(std::time::Instant, String)>>>;

/// Reads `child`'s piped stdout into [`TimedLines`].
#[allow(dead_code)]
pub fn timed_lines(child: &mut Child) -> TimedLines {
    let lines = TimedLines::default();
    let out = child.stdout.take().expect("a piped stdout");
    let l = lines.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            l.lock().unwrap().push((std::time::Instant::now(), line));
        }
    });
    lines
}

/// When the first line `line` arrived at or after `t0`, if one did.
#[allow(dead_code)]
pub fn line_after(
    lines: &TimedLines,
    t0: std::time::Instant,
    line: &str,
) -> Option<std::time::Instant> {
    let l = lines.lock().unwrap();
    l.iter()
        .find(|(at, s)| *at >= t0 && s == line)
        .map(|(at, _)| *at)
}

/// A running `jderobot --headless CONF` whose shell we type into.
pub struct Proc {
    pub child: Child,
    out: Arc<Mutex<String>>,
}

impl Proc {
    pub fn start(conf: &Path) -> Proc {
        Proc::spawn(super::jderobot([Path::new("--headless"), conf]))
    }

    /// `jderobot --headless CONF` in network namespace `ns` ([`super::TwoHosts`]).
    #[allow(dead_code)]
    pub fn start_in(ns: &str, conf: &Path) -> Proc {
        let c = super::jderobot([Path::new("--headless"), conf]);
        Proc::spawn(super::TwoHosts::command(ns, &c))
    }

    /// `jderobot --headless CONF` in a process group of its own (so that a stop
    /// signal's default action is not discarded as for an orphaned group) and
    /// without core files (tests that end it by SIGQUIT or SIGABRT), for tests
    /// that [`signal`](Proc::signal) it.
    #[allow(dead_code)]
    pub fn start_alone(conf: &Path) -> Proc {
        use std::os::unix::process::CommandExt;
        let mut c = super::jderobot([Path::new("--headless"), conf]);
        c.process_group(0);
        // SAFETY: setrlimit is async-signal-safe.
        unsafe {
            c.pre_exec(|| {
                let none = libc::rlimit {
                    rlim_cur: 0,
                    rlim_max: 0,
                };
                libc::setrlimit(libc::RLIMIT_CORE, &none);
                Ok(())
            });
        }
        Proc::spawn(c)
    }

    /// A `jderobot` command the caller made (limits, environment), started.
    pub fn spawn(mut c: std::process::Command) -> Proc {
        let mut child = c.spawn().expect("start jderobot");
        let out = collect_output(&mut child);
        Proc { child, out }
    }

    pub fn send(&mut self, cmd: &str) {
        let stdin = self.child.stdin.as_mut().unwrap();
        let _ = stdin.write_all(format!("{cmd}\n").as_bytes());
        let _ = stdin.flush();
    }

    pub fn text(&self) -> String {
        self.out.lock().unwrap().clone()
    }

    /// Sends `sig` to the process.
    #[allow(dead_code)]
    pub fn signal(&self, sig: i32) {
        // SAFETY: a signal to our own child.
        unsafe { libc::kill(self.child.id() as i32, sig) };
    }

    /// The process's state letter in /proc (R, S, T: stopped, ...).
    #[allow(dead_code)]
    pub fn state(&self) -> char {
        let stat =
            std::fs::read_to_string(format!("/proc/{}/stat", self.child.id())).unwrap_or_default();
        stat.rsplit(") ")
            .next()
            .and_then(|s| s.chars().next())
            .unwrap_or('?')
    }

    /// Its exit status, if it ends within `secs`.
    #[allow(dead_code)]
    pub fn wait(&mut self, secs: u64) -> Option<std::process::ExitStatus> {
        let mut status = None;
        super::poll_until(secs, || {
            status = self.child.try_wait().ok().flatten();
            status.is_some()
        });
        status
    }

    /// Types `cmd` until a line of its answer (after this call) satisfies `ok`;
    /// returns that line.
    pub fn ask_until(&mut self, cmd: &str, what: &str, ok: impl Fn(&str) -> bool) -> String {
        let mut found = None;
        let done = super::poll_until(30, || {
            let from = self.text().len();
            self.send(cmd);
            std::thread::sleep(Duration::from_millis(300));
            let t = self.text();
            found = t[from..].lines().find(|l| ok(l)).map(String::from);
            found.is_some()
        });
        assert!(
            done,
            "timed out waiting for {what}; output:\n{}",
            self.text()
        );
        found.unwrap()
    }

    /// The remote interfaces `names` arrive here from `provider` at 3 or more per
    /// second (`ps`), and `colorA` is a 320x240 image.
    pub fn expect_arriving(&mut self, names: &[&str], provider: &str) {
        for name in names {
            let l = self.ask_until("ps", &format!("{name} arriving"), |l| {
                l.starts_with(&format!("{name}: ")) && l.contains(provider) && rate(l) >= 3.0
            });
            eprintln!("{l}");
        }
        self.ask_until("echo colorA", "a 320x240 image", |l| {
            l.starts_with("colorA clock=") && l.contains("320x240 BGR")
        });
    }

    /// Asks `echo encoders` until the robot is more than `mm` from the pose of
    /// `start` (an earlier `echo encoders` line); returns that line.
    pub fn expect_moved(&mut self, start: &str, mm: f64) -> String {
        let (x0, y0) = xy(start);
        self.ask_until("echo encoders", "the robot moving", |l| {
            l.starts_with("encoders clock=") && {
                let (x, y) = xy(l);
                (x - x0).hypot(y - y0) > mm
            }
        })
    }

    /// Types `quit`; the process's exit status (it must end within 20 s).
    pub fn quit(mut self) -> std::process::ExitStatus {
        self.send("quit");
        let mut status = None;
        if !super::poll_until(20, || {
            status = self.child.try_wait().ok().flatten();
            status.is_some()
        }) {
            let _ = self.child.kill();
            let _ = self.child.wait();
            panic!("jderobot did not quit; output:\n{}", self.text());
        }
        status.unwrap()
    }
}

/// The signals a robot driver's stop is tested with (issue 52): one that ends
/// the process and one that suspends it.
#[allow(dead_code)]
pub const STOP_SIGNALS: [(i32, &str); 2] = [(libc::SIGTERM, "SIGTERM"), (libc::SIGTSTP, "SIGTSTP")];

/// Sends `sig` (one of [`STOP_SIGNALS`]) to `p`, a process driving a robot, and
/// returns how long after it the robot got its stop (`stop_after(t0)`: when the
/// first stop after `t0` arrived; polled for 5 s). Then SIGTERM must end the
/// process with 128 + 15; SIGTSTP must suspend it, and after SIGCONT it must quit
/// normally.
#[allow(dead_code)]
pub fn time_to_stop(
    p: &mut Proc,
    (sig, name): (i32, &str),
    mut stop_after: impl FnMut(std::time::Instant) -> Option<std::time::Instant>,
) -> Duration {
    let t0 = std::time::Instant::now();
    p.signal(sig);
    let mut stopped = None;
    super::poll_until(5, || {
        stopped = stop_after(t0);
        stopped.is_some()
    });
    let at =
        stopped.unwrap_or_else(|| panic!("{name}: no stop in 5 s; jderobot said:\n{}", p.text()));
    if sig == libc::SIGTSTP {
        assert!(
            super::poll_until(5, || p.state() == 'T'),
            "{name}: not suspended (state {}); jderobot said:\n{}",
            p.state(),
            p.text()
        );
        p.signal(libc::SIGCONT);
        assert!(super::poll_until(5, || p.state() != 'T'), "not resumed");
        p.send("quit");
    }
    let status = p
        .wait(20)
        .unwrap_or_else(|| panic!("{name}: jderobot did not end; it said:\n{}", p.text()));
    let code = if sig == libc::SIGTSTP { 0 } else { 128 + sig };
    assert_eq!(
        status.code(),
        Some(code),
        "{name}; jderobot said:\n{}",
        p.text()
    );
    at - t0
}

/// The driver stop tests' one shape: `p` drives its robot through the shell
/// (`set motors v=150 w=0`) until `moving` says the robot got it, then
/// [`signal_stops_within_100_ms`].
#[allow(dead_code)]
pub fn drive_then_signal(
    p: &mut Proc,
    what: &str,
    signal: (i32, &str),
    mut moving: impl FnMut() -> bool,
    stop_after: impl FnMut(std::time::Instant) -> Option<std::time::Instant>,
) -> Duration {
    let driving = super::poll_until(30, || {
        p.send("set motors v=150 w=0");
        std::thread::sleep(Duration::from_millis(200));
        moving()
    });
    assert!(
        driving,
        "{what}: the robot never drove; jderobot said:\n{}",
        p.text()
    );
    signal_stops_within_100_ms(p, what, signal, stop_after)
}

/// [`drive_then_signal`] for a peer that prints each Twist it gets as a line
/// `twist V W` (m/s, rad/s): the ROS 2 and Gazebo subscribers.
#[allow(dead_code)]
pub fn drive_twist_peer_then_signal(
    p: &mut Proc,
    what: &str,
    signal: (i32, &str),
    lines: &TimedLines,
) {
    drive_then_signal(
        p,
        what,
        signal,
        || {
            lines
                .lock()
                .unwrap()
                .last()
                .is_some_and(|l| l.1 == "twist 0.1500 0.0000")
        },
        |t0| line_after(lines, t0, "twist 0.0000 0.0000"),
    );
}

/// [`time_to_stop`], said (`what` names the robot and its stop) and asserted
/// within 100 ms.
#[allow(dead_code)]
pub fn signal_stops_within_100_ms(
    p: &mut Proc,
    what: &str,
    signal: (i32, &str),
    stop_after: impl FnMut(std::time::Instant) -> Option<std::time::Instant>,
) -> Duration {
    let took = time_to_stop(p, signal, stop_after);
    eprintln!(
        "{what}, {}: stop after {:.1} ms",
        signal.1,
        took.as_secs_f64() * 1e3
    );
    assert!(
        took < Duration::from_millis(100),
        "{what}, {}: stop after {took:?}",
        signal.1
    );
    took
}

impl Drop for Proc {
    /// A failed test leaves no process behind.
    fn drop(&mut self) {
        if self.child.try_wait().ok().flatten().is_none() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `NAME: N ips` from a `ps` line.
pub fn rate(line: &str) -> f64 {
    number_after(line, ": ")
}

/// The number after `key` in a line (`number_after(echo, " v=")`).
pub fn number_after(line: &str, key: &str) -> f64 {
    let tail = line
        .split(key)
        .nth(1)
        .unwrap_or_else(|| panic!("no `{key}` in: {line}"));
    let word = tail.split(' ').next().unwrap();
    word.parse()
        .unwrap_or_else(|_| panic!("`{word}` after `{key}` is not a number: {line}"))
}

/// x and y (mm) from an `echo encoders` line.
pub fn xy(echo: &str) -> (f64, f64) {
    (number_after(echo, " x="), number_after(echo, " y="))
}
