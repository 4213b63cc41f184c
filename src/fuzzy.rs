//! fuzzy: JDE 4.3's fuzzylib — fuzzy controllers read from `.fzz` files.
//!
//! # The `.fzz` format
//! One construct per line; `#` starts a comment line; blank lines are skipped.
//! ```text
//! controlador fuzzy_controller
//! etiqueta fuzzyvar1 valuename1 = 8000 12000 16000 20000
//! etiqueta fuzzyvar3 valuename9 = 0 0 0 0
//! IF ( fuzzyvar1 = valuename1 ) AND ( fuzzyvar2 = valuename4 ) THEN ( fuzzyvar3 = valuename7 )
//! defuzzificacion mamdani      # optional, ours: see "Inference" (default: jde)
//! ```
//! - `etiqueta VAR LABEL = p0 p1 p2 p3` defines a trapezoid label (p0 ≤ p1 ≤ p2 ≤ p3,
//!   in the variable's own unit; equal points give vertical edges, four equal points
//!   a singleton). Variables are created on first mention; a label is defined once.
//! - `IF ( v = l ) [AND ( v = l )]* THEN ( v = l ) [AND ( v = l )]*`: labels must be
//!   defined above the rule. There is no OR and no NOT (as in 4.3). Spaces around the
//!   brackets and `=` are optional here (4.3 required them).
//!
//! [`Controller::parse`] stops at the first bad line with `file:line: what was
//! expected`; [`Controller::parse_lenient`] skips bad lines and returns warnings, as
//! 4.3 did (its own `test.fzz` has a duplicate label, out-of-order parameters and a
//! rule on undefined variables: `assets/fuzzy/test.fzz`).
//!
//! # Inference
//! - [`Inference::Jde`] (default, exactly 4.3.0): a rule fires with the *product* of
//!   its antecedent memberships `a`; its output is the centroid of its consequent
//!   trapezoid clipped at height `a`; the result is `Σ a·out / Σ a` over the rules
//!   with `a > 0`. The manual's example (var1 = 12000, var2 = 500) gives −25.0 from 2
//!   rules (the manual's "−35" is loose).
//! - [`Inference::Mamdani`] (line `defuzzificacion mamdani`, or
//!   [`Controller::set_inference`]): scikit-fuzzy's defaults — AND = *min*,
//!   implication = min (clip), aggregation = max, centroid of the aggregated set
//!   (computed exactly; piecewise linear). If every fired consequent is a singleton
//!   (zero area) the result is their strength-weighted mean.
//!
//! A variable without an input value that is the consequent of other rules is
//! inferred first (chained controllers, as 4.3's internal variables); an input that
//! was never set makes the rules that use it not fire.
//!
//! # API (4.3 equivalents)
//! `fc_open` → [`Controller::from_file`]; `fc_close` → drop; `fc_save` →
//! [`Controller::save`]; `fc_link` → [`Controller::set_input`] (bind by name each
//! cycle); `fc_output` → [`Controller::output`], which returns the value and the
//! number of rules applied, or `None` where 4.3 returned −1.

pub use crate::files::FileError as FuzzyError;
use std::{fmt::Write as _, path::Path};

/// How rules are combined; see the module doc.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Inference {
    #[default]
    Jde,
    Mamdani,
}

/// A trapezoid `p0 ≤ p1 ≤ p2 ≤ p3`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trapezoid(pub [f32; 4]);

impl Trapezoid {
    /// 4.3's membership: ramps open at the ends, 1 on [p1, p2], else 0.
    pub fn membership(&self, x: f32) -> f32 {
        trapezoid(self.0, x)
    }

    /// Centroid of the trapezoid clipped at height `a` (4.3's three-piece formula);
    /// the point itself for a singleton.
    pub fn clipped_centroid(&self, a: f32) -> f32 {
        let [p0, p1, p2, p3] = self.0;
        let m1 = (p1 - p0) * a * a / 2.0;
        let c1 = p0 + 2.0 * (p1 - p0) * a / 3.0;
        let w = (p3 - p0) - a * (p3 - p2) - a * (p1 - p0);
        let m2 = a * w;
        let c2 = p0 + a * (p1 - p0) + w / 2.0;
        let m3 = (p3 - p2) * a * a / 2.0;
        let c3 = p3 - 2.0 * a * (p3 - p2) / 3.0;
        let m = m1 + m2 + m3;
        if m > 0.0 {
            (m1 * c1 + m2 * c2 + m3 * c3) / m
        } else {
            (p0 + p3) / 2.0
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
struct Variable {
    name: String,
    /// (label, trapezoid) in definition order.
    labels: Vec<(String, Trapezoid)>,
}

/// `(variable index, label index)`.
type Term = (usize, usize);

#[derive(Clone, Debug, PartialEq)]
struct Rule {
    antecedents: Vec<Term>,
    consequents: Vec<Term>,
}

/// A bad line skipped by [`Controller::parse_lenient`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning {
    pub line: usize,
    pub message: String,
}

/// A fuzzy controller (4.3's controller id).
#[derive(Clone, Debug, PartialEq)]
pub struct Controller {
    pub name: String,
    variables: Vec<Variable>,
    rules: Vec<Rule>,
    inference: Inference,
    inputs: Vec<Option<f32>>,
}

fn tokens(line: &str) -> Vec<String> {
    let mut spaced = String::with_capacity(line.len() + 16);
    for ch in line.chars() {
        if matches!(ch, '(' | ')' | '=') {
            spaced.push(' ');
            spaced.push(ch);
            spaced.push(' ');
        } else {
            spaced.push(ch);
        }
    }
    spaced.split_whitespace().map(str::to_string).collect()
}

impl Controller {
    /// Reads a `.fzz` file, failing on its first bad line (4.3's `fc_open`).
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, FuzzyError> {
        let path = path.as_ref();
        Self::parse(&read(path)?, path)
    }

    /// Reads a `.fzz` file skipping bad lines, as 4.3 did; returns the warnings.
    pub fn from_file_lenient(path: impl AsRef<Path>) -> Result<(Self, Vec<Warning>), FuzzyError> {
        let path = path.as_ref();
        Self::parse_lenient(&read(path)?, path)
    }

    /// Parses `.fzz` text (`file` names it in errors), failing on the first bad line.
    pub fn parse(text: &str, file: &Path) -> Result<Self, FuzzyError> {
        let mut c = Self::empty();
        for (n, line) in text.lines().enumerate() {
            c.parse_line(line).map_err(|message| FuzzyError::Syntax {
                file: file.to_path_buf(),
                line: n + 1,
                message,
            })?;
        }
        c.finish(file)
    }

    /// Parses `.fzz` text skipping bad lines; each skipped line is a [`Warning`] (also
    /// logged with `tracing::warn!`).
    pub fn parse_lenient(text: &str, file: &Path) -> Result<(Self, Vec<Warning>), FuzzyError> {
        let mut c = Self::empty();
        let mut warnings = Vec::new();
        for (n, line) in text.lines().enumerate() {
            if let Err(message) = c.parse_line(line) {
                tracing::warn!("{}:{}: {message}; line ignored", file.display(), n + 1);
                warnings.push(Warning {
                    line: n + 1,
                    message,
                });
            }
        }
        Ok((c.finish(file)?, warnings))
    }

    fn empty() -> Self {
        Controller {
            name: String::new(),
            variables: Vec::new(),
            rules: Vec::new(),
            inference: Inference::Jde,
            inputs: Vec::new(),
        }
    }

    fn finish(mut self, file: &Path) -> Result<Self, FuzzyError> {
        if self.variables.is_empty() || self.rules.is_empty() {
            return Err(FuzzyError::Invalid {
                file: file.to_path_buf(),
                message: format!(
                    "a controller needs labels (`etiqueta ...`) and rules (`IF ... THEN ...`); found {} variables and {} rules",
                    self.variables.len(),
                    self.rules.len()
                ),
            });
        }
        self.inputs = vec![None; self.variables.len()];
        Ok(self)
    }

    fn parse_line(&mut self, line: &str) -> Result<(), String> {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            return Ok(());
        }
        let t = tokens(line);
        match t[0].as_str() {
            "controlador" => {
                let [_, name] = &t[..] else {
                    return Err("expected `controlador NAME`".into());
                };
                self.name = name.clone();
                Ok(())
            }
            "defuzzificacion" | "defuzzification" => {
                match t.get(1).map(|s| s.to_ascii_lowercase()).as_deref() {
                    Some("jde") if t.len() == 2 => self.inference = Inference::Jde,
                    Some("mamdani") if t.len() == 2 => self.inference = Inference::Mamdani,
                    _ => {
                        return Err(
                            "expected `defuzzificacion jde` or `defuzzificacion mamdani`".into(),
                        );
                    }
                }
                Ok(())
            }
            "etiqueta" => self.parse_label(&t),
            "IF" | "if" => self.parse_rule(&t),
            other => Err(format!(
                "unknown line start `{other}`: expected `controlador`, `etiqueta`, `IF`, `defuzzificacion` or a `#` comment"
            )),
        }
    }

    fn parse_label(&mut self, t: &[String]) -> Result<(), String> {
        const EXPECTED: &str = "expected `etiqueta VARIABLE LABEL = p0 p1 p2 p3`";
        if t.len() != 8 || t[3] != "=" {
            return Err(EXPECTED.into());
        }
        let mut p = [0f32; 4];
        for (i, s) in t[4..8].iter().enumerate() {
            p[i] = s
                .parse::<f32>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{s}` is not a number; {EXPECTED}"))?;
        }
        if !(p[0] <= p[1] && p[1] <= p[2] && p[2] <= p[3]) {
            return Err(format!(
                "label {} {} has parameters out of order ({} {} {} {}); they must satisfy p0 <= p1 <= p2 <= p3",
                t[1], t[2], p[0], p[1], p[2], p[3]
            ));
        }
        let (var, label) = (&t[1], &t[2]);
        let vi = match self.variables.iter().position(|v| &v.name == var) {
            Some(i) => i,
            None => {
                self.variables.push(Variable {
                    name: var.clone(),
                    labels: Vec::new(),
                });
                self.variables.len() - 1
            }
        };
        let v = &mut self.variables[vi];
        if v.labels.iter().any(|(l, _)| l == label) {
            return Err(format!(
                "label {var} {label} is defined twice; keeping the first definition"
            ));
        }
        v.labels.push((label.clone(), Trapezoid(p)));
        Ok(())
    }

    fn term(&self, var: &str, label: &str) -> Result<Term, String> {
        let vi = self
            .variables
            .iter()
            .position(|v| v.name == var)
            .ok_or_else(|| format!("variable `{var}` has no labels defined above this rule"))?;
        let li = self.variables[vi]
            .labels
            .iter()
            .position(|(l, _)| l == label)
            .ok_or_else(|| {
                format!("label `{label}` of variable `{var}` is not defined above this rule")
            })?;
        Ok((vi, li))
    }

    fn parse_rule(&mut self, t: &[String]) -> Result<(), String> {
        const EXPECTED: &str = "expected `IF ( var = label ) [AND ( var = label )]* THEN ( var = label ) [AND ( var = label )]*`";
        let mut i = 1;
        let mut ante = Vec::new();
        let mut cons = Vec::new();
        let mut then = false;
        loop {
            let w = t.get(i..i + 5).ok_or_else(|| EXPECTED.to_string())?;
            if w[0] != "(" || w[2] != "=" || w[4] != ")" {
                return Err(EXPECTED.into());
            }
            let term = self.term(&w[1], &w[3])?;
            if then { &mut cons } else { &mut ante }.push(term);
            i += 5;
            match t.get(i).map(String::as_str) {
                None if then => break,
                Some("AND" | "and") => i += 1,
                Some("THEN" | "then") if !then => {
                    then = true;
                    i += 1
                }
                Some("OR" | "or") => return Err("OR is not supported (only AND)".into()),
                _ => return Err(EXPECTED.into()),
            }
        }
        self.rules.push(Rule {
            antecedents: ante,
            consequents: cons,
        });
        Ok(())
    }

    /// Which inference the controller uses.
    pub fn inference(&self) -> Inference {
        self.inference
    }

    pub fn set_inference(&mut self, inference: Inference) {
        self.inference = inference;
    }

    /// Variable names in definition order.
    pub fn variables(&self) -> impl Iterator<Item = &str> {
        self.variables.iter().map(|v| v.name.as_str())
    }

    /// Number of rules.
    pub fn rule_count(&self) -> usize {
        self.rules.len()
    }

    /// The label `(variable, label)`'s trapezoid.
    pub fn label(&self, var: &str, label: &str) -> Option<Trapezoid> {
        let (v, l) = self.term(var, label).ok()?;
        Some(self.variables[v].labels[l].1)
    }

    /// Sets an input's crisp value (4.3's `fc_link` + assignment). Returns false when
    /// the controller has no such variable.
    pub fn set_input(&mut self, var: &str, value: f32) -> bool {
        match self.variables.iter().position(|v| v.name == var) {
            Some(i) => {
                self.inputs[i] = Some(value);
                true
            }
            None => false,
        }
    }

    /// Makes a variable internal again (no input value: inferred if it is some rule's
    /// consequent).
    pub fn clear_input(&mut self, var: &str) {
        if let Some(i) = self.variables.iter().position(|v| v.name == var) {
            self.inputs[i] = None;
        }
    }

    /// The crisp value of `var` and the number of rules applied (4.3's `fc_output`);
    /// `None` when no rule concludes on `var` or none of them fires.
    pub fn output(&self, var: &str) -> Option<(f32, usize)> {
        let vi = self.variables.iter().position(|v| v.name == var)?;
        let mut cache: Vec<Option<Option<f32>>> = vec![None; self.variables.len()];
        let mut visiting = vec![false; self.variables.len()];
        self.infer(vi, &mut cache, &mut visiting)
    }

    fn value_of(
        &self,
        vi: usize,
        cache: &mut Vec<Option<Option<f32>>>,
        visiting: &mut Vec<bool>,
    ) -> Option<f32> {
        if let Some(v) = self.inputs[vi] {
            return Some(v);
        }
        if let Some(v) = cache[vi] {
            return v;
        }
        if visiting[vi] {
            return None;
        }
        let v = self.infer(vi, cache, visiting).map(|(v, _)| v);
        cache[vi] = Some(v);
        v
    }

    fn infer(
        &self,
        vi: usize,
        cache: &mut Vec<Option<Option<f32>>>,
        visiting: &mut Vec<bool>,
    ) -> Option<(f32, usize)> {
        visiting[vi] = true;
        // (strength, consequent label) of every fired rule on vi.
        let mut fired: Vec<(f32, Trapezoid)> = Vec::new();
        for rule in &self.rules {
            let Some(&(_, li)) = rule.consequents.iter().find(|(v, _)| *v == vi) else {
                continue;
            };
            let mut a = 1.0f32;
            for &(av, al) in &rule.antecedents {
                let mu = match self.value_of(av, cache, visiting) {
                    Some(x) => self.variables[av].labels[al].1.membership(x),
                    None => 0.0,
                };
                a = match self.inference {
                    Inference::Jde => a * mu,
                    Inference::Mamdani => a.min(mu),
                };
            }
            if a > 0.0 {
                fired.push((a, self.variables[vi].labels[li].1));
            }
        }
        visiting[vi] = false;
        if fired.is_empty() {
            return None;
        }
        let value = match self.inference {
            Inference::Jde => {
                let (num, den) = fired.iter().fold((0.0f32, 0.0f32), |(n, d), (a, t)| {
                    (n + a * t.clipped_centroid(*a), d + a)
                });
                num / den
            }
            Inference::Mamdani => mamdani_centroid(&fired),
        };
        Some((value, fired.len()))
    }

    /// The normalised `.fzz` text; it parses back to an equal controller.
    pub fn to_fzz_string(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "# fuzzy controller written by jderobot");
        let _ = writeln!(s, "controlador {}", self.name);
        if self.inference == Inference::Mamdani {
            let _ = writeln!(s, "defuzzificacion mamdani");
        }
        for v in &self.variables {
            let _ = writeln!(s);
            for (l, t) in &v.labels {
                let [a, b, c, d] = t.0;
                let _ = writeln!(s, "etiqueta {} {} = {a:?} {b:?} {c:?} {d:?}", v.name, l);
            }
        }
        let _ = writeln!(s);
        let term = |&(v, l): &Term| {
            format!(
                "( {} = {} )",
                self.variables[v].name, self.variables[v].labels[l].0
            )
        };
        for r in &self.rules {
            let a: Vec<String> = r.antecedents.iter().map(term).collect();
            let c: Vec<String> = r.consequents.iter().map(term).collect();
            let _ = writeln!(s, "IF {} THEN {}", a.join(" AND "), c.join(" AND "));
        }
        s
    }

    /// Writes the controller as a `.fzz` file (4.3's `fc_save`).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), FuzzyError> {
        let path = path.as_ref();
        std::fs::write(path, self.to_fzz_string()).map_err(|source| FuzzyError::Io {
            file: path.to_path_buf(),
            source,
        })
    }
}

fn read(path: &Path) -> Result<String, FuzzyError> {
    FuzzyError::read(path)
}

/// The clipped trapezoid `min(a, t(x))` as linear on [x0, x1] between breakpoints.
fn clipped(a: f32, t: &Trapezoid, x: f64) -> f64 {
    (t.membership_f64(x)).min(a as f64)
}

impl Trapezoid {
    /// [`Trapezoid::membership`] in f64, for the exact Mamdani centroid.
    fn membership_f64(&self, x: f64) -> f64 {
        trapezoid(self.0.map(f64::from), x)
    }
}

/// The trapezoid `p`'s membership at `x`, in the precision of `T` (f32 as 4.3
/// computed it, f64 for Mamdani).
fn trapezoid<T>(p: [T; 4], x: T) -> T
where
    T: Copy + PartialOrd + From<u8> + std::ops::Sub<Output = T> + std::ops::Div<Output = T>,
{
    let [p0, p1, p2, p3] = p;
    if p0 < x && x < p1 {
        (x - p0) / (p1 - p0)
    } else if p2 < x && x < p3 {
        (p3 - x) / (p3 - p2)
    } else if p1 <= x && x <= p2 {
        T::from(1)
    } else {
        T::from(0)
    }
}

/// Exact centroid of `max_r min(a_r, t_r(x))`.
fn mamdani_centroid(fired: &[(f32, Trapezoid)]) -> f32 {
    // Breakpoints: vertices and clip crossings of each term.
    let mut xs: Vec<f64> = Vec::new();
    for (a, t) in fired {
        let [p0, p1, p2, p3] = t.0.map(f64::from);
        let a = *a as f64;
        xs.extend([p0, p1, p2, p3, p0 + a * (p1 - p0), p3 - a * (p3 - p2)]);
    }
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    // Between breakpoints each clipped term is linear (on the open interval); the max
    // of linear functions is linear between their pairwise crossings.
    let (mut area, mut moment) = (0.0f64, 0.0f64);
    for w in xs.windows(2) {
        let (x0, x1) = (w[0], w[1]);
        if x1 <= x0 {
            continue;
        }
        let eps = (x1 - x0) * 1e-9;
        // Each term's line on the interval, evaluated just inside the ends.
        let lines: Vec<(f64, f64)> = fired
            .iter()
            .map(|(a, t)| {
                let (ya, yb) = (clipped(*a, t, x0 + eps), clipped(*a, t, x1 - eps));
                let slope = (yb - ya) / ((x1 - eps) - (x0 + eps));
                (ya - slope * (x0 + eps), slope) // intercept, slope
            })
            .collect();
        let mut cuts = vec![x0, x1];
        for i in 0..lines.len() {
            for j in i + 1..lines.len() {
                let ds = lines[i].1 - lines[j].1;
                if ds != 0.0 {
                    let xc = (lines[j].0 - lines[i].0) / ds;
                    if xc > x0 && xc < x1 {
                        cuts.push(xc);
                    }
                }
            }
        }
        cuts.sort_by(f64::total_cmp);
        let g = |x: f64| {
            lines
                .iter()
                .map(|(b, s)| b + s * x)
                .fold(0.0f64, f64::max)
                .max(0.0)
        };
        for c in cuts.windows(2) {
            let (u0, u1) = (c[0], c[1]);
            let (f0, f1) = (g(u0), g(u1));
            let dx = u1 - u0;
            area += (f0 + f1) * dx / 2.0;
            moment += dx / 6.0 * (f0 * (2.0 * u0 + u1) + f1 * (u0 + 2.0 * u1));
        }
    }
    if area > 0.0 {
        (moment / area) as f32
    } else {
        // Only singletons fired: their strength-weighted mean.
        let (n, d) = fired.iter().fold((0.0f64, 0.0f64), |(n, d), (a, t)| {
            (n + *a as f64 * t.0[0] as f64, d + *a as f64)
        });
        (n / d) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clipped_centroid_full_height_is_midpoint_of_symmetric() {
        let t = Trapezoid([-40.0, -35.0, -30.0, -25.0]);
        assert!((t.clipped_centroid(1.0) + 32.5).abs() < 1e-5);
    }
}
