"""Exercise 12.1 (spatial_softmax): a keypoint (x, y) from each of K heat maps (Levine et al. 2016).

References: closed forms (a peak sits on its pixel centre, a flat map's mean is the centre, two
equal peaks give their midpoint), the same expectation written in numpy (softmax per map over its
H*W positions, then the mean of x_j = -1 + 2 j / (W - 1) and y_i = -1 + 2 i / (H - 1)), autograd
through a torch version of it, and the library's SpatialSoftmax layer around the student's function.
Each failure message names the quantity that is wrong: x and y swapped, a softmax over the wrong
axis, coordinates in pixels or in [0, 1] instead of [-1, 1], an arg-max instead of the expectation.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from coursekit.grading.compare import assert_close

EXERCISE = "spatial_softmax"
PEAK = 1e3  # exp(-1e3) underflows to 0 in float64: the softmax of a map with one such peak is one-hot


# ------------------------------------------------------------------------------ references (numpy)
def _softmax(logits: np.ndarray, axis) -> np.ndarray:
    shifted = logits - logits.max(axis=axis, keepdims=True)
    e = np.exp(shifted)
    return e / e.sum(axis=axis, keepdims=True)


def _mean_position(p: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(B, K, H, W) weights -> (B, K, 2): sum_ij p_ij (xs_j, ys_i)."""
    x = np.einsum("bkhw,w->bk", p, xs)
    y = np.einsum("bkhw,h->bk", p, ys)
    return np.stack([x, y], axis=-1)


def reference(maps: np.ndarray) -> np.ndarray:
    """(B, K, H, W) -> (B, K, 2): the softmax over each map's H*W positions, then its mean (x, y)."""
    B, K, H, W = maps.shape
    p = _softmax(maps.reshape(B, K, H * W), axis=-1).reshape(B, K, H, W)
    return _mean_position(p, np.linspace(-1.0, 1.0, W), np.linspace(-1.0, 1.0, H))


def _mistakes(maps: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """What typical wrong implementations return on ``maps``, each with the sentence that names it."""
    B, K, H, W = maps.shape
    ref = reference(maps)
    xs, ys = np.linspace(-1.0, 1.0, W), np.linspace(-1.0, 1.0, H)
    pixels = np.stack([(ref[..., 0] + 1) / 2 * (W - 1), (ref[..., 1] + 1) / 2 * (H - 1)], axis=-1)
    hard = (maps.reshape(B, K, -1) == maps.reshape(B, K, -1).max(-1, keepdims=True)).reshape(maps.shape)
    edges_x, edges_y = (2 * np.arange(W) + 1) / W - 1, (2 * np.arange(H) + 1) / H - 1
    p = _softmax(maps.reshape(B, K, H * W), axis=-1).reshape(B, K, H, W)
    return [
        (ref[..., ::-1], "x and y are swapped: the column index j gives x, the row index i gives y (keypoint[..., 0] = x)"),
        (pixels, "coordinates span [0, W-1] x [0, H-1] pixels instead of [-1, 1]: use torch.linspace(-1, 1, n)"),
        (pixels[..., ::-1], "x and y are swapped AND in pixels: x from the column in [-1, 1], y from the row in [-1, 1]"),
        ((ref + 1) / 2, "coordinates span [0, 1] instead of [-1, 1]: x_j = -1 + 2 j / (W - 1)"),
        (ref * np.array([1.0, -1.0]), "y points up: it must grow DOWN the image (row 0 is y = -1, the last row y = +1)"),
        (ref * np.array([-1.0, 1.0]), "x points left: it must grow to the right (column 0 is x = -1, the last column x = +1)"),
        (_mean_position(p, edges_x, edges_y), "the grid runs over pixel edges ((2 j + 1) / W - 1); the first and last pixel "
                                              "CENTRES must be exactly -1 and +1 (torch.linspace(-1, 1, n))"),
        (_mean_position(_softmax(maps, axis=1), xs, ys), "softmax taken over the wrong axis (over the K maps): each of the K "
                                                         "maps must sum to 1 over its own H*W positions"),
        (_mean_position(_softmax(maps, axis=-1), xs, ys), "softmax taken over the width only: flatten H and W first, so each "
                                                          "map sums to 1 over all its H*W positions"),
        (_mean_position(_softmax(maps, axis=-2), xs, ys), "softmax taken over the height only: flatten H and W first, so each "
                                                          "map sums to 1 over all its H*W positions"),
        (_mean_position(hard / hard.sum(axis=(2, 3), keepdims=True), xs, ys),
         "yours is the arg-max pixel; the keypoint is the EXPECTED position under the softmax (a weighted mean)"),
    ]


def _diagnosis(got: np.ndarray, maps: np.ndarray) -> str:
    """The sentence naming the mistake ``got`` matches, else where it first differs."""
    for wrong, sentence in _mistakes(maps):
        if wrong.shape == got.shape and np.allclose(got, wrong, rtol=1e-5, atol=1e-5):
            return sentence
    want = reference(maps)
    b, k, c = np.unravel_index(int(np.argmax(np.abs(got - want))), got.shape)
    return (f"map (b={b}, k={k}): expected (x, y) = ({want[b, k, 0]:.4f}, {want[b, k, 1]:.4f}), "
            f"got ({got[b, k, 0]:.4f}, {got[b, k, 1]:.4f}) ({'xy'[c]} is off most)")


def _keypoints(student, maps: torch.Tensor) -> np.ndarray:
    """The student's (B, K, 2) keypoints of ``maps`` as float64 numpy (shape and type checked first)."""
    got = student.spatial_softmax(maps)
    assert torch.is_tensor(got), f"spatial_softmax returned a {type(got).__name__}; expected a torch tensor"
    B, K = maps.shape[:2]
    assert tuple(got.shape) == (B, K, 2), (
        f"keypoints of maps {tuple(maps.shape)} must have shape (B, K, 2) = {(B, K, 2)}, got {tuple(got.shape)}")
    return got.detach().double().numpy()


def _peaked(H: int, W: int, peaks: list[list[tuple[int, int]]]) -> torch.Tensor:
    """(B=len(peaks), K, H, W) float64 maps, zero except PEAK at each map's (row, column) list."""
    K = max(len(row) for row in peaks)
    maps = torch.zeros(len(peaks), K, H, W, dtype=torch.float64)
    for b, row in enumerate(peaks):
        for k, cells in enumerate(row):
            for i, j in cells if isinstance(cells, list) else [cells]:
                maps[b, k, i, j] = PEAK
    return maps


def _centre(i: int, j: int, H: int, W: int) -> tuple[float, float]:
    return -1.0 + 2.0 * j / (W - 1), -1.0 + 2.0 * i / (H - 1)


# ------------------------------------------------------------------------------ tests
def test_keypoints_shape_and_dtype(student):
    for dtype, shape in ((torch.float32, (2, 3, 5, 7)), (torch.float64, (1, 4, 6, 3))):
        maps = torch.randn(shape, generator=torch.Generator().manual_seed(0), dtype=dtype)
        got = student.spatial_softmax(maps)
        assert torch.is_tensor(got), f"spatial_softmax returned a {type(got).__name__}; expected a torch tensor"
        assert tuple(got.shape) == (*shape[:2], 2), (
            f"maps of shape (B, K, H, W) = {shape} must give keypoints of shape (B, K, 2) = {(*shape[:2], 2)}, "
            f"got {tuple(got.shape)}")
        assert got.dtype == dtype, f"keypoints must keep the maps' dtype {dtype}, got {got.dtype}"


@pytest.mark.parametrize("H,W", [(5, 9), (7, 4), (6, 6)])
def test_peak_gives_its_pixel_centre(student, H, W):
    cells = [(0, 0), (H - 1, W - 1), (0, W - 1), (H - 1, 0), (H // 2, 1), (1, W // 2)]
    maps = _peaked(H, W, [cells[:3], cells[3:]])  # (2, 3, H, W)
    got = _keypoints(student, maps)
    for b, row in enumerate((cells[:3], cells[3:])):
        for k, (i, j) in enumerate(row):
            want = _centre(i, j, H, W)
            assert np.allclose(got[b, k], want, rtol=0, atol=1e-9), (
                f"a peak at row {i}, column {j} of a {H}x{W} map sits on that pixel's centre (x, y) = "
                f"({want[0]:.4f}, {want[1]:.4f}), got ({got[b, k, 0]:.4f}, {got[b, k, 1]:.4f}): "
                f"{_diagnosis(got, maps.numpy())}")


def test_uniform_map_gives_the_centre(student):
    levels = torch.tensor([0.0, 3.5, -2.0], dtype=torch.float64)
    maps = levels.view(1, 3, 1, 1).expand(2, 3, 5, 8).contiguous()  # (2, 3, 5, 8), each map flat
    got = _keypoints(student, maps)
    assert np.allclose(got, 0.0, rtol=0, atol=1e-9), (
        f"a flat map weighs every pixel equally, so its keypoint is the image centre (0, 0); got "
        f"({got[0, 0, 0]:.4f}, {got[0, 0, 1]:.4f}): {_diagnosis(got, maps.numpy())}")


def test_two_equal_peaks_give_their_midpoint(student):
    H, W = 6, 9
    pairs = [((1, 2), (4, 7)), ((0, 0), (5, 8)), ((3, 1), (3, 6))]
    maps = _peaked(H, W, [[list(pair) for pair in pairs]])  # (1, 3, H, W)
    got = _keypoints(student, maps)
    for k, (a, b) in enumerate(pairs):
        ca, cb = np.array(_centre(*a, H, W)), np.array(_centre(*b, H, W))
        mid = (ca + cb) / 2
        on_one = any(np.allclose(got[0, k], c, atol=1e-6) for c in (ca, cb))
        assert np.allclose(got[0, k], mid, rtol=0, atol=1e-9), (
            f"two equal peaks at (row, column) {a} and {b} give their midpoint ({mid[0]:.4f}, {mid[1]:.4f}), got "
            f"({got[0, k, 0]:.4f}, {got[0, k, 1]:.4f}): " + (
                "yours sits on one peak (an arg-max?); the keypoint is the EXPECTED position under the softmax"
                if on_one else _diagnosis(got, maps.numpy())))


@pytest.mark.parametrize("seed,shape", [(0, (2, 3, 5, 7)), (1, (1, 8, 9, 4)), (2, (3, 2, 12, 12))])
def test_matches_numpy_on_random_maps(student, seed, shape):
    maps = 3.0 * torch.randn(shape, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    got, want = _keypoints(student, maps), reference(maps.numpy())
    assert np.allclose(got, want, rtol=1e-7, atol=1e-9), (
        f"keypoints of random {shape} maps differ from sum_ij softmax_ij * (x_j, y_i): {_diagnosis(got, maps.numpy())}")


def test_adding_a_constant_changes_nothing(student):
    g = torch.Generator().manual_seed(3)
    maps = torch.randn(2, 4, 6, 5, generator=g, dtype=torch.float64)
    shift = 5.0 * torch.randn(2, 4, 1, 1, generator=g, dtype=torch.float64)  # one constant per map
    plain, shifted = _keypoints(student, maps), _keypoints(student, maps + shift)
    assert np.allclose(plain, shifted, rtol=1e-7, atol=1e-9), (
        f"adding a constant to each map moved its keypoint by up to {np.abs(plain - shifted).max():.3g}; a softmax over "
        f"each map's own H*W positions ignores that constant: {_diagnosis(shifted, (maps + shift).numpy())}")


def _torch_reference(maps: torch.Tensor) -> torch.Tensor:
    """Autograd's reference: the expectation written with exp / sum and broadcasting (no softmax call)."""
    B, K, H, W = maps.shape
    e = (maps - maps.amax(dim=(2, 3), keepdim=True)).exp()  # (B, K, H, W)
    p = e / e.sum(dim=(2, 3), keepdim=True)
    xs = torch.linspace(-1.0, 1.0, W, dtype=maps.dtype)
    ys = torch.linspace(-1.0, 1.0, H, dtype=maps.dtype)
    return torch.stack([(p * xs).sum(dim=(2, 3)), (p * ys[:, None]).sum(dim=(2, 3))], dim=-1)  # (B, K, 2)


def test_gradients_reach_the_maps(student, sandbox):
    g = torch.Generator().manual_seed(4)
    maps = torch.randn(2, 3, 5, 6, generator=g, dtype=torch.float64)
    seed = torch.randn(2, 3, 2, generator=g, dtype=torch.float64)
    value, (got,) = sandbox.grad(student.spatial_softmax, maps, wrt=(0,), grad_output=seed)
    assert got is not None, "no gradient reached the maps: compute the keypoints with torch ops (no .item(), numpy or argmax)"
    leaf = maps.clone().requires_grad_(True)
    (want,) = torch.autograd.grad(_torch_reference(leaf), (leaf,), seed)
    forward = torch.as_tensor(value).detach().double().numpy()
    why = "" if np.allclose(forward, reference(maps.numpy()), rtol=1e-7, atol=1e-9) else \
        f" (the keypoints themselves are wrong: {_diagnosis(forward, maps.numpy())})"
    assert_close(got, want, rtol=1e-7, atol=1e-9,
                 msg=lambda m: f"d keypoints / d maps differs from autograd through the softmax expectation{why}: {m}")


def test_plugs_into_the_encoder_layer(student, sandbox):
    g = torch.Generator().manual_seed(5)
    C, K = 4, 3
    x = torch.randn(2, C, 6, 7, generator=g)
    weight, bias = torch.randn(K, C, 1, 1, generator=g), torch.randn(K, generator=g)
    layer = sandbox.new("coursekit.nn.vision:SpatialSoftmax", C, K, keypoints_fn=student.spatial_softmax)
    sandbox.load_state_dict(layer, {"to_maps.weight": weight, "to_maps.bias": bias})
    got = layer(x)
    maps = torch.nn.functional.conv2d(x, weight, bias)  # (2, K, 6, 7), the 1x1 conv's heat maps
    want = torch.as_tensor(reference(maps.double().numpy()), dtype=torch.float32)
    assert torch.is_tensor(got) and tuple(got.shape) == (2, K, 2), (
        f"SpatialSoftmax with your function must return (B, K, 2) = (2, {K}, 2), got {tuple(getattr(got, 'shape', ()))}")
    assert_close(got, want, rtol=1e-4, atol=1e-5,
                 msg=lambda m: f"SpatialSoftmax's keypoints with your spatial_softmax differ from the reference: "
                               f"{_diagnosis(got.double().numpy(), maps.double().numpy())}")
