"""Phone-flash photos that photomat did not make: a validation set for its highlight detectors.

Mitsuba 3 (an independent path tracer) renders planes textured with real texture photos
(scikit-image's bundled brick, grass, gravel and moon-surface photos, tinted), with a
principled BSDF and a normal map derived from the photo, lit by a point flash beside a
perspective camera. The camera pipeline then adds what phones add: auto-exposure with
clipping, vignetting, sensor noise and JPEG. None of it shares code or assumptions with
photomat's simulator (orthographic view, flash exactly above the highlight, procedural maps).

The truth is geometric: the specular peak of a flat plane z = 0 seen from camera C under a
point flash F is the mirror point P = C + t (F' - C) with F' = (Fx, Fy, -Fz) and
t = Cz / (Cz + Fz), projected through the camera. `--check` renders a near-mirror plane and
asserts that its brightest pixel is within 1 pixel of that projection.

Writes OUT/photos/NNNNNN.jpg and OUT/simulation.json in the format `photomat prepare` and
`photomat eval-detector` read (docs/datasets.md, "Highlight detectors"): per photo its true
highlight (row, col) in pixels and its texture as the family.

    validation/run.sh --count 48 --out flash-val      # then:
    photomat prepare --photos flash-val/photos --out flash-val-data --size 256
    photomat eval-detector --dataset flash-val-data
"""

import argparse
import io
import json
import math
import os
import sys

import numpy as np

SIZE = 320  # rendered side in pixels
SPP = 32  # samples per pixel: the sensor noise added afterwards dominates the Monte Carlo noise
TEXTURES = ["brick", "grass", "gravel", "moon"]
# Tints of the grey texture photos (linear rgb): fabric-red, leather-brown, stone-grey,
# paint-blue, wood-orange, moss-green.
TINTS = [
    (0.55, 0.18, 0.15),
    (0.35, 0.22, 0.12),
    (0.40, 0.40, 0.38),
    (0.15, 0.25, 0.50),
    (0.60, 0.35, 0.15),
    (0.22, 0.35, 0.15),
]


def look_at_frame(origin, target, up):
    """Mitsuba's look_at frame: columns (left, up, forward) of the camera."""
    forward = target - origin
    forward = forward / np.linalg.norm(forward)
    left = np.cross(up, forward)
    left = left / np.linalg.norm(left)
    new_up = np.cross(forward, left)
    return left, new_up, forward


def project(point, origin, frame, fov_deg, size):
    """Pixel (row, col), continuous with pixel centres at k + 0.5, of a world point seen by a
    Mitsuba perspective sensor at `origin` with look_at `frame` and horizontal `fov_deg`."""
    left, up, forward = frame
    d = point - origin
    z = d @ forward
    t = math.tan(math.radians(fov_deg) / 2)
    # Screen x grows to the camera's right (-left), y downwards (-up); both in [-1, 1].
    x = -(d @ left) / (z * t)
    y = -(d @ up) / (z * t)
    return (y + 1) / 2 * size, (x + 1) / 2 * size


def mirror_point(camera, flash):
    """The specular peak on the plane z = 0 (module docs)."""
    image = np.array([flash[0], flash[1], -flash[2]])
    t = camera[2] / (camera[2] + flash[2])
    return camera + t * (image - camera)


def texture_maps(name, tint, rng, relief):
    """(base colour in linear rgb, tangent-space normal map in [0, 1]) from a texture photo."""
    from skimage import data

    grey = getattr(data, name)().astype(np.float64) / 255.0
    # The photos are sRGB-encoded; their luminance pattern becomes albedo variation.
    linear = grey**2.2
    albedo = np.clip(linear[..., None] * np.array(tint) * 2.0, 0.0, 1.0)
    # Relief from the luminance (dark = deep), as artists derive bump maps (central
    # differences, in height units per texel).
    height = grey * relief
    gx = (np.roll(height, -1, 1) - np.roll(height, 1, 1)) / 2
    gy = (np.roll(height, -1, 0) - np.roll(height, 1, 0)) / 2
    n = np.stack([-gx, gy, np.ones_like(gx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return albedo, n * 0.5 + 0.5


def scene_dict(mi, camera, target, flash, fov, albedo, normals, roughness):
    """The Mitsuba scene of one photo."""
    T = mi.ScalarTransform4f
    principled = {
        "type": "principled",
        "base_color": {
            "type": "bitmap",
            "bitmap": mi.Bitmap(albedo.astype(np.float32)),
            "raw": True,
        },
        "roughness": roughness,
        "specular": 0.5,
    }
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {
            "type": "perspective",
            "fov": fov,
            "fov_axis": "x",
            "to_world": T().look_at(origin=camera.tolist(), target=target.tolist(), up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": SPP},
            "film": {
                "type": "hdrfilm",
                "width": SIZE,
                "height": SIZE,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
        },
        "plane": {
            "type": "rectangle",
            # 3 × 3 units: the whole view at the largest tilt and field of view, the texture
            # photo stretched over it once (no repetition seam in view).
            "to_world": T().scale([1.5, 1.5, 1.0]),
            "bsdf": {
                "type": "normalmap",
                "normalmap": {
                    "type": "bitmap",
                    "bitmap": mi.Bitmap(normals.astype(np.float32)),
                    "raw": True,
                },
                "bsdf": principled,
            },
        },
        "flash": {
            "type": "point",
            "position": flash.tolist(),
            "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
        },
    }


def develop(linear, rng, vignetting, noise, exposure, quality):
    """A phone's pipeline on a linear render: auto-exposure, vignetting, noise, sRGB, JPEG."""
    from PIL import Image

    h, w, _ = linear.shape
    # Auto-exposure puts the median at 18 % grey (times the scene's offset), the flash
    # highlight clips as it does on phones.
    img = linear * (0.18 * exposure / max(float(np.median(linear)), 1e-6))
    yy, xx = np.mgrid[0:h, 0:w]
    r2 = ((yy + 0.5 - h / 2) ** 2 + (xx + 0.5 - w / 2) ** 2) / (h * h / 2)
    img = img * (1.0 - vignetting * r2)[..., None]
    # Shot noise (variance ∝ signal) plus read noise.
    img = img + rng.normal(size=img.shape) * np.sqrt(noise * noise * (0.2 + np.clip(img, 0, 1)))
    img = np.clip(img, 0.0, 1.0)
    srgb = np.where(img <= 0.0031308, 12.92 * img, 1.055 * img ** (1 / 2.4) - 0.055)
    buf = io.BytesIO()
    Image.fromarray((srgb * 255 + 0.5).astype(np.uint8)).save(buf, "JPEG", quality=quality)
    return buf.getvalue()


def draw(rng, index):
    """The random parameters of photo `index`."""
    tilt = math.radians(rng.uniform(0, 12))
    azimuth = rng.uniform(0, 2 * math.pi)
    camera = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(0.9, 1.1)])
    down = np.array([math.sin(tilt) * math.cos(azimuth), math.sin(tilt) * math.sin(azimuth), -math.cos(tilt)])
    target = camera + down
    fov = rng.uniform(60, 75)
    frame = look_at_frame(camera, target, np.array([0.0, 1.0, 0.0]))
    # The flash sits 1–2 cm from the lens of a phone held 25–30 cm away: 0.03–0.07 of the
    # distance, in a random direction of the phone's plane.
    offset = rng.uniform(0.03, 0.07)
    angle = rng.uniform(0, 2 * math.pi)
    left, up, _ = frame
    flash = camera + offset * (math.cos(angle) * left + math.sin(angle) * up)
    return {
        "texture": TEXTURES[index % len(TEXTURES)],
        "tint": TINTS[rng.integers(len(TINTS))],
        "roughness": float(rng.uniform(0.15, 0.6)),
        "relief": float(rng.uniform(2.0, 8.0)),
        "camera": camera,
        "target": target,
        "frame": frame,
        "fov": fov,
        "flash": flash,
        "vignetting": float(rng.uniform(0.15, 0.45)),
        "noise": float(rng.uniform(0.01, 0.03)),
        "exposure": float(rng.uniform(0.7, 1.4)),
        "quality": int(rng.integers(72, 93)),
    }


def render(mi, p, rng, albedo=None, normals=None):
    """Linear rgb render (H, W, 3) of the parameters `p`."""
    if albedo is None:
        albedo, normals = texture_maps(p["texture"], p["tint"], rng, p["relief"])
    scene = mi.load_dict(
        scene_dict(mi, p["camera"], p["target"], p["flash"], p["fov"], albedo, normals, p["roughness"])
    )
    return np.array(mi.render(scene, seed=int(rng.integers(1 << 31))))


def check(mi):
    """A tilted near-mirror plane's brightest pixel is its projected mirror point."""
    rng = np.random.default_rng(7)
    worst = 0.0
    for k in range(3):
        p = draw(rng, k)
        p["roughness"] = 0.05
        flat_albedo = np.full((8, 8, 3), 0.3)
        flat_normals = np.tile(np.array([0.5, 0.5, 1.0]), (8, 8, 1))
        img = render(mi, p, rng, flat_albedo, flat_normals).sum(axis=-1)
        row, col = np.unravel_index(np.argmax(img), img.shape)
        truth = project(mirror_point(p["camera"], p["flash"]), p["camera"], p["frame"], p["fov"], SIZE)
        error = math.hypot(row + 0.5 - truth[0], col + 0.5 - truth[1])
        print(f"check {k}: brightest pixel ({row}, {col}), mirror point ({truth[0]:.1f}, {truth[1]:.1f}): {error:.2f} px")
        worst = max(worst, error)
    if worst > 1.5:
        sys.exit(f"check failed: the projection is {worst:.2f} px from the rendered peak")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=48)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", default="flash-val")
    parser.add_argument("--check", action="store_true", help="only check the truth's projection")
    args = parser.parse_args()

    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    if args.check:
        check(mi)
        return
    os.makedirs(os.path.join(args.out, "photos"), exist_ok=True)
    rng = np.random.default_rng(args.seed)
    photos = []
    for index in range(args.count):
        p = draw(rng, index)
        linear = render(mi, p, rng)
        jpeg = develop(linear, rng, p["vignetting"], p["noise"], p["exposure"], p["quality"])
        name = f"photos/{index:06}.jpg"
        with open(os.path.join(args.out, name), "wb") as f:
            f.write(jpeg)
        row, col = project(mirror_point(p["camera"], p["flash"]), p["camera"], p["frame"], p["fov"], SIZE)
        photos.append(
            {
                "photo": name,
                "family": p["texture"],
                "highlight_px": [row, col],
                "camera": {
                    "position": p["camera"].tolist(),
                    "target": p["target"].tolist(),
                    "fov_deg": p["fov"],
                    "flash": p["flash"].tolist(),
                },
                "material": {"tint": p["tint"], "roughness": p["roughness"], "relief": p["relief"]},
                "pipeline": {k: p[k] for k in ["vignetting", "noise", "exposure", "quality"]},
            }
        )
        print(f"{index + 1}/{args.count} {name} ({p['texture']}) highlight ({row:.1f}, {col:.1f})", flush=True)
    record = {
        "format": "photomat-simulation",
        "version": 1,
        "generator": "validation/render_flash_photos.py (Mitsuba 3 scalar_rgb)",
        "photos": photos,
    }
    with open(os.path.join(args.out, "simulation.json"), "w") as f:
        json.dump(record, f, indent=1)


if __name__ == "__main__":
    main()
