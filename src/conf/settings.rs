//! Declared settings: a component declares the lines it takes once, as data (a
//! [`Setting`] per keyword: its arguments with type, unit and range, a default and a
//! line of help), and a plain struct that derives `serde::Deserialize` receives the
//! values. From that one declaration the core
//!
//! - parses and checks a component's lines ([`ComponentConf::settings`]): an unknown
//!   keyword, a missing or extra argument, a word that is not a number, a value out
//!   of its range — each is an error at `file:line` naming the range or the choices,
//!   never a silent clamp;
//! - prints `jderobot help NAME` ([`help_text`]);
//! - validates a conf in `jderobot check` before anything is built.
//!
//! ```
//! use jderobot::conf::{ComponentConf, Kind, settings::{Setting, float, CYCLE}};
//! #[derive(serde::Deserialize)]
//! struct Lines { max_v: f32, walk: (f32, f32), cycle: u64 }
//! const LINES: &[Setting] = &[
//!     Setting::new("max_v", "joystick maximum speed", &[float("V", "mm/s", 1.0, 1000.0)]).default("500"),
//!     Setting::new("walk", "initial walk command", &[float("V", "mm/s", -1000.0, 1000.0),
//!         float("W", "deg/s", -180.0, 180.0)]).default("0 0"),
//!     CYCLE.default("100"),
//! ];
//! let conf = ComponentConf::from_text(Kind::Schema, "demo", "max_v 300\n").unwrap();
//! let l: Lines = conf.settings(LINES).unwrap();
//! assert_eq!((l.max_v, l.walk, l.cycle), (300.0, (0.0, 0.0), 100));
//! let bad = ComponentConf::from_text(Kind::Schema, "demo", "max_v 4000000000000\n").unwrap();
//! let e = bad.settings::<Lines>(LINES).err().unwrap().to_string();
//! assert!(e.contains("between 1 and 1000"), "{e}");
//! ```
//!
//! Why serde: the struct a component reads is ordinary Rust (tuples for multi-word
//! lines, `Option` for lines without default, `Vec` for repeated lines), and serde
//! builds it from the checked words; the ranges, units and help live in the
//! declaration, which serde has no place for. The two are kept in step by a check at
//! parse time (every declared key must be a field and every field a declared key)
//! and by a test that parses every component's defaults.

use std::fmt::{self, Write as _};

use serde::de::{self, DeserializeSeed, IntoDeserializer, MapAccess, SeqAccess, Visitor};

use super::{ComponentConf, ConfError, ConfLine, Location};

/// What one argument of a line may be.
#[derive(Clone, Copy, Debug)]
pub enum ArgType {
    /// A whole number within `[min, max]`.
    Int { min: i64, max: i64 },
    /// A finite number within `[min, max]`.
    Float { min: f64, max: f64 },
    /// One of these words.
    Choice(&'static [&'static str]),
    /// `on` or `off` (also yes/no, true/false, 1/0, 4.3's `NAME_on`/`NAME_off`).
    OnOff,
    /// An interface name as it is spelled (4.3's aliases accepted), or `none`.
    Interface,
    /// A file path, relative to the conf file the line is in.
    Path,
    /// Any one word.
    Word,
    /// Every remaining word (must be last; at least one unless the argument is optional).
    Rest,
}

/// One argument of a declared line.
#[derive(Clone, Copy, Debug)]
pub struct Arg {
    pub name: &'static str,
    pub ty: ArgType,
    /// The unit of a number (`mm/s`, `deg`, `ms`), or "".
    pub unit: &'static str,
    /// The line may stop before this argument (the ones after it are optional too).
    pub optional: bool,
}

impl Arg {
    /// This argument and the ones after it may be left out.
    pub const fn optional(mut self) -> Arg {
        self.optional = true;
        self
    }
}

const fn arg(name: &'static str, ty: ArgType, unit: &'static str) -> Arg {
    Arg {
        name,
        ty,
        unit,
        optional: false,
    }
}
/// A finite number in `[min, max]`, in `unit`.
pub const fn float(name: &'static str, unit: &'static str, min: f64, max: f64) -> Arg {
    arg(name, ArgType::Float { min, max }, unit)
}
/// A whole number in `[min, max]`, in `unit`.
pub const fn int(name: &'static str, unit: &'static str, min: i64, max: i64) -> Arg {
    arg(name, ArgType::Int { min, max }, unit)
}
/// One of `choices`.
pub const fn choice(name: &'static str, choices: &'static [&'static str]) -> Arg {
    arg(name, ArgType::Choice(choices), "")
}
/// `on` or `off`.
pub const fn on_off(name: &'static str) -> Arg {
    arg(name, ArgType::OnOff, "")
}
/// An interface name, or `none`.
pub const fn interface(name: &'static str) -> Arg {
    arg(name, ArgType::Interface, "")
}
/// A file path relative to the conf file.
pub const fn path(name: &'static str) -> Arg {
    arg(name, ArgType::Path, "")
}
/// Any word.
pub const fn word(name: &'static str) -> Arg {
    arg(name, ArgType::Word, "")
}
/// The rest of the line, one or more words.
pub const fn rest(name: &'static str) -> Arg {
    arg(name, ArgType::Rest, "")
}

/// One line a component takes: `KEY ARG...`.
#[derive(Clone, Copy, Debug)]
pub struct Setting {
    pub key: &'static str,
    pub args: &'static [Arg],
    /// The value when the line is absent, as written in a conf; `None`: no default
    /// (the field is an `Option`, or a `Vec` for a repeated line).
    pub default: Option<&'static str>,
    pub help: &'static str,
    /// The line may appear several times (read as a `Vec`); otherwise the last one
    /// counts, as in 4.3.
    pub repeats: bool,
    /// The component cannot do without it (a serial port, a `provides` line).
    pub required: bool,
}

impl Setting {
    pub const fn new(key: &'static str, help: &'static str, args: &'static [Arg]) -> Setting {
        Setting {
            key,
            args,
            default: None,
            help,
            repeats: false,
            required: false,
        }
    }
    /// The value when the line is absent, written as in a conf (`"0 0"`).
    pub const fn default(mut self, words: &'static str) -> Setting {
        self.default = Some(words);
        self
    }
    /// The line may appear several times; the field is a `Vec` of every one.
    pub const fn repeats(mut self) -> Setting {
        self.repeats = true;
        self
    }
    /// The component needs the line: its absence is an error naming it.
    pub const fn required(mut self) -> Setting {
        self.required = true;
        self
    }
    /// The same line with another key (for components that take a shared line
    /// under their own name).
    pub const fn key(mut self, key: &'static str) -> Setting {
        self.key = key;
        self
    }
    /// The same line with another help text.
    pub const fn help(mut self, help: &'static str) -> Setting {
        self.help = help;
        self
    }
    /// The usage: `KEY ARG1 ARG2 [ARG3]`.
    pub fn usage(&self) -> String {
        let mut s = self.key.to_string();
        let mut open = 0;
        for a in self.args {
            if a.optional {
                s.push_str(" [");
                open += 1;
            } else {
                s.push(' ');
            }
            s.push_str(a.name);
            if matches!(a.ty, ArgType::Rest) {
                s.push_str("...");
            }
        }
        s.push_str(&"]".repeat(open));
        s
    }
}

/// `cycle MS`: a schema's or driver's period, shared by every component that has one.
pub const CYCLE: Setting = Setting::new(
    "cycle",
    "the period of each iteration",
    &[int("MS", "ms", 1, 10_000)],
);
/// `motors_timeout MS`: a motors command older than this counts as zero.
pub const MOTORS_TIMEOUT: Setting = Setting::new(
    "motors_timeout",
    "a motors command older than this counts as zero (the robot stops when its controller dies)",
    &[int("MS", "ms", 1, 60_000)],
)
.default("500");

/// `initial_position X Y THETA`: a robot's starting pose or odometry offset.
pub const INITIAL_POSITION: Setting = Setting::new(
    "initial_position",
    "the robot's starting pose (the odometry offset of a remote one)",
    &[
        float("X", "mm", -1e9, 1e9),
        float("Y", "mm", -1e9, 1e9),
        float("THETA", "deg", -36_000.0, 36_000.0),
    ],
);

/// `bind ADDRESS`: where a server listens; loopback unless the conf says otherwise.
pub const BIND: Setting = Setting::new(
    "bind",
    "the address it listens on (beyond loopback only when said here: 0.0.0.0, ::)",
    &[word("ADDRESS")],
)
.default("127.0.0.1");

/// `insecure`: serve beyond loopback with no secret and no TLS, on purpose (a
/// network you trust). Every server that can listen beyond loopback declares it,
/// and [`guard_listen`] reads it.
pub const INSECURE: Setting = Setting::new(
    "insecure",
    "serve beyond loopback with no secret or TLS: anyone on that network may drive the robot",
    &[],
);

/// Whether `host` (an IP literal, `[::1]`, `localhost`) is on this machine only:
/// 127.0.0.0/8, ::1 (also as ::ffff:127.x.y.z) or `localhost`. Anything else
/// (0.0.0.0, ::, an interface's address, any other name) is beyond loopback.
pub fn is_loopback_host(host: &str) -> bool {
    let h = host.trim();
    let h = h
        .strip_prefix('[')
        .and_then(|x| x.strip_suffix(']'))
        .unwrap_or(h);
    if h.eq_ignore_ascii_case("localhost") {
        return true;
    }
    match h.parse::<std::net::IpAddr>() {
        Ok(ip) => ip.to_canonical().is_loopback(),
        Err(_) => false,
    }
}

/// How a listening socket is guarded, as [`guard_listen`] found it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exposure {
    /// It listens on loopback only.
    Loopback,
    /// Beyond loopback, with a secret or TLS.
    Secured,
    /// Beyond loopback with neither, because the conf says `insecure`.
    Insecure,
}

/// The one rule of every server in the suite: a socket beyond loopback needs a
/// secret (a token, TLS) unless the conf says `insecure` ([`INSECURE`]).
///
/// `key` is the line that set the address (`bind`, `listen`: the error points at
/// it), `host` the address it listens on, `secured` whether a secret or TLS
/// guards it, `add_one` how to add one (`add a `token SECRET` line`). Beyond
/// loopback with neither a secret nor `insecure` it is an error saying how to add
/// one; with `insecure` it logs one warning and returns
/// [`Exposure::Insecure`].
///
/// ```
/// use jderobot::conf::{ComponentConf, Kind, settings::{guard_listen, Exposure}};
/// let c = ComponentConf::from_text(Kind::Service, "demo", "bind 0.0.0.0\n").unwrap();
/// let e = guard_listen(&c, "bind", "0.0.0.0", false, "add a `token SECRET` line").unwrap_err();
/// assert!(e.to_string().contains("token SECRET"), "{e}");
/// assert_eq!(guard_listen(&c, "bind", "127.0.0.1", false, "").unwrap(), Exposure::Loopback);
/// assert_eq!(guard_listen(&c, "bind", "0.0.0.0", true, "").unwrap(), Exposure::Secured);
/// let c = ComponentConf::from_text(Kind::Service, "demo", "bind 0.0.0.0\ninsecure\n").unwrap();
/// assert_eq!(guard_listen(&c, "bind", "0.0.0.0", false, "").unwrap(), Exposure::Insecure);
/// ```
pub fn guard_listen(
    conf: &ComponentConf,
    key: &str,
    host: &str,
    secured: bool,
    add_one: &str,
) -> Result<Exposure, ConfError> {
    if is_loopback_host(host) {
        return Ok(Exposure::Loopback);
    }
    if secured {
        return Ok(Exposure::Secured);
    }
    if conf.line(INSECURE.key).is_some() {
        tracing::warn!(
            "{} {}: listening on {host}, beyond loopback, with no secret (`insecure`): \
             anyone on that network may drive the robot",
            conf.kind,
            conf.name
        );
        return Ok(Exposure::Insecure);
    }
    let message = format!(
        "{} {} listens on {host}, beyond loopback, with no secret: anyone on that network \
         could drive the robot. {add_one}; or listen on loopback (127.0.0.1); or, on a \
         network you trust, add an `insecure` line to say so",
        conf.kind, conf.name
    );
    Err(match conf.line(key) {
        Some(l) => l.error(message),
        None => ConfError {
            at: conf_location(conf),
            message,
        },
    })
}

/// How far a 3D view's camera may be from the origin on each axis (mm).
pub const VIEW_RANGE: f64 = 60_000.0;

/// `camera XCAM YCAM ZCAM FOAX FOAY FOAZ`: a 3D view's camera, its position and
/// its focus of attention (mm), as 4.3's OpenGL schemas placed it.
pub const fn look_at(help: &'static str) -> Setting {
    const R: f64 = VIEW_RANGE;
    const ARGS: &[Arg] = &[
        float("XCAM", "mm", -R, R),
        float("YCAM", "mm", -R, R),
        float("ZCAM", "mm", -R, R),
        float("FOAX", "mm", -R, R),
        float("FOAY", "mm", -R, R),
        float("FOAZ", "mm", -R, R),
    ];
    Setting::new("camera", help, ARGS)
}

/// `world FILE|none`: the world a schema draws: a world file, `none`, or (no
/// line) the exported `world.map`, whichever driver exports it. [`world`] reads it.
pub const WORLD: Setting = Setting::new(
    "world",
    "the world drawn: a world file, or none (default: the exported world.map)",
    &[word("FILE|none")],
);

/// The world a [`WORLD`] line (`value`) names: its file loaded, None for `none`,
/// and without a line the exported `world.map` (None if no driver exports one).
pub fn world(
    conf: &ComponentConf,
    value: Option<&str>,
    names: &crate::namespace::Namespace,
) -> Result<Option<std::sync::Arc<crate::world::World>>, ConfError> {
    match value {
        None => Ok(crate::world::map(names)),
        Some("none") => Ok(None),
        Some(_) => {
            let l = conf.line("world").expect("a world line gave the value");
            let file = l.existing_file(0, "the world file")?;
            let w = crate::world::World::load(&file).map_err(|e| l.error(format!("world: {e}")))?;
            Ok(Some(std::sync::Arc::new(w)))
        }
    }
}

/// `provides INTERFACE ...`, any number of them, in the forms `usage` says (a
/// driver whose provides lines take several forms reads their words itself).
pub const fn provides(usage: &'static str) -> Setting {
    const ARGS: &[Arg] = &[interface("INTERFACE"), rest("ARGS").optional()];
    Setting::new("provides", usage, ARGS).repeats()
}

/// `KEY INTERFACE`: an interface the component uses in a role (`motors motors`,
/// `camera varcolorA`), `default` when absent; schemas take `none` for "do
/// without" where they can (the help says so).
pub const fn uses(key: &'static str, default: &'static str, help: &'static str) -> Setting {
    const ARGS: &[Arg] = &[interface("INTERFACE")];
    Setting::new(key, help, ARGS).default(default)
}

/// Says a range in words.
fn range_words(min: f64, max: f64) -> String {
    // The extremes of a type mean "no bound".
    let n = |x: f64| {
        let unbounded = [f64::MAX, f64::MIN, i64::MAX as f64, i64::MIN as f64];
        (!unbounded.contains(&x)).then_some(x)
    };
    match (n(min), n(max)) {
        (Some(a), Some(b)) => format!("between {a} and {b}"),
        (Some(a), None) => format!("at least {a}"),
        (None, Some(b)) => format!("at most {b}"),
        (None, None) => "a number".into(),
    }
}

impl fmt::Display for ArgType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ArgType::Int { min, max } => {
                write!(
                    f,
                    "a whole number {}",
                    range_words(*min as f64, *max as f64)
                )
            }
            ArgType::Float { min, max } => write!(f, "a number {}", range_words(*min, *max)),
            ArgType::Choice(c) => write!(f, "one of {}", c.join(", ")),
            ArgType::OnOff => f.write_str("on or off"),
            ArgType::Interface => f.write_str("an interface name or none"),
            ArgType::Path => f.write_str("a file (relative to the conf file)"),
            ArgType::Word => f.write_str("a word"),
            ArgType::Rest => f.write_str("one or more words"),
        }
    }
}

/// At most this many characters of a word are echoed in an error.
const ECHO: usize = 60;

/// A word as an error message quotes it: cut when long.
pub fn echo(word: &str) -> String {
    if word.chars().count() <= ECHO {
        word.to_string()
    } else {
        let cut: String = word.chars().take(ECHO).collect();
        format!("{cut}… ({} bytes)", word.len())
    }
}

const ON: [&str; 4] = ["on", "yes", "true", "1"];
const OFF: [&str; 4] = ["off", "no", "false", "0"];

/// A checked argument value.
#[derive(Clone, Debug)]
enum Value {
    Int(i64),
    Float(f64),
    Bool(bool),
    Str(String),
}

/// Checks one word against its declared type.
fn check_word(line: &ConfLine, i: usize, a: &Arg, w: &str) -> Result<Value, ConfError> {
    let bad = |what: String| {
        line.error(format!(
            "`{}`: {} (argument {}) is `{}`, expected {what}",
            line.keyword(),
            a.name,
            i + 1,
            echo(w)
        ))
    };
    let unit = if a.unit.is_empty() {
        String::new()
    } else {
        format!(" {}", a.unit)
    };
    match a.ty {
        ArgType::Int { min, max } => match w.parse::<i64>() {
            Ok(v) if (min..=max).contains(&v) => Ok(Value::Int(v)),
            _ => Err(bad(format!("{}{unit}", a.ty))),
        },
        ArgType::Float { min, max } => match w.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= min && v <= max => Ok(Value::Float(v)),
            _ => Err(bad(format!("{}{unit}", a.ty))),
        },
        ArgType::Choice(c) => {
            if c.contains(&w) {
                Ok(Value::Str(w.to_string()))
            } else {
                Err(bad(a.ty.to_string()))
            }
        }
        ArgType::OnOff => {
            let tail = w.rsplit('_').next().unwrap_or(w);
            if ON.contains(&w) || (w.contains('_') && tail == "on") {
                Ok(Value::Bool(true))
            } else if OFF.contains(&w) || (w.contains('_') && tail == "off") {
                Ok(Value::Bool(false))
            } else {
                Err(bad(a.ty.to_string()))
            }
        }
        ArgType::Interface => {
            let base = w.split('.').next().unwrap_or(w);
            if w == "none" || crate::interfaces::family(base).is_some() {
                Ok(Value::Str(w.to_string()))
            } else {
                Err(bad(format!(
                    "an interface ({}) or none",
                    crate::interfaces::STANDARD_NAMES.join(", ")
                )))
            }
        }
        ArgType::Path => Ok(Value::Str(line.path(i, a.name)?.display().to_string())),
        ArgType::Word | ArgType::Rest => Ok(Value::Str(w.to_string())),
    }
}

/// Checks a line's arguments against its declaration.
fn check_line(s: &Setting, line: &ConfLine, component: &str) -> Result<Vec<Value>, ConfError> {
    let args = line.args();
    let required = s.args.iter().take_while(|a| !a.optional).count();
    let rest = s.args.last().is_some_and(|a| matches!(a.ty, ArgType::Rest));
    let max = if rest { usize::MAX } else { s.args.len() };
    if args.len() < required || args.len() > max {
        let n = args.len();
        return Err(line.error(format!(
            "`{}` takes {}, got {n}; usage: {} (see `jderobot help {component}`)",
            s.key,
            match (required, max) {
                (a, b) if a == b => format!("{a} argument(s)"),
                (a, usize::MAX) => format!("at least {a} argument(s)"),
                (a, b) => format!("{a} to {b} arguments"),
            },
            s.usage()
        )));
    }
    let mut out = Vec::with_capacity(args.len());
    for (i, w) in args.iter().enumerate() {
        let a = &s.args[i.min(s.args.len() - 1)];
        out.push(check_word(line, i, a, w)?);
    }
    Ok(out)
}

/// The checked values of every declared line: given or default.
struct Parsed<'a> {
    entries: Vec<Entry<'a>>,
}

/// Checks every line of `conf` against `decl`: all problems, in file order.
pub fn check(conf: &ComponentConf, decl: &[Setting]) -> Vec<ConfError> {
    match parse(conf, decl) {
        Ok(_) => Vec::new(),
        Err(e) => e,
    }
}

fn parse<'a>(conf: &ComponentConf, decl: &'a [Setting]) -> Result<Parsed<'a>, Vec<ConfError>> {
    let mut errors = Vec::new();
    // Required lines that are absent: said after the errors of the lines present.
    let mut missing = Vec::new();
    let mut entries = Vec::new();
    for l in &conf.lines {
        if !decl.iter().any(|s| s.key == l.keyword()) {
            let keys: Vec<&str> = decl.iter().map(|s| s.key).collect();
            errors.push(l.error(format!(
                "{} {} takes no `{}` line; its lines: {} (see `jderobot help {}`)",
                conf.kind,
                conf.name,
                echo(l.keyword()),
                if keys.is_empty() {
                    "none".to_string()
                } else {
                    keys.join(", ")
                },
                conf.name
            )));
        }
    }
    for s in decl {
        let lines: Vec<&ConfLine> = conf.lines_with(s.key).collect();
        let mut values = Vec::new();
        let mut at = None;
        let chosen: Vec<&ConfLine> = if s.repeats {
            lines
        } else {
            // The last line counts (4.3's rule); earlier ones are still checked.
            for l in lines.iter().rev().skip(1) {
                if let Err(e) = check_line(s, l, &conf.name) {
                    errors.push(e);
                }
            }
            lines.last().copied().into_iter().collect()
        };
        for l in &chosen {
            at = Some(l.at.clone());
            match check_line(s, l, &conf.name) {
                Ok(v) => values.push(v),
                Err(e) => errors.push(e),
            }
        }
        if chosen.is_empty() && s.required {
            missing.push(ConfError {
                at: conf_location(conf),
                message: format!(
                    "{} {} has no `{}` line, and needs one: `{}` ({}); see `jderobot help {}`",
                    conf.kind,
                    conf.name,
                    s.key,
                    s.usage(),
                    s.help,
                    conf.name
                ),
            });
        }
        if chosen.is_empty()
            && let Some(d) = s.default
        {
            let line = ConfLine {
                at: Location {
                    file: std::sync::Arc::from(std::path::Path::new("<default>")),
                    line: 0,
                },
                words: std::iter::once(s.key.to_string())
                    .chain(d.split_whitespace().map(String::from))
                    .collect(),
            };
            match check_line(s, &line, &conf.name) {
                Ok(v) => values.push(v),
                Err(e) => errors.push(ConfError {
                    at: conf_location(conf),
                    message: format!("internal: the default of `{}` is wrong: {e}", s.key),
                }),
            }
        }
        entries.push((s, at, values));
    }
    errors.sort_by_key(|e| e.at.line);
    errors.append(&mut missing);
    if errors.is_empty() {
        Ok(Parsed { entries })
    } else {
        Err(errors)
    }
}

fn conf_location(conf: &ComponentConf) -> Location {
    Location {
        file: std::sync::Arc::from(conf.file.as_path()),
        line: conf.lines.first().map(|l| l.at.line).unwrap_or(0),
    }
}

impl ComponentConf {
    /// The motor-safety timeout ([`MOTORS_TIMEOUT`], default 500 ms): a motors
    /// command older than this counts as zero for every driver that moves a robot.
    pub fn motors_timeout(&self) -> Result<std::time::Duration, ConfError> {
        #[derive(serde::Deserialize)]
        struct Line {
            motors_timeout: u64,
        }
        let only = ComponentConf {
            lines: self.lines_with(MOTORS_TIMEOUT.key).cloned().collect(),
            ..self.clone()
        };
        let l: Line = only.settings(&[MOTORS_TIMEOUT])?;
        Ok(std::time::Duration::from_millis(l.motors_timeout))
    }
    /// Checks this component's lines against `decl` (for a component that only
    /// needs them checked, such as one that takes no lines: `conf.check(&[])`).
    pub fn check(&self, decl: &[Setting]) -> Result<(), ConfError> {
        parse(self, decl).map(drop).map_err(|mut e| e.remove(0))
    }
    /// Parses this component's lines into `T` from their declaration `decl`: every
    /// line checked (type, range, count), defaults filled in. The first problem is
    /// returned ([`check`] gives them all).
    pub fn settings<T: serde::de::DeserializeOwned>(
        &self,
        decl: &[Setting],
    ) -> Result<T, ConfError> {
        let parsed = parse(self, decl).map_err(|mut e| e.remove(0))?;
        let at = conf_location(self);
        T::deserialize(Lines {
            parsed: &parsed,
            at: &at,
        })
        .map_err(|e| e.0)
    }
}

/// A serde error carrying its location.
#[derive(Debug)]
struct DeError(ConfError);

impl fmt::Display for DeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}
impl std::error::Error for DeError {}
impl de::Error for DeError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        DeError(ConfError {
            at: Location {
                file: std::sync::Arc::from(std::path::Path::new("<settings>")),
                line: 0,
            },
            message: format!("internal: settings do not match their declaration: {msg}"),
        })
    }
}

/// The whole component: a map from key to line.
struct Lines<'p, 'a> {
    parsed: &'p Parsed<'a>,
    at: &'p Location,
}

impl<'de> de::Deserializer<'de> for Lines<'_, '_> {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, DeError> {
        Err(de::Error::custom("settings deserialize into a struct"))
    }
    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        // The declaration and the struct must name the same lines.
        let internal = |m: String| {
            DeError(ConfError {
                at: self.at.clone(),
                message: format!("internal: {m}"),
            })
        };
        for (s, _, _) in &self.parsed.entries {
            if !fields.contains(&s.key) {
                return Err(internal(format!(
                    "line `{}` is declared but the settings struct has no such field",
                    s.key
                )));
            }
        }
        for f in fields {
            if !self.parsed.entries.iter().any(|(s, _, _)| s.key == *f) {
                return Err(internal(format!(
                    "field `{f}` of the settings struct is not a declared line"
                )));
            }
        }
        visitor.visit_map(LineMap {
            entries: self
                .parsed
                .entries
                .iter()
                .filter(|(s, _, v)| s.repeats || !v.is_empty())
                .collect(),
            next: 0,
            at: self.at,
        })
    }
    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf option unit unit_struct newtype_struct seq tuple
        tuple_struct map enum identifier ignored_any
    }
}

/// A declared line, where it was (None: its default), and the values of each
/// occurrence.
type Entry<'a> = (&'a Setting, Option<Location>, Vec<Vec<Value>>);

struct LineMap<'p, 'a> {
    entries: Vec<&'p Entry<'a>>,
    next: usize,
    at: &'p Location,
}

impl<'de> MapAccess<'de> for LineMap<'_, '_> {
    type Error = DeError;
    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, DeError> {
        let Some((s, _, _)) = self.entries.get(self.next) else {
            return Ok(None);
        };
        seed.deserialize(s.key.into_deserializer()).map(Some)
    }
    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, DeError> {
        let (s, at, values) = self.entries[self.next];
        self.next += 1;
        let at = at.as_ref().unwrap_or(self.at);
        let relocate = |e: DeError| {
            DeError(ConfError {
                at: at.clone(),
                message: format!("`{}`: {}", s.key, e.0.message),
            })
        };
        if s.repeats {
            seed.deserialize(Occurrences { values }).map_err(relocate)
        } else {
            seed.deserialize(LineValue { values: &values[0] })
                .map_err(relocate)
        }
    }
}

/// Every occurrence of a repeated line: a sequence of lines.
struct Occurrences<'p> {
    values: &'p [Vec<Value>],
}

impl<'de> de::Deserializer<'de> for Occurrences<'_> {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        visitor.visit_seq(
            self.values
                .iter()
                .map(|v| LineValue { values: v })
                .collect::<Seq<_>>(),
        )
    }
    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf option unit unit_struct newtype_struct seq tuple
        tuple_struct map struct enum identifier ignored_any
    }
}

struct Seq<D> {
    items: std::collections::VecDeque<D>,
}
impl<D> FromIterator<D> for Seq<D> {
    fn from_iter<I: IntoIterator<Item = D>>(i: I) -> Self {
        Seq {
            items: i.into_iter().collect(),
        }
    }
}
impl<'de, D: de::Deserializer<'de, Error = DeError>> SeqAccess<'de> for Seq<D> {
    type Error = DeError;
    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, DeError> {
        match self.items.pop_front() {
            Some(d) => seed.deserialize(d).map(Some),
            None => Ok(None),
        }
    }
    fn size_hint(&self) -> Option<usize> {
        Some(self.items.len())
    }
}

/// One line's values: a scalar for one word, a tuple or sequence for several, a
/// `bool` true for a line of no words.
struct LineValue<'p> {
    values: &'p [Value],
}

impl LineValue<'_> {
    /// The values as elements, padded with missing ones up to `len` (trailing
    /// optional arguments read as `None`).
    fn elements(&self, len: usize) -> Seq<ValueDe> {
        let given = self.values.iter().cloned().map(|v| ValueDe(Some(v)));
        let missing = (self.values.len()..len).map(|_| ValueDe(None));
        given.chain(missing).collect()
    }
}

impl<'de> de::Deserializer<'de> for LineValue<'_> {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.values {
            [one] => ValueDe(Some(one.clone())).deserialize_any(visitor),
            [] => visitor.visit_bool(true),
            _ => visitor.visit_seq(self.elements(0)),
        }
    }
    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        if self.values.is_empty() {
            visitor.visit_none()
        } else {
            visitor.visit_some(self)
        }
    }
    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        match self.values {
            [one] => ValueDe(Some(one.clone())).deserialize_enum(name, variants, visitor),
            _ => Err(de::Error::custom("an enum reads one word")),
        }
    }
    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        visitor.visit_seq(self.elements(0))
    }
    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, DeError> {
        visitor.visit_seq(self.elements(len))
    }
    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        // A `Rest` argument read as one string: its words joined by spaces.
        let words: Vec<String> = self.values.iter().map(Value::to_string).collect();
        visitor.visit_string(words.join(" "))
    }
    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        self.deserialize_string(visitor)
    }
    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char
        bytes byte_buf unit unit_struct newtype_struct
        tuple_struct map struct identifier ignored_any
    }
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::Str(s) => f.write_str(s),
            Value::Int(i) => write!(f, "{i}"),
            Value::Float(x) => write!(f, "{x}"),
            Value::Bool(b) => f.write_str(if *b { "on" } else { "off" }),
        }
    }
}

/// One argument's value (`None`: an optional argument left out). serde's number
/// visitors convert between the integer and float widths, checking the fit.
struct ValueDe(Option<Value>);

impl<'de> de::Deserializer<'de> for ValueDe {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.0 {
            Some(Value::Int(i)) => visitor.visit_i64(i),
            Some(Value::Float(f)) => visitor.visit_f64(f),
            Some(Value::Bool(b)) => visitor.visit_bool(b),
            Some(Value::Str(s)) => visitor.visit_string(s),
            None => visitor.visit_none(),
        }
    }
    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.0 {
            None => visitor.visit_none(),
            Some(_) => visitor.visit_some(self),
        }
    }
    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _: &'static str,
        _: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        match self.0 {
            Some(Value::Str(s)) => visitor.visit_enum(s.into_deserializer()),
            _ => Err(de::Error::custom("an enum reads a word")),
        }
    }
    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
        bytes byte_buf unit unit_struct newtype_struct seq tuple
        tuple_struct map struct identifier ignored_any
    }
}

/// `jderobot help NAME`: a component's lines, from its declaration.
pub fn help_text(
    kind: impl fmt::Display,
    name: &str,
    summary: &str,
    decl: &[Setting],
    lines_doc: &str,
) -> String {
    let mut out = format!("{kind} {name}: {summary}\n");
    if !lines_doc.is_empty() {
        let _ = writeln!(out, "\n{lines_doc}");
    }
    if decl.is_empty() {
        let _ = writeln!(out, "\nIt takes no lines.");
        return out;
    }
    let _ = writeln!(out, "\nLines ({kind} {name} ... end_{kind}):");
    for s in decl {
        let _ = write!(out, "  {:<32}", s.usage());
        match (s.default, s.repeats, s.required) {
            (Some(d), ..) => {
                let _ = writeln!(out, " default: {d}");
            }
            (None, true, true) => {
                let _ = writeln!(out, " (one or more)");
            }
            (None, true, false) => {
                let _ = writeln!(out, " (any number of these)");
            }
            (None, false, true) => {
                let _ = writeln!(out, " (required)");
            }
            (None, false, false) => {
                let _ = writeln!(out, " (optional)");
            }
        }
        let _ = writeln!(out, "      {}", s.help);
        for a in s.args {
            let unit = if a.unit.is_empty() {
                String::new()
            } else {
                format!(", in {}", a.unit)
            };
            let _ = writeln!(out, "      {}: {}{unit}", a.name, a.ty);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conf::Kind;

    #[derive(serde::Deserialize, Debug)]
    struct Demo {
        max_v: f32,
        walk: (f32, f32),
        cycle: u64,
        mode: String,
        camera: Option<String>,
        provides: Vec<(String, Option<String>)>,
        debug: bool,
    }
    const DEMO: &[Setting] = &[
        Setting::new("max_v", "speed", &[float("V", "mm/s", 1.0, 1000.0)]).default("500"),
        Setting::new(
            "walk",
            "walk",
            &[
                float("V", "mm/s", -1000.0, 1000.0),
                float("W", "deg/s", -180.0, 180.0),
            ],
        )
        .default("0 0"),
        CYCLE.default("100"),
        Setting::new("mode", "mode", &[choice("MODE", &["a", "b"])]).default("a"),
        Setting::new("camera", "camera", &[interface("INTERFACE")]),
        Setting::new(
            "provides",
            "provides",
            &[interface("INTERFACE"), word("ROBOT").optional()],
        )
        .repeats(),
        Setting::new("debug", "debug", &[on_off("SWITCH")]).default("off"),
    ];

    fn conf(text: &str) -> ComponentConf {
        ComponentConf::from_text(Kind::Schema, "demo", text).unwrap()
    }

    #[test]
    fn defaults_values_and_repeats() {
        let d: Demo = conf("").settings(DEMO).unwrap();
        assert_eq!((d.max_v, d.walk, d.cycle), (500.0, (0.0, 0.0), 100));
        assert_eq!(d.mode, "a");
        assert!(d.camera.is_none() && d.provides.is_empty() && !d.debug);
        let d: Demo = conf(
            "max_v 20\nwalk 1 -2\ncycle 5\nmode b\ncamera colorA\nprovides laser\n\
             provides motors robot2\ndebug on\n",
        )
        .settings(DEMO)
        .unwrap();
        assert_eq!((d.max_v, d.walk, d.cycle), (20.0, (1.0, -2.0), 5));
        assert_eq!(d.camera.as_deref(), Some("colorA"));
        assert_eq!(
            d.provides,
            vec![
                ("laser".into(), None),
                ("motors".into(), Some("robot2".into()))
            ]
        );
        assert!(d.debug);
    }

    #[test]
    fn every_bad_value_names_its_line_and_range() {
        let cases = [
            ("max_v 4000000000000", "between 1 and 1000 mm/s"),
            ("max_v nan", "between 1 and 1000"),
            ("walk 1", "takes 2 argument(s), got 1; usage: walk V W"),
            ("walk 1 2 3", "got 3"),
            ("cycle 18446744073709551616", "between 1 and 10000 ms"),
            ("mode c", "one of a, b"),
            ("camera lazer", "an interface"),
            ("debug maybe", "on or off"),
            ("colour 3", "takes no `colour` line; its lines: max_v, walk"),
        ];
        for (line, want) in cases {
            let e = conf(&format!("\n{line}\n"))
                .settings::<Demo>(DEMO)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("<inline>:2: "), "{line}: {e}");
            assert!(e.contains(want), "{line}: {e}");
        }
        let long = "x".repeat(1_000_000);
        let e = conf(&format!("mode {long}\n"))
            .settings::<Demo>(DEMO)
            .unwrap_err()
            .to_string();
        assert!(e.len() < 300, "a long word is cut: {} bytes", e.len());
    }

    #[test]
    fn check_reports_every_problem() {
        let e = check(&conf("max_v 0\nwalk x 0\nmode q\n"), DEMO);
        assert_eq!(e.len(), 3, "{e:?}");
    }

    #[test]
    fn help_lists_every_line() {
        let h = help_text(Kind::Schema, "demo", "a demo", DEMO, "");
        for s in DEMO {
            assert!(h.contains(&s.usage()), "{h}");
        }
        assert!(h.contains("V: a number between 1 and 1000, in mm/s"), "{h}");
        assert!(h.contains("default: 0 0"), "{h}");
    }

    #[test]
    fn loopback_hosts_and_the_listen_guard() {
        for h in [
            "127.0.0.1",
            "127.5.6.7",
            "::1",
            "[::1]",
            "localhost",
            "::ffff:127.0.0.1",
        ] {
            assert!(is_loopback_host(h), "{h}");
        }
        for h in [
            "0.0.0.0",
            "::",
            "10.0.0.2",
            "robot.lab",
            "",
            "[::]",
            "::ffff:10.0.0.1",
        ] {
            assert!(!is_loopback_host(h), "{h}");
        }
        let c = ComponentConf::from_text(Kind::Service, "srv", "bind 0.0.0.0\n").unwrap();
        let e = guard_listen(&c, "bind", "0.0.0.0", false, "add a `token SECRET` line")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(":1:") && e.contains("token SECRET") && e.contains("insecure"),
            "{e}"
        );
        let c = ComponentConf::from_text(Kind::Service, "srv", "insecure\n").unwrap();
        assert_eq!(
            guard_listen(&c, "bind", "10.1.2.3", false, "").unwrap(),
            Exposure::Insecure
        );
    }
}
