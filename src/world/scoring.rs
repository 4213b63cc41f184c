//! The scores the Robotics Academy shows for its classic exercises, kept from a
//! robot's true pose (not its odometry) as it moves through a [`World`]:
//!
//! - [`Rule::Swept`] (vacuum cleaner): the floor is a grid of [`SWEPT_CELL`] mm
//!   cells, those whose centres the start reaches by steps from cell centre to
//!   cell centre that cross no wall or box face (a flood fill: cells inside boxes,
//!   behind walls or outside the rooms do not count). A cell is swept when the
//!   robot's disc covers its centre. Corners a disc cannot reach stay unswept, so
//!   100 % is out of reach, as on a real floor.
//! - [`Rule::Targets`] (obstacle avoidance): the world's `target`s in file order;
//!   one counts when the robot's centre comes within [`TARGET_RADIUS`] of it, and
//!   only after the ones before it. The time is that of the latest target.
//! - [`Rule::Lap`] (follow line): the world's first closed painted line.
//!   [`LAP_CHECKPOINTS`] checkpoints split it into equal lengths, the first where
//!   the line passes nearest the start, in the direction the robot faces; a lap is
//!   done when the robot's centre has come within [`CHECKPOINT_RADIUS`] of each in
//!   order (half their spacing on a line shorter than 16 m) and then of the first again. Its time, and the mean (over time) and
//!   maximum distance of the robot's centre from the line during it.
//!
//! Times are the simulation's seconds since its start, so a score follows its
//! clock (real time, faster, or lock-stepped).

use super::{Paint, Point2, World, closest_on, distance, ray_segment};

/// Side of a swept cell, mm.
pub const SWEPT_CELL: f64 = 200.0;
/// A target is reached when the robot's centre comes this close to it, mm.
pub const TARGET_RADIUS: f64 = 500.0;
/// Checkpoints per lap, the start included.
pub const LAP_CHECKPOINTS: usize = 8;
/// A checkpoint is passed when the robot's centre comes this close to it, mm.
pub const CHECKPOINT_RADIUS: f64 = 1000.0;
/// The largest floor grid, cells (a 100 m x 100 m world at 200 mm).
const MAX_CELLS: usize = 250_000;

/// Which score a run keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rule {
    /// The share of the floor swept.
    Swept,
    /// The targets reached, in order, and when.
    Targets,
    /// Laps of the painted line: time, distance from the line.
    Lap,
}

/// A score as it stands (what `world.score` holds).
#[derive(Clone, Debug, PartialEq)]
pub enum Score {
    Swept(Swept),
    Targets(Targets),
    Lap(Laps),
}

/// [`Rule::Swept`]'s score.
#[derive(Clone, Debug, PartialEq)]
pub struct Swept {
    /// Floor cells swept so far, and in all.
    pub swept: usize,
    pub cells: usize,
    /// Side of a cell, mm.
    pub cell: f64,
    /// Seconds since the start.
    pub time: f64,
}

/// [`Rule::Targets`]'s score.
#[derive(Clone, Debug, PartialEq)]
pub struct Targets {
    /// Targets reached (the first `reached` of the world's), and in all.
    pub reached: usize,
    pub total: usize,
    /// When the latest one was reached, seconds since the start.
    pub last: Option<f64>,
    /// Seconds since the start.
    pub time: f64,
}

/// [`Rule::Lap`]'s score.
#[derive(Clone, Debug, PartialEq)]
pub struct Laps {
    /// The laps done, in order.
    pub laps: Vec<Lap>,
    /// Checkpoints passed in the lap under way (the start not counted), of
    /// `checkpoints - 1`.
    pub passed: usize,
    pub checkpoints: usize,
    /// Seconds since the start.
    pub time: f64,
}

/// One lap.
#[derive(Clone, Debug, PartialEq)]
pub struct Lap {
    /// Seconds.
    pub time: f64,
    /// The robot centre's distance from the line: mean over the lap's time, and
    /// maximum, mm.
    pub mean: f64,
    pub max: f64,
}

impl Score {
    /// One line for people, e.g. `targets 5 of 8 in 73.2 s`.
    pub fn summary(&self) -> String {
        match self {
            Score::Swept(s) => format!(
                "swept {:.0} % of the floor ({} of {} cells) in {:.0} s",
                100.0 * s.swept as f64 / s.cells.max(1) as f64,
                s.swept,
                s.cells,
                s.time
            ),
            Score::Targets(t) => match t.last {
                Some(last) => format!("targets {} of {} in {last:.1} s", t.reached, t.total),
                None => format!("targets 0 of {} ({:.1} s)", t.total, t.time),
            },
            Score::Lap(l) => match l.laps.last() {
                Some(lap) => format!(
                    "lap {}: {:.1} s, mean {:.0} mm / max {:.0} mm from the line",
                    l.laps.len(),
                    lap.time,
                    lap.mean,
                    lap.max
                ),
                None => format!(
                    "lap 1 under way: checkpoint {} of {} ({:.1} s)",
                    l.passed,
                    l.checkpoints - 1,
                    l.time
                ),
            },
        }
    }
}

/// Keeps one [`Score`] as a robot moves: [`Scorer::update`] with its true
/// position after each step.
#[derive(Clone, Debug)]
pub struct Scorer {
    score: Score,
    state: State,
}

#[derive(Clone, Debug)]
enum State {
    Swept(Floor),
    Targets(Vec<Point2>),
    Lap(Circuit),
}

impl Scorer {
    /// A scorer of `rule` for a robot of `radius` mm that starts at `start`
    /// heading `heading` radians. Errors say what the world lacks.
    pub fn new(
        rule: Rule,
        world: &World,
        start: Point2,
        heading: f64,
        radius: f64,
    ) -> Result<Scorer, String> {
        let (score, state) = match rule {
            Rule::Swept => {
                let floor = Floor::fill(world, start, radius)?;
                let score = Swept {
                    swept: 0,
                    cells: floor.cells,
                    cell: SWEPT_CELL,
                    time: 0.0,
                };
                (Score::Swept(score), State::Swept(floor))
            }
            Rule::Targets => {
                if world.targets.is_empty() {
                    return Err(
                        "the world has no targets; add `target X Y` lines (mm, in the \
                                order to reach them) to its file"
                            .into(),
                    );
                }
                let score = Targets {
                    reached: 0,
                    total: world.targets.len(),
                    last: None,
                    time: 0.0,
                };
                (Score::Targets(score), State::Targets(world.targets.clone()))
            }
            Rule::Lap => {
                let circuit = Circuit::new(world, start, heading)?;
                let score = Laps {
                    laps: Vec::new(),
                    passed: 0,
                    checkpoints: LAP_CHECKPOINTS,
                    time: 0.0,
                };
                (Score::Lap(score), State::Lap(circuit))
            }
        };
        let mut s = Scorer { score, state };
        s.update(start, 0.0);
        Ok(s)
    }

    /// The robot's centre is at `p` at `time` seconds since the start.
    pub fn update(&mut self, p: Point2, time: f64) {
        match (&mut self.score, &mut self.state) {
            (Score::Swept(s), State::Swept(floor)) => {
                s.swept += floor.sweep(p);
                s.time = time;
            }
            (Score::Targets(t), State::Targets(targets)) => {
                while t.reached < targets.len() && distance(p, targets[t.reached]) <= TARGET_RADIUS
                {
                    t.reached += 1;
                    t.last = Some(time);
                }
                t.time = time;
            }
            (Score::Lap(l), State::Lap(c)) => c.update(l, p, time),
            _ => {}
        }
    }

    /// The score as it stands.
    pub fn score(&self) -> &Score {
        &self.score
    }
}

/// The floor as a grid of cells: 0 not floor, 1 floor, 2 swept.
#[derive(Clone, Debug)]
struct Floor {
    origin: Point2,
    cols: usize,
    rows: usize,
    cell: Vec<u8>,
    cells: usize,
    radius: f64,
}

impl Floor {
    /// The floor cells the start reaches (see the module doc).
    fn fill(world: &World, start: Point2, radius: f64) -> Result<Floor, String> {
        let (lo, hi) = world.bounds().ok_or(
            "the world has no walls: the swept score needs a floor closed by walls (`room`, `wall`)",
        )?;
        let cols = ((hi[0] - lo[0]) / SWEPT_CELL).ceil().max(1.0) as usize;
        let rows = ((hi[1] - lo[1]) / SWEPT_CELL).ceil().max(1.0) as usize;
        if cols.saturating_mul(rows) > MAX_CELLS {
            return Err(format!(
                "the world's walls span {:.0} x {:.0} mm, over the swept score's {MAX_CELLS} cells of \
                 {SWEPT_CELL} mm; make the flat smaller",
                hi[0] - lo[0],
                hi[1] - lo[1]
            ));
        }
        let mut floor = Floor {
            origin: lo,
            cols,
            rows,
            cell: vec![0; cols * rows],
            cells: 0,
            radius,
        };
        let inside = |v: f64, n: usize| (v >= 0.0 && v < n as f64).then_some(v as usize);
        let (Some(c0), Some(r0)) = (
            inside((start[0] - lo[0]) / SWEPT_CELL, cols),
            inside((start[1] - lo[1]) / SWEPT_CELL, rows),
        ) else {
            return Err(format!(
                "the robot starts at ({:.0}, {:.0}), outside the world's walls",
                start[0], start[1]
            ));
        };
        let mut todo = vec![(c0, r0)];
        floor.cell[r0 * cols + c0] = 1;
        while let Some((c, r)) = todo.pop() {
            floor.cells += 1;
            let from = floor.centre(c, r);
            let next = [
                (c.wrapping_sub(1), r),
                (c + 1, r),
                (c, r.wrapping_sub(1)),
                (c, r + 1),
            ];
            for (nc, nr) in next {
                if nc >= cols || nr >= rows || floor.cell[nr * cols + nc] != 0 {
                    continue;
                }
                let to = floor.centre(nc, nr);
                if !crosses_a_wall(world, from, to) {
                    floor.cell[nr * cols + nc] = 1;
                    todo.push((nc, nr));
                }
            }
        }
        Ok(floor)
    }

    fn centre(&self, c: usize, r: usize) -> Point2 {
        [
            self.origin[0] + (c as f64 + 0.5) * SWEPT_CELL,
            self.origin[1] + (r as f64 + 0.5) * SWEPT_CELL,
        ]
    }

    /// Sweeps the floor cells whose centres the disc at `p` covers; returns how
    /// many were not swept before.
    fn sweep(&mut self, p: Point2) -> usize {
        let span = |v: f64, o: f64, n: usize| {
            let lo = ((v - self.radius - o) / SWEPT_CELL).floor().max(0.0) as usize;
            let hi = ((v + self.radius - o) / SWEPT_CELL).ceil().max(0.0) as usize;
            lo..hi.min(n)
        };
        let mut new = 0;
        for r in span(p[1], self.origin[1], self.rows) {
            for c in span(p[0], self.origin[0], self.cols) {
                let k = r * self.cols + c;
                if self.cell[k] == 1 && distance(p, self.centre(c, r)) <= self.radius {
                    self.cell[k] = 2;
                    new += 1;
                }
            }
        }
        new
    }
}

/// Whether the straight step from `a` to `b` crosses a wall or box face.
fn crosses_a_wall(world: &World, a: Point2, b: Point2) -> bool {
    let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
    let d = [b[0] - a[0], b[1] - a[1]];
    let mut hit = false;
    world.near(mid, distance(a, b), |s| {
        hit = hit || ray_segment(a, d, s).is_some_and(|t| t <= 1.0);
    });
    hit
}

/// The painted line a lap follows, its checkpoints and the lap under way.
#[derive(Clone, Debug)]
struct Circuit {
    line: Paint,
    checkpoints: Vec<Point2>,
    /// How near a checkpoint counts: [`CHECKPOINT_RADIUS`], or half the
    /// checkpoints' spacing on a short line.
    radius: f64,
    /// When the lap under way started, the last update's time, and the time
    /// integral and maximum of the distance from the line in it.
    lap_start: f64,
    last: f64,
    sum: f64,
    max: f64,
}

impl Circuit {
    fn new(world: &World, start: Point2, heading: f64) -> Result<Circuit, String> {
        let line = world.paint.iter().find(|p| p.closed).ok_or(
            "the world has no closed painted line; add `paint WIDTH COLOR closed` and its \
             `point X Y` lines to its file",
        )?;
        let length = line.length();
        // Where the line passes nearest the start (arc length), and which way along it
        // the robot faces.
        let (mut at, mut best, mut forward, mut s) = (0.0, f64::INFINITY, true, 0.0);
        for (a, b) in line.segments() {
            let q = closest_on(start, a, b);
            let d = distance(start, q);
            if d < best {
                (best, at) = (d, s + distance(a, q));
                forward = (b[0] - a[0]) * heading.cos() + (b[1] - a[1]) * heading.sin() >= 0.0;
            }
            s += distance(a, b);
        }
        let step = if forward { length } else { -length } / LAP_CHECKPOINTS as f64;
        let checkpoints = (0..LAP_CHECKPOINTS)
            .map(|k| point_at(line, (at + step * k as f64).rem_euclid(length)))
            .collect();
        Ok(Circuit {
            line: line.clone(),
            checkpoints,
            radius: CHECKPOINT_RADIUS.min(length / (2 * LAP_CHECKPOINTS) as f64),
            lap_start: 0.0,
            last: 0.0,
            sum: 0.0,
            max: 0.0,
        })
    }

    fn update(&mut self, l: &mut Laps, p: Point2, time: f64) {
        let d = self.line.distance(p);
        self.sum += d * (time - self.last).max(0.0);
        self.max = self.max.max(d);
        self.last = time;
        l.time = time;
        let next = (l.passed + 1) % self.checkpoints.len();
        if distance(p, self.checkpoints[next]) > self.radius {
            return;
        }
        if next != 0 {
            l.passed += 1;
            return;
        }
        let took = time - self.lap_start;
        l.laps.push(Lap {
            time: took,
            mean: if took > 0.0 { self.sum / took } else { d },
            max: self.max,
        });
        l.passed = 0;
        (self.lap_start, self.sum, self.max) = (time, 0.0, 0.0);
    }
}

/// The point `s` mm along `line` from its first point.
fn point_at(line: &Paint, mut s: f64) -> Point2 {
    for (a, b) in line.segments() {
        let l = distance(a, b);
        if s <= l && l > 0.0 {
            let t = s / l;
            return [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
        }
        s -= l;
    }
    line.points[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> World {
        let mut w = World::new();
        w.add_room([0.0, 0.0], [2000.0, 2000.0], 500.0, [1, 1, 1]);
        w.finish();
        w
    }

    #[test]
    fn the_floor_is_what_the_start_reaches() {
        let mut w = square();
        // A closed 400 mm cell in the corner does not count.
        w.add_room([0.0, 0.0], [400.0, 400.0], 500.0, [1, 1, 1]);
        w.finish();
        let s = Scorer::new(Rule::Swept, &w, [1000.0, 1000.0], 0.0, 250.0).unwrap();
        let Score::Swept(sw) = s.score() else {
            panic!()
        };
        assert_eq!(sw.cells, 100 - 4);
        assert!(
            (4..=5).contains(&sw.swept),
            "its own footprint: {}",
            sw.swept
        );
        assert!(
            s.score().summary().starts_with("swept "),
            "{}",
            s.score().summary()
        );
        let e = Scorer::new(Rule::Swept, &World::new(), [0.0; 2], 0.0, 250.0).unwrap_err();
        assert!(e.contains("no walls"), "{e}");
    }

    #[test]
    fn targets_count_in_order() {
        let mut w = square();
        w.targets = vec![[500.0, 500.0], [1500.0, 1500.0]];
        let mut s = Scorer::new(Rule::Targets, &w, [1500.0, 1500.0], 0.0, 250.0).unwrap();
        assert!(
            matches!(s.score(), Score::Targets(t) if t.reached == 0),
            "not the second first"
        );
        s.update([600.0, 600.0], 2.0);
        s.update([1400.0, 1400.0], 5.5);
        assert_eq!(s.score().summary(), "targets 2 of 2 in 5.5 s");
        let e = Scorer::new(Rule::Targets, &square(), [1.0; 2], 0.0, 250.0).unwrap_err();
        assert!(e.contains("target X Y"), "{e}");
    }

    #[test]
    fn a_lap_passes_every_checkpoint_and_comes_back() {
        let mut w = square();
        let pts = [
            [500.0, 500.0],
            [1500.0, 500.0],
            [1500.0, 1500.0],
            [500.0, 1500.0],
        ];
        w.paint.push(Paint {
            points: pts.to_vec(),
            closed: true,
            width: 40.0,
            color: [220, 20, 20],
        });
        let mut s = Scorer::new(Rule::Lap, &w, [1000.0, 500.0], 0.0, 250.0).unwrap();
        // Back and forth at the start is no lap.
        s.update([1000.0, 505.0], 1.0);
        assert!(matches!(s.score(), Score::Lap(l) if l.laps.is_empty()));
        // Around, 10 mm off the line, 1 s per 100 mm.
        let mut t = 1.0;
        for k in 0..=40 {
            let a = (k as f64 * 100.0 + 500.0) % 4000.0; // arc length from (500, 500)
            let p = point_at(&w.paint[0], a);
            let inward = [1000.0 - p[0], 1000.0 - p[1]];
            let n = inward[0].hypot(inward[1]);
            t += 1.0;
            s.update(
                [p[0] + 10.0 * inward[0] / n, p[1] + 10.0 * inward[1] / n],
                t,
            );
        }
        let Score::Lap(l) = s.score() else { panic!() };
        assert_eq!(l.laps.len(), 1, "{l:?}");
        assert!(l.laps[0].max < 15.0 && l.laps[0].mean > 5.0, "{l:?}");
        assert!(
            s.score().summary().starts_with("lap 1: "),
            "{}",
            s.score().summary()
        );
        let e = Scorer::new(Rule::Lap, &square(), [1.0; 2], 0.0, 250.0).unwrap_err();
        assert!(e.contains("closed painted line"), "{e}");
    }
}
