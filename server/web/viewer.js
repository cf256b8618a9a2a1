// The gmr viewer: a motion playing live, seen in the world and from any
// joint (the intrinsic viewpoint of Guerra-Filho's GMR). It speaks the gmr
// protocol over gmr-server's WebSocket in protobuf's JSON mapping
// (subprotocol gmr.stream.v1.json, docs/protocol.md "WebSocket").
//
// Two views of the motion live on the server: "world" (world coordinates)
// and "joint" (SetCoordinates relative_to the chosen joint). Root edits
// (shift, split, join) go to both, so both show the same forest. Each view
// has one subscription; play, pause, seek, speed and loop act on both.
//
// window.gmrViewer exposes what the browser test reads back (docs/viewer.md):
// the joints as drawn (from the scene's objects), where a joint is on
// screen, and the state of the connection.
import * as THREE from 'three';
import { OrbitControls } from '/three/examples/jsm/controls/OrbitControls.js';

const PROTOCOL_VERSION = 1;
const HEARTBEAT_MS = 2000;
const STALENESS_MS = 250;  // frames older than this are neither sent (the server's bound) nor drawn
const JOINT_CAPTION = 'From a joint: pick one and tick “View from this joint”';
const $ = (id) => document.getElementById(id);

// ------------------------------------------------------------------ protocol

class GmrSocket {
  constructor(url) {
    this.url = url;
    this.nextId = 1;
    this.pending = new Map();  // requestId -> {resolve, reject}
    this.onPush = () => {};
    this.onClose = () => {};
    this.clockOffsetMs = 0;  // server clock minus ours
  }

  open() {
    return new Promise((resolve, reject) => {
      this.ws = new WebSocket(this.url, 'gmr.stream.v1.json');
      this.ws.onopen = () => resolve();
      this.ws.onerror = () => reject(new Error(`cannot open ${this.url}`));
      this.ws.onclose = (e) => {
        clearInterval(this.heartbeat);
        for (const p of this.pending.values()) p.reject(new Error('connection closed'));
        this.pending.clear();
        this.onClose(e);
      };
      this.ws.onmessage = (e) => this.receive(JSON.parse(e.data));
    });
  }

  receive(m) {
    const id = Number(m.requestId || 0);
    if (id !== 0 && this.pending.has(id)) {
      const p = this.pending.get(id);
      this.pending.delete(id);
      if (m.error) p.reject(new Error(`${m.error.code}: ${m.error.message}`));
      else p.resolve(m);
      return;
    }
    this.onPush(m);
  }

  // Sends `body` (one ClientMessage field) and resolves with the reply.
  ask(body) {
    const requestId = this.nextId++;
    return new Promise((resolve, reject) => {
      this.pending.set(requestId, { resolve, reject });
      this.ws.send(JSON.stringify({ requestId, ...body }));
    });
  }

  async hello() {
    const t0 = Date.now();
    // A token, if the server wants one, comes in the address's fragment
    // (#token=...), which the browser never sends in an HTTP request.
    const token = new URLSearchParams(location.hash.slice(1)).get('token');
    const hello = { protocolVersion: PROTOCOL_VERSION, clientName: 'gmr viewer' };
    if (token) hello.authToken = token;
    const reply = await this.ask({ hello });
    const t1 = Date.now();
    if (reply.hello.serverTimeNs) this.clockOffsetMs = Number(reply.hello.serverTimeNs) / 1e6 - (t0 + t1) / 2;
    const every = Math.min(HEARTBEAT_MS, (reply.hello.idleTimeoutMs || 30000) / 3);
    this.heartbeat = setInterval(() => this.ws.send('{"heartbeat":{}}'), every);
    return reply.hello;
  }
}

// ------------------------------------------------------------------ drawing

const JOINT = new THREE.Color(0xd8dde6);
const ROOT = new THREE.Color(0xff9d3b);
const SELECTED = new THREE.Color(0x3bd1ff);

// One canvas: a skeleton (joints as spheres, bones as lines, soft links
// dashed), a ground grid, an orbit camera.
class SkeletonPanel {
  constructor(canvas, { axes = false } = {}) {
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio);
    this.renderer.setClearColor(0x14171c);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 1e6);
    this.controls = new OrbitControls(this.camera, canvas);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 1.0));
    this.skeleton = new THREE.Group();
    this.skeleton.name = 'skeleton';
    this.scene.add(this.skeleton);
    this.withAxes = axes;
    this.joints = new Map();  // name -> mesh
    this.frame = null;        // frame index drawn
    this.version = null;      // skeleton version drawn
    this.fitted = false;
  }

  clear() {
    for (const child of [...this.skeleton.children]) {
      this.skeleton.remove(child);
      if (child.geometry) child.geometry.dispose();
    }
    if (this.grid) this.scene.remove(this.grid);
    if (this.axes) this.scene.remove(this.axes);
    this.grid = this.axes = null;
    this.joints.clear();
    this.frame = null;
    this.fitted = false;
  }

  // `joints`: [{name, parent, softParent}] parents first; `order`: the joint
  // index of each position triple in the frames.
  setSkeleton(joints, order, version) {
    for (const m of this.joints.values()) this.skeleton.remove(m);
    if (this.bones) this.skeleton.remove(this.bones);
    if (this.soft) this.skeleton.remove(this.soft);
    this.joints.clear();
    this.list = joints;
    this.order = order;
    this.version = version;
    this.frame = null;
    const sphere = new THREE.SphereGeometry(1, 14, 10);
    for (const j of joints) {
      const mesh = new THREE.Mesh(sphere, new THREE.MeshLambertMaterial({ color: JOINT }));
      mesh.name = j.name;
      mesh.userData.joint = j.name;
      mesh.visible = false;  // until a frame places it
      this.joints.set(j.name, mesh);
      this.skeleton.add(mesh);
    }
    const pairs = joints.filter((j) => j.parent >= 0).length;
    this.bones = new THREE.LineSegments(
      new THREE.BufferGeometry().setAttribute('position', new THREE.BufferAttribute(new Float32Array(pairs * 6), 3)),
      new THREE.LineBasicMaterial({ color: 0x9fb0c8 }));
    const softPairs = joints.filter((j) => j.parent < 0 && j.softParent >= 0).length;
    this.soft = new THREE.LineSegments(
      new THREE.BufferGeometry().setAttribute('position', new THREE.BufferAttribute(new Float32Array(softPairs * 6), 3)),
      new THREE.LineDashedMaterial({ color: 0xff9d3b, dashSize: 1, gapSize: 1 }));
    this.skeleton.add(this.bones, this.soft);
    this.paint();
  }

  paint(selected) {
    for (const j of this.list || []) {
      const mesh = this.joints.get(j.name);
      const isRoot = j.parent < 0;
      mesh.material.color.copy(j.name === selected ? SELECTED : isRoot ? ROOT : JOINT);
      mesh.userData.scale = j.name === selected ? 1.7 : isRoot ? 1.5 : 1;
    }
    this.rescale();
  }

  rescale() {
    const r = (this.size || 1) * 0.012;
    for (const mesh of this.joints.values()) mesh.scale.setScalar(r * (mesh.userData.scale || 1));
  }

  // `p`: positions, 3 per entry of this.order.
  setFrame(p, frameIndex) {
    if (!this.list) return;
    const at = new Map();
    this.order.forEach((jointIndex, k) => at.set(jointIndex, k));
    for (const [jointIndex, k] of at) {
      const mesh = this.joints.get(this.list[jointIndex].name);
      mesh.position.set(p[3 * k], p[3 * k + 1], p[3 * k + 2]);
      mesh.visible = true;
    }
    const pos = (i) => this.joints.get(this.list[i].name).position;
    const bones = this.bones.geometry.attributes.position;
    let n = 0;
    this.list.forEach((j, i) => {
      if (j.parent < 0) return;
      bones.setXYZ(n++, ...pos(j.parent).toArray());
      bones.setXYZ(n++, ...pos(i).toArray());
    });
    bones.needsUpdate = true;
    const soft = this.soft.geometry.attributes.position;
    n = 0;
    this.list.forEach((j, i) => {
      if (j.parent >= 0 || j.softParent < 0) return;
      soft.setXYZ(n++, ...pos(j.softParent).toArray());
      soft.setXYZ(n++, ...pos(i).toArray());
    });
    soft.needsUpdate = true;
    this.soft.computeLineDistances();
    this.bones.geometry.computeBoundingSphere();
    this.frame = frameIndex;
    if (!this.fitted) {
      this.fit();
    } else {
      this.follow();
    }
  }

  centre() {
    const box = new THREE.Box3();
    for (const m of this.joints.values()) if (m.visible) box.expandByPoint(m.position);
    return box.isEmpty() ? null : box.getCenter(new THREE.Vector3());
  }

  // The camera follows the skeleton across the floor (the orbit stays the
  // user's); the grid moves by whole cells, so it reads as fixed ground.
  follow() {
    const c = this.centre();
    if (!c || !this.lastCentre) return;
    const d = c.clone().sub(this.lastCentre);
    this.camera.position.add(d);
    this.controls.target.add(d);
    this.lastCentre = c;
    if (this.grid && !this.withAxes) {
      const cell = this.cell;
      this.grid.position.x = Math.round(c.x / cell) * cell;
      this.grid.position.z = Math.round(c.z / cell) * cell;
    }
  }

  // Frames the skeleton: camera, grid under its lowest joint, dash length.
  fit() {
    const box = new THREE.Box3();
    for (const m of this.joints.values()) if (m.visible) box.expandByPoint(m.position);
    if (box.isEmpty()) return;
    const size = Math.max(box.getSize(new THREE.Vector3()).length(), 1e-6);
    this.size = size;
    this.rescale();
    this.soft.material.dashSize = this.soft.material.gapSize = size * 0.02;
    const centre = box.getCenter(new THREE.Vector3());
    this.controls.target.copy(centre);
    this.camera.position.copy(centre).add(new THREE.Vector3(0.9, 0.5, 1.6).multiplyScalar(size));
    this.camera.near = size * 0.005;
    this.camera.far = size * 200;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.lastCentre = centre.clone();
    if (this.grid) this.scene.remove(this.grid);
    // Seen from a joint, the grid is that joint's x-z plane through it.
    this.cell = size / 5;
    this.grid = new THREE.GridHelper(this.cell * 30, 30, 0x3a4252, 0x262b35);
    if (this.withAxes) {
      this.grid.position.set(0, 0, 0);
    } else {
      this.grid.position.set(Math.round(centre.x / this.cell) * this.cell, box.min.y,
                             Math.round(centre.z / this.cell) * this.cell);
    }
    this.scene.add(this.grid);
    if (this.withAxes) {
      if (this.axes) this.scene.remove(this.axes);
      this.axes = new THREE.AxesHelper(size * 0.25);
      this.scene.add(this.axes);
    }
    this.fitted = true;
  }

  resize() {
    const w = this.canvas.clientWidth, h = this.canvas.clientHeight;
    if (w === 0 || h === 0) return;
    if (this.canvas.width !== Math.floor(w * window.devicePixelRatio) ||
        this.canvas.height !== Math.floor(h * window.devicePixelRatio)) {
      this.renderer.setSize(w, h, false);
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
    }
  }

  render() {
    this.resize();
    this.renderer.render(this.scene, this.camera);
  }

  // The joint under client coordinates (x, y), or null.
  pick(x, y) {
    const rect = this.canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2(((x - rect.left) / rect.width) * 2 - 1, -((y - rect.top) / rect.height) * 2 + 1);
    const ray = new THREE.Raycaster();
    ray.setFromCamera(ndc, this.camera);
    const hits = ray.intersectObjects([...this.joints.values()].filter((m) => m.visible));
    return hits.length ? hits[0].object.userData.joint : null;
  }

  // Where joint `name` is drawn, in client coordinates.
  screenPosition(name) {
    const mesh = this.joints.get(name);
    if (!mesh || !mesh.visible) return null;
    const v = mesh.position.clone().project(this.camera);
    const rect = this.canvas.getBoundingClientRect();
    return { x: rect.left + ((v.x + 1) / 2) * rect.width, y: rect.top + ((1 - v.y) / 2) * rect.height };
  }

  // The joints as the scene holds them now.
  drawn() {
    const joints = {};
    for (const [name, mesh] of this.joints) if (mesh.visible) joints[name] = mesh.position.toArray();
    return { frame: this.frame, version: this.version, joints };
  }
}

// ------------------------------------------------------------------ the page

class Viewer {
  constructor() {
    this.socket = new GmrSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
    this.panels = { world: new SkeletonPanel($('world-canvas')), joint: new SkeletonPanel($('joint-canvas'), { axes: true }) };
    this.views = { world: null, joint: null };          // ViewInfo per panel
    this.subs = { world: null, joint: null };           // Subscribed per panel
    this.selected = null;
    this.viewpoint = null;   // the joint the right panel is seen from
    this.rig = null;         // the library motion whose skeleton the right panel shows the motion on
    this.playing = true;
    this.motion = null;
    this.figures = { frames: 0, windowStart: performance.now(), fps: 0, latencies: [], drops: 0, stale: 0, lastSeq: new Map() };
    this.motions = [];
    this.errors = [];
    this.connected = false;
  }

  async start() {
    this.socket.onPush = (m) => this.push(m);
    // The server went away (a restart, a stop): say so, and try again until it is back.
    // (A connection refused at Hello, a bad token say, stays refused: its error shows.)
    this.socket.onClose = (e) => {
      const was = this.connected;
      this.connected = false;
      const why = `disconnected (${e.code}${e.reason ? ': ' + e.reason : ''})`;
      this.status(was ? `${why}; retrying in 3 s` : why, 'bad');
      if (was) setTimeout(() => location.reload(), 3000);
    };
    try {
      await this.socket.open();
      const hello = await this.socket.hello();
      this.status(`connected to ${hello.serverName || 'gmr-server'}`, 'ok');
      this.connected = true;
      const list = await this.socket.ask({ listMotions: {} });
      this.motions = list.motions.motions || [];
      this.listMotions();
    } catch (e) {
      this.fail(e);
      return;
    }
    this.wire();
    const loop = () => {
      this.panels.world.render();
      this.panels.joint.render();
      this.tickFigures();
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
    const first = new URLSearchParams(location.search).get('motion') || (this.motions[0] && this.motions[0].name);
    if (first) await this.open(first);
  }

  status(text, kind = '') {
    $('status').textContent = text;
    $('status').className = `status ${kind}`;
  }

  fail(e) {
    console.error(e);
    this.errors.push(String(e.message || e));
    $('message').textContent = String(e.message || e);
  }

  listMotions() {
    const ul = $('motions');
    ul.replaceChildren();
    for (const m of this.motions) {
      const li = document.createElement('li');
      li.dataset.motion = m.name;
      const name = document.createElement('span');
      name.textContent = m.name;
      const meta = document.createElement('span');
      meta.className = 'meta';
      const frames = Number(m.frameCount || 0);
      meta.textContent = `${m.jointCount || 0} j · ${(frames * (m.frameTime || 0)).toFixed(1)} s`;
      li.append(name, meta);
      li.onclick = () => this.open(m.name).catch((e) => this.fail(e));
      ul.append(li);
    }
    const rigs = $('rig');
    rigs.replaceChildren(rigs.options[0]);
    for (const m of this.motions) {
      const o = document.createElement('option');
      o.value = o.textContent = m.name;
      rigs.append(o);
    }
  }

  wire() {
    $('play').onclick = () => this.togglePlay().catch((e) => this.fail(e));
    $('seek').oninput = () => { $('frame-label').textContent = this.frameLabel(Number($('seek').value)); };
    $('seek').onchange = () => this.seek(Number($('seek').value)).catch((e) => this.fail(e));
    $('speed').onchange = () => this.resubscribe().catch((e) => this.fail(e));
    $('loop').onchange = () => this.resubscribe().catch((e) => this.fail(e));
    $('btn-shift').onclick = () => this.edit('shiftRoot', { joint: this.selected }).catch((e) => this.fail(e));
    $('btn-split').onclick = () => this.edit('split', { joint: this.selected }).catch((e) => this.fail(e));
    $('btn-join').onclick = () => this.edit('join', { root: this.selected }).catch((e) => this.fail(e));
    $('viewpoint').onchange = () => this.setViewpoint($('viewpoint').checked ? this.selected : null).catch((e) => this.fail(e));
    $('rig').onchange = () => this.setRig($('rig').value).catch((e) => this.fail(e));
    for (const panel of Object.values(this.panels)) {
      // A click (not a drag of the orbit camera) on a joint selects it.
      let down = null;
      panel.canvas.addEventListener('pointerdown', (e) => { down = { x: e.clientX, y: e.clientY }; });
      panel.canvas.addEventListener('pointerup', (e) => {
        if (!down || Math.hypot(e.clientX - down.x, e.clientY - down.y) > 4) return;
        const joint = panel.pick(e.clientX, e.clientY);
        if (joint) this.select(joint);
      });
    }
  }

  async open(name) {
    const info = this.motions.find((m) => m.name === name);
    if (!info) throw new Error(`no motion ${name}`);
    for (const key of ['world', 'joint']) {
      if (this.subs[key]) await this.socket.ask({ unsubscribe: { subscriptionId: this.subs[key].subscriptionId } }).catch(() => {});
      if (this.views[key]) await this.socket.ask({ closeView: { viewId: this.views[key].viewId } }).catch(() => {});
      this.subs[key] = this.views[key] = null;
      this.panels[key].clear();
    }
    this.motion = info;
    this.selected = null;
    this.viewpoint = null;
    this.rig = null;
    $('rig').value = '';
    $('viewpoint').checked = false;
    $('joint-caption').textContent = JOINT_CAPTION;
    for (const li of $('motions').children) li.classList.toggle('current', li.dataset.motion === name);
    this.views.world = (await this.socket.ask({ createView: { motion: name } })).view;
    this.views.joint = (await this.socket.ask({ createView: { motion: name } })).view;
    const frames = Number(this.views.world.frameCount || 0);
    $('seek').max = String(Math.max(0, frames - 1));
    $('seek').value = '0';
    this.showJoint();
    await this.subscribe('world', 0);
    this.refreshRoots();
  }

  frameLabel(f) { return `${f} / ${Math.max(0, Number(this.views.world ? this.views.world.frameCount : 0) - 1)}`; }

  async subscribe(key, startFrame) {
    const view = this.views[key];
    const reply = await this.socket.ask({ subscribe: {
      viewId: view.viewId,
      startFrame,
      loop: $('loop').checked,
      speed: Number($('speed').value),
      precision: 'PRECISION_FLOAT64',
      maxStalenessMs: STALENESS_MS,
      // Held (its first frame drawn, then nothing) until Play.
      paused: !this.playing,
    } });
    const sub = reply.subscribed;
    this.subs[key] = sub;
    this.panels[key].setSkeleton(view.skeleton.joints.map(jointOf), sub.joints || [], sub.skeletonVersion || 0);
    this.panels[key].paint(this.selected);
    this.figures.lastSeq.delete(sub.subscriptionId);
  }

  async unsubscribe(key) {
    if (!this.subs[key]) return;
    const id = this.subs[key].subscriptionId;
    this.subs[key] = null;
    await this.socket.ask({ unsubscribe: { subscriptionId: id } }).catch(() => {});
  }

  currentFrame() { return this.panels.world.frame ?? 0; }

  async resubscribe() {
    const from = this.currentFrame();
    for (const key of ['world', 'joint']) {
      if (!this.subs[key]) continue;
      await this.unsubscribe(key);
      await this.subscribe(key, from);
    }
  }

  async togglePlay() {
    this.playing = !this.playing;
    $('play').textContent = this.playing ? 'Pause' : 'Play';
    for (const sub of Object.values(this.subs)) {
      if (sub) await this.socket.ask({ [this.playing ? 'resume' : 'pause']: { subscriptionId: sub.subscriptionId } });
    }
  }

  async seek(frame) {
    for (const sub of Object.values(this.subs)) {
      if (sub) await this.socket.ask({ seek: { subscriptionId: sub.subscriptionId, frame } });
    }
  }

  select(joint) {
    this.selected = joint;
    this.showJoint();
    for (const p of Object.values(this.panels)) p.paint(joint);
  }

  showJoint() {
    const j = this.selected && this.joint(this.selected);
    $('joint-name').textContent = j ? j.name : '— click one';
    $('btn-shift').disabled = !j || j.parent < 0;
    $('btn-split').disabled = !j || j.parent < 0;
    $('btn-join').disabled = !j || !(j.parent < 0 && j.softParent >= 0);
    $('viewpoint').disabled = this.rig !== null || (!j && !this.viewpoint);
  }

  joint(name) {
    const v = this.views.world;
    const j = v && v.skeleton.joints.find((x) => x.name === name);
    return j ? jointOf(j) : null;
  }

  // A root edit, on both views (the right panel shows the same forest; on a
  // rig it shows the rig's, which a root edit of the source leaves as it is).
  async edit(kind, args) {
    for (const key of this.rig === null ? ['world', 'joint'] : ['world']) {
      const reply = await this.socket.ask({ [kind]: { viewId: this.views[key].viewId, ...args } });
      this.views[key] = reply.view;
    }
    this.showJoint();
    this.refreshRoots();
  }

  async setViewpoint(joint) {
    const view = this.views.joint;
    if (!view) return;
    await this.unsubscribe('joint');
    this.panels.joint.clear();
    this.viewpoint = joint;
    if (!joint) {
      $('joint-caption').textContent = JOINT_CAPTION;
      this.showJoint();
      return;
    }
    this.views.joint = (await this.socket.ask({ setCoordinates: { viewId: view.viewId, relativeTo: joint } })).view;
    $('joint-caption').textContent = `From ${joint} (its bone frame; axes: x red, y green, z blue)`;
    await this.subscribe('joint', this.currentFrame());
    this.showJoint();
  }

  // The right panel shows the motion on another library motion's skeleton
  // (the server retargets a view of it, docs/retarget.md), beside the source;
  // '' brings back the view from a joint.
  async setRig(name) {
    if (!this.motion) return;
    await this.unsubscribe('joint');
    this.panels.joint.clear();
    if (this.views.joint) await this.socket.ask({ closeView: { viewId: this.views.joint.viewId } }).catch(() => {});
    this.views.joint = null;
    this.viewpoint = null;
    $('viewpoint').checked = false;
    this.rig = null;
    $('joint-caption').textContent = JOINT_CAPTION;
    // A fresh view of the source with the left panel's roots (a rig keeps its own).
    let view = (await this.socket.ask({ createView: { motion: this.motion.name } })).view;
    const roots = this.views.world.skeleton.joints.map(jointOf).filter((j) => j.parent < 0).map((j) => j.name);
    view = (await this.socket.ask({ setRoots: { viewId: view.viewId, roots } })).view;
    this.views.joint = view;
    if (name) {
      try {
        const rig = (await this.socket.ask({ getSkeleton: { motion: name } })).skeleton.skeleton;
        this.views.joint = (await this.socket.ask({ retarget: { viewId: view.viewId, target: rig } })).view;
      } catch (e) {
        $('rig').value = '';
        this.showJoint();
        throw new Error(`cannot put ${this.motion.name} on ${name}: ${e.message}`);
      }
      this.rig = name;
      $('message').textContent = '';
      $('joint-caption').textContent = `On ${name}'s skeleton (retargeted by the server)`;
      await this.subscribe('joint', this.currentFrame());
    }
    this.showJoint();
  }

  refreshRoots() {
    const ul = $('roots');
    ul.replaceChildren();
    const joints = this.views.world ? this.views.world.skeleton.joints.map(jointOf) : [];
    for (const j of joints) {
      if (j.parent >= 0) continue;
      const li = document.createElement('li');
      li.textContent = j.name;
      if (j.softParent >= 0) {
        const soft = document.createElement('span');
        soft.className = 'soft';
        soft.textContent = ` (soft link to ${joints[j.softParent].name})`;
        li.append(soft);
      }
      ul.append(li);
    }
    $('fig-version').textContent = String(this.views.world ? this.views.world.skeletonVersion || 0 : '–');
  }

  push(m) {
    if (m.frame) return this.onFrame(m.frame);
    if (m.skeletonChanged) return this.onSkeletonChanged(m.skeletonChanged);
    if (m.subscriptionEnded) {
      const e = m.subscriptionEnded;
      for (const key of ['world', 'joint']) {
        if (this.subs[key] && this.subs[key].subscriptionId === e.subscriptionId) {
          this.subs[key] = null;
          if (key === 'world') $('message').textContent = `stream ended: ${e.reason || ''}`;
        }
      }
      return;
    }
    if (m.error) this.fail(new Error(`${m.error.code}: ${m.error.message}`));
  }

  keyOf(subscriptionId) {
    for (const key of ['world', 'joint']) if (this.subs[key] && this.subs[key].subscriptionId === subscriptionId) return key;
    return null;
  }

  onSkeletonChanged(c) {
    const key = this.keyOf(c.subscriptionId);
    if (!key) return;
    const joints = c.skeleton ? c.skeleton.joints : this.views[key].skeleton.joints;
    this.subs[key].joints = c.joints || [];
    this.subs[key].skeletonVersion = c.skeletonVersion || 0;
    this.panels[key].setSkeleton(joints.map(jointOf), c.joints || [], c.skeletonVersion || 0);
    this.panels[key].paint(this.selected);
  }

  onFrame(f) {
    const key = this.keyOf(f.subscriptionId);
    if (!key) return;
    const panel = this.panels[key];
    if ((f.skeletonVersion || 0) !== panel.version) return;  // its SkeletonChanged comes first
    const frame = Number(f.frameIndex || 0);
    const latency = f.serverSendTimeNs ? Date.now() - (Number(f.serverSendTimeNs) / 1e6 - this.socket.clockOffsetMs) : 0;
    // A page that fell behind (a busy tab) skips what waited past the
    // staleness bound, as the other clients do, and so catches up.
    const stale = latency > STALENESS_MS;
    if (!stale) panel.setFrame(f.positionsF64 || f.positions || [], frame);
    if (key !== 'world') return;
    const seq = Number(f.sequence || 0);
    const last = this.figures.lastSeq.get(f.subscriptionId);
    if (last !== undefined && seq > last + 1) this.figures.drops += seq - last - 1;
    this.figures.lastSeq.set(f.subscriptionId, seq);
    this.figures.frames++;
    if (stale) this.figures.stale++;
    if (f.serverSendTimeNs) {
      this.figures.latencies.push(latency);
      if (this.figures.latencies.length > 120) this.figures.latencies.shift();
    }
    if (stale) return;
    if (document.activeElement !== $('seek')) $('seek').value = String(frame);
    $('frame-label').textContent = this.frameLabel(frame);
    $('fig-frame').textContent = String(frame);
    $('fig-version').textContent = String(f.skeletonVersion || 0);
  }

  tickFigures() {
    const now = performance.now();
    const f = this.figures;
    if (now - f.windowStart < 1000) return;
    f.fps = (f.frames * 1000) / (now - f.windowStart);
    f.frames = 0;
    f.windowStart = now;
    $('fig-fps').textContent = f.fps.toFixed(1);
    const sorted = [...f.latencies].sort((a, b) => a - b);
    $('fig-latency').textContent = sorted.length ? `${sorted[Math.floor(sorted.length / 2)].toFixed(1)} ms (median)` : '–';
    $('fig-drops').textContent = String(f.drops);
    $('fig-stale').textContent = String(f.stale);
  }
}

// A Joint of the JSON mapping, with its defaults (JSON leaves zeros out).
function jointOf(j) {
  return { name: j.name, parent: j.parent ?? 0, softParent: j.softParent ?? 0 };
}

const viewer = new Viewer();
window.gmrViewer = {
  viewer,
  // Everything the test reads back: the connection, the views and what each panel has drawn.
  state() {
    return {
      connected: viewer.connected,
      errors: viewer.errors,
      motions: viewer.motions.map((m) => m.name),
      motion: viewer.motion && viewer.motion.name,
      selected: viewer.selected,
      viewpoint: viewer.viewpoint,
      rig: viewer.rig,
      roots: viewer.views.world ? viewer.views.world.skeleton.joints.map(jointOf).filter((j) => j.parent < 0).map((j) => j.name) : [],
      figures: { fps: viewer.figures.fps, drops: viewer.figures.drops, stale: viewer.figures.stale },
      world: viewer.panels.world.drawn(),
      joint: viewer.panels.joint.drawn(),
    };
  },
  screenPosition(panel, joint) { return viewer.panels[panel].screenPosition(joint); },
};
viewer.start();
