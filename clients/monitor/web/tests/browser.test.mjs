// The monitor in a real browser (Debian's headless Chromium, driven by playwright-core) against
// a simulated cell (`cell up`: world simulator, two gateways with the ideal robot, motion
// service, the eye-in-hand camera, the monitor's bridge; vision and the task service when
// they are built). ctest: monitor_browser.simulated_cell (tests/monitor/CMakeLists.txt).
//
// What must hold (issue 10): the page loads with no console errors; the 3-D canvas renders (a
// screenshot is not blank); when the robot moves, the rendered robot's joint values follow
// RobotState within 100 ms; an unauthenticated page cannot send commands; a job submitted from
// the page shows up in `cellctl jobs` (skipped only when no task service answers on the bus).
//
// CELL_MONITOR_SCREENSHOTS=DIR also writes the README's screenshots (monitor.png, gripper.png).
import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { Cell, kOperator, openBrowser, sleep, until } from './cell.mjs';

// The bound: rendered joints follow RobotState within 100 ms. Held by 99 % of the frames
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
  cell = new Cell({ robots: ['ibm7545', 'scara_picker'] });
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
  // A job in the list when a task service runs (the thesis's: every IC to the output column).
  if (taskServiceServing()) {
    await page.selectOption('#job-template', 'table_ics');
    await page.fill('#job-id', 'readme-job');
    await page.click('#job-submit');
    await sleep(25000);
  }
  // A preview on screen: the ghost arm on its way to part ic12's grasp position.
  await page.fill('#goto-what', 'ic12');
  await page.click('#goto-preview');
  await page.waitForSelector('#preview-bar:not([hidden])', { timeout: 15000 }).catch(() => {});
  await sleep(1500);
  writeFileSync(join(dir, 'monitor.png'), await page.screenshot({ fullPage: true }));
  const canvas = await page.$('#view');
  const box = await canvas.boundingBox();
  writeFileSync(join(dir, 'gripper.png'), await page.screenshot({
    clip: { x: box.x + box.width * 0.68, y: box.y, width: box.width * 0.32, height: box.height } }));
});

test('no console errors from start to end', () => {
  assert.deepEqual(browser.errors, []);
});
