// Operator dashboard of the intention fleet.
//
// One ES module, no framework and no build step: it is embedded in the planner-service binary and
// must work offline. It keeps a local model of the fleet (maps, robots, tasks) fed by the REST API
// and the Server-Sent-Events stream of docs/api.md, and draws it on one canvas. The module exposes a
// read-only `window.fleetDashboard` so browser tests can check what is drawn.

const API = 'api/v1';
const TOKEN_KEY = 'fleet.token';
const MAP_KEY = 'fleet.map';
const TRAIL_WINDOW_MS = 60_000;
const TRAIL_MAX_POINTS = 900;
const LPE_REFRESH_MS = 600; // <= 2 Hz, as the service samples it
const CAMERA_REFRESH_MS = 1200; // <= 1 Hz: camera frames are large
const WORKERS_REFRESH_MS = 2000; // the worker list has no event: polled
const RECENT_TASKS = 100; // finished tasks listed after a (re)connect
const RECONNECT_MIN_MS = 1000;
const RECONNECT_MAX_MS = 15_000;
const ROBOT_RADIUS_M = 0.25;
const MAX_ALERTS = 6;
const TERMINAL_STATES = new Set(['completed', 'failed', 'cancelled']);
const PALETTE = ['#1f77b4', '#d62728', '#2ca02c', '#9467bd', '#ff7f0e', '#17becf', '#e377c2', '#8c564b'];
const DLM_GLYPH = { turn_left: '↰', turn_right: '↱', go_forward: '↑', stop: '■' };

// ---------------------------------------------------------------------------------------------
// State

const state = {
  maps: new Map(), // name -> MapMeta (latest version)
  mapName: null,
  meta: null, // MapMeta of the map on screen
  mapImage: null, // HTMLImageElement of the occupancy PNG
  mapLoadSeq: 0,
  mapsLoaded: false,
  mapsRefreshMs: 0,
  mapChosen: false, // by the operator (or remembered): then robots do not move the view
  robots: new Map(), // id -> Robot (docs/api.md)
  trails: new Map(), // id -> [{x, y, t}]
  tasks: new Map(), // id -> Task
  selectedRobot: null,
  readsProtected: false,
  connection: 'connecting',
  lastEventMs: null,
  eventCounts: { snapshot: 0, robot: 0, intention: 0, task: 0 },
  newTask: { active: false, goals: [] },
  drawn: [], // what the last frame drew: [{id, x_px, y_px, online}]
  colors: new Map(),
};

// `moved`: the operator zoomed or panned; until then the map is kept fitted to the canvas.
const view = { scale: 1, offsetX: 0, offsetY: 0, widthPx: 0, heightPx: 0, fitted: false, moved: false };

const $ = (id) => document.getElementById(id);
const el = {
  canvas: $('map-canvas'),
  wrap: $('canvas-wrap'),
  mapEmpty: $('map-empty'),
  mapSelect: $('map-select'),
  conn: $('conn-status'),
  health: $('health'),
  tokenForm: $('token-form'),
  tokenInput: $('token-input'),
  tokenClear: $('token-clear'),
  tokenState: $('token-state'),
  alerts: $('alerts'),
  notices: $('notices'),
  newTaskBtn: $('new-task-btn'),
  fitBtn: $('fit-btn'),
  cursorPos: $('cursor-pos'),
  taskBuilder: $('task-builder'),
  goalList: $('goal-list'),
  taskRobot: $('task-robot'),
  taskSubmit: $('task-submit'),
  taskClear: $('task-clear'),
  robotsBody: $('robots-body'),
  robotCount: $('robot-count'),
  tasksBody: $('tasks-body'),
  taskCount: $('task-count'),
  workersBody: $('workers-body'),
  workerCount: $('worker-count'),
  workersEmpty: $('workers-empty'),
  panelEmpty: $('robot-panel-empty'),
  panelBody: $('robot-panel-body'),
  lpeImg: $('lpe-img'),
  lpeCaption: $('lpe-caption'),
  cameraImg: $('camera-img'),
  cameraCaption: $('camera-caption'),
  uploadForm: $('upload-form'),
  uploadRos: $('upload-ros'),
  uploadPicture: $('upload-picture'),
  uploadPreview: $('upload-preview'),
  uploadSave: $('upload-save'),
  preview: $('preview'),
  previewImg: $('preview-img'),
  previewInfo: $('preview-info'),
};
const ctx = el.canvas.getContext('2d');

// ---------------------------------------------------------------------------------------------
// Messages: every API error is shown in the role="alert" area, never swallowed.

class ApiError extends Error {
  constructor(method, path, status, code, reason) {
    super(`${method} ${path} → ${status || 'no response'} ${code}: ${reason}`);
    this.method = method;
    this.path = path;
    this.status = status;
    this.code = code;
    this.reason = reason;
  }
}

function showError(message, code = 'error') {
  const last = el.alerts.lastElementChild;
  if (last && last.dataset.text === message) {
    const n = Number(last.dataset.count) + 1;
    last.dataset.count = String(n);
    last.querySelector('.count').textContent = ` (×${n})`;
    return;
  }
  const item = document.createElement('div');
  item.className = 'alert';
  item.dataset.testid = 'error-message';
  item.dataset.code = code;
  item.dataset.text = message;
  item.dataset.count = '1';
  const text = document.createElement('span');
  text.textContent = message;
  const count = document.createElement('span');
  count.className = 'count';
  const close = document.createElement('button');
  close.type = 'button';
  close.className = 'dismiss';
  close.textContent = '×';
  close.title = 'Dismiss';
  close.addEventListener('click', () => item.remove());
  item.append(text, count, close);
  el.alerts.append(item);
  while (el.alerts.children.length > MAX_ALERTS) el.alerts.firstElementChild.remove();
}

function reportError(err) {
  if (err instanceof ApiError) showError(err.message, err.code);
  else showError(String(err && err.message ? err.message : err));
  console.error(err);
}

function notice(message) {
  const item = document.createElement('div');
  item.className = 'notice';
  item.dataset.testid = 'notice-message';
  item.textContent = message;
  el.notices.append(item);
  while (el.notices.children.length > 3) el.notices.firstElementChild.remove();
  setTimeout(() => item.remove(), 8000);
}

// ---------------------------------------------------------------------------------------------
// HTTP

function getToken() {
  return sessionStorage.getItem(TOKEN_KEY) || '';
}

function withAccessToken(path) {
  const token = getToken();
  if (!state.readsProtected || !token) return path;
  return `${path}${path.includes('?') ? '&' : '?'}access_token=${encodeURIComponent(token)}`;
}

// Calls the API; resolves with the Response on 2xx, otherwise throws an ApiError carrying the
// service's `{"error","reason"}`. `quiet` is for callers that show the failure themselves.
async function request(method, path, { json, form, quiet = false } = {}) {
  const mutating = method !== 'GET' && method !== 'HEAD';
  const headers = {};
  let body;
  if (json !== undefined) {
    headers['content-type'] = 'application/json';
    body = JSON.stringify(json);
  } else if (form !== undefined) {
    body = form;
  }
  const token = getToken();
  if (token && (mutating || state.readsProtected)) headers.authorization = `Bearer ${token}`;
  let res;
  try {
    res = await fetch(path, { method, headers, body, cache: 'no-store' });
  } catch (cause) {
    const err = new ApiError(method, path, 0, 'network', cause.message || String(cause));
    if (!quiet) reportError(err);
    throw err;
  }
  if (res.status === 401 && !mutating && !state.readsProtected) {
    // Reads are protected on this service: from now on send the token with reads too.
    state.readsProtected = true;
    if (token) return request(method, path, { json, form, quiet });
  }
  if (!res.ok) {
    let code = `http_${res.status}`;
    let reason = res.statusText || 'request failed';
    const text = await res.text().catch(() => '');
    try {
      const parsed = JSON.parse(text);
      if (parsed && typeof parsed === 'object') {
        code = parsed.error || code;
        reason = parsed.reason || reason;
      }
    } catch {
      // Not the API's JSON (a proxy's HTML page, say): show its text without markup.
      const plain = text.replace(/<[^>]*>/g, ' ').replace(/\s+/g, ' ').trim();
      if (plain) reason = plain.slice(0, 200);
    }
    if (res.status === 401 && !mutating && !token) reason += ' (enter the API token above)';
    const err = new ApiError(method, path, res.status, code, reason);
    if (!quiet) reportError(err);
    throw err;
  }
  return res;
}

async function getJson(path, opts) {
  const res = await request('GET', path, opts);
  return res.json();
}

// ---------------------------------------------------------------------------------------------
// Geometry: world (map frame, metres) <-> image pixels <-> canvas CSS pixels.
// Image pixel edges: u = col, v = row; docs/api.md puts the centre of (col,row) at
// x = ox + (col + 0.5) * res, y = oy + (height - row - 0.5) * res. Rotated origins: grid axes.

function mapWidth(meta) {
  return meta.width_cells ?? meta.width;
}
function mapHeight(meta) {
  return meta.height_cells ?? meta.height;
}
function originYaw(meta) {
  return (meta.origin && meta.origin.yaw_rad) || 0;
}

function worldToImage(x, y) {
  const m = state.meta;
  const dx = x - m.origin.x_m;
  const dy = y - m.origin.y_m;
  const yaw = originYaw(m);
  const c = Math.cos(yaw);
  const s = Math.sin(yaw);
  const gx = (c * dx + s * dy) / m.resolution_m;
  const gy = (-s * dx + c * dy) / m.resolution_m;
  return { u: gx, v: mapHeight(m) - gy };
}

function imageToWorld(u, v) {
  const m = state.meta;
  const gx = u * m.resolution_m;
  const gy = (mapHeight(m) - v) * m.resolution_m;
  const yaw = originYaw(m);
  const c = Math.cos(yaw);
  const s = Math.sin(yaw);
  return { x: m.origin.x_m + c * gx - s * gy, y: m.origin.y_m + s * gx + c * gy };
}

function worldToCanvas(x, y) {
  const { u, v } = worldToImage(x, y);
  return { x: view.offsetX + u * view.scale, y: view.offsetY + v * view.scale };
}

function canvasToWorld(px, py) {
  return imageToWorld((px - view.offsetX) / view.scale, (py - view.offsetY) / view.scale);
}

// Canvas angle (y down) of a map-frame yaw.
function canvasAngle(yaw) {
  return -(yaw - originYaw(state.meta));
}

function pxPerMetre() {
  return view.scale / state.meta.resolution_m;
}

function fitView() {
  if (!state.meta) return;
  const w = mapWidth(state.meta);
  const h = mapHeight(state.meta);
  const scale = Math.min(view.widthPx / w, view.heightPx / h) * 0.96;
  view.scale = scale > 0 && Number.isFinite(scale) ? scale : 1;
  view.offsetX = (view.widthPx - w * view.scale) / 2;
  view.offsetY = (view.heightPx - h * view.scale) / 2;
  view.fitted = true;
  view.moved = false;
  markDirty();
}

// ---------------------------------------------------------------------------------------------
// Maps

function renderMapOptions() {
  const names = [...state.maps.keys()].sort();
  const current = el.mapSelect.value;
  el.mapSelect.replaceChildren(
    ...names.map((name) => {
      const meta = state.maps.get(name);
      const opt = document.createElement('option');
      opt.value = name;
      opt.textContent = `${name} (v${meta.version})`;
      opt.dataset.testid = 'map-option';
      return opt;
    }),
  );
  const want = state.mapName || current;
  if (want && state.maps.has(want)) el.mapSelect.value = want;
}

async function loadMaps() {
  const list = await getJson(`${API}/maps`);
  state.maps.clear();
  for (const meta of list) state.maps.set(String(meta.name), meta);
  state.mapsLoaded = true;
  renderMapOptions();
  if (!state.mapName || !state.maps.has(state.mapName)) {
    const remembered = sessionStorage.getItem(MAP_KEY);
    if (remembered && state.maps.has(remembered)) state.mapChosen = true;
    const robotMap = [...state.robots.values()].find((r) => r.online && r.map)?.map?.name;
    const pick = [remembered, robotMap, [...state.maps.keys()].sort()[0]].find(
      (n) => n && state.maps.has(n),
    );
    if (pick) await selectMap(pick);
  }
}

async function selectMap(name) {
  const seq = ++state.mapLoadSeq;
  state.mapName = name;
  sessionStorage.setItem(MAP_KEY, name);
  el.mapSelect.value = name;
  const path = `${API}/maps/${encodeURIComponent(name)}`;
  const meta = await getJson(path);
  const res = await request('GET', `${path}/image?version=${meta.version}`);
  const blob = await res.blob();
  const img = new Image();
  const url = URL.createObjectURL(blob);
  await new Promise((resolve, reject) => {
    img.onload = resolve;
    img.onerror = () => reject(new Error(`map image of '${name}' could not be decoded`));
    img.src = url;
  }).catch((err) => {
    reportError(err);
    throw err;
  });
  if (seq !== state.mapLoadSeq) return; // a newer selection won
  if (state.mapImage && state.mapImage.src.startsWith('blob:')) URL.revokeObjectURL(state.mapImage.src);
  state.maps.set(name, meta);
  state.meta = meta;
  state.mapImage = img;
  state.newTask.goals = [];
  renderGoals();
  renderTaskRobotOptions();
  el.mapEmpty.hidden = true;
  fitView();
}

// ---------------------------------------------------------------------------------------------
// Robots, tasks and the event stream

function colorOf(id) {
  if (!state.colors.has(id)) state.colors.set(id, PALETTE[state.colors.size % PALETTE.length]);
  return state.colors.get(id);
}

function upsertRobot(robot) {
  const prev = state.robots.get(robot.id);
  state.robots.set(robot.id, robot);
  colorOf(robot.id);
  if (robot.pose) {
    const trail = state.trails.get(robot.id) || [];
    if (prev && prev.map && robot.map && prev.map.name !== robot.map.name) trail.length = 0;
    const last = trail[trail.length - 1];
    const x = robot.pose.x_m;
    const y = robot.pose.y_m;
    if (!last || Math.hypot(last.x - x, last.y - y) > 0.01) trail.push({ x, y, t: performance.now() });
    while (trail.length > TRAIL_MAX_POINTS) trail.shift();
    state.trails.set(robot.id, trail);
  }
  if (robot.map && state.mapsLoaded && !state.maps.has(robot.map.name)) {
    // A robot on a map this page has not listed yet (uploaded elsewhere): refresh the list,
    // at most every few seconds since robot events come at up to 10 Hz.
    const now = Date.now();
    if (now - state.mapsRefreshMs > 5000) {
      state.mapsRefreshMs = now;
      loadMaps().catch(() => {});
    }
  }
}

function upsertTask(task) {
  // The POST answer and the event stream race: an older copy (e.g. 'assigned' arriving after
  // the stream already said 'active') must not overwrite a newer one.
  const known = state.tasks.get(task.id);
  if (known && (known.updated_ns ?? 0) > (task.updated_ns ?? 0)) return;
  state.tasks.set(task.id, task);
}

function handleEvent(kind, raw) {
  let data;
  try {
    data = JSON.parse(raw);
  } catch (err) {
    showError(`event '${kind}': malformed JSON (${err.message})`, 'bad_event');
    return;
  }
  state.lastEventMs = Date.now();
  state.eventCounts[kind] += 1;
  switch (kind) {
    case 'snapshot': {
      const seen = new Set();
      for (const robot of data.robots || []) {
        upsertRobot(robot);
        seen.add(robot.id);
      }
      for (const id of [...state.robots.keys()]) if (!seen.has(id)) state.robots.delete(id);
      for (const task of data.tasks || []) upsertTask(task);
      // The snapshot carries live tasks only; the recent history comes from the task list.
      loadRecentTasks();
      if (!state.mapChosen) {
        // Until the operator picks a map, show the one the robots are on.
        const robotMap = (data.robots || []).find((r) => r.online && r.map)?.map?.name;
        if (robotMap && robotMap !== state.mapName && state.maps.has(robotMap)) {
          selectMap(robotMap).catch(() => {});
        }
      }
      break;
    }
    case 'robot':
      upsertRobot(data);
      break;
    case 'intention': {
      const robot = state.robots.get(data.robot_id);
      if (robot) robot.intention = data.intention;
      else
        upsertRobot({
          id: data.robot_id,
          online: true,
          last_seen_ns: null,
          map: null,
          pose: null,
          status: null,
          task_id: data.intention ? data.intention.task_id : null,
          intention: data.intention,
        });
      break;
    }
    case 'task':
      upsertTask(data);
      break;
    default:
      break;
  }
  scheduleRender();
  markDirty();
}

/** The newest tasks of any state (finished ones too), for the task list after a (re)connect. */
async function loadRecentTasks() {
  try {
    const tasks = await getJson(`${API}/tasks?limit=${RECENT_TASKS}`);
    for (const task of tasks || []) upsertTask(task);
    scheduleRender();
  } catch {
    // reported by request(); the live tasks from the snapshot are shown either way
  }
}

let eventSource = null;
let reconnectTimer = null;
let reconnectDelayMs = RECONNECT_MIN_MS;

function setConnection(s, text) {
  state.connection = s;
  el.conn.dataset.state = s;
  el.conn.textContent = text;
}

function connectEvents() {
  clearTimeout(reconnectTimer);
  if (eventSource) eventSource.close();
  setConnection('connecting', 'connecting…');
  const es = new EventSource(withAccessToken(`${API}/events`));
  eventSource = es;
  es.onopen = () => {
    reconnectDelayMs = RECONNECT_MIN_MS;
    setConnection('live', 'live');
  };
  for (const kind of ['snapshot', 'robot', 'intention', 'task']) {
    es.addEventListener(kind, (e) => handleEvent(kind, e.data));
  }
  es.onerror = () => {
    if (es !== eventSource) return;
    // EventSource hides the status code; close it and find out with a plain request why, so a
    // 401 (protected reads) is shown and answered with access_token= on the next try.
    es.close();
    eventSource = null;
    setConnection('offline', `disconnected, retrying in ${Math.round(reconnectDelayMs / 1000)} s`);
    const delay = reconnectDelayMs;
    reconnectDelayMs = Math.min(reconnectDelayMs * 2, RECONNECT_MAX_MS);
    reconnectTimer = setTimeout(async () => {
      try {
        await request('GET', 'healthz', { quiet: true });
        // Shows a 401 (and switches to access_token=) when reads turned out to be protected.
        await request('GET', `${API}/robots`);
      } catch {
        // service down (quiet) or already reported; EventSource tries again either way
      }
      connectEvents();
    }, delay);
  };
}

async function refreshHealth() {
  try {
    const h = await getJson('healthz', { quiet: true });
    el.health.textContent = `v${h.version} · ${h.robots_online} online · ${h.tasks_active} active`;
    el.health.classList.remove('bad');
  } catch {
    el.health.textContent = 'service unreachable';
    el.health.classList.add('bad');
  }
}

// Background poll: a failure is shown in the panel's count, not as an alert every 2 s; the last
// list stays on screen. One request at a time, so a slow service does not pile them up.
let workersBusy = false;
async function refreshWorkers() {
  if (workersBusy) return;
  workersBusy = true;
  try {
    const workers = await getJson(`${API}/workers`, { quiet: true });
    renderWorkers(Array.isArray(workers) ? workers : []);
    el.workerCount.classList.remove('bad');
  } catch {
    setText(el.workerCount, 'unavailable');
    el.workerCount.classList.add('bad');
  } finally {
    workersBusy = false;
  }
}

async function cancelTask(id, button) {
  button.disabled = true;
  try {
    const res = await request('POST', `${API}/tasks/${encodeURIComponent(id)}/cancel`);
    upsertTask(await res.json());
    notice(`task ${id} cancelled`);
  } catch {
    button.disabled = false; // already reported
  }
  scheduleRender();
  markDirty();
}

// ---------------------------------------------------------------------------------------------
// DOM rendering (tables and the selected-robot panel), throttled: events come at up to 10 Hz
// per robot.

let renderPending = false;
function scheduleRender() {
  if (renderPending) return;
  renderPending = true;
  setTimeout(() => {
    renderPending = false;
    renderRobots();
    renderTasks();
    renderPanel();
    renderTaskRobotOptions();
  }, 150);
}

function setText(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

function ago(ns) {
  if (ns === null || ns === undefined) return '—';
  const ms = Date.now() - Number(ns) / 1e6;
  if (!Number.isFinite(ms)) return '—';
  if (ms < 1500) return 'just now';
  if (ms < 120_000) return `${(ms / 1000).toFixed(0)} s ago`;
  if (ms < 7_200_000) return `${(ms / 60_000).toFixed(0)} min ago`;
  return new Date(Number(ns) / 1e6).toLocaleString();
}

function formatStopReason(reason) {
  if (!reason) return '—';
  switch (reason.kind) {
    case 'stale_intention':
      return `stale intention (${reason.age_ms} ms old)`;
    case 'localization_lost':
      return `localization lost (σ ${Number(reason.position_std_m).toFixed(2)} m)`;
    case 'controller_error':
      return `controller error: ${reason.message}`;
    default:
      return String(reason.kind || JSON.stringify(reason)).replaceAll('_', ' ');
  }
}

function statusText(robot) {
  // An offline robot has no status: what it said last is not what it does now.
  if (!robot.online) return 'offline';
  if (!robot.status) return '—';
  return robot.status.localized === false ? `${robot.status.state} (not localized)` : robot.status.state;
}

// Keeps one <tr> per key in `tbody` in the given order; `fill(tr, item, created)` updates cells.
function syncRows(tbody, items, keyOf, create, fill) {
  const existing = new Map();
  for (const tr of tbody.children) existing.set(tr.dataset.key, tr);
  const wanted = new Set(items.map(keyOf));
  for (const [key, tr] of existing) if (!wanted.has(key)) tr.remove();
  let prev = null;
  for (const item of items) {
    const key = keyOf(item);
    let tr = existing.get(key);
    if (!tr) {
      tr = create(item);
      tr.dataset.key = key;
    }
    fill(tr, item);
    const expectedNext = prev ? prev.nextElementSibling : tbody.firstElementChild;
    if (expectedNext !== tr) tbody.insertBefore(tr, expectedNext);
    prev = tr;
  }
}

function makeRow(testid, cells) {
  const tr = document.createElement('tr');
  tr.dataset.testid = testid;
  for (const name of cells) {
    const td = document.createElement('td');
    td.dataset.col = name;
    tr.append(td);
  }
  return tr;
}

function renderRobots() {
  const robots = [...state.robots.values()].sort((a, b) => a.id.localeCompare(b.id));
  const online = robots.filter((r) => r.online).length;
  setText(el.robotCount, `${online}/${robots.length} online`);
  syncRows(
    el.robotsBody,
    robots,
    (r) => r.id,
    (r) => {
      const tr = makeRow('robot-row', ['id', 'controller', 'status', 'task', 'last-seen']);
      tr.dataset.robotId = r.id;
      const dot = document.createElement('span');
      dot.className = 'dot';
      const name = document.createElement('span');
      name.className = 'name';
      tr.cells[0].append(dot, name);
      tr.addEventListener('click', () => selectRobot(r.id));
      return tr;
    },
    (tr, r) => {
      tr.dataset.online = String(Boolean(r.online));
      tr.dataset.state = r.status ? r.status.state : '';
      tr.classList.toggle('offline', !r.online);
      tr.classList.toggle('selected', state.selectedRobot === r.id);
      const dot = tr.cells[0].querySelector('.dot');
      dot.style.background = r.online ? colorOf(r.id) : '#9aa0a6';
      dot.title = r.online ? 'online' : 'offline';
      setText(tr.cells[0].querySelector('.name'), `${r.id}${r.online ? '' : ' (offline)'}`);
      setText(tr.cells[1], controllerText(r.status));
      tr.dataset.takeover = r.online ? takeoverFlags(r.status) : '';
      setText(tr.cells[2], statusText(r));
      setText(tr.cells[3], r.task_id || '—');
      setText(tr.cells[4], ago(r.last_seen_ns));
    },
  );
}

// The agent's rules that drive in place of its controller for a while, by their status flags:
// the recovery (the dynamic window, or backing straight off from someone met face to face), the
// rotation shim turning the robot towards a path behind it, the give-way rule holding it short of
// a narrow passage. Older agents send no flag: none shown.
const TAKEOVERS = [
  ['recovering', 'recovering'],
  ['backing_up', 'backing off'],
  ['rotating_in_place', 'turning in place'],
  ['giving_way', 'giving way'],
];

function takeovers(status) {
  return status ? TAKEOVERS.filter(([flag]) => status[flag] === true) : [];
}

// The configured controller, and which rule drives in its place; while the agent recovers, the
// dynamic window drives instead, unless the recovery backs the robot off (no controller drives).
function controllerText(status) {
  if (!status) return '—';
  const window = status.recovering && status.backing_up !== true;
  const base = window ? `${status.controller} → dynamic-window` : status.controller;
  const notes = takeovers(status).map(([, text]) => text);
  return notes.length ? `${base} (${notes.join(', ')})` : base;
}

// The same flags for tests and styling: space-separated flag names, '' when the controller drives.
function takeoverFlags(status) {
  return takeovers(status)
    .map(([flag]) => flag)
    .join(' ');
}

function taskStateText(task) {
  const s = task.state || {};
  const n = (task.goals || []).length;
  switch (s.kind) {
    case 'active':
      return `active · goal ${s.goal_index + 1}/${n}`;
    case 'paused':
      return `paused · goal ${s.goal_index + 1}/${n}`;
    case 'completed':
      return `completed · ${n}/${n}`;
    default:
      return s.kind || '?';
  }
}

function taskRobot(task) {
  return (task.state && task.state.robot_id) || task.robot_id || '—';
}

function sortedTasks() {
  return [...state.tasks.values()].sort((a, b) => Number(b.created_ns) - Number(a.created_ns) || b.id.localeCompare(a.id));
}

function renderTasks() {
  const tasks = sortedTasks().slice(0, 200);
  const live = tasks.filter((t) => !TERMINAL_STATES.has(t.state && t.state.kind)).length;
  setText(el.taskCount, `${live} live · ${tasks.length} shown`);
  syncRows(
    el.tasksBody,
    tasks,
    (t) => t.id,
    (t) => {
      const tr = makeRow('task-row', ['id', 'map', 'robot', 'state', 'reason', 'action']);
      tr.dataset.taskId = t.id;
      tr.cells[3].dataset.testid = 'task-state';
      return tr;
    },
    (tr, t) => {
      const kind = (t.state && t.state.kind) || '';
      tr.dataset.state = kind;
      tr.className = `state-${kind}`;
      setText(tr.cells[0], t.id);
      setText(tr.cells[1], `${t.map}${t.map_version ? ` v${t.map_version}` : ''}`);
      setText(tr.cells[2], taskRobot(t));
      tr.cells[3].dataset.state = kind;
      setText(tr.cells[3], taskStateText(t));
      setText(tr.cells[4], (t.state && t.state.reason) || '');
      const action = tr.cells[5];
      const live = !TERMINAL_STATES.has(kind);
      let button = action.querySelector('button');
      if (live && !button) {
        button = document.createElement('button');
        button.type = 'button';
        button.textContent = 'Cancel';
        button.className = 'danger small';
        button.dataset.testid = 'task-cancel';
        button.addEventListener('click', (e) => {
          e.stopPropagation();
          cancelTask(t.id, button);
        });
        action.append(button);
      } else if (!live && button) {
        button.remove();
      }
    },
  );
}

function formatLatency(ms) {
  // The service reports 0 before a worker's first cycle: no measurement yet, not 0 ms.
  const v = Number(ms);
  return Number.isFinite(v) && v > 0 ? `${v.toFixed(1)} ms` : '—';
}

function renderWorkers(workers) {
  const alive = workers.filter((w) => w.alive).length;
  setText(el.workerCount, `${alive}/${workers.length} alive`);
  el.workersEmpty.hidden = workers.length > 0;
  const cols = ['id', 'alive', 'robots', 'replans', 'failures', 'latency'];
  syncRows(
    el.workersBody,
    workers,
    (w) => String(w.id),
    (w) => {
      const tr = makeRow('worker-row', cols);
      tr.dataset.workerId = String(w.id);
      cols.forEach((c, i) => {
        tr.cells[i].dataset.testid = `worker-${c}`;
      });
      return tr;
    },
    (tr, w) => {
      const robots = w.robots || [];
      tr.dataset.alive = String(Boolean(w.alive));
      tr.classList.toggle('dead', !w.alive);
      setText(tr.cells[0], String(w.id));
      setText(tr.cells[1], w.alive ? 'yes' : 'no');
      setText(tr.cells[2], robots.length ? robots.join(', ') : '—');
      setText(tr.cells[3], String(w.replans ?? 0));
      setText(tr.cells[4], String(w.failures ?? 0));
      setText(tr.cells[5], formatLatency(w.mean_latency_ms));
    },
  );
}

function selectRobot(id) {
  state.selectedRobot = id;
  const robot = state.robots.get(id);
  if (robot && robot.map && robot.map.name !== state.mapName && state.maps.has(robot.map.name)) {
    selectMap(robot.map.name).catch(() => {});
  }
  lastLpeLoad = 0;
  lastCameraLoad = 0;
  renderRobots();
  renderPanel();
  markDirty();
}

function renderPanel() {
  const robot = state.selectedRobot ? state.robots.get(state.selectedRobot) : null;
  el.panelEmpty.hidden = Boolean(robot);
  el.panelBody.hidden = !robot;
  if (!robot) return;
  const q = (t) => el.panelBody.querySelector(`[data-testid="${t}"]`);
  setText(q('sel-id'), robot.id);
  setText(q('sel-online'), robot.online ? 'online' : 'offline');
  setText(q('sel-status'), statusText(robot));
  setText(q('sel-stop-reason'), formatStopReason(robot.status && robot.status.stop_reason));
  setText(q('sel-controller'), controllerText(robot.status));
  q('sel-controller').dataset.takeover = robot.online ? takeoverFlags(robot.status) : '';
  setText(q('sel-task'), robot.task_id || '—');
  setText(q('sel-map'), robot.map ? `${robot.map.name} v${robot.map.version}` : '—');
  const p = robot.pose;
  setText(
    q('sel-pose'),
    p
      ? `x ${p.x_m.toFixed(2)} m, y ${p.y_m.toFixed(2)} m, yaw ${((p.yaw_rad * 180) / Math.PI).toFixed(0)}°, σ ${positionStd(p.covariance).toFixed(2)} m`
      : '—',
  );
  const i = robot.intention;
  setText(
    q('sel-intention'),
    i
      ? `${DLM_GLYPH[i.dlm] || ''} ${String(i.dlm).replaceAll('_', ' ')}${i.arriving ? ' (arriving)' : ''} · goal ${Number(i.goal_index) + 1} · ${(i.path || []).length} path points${i.latency_ms !== undefined && i.latency_ms !== null ? ` · ${Number(i.latency_ms).toFixed(1)} ms` : ''}`
      : '—',
  );
  setText(q('sel-last-seen'), ago(robot.last_seen_ns));
}

// Thumbnails: load into a detached Image and swap when decoded, so the panel never flickers;
// a 404 (no intention / frame yet) is a state, shown in the caption.
let lastLpeLoad = 0;
let lastCameraLoad = 0;
let thumbBusy = { lpe: false, camera: false };

function refreshThumb(kind, img, caption, file, label) {
  const id = state.selectedRobot;
  if (!id || thumbBusy[kind]) return;
  thumbBusy[kind] = true;
  const path = withAccessToken(`${API}/robots/${encodeURIComponent(id)}/${file}`);
  const probe = new Image();
  const done = () => {
    thumbBusy[kind] = false;
  };
  probe.onload = () => {
    done();
    if (state.selectedRobot !== id) return;
    img.src = probe.src;
    img.hidden = false;
    caption.textContent = `${label} · ${new Date().toLocaleTimeString()}`;
  };
  probe.onerror = () => {
    done();
    if (state.selectedRobot !== id) return;
    img.hidden = true;
    caption.textContent = `${label}: none yet`;
  };
  probe.src = `${path}${path.includes('?') ? '&' : '?'}t=${Date.now()}`;
}

setInterval(() => {
  const now = Date.now();
  if (!state.selectedRobot) return;
  if (now - lastLpeLoad >= LPE_REFRESH_MS) {
    lastLpeLoad = now;
    refreshThumb('lpe', el.lpeImg, el.lpeCaption, 'lpe.png', 'LPE');
  }
  if (now - lastCameraLoad >= CAMERA_REFRESH_MS) {
    lastCameraLoad = now;
    refreshThumb('camera', el.cameraImg, el.cameraCaption, 'camera.jpg', 'camera');
  }
}, 100);

// "last seen" columns age even without events.
setInterval(scheduleRender, 1000);

// ---------------------------------------------------------------------------------------------
// Task builder

function renderTaskRobotOptions() {
  const current = el.taskRobot.value;
  const robots = [...state.robots.values()]
    .filter((r) => !state.mapName || !r.map || r.map.name === state.mapName)
    .sort((a, b) => a.id.localeCompare(b.id));
  const wanted = ['', ...robots.map((r) => r.id)];
  const have = [...el.taskRobot.options].map((o) => o.value);
  if (wanted.join('\n') !== have.join('\n')) {
    const first = el.taskRobot.options[0];
    el.taskRobot.replaceChildren(first);
    for (const r of robots) {
      const opt = document.createElement('option');
      opt.value = r.id;
      el.taskRobot.append(opt);
    }
  }
  for (const opt of [...el.taskRobot.options].slice(1)) {
    const r = state.robots.get(opt.value);
    setText(opt, r ? `${r.id}${r.online ? '' : ' (offline)'}${r.task_id ? ' (busy)' : ''}` : opt.value);
  }
  if (wanted.includes(current)) el.taskRobot.value = current;
}

function setNewTaskMode(active) {
  state.newTask.active = active;
  el.newTaskBtn.setAttribute('aria-pressed', String(active));
  el.newTaskBtn.classList.toggle('active', active);
  el.taskBuilder.hidden = !active;
  el.canvas.classList.toggle('placing', active);
  if (!active) {
    state.newTask.goals = [];
    renderGoals();
  }
  renderTaskRobotOptions();
  markDirty();
}

function renderGoals() {
  el.goalList.replaceChildren(
    ...state.newTask.goals.map((g, i) => {
      const li = document.createElement('li');
      li.dataset.testid = 'goal-item';
      li.textContent = `(${g.x_m.toFixed(2)}, ${g.y_m.toFixed(2)})${g.yaw_rad === undefined ? '' : ` ${((g.yaw_rad * 180) / Math.PI).toFixed(0)}°`} `;
      const rm = document.createElement('button');
      rm.type = 'button';
      rm.className = 'small';
      rm.textContent = '×';
      rm.title = `Remove goal ${i + 1}`;
      rm.addEventListener('click', () => {
        state.newTask.goals.splice(i, 1);
        renderGoals();
        markDirty();
      });
      li.append(rm);
      return li;
    }),
  );
  el.taskSubmit.disabled = state.newTask.goals.length === 0 || !state.mapName;
}

async function submitTask() {
  if (!state.mapName || state.newTask.goals.length === 0) return;
  const body = { map: state.mapName, goals: state.newTask.goals.map((g) => ({ ...g })) };
  if (el.taskRobot.value) body.robot_id = el.taskRobot.value;
  el.taskSubmit.disabled = true;
  try {
    const res = await request('POST', `${API}/tasks`, { json: body });
    const task = await res.json();
    upsertTask(task);
    notice(`task ${task.id} created (${task.state.kind})`);
    setNewTaskMode(false);
  } catch {
    // reported in the alert area; keep the goals so the operator can fix them
  } finally {
    renderGoals();
    scheduleRender();
    markDirty();
  }
}

// ---------------------------------------------------------------------------------------------
// Canvas interaction: wheel zoom, drag pan, click select / place goal, shift+drag goal heading.

let pointer = null;

function canvasPoint(e) {
  const r = el.canvas.getBoundingClientRect();
  return { x: e.clientX - r.left, y: e.clientY - r.top };
}

el.canvas.addEventListener('pointerdown', (e) => {
  if (e.button !== 0) return;
  const p = canvasPoint(e);
  pointer = { start: p, last: p, moved: false, heading: e.shiftKey && state.newTask.active, id: e.pointerId };
  el.canvas.setPointerCapture(e.pointerId);
});

el.canvas.addEventListener('pointermove', (e) => {
  const p = canvasPoint(e);
  if (state.meta) {
    const w = canvasToWorld(p.x, p.y);
    setText(el.cursorPos, `x ${w.x.toFixed(2)} m  y ${w.y.toFixed(2)} m`);
  }
  if (!pointer) return;
  if (Math.hypot(p.x - pointer.start.x, p.y - pointer.start.y) > 4) pointer.moved = true;
  if (pointer.moved && !pointer.heading) {
    view.moved = true;
    view.offsetX += p.x - pointer.last.x;
    view.offsetY += p.y - pointer.last.y;
  }
  pointer.last = p;
  markDirty();
});

function endPointer(e, cancelled) {
  if (!pointer || pointer.id !== e.pointerId) return;
  const p = pointer;
  pointer = null;
  if (cancelled || !state.meta) return;
  if (state.newTask.active && (!p.moved || p.heading)) {
    const w = canvasToWorld(p.start.x, p.start.y);
    const goal = { x_m: round3(w.x), y_m: round3(w.y) };
    if (p.heading && p.moved) {
      const to = canvasToWorld(p.last.x, p.last.y);
      goal.yaw_rad = round3(Math.atan2(to.y - w.y, to.x - w.x));
    }
    state.newTask.goals.push(goal);
    renderGoals();
  } else if (!p.moved) {
    const hit = nearestDrawnRobot(p.start.x, p.start.y, 16);
    if (hit) selectRobot(hit);
  }
  markDirty();
}

el.canvas.addEventListener('pointerup', (e) => endPointer(e, false));
el.canvas.addEventListener('pointercancel', (e) => endPointer(e, true));

el.canvas.addEventListener(
  'wheel',
  (e) => {
    e.preventDefault();
    const p = canvasPoint(e);
    const factor = Math.exp(-e.deltaY * 0.0015);
    const scale = Math.min(Math.max(view.scale * factor, 0.05), 80);
    const k = scale / view.scale;
    view.offsetX = p.x - (p.x - view.offsetX) * k;
    view.offsetY = p.y - (p.y - view.offsetY) * k;
    view.scale = scale;
    view.moved = true;
    markDirty();
  },
  { passive: false },
);

function round3(v) {
  return Math.round(v * 1000) / 1000;
}

function nearestDrawnRobot(x, y, radiusPx) {
  let best = null;
  let bestD = radiusPx;
  for (const d of state.drawn) {
    const dist = Math.hypot(d.x_px - x, d.y_px - y);
    if (dist <= bestD) {
      best = d.id;
      bestD = dist;
    }
  }
  return best;
}

// ---------------------------------------------------------------------------------------------
// Drawing

let dirty = true;
let lastDrawMs = 0;
function markDirty() {
  dirty = true;
}

function resizeCanvas() {
  const rect = el.wrap.getBoundingClientRect();
  const dpr = window.devicePixelRatio || 1;
  view.widthPx = Math.max(1, Math.floor(rect.width));
  view.heightPx = Math.max(1, Math.floor(rect.height));
  el.canvas.width = Math.floor(view.widthPx * dpr);
  el.canvas.height = Math.floor(view.heightPx * dpr);
  el.canvas.style.width = `${view.widthPx}px`;
  el.canvas.style.height = `${view.heightPx}px`;
  if (!view.fitted || !view.moved) fitView();
  markDirty();
}

function positionStd(cov) {
  if (!cov || cov.length < 5) return 0;
  const a = cov[0];
  const d = cov[4];
  const b = 0.5 * (cov[1] + cov[3]);
  const mean = 0.5 * (a + d);
  const r = Math.hypot(0.5 * (a - d), b);
  return Math.sqrt(Math.max(mean + r, 0));
}

// 1-sigma ellipse of the xy block of a row-major 3x3 covariance: radii (m) and major-axis yaw.
function covarianceEllipse(cov) {
  if (!cov || cov.length < 5 || !cov.every(Number.isFinite)) return null;
  const a = cov[0];
  const d = cov[4];
  const b = 0.5 * (cov[1] + cov[3]);
  const mean = 0.5 * (a + d);
  const r = Math.hypot(0.5 * (a - d), b);
  return {
    major_m: Math.sqrt(Math.max(mean + r, 0)),
    minor_m: Math.sqrt(Math.max(mean - r, 0)),
    yaw_rad: 0.5 * Math.atan2(2 * b, a - d),
  };
}

function draw(now) {
  const dpr = window.devicePixelRatio || 1;
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.clearRect(0, 0, view.widthPx, view.heightPx);
  ctx.fillStyle = '#dfe3e8';
  ctx.fillRect(0, 0, view.widthPx, view.heightPx);
  const drawn = [];
  if (!state.meta || !state.mapImage) {
    state.drawn = drawn;
    return;
  }
  ctx.imageSmoothingEnabled = view.scale < 1;
  ctx.drawImage(
    state.mapImage,
    view.offsetX,
    view.offsetY,
    mapWidth(state.meta) * view.scale,
    mapHeight(state.meta) * view.scale,
  );
  const ppm = pxPerMetre();

  // Goals of live tasks on this map.
  for (const task of state.tasks.values()) {
    if (task.map !== state.mapName || TERMINAL_STATES.has(task.state && task.state.kind)) continue;
    const color = colorOf(taskRobot(task));
    const current = task.state && task.state.goal_index;
    (task.goals || []).forEach((g, i) => drawGoal(g, i + 1, task.robot_id || (task.state && task.state.robot_id) ? color : '#555', i === current ? 1 : 0.55));
  }

  for (const robot of [...state.robots.values()].sort((a, b) => a.id.localeCompare(b.id))) {
    if (!robot.pose || !robot.map || robot.map.name !== state.mapName) continue;
    const color = robot.online ? colorOf(robot.id) : '#8a8f96';
    drawTrail(robot, color, now);
    if (robot.online) drawUnmapped(robot.pose.unmapped_obstacles_m, ppm);
    if (robot.intention && robot.online) drawPath(robot.intention.path, color);
    const pos = worldToCanvas(robot.pose.x_m, robot.pose.y_m);
    drawRobot(robot, pos, color, ppm);
    drawn.push({ id: robot.id, x_px: pos.x, y_px: pos.y, online: Boolean(robot.online) });
  }

  // Goals being placed for a new task.
  if (state.newTask.active) {
    state.newTask.goals.forEach((g, i) => drawGoal(g, i + 1, '#f28c00', 1));
    if (pointer && pointer.heading && pointer.moved) {
      ctx.strokeStyle = '#f28c00';
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(pointer.start.x, pointer.start.y);
      ctx.lineTo(pointer.last.x, pointer.last.y);
      ctx.stroke();
    }
  }
  state.drawn = drawn;
}

function drawTrail(robot, color, now) {
  const trail = state.trails.get(robot.id);
  if (!trail) return;
  while (trail.length && now - trail[0].t > TRAIL_WINDOW_MS) trail.shift();
  ctx.lineWidth = 2;
  ctx.strokeStyle = color;
  for (let i = 1; i < trail.length; i += 1) {
    const age = now - trail[i].t;
    ctx.globalAlpha = Math.max(0.05, 0.8 * (1 - age / TRAIL_WINDOW_MS));
    const a = worldToCanvas(trail[i - 1].x, trail[i - 1].y);
    const b = worldToCanvas(trail[i].x, trail[i].y);
    ctx.beginPath();
    ctx.moveTo(a.x, a.y);
    ctx.lineTo(b.x, b.y);
    ctx.stroke();
  }
  ctx.globalAlpha = 1;
}

// What a robot's laser sees where the floor plan is free (its plan keeps clear of it): dark
// squares of the agent's 0.1 m marking cells.
function drawUnmapped(points, ppm) {
  if (!points || !points.length) return;
  const side = Math.max(2, 0.1 * ppm);
  ctx.save();
  ctx.fillStyle = '#7a3b12';
  ctx.globalAlpha = 0.8;
  for (const [x, y] of points) {
    const c = worldToCanvas(x, y);
    ctx.fillRect(c.x - side / 2, c.y - side / 2, side, side);
  }
  ctx.restore();
}

function drawPath(path, color) {
  if (!path || path.length < 2) return;
  ctx.save();
  ctx.strokeStyle = color;
  ctx.globalAlpha = 0.75;
  ctx.lineWidth = 2.5;
  ctx.setLineDash([7, 5]);
  ctx.beginPath();
  path.forEach((p, i) => {
    const c = worldToCanvas(p.x_m, p.y_m);
    if (i === 0) ctx.moveTo(c.x, c.y);
    else ctx.lineTo(c.x, c.y);
  });
  ctx.stroke();
  ctx.restore();
}

function drawRobot(robot, pos, color, ppm) {
  const ell = covarianceEllipse(robot.pose.covariance);
  if (ell) {
    const rx = Math.min(ell.major_m * ppm, 4000);
    const ry = Math.min(ell.minor_m * ppm, 4000);
    if (rx > 0.5) {
      ctx.save();
      ctx.fillStyle = color;
      ctx.globalAlpha = 0.18;
      ctx.strokeStyle = color;
      ctx.beginPath();
      ctx.ellipse(pos.x, pos.y, rx, Math.max(ry, 0.5), canvasAngle(ell.yaw_rad), 0, 2 * Math.PI);
      ctx.fill();
      ctx.globalAlpha = 0.6;
      ctx.lineWidth = 1;
      ctx.stroke();
      ctx.restore();
    }
  }
  const r = Math.max(ROBOT_RADIUS_M * ppm, 6);
  const ang = canvasAngle(robot.pose.yaw_rad);
  ctx.fillStyle = color;
  ctx.strokeStyle = '#fff';
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  ctx.arc(pos.x, pos.y, r, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  // Heading arrow.
  const tipX = pos.x + Math.cos(ang) * r * 2.2;
  const tipY = pos.y + Math.sin(ang) * r * 2.2;
  ctx.strokeStyle = color;
  ctx.lineWidth = 2.5;
  ctx.beginPath();
  ctx.moveTo(pos.x, pos.y);
  ctx.lineTo(tipX, tipY);
  ctx.stroke();
  ctx.fillStyle = color;
  ctx.beginPath();
  ctx.moveTo(tipX, tipY);
  ctx.lineTo(tipX - Math.cos(ang - 0.45) * 8, tipY - Math.sin(ang - 0.45) * 8);
  ctx.lineTo(tipX - Math.cos(ang + 0.45) * 8, tipY - Math.sin(ang + 0.45) * 8);
  ctx.closePath();
  ctx.fill();
  if (state.selectedRobot === robot.id) {
    ctx.strokeStyle = '#111';
    ctx.lineWidth = 2;
    ctx.setLineDash([3, 3]);
    ctx.beginPath();
    ctx.arc(pos.x, pos.y, r + 5, 0, 2 * Math.PI);
    ctx.stroke();
    ctx.setLineDash([]);
  }
  // Label with the intention (DLM) next to the robot.
  const dlm = robot.online && robot.intention ? robot.intention.dlm : null;
  const label = `${robot.id}${robot.online ? '' : ' (offline)'}${dlm ? `  ${DLM_GLYPH[dlm] || ''} ${dlm.replaceAll('_', ' ')}` : ''}`;
  ctx.font = '12px system-ui, sans-serif';
  const w = ctx.measureText(label).width + 8;
  const lx = pos.x + r + 6;
  const ly = pos.y - r - 18;
  ctx.fillStyle = 'rgba(255,255,255,0.85)';
  ctx.fillRect(lx, ly, w, 17);
  ctx.strokeStyle = color;
  ctx.lineWidth = 1;
  ctx.strokeRect(lx, ly, w, 17);
  ctx.fillStyle = '#111';
  ctx.fillText(label, lx + 4, ly + 13);
}

function drawGoal(goal, number, color, alpha) {
  const c = worldToCanvas(goal.x_m, goal.y_m);
  ctx.save();
  ctx.globalAlpha = alpha;
  if (goal.yaw_rad !== undefined && goal.yaw_rad !== null) {
    const ang = canvasAngle(goal.yaw_rad);
    ctx.strokeStyle = color;
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(c.x, c.y);
    ctx.lineTo(c.x + Math.cos(ang) * 22, c.y + Math.sin(ang) * 22);
    ctx.stroke();
  }
  ctx.fillStyle = color;
  ctx.strokeStyle = '#fff';
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  ctx.arc(c.x, c.y, 9, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  ctx.fillStyle = '#fff';
  ctx.font = 'bold 11px system-ui, sans-serif';
  ctx.textAlign = 'center';
  ctx.textBaseline = 'middle';
  ctx.fillText(String(number), c.x, c.y + 0.5);
  ctx.restore();
}

function frame(now) {
  const trailsFading = [...state.trails.values()].some((t) => t.length > 1);
  if (dirty || (trailsFading && now - lastDrawMs > 250)) {
    dirty = false;
    lastDrawMs = now;
    draw(now);
  }
  requestAnimationFrame(frame);
}

// ---------------------------------------------------------------------------------------------
// Floor-plan upload: preview first (nothing stored), then save.

function uploadMode() {
  return el.uploadForm.elements.mode.value;
}

function uploadFormData(forSave) {
  const f = el.uploadForm.elements;
  const data = new FormData();
  const name = f.name.value.trim();
  if (name || forSave) data.append('name', name);
  if (uploadMode() === 'ros') {
    if (f.yaml.files[0]) data.append('yaml', f.yaml.files[0]);
    if (f.image.files[0]) data.append('image', f.image.files[0]);
  } else {
    if (f.picture.files[0]) data.append('picture', f.picture.files[0]);
    data.append('resolution_m', f.resolution_m.value.trim());
    if (f.origin_x_m.value.trim()) data.append('origin_x_m', f.origin_x_m.value.trim());
    if (f.origin_y_m.value.trim()) data.append('origin_y_m', f.origin_y_m.value.trim());
  }
  return data;
}

function resetPreview() {
  el.uploadSave.disabled = true;
  el.preview.hidden = true;
  if (el.previewImg.src.startsWith('blob:')) URL.revokeObjectURL(el.previewImg.src);
  el.previewImg.removeAttribute('src');
  el.previewInfo.textContent = '';
}

async function previewUpload() {
  resetPreview();
  el.uploadPreview.disabled = true;
  try {
    const res = await request('POST', `${API}/maps/preview`, { form: uploadFormData(false) });
    const w = res.headers.get('x-map-width');
    const h = res.headers.get('x-map-height');
    const r = res.headers.get('x-map-resolution-m');
    const blob = await res.blob();
    el.previewImg.src = URL.createObjectURL(blob);
    await el.previewImg.decode().catch(() => {
      throw new Error('the preview PNG could not be decoded');
    });
    const size = w && h && r ? ` = ${(w * r).toFixed(2)} m × ${(h * r).toFixed(2)} m` : '';
    el.previewInfo.textContent = `${w} × ${h} cells at ${r} m/cell${size}`;
    el.previewInfo.dataset.width = w || '';
    el.previewInfo.dataset.height = h || '';
    el.preview.hidden = false;
    el.uploadSave.disabled = false;
  } catch (err) {
    if (!(err instanceof ApiError)) reportError(err);
  } finally {
    el.uploadPreview.disabled = false;
  }
}

async function saveUpload(e) {
  e.preventDefault();
  el.uploadSave.disabled = true;
  try {
    const res = await request('POST', `${API}/maps`, { form: uploadFormData(true) });
    const meta = await res.json();
    notice(
      res.status === 201
        ? `map ${meta.name} v${meta.version} saved`
        : `map ${meta.name} v${meta.version} already stored with this content`,
    );
    state.maps.set(String(meta.name), meta);
    await loadMaps();
    state.mapChosen = true;
    await selectMap(String(meta.name));
    el.uploadForm.reset();
    showUploadMode();
    resetPreview();
  } catch (err) {
    if (!(err instanceof ApiError)) reportError(err);
    el.uploadSave.disabled = false;
  }
}

function showUploadMode() {
  const ros = uploadMode() === 'ros';
  el.uploadRos.hidden = !ros;
  el.uploadPicture.hidden = ros;
}

// ---------------------------------------------------------------------------------------------
// Token

function renderToken() {
  const token = getToken();
  el.tokenState.textContent = token ? 'token set' : 'no token';
  el.tokenState.dataset.set = String(Boolean(token));
  el.tokenInput.value = token;
}

// ---------------------------------------------------------------------------------------------
// Wiring

function publicView() {
  const clone = (v) => (v === undefined ? undefined : JSON.parse(JSON.stringify(v)));
  return Object.freeze({
    get robots() {
      return clone([...state.robots.values()].sort((a, b) => a.id.localeCompare(b.id)));
    },
    get tasks() {
      return clone(sortedTasks());
    },
    get maps() {
      return clone([...state.maps.values()]);
    },
    get selectedMap() {
      return state.mapName;
    },
    get mapMeta() {
      return clone(state.meta);
    },
    get selectedRobot() {
      return state.selectedRobot;
    },
    get connection() {
      return state.connection;
    },
    get eventCounts() {
      return { ...state.eventCounts };
    },
    get readsProtected() {
      return state.readsProtected;
    },
    get newTaskGoals() {
      return clone(state.newTask.goals);
    },
    // Robots drawn in the last frame, with their canvas position (CSS pixels).
    get drawn() {
      return clone(state.drawn);
    },
    get view() {
      return { ...view };
    },
    worldToCanvas(x, y) {
      return state.meta ? worldToCanvas(x, y) : null;
    },
    canvasToWorld(x, y) {
      return state.meta ? canvasToWorld(x, y) : null;
    },
  });
}

function init() {
  Object.defineProperty(window, 'fleetDashboard', { value: publicView(), writable: false, configurable: false });
  renderToken();
  el.tokenForm.addEventListener('submit', (e) => {
    e.preventDefault();
    const token = el.tokenInput.value.trim();
    if (token) sessionStorage.setItem(TOKEN_KEY, token);
    else sessionStorage.removeItem(TOKEN_KEY);
    renderToken();
    notice(token ? 'token set for this tab' : 'token cleared');
    if (state.readsProtected) {
      loadMaps().catch(() => {});
      connectEvents();
    }
  });
  el.tokenClear.addEventListener('click', () => {
    sessionStorage.removeItem(TOKEN_KEY);
    renderToken();
    notice('token cleared');
  });
  el.mapSelect.addEventListener('change', () => {
    state.mapChosen = true;
    selectMap(el.mapSelect.value).catch(() => {});
  });
  el.newTaskBtn.addEventListener('click', () => setNewTaskMode(!state.newTask.active));
  el.fitBtn.addEventListener('click', fitView);
  el.taskSubmit.addEventListener('click', submitTask);
  el.taskClear.addEventListener('click', () => {
    state.newTask.goals = [];
    renderGoals();
    markDirty();
  });
  document.addEventListener('keydown', (e) => {
    if (e.key === 'Escape' && state.newTask.active) setNewTaskMode(false);
  });
  for (const radio of el.uploadForm.elements.mode) radio.addEventListener('change', showUploadMode);
  el.uploadForm.addEventListener('input', resetPreview);
  el.uploadForm.addEventListener('change', (e) => {
    if (e.target.type === 'file') resetPreview();
  });
  el.uploadPreview.addEventListener('click', previewUpload);
  el.uploadForm.addEventListener('submit', saveUpload);
  showUploadMode();

  new ResizeObserver(resizeCanvas).observe(el.wrap);
  resizeCanvas();
  requestAnimationFrame(frame);

  refreshHealth();
  setInterval(refreshHealth, 5000);
  refreshWorkers();
  setInterval(refreshWorkers, WORKERS_REFRESH_MS);
  loadMaps()
    .then(() => getJson(`${API}/tasks?limit=100`))
    .then((tasks) => {
      for (const t of tasks) if (!state.tasks.has(t.id)) upsertTask(t);
      scheduleRender();
      markDirty();
    })
    .catch(() => {});
  connectEvents();
}

init();
