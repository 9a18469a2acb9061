// meshdeco view: hand-written WebGL2 viewer and API client (no library; served from the binary).
// Geometry arrives as binary little-endian arrays (see src/view/mod.rs, `shape_bytes`).
// Data source: the live server's HTTP API (`meshdeco view`), or — in a standalone page
// (`meshdeco export --out view.html`, Python's `Model.show()`) — the same routes answered inside
// the page from embedded blendshapes (embedded.js); `api` is the one place that differs.
'use strict';
let api = (url, init) => fetch(url, init);

const $ = (id) => document.getElementById(id);
// Writes an element's text / shows or hides it only when that changes (no needless relayout).
function setText(e, text) { if (e.textContent !== text) e.textContent = text; }
function setShown(e, shown) { const v = shown ? '' : 'none'; if (e.style.display !== v) e.style.display = v; }
const canvas = $('gl');
const gl = canvas.getContext('webgl2', { antialias: false });

// ---------- state ----------
const S = {
  desc: null, n: 0, k: 0, faces: null, rest: null, pos: null, nrm: null, col: null,
  weights: null, dials: null, seg: null, heat: new Map(), selected: -1, overlay: 'none',
  pins: new Map(), undo: [], drag: null, frameErr: null, frameErms: null, frameTruth: null, frameRec: null,
  latencies: [], wire: false, ready: false, lastError: '',
};

function showError(msg) {
  S.lastError = msg || '';
  $('err').textContent = msg || '';
}

// ---------- small linear algebra (column-major 4x4) ----------
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scl = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const nrmz = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
function mul(a, b) {
  const o = new Float64Array(16);
  for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
    let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k]; o[c * 4 + r] = s;
  }
  return o;
}
function perspective(fovy, aspect, near, far) {
  const f = 1 / Math.tan(fovy / 2), o = new Float64Array(16);
  o[0] = f / aspect; o[5] = f; o[10] = (far + near) / (near - far); o[11] = -1; o[14] = 2 * far * near / (near - far);
  return o;
}
function lookAt(eye, center, up) {
  const z = nrmz(sub(eye, center)), x = nrmz(cross(up, z)), y = cross(z, x), o = new Float64Array(16);
  o[0] = x[0]; o[4] = x[1]; o[8] = x[2]; o[12] = -dot(x, eye);
  o[1] = y[0]; o[5] = y[1]; o[9] = y[2]; o[13] = -dot(y, eye);
  o[2] = z[0]; o[6] = z[1]; o[10] = z[2]; o[14] = -dot(z, eye);
  o[15] = 1;
  return o;
}
function invert(m) {
  const inv = new Float64Array(16);
  inv[0] = m[5]*m[10]*m[15]-m[5]*m[11]*m[14]-m[9]*m[6]*m[15]+m[9]*m[7]*m[14]+m[13]*m[6]*m[11]-m[13]*m[7]*m[10];
  inv[4] = -m[4]*m[10]*m[15]+m[4]*m[11]*m[14]+m[8]*m[6]*m[15]-m[8]*m[7]*m[14]-m[12]*m[6]*m[11]+m[12]*m[7]*m[10];
  inv[8] = m[4]*m[9]*m[15]-m[4]*m[11]*m[13]-m[8]*m[5]*m[15]+m[8]*m[7]*m[13]+m[12]*m[5]*m[11]-m[12]*m[7]*m[9];
  inv[12] = -m[4]*m[9]*m[14]+m[4]*m[10]*m[13]+m[8]*m[5]*m[14]-m[8]*m[6]*m[13]-m[12]*m[5]*m[10]+m[12]*m[6]*m[9];
  inv[1] = -m[1]*m[10]*m[15]+m[1]*m[11]*m[14]+m[9]*m[2]*m[15]-m[9]*m[3]*m[14]-m[13]*m[2]*m[11]+m[13]*m[3]*m[10];
  inv[5] = m[0]*m[10]*m[15]-m[0]*m[11]*m[14]-m[8]*m[2]*m[15]+m[8]*m[3]*m[14]+m[12]*m[2]*m[11]-m[12]*m[3]*m[10];
  inv[9] = -m[0]*m[9]*m[15]+m[0]*m[11]*m[13]+m[8]*m[1]*m[15]-m[8]*m[3]*m[13]-m[12]*m[1]*m[11]+m[12]*m[3]*m[9];
  inv[13] = m[0]*m[9]*m[14]-m[0]*m[10]*m[13]-m[8]*m[1]*m[14]+m[8]*m[2]*m[13]+m[12]*m[1]*m[10]-m[12]*m[2]*m[9];
  inv[2] = m[1]*m[6]*m[15]-m[1]*m[7]*m[14]-m[5]*m[2]*m[15]+m[5]*m[3]*m[14]+m[13]*m[2]*m[7]-m[13]*m[3]*m[6];
  inv[6] = -m[0]*m[6]*m[15]+m[0]*m[7]*m[14]+m[4]*m[2]*m[15]-m[4]*m[3]*m[14]-m[12]*m[2]*m[7]+m[12]*m[3]*m[6];
  inv[10] = m[0]*m[5]*m[15]-m[0]*m[7]*m[13]-m[4]*m[1]*m[15]+m[4]*m[3]*m[13]+m[12]*m[1]*m[7]-m[12]*m[3]*m[5];
  inv[14] = -m[0]*m[5]*m[14]+m[0]*m[6]*m[13]+m[4]*m[1]*m[14]-m[4]*m[2]*m[13]-m[12]*m[1]*m[6]+m[12]*m[2]*m[5];
  inv[3] = -m[1]*m[6]*m[11]+m[1]*m[7]*m[10]+m[5]*m[2]*m[11]-m[5]*m[3]*m[10]-m[9]*m[2]*m[7]+m[9]*m[3]*m[6];
  inv[7] = m[0]*m[6]*m[11]-m[0]*m[7]*m[10]-m[4]*m[2]*m[11]+m[4]*m[3]*m[10]+m[8]*m[2]*m[7]-m[8]*m[3]*m[6];
  inv[11] = -m[0]*m[5]*m[11]+m[0]*m[7]*m[9]+m[4]*m[1]*m[11]-m[4]*m[3]*m[9]-m[8]*m[1]*m[7]+m[8]*m[3]*m[5];
  inv[15] = m[0]*m[5]*m[10]-m[0]*m[6]*m[9]-m[4]*m[1]*m[10]+m[4]*m[2]*m[9]+m[8]*m[1]*m[6]-m[8]*m[2]*m[5];
  const det = m[0] * inv[0] + m[1] * inv[4] + m[2] * inv[8] + m[3] * inv[12];
  for (let i = 0; i < 16; i++) inv[i] /= det;
  return inv;
}
function xform(m, p) { // point -> clip (x, y, z, w)
  return [0, 1, 2, 3].map((r) => m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r]);
}

// ---------- camera ----------
const axisVec = (i) => [0, 1, 2].map((k) => (k === i ? 1 : 0));
const cam = { center: [0, 0, 0], dist: 1, radius: 1, yaw: 0, pitch: 0, up: [0, 1, 0], front: [0, 0, 1], fovy: 30 * Math.PI / 180 };
function frameCamera() {
  const d = S.desc, lo = d.bbox.min, hi = d.bbox.max;
  cam.center = [0, 1, 2].map((k) => 0.5 * (lo[k] + hi[k]));
  cam.radius = Math.max(1e-9, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
  cam.dist = 1.08 * cam.radius / Math.sin(cam.fovy / 2);
  cam.up = axisVec(d.up_axis); cam.front = scl(axisVec(d.view_axis), d.view_sign || 1); cam.yaw = 0; cam.pitch = 0;
}
function eye() {
  const r = cross(cam.up, cam.front), cp = Math.cos(cam.pitch);
  const e = add(add(scl(cam.front, cp * Math.cos(cam.yaw)), scl(r, cp * Math.sin(cam.yaw))), scl(cam.up, Math.sin(cam.pitch)));
  return add(cam.center, scl(e, cam.dist));
}
function matrices() {
  const aspect = canvas.clientWidth / Math.max(1, canvas.clientHeight);
  const view = lookAt(eye(), cam.center, cam.up);
  const proj = perspective(cam.fovy, aspect, cam.dist * 0.01, cam.dist * 10 + cam.radius * 4);
  return { view, proj, vp: mul(proj, view) };
}
// CSS-pixel position (relative to the viewport) and depth of a world point.
function screenOf(p) {
  const { vp } = matrices(), c = xform(vp, p), rect = canvas.getBoundingClientRect();
  return [rect.left + (c[0] / c[3] + 1) / 2 * rect.width, rect.top + (1 - c[1] / c[3]) / 2 * rect.height, c[2] / c[3]];
}
function rayAt(clientX, clientY) {
  const rect = canvas.getBoundingClientRect();
  const x = (clientX - rect.left) / rect.width * 2 - 1, y = 1 - (clientY - rect.top) / rect.height * 2;
  const inv = invert(matrices().vp);
  const a = xform(inv, [x, y, -1]), b = xform(inv, [x, y, 1]);
  const p0 = [a[0] / a[3], a[1] / a[3], a[2] / a[3]], p1 = [b[0] / b[3], b[1] / b[3], b[2] / b[3]];
  return { o: p0, d: nrmz(sub(p1, p0)) };
}
const vtx = (i) => [S.pos[3 * i], S.pos[3 * i + 1], S.pos[3 * i + 2]];

// Nearest hit of a ray with the current surface (Möller–Trumbore over every triangle); returns
// the hit triangle's vertex nearest to the hit point, or -1.
function pick(clientX, clientY) {
  const { o, d } = rayAt(clientX, clientY), P = S.pos, F = S.faces;
  let best = Infinity, bf = -1;
  for (let f = 0; f < F.length; f += 3) {
    const a = 3 * F[f], b = 3 * F[f + 1], c = 3 * F[f + 2];
    const e1x = P[b] - P[a], e1y = P[b + 1] - P[a + 1], e1z = P[b + 2] - P[a + 2];
    const e2x = P[c] - P[a], e2y = P[c + 1] - P[a + 1], e2z = P[c + 2] - P[a + 2];
    const px = d[1] * e2z - d[2] * e2y, py = d[2] * e2x - d[0] * e2z, pz = d[0] * e2y - d[1] * e2x;
    const det = e1x * px + e1y * py + e1z * pz;
    if (Math.abs(det) < 1e-20) continue;
    const inv = 1 / det, tx = o[0] - P[a], ty = o[1] - P[a + 1], tz = o[2] - P[a + 2];
    const u = (tx * px + ty * py + tz * pz) * inv; if (u < 0 || u > 1) continue;
    const qx = ty * e1z - tz * e1y, qy = tz * e1x - tx * e1z, qz = tx * e1y - ty * e1x;
    const v = (d[0] * qx + d[1] * qy + d[2] * qz) * inv; if (v < 0 || u + v > 1) continue;
    const t = (e2x * qx + e2y * qy + e2z * qz) * inv;
    if (t > 0 && t < best) { best = t; bf = f; }
  }
  if (bf < 0) return -1;
  const hit = add(o, scl(d, best));
  let bv = -1, bd = Infinity;
  for (let j = 0; j < 3; j++) {
    const v = F[bf + j], q = vtx(v), dd = dot(sub(q, hit), sub(q, hit));
    if (dd < bd) { bd = dd; bv = v; }
  }
  return bv;
}

// ---------- GL ----------
function shader(type, src) {
  const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}
function program(vs, fs) {
  const p = gl.createProgram();
  gl.attachShader(p, shader(gl.VERTEX_SHADER, vs)); gl.attachShader(p, shader(gl.FRAGMENT_SHADER, fs));
  gl.bindAttribLocation(p, 0, 'aPos'); gl.bindAttribLocation(p, 1, 'aNrm'); gl.bindAttribLocation(p, 2, 'aCol');
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}
const G = {};
function initGL() {
  G.mesh = program(`#version 300 es
    layout(location=0) in vec3 aPos; layout(location=1) in vec3 aNrm; layout(location=2) in vec3 aCol;
    uniform mat4 uVP; uniform mat4 uView; out vec3 vN; out vec3 vC; out vec3 vV;
    void main() { gl_Position = uVP * vec4(aPos, 1.0); vN = mat3(uView) * aNrm; vC = aCol; vV = (uView * vec4(aPos, 1.0)).xyz; }`,
  `#version 300 es
    precision highp float; in vec3 vN; in vec3 vC; in vec3 vV; out vec4 o;
    void main() {
      vec3 n = normalize(vN); vec3 v = normalize(-vV); if (dot(n, v) < 0.0) n = -n;
      vec3 l = normalize(vec3(-0.3, 0.5, 1.0)); float d = max(dot(n, l), 0.0);
      float s = pow(max(dot(reflect(-l, n), v), 0.0), 40.0) * 0.25;
      o = vec4(vC * (0.22 + 0.78 * d) + vec3(s), 1.0);
    }`);
  G.flat = program(`#version 300 es
    layout(location=0) in vec3 aPos; uniform mat4 uVP; uniform float uSize;
    void main() { gl_Position = uVP * vec4(aPos, 1.0); gl_Position.z -= 0.0005 * gl_Position.w; gl_PointSize = uSize; }`,
  `#version 300 es
    precision highp float; uniform vec4 uColor; out vec4 o; void main() { o = uColor; }`);
  G.vao = gl.createVertexArray(); gl.bindVertexArray(G.vao);
  G.bPos = gl.createBuffer(); G.bNrm = gl.createBuffer(); G.bCol = gl.createBuffer();
  G.bIdx = gl.createBuffer(); G.bEdge = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bPos); gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bNrm); gl.enableVertexAttribArray(1); gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bCol); gl.enableVertexAttribArray(2); gl.vertexAttribPointer(2, 3, gl.UNSIGNED_BYTE, true, 0, 0);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, G.bIdx); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, S.faces, gl.STATIC_DRAW);
  gl.bindVertexArray(null);
  // Wireframe: every edge once.
  const seen = new Set(), edges = [];
  for (let f = 0; f < S.faces.length; f += 3) for (let j = 0; j < 3; j++) {
    let a = S.faces[f + j], b = S.faces[f + (j + 1) % 3]; if (a > b) [a, b] = [b, a];
    const key = a * S.n + b; if (!seen.has(key)) { seen.add(key); edges.push(a, b); }
  }
  G.nEdges = edges.length;
  G.evao = gl.createVertexArray(); gl.bindVertexArray(G.evao);
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bPos); gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, G.bEdge); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(edges), gl.STATIC_DRAW);
  gl.bindVertexArray(null);
  G.pvao = gl.createVertexArray(); gl.bindVertexArray(G.pvao);
  G.bPin = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, G.bPin); gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);
}

function computeNormals() {
  const P = S.pos, F = S.faces, N = S.nrm; N.fill(0);
  for (let f = 0; f < F.length; f += 3) {
    const a = 3 * F[f], b = 3 * F[f + 1], c = 3 * F[f + 2];
    const ux = P[b] - P[a], uy = P[b + 1] - P[a + 1], uz = P[b + 2] - P[a + 2];
    const vx = P[c] - P[a], vy = P[c + 1] - P[a + 1], vz = P[c + 2] - P[a + 2];
    const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx; // area-weighted
    N[a] += nx; N[a + 1] += ny; N[a + 2] += nz; N[b] += nx; N[b + 1] += ny; N[b + 2] += nz; N[c] += nx; N[c + 1] += ny; N[c + 2] += nz;
  }
  for (let i = 0; i < N.length; i += 3) {
    const l = Math.hypot(N[i], N[i + 1], N[i + 2]) || 1; N[i] /= l; N[i + 1] /= l; N[i + 2] /= l;
  }
}

const RAMP = [[68,1,84],[71,44,122],[59,81,139],[44,113,142],[33,144,141],[39,173,129],[92,200,99],[170,220,50],[253,231,37]];
// Colours `values` on the ramp from 0 to the fixed range (the range box) or, when it is empty,
// to the largest value; returns that upper end (the colour bar shows it with its unit).
function ramp(values) {
  let hi = 0; for (let i = 0; i < values.length; i++) if (values[i] > hi) hi = values[i];
  if (S.fixedMax > 0) hi = S.fixedMax;
  const out = S.col;
  for (let i = 0; i < values.length; i++) {
    const t = hi > 0 ? Math.min(1, Math.max(0, values[i] / hi)) : 0, x = t * 8, k = Math.min(7, Math.floor(x)), a = x - k;
    for (let c = 0; c < 3; c++) out[3 * i + c] = Math.round(RAMP[k][c] * (1 - a) + RAMP[k + 1][c] * a);
  }
  return hi;
}
function colours() {
  const C = S.col, n = S.n;
  let note = '', bar = null;
  if (S.overlay === 'displacement') {
    const d = new Float32Array(n);
    for (let i = 0; i < n; i++) d[i] = Math.hypot(S.pos[3 * i] - S.rest[3 * i], S.pos[3 * i + 1] - S.rest[3 * i + 1], S.pos[3 * i + 2] - S.rest[3 * i + 2]);
    bar = { hi: ramp(d), unit: 'data units' };
    note = `displacement from rest: scale 0 … ${bar.hi.toPrecision(3)} data units`;
  } else if (S.overlay === 'heat' && S.selected >= 0 && S.heat.has(S.selected)) {
    bar = { hi: ramp(S.heat.get(S.selected)), unit: 'magnitude (data units at dial 1)' };
    note = `heat map of component ${S.selected}: scale 0 … ${bar.hi.toPrecision(3)}`;
  } else if (S.overlay === 'segmentation' && S.seg) {
    for (let i = 0; i < n; i++) {
      const h = (S.seg[i] * 0.618034) % 1, rgb = hsv(h, 0.55, 0.95);
      C[3 * i] = rgb[0]; C[3 * i + 1] = rgb[1]; C[3 * i + 2] = rgb[2];
    }
    note = `${S.desc.segmentation_groups} support groups`;
  } else if (S.overlay === 'error' && S.frameErr) {
    bar = { hi: ramp(S.frameErr), unit: 'data units' };
    note = `frame error: scale 0 … ${bar.hi.toPrecision(3)} data units, Erms ${(+S.frameErms).toPrecision(4)}`;
  } else C.fill(200);
  S.colorbar = bar;
  // The panel is touched only where it changes: a drag recolours every frame, and each change
  // of the page's layout costs a repaint beside the canvas.
  setText($('cbar-hi'), bar ? `${bar.hi.toPrecision(3)}` : ''); setText($('range-unit'), bar ? bar.unit : '');
  setShown($('cbar-row'), !!bar); setShown($('range-row'), !!bar);
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bCol); gl.bufferData(gl.ARRAY_BUFFER, C, gl.DYNAMIC_DRAW);
  S.overlayNote = note;
}
function hsv(h, s, v) {
  const i = Math.floor(h * 6), f = h * 6 - i, p = v * (1 - s), q = v * (1 - f * s), t = v * (1 - (1 - f) * s);
  const r = [[v, t, p], [q, v, p], [p, v, t], [p, q, v], [t, p, v], [v, p, q]][i % 6];
  return r.map((x) => Math.round(255 * x));
}

function uploadGeometry() {
  computeNormals();
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bPos); gl.bufferData(gl.ARRAY_BUFFER, S.pos, gl.DYNAMIC_DRAW);
  gl.bindBuffer(gl.ARRAY_BUFFER, G.bNrm); gl.bufferData(gl.ARRAY_BUFFER, S.nrm, gl.DYNAMIC_DRAW);
  if (S.overlay === 'displacement') colours();
}

function draw(sync) {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  gl.viewport(0, 0, w, h);
  gl.clearColor(0.114, 0.122, 0.141, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST);
  const { view, vp } = matrices(), f32 = (m) => new Float32Array(m);
  gl.useProgram(G.mesh);
  gl.uniformMatrix4fv(gl.getUniformLocation(G.mesh, 'uVP'), false, f32(vp));
  gl.uniformMatrix4fv(gl.getUniformLocation(G.mesh, 'uView'), false, f32(view));
  gl.enable(gl.POLYGON_OFFSET_FILL); gl.polygonOffset(1, 1);
  gl.bindVertexArray(G.vao); gl.drawElements(gl.TRIANGLES, S.faces.length, gl.UNSIGNED_INT, 0);
  gl.disable(gl.POLYGON_OFFSET_FILL);
  gl.useProgram(G.flat);
  gl.uniformMatrix4fv(gl.getUniformLocation(G.flat, 'uVP'), false, f32(vp));
  if (S.wire) {
    gl.uniform4f(gl.getUniformLocation(G.flat, 'uColor'), 0.1, 0.1, 0.12, 1);
    gl.bindVertexArray(G.evao); gl.drawElements(gl.LINES, G.nEdges, gl.UNSIGNED_INT, 0);
  }
  const pins = [...S.pins.values()]; if (S.drag && S.drag.target) pins.push(S.drag.target);
  if (pins.length) {
    gl.disable(gl.DEPTH_TEST);
    gl.bindBuffer(gl.ARRAY_BUFFER, G.bPin); gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(pins.flat()), gl.DYNAMIC_DRAW);
    gl.uniform1f(gl.getUniformLocation(G.flat, 'uSize'), 9 * dpr);
    gl.uniform4f(gl.getUniformLocation(G.flat, 'uColor'), 1, 0.25, 0.2, 1);
    gl.bindVertexArray(G.pvao); gl.drawArrays(gl.POINTS, 0, pins.length);
  }
  gl.bindVertexArray(null);
  if (sync) { const px = new Uint8Array(4); gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px); } // wait for the GPU
  setText($('hud'), `${S.desc.kind} · ${S.n} vertices · ${S.overlayNote || ''}`);
}
let drawQueued = false;
function redraw() { if (!drawQueued) { drawQueued = true; requestAnimationFrame(() => { drawQueued = false; draw(false); }); } }

// ---------- API: one request in flight, the newest waiting one wins ----------
let inflight = false, pending = null;
function submit(job) { pending = job; pump(); }
async function pump() {
  if (inflight || !pending) return;
  const job = pending; pending = null; inflight = true;
  try {
    const tSend = performance.now();
    const r = await api(job.url, { method: job.body ? 'POST' : 'GET', body: job.body ? JSON.stringify(job.body) : undefined, headers: { 'Content-Type': 'application/json' } });
    if (r.status === 409) {
      // A newer pose request superseded this one on the server; its answer follows.
    } else if (!r.ok) {
      const e = await r.json().catch(() => ({ error: r.statusText }));
      showError(`${job.url}: ${r.status} ${e.error}`);
    } else {
      const buf = await r.arrayBuffer(); const tRecv = performance.now();
      showError('');
      applyShape(buf, r, job);
      uploadGeometry(); const tGeom = performance.now();
      draw(true); const tDrawn = performance.now();
      const server = parseFloat(r.headers.get('X-Compute-Ms') || '0');
      S.latencies.push({ kind: job.kind, total: tDrawn - job.t0, queued: tSend - job.t0, server, http: tRecv - tSend - server, geometry: tGeom - tRecv, draw: tDrawn - tGeom });
      if (S.latencies.length > 2000) S.latencies.shift();
      showLatency();
    }
  } catch (e) { showError(String(e)); }
  finally { inflight = false; S.served = (S.served || 0) + 1; pump(); }
}
const idle = () => !inflight && !pending;
function applyShape(buf, r, job) {
  const dv = new DataView(buf), n = dv.getUint32(0, true), k = dv.getUint32(4, true);
  S.weights = new Float64Array(buf.slice(8, 8 + 8 * k)); S.dials = new Float64Array(buf.slice(8 + 8 * k, 8 + 16 * k));
  const off = 8 + 16 * k;
  S.pos = new Float32Array(buf.slice(off, off + 12 * n));
  if (job.kind === 'frame') {
    S.frameRec = S.pos; S.frameTruth = new Float32Array(buf.slice(off + 12 * n, off + 24 * n));
    S.frameErr = new Float32Array(buf.slice(off + 24 * n, off + 28 * n));
    S.frameErms = r.headers.get('X-Frame-Erms');
    $('frame-info').textContent = `${r.headers.get('X-Frame-Name')}: ${S.frameErms === null ? 'its training weights, blended' : `Erms ${(+S.frameErms).toPrecision(4)}`}`;
    if (document.querySelector('input[name=fshow]:checked').value === 'frame') S.pos = S.frameTruth;
    if (S.overlay === 'error') colours();
  }
  if (job.kind !== 'slider') syncSliders();
}
function showLatency() {
  const by = {};
  for (const l of S.latencies) (by[l.kind] = by[l.kind] || []).push(l);
  const med = (a, f) => { const v = a.map(f).sort((x, y) => x - y); return v[Math.floor(v.length / 2)]; };
  $('lat').innerHTML = Object.entries(by).map(([k, a]) =>
    `${k} (${a.length}): event→drawn median ${med(a, (l) => l.total).toFixed(1)} ms [server ${med(a, (l) => l.server).toFixed(1)}, http ${med(a, (l) => l.http).toFixed(1)}, normals+upload ${med(a, (l) => l.geometry).toFixed(1)}, draw ${med(a, (l) => l.draw).toFixed(1)}]`).join('<br>');
}

// ---------- components panel ----------
const sliders = new Map();
function buildComponents() {
  const box = $('comps'); box.innerHTML = '';
  for (const c of S.desc.components) {
    const row = document.createElement('div'); row.className = 'comp'; row.dataset.index = c.index;
    const name = document.createElement('span'); name.className = 'name'; name.textContent = c.name; name.title = `index ${c.index}, rank ${c.rank}, centre vertex ${c.center}: click to show its heat map`;
    const sl = document.createElement('input'); sl.type = 'range'; sl.min = c.range[0]; sl.max = c.range[1];
    sl.step = String((c.range[1] - c.range[0]) / 1000); sl.value = S.dials[c.index]; sl.dataset.index = c.index;
    const val = document.createElement('span'); val.className = 'val';
    const rs = document.createElement('button'); rs.textContent = '↺'; rs.title = 'reset to 0';
    row.append(name, sl, val, rs); box.append(row);
    sliders.set(c.index, { sl, val, row, range: c.range });
    name.onclick = () => select(c.index);
    let gesture = false;
    sl.addEventListener('input', () => {
      const t0 = performance.now();
      if (!gesture) { pushUndo(); gesture = true; }
      S.dials[c.index] = parseFloat(sl.value); val.textContent = S.dials[c.index].toFixed(3);
      submit({ url: '/api/decode', body: { dials: Array.from(S.dials) }, kind: 'slider', t0 });
    });
    sl.addEventListener('change', () => { gesture = false; });
    // Pressing a slider highlights its row; its heat map is a click on its name.
    sl.addEventListener('pointerdown', () => { for (const [j, s2] of sliders) s2.row.classList.toggle('sel', j === c.index); });
    rs.onclick = () => { pushUndo(); S.dials[c.index] = 0; syncSliders(); submit({ url: '/api/decode', body: { dials: Array.from(S.dials) }, kind: 'reset', t0: performance.now() }); };
  }
  syncSliders();
}
// A dial beyond its slider's range (a pose or a loaded weights file can go there) widens the
// slider to show it and marks the value: beyond the training range.
// Each property is written only when it differs from the element's (a pose updates every dial
// on every drag event).
function syncSliders() {
  for (const [i, s] of sliders) {
    const d = S.dials[i], c = s.range, lo = Math.min(c[0], d), hi = Math.max(c[1], d);
    if (+s.sl.min !== lo) s.sl.min = lo;
    if (+s.sl.max !== hi) s.sl.max = hi;
    if (+s.sl.value !== d) s.sl.value = d;
    setText(s.val, d.toFixed(3));
    const out = d < c[0] || d > c[1];
    if (s.val.classList.contains('over') !== out) {
      s.val.classList.toggle('over', out);
      s.val.title = out ? `beyond the training range [${c[0].toFixed(2)}, ${c[1].toFixed(2)}]` : '';
    }
  }
}
async function select(i) {
  S.selected = i;
  for (const [j, s] of sliders) s.row.classList.toggle('sel', j === i);
  if (!S.heat.has(i)) {
    const r = await api(`/api/heat/${i}`);
    if (!r.ok) { showError((await r.json()).error); return; }
    S.heat.set(i, new Float32Array(await r.arrayBuffer()));
  }
  if (S.overlay === 'none' || S.overlay === 'heat') { S.overlay = 'heat'; $('overlay').value = 'heat'; }
  colours(); redraw();
}

// ---------- undo, pins ----------
function pushUndo() {
  S.undo.push({ weights: Float64Array.from(S.weights), pins: new Map(S.pins) });
  if (S.undo.length > 200) S.undo.shift();
}
function undo() {
  const u = S.undo.pop(); if (!u) return;
  S.pins = u.pins; showPins();
  submit({ url: '/api/decode', body: { weights: Array.from(u.weights) }, kind: 'undo', t0: performance.now() });
}
function showPins() {
  const box = $('pins'); box.innerHTML = '';
  for (const [v, t] of S.pins) {
    const d = document.createElement('div');
    d.innerHTML = `pin vertex ${v} → (${t.map((x) => x.toPrecision(4)).join(', ')}) `;
    const b = document.createElement('button'); b.textContent = '×'; b.title = 'remove this pin';
    b.onclick = () => { pushUndo(); S.pins.delete(v); showPins(); redraw(); };
    d.append(b); box.append(d);
  }
  if (!S.pins.size) box.textContent = 'no pins: drag a point of the surface';
}
function poseParams() {
  return { gamma: Math.pow(10, parseFloat($('gamma').value)), beta: Math.pow(10, parseFloat($('beta').value)), spread: parseFloat($('spread').value) };
}
// While the pointer moves, solvers with iterations (the autoencoder's Gauss–Newton) run at most
// DRAG_ITERATIONS, warm-started from the previous solve; the release solves once more in full.
const DRAG_ITERATIONS = 4;
function requestPose(t0, final) {
  const cons = [];
  for (const [v, t] of S.pins) if (!S.drag || v !== S.drag.v) cons.push({ vertex: v, target: t });
  if (S.drag) cons.push({ vertex: S.drag.v, target: S.drag.target });
  if (!cons.length) return;
  const p = poseParams();
  // The pull is towards the shape the drag began from (S.dragBase), not towards the last answer
  // of the same drag: otherwise each move pulls only towards the previous one and a long drag
  // drifts as if the pull were off.
  const base = S.dragBase || S.weights;
  const body = { constraints: cons, start: Array.from(base), gamma: p.gamma, beta: p.beta, prior: S.prior, spread: p.spread };
  if (!final) body.max_iterations = DRAG_ITERATIONS;
  submit({ url: '/api/pose', body, kind: final ? 'release' : 'drag', t0 });
}

// ---------- pointer input ----------
let ptr = null;
canvas.addEventListener('contextmenu', (e) => e.preventDefault());
canvas.addEventListener('pointerdown', (e) => {
  canvas.setPointerCapture(e.pointerId);
  if (S.standalone && e.button === 0 && !e.shiftKey) { ptr = { mode: 'orbit', x: e.clientX, y: e.clientY }; return; }
  if (e.button === 0 && e.altKey) {
    // Alt-click: pin a point where it is, to hold its part in place while others are dragged.
    const v = pick(e.clientX, e.clientY);
    if (v >= 0) { pushUndo(); S.pins.set(v, vtx(v)); showPins(); redraw(); }
    return;
  }
  if (e.button === 0 && !e.shiftKey) {
    const v = pick(e.clientX, e.clientY);
    if (v >= 0) {
      pushUndo();
      const p = vtx(v), { view } = matrices();
      const fwd = [-view[2], -view[6], -view[10]]; // camera looks along −z of view space
      S.drag = { v, start: p, target: p, normal: fwd };
      S.dragBase = Float64Array.from(S.weights);
      ptr = { mode: 'pose', x: e.clientX, y: e.clientY };
      redraw(); return;
    }
    ptr = { mode: 'orbit', x: e.clientX, y: e.clientY };
  } else ptr = { mode: 'pan', x: e.clientX, y: e.clientY };
});
canvas.addEventListener('pointermove', (e) => {
  if (!ptr) return;
  const t0 = performance.now(), dx = e.clientX - ptr.x, dy = e.clientY - ptr.y;
  if (ptr.mode === 'pose') {
    const { o, d } = rayAt(e.clientX, e.clientY), n = S.drag.normal;
    const t = dot(sub(S.drag.start, o), n) / dot(d, n);
    S.drag.target = add(o, scl(d, t));
    requestPose(t0);
    return;
  }
  ptr.x = e.clientX; ptr.y = e.clientY;
  if (ptr.mode === 'orbit') {
    cam.yaw -= dx * 0.008; cam.pitch = Math.max(-1.55, Math.min(1.55, cam.pitch + dy * 0.008));
  } else {
    const { view } = matrices(), s = 2 * cam.dist * Math.tan(cam.fovy / 2) / canvas.clientHeight;
    const right = [view[0], view[4], view[8]], up = [view[1], view[5], view[9]];
    cam.center = add(cam.center, add(scl(right, -dx * s), scl(up, dy * s)));
  }
  redraw();
});
function endPointer() {
  if (ptr && ptr.mode === 'pose' && S.drag) {
    const moved = S.drag.target !== S.drag.start;
    if (moved) { S.pins.set(S.drag.v, S.drag.target); showPins(); }
    S.lastDrag = { v: S.drag.v, start: S.drag.start, target: S.drag.target };
    S.drag = null; redraw();
    if (moved) requestPose(performance.now(), true);
    S.dragBase = null;
  }
  ptr = null;
}
canvas.addEventListener('pointerup', endPointer);
canvas.addEventListener('pointercancel', endPointer);
canvas.addEventListener('wheel', (e) => { e.preventDefault(); cam.dist *= Math.exp(e.deltaY * 0.001); redraw(); }, { passive: false });
window.addEventListener('resize', redraw);

// ---------- frames, save ----------
function loadFrame(i) {
  // The box shows frame numbers from 1 (as the file names and --frames count); the API is 0-based.
  const n = S.desc.frames.names.length; i = Math.max(0, Math.min(n - 1, i)); $('frame-i').value = i + 1;
  submit({ url: `/api/frame/${i}`, kind: 'frame', t0: performance.now() });
}
async function save(fmt) {
  const r = await api('/api/export', { method: 'POST', body: JSON.stringify({ format: fmt, weights: Array.from(S.weights) }) });
  if (!r.ok) { showError((await r.json()).error); return; }
  const blob = await r.blob(), a = document.createElement('a');
  a.href = URL.createObjectURL(blob); a.download = fmt === 'json' ? 'weights.json' : `shape.${fmt}`; a.click();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

// ---------- start ----------
async function start() {
  if (!gl) { showError('this browser has no WebGL2'); return; }
  const local = window.meshdecoEmbedded && await window.meshdecoEmbedded();
  if (local) api = local;
  const get = async (u) => { const r = await api(u); if (!r.ok) throw new Error(`${u}: ${r.status}`); return r; };
  S.desc = await (await get('/api/model')).json();
  S.n = S.desc.n_vertices; S.k = S.desc.n_components;
  S.faces = new Uint32Array(await (await get('/api/faces')).arrayBuffer());
  S.rest = new Float32Array(await (await get('/api/rest')).arrayBuffer());
  S.seg = new Uint32Array(await (await get('/api/segmentation')).arrayBuffer());
  S.nrm = new Float32Array(3 * S.n); S.col = new Uint8Array(3 * S.n).fill(200);
  S.weights = Float64Array.from(S.desc.start.weights); S.dials = Float64Array.from(S.desc.start.dials);
  $('title').textContent = `${S.desc.model} — ${S.desc.kind}`;
  $('info').textContent = `${S.desc.representation} representation, ${S.n} vertices, ${S.desc.n_faces} faces, ${S.k} weights; start: ${S.desc.start.description}`;
  $('ranges').textContent = `(ranges: ${S.desc.ranges_from})`;
  S.standalone = S.desc.standalone || null;
  if (S.standalone) {
    // No model to solve with: posing, the frame's own shape and its error need `meshdeco view`.
    for (const id of ['pose-box', 'pose-hint', 'fshow']) $(id).style.display = 'none';
    $('standalone').textContent = S.standalone.note; $('standalone').style.display = '';
    document.title = `meshdeco — ${S.desc.model}`;
  }
  // Pose options: the model's defaults, or ?gamma=…&beta=…&prior=shape|weights&spread=… in the page's URL.
  const Q = new URLSearchParams(location.search), g = S.desc.pose_defaults;
  $('gamma').value = Math.log10(+(Q.get('gamma') || g.gamma)); $('beta').value = Math.log10(+(Q.get('beta') || g.beta));
  S.prior = Q.get('prior') || g.prior;
  $('spread').value = +(Q.get('spread') ?? g.spread);
  const pv = () => {
    const p = poseParams(); $('gamma-v').textContent = p.gamma.toPrecision(2); $('beta-v').textContent = p.beta.toPrecision(2);
    $('spread-v').textContent = p.spread > 0 ? p.spread.toFixed(2) : 'off';
  };
  $('gamma').oninput = pv; $('beta').oninput = pv; $('spread').oninput = pv; pv();
  if (!S.desc.pose_parameters.includes('beta')) $('beta-row').style.display = 'none';
  initGL(); frameCamera(); buildComponents(); showPins(); colours();
  // Start shape: the decoding of the start weights.
  const r = await api('/api/decode', { method: 'POST', body: JSON.stringify({ weights: Array.from(S.weights) }) });
  applyShape(await r.arrayBuffer(), r, { kind: 'start' }); uploadGeometry();
  $('overlay').onchange = () => { S.overlay = $('overlay').value; if (S.overlay === 'heat' && S.selected < 0) select(S.desc.components[0].index); colours(); redraw(); };
  $('wire').onchange = () => { S.wire = $('wire').checked; redraw(); };
  $('range-max').onchange = () => { const x = parseFloat($('range-max').value); S.fixedMax = x > 0 ? x : 0; colours(); redraw(); };
  $('frame-btn').onclick = () => { frameCamera(); redraw(); };
  $('reset-all').onclick = () => { pushUndo(); S.dials.fill(0); syncSliders(); submit({ url: '/api/decode', body: { dials: Array.from(S.dials) }, kind: 'reset', t0: performance.now() }); };
  $('undo').onclick = undo;
  $('clear-pins').onclick = () => { pushUndo(); S.pins.clear(); showPins(); redraw(); };
  window.addEventListener('keydown', (e) => { if ((e.ctrlKey || e.metaKey) && e.key === 'z') { e.preventDefault(); undo(); } });
  for (const b of document.querySelectorAll('button.save')) b.onclick = () => save(b.dataset.fmt);
  if (S.desc.frames) {
    $('frames-box').style.display = ''; $('opt-error').disabled = !!S.standalone;
    $('frame-i').max = S.desc.frames.names.length;
    $('prev').onclick = () => loadFrame(+$('frame-i').value - 2);
    $('next').onclick = () => loadFrame(+$('frame-i').value);
    $('frame-i').onchange = () => loadFrame(+$('frame-i').value - 1);
    for (const r of document.querySelectorAll('input[name=fshow]')) r.onchange = () => { if (S.frameRec) { S.pos = r.value === 'frame' && r.checked ? S.frameTruth : S.frameRec; uploadGeometry(); redraw(); } };
  }
  draw(true);
  S.ready = true;
}

// Read-only hooks for tests and scripts (the tests drive the page with real input events).
window.meshdeco = {
  S, idle, screenOf, vertex: (i) => vtx(i),
  ready: () => S.ready,
  latencies: () => S.latencies,
};
start().catch((e) => showError(String(e.stack || e)));
