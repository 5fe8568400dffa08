#!/usr/bin/env bash
# The browser demo on a fresh machine: installs what the build needs (the wasm32 target, and
# wasm-bindgen-cli at exactly the version of the wasm-bindgen crate in Cargo.lock, since the two
# must match; the nightly toolchain's rust-src for the threaded core; binaryen's wasm-opt from
# npm), builds the release WebAssembly core twice, generates their JS bindings into www/pkg
# (single-thread, with the GPU engine) and www/pkg-threads (threaded: wasm atomics and shared
# memory, used where the page is cross-origin isolated), shrinks both with wasm-opt, and serves
# www/ on localhost with the headers that isolate the page (COOP/COEP), gzipped.
#
#   bash scripts/serve.sh              build and serve on port 8000 (PORT=… to change)
#   bash scripts/serve.sh --build-only build www/pkg and www/pkg-threads and exit (the browser tests use this)
#   NO_WASM_OPT=1 bash scripts/serve.sh   skip wasm-opt (a quicker build, a larger download)
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

# wasm-opt from binaryen's npm package (Debian's binaryen 108 corrupts wasm-bindgen's output),
# installed with the browser tests' packages (tests/browser/package.json pins it).
WASM_OPT=tests/browser/node_modules/.bin/wasm-opt
if [ -z "${NO_WASM_OPT:-}" ] && [ ! -x "$WASM_OPT" ]; then
  if command -v npm >/dev/null; then
    say "installing binaryen's wasm-opt (npm, tests/browser)"
    (cd tests/browser && npm ci --no-audit --no-fund --loglevel=error)
  else
    say "no npm: the WebAssembly is not shrunk by wasm-opt (install Node and npm for a smaller download)"
  fi
fi
# Shrinks a wasm-bindgen output in place; $2: the WebAssembly features it uses beyond the
# defaults of Rust's wasm32 target. -O2 keeps IEEE arithmetic as it is (no fast-math), so the
# bits do not move (the browser tests compare the fingerprint with the native one).
shrink() {
  [ -z "${NO_WASM_OPT:-}" ] && [ -x "$WASM_OPT" ] || return 0
  local before after
  before=$(stat -c %s "$1")
  "$WASM_OPT" -O2 --enable-simd --enable-bulk-memory --enable-nontrapping-float-to-int --enable-sign-ext \
    --enable-mutable-globals --enable-reference-types --enable-multivalue ${2:-} "$1" -o "$1.opt"
  mv "$1.opt" "$1"
  after=$(stat -c %s "$1")
  say "wasm-opt: $1 $before → $after bytes"
}

say "building the WebAssembly core with its GPU engine (release)"
cargo build --target wasm32-unknown-unknown --lib --no-default-features --features gpu --release
say "generating the JS bindings into www/pkg"
wasm-bindgen --target web --out-dir www/pkg \
  "$TARGET_DIR/wasm32-unknown-unknown/release/monolayer.wasm"
shrink www/pkg/monolayer_bg.wasm

# The threaded core: wasm atomics need the standard library rebuilt with them (-Z build-std),
# which only the nightly toolchain does. RUSTFLAGS replaces .cargo/config.toml's simd128 flag,
# so it is repeated. Its own target directory keeps the stable build's cache.
if ! rustup component list --toolchain nightly --installed 2>/dev/null | grep -q '^rust-src'; then
  say "installing the nightly toolchain's rust-src and wasm32 target (for the threaded core)"
  rustup toolchain install nightly --profile minimal --component rust-src --target wasm32-unknown-unknown \
    || say "no nightly toolchain: the page will use its single-thread core only"
fi
if rustup component list --toolchain nightly --installed 2>/dev/null | grep -q '^rust-src'; then
  say "building the threaded WebAssembly core (nightly, atomics, release)"
  # The link makes the memory shared and imported (the pool's workers instantiate the same
  # module on it), and exports the thread-local storage symbols wasm-bindgen sets up per thread;
  # given to the final link only (`cargo rustc … -- …`), so that no dependency is rebuilt.
  RUSTFLAGS="-C target-feature=+atomics,+bulk-memory,+mutable-globals,+simd128" \
    cargo +nightly rustc --target wasm32-unknown-unknown --lib --no-default-features --features threads --release \
    -Z build-std=panic_abort,std --target-dir "$TARGET_DIR/threads" -- \
    -C link-arg=--shared-memory -C link-arg=--import-memory -C link-arg=--max-memory=1073741824 \
    -C link-arg=--export=__wasm_init_tls -C link-arg=--export=__tls_size -C link-arg=--export=__tls_align \
    -C link-arg=--export=__tls_base
  say "generating the threaded core's JS bindings into www/pkg-threads"
  wasm-bindgen --target web --out-dir www/pkg-threads \
    "$TARGET_DIR/threads/wasm32-unknown-unknown/release/monolayer.wasm"
  shrink www/pkg-threads/monolayer_bg.wasm --enable-threads
fi

if [ "${1:-}" = "--build-only" ]; then
  exit 0
fi

say "serving www/ — open http://localhost:$PORT/ (Ctrl-C stops)"
exec python3 scripts/serve.py "$PORT" www
