// monitor_bench: the web monitor in headless Chromium against a simulated cell (bench/README.md,
// section monitor). Two robots (the IBM 7545 and the conveyor picker, both moving back and forth
// all the time) and 50 parts on the table; measured in the page:
//   - frames per second of the 3-D view (orbit + gripper camera, 1600 x 1000 window);
//   - the delay from a RobotState sample (its header stamp: when the gateway read the joints)
//     to the page (the stream message's arrival), and to the first frame that drew it.
// Targets (issue 10): 60 fps, delay under 50 ms.
//   monitor_bench [--seconds S] [--parts N] [--json]      (node; CELL_BIN_DIR, CELL_SOURCE_DIR)
import { readFileSync } from 'node:fs';

import { Cell, openBrowser, sleep, until } from '../../clients/monitor/web/tests/cell.mjs';

const args = process.argv.slice(2);
const opt = (name, fallback) => {
  const i = args.indexOf(name);
  return i >= 0 ? Number(args[i + 1]) : fallback;
};
/// The bridge's pid, from its heartbeat (`cellctl ping`).
function bridgePid() {
  const ping = cell.cellctl('--json', 'ping');
  if (ping.code !== 0) return null;
  const services = JSON.parse(ping.stdout.slice(ping.stdout.indexOf('{'))).services;
  const monitor = services.find((x) => x.kind === 'monitor' || x.id === 'monitor');
  return monitor ? monitor.pid : null;
}

/// User + system CPU time of a process [s] (/proc/<pid>/stat, fields 14 and 15, in clock ticks
/// of 100 Hz on Linux).
function cpuSeconds(pid) {
  if (!pid) return 0;
  const stat = readFileSync(`/proc/${pid}/stat`, 'utf8');
  const fields = stat.slice(stat.lastIndexOf(')') + 2).split(' ');
  return (Number(fields[11]) + Number(fields[12])) / 100;
}

const seconds = opt('--seconds', 20);
const partsWanted = opt('--parts', 50);
const asJson = args.includes('--json');
const log = (...a) => console.error('monitor_bench:', ...a);

function quantiles(values) {
  const v = values.slice().sort((a, b) => a - b);
  const q = (p) => (v.length ? v[Math.min(v.length - 1, Math.floor(p * v.length))] : NaN);
  return { n: v.length, p50: q(0.5), p90: q(0.9), p99: q(0.99), max: v[v.length - 1] };
}

const cell = new Cell({ robots: ['ibm7545', 'scara_picker'] });
let browser;
let exitCode = 0;
try {
  log('starting the cell');
  await cell.start();
  // 50 parts: the table scene's 15 plus a grid of ICs on the free part of the table.
  const classes = ['ic_7x30', 'ic_6x19', 'dip14', 'dip8'];
  const count = () => JSON.parse(cell.cellctl('--json', 'world', 'parts').stdout).parts.length;
  let have = count();
  for (let i = 0; have < partsWanted && i < 200; ++i) {
    const x = -520 + 60 * (i % 12), y = -100 + 70 * Math.floor(i / 12);
    if (x > 40 && y > 380) continue;  // keep clear of the thesis's ICs
    const r = cell.cellctl('world', 'spawn', '--class', classes[i % 4], '--pose', `${x},${y},${(i * 37) % 180}`);
    if (r.code !== 0) log(`spawn: ${r.stderr.trim()}`);
    have = count();
  }
  log(`${have} parts in the world`);
  browser = await openBrowser(cell.url);
  const page = browser.page;
  await until(() => page.evaluate((n) => window.cellMonitor.parts() >= n &&
    window.cellMonitor.latest('ibm7545') && window.cellMonitor.latest('scara_picker'), have), 30000, 'parts and robots on the page');
  // Both robots move all the time.
  let moving = true;
  const mover = async (robot, a, b) => {
    for (let k = 0; moving; ++k) {
      const { spawn } = await import('node:child_process');
      await new Promise((resolve) => {
        const c = spawn(`${cell.bin}/cellctl`, ['--timeout', '5', 'move', 'joints', '--robot', robot,
          '--joints', k % 2 ? a : b, '--speed', '0.8'], { env: cell.env, stdio: 'ignore' });
        c.on('exit', resolve);
      });
    }
  };
  const movers = [mover('ibm7545', '30,60,50,-60', '150,110,150,90'), mover('scara_picker', '-40,60,20,0', '40,100,150,90')];
  // The peer for the delay: a native DDS reader of the same stream (tests/monitor's probe).
  const probe = await cell.probe('ibm7545', 'scara_picker');
  await sleep(2000);
  const t0 = await page.evaluate(() => performance.timeOrigin + performance.now());
  const frames0 = await page.evaluate(() => window.cellMonitor.stats().frames);
  const bridge = bridgePid();
  const cpu0 = cpuSeconds(bridge);
  const wall0 = Date.now();
  await sleep(seconds * 1000);
  const bridgeCpu = bridge ? 100 * (cpuSeconds(bridge) - cpu0) / ((Date.now() - wall0) / 1000) : null;
  const result = await page.evaluate(([since]) => {
    const m = window.cellMonitor;
    const frames = m.frameTimes().filter((t) => t >= since);
    const rendered = [];
    for (const id of ['ibm7545', 'scara_picker']) {
      const seen = new Set();
      for (const f of m.rendered(id, since)) {
        if (seen.has(f.seq)) continue;  // the first frame that drew each sample
        seen.add(f.seq);
        rendered.push(f.t_ms - f.stamp_ns / 1e6);
      }
    }
    return { frames, delays: m.delays(since), rendered, parts: m.parts() };
  }, [t0]);
  const native = (await probe.stop()).filter((x) => x.received_ns / 1e6 >= t0)
    .map((x) => (x.received_ns - x.stamp_ns) / 1e6);
  moving = false;
  await Promise.all(movers);
  const frames = result.frames;
  const fps = (frames.length - 1) / ((frames[frames.length - 1] - frames[0]) / 1000);
  const intervals = frames.slice(1).map((t, i) => t - frames[i]);
  const out = {
    window: '1600x1000',
    robots: 2,
    parts: result.parts,
    seconds,
    fps,
    frame_interval_ms: quantiles(intervals),
    state_to_page_ms: quantiles(result.delays),
    state_to_frame_ms: quantiles(result.rendered),
    state_to_native_reader_ms: quantiles(native),
    bridge_cpu_percent: bridgeCpu,  // of one core, user + system, over the window
    targets: { fps: 60, state_to_page_ms: 50 },
  };
  if (asJson) {
    console.log(JSON.stringify(out, null, 2));
  } else {
    const f = (q) => `p50 ${q.p50.toFixed(1)}  p90 ${q.p90.toFixed(1)}  p99 ${q.p99.toFixed(1)}  max ${q.max.toFixed(1)}  (n ${q.n})`;
    console.log(`monitor_bench: ${out.robots} robots, ${out.parts} parts, ${out.window}, ${seconds} s, headless Chromium (software WebGL)`);
    console.log(`  frames per second             ${fps.toFixed(1)}   (target 60; ${frames.length - 1} frames after ${frames0} warm-up)`);
    console.log(`  frame interval [ms]           ${f(out.frame_interval_ms)}`);
    console.log(`  RobotState -> page [ms]       ${f(out.state_to_page_ms)}   (target < 50)`);
    console.log(`  RobotState -> drawn [ms]      ${f(out.state_to_frame_ms)}`);
    console.log(`  peer: RobotState -> native DDS reader [ms]  ${f(out.state_to_native_reader_ms)}`);
    console.log(`  bridge CPU [% of one core]    ${bridgeCpu === null ? '?' : bridgeCpu.toFixed(1)}   (cell-monitor, user + system)`);
  }
  if (browser.errors.length) {
    log('page errors:', browser.errors);
    exitCode = 1;
  }
} catch (e) {
  log('error:', e.message);
  console.error(cell.logs());
  exitCode = 1;
} finally {
  if (browser) await browser.close();
  await cell.stop();
}
process.exit(exitCode);
