"""Noticing a lost (or kidnapped) robot: the short- and long-term likelihood averages of
Augmented MCL (Thrun et al., Probabilistic Robotics, table 8.3).

After each particle update the mean match quality of the predicted particles ``w_avg`` feeds two
exponential averages, ``w_slow += α_slow·(w_avg − w_slow)`` and ``w_fast += α_fast·(w_avg −
w_fast)``. Augmented MCL injects random particles with probability ``max(0, 1 − w_fast/w_slow)``;
on a map of hundreds of square metres random particles almost never land near the true pose, so
here the same signal *declares the robot lost* when ``w_fast < lost_ratio · w_slow``, and the
localizer starts the exact histogram filter over the whole map in the background
(:mod:`slam.localize.localizer`).
"""

from __future__ import annotations


class LostMonitor:
    """The two averages and the lost test."""

    def __init__(self, alpha_slow: float, alpha_fast: float, lost_ratio: float, warmup: int):
        self.alpha_slow = float(alpha_slow)
        self.alpha_fast = float(alpha_fast)
        self.lost_ratio = float(lost_ratio)
        self.warmup = int(warmup)
        self.reset()

    def reset(self) -> None:
        """Start over (after a (re)localization)."""
        self.w_slow = 0.0
        self.w_fast = 0.0
        self.count = 0

    def observe(self, w_avg: float) -> bool:
        """Feed one update's mean match quality; return whether the robot is lost."""
        if self.count == 0:
            self.w_slow = self.w_fast = float(w_avg)
        else:
            self.w_slow += self.alpha_slow * (w_avg - self.w_slow)
            self.w_fast += self.alpha_fast * (w_avg - self.w_fast)
        self.count += 1
        return self.count > self.warmup and self.w_fast < self.lost_ratio * self.w_slow

    @property
    def injection_probability(self) -> float:
        """Augmented MCL's ``max(0, 1 − w_fast/w_slow)``."""
        if self.w_slow <= 0:
            return 0.0
        return max(0.0, 1.0 - self.w_fast / self.w_slow)
