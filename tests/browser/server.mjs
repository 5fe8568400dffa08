// The static server for www/ that the browser tests load the page from: one file per request,
// on 127.0.0.1 at a free port, with the content types the page needs (the .wasm as
// application/wasm, which WebAssembly.instantiateStreaming requires); a path outside www/ is
// refused (403), a missing file is 404. As scripts/serve.sh's server does, it sends the
// cross-origin isolation headers (COOP/COEP: the page then runs its threaded core), gzips what
// the browser accepts gzipped, and answers a revalidation of an unchanged file with 304 (the
// page's worker fetches the core's .wasm after the main thread did).
//
//   const server = await serve();                    // isolated
//   const server = await serve({ isolated: false }); // as a host that sends no such headers
//   const server = await serve({ gzip: false });     // nothing compressed on the wire
//   const server = await serve({ sent: (path, bytes) => … });   // each body as sent
//   const server = await serve({ stall: (path, req) => … });  // true: that request is never answered
//   const base = `http://127.0.0.1:${server.address().port}`;   …   server.close();

import { createServer } from 'node:http';
import { readFile, stat } from 'node:fs/promises';
import { gzipSync } from 'node:zlib';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

export const WWW = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..', 'www');

const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css', '.wasm': 'application/wasm', '.png': 'image/png' };
// What is worth gzipping (the .png is compressed already).
const GZIP = new Set(['.html', '.js', '.css', '.wasm', '.bin']);

/** Serves www/; resolves to the listening http.Server. */
export function serve({ isolated = true, gzip = true, sent = null, stall = null } = {}) {
  const gzipped = new Map(); // file → { mtime, body }
  const stalled = new Set();
  const server = createServer(async (req, res) => {
    const url = new URL(req.url, 'http://x');
    const rel = decodeURIComponent(url.pathname === '/' ? '/index.html' : url.pathname);
    if (stall?.(rel, req)) {
      stalled.add(res);
      return;
    }
    const file = path.join(WWW, path.normalize(rel));
    if (!file.startsWith(WWW)) return res.writeHead(403).end();
    try {
      const { mtime } = await stat(file);
      const headers = {
        'content-type': TYPES[path.extname(file)] ?? 'application/octet-stream',
        'last-modified': mtime.toUTCString(),
        'cache-control': 'no-cache',
      };
      if (isolated) {
        headers['cross-origin-opener-policy'] = 'same-origin';
        headers['cross-origin-embedder-policy'] = 'require-corp';
        headers['cross-origin-resource-policy'] = 'cross-origin';
      }
      const since = Date.parse(req.headers['if-modified-since'] ?? '');
      if (since >= Math.floor(mtime.getTime() / 1000) * 1000) return res.writeHead(304, headers).end();
      let body = await readFile(file);
      if (gzip && GZIP.has(path.extname(file)) && /\bgzip\b/.test(req.headers['accept-encoding'] ?? '')) {
        const cached = gzipped.get(file);
        if (cached?.mtime !== mtime.getTime()) gzipped.set(file, { mtime: mtime.getTime(), body: gzipSync(body) });
        body = gzipped.get(file).body;
        headers['content-encoding'] = 'gzip';
      }
      res.writeHead(200, headers);
      res.end(body);
      sent?.(rel, body.length);
    } catch {
      res.writeHead(404).end();
    }
  });
  // A stalled answer would keep close() waiting on its connection.
  const close = server.close.bind(server);
  server.close = (done) => {
    stalled.forEach((res) => res.destroy());
    return close(done);
  };
  return new Promise((ok) => server.listen(0, '127.0.0.1', () => ok(server)));
}
