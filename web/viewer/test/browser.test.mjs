// Real-browser test of the viewer: headless Chromium (puppeteer-core driving the system's
// /usr/bin/chromium, software GL) opens dist/ served like `perch view` does (page at /, file at
// /recording.bin, opened as /?file=/recording.bin), and checks from the page state and from
// screenshot pixels that the humanoid and the chair are drawn where the recording says.
// Chromium that does not start fails the test (it never skips). Screenshots: test/out/.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { existsSync, mkdirSync, writeFileSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';
import { createCodec, HEADER_BYTES } from '../src/reader.js';
import { PROTO_TEXT, makeSyntheticRecording, SYNTH, qrot } from './synth.mjs';
import { startServer, DIST } from './server.mjs';
import { decodePng } from './png.mjs';

const here = dirname(fileURLToPath(import.meta.url));
const OUT = join(here, 'out');
const CHROMIUM = process.env.PERCH_CHROMIUM || '/usr/bin/chromium';
const W = 1000, H = 700;
const LOAD_TIMEOUT_MS = 90000;

const codec = createCodec(PROTO_TEXT);
const rec = makeSyntheticRecording();
const good = codec.encodeRecordingFile(rec);
const corrupt = good.slice();
corrupt[HEADER_BYTES + 1000] ^= 0x01;
const truncated = good.slice(0, good.length - 500);
const otherMagic = good.slice();
otherMagic.set(new TextEncoder().encode('PERCHBNK'));
const format2 = good.slice();
new DataView(format2.buffer).setUint32(8, 2, true);
const PELVIS = rec.bodies.findIndex((b) => b.name === 'pelvis');
const LAST = SYNTH.frames - 1;

let server, browser, page;
const pageErrors = [];

// ---- colours of the screenshot (lit and shaded, so by ratios) ----------------------------------
const isBody = ([r, g, b]) => r > 60 && g > 0.35 * r && g < 0.8 * r && b < 0.5 * r && r - b > 40;
const isChair = ([r, g, b]) => b > 50 && b > 1.5 * r && b > 1.2 * g;
const isTrail = ([r, g, b]) => r > 90 && g < 0.45 * r && b < 0.45 * r;
const near = (a, b, tol) => a.every((v, i) => Math.abs(v - b[i]) <= tol);
const hexRgb = (c) => [(c >> 16) & 255, (c >> 8) & 255, c & 255];

before(async () => {
  assert.ok(existsSync(join(DIST, 'index.html')) && existsSync(join(DIST, 'viewer.js')),
    `the viewer is not built (${DIST}): run scripts/build-viewer.sh`);
  mkdirSync(OUT, { recursive: true });
  writeFileSync(join(OUT, 'recording.bin'), good);
  writeFileSync(join(OUT, 'corrupt.bin'), corrupt);
  server = await startServer({
    files: {
      '/recording.bin': good, '/corrupt.bin': corrupt, '/truncated.bin': truncated,
      '/other.bin': otherMagic, '/format2.bin': format2,
    },
  });
  if (!existsSync(CHROMIUM)) {
    throw new Error(`Chromium not found at ${CHROMIUM} (apt-get install chromium, or set PERCH_CHROMIUM)`);
  }
  try {
    browser = await puppeteer.launch({
      executablePath: CHROMIUM,
      headless: true,  // new headless mode
      args: ['--no-sandbox', '--disable-dev-shm-usage', '--use-angle=swiftshader',
        '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', `--window-size=${W},${H}`],
      timeout: 60000,
    });
  } catch (e) {
    throw new Error(`Chromium (${CHROMIUM}) could not start: ${e.message}`);
  }
  page = await browser.newPage();
  page.on('pageerror', (e) => pageErrors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') pageErrors.push(`console: ${m.text()}`); });
  await page.setViewport({ width: W, height: H, deviceScaleFactor: 1 });
});

after(async () => {
  if (browser) await browser.close();
  if (server) await server.close();
});

async function open(query) {
  pageErrors.length = 0;
  await page.goto(`${server.url}/${query}`, { waitUntil: 'load' });
  await page.waitForFunction(() => window.perchViewer && (window.perchViewer.loaded || window.perchViewer.error),
    { timeout: LOAD_TIMEOUT_MS });
  return page.evaluate(() => ({ loaded: perchViewer.loaded, error: perchViewer.error, webgl: perchViewer.webgl }));
}

const state = () => page.evaluate(() => ({
  episode: perchViewer.episode, frame: perchViewer.frame, numFrames: perchViewer.numFrames,
  numEpisodes: perchViewer.numEpisodes, playing: perchViewer.playing,
}));
const seek = (e, f) => page.evaluate((e, f) => perchViewer.seek(e, f), e, f);
const project = (p) => page.evaluate((p) => perchViewer.project(...p), p);
const bodyWorld = (n) => page.evaluate((n) => perchViewer.bodyWorld(n), n);

async function shot(name) {
  const png = await page.screenshot({ type: 'png' });
  writeFileSync(join(OUT, name), png);
  const img = decodePng(Buffer.from(png));
  assert.equal(img.width, W);
  assert.equal(img.height, H);
  return img;
}

// the recording's world points of a frame: body origins and geom end points
function bodyPoints(ep, k) {
  const f = rec.episodes[ep].frames[k];
  const pts = [];
  rec.bodies.forEach((b, i) => {
    const p = f.body_pos.slice(3 * i, 3 * i + 3);
    const q = f.body_quat.slice(4 * i, 4 * i + 4);
    for (const g of b.geoms) for (const e of [g.from, g.to]) pts.push(qrot(q, e).map((v, j) => v + p[j]));
  });
  return pts;
}
const pelvisAt = (ep, k) => rec.episodes[ep].frames[k].body_pos.slice(3 * PELVIS, 3 * PELVIS + 3);

// bounding box and centroid of the pixels matching `pred`
function region(img, pred) {
  let n = 0, sx = 0, sy = 0, x0 = Infinity, y0 = Infinity, x1 = -1, y1 = -1;
  for (let y = 0; y < img.height; y++) {
    for (let x = 0; x < img.width; x++) {
      if (!pred(img.pixel(x, y))) continue;
      n++; sx += x; sy += y;
      x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y);
    }
  }
  return { n, cx: sx / n, cy: sy / n, x0, y0, x1, y1 };
}

async function projectedBox(points, pad) {
  const b = { x0: Infinity, y0: Infinity, x1: -Infinity, y1: -Infinity };
  for (const p of points) {
    for (const d of pad ? [[pad, 0, 0], [-pad, 0, 0], [0, pad, 0], [0, -pad, 0], [0, 0, pad], [0, 0, -pad]] : [[0, 0, 0]]) {
      const s = await project(p.map((v, i) => v + d[i]));
      assert.ok(s, `point ${p} projects in front of the camera`);
      b.x0 = Math.min(b.x0, s[0]); b.y0 = Math.min(b.y0, s[1]);
      b.x1 = Math.max(b.x1, s[0]); b.y1 = Math.max(b.y1, s[1]);
    }
  }
  return b;
}

async function onCanvas(px) {
  return page.evaluate(([x, y]) => document.elementFromPoint(x, y)?.tagName, px);
}

test('the page loads /?file=/recording.bin with WebGL', { timeout: 180000 }, async () => {
  const s = await open('?file=/recording.bin');
  assert.equal(s.error, null);
  assert.equal(s.loaded, true);
  assert.equal(s.webgl, true, 'WebGL (software GL) is available');
  assert.deepEqual(await state(), { episode: 0, frame: 0, numFrames: SYNTH.frames, numEpisodes: 3, playing: false });
  const options = await page.$$eval('#episode option', (os) => os.map((o) => o.textContent));
  assert.deepEqual(options, ['episode 0: success (91 frames)', 'episode 1: fell (40 frames)', 'episode 2: time_limit (30 frames)']);
  assert.deepEqual(pageErrors, []);
});

test('bodies and the chair are posed as recorded', async () => {
  for (const k of [0, 45, LAST]) {
    await seek(0, k);
    const f = rec.episodes[0].frames[k];
    for (const [i, b] of rec.bodies.entries()) {
      const w = await bodyWorld(b.name);
      const want = f.body_pos.slice(3 * i, 3 * i + 3);
      assert.ok(near(w, want, 1e-4), `frame ${k} ${b.name}: drawn at ${w}, recorded ${want}`);
    }
    const c = await page.evaluate(() => perchViewer.chairWorld());
    assert.ok(c && near(c, SYNTH.chairPos, 1e-5), `chair at ${c}`);
  }
  // the seat box centre: chair frame (0, 0, 0.435) rotated by the chair's yaw about z
  const seat = await page.evaluate(() => perchViewer.chairBoxWorld('seat'));
  assert.ok(near(seat, [SYNTH.chairPos[0], SYNTH.chairPos[1], 0.435], 1e-5), `seat at ${seat}`);
  const back = await page.evaluate(() => perchViewer.chairBoxWorld('backrest'));
  const wantBack = qrot([Math.cos(SYNTH.chairYaw / 2), 0, 0, Math.sin(SYNTH.chairYaw / 2)], [-0.24, 0, 0.725])
    .map((v, i) => v + SYNTH.chairPos[i]);
  assert.ok(near(back, wantBack, 1e-5), `backrest at ${back}, expected ${wantBack}`);
  assert.deepEqual(await page.evaluate(() => perchViewer.walkTargetWorld()), [...SYNTH.walkTarget, 0]);
});

test('the screenshot shows the humanoid and the chair where they are', async () => {
  await page.evaluate(() => perchViewer.setFollow(false));
  await seek(0, 0);
  const img = await shot('frame0.png');
  const bg = img.pixel(W / 2, 3);
  assert.ok(near(bg, hexRgb(0xcfd8e3), 12), `sky/background colour at the top: ${bg}`);

  const pp = await project(pelvisAt(0, 0));
  assert.equal(await onCanvas(pp), 'CANVAS', 'the pelvis is not covered by the HUD or the bar');
  assert.ok(isBody(img.pixel(...pp)), `pelvis pixel ${pp} is body-coloured: ${img.pixel(...pp)}`);
  for (const role of ['seat', 'backrest']) {
    const c = await project(await page.evaluate((r) => perchViewer.chairBoxWorld(r), role));
    assert.equal(await onCanvas(c), 'CANVAS');
    assert.ok(isChair(img.pixel(...c)), `chair ${role} pixel ${c} is chair-coloured: ${img.pixel(...c)}`);
  }
  // the body-coloured pixels cover the projected humanoid and not much more
  const body = region(img, isBody);
  const pts = bodyPoints(0, 0);
  const inner = await projectedBox(pts, 0);
  const outer = await projectedBox(pts, 0.12);
  assert.ok(body.n > 2000, `body pixels: ${body.n}`);
  assert.ok(body.x0 <= inner.x0 + 2 && body.x1 >= inner.x1 - 2 && body.y0 <= inner.y0 + 2 && body.y1 >= inner.y1 - 2,
    `body pixels ${JSON.stringify(body)} cover the projected geoms ${JSON.stringify(inner)}`);
  assert.ok(body.x0 >= outer.x0 && body.x1 <= outer.x1 && body.y0 >= outer.y0 && body.y1 <= outer.y1,
    `body pixels ${JSON.stringify(body)} lie within the projected geoms + radius ${JSON.stringify(outer)}`);
  // upright on the ground: the head (torso) is above the feet on screen, the feet touch the ground
  const head = await project(pelvisAt(0, 0).map((v, i) => (i === 2 ? v + 0.5 : v)));
  assert.ok(head[1] < pp[1] - 40, 'up (z) is up on the screen');
  const chair = region(img, isChair);
  assert.ok(chair.n > 1000, `chair pixels: ${chair.n}`);
});

test('moving the humanoid moves its pixels', async () => {
  await seek(0, 0);
  const p0 = await project(pelvisAt(0, 0));
  const before = region(await shot('frame0.png'), isBody);
  await seek(0, LAST);
  const img = await shot('frame90.png');
  const p1 = await project(pelvisAt(0, LAST));
  assert.ok(Math.hypot(p1[0] - p0[0], p1[1] - p0[1]) > 60, `the pelvis moves on screen: ${p0} -> ${p1}`);
  assert.ok(isBody(img.pixel(...p1)), `pelvis pixel at the last frame ${p1}: ${img.pixel(...p1)}`);
  assert.ok(!isBody(img.pixel(...p0)), `the old pelvis pixel ${p0} is no longer body: ${img.pixel(...p0)}`);
  const afterR = region(img, isBody);
  const dx = afterR.cx - before.cx, dy = afterR.cy - before.cy;
  const ex = p1[0] - p0[0], ey = p1[1] - p0[1];
  assert.ok(Math.hypot(dx - ex, dy - ey) < 0.35 * Math.hypot(ex, ey),
    `body pixel centroid moved (${dx.toFixed(1)}, ${dy.toFixed(1)}), the pelvis projection (${ex.toFixed(1)}, ${ey.toFixed(1)})`);
  // the pelvis trail: red pixels near its middle
  const mid = await project(pelvisAt(0, Math.round(LAST / 3)));
  let red = 0;
  for (let y = -3; y <= 3; y++) for (let x = -3; x <= 3; x++) if (isTrail(img.pixel(mid[0] + x, mid[1] + y))) red++;
  assert.ok(red > 0, `trail pixels near ${mid}`);
});

test('follow keeps the pelvis in place on screen', async () => {
  await page.evaluate(() => perchViewer.setFollow(true));
  await seek(0, 0);
  const p0 = await project(pelvisAt(0, 0));
  await seek(0, LAST);
  const p1 = await project(pelvisAt(0, LAST));
  assert.ok(Math.hypot(p1[0] - p0[0], p1[1] - p0[1]) < 3, `pelvis on screen ${p0} -> ${p1}`);
  const img = await shot('follow.png');
  assert.ok(isBody(img.pixel(...p1)), `pelvis pixel ${p1}: ${img.pixel(...p1)}`);
  await page.evaluate(() => perchViewer.setFollow(false));
  assert.equal(await page.$eval('#follow', (e) => e.checked), false);
});

test('the HUD and the episode selector', async () => {
  await seek(0, 0);
  let hud = await page.evaluate(() => perchViewer.hudText());
  for (const s of ['task     sit', 'model    models/sit/policy.bin (synthetic)', 'episode  0 (1/3)', 'success',
    'step 0', 'subtask  walk', 'R foot', 'seat', 'reward   0.0000']) assert.ok(hud.includes(s), `HUD has "${s}":\n${hud}`);
  await seek(0, 60);
  hud = await page.evaluate(() => perchViewer.hudText());
  assert.ok(hud.includes('time     1.000 s   step 60'), hud);
  assert.ok(hud.includes('subtask  sit   meta step 1'), hud);
  assert.ok(hud.includes('return 60.000'), hud);
  assert.ok(hud.includes('progress'), hud);

  await page.select('#episode', '1');
  assert.equal((await state()).episode, 1);
  hud = await page.evaluate(() => perchViewer.hudText());
  assert.ok(hud.includes('fell') && !hud.includes('subtask'), `episode 1: fell, no subtask line:\n${hud}`);
  assert.ok(near(await page.evaluate(() => perchViewer.chairWorld()), [1.5, -1.5, 0], 1e-5));
  await seek(1, 39);
  const torso = await bodyWorld('torso');
  assert.ok(near(torso, rec.episodes[1].frames[39].body_pos.slice(0, 3), 1e-4), `fallen torso at ${torso}`);
  const fell = await shot('fell.png');
  // Episode 1's chair is a mesh (its triangles in the recording, no boxes): drawn where it is.
  const mesh = await page.evaluate(() => perchViewer.chairBoxWorld('mesh'));
  assert.ok(mesh && near(mesh, [1.5, -1.5, 0], 1e-5), `mesh chair at ${mesh}`);
  const seatTop = await project([1.5, -1.5, 0.45]);
  assert.ok(isChair(fell.pixel(...seatTop)), `mesh seat top pixel ${seatTop} is chair-coloured: ${fell.pixel(...seatTop)}`);
  assert.ok(region(fell, isChair).n > 500, 'mesh chair pixels');

  await page.click('#next-ep');
  assert.deepEqual(await state(), { episode: 2, frame: 0, numFrames: 30, numEpisodes: 3, playing: false });
  assert.equal(await page.evaluate(() => perchViewer.chairWorld()), null, 'no chair in episode 2');
  hud = await page.evaluate(() => perchViewer.hudText());
  assert.ok(hud.includes('time_limit') && hud.includes('subtask  left turn'), hud);
  assert.ok(hud.includes('seed 12345678901234567891'), `exact uint64 seed:\n${hud}`);
  await page.click('#next-ep');
  assert.equal((await state()).episode, 2, 'stays on the last episode');
  await page.click('#prev-ep');
  await page.click('#prev-ep');
  assert.equal((await state()).episode, 0);
  assert.deepEqual(pageErrors, []);
});

test('play, speed and the scrubber', async () => {
  await seek(0, 0);
  await page.select('#speed', '4');
  assert.equal(await page.evaluate(() => perchViewer.speed), 4);
  await page.click('#play');
  await page.waitForFunction(() => perchViewer.frame > 5, { timeout: 30000 });
  await page.evaluate(() => perchViewer.pause());
  assert.equal((await state()).playing, false);
  // scrubber: set the range input and fire input
  await page.$eval('#scrub', (e) => { e.value = '30'; e.dispatchEvent(new Event('input')); });
  assert.equal((await state()).frame, 30);
  assert.equal(await page.$eval('#frame-label', (e) => e.textContent), '31 / 91');
  await page.keyboard.press('ArrowRight');
  assert.equal((await state()).frame, 31);
});

test('the file picker opens a recording', async () => {
  pageErrors.length = 0;
  await page.goto(`${server.url}/`, { waitUntil: 'load' });
  const status = await page.$eval('#status', (e) => e.textContent);
  assert.match(status, /Open a recording/);
  const input = await page.$('#file');
  await input.uploadFile(join(OUT, 'recording.bin'));
  await page.waitForFunction(() => perchViewer.loaded || perchViewer.error, { timeout: LOAD_TIMEOUT_MS });
  assert.equal(await page.evaluate(() => perchViewer.error), null);
  assert.equal(await page.evaluate(() => perchViewer.name), 'recording.bin');
  assert.equal((await state()).numEpisodes, 3);
  // a corrupt file from the picker replaces the scene with the error
  await input.uploadFile(join(OUT, 'corrupt.bin'));
  await page.waitForFunction(() => perchViewer.error, { timeout: LOAD_TIMEOUT_MS });
  assert.match(await page.$eval('#error', (e) => e.innerText), /corrupt\.bin: corrupt: payload CRC-32/);
  assert.deepEqual(pageErrors.filter((e) => !e.includes('corrupt')), []);
});

test('bad files show the error on the page', async () => {
  const cases = [
    ['corrupt.bin', /\/corrupt\.bin: corrupt: payload CRC-32 0x[0-9a-f]{8} differs/],
    ['truncated.bin', /\/truncated\.bin: truncated or corrupt/],
    ['other.bin', /\/other\.bin: not a recording/],
    ['format2.bin', /\/format2\.bin: format 2, this build reads 1/],
    ['missing.bin', /\/missing\.bin: could not fetch \(HTTP 404/],
  ];
  for (const [file, pattern] of cases) {
    const s = await open(`?file=/${file}`);
    assert.equal(s.loaded, false, file);
    assert.match(s.error, pattern);
    const shown = await page.$eval('#error', (e) => ({ text: e.innerText, visible: !e.hidden && e.offsetParent !== null }));
    assert.ok(shown.visible, `${file}: the error box is visible`);
    assert.match(shown.text, /^Cannot open the recording\./);
    assert.match(shown.text, pattern);
    if (file === 'corrupt.bin') await shot('corrupt.png');
  }
});
