#!/usr/bin/env python3
"""Compares two sweeps of the same grid and seeds made two ways (two storage precisions, two
solver tolerances, two builds), run by run, against the spread of the seeds.

For each grid point and each measure of `summary.csv` it prints, per seed, the value under A
and under B, then the largest |A - B| over the seeds beside the spread of the seeds under A
(max - min). A measure "agrees within the seed spread" when every seed's |A - B| is at most
that spread; a point where the seeds do not differ at all (spread 0, as in a tissue that never
opens a hole) agrees only where A and B are equal. The last lines give each point's regime
under both (regimes.csv).

    python3 scripts/compare_sweeps.py A_OUT B_OUT [--label-a f64 --label-b f32] [--markdown]

A_OUT and B_OUT are `monolayer sweep --out` directories with their tables written (after the
sweep, or `monolayer sweep --tables-only --out DIR ...`). Standard library only.
"""

import argparse
import csv
import sys
from pathlib import Path

MEASURES = [
    ("holes_nucleated", "holes"),
    ("max_hole_area", "largest hole (sites)"),
    ("time_with_hole_open", "time with a hole open"),
    ("max_holes_open", "most open at once"),
    ("mean_speed", "mean speed"),
    ("velocity_correlation_length", "C_v length"),
    ("nematic_correlation_length", "C_Q length"),
    ("aspect_ratio_mean", "aspect ratio (mean)"),
    ("aspect_ratio_p90", "aspect ratio (p90)"),
    ("min_packing_fraction_without_hole", "covered, no hole open (min)"),
]


def read_rows(out: Path):
    path = out / "summary.csv"
    if not path.is_file():
        sys.exit(f"{path}: no such file (run `monolayer sweep --tables-only --out {out} ...` first)")
    with path.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{path}: no runs")
    return rows


def grid_keys(rows):
    """The grid's own columns: those between `run` and `seed`."""
    header = list(rows[0].keys())
    return header[1 : header.index("seed")]


def number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def regimes(out: Path, keys):
    path = out / "regimes.csv"
    if not path.is_file():
        return {}
    with path.open(newline="") as f:
        return {
            tuple(r.get(k, "") for k in keys): f"{r.get('regime', '?')} (as regions: {r.get('regime_regions', '?')})"
            for r in csv.DictReader(f)
        }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--label-a", default="A")
    ap.add_argument("--label-b", default="B")
    ap.add_argument("--markdown", action="store_true", help="a Markdown table per point")
    args = ap.parse_args()
    rows_a, rows_b = read_rows(args.a), read_rows(args.b)
    keys = grid_keys(rows_a)
    if grid_keys(rows_b) != keys:
        sys.exit(f"the sweeps have different grids: {keys} and {grid_keys(rows_b)}")
    index = lambda rows: {(tuple(r[k] for k in keys), r["seed"]): r for r in rows}
    a, b = index(rows_a), index(rows_b)
    missing = sorted(set(a) ^ set(b))
    if missing:
        print(f"runs in only one of the sweeps (left out): {missing}", file=sys.stderr)
    points = sorted({p for p, _ in set(a) & set(b)})
    reg_a, reg_b = regimes(args.a, keys), regimes(args.b, keys)
    disagreements = 0
    for point in points:
        seeds = sorted((s for p, s in set(a) & set(b) if p == point), key=int)
        name = ", ".join(f"{k} = {v}" for k, v in zip(keys, point))
        print(f"\n{name}: seeds {', '.join(seeds)}")
        if args.markdown:
            cols = " | ".join(f"seed {s} {args.label_a} / {args.label_b}" for s in seeds)
            print(f"| measure | {cols} | largest difference | seed spread ({args.label_a}) | agrees |")
            print("|---" * (len(seeds) + 4) + "|")
        for col, label in MEASURES:
            va = [number(a[(point, s)].get(col)) for s in seeds]
            vb = [number(b[(point, s)].get(col)) for s in seeds]
            pairs = [(x, y) for x, y in zip(va, vb) if x is not None and y is not None]
            if not pairs:
                continue
            diff = max(abs(x - y) for x, y in pairs)
            known = [x for x in va if x is not None]
            spread = max(known) - min(known)
            agrees = diff <= spread if spread > 0 else diff == 0
            disagreements += not agrees
            fmt = lambda v: "—" if v is None else f"{v:.6g}"
            cells = [f"{fmt(x)} / {fmt(y)}" for x, y in zip(va, vb)]
            verdict = "yes" if agrees else "NO"
            if args.markdown:
                print(f"| {label} | {' | '.join(cells)} | {diff:.3g} | {spread:.3g} | {verdict} |")
            else:
                print(f"  {label:30} {'   '.join(cells):60}  |A-B| <= {diff:.3g}, spread {spread:.3g}: {verdict}")
        print(f"  regime: {reg_a.get(point, '?')} ({args.label_a}), {reg_b.get(point, '?')} ({args.label_b})")
        if reg_a.get(point) != reg_b.get(point):
            disagreements += 1
    print(f"\n{disagreements} measure(s) differ by more than the seed spread")
    return 1 if disagreements else 0


if __name__ == "__main__":
    sys.exit(main())
