#!/usr/bin/env bash
# The whole test suite: formatting, lints for both targets, the WebAssembly build of the core,
# and every native test (unit and full-size integration) in release mode.
# This is the README's test command; .ci/run calls it after installing what it needs.
set -euo pipefail
cd "$(dirname "$0")/.."

# Each step's header says when it began (seconds into the suite), so a slow step shows in the log.
step() { printf '\n== [%ss] %s\n' "$SECONDS" "$*"; }

step "format"
cargo fmt --all -- --check

step "lints (native; with the GPU stages of feature \`gpu\`)"
cargo clippy --all-targets --release --features gpu -- -D warnings

step "docs (rustdoc: no broken intra-doc links or other warnings; tests/docs.rs checks the .md links)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps

step "lints and build (wasm32-unknown-unknown, the browser's core)"
cargo clippy --target wasm32-unknown-unknown --lib --no-default-features -- -D warnings
# The page's build: the core with the GPU engine (wgpu's WebGPU backend, src/web/gpu_engine.rs).
cargo clippy --target wasm32-unknown-unknown --lib --no-default-features --features gpu -- -D warnings
cargo build --target wasm32-unknown-unknown --lib --no-default-features --features gpu --release

step "tests (release; --include-ignored adds the integration tests at the paper's full size)"
# --features gpu adds tests/gpu.rs: the GPU stages against the CPU on a Vulkan driver (lavapipe,
# Debian's mesa-vulkan-drivers, where there is no GPU); without an adapter they skip, and with
# CI=true they fail.
cargo test --release --features gpu -- --include-ignored

step "unit tests without the \`parallel\` feature (the serial path of par.rs the browser takes), debug assertions on"
# No --release: the test profile ([profile.test] in Cargo.toml: optimised, debug assertions on).
cargo test --no-default-features --lib

step "lints with the cells' fields stored in f32 (feature \`f32-storage\`, docs/performance.md)"
# Not the default (it is safe but not faster here); kept compiling, so that the comparison can be
# made again where memory traffic binds (its unit tests: cargo test --no-default-features
# --features f32-storage --lib).
cargo clippy --lib --no-default-features --features f32-storage -- -D warnings

step "the page's build (www/pkg, www/pkg-threads) and the browser tests' packages"
# Debian's chromium, firefox-esr and webkit2gtk-driver (with xvfb), and the npm packages of
# tests/browser; .ci/run installs them. No browser is ever downloaded.
for b in /usr/bin/chromium /usr/bin/firefox-esr /usr/bin/WebKitWebDriver; do
  if [ ! -x "$b" ]; then
    echo "error: $b is missing: apt-get install -y chromium firefox-esr webkit2gtk-driver xvfb xauth (.ci/run does)" >&2
    exit 1
  fi
done
# Without wasm-opt: it changes the bytes, not what the page does, and takes about two minutes of a
# core for the two builds; the README's serve command runs it (docs/performance.md, Loading).
NO_WASM_OPT=1 bash scripts/serve.sh --build-only
(cd tests/browser && npm ci --no-audit --no-fund --loglevel=error)

step "type check of the page's JavaScript (TypeScript's tsc over www/js, JSDoc types, the core's .d.ts)"
# www/jsconfig.json: strict, nothing emitted (the page is served as it is, without a build).
tests/browser/node_modules/.bin/tsc -p www/jsconfig.json

step "browser demo (Chromium: WebGPU on SwiftShader; the shared checks in Chromium, Firefox and WebKit)"
# The native binary the page is compared with (target/release/monolayer): the one the tests step
# built for the integration tests. Asked for with that step's own command, since a plain
# `cargo build --bin monolayer` resolves features without the dev-dependencies (proptest turns on
# bitflags' `std`), which would rebuild bitflags, wgpu and naga here a second time; with the same
# command nothing is compiled again.
cargo test --release --features gpu --no-run
# demo.test.mjs on WebGPU only: WebGL2 is drawn by WebKit's run of the shared checks and by
# Chromium's after its WebGPU device is lost (MODES=webgl2 runs the whole file on it).
MODES=webgpu node --test --test-reporter=spec tests/browser/url.test.mjs tests/browser/whatif.test.mjs tests/browser/demo.test.mjs \
  tests/browser/viewer.test.mjs tests/browser/engines.test.mjs
