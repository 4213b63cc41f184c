//! The standard interface names of the seed, their families (derived from the value
//! types), 4.3's aliases and robot suffixes.

use super::values::{
    Bumpers, Encoders, Image, Imu, InterfaceValue, Laser, Motors, PtEncoders, PtMotors, Sonars,
    ZoomEncoders, ZoomMotors,
};

/// Every standard interface name and its family, the value type's [`InterfaceValue::KIND`].
pub const STANDARD: &[(&str, &str)] = &[
    ("colorA", Image::KIND),
    ("colorB", Image::KIND),
    ("colorC", Image::KIND),
    ("colorD", Image::KIND),
    ("varcolorA", Image::KIND),
    ("varcolorB", Image::KIND),
    ("varcolorC", Image::KIND),
    ("varcolorD", Image::KIND),
    ("laser", Laser::KIND),
    ("sonars", Sonars::KIND),
    ("encoders", Encoders::KIND),
    ("motors", Motors::KIND),
    ("pantiltencoders", PtEncoders::KIND),
    ("pantiltmotors", PtMotors::KIND),
    ("zoomencoders", ZoomEncoders::KIND),
    ("zoommotors", ZoomMotors::KIND),
    ("bumpers", Bumpers::KIND),
    ("imu", Imu::KIND),
];

/// The standard interface names, for help texts and error messages.
pub const STANDARD_NAMES: [&str; STANDARD.len()] = {
    let mut out = [""; STANDARD.len()];
    let mut i = 0;
    while i < STANDARD.len() {
        out[i] = STANDARD[i].0;
        i += 1;
    }
    out
};

/// The interface family a standard name belongs to (`varcolorB` → image,
/// `laser.robot2` → laser), after resolving 4.3's aliases.
pub fn family(name: &str) -> Option<&'static str> {
    let base = canonical(name.split('.').next().unwrap_or(name));
    STANDARD
        .iter()
        .find(|(n, _)| *n == base)
        .map(|(_, kind)| *kind)
}

/// Resolves 4.3's export names to the manual's interface names.
pub fn canonical(name: &str) -> String {
    let (base, suffix) = match name.split_once('.') {
        Some((b, s)) => (b, Some(s)),
        None => (name, None),
    };
    let base = match base {
        "ptencoders" => "pantiltencoders",
        "ptmotors" => "pantiltmotors",
        "zencoders" => "zoomencoders",
        "zmotors" => "zoommotors",
        "us" => "sonars",
        other => other,
    };
    match suffix {
        Some(s) => format!("{base}.{s}"),
        None => base.to_string(),
    }
}

/// The name of interface `base` for robot/device `suffix` (`laser`, `robot2` →
/// `laser.robot2`); no suffix gives the plain name.
pub fn interface_name(base: &str, suffix: Option<&str>) -> String {
    match suffix {
        Some(s) if !s.is_empty() => format!("{}.{s}", canonical(base)),
        _ => canonical(base),
    }
}
