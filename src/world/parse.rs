//! The world file format (see the [module doc](super)): one statement per line,
//! `#` comments, errors as `file:line: what was wrong and what would be right`.

use std::path::Path;

use super::{BallSpec, BoxObstacle, Paint, Rgb, StartPose, World, WorldError};

/// Named colours accepted in world files.
pub const COLOR_NAMES: &[(&str, Rgb)] = &[
    ("red", [220, 20, 20]),
    ("green", [20, 170, 40]),
    ("blue", [30, 60, 220]),
    ("yellow", [240, 220, 20]),
    ("orange", [255, 130, 0]),
    ("cyan", [0, 200, 220]),
    ("magenta", [210, 0, 210]),
    ("pink", [255, 150, 180]),
    ("brown", [130, 80, 30]),
    ("white", [245, 245, 245]),
    ("grey", [128, 128, 128]),
    ("gray", [128, 128, 128]),
    ("lightgrey", [200, 200, 200]),
    ("darkgrey", [70, 70, 70]),
    ("black", [15, 15, 15]),
    ("wood", [180, 140, 90]),
    ("sky", [170, 200, 235]),
    ("beige", [225, 215, 185]),
];

/// Parses a colour word: a name from [`COLOR_NAMES`] or `R,G,B` (0-255 each).
pub fn parse_color(word: &str) -> Result<Rgb, String> {
    if let Some((_, c)) = COLOR_NAMES
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(word))
    {
        return Ok(*c);
    }
    let parts: Vec<&str> = word.split(',').collect();
    if parts.len() == 3 {
        let mut c = [0u8; 3];
        for (k, p) in parts.iter().enumerate() {
            c[k] = p
                .parse()
                .map_err(|_| format!("colour `{word}`: `{p}` is not a number 0-255"))?;
        }
        return Ok(c);
    }
    let names: Vec<&str> = COLOR_NAMES.iter().map(|(n, _)| *n).collect();
    Err(format!(
        "`{word}` is not a colour; expected R,G,B (e.g. 255,0,0) or one of {}",
        names.join(", ")
    ))
}

impl World {
    /// Reads a world file.
    pub fn load(file: &Path) -> Result<World, WorldError> {
        let text = crate::files::FileError::read(file).map_err(|e| WorldError {
            file: file.to_path_buf(),
            line: 0,
            message: format!("cannot read world file: {}", e.reason()),
        })?;
        World::parse(&text, file)
    }

    /// Parses world file text; `file` names it in errors and anchors relative paths.
    pub fn parse(text: &str, file: &Path) -> Result<World, WorldError> {
        let mut w = World::new();
        let mut pen = WallPen::default();
        // The line of the `paint` whose `point`s are being read.
        let mut painting: Option<usize> = None;
        for (n, raw) in text.lines().enumerate() {
            let content = raw.split('#').next().unwrap_or("");
            let words: Vec<&str> = content.split_whitespace().collect();
            let Some((&key, args)) = words.split_first() else {
                continue;
            };
            let st = Statement {
                file,
                line: n + 1,
                key,
                args,
            };
            if key != "point"
                && let Some(at) = painting.take()
            {
                painted(&w, file, at)?;
            }
            if key == "paint" || key == "point" {
                st.paint(&mut w, &mut painting)?;
            } else if !(st.looks(&mut w, &mut pen)?
                || st.walls(&mut w, &pen)?
                || st.things(&mut w)?)
            {
                return Err(st.err(format!(
                    "unknown keyword `{key}`; expected one of wall, room, floorplan, box, ball, start, \
                     target, paint, point, wall_height, wall_color, floor_color, sky_color, floor_tile"
                )));
            }
        }
        if let Some(at) = painting {
            painted(&w, file, at)?;
        }
        w.finish();
        Ok(w)
    }
}

/// Checks that the last `paint` (at line `at`) got enough `point`s.
fn painted(w: &World, file: &Path, at: usize) -> Result<(), WorldError> {
    let Some(p) = w.paint.last() else {
        return Ok(());
    };
    let need = if p.closed { 3 } else { 2 };
    if p.points.len() >= need {
        return Ok(());
    }
    Err(WorldError {
        file: file.to_path_buf(),
        line: at,
        message: format!(
            "`paint` has {} point(s); a{} painted line needs at least {need} `point X Y` lines right after it",
            p.points.len(),
            if p.closed { " closed" } else { "n open" }
        ),
    })
}

/// The height and colour of the walls that follow (`wall_height`, `wall_color`).
struct WallPen {
    height: f64,
    color: Rgb,
}

impl Default for WallPen {
    fn default() -> Self {
        WallPen {
            height: 1000.0,
            color: [225, 215, 185],
        }
    }
}

/// One statement of a world file: its keyword and arguments, where it stands.
struct Statement<'a> {
    file: &'a Path,
    line: usize,
    key: &'a str,
    args: &'a [&'a str],
}

impl Statement<'_> {
    fn err(&self, message: String) -> WorldError {
        WorldError {
            file: self.file.to_path_buf(),
            line: self.line,
            message,
        }
    }

    /// Argument `i` (from 0) as a finite number; `what` says what it should be.
    fn num(&self, i: usize, what: &str) -> Result<f64, WorldError> {
        let key = self.key;
        let word = self
            .args
            .get(i)
            .ok_or_else(|| self.err(format!("`{key}` needs {what} as argument {}", i + 1)))?;
        word.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                self.err(format!(
                    "`{key}`: argument {} is `{word}`, expected {what}",
                    i + 1
                ))
            })
    }

    /// Whether there are `min` to `max` arguments (`usage` shows the statement).
    fn count(&self, min: usize, max: usize, usage: &str) -> Result<(), WorldError> {
        let n = self.args.len();
        if n < min || n > max {
            let takes = if min == max {
                min.to_string()
            } else {
                format!("{min} to {max}")
            };
            return Err(self.err(format!(
                "`{}` takes {takes} arguments, got {n}; usage: {usage}",
                self.key
            )));
        }
        Ok(())
    }

    /// Argument `i` as a colour ([`parse_color`]).
    fn color(&self, i: usize) -> Result<Rgb, WorldError> {
        parse_color(self.args.get(i).copied().unwrap_or("")).map_err(|e| self.err(e))
    }

    /// `v` if it is > 0 (`what` names it in the error).
    fn positive(&self, v: f64, what: &str) -> Result<f64, WorldError> {
        if v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(format!("`{}`: {what} must be > 0, got {v}", self.key)))
        }
    }

    /// The looks: wall height and colour, floor, sky, tiles. False: not one of
    /// these.
    fn looks(&self, w: &mut World, pen: &mut WallPen) -> Result<bool, WorldError> {
        match self.key {
            "wall_height" => {
                self.count(1, 1, "wall_height MM")?;
                pen.height = self.positive(self.num(0, "a height in mm")?, "the height")?;
            }
            "wall_color" => {
                self.count(1, 1, "wall_color COLOR")?;
                pen.color = self.color(0)?;
            }
            "floor_color" => {
                self.count(1, 1, "floor_color COLOR")?;
                w.floor_color = self.color(0)?;
            }
            "sky_color" => {
                self.count(1, 1, "sky_color COLOR")?;
                w.sky_color = self.color(0)?;
            }
            "floor_tile" => {
                self.count(1, 1, "floor_tile MM (0 = plain floor)")?;
                let t = self.num(0, "a tile size in mm")?;
                if t < 0.0 {
                    return Err(self.err(format!("`floor_tile` must be >= 0, got {t}")));
                }
                w.tile = t;
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// The walls: `wall`, `room`, `floorplan`, drawn with `pen`. False: not one of
    /// these.
    fn walls(&self, w: &mut World, pen: &WallPen) -> Result<bool, WorldError> {
        match self.key {
            "wall" => {
                self.count(4, 4, "wall X1 Y1 X2 Y2")?;
                let a = [self.num(0, "X1 in mm")?, self.num(1, "Y1 in mm")?];
                let b = [self.num(2, "X2 in mm")?, self.num(3, "Y2 in mm")?];
                if a == b {
                    return Err(self.err("`wall`: both ends are the same point".into()));
                }
                w.add_wall(a, b, pen.height, pen.color);
            }
            "room" => {
                self.count(4, 4, "room X1 Y1 X2 Y2")?;
                let (x1, y1) = (self.num(0, "X1 in mm")?, self.num(1, "Y1 in mm")?);
                let (x2, y2) = (self.num(2, "X2 in mm")?, self.num(3, "Y2 in mm")?);
                if x1 == x2 || y1 == y2 {
                    return Err(self.err("`room`: the rectangle has no area".into()));
                }
                let (lo, hi) = ([x1.min(x2), y1.min(y2)], [x1.max(x2), y1.max(y2)]);
                w.add_room(lo, hi, pen.height, pen.color);
            }
            "floorplan" => self.floorplan(w, pen)?,
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// `floorplan FILE.png PIXEL_MM [X0 Y0]` (FILE relative to the world file).
    fn floorplan(&self, w: &mut World, pen: &WallPen) -> Result<(), WorldError> {
        let args = self.args;
        if args.len() != 2 && args.len() != 4 {
            return Err(self.err(format!(
                "`floorplan` takes 2 or 4 arguments, got {}; usage: floorplan FILE.png PIXEL_MM [X0 Y0]",
                args.len()
            )));
        }
        let pixel = self.positive(self.num(1, "the pixel size in mm")?, "the pixel size")?;
        let origin = if args.len() == 4 {
            [self.num(2, "X0 in mm")?, self.num(3, "Y0 in mm")?]
        } else {
            [0.0, 0.0]
        };
        let path = Path::new(args[0]);
        let path = if path.is_absolute() {
            path.to_path_buf()
        } else {
            (self.file.parent())
                .map(|d| d.join(path))
                .unwrap_or_else(|| path.to_path_buf())
        };
        w.add_floorplan(&path, pixel, origin, pen.height, pen.color)
            .map_err(|e| self.err(format!("floorplan {}: {e}", path.display())))
    }

    /// `paint WIDTH COLOR [closed]` starts a painted line (`painting` becomes its
    /// line); `point X Y` adds a vertex to it.
    fn paint(&self, w: &mut World, painting: &mut Option<usize>) -> Result<(), WorldError> {
        if self.key == "point" {
            self.count(2, 2, "point X Y (after a `paint` line)")?;
            let p = [self.num(0, "X in mm")?, self.num(1, "Y in mm")?];
            let line = match (painting.is_some(), w.paint.last_mut()) {
                (true, Some(line)) => line,
                _ => {
                    return Err(self.err(
                        "`point` adds to a painted line: put it right after a `paint WIDTH COLOR [closed]` \
                         line or another `point`"
                            .into(),
                    ));
                }
            };
            if line.points.last() == Some(&p) {
                return Err(self.err(format!(
                    "`point {} {}` repeats the point before it; each point must move on",
                    p[0], p[1]
                )));
            }
            line.points.push(p);
            return Ok(());
        }
        self.count(2, 3, "paint WIDTH COLOR [closed]")?;
        let closed = match self.args.get(2) {
            None => false,
            Some(&"closed") => true,
            Some(other) => {
                return Err(self.err(format!(
                    "`paint`: argument 3 is `{other}`, expected `closed` (or nothing: an open line)"
                )));
            }
        };
        w.paint.push(Paint {
            points: Vec::new(),
            closed,
            width: self.positive(self.num(0, "WIDTH in mm")?, "WIDTH")?,
            color: self.color(1)?,
        });
        *painting = Some(self.line);
        Ok(())
    }

    /// The things in the world: `box`, `ball`, `target`, `start`. False: not one of these.
    fn things(&self, w: &mut World) -> Result<bool, WorldError> {
        let args = self.args;
        match self.key {
            "box" => {
                self.count(6, 7, "box X Y SIZE_X SIZE_Y HEIGHT COLOR [THETA_DEG]")?;
                let b = BoxObstacle {
                    center: [self.num(0, "X in mm")?, self.num(1, "Y in mm")?],
                    size: [
                        self.positive(self.num(2, "SIZE_X in mm")?, "SIZE_X")?,
                        self.positive(self.num(3, "SIZE_Y in mm")?, "SIZE_Y")?,
                    ],
                    height: self.positive(self.num(4, "HEIGHT in mm")?, "HEIGHT")?,
                    color: self.color(5)?,
                    theta: if args.len() > 6 {
                        self.num(6, "THETA in degrees")?.to_radians()
                    } else {
                        0.0
                    },
                };
                w.add_box(b);
            }
            "ball" => {
                self.count(4, 5, "ball X Y RADIUS COLOR [FRICTION_MM_S2]")?;
                let friction = if args.len() > 4 {
                    self.num(4, "a rolling deceleration in mm/s²")?
                } else {
                    300.0
                };
                if friction < 0.0 {
                    return Err(self.err(format!("`ball`: friction must be >= 0, got {friction}")));
                }
                w.add_ball(BallSpec {
                    pos: [self.num(0, "X in mm")?, self.num(1, "Y in mm")?],
                    radius: self.positive(self.num(2, "RADIUS in mm")?, "RADIUS")?,
                    color: self.color(3)?,
                    friction,
                });
            }
            "target" => {
                self.count(2, 2, "target X Y")?;
                let t = [self.num(0, "X in mm")?, self.num(1, "Y in mm")?];
                w.targets.push(t);
            }
            "start" => {
                self.count(3, 3, "start X Y THETA_DEG")?;
                w.starts.push(StartPose {
                    x: self.num(0, "X in mm")?,
                    y: self.num(1, "Y in mm")?,
                    theta: self.num(2, "THETA in degrees")?,
                });
            }
            _ => return Ok(false),
        }
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_errors_name_the_line() {
        let e = World::parse("# c\nwall 0 0 1000\n", Path::new("x.world")).unwrap_err();
        assert_eq!(e.line, 2);
        assert!(e.to_string().starts_with("x.world:2:"), "{e}");
        let e = World::parse("ball 0 0 100 mauve\n", Path::new("x.world")).unwrap_err();
        assert!(e.message.contains("not a colour"), "{e}");
        let e = World::parse("tree 1 2\n", Path::new("x.world")).unwrap_err();
        assert!(e.message.contains("unknown keyword"), "{e}");
    }

    #[test]
    fn paint_and_targets_parse_in_order() {
        let text = "paint 40 red closed # a loop\npoint 0 0\n\npoint 1000 0\npoint 1000 1000\n\
                    paint 30 0,0,255\npoint 5 5\npoint 6 6\ntarget 1 2\ntarget 3 4\n";
        let w = World::parse(text, Path::new("x.world")).unwrap();
        assert_eq!(w.paint.len(), 2);
        let (a, b) = (&w.paint[0], &w.paint[1]);
        assert!(a.closed && !b.closed);
        assert_eq!((a.width, a.color, a.points.len()), (40.0, [220, 20, 20], 3));
        assert_eq!((b.width, b.color, b.points.len()), (30.0, [0, 0, 255], 2));
        assert_eq!(a.segments().count(), 3, "closed: back to the first point");
        assert_eq!(b.segments().count(), 1);
        assert!((a.length() - (2000.0 + 2f64.sqrt() * 1000.0)).abs() < 1e-9);
        assert!((a.distance([500.0, 100.0]) - 100.0).abs() < 1e-9);
        assert_eq!(w.targets, vec![[1.0, 2.0], [3.0, 4.0]]);
        assert!(w.segments.is_empty(), "paint is no obstacle");
    }

    #[test]
    fn bad_paint_and_targets_say_what_is_right() {
        let cases = [
            ("point 1 2\n", 1, "right after a `paint"),
            (
                "paint 40 red\npoint 0 0\nwall 0 0 1 1\n",
                1,
                "at least 2 `point X Y`",
            ),
            (
                "paint 40 red closed\npoint 0 0\npoint 1 0\n",
                1,
                "closed painted line needs at least 3",
            ),
            (
                "paint 40 red\npoint 0 0\nwall 0 0 1 1\npoint 1 1\n",
                1,
                "at least 2",
            ),
            ("paint 0 red\n", 1, "WIDTH must be > 0"),
            ("paint 40 red loop\n", 1, "expected `closed`"),
            ("paint 40\n", 1, "usage: paint WIDTH COLOR [closed]"),
            (
                "paint 40 red\npoint 0 0\npoint 0 0\n",
                3,
                "repeats the point",
            ),
            ("paint 40 red\npoint 0 x\n", 2, "expected Y in mm"),
            ("target 1\n", 1, "usage: target X Y"),
            ("target 1 inf\n", 1, "expected Y in mm"),
        ];
        for (text, line, says) in cases {
            let e = World::parse(text, Path::new("x.world")).unwrap_err();
            assert_eq!(e.line, line, "{text:?}: {e}");
            assert!(e.to_string().contains(says), "{text:?}: {e}");
        }
    }
}
