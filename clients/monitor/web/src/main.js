// The monitor's page: loads the cell's description (/api/config), opens the live stream
// (/api/stream) and keeps the 3-D view, the camera view, the panels and the plots current.
// `window.cellMonitor` exposes what the browser test and the benchmark read (frame rate,
// RobotState delays, the joint values the rendered robots have).
import * as api from './api.js';
import { CameraView } from './camera_view.js';
import { $, AlarmLog, JobsPanel, RobotPanel, SessionPanel, renderHealth } from './panels.js';
import { Plot } from './plots.js';
import { CellScene } from './scene.js';
import { Stream } from './stream.js';
import { TeachPanel } from './teach.js';

const kRing = 4000;

function nowMs() {
  return performance.timeOrigin + performance.now();
}

function push(ring, value, max = kRing) {
  ring.push(value);
  if (ring.length > max) ring.splice(0, ring.length - max);
}

class App {
  constructor(config, session) {
    this.config = config;
    this.session = session;
    this.latest = new Map();         // robot id -> newest sample
    this.delays = [];                // RobotState stamp -> page, and its parts (onRobots)
    this.frameTimes = [];            // wall ms of each rendered frame
    this.rendered = new Map();       // robot id -> [{t_ms, seq, stamp_ns, q}]
    this.supports = new Map();       // part id -> support (pick counting)
    this.picks = [];                 // [t_s, robot]
    this.planeZ = new Map();         // camera -> working plane z (base frame) from calibrations
    this.scene = new CellScene($('view'), config);
    this.cameraView = new CameraView($('camera-image'), $('camera-select'), $('camera-info'), config);
    this.sessionPanel = new SessionPanel(this);
    this.robotPanel = new RobotPanel(this);
    this.jobs = new JobsPanel(this);
    this.teach = new TeachPanel(this);
    this.alarms = new AlarmLog();
    $('alarms-only').addEventListener('change', () => this.alarms.render());
    $('gripper-robot').textContent = this.scene.gripperRobot || '';
    this.plots = {
      tracking: new Plot($('plot-tracking'), 'tracking error, revolute joints', 'deg'),
      jitter: new Plot($('plot-jitter'), 'servo loop jitter (worst per state)', 'µs'),
      picks: new Plot($('plot-picks'), 'pick rate', 'parts/min'),
    };
    this.setSession(session);
    this.stream = new Stream('/api/stream', {
      robots: (d, t) => this.onRobots(d, t),
      world: (d) => this.onWorld(d),
      health: (d) => renderHealth(d),
      event: (d) => this.alarms.add(d),
      events: (d) => this.alarms.replace(d),
      job: (d) => this.jobs.set(d),
      motion: (d) => this.onMotion(d),
      detections: (d) => this.onDetections(d),
      image: (d) => this.cameraView.setImage(d),
      edge: (d) => this.cameraView.addEdge(d),
      calibration: (d) => this.onCalibration(d),
      teach: (d) => this.teach.set(d),
    }, (connected) => {
      $('link').textContent = connected ? 'live' : 'reconnecting…';
      $('link').className = connected ? 'ok' : 'error';
    });
    requestAnimationFrame((t) => this.frame(t));
    setInterval(() => this.slow(), 500);
  }

  setSession(session) {
    this.session = session;
    this.sessionPanel.show(session);
    this.applyRole();
  }

  /// Commands are offered to a signed-in operator only (the bridge refuses them from anyone
  /// else anyway: 401/403).
  applyRole() {
    const operator = this.session.signed_in && this.session.role === 'operator';
    document.body.classList.toggle('operator', operator);
    for (const b of document.querySelectorAll('button.cmd, .cmd-input')) b.disabled = !operator;
  }

  onRobots(d, receivedMs) {
    for (const s of d.robots) {
      this.latest.set(s.id, s);
      // [received, total, gateway->bridge, in the bridge, bridge->page] [ms]
      push(this.delays, [receivedMs, receivedMs - s.stamp_ns / 1e6, (s.received_ns - s.stamp_ns) / 1e6,
        (d.sent_ns - s.received_ns) / 1e6, receivedMs - d.sent_ns / 1e6, s.id, s.seq]);
      this.scene.setRobot(s.id, s.q, s.gripper, { seq: s.seq, stamp_ns: s.stamp_ns });
      const t = s.stamp_ns / 1e9;
      const model = this.config.robots.find((r) => r.id === s.id);
      if (model && s.setpoint && s.setpoint.length === s.q.length) {
        let worst = 0;
        model.joints.forEach((j, i) => {
          if (j.type === 'revolute' && s.q[i] !== null && s.setpoint[i] !== null) {
            worst = Math.max(worst, Math.abs(s.setpoint[i] - s.q[i]) * 180 / Math.PI);
          }
        });
        this.plots.tracking.add(s.id, t, worst);
      }
      this.plots.jitter.add(s.id, t, s.jitter_max_us);
    }
  }

  onWorld(world) {
    this.scene.setWorld(world);
    const t = world.stamp_ns / 1e9;
    for (const p of world.parts) {
      const before = this.supports.get(p.id);
      if (before !== undefined && !before.startsWith('robot/') && p.support.startsWith('robot/')) {
        this.picks.push([t, p.support.slice(6)]);
      }
      this.supports.set(p.id, p.support);
    }
    this.worldParts = world.parts;
    const list = $('goto-parts');
    if (list.childElementCount !== world.parts.length) {
      list.replaceChildren(...world.parts.map((p) => {
        const o = document.createElement('option');
        o.value = p.id;
        o.textContent = `${p.class} (${p.support})`;
        return o;
      }));
    }
  }

  onDetections(d) {
    this.cameraView.setDetections(d);
    const cam = (this.config.cameras || []).find((c) => c.id === d.camera);
    let z = this.planeZ.get(d.camera);
    if (z === undefined && d.robot) {
      const robot = this.config.robots.find((r) => r.id === d.robot);
      const table = this.scene.tableHeight;
      if (robot && table) z = table - robot.world_T_base.p[2];
    }
    this.scene.setDetections(d, cam ? z : null);
  }

  onCalibration(c) {
    if (c.type === 'camera' && c.data.working_plane_z_mm !== null) {
      this.planeZ.set(c.data.camera, c.data.working_plane_z_mm);
    }
    const line = document.createElement('div');
    const d = c.data;
    line.textContent = c.type === 'camera'
      ? `${d.camera}: ${d.version}, ${d.rms_px !== null ? d.rms_px.toFixed(3) : '?'} px rms (${d.sample_count} samples)`
      : `${d.belt}: ${d.version}, ${d.mm_per_count !== null ? d.mm_per_count.toFixed(5) : '?'} mm/count`;
    line.dataset.key = `${c.type}/${d.camera || d.belt}`;
    const box = $('calibrations');
    const old = [...box.children].find((e) => e.dataset.key === line.dataset.key);
    if (old) old.replaceWith(line);
    else box.append(line);
  }

  onMotion(m) {
    const line = $('motion');
    line.textContent = `${m.robot} ${m.motion_id}: ${m.state} ${(100 * (m.progress || 0)).toFixed(0)} %${m.reason ? ` — ${m.reason}` : ''}`;
    line.className = m.state === 'refused' || m.state === 'failed' ? 'error' : '';
  }

  frame(t) {
    this.scene.render(t);
    const now = nowMs();
    push(this.frameTimes, now);
    for (const [id, view] of this.scene.robots) {
      if (!view.sample) continue;
      let log = this.rendered.get(id);
      if (!log) {
        log = [];
        this.rendered.set(id, log);
      }
      push(log, { t_ms: now, seq: view.sample.seq, stamp_ns: view.sample.stamp_ns, q: view.renderedJoints() });
    }
    requestAnimationFrame((t2) => this.frame(t2));
  }

  /// What does not need every frame: status text, plots, the frame-rate line.
  slow() {
    const nowS = nowMs() / 1e3;
    this.robotPanel.update();
    for (const [, robot] of this.config.robots.map((r) => [r.id, r])) {
      const n = this.picks.filter(([t, id]) => id === robot.id && t > nowS - 60).length;
      if (this.picks.length || n) this.plots.picks.add(robot.id, nowS, n);
    }
    for (const p of Object.values(this.plots)) p.draw(nowS);
    const s = this.stats();
    $('stats').textContent = `${s.fps.toFixed(0)} fps · RobotState → page ${s.delay_p50_ms === null ? '–' : s.delay_p50_ms.toFixed(1)} ms (p50)`;
  }

  stats() {
    const now = nowMs();
    const recent = this.frameTimes.filter((t) => t > now - 2000);
    const fps = recent.length > 1 ? (recent.length - 1) / ((recent[recent.length - 1] - recent[0]) / 1000) : 0;
    const sorted = this.delays.slice(-500).map(([, d]) => d).sort((a, b) => a - b);
    const q = (p) => (sorted.length ? sorted[Math.min(sorted.length - 1, Math.floor(p * sorted.length))] : null);
    return { fps, frames: this.scene.frames, delay_p50_ms: q(0.5), delay_p99_ms: q(0.99), messages: this.stream.messages };
  }
}

const errors = [];
window.addEventListener('error', (e) => errors.push(String(e.message)));
window.addEventListener('unhandledrejection', (e) => errors.push(String(e.reason)));

async function start() {
  const [config, session] = await Promise.all([api.getJson('/api/config'), api.getJson('/api/session')]);
  const app = new App(config, session);
  window.cellMonitor = {
    app,
    errors,
    stats: () => app.stats(),
    /// RobotState-to-page delays [ms] of the samples received since `sinceMs` (wall clock).
    delays: (sinceMs = 0) => app.delays.filter(([t]) => t >= sinceMs).map(([, d]) => d),
    /// The same split into gateway -> bridge, in the bridge, bridge -> page [ms].
    delayParts: (sinceMs = 0) => app.delays.filter(([t]) => t >= sinceMs).map(([, , a, b, c]) => [a, b, c]),
    /// Where the time of one sample went: {gateway_to_bridge, in_bridge, bridge_to_page} [ms].
    delayOf: (id, seq) => {
      const r = app.delays.find((x) => x[5] === id && x[6] === seq);
      return r ? { gateway_to_bridge: r[2], in_bridge: r[3], bridge_to_page: r[4], received_ms: r[0] } : null;
    },
    frameTimes: () => app.frameTimes.slice(),
    /// Frames rendered since `sinceMs` (wall clock) for robot `id`: {t_ms, seq, stamp_ns, q}.
    rendered: (id, sinceMs = 0) => (app.rendered.get(id) || []).filter((f) => f.t_ms >= sinceMs),
    latest: (id) => app.latest.get(id) || null,
    parts: () => app.scene.parts.size,
  };
  document.body.dataset.ready = 'true';
}

start().catch((e) => {
  errors.push(String(e));
  const line = $('message');
  line.className = 'error';
  line.textContent = `cannot start the monitor: ${e.message}`;
});
