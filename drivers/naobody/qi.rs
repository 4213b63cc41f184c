//! The qi messaging protocol (libqi, what NAOqi 2.x speaks on port 9559) over
//! plain TCP, as a client: written from libqi's documentation and sources
//! (`src/messaging/message.hpp`, the network binary protocol page, the
//! signature grammar) and checked against the real libqi (`qi` 3.1.5 on PyPI).
//!
//! - A message is a 28-byte header (magic `0x42dead42` big-endian, then little-
//!   endian: id, payload size, version 0 (u16), type (u8), flags (u8), service,
//!   object, action) and a payload.
//! - Session start: a `call` to service 0, object 0, action 8 (`authenticate`)
//!   with a capability map `{sm}`; the reply's `__qi_auth_state` must be 3 (done).
//!   A server that wants credentials (NAOqi 2.9) is refused with a clear error.
//! - Service 1 (the ServiceDirectory), object 1: `service(s)` (action 100) gives a
//!   service's id and endpoints; every object answers `metaObject(I)` (action 2)
//!   with its methods (uid, name, parameter and return signatures).
//! - Values are serialised by signature: `b` 1 byte, `c C w W i I l L` integers,
//!   `f d` IEEE floats, `s` and `r` u32 length + bytes, `[x]` u32 count + items,
//!   `{kv}` u32 count + pairs, `(...)` the members in order, `m` (dynamic) the
//!   signature as a string then the value, `+x` a bool then the value if set.
//!   Objects (`o`) are not needed by this driver and are refused.
//!
//! Defensive: every length is checked against what is left of the message and a
//! limit ([`MAX_PAYLOAD`], [`MAX_SIGNATURE`], [`MAX_DEPTH`], [`MAX_VALUES`]);
//! garbage is an error (the caller drops the connection and reconnects), never a
//! panic or an allocation bigger than the bytes that actually arrived. A call has
//! one deadline for the whole of it (a reply trickled a byte at a time times out
//! like a missing one); a service's endpoints are tried [`MAX_ENDPOINTS`] at most,
//! IP literals (or the conf's host) only, within one call's time; and a bad value
//! is shown in an error by its first [`SHOW`] characters, never formatted whole.

use std::{
    fmt,
    io::{Read, Write},
    net::{TcpStream, ToSocketAddrs},
    time::{Duration, Instant},
};

/// The magic cookie every header starts with (sent big-endian: 42 DE AD 42).
pub const MAGIC: u32 = 0x42de_ad42;
/// The header's size in bytes.
pub const HEADER: usize = 28;
/// The largest payload accepted (a k16VGA BGR frame is 14.7 MB).
pub const MAX_PAYLOAD: usize = 32 << 20;
/// The longest signature accepted, in characters.
pub const MAX_SIGNATURE: usize = 4096;
/// The deepest nesting of signatures and dynamic values accepted.
pub const MAX_DEPTH: u32 = 32;
/// The most values one message may decode into.
pub const MAX_VALUES: usize = 1 << 18;
/// The most endpoints of one service tried.
pub const MAX_ENDPOINTS: usize = 4;
/// The most characters of a value shown in a message.
pub const SHOW: usize = 120;

/// A string of at most `max` bytes that formatting stops writing into when full.
struct Capped {
    s: String,
    max: usize,
}

impl fmt::Write for Capped {
    fn write_str(&mut self, t: &str) -> fmt::Result {
        let room = self.max - self.s.len();
        if t.len() <= room {
            self.s.push_str(t);
            Ok(())
        } else {
            self.s.push_str(&t[..t.floor_char_boundary(room)]);
            Err(fmt::Error)
        }
    }
}

/// `x` formatted (Debug) to at most [`SHOW`] characters, with `…` when cut: the
/// formatting stops there, so a 30 MB value costs no more than a short one.
pub fn show(x: &impl fmt::Debug) -> String {
    let mut c = Capped {
        s: String::new(),
        max: SHOW,
    };
    if fmt::write(&mut c, format_args!("{x:?}")).is_err() {
        c.s.push('…');
    }
    c.s
}

/// A text of at most [`SHOW`] characters, with `…` when cut.
pub fn show_text(t: &str) -> String {
    if t.len() <= SHOW {
        t.to_string()
    } else {
        format!("{}…", &t[..t.floor_char_boundary(SHOW)])
    }
}

/// Message types (libqi `Message::Type`).
pub mod ty {
    pub const CALL: u8 = 1;
    pub const REPLY: u8 = 2;
    pub const ERROR: u8 = 3;
    pub const POST: u8 = 4;
    pub const EVENT: u8 = 5;
    pub const CAPABILITY: u8 = 6;
    pub const CANCEL: u8 = 7;
    pub const CANCELED: u8 = 8;
}

/// Flag: the payload is a dynamic value (`m`) instead of the expected type.
pub const FLAG_DYNAMIC_PAYLOAD: u8 = 1;

/// What went wrong talking qi.
#[derive(Debug, thiserror::Error)]
pub enum QiError {
    #[error("{0}")]
    Io(String),
    #[error("garbage on the connection: {0}")]
    Garbage(String),
    #[error("no reply in {0} ms")]
    Timeout(u128),
    #[error("{0}")]
    Remote(String),
    #[error("{0}")]
    Protocol(String),
}

impl QiError {
    fn io(e: std::io::Error) -> QiError {
        match e.kind() {
            std::io::ErrorKind::UnexpectedEof => QiError::Io("the connection was closed".into()),
            _ => QiError::Io(e.to_string()),
        }
    }
}

/// A message header.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Header {
    pub id: u32,
    pub size: u32,
    pub version: u16,
    pub ty: u8,
    pub flags: u8,
    pub service: u32,
    pub object: u32,
    pub action: u32,
}

impl Header {
    pub fn encode(&self) -> [u8; HEADER] {
        let mut b = [0u8; HEADER];
        b[0..4].copy_from_slice(&MAGIC.to_be_bytes());
        b[4..8].copy_from_slice(&self.id.to_le_bytes());
        b[8..12].copy_from_slice(&self.size.to_le_bytes());
        b[12..14].copy_from_slice(&self.version.to_le_bytes());
        b[14] = self.ty;
        b[15] = self.flags;
        b[16..20].copy_from_slice(&self.service.to_le_bytes());
        b[20..24].copy_from_slice(&self.object.to_le_bytes());
        b[24..28].copy_from_slice(&self.action.to_le_bytes());
        b
    }

    /// Parses and checks a header: the magic, version 0, a known type, a size
    /// within [`MAX_PAYLOAD`].
    pub fn decode(b: &[u8; HEADER]) -> Result<Header, QiError> {
        let u32le = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        let magic = u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
        if magic != MAGIC {
            return Err(QiError::Garbage(format!(
                "a message starts with {:02x} {:02x} {:02x} {:02x}, not qi's magic 42 de ad 42 \
                 (is this port NAOqi's?)",
                b[0], b[1], b[2], b[3]
            )));
        }
        let h = Header {
            id: u32le(4),
            size: u32le(8),
            version: u16::from_le_bytes([b[12], b[13]]),
            ty: b[14],
            flags: b[15],
            service: u32le(16),
            object: u32le(20),
            action: u32le(24),
        };
        if h.version != 0 {
            return Err(QiError::Garbage(format!(
                "header version {} (libqi speaks version 0)",
                h.version
            )));
        }
        if !(ty::CALL..=ty::CANCELED).contains(&h.ty) {
            return Err(QiError::Garbage(format!("message type {}", h.ty)));
        }
        if h.size as usize > MAX_PAYLOAD {
            return Err(QiError::Garbage(format!(
                "a payload of {} bytes (more than the {} MB accepted)",
                h.size,
                MAX_PAYLOAD >> 20
            )));
        }
        Ok(h)
    }
}

/// A message: its header and payload.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    pub header: Header,
    pub payload: Vec<u8>,
}

/// Reads one message. The payload buffer grows as bytes arrive, so a header
/// that lies about its size costs no more memory than what was sent.
pub fn read_message(r: &mut impl Read) -> Result<Message, QiError> {
    let mut hb = [0u8; HEADER];
    r.read_exact(&mut hb).map_err(QiError::io)?;
    let header = Header::decode(&hb)?;
    let size = header.size as usize;
    let mut payload = Vec::with_capacity(size.min(1 << 20));
    r.take(size as u64)
        .read_to_end(&mut payload)
        .map_err(QiError::io)?;
    if payload.len() != size {
        return Err(QiError::Garbage(format!(
            "the connection was closed {} bytes into a {size}-byte payload",
            payload.len()
        )));
    }
    Ok(Message { header, payload })
}

/// Writes one message.
pub fn write_message(
    w: &mut impl Write,
    mut header: Header,
    payload: &[u8],
) -> Result<(), QiError> {
    header.size = u32::try_from(payload.len())
        .map_err(|_| QiError::Protocol("a payload over 4 GB".into()))?;
    let mut out = Vec::with_capacity(HEADER + payload.len());
    out.extend_from_slice(&header.encode());
    out.extend_from_slice(payload);
    w.write_all(&out).map_err(QiError::io)?;
    w.flush().map_err(QiError::io)
}

// ---------------------------------------------------------------- signatures

/// A type signature (libqi's `qi::Signature`), annotations dropped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Sig {
    Void,
    /// `_`: the element type of an empty dynamic container.
    None,
    Bool,
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
    Str,
    Raw,
    Dynamic,
    Object,
    Unknown,
    List(Box<Sig>),
    Map(Box<Sig>, Box<Sig>),
    Tuple(Vec<Sig>),
    Optional(Box<Sig>),
    VarArgs(Box<Sig>),
    KwArgs(Box<Sig>),
}

impl Sig {
    /// Parses a whole signature.
    pub fn parse(s: &str) -> Result<Sig, QiError> {
        if s.len() > MAX_SIGNATURE {
            return Err(QiError::Garbage(format!(
                "a signature of {} characters (at most {MAX_SIGNATURE})",
                s.len()
            )));
        }
        let b = s.as_bytes();
        let mut i = 0;
        let sig = parse_one(b, &mut i, 0)
            .map_err(|e| QiError::Garbage(format!("signature `{}`: {e}", echo(s))))?;
        if i != b.len() {
            return Err(QiError::Garbage(format!(
                "signature `{}`: unexpected `{}` at {i}",
                echo(s),
                b[i] as char
            )));
        }
        Ok(sig)
    }

    /// The least number of bytes a value of this type takes (for checking a
    /// count against what is left).
    fn min_size(&self) -> usize {
        match self {
            Sig::Void | Sig::None | Sig::Unknown => 0,
            Sig::Bool | Sig::I8 | Sig::U8 | Sig::Optional(_) => 1,
            Sig::I16 | Sig::U16 => 2,
            Sig::I32 | Sig::U32 | Sig::F32 | Sig::Str | Sig::Raw | Sig::Dynamic => 4,
            Sig::List(_) | Sig::Map(..) | Sig::VarArgs(_) | Sig::KwArgs(_) => 4,
            Sig::I64 | Sig::U64 | Sig::F64 => 8,
            Sig::Object => 4,
            Sig::Tuple(m) => m.iter().map(Sig::min_size).sum(),
        }
    }
}

fn echo(s: &str) -> String {
    if s.chars().count() <= 80 {
        s.to_string()
    } else {
        format!("{}…", s.chars().take(80).collect::<String>())
    }
}

fn parse_one(b: &[u8], i: &mut usize, depth: u32) -> Result<Sig, String> {
    if depth > MAX_DEPTH {
        return Err(format!("nested deeper than {MAX_DEPTH}"));
    }
    let Some(&c) = b.get(*i) else {
        return Err("it ends early".into());
    };
    *i += 1;
    let sig = match c {
        b'v' => Sig::Void,
        b'_' => Sig::None,
        b'b' => Sig::Bool,
        b'c' => Sig::I8,
        b'C' => Sig::U8,
        b'w' => Sig::I16,
        b'W' => Sig::U16,
        b'i' => Sig::I32,
        b'I' => Sig::U32,
        b'l' => Sig::I64,
        b'L' => Sig::U64,
        b'f' => Sig::F32,
        b'd' => Sig::F64,
        b's' => Sig::Str,
        b'r' => Sig::Raw,
        b'm' => Sig::Dynamic,
        b'o' => Sig::Object,
        b'X' => Sig::Unknown,
        b'+' => Sig::Optional(Box::new(parse_one(b, i, depth + 1)?)),
        b'#' => Sig::VarArgs(Box::new(parse_one(b, i, depth + 1)?)),
        b'~' => Sig::KwArgs(Box::new(parse_one(b, i, depth + 1)?)),
        b'[' => {
            let e = parse_one(b, i, depth + 1)?;
            expect(b, i, b']')?;
            Sig::List(Box::new(e))
        }
        b'{' => {
            let k = parse_one(b, i, depth + 1)?;
            let v = parse_one(b, i, depth + 1)?;
            expect(b, i, b'}')?;
            Sig::Map(Box::new(k), Box::new(v))
        }
        b'(' => {
            let mut m = Vec::new();
            while b.get(*i) != Some(&b')') {
                if *i >= b.len() {
                    return Err("a `(` is not closed".into());
                }
                m.push(parse_one(b, i, depth + 1)?);
            }
            *i += 1;
            Sig::Tuple(m)
        }
        other => return Err(format!("unknown type `{}` at {}", other as char, *i - 1)),
    };
    // An annotation (`<Name,field,...>`, possibly nested) follows a type.
    if b.get(*i) == Some(&b'<') {
        let mut level = 0usize;
        while let Some(&c) = b.get(*i) {
            *i += 1;
            match c {
                b'<' => level += 1,
                b'>' => {
                    level -= 1;
                    if level == 0 {
                        break;
                    }
                }
                _ => {}
            }
        }
        if level != 0 {
            return Err("an annotation `<` is not closed".into());
        }
    }
    Ok(sig)
}

fn expect(b: &[u8], i: &mut usize, c: u8) -> Result<(), String> {
    if b.get(*i) == Some(&c) {
        *i += 1;
        Ok(())
    } else {
        Err(format!("expected `{}` at {}", c as char, *i))
    }
}

impl fmt::Display for Sig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = match self {
            Sig::Void => "v",
            Sig::None => "_",
            Sig::Bool => "b",
            Sig::I8 => "c",
            Sig::U8 => "C",
            Sig::I16 => "w",
            Sig::U16 => "W",
            Sig::I32 => "i",
            Sig::U32 => "I",
            Sig::I64 => "l",
            Sig::U64 => "L",
            Sig::F32 => "f",
            Sig::F64 => "d",
            Sig::Str => "s",
            Sig::Raw => "r",
            Sig::Dynamic => "m",
            Sig::Object => "o",
            Sig::Unknown => "X",
            Sig::List(e) => return write!(f, "[{e}]"),
            Sig::Map(k, v) => return write!(f, "{{{k}{v}}}"),
            Sig::Tuple(m) => {
                f.write_str("(")?;
                for s in m {
                    write!(f, "{s}")?;
                }
                return f.write_str(")");
            }
            Sig::Optional(e) => return write!(f, "+{e}"),
            Sig::VarArgs(e) => return write!(f, "#{e}"),
            Sig::KwArgs(e) => return write!(f, "~{e}"),
        };
        f.write_str(c)
    }
}

// -------------------------------------------------------------------- values

/// A decoded value. Dynamic values are unwrapped into what they hold.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Void,
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f32),
    Double(f64),
    /// A string's bytes (libqi strings are not checked for UTF-8).
    Str(Vec<u8>),
    Raw(Vec<u8>),
    List(Vec<Value>),
    Map(Vec<(Value, Value)>),
    Tuple(Vec<Value>),
    /// An unset optional.
    Nothing,
}

impl Value {
    pub fn str(s: &str) -> Value {
        Value::Str(s.as_bytes().to_vec())
    }
    /// Any number as f64.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::Bool(b) => Some(b as u8 as f64),
            Value::Int(i) => Some(i as f64),
            Value::UInt(u) => Some(u as f64),
            Value::Float(x) => Some(x as f64),
            Value::Double(x) => Some(x),
            _ => None,
        }
    }
    /// A whole number as i64 (a float must be whole).
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            Value::Bool(b) => Some(b as i64),
            Value::Int(i) => Some(i),
            Value::UInt(u) => i64::try_from(u).ok(),
            Value::Float(_) | Value::Double(_) => {
                let x = self.as_f64()?;
                (x.fract() == 0.0 && x.abs() < 9e15).then_some(x as i64)
            }
            _ => None,
        }
    }
    /// A string or raw buffer's bytes.
    pub fn bytes(&self) -> Option<&[u8]> {
        match self {
            Value::Str(b) | Value::Raw(b) => Some(b),
            _ => None,
        }
    }
    /// A string as text (lossy).
    pub fn text(&self) -> Option<String> {
        match self {
            Value::Str(b) => Some(String::from_utf8_lossy(b).into_owned()),
            _ => None,
        }
    }
    /// The items of a list or tuple.
    pub fn items(&self) -> Option<&[Value]> {
        match self {
            Value::List(v) | Value::Tuple(v) => Some(v),
            _ => None,
        }
    }
    /// A map's value under the string key `key`.
    pub fn get(&self, key: &str) -> Option<&Value> {
        match self {
            Value::Map(m) => m
                .iter()
                .find(|(k, _)| k.bytes() == Some(key.as_bytes()))
                .map(|(_, v)| v),
            _ => None,
        }
    }
    /// The signature a dynamic value of this is sent with.
    pub fn sig(&self) -> Sig {
        match self {
            Value::Void | Value::Nothing => Sig::Void,
            Value::Bool(_) => Sig::Bool,
            Value::Int(i) if i32::try_from(*i).is_ok() => Sig::I32,
            Value::Int(_) => Sig::I64,
            Value::UInt(u) if u32::try_from(*u).is_ok() => Sig::U32,
            Value::UInt(_) => Sig::U64,
            Value::Float(_) => Sig::F32,
            Value::Double(_) => Sig::F64,
            Value::Str(_) => Sig::Str,
            Value::Raw(_) => Sig::Raw,
            Value::List(v) => {
                let first = v.first().map(Value::sig);
                match first {
                    Some(s) if v.iter().all(|x| x.sig() == s) => Sig::List(Box::new(s)),
                    _ => Sig::List(Box::new(Sig::Dynamic)),
                }
            }
            Value::Map(m) => {
                let k = m.first().map(|(k, _)| k.sig());
                let v = m.first().map(|(_, v)| v.sig());
                match (k, v) {
                    (Some(k), Some(v)) if m.iter().all(|(a, b)| a.sig() == k && b.sig() == v) => {
                        Sig::Map(Box::new(k), Box::new(v))
                    }
                    _ => Sig::Map(Box::new(Sig::Dynamic), Box::new(Sig::Dynamic)),
                }
            }
            Value::Tuple(v) => Sig::Tuple(v.iter().map(Value::sig).collect()),
        }
    }
}

/// Reads values out of a payload, within its bounds and the limits.
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    values: usize,
}

impl<'a> Reader<'a> {
    pub fn new(buf: &'a [u8]) -> Reader<'a> {
        Reader {
            buf,
            pos: 0,
            values: 0,
        }
    }

    /// Bytes not read yet.
    pub fn left(&self) -> usize {
        self.buf.len() - self.pos
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], QiError> {
        if n > self.left() {
            return Err(QiError::Garbage(format!(
                "a value needs {n} bytes at offset {} but only {} are left",
                self.pos,
                self.left()
            )));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, QiError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    /// A count of items of type `item`, checked against what is left.
    fn count(&mut self, item: usize) -> Result<usize, QiError> {
        let n = self.u32()? as usize;
        if n.saturating_mul(item.max(1)) > self.left().max(if item == 0 { MAX_VALUES } else { 0 }) {
            return Err(QiError::Garbage(format!(
                "a count of {n} items at offset {} with {} bytes left",
                self.pos - 4,
                self.left()
            )));
        }
        Ok(n)
    }

    /// Reads one value of type `sig`.
    pub fn value(&mut self, sig: &Sig) -> Result<Value, QiError> {
        self.read(sig, 0)
    }

    fn read(&mut self, sig: &Sig, depth: u32) -> Result<Value, QiError> {
        if depth > MAX_DEPTH {
            return Err(QiError::Garbage(format!(
                "values nested deeper than {MAX_DEPTH}"
            )));
        }
        self.values += 1;
        if self.values > MAX_VALUES {
            return Err(QiError::Garbage(format!(
                "more than {MAX_VALUES} values in one message"
            )));
        }
        Ok(match sig {
            Sig::Void | Sig::None | Sig::Unknown => Value::Void,
            Sig::Bool => Value::Bool(self.take(1)?[0] != 0),
            Sig::I8 => Value::Int(self.take(1)?[0] as i8 as i64),
            Sig::U8 => Value::UInt(self.take(1)?[0] as u64),
            Sig::I16 => {
                let b = self.take(2)?;
                Value::Int(i16::from_le_bytes([b[0], b[1]]) as i64)
            }
            Sig::U16 => {
                let b = self.take(2)?;
                Value::UInt(u16::from_le_bytes([b[0], b[1]]) as u64)
            }
            Sig::I32 => Value::Int(self.u32()? as i32 as i64),
            Sig::U32 => Value::UInt(self.u32()? as u64),
            Sig::I64 | Sig::U64 | Sig::F64 => {
                let b: [u8; 8] = self.take(8)?.try_into().expect("8 bytes");
                match sig {
                    Sig::I64 => Value::Int(i64::from_le_bytes(b)),
                    Sig::U64 => Value::UInt(u64::from_le_bytes(b)),
                    _ => Value::Double(f64::from_le_bytes(b)),
                }
            }
            Sig::F32 => Value::Float(f32::from_bits(self.u32()?)),
            Sig::Str | Sig::Raw => {
                let n = self.count(1)?;
                let b = self.take(n)?.to_vec();
                if *sig == Sig::Str {
                    Value::Str(b)
                } else {
                    Value::Raw(b)
                }
            }
            Sig::Dynamic => {
                let n = self.count(1)?;
                let s = self.take(n)?;
                let s = std::str::from_utf8(s).map_err(|_| {
                    QiError::Garbage("a dynamic value's signature is not text".into())
                })?;
                let inner = Sig::parse(s)?;
                self.read(&inner, depth + 1)?
            }
            Sig::Optional(e) => {
                if self.take(1)?[0] != 0 {
                    self.read(e, depth + 1)?
                } else {
                    Value::Nothing
                }
            }
            Sig::List(e) | Sig::VarArgs(e) => {
                let n = self.count(e.min_size())?;
                let mut v = Vec::with_capacity(n.min(4096));
                for _ in 0..n {
                    v.push(self.read(e, depth + 1)?);
                }
                Value::List(v)
            }
            Sig::Map(..) | Sig::KwArgs(_) => {
                let (k, e) = match sig {
                    Sig::Map(k, e) => (k.as_ref().clone(), e.as_ref()),
                    Sig::KwArgs(e) => (Sig::Str, e.as_ref()),
                    _ => unreachable!("matched above"),
                };
                let n = self.count(k.min_size() + e.min_size())?;
                let mut m = Vec::with_capacity(n.min(4096));
                for _ in 0..n {
                    let key = self.read(&k, depth + 1)?;
                    let val = self.read(e, depth + 1)?;
                    m.push((key, val));
                }
                Value::Map(m)
            }
            Sig::Tuple(members) => {
                let mut v = Vec::with_capacity(members.len());
                for s in members {
                    v.push(self.read(s, depth + 1)?);
                }
                Value::Tuple(v)
            }
            Sig::Object => {
                return Err(QiError::Protocol(
                    "an object (`o`) in a reply: this client does not take remote objects".into(),
                ));
            }
        })
    }
}

/// Decodes a whole payload as one value of `sig` (trailing bytes are garbage).
pub fn decode(payload: &[u8], sig: &Sig) -> Result<Value, QiError> {
    let mut r = Reader::new(payload);
    let v = r.value(sig)?;
    if r.left() != 0 {
        return Err(QiError::Garbage(format!(
            "{} bytes after a `{sig}` value",
            r.left()
        )));
    }
    Ok(v)
}

/// Writes `v` as a value of type `sig`, converting numbers between the numeric
/// types and wrapping a dynamic (`m`) with the value's own signature, as libqi
/// converts call arguments. A value that does not fit is an error naming both.
pub fn encode(v: &Value, sig: &Sig, out: &mut Vec<u8>) -> Result<(), String> {
    let mismatch = || format!("cannot send {v:?} as `{sig}`");
    let num = || v.as_f64().ok_or_else(mismatch);
    let int = |lo: i64, hi: i64| -> Result<i64, String> {
        let x = match v {
            Value::Float(_) | Value::Double(_) => v.as_f64().map(|x| x.round() as i64),
            Value::UInt(u) => i64::try_from(*u).ok(),
            _ => v.as_i64(),
        }
        .ok_or_else(mismatch)?;
        if (lo..=hi).contains(&x) {
            Ok(x)
        } else {
            Err(format!("{x} does not fit `{sig}`"))
        }
    };
    match sig {
        Sig::Void | Sig::None => {}
        Sig::Bool => out.push((num()? != 0.0) as u8),
        Sig::I8 => out.push(int(i8::MIN as i64, i8::MAX as i64)? as i8 as u8),
        Sig::U8 => out.push(int(0, u8::MAX as i64)? as u8),
        Sig::I16 => {
            out.extend_from_slice(&(int(i16::MIN as i64, i16::MAX as i64)? as i16).to_le_bytes())
        }
        Sig::U16 => out.extend_from_slice(&(int(0, u16::MAX as i64)? as u16).to_le_bytes()),
        Sig::I32 => {
            out.extend_from_slice(&(int(i32::MIN as i64, i32::MAX as i64)? as i32).to_le_bytes())
        }
        Sig::U32 => out.extend_from_slice(&(int(0, u32::MAX as i64)? as u32).to_le_bytes()),
        Sig::I64 => out.extend_from_slice(&int(i64::MIN, i64::MAX)?.to_le_bytes()),
        Sig::U64 => out.extend_from_slice(&(int(0, i64::MAX)? as u64).to_le_bytes()),
        Sig::F32 => out.extend_from_slice(&(num()? as f32).to_le_bytes()),
        Sig::F64 => out.extend_from_slice(&num()?.to_le_bytes()),
        Sig::Str | Sig::Raw => {
            let b = v.bytes().ok_or_else(mismatch)?;
            out.extend_from_slice(&(b.len() as u32).to_le_bytes());
            out.extend_from_slice(b);
        }
        Sig::Dynamic => {
            let s = v.sig();
            let text = s.to_string();
            out.extend_from_slice(&(text.len() as u32).to_le_bytes());
            out.extend_from_slice(text.as_bytes());
            encode(v, &s, out)?;
        }
        Sig::Optional(e) => match v {
            Value::Nothing | Value::Void => out.push(0),
            _ => {
                out.push(1);
                encode(v, e, out)?;
            }
        },
        Sig::List(e) | Sig::VarArgs(e) => {
            let items = v.items().ok_or_else(mismatch)?;
            out.extend_from_slice(&(items.len() as u32).to_le_bytes());
            for x in items {
                encode(x, e, out)?;
            }
        }
        Sig::Map(k, e) => {
            let Value::Map(m) = v else {
                return Err(mismatch());
            };
            out.extend_from_slice(&(m.len() as u32).to_le_bytes());
            for (a, b) in m {
                encode(a, k, out)?;
                encode(b, e, out)?;
            }
        }
        Sig::KwArgs(e) => encode(v, &Sig::Map(Box::new(Sig::Str), e.clone()), out)?,
        Sig::Tuple(members) => {
            let items = v.items().ok_or_else(mismatch)?;
            if items.len() != members.len() {
                return Err(format!(
                    "{} values where `{sig}` takes {}",
                    items.len(),
                    members.len()
                ));
            }
            for (x, s) in items.iter().zip(members) {
                encode(x, s, out)?;
            }
        }
        Sig::Object | Sig::Unknown => return Err(format!("this client cannot send `{sig}`")),
    }
    Ok(())
}

// ------------------------------------------------------------- connection

/// Service 0 (the server) and its `authenticate` action.
pub const SERVICE_SERVER: u32 = 0;
pub const ACTION_AUTHENTICATE: u32 = 8;
/// Service 1, the ServiceDirectory; the main object of every service is 1.
pub const SERVICE_DIRECTORY: u32 = 1;
pub const MAIN_OBJECT: u32 = 1;
/// Every object's `metaObject(I)` action, and the ServiceDirectory's `service(s)`.
pub const ACTION_METAOBJECT: u32 = 2;
pub const ACTION_SERVICE: u32 = 100;

/// The libqi signature of a `MetaObject`.
pub const METAOBJECT_SIG: &str = "({I(Issss[(ss)<MetaMethodParameter,name,description>]s)<MetaMethod,uid,returnSignature,name,parametersSignature,description,parameters,returnDescription>}{I(Iss)<MetaSignal,uid,name,signature>}{I(Iss)<MetaProperty,uid,name,signature>}s)<MetaObject,methods,signals,properties,description>";

/// One connection to a qi endpoint, authenticated; calls are synchronous.
pub struct Conn {
    stream: TcpStream,
    next_id: u32,
    timeout: Duration,
    /// `host:port`, for messages.
    pub endpoint: String,
}

impl Conn {
    /// Connects to `host:port` within `timeout` and authenticates.
    pub fn connect(host: &str, port: u16, timeout: Duration) -> Result<Conn, QiError> {
        Conn::connect_by(host, port, timeout, Instant::now() + timeout)
    }

    /// Connects and authenticates by `end` (each call then waits `timeout`).
    fn connect_by(host: &str, port: u16, timeout: Duration, end: Instant) -> Result<Conn, QiError> {
        let endpoint = format!("{host}:{port}");
        let addrs: Vec<_> = (host, port)
            .to_socket_addrs()
            .map_err(|e| QiError::Io(format!("cannot resolve {host}: {e}")))?
            .take(MAX_ENDPOINTS)
            .collect();
        let mut last = QiError::Io(format!("{host} has no address"));
        for a in addrs {
            let left = end.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(QiError::Timeout(timeout.as_millis()));
            }
            match TcpStream::connect_timeout(&a, left) {
                Ok(stream) => {
                    let _ = stream.set_nodelay(true);
                    stream
                        .set_read_timeout(Some(timeout))
                        .and_then(|_| stream.set_write_timeout(Some(timeout)))
                        .map_err(QiError::io)?;
                    let mut c = Conn {
                        stream,
                        next_id: 0,
                        timeout: left,
                        endpoint: endpoint.clone(),
                    };
                    c.authenticate()?;
                    c.set_timeout(timeout);
                    return Ok(c);
                }
                Err(e) => last = QiError::io(e),
            }
        }
        Err(last)
    }

    /// The capability exchange: `authenticate({sm})` on service 0.
    fn authenticate(&mut self) -> Result<(), QiError> {
        let caps = Value::Map(vec![
            (Value::str("ClientServerSocket"), Value::Bool(true)),
            (Value::str("MessageFlags"), Value::Bool(true)),
        ]);
        let sig = Sig::parse("{sm}")?;
        let mut p = Vec::new();
        encode(&caps, &sig, &mut p).map_err(QiError::Protocol)?;
        match self.call_raw(SERVICE_SERVER, 0, ACTION_AUTHENTICATE, &p) {
            Ok((flags, payload)) => {
                let v = decode_reply(&payload, flags, &sig)?;
                let state = v.get("__qi_auth_state").and_then(Value::as_i64);
                match state {
                    Some(3) => Ok(()),
                    Some(2) | Some(1) => Err(QiError::Remote(
                        "NAOqi asks for credentials (NAOqi 2.9 authenticates every client, over TLS): \
                         naobody does not support that; see docs/nao.md"
                            .into(),
                    )),
                    _ => Err(QiError::Garbage(format!(
                        "the authentication reply has no `__qi_auth_state` 3 ({})",
                        show(&v)
                    ))),
                }
            }
            // A libqi older than authentication (NAOqi 2.1) has no service 0 and
            // answers with an error; it takes calls without it.
            Err(QiError::Remote(e)) if e.contains("can't find service") => Ok(()),
            Err(QiError::Remote(e)) => Err(QiError::Remote(format!(
                "NAOqi refused the connection: {e} (NAOqi 2.9 needs TLS and credentials, not supported; see docs/nao.md)"
            ))),
            Err(e) => Err(e),
        }
    }

    /// Sends a call and waits for its reply: (flags, payload), or the remote
    /// error's text. Events and capability messages on the way are skipped.
    pub fn call_raw(
        &mut self,
        service: u32,
        object: u32,
        action: u32,
        payload: &[u8],
    ) -> Result<(u8, Vec<u8>), QiError> {
        self.next_id = self.next_id.wrapping_add(1).max(DETACHED_ID + 1);
        let id = self.next_id;
        let h = Header {
            id,
            ty: ty::CALL,
            service,
            object,
            action,
            ..Header::default()
        };
        // One deadline for the whole call: writing, and reading whatever comes
        // until the reply (a reply trickled byte by byte does not extend it).
        let mut io = Timed {
            stream: &self.stream,
            end: Instant::now() + self.timeout,
        };
        let r = write_message(&mut io, h, payload);
        r.map_err(|e| self.timed(e))?;
        loop {
            let mut io = Timed {
                stream: &self.stream,
                end: io.end,
            };
            let m = read_message(&mut io).map_err(|e| self.timed(e))?;
            let h = m.header;
            if h.id != id || !matches!(h.ty, ty::REPLY | ty::ERROR | ty::CANCELED) {
                // An answer to an earlier call, an event, a capability message;
                // a stream of them does not hold the call past its deadline.
                if Instant::now() > io.end {
                    return Err(QiError::Timeout(self.timeout.as_millis()));
                }
                continue;
            }
            return match h.ty {
                ty::REPLY => Ok((h.flags, m.payload)),
                ty::ERROR => {
                    let v = decode(&m.payload, &Sig::Dynamic)?;
                    Err(QiError::Remote(match v.bytes() {
                        Some(b) => show_text(&String::from_utf8_lossy(&b[..b.len().min(SHOW * 4)])),
                        None => show(&v),
                    }))
                }
                _ => Err(QiError::Remote("the call was cancelled".into())),
            };
        }
    }

    /// Sets how long a call may wait for its reply.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
        let _ = self.stream.set_read_timeout(Some(timeout));
        let _ = self.stream.set_write_timeout(Some(timeout));
    }

    fn timed(&self, e: QiError) -> QiError {
        match &e {
            QiError::Io(s)
                if s.contains("timed out")
                    || s.contains("Resource temporarily unavailable")
                    || s.contains(DEADLINE) =>
            {
                QiError::Timeout(self.timeout.as_millis())
            }
            _ => e,
        }
    }
}

const DEADLINE: &str = "the call's deadline passed";

/// A stream with one deadline: each read or write waits at most what is left of it.
struct Timed<'a> {
    stream: &'a TcpStream,
    end: Instant,
}

impl Timed<'_> {
    fn left(&self) -> std::io::Result<Duration> {
        let left = self.end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::Error::new(std::io::ErrorKind::TimedOut, DEADLINE));
        }
        Ok(left)
    }
}

impl Read for Timed<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = self.left()?;
        self.stream.set_read_timeout(Some(left))?;
        let mut s = self.stream;
        s.read(buf)
    }
}

impl Write for Timed<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let left = self.left()?;
        self.stream.set_write_timeout(Some(left))?;
        let mut s = self.stream;
        s.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A reply's value: of the method's return type, or a dynamic if the flag says so.
pub fn decode_reply(payload: &[u8], flags: u8, sig: &Sig) -> Result<Value, QiError> {
    if flags & FLAG_DYNAMIC_PAYLOAD != 0 {
        decode(payload, &Sig::Dynamic)
    } else {
        decode(payload, sig)
    }
}

/// One method of an object.
#[derive(Clone, Debug, PartialEq)]
pub struct Method {
    pub uid: u32,
    pub name: String,
    /// The parameters, a tuple.
    pub params: Sig,
    pub ret: Sig,
}

/// Reads a `MetaObject` reply into its methods.
pub fn methods_of(meta: &Value) -> Result<Vec<Method>, QiError> {
    let bad = |what: &str| QiError::Garbage(format!("a metaObject reply with {what}"));
    let fields = meta.items().ok_or_else(|| bad("no fields"))?;
    let Some(Value::Map(methods)) = fields.first() else {
        return Err(bad("no method map"));
    };
    let mut out = Vec::with_capacity(methods.len());
    for (_, m) in methods {
        let f = m
            .items()
            .ok_or_else(|| bad("a method that is not a struct"))?;
        if f.len() < 4 {
            return Err(bad("a method of fewer than 4 fields"));
        }
        let text = |v: &Value| v.text().ok_or_else(|| bad("a name that is not a string"));
        let uid = f[0]
            .as_i64()
            .ok_or_else(|| bad("a uid that is not a number"))? as u32;
        let params = Sig::parse(&text(&f[3])?)?;
        let params = match params {
            Sig::Tuple(_) => params,
            other => Sig::Tuple(vec![other]),
        };
        out.push(Method {
            uid,
            ret: Sig::parse(&text(&f[1])?)?,
            name: text(&f[2])?,
            params,
        });
    }
    Ok(out)
}

/// A `tcp://HOST:PORT` endpoint (`tcps://` and others are refused with the reason).
pub fn parse_url(url: &str) -> Result<(String, u16), String> {
    let rest = if let Some(r) = url.strip_prefix("tcp://") {
        r
    } else if url.starts_with("tcps://") {
        return Err(format!(
            "`{url}`: tcps (TLS, NAOqi 2.9) is not supported; use NAOqi's plain tcp:// endpoint (port 9559 on NAOqi 2.1/2.5)"
        ));
    } else {
        return Err(format!("`{url}`: expected tcp://HOST:PORT"));
    };
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) if !h.is_empty() => (h, p),
        _ => return Err(format!("`{url}`: expected tcp://HOST:PORT")),
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let port: u16 = port
        .trim_end_matches('/')
        .parse()
        .ok()
        .filter(|p| *p > 0)
        .ok_or_else(|| format!("`{url}`: the port must be 1..65535"))?;
    Ok((host.to_string(), port))
}

/// A service found through the ServiceDirectory.
#[derive(Clone, Debug)]
pub struct Service {
    pub name: String,
    pub id: u32,
    /// Index of its connection in the session.
    conn: usize,
    pub methods: Vec<Method>,
}

impl Service {
    /// The method `name` taking `arity` arguments, if the service has one.
    pub fn method(&self, name: &str, arity: usize) -> Option<&Method> {
        self.methods
            .iter()
            .find(|m| m.name == name && matches!(&m.params, Sig::Tuple(p) if p.len() == arity))
    }
    /// Whether the service has a method called `name`.
    pub fn has(&self, name: &str) -> bool {
        self.methods.iter().any(|m| m.name == name)
    }
}

/// A client session: the connection to the ServiceDirectory and to the
/// endpoints of the services used.
pub struct Session {
    /// `host:port` of the ServiceDirectory.
    pub url: String,
    host: String,
    port: u16,
    conns: Vec<Conn>,
    sd: Service,
    timeout: Duration,
}

impl Session {
    /// Connects to the ServiceDirectory at `host:port`.
    pub fn connect(host: &str, port: u16, timeout: Duration) -> Result<Session, QiError> {
        let mut conn = Conn::connect(host, port, timeout)?;
        let methods = meta_object(&mut conn, SERVICE_DIRECTORY)?;
        let sd = Service {
            name: "ServiceDirectory".into(),
            id: SERVICE_DIRECTORY,
            conn: 0,
            methods,
        };
        Ok(Session {
            url: format!("tcp://{host}:{port}"),
            host: host.to_string(),
            port,
            conns: vec![conn],
            sd,
            timeout,
        })
    }

    /// Sets how long a call may wait for its reply, on every connection.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
        for c in &mut self.conns {
            c.set_timeout(timeout);
        }
    }

    /// The service `name`, or `Ok(None)` when the ServiceDirectory does not know it.
    pub fn service(&mut self, name: &str) -> Result<Option<Service>, QiError> {
        let sd = self.sd.clone();
        let info = match self.call(&sd, "service", &[Value::str(name)]) {
            Ok(v) => v,
            Err(QiError::Remote(e))
                // libqi: "Cannot find service 'NAME' in index".
                if e.contains("Cannot find service") || e.contains("not found") =>
            {
                return Ok(None);
            }
            Err(e) => return Err(e),
        };
        // ServiceInfo: (name s, serviceId I, machineId s, processId I, endpoints [s], sessionId s, ...)
        let f = info
            .items()
            .ok_or_else(|| QiError::Garbage("a ServiceInfo that is not a struct".into()))?;
        let id = f
            .get(1)
            .and_then(Value::as_i64)
            .ok_or_else(|| QiError::Garbage("a ServiceInfo without a service id".into()))?
            as u32;
        let endpoints: Vec<String> = f
            .get(4)
            .and_then(Value::items)
            .map(|v| v.iter().filter_map(Value::text).collect())
            .unwrap_or_default();
        let conn = self.conn_for(name, &endpoints)?;
        let methods = meta_object(&mut self.conns[conn], id)?;
        Ok(Some(Service {
            name: name.to_string(),
            id,
            conn,
            methods,
        }))
    }

    /// The connection that reaches a service's endpoints: the ServiceDirectory's
    /// own when it is among them, else the first tcp endpoint that answers.
    fn conn_for(&mut self, name: &str, endpoints: &[String]) -> Result<usize, QiError> {
        let mut tcp: Vec<(String, u16)> =
            endpoints.iter().filter_map(|e| parse_url(e).ok()).collect();
        // The address the ServiceDirectory's connection reached (a robot lists its
        // endpoints by IP address, the conf may name it `nao.local`).
        let sd_ip = self.conns[0].stream.peer_addr().ok().map(|a| a.ip());
        let is_sd_ip = |h: &str| {
            h.parse::<std::net::IpAddr>()
                .ok()
                .is_some_and(|ip| Some(ip) == sd_ip)
        };
        let same = |h: &str, p: u16| {
            p == self.port
                && (h == self.host || is_sd_ip(h) || (is_local(h) && is_local(&self.host)))
        };
        if tcp.is_empty() || tcp.iter().any(|(h, p)| same(h, *p)) {
            // No tcp endpoint at all (only `qi:` ones): the service lives in the
            // ServiceDirectory's process.
            if tcp.is_empty()
                && !endpoints.iter().any(|e| e.starts_with("qi:"))
                && !endpoints.is_empty()
            {
                return Err(QiError::Protocol(format!(
                    "service {name} is only reachable at {} (naobody speaks plain tcp://)",
                    endpoints.join(", ")
                )));
            }
            return Ok(0);
        }
        for (h, p) in &tcp {
            let ep = format!("{h}:{p}");
            if let Some(i) = self.conns.iter().position(|c| c.endpoint == ep) {
                return Ok(i);
            }
        }
        // The robot's own address first, loopback only when the robot is this
        // machine; IP literals only (or the conf's own host name: no name a peer
        // sends is resolved); at most MAX_ENDPOINTS, all within one call's time.
        tcp.retain(|(h, _)| {
            (!is_local(h) || is_local(&self.host) || sd_ip.is_some_and(|ip| ip.is_loopback()))
                && (h.parse::<std::net::IpAddr>().is_ok() || *h == self.host)
        });
        tcp.sort_by_key(|(h, _)| !(h == &self.host || is_sd_ip(h)));
        let listed = tcp.len();
        tcp.truncate(MAX_ENDPOINTS);
        let end = Instant::now() + self.timeout;
        let mut last = None;
        for (h, p) in tcp {
            match Conn::connect_by(&h, p, self.timeout, end) {
                Ok(c) => {
                    self.conns.push(c);
                    return Ok(self.conns.len() - 1);
                }
                Err(e) => last = Some(format!("{h}:{p}: {e}")),
            }
            if Instant::now() >= end {
                break;
            }
        }
        Err(QiError::Io(format!(
            "service {name}: none of its endpoints answers within {} ms ({listed} listed, the first \
             {MAX_ENDPOINTS} at most tried; {})",
            self.timeout.as_millis(),
            last.unwrap_or_default()
        )))
    }

    /// Calls `method` of `svc` with `args` (converted to the method's parameter
    /// types); its reply as a value.
    pub fn call(&mut self, svc: &Service, method: &str, args: &[Value]) -> Result<Value, QiError> {
        let (m, p) = arguments(svc, method, args)?;
        let (uid, ret) = (m.uid, m.ret.clone());
        let conn = self
            .conns
            .get_mut(svc.conn)
            .ok_or_else(|| QiError::Protocol("a service of another session".into()))?;
        let (flags, payload) =
            conn.call_raw(svc.id, MAIN_OBJECT, uid, &p)
                .map_err(|e| match e {
                    QiError::Remote(r) => QiError::Remote(format!("{}.{method}: {r}", svc.name)),
                    other => other,
                })?;
        decode_reply(&payload, flags, &ret)
    }

    /// `method` of `svc` with `args`, as a [`Detached`] call (id [`DETACHED_ID`]).
    pub fn detached(
        &self,
        svc: &Service,
        method: &str,
        args: &[Value],
    ) -> Result<Detached, QiError> {
        let (m, p) = arguments(svc, method, args)?;
        let conn = self
            .conns
            .get(svc.conn)
            .ok_or_else(|| QiError::Protocol("a service of another session".into()))?;
        let h = Header {
            id: DETACHED_ID,
            ty: ty::CALL,
            service: svc.id,
            object: MAIN_OBJECT,
            action: m.uid,
            ..Header::default()
        };
        let mut message = Vec::with_capacity(HEADER + p.len());
        write_message(&mut message, h, &p)?;
        Ok(Detached {
            stream: conn.stream.try_clone().map_err(QiError::io)?,
            message,
        })
    }
}

/// `method` of `svc` taking `args`, and `args` encoded for it.
fn arguments<'a>(
    svc: &'a Service,
    method: &str,
    args: &[Value],
) -> Result<(&'a Method, Vec<u8>), QiError> {
    let m = svc.method(method, args.len()).ok_or_else(|| {
        QiError::Protocol(format!(
            "{} has no method {method} taking {} argument(s)",
            svc.name,
            args.len()
        ))
    })?;
    let mut p = Vec::with_capacity(64);
    encode(&Value::Tuple(args.to_vec()), &m.params, &mut p)
        .map_err(|e| QiError::Protocol(format!("{}.{method}: {e}", svc.name)))?;
    Ok((m, p))
}

/// The message id of a [`Detached`] call: [`Conn::call_raw`] never uses it, so
/// its reply is skipped as an answer to another call.
pub const DETACHED_ID: u32 = 0;

/// A call made ready to send without its session, from any thread, through a
/// second handle on the service's connection: an emergency stop that must not
/// wait for the session's thread (which may be inside a call).
pub struct Detached {
    stream: TcpStream,
    message: Vec<u8>,
}

impl Detached {
    /// Sends the call, in one write (a message the session's thread writes at
    /// the same time is not cut into, unless the socket's send buffer is full),
    /// waiting at most the connection's write timeout.
    pub fn send(&self) -> std::io::Result<()> {
        (&self.stream).write_all(&self.message)
    }
}

fn is_local(h: &str) -> bool {
    matches!(h, "127.0.0.1" | "localhost" | "::1" | "0.0.0.0")
}

/// An object's methods (`metaObject`, action 2).
pub fn meta_object(conn: &mut Conn, service: u32) -> Result<Vec<Method>, QiError> {
    let (flags, payload) = conn.call_raw(
        service,
        MAIN_OBJECT,
        ACTION_METAOBJECT,
        &MAIN_OBJECT.to_le_bytes(),
    )?;
    let sig = Sig::parse(METAOBJECT_SIG)?;
    methods_of(&decode_reply(&payload, flags, &sig)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round(v: &Value, sig: &str) -> Value {
        let s = Sig::parse(sig).unwrap();
        let mut b = Vec::new();
        encode(v, &s, &mut b).unwrap();
        decode(&b, &s).unwrap()
    }

    #[test]
    fn signatures_parse_and_print() {
        for s in [
            "(fff)",
            "[f]",
            "{sm}",
            "(sIsI[s]s)",
            "+[i]",
            "()",
            "v",
            "(m[(ss)])",
        ] {
            assert_eq!(Sig::parse(s).unwrap().to_string(), s);
        }
        let mo = Sig::parse(METAOBJECT_SIG).unwrap();
        assert!(matches!(mo, Sig::Tuple(ref m) if m.len() == 4), "{mo:?}");
        for bad in ["(", "[f", "{s}", "q", "(f)<a,b", "[f]]", &"[".repeat(100)] {
            assert!(Sig::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn values_round_trip_and_numbers_convert() {
        assert_eq!(round(&Value::Double(0.5), "f"), Value::Float(0.5));
        assert_eq!(round(&Value::Int(3), "d"), Value::Double(3.0));
        let names = Value::List(vec![Value::str("HeadYaw"), Value::str("HeadPitch")]);
        assert_eq!(round(&names, "m"), names);
        let img = Value::List(vec![
            Value::Int(2),
            Value::Raw(vec![1, 2, 3]),
            Value::Float(0.25),
        ]);
        assert_eq!(round(&img, "m"), img);
        assert!(encode(&Value::Int(300), &Sig::U8, &mut Vec::new()).is_err());
        assert!(encode(&Value::str("x"), &Sig::F32, &mut Vec::new()).is_err());
    }

    #[test]
    fn headers_are_checked() {
        let h = Header {
            id: 7,
            size: 3,
            ty: ty::REPLY,
            service: 1,
            object: 1,
            action: 100,
            ..Header::default()
        };
        let b = h.encode();
        assert_eq!(&b[..4], &[0x42, 0xde, 0xad, 0x42]);
        assert_eq!(Header::decode(&b).unwrap(), h);
        let mut bad = b;
        bad[0] = 0;
        assert!(
            Header::decode(&bad)
                .unwrap_err()
                .to_string()
                .contains("magic")
        );
        let mut big = b;
        big[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(Header::decode(&big).is_err());
        // A header that promises more than arrives: an error, no big allocation.
        let mut stream = big.to_vec();
        stream[8..12].copy_from_slice(&(MAX_PAYLOAD as u32).to_le_bytes());
        stream.extend_from_slice(&[1, 2, 3]);
        assert!(read_message(&mut stream.as_slice()).is_err());
    }

    #[test]
    fn counts_beyond_the_payload_are_refused() {
        // A list claiming 2^32-1 floats, a string of 1 GB, a list of voids.
        for (bytes, sig) in [
            (vec![0xff, 0xff, 0xff, 0xff], "[f]"),
            (vec![0, 0, 0, 0x40, b'a'], "s"),
            (vec![0xff, 0xff, 0xff, 0xff], "[()]"),
            (vec![0xff, 0xff, 0xff, 0x7f], "{sm}"),
        ] {
            assert!(decode(&bytes, &Sig::parse(sig).unwrap()).is_err(), "{sig}");
        }
        // A dynamic whose signature nests too deep.
        let deep = format!("{}f{}", "[".repeat(40), "]".repeat(40));
        let mut b = (deep.len() as u32).to_le_bytes().to_vec();
        b.extend_from_slice(deep.as_bytes());
        assert!(decode(&b, &Sig::Dynamic).is_err());
    }

    /// Random bytes into every decoder: errors, never a panic, a hang or a huge
    /// allocation.
    #[test]
    fn random_bytes_never_panic() {
        let sigs: Vec<Sig> = [
            "m",
            "[m]",
            "{sm}",
            METAOBJECT_SIG,
            "(sIsI[s]ss)",
            "[f]",
            "+m",
            "(iisr)",
        ]
        .iter()
        .map(|s| Sig::parse(s).unwrap())
        .collect();
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for round in 0..20_000 {
            let n = (next() % 200) as usize;
            let mut b: Vec<u8> = (0..n).map(|_| next() as u8).collect();
            // Sometimes a plausible dynamic prefix, to get past the first check.
            if round % 3 == 0 && b.len() > 8 {
                let sig = [b"[m]".as_slice(), b"{sm}", b"(fr)", b"[[i]]"][round % 4];
                b[..4].copy_from_slice(&(sig.len() as u32).to_le_bytes());
                b.splice(4..4, sig.iter().copied());
            }
            for s in &sigs {
                let _ = decode(&b, s);
            }
            let mut framed = b.clone();
            if round % 2 == 0 && framed.len() >= 4 {
                framed[..4].copy_from_slice(&MAGIC.to_be_bytes());
            }
            let _ = read_message(&mut framed.as_slice());
            if let Ok(s) = std::str::from_utf8(&b) {
                let _ = Sig::parse(s);
            }
        }
    }

    #[test]
    fn urls() {
        assert_eq!(
            parse_url("tcp://nao.local:9559").unwrap(),
            ("nao.local".into(), 9559)
        );
        assert_eq!(parse_url("tcp://[::1]:9559").unwrap(), ("::1".into(), 9559));
        assert!(
            parse_url("tcps://10.0.0.2:9503")
                .unwrap_err()
                .contains("TLS")
        );
        assert!(parse_url("tcp://host").is_err());
        assert!(parse_url("tcp://host:0").is_err());
    }
}
