// Helpers of the dashboard browser tests: Chromium launch, polling, screenshots, floor-plan files
// and goal picking on the real occupancy grid the service serves.

import { mkdirSync, readFileSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { deflateSync } from 'node:zlib';
import { chromium } from 'playwright-core';

export const REPO = resolve(dirname(fileURLToPath(import.meta.url)), '..', '..');
export const SHOT_DIR = process.env.FLEET_SCREENSHOT_DIR || join(REPO, 'out', 'browser');

export function env(name) {
  const value = process.env[name];
  if (!value) {
    throw new Error(`${name} is not set: run the tests through scripts/browser-test.sh (it starts the demo)`);
  }
  return value;
}

export async function launchBrowser() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    args: [
      '--no-sandbox',
      '--disable-gpu',
      '--disable-quic',
      '--no-first-run',
      '--disable-background-networking',
      '--disable-component-update',
      '--disable-sync',
    ],
  });
}

export async function screenshot(page, name) {
  mkdirSync(SHOT_DIR, { recursive: true });
  const path = join(SHOT_DIR, `${name}.png`);
  await page.screenshot({ path });
  return path;
}

// Polls `probe` until it returns a truthy value; fails with `what` and the last value seen.
export async function waitFor(what, probe, { timeoutMs = 30_000, intervalMs = 250 } = {}) {
  const deadline = Date.now() + timeoutMs;
  let last;
  for (;;) {
    last = await probe();
    if (last) return last;
    if (Date.now() > deadline) {
      throw new Error(`timed out after ${timeoutMs} ms waiting for ${what} (last: ${JSON.stringify(last)})`);
    }
    await new Promise((r) => setTimeout(r, intervalMs));
  }
}

// --- floor-plan files ------------------------------------------------------------------------

// Reads a binary PGM (P5, 8 bit) as written by `sim gen-maps` and map_server.
export function readPgm(path) {
  const buf = readFileSync(path);
  let pos = 0;
  const tokens = [];
  while (tokens.length < 4) {
    while (pos < buf.length && /\s/.test(String.fromCharCode(buf[pos]))) pos += 1;
    if (buf[pos] === 0x23) {
      while (pos < buf.length && buf[pos] !== 0x0a) pos += 1;
      continue;
    }
    let tok = '';
    while (pos < buf.length && !/\s/.test(String.fromCharCode(buf[pos]))) tok += String.fromCharCode(buf[pos++]);
    tokens.push(tok);
  }
  pos += 1; // the single whitespace after maxval
  const [magic, w, h, maxval] = tokens;
  if (magic !== 'P5' || Number(maxval) > 255) throw new Error(`${path}: not an 8-bit binary PGM (${magic}, maxval ${maxval})`);
  const width = Number(w);
  const height = Number(h);
  return { width, height, pixels: buf.subarray(pos, pos + width * height) };
}

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n += 1) {
    let c = n;
    for (let k = 0; k < 8; k += 1) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

function crc32(bytes) {
  let c = 0xffffffff;
  for (const b of bytes) c = CRC_TABLE[(c ^ b) & 0xff] ^ (c >>> 8);
  return (c ^ 0xffffffff) >>> 0;
}

function pngChunk(type, data) {
  const out = Buffer.alloc(12 + data.length);
  out.writeUInt32BE(data.length, 0);
  out.write(type, 4, 'ascii');
  data.copy(out, 8);
  out.writeUInt32BE(crc32(out.subarray(4, 8 + data.length)), 8 + data.length);
  return out;
}

// Encodes 8-bit greyscale pixels as a PNG: a floor-plan "picture" as an operator would upload.
export function greyPng({ width, height, pixels }) {
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(width, 0);
  ihdr.writeUInt32BE(height, 4);
  ihdr[8] = 8; // bit depth
  ihdr[9] = 0; // greyscale
  const raw = Buffer.alloc((width + 1) * height);
  for (let y = 0; y < height; y += 1) {
    raw[y * (width + 1)] = 0; // filter: none
    pixels.copy(raw, y * (width + 1) + 1, y * width, (y + 1) * width);
  }
  return Buffer.concat([
    Buffer.from([0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a]),
    pngChunk('IHDR', ihdr),
    pngChunk('IDAT', deflateSync(raw)),
    pngChunk('IEND', Buffer.alloc(0)),
  ]);
}

// --- goals on the real occupancy grid -------------------------------------------------------

// Fetches the map's occupancy PNG through the page (same origin, same auth as the dashboard) and
// returns which pixels are free (white).
export async function fetchFreeGrid(page, mapName) {
  return page.evaluate(async (name) => {
    const res = await fetch(`api/v1/maps/${encodeURIComponent(name)}/image`);
    if (!res.ok) throw new Error(`map image ${name}: HTTP ${res.status}`);
    const bitmap = await createImageBitmap(await res.blob());
    const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
    const c = canvas.getContext('2d');
    c.drawImage(bitmap, 0, 0);
    const { data } = c.getImageData(0, 0, bitmap.width, bitmap.height);
    let free = '';
    for (let i = 0; i < data.length; i += 4) free += data[i] > 250 && data[i + 1] > 250 && data[i + 2] > 250 ? '1' : '0';
    return { width: bitmap.width, height: bitmap.height, free };
  }, mapName);
}

// Grid helper over the fetched image: clearance (chessboard distance to a non-free pixel) and
// 4-connected path distances, in pixels. Row 0 is the top of the image (+y), as the API draws it.
export class FreeGrid {
  constructor({ width, height, free }, meta) {
    this.w = width;
    this.h = height;
    this.free = free;
    this.meta = meta;
    this.res = meta.resolution_m;
    this.clearance = this.#clearance();
  }

  #clearance() {
    const { w, h } = this;
    const d = new Int32Array(w * h).fill(-1);
    const queue = new Int32Array(w * h);
    let head = 0;
    let tail = 0;
    for (let i = 0; i < w * h; i += 1) {
      const x = i % w;
      const y = (i / w) | 0;
      if (this.free[i] !== '1' || x === 0 || y === 0 || x === w - 1 || y === h - 1) {
        d[i] = 0;
        queue[tail++] = i;
      }
    }
    while (head < tail) {
      const i = queue[head++];
      const x = i % w;
      const y = (i / w) | 0;
      for (let dy = -1; dy <= 1; dy += 1) {
        for (let dx = -1; dx <= 1; dx += 1) {
          const nx = x + dx;
          const ny = y + dy;
          if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          const j = ny * w + nx;
          if (d[j] === -1) {
            d[j] = d[i] + 1;
            queue[tail++] = j;
          }
        }
      }
    }
    return d;
  }

  toCell(x, y) {
    const m = this.meta;
    return {
      col: Math.floor((x - m.origin.x_m) / this.res),
      row: this.h - 1 - Math.floor((y - m.origin.y_m) / this.res),
    };
  }

  toWorld(col, row) {
    const m = this.meta;
    return { x_m: m.origin.x_m + (col + 0.5) * this.res, y_m: m.origin.y_m + (this.h - row - 0.5) * this.res };
  }

  // Path distances (pixels) from the cell nearest to (x, y) with at least `minClear` clearance.
  distancesFrom(x, y, minClear) {
    const { w, h } = this;
    const start = this.toCell(x, y);
    let best = -1;
    let bestD = Infinity;
    for (let i = 0; i < w * h; i += 1) {
      if (this.clearance[i] < minClear) continue;
      const dd = (i % w - start.col) ** 2 + (((i / w) | 0) - start.row) ** 2;
      if (dd < bestD) {
        bestD = dd;
        best = i;
      }
    }
    if (best < 0) throw new Error(`no cell with ${minClear} px clearance on the map`);
    const dist = new Int32Array(w * h).fill(-1);
    const queue = new Int32Array(w * h);
    let head = 0;
    let tail = 0;
    dist[best] = 0;
    queue[tail++] = best;
    while (head < tail) {
      const i = queue[head++];
      const cx = i % w;
      const cy = (i / w) | 0;
      for (const [dx, dy] of [[1, 0], [-1, 0], [0, 1], [0, -1]]) {
        const nx = cx + dx;
        const ny = cy + dy;
        if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
        const j = ny * w + nx;
        if (dist[j] === -1 && this.clearance[j] >= minClear) {
          dist[j] = dist[i] + 1;
          queue[tail++] = j;
        }
      }
    }
    return dist;
  }

  // The cell with the most clearance whose path distance lies in [lo_m, hi_m] and that keeps
  // `awayFrom` points at least `awayM` metres off (straight line). Null when none.
  pick(dist, loM, hiM, awayFrom = [], awayM = 0) {
    let best = null;
    for (let i = 0; i < dist.length; i += 1) {
      const dm = dist[i] * this.res;
      if (dist[i] < 0 || dm < loM || dm > hiM) continue;
      const p = this.toWorld(i % this.w, (i / this.w) | 0);
      if (awayFrom.some((q) => Math.hypot(q.x_m - p.x_m, q.y_m - p.y_m) < awayM)) continue;
      if (!best || this.clearance[i] > best.clearance) best = { ...p, clearance: this.clearance[i], path_m: dm };
    }
    return best;
  }
}
