"""The simulator: synthetic ECE276A robot logs with ground truth.

A seeded procedural building (:mod:`slam.sim.world`), a smooth differential-drive trajectory
through it (:mod:`slam.sim.trajectory`, :mod:`slam.sim.scenarios`), the robot's sensors sampled
from that ground truth (:mod:`slam.sim.sensors`, Kinect frames in :mod:`slam.sim.render`, numba
kernels in :mod:`slam.sim.kernels`), and the dataset writer (:mod:`slam.sim.dataset`) that puts it
all in the exact ECE276A file format next to the true trajectory, map and floor texture.
:mod:`slam.sim.demo` caches the demo log of ``slam run demo``; :mod:`slam.sim.fixtures` builds
the "dataset20 with simulated LiDAR" test fixture. User documentation: ``docs/sim.md``.
"""
