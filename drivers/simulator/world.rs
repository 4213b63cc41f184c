//! The static world: walls (segments and occupancy bitmaps), boxes, the balls'
//! initial places, colours, and the world file parser.
//!
//! Coordinates are in mm: x to the right, y up (as seen from above), angles in
//! degrees counter-clockwise from the x axis at the file surface, z up from the
//! floor. See the module doc of [`super`] for the file format.

use std::{
    fmt,
    path::{Path, PathBuf},
};

/// An RGB colour (the renderer writes BGR).
pub type Rgb = [u8; 3];

/// A 2D point or vector in mm.
pub type P2 = [f64; 2];

/// One problem in a world file: `file:line: message`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct WorldError {
    pub file: PathBuf,
    pub line: usize,
    pub message: String,
}

impl fmt::Display for WorldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.file.display(), self.line, self.message)
    }
}

/// A vertical wall face: the segment a-b on the floor, `height` mm tall.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    pub a: P2,
    pub b: P2,
    pub height: f64,
    pub color: Rgb,
    /// For faces of solid things (bitmap walls, boxes): the unit normal that points
    /// into free space; the face is drawn only from that side. `None`: a thin wall
    /// seen from both sides.
    pub normal: Option<P2>,
}

/// A static box (an obstacle with a top face), centred at `center`.
#[derive(Clone, Debug, PartialEq)]
pub struct BoxObj {
    pub center: P2,
    /// Size along its own x and y axes, mm.
    pub size: P2,
    /// Rotation, radians counter-clockwise.
    pub theta: f64,
    pub height: f64,
    pub color: Rgb,
}

impl BoxObj {
    /// The footprint's corners, counter-clockwise.
    pub fn corners(&self) -> [P2; 4] {
        let (s, c) = self.theta.sin_cos();
        let (hx, hy) = (self.size[0] / 2.0, self.size[1] / 2.0);
        let at = |lx: f64, ly: f64| {
            [
                self.center[0] + c * lx - s * ly,
                self.center[1] + s * lx + c * ly,
            ]
        };
        [at(-hx, -hy), at(hx, -hy), at(hx, hy), at(-hx, hy)]
    }
}

/// A ball's initial state (the simulation moves it).
#[derive(Clone, Debug, PartialEq)]
pub struct BallSpec {
    pub pos: P2,
    pub radius: f64,
    pub color: Rgb,
    /// Rolling deceleration, mm/s².
    pub friction: f64,
}

/// A robot's start pose named in a world file (`start X Y THETA`).
#[derive(Clone, Debug, PartialEq)]
pub struct StartPose {
    pub x: f64,
    pub y: f64,
    /// Degrees.
    pub theta: f64,
}

/// The static world.
#[derive(Clone, Debug)]
pub struct World {
    pub segments: Vec<Segment>,
    pub boxes: Vec<BoxObj>,
    pub balls: Vec<BallSpec>,
    pub starts: Vec<StartPose>,
    pub floor_color: Rgb,
    pub sky_color: Rgb,
    /// Side of the floor's checker tiles, mm (0 = plain floor).
    pub tile: f64,
    grid: SegGrid,
}

impl Default for World {
    fn default() -> Self {
        World::new()
    }
}

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
    /// An empty world (no walls).
    pub fn new() -> World {
        World {
            segments: Vec::new(),
            boxes: Vec::new(),
            balls: Vec::new(),
            starts: Vec::new(),
            floor_color: [150, 150, 140],
            sky_color: [170, 200, 235],
            tile: 1000.0,
            grid: SegGrid::default(),
        }
    }

    /// Adds a thin wall seen from both sides.
    pub fn add_wall(&mut self, a: P2, b: P2, height: f64, color: Rgb) {
        self.segments.push(Segment {
            a,
            b,
            height,
            color,
            normal: None,
        });
        self.grid.dirty = true;
    }

    /// Adds the four walls of an axis-aligned rectangle.
    pub fn add_room(&mut self, min: P2, max: P2, height: f64, color: Rgb) {
        let c = [
            [min[0], min[1]],
            [max[0], min[1]],
            [max[0], max[1]],
            [min[0], max[1]],
        ];
        for k in 0..4 {
            self.add_wall(c[k], c[(k + 1) % 4], height, color);
        }
    }

    /// Adds a static box; its sides become one-sided wall faces.
    pub fn add_box(&mut self, b: BoxObj) {
        let c = b.corners();
        for k in 0..4 {
            let (p, q) = (c[k], c[(k + 1) % 4]);
            let e = [q[0] - p[0], q[1] - p[1]];
            let l = (e[0] * e[0] + e[1] * e[1]).sqrt().max(1e-9);
            // Corners are counter-clockwise, so the outward normal is to the right.
            self.segments.push(Segment {
                a: p,
                b: q,
                height: b.height,
                color: b.color,
                normal: Some([e[1] / l, -e[0] / l]),
            });
        }
        self.boxes.push(b);
        self.grid.dirty = true;
    }

    /// Adds a ball.
    pub fn add_ball(&mut self, b: BallSpec) {
        self.balls.push(b);
    }

    /// Adds the walls of an occupancy bitmap; cell (i, j) covers
    /// [x0 + i·pixel, x0 + (i+1)·pixel] × [y0 + j·pixel, ...]. Only the boundaries
    /// between occupied and free cells become (one-sided) wall faces, merged into runs.
    pub fn add_occupancy(&mut self, map: &Bitmap, pixel: f64, origin: P2, height: f64, color: Rgb) {
        let (dark, w, h) = (&map.dark, map.width, map.height);
        let occ = |i: isize, j: isize| -> bool {
            i >= 0
                && j >= 0
                && (i as usize) < w
                && (j as usize) < h
                && dark[j as usize * w + i as usize]
        };
        let x = |i: usize| origin[0] + i as f64 * pixel;
        let y = |j: usize| origin[1] + j as f64 * pixel;
        let mut push = |a: P2, b: P2, n: P2| {
            self.segments.push(Segment {
                a,
                b,
                height,
                color,
                normal: Some(n),
            })
        };
        // Horizontal boundaries at y(j), j in 0..=h: between row j-1 (below) and row j (above).
        for j in 0..=h {
            for dir in [1.0f64, -1.0] {
                // dir 1: solid below, free above (normal +y); dir -1: the reverse.
                let mut run: Option<usize> = None;
                for i in 0..=w {
                    let edge = i < w && {
                        let below = occ(i as isize, j as isize - 1);
                        let above = occ(i as isize, j as isize);
                        if dir > 0.0 {
                            below && !above
                        } else {
                            above && !below
                        }
                    };
                    match (edge, run) {
                        (true, None) => run = Some(i),
                        (false, Some(s)) => {
                            push([x(s), y(j)], [x(i), y(j)], [0.0, dir]);
                            run = None;
                        }
                        _ => {}
                    }
                }
            }
        }
        // Vertical boundaries at x(i), i in 0..=w: between column i-1 (left) and i (right).
        for i in 0..=w {
            for dir in [1.0f64, -1.0] {
                let mut run: Option<usize> = None;
                for j in 0..=h {
                    let edge = j < h && {
                        let left = occ(i as isize - 1, j as isize);
                        let right = occ(i as isize, j as isize);
                        if dir > 0.0 {
                            left && !right
                        } else {
                            right && !left
                        }
                    };
                    match (edge, run) {
                        (true, None) => run = Some(j),
                        (false, Some(s)) => {
                            push([x(i), y(s)], [x(i), y(j)], [dir, 0.0]);
                            run = None;
                        }
                        _ => {}
                    }
                }
            }
        }
        self.grid.dirty = true;
    }

    /// Loads a PNG floor plan: pixels darker than 50 % grey (and not transparent)
    /// are walls. The image's bottom-left corner is at `origin`.
    pub fn add_floorplan(
        &mut self,
        file: &Path,
        pixel: f64,
        origin: P2,
        height: f64,
        color: Rgb,
    ) -> Result<(), String> {
        let map = load_bitmap(file)?;
        self.add_occupancy(&map, pixel, origin, height, color);
        Ok(())
    }

    /// Builds the ray-casting index; call after adding walls (the simulation does).
    pub fn finish(&mut self) {
        if self.grid.dirty {
            self.grid = SegGrid::build(&self.segments);
        }
    }

    /// The nearest wall along the ray from `o` in unit direction `d` within `max`
    /// mm: (distance, segment index).
    pub fn cast(&self, o: P2, d: P2, max: f64) -> Option<(f64, usize)> {
        if self.grid.dirty {
            // Not indexed yet: test every segment.
            return cast_all(&self.segments, 0..self.segments.len(), o, d, max);
        }
        self.grid.cast(&self.segments, o, d, max)
    }

    /// Calls `f` with every wall segment that may lie within `r` of `p`.
    pub fn near(&self, p: P2, r: f64, mut f: impl FnMut(&Segment)) {
        if self.grid.dirty {
            self.segments.iter().for_each(f);
            return;
        }
        self.grid.near(p, r, |i| f(&self.segments[i as usize]));
    }

    /// The bounding box of all walls and boxes (min, max), if any.
    pub fn bounds(&self) -> Option<(P2, P2)> {
        let mut it = self.segments.iter().flat_map(|s| [s.a, s.b]);
        let first = it.next()?;
        Some(it.fold((first, first), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        }))
    }

    /// Reads a world file.
    pub fn load(file: &Path) -> Result<World, WorldError> {
        let text = std::fs::read_to_string(file).map_err(|e| WorldError {
            file: file.to_path_buf(),
            line: 0,
            message: format!("cannot read world file: {e}"),
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
                    let b = BoxObj {
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

/// An occupancy bitmap: `dark[j * width + i]` is cell (i, j), rows from the bottom.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Bitmap {
    pub dark: Vec<bool>,
    pub width: usize,
    pub height: usize,
}

/// Decodes a PNG into an occupancy bitmap.
pub fn load_bitmap(file: &Path) -> Result<Bitmap, String> {
    let bytes = std::fs::read(file).map_err(|e| format!("cannot read: {e}"))?;
    let mut dec = png::Decoder::new(std::io::Cursor::new(bytes));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec
        .read_info()
        .map_err(|e| format!("not a readable PNG: {e}"))?;
    let (w, h) = (reader.info().width as usize, reader.info().height as usize);
    if w == 0 || h == 0 || w * h > 16_000_000 {
        return Err(format!(
            "{w}x{h} pixels: expected a non-empty image of at most 16 Mpixels"
        ));
    }
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| "image too large".to_string())?;
    let mut buf = vec![0u8; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format!("cannot decode PNG: {e}"))?;
    let channels = info.color_type.samples();
    let mut dark = vec![false; w * h];
    for py in 0..h {
        let row = &buf[py * info.line_size..];
        let j = h - 1 - py;
        for i in 0..w {
            let px = &row[i * channels..(i + 1) * channels];
            let (lum, alpha) = match channels {
                1 => (px[0] as u32, 255),
                2 => (px[0] as u32, px[1] as u32),
                3 => (
                    (px[0] as u32 * 30 + px[1] as u32 * 59 + px[2] as u32 * 11) / 100,
                    255,
                ),
                _ => (
                    (px[0] as u32 * 30 + px[1] as u32 * 59 + px[2] as u32 * 11) / 100,
                    px[3] as u32,
                ),
            };
            dark[j * w + i] = lum < 128 && alpha >= 128;
        }
    }
    Ok(Bitmap {
        dark,
        width: w,
        height: h,
    })
}

#[inline]
fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Ray o + t·d against segment s: t if it hits.
#[inline]
pub fn ray_segment(o: P2, d: P2, s: &Segment) -> Option<f64> {
    let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let den = cross(d, e);
    if den.abs() < 1e-12 {
        return None;
    }
    let ao = [s.a[0] - o[0], s.a[1] - o[1]];
    let t = cross(ao, e) / den;
    let u = cross(ao, d) / den;
    (t >= 0.0 && (-1e-9..=1.0 + 1e-9).contains(&u)).then_some(t)
}

/// Ray o + t·d (d unit) against a circle: the nearest t ≥ 0 if it hits.
#[inline]
pub fn ray_circle(o: P2, d: P2, c: P2, r: f64) -> Option<f64> {
    let oc = [o[0] - c[0], o[1] - c[1]];
    let b = oc[0] * d[0] + oc[1] * d[1];
    let cc = oc[0] * oc[0] + oc[1] * oc[1] - r * r;
    if cc <= 0.0 {
        return Some(0.0); // inside
    }
    let disc = b * b - cc;
    if disc < 0.0 || b > 0.0 {
        return None;
    }
    Some(-b - disc.sqrt())
}

/// The point of segment s nearest to p.
#[inline]
pub fn closest_on_segment(p: P2, s: &Segment) -> P2 {
    let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
    let l2 = e[0] * e[0] + e[1] * e[1];
    let t = if l2 > 0.0 {
        (((p[0] - s.a[0]) * e[0] + (p[1] - s.a[1]) * e[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    [s.a[0] + t * e[0], s.a[1] + t * e[1]]
}

fn cast_all(
    segs: &[Segment],
    idx: impl Iterator<Item = usize>,
    o: P2,
    d: P2,
    max: f64,
) -> Option<(f64, usize)> {
    let mut best: Option<(f64, usize)> = None;
    for i in idx {
        if let Some(t) = ray_segment(o, d, &segs[i])
            && t <= max
            && best.is_none_or(|(b, _)| t < b)
        {
            best = Some((t, i));
        }
    }
    best
}

/// A uniform grid over the walls: each cell lists the segments that cross it.
#[derive(Clone, Debug)]
struct SegGrid {
    dirty: bool,
    origin: P2,
    cell: f64,
    nx: usize,
    ny: usize,
    /// CSR: segments of cell k are `items[start[k]..start[k+1]]`.
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Default for SegGrid {
    fn default() -> Self {
        SegGrid {
            dirty: true,
            origin: [0.0, 0.0],
            cell: 1.0,
            nx: 0,
            ny: 0,
            start: vec![0],
            items: Vec::new(),
        }
    }
}

impl SegGrid {
    fn build(segs: &[Segment]) -> SegGrid {
        if segs.is_empty() {
            return SegGrid {
                dirty: false,
                ..SegGrid::default()
            };
        }
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        let mut total_len = 0.0;
        for s in segs {
            for p in [s.a, s.b] {
                lo = [lo[0].min(p[0]), lo[1].min(p[1])];
                hi = [hi[0].max(p[0]), hi[1].max(p[1])];
            }
            total_len += ((s.b[0] - s.a[0]).powi(2) + (s.b[1] - s.a[1]).powi(2)).sqrt();
        }
        let ext = [(hi[0] - lo[0]).max(1.0), (hi[1] - lo[1]).max(1.0)];
        // About 2 segments per occupied cell, and at most 256x256 cells.
        let mean = total_len / segs.len() as f64;
        let cell = mean.clamp(100.0, 2000.0).max(ext[0].max(ext[1]) / 256.0);
        let origin = [lo[0] - 1.0, lo[1] - 1.0];
        let nx = ((ext[0] + 2.0) / cell).ceil() as usize + 1;
        let ny = ((ext[1] + 2.0) / cell).ceil() as usize + 1;
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); nx * ny];
        for (k, s) in segs.iter().enumerate() {
            let ci =
                |v: f64, o: f64, n: usize| (((v - o) / cell).floor().max(0.0) as usize).min(n - 1);
            let (i0, i1) = (
                ci(s.a[0].min(s.b[0]), origin[0], nx),
                ci(s.a[0].max(s.b[0]), origin[0], nx),
            );
            let (j0, j1) = (
                ci(s.a[1].min(s.b[1]), origin[1], ny),
                ci(s.a[1].max(s.b[1]), origin[1], ny),
            );
            let e = [s.b[0] - s.a[0], s.b[1] - s.a[1]];
            for j in j0..=j1 {
                for i in i0..=i1 {
                    // Keep the cell unless all its corners lie strictly on one side.
                    let x0 = origin[0] + i as f64 * cell;
                    let y0 = origin[1] + j as f64 * cell;
                    let sides = [
                        [x0, y0],
                        [x0 + cell, y0],
                        [x0, y0 + cell],
                        [x0 + cell, y0 + cell],
                    ]
                    .map(|c| cross(e, [c[0] - s.a[0], c[1] - s.a[1]]).signum());
                    if sides.iter().all(|&v| v > 0.0) || sides.iter().all(|&v| v < 0.0) {
                        continue;
                    }
                    lists[j * nx + i].push(k as u32);
                }
            }
        }
        let mut start = Vec::with_capacity(nx * ny + 1);
        let mut items = Vec::new();
        start.push(0);
        for l in &lists {
            items.extend_from_slice(l);
            start.push(items.len() as u32);
        }
        SegGrid {
            dirty: false,
            origin,
            cell,
            nx,
            ny,
            start,
            items,
        }
    }

    #[inline]
    fn cell_items(&self, i: usize, j: usize) -> &[u32] {
        let k = j * self.nx + i;
        &self.items[self.start[k] as usize..self.start[k + 1] as usize]
    }

    fn near(&self, p: P2, r: f64, mut f: impl FnMut(u32)) {
        if self.nx == 0 {
            return;
        }
        let ci = |v: f64, o: f64, n: usize| -> Option<(usize, usize)> {
            let a = ((v - r - o) / self.cell).floor();
            let b = ((v + r - o) / self.cell).floor();
            if b < 0.0 || a >= n as f64 {
                return None;
            }
            Some((a.max(0.0) as usize, (b as usize).min(n - 1)))
        };
        let (Some((i0, i1)), Some((j0, j1))) = (
            ci(p[0], self.origin[0], self.nx),
            ci(p[1], self.origin[1], self.ny),
        ) else {
            return;
        };
        for j in j0..=j1 {
            for i in i0..=i1 {
                self.cell_items(i, j).iter().for_each(|&k| f(k));
            }
        }
    }

    /// Amanatides-Woo traversal of the cells the ray crosses.
    fn cast(&self, segs: &[Segment], o: P2, d: P2, max: f64) -> Option<(f64, usize)> {
        if self.nx == 0 {
            return None;
        }
        let size = [self.nx as f64 * self.cell, self.ny as f64 * self.cell];
        // Clip the ray to the grid's box.
        let mut t0: f64 = 0.0;
        let mut t1: f64 = max;
        for a in 0..2 {
            let lo = self.origin[a];
            let hi = lo + size[a];
            if d[a].abs() < 1e-15 {
                if o[a] < lo || o[a] > hi {
                    return None;
                }
            } else {
                let (mut ta, mut tb) = ((lo - o[a]) / d[a], (hi - o[a]) / d[a]);
                if ta > tb {
                    std::mem::swap(&mut ta, &mut tb);
                }
                t0 = t0.max(ta);
                t1 = t1.min(tb);
            }
        }
        if t0 > t1 {
            return None;
        }
        let p = [o[0] + d[0] * t0, o[1] + d[1] * t0];
        let mut i =
            (((p[0] - self.origin[0]) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let mut j =
            (((p[1] - self.origin[1]) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        let step = |dv: f64| if dv > 0.0 { 1isize } else { -1 };
        let (si, sj) = (step(d[0]), step(d[1]));
        let next = |idx: usize, s: isize, a: usize| -> f64 {
            if d[a].abs() < 1e-15 {
                return f64::INFINITY;
            }
            let b = self.origin[a] + (idx as f64 + if s > 0 { 1.0 } else { 0.0 }) * self.cell;
            (b - o[a]) / d[a]
        };
        let mut tx = next(i, si, 0);
        let mut ty = next(j, sj, 1);
        let dtx = if d[0].abs() < 1e-15 {
            f64::INFINITY
        } else {
            self.cell / d[0].abs()
        };
        let dty = if d[1].abs() < 1e-15 {
            f64::INFINITY
        } else {
            self.cell / d[1].abs()
        };
        let mut best: Option<(f64, usize)> = None;
        loop {
            for &k in self.cell_items(i, j) {
                if let Some(t) = ray_segment(o, d, &segs[k as usize])
                    && t <= max
                    && best.is_none_or(|(b, _)| t < b)
                {
                    best = Some((t, k as usize));
                }
            }
            let exit = tx.min(ty);
            if best.is_some_and(|(b, _)| b <= exit) || exit > t1 {
                return best;
            }
            if tx < ty {
                let ni = i as isize + si;
                if ni < 0 || ni >= self.nx as isize {
                    return best;
                }
                i = ni as usize;
                tx += dtx;
            } else {
                let nj = j as isize + sj;
                if nj < 0 || nj >= self.ny as isize {
                    return best;
                }
                j = nj as usize;
                ty += dty;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_cast_matches_brute_force() {
        let mut w = World::new();
        w.add_room([0.0, 0.0], [10000.0, 8000.0], 1000.0, [1, 2, 3]);
        w.add_wall([2000.0, 1000.0], [7000.0, 6000.0], 1000.0, [1, 2, 3]);
        w.add_box(BoxObj {
            center: [8000.0, 2000.0],
            size: [600.0, 400.0],
            theta: 0.3,
            height: 500.0,
            color: [0, 0, 0],
        });
        w.finish();
        for k in 0..720 {
            let a = (k as f64 * 0.5f64).to_radians();
            let d = [a.cos(), a.sin()];
            for o in [[500.0, 500.0], [5000.0, 4000.0], [9000.0, 7000.0]] {
                let g = w.cast(o, d, 20000.0).map(|x| x.0);
                let b = cast_all(&w.segments, 0..w.segments.len(), o, d, 20000.0).map(|x| x.0);
                match (g, b) {
                    (Some(g), Some(b)) => assert!((g - b).abs() < 1e-6, "{g} vs {b}"),
                    (g, b) => assert_eq!(g.is_some(), b.is_some()),
                }
            }
        }
    }

    #[test]
    fn occupancy_boundaries_merge() {
        let mut w = World::new();
        // A 3x2 solid block: 4 merged faces.
        let map = Bitmap {
            dark: vec![true; 6],
            width: 3,
            height: 2,
        };
        w.add_occupancy(&map, 100.0, [0.0, 0.0], 500.0, [0, 0, 0]);
        assert_eq!(w.segments.len(), 4);
        w.finish();
        let (t, _) = w.cast([-500.0, 100.0], [1.0, 0.0], 10000.0).unwrap();
        assert!((t - 500.0).abs() < 1e-9);
    }

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
