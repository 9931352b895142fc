#!/usr/bin/env python3
"""Times two photomat binaries against each other on `photomat bench` cases, alternately.

    python3 bench/ab.py OLD_BINARY NEW_BINARY --cases g_step,d_step [--rounds 6] [--threads 1]

Each round runs both binaries once (the order swapped every other round, so that load from
other jobs hits both alike); each run reports per case the median of `--iters` timed
iterations. Printed per case: the median over rounds of each binary's medians and the median,
minimum and maximum over rounds of the per-round ratio NEW / OLD (< 1: NEW is faster). The
spread is the noise to read a change against. Standard library only.
"""

import argparse
import json
import os
import statistics
import subprocess


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("old")
    p.add_argument("new")
    p.add_argument("--cases", required=True, help="photomat bench cases, comma-separated")
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--multiplier", type=float, default=0.25)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--iters", type=int, default=5)
    a = p.parse_args()
    env = dict(os.environ, RAYON_NUM_THREADS=str(a.threads))
    medians = {a.old: [], a.new: []}
    for r in range(a.rounds):
        for binary in (a.old, a.new) if r % 2 == 0 else (a.new, a.old):
            out = subprocess.run(
                [binary, "bench", "--size", str(a.size), "--multiplier", str(a.multiplier),
                 "--batch", str(a.batch), "--iters", str(a.iters), "--cases", a.cases, "--json"],
                env=env, capture_output=True, text=True, check=True).stdout
            medians[binary].append({c["name"]: c["median_s"] for c in json.loads(out)["cases"]})
    print(f"{a.rounds} rounds, {a.threads} thread(s), {a.size}², load {os.getloadavg()[0]:.2f}")
    for case in medians[a.old][0]:
        old = [m[case] for m in medians[a.old]]
        new = [m[case] for m in medians[a.new]]
        ratios = [n / o for o, n in zip(old, new)]
        print(f"{case:12s} old {statistics.median(old):.4f} s  new {statistics.median(new):.4f} s  "
              f"new/old {statistics.median(ratios):.3f} (min {min(ratios):.3f}, "
              f"max {max(ratios):.3f})")


if __name__ == "__main__":
    main()
