//! Declared settings: a component declares the lines it takes once, with
//! [`declare_lines!`](crate::declare_lines): the struct that receives them, each
//! field beside its line's declaration (a [`Setting`]: its arguments with type,
//! unit and range, a default and a line of help). From that one declaration the
//! core
//!
//! - parses, checks and reads a component's lines ([`ComponentConf::read`]): an
//!   unknown keyword, a missing or extra argument, a word that is not a number, a
//!   value out of its range — each is an error at `file:line` naming the range or
//!   the choices, never a silent clamp;
//! - prints `jderobot help NAME` ([`help_text`]);
//! - validates a conf in `jderobot check` before anything is built: the lines
//!   against their declaration, then the typed read ([`check_declared`]), so a
//!   declaration its struct cannot take is an error there, never in a run.
//!
//! ```
//! use jderobot::conf::{ComponentConf, Kind, settings::{Setting, float, CYCLE}};
//! jderobot::declare_lines! {
//!     struct Lines {
//!         max_v: f32 = Setting::new("max_v", "joystick maximum speed",
//!             &[float("V", "mm/s", 1.0, 1000.0)]).default("500"),
//!         walk: (f32, f32) = Setting::new("walk", "initial walk command",
//!             &[float("V", "mm/s", -1000.0, 1000.0), float("W", "deg/s", -180.0, 180.0)])
//!             .default("0 0"),
//!         cycle: u64 = CYCLE.default("100"),
//!     }
//! }
//! let conf = ComponentConf::from_text(Kind::Schema, "demo", "max_v 300\n").unwrap();
//! let l: Lines = conf.read().unwrap();
//! assert_eq!((l.max_v, l.walk, l.cycle), (300.0, (0.0, 0.0), 100));
//! let bad = ComponentConf::from_text(Kind::Schema, "demo", "max_v 4000000000000\n").unwrap();
//! let e = bad.read::<Lines>().err().unwrap().to_string();
//! assert!(e.contains("between 1 and 1000"), "{e}");
//! ```
//!
//! Why serde: the struct a component reads is ordinary Rust (tuples for multi-word
//! lines, `Option` for lines without default, `Vec` for repeated lines, an enum for
//! a line in forms, [`Kind`](crate::interfaces::Kind) for an interface), and serde
//! builds it from the checked words; the ranges, units and help live in the
//! declaration beside each field. A key without its field cannot be written; a
//! type its declaration does not give fails `jderobot check` and the walk of every
//! form in `tests/declarations.rs`.
//!
//! Lines several components share as a set (a serial head's, the HSV range, a
//! Zenoh session's) are a group ([`Setting::group`]): each is still declared and
//! written as a plain line, and the group is read into one field, a struct of its
//! own (`field: Group = [LINE_A, LINE_B, ...]` in `declare_lines!`).

use std::fmt::{self, Write as _};

use serde::de::{self, DeserializeSeed, IntoDeserializer, MapAccess, SeqAccess, Visitor};

use super::{ComponentConf, ConfError, ConfLine, Location};

/// Declares a component's lines once: the struct that receives them, and beside
/// each field the declaration of its line (a [`Setting`]) or, for a group field,
/// of its lines (`[A, B, ...]`, each marked with [`Setting::group`]). It derives
/// `serde::Deserialize` and implements [`Declared`], so `help`, `check` and the
/// typed read ([`ComponentConf::read`]) all come from this one place.
///
/// ```
/// use jderobot::conf::{ComponentConf, Kind, settings::{self, Setting, float, CYCLE}};
/// jderobot::declare_lines! {
///     /// The demo's lines.
///     struct Lines {
///         max_v: f32 = Setting::new("max_v", "joystick maximum speed",
///             &[float("V", "mm/s", 1.0, 1000.0)]).default("500"),
///         cycle: u64 = CYCLE.default("100"),
///     }
/// }
/// let conf = ComponentConf::from_text(Kind::Schema, "demo", "max_v 300\n").unwrap();
/// let l: Lines = conf.read().unwrap();
/// assert_eq!((l.max_v, l.cycle), (300.0, 100));
/// assert_eq!(<Lines as settings::Declared>::LINES.len(), 2);
/// ```
#[macro_export]
macro_rules! declare_lines {
    ($(#[$m:meta])* $vis:vis struct $name:ident { $($body:tt)* }) => {
        $crate::declare_lines!(@field ($(#[$m])* $vis struct $name) [] [] $($body)*);
    };
    // A group field: its lines in a row.
    (@field $head:tt [$($fields:tt)*] [$($decls:tt)*]
        $(#[$fm:meta])* $fvis:vis $field:ident : $ty:ty = [$($g:expr),+ $(,)?] $(, $($rest:tt)*)?) => {
        $crate::declare_lines!(@field $head [$($fields)* $(#[$fm])* $fvis $field: $ty,]
            [$($decls)* $($g,)+] $($($rest)*)?);
    };
    // A field of one line.
    (@field $head:tt [$($fields:tt)*] [$($decls:tt)*]
        $(#[$fm:meta])* $fvis:vis $field:ident : $ty:ty = $decl:expr $(, $($rest:tt)*)?) => {
        $crate::declare_lines!(@field $head [$($fields)* $(#[$fm])* $fvis $field: $ty,]
            [$($decls)* $decl,] $($($rest)*)?);
    };
    (@field ($(#[$m:meta])* $vis:vis struct $name:ident) [$($fields:tt)*] [$($decls:tt)*]) => {
        $(#[$m])*
        #[derive(serde::Deserialize)]
        $vis struct $name { $($fields)* }
        impl $crate::conf::settings::Declared for $name {
            const LINES: &'static [$crate::conf::settings::Setting] = &[$($decls)*];
        }
    };
}

/// What one argument of a line may be.
#[derive(Clone, Copy, Debug)]
pub enum ArgType {
    /// A whole number within `[min, max]`.
    Int { min: i64, max: i64 },
    /// A finite number within `[min, max]`.
    Float { min: f64, max: f64 },
    /// A finite number within `[min, max]`, or the word `or` (`auto`, `max`):
    /// read as a [`NumberOr`].
    FloatOr {
        min: f64,
        max: f64,
        or: &'static str,
    },
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
    /// A name (a robot's, a camera's): a word that is not a number, without dots
    /// or colons (a name becomes an interface suffix: `laser.robot2`).
    Name,
    /// Every remaining word, each one of these and each at most once, in any order
    /// (must be last; none is fine). Read as a `Vec`.
    Flags(&'static [&'static str]),
    /// One of these interface kinds, by its name (4.3's aliases accepted): read
    /// as a [`Kind`](crate::interfaces::Kind), so a `provides` line's interface is
    /// a kind from the declaration on, never a string matched again.
    Kinds(&'static [crate::interfaces::Kind]),
    /// Every remaining word, each a finite number within `[min, max]` (must be
    /// last; at least one). Read as a `Vec` of numbers.
    Numbers { min: f64, max: f64 },
    /// A word that `check` accepts (a Zenoh key, an IPv4 address); `what` says
    /// what it must be, in `help` and in the error. Read as a `String`.
    Custom {
        what: &'static str,
        check: fn(&str) -> Result<(), String>,
    },
}

/// One argument of a declared line.
#[derive(Clone, Copy, Debug)]
pub struct Arg {
    pub name: &'static str,
    pub ty: ArgType,
    /// The unit of a number (`mm/s`, `deg`, `ms`), or "".
    pub unit: &'static str,
    /// The line may stop before this argument, or leave it out: it opens a group
    /// (it and the required arguments after it, to the next optional one) given
    /// whole or not at all.
    pub optional: bool,
}

impl Arg {
    /// Whether `word` is one of a [`choice`]'s words (a form's first word).
    pub fn accepts(&self, word: &str) -> bool {
        match self.ty {
            ArgType::Choice(c) => c.contains(&word),
            ArgType::Kinds(k) => kind_in(k, word).is_some(),
            _ => false,
        }
    }
    /// This argument opens an optional group (it and the required ones after it).
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
/// A finite number in `[min, max]`, in `unit`, or the word `or`.
pub const fn float_or(
    name: &'static str,
    unit: &'static str,
    min: f64,
    max: f64,
    or: &'static str,
) -> Arg {
    arg(name, ArgType::FloatOr { min, max, or }, unit)
}
/// What a [`float_or`] argument gives: its number, or its word.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NumberOr {
    Number(f64),
    Word,
}

impl<'de> serde::Deserialize<'de> for NumberOr {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = NumberOr;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a number or its word")
            }
            fn visit_f64<E>(self, v: f64) -> Result<NumberOr, E> {
                Ok(NumberOr::Number(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<NumberOr, E> {
                Ok(NumberOr::Number(v as f64))
            }
            fn visit_str<E>(self, _: &str) -> Result<NumberOr, E> {
                Ok(NumberOr::Word)
            }
            fn visit_string<E>(self, _: String) -> Result<NumberOr, E> {
                Ok(NumberOr::Word)
            }
        }
        d.deserialize_any(V)
    }
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
/// A name: a word that is not a number, without dots or colons.
pub const fn name(name: &'static str) -> Arg {
    arg(name, ArgType::Name, "")
}
/// Any of these words, each at most once, in any order, to the end of the line.
pub const fn flags(name: &'static str, words: &'static [&'static str]) -> Arg {
    arg(name, ArgType::Flags(words), "")
}
/// One of interface kinds `kinds` (read as a [`Kind`](crate::interfaces::Kind)).
pub const fn kinds(name: &'static str, kinds: &'static [crate::interfaces::Kind]) -> Arg {
    arg(name, ArgType::Kinds(kinds), "")
}
/// A word that `check` accepts; `what` names what it must be.
pub const fn custom(
    name: &'static str,
    what: &'static str,
    check: fn(&str) -> Result<(), String>,
) -> Arg {
    arg(name, ArgType::Custom { what, check }, "")
}
/// Every remaining word, each a number in `[min, max]`, in `unit`.
pub const fn numbers(name: &'static str, unit: &'static str, min: f64, max: f64) -> Arg {
    arg(name, ArgType::Numbers { min, max }, unit)
}
/// The kind of `kinds` that `word` names (4.3's aliases accepted).
fn kind_in(kinds: &[crate::interfaces::Kind], word: &str) -> Option<crate::interfaces::Kind> {
    crate::interfaces::Kind::parse(&crate::interfaces::canonical(word))
        .filter(|k| kinds.contains(k))
}
/// A size in pixels, 1..=`max`.
pub const fn pixels(name: &'static str, max: i64) -> Arg {
    arg(name, ArgType::Int { min: 1, max }, "px")
}

/// The fixed-size image interfaces (320x240), as a `provides` form's first word.
pub const COLOR: Arg = choice("colorA..D", &["colorA", "colorB", "colorC", "colorD"]);
/// The image interfaces of any size, as a `provides` form's first word.
pub const VARCOLOR: Arg = choice(
    "varcolorA..D",
    &["varcolorA", "varcolorB", "varcolorC", "varcolorD"],
);

/// One form of a line whose first word chooses the rest: a `provides` line, whose
/// interface decides what follows it (`provides laser N RESOLUTION`, `provides
/// varcolorA FILE W H`). A line is read in the first form it fits; a struct reads
/// such lines as an enum whose variants are the forms' names (each variant gets
/// every word of the line, the first included, an absent optional one as `None`).
#[derive(Clone, Copy, Debug)]
pub struct Form {
    /// The enum variant that receives it.
    pub name: &'static str,
    /// What it gives, for `help`.
    pub help: &'static str,
    /// Its arguments, the first word included (a [`choice`] of the words that
    /// choose this form).
    pub args: &'static [Arg],
}

impl Form {
    pub const fn new(name: &'static str, help: &'static str, args: &'static [Arg]) -> Form {
        Form { name, help, args }
    }
    /// The usage: `KEY ARG1 ARG2 [ARG3]`.
    pub fn usage(&self, key: &str) -> String {
        usage(key, self.args)
    }
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
    /// The forms of a line whose first word chooses the rest (`args` is then
    /// empty): see [`Form`].
    pub forms: &'static [Form],
    /// The group of lines it belongs to ([`Setting::group`]).
    pub group: Option<&'static str>,
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
            forms: &[],
            group: None,
        }
    }
    /// A line in several forms, its first word choosing which ([`Form`]).
    pub const fn forms(key: &'static str, help: &'static str, forms: &'static [Form]) -> Setting {
        let mut s = Setting::new(key, help, &[]);
        s.forms = forms;
        s
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
    /// The line belongs to the group `name`: a set of lines several components
    /// share, read into one field `name` of the settings struct (a struct of its
    /// own that derives `Deserialize`). The conf and `help` see plain lines.
    pub const fn group(mut self, name: &'static str) -> Setting {
        self.group = Some(name);
        self
    }
    /// The same line with another help text.
    pub const fn help(mut self, help: &'static str) -> Setting {
        self.help = help;
        self
    }
    /// The usage: `KEY ARG1 ARG2 [ARG3]` (its forms' usages, for a line in forms).
    pub fn usage(&self) -> String {
        if self.forms.is_empty() {
            usage(self.key, self.args)
        } else {
            let u: Vec<String> = self.forms.iter().map(|f| f.usage(self.key)).collect();
            u.join(" | ")
        }
    }
}

/// `KEY ARG1 ARG2 [ARG3 ARG4] [ARG5]`: an optional argument opens a group that
/// runs to the next optional one.
fn usage(key: &str, args: &[Arg]) -> String {
    let mut s = key.to_string();
    let mut open = false;
    for a in args {
        let flags = matches!(a.ty, ArgType::Flags(_));
        if (a.optional || flags) && open {
            s.push(']');
            open = false;
        }
        if a.optional || flags {
            s.push_str(" [");
            open = true;
        } else {
            s.push(' ');
        }
        match a.ty {
            ArgType::Flags(w) => {
                s.push_str(&w.join("|"));
                s.push_str("]...");
                open = false;
            }
            ArgType::Rest | ArgType::Numbers { .. } => {
                s.push_str(a.name);
                s.push_str("...");
            }
            _ => s.push_str(a.name),
        }
    }
    if open {
        s.push(']');
    }
    s
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

/// `token SECRET`: a shared secret ([`crate::secret`]: 16 to 128 printable
/// characters, refused at its line otherwise). Each component gives its help.
pub const TOKEN: Setting = Setting::new(
    "token",
    "a shared secret",
    &[custom(
        "SECRET",
        "a secret of 16 to 128 printable ASCII characters without spaces",
        crate::secret::check_token,
    )],
);

/// `domain ID`: the ROS 2 domain (ROS_DOMAIN_ID) of the ros2 driver and service.
pub const ROS_DOMAIN: Setting =
    Setting::new("domain", "ROS_DOMAIN_ID", &[int("ID", "", 0, 232)]).default("0");
/// `discovery localhost|subnet`: how far a ROS 2 component's DDS reaches (ROS 2's
/// `ROS_AUTOMATIC_DISCOVERY_RANGE`); without the line, that variable (or
/// `ROS_LOCALHOST_ONLY=1`) decides, else `subnet`.
pub const ROS_DISCOVERY: Setting = Setting::new(
    "discovery",
    "how far DDS reaches: localhost (this host only) or subnet (the LAN; needs `insecure`); \
     default: ROS_AUTOMATIC_DISCOVERY_RANGE or ROS_LOCALHOST_ONLY, else subnet",
    &[choice("RANGE", &["localhost", "subnet"])],
);
/// `node NAME`: the ROS 2 node's name (each component gives its default).
pub const ROS_NODE: Setting = Setting::new("node", "the ROS 2 node's name", &[word("NAME")]);
/// `namespace NS`: the ROS 2 node's namespace, which relative topic names are in.
pub const ROS_NAMESPACE: Setting = Setting::new(
    "namespace",
    "the node's namespace, also its relative topics'",
    &[word("NS")],
)
.default("/");
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

/// `provides INTERFACE ...`, any number of them, each in one of `forms` (the
/// interface, a form's first argument, chooses which).
pub const fn provides_forms(help: &'static str, forms: &'static [Form]) -> Setting {
    Setting::forms("provides", help, forms).repeats()
}

/// `KEY INTERFACE`: an interface the component uses in a role (`motors motors`,
/// `camera varcolorA`), the interface of the role's own name when absent
/// (another with `.default("colorA")`); schemas take `none` for "do without"
/// where they can (the help says so).
pub const fn uses(key: &'static str, help: &'static str) -> Setting {
    const ARGS: &[Arg] = &[interface("INTERFACE")];
    Setting::new(key, help, ARGS).default(key)
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

impl ArgType {
    /// Whether it takes every remaining word (it must be last).
    pub fn takes_the_rest(&self) -> bool {
        matches!(
            self,
            ArgType::Rest | ArgType::Flags(_) | ArgType::Numbers { .. }
        )
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
            ArgType::FloatOr { min, max, or } => {
                write!(f, "a number {}, or {or}", range_words(*min, *max))
            }
            ArgType::Choice(c) => write!(f, "one of {}", c.join(", ")),
            ArgType::OnOff => f.write_str("on or off"),
            ArgType::Interface => f.write_str("an interface name or none"),
            ArgType::Path => f.write_str("a file (relative to the conf file)"),
            ArgType::Word => f.write_str("a word"),
            ArgType::Rest => f.write_str("one or more words"),
            ArgType::Name => {
                f.write_str("a name (a word that is not a number, without dots or colons)")
            }
            ArgType::Flags(w) => write!(f, "any of {}, each at most once", w.join(", ")),
            ArgType::Kinds(k) => {
                let names: Vec<&str> = k.iter().map(|k| k.name()).collect();
                write!(f, "one of {}", names.join(", "))
            }
            ArgType::Custom { what, .. } => f.write_str(what),
            ArgType::Numbers { min, max } => {
                write!(f, "one or more numbers, each {}", range_words(*min, *max))
            }
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
    /// The words of a [`ArgType::Flags`] argument.
    List(Vec<String>),
    /// The numbers of a [`ArgType::Numbers`] argument.
    Numbers(Vec<f64>),
    /// An optional argument left out.
    Absent,
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
        ArgType::FloatOr { min, max, or } => match w.parse::<f64>() {
            _ if w == or => Ok(Value::Str(w.to_string())),
            Ok(v) if v.is_finite() && v >= min && v <= max => Ok(Value::Float(v)),
            _ => Err(bad(
                format!("{}", ArgType::Float { min, max }) + &format!("{unit}, or {or}")
            )),
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
        ArgType::Name => {
            if w.parse::<f64>().is_ok() || w.contains(['.', ':']) {
                Err(bad(a.ty.to_string()))
            } else {
                Ok(Value::Str(w.to_string()))
            }
        }
        ArgType::Flags(set) => {
            if set.contains(&w) {
                Ok(Value::Str(w.to_string()))
            } else {
                Err(bad(a.ty.to_string()))
            }
        }
        ArgType::Kinds(k) => match kind_in(k, w) {
            Some(kind) => Ok(Value::Str(kind.name().to_string())),
            None => Err(bad(a.ty.to_string())),
        },
        ArgType::Numbers { min, max } => match w.parse::<f64>() {
            Ok(v) if v.is_finite() && v >= min && v <= max => Ok(Value::Float(v)),
            _ => Err(bad(format!("a number {}{unit}", range_words(min, max)))),
        },
        ArgType::Custom { what, check } => match check(w) {
            Ok(()) => Ok(Value::Str(w.to_string())),
            Err(why) => Err(bad(format!("{what} ({why})"))),
        },
    }
}

/// One checked line: the form it is in (a line in forms) and its values, one per
/// declared argument ([`Value::Absent`] for an optional one left out; a `Rest`
/// argument gives one per word).
#[derive(Clone, Debug)]
struct Checked {
    form: Option<&'static str>,
    values: Vec<Value>,
}

/// Checks a line's arguments against its declaration (against the forms its
/// first word may be in, for a line in forms).
fn check_line(s: &Setting, line: &ConfLine, component: &str) -> Result<Checked, ConfError> {
    if s.forms.is_empty() {
        let values = check_args(s.key, s.args, &s.usage(), line, component)?;
        return Ok(Checked { form: None, values });
    }
    let first = line.args().first().map(String::as_str).unwrap_or("");
    let candidates: Vec<&Form> = s
        .forms
        .iter()
        .filter(|f| {
            f.args
                .first()
                .is_some_and(|a| check_word(line, 0, a, first).is_ok())
        })
        .collect();
    if candidates.is_empty() {
        let mut firsts: Vec<String> = Vec::new();
        for f in s.forms {
            if let Some(a) = f.args.first()
                && !firsts.contains(&a.name.to_string())
            {
                firsts.push(a.name.to_string());
            }
        }
        return Err(line.error(format!(
            "`{} {}`: {component} {} {}, not `{}`; usage: {} (see `jderobot help {component}`)",
            s.key,
            echo(first),
            if s.key == "provides" {
                "provides"
            } else {
                "takes"
            },
            firsts.join(", "),
            echo(first),
            s.usage()
        )));
    }
    // The first form that fits; else the error of the one that fits the most
    // leading words (the others' usages said with it).
    let mut errors = Vec::new();
    for f in &candidates {
        match check_args(s.key, f.args, &f.usage(s.key), line, component) {
            Ok(values) => {
                return Ok(Checked {
                    form: Some(f.name),
                    values,
                });
            }
            Err(e) => errors.push(e),
        }
    }
    // The form meant: one that takes as many words as given, then the one whose
    // arguments fit the most leading words.
    let fit = |f: &Form| {
        let words = line.args();
        (0..words.len())
            .take_while(|&k| {
                let a = &f.args[k.min(f.args.len() - 1)];
                (k < f.args.len() || a.ty.takes_the_rest())
                    && check_word(line, k, a, &words[k]).is_ok()
            })
            .count()
    };
    let score = |k: usize| (!errors[k].message.contains(" takes "), fit(candidates[k]));
    let pick = (0..candidates.len())
        .rev()
        .max_by_key(|&k| score(k))
        .unwrap_or(0);
    let mut e = errors.swap_remove(pick);
    if candidates.len() > 1 && !e.message.contains("usage:") {
        let all: Vec<String> = candidates.iter().map(|f| f.usage(s.key)).collect();
        e.message.push_str(&format!("; usage: {}", all.join(" | ")));
    }
    Err(e)
}

/// Checks a line's words against `args`: the required ones first, then each
/// optional group (an optional argument and the required ones after it) taken
/// when its words fit and skipped otherwise, then a trailing `Rest` or `Flags`.
fn check_args(
    key: &str,
    args: &[Arg],
    usage: &str,
    line: &ConfLine,
    component: &str,
) -> Result<Vec<Value>, ConfError> {
    let mut c = ArgCheck {
        key,
        usage,
        line,
        component,
        args,
        words: line.args(),
        out: Vec::with_capacity(args.len()),
        skipped: None,
        skipped_begun: false,
        at: 0,
    };
    let mut i = 0; // the next argument
    while i < args.len() {
        let a = &args[i];
        match a.ty {
            ArgType::Rest => c.rest(a)?,
            ArgType::Numbers { .. } => c.numbers(a)?,
            ArgType::Flags(_) => c.flags(a)?,
            _ => {
                // A group: this argument and the required ones after it.
                let end = args[i + 1..]
                    .iter()
                    .position(|b| b.optional || b.ty.takes_the_rest())
                    .map_or(args.len(), |p| i + 1 + p);
                c.group(&args[i..end])?;
                i = end;
                continue;
            }
        }
        i += 1;
    }
    c.finish()
}

/// [`check_args`]'s state: the words read so far and what they gave.
struct ArgCheck<'a> {
    key: &'a str,
    usage: &'a str,
    line: &'a ConfLine,
    component: &'a str,
    args: &'a [Arg],
    words: &'a [String],
    out: Vec<Value>,
    /// The first error of a group that was skipped: the likely mistake when
    /// words are left over; and whether that group was begun.
    skipped: Option<ConfError>,
    skipped_begun: bool,
    /// The next word.
    at: usize,
}

impl ArgCheck<'_> {
    /// The error of a wrong number of words.
    fn arity(&self) -> ConfError {
        let args = self.args;
        let required = args
            .iter()
            .take_while(|a| !a.optional && !matches!(a.ty, ArgType::Flags(_)))
            .count();
        let open_end = args.last().is_some_and(|a| a.ty.takes_the_rest());
        let fixed: usize = args.iter().filter(|a| !a.ty.takes_the_rest()).count();
        let max = if open_end { usize::MAX } else { fixed };
        let n = self.words.len();
        self.line.error(format!(
            "`{}` takes {}, got {n}; usage: {} (see `jderobot help {}`)",
            self.key,
            match (required, max) {
                (a, b) if a == b => format!("{a} argument(s)"),
                (a, usize::MAX) => format!("at least {a} argument(s)"),
                (a, b) => format!("{a} to {b} arguments"),
            },
            self.usage,
            self.component,
        ))
    }

    /// A trailing `Rest`: every word left.
    fn rest(&mut self, a: &Arg) -> Result<(), ConfError> {
        if self.words.len() <= self.at && !a.optional {
            return Err(self.arity());
        }
        for (k, w) in self.words.iter().enumerate().skip(self.at) {
            self.out.push(check_word(self.line, k, a, w)?);
        }
        self.at = self.words.len();
        Ok(())
    }

    /// A trailing `Numbers`: every word left, one list.
    fn numbers(&mut self, a: &Arg) -> Result<(), ConfError> {
        if self.words.len() <= self.at {
            return Err(self.arity());
        }
        let mut list = Vec::new();
        for (k, w) in self.words.iter().enumerate().skip(self.at) {
            if let Value::Float(v) = check_word(self.line, k, a, w)? {
                list.push(v);
            }
        }
        self.out.push(Value::Numbers(list));
        self.at = self.words.len();
        Ok(())
    }

    /// Trailing `Flags`: every word left, each once.
    fn flags(&mut self, a: &Arg) -> Result<(), ConfError> {
        let mut list: Vec<String> = Vec::new();
        for (k, w) in self.words.iter().enumerate().skip(self.at) {
            if let Err(e) = check_word(self.line, k, a, w) {
                return Err(self.skipped.take().unwrap_or(e));
            }
            if list.contains(w) {
                return Err(self.line.error(format!(
                    "`{}`: `{}` is given twice; usage: {}",
                    self.key,
                    echo(w),
                    self.usage
                )));
            }
            list.push(w.clone());
        }
        self.out.push(Value::List(list));
        self.at = self.words.len();
        Ok(())
    }

    /// A group: a required one must fit; an optional one is taken when it fits.
    fn group(&mut self, group: &[Arg]) -> Result<(), ConfError> {
        let (line, at, words) = (self.line, self.at, self.words);
        if !group[0].optional {
            if words.len() < at + group.len() {
                return Err(self.arity());
            }
            for (k, b) in group.iter().enumerate() {
                self.out.push(check_word(line, at + k, b, &words[at + k])?);
            }
            self.at += group.len();
            return Ok(());
        }
        let fits = if words.len() >= at + group.len() {
            group
                .iter()
                .enumerate()
                .map(|(k, b)| check_word(line, at + k, b, &words[at + k]))
                .collect::<Result<Vec<Value>, ConfError>>()
        } else {
            Err(self.arity())
        };
        match fits {
            Ok(v) => {
                self.out.extend(v);
                self.at += group.len();
            }
            Err(e) => {
                // A group whose first word fits was begun: its error is the
                // one to tell; else the first wrong word's.
                let begun = words
                    .get(at)
                    .is_some_and(|w| check_word(line, at, &group[0], w).is_ok());
                if words.len() > at
                    && (begun || !e.message.contains(" takes "))
                    && (self.skipped.is_none() || (begun && !self.skipped_begun))
                {
                    self.skipped = Some(e);
                    self.skipped_begun = begun;
                }
                self.out.extend(group.iter().map(|_| Value::Absent));
            }
        }
        Ok(())
    }

    /// The values, or the error of words left over.
    fn finish(mut self) -> Result<Vec<Value>, ConfError> {
        if self.at < self.words.len() {
            return Err(match self.skipped.take() {
                Some(mut e) => {
                    if !e.message.contains("usage:") {
                        e.message.push_str(&format!("; usage: {}", self.usage));
                    }
                    e
                }
                None => self.arity(),
            });
        }
        Ok(self.out)
    }
}

/// The checked values of every declared line: given or default.
struct Parsed<'a> {
    entries: Vec<Entry<'a>>,
}

/// A component's lines declared once: the struct that receives them, each field
/// beside its line's declaration. Made by [`declare_lines!`](crate::declare_lines),
/// read with [`ComponentConf::read`], registered with `declared = TYPE` so
/// `jderobot check` and `jderobot help` take the same declaration.
pub trait Declared: serde::de::DeserializeOwned {
    /// The lines, in the struct's field order (a group field's lines in a row).
    const LINES: &'static [Setting];
}

crate::declare_lines! {
    /// The lines of a component that takes none (`lines = NoLines`): any line is
    /// an error naming it.
    pub struct NoLines {}
}

/// `jderobot check` of a [`Declared`] component: every line against its
/// declaration ([`check`]), then, when they pass, the typed read itself, so a
/// declaration its struct cannot take is an `internal` error here, before a run.
pub fn check_declared<T: Declared>(conf: &ComponentConf) -> Vec<ConfError> {
    let errors = check(conf, T::LINES);
    if !errors.is_empty() {
        return errors;
    }
    conf.read::<T>().err().into_iter().collect()
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
    /// Reads this component's lines into `T`, the struct that declares them
    /// ([`Declared`]): every line checked (type, range, count), defaults filled in.
    pub fn read<T: Declared>(&self) -> Result<T, ConfError> {
        self.settings(T::LINES)
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
            entries: parsed.entries.iter().collect(),
            group: None,
            at: &at,
        })
        .map_err(|e| {
            // serde's own error (the struct does not take what was declared): the
            // component's conf is where it shows.
            if *e.0.at.file == *std::path::Path::new(SERDE_PLACE) {
                ConfError { at, ..e.0 }
            } else {
                e.0
            }
        })
    }
}

/// Where a serde error of its own is, until [`ComponentConf::settings`] places it.
const SERDE_PLACE: &str = "<settings>";

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
                file: std::sync::Arc::from(std::path::Path::new(SERDE_PLACE)),
                line: 0,
            },
            message: format!("internal: settings do not match their declaration: {msg}"),
        })
    }
}

/// The whole component (`group` None), or one group of its lines: a map from
/// key (or group name) to line (or group).
struct Lines<'p, 'a> {
    entries: Vec<&'p Entry<'a>>,
    group: Option<&'static str>,
    at: &'p Location,
}

/// A field at one level: a line, or a group of lines (`group`).
struct Item<'p, 'a> {
    key: &'static str,
    group: bool,
    entries: Vec<&'p Entry<'a>>,
}

impl<'p, 'a> Lines<'p, 'a> {
    /// The fields at this level, in declaration order: a line outside any group
    /// (or inside the group read here) by its key, a group by its name.
    fn items(&self) -> Vec<Item<'p, 'a>> {
        let mut items: Vec<Item<'p, 'a>> = Vec::new();
        for &e in &self.entries {
            let (key, group) = match e.0.group {
                Some(g) if self.group != Some(g) => (g, true),
                _ => (e.0.key, false),
            };
            match items.iter_mut().find(|i| i.key == key) {
                Some(i) => i.entries.push(e),
                None => items.push(Item {
                    key,
                    group,
                    entries: vec![e],
                }),
            }
        }
        items
    }
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
        let items = self.items();
        for i in &items {
            if !fields.contains(&i.key) {
                return Err(internal(format!(
                    "line or group `{}` is declared but the settings struct has no such field",
                    i.key
                )));
            }
        }
        for f in fields {
            if !items.iter().any(|i| i.key == *f) {
                return Err(internal(format!(
                    "field `{f}` of the settings struct is not a declared line or group"
                )));
            }
        }
        visitor.visit_map(LineMap {
            // An absent line without default is left out (an `Option` reads None).
            items: items
                .into_iter()
                .filter(|i| {
                    let (s, _, v) = i.entries[0];
                    i.group || s.repeats || !v.is_empty()
                })
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
type Entry<'a> = (&'a Setting, Option<Location>, Vec<Checked>);

struct LineMap<'p, 'a> {
    items: Vec<Item<'p, 'a>>,
    next: usize,
    at: &'p Location,
}

impl<'de> MapAccess<'de> for LineMap<'_, '_> {
    type Error = DeError;
    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, DeError> {
        let Some(i) = self.items.get(self.next) else {
            return Ok(None);
        };
        seed.deserialize(i.key.into_deserializer()).map(Some)
    }
    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, DeError> {
        let i = &self.items[self.next];
        self.next += 1;
        if i.group {
            return seed.deserialize(Lines {
                entries: i.entries.clone(),
                group: Some(i.key),
                at: self.at,
            });
        }
        let (s, at, values) = i.entries[0];
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
            seed.deserialize(LineValue::of(&values[0]))
                .map_err(relocate)
        }
    }
}

/// Every occurrence of a repeated line: a sequence of lines.
struct Occurrences<'p> {
    values: &'p [Checked],
}

impl<'de> de::Deserializer<'de> for Occurrences<'_> {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        visitor.visit_seq(self.values.iter().map(LineValue::of).collect::<Seq<_>>())
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
    /// The form the line is in, for a line in forms: an enum's variant.
    form: Option<&'static str>,
}

impl<'p> LineValue<'p> {
    fn of(c: &'p Checked) -> LineValue<'p> {
        LineValue {
            values: &c.values,
            form: c.form,
        }
    }
    /// The values as elements, padded with missing ones up to `len` (trailing
    /// optional arguments read as `None`).
    fn elements(&self, len: usize) -> Seq<ValueDe> {
        let given = self.values.iter().map(ValueDe::of);
        let missing = (self.values.len()..len).map(|_| ValueDe(None));
        given.chain(missing).collect()
    }
    /// The words given, as a sequence (absent ones left out, flags spread).
    fn words(&self) -> Seq<ValueDe> {
        let mut out = Vec::new();
        for v in self.values {
            match v {
                Value::Absent => {}
                Value::List(l) => {
                    out.extend(l.iter().map(|w| ValueDe(Some(Value::Str(w.clone())))))
                }
                Value::Numbers(l) => out.extend(l.iter().map(|x| ValueDe(Some(Value::Float(*x))))),
                v => out.push(ValueDe(Some(v.clone()))),
            }
        }
        out.into_iter().collect()
    }
}

/// A line in forms read as an enum: the form is the variant, every word its
/// content.
struct FormAccess<'p>(LineValue<'p>);

impl<'de> de::EnumAccess<'de> for FormAccess<'_> {
    type Error = DeError;
    type Variant = Self;
    fn variant_seed<V: DeserializeSeed<'de>>(self, seed: V) -> Result<(V::Value, Self), DeError> {
        let name = self.0.form.unwrap_or_default();
        let v = seed.deserialize(de::value::StrDeserializer::<DeError>::new(name))?;
        Ok((v, self))
    }
}

impl<'de> de::VariantAccess<'de> for FormAccess<'_> {
    type Error = DeError;
    fn unit_variant(self) -> Result<(), DeError> {
        Ok(())
    }
    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, DeError> {
        seed.deserialize(LineValue {
            values: self.0.values,
            form: None,
        })
    }
    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, DeError> {
        visitor.visit_seq(self.0.elements(len))
    }
    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, DeError> {
        visitor.visit_seq(self.0.elements(fields.len()))
    }
}

impl<'de> de::Deserializer<'de> for LineValue<'_> {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.values {
            [one] => ValueDe::of(one).deserialize_any(visitor),
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
        if self.form.is_some() {
            return visitor.visit_enum(FormAccess(self));
        }
        match self.values {
            [one] => ValueDe::of(one).deserialize_enum(name, variants, visitor),
            _ => Err(de::Error::custom("an enum reads one word")),
        }
    }
    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        visitor.visit_seq(self.words())
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
        let words: Vec<String> = self
            .values
            .iter()
            .filter(|v| !matches!(v, Value::Absent))
            .map(Value::to_string)
            .collect();
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
            Value::List(l) => f.write_str(&l.join(" ")),
            Value::Numbers(l) => {
                let words: Vec<String> = l.iter().map(f64::to_string).collect();
                f.write_str(&words.join(" "))
            }
            Value::Absent => Ok(()),
        }
    }
}

/// One argument's value (`None`: an optional argument left out). serde's number
/// visitors convert between the integer and float widths, checking the fit.
struct ValueDe(Option<Value>);

impl ValueDe {
    fn of(v: &Value) -> ValueDe {
        ValueDe(match v {
            Value::Absent => None,
            v => Some(v.clone()),
        })
    }
}

impl<'de> de::Deserializer<'de> for ValueDe {
    type Error = DeError;
    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, DeError> {
        match self.0 {
            Some(Value::Int(i)) => visitor.visit_i64(i),
            Some(Value::Float(f)) => visitor.visit_f64(f),
            Some(Value::Bool(b)) => visitor.visit_bool(b),
            Some(Value::Str(s)) => visitor.visit_string(s),
            Some(Value::List(l)) => visitor.visit_seq(
                l.into_iter()
                    .map(|w| ValueDe(Some(Value::Str(w))))
                    .collect::<Seq<_>>(),
            ),
            Some(Value::Numbers(l)) => visitor.visit_seq(
                l.into_iter()
                    .map(|x| ValueDe(Some(Value::Float(x))))
                    .collect::<Seq<_>>(),
            ),
            Some(Value::Absent) | None => visitor.visit_none(),
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
        let head = if s.forms.is_empty() {
            s.usage()
        } else {
            format!("{} ...", s.key)
        };
        let _ = write!(out, "  {head:<32}");
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
        help_args(&mut out, s.args, "      ");
        for f in s.forms {
            let _ = writeln!(out, "    {}", f.usage(s.key));
            let _ = writeln!(out, "        {}", f.help);
            help_args(&mut out, f.args, "        ");
        }
    }
    out
}

/// Each argument's line in `help`: its name, type, range and unit.
fn help_args(out: &mut String, args: &[Arg], indent: &str) {
    for a in args {
        let unit = if a.unit.is_empty() {
            String::new()
        } else {
            format!(", in {}", a.unit)
        };
        let _ = writeln!(out, "{indent}{}: {}{unit}", a.name, a.ty);
    }
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
    fn a_group_of_lines_is_one_field() {
        #[derive(serde::Deserialize, Debug)]
        struct Head {
            port: String,
            poll: u64,
            extra: Option<String>,
        }
        #[derive(serde::Deserialize, Debug)]
        struct Lines {
            head: Head,
            cycle: u64,
        }
        const LINES: &[Setting] = &[
            Setting::new("port", "p", &[word("DEV")]).group("head"),
            CYCLE.default("100"),
            Setting::new("poll", "q", &[int("MS", "ms", 1, 9)])
                .default("3")
                .group("head"),
            Setting::new("extra", "e", &[word("W")]).group("head"),
        ];
        let l: Lines = conf("port /dev/x\ncycle 7\n").settings(LINES).unwrap();
        assert_eq!(
            (l.head.port.as_str(), l.head.poll, l.cycle),
            ("/dev/x", 3, 7)
        );
        assert!(l.head.extra.is_none());
        let e = conf("port a\npoll 10\n")
            .settings::<Lines>(LINES)
            .unwrap_err();
        assert!(e.to_string().starts_with("<inline>:2: "), "{e}");
        // The struct and the declaration must agree about groups as well.
        let e = conf("port a\n").settings::<Head>(&LINES[..1]).unwrap_err();
        assert!(e.to_string().contains("group `head`"), "{e}");
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

    #[derive(serde::Deserialize, Debug, PartialEq)]
    enum Provides {
        #[serde(rename = "plain")]
        Plain(String, Option<String>),
        #[serde(rename = "laser")]
        Laser(String, Option<u32>, Option<f64>, Option<String>),
        #[serde(rename = "video")]
        Video(String, String, Option<u32>, Option<u32>, Vec<String>),
    }
    #[derive(serde::Deserialize, Debug)]
    struct Forms {
        provides: Vec<Provides>,
    }
    const FORMS: &[Setting] = &[provides_forms(
        "what it gives",
        &[
            Form::new(
                "plain",
                "plain",
                &[
                    choice("motors|encoders", &["motors", "encoders"]),
                    name("ROBOT").optional(),
                ],
            ),
            Form::new(
                "laser",
                "a scan",
                &[
                    choice("laser", &["laser"]),
                    int("N", "", 1, 720).optional(),
                    float("RESOLUTION", "readings/deg", 0.01, 100.0),
                    name("ROBOT").optional(),
                ],
            ),
            Form::new(
                "video",
                "frames",
                &[
                    VARCOLOR,
                    word("FILE"),
                    pixels("W", 4096).optional(),
                    pixels("H", 4096),
                    flags("OPTIONS", &["loop", "unpaced"]),
                ],
            ),
        ],
    )];

    #[test]
    fn forms_choose_their_arguments_by_the_first_word() {
        let f: Forms = conf(
            "provides motors\nprovides encoders r2\nprovides laser\nprovides laser r2\n\
             provides laser 360 0.5\nprovides laser 90 2 r3\nprovides varcolorA a.avi\n\
             provides varcolorB b.avi 64 48 unpaced loop\nprovides varcolorC c.avi loop\n",
        )
        .settings(FORMS)
        .unwrap();
        use Provides::*;
        let s = |x: &str| x.to_string();
        assert_eq!(
            f.provides,
            vec![
                Plain(s("motors"), None),
                Plain(s("encoders"), Some(s("r2"))),
                Laser(s("laser"), None, None, None),
                Laser(s("laser"), None, None, Some(s("r2"))),
                Laser(s("laser"), Some(360), Some(0.5), None),
                Laser(s("laser"), Some(90), Some(2.0), Some(s("r3"))),
                Video(s("varcolorA"), s("a.avi"), None, None, vec![]),
                Video(
                    s("varcolorB"),
                    s("b.avi"),
                    Some(64),
                    Some(48),
                    vec![s("unpaced"), s("loop")]
                ),
                Video(s("varcolorC"), s("c.avi"), None, None, vec![s("loop")]),
            ]
        );
        let cases = [
            (
                "provides laser 721 1",
                "N (argument 2) is `721`, expected a whole number between 1 and 720",
            ),
            ("provides laser 360 0", "RESOLUTION (argument 3) is `0`"),
            (
                "provides laser 360",
                "got 2; usage: provides laser [N RESOLUTION] [ROBOT]",
            ),
            (
                "provides laser r.2",
                "ROBOT (argument 2) is `r.2`, expected a name",
            ),
            (
                "provides motors r.2",
                "ROBOT (argument 2) is `r.2`, expected a name",
            ),
            ("provides motors a b", "takes 1 to 2 arguments, got 3"),
            (
                "provides sonars",
                "provides motors|encoders, laser, varcolorA..D, not `sonars`",
            ),
            ("provides varcolorA f 0 48", "W (argument 3) is `0`"),
            (
                "provides varcolorA f 64 48 again",
                "OPTIONS (argument 5) is `again`, expected any of loop, unpaced",
            ),
            ("provides varcolorA f loop loop", "`loop` is given twice"),
        ];
        for (line, want) in cases {
            let e = conf(&format!("{line}\n"))
                .settings::<Forms>(FORMS)
                .unwrap_err()
                .to_string();
            assert!(e.contains(want), "{line}: {e}");
        }
        let h = help_text(Kind::Driver, "demo", "a demo", FORMS, "");
        assert!(h.contains("provides laser [N RESOLUTION] [ROBOT]"), "{h}");
        assert!(
            h.contains("provides varcolorA..D FILE [W H] [loop|unpaced]..."),
            "{h}"
        );
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
