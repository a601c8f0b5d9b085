"""The public surface: pinned names, layout rules, console scripts."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from rtp import sdk

ROOT = Path(__file__).resolve().parents[1]


def test_sdk_all_is_pinned() -> None:
    assert sdk.__all__ == [
        "ALL_RATES",
        "BLOCK_CELL",
        "BLOCK_EPS",
        "BLOCK_RATES",
        "BLOCK_TILE",
        "CAMERA_KINDS",
        "CHANNELS",
        "COMBINERS",
        "DEFAULT_EXTRAPOLATION_K",
        "DEFAULT_INPUTS",
        "DEFAULT_OUTPUTS",
        "DEFAULT_REPROJECTION_TOLERANCE",
        "DEFAULT_TILE_SIZE",
        "DEPTH_KINDS",
        "EXIT_FAILED",
        "EXIT_USAGE",
        "FEATURES_NAME",
        "GBUFFERS",
        "LOGIT_EPS",
        "LUMA_WEIGHTS",
        "MAX_CARRY_SCALE",
        "MAX_RATE_FACTOR",
        "MAX_REPROJECTION_TOLERANCE",
        "MAX_RESCALE",
        "MAX_SAVING",
        "MAX_THRESHOLD",
        "METADATA_KEY",
        "METRICS",
        "METRIC_NAME_PATTERN",
        "NORMAL_SPACES",
        "OUTPUT_SETS",
        "OVERLAY_COLOURS",
        "OVERLAY_PALETTES",
        "PREDICTED_RATES",
        "RATE_CODES",
        "RATE_NAMES",
        "REUSE_CARRIES",
        "REUSE_REDUCTIONS",
        "REUSE_UNSEEN",
        "SCHEMA_VERSION",
        "TAIL_KEY",
        "TARGET_METRICS",
        "TILE_SIZES",
        "Channel",
        "InferenceError",
        "InputChannelError",
        "InputDtypeError",
        "InputError",
        "InputShapeError",
        "MetadataError",
        "ModelIntegrityError",
        "ModelLoadError",
        "ModelMetadata",
        "MetricInfo",
        "ModelNotFoundError",
        "NonFiniteInputError",
        "ParameterError",
        "PredictionReuse",
        "ProviderUnavailableError",
        "RateLike",
        "SavingSelection",
        "RtpError",
        "ShadingRatePredictor",
        "Transform",
        "adapters",
        "block_variances",
        "check_gbuffers",
        "check_projection",
        "check_reprojection",
        "check_threshold",
        "combine_rates",
        "complete_rates",
        "depth_edges",
        "draw_rate_overlay",
        "exit_code",
        "extrapolate",
        "fetch_from_motion",
        "files",
        "gbuffers_needed",
        "hardware_tiles",
        "input_planes",
        "linear_to_srgb",
        "load",
        "luma",
        "model_digest",
        "mse_from_psnr",
        "padded_size",
        "pixel_differences",
        "pool_tiles",
        "psnr_from_mse",
        "rate_size",
        "reproject",
        "reproject_positions",
        "resolve_allowed",
        "select_rates",
        "select_rates_for_saving",
        "shipped_models",
        "split_tiles",
        "srgb_to_linear",
        "tile_extents",
        "tile_grid",
        "tile_variances",
        "work_saved",
    ]
    public = sorted(n for n in vars(sdk) if not n.startswith("_") and n not in ("annotations", "logging"))
    assert public == sorted(sdk.__all__)
    assert sdk.ShadingRatePredictor.__module__ == "rtp.sdk"


def test_error_tree() -> None:
    for name in sdk.__all__:
        obj = getattr(sdk, name)
        if isinstance(obj, type) and issubclass(obj, Exception):
            assert issubclass(obj, sdk.RtpError), name
    assert issubclass(sdk.ModelNotFoundError, FileNotFoundError)
    assert issubclass(sdk.InputShapeError, ValueError) and issubclass(sdk.InputChannelError, sdk.InputShapeError)
    assert issubclass(sdk.InputDtypeError, TypeError) and issubclass(sdk.MetadataError, ValueError)


def test_sdk_imports_no_torch_or_gl() -> None:
    code = (
        "import sys, json; from rtp import sdk; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('torch', 'moderngl', 'OpenGL', 'pyrender', 'onnx', 'flip_evaluator', 'rtp'))))"
    )
    mods = json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
    assert not [m for m in mods if not m.startswith("rtp")], mods
    assert all(m == "rtp" or m.startswith("rtp.sdk") for m in mods), mods


def test_sdk_sources_import_only_the_runtime_stack() -> None:
    allowed = {"numpy", "onnxruntime", "yaml", "__future__"}
    import ast

    for path in (ROOT / "sdk").glob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            for n in names:
                top = n.split(".")[0]
                assert top in allowed or top in sys.stdlib_module_names, f"{path.name} imports {n}"


def test_py_typed_markers() -> None:
    for folder in ("sdk", "export", "train", "metrics", "capture", "plugins/moderngl"):
        assert (ROOT / folder / "py.typed").is_file()


def test_console_scripts_answer_help() -> None:
    bindir = Path(sys.executable).parent
    for script in ("rtp", "rtp-export"):
        r = subprocess.run([str(bindir / script), "--help"], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and "usage" in r.stdout
