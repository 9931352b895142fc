#!/usr/bin/env python3
"""Golden references for photomat's BRDF models, computed with Mitsuba 3 and Dr.Jit.

    python generate.py generate   # draw inputs from a fixed seed, write every golden JSON file
    python generate.py check      # recompute every reference from the committed inputs and
                                  # compare with tolerances; exit 1 on drift

Run it through ``golden/run.sh``, which creates the virtual environment, installs the pinned
wheels and libllvm19 and sets the Dr.Jit variables. Conventions, file layout and tolerances are
documented in ``golden/README.md``; this file documents how each number is obtained.

Sources of truth (all float32):
- values of ``ggx`` / ``coated``: Mitsuba's own plugins in ``scalar_rgb``, ``diffuse`` plus one
  ``principled`` (metallic 1, base_color = F0, roughness r) per specular lobe, evaluated in the
  local frame of the normalised normal. Where principled's α floor (1e-3) differs from ours (1e-4),
  i.e. roughness² < 1e-3 (tagged extreme cases only), the value comes from the composed model below;
- gradients, and those values: a model composed in Dr.Jit (``llvm_ad_rgb``) from Mitsuba's
  ``MicrofacetDistribution(GGX, α)`` (its ``eval`` = D and ``G`` = separable exact Smith) plus
  principled's Schlick Fresnel; reverse-mode AD gives per-case gradients w.r.t. every parameter,
  including the un-normalised normal. The composed model is checked against the plugin sum on
  every case (with principled's α floor emulated where it applies);
- height → normal: Mitsuba's ``bumpmap`` over a ``bitmap`` texture (bilinear, repeat), its shading
  normal read out by a probe BSDF nested inside it; the mean of its one-sided gradients a quarter
  texel either side of a texel centre is the central difference;
- renders: Mitsuba's ``direct`` integrator, one stratified (unjittered) sample per pixel, a
  perspective camera collocated with a point light at the flash, ``normalmap`` over raw bitmaps,
  one scene per lobe, summed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import random
import struct
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

SEED = 20230803
N_RANDOM = 256
# float32 unit roundoff: the resolution of every Mitsuba number stored here.
U32 = 2.0**-24
# float32 noise of a reference: how far it moves when every input moves by up to NOISE_ULPS
# roundoffs (NOISE_RUNS random draws). A case is "strict" when both its value noise (relative) and
# its gradient noise (relative to the gradient-row norm) stay ≤ STRICT_NOISE, half the tightest
# tolerance (1e-5); others are "ill_conditioned" (tagged extremes only: asserted).
NOISE_RUNS = 8
NOISE_ULPS = 1
STRICT_NOISE = 5e-6
# Random roughness stays above this: α ≥ 0.0225 keeps the peak of D well resolved in float32
# (the relative error of D grows like u/α near its peak) and far above principled's α floor.
RANDOM_ROUGHNESS_MIN = 0.15
# Blinn-Phong's cos^e θ_h moves by e·tan θ_h·δθ for an input rounding δθ: its condition number
# grows with the exponent e = 2/α² − 2 (GGX's stays below ~4), so its random cases stay at
# roughness ≥ 0.5 (e ≤ 30) for the float32 noise (gradients included) to stay below STRICT_NOISE. The low-roughness
# behaviour is still covered by the tagged extreme cases.
BLINN_RANDOM_ROUGHNESS_MIN = 0.5

# Tolerances of `check` (regenerated vs committed references; README "Drift check"). The LLVM
# backend may round differently on another CPU, by about a case's measured float32 noise.
DRIFT_REL = 2e-6  # floor: values relative, gradients relative to the per-case gradient-row norm
DRIFT_NOISE_FACTOR = 2.0  # per case: max(DRIFT_REL, factor × the case's noise)
DRIFT_NORMAL = 1e-6  # bumpmap normals, absolute; their height gradients relative to the max
DRIFT_RENDER = 5e-6  # render radiance, relative
# Composed model vs Mitsuba's plugins (asserted while generating and checking).
CROSS_REL = 4e-6

GGX_PARAMS = [("diffuse", 3), ("specular", 3), ("roughness", 1), ("normal", 3)]
GGX_ANISO_PARAMS = [
    ("diffuse", 3),
    ("specular", 3),
    ("roughness_t", 1),
    ("roughness_b", 1),
    ("angle", 1),
    ("normal", 3),
]
# Variants of `ggx` (its choice arguments; docs/plugins.md, "Model variants"). Mitsuba has no
# plugin for them, so their references come from the composed model alone, with Mitsuba's own
# `smith_g1` for the height-correlated term: (golden stem, specification, choices).
GGX_VARIANTS = [
    ("ggx_shadowing_correlated", "ggx(shadowing=correlated)", {"shadowing": "correlated"}),
    ("ggx_shadowing_implicit", "ggx(shadowing=implicit)", {"shadowing": "implicit"}),
    ("ggx_fresnel_constant", "ggx(fresnel=constant)", {"fresnel": "constant"}),
]
COATED_PARAMS = [
    ("diffuse", 3),
    ("specular", 3),
    ("roughness", 1),
    ("specular2", 3),
    ("roughness2", 1),
]

mi = None  # imported lazily so that `--help` works without the wheels
dr = None


def import_mitsuba():
    global mi, dr
    import drjit  # noqa: PLC0415
    import mitsuba  # noqa: PLC0415

    mi, dr = mitsuba, drjit


# ----------------------------------------------------------------------------------------------
# float32 numbers and small f64 vector helpers


def f32(x):
    """Round a Python float to the nearest float32 (returned as a Python float)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def v32(v):
    return [f32(x) for x in v]


def q(x):
    """A JSON number: 9 significant digits identify a float32 exactly; non-finite → null."""
    if x is None or not math.isfinite(x):
        return None
    return float(f"{x:.9g}")


def ql(v):
    return [q(x) for x in v]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def norm(a):
    return math.sqrt(dot(a, a))


def normalize(a):
    n = norm(a)
    return [x / n for x in a]


def scale(a, s):
    return [x * s for x in a]


def add(a, b):
    return [x + y for x, y in zip(a, b)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def basis(axis):
    """Two unit vectors completing the unit `axis` to an orthonormal frame."""
    helper = [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0]
    t = normalize(cross(axis, helper))
    return t, cross(axis, t)


def direction(axis, cos_theta, phi):
    """Unit vector at polar angle acos(cos_theta) from `axis`, azimuth phi."""
    s = math.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    t, b = basis(axis)
    return normalize(
        add(scale(axis, cos_theta), add(scale(t, s * math.cos(phi)), scale(b, s * math.sin(phi))))
    )


def random_direction(rnd, axis, cos_min, cos_max):
    return direction(axis, rnd.uniform(cos_min, cos_max), rnd.uniform(0.0, 2.0 * math.pi))


Z = [0.0, 0.0, 1.0]


# ----------------------------------------------------------------------------------------------
# BRDF cases: inputs


def rgb(rnd, lo=0.0, hi=1.0):
    return v32([rnd.uniform(lo, hi) for _ in range(3)])


def random_ggx_case(rnd, collocated, roughness_min=RANDOM_ROUGHNESS_MIN):
    """Well-conditioned random case: normal tilted ≤ 60° with length in [0.5, 2], both directions
    ≥ 0.05 above the normal's horizon, roughness ≥ roughness_min."""
    n = v32(scale(random_direction(rnd, Z, 0.5, 1.0), math.exp(rnd.uniform(-0.7, 0.7))))
    axis = normalize(n)
    while True:
        wi = v32(random_direction(rnd, axis, 0.05, 1.0))
        wo = wi if collocated else v32(random_direction(rnd, axis, 0.05, 1.0))
        if dot(wi, axis) > 0.045 and dot(wo, axis) > 0.045:
            break
    params = {
        "diffuse": rgb(rnd),
        "specular": rgb(rnd),
        "roughness": [f32(rnd.uniform(roughness_min, 1.0))],
        "normal": n,
    }
    tag = "random_collocated" if collocated else "random"
    return {"tag": tag, "wi": wi, "wo": wo, "params": params}


def random_aniso_case(rnd, collocated):
    """A random `ggx` case with two roughnesses (within 2× of each other) and a tangent angle
    instead of one roughness."""
    case = random_ggx_case(rnd, collocated)
    params = case["params"]
    params["roughness_t"] = params.pop("roughness")
    # Up to 2× the tangent's roughness either way: strong anisotropy at low roughness makes D's
    # slope in the angle too steep for float32 to resolve to the strict tolerance.
    r_t = params["roughness_t"][0]
    params["roughness_b"] = [f32(min(1.0, max(RANDOM_ROUGHNESS_MIN, r_t * math.exp(rnd.uniform(-0.7, 0.7)))))]
    params["angle"] = [f32(rnd.uniform(0.0, 1.0))]
    case["params"] = {name: params[name] for name, _ in GGX_ANISO_PARAMS}
    return case


def random_coated_case(rnd, collocated):
    while True:
        wi = v32(random_direction(rnd, Z, 0.05, 1.0))
        wo = wi if collocated else v32(random_direction(rnd, Z, 0.05, 1.0))
        if wi[2] > 0.045 and wo[2] > 0.045:
            break
    params = {
        "diffuse": rgb(rnd),
        "specular": rgb(rnd),
        "roughness": [f32(rnd.uniform(RANDOM_ROUGHNESS_MIN, 1.0))],
        "specular2": rgb(rnd),
        "roughness2": [f32(rnd.uniform(RANDOM_ROUGHNESS_MIN, 1.0))],
    }
    tag = "random_collocated" if collocated else "random"
    return {"tag": tag, "wi": wi, "wo": wo, "params": params}


def at(cos_theta, phi_deg, axis=Z):
    return v32(direction(axis, cos_theta, math.radians(phi_deg)))


def tilted(theta_deg, phi_deg, length=1.0):
    return v32(scale(direction(Z, math.cos(math.radians(theta_deg)), math.radians(phi_deg)), length))


def extreme_ggx_cases():
    """Tagged extreme cases (docs/plugins.md, "Evaluation contract"): roughness at its floor
    and at 1, grazing, below the horizon, tilted and degenerate normals, albedo at 0 and 1."""
    d0, s0 = v32([0.2, 0.5, 0.8]), v32([0.9, 0.6, 0.04])
    out = []

    def case(tag, wi, wo, r, n=Z, d=d0, s=s0):
        out.append(
            {
                "tag": tag,
                "wi": v32(wi),
                "wo": v32(wo),
                "params": {"diffuse": v32(d), "specular": v32(s), "roughness": [f32(r)], "normal": v32(n)},
            }
        )

    # Roughness at the floor: α = max(r², 1e-4) = 1e-4 (principled would use 1e-3).
    case("roughness_zero_peak", Z, Z, 0.0)
    case("roughness_zero_peak_tilted", at(0.8, 30), at(0.8, 30), 0.0, n=at(0.8, 30))
    case("roughness_zero_off_peak", at(0.9, 0), at(0.8, 180), 0.0)
    case("roughness_zero_collocated_30deg", at(math.cos(math.radians(30)), 45), at(math.cos(math.radians(30)), 45), 0.0)
    case("roughness_zero_near_peak", Z, at(math.cos(1e-3), 20), 0.0)
    case("roughness_floor_near_peak", at(0.95, 10), at(0.95, 190.05), 0.005)
    case("roughness_floor_off_peak", at(0.6, 10), at(0.7, 100), 0.005)
    case("roughness_below_principled_floor", at(0.7, 40), at(0.75, 215), 0.02)
    case("roughness_below_principled_floor_collocated", at(0.99, 40), at(0.99, 40), 0.02)
    # Roughness at the top of its range.
    case("roughness_one", at(0.6, 10), at(0.3, 150), 1.0)
    case("roughness_one_collocated", at(0.4, 70), at(0.4, 70), 1.0)
    case("roughness_one_normal_incidence", Z, Z, 1.0)
    # Grazing directions (flat normal: the local cosines are exact in float32).
    case("grazing_i_1e-6", at(1e-6, 30), at(0.7, 200), 0.5)
    case("grazing_o_1e-6", at(0.7, 200), at(1e-6, 30), 0.5)
    case("grazing_both_1e-4", at(1e-4, 0), at(1e-4, 120), 0.5)
    case("grazing_collocated_1e-3", at(1e-3, 60), at(1e-3, 60), 0.3)
    case("grazing_collocated_1e-6_rough", at(1e-6, 60), at(1e-6, 60), 1.0)
    case("grazing_i_smooth", at(1e-3, 0), at(0.5, 180), 0.15)
    case("grazing_i_1e-8", at(1e-8, 30), at(0.7, 200), 0.5)
    case("grazing_o_1e-8", at(0.7, 200), at(1e-8, 30), 0.5)
    # Grazing w.r.t. a tilted normal: the local cosine is rounded in float32 (ill-conditioned).
    case("grazing_tilted_normal", at(1e-3, 0, axis=at(0.5, 90)), at(0.6, 90), 0.4, n=at(0.5, 90))
    # On and below the horizon: exactly 0, gradients 0.
    case("horizon_i_exact", [1.0, 0.0, 0.0], at(0.7, 30), 0.5)
    case("horizon_o_exact", at(0.7, 30), [0.0, 1.0, 0.0], 0.5)
    case("below_horizon_i", at(-0.3, 10), at(0.7, 30), 0.5)
    case("below_horizon_o", at(0.7, 30), at(-0.3, 10), 0.5)
    case("below_horizon_both", at(-0.5, 10), at(-0.4, 190), 0.5)
    # Tilted normals.
    case("normal_tilted_80deg", at(0.5, 10, axis=tilted(80, 30)), at(0.4, 250, axis=tilted(80, 30)), 0.5, n=tilted(80, 30))
    case("normal_tilted_89deg", at(0.6, 70, axis=tilted(89, 200)), at(0.6, 70, axis=tilted(89, 200)), 0.3, n=tilted(89, 200))
    case("normal_backfacing_i", at(0.3, 0), at(0.9, 0), 0.5, n=tilted(80, 180))
    case("normal_backfacing_o", at(0.9, 0), at(0.3, 0), 0.5, n=tilted(80, 180))
    # Degenerate (un-normalised) normals: the model normalises, gradients scale with 1/|n|.
    case("normal_length_1e-3", at(0.8, 20), at(0.6, 160), 0.4, n=tilted(20, 45, 1e-3))
    case("normal_length_1e3", at(0.8, 20), at(0.6, 160), 0.4, n=tilted(20, 45, 1e3))
    case("normal_zero", at(0.8, 20), at(0.6, 160), 0.4, n=[0.0, 0.0, 0.0])
    case("normal_incidence", tilted(15, 80), tilted(15, 80), 0.3, n=tilted(15, 80))
    # Albedo at both ends.
    case("albedo_zero", at(0.7, 20), at(0.5, 170), 0.4, d=[0, 0, 0], s=[0, 0, 0])
    case("albedo_one", at(0.7, 20), at(0.5, 170), 0.4, d=[1, 1, 1], s=[1, 1, 1])
    case("albedo_zero_grazing", at(0.05, 20), at(0.05, 200), 0.4, d=[0, 0, 0], s=[0, 0, 0])
    return out


def extreme_aniso_cases():
    """`ggx`'s tagged extremes with α_b ≠ α_t and a tilted tangent, plus the anisotropy's own:
    equal roughnesses, one roughness at the floor and one at 1, angles 0, ½ and 1."""
    out = []
    for c in extreme_ggx_cases():
        params = dict(c["params"])
        r = params.pop("roughness")
        params["roughness_t"] = r
        params["roughness_b"] = [f32(min(1.0, 0.5 * r[0] + 0.3))]
        params["angle"] = [f32(0.3)]
        out.append({**c, "params": {name: params[name] for name, _ in GGX_ANISO_PARAMS}})
    base = {"diffuse": v32([0.2, 0.5, 0.8]), "specular": v32([0.9, 0.6, 0.04]), "normal": Z}
    for tag, rt, rb, angle, wi, wo in [
        ("aniso_isotropic", 0.4, 0.4, 0.7, at(0.8, 20), at(0.6, 160)),
        ("aniso_floor_along", 0.0, 1.0, 0.25, at(0.9, 10), at(0.7, 200)),
        ("aniso_floor_across", 1.0, 0.0, 0.25, at(0.9, 10), at(0.7, 200)),
        ("aniso_angle_zero", 0.1, 0.6, 0.0, at(0.7, 30), at(0.7, 30)),
        ("aniso_angle_half", 0.1, 0.6, 0.5, at(0.7, 30), at(0.7, 30)),
        ("aniso_angle_one", 0.1, 0.6, 1.0, at(0.7, 30), at(0.7, 30)),
        ("aniso_grazing_collocated", 0.2, 0.9, 0.4, at(1e-3, 70), at(1e-3, 70)),
    ]:
        params = {**base, "roughness_t": [f32(rt)], "roughness_b": [f32(rb)], "angle": [f32(angle)]}
        out.append(
            {"tag": tag, "wi": v32(wi), "wo": v32(wo), "params": {n: params[n] for n, _ in GGX_ANISO_PARAMS}}
        )
    tilted_n = v32(tilted(40, 30))
    params = {**base, "normal": tilted_n, "roughness_t": [f32(0.15)], "roughness_b": [f32(0.7)], "angle": [f32(0.6)]}
    out.append(
        {
            "tag": "aniso_tilted_normal",
            "wi": v32(at(0.8, 20, axis=normalize(tilted_n))),
            "wo": v32(at(0.7, 230, axis=normalize(tilted_n))),
            "params": {n: params[n] for n, _ in GGX_ANISO_PARAMS},
        }
    )
    return out


def params_of(model):
    return {"ggx": GGX_PARAMS, "blinn_phong": GGX_PARAMS, "ggx_aniso": GGX_ANISO_PARAMS, "coated": COATED_PARAMS}[model]


def extreme_coated_cases():
    d0, s0, t0 = v32([0.3, 0.1, 0.05]), v32([0.8, 0.5, 0.2]), v32([0.04, 0.04, 0.04])
    out = []

    def case(tag, wi, wo, r, r2, d=d0, s=s0, s2=t0):
        out.append(
            {
                "tag": tag,
                "wi": v32(wi),
                "wo": v32(wo),
                "params": {
                    "diffuse": v32(d),
                    "specular": v32(s),
                    "roughness": [f32(r)],
                    "specular2": v32(s2),
                    "roughness2": [f32(r2)],
                },
            }
        )

    case("roughness_zero_peak_both", Z, Z, 0.0, 0.0)
    case("roughness_zero_peak_lobe2", Z, Z, 0.6, 0.0)
    case("roughness_zero_off_peak", at(0.9, 0), at(0.8, 180), 0.0, 0.0)
    case("roughness_zero_collocated_30deg", at(math.cos(math.radians(30)), 45), at(math.cos(math.radians(30)), 45), 0.5, 0.0)
    case("roughness_zero_near_peak", Z, at(math.cos(1e-3), 20), 0.5, 0.0)
    case("roughness_floor_near_peak", at(0.95, 10), at(0.95, 190.05), 0.005, 0.005)
    case("roughness_below_principled_floor", at(0.7, 40), at(0.75, 215), 0.02, 0.3)
    case("roughness_below_principled_floor_collocated", at(0.99, 40), at(0.99, 40), 0.5, 0.02)
    case("roughness_one_both", at(0.6, 10), at(0.3, 150), 1.0, 1.0)
    case("roughness_one_collocated", at(0.4, 70), at(0.4, 70), 1.0, 0.2)
    case("roughness_one_normal_incidence", Z, Z, 1.0, 1.0)
    case("grazing_i_1e-6", at(1e-6, 30), at(0.7, 200), 0.5, 0.2)
    case("grazing_o_1e-6", at(0.7, 200), at(1e-6, 30), 0.5, 0.2)
    case("grazing_both_1e-4", at(1e-4, 0), at(1e-4, 120), 0.5, 0.2)
    case("grazing_collocated_1e-3", at(1e-3, 60), at(1e-3, 60), 0.3, 0.2)
    case("grazing_collocated_1e-6_rough", at(1e-6, 60), at(1e-6, 60), 1.0, 1.0)
    case("grazing_i_1e-8", at(1e-8, 30), at(0.7, 200), 0.5, 0.2)
    case("grazing_o_1e-8", at(0.7, 200), at(1e-8, 30), 0.5, 0.2)
    case("horizon_i_exact", [1.0, 0.0, 0.0], at(0.7, 30), 0.5, 0.2)
    case("horizon_o_exact", at(0.7, 30), [0.0, 1.0, 0.0], 0.5, 0.2)
    case("below_horizon_i", at(-0.3, 10), at(0.7, 30), 0.5, 0.2)
    case("below_horizon_o", at(0.7, 30), at(-0.3, 10), 0.5, 0.2)
    case("below_horizon_both", at(-0.5, 10), at(-0.4, 190), 0.5, 0.2)
    case("albedo_zero", at(0.7, 20), at(0.5, 170), 0.4, 0.2, d=[0, 0, 0], s=[0, 0, 0], s2=[0, 0, 0])
    case("albedo_one", at(0.7, 20), at(0.5, 170), 0.4, 0.2, d=[1, 1, 1], s=[1, 1, 1], s2=[1, 1, 1])
    case("albedo_zero_grazing", at(0.05, 20), at(0.05, 200), 0.4, 0.2, d=[0, 0, 0], s=[0, 0, 0], s2=[0, 0, 0])
    return out


# ----------------------------------------------------------------------------------------------
# BRDF cases: references


def lobes_of(model):
    if model in ("ggx", "blinn_phong", "ggx_aniso"):
        return [("specular", "roughness")]  # ggx_aniso reads roughness_t and roughness_b
    return [("specular", "roughness"), ("specular2", "roughness2")]


def principled_alpha_matters(model, params):
    """Whether principled's α floor (1e-3) differs from ours (1e-4) for some lobe of the case."""
    return any(f32(params[r][0]) ** 2 < 1e-3 for _, r in lobes_of(model))


def plugin_values(model, cases):
    """f·cos θ_o and the local cos θ_o from Mitsuba's plugins (scalar_rgb), one case at a time.
    `diffuse` + one `principled` (metallic 1) per lobe; local frame of the normalised normal."""
    mi.set_variant("scalar_rgb")
    ctx = mi.BSDFContext()
    out = []
    for c in cases:
        p = c["params"]
        n = p.get("normal", Z)
        frame = mi.Frame3f(dr.normalize(mi.Vector3f(*n)))
        wi = frame.to_local(mi.Vector3f(*c["wi"]))
        wo = frame.to_local(mi.Vector3f(*c["wo"]))
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = wi
        bsdfs = [mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": p["diffuse"]}})]
        for spec, rough in lobes_of(model):
            bsdfs.append(
                mi.load_dict(
                    {
                        "type": "principled",
                        "metallic": 1.0,
                        "base_color": {"type": "rgb", "value": p[spec]},
                        "roughness": p[rough][0],
                    }
                )
            )
        total = [0.0, 0.0, 0.0]
        for b in bsdfs:
            v = b.eval(ctx, si, wo)
            total = [t + float(v[k]) for k, t in enumerate(total)]
        out.append((total, float(wo.z)))
    return out


def composed(model, cases, alpha_floor=None, grad_channel=None, variant=None):
    """The composed model in llvm_ad_rgb, vectorised over cases; `variant` holds `ggx`'s
    non-default choices (GGX_VARIANTS).

    Returns (f_cos [3 lists], cos_o list, grads) where grads maps every input name (params plus
    "wi", "wo") to per-channel lists when `grad_channel` is given (reverse mode from the sum over
    cases of output channel `grad_channel`: cases are independent, so this is per-case)."""
    mi.set_variant("llvm_ad_rgb")
    names = [name for name, _ in params_of(model)]

    def color(key):
        return mi.Color3f(*[[c["params"][key][k] for c in cases] for k in range(3)])

    inputs = {
        "wi": mi.Vector3f(*[[c["wi"][k] for c in cases] for k in range(3)]),
        "wo": mi.Vector3f(*[[c["wo"][k] for c in cases] for k in range(3)]),
    }
    for name in names:
        if name.startswith("roughness") or name == "angle":
            inputs[name] = mi.Float([c["params"][name][0] for c in cases])
        elif name == "normal":
            inputs[name] = mi.Vector3f(*[[c["params"]["normal"][k] for c in cases] for k in range(3)])
        else:
            inputs[name] = color(name)
    if grad_channel is not None:
        for v in inputs.values():
            dr.enable_grad(v)

    wi, wo = inputs["wi"], inputs["wo"]
    if model == "ggx_aniso":
        # The tangent frame of `ggx_aniso`: t₀ = (cos πa, sin πa, 0) made perpendicular to n.
        n = dr.normalize(inputs["normal"])
        theta = inputs["angle"] * dr.pi
        t0 = mi.Vector3f(dr.cos(theta), dr.sin(theta), 0.0)
        t = dr.normalize(t0 - n * dr.dot(n, t0))
        frame = mi.Frame3f(t, dr.cross(n, t), n)
        wi, wo = frame.to_local(wi), frame.to_local(wo)
    elif "normal" in inputs:
        frame = mi.Frame3f(dr.normalize(inputs["normal"]))
        wi, wo = frame.to_local(wi), frame.to_local(wo)
    cos_i, cos_o = wi.z, wo.z
    active = (cos_i > 0) & (cos_o > 0)
    # Masked lanes divide by 1, not by a possibly zero cosine: their gradients stay finite (0).
    safe_cos_i = dr.select(active, dr.abs(cos_i), 1.0)
    value = inputs["diffuse"] * dr.inv_pi * cos_o  # Mitsuba `diffuse`
    h = dr.normalize(wi + wo)
    compatible = (dr.dot(wi, h) > 0) & (dr.dot(wo, h) > 0)
    for spec, rough in lobes_of(model):
        if model == "ggx_aniso":
            # α_u along the frame's first axis (the tangent), α_v along the bitangent.
            dist = mi.MicrofacetDistribution(
                mi.MicrofacetType.GGX, dr.square(inputs["roughness_t"]), dr.square(inputs["roughness_b"])
            )
        else:
            alpha = dr.square(inputs[rough])
            if alpha_floor is not None:
                alpha = dr.maximum(alpha, alpha_floor)  # principled's floor, emulated
            dist = mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha)  # clamps α ≥ 1e-4 itself
        D = dist.eval(h)
        shadowing = (variant or {}).get("shadowing", "separable")
        if model == "blinn_phong":
            # Normalised Blinn-Phong (e + 2)/(2π)·cos^e θ_h with e = 2/α² − 2 (Walter et al.
            # 2007, eq. 33) and the GGX floor on α; implicit masking, F = F0 (brdf-plugins'
            # blinn_phong.rs). cos^e = exp(−e/2 · ln(1 + tan²θ_h)) with tan² from the local
            # half vector's x, y (no 1 − cos² cancellation): `power(h.z, e)` in float32 is off
            # by up to 7× near the peak of an α = 1e-4 lobe (e·ulp(1) ≈ 12). Dr.Jit has no
            # log1p; this one is Goldberg 1991's `x·ln(u)/(u − 1)`, u = 1 + x, a different
            # form from photomat's series, accurate to a few ulps.
            alpha = dr.maximum(dr.square(inputs[rough]), 1e-4)
            e = 2.0 / dr.square(alpha) - 2.0
            # Masked lanes (h.z ≤ 0) only need a finite value; the floor never binds otherwise.
            tan2 = (dr.square(h.x) + dr.square(h.y)) / dr.maximum(dr.square(h.z), 1e-12)
            u = 1.0 + tan2
            exact = u == 1.0
            log1p = dr.select(exact, tan2, tan2 * dr.log(u) / dr.select(exact, 1.0, u - 1.0))
            D = (e + 2.0) * (0.5 * dr.inv_pi) * dr.exp(-0.5 * e * log1p)
            shadowing = "implicit"
            variant = {"fresnel": "constant"}
        if shadowing == "separable":
            G = dist.G(wi, wo, h)
        elif shadowing == "correlated":
            # 1/(1 + Λi + Λo) with Λ = 1/G1 − 1 (Heitz 2014, eq. 99); masked lanes use G1 = 1.
            g1_i = dr.select(active, dist.smith_g1(wi, h), 1.0)
            g1_o = dr.select(active, dist.smith_g1(wo, h), 1.0)
            G = 1.0 / (1.0 / g1_i + 1.0 / g1_o - 1.0)
        else:  # implicit: cos θ_i cos θ_o (Hoffman 2010)
            G = cos_i * cos_o
        if (variant or {}).get("fresnel", "schlick") == "schlick":
            m = dr.clip(1.0 - dr.dot(wi, h), 0.0, 1.0)
            weight = dr.square(dr.square(m)) * m  # principled's schlick_weight
            F = dr.lerp(weight, 1.0, inputs[spec])  # = F0 + (1 − F0)·weight, principled's calc_schlick
        else:  # constant: F0 at every angle
            F = inputs[spec]
        lobe = F * D * G / (4.0 * safe_cos_i)
        value = value + dr.select(compatible, lobe, 0.0)
    value = dr.select(active, value, 0.0)
    f_cos = [list(value[k]) for k in range(3)]
    grads = None
    if grad_channel is not None:
        dr.backward(value[grad_channel])
        grads = {}
        for name, v in inputs.items():
            g = dr.grad(v)
            if isinstance(g, mi.Float):
                grads[name] = [list(g)]
            else:
                grads[name] = [list(g[k]) for k in range(3)]
    return f_cos, list(cos_o), grads


def jittered(cases, rnd):
    """The cases with every input moved by up to NOISE_ULPS float32 roundoffs (zeros stay 0)."""

    def j(v):
        return [f32(x * (1.0 + rnd.uniform(-1.0, 1.0) * NOISE_ULPS * U32)) for x in v]

    return [
        {"tag": c["tag"], "wi": j(c["wi"]), "wo": j(c["wo"]), "params": {k: j(v) for k, v in c["params"].items()}}
        for c in cases
    ]


def composed_all(model, cases, variant=None):
    """Composed values and the gradients of all three output channels."""
    values, _, _ = composed(model, cases, variant=variant)
    return values, [composed(model, cases, grad_channel=c, variant=variant)[2] for c in range(3)]


def reference_noise(model, cases, values, grads, variant=None):
    """Per case, how far the float32 reference moves when its inputs move by a few roundoffs:
    (value noise relative to |f·cos θ_o|, gradient noise relative to the gradient-row norm).
    This measures what float32 can resolve of each reference, internal cancellation included."""
    names = [n for n, _ in params_of(model)]
    rnd = random.Random(f"{SEED}-{model}-noise")
    value_noise = [0.0] * len(cases)
    grad_noise = [0.0] * len(cases)
    for _ in range(NOISE_RUNS):
        v_j, g_j = composed_all(model, jittered(cases, rnd), variant)
        for i in range(len(cases)):
            for c in range(3):
                a, b = v_j[c][i], values[c][i]
                if a != b:
                    value_noise[i] = max(value_noise[i], abs(a - b) / abs(b) if b != 0 else math.inf)
                row = math.sqrt(sum(x[i] ** 2 for n in names for x in grads[c][n]))
                for n in names:
                    for x, y in zip(g_j[c][n], grads[c][n]):
                        d = abs(x[i] - y[i])
                        if not math.isfinite(d):
                            grad_noise[i] = math.inf
                        elif d > 0:
                            grad_noise[i] = max(grad_noise[i], d / row if row > 0 else math.inf)
    return value_noise, grad_noise


def reference_cases(model, cases, variant=None):
    """Fill every case with f, f·cos θ_o, gradients, float32 noise and class. A variant has no
    Mitsuba plugin: its values are the composed model's."""
    names = params_of(model)
    comp, per_channel = composed_all(model, cases, variant)
    # No Mitsuba plugin for the variants and the anisotropic model: composed values only.
    composed_only = bool(variant) or model in ("ggx_aniso", "blinn_phong")
    if composed_only:
        _, comp_cos_o, _ = composed(model, cases, variant=variant)
        plugin = [([comp[k][i] for k in range(3)], comp_cos_o[i]) for i in range(len(cases))]
    else:
        plugin = plugin_values(model, cases)
    comp_floor, _, _ = composed(model, cases, alpha_floor=1e-3)
    value_noise, grad_noise = reference_noise(model, cases, comp, per_channel, variant)
    report = {"plugin_vs_composed_max_rel": 0.0}
    out = []
    for i, c in enumerate(cases):
        (pv, cos_o) = plugin[i]
        floor_differs = not composed_only and principled_alpha_matters(model, c["params"])
        cv = [comp[k][i] for k in range(3)]
        # Cross-check: the plugin sum equals the composed model with principled's α floor.
        ref_for_plugin = [comp_floor[k][i] for k in range(3)] if floor_differs else cv
        for k in range(3):
            a, b = pv[k], ref_for_plugin[k]
            if a == b:
                continue
            rel = abs(a - b) / max(abs(b), 1e-30)
            bound = max(CROSS_REL, 4 * value_noise[i])
            if rel > bound:
                raise SystemExit(
                    f"{model} case {i} ({c['tag']}): Mitsuba plugin sum {pv} != composed {ref_for_plugin} "
                    f"(rel {rel:.3g} > {bound:.3g})"
                )
            report["plugin_vs_composed_max_rel"] = max(report["plugin_vs_composed_max_rel"], rel)
        value = cv if floor_differs or composed_only else pv
        f = [v / cos_o if cos_o > 0 else 0.0 for v in value]
        grads_finite = all(
            math.isfinite(per_channel[k][name][j][i]) for k in range(3) for name, ch in names for j in range(ch)
        )
        strict = value_noise[i] <= STRICT_NOISE and grad_noise[i] <= STRICT_NOISE and grads_finite
        if c["tag"].startswith("random") and not strict:
            raise SystemExit(
                f"{model} random case {i} is ill-conditioned in float32 (value noise {value_noise[i]:.3g}, "
                f"gradient noise {grad_noise[i]:.3g}); tighten the sampler"
            )
        grad = None
        if grads_finite:
            grad = {
                name: [[q(per_channel[k][name][j][i]) for j in range(ch)] for k in range(3)] for name, ch in names
            }
        out.append(
            {
                "tag": c["tag"],
                "class": "strict" if strict else "ill_conditioned",
                "value_source": "composed" if floor_differs or composed_only else "plugin",
                "value_noise": q(value_noise[i]) if math.isfinite(value_noise[i]) else 1.0,
                "grad_noise": q(grad_noise[i]) if math.isfinite(grad_noise[i]) else 1.0,
                "wi": ql(c["wi"]),
                "wo": ql(c["wo"]),
                "params": {name: ql(c["params"][name]) for name, _ in names},
                "f": ql(f),
                "f_cos": ql(value),
                "grad": grad,
            }
        )
    return out, report


def brdf_inputs(model):
    rnd = random.Random(f"{SEED}-{model}")
    make = {
        "ggx": random_ggx_case,
        "blinn_phong": lambda rnd, collocated: random_ggx_case(rnd, collocated, BLINN_RANDOM_ROUGHNESS_MIN),
        "ggx_aniso": random_aniso_case,
        "coated": random_coated_case,
    }[model]
    cases = [make(rnd, collocated=(i % 4 == 0)) for i in range(N_RANDOM)]
    cases += {
        "ggx": extreme_ggx_cases,
        "blinn_phong": extreme_ggx_cases,
        "ggx_aniso": extreme_aniso_cases,
        "coated": extreme_coated_cases,
    }[model]()
    return cases


def brdf_golden(model, cases, spec=None, variant=None):
    """`spec` and `variant` name one of GGX_VARIANTS (then `model` is "ggx")."""
    params = params_of(model)
    refs, report = reference_cases(model, cases, variant)
    meta = metadata(
        kind="brdf",
        model=spec or model,
        description=(
            f"Mitsuba 3 reference of photomat's `{model}`: per case the inputs (unit-ish float32 "
            "directions wi, wo in the model's world frame, parameter values), f, f·cos θ_o and "
            "the Jacobian of f·cos θ_o: grad[param][output channel][param channel]."
        ),
        params=[{"name": n, "channels": ch} for n, ch in params],
        extra={
            "normal": "normalised inside the model; gradients are w.r.t. the un-normalised vector"
            if model in ("ggx", "blinn_phong", "ggx_aniso")
            else "fixed +z (wi, wo are in the local frame)",
            "alpha": "max(roughness², 1e-4)",
            "strict_noise": STRICT_NOISE,
            "noise": f"{NOISE_RUNS} runs, inputs moved by up to {NOISE_ULPS} float32 roundoffs",
            "random_roughness_min": BLINN_RANDOM_ROUGHNESS_MIN if model == "blinn_phong" else RANDOM_ROUGHNESS_MIN,
            "plugin_vs_composed_max_rel": report["plugin_vs_composed_max_rel"],
            **({"variant": variant, "source": "composed model only (Mitsuba has no plugin)"} if variant else {}),
            **({"source": "composed in Dr.Jit (Mitsuba has no Blinn-Phong plugin)"} if model == "blinn_phong" else {}),
        },
    )
    return {"meta": meta, "cases": refs}


# ----------------------------------------------------------------------------------------------
# Height → normal (Mitsuba's bumpmap)

PROBE_REGISTERED = set()


def register_probe():
    """A BSDF that returns its shading normal as its value: nested in `bumpmap`, it reads out the
    bump-mapped frame that bumpmap hands to its nested BSDF."""
    variant = mi.variant()
    if variant in PROBE_REGISTERED:
        return

    class NormalProbe(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def eval(self, ctx, si, wo, active=True):
            n = si.sh_frame.n
            return mi.Color3f(n.x, n.y, n.z)

        def sample(self, ctx, si, sample1, sample2, active=True):
            return dr.zeros(mi.BSDFSample3f), mi.Color3f(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), mi.Float(0.0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return "NormalProbe[]"

    mi.register_bsdf("normal_probe", lambda props: NormalProbe(props))
    PROBE_REGISTERED.add(variant)


def bumpmap_normals(height, rows, cols, scale_, weights=None):
    """Normals (3 lists of rows·cols, our row order) of Mitsuba's bumpmap at every texel centre,
    as the mean of the one-sided gradients ¼ texel either side; with `weights` (3 lists) also the
    gradient of Σ weights·normal w.r.t. every height texel (our row order)."""
    mi.set_variant("llvm_ad_rgb")
    register_probe()
    # Mitsuba's texture row k covers v ∈ [k/rows, (k+1)/rows) and v grows with y: our row i
    # (row 0 at the top, +y) is texture row rows−1−i.
    flipped = [height[(rows - 1 - k) * cols + j] for k in range(rows) for j in range(cols)]
    data = mi.TensorXf(flipped, shape=(rows, cols, 1))
    bsdf = mi.load_dict(
        {
            "type": "bumpmap",
            "scale": scale_,
            "height": {"type": "bitmap", "data": data, "raw": True, "filter_type": "bilinear", "wrap_mode": "repeat"},
            "bsdf": {"type": "normal_probe"},
        }
    )
    params = mi.traverse(bsdf)
    if weights is not None:
        dr.enable_grad(params["nested_texture.data"])
        params.update()
    n_texels = rows * cols
    us, vs = [], []
    for i in range(rows):
        k = rows - 1 - i
        for j in range(cols):
            uc, vc = (j + 0.5) / cols, (k + 0.5) / rows
            du, dv = 0.25 / cols, 0.25 / rows
            us += [uc + du, uc - du, uc, uc]
            vs += [vc, vc, vc + dv, vc - dv]
    width = 4 * n_texels
    si = dr.zeros(mi.SurfaceInteraction3f, width)
    si.uv = mi.Point2f(us, vs)
    si.p = mi.Point3f(0.0)
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    si.dp_du = mi.Vector3f(1.0, 0.0, 0.0)  # the unit square: ∂p/∂u = x̂, ∂p/∂v = ŷ
    si.dp_dv = mi.Vector3f(0.0, 1.0, 0.0)
    si.wi = mi.Vector3f(0.0, 0.0, 1.0)
    probe = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.0, 0.0, 1.0))
    # n ∝ (−s·∂h/∂u, −s·∂h/∂v, 1): the scaled gradient is −n.xy / n.z.
    gu, gv = -probe[0] / probe[2], -probe[1] / probe[2]
    idx = dr.arange(mi.UInt32, n_texels) * 4
    mean_gu = 0.5 * (dr.gather(mi.Float, gu, idx) + dr.gather(mi.Float, gu, idx + 1))
    mean_gv = 0.5 * (dr.gather(mi.Float, gv, idx + 2) + dr.gather(mi.Float, gv, idx + 3))
    normal = dr.normalize(mi.Vector3f(-mean_gu, -mean_gv, 1.0))
    normals = [list(normal[k]) for k in range(3)]
    grad = None
    if weights is not None:
        loss = normal[0] * mi.Float(weights[0]) + normal[1] * mi.Float(weights[1]) + normal[2] * mi.Float(weights[2])
        dr.backward(loss)
        g = list(dr.grad(params["nested_texture.data"]).array)
        grad = [g[(rows - 1 - i) * cols + j] for i in range(rows) for j in range(cols)]
    return normals, grad


def central_difference_normals(height, rows, cols, scale_):
    """f64 central differences with wrap-around (docs/conventions.md, "Height adapter"), to
    verify the bumpmap reading."""
    out = [[], [], []]
    for i in range(rows):
        for j in range(cols):
            h = lambda r, c: height[(r % rows) * cols + (c % cols)]  # noqa: E731
            dx = (h(i, j + 1) - h(i, j - 1)) * cols / 2.0
            dy = (h(i - 1, j) - h(i + 1, j)) * rows / 2.0  # row index grows towards −y
            n = normalize([-scale_ * dx, -scale_ * dy, 1.0])
            for k in range(3):
                out[k].append(n[k])
    return out


def smooth_field(rnd, rows, cols, lo, hi, terms=3, max_freq=3):
    """A tileable random field: a sum of integer-frequency sinusoids mapped to [lo, hi]."""
    waves = [
        (rnd.randint(-max_freq, max_freq), rnd.randint(-max_freq, max_freq), rnd.uniform(0, 2 * math.pi), rnd.uniform(0.3, 1))
        for _ in range(terms)
    ]
    raw = []
    for i in range(rows):
        for j in range(cols):
            raw.append(sum(a * math.cos(2 * math.pi * (fx * j / cols + fy * i / rows) + ph) for fx, fy, ph, a in waves))
    mn, mx = min(raw), max(raw)
    span = (mx - mn) or 1.0
    return v32([lo + (hi - lo) * (x - mn) / span for x in raw])


def height_inputs():
    rnd = random.Random(f"{SEED}-height")
    specs = [
        ("smooth_16x16_scale_0.02", 16, 16, 0.02, "smooth"),
        ("smooth_16x16_scale_0.05", 16, 16, 0.05, "smooth"),
        ("noise_8x8_scale_0.05", 8, 8, 0.05, "noise"),
        ("noise_12x8_scale_0.1", 12, 8, 0.1, "noise"),  # rows ≠ cols: catches swapped axes
        ("noise_8x8_scale_1_huge_slopes", 8, 8, 1.0, "noise"),
        ("flat_8x8", 8, 8, 0.5, "flat"),
    ]
    cases = []
    for tag, rows, cols, s, kind in specs:
        if kind == "smooth":
            h = smooth_field(rnd, rows, cols, 0.0, 1.0)
        elif kind == "noise":
            h = v32([rnd.random() for _ in range(rows * cols)])
        else:
            h = v32([0.37] * (rows * cols))
        weights = [v32([rnd.uniform(-1, 1) for _ in range(rows * cols)]) for _ in range(3)]
        cases.append({"tag": tag, "rows": rows, "cols": cols, "scale": f32(s), "height": h, "weights": weights})
    return cases


def height_golden(cases):
    out = []
    worst = 0.0
    for c in cases:
        rows, cols = c["rows"], c["cols"]
        normals, grad = bumpmap_normals(c["height"], rows, cols, c["scale"], c["weights"])
        exact = central_difference_normals(c["height"], rows, cols, c["scale"])
        err = max(abs(normals[k][t] - exact[k][t]) for k in range(3) for t in range(rows * cols))
        worst = max(worst, err)
        if err > 1e-5:
            raise SystemExit(f"height case {c['tag']}: bumpmap normals differ from the central difference by {err:.3g}")
        out.append(
            {
                "tag": c["tag"],
                "rows": rows,
                "cols": cols,
                "scale": q(c["scale"]),
                "height": ql(c["height"]),
                "weights": [ql(w) for w in c["weights"]],
                "normal": [ql(n) for n in normals],
                "grad_height": ql(grad),
            }
        )
    meta = metadata(
        kind="height",
        model="height",
        description=(
            "Mitsuba 3 `bumpmap` normals of height maps on the unit square (plane side 1, world "
            "height scale·h), at every texel centre, as the mean of bumpmap's one-sided bilinear "
            "gradients ¼ texel either side (= wrap-around central differences). Maps are "
            "row-major, row 0 at the top (+y). normal[k] lists component k; grad_height is the "
            "gradient of Σ_k Σ_texels weights[k]·normal[k] w.r.t. every height texel."
        ),
        params=[{"name": "height", "channels": 1}],
        extra={"bumpmap_vs_f64_central_difference_max_abs": worst},
    )
    return {"meta": meta, "cases": out}


# ----------------------------------------------------------------------------------------------
# End-to-end renders

RENDERS = [
    # (file stem, model specification, size, highlight)
    ("render_ggx", "ggx", 32, (0.17, -0.11)),
    ("render_height_ggx", "height(ggx, scale=0.05)", 32, (0.08, 0.21)),
    ("render_coated", "coated", 32, (-0.23, 0.14)),
]


def render_inputs(stem, model, size):
    rnd = random.Random(f"{SEED}-{stem}")
    r = size
    maps = {}
    maps["diffuse"] = [smooth_field(rnd, r, r, 0.05, 0.8) for _ in range(3)]
    maps["specular"] = [smooth_field(rnd, r, r, 0.02, 0.9) for _ in range(3)]
    maps["roughness"] = [smooth_field(rnd, r, r, 0.3, 0.8)]
    if model == "ggx":
        # Components on a 2^-20 grid: the raw bitmap stores (n+1)/2 and normalmap computes 2v−1,
        # both exact in float32, so Mitsuba sees exactly the normal we do (before normalising).
        nx = [round(x * 2**20) / 2**20 for x in smooth_field(rnd, r, r, -0.5, 0.5)]
        ny = [round(x * 2**20) / 2**20 for x in smooth_field(rnd, r, r, -0.5, 0.5)]
        nz = [round(x * 2**20) / 2**20 for x in smooth_field(rnd, r, r, 0.6, 1.0)]
        maps["normal"] = [nx, ny, nz]
    elif model.startswith("height"):
        maps["height"] = [smooth_field(rnd, r, r, 0.0, 1.0)]
    else:
        maps["specular2"] = [smooth_field(rnd, r, r, 0.02, 0.3) for _ in range(3)]
        maps["roughness2"] = [smooth_field(rnd, r, r, 0.2, 0.45)]
    return maps


def render_scene(size, highlight, bsdf):
    lx, ly = highlight
    return mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
            "sensor": {
                "type": "perspective",
                "fov_axis": "x",
                # Camera at the flash, one unit above the plane: the film spans exactly the unit
                # square; the principal point is shifted (in film widths) back onto the plane.
                "fov": 2.0 * math.degrees(math.atan(0.5)),
                "principal_point_offset_x": -lx,
                "principal_point_offset_y": ly,
                "to_world": mi.ScalarTransform4f().look_at(origin=[lx, ly, 1.0], target=[lx, ly, 0.0], up=[0.0, 1.0, 0.0]),
                "sampler": {"type": "stratified", "sample_count": 1, "jitter": False},
                "film": {
                    "type": "hdrfilm",
                    "width": size,
                    "height": size,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgb",
                    "component_format": "float32",
                },
            },
            "flash": {"type": "point", "position": [lx, ly, 1.0], "intensity": {"type": "rgb", "value": [math.pi] * 3}},
            "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale([0.5, 0.5, 1.0]), "bsdf": bsdf},
        }
    )


def bitmap(channels, size):
    """Raw, nearest-filtered bitmap of our maps (row 0 at the top): texture row k = our row R−1−k."""
    r = size
    c = len(channels)
    flat = [channels[ch][(r - 1 - k) * r + j] for k in range(r) for j in range(r) for ch in range(c)]
    return {
        "type": "bitmap",
        "data": mi.TensorXf(flat, shape=(r, r, c)),
        "raw": True,
        "filter_type": "nearest",
        "wrap_mode": "clamp",
    }


def render_reference(model, size, highlight, maps):
    """Per-pixel radiance (3 lists, our row order) and, for height models, the normal map used."""
    normal = maps.get("normal")
    scale_ = None
    if model.startswith("height"):
        scale_ = float(model.split("scale=")[1].rstrip(")"))
        normal, _ = bumpmap_normals(maps["height"][0], size, size, f32(scale_))
    mi.set_variant("scalar_rgb")
    def lobes():
        yield {"type": "diffuse", "reflectance": bitmap(maps["diffuse"], size)}
        spec_pairs = [("specular", "roughness")] + ([("specular2", "roughness2")] if model == "coated" else [])
        for spec, rough in spec_pairs:
            yield {
                "type": "principled",
                "metallic": 1.0,
                "base_color": bitmap(maps[spec], size),
                "roughness": bitmap(maps[rough], size),
            }

    total = [[0.0] * (size * size) for _ in range(3)]
    for bsdf in lobes():
        if normal is not None:
            encoded = [[(x + 1.0) * 0.5 for x in normal[k]] for k in range(3)]
            bsdf = {
                "type": "normalmap",
                "normalmap": bitmap(encoded, size),
                "use_shadowing_function": False,
                "flip_invalid_normals": False,
                "bsdf": bsdf,
            }
        image = mi.render(render_scene(size, highlight, bsdf), spp=1)
        pixels = list(image.array)
        for i in range(size):
            for j in range(size):
                for k in range(3):
                    total[k][i * size + j] += pixels[(i * size + j) * 3 + k]  # image row 0 = top
    return total


def render_golden(stem, model, size, highlight, maps):
    radiance = render_reference(model, size, highlight, maps)
    meta = metadata(
        kind="render",
        model=model,
        description=(
            "Mitsuba 3 render of a textured unit plane under the collocated flash "
            "(docs/conventions.md#radiance): "
            "`direct` integrator, one unjittered sample per pixel centre, perspective camera and "
            "point light (intensity π) at (lx, ly, 1), one scene per lobe, summed. Maps and "
            "radiance are NCHW without the batch axis, flattened, row 0 at the top (+y)."
        ),
        params=[{"name": n, "channels": len(v)} for n, v in maps.items()],
        extra={"highlight": list(highlight)},
    )
    return {
        "meta": meta,
        "model": model,
        "size": size,
        "highlight": [q(highlight[0]), q(highlight[1])],
        "maps": {name: [ql(ch) for ch in chans] for name, chans in maps.items()},
        "radiance": [ql(ch) for ch in radiance],
    }


# ----------------------------------------------------------------------------------------------
# Files, metadata, drift check


def metadata(kind, model, description, params, extra):
    return {
        "kind": kind,
        "model": model,
        "description": description,
        "generator": "golden/generate.py",
        "seed": SEED,
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "python": platform.python_version(),
        "variants": {"values": "scalar_rgb", "gradients": "llvm_ad_rgb"},
        "dtype": "float32",
        "conventions": {
            "eval": "f·cos θ_o (Mitsuba BSDF::eval), 0 below the horizon of either direction",
            "directions": "wi, wo point away from the surface; f(wi, wo)·cos θ_o",
            "specular": "GGX D·F·G / (4 cos θ_i cos θ_o), separable exact Smith G1, Schlick F0 = rgb",
            "diffuse": "ρ/π",
            "plane": "side 1, centred at 0, +z up, row 0 at +y; flash/camera at (lx, ly, 1), I = π",
        },
        "params": params,
        **extra,
    }


def write(stem, data):
    path = os.path.join(HERE, f"{stem}.json")
    with open(path, "w") as fh:
        json.dump(data, fh, separators=(",", ":"))
        fh.write("\n")
    print(f"wrote {os.path.relpath(path)} ({os.path.getsize(path) // 1024} KiB)")


def load(stem):
    with open(os.path.join(HERE, f"{stem}.json")) as fh:
        return json.load(fh)


def unq(v):
    """Committed JSON numbers back to the exact float32 inputs they stand for."""
    return [f32(x) for x in v]


class Drift:
    def __init__(self):
        self.failures = []
        self.checked = 0

    def close(self, what, new, old, scale_, tol):
        self.checked += 1
        if old is None or new is None:
            if (old is None) != (new is None):
                self.failures.append(f"{what}: committed {old}, regenerated {new}")
            return
        if not math.isfinite(new) or abs(new - old) > tol * scale_:
            self.failures.append(f"{what}: committed {old!r}, regenerated {new!r} (tolerance {tol:g} × {scale_:.3g})")


def check_brdf(model, drift, stem=None, variant=None):
    stem = stem or model
    committed = load(stem)
    cases = [
        {"tag": c["tag"], "wi": unq(c["wi"]), "wo": unq(c["wo"]), "params": {k: unq(v) for k, v in c["params"].items()}}
        for c in committed["cases"]
    ]
    fresh, _ = reference_cases(model, cases, variant)
    for i, (old, new) in enumerate(zip(committed["cases"], fresh)):
        where = f"{stem}.json case {i} ({old['tag']})"
        if old["class"] != new["class"]:
            drift.failures.append(f"{where}: class {old['class']} → {new['class']}")
        value_tol = max(DRIFT_REL, DRIFT_NOISE_FACTOR * old["value_noise"])
        grad_tol = max(DRIFT_REL, DRIFT_NOISE_FACTOR * old["grad_noise"])
        for key in ("f_cos", "f"):
            for k in range(3):
                o, n = old[key][k], new[key][k]
                drift.close(f"{where} {key}[{k}]", n, o, max(abs(o or 0.0), 1e-30), value_tol)
        if (old["grad"] is None) != (new["grad"] is None):
            drift.failures.append(f"{where}: gradients finite changed")
            continue
        if old["grad"] is None:
            continue
        for k in range(3):
            row = math.sqrt(sum(g[k][j] ** 2 for g in old["grad"].values() for j in range(len(g[k]))))
            for name, g in old["grad"].items():
                for j in range(len(g[k])):
                    drift.close(
                        f"{where} d f_cos[{k}] / d {name}[{j}]",
                        new["grad"][name][k][j],
                        g[k][j],
                        max(row, 1e-30),
                        grad_tol,
                    )


def check_height(drift):
    committed = load("height")
    fresh = height_golden(
        [
            {
                "tag": c["tag"],
                "rows": c["rows"],
                "cols": c["cols"],
                "scale": f32(c["scale"]),
                "height": unq(c["height"]),
                "weights": [unq(w) for w in c["weights"]],
            }
            for c in committed["cases"]
        ]
    )
    for old, new in zip(committed["cases"], fresh["cases"]):
        for k in range(3):
            for t, (o, n) in enumerate(zip(old["normal"][k], new["normal"][k])):
                drift.close(f"height.json {old['tag']} normal[{k}][{t}]", n, o, 1.0, DRIFT_NORMAL)
        gmax = max(abs(g) for g in old["grad_height"]) or 1.0
        for t, (o, n) in enumerate(zip(old["grad_height"], new["grad_height"])):
            drift.close(f"height.json {old['tag']} grad_height[{t}]", n, o, gmax, DRIFT_REL)


def check_render(stem, drift):
    committed = load(stem)
    maps = {name: [unq(ch) for ch in chans] for name, chans in committed["maps"].items()}
    fresh = render_reference(committed["model"], committed["size"], tuple(committed["highlight"]), maps)
    for k in range(3):
        for t, (o, n) in enumerate(zip(committed["radiance"][k], fresh[k])):
            drift.close(f"{stem}.json radiance[{k}][{t}]", n, o, max(abs(o), 1e-30), DRIFT_RENDER)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=["generate", "check"])
    args = parser.parse_args()
    import_mitsuba()
    start = time.time()
    if args.mode == "generate":
        for model in ("ggx", "coated"):
            write(model, brdf_golden(model, brdf_inputs(model)))
        for stem, spec, variant in GGX_VARIANTS:
            write(stem, brdf_golden("ggx", brdf_inputs("ggx"), spec, variant))
        write("ggx_aniso", brdf_golden("ggx_aniso", brdf_inputs("ggx_aniso")))
        write("blinn_phong", brdf_golden("blinn_phong", brdf_inputs("blinn_phong")))
        write("height", height_golden(height_inputs()))
        for stem, model, size, highlight in RENDERS:
            write(stem, render_golden(stem, model, size, highlight, render_inputs(stem, model, size)))
        print(f"generated in {time.time() - start:.1f} s with mitsuba {mi.__version__}, drjit {dr.__version__}")
        return 0
    drift = Drift()
    for model in ("ggx", "coated"):
        check_brdf(model, drift)
    for stem, _, variant in GGX_VARIANTS:
        check_brdf("ggx", drift, stem, variant)
    check_brdf("ggx_aniso", drift)
    check_brdf("blinn_phong", drift)
    check_height(drift)
    for stem, _, _, _ in RENDERS:
        check_render(stem, drift)
    versions = load("ggx")["meta"]
    if (versions["mitsuba"], versions["drjit"]) != (mi.__version__, dr.__version__):
        print(
            f"note: goldens were generated with mitsuba {versions['mitsuba']} / drjit {versions['drjit']}, "
            f"checked with {mi.__version__} / {dr.__version__}"
        )
    if drift.failures:
        print(f"GOLDEN DRIFT: {len(drift.failures)} of {drift.checked} reference numbers moved:")
        for line in drift.failures[:50]:
            print("  " + line)
        if len(drift.failures) > 50:
            print(f"  … and {len(drift.failures) - 50} more")
        print("Regenerate with `golden/run.sh generate` only if the change is understood (golden/README.md).")
        return 1
    print(f"golden check: {drift.checked} reference numbers recomputed with mitsuba {mi.__version__}, "
          f"drjit {dr.__version__}: no drift ({time.time() - start:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
