"""Whole-step and per-op CPU timings of photomat's networks in plain PyTorch.

The PyTorch half of the side-by-side benchmark: the same cases, options and JSON
schema as `photomat bench` (cli/src/commands/bench.rs); `bench/compare.py` runs both and
prints the table. What each case measures is listed in `CASES` and in bench/README.md.

    bench/pytorch/.venv/bin/python bench/pytorch/bench_steps.py --size 64 --threads 2 --json

Timing: each case runs `--warmup` untimed iterations, then `--iters` timed ones; the JSON
holds every time, the median and the minimum (seconds per iteration). No optimiser update
is part of a step (both sides). Inputs are drawn once per case, outside the timed region.
"""

import argparse
import json
import math
import os
import platform
import sys
import time

import torch
import torch.nn.functional as F

sys.dont_write_bytecode = True  # keep bench/pytorch free of __pycache__ (nothing to ignore)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import models  # noqa: E402

#: The environment variables that cap the instruction set of ATen's kernels, MKL (GEMMs) and
#: oneDNN (convolutions): `bench/compare.py --isa avx2` sets all three.
ISA_CAPS = ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "ONEDNN_MAX_CPU_ISA")

#: name -> what it measures (same text as the Rust side's case table).
CASES = {
    "g_step": "G+M forward, frozen D on the fakes, softplus(-D) loss, backward (G and M gradients)",
    "d_step": "D forward on fake+real images, logistic loss, backward to D (no R1)",
    "d_r1": "R1 penalty (D forward, input gradient with graph, squared norm), backward to D",
    "e_step": "E forward, height(ggx) decode, flash render, 0.1*L1 to M's image, backward to E",
    "sample": "one material: G forward, M relight and E maps + analytic render at the centre",
    "mlp": "M alone (per-texel MLP on B*R*R rows), forward + backward",
    "conv3x3": "3x3 conv 64->64, stride 1, zero padding 1, at 2R x 2R: fwd + bwd",
    "conv4x4s2": "4x4 conv 64->64, stride 2, zero padding 1, at 2R x 2R: fwd + bwd",
    "conv1x1": "1x1 conv 64->64 at 2R x 2R: forward + backward",
    "modconv": "G's modulated 3x3 conv 64->64 with demodulation at R x R: fwd + bwd",
    "fir_up": "G's [1,3,3,1] FIR x2 upsampling of 64 channels, R -> 2R: fwd + bwd",
    "bias_lrelu": "bias + LeakyReLU(0.2) * sqrt(2) on 64 channels at 2R x 2R: fwd + bwd",
    "bilinear_up": "E's periodic bilinear x2 upsampling of 64 channels, R -> 2R: fwd + bwd",
    "sgemm": "one 1024x1024 by 1024x1024 f32 matrix product (the GEMM ceiling)",
}
DEFAULT_CASES = list(CASES)
R1_GAMMA_BASE = 0.0002  # docs/neural-models.md, "GAN training": gamma = 0.0002 * res^2 / batch
R1_INTERVAL = 16  # lazy R1 every 16 steps; the trainer scales the penalty by it
MICRO_CHANNELS = 64


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=64, help="resolution R of G, M, D and E")
    p.add_argument("--multiplier", type=float, default=0.25, help="channel multiplier of G and D")
    p.add_argument("--batch", type=int, default=4, help="batch of the training steps")
    p.add_argument("--iters", type=int, default=5, help="timed iterations per case")
    p.add_argument("--warmup", type=int, default=1, help="untimed iterations per case first")
    p.add_argument("--cases", default=",".join(DEFAULT_CASES),
                   help="comma-separated subset of: " + ", ".join(CASES))
    p.add_argument("--threads", type=int, default=None,
                   help="torch.set_num_threads (default: torch's own default)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = p.parse_args(argv)
    args.cases = [c for c in args.cases.split(",") if c]
    unknown = [c for c in args.cases if c not in CASES]
    if unknown:
        p.error(f"unknown case(s) {unknown}; known: {', '.join(CASES)}")
    if args.size < 32 or args.size & (args.size - 1):
        p.error(f"--size {args.size}: use a power of two >= 32")
    if args.iters < 1 or args.warmup < 0 or args.batch < 1:
        p.error("--iters >= 1, --warmup >= 0, --batch >= 1")
    return args


def time_case(fn, iters, warmup):
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(iters):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def highlights(batch, gen):
    """Highlights uniform in [-0.5, 0.5)^2 (docs/neural-models.md, "Training E"), one per sample."""
    xy = torch.rand(batch, 2, generator=gen, dtype=torch.float64) - 0.5
    return [(float(x), float(y)) for x, y in xy]


def conv_flops(b, c_in, c_out, ho, wo, k):
    return 2.0 * b * c_out * ho * wo * c_in * k * k


class Bench:
    """Networks and inputs shared by the cases of one run."""

    def __init__(self, a):
        self.a = a
        gen = torch.Generator().manual_seed(a.seed)
        self.gen = gen
        r, b = a.size, a.batch
        self.g = models.Generator(r, a.multiplier)
        self.m = models.Relight()
        self.d = models.Discriminator(r, a.multiplier)
        self.e = models.Estimator()
        self.omega, self.inv_d2 = models.flash_geometry(highlights(b, gen), r)
        self.omega_c, self.inv_d2_c = models.flash_geometry([(0.0, 0.0)], r)
        self.z = torch.randn(b, 512, generator=gen)
        self.noise = [torch.randn(s, generator=gen) for s in self.g.noise_shapes(b)]
        with torch.no_grad():
            self.features = self.g(self.z, self.noise)
            self.fake = self.m(self.features, self.omega)
        self.real = torch.rand(b, 3, r, r, generator=gen) * 2 - 1

    def params(self):
        return {
            "g": models.count_parameters(self.g),
            "g_buffers": sum(x.numel() for x in self.g.buffers()),
            "m": models.count_parameters(self.m),
            "d": models.count_parameters(self.d),
            "e": models.count_parameters(self.e),
        }

    def gradient_step(self, shape, f, params):
        """Forward + backward of sum(f(x) * g) w.r.t. x and `params` (tensors or modules)."""
        x = torch.randn(shape, generator=self.gen).requires_grad_(True)
        with torch.no_grad():
            g = torch.randn(f(x).shape, generator=self.gen)

        def step():
            x.grad = None
            for p in params:
                for t in (p.parameters() if isinstance(p, torch.nn.Module) else [p]):
                    t.grad = None
            (f(x) * g).sum().backward()
        return step

    @staticmethod
    def _clear(*modules):
        for mod in modules:
            for p in mod.parameters():
                p.grad = None

    def case(self, name):
        """(step function, FLOPs per step or None)."""
        r, b = self.a.size, self.a.batch
        if name == "g_step":
            # Gradients of G's and M's parameters only: D is frozen in the G phase, as in
            # StyleGAN2-ADA and photomat's trainer (D's input gradients, no weight gradients).
            g_m = list(self.g.parameters()) + list(self.m.parameters())

            def step():
                self._clear(self.g, self.m, self.d)
                f = self.g(self.z, self.noise)
                logits = self.d(self.m(f, self.omega), self.omega)
                F.softplus(-logits).mean().backward(inputs=g_m)
            return step, None
        if name == "d_step":

            def step():
                self._clear(self.d)
                loss = (F.softplus(self.d(self.fake, self.omega)).mean()
                        + F.softplus(-self.d(self.real, self.omega)).mean())
                loss.backward()
            return step, None
        if name == "d_r1":
            gamma = R1_GAMMA_BASE * r * r / b

            def step():
                self._clear(self.d)
                penalty = models.r1_penalty(self.d, self.real, self.omega)
                (penalty.mean() * (gamma / 2 * R1_INTERVAL)).backward()
            return step, None
        if name == "e_step":
            feats, target = self.features, self.fake

            def step():
                self._clear(self.e)
                maps = models.decode_height_ggx(self.e(feats))
                img = models.render_encoded(maps, self.omega, self.inv_d2) * 2 - 1
                ((img - target).abs().mean() * 0.1).backward()
            return step, None
        if name == "sample":
            z = self.z[:1]
            noise = [n[:1] for n in self.noise]

            def step():
                with torch.no_grad():
                    f = self.g(z, noise)
                    self.m(f, self.omega_c)
                    maps = models.decode_height_ggx(self.e(f))
                    models.render_encoded(maps, self.omega_c, self.inv_d2_c)
            return step, None
        if name == "mlp":
            rows = torch.cat([self.features, self.omega], 1).permute(0, 2, 3, 1).reshape(-1, 35)
            g_out = torch.randn(rows.shape[0], 3, generator=self.gen)

            def step():
                self._clear(self.m)
                (self.m.forward_rows(rows) * g_out).sum().backward()
            return step, None
        c = MICRO_CHANNELS
        if name in ("conv3x3", "conv4x4s2", "conv1x1"):
            k, stride, pad = {"conv3x3": (3, 1, 1), "conv4x4s2": (4, 2, 1),
                              "conv1x1": (1, 1, 0)}[name]
            w = torch.randn(c, c, k, k, generator=self.gen).requires_grad_(True)
            side = 2 * r
            out = (side + 2 * pad - k) // stride + 1
            step = self.gradient_step(
                (b, c, side, side), lambda x: F.conv2d(x, w, stride=stride, padding=pad), [w])
            return step, 3 * conv_flops(b, c, c, out, out, k)
        if name == "modconv":
            layer = models.ModulatedConv2d(c, c, 3, 512, True)
            w = torch.randn(b, 512, generator=self.gen)
            step = self.gradient_step((b, c, r, r), lambda x: layer(x, w), [layer])
            return step, 3 * conv_flops(b, c, c, r, r, 3)
        if name == "fir_up":
            return self.gradient_step((b, c, r, r), models.upsample2d, []), None
        if name == "bias_lrelu":
            bias = torch.randn(c, generator=self.gen).requires_grad_(True)
            step = self.gradient_step(
                (b, c, 2 * r, 2 * r), lambda x: models.lrelu(x + bias[None, :, None, None]),
                [bias])
            return step, None
        if name == "bilinear_up":
            return self.gradient_step((b, c, r, r), models.upsample2x_periodic, []), None
        if name == "sgemm":
            m1 = torch.randn(1024, 1024, generator=self.gen)
            m2 = torch.randn(1024, 1024, generator=self.gen)

            def step():
                torch.mm(m1, m2)
            return step, 2.0 * 1024**3
        raise ValueError(name)


def main(argv=None):
    a = parse_args(argv)
    if a.threads:
        torch.set_num_threads(a.threads)
    torch.manual_seed(a.seed)
    bench = Bench(a)
    report = {
        "implementation": "pytorch",
        "version": torch.__version__,
        "threads": torch.get_num_threads(),
        "platform": f"{platform.machine()} python {platform.python_version()}",
        # The kernels ATen dispatches to (AVX512, AVX2, …: ATEN_CPU_CAPABILITY caps it) and the
        # caps MKL and oneDNN were given, so that a table says which instruction set ran.
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "isa_caps": {k: os.environ[k] for k in ISA_CAPS if k in os.environ},
        "size": a.size,
        "multiplier": a.multiplier,
        "batch": a.batch,
        "iters": a.iters,
        "warmup": a.warmup,
        "parameters": bench.params(),
        "cases": [],
    }
    for name in a.cases:
        fn, flops = bench.case(name)
        times = time_case(fn, a.iters, a.warmup)
        ordered = sorted(times)
        report["cases"].append({
            "name": name,
            "what": CASES[name],
            "size": a.size,
            "batch": 1 if name == "sample" else a.batch,
            "median_s": ordered[len(ordered) // 2],
            "min_s": ordered[0],
            "times_s": times,
            "flops": flops,
        })
        if not a.json:
            c = report["cases"][-1]
            gf = f"  {flops / c['median_s'] / 1e9:7.1f} GFLOP/s" if flops else ""
            print(f"{name:<12} median {c['median_s']:.4f} s  min {c['min_s']:.4f} s{gf}",
                  flush=True)
    if a.json:
        json.dump(report, sys.stdout, indent=1)
        print()
    else:
        print(f"torch {report['version']}, {report['threads']} threads, "
              f"parameters {report['parameters']}")


if __name__ == "__main__":
    main()
