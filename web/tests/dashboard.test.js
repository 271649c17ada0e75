// Browser tests of the operator dashboard against the real fleet demo (planner service, simulator
// and robot agents as separate processes), started by scripts/browser-test.sh, which passes
// FLEET_URL and FLEET_TOKEN. Run in order: later tests use the robots and tasks of earlier ones.
// Every check reads the DOM (rows, states, options, images, canvas pixels); `window.fleetDashboard`
// only supplies coordinates and ids.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { writeFileSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { FreeGrid, REPO, env, fetchFreeGrid, greyPng, launchBrowser, readPgm, screenshot, waitFor } from './fleet.js';

const BASE = env('FLEET_URL').replace(/\/?$/, '/');
const TOKEN = env('FLEET_TOKEN');
const TASK_TIMEOUT_MS = Number(process.env.FLEET_TASK_TIMEOUT_MS || 300_000);
const GOAL_CLEARANCE_M = 0.6;

let browser;
let page;
const pageErrors = [];
// Shared between the tests, in order.
const fleet = { robots: [], mapName: null, grid: null, task: null };

const dash = (fn, arg) => page.evaluate(fn, arg);
const robotRow = (id) => page.locator(`[data-testid="robot-row"][data-robot-id="${id}"]`);
const taskRow = (id) => page.locator(`[data-testid="task-row"][data-task-id="${id}"]`);
const workerRow = (id) => page.locator(`[data-testid="worker-row"][data-worker-id="${id}"]`);
const alerts = () => page.locator('[data-testid="error-area"]');

async function api(path) {
  const res = await fetch(new URL(path, BASE), { headers: { authorization: `Bearer ${TOKEN}` } });
  assert.ok(res.ok, `GET ${path}: HTTP ${res.status}`);
  return res.json();
}

async function dismissAlerts() {
  for (const b of await alerts().locator('button.dismiss').all()) await b.click();
}

async function setToken(value) {
  await page.getByTestId('token-input').fill(value);
  await page.getByTestId('token-save').click();
  await waitFor('token saved', async () => (await page.getByTestId('token-state').getAttribute('data-set')) === 'true');
}

// Canvas pixel (CSS px, relative to the canvas) of a world point, checked to lie inside the canvas.
async function canvasPoint(x, y) {
  const p = await dash(([x, y]) => window.fleetDashboard.worldToCanvas(x, y), [x, y]);
  const box = await page.getByTestId('map-canvas').boundingBox();
  assert.ok(p && p.x > 2 && p.y > 2 && p.x < box.width - 2 && p.y < box.height - 2, `(${x}, ${y}) is off the canvas: ${JSON.stringify(p)}`);
  return { x: p.x, y: p.y, pageX: box.x + p.x, pageY: box.y + p.y };
}

// RGBA of the drawn canvas at a CSS pixel.
async function canvasPixel(p) {
  return dash(({ x, y }) => {
    const c = document.querySelector('[data-testid="map-canvas"]');
    const dpr = c.width / c.getBoundingClientRect().width;
    return [...c.getContext('2d').getImageData(Math.round(x * dpr), Math.round(y * dpr), 1, 1).data];
  }, p);
}

async function robotPose(id) {
  return dash((rid) => window.fleetDashboard.robots.find((r) => r.id === rid)?.pose ?? null, id);
}

// Clicks goals on the map in "New task" mode, picks `robotId` and presses Submit.
async function clickGoalsAndSubmit(robotId, goals, shotName) {
  await page.getByTestId('fit-btn').click();
  if ((await page.getByTestId('new-task-btn').getAttribute('aria-pressed')) !== 'true') {
    await page.getByTestId('new-task-btn').click();
  }
  await page.getByTestId('task-builder').waitFor({ state: 'visible' });
  await page.getByTestId('task-clear').click();
  for (const g of goals) {
    const p = await canvasPoint(g.x_m, g.y_m);
    await page.mouse.click(p.pageX, p.pageY);
  }
  await waitFor(`${goals.length} goal markers`, async () => (await page.getByTestId('goal-item').count()) === goals.length);
  const placed = await dash(() => window.fleetDashboard.newTaskGoals);
  const view = await dash(() => window.fleetDashboard.view);
  // One canvas pixel is 1/scale image pixels: the click lands within about one of them.
  const tolerance = (1.5 * fleet.grid.res) / Math.min(1, view.scale) + fleet.grid.res;
  placed.forEach((g, i) => {
    assert.ok(Math.hypot(g.x_m - goals[i].x_m, g.y_m - goals[i].y_m) < tolerance, `goal ${i + 1} placed at ${JSON.stringify(g)}, wanted ${JSON.stringify(goals[i])}`);
  });
  await page.getByTestId('task-robot-select').selectOption(robotId);
  if (shotName) await screenshot(page, shotName);
  await page.getByTestId('task-submit').click();
}

// Clicks a task together and waits for it in the tasks list; returns the Task.
async function createTaskByClicking(robotId, goals, shotName) {
  await setToken(TOKEN);
  const known = new Set((await dash(() => window.fleetDashboard.tasks)).map((t) => t.id));
  await clickGoalsAndSubmit(robotId, goals, shotName);
  const task = await waitFor('the new task in the dashboard', async () =>
    (await dash(() => window.fleetDashboard.tasks)).find((t) => !known.has(t.id)),
  );
  await taskRow(task.id).waitFor({ state: 'visible' });
  assert.equal(task.map, fleet.mapName);
  assert.equal(task.goals.length, goals.length);
  assert.equal(await page.getByTestId('task-builder').isHidden(), true, 'the builder stays open after a submit');
  return task;
}

async function taskRowState(id) {
  return taskRow(id).getByTestId('task-state').getAttribute('data-state');
}

before(async () => {
  browser = await launchBrowser();
  page = await browser.newPage({ viewport: { width: 1440, height: 960 } });
  page.on('pageerror', (err) => pageErrors.push(err.message));
});

after(async () => {
  if (page) await screenshot(page, '99-final').catch(() => {});
  if (browser) await browser.close();
});

test('the dashboard shows the live robots on the map', { timeout: 120_000 }, async () => {
  await page.goto(BASE);
  await page.locator('[data-testid="connection-status"][data-state="live"]').waitFor({ timeout: 30_000 });
  // Two robots online, with a pose, listed in the DOM.
  const robots = await waitFor(
    'two online robots with a pose',
    async () => {
      const rs = (await dash(() => window.fleetDashboard.robots)).filter((r) => r.online && r.pose && r.map);
      return rs.length >= 2 && rs;
    },
    { timeoutMs: 90_000 },
  );
  fleet.robots = robots.map((r) => r.id).sort();
  for (const id of fleet.robots) {
    await robotRow(id).waitFor();
    assert.equal(await robotRow(id).getAttribute('data-online'), 'true');
    assert.doesNotMatch(await robotRow(id).innerText(), /offline/);
  }
  // The map the robots are on is selected and drawn, with each robot at its pose.
  fleet.mapName = robots[0].map.name;
  if ((await page.getByTestId('map-select').inputValue()) !== fleet.mapName) {
    await page.getByTestId('map-select').selectOption(fleet.mapName);
  }
  await waitFor('the map selected', async () => (await dash(() => window.fleetDashboard.selectedMap)) === fleet.mapName);
  const options = await page.locator('[data-testid="map-select"] option').evaluateAll((os) => os.map((o) => o.value));
  assert.ok(options.includes(fleet.mapName), `map selector ${JSON.stringify(options)} lacks ${fleet.mapName}`);
  await waitFor('robots drawn', async () => {
    const drawn = await dash(() => window.fleetDashboard.drawn);
    return fleet.robots.every((id) => drawn.some((d) => d.id === id));
  });
  for (const id of fleet.robots) {
    const pose = await robotPose(id);
    const p = await canvasPoint(pose.x_m, pose.y_m);
    const [r, g, b] = await canvasPixel(p);
    // The robot disc is a saturated colour: neither map grey/white/black nor the background.
    assert.ok(Math.max(r, g, b) - Math.min(r, g, b) > 40, `no robot colour at ${id}'s pose on the canvas: rgb(${r},${g},${b})`);
  }
  const meta = await dash(() => window.fleetDashboard.mapMeta);
  fleet.grid = new FreeGrid(await fetchFreeGrid(page, fleet.mapName), meta);
  await screenshot(page, '01-live-robots');
});

test('a wrong token shows the API error and changes nothing', { timeout: 60_000 }, async () => {
  const robotId = fleet.robots[0];
  const pose = await robotPose(robotId);
  const tasksBefore = (await api('api/v1/tasks')).length;
  await setToken('not-the-token');
  await clickGoalsAndSubmit(robotId, [{ x_m: pose.x_m, y_m: pose.y_m }]);
  const alert = alerts().locator('[data-testid="error-message"]').filter({ hasText: 'unauthorized' });
  await alert.first().waitFor({ timeout: 20_000 });
  // The builder keeps the goals for another try.
  assert.equal(await page.getByTestId('goal-item').count(), 1);
  const text = await alert.first().innerText();
  assert.match(text, /401/);
  assert.match(text, /POST api\/v1\/tasks/);
  assert.equal((await api('api/v1/tasks')).length, tasksBefore, 'a task was stored despite the 401');
  await screenshot(page, '02-wrong-token');
  // Leave the builder, dismiss, and set the right token for the rest.
  await page.keyboard.press('Escape');
  await setToken(TOKEN);
  await dismissAlerts();
});

test('a floor-plan picture is previewed, then saved, and appears in the selector', { timeout: 90_000 }, async () => {
  const dir = mkdtempSync(join(tmpdir(), 'fleet-web-'));
  const picture = join(dir, 'office_plan.png');
  writeFileSync(picture, greyPng(readPgm(join(REPO, 'sim', 'scenarios', 'maps', 'office.pgm'))));
  const name = `office_upload_${Date.now().toString(36)}`;
  await setToken(TOKEN);
  await dismissAlerts();
  await page.getByTestId('upload-mode-picture').check();
  await page.getByTestId('upload-name').fill(name);
  await page.getByTestId('upload-picture').setInputFiles(picture);
  await page.getByTestId('upload-resolution').fill('0.05');
  assert.equal(await page.getByTestId('upload-save').isDisabled(), true, 'Save is enabled before a preview');
  await page.getByTestId('upload-preview').click();
  const preview = page.getByTestId('preview-image');
  await preview.waitFor({ state: 'visible', timeout: 30_000 });
  const natural = await preview.evaluate((img) => [img.naturalWidth, img.naturalHeight]);
  const pgm = readPgm(join(REPO, 'sim', 'scenarios', 'maps', 'office.pgm'));
  assert.deepEqual(natural, [pgm.width, pgm.height]);
  assert.match(await page.getByTestId('preview-info').innerText(), new RegExp(`${pgm.width} × ${pgm.height} cells`));
  // Preview stores nothing.
  assert.ok(!(await api('api/v1/maps')).some((m) => m.name === name), 'preview stored the map');
  await screenshot(page, '03-upload-preview');
  await page.getByTestId('upload-save').click();
  await page.locator(`[data-testid="map-select"] option[value="${name}"]`).waitFor({ state: 'attached', timeout: 30_000 });
  await waitFor('the uploaded map on screen', async () => (await page.getByTestId('map-select').inputValue()) === name);
  assert.ok((await api('api/v1/maps')).some((m) => m.name === name), 'saved map not listed by the API');
  await screenshot(page, '04-upload-saved');

  // The ROS way: yaml + image, as map_server writes them.
  const rosName = `hall_upload_${Date.now().toString(36)}`;
  await page.getByTestId('upload-mode-ros').check();
  await page.getByTestId('upload-name').fill(rosName);
  await page.getByTestId('upload-yaml').setInputFiles(join(REPO, 'sim', 'scenarios', 'maps', 'hall.yaml'));
  await page.getByTestId('upload-image').setInputFiles(join(REPO, 'sim', 'scenarios', 'maps', 'hall.pgm'));
  await page.getByTestId('upload-preview').click();
  await preview.waitFor({ state: 'visible', timeout: 30_000 });
  await page.getByTestId('upload-save').click();
  await page.locator(`[data-testid="map-select"] option[value="${rosName}"]`).waitFor({ state: 'attached', timeout: 30_000 });
  assert.equal(await alerts().locator('[data-testid="error-message"]').count(), 0, await alerts().innerText());

  // Back to the robots' map for the task tests.
  await page.getByTestId('map-select').selectOption(fleet.mapName);
  await waitFor('the robots map back on screen', async () => (await dash(() => window.fleetDashboard.mapMeta))?.name === fleet.mapName);
});

test('a task made by clicking two goals gets a robot driving', { timeout: 120_000 }, async () => {
  const [robotId, otherId] = fleet.robots;
  const grid = fleet.grid;
  const minClear = Math.ceil(GOAL_CLEARANCE_M / grid.res);
  const start = await robotPose(robotId);
  const other = await robotPose(otherId);
  const fromStart = grid.distancesFrom(start.x_m, start.y_m, minClear);
  const first = grid.pick(fromStart, 2.0, 3.5, [other], 2.5);
  assert.ok(first, 'no free goal 2-3.5 m from the robot');
  const second = grid.pick(grid.distancesFrom(first.x_m, first.y_m, minClear), 2.0, 3.5, [other, start], 2.0);
  assert.ok(second, 'no free second goal');
  const task = await createTaskByClicking(robotId, [first, second], '05-task-goals');
  fleet.task = task;
  assert.equal(task.robot_id, robotId);

  await waitFor('the task active in the tasks list', async () => (await taskRowState(task.id)) === 'active', { timeoutMs: 60_000 });
  assert.match(await taskRow(task.id).innerText(), /goal \d\/2/);
  // The robot moves: its pose (as drawn) changes.
  await waitFor(
    `${robotId} moving`,
    async () => {
      const p = await robotPose(robotId);
      return Math.hypot(p.x_m - start.x_m, p.y_m - start.y_m) > 0.3 && p;
    },
    { timeoutMs: 60_000 },
  );
  const drawn = (await dash(() => window.fleetDashboard.drawn)).find((d) => d.id === robotId);
  const startPx = await canvasPoint(start.x_m, start.y_m);
  assert.ok(Math.hypot(drawn.x_px - startPx.x, drawn.y_px - startPx.y) > 1, 'the drawn robot did not move');
  assert.match(await robotRow(robotId).innerText(), new RegExp(task.id));

  // Selected-robot panel with the LPE and camera thumbnails.
  await robotRow(robotId).click();
  const panel = page.getByTestId('robot-panel');
  await waitFor('panel shows the robot', async () => (await panel.getByTestId('sel-id').innerText()) === robotId);
  assert.match(await panel.getByTestId('sel-task').innerText(), new RegExp(task.id));
  // The controller names the agent's rule that drives in its place exactly when the status's
  // flag for it is set (both read in one go: one render writes them).
  const [controllerText, takeover] = await panel
    .getByTestId('sel-controller')
    .evaluate((dd) => [dd.innerText, dd.dataset.takeover]);
  const flags = takeover ? takeover.split(' ') : [];
  const configured = (await api(`api/v1/robots/${robotId}`)).status.controller;
  assert.ok(controllerText.startsWith(configured), `controller shown: ${controllerText}, configured: ${configured}`);
  for (const [flag, words] of [['recovering', 'recovering'], ['backing_up', 'backing off'], ['rotating_in_place', 'turning in place'], ['giving_way', 'giving way']]) {
    assert.equal(controllerText.includes(words), flags.includes(flag), `controller shown: ${controllerText}, flags: ${takeover}`);
  }
  for (const testid of ['lpe-image', 'camera-image']) {
    await waitFor(
      `${testid} loaded`,
      async () => panel.getByTestId(testid).evaluate((img) => !img.hidden && img.complete && img.naturalWidth > 0),
      { timeoutMs: 30_000 },
    );
  }
  await screenshot(page, '06-task-active');
});

test('cancelling a running task shows cancelled', { timeout: 120_000 }, async () => {
  const robotId = fleet.robots[1];
  const grid = fleet.grid;
  const minClear = Math.ceil(GOAL_CLEARANCE_M / grid.res);
  const pose = await robotPose(robotId);
  const busy = [await robotPose(fleet.robots[0]), ...fleet.task.goals];
  const goal = grid.pick(grid.distancesFrom(pose.x_m, pose.y_m, minClear), 5.0, 12.0, busy, 2.5) ||
    grid.pick(grid.distancesFrom(pose.x_m, pose.y_m, minClear), 3.0, 20.0, busy, 1.5);
  assert.ok(goal, 'no free goal for the second robot');
  const task = await createTaskByClicking(robotId, [goal]);
  await waitFor('the second task active', async () => (await taskRowState(task.id)) === 'active', { timeoutMs: 60_000 });
  const cancel = taskRow(task.id).getByTestId('task-cancel');
  await cancel.click();
  await waitFor('the task cancelled in the list', async () => (await taskRowState(task.id)) === 'cancelled', { timeoutMs: 20_000 });
  assert.equal(await cancel.count(), 0, 'a cancelled task still offers Cancel');
  assert.equal((await api(`api/v1/tasks/${task.id}`)).state.kind, 'cancelled');
  await screenshot(page, '07-task-cancelled');
});

test('the clicked task reaches completed', { timeout: TASK_TIMEOUT_MS + 30_000 }, async () => {
  const id = fleet.task.id;
  const state = await waitFor(
    'the first task to end',
    async () => {
      const s = await taskRowState(id);
      return ['completed', 'failed', 'cancelled'].includes(s) && s;
    },
    { timeoutMs: TASK_TIMEOUT_MS, intervalMs: 1000 },
  );
  await screenshot(page, '08-task-ended');
  assert.equal(state, 'completed', `task ended ${state}: ${await taskRow(id).innerText()}`);
  assert.match(await taskRow(id).innerText(), /completed · 2\/2/);
  // After a reload the event snapshot carries live tasks only; the finished one comes back from
  // the task list.
  await page.reload();
  await waitFor('the finished task listed after a reload', async () => (await taskRowState(id).catch(() => null)) === 'completed', {
    timeoutMs: 15_000,
    intervalMs: 250,
  });
  assert.deepEqual(pageErrors, [], 'uncaught errors in the page');
});

test('the workers panel shows the service planning every robot', { timeout: 90_000 }, async () => {
  // The demo starts no worker process, so the service itself plans every online robot; by now
  // the clicked tasks have made it replan, so its count is above zero.
  const demoRobots = (await api('api/v1/robots')).filter((r) => r.online).map((r) => r.id).sort();
  assert.ok(demoRobots.length >= 2, `the demo has ${JSON.stringify(demoRobots)} online`);
  assert.ok(fleet.robots.every((id) => demoRobots.includes(id)), `${JSON.stringify(fleet.robots)} not all online: ${JSON.stringify(demoRobots)}`);
  const table = page.getByTestId('workers-table');
  await table.waitFor({ state: 'visible' });
  const row = workerRow('service');
  await row.waitFor({ timeout: 20_000 });
  assert.equal(await page.getByTestId('workers-empty').isHidden(), true, 'the empty-state line shows next to a listed worker');
  assert.equal(await row.getByTestId('worker-id').innerText(), 'service');
  assert.equal(await row.getByTestId('worker-alive').innerText(), 'yes');
  assert.equal(await row.getAttribute('data-alive'), 'true');
  assert.doesNotMatch((await row.getAttribute('class')) || '', /\bdead\b/, 'the service row is greyed out as dead');
  await waitFor(
    `the service listing ${demoRobots.join(', ')}`,
    async () => {
      const text = await row.getByTestId('worker-robots').innerText();
      const listed = text.split(',').map((s) => s.trim()).filter(Boolean).sort();
      return JSON.stringify(listed) === JSON.stringify(demoRobots) || null;
    },
    { timeoutMs: 30_000 },
  );
  const replans = await waitFor(
    'the service replans counted',
    async () => {
      const n = Number(await row.getByTestId('worker-replans').innerText());
      return Number.isInteger(n) && n > 0 && n;
    },
    { timeoutMs: 30_000 },
  );
  const failures = Number(await row.getByTestId('worker-failures').innerText());
  assert.ok(Number.isInteger(failures) && failures >= 0 && failures <= replans, `failures ${failures} of ${replans} replans`);
  assert.match(await row.getByTestId('worker-latency').innerText(), /^\d+\.\d ms$/);
  // No worker process runs in the demo: nothing else is alive.
  const alive = await page.locator('[data-testid="worker-row"][data-alive="true"]').evaluateAll((rs) => rs.map((r) => r.dataset.workerId));
  assert.deepEqual(alive, ['service']);
  // The 2 s poll reports its failures in the panel, never as an alert.
  assert.equal(await alerts().locator('[data-testid="error-message"]').filter({ hasText: 'workers' }).count(), 0, await alerts().innerText());
  await table.scrollIntoViewIfNeeded();
  await screenshot(page, '09-workers');
  assert.deepEqual(pageErrors, [], 'uncaught errors in the page');
});
