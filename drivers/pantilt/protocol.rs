//! The Directed Perception PTU's ASCII protocol as 4.3 spoke it: the init sequence,
//! command encoding in encoder steps, and strict reply parsing.

/// Degrees per encoder step: 3.086 arc minutes (4.3's `ENCOD_TO_DEG`).
pub const ENCOD_TO_DEG: f64 = 3.086 / 60.0;

/// The maximum speed 4.3 allowed on either axis, deg/s (pioneer.h).
pub const MAX_SPEED: f32 = 205.89;

/// The speed the init sequence sets (`PS2900`, `TS2900`), in steps/s.
pub const INIT_SPEED_STEPS: i64 = 2900;

/// 4.3's init sequence, in order, each sent with a `\n`. The first one (`\xFF\xFF`)
/// flushes whatever was half-typed on the line; its answer is discarded. The query
/// commands at the end (`PN PX TN TX`) are sent by the driver as queries.
pub const INIT: &[&[u8]] = &[
    b"I", b"CI", b"PB1000", b"TB1000", b"PU6000", b"TU6000", b"PL31", b"TL31", b"PS2900",
    b"TS2900", b"PA9000", b"TA9000", b"PHL", b"PML", b"THL", b"TML", b"PP0", b"TP0", b"LE",
];

/// The flush sent before the init sequence.
pub const FLUSH: &[u8] = b"\xFF\xFF";

/// An axis of the unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    Pan,
    Tilt,
}

impl Axis {
    /// The command letter (`P`, `T`).
    pub fn letter(self) -> char {
        match self {
            Axis::Pan => 'P',
            Axis::Tilt => 'T',
        }
    }
    /// The word the unit uses in its replies (`Pan`, `Tilt`).
    pub fn word(self) -> &'static str {
        match self {
            Axis::Pan => "Pan",
            Axis::Tilt => "Tilt",
        }
    }
}

/// Degrees to encoder steps, rounded to the nearest step (4.3 rounded through a
/// string; the result is the same).
pub fn deg_to_steps(deg: f64) -> i64 {
    (deg / ENCOD_TO_DEG).round() as i64
}

/// Encoder steps to degrees.
pub fn steps_to_deg(steps: i64) -> f64 {
    steps as f64 * ENCOD_TO_DEG
}

/// `PP<steps>` / `TP<steps>`: absolute position.
pub fn position_command(axis: Axis, steps: i64) -> String {
    format!("{}P{steps}", axis.letter())
}

/// `PS<steps/s>` / `TS<steps/s>`: speed (`PS0` stops the axis, as 4.3 used it).
pub fn speed_command(axis: Axis, steps: i64) -> String {
    format!("{}S{steps}", axis.letter())
}

/// The widest range of the PTU-46 models, in steps: pan ±180°, tilt ±90° (the
/// PTU-D46 turns ±159° and tilts +31°/−47°, or −80° on the extended models).
/// Limits a unit reports outside it are refused.
pub const PAN_RANGE: (i64, i64) = (-3500, 3500);
pub const TILT_RANGE: (i64, i64) = (-1750, 1750);

/// Steps a reported position may lie outside the unit's limits (half a degree).
pub const POSITION_SLACK: i64 = 10;

/// The widest range of `axis`, steps.
pub fn device_range(axis: Axis) -> (i64, i64) {
    match axis {
        Axis::Pan => PAN_RANGE,
        Axis::Tilt => TILT_RANGE,
    }
}

/// `steps` answered to `command` if it lies in `range` (of `what`); a reply out
/// of it is refused, never written into an interface.
pub fn check_range(
    command: &str,
    steps: i64,
    range: (i64, i64),
    what: &str,
) -> Result<i64, ReplyError> {
    if (range.0..=range.1).contains(&steps) {
        Ok(steps)
    } else {
        Err(ReplyError::OutOfRange {
            command: command.to_string(),
            steps,
            range: format!(
                "{what} [{}, {}] steps ([{:.2}, {:.2}] deg)",
                range.0,
                range.1,
                steps_to_deg(range.0),
                steps_to_deg(range.1)
            ),
        })
    }
}

/// Why a reply was not what the command asked for.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReplyError {
    /// The unit answered `! ...`.
    #[error("the unit refused `{command}`: `{reply}`")]
    Refused { command: String, reply: String },
    /// Something that is not a PTU reply.
    #[error(
        "unexpected reply `{reply}` to `{command}` (a PTU answers `* ...` or `! ...`; is another device on this port, or the wrong baud rate?)"
    )]
    Garbage { command: String, reply: String },
    /// A well-formed answer with a number no PTU gives.
    #[error(
        "`{command}` answered {steps} steps, out of {range}; refused (a garbled line or another device?)"
    )]
    OutOfRange {
        command: String,
        steps: i64,
        range: String,
    },
}

/// Printable form of raw bytes (non-ASCII as `\xNN`).
pub fn printable(bytes: &[u8]) -> String {
    let mut s = String::new();
    for &b in bytes {
        if (0x20..0x7f).contains(&b) {
            s.push(b as char);
        } else {
            s.push_str(&format!("\\x{b:02X}"));
        }
    }
    s
}

/// Checks one reply line (without its line ending) to `command`: the unit may echo
/// the command first (its default `EE` mode); then `*` and the text (returned, trimmed)
/// or `!` and an error.
pub fn parse_reply<'a>(command: &str, line: &'a [u8]) -> Result<&'a str, ReplyError> {
    let garbage = || ReplyError::Garbage {
        command: command.to_string(),
        reply: printable(line),
    };
    let text = std::str::from_utf8(line).map_err(|_| garbage())?;
    let mut rest = text.trim_start();
    if let Some(r) = rest.strip_prefix(command) {
        rest = r.trim_start();
    }
    if let Some(r) = rest.strip_prefix('*') {
        Ok(r.trim())
    } else if rest.starts_with('!') {
        Err(ReplyError::Refused {
            command: command.to_string(),
            reply: rest.trim().to_string(),
        })
    } else {
        Err(garbage())
    }
}

/// Parses the text of a query reply, `Current Pan position is -123` (after `*`):
/// exactly `<prefix> <Axis> <what> is <integer>`.
pub fn parse_query(command: &str, text: &str, axis: Axis, what: &str) -> Result<i64, ReplyError> {
    let garbage = || ReplyError::Garbage {
        command: command.to_string(),
        reply: format!("* {text}"),
    };
    let words: Vec<&str> = text.split_whitespace().collect();
    match words.as_slice() {
        [prefix, ax, w, "is", n]
            if *ax == axis.word()
                && *w == what
                && matches!(*prefix, "Current" | "Minimum" | "Maximum") =>
        {
            n.parse::<i64>().map_err(|_| garbage())
        }
        _ => Err(garbage()),
    }
}

/// The query, its reply's first word, for position and limits.
pub fn query(axis: Axis, q: Query) -> (String, &'static str) {
    let l = axis.letter();
    match q {
        Query::Position => (format!("{l}P"), "Current"),
        Query::Min => (format!("{l}N"), "Minimum"),
        Query::Max => (format!("{l}X"), "Maximum"),
    }
}

/// What can be asked of an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Query {
    Position,
    Min,
    Max,
}

/// Parses a full query reply line to `q` on `axis`: the steps it names.
pub fn parse_query_line(axis: Axis, q: Query, line: &[u8]) -> Result<i64, ReplyError> {
    let (cmd, first) = query(axis, q);
    let text = parse_reply(&cmd, line)?;
    let n = parse_query(&cmd, text, axis, "position")?;
    if !text.starts_with(first) {
        return Err(ReplyError::Garbage {
            command: cmd,
            reply: printable(line),
        });
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_round_to_nearest() {
        assert_eq!(deg_to_steps(30.0), 583);
        assert_eq!(deg_to_steps(-10.0), -194);
        assert!((steps_to_deg(3090) - 158.93).abs() < 0.01);
    }

    #[test]
    fn steps_out_of_the_range_are_refused() {
        assert_eq!(
            check_range("PP", 3090, PAN_RANGE, "a PTU-46's pan"),
            Ok(3090)
        );
        let e = check_range("PP", 3_090_000, PAN_RANGE, "a PTU-46's pan").unwrap_err();
        assert!(
            e.to_string()
                .contains("`PP` answered 3090000 steps, out of a PTU-46's pan [-3500, 3500]"),
            "{e}"
        );
    }

    #[test]
    fn replies_are_parsed_strictly() {
        assert_eq!(
            parse_query_line(
                Axis::Pan,
                Query::Position,
                b"PP * Current Pan position is -12"
            ),
            Ok(-12)
        );
        assert_eq!(
            parse_query_line(Axis::Tilt, Query::Max, b"* Maximum Tilt position is 604"),
            Ok(604)
        );
        assert!(matches!(
            parse_query_line(Axis::Tilt, Query::Max, b"* Maximum Pan position is 604"),
            Err(ReplyError::Garbage { .. })
        ));
        assert!(matches!(
            parse_query_line(Axis::Pan, Query::Position, b"* Current Pan position is 12x"),
            Err(ReplyError::Garbage { .. })
        ));
        assert!(matches!(
            parse_reply("PP100", b"PP100 ! Maximum allowable Pan position is 3090"),
            Err(ReplyError::Refused { .. })
        ));
        assert!(matches!(
            parse_reply("PP", b"$GPGGA,123519,4807.038,N"),
            Err(ReplyError::Garbage { .. })
        ));
        assert_eq!(parse_reply("PS0", b"*"), Ok(""));
    }
}
