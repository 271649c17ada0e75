//! Top-down picture of a world: floor plan, ground-truth extras, start, goals and robots.
//!
//! Walls black, floor white, furniture brown, glass cyan, people in magenta with their routes,
//! the start as a green disc with a heading tick, goals as red discs (darker = later), robots
//! as red discs. One pixel per plan cell times `scale`.

use image::{Rgb, RgbImage};

use crate::geom::Obb;
use crate::world::World;

struct Canvas {
    img: RgbImage,
    scale: u32,
    origin_x: f64,
    origin_y: f64,
    px_per_m: f64,
}

impl Canvas {
    fn to_px(&self, x: f64, y: f64) -> (f64, f64) {
        let h = f64::from(self.img.height());
        (
            (x - self.origin_x) * self.px_per_m,
            h - (y - self.origin_y) * self.px_per_m,
        )
    }

    fn put(&mut self, px: i64, py: i64, c: [u8; 3]) {
        if px >= 0
            && py >= 0
            && px < i64::from(self.img.width())
            && py < i64::from(self.img.height())
        {
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            self.img.put_pixel(px as u32, py as u32, Rgb(c));
        }
    }

    fn disc(&mut self, x: f64, y: f64, r_m: f64, c: [u8; 3]) {
        let (cx, cy) = self.to_px(x, y);
        let r = (r_m * self.px_per_m).max(1.5);
        #[allow(clippy::cast_possible_truncation)]
        for py in (cy - r).floor() as i64..=(cy + r).ceil() as i64 {
            for px in (cx - r).floor() as i64..=(cx + r).ceil() as i64 {
                #[allow(clippy::cast_precision_loss)]
                let (fx, fy) = (px as f64 + 0.5 - cx, py as f64 + 0.5 - cy);
                if fx.hypot(fy) <= r {
                    self.put(px, py, c);
                }
            }
        }
    }

    fn line(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, c: [u8; 3], width: i64) {
        let (ax, ay) = self.to_px(x0, y0);
        let (bx, by) = self.to_px(x1, y1);
        let n = (bx - ax).abs().max((by - ay).abs()).ceil().max(1.0);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        for k in 0..=n as u64 {
            #[allow(clippy::cast_precision_loss)]
            let t = k as f64 / n;
            #[allow(clippy::cast_possible_truncation)]
            let (px, py) = (
                (ax + t * (bx - ax)).floor() as i64,
                (ay + t * (by - ay)).floor() as i64,
            );
            for dy in -(width / 2)..=(width / 2) {
                for dx in -(width / 2)..=(width / 2) {
                    self.put(px + dx, py + dy, c);
                }
            }
        }
    }

    fn obb(&mut self, s: &Obb, c: [u8; 3]) {
        let r = s.bounding_radius();
        let (x0, y0) = self.to_px(s.cx - r, s.cy + r);
        let (x1, y1) = self.to_px(s.cx + r, s.cy - r);
        #[allow(clippy::cast_possible_truncation)]
        for py in y0.floor() as i64..=y1.ceil() as i64 {
            for px in x0.floor() as i64..=x1.ceil() as i64 {
                #[allow(clippy::cast_precision_loss)]
                let (x, y) = (
                    self.origin_x + (px as f64 + 0.5) / self.px_per_m,
                    self.origin_y
                        + (f64::from(self.img.height()) - py as f64 - 0.5) / self.px_per_m,
                );
                // Thin panes still get at least a pixel.
                if s.distance(x, y) <= 0.5 / self.px_per_m {
                    self.put(px, py, c);
                }
            }
        }
    }
}

/// Draws the world top-down; `scale` pixels per plan cell (1..=8).
pub fn top_down(world: &World, scale: u32) -> RgbImage {
    let plan = &world.plan;
    let scale = scale.clamp(1, 8);
    let (w, h) = (plan.width_cells() * scale, plan.height_cells() * scale);
    let origin = plan.origin();
    let mut c = Canvas {
        img: RgbImage::new(w, h),
        scale,
        origin_x: origin.x_m,
        origin_y: origin.y_m,
        px_per_m: f64::from(scale) / plan.resolution_m(),
    };
    for py in 0..h {
        for px in 0..w {
            let cx = i64::from(px / c.scale);
            let cy = i64::from(plan.height_cells() - 1 - py / c.scale);
            let color = match plan.class_at(cx, cy) {
                map_core::CellClass::Free => [255, 255, 255],
                map_core::CellClass::Occupied => [0, 0, 0],
                map_core::CellClass::Unknown => [128, 128, 128],
            };
            c.img.put_pixel(px, py, Rgb(color));
        }
    }
    for f in &world.furniture {
        c.obb(&f.shape, [150, 95, 45]);
    }
    for g in &world.glass {
        c.obb(&g.shape, [0, 200, 220]);
    }
    for (spec, p) in world.scenario.people.iter().zip(&world.people) {
        for pair in spec.route.windows(2) {
            c.line(
                pair[0].x_m,
                pair[0].y_m,
                pair[1].x_m,
                pair[1].y_m,
                [230, 120, 230],
                1,
            );
        }
        c.disc(p.x_m, p.y_m, p.radius_m, [200, 0, 200]);
    }
    let n = world.scenario.goals.len().max(1);
    for (i, g) in world.scenario.goals.iter().enumerate() {
        #[allow(clippy::cast_possible_truncation)]
        let dark = (120 * i / n) as u8;
        c.disc(g.x_m, g.y_m, 0.3, [255 - dark, 30, 30]);
    }
    let s = world.scenario.start;
    c.disc(s.x_m, s.y_m, 0.3, [0, 170, 0]);
    c.line(
        s.x_m,
        s.y_m,
        s.x_m + 0.7 * s.yaw_rad.cos(),
        s.y_m + 0.7 * s.yaw_rad.sin(),
        [0, 110, 0],
        3,
    );
    for i in 0..world.robot_count() {
        if let Some(p) = world.ground_truth_pose(i) {
            c.disc(p.x_m, p.y_m, world.config.base.radius_m, [220, 40, 40]);
            c.line(
                p.x_m,
                p.y_m,
                p.x_m + 0.5 * p.yaw_rad.cos(),
                p.y_m + 0.5 * p.yaw_rad.sin(),
                [90, 0, 0],
                1,
            );
        }
    }
    c.img
}
