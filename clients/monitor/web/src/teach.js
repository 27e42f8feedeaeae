// The Teach panel: the thesis's teach pendant (digest 001 §5) in the page. One task is open
// for the whole cell (the bridge holds it); record the robot's live pose as a named step, add
// gripper steps and waits, delete or reorder steps, step forward and back or run, in preview
// (the planned motion animates as a ghost arm, nothing moves) or on the robot.
import * as api from './api.js';
import { $, el, report } from './panels.js';

export class TeachPanel {
  constructor(app) {
    this.app = app;
    this.state = null;
    this.selected = null;
    const robots = $('teach-robot');
    for (const r of app.config.robots) robots.append(el('option', { value: r.id, text: r.id }));
    const on = (id, fn) => $(id).addEventListener('click', fn);
    on('teach-new', () => this.act('create', { robot: $('teach-robot').value, name: $('teach-name').value.trim() }));
    on('teach-open', () => this.act('open', { file: $('teach-files').value }));
    on('teach-save', () => this.act('save', {}));
    on('teach-save-as', () => this.act('save', { file: `${$('teach-name').value.trim()}.yaml` }));
    on('teach-record', () => this.act('record', { name: $('teach-pose-name').value.trim(), move: $('teach-move').value }));
    on('teach-grip-open', () => this.act('gripper', { action: 'open' }));
    on('teach-grip-close', () => this.act('gripper', { action: 'close' }));
    on('teach-wait', () => this.act('wait', { seconds: Number($('teach-wait-s').value) }));
    on('teach-delete', () => this.withSelection((i) => this.act('delete', { index: i })));
    on('teach-up', () => this.withSelection((i) => i > 0 && this.act('move', { from: i, to: i - 1 }).then(() => { this.selected = i - 1; })));
    on('teach-down', () => this.withSelection((i) => this.act('move', { from: i, to: i + 1 }).then(() => { this.selected = i + 1; })));
    on('teach-rename', () => this.withSelection((i) => this.act('rename', { index: i, name: $('teach-pose-name').value.trim() })));
    on('teach-back', () => this.play('step', { direction: 'backward' }));
    on('teach-forward', () => this.play('step', { direction: 'forward' }));
    on('teach-run', () => this.play('run', {}));
    on('teach-stop', () => this.act('stop', {}));
    on('teach-rewind', () => this.act('seek', { position: 0 }));
  }

  withSelection(fn) {
    if (this.selected === null) {
      report({ ok: false, status: 0, body: { error: 'select a step first' } }, 'teach');
      return;
    }
    fn(this.selected);
  }

  async act(action, body) {
    const r = report(await api.post(`/api/teach/${action}`, body), `teach ${action}`);
    if (r.ok && r.body.state) this.set(r.body.state);
    return r;
  }

  /// Step or run: preview (default) animates the simulated joints; on the robot it starts the
  /// playback and the progress streams in.
  async play(action, body) {
    const preview = !$('teach-on-robot').checked;
    const r = await this.act(action, { ...body, preview });
    if (!r.ok || !preview || !r.body.steps) return;
    const samples = r.body.steps.flatMap((s) => s.samples);
    if (samples.length) {
      this.app.scene.showPreview(r.body.robot, samples, null, 1000 * r.body.sample_period_s);
    }
  }

  set(state) {
    this.state = state;
    const files = $('teach-files');
    const current = files.value;
    files.replaceChildren(...state.files.map((f) => el('option', { value: f, text: f })));
    if (state.files.includes(current)) files.value = current;
    $('teach-title').textContent = state.task
      ? `${state.file}${state.dirty ? ' (unsaved)' : ''} — ${state.task.robot}, ${state.task.steps.length} steps` : 'no task open';
    $('teach-message').textContent = `${state.running ? 'running on the robot: ' : ''}${state.message || ''}`;
    const list = $('teach-steps');
    list.replaceChildren();
    const steps = state.task ? state.task.steps : [];
    if (this.selected !== null && this.selected >= steps.length) this.selected = null;
    steps.forEach((s, i) => {
      if (i === state.cursor) list.append(el('div', { class: 'cursor', text: '▶ cursor' }));
      const item = el('div', { class: `step${i === this.selected ? ' selected' : ''}`, 'data-index': `${i}`,
        onclick: () => {
          this.selected = i;
          this.set(this.state);
        } }, el('span', { class: 'mono', text: `${i + 1}` }), el('span', { text: s.text }));
      list.append(item);
    });
    if (state.cursor >= steps.length && steps.length) list.append(el('div', { class: 'cursor', text: '▶ cursor (end)' }));
  }
}
