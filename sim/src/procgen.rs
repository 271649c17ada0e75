//! Procedural buildings: random floor plans with furniture, glass, people, looks, a start and
//! goals, made from a seed, so demonstrations can be recorded in many buildings and evaluation
//! can use buildings that training never saw.
//!
//! [`building`] turns a seed into a [`Building`]: the crude floor plan (what the planner gets),
//! the same plan as the occupancy grid [`crate::World::new`] takes (identical to what loading the
//! written ROS map gives), and a [`Scenario`] with everything the plan lacks. One seed gives one
//! building, byte for byte (ChaCha8 streams seeded from it); `sim gen-building` writes them
//! ([`generate`]).
//!
//! - **Families**, chosen by the seed: *offices* (one to three parallel corridors with rooms on
//!   both sides, cross corridors, sometimes a lobby), *corridor networks* (a random spanning tree
//!   plus loops on a grid of corridors, so T, + and L junctions and dead ends, rooms in the
//!   blocks), *halls* (large open rooms with pillar grids or free-standing partitions, often a side
//!   corridor of rooms) and *mixtures* of two of these side by side.
//! - **Plans**: 20–45 m a side at 0.05 m per cell, interior walls 0.2–0.4 m, corridors at least
//!   1.5 m wide (mostly 1.8–2.5 m), doors 1.2–1.6 m (at least 1.1 m where a wall is short;
//!   openings from halls 1.2–4 m), doors a metre of wall apart, pillars at least 2.7 m apart;
//!   all free cells form one connected region.
//! - **Ground truth**: unmapped furniture (desks, shelves, tables, crates, corridor benches and
//!   cabinets), glass (doors across corridors leaving an opening of at least 1.1 m, free-standing
//!   screens in halls), walking people and a look per building and per room. Every box or pane
//!   stands flush against a wall or leaves at least 1.1 m to walls and to every other one, keeps
//!   1 m clear of doors and 0.5 m of junctions, and a check on the rasterized ground truth keeps
//!   every room, hall and corridor connected through passages a 0.25 m robot passes with 0.2 m to
//!   spare (items are dropped until it holds).
//! - **Task**: a start and 2–4 goals, each at least 4 m from the previous point, 0.5 m clear of
//!   walls, furniture and glass, reachable in the ground truth; the time limit is twice the
//!   shortest path at 0.3 m/s plus 60 s.
//! - **Roles**: seeds below [`EVALUATION_SEED_BASE`] are training buildings (`gen_000123`);
//!   seeds from it up are evaluation buildings (`gen_eval_1000004`) that no recording may use
//!   (the recorder refuses them by role).

use std::collections::VecDeque;
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::{Path, PathBuf};

use map_core::search::NEIGHBOURS_8;
use map_core::{DistanceField, OccupancyGrid, Sources};
use rand::seq::{IteratorRandom, SliceRandom};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::config::SimConfig;
use crate::geom::Obb;
use crate::mapgen::{Plan, RESOLUTION_M};
use crate::scenario::{
    AppearanceSpec, AreaSpec, BoxSpec, FloorTexture, GlassSpec, Look, PersonSpec, PointSpec,
    PoseSpec, Rgb, Role, RouteMode, Scenario, WallTexture,
};
use crate::world::{rasterize_shapes, World};

/// Seeds from here up make evaluation buildings; seeds below it training buildings.
pub const EVALUATION_SEED_BASE: u64 = 1_000_000;

/// Attempts (independent random streams of one seed) before a seed is given up.
const MAX_ATTEMPTS: u64 = 24;
/// The solid margin around every building, in decimetres.
const OUTER_WALL_DM: Dm = 5;
/// Free gap kept between a box or pane and any wall or other box or pane it is not flush with.
const PASSAGE_M: f64 = 1.1;
/// A box this close to a wall stands flush against it.
const FLUSH_M: f64 = 0.15;
/// Gap between a flush box and its wall.
const FLUSH_GAP_M: f64 = 0.05;
/// Nothing is placed this close to a door or a corridor's mouth.
const DOOR_KEEP_OUT_M: f64 = 1.0;
/// Nothing is placed this close to a corridor junction.
const JUNCTION_KEEP_OUT_M: f64 = 0.5;
/// Nothing is placed this close to a space's anchor (its most open point).
const ANCHOR_KEEP_OUT_M: f64 = 0.6;
/// Robot radius plus 0.2 m: the clearance of the "wide" passages every space must stay connected
/// through, and that start and goals are reached through.
const WIDE_MARGIN_M: f64 = 0.2;
/// Start and goals lie at least this far from walls, furniture and glass.
const POINT_CLEARANCE_M: f64 = 0.5;
/// Each goal lies at least this far (straight line) from the previous point.
const MIN_GOAL_SPACING_M: f64 = 4.0;
/// The slow speed the time limit allows for: twice the shortest path at it, plus a minute.
const TIME_LIMIT_SPEED_MPS: f64 = 0.3;
/// The most furniture a building gets: one box per this much plan area, at most
/// [`MAX_FURNITURE`].
const AREA_PER_BOX_M2: f64 = 40.0;
const MAX_FURNITURE: usize = 30;

/// The kind of layout a building has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Family {
    /// Rooms off one to three parallel corridors, cross corridors, sometimes a lobby.
    Office,
    /// A grid of corridors thinned to a random spanning tree plus loops, rooms in the blocks.
    Corridors,
    /// Large open halls with pillars or partitions, often a side corridor of rooms.
    Hall,
    /// Two of the others side by side, joined through their shared wall.
    Mixed,
}

impl Family {
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Office => "office",
            Self::Corridors => "corridors",
            Self::Hall => "hall",
            Self::Mixed => "mixed",
        }
    }
}

impl std::fmt::Display for Family {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A generated building: the plan, the same plan as a grid, and the scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Building {
    /// The crude floor plan, named like the scenario.
    pub plan: Plan,
    /// The plan as [`crate::World::new`] takes it; identical to loading the written ROS map.
    pub grid: OccupancyGrid,
    /// Start, goals, furniture, glass, people and looks; `floor_plan` is `maps/<name>.yaml`.
    pub scenario: Scenario,
    pub family: Family,
}

impl Building {
    /// Fraction of the plan's cells that are free floor.
    #[must_use]
    pub fn free_fraction(&self) -> f64 {
        let free = self.plan.wall.iter().filter(|&&w| !w).count();
        free as f64 / self.plan.wall.len().max(1) as f64
    }

    /// One line for people: name, role, family, size and contents.
    #[must_use]
    pub fn summary(&self) -> String {
        let s = &self.scenario;
        format!(
            "{} ({}): {} {:.1} m x {:.1} m, {:.0}% free, {} goals, {} boxes, {} panes, {} people, \
             time limit {:.0} s",
            s.name,
            match s.role {
                Role::Training => "training",
                Role::Evaluation => "evaluation",
                Role::Behaviour => "behaviour",
            },
            self.family,
            self.plan.width as f64 * RESOLUTION_M,
            self.plan.height as f64 * RESOLUTION_M,
            100.0 * self.free_fraction(),
            s.goals.len(),
            s.furniture.len(),
            s.glass.len(),
            s.people.len(),
            s.time_limit_s
        )
    }
}

/// Why a building could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum ProcgenError {
    #[error("no valid building for seed {seed} in {attempts} attempts; last problem: {reason}")]
    NoBuilding {
        seed: u64,
        attempts: u64,
        reason: String,
    },
    #[error("seeds {first}..+{count} run past the largest seed")]
    SeedRange { first: u64, count: u64 },
    #[error("floor plan {name} is not a valid grid: {source}")]
    Grid {
        name: String,
        #[source]
        source: map_core::MapError,
    },
    #[error("building {name} does not make a world: {source}")]
    World {
        name: String,
        #[source]
        source: Box<crate::SimError>,
    },
    #[error("cannot serialize scenario {name}: {reason}")]
    Yaml { name: String, reason: String },
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write picture {path}: {reason}")]
    Picture { path: PathBuf, reason: String },
}

/// The role of the building a seed makes: evaluation from [`EVALUATION_SEED_BASE`] up.
#[must_use]
pub fn role_of_seed(seed: u64) -> Role {
    if seed >= EVALUATION_SEED_BASE {
        Role::Evaluation
    } else {
        Role::Training
    }
}

/// The scenario (and map) name of a seed: `gen_000123`, or `gen_eval_1000004` for evaluation.
#[must_use]
pub fn building_name(seed: u64) -> String {
    match role_of_seed(seed) {
        Role::Evaluation => format!("gen_eval_{seed}"),
        _ => format!("gen_{seed:06}"),
    }
}

/// The scenario seed (sensor noise, appearance jitter) derived from a building seed; below 2^48
/// so it survives any JSON reader.
#[must_use]
pub fn scenario_seed(seed: u64) -> u64 {
    // SplitMix64's finalizer.
    let mut z = seed ^ 0x5EED_B1D6_0000_0000;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) >> 16
}

/// Makes the building of `seed`.
///
/// # Errors
/// [`ProcgenError::NoBuilding`] if no attempt gives a valid building (not seen in practice), or
/// [`ProcgenError::Grid`] if the plan cannot become a grid.
pub fn building(seed: u64) -> Result<Building, ProcgenError> {
    let mut last = String::new();
    for attempt in 0..MAX_ATTEMPTS {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(attempt);
        match attempt_building(seed, &mut rng) {
            Ok(b) => return Ok(b),
            Err(Failure::Retry(reason)) => last = reason,
            Err(Failure::Fatal(e)) => return Err(e),
        }
    }
    Err(ProcgenError::NoBuilding {
        seed,
        attempts: MAX_ATTEMPTS,
        reason: last,
    })
}

enum Failure {
    /// This random stream gave no valid building; try the next.
    Retry(String),
    Fatal(ProcgenError),
}

impl From<String> for Failure {
    fn from(reason: String) -> Self {
        Self::Retry(reason)
    }
}

impl From<&str> for Failure {
    fn from(reason: &str) -> Self {
        Self::Retry(reason.to_string())
    }
}

// ---------------------------------------------------------------------------------------------
// Geometry: layouts in whole decimetres (exact), everything placed later in metres.

/// Decimetres.
type Dm = i32;

fn m(v: Dm) -> f64 {
    f64::from(v) / 10.0
}

fn round_mm(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn round_to(v: f64, step: f64) -> f64 {
    round_mm((v / step).round() * step)
}

fn pick(rng: &mut ChaCha8Rng, lo: Dm, hi: Dm) -> Dm {
    if hi <= lo {
        lo
    } else {
        rng.gen_range(lo..=hi)
    }
}

fn pick_f(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    if hi <= lo {
        lo
    } else {
        rng.gen_range(lo..hi)
    }
}

fn pick_of<T: Copy>(rng: &mut ChaCha8Rng, items: &[T], fallback: T) -> T {
    items.choose(rng).copied().unwrap_or(fallback)
}

/// An axis-aligned rectangle in decimetres.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct DRect {
    x0: Dm,
    y0: Dm,
    x1: Dm,
    y1: Dm,
}

impl DRect {
    fn new(x0: Dm, y0: Dm, x1: Dm, y1: Dm) -> Self {
        Self {
            x0: x0.min(x1),
            y0: y0.min(y1),
            x1: x0.max(x1),
            y1: y0.max(y1),
        }
    }

    fn w(self) -> Dm {
        self.x1 - self.x0
    }

    fn h(self) -> Dm {
        self.y1 - self.y0
    }

    fn grow(self, d: Dm) -> Self {
        Self::new(self.x0 - d, self.y0 - d, self.x1 + d, self.y1 + d)
    }

    fn overlaps(self, o: Self) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }

    fn transposed(self) -> Self {
        Self::new(self.y0, self.x0, self.y1, self.x1)
    }

    fn metres(self) -> Rect {
        Rect {
            x0: m(self.x0),
            y0: m(self.y0),
            x1: m(self.x1),
            y1: m(self.y1),
        }
    }
}

/// An axis-aligned rectangle in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Rect {
    fn centred(cx: f64, cy: f64, hx: f64, hy: f64) -> Self {
        Self {
            x0: cx - hx,
            y0: cy - hy,
            x1: cx + hx,
            y1: cy + hy,
        }
    }

    fn w(self) -> f64 {
        self.x1 - self.x0
    }

    fn h(self) -> f64 {
        self.y1 - self.y0
    }

    fn grow(self, d: f64) -> Self {
        Self {
            x0: self.x0 - d,
            y0: self.y0 - d,
            x1: self.x1 + d,
            y1: self.y1 + d,
        }
    }

    fn overlaps(self, o: Self) -> bool {
        self.x0 < o.x1 && o.x0 < self.x1 && self.y0 < o.y1 && o.y0 < self.y1
    }

    /// Distance between the two rectangles (0 when they overlap).
    fn gap(self, o: Self) -> f64 {
        let dx = (o.x0 - self.x1).max(self.x0 - o.x1).max(0.0);
        let dy = (o.y0 - self.y1).max(self.y0 - o.y1).max(0.0);
        dx.hypot(dy)
    }

    fn point_gap(self, x: f64, y: f64) -> f64 {
        self.gap(Self {
            x0: x,
            y0: y,
            x1: x,
            y1: y,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Layouts.

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Corridor,
    Room,
    Hall,
}

#[derive(Debug, Clone, Copy)]
struct Space {
    rect: DRect,
    kind: Kind,
}

/// What a family draws: spaces to carve, openings through walls, blocks to fill.
#[derive(Debug, Clone, Default)]
struct Layout {
    spaces: Vec<Space>,
    /// Free rectangles carved besides the spaces (corridor crossings).
    extra: Vec<DRect>,
    /// Openings through walls: doors, corridor mouths, openings between halls.
    doors: Vec<DRect>,
    /// Corridor crossings and corners.
    junctions: Vec<DRect>,
    /// Wall blocks filled after carving: pillars, free-standing partitions.
    solids: Vec<DRect>,
}

impl Layout {
    fn space(&mut self, rect: DRect, kind: Kind) {
        self.spaces.push(Space { rect, kind });
    }

    /// A door of about `width` through the wall between `a` and `b`, if they face each other
    /// across exactly `wall`; clear of junctions and other doors.
    fn add_door(&mut self, rng: &mut ChaCha8Rng, a: DRect, b: DRect, wall: Dm, width: Dm) -> bool {
        match door_between(rng, a, b, wall, width, &self.junctions, &self.doors) {
            Some(d) => {
                self.doors.push(d);
                true
            }
            None => false,
        }
    }

    fn transpose(&mut self) {
        for s in &mut self.spaces {
            s.rect = s.rect.transposed();
        }
        for list in [
            &mut self.extra,
            &mut self.doors,
            &mut self.junctions,
            &mut self.solids,
        ] {
            for r in list.iter_mut() {
                *r = r.transposed();
            }
        }
    }
}

/// Door margin from a room's corner, decimetres.
const DOOR_MARGIN_DM: Dm = 3;
const MIN_DOOR_DM: Dm = 11;

fn door_between(
    rng: &mut ChaCha8Rng,
    a: DRect,
    b: DRect,
    wall: Dm,
    width: Dm,
    junctions: &[DRect],
    doors: &[DRect],
) -> Option<DRect> {
    // (door runs along x, shared stretch lo..hi, wall from c0 to c1 across)
    let (along_x, lo, hi, c0, c1) = if b.y0 == a.y1 + wall {
        (true, a.x0.max(b.x0), a.x1.min(b.x1), a.y1, b.y0)
    } else if a.y0 == b.y1 + wall {
        (true, a.x0.max(b.x0), a.x1.min(b.x1), b.y1, a.y0)
    } else if b.x0 == a.x1 + wall {
        (false, a.y0.max(b.y0), a.y1.min(b.y1), a.x1, b.x0)
    } else if a.x0 == b.x1 + wall {
        (false, a.y0.max(b.y0), a.y1.min(b.y1), b.x1, a.x0)
    } else {
        return None;
    };
    let (lo, hi) = (lo + DOOR_MARGIN_DM, hi - DOOR_MARGIN_DM);
    let width = width.min(hi - lo);
    if width < MIN_DOOR_DM {
        return None;
    }
    for _ in 0..12 {
        let p = pick(rng, lo, hi - width);
        let d = if along_x {
            DRect::new(p, c0, p + width, c1)
        } else {
            DRect::new(c0, p, c1, p + width)
        };
        // Doors keep a metre of wall between them.
        let clear = |list: &[DRect], margin: Dm| list.iter().all(|o| !d.grow(margin).overlaps(*o));
        if clear(junctions, DOOR_MARGIN_DM) && clear(doors, 10) {
            return Some(d);
        }
    }
    None
}

fn corridor_width(rng: &mut ChaCha8Rng) -> Dm {
    if rng.gen_bool(0.15) {
        pick(rng, 15, 17)
    } else {
        pick(rng, 18, 25)
    }
}

fn door_width(rng: &mut ChaCha8Rng) -> Dm {
    pick(rng, 12, 16)
}

/// Splits `s0..s1` into rooms of about `target` decimetres with walls between; none below `min`.
fn partition(
    rng: &mut ChaCha8Rng,
    s0: Dm,
    s1: Dm,
    wall: Dm,
    min: Dm,
    target: (Dm, Dm),
) -> Vec<(Dm, Dm)> {
    let len = s1 - s0;
    if len < min {
        return Vec::new();
    }
    let t = pick(rng, target.0, target.1);
    let k = ((len + wall) / (t + wall)).max(1);
    let base = (len - (k - 1) * wall) / k;
    let starts: Vec<Dm> = (0..k)
        .map(|j| {
            let jitter = if j == 0 {
                0
            } else {
                pick(rng, -base / 6, base / 6)
            };
            s0 + j * (base + wall) + jitter
        })
        .collect();
    (0..k as usize)
        .map(|j| {
            let end = starts.get(j + 1).map_or(s1, |next| next - wall);
            (starts[j], end)
        })
        .filter(|&(a, b)| b - a >= min)
        .collect()
}

/// Rooms off parallel corridors running along x, bands of rooms between them.
fn office(rng: &mut ChaCha8Rng, region: DRect, wall: Dm, lay: &mut Layout) -> Result<(), String> {
    let h = region.h();
    let mut n: Dm = 1;
    let mut widths: Vec<Dm>;
    loop {
        widths = (0..n).map(|_| corridor_width(rng)).collect();
        let avail = h - widths.iter().sum::<Dm>() - 2 * n * wall;
        if n == 3 || avail / (n + 1) <= 90 {
            break;
        }
        n += 1;
    }
    let avail = h - widths.iter().sum::<Dm>() - 2 * n * wall;
    let base = avail / (n + 1);
    if base < 30 {
        return Err(format!("office region {h} dm high is too low"));
    }
    let mut bands = Vec::new();
    let mut corrs = Vec::new();
    let mut y = region.y0;
    let mut left = avail;
    for i in 0..=n {
        let d = if i == n {
            left
        } else {
            base + pick(rng, -base / 6, base / 6)
        };
        left -= d;
        bands.push((y, y + d));
        y += d;
        if let Some(&cw) = widths.get(i as usize) {
            y += wall;
            corrs.push((y, y + cw));
            y += cw + wall;
        }
    }
    let lobby =
        (region.w() >= 220 && rng.gen_bool(0.45)).then(|| (rng.gen_bool(0.5), pick(rng, 50, 90)));
    let (bx0, bx1, cx0, cx1) = match lobby {
        None => (region.x0, region.x1, region.x0, region.x1),
        Some((true, lw)) => (region.x0, region.x1 - lw - wall, region.x0, region.x1 - lw),
        Some((false, lw)) => (region.x0 + lw + wall, region.x1, region.x0 + lw, region.x1),
    };
    let corridors: Vec<DRect> = corrs
        .iter()
        .map(|&(y0, y1)| DRect::new(cx0, y0, cx1, y1))
        .collect();
    for c in &corridors {
        lay.space(*c, Kind::Corridor);
    }
    let lobby_rect = lobby.map(|(right, lw)| {
        if right {
            DRect::new(region.x1 - lw, region.y0, region.x1, region.y1)
        } else {
            DRect::new(region.x0, region.y0, region.x0 + lw, region.y1)
        }
    });
    if let Some(l) = lobby_rect {
        lay.space(l, Kind::Hall);
        for c in &corridors {
            let mouth = if l.x0 > c.x0 {
                DRect::new(l.x0 - wall, c.y0, l.x0, c.y1)
            } else {
                DRect::new(l.x1, c.y0, l.x1 + wall, c.y1)
            };
            lay.doors.push(mouth);
        }
    }
    // Cross corridors join the parallel ones (needed without a lobby) or branch off as stubs.
    let need_cross = n >= 2 && lobby.is_none();
    let want_cross = need_cross || rng.gen_bool(if n >= 2 { 0.4 } else { 0.5 });
    let mut crosses: Vec<DRect> = Vec::new();
    if want_cross {
        let count = if bx1 - bx0 > 260 && rng.gen_bool(0.5) {
            2
        } else {
            1
        };
        for _ in 0..count {
            let ccw = corridor_width(rng);
            let (lo, hi) = (bx0 + 30 + wall, bx1 - 30 - wall - ccw);
            if hi < lo {
                break;
            }
            for _ in 0..20 {
                let xc = pick(rng, lo, hi);
                if crosses
                    .iter()
                    .all(|c| xc >= c.x1 + 60 || xc + ccw + 60 <= c.x0)
                {
                    let (first, last) = (corridors[0], corridors[corridors.len() - 1]);
                    let (mut ylo, mut yhi) = (first.y0, last.y1);
                    if n == 1 {
                        if rng.gen_bool(0.5) {
                            ylo = region.y0;
                        } else {
                            yhi = region.y1;
                        }
                    } else {
                        if rng.gen_bool(0.3) {
                            ylo = region.y0;
                        }
                        if rng.gen_bool(0.3) {
                            yhi = region.y1;
                        }
                    }
                    crosses.push(DRect::new(xc, ylo, xc + ccw, yhi));
                    break;
                }
            }
        }
    }
    if need_cross && crosses.is_empty() {
        return Err("office corridors cannot be joined".into());
    }
    for c in &crosses {
        lay.space(*c, Kind::Corridor);
        for r in &corridors {
            if c.y0 <= r.y0 && c.y1 >= r.y1 {
                lay.junctions.push(DRect::new(c.x0, r.y0, c.x1, r.y1));
            }
        }
    }
    let all_corridors: Vec<DRect> = corridors.iter().chain(&crosses).copied().collect();
    for &(y0, y1) in &bands {
        let mut cuts: Vec<(Dm, Dm)> = crosses
            .iter()
            .filter(|c| c.y0 <= y0 && c.y1 >= y1)
            .map(|c| (c.x0 - wall, c.x1 + wall))
            .collect();
        cuts.sort_unstable();
        let mut segments = Vec::new();
        let mut s = bx0;
        for (a, b) in cuts {
            segments.push((s, a));
            s = b;
        }
        segments.push((s, bx1));
        for (s0, s1) in segments {
            let mut prev: Option<DRect> = None;
            for (rx0, rx1) in partition(rng, s0, s1, wall, 25, (40, 65)) {
                let room = DRect::new(rx0, y0, rx1, y1);
                let want = if rng.gen_bool(0.3) { 2 } else { 1 };
                let mut doors = 0;
                let mut candidates = all_corridors.clone();
                candidates.shuffle(rng);
                for c in candidates {
                    if doors >= want {
                        break;
                    }
                    let width = door_width(rng);
                    if lay.add_door(rng, room, c, wall, width) {
                        doors += 1;
                    }
                }
                if let Some(l) = lobby_rect {
                    let width = door_width(rng);
                    if rng.gen_bool(0.35) && lay.add_door(rng, room, l, wall, width) {
                        doors += 1;
                    }
                }
                if let Some(p) = prev {
                    let width = door_width(rng);
                    if (doors == 0 || rng.gen_bool(0.2)) && lay.add_door(rng, room, p, wall, width)
                    {
                        doors += 1;
                    }
                }
                if doors > 0 {
                    lay.space(room, Kind::Room);
                    prev = Some(room);
                } else {
                    prev = None;
                }
            }
        }
    }
    Ok(())
}

/// Corridor centre lines across `lo..lo + len`: (low edge, high edge) of each of `n` lines.
fn corridor_lines(rng: &mut ChaCha8Rng, lo: Dm, len: Dm, n: usize) -> Vec<(Dm, Dm)> {
    let slot = len / n as Dm;
    (0..n as Dm)
        .map(|i| {
            let cw = corridor_width(rng);
            let c = lo + slot * i + slot / 2 + pick(rng, -slot / 8, slot / 8);
            (c - cw / 2, c - cw / 2 + cw)
        })
        .collect()
}

fn find_root(parent: &mut [usize], mut i: usize) -> usize {
    while parent[i] != i {
        parent[i] = parent[parent[i]];
        i = parent[i];
    }
    i
}

/// A grid of corridors thinned to a random spanning tree plus loops; rooms in the blocks.
/// `entrance`: a corridor is led to the region's right (`Some(true)`) or left edge.
fn corridor_net(
    rng: &mut ChaCha8Rng,
    region: DRect,
    wall: Dm,
    entrance: Option<bool>,
    lay: &mut Layout,
) -> Result<(), String> {
    let (w, h) = (region.w(), region.h());
    let mut nx = usize::try_from((w / pick(rng, 65, 100)).clamp(1, 5)).unwrap_or(1);
    let mut ny = usize::try_from((h / pick(rng, 65, 100)).clamp(1, 5)).unwrap_or(1);
    while nx * ny < 3 {
        if w >= h && w / (nx as Dm + 1) >= 60 {
            nx += 1;
        } else if h / (ny as Dm + 1) >= 60 {
            ny += 1;
        } else {
            return Err("region too small for a corridor network".into());
        }
    }
    let xs = corridor_lines(rng, region.x0, w, nx);
    let ys = corridor_lines(rng, region.y0, h, ny);
    let idx = |i: usize, j: usize| j * nx + i;
    let mut edges: Vec<(usize, usize, bool)> = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            if i + 1 < nx {
                edges.push((idx(i, j), idx(i + 1, j), true));
            }
            if j + 1 < ny {
                edges.push((idx(i, j), idx(i, j + 1), false));
            }
        }
    }
    edges.shuffle(rng);
    let mut parent: Vec<usize> = (0..nx * ny).collect();
    let p_loop = pick_f(rng, 0.15, 0.6);
    // Per node: east, west, north, south.
    let mut dirs = vec![[false; 4]; nx * ny];
    let mut corridors: Vec<DRect> = Vec::new();
    for (a, b, horizontal) in edges {
        let (ra, rb) = (find_root(&mut parent, a), find_root(&mut parent, b));
        let keep = if ra == rb {
            rng.gen_bool(p_loop)
        } else {
            parent[ra] = rb;
            true
        };
        if !keep {
            continue;
        }
        let (i, j) = (a % nx, a / nx);
        let (full, segment) = if horizontal {
            dirs[a][0] = true;
            dirs[b][1] = true;
            (
                DRect::new(xs[i].0, ys[j].0, xs[i + 1].1, ys[j].1),
                DRect::new(xs[i].1, ys[j].0, xs[i + 1].0, ys[j].1),
            )
        } else {
            dirs[a][2] = true;
            dirs[b][3] = true;
            (
                DRect::new(xs[i].0, ys[j].0, xs[i].1, ys[j + 1].1),
                DRect::new(xs[i].0, ys[j].1, xs[i].1, ys[j + 1].0),
            )
        };
        lay.extra.push(full);
        corridors.push(segment);
    }
    // Stubs: dead ends towards the outer walls, and the entrance of a mixed building.
    let entrance_row = pick(rng, 0, ny as Dm - 1) as usize;
    for j in 0..ny {
        let forced_right = entrance == Some(true) && j == entrance_row;
        let forced_left = entrance == Some(false) && j == entrance_row;
        if (forced_right || rng.gen_bool(0.2)) && region.x1 - xs[nx - 1].1 >= 20 {
            corridors.push(DRect::new(xs[nx - 1].1, ys[j].0, region.x1, ys[j].1));
            dirs[idx(nx - 1, j)][0] = true;
        }
        if (forced_left || rng.gen_bool(0.2)) && xs[0].0 - region.x0 >= 20 {
            corridors.push(DRect::new(region.x0, ys[j].0, xs[0].0, ys[j].1));
            dirs[idx(0, j)][1] = true;
        }
    }
    for i in 0..nx {
        if rng.gen_bool(0.2) && region.y1 - ys[ny - 1].1 >= 20 {
            corridors.push(DRect::new(xs[i].0, ys[ny - 1].1, xs[i].1, region.y1));
            dirs[idx(i, ny - 1)][2] = true;
        }
        if rng.gen_bool(0.2) && ys[0].0 - region.y0 >= 20 {
            corridors.push(DRect::new(xs[i].0, region.y0, xs[i].1, ys[0].0));
            dirs[idx(i, 0)][3] = true;
        }
    }
    for j in 0..ny {
        for i in 0..nx {
            let [e, wst, n, s] = dirs[idx(i, j)];
            let count = [e, wst, n, s].iter().filter(|&&d| d).count();
            let straight = (e && wst) || (n && s);
            if count >= 3 || (count == 2 && !straight) {
                lay.junctions
                    .push(DRect::new(xs[i].0, ys[j].0, xs[i].1, ys[j].1));
            }
            if count > 0 {
                lay.extra
                    .push(DRect::new(xs[i].0, ys[j].0, xs[i].1, ys[j].1));
            }
        }
    }
    for c in &corridors {
        lay.space(*c, Kind::Corridor);
    }
    // Rooms in the blocks between the corridor lines (and the outer walls).
    let spans = |lines: &[(Dm, Dm)], lo: Dm, hi: Dm| -> Vec<(Dm, Dm)> {
        (0..=lines.len())
            .map(|c| {
                let a = if c == 0 { lo } else { lines[c - 1].1 + wall };
                let b = if c == lines.len() {
                    hi
                } else {
                    lines[c].0 - wall
                };
                (a, b)
            })
            .collect()
    };
    let cols = spans(&xs, region.x0, region.x1);
    let rows = spans(&ys, region.y0, region.y1);
    for &(c0, c1) in &cols {
        for &(r0, r1) in &rows {
            if c1 - c0 < 25 || r1 - r0 < 25 || !rng.gen_bool(0.85) {
                continue;
            }
            let block = DRect::new(c0, r0, c1, r1);
            let rooms = if block.w().max(block.h()) > 95 && rng.gen_bool(0.6) {
                if block.w() >= block.h() {
                    let xm = pick(rng, c0 + 35, c1 - 35 - wall);
                    vec![
                        DRect::new(c0, r0, xm, r1),
                        DRect::new(xm + wall, r0, c1, r1),
                    ]
                } else {
                    let ym = pick(rng, r0 + 35, r1 - 35 - wall);
                    vec![
                        DRect::new(c0, r0, c1, ym),
                        DRect::new(c0, ym + wall, c1, r1),
                    ]
                }
            } else {
                vec![block]
            };
            let mut prev: Option<DRect> = None;
            for room in rooms {
                let mut candidates = corridors.clone();
                candidates.shuffle(rng);
                let want = if rng.gen_bool(0.25) { 2 } else { 1 };
                let mut doors = 0;
                for c in candidates {
                    if doors >= want {
                        break;
                    }
                    let width = door_width(rng);
                    if lay.add_door(rng, room, c, wall, width) {
                        doors += 1;
                    }
                }
                if let Some(p) = prev {
                    let width = door_width(rng);
                    if (doors == 0 || rng.gen_bool(0.3)) && lay.add_door(rng, room, p, wall, width)
                    {
                        doors += 1;
                    }
                }
                if doors > 0 {
                    if room.w() >= 70 && room.h() >= 70 {
                        lay.space(room, Kind::Hall);
                        hall_obstacles(rng, room, wall, lay);
                    } else {
                        lay.space(room, Kind::Room);
                    }
                    prev = Some(room);
                }
            }
        }
    }
    Ok(())
}

/// Halls, with a side corridor of rooms on the right (`Some(true)`) or left.
fn hall_family(
    rng: &mut ChaCha8Rng,
    region: DRect,
    wall: Dm,
    strip: Option<bool>,
    lay: &mut Layout,
) -> Result<(), String> {
    if let Some(right) = strip {
        let cw = corridor_width(rng);
        let depth = pick(rng, 35, 60);
        if region.w() - cw - depth - 2 * wall >= 100 {
            let (corridor, rooms_x) = if right {
                let cx1 = region.x1 - depth - wall;
                (
                    DRect::new(cx1 - cw, region.y0, cx1, region.y1),
                    (region.x1 - depth, region.x1),
                )
            } else {
                let cx0 = region.x0 + depth + wall;
                (
                    DRect::new(cx0, region.y0, cx0 + cw, region.y1),
                    (region.x0, region.x0 + depth),
                )
            };
            lay.space(corridor, Kind::Corridor);
            for (ry0, ry1) in partition(rng, region.y0, region.y1, wall, 25, (35, 60)) {
                let room = DRect::new(rooms_x.0, ry0, rooms_x.1, ry1);
                let width = door_width(rng);
                if lay.add_door(rng, room, corridor, wall, width) {
                    lay.space(room, Kind::Room);
                }
            }
            let halls = if right {
                DRect::new(region.x0, region.y0, corridor.x0 - wall, region.y1)
            } else {
                DRect::new(corridor.x1 + wall, region.y0, region.x1, region.y1)
            };
            return halls_in(rng, halls, wall, Some(corridor), lay);
        }
    }
    halls_in(rng, region, wall, None, lay)
}

/// One hall, or two joined by wide openings, in `region`; opened onto `corridor` if given.
fn halls_in(
    rng: &mut ChaCha8Rng,
    region: DRect,
    wall: Dm,
    corridor: Option<DRect>,
    lay: &mut Layout,
) -> Result<(), String> {
    let halls = if region.w() >= 200 && rng.gen_bool(0.4) {
        let xm = region.x0 + pick(rng, region.w() * 2 / 5, region.w() * 3 / 5);
        let a = DRect::new(region.x0, region.y0, xm, region.y1);
        let b = DRect::new(xm + wall, region.y0, region.x1, region.y1);
        let mut opened = 0;
        for _ in 0..pick(rng, 1, 2) {
            let width = pick(rng, 15, 40);
            if lay.add_door(rng, a, b, wall, width) {
                opened += 1;
            }
        }
        if opened == 0 {
            return Err("halls cannot be joined".into());
        }
        vec![a, b]
    } else {
        vec![region]
    };
    if let Some(c) = corridor {
        let mut opened = 0;
        for hall in &halls {
            for _ in 0..pick(rng, 1, 3) {
                let width = pick(rng, 12, 30);
                if lay.add_door(rng, *hall, c, wall, width) {
                    opened += 1;
                }
            }
        }
        if opened == 0 {
            return Err("hall cannot be opened onto its corridor".into());
        }
    }
    for hall in halls {
        lay.space(hall, Kind::Hall);
        hall_obstacles(rng, hall, wall, lay);
    }
    Ok(())
}

/// A grid of pillars, or a few free-standing partition walls, clear of the hall's doors.
fn hall_obstacles(rng: &mut ChaCha8Rng, hall: DRect, wall: Dm, lay: &mut Layout) {
    if hall.w() < 80 || hall.h() < 80 {
        return;
    }
    let near_door = |r: DRect, lay: &Layout| lay.doors.iter().any(|d| d.grow(20).overlaps(r));
    if rng.gen_bool(0.7) {
        let (size, sx, sy, margin) = (
            pick(rng, 4, 8),
            pick(rng, 35, 55),
            pick(rng, 35, 55),
            pick(rng, 20, 30),
        );
        let nx = (hall.w() - 2 * margin - size) / sx + 1;
        let ny = (hall.h() - 2 * margin - size) / sy + 1;
        if nx < 1 || ny < 1 || nx * ny < 2 {
            return;
        }
        let ox = hall.x0 + (hall.w() - size - (nx - 1) * sx) / 2;
        let oy = hall.y0 + (hall.h() - size - (ny - 1) * sy) / 2;
        for i in 0..nx {
            for j in 0..ny {
                let (x, y) = (ox + i * sx, oy + j * sy);
                let p = DRect::new(x, y, x + size, y + size);
                if !near_door(p, lay) {
                    lay.solids.push(p);
                }
            }
        }
    } else if rng.gen_bool(0.6) {
        let mine: usize = lay.solids.len();
        for _ in 0..pick(rng, 1, 2) {
            for _ in 0..10 {
                let len = pick(rng, 30, 80);
                let (pw, ph) = if rng.gen_bool(0.5) {
                    (wall, len)
                } else {
                    (len, wall)
                };
                let x = pick(rng, hall.x0 + 20, hall.x1 - 20 - pw);
                let y = pick(rng, hall.y0 + 20, hall.y1 - 20 - ph);
                let p = DRect::new(x, y, x + pw, y + ph);
                let inside = p.x0 >= hall.x0 + 20
                    && p.x1 <= hall.x1 - 20
                    && p.y0 >= hall.y0 + 20
                    && p.y1 <= hall.y1 - 20;
                if inside
                    && !near_door(p, lay)
                    && lay.solids[mine..].iter().all(|o| !p.grow(20).overlaps(*o))
                {
                    lay.solids.push(p);
                    break;
                }
            }
        }
    }
}

/// One family filling `region`; it joins its neighbour on the right (`joins_right`) or left.
fn part(
    rng: &mut ChaCha8Rng,
    family: Family,
    region: DRect,
    wall: Dm,
    joins_right: bool,
    lay: &mut Layout,
) -> Result<(), String> {
    match family {
        Family::Office => office(rng, region, wall, lay),
        Family::Corridors => corridor_net(rng, region, wall, Some(joins_right), lay),
        _ => {
            let strip = rng.gen_bool(0.5).then_some(!joins_right);
            hall_family(rng, region, wall, strip, lay)
        }
    }
}

/// Doors through the wall at `x_split..x_split + wall` between the spaces on either side,
/// corridor to corridor where possible.
fn join_parts(
    rng: &mut ChaCha8Rng,
    lay: &mut Layout,
    split_index: usize,
    x_split: Dm,
    wall: Dm,
) -> Result<(), String> {
    let (left, right) = lay.spaces.split_at(split_index);
    let mut pairs: Vec<(u8, DRect, DRect)> = Vec::new();
    for a in left.iter().filter(|s| s.rect.x1 == x_split) {
        for b in right.iter().filter(|s| s.rect.x0 == x_split + wall) {
            let score = u8::from(a.kind == Kind::Corridor) + u8::from(b.kind == Kind::Corridor);
            pairs.push((score, a.rect, b.rect));
        }
    }
    pairs.shuffle(rng);
    pairs.sort_by_key(|p| std::cmp::Reverse(p.0));
    let want = pick(rng, 1, 2);
    let mut made = 0;
    for (score, a, b) in pairs {
        if made >= want {
            break;
        }
        let width = if score == 2 { 25 } else { door_width(rng) };
        if lay.add_door(rng, a, b, wall, width) {
            made += 1;
        }
    }
    if made == 0 {
        return Err("the two parts cannot be joined".into());
    }
    Ok(())
}

struct Drawn {
    family: Family,
    width_dm: Dm,
    height_dm: Dm,
    wall_dm: Dm,
    layout: Layout,
}

fn draw_layout(rng: &mut ChaCha8Rng) -> Result<Drawn, String> {
    let family = match rng.gen_range(0..4) {
        0 => Family::Office,
        1 => Family::Corridors,
        2 => Family::Hall,
        _ => Family::Mixed,
    };
    let wall = pick(rng, 2, 4);
    let (w, h) = match family {
        Family::Office => (pick(rng, 240, 450), pick(rng, 200, 400)),
        Family::Corridors => (pick(rng, 200, 450), pick(rng, 200, 450)),
        Family::Hall => (pick(rng, 200, 420), pick(rng, 200, 360)),
        Family::Mixed => (pick(rng, 340, 450), pick(rng, 200, 380)),
    };
    let region = DRect::new(
        OUTER_WALL_DM,
        OUTER_WALL_DM,
        w - OUTER_WALL_DM,
        h - OUTER_WALL_DM,
    );
    let mut lay = Layout::default();
    match family {
        Family::Office => office(rng, region, wall, &mut lay)?,
        Family::Corridors => corridor_net(rng, region, wall, None, &mut lay)?,
        Family::Hall => {
            let strip = rng.gen_bool(0.65).then(|| rng.gen_bool(0.5));
            hall_family(rng, region, wall, strip, &mut lay)?;
        }
        Family::Mixed => {
            let xs = region.x0 + pick(rng, 140, region.w() - 140 - wall);
            let left = DRect::new(region.x0, region.y0, xs, region.y1);
            let right = DRect::new(xs + wall, region.y0, region.x1, region.y1);
            let mut parts = [Family::Office, Family::Corridors, Family::Hall];
            parts.shuffle(rng);
            part(rng, parts[0], left, wall, true, &mut lay)?;
            let split_index = lay.spaces.len();
            part(rng, parts[1], right, wall, false, &mut lay)?;
            join_parts(rng, &mut lay, split_index, xs, wall)?;
        }
    }
    let (w, h) = if rng.gen_bool(0.5) {
        lay.transpose();
        (h, w)
    } else {
        (w, h)
    };
    Ok(Drawn {
        family,
        width_dm: w,
        height_dm: h,
        wall_dm: wall,
        layout: lay,
    })
}

fn carve_plan(name: &str, drawn: &Drawn) -> Plan {
    let lay = &drawn.layout;
    let mut plan = Plan::solid(name, m(drawn.width_dm), m(drawn.height_dm));
    let frees = lay
        .spaces
        .iter()
        .map(|s| s.rect)
        .chain(lay.extra.iter().copied())
        .chain(lay.doors.iter().copied());
    for r in frees {
        let r = r.metres();
        plan.carve(r.x0, r.y0, r.x1, r.y1);
    }
    for r in &lay.solids {
        let r = r.metres();
        plan.fill(r.x0, r.y0, r.x1, r.y1);
    }
    plan
}

// ---------------------------------------------------------------------------------------------
// Grid searches.

/// Labels the 4-connected components of `passable`; returns labels (`u32::MAX` off) and sizes.
fn components(passable: &[bool], w: usize, h: usize) -> (Vec<u32>, Vec<usize>) {
    let mut label = vec![u32::MAX; w * h];
    let mut sizes = Vec::new();
    let mut queue = VecDeque::new();
    for start in 0..w * h {
        if !passable[start] || label[start] != u32::MAX {
            continue;
        }
        let id = u32::try_from(sizes.len()).unwrap_or(u32::MAX - 1);
        let mut size = 0;
        label[start] = id;
        queue.push_back(start);
        while let Some(i) = queue.pop_front() {
            size += 1;
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if passable[j] && label[j] == u32::MAX {
                    label[j] = id;
                    queue.push_back(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

/// The 4-connected region of `passable` reached from `from`.
fn reached_from(passable: &[bool], w: usize, h: usize, from: usize) -> Vec<bool> {
    let mut seen = vec![false; w * h];
    if !passable[from] {
        return seen;
    }
    seen[from] = true;
    let mut queue = VecDeque::from([from]);
    while let Some(i) = queue.pop_front() {
        let (x, y) = (i % w, i / w);
        let mut visit = |j: usize| {
            if passable[j] && !seen[j] {
                seen[j] = true;
                queue.push_back(j);
            }
        };
        if x > 0 {
            visit(i - 1);
        }
        if x + 1 < w {
            visit(i + 1);
        }
        if y > 0 {
            visit(i - w);
        }
        if y + 1 < h {
            visit(i + w);
        }
    }
    seen
}

/// Octile path lengths in cells (steps 1 and √2, approximated 5 and 7 fifths) from `from` over
/// `passable`, diagonals only where both side cells are passable; `None` where unreachable.
fn octile_cells(passable: &[bool], w: usize, h: usize, from: usize) -> Vec<Option<f64>> {
    let mut dist = vec![u32::MAX; w * h];
    if passable[from] {
        dist[from] = 0;
        let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); 8];
        buckets[0].push(from);
        let mut pending = 1usize;
        let mut cur: u32 = 0;
        let (wi, hi) = (w as i64, h as i64);
        while pending > 0 {
            let b = (cur % 8) as usize;
            while let Some(i) = buckets[b].pop() {
                pending -= 1;
                if dist[i] != cur {
                    continue;
                }
                let (x, y) = ((i % w) as i64, (i / w) as i64);
                let open = |x: i64, y: i64| {
                    x >= 0 && y >= 0 && x < wi && y < hi && passable[(y * wi + x) as usize]
                };
                for (dx, dy) in NEIGHBOURS_8 {
                    let (nx, ny) = (x + dx, y + dy);
                    if !open(nx, ny) {
                        continue;
                    }
                    let diagonal = dx != 0 && dy != 0;
                    if diagonal && !(open(x + dx, y) && open(x, y + dy)) {
                        continue;
                    }
                    let j = (ny * wi + nx) as usize;
                    let nd = cur + if diagonal { 7 } else { 5 };
                    if nd < dist[j] {
                        dist[j] = nd;
                        buckets[(nd % 8) as usize].push(j);
                        pending += 1;
                    }
                }
            }
            cur += 1;
        }
    }
    dist.into_iter()
        .map(|d| (d != u32::MAX).then(|| f64::from(d) / 5.0))
        .collect()
}

/// Fills every free region but the largest; fails when that drops more than 3% of the floor.
fn keep_main_region(plan: &mut Plan) -> Result<(), String> {
    let free: Vec<bool> = plan.wall.iter().map(|&w| !w).collect();
    let (label, sizes) = components(&free, plan.width, plan.height);
    let total: usize = sizes.iter().sum();
    let Some((main, &main_size)) = sizes
        .iter()
        .enumerate()
        .max_by_key(|&(i, s)| (*s, usize::MAX - i))
    else {
        return Err("the plan has no floor".into());
    };
    if (total - main_size) * 100 > total * 3 {
        return Err(format!(
            "{} of {total} free cells are cut off",
            total - main_size
        ));
    }
    let main = u32::try_from(main).unwrap_or(u32::MAX);
    for (wall, l) in plan.wall.iter_mut().zip(label) {
        if l != u32::MAX && l != main {
            *wall = true;
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// The ground truth: furniture and glass.

fn cell_of(x_m: f64) -> i64 {
    (x_m / RESOLUTION_M).floor() as i64
}

fn cell_centre(c: i64) -> f64 {
    round_mm((c as f64 + 0.5) * RESOLUTION_M)
}

/// Where boxes and panes may go.
struct Site<'a> {
    plan: &'a Plan,
    keep_out: Vec<Rect>,
    anchors: Vec<(f64, f64)>,
}

impl Site<'_> {
    fn wall(&self, cx: i64, cy: i64) -> bool {
        if cx < 0 || cy < 0 {
            return true;
        }
        let (x, y) = (cx as usize, cy as usize);
        x >= self.plan.width || y >= self.plan.height || self.plan.wall[y * self.plan.width + x]
    }

    /// Whether a box with bounds `r` stands flush against walls or at least [`PASSAGE_M`] from
    /// them: no wall inside it; on each side the nearest wall is within [`FLUSH_M`] or at least
    /// [`PASSAGE_M`] away; a corner is checked the same unless a side next to it is flush (the
    /// corner then lies behind that wall, whose openings the door keep-outs guard).
    fn walls_ok(&self, r: Rect) -> bool {
        let res = RESOLUTION_M;
        for cy in cell_of(r.y0 - 0.02)..=cell_of(r.y1 + 0.02) {
            for cx in cell_of(r.x0 - 0.02)..=cell_of(r.x1 + 0.02) {
                if self.wall(cx, cy) {
                    return false;
                }
            }
        }
        let reach = PASSAGE_M + res;
        let steps = (reach / res).ceil() as i64 + 1;
        // Classifies the first wall at gap `d` on one scan line: Some(flush) or None (narrow).
        let classify = |d: f64| -> Option<bool> {
            if d <= FLUSH_M {
                Some(true)
            } else if d < PASSAGE_M {
                None
            } else {
                Some(false)
            }
        };
        let mut flush = [false; 4]; // south, north, west, east
        let xs = cell_of(r.x0)..=cell_of(r.x1 - 1e-9);
        let ys = cell_of(r.y0)..=cell_of(r.y1 - 1e-9);
        for cx in xs.clone() {
            for k in 1..=steps {
                let cy = cell_of(r.y0) - k;
                if self.wall(cx, cy) {
                    match classify(r.y0 - (cy + 1) as f64 * res) {
                        Some(f) => flush[0] |= f,
                        None => return false,
                    }
                    break;
                }
            }
            for k in 1..=steps {
                let cy = cell_of(r.y1 - 1e-9) + k;
                if self.wall(cx, cy) {
                    match classify(cy as f64 * res - r.y1) {
                        Some(f) => flush[1] |= f,
                        None => return false,
                    }
                    break;
                }
            }
        }
        for cy in ys {
            for k in 1..=steps {
                let cx = cell_of(r.x0) - k;
                if self.wall(cx, cy) {
                    match classify(r.x0 - (cx + 1) as f64 * res) {
                        Some(f) => flush[2] |= f,
                        None => return false,
                    }
                    break;
                }
            }
            for k in 1..=steps {
                let cx = cell_of(r.x1 - 1e-9) + k;
                if self.wall(cx, cy) {
                    match classify(cx as f64 * res - r.x1) {
                        Some(f) => flush[3] |= f,
                        None => return false,
                    }
                    break;
                }
            }
        }
        // Corners: (x side, y side, x cells, y cells).
        let left = (cell_of(r.x0) - steps)..cell_of(r.x0);
        let right = (cell_of(r.x1 - 1e-9) + 1)..=(cell_of(r.x1 - 1e-9) + steps);
        let below = (cell_of(r.y0) - steps)..cell_of(r.y0);
        let above = (cell_of(r.y1 - 1e-9) + 1)..=(cell_of(r.y1 - 1e-9) + steps);
        let corner_clear = |xs: Vec<i64>, ys: Vec<i64>| {
            ys.iter().all(|&cy| {
                xs.iter().all(|&cx| {
                    if !self.wall(cx, cy) {
                        return true;
                    }
                    let cell = Rect {
                        x0: cx as f64 * res,
                        y0: cy as f64 * res,
                        x1: (cx + 1) as f64 * res,
                        y1: (cy + 1) as f64 * res,
                    };
                    cell.gap(r) >= PASSAGE_M
                })
            })
        };
        let corners = [
            (
                2,
                0,
                left.clone().collect::<Vec<_>>(),
                below.clone().collect::<Vec<_>>(),
            ),
            (3, 0, right.clone().collect(), below.collect()),
            (2, 1, left.collect(), above.clone().collect()),
            (3, 1, right.collect(), above.collect()),
        ];
        corners
            .into_iter()
            .all(|(sx, sy, xs, ys)| flush[sx] || flush[sy] || corner_clear(xs, ys))
    }

    /// Whether bounds `r` keep out of doors, junctions and anchors and [`PASSAGE_M`] from
    /// `items`.
    fn clear_of(&self, r: Rect, items: &[Rect]) -> bool {
        let (w, h) = (
            self.plan.width as f64 * RESOLUTION_M,
            self.plan.height as f64 * RESOLUTION_M,
        );
        r.x0 > 0.0
            && r.y0 > 0.0
            && r.x1 < w
            && r.y1 < h
            && self.keep_out.iter().all(|k| !k.overlaps(r))
            && self
                .anchors
                .iter()
                .all(|&(x, y)| r.point_gap(x, y) >= ANCHOR_KEEP_OUT_M)
            && items.iter().all(|o| o.gap(r) >= PASSAGE_M)
    }
}

/// Placed boxes and panes, in placement order so the last can be taken back.
#[derive(Default)]
struct Extras {
    furniture: Vec<BoxSpec>,
    glass: Vec<GlassSpec>,
    /// Bounds of each placement (a glass door's panes share one) and its number of panes (0: a
    /// box).
    placed: Vec<(Rect, usize)>,
}

impl Extras {
    fn bounds(&self) -> Vec<Rect> {
        self.placed.iter().map(|p| p.0).collect()
    }

    fn add_box(&mut self, b: BoxSpec, bounds: Rect) {
        self.furniture.push(b);
        self.placed.push((bounds, 0));
    }

    fn add_glass(&mut self, panes: Vec<GlassSpec>, bounds: Rect) {
        let n = panes.len();
        self.glass.extend(panes);
        self.placed.push((bounds, n));
    }

    /// Takes back the last placement; false when there is none.
    fn pop(&mut self) -> bool {
        match self.placed.pop() {
            Some((_, 0)) => {
                self.furniture.pop();
                true
            }
            Some((_, n)) => {
                self.glass.truncate(self.glass.len().saturating_sub(n));
                true
            }
            None => false,
        }
    }

    fn shapes(&self) -> Vec<Obb> {
        self.furniture
            .iter()
            .map(BoxSpec::shape)
            .chain(self.glass.iter().map(GlassSpec::shape))
            .collect()
    }
}

const WOOD: Rgb = [140, 95, 55];
const GREY: Rgb = [110, 115, 120];
const GREEN: Rgb = [60, 120, 80];
const WHITE: Rgb = [215, 215, 210];
const ORANGE: Rgb = [200, 120, 40];
const DARK: Rgb = [60, 60, 66];
const BLUE: Rgb = [60, 90, 150];
const RED: Rgb = [150, 50, 45];

fn jitter(rng: &mut ChaCha8Rng, c: Rgb, amount: i32) -> Rgb {
    c.map(|v| u8::try_from((i32::from(v) + pick(rng, -amount, amount)).clamp(0, 255)).unwrap_or(v))
}

#[derive(Debug, Clone, Copy)]
enum Piece {
    Desk,
    Shelf,
    Table,
    Crate,
    Sofa,
    Bench,
    Cabinet,
}

/// A range of metres to draw from.
type Span = (f64, f64);

/// (length, depth, height, colour) of a piece of furniture.
fn piece_dims(rng: &mut ChaCha8Rng, piece: Piece) -> (f64, f64, f64, Rgb) {
    let (len, depth, height, colours): (Span, Span, Span, &[Rgb]) = match piece {
        Piece::Desk => ((1.2, 1.8), (0.6, 0.8), (0.72, 0.78), &[WOOD, WHITE, GREY]),
        Piece::Shelf => ((0.8, 2.0), (0.3, 0.45), (1.2, 1.9), &[WOOD, WHITE, DARK]),
        Piece::Table => ((0.8, 1.8), (0.7, 1.1), (0.72, 0.78), &[WOOD, WHITE, DARK]),
        Piece::Crate => (
            (0.4, 0.9),
            (0.4, 0.8),
            (0.4, 1.0),
            &[ORANGE, GREY, WOOD, GREEN],
        ),
        Piece::Sofa => (
            (1.5, 2.2),
            (0.75, 0.95),
            (0.75, 0.9),
            &[GREEN, BLUE, RED, DARK],
        ),
        Piece::Bench => ((1.0, 1.8), (0.35, 0.5), (0.45, 0.5), &[WOOD, GREY]),
        Piece::Cabinet => ((0.5, 1.2), (0.35, 0.6), (0.9, 1.3), &[GREY, WHITE, WOOD]),
    };
    let colour = pick_of(rng, colours, GREY);
    (
        round_to(pick_f(rng, len.0, len.1), 0.01),
        round_to(pick_f(rng, depth.0, depth.1), 0.01),
        round_to(pick_f(rng, height.0, height.1), 0.01),
        jitter(rng, colour, 15),
    )
}

/// A box flush against side `side` (0 south, 1 north, 2 west, 3 east) of `space`.
fn flush_box(
    rng: &mut ChaCha8Rng,
    site: &Site,
    extras: &mut Extras,
    space: Rect,
    side: u8,
    dims: (f64, f64, f64, Rgb),
) -> bool {
    let (len, depth, height_m, color) = dims;
    let (lo, hi) = if side < 2 {
        (space.x0, space.x1)
    } else {
        (space.y0, space.y1)
    };
    if hi - lo < len + 2.0 * FLUSH_GAP_M {
        return false;
    }
    let along = match rng.gen_range(0..4) {
        0 => lo + FLUSH_GAP_M,
        1 => hi - FLUSH_GAP_M - len,
        _ => round_to(pick_f(rng, lo + FLUSH_GAP_M, hi - FLUSH_GAP_M - len), 0.01),
    };
    let bounds = match side {
        0 => Rect {
            x0: along,
            y0: space.y0 + FLUSH_GAP_M,
            x1: along + len,
            y1: space.y0 + FLUSH_GAP_M + depth,
        },
        1 => Rect {
            x0: along,
            y0: space.y1 - FLUSH_GAP_M - depth,
            x1: along + len,
            y1: space.y1 - FLUSH_GAP_M,
        },
        2 => Rect {
            x0: space.x0 + FLUSH_GAP_M,
            y0: along,
            x1: space.x0 + FLUSH_GAP_M + depth,
            y1: along + len,
        },
        _ => Rect {
            x0: space.x1 - FLUSH_GAP_M - depth,
            y0: along,
            x1: space.x1 - FLUSH_GAP_M,
            y1: along + len,
        },
    };
    let spec = BoxSpec {
        x_m: round_mm(0.5 * (bounds.x0 + bounds.x1)),
        y_m: round_mm(0.5 * (bounds.y0 + bounds.y1)),
        size_x_m: round_mm(bounds.w()),
        size_y_m: round_mm(bounds.h()),
        yaw_rad: 0.0,
        height_m,
        color,
    };
    place_box(site, extras, spec)
}

/// A free-standing box somewhere in `space`, turned when `turn`.
fn free_box(
    rng: &mut ChaCha8Rng,
    site: &Site,
    extras: &mut Extras,
    space: Rect,
    turn: bool,
    dims: (f64, f64, f64, Rgb),
) -> bool {
    let (len, depth, height_m, color) = dims;
    let yaw_rad = if turn && rng.gen_bool(0.5) {
        round_to(pick_f(rng, -0.8, 0.8), 0.01)
    } else {
        0.0
    };
    let (size_x_m, size_y_m) = if rng.gen_bool(0.5) {
        (len, depth)
    } else {
        (depth, len)
    };
    let (s, c) = yaw_rad.sin_cos();
    let hx = 0.5 * (size_x_m * c.abs() + size_y_m * s.abs());
    let hy = 0.5 * (size_x_m * s.abs() + size_y_m * c.abs());
    let margin = PASSAGE_M + 0.05;
    let (x0, x1) = (space.x0 + margin + hx, space.x1 - margin - hx);
    let (y0, y1) = (space.y0 + margin + hy, space.y1 - margin - hy);
    if x1 < x0 || y1 < y0 {
        return false;
    }
    let spec = BoxSpec {
        x_m: round_to(pick_f(rng, x0, x1), 0.01),
        y_m: round_to(pick_f(rng, y0, y1), 0.01),
        size_x_m,
        size_y_m,
        yaw_rad,
        height_m,
        color,
    };
    place_box(site, extras, spec)
}

/// The axis-aligned bounds of a (turned) box.
fn box_bounds(b: &BoxSpec) -> Rect {
    let (s, c) = b.yaw_rad.sin_cos();
    Rect::centred(
        b.x_m,
        b.y_m,
        0.5 * (b.size_x_m * c.abs() + b.size_y_m * s.abs()),
        0.5 * (b.size_x_m * s.abs() + b.size_y_m * c.abs()),
    )
}

fn place_box(site: &Site, extras: &mut Extras, spec: BoxSpec) -> bool {
    let bounds = box_bounds(&spec);
    if site.clear_of(bounds, &extras.bounds()) && site.walls_ok(bounds) {
        extras.add_box(spec, bounds);
        true
    } else {
        false
    }
}

const FRAMES: [Rgb; 3] = [[90, 90, 95], [55, 55, 60], [170, 170, 175]];
const TINTS: [Rgb; 3] = [[170, 215, 225], [190, 225, 215], [200, 210, 230]];

fn pane(rng: &mut ChaCha8Rng, x0: f64, y0: f64, x1: f64, y1: f64) -> GlassSpec {
    GlassSpec {
        x0_m: round_mm(x0),
        y0_m: round_mm(y0),
        x1_m: round_mm(x1),
        y1_m: round_mm(y1),
        thickness_m: 0.04,
        frame_color: pick_of(rng, &FRAMES, FRAMES[0]),
        tint: pick_of(rng, &TINTS, TINTS[0]),
    }
}

/// A glass door across corridor `c`: panes from the walls leaving an opening of 1.1–1.5 m.
fn glass_door(rng: &mut ChaCha8Rng, site: &Site, extras: &mut Extras, c: Rect) -> bool {
    let along_x = c.w() >= c.h();
    let (a0, a1, b0, b1) = if along_x {
        (c.x0, c.x1, c.y0, c.y1)
    } else {
        (c.y0, c.y1, c.x0, c.x1)
    };
    if a1 - a0 < 4.0 {
        return false;
    }
    let at = round_to(pick_f(rng, a0 + 1.5, a1 - 1.5), 0.05);
    let width = b1 - b0;
    let opening = f64::from(pick(rng, 22, 30)) * 0.05;
    let spans: Vec<(f64, f64)> = if width - opening >= 0.3 {
        let slack = 0.5 * (width - opening) - 0.15;
        let mid = round_to(0.5 * (b0 + b1) + pick_f(rng, -slack, slack), 0.05);
        vec![(b0, mid - 0.5 * opening), (mid + 0.5 * opening, b1)]
    } else if width - opening >= 0.15 {
        if rng.gen_bool(0.5) {
            vec![(b0, b1 - opening)]
        } else {
            vec![(b0 + opening, b1)]
        }
    } else {
        return false;
    };
    if spans.iter().any(|&(s0, s1)| s1 - s0 < 0.12) {
        return false;
    }
    // The panes must meet walls on both sides of the corridor.
    let (ca, cb0, cb1) = (cell_of(at), cell_of(b0) - 1, cell_of(b1 - 1e-9) + 1);
    let walled = if along_x {
        site.wall(ca, cb0) && site.wall(ca, cb1)
    } else {
        site.wall(cb0, ca) && site.wall(cb1, ca)
    };
    let bounds = if along_x {
        Rect {
            x0: at - 0.05,
            y0: b0,
            x1: at + 0.05,
            y1: b1,
        }
    } else {
        Rect {
            x0: b0,
            y0: at - 0.05,
            x1: b1,
            y1: at + 0.05,
        }
    };
    if !walled || !site.clear_of(bounds, &extras.bounds()) {
        return false;
    }
    let panes = spans
        .into_iter()
        .map(|(s0, s1)| {
            if along_x {
                pane(rng, at, s0, at, s1)
            } else {
                pane(rng, s0, at, s1, at)
            }
        })
        .collect();
    extras.add_glass(panes, bounds);
    true
}

/// A free-standing glass screen 1.5–4 m long in `hall`.
fn glass_screen(rng: &mut ChaCha8Rng, site: &Site, extras: &mut Extras, hall: Rect) -> bool {
    let len = round_to(pick_f(rng, 1.5, 4.0), 0.05);
    let along_x = rng.gen_bool(0.5);
    let (hx, hy) = if along_x {
        (0.5 * len, 0.05)
    } else {
        (0.05, 0.5 * len)
    };
    let margin = PASSAGE_M + 0.05;
    let (x0, x1) = (hall.x0 + margin + hx, hall.x1 - margin - hx);
    let (y0, y1) = (hall.y0 + margin + hy, hall.y1 - margin - hy);
    if x1 < x0 || y1 < y0 {
        return false;
    }
    let (cx, cy) = (
        round_to(pick_f(rng, x0, x1), 0.05),
        round_to(pick_f(rng, y0, y1), 0.05),
    );
    let bounds = Rect::centred(cx, cy, hx, hy);
    if !site.clear_of(bounds, &extras.bounds()) || !site.walls_ok(bounds) {
        return false;
    }
    let p = if along_x {
        pane(rng, cx - 0.5 * len, cy, cx + 0.5 * len, cy)
    } else {
        pane(rng, cx, cy - 0.5 * len, cx, cy + 0.5 * len)
    };
    extras.add_glass(vec![p], bounds);
    true
}

/// Glass first (few), then furniture room by room, hall by hall, corridor by corridor.
fn furnish(rng: &mut ChaCha8Rng, site: &Site, spaces: &[Space]) -> Extras {
    let mut extras = Extras::default();
    let area_m2 = site.plan.wall.len() as f64 * RESOLUTION_M * RESOLUTION_M;
    let max_boxes = ((area_m2 / AREA_PER_BOX_M2) as usize).clamp(4, MAX_FURNITURE);
    let corridors: Vec<Rect> = spaces
        .iter()
        .filter(|s| s.kind == Kind::Corridor)
        .map(|s| s.rect.metres())
        .collect();
    let halls: Vec<Rect> = spaces
        .iter()
        .filter(|s| s.kind == Kind::Hall)
        .map(|s| s.rect.metres())
        .collect();
    let doors_wanted = match rng.gen_range(0..20) {
        0..=6 => 0,
        7..=15 => 1,
        _ => 2,
    };
    let mut order: Vec<Rect> = corridors.clone();
    order.shuffle(rng);
    let mut made = 0;
    for c in order {
        if made >= doors_wanted {
            break;
        }
        if (0..3).any(|_| glass_door(rng, site, &mut extras, c)) {
            made += 1;
        }
    }
    let mut screens = 0;
    for h in &halls {
        if screens < 2
            && rng.gen_bool(0.35)
            && (0..5).any(|_| glass_screen(rng, site, &mut extras, *h))
        {
            screens += 1;
        }
    }
    let mut order: Vec<&Space> = spaces.iter().collect();
    order.shuffle(rng);
    for s in order {
        let r = s.rect.metres();
        let tries = match s.kind {
            Kind::Room => {
                if rng.gen_bool(0.7) {
                    pick(rng, 1, 3)
                } else {
                    0
                }
            }
            Kind::Hall => pick(rng, 2, 6),
            Kind::Corridor => {
                let len = r.w().max(r.h());
                if len >= 12.0 && rng.gen_bool(0.4) {
                    2
                } else {
                    i32::from(len >= 4.0 && rng.gen_bool(0.3))
                }
            }
        };
        for _ in 0..tries {
            if extras.furniture.len() >= max_boxes {
                return extras;
            }
            for _ in 0..6 {
                let placed = match s.kind {
                    Kind::Room => {
                        if rng.gen_bool(0.7) {
                            let piece = pick_of(
                                rng,
                                &[Piece::Desk, Piece::Shelf, Piece::Cabinet, Piece::Sofa],
                                Piece::Desk,
                            );
                            let dims = piece_dims(rng, piece);
                            let side = rng.gen_range(0..4);
                            flush_box(rng, site, &mut extras, r, side, dims)
                        } else {
                            let piece = pick_of(rng, &[Piece::Table, Piece::Crate], Piece::Table);
                            let dims = piece_dims(rng, piece);
                            free_box(rng, site, &mut extras, r, true, dims)
                        }
                    }
                    Kind::Hall => {
                        if rng.gen_bool(0.6) {
                            let piece = pick_of(
                                rng,
                                &[Piece::Table, Piece::Crate, Piece::Sofa],
                                Piece::Table,
                            );
                            let dims = piece_dims(rng, piece);
                            free_box(rng, site, &mut extras, r, true, dims)
                        } else {
                            let piece = pick_of(rng, &[Piece::Shelf, Piece::Cabinet], Piece::Shelf);
                            let dims = piece_dims(rng, piece);
                            let side = rng.gen_range(0..4);
                            flush_box(rng, site, &mut extras, r, side, dims)
                        }
                    }
                    Kind::Corridor => {
                        let piece = pick_of(
                            rng,
                            &[Piece::Bench, Piece::Cabinet, Piece::Crate],
                            Piece::Bench,
                        );
                        let (len, depth, height, colour) = piece_dims(rng, piece);
                        let width = r.w().min(r.h());
                        let depth = depth.min(round_to(width - PASSAGE_M - 0.1, 0.01));
                        if depth < 0.3 {
                            false
                        } else {
                            let side = if r.w() >= r.h() {
                                rng.gen_range(0..2)
                            } else {
                                rng.gen_range(2..4)
                            };
                            flush_box(
                                rng,
                                site,
                                &mut extras,
                                r,
                                side,
                                (len, depth, height, colour),
                            )
                        }
                    }
                };
                if placed {
                    break;
                }
            }
        }
    }
    extras
}

// ---------------------------------------------------------------------------------------------
// People.

/// Whether a person of `radius_m` walking `route` keeps clear of walls and `shapes`.
fn route_clear(
    route: &[(f64, f64)],
    radius_m: f64,
    plan_df: &DistanceField,
    shapes: &[Obb],
) -> bool {
    route.windows(2).all(|pair| {
        let ((ax, ay), (bx, by)) = (pair[0], pair[1]);
        let n = ((bx - ax).hypot(by - ay) / 0.05).ceil().max(1.0) as usize;
        (0..=n).all(|k| {
            let t = k as f64 / n as f64;
            let (x, y) = (ax + t * (bx - ax), ay + t * (by - ay));
            f64::from(plan_df.at(cell_of(x), cell_of(y))) >= radius_m + 0.15
                && shapes.iter().all(|s| s.distance(x, y) >= radius_m + 0.1)
        })
    })
}

const SHIRTS: [Rgb; 8] = [
    [180, 40, 40],
    [40, 120, 60],
    [200, 170, 40],
    [90, 150, 200],
    [150, 60, 150],
    [60, 60, 60],
    [220, 120, 40],
    [200, 200, 220],
];
const PANTS: [Rgb; 4] = [[45, 45, 60], [30, 30, 35], [70, 60, 50], [40, 55, 90]];

/// 0–3 people walking corridors, halls, and through doors.
fn people(
    rng: &mut ChaCha8Rng,
    spaces: &[Space],
    doors: &[DRect],
    plan_df: &DistanceField,
    shapes: &[Obb],
) -> Vec<PersonSpec> {
    let radius_m = 0.25;
    let wanted = match rng.gen_range(0..20) {
        0..=2 => 0,
        3..=10 => 1,
        11..=16 => 2,
        _ => 3,
    };
    let mut out: Vec<PersonSpec> = Vec::new();
    for _ in 0..wanted {
        for _ in 0..30 {
            let route: Vec<(f64, f64)> = match rng.gen_range(0..3) {
                0 => {
                    let Some(s) = spaces
                        .iter()
                        .filter(|s| s.kind == Kind::Corridor)
                        .choose(rng)
                    else {
                        continue;
                    };
                    let r = s.rect.metres();
                    let off = pick_f(rng, -0.25, 0.25);
                    if r.w() >= r.h() {
                        let y = 0.5 * (r.y0 + r.y1) + off;
                        vec![(r.x0 + 0.6, y), (r.x1 - 0.6, y)]
                    } else {
                        let x = 0.5 * (r.x0 + r.x1) + off;
                        vec![(x, r.y0 + 0.6), (x, r.y1 - 0.6)]
                    }
                }
                1 => {
                    let Some(s) = spaces.iter().filter(|s| s.kind == Kind::Hall).choose(rng) else {
                        continue;
                    };
                    let r = s.rect.metres().grow(-0.8);
                    let n = if rng.gen_bool(0.3) { 3 } else { 2 };
                    (0..n)
                        .map(|_| (pick_f(rng, r.x0, r.x1), pick_f(rng, r.y0, r.y1)))
                        .collect()
                }
                _ => {
                    let Some(d) = doors.choose(rng) else {
                        continue;
                    };
                    let r = d.metres();
                    let (cx, cy) = (0.5 * (r.x0 + r.x1), 0.5 * (r.y0 + r.y1));
                    // The door's normal runs across its thin side.
                    let (nx, ny) = if r.w() < r.h() {
                        (1.0, 0.0)
                    } else {
                        (0.0, 1.0)
                    };
                    let s = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
                    let (near, far) = (pick_f(rng, 1.0, 1.6), pick_f(rng, 1.2, 2.5));
                    let a = (cx - s * nx * near, cy - s * ny * near);
                    let b = (cx + s * nx * far, cy + s * ny * far);
                    let along = pick_f(rng, 2.5, 6.0) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
                    let start = (a.0 + ny * along, a.1 + nx * along);
                    vec![start, a, b]
                }
            };
            let route: Vec<(f64, f64)> = route
                .into_iter()
                .map(|(x, y)| (round_to(x, 0.01), round_to(y, 0.01)))
                .collect();
            let length: f64 = route
                .windows(2)
                .map(|p| (p[1].0 - p[0].0).hypot(p[1].1 - p[0].1))
                .sum();
            let apart = out.iter().all(|o| {
                let (x, y) = (o.route[0].x_m, o.route[0].y_m);
                (x - route[0].0).hypot(y - route[0].1) >= 1.5
            });
            if length >= 3.0 && apart && route_clear(&route, radius_m, plan_df, shapes) {
                let mode = if route.len() >= 3 && rng.gen_bool(0.5) {
                    RouteMode::Loop
                } else {
                    RouteMode::PingPong
                };
                out.push(PersonSpec {
                    route: route
                        .iter()
                        .map(|&(x_m, y_m)| PointSpec { x_m, y_m })
                        .collect(),
                    speed_mps: round_to(pick_f(rng, 0.4, 0.9), 0.05),
                    mode,
                    radius_m,
                    shirt_color: {
                        let shirt = pick_of(rng, &SHIRTS, SHIRTS[0]);
                        jitter(rng, shirt, 10)
                    },
                    pants_color: pick_of(rng, &PANTS, PANTS[0]),
                });
                break;
            }
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Start and goals.

/// Everything the start and goals are drawn from.
struct Ground<'a> {
    w: usize,
    h: usize,
    plan_df: &'a DistanceField,
    truth_df: &'a DistanceField,
    /// The wide-passage region reached from the root anchor.
    main: Vec<bool>,
    /// Samples along the people's routes.
    walkers: Vec<(f64, f64)>,
}

impl Ground<'_> {
    fn eligible(&self, cx: i64, cy: i64, from_people_m: f64) -> bool {
        let (x, y) = (cell_centre(cx), cell_centre(cy));
        cx >= 0
            && cy >= 0
            && (cx as usize) < self.w
            && (cy as usize) < self.h
            && self.main[cy as usize * self.w + cx as usize]
            && f64::from(self.truth_df.at(cx, cy)) >= POINT_CLEARANCE_M
            && f64::from(self.plan_df.at(cx, cy)) >= POINT_CLEARANCE_M
            && self
                .walkers
                .iter()
                .all(|&(px, py)| (px - x).hypot(py - y) >= from_people_m)
    }

    /// A random eligible cell in a random space (not `avoid`), or `None` after `tries`.
    fn draw(
        &self,
        rng: &mut ChaCha8Rng,
        spaces: &[Space],
        avoid: Option<usize>,
        from_people_m: f64,
    ) -> Option<(usize, i64, i64)> {
        let si = loop {
            let si = rng.gen_range(0..spaces.len());
            if Some(si) != avoid || spaces.len() == 1 {
                break si;
            }
        };
        let r = spaces[si].rect.metres();
        for _ in 0..8 {
            let (cx, cy) = (
                cell_of(pick_f(rng, r.x0, r.x1)),
                cell_of(pick_f(rng, r.y0, r.y1)),
            );
            if self.eligible(cx, cy, from_people_m) {
                return Some((si, cx, cy));
            }
        }
        None
    }
}

/// Start pose, goals and the total shortest path length (metres) through them.
fn route_task(
    rng: &mut ChaCha8Rng,
    ground: &Ground,
    spaces: &[Space],
    wide: &[bool],
) -> Result<(PoseSpec, Vec<PointSpec>, f64), String> {
    let (w, h) = (ground.w, ground.h);
    let mut start = None;
    for _ in 0..400 {
        if let Some(found) = ground.draw(rng, spaces, None, 1.2) {
            start = Some(found);
            break;
        }
    }
    let (mut space, sx, sy) = start.ok_or("no free start")?;
    // Face the longest free stretch along an axis.
    let mut best = (0i64, 0.0);
    for (k, yaw) in [0.0, FRAC_PI_2, PI, -FRAC_PI_2].into_iter().enumerate() {
        let (dx, dy) = [(1, 0), (0, 1), (-1, 0), (0, -1)][k];
        let mut n = 0i64;
        while n < 200 {
            let (cx, cy) = (sx + dx * (n + 1), sy + dy * (n + 1));
            if cx < 0
                || cy < 0
                || cx as usize >= w
                || cy as usize >= h
                || !wide[cy as usize * w + cx as usize]
            {
                break;
            }
            n += 1;
        }
        if n > best.0 {
            best = (n, yaw);
        }
    }
    let start = PoseSpec {
        x_m: cell_centre(sx),
        y_m: cell_centre(sy),
        yaw_rad: best.1,
    };
    let n_goals = pick(rng, 2, 4);
    let mut goals = Vec::new();
    let (mut px, mut py) = (sx, sy);
    let mut total_m = 0.0;
    for _ in 0..n_goals {
        let from = py as usize * w + px as usize;
        let dist = octile_cells(&ground.main, w, h, from);
        let mut found = None;
        for attempt in 0..500 {
            let Some((si, cx, cy)) = ground.draw(rng, spaces, Some(space), 0.0) else {
                continue;
            };
            let straight_m = ((cx - px) as f64).hypot((cy - py) as f64) * RESOLUTION_M;
            let Some(path) = dist[cy as usize * w + cx as usize] else {
                continue;
            };
            let path_m = path * RESOLUTION_M;
            let wanted_m = if attempt < 300 {
                8.0
            } else {
                MIN_GOAL_SPACING_M
            };
            if straight_m >= MIN_GOAL_SPACING_M + RESOLUTION_M && path_m >= wanted_m {
                found = Some((si, cx, cy, path_m));
                break;
            }
        }
        let (si, cx, cy, path_m) = found.ok_or("no goal far enough")?;
        goals.push(PointSpec {
            x_m: cell_centre(cx),
            y_m: cell_centre(cy),
        });
        total_m += path_m;
        (px, py, space) = (cx, cy, si);
    }
    Ok((start, goals, total_m))
}

// ---------------------------------------------------------------------------------------------
// Looks.

const WALL_COLOURS: [Rgb; 10] = [
    [225, 220, 205],
    [205, 200, 185],
    [200, 225, 220],
    [170, 190, 210],
    [215, 200, 170],
    [190, 205, 185],
    [200, 195, 225],
    [180, 170, 150],
    [232, 232, 228],
    [165, 95, 75],
];
const FLOOR_COLOURS: [Rgb; 9] = [
    [120, 90, 60],
    [150, 135, 110],
    [185, 190, 185],
    [90, 80, 100],
    [70, 90, 120],
    [110, 95, 80],
    [85, 85, 110],
    [120, 120, 115],
    [170, 170, 175],
];
const CEILING_COLOURS: [Rgb; 5] = [
    [230, 228, 220],
    [240, 238, 230],
    [240, 245, 245],
    [235, 235, 240],
    [205, 205, 200],
];
const WALL_TEXTURES: [WallTexture; 6] = [
    WallTexture::Plain,
    WallTexture::Bricks,
    WallTexture::Panels,
    WallTexture::Wainscot,
    WallTexture::Tiles,
    WallTexture::Concrete,
];
const FLOOR_TEXTURES: [FloorTexture; 4] = [
    FloorTexture::Tiles,
    FloorTexture::Plain,
    FloorTexture::Planks,
    FloorTexture::Carpet,
];

fn draw_look(rng: &mut ChaCha8Rng) -> Look {
    let wall = pick_of(rng, &WALL_COLOURS, WALL_COLOURS[0]);
    let floor = pick_of(rng, &FLOOR_COLOURS, FLOOR_COLOURS[0]);
    let ceiling = pick_of(rng, &CEILING_COLOURS, CEILING_COLOURS[0]);
    Look {
        wall_color: jitter(rng, wall, 15),
        wall_texture: pick_of(rng, &WALL_TEXTURES, WallTexture::Plain),
        floor_color: jitter(rng, floor, 15),
        floor_texture: pick_of(rng, &FLOOR_TEXTURES, FloorTexture::Tiles),
        ceiling_color: jitter(rng, ceiling, 8),
        light: round_to(pick_f(rng, 0.8, 1.3), 0.05),
    }
}

/// A building look plus own looks for some rooms and halls (each with its half of the walls).
fn draw_appearance(rng: &mut ChaCha8Rng, spaces: &[Space], wall: Dm) -> AppearanceSpec {
    let default = draw_look(rng);
    let mut areas = Vec::new();
    let (mut rooms, mut halls) = (0, 0);
    for s in spaces {
        let (p, name) = match s.kind {
            Kind::Corridor => continue,
            Kind::Room => {
                rooms += 1;
                (0.35, format!("room {rooms}"))
            }
            Kind::Hall => {
                halls += 1;
                (0.6, format!("hall {halls}"))
            }
        };
        if areas.len() < 10 && rng.gen_bool(p) {
            let r = s.rect.grow(wall / 2).metres();
            areas.push(AreaSpec {
                name,
                min_x_m: r.x0,
                min_y_m: r.y0,
                max_x_m: r.x1,
                max_y_m: r.y1,
                look: draw_look(rng),
            });
        }
    }
    AppearanceSpec { default, areas }
}

// ---------------------------------------------------------------------------------------------
// One attempt.

fn attempt_building(seed: u64, rng: &mut ChaCha8Rng) -> Result<Building, Failure> {
    let name = building_name(seed);
    let drawn = draw_layout(rng)?;
    let mut plan = carve_plan(&name, &drawn);
    keep_main_region(&mut plan)?;
    let grid = plan.to_grid().map_err(|source| {
        Failure::Fatal(ProcgenError::Grid {
            name: name.clone(),
            source,
        })
    })?;
    let (w, h) = (plan.width, plan.height);
    let plan_df = DistanceField::compute(&grid, Sources::OccupiedOrUnknown);
    // Each space's anchor: its most open cell; spaces too tight or cut off are dropped.
    let mut spaces = Vec::new();
    let mut anchors: Vec<(i64, i64, f32)> = Vec::new();
    for s in &drawn.layout.spaces {
        let r = s.rect.metres();
        let mut best = (0, 0, 0.0f32);
        for cy in cell_of(r.y0)..cell_of(r.y1) {
            for cx in cell_of(r.x0)..cell_of(r.x1) {
                let d = plan_df.at(cx, cy);
                if d > best.2 {
                    best = (cx, cy, d);
                }
            }
        }
        if f64::from(best.2) >= ANCHOR_KEEP_OUT_M {
            spaces.push(*s);
            anchors.push(best);
        }
    }
    let root = anchors
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .2.total_cmp(&b.1 .2).then(b.0.cmp(&a.0)))
        .map(|(i, _)| i)
        .ok_or("no open space")?;
    let mut keep_out: Vec<Rect> = drawn
        .layout
        .doors
        .iter()
        .map(|d| d.metres().grow(DOOR_KEEP_OUT_M))
        .collect();
    keep_out.extend(
        drawn
            .layout
            .junctions
            .iter()
            .map(|j| j.metres().grow(JUNCTION_KEEP_OUT_M)),
    );
    let site = Site {
        plan: &plan,
        keep_out,
        anchors: anchors
            .iter()
            .map(|&(cx, cy, _)| (cell_centre(cx), cell_centre(cy)))
            .collect(),
    };
    let mut extras = furnish(rng, &site, &spaces);
    // Every space stays reachable through wide passages in the ground truth; take placements
    // back, last first, until it does.
    let radius_m = SimConfig::default().base.radius_m;
    let wide_m = radius_m + WIDE_MARGIN_M;
    let (truth_df, wide, main) = loop {
        let truth = rasterize_shapes(&grid, extras.shapes());
        let truth_df = DistanceField::compute(&truth, Sources::OccupiedOrUnknown);
        let wide: Vec<bool> = truth_df
            .as_slice()
            .iter()
            .map(|&d| f64::from(d) >= wide_m)
            .collect();
        let (rx, ry, _) = anchors[root];
        let main = reached_from(&wide, w, h, ry as usize * w + rx as usize);
        if anchors
            .iter()
            .all(|&(cx, cy, _)| main[cy as usize * w + cx as usize])
        {
            break (truth_df, wide, main);
        }
        if !extras.pop() {
            return Err("a space is cut off even without furniture".into());
        }
    };
    let shapes = extras.shapes();
    let people = people(rng, &spaces, &drawn.layout.doors, &plan_df, &shapes);
    let walkers: Vec<(f64, f64)> = people
        .iter()
        .flat_map(|p| {
            p.route.windows(2).flat_map(|pair| {
                let (a, b) = (pair[0], pair[1]);
                let n = ((b.x_m - a.x_m).hypot(b.y_m - a.y_m) / 0.1).ceil().max(1.0) as usize;
                (0..=n).map(move |k| {
                    let t = k as f64 / n as f64;
                    (a.x_m + t * (b.x_m - a.x_m), a.y_m + t * (b.y_m - a.y_m))
                })
            })
        })
        .collect();
    let ground = Ground {
        w,
        h,
        plan_df: &plan_df,
        truth_df: &truth_df,
        main,
        walkers,
    };
    let (start, goals, path_m) = route_task(rng, &ground, &spaces, &wide)?;
    let appearance = draw_appearance(rng, &spaces, drawn.wall_dm);
    let role = role_of_seed(seed);
    let rooms = spaces.iter().filter(|s| s.kind == Kind::Room).count();
    let halls = spaces.iter().filter(|s| s.kind == Kind::Hall).count();
    let scenario = Scenario {
        name: name.clone(),
        description: format!(
            "Generated {} building {} m x {} m (seed {seed}; rooms: {}, halls: {}), for {}",
            drawn.family,
            m(drawn.width_dm),
            m(drawn.height_dm),
            rooms,
            halls,
            if role == Role::Evaluation {
                "evaluation only: never record from it"
            } else {
                "training"
            }
        ),
        role,
        floor_plan: format!("maps/{name}.yaml"),
        seed: scenario_seed(seed),
        time_limit_s: (2.0 * path_m / TIME_LIMIT_SPEED_MPS + 60.0).ceil(),
        start,
        goals,
        appearance,
        furniture: extras.furniture,
        glass: extras.glass,
        people,
        parked_robots: Vec::new(),
        expect_goals_reached: true,
    };
    Ok(Building {
        plan,
        grid,
        scenario,
        family: drawn.family,
    })
}

// ---------------------------------------------------------------------------------------------
// Files.

const GENERATOR: &str = "`sim gen-building` (sim/src/procgen.rs)";

/// The ROS map YAML of a building's plan (the image is `<name>.pgm` beside it).
#[must_use]
pub fn map_yaml(b: &Building) -> String {
    b.plan.ros_yaml_by(GENERATOR)
}

/// The scenario file's text: a header comment and the YAML.
///
/// # Errors
/// [`ProcgenError::Yaml`] if serialization fails.
pub fn scenario_yaml(b: &Building) -> Result<String, ProcgenError> {
    let s = &b.scenario;
    let body = serde_yaml::to_string(s).map_err(|e| ProcgenError::Yaml {
        name: s.name.clone(),
        reason: e.to_string(),
    })?;
    Ok(format!(
        "# {}\n# Generated by {GENERATOR}; format: sim/scenarios/README.md,\n\
         # schema: sim/scenario.schema.json.\n{body}",
        s.description
    ))
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), ProcgenError> {
    std::fs::write(path, bytes).map_err(|source| ProcgenError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `maps/<name>.pgm`, `maps/<name>.yaml`, `<name>.yaml` (the scenario) and `<name>.png`
/// (the top-down picture of [`crate::view::top_down`]) under `dir`; returns the files written.
///
/// # Errors
/// [`ProcgenError`] on the first file that cannot be made or written.
pub fn write_building(b: &Building, dir: &Path) -> Result<Vec<PathBuf>, ProcgenError> {
    let maps = dir.join("maps");
    std::fs::create_dir_all(&maps).map_err(|source| ProcgenError::Io {
        path: maps.clone(),
        source,
    })?;
    let name = &b.scenario.name;
    let pgm = maps.join(format!("{name}.pgm"));
    write(&pgm, &b.plan.pgm())?;
    let map = maps.join(format!("{name}.yaml"));
    write(&map, map_yaml(b).as_bytes())?;
    let scenario = dir.join(format!("{name}.yaml"));
    write(&scenario, scenario_yaml(b)?.as_bytes())?;
    let world =
        World::new(b.scenario.clone(), b.grid.clone(), SimConfig::default()).map_err(|e| {
            ProcgenError::World {
                name: name.clone(),
                source: Box::new(e),
            }
        })?;
    let png = dir.join(format!("{name}.png"));
    crate::view::top_down(&world, 1)
        .save(&png)
        .map_err(|e| ProcgenError::Picture {
            path: png.clone(),
            reason: e.to_string(),
        })?;
    Ok(vec![pgm, map, scenario, png])
}

/// What [`generate`] made of one seed.
#[derive(Debug, Clone)]
pub struct Written {
    /// [`Building::summary`].
    pub summary: String,
    pub files: Vec<PathBuf>,
}

/// Makes and writes the buildings of seeds `first_seed..first_seed + count` under `dir`
/// (see [`write_building`]).
///
/// # Errors
/// [`ProcgenError::SeedRange`] when the seeds overflow, else the first failing building's error.
pub fn generate(dir: &Path, first_seed: u64, count: u64) -> Result<Vec<Written>, ProcgenError> {
    if count == 0 {
        return Ok(Vec::new());
    }
    let last = first_seed
        .checked_add(count - 1)
        .ok_or(ProcgenError::SeedRange {
            first: first_seed,
            count,
        })?;
    (first_seed..=last)
        .map(|seed| {
            let b = building(seed)?;
            let files = write_building(&b, dir)?;
            Ok(Written {
                summary: b.summary(),
                files,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octile_lengths_match_straight_and_diagonal_runs() {
        let (w, h) = (20, 10);
        let open = vec![true; w * h];
        let d = octile_cells(&open, w, h, 0);
        assert_eq!(d[9], Some(9.0));
        assert_eq!(d[5 * w + 5], Some(7.0));
        let mut walled = open.clone();
        for y in 0..9 {
            walled[y * w + 10] = false;
        }
        let d = octile_cells(&walled, w, h, 0);
        // Round the wall's end: 9 diagonals, two steps past its end, 9 steps down.
        assert!(d[11].is_some_and(|v| (v - (9.0 * 1.4 + 2.0 + 9.0)).abs() < 1e-9));
        walled[9 * w + 10] = false;
        assert_eq!(octile_cells(&walled, w, h, 0)[11], None);
    }

    #[test]
    fn doors_need_rooms_facing_each_other_across_one_wall() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let a = DRect::new(0, 0, 40, 40);
        let b = DRect::new(0, 43, 40, 60);
        let d = door_between(&mut rng, a, b, 3, 14, &[], &[]).unwrap();
        assert_eq!((d.y0, d.y1, d.w()), (40, 43, 14));
        assert!(d.x0 >= 3 && d.x1 <= 37);
        assert!(door_between(&mut rng, a, DRect::new(0, 44, 40, 60), 3, 14, &[], &[]).is_none());
        // Too short a shared stretch for a 1.1 m door.
        assert!(door_between(&mut rng, a, DRect::new(30, 43, 50, 60), 3, 14, &[], &[]).is_none());
    }

    #[test]
    fn partitions_cover_the_span_with_walls_between() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (s0, s1) in [(0, 400), (5, 130), (10, 36)] {
            let rooms = partition(&mut rng, s0, s1, 3, 25, (40, 65));
            assert_eq!(rooms.first().map(|r| r.0), Some(s0));
            assert_eq!(rooms.last().map(|r| r.1), Some(s1));
            for pair in rooms.windows(2) {
                assert_eq!(pair[1].0 - pair[0].1, 3);
            }
            assert!(rooms.iter().all(|r| r.1 - r.0 >= 25), "{rooms:?}");
        }
    }

    #[test]
    fn a_flush_box_passes_and_a_box_leaving_a_narrow_gap_does_not() {
        // A 6 m x 4 m room (cells 20..140 x 20..100 free).
        let mut plan = Plan::solid("t", 8.0, 6.0);
        plan.carve(1.0, 1.0, 7.0, 5.0);
        let site = Site {
            plan: &plan,
            keep_out: vec![],
            anchors: vec![],
        };
        // Flush against the south wall in the south-west corner.
        assert!(site.walls_ok(Rect {
            x0: 1.05,
            y0: 1.05,
            x1: 2.5,
            y1: 1.7
        }));
        // Flush south, 0.5 m from the west wall: too narrow to pass, too wide to be flush.
        assert!(!site.walls_ok(Rect {
            x0: 1.5,
            y0: 1.05,
            x1: 2.5,
            y1: 1.7
        }));
        // Free-standing in the middle.
        assert!(site.walls_ok(Rect {
            x0: 3.0,
            y0: 2.5,
            x1: 4.0,
            y1: 3.5
        }));
        // Into the wall.
        assert!(!site.walls_ok(Rect {
            x0: 0.9,
            y0: 2.0,
            x1: 1.5,
            y1: 2.5
        }));
        // 0.6 m from the north wall, free elsewhere.
        assert!(!site.walls_ok(Rect {
            x0: 3.0,
            y0: 3.8,
            x1: 4.0,
            y1: 4.4
        }));
    }
}
