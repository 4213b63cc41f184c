//! Gradient Path Planning over the world map, and a path follower.
//!
//! 1. [`GridMap::from_world`]: an occupancy grid (default 50 mm cells) with every
//!    wall and box face of a [`World`] drawn into it, and each cell's
//!    clearance (distance to the nearest occupied cell, Euclidean by nearest-seed
//!    propagation).
//! 2. [`Field::new`]: the navigation function. Cells closer to an obstacle than the
//!    robot's radius plus `margin` are forbidden (the obstacles inflated by the
//!    robot); from the goal, Dijkstra over the 8-connected free cells gives each
//!    cell its cost to the goal, where each step costs its length times
//!    `1 + k_clear·((safe − clearance)/safe)²` near obstacles, so paths keep to the
//!    middle of doors and corridors.
//! 3. [`Field::path_from`]: follows the gradient (the cheapest neighbour) from the
//!    robot's cell down to the goal.
//! 4. [`Follower`]: pure pursuit on that path: the carrot is the first path point
//!    `lookahead` mm ahead of the path point nearest the robot, and the robot
//!    steers toward it with VFF's local repulsion from laser points.

use std::{cmp::Reverse, collections::BinaryHeap};

use crate::{
    interfaces::{Encoders, Laser, Motors},
    world::World,
};

use super::vff::{self, Forces, VffParams};

/// Why a plan failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error(
        "the map is empty: no walls (give introrob a `world FILE` line, or load a driver that \
         exports world.map, such as the simulator)"
    )]
    EmptyMap,
    #[error("the goal ({0:.0}, {1:.0}) mm is outside the map")]
    GoalOutside(f32, f32),
    #[error("the goal ({0:.0}, {1:.0}) mm is too close to an obstacle for the robot")]
    GoalBlocked(f32, f32),
    #[error("the robot at ({0:.0}, {1:.0}) mm cannot reach the goal: no free path")]
    Unreachable(f32, f32),
}

/// An occupancy grid with clearances. Cell (i, j) covers
/// [origin.x + i·cell, +cell) × [origin.y + j·cell, +cell).
#[derive(Clone, Debug)]
pub struct GridMap {
    pub origin: [f32; 2],
    pub cell: f32,
    pub width: usize,
    pub height: usize,
    pub occupied: Vec<bool>,
    /// mm from the cell's centre to the nearest occupied cell's centre.
    pub clearance: Vec<f32>,
}

impl GridMap {
    /// The grid of a world's walls and boxes, `cell` mm per cell, with a margin of
    /// one metre around the walls' bounding box. An empty world gives an empty map.
    pub fn from_world(world: &World, cell: f32) -> GridMap {
        let segs: Vec<([f32; 2], [f32; 2])> = world
            .segments
            .iter()
            .map(|s| {
                (
                    [s.a[0] as f32, s.a[1] as f32],
                    [s.b[0] as f32, s.b[1] as f32],
                )
            })
            .collect();
        GridMap::from_segments(&segs, cell)
    }

    /// The grid of these segments (mm).
    pub fn from_segments(segs: &[([f32; 2], [f32; 2])], cell: f32) -> GridMap {
        let cell = if cell.is_finite() && cell >= 5.0 {
            cell
        } else {
            50.0
        };
        let finite = |p: &[f32; 2]| p[0].is_finite() && p[1].is_finite();
        let segs: Vec<_> = segs
            .iter()
            .filter(|(a, b)| finite(a) && finite(b))
            .collect();
        let mut lo = [f32::INFINITY; 2];
        let mut hi = [f32::NEG_INFINITY; 2];
        for (a, b) in &segs {
            for p in [a, b] {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
        }
        if segs.is_empty() {
            return GridMap {
                origin: [0.0, 0.0],
                cell,
                width: 0,
                height: 0,
                occupied: Vec::new(),
                clearance: Vec::new(),
            };
        }
        let margin = 1000.0;
        let origin = [lo[0] - margin, lo[1] - margin];
        // Bound the grid to 2000 x 2000 cells (100 m at 50 mm); farther goals are "outside".
        let cells = |span: f32| ((span + 2.0 * margin) / cell).ceil().clamp(1.0, 2000.0) as usize;
        let (width, height) = (cells(hi[0] - lo[0]), cells(hi[1] - lo[1]));
        let mut map = GridMap {
            origin,
            cell,
            width,
            height,
            occupied: vec![false; width * height],
            clearance: Vec::new(),
        };
        for (a, b) in segs {
            let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            let n = ((len / (cell * 0.25)).ceil() as usize).clamp(1, 1_000_000);
            for k in 0..=n {
                let f = k as f32 / n as f32;
                let p = [a[0] + (b[0] - a[0]) * f, a[1] + (b[1] - a[1]) * f];
                if let Some(i) = map.index(p) {
                    map.occupied[i] = true;
                }
            }
        }
        map.compute_clearance();
        map
    }

    /// The cell index holding world point `p`, if inside.
    pub fn index(&self, p: [f32; 2]) -> Option<usize> {
        let (i, j) = self.cell_of(p)?;
        Some(j * self.width + i)
    }

    /// The (column, row) holding `p`, if inside.
    pub fn cell_of(&self, p: [f32; 2]) -> Option<(usize, usize)> {
        let fi = ((p[0] - self.origin[0]) / self.cell).floor();
        let fj = ((p[1] - self.origin[1]) / self.cell).floor();
        if !(fi >= 0.0 && fj >= 0.0 && fi < self.width as f32 && fj < self.height as f32) {
            return None;
        }
        Some((fi as usize, fj as usize))
    }

    /// The centre of cell index `k`, world mm.
    pub fn center(&self, k: usize) -> [f32; 2] {
        let (i, j) = (k % self.width.max(1), k / self.width.max(1));
        [
            self.origin[0] + (i as f32 + 0.5) * self.cell,
            self.origin[1] + (j as f32 + 0.5) * self.cell,
        ]
    }

    /// The clearance at world point `p` (0 outside the map).
    pub fn clearance_at(&self, p: [f32; 2]) -> f32 {
        self.index(p).map_or(0.0, |k| self.clearance[k])
    }

    /// Nearest-seed propagation (two raster passes): each cell learns the nearest
    /// occupied cell its neighbours know of.
    fn compute_clearance(&mut self) {
        let (w, h) = (self.width as isize, self.height as isize);
        let none = (i32::MIN, i32::MIN);
        let mut seed: Vec<(i32, i32)> = (0..self.width * self.height)
            .map(|k| {
                if self.occupied[k] {
                    ((k % self.width) as i32, (k / self.width) as i32)
                } else {
                    none
                }
            })
            .collect();
        let d2 = |i: isize, j: isize, s: (i32, i32)| -> i64 {
            if s == none {
                i64::MAX
            } else {
                let (dx, dy) = (i as i64 - s.0 as i64, j as i64 - s.1 as i64);
                dx * dx + dy * dy
            }
        };
        let relax = |seed: &mut Vec<(i32, i32)>, i: isize, j: isize, nb: &[(isize, isize)]| {
            let k = (j * w + i) as usize;
            let mut best = d2(i, j, seed[k]);
            for (di, dj) in nb {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni >= w || nj >= h {
                    continue;
                }
                let s = seed[(nj * w + ni) as usize];
                let d = d2(i, j, s);
                if d < best {
                    best = d;
                    seed[k] = s;
                }
            }
        };
        let fwd = [(-1, -1), (0, -1), (1, -1), (-1, 0)];
        let bwd = [(1, 0), (-1, 1), (0, 1), (1, 1)];
        for _ in 0..2 {
            for j in 0..h {
                for i in 0..w {
                    relax(&mut seed, i, j, &fwd);
                }
                for i in (0..w).rev() {
                    relax(&mut seed, i, j, &[(1, 0)]);
                }
            }
            for j in (0..h).rev() {
                for i in (0..w).rev() {
                    relax(&mut seed, i, j, &bwd);
                }
                for i in 0..w {
                    relax(&mut seed, i, j, &[(-1, 0)]);
                }
            }
        }
        let cell = self.cell;
        self.clearance = (0..self.width * self.height)
            .map(|k| {
                let (i, j) = ((k % self.width) as isize, (k / self.width) as isize);
                let d = d2(i, j, seed[k]);
                if d == i64::MAX {
                    f32::INFINITY
                } else {
                    (d as f32).sqrt() * cell
                }
            })
            .collect();
    }
}

/// Planner tuning, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanParams {
    /// Robot radius.
    pub radius: f32,
    /// Extra clearance required beyond the radius (the obstacles are inflated by
    /// radius + margin; the clearance is measured between cell centres).
    pub margin: f32,
    /// Below this clearance, steps cost more.
    pub safe: f32,
    /// How much more (at zero clearance).
    pub k_clear: f32,
}

impl Default for PlanParams {
    fn default() -> Self {
        PlanParams {
            radius: 250.0,
            margin: 80.0,
            safe: 900.0,
            k_clear: 6.0,
        }
    }
}

/// The navigation function toward one goal: each cell's cost to reach it.
#[derive(Clone, Debug)]
pub struct Field {
    pub goal: [f32; 2],
    /// Cost to the goal (mm-equivalent); infinite where forbidden or unreachable.
    pub cost: Vec<f32>,
}

const NEIGHBOURS: [(isize, isize, f32); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, std::f32::consts::SQRT_2),
    (1, -1, std::f32::consts::SQRT_2),
    (-1, 1, std::f32::consts::SQRT_2),
    (-1, -1, std::f32::consts::SQRT_2),
];

impl Field {
    /// Dijkstra from `goal` over the map's free cells.
    pub fn new(map: &GridMap, goal: [f32; 2], p: &PlanParams) -> Result<Field, PlanError> {
        if map.width == 0 || map.height == 0 {
            return Err(PlanError::EmptyMap);
        }
        let g = map
            .index(goal)
            .ok_or(PlanError::GoalOutside(goal[0], goal[1]))?;
        let min_clear = p.radius + p.margin;
        if map.clearance[g] < min_clear {
            return Err(PlanError::GoalBlocked(goal[0], goal[1]));
        }
        let n = map.width * map.height;
        let mut cost = vec![f32::INFINITY; n];
        let mut heap = BinaryHeap::new();
        cost[g] = 0.0;
        heap.push(Reverse((0f32.to_bits(), g)));
        let (w, h) = (map.width as isize, map.height as isize);
        let safe = p.safe.max(1.0);
        while let Some(Reverse((bits, k))) = heap.pop() {
            let c = f32::from_bits(bits);
            if c > cost[k] {
                continue;
            }
            let (i, j) = ((k % map.width) as isize, (k / map.width) as isize);
            for (di, dj, len) in NEIGHBOURS {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni >= w || nj >= h {
                    continue;
                }
                let nk = (nj * w + ni) as usize;
                let clear = map.clearance[nk];
                if clear < min_clear {
                    continue;
                }
                let near = ((safe - clear) / safe).max(0.0);
                let step = len * map.cell * (1.0 + p.k_clear * near * near);
                let nc = c + step;
                if nc < cost[nk] {
                    cost[nk] = nc;
                    heap.push(Reverse((nc.to_bits(), nk)));
                }
            }
        }
        Ok(Field { goal, cost })
    }

    /// The path from `start` down the gradient to the goal (world mm, starting at
    /// `start` and ending at the goal). A start inside the inflated obstacles
    /// joins the nearest reachable cell within a metre.
    pub fn path_from(&self, map: &GridMap, start: [f32; 2]) -> Result<Vec<[f32; 2]>, PlanError> {
        let unreachable = PlanError::Unreachable(start[0], start[1]);
        let s = map.index(start).ok_or(unreachable.clone())?;
        let mut k = if self.cost[s].is_finite() {
            s
        } else {
            // The nearest cell with a finite cost, within 1 m.
            let reach = (1000.0 / map.cell).ceil() as isize;
            let (si, sj) = ((s % map.width) as isize, (s / map.width) as isize);
            let mut best: Option<(f32, usize)> = None;
            for dj in -reach..=reach {
                for di in -reach..=reach {
                    let (i, j) = (si + di, sj + dj);
                    if i < 0 || j < 0 || i >= map.width as isize || j >= map.height as isize {
                        continue;
                    }
                    let nk = j as usize * map.width + i as usize;
                    let d = ((di * di + dj * dj) as f32).sqrt();
                    if self.cost[nk].is_finite() && best.is_none_or(|(b, _)| d < b) {
                        best = Some((d, nk));
                    }
                }
            }
            best.ok_or(unreachable.clone())?.1
        };
        let mut path = vec![start, map.center(k)];
        let (w, h) = (map.width as isize, map.height as isize);
        for _ in 0..map.width * map.height {
            if self.cost[k] <= 0.0 {
                break;
            }
            let (i, j) = ((k % map.width) as isize, (k / map.width) as isize);
            let mut next = k;
            for (di, dj, _) in NEIGHBOURS {
                let (ni, nj) = (i + di, j + dj);
                if ni < 0 || nj < 0 || ni >= w || nj >= h {
                    continue;
                }
                let nk = (nj * w + ni) as usize;
                if self.cost[nk] < self.cost[next] {
                    next = nk;
                }
            }
            if next == k {
                return Err(unreachable);
            }
            k = next;
            path.push(map.center(k));
        }
        path.push(self.goal);
        Ok(path)
    }
}

/// Plans a path from `start` to `goal` (world mm) over `map`.
pub fn plan(
    map: &GridMap,
    start: [f32; 2],
    goal: [f32; 2],
    p: &PlanParams,
) -> Result<Vec<[f32; 2]>, PlanError> {
    Field::new(map, goal, p)?.path_from(map, start)
}

/// Follows a path with pure pursuit and local VFF repulsion.
#[derive(Clone, Debug, Default)]
pub struct Follower {
    pub path: Vec<[f32; 2]>,
    /// Index of the path point nearest the robot so far (progress only grows).
    pub progress: usize,
    /// Carrot distance ahead along the path, mm.
    pub lookahead: f32,
}

/// One follower step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FollowOutput {
    pub motors: Motors,
    pub carrot: [f32; 2],
    pub forces: Forces,
    /// The end of the path is reached.
    pub done: bool,
    /// The robot is more than a metre from the path: plan again.
    pub lost: bool,
}

fn dist(a: [f32; 2], b: [f32; 2]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

impl Follower {
    pub fn new(path: Vec<[f32; 2]>, lookahead: f32) -> Follower {
        Follower {
            path,
            progress: 0,
            lookahead,
        }
    }

    /// One step from `pose` with this scan. `p` tunes the steering (max speeds,
    /// arrival); the local repulsion is a gentler VFF than free navigation.
    pub fn step(&mut self, pose: &Encoders, laser: &Laser, p: &VffParams) -> FollowOutput {
        let Some(&goal) = self.path.last() else {
            return FollowOutput {
                done: true,
                ..Default::default()
            };
        };
        let here = [pose.x, pose.y];
        // Progress: the nearest point within the next 2 m of path.
        let mut best = (
            dist(here, self.path[self.progress.min(self.path.len() - 1)]),
            self.progress,
        );
        let mut along = 0.0;
        for k in self.progress + 1..self.path.len() {
            along += dist(self.path[k - 1], self.path[k]);
            if along > 2000.0 {
                break;
            }
            let d = dist(here, self.path[k]);
            if d < best.0 {
                best = (d, k);
            }
        }
        self.progress = best.1.min(self.path.len() - 1);
        let lost = best.0 > 1000.0;
        let mut carrot = goal;
        for k in self.progress..self.path.len() {
            if dist(here, self.path[k]) >= self.lookahead {
                carrot = self.path[k];
                break;
            }
        }
        let to_goal = dist(here, goal);
        if to_goal < p.arrive {
            return FollowOutput {
                carrot,
                done: true,
                lost,
                ..Default::default()
            };
        }
        let local = VffParams {
            influence: 450.0,
            k_rep: 0.6,
            ..*p
        };
        let f = vff::forces(pose, laser, carrot, &local);
        // Remaining distance along the path, for slowing down at the end.
        let remaining = to_goal.min(
            self.path[self.progress..]
                .windows(2)
                .map(|w| dist(w[0], w[1]))
                .sum::<f32>()
                + best.0,
        );
        FollowOutput {
            motors: vff::steer(f.resultant, remaining, laser, &local),
            carrot,
            forces: f,
            done: false,
            lost,
        }
    }
}
