// The live camera image with what vision made of it drawn over it: each detection's outline,
// centre and index (the N of "go to part N"), its clear-grip fingerprints (digest 002 §3: the
// two finger windows of the style that passed in green, of every style when none did in red),
// and the RAPT edge measurements (LOOK: the search window and the edge found).
//
// Pixels: u to the right, v down, origin at the top-left pixel's centre (vision.idl).

const GRIP = { clear: '#20b050', blocked: '#e03030', not_tested: '#a0a8b0' };

/// Eq. (5)-(7) of digest 002 §3.3 in the image: the two fingerprint windows of `style` for a
/// part at centre c (px) with major axis at angle `aim` (rad), `scale` px per mm.
export function fingerprintWindows(c, aim, style, model, scale) {
  const beta = aim + (style.alpha_rad || 0);
  const g = [c[0] - (style.d_cg_mm || 0) * scale * Math.cos(beta),
    c[1] - (style.d_cg_mm || 0) * scale * Math.sin(beta)];
  const ga = beta + (style.rz_off_rad || 0);
  const dg = (style.part_width_mm / 2 + model.finger_width_mm / 2) * scale;
  const ux = [Math.cos(ga), Math.sin(ga)], uy = [-Math.sin(ga), Math.cos(ga)];
  const hw = model.finger_width_mm / 2 * scale, hh = model.finger_height_mm / 2 * scale;
  return [-1, 1].map((side) => {
    const cw = [g[0] + side * dg * ux[0], g[1] + side * dg * ux[1]];
    return [[-1, -1], [1, -1], [1, 1], [-1, 1]].map(([a, b]) => [
      cw[0] + a * hw * ux[0] + b * hh * uy[0], cw[1] + a * hw * ux[1] + b * hh * uy[1]]);
  });
}

export class CameraView {
  constructor(canvas, select, info, config) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.select = select;
    this.info = info;
    this.cameras = config.cameras || [];
    this.grasps = new Map((config.grasps || []).map((g) => [g.class, g]));
    this.images = new Map();      // camera -> HTMLImageElement of the newest frame
    this.notes = new Map();       // camera -> image note
    this.detections = new Map();  // camera -> detections
    this.edges = new Map();       // camera -> recent edge results
    for (const c of this.cameras) {
      const o = document.createElement('option');
      o.value = c.id;
      o.textContent = c.id;
      select.appendChild(o);
    }
    select.addEventListener('change', () => this.draw());
  }

  get camera() {
    return this.select.value;
  }

  setImage(note) {
    this.notes.set(note.camera, note);
    const img = new Image();
    img.onload = () => {
      this.images.set(note.camera, img);
      if (note.camera === this.camera) this.draw();
    };
    img.onerror = () => {};  // a frame replaced before it loaded: the next one comes
    img.src = `/api/image/${encodeURIComponent(note.camera)}?seq=${note.seq}`;
  }

  setDetections(d) {
    this.detections.set(d.camera, d);
    if (d.camera === this.camera) this.draw();
  }

  addEdge(e) {
    const list = this.edges.get(e.camera) || [];
    list.push(e);
    while (list.length > 12) list.shift();
    this.edges.set(e.camera, list);
    if (e.camera === this.camera) this.draw();
  }

  draw() {
    const id = this.camera;
    const cam = this.cameras.find((c) => c.id === id);
    const img = this.images.get(id);
    const w = cam ? cam.width_px : 512, h = cam ? cam.height_px : 484;
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.canvas.width = w;
      this.canvas.height = h;
    }
    const g = this.ctx;
    g.fillStyle = '#101214';
    g.fillRect(0, 0, w, h);
    if (img) g.drawImage(img, 0, 0, w, h);
    const d = this.detections.get(id);
    const note = this.notes.get(id);
    g.lineWidth = 1.5;
    g.font = '14px sans-serif';
    if (d) {
      for (const item of d.items) this.drawDetection(g, item);
    }
    for (const e of this.edges.get(id) || []) this.drawEdge(g, e);
    const parts = [];
    parts.push(note ? `frame ${note.image_seq}` : 'no image yet');
    if (d) {
      parts.push(`${d.items.length} part${d.items.length === 1 ? '' : 's'} found` +
        (d.processing_ms !== null ? ` in ${d.processing_ms.toFixed(1)} ms` : ''));
      if (d.error) parts.push(`error: ${d.error}`);
      if (d.calibration) parts.push(`mapped by ${d.calibration}`);
    }
    this.info.textContent = parts.join(' · ');
  }

  drawDetection(g, item) {
    const colour = GRIP[item.grip] || GRIP.not_tested;
    g.strokeStyle = colour;
    if (item.corners_px && item.corners_px.length > 2) {
      g.beginPath();
      item.corners_px.forEach(([u, v], i) => (i ? g.lineTo(u, v) : g.moveTo(u, v)));
      g.closePath();
      g.stroke();
    }
    const [u, v] = item.center_px;
    g.beginPath();
    g.moveTo(u - 5, v);
    g.lineTo(u + 5, v);
    g.moveTo(u, v - 5);
    g.lineTo(u, v + 5);
    g.stroke();
    g.fillStyle = colour;
    g.fillText(`${item.id} ${item.class}`, u + 7, v - 7);
    // Fingerprints: the style that passed, or every style tried when none did.
    const model = this.grasps.get(item.class);
    const scale = item.length_mm > 0 && item.length_px > 0 ? item.length_px / item.length_mm
      : item.width_mm > 0 && item.width_px > 0 ? item.width_px / item.width_mm : 0;
    if (!model || !(scale > 0) || item.grip === 'not_tested') return;
    const styles = item.grip === 'clear' && item.grip_style >= 0
      ? [model.styles[item.grip_style]].filter(Boolean) : model.styles;
    g.setLineDash([3, 2]);
    for (const style of styles) {
      for (const win of fingerprintWindows(item.center_px, item.angle_rad, style, model, scale)) {
        g.beginPath();
        win.forEach(([x, y], i) => (i ? g.lineTo(x, y) : g.moveTo(x, y)));
        g.closePath();
        g.stroke();
      }
    }
    g.setLineDash([]);
  }

  drawEdge(g, e) {
    // The window: p1 -> p2 across the edge, p1 -> p3 along it; the fourth corner p2 + p3 - p1.
    const [p1, p2, p3] = e.window_px;
    if (p1 && p2 && p3 && p1.every((x) => x !== null)) {
      const p4 = [p2[0] + p3[0] - p1[0], p2[1] + p3[1] - p1[1]];
      g.strokeStyle = '#f0c020';
      g.beginPath();
      g.moveTo(...p1);
      g.lineTo(...p2);
      g.lineTo(...p4);
      g.lineTo(...p3);
      g.closePath();
      g.stroke();
    }
    if (e.accepted && e.start_px && e.end_px) {
      g.strokeStyle = '#30d0ff';
      g.lineWidth = 2.5;
      g.beginPath();
      g.moveTo(...e.start_px);
      g.lineTo(...e.end_px);
      g.stroke();
      g.lineWidth = 1.5;
    }
  }
}
