//! 2-D shapes of the ground truth (oriented boxes, discs) and their ray and disc tests.
//!
//! Furniture and glass panes are oriented boxes, people and robots discs; the camera, the LIDAR
//! and the collision checker all use these same exact tests so what is seen is what is hit.

/// An oriented rectangle: centre, half extents along its own axes, orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obb {
    pub cx: f64,
    pub cy: f64,
    pub hx: f64,
    pub hy: f64,
    pub cos: f64,
    pub sin: f64,
}

/// Where a ray enters and leaves a shape.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    pub t_in: f64,
    pub t_out: f64,
    /// Entry face: 0 = a face normal to the local x axis, 1 = local y axis.
    pub face: u8,
    /// Entry point in the shape's local frame (x along the local x axis).
    pub local_x: f64,
    pub local_y: f64,
}

impl Obb {
    pub fn new(cx: f64, cy: f64, size_x: f64, size_y: f64, yaw: f64) -> Self {
        let (sin, cos) = yaw.sin_cos();
        Self {
            cx,
            cy,
            hx: 0.5 * size_x,
            hy: 0.5 * size_y,
            cos,
            sin,
        }
    }

    /// The box spanning segment (x0, y0)–(x1, y1) with the given thickness.
    pub fn from_segment(x0: f64, y0: f64, x1: f64, y1: f64, thickness: f64) -> Self {
        let len = (x1 - x0).hypot(y1 - y0);
        Self::new(
            0.5 * (x0 + x1),
            0.5 * (y0 + y1),
            len,
            thickness,
            (y1 - y0).atan2(x1 - x0),
        )
    }

    /// A world point in the box frame.
    #[inline]
    pub fn to_local(&self, x: f64, y: f64) -> (f64, f64) {
        let dx = x - self.cx;
        let dy = y - self.cy;
        (
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }

    /// Distance from a point to the box (0 inside).
    pub fn distance(&self, x: f64, y: f64) -> f64 {
        let (lx, ly) = self.to_local(x, y);
        let ex = (lx.abs() - self.hx).max(0.0);
        let ey = (ly.abs() - self.hy).max(0.0);
        ex.hypot(ey)
    }

    /// Radius of the bounding circle.
    pub fn bounding_radius(&self) -> f64 {
        self.hx.hypot(self.hy)
    }

    /// Slab test of the ray `o + t d` (d unit) against the box, for t >= 0.
    #[inline]
    pub fn ray(&self, ox: f64, oy: f64, dx: f64, dy: f64) -> Option<Span> {
        let (lox, loy) = self.to_local(ox, oy);
        let ldx = self.cos * dx + self.sin * dy;
        let ldy = -self.sin * dx + self.cos * dy;
        let (mut t_in, mut t_out, mut face) = (f64::NEG_INFINITY, f64::INFINITY, 0u8);
        for (axis, (o, d, h)) in [(lox, ldx, self.hx), (loy, ldy, self.hy)]
            .into_iter()
            .enumerate()
        {
            if d.abs() < 1e-12 {
                if o.abs() > h {
                    return None;
                }
                continue;
            }
            let inv = 1.0 / d;
            let mut t0 = (-h - o) * inv;
            let mut t1 = (h - o) * inv;
            if t0 > t1 {
                std::mem::swap(&mut t0, &mut t1);
            }
            if t0 > t_in {
                t_in = t0;
                face = u8::from(axis == 1);
            }
            t_out = t_out.min(t1);
        }
        if t_in > t_out || t_out < 0.0 {
            return None;
        }
        let t = t_in.max(0.0);
        Some(Span {
            t_in: t,
            t_out,
            face,
            local_x: lox + t * ldx,
            local_y: loy + t * ldy,
        })
    }
}

/// Where the ray `o + t d` (d unit) enters a disc, and the signed lateral offset of the ray from
/// the centre (for shading a cylinder), or None.
#[inline]
pub fn ray_disc(
    ox: f64,
    oy: f64,
    dx: f64,
    dy: f64,
    cx: f64,
    cy: f64,
    r: f64,
) -> Option<(f64, f64)> {
    let px = cx - ox;
    let py = cy - oy;
    let along = px * dx + py * dy;
    let lateral = dx * py - dy * px;
    if lateral.abs() >= r {
        return None;
    }
    let half = (r * r - lateral * lateral).sqrt();
    let t_out = along + half;
    if t_out < 0.0 {
        return None;
    }
    Some(((along - half).max(0.0), lateral))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_hits_rotated_box_front_face() {
        let b = Obb::new(5.0, 0.0, 1.0, 2.0, 0.0);
        let s = b.ray(0.0, 0.0, 1.0, 0.0).unwrap();
        assert!((s.t_in - 4.5).abs() < 1e-12 && (s.t_out - 5.5).abs() < 1e-12);
        assert_eq!(s.face, 0);
        assert!(b.ray(0.0, 1.5, 1.0, 0.0).is_none());
        assert!(b.ray(0.0, 0.0, -1.0, 0.0).is_none());
        let r = Obb::new(5.0, 0.0, 1.0, 1.0, std::f64::consts::FRAC_PI_4);
        let s = r.ray(0.0, 0.0, 1.0, 0.0).unwrap();
        assert!((s.t_in - (5.0 - 0.5 * 2f64.sqrt())).abs() < 1e-9);
    }

    #[test]
    fn disc_and_distance() {
        let (t, lat) = ray_disc(0.0, 0.0, 1.0, 0.0, 3.0, 0.1, 0.5).unwrap();
        assert!((t - (3.0 - (0.25f64 - 0.01).sqrt())).abs() < 1e-12);
        assert!((lat - 0.1).abs() < 1e-12);
        assert!(ray_disc(0.0, 0.0, 1.0, 0.0, 3.0, 0.6, 0.5).is_none());
        let b = Obb::from_segment(0.0, 0.0, 2.0, 0.0, 0.1);
        assert!((b.distance(1.0, 1.0) - 0.95).abs() < 1e-12);
        assert_eq!(b.distance(1.0, 0.0), 0.0);
    }
}
