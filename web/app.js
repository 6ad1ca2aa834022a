// SODA view: draws the committed frames `soda view` sends (docs/formats.md "Viewer frames")
// with three.js, and sends the user's acts back as JSON messages.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/OrbitControls.js';
import { Occlusion } from './occlusion.js';

const HEADER = 64, WORLD = 24, BODY = 52;
const $ = (id) => document.getElementById(id);

// What tests and curious users can read: window.soda.
const soda = {
  scene: null, frames: 0, shown: null, outcomes: [], saved: null, selected: null,
  socket: null, ids: [],
  drawMs: 0, renderMs: 0,   // the page's own cost per frame: decoding, culling and vertex writing; WebGL
  // Bodies and box faces the camera cannot see are not sent to the GL (web/occlusion.js);
  // `?cull=0` sends them all. `drawn`, `triangles`: how many were sent last time.
  cull: new URLSearchParams(location.search).get('cull') !== '0', drawn: 0, triangles: 0,
  lod: new URLSearchParams(location.search).get('lod') !== '0',   // coarser balls when small (BALL_LEVELS)
};
window.soda = soda;

// --- three.js scene ---------------------------------------------------------------------
const host = $('view');
// No multisampling, at most one pixel per CSS pixel (times the render scale, below): a
// software GL draws every pixel on the CPU.
const renderer = new THREE.WebGLRenderer({ antialias: false, powerPreference: 'high-performance' });
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

// Bodies are drawn as one mesh per shape whose vertices and colours the page writes for
// every frame, lit on the CPU, with an unlit material: software GL (SwiftShader, a machine
// without a GPU) pays per instance drawn and per pixel shaded, and 8,000 instanced, per-pixel
// lit cubes took ~300 ms a frame (docs/performance.md, "The viewer page"). A box is its 8
// corners, each face coloured by the light it gets through one corner that belongs to it
// alone (a `flat` colour, taken from a triangle's last vertex); a ball is a low-poly
// icosahedron (42 vertices, 80 triangles) lit per vertex, or, small on the screen, a coarser
// one: BALL_LEVELS.
const boxShape = boxWithFaceCorners();
// A ball's shapes by its radius on the canvas (in its pixels): an icosahedron split once from
// 5 pixels up, the icosahedron (12 vertices, 20 triangles) from 2, an octahedron (6, 8) below,
// each as large in outline as the first (asLarge); `?lod=0` draws every ball the finest way.
const fineBall = weld(new THREE.IcosahedronGeometry(1, 1));
const BALL_LEVELS = [
  { shape: fineBall, pixels: 5 },
  { shape: asLarge(weld(new THREE.IcosahedronGeometry(1, 0)), fineBall), pixels: 2 },
  { shape: asLarge(weld(new THREE.OctahedronGeometry(1, 0)), fineBall), pixels: 0 },
];
const boxMaterial = new THREE.MeshBasicMaterial({ vertexColors: true });
boxMaterial.onBeforeCompile = (shader) => {
  shader.vertexShader = shader.vertexShader.replace('#include <color_pars_vertex>', 'flat varying vec3 vColor;');
  shader.fragmentShader = shader.fragmentShader.replace('#include <color_pars_fragment>', 'flat varying vec3 vColor;');
};
const ballMaterial = new THREE.MeshBasicMaterial({ vertexColors: true });
// Bodies of each kind, grown as needed: boxes, then balls by level of detail.
const KINDS = [boxShape, ...BALL_LEVELS.map((l) => l.shape)];
const sets = KINDS.map(() => null);
let flashMesh = null;                     // cells flashing after a rollback
const flash = new Map();                  // cell -> intensity
let lastRecomputes = null, lastOwners = null;   // per cell, in the frame drawn before

// The scene's lights (above) as MeshLambertMaterial applies them (three.js r170, linear
// light): colour × (hemisphere(n) · 1.6 + sun · 1.8 · max(0, n·l)) / π, hemisphere(n) =
// earth + (sky − earth)(n_y + 1)/2; LIGHT holds the constants per channel.
const SKY = new THREE.Color(0xdde6ff), EARTH = new THREE.Color(0x30302a);
const SUN = new THREE.Vector3(0.4, 1, 0.3).normalize();
const byte = (x) => (x >= 1 ? 255 : x <= 0 ? 0 : (x * 255 + 0.5) | 0);

// A box's 8 corners (±1) and 12 triangles, counter-clockwise seen from outside; each face's
// two triangles end at the corner `face[f]` that stands for face f (faces ±x, ±y, ±z).
function boxWithFaceCorners() {
  const corners = [], axes = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]];
  for (let k = 0; k < 8; k++) corners.push(k & 1 ? 1 : -1, k & 2 ? 1 : -1, k & 4 ? 1 : -1);
  const on = (k, n) => n.every((x, i) => x === 0 || corners[k * 3 + i] === x);
  const face = [];   // distinct corners, one per face (a matching: each corner is on 3 faces)
  (function pick(f, used) {
    if (f === 6) return true;
    for (let k = 0; k < 8; k++) {
      if (used & (1 << k) || !on(k, axes[f])) continue;
      face[f] = k;
      if (pick(f + 1, used | (1 << k))) return true;
    }
    return false;
  })(0, 0);
  const triangles = [];
  axes.forEach((n, f) => {
    // The face's corners around its normal, starting from face[f].
    const ring = [0, 1, 2, 3, 4, 5, 6, 7].filter((k) => on(k, n));
    const u = n[0] !== 0 ? 1 : 0, v = n[2] !== 0 ? 1 : 2;   // two axes in the face's plane
    const angle = (k) => Math.atan2(corners[k * 3 + v], corners[k * 3 + u]);
    ring.sort((a, b) => angle(a) - angle(b));
    while (ring[0] !== face[f]) ring.push(ring.shift());
    const [p, q, r, t] = ring;
    const ccw = (a, b, c) => {   // (b − a) × (c − a) · n > 0
      const A = [0, 1, 2].map((i) => corners[b * 3 + i] - corners[a * 3 + i]);
      const B = [0, 1, 2].map((i) => corners[c * 3 + i] - corners[a * 3 + i]);
      return (A[1] * B[2] - A[2] * B[1]) * n[0] + (A[2] * B[0] - A[0] * B[2]) * n[1] + (A[0] * B[1] - A[1] * B[0]) * n[2] > 0;
    };
    if (ccw(q, r, p)) triangles.push(q, r, p, r, t, p);
    else triangles.push(t, r, p, r, q, p);
  });
  return { corners: new Float32Array(corners), vertices: 8, triangles, face };
}

// A shape's distinct corners and its triangles over them.
function weld(geometry) {
  const p = geometry.getAttribute('position'), corners = [], index = [], seen = new Map();
  for (let i = 0; i < p.count; i++) {
    const key = `${p.getX(i).toFixed(4)},${p.getY(i).toFixed(4)},${p.getZ(i).toFixed(4)}`;
    let k = seen.get(key);
    if (k === undefined) { k = corners.length / 3; seen.set(key, k); corners.push(p.getX(i), p.getY(i), p.getZ(i)); }
    index.push(k);
  }
  const triangles = geometry.index ? Array.from(geometry.index.array, (i) => index[i]) : index;
  geometry.dispose();
  return { corners: new Float32Array(corners), normals: new Float32Array(corners), vertices: corners.length / 3, triangles, face: null, extent: 1 };
}

// The ball `shape` (corners on the unit sphere) grown to the surface area of `like`: a convex
// body's outline has on average a quarter of its surface's area (Cauchy), so a coarse ball
// covers as many pixels as the fine one, where an inscribed octahedron looks thin. Normals
// stay those of the sphere.
function asLarge(shape, like) {
  const area = (s) => {
    let a = 0;
    const c = s.corners, t = s.triangles, v = new THREE.Vector3(), u = new THREE.Vector3(), w = new THREE.Vector3();
    for (let j = 0; j < t.length; j += 3) {
      v.fromArray(c, t[j] * 3); u.fromArray(c, t[j + 1] * 3).sub(v); w.fromArray(c, t[j + 2] * 3).sub(v);
      a += u.cross(w).length() / 2;
    }
    return a;
  };
  const k = Math.sqrt(area(like) / area(shape));
  return { ...shape, corners: shape.corners.map((x) => x * k), extent: k };
}

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

// The bodies of one shape: capacity bodies, `count` drawn, slot k's vertices at k·vertices.
// A box's triangles are listed face by face, only the faces to draw (place's `faces`).
class Bodies {
  constructor(shape, material, capacity) {
    const v = shape.vertices, t = shape.triangles;
    this.shape = shape;
    this.capacity = capacity;
    this.count = 0;
    this.ids = new Float64Array(capacity);          // slot -> body id
    this.centres = new Float32Array(capacity * 3);  // slot -> position (picking, screenPointOf)
    const geometry = new THREE.BufferGeometry();
    const positions = new THREE.BufferAttribute(new Float32Array(capacity * v * 3), 3);
    positions.setUsage(THREE.DynamicDrawUsage);
    const colors = new THREE.BufferAttribute(new Uint8Array(capacity * v * 3), 3, true);
    colors.setUsage(THREE.DynamicDrawUsage);
    const index = new (capacity * v > 65535 ? Uint32Array : Uint16Array)(capacity * t.length);
    for (let k = 0, at = 0; k < capacity; k++) for (const i of t) index[at++] = k * v + i;
    geometry.setAttribute('position', positions);
    geometry.setAttribute('color', colors);
    const indices = new THREE.BufferAttribute(index, 1);
    indices.setUsage(THREE.DynamicDrawUsage);
    geometry.setIndex(indices);
    geometry.setDrawRange(0, 0);
    this.positions = positions; this.colors = colors; this.indices = indices;
    this.listed = 0;   // indices listed so far in this frame
    this.mesh = new THREE.Mesh(geometry, material);
    this.mesh.frustumCulled = false;
    world3.add(this.mesh);
  }
  dispose() { world3.remove(this.mesh); this.mesh.geometry.dispose(); }
  // Writes slot k: the shape scaled by (sx, sy, sz), rotated by r[at..at + 9] (rotationOf),
  // moved to (px, py, pz), coloured `colour` as lit; a box lists its faces in the bits of
  // `faces` (1 << f for f = +x, −x, +y, −y, +z, −z; Occlusion.faces).
  place(k, px, py, pz, r, at, sx, sy, sz, colour, faces) {
    const r0 = r[at], r1 = r[at + 1], r2 = r[at + 2], r4 = r[at + 3], r5 = r[at + 4], r6 = r[at + 5];
    const r8 = r[at + 6], r9 = r[at + 7], r10 = r[at + 8];
    const m0 = r0 * sx, m1 = r1 * sx, m2 = r2 * sx, m4 = r4 * sy, m5 = r5 * sy, m6 = r6 * sy;
    const m8 = r8 * sz, m9 = r9 * sz, m10 = r10 * sz;
    const c = this.shape.corners, out = this.positions.array, col = this.colors.array, n = this.shape.vertices;
    for (let i = 0, o = k * n * 3; i < n * 3; i += 3, o += 3) {
      const x = c[i], y = c[i + 1], z = c[i + 2];
      out[o] = m0 * x + m4 * y + m8 * z + px;
      out[o + 1] = m1 * x + m5 * y + m9 * z + py;
      out[o + 2] = m2 * x + m6 * y + m10 * z + pz;
    }
    const face = this.shape.face, cr = colour.r, cg = colour.g, cb = colour.b;
    const t = this.shape.triangles, index = this.indices.array;
    if (face) {
      // Face f's two triangles are t[6f..6f + 6].
      for (let f = 0; f < 6; f++) {
        if (!(faces & (1 << f))) continue;
        for (let j = f * 6; j < f * 6 + 6; j++) index[this.listed++] = k * n + t[j];
      }
    } else {
      this.listed += t.length;   // a ball's triangles stay where the constructor listed them
    }
    if (face) {
      // Face f's normal is ± a rotation column; its colour goes on its own corner.
      for (let f = 0; f < 6; f++) {
        const s = f & 1 ? -1 : 1, a = f >> 1;
        const nx = s * (a === 0 ? r0 : a === 1 ? r4 : r8), ny = s * (a === 0 ? r1 : a === 1 ? r5 : r9), nz = s * (a === 0 ? r2 : a === 1 ? r6 : r10);
        const w = 0.5 * ny + 0.5, d = Math.max(0, nx * SUN.x + ny * SUN.y + nz * SUN.z) * LIGHT.sun;
        const o = (k * n + face[f]) * 3;
        col[o] = byte(cr * (LIGHT.er + LIGHT.dr * w + d));
        col[o + 1] = byte(cg * (LIGHT.eg + LIGHT.dg * w + d));
        col[o + 2] = byte(cb * (LIGHT.eb + LIGHT.db * w + d));
      }
    } else {
      const nm = this.shape.normals;
      for (let i = 0, o = k * n * 3; i < n * 3; i += 3, o += 3) {
        const x = nm[i], y = nm[i + 1], z = nm[i + 2];   // the corner's normal (on the unit sphere)
        const nx = r0 * x + r4 * y + r8 * z, ny = r1 * x + r5 * y + r9 * z, nz = r2 * x + r6 * y + r10 * z;
        const w = 0.5 * ny + 0.5, d = Math.max(0, nx * SUN.x + ny * SUN.y + nz * SUN.z) * LIGHT.sun;
        col[o] = byte(cr * (LIGHT.er + LIGHT.dr * w + d));
        col[o + 1] = byte(cg * (LIGHT.eg + LIGHT.dg * w + d));
        col[o + 2] = byte(cb * (LIGHT.eb + LIGHT.db * w + d));
      }
    }
    this.centres[k * 3] = px; this.centres[k * 3 + 1] = py; this.centres[k * 3 + 2] = pz;
  }
  // Draws the first `count` slots (their listed triangles); the next frame lists anew.
  finish(count) {
    const n = this.shape.vertices;
    this.count = count;
    this.mesh.geometry.setDrawRange(0, this.listed);
    if (count > 0) {
      for (const a of [this.positions, this.colors]) {
        a.clearUpdateRanges();
        a.addUpdateRange(0, count * n * 3);
        a.needsUpdate = true;
      }
    }
    if (this.shape.face && this.listed > 0) {
      this.indices.clearUpdateRanges();
      this.indices.addUpdateRange(0, this.listed);
      this.indices.needsUpdate = true;
    }
    this.listed = 0;
    this.mesh.geometry.boundingSphere = null;   // recomputed when picking
  }
  slotOf(id) {
    for (let k = 0; k < this.count; k++) if (this.ids[k] === id) return k;
    return -1;
  }
}
const LIGHT = {
  er: EARTH.r * 1.6 / Math.PI, eg: EARTH.g * 1.6 / Math.PI, eb: EARTH.b * 1.6 / Math.PI,
  dr: (SKY.r - EARTH.r) * 1.6 / Math.PI, dg: (SKY.g - EARTH.g) * 1.6 / Math.PI, db: (SKY.b - EARTH.b) * 1.6 / Math.PI,
  sun: 1.8 / Math.PI,
};

// The rotation of the unit quaternion (qx, qy, qz, qw) as its columns, written into
// out[at..at + 9]: where the body's x (the first 3), y and z axes point.
function rotationOf(qx, qy, qz, qw, out, at) {
  const x2 = qx + qx, y2 = qy + qy, z2 = qz + qz;
  const xx = qx * x2, xy = qx * y2, xz = qx * z2, yy = qy * y2, yz = qy * z2, zz = qz * z2;
  const wx = qw * x2, wy = qw * y2, wz = qw * z2;
  out[at] = 1 - (yy + zz); out[at + 1] = xy + wz; out[at + 2] = xz - wy;
  out[at + 3] = xy - wz; out[at + 4] = 1 - (xx + zz); out[at + 5] = yz + wx;
  out[at + 6] = xz + wy; out[at + 7] = yz - wx; out[at + 8] = 1 - (xx + yy);
}

function ensureCapacity(bodies, shape, material, n) {
  if (bodies && bodies.capacity >= n) return bodies;
  if (bodies) bodies.dispose();
  return new Bodies(shape, material, Math.max(64, Math.ceil(n * 1.5)));
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
    // Lit once: a plane's light is the same everywhere.
    const lit = new THREE.Color(0x3b4550), up = 0.5 * 1 + 0.5, sun = SUN.y * LIGHT.sun;
    lit.setRGB(lit.r * (LIGHT.er + LIGHT.dr * up + sun), lit.g * (LIGHT.eg + LIGHT.dg * up + sun), lit.b * (LIGHT.eb + LIGHT.db * up + sun));
    const g = new THREE.Mesh(new THREE.PlaneGeometry(size.x * 1.5, size.z * 1.5), new THREE.MeshBasicMaterial({ color: lit }));
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
// Frames received and not yet drawn (bytes, oldest first; decoded only when drawn). Frames
// arrive at the display rate but bunched (two in one animation frame, none in the next):
// drawing the oldest of a few queued ones shows each of them, one per animation frame, where
// keeping only the newest dropped every second frame of a bunch. A page slower than the
// stream drops the oldest beyond `QUEUED_MAX`, so the picture lags by at most that many.
const queued = [];
const QUEUED_MAX = 3;

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

const m4 = new THREE.Matrix4();
const white = new THREE.Color(0xffffff);
let ids = new Float64Array(0);
const occlusion = new Occlusion(256);
const rotations = { r: new Float64Array(0) }, kinds = { k: new Uint8Array(0) };

// Which of BALL_LEVELS draws a ball of `radius` at (x, y, z) (view matrix v, canvas pixels
// per unit of height at distance 1: perPixel).
function ballLevel(x, y, z, radius, v, perPixel) {
  const depth = -(v[2] * x + v[6] * y + v[10] * z + v[14]);
  if (!soda.lod || depth <= radius) return 0;
  const pixels = radius * perPixel / depth;
  let level = 0;
  while (pixels < BALL_LEVELS[level].pixels) level++;
  return level;
}

// Writes the bodies of frame f that the camera can see (all with `?cull=0`) straight from
// its bytes into the meshes' vertex arrays. Runs for every frame whose bodies changed and
// whenever the camera moves or the canvas changes size: what is hidden depends on them all.
function placeBodies(f) {
  const n = f.bodies;
  const u8 = new Uint8Array(f.view.buffer, f.bodyOffset, n * BODY);
  const u16 = new Uint16Array(f.view.buffer, f.bodyOffset, n * BODY / 2);
  const f32 = new Float32Array(f.view.buffer, f.bodyOffset, n * BODY / 4);
  if (rotations.r.length < n * 9) rotations.r = new Float64Array(n * 9);
  const rot = rotations.r;
  // Every body is measured against the camera, then each is decided (web/occlusion.js).
  // Each body's kind (KINDS: a box, or a ball's level of detail; 255 when hidden).
  camera.updateMatrixWorld();
  if (kinds.k.length < n) kinds.k = new Uint8Array(n);
  const kind = kinds.k, count = KINDS.map(() => 0);
  const v = camera.matrixWorldInverse.elements, perPixel = renderer.domElement.height * camera.projectionMatrix.elements[5] / 2;
  if (soda.cull) occlusion.begin(camera, n);
  for (let i = 0; i < n; i++) {
    const w = i * (BODY / 4), box = u8[i * BODY + 10] === 1;
    rotationOf(f32[w + 6], f32[w + 7], f32[w + 8], f32[w + 9], rot, i * 9);
    kind[i] = box ? 0 : 1 + ballLevel(f32[w + 3], f32[w + 4], f32[w + 5], f32[w + 10], v, perPixel);
    if (soda.cull) {
      // A coarse ball reaches beyond the sphere (asLarge): its own extent bounds it.
      occlusion.body(i, f32[w + 3], f32[w + 4], f32[w + 5], box ? rot : null, i * 9, f32[w + 10], f32[w + 11], f32[w + 12],
        f32[w + 10] * KINDS[kind[i]].extent);
    }
  }
  if (soda.cull) occlusion.finish();
  for (let i = 0; i < n; i++) {
    if (soda.cull && occlusion.hidden(i)) kind[i] = 255;
    else count[kind[i]]++;
  }
  KINDS.forEach((shape, k) => { sets[k] = ensureCapacity(sets[k], shape, k === 0 ? boxMaterial : ballMaterial, count[k]); });
  const next = KINDS.map(() => 0);
  const selected = soda.selected;
  for (let i = 0; i < n; i++) {
    if (kind[i] === 255) continue;
    const w = i * (BODY / 4);
    const id = ids[i];
    const world = u16[w * 2 + 4], asleep = u8[i * BODY + 11] === 1;
    const into = sets[kind[i]], k = next[kind[i]]++;
    into.ids[k] = id;
    into.place(k, f32[w + 3], f32[w + 4], f32[w + 5], rot, i * 9,
      f32[w + 10], f32[w + 11], f32[w + 12], id === selected ? white : palette(world, f.worlds, asleep),
      kind[i] === 0 && soda.cull ? occlusion.faces(i) : 63);
  }
  soda.triangles = sets.reduce((t, b) => t + b.listed, 0) / 3;
  sets.forEach((b, k) => b.finish(next[k]));
  soda.drawn = next.reduce((a, b) => a + b, 0);
}

// Takes frame f as the one shown: its body ids, the cells' flashes, the panel and timeline
// (its bodies are placed by placeBodies, before the render).
function draw(f) {
  const n = f.bodies;
  const u32 = new Uint32Array(f.view.buffer, f.bodyOffset, n * BODY / 4);
  if (ids.length !== n) ids = new Float64Array(n);
  for (let i = 0; i < n; i++) ids[i] = u32[i * (BODY / 4) + 1] * 4294967296 + u32[i * (BODY / 4)];
  soda.ids = ids;
  // A cell flashes when a rollback reached it since the frame drawn before: its count of
  // re-executed computations grew (a cell that changed owner restarts its count: no flash).
  if (lastRecomputes && lastRecomputes.length === f.cells) {
    for (let c = 0; c < f.cells; c++) {
      if (f.recomputes[c] > lastRecomputes[c] && f.owners[c] === lastOwners[c]) flash.set(c, 1);
    }
  }
  // Views on this frame's own buffer (every message has its own): kept, not copied.
  lastRecomputes = f.recomputes;
  lastOwners = f.owners;
  drawFlashes();
  // The panel's text is rewritten about 8 times a second (every write costs the page a
  // layout and a repaint), at once when the display pauses or resumes.
  const was = soda.shown;
  soda.shown = { step: f.step, hash: f.hash, gvt: f.gvt, buffered: f.buffered, paused: f.paused };
  panelFrame = f;
  if (!was || was.paused !== f.paused || f.paused) drawPanel();
  drawTimeline(f);
}
let panelFrame = null, panelAt = 0;

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

function drawPanel() {
  const f = panelFrame;
  if (!f) return;
  panelFrame = null;
  panelAt = performance.now();
  $('step').textContent = f.step;
  $('hash').textContent = f.hash;
  $('gvt').textContent = soda.scene.worlds > 1 || soda.scene.executor !== 'reference' ? `${f.gvt} (${f.gvt - f.step} ahead)` : 'reference: none';
  $('rate').textContent = `${f.rate.toFixed(1)} frames/s, page ${stats.pageFps.toFixed(0)} fps (draw ${soda.drawMs.toFixed(1)} ms, render ${soda.renderMs.toFixed(1)} ms)`;
  $('scale').textContent = `${Math.round(stats.scale * 100)} % of ${stats.pixels}${stats.auto ? ', auto' : ', fixed'}`;
  const seconds = f.buffered / (soda.scene.fps * f.speed);
  $('buffer').textContent = `${f.buffered} frames, ${seconds.toFixed(2)} s`;
  $('starved').textContent = `${f.starved} ticks`;
  $('bodies').textContent = soda.cull ? `${f.bodies} (${soda.drawn} in sight)` : f.bodies;
  $('speed').textContent = `${+f.speed.toFixed(3)}×`;
  $('pause').textContent = f.paused ? 'resume' : 'pause';
}

// The timeline: each world's LVT as a bar ahead of the step shown, GVT as a line, and a
// flash where a world rolled back.
const timeline = $('timeline');
const rowFlash = [];
function drawTimeline(f) {
  const ctx = timeline.getContext('2d');
  // Resizing a canvas reallocates it: only when the page's size changed.
  if (timeline.width !== timeline.clientWidth) timeline.width = timeline.clientWidth;
  if (timeline.height !== timeline.clientHeight) timeline.height = timeline.clientHeight;
  const w = timeline.width, h = timeline.height;
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
  lastTimeline = f.rollbacks;
  ctx.strokeStyle = '#ffffff'; ctx.beginPath(); ctx.moveTo(x(f.gvt), 14); ctx.lineTo(x(f.gvt), h); ctx.stroke();
  ctx.fillStyle = '#ffffff'; ctx.fillText(`GVT ${f.gvt}`, Math.min(w - 60, x(f.gvt) + 3), 12);
  ctx.strokeStyle = '#4aa3ff'; ctx.beginPath(); ctx.moveTo(x(f.step + f.buffered), 14); ctx.lineTo(x(f.step + f.buffered), h); ctx.stroke();
}
let lastTimeline = null;

// --- connection -------------------------------------------------------------------------------
function say(text) { $('message').textContent = text; }

// The viewer to connect to: this page's server, or `?ws=HOST:PORT` (a copy of the page served
// from elsewhere, as scripts/measure-view-fps.py does to measure a page without a rebuild).
const wsHost = new URLSearchParams(location.search).get('ws') || location.host;

function connect() {
  const socket = new WebSocket(`ws://${wsHost}/ws`);
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
    queued.push(e.data);
    if (queued.length > QUEUED_MAX) queued.shift();
    soda.frames++;
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
  const shapes = sets.filter((b) => b && b.count > 0);
  for (const b of shapes) if (!b.mesh.geometry.boundingSphere) b.mesh.geometry.computeBoundingSphere();
  const targets = shapes.map((b) => b.mesh);
  const ground = world3.getObjectByName('ground');
  if (ground) targets.push(ground);
  const hit = raycaster.intersectObjects(targets, false)[0];
  if (!hit) return { ray: raycaster.ray.direction.clone() };
  const body = shapes.find((b) => b.mesh === hit.object);
  const id = body ? body.ids[Math.floor(hit.face.a / body.shape.vertices)] : null;
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

// Where body `id` appears on the page, in CSS pixels (for tests and scripted demos); null
// if it is not drawn (out of sight: see placeBodies).
soda.screenPointOf = (id) => {
  for (const b of sets) {
    const k = b ? b.slotOf(id) : -1;
    if (k < 0) continue;
    const p = new THREE.Vector3().fromArray(b.centres, k * 3).project(camera);
    const r = renderer.domElement.getBoundingClientRect();
    return { x: r.left + (p.x + 1) / 2 * r.width, y: r.top + (1 - p.y) / 2 * r.height, depth: p.z };
  }
  return null;
};

// --- render loop ------------------------------------------------------------------------------
// The page draws when a frame with changed bodies came, the camera moved, a flash fades or
// the page was resized, not on every animation frame (a frame whose bodies did not change is
// shown by the picture already on the canvas). Its own cost is in window.sodaStats: animation
// frames per second, frames drawn per second, the page's JS per frame drawn (decoding, culling, vertex writing) and render ms per frame
// (averages), and the render scale: the canvas has scale × the CSS pixels. With `auto`
// (the default; `?scale=0.5` fixes it), the scale drops a step each second the page draws
// fewer than 55 frames/s while frames keep coming, down to 25 %, and climbs back a step after
// 3 s at 58 or more — the panel shows it.
const fixedScale = Number(new URLSearchParams(location.search).get('scale'));
const stats = {
  pageFps: 0, drawnFps: 0, drawMs: 0, renderMs: 0,
  scale: fixedScale > 0 ? Math.min(1, fixedScale) : 1, auto: !(fixedScale > 0), pixels: '',
  ticks: 0, renders: 0, windowStart: performance.now(), fast: 0,
};
window.sodaStats = stats;
const SCALES = [1, 0.85, 0.7, 0.6, 0.5, 0.42, 0.35, 0.3, 0.25];
let needRender = true;
// The bodies are placed again when a new frame came, the camera moved, the page or the render
// scale changed size (a ball's level of detail depends on the canvas), or the selection changed.
let placeAgain = false, placedSelected = null;
function resize() {
  const w = host.clientWidth, h = host.clientHeight;
  renderer.setPixelRatio(Math.min(1, window.devicePixelRatio) * stats.scale);
  renderer.setSize(w, h, false);
  renderer.domElement.style.width = `${w}px`; renderer.domElement.style.height = `${h}px`;
  camera.aspect = w / Math.max(1, h); camera.updateProjectionMatrix();
  stats.pixels = `${w}×${h}`;
  needRender = true;
  placeAgain = true;
}
window.addEventListener('resize', resize);
controls.addEventListener('change', () => { needRender = true; });
resize();
function adapt(now) {
  const seconds = (now - stats.windowStart) / 1000;
  if (seconds < 1) return;
  stats.pageFps = stats.ticks / seconds;
  stats.drawnFps = stats.renders / seconds;
  // Busy: the page drew on (nearly) every animation frame, so frames wait for it.
  const busy = stats.renders >= stats.ticks * 0.9 && stats.renders > 0;
  // Lower a step while busy below 55 fps; raise one after 3 s at 58 or more.
  if (stats.auto) {
    const at = SCALES.indexOf(stats.scale);
    if (busy && stats.pageFps < 55 && at < SCALES.length - 1) { stats.scale = SCALES[at + 1]; stats.fast = 0; resize(); }
    else if (stats.pageFps >= 58 && at > 0 && ++stats.fast >= 3) { stats.scale = SCALES[at - 1]; stats.fast = 0; resize(); }
  }
  stats.ticks = 0; stats.renders = 0; stats.windowStart = now;
  if (!panelFrame && soda.shown) panelFrame = lastFrame;
}
let lastFrame = null;
// A frame whose bodies are byte for byte those of the frame
// placed last (a pile at rest: every body asleep) leaves the meshes as they are and, with no
// flash fading and the camera still, needs no render either: the picture on the canvas is
// already that frame's, pixel for pixel, and the software GL's time goes to frames that
// change.
function sameBodies(a, b) {
  if (!a || a.bodies !== b.bodies) return false;
  const words = a.bodies * (BODY / 4);
  const x = new Int32Array(a.view.buffer, a.bodyOffset, words), y = new Int32Array(b.view.buffer, b.bodyOffset, words);
  for (let i = 0; i < words; i++) if (x[i] !== y[i]) return false;
  return true;
}
soda.unchanged = 0;   // frames shown without placing the bodies (their bodies were unchanged)
soda.renders = 0;     // renderer.render calls so far
controls.addEventListener('change', () => { placeAgain = true; });
window.addEventListener('resize', () => { placeAgain = true; });
function loop(now) {
  stats.ticks++;
  const t0 = performance.now();
  if (queued.length > 0 && soda.scene) {
    let f = null;
    try { f = decode(queued.shift()); } catch (err) { say(String(err)); }
    if (f) {
      const flashing = flashMesh !== null && flashMesh.count > 0;
      draw(f);   // fades the flashes one step: drawn if any was showing
      if (flashing || (flashMesh !== null && flashMesh.count > 0)) needRender = true;
      if (sameBodies(lastFrame, f)) soda.unchanged++;
      else placeAgain = true;
      lastFrame = f;
    }
  }
  if (controls.update()) placeAgain = true;
  if (placedSelected !== soda.selected) placeAgain = true;
  if (placeAgain && lastFrame) {
    placeAgain = false;
    placedSelected = soda.selected;
    placeBodies(lastFrame);
    soda.drawMs = soda.drawMs * 0.9 + (performance.now() - t0) * 0.1;
    needRender = true;
  }
  if (flash.size > 0 && !needRender) { drawFlashes(); needRender = true; }
  if (needRender) {
    needRender = false;
    const r0 = performance.now();
    renderer.render(world3, camera);
    soda.renderMs = soda.renderMs * 0.9 + (performance.now() - r0) * 0.1;
    stats.renders++;
    soda.renders++;
  }
  stats.drawMs = soda.drawMs; stats.renderMs = soda.renderMs;
  if (panelFrame && now - panelAt > 125) drawPanel();
  adapt(now);
  requestAnimationFrame(loop);
}
requestAnimationFrame(loop);
connect();

// Places the bodies and renders at once, in this task (tests and tools compare the pixels
// with and without culling: the canvas can be read until the task ends).
soda.camera = camera;
soda.controls = controls;
soda.renderNow = () => {
  camera.updateMatrixWorld();
  if (lastFrame) placeBodies(lastFrame);
  renderer.render(world3, camera);
  return renderer.domElement;
};
