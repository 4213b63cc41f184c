//! The protobuf wire, once: varints, tags, fixed-size and length-delimited
//! fields, written ([`Writer`]) and read ([`fields`]). Gazebo's gz-msgs
//! (`drivers/gazebo/pb.rs`) and Foxglove's messages in MCAP and on Foxglove's
//! WebSocket (`mcapfmt/protobuf.rs`) are written and read with it; each of those
//! says which fields its messages have.
//!
//! Why not `prost` (already in the tree): it is slower here, measured in one run
//! by `benches/protowire.rs` (medians of 7 alternated rounds, this machine):
//! a 1081-reading `foxglove.LaserScan` encodes in 1.5 µs (prost 1.9, 1.27x) and
//! decodes in 2.3 µs (prost 4.1, 1.77x); a 640x480 `foxglove.RawImage` encodes
//! in 26 µs (prost 52, 1.99x: its message owns a copy of the pixels) and decodes,
//! pixels copied out, in 27 µs (prost 1055 µs). Reading borrows fields from the
//! message (pixels and packed ranges are not copied until the caller does), and
//! `gazebo` and `recorder` builds need no extra dependency.

use std::fmt;

/// Wire type of varint fields (int, uint, bool, enum).
pub const VARINT: u64 = 0;
/// Wire type of 8-byte fields (double, fixed64).
pub const I64: u64 = 1;
/// Wire type of length-delimited fields (bytes, strings, messages, packed).
pub const LEN: u64 = 2;
/// Wire type of 4-byte fields (float, fixed32).
pub const I32: u64 = 5;

/// A malformed message: what was wrong (the caller says where).
#[derive(Debug, Clone, PartialEq)]
pub struct WireError(pub String);

impl fmt::Display for WireError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Protobuf writing at the end of a buffer.
pub struct Writer<'a>(pub &'a mut Vec<u8>);

impl Writer<'_> {
    pub fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.0.push(v as u8 | 0x80);
            v >>= 7;
        }
        self.0.push(v as u8);
    }
    pub fn tag(&mut self, field: u64, wire: u64) {
        self.varint(field << 3 | wire);
    }
    pub fn uint(&mut self, field: u64, v: u64) {
        self.tag(field, VARINT);
        self.varint(v);
    }
    pub fn fixed32(&mut self, field: u64, v: u32) {
        self.tag(field, I32);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn double(&mut self, field: u64, v: f64) {
        self.tag(field, I64);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    pub fn bytes(&mut self, field: u64, b: &[u8]) {
        self.tag(field, LEN);
        self.varint(b.len() as u64);
        self.0.extend_from_slice(b);
    }
    /// Packed doubles (nothing for none, as protobuf writes an empty repeated field).
    pub fn packed_doubles(&mut self, field: u64, n: usize, values: impl Iterator<Item = f64>) {
        if n == 0 {
            return;
        }
        self.tag(field, LEN);
        self.varint(8 * n as u64);
        for v in values.take(n) {
            self.0.extend_from_slice(&v.to_le_bytes());
        }
    }
    /// A nested message written by `body`: its length is put before it once
    /// known (in place: no second buffer).
    pub fn message(&mut self, field: u64, body: impl FnOnce(&mut Self)) {
        self.tag(field, LEN);
        let at = self.0.len();
        self.0.push(0);
        body(self);
        let len = self.0.len() - at - 1;
        if len < 0x80 {
            self.0[at] = len as u8;
        } else {
            let mut prefix = Vec::new();
            Writer(&mut prefix).varint(len as u64);
            self.0.splice(at..at + 1, prefix);
        }
    }
}

/// One field's value, borrowed from the message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'a> {
    Varint(u64),
    I64([u8; 8]),
    Len(&'a [u8]),
    I32([u8; 4]),
}

impl<'a> Value<'a> {
    /// An integer field (varint or fixed); 0 for bytes.
    pub fn u64(self) -> u64 {
        match self {
            Value::Varint(v) => v,
            Value::I64(b) => u64::from_le_bytes(b),
            Value::I32(b) => u32::from_le_bytes(b) as u64,
            Value::Len(_) => 0,
        }
    }
    /// A double or float field; 0 for others.
    pub fn f64(self) -> f64 {
        match self {
            Value::I64(b) => f64::from_le_bytes(b),
            Value::I32(b) => f32::from_le_bytes(b) as f64,
            _ => 0.0,
        }
    }
    /// A length-delimited field's bytes; empty for others.
    pub fn bytes(self) -> &'a [u8] {
        match self {
            Value::Len(b) => b,
            _ => &[],
        }
    }
}

/// The fields of a message, in order: (field number, value). A malformed field
/// is an error and ends the iteration.
pub struct Fields<'a> {
    data: &'a [u8],
}

/// The fields of message `data`.
pub fn fields(data: &[u8]) -> Fields<'_> {
    Fields { data }
}

fn bad(m: impl Into<String>) -> WireError {
    WireError(m.into())
}

impl<'a> Fields<'a> {
    fn varint(&mut self) -> Result<u64, WireError> {
        let mut v = 0u64;
        for i in 0..10 {
            let (&b, rest) = self
                .data
                .split_first()
                .ok_or_else(|| bad("the protobuf message ends inside a varint"))?;
            self.data = rest;
            v |= ((b & 0x7f) as u64) << (7 * i);
            if b < 0x80 {
                return Ok(v);
            }
        }
        Err(bad("a protobuf varint longer than 10 bytes"))
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], WireError> {
        if n > self.data.len() {
            return Err(bad(format!(
                "the protobuf message ends early (a field of {n} bytes, {} left)",
                self.data.len()
            )));
        }
        let (a, b) = self.data.split_at(n);
        self.data = b;
        Ok(a)
    }
    fn read_field(&mut self) -> Result<(u64, Value<'a>), WireError> {
        let key = self.varint()?;
        let value = match key & 7 {
            VARINT => Value::Varint(self.varint()?),
            I64 => Value::I64(self.take(8)?.try_into().expect("8 bytes")),
            LEN => {
                let n = self.varint()?;
                Value::Len(self.take(usize::try_from(n).unwrap_or(usize::MAX))?)
            }
            I32 => Value::I32(self.take(4)?.try_into().expect("4 bytes")),
            w => {
                return Err(bad(format!(
                    "protobuf field {} has wire type {w} (groups are not used)",
                    key >> 3
                )));
            }
        };
        Ok((key >> 3, value))
    }
}

impl<'a> Iterator for Fields<'a> {
    type Item = Result<(u64, Value<'a>), WireError>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.data.is_empty() {
            return None;
        }
        let r = self.read_field();
        if r.is_err() {
            self.data = &[];
        }
        Some(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_and_long_nested_messages() {
        let mut out = Vec::new();
        let mut w = Writer(&mut out);
        w.message(3, |w| w.bytes(1, &[7u8; 300]));
        // tag 3/LEN, length 303 as a two-byte varint, then tag 1/LEN, 300 as varint.
        assert_eq!(&out[..3], &[0x1a, 0xaf, 0x02]);
        assert_eq!(&out[3..6], &[0x0a, 0xac, 0x02]);
        assert_eq!(out.len(), 3 + 3 + 300);
        let mut f = fields(&out);
        match f.next() {
            Some(Ok((3, Value::Len(b)))) => assert_eq!(b.len(), 303),
            _ => panic!("not a nested message"),
        }
        assert!(f.next().is_none());
    }

    #[test]
    fn garbage_ends_with_an_error() {
        for data in [&[0x0au8, 0x05, 1][..], &[0xff; 11], &[0x0b], &[0x09, 1, 2]] {
            let mut f = fields(data);
            let e = f.next().unwrap().unwrap_err();
            assert!(e.0.contains("protobuf"), "{e}");
            assert!(f.next().is_none());
        }
    }
}
