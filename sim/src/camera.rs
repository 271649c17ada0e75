//! The monocular camera: a column ray-caster over the wall grid plus analytic sprites.
//!
//! One ray per image column walks the wall grid (DDA); furniture, glass, people and robots are
//! intersected analytically along the same ray and painted far to near over the wall, floor and
//! ceiling of that column. Per-row floor and ceiling distances and the distance fall-off are
//! cached in a [`CameraModel`], so each pixel costs a couple of table look-ups. The reference
//! [`render_per_pixel`] casts the whole ray again for every pixel (what a per-pixel ray caster
//! does) and must give the very same image; the benchmark compares the two.

use protocol::{Image, ImageEncoding, Pose2D};

use crate::appearance::{Appearance, TEX, TEXELS_PER_M};
use crate::config::CameraConfig;
use crate::geom::ray_disc;
use crate::world::{SimError, World};

/// Forward offset of the camera from the robot centre.
pub const CAMERA_FORWARD_M: f64 = 0.15;
const FOG: [u8; 3] = [40, 40, 44];
const SKIN: [u8; 3] = [205, 160, 130];
const HAIR: [u8; 3] = [50, 35, 25];

/// Per-camera tables that do not depend on the pose.
#[derive(Debug, Clone)]
pub struct CameraModel {
    width: usize,
    height: usize,
    focal_px: f64,
    cam_h: f64,
    wall_h: f64,
    max_range_m: f64,
    /// Lateral offset of each column's ray on the unit-depth image plane (left positive).
    col_offset: Vec<f64>,
    /// Perpendicular depth of the floor (below the horizon) or ceiling (above) at each row.
    row_depth: Vec<f64>,
    /// Distance fall-off of each row's floor or ceiling, in 1/256 units.
    row_falloff_q8: Vec<u32>,
}

#[inline]
fn falloff(z: f64) -> f64 {
    1.0 / (1.0 + 0.07 * z)
}

#[inline]
fn shade(c: [u8; 3], k_q8: u32) -> [u8; 3] {
    // min(255) makes the narrowing exact.
    #[allow(clippy::cast_possible_truncation)]
    c.map(|v| ((u32::from(v) * k_q8) >> 8).min(255) as u8)
}

#[inline]
fn blend(under: [u8; 3], over: [u8; 3], alpha_q8: u32) -> [u8; 3] {
    let mut out = [0u8; 3];
    for k in 0..3 {
        let v = (u32::from(under[k]) * (256 - alpha_q8) + u32::from(over[k]) * alpha_q8) >> 8;
        #[allow(clippy::cast_possible_truncation)]
        {
            out[k] = v.min(255) as u8;
        }
    }
    out
}

#[inline]
fn q8(k: f64) -> u32 {
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    let v = (k * 256.0).clamp(0.0, 65535.0) as u32;
    v
}

impl CameraModel {
    pub fn new(c: &CameraConfig) -> Self {
        let width = c.width_px as usize;
        let height = c.height_px as usize;
        #[allow(clippy::cast_precision_loss)]
        let (wf, hf) = (width as f64, height as f64);
        let focal_px = 0.5 * wf / (0.5 * c.hfov_rad).tan();
        #[allow(clippy::cast_precision_loss)]
        let col_offset = (0..width)
            .map(|col| (0.5 * wf - col as f64 - 0.5) / focal_px)
            .collect();
        let mut row_depth = Vec::with_capacity(height);
        let mut row_falloff_q8 = Vec::with_capacity(height);
        for r in 0..height {
            #[allow(clippy::cast_precision_loss)]
            let yc = 0.5 * hf - (r as f64 + 0.5);
            let z = if yc < 0.0 {
                c.height_m * focal_px / -yc
            } else {
                (c.wall_height_m - c.height_m) * focal_px / yc.max(1e-9)
            };
            row_depth.push(z);
            row_falloff_q8.push(q8(falloff(z)));
        }
        Self {
            width,
            height,
            focal_px,
            cam_h: c.height_m,
            wall_h: c.wall_height_m,
            max_range_m: c.max_range_m,
            col_offset,
            row_depth,
            row_falloff_q8,
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Height above the floor seen at the centre of row `r` at perpendicular depth `z`.
    #[inline]
    fn height_at(&self, r: usize, z: f64) -> f64 {
        #[allow(clippy::cast_precision_loss)]
        let yc = 0.5 * self.height as f64 - (r as f64 + 0.5);
        self.cam_h + yc * z / self.focal_px
    }

    /// Rows (clipped to `rows`) whose centres see heights in [h0, h1) at depth z.
    #[inline]
    fn rows_for(&self, h0: f64, h1: f64, z: f64, rows: (usize, usize)) -> (usize, usize) {
        #[allow(clippy::cast_precision_loss)]
        let half = 0.5 * self.height as f64;
        let to_row = |h: f64| half - (h - self.cam_h) * self.focal_px / z - 0.5;
        // Row r sees height h(r), decreasing in r: rows from to_row(h1) to to_row(h0).
        let top = to_row(h1).ceil().max(0.0);
        let bottom = to_row(h0).floor() + 1.0;
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let (a, b) = (top as usize, bottom.max(0.0) as usize);
        (a.max(rows.0), b.min(rows.1))
    }
}

/// Something drawn over the walls in one column.
#[derive(Debug, Clone, Copy)]
enum Sprite {
    Furniture {
        t_in: f64,
        t_out: f64,
        index: usize,
        face: u8,
        edge: bool,
    },
    Glass {
        t: f64,
        index: usize,
        local_x: f64,
    },
    Person {
        t: f64,
        lateral: f64,
        index: usize,
    },
    Robot {
        t: f64,
        lateral: f64,
    },
}

impl Sprite {
    fn t(&self) -> f64 {
        match *self {
            Sprite::Furniture { t_in, .. } => t_in,
            Sprite::Glass { t, .. } | Sprite::Person { t, .. } | Sprite::Robot { t, .. } => t,
        }
    }
}

/// Renders rows `rows.0..rows.1` of column `col` into `px` (indexed by row).
#[allow(clippy::too_many_lines, clippy::too_many_arguments)]
fn render_column(
    world: &World,
    model: &CameraModel,
    cam: (f64, f64, f64),
    skip_robot: Option<usize>,
    col: usize,
    rows: (usize, usize),
    sprites: &mut Vec<Sprite>,
    px: &mut [[u8; 3]],
) {
    let (cx, cy, yaw) = cam;
    let (s, c) = yaw.sin_cos();
    let off = model.col_offset[col];
    // Unnormalized ray with unit forward component: a point at perpendicular depth z is at
    // cam + z * (rx, ry).
    let rx = c - s * off;
    let ry = s + c * off;
    let norm = rx.hypot(ry);
    let (dx, dy) = (rx / norm, ry / norm);
    let cos_theta = 1.0 / norm;
    let max_t = model.max_range_m * norm;
    let wall = world.walls.cast(cx, cy, dx, dy, max_t);
    let t_wall = wall.map_or(f64::INFINITY, |h| h.dist_m);
    let z_wall = t_wall * cos_theta;
    let app = &world.appearance;

    // Background: wall, floor, ceiling.
    let mut wall_style = None;
    let mut wall_tex_col = 0usize;
    let mut wall_k = 0u32;
    if let Some(h) = wall {
        // The look of the area the ray comes from, just before the wall face.
        let (ax, ay) = world.walls.cell_of(h.x_m - 0.02 * dx, h.y_m - 0.02 * dy);
        let style = &app.styles[app.area_at_cell(ax, ay)];
        wall_tex_col = Appearance::wall_column(h.along_m);
        let side_k = if h.side == 0 { 1.0 } else { 0.8 };
        wall_k = (style.light_q8 * q8(side_k * falloff(z_wall))) >> 8;
        wall_style = Some(style);
    }
    for (r, out) in px.iter_mut().enumerate().take(rows.1).skip(rows.0) {
        if let Some(style) = wall_style {
            let hh = model.height_at(r, z_wall);
            if (0.0..model.wall_h).contains(&hh) {
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let tr = ((hh * TEXELS_PER_M) as usize).min(style.wall_rows - 1);
                *out = shade(style.wall[tr * TEX + wall_tex_col], wall_k);
                continue;
            }
        }
        let z = model.row_depth[r];
        if z > model.max_range_m {
            *out = FOG;
            continue;
        }
        let (x, y) = (cx + z * rx, cy + z * ry);
        let (gx, gy) = world.walls.cell_of(x, y);
        let style = &app.styles[app.area_at_cell(gx, gy)];
        let k = (style.light_q8 * model.row_falloff_q8[r]) >> 8;
        let tex = if model.height_at(r, 1.0) < model.cam_h {
            &style.floor
        } else {
            &style.ceiling
        };
        *out = shade(tex[Appearance::flat_index(x, y)], k);
    }

    // Sprites in front of the wall, painted far to near.
    sprites.clear();
    for (index, f) in world.furniture.iter().enumerate() {
        if let Some(sp) = f.shape.ray(cx, cy, dx, dy) {
            if sp.t_in < t_wall && sp.t_in > 0.0 {
                let along = if sp.face == 0 {
                    sp.local_y / f.shape.hy
                } else {
                    sp.local_x / f.shape.hx
                };
                sprites.push(Sprite::Furniture {
                    t_in: sp.t_in,
                    t_out: sp.t_out.min(t_wall),
                    index,
                    face: sp.face,
                    edge: along.abs() > 0.96,
                });
            }
        }
    }
    for (index, g) in world.glass.iter().enumerate() {
        if let Some(sp) = g.shape.ray(cx, cy, dx, dy) {
            if sp.t_in < t_wall && sp.t_in > 0.0 {
                sprites.push(Sprite::Glass {
                    t: sp.t_in,
                    index,
                    local_x: sp.local_x,
                });
            }
        }
    }
    for (index, p) in world.people.iter().enumerate() {
        if let Some((t, lateral)) = ray_disc(cx, cy, dx, dy, p.x_m, p.y_m, p.radius_m) {
            if t < t_wall && t > 0.0 {
                sprites.push(Sprite::Person { t, lateral, index });
            }
        }
    }
    let rr = world.config.base.radius_m;
    for (j, robot) in world.robots.iter().enumerate() {
        if Some(j) == skip_robot {
            continue;
        }
        if let Some((t, lateral)) = ray_disc(cx, cy, dx, dy, robot.pose.x_m, robot.pose.y_m, rr) {
            if t < t_wall && t > 0.0 {
                sprites.push(Sprite::Robot {
                    t,
                    lateral: lateral / rr,
                });
            }
        }
    }
    // Few sprites per column: a stable insertion sort keeps the order deterministic.
    for i in 1..sprites.len() {
        let mut j = i;
        while j > 0 && sprites[j - 1].t() < sprites[j].t() {
            sprites.swap(j - 1, j);
            j -= 1;
        }
    }
    for sprite in sprites.iter() {
        match *sprite {
            Sprite::Furniture {
                t_in,
                t_out,
                index,
                face,
                edge,
            } => {
                let f = &world.furniture[index];
                let z_in = t_in * cos_theta;
                let z_out = t_out * cos_theta;
                let base_k = falloff(z_in)
                    * if face == 0 { 1.0 } else { 0.78 }
                    * if edge { 0.6 } else { 1.0 };
                let (a, b) = model.rows_for(0.0, f.height_m, z_in, rows);
                let k = q8(base_k);
                for (r, out) in px.iter_mut().enumerate().take(b).skip(a) {
                    // A darker band at the top edge and a shadow line at the floor.
                    let hh = model.height_at(r, z_in);
                    let kk = if hh > f.height_m - 0.03 || hh < 0.03 {
                        k * 3 / 4
                    } else {
                        k
                    };
                    *out = shade(f.color, kk);
                }
                if f.height_m < model.cam_h {
                    // Top face, seen from above between the entry and exit depths.
                    let (a, b) = model.rows_for(f.height_m, f.height_m + 1e-6, z_out, rows);
                    let (a2, _) = model.rows_for(f.height_m, f.height_m + 1e-6, z_in, rows);
                    let top = shade(f.color, q8(1.2 * falloff(z_in)));
                    for out in px
                        .iter_mut()
                        .take(a2.min(rows.1))
                        .skip(a.min(b).max(rows.0))
                    {
                        *out = top;
                    }
                }
            }
            Sprite::Glass { t, index, local_x } => {
                let g = &world.glass[index];
                let z = t * cos_theta;
                let (a, b) = model.rows_for(0.0, model.wall_h, z, rows);
                let post = local_x.abs() > g.shape.hx - 0.06;
                let frame = shade(g.frame_color, q8(falloff(z)));
                for (r, out) in px.iter_mut().enumerate().take(b).skip(a) {
                    let hh = model.height_at(r, z);
                    let bar = hh < 0.12 || (2.05..2.13).contains(&hh) || hh > model.wall_h - 0.06;
                    *out = if post || bar {
                        frame
                    } else {
                        // Faint tint plus a diagonal glint so the pane reads as glass.
                        let glint = ((local_x * 3.0 + hh * 1.5).rem_euclid(2.0)) < 0.12;
                        blend(*out, g.tint, if glint { 120 } else { 72 })
                    };
                }
            }
            Sprite::Person { t, lateral, index } => {
                let p = &world.people[index];
                let z = t * cos_theta;
                let u = lateral / p.radius_m;
                let round = 0.55 + 0.45 * (1.0 - u * u).max(0.0).sqrt();
                let k = q8(round * falloff(z));
                // Legs swing with the distance walked.
                let swing = 0.06 * (p.walked_m * 4.0).sin();
                let (a, b) = model.rows_for(0.0, 1.78, z, rows);
                for (r, out) in px.iter_mut().enumerate().take(b).skip(a) {
                    let hh = model.height_at(r, z);
                    let color = if hh < 0.85 {
                        let leg_a = (u - 0.3 - swing).abs() < 0.22;
                        let leg_b = (u + 0.3 + swing).abs() < 0.22;
                        (leg_a || leg_b).then_some(if hh < 0.1 { HAIR } else { p.pants_color })
                    } else if hh < 1.45 {
                        (u.abs() < 0.95).then_some(p.shirt_color)
                    } else if hh < 1.52 {
                        (u.abs() < 0.22).then_some(SKIN)
                    } else if hh < 1.78 {
                        let w = 0.42 * (1.0 - ((hh - 1.65) / 0.13).powi(2)).max(0.0).sqrt();
                        (u.abs() < w).then_some(if hh > 1.7 { HAIR } else { SKIN })
                    } else {
                        None
                    };
                    if let Some(color) = color {
                        *out = shade(color, k);
                    }
                }
            }
            Sprite::Robot { t, lateral } => {
                let z = t * cos_theta;
                let round = 0.55 + 0.45 * (1.0 - lateral * lateral).max(0.0).sqrt();
                let k = q8(round * falloff(z));
                let (a, b) = model.rows_for(0.0, 0.5, z, rows);
                for (r, out) in px.iter_mut().enumerate().take(b).skip(a) {
                    let hh = model.height_at(r, z);
                    let color = if hh < 0.12 {
                        Some([25, 25, 25])
                    } else if hh < 0.3 {
                        Some([175, 30, 30])
                    } else if hh < 0.34 {
                        Some([30, 30, 30])
                    } else {
                        // The laser scanner on top.
                        (lateral.abs() < 0.35).then_some([40, 60, 150])
                    };
                    if let Some(color) = color {
                        *out = shade(color, k);
                    }
                }
            }
        }
    }
}

/// Where the camera of a robot at `pose` sits and looks: (x, y, yaw), [`CAMERA_FORWARD_M`] ahead
/// of the robot's centre.
#[must_use]
pub fn camera_origin(pose: Pose2D) -> (f64, f64, f64) {
    let (s, c) = pose.yaw_rad.sin_cos();
    (
        pose.x_m + CAMERA_FORWARD_M * c,
        pose.y_m + CAMERA_FORWARD_M * s,
        pose.yaw_rad,
    )
}

/// Renders the view from `pose` (a robot pose; the camera sits [`CAMERA_FORWARD_M`] ahead of it)
/// as RGB8, row-major from the top-left, into `out`. `skip_robot` is the robot carrying the camera.
pub fn render(
    world: &World,
    model: &CameraModel,
    pose: Pose2D,
    skip_robot: Option<usize>,
    out: &mut Vec<u8>,
) {
    let (w, h) = (model.width, model.height);
    out.clear();
    out.resize(w * h * 3, 0);
    let cam = camera_origin(pose);
    let mut column = vec![[0u8; 3]; h];
    let mut sprites = Vec::new();
    for col in 0..w {
        render_column(
            world,
            model,
            cam,
            skip_robot,
            col,
            (0, h),
            &mut sprites,
            &mut column,
        );
        for (r, px) in column.iter().enumerate() {
            let i = (r * w + col) * 3;
            out[i..i + 3].copy_from_slice(px);
        }
    }
}

/// Reference renderer: the same scene, but every pixel casts its own ray (no per-column sharing).
/// Gives the same bytes as [`render`]; exists for the benchmark and the equivalence test.
pub fn render_per_pixel(
    world: &World,
    model: &CameraModel,
    pose: Pose2D,
    skip_robot: Option<usize>,
    out: &mut Vec<u8>,
) {
    let (w, h) = (model.width, model.height);
    out.clear();
    out.resize(w * h * 3, 0);
    let cam = camera_origin(pose);
    let mut column = vec![[0u8; 3]; h];
    let mut sprites = Vec::new();
    for r in 0..h {
        for col in 0..w {
            render_column(
                world,
                model,
                cam,
                skip_robot,
                col,
                (r, r + 1),
                &mut sprites,
                &mut column,
            );
            let i = (r * w + col) * 3;
            out[i..i + 3].copy_from_slice(&column[r]);
        }
    }
}

impl World {
    /// The camera model of this world's configuration.
    pub fn camera_model(&self) -> &CameraModel {
        &self.camera_model
    }

    /// Renders robot `index`'s camera as an RGB8 image.
    ///
    /// # Errors
    /// [`SimError::NoSuchRobot`].
    pub fn render_camera(&self, index: usize) -> Result<Image, SimError> {
        let robot = self.robots.get(index).ok_or(SimError::NoSuchRobot {
            index,
            count: self.robots.len(),
        })?;
        let mut data = Vec::new();
        render(self, &self.camera_model, robot.pose, Some(index), &mut data);
        Ok(Image {
            width_px: self.config.camera.width_px,
            height_px: self.config.camera.height_px,
            encoding: ImageEncoding::Rgb8,
            data,
        })
    }

    /// Renders robot `index`'s camera as a stamped frame (advancing its camera sequence number).
    ///
    /// # Errors
    /// [`SimError::NoSuchRobot`].
    pub fn camera_frame(&mut self, index: usize) -> Result<protocol::CameraFrame, SimError> {
        let image = self.render_camera(index)?;
        let header = self.next_camera_header(index);
        Ok(protocol::CameraFrame { header, image })
    }
}
