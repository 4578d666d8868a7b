// The web viewer in a real browser: `omnisculpt view REC` on a reconstruction with snapshots,
// then Debian's chromium, headless (software WebGL), driven through the DevTools protocol
// (the npm package `ws`, pinned in viewer/package-lock.json). It opens OUT/viewer/index.html
// from the file system and checks what a user would: the mesh is drawn (pixels other than the
// background in the middle, the mesh's colours), the normal colouring colours the walls, the
// time slider changes the number of triangles the page shows, "view from keyframe" changes the
// picture, and the console has no error. A browser that cannot start fails the test.
//
// Usage: node viewer_browser_test.js --omnisculpt BIN --rec FOLDER --work FOLDER [--chromium BIN]
'use strict';

const { spawn, spawnSync } = require('child_process');
const fs = require('fs');
const http = require('http');
const path = require('path');
const zlib = require('zlib');
const WebSocket = require('ws');

const args = {};
for (let i = 2; i + 1 < process.argv.length; i += 2) args[process.argv[i].replace(/^--/, '')] = process.argv[i + 1];
const chromium_binary = args.chromium || '/usr/bin/chromium';
const width = 1400, height = 800;
const side_panel = 360;  // viewer.css #side: the 3D view is the rest, on the left
const background = [0x14, 0x17, 0x1d];

let passed = 0, failed = 0;
let browser_process = null;  // killed on every way out
function Check(condition, what) {
  if (condition) { ++passed; console.log('ok   ' + what); } else { ++failed; console.log('FAIL ' + what); }
}
function Finish(browser, code) {
  browser = browser || browser_process;
  if (browser && browser.exitCode === null) browser.kill('SIGKILL');
  console.log(passed + ' passed, ' + failed + ' failed');
  process.exit(code !== undefined ? code : (failed > 0 ? 1 : 0));
}
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// ---- PNG decoding (8-bit RGB or RGBA, not interlaced: what chromium writes) ------------------
function DecodePng(buffer) {
  if (buffer.readUInt32BE(0) !== 0x89504e47) throw new Error('not a PNG');
  let offset = 8, w = 0, h = 0, type = 0;
  const idat = [];
  while (offset < buffer.length) {
    const length = buffer.readUInt32BE(offset);
    const kind = buffer.toString('ascii', offset + 4, offset + 8);
    const data = buffer.subarray(offset + 8, offset + 8 + length);
    if (kind === 'IHDR') {
      w = data.readUInt32BE(0); h = data.readUInt32BE(4); type = data[9];
      if (data[8] !== 8 || (type !== 2 && type !== 6) || data[12] !== 0) throw new Error('unsupported PNG');
    } else if (kind === 'IDAT') idat.push(data);
    offset += 12 + length;
  }
  const channels = type === 6 ? 4 : 3, stride = w * channels;
  const raw = zlib.inflateSync(Buffer.concat(idat));
  const out = Buffer.alloc(w * h * 3);
  let previous = Buffer.alloc(stride), row = Buffer.alloc(stride);
  for (let y = 0; y < h; ++y) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; ++x) {
      const a = x >= channels ? row[x - channels] : 0, b = previous[x], c = x >= channels ? previous[x - channels] : 0;
      let v = line[x];
      if (filter === 1) v += a;
      else if (filter === 2) v += b;
      else if (filter === 3) v += (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
        v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      }
      row[x] = v & 255;
    }
    for (let x = 0; x < w; ++x) for (let k = 0; k < 3; ++k) out[(y * w + x) * 3 + k] = row[x * channels + k];
    [previous, row] = [row, previous];
  }
  return { width: w, height: h, rgb: out };
}

// Pixel statistics over the middle of the 3D view (the central half of its width and height).
function MiddleStats(image) {
  const view_width = image.width - side_panel;
  const x0 = Math.floor(view_width / 4), x1 = Math.floor(view_width * 3 / 4);
  const y0 = Math.floor(image.height / 4), y1 = Math.floor(image.height * 3 / 4);
  let total = 0, drawn = 0, grey = 0, saturated = 0;
  for (let y = y0; y < y1; ++y) {
    for (let x = x0; x < x1; ++x) {
      const i = (y * image.width + x) * 3;
      const r = image.rgb[i], g = image.rgb[i + 1], b = image.rgb[i + 2];
      ++total;
      const distance = Math.abs(r - background[0]) + Math.abs(g - background[1]) + Math.abs(b - background[2]);
      if (distance <= 24) continue;
      ++drawn;
      const spread = Math.max(r, g, b) - Math.min(r, g, b);
      if (spread > 80) ++saturated;
      else if (spread < 24) ++grey;
    }
  }
  return { drawn: drawn / total, grey: grey / total, saturated: saturated / total };
}
function DifferentShare(a, b) {
  let different = 0;
  const view_width = a.width - side_panel;
  for (let y = 0; y < a.height; ++y)
    for (let x = 0; x < view_width; ++x) {
      const i = (y * a.width + x) * 3;
      if (Math.abs(a.rgb[i] - b.rgb[i]) + Math.abs(a.rgb[i + 1] - b.rgb[i + 1]) + Math.abs(a.rgb[i + 2] - b.rgb[i + 2]) > 30) ++different;
    }
  return different / (view_width * a.height);
}

// ---- DevTools protocol ---------------------------------------------------------------------
function GetJson(url) {
  return new Promise((resolve, reject) => {
    http.get(url, (response) => {
      let text = '';
      response.on('data', (chunk) => { text += chunk; });
      response.on('end', () => { try { resolve(JSON.parse(text)); } catch (e) { reject(e); } });
    }).on('error', reject);
  });
}
class Page {
  constructor(socket) {
    this.socket = socket; this.next = 1; this.waiting = new Map(); this.errors = []; this.warnings = [];
    socket.on('message', (text) => {
      const message = JSON.parse(text);
      if (message.id && this.waiting.has(message.id)) {
        const { resolve, reject } = this.waiting.get(message.id);
        this.waiting.delete(message.id);
        if (message.error) reject(new Error(JSON.stringify(message.error))); else resolve(message.result);
      } else if (message.method === 'Runtime.consoleAPICalled') {
        const line = message.params.args.map((a) => a.value !== undefined ? a.value : a.description).join(' ');
        if (message.params.type === 'error' || message.params.type === 'assert') this.errors.push('console: ' + line);
        else if (message.params.type === 'warning') this.warnings.push(line);
      } else if (message.method === 'Runtime.exceptionThrown') {
        this.errors.push('exception: ' + JSON.stringify(message.params.exceptionDetails.exception
          ? message.params.exceptionDetails.exception.description : message.params.exceptionDetails.text));
      } else if (message.method === 'Log.entryAdded' && message.params.entry.level === 'error') {
        this.errors.push('log: ' + message.params.entry.text + ' ' + (message.params.entry.url || ''));
      }
    });
  }
  Send(method, params) {
    const id = this.next++;
    this.socket.send(JSON.stringify({ id, method, params: params || {} }));
    return new Promise((resolve, reject) => this.waiting.set(id, { resolve, reject }));
  }
  async Evaluate(expression) {
    const result = await this.Send('Runtime.evaluate', { expression, returnByValue: true, awaitPromise: true });
    if (result.exceptionDetails) throw new Error('evaluate ' + expression + ': ' + result.exceptionDetails.text);
    return result.result.value;
  }
  async WaitFor(expression, seconds, what) {
    const end = Date.now() + seconds * 1000;
    while (Date.now() < end) {
      if (await this.Evaluate(expression)) return true;
      await sleep(100);
    }
    throw new Error('timed out after ' + seconds + ' s waiting for ' + what);
  }
  // A screenshot after `frames` more frames were drawn.
  async Screenshot(file, frames) {
    const start = await this.Evaluate('window.omniViewer.frames()');
    await this.WaitFor('window.omniViewer.frames() >= ' + (start + (frames || 3)), 60, 'frames drawn');
    const shot = await this.Send('Page.captureScreenshot', { format: 'png' });
    const bytes = Buffer.from(shot.data, 'base64');
    fs.writeFileSync(file, bytes);
    return DecodePng(bytes);
  }
}

async function Main() {
  for (const key of ['omnisculpt', 'rec', 'work'])
    if (!args[key]) { console.log('usage: --omnisculpt BIN --rec FOLDER --work FOLDER'); Finish(null, 2); }
  fs.rmSync(args.work, { recursive: true, force: true });
  fs.mkdirSync(args.work, { recursive: true });
  const view = spawnSync(args.omnisculpt, ['--quiet', 'view', args.rec], { encoding: 'utf8' });
  Check(view.status === 0, 'omnisculpt view exits 0 (' + (view.stderr || '').trim() + ')');
  const index = path.resolve(args.rec, 'viewer', 'index.html');
  Check(fs.existsSync(index), 'OUT/viewer/index.html written');
  if (failed) Finish(null);

  // The browser: a failure to start fails the test.
  const browser = spawn(chromium_binary, [
    '--headless=new', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader', '--no-first-run', '--no-default-browser-check',
    '--remote-debugging-port=0', '--user-data-dir=' + path.join(args.work, 'profile'),
    '--window-size=' + width + ',' + height, 'about:blank'], { stdio: ['ignore', 'ignore', 'pipe'] });
  browser_process = browser;
  let stderr = '';
  const endpoint = await new Promise((resolve) => {
    const timer = setTimeout(() => resolve(null), 60000);
    browser.on('error', (e) => { stderr += String(e); clearTimeout(timer); resolve(null); });
    browser.on('exit', () => { clearTimeout(timer); resolve(null); });
    browser.stderr.on('data', (chunk) => {
      stderr += chunk;
      const match = /DevTools listening on (ws:\/\/[^\s]+)/.exec(stderr);
      if (match) { clearTimeout(timer); resolve(match[1]); }
    });
  });
  Check(endpoint !== null, 'chromium starts (' + chromium_binary + ')');
  if (!endpoint) { console.log(stderr.slice(-2000)); Finish(browser); }
  const port = new URL(endpoint).port;
  const targets = await GetJson('http://127.0.0.1:' + port + '/json/list');
  const target = targets.find((t) => t.type === 'page');
  const socket = new WebSocket(target.webSocketDebuggerUrl, { perMessageDeflate: false, maxPayload: 512 * 1024 * 1024 });
  await new Promise((resolve, reject) => { socket.on('open', resolve); socket.on('error', reject); });
  const page = new Page(socket);
  await page.Send('Runtime.enable');
  await page.Send('Log.enable');
  await page.Send('Page.enable');
  await page.Send('Emulation.setDeviceMetricsOverride', { width, height, deviceScaleFactor: 1, mobile: false });
  const started = Date.now();
  await page.Send('Page.navigate', { url: 'file://' + index });
  await page.WaitFor("document.body && document.body.dataset.ready === '1'", 90, 'the scene (body data-ready)');
  console.log('scene ready in ' + ((Date.now() - started) / 1000).toFixed(1) + ' s');

  const scene = await page.Evaluate('({ snapshot_keyframes: OMNI_SCENE.snapshots.map((s) => s.keyframe), loop_keyframes: OMNI_SCENE.loop_closures.map((l) => l.keyframe), snapshots: OMNI_SCENE.snapshots.map((s) => s.triangles), triangles: OMNI_SCENE.surface.triangles, keyframes: OMNI_SCENE.keyframes.length, cameras: OMNI_SCENE.cameras.length })');
  const triangles_shown = async () => +(await page.Evaluate("document.getElementById('triangle-count').textContent"));
  Check(await triangles_shown() === scene.triangles, 'the page shows the final surface: ' + scene.triangles + ' triangles');
  Check(scene.snapshots.length >= 2, scene.snapshots.length + ' snapshots in the slider');

  // The final surface, vertex colours (this drive's images are grey: grey points, grey mesh).
  const final_shot = await page.Screenshot(path.join(args.work, 'viewer_final.png'));
  await page.Evaluate("(() => { const t = document.getElementById('show-trajectory'); t.checked = false; t.dispatchEvent(new Event('change')); })()");
  const vertex = MiddleStats(await page.Screenshot(path.join(args.work, 'viewer_vertex_colours.png')));
  console.log('vertex colours, middle: drawn ' + vertex.drawn.toFixed(3) + ', grey ' + vertex.grey.toFixed(3) + ', saturated ' + vertex.saturated.toFixed(3));
  Check(vertex.drawn > 0.3, 'the mesh is drawn: ' + (100 * vertex.drawn).toFixed(1) + '% of the middle is not background');
  Check(vertex.grey > 0.2 && vertex.saturated < 0.01, 'the mesh has its vertex colours (grey for this drive): ' + (100 * vertex.grey).toFixed(1) + '% grey, ' + (100 * vertex.saturated).toFixed(2) + '% saturated');
  await page.Evaluate("(() => { const c = document.getElementById('coloring'); c.value = 'normal'; c.dispatchEvent(new Event('change')); })()");
  const normal = MiddleStats(await page.Screenshot(path.join(args.work, 'viewer_normal_colouring.png')));
  console.log('normal colouring, middle: drawn ' + normal.drawn.toFixed(3) + ', saturated ' + normal.saturated.toFixed(3));
  Check(normal.saturated > 0.05, 'the normal colouring colours the walls: ' + (100 * normal.saturated).toFixed(1) + '% saturated');
  await page.Evaluate("(() => { const c = document.getElementById('coloring'); c.value = 'vertex'; c.dispatchEvent(new Event('change')); const t = document.getElementById('show-trajectory'); t.checked = true; t.dispatchEvent(new Event('change')); })()");

  // The time slider: each snapshot shows its own number of triangles.
  const move_slider = (value) => page.Evaluate("(() => { const s = document.getElementById('time-slider'); s.value = '" + value + "'; s.dispatchEvent(new Event('input')); })()");
  await move_slider(0);
  await page.WaitFor("+document.getElementById('triangle-count').textContent === " + scene.snapshots[0], 30, 'the first snapshot');
  Check(await triangles_shown() === scene.snapshots[0], 'slider at the first snapshot: ' + scene.snapshots[0] + ' triangles shown (final: ' + scene.triangles + ')');
  const first_shot = await page.Screenshot(path.join(args.work, 'viewer_snapshot_first.png'));
  const last = scene.snapshots.length - 1;
  await move_slider(last);
  await page.WaitFor("+document.getElementById('triangle-count').textContent === " + scene.snapshots[last], 30, 'the last snapshot');
  Check(scene.snapshots[0] !== scene.snapshots[last] && await triangles_shown() === scene.snapshots[last], 'slider at the last snapshot: ' + scene.snapshots[last] + ' triangles shown');
  const last_shot = await page.Screenshot(path.join(args.work, 'viewer_snapshot_last.png'));
  Check(DifferentShare(first_shot, last_shot) > 0.01, 'the first and the last snapshots look different (' + (100 * DifferentShare(first_shot, last_shot)).toFixed(1) + '% of the view)');

  // The first snapshot after a loop closure says that the surface was re-sculpted; the one
  // before it does not.
  const after_loop = scene.loop_keyframes.length ? scene.snapshot_keyframes.findIndex((k) => k >= scene.loop_keyframes[0]) : -1;
  Check(after_loop > 0, 'a snapshot before and one after the first loop closure (keyframe ' + scene.loop_keyframes[0] + ')');
  if (after_loop > 0) {
    const badge = async (i) => { await move_slider(i); return page.Evaluate("!document.getElementById('replay-badge').hidden && document.getElementById('time-label').textContent.includes('re-sculpting')"); };
    Check(!(await badge(after_loop - 1)) && await badge(after_loop), 'the snapshot after the loop closure shows the re-sculpting, the one before does not');
    await page.WaitFor("+document.getElementById('triangle-count').textContent === " + scene.snapshots[after_loop], 30, 'the snapshot after the loop closure');
    await page.Screenshot(path.join(args.work, 'viewer_after_loop_closure.png'));
  }

  // Play: the slider moves by itself.
  await move_slider(0);
  await page.Evaluate("document.getElementById('play').click()");
  const played = await page.Evaluate("new Promise((resolve) => setTimeout(() => resolve(+document.getElementById('time-slider').value), 2500))");
  await page.Evaluate("document.getElementById('play').click()");
  Check(played >= 2, 'play moves the slider by itself: at ' + played + ' after 2.5 s');
  await move_slider(scene.snapshots.length);
  await page.WaitFor("+document.getElementById('triangle-count').textContent === " + scene.triangles, 30, 'the final surface again');

  // View from keyframe K with a rig camera.
  const before = await page.Screenshot(path.join(args.work, 'viewer_before_keyframe_view.png'));
  const k = Math.floor(scene.keyframes / 3);
  await page.Evaluate("(() => { document.getElementById('view-keyframe').value = '" + k + "'; document.getElementById('view-camera').value = '0'; document.getElementById('view-from-keyframe').click(); })()");
  const from_keyframe = await page.Screenshot(path.join(args.work, 'viewer_from_keyframe.png'));
  const changed = DifferentShare(before, from_keyframe);
  Check(changed > 0.2, 'view from keyframe ' + k + ' (camera 0 of ' + scene.cameras + ') changes the picture: ' + (100 * changed).toFixed(1) + '% of the view');
  Check(MiddleStats(from_keyframe).drawn > 0.2, 'the keyframe view shows the surface');
  const selection = await page.Evaluate("document.getElementById('selection').textContent");
  Check(selection.startsWith('keyframe ' + k + ','), 'the selection names keyframe ' + k + ': ' + selection.split('\n')[0]);
  // Clicking a keyframe and a loop closure in the overview names them.
  const click = async (where) => {
    for (const type of ['mousePressed', 'mouseReleased'])
      await page.Send('Input.dispatchMouseEvent', { type, x: where.x, y: where.y, button: 'left', clickCount: 1 });
  };
  await page.Evaluate("document.getElementById('overview').click()");
  await page.Screenshot(path.join(args.work, 'viewer_overview.png'));
  const k_click = Math.floor(scene.keyframes * 2 / 3);
  await click(await page.Evaluate('window.omniViewer.screenPosition(' + k_click + ')'));
  const clicked = (await page.Evaluate("document.getElementById('selection').textContent")).split('\n')[0];
  Check(clicked.startsWith('keyframe ' + k_click + ','), 'a click on keyframe ' + k_click + ' selects it: ' + clicked);
  const loop_keyframes = await page.Evaluate('window.omniViewer.loopKeyframes()');
  Check(loop_keyframes.length >= 1, loop_keyframes.length + ' loop closure(s) marked');
  if (loop_keyframes.length >= 1) {
    await click(await page.Evaluate('window.omniViewer.screenPosition(' + loop_keyframes[0] + ')'));
    const loop_text = await page.Evaluate("document.getElementById('selection').textContent");
    Check(loop_text.startsWith('loop closure 1: keyframe ' + loop_keyframes[0]) && loop_text.includes('correction'),
          'a click on the loop closure shows it: ' + loop_text.replace(/\n/g, ' | '));
  }
  const final_stats = MiddleStats(final_shot);
  Check(final_stats.drawn > 0.3, 'the first screenshot shows the scene');

  for (const warning of page.warnings) console.log('console warning: ' + warning);
  for (const error of page.errors) console.log('console error: ' + error);
  Check(page.errors.length === 0, 'no console error (' + page.errors.length + ')');
  try { await page.Send('Browser.close'); } catch (e) { /* closing */ }
  socket.terminate();
  Finish(browser);
}

Main().catch((error) => { console.log('FAIL ' + error.stack); ++failed; Finish(null, 1); });
