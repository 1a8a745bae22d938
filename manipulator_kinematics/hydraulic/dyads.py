"""The dyad: a pin X at distances r_a, r_b from two known pins A, B (circle-circle intersection).

Paper 000 solves each closed loop of a cylinder-driven manipulator in closed form (eq. 1 for a
cylinder triangle, eq. 2 for a four-bar); both are this one construction applied in sequence, a
triangle being a dyad whose one side is a cylinder. Everything here is vectorised over leading
axes (..., 2 for points); one state is a batch of one.

The derivatives come from the loop closures themselves (implicit differentiation, no finite
differences): |X - A|^2 = r_a^2 and |X - B|^2 = r_b^2 give, differentiated once,

    (X - A) . (Xdot - Adot) = r_a r_a_dot,      (X - B) . (Xdot - Bdot) = r_b r_b_dot,

a 2 x 2 system M Xdot = rhs with M = [(X - A)^T; (X - B)^T], det M = cross(X - A, X - B), which
vanishes exactly at a dead centre; differentiated twice, the same M with

    (X - A) . Xddot = (X - A) . Addot + r_a_dot^2 + r_a r_a_ddot - |Xdot - Adot|^2   (likewise B).
"""

from __future__ import annotations

import numpy as np

__all__ = ["cross", "intersect", "margin", "perp", "rates", "second_rates"]


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """u_r v_z - u_z v_r over the last axis."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def perp(u: np.ndarray) -> np.ndarray:
    """u turned +90 degrees (counter-clockwise in the side view)."""
    return np.stack((-u[..., 1], u[..., 0]), axis=-1)


def intersect(
    a: np.ndarray, b: np.ndarray, r_a: np.ndarray | float, r_b: np.ndarray | float, orientation: int
) -> tuple[np.ndarray, np.ndarray]:
    """X on the side ``orientation`` = sign(cross(B - A, X - A)) and h^2, the squared distance of X
    from the line A-B (< 0: the circles do not meet, the dyad does not close; X is then NaN)."""
    d = b - a
    dist2 = np.sum(d * d, axis=-1)
    along = (r_a * r_a - r_b * r_b + dist2) / (2.0 * dist2)  # (foot of X on A-B - A) / |d|
    h2 = r_a * r_a / dist2 - along * along  # (h / |d|)^2
    with np.errstate(invalid="ignore"):
        height = np.sqrt(h2)
    x = a + along[..., None] * d + (orientation * height)[..., None] * perp(d)
    return x, h2 * dist2


def margin(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dead-centre margin (rad): min(g, pi - g), g the angle A-X-B (0: a dead centre)."""
    u, v = a - x, b - x
    g = np.arctan2(np.abs(cross(u, v)), np.sum(u * v, axis=-1))
    return np.minimum(g, np.pi - g)


def _solve(x: np.ndarray, a: np.ndarray, b: np.ndarray, rhs_a: np.ndarray, rhs_b: np.ndarray) -> np.ndarray:
    """M^-1 [rhs_a, rhs_b] with M = [(X - A)^T; (X - B)^T]; rhs may carry one more axis (..., m)
    (a Jacobian's columns), the result then (..., m, 2)."""
    u, v = x - a, x - b
    det = cross(u, v)
    if rhs_a.ndim > det.ndim:
        u, v, det = u[..., None, :], v[..., None, :], det[..., None]
    return (
        np.stack((v[..., 1] * rhs_a - u[..., 1] * rhs_b, u[..., 0] * rhs_b - v[..., 0] * rhs_a), axis=-1)
        / det[..., None]
    )


def rates(
    x: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    r_a: np.ndarray | float,
    r_b: np.ndarray | float,
    a_dot: np.ndarray,
    b_dot: np.ndarray,
    r_a_dot: np.ndarray | float,
    r_b_dot: np.ndarray | float,
) -> np.ndarray:
    """Xdot from the once-differentiated closures (module docstring). With Jacobians (a_dot (...,
    m, 2), r_a_dot (..., m)) it gives dX/dD (..., m, 2): the same linear map per column."""
    u, v = x - a, x - b
    if np.ndim(a_dot) > np.ndim(x):  # Jacobian columns: one more axis before the point's
        u, v = u[..., None, :], v[..., None, :]
        r_a, r_b = np.asarray(r_a)[..., None], np.asarray(r_b)[..., None]
    rhs_a = np.sum(u * a_dot, axis=-1) + r_a * r_a_dot
    rhs_b = np.sum(v * b_dot, axis=-1) + r_b * r_b_dot
    return _solve(x, a, b, rhs_a, rhs_b)


def second_rates(
    x: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    r_a: np.ndarray | float,
    r_b: np.ndarray | float,
    x_dot: np.ndarray,
    a_dot: np.ndarray,
    b_dot: np.ndarray,
    r_a_dot: np.ndarray | float,
    r_b_dot: np.ndarray | float,
    a_ddot: np.ndarray,
    b_ddot: np.ndarray,
    r_a_ddot: np.ndarray | float,
    r_b_ddot: np.ndarray | float,
) -> np.ndarray:
    """Xddot from the twice-differentiated closures (module docstring), along one motion."""
    u, v = x - a, x - b
    ea, eb = x_dot - a_dot, x_dot - b_dot
    rhs_a = np.sum(u * a_ddot, axis=-1) + r_a_dot * r_a_dot + r_a * r_a_ddot - np.sum(ea * ea, axis=-1)
    rhs_b = np.sum(v * b_ddot, axis=-1) + r_b_dot * r_b_dot + r_b * r_b_ddot - np.sum(eb * eb, axis=-1)
    return _solve(x, a, b, rhs_a, rhs_b)
