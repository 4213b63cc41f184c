//! The Slamtec RPLIDAR serial protocol as this driver speaks it (Slamtec, *RPLIDAR
//! Interface Protocol and Application Notes*): requests `A5 CMD [size payload
//! checksum]`, response descriptors `A5 5A len(30 bits)|mode(2 bits) type`, and the
//! standard scan's 5-byte measurement nodes. Pure functions, no I/O.

pub const SYNC: u8 = 0xA5;
pub const SYNC2: u8 = 0x5A;
pub const STOP: u8 = 0x25;
pub const RESET: u8 = 0x40;
pub const SCAN: u8 = 0x20;
pub const GET_INFO: u8 = 0x50;
pub const GET_HEALTH: u8 = 0x52;
/// Motor speed (PWM) control, A2 and later (payload: u16 duty, 0 stops).
pub const SET_MOTOR_PWM: u8 = 0xF0;
/// Response types.
pub const TYPE_INFO: u8 = 0x04;
pub const TYPE_HEALTH: u8 = 0x06;
pub const TYPE_SCAN: u8 = 0x81;

/// A request without payload.
pub fn request(cmd: u8) -> [u8; 2] {
    [SYNC, cmd]
}

/// A request with a payload: `A5 cmd size payload checksum`, the checksum the XOR
/// of every byte before it.
pub fn request_with(cmd: u8, payload: &[u8]) -> Vec<u8> {
    let mut r = vec![SYNC, cmd, payload.len() as u8];
    r.extend_from_slice(payload);
    let x = r.iter().fold(0u8, |a, &b| a ^ b);
    r.push(x);
    r
}

/// A response descriptor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Descriptor {
    pub len: u32,
    /// 0 single response, 1 multiple.
    pub mode: u8,
    pub kind: u8,
}

/// Parses a 7-byte descriptor.
pub fn descriptor(b: &[u8; 7]) -> Option<Descriptor> {
    if b[0] != SYNC || b[1] != SYNC2 {
        return None;
    }
    let v = u32::from_le_bytes([b[2], b[3], b[4], b[5]]);
    Some(Descriptor {
        len: v & 0x3FFF_FFFF,
        mode: (v >> 30) as u8,
        kind: b[6],
    })
}

/// GET_INFO's answer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Info {
    pub model: u8,
    pub firmware: (u8, u8),
    pub hardware: u8,
    pub serial: [u8; 16],
}

impl Info {
    pub fn parse(b: &[u8]) -> Option<Info> {
        (b.len() == 20).then(|| Info {
            model: b[0],
            firmware: (b[2], b[1]),
            hardware: b[3],
            serial: b[4..20].try_into().unwrap_or_default(),
        })
    }
    /// The model's family: A1, A2, A3, S1 ... (the major number in the model byte).
    pub fn family(&self) -> String {
        match self.model >> 4 {
            1 => "A1".into(),
            2 => "A2".into(),
            3 => "A3".into(),
            6 => "S1".into(),
            7 => "S2".into(),
            _ => format!("model 0x{:02X}", self.model),
        }
    }
    pub fn serial_hex(&self) -> String {
        self.serial.iter().map(|b| format!("{b:02X}")).collect()
    }
}

/// GET_HEALTH's answer: status 0 good, 1 warning, 2 error, and the error code.
pub fn health(b: &[u8]) -> Option<(u8, u16)> {
    (b.len() == 3).then(|| (b[0], u16::from_le_bytes([b[1], b[2]])))
}

/// One standard scan measurement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// The first node of a new revolution (S).
    pub start: bool,
    pub quality: u8,
    /// Degrees, clockwise as the device measures.
    pub angle: f32,
    /// mm; 0 is no measurement.
    pub distance: f32,
}

/// Decodes a 5-byte node: byte 0 `quality:6 !S:1 S:1`, byte 1 `angle_q6[6:0] C:1`,
/// byte 2 `angle_q6[14:7]`, bytes 3..4 `distance_q2` little-endian. None when the
/// checks fail (S == !S, or C not 1): the stream is out of step.
pub fn node(b: &[u8]) -> Option<Node> {
    let s = b[0] & 1;
    let ns = (b[0] >> 1) & 1;
    if s == ns || b[1] & 1 != 1 {
        return None;
    }
    let angle_q6 = ((b[1] as u16) >> 1) | ((b[2] as u16) << 7);
    let angle = angle_q6 as f32 / 64.0;
    if angle >= 360.0 {
        return None;
    }
    Some(Node {
        start: s == 1,
        quality: b[0] >> 2,
        angle,
        distance: u16::from_le_bytes([b[3], b[4]]) as f32 / 4.0,
    })
}

/// What a plausible revolution of standard-scan nodes looks like. The protocol
/// gives the node's own checks (S ≠ !S, C = 1, an angle under 360°); a stream of
/// random bytes passes them in about one 5-byte window in six, so a revolution,
/// the nodes between two start flags, is checked as a whole too. Its rate within
/// the models' (Slamtec's datasheets: A1 1–10 Hz, A2 5–15 Hz, A3 10–20 Hz, S1
/// 8–15 Hz) with a margin, enough nodes for a standard scan (2000 samples/s or
/// more, so 100 or more a revolution at 20 Hz), its angles going round one way
/// (the device's angles grow through a revolution; random ones go back half the
/// time) and round most of the circle (a revolution cut short by noise would
/// read "nothing there" where it has no node), no byte skipped while it was
/// gathered (the skipped bytes may have hidden a misread node; a glitch costs
/// one revolution), and few nodes with a distance but
/// quality 0 (the device reports quality 0 with distance 0, "no measurement"; our
/// reading of the protocol, not a rule Slamtec states).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Revolutions a second: the slowest and the fastest believed.
    pub min_hz: f64,
    pub max_hz: f64,
    pub min_nodes: usize,
    /// Degrees from its first node's angle to its largest.
    pub min_span: f32,
    /// The most bytes skipped as no node while a revolution is gathered.
    pub max_skipped: usize,
    /// The largest share of a revolution's nodes whose angle does not grow.
    pub max_backwards: f64,
    /// The largest share of nodes with a distance and quality 0.
    pub max_no_quality: f64,
}

/// The limits the driver uses for every model.
pub const LIMITS: Limits = Limits {
    min_hz: 1.0,
    max_hz: 25.0,
    min_nodes: 64,
    min_span: 320.0,
    max_skipped: 0,
    max_backwards: 0.10,
    max_no_quality: 0.20,
};

/// One finished revolution's counts.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RevStats {
    pub nodes: usize,
    /// Bytes skipped as no node while it was gathered.
    pub skipped: usize,
    /// Nodes whose angle did not grow from the previous node's.
    pub backwards: usize,
    /// Nodes with a distance but quality 0.
    pub no_quality: usize,
    /// Degrees from its first node's angle to its largest.
    pub span: f32,
    /// From its start flag to the next one's (as the host read them).
    pub duration: std::time::Duration,
}

impl RevStats {
    /// Why this revolution cannot be a lidar's, or None if it can.
    pub fn implausible(&self, l: &Limits) -> Option<String> {
        let secs = self.duration.as_secs_f64();
        let share = |n: usize, of: usize| n as f64 / of.max(1) as f64;
        let mut why = Vec::new();
        if secs < 1.0 / l.max_hz || secs > 1.0 / l.min_hz {
            why.push(format!(
                "{:.1} revolutions/s (expected {}..{})",
                1.0 / secs.max(1e-6),
                l.min_hz,
                l.max_hz
            ));
        }
        if self.nodes < l.min_nodes {
            why.push(format!(
                "{} nodes in a revolution (expected {} or more)",
                self.nodes, l.min_nodes
            ));
        }
        if self.span < l.min_span {
            why.push(format!(
                "a revolution round {:.0}° (expected {}° or more)",
                self.span, l.min_span
            ));
        }
        if self.skipped > l.max_skipped {
            why.push(format!(
                "{} byte(s) skipped as no node (expected {})",
                self.skipped, l.max_skipped
            ));
        }
        if share(self.backwards, self.nodes) > l.max_backwards {
            why.push(format!(
                "{:.0} % of its angles going backwards",
                100.0 * share(self.backwards, self.nodes)
            ));
        }
        if share(self.no_quality, self.nodes) > l.max_no_quality {
            why.push(format!(
                "{:.0} % of its distances with quality 0",
                100.0 * share(self.no_quality, self.nodes)
            ));
        }
        (!why.is_empty()).then(|| why.join(", "))
    }
}

/// Puts revolutions together: nodes in, one scan of N readings at R per degree
/// out (reading i at `start + i/R` degrees counter-clockwise, no return →
/// `max_range`) each time a node with S arrives, with the finished revolution's
/// [`RevStats`] for the plausibility check.
pub struct Revolution {
    pub n: usize,
    pub per_deg: f64,
    pub start: f64,
    pub max_range: i32,
    readings: Vec<i32>,
    /// The distance from each reading's own angle of the node written there.
    err: Vec<f32>,
    stats: RevStats,
    last_angle: f32,
    first_angle: f32,
    /// When the revolution being gathered began (its start flag was read).
    began: Option<std::time::Instant>,
}

impl Revolution {
    pub fn new(n: usize, per_deg: f64, start: f64, max_range: i32) -> Revolution {
        Revolution {
            n,
            per_deg,
            start,
            max_range,
            readings: vec![max_range; n],
            err: vec![f32::MAX; n],
            stats: RevStats::default(),
            last_angle: 0.0,
            first_angle: 0.0,
            began: None,
        }
    }

    /// `n` bytes were skipped as no node.
    pub fn skipped(&mut self, n: usize) {
        self.stats.skipped += n;
    }

    /// How long the revolution being gathered has been going, if one is.
    pub fn going_for(&self, now: std::time::Instant) -> Option<std::time::Duration> {
        self.began.map(|b| now.saturating_duration_since(b))
    }

    /// Adds a node read at `at`; when it starts a new revolution and a whole one
    /// was gathered, the finished scan's readings are swapped into `out` and its
    /// counts returned.
    pub fn push(
        &mut self,
        nd: &Node,
        at: std::time::Instant,
        out: &mut Vec<i32>,
    ) -> Option<RevStats> {
        let mut done = None;
        if nd.start {
            if let Some(began) = self.began
                && self.stats.nodes > 0
            {
                out.clear();
                out.extend_from_slice(&self.readings);
                self.stats.duration = at.saturating_duration_since(began);
                done = Some(self.stats);
            }
            self.began = Some(at);
            self.readings.iter_mut().for_each(|r| *r = self.max_range);
            self.err.iter_mut().for_each(|e| *e = f32::MAX);
            self.stats = RevStats::default();
            self.first_angle = nd.angle;
        } else if self.began.is_some() {
            if nd.angle <= self.last_angle {
                self.stats.backwards += 1;
            }
            self.stats.span = self.stats.span.max(nd.angle - self.first_angle);
        }
        self.last_angle = nd.angle;
        self.began?;
        self.stats.nodes += 1;
        if nd.distance > 0.0 && nd.quality == 0 {
            self.stats.no_quality += 1;
        }
        // Clockwise device angle → counter-clockwise, in [start, start + 360).
        let ccw = -(nd.angle as f64);
        let k = ((ccw - self.start) * self.per_deg).rem_euclid(360.0 * self.per_deg);
        let i = k.round() as usize;
        let span = (360.0 * self.per_deg).round() as usize;
        let i = if i >= span { 0 } else { i };
        if i < self.n && nd.distance > 0.0 {
            let e = (k - k.round()).abs() as f32;
            if e < self.err[i] {
                self.err[i] = e;
                self.readings[i] = (nd.distance.round() as i32).min(self.max_range);
            }
        }
        done
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::{Duration, Instant};

    fn enc(start: bool, deg: f32, mm: f32) -> [u8; 5] {
        let q = (deg * 64.0) as u16;
        let d = (mm * 4.0) as u16;
        [
            (10 << 2) | ((!start as u8) << 1) | start as u8,
            ((q << 1) as u8) | 1,
            (q >> 7) as u8,
            d as u8,
            (d >> 8) as u8,
        ]
    }

    #[test]
    fn nodes_and_revolutions() {
        let n = node(&enc(true, 90.5, 1234.25)).unwrap();
        assert!(n.start && n.angle == 90.5 && n.distance == 1234.25);
        let mut bad = enc(false, 10.0, 100.0);
        bad[1] &= !1;
        assert!(node(&bad).is_none());
        assert!(node(&[3, 1, 0, 0, 0]).is_none());
        let mut r = Revolution::new(360, 1.0, -180.0, 12000);
        let mut out = Vec::new();
        let t0 = Instant::now();
        assert!(
            r.push(&node(&enc(true, 0.0, 500.0)).unwrap(), t0, &mut out)
                .is_none()
        );
        // 90° clockwise is −90° counter-clockwise: index 90.
        r.push(&node(&enc(false, 90.0, 700.0)).unwrap(), t0, &mut out);
        let t1 = t0 + Duration::from_millis(180);
        let st = r.push(&node(&enc(true, 0.0, 500.0)).unwrap(), t1, &mut out);
        assert_eq!(st.map(|s| (s.nodes, s.duration)), Some((2, t1 - t0)));
        assert_eq!((out[180], out[90], out[270]), (500, 700, 12000));
        assert_eq!(
            request_with(SET_MOTOR_PWM, &[0x94, 0x02]),
            [0xA5, 0xF0, 2, 0x94, 2, 0xA5 ^ 0xF0 ^ 2 ^ 0x94 ^ 2]
        );
        let d = descriptor(&[0xA5, 0x5A, 5, 0, 0, 0x40, 0x81]).unwrap();
        assert_eq!((d.len, d.mode, d.kind), (5, 1, TYPE_SCAN));
    }

    /// Feeds `bytes` as the driver does (nodes where the checks pass, else a
    /// byte skipped), the host reading them at `rate` bytes/s; the finished
    /// revolutions' counts.
    fn revolutions(bytes: &[u8], rate: f64) -> Vec<RevStats> {
        let mut r = Revolution::new(360, 1.0, -180.0, 12000);
        let (mut out, mut done) = (Vec::new(), Vec::new());
        let t0 = Instant::now();
        let mut i = 0;
        while i + 5 <= bytes.len() {
            let at = t0 + Duration::from_secs_f64(i as f64 / rate);
            match node(&bytes[i..i + 5]) {
                Some(nd) => {
                    done.extend(r.push(&nd, at, &mut out));
                    i += 5;
                }
                None => {
                    r.skipped(1);
                    i += 1;
                }
            }
        }
        done
    }

    #[test]
    fn a_lidars_revolutions_are_plausible_and_random_bytes_are_not() {
        // An A1: 360 nodes a revolution at 5.5 Hz, quality 47 (0 with no return).
        let mut good = Vec::new();
        for k in 0..360 * 4 {
            let a = (k % 360) as f32 * 360.0 / 360.5;
            let mm = if k % 50 == 7 { 0.0 } else { 1500.0 };
            let mut b = enc(k % 360 == 0, a, mm);
            if mm == 0.0 {
                b[0] &= 3;
            }
            good.extend(b);
        }
        let revs = revolutions(&good, 360.0 * 5.5 * 5.0);
        assert_eq!(revs.len(), 3);
        for r in &revs {
            assert_eq!(r.implausible(&LIMITS), None, "{r:?}");
        }
        // Uniformly random bytes at 115200 baud.
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let noise: Vec<u8> = (0..11_520)
            .map(|_| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x as u8
            })
            .collect();
        let revs = revolutions(&noise, 11_520.0);
        assert!(revs.len() > 100, "{} revolutions in a second", revs.len());
        let believed: Vec<_> = revs
            .iter()
            .filter(|r| r.implausible(&LIMITS).is_none())
            .collect();
        assert!(believed.is_empty(), "{believed:?}");
        let why = revs[0].implausible(&LIMITS).unwrap();
        assert!(
            why.contains("revolutions/s") && why.contains("nodes"),
            "{why}"
        );
        // A revolution too slow (a stalled motor), and one of angles shuffled.
        let slow = RevStats {
            nodes: 360,
            span: 359.0,
            duration: Duration::from_millis(1500),
            ..Default::default()
        };
        assert!(
            slow.implausible(&LIMITS)
                .unwrap()
                .contains("0.7 revolutions/s")
        );
        let back = RevStats {
            nodes: 360,
            span: 359.0,
            backwards: 100,
            duration: Duration::from_millis(180),
            ..Default::default()
        };
        assert!(back.implausible(&LIMITS).unwrap().contains("backwards"));
        // Cut short: 200 nodes over 200° (noise began), and a glitch of one byte.
        let short = RevStats {
            nodes: 200,
            span: 200.0,
            duration: Duration::from_millis(100),
            ..Default::default()
        };
        assert!(short.implausible(&LIMITS).unwrap().contains("round 200°"));
        let glitch = RevStats { skipped: 1, ..back };
        assert!(
            glitch
                .implausible(&LIMITS)
                .unwrap()
                .contains("1 byte(s) skipped")
        );
    }
}
