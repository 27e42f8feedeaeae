// Small rolling time plots on a 2-D canvas (no library): tracking error, servo loop jitter and
// pick rate, one line per robot, the last `windowS` seconds.

const COLOURS = ['#e0a020', '#3a8ee6', '#57b85a', '#c05ad0', '#d04040'];

export class Plot {
  constructor(canvas, title, unit, windowS = 60) {
    this.canvas = canvas;
    this.title = title;
    this.unit = unit;
    this.windowS = windowS;
    this.series = new Map();  // name -> [[t_s, value]]
  }

  add(name, tS, value) {
    if (value === null || value === undefined || !Number.isFinite(value)) return;
    let s = this.series.get(name);
    if (!s) {
      s = [];
      this.series.set(name, s);
    }
    // Keep at most ~10 points per second per series.
    if (s.length && tS - s[s.length - 1][0] < 0.1) {
      s[s.length - 1][1] = Math.max(s[s.length - 1][1], value);
      return;
    }
    s.push([tS, value]);
    while (s.length && s[0][0] < tS - this.windowS) s.shift();
  }

  latest(name) {
    const s = this.series.get(name);
    return s && s.length ? s[s.length - 1][1] : null;
  }

  draw(nowS) {
    const c = this.canvas;
    const w = c.clientWidth || 300, h = c.clientHeight || 120;
    if (c.width !== w || c.height !== h) {
      c.width = w;
      c.height = h;
    }
    const g = c.getContext('2d');
    g.clearRect(0, 0, w, h);
    g.fillStyle = '#fff';
    g.fillRect(0, 0, w, h);
    let max = 0;
    for (const s of this.series.values()) for (const [, v] of s) max = Math.max(max, v);
    max = max > 0 ? max * 1.15 : 1;
    const left = 44, right = 6, top = 18, bottom = 16;
    const x = (t) => left + (w - left - right) * (1 - (nowS - t) / this.windowS);
    const y = (v) => top + (h - top - bottom) * (1 - v / max);
    g.strokeStyle = '#d8dde2';
    g.beginPath();
    for (let k = 0; k <= 4; ++k) {
      g.moveTo(left, y(max * k / 4));
      g.lineTo(w - right, y(max * k / 4));
    }
    g.stroke();
    g.fillStyle = '#556';
    g.font = '11px sans-serif';
    g.fillText(`${this.title} [${this.unit}]`, left, 12);
    g.fillText(formatTick(max), 2, top + 4);
    g.fillText('0', 2, h - bottom);
    g.fillText(`-${this.windowS} s`, left, h - 3);
    let i = 0;
    for (const [name, s] of this.series) {
      g.strokeStyle = COLOURS[i % COLOURS.length];
      g.beginPath();
      s.forEach(([t, v], k) => (k ? g.lineTo(x(t), y(v)) : g.moveTo(x(t), y(v))));
      g.stroke();
      g.fillStyle = g.strokeStyle;
      g.fillText(name, w - right - 90, 12 + 12 * i);
      ++i;
    }
  }
}

function formatTick(v) {
  return v >= 100 ? v.toFixed(0) : v >= 1 ? v.toFixed(1) : v.toPrecision(2);
}
