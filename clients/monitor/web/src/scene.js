// The 3-D view of the cell (three.js): world z up, millimetres. Robots are built from their
// kinematic models and posed from RobotState through kinematics.js; parts and belts come from
// WorldState; detected parts from Detections (in their robot's base frame, on the camera's
// working plane); camera frustums from the camera files. Two views share one canvas (one
// WebGL context): the orbit camera and, at the right, the gripper camera looking along the
// tool's approach vector (EXCAL's dual views, digest 001 §4.3).
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import * as K from './kinematics.js';

const ROBOT_COLOURS = [0xe0a020, 0x3a8ee6, 0x57b85a, 0xc05ad0];
const GRIP_COLOURS = { clear: 0x20b050, blocked: 0xe03030, not_tested: 0x9098a0 };

export function matrix4(m) {
  const out = new THREE.Matrix4();
  out.set(...m);
  return out;
}

/// three's column-major elements back to our row-major 16 numbers.
function rowMajor(matrix) {
  const e = matrix.elements;
  return [e[0], e[4], e[8], e[12], e[1], e[5], e[9], e[13], e[2], e[6], e[10], e[14],
    e[3], e[7], e[11], e[15]];
}

// Lambert shading: headless Chromium renders WebGL in software (SwiftShader), where a
// physically based material per pixel costs frames; the cell reads as well without it.
function material(colour, opts = {}) {
  return new THREE.MeshLambertMaterial({
    color: colour,
    transparent: !!opts.ghost, opacity: opts.ghost ? 0.35 : 1, depthWrite: !opts.ghost,
  });
}

function box(x, y, z, colour, opts = {}) {
  return new THREE.Mesh(new THREE.BoxGeometry(x, y, z), material(colour, opts));
}

function cylinder(r, h, colour, segments = 24, opts = {}) {
  const mesh = new THREE.Mesh(new THREE.CylinderGeometry(r, r, h, segments), material(colour, opts));
  mesh.geometry.rotateX(Math.PI / 2);  // three's cylinders stand on y; ours on z
  return mesh;
}

/// Puts a unit-length bar mesh between two points (a link of the arm).
function placeBar(mesh, a, b) {
  const va = new THREE.Vector3(...a), vb = new THREE.Vector3(...b);
  const len = va.distanceTo(vb);
  mesh.visible = len > 1;
  if (!mesh.visible) return;
  mesh.position.copy(va).add(vb).multiplyScalar(0.5);
  mesh.scale.set(1, 1, len);
  mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 0, 1), vb.clone().sub(va).normalize());
}

function wrapAngle(a) {
  return Math.atan2(Math.sin(a), Math.cos(a));
}

/// Nearest value to `ref` of angle `a` modulo 2 pi (joints may lie outside (-pi, pi]).
function unwrapNear(a, ref) {
  return ref + wrapAngle(a - ref);
}

/// One robot drawn from its model; pose(q) sets its joints. Its joint frames are Object3Ds of
/// the scene graph (`frames`), set from the forward kinematics and read back by
/// renderedJoints(): the joint values the drawn robot really has.
class RobotView {
  constructor(model, colour, opts = {}) {
    this.model = model;
    this.group = new THREE.Group();
    this.world_T_base = K.fromPose(model.world_T_base);
    this.group.matrixAutoUpdate = false;
    this.group.matrix.copy(matrix4(this.world_T_base));
    this.q = null;
    this.tool = null;
    this.sample = null;  // {seq, stamp_ns} of the RobotState drawn
    this.ghost = !!opts.ghost;
    const g = { ghost: this.ghost };
    const frameCount = model.kind === 'scara' ? 4 : 7;
    this.frames = [];
    for (let i = 0; i < frameCount; ++i) {
      const f = new THREE.Object3D();
      f.matrixAutoUpdate = false;
      this.frames.push(f);
      this.group.add(f);
    }
    if (model.kind === 'scara') {
      const sc = model.scara;
      const baseZ = Math.max(200, model.world_T_base.p[2] - 60);
      this.pedestal = cylinder(90, baseZ, 0x555a60, 24, g);
      this.pedestal.position.set(0, 0, -baseZ / 2 - 60 + sc.z_at_zero_mm);
      this.link1 = box(90, 70, 1, colour, g);
      this.link2 = box(70, 60, 1, colour, g);
      this.hub = cylinder(55, 120, colour, 24, g);
      this.hub.position.set(0, 0, sc.z_at_zero_mm + 0);
      this.quill = cylinder(14, 1, 0xb0b0b0, 16, g);
      this.group.add(this.pedestal, this.link1, this.link2, this.hub, this.quill);
    } else {
      // The thesis's look: a 12-sided prism base and one box per link (digest 001 §4.1).
      this.pedestal = cylinder(110, 80, 0x555a60, 12, g);
      this.pedestal.position.set(0, 0, 40);
      this.links = [];
      for (let i = 0; i < 6; ++i) {
        const link = box(60 - i * 6, 60 - i * 6, 1, i % 2 ? colour : 0x8a8f96, g);
        this.links.push(link);
        this.group.add(link);
      }
      this.group.add(this.pedestal);
    }
    this.fingers = [box(8, 22, 40, 0x303030, g), box(8, 22, 40, 0x303030, g)];
    for (const f of this.fingers) f.matrixAutoUpdate = false;
    this.group.add(...this.fingers);
    this.toolAxes = new THREE.AxesHelper(60);
    this.toolAxes.matrixAutoUpdate = false;
    if (!this.ghost) this.group.add(this.toolAxes);
  }

  /// Sets the joints (rad / mm) and the gripper ("open", "closed", ...).
  pose(q, gripper = 'open', sample = null) {
    this.q = q.slice();
    this.sample = sample;
    const model = this.model;
    let tool;
    if (model.kind === 'scara') {
      const f = K.scaraFrames(model, q);
      // frames: shoulder (J1), elbow (J2), link 2's end (R axis, Z = 0), flange (Z, R).
      [f.shoulder, f.elbow, f.link2, f.flange].forEach((m, i) => this.frames[i].matrix.copy(matrix4(m)));
      const z0 = model.scara.z_at_zero_mm + 20;
      const elbow = K.position(f.elbow), end = K.position(f.link2);
      placeBar(this.link1, [0, 0, z0], [elbow[0], elbow[1], z0]);
      placeBar(this.link2, [elbow[0], elbow[1], z0 + 10], [end[0], end[1], z0 + 10]);
      const t = K.position(f.tool);
      placeBar(this.quill, [t[0], t[1], z0 + 60], t);
      tool = f.tool;
    } else {
      const { frames, tool: t } = K.excaliburFrames(model, q);
      frames.forEach((m, i) => this.frames[i].matrix.copy(matrix4(m)));
      for (let i = 0; i < 6; ++i) {
        placeBar(this.links[i], K.position(frames[i]), K.position(frames[i + 1]));
      }
      tool = t;
    }
    this.tool = tool;
    // Fingers: either side of the tool point along its y axis, closer when closed. The tool
    // point is the grasp point (a part is gripped with it at the part's grasp height), so the
    // 40 mm fingers end there and reach back towards the flange, against the approach
    // direction (down for the SCARA, along a for the arm).
    const open = gripper === 'closed' || gripper === 'closing' ? 9 : 22;
    const approach = model.kind === 'scara' ? -1 : 1;
    for (let s = 0; s < 2; ++s) {
      const side = s ? -1 : 1;
      this.fingers[s].matrix.copy(matrix4(K.multiply(tool, K.translation(0, side * open, -approach * 20))));
    }
    this.toolAxes.matrix.copy(matrix4(tool));
    this.group.updateMatrixWorld(true);
  }

  /// The joint values the drawn robot has, decoded from its frames' world matrices (rad / mm).
  renderedJoints() {
    if (!this.q) return null;
    const world_T_base = rowMajor(this.group.matrixWorld);
    const base_T_world = K.invert(world_T_base);
    const local = this.frames.map((f) => K.multiply(base_T_world, rowMajor(f.matrixWorld)));
    if (this.model.kind === 'scara') {
      const sc = this.model.scara;
      const [shoulder, elbow, , flange] = local;
      const j1 = Math.atan2(shoulder[4], shoulder[0]);
      const j12 = Math.atan2(elbow[4], elbow[0]);
      const z = sc.z_down ? sc.z_at_zero_mm - flange[11] : flange[11] - sc.z_at_zero_mm;
      const yaw = Math.atan2(flange[4], flange[0]);
      const link = sc.roll_world ? 0 : j12;
      const r = (sc.roll_clockwise ? -1 : 1) * wrapAngle(yaw - link);
      return [unwrapNear(j1, this.q[0]), unwrapNear(j12 - j1, this.q[1]), z,
        unwrapNear(r, this.q[3])];
    }
    // A_i = T_{i-1}^-1 T_i = Rot(z, theta_i) Trans(0, 0, d) Trans(a, 0, 0) Rot(x, alpha): its
    // first column is (cos theta_i, sin theta_i, 0).
    const q = [];
    for (let i = 1; i < 7; ++i) {
      const a = K.multiply(K.invert(local[i - 1]), local[i]);
      q.push(unwrapNear(Math.atan2(a[4], a[0]), this.q[i - 1]));
    }
    return q;
  }

  /// world_T_tool of the last pose.
  worldTool() {
    return this.tool ? K.multiply(this.world_T_base, this.tool) : null;
  }
}

function partMesh(part) {
  const reflect = Math.round(40 + 180 * (part.reflectance ?? 0.5));
  const colour = part.shape === 'dip' ? 0x1c1c1c : (reflect << 16) | (reflect << 8) | reflect;
  const l = part.length_mm || 10, w = part.width_mm || 10, h = part.height_mm || 3;
  let mesh;
  if (part.shape === 'disc') {
    mesh = cylinder(l / 2, h, colour, 24);
    mesh.position.z = h / 2;
  } else if (part.shape === 'polyhedron' && part.mesh) {
    const geometry = new THREE.BufferGeometry();
    const verts = [];
    const V = part.mesh.vertices_mm;
    let k = 0;
    for (const n of part.mesh.face_sizes) {
      const f = part.mesh.face_indices.slice(k, k + n);
      k += n;
      for (let i = 1; i + 1 < f.length; ++i) verts.push(...V[f[0]], ...V[f[i]], ...V[f[i + 1]]);
    }
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(verts, 3));
    geometry.computeVertexNormals();
    mesh = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({ color: 0xc8a060, side: THREE.DoubleSide }));
  } else if (part.shape === 'triangle') {
    const s = new THREE.Shape();
    const r = l / Math.sqrt(3);
    for (let i = 0; i < 3; ++i) {
      const a = Math.PI / 2 + i * 2 * Math.PI / 3;
      if (i === 0) s.moveTo(r * Math.cos(a), r * Math.sin(a));
      else s.lineTo(r * Math.cos(a), r * Math.sin(a));
    }
    mesh = new THREE.Mesh(new THREE.ExtrudeGeometry(s, { depth: h, bevelEnabled: false }), material(colour));
  } else {
    mesh = box(l, w, h, colour);
    mesh.position.z = h / 2;
    if (part.shape === 'dip' && part.pins > 0) {
      // The pins: a light strip along each long side.
      for (const side of [-1, 1]) {
        const pins = box(l * 0.9, 1.2, h * 0.6, 0xc8c8c8);
        pins.position.set(0, side * (w / 2 + 0.6), h * 0.3 - h / 2);
        mesh.add(pins);
      }
    }
  }
  const group = new THREE.Group();
  group.add(mesh);
  group.matrixAutoUpdate = false;
  return group;
}

export class CellScene {
  constructor(canvas, config) {
    this.canvas = canvas;
    this.config = config;
    // No MSAA (software WebGL pays for it on every pixel). The drawing buffer is preserved: the
    // gripper view is not redrawn every frame (below).
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true,
      powerPreference: 'high-performance' });
    this.renderer.setPixelRatio(1);
    this.renderer.autoClear = false;
    this.scene = new THREE.Scene();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8090a0, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.4);
    sun.position.set(800, -600, 2500);
    this.scene.add(sun);
    const floor = new THREE.GridHelper(4000, 40, 0xb0b8c0, 0xd0d6dc);
    floor.rotation.x = Math.PI / 2;
    this.scene.add(floor);
    this.scene.add(new THREE.AxesHelper(200));

    const t = config.table || { x_mm: [-600, 600], y_mm: [-150, 750], height_mm: 750 };
    this.table = box(t.x_mm[1] - t.x_mm[0], t.y_mm[1] - t.y_mm[0], 20, 0xf4f4f0);
    this.tableSpec = t;
    this.scene.add(this.table);
    // Four legs (a see-through box under the table looked nice but cost a third of the frame
    // rate in software WebGL: two large transparent faces over much of the view).
    this.legs = [];
    for (const [x, y] of [[0, 0], [1, 0], [0, 1], [1, 1]]) {
      const leg = box(40, 40, 1, 0xa8aeb4);
      leg.userData.xy = [t.x_mm[x] + (x ? -40 : 40), t.y_mm[y] + (y ? -40 : 40)];
      this.legs.push(leg);
      this.scene.add(leg);
    }
    this.setTableHeight(t.height_mm);

    this.robots = new Map();
    this.ghosts = new Map();
    config.robots.forEach((model, i) => {
      const view = new RobotView(model, ROBOT_COLOURS[i % ROBOT_COLOURS.length]);
      this.scene.add(view.group);
      this.robots.set(model.id, view);
      const ghost = new RobotView(model, 0x30c0ff, { ghost: true });
      ghost.group.visible = false;
      this.scene.add(ghost.group);
      this.ghosts.set(model.id, ghost);
    });
    this.parts = new Map();
    this.belts = new Map();
    this.detections = new Map();  // camera -> Group of outlines
    this.cameras = (config.cameras || []).map((c) => this.makeFrustum(c));
    this.pathLine = null;
    this.target = new THREE.AxesHelper(40);
    this.target.visible = false;
    this.target.matrixAutoUpdate = false;
    this.scene.add(this.target);

    this.main = new THREE.PerspectiveCamera(45, 1, 10, 20000);
    this.main.up.set(0, 0, 1);
    this.main.position.set(1500, -2100, 2200);
    this.controls = new OrbitControls(this.main, canvas);
    this.controls.target.set(0, 250, 800);
    this.controls.update();
    this.gripperCam = new THREE.PerspectiveCamera(60, 1, 5, 10000);
    this.gripperRobot = config.robots.length ? config.robots[0].id : null;
    this.split = 0.68;  // the orbit view's share of the width
    // The gripper view is redrawn every `gripperEvery` frames, the orbit view every frame: as in
    // EXCAL, "the inactive [view] refreshes every few frames" (digest 001 §4.3). Its pixels stay
    // in the preserved drawing buffer in between.
    this.gripperEvery = 3;
    this.frames = 0;
  }

  setTableHeight(height) {
    const t = this.tableSpec;
    if (!(height > 20) || this.tableHeight === height) return;
    this.tableHeight = height;
    this.table.position.set((t.x_mm[0] + t.x_mm[1]) / 2, (t.y_mm[0] + t.y_mm[1]) / 2, height - 10);
    for (const leg of this.legs) {
      leg.scale.set(1, 1, height - 20);
      leg.position.set(leg.userData.xy[0], leg.userData.xy[1], (height - 20) / 2);
    }
  }

  makeFrustum(camera) {
    const depth = 300;
    const w = camera.width_px, h = camera.height_px;
    const corners = [[0, 0], [w, 0], [w, h], [0, h]].map(([u, v]) => [
      (u - camera.cx_px) / camera.fx_px * depth, (v - camera.cy_px) / camera.fy_px * depth, depth]);
    const pts = [];
    for (const c of corners) pts.push(0, 0, 0, ...c);
    for (let i = 0; i < 4; ++i) pts.push(...corners[i], ...corners[(i + 1) % 4]);
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(pts, 3));
    const lines = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: 0xd03050 }));
    lines.matrixAutoUpdate = false;
    this.scene.add(lines);
    const frustum = { camera, lines };
    this.placeFrustum(frustum);
    return frustum;
  }

  /// world_T_camera of a camera of the config, from its mount and its robot's drawn joints.
  worldCamera(c) {
    if (c.mount === 'fixed') return K.fromPose(c.world_T_camera);
    const robot = this.robots.get(c.robot);
    if (!robot || !robot.q) return null;
    const base_T_mount = c.frame === 'link2' && robot.model.kind === 'scara'
      ? K.scaraFrames(robot.model, robot.q).link2 : robot.tool;
    return K.multiply(K.multiply(robot.world_T_base, base_T_mount), K.fromPose(c.mount_T_camera));
  }

  placeFrustum(f) {
    const m = this.worldCamera(f.camera);
    f.lines.visible = !!m;
    if (m) f.lines.matrix.copy(matrix4(m));
  }

  /// Poses robot `id` from a RobotState sample ({q, gripper, seq, stamp_ns}).
  setRobot(id, q, gripper, sample = null) {
    const view = this.robots.get(id);
    if (!view || !q || q.length !== view.model.dof || q.some((v) => v === null)) return false;
    view.pose(q, gripper, sample);
    return true;
  }

  /// The preview ghost: joints along the planned motion, animated by animateGhost().
  showPreview(id, samples, path, period_ms = 50) {
    const ghost = this.ghosts.get(id);
    const robot = this.robots.get(id);
    if (!ghost || !robot || !samples || !samples.length) return false;
    this.preview = { id, samples, start: performance.now(), period_ms };
    ghost.group.visible = true;
    ghost.pose(samples[0]);
    if (this.pathLine) this.scene.remove(this.pathLine);
    const pts = [];
    if (path && path.length) {
      for (const pose of path) {
        pts.push(new THREE.Vector3(...K.position(K.multiply(robot.world_T_base, K.fromPose(pose)))));
      }
    } else {
      for (const q of samples) {
        pts.push(new THREE.Vector3(...K.position(K.multiply(robot.world_T_base, K.forward(robot.model, q)))));
      }
    }
    this.pathLine = new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts),
      new THREE.LineBasicMaterial({ color: 0x0090ff }));
    this.scene.add(this.pathLine);
    return true;
  }

  clearPreview() {
    this.preview = null;
    for (const g of this.ghosts.values()) g.group.visible = false;
    if (this.pathLine) {
      this.scene.remove(this.pathLine);
      this.pathLine = null;
    }
  }

  animateGhost(now) {
    if (!this.preview) return;
    const { id, samples, start, period_ms } = this.preview;
    // A frame's timestamp may precede the preview's start by a little: clamp at the first sample.
    const i = Math.max(0, Math.min(samples.length - 1, Math.floor((now - start) / period_ms)));
    this.ghosts.get(id).pose(samples[i]);
    if (i === samples.length - 1 && now - start > samples.length * period_ms + 1500) {
      this.preview.start = now;  // loop the preview until it is sent or cleared
    }
  }

  /// Marks a target tool pose (world_T_tool) with an axis triad, or hides it (null).
  showTarget(world_T_tool) {
    this.target.visible = !!world_T_tool;
    if (world_T_tool) this.target.matrix.copy(matrix4(world_T_tool));
  }

  setWorld(world) {
    this.setTableHeight(world.table_height_mm);
    const seen = new Set();
    for (const part of world.parts) {
      if (!part.pose) continue;
      seen.add(part.id);
      let g = this.parts.get(part.id);
      if (!g) {
        g = partMesh(part);
        this.parts.set(part.id, g);
        this.scene.add(g);
      }
      g.matrix.copy(matrix4(K.fromPose(part.pose)));
      g.matrixWorldNeedsUpdate = true;
    }
    for (const [id, g] of this.parts) {
      if (!seen.has(id)) {
        this.scene.remove(g);
        this.parts.delete(id);
      }
    }
    for (const belt of world.belts) this.setBelt(belt);
  }

  /// Outlines of the parts a camera's last image found, where vision located them: in the
  /// robot's base frame (base_pose) on the working plane at `plane_z` (base frame, mm).
  setDetections(d, plane_z) {
    let group = this.detections.get(d.camera);
    if (group) this.scene.remove(group);
    group = new THREE.Group();
    this.detections.set(d.camera, group);
    this.scene.add(group);
    const robot = this.robots.get(d.robot);
    if (!robot || plane_z === null || plane_z === undefined) return;
    for (const item of d.items) {
      if (!item.base_pose) continue;
      const l = item.length_mm || 10, w = item.width_mm || 5;
      const pts = [[-l / 2, -w / 2], [l / 2, -w / 2], [l / 2, w / 2], [-l / 2, w / 2], [-l / 2, -w / 2]]
        .map(([x, y]) => new THREE.Vector3(x, y, 0));
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints(pts),
        new THREE.LineBasicMaterial({ color: GRIP_COLOURS[item.grip] ?? 0x9098a0 }));
      line.matrixAutoUpdate = false;
      const base_T_part = K.multiply(K.translation(item.base_pose.x_mm, item.base_pose.y_mm, plane_z + 4),
        K.rotZ(item.base_pose.rz_rad));
      line.matrix.copy(matrix4(K.multiply(robot.world_T_base, base_T_part)));
      group.add(line);
    }
  }

  setBelt(belt) {
    let b = this.belts.get(belt.id);
    const dir = new THREE.Vector3(...belt.direction).normalize();
    if (!b) {
      const group = new THREE.Group();
      const surface = box(belt.length_mm, belt.width_mm, 10, 0x3c4248);
      surface.position.set(belt.length_mm / 2, 0, -5);
      group.add(surface);
      const slats = [];
      for (let i = 0; i < Math.floor(belt.length_mm / 100); ++i) {
        const slat = box(8, belt.width_mm, 1, 0x8a929a);
        slats.push(slat);
        group.add(slat);
      }
      const beam = box(4, belt.width_mm + 80, 4, 0xff4040);
      beam.position.set(belt.photocell_at_mm, 0, 30);
      group.add(beam);
      group.position.set(...belt.origin_mm);
      group.quaternion.setFromUnitVectors(new THREE.Vector3(1, 0, 0), dir);
      this.scene.add(group);
      b = { group, slats, beam };
      this.belts.set(belt.id, b);
    }
    // The slats move with the belt's travel: the belt visibly runs.
    const offset = ((belt.travel_mm % 100) + 100) % 100;
    b.slats.forEach((s, i) => s.position.set(i * 100 + offset, 0, 1));
    b.beam.material.color.setHex(belt.photocell_blocked ? 0xff2020 : 0x40c040);
  }

  /// Matches the drawing buffer to the canvas's size on the page; true when it changed.
  resize() {
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    if (w > 0 && h > 0 && (this.canvas.width !== w || this.canvas.height !== h)) {
      this.renderer.setSize(w, h, false);
      return true;
    }
    return false;
  }

  /// Places the gripper camera: at the tool point, looking along the approach (a: down for a
  /// SCARA's gripper, the tool's +z for the arm), the tool's x axis (n) up, o to the right
  /// (digest 001 §4.3). Returns false when the robot has no state yet.
  placeGripperCamera() {
    const robot = this.robots.get(this.gripperRobot);
    if (!robot || !robot.tool) return false;
    const wt = robot.worldTool();
    const p = K.position(wt), n = K.column(wt, 0), a = K.column(wt, 2);
    const look = robot.model.kind === 'scara' ? -1 : 1;
    const ahead = 2;  // between the finger tips (the tool point), just past them
    this.gripperCam.position.set(p[0] + look * a[0] * ahead, p[1] + look * a[1] * ahead,
      p[2] + look * a[2] * ahead);
    this.gripperCam.up.set(...n);
    this.gripperCam.lookAt(p[0] + look * a[0] * 1000, p[1] + look * a[1] * 1000, p[2] + look * a[2] * 1000);
    return true;
  }

  render(now) {
    const resized = this.resize();
    this.animateGhost(now);
    for (const f of this.cameras) this.placeFrustum(f);
    const w = this.canvas.width, h = this.canvas.height;
    const split = Math.round(w * this.split);
    this.renderer.setScissorTest(true);
    this.renderer.setViewport(0, 0, split, h);
    this.renderer.setScissor(0, 0, split, h);
    this.main.aspect = split / h;
    this.main.updateProjectionMatrix();
    this.renderer.setClearColor(0xeef1f4);
    this.renderer.clear();
    this.renderer.render(this.scene, this.main);
    if (resized || this.frames % this.gripperEvery === 0 || this.gripperChanged) {
      this.gripperChanged = false;
      this.renderer.setViewport(split, 0, w - split, h);
      this.renderer.setScissor(split, 0, w - split, h);
      this.renderer.setClearColor(0x202428);
      this.renderer.clear();
      if (this.placeGripperCamera()) {
        this.gripperCam.aspect = (w - split) / h;
        this.gripperCam.updateProjectionMatrix();
        this.renderer.render(this.scene, this.gripperCam);
      }
    }
    this.renderer.setScissorTest(false);
    ++this.frames;
  }
}
