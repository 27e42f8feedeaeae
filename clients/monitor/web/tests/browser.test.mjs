// The monitor in a real browser (Debian's headless Chromium, driven by playwright-core) against
// a simulated cell (`cell up`: world simulator, two gateways with the ideal robot, motion
// service, the eye-in-hand camera, the monitor's bridge; vision and the task service when
// they are built). ctest: monitor_browser.simulated_cell (tests/monitor/CMakeLists.txt).
//
// What must hold (issue 10): the page loads with no console errors; the 3-D canvas renders (a
// screenshot is not blank); when the robot moves, the rendered robot's joint values follow
// RobotState within 100 ms; an unauthenticated page cannot send commands; a job submitted from
// the page shows up in `cellctl jobs` (skipped only when no task service answers on the bus).
// And what a user sees besides: the camera view's detections, "go to the grasp position of
// part N" with the gripper camera, the alarm log, the plots, and the job list with each part's
// result as `cellctl job` has it.
//
// CELL_MONITOR_SCREENSHOTS=DIR also writes the README's screenshots (monitor-main.png,
// monitor-gripper.png, monitor-jobs.png; docs/ holds the committed ones).
import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { Cell, kOperator, openBrowser, sleep, until } from './cell.mjs';

// The issue's bound: rendered joints follow RobotState within 100 ms. Held by 99 % of the frames
// drawn during a move; no frame may lag twice that (the margin is for the scheduler of a shared
// 2-core machine, where the browser, the bridge and a whole cell compete with other work).
const kFollowMs = 100;
const kFollowWorstMs = 200;
const kJointTol = 1e-9;  // rendered joints (decoded from the scene graph) vs RobotState [rad|mm]
const kFkTolMm = 1e-6;   // the page's FK vs the gateway's (RobotState.base_T_tool)

let cell;
let browser;
let page;

// ctest runs this file twice: monitor_browser.simulated_cell (everything but the job check)
// and monitor_browser.job_from_the_page (CELL_BROWSER_TESTS=jobs: the job check alone, so
// that ctest reports it skipped when no task service answers).
const jobsOnly = process.env.CELL_BROWSER_TESTS === 'jobs';
const main = jobsOnly ? (name, fn) => test(name, (t) => t.skip('run by monitor_browser.simulated_cell')) : test;
const jobs = jobsOnly ? test : (name, fn) => test(name, (t) => t.skip('run by monitor_browser.job_from_the_page'));

/// True when a task service answers on the bus (its heartbeat says serving).
function taskServiceServing() {
  const ping = cell.cellctl('--json', 'ping');
  if (ping.code !== 0) return false;
  const services = JSON.parse(ping.stdout.slice(ping.stdout.indexOf('{'))).services;
  return services.some((s) => s.kind === 'task' && s.state === 'serving');
}

async function signIn() {
  if (await page.evaluate(() => window.cellMonitor.app.session.signed_in)) return;
  await page.fill('#login-user', kOperator.user);
  await page.fill('#login-password', kOperator.password);
  await page.click('#login-submit');
  await page.waitForSelector('#who:not([hidden])', { timeout: 10000 });
}

before(async () => {
  // The job check runs the page's table_ics template to its end: three parts show what the
  // page must (every part's row as the task service has it, the alarms, the pick-rate plot) in
  // a quarter of the fifteen's time; the README's screenshot shows the whole job.
  cell = new Cell({ robots: ['ibm7545', 'scara_picker'],
    jobMaxParts: process.env.CELL_MONITOR_SCREENSHOTS ? undefined : 3 });
  try {
    await cell.start();
    browser = await openBrowser(cell.url);
    page = browser.page;
    await until(() => page.evaluate(() => window.cellMonitor.latest('ibm7545') !== null), 20000,
      'the page to receive RobotState');
  } catch (e) {
    console.error(cell.logs());
    throw e;
  }
});

after(async () => {
  if (browser) await browser.close();
  if (cell) await cell.stop();
});

/// Fraction of pixels differing from the background colour `bg` (the view's clear colour) and
/// the number of distinct colours of a PNG (analysed in the page: it has a PNG decoder, node
/// has none).
async function pngStats(png, bg) {
  return page.evaluate(async ([b64, bg]) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = new OffscreenCanvas(img.width, img.height);
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, img.width, img.height).data;
    const colours = new Set();
    let differ = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (Math.abs(d[i] - bg[0]) + Math.abs(d[i + 1] - bg[1]) + Math.abs(d[i + 2] - bg[2]) > 24) ++differ;
      colours.add((d[i] >> 3) << 10 | (d[i + 1] >> 3) << 5 | (d[i + 2] >> 3));
    }
    return { width: img.width, height: img.height, differ: differ / (d.length / 4), colours: colours.size };
  }, [png.toString('base64'), bg]);
}

const kOrbitBackground = [0xee, 0xf1, 0xf4];    // scene.js: the orbit view's clear colour
const kGripperBackground = [0x20, 0x24, 0x28];  // and the gripper view's

main('the page loads with no console errors', async () => {
  await sleep(2000);  // a couple of seconds of streaming and rendering
  const stats = await page.evaluate(() => window.cellMonitor.stats());
  assert.ok(stats.frames > 10, `only ${stats.frames} frames rendered`);
  assert.ok(stats.messages > 10, `only ${stats.messages} stream messages`);
  assert.deepEqual(browser.errors, []);
  assert.deepEqual(await page.evaluate(() => window.cellMonitor.errors), []);
});

main('the 3-D canvas renders: its screenshot is not blank', async () => {
  const canvas = await page.$('#view');
  const png = await canvas.screenshot();
  const s = await pngStats(png, kOrbitBackground);
  console.log(`canvas ${s.width}x${s.height}: ${(100 * s.differ).toFixed(1)} % of pixels drawn, ${s.colours} colours`);
  assert.ok(s.differ > 0.05, `only ${(100 * s.differ).toFixed(2)} % of the canvas differs from its background`);
  assert.ok(s.colours > 50, `only ${s.colours} colours: a blank or flat canvas`);
  // The gripper camera's half is drawn too (it has its own dark background).
  const box = await canvas.boundingBox();
  const gripper = await page.screenshot({ clip: { x: box.x + box.width * 0.7, y: box.y, width: box.width * 0.3, height: box.height } });
  const g = await pngStats(gripper, kGripperBackground);
  console.log(`gripper view: ${(100 * g.differ).toFixed(1)} % of pixels drawn, ${g.colours} colours`);
  assert.ok(g.differ > 0.05 && g.colours >= 5, `the gripper view is blank: ${JSON.stringify(g)}`);
});

main('when the robot moves, the rendered joints follow RobotState within 100 ms', async () => {
  const probe = await cell.probe('ibm7545');
  const startMs = Date.now();
  const target = [80, 60, 120, 45];  // deg, deg, mm, deg
  const move = cell.cellctl('move', 'joints', '--robot', 'ibm7545', '--joints', target.join(','), '--speed', '0.5', '--wait', '60');
  assert.equal(move.code, 0, `cellctl move failed: ${move.stdout}${move.stderr}`);
  await sleep(500);  // the last frames of the move reach the page
  const samples = (await probe.stop()).filter((s) => s.received_ns / 1e6 >= startMs);
  const bySeq = new Map(samples.map((s) => [s.seq, s]));
  // The motion's span on the bus: from the first sample that differs from the start to the
  // first that reached the end.
  const q0 = samples[0].q;
  const qEnd = samples[samples.length - 1].q;
  const moved = (s, ref) => s.q.some((v, i) => Math.abs(v - ref[i]) > 1e-6);
  const first = samples.find((s) => moved(s, q0));
  const last = samples.find((s) => !moved(s, qEnd));
  assert.ok(first && last && last.stamp_ns > first.stamp_ns, 'the robot did not move on the bus');
  const frames = await page.evaluate(([since]) => window.cellMonitor.rendered('ibm7545', since), [startMs]);
  const during = frames.filter((f) => f.t_ms >= first.stamp_ns / 1e6 + kFollowMs && f.t_ms <= last.stamp_ns / 1e6);
  assert.ok(during.length >= 20, `only ${during.length} frames rendered during the ${((last.stamp_ns - first.stamp_ns) / 1e9).toFixed(2)} s move`);
  // What it drew is that RobotState: the same joints (decoded from the scene graph) and
  // stamp as the bus sample of that sequence number. The probe is a best-effort reader too and
  // may miss a sample under load; a frame of a sample it missed must lie between the bus
  // samples just before and after it.
  let worstJoint = 0;
  let matched = 0;
  const sorted = samples.slice().sort((a, b) => a.seq - b.seq);
  // How far each frame lags RobotState: how long a newer sample than the one it drew had been
  // on the bus (from the newer sample's stamp; 0 when the drawn one was the newest). A pause
  // of the robot's own stream is no lag of the page.
  const lags = [];
  for (const f of during) {
    const next = sorted.find((x) => x.seq > f.seq);
    lags.push({ frame: f, lag: next ? Math.max(0, f.t_ms - next.stamp_ns / 1e6) : 0, next });
    const s = bySeq.get(f.seq);
    if (s) {
      ++matched;
      assert.equal(f.stamp_ns, s.stamp_ns, `frame of sample ${f.seq}: stamp differs from the bus's`);
      worstJoint = Math.max(worstJoint, ...f.q.map((v, i) => Math.abs(v - s.q[i])));
      continue;
    }
    const prev = sorted.filter((x) => x.seq < f.seq).pop();
    assert.ok(prev && next, `frame of sample ${f.seq}: no bus samples around it`);
    f.q.forEach((v, i) => {
      const lo = Math.min(prev.q[i], next.q[i]) - kJointTol, hi = Math.max(prev.q[i], next.q[i]) + kJointTol;
      assert.ok(v >= lo && v <= hi, `frame of sample ${f.seq}: joint ${i} = ${v} outside [${lo}, ${hi}]`);
    });
  }
  lags.sort((a, b) => a.lag - b.lag);
  const ages = during.map((f) => f.t_ms - f.stamp_ns / 1e6).sort((a, b) => a - b);
  const pct = (v, p) => v[Math.min(v.length - 1, Math.floor(p * v.length))];
  const lagValues = lags.map((l) => l.lag);
  const worst = lags[lags.length - 1];
  console.log(`${during.length} frames during the move: lag behind RobotState p50 ${pct(lagValues, 0.5).toFixed(1)} ms, ` +
    `p99 ${pct(lagValues, 0.99).toFixed(1)} ms, max ${worst.lag.toFixed(1)} ms; age of the sample drawn p50 ` +
    `${pct(ages, 0.5).toFixed(1)} ms, max ${ages[ages.length - 1].toFixed(1)} ms; rendered vs bus joints ` +
    `${worstJoint.toExponential(1)} over ${matched} frames the probe can match`);
  for (const { frame: f, lag, next } of lags.slice(-3).filter((l) => l.lag > kFollowMs / 2)) {
    const parts = next ? await page.evaluate(([seq]) => window.cellMonitor.delayOf('ibm7545', seq), [next.seq]) : null;
    console.log(`slow frame: drew sample ${f.seq} ${lag.toFixed(1)} ms after sample ${next.seq} was stamped; sample ` +
      `${next.seq}: ` + (parts ? `gateway->bridge ${parts.gateway_to_bridge.toFixed(1)}, in the bridge ` +
        `${parts.in_bridge.toFixed(1)}, bridge->page ${parts.bridge_to_page.toFixed(1)} ms` : 'never reached the page'));
  }
  assert.ok(matched >= during.length / 2, `only ${matched} of ${during.length} frames match a bus sample`);
  assert.ok(worstJoint <= kJointTol, `the rendered joints differ from RobotState by ${worstJoint}`);
  assert.ok(pct(lagValues, 0.99) <= kFollowMs,
    `1 % of the frames lagged RobotState by over ${pct(lagValues, 0.99).toFixed(1)} ms (bound ${kFollowMs} ms)`);
  assert.ok(worst.lag <= kFollowWorstMs,
    `a frame lagged RobotState by ${worst.lag.toFixed(1)} ms (never more than ${kFollowWorstMs} ms)`);
  // The rendered robot ends where the robot is; the page's FK agrees with the gateway's.
  const end = frames[frames.length - 1];
  const deg = Math.PI / 180;
  [target[0] * deg, target[1] * deg, target[2], target[3] * deg].forEach((v, i) =>
    assert.ok(Math.abs(end.q[i] - v) < 1e-6, `rendered joint ${i} ends at ${end.q[i]}, target ${v}`));
  const fk = await page.evaluate(() => {
    const view = window.cellMonitor.app.scene.robots.get('ibm7545');
    return { tool: view.tool, seq: view.sample.seq };
  });
  const bus = samples.find((s) => s.seq === fk.seq) || samples[samples.length - 1];
  const dp = Math.hypot(fk.tool[3] - bus.base_T_tool[3], fk.tool[7] - bus.base_T_tool[7], fk.tool[11] - bus.base_T_tool[11]);
  assert.ok(dp < kFkTolMm, `the page's FK is ${dp} mm from the gateway's base_T_tool`);
});

main('an unauthenticated page cannot send commands', async () => {
  const before = await page.evaluate(() => window.cellMonitor.latest('ibm7545'));
  const errorsBefore = browser.errors.length;
  // The controls are disabled...
  const disabled = await page.$$eval('button.cmd', (bs) => bs.filter((b) => !b.disabled).map((b) => b.id || b.textContent));
  assert.deepEqual(disabled, []);
  // ...and the bridge refuses every command the page (or anything else) would try.
  const answers = await page.evaluate(async () => {
    const post = async (path, body) => (await fetch(path, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) })).status;
    return {
      motion: await post('/api/motion', { robot: 'ibm7545', joints: [100, 50, 10, 0] }),
      robot: await post('/api/robot/command', { robot: 'ibm7545', command: 'open' }),
      goto: await post('/api/goto_part', { robot: 'ibm7545', part: 'ic8' }),
      job: await post('/api/job/submit', { template: 'table_ics' }),
      teach: await post('/api/teach/create', { robot: 'ibm7545', name: 'x' }),
    };
  });
  assert.deepEqual(answers, { motion: 401, robot: 401, goto: 401, job: 401, teach: 401 });
  // Chromium logs each refused request as a console error: exactly those five, and they are
  // this test's own doing, so they do not count against the page.
  const refused = browser.errors.splice(errorsBefore);
  assert.equal(refused.length, 5, refused.join('\n'));
  assert.ok(refused.every((e) => e.includes('401 (Unauthorized)')), refused.join('\n'));
  await sleep(1000);
  const after = await page.evaluate(() => window.cellMonitor.latest('ibm7545'));
  assert.deepEqual(after.q, before.q, 'the robot moved after a refused command');
  assert.equal(after.gripper, before.gripper, 'the gripper changed after a refused command');
});

main('a signed-in operator jogs with a preview first; nothing moves before Send', async () => {
  await signIn();
  await page.selectOption('#robot-select', 'ibm7545');
  await page.selectOption('#jog-space', 'joint');
  await page.fill('#jog-step', '10');
  const before = await page.evaluate(() => window.cellMonitor.latest('ibm7545').q);
  await page.click('#jog-buttons .jog-row:first-child button:last-child');  // j1 +10 deg
  await page.waitForSelector('#preview-bar:not([hidden])', { timeout: 15000 });
  assert.ok(await page.evaluate(() => window.cellMonitor.app.scene.ghosts.get('ibm7545').group.visible));
  await sleep(1000);
  const still = await page.evaluate(() => window.cellMonitor.latest('ibm7545').q);
  assert.deepEqual(still, before, 'the robot moved on a preview');
  await page.click('#preview-send');
  const want = before[0] + 10 * Math.PI / 180;
  await until(() => page.evaluate((w) => Math.abs(window.cellMonitor.latest('ibm7545').q[0] - w) < 1e-6, want),
    30000, 'j1 to reach +10 deg');
});

/// Moves `robot` to `joints` (deg, deg, mm, deg) with cellctl and waits for the page to show it.
async function moveTo(robot, joints) {
  const r = cell.cellctl('move', 'joints', '--robot', robot, '--joints', joints.join(','), '--wait', '60');
  assert.equal(r.code, 0, `cellctl move failed: ${r.stdout}${r.stderr}`);
  const deg = Math.PI / 180;
  const want = [joints[0] * deg, joints[1] * deg, joints[2], joints[3] * deg];
  await until(() => page.evaluate(([id, w]) => {
    const s = window.cellMonitor.latest(id);
    return s && !s.moving && s.q.every((v, i) => Math.abs(v - w[i]) < 1e-6);
  }, [robot, want]), 20000, `the page to show ${robot} at ${joints}`);
}

/// The newest detections of `camera` the page has, once they come from an image taken after
/// `sinceMs` (wall clock) and found at least one part.
async function freshDetections(camera, sinceMs) {
  return until(() => page.evaluate(([cam, since]) => {
    const d = window.cellMonitor.app.cameraView.detections.get(cam);
    return d && d.stamp_ns / 1e6 > since && d.items.length > 0 && d.items[0].base_pose ? d : null;
  }, [camera, sinceMs]), 30000, `detections of ${camera} after the move`, 200);
}

main('the camera view draws the live image with each detection, its index and fingerprints', async (t) => {
  if (!cell.has('cell-vision')) {
    t.skip('cell-vision is not built: no detections to draw');
    return;
  }
  await page.click('#preview-discard').catch(() => {});
  await page.selectOption('#camera-select', 'ibm7545_eye');
  // The thesis's image-grab pose: the eye-in-hand camera sees the table's ICs.
  const since = Date.now();
  await moveTo('ibm7545', [45, 105, 0, 0]);
  const d = await freshDetections('ibm7545_eye', since);
  await sleep(600);  // the image of those detections loads and the view redraws
  const info = await page.textContent('#camera-info');
  const found = info.match(/(\d+) parts? found/);
  assert.ok(found && Number(found[1]) > 0, info);
  // Each detection's centre cross is drawn in its grip colour (green clear, red blocked, grey
  // not tested) over the image: read the canvas 3 px right of every centre.
  const colours = { clear: [0x20, 0xb0, 0x50], blocked: [0xe0, 0x30, 0x30], not_tested: [0xa0, 0xa8, 0xb0] };
  const drawn = await page.evaluate(() => {
    const view = window.cellMonitor.app.cameraView;
    const d = view.detections.get('ibm7545_eye');
    const g = view.canvas.getContext('2d');
    // The arms of the cross (1.5 px wide at a sub-pixel centre): the pixels 2-4 px right of
    // the centre on the rows either side of it.
    return d.items.map((item) => {
      const [u, v] = item.center_px;
      const arm = [];
      for (const y of [Math.floor(v), Math.ceil(v)]) {
        for (const x of [Math.round(u) + 2, Math.round(u) + 3, Math.round(u) + 4]) {
          arm.push([...g.getImageData(x, y, 1, 1).data].slice(0, 3));
        }
      }
      return { grip: item.grip, arm, image: [...g.getImageData(Math.round(u) + 30, Math.round(v) + 30, 1, 1).data].slice(0, 3) };
    });
  });
  let crosses = 0;
  for (const x of drawn) {
    const want = colours[x.grip] || colours.not_tested;
    if (x.arm.some((rgb) => rgb.every((v, i) => Math.abs(v - want[i]) <= 40))) ++crosses;
  }
  console.log(`${d.items.length} detections: ${drawn.map((x) => x.grip).join(', ')}; ${crosses} centre crosses in their grip colour`);
  // Antialiasing may blend a cross with its neighbour's outline: most, not all, must match.
  assert.ok(crosses >= Math.ceil(0.75 * drawn.length), `only ${crosses} of ${drawn.length} centre crosses drawn in their grip colour`);
  // The image itself is under the overlay (not the empty view's flat #101214).
  assert.ok(drawn.some((x) => x.image.some((v, i) => Math.abs(v - [0x10, 0x12, 0x14][i]) > 24)), 'no camera image under the overlay');
  // The clear-grip fingerprints: the grasp models come with the config for every detected class.
  const classes = await page.evaluate(() => [...window.cellMonitor.app.cameraView.grasps.keys()]);
  const tested = d.items.filter((i) => i.grip !== 'not_tested');
  assert.ok(tested.every((i) => classes.includes(i.class)), `no grasp model for ${tested.map((i) => i.class)} in ${classes}`);
});

main('"go to the grasp position of part N": preview, send, and the tool stops above that part', async (t) => {
  if (!cell.has('cell-vision')) {
    t.skip('cell-vision is not built: no detection N to go to');
    return;
  }
  await signIn();
  await page.selectOption('#robot-select', 'ibm7545');
  const d = await freshDetections('ibm7545_eye', 0);
  // A part with a clear grip if there is one, else one vision classified, else the first.
  const n = [d.items.findIndex((i) => i.grip === 'clear'), d.items.findIndex((i) => i.class !== 'unknown')]
    .find((k) => k >= 0);
  const index = n === undefined ? 0 : n;
  const before = await page.evaluate(() => window.cellMonitor.latest('ibm7545').q);
  await page.fill('#goto-what', String(index));
  await page.click('#goto-preview');
  await page.waitForSelector('#preview-bar:not([hidden])', { timeout: 15000 });
  assert.match(await page.textContent('#preview-text'), new RegExp(`go to part ${index}: [0-9.]+ s planned`));
  assert.ok(await page.evaluate(() => window.cellMonitor.app.scene.ghosts.get('ibm7545').group.visible), 'no ghost arm');
  await sleep(800);
  assert.deepEqual(await page.evaluate(() => window.cellMonitor.latest('ibm7545').q), before, 'the robot moved on a preview');
  await page.click('#preview-send');
  await until(() => page.evaluate((q0) => {
    const s = window.cellMonitor.latest('ibm7545');
    return !s.moving && s.q.some((v, i) => Math.abs(v - q0[i]) > 1e-3);
  }, before), 60000, 'the robot to arrive at the part');
  // Where the tool is (the gateway's base_T_tool, in the world) against where the world
  // simulator has the parts: right above one of them, the bridge's approach height over it.
  const where = await page.evaluate(() => {
    const app = window.cellMonitor.app;
    const view = app.scene.robots.get('ibm7545');
    const s = app.latest.get('ibm7545');
    const K = view.world_T_base;
    const m = s.base_T_tool;  // {p, q}
    const p = m.p;
    const w = [K[0] * p[0] + K[1] * p[1] + K[2] * p[2] + K[3], K[4] * p[0] + K[5] * p[1] + K[6] * p[2] + K[7],
      K[8] * p[0] + K[9] * p[1] + K[10] * p[2] + K[11]];
    return { tool: w, base: p, table: app.scene.tableHeight,
      parts: app.worldParts.map((x) => ({ id: x.id, class: x.class, support: x.support, p: x.pose.p })) };
  });
  const near = where.parts.map((x) => ({ ...x, dxy: Math.hypot(x.p[0] - where.tool[0], x.p[1] - where.tool[1]) }))
    .sort((a, b) => a.dxy - b.dxy)[0];
  const item = d.items[index];
  const bp = item.base_pose;
  const toBase = Math.hypot(where.base[0] - bp.x_mm, where.base[1] - bp.y_mm);
  console.log(`detection ${index} (${item.class}, ${item.grip}) at (${bp.x_mm.toFixed(1)}, ${bp.y_mm.toFixed(1)}) mm in ` +
    `the base: the tool stopped ${toBase.toFixed(3)} mm from it, at (${where.tool.map((v) => v.toFixed(1)).join(', ')}) mm ` +
    `in the world, ${near.dxy.toFixed(2)} mm (xy) from part ${near.id} (${near.class}), ` +
    `${(where.tool[2] - where.table).toFixed(1)} mm above the table`);
  // Where vision said (the gateway's tolerance), and over a real part of that class: vision
  // maps pixels with the camera's NOMINAL model until cell-calibration publishes one, and the
  // simulated camera renders through the true one, so the part can be some mm off.
  const kGatewayTolMm = 0.5;
  const kNominalCalibrationTolMm = 15;
  assert.ok(toBase < kGatewayTolMm, `the tool is ${toBase.toFixed(3)} mm from detection ${index}'s position`);
  assert.ok(near.dxy < kNominalCalibrationTolMm, `the tool is ${near.dxy.toFixed(2)} mm from the nearest part (${near.id})`);
  if (item.class !== 'unknown') {
    assert.equal(near.class, item.class, `detection ${index} is a ${item.class}, the part under the tool a ${near.class}`);
  }
  // 20 mm approach (goto_part.approach_mm) over the grasp height (3.81 mm) on the table.
  assert.ok(Math.abs(where.tool[2] - where.table - 23.81) < 1, `the tool is ${(where.tool[2] - where.table).toFixed(2)} mm above the table, not 23.81`);
  // The gripper camera rides the tool point and looks straight down along the approach: the
  // part is 20 mm ahead of it (and off its centre by what the nominal calibration is off).
  await sleep(300);  // a gripper-view frame after the last RobotState
  const view = await page.evaluate(([id, tool]) => {
    const scene = window.cellMonitor.app.scene;
    const obj = scene.parts.get(id);
    const v = obj.position.clone();
    obj.getWorldPosition(v);
    const cam = scene.gripperCam;
    cam.updateMatrixWorld();
    const inCam = v.clone().applyMatrix4(cam.matrixWorldInverse);
    v.project(cam);
    const c = cam.position;
    const e = cam.matrixWorld.elements;  // column-major: the camera looks along its -z column
    return { x: v.x, y: v.y, ahead_mm: -inCam.z, fromTool_mm: Math.hypot(c.x - tool[0], c.y - tool[1], c.z - tool[2]),
      look: [-e[8], -e[9], -e[10]] };
  }, [near.id, where.tool]);
  console.log(`gripper view: part ${near.id} ${view.ahead_mm.toFixed(1)} mm ahead at (${view.x.toFixed(2)}, ${view.y.toFixed(2)}) ` +
    `of the view's [-1, 1]; camera ${view.fromTool_mm.toFixed(1)} mm from the tool point`);
  assert.ok(view.fromTool_mm < 5, `the gripper camera is ${view.fromTool_mm} mm from the tool point`);
  assert.ok(view.look[2] < -0.999, `the gripper camera does not look down: ${view.look}`);
  assert.ok(Math.abs(view.ahead_mm - 20) < 5, `part ${near.id} is ${view.ahead_mm} mm ahead of the gripper camera, not 20`);
});

main('the alarm log shows each operator command as it comes back over the bus, newest first', async () => {
  // The goto of the test before: the bridge published it as a CellEvent, read it back from the
  // bus and streamed it to the page.
  const line = await until(() => page.evaluate((user) => [...document.querySelectorAll('#alarms .event')]
    .map((e) => e.textContent).find((t) => t.includes(`${user}: go to the grasp position of`)), kOperator.user),
  10000, 'the operator\'s command in the alarm log');
  console.log(`alarm log: ${line}`);
  assert.match(line, /info.*monitor.*\[monitor\.command\]/);
  const times = await page.$$eval('#alarms .event span:first-child', (es) => es.map((e) => e.textContent));
  assert.deepEqual(times, times.slice().sort().reverse(), 'the log is not newest first');
  // "warnings and errors only" hides the info lines.
  const all = await page.$$eval('#alarms .event', (es) => es.length);
  await page.check('#alarms-only');
  const shown = await page.$$eval('#alarms .event', (es) => es.map((e) => e.className));
  await page.uncheck('#alarms-only');
  assert.ok(shown.length < all, `${shown.length} of ${all} lines still shown`);
  assert.ok(shown.every((c) => !c.includes('info')), shown.join(', '));
});

main('the plots follow each robot\'s tracking error and servo loop jitter', async () => {
  const plots = await page.evaluate(() => {
    const app = window.cellMonitor.app;
    const out = {};
    for (const [name, plot] of Object.entries(app.plots)) {
      out[name] = Object.fromEntries([...plot.series].map(([id, s]) => [id, s.length]));
    }
    const s = app.latest.get('ibm7545');
    return { out, jitterLatest: app.plots.jitter.latest('ibm7545'), jitter: s.jitter_max_us };
  });
  console.log(`plot points: ${JSON.stringify(plots.out)}`);
  for (const robot of ['ibm7545', 'scara_picker']) {
    assert.ok(plots.out.tracking[robot] > 20, `tracking error of ${robot}: ${plots.out.tracking[robot]} points`);
    assert.ok(plots.out.jitter[robot] > 20, `jitter of ${robot}: ${plots.out.jitter[robot]} points`);
  }
  assert.ok(Number.isFinite(plots.jitterLatest) && plots.jitterLatest >= 0, `jitter ${plots.jitterLatest}`);
  // Each plot's canvas has its lines drawn (the first series is amber, the second blue).
  const inked = await page.evaluate(() => ['plot-tracking', 'plot-jitter'].map((id) => {
    const c = document.getElementById(id);
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (Math.abs(d[i] - 0xe0) + Math.abs(d[i + 1] - 0xa0) + Math.abs(d[i + 2] - 0x20) < 60 ||
      Math.abs(d[i] - 0x3a) + Math.abs(d[i + 1] - 0x8e) + Math.abs(d[i + 2] - 0xe6) < 60) ++n;
    return n;
  }));
  assert.ok(inked.every((n) => n > 20), `plot lines: ${inked} pixels`);
});

jobs('a job submitted from the page shows up in `cellctl jobs`', async (t) => {
  if (!taskServiceServing()) {
    t.skip('no task service answers on the bus (cellctl ping lists none): the job check needs cell-task');
    return;
  }
  await signIn();
  const jobId = `browser-${Date.now()}`;
  await page.selectOption('#job-template', 'table_ics');
  await page.fill('#job-id', jobId);
  await page.click('#job-submit');
  await page.waitForSelector(`.job[data-job="${jobId}"]`, { timeout: 20000 });
  const listed = await until(() => {
    const r = cell.cellctl('jobs');
    return r.code === 0 && r.stdout.includes(jobId) ? r.stdout : null;
  }, 20000, `${jobId} in cellctl jobs`, 500);
  assert.ok(listed.includes(jobId));
  jobFromThePage = jobId;
});

let jobFromThePage = null;

/// The page's job list entry of `jobId`: state, counts line and its per-part rows.
function pageJob(jobId) {
  return page.evaluate((id) => {
    const item = document.querySelector(`.job[data-job="${id}"]`);
    if (!item) return null;
    return {
      state: item.querySelector('.state').textContent,
      counts: item.querySelector('.job-head .muted').textContent,
      fill: item.querySelector('.bar .fill').style.width,
      rows: [...item.querySelectorAll('table.parts tr')].map((tr) => [...tr.children].map((td) => td.textContent)),
    };
  }, jobId);
}

jobs('the job runs to the end and the page lists each part\'s result as the task service has it', async (t) => {
  if (!jobFromThePage) {
    t.skip('no job was submitted');
    return;
  }
  const jobId = jobFromThePage;
  // While it runs the page shows its progress and the parts done so far; at the end, all.
  let running = null;
  const done = await until(async () => {
    const j = await pageJob(jobId);
    if (j && j.state === 'running' && j.rows.length > 0 && !running) running = j;
    return j && ['succeeded', 'failed', 'cancelled'].includes(j.state) ? j : null;
  }, 400000, `${jobId} to end`, 250).catch(async (e) => {
    console.log(`${JSON.stringify(await pageJob(jobId))}\n${cell.cellctl('job', jobId).stdout}\n${cell.logs()}`);
    throw e;
  });
  if (running) console.log(`while running: ${running.counts}, bar ${running.fill}, ${running.rows.length} part rows`);
  const r = cell.cellctl('--json', 'job', jobId);
  assert.equal(r.code, 0, r.stderr);
  const bus = JSON.parse(r.stdout);
  console.log(`ended: ${done.state}, ${done.counts}; task service: ${bus.state}, ${bus.parts_done} placed, ` +
    `${bus.parts_failed} failed, ${bus.parts.length} parts, ${bus.elapsed_s.toFixed(1)} s`);
  if (bus.reasons.length) console.log(`reasons: ${bus.reasons.join('; ')}`);
  assert.equal(done.state, bus.state);
  // A real job: the robot picked and placed parts (whether every one made it is the task
  // service's business; the page must show what it says).
  assert.ok(['succeeded', 'failed'].includes(bus.state), `the job was ${bus.state}`);
  assert.ok(bus.parts_done > 0, `no part placed: ${bus.parts.map((p) => `${p.outcome} ${p.detail}`).join('; ')}`);
  const reasons = await page.$$eval(`.job[data-job="${jobId}"] .error`, (es) => es.map((e) => e.textContent));
  assert.deepEqual(reasons, bus.reasons);
  if (bus.state === 'succeeded') assert.equal(done.fill, '100%');
  assert.match(done.counts, new RegExp(`^${bus.parts_done} placed, ${bus.parts_failed} failed`));
  // Row by row the same parts, classes, outcomes and place positions as `cellctl job`.
  assert.equal(done.rows.length, bus.parts.length);
  for (const p of bus.parts) {
    const row = done.rows.find((x) => x[0] === String(p.index));
    assert.ok(row, `part ${p.index} missing from the page`);
    assert.equal(row[1], p.class);
    assert.equal(row[2], p.outcome.replaceAll('_', ' '));
    if (p.outcome === 'placed') {
      assert.equal(row[3], `${p.placed_at.x_mm.toFixed(1)}, ${p.placed_at.y_mm.toFixed(1)} mm`);
    }
  }
  // The alarm log has the task service's own events about it (not only the operator's).
  const lines = await page.$$eval('#alarms .event', (es) => es.map((e) => e.textContent));
  const ofJob = lines.filter((l) => l.includes(jobId));
  console.log(`alarm log about ${jobId}:\n  ${ofJob.join('\n  ')}`);
  assert.ok(ofJob.some((l) => l.includes('task')), `no event from the task service about ${jobId}`);
  // The pick-rate plot counted the parts that left the table on the gripper.
  const { rate, picks, supports } = await page.evaluate(() => {
    const app = window.cellMonitor.app;
    const s = app.plots.picks.series.get('ibm7545') || [];
    return { rate: Math.max(0, ...s.map(([, v]) => v)), picks: app.picks.filter(([, r]) => r === 'ibm7545').length,
      supports: [...app.supports.values()].join(' ') };
  });
  console.log(`world supports at the end: ${supports}`);
  console.log(`pick rate peak ${rate} parts/min; ${picks} parts seen leaving the table on the gripper`);
  // Each part the task service placed had the gripper close on it: the world either lifted a
  // part off the table (the page counts it from WorldState) or said the gripper closed on
  // nothing (a world.pick_missed event in the alarm log: the eye-in-hand camera's NOMINAL
  // calibration puts parts ~11 mm from where the simulated camera's true model sees them).
  const missed = lines.filter((l) => l.includes('[world.pick_missed]') && l.includes("'ibm7545'")).length;
  console.log(`the world: ${picks} parts lifted off the table, ${missed} grasps on nothing`);
  assert.ok(picks + missed >= bus.parts_done, `the page saw ${picks} picks and ${missed} misses; the task service placed ${bus.parts_done}`);
  assert.equal(rate > 0, picks > 0, `pick-rate plot peak ${rate} with ${picks} picks`);
});

main('screenshots for the README (CELL_MONITOR_SCREENSHOTS)', async (t) => {
  const dir = process.env.CELL_MONITOR_SCREENSHOTS;
  if (!dir) {
    t.skip('CELL_MONITOR_SCREENSHOTS is not set');
    return;
  }
  await signIn();
  await page.click('#preview-discard').catch(() => {});
  // Back at the thesis's image-grab pose, where the eye-in-hand camera sees the ICs.
  assert.equal(cell.cellctl('move', 'joints', '--robot', 'ibm7545', '--joints', '45,105,0,0', '--wait', '60').code, 0);
  await sleep(3000);
  // A preview on screen: the ghost arm on its way to part ic12's grasp position; the camera
  // shows the ICs the eye-in-hand camera sees from the image-grab pose, with their detections.
  await page.fill('#goto-what', 'ic12');
  await page.click('#goto-preview');
  await page.waitForSelector('#preview-bar:not([hidden])', { timeout: 15000 }).catch(() => {});
  await sleep(1500);
  await page.evaluate(() => window.scrollTo(0, 0));
  await sleep(300);
  // The page as a user sees it on opening (the viewport, not the whole scrolled page) and the
  // gripper camera's half of the 3-D view.
  writeFileSync(join(dir, 'monitor-main.png'), await page.screenshot());
  const canvas = await page.$('#view');
  const box = await canvas.boundingBox();
  writeFileSync(join(dir, 'monitor-gripper.png'), await page.screenshot({
    clip: { x: box.x + box.width * 0.68, y: box.y, width: box.width * 0.32, height: box.height } }));
  await page.click('#preview-discard').catch(() => {});
  // A job in the list when a task service runs (the thesis's: every IC to the output column),
  // with its parts so far, the plots and the alarm log.
  if (!taskServiceServing()) return;
  await page.selectOption('#job-template', 'table_ics');
  await page.fill('#job-id', 'readme-job');
  await page.click('#job-submit');
  await sleep(30000);
  const jobsBox = await (await page.$('#jobs-box')).boundingBox();
  const alarms = await (await page.$('#alarms-box')).boundingBox();
  await page.evaluate((y) => window.scrollTo(0, y - 10), jobsBox.y);
  const scroll = await page.evaluate(() => window.scrollY);
  writeFileSync(join(dir, 'monitor-jobs.png'), await page.screenshot({
    clip: { x: 0, y: jobsBox.y - scroll - 8, width: 1600,
      height: Math.min(1000 - (jobsBox.y - scroll - 8), alarms.y + alarms.height - jobsBox.y + 16) } }));
});

test('no console errors from start to end', () => {
  assert.deepEqual(browser.errors, []);
});
