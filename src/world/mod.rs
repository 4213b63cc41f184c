//! Worlds: the static map robots live in (walls, boxes, where balls and robots
//! start), its file format, the 2D geometry over it and the grid that makes ray
//! casting fast. A world belongs to no driver: the simulator simulates one, a
//! schema draws or plans over one, a Player/Stage driver or a replay could export
//! one.
//!
//! - [`World`] (this file): [`Segment`]s (wall faces), [`BoxObstacle`]s,
//!   [`BallSpec`]s, [`StartPose`]s, floor [`Paint`] and targets, with [`World::cast`] (the nearest wall along
//!   a ray) and [`World::near`] (the walls around a point).
//! - [`parse`]: the world file format ([`World::load`], [`World::parse`]) and
//!   colours ([`parse_color`], [`COLOR_NAMES`]).
//! - [`geometry`]: [`Point2`] and rays against segments and circles.
//! - [`grid`]: the uniform grid over the walls that [`World::cast`] walks.
//! - [`bitmap`]: occupancy bitmaps (PNG floor plans) turned into wall faces.
//! - [`scoring`]: the Robotics Academy's scores (floor swept, targets reached,
//!   laps of a painted line) kept from a robot's true pose: [`Scorer`], [`Score`].
//!
//! Coordinates are in mm: x to the right, y up (as seen from above), z up from the
//! floor; angles in degrees counter-clockwise from the x axis in files, radians in
//! code.
//!
//! # Name space keys
//! A driver that knows the world exports it; schemas find it by these keys,
//! whichever driver exported it (the first export wins):
//!
//! | component | name | type | what |
//! |---|---|---|---|
//! | [`COMPONENT`] (`world`) | [`MAP`] (`map`) | [`World`] | the static world: walls, boxes, where balls start |
//! | [`COMPONENT`] (`world`) | [`BALLS`] (`balls`) | [`LiveBalls`] | the balls as they roll, refreshed by the exporter (the simulator: at its encoders' period); readers never wait |
//! | [`COMPONENT`] (`world`) | [`SCORE`] (`score`) | [`LiveScore`] | the exercise's [`Score`] as it stands (the simulator's `score` line: at its encoders' period); [`Score::summary`] says it in one line |
//!
//! [`export_map`]/[`export_balls`]/[`export_score`] export them,
//! [`map`]/[`balls`]/[`score`] look them up. Import the balls or the score once
//! and `load()` them whenever they are drawn.
//!
//! # World file
//! Line based, `#` comments, lengths in mm, angles in degrees; errors name
//! `file:line`. Colours are names (`red`, `green`, `blue`, `yellow`, `orange`,
//! `white`, `grey`, ... see [`COLOR_NAMES`]) or `R,G,B`.
//! ```text
//! wall_height 1000             # height of the walls that follow (default 1000)
//! wall_color beige             # colour of the walls that follow
//! floor_color 150,150,140      # floor_tile 1000: checker tiles (0 = plain floor)
//! sky_color sky
//! room X1 Y1 X2 Y2             # four walls around a rectangle
//! wall X1 Y1 X2 Y2             # one thin wall
//! floorplan plan.png 50 [X0 Y0]  # occupancy bitmap, 50 mm per pixel, bottom-left corner at
//!                              #   (X0, Y0); pixels darker than 50 % grey are walls
//! box X Y SIZE_X SIZE_Y HEIGHT COLOR [THETA]   # a static box centred at (X, Y)
//! ball X Y RADIUS COLOR [FRICTION]             # a ball; rolling deceleration mm/s² (300)
//! start X Y THETA              # a start pose for robots the conf does not place
//! target X Y                   # the next target of the obstacle course (in order)
//! paint WIDTH COLOR [closed]   # a line painted on the floor, WIDTH mm wide, through the
//! point X Y                    #   `point` lines right after it (2 or more; 3 if closed,
//! point X Y                    #   the last joins the first); the camera sees it, the
//! point X Y                    #   laser and bumpers do not (no obstacle)
//! ```
//!
//! This is the bottom layer: it uses only std, external crates (`png` for floor
//! plans, `arc-swap` for the live balls, `thiserror`) and the [`Namespace`] type
//! (same layer); never conf, runtime, registry, gui, drivers or schemas.

pub mod bitmap;
pub mod geometry;
pub mod grid;
pub mod parse;
pub mod scoring;

use std::{fmt, path::PathBuf, sync::Arc};

use arc_swap::ArcSwap;

use crate::namespace::{Namespace, NamespaceError};

pub use bitmap::{Bitmap, load_bitmap};
pub use geometry::{Point2, closest_on, closest_on_segment, distance, ray_circle, ray_segment};
pub use parse::{COLOR_NAMES, parse_color};
pub use scoring::{Rule, Score, Scorer};

use grid::SegmentGrid;

/// An RGB colour (the renderer writes BGR).
pub type Rgb = [u8; 3];

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
    pub a: Point2,
    pub b: Point2,
    pub height: f64,
    pub color: Rgb,
    /// For faces of solid things (bitmap walls, boxes): the unit normal that points
    /// into free space; the face is drawn only from that side. `None`: a thin wall
    /// seen from both sides.
    pub normal: Option<Point2>,
}

/// A static box (an obstacle with a top face), centred at `center`.
#[derive(Clone, Debug, PartialEq)]
pub struct BoxObstacle {
    pub center: Point2,
    /// Size along its own x and y axes, mm.
    pub size: Point2,
    /// Rotation, radians counter-clockwise.
    pub theta: f64,
    pub height: f64,
    pub color: Rgb,
}

impl BoxObstacle {
    /// The footprint's corners, counter-clockwise.
    pub fn corners(&self) -> [Point2; 4] {
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

/// A ball's initial state (a simulation moves it: see [`Ball`]).
#[derive(Clone, Debug, PartialEq)]
pub struct BallSpec {
    pub pos: Point2,
    pub radius: f64,
    pub color: Rgb,
    /// Rolling deceleration, mm/s².
    pub friction: f64,
}

/// A ball as it moves (what [`LiveBalls`] holds).
#[derive(Clone, Debug)]
pub struct Ball {
    /// Centre on the floor, mm.
    pub pos: Point2,
    /// Velocity, mm/s.
    pub vel: Point2,
    pub radius: f64,
    pub color: Rgb,
    /// Rolling deceleration, mm/s².
    pub friction: f64,
}

impl From<&BallSpec> for Ball {
    fn from(b: &BallSpec) -> Ball {
        Ball {
            pos: b.pos,
            vel: [0.0, 0.0],
            radius: b.radius,
            color: b.color,
            friction: b.friction,
        }
    }
}

/// The balls as they are now, replaced whole by their exporter; readers never wait.
pub type LiveBalls = ArcSwap<Vec<Ball>>;

/// A line painted on the floor (`paint` and its `point`s): the camera sees it,
/// nothing bumps into it (the laser, sonars and bumpers ignore it).
#[derive(Clone, Debug, PartialEq)]
pub struct Paint {
    /// The centre line's vertices, mm (at least 2; 3 if closed).
    pub points: Vec<Point2>,
    /// Whether the last point joins the first.
    pub closed: bool,
    /// Width of the stroke, mm.
    pub width: f64,
    pub color: Rgb,
}

impl Paint {
    /// The centre line's pieces, in order (the closing one last when closed).
    pub fn segments(&self) -> impl Iterator<Item = (Point2, Point2)> + '_ {
        let n = self.points.len();
        let pieces = if self.closed && n > 2 {
            n
        } else {
            n.saturating_sub(1)
        };
        (0..pieces).map(move |k| (self.points[k], self.points[(k + 1) % n]))
    }

    /// The distance from `p` to the centre line, mm.
    pub fn distance(&self, p: Point2) -> f64 {
        self.segments()
            .map(|(a, b)| distance(p, closest_on(p, a, b)))
            .fold(f64::INFINITY, f64::min)
    }

    /// The centre line's length, mm.
    pub fn length(&self) -> f64 {
        self.segments().map(|(a, b)| distance(a, b)).sum()
    }
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
    pub boxes: Vec<BoxObstacle>,
    pub balls: Vec<BallSpec>,
    pub starts: Vec<StartPose>,
    /// Lines painted on the floor, in file order.
    pub paint: Vec<Paint>,
    /// Targets (`target X Y`), in the order they are to be reached, mm.
    pub targets: Vec<Point2>,
    pub floor_color: Rgb,
    pub sky_color: Rgb,
    /// Side of the floor's checker tiles, mm (0 = plain floor).
    pub tile: f64,
    grid: SegmentGrid,
}

impl Default for World {
    fn default() -> Self {
        World::new()
    }
}

impl World {
    /// An empty world (no walls).
    pub fn new() -> World {
        World {
            segments: Vec::new(),
            boxes: Vec::new(),
            balls: Vec::new(),
            starts: Vec::new(),
            paint: Vec::new(),
            targets: Vec::new(),
            floor_color: [150, 150, 140],
            sky_color: [170, 200, 235],
            tile: 1000.0,
            grid: SegmentGrid::default(),
        }
    }

    /// Adds a thin wall seen from both sides.
    pub fn add_wall(&mut self, a: Point2, b: Point2, height: f64, color: Rgb) {
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
    pub fn add_room(&mut self, min: Point2, max: Point2, height: f64, color: Rgb) {
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
    pub fn add_box(&mut self, b: BoxObstacle) {
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

    /// Builds the ray-casting index; call after adding walls (a simulation does).
    pub fn finish(&mut self) {
        if self.grid.dirty {
            self.grid = SegmentGrid::build(&self.segments);
        }
    }

    /// The nearest wall along the ray from `o` in unit direction `d` within `max`
    /// mm: (distance, segment index).
    pub fn cast(&self, o: Point2, d: Point2, max: f64) -> Option<(f64, usize)> {
        if self.grid.dirty {
            // Not indexed yet: test every segment.
            return grid::cast_every(&self.segments, 0..self.segments.len(), o, d, max);
        }
        self.grid.cast(&self.segments, o, d, max)
    }

    /// Calls `f` with every wall segment that may lie within `r` of `p`.
    pub fn near(&self, p: Point2, r: f64, mut f: impl FnMut(&Segment)) {
        if self.grid.dirty {
            self.segments.iter().for_each(f);
            return;
        }
        self.grid.near(p, r, |i| f(&self.segments[i as usize]));
    }

    /// The bounding box of all walls and boxes (min, max), if any.
    pub fn bounds(&self) -> Option<(Point2, Point2)> {
        let mut it = self.segments.iter().flat_map(|s| [s.a, s.b]);
        let first = it.next()?;
        Some(it.fold((first, first), |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        }))
    }
}

/// The name-space component under which the world is exported.
pub const COMPONENT: &str = "world";
/// The name of the static [`World`] under [`COMPONENT`].
pub const MAP: &str = "map";
/// The name of the [`LiveBalls`] under [`COMPONENT`].
pub const BALLS: &str = "balls";

/// The name of the [`LiveScore`] under [`COMPONENT`].
pub const SCORE: &str = "score";
/// The name of the [`LiveDrawings`] under [`COMPONENT`].
pub const DRAWINGS: &str = "drawings";

/// What a robot's program draws over the world, in the robot's frame (x ahead,
/// y left): the obstacle-avoidance exercise's car (attraction), obstacle
/// (repulsion) and average forces (unitless), and its local target (m).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Drawings {
    pub forces: Option<[[f64; 2]; 3]>,
    pub local_target: Option<[f64; 2]>,
}

/// The program's latest drawings, replaced whole; readers never wait.
pub type LiveDrawings = ArcSwap<Drawings>;

/// Exports empty drawings as `world.drawings`, or gives the ones exported
/// already (one robot's program draws them).
pub fn export_drawings(names: &Namespace) -> Result<Arc<LiveDrawings>, NamespaceError> {
    match drawings(names) {
        Some(d) => Ok(d),
        None => names.export(
            COMPONENT,
            DRAWINGS,
            LiveDrawings::from_pointee(Drawings::default()),
        ),
    }
}

/// The exported drawings (`world.drawings`), whoever draws them.
pub fn drawings(names: &Namespace) -> Option<Arc<LiveDrawings>> {
    names.import::<LiveDrawings>(COMPONENT, DRAWINGS).ok()
}

/// The score of the run as it stands, replaced whole by its keeper; readers never
/// wait.
pub type LiveScore = ArcSwap<Score>;

/// Exports `score` as `world.score`; the returned handle is where the keeper
/// stores each new state.
pub fn export_score(names: &Namespace, score: Score) -> Result<Arc<LiveScore>, NamespaceError> {
    names.export(COMPONENT, SCORE, LiveScore::from_pointee(score))
}

/// The exported score (`world.score`), whoever keeps it; None if nobody does.
/// Import once and `load()` whenever it is shown.
pub fn score(names: &Namespace) -> Option<Arc<LiveScore>> {
    names.import::<LiveScore>(COMPONENT, SCORE).ok()
}

/// Exports `world` as `world.map` for the schemas that draw or plan over it. If
/// another component exported a map first, that one stays and this is an error.
pub fn export_map(names: &Namespace, world: World) -> Result<Arc<World>, NamespaceError> {
    names.export(COMPONENT, MAP, world)
}

/// Exports `balls` as `world.balls`; the returned handle is where the exporter
/// stores each new state (`store(Arc::new(balls))`).
pub fn export_balls(names: &Namespace, balls: Vec<Ball>) -> Result<Arc<LiveBalls>, NamespaceError> {
    names.export(COMPONENT, BALLS, LiveBalls::from_pointee(balls))
}

/// The exported world map (`world.map`), whoever exported it; None if nobody did.
pub fn map(names: &Namespace) -> Option<Arc<World>> {
    names.import::<World>(COMPONENT, MAP).ok()
}

/// The exported live balls (`world.balls`), whoever exported them; None if nobody
/// did. Import once and `load()` whenever they are drawn.
pub fn balls(names: &Namespace) -> Option<Arc<LiveBalls>> {
    names.import::<LiveBalls>(COMPONENT, BALLS).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_find_what_any_component_exported() {
        let ns = Namespace::default();
        assert!(map(&ns).is_none() && balls(&ns).is_none());
        let mut w = World::new();
        w.add_room([0.0, 0.0], [1000.0, 1000.0], 500.0, [1, 2, 3]);
        export_map(&ns, w).unwrap();
        let spec = BallSpec {
            pos: [500.0, 500.0],
            radius: 100.0,
            color: [255, 0, 0],
            friction: 300.0,
        };
        let live = export_balls(&ns, vec![Ball::from(&spec)]).unwrap();
        assert_eq!(map(&ns).unwrap().segments.len(), 4);
        let seen = balls(&ns).unwrap();
        live.store(Arc::new(Vec::new()));
        assert!(
            seen.load().is_empty(),
            "importers see the exporter's updates"
        );
        assert!(
            export_map(&ns, World::new()).is_err(),
            "the first map stays"
        );
    }
}
