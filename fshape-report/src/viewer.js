// fshape's report viewer: the scenes of #fshape-data drawn with WebGL,
// written here (no library, nothing loaded from the network). Arrays come
// as base64 of gzip (float32 or uint32, little endian) and are inflated
// with the browser's DecompressionStream.
"use strict";
(function () {
  const data = JSON.parse(document.getElementById("fshape-data").textContent);
  // The colour map, 256 RGB bytes, as the PNG pictures draw it (the page's
  // data carries it): the texture and the colour bar read it.
  const colours = data.colours;
  const colour = (t) => { const i = 3 * Math.round(255 * Math.min(1, Math.max(0, isNaN(t) ? 0 : t))); return colours.slice(i, i + 3); };
  async function inflate(b64, Type) {
    const bytes = Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("gzip"));
    return new Type(await new Response(stream).arrayBuffer());
  }
  // like: a mesh whose cells and frames these are (another map of it).
  async function mesh(m, like) {
    if (!m) return null;
    const cells = like ? like.cells : await inflate(m.cells, Uint32Array);
    const frames = like ? like.frames : await Promise.all(m.frames.map((f) => inflate(f, Float32Array)));
    const signals = m.signals ? await Promise.all(m.signals.map((f) => inflate(f, Float32Array))) : null;
    // A masked vertex's signal is NaN (no value): drawn grey, through a
    // value far below the range (the fragment shader greys v < -0.5).
    let lo = Infinity, hi = -Infinity;
    for (const f of signals || []) for (const v of f) if (v === v) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
    const masked = lo <= hi ? lo - 100 * Math.max(hi - lo, 1e-6) : -100;
    return { kind: m.kind, planar: m.planar, cells, frames, signals, masked, n: frames[0].length / 3 };
  }
  function lerp(arrays, s) {
    const k = Math.min(arrays.length - 1, Math.floor(s)), u = s - k;
    if (u === 0 || k + 1 >= arrays.length) return arrays[k];
    const a = arrays[k], b = arrays[k + 1], out = new Float32Array(a.length);
    for (let i = 0; i < a.length; i++) out[i] = a[i] * (1 - u) + b[i] * u;
    return out;
  }
  function normals(m, x) {
    const nrm = new Float32Array(x.length);
    if (m.kind !== "triangle") return nrm;
    const c = m.cells;
    for (let t = 0; t < c.length; t += 3) {
      const a = 3 * c[t], b = 3 * c[t + 1], d = 3 * c[t + 2];
      const ux = x[b] - x[a], uy = x[b + 1] - x[a + 1], uz = x[b + 2] - x[a + 2];
      const vx = x[d] - x[a], vy = x[d + 1] - x[a + 1], vz = x[d + 2] - x[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const v of [a, b, d]) { nrm[v] += nx; nrm[v + 1] += ny; nrm[v + 2] += nz; }
    }
    return nrm;
  }

  const canvas = document.getElementById("view");
  const gl = canvas && (canvas.getContext("webgl", { preserveDrawingBuffer: true, antialias: true }));
  const status = document.getElementById("status");
  if (!canvas) return;
  if (!gl || !gl.getExtension("OES_element_index_uint")) {
    status.textContent = "This browser has no WebGL: the 3-D view cannot be drawn (the tables below are complete).";
    window.fshapeReport = { ready: Promise.resolve(false) };
    return;
  }
  const vs = `attribute vec3 p; attribute vec3 n; attribute float f;
    uniform mat3 R; uniform vec3 c; uniform vec2 shift; uniform float s, zs; uniform vec2 range; uniform float aspect;
    varying float v; varying float light;
    void main() {
      vec3 q = R * (p - c); q.xy += shift;
      gl_Position = vec4(q.x * s / aspect, q.y * s, -q.z * zs, 1.0);
      vec3 m = R * n; float l = length(m);
      light = l > 0.0 ? 0.35 + 0.65 * abs(m.z / l) : 1.0;
      v = (f - range.x) / (range.y - range.x);
    }`;
  const fs = `precision mediump float; varying float v; varying float light; uniform sampler2D cmap; uniform float alpha;
    void main() { vec3 col = v < -0.5 ? vec3(0.75) : texture2D(cmap, vec2(clamp(v, 0.0, 1.0), 0.5)).rgb; gl_FragColor = vec4(col * light, alpha); }`;
  function shader(type, src) {
    const sh = gl.createShader(type); gl.shaderSource(sh, src); gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(sh));
    return sh;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, vs)); gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(prog); gl.useProgram(prog);
  const loc = (name) => gl.getUniformLocation(prog, name);
  const attr = { p: gl.getAttribLocation(prog, "p"), n: gl.getAttribLocation(prog, "n"), f: gl.getAttribLocation(prog, "f") };
  const tex = gl.createTexture();
  const texels = new Uint8Array(256 * 4);
  for (let i = 0; i < 256; i++) texels.set([...colours.slice(3 * i, 3 * i + 3), 255], 4 * i);
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, 256, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, texels);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
  // Each mesh keeps its own GL buffers: the cells are uploaded once, the
  // positions, normals and signal only when the slider moves (turning or
  // zooming the view draws the same buffers again).
  function upload(m, position) {
    if (!m.gl) {
      m.gl = { p: gl.createBuffer(), n: gl.createBuffer(), f: gl.createBuffer(), i: gl.createBuffer(), at: null };
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, m.gl.i); gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, m.cells, gl.STATIC_DRAW);
    }
    if (m.gl.at === position) return;
    const x = lerp(m.frames, position), f = m.signals ? Float32Array.from(lerp(m.signals, position), (v) => (v === v ? v : m.masked)) : new Float32Array(m.n);
    for (const [buf, values] of [[m.gl.p, x], [m.gl.n, m.planar ? new Float32Array(x.length) : normals(m, x)], [m.gl.f, f]]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, buf); gl.bufferData(gl.ARRAY_BUFFER, values, gl.DYNAMIC_DRAW);
    }
    m.gl.at = position;
  }

  function draw(m, position, alpha, shift) {
    upload(m, position);
    for (const [buf, a, size] of [[m.gl.p, attr.p, 3], [m.gl.n, attr.n, 3], [m.gl.f, attr.f, 1]]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, buf); gl.enableVertexAttribArray(a); gl.vertexAttribPointer(a, size, gl.FLOAT, false, 0, 0);
    }
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, m.gl.i);
    gl.uniform1f(loc("alpha"), alpha); gl.uniform2f(loc("shift"), shift[0], shift[1]);
    gl.drawElements(m.kind === "triangle" ? gl.TRIANGLES : gl.LINES, m.cells.length, gl.UNSIGNED_INT, 0);
  }

  // Camera: azimuth about z, then elevation (as the PNG renders), an
  // orthographic view fitted to the scene, zoom by the wheel.
  const cam = { az: data.view[0], el: data.view[1], zoom: 1 };
  function rotation() {
    const a = (cam.az * Math.PI) / 180, e = (cam.el * Math.PI) / 180;
    const ca = Math.cos(a), sa = Math.sin(a), ce = Math.cos(e), se = Math.sin(e);
    // Column-major for WebGL: rows [ca, sa, 0], [-sa se, ca se, ce], [sa ce, -ca ce, se].
    return new Float32Array([ca, -sa * se, sa * ce, sa, ca * se, -ca * ce, 0, ce, se]);
  }
  const scenes = [];
  let current = 0, position = 0, companionMode = "beside", playing = null;
  const slider = document.getElementById("frame"), label = document.getElementById("frame-label");
  const picker = document.getElementById("scene"), mode = document.getElementById("companion");
  const play = document.getElementById("play");

  function render() {
    const sc = scenes[current];
    if (!sc) return;
    const width = canvas.clientWidth, height = canvas.clientHeight;
    if (canvas.width !== width || canvas.height !== height) { canvas.width = width; canvas.height = height; }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(1, 1, 1, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    const planar = sc.mesh.planar;
    gl.uniformMatrix3fv(loc("R"), false, planar ? new Float32Array([1, 0, 0, 0, 1, 0, 0, 0, 1]) : rotation());
    gl.uniform3fv(loc("c"), sc.centre);
    const beside = sc.companion && companionMode === "beside";
    // The scene (both meshes side by side when beside) fits the canvas.
    const aspect = canvas.width / canvas.height;
    const half = Math.max(1.1 * sc.radius, (beside ? 2.2 : 1.1) * sc.radius / aspect);
    gl.uniform1f(loc("s"), cam.zoom / half); gl.uniform1f(loc("zs"), 0.5 / (sc.radius * 2.5));
    gl.uniform1f(loc("aspect"), aspect);
    gl.uniform2f(loc("range"), sc.range[0], sc.range[1]);
    gl.disable(gl.BLEND); gl.depthMask(true);
    draw(sc.mesh, position, 1.0, beside ? [-1.1 * sc.radius, 0] : [0, 0]);
    if (sc.companion && companionMode !== "hidden") {
      if (beside) draw(sc.companion, 0, 1.0, [1.1 * sc.radius, 0]);
      else {
        gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA); gl.depthMask(false);
        draw(sc.companion, 0, 0.45, [0, 0]);
        gl.depthMask(true);
      }
    }
    const k = Math.round(position);
    label.textContent = sc.labels.length > 1 ? sc.labels[Math.min(sc.labels.length - 1, k)] : sc.labels[0] || "";
  }

  function colourBar(sc) {
    const bar = document.getElementById("bar"), ctx = bar.getContext("2d");
    for (let i = 0; i < bar.width; i++) {
      ctx.fillStyle = `rgb(${colour(i / (bar.width - 1)).join(",")})`;
      ctx.fillRect(i, 0, 1, bar.height);
    }
    const fmt = (v) => (Math.abs(v) >= 1e4 || (Math.abs(v) < 1e-2 && v !== 0) ? v.toExponential(2) : v.toPrecision(3));
    document.getElementById("lo").textContent = fmt(sc.range[0]);
    document.getElementById("hi").textContent = fmt(sc.range[1]);
    document.getElementById("colourbar").style.visibility = sc.mesh.signals ? "visible" : "hidden";
  }

  function select(i) {
    current = i; position = 0;
    const sc = scenes[i];
    slider.max = String((sc.mesh.frames.length - 1) * 20);
    slider.value = "0";
    slider.disabled = play.disabled = sc.mesh.frames.length < 2;
    mode.disabled = !sc.companion;
    for (const o of mode.options) o.textContent = sc.companion ? `${sc.companionName} ${o.value === "overlay" ? "overlaid" : o.value}` : "—";
    document.getElementById("note").textContent = sc.note || "";
    colourBar(sc);
    render();
  }

  async function load() {
    for (const s of data.scenes) {
      // A scene of another map shares the scene before's geometry.
      const prev = s.same_geometry ? scenes[scenes.length - 1] : null;
      const m = await mesh(s.mesh, prev && prev.mesh), companion = await mesh(s.companion, prev && prev.companion);
      let lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
      for (const x of m.frames.concat(companion ? companion.frames : [])) {
        for (let i = 0; i < x.length; i += 3) for (let k = 0; k < 3; k++) { lo[k] = Math.min(lo[k], x[i + k]); hi[k] = Math.max(hi[k], x[i + k]); }
      }
      const centre = new Float32Array(lo.map((v, k) => 0.5 * (v + hi[k])));
      const radius = 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;
      let range = s.range;
      if (!range) {
        let a = Infinity, b = -Infinity;
        for (const f of (m.signals || []).concat(companion && companion.signals ? companion.signals : [])) for (const v of f) if (v === v) { a = Math.min(a, v); b = Math.max(b, v); }
        range = a < b ? [a, b] : [a === Infinity ? 0 : a, (a === Infinity ? 0 : a) + 1];
      }
      scenes.push({ name: s.name, labels: s.labels, note: s.note, mesh: m, companion, companionName: s.companion_name, centre, radius, range });
      const o = document.createElement("option"); o.textContent = s.name; o.value = String(scenes.length - 1); picker.appendChild(o);
    }
    picker.parentElement.style.display = scenes.length > 1 ? "" : "none";
    if (scenes.length) select(0);
    status.textContent = "";
    return true;
  }

  slider.addEventListener("input", () => { position = Number(slider.value) / 20; render(); });
  picker.addEventListener("change", () => select(Number(picker.value)));
  mode.addEventListener("change", () => { companionMode = mode.value; render(); });
  play.addEventListener("click", () => {
    if (playing) { clearInterval(playing); playing = null; play.textContent = "▶ play"; return; }
    play.textContent = "❚❚ pause";
    playing = setInterval(() => {
      const max = Number(slider.max);
      slider.value = String((Number(slider.value) + 1) % (max + 1));
      position = Number(slider.value) / 20; render();
    }, 50);
  });
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    cam.az -= 0.4 * (e.clientX - drag[0]); cam.el = Math.max(-90, Math.min(90, cam.el + 0.4 * (e.clientY - drag[1])));
    drag = [e.clientX, e.clientY]; render();
  });
  canvas.addEventListener("wheel", (e) => { e.preventDefault(); cam.zoom *= Math.exp(-0.001 * e.deltaY); render(); }, { passive: false });
  canvas.addEventListener("dblclick", () => { cam.az = data.view[0]; cam.el = data.view[1]; cam.zoom = 1; render(); });
  window.addEventListener("resize", render);
  window.fshapeReport = { ready: load().catch((e) => { status.textContent = "The 3-D view failed: " + e; throw e; }) };
})();

// Sortable tables: a click on a header sorts by that column (numbers as numbers).
document.querySelectorAll("table.sortable th").forEach((th) => {
  th.addEventListener("click", () => {
    const col = th.cellIndex;
    const body = th.closest("table").tBodies[0];
    const asc = th.dataset.order !== "asc";
    th.closest("tr").querySelectorAll("th").forEach((h) => delete h.dataset.order);
    th.dataset.order = asc ? "asc" : "desc";
    const key = (r) => { const t = r.cells[col].dataset.value ?? r.cells[col].textContent; const v = parseFloat(t); return isNaN(v) ? t : v; };
    [...body.rows].sort((a, b) => { const x = key(a), y = key(b); return (x < y ? -1 : x > y ? 1 : 0) * (asc ? 1 : -1); }).forEach((r) => body.appendChild(r));
  });
});
