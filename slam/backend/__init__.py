"""The back end of ``rbpf`` beyond the local loop closing: submaps and a global loop search.

* :mod:`slam.backend.submaps` — consecutive node scans at their current poses as branch-and-bound
  grids (:mod:`slam.kernels.bnb`) and as distance-field maps for refinement;
* :mod:`slam.backend.global_loops` — closures found by branch-and-bound over a window that grows
  with the path since the submap, verified, cross-checked and χ²-gated in the pose graph of
  :mod:`slam.graph`.
"""
