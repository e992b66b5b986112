// A tiny static HTTP server with the URL layout of `perch view`: the viewer (dist/) at `/`, a
// recording at `/recording.bin` (the page is opened as `/?file=/recording.bin`).
//   node test/server.mjs FILE [PORT]   serves dist/ and FILE on 127.0.0.1 (for trying the viewer)
import { createServer } from 'node:http';
import { readFileSync, existsSync, statSync } from 'node:fs';
import { dirname, join, normalize, extname } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
export const DIST = join(here, '..', 'dist');

const TYPES = {
  '.html': 'text/html; charset=utf-8',
  '.js': 'text/javascript; charset=utf-8',
  '.css': 'text/css; charset=utf-8',
  '.map': 'application/json',
  '.bin': 'application/octet-stream',
  '.rec': 'application/octet-stream',
};

// files: { '/recording.bin': Buffer | Uint8Array | () => Buffer }
export function startServer({ root = DIST, files = {}, port = 0 } = {}) {
  const server = createServer((req, res) => {
    const path = decodeURIComponent(new URL(req.url, 'http://x').pathname);
    const send = (status, body, type) => {
      res.writeHead(status, { 'Content-Type': type, 'Cache-Control': 'no-store' });
      res.end(body);
    };
    if (Object.hasOwn(files, path)) {
      const f = files[path];
      send(200, Buffer.from(typeof f === 'function' ? f() : f), 'application/octet-stream');
      return;
    }
    const rel = normalize(path === '/' ? '/index.html' : path);
    const full = join(root, rel);
    if (!full.startsWith(root) || !existsSync(full) || !statSync(full).isFile()) {
      send(404, `not found: ${path}\n`, 'text/plain');
      return;
    }
    send(200, readFileSync(full), TYPES[extname(full)] || 'application/octet-stream');
  });
  return new Promise((resolve, reject) => {
    server.once('error', reject);
    server.listen(port, '127.0.0.1', () => {
      const url = `http://127.0.0.1:${server.address().port}`;
      resolve({ url, server, close: () => new Promise((r) => server.close(r)) });
    });
  });
}

if (process.argv[1] && fileURLToPath(import.meta.url) === process.argv[1]) {
  const file = process.argv[2];
  if (!file) { console.error('usage: node test/server.mjs FILE [PORT]'); process.exit(2); }
  const { url } = await startServer({
    files: { '/recording.bin': () => readFileSync(file) },
    port: Number(process.argv[3] || 0),
  });
  console.log(`${url}/?file=/recording.bin`);
}
