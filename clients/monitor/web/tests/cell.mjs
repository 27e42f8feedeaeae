// A simulated cell for the browser test and the page benchmark: `cell up` (the launcher) with
// a generated profile on a private DDS domain and partition, the loopback-only Cyclone
// configuration and a temporary run directory; plus Chromium (Debian's /usr/bin/chromium)
// driven by playwright-core with a fresh profile. Every wait has a deadline.
//
// Environment: CELL_BIN_DIR (the build's bin/), CELL_SOURCE_DIR (the checkout).
import { execFileSync, spawn, spawnSync } from 'node:child_process';
import { existsSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { createRequire } from 'node:module';
import { createServer } from 'node:net';
import { tmpdir } from 'node:os';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const require = createRequire(join(here, '..', 'package.json'));
export const { chromium } = require('playwright-core');

/// The flags Chromium needs on this closed network (without the background-networking ones
/// its connections are refused), headless, software WebGL.
export const kChromiumArgs = ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic',
  '--no-first-run', '--disable-background-networking', '--disable-component-update',
  '--disable-sync'];

export const kOperator = { user: 'operator', password: 'browser-test-pw' };

export function sleep(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

/// Polls `fn` (sync or async) every `every` ms until it returns a truthy value or `ms` pass.
export async function until(fn, ms, what, every = 100) {
  const deadline = Date.now() + ms;
  let last;
  for (;;) {
    try {
      last = await fn();
      if (last) return last;
    } catch (e) {
      last = e;
    }
    if (Date.now() > deadline) throw new Error(`timed out after ${ms} ms waiting for ${what} (last: ${last})`);
    await sleep(every);
  }
}

async function freePort() {
  return new Promise((resolve, reject) => {
    const s = createServer();
    s.listen(0, '127.0.0.1', () => {
      const { port } = s.address();
      s.close(() => resolve(port));
    });
    s.on('error', reject);
  });
}

export class Cell {
  /// options: {robots: ['ibm7545', 'scara_picker'], camera: true, extraServices: [...],
  ///   jobMaxParts: N (the page's table_ics template takes at most N parts; default: the
  ///   shipped job's max_parts)}
  constructor(options = {}) {
    this.bin = process.env.CELL_BIN_DIR;
    this.src = process.env.CELL_SOURCE_DIR;
    if (!this.bin || !this.src) throw new Error('set CELL_BIN_DIR and CELL_SOURCE_DIR (ctest does)');
    this.options = { robots: ['ibm7545', 'scara_picker'], camera: true, ...options };
    this.dir = mkdtempSync(join(tmpdir(), 'cell-monitor-browser-'));
    this.domain = process.env.CELL_TEST_DOMAIN ? Number(process.env.CELL_TEST_DOMAIN) : 100 + (process.pid % 100);
    this.partition = `browser-${process.pid}-${Date.now() % 100000}`;
    this.env = {
      ...process.env,
      CELL_HOME: this.src,
      CELL_DOMAIN_ID: String(this.domain),
      CELL_PARTITION: this.partition,
      CYCLONEDDS_URI: `file://${this.src}/config/dds/loopback.xml`,
    };
    this.children = [];
  }

  has(exec) {
    return existsSync(join(this.bin, exec));
  }

  write(name, text) {
    const path = join(this.dir, name);
    writeFileSync(path, text);
    return path;
  }

  /// Runs a built tool to completion; returns {code, stdout, stderr}.
  tool(exec, args, timeoutMs = 60000, input = undefined) {
    const r = spawnSync(join(this.bin, exec), args, { env: this.env, encoding: 'utf8', timeout: timeoutMs, input });
    return { code: r.status, stdout: r.stdout || '', stderr: r.stderr || '', error: r.error };
  }

  cellctl(...args) {
    return this.tool('cellctl', ['--timeout', '5', ...args], 120000);
  }

  async start() {
    this.port = await freePort();
    const hash = this.tool('cell-monitor', ['--hash-password', '--iterations', '1000'], 30000,
      `${kOperator.password}\n`);
    if (hash.code !== 0) throw new Error(`cell-monitor --hash-password: ${hash.stderr}`);
    const robots = {
      ibm7545: '{id: ibm7545, config: config/robots/ibm7545.yaml, xyz_mm: [0, 0, 981.51]}',
      scara_picker: '{id: scara_picker, config: config/robots/scara_picker.yaml, xyz_mm: [1000, 0, 960]}',
    };
    let jobFile = join(this.src, 'config/jobs/table_ics.yaml');
    if (existsSync(jobFile) && this.options.jobMaxParts) {
      const spec = readFileSync(jobFile, 'utf8');
      if (!/^max_parts: \d+/m.test(spec)) throw new Error(`${jobFile} has no max_parts line`);
      jobFile = this.write('table_ics.yaml',
        spec.replace(/^max_parts: \d+/m, `max_parts: ${this.options.jobMaxParts}`));
    }
    this.write('monitor.yaml', [
      'service: {id: monitor, heartbeat_period_s: 0.5}',
      `http: {bind: 127.0.0.1, port: ${this.port}}`,
      'auth:',
      '  users:',
      `    - {name: ${kOperator.user}, role: operator, password_hash: "${hash.stdout.trim()}"}`,
      'robots:',
      ...this.options.robots.map((r) => `  - ${robots[r]}`),
      'cameras: [config/cameras/ibm7545_eye.yaml, config/cameras/belt_cam.yaml]',
      ...(existsSync(jobFile) ? ['job_templates:', `  - {name: table_ics, spec_file: ${jobFile}}`] : []),
      `teach: {tasks_dir: ${this.dir}/tasks}`,
      '',
    ].join('\n'));
    this.write('gateway-ibm7545.yaml', [
      'service: {id: gateway.ibm7545}',
      'robot_config: config/robots/ibm7545.yaml',
      'cycle_hz: 1000',
      'state_rate_hz: 100',
      'driver: {kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.3}',
      '',
    ].join('\n'));
    this.write('camera-ibm7545.yaml', [
      'service: {id: camera.ibm7545_eye}',
      'camera_id: ibm7545_eye',
      'source: sim',
      'camera_file: config/cameras/ibm7545_eye.yaml',
      'sim: {noise_sigma: 2.0, seed: 1994, gain: 1.0}',
      'trigger: {mode: free, rate_hz: 2}',
      '',
    ].join('\n'));
    const services = [
      '  - {name: sim-world, exec: cell-sim-world, config: config/sim-world.yaml}',
      `  - {name: gateway.ibm7545, exec: cell-gateway, config: ${this.dir}/gateway-ibm7545.yaml}`,
      '  - {name: gateway.picker, exec: cell-gateway, config: config/gateway-picker.yaml}',
      '  - {name: motion, exec: cell-motion, config: config/motion.yaml}',
      `  - {name: monitor, exec: cell-monitor, config: ${this.dir}/monitor.yaml}`,
    ];
    if (this.options.camera && this.has('cell-camera')) {
      services.push(`  - {name: camera.ibm7545_eye, exec: cell-camera, config: ${this.dir}/camera-ibm7545.yaml}`);
    }
    // The services other issues are landing: part of the cell as soon as they are built.
    if (this.has('cell-vision') && existsSync(join(this.src, 'config/vision.yaml'))) {
      services.push('  - {name: vision, exec: cell-vision, config: config/vision.yaml}');
    }
    if (this.has('cell-task') && existsSync(join(this.src, 'config/task.yaml'))) {
      // The shipped config with a journal of this run's own: a job another run left "running"
      // in the checkout's journal would otherwise resume here and hold the robot.
      const task = readFileSync(join(this.src, 'config/task.yaml'), 'utf8')
        .replace(/^journal:.*$/m, `journal: ${this.dir}/task/journal.sqlite`);
      services.push(`  - {name: task, exec: cell-task, config: ${this.write('task.yaml', task)}}`);
    }
    for (const s of this.options.extraServices || []) services.push(s);
    this.profile = this.write('profile.yaml', [
      'profile: monitor-browser-test',
      `bus: {domain_id: 0, partition: overridden, cyclonedds_config: config/dds/loopback.xml}`,
      `run_dir: ${this.dir}/run`,
      'restart: {backoff_initial_s: 0.5, backoff_max_s: 2, stable_after_s: 10}',
      'stop_grace_s: 5',
      'services:',
      ...services,
      '',
    ].join('\n'));
    this.output = '';
    this.launcher = spawn(join(this.bin, 'cell'), ['up', '--profile', this.profile], { env: this.env, detached: true });
    this.launcher.stdout.on('data', (d) => { this.output += d; });
    this.launcher.stderr.on('data', (d) => { this.output += d; });
    this.url = `http://127.0.0.1:${this.port}/`;
    await until(async () => (await fetch(`${this.url}api/status`)).ok, 60000, 'the monitor to serve');
    // Every service up and serving (heartbeats), so that none meets a job before it has
    // found the others on the bus.
    this.serviceCount = services.length;
    await until(() => {
      const ping = this.cellctl('--json', 'ping');
      if (ping.code !== 0) return false;
      const all = JSON.parse(ping.stdout.slice(ping.stdout.indexOf('{'))).services;
      return all.filter((x) => x.state === 'serving').length >= this.serviceCount;
    }, 90000, `all ${services.length} services serving`, 500);
    // The robots up and homed (the ideal robot starts unhomed, like the real ones).
    for (const robot of this.options.robots) {
      await until(() => this.cellctl('robot', 'home', '--robot', robot).code === 0, 60000, `${robot} homed`, 500);
    }
    // The 7545's lights: its gateway starts them off (the latch is write-only), and in the dark
    // the eye-in-hand camera sees black blobs vision cannot classify. An operator switches them
    // on before a job; so does this cell.
    if (this.options.robots.includes('ibm7545')) {
      const lit = this.cellctl('robot', 'lights', '--robot', 'ibm7545', '--halogen', '--fluorescent');
      if (lit.code !== 0) throw new Error(`cellctl robot lights: ${lit.stdout}${lit.stderr}`);
    }
  }

  /// Starts monitor_probe (it records every RobotState of `robots`); `await probe.stop()`
  /// ends it and returns the samples (parsed objects).
  async probe(...robots) {
    const child = spawn(join(this.bin, 'monitor_probe'), robots, { env: this.env, stdio: ['pipe', 'pipe', 'inherit'] });
    this.children.push(child);
    const probe = { child, samples: [], ready: false, first: false };
    let buffer = '';
    child.stdout.on('data', (d) => {
      buffer += d;
      let nl;
      while ((nl = buffer.indexOf('\n')) >= 0) {
        const line = buffer.slice(0, nl);
        buffer = buffer.slice(nl + 1);
        const j = JSON.parse(line);
        if (j.ready) probe.ready = true;
        else if (j.first) probe.first = true;
        else probe.samples.push(j);
      }
    });
    const exited = new Promise((resolve) => child.on('exit', resolve));
    await until(() => probe.ready && probe.first, 20000, 'monitor_probe to see RobotState');
    probe.stop = async () => {
      child.stdin.end();
      await exited;
      return probe.samples;
    };
    return probe;
  }

  async stop() {
    for (const c of this.children) c.kill('SIGTERM');
    if (this.launcher && this.launcher.exitCode === null) {
      const down = this.tool('cell', ['down', '--profile', this.profile, '--timeout', '20'], 40000);
      if (down.code !== 0) this.launcher.kill('SIGTERM');
      await until(() => this.launcher.exitCode !== null || this.launcher.signalCode !== null, 30000, 'cell up to end')
        .catch(() => process.kill(-this.launcher.pid, 'SIGKILL'));
    }
    if (!process.env.CELL_KEEP_TEST_DIR) rmSync(this.dir, { recursive: true, force: true });
  }

  /// The last lines of every service's log (for failure messages).
  logs() {
    try {
      return execFileSync('sh', ['-c', `tail -n 15 ${this.dir}/run/logs/*.log`], { encoding: 'utf8' });
    } catch {
      return this.output.slice(-4000);
    }
  }
}

/// Chromium with a fresh profile (playwright's persistent context is how a user-data-dir is
/// given); returns {context, page, errors}: console errors and page errors collect in errors.
export async function openBrowser(url, viewport = { width: 1600, height: 1000 }) {
  const profile = mkdtempSync(join(tmpdir(), 'cell-monitor-chromium-'));
  const context = await chromium.launchPersistentContext(profile, {
    executablePath: '/usr/bin/chromium',
    headless: true,
    args: kChromiumArgs,
    viewport,
  });
  const page = context.pages()[0] || await context.newPage();
  const errors = [];
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => errors.push(`page: ${e.message}`));
  await page.goto(url);
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  const close = async () => {
    await context.close();
    rmSync(profile, { recursive: true, force: true });
  };
  return { context, page, errors, close };
}
