"""Accuracy study behind the default step controls (h_max, step_c); results in docs/numerics.md.

For each case, the statistics at the final time with the step controls under test are compared
with a reference run whose controls are four times finer (same seed, independent noise
because the steps differ). The deviation is reported in units of the combined standard error,
and relative to the standard error of a paper-size (10^4-path) run, which is the accuracy a
user needs: a bias well below that is invisible in every figure.

Run:  .venv/bin/python docs/accuracy_study.py [--paths N] > docs/accuracy_study.txt
"""

from __future__ import annotations

import argparse
import itertools
import math
import time

import numpy as np

import stochpend

STATS = ("mean_E", "mean_E2", "skewness", "flatness")


def run_case(noise, D, tau, omega, t_end, paths, h_max, step_c, seed):
    ds = stochpend.simulate(noise=noise, D=D, tau=tau, omega=omega, paths=paths, t_max=t_end,
                            times=[t_end], seed=seed, h_max=h_max, step_c=step_c)
    return ds.isel(time=-1), ds.attrs["path_steps"], ds.attrs["wall_time_s"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", type=int, default=20_000)
    ap.add_argument("--h-max", type=float, default=stochpend.model.settings.DEFAULT_H_MAX)
    ap.add_argument("--step-c", type=float, default=stochpend.model.settings.DEFAULT_STEP_C)
    ap.add_argument("--refine", type=float, default=4.0)
    args = ap.parse_args()
    cases = []
    for tau, D, omega in itertools.product((0.01, 0.1, 1.0, 10.0), (1.0, 100.0), (0.0, 1.0)):
        # A time in the colored regime when it is reachable, else deep in the white-like one;
        # capped so that the whole study stays within minutes on 2 cores.
        t_c = 1.0 / (D * tau * tau)
        t_end = float(min(max(10.0 * t_c, 10.0), 200.0 if D == 1.0 else 20.0))
        cases.append(("ou", D, tau, omega, t_end))
    cases += [("white", 1.0, None, 0.0, 200.0), ("white", 1.0, None, 1.0, 200.0),
              ("white", 100.0, None, 1.0, 20.0)]
    print(f"# accuracy study: h_max={args.h_max}, step_c={args.step_c} vs /{args.refine}; "
          f"{args.paths} paths per run")
    print("| noise | D | tau | omega | t | path-steps/path | " + " | ".join(
        f"{s}: dev/SE (dev/SE_1e4)" for s in STATS) + " |")
    print("|---" * (6 + len(STATS)) + "|")
    worst = 0.0
    for noise, D, tau, omega, t_end in cases:
        t0 = time.perf_counter()
        a, steps_a, _ = run_case(noise, D, tau, omega, t_end, args.paths, args.h_max, args.step_c, 1)
        b, _, _ = run_case(noise, D, tau, omega, t_end, args.paths, args.h_max / args.refine,
                           args.step_c / args.refine, 2)
        cells = []
        for s in STATS:
            dev = float(a[s] - b[s])
            se = math.hypot(float(a[f"{s}_stderr"]), float(b[f"{s}_stderr"]))
            se_1e4 = float(a[f"{s}_stderr"]) * math.sqrt(args.paths / 1e4)
            z = dev / se
            worst = max(worst, abs(z))
            cells.append(f"{z:+.2f} ({dev / se_1e4:+.2f})")
        print(f"| {noise} | {D:g} | {tau if tau is not None else '-'} | {omega:g} | {t_end:g} | "
              f"{steps_a / args.paths:.0f} | " + " | ".join(cells) + f" |  <!-- {time.perf_counter() - t0:.0f}s -->",
              flush=True)
    print(f"\nlargest |dev|/SE: {worst:.2f}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
