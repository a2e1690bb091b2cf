"""The exact histogram filter: the Bayes filter on a finite state space.

The belief ``bel(x)`` is a probability for every state ``x`` (cell, or cell and heading), held as
an ``(H, R, C)`` array. One filter cycle is the same as the particle filter's, computed exactly:

* **predict** with the motion model and action ``u``: ``bel⁻(x') = Σ_x p(x' | x, u) · bel(x)``;
* **update** with the sensor model and observation ``z``: ``bel(x) = η · p(z | x) · bel⁻(x)``;
* **normalize**: ``η = 1 / Σ_x p(z | x) · bel⁻(x)``.

The belief is renormalised after every update *and* every prediction, so long runs neither
underflow nor drift: the total stays 1 to rounding (about 1e-15 per step) however many steps run.
An observation that has probability 0 in every state (a perfect sensor contradicting the model)
is an :class:`ImpossibleObservation`.

The stopping rule of the colour-grid experiments is :func:`localized`: the robot declares its
position when one cell holds at least ``threshold`` of the probability.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from slam.discrete.motion import MotionModel
from slam.discrete.sensors import SensorModel
from slam.discrete.world import GridWorld
from slam.errors import DataError, UsageError


class ImpossibleObservation(DataError):
    """An observation whose likelihood is 0 in every state the belief allows."""


def normalize(belief: np.ndarray, total: float | None = None) -> np.ndarray:
    """``belief / Σ belief``, in place; :class:`ImpossibleObservation` if the sum is 0.

    ``total`` may be passed when a kernel already computed the sum in the same pass.
    """
    if total is None:
        total = float(belief.sum())
    if not total > 0.0 or not np.isfinite(total):
        raise ImpossibleObservation(
            f"belief sums to {total!r}: the observation is impossible in every state the robot "
            f"could be in"
        )
    belief /= total
    return belief


def predict(
    belief: np.ndarray, world: GridWorld, motion: MotionModel, action: object
) -> np.ndarray:
    """Prediction step: ``bel⁻(x') = Σ_x p(x' | x, u) · bel(x)``, renormalised."""
    return normalize(motion.predict(belief, world, action))


def update(belief: np.ndarray, likelihood: np.ndarray) -> np.ndarray:
    """Measurement update: ``bel(x) = η · p(z | x) · bel⁻(x)`` (``likelihood`` broadcasts over
    headings). Returns a new array."""
    return normalize(belief * likelihood)


def marginal(belief: np.ndarray) -> np.ndarray:
    """``(R, C)`` probability of each cell: the belief summed over headings."""
    return belief.sum(axis=0)


def localized(belief: np.ndarray, threshold: float) -> tuple[int, int] | None:
    """Stopping rule: the cell ``(row, col)`` holding at least ``threshold``, else ``None``."""
    cells = marginal(belief)
    best = int(np.argmax(cells))
    if cells.flat[best] >= threshold:
        return tuple(int(i) for i in np.unravel_index(best, cells.shape))  # type: ignore[return-value]
    return None


@dataclass
class HistogramFilter:
    """A world, a sensor model and a motion model, with the current belief.

    Likelihood arrays are cached per observation: the sensor models have few distinct readings
    (colours, 16 WNES patterns), so a long run computes each one once.
    """

    world: GridWorld
    sensor: SensorModel | None = None
    """Sensor model; needed only by :meth:`update`."""
    motion: MotionModel | None = None
    """Motion model; needed only by :meth:`predict`."""
    belief: np.ndarray | None = None
    """``(H, R, C)`` current belief; default: uniform over open cells and headings. A ``(R, C)``
    prior is spread evenly over the headings."""
    _likelihoods: dict = field(default_factory=dict, init=False, repr=False)
    _spare: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        for model in (self.sensor, self.motion):
            check = getattr(model, "check", None)
            if check is not None:
                check(self.world)
        if self.belief is None:
            self.belief = self.world.uniform_belief()
        else:
            belief = np.asarray(self.belief, dtype=float)
            if belief.shape == self.world.shape:
                belief = np.broadcast_to(belief / self.world.headings, self.world.belief_shape)
            if belief.shape != self.world.belief_shape:
                raise DataError(
                    f"prior: expected shape {self.world.shape} or {self.world.belief_shape}, "
                    f"found {belief.shape}"
                )
            self.belief = normalize(np.array(belief, dtype=float))

    def likelihood(self, observation: object) -> np.ndarray:
        """``p(z | cell)`` for ``observation``, ``(R, C)``, cached."""
        if self.sensor is None:
            raise UsageError("this filter has no sensor model: it cannot sense")
        cached = self._likelihoods.get(observation)
        if cached is None:
            cached = self.sensor.likelihood(self.world, observation)
            cached.setflags(write=False)
            self._likelihoods[observation] = cached
        return cached

    def _buffer(self) -> np.ndarray:
        spare = self._spare
        if spare is None or spare.shape != self.belief.shape or spare is self.belief:
            spare = np.empty_like(self.belief)
        return spare

    def predict(self, action: object) -> np.ndarray:
        """Apply the motion model for ``action``; return the new belief.

        Models with a one-pass kernel (``predict_into``) write into a spare buffer that the
        filter reuses every step, so the previous belief array is overwritten two steps later:
        copy :attr:`belief` to keep it.
        """
        if self.motion is None:
            raise UsageError("this filter has no motion model: it cannot move")
        into = getattr(self.motion, "predict_into", None)
        if into is None:
            self.belief = predict(self.belief, self.world, self.motion, action)
            return self.belief
        out = self._buffer()
        total = into(self.belief, self.world, action, out)
        self._spare, self.belief = self.belief, normalize(out, total)
        return self.belief

    def update(self, observation: object) -> np.ndarray:
        """Apply the sensor model for ``observation``; return the new belief."""
        out = self._buffer()
        np.multiply(self.belief, self.likelihood(observation), out=out)
        self._spare, self.belief = self.belief, normalize(out)
        return self.belief

    def step(self, action: object, observation: object) -> np.ndarray:
        """One full cycle: predict with ``action``, then update with ``observation``.

        Models with a one-pass kernel do both in a single sweep (the prediction is not normalised
        on its own: the update's normalisation absorbs it); otherwise :meth:`predict` then
        :meth:`update`.
        """
        into = getattr(self.motion, "predict_into", None)
        if into is None:
            self.predict(action)
            return self.update(observation)
        out = self._buffer()
        total = into(self.belief, self.world, action, out, self.likelihood(observation))
        self._spare, self.belief = self.belief, normalize(out, total)
        return self.belief

    @property
    def posterior(self) -> np.ndarray:
        """``(R, C)`` probability of each cell (summed over headings)."""
        return marginal(self.belief)


def sample_motion(
    world: GridWorld,
    motion: MotionModel,
    state: tuple[int, int, int],
    action: object,
    rng: np.random.Generator,
) -> tuple[int, int, int]:
    """Draw the next state ``x' ~ p(x' | x, u)`` of a simulated robot.

    A model with its own ``sample`` method draws directly; otherwise the transition distribution
    from ``x`` is the prediction of the one-hot belief at ``x``, so the simulation uses exactly the
    model the filter assumes.
    """
    direct = getattr(motion, "sample", None)
    if direct is not None:
        return direct(world, state, action, rng)
    one_hot = np.zeros(world.belief_shape)
    one_hot[state] = 1.0
    p = motion.predict(one_hot, world, action).ravel()
    p = np.clip(p, 0.0, None)
    index = int(rng.choice(p.size, p=p / p.sum()))
    return tuple(int(i) for i in np.unravel_index(index, world.belief_shape))  # type: ignore[return-value]
