// The static server for www/ that the browser tests load the page from: one file per request,
// on 127.0.0.1 at a free port, with the content types the page needs (the .wasm as
// application/wasm, which WebAssembly.instantiateStreaming requires); a path outside www/ is
// refused (403), a missing file is 404.
//
//   const server = await serve();
//   const base = `http://127.0.0.1:${server.address().port}`;   …   server.close();

import { createServer } from 'node:http';
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

export const WWW = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..', 'www');

const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css', '.wasm': 'application/wasm', '.png': 'image/png' };

/** Serves www/; resolves to the listening http.Server. */
export function serve() {
  const server = createServer(async (req, res) => {
    const url = new URL(req.url, 'http://x');
    const rel = decodeURIComponent(url.pathname === '/' ? '/index.html' : url.pathname);
    const file = path.join(WWW, path.normalize(rel));
    if (!file.startsWith(WWW)) return res.writeHead(403).end();
    try {
      const body = await readFile(file);
      res.writeHead(200, { 'content-type': TYPES[path.extname(file)] ?? 'application/octet-stream' });
      res.end(body);
    } catch {
      res.writeHead(404).end();
    }
  });
  return new Promise((ok) => server.listen(0, '127.0.0.1', () => ok(server)));
}
