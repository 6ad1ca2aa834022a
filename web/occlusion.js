// Which bodies the camera cannot see in this frame, so the page does not send them to the
// GL: bodies wholly outside the view, and bodies wholly behind boxes nearer the camera (the
// inside of a settled pile). Software GL (SwiftShader) pays for every primitive sent, seen
// or not (docs/performance.md, "The viewer page in software GL").
//
// A small depth buffer, on the CPU, over the same view as the canvas (W × H cells, each a
// rectangle of normalised device coordinates): every box in front of the camera marks the
// cells its outline covers *completely* with an upper bound of how far the camera's rays
// through that cell enter it; a body is hidden when every cell its outline touches holds a
// bound nearer than the body's nearest point. Both sides are conservative, so a hidden body
// is provably covered on every ray that could reach it: by a box that is drawn, or by one
// that is hidden itself, and then (distances strictly decrease along the ray) by a nearer
// one that is drawn. Only boxes occlude (a ball's outline is a disc: its share of covered
// cells is small); balls and boxes are both tested.
//
// Bodies are taken nearest first (bucketed by their nearest point): each is tested against
// the boxes marked so far, and marks the buffer only if it is not hidden (a hidden body's
// marks would change nothing: every cell under it already holds a nearer bound). The order
// only decides how much is culled, never whether a culled body could be seen.
//
// The same buffer, once all bodies are decided, tells which faces of a box in sight to
// draw: those turned to the camera and not covered nearer than the face (faces()).
//
// Usage per frame: begin(camera, n), body() for each of the n bodies, finish(), then
// hidden(i) and, for a box, faces(i) for each.
const BUCKETS = 512;
// Distances compare with this margin (metres): vertex positions reach the GL as float32.
const MARGIN = 1e-3;
// A face is left to the GL as back-facing only when the camera is behind its plane by more
// than this share of the distance (about 3°): the GL decides a face's side from vertices
// snapped to its sub-pixel grid, and can draw a sliver of a face that is nearly edge-on.
const EDGE_ON = 0.05;

export class Occlusion {
  constructor(width) {
    this.width = width;
    this.height = 0;
    this.depth = new Float32Array(0);   // per cell: nearest covering bound, Infinity if none
    this.rect = new Int32Array(0);      // per body: cells x0, y0, x1, y1 its outline touches
    this.nearest = new Float64Array(0); // per body: distance from the camera to its nearest point (0: around the camera), −1: partly behind the near plane
    this.outside = new Uint8Array(0);   // per body: 1 if wholly outside the view
    this.far = new Float64Array(0);     // per body: a box's bound for the cells it covers, 0: not an occluder
    this.corners = new Float64Array(0); // per body: its 8 projected corners, x and y in cells
    this.hide = new Uint8Array(0);      // per body: the verdict
    this.order = new Int32Array(0); this.count = new Int32Array(BUCKETS + 1);
    this.n = 0;
    this.v = new Float64Array(16);      // the view matrix (world → camera), column-major
    this.eye = [0, 0, 0];               // the camera in the world
    this.px = new Float64Array(8); this.py = new Float64Array(8); this.pd = new Float64Array(8);
    this.hull = new Int32Array(16);
    this.sorted = new Int32Array(8);
    this.edges = new Float64Array(8 * 3);
  }

  // Starts a frame of `n` bodies seen by `camera` (a PerspectiveCamera, matrices current).
  begin(camera, n) {
    const w = this.width, h = Math.max(1, Math.round(w / camera.aspect));
    if (h !== this.height) { this.height = h; this.depth = new Float32Array(w * h); }
    this.depth.fill(Infinity);
    if (this.nearest.length < n) {
      this.rect = new Int32Array(n * 4); this.nearest = new Float64Array(n); this.outside = new Uint8Array(n);
      this.far = new Float64Array(n); this.corners = new Float64Array(n * 16); this.hide = new Uint8Array(n);
      this.order = new Int32Array(n); this.bucket = new Int32Array(n);
      this.local = new Float64Array(n * 6); this.box = new Uint8Array(n);
    }
    this.n = n;
    this.v.set(camera.matrixWorldInverse.elements);
    const m = camera.matrixWorld.elements;
    this.eye[0] = m[12]; this.eye[1] = m[13]; this.eye[2] = m[14];
    const p = camera.projectionMatrix.elements;
    this.sx = p[0]; this.sy = p[5]; this.ox = p[8]; this.oy = p[9];
    this.near = camera.near;
  }

  // Body i: centre (cx, cy, cz); a box with rotation columns r[at..at + 9] (its x, y and z
  // axes) and half extents (hx, hy, hz), or a ball of radius `radius` when r is null.
  body(i, cx, cy, cz, r, at, hx, hy, hz, radius) {
    const e = this.eye, dx = e[0] - cx, dy = e[1] - cy, dz = e[2] - cz;
    // The corners: a box's own, or a ball's bounding cube (along the world's axes).
    let ax = 0, ay = 0, az = 0, bx = 0, by = 0, bz = 0, qx = 0, qy = 0, qz = 0;
    let near;
    // The camera in the box's frame: its coordinates along the box's axes.
    let l0 = 0, l1 = 0, l2 = 0;
    if (r) {
      const r0 = r[at], r1 = r[at + 1], r2 = r[at + 2], r3 = r[at + 3], r4 = r[at + 4], r5 = r[at + 5];
      const r6 = r[at + 6], r7 = r[at + 7], r8 = r[at + 8];
      ax = r0 * hx; ay = r1 * hx; az = r2 * hx;
      bx = r3 * hy; by = r4 * hy; bz = r5 * hy;
      qx = r6 * hz; qy = r7 * hz; qz = r8 * hz;
      l0 = dx * r0 + dy * r1 + dz * r2; l1 = dx * r3 + dy * r4 + dz * r5; l2 = dx * r6 + dy * r7 + dz * r8;
      const o0 = Math.max(0, Math.abs(l0) - hx), o1 = Math.max(0, Math.abs(l1) - hy), o2 = Math.max(0, Math.abs(l2) - hz);
      near = Math.sqrt(o0 * o0 + o1 * o1 + o2 * o2);
    } else {
      ax = radius; by = radius; qz = radius;
      near = Math.sqrt(dx * dx + dy * dy + dz * dz) - radius;
    }
    // Project the corners into buffer cells (x right, y down); their bounding rectangle holds
    // the body's outline when every corner is in front of the near plane.
    const v = this.v, W = this.width, H = this.height, pc = this.corners, pd = this.pd, c0 = i * 16;
    let behind = 0, x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let k = 0; k < 8; k++) {
      const s0 = k & 1 ? 1 : -1, s1 = k & 2 ? 1 : -1, s2 = k & 4 ? 1 : -1;
      const wx = cx + s0 * ax + s1 * bx + s2 * qx;
      const wy = cy + s0 * ay + s1 * by + s2 * qy;
      const wz = cz + s0 * az + s1 * bz + s2 * qz;
      const X = v[0] * wx + v[4] * wy + v[8] * wz + v[12];
      const Y = v[1] * wx + v[5] * wy + v[9] * wz + v[13];
      const Z = v[2] * wx + v[6] * wy + v[10] * wz + v[14];
      const depth = -Z;
      if (depth <= this.near) { behind++; continue; }
      const x = ((this.sx * X / depth - this.ox) + 1) * 0.5 * W;
      const y = (1 - (this.sy * Y / depth - this.oy)) * 0.5 * H;
      pc[c0 + k] = x; pc[c0 + 8 + k] = y; pd[k] = Math.sqrt(X * X + Y * Y + Z * Z);
      if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y;
    }
    this.outside[i] = behind === 8 || (behind === 0 && (x1 < 0 || y1 < 0 || x0 > W || y0 > H)) ? 1 : 0;
    this.far[i] = 0;
    const lh = this.local, b = i * 6;
    lh[b] = l0; lh[b + 1] = l1; lh[b + 2] = l2; lh[b + 3] = hx; lh[b + 4] = hy; lh[b + 5] = hz;
    this.box[i] = r ? 1 : 0;
    if (behind > 0) { this.nearest[i] = -1; return; }   // part of it behind the near plane
    this.nearest[i] = near;
    const rect = this.rect, o = i * 4;
    rect[o] = Math.max(0, Math.floor(x0)); rect[o + 1] = Math.max(0, Math.floor(y0));
    rect[o + 2] = Math.min(W - 1, Math.floor(x1)); rect[o + 3] = Math.min(H - 1, Math.floor(y1));
    if (r && near > 0 && x1 - x0 >= 1 && y1 - y0 >= 1) {
      // As an occluder: a ray through the outline enters the box through a face that faces
      // the camera, no farther than that face's farthest corner.
      let far = 0;
      for (let k = 0; k < 8; k++) {
        if ((k & 1 ? l0 : -l0) > hx || (k & 2 ? l1 : -l1) > hy || (k & 4 ? l2 : -l2) > hz) far = Math.max(far, pd[k]);
      }
      this.far[i] = far + MARGIN;
    }
  }

  // Decides every body, nearest first (see the top of this file).
  finish() {
    const n = this.n, nearest = this.nearest, count = this.count, order = this.order;
    let lo = Infinity, hi = 0;
    for (let i = 0; i < n; i++) if (nearest[i] > 0) { lo = Math.min(lo, nearest[i]); hi = Math.max(hi, nearest[i]); }
    const scale = hi > lo ? (BUCKETS - 1) / (hi - lo) : 0;
    const bucket = this.bucket;
    for (let i = 0; i < n; i++) bucket[i] = nearest[i] > 0 ? ((nearest[i] - lo) * scale) | 0 : 0;
    count.fill(0);
    for (let i = 0; i < n; i++) count[bucket[i] + 1]++;
    for (let b = 0; b < BUCKETS; b++) count[b + 1] += count[b];
    for (let i = 0; i < n; i++) order[count[bucket[i]]++] = i;
    for (let t = 0; t < n; t++) {
      const i = order[t];
      this.hide[i] = this.test(i) ? 1 : 0;
      if (!this.hide[i] && this.far[i] > 0) this.cover(i);
    }
  }

  // Marks with body i's bound every cell of its rectangle that lies wholly inside the convex
  // hull of its 8 projected corners.
  cover(i) {
    const o = i * 4, x0 = this.rect[o], y0 = this.rect[o + 1], x1 = this.rect[o + 2], y1 = this.rect[o + 3];
    const far = this.far[i], pc = this.corners, c0 = i * 16;
    const px = this.px, py = this.py, hull = this.hull, order = this.sorted;
    for (let k = 0; k < 8; k++) { px[k] = pc[c0 + k]; py[k] = pc[c0 + 8 + k]; }
    // Andrew's monotone chain over the 8 corners, sorted by x then y (insertion sort).
    for (let t = 0; t < 8; t++) {
      let u = t;
      while (u > 0 && (px[order[u - 1]] > px[t] || (px[order[u - 1]] === px[t] && py[order[u - 1]] > py[t]))) { order[u] = order[u - 1]; u--; }
      order[u] = t;
    }
    let m = 0;
    const turn = (a, b, c) => (px[b] - px[a]) * (py[c] - py[a]) - (py[b] - py[a]) * (px[c] - px[a]);
    for (let t = 0; t < 8; t++) {
      while (m >= 2 && turn(hull[m - 2], hull[m - 1], order[t]) <= 0) m--;
      hull[m++] = order[t];
    }
    for (let t = 6, lower = m + 1; t >= 0; t--) {
      while (m >= lower && turn(hull[m - 2], hull[m - 1], order[t]) <= 0) m--;
      hull[m++] = order[t];
    }
    m--;   // the last point is the first
    if (m < 3) return;
    // Edge j: inside where A·x + B·y + C ≥ 0; a cell (half-size ½) is wholly inside when its
    // centre is at least (|A| + |B|)/2 inside every edge.
    const E = this.edges;
    for (let j = 0; j < m; j++) {
      const a = hull[j], b = hull[j + 1];
      const A = -(py[b] - py[a]), B = px[b] - px[a];
      E[j * 3] = A; E[j * 3 + 1] = B;
      E[j * 3 + 2] = -(A * px[a] + B * py[a]) - 0.5 * (Math.abs(A) + Math.abs(B)) - 1e-6 * (Math.abs(A) + Math.abs(B));
    }
    // Per row, the edges bound the cells' centres x to one interval.
    const depth = this.depth, W = this.width;
    for (let y = y0; y <= y1; y++) {
      const cy = y + 0.5;
      let lo = x0 + 0.5, hi = x1 + 0.5;
      for (let j = 0; j < m * 3 && lo <= hi; j += 3) {
        const A = E[j], rest = E[j + 1] * cy + E[j + 2];   // A·x + rest ≥ 0
        if (A > 0) lo = Math.max(lo, -rest / A);
        else if (A < 0) hi = Math.min(hi, -rest / A);
        else if (rest < 0) hi = -Infinity;
      }
      for (let x = Math.ceil(lo - 0.5), end = Math.floor(hi - 0.5), at = y * W + x; x <= end; x++, at++) {
        if (far < depth[at]) depth[at] = far;
      }
    }
  }

  // Whether body i can't be seen (after finish()).
  hidden(i) { return this.hide[i] === 1; }

  // Which faces of box i (not hidden) to draw, as bits 1 << f for faces f = +x, −x, +y, −y,
  // +z, −z (after finish()): those that face the camera (the GL culls the others after
  // paying for their vertices; one nearly edge-on is kept) and are not covered in the
  // buffer nearer than the face's nearest point. All six for a body not wholly in front of
  // the camera, or around it.
  faces(i) {
    const lh = this.local, b = i * 6;
    if (!(this.nearest[i] > 0)) return 63;
    const back = -EDGE_ON * Math.sqrt(lh[b] * lh[b] + lh[b + 1] * lh[b + 1] + lh[b + 2] * lh[b + 2]);
    let mask = 0;
    for (let a = 0; a < 3; a++) {
      const l = lh[b + a], h = lh[b + 3 + a];
      for (let f = a * 2; f < a * 2 + 2; f++) {
        const beyond = (f & 1 ? -l : l) - h;   // how far the camera is in front of face f's plane
        if (beyond < back) continue;
        if (beyond > MARGIN && this.covers(i, a, f & 1 ? 0 : 1, beyond)) continue;
        mask |= 1 << f;
      }
    }
    return mask;
  }

  // Whether every cell the face of box i on axis a (side 1: +, 0: −) touches holds a bound
  // nearer than the face's nearest point; `beyond`: the camera's height over its plane.
  covers(i, a, side, beyond) {
    const lh = this.local, b = i * 6, pc = this.corners, c0 = i * 16;
    let d2 = beyond * beyond;
    for (let e = 0; e < 3; e++) {
      if (e === a) continue;
      const o = Math.max(0, Math.abs(lh[b + e]) - lh[b + 3 + e]);
      d2 += o * o;
    }
    const near = Math.sqrt(d2) - MARGIN;
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let k = 0; k < 8; k++) {
      if (((k >> a) & 1) !== side) continue;
      const x = pc[c0 + k], y = pc[c0 + 8 + k];
      if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y;
    }
    return this.under(Math.max(0, Math.floor(x0)), Math.max(0, Math.floor(y0)),
      Math.min(this.width - 1, Math.floor(x1)), Math.min(this.height - 1, Math.floor(y1)), near);
  }

  // Whether every cell of the rectangle holds a bound nearer than `near`.
  under(x0, y0, x1, y1, near) {
    const depth = this.depth, W = this.width;
    for (let y = y0; y <= y1; y++) {
      for (let x = x0, at = y * W + x0; x <= x1; x++, at++) if (!(depth[at] < near)) return false;
    }
    return true;
  }

  // Whether body i is wholly outside the view, or every cell its outline touches is covered
  // nearer than its nearest point by the boxes marked so far.
  test(i) {
    if (this.outside[i]) return true;
    const near = this.nearest[i] - MARGIN;
    if (near <= 0) return false;
    const o = i * 4;
    return this.under(this.rect[o], this.rect[o + 1], this.rect[o + 2], this.rect[o + 3], near);
  }
}
