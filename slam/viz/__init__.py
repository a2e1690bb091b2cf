"""Rerun visualisation: every run records itself for the rerun viewer.

* :mod:`slam.viz.recorder`: :class:`~slam.viz.recorder.RunRecorder`, the filter observer that writes
  ``recording.rrd`` in a ``slam run`` folder (and streams to a live viewer with ``--viewer``);
* :mod:`slam.viz.blueprint`: the default layouts (map beside the time series; grid and maze views);
* :mod:`slam.viz.images`: occupancy grids and texture maps as images placed in world coordinates;
* :mod:`slam.viz.grid`, :mod:`slam.viz.maze`: recordings of ``slam grid run`` and ``slam maze run``;
* :mod:`slam.viz.stream`: recording streams (file and viewer sinks, timelines), the viewer process
  (always bound to 127.0.0.1), and reading recordings back (entities, timelines, row counts);
* :mod:`slam.viz.webserve`: the one-file HTTP server from which ``slam view --web``'s page fetches
  the recording.

Only :mod:`rerun` is used (``rerun-sdk``); the viewer only observes, nothing here changes a result.
See ``docs/viz.md``.
"""
