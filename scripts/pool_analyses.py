#!/usr/bin/env python3
"""Pools the tables `monolayer analyze` wrote for several runs (each ANALYSIS dir holds
hole_precursors.csv, hole_precursors_chance.csv, hole_alignment.csv, hole_probability.csv) into
the numbers docs/figures.md quotes for runs made outside `monolayer figures`:

- Figs. 1c-d, S2 and the mechanism's pair angle and -1/2 distance: the mean over nucleations of
  each precursor measure, k frames before nucleation, with its standard error, beside the same
  measure about the random sites of the same frames (the chance line);
- the seed spread of each precursor measure: per run with a nucleation, its mean over its
  nucleations minus its chance mean (same run, same frames before), and in how many runs the
  difference has the sign of the paper's claim (nearer than chance for distances, above chance
  for the strain rate and the pair angle);
- tangential alignment: per run, the mean angle (degrees) between the elongation axis and the
  hole's edge of cells bordering a hole, and of cells away from holes;
- Fig. 2: P(hole | strain rate) pooled over the runs, fitted as P = A exp(b eps) by binomial
  maximum likelihood (the standard error treats sites as independent, which they are not: a
  hole opens many neighbouring sites at once, so it is a lower bound), and with three runs or
  more the jackknife standard error over runs (leave one run with a hole site out at a time).

    python3 scripts/pool_analyses.py DIR/analysis ...     # e.g. runs/*/analysis

Needs numpy and scipy for the fit only (pip install numpy scipy); the rest is the standard
library.
"""

import csv
import math
import statistics
import sys
from collections import defaultdict
from pathlib import Path

PRECURSORS = [
    "spiral_core_distance_over_r",
    "plus_half_distance_over_r",
    "second_plus_half_distance_over_r",
    "max_strain_rate_within_r_half_over_max",
    "plus_half_pair_angle",
    "minus_half_distance_over_r",
]
FRAMES_BEFORE = [0, 1, 2, 3, 5, 10]


def rows(path):
    with open(path, newline="") as f:
        yield from csv.DictReader(f)


def finite(value):
    try:
        x = float(value)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def pooled_precursors(dirs, name):
    """{frames_before: {column: [values over nucleations or random sites]}}."""
    out = defaultdict(lambda: defaultdict(list))
    for d in dirs:
        for r in rows(d / name):
            for c in PRECURSORS:
                x = finite(r[c])
                if x is not None:
                    out[int(r["frames_before"])][c].append(x)
    return out


def mean_sem(v):
    if len(v) < 2:
        return (v[0] if v else math.nan), math.nan
    return statistics.mean(v), statistics.stdev(v) / math.sqrt(len(v))


def report_precursors(dirs):
    holes = pooled_precursors(dirs, "hole_precursors.csv")
    chance = pooled_precursors(dirs, "hole_precursors_chance.csv")
    print(f"precursors: {len(holes[0][PRECURSORS[0]])} nucleations; mean ± s.e. (nucleations) vs chance")
    for c in PRECURSORS:
        cells = []
        for k in FRAMES_BEFORE:
            if holes[k][c] and chance[k][c]:
                (m, s), (mc, sc) = mean_sem(holes[k][c]), mean_sem(chance[k][c])
                cells.append(f"{k}: {m:.2f}±{s:.2f} (n={len(holes[k][c])}) vs {mc:.2f}±{sc:.2f}")
        print(f"  {c}: " + " | ".join(cells))


# The sign of (measure - chance) that the paper's claim predicts.
CLAIMED_SIGN = {
    "spiral_core_distance_over_r": -1,
    "plus_half_distance_over_r": -1,
    "second_plus_half_distance_over_r": -1,
    "max_strain_rate_within_r_half_over_max": 1,
    "plus_half_pair_angle": 1,
    "minus_half_distance_over_r": 1,
}


def report_seed_spread(dirs):
    """Per run: mean over its nucleations minus its chance mean, k frames before."""
    per_run = [(pooled_precursors([d], "hole_precursors.csv"), pooled_precursors([d], "hole_precursors_chance.csv")) for d in dirs]
    print("seed spread: per run with a nucleation, (mean - chance); runs with the claimed sign / runs")
    for c in PRECURSORS:
        cells = []
        for k in FRAMES_BEFORE:
            diffs = [statistics.mean(h[k][c]) - statistics.mean(ch[k][c]) for h, ch in per_run if h[k][c] and ch[k][c]]
            if diffs:
                agree = sum(1 for x in diffs if x * CLAIMED_SIGN[c] > 0)
                cells.append(f"{k}: {statistics.median(diffs):+.2f} [{min(diffs):+.2f}, {max(diffs):+.2f}] {agree}/{len(diffs)}")
        print(f"  {c}: " + " | ".join(cells))


def report_alignment(dirs):
    near, far = [], []
    for d in dirs:
        angles = defaultdict(list)
        for r in rows(d / "hole_alignment.csv"):
            x = finite(r["mean_angle_to_tangent"])
            if x is not None:
                angles[r["where"]].append(math.degrees(x))
        if angles["bordering_a_hole"] and angles["away_from_holes"]:
            near.append(statistics.mean(angles["bordering_a_hole"]))
            far.append(statistics.mean(angles["away_from_holes"]))
    if near:
        print(
            f"alignment over {len(near)} runs with a hole: bordering a hole {statistics.mean(near):.1f}° "
            f"({min(near):.1f}–{max(near):.1f}), away from holes {statistics.mean(far):.1f}° "
            f"({min(far):.1f}–{max(far):.1f}); 0° tangential, 45° random"
        )


def pooled_probability(dirs):
    """{bin centre: [sites, sites opening into a new hole]} summed over `dirs`."""
    pooled = defaultdict(lambda: [0, 0])
    for d in dirs:
        for r in rows(d / "hole_probability.csv"):
            eps = 0.5 * (float(r["strain_rate_bin_low"]) + float(r["strain_rate_bin_high"]))
            pooled[eps][0] += int(r["sites"])
            pooled[eps][1] += int(r["sites_opening_into_a_new_hole"])
    return pooled


def binomial_fit(pooled):
    """(ln A, b, s.e. of b from the curvature) of P = A exp(b eps) by binomial likelihood."""
    import numpy as np
    from scipy.optimize import minimize

    x = np.array(sorted(pooled))
    n = np.array([pooled[e][0] for e in x], dtype=float)
    k = np.array([pooled[e][1] for e in x], dtype=float)

    def nll(t):
        lp = np.minimum(t[0] + t[1] * x, -1e-12)
        return -(k * lp + (n - k) * np.log1p(-np.exp(lp))).sum()

    fit = minimize(nll, [-12.0, 1000.0], method="Nelder-Mead", options={"maxiter": 20000, "xatol": 1e-8, "fatol": 1e-10})
    h = 1e-3 * abs(fit.x[1]) + 1e-3
    curvature = (nll(fit.x + [0, h]) - 2 * nll(fit.x) + nll(fit.x - [0, h])) / h**2
    return fit.x[0], fit.x[1], (1 / math.sqrt(curvature) if curvature > 0 else math.nan), x, n, k


def report_hole_probability(dirs):
    try:
        import numpy  # noqa: F401
        import scipy  # noqa: F401
    except ImportError:
        print("P(hole | eps): not fitted (needs numpy and scipy: pip install numpy scipy)")
        return
    ln_a, b, se, x, n, k = binomial_fit(pooled_probability(dirs))
    print(f"P(hole | eps): {int(n.sum())} sites, {int(k.sum())} opened; b = {b:.0f} ± {se:.0f}, P(0) = {math.exp(ln_a):.2e}")
    if len(dirs) >= 3:
        # The curvature's error treats sites as independent; leaving out one run at a time
        # measures the spread between runs (jackknife over the runs with a hole site).
        with_holes = [d for d in dirs if any(int(r["sites_opening_into_a_new_hole"]) for r in rows(d / "hole_probability.csv"))]
        if len(with_holes) >= 3:
            rest = [d for d in dirs if d not in with_holes]
            bs = [binomial_fit(pooled_probability(rest + with_holes[:i] + with_holes[i + 1 :]))[1] for i in range(len(with_holes))]
            m = statistics.mean(bs)
            jack = math.sqrt((len(bs) - 1) / len(bs) * sum((v - m) ** 2 for v in bs))
            print(f"  jackknife over the {len(with_holes)} runs with a hole site: s.e. of b = {jack:.0f}")
    for lo, hi in [(-1, 0), (0, 0.001), (0.001, 0.002), (0.002, 0.004), (0.004, 1)]:
        m = (x >= lo) & (x < hi)
        if n[m].sum():
            print(f"  eps in [{lo}, {hi}): {int(n[m].sum())} sites, {int(k[m].sum())} opened, P = {k[m].sum() / n[m].sum():.2e}")


def main(args):
    if not args or args[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if args else 2
    dirs = [Path(a) for a in args]
    for d in dirs:
        missing = [f for f in ("hole_precursors.csv", "hole_alignment.csv", "hole_probability.csv") if not (d / f).is_file()]
        if missing:
            print(f"error: {d}: no {', '.join(missing)} (run `monolayer analyze RUN --out {d}` first)", file=sys.stderr)
            return 2
    report_precursors(dirs)
    report_seed_spread(dirs)
    report_alignment(dirs)
    report_hole_probability(dirs)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
