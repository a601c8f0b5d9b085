"""How much of a model's miss is its input: the recipe trained on the frame itself instead of the
reprojected previous one.

    python bench/input_ceiling.py --metric lpips [--data data/train] [--out data/study/lpips-current-frame.pt]

An engine predicts from the previous frame reprojected into the current view: resampled, with holes
where the surface was not visible. This study trains the shipped recipe for ``--metric`` with that
plane replaced by the current full-rate frame (``final_1x1``, every pixel seen), then scores it on the
validation maps with the same substitution (``rtp evaluate`` and ``bench/residuals.py``'s per-output
table). No engine has that input: the model it writes must never ship (its metadata names the
reprojected planes it was not trained on; it lives under data/study). What it bounds is what a
better history (sharper resampling, no holes) could buy; the rest of the distance to
``bench/target_ceiling.py``'s ceiling is the network's.

The substitution patches ``rtp.capture.Sample.buffer`` in this process only; training resumes like
``rtp train`` (same output path, same configuration).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from _common import UsageError, dataset_folder, positive, run_main  # bench/ is on sys.path when run as a script

from rtp.capture import Sample, open_dataset
from rtp.capture.scenes import map_names
from rtp.cli import main as rtp_main
from rtp.sdk import METRICS


def use_current_frame() -> None:
    """Make every sample's ``reprojected`` buffer its own full-rate frame and ``seen`` all ones."""
    original = Sample.buffer

    def buffer(self: Sample, name: str) -> np.ndarray:
        if name == "reprojected":
            return original(self, "final_1x1")
        if name == "seen":
            return np.ones_like(original(self, "seen"))
        return original(self, name)

    Sample.buffer = buffer  # type: ignore[method-assign]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    # (checked here, not by the ``rtp train`` this runs: its usage line would name the wrong command)
    ap.add_argument("--metric", required=True, choices=tuple(METRICS), help="the metric whose shipped recipe is trained")
    ap.add_argument("--data", type=dataset_folder, default="data/train",
                    help="dataset with targets (default: data/train)")
    ap.add_argument("--out", default=None, help="checkpoint (default: data/study/METRIC-current-frame.pt)")
    ap.add_argument("--steps", type=positive, default=None, help="training steps (default: the recipe's)")
    ap.add_argument("--scene", default=",".join(map_names("validation")),
                    help="maps scored (default: the validation maps of scenes.yaml, which training holds out)")
    args = ap.parse_args(argv)
    # the maps scored, checked before the hours of training they come after
    reader = open_dataset(args.data)
    have = {str(reader[i].meta.get("scene")) for i in reader.ids}
    names = {n.strip() for n in args.scene.split(",") if n.strip()}
    if not names:
        raise UsageError(f"--scene: expected comma-separated map names, got {args.scene!r}")
    if names - have:
        raise UsageError(f"--scene: {', '.join(sorted(names - have))} not in {args.data}; it holds "
                         f"{', '.join(sorted(have))}")
    out = Path(args.out or f"data/study/{args.metric}-current-frame.pt")
    out.parent.mkdir(parents=True, exist_ok=True)
    use_current_frame()
    steps = ["--steps", str(args.steps)] if args.steps else []
    code = rtp_main(["train", "--data", args.data, "--metric", args.metric, "--out", str(out), *steps])
    if code:
        return code
    onnx = out.with_suffix(".onnx")
    _export(out, onnx)
    scenes = args.scene
    code = rtp_main(["evaluate", str(onnx), "--data", args.data, "--scene", scenes, "--no-baselines",
                     "--out", str(out.parent.parent / f"evalval-{out.stem}")])
    if code:
        return code
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import residuals  # bench/residuals.py, in this process so the substitution holds

    return residuals.main([str(onnx), "--data", args.data, "--scene", scenes])


def _export(ckpt: Path, onnx: Path) -> None:
    from rtp.export import export_checkpoint

    export_checkpoint(ckpt, onnx)
    print(f"exported {onnx} (trained on the current frame: a study model, never to ship)")


if __name__ == "__main__":
    run_main(main)
