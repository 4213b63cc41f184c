//! A JDE 4.3-style networkserver, written from `reference/jde43-behaviour.md` §4
//! (not from our codec): reads the 20-byte name, answers `1019 cam` with
//! `1020 clock cam w h 3` and the pixels, pushes subscribed devices every 33 ms in
//! 4.3's formats (`%1.1f`, theta `%1.5f`, the clock again as the encoders' last
//! field), answers `1004`/`1022`, closes on `0`/`1000`, and records every line
//! and name it receives.
#![allow(dead_code)]

use std::{
    io::{BufRead, BufReader, Write},
    net::{Shutdown, SocketAddr, TcpListener, TcpStream},
    sync::{
        Arc, Mutex,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    thread,
    time::{Duration, Instant},
};

/// What the emulated robot sends.
#[derive(Clone)]
pub struct Robot43 {
    /// Image size per network id (netid = index).
    pub sizes: Vec<(usize, usize)>,
    pub laser_number: usize,
    pub sonars_number: usize,
}

pub struct Server43 {
    pub addr: SocketAddr,
    /// Every line received, in order.
    pub lines: Arc<Mutex<Vec<String>>>,
    /// Every 20-byte name received.
    pub names: Arc<Mutex<Vec<[u8; 20]>>>,
    stop: Arc<AtomicBool>,
    conns: Arc<Mutex<Vec<TcpStream>>>,
    accept: Option<thread::JoinHandle<()>>,
    pub clock: Arc<AtomicU64>,
}

impl Server43 {
    pub fn start(port: u16, robot: Robot43) -> Server43 {
        let l = TcpListener::bind(("127.0.0.1", port)).expect("bind the 4.3 server");
        let addr = l.local_addr().unwrap();
        l.set_nonblocking(true).unwrap();
        let lines = Arc::new(Mutex::new(Vec::new()));
        let names = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let conns = Arc::new(Mutex::new(Vec::new()));
        let clock = Arc::new(AtomicU64::new(1));
        let (li, na, st, co, cl) = (
            lines.clone(),
            names.clone(),
            stop.clone(),
            conns.clone(),
            clock.clone(),
        );
        let accept = thread::spawn(move || {
            while !st.load(Ordering::Acquire) {
                match l.accept() {
                    Ok((s, _)) => {
                        s.set_nonblocking(false).unwrap();
                        co.lock().unwrap().push(s.try_clone().unwrap());
                        let (li, na, st, cl, r) = (
                            li.clone(),
                            na.clone(),
                            st.clone(),
                            cl.clone(),
                            robot.clone(),
                        );
                        thread::spawn(move || serve(s, li, na, st, cl, r));
                    }
                    Err(_) => thread::sleep(Duration::from_millis(5)),
                }
            }
        });
        Server43 {
            addr,
            lines,
            names,
            stop,
            conns,
            accept: Some(accept),
            clock,
        }
    }

    /// Whether a line equal to `l` was received.
    pub fn got(&self, l: &str) -> bool {
        self.lines.lock().unwrap().iter().any(|x| x == l)
    }

    pub fn count(&self, l: &str) -> usize {
        self.lines
            .lock()
            .unwrap()
            .iter()
            .filter(|x| *x == l)
            .count()
    }

    /// Closes the listener and every connection (the robot goes away).
    pub fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.accept.take() {
            t.join().unwrap();
        }
        for c in self.conns.lock().unwrap().drain(..) {
            let _ = c.shutdown(Shutdown::Both);
        }
    }
}

impl Drop for Server43 {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn serve(
    s: TcpStream,
    lines: Arc<Mutex<Vec<String>>>,
    names: Arc<Mutex<Vec<[u8; 20]>>>,
    stop: Arc<AtomicBool>,
    clock: Arc<AtomicU64>,
    robot: Robot43,
) {
    let mut out = s.try_clone().unwrap();
    let mut inp = BufReader::new(s);
    let mut name = [0u8; 20];
    if std::io::Read::read_exact(&mut inp, &mut name).is_err() {
        return;
    }
    names.lock().unwrap().push(name);
    inp.get_ref()
        .set_read_timeout(Some(Duration::from_millis(5)))
        .unwrap();
    let mut subs: Vec<&str> = Vec::new();
    let mut next = Instant::now();
    let mut buf = String::new();
    while !stop.load(Ordering::Acquire) {
        if let Ok(n) = inp.read_line(&mut buf) {
            if n == 0 {
                return;
            }
            if buf.ends_with('\n') {
                let l = buf.trim_end().to_string();
                buf.clear();
                lines.lock().unwrap().push(l.clone());
                let f: Vec<&str> = l.split(' ').collect();
                let c = clock.fetch_add(1, Ordering::AcqRel);
                if !matches!(request(&f, c, &robot, &mut subs, &mut out), Ok(true)) {
                    return;
                }
            }
        }
        if Instant::now() >= next {
            next += Duration::from_millis(33);
            let c = clock.fetch_add(1, Ordering::AcqRel);
            if out.write_all(pushes(&subs, c, &robot).as_bytes()).is_err() {
                return;
            }
        }
    }
}

/// 4.3's subscribe and unsubscribe codes of each pushed device.
const SUBSCRIPTIONS: [(&str, &str, &str); 5] = [
    ("27", "28", "laser"),
    ("11", "12", "encoders"),
    ("2", "3", "sonars"),
    ("1001", "1002", "pantilt"),
    ("1025", "1026", "zoom"),
];

/// Answers one request line `f` at clock `c`; false once the client said goodbye.
fn request(
    f: &[&str],
    c: u64,
    robot: &Robot43,
    subs: &mut Vec<&'static str>,
    out: &mut TcpStream,
) -> std::io::Result<bool> {
    if let Some(&(_, _, d)) = SUBSCRIPTIONS.iter().find(|s| s.0 == f[0]) {
        subs.push(d);
    } else if let Some(&(_, _, d)) = SUBSCRIPTIONS.iter().find(|s| s.1 == f[0]) {
        subs.retain(|x| *x != d);
    } else {
        match f[0] {
            "0" | "1000" => {
                let _ = out.shutdown(Shutdown::Both);
                return Ok(false);
            }
            "1004" => out.write_all(b"1005 159.13 30.00 -159.13 -46.00 205.89 205.89\n")?,
            "1022" => out.write_all(b"1023 40.00 0.00 7.00\n")?,
            "1019" => {
                let cam: usize = f[1].parse().unwrap();
                let (w, h) = robot.sizes[cam];
                let mut msg = format!("1020 {c} {cam} {w} {h} 3\n").into_bytes();
                // Pixel i of frame c: (i + c) mod 251.
                msg.extend((0..w * h * 3).map(|i| ((i as u64 + c) % 251) as u8));
                out.write_all(&msg)?
            }
            _ => {}
        }
    }
    Ok(true)
}

/// The lines pushed at clock `c` for the subscribed devices, in 4.3's formats.
fn pushes(subs: &[&str], c: u64, robot: &Robot43) -> String {
    let mut msg = String::new();
    for d in subs {
        match *d {
            "laser" => {
                msg += &format!("26 {c}");
                for i in 0..robot.laser_number {
                    msg += &format!(" {}", 1000 + i);
                }
                msg += "\n";
            }
            "encoders" => msg += &format!("10 {c} {:.1} {:.1} {:.5} {c}\n", 1500.0, -250.0, 90.0),
            "sonars" => {
                msg += &format!("1 {c}");
                for i in 0..robot.sonars_number {
                    msg += &format!(" {i} {:.1}", 300.0 + i as f64);
                }
                msg += "\n";
            }
            "pantilt" => msg += &format!("1003 {c} {:.1} {:.1}\n", 12.5, -7.5),
            "zoom" => msg += &format!("1021 {c} {:.1}\n", 3.0),
            _ => {}
        }
    }
    msg
}
