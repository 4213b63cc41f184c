//! The standard interface names of the seed, their families (derived from the value
//! types), 4.3's aliases and robot suffixes.

use super::kinds::Kind;

/// The standard names of images (family [`Kind::Image`]); every other kind of the
/// table has one standard name, its own.
pub const IMAGE_NAMES: [&str; 8] = [
    "colorA",
    "colorB",
    "colorC",
    "colorD",
    "varcolorA",
    "varcolorB",
    "varcolorC",
    "varcolorD",
];

/// Whether two names are the same (`==` in a const context).
const fn same(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The standard interface names, for help texts and error messages: the
/// images', then every other kind of the table ([`Kind::ALL`]) under its own name.
pub const STANDARD_NAMES: [&str; IMAGE_NAMES.len() + Kind::ALL.len() - 1] = {
    let mut out = [""; IMAGE_NAMES.len() + Kind::ALL.len() - 1];
    let mut n = 0;
    while n < IMAGE_NAMES.len() {
        out[n] = IMAGE_NAMES[n];
        n += 1;
    }
    let mut i = 0;
    while i < Kind::ALL.len() {
        if !same(Kind::NAMES[i], Kind::Image.name()) {
            out[n] = Kind::NAMES[i];
            n += 1;
        }
        i += 1;
    }
    out
};

/// The interface family a standard name belongs to (`varcolorB` → image,
/// `laser.robot2` → laser), after resolving 4.3's aliases.
pub fn family(name: &str) -> Option<Kind> {
    let base = canonical(name.split('.').next().unwrap_or(name));
    if IMAGE_NAMES.contains(&base.as_str()) {
        return Some(Kind::Image);
    }
    Kind::parse(&base).filter(|k| *k != Kind::Image)
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
