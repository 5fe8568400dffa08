#!/usr/bin/env bash
# The browser demo on a fresh machine: installs what the build needs (the wasm32 target, and
# wasm-bindgen-cli at exactly the version of the wasm-bindgen crate in Cargo.lock, since the two
# must match), builds the release WebAssembly core, generates its JS bindings into www/pkg, and
# serves www/ on localhost.
#
#   bash scripts/serve.sh              build and serve on port 8000 (PORT=… to change)
#   bash scripts/serve.sh --build-only build www/pkg and exit (the browser tests use this)
set -euo pipefail
cd "$(dirname "$0")/.."

PORT="${PORT:-8000}"
TARGET_DIR="${CARGO_TARGET_DIR:-target}"

say() { printf '== %s\n' "$*"; }

if ! rustup target list --installed | grep -qx wasm32-unknown-unknown; then
  say "installing the wasm32-unknown-unknown target"
  rustup target add wasm32-unknown-unknown
fi

# The version of wasm-bindgen the crate is locked to; the CLI must be exactly that version.
WB_VERSION="$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/version = |"/, ""); print; exit }' Cargo.lock)"
if [ -z "$WB_VERSION" ]; then
  echo "error: wasm-bindgen is not in Cargo.lock" >&2
  exit 1
fi
if [ "$(wasm-bindgen --version 2>/dev/null | awk '{print $2}')" != "$WB_VERSION" ]; then
  say "installing wasm-bindgen-cli $WB_VERSION (about 3 minutes on 2 cores)"
  # Not --locked: one of its pinned dependencies is missing from the registry mirror here.
  cargo install wasm-bindgen-cli --version "$WB_VERSION"
fi

say "building the WebAssembly core with its GPU engine (release)"
cargo build --target wasm32-unknown-unknown --lib --no-default-features --features gpu --release
say "generating the JS bindings into www/pkg"
wasm-bindgen --target web --no-typescript --out-dir www/pkg \
  "$TARGET_DIR/wasm32-unknown-unknown/release/monolayer.wasm"

if [ "${1:-}" = "--build-only" ]; then
  exit 0
fi

say "serving www/ — open http://localhost:$PORT/ (Ctrl-C stops)"
cd www
exec python3 -m http.server "$PORT" --bind 127.0.0.1
