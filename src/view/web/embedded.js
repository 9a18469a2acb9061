// meshdeco's standalone page (`meshdeco export MODEL --out view.html`, `Model.show()` in Python):
// the model's neutral mesh and blendshapes are embedded in the page, and this script answers the
// routes of the live viewer's API (src/view/mod.rs) inside the page, so that app.js runs
// unchanged against either data source. No server, no network request: the data are a gzip'd
// binary block, base64 in the page, unpacked with the browser's DecompressionStream.
//
// The block (little-endian, each array 8-byte aligned; `layout`: name → [byte offset, count]):
// faces u32 T×3, rest f32 N×3 (the model's rest mesh), base f32 N×3 (the neutral shape, all
// dials 0), segmentation u32 N, targets (int16: K×N×3, target k = q × scales[k]; float32: the
// deltas as they are), heat u16 K×N (magnitude = q / 65535 × peak), frame_dials f64 F×K.
// A shape is base + Σ_k dial_k × target_k (weights = dials: the page blends in dial space).
'use strict';
window.meshdecoEmbedded = async function meshdecoEmbedded() {
  const el = document.getElementById('meshdeco-embedded');
  if (!el) return null;
  const E = JSON.parse(el.textContent);
  const packed = Uint8Array.from(atob(E.blob), (c) => c.charCodeAt(0));
  const buf = await new Response(new Blob([packed]).stream().pipeThrough(new DecompressionStream('gzip'))).arrayBuffer();
  const at = (T, name) => new T(buf, E.layout[name][0], E.layout[name][1]);
  const desc = E.desc, n = desc.n_vertices, k = desc.n_components;
  const faces = at(Uint32Array, 'faces'), rest = at(Float32Array, 'rest'), base = at(Float32Array, 'base');
  const seg = at(Uint32Array, 'segmentation'), heat = at(Uint16Array, 'heat'), frameDials = at(Float64Array, 'frame_dials');
  const targets = at(E.targets === 'int16' ? Int16Array : Float32Array, 'targets');
  const scales = E.targets === 'int16' ? E.scales : new Array(k).fill(1);
  const names = (desc.frames && desc.frames.names) || [];

  function blend(dials) {
    const acc = Float64Array.from(base), m = 3 * n;
    for (let j = 0; j < k; j++) {
      const s = dials[j] * scales[j];
      if (s === 0) continue;
      for (let i = 0, o = j * m; i < m; i++) acc[i] += s * targets[o + i];
    }
    return Float32Array.from(acc);
  }
  // The binary shape of the API: u32 N, u32 K, K f64 weights, K f64 dials, N×3 f32 positions,
  // then `extra` (frames: the frame's positions and per-vertex error).
  function shape(dials, pos, extra) {
    const out = new ArrayBuffer(8 + 16 * k + 12 * n + extra.reduce((s, a) => s + a.byteLength, 0)), dv = new DataView(out);
    dv.setUint32(0, n, true); dv.setUint32(4, k, true);
    new Float64Array(out, 8, k).set(dials); new Float64Array(out, 8 + 8 * k, k).set(dials);
    let off = 8 + 16 * k;
    for (const a of [pos, ...extra]) { new Uint8Array(out, off, a.byteLength).set(new Uint8Array(a.buffer, a.byteOffset, a.byteLength)); off += a.byteLength; }
    return out;
  }
  const ok = (body, type, headers) => new Response(body, { status: 200, headers: { 'Content-Type': type, ...(headers || {}) } });
  const bin = (a) => ok(a.slice().buffer, 'application/octet-stream');
  const bad = (status, error) => new Response(JSON.stringify({ error }), { status, headers: { 'Content-Type': 'application/json' } });
  function vector(body) {
    const v = body.dials !== undefined ? body.dials : body.weights;
    if (!Array.isArray(v) || v.length !== k || !v.every(Number.isFinite)) throw new Error(`give ${k} finite dials`);
    return Float64Array.from(v);
  }
  function meshText(format, pos) {
    const lines = [];
    if (format === 'ply') {
      lines.push('ply', 'format ascii 1.0', `element vertex ${n}`, 'property float x', 'property float y', 'property float z',
        `element face ${faces.length / 3}`, 'property list uchar int vertex_indices', 'end_header');
      for (let i = 0; i < n; i++) lines.push(`${pos[3 * i]} ${pos[3 * i + 1]} ${pos[3 * i + 2]}`);
      for (let f = 0; f < faces.length; f += 3) lines.push(`3 ${faces[f]} ${faces[f + 1]} ${faces[f + 2]}`);
    } else {
      lines.push(`# ${desc.model} (${desc.kind}), meshdeco standalone page`);
      for (let i = 0; i < n; i++) lines.push(`v ${pos[3 * i]} ${pos[3 * i + 1]} ${pos[3 * i + 2]}`);
      for (let f = 0; f < faces.length; f += 3) lines.push(`f ${faces[f] + 1} ${faces[f + 1] + 1} ${faces[f + 2] + 1}`);
    }
    return lines.join('\n') + '\n';
  }

  return async function api(url, init) {
    const body = init && init.body ? JSON.parse(init.body) : null;
    try {
      switch (url) {
        case '/api/model': return ok(JSON.stringify(desc), 'application/json');
        case '/api/faces': return bin(faces);
        case '/api/rest': return bin(rest);
        case '/api/segmentation': return bin(seg);
        case '/api/decode': { const d = vector(body); return ok(shape(d, blend(d), []), 'application/octet-stream'); }
        case '/api/pose': return bad(400, 'posing needs the live viewer: meshdeco view MODEL');
        case '/api/export': {
          const d = vector(body), fmt = body.format || 'obj';
          if (fmt === 'json') return ok(JSON.stringify({ kind: desc.kind, dials: Array.from(d), weights: Array.from(d) }), 'application/json');
          return ok(meshText(fmt, blend(d)), 'text/plain; charset=utf-8');
        }
        default: break;
      }
      let m = /^\/api\/heat\/(\d+)$/.exec(url);
      if (m && +m[1] < k) {
        const i = +m[1], peak = desc.components.find((c) => c.index === i).peak, h = new Float32Array(n);
        for (let v = 0; v < n; v++) h[v] = heat[i * n + v] / 65535 * peak;
        return bin(h);
      }
      m = /^\/api\/frame\/(\d+)$/.exec(url);
      if (m && +m[1] < names.length) {
        const f = +m[1], d = frameDials.slice(f * k, (f + 1) * k), p = blend(d);
        return ok(shape(d, p, [p, new Float32Array(n)]), 'application/octet-stream', { 'X-Frame-Name': names[f] });
      }
      return bad(404, `no such route in the standalone page: ${url}`);
    } catch (e) {
      return bad(400, `${url}: ${e.message}`);
    }
  };
};
