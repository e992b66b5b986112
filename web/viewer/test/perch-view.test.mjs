// End to end with the real programs: `perch eval --record` writes a recording of a sit episode of
// the delivered sit policy, `perch view` serves it with the built viewer on 127.0.0.1, headless
// Chromium opens the printed URL. Checks that the page draws the recorded pelvis and the chair
// where the file says (decoded here with the same reader), and saves a screenshot. PERCH_BIN:
// the perch program (CTest passes it). Chromium that does not start fails the test.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, execFileSync } from 'node:child_process';
import { existsSync, mkdirSync, readFileSync, mkdtempSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';
import { createCodec } from '../src/reader.js';
import { PROTO_TEXT } from './synth.mjs';

const here = dirname(fileURLToPath(import.meta.url));
const ROOT = resolve(here, '../../..');
const OUT = join(here, 'out');
const PERCH = process.env.PERCH_BIN || join(ROOT, 'build/app/perch');
const CHROMIUM = process.env.PERCH_CHROMIUM || '/usr/bin/chromium';
const MODEL = join(ROOT, 'models/sit/policy.bin');

let view, browser, page, rec;
const tmp = mkdtempSync(join(tmpdir(), 'perch-view-'));
const file = join(tmp, 'sit.rec');

before(async () => {
  assert.ok(existsSync(PERCH), `perch not found at ${PERCH} (set PERCH_BIN)`);
  mkdirSync(OUT, { recursive: true });
  execFileSync(PERCH, ['eval', '--model', MODEL, '--episodes', '1', '--seed', '3',
    '--record', file], { cwd: ROOT, stdio: ['ignore', 'ignore', 'inherit'] });
  rec = createCodec(PROTO_TEXT).readRecording(new Uint8Array(readFileSync(file)), file);
  view = spawn(PERCH, ['view', file, '--port', '0', '--exit-after', '300'], { cwd: ROOT });
  const url = await new Promise((res, rej) => {
    let out = '';
    view.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/http:\/\/127\.0\.0\.1:\d+\/\S*/);
      if (m) res(m[0]);
    });
    view.on('exit', (c) => rej(new Error(`perch view exited (${c}) before printing a URL`)));
    setTimeout(() => rej(new Error('perch view printed no URL in 30 s')), 30000);
  });
  try {
    browser = await puppeteer.launch({
      executablePath: CHROMIUM, headless: true, timeout: 60000,
      args: ['--no-sandbox', '--disable-dev-shm-usage', '--use-angle=swiftshader',
        '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--window-size=1000,700'],
    });
  } catch (e) {
    throw new Error(`Chromium (${CHROMIUM}) could not start: ${e.message}`);
  }
  page = await browser.newPage();
  await page.setViewport({ width: 1000, height: 700 });
  await page.goto(url);
  await page.waitForFunction('window.perchViewer && (window.perchViewer.loaded || window.perchViewer.error)',
    { timeout: 90000 });
});

after(async () => {
  if (browser) await browser.close();
  if (view) view.kill('SIGTERM');
});

test('perch view serves a real recording that the page draws where the file says', async () => {
  const err = await page.evaluate('window.perchViewer.error');
  assert.equal(err, null, `page error: ${err}`);
  const ep = rec.episodes[0];
  const last = ep.frames.length - 1;
  assert.equal(await page.evaluate('window.perchViewer.numFrames'), ep.frames.length);
  await page.evaluate(`window.perchViewer.seek(0, ${last})`);
  const pelvisIdx = rec.bodies.findIndex((b) => b.name === 'pelvis');
  const want = ep.frames[last].body_pos.slice(3 * pelvisIdx, 3 * pelvisIdx + 3);
  const drawn = await page.evaluate("window.perchViewer.bodyWorld('pelvis')");
  for (let i = 0; i < 3; ++i) assert.ok(Math.abs(drawn[i] - want[i]) < 1e-4, `pelvis ${drawn} vs ${want}`);
  const chair = await page.evaluate('window.perchViewer.chairWorld()');
  const cp = ep.frames[last].chair_pos;
  for (let i = 0; i < 3; ++i) assert.ok(Math.abs(chair[i] - cp[i]) < 1e-4, `chair ${chair} vs ${cp}`);
  // Seated at the end: the recorded pelvis is within 0.3 m of the seat target, horizontally.
  const st = ep.chair.seat_target;
  assert.ok(Math.hypot(want[0] - (cp[0] + st[0]), want[1] - (cp[1] + st[1])) < 0.3);
  await page.screenshot({ path: join(OUT, 'perch-view-sit.png') });
});
