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
// Usage per frame: begin(camera), then body() for every body (its outline marks the
// buffer), then hidden(i) for every body.
const SIGNS = [[-1, -1, -1], [1, -1, -1], [-1, 1, -1], [1, 1, -1], [-1, -1, 1], [1, -1, 1], [-1, 1, 1], [1, 1, 1]];
// Distances compare with this margin (metres): vertex positions reach the GL as float32.
const MARGIN = 1e-3;

export class Occlusion {
  constructor(width) {
    this.width = width;
    this.height = 0;
    this.depth = new Float32Array(0);   // per cell: nearest covering bound, Infinity if none
    this.rect = new Int32Array(0);      // per body: cells x0, y0, x1, y1 its outline touches
    this.nearest = new Float64Array(0); // per body: distance from the camera to its nearest point, or −1: never hidden
    this.outside = new Uint8Array(0);   // per body: 1 if wholly outside the view
    this.v = new Float64Array(16);      // the view matrix (world → camera), column-major
    this.eye = [0, 0, 0];               // the camera in the world
    this.px = new Float64Array(8); this.py = new Float64Array(8); this.pd = new Float64Array(8);
    this.hull = new Int32Array(16);
    this.order = new Int32Array(8);
    this.edges = new Float64Array(8 * 3);
  }

  // Starts a frame of `n` bodies seen by `camera` (a PerspectiveCamera, matrices current).
  begin(camera, n) {
    const w = this.width, h = Math.max(1, Math.round(w / camera.aspect));
    if (h !== this.height) { this.height = h; this.depth = new Float32Array(w * h); }
    this.depth.fill(Infinity);
    if (this.nearest.length < n) {
      this.rect = new Int32Array(n * 4); this.nearest = new Float64Array(n); this.outside = new Uint8Array(n);
    }
    this.v.set(camera.matrixWorldInverse.elements);
    const m = camera.matrixWorld.elements;
    this.eye[0] = m[12]; this.eye[1] = m[13]; this.eye[2] = m[14];
    const p = camera.projectionMatrix.elements;
    this.sx = p[0]; this.sy = p[5]; this.ox = p[8]; this.oy = p[9];
    this.near = camera.near;
  }

  // Body i: centre (cx, cy, cz); a box with rotation columns r (9 numbers: its x, y and z
  // axes) and half extents (hx, hy, hz), or a ball of radius `radius` when r is null.
  body(i, cx, cy, cz, r, hx, hy, hz, radius) {
    const e = this.eye, dx = e[0] - cx, dy = e[1] - cy, dz = e[2] - cz;
    // The corners: a box's own, or a ball's bounding cube (along the world's axes).
    let ax = 0, ay = 0, az = 0, bx = 0, by = 0, bz = 0, qx = 0, qy = 0, qz = 0;
    let near;
    // How far the camera is, along each of the box's axes, beyond the box's face (≤ 0: between them).
    let l0 = 0, l1 = 0, l2 = 0;
    if (r) {
      ax = r[0] * hx; ay = r[1] * hx; az = r[2] * hx;
      bx = r[3] * hy; by = r[4] * hy; bz = r[5] * hy;
      qx = r[6] * hz; qy = r[7] * hz; qz = r[8] * hz;
      l0 = dx * r[0] + dy * r[1] + dz * r[2]; l1 = dx * r[3] + dy * r[4] + dz * r[5]; l2 = dx * r[6] + dy * r[7] + dz * r[8];
      const o0 = Math.max(0, Math.abs(l0) - hx), o1 = Math.max(0, Math.abs(l1) - hy), o2 = Math.max(0, Math.abs(l2) - hz);
      near = Math.sqrt(o0 * o0 + o1 * o1 + o2 * o2);
    } else {
      ax = radius; by = radius; qz = radius;
      near = Math.sqrt(dx * dx + dy * dy + dz * dz) - radius;
    }
    // Project the corners into buffer cells (x right, y down); their bounding rectangle holds
    // the body's outline when every corner is in front of the near plane.
    const v = this.v, W = this.width, H = this.height, px = this.px, py = this.py, pd = this.pd;
    let behind = 0, x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let k = 0; k < 8; k++) {
      const s = SIGNS[k];
      const wx = cx + s[0] * ax + s[1] * bx + s[2] * qx;
      const wy = cy + s[0] * ay + s[1] * by + s[2] * qy;
      const wz = cz + s[0] * az + s[1] * bz + s[2] * qz;
      const X = v[0] * wx + v[4] * wy + v[8] * wz + v[12];
      const Y = v[1] * wx + v[5] * wy + v[9] * wz + v[13];
      const Z = v[2] * wx + v[6] * wy + v[10] * wz + v[14];
      const depth = -Z;
      if (depth <= this.near) { behind++; continue; }
      const x = ((this.sx * X / depth - this.ox) + 1) * 0.5 * W;
      const y = (1 - (this.sy * Y / depth - this.oy)) * 0.5 * H;
      px[k] = x; py[k] = y; pd[k] = Math.sqrt(X * X + Y * Y + Z * Z);
      if (x < x0) x0 = x; if (x > x1) x1 = x; if (y < y0) y0 = y; if (y > y1) y1 = y;
    }
    this.outside[i] = behind === 8 || (behind === 0 && (x1 < 0 || y1 < 0 || x0 > W || y0 > H)) ? 1 : 0;
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
        const s = SIGNS[k];
        if (s[0] * l0 > hx || s[1] * l1 > hy || s[2] * l2 > hz) far = Math.max(far, pd[k]);
      }
      this.cover(rect[o], rect[o + 1], rect[o + 2], rect[o + 3], far + MARGIN);
    }
  }

  // Marks with `far` every cell of the rectangle that lies wholly inside the convex hull of
  // the 8 projected corners (px, py).
  cover(x0, y0, x1, y1, far) {
    const px = this.px, py = this.py, hull = this.hull, order = this.order;
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
    const depth = this.depth, W = this.width;
    for (let y = y0; y <= y1; y++) {
      const cy = y + 0.5;
      for (let x = x0; x <= x1; x++) {
        const cx = x + 0.5;
        let inside = true;
        for (let j = 0; j < m * 3; j += 3) if (E[j] * cx + E[j + 1] * cy + E[j + 2] < 0) { inside = false; break; }
        if (inside && far < depth[y * W + x]) depth[y * W + x] = far;
      }
    }
  }

  // Whether body i can't be seen: wholly outside the view, or every cell its outline
  // touches is covered nearer than its nearest point.
  hidden(i) {
    if (this.outside[i]) return true;
    const near = this.nearest[i] - MARGIN;
    if (near <= 0) return false;
    const o = i * 4, x0 = this.rect[o], y0 = this.rect[o + 1], x1 = this.rect[o + 2], y1 = this.rect[o + 3];
    const depth = this.depth, W = this.width;
    for (let y = y0; y <= y1; y++) {
      for (let x = x0, at = y * W + x0; x <= x1; x++, at++) if (!(depth[at] < near)) return false;
    }
    return true;
  }
}
