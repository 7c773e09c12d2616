// ptmkit's WebGL2 viewer for the relight/OpenLIME web folder (docs/WEB.md).
//
// Reads info.json and the coefficient planes (one JPEG per three planes, as single images or
// deep-zoom tiles) from the folder it is served from, and evaluates the texture per pixel in
// the fragment shader exactly as `ptmkit relight` does: coef = (byte / 255 - bias) * scale,
// the PTM or HSH basis at the light (computed here in double precision, the same formulas as
// core/hsh.h), summed per channel, lrgb times the per-texel colour, clamped to 0..1 and
// written as is (the values are the photographs' encoded values; nothing is linearised).
// A light at or below the horizon gives black, as in `ptmkit relight`.
//
// No network access beyond the folder, no third-party code, no build step.
'use strict';

(() => {
  // ---- the bases -------------------------------------------------------------------------

  // PTM terms in the web order 1, u, v, u^2, uv, v^2.
  function ptmBasis(l) {
    const u = l[0], v = l[1];
    return [1, u, v, u * u, u * v, v * v];
  }

  // HSH terms (4, 9 or 16), the formulas and theta clamp of core/hsh.h.
  function hshBasis(terms, l) {
    const n = Math.hypot(l[0], l[1], l[2]);
    const x = l[0] / n, y = l[1] / n, z = l[2] / n;
    const theta = Math.min(Math.acos(Math.min(1, Math.max(-1, z))), Math.PI / 2 - 0.04);
    const phi = Math.atan2(y, x);
    const c = Math.cos(theta), c2 = c * c;
    const s = Math.sqrt(Math.max(0, c - c2));
    const b = new Array(terms).fill(0);
    b[0] = 1 / Math.sqrt(2 * Math.PI);
    b[1] = Math.sqrt(6 / Math.PI) * Math.cos(phi) * s;
    b[2] = Math.sqrt(3 / (2 * Math.PI)) * (2 * c - 1);
    b[3] = Math.sqrt(6 / Math.PI) * Math.sin(phi) * s;
    if (terms <= 4) return b;
    const k30 = Math.sqrt(30 / Math.PI);
    b[4] = k30 * Math.cos(2 * phi) * (c2 - c);
    b[5] = k30 * Math.cos(phi) * (2 * c - 1) * s;
    b[6] = Math.sqrt(5 / (2 * Math.PI)) * (6 * c2 - 6 * c + 1);
    b[7] = k30 * Math.sin(phi) * (2 * c - 1) * s;
    b[8] = k30 * Math.sin(2 * phi) * (c2 - c);
    if (terms <= 9) return b;
    const s3 = s * s * s;
    const k35 = 2 * Math.sqrt(35 / Math.PI), k210 = Math.sqrt(210 / Math.PI);
    const k21 = 2 * Math.sqrt(21 / Math.PI), q = 5 * c2 - 5 * c + 1;
    b[9] = k35 * Math.cos(3 * phi) * s3;
    b[10] = k210 * Math.cos(2 * phi) * (2 * c - 1) * (c2 - c);
    b[11] = k21 * Math.cos(phi) * s * q;
    b[12] = Math.sqrt(7 / (2 * Math.PI)) * (20 * c2 * c - 30 * c2 + 12 * c - 1);
    b[13] = k21 * Math.sin(phi) * s * q;
    b[14] = k210 * Math.sin(2 * phi) * (2 * c - 1) * (c2 - c);
    b[15] = k35 * Math.sin(3 * phi) * s3;
    return b;
  }

  // ---- shaders -----------------------------------------------------------------------------

  const VERTEX = `#version 300 es
in vec2 a_pos;   // image pixels, y down
in vec2 a_tc;    // texture coordinates, (0, 0) = the tile's first pixel
uniform vec3 u_view;    // centre x, y (image pixels), zoom (screen pixels per image pixel)
uniform vec2 u_canvas;  // canvas size in pixels
out vec2 v_tc;
void main() {
  vec2 s = (a_pos - u_view.xy) * u_view.z + 0.5 * u_canvas;
  gl_Position = vec4(2.0 * s.x / u_canvas.x - 1.0, 1.0 - 2.0 * s.y / u_canvas.y, 0.0, 1.0);
  v_tc = a_tc;
}`;

  // One term: (texel - bias) * scale, the format's decoding.
  function relightShader(info, jpegs) {
    let src = `#version 300 es
precision highp float;
in vec2 v_tc;
out vec4 o_colour;
uniform float u_basis[${Math.max(1, info.terms)}];
uniform vec3 u_scale[${jpegs}];
uniform vec3 u_bias[${jpegs}];
`;
    for (let j = 0; j < jpegs; ++j) src += `uniform sampler2D u_plane${j};\n`;
    src += `vec3 coef(int j, sampler2D s) { return (texture(s, v_tc).rgb - u_bias[j]) * u_scale[j]; }
void main() {
  vec3 c = vec3(0.0);
`;
    if (info.colorspace === 'lrgb') {
      // plane_0: the colour; JPEGs 1 and 2: the six luminance terms.
      src += `  vec3 colour = coef(0, u_plane0);\n  float l = 0.0;\n`;
      for (let j = 1; j < jpegs; ++j) {
        src += `  { vec3 t = coef(${j}, u_plane${j});\n`;
        for (let k = 0; k < 3; ++k) {
          const term = 3 * (j - 1) + k;
          if (term < info.terms) src += `    l += u_basis[${term}] * t[${k}];\n`;
        }
        src += `  }\n`;
      }
      src += `  c = l * colour;\n`;
    } else {
      // JPEG j: term j of R, G, B.
      for (let j = 0; j < jpegs; ++j) src += `  c += u_basis[${j}] * coef(${j}, u_plane${j});\n`;
    }
    src += `  o_colour = vec4(clamp(c, 0.0, 1.0), 1.0);
}`;
    return src;
  }

  const NORMALS_SHADER = `#version 300 es
precision highp float;
in vec2 v_tc;
out vec4 o_colour;
uniform sampler2D u_normals;
void main() { o_colour = vec4(texture(u_normals, v_tc).rgb, 1.0); }`;

  function compile(gl, vs, fs) {
    const prog = gl.createProgram();
    for (const [type, text] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const sh = gl.createShader(type);
      gl.shaderSource(sh, text);
      gl.compileShader(sh);
      if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) {
        throw new Error('shader compilation failed: ' + gl.getShaderInfoLog(sh));
      }
      gl.attachShader(prog, sh);
    }
    gl.bindAttribLocation(prog, 0, 'a_pos');
    gl.bindAttribLocation(prog, 1, 'a_tc');
    gl.linkProgram(prog);
    if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) {
      throw new Error('shader link failed: ' + gl.getProgramInfoLog(prog));
    }
    return prog;
  }

  // ---- the folder ---------------------------------------------------------------------------

  async function fetchOk(url) {
    const r = await fetch(url, {cache: 'no-cache'});
    if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
    return r;
  }

  // info.json checked: what this viewer draws, or an Error saying what is not supported.
  function checkInfo(info) {
    const w = info.width, h = info.height;
    if (!(Number.isInteger(w) && Number.isInteger(h) && w > 0 && h > 0)) {
      throw new Error('info.json: width and height must be positive integers');
    }
    const type = info.type, cs = info.colorspace || 'rgb';
    const np = info.nplanes;
    let terms;
    if (type === 'ptm' && cs === 'rgb' && np === 18) terms = 6;
    else if (type === 'ptm' && cs === 'lrgb' && np === 9) terms = 6;
    else if (type === 'hsh' && cs === 'rgb' && [12, 27, 48].includes(np)) terms = np / 3;
    else {
      throw new Error(`info.json: type "${type}", colorspace "${cs}" with ${np} planes is not ` +
        'supported (this viewer shows ptm rgb 18, ptm lrgb 9, hsh rgb 12/27/48)');
    }
    const m = info.materials && info.materials[0];
    if (!m || !Array.isArray(m.scale) || !Array.isArray(m.bias) || m.scale.length < np ||
        m.bias.length < np) {
      throw new Error('info.json: materials[0] needs one scale and one bias per plane');
    }
    return {width: w, height: h, type, colorspace: cs, nplanes: np, terms,
      scale: m.scale, bias: m.bias, pixelSizeInMM: info.pixelSizeInMM || 0,
      format: info.format || 'jpg', own: info.ptmkit || {}};
  }

  // The pyramid: levels[L] = {width, height, nx, ny}, level 0 the coarsest. For deep zoom
  // the level count is OpenLIME's, ceil(log2(max(w, h) / tile)) + 1, sizes halving with floor.
  async function readLayout(info) {
    let deepzoom = info.own.layout === 'deepzoom';
    let dzi = null;
    if (!info.own.layout) {
      try { dzi = await (await fetchOk('plane_0.dzi')).text(); deepzoom = true; } catch (e) { /* image */ }
    }
    if (!deepzoom) {
      return {type: 'image', tile: Math.max(info.width, info.height), overlap: 0,
        levels: [{width: info.width, height: info.height, nx: 1, ny: 1}],
        url: (j, L, x, y) => `plane_${j}.${info.format}`};
    }
    if (!dzi) dzi = await (await fetchOk('plane_0.dzi')).text();
    const doc = new DOMParser().parseFromString(dzi, 'text/xml').documentElement;
    const size = doc.getElementsByTagName('Size')[0];
    const tile = parseInt(doc.getAttribute('TileSize'), 10);
    const overlap = parseInt(doc.getAttribute('Overlap') || '0', 10);
    const suffix = doc.getAttribute('Format') || 'jpg';
    const w = parseInt(size.getAttribute('Width'), 10), h = parseInt(size.getAttribute('Height'), 10);
    if (w !== info.width || h !== info.height || !(tile > 0)) {
      throw new Error('plane_0.dzi: size or tile size does not match info.json');
    }
    const ratio = Math.max(w, h) / tile;
    const n = ratio <= 1 ? 1 : Math.ceil(Math.log2(ratio)) + 1;
    const levels = [];
    for (let L = 0; L < n; ++L) {
      const lw = Math.floor(w / 2 ** (n - 1 - L)), lh = Math.floor(h / 2 ** (n - 1 - L));
      levels.push({width: lw, height: lh, nx: Math.ceil(lw / tile), ny: Math.ceil(lh / tile)});
    }
    return {type: 'deepzoom', tile, overlap, levels,
      url: (j, L, x, y) => `plane_${j}_files/${L}/${x}_${y}.${suffix}`};
  }

  async function loadBitmap(url) {
    const blob = await (await fetchOk(url)).blob();
    // The planes are data, not pictures: no colour management, no premultiplication.
    return createImageBitmap(blob, {colorSpaceConversion: 'none', premultiplyAlpha: 'none',
      imageOrientation: 'none'});
  }

  // ---- the viewer ---------------------------------------------------------------------------

  class Viewer {
    constructor(canvas) {
      this.canvas = canvas;
      const gl = canvas.getContext('webgl2', {preserveDrawingBuffer: true, alpha: false,
        antialias: false, premultipliedAlpha: false, depth: false, stencil: false});
      if (!gl) throw new Error('WebGL2 is not available in this browser');
      this.gl = gl;
      this.light = [0, 0, 1];
      this.view = {cx: 0, cy: 0, zoom: 1};
      this.mode = 'light';
      this.tiles = new Map();  // "L/x/y" -> {state, textures}
      this.loading = 0;
      this.maxLoading = 6;
      this.queue = [];
      this.frameRequested = false;
      this.requested = [];     // tile URLs fetched, in order (for tests)
      this.useClock = 0;
      this.maxTiles = 256;     // loaded tiles kept (each holds one texture per plane JPEG)
      this.listeners = [];
    }

    async open() {
      const raw = await (await fetchOk('info.json')).json();
      this.info = checkInfo(raw);
      this.layout = await readLayout(this.info);
      this.jpegs = Math.ceil(this.info.nplanes / 3);
      const gl = this.gl;
      if (this.jpegs > gl.getParameter(gl.MAX_TEXTURE_IMAGE_UNITS)) {
        throw new Error(`${this.jpegs} plane images exceed this GPU's texture units`);
      }
      this.program = compile(gl, VERTEX, relightShader(this.info, this.jpegs));
      this.normalsProgram = compile(gl, VERTEX, NORMALS_SHADER);
      const sc = [], bi = [];
      for (let j = 0; j < this.jpegs; ++j) {
        for (let k = 0; k < 3; ++k) {
          const p = 3 * j + k;
          sc.push(p < this.info.nplanes ? this.info.scale[p] : 0);
          bi.push(p < this.info.nplanes ? this.info.bias[p] : 0);
        }
      }
      gl.useProgram(this.program);
      gl.uniform3fv(gl.getUniformLocation(this.program, 'u_scale'), sc);
      gl.uniform3fv(gl.getUniformLocation(this.program, 'u_bias'), bi);
      for (let j = 0; j < this.jpegs; ++j) {
        gl.uniform1i(gl.getUniformLocation(this.program, `u_plane${j}`), j);
      }
      this.buffer = gl.createBuffer();
      this.vao = gl.createVertexArray();
      gl.bindVertexArray(this.vao);
      gl.bindBuffer(gl.ARRAY_BUFFER, this.buffer);
      gl.enableVertexAttribArray(0);
      gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 16, 0);
      gl.enableVertexAttribArray(1);
      gl.vertexAttribPointer(1, 2, gl.FLOAT, false, 16, 8);
      gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
      gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
      gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
      this.normals = null;
      if (raw.ptmkit ? raw.ptmkit.normals : true) {
        try {
          this.normals = this.makeTexture(await loadBitmap('normals.png'));
        } catch (e) {
          if (raw.ptmkit && raw.ptmkit.normals) console.warn('normals.png: ' + e.message);
        }
      }
      this.resize();
      this.fit();
      this.setLight(this.light);
    }

    makeTexture(bitmap) {
      const gl = this.gl;
      const tex = gl.createTexture();
      gl.bindTexture(gl.TEXTURE_2D, tex);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, bitmap);
      gl.generateMipmap(gl.TEXTURE_2D);
      // Level 0 exactly at 1:1 and closer (the comparison with `ptmkit relight` needs it);
      // averaged coefficients (mip levels) when zoomed out: the relit image's average.
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      if (bitmap.close) bitmap.close();
      return tex;
    }

    // ---- view ----
    resize() {
      const dpr = window.devicePixelRatio || 1;
      const w = Math.max(1, Math.round(this.canvas.clientWidth * dpr));
      const h = Math.max(1, Math.round(this.canvas.clientHeight * dpr));
      if (this.canvas.width !== w || this.canvas.height !== h) {
        this.canvas.width = w;
        this.canvas.height = h;
      }
      this.redraw();
    }
    fit() {
      const z = Math.min(this.canvas.width / this.info.width, this.canvas.height / this.info.height);
      this.setView({cx: this.info.width / 2, cy: this.info.height / 2, zoom: z});
    }
    setView(v) {
      Object.assign(this.view, v);
      const z = this.view.zoom;
      this.view.zoom = Math.min(64, Math.max(1e-3, z));
      this.redraw();
      this.emit();
    }
    zoomAt(factor, sx, sy) {
      // Keeps the image point under the screen point (sx, sy) fixed.
      const v = this.view, W = this.canvas.width, H = this.canvas.height;
      const ix = v.cx + (sx - W / 2) / v.zoom, iy = v.cy + (sy - H / 2) / v.zoom;
      const z = Math.min(64, Math.max(1e-3, v.zoom * factor));
      this.setView({zoom: z, cx: ix - (sx - W / 2) / z, cy: iy - (sy - H / 2) / z});
    }
    setLight(l) {
      const n = Math.hypot(l[0], l[1], l[2]);
      if (!(n > 0) || !Number.isFinite(n)) throw new Error('light direction must be finite and non-zero');
      this.light = [l[0] / n, l[1] / n, l[2] / n];
      this.redraw();
      this.emit();
    }
    setMode(mode) {
      if (mode === 'normals' && !this.normals) throw new Error('this export has no normals.png');
      this.mode = mode;
      this.redraw();
      this.emit();
    }
    onChange(f) { this.listeners.push(f); }
    emit() { for (const f of this.listeners) f(this); }

    basis() {
      const l = this.light;
      if (l[2] <= 0) return new Array(this.info.terms).fill(0);  // black, as `ptmkit relight`
      return this.info.type === 'ptm' ? ptmBasis(l) : hshBasis(this.info.terms, l);
    }

    // ---- tiles ----
    // The level drawn at this zoom: the coarsest with at least one texel per screen pixel.
    targetLevel(zoom) {
      const n = this.layout.levels.length;
      const i = Math.max(0, Math.min(n - 1, Math.floor(-Math.log2(zoom) + 1e-9)));
      return n - 1 - i;
    }
    // Image-space rectangle of tile (L, x, y), OpenLIME's mapping.
    tileRect(L, x, y) {
      const n = this.layout.levels.length, side = this.layout.tile * 2 ** (n - 1 - L);
      const x0 = x * side, y0 = y * side;
      return [x0, y0, Math.min(x0 + side, this.info.width), Math.min(y0 + side, this.info.height)];
    }
    visibleTiles(L, view, width, height) {
      const v = view || this.view;
      const W = width || this.canvas.width, H = height || this.canvas.height;
      const x0 = v.cx - W / 2 / v.zoom, x1 = v.cx + W / 2 / v.zoom;
      const y0 = v.cy - H / 2 / v.zoom, y1 = v.cy + H / 2 / v.zoom;
      const lv = this.layout.levels[L];
      const n = this.layout.levels.length, side = this.layout.tile * 2 ** (n - 1 - L);
      const out = [];
      // The view's right and bottom edges are exclusive.
      const tx0 = Math.max(0, Math.floor(x0 / side)), tx1 = Math.min(lv.nx - 1, Math.ceil(x1 / side) - 1);
      const ty0 = Math.max(0, Math.floor(y0 / side)), ty1 = Math.min(lv.ny - 1, Math.ceil(y1 / side) - 1);
      for (let y = ty0; y <= ty1; ++y) for (let x = tx0; x <= tx1; ++x) out.push([L, x, y]);
      return out;
    }
    tile(L, x, y) {
      const key = `${L}/${x}/${y}`;
      let t = this.tiles.get(key);
      if (!t) {
        t = {L, x, y, key, state: 'new', textures: null, waiters: [], used: 0};
        this.tiles.set(key, t);
      }
      t.used = ++this.useClock;
      return t;
    }
    // Frees loaded tiles beyond `keep`, least recently used first (never one in use now).
    evict(keep) {
      const ready = [...this.tiles.values()].filter((t) => t.state === 'ready' || t.state === 'error');
      if (ready.length <= keep) return;
      const inUse = new Set(this.neededTiles().map(([L, x, y]) => `${L}/${x}/${y}`));
      ready.sort((a, b) => a.used - b.used);
      for (const t of ready.slice(0, ready.length - keep)) {
        if (inUse.has(t.key)) continue;
        if (t.textures) for (const tex of t.textures) this.gl.deleteTexture(tex);
        this.tiles.delete(t.key);
      }
    }
    // Forgets every tile (and the record of fetched URLs): the next frame fetches afresh.
    clearTiles() {
      for (const t of this.tiles.values()) {
        if (t.textures) for (const tex of t.textures) this.gl.deleteTexture(tex);
      }
      this.tiles.clear();
      this.queue = [];
      this.requested = [];
    }
    // Loads a tile's JPEGs (once); resolves when loaded or failed.
    request(t) {
      if (t.state === 'ready' || t.state === 'error') return Promise.resolve(t);
      const p = new Promise((resolve) => t.waiters.push(resolve));
      if (t.state === 'new') {
        t.state = 'queued';
        this.queue.push(t);
        this.pump();
      }
      return p;
    }
    pump() {
      while (this.loading < this.maxLoading && this.queue.length) {
        const t = this.queue.shift();
        t.state = 'loading';
        ++this.loading;
        const urls = [];
        for (let j = 0; j < this.jpegs; ++j) urls.push(this.layout.url(j, t.L, t.x, t.y));
        this.requested.push(...urls);
        Promise.all(urls.map(loadBitmap)).then((bitmaps) => {
          t.textures = bitmaps.map((b) => this.makeTexture(b));
          t.state = 'ready';
        }, (e) => {
          t.state = 'error';
          this.status(`tile ${t.L}/${t.x}_${t.y}: ${e.message}`);
        }).finally(() => {
          --this.loading;
          for (const w of t.waiters) w(t);
          t.waiters = [];
          if (this.tiles.get(t.key) !== t && t.textures) {  // cleared while loading
            for (const tex of t.textures) this.gl.deleteTexture(tex);
          }
          this.evict(this.maxTiles);
          this.redraw();
          this.pump();
        });
      }
    }
    // Every tile the current view needs, coarse to fine (coarse ones show while fine ones load).
    neededTiles(view, width, height) {
      const v = view || this.view;
      const target = this.targetLevel(v.zoom);
      const out = [];
      for (let L = 0; L <= target; ++L) out.push(...this.visibleTiles(L, v, width, height));
      return out;
    }

    // ---- drawing ----
    redraw() {
      if (this.frameRequested || !this.program) return;
      this.frameRequested = true;
      requestAnimationFrame(() => {
        this.frameRequested = false;
        this.draw();
      });
    }
    draw(target) {
      const gl = this.gl;
      const W = target ? target.width : this.canvas.width;
      const H = target ? target.height : this.canvas.height;
      const view = target ? target.view : this.view;
      gl.bindFramebuffer(gl.FRAMEBUFFER, target ? target.fbo : null);
      gl.viewport(0, 0, W, H);
      gl.clearColor(0.125, 0.125, 0.125, 1);
      gl.clear(gl.COLOR_BUFFER_BIT);
      gl.bindVertexArray(this.vao);
      const needed = this.neededTiles(view, W, H);
      let missing = 0;
      if (this.mode === 'normals' && this.normals && !target) {
        gl.useProgram(this.normalsProgram);
        this.setViewUniforms(this.normalsProgram, view, W, H);
        gl.activeTexture(gl.TEXTURE0);
        gl.bindTexture(gl.TEXTURE_2D, this.normals);
        this.quad([0, 0, this.info.width, this.info.height], [0, 0, 1, 1]);
      } else {
        gl.useProgram(this.program);
        this.setViewUniforms(this.program, view, W, H);
        gl.uniform1fv(gl.getUniformLocation(this.program, 'u_basis'), this.basis());
        for (const [L, x, y] of needed) {
          const t = this.tile(L, x, y);
          if (t.state !== 'ready') {
            ++missing;
            if (!target) this.request(t);
            continue;
          }
          for (let j = 0; j < this.jpegs; ++j) {
            gl.activeTexture(gl.TEXTURE0 + j);
            gl.bindTexture(gl.TEXTURE_2D, t.textures[j]);
          }
          this.drawTile(t);
        }
      }
      if (!target) {
        this.lastDraw = {missing, level: this.targetLevel(view.zoom), time: performance.now()};
        this.updateScaleBar();
      }
      return missing;
    }
    setViewUniforms(prog, view, W, H) {
      const gl = this.gl;
      gl.uniform3f(gl.getUniformLocation(prog, 'u_view'), view.cx, view.cy, view.zoom);
      gl.uniform2f(gl.getUniformLocation(prog, 'u_canvas'), W, H);
    }
    drawTile(t) {
      const lay = this.layout;
      if (lay.type === 'image') {
        this.quad([0, 0, this.info.width, this.info.height], [0, 0, 1, 1]);
        return;
      }
      const lv = lay.levels[t.L], ts = lay.tile, ov = lay.overlap;
      // The tile image: its own pixels plus `overlap` on each inner side.
      const px0 = t.x * ts, px1 = Math.min(px0 + ts, lv.width);
      const py0 = t.y * ts, py1 = Math.min(py0 + ts, lv.height);
      const left = t.x > 0 ? ov : 0, top = t.y > 0 ? ov : 0;
      const right = t.x < lv.nx - 1 ? ov : 0, bottom = t.y < lv.ny - 1 ? ov : 0;
      const tw = px1 - px0 + left + right, th = py1 - py0 + top + bottom;
      const tc = [left / tw, top / th, (left + px1 - px0) / tw, (top + py1 - py0) / th];
      this.quad(this.tileRect(t.L, t.x, t.y), tc);
    }
    quad(r, tc) {
      const gl = this.gl;
      const d = new Float32Array([
        r[0], r[1], tc[0], tc[1], r[2], r[1], tc[2], tc[1], r[0], r[3], tc[0], tc[3],
        r[2], r[3], tc[2], tc[3]]);
      gl.bindBuffer(gl.ARRAY_BUFFER, this.buffer);
      gl.bufferData(gl.ARRAY_BUFFER, d, gl.STREAM_DRAW);
      gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    }

    // Resolves once every tile the current view needs has loaded (or failed) and been drawn.
    async idle() {
      for (;;) {
        await Promise.all(this.neededTiles().map((t) => this.request(this.tile(...t))));
        await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r)));
        if (!this.frameRequested && this.lastDraw && this.lastDraw.missing === 0) return;
        this.redraw();
      }
    }

    // The relit image at full resolution (finest level), rendered in blocks into a 2D canvas.
    async renderFull() {
      const gl = this.gl, W = this.info.width, H = this.info.height;
      const block = Math.min(2048, gl.getParameter(gl.MAX_RENDERBUFFER_SIZE));
      const out = document.createElement('canvas');
      out.width = W;
      out.height = H;
      const ctx = out.getContext('2d');
      const fbo = gl.createFramebuffer();
      const rb = gl.createRenderbuffer();
      for (let y0 = 0; y0 < H; y0 += block) {
        for (let x0 = 0; x0 < W; x0 += block) {
          const w = Math.min(block, W - x0), h = Math.min(block, H - y0);
          const view = {cx: x0 + w / 2, cy: y0 + h / 2, zoom: 1};
          await Promise.all(this.neededTiles(view, w, h).map((t) => this.request(this.tile(...t))));
          gl.bindRenderbuffer(gl.RENDERBUFFER, rb);
          gl.renderbufferStorage(gl.RENDERBUFFER, gl.RGBA8, w, h);
          gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
          gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, rb);
          const mode = this.mode;
          this.mode = 'light';
          this.draw({fbo, width: w, height: h, view});
          this.mode = mode;
          const px = new Uint8Array(w * h * 4);
          gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
          const img = ctx.createImageData(w, h);
          for (let y = 0; y < h; ++y) {  // readPixels rows are bottom-up
            img.data.set(px.subarray((h - 1 - y) * w * 4, (h - y) * w * 4), y * w * 4);
          }
          ctx.putImageData(img, x0, y0);
        }
      }
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.deleteFramebuffer(fbo);
      gl.deleteRenderbuffer(rb);
      this.redraw();
      return out;
    }
    async download() {
      const c = await this.renderFull();
      const blob = await new Promise((r) => c.toBlob(r, 'image/png'));
      const a = document.createElement('a');
      const l = this.light.map((v) => v.toFixed(3)).join('_');
      a.download = `relit_${l}.png`;
      a.href = URL.createObjectURL(blob);
      document.body.appendChild(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(a.href), 10000);
      return blob;
    }

    // A bar of a round length (1, 2 or 5 times a power of ten, in mm) about 120 px long.
    updateScaleBar() {
      const bar = document.getElementById('scalebar');
      if (!bar) return;
      const mm = this.info.pixelSizeInMM;
      if (!(mm > 0)) { bar.hidden = true; return; }
      const dpr = window.devicePixelRatio || 1;
      const mmPerCss = mm / this.view.zoom * dpr;
      const want = 120 * mmPerCss;
      const p = 10 ** Math.floor(Math.log10(want));
      const len = [1, 2, 5, 10].map((k) => k * p).filter((v) => v <= want).pop() || p;
      document.getElementById('scalebar-bar').style.width = `${len / mmPerCss}px`;
      document.getElementById('scalebar-label').textContent =
        len >= 10 ? `${+(len / 10).toPrecision(3)} cm` : len >= 1 ? `${+len.toPrecision(3)} mm`
          : `${+(len * 1000).toPrecision(3)} µm`;
      bar.hidden = false;
    }

    status(text) {
      const s = document.getElementById('status');
      if (s) s.textContent = text;
    }
  }

  // ---- the page ----------------------------------------------------------------------------

  function drawLightWidget(canvas, light) {
    const ctx = canvas.getContext('2d'), w = canvas.width, r = w / 2 - 6;
    ctx.clearRect(0, 0, w, w);
    ctx.fillStyle = '#111';
    ctx.beginPath(); ctx.arc(w / 2, w / 2, r, 0, 2 * Math.PI); ctx.fill();
    ctx.strokeStyle = '#555';
    for (const e of [30, 60]) {  // elevation rings
      ctx.beginPath(); ctx.arc(w / 2, w / 2, r * Math.cos(e * Math.PI / 180), 0, 2 * Math.PI); ctx.stroke();
    }
    ctx.beginPath(); ctx.moveTo(w / 2 - r, w / 2); ctx.lineTo(w / 2 + r, w / 2);
    ctx.moveTo(w / 2, w / 2 - r); ctx.lineTo(w / 2, w / 2 + r); ctx.stroke();
    const x = w / 2 + light[0] * r, y = w / 2 - light[1] * r;  // y up the image
    const g = ctx.createRadialGradient(x, y, 1, x, y, 9);
    g.addColorStop(0, '#fff'); g.addColorStop(1, 'rgba(255,220,120,0)');
    ctx.fillStyle = g;
    ctx.beginPath(); ctx.arc(x, y, 9, 0, 2 * Math.PI); ctx.fill();
  }

  function lightText(l) {
    const el = Math.asin(Math.max(-1, Math.min(1, l[2]))) * 180 / Math.PI;
    let az = Math.atan2(l[1], l[0]) * 180 / Math.PI;
    if (az < 0) az += 360;
    return `${l.map((v) => v.toFixed(3)).join(', ')}\nel ${el.toFixed(1)}°  az ${az.toFixed(0)}°`;
  }

  async function main() {
    const canvas = document.getElementById('view');
    const message = document.getElementById('message');
    let viewer;
    try {
      viewer = new Viewer(canvas);
      window.ptmkitViewer = viewer;
      const params = new URLSearchParams(location.search);
      await viewer.open();
      if (params.has('light')) {
        const l = params.get('light').split(',').map(Number);
        if (l.length === 3) viewer.setLight(l);
      }
    } catch (e) {
      message.textContent = 'Cannot show this folder: ' + e.message;
      message.hidden = false;
      window.ptmkitViewerError = e.message;
      throw e;
    }
    const info = viewer.info;
    document.getElementById('title').textContent =
      `${info.type} ${info.colorspace}, ${info.width} × ${info.height}` +
      (viewer.layout.type === 'deepzoom' ? `, ${viewer.layout.levels.length} levels` : '');
    document.getElementById('mode-normals').disabled = !viewer.normals;

    // Light widget: drag inside the circle; the rim is the horizon.
    const widget = document.getElementById('light-widget');
    const text = document.getElementById('light-text');
    const fromWidget = (ev) => {
      const b = widget.getBoundingClientRect(), r = b.width / 2 - 6;
      let x = (ev.clientX - b.left - b.width / 2) / r, y = -(ev.clientY - b.top - b.height / 2) / r;
      const d = Math.hypot(x, y);
      if (d > 1) { x /= d; y /= d; }
      viewer.setLight([x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))]);
    };
    let moving = false;
    widget.addEventListener('pointerdown', (ev) => {
      widget.setPointerCapture(ev.pointerId);
      moving = true;
      fromWidget(ev);
    });
    widget.addEventListener('pointermove', (ev) => { if (moving) fromWidget(ev); });
    widget.addEventListener('pointerup', (ev) => { if (moving) fromWidget(ev); moving = false; });
    widget.addEventListener('pointercancel', () => { moving = false; });
    const refresh = () => {
      drawLightWidget(widget, viewer.light);
      text.textContent = lightText(viewer.light);
      document.getElementById('mode-light').classList.toggle('active', viewer.mode === 'light');
      document.getElementById('mode-normals').classList.toggle('active', viewer.mode === 'normals');
    };
    viewer.onChange(refresh);
    refresh();

    // Pan by dragging the image (shift-drag moves the light), zoom with the wheel.
    let drag = null;
    canvas.addEventListener('pointerdown', (ev) => {
      canvas.setPointerCapture(ev.pointerId);
      drag = {x: ev.clientX, y: ev.clientY, cx: viewer.view.cx, cy: viewer.view.cy, shift: ev.shiftKey};
      canvas.classList.add('dragging');
    });
    canvas.addEventListener('pointermove', (ev) => {
      if (!drag) return;
      const dpr = window.devicePixelRatio || 1;
      if (drag.shift) {
        const b = canvas.getBoundingClientRect(), r = Math.min(b.width, b.height) / 2;
        let x = (ev.clientX - b.left - b.width / 2) / r, y = -(ev.clientY - b.top - b.height / 2) / r;
        const d = Math.hypot(x, y);
        if (d > 1) { x /= d; y /= d; }
        viewer.setLight([x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))]);
        return;
      }
      viewer.setView({cx: drag.cx - (ev.clientX - drag.x) * dpr / viewer.view.zoom,
        cy: drag.cy - (ev.clientY - drag.y) * dpr / viewer.view.zoom});
    });
    const end = () => { drag = null; canvas.classList.remove('dragging'); };
    canvas.addEventListener('pointerup', end);
    canvas.addEventListener('pointercancel', end);
    canvas.addEventListener('wheel', (ev) => {
      ev.preventDefault();
      const b = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
      viewer.zoomAt(Math.pow(2, -ev.deltaY / 300), (ev.clientX - b.left) * dpr, (ev.clientY - b.top) * dpr);
    }, {passive: false});
    const centre = () => [canvas.width / 2, canvas.height / 2];
    document.getElementById('zoom-in').onclick = () => viewer.zoomAt(2, ...centre());
    document.getElementById('zoom-out').onclick = () => viewer.zoomAt(0.5, ...centre());
    document.getElementById('zoom-fit').onclick = () => viewer.fit();
    document.getElementById('zoom-one').onclick = () => viewer.setView({zoom: 1});
    document.getElementById('mode-light').onclick = () => viewer.setMode('light');
    document.getElementById('mode-normals').onclick = () => viewer.setMode('normals');
    document.getElementById('download').onclick = async () => {
      viewer.status('rendering the full image...');
      await viewer.download();
      viewer.status('');
    };
    new ResizeObserver(() => viewer.resize()).observe(canvas);
    viewer.ready = true;
  }

  window.ptmkitViewerReady = main();
})();
