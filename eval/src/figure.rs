//! Pictures of runs like the paper's Figure 5: the floor plan with what the plan lacks drawn in,
//! the goals numbered, the planned path and each method's driven trace.
//!
//! [`scenario_picture`] draws one scenario with every method's trace over it (a legend below);
//! [`grid_picture`] lays scenarios out as rows and "task" plus one column per method, as in the
//! paper. Everything is rasterized here, text included: labels use a built-in 5×7 bitmap font
//! because the machines that make these pictures need not have a font file.
//!
//! Pictures are north (grid +y) up. Walls are grey on white floor, the ground-truth furniture
//! brown, parked robots (`parked_robots` of the scenario) dark slate discs and glass cyan,
//! drawn at least 3 px thick so a 4 cm pane shows. The planned path is a
//! dashed light-blue line, traces solid in their method's colour; an intervention is an X and a
//! collision a hollow square, both in the trace's colour. Consecutive trace points more than
//! [`TRACE_GAP_M`] apart (a robot carried elsewhere) are not joined.

use image::{Rgb, RgbImage};
use map_core::{CellClass, OccupancyGrid};
use sim::World;

/// One method's run over a scenario, in map-frame metres.
#[derive(Debug, Clone, Copy)]
pub struct Trace<'a> {
    /// The method's name: the legend text, and in [`grid_picture`] the column it belongs to.
    pub label: &'a str,
    /// The driven (true) path, in time order.
    pub points_m: &'a [(f64, f64)],
    /// Where a person intervened (carried the robot).
    pub interventions_m: &'a [(f64, f64)],
    /// Where the robot touched something.
    pub collisions_m: &'a [(f64, f64)],
}

/// One row of [`grid_picture`]: a scenario and the runs of the methods on it.
#[derive(Debug, Clone, Copy)]
pub struct GridRow<'a> {
    /// Row label, e.g. `task_a`.
    pub label: &'a str,
    pub world: &'a World,
    /// The planned path (the planner's first path of every leg, joined), map frame.
    pub planned_m: &'a [(f64, f64)],
    pub goals_m: &'a [(f64, f64)],
    /// The runs; a method's column shows the trace whose `label` is the method's name, and only
    /// the map where there is none.
    pub traces: &'a [Trace<'a>],
}

/// Scale of [`scenario_picture`]: a 30 m floor plan is 750 px wide.
pub const SCENARIO_PX_PER_M: f64 = 25.0;
/// Trace points further apart than this are not joined: the robot was carried, not driven.
pub const TRACE_GAP_M: f64 = 2.0;

pub const FREE: [u8; 3] = [255, 255, 255];
pub const WALL: [u8; 3] = [150, 150, 150];
pub const UNKNOWN: [u8; 3] = [205, 205, 205];
pub const FURNITURE: [u8; 3] = [150, 105, 60];
pub const GLASS: [u8; 3] = [0, 175, 220];
pub const PARKED_ROBOT: [u8; 3] = [70, 80, 95];
pub const PLANNED: [u8; 3] = [130, 185, 245];
pub const GOAL: [u8; 3] = [215, 30, 30];
pub const START: [u8; 3] = [20, 160, 60];
const BACKGROUND: [u8; 3] = [255, 255, 255];
const INK: [u8; 3] = [0, 0, 0];
const FRAME: [u8; 3] = [180, 180, 180];

/// Trace colours, by method (trace) index, repeating past the end; none is close to the map's.
pub const PALETTE: [[u8; 3]; 8] = [
    [20, 60, 200],
    [235, 120, 0],
    [20, 140, 40],
    [150, 40, 170],
    [190, 0, 60],
    [0, 130, 130],
    [110, 80, 20],
    [230, 0, 200],
];

/// The colour of the trace or method with index `i`.
#[must_use]
pub fn trace_colour(i: usize) -> [u8; 3] {
    PALETTE[i % PALETTE.len()]
}

// ---------------------------------------------------------------------------------------------
// Text: a 5×7 bitmap font.

const GLYPH_W: i64 = 5;
const GLYPH_H: i64 = 7;

/// Rows of a glyph, top first; bit 4 is the leftmost column. Letters are drawn as capitals
/// (either case maps to them) because 5×7 lower case is hard to read.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_lowercase() {
        'a' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'b' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'c' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'd' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'e' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'f' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'g' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'h' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'i' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'j' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'k' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'l' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'm' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'n' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'o' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'p' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'r' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        's' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        't' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'u' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'v' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'w' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'x' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        ' ' => [0; 7],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        // Anything else: a question mark, so a missing glyph shows rather than vanishes.
        _ => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04],
    }
}

/// Width in pixels of `text` at integer `scale` (one blank column between glyphs).
fn text_width_px(text: &str, scale: i64) -> i64 {
    let n = i64::try_from(text.chars().count()).unwrap_or(i64::MAX / 64);
    (n * (GLYPH_W + 1) - 1).max(0) * scale
}

// ---------------------------------------------------------------------------------------------
// Canvas: clipped pixel drawing.

/// A pixel rectangle, `x0..x1` × `y0..y1`.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
}

struct Canvas {
    img: RgbImage,
    /// Drawing outside it is dropped, so a grid cell never spills into its neighbours.
    clip: Rect,
}

impl Canvas {
    fn new(w: u32, h: u32) -> Self {
        let img = RgbImage::from_pixel(w, h, Rgb(BACKGROUND));
        let clip = Rect {
            x0: 0,
            y0: 0,
            x1: i64::from(w),
            y1: i64::from(h),
        };
        Self { img, clip }
    }

    fn full(&self) -> Rect {
        Rect {
            x0: 0,
            y0: 0,
            x1: i64::from(self.img.width()),
            y1: i64::from(self.img.height()),
        }
    }

    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        let r = self.clip;
        if x >= r.x0 && x < r.x1 && y >= r.y0 && y < r.y1 {
            if let (Ok(u), Ok(v)) = (u32::try_from(x), u32::try_from(y)) {
                if u < self.img.width() && v < self.img.height() {
                    self.img.put_pixel(u, v, Rgb(c));
                }
            }
        }
    }

    fn fill_rect(&mut self, r: Rect, c: [u8; 3]) {
        for y in r.y0..r.y1 {
            for x in r.x0..r.x1 {
                self.put(x, y, c);
            }
        }
    }

    fn outline_rect(&mut self, r: Rect, c: [u8; 3]) {
        for x in r.x0..r.x1 {
            self.put(x, r.y0, c);
            self.put(x, r.y1 - 1, c);
        }
        for y in r.y0..r.y1 {
            self.put(r.x0, y, c);
            self.put(r.x1 - 1, y, c);
        }
    }

    /// A filled disc of radius `r` px around pixel (x, y).
    fn disc(&mut self, x: i64, y: i64, r: i64, c: [u8; 3]) {
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r * r + r {
                    self.put(x + dx, y + dy, c);
                }
            }
        }
    }

    /// A square brush of `width` px centred on (x, y).
    fn stamp(&mut self, x: i64, y: i64, width: i64, c: [u8; 3]) {
        let lo = -(width - 1) / 2;
        for dy in lo..lo + width {
            for dx in lo..lo + width {
                self.put(x + dx, y + dy, c);
            }
        }
    }

    /// Bresenham from `a` to `b` with a `width` px brush. With a dash pattern `(on, off)` in
    /// pixels, `phase` counts the pixels already drawn along the polyline so the pattern runs on
    /// across segments.
    fn line(
        &mut self,
        a: (i64, i64),
        b: (i64, i64),
        width: i64,
        c: [u8; 3],
        dash: Option<(i64, i64)>,
        phase: &mut i64,
    ) {
        let (mut x, mut y) = a;
        let (dx, dy) = ((b.0 - a.0).abs(), -(b.1 - a.1).abs());
        let (sx, sy) = (
            if a.0 < b.0 { 1 } else { -1 },
            if a.1 < b.1 { 1 } else { -1 },
        );
        let mut err = dx + dy;
        // Bounded by the number of pixels on the line; guards against a runaway loop.
        for _ in 0..=(dx - dy + 1) {
            let on = dash.is_none_or(|(on, off)| phase.rem_euclid(on + off) < on);
            if on {
                self.stamp(x, y, width, c);
            }
            *phase += 1;
            if (x, y) == b {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// `text` with its top-left corner at (x, y), each font pixel a `scale`² block.
    fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, c: [u8; 3]) {
        let mut gx = x;
        for ch in text.chars() {
            for (row, bits) in (0_i64..).zip(glyph(ch)) {
                for col in 0..GLYPH_W {
                    if bits & (0x10 >> col) != 0 {
                        for sy in 0..scale {
                            for sx in 0..scale {
                                self.put(gx + col * scale + sx, y + row * scale + sy, c);
                            }
                        }
                    }
                }
            }
            gx += (GLYPH_W + 1) * scale;
        }
    }

    /// `text` on a white box with a 1 px margin, so it reads over the map.
    fn label(&mut self, x: i64, y: i64, text: &str, scale: i64, c: [u8; 3]) {
        let r = Rect {
            x0: x - 1,
            y0: y - 1,
            x1: x + text_width_px(text, scale) + 1,
            y1: y + GLYPH_H * scale + 1,
        };
        self.fill_rect(r, BACKGROUND);
        self.text(x, y, text, scale, c);
    }
}

// ---------------------------------------------------------------------------------------------
// Map view: where the map lies on the canvas.

/// The plan's grid drawn into a pixel rectangle, north (grid +y) up.
struct View<'w> {
    grid: &'w OccupancyGrid,
    /// Pixel position of grid point (0, height).
    off_x: f64,
    off_y: f64,
    px_per_cell: f64,
}

impl<'w> View<'w> {
    /// The grid scaled to fit `r` (less `pad` px each side) and centred in it.
    fn fit(grid: &'w OccupancyGrid, r: Rect, pad: i64) -> Self {
        let (wc, hc) = (
            f64::from(grid.width_cells().max(1)),
            f64::from(grid.height_cells().max(1)),
        );
        #[allow(clippy::cast_precision_loss)]
        let (aw, ah) = (
            ((r.x1 - r.x0 - 2 * pad).max(1)) as f64,
            ((r.y1 - r.y0 - 2 * pad).max(1)) as f64,
        );
        let s = (aw / wc).min(ah / hc);
        #[allow(clippy::cast_precision_loss)]
        let (off_x, off_y) = (
            r.x0 as f64 + 0.5 * ((r.x1 - r.x0) as f64 - s * wc),
            r.y0 as f64 + 0.5 * ((r.y1 - r.y0) as f64 - s * hc),
        );
        Self {
            grid,
            off_x,
            off_y,
            px_per_cell: s,
        }
    }

    /// The grid at `px_per_m` with its top-left corner at pixel (0, 0).
    fn at_scale(grid: &'w OccupancyGrid, px_per_m: f64) -> Self {
        Self {
            grid,
            off_x: 0.0,
            off_y: 0.0,
            px_per_cell: px_per_m * grid.resolution_m(),
        }
    }

    fn px_per_m(&self) -> f64 {
        self.px_per_cell / self.grid.resolution_m()
    }

    /// The pixel of a map-frame point.
    fn to_px(&self, x_m: f64, y_m: f64) -> (i64, i64) {
        let (gx, gy) = self.grid.world_to_grid(x_m, y_m);
        let h = f64::from(self.grid.height_cells());
        let (u, v) = (
            self.off_x + gx * self.px_per_cell,
            self.off_y + (h - gy) * self.px_per_cell,
        );
        // Saturating float-to-int casts are the intent for points far off the picture.
        #[allow(clippy::cast_possible_truncation)]
        (u.floor() as i64, v.floor() as i64)
    }

    /// The map-frame point at the centre of pixel (x, y).
    fn to_world(&self, x: i64, y: i64) -> (f64, f64) {
        let h = f64::from(self.grid.height_cells());
        #[allow(clippy::cast_precision_loss)]
        let (gx, gy) = (
            (x as f64 + 0.5 - self.off_x) / self.px_per_cell,
            h - (y as f64 + 0.5 - self.off_y) / self.px_per_cell,
        );
        self.grid.geometry().grid_to_world(gx, gy)
    }

    /// The pixel rectangle the grid covers.
    fn bounds(&self) -> Rect {
        let (w, h) = (
            f64::from(self.grid.width_cells()) * self.px_per_cell,
            f64::from(self.grid.height_cells()) * self.px_per_cell,
        );
        #[allow(clippy::cast_possible_truncation)]
        Rect {
            x0: self.off_x.round() as i64,
            y0: self.off_y.round() as i64,
            x1: (self.off_x + w).round() as i64,
            y1: (self.off_y + h).round() as i64,
        }
    }
}

/// Marker sizes: the scenario picture draws them larger than a grid cell does.
#[derive(Debug, Clone, Copy)]
struct Style {
    trace_px: i64,
    planned_px: i64,
    dash_px: (i64, i64),
    goal_px: i64,
    mark_px: i64,
    text_scale: i64,
}

const BIG: Style = Style {
    trace_px: 2,
    planned_px: 3,
    dash_px: (10, 6),
    goal_px: 6,
    mark_px: 6,
    text_scale: 2,
};

const SMALL: Style = Style {
    trace_px: 1,
    planned_px: 2,
    dash_px: (6, 4),
    goal_px: 3,
    mark_px: 3,
    text_scale: 1,
};

/// The plan (walls grey, free white, unknown light grey) with the ground-truth furniture,
/// parked robots and glass drawn in, inside the view's bounds.
fn draw_map(cv: &mut Canvas, view: &View<'_>, world: &World) {
    let parked_radius_m = world.config.base.radius_m;
    let b = view.bounds();
    // Glass is at least 3 px thick: a 4 cm pane is under one pixel at these scales.
    let glass_reach_m = 1.5 / view.px_per_m();
    for y in b.y0..b.y1 {
        for x in b.x0..b.x1 {
            let (wx, wy) = view.to_world(x, y);
            let (cx, cy) = view.grid.world_to_cell(wx, wy);
            let mut c = match view.grid.class_at(cx, cy) {
                CellClass::Free => FREE,
                CellClass::Occupied => WALL,
                CellClass::Unknown => UNKNOWN,
            };
            if world
                .furniture
                .iter()
                .any(|f| f.shape.distance(wx, wy) <= 0.0)
            {
                c = FURNITURE;
            }
            if world
                .scenario
                .parked_robots
                .iter()
                .any(|p| (p.x_m - wx).hypot(p.y_m - wy) <= parked_radius_m)
            {
                c = PARKED_ROBOT;
            }
            if world
                .glass
                .iter()
                .any(|g| g.shape.distance(wx, wy) <= glass_reach_m)
            {
                c = GLASS;
            }
            cv.put(x, y, c);
        }
    }
}

/// A map-frame polyline; points further apart than `gap_m` are not joined.
fn draw_polyline(
    cv: &mut Canvas,
    view: &View<'_>,
    pts: &[(f64, f64)],
    width: i64,
    c: [u8; 3],
    dash: Option<(i64, i64)>,
    gap_m: f64,
) {
    let mut phase = 0;
    if let [only] = pts {
        let p = view.to_px(only.0, only.1);
        cv.stamp(p.0, p.1, width, c);
    }
    for pair in pts.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if (b.0 - a.0).hypot(b.1 - a.1) > gap_m {
            continue;
        }
        cv.line(
            view.to_px(a.0, a.1),
            view.to_px(b.0, b.1),
            width,
            c,
            dash,
            &mut phase,
        );
    }
}

/// An X (intervention) centred on `p`.
fn draw_cross(cv: &mut Canvas, p: (i64, i64), r: i64, width: i64, c: [u8; 3]) {
    let mut phase = 0;
    cv.line(
        (p.0 - r, p.1 - r),
        (p.0 + r, p.1 + r),
        width,
        c,
        None,
        &mut phase,
    );
    cv.line(
        (p.0 - r, p.1 + r),
        (p.0 + r, p.1 - r),
        width,
        c,
        None,
        &mut phase,
    );
}

/// A hollow square (collision) centred on `p`.
fn draw_square(cv: &mut Canvas, p: (i64, i64), r: i64, width: i64, c: [u8; 3]) {
    for k in 0..width {
        cv.outline_rect(
            Rect {
                x0: p.0 - r - k,
                y0: p.1 - r - k,
                x1: p.0 + r + k + 1,
                y1: p.1 + r + k + 1,
            },
            c,
        );
    }
}

fn draw_trace(cv: &mut Canvas, view: &View<'_>, t: &Trace<'_>, c: [u8; 3], st: Style) {
    draw_polyline(cv, view, t.points_m, st.trace_px, c, None, TRACE_GAP_M);
    for &(x, y) in t.interventions_m {
        draw_cross(cv, view.to_px(x, y), st.mark_px, st.trace_px.max(2), c);
    }
    for &(x, y) in t.collisions_m {
        draw_square(cv, view.to_px(x, y), st.mark_px, st.trace_px, c);
    }
}

/// The start (green disc with a heading tick) and the goals (red discs numbered from 1).
fn draw_start_and_goals(
    cv: &mut Canvas,
    view: &View<'_>,
    world: &World,
    goals_m: &[(f64, f64)],
    st: Style,
) {
    let start = world.scenario.start;
    let p = view.to_px(start.x_m, start.y_m);
    let tick_m = 3.0 * st.goal_px as f64 / view.px_per_m();
    let q = view.to_px(
        start.x_m + tick_m * start.yaw_rad.cos(),
        start.y_m + tick_m * start.yaw_rad.sin(),
    );
    let mut phase = 0;
    cv.line(p, q, st.trace_px.max(2), START, None, &mut phase);
    cv.disc(p.0, p.1, st.goal_px, START);
    for (i, &(x, y)) in goals_m.iter().enumerate() {
        let p = view.to_px(x, y);
        cv.disc(p.0, p.1, st.goal_px, GOAL);
        let n = (i + 1).to_string();
        cv.label(
            p.0 + st.goal_px + 1,
            p.1 - st.goal_px - GLYPH_H * st.text_scale,
            &n,
            st.text_scale,
            INK,
        );
    }
}

/// The floor plan (crude plan, grey/white) with the ground-truth furniture and glass drawn in
/// (glass tinted cyan), the goals numbered from 1, the start, the planned path (dashed light
/// blue; the planner's first path of every leg) and each method's driven trace in its own
/// colour ([`trace_colour`] by index in `traces`) with its interventions (X) and collisions
/// (hollow squares). Scale [`SCENARIO_PX_PER_M`]; a legend below names the traces.
#[must_use]
pub fn scenario_picture(
    world: &World,
    planned_m: &[(f64, f64)],
    goals_m: &[(f64, f64)],
    traces: &[Trace<'_>],
) -> RgbImage {
    let view = View::at_scale(&world.plan, SCENARIO_PX_PER_M);
    let map = view.bounds();
    let st = BIG;
    let line_h = GLYPH_H * st.text_scale + 8;
    let legend_h = if traces.is_empty() {
        0
    } else {
        let n = i64::try_from(traces.len()).unwrap_or(0);
        8 + (n + 1) * line_h
    };
    let (w, h) = (map.x1.max(1), map.y1.max(1) + legend_h);
    let mut cv = Canvas::new(
        u32::try_from(w).unwrap_or(u32::MAX),
        u32::try_from(h).unwrap_or(u32::MAX),
    );
    cv.clip = map;
    draw_map(&mut cv, &view, world);
    draw_polyline(
        &mut cv,
        &view,
        planned_m,
        st.planned_px,
        PLANNED,
        Some(st.dash_px),
        f64::INFINITY,
    );
    for (i, t) in traces.iter().enumerate() {
        draw_trace(&mut cv, &view, t, trace_colour(i), st);
    }
    draw_start_and_goals(&mut cv, &view, world, goals_m, st);
    cv.clip = cv.full();
    if !traces.is_empty() {
        let mut y = map.y1 + 8;
        for (i, t) in traces.iter().enumerate() {
            let c = trace_colour(i);
            let mid = y + GLYPH_H * st.text_scale / 2;
            let mut phase = 0;
            cv.line((8, mid), (40, mid), st.trace_px + 1, c, None, &mut phase);
            cv.text(48, y, t.label, st.text_scale, INK);
            y += line_h;
        }
        let mid = y + GLYPH_H * st.text_scale / 2;
        draw_cross(&mut cv, (16, mid), st.mark_px, 2, INK);
        cv.text(30, y, "intervention", st.text_scale, INK);
        let x = 30 + text_width_px("intervention", st.text_scale) + 24;
        draw_square(&mut cv, (x + 8, mid), st.mark_px, 2, INK);
        cv.text(x + 22, y, "collision", st.text_scale, INK);
        let x = x + 22 + text_width_px("collision", st.text_scale) + 24;
        let mut phase = 0;
        cv.line(
            (x, mid),
            (x + 32, mid),
            st.planned_px,
            PLANNED,
            Some(st.dash_px),
            &mut phase,
        );
        cv.text(x + 40, y, "planned", st.text_scale, INK);
    }
    cv.img
}

/// Space around and between grid cells, in pixels.
const GRID_GAP_PX: i64 = 6;
/// Scale of the grid's row and column labels.
const GRID_TEXT_SCALE: i64 = 2;

/// The grid's layout: label column width, header height, cell pitch.
fn grid_layout(rows: &[GridRow<'_>], cell_px: i64) -> (i64, i64, i64) {
    let label_w = rows
        .iter()
        .map(|r| text_width_px(r.label, GRID_TEXT_SCALE))
        .max()
        .unwrap_or(0)
        + 2 * GRID_GAP_PX;
    let header_h = GLYPH_H * GRID_TEXT_SCALE + 2 * GRID_GAP_PX;
    (label_w, header_h, cell_px + GRID_GAP_PX)
}

/// One grid image like the paper's Figure 5: a row per scenario, columns "task" (the plan with
/// furniture, glass, goals and the planned path) and then one per method (the plan with that
/// method's trace only: the trace in `row.traces` whose label is the method's name, in the
/// method's colour, [`trace_colour`] by index in `methods`). Row labels on the left, column
/// labels on top; each cell is `cell_px` square (at least 32) with the map fitted inside.
#[must_use]
pub fn grid_picture(rows: &[GridRow<'_>], methods: &[&str], cell_px: u32) -> RgbImage {
    let cell = i64::from(cell_px.max(32));
    let (label_w, header_h, pitch) = grid_layout(rows, cell);
    let cols = i64::try_from(methods.len()).unwrap_or(0) + 1;
    let nrows = i64::try_from(rows.len()).unwrap_or(0);
    let w = label_w + cols * pitch;
    let h = header_h + nrows * pitch;
    let mut cv = Canvas::new(
        u32::try_from(w).unwrap_or(u32::MAX),
        u32::try_from(h).unwrap_or(u32::MAX),
    );
    let col_rect = |j: i64, i: i64| Rect {
        x0: label_w + j * pitch,
        y0: header_h + i * pitch,
        x1: label_w + j * pitch + cell,
        y1: header_h + i * pitch + cell,
    };
    for (j, name) in (0_i64..).zip(std::iter::once("task").chain(methods.iter().copied())) {
        let r = col_rect(j, 0);
        cv.clip = Rect {
            y0: 0,
            y1: header_h,
            ..r
        };
        let x = r.x0 + ((cell - text_width_px(name, GRID_TEXT_SCALE)) / 2).max(0);
        cv.text(x, GRID_GAP_PX, name, GRID_TEXT_SCALE, INK);
    }
    let st = SMALL;
    for (i, row) in (0_i64..).zip(rows) {
        let r = col_rect(0, i);
        cv.clip = cv.full();
        let y = r.y0 + (cell - GLYPH_H * GRID_TEXT_SCALE) / 2;
        cv.text(GRID_GAP_PX, y, row.label, GRID_TEXT_SCALE, INK);
        for j in 0..cols {
            let r = col_rect(j, i);
            cv.clip = r;
            let view = View::fit(&row.world.plan, r, 4);
            draw_map(&mut cv, &view, row.world);
            if j == 0 {
                draw_polyline(
                    &mut cv,
                    &view,
                    row.planned_m,
                    st.planned_px,
                    PLANNED,
                    Some(st.dash_px),
                    f64::INFINITY,
                );
            } else {
                let m = usize::try_from(j - 1).unwrap_or(0);
                let name = methods.get(m).copied().unwrap_or_default();
                if let Some(t) = row.traces.iter().find(|t| t.label == name) {
                    draw_trace(&mut cv, &view, t, trace_colour(m), st);
                }
            }
            draw_start_and_goals(&mut cv, &view, row.world, row.goals_m, st);
            cv.outline_rect(r, FRAME);
        }
    }
    cv.img
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::SimConfig;

    fn world(name: &str) -> World {
        World::from_scenario_file(&test_support::scenario(name), SimConfig::default()).unwrap()
    }

    fn px(img: &RgbImage, p: (i64, i64)) -> [u8; 3] {
        img.get_pixel(u32::try_from(p.0).unwrap(), u32::try_from(p.1).unwrap())
            .0
    }

    #[test]
    fn every_character_the_labels_use_has_its_own_glyph() {
        let unknown = glyph('~');
        let chars = "abcdefghijklmnopqrstuvwxyz0123456789-_.";
        for c in chars.chars() {
            assert_ne!(glyph(c), unknown, "{c:?}");
            assert_eq!(glyph(c), glyph(c.to_ascii_uppercase()), "{c:?}");
        }
        let glyphs: std::collections::BTreeSet<[u8; 7]> = chars.chars().map(glyph).collect();
        assert_eq!(glyphs.len(), chars.len(), "two characters share a glyph");
        assert_eq!(glyph(' '), [0; 7]);
        assert_eq!(text_width_px("ab", 2), 22);
        assert_eq!(text_width_px("", 2), 0);
    }

    #[test]
    fn scenario_picture_shows_parked_robots() {
        let w = world("behaviour_robot_parked");
        let parked = w.scenario.parked_robots[0];
        let img = scenario_picture(&w, &[], &[], &[]);
        let view = View::at_scale(&w.plan, SCENARIO_PX_PER_M);
        assert_eq!(px(&img, view.to_px(parked.x_m, parked.y_m)), PARKED_ROBOT);
        assert_eq!(
            px(&img, view.to_px(parked.x_m + 0.4, parked.y_m)),
            FREE,
            "a disc of the robot's radius"
        );
    }

    #[test]
    fn scenario_picture_shows_plan_glass_furniture_path_and_trace() {
        let w = world("task_a");
        // Along the south corridor (y 3..5), past the box at (8.0, 3.35).
        let trace: Vec<(f64, f64)> = (0..=90).map(|k| (3.0 + 0.1 * f64::from(k), 4.4)).collect();
        let interventions = [(20.0, 10.0)];
        let collisions = [(22.0, 4.0)];
        let traces = [Trace {
            label: "lpe-net",
            points_m: &trace,
            interventions_m: &interventions,
            collisions_m: &collisions,
        }];
        let planned = [(13.0, 12.0), (13.0, 16.0)];
        let goals = [(13.0, 10.0), (23.0, 4.0)];
        let img = scenario_picture(&w, &planned, &goals, &traces);
        let view = View::at_scale(&w.plan, SCENARIO_PX_PER_M);
        // 26 m x 20 m at 25 px/m, plus the legend.
        assert_eq!(img.width(), 650);
        assert!(img.height() > 500 && img.height() < 600, "{}", img.height());
        assert_eq!(px(&img, view.to_px(10.0, 4.4)), trace_colour(0));
        // task_a's glass door: panes at x = 8 from y 9.0 to 9.4 and 10.6 to 11.0.
        assert_eq!(px(&img, view.to_px(8.0, 9.2)), GLASS);
        assert_eq!(px(&img, view.to_px(8.0, 10.8)), GLASS);
        assert_eq!(px(&img, view.to_px(8.0, 10.0)), FREE, "the doorway is open");
        assert_eq!(px(&img, view.to_px(8.0, 3.3)), FURNITURE);
        assert_eq!(px(&img, view.to_px(1.0, 1.0)), WALL);
        assert_eq!(px(&img, view.to_px(18.0, 10.0)), FREE);
        assert_eq!(px(&img, view.to_px(13.0, 12.0)), PLANNED);
        assert_eq!(
            px(&img, view.to_px(20.0, 10.0)),
            trace_colour(0),
            "intervention X"
        );
        let c = view.to_px(22.0, 4.0);
        assert_eq!(
            px(&img, (c.0 - BIG.mark_px, c.1)),
            trace_colour(0),
            "collision square"
        );
        assert_eq!(px(&img, view.to_px(13.0, 10.0)), GOAL);
        assert_eq!(px(&img, view.to_px(3.0, 4.0)), START);
        // The legend holds ink.
        let legend_ink = (500..img.height())
            .flat_map(|y| (0..img.width()).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == INK)
            .count();
        assert!(legend_ink > 100, "{legend_ink}");
    }

    #[test]
    fn a_carried_robot_is_not_drawn_driving_through_walls() {
        let w = world("task_a");
        // From the south corridor to the middle one: carried, not driven.
        let trace = [(3.0, 4.0), (3.0, 4.1), (6.0, 10.0), (6.0, 10.1)];
        let traces = [Trace {
            label: "x",
            points_m: &trace,
            interventions_m: &[],
            collisions_m: &[],
        }];
        let img = scenario_picture(&w, &[], &[], &traces);
        let view = View::at_scale(&w.plan, SCENARIO_PX_PER_M);
        assert_eq!(px(&img, view.to_px(4.5, 7.0)), WALL);
    }

    #[test]
    fn grid_has_a_row_per_scenario_and_a_column_per_method_plus_the_task() {
        let (a, e) = (world("task_a"), world("task_e"));
        let trace: Vec<(f64, f64)> = (0..=90).map(|k| (3.0 + 0.1 * f64::from(k), 4.4)).collect();
        let traces_a = [
            Trace {
                label: "lpe-net",
                points_m: &trace,
                interventions_m: &[],
                collisions_m: &[],
            },
            Trace {
                label: "dlm-net",
                points_m: &trace,
                interventions_m: &[],
                collisions_m: &[],
            },
        ];
        let planned = [(3.0, 4.0), (13.0, 4.0), (13.0, 10.0)];
        let goals = [(13.0, 10.0)];
        let rows = [
            GridRow {
                label: "task_a",
                world: &a,
                planned_m: &planned,
                goals_m: &goals,
                traces: &traces_a,
            },
            GridRow {
                label: "task_e",
                world: &e,
                planned_m: &[],
                goals_m: &[],
                traces: &[],
            },
        ];
        let methods = ["dlm-net", "lpe-net", "path-tracker"];
        let img = grid_picture(&rows, &methods, 256);
        let label_w = text_width_px("task_a", GRID_TEXT_SCALE) + 2 * GRID_GAP_PX;
        let header_h = GLYPH_H * GRID_TEXT_SCALE + 2 * GRID_GAP_PX;
        let pitch = 256 + GRID_GAP_PX;
        assert_eq!(i64::from(img.width()), label_w + 4 * pitch);
        assert_eq!(i64::from(img.height()), header_h + 2 * pitch);
        let count = |j: i64, i: i64, c: [u8; 3]| {
            let (x0, y0) = (label_w + j * pitch, header_h + i * pitch);
            (y0..y0 + 256)
                .flat_map(|y| (x0..x0 + 256).map(move |x| (x, y)))
                .filter(|&p| px(&img, p) == c)
                .count()
        };
        // Each method's column holds its own trace in its own colour, and only that.
        assert!(count(1, 0, trace_colour(0)) > 20);
        assert_eq!(count(1, 0, trace_colour(1)), 0);
        assert!(count(2, 0, trace_colour(1)) > 20);
        assert_eq!(count(3, 0, trace_colour(2)), 0, "no path-tracker run");
        assert_eq!(
            count(0, 0, trace_colour(0)),
            0,
            "the task column has no trace"
        );
        assert!(count(0, 0, PLANNED) > 10);
        assert!(count(0, 1, WALL) > 1000, "task_e's maze is drawn");
        // Labels: ink left of the cells and above them.
        let ink_in = |x0: i64, x1: i64, y0: i64, y1: i64| {
            (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .filter(|&p| px(&img, p) == INK)
                .count()
        };
        assert!(ink_in(0, label_w, header_h, header_h + 256) > 50);
        assert!(ink_in(label_w, label_w + 256, 0, header_h) > 50);
    }
}
