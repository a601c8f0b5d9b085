"""Training: the network, checkpoints, the training loop and safety calibration.

Importing this package needs torch (the ``rtp[train]`` extra). Scores and evaluation are
:mod:`rtp.evaluate`'s (no torch); targets and the dataset are :mod:`rtp.capture`'s.
"""

from ._loop import TrainConfig, TrainingDivergedError, TrainResult, step_bytes, train
from ._recipe import SHIPPED_RECIPE, Recipe, RecipeError, load_recipe, packaged_recipes
from ._safety import calibrate_safety

__all__ = [
    "SHIPPED_RECIPE",
    "Recipe",
    "RecipeError",
    "TrainConfig",
    "TrainResult",
    "TrainingDivergedError",
    "calibrate_safety",
    "load_recipe",
    "packaged_recipes",
    "step_bytes",
    "train",
]
