"""Buffered Gaussian noise and first-order Gauss-Markov processes.

Drawing scalars one at a time from a `np.random.Generator` costs a few
microseconds each; the simulator needs several per step, so noise is drawn in
blocks. The stream is the same whatever the block size is asked for later,
because blocks are always drawn with the same size.
"""

from __future__ import annotations

import hashlib
import itertools
import math

import numpy as np

_BLOCK = 4096


class GaussianStream:
    """Standard-normal samples from one Generator, drawn in blocks. `next()` gives the next sample."""

    __slots__ = ("next",)

    def __init__(self, rng: np.random.Generator) -> None:
        def blocks():
            while True:
                yield rng.standard_normal(_BLOCK).tolist()

        # A C-level iterator over the blocks, each drawn when the first of its samples is asked for: the
        # simulator asks for several samples a physics step, where a Python-level method's call and
        # bookkeeping would cost more than the sample.
        self.next = itertools.chain.from_iterable(blocks()).__next__


class GaussMarkov:
    """A first-order Gauss-Markov process with stationary std `sigma` and time constant `tau_s`.

    Discretised exactly: x[k+1] = a x[k] + sigma sqrt(1 - a^2) w[k], a = exp(-dt/tau).
    The initial value is drawn from the stationary distribution.
    """

    __slots__ = ("sigma", "tau_s", "value", "_next", "_dt_s", "_a", "_b")

    def __init__(self, *, sigma: float, tau_s: float, noise: GaussianStream) -> None:
        self.sigma = sigma
        self.tau_s = tau_s
        self._next = noise.next  # the stream's draw, looked up once: processes step ~12 times a physics step
        self.value = sigma * noise.next()
        self._dt_s = -1.0
        self._a = 0.0
        self._b = 0.0

    def step(self, dt_s: float) -> float:
        if dt_s != self._dt_s:
            self._dt_s = dt_s
            self._a = math.exp(-dt_s / self.tau_s) if self.tau_s > 0 else 0.0
            self._b = self.sigma * math.sqrt(max(0.0, 1.0 - self._a * self._a))
        self.value = value = self._a * self.value + self._b * self._next()
        return value

    def retune(self, *, sigma: float, tau_s: float) -> None:
        """Change sigma and time constant, keeping the current value (scaled to the new sigma)."""
        if self.sigma > 0:
            self.value *= sigma / self.sigma
        self.sigma = sigma
        self.tau_s = tau_s
        self._dt_s = -1.0


class SmoothGaussMarkov:
    """A Gauss-Markov process passed through a first-order low-pass filter (time constant `smooth_s`).

    Its stationary std is `sigma` and its correlation time about `tau_s`, like
    `GaussMarkov`, but it changes smoothly over seconds instead of jittering:
    the shape of a GPS position error, which wanders rather than jumps.
    """

    __slots__ = ("value", "_inner", "_smooth_s")

    def __init__(self, *, sigma: float, tau_s: float, smooth_s: float, noise: GaussianStream) -> None:
        # A first-order low-pass of a GM process scales its variance by tau / (tau + smooth).
        inner_sigma = sigma * math.sqrt((tau_s + smooth_s) / tau_s)
        self._inner = GaussMarkov(sigma=inner_sigma, tau_s=tau_s, noise=noise)
        self._smooth_s = smooth_s
        # Start next to the inner process (scaled to the output's spread) so there is no start-up transient.
        self.value = self._inner.value * sigma / inner_sigma if inner_sigma > 0 else 0.0

    def step(self, dt_s: float) -> float:
        inner = self._inner.step(dt_s)
        self.value += (inner - self.value) * min(1.0, dt_s / self._smooth_s)
        return self.value


def child_rng(seed: int, stream: str) -> np.random.Generator:
    """An independent Generator for one named random stream of a trial.

    Streams are keyed by a stable hash of their name, so adding a new noise
    source never shifts the draws of existing ones.
    """
    digest = hashlib.sha256(stream.encode("utf-8")).digest()
    words = [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4)]
    return np.random.default_rng(np.random.SeedSequence([seed & 0xFFFFFFFFFFFFFFFF, *words]))
