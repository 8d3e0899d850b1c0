"""Adaptive run-length coding of sparse bit vectors, and the bit reader the decoder walks.

A vector of n bits whose length the decoder already knows (the candidates of one coding step) is
coded as the runs of zeros between its ones, with an adaptive block size 2^k in the manner of
the JPEG-LS run mode:

* ``1``: the next 2^k bits are all zero (or, if fewer than 2^k remain, all the rest are); k
  then grows by one (up to ``K_MAX``);
* ``0`` followed by r in ceil(log2(min(2^k, left))) bits: r zeros, then a one; for a
  significance vector, the one's sign bit follows. k then shrinks by one.

Long zero runs cost about one bit per 2^k zeros and dense vectors settle at k = 0, where every
input bit costs exactly one output bit (the raw cost). The state k is the only adaptation; the
caller keeps one per context and passes it in and out. The work is one Python step per one-bit
or per block, never per zero, so sparse vectors cost little time.

``Writer`` gathers coded segments as numpy bit arrays; ``Reader`` walks the received bits and
reports a vector cut short by the end of the data instead of raising.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

K_MAX = 15


class Writer:
    """Coded bits, gathered as numpy segments."""

    __slots__ = ("parts", "size")

    def __init__(self) -> None:
        self.parts: list[NDArray[np.uint8]] = []
        self.size = 0

    def raw(self, bits: NDArray[np.bool_]) -> None:
        """Append bits as they are."""
        self.parts.append(bits.astype(np.uint8))
        self.size += bits.size

    def runs(self, bits: NDArray[np.bool_], signs: NDArray[np.bool_] | None, k: int) -> int:
        """Append ``bits`` run-length coded (each one followed by its sign, if given).

        Returns:
            The adaptation state k after the vector.
        """
        n = bits.size
        ones = np.flatnonzero(bits).tolist()
        sign_list = signs.tolist() if signs is not None else [0] * len(ones)
        extra = 1 if signs is not None else 0
        vals: list[int] = []
        lens: list[int] = []
        i = 0
        for j, s in zip(ones, sign_list, strict=True):
            r = j - i
            blk = 1 << k
            while r >= blk:
                vals.append(1)
                lens.append(1)
                r -= blk
                i += blk
                if k < K_MAX:
                    k += 1
                blk = 1 << k
            left = n - i
            nb = ((blk if blk < left else left) - 1).bit_length()
            if extra:
                vals.append((r << 1) | s)
                lens.append(nb + 2)
            else:
                vals.append(r)
                lens.append(nb + 1)
            i = j + 1
            if k:
                k -= 1
        while i < n:
            vals.append(1)
            lens.append(1)
            i += 1 << k
            if k < K_MAX:
                k += 1
        if vals:
            self.parts.append(_expand(vals, lens))
            self.size += sum(lens)
        return k

    def bits(self) -> NDArray[np.uint8]:
        """All bits so far, one per element."""
        return np.concatenate(self.parts) if self.parts else np.zeros(0, dtype=np.uint8)


def _expand(vals: list[int], lens: list[int]) -> NDArray[np.uint8]:
    """Bits of the codes ``vals[i]`` of ``lens[i]`` bits each, most significant bit first."""
    v = np.asarray(vals, dtype=np.int64)
    ln = np.asarray(lens, dtype=np.int64)
    ends = np.cumsum(ln)
    total = int(ends[-1])
    code = np.repeat(np.arange(v.size), ln)
    shift = ends[code] - 1 - np.arange(total)
    out: NDArray[np.uint8] = ((v[code] >> shift) & 1).astype(np.uint8)
    return out


class Reader:
    """A cursor over the received bits."""

    __slots__ = ("arr", "pos", "text")

    def __init__(self, data: bytes) -> None:
        self.arr = np.unpackbits(np.frombuffer(data, dtype=np.uint8))
        self.text = (self.arr + ord("0")).tobytes().decode("ascii")
        self.pos = 0

    @property
    def left(self) -> int:
        """Bits not yet read."""
        return self.arr.size - self.pos

    def raw(self, n: int) -> NDArray[np.bool_]:
        """Up to n next bits as they are (fewer at the end of the data)."""
        chunk = self.arr[self.pos : self.pos + n].astype(bool)
        self.pos += chunk.size
        return chunk

    def runs(self, n: int, signed: bool, k: int) -> tuple[list[int], list[int], int, bool]:
        """Read a run-length coded vector of n bits (see ``Writer.runs``).

        Returns:
            Positions of its ones, their signs (1 = negative; zeros if not ``signed``), the
            state k after the vector, and whether the vector was complete. A one whose position
            or sign is cut off by the end of the data is not returned.
        """
        text = self.text
        end = len(text)
        pos = self.pos
        ones: list[int] = []
        signs: list[int] = []
        i = 0
        while i < n:
            if pos >= end:
                self.pos = pos
                return ones, signs, k, False
            if text[pos] == "1":
                pos += 1
                i += 1 << k
                if k < K_MAX:
                    k += 1
                continue
            blk = 1 << k
            left = n - i
            nb = ((blk if blk < left else left) - 1).bit_length()
            stop = pos + 1 + nb + signed
            if stop > end:
                self.pos = end
                return ones, signs, k, False
            r = int(text[pos + 1 : pos + 1 + nb], 2) if nb else 0
            if r >= left:  # only corrupt data says so
                self.pos = end
                return ones, signs, k, False
            ones.append(i + r)
            signs.append(text[stop - 1] == "1" if signed else 0)
            pos = stop
            i += r + 1
            if k:
                k -= 1
        self.pos = pos
        return ones, signs, k, True
