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

/// Puts revolutions together: nodes in, one scan of N readings at R per degree
/// out (reading i at `start + i/R` degrees counter-clockwise, no return →
/// `max_range`) each time a node with S arrives.
pub struct Revolution {
    pub n: usize,
    pub per_deg: f64,
    pub start: f64,
    pub max_range: i32,
    readings: Vec<i32>,
    /// The distance from each reading's own angle of the node written there.
    err: Vec<f32>,
    nodes: usize,
    started: bool,
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
            nodes: 0,
            started: false,
        }
    }

    /// Adds a node; when it starts a new revolution and a whole one was gathered,
    /// the finished scan's readings are swapped into `out` and its node count returned.
    pub fn push(&mut self, nd: &Node, out: &mut Vec<i32>) -> Option<usize> {
        let mut done = None;
        if nd.start {
            if self.started && self.nodes > 0 {
                out.clear();
                out.extend_from_slice(&self.readings);
                done = Some(self.nodes);
            }
            self.started = true;
            self.readings.iter_mut().for_each(|r| *r = self.max_range);
            self.err.iter_mut().for_each(|e| *e = f32::MAX);
            self.nodes = 0;
        }
        if !self.started {
            return None;
        }
        self.nodes += 1;
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
        assert!(
            r.push(&node(&enc(true, 0.0, 500.0)).unwrap(), &mut out)
                .is_none()
        );
        // 90° clockwise is −90° counter-clockwise: index 90.
        r.push(&node(&enc(false, 90.0, 700.0)).unwrap(), &mut out);
        assert_eq!(
            r.push(&node(&enc(true, 0.0, 500.0)).unwrap(), &mut out),
            Some(2)
        );
        assert_eq!((out[180], out[90], out[270]), (500, 700, 12000));
        assert_eq!(
            request_with(SET_MOTOR_PWM, &[0x94, 0x02]),
            [0xA5, 0xF0, 2, 0x94, 2, 0xA5 ^ 0xF0 ^ 2 ^ 0x94 ^ 2]
        );
        let d = descriptor(&[0xA5, 0x5A, 5, 0, 0, 0x40, 0x81]).unwrap();
        assert_eq!((d.len, d.mode, d.kind), (5, 1, TYPE_SCAN));
    }
}
