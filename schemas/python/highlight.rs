//! A small Python tokenizer for the panel's highlighting: keywords, builtins,
//! strings (with triple quotes across lines), comments, numbers and the rest.
//! It only colours; it never judges the program (the interpreter does).

/// What a piece of text is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Token {
    Keyword,
    Builtin,
    String,
    Comment,
    Number,
    /// `HAL`, `GUI` and the Academy's calls.
    Academy,
    Plain,
}

const KEYWORDS: &[&str] = &[
    "False", "None", "True", "and", "as", "assert", "async", "await", "break", "class", "continue",
    "def", "del", "elif", "else", "except", "finally", "for", "from", "global", "if", "import",
    "in", "is", "lambda", "nonlocal", "not", "or", "pass", "raise", "return", "try", "while",
    "with", "yield", "match", "case",
];
const BUILTINS: &[&str] = &[
    "print",
    "len",
    "range",
    "min",
    "max",
    "abs",
    "sum",
    "int",
    "float",
    "str",
    "list",
    "dict",
    "tuple",
    "set",
    "enumerate",
    "zip",
    "round",
    "sorted",
    "isinstance",
    "self",
];
const ACADEMY: &[&str] = &[
    "HAL",
    "GUI",
    "WebGUI",
    "Frequency",
    "tick",
    "getSimTime",
    "setV",
    "setW",
    "getPose3d",
    "getLaserData",
    "getBumperData",
    "getImage",
    "showImage",
];

/// Splits `source` into (byte range, token) pieces covering all of it.
pub fn tokens(source: &str) -> Vec<(std::ops::Range<usize>, Token)> {
    let b = source.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    let mut plain_from = 0;
    let flush = |out: &mut Vec<_>, from: usize, to: usize| {
        if to > from {
            out.push((from..to, Token::Plain));
        }
    };
    while i < b.len() {
        let c = b[i];
        let start = i;
        let tok = if c == b'#' {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
            Some(Token::Comment)
        } else if c == b'"' || c == b'\'' {
            let triple = b[i..].starts_with(&[c, c, c]);
            i += if triple { 3 } else { 1 };
            loop {
                if i >= b.len() {
                    break;
                }
                if b[i] == b'\\' {
                    i = (i + 2).min(b.len());
                    continue;
                }
                if triple {
                    if b[i..].starts_with(&[c, c, c]) {
                        i += 3;
                        break;
                    }
                } else if b[i] == c {
                    i += 1;
                    break;
                } else if b[i] == b'\n' {
                    break;
                }
                i += 1;
            }
            Some(Token::String)
        } else if c.is_ascii_digit() && (i == 0 || !is_word(b[i - 1])) {
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'.' || b[i] == b'_') {
                i += 1;
            }
            Some(Token::Number)
        } else if is_word(c) && (i == 0 || !is_word(b[i - 1])) {
            while i < b.len() && is_word(b[i]) {
                i += 1;
            }
            let w = &source[start..i];
            if KEYWORDS.contains(&w) {
                Some(Token::Keyword)
            } else if ACADEMY.contains(&w) {
                Some(Token::Academy)
            } else if BUILTINS.contains(&w) {
                Some(Token::Builtin)
            } else {
                None
            }
        } else {
            // Step over one character (UTF-8 safe).
            i += source[i..].chars().next().map_or(1, char::len_utf8);
            None
        };
        if let Some(t) = tok {
            flush(&mut out, plain_from, start);
            out.push((start..i, t));
            plain_from = i;
        }
    }
    flush(&mut out, plain_from, b.len());
    out
}

fn is_word(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_' || c >= 0x80
}

/// The colour of a token (dark theme friendly).
pub fn color(t: Token) -> egui::Color32 {
    use egui::Color32;
    match t {
        Token::Keyword => Color32::from_rgb(198, 120, 221),
        Token::Builtin => Color32::from_rgb(97, 175, 239),
        Token::String => Color32::from_rgb(152, 195, 121),
        Token::Comment => Color32::from_rgb(127, 132, 142),
        Token::Number => Color32::from_rgb(209, 154, 102),
        Token::Academy => Color32::from_rgb(229, 192, 123),
        Token::Plain => Color32::from_rgb(220, 223, 228),
    }
}

/// A layout job for `source`: monospace, highlighted, line `error_line`
/// (1-based; 0: none) on a red background.
pub fn layout(source: &str, error_line: usize, font: egui::FontId) -> egui::text::LayoutJob {
    use egui::text::{LayoutJob, TextFormat};
    let mut job = LayoutJob::default();
    let err_range = (error_line > 0)
        .then(|| {
            let start = source
                .split_inclusive('\n')
                .take(error_line - 1)
                .map(str::len)
                .sum::<usize>();
            let len = source[start.min(source.len())..]
                .split_inclusive('\n')
                .next()
                .map_or(0, str::len);
            start..start + len
        })
        .filter(|r| r.start < source.len());
    for (range, t) in tokens(source) {
        // Pieces that straddle the error line's ends are split there.
        let mut cuts = vec![range.start, range.end];
        if let Some(e) = &err_range {
            for c in [e.start, e.end] {
                if c > range.start && c < range.end {
                    cuts.push(c);
                }
            }
        }
        cuts.sort_unstable();
        for w in cuts.windows(2) {
            let (a, b) = (w[0], w[1]);
            let mut f = TextFormat::simple(font.clone(), color(t));
            if err_range
                .as_ref()
                .is_some_and(|e| a >= e.start && b <= e.end)
            {
                f.background = egui::Color32::from_rgb(110, 30, 30);
            }
            job.append(&source[a..b], 0.0, f);
        }
    }
    job
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_cover_the_text_and_find_the_kinds() {
        let src =
            "from HAL import HAL\nx = 1.5  # speed\ns = '''a\nb'''\nwhile True:\n    HAL.setV(x)\n";
        let t = tokens(src);
        let joined: String = t.iter().map(|(r, _)| &src[r.clone()]).collect();
        assert_eq!(joined, src);
        let kind = |w: &str| {
            t.iter()
                .find(|(r, _)| &src[r.clone()] == w)
                .map(|(_, k)| *k)
        };
        assert_eq!(kind("from"), Some(Token::Keyword));
        assert_eq!(kind("HAL"), Some(Token::Academy));
        assert_eq!(kind("1.5"), Some(Token::Number));
        assert_eq!(kind("# speed"), Some(Token::Comment));
        assert_eq!(kind("'''a\nb'''"), Some(Token::String));
        assert_eq!(kind("setV"), Some(Token::Academy));
    }
}
