"""The Python module's values against independent references computed here with numpy or
in closed form, one family at a time: convolve (a direct 2-D convolution), the resample
family (block means, linear interpolation at the documented pixel centres, constants),
defocus (the thin-lens CoC formula, a disk blur by exact pixel areas, energy), the deep
nodes (OpenEXR's front-to-back "over" and its merge and split rules), compare (the RMSE /
PSNR / max definitions of docs/methods/metrics.md), lens_distort (the radial models and
bilinear sampling of docs/methods/distortion.md) and scene (its documented depths,
camera, alpha, and its deep render's flatten).

test_openbokeh.py compares the module with bokehtool, which runs the same C++ code, so it
cannot see a wrong answer; these tests can. No expected value here comes from the module
or from bokehtool: the module only makes the inputs (a scene) and the results under test.
Each tolerance says why it is that size.

Run by run_tests.py from ctest with PYTHONPATH set to the built module.
"""
import numpy as np
import OpenImageIO as oiio
import pytest

import openbokeh as ob

# --- numpy references -------------------------------------------------------------------


def np_convolve(img, kernel, mode):
    """Direct 2-D convolution out(x, y) = sum_d k(d) in(x - dx, y - dy), the kernel's centre
    at (kw // 2, kh // 2) (blur.h: the data window's pixel xbegin + width / 2), so d =
    (j - kw // 2, i - kh // 2) for kernel[i, j]; past the edge numpy.pad's `mode`. kernel is
    (kh, kw) or (kh, kw, C) and is applied as given (normalise it first)."""
    img = np.asarray(img, np.float64)
    k = np.asarray(kernel, np.float64)
    if k.ndim == 2:
        k = np.repeat(k[..., None], img.shape[2], axis=2)
    kh, kw = k.shape[:2]
    cy, cx = kh // 2, kw // 2
    py, px = max(cy, kh - 1 - cy), max(cx, kw - 1 - cx)
    pad = np.pad(img, ((py, py), (px, px), (0, 0)), mode=mode)
    h, w = img.shape[:2]
    out = np.zeros_like(img)
    for i in range(kh):
        for j in range(kw):
            dy, dx = i - cy, j - cx
            out += k[i, j] * pad[py - dy:py - dy + h, px - dx:px - dx + w]
    return out


def disk_areas(diameter, n_sub=4096):
    """The area of each unit pixel square (centres at integer offsets) inside the circle of
    `diameter` centred on pixel (0, 0): integral over x of the overlap of [y - 1/2, y + 1/2]
    with the chord [-sqrt(R^2 - x^2), +sqrt(R^2 - x^2)], by the midpoint rule on n_sub
    points a pixel (error ~1e-7 of a pixel: the rim is smooth between its kinks).
    Returns (areas[y, x], r) with offsets -r .. r."""
    R = diameter / 2.0
    r = int(np.ceil(R + 0.5))
    idx = np.arange(-r, r + 1)
    x = idx[:, None] + (np.arange(n_sub) + 0.5) / n_sub - 0.5
    half = np.sqrt(np.maximum(R * R - x * x, 0.0))
    lo = np.maximum(idx[None, :, None] - 0.5, -half[:, None, :])
    hi = np.minimum(idx[None, :, None] + 0.5, half[:, None, :])
    return np.clip(hi - lo, 0.0, None).mean(axis=2).T, r


def thin_lens_coc_px(depth, focus, fstop, focal_mm, sensor_mm, width_px, unit_mm=1000.0):
    """docs/defocus.md: CoC(d) = (d - d0) / d * f^2 / (F (d0 - f)) / (sensor / width) px,
    signed (negative in front of focus); d, d0 in depth units converted to mm."""
    d, d0 = np.asarray(depth, np.float64) * unit_mm, focus * unit_mm
    return (d - d0) / d * focal_mm ** 2 / (fstop * (d0 - focal_mm)) / (sensor_mm / width_px)


def bilinear_black(channel, X, Y):
    """OIIO's interppixel at continuous pixel coordinates (X, Y) (pixel i's centre at
    i + 0.5): the 4 pixels around (X - 1/2, Y - 1/2) weighted by the fractions, 0 past the
    data window."""
    h, w = channel.shape
    x, y = X - 0.5, Y - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    out = np.zeros_like(X)
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            xi, yi = x0 + dx, y0 + dy
            ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
            out += np.where(ok, wx * wy * channel[np.clip(yi, 0, h - 1), np.clip(xi, 0, w - 1)], 0.0)
    return out


# Deep pixels as numpy arrays of samples (rows: R, G, B, A, Z[, ZBack]).

def make_deep(width, height, pixels, names=("R", "G", "B", "A", "Z")):
    """A deep float ImageBuf holding `pixels` (row-major list of (n, C) sample arrays)."""
    spec = oiio.ImageSpec(width, height, len(names), oiio.FLOAT)
    spec.channelnames = names
    spec.deep = True
    spec.alpha_channel = names.index("A")
    spec.z_channel = names.index("Z")
    buf = oiio.ImageBuf(spec)
    for p, samples in enumerate(pixels):
        x, y = p % width, p // width
        buf.set_deep_samples(x, y, 0, len(samples))
        for s, row in enumerate(samples):
            for c, v in enumerate(row):
                buf.set_deep_value(x, y, 0, c, s, float(v))
    return buf


def read_deep(buf):
    dd = buf.deepdata()
    return [np.array([[dd.deep_value(p, c, s) for c in range(dd.channels)] for s in range(dd.samples(p))],
                     np.float64).reshape(-1, dd.channels) for p in range(dd.pixels)]


def random_point_samples(rng, npix, max_samples=5):
    """Point samples at distinct depths of a 0.5 grid, in random order; alphas in
    (0.05, 0.95), one in seven opaque; premultiplied colours (c <= 3 a)."""
    pixels = []
    for _ in range(npix):
        n = int(rng.integers(0, max_samples + 1))
        z = rng.choice(np.arange(1, 60) * 0.5, size=n, replace=False)
        a = rng.uniform(0.05, 0.95, n)
        a[rng.random(n) < 1 / 7] = 1.0
        pixels.append(np.column_stack([rng.random((n, 3)) * 3 * a[:, None], a, z]))
    return pixels


def over_front_to_back(samples):
    """OpenEXR's flatten of point samples at distinct depths: sorted by Z,
    C = sum_i c_i prod_{j<i} (1 - a_j) for C in R, G, B, A; Z where the first sample with
    alpha lies (docs/deep.md), 1e30 for an empty pixel."""
    if len(samples) == 0:
        return np.array([0.0, 0.0, 0.0, 0.0, 1e30])
    s = samples[np.argsort(samples[:, 4], kind="stable")]
    through = np.concatenate([[1.0], np.cumprod(1.0 - s[:, 3])[:-1]])
    rgba = (s[:, :4] * through[:, None]).sum(axis=0)
    return np.append(rgba, s[s[:, 3] > 0][0, 4] if np.any(s[:, 3] > 0) else 1e30)


def merge_coincident(samples):
    """OpenEXR's merge of point samples at one Z (docs/deep.md): a = 1 - prod(1 - a_k),
    colour a / sum(u_k) * sum(c_k u_k / a_k), u_k = -log1p(-a_k); where some a_k = 1, the
    colour is the mean of those samples' colours."""
    a = samples[:, 3]
    if np.any(a >= 1.0):
        colour, alpha = samples[a >= 1.0, :3].mean(axis=0), 1.0
    else:
        u = -np.log1p(-a)
        alpha = 1.0 - np.prod(1.0 - a)
        colour = alpha / u.sum() * (samples[:, :3] * (u / a)[:, None]).sum(axis=0)
    return np.concatenate([colour, [alpha, samples[0, 4]]])


def flatten_with_merges(samples):
    if len(samples) == 0:
        return over_front_to_back(samples)
    return over_front_to_back(np.array([merge_coincident(samples[samples[:, 4] == z])
                                        for z in np.unique(samples[:, 4])]))


def assert_deep_flat_close(got, want, atol):
    """R, G, B, A within atol; Z relative to float32 (1e30 for empty pixels included)."""
    assert got.shape == want.shape
    assert np.max(np.abs(got[..., :4] - want[..., :4])) <= atol
    assert np.max(np.abs(got[..., 4] / want[..., 4] - 1.0)) <= 1e-7


@pytest.fixture(scope="module")
def lights():
    """The lights scene's pixels (HDR lights up to ~300 over a textured floor): an input."""
    return ob.to_array(ob.scene("lights", width=64, height=40))


# --- convolve ---------------------------------------------------------------------------

def test_convolve_against_numpy(lights):
    """convolve is a convolution (docs/blur.md: "convolve with an image as the kernel";
    blur.h: centre at the data window's pixel (xbegin + width / 2, ybegin + height / 2),
    each channel normalised to sum 1), not a correlation: an asymmetric 3 x 4 kernel (even
    width: centre column 2) checks the orientation and the centre, on clamp (edge repeated),
    black (0) and mirror (core/base/plane.cpp: ... 2 1 0 | 0 1 2 ..., numpy's "symmetric")
    borders, and with grow=True the window grown by the kernel's reach (2 px left and right:
    max(2, 4 - 1 - 2); 1 px up and down)."""
    img = lights[:, :, :4].astype(np.float64)
    kernel = np.array([[0.0, 0.5, 0.0, 0.0],
                       [0.2, 1.0, 3.0, 0.0],
                       [0.0, 0.0, 0.7, 1.5]])
    want_k = kernel / kernel.sum()
    for border, mode in (("clamp", "edge"), ("black", "constant"), ("mirror", "symmetric")):
        got = ob.convolve(img.astype(np.float32), kernel.astype(np.float32)[..., None], border=border)
        want = np_convolve(img, want_k, mode)
        # By FFT in double, stored as float: float32 rounding of values up to ~300.
        assert got.shape == want.shape
        assert np.max(np.abs(got - want)) <= 1e-6 * (1.0 + np.max(np.abs(want))), border
    # The orientation alone, on a unit impulse: the result is the kernel itself, not its
    # point reflection (a correlation would put the weight 1.5 at (-1, -1)).
    impulse = np.zeros((9, 9, 1), np.float32)
    impulse[4, 4] = 1.0
    got = ob.convolve(impulse, kernel.astype(np.float32)[..., None], border="black")[..., 0]
    assert np.allclose(got[3:6, 2:6], want_k, atol=1e-7)
    # grow=True with border=black: the full convolution over the grown window.
    got = ob.convolve(img.astype(np.float32), kernel.astype(np.float32)[..., None], border="black", grow=True)
    padded = np.pad(img, ((1, 1), (2, 2), (0, 0)))
    want = np_convolve(padded, want_k, "constant")
    assert got.shape == want.shape
    assert np.max(np.abs(got - want)) <= 1e-6 * (1.0 + np.max(np.abs(want)))


def test_convolve_with_a_colour_kernel_against_numpy(lights):
    """A colour kernel (blur.h): source channel c by kernel channel c, each normalised on
    its own; the source channels past the kernel's (alpha here) by the mean of the
    normalised kernel channels."""
    img = lights[:24, :32, :4].astype(np.float64)
    rng = np.random.default_rng(11)
    kernel = rng.random((5, 3, 3))
    kernel[0, 0, 1] = 0.0
    normalised = kernel / kernel.sum(axis=(0, 1))
    want_k = np.concatenate([normalised, normalised.mean(axis=2, keepdims=True)], axis=2)
    got = ob.convolve(img.astype(np.float32), kernel.astype(np.float32), border="clamp")
    want = np_convolve(img, want_k, "edge")
    # float32 rounding of values up to ~300.
    assert np.max(np.abs(got - want)) <= 1e-6 * (1.0 + np.max(np.abs(want)))


# --- the resample family ------------------------------------------------------------------

def ramp_image(w, h):
    """Three planes linear in x and y (pixel centres at integers): f = a x + b y + c."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([0.3 * x + 0.1 * y + 1.0, -0.2 * x + 0.7 * y + 5.0, 0.05 * x - 0.02 * y + 2.0], axis=-1)


def ramp_at(u, v, w, h):
    """The ramp at source position (u, v), clamped to the edge pixels' centres
    (border=clamp: beyond them the edge pixel repeats, and linear interpolation between a
    pixel and its copy is flat)."""
    u, v = np.clip(u, 0, w - 1), np.clip(v, 0, h - 1)
    return np.stack([0.3 * u + 0.1 * v + 1.0, -0.2 * u + 0.7 * v + 5.0, 0.05 * u - 0.02 * v + 2.0], axis=-1)


@pytest.mark.parametrize("factor", [2, 2.5, 3.7])
def test_enlarge_bilinear_of_a_ramp_is_the_linear_interpolation(factor):
    """resample.h: destination pixel i samples the source at u = (i + 0.5) / factor - 0.5
    (anchored at 0; the window the ceil(W factor) pixels it touches); bilinear of a linear
    function there is the function, clamped at the edges."""
    w, h = 20, 12
    got = ob.enlarge(ramp_image(w, h).astype(np.float32), factor)
    H, W = int(np.ceil(h * factor)), int(np.ceil(w * factor))
    assert got.shape == (H, W, 3)
    j, i = np.mgrid[0:H, 0:W].astype(np.float64)
    want = ramp_at((i + 0.5) / factor - 0.5, (j + 0.5) / factor - 0.5, w, h)
    # float32 sums of 4 taps on values up to ~14: a few ulp.
    assert np.max(np.abs(got - want)) <= 1e-5


@pytest.mark.parametrize("function,size", [("resize", (53, 29)), ("resample", (53, 29)),
                                           ("resample", (13, 7)), ("resize", (10, 6))])
def test_resize_and_resample_of_a_ramp_at_the_display_window_mapping(function, size):
    """resize and resample map the display windows onto each other (IBA's mapping):
    destination pixel i samples u = (i + 0.5) W / W' - 0.5. Unfiltered bilinear (resample,
    and resize's bilinear enlarging) gives the ramp there. resize reducing by 2 stretches the
    filter to the destination pixel; each destination centre then lies midway between
    source centres, so the taps are symmetric about it and every normalised symmetric filter
    gives a linear function back away from the edges (its reach in source pixels:
    bilinear 2, bspline/catmull-rom 4, box 1)."""
    w, h = 20, 12
    src = ramp_image(w, h).astype(np.float32)
    W, H = size
    j, i = np.mgrid[0:H, 0:W].astype(np.float64)
    u, v = (i + 0.5) * w / W - 0.5, (j + 0.5) * h / H - 0.5
    want = ramp_at(u, v, w, h)
    if function == "resample":
        got = ob.resample(src, size)
        inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)  # its border is not documented
        checks = [(got, inside)]
    elif W > w:
        checks = [(ob.resize(src, size, filter="bilinear"), np.ones_like(u, bool))]
    else:
        checks = []
        for f, reach in (("bilinear", 2), ("bspline", 4), ("catmull-rom", 4), ("box", 1)):
            inside = (u - reach >= 0) & (u + reach <= w - 1) & (v - reach >= 0) & (v + reach <= h - 1)
            assert inside.sum() >= 4
            checks.append((ob.resize(src, size, filter=f), inside))
    for got, inside in checks:
        assert got.shape == (H, W, 3)
        # float32 sums of at most a few dozen taps on values up to ~14.
        assert np.max(np.abs(got - want)[inside]) <= 1e-5


def test_nearest_samples_are_the_pixel_whose_square_holds_the_centre():
    """resample(interp=0) and enlarge(filter=nearest|box) at a whole factor: each output
    pixel is the source pixel whose square [x, x+1) holds the sample, floor((i + 0.5) W / W');
    at a whole factor the area-exact box is the same (resample.h), i.e. numpy.repeat."""
    rng = np.random.default_rng(1)
    src = rng.random((12, 20, 3)).astype(np.float32)
    for W, H in ((53, 29), (13, 7)):
        got = ob.resample(src, (W, H), interp=0)
        j, i = np.mgrid[0:H, 0:W]
        assert np.array_equal(got, src[np.floor((j + 0.5) * 12 / H).astype(int),
                                       np.floor((i + 0.5) * 20 / W).astype(int)])
    for f in ("nearest", "box"):
        got = ob.enlarge(src, 3, filter=f)
        # Exact: one tap of weight 1 (box: the whole footprint in one source pixel).
        assert np.array_equal(got, np.repeat(np.repeat(src, 3, axis=0), 3, axis=1)), f


def test_reduce_is_the_block_mean():
    """reduce(N): pixel (i, j) covers source [i N, (i + 1) N) x [j N, (j + 1) N), the window
    the blocks it touches (ceil); colour the mean of the block's pixels inside the window,
    or (black=True) their sum over N^2, which keeps the energy; depth (Z) the block's min,
    max, mean, or the depth of its nearest pixel (= the min for Z itself)."""
    rng = np.random.default_rng(3)
    h, w = 27, 38
    img = np.empty((h, w, 5), np.float32)
    img[..., :3] = rng.random((h, w, 3)) * 4
    img[..., 3] = rng.random((h, w))
    img[..., 4] = 1 + 20 * rng.random((h, w))
    for n in (2, 3, 4):
        H, W = -(-h // n), -(-w // n)
        pad = np.full((H * n, W * n, 5), np.nan)
        pad[:h, :w] = img
        blocks = pad.reshape(H, n, W, n, 5).transpose(0, 2, 4, 1, 3).reshape(H, W, 5, n * n)
        depth = {"min": np.nanmin(blocks[..., 4, :], -1), "max": np.nanmax(blocks[..., 4, :], -1),
                 "mean": np.nanmean(blocks[..., 4, :], -1), "nearest": np.nanmin(blocks[..., 4, :], -1)}
        for black in (False, True):
            colour = (np.nansum(blocks[..., :4, :], -1) / (n * n) if black
                      else np.nanmean(blocks[..., :4, :], -1))
            for z in ("min", "max", "mean", "nearest"):
                if black and z == "mean":
                    continue  # test_reduce_black_leaves_depth_alone
                got = ob.reduce(img, n, black=black, z=z)
                assert got.shape == (H, W, 5)
                # float32 sums of at most 16 values up to 21.
                assert np.max(np.abs(got[..., :4] - colour)) <= 1e-6 * 4, (n, black, z)
                assert np.max(np.abs(got[..., 4] - depth[z])) <= 1e-6 * 21, (n, black, z)
            if black:
                # The energy: sum of the reduced image times N^2 is the source's sum.
                got = ob.reduce(img, n, black=True)
                assert np.allclose(got[..., :4].sum(axis=(0, 1), dtype=np.float64) * n * n,
                                   img[..., :4].sum(axis=(0, 1), dtype=np.float64), rtol=1e-6)


def test_reduce_black_leaves_depth_alone():
    """black=True is documented as keeping the energy (commands/resample.md: "count block
    pixels outside the data window as 0 (keeps the energy)"); the depth reducers min, max
    and nearest leave those pixels out, and a mean depth of a constant-depth frame is that
    depth: what a depth of 0 ("no depth", docs/defocus.md) would change is a surface."""
    img = np.ones((3, 3, 5), np.float32)
    img[..., 4] = 10.0
    for z in ("min", "max", "nearest", "mean"):
        got = ob.reduce(img, 2, black=True, z=z)
        assert np.array_equal(got[..., 0], [[1.0, 0.5], [0.5, 0.25]]), z  # colour: sum / 4
        assert np.array_equal(got[..., 4], np.full((2, 2), 10.0)), z


@pytest.mark.parametrize("filter", ["bilinear", "nearest", "catmull-rom", "bspline", "lanczos2", "lanczos3",
                                    "gaussian", "box", "reduced-blur", "upscale-blur", "upscale-blur-fused",
                                    "upscale-blur-2stage"])
def test_resampling_a_constant_gives_the_constant(filter):
    """Every filter's weights are normalised (resample.h), so a constant stays itself,
    enlarged (any border) or, for the filters that reduce, resized down."""
    c = np.empty((12, 20, 4), np.float32)
    c[...] = (0.37, 2.5, 120.0, 1.0)
    # float32 sums of at most a few dozen taps: a few ulp of the value.
    tol = 4e-7 * np.abs(c[0, 0])
    for border in ("clamp", "black", "mirror"):
        got = ob.enlarge(c, 3.3, filter=filter, border=border)
        if border == "black":
            # Black past the edge: only the interior (beyond every filter's reach, 4 sigma
            # of the Gaussian = 2.6 source px, 3 for Lanczos-3 plus the compound stages).
            got = got[15:-15, 15:-15]
        assert np.all(np.abs(got - c[0, 0]) <= tol), border
    if filter not in ("reduced-blur", "upscale-blur", "upscale-blur-fused", "upscale-blur-2stage"):
        assert np.all(np.abs(ob.resize(c, (7, 5), filter=filter) - c[0, 0]) <= tol)


# --- defocus ----------------------------------------------------------------------------

def test_defocus_coc_map_is_the_thin_lens_formula():
    """output='coc' against docs/defocus.md's CoC(d) = (d - d0) / d * f^2 / (F (d0 - f)) /
    (sensor / width), over depths from 0.6 to 60 m in m, and in cm with unit='cm'."""
    h, w = 20, 64
    img = np.zeros((h, w, 5), np.float32)
    img[..., :4] = 0.5
    img[..., 4] = np.geomspace(0.6, 60.0, w * h).reshape(h, w)
    for focus, fstop, focal, sensor in ((4.0, 2.0, 50.0, 36.0), (1.5, 1.4, 85.0, 24.89)):
        got, report = ob.defocus(img, focus=focus, fstop=fstop, focal=focal, sensor=sensor, output="coc")
        assert report is None and got.shape == (h, w, 1)
        want = thin_lens_coc_px(img[..., 4], focus, fstop, focal, sensor, w)
        # Computed in float: float32 rounding of CoCs up to ~20 px.
        assert np.max(np.abs(got[..., 0] - want)) <= 1e-5 * (1 + np.max(np.abs(want)))
    cm = img.copy()
    cm[..., 4] *= 100.0
    got, _ = ob.defocus(cm, focus=400, unit="cm", fstop=2, focal=50, sensor=36, output="coc")
    want = thin_lens_coc_px(img[..., 4], 4.0, 2.0, 50.0, 36.0, w)
    assert np.max(np.abs(got[..., 0] - want)) <= 1e-5 * (1 + np.max(np.abs(want)))


# The defocus's own lens for the disk checks: 50 mm at f/1.4 focused at 2 m, a 6 mm film
# back over 64 px: CoC = (d - 2) / d * 9.77 px.
LENS = dict(focus=2.0, fstop=1.4, focal=50.0, sensor=6.0)


@pytest.mark.parametrize("depth", [1.0, 5.0])
@pytest.mark.parametrize("method", ["auto", "reference"])
def test_defocus_at_one_depth_is_a_disk_blur(depth, method):
    """Every pixel at one depth: one layer, the aperture (a disk) of the thin-lens CoC's
    diameter everywhere, border clamp (docs/methods/defocus.md), so the result is the
    convolution with the disk's normalised pixel areas, computed here exactly. With alpha 1
    the layer's visibility is 1 and the result is that blur, premultiplied R, G, B, A."""
    rng = np.random.default_rng(5)
    h, w = 48, 64
    img = np.zeros((h, w, 5), np.float32)
    img[..., :3] = rng.random((h, w, 3))
    img[10, 20, :3] = 100.0      # a light: its disk shows every weight
    img[30, 45, :3] = (5.0, 40.0, 2.0)
    img[..., 3] = 1.0
    img[..., 4] = depth
    coc = float(thin_lens_coc_px(depth, LENS["focus"], LENS["fstop"], LENS["focal"], LENS["sensor"], w))
    got, report = ob.defocus(img, method=method, **LENS)
    assert abs(report.min_coc_px - coc) < 1e-4 and abs(report.max_coc_px - coc) < 1e-4
    areas, r = disk_areas(abs(coc))
    kernel = areas / areas.sum()  # point-symmetric: the front disk's reflection is itself
    src = img[..., :4].astype(np.float64)
    want = np_convolve(src, kernel, "edge")
    assert got.shape == want.shape
    # The library estimates each rim pixel's area (0 < area < 1) with 64 x 64 stratified
    # samples (docs/methods/uniform-kernels.md); allow 4e-3 of a pixel per rim pixel
    # (measured at most 8.4e-4 on 5 diameters), i.e. weights off by 4e-3 / area on the rim
    # and, through the normalisation, by n_rim 4e-3 / area relative everywhere.
    rim = ((areas > 0) & (areas < 1)).astype(np.float64)
    e = 4e-3 / areas.sum()
    tol = e * (np_convolve(np.abs(src), rim, "edge") + rim.sum() * np_convolve(np.abs(src), kernel, "edge"))
    err = np.abs(got - want)
    assert np.all(err <= tol + 1e-6), f"worst {err.max():.3g} where the bound is {tol.flat[err.argmax()]:.3g}"
    # The bound still tells a wrong diameter: the disk 1 % larger breaks it (its rim pixels
    # move by ~0.01 R of a pixel's area, times the light's 100).
    areas, _ = disk_areas(1.01 * abs(coc))
    wrong = np_convolve(src, areas / areas.sum(), "edge")
    assert np.any(np.abs(wrong - want) > tol + 1e-6)


def test_defocus_in_focus_gives_the_input_back():
    """CoC 0 everywhere (the depth is the focus distance): no blur; the premultiplied
    R, G, B, A come back, whatever the alpha."""
    rng = np.random.default_rng(4)
    img = np.zeros((40, 56, 5), np.float32)
    img[..., 3] = rng.uniform(0.2, 1.0, (40, 56))
    img[..., :3] = rng.random((40, 56, 3)) * img[..., 3:4] * 2
    img[..., 4] = LENS["focus"]
    for method in ("auto", "reference"):
        got, report = ob.defocus(img, method=method, **LENS)
        assert report.max_coc_px == 0.0
        # The identity: nothing is summed.
        assert np.array_equal(got, img[..., :4]), method


@pytest.mark.parametrize("depth", [1.0, 20.0])
def test_defocus_keeps_a_lone_lights_energy(depth):
    """A light on black at one depth is spread over its disk, away from the borders: its
    sum per channel stays what it was, and its centroid stays on the light."""
    h, w = 40, 64
    img = np.zeros((h, w, 5), np.float32)
    img[..., 3] = 1.0
    img[20, 27, :3] = (100.0, 50.0, 25.0)
    img[..., 4] = depth
    coc = thin_lens_coc_px(depth, LENS["focus"], LENS["fstop"], LENS["focal"], LENS["sensor"], w)
    assert 7 < abs(coc) < 10  # the disk stays 10 px or more from every edge
    for method in ("auto", "reference"):
        got, _ = ob.defocus(img, method=method, **LENS)
        total = got[..., :3].sum(axis=(0, 1), dtype=np.float64)
        # float32 weights summing to 1 within a few ulp each.
        assert np.allclose(total, (100.0, 50.0, 25.0), rtol=1e-5), method
        yy, xx = np.mgrid[0:h, 0:w]
        r = got[..., 0].astype(np.float64)
        # The disk is point-symmetric about the light's centre.
        assert abs((r * xx).sum() / r.sum() - 27) < 1e-4 and abs((r * yy).sum() / r.sum() - 20) < 1e-4
        assert np.max(np.abs(got[..., 3] - 1.0)) <= 1e-6  # alpha 1 blurred stays 1


# --- the deep nodes -----------------------------------------------------------------------

DW, DH = 16, 12


def test_flatten_is_the_front_to_back_over():
    """flatten of point samples in random order at distinct depths: sorted by Z,
    C = sum_i c_i prod_{j<i} (1 - a_j) for R, G, B and A; Z where the samples with alpha
    begin; 1e30 for empty pixels (docs/deep.md, the OpenEXR rules)."""
    pixels = random_point_samples(np.random.default_rng(7), DW * DH)
    assert any(len(p) == 0 for p in pixels) and any(len(p) == 5 for p in pixels)
    got = ob.to_array(ob.flatten(make_deep(DW, DH, pixels)))
    want = np.array([over_front_to_back(p) for p in pixels]).reshape(DH, DW, 5)
    # float32 sums of up to 5 terms up to 3.
    assert_deep_flat_close(got, want, 1e-6)


def test_flatten_splits_a_volume_where_a_point_lies_inside_it():
    """A volume [2, 6) of alpha 0.6 with a point at Z 3 inside: the volume is cut there
    (docs/deep.md): its front quarter keeps alpha 1 - (1 - 0.6)^(1/4), its back
    1 - (1 - 0.6)^(3/4), colours scaled with their alphas, and the point lies between them:
    front over point over back. Z, ZBack = where the visible samples begin and end."""
    a, c = 0.6, np.array([0.3, 0.45, 0.6])         # the volume, premultiplied
    ap, cp = 0.5, np.array([0.4, 0.1, 0.05])       # the point at 3
    pixels = [np.array([[*c, a, 2.0, 6.0], [*cp, ap, 3.0, 3.0]])]
    got = ob.to_array(ob.flatten(make_deep(1, 1, pixels, ("R", "G", "B", "A", "Z", "ZBack"))))[0, 0]
    af, ab = 1 - (1 - a) ** 0.25, 1 - (1 - a) ** 0.75
    front, back = np.append(c * af / a, af), np.append(c * ab / a, ab)
    point = np.append(cp, ap)
    want = front + (1 - af) * point + (1 - af) * (1 - ap) * back
    # float32 of values under 1.
    assert np.max(np.abs(got[:4] - want)) <= 1e-6, (got[:4], want)
    assert got[4] == 2.0 and got[5] == 6.0


def test_deep_merge_then_flatten_is_the_over_of_the_pooled_samples():
    """deep_merge pools the samples per pixel and tidies them: samples of the two images at
    the same Z merge by the OpenEXR rule (merge_coincident), the rest are composited as
    they are; flatten then gives the over of the pooled, merged samples. One pixel in eight
    here holds a depth in both images."""
    rng = np.random.default_rng(8)
    pa, pb = random_point_samples(rng, DW * DH), random_point_samples(rng, DW * DH)
    coincident = sum(len(np.intersect1d(a[:, 4], b[:, 4])) > 0 for a, b in zip(pa, pb))
    assert coincident >= DW * DH // 10
    merged = ob.deep_merge([make_deep(DW, DH, pa), make_deep(DW, DH, pb)])
    got = ob.to_array(ob.flatten(merged))
    want = np.array([flatten_with_merges(np.vstack([a, b])) for a, b in zip(pa, pb)]).reshape(DH, DW, 5)
    # float32 sums of up to 10 terms up to 3 (log1p and expm1 in the merge).
    assert_deep_flat_close(got, want, 2e-6)
    # Nothing culled (cull=False): every pixel keeps its distinct depths.
    counts = [len(s) for s in read_deep(merged)]
    assert counts == [len(np.unique(np.concatenate([a[:, 4], b[:, 4]]))) for a, b in zip(pa, pb)]


def test_deep_holdout_then_flatten_is_the_held_out_over():
    """deep_holdout: each sample times the holdout's transmittance in front of it,
    T(z) = prod over holdout samples at z_h <= z (a point at the same depth counts as in
    front) of (1 - a_h); the result flattens to sum_i T(z_i) (c_i, a_i) prod_{j<i} (1 - a_j)
    (docs/deep.md). Holdout depths share the image's 0.5 grid, so some coincide."""
    rng = np.random.default_rng(9)
    image, hold = random_point_samples(rng, DW * DH), random_point_samples(rng, DW * DH, 3)

    def held(p, h):
        if len(p) == 0:
            return over_front_to_back(p)
        p = p[np.argsort(p[:, 4])]
        T = np.array([np.prod(1 - h[h[:, 4] <= z, 3]) for z in p[:, 4]])
        through = np.concatenate([[1.0], np.cumprod(1.0 - p[:, 3])[:-1]])
        return np.append(((p[:, :4] * (T * through)[:, None]).sum(axis=0)), p[0, 4])

    got = ob.to_array(ob.flatten(ob.deep_holdout(make_deep(DW, DH, image), make_deep(DW, DH, hold))))
    want = np.array([held(p, h) for p, h in zip(image, hold)]).reshape(DH, DW, 5)
    visible = want[..., 3] > 0  # Z is where samples with alpha begin: a fully held-out pixel has none
    assert np.max(np.abs(got[..., :4] - want[..., :4])) <= 1e-6  # float32 sums of 5 terms
    assert np.max(np.abs(got[..., 4][visible] / want[..., 4][visible] - 1)) <= 1e-7


@pytest.mark.parametrize("near,far", [(5.0, 20.0), (-np.inf, 10.0), (12.5, np.inf)])
def test_deep_slice_keeps_the_samples_in_near_far(near, far):
    """deep_slice(near, far): the point samples with near <= Z < far (docs/deep.md), so its
    flatten is the over of those alone; 12.5 and 10 are on the samples' grid, so both ends
    of the half-open range are met."""
    pixels = random_point_samples(np.random.default_rng(10), DW * DH)
    got = ob.to_array(ob.flatten(ob.deep_slice(make_deep(DW, DH, pixels), near, far)))
    want = np.array([over_front_to_back(p[(p[:, 4] >= near) & (p[:, 4] < far)]) for p in pixels])
    assert_deep_flat_close(got, want.reshape(DH, DW, 5), 1e-6)


def test_deepen_makes_one_sample_a_pixel_none_where_empty():
    """deepen: one sample with the flat pixel's values; none where every non-depth channel
    is 0 and the depth is 0, not finite or >= 1e30 (docs/deep.md, OIIO's rule)."""
    rng = np.random.default_rng(12)
    img = rng.random((6, 8, 5)).astype(np.float32)
    img[..., 4] += 1.0
    img[0, 0] = (0, 0, 0, 0, 0)
    img[0, 1] = (0, 0, 0, 0, 1e30)
    img[0, 2] = (0, 0, 0, 0, np.inf)
    img[0, 3] = (0, 0, 0, 0, 4.0)    # empty colour at a finite depth: kept
    img[0, 4] = (0, 0, 0.1, 0, 0)    # colour at depth 0: kept
    deep = read_deep(ob.deepen(img))
    for p, samples in enumerate(deep):
        y, x = divmod(p, 8)
        if (y, x) in ((0, 0), (0, 1), (0, 2)):
            assert len(samples) == 0, (y, x)
        else:
            assert len(samples) == 1 and np.array_equal(samples[0], img[y, x]), (y, x)


# --- compare ----------------------------------------------------------------------------

def test_compare_against_the_metrics_definitions():
    """docs/methods/metrics.md: RMSE of the linear values, PSNR = 10 log10(1 / MSE) of the
    tone-mapped values x / (1 + |x|) (peak 1; the |x| is metrics.h's, for negatives), the
    largest absolute difference, channel by channel over the union of the data windows (a
    pixel outside an image's window counts as 0); 999 dB when identical; a NaN where the
    other image differs is an infinite error."""
    rng = np.random.default_rng(13)
    ref = (rng.random((10, 12, 3)) * 40 - 5).astype(np.float32)   # HDR, some negative
    res = (ref + rng.normal(0, 0.3, ref.shape)).astype(np.float32)
    a, b = ref.astype(np.float64), res.astype(np.float64)

    def tone(x):
        return x / (1 + np.abs(x))

    e = ob.compare(res, ref)
    # Sums in double over 360 values: only the last digits differ.
    assert e.values == a.size
    assert e.rmse_linear == pytest.approx(np.sqrt(np.mean((a - b) ** 2)), rel=1e-12)
    assert e.psnr_db == pytest.approx(10 * np.log10(1 / np.mean((tone(a) - tone(b)) ** 2)), rel=1e-12)
    assert e.max_abs == pytest.approx(np.max(np.abs(a - b)), rel=1e-12)
    assert ob.compare(ref, ref.copy()).psnr_db == 999
    # The union of windows: the result moved to (3, 2) covers x 0..15, y 0..12.
    moved = ob.to_imagebuf(res)
    moved.set_origin(3, 2)
    A, B = np.zeros((12, 15, 3)), np.zeros((12, 15, 3))
    A[:10, :12], B[2:, 3:] = a, b
    e = ob.compare(moved, ob.to_imagebuf(ref))
    assert e.values == A.size
    assert e.rmse_linear == pytest.approx(np.sqrt(np.mean((A - B) ** 2)), rel=1e-12)
    assert e.psnr_db == pytest.approx(10 * np.log10(1 / np.mean((tone(A) - tone(B)) ** 2)), rel=1e-12)
    assert e.max_abs == pytest.approx(np.max(np.abs(A - B)), rel=1e-12)
    bad = res.copy()
    bad[1, 2, 0] = np.nan
    e = ob.compare(bad, ref)
    assert e.nonfinite == 1 and e.rmse_linear == np.inf and e.psnr_db == -np.inf and e.max_abs == np.inf


# --- lens_distort -------------------------------------------------------------------------

LW, LH = 96, 54


def normalised_positions(cx=0.0, cy=0.0):
    """docs/methods/distortion.md: p = (X - c) / R, X the pixel centre (x + 0.5, y + 0.5),
    c the display window's centre moved by (centrex, centrey), R its half-diagonal."""
    y, x = np.mgrid[0:LH, 0:LW].astype(np.float64)
    c = np.array([LW / 2 + cx, LH / 2 + cy])
    R = np.hypot(LW, LH) / 2
    return (x + 0.5 - c[0]) / R, (y + 0.5 - c[1]) / R, c, R


@pytest.mark.parametrize("model,direction,k1,k2", [
    ("polynomial", "undistort", -0.1, 0.01),   # explicit: r_d = r_u (1 + k1 r_u^2 + k2 r_u^4)
    ("division", "distort", -0.1, 0.02),       # explicit: r_u = r_d / (1 + k1 r_d^2 + k2 r_d^4)
    ("polynomial", "distort", 0.08, 0.0),      # solved by the library: checked by the forward formula
    ("division", "undistort", 0.05, -0.01),
])
def test_lens_distort_stmap_against_the_radial_formulas(model, direction, k1, k2):
    """output='stmap' holds each output pixel's source position (s = X / W, t = 1 - Y / H).
    Distort: the output is what the lens records (p_d), the source the pinhole frame (p_u);
    undistort the other way round. Where the formula is explicit the source position is
    computed; where the library solves it (Newton), the formula applied to the source
    position must give the output pixel's. A moved centre checks centrex/centrey."""
    px, py, c, R = normalised_positions(3.0, -2.0)
    st = ob.lens_distort(np.zeros((LH, LW, 3), np.float32), model=model, direction=direction,
                         k1=k1, k2=k2, centrex=3.0, centrey=-2.0, output="stmap")
    assert st.shape == (LH, LW, 2)
    qx, qy = (st[..., 0] * LW - c[0]) / R, ((1.0 - st[..., 1]) * LH - c[1]) / R
    explicit_source = (model, direction) in (("polynomial", "undistort"), ("division", "distort"))
    a, b = (px, py) if explicit_source else (qx, qy)   # where the formula starts
    r2 = a * a + b * b
    g = 1 + k1 * r2 + k2 * r2 * r2
    f = g if model == "polynomial" else 1 / g
    if explicit_source:
        err = np.hypot(qx - px * f, qy - py * f) * R
    else:
        err = np.hypot(qx * f - px, qy * f - py) * R
    # In px: s and t are float32 (2^-24 of ~1, times 96 px), the Newton solve to ~1e-10.
    assert np.max(err) <= 5e-5
    # The warp moves pixels by more than 1 px, so no map near the identity passes.
    assert np.max(np.hypot(px * f - px, py * f - py) * R) > 1.0


def test_lens_distort_image_against_numpy_bilinear():
    """A plate undistorted (the explicit polynomial direction): green and alpha sample the
    source at p_d = p_u (1 + k1 r^2 + k2 r^4), red and blue at (1 + lateral) p_d (their
    recorded positions are 1 + lateral times green's), bilinear with black past the data
    window (OIIO's interppixel); Z the nearest pixel's (the one whose square holds it).
    k1 > 0 (pincushion) makes the corners sample past the frame."""
    rng = np.random.default_rng(2)
    img = rng.random((LH, LW, 5)).astype(np.float32)
    img[..., 4] = 1 + 10 * rng.random((LH, LW))
    k1, k2, lr, lb = 0.15, 0.02, 0.01, -0.008
    got = ob.lens_distort(img, direction="undistort", k1=k1, k2=k2, lateralr=lr, lateralb=lb)
    px, py, c, R = normalised_positions()
    r2 = px * px + py * py
    f = 1 + k1 * r2 + k2 * r2 * r2
    want = np.zeros((LH, LW, 4))
    for ch, m in ((0, 1 + lr), (1, 1.0), (2, 1 + lb), (3, 1.0)):
        want[..., ch] = bilinear_black(img[..., ch].astype(np.float64), c[0] + R * px * f * m, c[1] + R * py * f * m)
    assert np.count_nonzero(want[..., 1] == 0) > 100  # the corners are black
    # float32 bilinear of values under 1 (position rounding included).
    assert np.max(np.abs(got[..., :4] - want)) <= 1e-5
    X, Y = np.floor(c[0] + R * px * f).astype(int), np.floor(c[1] + R * py * f).astype(int)
    inside = (X >= 0) & (X < LW) & (Y >= 0) & (Y < LH)
    assert np.array_equal(got[..., 4][inside], img[Y[inside], X[inside], 4])


# --- scene ------------------------------------------------------------------------------

SCENE_CAMERAS = {  # scene() help and docs/io.md: a 50 mm lens on a 36 mm back; focus, f-number
    "lights": (6.0, 1.27), "edges": (3.0, 1.06), "giant": (0.5, 2.0)}


@pytest.mark.parametrize("name", sorted(SCENE_CAMERAS))
def test_scene_documented_camera_alpha_depths_and_deep_flatten(name):
    """What docs/io.md and scene.h state of a scene: its camera in the metadata, alpha 1
    everywhere, Z in metres (edges: only 1.2, 3 and 30 m); and its deep render (each
    surface's alpha its share of the rays not yet taken, colour the mean of its hits, the
    nearest Z) flattens, by the numpy over, to the sharp scene, with Z the nearest
    surface's."""
    sharp = ob.scene(name, width=96, height=54)
    spec = sharp.spec()
    focus, fstop = SCENE_CAMERAS[name]
    assert spec.get_float_attribute("bokeh:focal_mm") == 50.0
    assert spec.get_float_attribute("bokeh:sensor_width_mm") == 36.0
    assert spec.get_string_attribute("bokeh:depth_unit") == "m"
    assert spec.get_float_attribute("bokeh:focus_m") == pytest.approx(focus, rel=1e-7)
    assert spec.get_float_attribute("bokeh:fstop") == pytest.approx(fstop, rel=1e-7)
    pixels = ob.to_array(sharp).astype(np.float64)
    assert np.all(pixels[..., 3] == 1.0)
    if name == "edges":
        assert set(np.unique(pixels[..., 4])) == {np.float32(1.2), np.float32(3.0), np.float32(30.0)}
    deep = read_deep(ob.scene(name, width=96, height=54, output="deep"))
    flat = np.array([over_front_to_back(s) for s in deep]).reshape(54, 96, 5)
    # The share of the rays in float32 and sums of up to 9 hits: 1e-7 of 1 + the value
    # (the lights reach ~300).
    assert np.max(np.abs(flat[..., :4] - pixels[..., :4]) / (1 + np.abs(pixels[..., :4]))) <= 1e-6
    assert np.array_equal(flat[..., 4], pixels[..., 4])
