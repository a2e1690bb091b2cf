"""Localization on a saved map: ``slam localize`` and :class:`slam.Localizer`.

* :mod:`~slam.localize.maps` — the map (a ``slam run`` folder's ``map.npz``) and its likelihood
  field (the distance transform of the occupied cells);
* :mod:`~slam.localize.sensor` — the beam model: likelihood field with the z_hit / z_rand /
  z_max mixture (Thrun et al., ch. 6.4);
* :mod:`~slam.localize.mcl` — Monte Carlo localization: odometry motion model, KLD-sampling
  (:mod:`~slam.localize.kld`, Fox 2003), low-variance resampling, pose and covariance;
* :mod:`~slam.localize.histogram` — global localization: the exact histogram filter over the
  map's free (x, y, θ) cells (the grid world's Bayes filter, :mod:`slam.discrete`, for real);
* :mod:`~slam.localize.recovery` — a lost or kidnapped robot noticed from the short- and
  long-term averages of the match quality (Augmented MCL);
* :mod:`~slam.localize.localizer` — :class:`~slam.localize.localizer.Localizer`, the three
  phases (global, tracking, recovering) behind one ``update(scan, odometry)`` per scan;
* :mod:`~slam.localize.run` — ``slam localize``: a log through the localizer into a run folder;
* :mod:`~slam.localize.kernels` — the numba loops.

See docs/localize.md.
"""
