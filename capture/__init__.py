"""Dataset capture: scene sources, viewpoint sampling, the capture driver, the dataset format and
the per-tile target store, and the import of an engine's own frames (:func:`import_frames`).

Importing this package needs only numpy; rendering (:func:`capture`) needs ``rtp[capture]`` and
computing targets (:func:`compute_targets`) ``rtp[metrics]``, both imported when called.
"""

from ._capture import (
    MESH_EXTENSIONS,
    PROCEDURAL_PREFIX,
    CaptureReport,
    capture,
    check_disk,
    check_frame_size,
    check_scene,
    load_scene,
    scene_id,
)
from ._dataset import (
    BUFFERS,
    DatasetError,
    DatasetReader,
    DatasetWriter,
    PaperDatasetReader,
    Sample,
    open_dataset,
    write_png,
)
from ._images import (
    check_image_output,
    figure_image,
    image_values,
    read_image_values,
    save_image,
    text_width,
    wrap_to_width,
)
from ._import import ImportReport, import_frames, linear_light_warning
from ._memory import check_frame_memory, check_memory, job_bytes
from ._pool import WorkerDiedError, tick_queue, with_ticks, worker_pool, worker_threads
from ._preview import preview_sheet
from ._ray import RayExecutorError, RayWorkerError
from ._targets import BASE_TILE, MAX_WEBER_L, TargetError, TargetStore, compute_targets, pool_targets

__all__ = [
    "tick_queue",
    "with_ticks",
    "worker_pool",
    "worker_threads",
    "BASE_TILE",
    "BUFFERS",
    "MAX_WEBER_L",
    "MESH_EXTENSIONS",
    "PROCEDURAL_PREFIX",
    "CaptureReport",
    "DatasetError",
    "DatasetReader",
    "DatasetWriter",
    "ImportReport",
    "PaperDatasetReader",
    "RayExecutorError",
    "RayWorkerError",
    "Sample",
    "TargetError",
    "TargetStore",
    "WorkerDiedError",
    "capture",
    "check_disk",
    "check_frame_memory",
    "check_frame_size",
    "check_memory",
    "check_scene",
    "compute_targets",
    "check_image_output",
    "figure_image",
    "image_values",
    "import_frames",
    "read_image_values",
    "job_bytes",
    "linear_light_warning",
    "load_scene",
    "open_dataset",
    "pool_targets",
    "preview_sheet",
    "save_image",
    "scene_id",
    "text_width",
    "wrap_to_width",
    "write_png",
]
