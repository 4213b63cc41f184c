//! The layers of docs/architecture.md hold: no module imports one above it or
//! beside it, and no component imports another component.
//!
//! The diagram in docs/architecture.md (the fenced block after `<!-- layers -->`)
//! is the rule: one layer per line, top first; names on one line are peers. Every
//! `crate::NAME` path in a file's code (not its comments) must name its own module
//! or one on a lower line; peers may use each other only on the bottom line (the
//! libraries). Components (`drivers`, `services`, `schemas`) are each a peer of every
//! other component: `drivers/player` may not use `crate::drivers::simulator`.

use std::{
    collections::HashMap,
    fs,
    path::{Path, PathBuf},
};

const COMPONENT_FOLDERS: [&str; 3] = ["drivers", "services", "schemas"];

/// The layers, top first, read from docs/architecture.md.
fn layers() -> Vec<Vec<String>> {
    let doc =
        fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/architecture.md"))
            .expect("docs/architecture.md");
    let after = doc
        .split("<!-- layers -->")
        .nth(1)
        .expect("docs/architecture.md has a `<!-- layers -->` marker before the diagram");
    let block = after
        .split("```")
        .nth(1)
        .expect("a fenced diagram after the marker");
    block
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .map(|l| {
            l.split_whitespace()
                .filter(|w| w.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'))
                .map(String::from)
                .collect::<Vec<_>>()
        })
        .filter(|l| !l.is_empty())
        .collect()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The module a file belongs to: `src/runtime/slot.rs` → `runtime`,
/// `drivers/player/wire.rs` → `drivers::player`.
fn module_of(root: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(root).ok()?;
    let parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    match parts.first()?.as_str() {
        "src" if parts.len() >= 2 && parts[1] != "lib" && parts[1] != "main" => {
            Some(parts[1].clone())
        }
        f if COMPONENT_FOLDERS.contains(&f) && parts.len() >= 2 && parts[1] != "mod" => {
            Some(format!("{f}::{}", parts[1]))
        }
        _ => None,
    }
}

/// Every module a piece of code names through `crate::`: `crate::a::b`, and each
/// top-level name of `use crate::{a, b::c, d::{e, f}}`. Comments are skipped.
fn referenced(code: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let lines: Vec<&str> = code.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].split("//").next().unwrap_or("");
        let mut rest = line;
        while let Some(pos) = rest.find("crate::") {
            let before = &rest[..pos];
            let after = &rest[pos + "crate::".len()..];
            rest = after;
            if before.ends_with('$') || before.ends_with(|c: char| c.is_alphanumeric() || c == '_')
            {
                continue;
            }
            if let Some(group) = after.strip_prefix('{') {
                // A `use crate::{...}` group, maybe over several lines.
                let mut text = group.to_string();
                let mut j = i;
                let mut depth =
                    1 + text.matches('{').count() as i32 - text.matches('}').count() as i32;
                while depth > 0 && j + 1 < lines.len() {
                    j += 1;
                    let l = lines[j].split("//").next().unwrap_or("");
                    depth += l.matches('{').count() as i32 - l.matches('}').count() as i32;
                    text.push_str(l);
                    text.push('\n');
                }
                let mut d = 0;
                let mut expect_name = true;
                let mut name = String::new();
                for c in text.chars() {
                    match c {
                        '{' => d += 1,
                        '}' if d == 0 => break,
                        '}' => d -= 1,
                        ',' if d == 0 => expect_name = true,
                        c if d == 0 && expect_name && (c.is_alphanumeric() || c == '_') => {
                            name.push(c)
                        }
                        _ if d == 0 && expect_name && !name.is_empty() => {
                            out.push((i + 1, std::mem::take(&mut name)));
                            expect_name = false;
                        }
                        _ => {}
                    }
                }
                if !name.is_empty() {
                    out.push((i + 1, name));
                }
                continue;
            }
            let path: String = after
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                .collect();
            let mut segs = path.split("::").filter(|s| !s.is_empty());
            if let Some(first) = segs.next() {
                let name = match (COMPONENT_FOLDERS.contains(&first), segs.next()) {
                    (true, Some(second)) => format!("{first}::{second}"),
                    _ => first.to_string(),
                };
                out.push((i + 1, name));
            }
        }
        i += 1;
    }
    out
}

/// The problems: `file:line: MODULE (layer) uses NAME (layer)`.
fn violations() -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let layers = layers();
    let mut level: HashMap<String, usize> = HashMap::new();
    for (i, line) in layers.iter().enumerate() {
        for name in line {
            level.insert(name.clone(), layers.len() - 1 - i);
        }
    }
    let level_of = |module: &str| {
        let top = module.split("::").next().unwrap_or(module);
        level.get(top).copied()
    };
    let mut files = Vec::new();
    for dir in ["src", "drivers", "services", "schemas"] {
        rust_files(&root.join(dir), &mut files);
    }
    files.sort();
    let mut problems = Vec::new();
    for f in files {
        let Some(module) = module_of(root, &f) else {
            continue;
        };
        let Some(mine) = level_of(&module) else {
            problems.push(format!(
                "{}: module `{module}` is in no layer of docs/architecture.md; add it to the diagram",
                f.display()
            ));
            continue;
        };
        let code = fs::read_to_string(&f).unwrap();
        for (line, name) in referenced(&code) {
            let Some(theirs) = level_of(&name) else {
                continue; // a macro or a crate-root re-export
            };
            let ok = name == module || theirs < mine || (theirs == mine && mine == 0);
            if !ok {
                problems.push(format!(
                    "{}:{line}: `{module}` (layer {mine}) uses `{name}` (layer {theirs})",
                    f.strip_prefix(root).unwrap().display()
                ));
            }
        }
    }
    problems
}

#[test]
fn modules_import_only_lower_layers() {
    let problems = violations();
    assert!(
        problems.is_empty(),
        "imports against docs/architecture.md's layers:\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_checker_sees_upward_and_sideways_imports() {
    let found: Vec<String> = referenced(
        "use crate::{\n    conf::Conf,\n    gui::{GuiHost, x},\n    output,\n};\n// crate::shell in a comment\nlet a = crate::drivers::simulator::World::new();\n$crate::registry::Entry\n",
    )
    .into_iter()
    .map(|(_, n)| n)
    .collect();
    assert_eq!(found, ["conf", "gui", "output", "drivers::simulator"]);
}

/// Where code outside the kinds module matches an interface kind by its name: a
/// string literal that is a kind's name in a match arm (`"laser" =>`, `"laser" |`),
/// a comparison (`== "laser"`, `"laser" !=`) or a pattern (`Some("laser")`). A kind
/// is an `interfaces::Kind`; its name is parsed once, at the edge.
fn kind_string_matches(files: &[(PathBuf, String)]) -> Vec<String> {
    let names = jderobot::interfaces::Kind::NAMES;
    let mut out = Vec::new();
    for (path, code) in files {
        if path.ends_with("src/interfaces/kinds.rs") {
            continue;
        }
        for (n, line) in code.lines().enumerate() {
            let code_part = line.split("//").next().unwrap_or("");
            for k in names {
                let lit = format!("\"{k}\"");
                let hit = [
                    format!("{lit} =>"),
                    format!("{lit} |"),
                    format!("| {lit}"),
                    format!("== {lit}"),
                    format!("!= {lit}"),
                    format!("{lit} =="),
                    format!("{lit} !="),
                    format!("Some({lit})"),
                ]
                .iter()
                .any(|p| code_part.contains(p.as_str()));
                if hit {
                    out.push(format!("{}:{}: {}", path.display(), n + 1, line.trim()));
                }
            }
        }
    }
    out
}

/// The code of every Rust file of the crate (its tests excepted).
fn crate_code() -> Vec<(PathBuf, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["src", "drivers", "services", "schemas"] {
        rust_files(&root.join(dir), &mut files);
    }
    files
        .into_iter()
        .map(|p| {
            let code = fs::read_to_string(&p).unwrap();
            (p, code)
        })
        .collect()
}

#[test]
fn no_kind_is_matched_as_a_string_outside_the_kinds_module() {
    let hits = kind_string_matches(&crate_code());
    assert!(
        hits.is_empty(),
        "match an interfaces::Kind, not its name (parse the name once, at the edge, with \
         Kind::parse):\n{}",
        hits.join("\n")
    );
}

#[test]
fn the_kind_check_sees_a_string_match() {
    let code = "match kind {\n    \"laser\" => 1,\n    _ if k == \"motors\" => 2,\n    // \"imu\" => in a comment\n}\n";
    let hits = kind_string_matches(&[(PathBuf::from("drivers/x/mod.rs"), code.to_string())]);
    assert_eq!(hits.len(), 2, "{hits:?}");
}
