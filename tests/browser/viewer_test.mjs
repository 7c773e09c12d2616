// Browser test of the web export and its viewer: Debian's chromium (SwiftShader WebGL2)
// driven by playwright-core, pages served by `ptmkit view` on 127.0.0.1.
//
// Usage: node viewer_test.mjs PTMKIT WORK_DIR [CHROMIUM]
// Checks (each failure is reported; the exit code is 1 if any failed):
//  - for an RGB PTM, an LRGB PTM and an HSH .rti, at 5 lights (one 10 degrees above the
//    horizon), the canvas at 1:1 against `ptmkit relight` of the same file at the same light:
//    mean <= 1 and max <= 3 grey levels; the same canvas flipped vertically, mirrored, or
//    compared at the mirrored light must fail those bounds (orientation is tested);
//  - the canvas against an evaluation of the exported planes written here (decoded by the
//    browser's 2D canvas, summed in double precision): the shader itself, without JPEG loss;
//  - deep zoom: zoomed out, the coarse level's tiles are fetched; at 1:1 on a region, exactly
//    the finest level's tiles over that region are fetched and the canvas matches `ptmkit
//    relight` cropped there;
//  - the full-resolution download, the normals layer, the scale bar, the light widget, pan;
//  - `ptmkit view` answers range requests, serves 127.0.0.1 only, stops on SIGTERM.
import {execFileSync, spawn} from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import {createRequire} from 'node:module';
import {decodePng, diff, flipVertical, flipHorizontal, crop} from './png.mjs';

const [ptmkit, workArg, chromiumArg] = process.argv.slice(2);
const chromiumPath = chromiumArg || '/usr/bin/chromium';
const work = path.resolve(workArg);
const require = createRequire(path.join(work, 'node', 'package.json'));
const {chromium} = require('playwright-core');

const BOUND_MEAN = 1, BOUND_MAX = 3;
let failures = 0;
function check(ok, what) {
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
  if (!ok) ++failures;
}
const fmt = (d) => `mean ${d.mean.toFixed(3)}, max ${d.max}`;
const within = (d) => d.mean <= BOUND_MEAN && d.max <= BOUND_MAX;

function run(...args) {
  return execFileSync(ptmkit, args, {encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe']});
}

// Starts `ptmkit view`, resolves with {url, proc, exited} once it prints its address.
function startView(input, extra = []) {
  const proc = spawn(ptmkit, ['view', input, '--port', '0', '--exit-after-seconds', '300', ...extra],
    {stdio: ['ignore', 'pipe', 'pipe']});
  const exited = new Promise((resolve) => proc.on('exit', (code, sig) => resolve({code, sig})));
  return new Promise((resolve, reject) => {
    let out = '', err = '';
    proc.stderr.on('data', (d) => { err += d; });
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/at (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) resolve({url: m[1], proc, exited, output: () => out});
    });
    exited.then(({code}) => reject(new Error(`ptmkit view exited (${code}): ${err}`)));
    setTimeout(() => reject(new Error('ptmkit view did not print its address')), 30000);
  });
}

async function stopView(v) {
  v.proc.kill('SIGTERM');
  const {code, sig} = await v.exited;
  return code === 0 && sig === null && /stopped/.test(v.output());
}

function lightAt(elevationDeg, azimuthDeg) {
  const e = elevationDeg * Math.PI / 180, a = azimuthDeg * Math.PI / 180;
  return [Math.cos(e) * Math.cos(a), Math.cos(e) * Math.sin(a), Math.sin(e)];
}
const LIGHTS = [
  [0, 0, 1],
  lightAt(40, 30),
  lightAt(55, 160),
  lightAt(25, 290),
  lightAt(10, 135),  // 10 degrees above the horizon
];
const lightArg = (l) => l.map((v) => v.toFixed(9)).join(',');

function relightRef(input, l, name) {
  const out = path.join(work, `${name}.png`);
  run('relight', input, '--light', lightArg(l), '-o', out);
  return decodePng(fs.readFileSync(out));
}

async function openViewer(page, url) {
  await page.goto(url);
  await page.waitForFunction(() => window.ptmkitViewer && window.ptmkitViewer.ready ||
    window.ptmkitViewerError, null, {timeout: 30000});
  const error = await page.evaluate(() => window.ptmkitViewerError || null);
  if (error) throw new Error('viewer: ' + error);
}

// Canvas of w x h CSS (= device) pixels, one image pixel per pixel, the image point
// (x0, y0) at its top-left corner.
async function setOneToOne(page, x0, y0, w, h) {
  await page.evaluate(([x0, y0, w, h]) => {
    const v = window.ptmkitViewer;
    v.canvas.style.width = `${w}px`;
    v.canvas.style.height = `${h}px`;
    v.resize();
    v.setView({cx: x0 + w / 2, cy: y0 + h / 2, zoom: 1});
  }, [x0, y0, w, h]);
}

async function canvasAt(page, l) {
  const data = await page.evaluate(async (l) => {
    const v = window.ptmkitViewer;
    v.setLight(l);
    await v.idle();
    return v.canvas.toDataURL('image/png');
  }, l);
  return decodePng(Buffer.from(data.split(',')[1], 'base64'));
}

// Test code's own evaluation of the folder's planes (an independent reader): each JPEG
// decoded by the browser's 2D canvas, coef = (byte / 255 - bias) * scale, the basis in
// double precision, clamped, rounded.
async function planesEvaluation(page, l, region) {
  const rgb = await page.evaluate(async ([l, region]) => {
    const info = await (await fetch('info.json')).json();
    const np = info.nplanes, m = info.materials[0];
    const [X0, Y0, W, H] = region || [0, 0, info.width, info.height];
    const jpegs = Math.ceil(np / 3);
    const planes = [];
    for (let j = 0; j < jpegs; ++j) {
      const bmp = await createImageBitmap(await (await fetch(`plane_${j}.jpg`)).blob(),
        {colorSpaceConversion: 'none', premultiplyAlpha: 'none'});
      const c = new OffscreenCanvas(W, H).getContext('2d');
      c.drawImage(bmp, -X0, -Y0);
      planes.push(c.getImageData(0, 0, W, H).data);
    }
    const n = Math.hypot(...l), x = l[0] / n, y = l[1] / n, z = l[2] / n;
    let basis;
    if (info.type === 'ptm') {
      basis = [1, x, y, x * x, x * y, y * y];
    } else {
      const th = Math.min(Math.acos(z), Math.PI / 2 - 0.04), ph = Math.atan2(y, x);
      const c = Math.cos(th), c2 = c * c, s = Math.sqrt(Math.max(0, c - c2));
      const k30 = Math.sqrt(30 / Math.PI);
      basis = [1 / Math.sqrt(2 * Math.PI), Math.sqrt(6 / Math.PI) * Math.cos(ph) * s,
        Math.sqrt(3 / (2 * Math.PI)) * (2 * c - 1), Math.sqrt(6 / Math.PI) * Math.sin(ph) * s,
        k30 * Math.cos(2 * ph) * (c2 - c), k30 * Math.cos(ph) * (2 * c - 1) * s,
        Math.sqrt(5 / (2 * Math.PI)) * (6 * c2 - 6 * c + 1), k30 * Math.sin(ph) * (2 * c - 1) * s,
        k30 * Math.sin(2 * ph) * (c2 - c)];
    }
    const coef = (p, i) => (planes[Math.floor(p / 3)][4 * i + (p % 3)] / 255 - m.bias[p]) * m.scale[p];
    const out = new Array(W * H * 3);
    for (let i = 0; i < W * H; ++i) {
      let c3 = [0, 0, 0];
      if (z <= 0) {
        c3 = [0, 0, 0];
      } else if (info.colorspace === 'lrgb') {
        let lum = 0;
        for (let t = 0; t < 6; ++t) lum += basis[t] * coef(3 + t, i);
        c3 = [0, 1, 2].map((k) => lum * coef(k, i));
      } else {
        for (let t = 0; t < np / 3; ++t) for (let k = 0; k < 3; ++k) c3[k] += basis[t] * coef(3 * t + k, i);
      }
      for (let k = 0; k < 3; ++k) out[3 * i + k] = Math.round(Math.min(1, Math.max(0, c3[k])) * 255);
    }
    return out;
  }, [l, region]);
  return Uint8Array.from(rgb);
}

async function main() {
  fs.mkdirSync(work, {recursive: true});
  const t0 = Date.now();
  // A rendered capture, not square (a transposed image cannot pass), fitted three ways.
  const cap = path.join(work, 'cap');
  fs.rmSync(cap, {recursive: true, force: true});
  run('synth', '--out', cap, '--width', '120', '--height', '90', '--seed', '7');
  const textures = {
    rgb: path.join(work, 'rgb.ptm'), lrgb: path.join(work, 'lrgb.ptm'), hsh: path.join(work, 'hsh.rti'),
  };
  const normalsPng = path.join(work, 'normals.png');
  run('fit', path.join(cap, 'lights.lp'), '-o', textures.rgb, '--normals', normalsPng);
  run('fit', path.join(cap, 'lights.lp'), '-o', textures.lrgb, '--format', 'lrgb');
  run('fit', path.join(cap, 'lights.lp'), '-o', textures.hsh, '--model', 'hsh3');
  const W = 120, H = 90;

  const userData = fs.mkdtempSync(path.join(os.tmpdir(), 'ptmkit-chromium-'));
  const context = await chromium.launchPersistentContext(userData, {
    executablePath: chromiumPath,
    headless: true,
    viewport: {width: 400, height: 300},
    deviceScaleFactor: 1,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader', '--disable-background-networking',
      '--disable-component-update', '--disable-sync', '--no-first-run'],
  });
  try {
    const page = await context.newPage();
    page.on('pageerror', (e) => console.log('page error: ' + e.message));
    // Nothing but the loopback server may be reached.
    const offsite = [];
    page.on('request', (r) => { if (!r.url().startsWith('http://127.0.0.1:')) offsite.push(r.url()); });

    for (const [name, file] of Object.entries(textures)) {
      const extra = name === 'rgb' ? ['--normals', normalsPng, '--pixel-size-mm', '0.25'] : [];
      // The least lossy planes (quality 100, no colour transform: at most about one byte of
      // JPEG error a plane), so that the comparison measures the viewer, not the JPEG coding.
      const view = await startView(file, ['--quality', '100', '--jpeg-colour', 'none', ...extra]);
      await openViewer(page, view.url);
      await setOneToOne(page, 0, 0, W, H);
      for (let i = 0; i < LIGHTS.length; ++i) {
        const l = LIGHTS[i];
        const canvas = await canvasAt(page, l);
        const ref = relightRef(file, l, `${name}_ref_${i}`);
        const d = diff(canvas, ref);
        const el = (Math.asin(l[2]) * 180 / Math.PI).toFixed(0);
        check(within(d), `${name} light ${i} (elevation ${el}): canvas vs ptmkit relight: ${fmt(d)}`);
        const planes = {width: W, height: H, rgb: await planesEvaluation(page, l)};
        const dp = diff(canvas, planes);
        check(within(dp) && dp.max <= 1,
          `${name} light ${i}: canvas vs the planes evaluated in test code: ${fmt(dp)}`);
        if (i === 1 || i === 4) {
          const fv = diff(flipVertical(canvas), ref), fh = diff(flipHorizontal(canvas), ref);
          check(!within(fv), `${name} light ${i}: a vertically flipped canvas fails: ${fmt(fv)}`);
          check(!within(fh), `${name} light ${i}: a mirrored canvas fails: ${fmt(fh)}`);
          const mirrored = relightRef(file, [-l[0], l[1], l[2]], `${name}_mirror_${i}`);
          const dm = diff(canvas, mirrored);
          check(!within(dm), `${name} light ${i}: the light mirrored in x fails: ${fmt(dm)}`);
        }
      }
      // The download: the full image rendered off screen at the last light.
      const full = await page.evaluate(async () => (await window.ptmkitViewer.renderFull()).toDataURL('image/png'));
      const df = diff(decodePng(Buffer.from(full.split(',')[1], 'base64')),
        relightRef(file, LIGHTS[4], `${name}_ref_full`));
      check(within(df), `${name}: full-resolution download vs ptmkit relight: ${fmt(df)}`);

      if (name === 'rgb') {
        // Normals layer: normals.png as stored, (n + 1) / 2.
        const data = await page.evaluate(async () => {
          const v = window.ptmkitViewer;
          v.setMode('normals');
          await v.idle();
          const url = v.canvas.toDataURL('image/png');
          v.setMode('light');
          return url;
        });
        const shown = decodePng(Buffer.from(data.split(',')[1], 'base64'));
        const stored = decodePng(Buffer.from(await (await fetch(view.url + 'normals.png')).arrayBuffer()));
        const dn = diff(shown, stored);
        check(dn.max <= 1, `normals layer shows normals.png: ${fmt(dn)}`);
        // Scale bar: 0.25 mm a pixel at 1:1.
        const label = await page.evaluate(() => !document.getElementById('scalebar').hidden &&
          document.getElementById('scalebar-label').textContent);
        check(label === '2 cm', `scale bar at 0.25 mm/px, 1:1: "${label}"`);
        // Light widget: a drag to the widget's right edge puts the light at azimuth 0,
        // on the horizon.
        const box = await page.locator('#light-widget').boundingBox();
        await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
        await page.mouse.down();
        await page.mouse.move(box.x + box.width - 1, box.y + box.height / 2, {steps: 4});
        await page.mouse.up();
        const lw = await page.evaluate(() => window.ptmkitViewer.light);
        check(lw[0] > 0.99 && Math.abs(lw[1]) < 0.02 && lw[2] < 0.15,
          `light widget drag to the right edge: light ${lw.map((v) => v.toFixed(3))}`);
        // Pan: dragging the image 20 px left moves the view 20 image pixels right at 1:1.
        const before = await page.evaluate(() => window.ptmkitViewer.view.cx);
        const cb = await page.locator('#view').boundingBox();
        await page.mouse.move(cb.x + 60, cb.y + 45);
        await page.mouse.down();
        await page.mouse.move(cb.x + 40, cb.y + 45, {steps: 4});
        await page.mouse.up();
        const after = await page.evaluate(() => window.ptmkitViewer.view.cx);
        check(Math.abs(after - before - 20) < 1e-6, `pan by drag: centre x ${before} -> ${after}`);
        // Range requests.
        const r = await fetch(view.url + 'plane_0.jpg', {headers: {Range: 'bytes=2-9'}});
        const body = Buffer.from(await r.arrayBuffer());
        check(r.status === 206 && body.length === 8 && /^bytes 2-9\//.test(r.headers.get('content-range')),
          `range request: HTTP ${r.status}, ${body.length} bytes, ${r.headers.get('content-range')}`);
      } else {
        const hidden = await page.evaluate(() => document.getElementById('scalebar').hidden);
        check(hidden, `${name}: no scale bar without a pixel size`);
      }
      check(await stopView(view), `${name}: ptmkit view stops on SIGTERM with exit code 0`);
    }

    // The default export (quality 95, YCbCr for rgb): measured and printed, not bounded (the
    // JPEG coding's loss, not the viewer's, dominates; docs/WEB.md).
    for (const name of ['rgb', 'hsh']) {
      const view = await startView(textures[name]);
      await openViewer(page, view.url);
      await setOneToOne(page, 0, 0, W, H);
      for (let i = 0; i < LIGHTS.length; ++i) {
        const d = diff(await canvasAt(page, LIGHTS[i]), relightRef(textures[name], LIGHTS[i], 'default_ref'));
        console.log(`info ${name} default export (quality 95) light ${i}: canvas vs ptmkit relight: ${fmt(d)}`);
      }
      await stopView(view);
    }

    // Deep zoom: an export with small tiles, served as a folder.
    const dz = path.join(work, 'deepzoom');
    run('export', 'web', textures.hsh, '-o', dz, '--layout', 'deepzoom', '--tile-size', '32',
      '--quality', '100', '--jpeg-colour', 'none');
    const info = JSON.parse(fs.readFileSync(path.join(dz, 'info.json'), 'utf8'));
    const levels = Math.ceil(Math.log2(Math.max(W, H) / 32)) + 1;  // OpenLIME's count
    const onDisk = fs.readdirSync(path.join(dz, 'plane_0_files')).length;
    check(onDisk === levels && info.ptmkit.levels === levels,
      `deep zoom: ${onDisk} levels on disk, ${levels} expected`);
    const view = await startView(dz);
    await openViewer(page, view.url);
    const requested = () => page.evaluate(() => window.ptmkitViewer.requested.slice());
    // Zoomed out 4x: the level two below the finest is drawn, from its tiles only.
    await page.evaluate(async ([W, H]) => {
      const v = window.ptmkitViewer;
      v.canvas.style.width = `${W / 4}px`;
      v.canvas.style.height = `${H / 4}px`;
      v.resize();
      v.setView({cx: W / 2, cy: H / 2, zoom: 0.25});
      v.clearTiles();
      await v.idle();
    }, [W, H]);
    const coarse = (await requested()).filter((u) => u.startsWith('plane_0_'));
    const maxLevel = Math.max(...coarse.map((u) => +u.split('/')[1]));
    check(maxLevel === levels - 3, `zoomed out 4x: finest level fetched ${maxLevel}, expected ${levels - 3}`);
    // 1:1 on the region x 40..88, y 36..68: tiles x 1..2, y 1..2 of the finest level.
    await setOneToOne(page, 40, 36, 48, 32);
    await page.evaluate(() => window.ptmkitViewer.clearTiles());
    const l = LIGHTS[1];
    const canvas = await canvasAt(page, l);
    const fine = (await requested()).filter((u) => u.startsWith(`plane_0_files/${levels - 1}/`))
      .map((u) => path.basename(u, '.jpg')).sort();
    check(JSON.stringify(fine) === JSON.stringify(['1_1', '1_2', '2_1', '2_2']),
      `1:1 on a region: finest-level tiles fetched ${fine.join(' ')} (expected 1_1 1_2 2_1 2_2)`);
    const ref = crop(relightRef(textures.hsh, l, 'dz_ref'), 40, 36, 48, 32);
    const d = diff(canvas, ref);
    check(within(d), `deep zoom 1:1 region vs ptmkit relight cropped: ${fmt(d)}`);
    const dflip = diff(flipVertical(canvas), ref);
    check(!within(dflip), `deep zoom: the flipped region fails: ${fmt(dflip)}`);
    check(await stopView(view), 'deep zoom: ptmkit view stops on SIGTERM');

    // A folder exported by relight (OpenLIME's sample, ../shared/data): it opens in this
    // viewer as a folder, and the canvas equals the test code's evaluation of its planes.
    const sample = path.join(process.env.PTMKIT_DATA_DIR || path.join(path.dirname(new URL(import.meta.url).pathname), '..', '..', '..', 'shared', 'data'), 'real-files', 'openlime-ptm');
    if (fs.existsSync(path.join(sample, 'info.json'))) {
      const v = await startView(sample);
      await openViewer(page, v.url);
      const si = JSON.parse(fs.readFileSync(path.join(sample, 'info.json'), 'utf8'));
      // A 200 x 150 region at 1:1 (the whole 1024 x 1024 evaluated in JavaScript is slow).
      const region = [400, 300, 200, 150];
      await setOneToOne(page, ...region);
      for (const l of [LIGHTS[1], LIGHTS[4]]) {
        const c = await canvasAt(page, l);
        const dp = diff(c, {width: region[2], height: region[3], rgb: await planesEvaluation(page, l, region)});
        check(dp.max <= 1, `relight's export (openlime-ptm, ${si.width} x ${si.height}), region at 1:1: canvas vs its planes evaluated in test code: ${fmt(dp)}`);
      }
      check(await stopView(v), 'openlime-ptm: ptmkit view stops on SIGTERM');
    } else {
      console.log('skip: relight\'s sample export not found at ' + sample + ' (set PTMKIT_DATA_DIR)');
    }
    check(offsite.length === 0, `no request left 127.0.0.1 (${offsite.length})`);
  } finally {
    await context.close();
    fs.rmSync(userData, {recursive: true, force: true});
  }
  console.log(`${failures ? 'FAILED' : 'passed'}: ${failures} failure(s), ${((Date.now() - t0) / 1000).toFixed(1)} s`);
  process.exit(failures ? 1 : 0);
}

main().catch((e) => {
  console.log('FAIL ' + (e && e.stack || e));
  process.exit(1);
});
