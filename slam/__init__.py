"""slam: robot logs in, trajectory, occupancy map and floor texture out.

The package owns the whole pipeline of the toolkit: loaders (:mod:`slam.io`), odometry,
numba kernels, the particle filter, texture mapping, the discrete (grid-world) filter, the
micromouse maze robot, the simulator, evaluation and visualisation.
"""

__version__ = "0.1.0"
