"""The page's static server (scripts/serve.sh): www/ on 127.0.0.1, with the headers that make the
page cross-origin isolated (COOP/COEP: SharedArrayBuffer, so the threaded core) and the files
gzipped for a browser that accepts it. tests/browser/server.mjs serves the browser tests alike.

    python3 scripts/serve.py PORT DIR
"""

import gzip
import http.server
import os
import sys

# Worth gzipping: text, the WebAssembly and the shipped states.
GZIP = (".html", ".js", ".css", ".wasm", ".bin")


class Handler(http.server.SimpleHTTPRequestHandler):
    extensions_map = {
        **http.server.SimpleHTTPRequestHandler.extensions_map,
        ".js": "text/javascript",
        ".wasm": "application/wasm",
    }

    def end_headers(self):
        self.send_header("Cross-Origin-Opener-Policy", "same-origin")
        self.send_header("Cross-Origin-Embedder-Policy", "require-corp")
        # Embeddable in an isolated page of another origin (docs/demo.md, "Embedding").
        self.send_header("Cross-Origin-Resource-Policy", "cross-origin")
        self.send_header("Cache-Control", "no-cache")
        super().end_headers()

    def send_head(self):
        path = self.translate_path(self.path)
        if os.path.isdir(path) and self.path.split("?")[0].endswith("/"):
            path = os.path.join(path, "index.html")
        accepts = "gzip" in self.headers.get("Accept-Encoding", "")
        if not (accepts and path.endswith(GZIP) and os.path.isfile(path)):
            return super().send_head()
        mtime = os.stat(path).st_mtime
        since = self.headers.get("If-Modified-Since")
        if since and self.date_time_string(int(mtime)) == since:
            self.send_response(304)
            self.end_headers()
            return None
        with open(path, "rb") as f:
            body = gzip.compress(f.read(), 6)
        self.send_response(200)
        self.send_header("Content-Type", self.guess_type(path))
        self.send_header("Content-Encoding", "gzip")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Last-Modified", self.date_time_string(int(mtime)))
        self.end_headers()
        return _Body(body)


class _Body:
    """What send_head returns for copyfile: the gzipped bytes."""

    def __init__(self, body):
        self.body = body

    def read(self, n=-1):
        out, self.body = (self.body, b"") if n < 0 else (self.body[:n], self.body[n:])
        return out

    def close(self):
        pass


if __name__ == "__main__":
    port, root = int(sys.argv[1]), sys.argv[2]
    handler = lambda *a, **k: Handler(*a, directory=root, **k)  # noqa: E731
    http.server.ThreadingHTTPServer(("127.0.0.1", port), handler).serve_forever()
