#!/usr/bin/env bash
# The GPU engine against the CPU engine, statistically: the same runs (the page's reduced
# tissue, 33 cells on 80², χ = 0.001, ζ = 2.5, γ = 0.06: the "persistent holes" preset) on
# both engines for several seeds, analysed alike, then compared run by run against the spread
# of the seeds (scripts/compare_sweeps.py). The two engines' trajectories part after a few
# thousand steps (f32 against f64), so agreement is asked of the statistics, not of the bits.
#
#   bash scripts/compare_engines.sh OUT            seeds 1,2,3, 1,500 relaxation + 3,000 active steps
#   SEEDS=1,2,3,4 STEPS=5000 bash scripts/compare_engines.sh OUT
#
# Resumable: run it again after a stop and each run continues from its checkpoint. Needs a
# release build with the GPU kernels (cargo build --release --features gpu) and a Vulkan
# adapter; on a machine without a GPU (lavapipe) the GPU runs take hours.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:?usage: bash scripts/compare_engines.sh OUT}"
SEEDS="${SEEDS:-1,2,3}"
STEPS="${STEPS:-3000}"
BIN="${MONOLAYER_BIN:-target/release/monolayer}"
FRAMES=250
SET=(--set box_size=80 --set n_cells=33 --set gamma=0.06 --set relax_steps=1500 --set "active_steps=$STEPS")
GRID=(--grid chi=0.001 --grid zeta=2.5)

echo "== CPU engine: a sweep over seeds $SEEDS"
"$BIN" sweep --out "$OUT/cpu" "${GRID[@]}" --seeds "$SEEDS" --frame-interval "$FRAMES" "${SET[@]}" --jobs 1 --quiet

echo "== GPU engine: the same runs, one after the other (the adapter is shared)"
for cpu_run in "$OUT"/cpu/runs/*; do
  name="$(basename "$cpu_run")"
  seed="${name##*_seed}"
  dir="$OUT/gpu/runs/$name"
  # A run that stopped on a fault of the model (a cell lost, φ out of range) has ended as the
  # CPU's sweep counts it: its measures are those up to the stop, and the others go on.
  if [ -f "$dir/run.json" ] && grep -q '"status": "\(finished\|failed\)' "$dir/run.json"; then
    echo "seed $seed: ended"
  elif [ -f "$dir/run.json" ]; then
    "$BIN" run --resume "$dir" --quiet || echo "seed $seed: stopped (its run.json says why)"
  else
    "$BIN" run --engine gpu --out "$dir" --seed "$seed" --chi 0.001 --zeta 2.5 --frame-interval "$FRAMES" "${SET[@]}" --quiet \
      || echo "seed $seed: stopped (its run.json says why)"
  fi
done
# The GPU runs become a sweep directory: tables-only checks each run's parameters and seed
# against the grid and writes summary.csv and regimes.csv.
"$BIN" sweep --tables-only --out "$OUT/gpu" "${GRID[@]}" --seeds "$SEEDS" --frame-interval "$FRAMES" "${SET[@]}"

echo "== the engines compared against the seed spread"
python3 scripts/compare_sweeps.py "$OUT/cpu" "$OUT/gpu" --label-a cpu --label-b gpu-f32 --markdown
