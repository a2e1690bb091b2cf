"""Micromouse mazes: file formats, the Udacity tester's rules, planners and exploring robots.

* :mod:`slam.maze.formats`: :class:`~slam.maze.formats.Maze`, the Udacity and micromouseonline
  readers and writers, wall validation.
* :mod:`slam.maze.referee`: the tester's rules step for step, the trial record and score.
* :mod:`slam.maze.planner` (kernels in :mod:`slam.maze.kernels`): step-optimal plans.
* :mod:`slam.maze.robots`: the report's flood-fill baselines and our ``bounded`` explorer.
* :mod:`slam.maze.bench`, :mod:`slam.maze.render`: many-maze benchmarks and PNG pictures.
"""

ROBOT_NAMES = ("bounded", "explore-all", "block-out")
"""The exploring robots of :data:`slam.maze.robots.ROBOTS`, by name: here, so that ``slam``'s
argument parser lists them without importing the robots' kernels (and numba)."""
DEFAULT_ROBOT = "bounded"
"""The robot ``slam maze`` runs unless told otherwise."""
