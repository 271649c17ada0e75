//! What surfaces look like: per-area procedural textures, with colour and light varied by seed.
//!
//! Textures are baked once per world (64 texels per metre, repeating every 2 m) so the renderer
//! only does table look-ups per pixel. The scenario seed jitters every colour and the overall
//! light level, so two scenarios with the same look still differ slightly, as real buildings do.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::raycast::WallGrid;
use crate::scenario::{AppearanceSpec, FloorTexture, Look, Rgb, WallTexture};

/// Texels per metre.
pub const TEXELS_PER_M: f64 = 64.0;
/// Texture side in texels (a 2 m repeat); a power of two so wrapping is a mask.
pub const TEX: usize = 128;
const MASK: i64 = TEX as i64 - 1;

/// Baked textures of one area.
#[derive(Debug, Clone)]
pub struct AreaStyle {
    /// `TEX` columns × `wall_rows` rows, row 0 at the floor.
    pub wall: Vec<[u8; 3]>,
    pub wall_rows: usize,
    /// `TEX × TEX`, indexed by map-frame position.
    pub floor: Vec<[u8; 3]>,
    pub ceiling: Vec<[u8; 3]>,
    /// Light multiplier in 1/256 units.
    pub light_q8: u32,
}

/// Appearance of a whole world.
#[derive(Debug, Clone)]
pub struct Appearance {
    pub styles: Vec<AreaStyle>,
    /// One style index per floor-plan cell (row-major like the grid).
    area_of_cell: Vec<u8>,
    width: i64,
    height: i64,
}

fn jitter(rng: &mut ChaCha8Rng, c: Rgb, amount: i32) -> [f32; 3] {
    let mut out = [0.0; 3];
    for (o, &v) in out.iter_mut().zip(c.iter()) {
        let d = rng.gen_range(-amount..=amount);
        #[allow(clippy::cast_precision_loss)]
        {
            *o = (i32::from(v) + d).clamp(0, 255) as f32;
        }
    }
    out
}

fn to_rgb(c: [f32; 3], k: f32) -> [u8; 3] {
    // Clamped to 0..=255 first, so the casts cannot truncate.
    #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
    c.map(|v| (v * k).clamp(0.0, 255.0) as u8)
}

/// Deterministic value noise in [0, 1) for texel (x, y) and a salt.
fn hash01(x: i64, y: i64, salt: u64) -> f32 {
    #[allow(clippy::cast_sign_loss)]
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ salt.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 29;
    h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h ^= h >> 32;
    #[allow(clippy::cast_precision_loss)]
    let v = (h >> 40) as f32 / (1u64 << 24) as f32;
    v
}

fn bake_wall(look: &Look, color: [f32; 3], rows: usize, salt: u64) -> Vec<[u8; 3]> {
    let mut tex = Vec::with_capacity(TEX * rows);
    for r in 0..rows {
        #[allow(clippy::cast_precision_loss)]
        let h_m = (r as f64 + 0.5) / TEXELS_PER_M;
        for c in 0..TEX {
            #[allow(clippy::cast_precision_loss)]
            let u_m = (c as f64 + 0.5) / TEXELS_PER_M;
            #[allow(clippy::cast_possible_wrap)]
            let n = hash01(c as i64, r as i64, salt);
            let mut k = 0.94 + 0.06 * n;
            let mut col = color;
            match look.wall_texture {
                WallTexture::Plain => {}
                WallTexture::Concrete => {
                    k = 0.82 + 0.22 * n;
                    // Formwork joints every 1.2 m high, 2 m wide.
                    if (h_m % 1.2) < 0.025 || u_m < 0.025 {
                        k *= 0.7;
                    }
                }
                WallTexture::Bricks => {
                    let row = (h_m / 0.16).floor();
                    let offset = if row % 2.0 == 0.0 { 0.0 } else { 0.125 };
                    let in_mortar_h = (h_m % 0.16) < 0.02;
                    let in_mortar_v = ((u_m + offset) % 0.25) < 0.02;
                    if in_mortar_h || in_mortar_v {
                        col = [200.0, 195.0, 185.0];
                    } else {
                        #[allow(clippy::cast_possible_truncation)]
                        let brick = hash01(((u_m + offset) / 0.25) as i64, row as i64, salt ^ 7);
                        k = 0.8 + 0.3 * brick;
                    }
                }
                WallTexture::Panels => {
                    // Wooden panels 0.5 m wide with dark seams and vertical grain.
                    if (u_m % 0.5) < 0.02 {
                        k = 0.55;
                    } else {
                        #[allow(clippy::cast_possible_wrap)]
                        let grain = hash01(c as i64, 0, salt ^ 3);
                        k = 0.85 + 0.2 * grain;
                    }
                }
                WallTexture::Wainscot => {
                    if h_m < 0.9 {
                        col = col.map(|v| v * 0.6);
                        if (u_m % 0.4) < 0.015 {
                            k *= 0.8;
                        }
                    } else if h_m < 0.96 {
                        col = [235.0, 235.0, 230.0];
                    }
                }
                WallTexture::Tiles => {
                    if (u_m % 0.2) < 0.012 || (h_m % 0.2) < 0.012 {
                        col = [120.0, 120.0, 120.0];
                    } else if h_m > 1.4 {
                        col = color.map(|v| (v * 1.15).min(255.0));
                    }
                }
            }
            // Skirting board.
            if h_m < 0.08 {
                col = [60.0, 55.0, 50.0];
                k = 1.0;
            }
            tex.push(to_rgb(col, k));
        }
    }
    tex
}

fn bake_floor(look: &Look, color: [f32; 3], salt: u64) -> Vec<[u8; 3]> {
    let mut tex = Vec::with_capacity(TEX * TEX);
    for r in 0..TEX {
        #[allow(clippy::cast_precision_loss)]
        let y_m = (r as f64 + 0.5) / TEXELS_PER_M;
        for c in 0..TEX {
            #[allow(clippy::cast_precision_loss)]
            let x_m = (c as f64 + 0.5) / TEXELS_PER_M;
            #[allow(clippy::cast_possible_wrap)]
            let n = hash01(c as i64, r as i64, salt);
            let k = match look.floor_texture {
                FloorTexture::Plain => 0.95 + 0.05 * n,
                FloorTexture::Carpet => 0.8 + 0.25 * n,
                FloorTexture::Tiles => {
                    let checker = ((x_m / 0.5).floor() + (y_m / 0.5).floor()) % 2.0 == 0.0;
                    let grout = (x_m % 0.5) < 0.015 || (y_m % 0.5) < 0.015;
                    if grout {
                        0.6
                    } else if checker {
                        1.0 + 0.04 * n
                    } else {
                        0.82 + 0.04 * n
                    }
                }
                FloorTexture::Planks => {
                    #[allow(clippy::cast_possible_truncation)]
                    let plank = (y_m / 0.2).floor() as i64;
                    let shift = f64::from(hash01(plank, 0, salt ^ 5)) * 2.0;
                    if (y_m % 0.2) < 0.01 || ((x_m + shift) % 1.0) < 0.01 {
                        0.55
                    } else {
                        0.8 + 0.25 * hash01(plank, 1, salt ^ 9) + 0.05 * n
                    }
                }
            };
            tex.push(to_rgb(color, k));
        }
    }
    tex
}

fn bake_ceiling(color: [f32; 3], salt: u64) -> Vec<[u8; 3]> {
    let mut tex = Vec::with_capacity(TEX * TEX);
    for r in 0..TEX {
        #[allow(clippy::cast_precision_loss)]
        let y_m = (r as f64 + 0.5) / TEXELS_PER_M;
        for c in 0..TEX {
            #[allow(clippy::cast_precision_loss)]
            let x_m = (c as f64 + 0.5) / TEXELS_PER_M;
            #[allow(clippy::cast_possible_wrap)]
            let n = hash01(c as i64, r as i64, salt);
            // 0.6 m acoustic tiles with one light panel per 2 m square.
            let light = (0.7..1.3).contains(&x_m) && (0.4..1.6).contains(&y_m);
            let seam = (x_m % 0.6) < 0.015 || (y_m % 0.6) < 0.015;
            let px = if light {
                [255.0, 255.0, 245.0]
            } else if seam {
                color.map(|v| v * 0.75)
            } else {
                color.map(|v| v * (0.92 + 0.06 * n))
            };
            tex.push(to_rgb(px, 1.0));
        }
    }
    tex
}

impl Appearance {
    /// Bakes the styles of `spec` for the walls of `walls`, varied by `seed`.
    pub fn build(spec: &AppearanceSpec, walls: &WallGrid, wall_height_m: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xA11CE);
        let global_light = rng.gen_range(0.85..1.12);
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let wall_rows = ((wall_height_m * TEXELS_PER_M).ceil() as usize).max(1);
        let looks: Vec<&Look> = std::iter::once(&spec.default)
            .chain(spec.areas.iter().map(|a| &a.look))
            .collect();
        let styles = looks
            .iter()
            .enumerate()
            .map(|(i, look)| {
                let salt = seed.wrapping_add(i as u64 * 1000);
                let wall = jitter(&mut rng, look.wall_color, 12);
                let floor = jitter(&mut rng, look.floor_color, 12);
                let ceiling = jitter(&mut rng, look.ceiling_color, 8);
                #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
                let light_q8 = (look.light * global_light * 256.0).round() as u32;
                AreaStyle {
                    wall: bake_wall(look, wall, wall_rows, salt),
                    wall_rows,
                    floor: bake_floor(look, floor, salt ^ 0xF100),
                    ceiling: bake_ceiling(ceiling, salt ^ 0xCE11),
                    light_q8,
                }
            })
            .collect();
        let (width, height) = walls.size_cells();
        let mut area_of_cell = vec![0u8; usize::try_from(width * height).unwrap_or(0)];
        for (i, a) in spec.areas.iter().enumerate().take(254) {
            for cy in 0..height {
                for cx in 0..width {
                    let (x, y) = walls.cell_centre(cx, cy);
                    if x >= a.min_x_m && x <= a.max_x_m && y >= a.min_y_m && y <= a.max_y_m {
                        #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
                        {
                            area_of_cell[(cy * width + cx) as usize] = (i + 1) as u8;
                        }
                    }
                }
            }
        }
        Self {
            styles,
            area_of_cell,
            width,
            height,
        }
    }

    /// Style index of the cell holding grid cell (cx, cy); default style off the grid.
    #[inline]
    pub fn area_at_cell(&self, cx: i64, cy: i64) -> usize {
        if cx < 0 || cy < 0 || cx >= self.width || cy >= self.height {
            0
        } else {
            #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
            usize::from(self.area_of_cell[(cy * self.width + cx) as usize])
        }
    }

    /// Texel index for a map-frame position on a floor or ceiling texture.
    #[inline]
    pub fn flat_index(x_m: f64, y_m: f64) -> usize {
        #[allow(clippy::cast_possible_truncation)]
        let tx = (x_m * TEXELS_PER_M).floor() as i64 & MASK;
        #[allow(clippy::cast_possible_truncation)]
        let ty = (y_m * TEXELS_PER_M).floor() as i64 & MASK;
        #[allow(clippy::cast_sign_loss, clippy::cast_possible_truncation)]
        let i = (ty as usize) * TEX + tx as usize;
        i
    }

    /// Texture column for a position along a wall.
    #[inline]
    pub fn wall_column(along_m: f64) -> usize {
        #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
        let c = ((along_m * TEXELS_PER_M).floor() as i64 & MASK) as usize;
        c
    }
}
