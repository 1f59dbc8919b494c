"""Cosine-sum tapers of the harmonic tracker and their response off a line.

Sources: Harris 1978 ("On the use of windows for harmonic analysis with the DFT", Proc. IEEE 66)
for the Hann, Blackman-Harris and flat-top coefficients and the scalloping response
``|W(ε)| / W(0)``; Jain et al. 1979 for the 3-bin peak interpolation from that response. Pure
window maths: no state, no configuration.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "COSINE_WINDOWS",
    "interpolation_table",
    "response_at",
    "window_response",
    "window_values",
]

#: Cosine-sum windows ``w(u) = Σ a_k (−1)^k cos 2πku`` on ``u ∈ [0, 1)`` (periodic).
COSINE_WINDOWS: dict[str, tuple[float, ...]] = {
    "hann": (0.5, 0.5),
    "blackmanharris": (0.35875, 0.48829, 0.14128, 0.01168),
    "flattop": (0.21557895, 0.41663158, 0.277263158, 0.083578947, 0.006947368),
}


def window_values(name: str, u: np.ndarray) -> np.ndarray:
    """Cosine-sum window ``name`` at fractions ``u ∈ [0, 1)`` of the segment."""
    a = COSINE_WINDOWS[name]
    w = np.full_like(u, a[0], dtype=np.float64)
    for k in range(1, len(a)):
        w += (-1) ** k * a[k] * np.cos(2.0 * np.pi * k * u)
    return w


def window_response(name: str, eps: np.ndarray | float) -> np.ndarray:
    """|W(ε)| / W(0): the window's amplitude response ``ε`` bins off a line (scalloping)."""
    a = COSINE_WINDOWS[name]
    e = np.asarray(eps, dtype=np.float64)
    s = a[0] * np.sinc(e)
    for k in range(1, len(a)):
        s = s + 0.5 * a[k] * (np.sinc(e - k) + np.sinc(e + k))
    return np.abs(s) / a[0]


def _sinc(x: float) -> float:
    """``np.sinc`` of one float (the same formula, without array overhead)."""
    y = math.pi * (x if x != 0.0 else 1.0e-20)
    return math.sin(y) / y


def response_at(name: str, eps: float) -> float:
    """:func:`window_response` of one offset as a float (per line in every table: scalar math)."""
    a = COSINE_WINDOWS[name]
    s = a[0] * _sinc(eps)
    for k in range(1, len(a)):
        s = s + 0.5 * a[k] * (_sinc(eps - k) + _sinc(eps + k))
    return abs(s) / a[0]


def interpolation_table(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(ρ, δ): ρ(δ) = (|W(1−δ)| − |W(1+δ)|) / |W(δ)| for the 3-bin peak interpolation."""
    d = np.linspace(-0.5, 0.5, 2001)
    rho = (window_response(name, 1.0 - d) - window_response(name, 1.0 + d)) / window_response(
        name, d
    )
    return rho, d
