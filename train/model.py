"""The networks: the paper's metric-prediction network (Section 3.1 and its appendix table of layers),
:class:`MetricNet`, kept as the reference, and rtp's fast family, :class:`FastNet`. Both map an
``(N, C, H, W)`` input to ``(N, R, H/w, W/w)`` values in (0, 1); :func:`build_network` makes either by
name (``rtp train --arch``), and a checkpoint records which.

The paper's network (``arch="paper"``):

Five blocks of ``Conv3x3 -> ReLU -> BatchNorm -> MaxPool``; the last block's BatchNorm feeds a
sigmoid. Pooling shrinks the frame by the tile size ``w`` in total (factors of 2, as early as
possible after the first, full-resolution layer), and hidden convolutions are split into groups
at the rate the pixel count falls, so groups x pixels stays about constant. For ``w = 16`` this is
exactly the paper's table:

=====  ===========  ============  ======  =======
layer  in channels  out channels  groups  pooling
=====  ===========  ============  ======  =======
1      inputs       16            1       1
2      16           16            1       2
3      16           16            4       2
4      16           16            8       2
5      16           outputs       1       2
=====  ===========  ============  ======  =======

``head="paper"`` is that table exactly; its last block applies ReLU before BatchNorm and the
sigmoid, so an output whose ReLU stops firing on every input predicts a constant (the "output
floor" of the paper's own ONNX files) and gets no gradient to recover. ``head="linear"`` drops that
last ReLU (conv -> BatchNorm -> sigmoid); it cannot die that way. Same parameter count.

Generalised to tile sizes 1..32 (see :func:`layer_plan`): layer i > 1 pools by 2 while pooling is
left; with ``w = 32`` the first layer pools as well. A hidden layer that follows p pooling steps
uses ``min(4**p, width // 2)`` groups (at least two channels per group), rounded to a divisor of
``width``. The network is fully convolutional: an ``H x W`` input gives ``H/w x W/w`` tiles.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from rtp.sdk import (
    ALL_RATES,
    BLOCK_CELL,
    BLOCK_EPS,
    BLOCK_RATES,
    BLOCK_TILE,
    DEFAULT_INPUTS,
    DEFAULT_OUTPUTS,
    DEFAULT_TILE_SIZE,
    TILE_SIZES,
    ParameterError,
    rate_size,
)

__all__ = ["ARCHS", "HEADS", "MAX_BLOCKS", "MAX_PARAMETERS", "BlockContrast", "EnergyNorm", "FastNet", "LayerSpec",
           "MetricNet", "Network", "StoredBlockContrast", "TileContrast", "build_network", "haar_details", "keep_outputs",
           "layer_plan"]

#: Most parameters :func:`build_network` builds (400 MB of float32 weights; rtp's networks hold 4,500-15,000):
#: a width or head typed with extra digits is refused before its memory is allocated, not OOM-killed.
MAX_PARAMETERS = 100_000_000
#: Most blocks (``depth``, ``coarse``) of the fast network.
MAX_BLOCKS = 256

#: ``paper``: the last block is conv -> ReLU -> BatchNorm -> sigmoid as in the paper's table;
#: ``linear``: conv -> BatchNorm -> sigmoid (no output can die).
HEADS = ("paper", "linear")


@dataclass(frozen=True)
class LayerSpec:
    in_channels: int
    out_channels: int
    groups: int
    pool: int


def layer_plan(in_channels: int, out_channels: int, tile: int, width: int) -> list[LayerSpec]:
    """The five layers of :class:`MetricNet` for a tile size and width."""
    if tile not in TILE_SIZES:
        raise ParameterError(f"tile must be one of {TILE_SIZES}, got {tile}")
    if width < 2:
        raise ParameterError(f"width must be at least 2, got {width}")
    if in_channels < 1 or out_channels < 1:
        raise ParameterError(f"in_channels and out_channels must be >= 1, got {in_channels}, {out_channels}")
    n_pools = int(math.log2(tile))
    pools = [2] * 5 if n_pools == 5 else [1] + [2] * n_pools + [1] * (4 - n_pools)
    plan: list[LayerSpec] = []
    pooled = 0
    for i in range(5):
        cin = in_channels if i == 0 else width
        cout = out_channels if i == 4 else width
        if i in (0, 4):
            groups = 1
        else:
            groups = math.gcd(min(4**pooled, width // 2), width)
        plan.append(LayerSpec(cin, cout, groups, pools[i]))
        if pools[i] > 1:
            pooled += 1
    return plan


class MetricNet(nn.Module):
    """Predicts, per ``tile x tile`` block, the transformed metric of each output rate.

    Input ``(N, in_channels, H, W)`` with H and W multiples of ``tile``; output
    ``(N, out_channels, H/tile, W/tile)`` in (0, 1).
    """

    def __init__(self, in_channels: int = len(DEFAULT_INPUTS), out_channels: int = len(DEFAULT_OUTPUTS),
                 tile: int = DEFAULT_TILE_SIZE, width: int = 16,
                 head: str = "paper") -> None:
        super().__init__()
        if head not in HEADS:
            raise ParameterError(f"head must be one of {HEADS}, got {head!r}")
        self.config: dict[str, Any] = {"in_channels": in_channels, "out_channels": out_channels, "tile": tile,
                                       "width": width, "head": head}
        layers: list[nn.Module] = []
        plan = layer_plan(in_channels, out_channels, tile, width)
        for i, spec in enumerate(plan):
            layers.append(nn.Conv2d(spec.in_channels, spec.out_channels, 3, padding=1, groups=spec.groups))
            if head == "paper" or i < len(plan) - 1:
                layers.append(nn.ReLU(inplace=True))
            layers.append(nn.BatchNorm2d(spec.out_channels))
            if spec.pool > 1:
                layers.append(nn.MaxPool2d(spec.pool))
        layers.append(nn.Sigmoid())
        self.layers = nn.Sequential(*layers)

    @property
    def tile(self) -> int:
        return int(self.config["tile"])

    @property
    def input_multiple(self) -> None:
        """None: floor-mode pooling needs whole tiles (the runtime pads frames up to them)."""
        return None

    def plan(self) -> list[dict[str, int]]:
        c = self.config
        return [asdict(s) for s in layer_plan(c["in_channels"], c["out_channels"], c["tile"], c["width"])]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.layers(x)


class EnergyNorm(nn.Module):
    """Each position's channels divided by their root mean square, with the log of the mean square
    appended as one more channel: ``(N, C, H, W) -> (N, C + 1, H, W)``. ``eps`` keeps a dark, flat
    position (all channels 0 after a ReLU) finite: its features stay 0 and its energy reads log(eps)."""

    def __init__(self, eps: float = 1e-2) -> None:
        super().__init__()
        self.eps = eps

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        e = x.pow(2).mean(dim=1, keepdim=True) + self.eps
        return torch.cat([x * torch.rsqrt(e), torch.log(e)], dim=1)


class ContextPool(nn.Module):
    """The mean of each feature over a ``size x size`` window around each position, appended as
    many channels again: ``(N, C, H, W) -> (N, 2C, H, W)``. Positions outside the frame (or the crop)
    do not count (``count_include_pad=False``), so a tile at the border averages what it has. At tile
    resolution a 9-tile window covers 144 pixels of a 16-pixel-tile frame: the neighbourhood whose
    error LPIPS's deep AlexNet features pool (about 200 pixels), at the cost of one pooling pass over
    the tile grid instead of more 3x3 blocks."""

    def __init__(self, size: int) -> None:
        super().__init__()
        if size < 3 or size % 2 == 0:
            raise ParameterError(f"context_pool must be an odd window of at least 3 tiles, got {size}")
        self.pool = nn.AvgPool2d(size, stride=1, padding=size // 2, count_include_pad=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([x, self.pool(x)], dim=1)


class CoarseContext(nn.Module):
    """Features of the neighbourhood at twice the tile's scale, appended: ``(N, C, H, W) -> (N, 2C, H, W)``.
    A 2x2 max-pool (ceil mode: a partial last tile pools what it has), ``blocks`` 3x3 conv -> BatchNorm ->
    ReLU blocks of ``width`` channels, a 1x1 back to ``C`` (BatchNorm, ReLU), then each coarse position
    repeated over the 2x2 tiles it covers (nearest-neighbour upsampling, cut to the tile grid). A block at
    1/32 resolution costs a quarter of one at tile resolution and sees twice as far: two of them widen
    what a tile's features see by about 256 pixels, towards the 200-pixel neighbourhood LPIPS's deep
    AlexNet features pool, with learned 3x3 mixing where :class:`ContextPool` only averages."""

    def __init__(self, channels: int, width: int = 64, blocks: int = 2) -> None:
        super().__init__()
        if channels < 1 or width < 2 or blocks < 1:
            raise ParameterError(f"coarse context: expected channels >= 1, width >= 2 and blocks >= 1, got {channels}, "
                             f"{width}, {blocks}")
        layers: list[nn.Module] = [nn.MaxPool2d(2, ceil_mode=True)]
        c = channels
        for _ in range(blocks):
            layers += [nn.Conv2d(c, width, 3, padding=1, bias=False), nn.BatchNorm2d(width), nn.ReLU(inplace=True)]
            c = width
        layers += [nn.Conv2d(c, channels, 1, bias=False), nn.BatchNorm2d(channels), nn.ReLU(inplace=True)]
        self.body = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = nn.functional.interpolate(self.body(x), scale_factor=2.0, mode="nearest")
        return torch.cat([x, y[:, :, : x.shape[2], : x.shape[3]]], dim=1)


def haar_details(cell: int) -> list[np.ndarray]:
    """The ``cell * cell - 1`` detail kernels of the orthonormal 2D Haar pyramid of a ``cell x cell``
    cell (a power of two): per level, each 2x2 group of the level's averages gives three differences
    (horizontal, vertical, diagonal), the averages go on to the next level. With the cell's mean
    they are an orthonormal basis of the cell."""
    if cell < 2 or cell & (cell - 1):
        raise ParameterError(f"the Haar pyramid needs a power-of-two cell of at least 2, got {cell}")
    grid = [[np.eye(cell * cell)[i * cell + j].reshape(cell, cell) for j in range(cell)] for i in range(cell)]
    out: list[np.ndarray] = []
    while len(grid) > 1:
        n = len(grid) // 2
        nxt = []
        for i in range(n):
            row = []
            for j in range(n):
                a, b, c, d = grid[2 * i][2 * j], grid[2 * i][2 * j + 1], grid[2 * i + 1][2 * j], grid[2 * i + 1][2 * j + 1]
                out += [(a - b + c - d) / 2, (a + b - c - d) / 2, (a - b - c + d) / 2]
                row.append((a + b + c + d) / 2)
            nxt.append(row)
        grid = nxt
    return out


def _check_planes(planes: tuple[int, ...], in_channels: int) -> None:
    """A block contrast's planes: distinct input channel indices, or a ValueError."""
    if not planes or len(set(planes)) != len(planes) or min(planes) < 0 or max(planes) >= in_channels:
        raise ParameterError(f"block_contrast: expected distinct input channel indices below {in_channels}, got "
                         f"{list(planes)}")


class BlockContrast(nn.Module):
    """What each reduced shading rate would lose of chosen input planes, per stem cell: for every
    rate whose block fits in the ``cell x cell`` stem cell, the mean over the cell of the variance
    inside the rate's blocks (the squared error of shading each block with its mean), as
    ``log(variance + eps)``: ``(N, C, H, W) -> (N, len(planes) * rates, H / cell, W / cell)``,
    plane-major.

    The renderer's software VRS shades each block once and repeats the sample, so what a rate
    loses of a plane that varies inside its blocks (the albedo of the current frame, the luma of
    the reprojected one) is about that variance. One linear stem read cannot compute it (it needs
    squares); here it is fixed arithmetic, nothing learned: the cell's orthonormal Haar details
    (:func:`haar_details`; per plane a slice and one strided convolution), squared; a rate's
    within-block error is the sum of the squared details that sum to zero over each of its blocks
    (the others are constant on them), one fixed 1x1 convolution. A cell larger than 4 pixels takes
    the mean of its 4x4 cells' values (the same number: every rate's blocks fit in 4x4 cells), and
    with ``tile_max`` also their maximum, as more channels (per plane: the means, then the maxima)."""

    weight: torch.Tensor
    reduce: torch.Tensor

    def __init__(self, planes: tuple[int, ...], in_channels: int, cell: int, eps: float = 1e-4,
                 tile_max: bool = False) -> None:
        super().__init__()
        _check_planes(planes, in_channels)
        self.planes = tuple(int(i) for i in planes)
        self.eps = eps
        self.rates = tuple(r for r in ALL_RATES[1:] if max(rate_size(r)) <= cell)
        if not self.rates:
            raise ParameterError(f"block_contrast needs a stem of at least 2 pixels, got {cell}")
        # Every rate's blocks fit in 4x4 cells: a larger cell's mean is the mean of its 4x4 cells' (the
        # cell's coarser Haar details are constant on every block), so measure 4x4 cells and average
        # them (16 taps a pixel per plane instead of cell * cell)
        base = min(cell, 4)
        details = haar_details(base)
        n, r = len(details), len(self.rates)
        reduce = torch.zeros(r, n, 1, 1)
        for j, rate in enumerate(self.rates):
            w, h = rate_size(rate)
            for i, d in enumerate(details):
                sums = d.reshape(base // h, h, base // w, w).sum(axis=(1, 3))
                if np.abs(sums).max() < 1e-9:  # zero on every block: part of what the rate loses
                    reduce[j, i] = 1.0 / (base * base)
        self.base, self.pool, self.tile_max = base, cell // base, bool(tile_max and cell > base)
        weight = torch.tensor(np.stack(details), dtype=torch.float32)[:, None]
        self.register_buffer("weight", weight, persistent=False)
        self.register_buffer("reduce", reduce, persistent=False)
        self.in_channels = in_channels
        self.cell = cell
        self.channels = len(self.planes) * r * (2 if self.tile_max else 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = []
        for p in self.planes:  # a slice of one plane and a one-input convolution: a fraction of a dense one
            c = nn.functional.conv2d(x[:, p:p + 1], self.weight, stride=self.base)
            v = nn.functional.conv2d(c * c, self.reduce)
            if self.pool > 1:
                out.append(torch.log(nn.functional.avg_pool2d(v, self.pool) + self.eps))
                if self.tile_max:  # the worst 4x4 cell as well: the targets are the worst error in a tile
                    out.append(torch.log(nn.functional.max_pool2d(v, self.pool) + self.eps))
            else:
                out.append(torch.log(v + self.eps))
        return out[0] if len(out) == 1 else torch.cat(out, dim=1)


class StoredBlockContrast(nn.Module):
    """:class:`BlockContrast` read from ``.blocks`` input planes instead of computed from the luma:
    ``sdk.block_variances`` stores, per 4x4 cell, each rate's ``log(variance + eps)`` rescaled to
    [0, 1] on one pixel of the cell (rate k on the cell's k-th pixel in raster order: the first two
    rows of the cell), so one slice of those rows (a reshape of the frame into cells, free, then
    one ONNX ``Slice`` of the planes' first two rows of each cell) and a fixed one-hot 2x4
    convolution with stride (2, 4) pick the six values of each plane, and undoing the rescale gives
    ``log(variance + eps)`` (at 1080p a third less time than a strided slice per value); a larger
    ``cell`` takes the log of the mean of ``variance + eps`` (and with ``tile_max`` the maximum) over
    its 4x4 cells, as :class:`BlockContrast` does. The adapters build the planes (on the GPU in the
    moderngl adapter), so the network pays only for the read: what makes a split network (the
    contrast at tile resolution) as cheap as one that reads the planes with its stem.

    The cells of a partial last tile (a 1080-row frame has half a tile row at the bottom) pool the
    cells they have, as the trunk's ceil-mode max-pools do; the mean is computed as a sum over the
    tile with the frame padded by zeros, divided by the number of its cells inside the frame
    (onnxruntime runs a ceil-mode average pool several times slower than this)."""

    pick: torch.Tensor

    def __init__(self, planes: tuple[int, ...], in_channels: int, cell: int, tile_max: bool = False) -> None:
        super().__init__()
        _check_planes(planes, in_channels)
        if cell % BLOCK_CELL:
            raise ParameterError(f"block_contrast from .blocks planes: the cell must be a multiple of {BLOCK_CELL}, got {cell}")
        if list(planes) != list(range(min(planes), min(planes) + len(planes))):
            raise ParameterError(f"block_contrast from .blocks planes: expected consecutive input channels, got {list(planes)}")
        self.planes = tuple(int(i) for i in planes)
        self.rates = tuple(BLOCK_RATES)
        self.rows = -(-len(self.rates) // BLOCK_CELL)  # the cell rows that hold the rates' values
        pick = torch.zeros(len(self.planes) * len(self.rates), len(self.planes), self.rows, BLOCK_CELL)
        for p in range(len(self.planes)):  # plane-major: rate k of plane p on pixel (k // 4, k % 4) of the cell
            for k in range(len(self.rates)):
                pick[p * len(self.rates) + k, p, k // BLOCK_CELL, k % BLOCK_CELL] = 1.0
        self.register_buffer("pick", pick, persistent=False)
        self.scale = -math.log(BLOCK_EPS)
        self.cell, self.pool = cell, cell // BLOCK_CELL
        self.tile_max = bool(tile_max and self.pool > 1)
        self.in_channels = in_channels
        self.channels = len(self.planes) * len(self.rates) * (2 if self.tile_max else 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n = len(self.rates)
        b, c, h, w = x.shape
        lo, hi = self.planes[0], self.planes[-1] + 1
        rows = x.reshape(b, c, h // BLOCK_CELL, BLOCK_CELL, w)[:, lo:hi, :, :self.rows]  # the cells' first rows
        stored = nn.functional.conv2d(rows.reshape(b, hi - lo, h // BLOCK_CELL * self.rows, w), self.pick,
                                      stride=(self.rows, BLOCK_CELL))
        if self.pool == 1:
            return (stored - 1.0) * self.scale  # log(variance + eps)
        q = self.pool
        # variance + eps up to the factor eps (taken back after the log); zeros beyond the frame, so a
        # floor-mode pool of the padded cells sums each tile's cells, and the same pool of a plane of
        # ones counts the share of them inside the frame
        v = nn.functional.pad(torch.exp(stored * self.scale), (0, q - 1, 0, q - 1))
        inside = nn.functional.pad(torch.ones_like(stored[:, :1]), (0, q - 1, 0, q - 1))
        mean = torch.log(nn.functional.avg_pool2d(v, q)) - torch.log(nn.functional.avg_pool2d(inside, q)) - self.scale
        if not self.tile_max:
            return mean
        worst = (nn.functional.max_pool2d(stored, q, ceil_mode=True) - 1.0) * self.scale
        return torch.cat([t for i in range(len(self.planes))
                          for t in (mean[:, i * n:(i + 1) * n], worst[:, i * n:(i + 1) * n])], dim=1)


class TileContrast(nn.Module):
    """:class:`StoredBlockContrast` with ``cell`` = the tile, read from ``.tiles`` input planes
    (``sdk.tile_variances``), which hold each tile's twelve values (per rate the log of the mean block
    variance over the tile's 4x4 cells, then the maximum) on its first pixels: one convolution with
    the tile as its stride and fixed one-hot weights (scaled to undo the planes' [0, 1] encoding)
    picks them, so the contrast costs a read of twelve pixels per tile and plane instead of a pass
    over the 4x4 cells. The same numbers as :class:`StoredBlockContrast` on the ``.blocks`` planes of
    the same frame (tests compare, partial tiles included): a network trained on either computes the
    same function. Its weight and bias are fixed buffers, not parameters.

    An adapter builds the planes (on the GPU in the moderngl adapter), so a split network's tail
    reads nothing finer than the tile grid, and a frame whose trunk features are carried costs a
    small fraction of a network run (docs/results.md "The tail at tile resolution")."""

    weight: torch.Tensor
    bias: torch.Tensor

    def __init__(self, planes: tuple[int, ...], in_channels: int, cell: int, tile_max: bool = False) -> None:
        super().__init__()
        _check_planes(planes, in_channels)
        if cell != BLOCK_TILE:
            raise ParameterError(f"block_contrast from .tiles planes: the cell must be their tile, {BLOCK_TILE}, got {cell}")
        self.planes = tuple(int(i) for i in planes)
        self.rates = tuple(BLOCK_RATES)
        self.cell = cell
        self.tile_max = bool(tile_max)
        per = len(self.rates) * (2 if self.tile_max else 1)  # the values read of each plane
        self.channels = len(self.planes) * per
        self.in_channels = in_channels
        scale = -math.log(BLOCK_EPS)
        rows = -(-per // BLOCK_CELL)
        weight = torch.zeros(self.channels, in_channels, rows, BLOCK_CELL)
        for p, channel in enumerate(self.planes):  # plane-major: means, then maxima, as StoredBlockContrast
            for j in range(per):
                weight[p * per + j, channel, j // BLOCK_CELL, j % BLOCK_CELL] = scale
        self.register_buffer("weight", weight, persistent=False)
        self.register_buffer("bias", torch.full((self.channels,), -scale), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return nn.functional.conv2d(x, self.weight, self.bias, stride=self.cell)  # (v - 1) * scale


class BlindConv2d(nn.Conv2d):
    """A strided stem convolution (kernel = stride, no bias) whose weights from the last ``blind``
    input channels are held at exactly zero: made zero at construction and whenever a state is
    loaded, and in training multiplied by a fixed mask, so no gradient reaches them (AdamW's decay
    keeps a zero at zero); evaluation and export read the plain weights (one ``Conv`` node that
    BatchNorm folds into). A split network's
    stem reads every input plane in one pass this way, the .blocks planes included, without its
    features depending on them: cheaper at run time than slicing the other planes out of the frame
    (onnxruntime copies a slice), and the trunk stays a function of the planes it may carry across
    frames."""

    mask: torch.Tensor

    def __init__(self, in_channels: int, out_channels: int, kernel: int, blind: int = 0) -> None:
        super().__init__(in_channels, out_channels, kernel, stride=kernel, bias=False)
        if not 0 < blind < in_channels:
            raise ParameterError(f"blind: expected 1 to {in_channels - 1} input channels, got {blind}")
        mask = torch.ones_like(self.weight)
        mask[:, in_channels - blind:] = 0.0
        self.blind = blind
        self.register_buffer("mask", mask, persistent=False)
        with torch.no_grad():
            self.weight.mul_(mask)

    def _load_from_state_dict(self, *args: Any, **kwargs: Any) -> None:
        super()._load_from_state_dict(*args, **kwargs)
        with torch.no_grad():
            self.weight.mul_(self.mask)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self._conv_forward(x, self.weight * self.mask if self.training else self.weight, None)


class FastNet(nn.Module):
    """rtp's fast network: a strided stem, then conv -> BatchNorm -> ReLU blocks at low resolution.

    The paper's network spends most of its time in two 3x3 convolutions at full resolution. Here a
    ``stem x stem`` convolution with stride ``stem`` (4 by default) reads every pixel once and
    leaves a quarter-resolution feature map; ``depth`` 3x3 blocks follow, the first ones each at a
    coarser scale (a 2x2 max-pool after each, until the tile size is reached), any further ones at
    tile resolution, where they are almost free and widen the context each tile sees; a 1x1
    convolution and a sigmoid give the outputs (no ReLU before it: no output can die). Every
    convolution is followed by BatchNorm before its ReLU, so BatchNorm folds into the convolution at
    export. ``context_pool`` K > 0 appends, before the head, the mean of the last block's features
    over a K x K window of tiles (:class:`ContextPool`): what the neighbourhood holds, for a metric
    whose per-tile value depends on it. ``coarse`` N > 0 appends, after the first block at tile
    resolution, features of the neighbourhood from N 3x3 blocks of ``coarse_width`` channels at twice
    the tile's scale (:class:`CoarseContext`): a wider view, learned, at a quarter of a tile block's
    cost per channel. ``width`` channels throughout, unless ``grow`` is 2: then each block after a pool doubles
    them (16, 32, 64 for width 16 and depth 3), widening the cheap low-resolution end while the
    full-resolution read stays at ``width``; ``max_width`` caps what it doubles to (16, 32, 32, 32, 32
    for depth 5 and ``max_width`` 32: most of the tile-resolution weights at a quarter of their cost).
    ``separable`` makes each 3x3 block depthwise-separable (a 3x3 convolution per channel, BatchNorm,
    ReLU, then a 1x1 across channels, BatchNorm, ReLU: MobileNet's block), about a ninth of a block's
    multiply-adds, so the network can be twice as wide for the same cost at 1/4 resolution.
    ``separable_tail`` makes only the blocks at tile resolution (after the last pool) so: with
    ``grow`` 2 a 64-channel end at about a seventh of its cost, the frame still read by full 3x3 blocks.
    ``tail_width`` N > 0 gives the blocks at tile resolution (after the last pool) N channels whatever
    ``grow`` gives them: with width 16 and depth 5, 16 / 16 / N / N / N, capacity where a block costs a
    sixteenth of one at 1/4 resolution, the frame still read at 16 channels (``grow`` 2 also widens the
    1/8 block, which costs four times as much per channel).
    ``head_width`` N > 0 makes the head a small per-tile MLP: a 1x1 convolution to N channels,
    BatchNorm, ReLU, then the 1x1 to the outputs. At tile resolution it is almost free (a 1080p frame
    has 8,160 16-pixel tiles: 1,000 multiply-adds per tile for N = 64 and width 16) and turns the
    linear read-out of the last block's features into a nonlinear one, the function class a ratio of
    energies such as LPIPS's asks for, without widening any 3x3 block.
    ``energy_norm`` divides the features after the first
    block and pool (after the stem where there is no pool) at each position by their root mean square
    over the channels and appends its logarithm as one more channel (:class:`EnergyNorm`, LPIPS's own
    normalisation of AlexNet features), so a ratio of local energies, which LPIPS's value is, becomes
    a difference the next blocks can take. ``stem_layers`` 2 splits the stem in two: a
    ``stem/2 x stem/2`` convolution with that stride to ``width / 2`` channels, BatchNorm and ReLU,
    then a 2x2 stride-2 one to ``width`` (for stem 4: two 2x2 reads, a nonlinearity at half
    resolution that can see contrast inside each 4x4 cell, which one linear 4x4 read cannot). For
    width 16, depth 3, grow 1, one stem layer, the layers are:

    =========  ============  =====================  ==========
    layer      resolution    channels               parameters
    =========  ============  =====================  ==========
    stem 4x4   1/4           4 -> 16                1,024 (+32 BatchNorm)
    3x3 block  1/4, pool     16 -> 16               2,304 (+32)
    3x3 block  1/8, pool     16 -> 16               2,304 (+32)
    3x3 block  1/16          16 -> 16               2,304 (+32)
    1x1 head   1/16          16 -> 4                68
    =========  ============  =====================  ==========

    8,132 parameters (the paper's network: 4,524), about a tenth of its multiply-adds.
    """

    def __init__(self, in_channels: int = len(DEFAULT_INPUTS), out_channels: int = len(DEFAULT_OUTPUTS),
                 tile: int = DEFAULT_TILE_SIZE, width: int = 16, depth: int = 3, stem: int = 4, grow: int = 1,
                 stem_layers: int = 1, energy_norm: bool = False, max_width: int = 0,
                 separable: bool = False, head_width: int = 0, context_pool: int = 0,
                 block_contrast: tuple[int, ...] | list[int] = (), contrast_cell: int = 0,
                 separable_tail: bool = False, tail_width: int = 0, contrast_max: bool = False,
                 contrast_stored: bool = False, contrast_tiles: bool = False, coarse: int = 0,
                 coarse_width: int = 64) -> None:
        super().__init__()
        if tile not in TILE_SIZES:
            raise ParameterError(f"tile must be one of {TILE_SIZES}, got {tile}")
        if width < 2 or not 0 <= depth <= MAX_BLOCKS or stem not in (1, 2, 4, 8) or grow not in (1, 2):
            raise ParameterError(f"expected width >= 2, depth in [0, {MAX_BLOCKS}], stem in (1, 2, 4, 8) and grow 1 or 2, "
                             f"got {width}, {depth}, {stem}, {grow}")
        if max_width and (grow == 1 or max_width < width):
            raise ParameterError(f"max_width caps grow 2's channels: expected 0 (none), or >= width ({width}) with grow 2, "
                             f"got {max_width} with grow {grow}")
        if stem_layers not in (1, 2) or (stem_layers == 2 and min(stem, tile) < 2):
            raise ParameterError(f"stem_layers must be 1, or 2 with a stem (and tile) of at least 2, got {stem_layers} "
                             f"with stem {stem} and tile {tile}")
        if in_channels < 1 or out_channels < 1:
            raise ParameterError(f"in_channels and out_channels must be >= 1, got {in_channels}, {out_channels}")
        pools = int(math.log2(tile // min(stem, tile)))
        if tail_width and (tail_width < 2 or depth <= pools):
            raise ParameterError(f"tail_width sets the channels of the blocks at tile resolution: expected 0 (none), or >= 2 "
                             f"with a depth over the {pools} pooled blocks, got {tail_width} with depth {depth}")
        if head_width < 0:
            raise ParameterError(f"head_width must be 0 (a linear 1x1 head) or the hidden channels of an MLP head, got "
                             f"{head_width}")
        if context_pool and (context_pool < 3 or context_pool % 2 == 0):
            raise ParameterError(f"context_pool must be 0 (none) or an odd window of at least 3 tiles, got {context_pool}")
        if not 0 <= coarse <= MAX_BLOCKS or (coarse and (depth <= pools or coarse_width < 2)):
            raise ParameterError(f"coarse: expected 0 (none), or the blocks at twice the tile's scale after the first block at "
                             f"tile resolution (a depth over the {pools} pooled blocks, coarse_width >= 2), got coarse "
                             f"{coarse} with depth {depth} and coarse_width {coarse_width}")
        self.config: dict[str, Any] = {"in_channels": in_channels, "out_channels": out_channels, "tile": tile,
                                       "width": width, "depth": depth, "stem": stem}
        if grow != 1:  # checkpoints from before the option hold no "grow"
            self.config["grow"] = grow
        if max_width:  # likewise
            self.config["max_width"] = max_width
        if separable:  # likewise
            self.config["separable"] = True
        if separable_tail:  # likewise
            self.config["separable_tail"] = True
        if tail_width:  # likewise
            self.config["tail_width"] = tail_width
        if stem_layers != 1:  # likewise
            self.config["stem_layers"] = stem_layers
        if energy_norm:  # likewise
            self.config["energy_norm"] = True
        if head_width:  # likewise
            self.config["head_width"] = head_width
        if context_pool:  # likewise
            self.config["context_pool"] = context_pool
        if coarse:  # likewise
            self.config.update(coarse=coarse, coarse_width=coarse_width)
        s = min(stem, tile)
        pools = int(math.log2(tile // s))
        cell = contrast_cell or s
        if block_contrast and cell not in [s * 2 ** i for i in range(pools + 1)]:
            raise ParameterError(f"contrast_cell: expected the stem ({s}) or a pooled resolution up to the tile "
                             f"({', '.join(str(s * 2 ** i) for i in range(pools + 1))}), got {contrast_cell}")
        if contrast_max and (not block_contrast or cell <= 4):
            raise ParameterError(f"contrast_max adds the worst 4x4 cell of a larger contrast cell: expected block_contrast "
                             f"and a contrast_cell over 4, got {cell}")
        if contrast_stored and (not block_contrast or sorted(block_contrast) != list(
                range(in_channels - len(block_contrast), in_channels))):
            raise ParameterError(f"contrast_stored reads the block contrast from .blocks or .tiles planes that only it reads: "
                             f"expected block_contrast to be the last input channels, got {list(block_contrast)} of "
                             f"{in_channels}")
        if contrast_tiles and not (contrast_stored and cell == tile == BLOCK_TILE):
            raise ParameterError(f"contrast_tiles reads the block contrast from .tiles planes of {BLOCK_TILE}-pixel tiles: "
                             f"expected contrast_stored, tile {BLOCK_TILE} and contrast_cell {BLOCK_TILE}, got "
                             f"contrast_stored={contrast_stored}, tile {tile}, contrast_cell {cell}")
        if contrast_cell and not block_contrast:  # (built without a contrast, the cell taken and ignored, as rtp train refuses)
            raise ParameterError(f"contrast_cell: the cell of the block contrast, read only with block_contrast (the planes "
                                 f"to measure): expected 0 without it, got {contrast_cell}", "contrast_cell")
        self.contrast: BlockContrast | StoredBlockContrast | TileContrast | None = None
        if block_contrast and contrast_tiles:
            self.contrast = TileContrast(tuple(block_contrast), in_channels, cell, tile_max=contrast_max)
        elif block_contrast and contrast_stored:
            self.contrast = StoredBlockContrast(tuple(block_contrast), in_channels, cell, tile_max=contrast_max)
        elif block_contrast:
            self.contrast = BlockContrast(tuple(block_contrast), in_channels, cell, tile_max=contrast_max)
        #: the last input channels the stem is blind to (stored .blocks or .tiles planes, which only the contrast reads)
        self.blind = len(block_contrast) if contrast_stored else 0
        if self.contrast is not None:  # likewise
            self.config["block_contrast"] = list(self.contrast.planes)
            if contrast_cell and contrast_cell != s:
                self.config["contrast_cell"] = contrast_cell
            if contrast_max:
                self.config["contrast_max"] = True
            if contrast_stored:
                self.config["contrast_stored"] = True
            if contrast_tiles:
                self.config["contrast_tiles"] = True
        layers: list[nn.Module] = []
        def stem_conv(out: int, k: int) -> nn.Conv2d:  # a plain convolution unless some planes are hidden from it
            if self.blind:
                return BlindConv2d(in_channels, out, k, self.blind)
            return nn.Conv2d(in_channels, out, k, stride=k, bias=False)

        if stem_layers == 2:
            mid = max(width // 2, 1)
            layers += [stem_conv(mid, s // 2), nn.BatchNorm2d(mid),
                       nn.ReLU(inplace=True), nn.Conv2d(mid, width, 2, stride=2, bias=False)]
        else:
            layers.append(stem_conv(width, s))
        layers += [nn.BatchNorm2d(width), nn.ReLU(inplace=True)]
        c = width
        self._contrast_at = len(layers)
        if self.contrast is not None:  # the fixed per-rate contrast beside the features of its resolution
            self.contrast_bn = nn.BatchNorm2d(self.contrast.channels)
            if cell == s:
                c += self.contrast.channels
        if energy_norm and not pools:
            layers.append(EnergyNorm())
            c += 1
        for i in range(max(depth, pools)):
            if i < depth:
                # grow 2: each block after a pool doubles the channels (cheap at 1/8 and 1/16 resolution)
                out = width * grow ** min(i, pools)
                out = min(out, max_width) if max_width else out
                out = tail_width if tail_width and i >= pools else out
                if separable or (separable_tail and i >= pools):
                    layers += [nn.Conv2d(c, c, 3, padding=1, groups=c, bias=False), nn.BatchNorm2d(c),
                               nn.ReLU(inplace=True), nn.Conv2d(c, out, 1, bias=False)]
                else:
                    layers.append(nn.Conv2d(c, out, 3, padding=1, bias=False))
                layers += [nn.BatchNorm2d(out), nn.ReLU(inplace=True)]
                c = out
                if coarse and i == pools:  # after the first block at tile resolution, so the next ones mix it in
                    layers.append(CoarseContext(c, coarse_width, coarse))
                    c *= 2
            if i < pools:
                # ceil_mode: a frame of any multiple of the stem gives ceil(H / tile) tile rows, the last
                # partial tile pooling the pixels it has (identical to floor mode on whole tiles)
                layers.append(nn.MaxPool2d(2, ceil_mode=True))
                if energy_norm and i == 0:  # after the first pool: a quarter of the stem's positions to normalise
                    layers.append(EnergyNorm())
                    c += 1
                if self.contrast is not None and cell == s * 2 ** (i + 1):
                    self._contrast_at = len(layers)
                    c += self.contrast.channels
        if context_pool:
            layers.append(ContextPool(context_pool))
            c *= 2
        if head_width:
            layers += [nn.Conv2d(c, head_width, 1, bias=False), nn.BatchNorm2d(head_width), nn.ReLU(inplace=True)]
            c = head_width
        layers += [nn.Conv2d(c, out_channels, 1), nn.Sigmoid()]
        self.layers = nn.Sequential(*layers)

    @property
    def tile(self) -> int:
        return int(self.config["tile"])

    @property
    def input_multiple(self) -> int:
        """Frames need only be a multiple of the stem's stride (metadata ``input_multiple``): the
        runtime pads a 1920x1080 frame not at all where whole 16-pixel tiles would need 1088 rows."""
        # a computed contrast's strided read takes whole cells; a stored one reads 4x4 cells and pools them
        # in ceil mode (.tiles planes: a tile's values lie on its first 3 rows and 4 columns, inside any
        # multiple of 4)
        cell = 0 if self.contrast is None else BLOCK_CELL if isinstance(self.contrast, (StoredBlockContrast, TileContrast)) \
            else self.contrast.cell
        return max(min(int(self.config["stem"]), self.tile), cell)

    @property
    def splits(self) -> bool:
        """Whether ``rtp-export`` splits the network into a trunk whose per-tile features a runtime carries
        across frames and a tail (metadata ``tail``): its block contrast is read from stored planes
        (``contrast_stored``) and joins at tile resolution. A stored contrast that joins at a finer cell (the
        stem's, or after a pool short of the tile) is exported as one graph: its trunk's features are not
        per tile."""
        return self.contrast is not None and bool(self.config.get("contrast_stored")) and self.contrast.cell == self.tile

    def trunk(self, x: torch.Tensor) -> torch.Tensor:
        """The features before the block contrast joins (the whole network's output without one); with
        ``contrast_stored`` they do not depend on the .blocks or .tiles planes."""
        return self.layers(x) if self.contrast is None else self.layers[:self._contrast_at](x)

    def tail(self, features: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """The outputs from :meth:`trunk`'s features (of this frame, or carried from an earlier one)
        and the block contrast of ``x``."""
        if self.contrast is None:
            raise ParameterError("a network without block contrast does not split: its trunk is the whole network")
        h = torch.cat([features, self.contrast_bn(self.contrast(x))], dim=1)
        return self.layers[self._contrast_at:](h)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.trunk(x)
        return h if self.contrast is None else self.tail(h, x)


#: A network rtp trains and exports.
Network = MetricNet | FastNet

#: ``rtp train --arch NAME``: the network classes by name.
ARCHS: dict[str, type[MetricNet] | type[FastNet]] = {"paper": MetricNet, "fast": FastNet}


def build_network(arch: str, in_channels: int, out_channels: int, tile: int, *, width: int = 16,
                  head: str = "paper", depth: int = 3, stem: int = 4, grow: int = 1, stem_layers: int = 1,
                  energy_norm: bool = False, max_width: int = 0, separable: bool = False,
                  head_width: int = 0, context_pool: int = 0, block_contrast: tuple[int, ...] = (),
                  contrast_cell: int = 0, separable_tail: bool = False, tail_width: int = 0,
                  contrast_max: bool = False, contrast_stored: bool = False, contrast_tiles: bool = False,
                  coarse: int = 0, coarse_width: int = 64) -> Network:
    """The network ``arch`` (one of :data:`ARCHS`) for the given channels and tile size. ``head``
    applies to the paper's network, ``depth``, ``stem``, ``grow``, ``max_width``, ``stem_layers``, ``energy_norm``,
    ``separable``, ``separable_tail``, ``tail_width``, ``head_width``, ``context_pool``, ``block_contrast``, ``contrast_cell``
    ``contrast_max``, ``contrast_stored``, ``contrast_tiles``, ``coarse`` and ``coarse_width`` to the fast one. As in
    ``rtp train``, one network's option given with the other ``arch`` (``head="linear"`` with ``"fast"``, ``depth=5``
    with ``"paper"``) is refused with a :class:`ParameterError` naming it, not ignored."""
    counts = {"in_channels": in_channels, "out_channels": out_channels, "tile": tile, "width": width, "depth": depth,
              "stem": stem, "grow": grow, "stem_layers": stem_layers, "max_width": max_width, "head_width": head_width,
              "context_pool": context_pool, "contrast_cell": contrast_cell, "tail_width": tail_width, "coarse": coarse,
              "coarse_width": coarse_width}
    flags = {"energy_norm": energy_norm, "separable": separable, "separable_tail": separable_tail,
             "contrast_max": contrast_max, "contrast_stored": contrast_stored, "contrast_tiles": contrast_tiles}
    for key, value in counts.items():  # (True for a channel count reached torch as a bool size)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ParameterError(f"{key}: expected an integer >= 0, got {value!r}")
    for key, value in flags.items():
        if not isinstance(value, bool):
            raise ParameterError(f"{key}: expected True or False, got {value!r}")
    if not isinstance(block_contrast, (tuple, list)) or not all(
            isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in block_contrast):
        raise ParameterError(f"block_contrast: expected input channel indices, got {block_contrast!r}")
    if not isinstance(arch, str) or arch not in ARCHS:
        raise ParameterError(f"arch must be one of {tuple(ARCHS)}, got {arch!r}")
    if arch != "paper" and head != "paper":  # (rtp train refuses it too: the fast network reads no head)
        raise ParameterError(f"head: the paper network's option (the fast network's head has no ReLU before its "
                             f"sigmoid; head_width sets it), got head {head!r} with arch {arch!r}", "head")
    if arch == "paper":  # the fast network's options, each away from its default, would be taken and ignored
        # (not coarse_width: the width of coarse blocks, of which there are none without coarse, as in rtp train)
        fast_defaults = {"depth": 3, "stem": 4, "grow": 1, "stem_layers": 1, "max_width": 0, "head_width": 0,
                         "context_pool": 0, "contrast_cell": 0, "tail_width": 0, "coarse": 0,
                         "energy_norm": False, "separable": False, "separable_tail": False, "contrast_max": False,
                         "contrast_stored": False, "contrast_tiles": False, "block_contrast": ()}
        given = {**counts, **flags, "block_contrast": tuple(block_contrast)}
        wrong = next((k for k, v in fast_defaults.items() if given[k] != v), None)
        if wrong is not None:
            raise ParameterError(f"{wrong}: the fast network's option (the paper's network has its own fixed layers), "
                                 f"got {wrong} {given[wrong]!r} with arch 'paper'", wrong)

    def build() -> Network:
        if arch == "paper":
            return MetricNet(in_channels, out_channels, tile, width, head)
        return FastNet(in_channels, out_channels, tile, width, depth, stem, grow, stem_layers, energy_norm, max_width,
                       separable, head_width, context_pool, block_contrast, contrast_cell, separable_tail, tail_width,
                       contrast_max, contrast_stored, contrast_tiles, coarse, coarse_width)

    try:  # first on torch's meta device, which allocates nothing: its size is known before its memory is taken
        with torch.device("meta"):
            n = sum(p.numel() for p in build().parameters())
    except RuntimeError as err:  # (a size past what torch can describe)
        raise ParameterError(f"the {arch} network of these sizes cannot be built: {err}") from err
    if n > MAX_PARAMETERS:
        raise ParameterError(f"the {arch} network would hold {n:,} parameters ({4 * n / 2**30:.1f} GiB of weights), more "
                             f"than {MAX_PARAMETERS:,}: check the widths (width {width}, head_width {head_width}, "
                             f"tail_width {tail_width}, coarse_width {coarse_width}, max_width {max_width})")
    return build()


def keep_outputs(net: FastNet, n: int) -> FastNet:
    """A copy of ``net`` with only its first ``n`` outputs: the head's last 1x1 convolution cut to its
    first ``n`` rows, every other weight as it is (the predictions of those outputs are unchanged).
    Training with auxiliary targets (``TrainConfig.aux_metrics``) saves the network so: the extra
    outputs taught the features and cost nothing at run time."""
    if not isinstance(net, FastNet):
        raise ParameterError(f"keep_outputs: expected a FastNet, got {type(net).__name__}")
    total = int(net.config["out_channels"])
    if not 1 <= n <= total:
        raise ParameterError(f"keep_outputs: expected 1 to {total} outputs, got {n}")
    out = FastNet(**{**net.config, "out_channels": n})
    head = len(net.layers) - 2  # the last 1x1 convolution, before the sigmoid
    state = {k: (v[:n] if k in (f"layers.{head}.weight", f"layers.{head}.bias") else v)
             for k, v in net.state_dict().items()}
    out.load_state_dict(state)
    out.train(net.training)
    return out
