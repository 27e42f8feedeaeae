// The page's panels besides the 3-D view: sign-in, robot status and commands (jog in joints or
// Cartesian with a preview first, go to the grasp position of part N, home, gripper, stop),
// jobs, services' health and the alarm log. Text from the bus is always set as textContent.
import * as api from './api.js';
import * as K from './kinematics.js';

export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

export function $(id) {
  return document.getElementById(id);
}

const deg = (rad) => rad * 180 / Math.PI;

/// "12.3 s", "4 min 2 s", "3 h 1 min".
export function duration(s) {
  if (s === null || s === undefined) return '';
  if (s < 60) return `${s.toFixed(1)} s`;
  if (s < 3600) return `${Math.floor(s / 60)} min ${Math.floor(s % 60)} s`;
  return `${Math.floor(s / 3600)} h ${Math.floor((s % 3600) / 60)} min`;
}

/// Shows the result of a command in the message line: green when it went, red with the
/// bridge's sentence when not.
export function report(result, what) {
  const line = $('message');
  line.className = result.ok ? 'ok' : 'error';
  line.textContent = result.ok ? `${what}: ${result.body.what || 'done'}` :
    `${what}: ${result.body.error || `HTTP ${result.status}`}`;
  return result;
}

// ---- sign-in --------------------------------------------------------------------------------

export class SessionPanel {
  constructor(app) {
    this.app = app;
    $('login-form').addEventListener('submit', (e) => {
      e.preventDefault();
      this.signIn();
    });
    $('logout').addEventListener('click', () => this.signOut());
  }

  async signIn() {
    const r = await api.post('/api/login', { user: $('login-user').value, password: $('login-password').value });
    $('login-password').value = '';
    if (!r.ok) {
      report(r, 'sign in');
      return;
    }
    this.app.setSession({ signed_in: true, user: r.body.user, role: r.body.role });
    report({ ok: true, body: { what: `signed in as ${r.body.user} (${r.body.role})` } }, 'session');
  }

  async signOut() {
    await api.post('/api/logout', {});
    this.app.setSession({ signed_in: false });
  }

  show(session) {
    $('login-form').hidden = session.signed_in;
    $('who').hidden = !session.signed_in;
    $('who-name').textContent = session.signed_in ? `${session.user} (${session.role})` : '';
  }
}

// ---- robot ------------------------------------------------------------------------------------

export class RobotPanel {
  constructor(app) {
    this.app = app;
    this.pending = null;  // the previewed command, sent by "Send"
    const select = $('robot-select');
    for (const r of app.config.robots) select.append(el('option', { value: r.id, text: r.id }));
    select.addEventListener('change', () => {
      this.discard();
      this.buildJog();
      app.scene.gripperRobot = this.robotId;
      app.scene.gripperChanged = true;
      $('gripper-robot').textContent = this.robotId;
      this.update();
    });
    app.scene.gripperRobot = this.robotId;
    $('jog-space').addEventListener('change', () => this.buildJog());
    for (const [id, command] of [['cmd-home', 'home'], ['cmd-open', 'open'], ['cmd-close', 'close'],
      ['cmd-stop', 'stop'], ['cmd-reset', 'reset']]) {
      $(id).addEventListener('click', () => this.robotCommand(command));
    }
    $('preview-send').addEventListener('click', () => this.send());
    $('preview-discard').addEventListener('click', () => this.discard());
    $('goto-preview').addEventListener('click', () => this.gotoPart());
    $('joints-preview').addEventListener('click', () => this.moveJoints());
    this.buildJog();
  }

  get robotId() {
    return $('robot-select').value;
  }

  get model() {
    return this.app.config.robots.find((r) => r.id === this.robotId);
  }

  buildJog() {
    const box = $('jog-buttons');
    box.replaceChildren();
    const model = this.model;
    if (!model) return;
    const space = $('jog-space').value;
    const axes = space === 'joint'
      ? model.joints.map((j) => ({ key: j.name, label: j.name, unit: j.unit }))
      : ['x', 'y', 'z', 'rx', 'ry', 'rz'].map((a) => ({ key: a, label: a, unit: a.startsWith('r') ? 'deg' : 'mm' }));
    for (const a of axes) {
      const minus = el('button', { class: 'cmd', text: '−', title: `${a.label} minus one step`,
        onclick: () => this.jog(space, a.key, -1) });
      const plus = el('button', { class: 'cmd', text: '+', title: `${a.label} plus one step`,
        onclick: () => this.jog(space, a.key, +1) });
      box.append(el('div', { class: 'jog-row' }, el('span', { class: 'jog-axis', text: `${a.label} [${a.unit}]` }), minus, plus));
    }
    const inputs = $('joints-input');
    inputs.replaceChildren();
    for (const j of model.joints) {
      inputs.append(el('input', { type: 'number', step: 'any', 'data-joint': j.name, title: `${j.name} [${j.unit}]`,
        placeholder: `${j.name} ${j.unit}` }));
    }
  }

  async jog(space, axis, sign) {
    const step = Number($('jog-step').value) || 1;
    const body = { robot: this.robotId, speed: Number($('jog-speed').value) || 0.5 };
    body.jog = space === 'joint' ? { space, joint: axis, delta: sign * step } : { space, axis, delta: sign * step };
    await this.preview('/api/motion', body, `jog ${space} ${axis} ${sign > 0 ? '+' : '−'}${step}`);
  }

  async moveJoints() {
    const values = [...$('joints-input').querySelectorAll('input')].map((i) => i.value === '' ? NaN : Number(i.value));
    if (values.some((v) => !Number.isFinite(v))) {
      report({ ok: false, status: 0, body: { error: 'give every joint a value (deg or mm)' } }, 'move');
      return;
    }
    await this.preview('/api/motion', { robot: this.robotId, joints: values,
      speed: Number($('jog-speed').value) || 0.5 }, 'move to joints');
  }

  async gotoPart() {
    const what = $('goto-what').value.trim();
    const body = { robot: this.robotId, speed: Number($('jog-speed').value) || 0.5 };
    if (/^\d+$/.test(what)) {
      body.camera = this.app.cameraView.camera;
      body.index = Number(what);
    } else {
      body.part = what;
    }
    await this.preview('/api/goto_part', body, `go to part ${what}`);
  }

  /// The thesis's off-line mode: plan, animate the plan as a ghost arm, send only on "Send".
  async preview(path, body, what) {
    const r = report(await api.post(path, { ...body, preview: true }), `preview ${what}`);
    if (!r.ok) return r;
    this.pending = { path, body, what };
    this.app.scene.showPreview(body.robot, r.body.samples, r.body.path);
    if (r.body.path && r.body.path.length) {
      const robot = this.app.scene.robots.get(body.robot);
      this.app.scene.showTarget(K.multiply(robot.world_T_base, K.fromPose(r.body.path[r.body.path.length - 1])));
    }
    $('preview-bar').hidden = false;
    $('preview-text').textContent = `${what}: ${r.body.duration_s.toFixed(2)} s planned`;
    return r;
  }

  async send() {
    if (!this.pending) return;
    const { path, body, what } = this.pending;
    this.discard();
    report(await api.post(path, { ...body, preview: false }), what);
  }

  discard() {
    this.pending = null;
    this.app.scene.clearPreview();
    this.app.scene.showTarget(null);
    $('preview-bar').hidden = true;
  }

  async robotCommand(command) {
    report(await api.post('/api/robot/command', { robot: this.robotId, command }), `${command} ${this.robotId}`);
  }

  update() {
    const s = this.app.latest.get(this.robotId);
    const model = this.model;
    const box = $('robot-status');
    if (!s || !model) {
      box.textContent = 'no state from this robot yet';
      return;
    }
    const joints = model.joints.map((j, i) => `${j.name} ${s.q[i] === null ? '?' :
      (j.unit === 'deg' ? deg(s.q[i]).toFixed(2) : s.q[i].toFixed(2))} ${j.unit}`).join('  ');
    let pose = '';
    if (s.base_T_tool) {
      const m = K.fromPose(s.base_T_tool);
      const [r, p, y] = K.rpy(m);
      pose = `tool ${m[3].toFixed(1)}, ${m[7].toFixed(1)}, ${m[11].toFixed(1)} mm · rpy ${deg(r).toFixed(1)}, ${deg(p).toFixed(1)}, ${deg(y).toFixed(1)} deg`;
    }
    box.replaceChildren(
      el('div', { text: `${s.mode}${s.homed ? '' : ' (not homed)'} · gripper ${s.gripper}${s.moving ? ` · moving ${(100 * s.progress).toFixed(0)} %` : ''}${s.tracking ? ' · tracking' : ''}` }),
      el('div', { class: 'mono', text: joints }),
      el('div', { class: 'mono', text: pose }),
      ...(s.fault ? [el('div', { class: 'error', text: `fault: ${s.fault}` })] : []));
  }
}

// ---- jobs -------------------------------------------------------------------------------------

export class JobsPanel {
  constructor(app) {
    this.app = app;
    this.jobs = new Map();
    const select = $('job-template');
    for (const t of app.config.job_templates) {
      select.append(el('option', { value: t.name, text: t.name, title: t.description }));
    }
    $('job-submit').addEventListener('click', () => this.submit());
  }

  async submit() {
    const body = { template: $('job-template').value };
    const id = $('job-id').value.trim();
    if (id) body.job_id = id;
    const r = await api.post('/api/job/submit', body);
    report({ ...r, body: { ...r.body, what: r.body.job_id ? `job ${r.body.job_id} ${r.body.status ? r.body.status.state : r.body.state}` : undefined } }, 'submit');
  }

  async command(jobId, command) {
    report(await api.post('/api/job/command', { job_id: jobId, command }), `${command} ${jobId}`);
  }

  set(job) {
    this.jobs.set(job.job_id, job);
    this.render();
  }

  render() {
    const list = $('jobs');
    list.replaceChildren();
    const jobs = [...this.jobs.values()].sort((a, b) => (b.accepted_stamp_ns || b.stamp_ns) - (a.accepted_stamp_ns || a.stamp_ns));
    if (!jobs.length) list.append(el('div', { class: 'muted', text: 'no jobs yet' }));
    for (const j of jobs.slice(0, 20)) {
      const active = ['queued', 'running', 'paused'].includes(j.state);
      const bar = el('div', { class: 'bar' }, el('div', { class: 'fill' }));
      bar.firstChild.style.width = `${Math.round(100 * (j.progress || 0))}%`;
      const buttons = el('span', { class: 'job-buttons' });
      if (active) {
        for (const c of j.state === 'paused' ? ['resume', 'cancel'] : ['pause', 'cancel']) {
          buttons.append(el('button', { class: 'cmd small', text: c, onclick: () => this.command(j.job_id, c) }));
        }
      }
      const head = el('div', { class: 'job-head' },
        el('span', { class: `state ${j.state}`, text: j.state }),
        el('span', { class: 'job-id', text: `${j.job_id}${j.name ? ` — ${j.name}` : ''}` }),
        el('span', { class: 'muted', text: `${j.parts_done} placed, ${j.parts_failed} failed${j.elapsed_s ? `, ${duration(j.elapsed_s)}` : ''}` }),
        buttons);
      const parts = el('table', { class: 'parts' });
      for (const p of j.parts || []) {
        parts.append(el('tr', {}, el('td', { text: `${p.index}` }), el('td', { text: p.class }),
          el('td', { class: `outcome ${p.outcome}`, text: p.outcome.replaceAll('_', ' ') }),
          el('td', { class: 'mono', text: p.outcome === 'placed' ? `${p.placed_at.x_mm.toFixed(1)}, ${p.placed_at.y_mm.toFixed(1)} mm` : '' }),
          el('td', { class: 'muted', text: p.detail })));
      }
      const item = el('div', { class: 'job', 'data-job': j.job_id }, head, bar,
        el('div', { class: 'muted', text: j.step || '' }),
        ...(j.reasons || []).map((r) => el('div', { class: 'error', text: r })), parts);
      list.append(item);
    }
    this.app.applyRole();
  }
}

// ---- health and alarms -------------------------------------------------------------------------

export function renderHealth(health) {
  const table = $('health');
  table.replaceChildren(el('tr', {}, ...['service', 'state', 'host', 'pid', 'up', 'detail'].map((h) => el('th', { text: h }))));
  for (const s of health.services) {
    table.append(el('tr', {}, el('td', { text: s.id }), el('td', { class: `state ${s.state}`, text: s.state }),
      el('td', { text: s.host }), el('td', { text: `${s.pid}` }), el('td', { text: duration(s.uptime_s) }),
      el('td', { class: 'muted', text: s.detail })));
  }
  $('bridge-info').textContent = `bridge: ${health.bridge.clients} stream${health.bridge.clients === 1 ? '' : 's'}, ${health.bridge.dropped} dropped`;
}

export class AlarmLog {
  constructor() {
    this.events = [];
  }

  replace(events) {
    this.events = events.slice(-200);
    this.render();
  }

  add(event) {
    this.events.push(event);
    if (this.events.length > 200) this.events.shift();
    this.render();
  }

  render() {
    const list = $('alarms');
    const onlyAlarms = $('alarms-only').checked;
    list.replaceChildren();
    for (const e of this.events.slice().reverse()) {
      if (onlyAlarms && e.severity === 'info') continue;
      const t = new Date(e.stamp_ns / 1e6);
      list.append(el('div', { class: `event ${e.severity}` },
        el('span', { class: 'mono', text: t.toLocaleTimeString() }),
        el('span', { class: 'sev', text: e.severity }),
        el('span', { class: 'mono', text: e.source }),
        el('span', { class: 'text', text: `${e.code ? `[${e.code}] ` : ''}${e.text}` })));
    }
  }
}
