"""Tables a generated kernel reads, computed from a component's parameters when the kernel
is generated (a stencil's 'tables:', gpucompgen/fusable.py): plain Python, the same
numbers on every machine, never code of a type file.  A table of floats (gaussian_f32)
becomes a float __constant table, one of integers an int one.

gaussian_q8: the 1-D Gaussian kernel OpenCV's GaussianBlur applies to 8-bit images, in
fixed point with 8 fraction bits (OpenCV's ufixedpoint16), as found in OpenCV's
smooth.dispatch.cpp and checked against cv2 (tests/test_ops_gauss.py):

1. the kernel in double (OpenCV computes it in software double, softdouble): for sigma
   <= 0 and n = 1, 3, 5, 7, 9 fixed binomial-like tables; otherwise sigma (or, for sigma
   <= 0, 0.15 n + 0.35 with one rounding, OpenCV's fused multiply-add of ((n - 1) / 2 -
   1) 0.3 + 0.8), t_i = exp(-x_i^2 / (8 sigma^2)) at x_i = 1 - n, 3 - n, ..., -2 (twice
   the distance from the centre), normalised by 1 / (2 sum t_i + 1), the centre 1 / sum;
2. to fixed point by error diffusion from the outer taps in: v_i = round-half-even(k_i
   256 + e), e the rounding error carried to the next tap; the centre takes what makes
   the weights sum to exactly 256.

OpenCV's exp is its own software one: its doubles differ from Python's math.exp by an
ulp or a few (more for values below 1e-20), which changes an 8-bit weight only when k_i
256 + e falls within about 1e-13 of a half; over 42,000 (n, sigma) pairs (n 1..31, sigma
0..12 by 0.01 and 2,000 random ones) the weights equal those made from
cv2.getGaussianKernel's doubles, every one.
"""

from __future__ import annotations

import math
import struct
from fractions import Fraction

# sigma <= 0: OpenCV's fixed tables (their sums: 1, 4, 16, 128, 256)
_FIXED = {1: ((1,), 1), 3: ((1, 2, 1), 4), 5: ((1, 4, 6, 4, 1), 16),
          7: ((4, 14, 28, 36, 28, 14, 4), 128),
          9: ((4, 13, 30, 51, 60, 51, 30, 13, 4), 256)}
MAX_TAPS = 255  # the weights stay non-negative and below 2^16 (ufixedpoint16) up to here


def gaussian_kernel(n: int, sigma: float) -> list[float]:
    """OpenCV's 1-D Gaussian kernel of n taps (n odd) in double, as
    cv2.getGaussianKernel(n, sigma, ktype=cv2.CV_64F) gives it, up to the last bits of
    OpenCV's software exp."""
    if n < 1 or n % 2 == 0 or n > MAX_TAPS:
        raise ValueError(f"a Gaussian kernel has an odd number of taps, 1 to {MAX_TAPS}, "
                         f"not {n}")
    if sigma <= 0 and n in _FIXED:
        values, total = _FIXED[n]
        return [v / total for v in values]
    # sigma from the size: n 0.15 + 0.35 rounded once (a fused multiply-add)
    s = float(sigma) if sigma > 0 else float(Fraction(n) * Fraction(0.15) + Fraction(0.35))
    scale = -0.125 / (s * s)
    outer = [math.exp(float(x * x) * scale) for x in range(1 - n, 0, 2)]
    total = 0.0
    for t in outer:  # summed in this order, then doubled, then the centre's 1 added
        total += t
    total = total * 2.0 + 1.0
    mul = 1.0 / total
    side = [t * mul for t in outer]
    return side + [mul] + side[::-1]


def gaussian_q8(n: int, sigma: float, n_else: int = 0, sigma_else: float = 0.0,
                reduced: bool = False) -> tuple:
    """The fixed-point weights (integers summing to 256) of OpenCV's 8-bit GaussianBlur
    along one axis: n taps for sigma; n <= 0 takes n_else, sigma <= 0 takes sigma_else
    (GaussianBlur's ksize height and sigmaY of 0: those of the width).  reduced: divided
    by the largest power of two that divides them all (their sum 256 by it too)."""
    n = int(n) if n > 0 else int(n_else)
    sigma = float(sigma) if sigma > 0 else float(sigma_else)
    k = gaussian_kernel(n, sigma)
    err = 0.0
    side = []
    for v in k[:n // 2]:
        adjusted = v * 256.0 + err
        q = round(adjusted)  # half to even, as cvRound
        err = adjusted - float(q)
        side.append(q)
    weights = (*side, 256 - 2 * sum(side), *side[::-1])
    if reduced:
        common = 256
        while any(w % common for w in weights):
            common //= 2
        weights = tuple(w // common for w in weights)
    return weights


def gaussian_f32(n: int, sigma: float, n_else: int = 0, sigma_else: float = 0.0) -> tuple:
    """OpenCV's Gaussian weights in float32 (its kernel for int16 and float32 frames:
    the double kernel rounded to float32), n taps for sigma, n <= 0 taking n_else and
    sigma <= 0 sigma_else (as gaussian_q8)."""
    n = int(n) if n > 0 else int(n_else)
    sigma = float(sigma) if sigma > 0 else float(sigma_else)
    return tuple(struct.unpack("f", struct.pack("f", v))[0] for v in gaussian_kernel(n, sigma))


def gaussian_q8_reduced(n: int, sigma: float, n_else: int = 0,
                        sigma_else: float = 0.0) -> tuple:
    """gaussian_q8's weights divided by the largest power of two that divides them all:
    the same sums in smaller numbers ((1 2 1) for 3 taps and sigma 0, whose row sums fit
    16 bits: a CPU's vector lanes hold twice as many), their sum 256 divided by it."""
    return gaussian_q8(n, sigma, n_else, sigma_else, reduced=True)


MAX_DERIVATIVE_TAPS = 7  # OpenCV's documented apertures 1, 3, 5, 7: integer sums stay
# below 255 * 64 * 64 (the smoothing's 64 squared) in magnitude


def sobel_taps(ksize: int, order: int) -> tuple:
    """OpenCV's Sobel kernel along one axis (cv2.getDerivKernels(..., normalize=False)):
    the binomial smoothing of n - order taps (1 2 1; 1 4 6 4 1; ...) convolved order
    times with the difference (-1 1), n = ksize, or 3 where ksize is 1 and the order is
    not 0 (ksize 1 with order 0: the single tap 1): (1 2 1), (-1 0 1) and (1 -2 1) for
    three taps.  ksize -1 (OpenCV's FILTER_SCHARR): Scharr's (3 10 3) or (-1 0 1)."""
    ksize, order = int(ksize), int(order)
    if ksize == -1:
        if order not in (0, 1):
            raise ValueError(f"the Scharr kernel (ksize -1) has orders 0 and 1, not {order}")
        return (3, 10, 3) if order == 0 else (-1, 0, 1)
    n = 3 if ksize == 1 and order > 0 else ksize
    if not (n >= 1 and n % 2 == 1 and n <= MAX_DERIVATIVE_TAPS and 0 <= order < n):
        raise ValueError(f"a derivative kernel has 1, 3, 5 or 7 taps and an order below "
                         f"them, not ksize {ksize} with order {order}")
    taps = [1]
    for step in [(1, 1)] * (n - order - 1) + [(-1, 1)] * order:
        taps = [a * step[0] + b * step[1]
                for a, b in zip([*taps, 0], [0, *taps], strict=True)]
    return tuple(taps)


def scharr_taps(order: int) -> tuple:
    """Scharr's kernel along one axis: (3 10 3) smoothing, (-1 0 1) for order 1."""
    return sobel_taps(-1, order)


def second_derivative_taps(ksize: int) -> tuple:
    """Sobel's second-derivative kernel of ksize (3 taps for ksize 1): the Laplacian's."""
    return sobel_taps(ksize, 2)


def smoothing_taps(ksize: int) -> tuple:
    """Sobel's smoothing kernel of ksize (the single tap 1 for ksize 1): the Laplacian's."""
    return sobel_taps(ksize, 0)


def median_network(ksize: int) -> tuple:
    """A compare-exchange network that leaves the median of ksize x ksize values (in
    slots 0..ksize^2-1, row by row) in one slot: (count, slot of the median, then count
    pairs (a, b): a takes the smaller, b the larger).  Batcher's odd-even merge sort of
    the next power of two, the slots beyond the values holding the largest value (a
    comparison with one of those moves nothing, or swaps two slots' names: neither is
    written), then only the exchanges the median depends on.  (0, 0) for ksize 3 and
    above 5: MedianBlur sorts 3 x 3 by a network of its own and counts above 5."""
    ksize = int(ksize)
    if ksize != 5:
        return (0, 0)
    n = ksize * ksize
    size = 1 << (n - 1).bit_length()
    pairs: list[tuple[int, int]] = []

    def merge(lo: int, length: int, r: int) -> None:
        step = 2 * r
        if step < length:
            merge(lo, length, step)
            merge(lo + r, length, step)
            pairs.extend((i, i + r) for i in range(lo + r, lo + length - r, step))
        else:
            pairs.append((lo, lo + r))

    def sort(lo: int, length: int) -> None:
        if length > 1:
            sort(lo, length // 2)
            sort(lo + length // 2, length // 2)
            merge(lo, length, 1)

    sort(0, size)
    slot = list(range(size))  # the slot holding the value at each position
    largest = set(range(n, size))  # positions holding the padding (the largest value)
    kept = []
    for i, j in pairs:
        if j in largest:
            continue
        if i in largest:  # the value moves down, the padding up: rename, do not compute
            slot[i], slot[j] = slot[j], slot[i]
            largest.discard(i)
            largest.add(j)
            continue
        kept.append((slot[i], slot[j]))
    live = {slot[n // 2]}
    needed = []
    for a, b in reversed(kept):
        if a in live or b in live:
            needed.append((a, b))
            live |= {a, b}
    needed.reverse()
    return (len(needed), slot[n // 2], *(v for pair in needed for v in pair))


# the functions a type's 'tables:' may call, by name: (function, least and most arguments)
TABLES = {"gaussian_q8": (gaussian_q8, 2, 4), "gaussian_q8_reduced": (gaussian_q8_reduced, 2, 4),
          "gaussian_f32": (gaussian_f32, 2, 4),
          "sobel_taps": (sobel_taps, 2, 2), "scharr_taps": (scharr_taps, 1, 1),
          "second_derivative_taps": (second_derivative_taps, 1, 1),
          "smoothing_taps": (smoothing_taps, 1, 1), "median_network": (median_network, 1, 1)}
