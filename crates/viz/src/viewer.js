// The fmaps map viewer: two shapes side by side in WebGL, turning together,
// with colour transfer, texture transfer, the per-vertex error and picking.
// Everything it shows is in the page (the JSON block `fmaps-data`): it
// needs no network. Options after `#` in the address (for links and
// tests): mode=color|texture|error, pick=I (vertex I of A), click=X,Y
// (a click at canvas pixel X, Y).
(function () {
  "use strict";
  const status = document.getElementById("status");
  const errors = document.getElementById("errors");
  window.addEventListener("error", function (e) {
    errors.textContent += (e.message || String(e)) + "\n";
  });

  const D = JSON.parse(document.getElementById("fmaps-data").textContent);

  function decode(s, Type) {
    const bin = atob(s);
    const bytes = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Type(bytes.buffer);
  }

  // Vertex positions turned so that the shape's up axis is y, centred on
  // the bounding box and scaled into the unit ball.
  function positions(raw, up) {
    const n = raw.length / 3;
    const p = new Float32Array(raw.length);
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < n; i++) {
      let x = raw[3 * i], y = raw[3 * i + 1], z = raw[3 * i + 2];
      if (up === 2) { const t = y; y = z; z = -t; }
      else if (up === 0) { const t = x; x = -y; y = t; }
      p[3 * i] = x; p[3 * i + 1] = y; p[3 * i + 2] = z;
      for (let d = 0; d < 3; d++) {
        lo[d] = Math.min(lo[d], p[3 * i + d]);
        hi[d] = Math.max(hi[d], p[3 * i + d]);
      }
    }
    let r = 0;
    const c = [0, 1, 2].map(function (d) { return 0.5 * (lo[d] + hi[d]); });
    for (let i = 0; i < n; i++) {
      let s = 0;
      for (let d = 0; d < 3; d++) { p[3 * i + d] -= c[d]; s += p[3 * i + d] * p[3 * i + d]; }
      r = Math.max(r, s);
    }
    r = Math.sqrt(r) || 1;
    for (let i = 0; i < p.length; i++) p[i] /= r;
    return p;
  }

  function vertexNormals(p, f) {
    const nrm = new Float32Array(p.length);
    for (let t = 0; t < f.length; t += 3) {
      const a = 3 * f[t], b = 3 * f[t + 1], c = 3 * f[t + 2];
      const u = [p[b] - p[a], p[b + 1] - p[a + 1], p[b + 2] - p[a + 2]];
      const v = [p[c] - p[a], p[c + 1] - p[a + 1], p[c + 2] - p[a + 2]];
      const n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
      for (const k of [a, b, c]) for (let d = 0; d < 3; d++) nrm[k + d] += n[d];
    }
    for (let i = 0; i < nrm.length; i += 3) {
      const l = Math.hypot(nrm[i], nrm[i + 1], nrm[i + 2]) || 1;
      nrm[i] /= l; nrm[i + 1] /= l; nrm[i + 2] /= l;
    }
    return nrm;
  }

  // Source colours from the position, as the PNG pictures: each
  // coordinate over the bounding box drives one channel.
  function positionColors(p) {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < p.length; i++) {
      lo[i % 3] = Math.min(lo[i % 3], p[i]);
      hi[i % 3] = Math.max(hi[i % 3], p[i]);
    }
    const c = new Float32Array(p.length);
    for (let i = 0; i < p.length; i++) {
      const d = i % 3;
      c[i] = (40 + 215 * (p[i] - lo[d]) / Math.max(hi[d] - lo[d], 1e-30)) / 255;
    }
    return c;
  }

  // Values per source vertex carried to the target: each target vertex
  // gets the mean of the values of the source vertices mapped to it;
  // vertices no source vertex reaches take their nearest reached
  // neighbour's, along edges.
  function push(map, values, dim, nb, faces) {
    const out = new Float32Array(nb * dim), count = new Uint32Array(nb);
    for (let i = 0; i < map.length; i++) {
      const j = map[i];
      count[j]++;
      for (let d = 0; d < dim; d++) out[dim * j + d] += values[dim * i + d];
    }
    const queue = [];
    for (let j = 0; j < nb; j++) {
      if (count[j] > 0) {
        for (let d = 0; d < dim; d++) out[dim * j + d] /= count[j];
        queue.push(j);
      }
    }
    const adj = [];
    for (let j = 0; j < nb; j++) adj.push([]);
    for (let t = 0; t < faces.length; t += 3) {
      for (let k = 0; k < 3; k++) {
        const a = faces[t + k], b = faces[t + (k + 1) % 3];
        adj[a].push(b); adj[b].push(a);
      }
    }
    for (let q = 0; q < queue.length; q++) {
      const v = queue[q];
      for (const w of adj[v]) {
        if (count[w] === 0) {
          count[w] = 1;
          for (let d = 0; d < dim; d++) out[dim * w + d] = out[dim * v + d];
          queue.push(w);
        }
      }
    }
    return out;
  }

  const STOPS = [[68, 1, 84], [65, 68, 135], [42, 120, 142], [34, 168, 132], [122, 209, 81], [253, 231, 37]];
  function colormap(t) {
    if (!(t === t)) return [0.5, 0.5, 0.5];
    const s = Math.min(Math.max(t, 0), 1) * (STOPS.length - 1);
    const i = Math.min(Math.floor(s), STOPS.length - 2), f = s - i;
    return [0, 1, 2].map(function (d) { return (STOPS[i][d] + f * (STOPS[i + 1][d] - STOPS[i][d])) / 255; });
  }

  // The two shapes and what each mode draws on them.
  const A = { name: D.a.name, raw: decode(D.a.vertices, Float32Array), faces: decode(D.a.faces, Uint32Array) };
  // One shape (a mesh on its own): drawn alone, across the whole canvas.
  const single = !D.b;
  const B = single ? A : { name: D.b.name, raw: decode(D.b.vertices, Float32Array), faces: decode(D.b.faces, Uint32Array) };
  let map = null;
  if (single) {
    map = new Uint32Array(A.raw.length / 3);
    for (let i = 0; i < map.length; i++) map[i] = i;
  } else {
    map = decode(D.map_ab, Uint32Array);
  }
  const error = D.error ? decode(D.error, Float32Array) : null;
  for (const S of single ? [A] : [A, B]) {
    S.p = positions(S.raw, D.up);
    S.n = S.p.length / 3;
    S.normals = vertexNormals(S.p, S.faces);
  }
  A.colors = { color: positionColors(A.raw) };
  if (!single) B.colors = { color: push(map, A.colors.color, 3, B.n, B.faces) };
  // Texture: a planar parameterisation of A seen from the front.
  A.uv = new Float32Array(2 * A.n);
  for (let i = 0; i < A.n; i++) { A.uv[2 * i] = A.p[3 * i]; A.uv[2 * i + 1] = A.p[3 * i + 1]; }
  if (!single) B.uv = push(map, A.uv, 2, B.n, B.faces);
  const grey = function (S) { const c = new Float32Array(3 * S.n); c.fill(0.78); return c; };
  if (error) {
    A.colors.error = new Float32Array(3 * A.n);
    for (let i = 0; i < A.n; i++) A.colors.error.set(colormap(error[i] / D.error_max), 3 * i);
    B.colors.error = grey(B);
  }

  const canvas = document.getElementById("view");
  const gl = canvas.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
  if (!gl) {
    status.textContent = "This browser has no WebGL: the viewer cannot draw.";
    status.dataset.state = "no-webgl";
    return;
  }

  const VS = "attribute vec3 aPos; attribute vec3 aNormal; attribute vec3 aColor; attribute vec2 aUv;" +
    "uniform mat4 uMvp; uniform mat3 uRot; uniform float uPointSize;" +
    "varying vec3 vColor; varying vec2 vUv; varying float vLight;" +
    "void main() { gl_Position = uMvp * vec4(aPos, 1.0); gl_PointSize = uPointSize;" +
    " vec3 n = normalize(uRot * aNormal); vLight = 0.35 + 0.65 * abs(n.z); vColor = aColor; vUv = aUv; }";
  const FS = "precision mediump float; uniform int uMode; uniform float uSquares; uniform vec3 uFlat;" +
    "varying vec3 vColor; varying vec2 vUv; varying float vLight;" +
    "void main() { vec3 c = vColor;" +
    " if (uMode == 1) { vec2 q = floor(vUv * uSquares); c = mod(q.x + q.y, 2.0) < 0.5 ? vec3(0.93, 0.6, 0.2) : vec3(0.2, 0.25, 0.45); }" +
    " if (uMode == 2) { gl_FragColor = vec4(uFlat, 1.0); return; }" +
    " gl_FragColor = vec4(c * vLight, 1.0); }";
  function shader(type, src) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, VS));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, FS));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  gl.useProgram(prog);
  const loc = {};
  for (const a of ["aPos", "aNormal", "aColor", "aUv"]) loc[a] = gl.getAttribLocation(prog, a);
  for (const u of ["uMvp", "uRot", "uPointSize", "uMode", "uSquares", "uFlat"]) loc[u] = gl.getUniformLocation(prog, u);

  // Triangles unrolled (no 32-bit index extension needed): one entry per corner.
  function corners(S, values, dim) {
    const out = new Float32Array(S.faces.length * dim);
    for (let t = 0; t < S.faces.length; t++) {
      for (let d = 0; d < dim; d++) out[dim * t + d] = values[dim * S.faces[t] + d];
    }
    return out;
  }
  function buffer(data) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    return b;
  }
  for (const S of single ? [A] : [A, B]) {
    S.buf = {
      aPos: buffer(corners(S, S.p, 3)),
      aNormal: buffer(corners(S, S.normals, 3)),
      aUv: buffer(corners(S, S.uv, 2)),
      aColor: buffer(corners(S, S.colors.color, 3)),
    };
    S.marker = gl.createBuffer();
  }

  let mode = "color";
  let rot = [1, 0, 0, 0, 1, 0, 0, 0, 1]; // row-major 3 x 3
  let zoom = 1;
  let picked = null;

  function mul3(a, b) {
    const c = new Array(9).fill(0);
    for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) for (let k = 0; k < 3; k++) c[3 * i + j] += a[3 * i + k] * b[3 * k + j];
    return c;
  }
  function turn(dx, dy) {
    const cy = Math.cos(dx), sy = Math.sin(dx), cx = Math.cos(dy), sx = Math.sin(dy);
    const ry = [cy, 0, sy, 0, 1, 0, -sy, 0, cy];
    const rx = [1, 0, 0, 0, cx, -sx, 0, sx, cx];
    rot = mul3(rx, mul3(ry, rot));
  }
  // Screen position (pixels in the half's viewport) and depth of point p
  // seen through the camera: rotation, then a perspective from z = 3.
  const half = function () { return { w: single ? canvas.width : canvas.width / 2, h: canvas.height }; };
  const FOCAL = 2.2;
  function project(p, i) {
    const x = rot[0] * p[3 * i] + rot[1] * p[3 * i + 1] + rot[2] * p[3 * i + 2];
    const y = rot[3] * p[3 * i] + rot[4] * p[3 * i + 1] + rot[5] * p[3 * i + 2];
    const z = rot[6] * p[3 * i] + rot[7] * p[3 * i + 1] + rot[8] * p[3 * i + 2];
    return [x, y, z];
  }
  function mvp() {
    const v = half(), aspect = v.w / v.h, f = FOCAL * zoom, near = 0.5, far = 6, dist = 3;
    // Column-major: clip = P * T(0, 0, -dist) * R.
    const sx = f / aspect, sy = f, a = (far + near) / (near - far), b = 2 * far * near / (near - far);
    const m = new Float32Array(16);
    for (let c = 0; c < 3; c++) {
      m[4 * c] = sx * rot[c];
      m[4 * c + 1] = sy * rot[3 + c];
      m[4 * c + 2] = a * rot[6 + c];
      m[4 * c + 3] = -rot[6 + c];
    }
    m[12] = 0; m[13] = 0; m[14] = -a * dist + b; m[15] = dist;
    return m;
  }
  function toPixel(q) {
    const v = half(), f = FOCAL * zoom, w = 3 - q[2];
    return [(0.5 + 0.5 * f * q[0] * v.h / v.w / w) * v.w, (0.5 - 0.5 * f * q[1] / w) * v.h, w];
  }

  function drawShape(S, viewportX) {
    const v = half();
    gl.viewport(viewportX, 0, v.w, v.h);
    gl.uniformMatrix4fv(loc.uMvp, false, mvp());
    gl.uniformMatrix3fv(loc.uRot, false, new Float32Array([rot[0], rot[3], rot[6], rot[1], rot[4], rot[7], rot[2], rot[5], rot[8]]));
    gl.uniform1i(loc.uMode, mode === "texture" ? 1 : 0);
    gl.uniform1f(loc.uSquares, 6.0);
    gl.uniform1f(loc.uPointSize, 1.0);
    for (const a of ["aPos", "aNormal", "aUv", "aColor"]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, S.buf[a]);
      gl.enableVertexAttribArray(loc[a]);
      gl.vertexAttribPointer(loc[a], a === "aUv" ? 2 : 3, gl.FLOAT, false, 0, 0);
    }
    gl.enable(gl.DEPTH_TEST);
    gl.drawArrays(gl.TRIANGLES, 0, S.faces.length);
    if (S.markerAt !== undefined) {
      gl.bindBuffer(gl.ARRAY_BUFFER, S.marker);
      gl.bufferData(gl.ARRAY_BUFFER, S.p.slice(3 * S.markerAt, 3 * S.markerAt + 3), gl.DYNAMIC_DRAW);
      gl.vertexAttribPointer(loc.aPos, 3, gl.FLOAT, false, 0, 0);
      for (const a of ["aNormal", "aUv", "aColor"]) gl.disableVertexAttribArray(loc[a]);
      gl.disable(gl.DEPTH_TEST);
      gl.uniform1i(loc.uMode, 2);
      for (const [size, c] of [[16, [0, 0, 0]], [10, [1, 0.1, 0.6]]]) {
        gl.uniform1f(loc.uPointSize, size);
        gl.uniform3fv(loc.uFlat, c);
        gl.drawArrays(gl.POINTS, 0, 1);
      }
    }
  }

  let frames = 0;
  function draw() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(2, Math.floor(canvas.clientWidth * dpr / 2) * 2), h = Math.max(1, Math.floor(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    gl.clearColor(1, 1, 1, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    drawShape(A, 0);
    if (!single) drawShape(B, canvas.width / 2);
    frames++;
    status.dataset.frames = String(frames);
  }
  let pending = false;
  function redraw() {
    if (!pending) {
      pending = true;
      requestAnimationFrame(function () { pending = false; draw(); });
    }
  }

  function setMode(m) {
    if (m === "error" && !error) m = "color";
    if (!(m in { color: 1, texture: 1, error: 1 })) m = "color";
    mode = m;
    for (const S of single ? [A] : [A, B]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, S.buf.aColor);
      gl.bufferData(gl.ARRAY_BUFFER, corners(S, S.colors[m === "error" ? "error" : "color"], 3), gl.STATIC_DRAW);
    }
    for (const b of document.querySelectorAll("button[data-mode]")) b.classList.toggle("on", b.dataset.mode === m);
    document.getElementById("legend-box").style.display = m === "error" ? "" : "none";
    status.dataset.mode = m;
    draw();
  }

  function select(i) {
    picked = i;
    A.markerAt = i;
    B.markerAt = map[i];
    let text = single ? "vertex " + i : "vertex " + i + " of A \u2192 vertex " + map[i] + " of B";
    if (error && error[i] === error[i]) text += " (error " + error[i].toFixed(4) + ")";
    document.getElementById("picked").textContent = text;
    status.dataset.pickA = String(i);
    status.dataset.pickB = String(map[i]);
    draw();
  }

  // The vertex of A under canvas pixel (x, y) (CSS pixels), or null: the
  // nearest triangle under it, then its corner of largest weight.
  function pickAt(x, y) {
    const dpr = canvas.width / canvas.clientWidth;
    x *= dpr; y *= dpr;
    if (x >= half().w) return null;
    const px = [];
    for (let i = 0; i < A.n; i++) px.push(toPixel(project(A.p, i)));
    let best = null, bestDepth = Infinity;
    const f = A.faces;
    for (let t = 0; t < f.length; t += 3) {
      const a = px[f[t]], b = px[f[t + 1]], c = px[f[t + 2]];
      const det = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1]);
      if (Math.abs(det) < 1e-12) continue;
      const l0 = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / det;
      const l1 = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / det;
      const l2 = 1 - l0 - l1;
      if (l0 < 0 || l1 < 0 || l2 < 0) continue;
      const depth = l0 * a[2] + l1 * b[2] + l2 * c[2];
      if (depth < bestDepth) {
        bestDepth = depth;
        const l = [l0, l1, l2];
        best = f[t + l.indexOf(Math.max(l0, l1, l2))];
      }
    }
    return best;
  }

  // Mouse: drag turns both shapes, the wheel zooms, a click on A picks.
  let drag = null;
  canvas.addEventListener("pointerdown", function (e) { drag = { x: e.clientX, y: e.clientY, moved: 0 }; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointermove", function (e) {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.moved += Math.abs(dx) + Math.abs(dy);
    drag.x = e.clientX; drag.y = e.clientY;
    turn(dx * 0.01, dy * 0.01);
    redraw();
  });
  canvas.addEventListener("pointerup", function (e) {
    if (drag && drag.moved < 4) {
      const r = canvas.getBoundingClientRect();
      const i = pickAt(e.clientX - r.left, e.clientY - r.top);
      if (i !== null) select(i);
    }
    drag = null;
  });
  canvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    zoom = Math.min(8, Math.max(0.3, zoom * Math.exp(-e.deltaY * 0.001)));
    redraw();
  }, { passive: false });
  for (const b of document.querySelectorAll("button[data-mode]")) {
    b.addEventListener("click", function () { setMode(b.dataset.mode); });
  }
  if (!error) document.querySelector("button[data-mode=error]").disabled = true;
  else document.getElementById("legend-max").textContent = String(D.error_max) + " (geodesic error / \u221aarea)";
  window.addEventListener("resize", redraw);

  document.getElementById("name-a").textContent = "A: " + A.name + " (" + A.n + " vertices)";
  if (single) {
    document.getElementById("name-a").textContent = A.name + " (" + A.n + " vertices, " + A.faces.length / 3 + " triangles)";
    document.querySelector("button[data-mode=texture]").style.display = "none";
  } else {
    document.getElementById("name-b").textContent = "B: " + B.name + " (" + B.n + " vertices)";
  }
  const opts = {};
  for (const kv of location.hash.replace(/^#/, "").split("&")) {
    const [k, v] = kv.split("=");
    if (k) opts[k] = v;
  }
  setMode(opts.mode || "color");
  if (opts.pick !== undefined) {
    const i = Number(opts.pick);
    if (Number.isInteger(i) && i >= 0 && i < A.n) select(i);
  }
  if (opts.click !== undefined) {
    const [x, y] = opts.click.split(",").map(Number);
    const i = pickAt(x, y);
    if (i !== null) select(i);
    status.dataset.click = i === null ? "miss" : String(i);
  }
  status.dataset.state = "ready";
  status.textContent = single
    ? "Drag to turn, scroll to zoom, click to pick a vertex."
    : "Drag to turn both shapes, scroll to zoom, click a point on A to see its image on B.";
})();
