"""Training: the network, checkpoints, the training loop and safety calibration.

Importing this package needs torch (the ``rtp[train]`` extra). Scores and evaluation are
:mod:`rtp.evaluate`'s (no torch); targets and the dataset are :mod:`rtp.capture`'s.
"""

from ._loop import TrainConfig, TrainResult, train
from ._safety import calibrate_safety

__all__ = [
    "TrainConfig",
    "TrainResult",
    "calibrate_safety",
    "train",
]
