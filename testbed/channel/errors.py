"""Bit-error models that flip real bits of delivered bytes.

One :class:`BitErrors` per receiver draws where a received copy's bits flip. Bits are numbered in
transmission order: bit ``i`` is bit ``7 - i % 8`` (MSB first) of byte ``i // 8``.

Two sources, combined by OR of their error masks (a bit flips once if any source hits it):

- **independent** errors with a per-bit probability ``p`` given per copy (the link's ``ber``
  combined with the range-dependent part). Nothing is drawn per bit: the gaps between errors of a
  Bernoulli(p) bit stream are geometric, so a countdown to the next error is kept across frames
  while ``p`` stays the same (one draw per *error*, none for a clean frame); when ``p`` changes
  the countdown is redrawn, which is exact because the geometric law is memoryless. When many
  errors per frame are expected the count is drawn from Binomial(n, p) and the positions
  uniformly without replacement instead.
- the **Gilbert–Elliott** chain (:class:`~testbed.channel.config.GilbertElliott`), simulated by
  state sojourns: a sojourn in a state left with probability q per bit lasts Geometric(q) bits;
  within each sojourn the number of errors is Binomial(k, ber_state) and their positions uniform.
  The state and the rest of the current sojourn carry over to the receiver's next copy. A chain
  in time (``mean_good_s``, ``mean_bad_s``: :class:`TimedGilbertElliottChain`) holds its state
  for exponential sojourns in seconds instead, and a copy takes the state at its arrival.

Randomness only through the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import numpy as np

from testbed.channel.config import GilbertElliott

__all__ = ["BitErrors", "GilbertElliottChain", "TimedGilbertElliottChain", "flip_bits"]

_BINOMIAL_ABOVE = 2.0
"""Expected errors per copy above which independent errors are drawn as Binomial + positions."""
_NUMPY_FLIPS_ABOVE = 32
"""Flip with numpy above this many errors; a Python loop is faster below."""


def flip_bits(data: bytes, positions: list[int]) -> bytes:
    """Return ``data`` with the bits at ``positions`` inverted (positions distinct, MSB first)."""
    if len(positions) > _NUMPY_FLIPS_ABOVE:
        mask = np.zeros(len(data) * 8, dtype=np.bool_)
        mask[positions] = True
        flipped = np.frombuffer(data, dtype=np.uint8) ^ np.packbits(mask)
        return flipped.tobytes()
    buf = bytearray(data)
    for pos in positions:
        buf[pos >> 3] ^= 0x80 >> (pos & 7)
    return bytes(buf)


class GilbertElliottChain:
    """State of one receiver's Gilbert–Elliott chain; draws error positions frame after frame.

    Args:
        model: the chain's parameters.
        rng: random generator (owned by the receiver).
    """

    __slots__ = ("_ber", "_leave", "_remaining", "_rng", "bad")

    def __init__(self, model: GilbertElliott, rng: np.random.Generator) -> None:
        self._rng = rng
        self._leave = (model.p_good_to_bad, model.p_bad_to_good)
        self._ber = (model.ber_good, model.ber_bad)
        # Start in the stationary distribution; the residual sojourn of a memoryless chain is
        # again Geometric, so starting a fresh sojourn here is exact.
        self.bad = bool(rng.random() < model.stationary_bad)
        self._remaining = self._sojourn()

    def _sojourn(self) -> int:
        leave = self._leave[self.bad]
        if leave <= 0.0:
            return 1 << 62  # never leaves this state
        return int(self._rng.geometric(leave))

    def error_positions(self, n_bits: int) -> list[int]:
        """Advance the chain over ``n_bits`` received bits; return the positions that flip."""
        rng = self._rng
        out: list[int] = []
        pos = 0
        while pos < n_bits:
            k = min(self._remaining, n_bits - pos)
            ber = self._ber[self.bad]
            if ber >= 1.0:
                out.extend(range(pos, pos + k))
            elif ber > 0.0:
                m = int(rng.binomial(k, ber))
                if m:
                    out.extend((rng.choice(k, m, replace=False) + pos).tolist())
            pos += k
            self._remaining -= k
            if self._remaining == 0:
                self.bad = not self.bad
                self._remaining = self._sojourn()
        return out


class TimedGilbertElliottChain:
    """One receiver's Gilbert–Elliott chain in time (``mean_good_s``, ``mean_bad_s``): the
    state holds for exponential sojourns of those means (a continuous-time Markov chain), and
    a copy received at ``t_s`` takes the state at ``t_s`` for all its bits.

    Args:
        model: the chain's parameters (:attr:`GilbertElliott.timed`).
        rng: random generator (owned by the receiver).
    """

    __slots__ = ("_ber", "_means", "_rng", "_switch_s", "bad")

    def __init__(self, model: GilbertElliott, rng: np.random.Generator) -> None:
        self._rng = rng
        self._means = (model.mean_good_s, model.mean_bad_s)
        self._ber = (model.ber_good, model.ber_bad)
        # the stationary state at t = 0, and a fresh sojourn from it (memoryless: exact)
        self.bad = bool(rng.random() < model.stationary_bad)
        self._switch_s = float(rng.exponential(self._means[self.bad]))

    def state_at(self, t_s: float) -> bool:
        """Advance the chain to ``t_s`` [s] (never back); True when it is bad then."""
        while self._switch_s <= t_s:
            self.bad = not self.bad
            self._switch_s += float(self._rng.exponential(self._means[self.bad]))
        return self.bad

    def error_positions(self, n_bits: int, t_s: float) -> list[int]:
        """The positions that flip in a copy of ``n_bits`` bits received at ``t_s`` [s]."""
        ber = self._ber[self.state_at(t_s)]
        if ber <= 0.0:
            return []
        if ber >= 1.0:
            return list(range(n_bits))
        m = int(self._rng.binomial(n_bits, ber))
        return self._rng.choice(n_bits, m, replace=False).tolist() if m else []


class BitErrors:
    """One receiver's bit-error state: independent errors plus an optional burst chain.

    Args:
        burst: Gilbert–Elliott parameters (ignored when they cannot flip a bit).
        rng: random generator owned by this receiver.
    """

    __slots__ = ("_chain", "_gap", "_p", "_rng", "_timed")

    def __init__(self, burst: GilbertElliott, rng: np.random.Generator) -> None:
        self._rng = rng
        self._chain: GilbertElliottChain | None = None
        self._timed: TimedGilbertElliottChain | None = None
        if burst.enabled and burst.timed:
            self._timed = TimedGilbertElliottChain(burst, rng)
        elif burst.enabled:
            self._chain = GilbertElliottChain(burst, rng)
        self._p = -1.0  # probability the countdown was drawn for; -1 = none
        self._gap = 0  # clean bits left before the next independent error

    def _independent(self, n_bits: int, p: float) -> list[int]:
        if p <= 0.0:
            return []
        if p >= 1.0:
            return list(range(n_bits))
        rng = self._rng
        if n_bits * p > _BINOMIAL_ABOVE:
            self._p = -1.0  # the countdown is stale after a frame drawn this way
            m = int(rng.binomial(n_bits, p))
            return rng.choice(n_bits, m, replace=False).tolist() if m else []
        if p != self._p:
            self._p = p
            self._gap = int(rng.geometric(p)) - 1
        gap = self._gap
        if gap >= n_bits:
            self._gap = gap - n_bits
            return []
        out = []
        pos = gap
        while pos < n_bits:
            out.append(pos)
            pos += int(rng.geometric(p))
        self._gap = pos - n_bits
        return out

    def corrupt(self, data: bytes, p_independent: float, t_s: float = 0.0) -> tuple[bytes, int]:
        """Apply bit errors to one received copy.

        Args:
            data: the bytes as sent.
            p_independent: per-bit probability of independent errors for this copy.
            t_s: when it is received [s]: the time of a chain in time (else unused).

        Returns:
            The bytes as received and the number of flipped bits.
        """
        n_bits = len(data) * 8
        positions = self._independent(n_bits, p_independent)
        burst: list[int] = []
        if self._chain is not None:
            burst = self._chain.error_positions(n_bits)
        elif self._timed is not None:
            burst = self._timed.error_positions(n_bits, t_s)
        if burst:
            positions = sorted(set(positions).union(burst)) if positions else burst
        if not positions:
            return data, 0
        return flip_bits(data, positions), len(positions)
