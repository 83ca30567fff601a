"""Elliptic Fourier descriptors of closed outlines (Kuhl & Giardina 1982).

An outline traced once at constant speed, t ∈ [0, T) along its perimeter T,
is a sum of ellipses, harmonic n turning n times:

    x(t) = A0 + Σ a_n cos(2πnt/T) + b_n sin(2πnt/T)
    y(t) = C0 + Σ c_n cos(2πnt/T) + d_n sin(2πnt/T)

For a polygon the coefficients are exact sums over its sides (K&G eq. 6–7):

    a_n = T / (2n²π²) Σ_p (Δx_p / Δt_p) (cos φ_p − cos φ_{p−1}),   φ_p = 2πn t_p / T
    b_n = T / (2n²π²) Σ_p (Δx_p / Δt_p) (sin φ_p − sin φ_{p−1})

and c_n, d_n likewise with Δy_p.

References
----------
F. P. Kuhl and C. R. Giardina, "Elliptic Fourier features of a closed
contour", Computer Graphics and Image Processing 18 (1982) 236–258.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["efd_coefficients", "normalise_efd", "efd_aligned_distance"]

#: Start-point shifts tried per harmonic before refining the best one: the
#: cross-correlation of H harmonics has no feature narrower than 360°/(2H)
#: (9° for 20), so 72 points per harmonic (0.25° for 20) cannot step over its
#: maximum.
_SHIFT_GRID_PER_HARMONIC = 72


def efd_coefficients(outline: np.ndarray, harmonics: int) -> np.ndarray:
    """Kuhl & Giardina coefficients ``[[a_n, b_n, c_n, d_n], ...]``, n = 1 … ``harmonics``.

    ``outline`` is an (N, 2) closed polygon without repeated points (see
    :func:`bokehfit.metrics.outlines.as_outline`); the DC terms A0, C0 are
    left out, since every metric ignores position.
    """
    delta = np.concatenate((outline[1:], outline[:1])) - outline
    dt = np.hypot(delta[:, 0], delta[:, 1])
    t = np.concatenate([[0.0], np.cumsum(dt)])
    period = t[-1]
    n = np.arange(1, harmonics + 1)[:, None]
    phi = 2.0 * np.pi * n * t[None, :] / period
    dcos = np.cos(phi[:, 1:]) - np.cos(phi[:, :-1])
    dsin = np.sin(phi[:, 1:]) - np.sin(phi[:, :-1])
    slope = delta / dt[:, None]
    scale = period / (2.0 * n[:, 0] ** 2 * np.pi**2)
    a = scale * (dcos @ slope[:, 0])
    b = scale * (dsin @ slope[:, 0])
    c = scale * (dcos @ slope[:, 1])
    d = scale * (dsin @ slope[:, 1])
    return np.stack([a, b, c, d], axis=1)


def normalise_efd(coeffs: np.ndarray) -> np.ndarray:
    """Coefficients normalised for size, rotation and start point (K&G 1982, §4).

    The start point is moved to an end of the first harmonic's major axis
    (θ1), the outline rotated so that axis lies along +x (ψ1) and scaled so its
    semi-major axis is 1. Then a1 = 1, b1 = c1 = 0 and |d1| ≤ 1.

    Notes
    -----
    θ1 = ½ atan2(2(a1 b1 + c1 d1), a1² − b1² + c1² − d1²); each harmonic n is
    multiplied on the right by the rotation R(nθ1), then on the left by R(−ψ1),
    ψ1 = atan2(c1*, a1*), and divided by E = √(a1*² + c1*²).

    θ1 is defined only up to 180°, and not at all when the first harmonic is a
    circle, as it is for every regular n-gon (n ≥ 3) and the star: there the
    normal form depends on rounding noise. :func:`efd_aligned_distance`
    resolves that freedom by least squares.
    """
    a1, b1, c1, d1 = coeffs[0]
    theta = 0.5 * math.atan2(2.0 * (a1 * b1 + c1 * d1), a1 * a1 - b1 * b1 + c1 * c1 - d1 * d1)
    n = np.arange(1, len(coeffs) + 1)
    cos_n, sin_n = np.cos(n * theta), np.sin(n * theta)
    # [[a, b], [c, d]] @ [[cos nθ, −sin nθ], [sin nθ, cos nθ]]
    a = coeffs[:, 0] * cos_n + coeffs[:, 1] * sin_n
    b = -coeffs[:, 0] * sin_n + coeffs[:, 1] * cos_n
    c = coeffs[:, 2] * cos_n + coeffs[:, 3] * sin_n
    d = -coeffs[:, 2] * sin_n + coeffs[:, 3] * cos_n
    psi = math.atan2(c[0], a[0])
    semi_major = math.hypot(a[0], c[0])
    cos_p, sin_p = math.cos(psi), math.sin(psi)
    # [[cos ψ, sin ψ], [−sin ψ, cos ψ]] @ [[a, b], [c, d]]
    out = np.stack([cos_p * a + sin_p * c, cos_p * b + sin_p * d, -sin_p * a + cos_p * c, -sin_p * b + cos_p * d], axis=1)
    return out / semi_major


def _to_complex(coeffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Harmonic n as z(t) = P_n e^{int} + M_n e^{−int}: (P, M)."""
    a, b, c, d = coeffs.T
    return 0.5 * ((a + d) + 1j * (c - b)), 0.5 * ((a - d) + 1j * (c + b))


def _from_complex(plus: np.ndarray, minus: np.ndarray) -> np.ndarray:
    a, d = (plus + minus).real, (plus - minus).real
    c, b = (plus + minus).imag, (minus - plus).imag
    return np.stack([a, b, c, d], axis=1)


def efd_aligned_distance(normal_a: np.ndarray, normal_b: np.ndarray) -> tuple[float, float, float]:
    """Least-squares distance of two K&G-normalised coefficient arrays over the residual start point and rotation.

    Shifting the start point by τ (in 2π per perimeter) and rotating by ψ
    multiply P_n by e^{i(nτ+ψ)} and M_n by e^{i(−nτ+ψ)}; both are isometries of
    the coefficient vector (a² + b² + c² + d² = 2(|P|² + |M|²) per harmonic).
    The best ψ for a given τ is the phase that makes the cross-correlation
    S(τ) = Σ conj(A) B e^{±inτ} real, so the search is over τ alone: a grid
    that includes τ = 0 and π (the two K&G normal forms), then a bounded
    refinement. The result is therefore never above K&G's own distance.

    Returns
    -------
    distance, tau, psi
        The Euclidean distance between the real vectors [a_n, b_n, c_n, d_n]
        of A and of B moved by (τ, ψ), radians.
    """
    from scipy.optimize import minimize_scalar  # on first use: scipy.optimize takes ~0.3 s to import

    pa, ma = _to_complex(normal_a)
    pb, mb = _to_complex(normal_b)
    n = np.arange(1, len(normal_a) + 1)
    cross_plus, cross_minus = np.conj(pa) * pb, np.conj(ma) * mb

    def pose(tau):
        s = np.sum(cross_plus * np.exp(1j * n * tau) + cross_minus * np.exp(-1j * n * tau))
        psi = -float(np.angle(s))
        moved = _from_complex(pb * np.exp(1j * (n * tau + psi)), mb * np.exp(1j * (-n * tau + psi)))
        # From the difference, not from |A|² + |B|² − 2|S|, which cancels.
        return float(np.linalg.norm(normal_a - moved)), psi

    size = _SHIFT_GRID_PER_HARMONIC * len(n)  # even: the grid holds τ = 0 and π
    # S on the grid τ_k = 2πk/size is a discrete Fourier sum: P_n at frequency n, M_n at −n.
    spectrum = np.zeros(size, dtype=np.complex128)
    spectrum[n] = cross_plus
    spectrum[-n] = cross_minus
    best = 2.0 * np.pi * float(np.argmax(np.abs(np.fft.ifft(spectrum)))) / size
    step = 2.0 * np.pi / size
    # The distance itself, not |S|, is refined: near a match it has a sharp
    # minimum (∝ |τ − τ*|) where |S| is flat (∝ (τ − τ*)²), so τ comes out
    # to the tolerance rather than to its square root.
    # Searched as an offset from the grid point: the bounded search's tolerance
    # has a term relative to |x| (√ε·|x|), which an offset keeps small.
    refined = minimize_scalar(
        lambda offset: pose(best + offset)[0], bounds=(-step, step), method="bounded", options={"xatol": 1e-13}
    )
    tau = best + float(refined.x) if refined.fun < pose(best)[0] else best
    distance, psi = pose(tau)
    return distance, tau, psi
