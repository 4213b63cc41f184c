//! A JDE 4.3-style networkclient, written from `reference/jde43-behaviour.md` §4
//! (not from our codec): one TCP connection per device, the 20-byte name `jdec`
//! NUL-padded, lines formatted as 4.3's printf did (`22 %1.1f 0.0`), replies split
//! on spaces as sscanf would.
#![allow(dead_code)]

use std::{
    io::{BufRead, BufReader, Read, Write},
    net::{SocketAddr, TcpStream},
    time::{Duration, Instant},
};

pub struct Client43 {
    pub out: TcpStream,
    pub inp: BufReader<TcpStream>,
}

impl Client43 {
    /// Connects and sends the 20-byte name (`jdec`, NULs; `token` after the first NUL).
    pub fn connect(addr: SocketAddr, token: Option<&str>) -> Client43 {
        let s = TcpStream::connect(addr).expect("connect to the server");
        s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        // `jdec`, NUL-padded; with a token (jderobot's): the marker after the
        // NUL and the token line (docs/network.md).
        let mut name = b"jdec".to_vec();
        name.resize(20, 0);
        if let Some(t) = token {
            name[5..15].copy_from_slice(b"token-line");
            name.extend_from_slice(format!("2100 {t}\n").as_bytes());
        }
        let mut out = s.try_clone().unwrap();
        out.write_all(&name).unwrap();
        Client43 {
            out,
            inp: BufReader::new(s),
        }
    }

    /// Writes one line exactly as given (the `\n` is added).
    pub fn send(&mut self, line: &str) {
        self.out.write_all(format!("{line}\n").as_bytes()).unwrap();
    }

    /// The next line (without `\n`); None when the server closed the connection.
    pub fn line(&mut self) -> Option<String> {
        let mut l = String::new();
        match self.inp.read_line(&mut l) {
            Ok(0) => None,
            Ok(_) => Some(l.trim_end_matches('\n').to_string()),
            Err(e) => panic!("reading from the server: {e}"),
        }
    }

    /// The next line whose first field is `code`, skipping others; its fields.
    pub fn expect(&mut self, code: &str) -> Vec<String> {
        let t0 = Instant::now();
        loop {
            let l = self
                .line()
                .unwrap_or_else(|| panic!("connection closed waiting for {code}"));
            let f: Vec<String> = l.split(' ').map(String::from).collect();
            if f[0] == code {
                return f;
            }
            assert!(t0.elapsed() < Duration::from_secs(10), "no {code} line");
        }
    }

    /// `1019 cam`, then the `1020` header and the pixels.
    pub fn image(&mut self, cam: u32) -> (Vec<String>, Vec<u8>) {
        self.send(&format!("1019 {cam}"));
        self.read_image()
    }

    pub fn read_image(&mut self) -> (Vec<String>, Vec<u8>) {
        let h = self.expect("1020");
        let w: usize = h[3].parse().unwrap();
        let hh: usize = h[4].parse().unwrap();
        let d: usize = h[5].parse().unwrap();
        let mut px = vec![0u8; w * hh * d];
        self.inp.read_exact(&mut px).unwrap();
        (h, px)
    }

    /// Whether the server closes the connection within `secs`.
    pub fn closed_within(&mut self, secs: u64) -> bool {
        self.inp
            .get_ref()
            .set_read_timeout(Some(Duration::from_secs(secs)))
            .unwrap();
        let mut b = [0u8; 4096];
        loop {
            match self.inp.read(&mut b) {
                Ok(0) => return true,
                Ok(_) => continue,
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => return true,
                Err(_) => return false,
            }
        }
    }
}
