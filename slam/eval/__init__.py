"""Trajectory evaluation: pure metrics, no file I/O except the thin report writer.

* :mod:`slam.eval.relations`: the relation metric of Kümmerle et al. 2009 against a relations
  file (ground-truth relative motions between scan timestamps).
* :mod:`slam.eval.retime`: relations whose log lost its times (mit-killian's synthetic ones), put
  back on its scans.
* :mod:`slam.eval.trajectory`: SE(2) alignment, ATE and RPE against a reference trajectory.
* :mod:`slam.eval.report`: the table printed by ``slam eval`` and the ``eval.json`` writer.
"""
