"""slam: robot logs in, trajectory, occupancy map and floor texture out.

The package owns the whole pipeline of the toolkit: loaders (:mod:`slam.io`), odometry,
numba kernels, the particle filter, texture mapping, the discrete (grid-world) filter, the
micromouse maze robot, the simulator, evaluation and visualisation.
"""

import os as _os

# numba's OpenMP threads spin while idle by default; when the other cores are busy (a laptop
# running anything else, CI), every parallel region then waits milliseconds for a descheduled
# spinner. Sleeping idle threads cost microseconds instead. Set before numba loads OpenMP; an
# explicit user setting wins.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
