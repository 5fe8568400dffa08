#!/usr/bin/env bash
# The speed yardstick (docs/performance.md, "The yardstick: celadro"): builds celadro, the public
# C++ code of this model family (github.com/rhomu/celadro), at a pinned commit, writes a runcard of
# this project's full size, and times it against `monolayer bench` in alternation on one thread,
# printing each pair's ratio. Not part of CI: it needs celadro's source and takes a few minutes.
#
#   bash scripts/celadro.sh                      clone celadro from GitHub (needs the network)
#   bash scripts/celadro.sh --source DIR         a checkout of celadro, or a bare clone (git dir)
#   bash scripts/celadro.sh --pairs 3            pairs to run (default 2)
#   bash scripts/celadro.sh --set friction_weights=presence   passed on to `monolayer bench`
#   bash scripts/celadro.sh --binary A --binary B   time these monolayer binaries instead of
#                                                a fresh build, each after the same celadro run
#                                                of every pair (two builds paired: f32 and f64)
#
# Needs cmake, a C++ compiler and Boost program_options (Debian: cmake g++
# libboost-program-options-dev). Work files go to $CELADRO_WORK (default target/celadro).
# Pause anything else running on the machine first: the ratio is only as good as the pairing.
set -euo pipefail
cd "$(dirname "$0")/.."

COMMIT=4907f7d
SOURCE=""
PAIRS=2
BENCH_EXTRA=()
BINARIES=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --source) SOURCE="$2"; shift 2 ;;
    --pairs) PAIRS="$2"; shift 2 ;;
    --set) BENCH_EXTRA+=(--set "$2"); shift 2 ;;
    --binary) [[ -x "$2" ]] || { echo "celadro.sh: --binary $2 is not an executable" >&2; exit 2; }
              BINARIES+=("$2"); shift 2 ;;
    -h|--help) sed -n '2,17p' "$0"; exit 0 ;;
    *) echo "celadro.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
done
[[ "$PAIRS" =~ ^[1-9][0-9]*$ ]] || { echo "celadro.sh: --pairs must be a whole number ≥ 1, got '$PAIRS'" >&2; exit 2; }

for tool in cmake c++ git; do
  command -v "$tool" >/dev/null || { echo "celadro.sh: '$tool' not found (Debian: apt-get install cmake g++ git libboost-program-options-dev)" >&2; exit 1; }
done

WORK="${CELADRO_WORK:-target/celadro}"
mkdir -p "$WORK"
WORK="$(cd "$WORK" && pwd)"
SRC="$WORK/src-$COMMIT"

say() { printf '== %s\n' "$*"; }

if [[ ! -f "$SRC/CMakeLists.txt" ]]; then
  rm -rf "$SRC.tmp" && mkdir -p "$SRC.tmp"
  if [[ -z "$SOURCE" ]]; then
    say "cloning github.com/rhomu/celadro"
    git clone --quiet https://github.com/rhomu/celadro "$WORK/clone" 2>/dev/null || [[ -d "$WORK/clone/.git" ]] || {
      echo "celadro.sh: cannot clone github.com/rhomu/celadro; pass a local copy with --source DIR" >&2; exit 1; }
    SOURCE="$WORK/clone"
  fi
  if git --git-dir "$SOURCE" rev-parse --verify -q "$COMMIT^{commit}" >/dev/null 2>&1; then
    GITDIR="$SOURCE"
  elif git --git-dir "$SOURCE/.git" rev-parse --verify -q "$COMMIT^{commit}" >/dev/null 2>&1; then
    GITDIR="$SOURCE/.git"
  else
    echo "celadro.sh: $SOURCE is not a git copy of celadro holding commit $COMMIT" >&2; exit 1
  fi
  say "extracting celadro $COMMIT from $GITDIR"
  git --git-dir "$GITDIR" archive "$COMMIT" | tar -x -C "$SRC.tmp"
  mv "$SRC.tmp" "$SRC"
fi

CELADRO="$WORK/build-$COMMIT/celadro"
if [[ ! -x "$CELADRO" ]]; then
  say "building celadro (cmake, Release)"
  cmake -S "$SRC" -B "$WORK/build-$COMMIT" -DCMAKE_BUILD_TYPE=Release >"$WORK/cmake.log" 2>&1 || {
    echo "celadro.sh: cmake failed (is libboost-program-options-dev installed?); see $WORK/cmake.log" >&2; exit 1; }
  make -C "$WORK/build-$COMMIT" -j2 >"$WORK/make.log" 2>&1 || { echo "celadro.sh: the build failed; see $WORK/make.log" >&2; exit 1; }
fi

# The bench's size and Heun scheme in celadro's terms: 100 cells on 140², R = 8, 31×31 subdomains
# (margin 15), Δt = 0.1 as 10 substeps per step with one predictor and one corrector (npc = 1),
# ζ = 0.5, no relaxation phase; 100 steps = 1,000 substeps.
NSTEPS=100
NSUBSTEPS=10
RUNCARD="$WORK/full.dat"
cat >"$RUNCARD" <<EOF
config     = random
nsteps     = $NSTEPS
ninfo      = $NSTEPS
LX         = 140
LY         = 140
nsubsteps  = $NSUBSTEPS
npc        = 1
bc         = 0
margin     = 15
relax-time = 0
nphases    = 100
gamma      = .06
mu         = 45
lambda     = 2
kappa      = .5
R          = 8
xi         = 1
zetaQ      = 0.5
EOF

if [[ ${#BINARIES[@]} -eq 0 ]]; then
  say "building monolayer (release)"
  cargo build --release --quiet
  BINARIES=("${CARGO_TARGET_DIR:-target}/release/monolayer")
fi

now() { date +%s.%N; }
for pair in $(seq 1 "$PAIRS"); do
  t0=$(now)
  (cd "$WORK" && OMP_NUM_THREADS=1 "$CELADRO" "$RUNCARD" --no-write >"$WORK/celadro.out" 2>&1) || {
    echo "celadro.sh: celadro failed; see $WORK/celadro.out" >&2; exit 1; }
  t1=$(now)
  # Milliseconds per substep: each of celadro's substeps is one Heun step of Δt = 0.1, as ours.
  cel=$(awk -v a="$t0" -v b="$t1" -v n=$((NSTEPS * NSUBSTEPS)) 'BEGIN { print (b - a) * 1000 / n }')
  for MONOLAYER in "${BINARIES[@]}"; do
    line=$("$MONOLAYER" bench --threads 1 --chi 0.001 "${BENCH_EXTRA[@]}" 2>&1 | grep 'ms/step over') || {
      echo "celadro.sh: $MONOLAYER bench failed (run it by hand to see why)" >&2; exit 1; }
    ours=$(sed -E 's/.*: ([0-9.]+) ms\/step over.*/\1/' <<<"$line")
    printf 'pair %d: celadro %.1f ms per substep (Δt = 0.1); %s %.2f ms per step: ratio %.3f\n' \
      "$pair" "$cel" "$(basename "$MONOLAYER")" "$ours" "$(awk -v a="$ours" -v b="$cel" 'BEGIN { print a / b }')"
  done
done
