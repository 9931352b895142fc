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

With `--capture-set`, every photo also gets its truth maps in its own pixel grid
(OUT/truth/NNNNNN/, a photomat material folder) and linear renders under the eight held-out
flashes of `photomat capture`'s relighting (OUT/held/NNNNNN/K.exr), registered to the photo's
pixels: what `capture/examples/mitsuba_validation.rs` judges captures against
(validation/README.md, "A capture set").

With `--library LIB --split test`, the planes are textured with the materials of a photomat
material library's split instead (`photomat library import`, docs/data.md): each material's
`ggx` folder gives the base colour, the artist's normal map and the roughness (a map, or for a
material whose package gave none a roughness drawn per photo), tiled over the plane at a random
scale; the specular stays the principled BSDF's dielectric 0.04. Photo i shows material
i mod M of the split. The truth is written as for `--capture-set`.
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
# The principled BSDF's `specular` (0.5: index of refraction 1.5), and the normal-incidence
# Fresnel reflectance it means, ((1.5 − 1) / (1.5 + 1))² = 0.04: photomat's `specular` (F0).
PRINCIPLED_SPECULAR = 0.5
PRINCIPLED_F0 = 0.04
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


def texture_maps(name, tint, rng, relief, relief_source="luminance"):
    """(base colour in linear rgb, tangent-space normal map in [0, 1]) from a texture photo.

    `relief_source` "luminance" derives the heights from the texture's own luminance (dark =
    deep); "independent" from the same texture turned by 90° and shifted by half its side, so
    that the relief has the texture's kind of structure but no texel's height follows from its
    colour (a fair test of recovering relief from shading)."""
    from skimage import data

    grey = getattr(data, name)().astype(np.float64) / 255.0
    # The photos are sRGB-encoded; their luminance pattern becomes albedo variation.
    linear = grey**2.2
    albedo = np.clip(linear[..., None] * np.array(tint) * 2.0, 0.0, 1.0)
    # Relief from the luminance (dark = deep), as artists derive bump maps (central
    # differences, in height units per texel).
    if relief_source == "independent":
        turned = np.rot90(grey)
        height = np.roll(turned, (turned.shape[0] // 2, turned.shape[1] // 2), axis=(0, 1)) * relief
    else:
        height = grey * relief
    gx = (np.roll(height, -1, 1) - np.roll(height, 1, 1)) / 2
    gy = (np.roll(height, -1, 0) - np.roll(height, 1, 0)) / 2
    n = np.stack([-gx, gy, np.ones_like(gx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return albedo, n * 0.5 + 0.5


def library_materials(library, split):
    """The material folders of `split` in the library at `library` (its library.json), in index
    order."""
    with open(os.path.join(library, "library.json")) as f:
        index = json.load(f)
    return [
        (m["id"], os.path.join(library, "materials", m["id"], "ggx"))
        for m in index["materials"]
        if m["split"] == split
    ]


def read_map(folder, entry, channels):
    """One map of a photomat material folder as an (H, W, channels) array of stored values in
    [0, 1] (its PNG; a constant map's value broadcast), and whether it was a constant."""
    from PIL import Image

    if "value" in entry:
        return np.array(entry["value"], dtype=np.float64).reshape(1, 1, -1), True
    image = Image.open(os.path.join(folder, entry["png"]))
    bits = 65535.0 if image.mode.startswith("I;16") or image.mode == "I" else 255.0
    array = np.asarray(image, dtype=np.float64) / bits
    if array.ndim == 2:
        array = array[..., None]
    if array.shape[-1] == 1 and channels == 3:
        array = np.repeat(array, 3, axis=-1)
    return array[..., :channels], False


def library_maps(folder, rng):
    """(base colour in linear rgb, normal map in [0, 1], roughness (a number or (H, W, 1)))
    of a library material's `ggx` folder, flipped upside down: Mitsuba's bitmap puts row 0 at
    v = 0, the bottom of the plane, and photomat's maps have row 0 at the top (+y). The
    normals keep their components (x right, y up: the rectangle's tangent frame). A material
    whose package gave no roughness (`source.roughness.from` = default) gets one uniform in
    [0.25, 0.9], as `photomat simulate --library` draws it."""
    with open(os.path.join(folder, "material.json")) as f:
        manifest = json.load(f)
    entries = {m["name"]: m for m in manifest["maps"]}
    diffuse, _ = read_map(folder, entries["diffuse"], 3)
    normal, _ = read_map(folder, entries["normal"], 3)
    roughness, constant = read_map(folder, entries["roughness"], 1)
    size = normal.shape[0]
    # The PNG holds the albedo display-encoded (x^(1/2.2)).
    albedo = np.broadcast_to(diffuse**2.2, (size, size, 3))
    source = manifest.get("source", {}).get("roughness", {})
    if constant:
        value = float(roughness.ravel()[0])
        if source.get("from") == "default":
            value = float(rng.uniform(0.25, 0.9))
        rough = value
    else:
        rough = np.flipud(roughness)
    return np.flipud(albedo).copy(), np.flipud(normal).copy(), rough


def scene_dict(
    mi, camera, target, flash, fov, albedo, normals, roughness, principal_point=(0.0, 0.0), size=SIZE, uv_scale=1.0
):
    """The Mitsuba scene of one photo; `principal_point` is the sensor's principal point
    offset (fractions of the film's width and height, Mitsuba's convention); `roughness` a
    number or an (H, W, 1) map; the textures repeat `uv_scale` times across the plane."""
    T = mi.ScalarTransform4f

    def bitmap(array):
        return {
            "type": "bitmap",
            "bitmap": mi.Bitmap(np.ascontiguousarray(array, dtype=np.float32)),
            "raw": True,
            "to_uv": mi.ScalarTransform4f().scale([uv_scale, uv_scale, 1.0]),
        }

    principled = {
        "type": "principled",
        "base_color": bitmap(albedo),
        "roughness": roughness if np.isscalar(roughness) else bitmap(roughness),
        "specular": PRINCIPLED_SPECULAR,
    }
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {
            "type": "perspective",
            "fov": fov,
            "fov_axis": "x",
            "principal_point_offset_x": principal_point[0],
            "principal_point_offset_y": principal_point[1],
            "to_world": T().look_at(origin=camera.tolist(), target=target.tolist(), up=[0, 1, 0]),
            "sampler": {"type": "independent", "sample_count": SPP},
            "film": {
                "type": "hdrfilm",
                "width": size,
                "height": size,
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
                "normalmap": bitmap(normals),
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


def render(mi, p, rng, albedo=None, normals=None, principal_point=(0.0, 0.0), size=SIZE):
    """Linear rgb render (size, size, 3) of the parameters `p`."""
    if albedo is None:
        albedo, normals = texture_maps(p["texture"], p["tint"], rng, p["relief"])
    roughness = p.get("roughness_map", p["roughness"])
    scene = mi.load_dict(
        scene_dict(
            mi,
            p["camera"],
            p["target"],
            p["flash"],
            p["fov"],
            albedo,
            normals,
            roughness,
            principal_point,
            size,
            p.get("uv_scale", 1.0),
        )
    )
    return np.array(mi.render(scene, seed=int(rng.integers(1 << 31))))


def unproject(row, col, camera, frame, fov_deg, size):
    """Points on the plane z = 0 seen through continuous pixels (row, col) (arrays), the
    inverse of `project` for the input camera."""
    left, up, forward = frame
    t = math.tan(math.radians(fov_deg) / 2)
    x = 2 * col / size - 1
    y = 2 * row / size - 1
    d = forward[None, :] - (x * t)[:, None] * left[None, :] - (y * t)[:, None] * up[None, :]
    s = -camera[2] / d[:, 2]
    return camera[None, :] + s[:, None] * d


def bilinear(texture, u, v):
    """Mitsuba's bilinear `bitmap` lookup at uv (arrays), repeat wrap: row 0 is v = 0."""
    h, w = texture.shape[:2]
    fx = u * w - 0.5
    fy = v * h - 0.5
    x0 = np.floor(fx).astype(int)
    y0 = np.floor(fy).astype(int)
    ax = (fx - x0)[:, None]
    ay = (fy - y0)[:, None]
    at = lambda yy, xx: texture[yy % h, xx % w]
    top = at(y0, x0) * (1 - ax) + at(y0, x0 + 1) * ax
    bottom = at(y0 + 1, x0) * (1 - ax) + at(y0 + 1, x0 + 1) * ax
    return top * (1 - ay) + bottom * ay


def plane_axes(frame):
    """Tangent axes of the plane z = 0 that follow the photo: x along the image's right, y
    along its up (what a capture's normal map means), z = +z."""
    left, _, _ = frame
    right = -left
    ax = np.array([right[0], right[1], 0.0])
    ax /= np.linalg.norm(ax)
    ay = np.cross([0.0, 0.0, 1.0], ax)
    return ax, ay, np.array([0.0, 0.0, 1.0])


def truth_maps(p, albedo, normals, size, supersample=3):
    """The photographed maps in the photo's pixel grid, (size, size, ·) each: base colour
    (photomat's `diffuse`), and the normal in `plane_axes` (unit vectors), each averaged over
    supersample² points per pixel."""
    k = supersample
    rows, cols = np.mgrid[0 : size * k, 0 : size * k]
    points = unproject((rows.ravel() + 0.5) / k, (cols.ravel() + 0.5) / k, p["camera"], p["frame"], p["fov"], size)
    # The 3 × 3 rectangle's uv: (x + 1.5) / 3, (y + 1.5) / 3 (checked against Mitsuba's uv AOV).
    u = (points[:, 0] + 1.5) / 3 * p.get("uv_scale", 1.0)
    v = (points[:, 1] + 1.5) / 3 * p.get("uv_scale", 1.0)
    diffuse = bilinear(albedo, u, v)
    roughness = bilinear(p["roughness_map"], u, v) if "roughness_map" in p else None
    world = bilinear(normals * 2 - 1, u, v)
    world /= np.linalg.norm(world, axis=-1, keepdims=True)
    ax, ay, az = plane_axes(p["frame"])
    normal = np.stack([world @ ax, world @ ay, world @ az], axis=-1)

    def pool(x):
        return x.reshape(size, k, size, k, -1).mean(axis=(1, 3))

    normal = pool(normal)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    return pool(diffuse), normal, None if roughness is None else pool(roughness)


# Held-out renders: rendered HELD_SCALE× finer than the photo over a field of view
# HELD_MARGIN× wider (room for the tilt's parallax), then resampled into the photo's grid.
HELD_SCALE = 2
HELD_MARGIN = 1.1


def held_out_rigs(p, size):
    """The eight held-out flashes of a capture (photomat's `new_flash_positions`: a ring at a
    quarter of the photographed square's side around its centre), as Mitsuba rigs.

    photomat relights a capture with camera and flash together above each new highlight h_k
    (capture units: camera height 1, x right, y up). Here the whole rig (camera, flash and its
    offset from the lens) moves parallel to the sensor by D·(h_k − h₀), D the distance to the
    plane along the view axis and h₀ the photo's true highlight in capture units; the sensor's
    principal point shifts back so that the photographed region stays in view. `warp_to_photo`
    then puts every plane point back on the photo's pixel that saw it.
    """
    left, up, forward = p["frame"]
    right = -left
    t = math.tan(math.radians(p["fov"]) / 2)
    side = 2 * t  # photomat_capture::square_side of a square photo
    depth = -p["camera"][2] / forward[2]
    row0, col0 = project(mirror_point(p["camera"], p["flash"]), p["camera"], p["frame"], p["fov"], size)
    h0 = np.array([(col0 / size - 0.5) * side, (0.5 - row0 / size) * side])
    wide = 2 * math.degrees(math.atan(t * HELD_MARGIN))
    rigs = []
    for k in range(8):
        angle = k * math.pi / 4
        hk = np.array([0.25 * side * math.cos(angle), 0.25 * side * math.sin(angle)])
        a, b = depth * (hk - h0)
        shift = a * right + b * up
        # Screen coordinates of the wide sensor move by −a/(D t') and +b/(D t'); the principal
        # point (fractions of the film, Mitsuba's convention: +x shows more of the right, +y
        # more of the bottom) takes them back.
        tw = t * HELD_MARGIN
        # Where the moved rig's specular peak lands in the photo's grid, against where
        # photomat's collocated model puts it (h_k): the flash offset and the tilt move it.
        peak = project(mirror_point(p["camera"] + shift, p["flash"] + shift), p["camera"], p["frame"], p["fov"], size)
        model_px = ((0.5 - hk[1] / side) * size, (hk[0] / side + 0.5) * size)
        rigs.append(
            {
                "highlight": hk.tolist(),
                "peak_offset_px": math.hypot(peak[0] - model_px[0], peak[1] - model_px[1]),
                "camera": p["camera"] + shift,
                "target": p["target"] + shift,
                "flash": p["flash"] + shift,
                "fov": wide,
                "principal_point": (-a / (2 * depth * tw), b / (2 * depth * tw)),
            }
        )
    return rigs


def warp_to_photo(image, rig, p, size, supersample=2):
    """A held-out render (rendered by `rig`, (S, S, 3)) resampled into the photo's pixel grid:
    each photo pixel gets the mean of supersample² bilinear lookups at the projections of the
    plane points it saw (the plane induces an exact correspondence). Returns (size, size, 3)
    and the fraction of lookups that fell outside the render (clamped to its border)."""
    k = supersample
    rows, cols = np.mgrid[0 : size * k, 0 : size * k]
    points = unproject((rows.ravel() + 0.5) / k, (cols.ravel() + 0.5) / k, p["camera"], p["frame"], p["fov"], size)
    left, up, forward = p["frame"]  # the rig keeps the photo's orientation
    d = points - rig["camera"][None, :]
    z = d @ forward
    tw = math.tan(math.radians(rig["fov"]) / 2)
    x = -(d @ left) / (z * tw) - 2 * rig["principal_point"][0]
    y = -(d @ up) / (z * tw) - 2 * rig["principal_point"][1]
    n = image.shape[0]
    fc = (x + 1) / 2 * n - 0.5
    fr = (y + 1) / 2 * n - 0.5
    outside = float(np.mean((fc < 0) | (fc > n - 1) | (fr < 0) | (fr > n - 1)))
    fc = np.clip(fc, 0, n - 1.001)
    fr = np.clip(fr, 0, n - 1.001)
    c0 = fc.astype(int)
    r0 = fr.astype(int)
    ac = (fc - c0)[:, None]
    ar = (fr - r0)[:, None]
    top = image[r0, c0] * (1 - ac) + image[r0, c0 + 1] * ac
    bottom = image[r0 + 1, c0] * (1 - ac) + image[r0 + 1, c0 + 1] * ac
    values = top * (1 - ar) + bottom * ar
    return values.reshape(size, k, size, k, 3).mean(axis=(1, 3)), outside


def write_exr(mi, path, array):
    """A float32 EXR of an (H, W, C) array, C = 1 (channel Y) or 3 (R, G, B)."""
    fmt = mi.Bitmap.PixelFormat.Y if array.shape[-1] == 1 else mi.Bitmap.PixelFormat.RGB
    mi.Bitmap(np.ascontiguousarray(array, dtype=np.float32), fmt).write(path)


def write_truth(mi, folder, diffuse, normal, roughness, specular):
    """The truth as a photomat material folder of model `ggx` (docs/datasets.md): EXR maps and
    material.json; specular is the principled BSDF's constant, roughness a constant or an
    (H, W, 1) map."""
    os.makedirs(folder, exist_ok=True)
    size = diffuse.shape[0]
    write_exr(mi, os.path.join(folder, "diffuse.exr"), diffuse)
    write_exr(mi, os.path.join(folder, "normal.exr"), normal)
    if np.isscalar(roughness):
        rough_entry = {"value": [roughness]}
    else:
        write_exr(mi, os.path.join(folder, "roughness.exr"), roughness)
        rough_entry = {"exr": "roughness.exr"}
    entry = lambda name, space, lo, **kw: {
        "name": name, "channels": 1 if name == "roughness" else 3, "color_space": space, "range": [lo, 1.0], **kw
    }
    manifest = {
        "format": "photomat-material",
        "version": 1,
        "brdf": "ggx",
        "resolution": size,
        "maps": [
            entry("diffuse", "gamma22", 0.0, exr="diffuse.exr"),
            entry("specular", "gamma22", 0.0, value=[specular] * 3),
            entry("roughness", "linear", 0.0, **rough_entry),
            entry("normal", "unit-vector", -1.0, exr="normal.exr"),
        ],
    }
    with open(os.path.join(folder, "material.json"), "w") as f:
        json.dump(manifest, f, indent=1)


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
    parser.add_argument(
        "--capture-set",
        action="store_true",
        help="also write each photo's truth maps (truth/NNNNNN/, a photomat ggx material in the photo's "
        "pixel grid) and its renders under the 8 held-out flashes of photomat capture (held/NNNNNN/K.exr, "
        "linear, without the phone's pipeline)",
    )
    parser.add_argument(
        "--library",
        help="a photomat material library: texture the planes with the materials of --split (ggx maps, "
        "the artist's normals) instead of scikit-image's photos",
    )
    parser.add_argument("--split", default="test", choices=["train", "validation", "test"])
    parser.add_argument(
        "--relief-source",
        choices=["luminance", "independent"],
        default="luminance",
        help="heights from the texture's luminance (dark = deep, as artists derive bump maps) or from the "
        "texture turned by 90° and shifted (independent of the colour: texture_maps)",
    )
    args = parser.parse_args()

    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    if args.check:
        check(mi)
        return
    os.makedirs(os.path.join(args.out, "photos"), exist_ok=True)
    rng = np.random.default_rng(args.seed)
    materials = library_materials(args.library, args.split) if args.library else None
    if materials is not None and not materials:
        sys.exit(f"{args.library} has no {args.split} materials")
    photos = []
    for index in range(args.count):
        p = draw(rng, index)
        if materials is not None:
            material_id, folder = materials[index % len(materials)]
            albedo, normals, rough = library_maps(folder, rng)
            p["texture"] = material_id
            if np.isscalar(rough):
                p["roughness"] = rough
            else:
                p["roughness_map"] = rough
                p["roughness"] = float(rough.mean())
            # The material spans 2/z of the photo's square (camera height ~1), z in [0.5, 1.5]
            # as `photomat simulate --library`: 1.5·z repeats over the 3-unit plane.
            p["uv_scale"] = 1.5 * float(np.exp(rng.uniform(np.log(0.5), np.log(1.5))))
        else:
            albedo, normals = texture_maps(p["texture"], p["tint"], rng, p["relief"], args.relief_source)
        linear = render(mi, p, rng, albedo, normals)
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
                "material": {
                    "tint": p["tint"],
                    "roughness": p["roughness"],
                    "relief": p["relief"],
                    "relief_source": args.relief_source,
                }
                if materials is None
                else {"library": args.library, "id": p["texture"], "roughness": p["roughness"], "uv_scale": p["uv_scale"]},
                "pipeline": {k: p[k] for k in ["vignetting", "noise", "exposure", "quality"]},
            }
        )
        if args.capture_set:
            truth = f"truth/{index:06}"
            diffuse, normal, rough_map = truth_maps(p, albedo, normals, SIZE)
            rough_truth = p["roughness"] if rough_map is None else rough_map
            write_truth(mi, os.path.join(args.out, truth), diffuse, normal, rough_truth, PRINCIPLED_F0)
            # Its own stream, so that the photos are the same with and without --capture-set.
            held_rng = np.random.default_rng([args.seed, index])
            held = []
            for k, rig in enumerate(held_out_rigs(p, SIZE)):
                q = dict(p, camera=rig["camera"], target=rig["target"], flash=rig["flash"], fov=rig["fov"])
                wide = render(mi, q, held_rng, albedo, normals, rig["principal_point"], HELD_SCALE * SIZE)
                image, outside = warp_to_photo(wide, rig, p, SIZE)
                name_k = f"held/{index:06}/{k}.exr"
                os.makedirs(os.path.dirname(os.path.join(args.out, name_k)), exist_ok=True)
                write_exr(mi, os.path.join(args.out, name_k), image)
                held.append(
                    {
                        "render": name_k,
                        "highlight": rig["highlight"],
                        "peak_offset_px": rig["peak_offset_px"],
                        "outside": outside,
                    }
                )
            photos[-1]["truth"] = truth
            photos[-1]["held_out"] = held
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
