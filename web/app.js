// SODA view: draws the committed frames `soda view` sends (docs/formats.md "Viewer frames")
// with three.js, and sends the user's acts back as JSON messages.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/OrbitControls.js';

const HEADER = 64, WORLD = 24, BODY = 52;
const $ = (id) => document.getElementById(id);

// What tests and curious users can read: window.soda.
const soda = {
  scene: null, frames: 0, shown: null, outcomes: [], saved: null, selected: null,
  socket: null, ids: [],
  drawMs: 0, renderMs: 0,   // the page's own cost per frame: decoding and instancing, and WebGL
};
window.soda = soda;

// --- three.js scene ---------------------------------------------------------------------
const host = $('view');
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
host.appendChild(renderer.domElement);
const world3 = new THREE.Scene();
world3.background = new THREE.Color(0x1a2027);
const camera = new THREE.PerspectiveCamera(50, 1, 0.05, 2000);
const controls = new OrbitControls(camera, renderer.domElement);
controls.enableDamping = true;
world3.add(new THREE.HemisphereLight(0xdde6ff, 0x30302a, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(0.4, 1, 0.3);
world3.add(sun);

const boxGeometry = new THREE.BoxGeometry(2, 2, 2);
const ballGeometry = new THREE.SphereGeometry(1, 16, 12);
const bodyMaterial = new THREE.MeshLambertMaterial({ color: 0xffffff });
let boxes = null, balls = null;           // InstancedMesh, grown as needed
let boxIds = [], ballIds = [];            // instance index -> body id
let flashMesh = null;                     // cells flashing after a rollback
const flash = new Map();                  // cell -> intensity
let lastRecomputes = null, lastOwners = null;   // per cell, in the frame drawn before

// World colours, made once per (world, asleep): a frame of 8,000 bodies allocates none.
const colours = new Map();
function palette(world, worlds, asleep) {
  const key = world * 2 + (asleep ? 1 : 0);
  let c = colours.get(key);
  if (!c) {
    c = new THREE.Color();
    if (world === 0xffff) c.setRGB(0.5, 0.5, 0.5);
    else c.setHSL(((world * 0.61803398875) % 1 + 1) % 1, 0.65, asleep ? 0.38 : 0.55);
    colours.set(key, c);
  }
  return c;
}

function instanced(geometry, capacity) {
  const m = new THREE.InstancedMesh(geometry, bodyMaterial, capacity);
  m.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
  m.setColorAt(0, new THREE.Color());
  m.count = 0;
  m.frustumCulled = false;
  world3.add(m);
  return m;
}

function ensureCapacity(mesh, geometry, n) {
  if (mesh && mesh.instanceMatrix.count >= n) return mesh;
  if (mesh) { world3.remove(mesh); mesh.dispose(); }
  return instanced(geometry, Math.max(64, Math.ceil(n * 1.5)));
}

function setUpScene(s) {
  soda.scene = s;
  $('scene').textContent = `${s.name} (${s.bodies} bodies)`;
  $('executor').textContent = `${s.executor}, ${s.worlds} world${s.worlds === 1 ? '' : 's'}`;
  const min = new THREE.Vector3(...s.domain.min), max = new THREE.Vector3(...s.domain.max);
  const size = new THREE.Vector3().subVectors(max, min), centre = new THREE.Vector3().addVectors(min, max).multiplyScalar(0.5);
  const domain = new THREE.LineSegments(
    new THREE.EdgesGeometry(new THREE.BoxGeometry(size.x, size.y, size.z)),
    new THREE.LineBasicMaterial({ color: 0x55606b }));
  domain.position.copy(centre);
  world3.add(domain);
  if (s.ground !== null && s.ground !== undefined) {
    const g = new THREE.Mesh(new THREE.PlaneGeometry(size.x * 1.5, size.z * 1.5),
      new THREE.MeshLambertMaterial({ color: 0x3b4550 }));
    g.rotation.x = -Math.PI / 2;
    g.position.set(centre.x, s.ground, centre.z);
    g.name = 'ground';
    world3.add(g);
  }
  if (s.walls) {
    const wm = new THREE.MeshLambertMaterial({ color: 0x6b7a88, transparent: true, opacity: 0.12, side: THREE.DoubleSide });
    for (const [w, h, x, z, ry] of [
      [size.x, size.y, centre.x, min.z, 0], [size.x, size.y, centre.x, max.z, 0],
      [size.z, size.y, min.x, centre.z, Math.PI / 2], [size.z, size.y, max.x, centre.z, Math.PI / 2]]) {
      const wall = new THREE.Mesh(new THREE.PlaneGeometry(w, h), wm);
      wall.position.set(x, centre.y, z);
      wall.rotation.y = ry;
      world3.add(wall);
    }
  }
  for (const c of s.cuboids) {
    const m = new THREE.Mesh(new THREE.BoxGeometry(2 * c.half_extents[0], 2 * c.half_extents[1], 2 * c.half_extents[2]),
      new THREE.MeshLambertMaterial({ color: 0x8a8f96 }));
    m.position.set(...c.position);
    m.quaternion.set(...c.rotation);
    world3.add(m);
  }
  const e = s.grid.edge;
  flashMesh = new THREE.InstancedMesh(new THREE.BoxGeometry(e, e, e),
    new THREE.MeshBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.35, depthWrite: false, blending: THREE.AdditiveBlending }),
    s.grid.dims[0] * s.grid.dims[1] * s.grid.dims[2]);
  flashMesh.count = 0;
  flashMesh.frustumCulled = false;
  world3.add(flashMesh);
  const radius = size.length() * 0.45;
  camera.position.set(centre.x + radius, (s.ground ?? min.y) + radius * 0.8, centre.z + radius * 1.2);
  controls.target.set(centre.x, (s.ground ?? min.y) + Math.min(size.y, size.x) * 0.2, centre.z);
  controls.update();
}

// --- frames -------------------------------------------------------------------------------
let pending = null;     // the latest frame received, not yet drawn

function decode(buffer) {
  const v = new DataView(buffer);
  const magic = String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3));
  if (magic !== 'SODF' || v.getUint16(4, true) !== 2) throw new Error('not a SODA frame of version 2');
  const f = {
    step: v.getFloat64(8, true),
    hash: v.getUint32(20, true).toString(16).padStart(8, '0') + v.getUint32(16, true).toString(16).padStart(8, '0'),
    gvt: v.getFloat64(24, true),
    buffered: v.getUint32(32, true), starved: v.getUint32(36, true),
    rate: v.getFloat32(40, true), speed: v.getFloat32(44, true),
    bodies: v.getUint32(48, true), worlds: v.getUint32(52, true), cells: v.getUint32(56, true),
    paused: v.getUint32(60, true) === 1,
    lvt: [], rollbacks: [], recomputed: [],
  };
  let at = HEADER;
  for (let w = 0; w < f.worlds; w++, at += WORLD) {
    f.lvt.push(v.getFloat64(at, true));
    f.rollbacks.push(v.getFloat64(at + 8, true));
    f.recomputed.push(v.getFloat64(at + 16, true));
  }
  f.owners = new Uint16Array(buffer, at, f.cells);
  at += Math.ceil(f.cells * 2 / 4) * 4;
  f.recomputes = new Uint32Array(buffer, at, f.cells);
  at += f.cells * 4;
  f.bodyOffset = at;
  f.view = v;
  return f;
}

const m4 = new THREE.Matrix4(), pos = new THREE.Vector3(), quat = new THREE.Quaternion(), scl = new THREE.Vector3();
const white = new THREE.Color(0xffffff);

function draw(f) {
  const v = f.view;
  let nb = 0, nl = 0;
  for (let i = 0, at = f.bodyOffset; i < f.bodies; i++, at += BODY) if (v.getUint8(at + 10) === 1) nb++; else nl++;
  boxes = ensureCapacity(boxes, boxGeometry, nb);
  balls = ensureCapacity(balls, ballGeometry, nl);
  boxIds = new Array(nb); ballIds = new Array(nl);
  const ids = new Array(f.bodies);
  let ib = 0, il = 0;
  for (let i = 0, at = f.bodyOffset; i < f.bodies; i++, at += BODY) {
    const id = v.getUint32(at + 4, true) * 4294967296 + v.getUint32(at, true);
    ids[i] = id;
    const world = v.getUint16(at + 8, true), kind = v.getUint8(at + 10), asleep = v.getUint8(at + 11) === 1;
    pos.set(v.getFloat32(at + 12, true), v.getFloat32(at + 16, true), v.getFloat32(at + 20, true));
    quat.set(v.getFloat32(at + 24, true), v.getFloat32(at + 28, true), v.getFloat32(at + 32, true), v.getFloat32(at + 36, true));
    scl.set(v.getFloat32(at + 40, true), v.getFloat32(at + 44, true), v.getFloat32(at + 48, true));
    m4.compose(pos, quat, scl);
    const colour = id === soda.selected ? white : palette(world, f.worlds, asleep);
    if (kind === 1) { boxes.setMatrixAt(ib, m4); boxes.setColorAt(ib, colour); boxIds[ib++] = id; }
    else { balls.setMatrixAt(il, m4); balls.setColorAt(il, colour); ballIds[il++] = id; }
  }
  soda.ids = ids;
  for (const m of [boxes, balls]) {
    m.count = m === boxes ? ib : il;
    m.instanceMatrix.needsUpdate = true;
    if (m.instanceColor) m.instanceColor.needsUpdate = true;
  }
  // A cell flashes when a rollback reached it since the frame drawn before: its count of
  // re-executed computations grew (a cell that changed owner restarts its count: no flash).
  if (lastRecomputes && lastRecomputes.length === f.cells) {
    for (let c = 0; c < f.cells; c++) {
      if (f.recomputes[c] > lastRecomputes[c] && f.owners[c] === lastOwners[c]) flash.set(c, 1);
    }
  }
  lastRecomputes = f.recomputes.slice();
  lastOwners = f.owners.slice();
  drawFlashes();
  drawPanel(f);
  drawTimeline(f);
}

function drawFlashes() {
  if (!flashMesh) return;
  const dims = soda.scene.grid.dims, gmin = soda.scene.grid.min, e = soda.scene.grid.edge;
  let n = 0;
  const c = new THREE.Color();
  for (const [cell, k] of flash) {
    if (k < 0.05) { flash.delete(cell); continue; }
    const x = cell % dims[0], y = Math.floor(cell / dims[0]) % dims[1], z = Math.floor(cell / (dims[0] * dims[1]));
    m4.makeTranslation(gmin[0] + (x + 0.5) * e, gmin[1] + (y + 0.5) * e, gmin[2] + (z + 0.5) * e);
    flashMesh.setMatrixAt(n, m4);
    flashMesh.setColorAt(n, c.setRGB(k, 0.25 * k, 0.1 * k));
    flash.set(cell, k * 0.85);
    n++;
  }
  flashMesh.count = n;
  flashMesh.instanceMatrix.needsUpdate = true;
  if (flashMesh.instanceColor) flashMesh.instanceColor.needsUpdate = true;
}

function drawPanel(f) {
  soda.shown = { step: f.step, hash: f.hash, gvt: f.gvt, buffered: f.buffered, paused: f.paused };
  $('step').textContent = f.step;
  $('hash').textContent = f.hash;
  $('gvt').textContent = soda.scene.worlds > 1 || soda.scene.executor !== 'reference' ? `${f.gvt} (${f.gvt - f.step} ahead)` : 'reference: none';
  $('rate').textContent = `${f.rate.toFixed(1)} frames/s, page ${pageRate.toFixed(0)} fps (draw ${soda.drawMs.toFixed(1)} ms, render ${soda.renderMs.toFixed(1)} ms)`;
  const seconds = f.buffered / (soda.scene.fps * f.speed);
  $('buffer').textContent = `${f.buffered} frames, ${seconds.toFixed(2)} s`;
  $('starved').textContent = `${f.starved} ticks`;
  $('bodies').textContent = f.bodies;
  $('speed').textContent = `${+f.speed.toFixed(3)}×`;
  $('pause').textContent = f.paused ? 'resume' : 'pause';
}

// The timeline: each world's LVT as a bar ahead of the step shown, GVT as a line, and a
// flash where a world rolled back.
const timeline = $('timeline');
const rowFlash = [];
function drawTimeline(f) {
  const ctx = timeline.getContext('2d');
  const w = timeline.width = timeline.clientWidth, h = timeline.height = timeline.clientHeight;
  ctx.fillStyle = '#0b0e11'; ctx.fillRect(0, 0, w, h);
  const ahead = Math.max(f.gvt, ...f.lvt) - f.step;
  const span = Math.max(8, ahead * 1.2, soda.scene.buffer * 1.1);
  const x = (step) => 60 + (w - 70) * Math.min(1, Math.max(0, (step - f.step) / span));
  const rows = Math.max(1, f.worlds), rh = Math.max(2, Math.min(14, (h - 22) / rows));
  ctx.font = '11px system-ui'; ctx.fillStyle = '#9aa4ae';
  ctx.fillText(`step ${f.step}`, 4, 12);
  for (let i = 0; i < f.worlds; i++) {
    if (lastTimeline && f.rollbacks[i] > lastTimeline[i]) rowFlash[i] = 1;
    const y = 18 + i * rh;
    ctx.fillStyle = `#${palette(i, f.worlds, false).getHexString()}`;
    ctx.fillRect(x(f.step), y, Math.max(1, x(f.lvt[i]) - x(f.step)), rh - 1);
    if (rowFlash[i] > 0.05) {
      ctx.fillStyle = `rgba(255, 70, 40, ${rowFlash[i]})`;
      ctx.fillRect(0, y, 56, rh - 1);
      rowFlash[i] *= 0.85;
    }
    if (rh >= 9) { ctx.fillStyle = '#9aa4ae'; ctx.fillText(`w${i}`, 4, y + rh - 2); }
  }
  lastTimeline = f.rollbacks.slice();
  ctx.strokeStyle = '#ffffff'; ctx.beginPath(); ctx.moveTo(x(f.gvt), 14); ctx.lineTo(x(f.gvt), h); ctx.stroke();
  ctx.fillStyle = '#ffffff'; ctx.fillText(`GVT ${f.gvt}`, Math.min(w - 60, x(f.gvt) + 3), 12);
  ctx.strokeStyle = '#4aa3ff'; ctx.beginPath(); ctx.moveTo(x(f.step + f.buffered), 14); ctx.lineTo(x(f.step + f.buffered), h); ctx.stroke();
}
let lastTimeline = null;

// --- connection -------------------------------------------------------------------------------
function say(text) { $('message').textContent = text; }

function connect() {
  const socket = new WebSocket(`ws://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  soda.socket = socket;
  socket.onmessage = (e) => {
    if (typeof e.data === 'string') {
      const m = JSON.parse(e.data);
      if (m.type === 'scene') { if (!soda.scene) setUpScene(m); return; }
      soda.outcomes.push(m);
      if (m.type === 'stamped') say(`${m.action} body ${m.id} at step ${m.step} (${m.logged} inputs logged)`);
      else if (m.type === 'rejected') say(`refused: ${m.reason}`);
      else if (m.type === 'saved') { soda.saved = m; say(`saved at step ${m.step}, hash ${m.hash}:\n${m.command}`); }
      return;
    }
    try { pending = decode(e.data); soda.frames++; } catch (err) { say(String(err)); }
  };
  socket.onclose = () => setTimeout(connect, 1000);
}
function send(message) {
  if (soda.socket && soda.socket.readyState === WebSocket.OPEN) soda.socket.send(JSON.stringify(message));
}
soda.send = send;
soda.pause = () => send({ type: 'pause' });
soda.resume = () => send({ type: 'resume' });
soda.save = () => send({ type: 'save' });
let speed = 1;
function setSpeed(s) { speed = Math.min(16, Math.max(1 / 16, s)); send({ type: 'speed', value: speed }); }
$('pause').onclick = () => (soda.shown && soda.shown.paused ? soda.resume() : soda.pause());
$('slower').onclick = () => setSpeed(speed / 2);
$('faster').onclick = () => setSpeed(speed * 2);
$('save').onclick = () => soda.save();

// --- picking ----------------------------------------------------------------------------------
const raycaster = new THREE.Raycaster();
const pointer = new THREE.Vector2();
function pick(event) {
  const r = renderer.domElement.getBoundingClientRect();
  pointer.set(((event.clientX - r.left) / r.width) * 2 - 1, -((event.clientY - r.top) / r.height) * 2 + 1);
  raycaster.setFromCamera(pointer, camera);
  const targets = [boxes, balls].filter(Boolean);
  const ground = world3.getObjectByName('ground');
  if (ground) targets.push(ground);
  const hit = raycaster.intersectObjects(targets, false)[0];
  if (!hit) return { ray: raycaster.ray.direction.clone() };
  let id = null;
  if (hit.object === boxes) id = boxIds[hit.instanceId];
  else if (hit.object === balls) id = ballIds[hit.instanceId];
  return { id, point: hit.point, ray: raycaster.ray.direction.clone() };
}
let down = null;
renderer.domElement.addEventListener('pointerdown', (e) => { down = { x: e.clientX, y: e.clientY }; });
renderer.domElement.addEventListener('pointerup', (e) => {
  if (!down || Math.hypot(e.clientX - down.x, e.clientY - down.y) > 5) return;   // an orbit drag
  const p = pick(e);
  if (e.shiftKey) {
    const at = p.point || camera.position.clone().add(p.ray.multiplyScalar(10));
    send({ type: 'spawn', position: [at.x, at.y + 1.5, at.z] });
  } else if (p.id !== null && p.id !== undefined) {
    soda.selected = p.id;
    const d = p.ray; d.y = Math.max(d.y, 0.15);
    send({ type: 'push', id: p.id, direction: [d.x, d.y, d.z], speed: 4 });
  } else {
    soda.selected = null;
  }
});
window.addEventListener('keydown', (e) => {
  if ((e.key === 'Delete' || e.key === 'Backspace') && soda.selected !== null) {
    send({ type: 'remove', id: soda.selected });
    soda.selected = null;
  } else if (e.key === ' ') { $('pause').click(); e.preventDefault(); }
  else if (e.key === '+' || e.key === '=') setSpeed(speed * 2);
  else if (e.key === '-') setSpeed(speed / 2);
});

// Where body `id` appears on the page, in CSS pixels (for tests and scripted demos).
soda.screenPointOf = (id) => {
  for (const [mesh, ids] of [[boxes, boxIds], [balls, ballIds]]) {
    if (!mesh) continue;
    const k = ids.indexOf(id);
    if (k < 0) continue;
    mesh.getMatrixAt(k, m4);
    const p = new THREE.Vector3().setFromMatrixPosition(m4).project(camera);
    const r = renderer.domElement.getBoundingClientRect();
    return { x: r.left + (p.x + 1) / 2 * r.width, y: r.top + (1 - p.y) / 2 * r.height, depth: p.z };
  }
  return null;
};

// --- render loop ------------------------------------------------------------------------------
let pageRate = 0, lastTime = performance.now();
function resize() {
  const w = host.clientWidth, h = host.clientHeight;
  renderer.setSize(w, h, false);
  renderer.domElement.style.width = `${w}px`; renderer.domElement.style.height = `${h}px`;
  camera.aspect = w / Math.max(1, h); camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);
resize();
function loop(now) {
  const dt = now - lastTime; lastTime = now;
  pageRate = pageRate * 0.9 + (dt > 0 ? 1000 / dt : 0) * 0.1;
  if (pending && soda.scene) {
    const t0 = performance.now();
    draw(pending);
    pending = null;
    soda.drawMs = soda.drawMs * 0.9 + (performance.now() - t0) * 0.1;
  }
  controls.update();
  const r0 = performance.now();
  renderer.render(world3, camera);
  soda.renderMs = soda.renderMs * 0.9 + (performance.now() - r0) * 0.1;
  requestAnimationFrame(loop);
}
requestAnimationFrame(loop);
connect();
