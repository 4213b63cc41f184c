//! The world file format (see the [module doc](super)): one statement per line,
//! `#` comments, errors as `file:line: what was wrong and what would be right`.

use std::path::Path;

use super::{BallSpec, BoxObstacle, Rgb, StartPose, World, WorldError};

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
        let mut wall_height = 1000.0;
        let mut wall_color: Rgb = [225, 215, 185];
        for (n, raw) in text.lines().enumerate() {
            let content = raw.split('#').next().unwrap_or("");
            let words: Vec<&str> = content.split_whitespace().collect();
            let Some(&key) = words.first() else { continue };
            let err = |message: String| WorldError {
                file: file.to_path_buf(),
                line: n + 1,
                message,
            };
            let args = &words[1..];
            let num = |i: usize, what: &str| -> Result<f64, WorldError> {
                let word = args
                    .get(i)
                    .ok_or_else(|| err(format!("`{key}` needs {what} as argument {}", i + 1)))?;
                word.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        err(format!(
                            "`{key}`: argument {} is `{word}`, expected {what}",
                            i + 1
                        ))
                    })
            };
            let count = |min: usize, max: usize, usage: &str| -> Result<(), WorldError> {
                if args.len() < min || args.len() > max {
                    return Err(err(format!(
                        "`{key}` takes {} arguments, got {}; usage: {usage}",
                        if min == max {
                            min.to_string()
                        } else {
                            format!("{min} to {max}")
                        },
                        args.len()
                    )));
                }
                Ok(())
            };
            let color = |i: usize| parse_color(args.get(i).copied().unwrap_or("")).map_err(&err);
            let positive = |v: f64, what: &str| -> Result<f64, WorldError> {
                if v > 0.0 {
                    Ok(v)
                } else {
                    Err(err(format!("`{key}`: {what} must be > 0, got {v}")))
                }
            };
            match key {
                "wall_height" => {
                    count(1, 1, "wall_height MM")?;
                    wall_height = positive(num(0, "a height in mm")?, "the height")?;
                }
                "wall_color" => {
                    count(1, 1, "wall_color COLOR")?;
                    wall_color = color(0)?;
                }
                "floor_color" => {
                    count(1, 1, "floor_color COLOR")?;
                    w.floor_color = color(0)?;
                }
                "sky_color" => {
                    count(1, 1, "sky_color COLOR")?;
                    w.sky_color = color(0)?;
                }
                "floor_tile" => {
                    count(1, 1, "floor_tile MM (0 = plain floor)")?;
                    let t = num(0, "a tile size in mm")?;
                    if t < 0.0 {
                        return Err(err(format!("`floor_tile` must be >= 0, got {t}")));
                    }
                    w.tile = t;
                }
                "wall" => {
                    count(4, 4, "wall X1 Y1 X2 Y2")?;
                    let a = [num(0, "X1 in mm")?, num(1, "Y1 in mm")?];
                    let b = [num(2, "X2 in mm")?, num(3, "Y2 in mm")?];
                    if a == b {
                        return Err(err("`wall`: both ends are the same point".into()));
                    }
                    w.add_wall(a, b, wall_height, wall_color);
                }
                "room" => {
                    count(4, 4, "room X1 Y1 X2 Y2")?;
                    let (x1, y1, x2, y2) = (
                        num(0, "X1 in mm")?,
                        num(1, "Y1 in mm")?,
                        num(2, "X2 in mm")?,
                        num(3, "Y2 in mm")?,
                    );
                    if x1 == x2 || y1 == y2 {
                        return Err(err("`room`: the rectangle has no area".into()));
                    }
                    w.add_room(
                        [x1.min(x2), y1.min(y2)],
                        [x1.max(x2), y1.max(y2)],
                        wall_height,
                        wall_color,
                    );
                }
                "floorplan" => {
                    if args.len() != 2 && args.len() != 4 {
                        return Err(err(format!(
                            "`floorplan` takes 2 or 4 arguments, got {}; usage: floorplan FILE.png PIXEL_MM [X0 Y0]",
                            args.len()
                        )));
                    }
                    let pixel = positive(num(1, "the pixel size in mm")?, "the pixel size")?;
                    let origin = if args.len() == 4 {
                        [num(2, "X0 in mm")?, num(3, "Y0 in mm")?]
                    } else {
                        [0.0, 0.0]
                    };
                    let path = Path::new(args[0]);
                    let path = if path.is_absolute() {
                        path.to_path_buf()
                    } else {
                        file.parent()
                            .map(|d| d.join(path))
                            .unwrap_or_else(|| path.to_path_buf())
                    };
                    w.add_floorplan(&path, pixel, origin, wall_height, wall_color)
                        .map_err(|e| err(format!("floorplan {}: {e}", path.display())))?;
                }
                "box" => {
                    count(6, 7, "box X Y SIZE_X SIZE_Y HEIGHT COLOR [THETA_DEG]")?;
                    let b = BoxObstacle {
                        center: [num(0, "X in mm")?, num(1, "Y in mm")?],
                        size: [
                            positive(num(2, "SIZE_X in mm")?, "SIZE_X")?,
                            positive(num(3, "SIZE_Y in mm")?, "SIZE_Y")?,
                        ],
                        height: positive(num(4, "HEIGHT in mm")?, "HEIGHT")?,
                        color: color(5)?,
                        theta: if args.len() > 6 {
                            num(6, "THETA in degrees")?.to_radians()
                        } else {
                            0.0
                        },
                    };
                    w.add_box(b);
                }
                "ball" => {
                    count(4, 5, "ball X Y RADIUS COLOR [FRICTION_MM_S2]")?;
                    let friction = if args.len() > 4 {
                        num(4, "a rolling deceleration in mm/s²")?
                    } else {
                        300.0
                    };
                    if friction < 0.0 {
                        return Err(err(format!(
                            "`ball`: friction must be >= 0, got {friction}"
                        )));
                    }
                    w.add_ball(BallSpec {
                        pos: [num(0, "X in mm")?, num(1, "Y in mm")?],
                        radius: positive(num(2, "RADIUS in mm")?, "RADIUS")?,
                        color: color(3)?,
                        friction,
                    });
                }
                "start" => {
                    count(3, 3, "start X Y THETA_DEG")?;
                    w.starts.push(StartPose {
                        x: num(0, "X in mm")?,
                        y: num(1, "Y in mm")?,
                        theta: num(2, "THETA in degrees")?,
                    });
                }
                other => {
                    return Err(err(format!(
                        "unknown keyword `{other}`; expected one of wall, room, floorplan, box, ball, start, \
                         wall_height, wall_color, floor_color, sky_color, floor_tile"
                    )));
                }
            }
        }
        w.finish();
        Ok(w)
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
}
