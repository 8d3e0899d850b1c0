"""The coding schedule both ends of the bit-plane coder walk: which coefficients each step codes.

The encoder and the decoder share one generator, ``steps``: it yields a step (what kind of bits,
which coefficients, which adaptation context) and, before it is resumed, the caller records the
step's outcome in the shared ``State`` (the encoder from the true magnitudes, the decoder from
the bits it read). The schedule therefore cannot differ between the two ends.

Per bit plane p, top plane first (t = 2^p):

1. *near* pass, for each group coarse to fine: significance of the active, not yet significant
   coefficients that have a significant neighbour (8-neighbourhood in the band) or a significant
   parent as of the previous plane (these are the likely ones), then the descendant-set bits
   of the group's active coefficients whose set is not yet significant; a 1 activates the
   children in the next group, in this plane;
2. *far* pass, for each group coarse to fine: significance of the remaining active candidates;
3. refinement bits (bit p) of coefficients significant before plane p, coarse to fine.

The order follows the measured quality gain per bit: significance steps (with the descendant
bits that open them) gain several times more per bit than raw refinement bits, so refinement
comes last (0.4 dB at 320 x 240, 1200 B, over refinement between the passes). Splitting
significance by neighbourhood gives the run-length coder separate statistics to adapt to.
No I/O lives here.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from testbed.imaging.wavelet import Layout

SIG = 0  # significance bits, each 1 followed by its sign
DESC = 1  # descendant-set significance bits
REF = 2  # refinement bits, coded raw


@dataclass(slots=True)
class State:
    """What both ends know about the coefficients so far.

    Attributes:
        sig: (n,) significant (magnitude >= 2^p for some coded plane p).
        desc_sig: (m,) descendant set significant, for the m coefficients that have children.
    """

    sig: NDArray[np.bool_]
    desc_sig: NDArray[np.bool_]

    @classmethod
    def empty(cls, lay: Layout) -> State:
        """Nothing known yet."""
        return cls(np.zeros(lay.size, dtype=bool), np.zeros(lay.bounds[-2], dtype=bool))


@dataclass(frozen=True, slots=True)
class Step:
    """One coding step.

    Attributes:
        kind: SIG, DESC or REF.
        context: key of the run-length adaptation state the step uses.
        plane: bit plane p.
        idx: flat indices of the coefficients whose bit the step carries, in coding order.
    """

    kind: int
    context: int
    plane: int
    idx: NDArray[np.int64]


def near_map(sig: NDArray[np.bool_], lay: Layout) -> NDArray[np.bool_]:
    """(n,) True where a coefficient has a significant 8-neighbour in its band or parent."""
    out = np.zeros(lay.size, dtype=bool)
    pos = 0
    for rows, cols in lay.shapes:
        band = sig[pos : pos + rows * cols].reshape(rows, cols)
        pad = np.zeros((rows + 2, cols + 2), dtype=bool)
        pad[1:-1, 1:-1] = band
        acc = pad[:-2, :-2] | pad[:-2, 1:-1] | pad[:-2, 2:] | pad[1:-1, :-2]
        acc |= pad[1:-1, 2:] | pad[2:, :-2] | pad[2:, 1:-1] | pad[2:, 2:]
        out[pos : pos + rows * cols] = acc.ravel()
        pos += rows * cols
    start = lay.bounds[1]
    out[start:] |= sig[lay.parent[start:]]
    return out


def _near_group(sig0: NDArray[np.bool_], lay: Layout, g: int) -> NDArray[np.bool_]:
    """``near_map(sig0, lay)[bounds[g]:bounds[g + 1]]``, computed for group g alone."""
    a, b = lay.bounds[g], lay.bounds[g + 1]
    out = np.empty(b - a, dtype=bool)
    first = 0 if g == 0 else 1 + 3 * (g - 1)
    pos = a
    for rows, cols in lay.shapes[first : first + (1 if g == 0 else 3)]:
        band = sig0[pos : pos + rows * cols].reshape(rows, cols)
        pad = np.zeros((rows + 2, cols + 2), dtype=bool)
        pad[1:-1, 1:-1] = band
        acc = pad[:-2, :-2] | pad[:-2, 1:-1] | pad[:-2, 2:] | pad[1:-1, :-2]
        acc |= pad[1:-1, 2:] | pad[2:, :-2] | pad[2:, 1:-1] | pad[2:, 2:]
        out[pos - a : pos - a + rows * cols] = acc.ravel()
        pos += rows * cols
    if g:
        out |= sig0[lay.parent[a:b]]
    return out


def steps(state: State, lay: Layout, planes: int) -> Iterator[Step]:
    """The coding steps, top plane first; ``state`` must be updated before each resumption.

    The work follows what is open, not the image size: a group whose parents have no
    significant descendant set yet has no active coefficients and yields its steps empty
    without being scanned, and the neighbour map of a group is computed only once it has
    active coefficients (from the significance at the start of the plane, as ``near_map``).
    """
    bounds = lay.bounds
    ngroups = len(bounds) - 1
    parent = lay.parent
    none = np.zeros(0, dtype=np.int64)

    def active_of(g: int) -> NDArray[np.bool_] | None:
        """Active coefficients of group g (None if there are none)."""
        a, b = bounds[g], bounds[g + 1]
        if g == 0:
            return np.ones(b - a, dtype=bool)
        if not state.desc_sig[bounds[g - 1] : a].any():
            return None
        found: NDArray[np.bool_] = state.desc_sig[parent[a:b]]
        return found

    for p in range(planes - 1, -1, -1):
        sig0 = state.sig.copy()
        near: dict[int, NDArray[np.bool_]] = {}
        before = np.flatnonzero(sig0)
        for g in range(ngroups):
            a, b = bounds[g], bounds[g + 1]
            active = active_of(g)
            if active is None:
                yield Step(SIG, 4 * g, p, none)
                if g < ngroups - 1:
                    yield Step(DESC, 4 * g + 1, p, none)
                continue
            near[g] = _near_group(sig0, lay, g)
            cand = active & ~state.sig[a:b] & near[g]
            yield Step(SIG, 4 * g, p, a + np.flatnonzero(cand))
            if g < ngroups - 1:
                open_sets = active & ~state.desc_sig[a:b]
                yield Step(DESC, 4 * g + 1, p, a + np.flatnonzero(open_sets))
        for g in range(ngroups):
            a, b = bounds[g], bounds[g + 1]
            active = active_of(g)
            if active is None:
                yield Step(SIG, 4 * g + 2, p, none)
                continue
            if g not in near:
                near[g] = _near_group(sig0, lay, g)
            cand = active & ~state.sig[a:b] & ~near[g]
            yield Step(SIG, 4 * g + 2, p, a + np.flatnonzero(cand))
        yield Step(REF, -1, p, before)
