"""Sweeps and tuning: many ``slam run`` cells (logs × seeds × settings), evaluated and tabulated.

* :mod:`slam.sweep.spec` — the sweep specification (TOML file and command-line values) and its
  cells;
* :mod:`slam.sweep.cell` — one cell: an ordinary ``slam run`` into its folder, then its
  evaluation (also the worker process of the local executor);
* :mod:`slam.sweep.executors` — where cells run: a local process pool or a Ray cluster;
* :mod:`slam.sweep.driver` — the sweep folder (safety, resume), results table, summary and plot;
* :mod:`slam.sweep.tune` — ``slam tune``: random or grid search over declared ranges.
"""
