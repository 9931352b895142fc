#!/usr/bin/env python3
"""Runs `photomat bench` and the PyTorch script side by side and prints a markdown table.

    python3 bench/compare.py                      # threads 2 and 1, 2 rounds, release build
    python3 bench/compare.py --threads 2 --rounds 3 --iters 5

With `--candle-baseline` each round also runs photomat on its plain-candle reference ops
(`photomat bench --candle-reference`), and the table adds that time and the kernels'
speed-up (candle / photomat).

For every thread count and configuration (`--configs`, default: all cases at 64², sampling
and the E step at 256²) it runs the two implementations alternately, round after round
(photomat, PyTorch, photomat, PyTorch, ...), so that load from other jobs on the machine hits
both alike; each run reports per case the median of its timed iterations. The table gives,
per case, the median over rounds of those medians for each side, and the median over rounds
of the per-round ratio photomat / PyTorch (< 1: photomat is faster). Convolution and sgemm
cases also show GFLOP/s and the share of the sgemm ceiling: the faster of the two sides'
1024² sgemm in the same run. The load average is printed with every run.

Before timing, it checks that both sides built networks with exactly the same parameter
counts (G, its buffers, M, D, E) and stops if not. Raw reports go to `--out` (JSON).

With `--isa avx2` both sides are kept to AVX2 + FMA on a CPU that has AVX-512, to emulate an
AVX2-only machine: photomat with PHOTOMAT_SIMD=avx2 (its direct kernels; give `--photomat` a
binary built without gemm's `x86-v4` feature to keep its GEMMs off AVX-512 too, which gemm
cannot be told at run time), PyTorch with ATEN_CPU_CAPABILITY=avx2,
MKL_ENABLE_INSTRUCTIONS=AVX2 and ONEDNN_MAX_CPU_ISA=AVX2. The header names the CPU, its vector
flags and what each side says it ran.

PyTorch runs with OMP_WAIT_POLICY=PASSIVE unless `--omp-wait-policy ACTIVE`: libgomp's
default spin-waiting made a 2-thread PyTorch 1.4-7.5x slower while other jobs shared the two
cores (build machine, load average 12: E step 5.4 s ACTIVE vs 0.72 s PASSIVE, conv3x3 1.34
vs 0.96 s, mlp 1.53 vs 0.31 s), which would flatter photomat. ACTIVE is PyTorch's default
and may be the faster one on an idle machine: compare both there.
Standard library only; PyTorch comes from bench/pytorch/.venv (bench/pytorch/setup.sh).
"""

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
VENV_PYTHON = os.path.join(ROOT, "bench", "pytorch", ".venv", "bin", "python")
SCRIPT = os.path.join(ROOT, "bench", "pytorch", "bench_steps.py")
PHOTOMAT = os.path.join(ROOT, "target", "release", "photomat")
DEFAULT_CONFIGS = "64:all;256:sample,e_step"
#: --isa → (photomat's environment, PyTorch's environment).
ISA_ENV = {
    "native": ({}, {}),
    "avx2": ({"PHOTOMAT_SIMD": "avx2"},
             {"ATEN_CPU_CAPABILITY": "avx2", "MKL_ENABLE_INSTRUCTIONS": "AVX2",
              "ONEDNN_MAX_CPU_ISA": "AVX2"}),
}
#: The /proc/cpuinfo flags a table reports: which kernel families the CPU could run.
VECTOR_FLAGS = ("avx512f", "avx512bw", "avx512vl", "avx512_vnni", "avx2", "fma", "avx")


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--threads", default="2,1", help="thread counts, comma-separated")
    p.add_argument("--rounds", type=int, default=2, help="alternating runs per side")
    p.add_argument("--iters", type=int, default=3, help="timed iterations per case and run")
    p.add_argument("--warmup", type=int, default=1)
    p.add_argument("--multiplier", type=float, default=0.25)
    p.add_argument("--batch", type=int, default=4)
    p.add_argument("--configs", default=DEFAULT_CONFIGS,
                   help="SIZE:CASES;SIZE:CASES with CASES 'all' or a comma list "
                        f"(default {DEFAULT_CONFIGS!r})")
    p.add_argument("--omp-wait-policy", default="PASSIVE", choices=["PASSIVE", "ACTIVE"],
                   help="OMP_WAIT_POLICY of the PyTorch side (default PASSIVE: see the docs)")
    p.add_argument("--candle-baseline", action="store_true",
                   help="also run photomat on plain candle (photomat bench --candle-reference)")
    p.add_argument("--skip-build", action="store_true",
                   help="use the existing target/release/photomat")
    p.add_argument("--photomat", default=None,
                   help="photomat binary to time (implies --skip-build; default: "
                        "target/release/photomat)")
    p.add_argument("--isa", default="native", choices=sorted(ISA_ENV),
                   help="instruction set both sides may use (default native: the CPU's "
                        "widest); avx2 emulates an AVX2-only machine on an AVX-512 one")
    p.add_argument("--out", default=os.path.join(ROOT, "target", "bench"),
                   help="folder for the raw JSON reports")
    a = p.parse_args()
    a.threads = [int(t) for t in a.threads.split(",") if t]
    configs = []
    for item in a.configs.split(";"):
        size, _, cases = item.partition(":")
        configs.append((int(size), None if cases in ("", "all") else cases))
    a.configs = configs
    if a.rounds < 1 or a.iters < 1 or not a.threads:
        p.error("--rounds, --iters and --threads need at least 1")
    return a


def load():
    return "%.2f %.2f %.2f" % os.getloadavg()


def run_side(side, threads, size, cases, a, photomat):
    common = ["--size", str(size), "--multiplier", str(a.multiplier), "--batch", str(a.batch),
              "--iters", str(a.iters), "--warmup", str(a.warmup), "--json"]
    if cases:
        common += ["--cases", cases]
    env = dict(os.environ)
    ours, theirs = ISA_ENV[a.isa]
    if side in ("photomat", "candle"):
        cmd = [photomat, "bench"] + common + (["--candle-reference"] if side == "candle" else [])
        env["RAYON_NUM_THREADS"] = str(threads)
        env.update(ours)
    else:
        cmd = [VENV_PYTHON, SCRIPT, "--threads", str(threads)] + common
        env["OMP_NUM_THREADS"] = env["MKL_NUM_THREADS"] = str(threads)
        env["OMP_WAIT_POLICY"] = a.omp_wait_policy
        env.update(theirs)
    before = load()
    start = time.time()
    done = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True)
    if done.returncode != 0:
        sys.exit(f"{side} failed ({' '.join(cmd)}):\n{done.stderr[-3000:]}")
    report = json.loads(done.stdout)
    print(f"  {side:<8} {threads} thread(s) {size}²: {time.time() - start:5.0f} s, "
          f"load {before} -> {load()}", flush=True)
    if report["threads"] != threads:
        sys.exit(f"{side} ran with {report['threads']} threads, {threads} requested")
    return report


def cpu():
    """(model name, the vector flags of VECTOR_FLAGS it has) from /proc/cpuinfo."""
    model, flags = "unknown CPU", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and model == "unknown CPU":
                    model = value.strip()
                elif key.strip() == "flags" and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    return model, [f for f in VECTOR_FLAGS if f in flags]


def check_parameters(reports):
    ours = reports["photomat"][0]["parameters"]
    for side, runs in reports.items():
        if runs[0]["parameters"] != ours:
            sys.exit(f"parameter counts differ: photomat {ours}, {side} {runs[0]['parameters']}")
    return ours


def table(results):
    """results: list of (config, {side: [report per round]}) for one thread count."""
    by = {}
    for _, reports in results:
        for side, runs in reports.items():
            for r, rep in enumerate(runs):
                for c in rep["cases"]:
                    by.setdefault((c["name"], c["size"]), {}).setdefault(side, {})[r] = c
    ceiling = max(
        (c["flops"] / c["median_s"] for (name, _), sides in by.items() if name == "sgemm"
         for runs in sides.values() for c in runs.values()),
        default=None)
    baseline = any("candle" in sides for sides in by.values())
    lines = ["| case | size | batch | photomat s | PyTorch s | ratio photomat/PyTorch "
             "| photomat GFLOP/s | PyTorch GFLOP/s |"
             + (" plain candle s | speed-up of the kernels (candle/photomat) |" if baseline
                else ""),
             "|---|---|---|---|---|---|---|---|" + ("---|---|" if baseline else "")]
    for (name, size), sides in by.items():
        ours, theirs = sides["photomat"], sides["pytorch"]
        rounds = sorted(set(ours) & set(theirs))
        o = statistics.median(ours[r]["median_s"] for r in rounds)
        t = statistics.median(theirs[r]["median_s"] for r in rounds)
        ratio = statistics.median(ours[r]["median_s"] / theirs[r]["median_s"] for r in rounds)
        flops = ours[rounds[0]]["flops"]

        def rate(seconds):
            if not flops:
                return "–"
            g = flops / seconds / 1e9
            share = f" ({100 * flops / seconds / ceiling:.0f} %)" if ceiling else ""
            return f"{g:.1f}{share}"
        row = (f"| {name} | {size}² | {ours[rounds[0]]['batch']} | {o:.4f} | {t:.4f} | "
               f"{ratio:.2f} | {rate(o)} | {rate(t)} |")
        if baseline:
            cand = sides["candle"]
            both = [r for r in rounds if r in cand]
            c = statistics.median(cand[r]["median_s"] for r in both)
            gain = statistics.median(cand[r]["median_s"] / ours[r]["median_s"] for r in both)
            row += f" {c:.4f} | {gain:.2f} |"
        lines.append(row)
    if ceiling:
        lines.append(f"\nsgemm ceiling (faster side, 1024² f32): {ceiling / 1e9:.1f} GFLOP/s; "
                     "percentages are shares of it.")
    return "\n".join(lines)


def main():
    a = parse_args()
    if not a.skip_build and not a.photomat:
        subprocess.run(["cargo", "build", "--release", "-p", "photomat-cli"], cwd=ROOT,
                       check=True)
    if not os.path.exists(VENV_PYTHON):
        sys.exit(f"{VENV_PYTHON} is missing: run bench/pytorch/setup.sh first")
    os.makedirs(a.out, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    # A private copy: other builds in the same tree cannot swap the binary between rounds.
    photomat = os.path.join(a.out, f"photomat-{stamp}")
    shutil.copy2(a.photomat or PHOTOMAT, photomat)
    everything = {}
    commit = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True).stdout.strip()
    model, flags = cpu()
    ours, theirs = ISA_ENV[a.isa]
    caps = ", ".join(f"{k}={v}" for k, v in {**ours, **theirs}.items()) or "none"
    print(f"machine: {model}, {os.cpu_count()} CPUs, CPU flags {' '.join(flags) or 'none'}, "
          f"load {load()}; photomat {a.photomat or 'built'} at {commit}; --isa {a.isa} "
          f"(caps: {caps})", flush=True)
    for threads in a.threads:
        results = []
        for size, cases in a.configs:
            sides = ("photomat", "pytorch") + (("candle",) if a.candle_baseline else ())
            reports = {side: [] for side in sides}
            for _ in range(a.rounds):
                for side in sides:
                    reports[side].append(run_side(side, threads, size, cases, a, photomat))
            params = check_parameters(reports)
            print(f"  parameters equal on every side at {size}²: {params}", flush=True)
            results.append(((size, cases), reports))
        everything[str(threads)] = [
            {"size": s, "cases": c, "reports": r} for (s, c), r in results]
        first = results[0][1]
        print(f"\n### {threads} thread(s): {first['photomat'][0]['version']} (kernels "
              f"{first['photomat'][0].get('kernels', '?')}) vs PyTorch "
              f"{first['pytorch'][0]['version']} (CPU capability "
              f"{first['pytorch'][0].get('cpu_capability', '?')}, "
              f"OMP_WAIT_POLICY={a.omp_wait_policy}), {model} ({' '.join(flags)}), "
              f"multiplier {a.multiplier}, "
              f"{a.rounds} rounds × {a.iters} iterations (+{a.warmup} warm-up)\n")
        print(table(results), flush=True)
        print()
    path = os.path.join(a.out, f"compare-{stamp}.json")
    with open(path, "w") as f:
        json.dump(everything, f, indent=1)
    os.remove(photomat)
    print(f"raw reports: {path}")


if __name__ == "__main__":
    main()
