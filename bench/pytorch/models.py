"""photomat's networks rebuilt in plain PyTorch, for side-by-side CPU timings.

Each module mirrors the Rust module named in its docstring layer for layer, so that both
sides run the same operator graph (same convolutions at the same shapes, same resampling
filters, same activations) and have exactly the same number of trainable parameters
(`bench_steps.py` prints the counts; `compare.py` asserts they are equal):

- G  (`generator/src/{mapping,synthesis,modulated_conv,noise,fir}.rs`): StyleGAN2 "skip"
  generator (Karras et al. 2020, Fig. 7; StyleGAN2-ADA) whose toRGB layers output the 32
  feature channels of PhotoMat's neural material; mapping depth 2; modulated 3x3 convs with
  demodulation in StyleGAN2's non-fused form (`x * s`, conv, `* d`); per-pixel noise; FIR
  [1,3,3,1] upsampling *before* the 3x3 conv (the Rust order, see synthesis.rs).
- M  (`generator/src/relight.rs`): per-texel MLP 35 -> 64 x 7 -> 3 on (B*H*W, C) rows.
- D  (`generator/src/discriminator.rs`): StyleGAN2 residual discriminator on RGB || omega
  (6 channels) with minibatch standard deviation (group 4, 1 channel).
- E  (`estimator/src/{unet,conv,upsample}.rs`; docs/neural-models.md, "Map estimator E"): UNet
  32->32->64->128->256->256->256->128->64->32->n with circular padding and periodic bilinear x2
  upsampling.
- the `height(ggx)` decode and the collocated-flash render (`core/src/{param,lobes,
  microfacet,shading,render,flash}.rs`, `brdf-plugins/src/{ggx,height}.rs`).

"Plain PyTorch" means what a PyTorch user runs on a CPU: `torch.nn.functional` ops in fp32,
no `torch.compile`, no custom kernels. FIR resampling uses StyleGAN2-ADA's reference
`upfirdn2d` path (zero-stuffing, padding and a depthwise 4x4 `conv2d`), the path that code
takes on a CPU (its fused kernel is CUDA-only).

Initial values follow the Rust side's distributions only loosely (timings do not depend
on them); shapes and parameter counts are exact.

# Shapes
NCHW throughout: features F (B, 32, R, R), images and omega (B, 3, R, R), maps (B, n, R, R).
"""

import math

import torch
import torch.nn.functional as F
from torch import nn

LRELU_SLOPE = 0.2  # StyleGAN2 `lrelu` (generator/src/activation.rs)
LRELU_GAIN = math.sqrt(2.0)
Z_NORM_EPS = 1e-8  # mapping.rs: RMS normalisation of z
DEMOD_EPS = 1e-8  # modulated_conv.rs: StyleGAN2 eq. 3
MBSTD_EPS = 1e-8  # discriminator.rs
RESIDUAL_GAIN = math.sqrt(0.5)  # discriminator.rs: residual branches' gain
FIR = torch.tensor([1.0, 3.0, 3.0, 1.0])
BASE_RESOLUTION = 4
MAX_CHANNELS = 512


def lrelu(x):
    """StyleGAN2's `lrelu`: sqrt(2) * LeakyReLU(x, 0.2)."""
    return F.leaky_relu(x, LRELU_SLOPE) * LRELU_GAIN


def channels_at(resolution, res, multiplier):
    """generator/src/lib.rs `GeneratorConfig::channels_at`."""
    base = 32768 if resolution >= 512 else 16384
    full = min(base // res, MAX_CHANNELS)
    return max(1, int(round(full * multiplier)))


# ---------------------------------------------------------------------------------------
# FIR resampling: StyleGAN2-ADA `upfirdn2d._upfirdn2d_ref`, 2-D [1,3,3,1] filter.
# ---------------------------------------------------------------------------------------


def _fir2d(gain):
    f = FIR / FIR.sum()
    return torch.outer(f, f) * gain


def upfirdn2d(x, f, up=1, down=1, pad=(0, 0, 0, 0)):
    """Upsample by zero insertion, pad, depthwise FIR, decimate (StyleGAN2-ADA reference)."""
    b, c, h, w = x.shape
    if up > 1:
        x = x.reshape(b, c, h, 1, w, 1)
        x = F.pad(x, [0, up - 1, 0, 0, 0, up - 1])
        x = x.reshape(b, c, h * up, w * up)
    x = F.pad(x, list(pad))
    weight = f.flip([0, 1])[None, None].repeat(c, 1, 1, 1).to(x.dtype)
    x = F.conv2d(x, weight, groups=c)
    if down > 1:
        x = x[:, :, ::down, ::down]
    return x


FIR_UP = _fir2d(4.0)  # gain up^2: rows/columns of the zero-stuffed signal sum to 2 per axis
FIR_DOWN = _fir2d(1.0)


def upsample2d(x):
    """x2 FIR upsampling, paddings (2, 1) per axis (fir.rs `upsample2d`)."""
    return upfirdn2d(x, FIR_UP, up=2, pad=(2, 1, 2, 1))


def downsample2d(x):
    """x2 FIR downsampling, paddings (1, 1) (fir.rs `downsample2d`)."""
    return upfirdn2d(x, FIR_DOWN, down=2, pad=(1, 1, 1, 1))


def blur_for_strided_conv(x):
    """The blur before a stride-2 3x3 conv, paddings (2, 2): (H, W) -> (H+1, W+1)."""
    return upfirdn2d(x, FIR_DOWN, pad=(2, 2, 2, 2))


# ---------------------------------------------------------------------------------------
# Equalised-learning-rate layers (equalized.rs)
# ---------------------------------------------------------------------------------------


class EqualizedLinear(nn.Module):
    """y = x (lr/sqrt(in) W)^T + lr b; weight (out, in), bias (out)."""

    def __init__(self, fan_in, fan_out, lr_multiplier=1.0, bias_init=0.0, bias=True):
        super().__init__()
        self.weight = nn.Parameter(torch.randn(fan_out, fan_in) / lr_multiplier)
        self.bias = nn.Parameter(torch.full((fan_out,), float(bias_init))) if bias else None
        self.weight_gain = lr_multiplier / math.sqrt(fan_in)
        self.bias_gain = lr_multiplier

    def forward(self, x):
        b = None if self.bias is None else self.bias * self.bias_gain
        return F.linear(x, self.weight * self.weight_gain, b)


class EqualizedConv2d(nn.Module):
    """k x k conv, weight gain 1/sqrt(in k^2); padding and resampling by the caller."""

    def __init__(self, c_in, c_out, k, bias=True):
        super().__init__()
        self.weight = nn.Parameter(torch.randn(c_out, c_in, k, k))
        self.bias = nn.Parameter(torch.zeros(c_out)) if bias else None
        self.weight_gain = 1.0 / math.sqrt(c_in * k * k)

    def forward(self, x, stride=1, padding=0):
        return F.conv2d(x, self.weight * self.weight_gain, self.bias, stride, padding)


# ---------------------------------------------------------------------------------------
# G: mapping + synthesis (mapping.rs, synthesis.rs, modulated_conv.rs, noise.rs)
# ---------------------------------------------------------------------------------------


class Mapping(nn.Module):
    def __init__(self, latent_dim, depth, lr_multiplier=0.01):
        super().__init__()
        self.layers = nn.ModuleList(
            EqualizedLinear(latent_dim, latent_dim, lr_multiplier) for _ in range(depth)
        )
        self.register_buffer("w_avg", torch.zeros(latent_dim))

    def forward(self, z):
        x = z * (z.square().mean(dim=1, keepdim=True) + Z_NORM_EPS).rsqrt()
        for layer in self.layers:
            x = lrelu(layer(x))
        return x


class ModulatedConv2d(nn.Module):
    """StyleGAN2 modulated conv, non-fused: d * conv(x * s, W) (modulated_conv.rs)."""

    def __init__(self, c_in, c_out, k, w_dim, demodulate):
        super().__init__()
        self.affine = EqualizedLinear(w_dim, c_in, bias_init=1.0)
        self.weight = nn.Parameter(torch.randn(c_out, c_in, k, k))
        self.demodulate = demodulate
        self.style_gain = 1.0 if demodulate else 1.0 / math.sqrt(c_in * k * k)
        self.padding = k // 2

    def forward(self, x, w):
        s = self.affine(w) * self.style_gain
        y = F.conv2d(x * s[:, :, None, None], self.weight, padding=self.padding)
        if self.demodulate:
            w2 = self.weight.square().sum(dim=[2, 3])
            d = (s.square() @ w2.t() + DEMOD_EPS).rsqrt()
            y = y * d[:, :, None, None]
        return y


class SynthesisLayer(nn.Module):
    """(FIR x2 up,) modulated 3x3 conv, noise, bias, lrelu."""

    def __init__(self, c_in, c_out, w_dim, up):
        super().__init__()
        self.conv = ModulatedConv2d(c_in, c_out, 3, w_dim, True)
        self.noise_strength = nn.Parameter(torch.zeros(1))
        self.bias = nn.Parameter(torch.zeros(c_out))
        self.up = up

    def forward(self, x, w, noise):
        if self.up:
            x = upsample2d(x)
        y = self.conv(x, w)
        y = y + noise * self.noise_strength
        return lrelu(y + self.bias[None, :, None, None])


class ToFeatures(nn.Module):
    """1x1 modulated conv without demodulation, plus bias (StyleGAN2 toRGB, 32 outputs)."""

    def __init__(self, c_in, c_out, w_dim):
        super().__init__()
        self.conv = ModulatedConv2d(c_in, c_out, 1, w_dim, False)
        self.bias = nn.Parameter(torch.zeros(c_out))

    def forward(self, x, w):
        return self.conv(x, w) + self.bias[None, :, None, None]


class SynthesisBlock(nn.Module):
    def __init__(self, res, c_in, c, w_dim, feature_channels):
        super().__init__()
        self.res = res
        if res == BASE_RESOLUTION:
            self.const = nn.Parameter(torch.randn(c, res, res))
            self.conv0 = None
        else:
            self.const = None
            self.conv0 = SynthesisLayer(c_in, c, w_dim, up=True)
        self.conv1 = SynthesisLayer(c, c, w_dim, up=False)
        self.tofeat = ToFeatures(c, feature_channels, w_dim)

    def num_conv(self):
        return 1 if self.conv0 is None else 2

    def forward(self, x, img, ws, noises):
        if self.const is not None:
            x = self.const[None].repeat(ws.shape[0], 1, 1, 1)
        i = 0
        if self.conv0 is not None:
            x = self.conv0(x, ws[:, i], noises[i])
            i += 1
        x = self.conv1(x, ws[:, i], noises[i])
        y = self.tofeat(x, ws[:, i + 1])
        img = y if img is None else upsample2d(img) + y
        return x, img


class Generator(nn.Module):
    """z -> F (B, feature_channels, R, R)."""

    def __init__(self, resolution, multiplier, latent_dim=512, mapping_depth=2,
                 feature_channels=32):
        super().__init__()
        self.mapping = Mapping(latent_dim, mapping_depth)
        blocks = []
        res = BASE_RESOLUTION
        while res <= resolution:
            c = channels_at(resolution, res, multiplier)
            c_in = channels_at(resolution, res // 2, multiplier)
            blocks.append(SynthesisBlock(res, c_in, c, latent_dim, feature_channels))
            res *= 2
        self.blocks = nn.ModuleList(blocks)
        self.num_ws = 2 * len(blocks)

    def noise_shapes(self, batch):
        return [(batch, 1, b.res, b.res) for b in self.blocks for _ in range(b.num_conv())]

    def forward(self, z, noises):
        w = self.mapping(z)
        ws = w[:, None].expand(-1, self.num_ws, -1)
        x = img = None
        wi = ni = 0
        for block in self.blocks:
            nc = block.num_conv()
            x, img = block(x, img, ws[:, wi:wi + nc + 1], noises[ni:ni + nc])
            wi += nc
            ni += nc
        return img


# ---------------------------------------------------------------------------------------
# M (relight.rs)
# ---------------------------------------------------------------------------------------


class Relight(nn.Module):
    """Per-texel MLP F || omega -> RGB on (B*H*W, C) rows."""

    def __init__(self, feature_channels=32, hidden=64, layers=8, lr_multiplier=0.01):
        super().__init__()
        dims = [feature_channels + 3] + [hidden] * (layers - 1) + [3]
        self.layers = nn.ModuleList(
            EqualizedLinear(dims[i], dims[i + 1], lr_multiplier) for i in range(layers)
        )

    def forward_rows(self, x):
        last = len(self.layers) - 1
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < last:
                x = lrelu(x)
        return x

    def forward(self, features, omega):
        b, c, h, w = features.shape
        rows = torch.cat([features, omega], 1).permute(0, 2, 3, 1).reshape(b * h * w, c + 3)
        return self.forward_rows(rows).reshape(b, h, w, 3).permute(0, 3, 1, 2).contiguous()


# ---------------------------------------------------------------------------------------
# D (discriminator.rs)
# ---------------------------------------------------------------------------------------


class DConv(nn.Module):
    """StyleGAN2 `Conv2dLayer`: conv (optionally down x2), bias, optional lrelu, gain."""

    def __init__(self, c_in, c_out, k, bias, activate, down, gain):
        super().__init__()
        self.conv = EqualizedConv2d(c_in, c_out, k, bias)
        self.k, self.activate, self.down, self.gain = k, activate, down, gain

    def forward(self, x):
        if not self.down:
            y = self.conv(x, padding=self.k // 2)
        elif self.k == 1:
            y = self.conv(downsample2d(x))
        else:
            y = self.conv(blur_for_strided_conv(x), stride=2)
        if self.activate:
            y = lrelu(y)
        return y * self.gain if self.gain != 1.0 else y


class DBlock(nn.Module):
    def __init__(self, c, c_out, fromrgb_channels):
        super().__init__()
        self.fromrgb = (
            DConv(fromrgb_channels, c, 1, True, True, False, 1.0) if fromrgb_channels else None
        )
        self.conv0 = DConv(c, c, 3, True, True, False, 1.0)
        self.conv1 = DConv(c, c_out, 3, True, True, True, RESIDUAL_GAIN)
        self.skip = DConv(c, c_out, 1, False, False, True, RESIDUAL_GAIN)

    def forward(self, x):
        if self.fromrgb is not None:
            x = self.fromrgb(x)
        return self.skip(x) + self.conv1(self.conv0(x))


def minibatch_stddev(x, group_size=4, channels=1):
    """StyleGAN2-ADA `MinibatchStdLayer` (sample n in group n mod (B/G))."""
    b, c, h, w = x.shape
    g = min(group_size, b)
    y = x.reshape(g, -1, channels, c // channels, h, w)
    y = y - y.mean(dim=0)
    y = (y.square().mean(dim=0) + MBSTD_EPS).sqrt()
    y = y.mean(dim=[2, 3, 4]).reshape(-1, channels, 1, 1).repeat(g, 1, h, w)
    return torch.cat([x, y], 1)


class Discriminator(nn.Module):
    """(image, omega) (B, 3, R, R) x 2 -> logits (B, 1)."""

    def __init__(self, resolution, multiplier, mbstd_group=4, mbstd_channels=1):
        super().__init__()
        blocks = []
        res = resolution
        while res > BASE_RESOLUTION:
            c, c_out = channels_at(resolution, res, multiplier), channels_at(
                resolution, res // 2, multiplier)
            blocks.append(DBlock(c, c_out, 6 if res == resolution else 0))
            res //= 2
        self.blocks = nn.ModuleList(blocks)
        c4 = channels_at(resolution, BASE_RESOLUTION, multiplier)
        self.conv = DConv(c4 + mbstd_channels, c4, 3, True, True, False, 1.0)
        self.fc = EqualizedLinear(c4 * BASE_RESOLUTION**2, c4)
        self.out = EqualizedLinear(c4, 1)
        self.mbstd_group, self.mbstd_channels = mbstd_group, mbstd_channels

    def forward(self, image, omega):
        x = torch.cat([image, omega], 1)
        for block in self.blocks:
            x = block(x)
        x = minibatch_stddev(x, self.mbstd_group, self.mbstd_channels)
        x = self.conv(x)
        x = lrelu(self.fc(x.flatten(1)))
        return self.out(x)


def r1_penalty(d, image, omega):
    """Per-sample ||grad_x D(x, omega)||^2 with its graph kept (discriminator.rs)."""
    x = image.detach().requires_grad_(True)
    logits = d(x, omega)
    (gx,) = torch.autograd.grad(logits.sum(), x, create_graph=True)
    return gx.square().flatten(1).sum(1)


# ---------------------------------------------------------------------------------------
# E (unet.rs, conv.rs, upsample.rs)
# ---------------------------------------------------------------------------------------


class CircularConv2d(nn.Module):
    """Circular padding (k - s)/2, then an unpadded conv with stride s."""

    def __init__(self, c_in, c_out, k, stride):
        super().__init__()
        self.conv = nn.Conv2d(c_in, c_out, k, stride)
        self.pad = (k - stride) // 2

    def forward(self, x):
        p = self.pad
        return self.conv(F.pad(x, (p, p, p, p), mode="circular") if p else x)


def upsample2x_periodic(x):
    """x2 bilinear (align_corners=False) of the periodically extended image."""
    y = F.interpolate(F.pad(x, (1, 1, 1, 1), mode="circular"), scale_factor=2,
                      mode="bilinear", align_corners=False)
    return y[:, :, 2:-2, 2:-2]


class Estimator(nn.Module):
    """The UNet E: F (B, 32, H, W) -> raw pre-tanh maps (B, n, H, W)."""

    def __init__(self, in_channels=32, encoder=(32, 64, 128, 256, 256),
                 decoder=(256, 128, 64, 32), out_channels=8, slope=0.01):
        super().__init__()
        self.slope = slope
        self.enc = nn.ModuleList()
        c = in_channels
        for e in encoder:
            self.enc.append(nn.ModuleList([CircularConv2d(c, e, 4, 2), CircularConv2d(e, e, 3, 1)]))
            c = e
        self.dec = nn.ModuleList()
        for j, d in enumerate(decoder):
            skip = encoder[len(encoder) - 2 - j]
            self.dec.append(nn.ModuleList([CircularConv2d(c + skip, d, 3, 1),
                                           CircularConv2d(d, d, 3, 1)]))
            c = d
        self.head = CircularConv2d(c, out_channels, 3, 1)

    def forward(self, x):
        act = lambda t: F.leaky_relu(t, self.slope)  # noqa: E731
        skips = []
        for down, conv in self.enc:
            x = act(conv(act(down(x))))
            skips.append(x)
        for (conv1, conv2), skip in zip(self.dec, reversed(skips[:-1])):
            x = torch.cat([upsample2x_periodic(x), skip], 1)
            x = act(conv2(act(conv1(x))))
        return self.head(upsample2x_periodic(x))


# ---------------------------------------------------------------------------------------
# height(ggx): decode and collocated-flash render (core/, brdf-plugins/)
# ---------------------------------------------------------------------------------------

HEIGHT_SCALE = 0.02  # height.rs default `scale`
ALPHA_MIN = 1e-4  # microfacet.rs
NORM_SQ_FLOOR = 1e-24  # vecops.rs
ENCODE_FLOOR = 1e-6  # render.rs
DISPLAY_GAMMA = 2.2


def decode_height_ggx(raw):
    """raw (B, 8, H, W) -> diffuse, specular (gamma 2.2), roughness, height (linear)."""
    unit = (torch.tanh(raw) + 1.0) * 0.5
    return {
        "diffuse": unit[:, 0:3].pow(2.2),
        "specular": unit[:, 3:6].pow(2.2),
        "roughness": unit[:, 6:7],
        "height": unit[:, 7:8],
    }


def _normalize3(v):
    return v / v.square().sum(1, keepdim=True).clamp_min(NORM_SQ_FLOOR).sqrt()


def _dot3(a, b):
    return (a * b).sum(1, keepdim=True)


def _cross3(a, b):
    ax, ay, az = a[:, 0:1], a[:, 1:2], a[:, 2:3]
    bx, by, bz = b[:, 0:1], b[:, 1:2], b[:, 2:3]
    return torch.cat([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], 1)


def height_normals(height, scale=HEIGHT_SCALE):
    """Wrap-around central differences on the unit square (height.rs)."""
    rows, cols = height.shape[2], height.shape[3]
    gx = (height.roll(-1, 3) - height.roll(1, 3)) * (cols / 2.0)
    gy = (height.roll(1, 2) - height.roll(-1, 2)) * (rows / 2.0)
    nx, ny = gx * -scale, gy * -scale
    return _normalize3(torch.cat([nx, ny, torch.ones_like(nx)], 1))


def eval_height_ggx(omega, maps):
    """f cos(theta_o) of Lambert + GGX at wi = wo = omega (lobes.rs, microfacet.rs)."""
    n = _normalize3(height_normals(maps["height"]))
    raw = _dot3(n, omega)
    mask = (raw > 0).to(raw.dtype)
    cos = raw.clamp_min(0.0)
    h = _normalize3(omega + omega)
    cos_h = _dot3(n, h)
    sin2_h = _cross3(n, h).square().sum(1, keepdim=True)
    cos_d = _dot3(omega, h)
    diffuse = maps["diffuse"] * (cos * mask / math.pi)
    alpha2 = maps["roughness"].square().clamp_min(ALPHA_MIN).square()
    inner = (sin2_h / alpha2 + cos_h.square()).clamp_min(0.5)
    d = 1.0 / (alpha2 * inner.square() * math.pi)
    denom = cos + (cos.square() * (1.0 - alpha2) + alpha2).sqrt()
    g1_o = cos * 2.0 / denom
    g1_i_over_cos = 2.0 / denom
    scalar = d * g1_o * g1_i_over_cos * 0.25 * mask
    f0 = maps["specular"]
    fresnel = f0 + (1.0 - f0) * (1.0 - cos_d.clamp(0.0, 1.0)).pow(5.0)
    return diffuse + fresnel * scalar


def flash_geometry(highlights, size):
    """omega (B, 3, R, R) and 1/d^2 (B, 1, R, R) for flashes at (x, y, 1) (flash.rs)."""
    centres = (torch.arange(size, dtype=torch.float64) + 0.5) / size - 0.5
    px = centres[None, :].expand(size, size)
    py = -centres[:, None].expand(size, size)
    omegas, inv = [], []
    for x, y in highlights:
        v = torch.stack([x - px, y - py, torch.ones_like(px)])
        d2 = v.square().sum(0, keepdim=True)
        omegas.append(v / d2.sqrt())
        inv.append(1.0 / d2)
    return torch.stack(omegas).float(), torch.stack(inv).float()


def render_encoded(maps, omega, inv_dist2):
    """Display-encoded render clamp(x, 1e-6, 1)^(1/2.2) of pi f cos / d^2 (render.rs)."""
    radiance = eval_height_ggx(omega, maps) * inv_dist2 * math.pi
    return radiance.clamp(ENCODE_FLOOR, 1.0).pow(1.0 / DISPLAY_GAMMA)


def count_parameters(module):
    """Trainable scalars (buffers such as w_avg excluded)."""
    return sum(p.numel() for p in module.parameters())
