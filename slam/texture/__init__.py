"""Floor texture mapping: the colours of the floor, from RGB-D frames, on the run's map grid.

The last stage of ``slam run`` (and ``slam texture RUN_DIR``), top to bottom (docs/texture.md):

1. **Frame pairing** (:mod:`slam.texture.pairing`): every ``frame_stride``-th RGB frame whose PNG
   exists is paired with the disparity frame nearest in time (among those whose PNG exists) when
   they are at most ``pair_tolerance_s`` apart; frames outside the trajectory's time span are
   skipped (poses are never extrapolated). Every skipped frame is counted by reason.
2. **Poses** (:func:`~slam.texture.pairing.frame_poses`): the robot pose at the disparity frame's
   time and at the RGB frame's time, linearly interpolated from the trajectory.
3. **Projection and floor extraction** (:mod:`slam.texture.kernels`, one fused numba pass over
   the disparity image): disparity → depth (course formula) → optical point (intrinsics of
   :class:`~slam.kinect.KinectModel`, cx ≈ 315.8 column, cy ≈ 242.9 row) → world point (camera
   extrinsics, pose at the disparity time). Points with a depth in ``[min_depth, max_depth]`` and
   a height within ``±floor_height`` of the floor plane are floor.
4. **Colour**: the floor point is projected back into the depth camera at the pose of the RGB
   frame's time (motion compensation: the two frames are up to tens of milliseconds apart) and the
   course's RGB alignment formula gives the RGB pixel, read at the nearest pixel.
5. **Accumulation** per map cell (:mod:`slam.texture.accumulate`): ``mean`` keeps the running
   mean of every floor sample, ``latest`` the mean of the most recent frame that saw the cell.
6. **Outputs** (:mod:`slam.texture.outputs`): ``texture.npz``, ``texture.png`` (same pixels as
   ``map.png``) and ``texture_overlay.png``.
7. **Evaluation** against a simulated dataset's ground truth (:mod:`slam.texture.evaluate`):
   colour error over the true floor cells that were coloured, and coverage of the *swept* floor.

:mod:`slam.texture.stage` ties them together for ``slam run`` (:func:`run_stage`) and for a
finished run (:func:`recompute_run`). Bad frames (missing or unreadable PNG, wrong image size,
more timestamps than files) are skipped with one :class:`TextureWarning` per reason and counted
in the metrics; they never stop a run.

This package re-exports the names other code uses, so ``from slam.texture import run_stage``
keeps working whichever module holds it.
"""

from __future__ import annotations

from slam.config import TEXTURE_MODES
from slam.texture.accumulate import (
    UNSEEN_COLOR,
    TextureAccumulator,
    TextureMap,
    TextureResult,
    build_texture,
    warm_up,
)
from slam.texture.evaluate import (
    GroundTruth,
    TrueTexture,
    evaluate_texture,
    load_ground_truth,
    swept_cells,
)
from slam.texture.kernels import (
    CameraParameters,
    accumulate_frame,
    camera_in_world,
    camera_parameters,
    depth_table,
    kinect_model,
    mark_swept,
)
from slam.texture.outputs import display_scale, render_overlay, render_texture, write_outputs
from slam.texture.pairing import (
    SKIP_REASONS,
    FramePlan,
    TextureWarning,
    frame_numbers,
    frame_poses,
    nearest_frames,
    pair_frames,
    plan_frames,
)
from slam.texture.stage import (
    RUN_FILES,
    images_missing,
    read_map,
    recompute_run,
    run_stage,
    texture_stage,
    update_metrics,
)

__all__ = [
    "RUN_FILES",
    "SKIP_REASONS",
    "TEXTURE_MODES",
    "UNSEEN_COLOR",
    "CameraParameters",
    "FramePlan",
    "GroundTruth",
    "TextureAccumulator",
    "TextureMap",
    "TextureResult",
    "TextureWarning",
    "TrueTexture",
    "accumulate_frame",
    "build_texture",
    "camera_in_world",
    "camera_parameters",
    "depth_table",
    "display_scale",
    "evaluate_texture",
    "frame_numbers",
    "frame_poses",
    "images_missing",
    "kinect_model",
    "load_ground_truth",
    "mark_swept",
    "nearest_frames",
    "pair_frames",
    "plan_frames",
    "read_map",
    "recompute_run",
    "render_overlay",
    "render_texture",
    "run_stage",
    "swept_cells",
    "texture_stage",
    "update_metrics",
    "warm_up",
    "write_outputs",
]
